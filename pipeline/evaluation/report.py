"""`neuralao report`: every AO method on the same held-back frames, speed against error, in one run.

What is measured
----------------
Frames: per scene, the dataset's held-back views (``holdout``: never used to train either model),
topped up with other views of ``val`` / ``test`` scenes (which no model trained on), at most
``frames_per_scene``. Ground truth: the frames relabelled with ``gt_rays`` (1024) Embree rays with
the dataset's own label settings (kernel, max distance, back-face rule) and a seed of their own; when
the dataset was labelled with at least that many rays (at every radius needed) its labels are used as
they are. Relabelled ground truth is cached under ``OUT/gt/`` (keyed by the dataset hash, frame,
settings and radii).

Radii: the main figures are at the labels' max distance. The methods that take the AO radius at run
time (SSAO, GTAO, the U-Nets: ``RADIUS_FAMILIES``) are also evaluated at every radius of
``radii_rel`` (x the scene diagonal; default the dataset's ``labels.radii_rel``), each given the same
radius (the U-Net as its radius input rho, :func:`neuralao.pipeline.models.unet.frame_radius_param`),
against ground truth at that radius; the ground truth at all radii comes from ONE trace to the largest
(:meth:`neuralao.pipeline.tracing.labeller.Labeller.label_frame_radii`, equal to separate traces bit for
bit). Methods with a baked-in radius (vertex bakes, MLPs, fields, traced) are evaluated at the max distance
only.

Methods (each one run on every frame it applies to):

* ``ssao``, ``gtao``: the screen-space baselines of :mod:`neuralao.runtime.baselines` (GLSL fragment passes),
  radius = the labels' max distance (and every radius of ``radii_rel``);
* ``vertex-sampled``, ``vertex-lsq``: AO baked per vertex (:mod:`neuralao.pipeline.bakes.vertex`: sampled at
  vertices, or least-squares fitted to surface samples) with ``bake_rays`` rays, shown as a vertex-colour
  draw shows it (barycentric interpolation per pixel);
* ``trace-4`` / ``-16`` / ``-64``: Embree AO of every pixel at that ray count (the labeller itself);
* ``vertex-lsq-8bit``: the least-squares bake stored as 8-bit UNORM vertex colours (1 B per vertex);
* ``mlp-<size>``: every exported baked MLP, on the frames of the scene it was trained for (its
  generated GLSL fragment shader on the frame's object-space normals, output clamped to [0, 1]);
* ``field-<size>``: every exported AO field (:mod:`neuralao.pipeline.models.field`), on the frames of the
  scene it was trained for: its generated GLSL fragment shader on the frame's object-space position +
  normal;
* ``unet``: the exported U-Net through onnxruntime (:func:`neuralao.runtime.predict.unet_predictor`), every
  frame; half / quarter-resolution variants (manifest metadata ``scale`` 2 / 4) are rows like any U-Net;
* ``shipped:<name>``: the release U-Nets of ``runtime/models/`` (:mod:`neuralao.runtime.shipped`), included
  when no ``--exports`` is given, or in addition with ``--shipped``: by default the ``default`` and ``fast``
  models only (:func:`pick_shipped`; ``--shipped all`` or names for others); their training curves,
  corpus-size study and test figures (from ``index.json`` and the manifests' provenance) are plotted by
  :mod:`neuralao.pipeline.evaluation.plots`. None shipped: the report says so in one line.

Error: masked SSIM (:func:`neuralao.runtime.foundation.metrics.masked_ssim`) and RMSE over foreground pixels
whose ground truth is valid, averaged over frames. Time: seconds per frame at ``time_size`` (512 x 512), all
in this run: GL passes (SSAO, GTAO, the MLP fragment shader, the U-Net's generated compute shaders, the
vertex-colour draw) on the same headless GL context, timed with ``glFinish`` around each frame with the
G-buffer resident; traced AO as the wall time of the Embree trace on the CPU (``workers`` threads);
onnxruntime (CPU) times of the models (a whole frame through
:mod:`neuralao.runtime.predict`, input packing and clamping included) are reported beside the GL ones. Each
scene gets a ``time_size`` G-buffer rendered from the pose of its first evaluation frame; a
method's time is the median over scenes. Ratios: time over SSAO's time, and RMSE (and 1 - SSIM)
over SSAO's on the same frames.

Outputs (every file atomic): ``report.md`` (tables), ``report.json`` (everything, per scene and per
frame), ``speed_vs_error.png`` (scatter with the Pareto front), ``contact_<scene>.png`` (ground truth |
each method, and the error heat maps); with shipped models ``learning_curves.png``, ``corpus_size.png``
and ``shipped_front.png`` (each skipped when its data is absent). Methods whose export is missing or
broken are listed as not available; the report never fails because a model is absent.
"""

from __future__ import annotations

