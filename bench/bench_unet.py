"""Benchmark the DeepAO U-Net's inference cost: torch CPU, onnxruntime CPU and the generated GLSL on llvmpipe.

    PYOPENGL_PLATFORM=osmesa .venv/bin/python bench/bench_unet.py --out build/bench \
        [--sizes 512x512 1920x1080] [--repeats 5] [--checkpoint MODEL.pt] [--data DATASET]

Inference cost at 512x512 and 1920x1080 for torch CPU, onnxruntime CPU and the
generated GLSL compute passes on Mesa llvmpipe, in one run; parameters and bytes of the model;
training time per epoch. Also the same graph generated with other conv blocks
(``--compare-blocks``: texels x, y and output layers per invocation; by default the steps from one
texel of one layer to the default block) timed in the same rounds, with their compile times.

1. Model: the paper architecture (``neuralao.pipeline.models.unet`` defaults, widths 4/8/16/32) with a
   seeded random init, or ``--checkpoint`` (loaded weights_only by the project's loader). Timing does not
   depend on the weights. Exported with the project's own path: ``neuralao.export.unet.export_onnx``
   (TorchScript exporter, batch norm folded) and ``neuralao.export.unet.write_glsl`` (fp32 compute passes)
   into DIR/unet/.
2. Input per size: a real G-buffer frame of ``--mesh`` (neuralao.pipeline.gbuffers.rasterizer, first camera
   of a 4-view orbit) preprocessed with ``neuralao.pipeline.models.unet.preprocess_frame``; seeded random
   depth / normals with a background band (``neuralao.export.unet.random_input``) only if rendering fails
   (the table says which).
3. Per size, ``--repeats`` interleaved rounds (the order rotates each round) of
   (a) torch: ``PaddedUNet`` forward in eval mode under no_grad (pad, network, crop, as deployed);
   (b) onnxruntime CPU session (``neuralao.runtime.predict.ort_runner`` + ``run_padded``, as ``neuralao
       infer``);
   (c) the generated GLSL passes (pad, network, crop) through ``neuralao.runtime.glsl_runner``'s compute
       runner: input upload, dispatch of every pass, readback, each closed by ``glFinish`` and timed apart.
   The main GLSL figure is the dispatch alone (upload and readback excluded: an engine already has
   its G-buffer on the GPU and consumes the AO there); the sum with upload + readback is reported too.
   Medians over rounds; ratios ORT / torch, GLSL / torch and GLSL / ORT from the same rounds. GLSL on
   llvmpipe is slow at full HD, so sizes over one megapixel get ``--glsl-repeats-large`` GLSL rounds
   (spread over the rounds). Before each size, one untimed GLSL run at a small size of the same
   texture class (llvmpipe JIT-compiles a shader variant per power-of-two-ness of the textures), and
   one untimed torch and onnxruntime run. ``OMP_WAIT_POLICY=PASSIVE`` unless set (spinning OpenMP
   threads made 2-thread torch 20-50x slower while other processes held a core).
4. Training time per epoch: ``neuralao.pipeline.models.unet_train.train`` for ``--epochs`` epochs (default
   settings: 64-px crops, 2 crops per training frame, batch 16) on ``--data`` if given, otherwise on a tiny
   dataset built here with ``neuralao.pipeline.datasets.dataset`` (four small meshes at 128x128, 32 views,
   64 rays), reused on later runs when its config is unchanged.

Writes DIR/unet.json and DIR/unet.md (ONNX, GLSL, dataset and checkpoint under DIR/unet/).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path

import numpy as np

# Before torch loads: OpenMP threads that spin while another process holds a core made 2-thread torch
# 20-50x slower here (360 ms instead of 7 ms for a 128x128 forward); passive waiting removes that.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# Compile times are reported: Mesa's on-disk shader cache would hide them on a rerun.
os.environ.setdefault("MESA_SHADER_CACHE_DISABLE", "true")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.export.glsl.image import CONV_BLOCK  # noqa: E402
from neuralao.runtime.foundation.errors import NeuralaoError  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402

log = logging.getLogger("bench_unet")
# The radius parameter rho of the timed runs (the cost does not depend on it).
BENCH_RHO = 0.1

LARGE_PIXELS = 1_000_000  # sizes above this get --glsl-repeats-large GLSL rounds
WARMUP_SIZE = 64  # padded side of the untimed JIT warm-up for power-of-two sizes (else 3 x multiple)


def parse_block(text: str) -> tuple[int, int, int]:
    """ "8,4,2" -> (8, 4, 2)."""
    try:
        x, y, layers = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a conv block looks like 8,4,2, got {text!r}") from None
    return x, y, layers


def parse_size(text: str) -> tuple[int, int]:
    """ "WxH" -> (width, height)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 1920x1080, got {text!r}") from None
    if w < 8 or h < 8:
        raise argparse.ArgumentTypeError(f"size {text} is smaller than the U-Net's pad multiple")
    return w, h


