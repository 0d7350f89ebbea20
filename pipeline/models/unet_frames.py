"""The U-Net's training frames: a dataset's frames preprocessed for one input contract, with labels
and (for a hybrid) GTAO at every label radius, prepared once on disk and memory-mapped.

    load_dataset_frames(data, train_fraction, internal_height=, gtao=, version=) -> (train, val, info)
    frames_to_set(frames, internal_height, gtao, version) -> FrameSet     (in memory, any iterable)
    foreground(x) -> bool                                               (background of any contract)

Preparing a frame costs more than a training step: GTAO runs in GL at every radius, the frame is
point-sampled to the network's rows. A corpus of thousands of frames also outgrows memory (about
36 bytes a pixel at four radii). So :func:`load_dataset_frames` prepares each shard of the dataset
once into ``<dataset>.prepared/<key>/`` (one ``.bin`` of aligned arrays and a ``.json`` describing
them, written to temporary names and renamed: an interrupted preparation resumes at the next shard),
and training reads crops from memory-mapped views of those files. The key hashes everything the
arrays depend on (the dataset's hash, the rows, GTAO and its settings, the contract, this format's
version); a folder of another key is never read. Delete the folder to reclaim the disk.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from neuralao.pipeline.datasets.dataset import Dataset, open_dataset
from neuralao.runtime.baselines import GTAOSettings, gtao_settings_entry, hybrid_gtao
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_bytes, write_json
from neuralao.runtime.foundation.limits import check_disk
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.internal_resolution import downsample_frame, internal_size
from neuralao.runtime.unet_input import (
    BACK_LAYER_VERSION,
    FOREGROUND_GAIN,
    PREPROCESS_VERSION,
    frame_radius_param,
    input_channels,
    preprocess_frame,
    scales_up,
)

log = logging.getLogger(__name__)

PREPARED_FORMAT = "neuralao-prepared-frames"
PREPARED_VERSION = 1
ALIGN = 64  # byte alignment of every array in a prepared shard
# Frames of one size are stacked into one tensor in memory up to this many bytes; a larger set keeps one
# memory-mapped view per frame (the training code indexes both the same way).
STACK_BYTES = 1 << 30


def foreground(x: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
    """(4 | 5, H, W) or (N, 4 | 5, H, W) network input -> (…, H, W) bool foreground: the normal is zero on
    background under every contract (version 3's depth channel, a logarithm, is 0 at depth 1 and negative
    nearer, so it cannot tell background apart)."""
    n = x[..., 1:4, :, :]
    return (n * n).sum(-3) * FOREGROUND_GAIN >= 1.0


@dataclass
class FrameSet:
    """Preprocessed frames in memory, with labels at K radii.

    x : (N, C, H, W) float32 network input (C = 4, or 5 with the back layer); y : (N, K, H, W) float16 AO
    labels (exact: binary-kernel labels are multiples of 1/rays); m : (N, K, H, W) bool valid &
    foreground; rho : (N, K) float32 radius parameters (:func:`neuralao.pipeline.models.unet.radius_param`);
    radii : (N, K) float32 radii in scene units; names : N strings "scene/view"; scenes : N scene names.
    About (16 + 3 K) bytes a pixel.
    Frames of several sizes: x, y and m are lists of N tensors (C | K, H_i, W_i) instead; code that indexes
    them by frame (``x[i]``) takes both. Hybrid sets add g, GTAO at every radius like y; the network's input
    for radius j is then ``cat(x[i], g[i][j])`` (:func:`network_input`).
    """

    x: torch.Tensor | list[torch.Tensor]
    y: torch.Tensor | list[torch.Tensor]
    m: torch.Tensor | list[torch.Tensor]
    rho: torch.Tensor
    radii: torch.Tensor
    names: list[str]
    scenes: list[str]
    g: torch.Tensor | list[torch.Tensor] | None = None  # hybrid: GTAO (N, K, H, W) float16 at each radius
    r: torch.Tensor | list[torch.Tensor] | None = None  # and GTAO before its blur, where the hybrid reads it

    def __len__(self) -> int:
        return len(self.names)

    @property
    def sizes(self) -> list[tuple[int, int]]:
        """(H, W) of every frame."""
        if isinstance(self.x, torch.Tensor):
            return [tuple(self.x.shape[-2:])] * len(self)
        return [tuple(x.shape[-2:]) for x in self.x]

    def subset(self, index: list[int]) -> FrameSet:
        i = torch.as_tensor(index, dtype=torch.int64)
        pick = lambda a: None if a is None else a[i] if isinstance(a, torch.Tensor) else [a[k] for k in index]  # noqa: E731
        return FrameSet(
            pick(self.x),
            pick(self.y),
            pick(self.m),
            self.rho[i],
            self.radii[i],
            [self.names[k] for k in index],
            [self.scenes[k] for k in index],
            pick(self.g),
            pick(self.r),
        )


def network_input(data: FrameSet, f: int, j: int, crop: tuple[slice, slice] | None = None) -> torch.Tensor:
    """(C, H, W) float32 input of frame ``f`` at radius index ``j``: the G-buffer channels, and for a
    hybrid set GTAO at that radius last (GTAO before its blur in front of it where the set has it).
    ``crop``: (rows, columns) slices, taken before anything is copied (the frame may be a memory-mapped
    view)."""
    rows, cols = crop or (slice(None), slice(None))
    x = data.x[f][:, rows, cols]
    if data.g is None:
        return x.float()
    parts = [x.float()]
    if data.r is not None:
        parts.append(data.r[f][j : j + 1, rows, cols].float())
    parts.append(data.g[f][j : j + 1, rows, cols].float())
    return torch.cat(parts, dim=0)


def frame_labels(frame: FrameLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ao (K, H, W) float32, valid (K, H, W) bool, radii (K,) float32) of a frame's labels at every radius.

    Frames from a dataset with ``labels.radii_rel`` carry ``ao_radii``/``valid_radii``/``radii``; others
    are refused (the network takes the radius as an input, so it needs to know each label's radius).
    """
    name = f"{frame.get('scene', '?')}/{frame.get('view', '?')}"
    if not all(k in frame for k in ("ao_radii", "valid_radii", "radii")):
        raise NeuralaoError(
            f"frame {name} has no labels at known radii (ao_radii, valid_radii, radii): "
            "build the dataset with labels.radii_rel set"
        )
    ao = np.moveaxis(np.asarray(frame["ao_radii"], dtype=np.float32), -1, 0)
    valid = np.moveaxis(np.asarray(frame["valid_radii"], dtype=bool), -1, 0)
    return ao, valid, np.asarray(frame["radii"], dtype=np.float32).reshape(-1)


