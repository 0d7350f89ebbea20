"""Atomic writes and hashing: nothing is ever half-written.

Every output file goes through :func:`atomic_path` (write to a temporary name in the same
directory, fsync, rename), so an interrupted run leaves either the old file or the new one.
"""

from __future__ import annotations

import contextlib
import hashlib
import io as _io
import json
import os
import struct
import tempfile
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from neuralao.runtime.foundation.errors import NeuralaoError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it onto ``path`` if the block succeeds.

    ``suffix`` defaults to the target's suffix so libraries that infer a format from the file name
    (numpy, PIL, trimesh) still do the right thing.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{path.name}.",
        suffix=".tmp" + (suffix if suffix is not None else path.suffix),
        dir=path.parent,
    )
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def remove_stale_temporaries(directory: str | os.PathLike) -> list[Path]:
    """Delete temporaries that :func:`atomic_path` left in ``directory`` when a run was killed
    (SIGKILL skips its ``finally``). Call it before resuming work in that folder. Returns what went."""
    d = Path(directory)
    stale = [p for p in d.glob(".*.tmp*") if p.is_file()] if d.is_dir() else []
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, obj: Any) -> None:
    write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """Uncompressed npz written atomically, byte-for-byte deterministic for identical arrays.

    ``np.savez`` stamps each member with the current time, so two identical datasets would hash
    differently; here every member gets a fixed timestamp and members are sorted by name.
    """
    with atomic_path(path) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for name in sorted(arrays):
                buf = _io.BytesIO()
                np.lib.format.write_array(
                    buf, np.asarray(arrays[name], order="C"), allow_pickle=False
                )  # keeps 0-d scalars 0-d
                info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.external_attr = 0o644 << 16
                zf.writestr(info, buf.getvalue())


def read_npz(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Load every array of an npz (no pickles); a truncated or corrupt file is a one-line error."""
    try:  # our own handle: np.load leaves its file open when the zip directory is unreadable
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise NeuralaoError(f"file not found: {path}") from None
    except Exception as e:
        raise NeuralaoError(f"cannot read {path}: corrupt or truncated ({type(e).__name__})") from None


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W) or (H, W, 3|4) image; float input in [0, 1] is quantised to 8 bits."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = (np.clip(np.nan_to_num(img), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    with atomic_path(path) as tmp:
        Image.fromarray(img).save(tmp, format="PNG")


def write_exr(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W) or (H, W, 3|4) float image as an OpenEXR file: float32 channels (Y, or R G B [A]),
    uncompressed scanlines, written atomically. Values are stored as they are (no clamping or
    quantisation): the point of EXR output is the full float32 AO.

    The layout (OpenEXR 2 single-part scanline file): magic and version, a header of typed attributes
    ending in a zero byte, one uint64 offset per scanline, then each scanline as int32 y, int32 byte
    count and the line's pixels channel by channel, channels in alphabetical order.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4) or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"EXR image must be (H, W) or (H, W, 3|4), got {np.shape(image)}")
    h, w, c = img.shape
    names = {1: ["Y"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}[c]
    order = sorted(range(c), key=lambda k: names[k])  # channels are stored alphabetically

    def attr(name: str, kind: str, value: bytes) -> bytes:
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value

    FLOAT = 2  # OpenEXR pixel type
    chlist = (
        b"".join(names[k].encode() + b"\0" + struct.pack("<iB3xii", FLOAT, 0, 1, 1) for k in order) + b"\0"
    )
    window = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    header = b"".join(
        [
            struct.pack("<ii", 20000630, 2),
            attr("channels", "chlist", chlist),
            attr("compression", "compression", b"\0"),  # NO_COMPRESSION
            attr("dataWindow", "box2i", window),
            attr("displayWindow", "box2i", window),
            attr("lineOrder", "lineOrder", b"\0"),  # INCREASING_Y
            attr("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
            attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
            attr("screenWindowWidth", "float", struct.pack("<f", 1.0)),
            b"\0",
        ]
    )
    line_bytes = w * c * 4
    first = len(header) + 8 * h
    offsets = np.arange(h, dtype="<u8") * (8 + line_bytes) + first
    planar = np.ascontiguousarray(img[:, :, order].transpose(0, 2, 1), dtype="<f4")  # (H, C, W)
    lines = np.empty((h, 8 + line_bytes), np.uint8)
    lines[:, :4] = np.arange(h, dtype="<i4").view(np.uint8).reshape(h, 4)
    lines[:, 4:8] = np.frombuffer(struct.pack("<i", line_bytes), np.uint8)
    lines[:, 8:] = planar.reshape(h, -1).view(np.uint8)
    with atomic_path(path) as tmp:
        tmp.write_bytes(header + offsets.tobytes() + lines.tobytes())


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def sha256_json(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=_json_default).encode()).hexdigest()
