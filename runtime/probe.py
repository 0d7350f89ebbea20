"""Evaluate per-region volume AO models (``neuralao volumes``) at points and normals, with temporal
blending for objects that move between regions (the library side of ``neuralao probe``).

    probe = VolumeProbe(read_volumes("VOLUMES.json"))
    ao = probe.ao(points, normals)                      # (n,) float32 in [0, 1], blended distances
    ao = probe.ao(points, normals, order="linear")      # bands 0-1 only, as the paper's engine
    path = blended_path(probe, positions, normals, dt=1/30, tau=0.2)   # one moving object, per frame

Region lookup (as an engine's visibility system tags an object): the first region whose box holds
the point; a point outside every box takes the nearest box (Euclidean distance to the box).

Temporal blending (Sloan et al. 2013: the model is blended with the previous frame's, exponential
decay): the state is the *packed model* the shader reads (export/glsl/volume.py), updated per frame as
``state = target + (state - target) * exp(-dt / tau)`` on the CPU, once per object. Two models with
different centres do not mix exactly by blending their numbers (the centre would be blended too, and
AO dips or overshoots at a switch: measured in bench/bench_volumes.py), so by default both are first
linearised at the object's position (:func:`anchored`): linear functions re-centred at one point blend
exactly. The shader and the layout stay the same.
"""

from __future__ import annotations

import math

import numpy as np

from neuralao.export.glsl.volume import evaluate_packed, pack_volumes
from neuralao.runtime.foundation import sh
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.volumes import Volumes, design

ORDERS = {"linear": sh.LINEAR, "quadratic": sh.QUADRATIC}
# Bytes per point and region of the lookup (nearest points of every box, their differences), the
# design rows and the SH evaluation: what `probe` allocates for each row of --points.
POINT_BYTES = 256


