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
ray on one core. The projection of a level bake on N machines of C cores reads a level bake's log
(``--level-json``: bench/bench_level.py's bench_level.json, or any bake_log.json), whose every stage
records its wall time and each of its tasks' seconds and waves (the engine's map calls, one after the
other): per stage, the driver's own seconds plus, wave after wave, the makespan of the wave's tasks
scheduled longest first on N C cores (one task per core, at the measured Ray / local efficiency and
per-task round trip); the trace's blocks divide (``trace.block_samples`` is sized to the cores), the
other stages' tasks do not (the largest piece's solve and LOD bound them); every machine builds its
BVHs once, in parallel.

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

from neuralao.pipeline.bakes.vertex import BakeSettings, bake  # noqa: E402
from neuralao.pipeline.datasets.dataset import DatasetSettings, build_dataset  # noqa: E402
from neuralao.pipeline.engines.engine import Context, LocalEngine, RayEngine, Task, content_key  # noqa: E402
from neuralao.pipeline.geometry.scene import load_scene  # noqa: E402
from neuralao.pipeline.tracing.engine_labeller import labeller_context  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402

# Tasks per core in the projection: enough that the last round of tasks balances (block size follows).
TASKS_PER_CORE = 4
# Measured on a private Ray instance on this machine (2 single-CPU actors, no-op tasks:
# ``bench_ray.py --driver-only``, :func:`driver_costs`): a wave's round trip (a one-task map: 1.4 ms of wall
# clock in the latest run; 1.9 ms kept, a network round trip across machines being of that order) and the
# driver's CPU seconds per task it submits and takes the result of, in maps of 2,000 (a Ray bake's log has
# them in its driver's CPU seconds, a local bake's does not): 0.69 ms with each task's call as six
# arguments, 0.58 ms as one tuple (back to back, 2026-12-06, AMD EPYC, 2 cores; 0.8 ms in an older run).
WAVE_S = 1.9e-3
SUBMIT_S = 0.58e-3
# The CPU an idle Ray driver spends, a fraction of the wall clock (its process's Ray threads; the same
# measurement, 20 s of sleep): 0.36% and 0.44% in two runs. What a Ray bake's driver seconds hold beyond
# its own work, in proportion to a stage's length (bench_level_cluster.ray_driver_seconds).
IDLE_CPU = 0.004


def _noop_state(payload):
    return payload


def _noop(state, args):
    return args


def timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def dataset_settings(rays: int, views: int) -> DatasetSettings:
    from neuralao.runtime.foundation.settings import from_dict

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
    from neuralao.pipeline.bakes.level import bake_level
    from neuralao.pipeline.bakes.level_settings import load_level_settings
    from neuralao.pipeline.geometry.level_gen import settings_for, write_level

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


# Stages whose tasks trace (their seconds were taken with the bake's tracing threads); the others' tasks
# (the solve, the output) run on one thread, and so do the LOD's tasks but its resampling (:func:`traces`).
TRACING_STAGES = ("trace", "decorators", "small_decorators", "lod", "blend_check")
# Stages that only produce the error tables (a production bake leaves them out: ``error_tables`` false).
CHECK_STAGES = ("blend_check", "lod_check")


def driver_costs(engine, tasks: int = 2000, waves: int = 50, idle_s: float = 20.0) -> dict:
    """The driver's CPU seconds per task of a map of ``tasks`` no-op tasks on ``engine`` (what it costs to
    submit one and take its result) and the wall seconds of a one-task map (a wave's round trip), best of
    three each; and the CPU it spends idle for ``idle_s`` seconds, a fraction of the wall clock."""
    import operator

    from neuralao.pipeline.engines.engine import no_state

    ctx = Context("noop-driver", no_state, None)
    list(engine.map([Task(ctx, operator.is_, 0)]))  # the context on the workers
    submit, wave = [], []
    for _ in range(3):
        c0 = time.process_time()
        list(engine.map(Task(ctx, operator.is_, i) for i in range(tasks)))
        submit.append((time.process_time() - c0) / tasks)
        t0 = time.perf_counter()
        for i in range(waves):
            list(engine.map([Task(ctx, operator.is_, i)]))
        wave.append((time.perf_counter() - t0) / waves)
    c0, t0 = time.process_time(), time.perf_counter()
    time.sleep(idle_s)
    idle = (time.process_time() - c0) / (time.perf_counter() - t0)
    return {
        "submit_cpu_s": min(submit),
        "wave_s": min(wave),
        "idle_cpu": idle,
        "tasks": tasks,
        "workers": engine.workers,
    }