@dataclass
class PreparedFrame:
    """One frame as training reads it: x (4, H, W) float32 input channels; y (K, H, W) float16 labels; m
    (K, H, W) bool valid & foreground; g (K, H, W) float16 GTAO at each radius or None; rho (K,) radius
    parameters; radii (K,) float32 scene units; its name "scene/view", scene, split and holdout flag; r
    (K, H, W) float16 GTAO before its blur at each radius, for a hybrid that reads it, or None."""

    x: np.ndarray
    y: np.ndarray
    m: np.ndarray
    g: np.ndarray | None
    rho: list[float]
    radii: np.ndarray
    name: str
    scene: str
    split: str = ""
    holdout: bool = False
    r: np.ndarray | None = None


def prepare_frame(
    f: FrameLike,
    index: int,
    internal_height: int = 0,
    gtao: bool = False,
    version: int = PREPROCESS_VERSION,
    gtao_blur: bool = True,
    gtao_raw: bool = False,
) -> PreparedFrame:
    """One frame dict (labels at several radii) -> :class:`PreparedFrame`. ``index`` names a frame that
    has no view number. ``gtao_blur`` False: the hybrid's GTAO is its pass without the blur; ``gtao_raw``:
    that pass is kept as well, beside the blurred GTAO."""
    _, _, r = frame_labels(f)
    if gtao:
        images = [hybrid_gtao(f, float(v), gtao_blur, gtao_raw) for v in r]
        f = dict(f) | {f"{k}_radii": np.stack([g[k] for g in images], axis=-1) for k in images[0]}
    h, w = np.shape(f["depth"])
    lw, lh = internal_size(w, h, internal_height or None, scales_up(version))
    if (lw, lh) != (w, h):
        f = downsample_frame(f, lw, lh)
    ao, valid, r = frame_labels(f)
    scene = str(f.get("scene", "frames"))
    return PreparedFrame(
        x=preprocess_frame(f, version=version),
        y=ao.astype(np.float16),
        m=valid & np.asarray(f["mask"], dtype=bool)[None],
        g=np.moveaxis(f["gtao_radii"], -1, 0).astype(np.float16) if gtao else None,
        rho=[frame_radius_param(f, float(v), version) for v in r],
        radii=np.asarray(r, np.float32),
        name=f"{scene}/{f.get('view', index)}",
        scene=scene,
        split=str(f.get("split", "")),
        holdout=bool(f.get("holdout", False)),
        r=np.moveaxis(f["gtao_raw_radii"], -1, 0).astype(np.float16) if gtao and gtao_raw else None,
    )


