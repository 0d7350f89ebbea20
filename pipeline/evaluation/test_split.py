"""Error of AO methods on a dataset split (by mesh: e.g. ``test``) at every label radius.

Ground truth is the dataset's own labels at each radius (``ao_radii`` / ``valid_radii``, one trace);
every method gets the same radius in scene units (the U-Net as its radius input, SSAO and GTAO as
their kernel radius). A score is the masked SSIM / RMSE (neuralao.runtime.foundation.metrics) of one (frame,
radius) pair over the valid foreground pixels; a method's figure is the mean over pairs, also per radius (by
its ``radii_rel`` entry) and per scene.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from neuralao.pipeline.datasets.dataset import open_dataset
from neuralao.runtime.baselines import run_screen_space
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.metrics import masked_flip, masked_rmse, masked_ssim
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.predict import unet_predictor as runtime_unet_predictor

# predictor(frame, radius in scene units) -> AO (H, W) float32, 1 on background
Predictor = Callable[[dict, float], np.ndarray]


def unet_predictor(onnx_path: str | Path, internal_height: int | str | None = None) -> Predictor:
    """onnxruntime inference of a U-Net export at a given radius
    (:func:`neuralao.runtime.predict.unet_predictor`);
    ``internal_height`` None (the default here) runs it at the frame's own size, "model" at the height
    it declares."""
    return runtime_unet_predictor(onnx_path, internal_height)


def screen_space_predictor(method: str, settings=None) -> Predictor:
    """SSAO / GTAO (neuralao.runtime.baselines) with the label radius as their kernel radius."""
    return lambda frame, radius: run_screen_space(frame, method, radius, settings)


def score_frame(frame: FrameLike, methods: dict[str, Predictor], flip: bool = True) -> list[dict]:
    """One row {method, radius (index), ssim, rmse, flip} per (method, radius) of a labelled frame, over
    its valid foreground pixels at that radius; a radius with none is skipped. ``flip`` False: FLIP nan.
    A method returning non-finite AO on those pixels is a one-line error."""
    rows = []
    fg = np.asarray(frame["mask"], bool)
    for j, radius in enumerate(np.asarray(frame["radii"], np.float64).reshape(-1)):
        mask = fg & np.asarray(frame["valid_radii"][..., j], bool)
        if not mask.any():
            continue
        gt = np.asarray(frame["ao_radii"][..., j], np.float32)
        for name, fn in methods.items():
            pred = fn(frame, float(radius))
            if not np.isfinite(pred[mask]).all():
                raise NeuralaoError(
                    f"{name} returned non-finite AO on {frame.get('scene')}/{frame.get('view')}"
                )
            rows.append(
                {
                    "method": name,
                    "radius": j,
                    "ssim": masked_ssim(pred, gt, mask),
                    "rmse": masked_rmse(pred, gt, mask),
                    "flip": masked_flip(pred, gt, mask) if flip else float("nan"),
                }
            )
    return rows


def evaluate_frames(
    frames: Iterable[dict], methods: dict[str, Predictor], radii_rel: list[float] | None = None
) -> dict:
    """Scores of every method on ``frames`` (dicts with ao_radii, valid_radii, radii) at every radius."""
    rows: dict[str, list[tuple[str, int, float, float]]] = {name: [] for name in methods}
    frames_seen = 0
    for frame in frames:
        if not all(k in frame for k in ("ao_radii", "valid_radii", "radii")):
            raise NeuralaoError(
                f"frame {frame.get('scene')}/{frame.get('view')} has no labels at several radii"
            )
        frames_seen += 1
        for row in score_frame(frame, methods, flip=False):
            rows[row["method"]].append((str(frame.get("scene")), row["radius"], row["ssim"], row["rmse"]))
    if frames_seen == 0:
        raise NeuralaoError("no frame to evaluate on")

    def mean(sel, k):
        return float(np.mean([r[k] for r in sel])) if sel else float("nan")

    out = {"frames": frames_seen, "methods": {}}
    for name, rs in rows.items():
        radii = sorted({r[1] for r in rs})
        out["methods"][name] = {
            "ssim": mean(rs, 2),
            "rmse": mean(rs, 3),
            "pairs": len(rs),
            "per_radius": {
                (f"{radii_rel[j]:g}" if radii_rel and j < len(radii_rel) else str(j)): {
                    "ssim": mean([r for r in rs if r[1] == j], 2),
                    "rmse": mean([r for r in rs if r[1] == j], 3),
                }
                for j in radii
            },
            "per_scene": {
                s: {
                    "ssim": mean([r for r in rs if r[0] == s], 2),
                    "rmse": mean([r for r in rs if r[0] == s], 3),
                }
                for s in sorted({r[0] for r in rs})
            },
        }
    return out


def evaluate_split(data: str | Path, split: str, methods: dict[str, Predictor], max_frames: int = 0) -> dict:
    """:func:`evaluate_frames` on a dataset split (``max_frames`` > 0: every k-th frame, about that many)."""
    ds = open_dataset(data)
    if not any(e["split"] == split for e in ds.manifest["shards"]):
        raise NeuralaoError(f"dataset {data} has no {split!r} split")
    total = sum(len(e["holdout"]) for e in ds.manifest["shards"] if e["split"] == split)
    step = max(1, total // max_frames) if max_frames > 0 else 1
    frames = (f for i, f in enumerate(ds.frames(split=split)) if i % step == 0)
    radii_rel = (ds.manifest.get("config", {}).get("labels") or {}).get("radii_rel")
    result = evaluate_frames(frames, methods, radii_rel)
    result.update(
        split=split,
        dataset_hash=ds.manifest.get("dataset_hash"),
        frame_step=step,
        scenes=sorted({e["scene"] for e in ds.manifest["shards"] if e["split"] == split}),
    )
    return result
