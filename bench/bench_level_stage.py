"""One stage of a kept level bake run again from its stored inputs, here or on a loopback Ray cluster, then
the projection of the bake with that stage's fresh costs in place of the kept ones.

    .venv/bin/python bench/bench_level_stage.py --bake build/bench/level_cluster/world10x/bake_1 \
        --level build/bench/level_cluster/world10x/level/level.gltf --stage solve --keep trace

The kept bake's settings (its bake_log.json) are used as they are, so the stored stages named by ``--keep``
(their files under stages/) are reused and the bake runs up to ``--stage``, which is made fresh and timed
(local engine: its driver seconds are its wall time less its tasks'; with ``--nodes`` on a loopback Ray
cluster: the driver's CPU seconds), and stops there. What a change to a
stage's code does to a bake too big to rerun whole (the 10x world's trace is 11 CPU-minutes) is measured
this way, the stage's code before and after run on the same stored inputs. The projection onto 1, 4, 32 and
128 machines of 16 cores (``bench_level_cluster.project``) then takes the kept bake's log with this stage's
row and task seconds replaced; ``--bvh-scale`` multiplies the states' (BVH builds') seconds, for a kept log
measured before a change of the BVH build.

Writes OUT/STAGE.json (the stage's row, its task seconds, the projection).
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
from bench_ray import TRACING_STAGES  # noqa: E402

from neuralao.pipeline.bakes import level as level_bake  # noqa: E402
from neuralao.pipeline.bakes.level_settings import LevelBakeSettings  # noqa: E402
from neuralao.runtime.foundation.io import write_json  # noqa: E402
from neuralao.runtime.foundation.settings import from_dict  # noqa: E402


class _Stop(Exception):
    pass


def run_stage(bake: Path, level: Path, stage: str, keep: list[str], out: Path, engine=None) -> dict:
    """The bake ``bake``'s stage ``stage`` made fresh in ``out`` (the kept stages copied there first), here
    or on ``engine``."""
    (out / "stages").mkdir(parents=True, exist_ok=True)
    for name in keep:
        for src in (bake / "stages").glob(f"{name}*"):
            dst = out / "stages" / src.name
            if not dst.exists():
                (shutil.copytree if src.is_dir() else shutil.copy)(src, dst)
    fresh = out / "stages" / f"{stage}.npz"
    fresh.unlink(missing_ok=True)
    shutil.rmtree(out / "stages" / stage, ignore_errors=True)
    log = json.loads((bake / "bake_log.json").read_text())
    settings = from_dict(LevelBakeSettings, log["settings"])
    found: dict = {}
    record = level_bake.BakeLog._record

    def stop_after(self, name, *args, **kwargs):
        record(self, name, *args, **kwargs)
        print(json.dumps(self.stages[-1]), flush=True)
        if name == stage:
            found.update(
                row=self.stages[-1],
                task_seconds=self.task_seconds.get(name, []),
                task_waves=self.task_waves.get(name, []),
            )
            raise _Stop

    level_bake.BakeLog._record = stop_after
    try:
        level_bake.bake_level(level, settings, out, engine=engine)
    except _Stop:
        pass
    finally:
        level_bake.BakeLog._record = record
    if not found:
        raise SystemExit(f"the bake has no stage {stage!r}")
    return found | {"kept_log": log}


def patched(log: dict, stage: str, fresh: dict, bvh_scale: float) -> dict:
    """``log`` (a Ray bake's) with ``stage``'s driver and task seconds and waves from ``fresh`` (a local
    run's driver seconds stand for the Ray driver's CPU seconds; a cluster run's are them) and the BVH
    states' seconds (the stages that trace) times ``bvh_scale``."""
    out = copy.deepcopy(log)
    for row in out["stages"]:
        if row["stage"] == stage:
            row["cpu_seconds"] = fresh["row"]["driver_seconds"]
    out["task_seconds"][stage] = list(fresh["task_seconds"])
    out.setdefault("task_waves", {})[stage] = list(fresh["task_waves"])
    out["state_seconds"] = {
        k: [x * (bvh_scale if k in TRACING_STAGES else 1.0) for x in v]
        for k, v in out.get("state_seconds", {}).items()
    }
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bake", required=True, help="a kept bake folder (bake_log.json and stages/)")
    p.add_argument("--level", required=True, help="the level it baked")
    p.add_argument("--stage", default="solve")
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
    args = p.parse_args()
    out = Path(args.out)
    where = (Path(args.bake), Path(args.level), args.stage, args.keep, out / "bake")
    if args.nodes:
        with loopback_cluster(args.nodes, 1) as (engine, _, _):
            fresh = run_stage(*where, engine=engine)
    else:
        fresh = run_stage(*where)
    log = patched(fresh.pop("kept_log"), args.stage, fresh, args.bvh_scale)
    result = {
        "stage": args.stage,
        "fresh": fresh,
        "bvh_scale": args.bvh_scale,
        "bvh_speedup": args.bvh_speedup,
    }
    result["projection"] = {
        "single": [{"machines": m, **project(log, m, 16)} for m in (1, 4, 32, 128)],
        "threads": [{"machines": m, **project(log, m, 16, 16, args.bvh_speedup)} for m in (1, 4, 32, 128)],
    }
    write_json(out / f"{args.stage}.json", result)
    row = fresh["row"]
    print(
        f"{args.stage}: {row['seconds']:.1f} s, driver {row['driver_seconds']:.1f} s, "
        f"{len(fresh['task_seconds'])} tasks, largest {max(fresh['task_seconds'], default=0.0):.2f} s"
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