def traces(info: dict, stage: dict, count: int) -> list[bool]:
    """Which of a stage's ``count`` tasks (in the bake log's order) trace. The LOD's run in three rounds:
    its simplifications, then its resampling (the rays), then per piece its least squares and held-out
    points (the log's ``simplify_tasks`` and ``resample_tasks``; a log without the latter: all but the
    pieces')."""
    name = stage["stage"]
    if name not in TRACING_STAGES:
        return [False] * count
    if name != "lod":
        return [True] * count
    first = int(stage.get("simplify_tasks", 1))
    pieces = int(info.get("counts", {}).get("pieces", 0))
    resample = int(stage.get("resample_tasks", max(0, count - first - pieces)))
    return [first <= i < first + resample for i in range(count)]


def stage_costs(info: dict, checks: bool = False) -> list[dict]:
    """Per stage of a level bake log (bake_log.json; ``bench_level.json``'s ``bake``): the driver's own
    seconds (a local bake: the stage's wall time less its tasks', which ran in the driver, or, with several
    tasks at once beside it, less the time it waited for them; a Ray bake: the driver's CPU seconds) and
    each task's core-seconds (its seconds x the threads it traced with, for the tasks that trace:
    :func:`traces`), and whether it traces ("traces"), and the states workers build (the opaque BVH: the
    ``bvh`` stage of a local bake, the trace's first tasks' on Ray; the gold BVH: ``seconds_gold_state`` of
    the decorators, their first tasks' on Ray): "state_s", the slowest built by the stage's tasks, and
    "prepared_s", the slowest built ahead (``Engine.prepare``: a ``prepare_*`` row of the log names the
    stage it prepares for, "prepared_at" its place), with "waited_s", what the stage's tasks still waited
    for it (a local bake builds its BVHs itself, so its log's prepared states are where a cluster's would
    be: what they waited for is not measured). "position" is each stage's place in the log. The stages
    that only make error tables are left out unless ``checks`` (a run's own wall clock has them)."""
    threads = int(info.get("task_threads", info["settings"].get("workers", 1)))
    tasks = info.get("task_seconds", {})
    local = info.get("engine", "local") == "local"
    stages = info["stages"]
    ahead = {st["prepares"]: i for i, st in enumerate(stages) if "prepares" in st}
    rows = []
    for position, st in enumerate(stages):
        name = st["stage"]
        if name in CHECK_STAGES and not checks:
            continue
        t = list(tasks.get(name, []))
        # another stage's tasks run in this one's wave (the solve's plans beside the trace) trace nothing
        aside = set(info.get("task_aside", {}).get(name, []))
        traced = [tr and i not in aside for i, tr in enumerate(traces(info, st, len(t)))]
        cores = [x * (threads if tr else 1) for x, tr in zip(t, traced, strict=True)]
        state = prepared = waited = 0.0
        at = ahead.get("trace" if name == "bvh" else name)
        if name == "bvh":  # a local bake builds the opaque BVH here; every worker builds its own
            state, driver = st["seconds"], 0.0
        elif local and int(info.get("tasks_at_once", 1)) > 1:  # the tasks ran beside the driver
            state = float(st.get("seconds_gold_state", 0.0))
            driver = max(0.0, float(st["driver_seconds"]) - state)
        elif local:  # the tasks ran in the driver, one after the other
            state = float(st.get("seconds_gold_state", 0.0))
            driver = max(0.0, st["seconds"] - sum(t) - state)
        else:  # on an engine the driver waits for the tasks: its own work is its CPU time
            driver = st["cpu_seconds"]
            built = info.get("state_seconds", {}).get(name, [])
            flags = info.get("state_prepared", {}).get(name, [False] * len(built))
            waits = info.get("state_waits", {}).get(name, built)
            state = max([x for x, p in zip(built, flags, strict=True) if not p], default=0.0)
            prepared = max([x for x, p in zip(built, flags, strict=True) if p], default=0.0)
            waited = max([w for w, p in zip(waits, flags, strict=True) if p], default=0.0)
            at = at if prepared else None
        if local and at is not None:  # built here, prepared on a cluster's workers
            state, prepared = 0.0, state
        if local:  # on Ray the driver would also submit every task
            driver += SUBMIT_S * len(t)
        waves = list(info.get("task_waves", {}).get(name, [0] * len(t)))  # a log without them: one wave
        rows.append(
            {
                "stage": name,
                "position": position,
                "driver_s": driver,
                "task_core_s": cores,
                "waves": waves,
                "traces": traced,
                "state_s": state,
                "prepared_s": prepared,
                "prepared_at": at if prepared else None,
                "waited_s": waited,
            }
        )
    return rows


