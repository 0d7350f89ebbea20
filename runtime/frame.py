"""The G-buffer frame: one camera's view as arrays (row 0 at the top), its one reader, validator and writer.

A frame is what ``neuralao render`` writes (``OUT/view_NNNN.npz``), what a dataset shard stacks along a
first axis, what ``neuralao infer`` reads, and what every model, baseline and metric here takes.
:data:`CHANNELS` is the one list of its keys, with their shapes and dtypes (docs/formats.md describes
the file from it); :class:`Frame` holds them by name.

Frames are checked where they enter (:func:`read_frame`, :meth:`Frame.from_arrays`): real numbers only
(floats, ints, bools), one (H, W) for every image channel, no NaN or inf in a float channel, depth
>= 0 (``-z_cam``: a frame holding ``z_cam`` is refused by name), and a mask that covers only pixels
with depth > 0. Each refusal is one line naming the file and the key.
"""

from __future__ import annotations

import difflib
import math
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import npz_keys, read_npz, write_npz


@dataclass(frozen=True)
class Channel:
    """One key of a frame: the trailing shape after (H, W) for an image channel (None: not an image),
    and the dtype kinds it may hold (numpy's kind letters: f float, i/u int, b bool)."""

    trailing: tuple[int, ...] | None
    kinds: str
    dtype: str  # as `neuralao render` writes it and dataset shards store it


# key -> Channel; the order is the order of docs/formats.md's table.
CHANNELS: dict[str, Channel] = {
    "depth": Channel((), "fiu", "float32"),  # linear camera-space depth -z_cam, scene units; 0 on background
    "normal_cam": Channel((3,), "fiu", "float32"),  # unit camera-space normal, facing the viewer
    "mask": Channel((), "biu", "bool"),  # foreground; absent: depth > 0
    # the back layer: depth where the pixel's camera ray leaves the solid it entered, 0 where thin
    "depth_back": Channel((), "fiu", "float32"),
    "yfov": Channel(None, "fiu", "float64"),  # vertical field of view, radians, ()
    "radii": Channel(None, "fiu", "float32"),  # (k,) AO radii of the labels, scene units
    "normal_obj": Channel((3,), "fiu", "float32"),  # unit object-space normal, facing the viewer
    "position": Channel((3,), "fiu", "float32"),  # world-space position, scene units
    "tri_id": Channel((), "iu", "int32"),  # face index, -1 on background
    "pose": Channel(None, "fiu", "float64"),  # (4, 4) camera-to-world
    "znear": Channel(None, "fiu", "float64"),  # clip planes, scene units, ()
    "zfar": Channel(None, "fiu", "float64"),
    "ao": Channel((), "fiu", "float32"),  # ray-traced AO label at the largest radius
    "valid": Channel((), "biu", "bool"),  # label valid: foreground, not rejected by the back-face rule
    "ao_radii": Channel(None, "fiu", "float32"),  # (H, W, k) labels at each radius
    "valid_radii": Channel(None, "biu", "bool"),  # (H, W, k)
}
# Keys of a frame that are not arrays of the view: where it came from (dataset frames carry them).
PROVENANCE = ("scene", "view", "split", "holdout")
_SCALARS = ("yfov", "znear", "zfar")
_NORMALS = ("normal_cam", "normal_obj")
# The longest normal a frame may hold. Models normalise in float32, where the square of a length past
# 1.8e19 is inf (the AO then comes out NaN): such a normal is a broken exporter, named where it enters.
MAX_NORMAL_LENGTH = 1e18
# The foreground depths, and the AO radii compared with them, whose AO is computed exactly (scene units).
# Screen-space passes (GTAO, a hybrid U-Net's input) work in float32, where the squared distance between
# neighbouring pixels overflows past 1.8e19 and underflows (to denormals, then 0) below about 1e-19: a frame
# scaled by 1e-17 .. 1e18, its radius alike, gives the same AO, one scaled by 1e-20 or 1e19 an AO of 0.05
# for 0.97, and 1e-42 (a float32 denormal) overflows a cast. Taller and narrower frames put neighbours
# closer (at 192 rows and 10 degrees, 1e-16 already differs); the bounds keep a margin of 1e4 and more.
DEPTH_RANGE = (1e-12, 1e12)