# ----------------------------------------------------------------------------------------------- model


def build(checkpoint: Path | None, seed: int):
    """(UNet in eval mode, description, checkpoint dict or None)."""
    import torch

    from neuralao.pipeline.models.unet import UNet, UNetArgs

    if checkpoint is not None:
        from neuralao.export.unet import load_model

        model, ckpt = load_model(checkpoint)
        return model.eval(), f"checkpoint {checkpoint} (epoch {ckpt.get('epoch')})", ckpt
    torch.manual_seed(seed)
    return UNet(UNetArgs()).eval(), f"random init (torch.manual_seed({seed}))", None


def export(model, ckpt: dict | None, out: Path) -> dict:
    """model.onnx + glsl/ under ``out`` with the project's export functions; sizes and pass counts."""
    from neuralao.export.glsl import load_compute_export
    from neuralao.export.unet import export_onnx, onnx_metadata, write_glsl

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    onnx_path = out / "model.onnx"
    proto = export_onnx(model, onnx_path, onnx_metadata(model, ckpt))
    glsl_dir = write_glsl(proto, out / "glsl", "fp32")
    program = load_compute_export(glsl_dir)
    kinds: dict[str, int] = {}
    for p in program.manifest["passes"]:
        kinds[p["kind"]] = kinds.get(p["kind"], 0) + 1
    return {
        "onnx": str(onnx_path),
        "onnx_bytes": onnx_path.stat().st_size,
        "onnx_ops": sorted({n.op_type for n in proto.graph.node}),
        "glsl_dir": str(glsl_dir),
        "glsl_passes": len(program.manifest["passes"]),
        "glsl_pass_kinds": kinds,
        "glsl_weights_bytes": int(program.manifest["weights"]["bytes"]),
        "pad_multiple": program.pad_multiple,
        "seconds": time.perf_counter() - t0,
        "_program": program,
    }


# ----------------------------------------------------------------------------------------------- input


def make_input(mesh: str, width: int, height: int, seed: int) -> tuple[np.ndarray, str, float]:
    """(x (4, H, W) float32 network input, its source in words, foreground fraction)."""
    from neuralao.runtime.unet_input import preprocess_frame

    try:
        from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
        from neuralao.pipeline.geometry.camera import orbit
        from neuralao.pipeline.geometry.scene import load_scene

        scene = load_scene(mesh)
        frame = render_gbuffer(scene, orbit(scene, 4, width, height, seed=1)[0])
        x = preprocess_frame(frame)
        return (
            x,
            f"G-buffer of `{scene.name}` (neuralao.pipeline.gbuffers.rasterizer)",
            float(np.mean(frame["mask"])),
        )
    except (ImportError, NeuralaoError) as e:
        log.warning("cannot render %s (%s); using a random input", mesh, e)
        from neuralao.export.unet import random_input

        x = random_input(width, height, seed)
        return x, "seeded random depth/normals (neuralao.export.unet.random_input)", float(np.mean(x[0] > 0))


# ----------------------------------------------------------------------------------------------- timing


def glsl_rounds(repeats: int, n: int) -> set[int]:
    """Which of ``repeats`` rounds run GLSL when only ``n`` may: spread evenly."""
    n = max(1, min(n, repeats))
    return {int(round(v)) for v in np.linspace(0, repeats - 1, n)}


