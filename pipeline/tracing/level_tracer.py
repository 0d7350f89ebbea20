"""Level tracing: obscurance at several half distances from one trace, foliage, sphere resampling.

:class:`LevelLabeller` is the project's :class:`~neuralao.pipeline.tracing.labeller.Labeller` (same Hammersley
directions, per-sample rotations, ray offset, local frame and back-face rule) with two additions:

* :meth:`LevelLabeller.obscurance` traces every ray once (closest hit, to ``max_distance``) and
  evaluates ``rho(d) = 1 - 2^(-d / h)`` for each half distance ``h`` from the same hit distances
  (Sloan et al.: 2 m and 300 m, blended per level). Without foliage each column equals a separate
  ``Labeller.ao_at_points`` trace with ``kernel="obscurance", half_distance=h`` bit for bit (the
  arithmetic is the same, in the same order; tests/test_level_trace.py checks it). With a
  :class:`~neuralao.pipeline.tracing.foliage.Foliage`, each ray's rho is multiplied by the transmittance of
  its segment through the shrub boxes and tree triangles.
* :meth:`LevelLabeller.closest_hits` traces caller-chosen rays (for the sphere resampler of grass
  clumps and LODs, :func:`resample_in_spheres`).
"""

from __future__ import annotations

import numpy as np

from neuralao.pipeline.geometry.scene import Scene
from neuralao.pipeline.geometry.surface import interpolate
from neuralao.pipeline.tracing.labeller import Labeller, run_chunks
from neuralao.runtime.foundation.errors import NeuralaoError

# Rays per chunk of caller-chosen rays (as the labeller's own chunks).
_CHUNK = 1 << 16
# Rays per block of resampling spheres (keeps the hit arrays at tens of MB).
_RESAMPLE_RAYS = 1 << 20