@dataclass(frozen=True, eq=False)  # eq=False: arrays have no truth value to compare by
class Frame(Mapping):
    """One G-buffer frame (H x W pixels, row 0 at the top). Every key is optional; what a consumer needs
    is checked by that consumer (a U-Net needs ``depth``, ``normal_cam`` and ``yfov``).

    depth : (H, W) float32, linear camera-space depth ``-z_cam`` in scene units, 0 on background
    normal_cam : (H, W, 3) float32, unit normal in camera space (OpenGL: z towards the viewer)
    mask : (H, W) bool, foreground (something was hit)
    depth_back : (H, W) float32, the back layer (where the camera ray leaves the solid it entered; 0 where
        the visible surface is thin, and on background): what a version-4 U-Net reads beside depth
    yfov : float, vertical field of view in radians
    radii : (k,) float32, the AO radii the labels were traced at, scene units
    normal_obj : (H, W, 3) float32, unit normal in object space
    position : (H, W, 3) float32, world-space position, scene units
    tri_id : (H, W) int32, face index, -1 on background
    pose : (4, 4) float64, camera-to-world; znear, zfar : float, clip planes
    ao : (H, W) float32, AO label in [0, 1]; valid : (H, W) bool, label valid
    ao_radii : (H, W, k) float32, valid_radii : (H, W, k) bool, labels at each of ``radii``
    scene : str, view : int, split : str, holdout : bool, where a dataset frame came from

    A frame reads like a mapping of its present keys (``frame["depth"]``, ``"mask" in frame``,
    ``frame.get("radii")``), so array code indexes channels by the names the file uses.
    """

    depth: np.ndarray | None = None
    normal_cam: np.ndarray | None = None
    mask: np.ndarray | None = None
    depth_back: np.ndarray | None = None
    yfov: float | None = None
    radii: np.ndarray | None = None
    normal_obj: np.ndarray | None = None
    position: np.ndarray | None = None
    tri_id: np.ndarray | None = None
    pose: np.ndarray | None = None
    znear: float | None = None
    zfar: float | None = None
    ao: np.ndarray | None = None
    valid: np.ndarray | None = None
    ao_radii: np.ndarray | None = None
    valid_radii: np.ndarray | None = None
    scene: str | None = None
    view: int | None = None
    split: str | None = None
    holdout: bool | None = None

    KEYS: ClassVar[tuple[str, ...]] = (*CHANNELS, *PROVENANCE)

    # ---------------------------------------------------------------- reading like a mapping of channels
    def __getitem__(self, key: str) -> Any:
        value = getattr(self, key, None) if key in self.KEYS else None
        if value is None:
            raise KeyError(key)
        return value

    def __iter__(self) -> Iterator[str]:
        return (k for k in self.KEYS if getattr(self, k) is not None)

    def __len__(self) -> int:
        return sum(1 for _ in self)

    # ---------------------------------------------------------------- making and changing
    @classmethod
    def from_arrays(cls, arrays: Mapping[str, Any], where: str = "frame", strict: bool = True) -> Frame:
        """A checked frame from ``arrays`` (name -> value). Unknown keys are refused when ``strict``
        (a misspelt key would otherwise be ignored), else dropped."""
        unknown = sorted(set(arrays) - set(cls.KEYS))
        if unknown and strict:
            raise NeuralaoError(f"{where}: unknown frame key {unknown[0]!r} (known: {', '.join(cls.KEYS)})")
        values = {k: _value(k, arrays[k], where) for k in cls.KEYS if k in arrays and arrays[k] is not None}
        frame = cls(**values)
        frame.check(where)
        return frame

    def replace(self, **changes: Any) -> Frame:
        """A copy with ``changes`` (None removes a key), checked again."""
        values = {k: getattr(self, k) for k in self} | changes
        return Frame.from_arrays({k: v for k, v in values.items() if v is not None}, "frame")

    def arrays(self) -> dict[str, np.ndarray]:
        """The present channels as arrays (what :func:`write_frame` stores), provenance left out."""
        return {k: np.asarray(getattr(self, k)) for k in CHANNELS if getattr(self, k) is not None}

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) of the frame's image channels."""
        h, w = self.shape
        return w, h

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the frame's image channels."""
        for k, ch in CHANNELS.items():
            v = getattr(self, k)
            if v is not None and ch.trailing is not None:
                return tuple(np.shape(v)[:2])
        raise NeuralaoError("the frame has no image channel (depth, normal_cam, mask, ...)")

    # ---------------------------------------------------------------- the checks
    def check(self, where: str = "frame") -> None:
        """Refuse a frame that would give finite-looking nonsense: see the module docstring."""
        ref = None
        for k, ch in CHANNELS.items():
            v = getattr(self, k)
            if v is None or ch.trailing is None:
                continue
            shape = np.shape(v)
            if ref is None and len(shape) == 2 + len(ch.trailing):
                ref = shape[:2]
            if ref is None or shape != (*ref, *ch.trailing):
                want = "(H, W" + "".join(f", {n}" for n in ch.trailing) + ")"
                got = f" with (H, W) = {ref}" if ref else ""
                raise NeuralaoError(
                    f"{where}: G-buffer channel {k!r} has shape {shape}, expected {want}{got}"
                )
        if ref is not None and min(ref) < 1:
            raise NeuralaoError(f"{where}: the frame is {ref[1]}x{ref[0]} pixels; it needs at least 1x1")
        for k in ("ao_radii", "valid_radii"):
            v = getattr(self, k)
            if v is not None and (ref is None or np.ndim(v) != 3 or np.shape(v)[:2] != ref):
                raise NeuralaoError(f"{where}: {k!r} has shape {np.shape(v)}, expected (H, W, k)")
        for k in CHANNELS:
            v = getattr(self, k)
            if v is None:
                continue
            a = np.asarray(v)
            if a.dtype.kind == "f" and not np.isfinite(a).all():
                bad = int(a.size - np.count_nonzero(np.isfinite(a)))
                raise NeuralaoError(
                    f"{where}: G-buffer channel {k!r} has {bad} non-finite value(s) (NaN or inf) of {a.size}"
                )
        for k in _NORMALS:
            v = getattr(self, k)
            if v is None or np.asarray(v).dtype.kind != "f":
                continue
            length = np.sqrt(np.square(np.asarray(v, np.float64)).sum(axis=-1))
            if (length > MAX_NORMAL_LENGTH).any():
                raise NeuralaoError(
                    f"{where}: {k!r} has {int((length > MAX_NORMAL_LENGTH).sum())} normal(s) of length up to "
                    f"{length.max():.3g}; a normal is a direction (unit length; lengths up to "
                    f"{MAX_NORMAL_LENGTH:g} are normalised)"
                )
        if self.depth is not None:
            depth = np.asarray(self.depth)
            if (depth < 0).any():
                raise NeuralaoError(
                    f"{where}: 'depth' has {int((depth < 0).sum())} negative value(s): depth is linear "
                    "-z_cam (positive in front of the camera, 0 on background), not z_cam"
                )
            if self.mask is not None and (np.asarray(self.mask, bool) & (depth <= 0)).any():
                n = int((np.asarray(self.mask, bool) & (depth <= 0)).sum())
                raise NeuralaoError(
                    f"{where}: 'mask' is true on {n} pixel(s) where 'depth' is 0 (background)"
                )
            fg = depth[np.asarray(self.mask, bool) if self.mask is not None else depth > 0]
            outside = (fg < DEPTH_RANGE[0]) | (fg > DEPTH_RANGE[1])
            if outside.any():
                raise NeuralaoError(
                    f"{where}: 'depth' has {int(outside.sum())} foreground value(s) from "
                    f"{float(fg[outside].min()):.3g} to {float(fg[outside].max()):.3g}; {_IN_RANGE}"
                )
        negative = 0 if self.depth_back is None else int((np.asarray(self.depth_back) < 0).sum())
        if negative:
            raise NeuralaoError(
                f"{where}: 'depth_back' has {negative} negative value(s): it is linear -z_cam like depth "
                "(0 where the visible surface is thin)"
            )
        if self.yfov is not None:
            check_yfov(f"{where}: 'yfov'", self.yfov, radians=True)


