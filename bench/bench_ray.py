"""Ray's overhead at equal cores, and a projection of the level bake (Table 1) on N machines.

    .venv/bin/python bench/bench_ray.py --out build/bench

Throughput of the same work on the local engine (threads in one process) and on Ray (a private
Ray instance on this machine, one actor per worker), with 1 and 2 workers, best of ``--repeats``
interleaved rounds, as ratios to the local engine at the same worker count (goal: >= 0.9):

* **bake**: `neuralao bake` least-squares on a mesh (sample chunks as tasks), samples per second;
* **dataset**: `neuralao dataset` on a small config (one shard per task: G-buffer + labels), frames
  per second;
* **level trace**: the level baker's trace stage on the tiny generated level (blocks as tasks).

Per-task costs measured on the same instance: the round trip of an empty task, the first task of a
new context (payload through the object store + Embree build on the worker) and the trace cost per
ray on one core. The projection for Table 1 of Sloan et al. 2013 (6.7 M samples x 256 rays) on N
machines of C cores, with ``tasks = TASKS_PER_CORE * N * C`` blocks (trace.block_samples chosen to
match; the default 262,144 would make 26 tasks and leave cores idle beyond 26):
``T(N) = serial + ceil(tasks / (N C)) * block * rays * c_ray / e + tasks * t_task / (N C) + t_ctx
+ max(task stages / (N C e), largest task)`` (driver stages serial; the stages that run as tasks,
decorators, grass and shrubs, LOD resampling and the solve's blocks, spread over the cores but not
below the largest solve block; ``e`` the measured Ray / local ratio of the level trace; ``t_ctx``
the first-task cost scaled by faces, paid once per actor, in parallel on every machine), using a
bench_level.json of bench/bench_level.py for the serial stages when one exists.

Writes OUT/bench_ray.json and OUT/bench_ray.md. The machine's load average is recorded before and
after: on a shared machine absolute numbers move, ratios within one run still compare.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from pipeline.bakes.vertex import BakeSettings, bake  # noqa: E402
from pipeline.datasets.dataset import DatasetSettings, build_dataset  # noqa: E402
from pipeline.engines.engine import Context, LocalEngine, RayEngine, Task, content_key  # noqa: E402
from pipeline.foundation.io import write_json, write_text  # noqa: E402
from pipeline.geometry.scene import load_scene  # noqa: E402
from pipeline.tracing.engine_labeller import labeller_context  # noqa: E402

# Table 1 of Sloan et al. 2013: the trace row's workload (6.7 M samples, 256 rays a sample, 1.8 M faces).
TABLE1_SAMPLES = 6_700_000
TABLE1_RAYS = 256
TABLE1_FACES = 1_800_000
# Tasks per core in the projection: enough that the last round of tasks balances (block size follows).
TASKS_PER_CORE = 4


def _noop_state(payload):
    return payload


def _noop(state, args):
    return args


def timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def dataset_settings(rays: int, views: int) -> DatasetSettings:
    from pipeline.foundation.settings import from_dict

    return from_dict(
        DatasetSettings,
        {
            "name": "bench-ray",
            "seed": 1,
            "size": [128, 128],
            "frames_per_shard": 1,
            "labels": {"rays": rays},
            "scenes": [
                {"name": "spot", "mesh": "spot", "views": views},
                {"name": "bunny", "mesh": "bunny", "views": views},
            ],
        },
    )


def measure(args) -> dict:
    import ray

    scene = load_scene(args.mesh)
    bake_s = BakeSettings(rays=args.rays, samples_per_vertex=args.samples_per_vertex)
    ds = dataset_settings(args.dataset_rays, args.views)
    from pipeline.bakes.level import bake_level
    from pipeline.bakes.level_settings import load_level_settings
    from pipeline.geometry.level_gen import settings_for, write_level

    tmp = Path(tempfile.mkdtemp(prefix="bench_ray_"))
    level, cfg = write_level(tmp / "level", settings_for("tiny", seed=2), "tiny")
    level_s = load_level_settings(
        cfg,
        [
            f"trace.rays={args.rays}",
            f"trace.block_samples={args.level_block}",
            "trace.samples_per_vertex=16",
            "trace.samples_per_face_cap=64",
        ],
    )
    reference: dict = {}
    runs: dict[str, list[float]] = {}
    samples = frames = level_samples = 0

    def run_bake(engine, k):
        nonlocal samples
        r = bake(scene, replace(bake_s, workers=k), engine=engine)
        samples = r.info["samples"]
        reference.setdefault("bake", r.ao)
        assert np.array_equal(r.ao, reference["bake"]), "bake differs between engines"

    def run_dataset(engine, k):
        nonlocal frames
        out = Path(tempfile.mkdtemp(dir=tmp))
        m = build_dataset(
            replace(ds, labels=replace(ds.labels, workers=k)),
            out,
            progress=False,
            engine=engine or LocalEngine(),
        )
        frames = m["frames"]
        reference.setdefault("dataset", m["dataset_hash"])
        assert m["dataset_hash"] == reference["dataset"], "dataset differs between engines"

    def run_level(engine, k):
        nonlocal level_samples
        out = Path(tempfile.mkdtemp(dir=tmp))
        info = bake_level(level, replace(level_s, workers=k), out, engine=engine)
        level_samples = info["counts"]["samples"]
        glb = (out / level_s.output).read_bytes()
        reference.setdefault("level", glb)
        assert glb == reference["level"], "level bake differs between engines"
        return next(s["seconds"] for s in info["stages"] if s["stage"] == "trace")

    load_before = list(os.getloadavg())
    t_start_ray = timed(lambda: RayEngine(None, workers=1).close())  # starts the private instance
    for _ in range(args.repeats):
        for k in (1, 2):
            ray_engine = RayEngine(None, workers=k)  # the instance has 2 CPUs: one engine at a time
            ray_engine.worker_info()  # actors up (process start is not per-task cost; see seconds_start_ray)
            for name, fn in (("bake", run_bake), ("dataset", run_dataset)):
                runs.setdefault(f"{name}/local/{k}", []).append(timed(lambda fn=fn, k=k: fn(None, k)))
                ray_run = lambda fn=fn, k=k, e=ray_engine: fn(e, k)  # noqa: E731
                runs.setdefault(f"{name}/ray/{k}", []).append(timed(ray_run))
                # Again on the same actors: their processes, GL contexts and scene states already exist.
                runs.setdefault(f"{name}/warm/{k}", []).append(timed(ray_run))
            # The level row times its trace stage only (the other stages run on the driver either way).
            runs.setdefault(f"level/local/{k}", []).append(run_level(None, k))
            runs.setdefault(f"level/ray/{k}", []).append(run_level(ray_engine, k))
            ray_engine.close()
    # Per-task costs on one actor.
    one = RayEngine(None, workers=1)
    one.worker_info()
    ctx = Context("noop", _noop_state, None)
    list(one.map([Task(ctx, _noop, 0)]))  # warm
    n_noop = 200
    t_task = timed(lambda: list(one.map(Task(ctx, _noop, i) for i in range(n_noop)))) / n_noop
    lab_ctx = labeller_context(scene, bake_s.label_settings(), 1)
    fresh = Context(content_key("bench", time.time()), lab_ctx.build, lab_ctx.payload)
    t_ctx = timed(lambda: list(one.map([Task(fresh, _noop, 0)]))) - t_task
    payload_bytes = scene.vertices.nbytes + scene.faces.nbytes
    faces = len(scene.faces)
    one.close()
    ray.shutdown()
    load_after = list(os.getloadavg())
    best = {key: min(v) for key, v in runs.items()}
    work = {"bake": samples, "dataset": frames, "level": level_samples}
    rows = []
    for name in ("bake", "dataset", "level"):
        for k in (1, 2):
            local, remote = best[f"{name}/local/{k}"], best[f"{name}/ray/{k}"]
            warm = best.get(f"{name}/warm/{k}")
            rows.append(
                {
                    "workload": name,
                    "workers": k,
                    "local_s": local,
                    "ray_s": remote,
                    "local_per_s": work[name] / local,
                    "ray_per_s": work[name] / remote,
                    "ray_over_local": local / remote,
                    "warm_s": warm,
                    "warm_over_local": local / warm if warm else None,
                }
            )
    # Cost of one ray on one core, from the local 1-worker bake (sampling and solve included: upper bound).
    c_ray = best["bake/local/1"] / (samples * args.rays)
    c_ray_level = best["level/local/1"] / (level_samples * args.rays)
    return {
        "mesh": args.mesh,
        "rays": args.rays,
        "samples_per_vertex": args.samples_per_vertex,
        "dataset": {"scenes": 2, "views": args.views, "size": [128, 128], "rays": args.dataset_rays},
        "repeats": args.repeats,
        "runs": runs,
        "rows": rows,
        "work": work,
        "seconds_start_ray": t_start_ray,
        "t_task_s": t_task,
        "t_context_s": t_ctx,
        "payload_bytes": payload_bytes,
        "faces": faces,
        "c_ray_bake_s": c_ray,
        "c_ray_level_s": c_ray_level,
        "load_average_before": load_before,
        "load_average_after": load_after,
        "cpu_count": os.cpu_count(),
    }


# Stages (bench_level.json stage rows, or "stage:part" notes) whose work runs as engine tasks: their measured
# seconds on this machine's 2 tracing threads spread over the cluster's cores.
TASK_STAGES = ("decorators", "small_decorators", "lod:resample", "solve:blocks")


def split_stages(stages: list[dict]) -> tuple[float, float, float, str]:
    """(serial s, task-stage s (core-seconds at 2 threads), largest single task s, description) of a
    level bake's stage rows; every production stage but the trace. A bake log from before the stages
    became tasks (no solve:blocks note) counts all of them as serial."""
    secs = {st["stage"]: st["seconds"] for st in stages}
    for st in stages:
        secs.update({f"{st['stage']}:{k[8:]}": v for k, v in st.items() if k.startswith("seconds_")})
    production = sum(v for k, v in secs.items() if ":" not in k and k not in ("trace", "blend_check"))
    if "solve:blocks" not in secs:
        return production, 0.0, 0.0, "every production stage but the trace, on the driver"
    # The tasks ran on the driver's 2 threads (local bake): core-seconds = 2 x wall for the traced ones.
    parallel = sum(secs.get(k, 0.0) for k in TASK_STAGES if k != "solve:blocks") * 2 + secs["solve:blocks"]
    serial = production - sum(secs.get(k, 0.0) for k in TASK_STAGES)
    return (
        serial,
        parallel,
        secs.get("solve:largest_block", 0.0),
        ("driver stages serial; decorators, grass/shrubs, LOD resampling and solve blocks as tasks"),
    )


def projection(result: dict, level_json: Path | None, cores: int, machines: list[int]) -> dict:
    """Table 1's trace (and serial stages when a bench_level.json exists) on N machines x C cores."""
    import math

    rays = TABLE1_SAMPLES * TABLE1_RAYS
    efficiency = next(
        r["ray_over_local"] for r in result["rows"] if r["workload"] == "level" and r["workers"] == 2
    )
    c_ray = result["c_ray_level_s"]
    t_ctx = result["t_context_s"] * TABLE1_FACES / result["faces"]  # BVH build ~ linear in faces: upper bound
    serial, parallel, largest, source = 0.0, 0.0, 0.0, "not measured (no bench_level.json): trace stage only"
    if level_json is not None and level_json.is_file():
        data = json.loads(level_json.read_text())
        serial, parallel, largest, source = split_stages(
            data.get("bake", data.get("info", {})).get("stages", [])
        )
        source = f"{level_json} ({source}, on this machine)"
    rows = []
    for n in machines:
        tasks = TASKS_PER_CORE * n * cores
        block = math.ceil(TABLE1_SAMPLES / tasks)
        trace_s = math.ceil(tasks / (n * cores)) * block * TABLE1_RAYS * c_ray / efficiency
        overhead = tasks * result["t_task_s"] / (n * cores) + t_ctx
        # Task stages spread over every core, but never below their largest single task (the solve's
        # biggest connected component).
        spread = max(parallel / (n * cores) / efficiency, largest)
        rows.append(
            {
                "machines": n,
                "cores": n * cores,
                "tasks": tasks,
                "block_samples": block,
                "trace_s": trace_s,
                "overhead_s": overhead,
                "serial_s": serial,
                "task_stages_s": spread,
                "total_s": serial + spread + trace_s + overhead,
            }
        )
    return {
        "rays": rays,
        "c_ray_s": c_ray,
        "efficiency": efficiency,
        "t_context_table1_s": t_ctx,
        "cores_per_machine": cores,
        "serial_source": source,
        "rows": rows,
        "paper_trace_s": 35.1,
    }


