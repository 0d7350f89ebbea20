"""Points on a triangle mesh's surface and per-vertex values read back at them.

Samples (:func:`surface_samples`): every face gets ``round(total * area share)`` samples, at least 1
and at most ``cap`` (Sloan et al. cap samples per face so a single huge face, a floor or a wall,
cannot eat the budget). Inside a face the k samples are a Hammersley set
``((i + s1) / k, frac(radinv(i) + s2))`` with a per-face random shift ``(s1, s2)``
(:mod:`neuralao.pipeline.geometry.sequences`), mapped area-preservingly to the triangle (square-root warp):
stratified, deterministic for a seed.

Interpolation (:func:`interpolate`, :func:`interpolation_matrix`): the barycentric blend of a face's
three corner values, exactly what a rasteriser shows inside the face. Error against a reference is
measured over surface samples (:func:`surface_error`), never at the vertices.

Edges (:func:`edge_weights`, :func:`edge_laplacian`): the unique mesh edges weighted by the area they
span, the regulariser of :mod:`neuralao.pipeline.geometry.least_squares`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from neuralao.pipeline.geometry.scene import Scene
from neuralao.pipeline.geometry.sequences import hammersley, sample_shifts
from neuralao.runtime.foundation.errors import NeuralaoError


@dataclass
class SurfaceSamples:
    """Points on the surface.

    face    : (k,) int64 face index
    bary    : (k, 3) float64 barycentric coordinates at the face's corners (sum 1)
    points  : (k, 3) float64 world positions
    normals : (k, 3) float64 unit geometric face normals
    weights : (k,) float64 area share (sums to 1 over all samples)
    """

    face: np.ndarray
    bary: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    weights: np.ndarray

    def __len__(self) -> int:
        return len(self.face)

    def __getitem__(self, index: slice | np.ndarray) -> SurfaceSamples:
        """The samples at ``index`` (a slice or indices), with their face numbers as they are."""
        return SurfaceSamples(
            self.face[index], self.bary[index], self.points[index], self.normals[index], self.weights[index]
        )


def face_areas(scene: Scene) -> np.ndarray:
    """(m,) float64 triangle areas."""
    return 0.5 * np.linalg.norm(scene.face_cross(), axis=1)


def samples_per_face(areas: np.ndarray, total: float, cap: int) -> np.ndarray:
    """(m,) int64 sample counts: round(total * area share), clipped to [1, cap]."""
    if cap < 1:
        raise NeuralaoError(f"samples_per_face_cap must be >= 1, got {cap}")
    share = areas / areas.sum()
    return np.clip(np.rint(total * share), 1, cap).astype(np.int64)


def surface_samples(
    scene: Scene,
    total: float,
    cap: int = 32,
    seed: int = 0,
    counts: np.ndarray | None = None,
    face_offset: int | np.ndarray = 0,
    area_total: float | None = None,
) -> SurfaceSamples:
    """Stratified area-proportional samples: ``total`` overall (about), 1..``cap`` per face.

    ``counts`` (m,) int overrides the per-face numbers (0 allowed). Deterministic for ``seed``.
    ``scene`` may be a piece of a bigger one: its faces are numbered from ``face_offset`` there, or
    ``face_offset`` (m,) int gives each face's number (faces picked anywhere in it); each face's random
    shifts follow its number. ``area_total`` is the area of the bigger scene's faces with samples (what
    the weights are shares of; default: this scene's).
    """
    areas = face_areas(scene)
    if counts is None:
        counts = samples_per_face(areas, total, cap)
    counts = np.asarray(counts, dtype=np.int64)
    face = np.repeat(np.arange(len(scene.faces), dtype=np.int64), counts)
    start = np.cumsum(counts) - counts
    index = np.arange(len(face), dtype=np.int64) - np.repeat(start, counts)  # index within the face
    numbers = np.asarray(face_offset)[face] if np.ndim(face_offset) else face + face_offset
    s1, s2 = sample_shifts(seed, numbers)  # one shift pair per face (for all its samples)
    k = counts[face].astype(np.float64)
    # radical inverse of the in-face index (Hammersley's second coordinate)
    _, radinv = hammersley(int(index.max()) + 1 if len(index) else 1)
    u1 = (index + s1) / k
    u2 = np.mod(radinv[index] + s2, 1.0)
    r = np.sqrt(u1)  # square-root warp: uniform by area over the triangle
    bary = np.stack([1.0 - r, r * (1.0 - u2), r * u2], axis=1)
    tri = scene.vertices[scene.faces[face]]
    points = np.einsum("kc,kcd->kd", bary, tri)
    norm = areas[counts > 0].sum() if area_total is None else area_total
    weights = (areas / np.maximum(counts, 1))[face] / norm
    return SurfaceSamples(face, bary, points, scene.face_normals[face], weights)


def samples_in_range(
    scene: Scene,
    ends: np.ndarray,
    lo: int,
    hi: int,
    seed: int,
    face_offset: int = 0,
    area_total: float | None = None,
) -> SurfaceSamples:
    """Samples ``lo`` .. ``hi`` of ``surface_samples(scene, counts=counts, seed=seed, ...)``, bit for bit,
    made from the faces they lie on alone (a task's block of a big surface's samples). ``ends`` (m,) int:
    the running sum of the per-face ``counts``; ``area_total`` as there (default: the area of the faces
    with samples, computed here over every face)."""
    if area_total is None:
        counts = np.diff(ends, prepend=0)
        area_total = float(face_areas(scene)[counts > 0].sum())
    first = int(np.searchsorted(ends, lo, side="right"))  # the face of sample lo
    last = int(np.searchsorted(ends, hi - 1, side="right")) + 1 if hi > lo else first
    before = int(ends[first - 1]) if first else 0
    part = surface_samples(
        Scene(scene.vertices, scene.faces[first:last], scene.name, scene.source),
        0,
        seed=seed,
        counts=np.diff(ends[first:last], prepend=before),
        face_offset=face_offset + first,
        area_total=area_total,
    )
    block = part[lo - before : hi - before]
    block.face = block.face + first  # numbered in ``scene``
    return block


def interpolation_matrix(scene: Scene, samples: SurfaceSamples):
    """B (k, n_vertices) scipy.sparse.csr_matrix: row s = barycentric weights of sample s."""
    k = len(samples)
    rows = np.repeat(np.arange(k), 3)
    cols = scene.faces[samples.face].reshape(-1)
    return sp.csr_matrix((samples.bary.reshape(-1), (rows, cols)), shape=(k, len(scene.vertices)))


def interpolate(scene: Scene, vertex_values: np.ndarray, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Values at surface points as the rasteriser shows them: (k,) float64
    = sum_c bary[:, c] v[face corner c]."""
    corners = np.asarray(vertex_values, dtype=np.float64)[scene.faces[face]]
    return np.einsum("kc,kc->k", bary, corners)


