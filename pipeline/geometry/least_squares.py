"""Least-squares vertex values from surface samples (Kavan, Bargteil, Sloan 2011, "Least Squares
Vertex Baking", as used for AO by Sloan, Tranchida, Chen, Kavan 2013).

Given surface samples ``s`` (:func:`neuralao.pipeline.geometry.surface.surface_samples`) with values ``f_s``,
the per-vertex values ``v`` minimise

    E(v) = sum_s w_s (B_s v - f_s)^2  +  alpha * REG_SCALE * sum_(i,j) m_ij (v_i - v_j)^2

* ``B`` (k, n): barycentric interpolation matrix, row s holds the barycentric coordinates of sample s
  at its face's three vertices, so ``B v`` is exactly what the rasteriser shows at the samples;
* ``w_s = area(face_s) / n_samples(face_s) / total_area``: area weights, so the data term is the
  area-weighted mean squared error over the surface: independent of the sample count and of the
  scene's scale (the integral of Kavan et al. divided by the total area);
* ``m_ij = sum over the faces sharing edge ij of area / (3 total_area)`` (the weights sum to 1 over
  all edges): the edge regulariser of Kavan et al. with each edge weighted by the surface it spans,
  so data and regulariser stiffness both scale with the local area and ``alpha`` means the same on
  coarse and fine meshes and at any scene scale (a plain unweighted edge sum would dominate on fine
  meshes and vanish on coarse ones);
* ``REG_SCALE`` = 0.01 (see the constant): with it ``alpha = 1`` is a mild regulariser, measured
  near the error minimum on held-out samples (bench/bench_bake.py sweeps alpha); it fixes vertices
  that no valid sample constrains and damps Monte-Carlo noise without blurring creases;
* invalid samples (for AO: the back-face rule of Sloan et al. 2013, more than 25% of a sample's rays
  hit back faces, i.e. it lies inside geometry) are left out of the data term;
* a ridge ``1e-9 * max(diag) * (v - prior)^2`` (prior: mean of the valid samples) makes the system
  positive definite when a connected component has no valid sample at all (e.g. a part sealed
  inside another): such vertices take the prior, everything else is unaffected.

The normal equations ``(B^T W B + alpha REG_SCALE L_m + ridge) v = B^T W f`` are sparse, symmetric
positive definite and solved directly (SuperLU via ``scipy.sparse.linalg.splu``), or iteratively
(:func:`solve_cg`, :func:`solve_amg`) for million-vertex levels; the result is clamped to [0, 1].

:func:`fill_invalid` is the harmonic fill of vertex samples: invalid vertices solve the area-weighted
graph Laplace equation with the valid ones fixed.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import cg, splu

from neuralao.pipeline.geometry.scene import Scene
from neuralao.pipeline.geometry.surface import (
    SurfaceSamples,
    edge_laplacian,
    edge_weights,
    face_areas,
)
from neuralao.runtime.foundation.errors import NeuralaoError

# Base scale of the edge regulariser (module doc). With area-weighted edges a vertex's regulariser
# stiffness is ~4x its data stiffness at alpha * REG_SCALE = 1 on a regular mesh; 0.01 makes
# alpha = 1 a light touch (~4% of the data stiffness). Chosen from the alpha sweep of
# bench/bench_bake.py (5 meshes, 128 rays): alpha = 1 has the lowest held-out RMSE or is within 0.1%
# of it on every mesh; alpha = 10 costs up to 12% (cornell_box), alpha = 100 20-100%.
REG_SCALE = 0.01
# Ridge towards the prior, relative to the largest diagonal entry: far below any data or
# regulariser stiffness (float64 solve), only there to remove the null space of empty components.
RIDGE_REL = 1e-9


@dataclass(frozen=True)
class Whole:
    """What the normal equations of a piece of a surface take from the whole surface: its valid samples'
    weight, its area and the weighted mean of its valid values (where a part without samples settles)."""

    weight: float
    area: float
    prior: Any = None


def normal_equations(
    scene: Scene,
    samples: SurfaceSamples,
    values: np.ndarray,
    valid: np.ndarray,
    alpha: float = 1.0,
    whole: Whole | None = None,
):
    """The normal equations of the module-doc energy, what :func:`fit_least_squares` solves:
    A (n, n) scipy.sparse csc, symmetric positive definite, and rhs (n,) or (n, c) float64.

    The valid samples' weights are divided by their sum, the edges' by the surface's area and the ridge
    pulls toward the samples' weighted mean; with ``whole`` (``scene`` is a piece of a bigger surface that
    shares no vertex with the rest) by the whole's: the piece's equations are then the whole's block.

    A couples only vertices that share a face, so it is block diagonal over the mesh's connected
    components (the level baker solves each block on its own). Made as one :func:`equation_share` of
    every sample and face, summed by :func:`sum_shares`."""
    if not (math.isfinite(alpha) and alpha >= 0):
        raise NeuralaoError(f"alpha must be a finite number >= 0, got {alpha}")
    values = np.asarray(values, dtype=np.float64)
    valid = usable(values, valid)
    prior = None if whole is None else whole.prior
    if prior is None:  # the samples' own weighted mean
        w, f = samples.weights[valid], _columns(values)[valid]
        prior = np.average(f, axis=0, weights=w) if len(f) and w.sum() > 0 else np.ones(f.shape[1:])
        prior = prior.reshape(values.shape[1:])
    if whole is None:
        whole = Whole(float(samples.weights[valid].sum()), float(face_areas(scene).sum()))
    share = equation_share(scene, samples, values, valid, alpha, whole, (0, len(scene.faces)))
    return sum_shares(len(scene.vertices), [share], prior)


def _columns(values: np.ndarray) -> np.ndarray:
    """(k, c) view of values (k,) or (k, c...), also for k = 0 (where reshape cannot infer c)."""
    return values.reshape(len(values), int(np.prod(values.shape[1:])))


def usable(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(k,) bool: the samples of the data term, valid and with every value finite."""
    values = np.asarray(values)
    return np.asarray(valid, dtype=bool) & np.isfinite(_columns(values)).all(axis=1)


