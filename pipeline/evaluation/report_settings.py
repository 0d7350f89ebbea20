"""What `neuralao report` is asked for and what one of its rows is: :class:`ReportSettings` (with
:func:`check_settings`) and :class:`Method`, shared by every report module
(:mod:`neuralao.pipeline.evaluation.report` describes the whole measurement)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from neuralao.pipeline.tracing.labeller import check_rays
from neuralao.runtime.baselines import GTAOSettings, SSAOSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import (
    MAX_CAP,
    SAMPLE_BYTES,
    THREAD_BYTES,
    check_count,
    check_int_range,
    check_pixels,
    check_seed,
)
from neuralao.runtime.predict import Predictor

EXPECTED_EXPORTS = ("mlp-16x8", "mlp-32x16", "mlp-64x32", "unet")
SHIPPED_PREFIX = "shipped:"  # row-name prefix of the release models of runtime/models
# Shipped rows a report shows unless told otherwise: the default model and the fast one
# (neuralao.pipeline.evaluation.report_rows.pick_shipped).
SHIPPED_PICKS = ("default", "fast")

# Bounds of the screen-space baselines' counts, which are compiled into their shaders. An SSAO kernel of 128
# points (8x Crytek's 16) fits the 1024 fragment uniform components every GL 4.3 implementation holds, a
# vec4 slot a point, with room for the other uniforms; GTAO reads 2 x slices x steps texels a pixel, and the
# blur pass noise_size^2: at these bounds already thousands, where the defaults read 64 and 16.
MAX_SSAO_SAMPLES = 128
MAX_GTAO_COUNT = 64
MAX_NOISE_SIZE = 32
# Bytes of one timed repetition's record (its time, kept for the median).
REPEAT_BYTES = 64


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


def check_settings(s: ReportSettings, name: Callable[[str], str] | None = None) -> None:
    """Every setting in its range and every count within the memory, before any work: a refusal is one
    line naming the setting as ``name(key)`` gives it (the command's flag where one set it; default the
    key, as ``--set`` writes it)."""
    n = name or str
    check_count(n("workers"), s.workers, bytes_each=THREAD_BYTES, each="per tracing thread")
    check_rays(n("gt_rays"), s.gt_rays, s.workers)
    for rays in s.trace_rays:
        check_rays(n("trace_rays"), rays, s.workers)
    if len(set(s.trace_rays)) != len(s.trace_rays):
        raise NeuralaoError(
            f"{n('trace_rays')} must not repeat a ray count (one row each), got {s.trace_rays}"
        )
    check_rays(n("bake_rays"), s.bake_rays, s.workers)
    spv = s.bake_samples_per_vertex
    if not (math.isfinite(spv) and spv > 0):
        raise NeuralaoError(f"{n('bake_samples_per_vertex')} must be > 0, got {spv}")
    # one vertex's samples at least must fit; the bake checks them times each scene's vertices
    check_count(
        n("bake_samples_per_vertex"),
        math.ceil(spv),
        bytes_each=SAMPLE_BYTES,
        each="per surface sample",
        shown=f"{spv:g}",
    )
    check_int_range(n("frames_per_scene"), s.frames_per_scene, 1, MAX_CAP)
    check_count(n("repeats"), s.repeats, bytes_each=REPEAT_BYTES, each="a timed repetition's record")
    if len(s.time_size) != 2:
        raise NeuralaoError(f"{n('time_size')} must be a width and a height, got {list(s.time_size)}")
    check_pixels(n("time_size"), *s.time_size)
    check_seed(n("seed"), s.seed)
    for key, targets in (("target_ssim", [s.target_ssim]), ("select_targets", s.select_targets)):
        for t in targets:
            if not (0.0 < t <= 1.0):
                raise NeuralaoError(f"{n(key)}: a masked SSIM target must be in (0, 1], got {t}")
    if s.radii_rel is not None and any(not (math.isfinite(r) and r > 0) for r in s.radii_rel):
        raise NeuralaoError(
            f"{n('radii_rel')} must be positive fractions of the scene diagonal, got {s.radii_rel}"
        )
    check_screen_space(s.ssao, "ssao", n)
    check_screen_space(s.gtao, "gtao", n)


def check_screen_space(s: SSAOSettings | GTAOSettings, method: str, n: Callable[[str], str]) -> None:
    """The SSAO or GTAO settings (``method``): the counts compiled into the shaders within their bounds,
    the fractions of the radius within [0, 1], the seed one numpy takes."""
    counts = (
        {"samples": MAX_SSAO_SAMPLES}
        if method == "ssao"
        else {"slices": MAX_GTAO_COUNT, "steps": MAX_GTAO_COUNT}
    )
    for key, high in {**counts, "noise_size": MAX_NOISE_SIZE}.items():
        check_int_range(n(f"{method}.{key}"), getattr(s, key), 1, high)
    fraction = "bias_rel" if method == "ssao" else "falloff"
    value = getattr(s, fraction)
    if not 0.0 <= value <= 1.0:
        raise NeuralaoError(
            f"{n(f'{method}.{fraction}')} must be a fraction of the radius in [0, 1], got {value}"
        )
    if method == "gtao":
        beta, c = s.thickness_blend, s.thin_occluder_compensation
        if not (math.isfinite(beta) and 0.0 <= beta < 1.0):
            raise NeuralaoError(f"{n('gtao.thickness_blend')} must be a finite blend in [0, 1), got {beta}")
        if not (math.isfinite(c) and c >= 0.0):
            raise NeuralaoError(f"{n('gtao.thin_occluder_compensation')} must be finite and >= 0, got {c}")
    check_seed(n(f"{method}.seed"), s.seed)


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
