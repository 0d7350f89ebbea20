"""What `neuralao report` is asked for and what one of its rows is: :class:`ReportSettings` (with
:func:`check_settings`) and :class:`Method`, shared by every report module
(:mod:`neuralao.pipeline.evaluation.report` describes the whole measurement)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from neuralao.runtime.baselines import GTAOSettings, SSAOSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.predict import Predictor

EXPECTED_EXPORTS = ("mlp-16x8", "mlp-32x16", "mlp-64x32", "unet")
SHIPPED_PREFIX = "shipped:"  # row-name prefix of the release models of runtime/models
# Shipped rows a report shows unless told otherwise: the default model and the fast one
# (neuralao.pipeline.evaluation.report_rows.pick_shipped).
SHIPPED_PICKS = ("default", "fast")


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


@dataclass
class Method:
    """One entry of the report: what it is, where it runs, what it applies to."""

    name: str
    # A baseline family (screen-space | baked | traced) or a model kind (neuralao.runtime.kinds).
    family: str
    description: str
    time_on: str
    error_on: str
    scene: str | None = None  # the only scene it applies to (baked MLP), None = every scene
    bytes: int | None = None
    bytes_note: str = ""
    export: Path | None = None
    available: bool = True
    reason: str = ""
    # Model methods, prepared by report_gl.prepare_model: the AO its error is measured on, its
    # onnxruntime inference (neuralao.runtime.predict) and the generated GLSL program that is timed.
    predictor: Predictor | None = None
    ort: Predictor | None = None
    program: Any = None
    # One network per mesh, one row per size (fields): scene -> export folder; the rows of one name
    # from several export folders are merged into one (report_rows.discover_exports).
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