def equation_share(
    scene: Scene,
    samples: SurfaceSamples,
    values: np.ndarray,
    valid: np.ndarray,
    alpha: float,
    whole: Whole,
    faces: tuple[int, int],
    compact: bool = False,
) -> dict[str, np.ndarray]:
    """A share of the normal equations of ``scene``: the data term of ``samples`` (any subset of its
    samples) and the regulariser of its faces ``faces`` = [first, stop). Shares of disjoint samples and
    face ranges covering them all add up (:func:`sum_shares`) to :func:`normal_equations`' A and rhs
    without the ridge, so a big surface's equations are made in parts, each a task. The weights are the
    ``whole``'s: valid samples' ``weight``, faces' ``area``.

    Per face, the samples' products w b_a b_b and w b_a f are summed first (one pass over the samples),
    then the face's nine entries go to its corners: A's entries are then as many as the faces, not the
    samples. Returns {"rows", "cols", "data"}: A's entries (duplicates to be added), {"rhs_rows",
    "rhs"}: (m,) vertices and their (m, c) right-hand sides. ``compact``: each entry and each vertex's
    right-hand side once (a share that travels: about a third of the entries of a mesh's faces)."""
    values = np.asarray(values, np.float64)
    keep = usable(values, valid)
    face = samples.face[keep]
    regularised = alpha > 0 and faces[1] > faces[0]
    # the faces of the samples and of the regularised range, as one span [lo, hi)
    spans = ([(int(faces[0]), int(faces[1]))] if regularised else []) + (
        [(int(face.min()), int(face.max()) + 1)] if len(face) else []
    )
    lo, hi = (min(a for a, _ in spans), max(b for _, b in spans)) if spans else (0, 0)
    k, r = _data_terms(samples, values, keep, face - lo, hi - lo, whole)
    used = np.bincount(face - lo, minlength=hi - lo) > 0
    if regularised:
        span = slice(int(faces[0]) - lo, int(faces[1]) - lo)
        _regularise(k, span, scene, slice(int(faces[0]), int(faces[1])), alpha, whole)
        used[span] = True
    hit = np.flatnonzero(used)
    corners = scene.faces[lo + hit].astype(np.int64)
    rows, cols, data = _entries(corners, k[hit])
    share = {
        "rows": rows,
        "cols": cols,
        "data": data,
        "rhs_rows": corners.reshape(-1),
        "rhs": r[:, :, hit].transpose(2, 0, 1).reshape(-1, r.shape[1]),
    }
    return _compacted(share) if compact else share


