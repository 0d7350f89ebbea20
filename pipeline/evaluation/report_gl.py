"""The report's model rows at run time: how each kind's generated GLSL is loaded, run and timed
(:class:`GLPath`, named by the kind's ``report_gl`` in :mod:`neuralao.runtime.kinds`; those of mlp,
field and unet are here), its onnxruntime predictor loaded beside it (:func:`prepare_model`), its AO on
a frame (:func:`predict_model`) and its GL and onnxruntime seconds per frame (:func:`time_model`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from neuralao.export.field import gbuffer_textures
from neuralao.export.glsl import load_compute_export, load_mlp_export
from neuralao.pipeline.evaluation.report_settings import Method
from neuralao.runtime import gl, kinds
from neuralao.runtime.foundation.manifest import read_manifest
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.glsl_runner import (
    run_mlp_fragment,
    run_vector_fragment,
    time_compute,
    time_mlp_fragment,
    time_vector_fragment,
)
from neuralao.runtime.predict import Predictor


def _clamped(raw: np.ndarray, frame: FrameLike) -> np.ndarray:
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
    # Keyword arguments of the kind's onnxruntime predictor (its ``predictor`` in neuralao.runtime.kinds).
    ort_options: dict = field(default_factory=dict)


# A U-Net frame costs ~100x an MLP's: at most 5 repetitions of each; the report's U-Nets run at the


MLP_GL = GLPath(
    load_mlp_export,
    lambda shader, f: run_mlp_fragment(
        shader, np.asarray(f["normal_obj"], np.float32), np.asarray(f["mask"], bool)
    ),
    lambda shader, w, h, n: time_mlp_fragment(shader, h, w, repeats=n),
    lambda n: max(1, n // 3),
)
FIELD_GL = GLPath(
    load_mlp_export,
    lambda shader, f: run_vector_fragment(shader, gbuffer_textures(f)),
    lambda shader, w, h, n: time_vector_fragment(shader, h, w, repeats=n),
    lambda n: max(1, n // 3),
)
# A U-Net frame costs ~100x an MLP's: at most 5 repetitions of each; the report's U-Nets run at the
# frame's own size (the network's ``scale`` does any downsampling).
UNET_GL = GLPath(
    load_compute_export,
    None,
    lambda program, w, h, n: time_compute(program, h, w, repeats=max(1, min(n, 5))),
    lambda n: max(1, min(n, 5)),
    {"internal_height": None},
)


def gl_predictor(run: Callable[[Any, dict], np.ndarray], programs: dict[str | None, Any]) -> Predictor:
    """``predict(frame) -> ao`` through the generated GLSL: the program of the frame's scene, or the one
    program (key None) of a row that applies to every scene."""

    def predict(frame: FrameLike, radius: float | None = None) -> np.ndarray:
        program = programs[None] if None in programs else programs[frame["scene"]]
        return _clamped(run(program, frame), frame)

    return predict


def prepare_model(m: Method) -> None:
    """Load what a model method needs once (GL programs, onnxruntime predictors); failure -> unavailable.

    A per-mesh row of fields holds every scene's export: every one is loaded and checked, the first
    one's program and onnxruntime inference are timed."""
    try:
        path = kinds.role(m.family, "report_gl")
        predictor = kinds.role(m.family, "predictor")
        exports = m.scene_exports if m.scene_exports is not None else {m.scene: m.export}
        programs: dict = {}
        for scene, d in sorted(exports.items()):
            manifest = read_manifest(d)
            programs[scene] = path.load(d / manifest.get("glsl", "glsl"))
            ort = predictor(d / manifest.get("onnx", "model.onnx"), **path.ort_options)
            if m.ort is None:
                m.program, m.ort = programs[scene], ort
        m.predictor = m.ort if path.run is None else gl_predictor(path.run, programs)
    except Exception as e:  # a broken export must not stop the report: list it with the reason
        m.available, m.reason = (
            False,
            f"cannot load export: {str(e).splitlines()[0][:160] if str(e) else type(e).__name__}",
        )


def predict_model(m: Method, frame: FrameLike, radius: float | None = None) -> np.ndarray:
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
    path = kinds.role(m.family, "report_gl")
    frame = timing_inputs(size)
    radius = 1.0 if kinds.KINDS[m.family].radius_input else None
    return {
        "seconds": path.seconds(m.program, *size, repeats),
        "seconds_onnxruntime": gl.median_frame_seconds(
            lambda: m.ort(frame, radius), path.ort_repeats(repeats), warmup=1
        ),
    }
