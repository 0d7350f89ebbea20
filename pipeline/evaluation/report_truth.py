"""The report's evaluation frames and their ground truth: which frames of the dataset each scene is
measured on (:func:`evaluation_frames`), the radii of the per-radius evaluation
(:func:`report_radii_rel`) and the ground truth of a frame at every radius from one trace, cached
(:func:`ground_truth` -> :class:`GroundTruth`)."""

from __future__ import annotations

import logging
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from neuralao.pipeline.evaluation.report_settings import ReportSettings
from neuralao.pipeline.tracing.labeller import LabelSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import read_npz, sha256_json, write_npz
from neuralao.runtime.foundation.settings import from_dict
from neuralao.runtime.frame import FrameLike

log = logging.getLogger(__name__)


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
    frame: FrameLike, radii: tuple[float, ...], main: int
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
    frame: FrameLike,
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
