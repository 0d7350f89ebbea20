"""The level bake's driver-heavy stages, old and new side by side in one process (ratios, not seconds,
are what a shared machine measures well): LOD resampling weighting and the least-squares solve.

    .venv/bin/python bench/bench_level_stages.py                           # the "medium" level (~300k faces)
    .venv/bin/python bench/bench_level_stages.py --preset table1 --set ...  # any generator preset

Writes OUT/bench_level_stages.json and .md (default build/bench/level_stages/):

* **resampling** (the LOD's vertices and surface samples, as `bake_lod` does): the geometric reference
  (projected world hit points, bincount: what the bake did before) against the trace-speed weighting
  (Embree's barycentrics, weight r - |r - t|, row sums), each run twice interleaved, best kept; both
  beside a bare trace of the same rays; the largest difference between the two.
* **solve** (the receivers' least squares, both distances): SuperLU against multigrid-preconditioned
  CG (pyamg) and the per-component solve (the level default, here its blocks in series), each with its
  error against SuperLU (max abs, RMSE, share of vertices off by more than half an 8-bit step).

The samples' AO comes from a trace at ``--rays`` (default 16): only the inputs of the measured stages,
whose cost does not depend on it.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.pipeline.bakes.level_pieces import scene_samples  # noqa: E402
from neuralao.pipeline.bakes.level_settings import blend, halves, label_settings, load_level_settings  # noqa: E402
from neuralao.pipeline.bakes.level_stages import fit_level, opaque_scene, simplify  # noqa: E402
from neuralao.pipeline.geometry.least_squares import fit_least_squares  # noqa: E402
from neuralao.pipeline.geometry.level_files import (
    flatten,  # noqa: E402
    read_level,  # noqa: E402
)
from neuralao.pipeline.geometry.level_gen import settings_for, write_level  # noqa: E402
from neuralao.pipeline.geometry.scene import scene_from_arrays  # noqa: E402
from neuralao.pipeline.geometry.surface import surface_samples  # noqa: E402
from neuralao.pipeline.tracing.level_tracer import (  # noqa: E402
    _RESAMPLE_RAYS,
    LevelLabeller,
    _resample_block,
    _resample_block_geometric,
    sphere_directions,
)
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402

# The "medium" level: the small preset at 4x its area and 9x its terrain cells (~300k faces).
MEDIUM = ["terrain_cells=360", "houses=400", "terrain_size=240"]


def resample(fn, labeller, values, centers, radius, rays):
    """resample_in_spheres' blocking with one block function (the reference or the fast one)."""
    u = sphere_directions(rays)
    cols = values.reshape(len(values), -1)
    out = np.full(len(centers), np.nan)
    block = max(1, _RESAMPLE_RAYS // len(u))
    for lo in range(0, len(centers), block):
        c = centers[lo : lo + block]
        out[lo : lo + block] = fn(labeller, cols, c, np.full(len(c), radius), u)[0][:, 0]
    return out


CPU: dict[str, float] = {}  # CPU seconds (all threads) of the latest timed call, by label


def timed(fn, label: str = ""):
    """Wall seconds and result of ``fn()``; its CPU seconds (all threads) go to ``CPU[label]``: on a
    shared, loaded machine CPU seconds are what the same work costs on idle cores."""
    t0, c0 = time.perf_counter(), time.process_time()
    result = fn()
    CPU[label] = time.process_time() - c0
    return time.perf_counter() - t0, result


def whole_level(level):
    """The level flattened whole: its receivers (static instances) and its opaque scene."""
    from types import SimpleNamespace

    rv, rf, _ = flatten(level, level.nodes_with("static"))
    receivers = scene_from_arrays(rv, rf, "receivers", drop_degenerate=False)
    return SimpleNamespace(receivers=receivers, opaque=opaque_scene(level))


def median_edge(scene) -> float:
    v, f = scene.vertices, scene.faces
    return float(np.median(np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1)))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", default="small")
    p.add_argument(
        "--set", action="append", default=None, help="generator overrides (default: the medium level)"
    )
    p.add_argument(
        "--rays", type=int, default=16, help="rays of the trace that makes the inputs (default 16)"
    )
    p.add_argument("--out", default="build/bench/level_stages")
    args = p.parse_args(argv)
    out = Path(args.out)
    overrides = MEDIUM if args.set is None and args.preset == "small" else (args.set or [])
    level, cfg = write_level(out / "level", settings_for(args.preset, 0, overrides), args.preset)
    s = load_level_settings(cfg, [f"trace.rays={args.rays}"])
    g = whole_level(read_level(level))
    t = s.trace
    samples = scene_samples(
        g.receivers, t.samples_per_vertex, t.min_samples_per_face, t.samples_per_face_cap, s.seed
    )
    lab = LevelLabeller(g.opaque, label_settings(s, g.opaque.diagonal))
    load_before = os.getloadavg()[0]
    t_trace, (ao, valid) = timed(lambda: lab.obscurance(samples.points, samples.normals, halves(s)), "trace")
    result = {
        "level": {
            "preset": args.preset,
            "overrides": overrides,
            "vertices": len(g.receivers.vertices),
            "faces": len(g.receivers.faces),
            "samples": len(samples),
        },
        "trace": {"seconds": t_trace, "rays_per_second": len(samples) * args.rays / t_trace},
        "workers": s.workers,
    }

    # ---- solve
    solve = {}
    t_direct, ref = timed(
        lambda: fit_least_squares(g.receivers, samples, ao, valid, s.trace.alpha, "direct"), "direct"
    )
    solve["direct"] = {"seconds": t_direct, "cpu_seconds": CPU["direct"]}
    # (Jacobi CG, solver="cg", is left out: on this regulariser it needs thousands of iterations, 40x
    # SuperLU's time at rtol 1e-8 on the medium level, and at rtol 1e-6 it is off by up to 0.8.)
    for solver in ("amg", "components"):
        t, v = timed(lambda solver=solver: _try_fit(g, samples, ao, valid, s, solver), solver)
        e = np.abs(v.astype(np.float64) - ref) if v is not None else None
        solve[solver] = {
            "seconds": t,
            "speedup": t_direct / t,
            "cpu_seconds": CPU[solver],
            "cpu_speedup": CPU["direct"] / CPU[solver],
            **(
                {
                    "max_abs": float(e.max()),
                    "rmse": float(np.sqrt((e**2).mean())),
                    "share_over_half_8bit": float((e > 0.5 / 255).mean()),
                }
                if e is not None
                else {"failed": True}
            ),
        }
    result["solve"] = solve

    # ---- LOD resampling (bake_lod's two resamplings)
    final = blend(ref[:, 0], ref[:, 1], s.blend)
    lod = simplify(g.receivers, s.lod.target_reduction)
    radius = s.lod.radius or 1.5 * median_edge(lod)
    lod_samples = surface_samples(lod, s.lod.samples_per_vertex * len(lod.vertices), 16, s.seed + 3)
    centers = np.r_[lod.vertices, lod_samples.points]
    values = np.r_[final, np.full(len(g.opaque.vertices) - len(final), np.nan)]
    rays = len(centers) * len(sphere_directions(s.lod.rays))
    times = {"geometric": [], "fast": []}
    cpu = {"geometric": [], "fast": []}
    got = {}
    for _ in range(2):
        for name, fn in (("geometric", _resample_block_geometric), ("fast", _resample_block)):
            t, got[name] = timed(lambda fn=fn: resample(fn, lab, values, centers, radius, s.lod.rays), name)
            times[name].append(t)
            cpu[name].append(CPU[name])
    bare, _ = timed(lambda: _bare_trace_seconds(lab, centers, radius, s.lod.rays), "bare")
    both = np.isfinite(got["fast"]) & np.isfinite(got["geometric"])
    result["resample"] = {
        "points": len(centers),
        "rays": rays,
        "radius": radius,
        "geometric_seconds": min(times["geometric"]),
        "fast_seconds": min(times["fast"]),
        "bare_trace_seconds": bare,
        "speedup": min(times["geometric"]) / min(times["fast"]),
        "geometric_cpu_seconds": min(cpu["geometric"]),
        "fast_cpu_seconds": min(cpu["fast"]),
        "bare_trace_cpu_seconds": CPU["bare"],
        "cpu_speedup": min(cpu["geometric"]) / min(cpu["fast"]),
        "geometric_rays_per_second": rays / min(times["geometric"]),
        "fast_rays_per_second": rays / min(times["fast"]),
        "bare_trace_rays_per_second": rays / bare,
        "same_misses": bool((np.isfinite(got["fast"]) == np.isfinite(got["geometric"])).all()),
        "max_abs_difference": float(np.abs(got["fast"][both] - got["geometric"][both]).max(initial=0.0)),
    }
    result["load_average"] = [load_before, os.getloadavg()[0]]
    result["cpu_count"] = os.cpu_count()
    result["peak_rss_bytes"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    write_json(out / "bench_level_stages.json", result)
    write_text(out / "bench_level_stages.md", markdown(result))
    print(markdown(result))
    return 0


def _try_fit(g, samples, ao, valid, s, solver):
    from dataclasses import replace

    from neuralao.runtime.foundation.errors import NeuralaoError

    try:
        return fit_level(g.receivers, samples, ao, valid, replace(s.trace, solver=solver))
    except NeuralaoError:
        return None  # did not converge: reported as failed


def _bare_trace_seconds(lab: LevelLabeller, centers, radius, rays) -> float:
    """The same rays through closest_hits_local alone (no weighting)."""
    u = sphere_directions(rays)
    scale = lab.scale
    block = max(1, _RESAMPLE_RAYS // len(u))
    t0 = time.perf_counter()
    for lo in range(0, len(centers), block):
        c = (centers[lo : lo + block] - lab.center) / scale
        o = (c[:, None] + (radius / scale) * u[None]).reshape(-1, 3).astype(np.float32)
        d = np.ascontiguousarray(np.broadcast_to(-u.astype(np.float32), (len(c), len(u), 3)).reshape(-1, 3))
        lab.closest_hits_local(o, d, np.full(len(o), 2 * radius / scale, np.float32))
    return time.perf_counter() - t0


def markdown(r: dict) -> str:
    lv, rs, sv = r["level"], r["resample"], r["solve"]
    lines = [
        f"Level: {lv['vertices']:,} V / {lv['faces']:,} F, {lv['samples']:,} samples; "
        f"{r['workers']} tracing threads; load average {r['load_average'][0]:.1f} -> "
        f"{r['load_average'][1]:.1f} on {r['cpu_count']} cores.",
        "",
        f"| LOD resampling ({rs['points']:,} points x {rs['rays'] // rs['points']} rays) | wall s | "
        "CPU s | M rays per CPU s |",
        "|---|---:|---:|---:|",
        f"| geometric weighting (before) | {rs['geometric_seconds']:.2f} | "
        f"{rs['geometric_cpu_seconds']:.2f} | {rs['rays'] / rs['geometric_cpu_seconds'] / 1e6:.2f} |",
        f"| trace-speed weighting (now) | {rs['fast_seconds']:.2f} | "
        f"{rs['fast_cpu_seconds']:.2f} | {rs['rays'] / rs['fast_cpu_seconds'] / 1e6:.2f} |",
        f"| bare trace of the same rays | {rs['bare_trace_seconds']:.2f} | "
        f"{rs['bare_trace_cpu_seconds']:.2f} | {rs['rays'] / rs['bare_trace_cpu_seconds'] / 1e6:.2f} |",
        f"| **speedup (now / before)** | **{rs['speedup']:.2f}x** | **{rs['cpu_speedup']:.2f}x** | "
        f"max abs difference {rs['max_abs_difference']:.1e} |",
        "",
        "| least squares (receivers, 2 columns, incl. building the system) | wall s | CPU s | "
        "CPU speedup | max abs vs SuperLU | RMSE | share > half an 8-bit step |",
        "|---|---:|---:|---:|---:|---:|---:|",
        f"| SuperLU (direct) | {sv['direct']['seconds']:.2f} | {sv['direct']['cpu_seconds']:.2f} | 1.00 | "
        "0 | 0 | 0 |",
    ]
    for k, label in (
        ("amg", "multigrid-preconditioned CG (pyamg, rtol 1e-10)"),
        ("components", "per connected component (SuperLU; multigrid CG from 100k vertices), in series"),
    ):
        v = sv[k]
        if v.get("failed"):
            lines.append(
                f"| {label} | {v['seconds']:.2f} | {v['cpu_seconds']:.2f} | did not converge | | | |"
            )
        else:
            lines.append(
                f"| {label} | {v['seconds']:.2f} | {v['cpu_seconds']:.2f} | "
                f"{v['cpu_speedup']:.2f} | {v['max_abs']:.1e} | {v['rmse']:.1e} | "
                f"{v['share_over_half_8bit']:.1e} |"
            )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
