"""The partitioned least-squares solve (neuralao.pipeline.geometry.partitioned_solve) against subdomain count,
beside SuperLU and today's one-task multigrid CG, on three systems:

    .venv/bin/python bench/bench_partitioned_solve.py                      # Table 1's terrain, ~2-3 minutes
    .venv/bin/python bench/bench_partitioned_solve.py --terrain-cells 200  # a smaller terrain, seconds
    .venv/bin/python bench/bench_partitioned_solve.py --terrain-cells 2087 --terrain-size 1897 \
        --houses 60000 --cases terrain --subdomains 16,64 --reference amg --no-ablation  # the 10x terrain

* **terrain**: the level generator's Table 1 terrain (660 x 660 cells, 436,921 vertices, 600 m), sampled by
  Table 1's rule (1.25 samples a vertex, at most 2 a face, small faces none), the samples under 6,000 yawed
  4-9 m house footprints invalid (the terrain inside the houses, where the back-face rule rejects them):
  the level's one big connected component;
* **soup**: triangle soup (tests/helpers.py ``soup_scene``: houses' split-vertex boxes, interpenetrating,
  duplicated and fanned triangles, ellipsoids, ribbons across it), one ribbon and a sphere without valid
  samples;
* **bunny**: the closed bunny, a patch without valid samples.

Sample values are smooth signals plus noise (the solve's cost does not depend on them). Per case: SuperLU of
the whole system (the reference), multigrid CG (pyamg, rtol 1e-10: today's one task for a big component),
then the partitioned solve at each ``--subdomains`` count, in this process: CG iterations, max abs error
against SuperLU, wall seconds, the largest single task (a subdomain's system and factorisation: what
bounds the scale-out) and the projected wall time on one worker per subdomain (the driver's setup and
iterations plus, per wave, the slowest subdomain's step; no transfer time). An ablation at the
largest count compares coarse spaces. Writes OUT/bench_partitioned_solve.json and .md.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from helpers import smooth_values, soup_scene, under_footprints  # noqa: E402
from scipy.sparse.linalg import splu  # noqa: E402

from neuralao.pipeline.bakes.level_pieces import scene_samples  # noqa: E402
from neuralao.pipeline.geometry.least_squares import normal_equations, solve_amg  # noqa: E402
from neuralao.pipeline.geometry.level_gen import settings_for, terrain  # noqa: E402
from neuralao.pipeline.geometry.partitioned_solve import (  # noqa: E402
    Partition,
    SolveInfo,
    partition,
    solve_partitioned,
)
from neuralao.pipeline.geometry.scene import load_scene, scene_from_arrays  # noqa: E402
from neuralao.pipeline.geometry.surface import surface_samples  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402


def terrain_system(cells: int, houses: int, seed: int = 0, size: float | None = None):
    """Table 1's terrain (``cells`` per side, ``size`` metres: None, Table 1's) and its normal equations
    (module doc)."""
    s = settings_for("table1", seed)
    s.terrain_cells = cells
    s.terrain_size = size or s.terrain_size
    rng = np.random.default_rng(seed)
    scene = scene_from_arrays(
        *terrain(s, rng.uniform(0, 2 * math.pi, (4, 2))), "terrain", drop_degenerate=False
    )
    samples = scene_samples(scene, 1.25, 0, 2, seed)
    valid = ~under_footprints(samples.points, rng, houses, s.terrain_size / 2 - 8)
    return scene, samples, smooth_values(samples.points, rng), valid


def soup_system(seed: int = 4):
    rng = np.random.default_rng(seed)
    scene, ribbon = soup_scene(rng, houses=200, half=100.0)
    samples = surface_samples(scene, 3 * len(scene.vertices), 8, seed)
    p = samples.points
    valid = (rng.uniform(size=len(p)) > 0.2) & (np.linalg.norm(p - [10, 0, 10], axis=1) > 30)
    valid &= (samples.face < ribbon) | (samples.face >= ribbon + 300)
    return scene, samples, smooth_values(p, rng), valid


def bunny_system(seed: int = 5):
    rng = np.random.default_rng(seed)
    scene = load_scene("bunny")
    samples = surface_samples(scene, 3 * len(scene.vertices), 8, seed)
    p = samples.points
    valid = np.linalg.norm(p - p[0], axis=1) >= 0.3 * np.ptp(p, axis=0).max()
    valid &= rng.uniform(size=len(p)) > 0.2
    return scene, samples, smooth_values(p * 20 / np.ptp(p, axis=0).max(), rng), valid


def timed(fn):
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - t0, time.process_time() - c0, out


def projected(info: SolveInfo, k: int) -> float:
    """Wall seconds with one worker per subdomain: the driver's own work plus, per wave (two an iteration),
    the slowest subdomain's task (tasks are recorded wave by wave, subdomain by subdomain)."""
    per_wave = np.asarray(info.seconds_tasks).reshape(-1, k)
    return info.seconds_setup + info.seconds_driver + float(per_wave.max(axis=1).sum())


