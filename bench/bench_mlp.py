"""Benchmark the baked MLP (Erra et al. 2017) end to end on the paper's four Stanford models.

    .venv/bin/python bench/bench_mlp.py --out build/bench [--meshes bunny dragon happy_buddha lucy]

Per mesh (samples are drawn once and shared by the three sizes):

1. Samples from the mesh directly: ``--views`` orbit views at ``--size``, 512 pixels each, only those
   labelled (``--rays``); ``--holdout-views`` held-back views (another orbit) at ``--holdout-size``,
   fully labelled. The held-back views are labelled a second time with another seed: the SSIM / RMSE
   between the two labellings is the Monte-Carlo noise ceiling of the reference itself.
2. For each size (16x8, 32x16, 64x32): training time, sample RMSE (test split) against a constant
   predictor, and on the held-back views (network at radius zero, as deployed, clamped) masked SSIM /
   RMSE next to the paper's Table 2; whole-image SSIM (background included, as MATLAB's ``ssim``
   would give) for comparison with the paper only; the same network at radius 10 (its training input).
3. Export (ONNX + GLSL) and parity: generated GLSL 3.30 (fp32 and fp16 storage) vs onnxruntime on the
   held-back frames (the ES 3.0 variant is checked by the tests and ``neuralao parity``).
4. Shader cost on Mesa (llvmpipe) at ``--timing-size`` squared: the MLP fragment pass per size (all pixels
   foreground, the worst case) and, in the same run, the plain vertex-colour AO draw of the mesh; ratios.
5. Ablation (16x8): trained on circle + radius-zero copies of every sample (``train_inputs=both``).
6. The paper's Table 2 protocol (``--paper-views``, default 2): whole-image SSIM at 1920x1080 (camera on an
   orbit around the bounding sphere, a third phase), the generated GLSL at radius zero against ray-traced
   AO. scikit-image's ``structural_similarity`` (Gaussian sigma 1.5, population covariance, data range 1) is
   the reference; ``neuralao.runtime.foundation.metrics.image_ssim`` and the masked SSIM beside it. In the
   same run, at 1920x1080: each MLP's shader time against SSAO's (the paper: NN-16x8 about 0.12x).

Writes DIR/mlp.json and DIR/mlp.md (checkpoints and exports under DIR/mlp/).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.export.mlp import export_checkpoint, parity  # noqa: E402
from neuralao.pipeline.geometry.camera import orbit  # noqa: E402
from neuralao.pipeline.geometry.scene import load_scene  # noqa: E402
from neuralao.pipeline.models.mlp import MLPSettings, parse_size, samples_from_mesh, train  # noqa: E402
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402
from neuralao.runtime.foundation.metrics import masked_rmse, masked_ssim  # noqa: E402

# Erra et al. 2017, Table 2: SSIM against ray-traced AO for NN-16x8, NN-32x16, NN-64x32.
PAPER_SSIM = {
    "bunny": (0.9814, 0.9819, 0.9793),
    "happy_buddha": (0.9646, 0.9642, 0.9655),
    "dragon": (0.9495, 0.9504, 0.9489),
    "lucy": (0.9743, 0.9750, 0.9754),
}
SIZES = ("16x8", "32x16", "64x32")


def noise_ceiling(mesh: str, frames: list[dict], settings: LabelSettings) -> dict:
    """Masked SSIM / RMSE between the held-back labels and a second labelling with another seed."""
    labeller = Labeller(load_scene(mesh), replace(settings, seed=settings.seed + 7919))
    ssim, rmse = [], []
    for f in frames:
        ao2, valid2 = labeller.label_frame(f)
        valid = f["valid"] & valid2
        ssim.append(masked_ssim(ao2, f["ao"], valid))
        rmse.append(masked_rmse(ao2, f["ao"], valid))
    return {"ssim": float(np.mean(ssim)), "rmse": float(np.mean(rmse))}


def bench_mesh(mesh: str, base: MLPSettings, sizes: list[str], out: Path, ablation: bool) -> dict:
    log = logging.getLogger("bench_mlp")
    t0 = time.perf_counter()
    samples = samples_from_mesh(mesh, base, progress=True)
    log.info(
        "%s: %d samples in %.1f s (+ %d held-back views in %.1f s)",
        mesh,
        samples.info["samples"],
        samples.info["sampling_seconds"],
        len(samples.holdout),
        samples.info["holdout_seconds"],
    )
    ceiling = noise_ceiling(mesh, samples.holdout, base.labels)
    row: dict = {
        "mesh": mesh,
        "faces": samples.info["faces"],
        "samples": samples.info["samples"],
        "substituted_fraction": samples.info["substituted_fraction"],
        "sampling_seconds": samples.info["sampling_seconds"],
        "holdout_label_seconds": samples.info["holdout_seconds"],
        "noise_ceiling": ceiling,
        "sizes": {},
    }
    parity_frames = samples.holdout[:2]
    for k, size in enumerate(sizes):
        settings = replace(base, hidden=parse_size(size))
        ckpt_path = out / "models" / f"{mesh}-{size}.pt"
        ckpt = train(settings, ckpt_path, samples=samples, progress=True)
        m = ckpt["metrics"]
        if k == 0:
            row["constant"] = {
                "test_rmse": m["constant_test_rmse"],
                "holdout_ssim": m["holdout_constant_ssim"],
                "holdout_rmse": m["holdout_constant_rmse"],
            }
        export_dir = out / "exports" / f"{mesh}-{size}"
        manifest = export_checkpoint(ckpt_path, export_dir)
        par = parity(export_dir, parity_frames, fp16=True, dialects=("glsl330",))
        paper = PAPER_SSIM.get(mesh, (None,) * 3)[SIZES.index(size)] if size in SIZES else None
        row["sizes"][size] = {
            "parameters": ckpt["parameters"],
            "parameter_bytes": ckpt["parameter_bytes"],
            "training_seconds": ckpt["training_time_s"],
            "iterations": ckpt["training"]["iterations"],
            "stopped_early": ckpt["training"]["stopped_early"],
            "test_rmse": m["test_rmse"],
            "holdout_ssim": m["holdout_ssim"],
            "holdout_rmse": m["holdout_rmse"],
            "holdout_ssim_full": m["holdout_ssim_full"],
            "holdout_ssim_r10": m["holdout_ssim_r10"],
            "holdout_rmse_r10": m["holdout_rmse_r10"],
            "paper_ssim": paper,
            "onnxruntime_vs_torch": manifest["checks"]["onnxruntime_vs_torch"],
            "opencv_vs_onnxruntime": manifest["checks"]["opencv_vs_onnxruntime"],
            "parity_fp32": par["max_abs_err"],
            "parity_fp16": par["max_abs_err_fp16"],
            "parity_passed": par["passed"],
            "glsl_dir": str(export_dir / "glsl"),
        }
        log.info(
            "%s %s: %.1f s, held-back SSIM %.4f (paper %s) RMSE %.4f, parity %.2g",
            mesh,
            size,
            ckpt["training_time_s"],
            m["holdout_ssim"],
            paper,
            m["holdout_rmse"],
            par["max_abs_err"],
        )
    if ablation:
        ckpt = train(
            replace(base, hidden=parse_size(sizes[0]), train_inputs="both"),
            None,
            samples=samples,
            progress=True,
        )
        m = ckpt["metrics"]
        row["ablation_both"] = {
            "size": sizes[0],
            "training_seconds": ckpt["training_time_s"],
            "test_rmse": m["test_rmse"],
            "holdout_ssim": m["holdout_ssim"],
            "holdout_rmse": m["holdout_rmse"],
            "holdout_ssim_full": m["holdout_ssim_full"],
        }
    row["seconds"] = time.perf_counter() - t0
    return row


def shader_costs(rows: list[dict], sizes: list[str], side: int, repeats: int) -> dict:
    """Median ms per frame at side x side: MLP pass per size (first mesh's export: the cost does not depend
    on the weights) and vertex-colour AO per mesh."""
    from neuralao.runtime.glsl_runner import time_mlp_fragment, time_vertex_colour

    mlp = {}
    for size in sizes:
        mlp[size] = {
            "ms": 1e3 * time_mlp_fragment(rows[0]["sizes"][size]["glsl_dir"], side, side, repeats=repeats)
        }
    vc = {}
    for r in rows:
        scene = load_scene(r["mesh"])
        vc[r["mesh"]] = 1e3 * time_vertex_colour(scene, orbit(scene, 1, side, side)[0], repeats=repeats)
    return {"size": side, "repeats": repeats, "mlp_ms": mlp, "vertex_colour_ms": vc}


def paper_protocol(
    rows: list[dict], sizes: list[str], views: int, size: tuple[int, int], labels: LabelSettings, repeats: int
) -> dict:
    """Table 2 as the paper measures it: whole-image SSIM at ``size`` on orbit views, plus GL times vs
    SSAO."""
    from skimage.metrics import structural_similarity

    from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
    from neuralao.runtime.baselines import run_screen_space, time_screen_space
    from neuralao.runtime.foundation.metrics import SSIM_SIGMA, image_ssim
    from neuralao.runtime.glsl_runner import run_mlp_fragment, time_mlp_fragment, time_vector_fragment

    w, h = size
    out: dict = {"size": [w, h], "views": views, "meshes": {}}
    timing_frame = None
    for r in rows:
        scene = load_scene(r["mesh"])
        labeller = Labeller(scene, replace(labels, seed=labels.seed + 104729))
        with GBufferRenderer(scene) as renderer:
            frames = [renderer.render(c) for c in orbit(scene, views, w, h, seed=3)]
        per = {size_: {"skimage": [], "ours": [], "masked": []} for size_ in [*sizes, "ssao"]}
        for f in frames:
            f["ao"], f["valid"] = labeller.label_frame(f)
            valid = f["valid"] & f["mask"]
            preds = {
                sz: run_mlp_fragment(r["sizes"][sz]["glsl_dir"], f["normal_obj"], f["mask"]) for sz in sizes
            }
            preds["ssao"] = run_screen_space(f, "ssao", labeller.max_distance)
            for key, raw in preds.items():
                pred = np.where(f["mask"], np.clip(np.nan_to_num(raw, nan=1.0), 0, 1), 1.0)
                per[key]["skimage"].append(
                    float(
                        structural_similarity(
                            pred,
                            f["ao"].astype(np.float64),
                            data_range=1.0,
                            gaussian_weights=True,
                            sigma=SSIM_SIGMA,
                            use_sample_covariance=False,
                        )
                    )
                )
                per[key]["ours"].append(image_ssim(pred, f["ao"]))
                per[key]["masked"].append(masked_ssim(pred, f["ao"], valid))
        out["meshes"][r["mesh"]] = {k: {m: float(np.mean(v)) for m, v in d.items()} for k, d in per.items()}
        out["meshes"][r["mesh"]]["foreground_fraction"] = float(np.mean([f["mask"].mean() for f in frames]))
        timing_frame = timing_frame or (frames[0], labeller.max_distance, r)
    f, radius, r0 = timing_frame
    out["ssao_ms"] = 1e3 * time_screen_space(f, "ssao", radius, repeats=repeats)
    # the same real frame (background pixels exit early in both shaders), and every pixel foreground
    g = np.concatenate([f["normal_obj"], f["mask"][..., None].astype(np.float32)], axis=-1)
    out["mlp_ms"] = {
        sz: 1e3
        * time_vector_fragment(r0["sizes"][sz]["glsl_dir"], h, w, repeats=repeats, textures={"gbuffer": g})
        for sz in sizes
    }
    out["mlp_full_ms"] = {
        sz: 1e3 * time_mlp_fragment(r0["sizes"][sz]["glsl_dir"], h, w, repeats=repeats) for sz in sizes
    }
    out["timing_mesh"] = r0["mesh"]
    out["timing_foreground"] = float(f["mask"].mean())
    out["mlp_vs_ssao"] = {sz: v / out["ssao_ms"] for sz, v in out["mlp_ms"].items()}
    return out


def paper_markdown(p: dict, sizes: list[str]) -> list[str]:
    w, h = p["size"]
    lines = [
        "",
        f"## The paper's protocol: whole-image SSIM at {w}x{h}, {p['views']} orbit views per mesh",
        "",
        "Reference: scikit-image `structural_similarity` (Gaussian sigma 1.5, population covariance, "
        "data range 1, border of 5 px excluded); `ours`: neuralao.runtime.foundation.metrics.image_ssim "
        "on the same images (edge replicated, border kept); masked: foreground pixels only. "
        "SSAO on the same frames for scale.",
        "",
        "| mesh | foreground | method | paper | whole-image SSIM (skimage) | whole-image (ours) | "
        "masked SSIM |",
        "|---|---:|---|---:|---:|---:|---:|",
    ]
    for mesh, d in p["meshes"].items():
        for key in [*sizes, "ssao"]:
            paper = PAPER_SSIM.get(mesh, (None,) * 3)[SIZES.index(key)] if key in SIZES else None
            lines.append(
                f"| {mesh} | {d['foreground_fraction']:.2f} | {'mlp-' + key if key != 'ssao' else 'ssao'} | "
                f"{fmt(paper)} | {d[key]['skimage']:.4f} | {d[key]['ours']:.4f} | {d[key]['masked']:.4f} |"
            )
    lines += [
        "",
        f"GL time at {w}x{h} (llvmpipe, same run, both on the first view of {p.get('timing_mesh')}, "
        f"{100 * p.get('timing_foreground', 0):.0f}% foreground): SSAO {p['ssao_ms']:.1f} ms; "
        + ", ".join(f"mlp-{k} {v:.1f} ms = {p['mlp_vs_ssao'][k]:.2f}x SSAO" for k, v in p["mlp_ms"].items())
        + " (the paper: NN-16x8 about 0.12x its SSAO on a GTX 1070). Every pixel foreground (worst case): "
        + ", ".join(f"mlp-{k} {v:.1f} ms" for k, v in p.get("mlp_full_ms", {}).items())
        + ".",
    ]
    return lines


def fmt(v, spec: str = ".4f") -> str:
    return "-" if v is None else format(v, spec)


def markdown(result: dict) -> str:
    s = result["settings"]
    sizes = result["sizes"]
    lines = [
        "# Baked MLP (Erra et al. 2017) on the paper's models",
        "",
        f"CPU: {result['cpu']} ({result['cores']} cores, torch threads 1, Embree 2 threads); GL: "
        f"Mesa llvmpipe. Samples: {s['views']} orbit views at {s['size'][0]}x{s['size'][1]}, "
        f"{s['samples_per_view']} pixels each, {s['labels']['rays']} rays ({s['labels']['kernel']}, "
        f"max distance {s['labels']['max_distance_rel']} x diagonal); held back: "
        f"{s['holdout_views']} views (another orbit) at {s['holdout_size'][0]}x{s['holdout_size'][1]}. "
        f"L-BFGS, at most {s['max_iterations']} iterations, early stopping. Total {result['seconds']:.0f} s.",
        "",
        "## SSIM on held-back views (network at radius zero, as deployed) next to the paper's Table 2",
        "",
        "Ours: masked SSIM over valid foreground pixels (Gaussian 11, sigma 1.5, C1 1e-4, "
        "C2 9e-4). Whole-image: the same images with the background (1 in both) included, "
        "as the paper most likely measured. Constant: the mean training AO everywhere. Ceiling: "
        "the reference against a second labelling (other seed).",
        "",
        "| mesh | size | ours (masked) | whole-image | paper | RMSE | radius 10: SSIM / RMSE | "
        "constant: SSIM / RMSE | ceiling: SSIM / RMSE |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["meshes"]:
        for size in sizes:
            z = r["sizes"][size]
            c, n = r["constant"], r["noise_ceiling"]
            lines.append(
                f"| {r['mesh']} | {size} | {fmt(z['holdout_ssim'])} | {fmt(z['holdout_ssim_full'])} | "
                f"{fmt(z['paper_ssim'])} | {fmt(z['holdout_rmse'])} | {fmt(z['holdout_ssim_r10'])} / "
                f"{fmt(z['holdout_rmse_r10'])} | {fmt(c['holdout_ssim'])} / {fmt(c['holdout_rmse'])} | "
                f"{fmt(n['ssim'])} / {fmt(n['rmse'])} |"
            )
    lines += [
        "",
        "## Training (per size) and sample error",
        "",
        "| mesh | samples | size | parameters (bytes) | iterations | training s | test RMSE | "
        "constant test RMSE |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in result["meshes"]:
        for size in sizes:
            z = r["sizes"][size]
            lines.append(
                f"| {r['mesh']} | {r['samples']} | {size} | {z['parameters']} ({z['parameter_bytes']}) "
                f"| {z['iterations']} | {z['training_seconds']:.1f} | {fmt(z['test_rmse'])} | "
                f"{fmt(r['constant']['test_rmse'])} |"
            )
    lines += [
        "",
        "## Export checks and GLSL parity (held-back frames, every foreground pixel, raw output)",
        "",
        "| mesh | size | onnxruntime vs torch | OpenCV vs onnxruntime | GLSL fp32 vs onnxruntime | "
        "GLSL fp16 storage | passed |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in result["meshes"]:
        for size in sizes:
            z = r["sizes"][size]
            lines.append(
                f"| {r['mesh']} | {size} | {z['onnxruntime_vs_torch']:.2g} | "
                f"{z['opencv_vs_onnxruntime']:.2g} | {z['parity_fp32']:.2g} | "
                f"{fmt(z['parity_fp16'], '.2g')} | {z['parity_passed']} |"
            )
    sc = result["shader_cost"]
    lines += [
        "",
        f"## Shader cost on Mesa llvmpipe at {sc['size']}x{sc['size']} (median of {sc['repeats']} frames, "
        "same run)",
        "",
        "MLP: one full-screen fragment pass, every pixel foreground (worst case). Vertex colours: "
        "the mesh drawn with one AO value per vertex (the paper's cheapest baseline). "
        "Ratio = MLP / vertex colours.",
        "",
        "| size | MLP ms | " + " | ".join(f"ratio vs {m}" for m in sc["vertex_colour_ms"]) + " |",
        "|---|---|" + "---|" * len(sc["vertex_colour_ms"]),
    ]
    for size in sizes:
        ms = sc["mlp_ms"][size]["ms"]
        ratios = " | ".join(f"{ms / v:.2f}" for v in sc["vertex_colour_ms"].values())
        lines.append(f"| {size} | {ms:.2f} | {ratios} |")
    lines.append("")
    lines.append(
        "Vertex-colour AO ms: " + ", ".join(f"{m} {v:.2f}" for m, v in sc["vertex_colour_ms"].items()) + "."
    )
    if result.get("paper_protocol"):
        lines += paper_markdown(result["paper_protocol"], sizes)
    if any("ablation_both" in r for r in result["meshes"]):
        lines += [
            "",
            "## Ablation: trained on circle inputs plus a radius-zero copy of every sample "
            "(train_inputs=both)",
            "",
            "| mesh | size | held-back SSIM (masked) | RMSE | whole-image SSIM | "
            "vs paper-faithful SSIM / RMSE |",
            "|---|---|---|---|---|---|",
        ]
        for r in result["meshes"]:
            a = r.get("ablation_both")
            if a:
                z = r["sizes"][a["size"]]
                lines.append(
                    f"| {r['mesh']} | {a['size']} | {fmt(a['holdout_ssim'])} | {fmt(a['holdout_rmse'])} | "
                    f"{fmt(a['holdout_ssim_full'])} | {fmt(z['holdout_ssim'])} / {fmt(z['holdout_rmse'])} |"
                )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="output folder (mlp.json, mlp.md, mlp/ artifacts)")
    p.add_argument(
        "--meshes", nargs="+", default=list(PAPER_SSIM), help="meshes (names under the shared folder)"
    )
    p.add_argument("--sizes", nargs="+", default=list(SIZES), help="network sizes XxY")
    p.add_argument("--views", type=int, default=128, help="orbit views to sample (paper: 128)")
    p.add_argument(
        "--size", type=int, nargs=2, default=(256, 256), metavar=("W", "H"), help="sampled view size"
    )
    p.add_argument("--holdout-views", type=int, default=8, help="held-back evaluation views")
    p.add_argument("--holdout-size", type=int, nargs=2, default=(256, 256), metavar=("W", "H"))
    p.add_argument("--rays", type=int, default=256, help="AO rays per label")
    p.add_argument("--max-iterations", type=int, default=1000, help="L-BFGS iterations at most")
    p.add_argument("--timing-size", type=int, default=512, help="shader timing resolution (square)")
    p.add_argument("--repeats", type=int, default=20, help="timed frames per measurement")
    p.add_argument("--no-ablation", action="store_true", help="skip the train_inputs=both ablation")
    p.add_argument(
        "--paper-views", type=int, default=2, help="views per mesh of the paper's protocol (0: skip)"
    )
    p.add_argument("--paper-size", type=int, nargs=2, default=(1920, 1080), metavar=("W", "H"))
    p.add_argument(
        "--paper-only",
        action="store_true",
        help="reuse OUT/mlp.json and its exports; rerun only the paper's protocol",
    )
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    out = Path(args.out)
    base = MLPSettings(
        views=args.views,
        size=tuple(args.size),
        holdout_views=args.holdout_views,
        holdout_size=tuple(args.holdout_size),
        max_iterations=args.max_iterations,
        labels=LabelSettings(rays=args.rays),
    )
    t0 = time.perf_counter()
    if args.paper_only:
        import json

        result = json.loads((out / "mlp.json").read_text())
        result["paper_protocol"] = paper_protocol(
            result["meshes"],
            result["sizes"],
            args.paper_views,
            tuple(args.paper_size),
            base.labels,
            max(3, args.repeats // 4),
        )
        write_json(out / "mlp.json", result)
        write_text(out / "mlp.md", markdown(result))
        print(markdown(result))
        return 0
    rows = [bench_mesh(m, base, args.sizes, out / "mlp", not args.no_ablation) for m in args.meshes]
    from neuralao.runtime.foundation.settings import settings_to_dict

    result = {
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "settings": settings_to_dict(base),
        "sizes": args.sizes,
        "meshes": rows,
        "shader_cost": shader_costs(rows, args.sizes, args.timing_size, args.repeats),
        "paper_ssim": PAPER_SSIM,
    }
    if args.paper_views > 0:
        result["paper_protocol"] = paper_protocol(
            rows, args.sizes, args.paper_views, tuple(args.paper_size), base.labels, max(3, args.repeats // 4)
        )
    result["seconds"] = time.perf_counter() - t0
    write_json(out / "mlp.json", result)
    write_text(out / "mlp.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