def time_size(
    model, ort, program, x: np.ndarray, repeats: int, glsl_n: int, others: dict | None = None
) -> dict:
    """Interleaved rounds of torch / onnxruntime / GLSL on one input; medians, ratios, differences.

    others : {label: ComputeProgram} of the same graph generated with other conv blocks, timed in the
    same rounds (``glsl_variants``)."""
    import torch

    from neuralao.pipeline.models.unet import PaddedUNet
    from neuralao.runtime import gl
    from neuralao.runtime.glsl_runner import _ComputeRun
    from neuralao.runtime.predict import run_padded

    h, w = x.shape[-2:]
    m = model.pad_multiple
    padded = PaddedUNet(model).eval()

    def run_torch() -> np.ndarray:
        with torch.no_grad():
            return padded(torch.from_numpy(x)[None], torch.full((1, 1, 1, 1), BENCH_RHO))[0, 0].numpy()

    threads = torch.get_num_threads()

    def run_torch1() -> np.ndarray:
        torch.set_num_threads(1)
        try:
            return run_torch()
        finally:
            torch.set_num_threads(threads)

    def run_ort() -> np.ndarray:
        return run_padded(ort, x, m, BENCH_RHO)

    out_spec = program.manifest["outputs"][0]
    run = _ComputeRun(program, h, w, scalars={"radius": BENCH_RHO})
    variants = {
        label: _ComputeRun(prog, h, w, scalars={"radius": BENCH_RHO})
        for label, prog in (others or {}).items()
    }
    x_gl = np.ascontiguousarray(x[None])
    glsl_out: dict[str, np.ndarray] = {}

    def run_program(r, key: str) -> dict[str, float]:
        t0 = time.perf_counter()
        r.upload(x_gl)
        gl.finish()
        t1 = time.perf_counter()
        r.dispatch()
        gl.finish()
        t2 = time.perf_counter()
        y = r.read(out_spec["texture"], out_spec["channels"])
        t3 = time.perf_counter()
        glsl_out[key] = y[0, 0]
        return {"upload": t1 - t0, "dispatch": t2 - t1, "readback": t3 - t2, "total": t3 - t0}

    def run_glsl() -> dict[str, float]:
        return run_program(run, "y")

    def run_variant(label: str) -> float:  # dispatch only
        return run_program(variants[label], label)["dispatch"]

    try:
        y_torch, y_ort = run_torch(), run_ort()  # untimed warm-up (and the outputs for the sanity check)
        run_torch1()
        fns = {"torch": run_torch, "torch_1thread": run_torch1, "onnxruntime": run_ort}
        times: dict[str, list] = {"torch": [], "torch_1thread": [], "onnxruntime": [], "glsl": []}
        times.update({label: [] for label in variants})
        with_glsl = glsl_rounds(repeats, glsl_n)
        for label in variants:  # untimed first dispatch at this size
            run_variant(label)
        for r in range(repeats):
            order = ["torch", "onnxruntime", "glsl", "torch_1thread", *variants]
            order = order[r % len(order) :] + order[: r % len(order)]
            for name in order:
                if name == "glsl":
                    if r in with_glsl:
                        times["glsl"].append(run_glsl())
                    continue
                if name in variants:
                    if r in with_glsl:
                        times[name].append(run_variant(name))
                    continue
                t0 = time.perf_counter()
                fns[name]()
                times[name].append(time.perf_counter() - t0)
            log.info(
                "%dx%d round %d/%d: torch %.0f ms, ort %.0f ms%s",
                w,
                h,
                r + 1,
                repeats,
                1e3 * times["torch"][-1],
                1e3 * times["onnxruntime"][-1],
                f", glsl {1e3 * times['glsl'][-1]['dispatch']:.0f} ms" if r in with_glsl else "",
            )
    finally:
        run.release()
        for v in variants.values():
            v.release()
    y_gl = glsl_out["y"][:h, :w]
    med = lambda v: float(np.median(v))  # noqa: E731
    g = {k: med([t[k] for t in times["glsl"]]) for k in ("upload", "dispatch", "readback", "total")}
    t_torch, t_ort = med(times["torch"]), med(times["onnxruntime"])
    return {
        "size": [w, h],
        "rounds": repeats,
        "glsl_rounds": len(times["glsl"]),
        "torch_ms": 1e3 * t_torch,
        "torch_1thread_ms": 1e3 * med(times["torch_1thread"]),
        "torch_threads": threads,
        "onnxruntime_ms": 1e3 * t_ort,
        "glsl_ms": 1e3 * g["dispatch"],
        "glsl_upload_ms": 1e3 * g["upload"],
        "glsl_readback_ms": 1e3 * g["readback"],
        "glsl_with_transfers_ms": 1e3 * g["total"],
        "ratio_ort_torch": t_ort / t_torch,
        "ratio_glsl_torch": g["dispatch"] / t_torch,
        "ratio_glsl_ort": g["dispatch"] / t_ort,
        "best_ms": {
            "torch": 1e3 * min(times["torch"]),
            "torch_1thread": 1e3 * min(times["torch_1thread"]),
            "onnxruntime": 1e3 * min(times["onnxruntime"]),
            "glsl": 1e3 * min(t["dispatch"] for t in times["glsl"]),
        },
        "per_round_ms": {
            "torch": [1e3 * t for t in times["torch"]],
            "torch_1thread": [1e3 * t for t in times["torch_1thread"]],
            "onnxruntime": [1e3 * t for t in times["onnxruntime"]],
            "glsl": [{k: 1e3 * v for k, v in t.items()} for t in times["glsl"]],
        },
        "glsl_variants": {
            label: {
                "ms": 1e3 * med(times[label]),
                "ratio_ort": med(times[label]) / t_ort,
                "speedup_of_default": med(times[label]) / g["dispatch"],
                "max_abs_vs_ort": float(np.abs(glsl_out[label][:h, :w] - y_ort).max()),
            }
            for label in variants
        },
        "max_abs_glsl_vs_ort": float(np.abs(y_gl - y_ort).max()),
        "max_abs_ort_vs_torch": float(np.abs(y_ort - y_torch).max()),
    }


