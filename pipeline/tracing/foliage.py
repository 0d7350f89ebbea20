"""Foliage as participating media (Sloan et al. 2013, section 2.1).

Shrubs are not in the opaque BVH. Each shrub instance becomes its world-space bounding box with a
density ``sigma`` (per scene unit); trees are semi-transparent, every crossing of a tree triangle
multiplies visibility by the node's ``transmission`` (0.5 in the paper). Both live in a second
Embree scene (box faces first, tree triangles after), in the opaque labeller's local frame. After
the opaque ray, the segment from the origin to the opaque hit (or to the max distance) is walked
through that scene hit by hit, and the ray's obscurance is multiplied by

    T = exp(-integral_0^end f(t) dt) * prod_(tree hits) transmission,

with ``f(t)`` the summed density of the boxes containing the point at ``t``. ``f`` is piecewise
constant: ``f(0)`` is the density of the boxes around the ray's origin (a point-in-box test per
sample), and every box face crossed
at ``t_j`` changes it by ``+sigma`` (entry, ``dot(d, n) < 0``) or ``-sigma`` (exit), so

    integral = f(0) * end + sum_j dsigma_j * (end - t_j).

Overlaps: a box's density is divided by ``1 + sum_j vol(B_i & B_j) / vol(B_i)``, so ``k`` equal
boxes stacked on top of each other attenuate like one (the paper reduces densities "so that
visibility does not darken too much where bounding boxes overlap"; this is one such rule).

Limitation: Embree reports one closest hit, and the walk steps past it, so two faces crossed at the
same ``t`` (coplanar faces of two boxes, or coincident tree triangles) count once. Boxes of
instances at random positions practically never share a plane.
"""

from __future__ import annotations

import numpy as np

from neuralao.pipeline.tracing.embree_buffers import add_triangles
from neuralao.runtime.foundation.errors import NeuralaoError

# Box candidates per point tested vectorised in origin_density (more take the exact slow path).
_NEAREST = 8
# Step past a crossed surface before tracing on (local units, diagonal = 1): 100x the float32
# rounding of local coordinates (~3e-8), far below any box or tree feature.
_STEP = 3e-6


def box_triangles(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (b, 3) lo / hi -> vertices (8b, 3) and outward faces (12b, 3) int64
    (box i: faces 12i..12i+11)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    v = lo[:, None, :] + corners[None] * (hi - lo)[:, None, :]
    f = np.array(
        [
            [0, 1, 3],
            [0, 3, 2],
            [4, 6, 7],
            [4, 7, 5],
            [0, 4, 5],
            [0, 5, 1],
            [2, 3, 7],
            [2, 7, 6],
            [0, 2, 6],
            [0, 6, 4],
            [1, 5, 7],
            [1, 7, 3],
        ],
        np.int64,
    )
    faces = f[None] + 8 * np.arange(len(lo))[:, None, None]
    return v.reshape(-1, 3), faces.reshape(-1, 3)


def overlap_reduced(lo: np.ndarray, hi: np.ndarray, density: np.ndarray) -> np.ndarray:
    """(b,) densities divided by 1 + (volume of box i shared with the other boxes) / vol(box i)."""
    from scipy.spatial import cKDTree  # measured: ~0.8 s to import; only this step needs it

    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    density = np.asarray(density, np.float64)
    if len(lo) < 2:
        return density.copy()
    centre, half = (lo + hi) / 2, np.linalg.norm(hi - lo, axis=1) / 2
    pairs = cKDTree(centre).query_pairs(2 * float(half.max()), output_type="ndarray")
    share = np.zeros(len(lo))
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        ext = np.clip(np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j]), 0, None)
        inter = ext.prod(axis=1)
        np.add.at(share, i, inter)
        np.add.at(share, j, inter)
    vol = np.maximum((hi - lo).prod(axis=1), 1e-300)
    return density / (1.0 + share / vol)