def wave_spans(
    work: list[float], waves: list[int], slots: int, divides: bool, traced: list[bool] | None = None
) -> list[tuple[float, bool]]:
    """Seconds of each wave of a stage's tasks ``work`` (seconds each) on ``slots`` task slots, and whether
    any of its tasks ``traced``: a wave is one of the engine's map calls, and the driver starts the next
    once it has this one's results (the partitioned solve's CG: one wave per iteration). Each wave takes
    the makespan of its tasks scheduled longest first, or, if its work ``divides`` (the trace's blocks,
    sized to the cores), its work over the slots, but no less than the makespan of its tasks that do not
    trace (another stage's, run beside the blocks: they do not divide); and a round trip
    (:data:`WAVE_S`)."""
    traced = traced if traced is not None else [divides] * len(work)
    groups: dict[int, list[tuple[float, bool]]] = {}
    for w, x, tr in zip(waves, work, traced, strict=True):
        groups.setdefault(w, []).append((x, tr))
    spans = []
    for _, g in sorted(groups.items()):
        if divides:
            whole = makespan([x for x, tr in g if not tr], slots)
            span = max(sum(x for x, _ in g) / slots, whole)
        else:
            span = makespan([x for x, _ in g], slots)
        spans.append((span + WAVE_S, any(tr for _, tr in g)))
    return spans


def wave_span(
    work: list[float], waves: list[int], slots: int, divides: bool, traced: list[bool] | None = None
) -> float:
    """The seconds of a stage's tasks, wave after wave (:func:`wave_spans`)."""
    return sum(span for span, _ in wave_spans(work, waves, slots, divides, traced))


def makespan(durations: list[float], cores: int) -> float:
    """Longest-processing-time list scheduling of independent tasks on ``cores`` cores."""
    import heapq

    if not durations:
        return 0.0
    load = [0.0] * min(cores, len(durations))
    heapq.heapify(load)
    for d in sorted(durations, reverse=True):
        heapq.heapreplace(load, load[0] + d)
    return max(load)