def assemble(frames: Iterable[PreparedFrame]) -> FrameSet:
    """Prepared frames -> :class:`FrameSet`: stacked when every frame has one size and the set is small
    (:data:`STACK_BYTES`), else per-frame lists (views of memory-mapped files stay views)."""
    frames = list(frames)
    if not frames:
        raise NeuralaoError("no frames to train or validate on")
    counts = {len(p.rho) for p in frames}
    if len(counts) != 1:
        raise NeuralaoError(f"frames have labels at {sorted(counts)} radii; use one radius list per dataset")
    kept = [k for k in ("g", "r") if getattr(frames[0], k) is not None]
    tensors = {k: [torch.from_numpy(getattr(p, k)) for p in frames] for k in ("x", "y", "m", *kept)}
    size = sum(t.numel() * t.element_size() for ts in tensors.values() for t in ts)
    if len({p.x.shape for p in frames}) == 1 and size <= STACK_BYTES:
        tensors = {k: torch.stack(v) for k, v in tensors.items()}
    return FrameSet(
        tensors["x"],
        tensors["y"],
        tensors["m"],
        torch.tensor([p.rho for p in frames], dtype=torch.float32),
        torch.from_numpy(np.stack([p.radii for p in frames])),
        [p.name for p in frames],
        [p.scene for p in frames],
        tensors.get("g"),
        tensors.get("r"),
    )


def frames_to_set(
    frames,
    internal_height: int = 0,
    gtao: bool = False,
    version: int = PREPROCESS_VERSION,
    gtao_blur: bool = True,
    gtao_raw: bool = False,
) -> FrameSet:
    """Frame dicts (with labels at several radii) -> :class:`FrameSet` in memory (one radius count).

    ``internal_height`` > 0: every frame is point-sampled to that many rows first (up or down; input
    contract 5: down only, shorter frames as rendered), labels included
    (:func:`neuralao.runtime.internal_resolution.downsample_frame`; the radius parameter is relative to the
    screen, and under contract 5 states the rows kept). ``gtao``: GTAO's AO at every label radius, run on
    the frame as rendered (before the point sampling, as an engine runs it at full resolution), is kept
    as ``g``.
    ``frames`` may be any iterable (a dataset's generator): frames are converted one at a time and
    only the compact arrays are kept. ``version``: the input contract the frames are preprocessed for.
    ``gtao_blur`` False: GTAO without its blur (the pass alone); ``gtao_raw``: that pass kept as ``r``
    beside the blurred GTAO.
    """
    return assemble(
        prepare_frame(f, i, internal_height, gtao, version, gtao_blur, gtao_raw) for i, f in enumerate(frames)
    )


