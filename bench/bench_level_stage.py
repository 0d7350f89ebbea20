"""Stages of a kept level bake run again from its stored inputs, here or on a loopback Ray cluster, then
the projection of the bake with those stages' fresh costs in place of the kept ones.

    .venv/bin/python bench/bench_level_stage.py --bake build/bench/level_cluster/world10x/bake_1 \
        --level build/bench/level_cluster/world10x/level/level.gltf --stage solve --keep trace

The kept bake's settings (its bake_log.json, with any ``--set`` overrides) are used, so the stored stages
named by ``--keep`` (their files under stages/) are reused and the bake runs up to the last of ``--stage``,
whose stages are made fresh and timed (local engine: its driver thread's CPU seconds, with Ray's cost to
submit each task added; with ``--nodes`` on a loopback Ray cluster: the driver's CPU seconds), and stops
there. What a change to a stage's code does to a bake too big to rerun whole (the 10x world's trace is 11
CPU-minutes) is measured this way, the stage's code before and after run on the same stored inputs. The
projection onto 1, 4, 32 and 128 machines of 16 cores (``bench_level_cluster.project``) then takes the kept
bake's log with these stages' rows and task seconds replaced; ``--bvh-scale`` multiplies the states' (BVH
builds') seconds, for a kept log measured before a change of the BVH build.

Writes OUT/STAGE[_STAGE...].json (each stage's row and task seconds, the projection).
"""

from __future__ import annotations

import argparse
import copy
import json
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_level_cluster import loopback_cluster, project  # noqa: E402
from bench_ray import SUBMIT_S, TRACING_STAGES  # noqa: E402

from neuralao.pipeline.bakes import level as level_bake  # noqa: E402
from neuralao.pipeline.bakes.level_settings import LevelBakeSettings  # noqa: E402
from neuralao.runtime.foundation.io import write_json  # noqa: E402
from neuralao.runtime.foundation.settings import apply_overrides, from_dict  # noqa: E402


class _Stop(Exception):
    pass


def run_stage(
    bake: Path, level: Path, stages: list[str], keep: list[str], out: Path, engine=None, overrides=()
) -> dict:
    """The bake ``bake``'s ``stages`` made fresh in ``out`` (the kept stages copied there first), here or
    on ``engine``, with the settings ``overrides`` (``key=value``) applied to the kept bake's; the bake stops
    after the last of them. Returns {stage: {row, task_seconds, task_waves}, "kept_log": the kept log}."""
    (out / "stages").mkdir(parents=True, exist_ok=True)
    for name in keep:
        for src in (bake / "stages").glob(f"{name}*"):
            dst = out / "stages" / src.name
            if not dst.exists():
                (shutil.copytree if src.is_dir() else shutil.copy)(src, dst)
    for stage in stages:
        (out / "stages" / f"{stage}.npz").unlink(missing_ok=True)
        shutil.rmtree(out / "stages" / stage, ignore_errors=True)
    log = json.loads((bake / "bake_log.json").read_text())
    settings = from_dict(LevelBakeSettings, apply_overrides(copy.deepcopy(log["settings"]), list(overrides)))
    found: dict = {}
    record, begin = level_bake.BakeLog._record, level_bake.BakeLog._begin

    def keep(self, name, *args, **kwargs):
        record(self, name, *args, **kwargs)
        print(json.dumps(self.stages[-1]), flush=True)
        if name in stages:  # the row itself: the counts the bake notes after it (the LOD's rounds) reach it
            found[name] = {
                "row": self.stages[-1],
                "task_seconds": self.task_seconds.get(name, []),
                "task_waves": self.task_waves.get(name, []),
                "task_aside": self.task_aside.get(name, []),
            }

    def stop_before_next(self):
        if len(found) == len(stages):
            raise _Stop
        begin(self)

    level_bake.BakeLog._record, level_bake.BakeLog._begin = keep, stop_before_next
    try:
        level_bake.bake_level(level, settings, out, engine=engine)
    except _Stop:
        pass
    finally:
        level_bake.BakeLog._record, level_bake.BakeLog._begin = record, begin
    missing = [s for s in stages if s not in found]
    if missing:
        raise SystemExit(f"the bake has no stage {missing[0]!r}")
    return found | {"kept_log": log}