def run_case(
    name: str,
    scene,
    samples,
    values,
    valid,
    counts: list[int],
    reference: str = "superlu",
    ablate: bool = True,
) -> dict:
    t_eq, _, (a, rhs) = timed(lambda: normal_equations(scene, samples, values, valid))
    n = a.shape[0]
    print(f"{name}: {n:,} vertices, {a.nnz:,} non-zeros, {(~valid).mean():.1%} samples invalid", flush=True)
    t_amg, c_amg, amg = timed(lambda: solve_amg(a, rhs))
    # The reference: SuperLU of the whole system, or (a 10x terrain, whose factor takes too long and too
    # much memory here) today's multigrid CG at relative residual 1e-10.
    t_lu, c_lu, ref = timed(lambda: splu(a.tocsc()).solve(rhs)) if reference == "superlu" else (0.0, 0.0, amg)
    out = {
        "vertices": n,
        "nonzeros": int(a.nnz),
        "invalid_share": float((~valid).mean()),
        "assembly_seconds": t_eq,
        "reference": reference,
        "superlu": {"seconds": t_lu, "cpu_seconds": c_lu} if reference == "superlu" else None,
        "amg": {"seconds": t_amg, "cpu_seconds": c_amg, "max_abs": float(np.abs(amg - ref).max())},
        "partitioned": [],
    }
    print(
        f"  reference {reference} {t_lu:.2f} s, multigrid CG {t_amg:.2f} s "
        f"(max abs {out['amg']['max_abs']:.1e})",
        flush=True,
    )
    for k in counts:
        info = SolveInfo()
        t, c, v = timed(lambda k=k, info=info: solve_partitioned(a, rhs, scene.vertices, k, info=info))
        row = {
            "subdomains": k,
            "iterations": info.iterations,
            "max_abs": float(np.abs(v - ref).max()),
            "max_abs_vs_amg": float(np.abs(v - amg).max()),
            "seconds": t,
            "cpu_seconds": c,
            "setup_seconds": info.seconds_setup,
            "driver_seconds": info.seconds_driver,
            "task_seconds_sum": float(sum(info.seconds_tasks)),
            "largest_task_seconds": info.largest_task,
            "projected_seconds": projected(info, len(info.subdomain_vertices)),
            "largest_subdomain_vertices": max(info.subdomain_vertices),
            "coarse_size": info.coarse_size,
        }
        out["partitioned"].append(row)
        print(
            f"  {k:>3} subdomains: {max(info.iterations):>3} iterations, max abs {row['max_abs']:.1e}, "
            f"{t:.2f} s, largest task {row['largest_task_seconds']:.3f} s, "
            f"projected {row['projected_seconds']:.2f} s",
            flush=True,
        )
    out["ablation"] = ablation(a, rhs, scene.vertices, max(counts), ref) if ablate else []
    return out


