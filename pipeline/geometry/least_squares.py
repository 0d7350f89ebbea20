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
    interpolation_matrix,
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
    components (the level baker solves each block on its own)."""
    if not (math.isfinite(alpha) and alpha >= 0):
        raise NeuralaoError(f"alpha must be a finite number >= 0, got {alpha}")
    values = np.asarray(values, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(values).reshape(len(values), -1).all(axis=1)
    n = len(scene.vertices)
    b = interpolation_matrix(scene, samples)[valid]
    w = samples.weights[valid]
    total = w.sum() if whole is None else whole.weight
    w = w / total if total > 0 else w
    f = values[valid]
    bw = b.T.multiply(w).tocsr()  # (n, k) B^T W
    a = (bw @ b).tocsc()
    rhs = bw @ f
    if alpha > 0:
        edges, ew = edge_weights(scene, None if whole is None else whole.area)
        a = a + (alpha * REG_SCALE) * edge_laplacian(n, edges, ew)
    if whole is not None and whole.prior is not None:
        prior = np.asarray(whole.prior, np.float64)
    else:
        prior = np.average(f, weights=w, axis=0) if len(f) and w.sum() > 0 else np.ones(f.shape[1:])
    diag = a.diagonal()
    ridge = RIDGE_REL * (float(diag.max()) if diag.size and diag.max() > 0 else 1.0)
    a = (a + ridge * sp.identity(n, format="csc")).tocsc()
    rhs = rhs + ridge * prior
    return a, rhs


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


def solve_amg(a, rhs: np.ndarray) -> np.ndarray:
    """CG on the SPD normal equations with a smoothed-aggregation AMG preconditioner (one hierarchy for
    every column of ``rhs``)."""
    import pyamg  # imported here: ~1 s to import (measured), and only this solver needs it

    precond = pyamg.smoothed_aggregation_solver(a.tocsr(), symmetry="symmetric").aspreconditioner(cycle="V")
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