def projection(result: dict, level_json: Path | None, cores: int, machines: list[int]) -> dict:
    """A level bake on N machines x C cores from its measured per-stage costs (:func:`stage_costs`): per
    stage, the driver's own seconds plus the makespan of its tasks on N C cores (one task per core at the
    measured Ray / local efficiency e and per-task round trip); the trace's blocks are resized to the
    cores (its work divides: total core-seconds / (N C)); states are built once per machine, in parallel."""
    efficiency = next(
        r["ray_over_local"] for r in result["rows"] if r["workload"] == "level" and r["workers"] == 2
    )
    t_task = result["t_task_s"]
    if level_json is None or not level_json.is_file():
        return {"rows": [], "source": f"no level bake log at {level_json}"}
    data = json.loads(level_json.read_text())
    info = data.get("bake", data.get("bake_log", data))  # bench_level.json, bench_world.json or a bake log
    if info.get("engine") == "ray":  # its tasks were timed on Ray actors already
        efficiency = 1.0
    costs = stage_costs(info)
    rows = []
    for n in machines:
        p = n * cores
        per_stage = {}
        for c in costs:
            work = [x / efficiency for x in c["task_core_s"]]
            span = wave_span(work, c["waves"], p, c["stage"] == "trace", c["traces"])
            if work:  # each core's share of the tasks' round trips (the trace's blocks: a few per core)
                span += t_task * (TASKS_PER_CORE if c["stage"] == "trace" else len(work) / p)
            # single-CPU actors: a state built ahead shares its actor's one core, so all of it is counted
            per_stage[c["stage"]] = c["driver_s"] + max(c["state_s"], c["prepared_s"]) + span
        rows.append({"machines": n, "cores": p, "stages": per_stage, "total_s": sum(per_stage.values())})
    base = rows[0]["total_s"]
    for r in rows:
        r["speedup"] = base / r["total_s"]
    largest = {c["stage"]: max(c["task_core_s"], default=0.0) / efficiency for c in costs}
    return {
        "source": str(level_json),
        "level_counts": info.get("counts", {}),
        "engine": info.get("engine", "local"),
        "efficiency": efficiency,
        "t_task_s": t_task,
        "cores_per_machine": cores,
        "driver_s": sum(c["driver_s"] for c in costs),
        "state_s": sum(max(c["state_s"], c["prepared_s"]) for c in costs),
        "largest_task_s": largest,
        "rows": rows,
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
        "## Projection: the level bake on N machines",
        "",
    ]
    if not proj["rows"]:
        return "\n".join(lines + [proj["source"]]) + "\n"
    c = proj["level_counts"]
    stages = list(proj["rows"][0]["stages"])
    lines += [
        f"From the measured per-stage costs of {proj['source']} "
        f"({c.get('receiver_faces', 0):,} faces, {c.get('samples', 0):,} samples; "
        f"a {proj['engine']} bake): each stage's driver seconds, plus its tasks scheduled longest "
        f"first on N x {proj['cores_per_machine']} cores at Ray's measured efficiency "
        f"e = {proj['efficiency']:.2f} and {proj['t_task_s'] * 1e3:.1f} ms a task; the trace's "
        "blocks resized to the cores; every machine builds its BVHs once, in parallel. "
        f"Driver seconds in all: {proj['driver_s']:.1f}; BVH builds: {proj['state_s']:.1f}. "
        "Longest single task per stage (s): "
        + ", ".join(f"{k} {v:.1f}" for k, v in proj["largest_task_s"].items() if v > 0)
        + ".",
        "",
        "| machines | cores | " + " | ".join(stages) + " | total s | speed-up vs 1 |",
        "|---:|---:|" + "---:|" * len(stages) + "---:|---:|",
    ]
    for r in proj["rows"]:
        cells = " | ".join(f"{r['stages'][k]:.1f}" for k in stages)
        lines.append(
            f"| {r['machines']} | {r['cores']} | {cells} | **{r['total_s']:.1f}** | {r['speedup']:.1f}x |"
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
    p.add_argument(
        "--driver-only",
        action="store_true",
        help="only the driver's costs per task and per wave on 2 actors (OUT/ray_driver.json)",
    )
    args = p.parse_args()
    out = Path(args.out)
    if args.driver_only:
        engine = RayEngine(None, workers=2)
        engine.worker_info()
        costs = driver_costs(engine)
        engine.close()
        write_json(out / "ray_driver.json", costs)
        print(
            f"driver CPU a task {costs['submit_cpu_s'] * 1e3:.3f} ms (maps of {costs['tasks']:,}), "
            f"a one-task map {costs['wave_s'] * 1e3:.2f} ms, idle {100 * costs['idle_cpu']:.2f}% of a CPU"
        )
        return
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