# ----------------------------------------------------------------------------------------------- on disk

_ARRAYS = ("x", "y", "m", "g", "r")


def prepared_folder(
    data: Path,
    ds: Dataset,
    internal_height: int,
    gtao: bool,
    version: int,
    gtao_blur: bool = True,
    gtao_raw: bool = False,
) -> Path:
    """``<dataset>.prepared/<key>``: the key hashes everything a prepared array depends on."""
    key = {
        "format": PREPARED_FORMAT,
        "version": PREPARED_VERSION,
        "dataset_hash": ds.manifest.get("dataset_hash"),
        "internal_height": internal_height,
        "gtao": gtao_settings_entry(GTAOSettings(blur=gtao_blur)) if gtao else None,
        "preprocess_version": version,
        # the back layer's files (a version-4 input reads them); absent before, so older keys stay
        **({"back_layer": (ds.back_layer or {}).get("hash")} if version == BACK_LAYER_VERSION else {}),
        # GTAO before its blur beside the blurred one (absent before, so older keys stay)
        **({"gtao_raw": True} if gtao and gtao_raw else {}),
    }
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    return data.parent / f"{data.name}.prepared" / digest


def _write_shard(frames: list[PreparedFrame], bin_path: Path, json_path: Path) -> None:
    """The frames' arrays, each at an ALIGN-byte offset of one file, and their description beside."""
    chunks, described, offset = [], [], 0
    for p in frames:
        arrays = {}
        for k in _ARRAYS:
            a = getattr(p, k)
            if a is None:
                continue
            a = np.ascontiguousarray(a)
            pad = -offset % ALIGN
            chunks.append(b"\0" * pad)
            offset += pad
            arrays[k] = [offset, a.dtype.str, list(a.shape)]
            chunks.append(a.tobytes())
            offset += a.nbytes
        described.append(
            {
                "name": p.name,
                "scene": p.scene,
                "split": p.split,
                "holdout": p.holdout,
                "rho": [float(v) for v in p.rho],
                "radii": [float(v) for v in p.radii],
                "arrays": arrays,
            }
        )
    write_bytes(bin_path, b"".join(chunks))
    # the description last: its presence says the shard is complete
    write_json(json_path, {"format": PREPARED_FORMAT, "version": PREPARED_VERSION, "frames": described})


def _read_shard(bin_path: Path, json_path: Path) -> list[PreparedFrame]:
    """Memory-mapped views of a prepared shard (copy-on-write: nothing is read until used)."""
    meta = read_json(json_path, "prepared frames")
    if meta.get("format") != PREPARED_FORMAT or meta.get("version") != PREPARED_VERSION:
        raise NeuralaoError(f"{json_path} is not a prepared-frames file of version {PREPARED_VERSION}")
    raw = np.memmap(bin_path, dtype=np.uint8, mode="c") if bin_path.stat().st_size else np.zeros(0, np.uint8)
    out = []
    for d in meta["frames"]:

        def view(k: str, d=d) -> np.ndarray | None:
            if k not in d["arrays"]:
                return None
            offset, dtype, shape = d["arrays"][k]
            dt = np.dtype(dtype)
            return raw[offset : offset + dt.itemsize * int(np.prod(shape))].view(dt).reshape(shape)

        out.append(
            PreparedFrame(
                view("x"),
                view("y"),
                view("m"),
                view("g"),
                d["rho"],
                np.asarray(d["radii"], np.float32),
                d["name"],
                d["scene"],
                d["split"],
                d["holdout"],
                view("r"),
            )
        )
    return out