def ablation(a, rhs, points, k: int, ref) -> list[dict]:
    """Coarse spaces at ``k`` subdomains: per core and connected component (the method), per core only, and
    one aggregate for everything (about one-level Schwarz)."""
    full = partition(a, points, k)
    rows = []
    for label, coarse in (
        ("core x component (the method)", full.coarse),
        ("core only", full.core.copy()),
        ("one aggregate", np.zeros_like(full.coarse)),
    ):
        info = SolveInfo()
        try:
            v = solve_partitioned(
                a,
                rhs,
                points,
                k,
                info=info,
                max_iterations=2000,
                subdivision=Partition(full.core, full.parts, coarse),
            )
            rows.append(
                {"coarse": label, "iterations": info.iterations, "max_abs": float(np.abs(v - ref).max())}
            )
        except Exception as e:  # noqa: BLE001 - a failed variant is a row of the table
            rows.append({"coarse": label, "failed": str(e)})
    return rows


def markdown(r: dict) -> str:
    lines = [
        f"Partitioned least squares (two columns), one process; load average {r['load_average'][0]:.1f} -> "
        f"{r['load_average'][1]:.1f} on {r['cpu_count']} cores.",
        "",
    ]
    for name, c in r["cases"].items():
        lines += [
            f"**{name}** ({c['vertices']:,} vertices, {c['invalid_share']:.0%} of the samples invalid): "
            + (
                f"SuperLU {c['superlu']['seconds']:.2f} s; "
                if c.get("superlu")
                else "reference: multigrid CG; "
            )
            + f"multigrid CG, one task (today) {c['amg']['seconds']:.2f} s, "
            f"max abs {c['amg']['max_abs']:.1e}; assembling the system {c['assembly_seconds']:.2f} s",
            "",
            f"| subdomains | iterations | max abs vs {'SuperLU' if c.get('superlu') else 'multigrid CG'} "
            "| wall s (one process) | largest task s | "
            "projected s (a worker each) | largest subdomain (vertices) |",
            "|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for p in c["partitioned"]:
            lines.append(
                f"| {p['subdomains']} | {'/'.join(map(str, p['iterations']))} | {p['max_abs']:.1e} | "
                f"{p['seconds']:.2f} | {p['largest_task_seconds']:.3f} | {p['projected_seconds']:.2f} | "
                f"{p['largest_subdomain_vertices']:,} |"
            )
        k = c["partitioned"][-1]["subdomains"]
        lines += [
            "",
            f"| coarse space at {k} subdomains | iterations | max abs vs SuperLU |",
            "|---|---:|---:|",
        ]
        for row in c["ablation"]:
            if "failed" in row:
                lines.append(f"| {row['coarse']} | failed | |")
            else:
                its = "/".join(map(str, row["iterations"]))
                lines.append(f"| {row['coarse']} | {its} | {row['max_abs']:.1e} |")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--terrain-cells", type=int, default=660, help="terrain cells per side (Table 1: 660)")
    p.add_argument("--houses", type=int, default=6000, help="house footprints on the terrain (Table 1: 6000)")
    p.add_argument(
        "--terrain-size", type=float, default=None, help="metres (Table 1: 600; the 10x world: 1897)"
    )
    p.add_argument("--subdomains", default="1,2,4,8,16,32", help="comma-separated subdomain counts")
    p.add_argument("--cases", default="terrain,soup,bunny")
    p.add_argument(
        "--reference", choices=("superlu", "amg"), default="superlu", help="amg: a 10x terrain (no SuperLU)"
    )
    p.add_argument("--no-ablation", action="store_true", help="skip the coarse-space ablation")
    p.add_argument("--out", default="build/bench/partitioned_solve")
    args = p.parse_args(argv)
    counts = [int(k) for k in args.subdomains.split(",")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    builders = {
        "terrain": lambda: terrain_system(args.terrain_cells, args.houses, size=args.terrain_size),
        "soup": soup_system,
        "bunny": bunny_system,
    }
    load_before = os.getloadavg()[0]
    cases = {}
    for name in args.cases.split(","):
        cases[name] = run_case(name, *builders[name](), counts, args.reference, not args.no_ablation)
    result = {
        "terrain_cells": args.terrain_cells,
        "houses": args.houses,
        "cases": cases,
        "load_average": [load_before, os.getloadavg()[0]],
        "cpu_count": os.cpu_count(),
    }
    write_json(out / "bench_partitioned_solve.json", result)
    write_text(out / "bench_partitioned_solve.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
