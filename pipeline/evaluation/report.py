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
time (SSAO, GTAO, the U-Nets: the families whose ``radius_input`` is set) are also evaluated at every
radius of ``radii_rel`` (x the scene diagonal; default the dataset's ``labels.radii_rel``), each given
the same radius (the U-Net as its radius input rho, :func:`neuralao.pipeline.models.unet.frame_radius_param`),
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
  models only (:func:`neuralao.pipeline.evaluation.report_rows.pick_shipped`; ``--shipped all`` or names
  for others); their training curves, corpus-size study and test figures (from ``index.json`` and the
  manifests' provenance) are plotted by :mod:`neuralao.pipeline.evaluation.plots`. None shipped: the
  report says so in one line.

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

The report's modules, in the order a run uses them: ``report_settings`` (settings, ``Method``),
``report_truth`` (frames, ground truth), ``report_baselines`` (baseline rows and families, the
per-scene context), ``report_rows`` (model rows from export folders and shipped models), ``report_gl``
(model rows' GLSL and onnxruntime runs and timings), this module (the run, the per-method summaries)
and ``report_writing`` (markdown, figures, report.json and report.html). The model kinds come from
:mod:`neuralao.runtime.kinds`.
"""

from __future__ import annotations

import logging
import platform
from pathlib import Path

import numpy as np
from tqdm import tqdm

from neuralao.pipeline.datasets.dataset import open_dataset, scene_of
from neuralao.pipeline.evaluation.report_baselines import (
    BASELINES,
    SceneContext,
    baseline_methods,
    family_two_sided,
    radius_families,
)
from neuralao.pipeline.evaluation.report_gl import predict_model, prepare_model, time_model
from neuralao.pipeline.evaluation.report_rows import discover_exports, discover_shipped
from neuralao.pipeline.evaluation.report_settings import Method, ReportSettings, check_settings
from neuralao.pipeline.evaluation.report_truth import (
    GroundTruth,
    evaluation_frames,
    ground_truth,
    label_settings_of,
    radius_key,
    report_radii_rel,
)
from neuralao.runtime import gl, kinds
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.machine import cpu_name
from neuralao.runtime.foundation.metrics import masked_flip, masked_rmse, masked_ssim
from neuralao.runtime.foundation.settings import settings_to_dict
from neuralao.runtime.frame import FrameLike

log = logging.getLogger(__name__)

FORMAT_VERSION = 1


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
    ``shipped_picks`` (roles or names, :func:`neuralao.pipeline.evaluation.report_rows.pick_shipped`;
    None: every one)."""
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
    model_families = kinds.reported()
    radius_fams = radius_families()
    for m in methods:
        if m.available and m.family in model_families:
            prepare_model(m)
    if out is not None:  # made only now that the inputs are read: a refused run leaves no folder behind
        out.mkdir(parents=True, exist_ok=True)
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
            if ctx.radii:  # the same frame at every radius of radii_rel: the radius families only
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
                    at_radii = score_radii(m, ctx, frame, truth, pred) if m.family in radius_fams else {}
                except Exception as e:  # one method failing must not sink the report
                    if m.family not in model_families:
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
            if m.family in model_families:
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
        "radius_families": list(radius_fams),
        "methods": summarise(methods, per_frame, per_scene_time, scene_info, model_times),
        "shipped": shipped_info,
    }
    result["pareto"] = pareto_front(result["methods"])
    result["_sheets"] = sheets
    return result


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


def predict(m: Method, ctx: SceneContext, frame: FrameLike, radius: float | None = None) -> np.ndarray:
    """AO (H, W) float32 of method ``m`` on ``frame``; ``radius`` (scene units, default the labels'
    max distance) for the methods that take one (``report_baselines.radius_families``)."""
    radius = ctx.radius if radius is None else radius
    baseline = BASELINES.get(m.family)
    return predict_model(m, frame, radius) if baseline is None else baseline.ao(m, ctx, frame, radius)


def time_method(m: Method, ctx: SceneContext, frame512: dict, camera) -> float:
    """Seconds per frame of baseline ``m`` on the scene's ``time_size`` G-buffer and its camera."""
    return BASELINES[m.family].seconds(m, ctx, frame512, camera)


def score_radii(m: Method, ctx: SceneContext, frame: FrameLike, truth: GroundTruth, pred: np.ndarray) -> dict:
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
            "two_sided": family_two_sided(m.family),
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
        if m.family in radius_families():
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
