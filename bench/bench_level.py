"""Table 1 of Sloan et al. 2013 reproduced: a level bake at >= 1.5M vertices / 1.8M faces, 256 rays.

    .venv/bin/python bench/bench_level.py                       # the table1 preset (minutes)
    .venv/bin/python bench/bench_level.py --preset small        # a quick run

Generates the seeded synthetic level (pipeline/geometry/level_gen.py), bakes it with `neuralao bake LEVEL
--config` semantics (pipeline/bakes/level.py) and writes OUT/bench_level.json and OUT/bench_level.md:
every stage's seconds beside the paper's row (NVIDIA K20, OptiX), the ratio, peak memory, rays per
second and the machine's load average before and after (other jobs on a shared machine slow it).
The bake folder keeps its stages, so a second run of the same command only reruns what is stale
(use --fresh to time everything again).

``--baseline DIR`` first bakes the same level with the checkout at DIR (another version of this project,
e.g. a ``git worktree`` of an older commit; it runs its own bench/bench_level.py, fresh), then this one,
in the same run on the same idle machine, and adds a before / after table per stage (OUT/bench_level.md).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.pipeline.bakes.level import bake_level  # noqa: E402
from neuralao.pipeline.bakes.level_settings import load_level_settings  # noqa: E402
from neuralao.pipeline.geometry.level_gen import settings_for, write_level  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402

# Table 1 of the paper: description, seconds (on a K20), our stage(s).
PAPER = [
    ("Process geometry, 1.5M V 1.8M F", 2.0, ["geometry"]),
    ("Samples mesh, 6.7M samples", 1.0, ["samples"]),
    ("Flatten 46 trees, 7856 'fog' proxies for shrubs", 1.0, ["foliage"]),
    ("OptiX BVH build", 10.5, ["bvh"]),
    ("Ray trace samples", 35.1, ["trace"]),
    ("Build sparse volume for 'trees', ray trace 11829 pts", 0.53, ["decorators"]),
    ("Ray trace region for dynamic AO 332741 pts", 9.2, []),
    ("Least squares solve", 8.6, ["solve"]),
    ("Resample LOD geometry 5.7M pts", 5.7, ["lod:resample"]),
    ("Least squares solve LOD 0.65M V 0.8M F", 4.2, ["lod:solve"]),
]
PAPER_TOTAL = 78.0
# Stages that only produce the README's error tables (not part of a production bake).
CHECK_STAGES = {"blend_check", "lod_check"}


def stage_seconds(info: dict) -> dict[str, float]:
    out = {s["stage"]: s["seconds"] for s in info["stages"]}
    for s in info["stages"]:
        for k, v in s.items():
            if k.startswith("seconds_"):
                out[f"{s['stage']}:{k[8:]}"] = v
    return out


def markdown(result: dict) -> str:
    info, secs = result["bake"], result["stage_seconds"]
    c = info["counts"]
    lines = [
        f"Level: {c['receiver_vertices']:,} V, {c['receiver_faces']:,} F baked per vertex; "
        f"{c['samples']:,} samples x {info['settings']['trace']['rays']} rays = "
        f"{c['samples'] * info['settings']['trace']['rays'] / 1e6:,.0f} M rays; "
        f"{c.get('tree_instances', 0)} trees, {c.get('shrub_instances', 0)} shrub boxes, "
        f"{c.get('grass_instances', 0)} grass clumps.",
        "",
        "| Table 1 row (K20) | paper (s) | here (s) | here / paper |",
        "|---|---:|---:|---:|",
    ]
    for desc, paper, ours in PAPER:
        if not ours:
            lines.append(f"| {desc} | {paper:g} | (volumes: bench_volumes.py) | - |")
            continue
        t = sum(secs.get(k, 0.0) for k in ours)
        lines.append(f"| {desc} | {paper:g} | {t:.1f} | {t / paper:.1f}x |")
    extra = [
        s
        for s in info["stages"]
        if not any(
            s["stage"] in row[2] or any(k.startswith(s["stage"] + ":") for k in row[2]) for row in PAPER
        )
    ]
    for s in extra:
        lines.append(f"| (not in Table 1) {s['description']} | - | {s['seconds']:.1f} | - |")
    lines += [
        f"| **Total** | **{PAPER_TOTAL:g}** | **{result['seconds_total']:.1f}** | "
        f"**{result['seconds_total'] / PAPER_TOTAL:.1f}x** |",
        f"| Total without the error-table checks | | {result['seconds_method']:.1f} | "
        f"{result['seconds_method'] / PAPER_TOTAL:.1f}x |",
        "",
        f"Trace: {result['trace_mrays_per_s']:.2f} M rays/s. Peak memory (RSS) "
        f"{info['peak_rss_bytes'] / 2**30:.1f} GiB. {result['cpu_count']} cores; "
        f"load average {result['load_before'][0]:.2f} before, {result['load_after'][0]:.2f} after (1-min; "
        f"the bake itself accounts for up to {result['cpu_count']}: above that, "
        "other jobs shared the cores).",
    ]
    return "\n".join(lines) + "\n"


# Run first in the baseline's process (PYTHONPATH): the editable install maps neuralao's packages to this
# checkout's folders; this points them at NEURALAO_ROOT's.
BASELINE_SITE = """import os, sys
for finder in sys.meta_path:
    mapping = getattr(finder, "MAPPING", None) or getattr(sys.modules.get(finder.__module__), "MAPPING", None)
    if isinstance(mapping, dict) and any(k.startswith("neuralao.") for k in mapping):
        for name in list(mapping):
            mapping[name] = os.path.join(os.environ["NEURALAO_ROOT"], name.split(".")[1])