class Foliage:
    """The second BVH: shrub boxes (media) and tree triangles (semi-transparent), in local units.

    boxes_lo, boxes_hi : (b, 3) float64 world; density (b,) per scene unit (already overlap-reduced)
    tree_vertices (t, 3) float64 world, tree_faces (f, 3) int64, tree_transmission (f,) per triangle
    center (3,), scale: the opaque labeller's local frame ``(x - center) / scale``.
    """

    def __init__(
        self,
        boxes_lo,
        boxes_hi,
        density,
        tree_vertices,
        tree_faces,
        tree_transmission,
        center,
        scale,
        max_hits: int = 32,
    ):
        from embreex import rtcore_scene  # measured: ~0.2 s to import; only the ray queries need it

        # Kept for pickling (see __reduce__): the Embree scene is rebuilt where a copy is unpickled.
        self._args = (
            boxes_lo,
            boxes_hi,
            density,
            tree_vertices,
            tree_faces,
            tree_transmission,
            center,
            scale,
            max_hits,
        )
        self.center, self.scale = np.asarray(center, np.float64), float(scale)
        bv, bf = box_triangles(np.reshape(boxes_lo, (-1, 3)), np.reshape(boxes_hi, (-1, 3)))
        tv = np.reshape(np.asarray(tree_vertices, np.float64), (-1, 3))
        tf = np.reshape(np.asarray(tree_faces, np.int64), (-1, 3))
        verts = np.concatenate([bv, tv]) if len(tv) else bv
        faces = np.concatenate([bf, tf + len(bv)]) if len(tf) else bf
        self.n_boxes, self.n_tree_faces = len(bf) // 12, len(tf)
        self.empty = len(faces) == 0
        if max_hits < 1:
            raise NeuralaoError(f"foliage max_hits must be >= 1, got {max_hits}")
        self.max_hits = int(max_hits)
        # Per primitive: density (per local unit) for box faces, transmission for tree triangles.
        dens = np.asarray(density, np.float64).reshape(-1)
        if len(dens) != self.n_boxes or (dens < 0).any() or not np.isfinite(dens).all():
            raise NeuralaoError("foliage densities must be finite, >= 0, one per box")
        self._sigma = np.concatenate([np.repeat(dens * self.scale, 12), np.zeros(len(tf))]).astype(np.float64)
        trans = np.asarray(tree_transmission, np.float64).reshape(-1)
        self._trans = np.concatenate([np.ones(len(bf)), trans]).astype(np.float32)
        local = (verts - self.center) / self.scale
        t = local[faces]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        self._normals = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
        self._is_box = np.arange(len(faces)) < len(bf)
        if self.n_boxes:
            from scipy.spatial import cKDTree  # measured: ~0.8 s to import; only this step needs it

            self._lo = (np.reshape(boxes_lo, (-1, 3)) - self.center) / self.scale
            self._hi = (np.reshape(boxes_hi, (-1, 3)) - self.center) / self.scale
            self._box_sigma = dens * self.scale
            self._box_tree = cKDTree((self._lo + self._hi) / 2)
            self._box_reach = float(np.linalg.norm(self._hi - self._lo, axis=1).max()) / 2 * (1 + 1e-9)
        if not self.empty:
            self._embree = rtcore_scene.EmbreeScene()
            add_triangles(self._embree, local, faces)
            self._embree.run(
                np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED", dists=1.0
            )

    def __reduce__(self):
        """Pickle as the constructor's inputs (an Embree scene does not pickle): Ray workers of
        neuralao.pipeline.engines.engine get a working copy through the object store."""
        return (Foliage, self._args)

    def _walk(self, orig: np.ndarray, dirs: np.ndarray, end: np.ndarray):
        """Every crossing within (0, end): yields (ray index (h,), t (h,) float64, prim (h,))."""
        active = np.arange(len(orig))
        t = np.zeros(len(orig), np.float64)
        for i in range(self.max_hits):
            if not len(active):
                break
            if i == 0:  # every ray from its origin (t = 0): the arrays as they are, no gather
                o, d, rem = orig, dirs, end.astype(np.float32)
            else:
                o = (orig[active] + dirs[active] * t[active, None].astype(np.float32)).astype(np.float32)
                d = np.ascontiguousarray(dirs[active])
                rem = (end[active] - t[active]).astype(np.float32)
            out = self._embree.run(o, d, query="INTERSECT", dists=rem, output=1)
            prim = out["primID"]
            hit = prim >= 0
            a, p = active[hit], prim[hit]
            th = t[a] + out["tfar"][hit]
            yield a, th, p
            t[a] = th + _STEP
            active = a[t[a] < end[a]]

    def origin_density(self, origins: np.ndarray) -> np.ndarray:
        """(m,) summed density (per local unit) of the boxes containing each local origin (m, 3): an
        exact point-in-box test on the box centres a KD-tree finds within reach (a ray walk would
        count coplanar faces of two boxes, crossed at the same t, once). Vectorised over the nearest
        ``_NEAREST`` candidates; points with more candidates than that take an exact slow path."""
        origins = np.asarray(origins, np.float64).reshape(-1, 3)
        out = np.zeros(len(origins))
        if self.n_boxes == 0 or not len(origins):
            return out
        k = min(_NEAREST, self.n_boxes)
        _, idx = self._box_tree.query(origins, k=k, distance_upper_bound=self._box_reach)
        idx = idx.reshape(len(origins), k)
        missing = idx >= self.n_boxes
        safe = np.where(missing, 0, idx)
        o = origins[:, None, :]
        inside = ~missing & ((self._lo[safe] <= o) & (o <= self._hi[safe])).all(axis=2)
        out = (inside * self._box_sigma[safe]).sum(axis=1)
        crowded = np.flatnonzero(~missing[:, -1]) if k < self.n_boxes else np.zeros(0, np.int64)
        for i, cand in zip(
            crowded, self._box_tree.query_ball_point(origins[crowded], self._box_reach), strict=True
        ):
            c = np.asarray(cand, np.int64)
            hit = ((self._lo[c] <= origins[i]) & (origins[i] <= self._hi[c])).all(axis=1)
            out[i] = self._box_sigma[c[hit]].sum()
        return out

    def transmittance(
        self, orig: np.ndarray, dirs: np.ndarray, end: np.ndarray, start_density: np.ndarray
    ) -> np.ndarray:
        """Visibility (r,) float32 in [0, 1] of segments ``orig + t dirs``, t in [0, end] (local units).

        orig, dirs : (r, 3) float32; end (r,) float; start_density (r,) density around each origin.
        """
        end = np.asarray(end, np.float64)
        if self.empty:
            return np.ones(len(orig), np.float32)
        optical = np.asarray(start_density, np.float64) * end
        trans = np.ones(len(orig), np.float32)
        # float32 views as given (Embree reads strided rays; a planar buffer's transpose is not copied)
        dirs = np.asarray(dirs, dtype=np.float32)
        for a, th, p in self._walk(np.asarray(orig, dtype=np.float32), dirs, end):
            box = self._is_box[p]
            ab, pb = a[box], p[box]
            entering = np.einsum("ij,ij->i", dirs[ab], self._normals[pb]) < 0
            # a ray crosses at most once per step of the walk: its indices are distinct, so plain fancy
            # updates add and multiply exactly as ufunc.at would, without its unbuffered loop
            optical[ab] += np.where(entering, 1.0, -1.0) * self._sigma[pb] * (end[ab] - th[box])
            trans[a[~box]] *= self._trans[p[~box]]
        # exp(-0) * trans is trans exactly: only rays through a medium take the exponential
        inside = np.flatnonzero(optical > 0.0)
        trans[inside] = np.exp(-optical[inside]) * trans[inside]
        return trans