def markdown(result: dict, proj: dict) -> str:
    lines = [
        "# Ray vs local engine at equal cores",
        "",
        f"load average before {result['load_average_before']}, after {result['load_average_after']} "
        f"({result['cpu_count']} CPUs; "
        + (
            "a background job shared them: compare ratios, not seconds). "
            if result["load_average_before"][0] > 0.5 * result["cpu_count"]
            else "idle before the run). "
        )
        + f"Best of {result['repeats']} interleaved rounds. Ray: fresh actors per round (process start "
        "excluded, their imports, GL context and scene states included, as in one CLI run); Ray warm: "
        "the same work again on those actors.",
        "",
        "| workload | workers | local s | Ray s | local /s | Ray /s | Ray / local | Ray warm s | "
        "warm / local |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    unit = {"bake": "samples", "dataset": "frames", "level": "samples (trace stage)"}
    for r in result["rows"]:
        lines.append(
            f"| {r['workload']} ({unit[r['workload']]}) | {r['workers']} | "
            f"{r['local_s']:.2f} | {r['ray_s']:.2f} | {r['local_per_s']:,.0f} | "
            f"{r['ray_per_s']:,.0f} | **{r['ray_over_local']:.2f}** | "
            + (f"{r['warm_s']:.2f} | **{r['warm_over_local']:.2f}** |" if r.get("warm_s") else "- | - |")
        )
    lines += [
        "",
        f"Per task: empty round trip {result['t_task_s'] * 1e3:.2f} ms; "
        f"first task of a new context ({result['payload_bytes'] / 1e6:.1f} MB mesh: "
        f"object store + Embree build) {result['t_context_s'] * 1e3:.0f} ms; "
        f"trace {result['c_ray_level_s'] * 1e9:.0f} ns per ray per core (level), "
        f"{result['c_ray_bake_s'] * 1e9:.0f} ns (bake, sampling and solve included). "
        f"Starting the private Ray instance: {result['seconds_start_ray']:.1f} s (not in the rows).",
        "",
        f"## Projection: Table 1 trace ({TABLE1_SAMPLES / 1e6:.1f} M samples x {TABLE1_RAYS} rays = "
        f"{proj['rays'] / 1e9:.2f} G rays) on N machines x {proj['cores_per_machine']} cores, "
        f"{TASKS_PER_CORE} trace blocks per core",
        "",
        f"Efficiency e = {proj['efficiency']:.2f} (level trace, Ray / local at 2 workers); "
        f"serial stages: {proj['serial_source']}; per-ray cost {proj['c_ray_s'] * 1e9:.0f} ns per core as "
        f"measured here; first-task cost scaled to 1.8 M faces {proj['t_context_table1_s']:.1f} s. "
        f"The paper's trace row: {proj['paper_trace_s']} s on one K20.",
        "",
        "| machines | cores | tasks | samples / task | trace s | Ray overhead s | driver s | "
        "task stages s | total s |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in proj["rows"]:
        lines.append(
            f"| {r['machines']} | {r['cores']} | {r['tasks']} | {r['block_samples']:,} | "
            f"{r['trace_s']:.1f} | {r['overhead_s']:.2f} | {r['serial_s']:.1f} | "
            f"{r['task_stages_s']:.1f} | {r['total_s']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="build/bench")
    p.add_argument("--mesh", default="bunny")
    p.add_argument("--rays", type=int, default=128)
    p.add_argument("--samples-per-vertex", type=float, default=4.0)
    p.add_argument("--dataset-rays", type=int, default=64)
    p.add_argument("--views", type=int, default=8)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--level-block", type=int, default=2048, help="samples per level trace task")
    p.add_argument("--cores-per-machine", type=int, default=16)
    p.add_argument("--level-json", default="build/bench/level/table1/bench_level.json")
    p.add_argument(
        "--project-only", action="store_true", help="recompute the projection from OUT/bench_ray.json"
    )
    args = p.parse_args()
    out = Path(args.out)
    result = json.loads((out / "bench_ray.json").read_text()) if args.project_only else measure(args)
    proj = projection(
        result,
        Path(args.level_json) if args.level_json else None,
        args.cores_per_machine,
        [1, 2, 4, 8, 16, 32],
    )
    result["projection"] = proj
    write_json(out / "bench_ray.json", result)
    text = markdown(result, proj)
    write_text(out / "bench_ray.md", text)
    print(text)


if __name__ == "__main__":
    main()