# The vertical fields of view a camera may have, degrees: a pinhole camera's useful range. Narrower, the
# camera stands so far back that float32 depth cannot tell the scene's front from its back (at 1e-5 degrees
# the AO of most pixels comes out 0); wider, the scene shrinks to a few pixels and the image's edges
# stretch without bound (at 178 degrees a fitted object leaves no pixel).
YFOV_RANGE_DEG = (0.1, 170.0)


def check_yfov(name: str, value: float, radians: bool = False) -> float:
    """The field of view ``value`` (degrees, or radians) in degrees if it lies within
    :data:`YFOV_RANGE_DEG`, else a one-line error naming ``name`` and the range in its unit."""
    low, high = (math.radians(v) for v in YFOV_RANGE_DEG) if radians else YFOV_RANGE_DEG
    if not (math.isfinite(value) and low <= value <= high):
        unit = "radians" if radians else "degrees"
        raise NeuralaoError(f"{name} must be within [{low:.4g}, {high:.4g}] {unit}, got {value:g}")
    return math.degrees(value) if radians else float(value)


_IN_RANGE = (
    f"AO is computed exactly for depths and radii in [{DEPTH_RANGE[0]:g}, {DEPTH_RANGE[1]:g}] scene units: "
    "scale the scene (and the radius alike) into that range"
)


def check_scene_length(name: str, value: float) -> float:
    """A length compared with the frame's depths (the AO radius) within :data:`DEPTH_RANGE`: one line
    naming ``name`` otherwise (NaN, inf, 0 and what float32 rounds to 0 included)."""
    if not DEPTH_RANGE[0] <= value <= DEPTH_RANGE[1]:
        raise NeuralaoError(f"{name} {value:.6g} is out of range; {_IN_RANGE}")
    return float(value)


