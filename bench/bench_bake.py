"""Benchmark vertex AO baking: least-squares fitting (Kavan et al. 2011) against per-vertex sampling.

    .venv/bin/python bench/bench_bake.py --out build/bench [--meshes cornell_box,fandisk,teapot,spot,beetle]
        [--rays 128] [--ref-rays 1024] [--held-out 20000] [--largest ReciprocatingSaw] [--skip-largest]

1. Error, per mesh: both bakes shown as the renderer shows them (vertex values interpolated across
   faces), compared with a ``--ref-rays`` Embree reference at ``--held-out`` surface samples that are
   not the least-squares samples (other positions, other seed, area-weighted). Three bakes side by
   side: vertex sampling at ``rays`` rays, vertex sampling at the least-squares run's total ray
   budget (same rays traced), and least squares at ``rays`` rays per surface sample. Ratios: LSQ
   RMSE over vertex RMSE.
2. Regulariser: held-out RMSE of the least-squares fit against ``alpha`` (same traced samples),
   the evidence for the default alpha = 1 (REG_SCALE in pipeline/geometry/least_squares.py).
3. Bake time of the largest test mesh (default ReciprocatingSaw, 198k faces) with the default
   ``neuralao bake`` settings (256 rays, 8 samples per vertex), both methods, split into sampling,
   tracing and solving.

Writes DIR/bake.json and DIR/bake.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.pipeline.bakes.vertex import BakeSettings, bake, reference_at_samples  # noqa: E402
from neuralao.pipeline.geometry.least_squares import fit_least_squares  # noqa: E402
from neuralao.pipeline.geometry.scene import load_scene  # noqa: E402
from neuralao.pipeline.geometry.surface import surface_error, surface_samples  # noqa: E402
from neuralao.pipeline.tracing.labeller import Labeller  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402

ALPHAS = (0.0, 0.1, 1.0, 10.0, 100.0)


def compare(name: str, rays: int, ref_rays: int, held_out: int) -> dict:
    scene = load_scene(name)
    settings = BakeSettings(rays=rays)
    held = surface_samples(scene, held_out, cap=10**6, seed=987654)
    t0 = time.perf_counter()
    ref, ref_valid = reference_at_samples(scene, held, settings, rays=ref_rays, seed=4242)
    t_ref = time.perf_counter() - t0
    lsq = bake(scene, settings)
    budget = max(1, round(lsq.info["rays_traced"] / len(scene.vertices)))
    vertex = bake(scene, replace(settings, method="vertex"))
    vertex_budget = bake(scene, replace(settings, method="vertex", rays=budget))
    out = {
        "mesh": name,
        "vertices": len(scene.vertices),
        "faces": len(scene.faces),
        "held_out_samples": int(ref_valid.sum()),
        "reference_rays": ref_rays,
        "reference_seconds": t_ref,
        "lsq_samples": lsq.info["samples"],
        "lsq_invalid_samples": lsq.info["invalid_samples"],
        "vertex_budget_rays": budget,
    }
    for key, r in (("vertex", vertex), ("vertex_same_budget", vertex_budget), ("lsq", lsq)):
        out[key] = {
            **surface_error(scene, r.ao, held, ref, ref_valid),
            "seconds": r.info["seconds"],
            "rays_traced": r.info["rays_traced"],
        }
    out["rmse_ratio_lsq_vs_vertex"] = out["lsq"]["rmse"] / out["vertex"]["rmse"]
    out["rmse_ratio_lsq_vs_vertex_same_budget"] = out["lsq"]["rmse"] / out["vertex_same_budget"]["rmse"]
    # regulariser sweep on the same traced samples
    samples = surface_samples(
        scene, settings.samples_per_vertex * len(scene.vertices), settings.samples_per_face_cap, settings.seed
    )
    ao, valid = Labeller(scene, settings.label_settings()).ao_at_points(samples.points, samples.normals)
    out["alpha_sweep"] = {
        str(a): surface_error(scene, fit_least_squares(scene, samples, ao, valid, a), held, ref, ref_valid)[
            "rmse"
        ]
        for a in ALPHAS
    }
    return out


def largest(name: str) -> dict:
    scene = load_scene(name)
    out = {"mesh": name, "vertices": len(scene.vertices), "faces": len(scene.faces)}
    for method in ("vertex", "least-squares"):
        r = bake(scene, BakeSettings(method=method))
        out[method] = {k: v for k, v in r.info.items() if k != "settings"}
    out["settings"] = (
        "defaults of `neuralao bake`: 256 rays, binary kernel, max distance 0.25 x diagonal, "
        "8 samples/vertex, cap 32/face"
    )
    return out


def markdown(result: dict) -> str:
    lines = [
        "# Vertex AO baking: least squares vs per-vertex sampling",
        "",
        f"CPU: {result['cpu']} ({result['cores']} cores). Error = area-weighted RMSE of the interpolated "
        f"vertex AO against a {result['ref_rays']}-ray reference at held-out surface samples; "
        f"bakes at {result['rays']} rays per sample (binary kernel, max distance 0.25 x diagonal).",
        "",
        "| mesh | vertices | faces | RMSE vertex | RMSE vertex (same rays as LSQ) | RMSE LSQ | "
        "LSQ / vertex | LSQ / vertex same rays | max err vertex | max err LSQ |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for m in result["meshes"]:
        lines.append(
            f"| {m['mesh']} | {m['vertices']} | {m['faces']} | {m['vertex']['rmse']:.4f} | "
            f"{m['vertex_same_budget']['rmse']:.4f} ({m['vertex_budget_rays']} rays) "
            f"| {m['lsq']['rmse']:.4f} | {m['rmse_ratio_lsq_vs_vertex']:.2f} | "
            f"{m['rmse_ratio_lsq_vs_vertex_same_budget']:.2f} | {m['vertex']['max']:.3f} | "
            f"{m['lsq']['max']:.3f} |"
        )
    lines += [
        "",
        "Held-out RMSE of the least-squares fit against the regulariser weight alpha (same traced samples):",
        "",
        "| mesh | " + " | ".join(f"alpha {a:g}" for a in ALPHAS) + " |",
        "|---|" + "---:|" * len(ALPHAS),
    ]
    for m in result["meshes"]:
        lines.append(
            f"| {m['mesh']} | " + " | ".join(f"{m['alpha_sweep'][str(a)]:.4f}" for a in ALPHAS) + " |"
        )
    big = result.get("largest")
    if big:
        lv, ll = big["vertex"], big["least-squares"]
        lines += [
            "",
            f"Bake time, largest test mesh {big['mesh']} ({big['vertices']} vertices, "
            f"{big['faces']} faces), {big['settings']}:",
            "",
            "| method | samples | rays traced | sampling s | trace s | solve s | total s |",
            "|---|---:|---:|---:|---:|---:|---:|",
            f"| vertex | {lv['samples']} | {lv['rays_traced']:.3g} | - | "
            f"{lv['seconds_trace']:.1f} | {lv['seconds_solve']:.2f} | {lv['seconds']:.1f} |",
            f"| least-squares | {ll['samples']} | {ll['rays_traced']:.3g} | "
            f"{ll['seconds_sampling']:.2f} | {ll['seconds_trace']:.1f} | "
            f"{ll['seconds_solve']:.2f} | {ll['seconds']:.1f} |",
        ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path, help="output folder")
    ap.add_argument(
        "--meshes", default="cornell_box,fandisk,teapot,spot,beetle", help="meshes for the error comparison"
    )
    ap.add_argument("--rays", type=int, default=128, help="rays per sample of the compared bakes")
    ap.add_argument("--ref-rays", type=int, default=1024, help="rays of the held-out reference")
    ap.add_argument("--held-out", type=int, default=20000, help="held-out surface samples per mesh")
    ap.add_argument("--largest", default="ReciprocatingSaw", help="mesh for the bake-time measurement")
    ap.add_argument("--skip-largest", action="store_true", help="skip the bake-time measurement")
    args = ap.parse_args(argv)
    result = {
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "rays": args.rays,
        "ref_rays": args.ref_rays,
        "loadavg_before": os.getloadavg(),
        "meshes": [],
    }
    for name in [m for m in args.meshes.split(",") if m]:
        result["meshes"].append(compare(name, args.rays, args.ref_rays, args.held_out))
        m = result["meshes"][-1]
        print(
            f"{name}: vertex {m['vertex']['rmse']:.4f}  lsq {m['lsq']['rmse']:.4f}  ratio "
            f"{m['rmse_ratio_lsq_vs_vertex']:.2f}",
            flush=True,
        )
    if not args.skip_largest:
        result["largest"] = largest(args.largest)
    result["loadavg_after"] = os.getloadavg()
    write_json(args.out / "bake.json", result)
    write_text(args.out / "bake.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