"""


def run_baseline(checkout: Path, args) -> dict:
    """bench/bench_level.py of the checkout at ``checkout`` (fresh, same preset and seed), run as its own
    process with neuralao's packages imported from that checkout; returns its bench_level.json."""
    import subprocess

    out = Path(args.out).resolve() / "baseline"
    site = out / "site"
    site.mkdir(parents=True, exist_ok=True)
    (site / "sitecustomize.py").write_text(BASELINE_SITE)
    cmd = [sys.executable, "bench/bench_level.py", "--preset", args.preset, "--seed", str(args.seed)]
    cmd += ["--out", str(out), "--fresh"] + [f"--set={kv}" for kv in args.set]
    env = dict(os.environ, PYTHONPATH=str(site), NEURALAO_ROOT=str(checkout.resolve()))
    subprocess.run(cmd, cwd=checkout, env=env, check=True)
    return json.loads((out / "level" / args.preset / "bench_level.json").read_text())


def before_after(before: dict, after: dict) -> str:
    """Per-stage seconds of the baseline and of this checkout, side by side, with their ratio."""
    b = {s["stage"]: s for s in before["bake"]["stages"]}
    a = {s["stage"]: s for s in after["bake"]["stages"]}
    lines = [
        "| stage | before (s) | after (s) | before / after | driver peak RSS before / after (MiB) |",
        "|---|---:|---:|---:|---:|",
    ]
    for name in list(b) + [n for n in a if n not in b]:
        sb, sa = b.get(name, {}).get("seconds"), a.get(name, {}).get("seconds")
        rb, ra = (x.get(name, {}).get("peak_rss_bytes", 0) / 2**20 for x in (b, a))
        ratio = f"{sb / sa:.2f}x" if sb and sa else "-"
        fmt = lambda v: f"{v:.1f}" if v is not None else "-"  # noqa: E731
        lines.append(f"| {name} | {fmt(sb)} | {fmt(sa)} | {ratio} | {rb:,.0f} / {ra:,.0f} |")
    tb, ta = before["seconds_total"], after["seconds_total"]
    pb, pa = before["bake"]["peak_rss_bytes"] / 2**30, after["bake"]["peak_rss_bytes"] / 2**30
    lines.append(
        f"| **total** | **{tb:.1f}** | **{ta:.1f}** | **{tb / ta:.2f}x** | {pb:.2f} / {pa:.2f} GiB |"
    )
    return "\n".join(lines) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", default="table1")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--out", default="build/bench", help="results go to OUT/level/PRESET/ (default build/bench)"
    )
    p.add_argument("--set", action="append", default=[], help="bake setting override, e.g. trace.rays=64")
    p.add_argument("--fresh", action="store_true", help="delete the bake folder first (time every stage)")
    p.add_argument("--baseline", default=None, help="a checkout of another version to bake first (before)")
    args = p.parse_args()
    out = Path(args.out) / "level" / args.preset
    before = None
    if args.baseline:
        before = run_baseline(Path(args.baseline), args)
    load_before = list(os.getloadavg())
    t0 = time.perf_counter()
    level, cfg = write_level(out / "level", settings_for(args.preset, args.seed), args.preset)
    t_gen = time.perf_counter() - t0
    if args.fresh and (out / "bake").exists():
        shutil.rmtree(out / "bake")
    settings = load_level_settings(cfg, args.set)
    info = bake_level(level, settings, out / "bake", progress=True)
    secs = stage_seconds(info)
    trace = next(s for s in info["stages"] if s["stage"] == "trace")
    method = sum(s["seconds"] for s in info["stages"] if s["stage"] not in CHECK_STAGES)
    result = {
        "preset": args.preset,
        "seed": args.seed,
        "overrides": args.set,
        "seconds_generate": t_gen,
        "seconds_total": info["seconds_total"],
        "seconds_method": method,
        "paper_total_s": PAPER_TOTAL,
        "ratio_total_vs_paper": info["seconds_total"] / PAPER_TOTAL,
        "stage_seconds": secs,
        "trace_mrays_per_s": trace["rays"] / trace["seconds"] / 1e6 if not trace["reused"] else None,
        "load_before": load_before,
        "load_after": list(os.getloadavg()),
        "cpu_count": os.cpu_count(),
        "paper_rows": [{"description": d, "seconds": s, "stages": k} for d, s, k in PAPER],
        "bake": info,
    }
    if result["trace_mrays_per_s"] is None:
        result["trace_mrays_per_s"] = float("nan")
    text = markdown(result)
    if before is not None:
        result["baseline"] = {"checkout": str(args.baseline), "result": before}
        text += "\n" + before_after(before, result)
    write_json(out / "bench_level.json", result)
    write_text(out / "bench_level.md", text)
    print(text)
    print(json.dumps(info["errors"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
