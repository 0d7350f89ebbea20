"""Benchmark the AO labeller against raw embreex on the same rays, and its Monte-Carlo error.

    .venv/bin/python bench/bench_labeller.py --out build/bench [--mesh spot] [--size 256] [--rays 256]

1. Throughput: the rays of one real frame (a ``size`` x ``size`` pyrender G-buffer of ``mesh``,
   ``rays`` per foreground pixel) traced by (a) raw ``EmbreeScene.run(query='OCCLUDED')`` on
   precomputed arrays - the ceiling - on one thread and on two threads (embreex releases the GIL),
   and (b) :meth:`Labeller.label_frame` with ``workers`` 1 and 2, for the binary kernel without the
   back-face rule (OCCLUDED rays), with it (the default: INTERSECT rays), and obscurance. Variants
   run interleaved, ``--repeats`` rounds, best round kept (other processes share the two cores).
2. Seconds per ``size`` x ``size`` view at ``rays`` rays (label_frame, default settings, 2 workers).
3. Monte-Carlo error of the default labeller against ray count on that frame, vs a ``--ref-rays``
   reference with a different seed (the reference's own error is reported too).

Writes DIR/labeller.json and DIR/labeller.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.pipeline.geometry.camera import orbit  # noqa: E402
from neuralao.pipeline.geometry.scene import load_scene  # noqa: E402
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402

RAW_CHUNK = 1 << 16  # rays per raw call when split over threads (same granularity as the labeller)


def render_frame(scene, size: int) -> tuple[dict, str]:
    """A size x size frame of ``scene`` from its first orbit camera: pyrender G-buffer if available."""
    camera = orbit(scene, 4, size, size, seed=1)[0]
    try:
        from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer

        return render_gbuffer(scene, camera), "neuralao.pipeline.gbuffers.rasterizer (pyrender/OSMesa)"
    except ImportError:
        return embree_frame(scene, camera), "Embree primary rays"


def embree_frame(scene, camera) -> dict:
    """Minimal frame (tri_id, pose, yfov) from Embree primary rays, for when gbuffer is missing."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    center, diag = scene.center, scene.diagonal
    es = rtcore_scene.EmbreeScene()
    TriangleMesh(es, ((scene.vertices - center) / diag).astype(np.float32), scene.faces.astype(np.int32))
    o, d = camera.pixel_rays()
    prim = es.run(((o - center) / diag).astype(np.float32), d.astype(np.float32), query="INTERSECT")
    tri = np.asarray(prim, np.int32).reshape(camera.height, camera.width)
    return {"tri_id": tri, "pose": camera.pose, "yfov": camera.yfov}


def raw_trace(es, origins: np.ndarray, dirs: np.ndarray, tfar: np.float32, workers: int, query: str) -> None:
    """Raw embreex ``query`` over precomputed rays, on ``workers`` threads in RAW_CHUNK pieces."""
    n = len(dirs)
    bounds = [(lo, min(lo + RAW_CHUNK, n)) for lo in range(0, n, RAW_CHUNK)]

    def run(b: tuple[int, int]) -> None:
        es.run(origins[b[0] : b[1]], dirs[b[0] : b[1]], query=query, dists=tfar)

    if workers == 1:
        for b in bounds:
            run(b)
    else:
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(run, bounds))