class LevelLabeller(Labeller):
    bvh = "fast"  # Embree's high-quality BVH without the robust flag (Labeller.bvh)

    def obscurance(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        half_distances: list[float],
        foliage=None,
        ids: np.ndarray | None = None,
        progress: bool = False,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Obscurance at every half distance (scene units) from one trace.

        points, normals : (n, 3) float64; ids (n,) int64 randomisation ids (default arange(n)).
        Returns ao (n, k) float32 in [0, 1] and valid (n,) bool (back-face rule, usable normal).
        """
        if self._kernel != "obscurance":
            raise NeuralaoError("LevelLabeller.obscurance needs settings with kernel='obscurance'")
        h_local = [float(h) / self.scale for h in half_distances]
        if not h_local or not all(np.isfinite(h) and h > 0 for h in h_local):
            raise NeuralaoError(f"half distances must be positive and finite, got {half_distances!r}")
        local, normals, ids = self._local_points(points, normals, ids)
        count, k = len(local), len(h_local)
        ao = np.ones((count, k), np.float32)
        valid = np.zeros(count, bool)
        if count == 0:
            return ao, valid
        origins, frames, jitter, ok = self._prepare_all(local, normals, ids)

        def trace(lo: int, hi: int) -> None:
            ao[lo:hi], valid[lo:hi] = self._trace_halves(
                origins[lo:hi], frames[:, :, lo:hi], jitter[lo:hi], h_local, foliage
            )

        run_chunks(trace, count, self._chunk_points, self.settings.workers, progress)
        ao[~np.isfinite(local).all(axis=1)] = 1.0
        return ao, valid & ok

    # Early out of the back-face rule: after each of these points of the ray loop, samples whose back-face
    # hits already exceed the threshold (so are invalid whatever the rest would hit) trace no more rays.
    # Valid samples trace every ray and their AO is bit for bit the full trace's (tests/test_level_trace.py).
    early_out = True

    def _checkpoints(self, n_rays: int) -> list[int]:
        """Ray counts after which the back-face rule is checked: the first count that can prove a sample
        invalid, half the rays, all of them (just ``[n_rays]`` without the rule or the early out)."""
        if not (self.backface_rule and self.early_out):
            return [n_rays]
        first = int(np.floor(self._threshold * n_rays)) + 1
        return sorted({p for p in (max(first, 8), n_rays // 2) if 0 < p < n_rays} | {n_rays})

    def _trace_halves(self, origins, frames, jitter, h_local, foliage):
        """One INTERSECT per ray; rho at each half distance (the arithmetic of ``Labeller._trace``).

        Rays go in rounds (:meth:`_checkpoints`): a sample the back-face rule has already rejected traces
        no more rounds, and its AO (unused: it is invalid) is the mean over the rays it traced. Each round
        makes only its own rays (the directions are elementwise, so they are the bits a whole trace makes)
        and walks them through the foliage at once."""
        m, n_rays = len(origins), self._rays
        dirs_p, orig_p, tmp, dists = self._buffers(m * n_rays)
        r = self.r_local
        tfar = np.full((m, n_rays), r, np.float32)  # untraced rays read as misses
        vis = None if foliage is None or foliage.empty else np.ones((m, n_rays), np.float32)
        start = None if vis is None else foliage.origin_density(origins)
        back = np.zeros(m, np.int64)
        done = np.full(m, n_rays)  # rays traced per sample
        active, lo = np.arange(m), 0
        for hi in self._checkpoints(n_rays):
            if not len(active):
                break
            k, w = len(active), hi - lo
            every = k == m
            count = k * w
            d_p, o_p = dirs_p[:, :count], orig_p[:, :count]
            fr = frames if every else frames[:, :, active]
            scratch = tmp[:count].reshape(k, w)
            self._directions(fr, jitter[active], d_p.reshape(3, k, w), scratch, slice(lo, hi))
            for c in range(3):
                o_p[c].reshape(k, w)[:] = origins[active, c, None]
            t_in = dists[:count]
            t_in.fill(r)
            out = self.embree.run(o_p.T, d_p.T, query="INTERSECT", dists=t_in, output=1)
            prim = out["primID"]
            rows = slice(None) if every else active
            tfar[rows, lo:hi] = out["tfar"].reshape(k, w)
            if vis is not None:
                vis[rows, lo:hi] = foliage.transmittance(
                    o_p.T, d_p.T, np.minimum(out["tfar"], r), np.repeat(start[active], w)
                ).reshape(k, w)
            if self.backface_rule:
                hit_idx = np.flatnonzero(prim >= 0)
                fn = self._face_normals32[prim[hit_idx]]
                facing = d_p[0, hit_idx] * fn[:, 0]
                facing += d_p[1, hit_idx] * fn[:, 1]
                facing += d_p[2, hit_idx] * fn[:, 2]
                back[active] += np.bincount(hit_idx[facing > 0] // w, minlength=k)
            if hi < n_rays:
                stop = back[active] / n_rays > self._threshold
                done[active[stop]] = hi
                active = active[~stop]
            lo = hi
        back_ok = back / n_rays <= self._threshold if self.backface_rule else np.ones(m, dtype=bool)
        partial = np.flatnonzero(done < n_rays)
        ao = np.empty((m, len(h_local)), np.float32)
        # 1 - 2^(-t / h) on a hit, 1 on a miss, times the foliage's transmittance: in place, the same
        # float32 operations as Labeller._trace's expression; a miss reads t = inf, so 2^(-inf) = 0 gives it
        # exactly 1
        neg_t = tfar
        np.copyto(neg_t, np.float32(np.inf), where=~(tfar < r))
        np.negative(neg_t, out=neg_t)
        rho = tmp[: m * n_rays].reshape(m, n_rays)
        for j, h in enumerate(h_local):
            np.divide(neg_t, np.float32(h), out=rho)
            np.exp2(rho, out=rho)
            np.subtract(np.float32(1.0), rho, out=rho)
            if vis is not None:
                rho *= vis
            ao[:, j] = np.clip(rho.mean(axis=1, dtype=np.float64).astype(np.float32), 0.0, 1.0)
            for n in np.unique(done[partial]):  # rejected samples: the mean over the rays they traced
                rej = partial[done[partial] == n]
                ao[rej, j] = np.clip(rho[rej, :n].mean(axis=1, dtype=np.float64).astype(np.float32), 0.0, 1.0)
        return ao, back_ok

    def closest_hits(
        self, origins: np.ndarray, dirs: np.ndarray, tmax: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Closest hits of rays ``origins + t dirs`` (world, (r, 3) float64, unit dirs), t in (0, tmax (r,)].

        Returns prim (r,) int64 (-1 = miss) and t (r,) float64 scene units (inf on a miss).
        """
        local = ((np.asarray(origins, np.float64) - self.center) / self.scale).astype(np.float32)
        d = np.ascontiguousarray(dirs, dtype=np.float32)
        tl = (np.asarray(tmax, np.float64) / self.scale).astype(np.float32)
        prim = np.full(len(local), -1, np.int64)
        t = np.full(len(local), np.inf)

        def work(lo: int, hi: int) -> None:
            out = self.embree.run(
                np.ascontiguousarray(local[lo:hi]),
                d[lo:hi],
                query="INTERSECT",
                dists=tl[lo:hi].copy(),
                output=1,
            )
            p = out["primID"]
            hit = p >= 0
            prim[lo:hi] = np.where(hit, p, -1)
            t[lo:hi] = np.where(hit, out["tfar"].astype(np.float64) * self.scale, np.inf)

        if len(local):
            run_chunks(work, len(local), _CHUNK, self.settings.workers, False)
        return prim, t

    def closest_hits_local(
        self, origins: np.ndarray, dirs: np.ndarray, tmax: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Closest hits of rays in the labeller's local frame, as Embree returns them.

        origins, dirs (r, 3) float32 (unit dirs), tmax (r,) float32 local units.
        Returns prim (r,) int32 (-1 = miss) and Embree's barycentrics u, v and distance t (r,) float32
        (the hit is ``(1 - u - v) v0 + u v1 + v v2`` of face ``prim``; t = tmax on a miss).
        """
        n = len(origins)
        prim = np.empty(n, np.int32)
        bu, bv, t = np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)

        def work(lo: int, hi: int) -> None:
            out = self.embree.run(
                origins[lo:hi],
                dirs[lo:hi],
                query="INTERSECT",
                dists=np.array(tmax[lo:hi], np.float32),
                output=1,
            )
            prim[lo:hi], bu[lo:hi], bv[lo:hi], t[lo:hi] = out["primID"], out["u"], out["v"], out["tfar"]

        if n:
            run_chunks(work, n, _CHUNK, self.settings.workers, False)
        return prim, bu, bv, t


def _resample_block(
    labeller: LevelLabeller, cols: np.ndarray, centers: np.ndarray, rad: np.ndarray, u: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """resample_in_spheres for one block of centres: values (p, c) float64 (NaN: no hit), weight sums (p,).

    At trace speed: the ray from ``c + r u`` toward ``c`` that hits at distance ``t`` hits at
    ``c + (r - t) u``, so its weight ``r - |hit - c|`` is ``r - |r - t|`` (no hit point is formed), and
    Embree's own barycentrics (u, v) of the hit interpolate the values; the sums per centre are row
    sums of a (p, k) layout (a centre's k rays are consecutive). :func:`_resample_block_geometric` is
    the reference it is tested against (projected hit points, bincount)."""
    p, k, nc = len(centers), len(u), cols.shape[1]
    scale = labeller.scale
    rl = rad / scale  # local units
    local_c = (centers - labeller.center) / scale
    origins = (local_c[:, None, :] + rl[:, None, None] * u[None]).reshape(-1, 3).astype(np.float32)
    dirs = np.ascontiguousarray(np.broadcast_to(-u.astype(np.float32), (p, k, 3)).reshape(-1, 3))
    prim, bu, bv, t = labeller.closest_hits_local(origins, dirs, np.repeat((2 * rl).astype(np.float32), k))
    hit = prim >= 0
    face = labeller.scene.faces[np.where(hit, prim, 0)]  # misses read face 0 and get weight 0
    b1, b2 = bu.astype(np.float64), bv.astype(np.float64)
    b0 = 1.0 - b1 - b2
    vals = b0[:, None] * cols[face[:, 0]] + b1[:, None] * cols[face[:, 1]] + b2[:, None] * cols[face[:, 2]]
    keep = hit & np.isfinite(vals).all(axis=1)  # hits on faces without values (e.g. blockers) are left out
    rr = np.repeat(rad, k)
    ww = np.where(keep, np.maximum(rr - np.abs(rr - t.astype(np.float64) * scale), 0.0), 0.0)
    wv = ww[:, None] * np.where(keep[:, None], vals, 0.0)
    total = ww.reshape(p, k).sum(axis=1)
    out = wv.reshape(p, k, nc).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(total[:, None] > 0, out / total[:, None], np.nan)
    return out, total


def _resample_block_geometric(
    labeller: LevelLabeller, cols: np.ndarray, centers: np.ndarray, rad: np.ndarray, u: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The reference :func:`_resample_block` is checked against: world hit points, their distance to
    the centre, barycentrics by projection onto the hit triangle, sums by bincount (4x slower)."""

    k = len(u)
    origins = (centers[:, None, :] + rad[:, None, None] * u[None]).reshape(-1, 3)
    dirs = np.tile(-u, (len(centers), 1))
    prim, t = labeller.closest_hits(origins, dirs, np.repeat(2 * rad, k))
    hit = prim >= 0
    owner = np.repeat(np.arange(len(centers)), k)[hit]
    points = origins[hit] + t[hit, None] * dirs[hit]
    w = np.maximum(rad[owner] - np.linalg.norm(points - centers[owner], axis=1), 0.0)
    face = prim[hit]
    bary = barycentric(labeller.scene, face, points)
    vals = np.stack([interpolate(labeller.scene, cols[:, j], face, bary) for j in range(cols.shape[1])], 1)
    keep = np.isfinite(vals).all(axis=1)
    out = np.stack(
        [
            np.bincount(owner[keep], weights=(w * vals[:, j])[keep], minlength=len(centers))
            for j in range(cols.shape[1])
        ],
        1,
    )
    total = np.bincount(owner[keep], weights=w[keep], minlength=len(centers))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(total[:, None] > 0, out / total[:, None], np.nan)
    return out, total


def sphere_directions(k: int) -> np.ndarray:
    """(8 * ceil(k / 8), 3) float64 unit directions: a Fibonacci set in the positive octant, reflected
    into all eight, so the set is symmetric under every sign flip of x, y or z. On an axis-aligned
    plane the hits then lie symmetrically about the centre's foot point and the weights are symmetric
    too, so a linear signal is resampled exactly (its value at the foot point)."""
    n = max(1, -(-k // 8))
    i = np.arange(n) + 0.5
    z = 1.0 - i / n  # cos(theta) uniform over (0, 1]: equal-area bands of the octant
    phi = (np.pi / 2) * np.mod(i * (np.sqrt(5.0) - 1.0) / 2.0, 1.0)
    r = np.sqrt(1.0 - z * z)
    u = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    signs = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)], np.float64)
    return (signs[:, None, :] * u[None]).reshape(-1, 3)


def barycentric(scene: Scene, face: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(h, 3) barycentric coordinates of ``points`` (h, 3) projected onto triangles ``face`` (h,)."""
    t = scene.vertices[scene.faces[face]]
    v0, v1, v2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0], points - t[:, 0]
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = d00 * d11 - d01 * d01
    b1 = (d11 * d20 - d01 * d21) / den
    b2 = (d00 * d21 - d01 * d20) / den
    bary = np.clip(np.stack([1 - b1 - b2, b1, b2], 1), 0.0, 1.0)
    return bary / bary.sum(1, keepdims=True)


def resample_in_spheres(
    labeller: LevelLabeller,
    vertex_values: np.ndarray,
    centers: np.ndarray,
    radius: np.ndarray | float,
    rays: int = 32,
) -> tuple[np.ndarray, np.ndarray]:
    """Sloan et al. 2.2.1: the signal on the surface near each centre, by rays from the boundary of a
    sphere toward its centre; each hit's value (``vertex_values`` interpolated at the hit) is weighted
    by the hit's distance to the sphere's boundary, ``radius - |hit - centre|``.

    labeller : traces ``labeller.scene`` (whose vertices ``vertex_values`` (n,) or (n, c) belong to)
    centers (p, 3) float64, radius scalar or (p,) scene units.
    Returns values (p,) or (p, c) float64 (NaN where no ray hit) and hit weights' sum (p,).
    Hits on faces whose values are NaN (blockers, which carry no AO) are left out.
    """
    centers = np.asarray(centers, np.float64).reshape(-1, 3)
    rad = np.broadcast_to(np.asarray(radius, np.float64), (len(centers),))
    if not (np.isfinite(rad).all() and (rad > 0).all()):
        raise NeuralaoError("resampling radius must be positive and finite")
    values = np.asarray(vertex_values, np.float64)
    cols = values.reshape(len(values), -1)
    u = sphere_directions(rays)
    out = np.full((len(centers), cols.shape[1]), np.nan)
    total = np.zeros(len(centers))
    block = max(1, _RESAMPLE_RAYS // len(u))  # bounded memory: a few MB of rays per block
    for lo in range(0, len(centers), block):
        c, r = centers[lo : lo + block], rad[lo : lo + block]
        out[lo : lo + block], total[lo : lo + block] = _resample_block(labeller, cols, c, r, u)
    return (out[:, 0] if values.ndim == 1 else out), total
