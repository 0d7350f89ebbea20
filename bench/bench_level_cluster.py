"""A level bake on a loopback Ray cluster of 1, 2 and 4 nodes, beside the projection from the same runs.

    .venv/bin/python bench/bench_level_cluster.py --set trace.rays=32 --set lod.max_error=1e-4   # Table 1
    .venv/bin/python bench/bench_level_cluster.py --preset small --nodes 1 2                       # quick
    .venv/bin/python bench/bench_level_cluster.py --project-only                                   # redo

Each cluster is real Ray nodes on 127.0.0.1 (``ray.cluster_utils.Cluster``: a head and N - 1 more raylets,
each its own processes with ``--cpus-per-node`` CPUs and its own object store), this process its driver,
one single-CPU actor per CPU. The same level is baked fresh on each (``bake_level(..., engine=RayEngine)``,
what ``neuralao bake --engine ray --address`` runs), and every run's bake log (its tasks' own seconds,
timed on the actors, and the driver's seconds per stage) gives the projection of the same run on N
machines of the same CPUs (:func:`project`), so the measured wall clock checks the model. The bakes are
checked byte-identical to each other. Then the model's projection of the 1-node run onto 1, 4, 32 and 128
machines of 16 cores, per stage, for two deployments: single-CPU actors (16 per machine: every actor builds
its own BVH, on its one core) and ``--ray-threads 16`` (one actor per machine: one BVH, built with the
machine's threads, but the tasks that do not trace run one at a time per machine), the second also with
each BVH built by its stage's first task, as without ``Engine.prepare`` (:func:`project` says what a BVH
built ahead costs).

Writes OUT/level_cluster/PRESET/bench_cluster.json and .md. On a machine with fewer cores than the cluster
has CPUs, the nodes share them (the table says so): the wall clock then measures Ray's scheduling and
transfers, not speed.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import shutil
import sys
import time
from pathlib import Path

os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")  # keep 127.0.0.1 (see tests/test_ray.py)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_ray import IDLE_CPU, stage_costs, wave_spans  # noqa: E402

from neuralao.pipeline.bakes.level import bake_level  # noqa: E402
from neuralao.pipeline.bakes.level_settings import load_level_settings  # noqa: E402
from neuralao.pipeline.geometry.level_gen import settings_for, write_level  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402


def project(
    info: dict,
    machines: int,
    cores: int,
    threads_per_actor: int = 1,
    bvh_speedup: float = 1.0,
    checks: bool = False,
    same_run: bool = False,
    ahead: bool = True,
    driver: dict[str, float] | None = None,
) -> dict:
    """Seconds per stage of the bake ``info`` (a bake log) on ``machines`` x ``cores``: the driver's own
    seconds (with a local bake's, what Ray's driver would spend submitting its tasks), plus the stage's
    tasks wave after wave, each wave's scheduled longest first (``bench_ray.wave_spans``: the trace's
    blocks divide to the cores; no other stage's tasks split), plus its states (BVHs) built once per
    machine, in parallel.

    threads_per_actor : 1, one actor per core (each builds its own BVH on its core); ``cores``: one actor
        per machine, whose tracing tasks use all its threads and whose BVH build is ``bvh_speedup`` times
        faster, while tasks that do not trace run one at a time per machine.
    checks : include the stages that only make error tables (the blend check): what a run's own wall clock
        is checked against; a production bake leaves them out.
    same_run : the run that made ``info`` itself: a state built ahead (``Engine.prepare``) costs what its
        stage's first tasks waited for it, as measured.
    ahead : False: every state costs its whole build, as if its stage's first task built it.
    driver : {stage: driver seconds} to take instead of the log's (:func:`ray_driver_seconds` of a Ray
        bake of the same level and settings: what a Ray driver spends, where a local bake's log has its
        own seconds and Ray's cost of an empty task).

    A state built ahead on machines of one actor costs max(0, its build at the machine's threads - the
    seconds its machine's cores are free between the prepare call and the stage that needs it), the free
    seconds being those stages' driver seconds and their waves of tasks that do not trace (one task of one
    thread at a time per machine: the build is taken to get the other cores), not their tracing waves
    (which use every core). For a level bake's opaque BVH, prepared right after the geometry, those are the
    foliage's stage (the driver's alone: the workers' cores are taken to be free) and the samples' passes;
    the gold BVH's, from the solve to the trees. On single-CPU actors it costs its whole build (it shares
    the actor's core)."""
    out, free = {}, {}
    costs = stage_costs(info, checks)
    for c in costs:
        name, work = c["stage"], c["task_core_s"]
        if driver is not None and name in driver:
            c = {**c, "driver_s": driver[name]}
        if threads_per_actor == 1:
            slots = machines * cores
        else:  # one actor per machine: tracing tasks spread over its threads, the others use one
            slots = machines
            work = [w / threads_per_actor if t else w for w, t in zip(work, c["traces"], strict=True)]
        spans = wave_spans(work, c["waves"], slots, name == "trace", c["traces"])
        free[c["position"]] = c["driver_s"] + sum(span for span, tracing in spans if not tracing)
        speedup = bvh_speedup if threads_per_actor > 1 else 1.0
        state = c["state_s"] / speedup
        if c["prepared_s"]:
            if not ahead:
                ahead_s = c["prepared_s"] / speedup
            elif same_run:
                ahead_s = c["waited_s"]
            elif threads_per_actor > 1:
                hidden = sum(f for at, f in free.items() if c["prepared_at"] < at < c["position"])
                ahead_s = max(0.0, c["prepared_s"] / speedup - hidden)
            else:
                ahead_s = c["prepared_s"]
            state = max(state, ahead_s)
        out[name] = c["driver_s"] + state + sum(span for span, _ in spans)
    return {"stages": out, "total_s": sum(out.values())}