def throughput(scene, frame: dict, rays: int, repeats: int) -> dict:
    base = LabelSettings(rays=rays)
    variants = {
        "binary, no back-face rule (OCCLUDED)": replace(base, backface_threshold=None),
        "binary, back-face rule (default, INTERSECT)": base,
        "obscurance, back-face rule (INTERSECT + tfar)": replace(base, kernel="obscurance"),
    }
    labellers = {name: Labeller(scene, s) for name, s in variants.items()}
    any_lab = next(iter(labellers.values()))
    points, normals, pix, _ = any_lab.visible_points(frame)
    origins, dirs = any_lab.rays(points, normals, ids=pix)
    n_rays = len(dirs)
    es, tfar = any_lab.embree, any_lab.r_local  # the same committed Embree scene and ray length
    best: dict[str, float] = {}

    cpu: dict[str, float] = {}

    def timed(key: str, fn) -> None:
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best[key] = min(best.get(key, float("inf")), time.perf_counter() - t0)
        cpu[key] = min(cpu.get(key, float("inf")), time.process_time() - c0)

    for _ in range(repeats):
        for workers in (1, 2):
            timed(f"raw/{workers}", lambda w=workers: raw_trace(es, origins, dirs, tfar, w, "OCCLUDED"))
            timed(f"rawi/{workers}", lambda w=workers: raw_trace(es, origins, dirs, tfar, w, "INTERSECT"))
            for name, lab in labellers.items():
                lab.settings = replace(lab.settings, workers=workers)
                timed(f"{name}/{workers}", lambda lab=lab: lab.label_frame(frame))
    rows = []
    for name in variants:
        for workers in (1, 2):
            raw = n_rays / best[f"raw/{workers}"]
            mine = n_rays / best[f"{name}/{workers}"]
            rows.append(
                {
                    "variant": name,
                    "workers": workers,
                    "labeller_mrays_s": mine / 1e6,
                    "raw_occluded_mrays_s": raw / 1e6,
                    "ratio": mine / raw,
                    "raw_intersect_mrays_s": n_rays / best[f"rawi/{workers}"] / 1e6,
                    "ratio_vs_raw_intersect": mine * best[f"rawi/{workers}"] / n_rays,
                    "labeller_seconds": best[f"{name}/{workers}"],
                    # CPU seconds (all threads) of raw / labeller: the work ratio, immune to other
                    # processes taking a core (not to load imbalance, which wall time shows).
                    "cpu_ratio": cpu[f"raw/{workers}"] / cpu[f"{name}/{workers}"],
                }
            )
    return {
        "rays_total": n_rays,
        "foreground_pixels": len(pix),
        "raw_speedup_2_threads": best["raw/1"] / best["raw/2"],
        "rows": rows,
    }


def mc_error(scene, frame: dict, counts: list[int], ref_rays: int) -> dict:
    """RMSE / mean |error| of label_frame at several ray counts vs a high-ray reference (other seed)."""
    ref_lab = Labeller(scene, LabelSettings(rays=ref_rays, seed=12345))
    ref, ref_valid = ref_lab.label_frame(frame)
    rows = []
    for n in counts:
        lab = Labeller(scene, LabelSettings(rays=n, seed=1))
        ao, valid = lab.label_frame(frame)
        m = valid & ref_valid
        err = (ao - ref)[m].astype(np.float64)
        p = ref[m].astype(np.float64)
        iid = np.sqrt(np.mean(p * (1 - p) / n))  # RMSE an i.i.d. binomial estimator would have
        rows.append(
            {
                "rays": n,
                "rmse": float(np.sqrt(np.mean(err**2))),
                "mean_abs": float(np.mean(np.abs(err))),
                "p99_abs": float(np.quantile(np.abs(err), 0.99)),
                "max_abs": float(np.max(np.abs(err))),
                "iid_binomial_rmse": float(iid),
                "pixels": int(m.sum()),
            }
        )
    p = ref[ref_valid].astype(np.float64)
    return {
        "reference_rays": ref_rays,
        "reference_iid_rmse_bound": float(np.sqrt(np.mean(p * (1 - p) / ref_rays))),
        "rows": rows,
    }


