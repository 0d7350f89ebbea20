"""U-Net export: ONNX (dynamic H, W) + generated GLSL + manifest; backend checks, GLSL parity, inference.

The ONNX graph is the raw :class:`neuralao.pipeline.models.unet.UNet` (H, W multiples of ``pad_multiple``);
padding stays outside it. Every consumer here goes through :func:`run_padded`: preprocess the frame with
:func:`neuralao.pipeline.models.unet.preprocess_frame`, reflect-pad bottom/right to the multiple, run, crop
back, and set background pixels to AO 1. The metadata of the ONNX file states all of it in words.

Exporters: the TorchScript exporter (``dynamo=False``, the shipped model.onnx) folds batch norm into
the preceding conv in eval mode. :func:`export_onnx_dynamo` is the second path: the dynamo exporter
without graph optimisation keeps ``BatchNormalization`` nodes and emits the Resize scales as
``Constant`` nodes, which are moved into initializers here so the graph holds only the ops the GLSL
generator knows.
"""

from __future__ import annotations

import contextlib
import io
import logging
import time
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path

import cv2
import numpy as np
import onnx
import torch
from onnx import numpy_helper

from neuralao.export.glsl import generate_compute, spirv_cross_available, write_compute_export
from neuralao.export.glsl.frame import generate_frame
from neuralao.export.manifest import OPSET
from neuralao.export.onnx_io import (
    backend_checks,
    load_onnx,
    run_opencv,
    save_onnx,
)
from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
from neuralao.pipeline.geometry.camera import interior, orbit
from neuralao.pipeline.geometry.compose import ComposeSettings, compose
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.models.checkpoint import count_parameters
from neuralao.pipeline.models.unet import UNet, predict
from neuralao.pipeline.models.unet_train import load_checkpoint, model_from_checkpoint
from neuralao.runtime.baselines import (
    GTAOSettings,
    blur_source,
    fragment_source,
    gtao_pass_description,
    hybrid_gtao,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import sha256_file, write_json, write_text
from neuralao.runtime.foundation.limits import check_int_range
from neuralao.runtime.foundation.manifest import read_manifest
from neuralao.runtime.foundation.metadata import MAX_INTERNAL_HEIGHT, MIN_INTERNAL_HEIGHT
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.frame_runner import FrameRunner, frame_program, model_frame_settings
from neuralao.runtime.glsl_runner import load_compute_export, run_compute
from neuralao.runtime.internal_resolution import downsample_source, upsample_source, vertex_source

# onnxruntime inference is the consumer runtime's (one copy); re-exported for the export checks and callers.
from neuralao.runtime.predict import (
    UNET_INPUT,
    UNET_RADIUS,
    Runner,
    check_unet_onnx,
    is_hybrid,
    ort_runner,
    radius_array,
    reads_gtao_raw,
    run_padded,
    unet_predictor,
)
from neuralao.runtime.unet_input import (
    DESCRIPTIONS,
    PAD_MODE,
    check_version,
    hybrid_description,
    hybrid_gtao_blur,
    preprocess_frame,
    radius_of_param,
)

log = logging.getLogger(__name__)

INPUT, RADIUS, OUTPUT = UNET_INPUT, UNET_RADIUS, "ao"
# Radius parameters (rho) of the export-time checks and of parity: a small and a large radius on screen.
# Radius parameters the backend and GLSL checks run at, per preprocessing version (version 3's reach the
# radius channel's cap on the check inputs' depths around 1, and its small end).
CHECK_RHOS: dict[int, tuple[float, ...]] = {2: (0.05, 0.4)} | {v: (-1.5, 0.5, 2.5) for v in (3, 4, 5)}
# The composed room of the fp16 check: primitives only (no mesh to load), two walls, objects on the floor.
PARITY_ROOM = ComposeSettings(seed=3, objects=(6, 6), mesh_fraction=0.0, walls=(2, 2), ceiling=0.0)
# The fp16 bound's radii: wider, to the small radii (a few pixels) where fp16's rounding of the network's
# features moves the AO most.
FP16_RHOS: dict[int, tuple[float, ...]] = {2: (0.05, 0.2, 0.4)} | {
    v: (-3.0, -2.0, -1.0, 0.5, 2.5) for v in (3, 4, 5)
}
# Sizes (width, height) of the export-time backend checks: a power of two, a non-square multiple of
# 8, odd sizes that need padding on both axes (through the pad/crop wrapper).
CHECK_SIZES: tuple[tuple[int, int], ...] = ((64, 64), (96, 72), (101, 67), (37, 53))
# A model's fp16 bound: its largest measured fp16 error on the export's check frames times this margin
# (frames the check did not see), rounded up to two significant digits, and never below the project's
# TOL.parity_fp16 (the release models' worst test-split frame measured 2.2x the check frames' largest).
FP16_BOUND_MARGIN = 3.0
# Half an 8-bit AO step (1 / 510): an fp16 error below it does not show in an 8-bit AO target.
FP16_INVISIBLE_IN_8_BIT = 1.0 / 510.0
# Parity sizes: the frames' own size, plus crops to a non-power-of-two and an odd size.
PARITY_SIZES: tuple[tuple[int, int], ...] = ((96, 72), (101, 67))


# ----------------------------------------------------------------------------------------------- loading


def load_model(ckpt_path: str | Path) -> tuple[UNet, dict]:
    """(model in eval mode, checkpoint dict) from a U-Net checkpoint (weights_only load, kind checked)."""
    ckpt = load_checkpoint(ckpt_path)
    return model_from_checkpoint(ckpt), ckpt


def onnx_metadata(model: UNet, ckpt: dict | None = None, internal_height: int | None = None) -> dict:
    """Metadata for ``metadata_props``: input semantics, units, padding contract, provenance, error.
    ``internal_height``: the rows the network runs at, when not the rows it trained at."""
    ckpt = ckpt or {}
    dataset = ckpt.get("dataset", {})
    trained_height = dataset.get("internal_height") or None
    metrics = {
        k: v
        for k, v in ckpt.get("metrics", {}).items()
        if k in ("val_ssim", "val_rmse", "val_frames", "per_scene")
    }
    meta = {
        "neuralao_kind": "unet",
        **DESCRIPTIONS[int(model.args.preprocess_version)],
        **(
            hybrid_description(
                int(model.args.preprocess_version),
                bool(model.args.gtao_blur),
                bool(model.args.gtao_raw_input),
            )
            if model.args.gtao_input
            else {}
        ),
        "pad_multiple": str(model.pad_multiple),
        "pad_mode": PAD_MODE,
        "model_args": {"widths": list(model.args.widths), "negative_slope": model.args.negative_slope},
        "parameters": str(count_parameters(model)),
        "training_scenes": dataset.get("training_scenes", []),
        "validation_scenes": dataset.get("val_scenes", []),
        "validation_error": metrics,
        "ao_labels": dataset.get("labels") or {},
        "dataset_hash": dataset.get("dataset_hash") or "",
        "epochs": str(ckpt.get("epoch", 0)),
        "scale": str(model.args.scale),
        # rows inference resamples frames to (neuralao.runtime.internal_resolution): the rows the training
        # frames were resampled to unless the export chose others
        "internal_height": str(internal_height or trained_height or ""),
        **(
            {"trained_internal_height": str(trained_height or "")}
            if internal_height and internal_height != trained_height
            else {}
        ),
        "trained_radii_rel": (dataset.get("labels") or {}).get("radii_rel") or [],
        "training": {
            "plan": ckpt.get("plan", {}),
            "wall_seconds": ckpt.get("wall_seconds"),
            "device": ckpt.get("device"),
            "budget_minutes": ckpt.get("config", {}).get("budget_minutes"),
        },
    }
    return meta


# ----------------------------------------------------------------------------------------------- exporters


def _dummy(model: UNet, size: int = 64) -> tuple[torch.Tensor, torch.Tensor]:
    m = model.pad_multiple
    s = max(m, (size // m) * m)
    return torch.zeros(1, model.args.in_channels, s, s), torch.full((1, 1, 1, 1), 0.1)


def _input_names(model: UNet) -> list[str]:
    return [INPUT, RADIUS] if model.args.radius_input else [INPUT]


def export_onnx(model: UNet, path: str | Path, metadata: dict | None = None) -> onnx.ModelProto:
    """TorchScript exporter (``dynamo=False``), opset 17, dynamic H and W; checked and written atomically."""
    model = model.eval()
    buf = io.BytesIO()
    with torch.no_grad():
        torch.onnx.export(
            model,
            _dummy(model),
            buf,
            dynamo=False,
            opset_version=OPSET,
            input_names=_input_names(model),
            output_names=[OUTPUT],
            dynamic_axes={INPUT: {2: "height", 3: "width"}, OUTPUT: {2: "height", 3: "width"}},
            do_constant_folding=True,
        )
    proto = onnx.load_from_string(buf.getvalue())
    save_onnx(proto, path, metadata if metadata is not None else onnx_metadata(model))
    return proto


def constants_to_initializers(proto: onnx.ModelProto) -> onnx.ModelProto:
    """Move ``Constant`` nodes (tensor values) into graph initializers, in place; returns ``proto``."""
    dtypes = {
        "value_float": np.float32,
        "value_floats": np.float32,
        "value_int": np.int64,
        "value_ints": np.int64,
    }
    graph = proto.graph
    keep = []
    for node in graph.node:
        attr = node.attribute[0] if node.op_type == "Constant" and len(node.attribute) == 1 else None
        if attr is not None and attr.name == "value":
            t = onnx.TensorProto()
            t.CopyFrom(attr.t)
            t.name = node.output[0]
            graph.initializer.append(t)
        elif attr is not None and attr.name in dtypes:
            value = np.asarray(onnx.helper.get_attribute_value(attr), dtype=dtypes[attr.name])
            graph.initializer.append(numpy_helper.from_array(value, node.output[0]))
        else:
            keep.append(node)
    del graph.node[:]
    graph.node.extend(keep)
    return proto


def export_onnx_dynamo(
    model: UNet, path: str | Path | None = None, metadata: dict | None = None
) -> onnx.ModelProto:
    """Dynamo exporter (torch.export + onnxscript) WITHOUT graph optimisation: keeps BatchNormalization.

    H and W are dynamic as ``pad_multiple * k``; the symbolic dim names are renamed to height/width.
    Written (checked, atomically) when ``path`` is given.
    """
    model = model.eval()
    m = model.pad_multiple
    h = torch.export.Dim("h", min=1, max=4096)
    w = torch.export.Dim("w", min=1, max=4096)
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        program = torch.onnx.export(
            model,
            _dummy(model),
            dynamo=True,
            input_names=_input_names(model),
            output_names=[OUTPUT],
            dynamic_shapes={"x": {2: m * h, 3: m * w}, "radius": None},
            optimize=False,
            verbose=False,
        )
    proto = constants_to_initializers(program.model_proto)
    for vi in list(proto.graph.input) + list(proto.graph.output):
        dims = vi.type.tensor_type.shape.dim
        if vi.name != RADIUS:
            dims[2].dim_param, dims[3].dim_param = "height", "width"
    if path is not None:
        save_onnx(proto, path, metadata if metadata is not None else onnx_metadata(model))
    return proto


# ----------------------------------------------------------------------------------------------- runners


@contextlib.contextmanager
def quiet_opencv() -> Iterator[None]:
    """OpenCV's logging at errors only, restored after: its dnn module writes a ``[ WARN:0@...]
    setPreferableTarget`` line to stderr for every network it runs (its graph engine ignores the target),
    which is no news to a user; errors still raise."""
    logs = getattr(getattr(cv2, "utils", None), "logging", None)
    if logs is None:  # a build without the logging utilities
        yield
        return
    previous = logs.getLogLevel()
    logs.setLogLevel(logs.LOG_LEVEL_ERROR)
    try:
        yield
    finally:
        logs.setLogLevel(previous)


def opencv_runner(path: str | Path) -> Runner:
    def run(xp: np.ndarray, rho: float) -> np.ndarray:
        with quiet_opencv():
            return run_opencv(path, {INPUT: xp, RADIUS: radius_array(rho)})

    return run


def glsl_runner(glsl_dir: str | Path) -> Runner:
    program = load_compute_export(glsl_dir)
    return lambda xp, rho: run_compute(
        program, np.ascontiguousarray(xp, dtype=np.float32), scalars={RADIUS: rho}
    )


def random_input(width: int, height: int, seed: int = 0, channels: int = 4) -> np.ndarray:
    """A G-buffer-like network input (C, H, W) float32: smooth depth around 1, unit normals, a background
    band; each channel past the fourth (a hybrid's GTAO images, the back layer's thickness) a smooth image in
    [0, 1] (1 on background)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    depth = (
        1.0
        + 0.3 * np.sin(xx / 7.0 + rng.uniform(0, 6)) * np.cos(yy / 5.0)
        + 0.05 * rng.standard_normal((height, width))
    )
    n = rng.standard_normal((3, height, width)).astype(np.float32)
    n[2] = np.abs(n[2]) + 0.5
    n /= np.linalg.norm(n, axis=0, keepdims=True)
    x = np.concatenate([depth[None], n]).astype(np.float32)
    x[:, :, : max(1, width // 8)] = 0.0  # background: depth 0, normal 0
    for c in range(4, channels):
        phase = 1.3 * (c - 4)
        gtao = np.clip(0.7 + 0.3 * np.cos(xx / 9.0 + phase) * np.sin(yy / 6.0), 0.0, 1.0).astype(np.float32)
        gtao[:, : max(1, width // 8)] = 1.0
        x = np.concatenate([x, gtao[None]])
    return x


def check_backends(
    model: UNet, onnx_path: Path, sizes: Sequence[tuple[int, int]] = CHECK_SIZES, seed: int = 0
) -> dict:
    """Max |difference| torch vs onnxruntime and OpenCV dnn vs onnxruntime at ``sizes`` (width, height).

    Every size goes through the pad/crop path. Raises NeuralaoError above TOL.onnx_vs_torch (the rule
    for these outputs and this depth) / TOL.opencv_vs_onnx (a model that does not survive export is not
    written as if it did).
    """
    ort = ort_runner(onnx_path)
    cv = opencv_runner(onnx_path)
    m = model.pad_multiple
    rows, ref_max = [], 0.0
    for k, (w, h) in enumerate(sizes):
        x = random_input(w, h, seed + k, model.args.in_channels)
        rhos = CHECK_RHOS[int(model.args.preprocess_version)]
        rho = rhos[k % len(rhos)]
        ref_torch = predict(model, x, rho)
        ref_max = max(ref_max, float(np.abs(ref_torch).max()))
        y_ort = run_padded(ort, x, m, rho)
        y_cv = run_padded(cv, x, m, rho)
        rows.append(
            {
                "size": [w, h],
                "rho": rho,
                "onnxruntime_vs_torch": float(np.abs(y_ort - ref_torch).max()),
                "opencv_vs_onnxruntime": float(np.abs(y_cv - y_ort).max()),
            }
        )
    return backend_checks(rows, ref_max, onnx_path, sizes=rows)


# ----------------------------------------------------------------------------------------------- export


def write_internal_passes(
    glsl_dir: Path, height: int, hybrid: bool, gtao_blur: bool = True, gtao_raw: bool = False
) -> dict:
    """The fragment passes around the network at its internal height (neuralao.runtime.internal_resolution) as
    files under ``glsl_dir/internal/``, and the manifest entry that says how an engine runs them. A
    hybrid also gets the GTAO pass it refines (neuralao.runtime.baselines' shaders, default settings but
    for ``gtao_blur``: the ones :func:`neuralao.runtime.predict.unet_predictor` runs) and an upsampling
    pass that leaves GTAO alone where no foreground texel is in reach."""
    folder = glsl_dir / "internal"
    sources = {"vertex": "fullscreen.vert", "downsample": "downsample.frag", "upsample": "upsample.frag"}
    texts = {
        "vertex": vertex_source(),
        "downsample": downsample_source(),
        "upsample": upsample_source(empty=0.0 if hybrid else 1.0),
    }
    gtao = GTAOSettings(blur=gtao_blur)
    if hybrid:
        sources.update(gtao="gtao.frag")
        texts.update(gtao=fragment_source("gtao", gtao))
        if gtao.blur:
            sources.update(gtao_blur="gtao_blur.frag")
            texts.update(gtao_blur=blur_source(gtao.noise_size))
    for key, name in sources.items():
        write_text(folder / name, texts[key])
    steps = [
        f"downsample.frag at (round(W * {height} / H), {height}): the G-buffer's position (xyz camera "
        "space, w mask) and normal textures point-sampled into two RGBA32F targets (uniform u_low_size = "
        "that size)",
        "the network's compute passes at that size, input built from the two targets (depth = -z / mean "
        "foreground depth, camera-space normal"
        + (", GTAO point-sampled the same way" if hybrid else "")
        + ")",
        "upsample.frag at W x H: the network's AO (u_low_ao)"
        + (" minus the point-sampled GTAO, i.e. its correction," if hybrid else "")
        + " upsampled with the full-resolution G-buffer as guide",
    ]
    if hybrid:
        steps = [
            "gtao.frag at W x H (the frame's own resolution) with the full-resolution G-buffer textures, "
            'the noise tile and the uniforms of "gtao" (u_radius = the AO radius R in scene units)'
            + (
                ", then gtao_blur.frag at W x H on its output (u_raw): the GTAO image, 1 on background"
                if gtao.blur
                else ": the GTAO image before any blur (the network denoises it), 1 on background"
            ),
            *steps[:1],
            "GTAO point-sampled to the same size with the same texels (low texel t of an axis of n reads "
            "full-resolution pixel floor((t + 0.5) * N / n), GL order)",
            *steps[1:],
            "AO = clamp(GTAO + upsampled correction, 0, 1) at W x H, 1 on background",
        ]
    if gtao_raw:  # the network also reads GTAO before its blur: gtao.frag's own output, point-sampled too
        steps.insert(
            2 if hybrid else 1,
            "the network's input also takes gtao.frag's output before the blur, point-sampled the same way, "
            "as the channel in front of GTAO (input_channels ..., gtao_raw, gtao)",
        )
    entry = {"height": height, "folder": "internal", "sources": sources, "steps": steps}
    if gtao_raw:
        entry["gtao_raw"] = True
    if hybrid:
        entry["gtao"] = gtao_pass_description(gtao) | {
            "resolution": "W x H, the frame's own; the network reads it point-sampled with the G-buffer"
        }
    return entry


def write_internal_passes_of(glsl_dir: Path, height: int, meta: dict) -> dict:
    """:func:`write_internal_passes` for the model whose ONNX metadata is ``meta``: a hybrid's GTAO (with or
    without its blur, and the image before it when the network reads both) as its metadata declares."""
    hybrid = is_hybrid(meta)
    blur = hybrid_gtao_blur(meta) if hybrid else True
    return write_internal_passes(glsl_dir, height, hybrid, blur, hybrid and reads_gtao_raw(meta))


# The compute dialects an export carries besides glsl/ (GLSL 4.30, HLSL and MSL), each in its own folder
# beside it, with the frame passes: (folder, dialect).
FRAME_TARGETS = (("vulkan", "vulkan"), ("wgsl", "wgsl"))


def write_glsl(proto: onnx.ModelProto, out_dir: Path, precision: str = "fp32", preset: str = "gpu") -> Path:
    """Generate the compute passes from the ONNX graph, with the frame passes around the network
    (:mod:`neuralao.export.glsl.frame`), and write them (and their manifest) to ``out_dir`` in GLSL 4.30,
    with HLSL and MSL beside each pass where SPIRV-Cross is installed; the same passes in Vulkan GLSL +
    SPIR-V and in WGSL go to the folders of :data:`FRAME_TARGETS` beside ``out_dir``
    (``preset``: a name of :data:`neuralao.export.glsl.image.PRESETS`)."""
    settings = model_frame_settings(proto)
    program = generate_frame(generate_compute(proto, precision=precision, preset=preset), settings)
    write_compute_export(program, out_dir, cross=spirv_cross_available())
    for folder, dialect in FRAME_TARGETS:
        other = generate_compute(proto, precision=precision, preset=preset, dialect=dialect)
        write_compute_export(generate_frame(other, settings), out_dir.parent / folder)
    return out_dir


def export_checkpoint(ckpt_path: str | Path, out_dir: str | Path, internal_height: int | None = None) -> dict:
    """model.onnx + glsl/ (fp32 compute passes) + manifest.json in ``out_dir``. Returns the manifest.

    ``internal_height``: the rows the exported network runs at (its metadata, frame passes and manifest
    say so), instead of the rows it trained at: more rows cost the network's passes in proportion and
    change its AO (docs/results.md measures it at 256 and 512 rows)."""
    t0 = time.perf_counter()
    ckpt_path, out_dir = Path(ckpt_path), Path(out_dir)
    if internal_height is not None:
        internal_height = check_int_range(
            "internal_height", internal_height, MIN_INTERNAL_HEIGHT, MAX_INTERNAL_HEIGHT
        )
    model, ckpt = load_model(ckpt_path)
    out_dir.mkdir(parents=True, exist_ok=True)
    onnx_path = out_dir / "model.onnx"
    metadata = onnx_metadata(model, ckpt, internal_height)
    proto = export_onnx(model, onnx_path, metadata)
    checks = check_backends(model, onnx_path)
    glsl_dir = write_glsl(proto, out_dir / "glsl", "fp32")
    trained_height = (ckpt.get("dataset") or {}).get("internal_height") or None
    height = internal_height or trained_height
    internal = (
        write_internal_passes_of(glsl_dir, int(height), check_unet_onnx(proto, onnx_path)) if height else None
    )
    n_params = count_parameters(model)
    manifest = {
        "kind": "unet",
        "format_version": 1,
        "onnx": "model.onnx",
        "onnx_sha256": sha256_file(onnx_path),
        "glsl": glsl_dir.name,
        "exporter": f"torch.onnx.export(dynamo=False, opset={OPSET}) {torch.__version__}",
        "ops": sorted({n.op_type for n in proto.graph.node}),
        "metadata": metadata,
        "pad_multiple": model.pad_multiple,
        "pad_mode": PAD_MODE,
        "preprocess_version": int(model.args.preprocess_version),
        "parameters": n_params,
        "bytes_fp32": 4 * n_params,
        "internal_height": height,
        **({"trained_internal_height": trained_height} if height != trained_height else {}),
        "internal_resolution": internal,
        "checks": checks,
        "checkpoint": {"path": str(ckpt_path), "sha256": sha256_file(ckpt_path), "epoch": ckpt.get("epoch")},
        "config": ckpt.get("config", {}),
        "metrics": ckpt.get("metrics", {}),
        "seconds": time.perf_counter() - t0,
    }
    write_json(out_dir / "manifest.json", manifest)
    log.info(
        "exported %s: %d parameters, ort-vs-torch %.2g, opencv-vs-ort %.2g",
        out_dir,
        n_params,
        checks["onnxruntime_vs_torch"],
        checks["opencv_vs_onnxruntime"],
    )
    return manifest


def export_folder_at_height(src: str | Path, out_dir: str | Path, internal_height: int) -> dict:
    """An existing U-Net export (a shipped model's folder: no checkpoint needed) written again to
    ``out_dir`` with the network at ``internal_height`` rows: the same graph and weights, its metadata's
    ``internal_height`` (and ``trained_internal_height``), every pass regenerated for those rows, the GLSL
    checked against onnxruntime. Returns the manifest."""
    src, out_dir = Path(src), Path(out_dir)
    height = check_int_range("internal_height", internal_height, MIN_INTERNAL_HEIGHT, MAX_INTERNAL_HEIGHT)
    manifest = read_manifest(src, "unet", "a U-Net")
    onnx_in = src / str(manifest.get("onnx", "model.onnx"))
    proto = load_onnx(onnx_in)
    check_unet_onnx(proto, onnx_in)
    trained = manifest.get("trained_internal_height") or manifest.get("internal_height") or None
    props = {p.key: p.value for p in proto.metadata_props if p.key != "trained_internal_height"}
    props["internal_height"] = str(height)
    if trained and int(trained) != height:
        props["trained_internal_height"] = str(trained)
    out_dir.mkdir(parents=True, exist_ok=True)
    onnx_path = save_onnx(proto, out_dir / "model.onnx", props)
    glsl_dir = write_glsl(proto, out_dir / "glsl", "fp32")
    meta = check_unet_onnx(proto, onnx_path)
    # what was measured at the trained rows (test scores, times, parity) does not describe these rows
    measured = ("evaluation", "shaders", "seconds", "trained_internal_height")
    manifest = {k: v for k, v in manifest.items() if k not in measured}
    if isinstance(manifest.get("provenance"), dict):
        manifest["provenance"] = {
            k: v for k, v in manifest["provenance"].items() if not k.startswith(("test", "gl_", "parity"))
        }
    manifest |= {
        "onnx": onnx_path.name,
        "onnx_sha256": sha256_file(onnx_path),
        "glsl": glsl_dir.name,
        "metadata": meta,
        "internal_height": height,
        **({"trained_internal_height": int(trained)} if trained and int(trained) != height else {}),
        "internal_resolution": write_internal_passes_of(glsl_dir, height, meta),
        "exported_from": {"folder": str(src), "onnx_sha256": sha256_file(onnx_in)},
    }
    write_json(out_dir / "manifest.json", manifest)
    par = parity(out_dir)
    if not par["passed"]:
        raise NeuralaoError(
            f"{out_dir}: GLSL differs from onnxruntime by {par['max_abs_err']:.3g} > {par['tolerance']:g}"
        )
    manifest["parity"] = {"glsl_vs_onnxruntime": par["max_abs_err"], "tolerance": par["tolerance"]}
    write_json(out_dir / "manifest.json", manifest)
    return manifest


# ----------------------------------------------------------------------------------------------- inference


# ----------------------------------------------------------------------------------------------- parity


def crop_frame(frame: FrameLike, width: int, height: int) -> dict:
    """Centre crop of every image channel of a frame to ``width`` x ``height`` (scalars kept)."""
    h, w = frame["depth"].shape
    if width > w or height > h:
        raise NeuralaoError(f"cannot crop a {w}x{h} frame to {width}x{height}")
    top, left = (h - height) // 2, (w - width) // 2
    out = {}
    for k, v in frame.items():
        if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[:2] == (h, w):
            out[k] = v[top : top + height, left : left + width]
        else:
            out[k] = v
    return out


def render_parity_frames(size: tuple[int, int] = (128, 128), room: bool = False) -> list[dict]:
    """Real G-buffer frames when no dataset is given: an orbit of a closed mesh, an interior view and, with
    ``room``, a view into a composed room of primitives (floor, walls, objects resting on them)."""
    w, h = size
    frames = []
    scenes = [("spot", orbit), ("cornell_box", interior)]
    for name, cams in scenes + ([("room", interior)] if room else []):
        scene = compose(PARITY_ROOM, name="room") if name == "room" else load_scene(name)
        cam = cams(scene, 3, w, h, seed=1)[1]
        frame = render_gbuffer(scene, cam)
        frame["scene"] = name
        frames.append(frame)
    return frames


def _hybrid_input(frame: FrameLike, rho: float, version: int, blur: bool, raw: bool) -> np.ndarray:
    """A hybrid's input on ``frame`` at the radius whose parameter is ``rho``: the G-buffer channels and
    GTAO (neuralao.runtime.baselines, with or without its blur; with ``raw`` its pass before the blur
    in front of it, from the same draw)."""
    radius = radius_of_param(rho, frame["depth"], frame["mask"], float(frame["yfov"]), version)
    g = hybrid_gtao(frame, radius, blur, raw)
    return preprocess_frame(frame, g["gtao"], version, g.get("gtao_raw"))


def parity(
    export_dir: str | Path,
    frames: list[FrameLike] | None = None,
    sizes: Sequence[tuple[int, int]] | None = None,
) -> dict:
    """Generated GLSL (fp32) vs onnxruntime on real frames, each at its own size and at ``sizes`` (w, h).

    Both consumers get the same preprocessed, reflect-padded input; outputs are cropped back and
    compared over all pixels. Returns figures with ``passed`` = max error <= TOL.parity_unet_fp32.
    """
    export_dir = Path(export_dir)
    manifest = read_manifest(export_dir)
    onnx_path = export_dir / manifest.get("onnx", "model.onnx")
    proto = load_onnx(onnx_path)
    meta = check_unet_onnx(proto, onnx_path)
    m = int(meta["pad_multiple"])
    glsl_dir = export_dir / manifest.get("glsl", "glsl")
    if not glsl_dir.is_dir():
        raise NeuralaoError(f"export {export_dir} has no GLSL folder {glsl_dir.name}")
    frames = frames if frames else render_parity_frames()
    sizes = list(PARITY_SIZES if sizes is None else sizes)
    ort, gl = ort_runner(proto.SerializeToString()), glsl_runner(glsl_dir)
    hybrid = is_hybrid(meta)
    blur = hybrid_gtao_blur(meta, str(onnx_path))
    raw = hybrid and reads_gtao_raw(meta)
    version = check_version(meta.get("preprocess_version"), str(onnx_path))
    rows = []
    for i, frame in enumerate(frames):
        h0, w0 = frame["depth"].shape
        for w, h in [(w0, h0)] + [s for s in sizes if tuple(s) != (w0, h0)]:
            if w > w0 or h > h0:
                rows.append({"frame": i, "size": [w, h], "skipped": f"larger than the {w0}x{h0} frame"})
                continue
            f = crop_frame(frame, w, h)
            rho = CHECK_RHOS[version][len(rows) % len(CHECK_RHOS[version])]
            # a hybrid's GTAO channels: GTAO on the same frame at the radius rho stands for
            x = _hybrid_input(f, rho, version, blur, raw) if hybrid else preprocess_frame(f, None, version)
            y_ort = run_padded(ort, x, m, rho)
            t0 = time.perf_counter()
            y_gl = run_padded(gl, x, m, rho)
            seconds = time.perf_counter() - t0
            fg = np.asarray(f["mask"], dtype=bool)
            rows.append(
                {
                    "frame": i,
                    "scene": str(frame.get("scene", "")),
                    "size": [w, h],
                    "rho": rho,
                    "max_abs_err": float(np.abs(y_gl - y_ort).max()),
                    "max_abs_err_foreground": float(np.abs(y_gl - y_ort)[fg].max()) if fg.any() else 0.0,
                    "glsl_seconds": seconds,
                }
            )
    checked = [r for r in rows if "max_abs_err" in r]
    if not checked:
        raise NeuralaoError("parity: no frame/size could be checked")
    max_err = max(r["max_abs_err"] for r in checked)
    return {
        "kind": "unet",
        "precision": "fp32",
        "max_abs_err": max_err,
        "tolerance": TOL.parity_unet_fp32,
        "passed": bool(max_err <= TOL.parity_unet_fp32),
        "checks": rows,
        "frames": len(frames),
    }


def _round_up(x: float, digits: int = 2) -> float:
    if x <= 0:
        return 0.0
    scale = 10.0 ** (np.floor(np.log10(x)) - digits + 1)
    return round(float(np.ceil(x / scale) * scale), digits - int(np.floor(np.log10(x))) + 1)


def _sizes(frames: Sequence[FrameLike]) -> str:
    """The frames' sizes as a user reads them: ``128x128, 455x256``."""
    sizes = dict.fromkeys(f"{np.shape(f['depth'])[1]}x{np.shape(f['depth'])[0]}" for f in frames)
    return ", ".join(sizes)


def parity_fp16(onnx_path: str | Path, frames: list[FrameLike] | None = None) -> dict:
    """The model's whole frame at fp16 (frame passes + network, GL) against onnxruntime's reference
    (``unet_predictor``, the model at its internal height) on real frames, at the check radii of its
    input contract: the fp16 error a user of this model gets, and the bound the manifest states for it
    (:data:`FP16_BOUND_MARGIN` times the largest error, two significant digits, at least
    TOL.parity_fp16). The fp32 frame's error is measured beside it."""
    onnx_path = Path(onnx_path)
    proto = load_onnx(onnx_path)
    meta = check_unet_onnx(proto, onnx_path)
    version = check_version(meta.get("preprocess_version"), str(onnx_path))
    if not frames:
        # small frames the network upsamples, and 16:9 frames at its own height (where its features are
        # sharpest and fp16's rounding of them shows most)
        rows = int(meta.get("internal_height") or 0) or 256
        frames = render_parity_frames() + render_parity_frames((round(rows * 16 / 9), rows), room=True)
    reference = unet_predictor(onnx_path)
    programs = {p: frame_program(proto, "glsl430", precision=p) for p in ("fp32", "fp16")}
    rows = []
    for i, frame in enumerate(frames):
        h, w = np.shape(frame["depth"])
        with FrameRunner(programs["fp32"], w, h) as fp32, FrameRunner(programs["fp16"], w, h) as fp16:
            for rho in FP16_RHOS[version]:
                radius = radius_of_param(rho, frame["depth"], frame["mask"], float(frame["yfov"]), version)
                want = reference(frame, radius)
                rows.append(
                    {
                        "frame": i,
                        "scene": str(frame.get("scene", "")),
                        "size": [int(w), int(h)],
                        "radius": float(radius),
                        "fp16_max_abs_err": float(np.abs(fp16.run(frame, radius) - want).max()),
                        "fp32_max_abs_err": float(np.abs(fp32.run(frame, radius) - want).max()),
                    }
                )
    err = max(r["fp16_max_abs_err"] for r in rows)
    return {
        "precision": "fp16",
        "max_abs_err": err,
        "fp32_max_abs_err": max(r["fp32_max_abs_err"] for r in rows),
        "bound": max(TOL.parity_fp16, _round_up(FP16_BOUND_MARGIN * err)),
        "visible_in_8_bit": bool(err > FP16_INVISIBLE_IN_8_BIT),
        "how": (
            "the whole frame (frame passes + network) in GL at fp16 against onnxruntime's AO, over every "
            f"pixel of {len(frames)} rendered frames ({_sizes(frames)}) at the radii of rho "
            f"{list(FP16_RHOS[version])}; "
            f"bound = {FP16_BOUND_MARGIN} x the largest error, rounded up to two significant digits, "
            f"at least {TOL.parity_fp16:g}"
        ),
        "checks": rows,
    }