def patched(log: dict, fresh: dict, bvh_scale: float, local: bool) -> dict:
    """``log`` (a Ray bake's) with each stage of ``fresh`` ({stage: run}) taking its driver and task
    seconds and waves from the run (a ``local`` run's driver seconds, with Ray's cost to submit each task
    added, stand for the Ray driver's CPU seconds; a cluster run's are them; a local bake's log and a local
    run: the stage's seconds and driver seconds, from which the projection takes the driver's) and the BVH
    states' seconds (the stages that trace) times ``bvh_scale``."""
    out = copy.deepcopy(log)
    kept_local = out.get("engine", "local") == "local"
    for stage, run in fresh.items():
        for row in out["stages"]:
            if row["stage"] == stage:
                submit = SUBMIT_S * len(run["task_seconds"]) if local else 0.0
                row["cpu_seconds"] = run["row"]["driver_seconds"] + submit
                if kept_local and local:  # a local log's driver is its stage's seconds less its tasks'
                    row["seconds"], row["driver_seconds"] = (
                        run["row"]["seconds"],
                        run["row"]["driver_seconds"],
                    )
                for k in ("simplify_tasks", "resample_tasks"):  # the LOD's rounds (bench_ray.traces)
                    if k in run["row"]:
                        row[k] = run["row"][k]
        out["task_seconds"][stage] = list(run["task_seconds"])
        out.setdefault("task_waves", {})[stage] = list(run["task_waves"])
        out.setdefault("task_aside", {})[stage] = list(run["task_aside"])
    out["state_seconds"] = {
        k: [x * (bvh_scale if k in TRACING_STAGES else 1.0) for x in v]
        for k, v in out.get("state_seconds", {}).items()
    }
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bake", required=True, help="a kept bake folder (bake_log.json and stages/)")
    p.add_argument("--level", required=True, help="the level it baked")
    p.add_argument("--stage", nargs="+", default=["solve"], help="the stages to make fresh")
    p.add_argument("--set", action="append", default=[], help="setting override, e.g. lod.tile_faces=65536")
    p.add_argument("--keep", nargs="+", default=["trace"], help="stored stages to reuse")
    p.add_argument("--bvh-scale", type=float, default=1.0)
    p.add_argument("--bvh-speedup", type=float, default=7.9, help="BVH build, 16 threads vs 1")
    p.add_argument("--out", default="build/bench/level_stage")
    p.add_argument(
        "--nodes",
        type=int,
        default=0,
        help="run on a loopback Ray cluster of N 1-CPU nodes (0: here)",
    )
    p.add_argument("--object-store-gib", type=float, default=1.0, help="each node's object store")
    args = p.parse_args()
    out = Path(args.out)
    where = (Path(args.bake), Path(args.level), args.stage, args.keep, out / "bake")
    if args.nodes:
        with loopback_cluster(args.nodes, 1, args.object_store_gib) as (engine, _, _):
            fresh = run_stage(*where, engine=engine, overrides=args.set)
    else:
        fresh = run_stage(*where, overrides=args.set)
    log = patched(fresh.pop("kept_log"), fresh, args.bvh_scale, local=not args.nodes)
    result = {
        "stages": args.stage,
        "overrides": args.set,
        "fresh": fresh,
        "bvh_scale": args.bvh_scale,
        "bvh_speedup": args.bvh_speedup,
    }
    result["projection"] = {
        "single": [{"machines": m, **project(log, m, 16)} for m in (1, 4, 32, 128)],
        "threads": [{"machines": m, **project(log, m, 16, 16, args.bvh_speedup)} for m in (1, 4, 32, 128)],
    }
    write_json(out / f"{'_'.join(args.stage)}.json", result)
    for stage, run in fresh.items():
        row = run["row"]
        print(
            f"{stage}: {row['seconds']:.1f} s, driver {row['driver_seconds']:.1f} s, "
            f"{len(run['task_seconds'])} tasks, largest {max(run['task_seconds'], default=0.0):.2f} s"
        )
    for kind, rows in result["projection"].items():
        totals = " / ".join(f"{r['total_s']:.1f}" for r in rows)
        print(
            f"projection, {kind} actors: {totals} s at 1/4/32/128 machines, "
            f"{rows[0]['total_s'] / rows[2]['total_s']:.2f}x at 32"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