def markdown(result: dict) -> str:
    t, e, v = result["throughput"], result["mc_error"], result["view"]
    lines = [
        "# AO labeller benchmark",
        "",
        f"Mesh `{result['mesh']}` ({result['faces']} faces), one {result['size']}x{result['size']} view "
        f"({t['foreground_pixels']} foreground pixels, frame from {result['frame_source']}), "
        f"{result['rays']} rays/pixel = {t['rays_total'] / 1e6:.2f} M rays. CPU: {result['cpu']} "
        f"({result['cores']} cores; load average {result['loadavg_before'][0]:.2f} before, "
        f"{result['loadavg_after'][0]:.2f} after - other processes may share the cores). "
        f"Best of {result['repeats']} interleaved rounds.",
        "",
        f"Raw embreex OCCLUDED, 2 threads vs 1: {t['raw_speedup_2_threads']:.2f}x "
        "(well below 2x means another process held a core during the run).",
        "",
        "| labeller variant | workers | labeller Mrays/s | raw OCCLUDED Mrays/s | ratio | "
        "CPU-time ratio | raw INTERSECT Mrays/s | ratio vs INTERSECT |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in t["rows"]:
        lines.append(
            f"| {r['variant']} | {r['workers']} | {r['labeller_mrays_s']:.2f} | "
            f"{r['raw_occluded_mrays_s']:.2f} | **{r['ratio']:.3f}** | {r['cpu_ratio']:.3f} | "
            f"{r['raw_intersect_mrays_s']:.2f} | "
            f"{r['ratio_vs_raw_intersect']:.3f} |"
        )
    lines += [
        "",
        "Raw columns: embreex `EmbreeScene.run` on the labeller's exact rays, precomputed, same thread "
        "count, same Embree scene; ratio = labeller / raw OCCLUDED (the ceiling), wall clock; CPU-time "
        "ratio = raw CPU seconds / labeller CPU seconds (all threads). The back-face rule "
        "needs the closest hit (INTERSECT), which Embree itself traces slower than any-hit OCCLUDED.",
    ]
    lines += [
        "",
        f"Seconds per {result['size']}x{result['size']} view at {result['rays']} rays (default settings, "
        f"2 workers, label_frame end to end): **{v['seconds']:.2f} s** ({v['foreground_pixels']} pixels).",
        "",
        f"## Monte-Carlo error vs rays (reference: {e['reference_rays']} rays, other seed; its own i.i.d. "
        f"RMSE bound {e['reference_iid_rmse_bound']:.4f})",
        "",
        "| rays | RMSE | mean abs | p99 abs | max abs | i.i.d. binomial RMSE |",
        "|---|---|---|---|---|---|",
    ]
    for r in e["rows"]:
        lines.append(
            f"| {r['rays']} | {r['rmse']:.4f} | {r['mean_abs']:.4f} | {r['p99_abs']:.4f} | "
            f"{r['max_abs']:.4f} | {r['iid_binomial_rmse']:.4f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path, help="output folder")
    ap.add_argument("--mesh", default="spot", help="mesh name or path (default spot)")
    ap.add_argument("--size", type=int, default=256, help="view size in pixels (square)")
    ap.add_argument("--rays", type=int, default=256, help="rays per pixel for the throughput and view timing")
    ap.add_argument("--repeats", type=int, default=3, help="interleaved timing rounds (best kept)")
    ap.add_argument("--counts", default="16,64,256,1024", help="ray counts for the MC error table")
    ap.add_argument("--ref-rays", type=int, default=4096, help="rays of the MC reference")
    args = ap.parse_args(argv)

    scene = load_scene(args.mesh)
    frame, source = render_frame(scene, args.size)
    load_before = os.getloadavg()
    result = {
        "mesh": scene.name,
        "faces": len(scene.faces),
        "size": args.size,
        "rays": args.rays,
        "repeats": args.repeats,
        "frame_source": source,
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "loadavg_before": load_before,
    }
    result["throughput"] = throughput(scene, frame, args.rays, args.repeats)
    lab = Labeller(scene, LabelSettings(rays=args.rays))
    t0 = time.perf_counter()
    _, valid = lab.label_frame(frame)
    result["view"] = {
        "seconds": time.perf_counter() - t0,
        "foreground_pixels": int((frame["tri_id"] >= 0).sum()),
    }
    counts = [int(c) for c in args.counts.split(",") if c]
    result["mc_error"] = mc_error(scene, frame, counts, args.ref_rays)
    result["loadavg_after"] = os.getloadavg()
    write_json(args.out / "labeller.json", result)
    write_text(args.out / "labeller.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