def read_log(path: str, option: str) -> dict:
    """The bake log (bench_level.json, bench_world.json or bake_log.json) at ``path``, given as ``option``;
    a missing or unreadable file is a one-line error."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise SystemExit(f"{option} {path}: not a readable bake log ({type(e).__name__}: {e})") from None
    log = data.get("bake", data.get("bake_log", data)) if isinstance(data, dict) else None
    if not isinstance(log, dict) or not isinstance(log.get("stages"), list):
        raise SystemExit(f"{option} {path}: not a bake log (no stages)")
    return log


def ray_driver_seconds(log: dict, idle: float = IDLE_CPU) -> dict[str, float]:
    """{stage: its driver's CPU seconds} of a Ray bake's log, less what an idle Ray driver spends over the
    stage's wall clock (``idle``, a fraction of it: Ray's own threads in the driver's process), which on
    a cluster that makes the stage shorter shrinks with it."""
    if log.get("engine") != "ray":
        raise SystemExit("--driver-from needs a Ray bake's log (bake_log.json of --engine ray)")
    return {st["stage"]: max(0.0, st["cpu_seconds"] - idle * st["seconds"]) for st in log["stages"]}


def _build_bvh(level: str, cpus: list[int], queue) -> None:
    """Child process: the opaque level's Embree BVH built on ``cpus`` only; its seconds to ``queue``."""
    os.sched_setaffinity(0, cpus)  # before Embree starts its threads: it sizes its pool to the mask
    from neuralao.pipeline.bakes.level_stages import opaque_scene
    from neuralao.pipeline.geometry.level_files import read_level
    from neuralao.pipeline.tracing.labeller import LabelSettings
    from neuralao.pipeline.tracing.level_tracer import LevelLabeller

    scene = opaque_scene(read_level(Path(level)))
    t0 = time.perf_counter()
    LevelLabeller(scene, LabelSettings(rays=4, kernel="obscurance", workers=len(cpus)))
    queue.put(time.perf_counter() - t0)


def bvh_speedup(level: Path, repeats: int = 2) -> dict:
    """The BVH build on 1 and on 2 of this machine's cores (best of ``repeats``, interleaved), and Amdahl's
    law fitted to the two, extrapolated to 16 threads: S16 = 1 / ((1 - p) + p / 16), p = 2 (1 - 1 / S2)."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    best = {1: float("inf"), 2: float("inf")}
    for _ in range(repeats):
        for n in (1, 2):
            q = ctx.Queue()
            proc = ctx.Process(target=_build_bvh, args=(str(level), list(range(n)), q))
            proc.start()
            best[n] = min(best[n], q.get())
            proc.join()
    s2 = best[1] / best[2]
    frac = min(max(2.0 * (1.0 - 1.0 / s2), 0.0), 1.0)
    return {
        "one_core_s": best[1],
        "two_cores_s": best[2],
        "s2": s2,
        "parallel_fraction": frac,
        "s16": 1.0 / ((1.0 - frac) + frac / 16.0),
    }


def output_hash(bake: Path) -> str:
    return hashlib.sha256((bake / "level_baked.glb").read_bytes()).hexdigest()[:16]


@contextlib.contextmanager
def loopback_cluster(nodes: int, cpus: int, object_store_gib: float = 1.0, heavy_states: int | None = None):
    """A fresh Ray cluster of ``nodes`` x ``cpus`` on 127.0.0.1 (its own raylets and an object store of
    ``object_store_gib`` per node; what does not fit spills to the disk, which Ray refuses past 95% full),
    this process its driver: yields (engine, alive nodes, nodes with actors). ``heavy_states``: the BVHs
    an actor may hold at once (``RayEngine``'s; None: its rule)."""
    import ray
    from ray.cluster_utils import Cluster

    from neuralao.pipeline.engines import engine as engine_mod
    from neuralao.pipeline.engines.engine import RayEngine

    node = {"num_cpus": cpus, "object_store_memory": int(object_store_gib * (1 << 30))}
    c = Cluster(initialize_head=True, head_node_args=node | {"include_dashboard": False})
    try:
        for _ in range(nodes - 1):
            c.add_node(**node)
        engine_mod._connect(c.address)
        c.wait_for_nodes()
        alive = [n for n in ray.nodes() if n["Alive"]]
        with RayEngine(c.address, heavy_states=heavy_states) as engine:
            yield engine, len(alive), len({node_id for _, node_id in engine.worker_info()})
    finally:
        ray.shutdown()
        c.shutdown()


def run_cluster(
    level: Path, settings, nodes: int, cpus: int, out: Path, heavy_states: int | None = None
) -> dict:
    """Bake on a fresh loopback cluster of ``nodes`` x ``cpus``; the bake log, wall seconds and hash."""
    with loopback_cluster(nodes, cpus, heavy_states=heavy_states) as (engine, alive, placed):
        shutil.rmtree(out, ignore_errors=True)
        t0 = time.perf_counter()
        info = bake_level(level, settings, out, engine=engine)
        wall = time.perf_counter() - t0
    return {
        "nodes": nodes,
        "cpus_per_node": cpus,
        "alive_nodes": alive,
        "nodes_with_actors": placed,
        "wall_s": wall,
        "glb_sha256": output_hash(out),
        "bake": info,
    }


def markdown(r: dict) -> str:
    if r["runs"]:
        lines = [
            f"# Level bake on a loopback Ray cluster ({r['preset']}, overrides {r['overrides']})",
            "",
            f"{r['cpu_count']} cores on this machine; load average before {r['load_before']}, "
            f"after {r['load_after']}",
            "",
            *_runs_markdown(r),
        ]
    else:
        lines = [f"# Projection of a level bake ({r['preset']})"]
    labels = (
        ("single-CPU actors", "single"),
        ("one actor of 16 threads per machine", "threads"),
        ("one actor of 16 threads per machine, each BVH built by its stage's first task", "threads_in_line"),
    )
    for label, key in labels:
        proj = r["projection"][key]
        names = list(proj[0]["stages"])
        source = r.get("projected_from", "the 1-node run")
        if r.get("driver_from"):
            source += f" with the driver seconds of {r['driver_from']}"
        lines += ["", f"Projection of {source}, machines of 16 cores, {label}:", ""]
        lines += ["| machines | " + " | ".join(names) + " | total s | vs 1 machine | bound by |"]
        lines += ["|---:|" + "---:|" * (len(names) + 2) + "---|"]
        for row in proj:
            bound = max(row["stages"], key=row["stages"].get)
            cells = " | ".join(f"{row['stages'][n]:.1f}" for n in names)
            lines.append(
                f"| {row['machines']} | {cells} | **{row['total_s']:.1f}** "
                f"| {proj[0]['total_s'] / row['total_s']:.1f}x | {bound} |"
            )
    return "\n".join(lines) + "\n"


def _runs_markdown(r: dict) -> list[str]:
    """The cluster runs' table and their driver seconds per stage."""
    lines = [
        "| nodes x CPUs | wall s | projected s (same run) | measured / projected "
        "| speed-up vs 1 node, measured | projected from the 1-node run | bytes |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    base = r["runs"][0]
    for run in r["runs"]:
        lines.append(
            f"| {run['nodes']} x {run['cpus_per_node']} | {run['wall_s']:.1f} | {run['projected_s']:.1f} | "
            f"{run['wall_s'] / run['projected_s']:.2f} | {base['wall_s'] / run['wall_s']:.2f}x | "
            f"{run['speedup_projected_from_1']:.2f}x | {run['glb_sha256']} |"
        )
    lines += ["", "Driver seconds per stage (Ray runs: the driver's CPU seconds):", ""]
    stages = [s["stage"] for s in base["bake"]["stages"]]
    lines += [
        "| stage | " + " | ".join(f"{x['nodes']} node(s)" for x in r["runs"]) + " | tasks | largest task s |"
    ]
    lines += ["|---|" + "---:|" * (len(r["runs"]) + 2)]
    for name in stages:
        row = []
        for run in r["runs"]:
            st = next((s for s in run["bake"]["stages"] if s["stage"] == name), {})
            row.append(f"{st.get('driver_seconds', 0.0):.2f}")
        st0 = next(s for s in base["bake"]["stages"] if s["stage"] == name)
        lines.append(
            f"| {name} | {' | '.join(row)} | {st0.get('tasks', '-')} "
            f"| {st0.get('task_seconds_max', 0.0):.2f} |"
        )
    return lines


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", default="table1")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", action="append", default=[], help="bake setting override, e.g. trace.rays=32")
    p.add_argument("--nodes", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--cpus-per-node", type=int, default=1)
    p.add_argument("--machines", type=int, nargs="+", default=[1, 4, 32, 128])
    p.add_argument(
        "--bvh-speedup", type=float, default=None, help="BVH build, 16 threads vs 1 (default: measured)"
    )
    p.add_argument(
        "--heavy-states",
        type=int,
        default=None,
        help="BVHs an actor may hold at once (default: the engine's rule, 1 for single-CPU actors)",
    )
    p.add_argument("--out", default="build/bench")
    p.add_argument("--project-only", action="store_true", help="recompute from OUT's bench_cluster.json")
    p.add_argument(
        "--project-from",
        default=None,
        help="project this bake log (bench_level.json, bench_world.json, bake_log.json) instead of the "
        "1-node run; written to OUT/bench_cluster_projected.{json,md} (a local bake's tasks run one per "
        "core, as single-CPU actors' do)",
    )
    p.add_argument(
        "--driver-from",
        default=None,
        help="a Ray bake's bake_log.json of the same level and settings: the projections take its driver's "
        "CPU seconds per stage (less an idle Ray driver's) instead of the projected log's",
    )
    args = p.parse_args()
    out = Path(args.out) / "level_cluster" / args.preset
    if args.project_only:
        kept = out / "bench_cluster.json"
        if not kept.exists() and not args.project_from:
            raise SystemExit(f"--project-only: no {kept} (run the clusters first, or give --project-from)")
        # a projection of another bake log needs no cluster run of its own
        result = json.loads(kept.read_text()) if kept.exists() else {"preset": args.preset, "runs": []}
    else:
        level, cfg = write_level(out / "level", settings_for(args.preset, args.seed), args.preset)
        settings = load_level_settings(cfg, args.set)
        # the load average around the runs as they were made (a rerun that keeps every run keeps its own)
        earlier = out / "bench_cluster.json"
        earlier = json.loads(earlier.read_text()) if earlier.exists() else {}
        result = {"preset": args.preset, "overrides": args.set, "load_before": list(os.getloadavg())}
        runs, fresh = [], False
        for n in args.nodes:
            # each run kept as it ends, so a rerun of the same command resumes after the last finished one
            saved = out / f"run_{n}x{args.cpus_per_node}.json"
            key = {"preset": args.preset, "seed": args.seed, "overrides": args.set}
            if args.heavy_states is not None:
                key["heavy_states"] = args.heavy_states
            kept = json.loads(saved.read_text()) if saved.exists() else {}
            if kept.get("key") == key:
                run = kept["run"]
            else:
                bake = out / f"bake_{n}"
                run = run_cluster(level, settings, n, args.cpus_per_node, bake, args.heavy_states)
                write_json(saved, {"key": key, "run": run})
                fresh = True
            run["projected_s"] = project(run["bake"], n, args.cpus_per_node, checks=True, same_run=True)[
                "total_s"
            ]
            runs.append(run)
            print(f"{n} node(s): {run['wall_s']:.1f} s, projected {run['projected_s']:.1f} s", flush=True)
        for run in runs:
            run["speedup_projected_from_1"] = (
                project(runs[0]["bake"], 1, args.cpus_per_node, checks=True)["total_s"]
                / project(runs[0]["bake"], run["nodes"], args.cpus_per_node, checks=True)["total_s"]
            )
        result.update(runs=runs, load_after=list(os.getloadavg()), cpu_count=os.cpu_count())
        if not fresh and earlier.get("overrides") == args.set:
            result.update(load_before=earlier["load_before"], load_after=earlier["load_after"])
    if args.bvh_speedup is not None:
        result["bvh_speedup_16"] = args.bvh_speedup
    elif "bvh" not in result:
        result["bvh"] = bvh_speedup(out / "level" / "level.gltf")
        result["bvh_speedup_16"] = result["bvh"]["s16"]
    speedup = result.get("bvh_speedup_16", 1.0)
    base = result["runs"][0]["bake"] if result["runs"] else None
    if args.project_from:
        base = read_log(args.project_from, "--project-from")
        result["projected_from"] = args.project_from
    driver = None
    if args.driver_from:
        driver = ray_driver_seconds(read_log(args.driver_from, "--driver-from"))
        result["driver_from"] = args.driver_from
    result["projection"] = {
        "single": [{"machines": m, **project(base, m, 16, driver=driver)} for m in args.machines],
        "threads": [
            {"machines": m, **project(base, m, 16, 16, speedup, driver=driver)} for m in args.machines
        ],
        "threads_in_line": [
            {"machines": m, **project(base, m, 16, 16, speedup, ahead=False, driver=driver)}
            for m in args.machines
        ],
    }
    name = "bench_cluster_projected" if args.project_from else "bench_cluster"
    write_json(out / f"{name}.json", result)
    write_text(out / f"{name}.md", markdown(result))
    print(markdown(result))
    hashes = {r["glb_sha256"] for r in result["runs"]}
    if len(hashes) > 1:
        print(f"the runs' glTFs differ: {hashes}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