def _value(key: str, value: Any, where: str) -> Any:
    """``value`` as the frame stores ``key``: arrays of real numbers, floats for the scalar keys."""
    if key in PROVENANCE:
        return value.item() if isinstance(value, np.ndarray) else value
    a = np.asarray(value)
    ch = CHANNELS[key]
    if a.dtype.kind not in ch.kinds or a.dtype.names is not None:
        allowed = {"f": "float", "i": "int", "u": "unsigned int", "b": "bool"}
        kinds = " or ".join(allowed[c] for c in ch.kinds)
        raise NeuralaoError(f"{where}: {key!r} holds {a.dtype} values; it must be {kinds}")
    if key in _SCALARS:
        if a.size != 1:
            raise NeuralaoError(f"{where}: {key!r} must be one number, got shape {a.shape}")
        number = float(a.reshape(()))
        if not math.isfinite(number):
            raise NeuralaoError(f"{where}: {key!r} is {number}; it must be finite")
        return number
    if key == "pose" and a.shape != (4, 4):
        raise NeuralaoError(f"{where}: 'pose' has shape {a.shape}, expected (4, 4)")
    if key == "radii" and a.ndim != 1:
        raise NeuralaoError(f"{where}: 'radii' has shape {a.shape}, expected (k,)")
    return a


def read_frame(path: str | os.PathLike, index: int | None = None) -> Frame:
    """The checked frame of an .npz: a single frame, or frame ``index`` of stacked frames (a dataset
    shard, whose bookkeeping keys are left out). A key that looks like a misspelt frame key (``fov``) is
    refused; other extra arrays (a user's own ``albedo``) are not frame keys and are left out."""
    keys = npz_keys(path)
    if not {"mask", "normal_obj", "depth", "normal_cam"} & set(keys):
        raise NeuralaoError(
            f"{path} is not a G-buffer frame (no depth / normal_cam / mask / normal_obj arrays)"
        )
    for key in keys:
        near = difflib.get_close_matches(key, Frame.KEYS, n=1, cutoff=0.75)
        if key not in Frame.KEYS and near:
            raise NeuralaoError(f"{path}: unknown frame key {key!r} (did you mean {near[0]!r}?)")
    arrays = read_npz(path, Frame.KEYS)  # a user's own extra arrays are never inflated
    n = _stacked_frames(arrays)
    if n is not None:
        if index is None:
            if n != 1:
                raise NeuralaoError(f"{path} holds {n} frames; pick one with --index K (0..{n - 1})")
            index = 0
        if not 0 <= index < n:
            raise NeuralaoError(f"--index {index} is outside 0..{n - 1} for {path}")
        arrays = {k: (v[index] if np.ndim(v) >= 1 and np.shape(v)[0] == n else v) for k, v in arrays.items()}
    elif index not in (None, 0):
        raise NeuralaoError(f"{path} holds one frame; --index {index} is out of range")
    return Frame.from_arrays({k: v for k, v in arrays.items() if k in Frame.KEYS}, str(path))


def _stacked_frames(arrays: Mapping[str, Any]) -> int | None:
    """N when every image channel has one axis more than a frame's (N, H, W, ...) and they agree on N;
    None otherwise (a channel of the wrong rank is then named by the shape check, not taken for a stack)."""
    ranks = {k: np.ndim(v) - 2 - len(CHANNELS[k].trailing) for k, v in arrays.items() if _image(k)}
    if not ranks or set(ranks.values()) != {1}:
        return None
    counts = {int(np.shape(arrays[k])[0]) for k in ranks}
    return counts.pop() if len(counts) == 1 else None


def _image(key: str) -> bool:
    return key in CHANNELS and CHANNELS[key].trailing is not None


def write_frame(path: str | os.PathLike, frame: Frame) -> None:
    """``frame``'s channels as an .npz (atomically; the file :func:`read_frame` reads)."""
    write_npz(path, **frame.arrays())


def as_frame(frame: Frame | Mapping[str, Any], where: str = "frame") -> Frame:
    """``frame`` itself, or a checked :class:`Frame` of a mapping's frame keys (a caller's own dict)."""
    if isinstance(frame, Frame):
        return frame
    return Frame.from_arrays({k: v for k, v in frame.items() if k in Frame.KEYS}, where, strict=False)


# What a function that reads a frame takes: a Frame, or any mapping of its keys (a caller's own dict of
# arrays, such as a renderer's before it is checked); the keys and shapes are Frame's.
FrameLike = Frame | Mapping[str, Any]