import json
import logging
import math
import platform
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from neuralao.export.field import gbuffer_textures
from neuralao.export.glsl import load_compute_export, load_mlp_export
from neuralao.pipeline import kinds
from neuralao.pipeline.bakes.vertex import BakeSettings, bake
from neuralao.pipeline.datasets.dataset import open_dataset, scene_of
from neuralao.pipeline.evaluation.figures import contact_sheet as readable_sheet
from neuralao.pipeline.evaluation.figures import write_html, write_viewer_pages
from neuralao.pipeline.evaluation.plots import shipped_markdown, shipped_summary, write_shipped_plots
from neuralao.pipeline.evaluation.selection import render_markdown as select_markdown
from neuralao.pipeline.evaluation.selection import render_targets_markdown as targets_markdown
from neuralao.pipeline.evaluation.selection import select_from_results
from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.camera import Camera
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime import gl
from neuralao.runtime.baselines import (
    GTAOSettings,
    SSAOSettings,
    run_screen_space,
    time_screen_space,
    time_vertex_ao,
    traced_ao,
    vertex_ao_image,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import (
    atomic_path,
    read_npz,
    sha256_json,
    write_json,
    write_npz,
    write_text,
)
from neuralao.runtime.foundation.metrics import masked_flip, masked_rmse, masked_ssim
from neuralao.runtime.foundation.settings import from_dict, settings_to_dict
from neuralao.runtime.glsl_runner import (
    run_mlp_fragment,
    run_vector_fragment,
    time_compute,
    time_mlp_fragment,
    time_vector_fragment,
)
from neuralao.runtime.predict import PREDICTORS, Predictor

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
EXPECTED_EXPORTS = ("mlp-16x8", "mlp-32x16", "mlp-64x32", "unet")
BASELINE_ORDER = ("ssao", "gtao", "vertex-sampled", "vertex-lsq", "vertex-lsq-8bit")
# The report's own families (baselines); the model families (rows loaded from exports) come from
# neuralao.pipeline.kinds.
FAMILY_ORDER = {
    "screen-space": 0,
    "baked": 1,
    "traced": 2,
    **{n: k.report_order for n, k in kinds.REPORTED.items()},
}
MODEL_FAMILIES = tuple(kinds.REPORTED)  # methods loaded from exports
# Methods that take the AO radius at run time: evaluated at every radius of ReportSettings.radii_rel.
RADIUS_FAMILIES = ("screen-space", *(n for n, k in kinds.REPORTED.items() if k.radius_input))
# Scatter-plot colours of the families (neuralao.pipeline.kinds gives the models').
COLOURS = {
    "screen-space": "tab:blue",
    "baked": "tab:green",
    "traced": "tab:gray",
    **{n: k.colour for n, k in kinds.REPORTED.items()},
}
SHIPPED_PREFIX = "shipped:"  # row-name prefix of the release models of runtime/models
# Shipped rows a report shows unless told otherwise: the default model and the fast one (pick_shipped).
SHIPPED_PICKS = ("default", "fast")
# Which methods can show a single-sided surface differently from its two sides (the G-buffer turns
# the normal towards the viewer): per-vertex bakes store one value per vertex, so both sides of an
# open sheet show the same AO; networks fed the viewer-facing normal and screen-space methods can differ.
TWO_SIDED = {
    "screen-space": True,
    "baked": False,
    "traced": True,
    **{n: k.two_sided for n, k in kinds.REPORTED.items()},
}


@dataclass
class ReportSettings:
    # Rays per pixel of the ground truth (frames are relabelled when the dataset used fewer).
    gt_rays: int = 1024
    # At most this many evaluation frames per scene (held-back views first).
    frames_per_scene: int = 4
    # Width, height of the timing frames.
    time_size: tuple[int, int] = (512, 512)
    # Timed repetitions per GL measurement (median kept); traced AO is timed once per scene.
    repeats: int = 10
    # Ray counts of the "just trace it" baselines.
    trace_rays: list[int] = field(default_factory=lambda: [4, 16, 64])
    # Rays per sample of the vertex bakes.
    bake_rays: int = 128
    # Least-squares bake sample budget per vertex.
    bake_samples_per_vertex: float = 8.0
    # Target masked SSIM of the model-selection section.
    target_ssim: float = 0.95
    # Further targets shown side by side in the selection table.
    select_targets: list[float] = field(default_factory=lambda: [0.9, 0.95])
    # Seed of ground-truth and low-ray tracing directions.
    seed: int = 0
    # Tracing threads (ground truth, baselines).
    workers: int = 2
    # Write a contact sheet per scene (neuralao.pipeline.evaluation.figures: cropped, methods side by side,
    # error inset).
    contact_sheets: bool = True
    # The methods a contact sheet shows, in order (those present in the report); "shipped:default" and
    # "shipped:fast" stand for the shipped rows of those roles, "field" / "mlp" for the smallest of each.
    contact_methods: list[str] = field(
        default_factory=lambda: [
            "ssao",
            "gtao",
            "vertex-lsq",
            "field",
            "unet",
            "shipped:default",
            "shipped:fast",
        ]
    )
    # Write a viewer page per scene (`neuralao view`: its least-squares bake and its MLP / field shaders)
    # under OUT/viewer/, linked from report.html.
    viewer_pages: bool = True
    # Also score every frame with NVIDIA FLIP (neuralao.runtime.foundation.metrics.masked_flip,
    # flip-evaluator; background set to 1 in both images); about 0.1-0.3 s per method and 128x128 frame on
    # one core.
    flip: bool = True
    # Screen-space baseline settings (radius: the labels' max distance, and each of radii_rel).
    ssao: SSAOSettings = field(default_factory=SSAOSettings)
    gtao: GTAOSettings = field(default_factory=GTAOSettings)
    # Export folders the report expects under --exports: each one missing is a row "not available".
    expected_exports: list[str] = field(default_factory=lambda: list(EXPECTED_EXPORTS))
    # AO radii (fractions of the scene diagonal) at which SSAO, GTAO and the U-Nets are also evaluated,
    # all given the same radius, ground truth at every one from one trace; None: the dataset's
    # labels.radii_rel, else its max_distance_rel. The main table stays at the labels' max distance.
    radii_rel: list[float] | None = None


@dataclass
class Method:
    """One entry of the report: what it is, where it runs, what it applies to."""

    name: str
    family: str  # screen-space | baked | traced | mlp | unet
    description: str
    time_on: str
    error_on: str
    scene: str | None = None  # the only scene it applies to (baked MLP), None = every scene
    bytes: int | None = None
    bytes_note: str = ""
    export: Path | None = None
    available: bool = True
    reason: str = ""
    # Model methods, prepared by prepare_model: the AO its error is measured on, its onnxruntime
    # inference (neuralao.runtime.predict) and the generated GLSL program that is timed.
    predictor: Predictor | None = None
    ort: Predictor | None = None
    program: Any = None
    # Fields: one export per mesh, one row per size: scene -> export folder.
    scene_exports: dict[str, Path] | None = None
    scale: int = 1  # U-Nets: 1 = full resolution, 2 / 4 = run at 1/2 / 1/4 resolution
    shipped: str | None = None  # name under runtime/models when a shipped release model

    def applies_to(self, scene: str) -> bool:
        if self.scene_exports is not None:
            return scene in self.scene_exports
        return self.scene is None or self.scene == scene

    @property
    def scope(self) -> str:
        if self.scene_exports is not None:
            return ", ".join(sorted(self.scene_exports))
        return self.scene or "all scenes"


# --------------------------------------------------------------------------- frames and ground truth


def evaluation_frames(ds, per_scene: int) -> dict[str, list[dict]]:
    """Per scene: held-back frames first, then (val/test scenes only) other frames; at most ``per_scene``."""
    out: dict[str, list[dict]] = {}
    for scene in ds.scenes:
        frames = list(ds.frames(scene=scene, holdout=True))[:per_scene]
        if len(frames) < per_scene and ds.split_of(scene) in ("val", "test"):
            for f in ds.frames(scene=scene, holdout=False):
                if len(frames) >= per_scene:
                    break
                frames.append(f)
        if frames:
            out[scene] = frames
    return out


def label_settings_of(ds, workers: int):
    return replace(from_dict(LabelSettings, dict(ds.label_settings)), workers=workers)


def frame_key_seed(seed: int, *parts) -> int:
    return zlib.crc32("/".join(str(p) for p in (seed, *parts)).encode()) & 0x7FFFFFFF


def radius_key(rel: float) -> str:
    """The JSON / table key of a relative radius: ``0.0625`` -> "0.0625"."""
    return f"{float(rel):g}"


def report_radii_rel(settings: ReportSettings, label_settings) -> list[float]:
    """Relative radii of the per-radius evaluation, ascending: ``settings.radii_rel``, else the
    dataset's ``labels.radii_rel``, else its ``max_distance_rel`` (none when the max distance is
    absolute: then only the max distance is evaluated)."""
    if settings.radii_rel is not None:
        rels = settings.radii_rel
    elif label_settings.radii_rel:
        rels = label_settings.radii_rel
    else:
        rels = [] if label_settings.max_distance is not None else [label_settings.max_distance_rel]
    return sorted({float(r) for r in rels})


@dataclass
class GroundTruth:
    """Ground truth of one frame at several radii (one trace): ``ao`` (H, W, k) float32, ``valid``
    (H, W, k) bool at ``radii`` (k,) scene units; column ``main`` is the labels' max distance."""

    ao: np.ndarray
    valid: np.ndarray
    radii: tuple[float, ...]
    main: int
    source: str

    def at(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """(ao (H, W) float32, valid (H, W) bool) at radius column ``j``."""
        return self.ao[..., j], self.valid[..., j]


def _dataset_columns(
    frame: dict, radii: tuple[float, ...], main: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """The dataset's own labels at every radius of ``radii`` (``ao`` at the max distance, ``ao_radii``
    at its ``radii``), or None when a radius is not among them."""
    have = np.asarray(frame.get("radii", []), np.float64).reshape(-1)  # float32 in the shards
    ao, valid = [], []
    for j, r in enumerate(radii):
        if j == main:
            ao.append(frame["ao"])
            valid.append(frame["valid"])
            continue
        hit = np.flatnonzero(np.isclose(have, r, rtol=1e-6, atol=0.0))
        if not len(hit):
            return None
        ao.append(frame["ao_radii"][..., hit[0]])
        valid.append(frame["valid_radii"][..., hit[0]])
    return np.stack(ao, axis=-1).astype(np.float32), np.stack(valid, axis=-1).astype(bool)


def ground_truth(
    labeller,
    frame: dict,
    ds_rays: int,
    settings: ReportSettings,
    cache: Path | None,
    key: dict,
    radii: tuple[float, ...] | None = None,
    main: int = 0,
) -> GroundTruth:
    """Ground truth of one frame at ``radii`` (k,) scene units (default: the labels' max distance
    alone; column ``main`` must be the max distance): the dataset's labels when they have
    ``gt_rays`` rays and every radius, else ONE ``gt_rays`` trace to the largest radius
    (:meth:`Labeller.label_frame_radii`, equal to a trace per radius bit for bit), cached as
    ``ao`` / ``valid`` (H, W) at the max distance + ``ao_radii`` / ``valid_radii`` (H, W, k), ``radii``."""
    radii = (labeller.max_distance,) if radii is None else tuple(float(r) for r in radii)
    if ds_rays >= settings.gt_rays:
        cols = _dataset_columns(frame, radii, main)
        if cols is not None:
            return GroundTruth(*cols, radii, main, f"dataset labels ({ds_rays} rays)")
    digest = sha256_json({**key, "radii": list(radii)})[:16]
    path = cache / f"{frame['scene']}-{int(frame['view']):04d}-{digest}.npz" if cache else None
    if path is not None and path.is_file():
        try:
            z = read_npz(path)
            if z["ao_radii"].shape[-1] == len(radii):
                return GroundTruth(
                    z["ao_radii"],
                    z["valid_radii"].astype(bool),
                    radii,
                    main,
                    f"relabelled, {settings.gt_rays} rays (cached)",
                )
            log.warning("ground-truth cache %s has other radii; relabelling", path)
        except (NeuralaoError, KeyError):
            log.warning("ground-truth cache %s unreadable; relabelling", path)
    saved = labeller.settings
    labeller.settings = replace(
        saved, rays=settings.gt_rays, seed=frame_key_seed(settings.seed, "gt", frame["scene"], frame["view"])
    )
    try:
        ao, valid = labeller.label_frame_radii(frame, radii)
    finally:
        labeller.settings = saved
    if path is not None:
        write_npz(
            path,
            ao=ao[..., main],
            valid=valid[..., main],
            ao_radii=ao,
            valid_radii=valid,
            radii=np.asarray(radii, np.float64),
        )
    return GroundTruth(ao, valid, radii, main, f"relabelled, {settings.gt_rays} rays")


# --------------------------------------------------------------------------- methods


def discover_exports(
    exports: Path | None, scenes: list[str], expected: list[str] | tuple[str, ...] = EXPECTED_EXPORTS
) -> list[Method]:
    """Model methods from export folders (kind mlp / unet); broken ones and absent ``expected`` ones
    are unavailable."""
    methods: list[Method] = []
    found: dict[str, Path] = {}
    if exports is not None and Path(exports).is_dir():
        for m in sorted(Path(exports).glob("*/manifest.json")):
            found[m.parent.name] = m.parent
    for name in expected:
        if name not in found:
            family = "unet" if name == "unet" else "mlp"
            where = Path(exports) / name if exports is not None else name
            methods.append(Method(name, family, "", "", "", available=False, reason=f"no export at {where}"))
    fields: dict[str, Method] = {}
    for name, d in sorted(found.items()):
        m = _export_method(name, d, scenes)
        if m.family != "field":
            methods.append(m)
        elif not m.available:
            methods.append(m)  # listed with its reason under its folder's name
        else:  # one row per size: every scene's field of that size
            row = fields.setdefault(m.name, replace(m, scene=None, scene_exports={}))
            if m.scene in row.scene_exports:
                row.available, row.reason = False, f"two {m.name} exports for scene {m.scene!r}"
            row.scene_exports[m.scene] = m.export
            row.bytes = max(row.bytes or 0, m.bytes or 0)
    return methods + list(fields.values())


def _export_method(name: str, d: Path, scenes: list[str]) -> Method:
    try:
        manifest = json.loads((d / "manifest.json").read_text())
    except (OSError, json.JSONDecodeError) as e:
        return Method(
            name,
            "mlp" if name.startswith("mlp") else "unet",
            "",
            "",
            "",
            available=False,
            reason=f"unreadable manifest ({type(e).__name__})",
        )
    kind = manifest.get("kind")
    if kind == "mlp":
        scene = manifest.get("scene")
        m = Method(
            name,
            "mlp",
            f"baked MLP {manifest.get('model_size', '')} (Erra et al.), one network per mesh",
            "GL fragment shader (generated GLSL)",
            "GL fragment shader, clamped to [0, 1]",
            scene=scene,
            bytes=manifest.get("parameter_bytes"),
            bytes_note="float32 weights",
            export=d,
        )
        if scene not in scenes:
            m.available, m.reason = False, f"trained for scene {scene!r}, which the dataset does not hold"
        return m
    if kind == "field":
        scene = manifest.get("scene")
        octaves = manifest.get("octaves")
        row = f"field-{manifest.get('model_size', '')}" + ("" if octaves == 4 else f"-o{octaves}")
        m = Method(
            row,
            "field",
            f"AO field {manifest.get('model_size', '')}, {manifest.get('octaves')} octaves "
            "(object-space position + normal), one network per mesh",
            "GL fragment shader (generated GLSL)",
            "GL fragment shader, clamped to [0, 1]",
            scene=scene,
            bytes=manifest.get("parameter_bytes"),
            bytes_note="float32 weights + encoding constants",
            export=d,
        )
        if scene not in scenes:
            m.name = name
            m.available, m.reason = False, f"trained for scene {scene!r}, which the dataset does not hold"
        return m
    if kind == "unet":
        scale = _unet_scale(manifest)
        at = "" if scale == 1 else f", run at 1/{scale} resolution (depth- and normal-aware upsampling)"
        return Method(
            name,
            "unet",
            f"DeepAO screen-space U-Net (Zhang et al.){at}",
            "GL compute shaders (generated GLSL)",
            "onnxruntime (GLSL parity-checked)",
            bytes=manifest.get("bytes_fp32"),
            bytes_note="float32 weights",
            export=d,
            scale=scale,
        )
    return Method(name, "unknown", "", "", "", available=False, reason=f"unknown export kind {kind!r}")


def _unet_scale(manifest: dict) -> int:
    """Resolution divisor of a U-Net export (manifest metadata ``scale``; 1 when absent)."""
    try:
        return int((manifest.get("metadata") or {}).get("scale", 1))
    except (TypeError, ValueError):
        return 1


def pick_shipped(summary: dict, picks: list[str] | tuple[str, ...] | None) -> list[str]:
    """Names of the shipped U-Nets to report: ``picks`` holds roles and names. ``default``: the model
    index.json names default; ``fast``: ``index.json`` ``fast`` (per kind) if it names one, else the
    U-Net with the smallest GL time at 512x512 other than the default; ``all`` (or None): every one.
    A pick that matches nothing is left out with a log line (the report never fails on it)."""
    models = {n: m for n, m in summary["models"].items() if m.get("kind", "unet") == "unet"}
    if picks is None or "all" in picks:
        return list(models)
    default = (summary.get("default") or {}).get("unet")
    chosen: list[str] = []
    for pick in picks:
        if pick == "default":
            name = default
        elif pick == "fast":
            name = (summary.get("fast") or {}).get("unet")
            if name is None:
                timed = [
                    (float((m.get("gl_seconds") or {}).get("512x512") or math.inf), n)
                    for n, m in models.items()
                    if n != default
                ]
                name = min(timed)[1] if timed else None
        else:
            name = pick
        if name in models and name not in chosen:
            chosen.append(name)
        elif name not in models:
            log.info("shipped %s: no such model in %s", pick, summary.get("folder"))
    return chosen


def discover_shipped(
    models_dir: Path, scenes: list[str], picks: list[str] | tuple[str, ...] | None = None
) -> tuple[list[Method], dict]:
    """The shipped U-Nets of ``models_dir`` (runtime/models) picked by :func:`pick_shipped` (None:
    every one) as rows ``shipped:<name>``, and the summary of the index
    (:func:`neuralao.pipeline.evaluation.plots.shipped_summary`, its models cut to the picked ones and their
    ``roles``; its ``note`` says why none)."""
    summary = shipped_summary(models_dir)
    names = pick_shipped(summary, picks)
    others = [n for n in summary["models"] if n not in names]
    summary["models"] = {n: summary["models"][n] for n in names}
    summary["roles"] = {p: n for p in ("default", "fast") for n in pick_shipped({**summary}, [p])}
    summary["not_shown"] = others
    methods = []
    for name, info in summary["models"].items():
        if info.get("kind", "unet") != "unet":
            continue
        row = SHIPPED_PREFIX + name
        folder = Path(info["folder"])
        if not (folder / "manifest.json").is_file():
            m = Method(
                row, "unet", "", "", "", available=False, reason=f"no manifest at {folder / 'manifest.json'}"
            )
        else:
            m = _export_method(row, folder, scenes)
            m.description += f"; shipped release model {name} (runtime/models)"
        m.shipped = name
        methods.append(m)
    return methods, summary


def baseline_methods(settings: ReportSettings) -> list[Method]:
    s = settings.ssao
    ssao_bytes = s.samples * 12 + s.noise_size**2 * 16
    gtao_bytes = settings.gtao.noise_size**2 * 16
    out = [
        Method(
            "ssao",
            "screen-space",
            f"Crytek-style normal-oriented hemisphere SSAO, {s.samples} samples + "
            f"{s.noise_size}x{s.noise_size} blur",
            "GL fragment shader",
            "GL fragment shader",
            bytes=ssao_bytes,
            bytes_note="kernel + noise tile",
        ),
        Method(
            "gtao",
            "screen-space",
            f"GTAO, {settings.gtao.slices} slices x {settings.gtao.steps} steps + blur",
            "GL fragment shader",
            "GL fragment shader",
            bytes=gtao_bytes,
            bytes_note="noise tile",
        ),
        Method(
            "vertex-sampled",
            "baked",
            f"per-vertex AO sampled at vertices ({settings.bake_rays} rays), vertex colours",
            "GL vertex-colour draw",
            "barycentric interpolation (= the draw)",
            bytes_note="4 B per vertex",
        ),
        Method(
            "vertex-lsq",
            "baked",
            f"least-squares vertex bake ({settings.bake_rays} rays/sample), vertex colours",
            "GL vertex-colour draw",
            "barycentric interpolation (= the draw)",
            bytes_note="4 B per vertex",
        ),
        Method(
            "vertex-lsq-8bit",
            "baked",
            "the least-squares bake stored as 8-bit UNORM vertex colours",
            "GL vertex-colour draw",
            "barycentric interpolation of the 8-bit values",
            bytes_note="1 B per vertex",
        ),
    ]
    for r in settings.trace_rays:
        out.append(
            Method(
                f"trace-{r}",
                "traced",
                f"Embree ray-traced AO, {r} rays per pixel",
                f"CPU Embree ({settings.workers} threads)",
                "CPU Embree",
                bytes_note="scene + BVH",
            )
        )
    return out


def _clamped(raw: np.ndarray, frame: dict) -> np.ndarray:
    """Raw AO (H, W) clamped to [0, 1] on the frame's mask (NaN counts as 1), 1 on background."""
    mask = np.asarray(frame["mask"], bool)
    return np.where(mask, np.clip(np.nan_to_num(raw, nan=1.0), 0.0, 1.0), 1.0).astype(np.float32)


@dataclass(frozen=True)
class GLPath:
    """How the report runs the generated GLSL of one model kind."""

    # The export's GLSL folder -> its program.
    load: Callable[[Path], Any]
    # (program, frame) -> raw AO (H, W) of the frame; None: the kind's error is measured with
    # onnxruntime (its GLSL is parity-checked against onnxruntime at export).
    run: Callable[[Any, dict], np.ndarray] | None
    # (program, W, H, repeats) -> median seconds per frame, random content.
    seconds: Callable[[Any, int, int, int], float]
    # Timed repetitions of the onnxruntime inference, from ReportSettings.repeats.
    ort_repeats: Callable[[int], int]
    # Keyword arguments of the kind's onnxruntime predictor (neuralao.runtime.predict.PREDICTORS).
    ort_options: dict = field(default_factory=dict)


# A U-Net frame costs ~100x an MLP's: at most 5 repetitions of each; the report's U-Nets run at the
# frame's own size (the network's ``scale`` does any downsampling).
GL_PATHS: dict[str, GLPath] = {
    "mlp": GLPath(
        load_mlp_export,
        lambda shader, f: run_mlp_fragment(
            shader, np.asarray(f["normal_obj"], np.float32), np.asarray(f["mask"], bool)
        ),
        lambda shader, w, h, n: time_mlp_fragment(shader, h, w, repeats=n),
        lambda n: max(1, n // 3),
    ),
    "field": GLPath(
        load_mlp_export,
        lambda shader, f: run_vector_fragment(shader, gbuffer_textures(f)),
        lambda shader, w, h, n: time_vector_fragment(shader, h, w, repeats=n),
        lambda n: max(1, n // 3),
    ),
    "unet": GLPath(
        load_compute_export,
        None,
        lambda program, w, h, n: time_compute(program, h, w, repeats=max(1, min(n, 5))),
        lambda n: max(1, min(n, 5)),
        {"internal_height": None},
    ),
}


def gl_predictor(run: Callable[[Any, dict], np.ndarray], programs: dict[str, Any]) -> Predictor:
    """``predict(frame) -> ao`` through the generated GLSL: the program of the frame's scene."""

    def predict(frame: dict, radius: float | None = None) -> np.ndarray:
        return _clamped(run(programs[frame["scene"]], frame), frame)

    return predict


def prepare_model(m: Method) -> None:
    """Load what a model method needs once (GL programs, onnxruntime predictors); failure -> unavailable.

    A per-mesh row of fields holds every scene's export: every one is loaded and checked, the first
    one's program and onnxruntime inference are timed."""
    try:
        path = GL_PATHS[m.family]
        exports = m.scene_exports if m.scene_exports is not None else {m.scene: m.export}
        programs: dict = {}
        for scene, d in sorted(exports.items()):
            manifest = json.loads((d / "manifest.json").read_text())
            programs[scene] = path.load(d / manifest.get("glsl", "glsl"))
            ort = PREDICTORS[m.family](d / manifest.get("onnx", "model.onnx"), **path.ort_options)
            if m.ort is None:
                m.program, m.ort = programs[scene], ort
        m.predictor = m.ort if path.run is None else gl_predictor(path.run, programs)
    except Exception as e:  # a broken export must not stop the report: list it with the reason
        m.available, m.reason = (
            False,
            f"cannot load export: {str(e).splitlines()[0][:160] if str(e) else type(e).__name__}",
        )


def predict_model(m: Method, frame: dict, radius: float | None = None) -> np.ndarray:
    """AO (H, W) float32 in [0, 1] of a model method on one frame, background 1 (``radius``: the AO
    radius in scene units, given to the kinds that take it as an input)."""
    return np.clip(m.predictor(frame, radius if kinds.KINDS[m.family].radius_input else None), 0.0, 1.0)


def timing_inputs(size: tuple[int, int]) -> dict:
    """A G-buffer frame of ``size`` (W, H), every pixel foreground, seeded random content: what the
    onnxruntime timings run on (the networks' cost does not depend on content)."""
    w, h = size
    rng = np.random.default_rng(0)
    n = rng.normal(size=(h, w, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return {
        "depth": rng.uniform(1.0, 2.0, (h, w)).astype(np.float32),
        "normal_cam": n,
        "normal_obj": n,
        "position": rng.uniform(-1.0, 1.0, (h, w, 3)).astype(np.float32),
        "mask": np.ones((h, w), bool),
        "yfov": 0.8,
    }


def time_model(m: Method, size: tuple[int, int], repeats: int) -> dict:
    """GL and onnxruntime seconds per frame at ``size`` (W, H) (content-independent networks)."""
    path = GL_PATHS[m.family]
    frame = timing_inputs(size)
    radius = 1.0 if kinds.KINDS[m.family].radius_input else None
    return {
        "seconds": path.seconds(m.program, *size, repeats),
        "seconds_onnxruntime": gl.median_frame_seconds(
            lambda: m.ort(frame, radius), path.ort_repeats(repeats), warmup=1
        ),
    }


# --------------------------------------------------------------------------- per-scene context


class SceneContext:
    """The scene's mesh, labeller, radii, bakes and timing frame, built lazily.

    ``radius``: the labels' max distance (scene units), the radius of the main figures;
    ``radii``: (k,) scene units of the per-radius evaluation (``radii_rel`` x diagonal);
    ``trace_radii``: ``radii`` (columns 0..k-1) plus the max distance when it is not one of them, the
    radii of the one ground-truth trace; ``main``: the max distance's column.
    """

    def __init__(
        self,
        name: str,
        scene,
        label_settings,
        settings: ReportSettings,
        cache: Path | None,
        progress: bool,
        radii_rel: list[float] | None = None,
    ):
        self.name = name
        self.scene = scene
        self.labeller = Labeller(self.scene, label_settings)
        self.radius = self.labeller.max_distance
        diag = float(scene.diagonal)
        self.radii_rel = list(radii_rel or [])
        # rel * diag, as Labeller resolves radii_rel; the max distance itself where they agree, so its
        # column is exactly the single-radius label (bit for bit)
        self.radii = tuple(
            self.radius if math.isclose(float(r) * diag, self.radius, rel_tol=1e-9) else float(r) * diag
            for r in self.radii_rel
        )
        self.trace_radii = self.radii if self.radius in self.radii else (*self.radii, self.radius)
        self.main = self.trace_radii.index(self.radius)
        self.settings = settings
        self.cache = cache
        self.progress = progress
        self.bakes: dict[str, np.ndarray] = {}
        self.bake_info: dict[str, dict] = {}

    def baked(self, method: str) -> np.ndarray:
        """Per-vertex AO (n,) float32 of 'vertex-sampled' / 'vertex-lsq' (cached under OUT/bake/)."""
        if method in self.bakes:
            return self.bakes[method]
        if method == "vertex-lsq-8bit":  # what an RGBA8 vertex-colour attribute stores
            lsq = self.baked("vertex-lsq")
            self.bakes[method] = (np.rint(np.clip(lsq, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)
            return self.bakes[method]
        ls = self.labeller.settings
        bs = BakeSettings(
            rays=self.settings.bake_rays,
            max_distance=self.labeller.max_distance,
            kernel=ls.kernel,
            half_distance=self.labeller.half_distance,
            method="vertex" if method == "vertex-sampled" else "least-squares",
            samples_per_vertex=self.settings.bake_samples_per_vertex,
            backface_threshold=ls.backface_threshold,
            seed=frame_key_seed(self.settings.seed, "bake", self.name),
            workers=ls.workers,
        )
        key = {
            "scene": self.name,
            "vertices": len(self.scene.vertices),
            "faces": len(self.scene.faces),
            "source": self.scene.source,
            "bake": settings_to_dict(bs),
        }
        path = self.cache / f"{self.name}-{method}-{sha256_json(key)[:16]}.npz" if self.cache else None
        if path is not None and path.is_file():
            z = read_npz(path)
            self.bakes[method] = z["ao"]
            self.bake_info[method] = json.loads(str(z["info"]))
        else:
            log.info(
                "baking %s (%s, %d vertices) for the vertex-AO baselines",
                self.name,
                method,
                len(self.scene.vertices),
            )
            r = bake(self.scene, bs, progress=self.progress)
            self.bakes[method], self.bake_info[method] = r.ao, r.info
            if path is not None:
                write_npz(path, ao=r.ao, info=np.array(json.dumps(r.info, default=str)))
        return self.bakes[method]

    def timing_frame(self, frame: dict) -> tuple[dict, Camera]:
        """A ``time_size`` G-buffer from the pose of ``frame`` and its camera."""
        return timing_frame(self.scene, frame, self.settings.time_size)


def timing_frame(scene, frame: dict, size: tuple[int, int]) -> tuple[dict, Camera]:
    """A G-buffer of ``scene`` at ``size`` (W, H) from the pose of ``frame``, and its camera."""
    w, h = size
    cam = Camera(
        np.asarray(frame["pose"], np.float64),
        int(w),
        int(h),
        float(frame["yfov"]),
        float(frame["znear"]),
        float(frame["zfar"]),
    )
    with GBufferRenderer(scene) as r:
        return r.render(cam), cam


def predict(m: Method, ctx: SceneContext, frame: dict, radius: float | None = None) -> np.ndarray:
    """AO (H, W) float32 of method ``m`` on ``frame``; ``radius`` (scene units, default the labels'
    max distance) for the methods that take one (RADIUS_FAMILIES)."""
    s = ctx.settings
    radius = ctx.radius if radius is None else radius
    if m.family == "screen-space":
        return run_screen_space(frame, m.name, radius, s.ssao if m.name == "ssao" else s.gtao)
    if m.family == "baked":
        return vertex_ao_image(ctx.scene, ctx.baked(m.name), frame)
    if m.family == "traced":
        rays = int(m.name.split("-")[1])
        ao, _, _ = traced_ao(
            ctx.labeller, frame, rays, seed=frame_key_seed(s.seed, m.name, ctx.name, frame["view"])
        )
        return ao
    return predict_model(m, frame, radius)


def time_method(m: Method, ctx: SceneContext, frame512: dict, camera) -> float:
    s = ctx.settings
    if m.family == "screen-space":
        return time_screen_space(
            frame512, m.name, ctx.radius, s.ssao if m.name == "ssao" else s.gtao, repeats=s.repeats
        )
    if m.family == "baked":
        return time_vertex_ao(ctx.scene, camera, ctx.baked(m.name), repeats=s.repeats)
    if m.family == "traced":
        return traced_ao(ctx.labeller, frame512, int(m.name.split("-")[1]), seed=1)[2]
    raise ValueError(m.family)


# --------------------------------------------------------------------------- the run


def evaluate(
    data: str | Path,
    exports: str | Path | None,
    settings: ReportSettings,
    out: Path | None,
    families: set[str] | None = None,
    progress: bool = True,
    keep_images: bool = True,
    shipped: str | Path | None = None,
    shipped_picks: list[str] | tuple[str, ...] | None = None,
) -> dict:
    """Measure every method (or only ``families``) on the evaluation frames; returns the result dict
    (the content of report.json, without the figures). ``out`` holds the caches (None: no cache).
    ``exports``: a folder of export folders (None: none); ``shipped``: a shipped-models folder
    (runtime/models) whose U-Nets are added as ``shipped:<name>`` rows (None: not looked at), those of
    ``shipped_picks`` (roles or names, :func:`pick_shipped`; None: every one)."""
    check_settings(settings)
    ds = open_dataset(data)
    frames_by_scene = evaluation_frames(ds, settings.frames_per_scene)
    if not frames_by_scene:
        raise NeuralaoError(f"dataset {data} has no frame to evaluate on")
    label_settings = label_settings_of(ds, settings.workers)
    ds_rays = int(label_settings.rays)
    radii_rel = report_radii_rel(settings, label_settings)
    methods = baseline_methods(settings)
    if exports is not None:
        methods += discover_exports(Path(exports), ds.scenes, settings.expected_exports)
    shipped_info = None
    if shipped is not None:
        shipped_methods, shipped_info = discover_shipped(Path(shipped), ds.scenes, shipped_picks)
        methods += shipped_methods
    if families is not None:
        methods = [m for m in methods if m.family in families]
    for m in methods:
        if m.available and m.family in MODEL_FAMILIES:
            prepare_model(m)
    gt_cache = out / "gt" if out is not None else None
    bake_cache = out / "bake" if out is not None else None
    per_frame: list[dict] = []
    per_scene_time: dict[str, dict[str, float]] = {}
    sheets: dict[str, dict] = {}
    scene_info: dict[str, dict] = {}
    model_times: dict[str, dict] = {}
    total = sum(len(v) for v in frames_by_scene.values())
    bar = tqdm(total=total, desc="report", unit="frame", disable=not progress)
    for scene_name, frames in frames_by_scene.items():
        try:
            scene = scene_of(ds.manifest, scene_name)  # a mesh, or a composed scene rebuilt from its seed
            ctx = SceneContext(
                scene_name, scene, label_settings, settings, bake_cache, progress=False, radii_rel=radii_rel
            )
        except NeuralaoError as e:
            log.warning("scene %s skipped: %s", scene_name, e)
            scene_info[scene_name] = {"skipped": str(e)}
            bar.update(len(frames))
            continue
        scene_info[scene_name] = {
            "split": ds.split_of(scene_name),
            "vertices": len(ctx.scene.vertices),
            "faces": len(ctx.scene.faces),
            "radius": ctx.radius,
            "radii": list(ctx.radii),
            "frames": len(frames),
        }
        applicable = [m for m in methods if m.available and m.applies_to(scene_name)]
        for fi, frame in enumerate(frames):
            key = {
                "dataset": ds.manifest.get("dataset_hash"),
                "scene": scene_name,
                "view": frame["view"],
                "labels": settings_to_dict(label_settings),
                "gt_rays": settings.gt_rays,
                "seed": settings.seed,
            }
            truth = ground_truth(
                ctx.labeller, frame, ds_rays, settings, gt_cache, key, ctx.trace_radii, ctx.main
            )
            gt, gt_valid = truth.at(truth.main)
            fg = np.asarray(frame["mask"], bool)
            mask = fg & gt_valid
            row = {
                "scene": scene_name,
                "view": int(frame["view"]),
                "split": frame["split"],
                "holdout": bool(frame["holdout"]),
                "pixels": int(mask.sum()),
                "gt": truth.source,
                "methods": {},
            }
            if ctx.radii:  # the same frame at every radius of radii_rel: RADIUS_FAMILIES only
                row["radii"] = {
                    radius_key(rel): {
                        "radius": r,
                        "pixels": int((fg & truth.valid[..., j]).sum()),
                        "methods": {},
                    }
                    for j, (rel, r) in enumerate(zip(ctx.radii_rel, ctx.radii, strict=True))
                }
            if not mask.any():
                row["skipped"] = "no valid foreground pixel"
                per_frame.append(row)
                bar.update(1)
                continue
            images = {}
            for m in applicable:
                try:
                    pred = predict(m, ctx, frame)
                    at_radii = score_radii(m, ctx, frame, truth, pred) if m.family in RADIUS_FAMILIES else {}
                except Exception as e:  # one method failing must not sink the report
                    if m.family not in MODEL_FAMILIES:
                        raise
                    m.available, m.reason = (
                        False,
                        f"failed on {scene_name}/{frame['view']}: {str(e).splitlines()[0][:160]}",
                    )
                    continue
                row["methods"][m.name] = {
                    "ssim": masked_ssim(pred, gt, mask),
                    "rmse": masked_rmse(pred, gt, mask),
                }
                if settings.flip:
                    row["methods"][m.name]["flip"] = masked_flip(pred, gt, mask)
                for k, scores in at_radii.items():
                    row["radii"][k]["methods"][m.name] = scores
                if fi == 0 and keep_images:
                    images[m.name] = pred
            if fi == 0 and keep_images:
                sheets[scene_name] = {
                    "gt": gt,
                    "mask": mask,
                    "fg": np.asarray(frame["mask"], bool),
                    "view": int(frame["view"]),
                    "images": images,
                    "scene": ctx.scene,
                    "bakes": {k: v for k, v in ctx.bakes.items() if k == "vertex-lsq"},
                    "exports": _scene_exports(applicable, scene_name),
                }
            per_frame.append(row)
            bar.update(1)
        # timing at time_size, from the first frame's pose
        frame512, cam512 = ctx.timing_frame(frames[0])
        times = per_scene_time.setdefault(scene_name, {})
        for m in applicable:
            if not m.available:
                continue
            if m.family in MODEL_FAMILIES:
                if m.name not in model_times:
                    try:
                        model_times[m.name] = time_model(m, settings.time_size, settings.repeats)
                    except Exception as e:  # listed with its error, never fatal
                        model_times[m.name] = {
                            "error": str(e).splitlines()[0][:160] if str(e) else type(e).__name__
                        }
                if "seconds" in model_times[m.name]:
                    times[m.name] = model_times[m.name]["seconds"]
            else:
                times[m.name] = time_method(m, ctx, frame512, cam512)
        for name in ("vertex-sampled", "vertex-lsq"):
            if name in ctx.bake_info:
                scene_info[scene_name][f"bake_{name}"] = {
                    k: ctx.bake_info[name].get(k)
                    for k in ("samples", "invalid_samples", "seconds", "vertices")
                }
        for m in methods:
            if m.family == "baked" and m.available:
                scene_info[scene_name].setdefault("vertex_ao_bytes", 4 * len(ctx.scene.vertices))
                scene_info[scene_name].setdefault("vertices", len(ctx.scene.vertices))
    bar.close()
    ctx_gl = gl.context()
    result = {
        "format": "neuralao-report",
        "version": FORMAT_VERSION,
        "settings": settings_to_dict(settings),
        "dataset": {
            "path": str(data),
            "name": ds.manifest.get("name"),
            "dataset_hash": ds.manifest.get("dataset_hash"),
            "labels": settings_to_dict(label_settings),
            "label_rays": ds_rays,
            "size": ds.manifest.get("size"),
        },
        "device": {
            "gl_renderer": ctx_gl.info.renderer,
            "gl_version": ctx_gl.info.version,
            "gl_platform": ctx_gl.info.platform,
            "cpu": cpu_name(),
            "python": platform.python_version(),
        },
        "scenes": scene_info,
        "frames": per_frame,
        "model_times": model_times,
        "radii_rel": radii_rel,
        "radius_families": list(RADIUS_FAMILIES),
        "methods": summarise(methods, per_frame, per_scene_time, scene_info, model_times),
        "shipped": shipped_info,
    }
    result["pareto"] = pareto_front(result["methods"])
    result["_sheets"] = sheets
    return result


def score_radii(m: Method, ctx: SceneContext, frame: dict, truth: GroundTruth, pred: np.ndarray) -> dict:
    """radius key -> {ssim, rmse} of ``m`` given each radius of ``ctx.radii`` against the ground truth
    at that radius (``pred``: its output at the max distance, reused where a radius equals it)."""
    fg = np.asarray(frame["mask"], bool)
    out = {}
    for j, (rel, r) in enumerate(zip(ctx.radii_rel, ctx.radii, strict=True)):
        gt, valid = truth.at(j)
        mask = fg & valid
        if not mask.any():
            continue
        p = pred if r == ctx.radius else predict(m, ctx, frame, r)
        out[radius_key(rel)] = {"ssim": masked_ssim(p, gt, mask), "rmse": masked_rmse(p, gt, mask)}
    return out


def summarise_radii(name: str, per_frame: list[dict]) -> dict:
    """radius key -> mean SSIM / RMSE of ``name`` over the frames scored at that radius (and per scene),
    with its RMSE and (1 - SSIM) over SSAO's on the same frames at the same radius."""
    keys = sorted({k for r in per_frame for k in r.get("radii", {})}, key=float)
    out: dict = {}
    for k in keys:
        rows = [
            r["radii"][k]["methods"]
            for r in per_frame
            if name in r.get("radii", {}).get(k, {}).get("methods", {})
        ]
        if not rows:
            continue
        scenes = [r["scene"] for r in per_frame if name in r.get("radii", {}).get(k, {}).get("methods", {})]
        e = {
            "radius_rel": float(k),
            "frames": len(rows),
            "ssim": float(np.mean([r[name]["ssim"] for r in rows])),
            "rmse": float(np.mean([r[name]["rmse"] for r in rows])),
        }
        if all("ssao" in r for r in rows):
            s_rmse = float(np.mean([r["ssao"]["rmse"] for r in rows]))
            s_dssim = float(np.mean([1.0 - r["ssao"]["ssim"] for r in rows]))
            e["rmse_ratio_vs_ssao"] = e["rmse"] / s_rmse if s_rmse > 0 else None
            e["dssim_ratio_vs_ssao"] = (1.0 - e["ssim"]) / s_dssim if s_dssim > 0 else None
        e["per_scene"] = {
            s: {
                "ssim": float(
                    np.mean([r[name]["ssim"] for r, s2 in zip(rows, scenes, strict=True) if s2 == s])
                ),
                "rmse": float(
                    np.mean([r[name]["rmse"] for r, s2 in zip(rows, scenes, strict=True) if s2 == s])
                ),
            }
            for s in dict.fromkeys(scenes)
        }
        out[k] = e
    return out


def summarise(methods, per_frame, per_scene_time, scene_info, model_times) -> dict:
    """Per-method means, per-scene breakdown and ratios to SSAO on the same frames."""
    out: dict = {}
    for m in methods:
        entry = {
            "family": m.family,
            "description": m.description,
            "available": m.available,
            "reason": m.reason,
            "time_on": m.time_on,
            "error_on": m.error_on,
            "scope": m.scope,
            "bytes": m.bytes,
            "bytes_note": m.bytes_note,
            "two_sided": TWO_SIDED.get(m.family, True),
        }
        if m.family == "unet":
            entry["scale"] = m.scale
        if m.shipped is not None:
            entry["shipped"] = m.shipped
        rows = [r for r in per_frame if m.name in r["methods"]]
        if not m.available or not rows:
            if m.available:
                entry.update(available=False, reason="no frame of its scene in the evaluation set")
            out[m.name] = entry
            continue
        ssim = [r["methods"][m.name]["ssim"] for r in rows]
        rmse = [r["methods"][m.name]["rmse"] for r in rows]
        per_scene: dict = {}
        for r in rows:
            ps = per_scene.setdefault(r["scene"], {"ssim": [], "rmse": []})
            ps["ssim"].append(r["methods"][m.name]["ssim"])
            ps["rmse"].append(r["methods"][m.name]["rmse"])
        for scene, ps in per_scene.items():
            ps["frames"] = len(ps["ssim"])
            ps["ssim"], ps["rmse"] = float(np.mean(ps["ssim"])), float(np.mean(ps["rmse"]))
            t = per_scene_time.get(scene, {}).get(m.name)
            ps["seconds"] = t
        times = [per_scene_time[s][m.name] for s in per_scene if m.name in per_scene_time.get(s, {})]
        entry.update(
            frames=len(rows),
            ssim=float(np.mean(ssim)),
            rmse=float(np.mean(rmse)),
            seconds=float(np.median(times)) if times else None,
            per_scene=per_scene,
        )
        flip = [r["methods"][m.name].get("flip") for r in rows]
        entry["flip"] = float(np.mean(flip)) if all(f is not None for f in flip) else None
        if m.family == "baked":
            per_vertex = 1 if m.name.endswith("-8bit") else 4
            for scene, ps in per_scene.items():
                if scene_info[scene].get("vertices"):
                    ps["bytes"] = per_vertex * scene_info[scene]["vertices"]
            sizes = [ps["bytes"] for ps in per_scene.values() if "bytes" in ps]
            entry["bytes"] = int(np.mean(sizes)) if sizes else None
            entry["bytes_note"] = f"{per_vertex} B per vertex (mean over scenes)"
        if m.family in RADIUS_FAMILIES:
            per_radius = summarise_radii(m.name, per_frame)
            if per_radius:
                entry["per_radius"] = per_radius
        if m.name in model_times:
            entry["seconds_onnxruntime"] = model_times[m.name].get("seconds_onnxruntime")
            if "error" in model_times[m.name]:
                entry["timing_error"] = model_times[m.name]["error"]
        # SSAO on exactly the same frames
        ssao_rows = [r for r in rows if "ssao" in r["methods"]]
        if ssao_rows and len(ssao_rows) == len(rows):
            s_rmse = float(np.mean([r["methods"]["ssao"]["rmse"] for r in rows]))
            s_dssim = float(np.mean([1.0 - r["methods"]["ssao"]["ssim"] for r in rows]))
            entry["rmse_ratio_vs_ssao"] = entry["rmse"] / s_rmse if s_rmse > 0 else None
            entry["dssim_ratio_vs_ssao"] = (1.0 - entry["ssim"]) / s_dssim if s_dssim > 0 else None
            s_times = [per_scene_time[s]["ssao"] for s in per_scene if "ssao" in per_scene_time.get(s, {})]
            if entry["seconds"] is not None and s_times:
                entry["time_ratio_vs_ssao"] = entry["seconds"] / float(np.median(s_times))
        out[m.name] = entry
    return out


def pareto_front(methods: dict) -> list[str]:
    """Methods not dominated in (seconds, RMSE ratio vs SSAO): nothing else is both faster and better."""
    pts = {
        n: (e["seconds"], e["rmse_ratio_vs_ssao"])
        for n, e in methods.items()
        if e.get("available") and e.get("seconds") is not None and e.get("rmse_ratio_vs_ssao") is not None
    }
    front = []
    for n, (t, r) in pts.items():
        dominated = any(
            (t2 <= t and r2 <= r) and (t2 < t or r2 < r) for n2, (t2, r2) in pts.items() if n2 != n
        )
        if not dominated:
            front.append(n)
    return sorted(front, key=lambda n: pts[n][0])


def check_settings(s: ReportSettings) -> None:
    if s.gt_rays < 1 or s.frames_per_scene < 1 or s.repeats < 1 or s.bake_rays < 1:
        raise NeuralaoError("gt_rays, frames_per_scene, repeats and bake_rays must be >= 1")
    if len(s.time_size) != 2 or min(s.time_size) < 1:
        raise NeuralaoError(f"time_size must be two positive integers, got {s.time_size}")
    if any(r < 1 for r in s.trace_rays):
        raise NeuralaoError(f"trace_rays must be positive, got {s.trace_rays}")
    for t in [s.target_ssim, *s.select_targets]:
        if not (0.0 < t <= 1.0):
            raise NeuralaoError(f"target SSIM must be in (0, 1], got {t}")
    if s.radii_rel is not None and any(not (math.isfinite(r) and r > 0) for r in s.radii_rel):
        raise NeuralaoError(f"radii_rel must be positive fractions of the scene diagonal, got {s.radii_rel}")


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


# --------------------------------------------------------------------------- writing


def method_order(methods: dict) -> list[str]:
    def key(n: str):
        e = methods[n]
        fam = FAMILY_ORDER.get(e["family"], 9)
        sub = BASELINE_ORDER.index(n) if n in BASELINE_ORDER else (e.get("bytes") or 0)
        if e["family"] == "traced":
            sub = int(n.split("-")[1])
        return (fam, sub, n)

    return sorted(methods, key=key)


def _fmt(v, spec: str, none: str = "-") -> str:
    return none if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def _bytes(v) -> str:
    if v is None:
        return "-"
    return f"{v / 1024:.1f} KiB" if v >= 1024 else f"{v} B"


def render_markdown(result: dict, selection: dict | None, figures: dict) -> str:
    ms = result["methods"]
    d = result["dataset"]
    w, h = result["settings"]["time_size"]
    lines = [
        "# neuralao report: speed against error",
        "",
        f"Dataset `{d['name']}` ({d['dataset_hash'][:12] if d.get('dataset_hash') else '?'}), "
        f"{sum(1 for f in result['frames'] if 'skipped' not in f)} held-back frames at "
        f"{d['size'][0]}x{d['size'][1]}; ground truth: {result['settings']['gt_rays']} rays, "
        f"kernel {d['labels']['kernel']}, max distance {d['labels']['max_distance_rel']} x scene diagonal. "
        f"Times: {w}x{h} frames, GL on {result['device']['gl_renderer']} "
        f"({result['device']['gl_platform']}); CPU: {result['device']['cpu']}.",
        "",
        f"| method | scope | frames | SSIM | RMSE | FLIP | ms / frame ({w}x{h}) | time / SSAO | "
        "RMSE / SSAO | (1-SSIM) / SSAO | bytes | timed on |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for n in method_order(ms):
        e = ms[n]
        if not e.get("available"):
            continue
        pareto = " *" if n in result.get("pareto", []) else ""
        lines.append(
            f"| {n}{pareto} | {e['scope']} | {e['frames']} | {_fmt(e['ssim'], '.3f')} | "
            f"{_fmt(e['rmse'], '.4f')} | {_fmt(e.get('flip'), '.4f')} | "
            f"{_fmt(e['seconds'] * 1e3 if e.get('seconds') is not None else None, '.2f')} | "
            f"{_fmt(e.get('time_ratio_vs_ssao'), '.2f')} | {_fmt(e.get('rmse_ratio_vs_ssao'), '.2f')} | "
            f"{_fmt(e.get('dssim_ratio_vs_ssao'), '.2f')} | {_bytes(e.get('bytes'))} | {e['time_on']} |"
        )
    lines += [
        "",
        "`*` on the Pareto front of (time, RMSE / SSAO). Ratios are over SSAO on the same frames "
        "(an MLP or a field is measured on its own scene only). FLIP: NVIDIA's perceptual error "
        "(flip-evaluator, LDR, 67 pixels per degree; 0 = identical), AO shown as grey with the "
        "background set to 1 in both images, averaged over the foreground.",
    ]
    one_sided = [n for n in method_order(ms) if ms[n].get("available") and ms[n].get("two_sided") is False]
    if one_sided:
        lines += [
            "",
            "Single-sided surfaces: " + ", ".join(one_sided) + " store one value per vertex and so show "
            "the same AO on both sides of an open sheet (the G-buffer turns the normal towards the viewer); "
            "the fields, MLPs, U-Nets, screen-space and traced methods can tell the sides apart.",
        ]
    ort = [(n, ms[n]["seconds_onnxruntime"]) for n in method_order(ms) if ms[n].get("seconds_onnxruntime")]
    if ort:
        lines += [
            "",
            f"onnxruntime (CPU) at {w}x{h}: " + ", ".join(f"{n} {t * 1e3:.1f} ms" for n, t in ort) + ".",
        ]
    missing = [n for n in method_order(ms) if not ms[n].get("available")]
    if missing:
        lines += ["", "Not available:", ""] + [
            f"- {n}: {ms[n].get('reason') or 'not available'}" for n in missing
        ]
    lines += ["", "## Per scene (SSIM / RMSE)", ""]
    scenes = [s for s, info in result["scenes"].items() if "skipped" not in info]
    avail = [n for n in method_order(ms) if ms[n].get("available")]
    lines += ["| method | " + " | ".join(scenes) + " |", "|---|" + "---:|" * len(scenes)]
    for n in avail:
        cells = []
        for s in scenes:
            ps = ms[n].get("per_scene", {}).get(s)
            cells.append(f"{ps['ssim']:.3f} / {ps['rmse']:.3f}" if ps else "")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    skipped = {s: i["skipped"] for s, i in result["scenes"].items() if "skipped" in i}
    if skipped:
        lines += [""] + [f"- scene {s} skipped: {why}" for s, why in skipped.items()]
    lines += radius_markdown(result)
    lines += shipped_markdown(result.get("shipped"), figures)
    if figures:
        lines += ["", "## Figures", ""]
        if figures.get("scatter"):
            lines += [f"![speed vs error]({figures['scatter']})", ""]
        for s, p in figures.get("contact_sheets", {}).items():
            lines += [f"![{s}]({p})", ""]
        if figures.get("viewer"):
            lines += [
                "WebGL2 viewer pages (`neuralao view`; also linked from report.html): "
                + ", ".join(f"[{s}]({p})" for s, p in figures["viewer"].items()),
                "",
            ]
    if selection is not None:
        lines += ["", select_markdown(selection, heading="## Model selection")]
    if result.get("select_at"):
        lines += ["", targets_markdown({float(t): sel for t, sel in result["select_at"].items()})]
    lines += [
        "",
        "## How this was measured",
        "",
        "- Error: masked SSIM (Gaussian window 11, sigma 1.5) and RMSE over foreground pixels with valid "
        "ground truth, mean over frames. SSAO, GTAO and the MLP: their GLSL on the frames' G-buffers; "
        "U-Net: onnxruntime (its generated GLSL matches it within the parity tolerance); "
        "vertex AO: barycentric interpolation of the baked values (what the vertex-colour draw shows); "
        "traced: Embree.",
        "- Time: median seconds per frame at the stated size, G-buffer resident; "
        "GL methods with glFinish around each frame in this process's headless context; traced AO: "
        "wall time of the CPU trace; the U-Net's GL time covers all generated compute passes. "
        "A method's time is the median over scenes.",
        "- Bytes: float32 weights for the networks, 4 bytes per vertex for baked AO, "
        "shader constants for SSAO/GTAO.",
    ]
    return "\n".join(lines) + "\n"


def radius_markdown(result: dict) -> list[str]:
    """The per-radius section: every RADIUS_FAMILIES method at each radius of ``radii_rel``."""
    ms = result["methods"]
    keys = [radius_key(r) for r in result.get("radii_rel") or []]
    rows = [n for n in method_order(ms) if ms[n].get("available") and ms[n].get("per_radius")]
    labels = result["dataset"]["labels"]
    main = (
        f"r = {labels['max_distance_rel']:g}"
        if labels.get("max_distance") is None
        else f"{labels['max_distance']:g} scene units"
    )
    if not keys or not rows:
        return ["", f"Per-radius evaluation: none (only the labels' max distance, {main})."]
    lines = [
        "",
        "## Per radius (SSAO, GTAO and the U-Nets given the same radius)",
        "",
        "Radius r as a fraction of each scene's diagonal; ground truth at every radius from one "
        f"{result['settings']['gt_rays']}-ray trace. The tables above are at the labels' max distance "
        f"({main}); the vertex bakes, MLPs, fields and traced rows have that radius baked in. Cells: "
        "SSIM / RMSE (RMSE / SSAO's RMSE at the same radius).",
        "",
        "| method | " + " | ".join(f"r = {k}" for k in keys) + " |",
        "|---|" + "---:|" * len(keys),
    ]
    for n in rows:
        cells = []
        for k in keys:
            e = ms[n]["per_radius"].get(k)
            ratio = (
                f" ({e['rmse_ratio_vs_ssao']:.2f}x)" if e and e.get("rmse_ratio_vs_ssao") is not None else ""
            )
            cells.append(f"{e['ssim']:.3f} / {e['rmse']:.4f}{ratio}" if e else "-")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return lines


def scatter_plot(result: dict, path: Path) -> Path | None:
    """Speed (ms, log) against RMSE relative to SSAO, with the Pareto front."""
    import matplotlib  # imported here: a measured import-time cost (~0.5 s), for this plot only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    ms = result["methods"]
    pts = [
        (n, ms[n]["seconds"] * 1e3, ms[n]["rmse_ratio_vs_ssao"], ms[n]["family"])
        for n in method_order(ms)
        if ms[n].get("available") and ms[n].get("seconds") and ms[n].get("rmse_ratio_vs_ssao") is not None
    ]
    if not pts:
        return None
    fig, ax = plt.subplots(figsize=(7.5, 5.0), dpi=110)
    for n, t, r, fam in pts:
        on = n in result.get("pareto", [])
        ax.scatter(
            [t],
            [r],
            s=60 if on else 36,
            color=COLOURS.get(fam, "k"),
            edgecolors="k" if on else "none",
            zorder=3,
        )
        ax.annotate(n, (t, r), textcoords="offset points", xytext=(5, 4), fontsize=8)
    front = [(ms[n]["seconds"] * 1e3, ms[n]["rmse_ratio_vs_ssao"]) for n in result.get("pareto", [])]
    if len(front) > 1:
        xs, ys = zip(*sorted(front), strict=True)
        ax.step(xs, ys, where="post", color="k", lw=1, ls="--", zorder=2, label="Pareto front")
        ax.legend(loc="upper right", fontsize=8)
    ax.axhline(1.0, color="tab:blue", lw=0.6, ls=":")
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    w, h = result["settings"]["time_size"]
    ax.set_xlabel(
        f"time per frame at {w}x{h} (ms, log; GL on {result['device']['gl_renderer'][:40]}, traced on CPU)"
    )
    ax.set_ylabel("RMSE / SSAO's RMSE (same frames)")
    ax.set_title("AO methods: speed against error")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


def _scene_exports(methods: list[Method], scene: str) -> dict[str, str]:
    """Method name -> export folder of the per-mesh networks (MLP, field) that apply to ``scene``."""
    out = {}
    for m in methods:
        if m.family not in kinds.KINDS or not kinds.KINDS[m.family].per_mesh:
            continue
        exports = m.scene_exports if m.scene_exports is not None else {m.scene: m.export}
        if exports.get(scene) is not None:
            out[m.name] = str(exports[scene])
    return out


def contact_order(result: dict, wanted: list[str]) -> list[str]:
    """The methods of a contact sheet: ``wanted`` (ReportSettings.contact_methods) resolved against the
    report's rows: ``shipped:default`` / ``shipped:fast`` to the shipped rows of those roles, ``field`` /
    ``mlp`` to the smallest row of that family; names not in the report are left out. Empty: every row."""
    ms = result["methods"]
    roles = (result.get("shipped") or {}).get("roles") or {}
    order: list[str] = []
    for name in wanted:
        role = name[len(SHIPPED_PREFIX) :] if name.startswith(SHIPPED_PREFIX) else None
        if role in ("default", "fast"):
            name = SHIPPED_PREFIX + roles.get(role, "")
        elif name in MODEL_FAMILIES and name not in ms:
            rows = sorted((ms[n].get("bytes") or 0, n) for n in ms if ms[n].get("family") == name)
            name = rows[0][1] if rows else name
        if name in ms and ms[name].get("available", True) and name not in order:
            order.append(name)
    return order or method_order(ms)


def contact_sheet(scene: str, sheet: dict, order: list[str], path: Path) -> Path:
    """The scene's contact sheet (:func:`neuralao.pipeline.evaluation.figures.contact_sheet`)."""
    return readable_sheet(scene, sheet, order, path)


def write_report(result: dict, out: Path, settings: ReportSettings) -> dict:
    """Figures, the selection section, report.json and report.md (written last) under ``out``."""
    sheets = result.pop("_sheets", {})
    figures: dict = {"contact_sheets": {}}
    scatter = scatter_plot(result, out / "speed_vs_error.png")
    if scatter is not None:
        figures["scatter"] = scatter.name
    figures.update(write_shipped_plots(result.get("shipped"), out))
    if settings.contact_sheets:
        order = contact_order(result, settings.contact_methods)
        for scene, sheet in sheets.items():
            figures["contact_sheets"][scene] = contact_sheet(
                scene, sheet, order, out / f"contact_{scene}.png"
            ).name
    selection = select_from_results(result, settings.target_ssim)
    result["select"] = selection
    result["select_at"] = {
        str(t): select_from_results(result, t) for t in sorted(set(settings.select_targets))
    }
    viewer_links = write_viewer_pages(sheets, out) if settings.viewer_pages else {}
    figures["viewer"] = viewer_links
    result["figures"] = figures
    write_json(out / "report.json", result)
    write_html(result, out, figures, viewer_links)
    write_text(out / "report.md", render_markdown(result, selection, figures))
    return result
