"""Image tensors seen through Reshape / Transpose / Flatten / Squeeze, as index arithmetic.

A texture holds a (1, C, H, W) tensor. Exporters write channel shuffles, GroupNorm, LayerNorm over
channels, PixelUnshuffle and flattening before a Gemm as Reshape / Transpose on that tensor. The
image target keeps such a tensor as a :class:`View`: the texture plus, per logical axis, the run of
*atoms* (mixed-radix digits) its index is made of. An atom moves one texture coordinate (channel,
y or x) by ``digit * stride``. Reshape splits and regroups atoms, Transpose permutes axes, and the
ops that read views (reductions, normalisations, softmax, Gemm, the gather pass that materialises a
view as a new texture) turn atoms back into texture coordinates. Everything here is static: a view
needs a static image size.

Pure Python and numpy: no shader text (the image writer turns atoms into GLSL).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Atom:
    """One digit of a logical index: ``size`` values, each moving texture coordinate ``axis``
    ("c", "y" or "x") by ``stride``."""

    axis: str
    size: int
    stride: int


Axes = tuple[tuple[Atom, ...], ...]


def image_axes(channels: int, height: int, width: int) -> Axes:
    """The atoms of a (1, C, H, W) texture read as itself (size-1 atoms dropped)."""
    return ((), _atoms("c", channels), _atoms("y", height), _atoms("x", width))


def _atoms(axis: str, size: int) -> tuple[Atom, ...]:
    return (Atom(axis, size, 1),) if size > 1 else ()


def axes_shape(axes: Axes) -> list[int]:
    return [math.prod(a.size for a in run) for run in axes]


def reshape(axes: Axes, shape: list[int]) -> Axes | str:
    """The atoms regrouped into ``shape`` (row-major, as numpy's reshape), splitting an atom where a
    new dimension ends inside it; a string says why it cannot be done."""
    queue = [a for run in axes for a in run]
    if math.prod(shape) != math.prod(a.size for a in queue):
        return f"cannot reshape {axes_shape(axes)} to {shape}"
    out = []
    for d in shape:
        run: list[Atom] = []
        p = 1
        while p < d:
            atom = queue.pop(0)
            if d % (p * atom.size) == 0:
                run.append(atom)
                p *= atom.size
                continue
            need = d // p
            if d % p or atom.size % need:
                return f"dimension {d} of {shape} cuts across a digit of size {atom.size}"
            inner = atom.size // need
            run.append(Atom(atom.axis, need, atom.stride * inner))
            queue.insert(0, Atom(atom.axis, inner, atom.stride))
            p = d
        out.append(tuple(run))
    return tuple(out)


def transpose(axes: Axes, perm: list[int]) -> Axes:
    return tuple(axes[p] for p in perm)


def coordinates(axes: Axes) -> dict[str, np.ndarray]:
    """Texture coordinate ("c", "y", "x") of every logical element: int64 arrays of the logical shape."""
    shape = axes_shape(axes)
    out = {k: np.zeros(shape, np.int64) for k in "cyx"}
    for i, run in enumerate(axes):
        index = np.arange(shape[i]).reshape([-1 if k == i else 1 for k in range(len(shape))])
        for atom in reversed(run):  # innermost digit first
            out[atom.axis] = out[atom.axis] + (index % atom.size) * atom.stride
            index = index // atom.size
    return out


def is_image(axes: Axes, channels: int, height: int, width: int) -> bool:
    """The view is its texture, element for element: rank 4, (1, C, H, W), identity order."""
    if len(axes) != 4 or axes[0]:
        return False
    want = {1: ("c", channels), 2: ("y", height), 3: ("x", width)}
    for i, (axis, size) in want.items():
        stride = 1
        for atom in reversed(axes[i]):
            if atom.axis != axis or atom.stride != stride:
                return False
            stride *= atom.size
        if stride != size:
            return False
    return True


def channel_atoms(atoms: list[Atom]) -> list[Atom]:
    """The channel atoms, outermost (largest stride) first: the mixed radix of the channel index."""
    return sorted((a for a in atoms if a.axis == "c"), key=lambda a: -a.stride)


@dataclass
class Reduction:
    """Which texture coordinates a reduction over some logical axes folds together.

    groups : output channel count (the kept channel digits); base : (groups,) int, first input
    channel of each group; offsets : (n,) int, added to base for the n members of a group;
    group_of : (C,) int, the group of every input channel; spatial : (reduce y, reduce x);
    kept : the kept axes' atoms rewritten for the output texture (channel strides renumbered).
    """

    groups: int
    base: np.ndarray
    offsets: np.ndarray
    group_of: np.ndarray
    spatial: tuple[bool, bool]
    kept: Axes


def reduction(axes: Axes, reduced: list[int], channels: int) -> Reduction | str:
    """The reduction of a view over logical axes ``reduced``; a string says why it cannot be done
    (a spatial coordinate both reduced and kept)."""
    gone = [a for i in reduced for a in axes[i]]
    kept_atoms = [a for i, run in enumerate(axes) if i not in reduced for a in run]
    for axis in "yx":
        if any(a.axis == axis for a in gone) and any(a.axis == axis for a in kept_atoms):
            return f"the reduction folds part of the image's {'height' if axis == 'y' else 'width'} only"
    kept_c, gone_c = channel_atoms(kept_atoms), channel_atoms(gone)
    # output stride of each kept channel atom: mixed radix over the kept digits, outermost first
    new_stride, s = {}, 1
    for atom in reversed(kept_c):
        new_stride[atom] = s
        s *= atom.size
    groups = s
    base = np.zeros(groups, np.int64)
    for digits in itertools.product(*(range(a.size) for a in kept_c)):
        g = sum(d * new_stride[a] for d, a in zip(digits, kept_c, strict=True))
        base[g] = sum(d * a.stride for d, a in zip(digits, kept_c, strict=True))
    offsets = np.asarray(
        [
            sum(d * a.stride for d, a in zip(digits, gone_c, strict=True))
            for digits in itertools.product(*(range(a.size) for a in gone_c))
        ],
        np.int64,
    )
    group_of = np.zeros(channels, np.int64)
    for c in range(channels):
        group_of[c] = sum(((c // a.stride) % a.size) * new_stride[a] for a in kept_c)
    kept = tuple(
        ()
        if i in reduced
        else tuple(Atom(a.axis, a.size, new_stride[a] if a.axis == "c" else a.stride) for a in run)
        for i, run in enumerate(axes)
    )
    spatial = (any(a.axis == "y" for a in gone), any(a.axis == "x" for a in gone))
    return Reduction(groups, base, offsets, group_of, spatial, kept)


def per_channel(axes: Axes, value: np.ndarray, channels: int) -> np.ndarray | str:
    """(C,) float64: a constant broadcast over the view's logical shape, as one value per texture
    channel; a string says why it is not one (it varies over the image's height or width). Works on
    the channel digits only, so a large image costs nothing."""
    shape = axes_shape(axes)
    v = np.asarray(value, np.float64)
    if v.ndim > len(shape):
        return f"a constant of shape {list(v.shape)} has more axes than the tensor {shape}"
    vshape = (1,) * (len(shape) - v.ndim) + v.shape
    index: list[np.ndarray | int] = []
    c = np.arange(channels)
    for n, size, run in zip(vshape, shape, axes, strict=True):
        if n not in (1, size):
            return f"a constant of shape {list(v.shape)} does not broadcast to {shape}"
        if n == 1:
            index.append(0)
            continue
        if any(a.axis != "c" for a in run):
            return f"a constant of shape {list(v.shape)} varies over the image's height or width"
        i, scale = np.zeros(channels, np.int64), 1
        for a in reversed(run):
            i += ((c // a.stride) % a.size) * scale
            scale *= a.size
        index.append(i)
    return np.broadcast_to(v.reshape(vshape)[tuple(index)], (channels,)).astype(np.float64)