class VolumeProbe:
    """numpy evaluator of a :class:`neuralao.runtime.volumes.Volumes` (the reference for the GLSL
    function)."""

    def __init__(self, volumes: Volumes):
        self.volumes = volumes
        self.lo = np.array([r.lo for r in volumes.regions], dtype=np.float64)
        self.hi = np.array([r.hi for r in volumes.regions], dtype=np.float64)
        self.centres = np.stack([m.centre for m in volumes.models])
        self.coefficients = np.stack([m.coefficients for m in volumes.models])  # (R, 7, 2, 9)

    def region_of(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) -> (n,) int64: the first region holding each point, else the nearest box.

        Far from the level, squared distances cannot tell the boxes apart: at 1e30 every |p - q|^2 is
        1e60 to the last bit (and past 1e154 it overflows), so the first box would win. The nearest box
        is instead the one with the smallest |p - q_r|^2 - |p - q_0|^2 = (q_0 - q_r) . (2p - q_0 - q_r),
        q_r = the point of box r nearest to p (a clamp: exact), which keeps the differences between
        boxes at any distance; p is scaled by its largest coordinate first so nothing overflows."""
        p = np.asarray(points, np.float64)
        q = np.clip(p[:, None, :], self.lo[None], self.hi[None])  # (n, R, 3) nearest point of each box
        inside = (q == p[:, None, :]).all(axis=2)
        scale = np.maximum(np.abs(p).max(axis=1, initial=0.0), 1.0)[:, None, None]
        q0 = q[:, :1]
        excess = ((q0 - q) / scale * (2.0 * (p[:, None, :] / scale) - (q0 + q) / scale)).sum(axis=2)
        first = np.argmax(inside, axis=1)
        return np.where(inside.any(axis=1), first, np.argmin(excess, axis=1)).astype(np.int64)

    def sh_at(self, points: np.ndarray, regions: np.ndarray | None = None) -> np.ndarray:
        """AO-space SH (n, 2, 9) float64 of the models (of ``regions`` or the looked-up ones) at points."""
        p = np.asarray(points, np.float64)
        r = self.region_of(p) if regions is None else np.asarray(regions, np.int64)
        out = np.empty((len(p), 2, sh.QUADRATIC))
        for k in np.unique(r):
            sel = r == k
            with np.errstate(over="ignore", invalid="ignore"):  # checked just below
                out[sel] = np.einsum("nt,tdj->ndj", design(p[sel], self.centres[k]), self.coefficients[k])
        bad = ~np.isfinite(out).all(axis=(1, 2))
        if bad.any():
            i = int(np.argmax(bad))
            raise NeuralaoError(
                f"point {i} {p[i].tolist()} is too far from region {self.volumes.regions[r[i]].name!r} "
                f"for its model to be evaluated ({int(bad.sum())} such point(s)): "
                "the model overflows float64 there"
            )
        return out

    def ao(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        distance: str = "blend",
        order: str = "quadratic",
        regions: np.ndarray | None = None,
    ) -> np.ndarray:
        """AO (n,) float32 in [0, 1] for unit normals (n, 3): ``distance`` short | long | blend (the
        file's blend weight), ``order`` quadratic (9 SH) or linear (bands 0-1)."""
        count = _order(order)
        f = self.sh_at(points, regions)
        w = {"short": (1.0, 0.0), "long": (0.0, 1.0), "blend": (1.0 - self.volumes.blend, self.volumes.blend)}
        if distance not in w:
            raise NeuralaoError(f"distance must be short, long or blend, got {distance!r}")
        g = np.einsum("d,ndj->nj", np.array(w[distance]), f)[:, :count]
        return np.clip(sh.evaluate(g, normals), 0.0, 1.0).astype(np.float32)


def _order(order: str) -> int:
    try:
        return ORDERS[order]
    except KeyError:
        raise NeuralaoError(f"order must be 'linear' or 'quadratic', got {order!r}") from None


def anchored(packed: np.ndarray, anchor: np.ndarray) -> np.ndarray:
    """The packed model linearised at ``anchor`` (3,): centre = anchor, constant = the model's value
    there, each axis's +/- derivative = the one on the anchor's side of the model centre. Same layout
    (SIZE, 4), so the same shader; exact at the anchor and on the anchor's side of every centre plane.
    A model that is already linear (equal +/- derivatives) is only re-centred: the same function."""
    u = np.array(packed, dtype=np.float64)
    d = np.asarray(anchor, np.float64) - u[0, :3]
    k = (len(u) - 1) // 7
    out = np.zeros_like(u)
    out[0, :3] = anchor
    for c in range(k):
        t = u[1 + 7 * c : 8 + 7 * c]
        value = t[0].copy()
        for axis in range(3):
            slope = t[1 + 2 * axis] if d[axis] >= 0 else t[2 + 2 * axis]
            value += d[axis] * slope
            out[2 + 2 * axis + 7 * c] = out[3 + 2 * axis + 7 * c] = slope
        out[1 + 7 * c] = value
    return out


class TemporalBlend:
    """Exponential decay towards the current region's packed model (module doc).

    ``mode="anchored"`` (default): target and state are linearised at the object's anchor each frame
    (:func:`anchored`), so the state is always exactly ``w * f_new + (1 - w) * f_old`` of the functions
    it has seen (no overshoot when the two models' centres differ), at the cost of the kink at a
    model's centre inside the object's extent. ``mode="parameters"``: the packed numbers themselves,
    centre included, are blended (kinks kept, but across centres not exactly a mix of the functions).
    """

    def __init__(self, tau: float, mode: str = "anchored"):
        if not (math.isfinite(tau) and tau >= 0):
            raise NeuralaoError(f"tau must be a finite time >= 0, got {tau!r}")
        if mode not in ("anchored", "parameters"):
            raise NeuralaoError(f"temporal blend mode must be anchored or parameters, got {mode!r}")
        self.tau = float(tau)
        self.mode = mode
        self.state: np.ndarray | None = None

    def step(self, target: np.ndarray, dt: float, anchor: np.ndarray | None = None) -> np.ndarray:
        """Advance by ``dt`` towards ``target`` (SIZE, 4); the first call adopts it. ``anchor`` (3,):
        the object's position (required in anchored mode). Returns the state to upload."""
        target = np.asarray(target, np.float64)
        if self.mode == "anchored":
            if anchor is None:
                raise NeuralaoError("anchored temporal blending needs the object's anchor position")
            target = anchored(target, anchor)
        if self.state is None or self.tau == 0.0:
            self.state = target.copy()
            return self.state
        prev = anchored(self.state, anchor) if self.mode == "anchored" else self.state
        self.state = target + (prev - target) * math.exp(-float(dt) / self.tau)
        return self.state


def blended_path(
    probe: VolumeProbe,
    positions: np.ndarray,
    normals: np.ndarray,
    dt: float,
    tau: float,
    order: str = "linear",
    mode: str = "anchored",
) -> np.ndarray:
    """AO (T,) float64 of one object moving along ``positions`` (T, 3) (its anchor) with ``normals``
    (T, 3), one frame every ``dt``: per frame the packed model of its region, temporally blended with
    ``tau`` (0: none, the model switches at region boundaries), evaluated as the shader does."""
    packed = pack_volumes(probe.volumes, order)
    regions = probe.region_of(positions)
    blend = TemporalBlend(tau, mode)
    states = np.stack([blend.step(packed[r], dt, p) for r, p in zip(regions, positions, strict=True)])
    return evaluate_packed(states, positions, normals)