def prepared_shards(
    ds: Dataset,
    entries: list[dict],
    folder: Path,
    internal_height: int,
    gtao: bool,
    version: int,
    gtao_blur: bool = True,
    gtao_raw: bool = False,
) -> Iterator[PreparedFrame]:
    """Every frame of ``entries`` (manifest shards, in order), prepared once into ``folder`` and read back
    memory-mapped."""
    folder.mkdir(parents=True, exist_ok=True)
    todo = [e for e in entries if not (folder / f"{e['sha256'][:32]}.json").exists()]
    if todo:
        _check_room(ds, todo, folder, internal_height, gtao, version, gtao_raw)
        log.info(
            "preparing %d of %d shards into %s (once; later runs read them)", len(todo), len(entries), folder
        )
    t0, done = time.perf_counter(), 0
    for e in entries:
        stem = folder / e["sha256"][:32]
        bin_path, json_path = stem.with_suffix(".bin"), stem.with_suffix(".json")
        if not json_path.exists():
            frames = [
                prepare_frame(f, i, internal_height, gtao, version, gtao_blur, gtao_raw)
                for i, f in enumerate(ds.shard_frames(e))
            ]
            _write_shard(frames, bin_path, json_path)
            done += 1
            if done % 50 == 0 or done == len(todo):
                log.info("prepared %d of %d shards (%.0f s)", done, len(todo), time.perf_counter() - t0)
        yield from _read_shard(bin_path, json_path)


def prepared_bytes(
    ds: Dataset, entries: list[dict], internal_height: int, gtao: bool, version: int, gtao_raw: bool = False
) -> int:
    """The bytes the prepared frames of ``entries`` take on disk: per pixel at the size training reads,
    the input's channels (float32), the labels and GTAO (and GTAO before its blur) at each radius
    (float16) and the masks (bool)."""
    radii = len(ds.manifest.get("config", {}).get("labels", {}).get("radii_rel") or [1])
    gtao_bytes = (2 if gtao else 0) + (2 if gtao and gtao_raw else 0)
    per_pixel = 4 * len(input_channels(version)) + radii * (2 + 1 + gtao_bytes)
    total = 0
    for e in entries:
        w, h = e.get("size") or ds.manifest.get("size") or (0, 0)
        lw, lh = internal_size(int(w), int(h), internal_height or None, scales_up(version))
        total += len(e["views"]) * lw * lh * per_pixel
    return total


def _check_room(
    ds: Dataset,
    todo: list[dict],
    folder: Path,
    internal_height: int,
    gtao: bool,
    version: int,
    gtao_raw: bool = False,
):
    """Refuse, before any is written, prepared frames the disk cannot hold (naming the other prepared sets
    beside them, which can be removed: each is made again when a run needs it)."""
    others = sorted(p.name for p in folder.parent.iterdir() if p.is_dir() and p != folder)
    hint = f" (other prepared sets in {folder.parent}: {', '.join(others)}; remove those no run needs)"
    try:
        check_disk(
            "the prepared frames",
            prepared_bytes(ds, todo, internal_height, gtao, version, gtao_raw),
            folder,
            f"of {len(todo)} shards in {folder}",
        )
    except NeuralaoError as e:
        raise NeuralaoError(f"{e}{hint if others else ''}") from None


def kept_training_scenes(train_scenes: list[str], train_fraction: float) -> list[str]:
    """The training scenes a ``train_fraction`` keeps: every k-th of the sorted scenes (all at 1)."""
    if not 0.0 < train_fraction <= 1.0:
        raise NeuralaoError(f"train_fraction must lie in (0, 1], got {train_fraction}")
    scenes = sorted(train_scenes)
    n = max(1, round(len(scenes) * train_fraction))  # n = all of them at 1
    return [scenes[int(i * len(scenes) / n)] for i in range(n)]