def _pot(n: int) -> bool:
    return n > 0 and n & (n - 1) == 0


def warmup_size(width: int, height: int, multiple: int) -> tuple[int, int]:
    """A small size whose textures have the same power-of-two-ness as those of ``width`` x ``height``.

    llvmpipe compiles a shader variant per texture state, which includes whether each dimension is
    a power of two, on the first dispatch that meets it (seconds per pass). Padded size m q: every
    level m q / 2^i is a power of two iff q is; the raw size keeps its padding amount (0..m-1), which
    decides its own power-of-two-ness the same way.
    """

    def side(n: int) -> int:
        q = -(-n // multiple)
        qs = WARMUP_SIZE // multiple if _pot(q) else 3
        return qs * multiple - (q * multiple - n)

    return side(width), side(height)


def warm_glsl(program, width: int, height: int, done: set) -> float:
    """Run every pass once, untimed, at a small size of the same texture class (JIT compiles)."""
    from neuralao.runtime.glsl_runner import run_compute

    size = warmup_size(width, height, program.pad_multiple)
    if size in done:
        return 0.0
    done.add(size)
    t0 = time.perf_counter()
    c = program.manifest["input"]["channels"]
    run_compute(program, np.zeros((1, c, size[1], size[0]), np.float32), scalars={"radius": BENCH_RHO})
    return time.perf_counter() - t0


# ----------------------------------------------------------------------------------------------- training


def tiny_dataset_settings(meshes: list[str], views: int, rays: int):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec
    from neuralao.pipeline.tracing.labeller import LabelSettings

    scenes = [
        SceneSpec(
            name=m, mesh=m, cameras="orbit", views=views, split="train" if i < len(meshes) - 1 else "val"
        )
        for i, m in enumerate(meshes)
    ]
    if len(scenes) == 1:
        scenes[0].split = "train"
    return DatasetSettings(
        name="bench-unet", scenes=scenes, size=(128, 128), labels=LabelSettings(rays=rays), seed=0
    )


def tiny_dataset(out: Path, meshes: list[str], views: int, rays: int) -> dict:
    """Build (or reuse, when its config is unchanged) a small dataset; returns where and how long."""
    from neuralao.pipeline.datasets.dataset import build_dataset
    from neuralao.runtime.foundation.settings import settings_to_dict

    settings = tiny_dataset_settings(meshes, views, rays)
    config = json.loads(json.dumps(settings_to_dict(settings)))
    manifest_path = out / "manifest.json"
    if manifest_path.is_file():
        try:
            if json.loads(manifest_path.read_text()).get("config") == config:
                return {"path": str(out), "built": False, "seconds": 0.0}
        except json.JSONDecodeError:
            pass
    t0 = time.perf_counter()
    build_dataset(settings, out, progress=False)
    return {"path": str(out), "built": True, "seconds": time.perf_counter() - t0}


def training_cost(args: argparse.Namespace, out: Path) -> dict:
    """Seconds per epoch of neuralao.pipeline.models.unet_train.train (default settings, ``--epochs``
    epochs)."""
    import torch

    from neuralao.pipeline.models.unet_frames import load_dataset_frames
    from neuralao.pipeline.models.unet_train import UNetTrainSettings, train

    if args.no_train:
        return {"skipped": "--no-train"}
    if args.data is not None:
        if not (args.data / "manifest.json").is_file():
            return {"skipped": f"no finished dataset at {args.data} (no manifest.json)"}
        data = {"path": str(args.data), "built": False, "seconds": 0.0, "source": "--data"}
    else:
        data = tiny_dataset(out / "dataset", args.train_meshes, args.train_views, args.train_rays)
        data["source"] = (
            f"tiny dataset built here: {', '.join(args.train_meshes)} (last one = val scene), "
            f"{args.train_views} orbit views each at 128x128, {args.train_rays} rays"
        )
    train_set, val_set, info = load_dataset_frames(Path(data["path"]))
    settings = UNetTrainSettings(epochs=args.epochs)
    threads = torch.get_num_threads()
    ckpt = train(settings, train_set, val_set, out / "train.pt", info, restart=True, progress=False)
    hist = ckpt["history"]
    crops = settings.crops_per_frame * len(train_set)
    train_s = [h["train_seconds"] for h in hist]
    return {
        "dataset": data,
        "train_frames": len(train_set),
        "val_frames": len(val_set) if val_set is not None else 0,
        "val_source": info.get("val_source"),
        "frame_size": list(train_set.x.shape[-2:][::-1]),
        "epochs": len(hist),
        "crops_per_epoch": crops,
        "crop": settings.crop,
        "batch_size": settings.batch_size,
        "batches_per_epoch": -(-crops // settings.batch_size),
        "torch_threads": threads,
        "train_seconds_per_epoch": train_s,
        "seconds_per_epoch_with_validation": [h["seconds"] for h in hist],
        "median_train_seconds_per_epoch": float(np.median(train_s)),
        "ms_per_crop": 1e3 * float(np.median(train_s)) / crops,
        "final_train_loss": hist[-1]["train_loss"],
    }


# ----------------------------------------------------------------------------------------------- report


def markdown(result: dict) -> str:
    mdl, ex = result["model"], result["export"]
    lines = [
        "# DeepAO U-Net inference cost",
        "",
        f"Model: widths {mdl['widths']}, {mdl['source']}. CPU: {result['cpu']} ({result['cores']} cores; "
        f"load average {result['loadavg_before'][0]:.2f} before, {result['loadavg_after'][0]:.2f} after - "
        f"other processes share the cores, so compare ratios from this run). GL: {result['gl_renderer']} "
        f"({result['gl_version']}). Threads: torch {result['threads']['torch']}, onnxruntime "
        f"{result['threads']['onnxruntime']}, llvmpipe LP_NUM_THREADS={result['threads']['llvmpipe']}. "
        f"Total {result['seconds']:.0f} s.",
        "",
        "## Model",
        "",
        "| parameters | fp32 bytes | ONNX file bytes | ONNX ops | GLSL passes | GLSL weights.bin bytes |",
        "|---|---|---|---|---|---|",
        f"| {mdl['parameters']} | {mdl['bytes_fp32']} | {ex['onnx_bytes']} | {', '.join(ex['onnx_ops'])} | "
        f"{ex['glsl_passes']} ({', '.join(f'{v} {k}' for k, v in ex['glsl_pass_kinds'].items())}) | "
        f"{ex['glsl_weights_bytes']} (256-byte aligned ranges) |",
        "",
        "## Inference, median ms per frame (interleaved rounds, same run)",
        "",
        "torch: `PaddedUNet` forward, eval, no_grad (pad, network, crop), "
        f"{result['threads']['torch']} threads (OMP_WAIT_POLICY={result['threads']['omp_wait_policy']}), "
        "and the same on 1 thread. onnxruntime: CPU session, reflect pad + run + crop as `neuralao infer`. "
        "GLSL: all generated compute passes (pad, network, crop) on llvmpipe, closed by glFinish; "
        "**upload and readback excluded** in the GLSL column, included in the column after it. "
        "Ratios use the multi-thread torch and the GLSL column. Differences: max |.| "
        "over all pixels of the raw network output on the timed input.",
        "",
        "| size | input (foreground) | torch CPU | torch CPU 1 thread | onnxruntime CPU | "
        "GLSL llvmpipe (upload excl.) | GLSL + upload + readback | ORT / torch | GLSL / torch | "
        "GLSL / ORT | rounds (GLSL) | GLSL vs ORT | ORT vs torch |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["sizes"]:
        w, h = r["size"]
        lines.append(
            f"| {w}x{h} | {r['input']} ({100 * r['foreground']:.0f}%) | {r['torch_ms']:.1f} | "
            f"{r['torch_1thread_ms']:.1f} | "
            f"{r['onnxruntime_ms']:.1f} | {r['glsl_ms']:.0f} | {r['glsl_with_transfers_ms']:.0f} | "
            f"{r['ratio_ort_torch']:.2f} | {r['ratio_glsl_torch']:.1f} | {r['ratio_glsl_ort']:.1f} | "
            f"{r['rounds']} ({r['glsl_rounds']}) | {r['max_abs_glsl_vs_ort']:.1e} | "
            f"{r['max_abs_ort_vs_torch']:.1e} |"
        )
    labels = list(result["sizes"][0].get("glsl_variants", {})) if result["sizes"] else []
    if labels:
        default = "x".join(map(str, result["conv_block"]))
        lines += [
            "",
            f"## Generated conv passes: texels x texels x output layers per invocation (default {default})",
            "",
            "The same graph generated with other conv blocks, timed in the same rounds (dispatch only). "
            "Speed-up = that block's time / the default's. Compile = untimed first run(s) at the warm-up "
            "size(s), shader cache off.",
            "",
            "| conv block | "
            + " | ".join(f"{r['size'][0]}x{r['size'][1]} ms (/ ORT)" for r in result["sizes"])
            + " | speed-up of the default | compile s | max abs vs ORT |",
            "|---|" + "---|" * (len(result["sizes"]) + 3),
            f"| **{default}** (default) | "
            + " | ".join(f"{r['glsl_ms']:.0f} ({r['ratio_glsl_ort']:.1f})" for r in result["sizes"])
            + (
                f" | 1 | {result['glsl_warmup_s']:.1f} | "
                f"{max(r['max_abs_glsl_vs_ort'] for r in result['sizes']):.1e} |"
            ),
        ]
        for label in labels:
            v = [r["glsl_variants"][label] for r in result["sizes"]]
            lines.append(
                f"| {label} | "
                + " | ".join(f"{x['ms']:.0f} ({x['ratio_ort']:.1f})" for x in v)
                + " | "
                + ", ".join(f"{x['speedup_of_default']:.1f}x" for x in v)
                + (
                    f" | {result['glsl_variant_warmup_s'][label]:.1f} | "
                    f"{max(x['max_abs_vs_ort'] for x in v):.1e} |"
                )
            )
    lines += [
        "",
        "GLSL upload / readback ms: "
        + "; ".join(
            f"{r['size'][0]}x{r['size'][1]} {r['glsl_upload_ms']:.0f} / {r['glsl_readback_ms']:.0f}"
            for r in result["sizes"]
        )
        + ". Shader JIT warm-up (untimed, small sizes of the same texture class: "
        + (
            f"{', '.join(f'{a}x{b}' for a, b in result['glsl_warmup_sizes'])}): "
            f"{result['glsl_warmup_s']:.1f} s."
        ),
        "",
        "## Training time per epoch (`neuralao.pipeline.models.unet_train.train`, default settings)",
        "",
    ]
    t = result["training"]
    if "skipped" in t:
        lines.append(f"Skipped: {t['skipped']}.")
    else:
        d = t["dataset"]
        built = f"built in {d['seconds']:.0f} s" if d["built"] else "reused"
        lines += [
            f"Dataset: {d['source']} ({d['path']}, {built}); {t['train_frames']} training frames "
            f"{t['frame_size'][0]}x{t['frame_size'][1]}, {t['val_frames']} validation frames "
            f"({t['val_source']}). Torch threads {t['torch_threads']}, "
            "deterministic algorithms (as `neuralao train unet`).",
            "",
            "| epochs | crops / epoch (crop px, batch) | batches / epoch | train s / epoch (median) | "
            "per epoch incl. validation s | ms / crop |",
            "|---|---|---|---|---|---|",
            f"| {t['epochs']} | {t['crops_per_epoch']} ({t['crop']}, {t['batch_size']}) "
            f"| {t['batches_per_epoch']} | {t['median_train_seconds_per_epoch']:.2f} "
            f"({', '.join(f'{v:.2f}' for v in t['train_seconds_per_epoch'])}) "
            f"| {', '.join(f'{v:.2f}' for v in t['seconds_per_epoch_with_validation'])} | "
            f"{t['ms_per_crop']:.1f} |",
            "",
            "An epoch is `crops_per_frame` (2) random 64-px crops of every training frame, so its time "
            "scales with the dataset: multiply ms / crop by 2 x the training frames of another dataset.",
        ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, type=Path, help="output folder (unet.json, unet.md, unet/)")
    p.add_argument(
        "--sizes", nargs="+", type=parse_size, default=[(512, 512), (1920, 1080)], help="WxH sizes"
    )
    p.add_argument("--repeats", type=int, default=5, help="interleaved timing rounds (median kept)")
    p.add_argument(
        "--glsl-repeats-large",
        type=int,
        default=3,
        help=f"GLSL rounds at sizes over {LARGE_PIXELS} pixels (llvmpipe needs ~45 s per 1920x1080 frame)",
    )
    p.add_argument("--checkpoint", type=Path, help="U-Net checkpoint MODEL.pt (default: seeded random init)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random init (and random input)")
    p.add_argument("--mesh", default="spot", help="mesh rendered as the timed G-buffer")
    p.add_argument(
        "--data", type=Path, help="existing dataset for the training timing (skips the tiny build)"
    )
    p.add_argument("--epochs", type=int, default=3, help="training epochs timed")
    p.add_argument(
        "--train-meshes",
        nargs="+",
        default=["spot", "cow", "teapot", "fandisk"],
        help="meshes of the tiny dataset (the last one is its val scene)",
    )
    p.add_argument("--train-views", type=int, default=32, help="orbit views per mesh of the tiny dataset")
    p.add_argument("--train-rays", type=int, default=64, help="AO rays per pixel of the tiny dataset")
    p.add_argument("--no-train", action="store_true", help="skip the training timing")
    p.add_argument(
        "--compare-blocks",
        nargs="*",
        type=parse_block,
        default=[(1, 1, 1), (4, 4, 1), (8, 4, 1)],
        metavar="X,Y,L",
        help="conv blocks (texels x, y, output layers per invocation) timed beside the default "
        f"{CONV_BLOCK} in the same rounds; the default list is the steps to it: one texel of "
        "one layer (before), 4x4 texels, 8x4 texels",
    )
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if args.repeats < 1 or args.glsl_repeats_large < 1 or args.epochs < 1:
        p.error("--repeats, --glsl-repeats-large and --epochs must be >= 1")
    try:
        return run(args)
    except NeuralaoError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1


def run(args: argparse.Namespace) -> int:
    import torch

    from neuralao.pipeline.models.checkpoint import count_parameters
    from neuralao.runtime import gl
    from neuralao.runtime.predict import ort_runner

    t_start = time.perf_counter()
    out = args.out
    work = out / "unet"
    load_before = os.getloadavg()
    model, source, ckpt = build(args.checkpoint, args.seed)
    n_params = count_parameters(model)
    ex = export(model, ckpt, work / "export")
    program = ex.pop("_program")
    log.info("exported: %d parameters, %d GLSL passes (%.1f s)", n_params, ex["glsl_passes"], ex["seconds"])
    ort = ort_runner(ex["onnx"])
    info = gl.context().info
    default_block = tuple(CONV_BLOCK)
    others = {}
    from neuralao.export.glsl import generate_compute
    from neuralao.export.onnx_io import load_onnx

    proto = load_onnx(ex["onnx"])
    for blk in args.compare_blocks:
        if blk != default_block:
            others["x".join(map(str, blk))] = generate_compute(proto, conv_block=blk)
    warm_s, warmed = 0.0, set()
    warm_variants = {label: 0.0 for label in others}
    warmed_variants: dict[str, set] = {label: set() for label in others}
    rows = []
    for w, h in args.sizes:
        warm_s += warm_glsl(program, w, h, warmed)
        for label, prog in others.items():
            warm_variants[label] += warm_glsl(prog, w, h, warmed_variants[label])
        x, input_source, fg = make_input(args.mesh, w, h, args.seed)
        glsl_n = args.repeats if w * h <= LARGE_PIXELS else args.glsl_repeats_large
        row = time_size(model, ort, program, x, args.repeats, glsl_n, others)
        row["input"], row["foreground"] = input_source, fg
        rows.append(row)
        log.info(
            "%dx%d: torch %.1f ms, ort %.1f ms, glsl %.0f ms",
            w,
            h,
            row["torch_ms"],
            row["onnxruntime_ms"],
            row["glsl_ms"],
        )
    t0 = time.perf_counter()
    training = training_cost(args, work)
    log.info("training timing: %.0f s", time.perf_counter() - t0)
    result = {
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "gl_renderer": info.renderer,
        "gl_version": info.version,
        "gl_platform": info.platform,
        "threads": {
            "torch": torch.get_num_threads(),
            "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
            "onnxruntime": 2,  # neuralao.export.onnx_io.ort_session: intra_op_num_threads = 2
            "llvmpipe": os.environ.get("LP_NUM_THREADS", f"unset (Mesa default: {os.cpu_count()} cores)"),
        },
        "model": {
            "source": source,
            "widths": list(model.args.widths),
            "parameters": n_params,
            "bytes_fp32": 4 * n_params,
            "pad_multiple": model.pad_multiple,
        },
        "export": ex,
        "glsl_warmup_s": warm_s,
        "conv_block": list(default_block),
        "glsl_variant_warmup_s": warm_variants,
        "glsl_warmup_sizes": sorted(warmed),
        "settings": {
            "repeats": args.repeats,
            "glsl_repeats_large": args.glsl_repeats_large,
            "large_pixels": LARGE_PIXELS,
            "mesh": args.mesh,
            "seed": args.seed,
            "timing": (
                "median over interleaved rounds; GLSL dispatch timed to glFinish, upload/readback apart"
            ),
        },
        "sizes": rows,
        "training": training,
        "loadavg_before": load_before,
        "loadavg_after": os.getloadavg(),
    }
    result["seconds"] = time.perf_counter() - t_start
    write_json(out / "unet.json", result)
    write_text(out / "unet.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
