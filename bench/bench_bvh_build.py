"""A level's opaque Embree scene built two ways, side by side: embreex's per-element ``TriangleMesh`` copy and
the whole-buffer copy the labeller uses (:mod:`neuralao.pipeline.tracing.embree_buffers`), each followed by
Embree's own build (the scene's commit), on 1 and on 2 of this machine's cores.

    .venv/bin/python bench/bench_bvh_build.py --level build/bench/level_cluster/world10x/level/level.gltf
    .venv/bin/python bench/bench_bvh_build.py --preset table1        # writes the level first

Each core count runs in its own process (Embree sizes its thread pool to the process's CPU mask when it
starts), the two ways interleaved, best of ``--repeats``. Writes OUT/bvh_build/NAME.json and .md.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402


def _child(level: str, cpus: list[int], repeats: int, queue) -> None:
    os.sched_setaffinity(0, cpus)
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    from neuralao.pipeline.bakes.level_stages import opaque_scene
    from neuralao.pipeline.geometry.level_files import read_level
    from neuralao.pipeline.tracing.embree_buffers import attach_triangles

    scene = opaque_scene(read_level(Path(level)))
    verts = ((scene.vertices - scene.center) / scene.diagonal).astype(np.float32)
    faces = np.asarray(scene.faces, np.int32)
    ray = (np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
    best = {}
    for _ in range(repeats):
        for way in ("binding", "buffers"):
            t0 = time.perf_counter()
            e = rtcore_scene.EmbreeScene()
            if way == "binding":
                TriangleMesh(e, verts, faces)
            elif not attach_triangles(e, verts, faces):
                raise SystemExit("the whole-buffer path is not available for this embreex build")
            t1 = time.perf_counter()
            e.run(*ray, query="OCCLUDED", dists=1.0)  # commits: Embree's build
            t2 = time.perf_counter()
            del e
            copy, build = best.get(way, (np.inf, np.inf))
            best[way] = (min(copy, t1 - t0), min(build, t2 - t1))
    queue.put({"faces": len(faces), "vertices": len(verts), **{k: list(v) for k, v in best.items()}})


def measure(level: Path, repeats: int) -> dict:
    ctx = mp.get_context("spawn")
    out = {}
    for n in (1, 2):
        q = ctx.Queue()
        proc = ctx.Process(target=_child, args=(str(level), list(range(n)), repeats, q))
        proc.start()
        out[n] = q.get()
        proc.join()
    return out


def markdown(name: str, r: dict) -> str:
    one = r["cores"]["1"]
    lines = [
        f"# Opaque Embree scene of {name}: {one['faces']:,} triangles, {one['vertices']:,} vertices",
        "",
        "| cores | way | copy s | Embree build s | total s | total / binding's |",
        "|---:|---|---:|---:|---:|---:|",
    ]
    for n, c in r["cores"].items():
        base = sum(c["binding"])
        for way in ("binding", "buffers"):
            copy, build = c[way]
            total = copy + build
            lines.append(f"| {n} | {way} | {copy:.2f} | {build:.2f} | {total:.2f} | {total / base:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--level", help="a level.gltf (default: write --preset's)")
    p.add_argument("--preset", default="table1")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--out", default="build/bench")
    args = p.parse_args()
    if args.level:
        level, name = Path(args.level), Path(args.level).parent.parent.name
    else:
        from neuralao.pipeline.geometry.level_gen import settings_for, write_level

        name = args.preset
        level, _ = write_level(Path(args.out) / "bvh_build" / name / "level", settings_for(name), name)
    r = {"level": str(level), "repeats": args.repeats, "cpu_count": os.cpu_count()}
    r["cores"] = {str(k): v for k, v in measure(level, args.repeats).items()}
    out = Path(args.out) / "bvh_build"
    write_json(out / f"{name}.json", r)
    write_text(out / f"{name}.md", markdown(name, r))
    print(markdown(name, r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