def edge_weights(scene: Scene, total: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges (e, 2) int64 and their area weights (e,) float64 summing to 1, or divided by
    ``total`` when ``scene`` is a piece of a bigger one (the bigger one's face area: its edges' weight)."""
    areas = face_areas(scene)
    f = scene.faces
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    w = np.tile(areas / 3.0, 3)
    e.sort(axis=1)
    keep = e[:, 0] != e[:, 1]
    e, w = e[keep], w[keep]
    # One int64 key per edge (i * n + j, i < j): the same order as unique rows, at 1-D sort speed
    # (unique(axis=0) sorts a structured view, 10x slower on a level's millions of edges).
    n = np.int64(max(len(scene.vertices), 1))
    keys, inverse = np.unique(e[:, 0] * n + e[:, 1], return_inverse=True)
    edges = np.stack([keys // n, keys % n], axis=1)
    weights = np.bincount(inverse.reshape(-1), weights=w, minlength=len(edges))
    total = weights.sum() if total is None else total
    return edges, (weights / total if total > 0 else weights)


def edge_laplacian(n: int, edges: np.ndarray, weights: np.ndarray):
    """L (n, n) csc: v^T L v = sum_e w_e (v_i - v_j)^2."""
    i, j = edges[:, 0], edges[:, 1]
    off = sp.coo_matrix(
        (np.concatenate([-weights, -weights]), (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(n, n)
    )
    deg = np.bincount(i, weights=weights, minlength=n) + np.bincount(j, weights=weights, minlength=n)
    return (off + sp.diags(deg)).tocsc()


def surface_error(
    scene: Scene, vertex_ao: np.ndarray, samples: SurfaceSamples, reference: np.ndarray, valid: np.ndarray
) -> dict:
    """Area-weighted error of interpolated vertex AO against ``reference`` at valid surface samples.

    Returns {"rmse", "mae", "max", "samples"} (floats / int).
    """
    pred = interpolate(scene, vertex_ao, samples.face, samples.bary)
    ref = np.asarray(reference, np.float64)
    m = np.asarray(valid, bool)
    if not m.any():
        raise NeuralaoError("no valid reference sample to measure the error on")
    w = samples.weights[m] / samples.weights[m].sum()
    d = pred[m] - ref[m]
    return {
        "rmse": float(np.sqrt(np.sum(w * d * d))),
        "mae": float(np.sum(w * np.abs(d))),
        "max": float(np.abs(d).max()),
        "samples": int(m.sum()),
    }


def vertex_colours(ao: np.ndarray) -> np.ndarray:
    """(n, 4) uint8 grey RGBA: round(255 ao), alpha 255."""
    g = np.rint(np.clip(np.asarray(ao, np.float64), 0.0, 1.0) * 255.0).astype(np.uint8)
    return np.stack([g, g, g, np.full_like(g, 255)], axis=1)


def vertex_components(faces: np.ndarray, n: int) -> np.ndarray:
    """(n,) int64: the connected component of each vertex of a mesh of ``n`` vertices and ``faces`` (f, 3)
    (vertices joined by a face are connected; a vertex in no face is a component of its own)."""
    e = np.asarray(faces, np.int64)[:, [0, 1, 1, 2]].reshape(-1, 2)
    graph = sp.csr_matrix((np.ones(len(e), bool), (e[:, 0], e[:, 1])), shape=(n, n))
    # weak components of the directed edges are the mesh's, without the symmetric copy of the graph that
    # directed=False makes: the same labels, less memory (the 10x world's terrain, 4.4M vertices, six runs:
    # 0.87-2.48 s, median 1.3, against 0.85-1.77 s, median 0.86)
    return connected_components(graph, directed=True, connection="weak")[1].astype(np.int64)