def _compacted(share: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``share`` with its duplicate entries and right-hand sides added (in their order), over the vertices
    it touches only; indices int32 where they fit."""
    vertices, local = np.unique(share["rhs_rows"], return_inverse=True)
    n = len(vertices)
    index = np.int32 if n == 0 or vertices[-1] < np.iinfo(np.int32).max else np.int64
    where = np.searchsorted(vertices, np.stack([share["rows"], share["cols"]]))
    a = sp.csr_matrix((share["data"], (where[0], where[1])), shape=(n, n))
    a.sum_duplicates()
    rhs = share["rhs"]
    return {
        "rows": vertices[np.repeat(np.arange(n), np.diff(a.indptr))].astype(index),
        "cols": vertices[a.indices].astype(index),
        "data": a.data,
        "rhs_rows": vertices.astype(index),
        "rhs": np.stack([np.bincount(local, weights=rhs[:, j], minlength=n) for j in range(rhs.shape[1])], 1),
    }


# The six entries of a face's symmetric 3x3 block: its diagonal, then (0, 1), (1, 2), (2, 0).
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0))


def _data_terms(
    samples: SurfaceSamples, values: np.ndarray, keep: np.ndarray, local: np.ndarray, m: int, whole
):
    """Per face of m, the data term of the ``keep`` samples (their faces ``local`` (k,) in 0..m-1): the
    symmetric 3x3 block's six entries (m, 6) float64 in :data:`_PAIRS` order, and each corner's right-hand
    sides (3, c, m). Each face's sums run over its samples in their order (one ``np.bincount`` pass), so a
    face's terms are the same bits whichever other faces are summed with it."""
    bary = samples.bary[keep]
    w = samples.weights[keep] / whole.weight if whole.weight > 0 else samples.weights[keep]
    f = _columns(values)[keep]

    def per_face(x: np.ndarray) -> np.ndarray:
        return np.bincount(local, weights=x, minlength=m).astype(np.float64, copy=False)

    k = np.stack([per_face(w * bary[:, a] * bary[:, b]) for a, b in _PAIRS], 1)
    r = np.stack([[per_face(w * bary[:, a] * col) for col in f.T] for a in range(3)]).reshape(
        3, f.shape[1], m
    )
    return k, r


def _regularise(k: np.ndarray, rows, scene: Scene, faces, alpha: float, whole) -> None:
    """Add to ``k[rows]`` (the six entries of each of ``faces``: face numbers of ``scene``, an array or a
    slice) the edge regulariser: every edge of a face gets a third of its area, +e twice on each corner's
    diagonal, -e off it."""
    e = (alpha * REG_SCALE / 3.0) * face_areas(Scene(scene.vertices, scene.faces[faces]))
    e = e / whole.area if whole.area > 0 else e
    k[rows, :3] += 2.0 * e[:, None]
    k[rows, 3:] -= e[:, None]


def _entries(corners: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nine matrix entries (rows, cols, data) of each face (corners (m, 3), blocks k (m, 6)), face by
    face."""
    return (
        corners[:, [0, 1, 2, 0, 1, 1, 2, 2, 0]].reshape(-1),
        corners[:, [0, 1, 2, 1, 0, 2, 1, 0, 2]].reshape(-1),
        k[:, [0, 1, 2, 3, 3, 4, 4, 5, 5]].reshape(-1),
    )


def touching_faces(faces: np.ndarray, vertices: np.ndarray, n: int) -> np.ndarray:
    """(m,) int64 ascending: the faces of ``faces`` (f, 3) into n vertices with a corner in ``vertices``."""
    inside = np.zeros(n, bool)
    inside[vertices] = True
    return np.flatnonzero(inside[faces[:, 0]] | inside[faces[:, 1]] | inside[faces[:, 2]])


def vertex_equations(
    scene: Scene,
    faces: np.ndarray,
    samples: SurfaceSamples,
    values: np.ndarray,
    valid: np.ndarray,
    alpha: float,
    whole: Whole,
    vertices: np.ndarray,
) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
    """The rows of ``vertices`` ((p,) int64 ascending) of the normal equations of ``scene`` (a piece of a
    surface of weights ``whole``: :func:`normal_equations`' A and rhs without the ridge), made from the faces
    touching them alone: ``faces`` (m,) ascending, every face with a corner among ``vertices``
    (:func:`touching_faces`); ``samples`` every sample on those faces, in the surface's sample order (their
    ``face`` numbered in ``scene``), with their ``values`` (k,) or (k, c) and ``valid``.

    Returns (columns (e,) int64 ascending: ``vertices`` and every vertex sharing a face with one, rows
    (p, e) csr over those columns with every diagonal entry stored, rhs (p, c) float64). A row is the same
    bits whichever vertices it is asked with: each face's terms are summed over its own samples
    (:func:`_data_terms`), a diagonal entry adds its faces' terms in face order, and an entry off it the
    terms of the faces of its pair of vertices in face order (the same value in both of their rows: the
    rows are exactly symmetric). What a subdomain of a partitioned solve assembles where it runs, instead of
    cutting rows from the whole matrix."""
    values = np.asarray(values, np.float64)
    faces = np.asarray(faces, np.int64)
    vertices = np.asarray(vertices, np.int64)
    keep = usable(values, valid)
    local = np.searchsorted(faces, samples.face[keep])
    if len(local) and (local.max() >= len(faces) or (faces[local] != samples.face[keep]).any()):
        raise NeuralaoError("vertex_equations: a sample lies on a face that touches none of the vertices")
    k, r = _data_terms(samples, values, keep, local, len(faces), whole)
    if alpha > 0:
        _regularise(k, slice(None), scene, faces, alpha, whole)
    corners = scene.faces[faces].astype(np.int64)
    n = len(scene.vertices)
    # positions of the vertices among the rows and among the columns, by lookup (no sort of the entries)
    row_of = np.full(n, -1, np.int64)
    row_of[vertices] = np.arange(len(vertices))
    used = np.zeros(n, bool)
    used[vertices] = True
    used[corners.reshape(-1)] = True
    columns = np.flatnonzero(used)
    col_of = np.full(n, -1, np.int64)
    col_of[columns] = np.arange(len(columns))
    # each face's three pairs of corners (0-1, 1-2, 2-0) and their term; a pair on one vertex (a degenerate
    # face) is that vertex's twice, like the block's two entries off its diagonal
    first, second, term = corners.reshape(-1), corners[:, [1, 2, 0]].reshape(-1), k[:, 3:].reshape(-1)
    same = first == second
    # the diagonal: the corners' own terms in face order, then those of the pairs on one vertex
    mine = np.concatenate([first, first[same], first[same]])
    terms = np.concatenate([k[:, :3].reshape(-1), term[same], term[same]])
    held = row_of[mine] >= 0
    diagonal = np.bincount(row_of[mine[held]], weights=terms[held], minlength=len(vertices))
    # off it: each pair of vertices summed once, over its faces in face order, then entered in both rows
    lo, hi = np.minimum(first, second), np.maximum(first, second)
    off = ~same & ((row_of[lo] >= 0) | (row_of[hi] >= 0))
    e = max(len(columns), 1)
    pair, inverse = np.unique(col_of[lo[off]] * e + col_of[hi[off]], return_inverse=True)
    summed = np.bincount(inverse, weights=term[off], minlength=len(pair))
    lo, hi = pair // e, pair % e  # positions in columns, lo < hi
    r_lo, r_hi = row_of[columns[lo]], row_of[columns[hi]]
    a = sp.coo_matrix(
        (
            np.concatenate([summed[r_lo >= 0], summed[r_hi >= 0], diagonal]),
            (
                np.concatenate([r_lo[r_lo >= 0], r_hi[r_hi >= 0], np.arange(len(vertices))]),
                np.concatenate([hi[r_lo >= 0], lo[r_hi >= 0], col_of[vertices]]),
            ),
        ),
        shape=(len(vertices), len(columns)),
    ).tocsr()  # each (row, column) once: nothing added
    at = row_of[corners.reshape(-1)]
    on = at >= 0
    rv = r.transpose(2, 0, 1).reshape(-1, r.shape[1])[on]
    rhs = np.stack(
        [np.bincount(at[on], weights=rv[:, j], minlength=len(vertices)) for j in range(rv.shape[1])], 1
    )
    return columns, a, rhs.astype(np.float64, copy=False)


def sum_shares(n: int, shares: list[dict[str, np.ndarray]], prior) -> tuple:
    """A (n, n) csc and rhs (n,) or (n, c) of the normal equations from the :func:`equation_share` results
    (added in list order: the same shares give the same bytes), with the ridge toward ``prior`` (the
    whole surface's weighted mean value: a scalar or (c,))."""
    prior = np.asarray(prior, np.float64)
    rows = np.concatenate([s["rows"] for s in shares])
    cols = np.concatenate([s["cols"] for s in shares])
    data = np.concatenate([s["data"] for s in shares])
    a = sp.csc_matrix((data, (rows, cols)), shape=(n, n))
    a.sum_duplicates()
    rr = np.concatenate([s["rhs_rows"] for s in shares])
    rv = np.concatenate([s["rhs"].reshape(len(s["rhs"]), -1) for s in shares])
    rhs = np.stack([np.bincount(rr, weights=rv[:, j], minlength=n) for j in range(rv.shape[1])], 1)
    a, rhs = with_ridge(a, rhs, prior)
    return a, rhs.reshape((n,) + prior.shape)


def ridge_of(largest_diagonal: float) -> float:
    """The module-doc ridge of a system whose largest diagonal entry is ``largest_diagonal``: RIDGE_REL times
    it (times 1 when it is not positive)."""
    return RIDGE_REL * (float(largest_diagonal) if largest_diagonal > 0 else 1.0)


def with_ridge(a, rhs: np.ndarray, prior, ridge: float | None = None) -> tuple:
    """A (n, n) sparse and rhs (n, c) with the module-doc ridge toward ``prior`` (a scalar or (c,)):
    ``ridge``, or None: :func:`ridge_of` A's largest diagonal entry. Returns (A csc, rhs (n, c) float64)."""
    if ridge is None:
        diag = a.diagonal()
        ridge = ridge_of(float(diag.max()) if diag.size else 0.0)
    a = (a + ridge * sp.identity(a.shape[0], format="csc")).tocsc()
    return a, rhs + ridge * np.asarray(prior, np.float64).reshape(1, -1)


def fit_least_squares(
    scene: Scene,
    samples: SurfaceSamples,
    values: np.ndarray,
    valid: np.ndarray,
    alpha: float = 1.0,
    solver: Literal["direct", "cg", "amg"] = "direct",
    whole: Whole | None = None,
) -> np.ndarray:
    """Per-vertex values (n,) float32 in [0, 1] minimising the module-doc energy.

    values : (k,) sample AO, or (k, c) for c signals fitted with one factorisation (the level
    baker's two obscurance distances; result (n, c)); valid : (k,) bool, invalid samples are left
    out entirely. ``solver="cg"``: Jacobi-preconditioned conjugate gradients (relative residual
    1e-10) instead of SuperLU, for million-vertex levels where the direct factor's fill-in costs
    more memory and time than the well-conditioned system needs. ``solver="amg"``: conjugate gradients
    preconditioned by a smoothed-aggregation multigrid V-cycle (pyamg; relative residual 1e-10): linear
    in the vertex count, where Jacobi CG needs thousands of iterations on a level's regulariser.
    """
    a, rhs = normal_equations(scene, samples, values, valid, alpha, whole)
    if solver == "direct":
        v = splu(a).solve(rhs)
    elif solver == "cg":
        v = solve_cg(a, rhs)
    elif solver == "amg":
        v = solve_amg(a, rhs)
    else:
        raise NeuralaoError(f"solver must be 'direct', 'cg' or 'amg', got {solver!r}")
    return np.clip(v, 0.0, 1.0).astype(np.float32)


def solve_cg(a, rhs: np.ndarray) -> np.ndarray:
    """Jacobi-preconditioned CG on the SPD normal equations, one column of ``rhs`` at a time."""
    precond = sp.diags(1.0 / a.diagonal())
    cols = rhs.reshape(len(rhs), -1)
    out = np.empty_like(cols)
    for j in range(cols.shape[1]):
        out[:, j], info = cg(a, cols[:, j], rtol=1e-10, atol=0.0, maxiter=10000, M=precond)
        if info != 0:
            raise NeuralaoError(f"least-squares CG did not converge ({info} iterations)")
    return out.reshape(rhs.shape)


# pyamg's hierarchy estimates spectral radii from numpy's global random stream (an unseeded start vector):
# one hierarchy is built at a time, from a fixed seed, and the stream is given back as it was.
_AMG_LOCK = threading.Lock()
_AMG_SEED = 0


def solve_amg(a, rhs: np.ndarray) -> np.ndarray:
    """CG on the SPD normal equations with a smoothed-aggregation AMG preconditioner (one hierarchy for
    every column of ``rhs``). The same system gives the same bytes: the hierarchy's random start vectors
    come from a fixed seed."""
    import pyamg  # imported here: ~1 s to import (measured), and only this solver needs it

    with _AMG_LOCK:
        state = np.random.get_state()
        np.random.seed(_AMG_SEED)
        try:
            hierarchy = pyamg.smoothed_aggregation_solver(a.tocsr(), symmetry="symmetric")
        finally:
            np.random.set_state(state)
    precond = hierarchy.aspreconditioner(cycle="V")
    cols = rhs.reshape(len(rhs), -1)
    out = np.empty_like(cols)
    for j in range(cols.shape[1]):
        out[:, j], info = cg(a, cols[:, j], rtol=1e-10, atol=0.0, maxiter=1000, M=precond)
        if info != 0:
            raise NeuralaoError(f"least-squares AMG-preconditioned CG did not converge ({info} iterations)")
    return out.reshape(rhs.shape)


def fill_invalid(scene: Scene, values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Harmonic fill: invalid vertices solve the area-weighted graph Laplace equation with the valid
    vertices fixed (a component without any valid vertex takes the mean of the valid ones).

    values : (n,) float, valid : (n,) bool -> (n,) float32.
    """
    values = np.asarray(values, dtype=np.float64).copy()
    valid = np.asarray(valid, dtype=bool)
    unknown = np.flatnonzero(~valid)
    if len(unknown) == 0:
        return values.astype(np.float32)
    prior = float(values[valid].mean()) if valid.any() else 1.0
    edges, ew = edge_weights(scene)
    lap = edge_laplacian(len(values), edges, ew).tocsr()
    known = np.flatnonzero(valid)
    l_uu = lap[unknown][:, unknown].tocsc()
    rhs = -(lap[unknown][:, known] @ values[known])
    ridge = RIDGE_REL * (float(l_uu.diagonal().max()) if l_uu.nnz else 1.0)
    l_uu = l_uu + ridge * sp.identity(len(unknown), format="csc")
    values[unknown] = splu(l_uu.tocsc()).solve(rhs + ridge * prior)
    return np.clip(values, 0.0, 1.0).astype(np.float32)
