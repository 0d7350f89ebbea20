"""Screen-space AO judged where users run it (`neuralao evaluate`, :mod:`neuralao.pipeline.cli.evaluate`).

Test frames in categories (isolated scans, glTF game assets, low-poly interiors, composed rooms: all
from test-split meshes, :mod:`neuralao.pipeline.geometry.splits`) at several resolutions (128, 256, 512,
1920x1080 in
``configs/eval.json``), labelled by Embree at every radius of the trained range from one trace. Each
resolution is a dataset of its own under ``OUT/frames/<W>x<H>`` (built, or resumed, by the dataset
stage: an interrupted run continues). Every method gets the same radius in scene units: a U-Net
export as its radius input, SSAO and GTAO as their kernel radius in the same GL runtime. A U-Net
runs at its frame's resolution (``native``) or at an internal height (``h256``: point-sampled
G-buffer, joint bilateral upsampling; :mod:`neuralao.runtime.internal_resolution`); ``--internal`` lists the
policies to score, ``model`` is the one the model's manifest declares.

A score is masked SSIM, RMSE and FLIP over the valid foreground pixels of one (frame, radius) pair;
a cell of the table (category x resolution) is the mean over its pairs. Writes ``OUT/evaluation.json``
and ``OUT/evaluation.md``; with ``--write-manifest`` each U-Net's manifest gets the table under
``evaluation``.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from neuralao.pipeline.datasets.dataset import (
    ComposedScenes,
    DatasetSettings,
    SceneSpec,
    _config_dict,
    build_dataset,
    check_counts,
    open_dataset,
)
from neuralao.pipeline.evaluation.test_split import score_frame, screen_space_predictor, unet_predictor
from neuralao.pipeline.geometry.splits import HELD_ASIDE, split_of
from neuralao.pipeline.tracing.labeller import LabelSettings, check_rays
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json, write_text
from neuralao.runtime.foundation.limits import MAX_CAP, MAX_SEED, check_count, check_int_range, check_seed
from neuralao.runtime.foundation.manifest import read_json, read_manifest
from neuralao.runtime.foundation.paths import check_plain_name
from neuralao.runtime.foundation.settings import settings_to_dict
from neuralao.runtime.unet_input import BACK_LAYER_VERSION

log = logging.getLogger(__name__)

Predictor = Callable[[dict, float], np.ndarray]  # (frame, radius in scene units) -> AO (H, W)
METRICS = ("ssim", "rmse", "flip")
# The camera kinds of a category (a category has no poses file: "file" is the dataset's alone).
CAMERA_KINDS = ("orbit", "interior", "closeup")
# What one camera or scene entry takes before anything is rendered (as the dataset stage counts it).
SCENE_BYTES = 4096


@dataclass
class EvalCategory:
    """One category of test frames."""

    name: str  # short name used in scene names and the table (e.g. "scans")
    meshes: list[str] = field(default_factory=list)  # test-split meshes shown alone (bare names or files)
    cameras: str = "orbit"  # camera kind of the meshes: orbit (isolated objects) or interior (rooms)
    composed: int = 0  # number of composed rooms of test-split meshes (instead of ``meshes``)
    composed_seed: int = 20000  # room i is composed with composed_seed + i
    # The meshes are held aside (pipeline.geometry.splits.HELD_ASIDE): in no frame of the larger corpus.
    # Only such meshes are accepted outside the test split; score models trained on that corpus with it.
    held_aside: bool = False


@dataclass
class EvalResolution:
    """One resolution of the evaluation."""

    size: tuple[int, int] = (256, 256)  # width, height in pixels
    rays: int = 512  # label rays per pixel
    views: int = 3  # views per scene
    scenes_per_category: int = 0  # > 0: only the first k scenes of each category (large frames)


@dataclass
class EvalSettings:
    """Settings of `neuralao evaluate`."""

    name: str = "evaluation"  # recorded in the output
    seed: int = 0  # cameras and label directions derive from it
    radii_rel: list[float] = field(
        default_factory=lambda: [0.03125, 0.0625, 0.125, 0.25]
    )  # AO radii / diagonal
    max_distance_rel: float = 0.25  # longest label ray / diagonal (>= the largest radius)
    categories: list[EvalCategory] = field(default_factory=list)  # the kinds of frames
    resolutions: list[EvalResolution] = field(default_factory=list)  # the sizes they are rendered at
    allow_trained_meshes: bool = False  # True: accept train/val meshes (an evaluation of memory, not use)


def dataset_settings(
    settings: EvalSettings, res: EvalResolution, back_layer: bool = False
) -> DatasetSettings:
    """The dataset of one resolution: every category's scenes, all in the test split (with the G-buffer's
    back layer where a model reads it)."""
    w, h = (int(v) for v in res.size)
    scenes: list[SceneSpec] = []
    composed: list[ComposedScenes] = []
    for cat in settings.categories:
        names = cat.meshes[: res.scenes_per_category] if res.scenes_per_category > 0 else cat.meshes
        for mesh in names:
            label = Path(mesh).stem if ("/" in mesh or "." in mesh) else mesh
            scenes.append(
                SceneSpec(
                    name=f"{cat.name}-{label}", mesh=mesh, cameras=cat.cameras, views=res.views, split="test"
                )
            )
        count = min(cat.composed, res.scenes_per_category) if res.scenes_per_category > 0 else cat.composed
        if count > 0:
            cameras = [cat.cameras] if cat.cameras in CAMERA_KINDS else ["interior"]
            composed.append(
                ComposedScenes(
                    count=count,
                    seed=cat.composed_seed,
                    prefix=cat.name,
                    views=res.views,
                    split="test",
                    cameras=cameras,
                )
            )
    labels = LabelSettings(
        rays=res.rays, max_distance_rel=settings.max_distance_rel, radii_rel=list(settings.radii_rel)
    )
    return DatasetSettings(
        name=f"{settings.name}-{w}x{h}",
        scenes=scenes,
        composed=composed,
        size=(w, h),
        labels=labels,
        seed=settings.seed,
        holdout_every=0,
        frames_per_shard=1 if w * h > 1 << 20 else 4,
        back_layer=back_layer,
    )


def ensure_frames(ds: DatasetSettings, folder: Path, config_dir: Path, progress: bool) -> None:
    """The labelled frames of one resolution: kept when ``folder`` holds a finished dataset of exactly
    this config (its manifest's config), else built or resumed by the dataset stage."""
    if (folder / "manifest.json").is_file():
        try:
            made = read_json(folder / "manifest.json", "dataset manifest")
            done, layered = made.get("config"), made.get("back_layer") is not None
        except (NeuralaoError, AttributeError):
            done = layered = None
        if done == json.loads(json.dumps(_config_dict(ds), default=str)) and (layered or not ds.back_layer):
            return
    build_dataset(ds, folder, config_dir, progress)


def check_settings(settings: EvalSettings) -> None:
    """Every setting before any work: names that become file names, camera kinds, radii, and every count
    within what the machine can hold (neuralao.runtime.foundation.limits)."""
    if not settings.categories or not settings.resolutions:
        raise NeuralaoError("the evaluation config needs at least one category and one resolution")
    check_seed("seed", settings.seed)
    if not settings.radii_rel or any(not (0 < r <= settings.max_distance_rel) for r in settings.radii_rel):
        raise NeuralaoError(
            f"radii_rel must be in (0, max_distance_rel={settings.max_distance_rel}], "
            f"got {settings.radii_rel}"
        )
    names = [c.name for c in settings.categories]
    if len(set(names)) != len(names):
        raise NeuralaoError(f"category names must be unique, got {names}")
    for cat in settings.categories:
        check_plain_name("category name", cat.name)  # it prefixes the scene and shard names
        where = f"category {cat.name!r}"
        if cat.cameras not in CAMERA_KINDS:
            raise NeuralaoError(
                f"{where}: cameras {cat.cameras!r} is not a camera kind; a category's is one of "
                f"{', '.join(CAMERA_KINDS)}"
            )
        check_count(f"{where}: composed", cat.composed, low=0, bytes_each=SCENE_BYTES, each="a scene entry")
        check_int_range(f"{where}: composed_seed", cat.composed_seed, 0, MAX_SEED - cat.composed)
        if not cat.meshes and cat.composed < 1:
            raise NeuralaoError(f"category {cat.name!r} has no meshes and no composed rooms")
        for mesh in cat.meshes:
            split = split_of(mesh)
            if cat.held_aside and mesh not in HELD_ASIDE:
                raise NeuralaoError(
                    f"category {cat.name!r}: mesh {mesh!r} is not held aside "
                    f"(those are {', '.join(HELD_ASIDE)})"
                )
            if split not in (None, "test") and not settings.allow_trained_meshes and not cat.held_aside:
                raise NeuralaoError(
                    f"category {cat.name!r}: mesh {mesh!r} is in the {split} split; evaluate on test meshes"
                )
    workers = LabelSettings().workers  # the labeller's, which the frames are traced with
    for res in settings.resolutions:
        w, h = res.size
        if not (16 <= w <= 8192 and 16 <= h <= 8192):
            raise NeuralaoError(f"resolution {w}x{h}: sizes must be 16..8192")
        check_rays(f"resolution {w}x{h}: rays", res.rays, workers)
        check_count(f"resolution {w}x{h}: views", res.views, bytes_each=SCENE_BYTES, each="a camera")
        check_int_range(f"resolution {w}x{h}: scenes_per_category", res.scenes_per_category, 0, MAX_CAP)


def check_frames(settings: EvalSettings, out: Path) -> None:
    """:func:`check_settings`, then each resolution's dataset as the dataset stage counts it (scenes
    and views together, frames in memory, the disk under ``out``): all before any model is read."""
    check_settings(settings)
    for res in settings.resolutions:
        w, h = (int(v) for v in res.size)
        check_counts(dataset_settings(settings, res), out / "frames" / f"{w}x{h}")


# ------------------------------------------------------------------------------------------ methods


def unet_predictors(folder: Path, policies: list[str]) -> dict[str, Predictor]:
    """A predictor per internal-resolution policy of one U-Net export folder (onnxruntime)."""
    if not (folder / "manifest.json").is_file():
        raise NeuralaoError(f"{folder} is not an export folder (no manifest.json)")
    manifest = read_manifest(folder)
    if manifest.get("kind") != "unet":
        raise NeuralaoError(
            f"{folder}: evaluate scores screen-space U-Nets, this export is {manifest.get('kind')!r}"
        )
    onnx_path = folder / manifest.get("onnx", "model.onnx")
    out = {}
    for policy in policies:
        label = folder.name if policy == "model" else f"{folder.name}@{policy}"
        out[label] = unet_predictor(onnx_path, internal_height_of(policy, manifest))
    return out


def reads_back_layer(manifest: dict) -> bool:
    """Whether an export's input has the G-buffer's back layer (its input contract's version)."""
    version = (manifest.get("metadata") or {}).get("preprocess_version", 0)
    return str(version).isdigit() and int(version) == BACK_LAYER_VERSION


def trained_on_held_aside(manifest: dict) -> bool:
    """Whether an export's training scenes include a held-aside mesh (alone or as a close-up of it)."""
    scenes = (manifest.get("metadata") or {}).get("training_scenes") or []
    return any(str(s).split("-close")[0] in HELD_ASIDE for s in scenes)


def internal_height_of(policy: str, manifest: dict) -> int | None:
    """Internal height of a policy: ``native`` -> None, ``h<N>`` -> N, ``model`` -> the manifest's."""
    if policy == "native":
        return None
    if policy == "model":
        return manifest.get("internal_height")
    if policy.startswith("h") and policy[1:].isdigit() and int(policy[1:]) >= 16:
        return int(policy[1:])
    raise NeuralaoError(f"--internal {policy!r}: use native, model or h<HEIGHT> (e.g. h256)")


BASELINES = ("ssao", "gtao")  # the screen-space methods every table scores beside the U-Nets


def baseline_predictors() -> dict[str, Predictor]:
    return {name: screen_space_predictor(name) for name in BASELINES}


# ------------------------------------------------------------------------------------------ scoring


def category_of(scene: str, settings: EvalSettings) -> str:
    for cat in settings.categories:
        if scene.startswith(f"{cat.name}-"):
            return cat.name
    raise NeuralaoError(f"scene {scene!r} belongs to no category")


def summarise(rows: list[dict], methods: list[str], radii_rel: list[float]) -> dict:
    """method -> {cells: {category: {resolution: {ssim, rmse, flip, pairs}}}, per_radius: ..., all: ...}."""
    mean = lambda sel, k: float(np.mean([r[k] for r in sel])) if sel else float("nan")  # noqa: E731
    out = {}
    for m in methods:
        mine = [r for r in rows if r["method"] == m]
        cells: dict[str, dict] = {}
        for cat in sorted({r["category"] for r in mine}):
            cells[cat] = {}
            for res in sorted({r["resolution"] for r in mine if r["category"] == cat}, key=_pixels):
                sel = [r for r in mine if r["category"] == cat and r["resolution"] == res]
                cells[cat][res] = {k: mean(sel, k) for k in METRICS} | {"pairs": len(sel)}
        per_radius = {
            f"{radii_rel[j]:g}": {k: mean([r for r in mine if r["radius"] == j], k) for k in METRICS}
            for j in sorted({r["radius"] for r in mine})
        }
        out[m] = {
            "cells": cells,
            "per_radius": per_radius,
            "all": {k: mean(mine, k) for k in METRICS} | {"pairs": len(mine)},
        }
    return out


def _pixels(res: str) -> int:
    w, h = res.split("x")
    return int(w) * int(h)


def markdown(summary: dict, reference: str = "gtao", level: int = 3) -> str:
    """Tables of categories x resolutions, one per metric, every method a column."""
    methods = list(summary)
    cats = sorted({c for m in methods for c in summary[m]["cells"]})
    lines = []
    for metric, better in (("ssim", "higher"), ("rmse", "lower"), ("flip", "lower")):
        lines += [
            f"{'#' * level} {metric.upper()} ({better} is better)",
            "",
            "| category | resolution | " + " | ".join(methods) + " |",
            "|---|---|" + "---:|" * len(methods),
        ]
        for cat in cats:
            ress = sorted({r for m in methods for r in summary[m]["cells"].get(cat, {})}, key=_pixels)
            for res in ress:
                vals = [
                    summary[m]["cells"].get(cat, {}).get(res, {}).get(metric, float("nan")) for m in methods
                ]
                lines.append(f"| {cat} | {res} | " + " | ".join(f"{v:.3f}" for v in vals) + " |")
        vals = [summary[m]["all"][metric] for m in methods]
        lines += ["| **all** | | " + " | ".join(f"**{v:.3f}**" for v in vals) + " |", ""]
    if reference in summary:
        lines += [f"Cells where a method beats {reference.upper()} in both SSIM and RMSE:", ""]
        for m in methods:
            if m == reference:
                continue
            won = total = 0
            for cat, by_res in summary[m]["cells"].items():
                for res, cell in by_res.items():
                    ref = summary[reference]["cells"].get(cat, {}).get(res)
                    if ref is None:
                        continue
                    total += 1
                    won += cell["ssim"] > ref["ssim"] and cell["rmse"] < ref["rmse"]
            lines.append(f"- {m}: {won} of {total}")
        lines.append("")
    return "\n".join(lines)


def check_model_names(models: list[Path]) -> None:
    """The tables name each U-Net by its folder: two folders of one name, or one named like a baseline,
    would share a column (one model's scores lost). One line naming them."""
    seen: dict[str, Path] = {}
    for folder in map(Path, models):
        if folder.name in BASELINES:
            raise NeuralaoError(f"--models {folder}: the folder's name is a baseline's column; rename it")
        if folder.name in seen:
            raise NeuralaoError(
                f"--models {seen[folder.name]} and {folder} have the same folder name, and the tables name "
                "each model by its folder; give them different names"
            )
        seen[folder.name] = folder


def evaluate(
    settings: EvalSettings,
    out: Path,
    models: list[Path],
    policies: list[str],
    config_dir: Path,
    flip: bool = True,
    progress: bool = True,
) -> dict:
    """Build (or resume) the frames of every resolution, score every method, write the tables."""
    check_model_names(models)
    check_frames(settings, out)
    methods: dict[str, Predictor] = {}
    saw_held_aside: set[str] = set()  # methods whose model trained on the held-aside meshes
    for folder in models:
        mine = unet_predictors(Path(folder), policies)
        if trained_on_held_aside(read_manifest(Path(folder))):
            log.info("%s trained on held-aside meshes: its held-aside rows are left out", Path(folder).name)
            saw_held_aside.update(mine)
        methods.update(mine)
    back_layer = any(reads_back_layer(read_manifest(Path(folder))) for folder in models)
    held_aside = {c.name for c in settings.categories if c.held_aside}
    methods.update(baseline_predictors())
    rows: list[dict] = []
    build_times = {}
    for res in settings.resolutions:
        w, h = (int(v) for v in res.size)
        key = f"{w}x{h}"
        t0 = time.perf_counter()
        ensure_frames(dataset_settings(settings, res, back_layer), out / "frames" / key, config_dir, progress)
        build_times[key] = time.perf_counter() - t0
        t0 = time.perf_counter()
        for frame in open_dataset(out / "frames" / key).frames(split="test"):
            category = category_of(frame["scene"], settings)
            for row in score_frame(frame, methods, flip):
                if category in held_aside and row["method"] in saw_held_aside:
                    continue  # not held aside for this model: its score there would be one of memory
                rows.append(
                    row
                    | {
                        "category": category,
                        "resolution": key,
                        "scene": frame["scene"],
                        "view": frame["view"],
                    }
                )
        log.info(
            "%s: labels ready in %.0f s, scored in %.0f s", key, build_times[key], time.perf_counter() - t0
        )
        result = _write_tables(
            out, settings, policies, models, list(methods), rows, build_times
        )  # done so far
    return result


def _write_tables(
    out: Path, settings: EvalSettings, policies, models, methods: list[str], rows, build_times
) -> dict:
    """evaluation.json and evaluation.md of the rows scored so far (rewritten after each resolution)."""
    summary = summarise(rows, methods, list(settings.radii_rel))
    result = {
        "config": settings_to_dict(settings),
        "policies": policies,
        "methods": summary,
        "rows": rows,
        "models": [str(m) for m in models],
        "build_seconds": dict(build_times),
    }
    write_json(out / "evaluation.json", result)
    write_text(out / "evaluation.md", markdown(summary))
    return result


def write_to_manifests(result: dict, models: list[Path]) -> None:
    """Each U-Net export's manifest gets its rows of the table (and SSAO's and GTAO's beside them)."""
    for folder in models:
        path = Path(folder) / "manifest.json"
        manifest = read_manifest(folder)
        mine = {
            k: v
            for k, v in result["methods"].items()
            if k.split("@")[0] == Path(folder).name or k in ("ssao", "gtao")
        }
        manifest["evaluation"] = {"config": result["config"], "methods": mine}
        write_json(path, manifest)