def load_dataset_frames(
    data: Path,
    train_fraction: float = 1.0,
    loaded: tuple | None = None,
    internal_height: int = 0,
    gtao: bool = False,
    version: int = PREPROCESS_VERSION,
    gtao_blur: bool = True,
    gtao_raw: bool = False,
) -> tuple[FrameSet, FrameSet | None, dict]:
    """Train frames (train scenes, held-back views excluded), validation frames and dataset info.

    ``train_fraction`` < 1 keeps that fraction of the training SCENES (every k-th in sorted order), for
    the corpus-size study; validation is unchanged. ``loaded``: what this function returned for the same
    dataset at ``train_fraction`` 1; the subset is then cut from it (same frames, same order, same info)
    instead of read again. ``internal_height``, ``gtao``, ``version``, ``gtao_blur`` and ``gtao_raw``: see
    :func:`frames_to_set`. The
    frames are prepared once on disk and memory-mapped (see the module docstring).
    """
    data = Path(data)
    ds = open_dataset(data)
    if version == BACK_LAYER_VERSION and ds.back_layer is None:
        raise NeuralaoError(
            f"dataset {data} has no back layer (depth_back), which a version-{version} U-Net reads: set "
            '"back_layer": true in its config and run `neuralao dataset` again (it renders only the layer)'
        )
    train_scenes = sorted({e["scene"] for e in ds.manifest["shards"] if e["split"] == "train"})
    if not train_scenes:
        raise NeuralaoError(f"dataset {data} has no training frames (no scene with split 'train')")
    keep_set = set(kept_training_scenes(train_scenes, train_fraction))
    val_source = "val scenes"
    has_val = any(e["split"] == "val" for e in ds.manifest["shards"])
    if not has_val:
        val_source = "held-back views of the training scenes (the dataset has no val scene)"
    if loaded is not None:
        full, val, full_info = loaded
        if (
            full_info.get("train_fraction") != 1.0
            or full_info.get("dataset_hash") != ds.manifest.get("dataset_hash")
            or full_info.get("internal_height") != internal_height
            or full_info.get("gtao") != gtao
            or full_info.get("gtao_blur", True) != gtao_blur
            or full_info.get("gtao_raw", False) != (gtao and gtao_raw)
            or full_info.get("preprocess_version") != version
        ):
            raise NeuralaoError(
                "load_dataset_frames: `loaded` must be this dataset's frames at train_fraction 1"
            )
        train = full.subset([i for i, sc in enumerate(full.scenes) if sc in keep_set])
    else:
        entries = [
            e
            for e in ds.manifest["shards"]
            if (e["split"] == "train" and e["scene"] in keep_set) or (has_val and e["split"] == "val")
        ]
        folder = prepared_folder(data, ds, internal_height, gtao, version, gtao_blur, gtao_raw)
        train_frames, val_frames = [], []
        for p in prepared_shards(ds, entries, folder, internal_height, gtao, version, gtao_blur, gtao_raw):
            if p.split == "train" and not p.holdout:
                train_frames.append(p)
            elif (p.split == "val") if has_val else (p.split == "train" and p.holdout):
                val_frames.append(p)
        train, val = assemble(train_frames), assemble(val_frames)
    info = {
        "path": str(data),
        "name": ds.manifest.get("name"),
        "dataset_hash": ds.manifest.get("dataset_hash"),
        "labels": ds.manifest.get("config", {}).get("labels"),
        "training_scenes": sorted(set(train.scenes)),
        "val_scenes": sorted(set(val.scenes)),
        "val_source": val_source,
        "train_frames": len(train),
        "val_frames": len(val),
        "train_fraction": train_fraction,
        "internal_height": internal_height,
        "gtao": gtao,
        "preprocess_version": version,
        # only where GTAO is the pass without its blur (the records of every other run stay as they were)
        **({"gtao_blur": False} if gtao and not gtao_blur else {}),
        **({"gtao_raw": True} if gtao and gtao_raw else {}),
    }
    return train, val, info
