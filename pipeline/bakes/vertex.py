"""`neuralao bake`: per-vertex AO, by sampling at vertices or by least-squares fitting of surface samples.

Methods
-------
``vertex``: one AO sample per vertex at the vertex position along its area-weighted vertex normal.
Cheap, but what the renderer shows inside a face is the *linear interpolation* of those corner values,
and a vertex value is the AO of one point, not the best value for the faces around it: a coarse floor
vertex at a contact line is dark and its darkness is smeared across every face that touches it.
Vertices whose sample is invalid (back-face rule) are filled harmonically from their valid
neighbours (Dirichlet problem on the mesh graph).

``least-squares`` (Kavan, Bargteil, Sloan 2011, "Least Squares Vertex Baking", as used for AO by
Sloan, Tranchida, Chen, Kavan 2013): stratified surface samples ``s`` spread by area, each with the
AO ``f_s`` traced along its face's geometric normal; the per-vertex values ``v`` minimise

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
* samples invalidated by the back-face rule (Sloan et al. 2013: more than 25% of a sample's rays hit
  back faces, i.e. it lies inside geometry) are left out of the data term;
* a ridge ``1e-9 * max(diag) * (v - prior)^2`` (prior: mean of the valid samples) makes the system
  positive definite when a connected component has no valid sample at all (e.g. a part sealed
  inside another): such vertices take the prior, everything else is unaffected.

The normal equations ``(B^T W B + alpha REG_SCALE L_m + ridge) v = B^T W f`` are sparse, symmetric
positive definite and solved directly (SuperLU via ``scipy.sparse.linalg.splu``); the result is
clamped to [0, 1].

Samples: every face gets ``round(density * area)`` samples, at least 1 and at most
``samples_per_face_cap`` (Sloan et al. cap samples per face so a single huge face, a floor or a
wall, cannot eat the budget), with ``density = samples_per_vertex * n_vertices / total_area``.
Inside a face the k samples are a Hammersley set ``((i + s1) / k, frac(radinv(i) + s2))`` with a
per-face random shift ``(s1, s2)``, mapped area-preservingly to the triangle (square-root warp):
stratified, deterministic for a seed.

Output (PLY or GLB): the scene's vertices and faces as loaded (glTF nodes flattened), per-vertex
colour = grey ``round(255 * ao)`` (RGBA8, alpha 255) AND the exact float32 value:

* PLY: a custom vertex property ``property float ao`` (trimesh's PLY exporter writes
  ``vertex_attributes`` as extra vertex properties, and its loader reads them back);
* GLB: glTF 2.0 allows application-specific vertex attributes only with a leading underscore, so
  the float is the attribute ``_AO`` (FLOAT SCALAR accessor), beside ``COLOR_0``.

Error against a reference is measured over surface samples (:func:`surface_error`), never at the
vertices (where vertex sampling is exact by construction).
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from pipeline.foundation.errors import NeuralaoError
from pipeline.foundation.io import atomic_path
from pipeline.foundation.limits import MAX_CAP, SAMPLE_BYTES, check_count, check_int_range, check_seed
from pipeline.foundation.settings import settings_to_dict
from pipeline.geometry.scene import Scene, load_scene
from pipeline.tracing.labeller import Labeller, LabelSettings, check_label_args, hammersley, sample_shifts

log = logging.getLogger(__name__)

# Base scale of the edge regulariser (module doc). With area-weighted edges a vertex's regulariser
# stiffness is ~4x its data stiffness at alpha * REG_SCALE = 1 on a regular mesh; 0.01 makes
# alpha = 1 a light touch (~4% of the data stiffness). Chosen from the alpha sweep of
# bench/bench_bake.py (5 meshes, 128 rays): alpha = 1 has the lowest held-out RMSE or is within 0.1%
# of it on every mesh; alpha = 10 costs up to 12% (cornell_box), alpha = 100 20-100%.
REG_SCALE = 0.01
# Ridge towards the prior, relative to the largest diagonal entry: far below any data or
# regulariser stiffness (float64 solve), only there to remove the null space of empty components.
RIDGE_REL = 1e-9
OUTPUT_SUFFIXES = (".ply", ".glb")
GLB_AO_ATTRIBUTE = "_AO"


@dataclass
class BakeSettings:
    # Rays per sample (cosine-weighted hemisphere, as the labeller).
    rays: int = 256
    # Longest AO ray in scene units; None -> max_distance_rel * diagonal (the labels' default).
    max_distance: float | None = None
    # Default max distance as a fraction of the bounding-box diagonal.
    max_distance_rel: float = 0.25
    # "binary" or "obscurance" (Sloan et al. 2013 rho(d)).
    kernel: Literal["binary", "obscurance"] = "binary"
    # Obscurance half distance, scene units; None -> half_distance_rel * diagonal.
    half_distance: float | None = None
    # Default half distance as a fraction of the diagonal.
    half_distance_rel: float = 0.05
    # "vertex": sample at vertices; "least-squares": fit vertex values to surface samples.
    method: Literal["vertex", "least-squares"] = "least-squares"
    # Weight of the edge regulariser (least-squares), in units of REG_SCALE.
    alpha: float = 1.0
    # Surface sample budget (least-squares) in samples per vertex, spread over faces by area.
    samples_per_vertex: float = 8.0
    # At most this many samples on one face (least-squares; every face gets at least one).
    samples_per_face_cap: int = 32
    # Back-face rule threshold (Sloan et al.: 0.25); None disables it.
    backface_threshold: float | None = 0.25
    # Seed of the sample positions and ray directions.
    seed: int = 0
    # Tracing threads.
    workers: int = 2

    def label_settings(self) -> LabelSettings:
        return LabelSettings(
            rays=self.rays,
            max_distance=self.max_distance,
            max_distance_rel=self.max_distance_rel,
            kernel=self.kernel,
            half_distance=self.half_distance,
            half_distance_rel=self.half_distance_rel,
            backface_threshold=self.backface_threshold,
            seed=self.seed,
            workers=self.workers,
        )


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


@dataclass
class BakeResult:
    """ao (n_vertices,) float32 in [0, 1]; info: counts, timings, settings."""

    ao: np.ndarray
    info: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- geometry helpers


def face_areas(scene: Scene) -> np.ndarray:
    """(m,) float64 triangle areas."""
    t = scene.triangles
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


def samples_per_face(areas: np.ndarray, total: float, cap: int) -> np.ndarray:
    """(m,) int64 sample counts: round(total * area share), clipped to [1, cap]."""
    if cap < 1:
        raise NeuralaoError(f"samples_per_face_cap must be >= 1, got {cap}")
    share = areas / areas.sum()
    return np.clip(np.rint(total * share), 1, cap).astype(np.int64)


def surface_samples(
    scene: Scene, total: float, cap: int = 32, seed: int = 0, counts: np.ndarray | None = None
) -> SurfaceSamples:
    """Stratified area-proportional samples: ``total`` overall (about), 1..``cap`` per face.

    ``counts`` (m,) int overrides the per-face numbers (0 allowed). Deterministic for ``seed``.
    """
    areas = face_areas(scene)
    if counts is None:
        counts = samples_per_face(areas, total, cap)
    counts = np.asarray(counts, dtype=np.int64)
    face = np.repeat(np.arange(len(scene.faces), dtype=np.int64), counts)
    start = np.cumsum(counts) - counts
    index = np.arange(len(face), dtype=np.int64) - np.repeat(start, counts)  # index within the face
    s1, s2 = sample_shifts(seed, face)  # one shift pair per face (same id for all its samples)
    k = counts[face].astype(np.float64)
    # radical inverse of the in-face index (Hammersley's second coordinate)
    _, radinv = hammersley(int(index.max()) + 1 if len(index) else 1)
    u1 = (index + s1) / k
    u2 = np.mod(radinv[index] + s2, 1.0)
    r = np.sqrt(u1)  # square-root warp: uniform by area over the triangle
    bary = np.stack([1.0 - r, r * (1.0 - u2), r * u2], axis=1)
    tri = scene.triangles[face]
    points = np.einsum("kc,kcd->kd", bary, tri)
    weights = (areas / np.maximum(counts, 1))[face] / areas[counts > 0].sum()
    return SurfaceSamples(face, bary, points, scene.face_normals[face], weights)


def interpolation_matrix(scene: Scene, samples: SurfaceSamples):
    """B (k, n_vertices) scipy.sparse.csr_matrix: row s = barycentric weights of sample s."""
    import scipy.sparse as sp

    k = len(samples)
    rows = np.repeat(np.arange(k), 3)
    cols = scene.faces[samples.face].reshape(-1)
    return sp.csr_matrix((samples.bary.reshape(-1), (rows, cols)), shape=(k, len(scene.vertices)))


def interpolate(scene: Scene, vertex_values: np.ndarray, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Values at surface points as the rasteriser shows them: (k,) float64 = sum_c bary[:, c] v[face corner c]."""
    corners = np.asarray(vertex_values, dtype=np.float64)[scene.faces[face]]
    return np.einsum("kc,kc->k", bary, corners)


def edge_weights(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges (e, 2) int64 and their area weights (e,) float64 summing to 1."""
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
    total = weights.sum()
    return edges, (weights / total if total > 0 else weights)


def edge_laplacian(n: int, edges: np.ndarray, weights: np.ndarray):
    """L (n, n) csc: v^T L v = sum_e w_e (v_i - v_j)^2."""
    import scipy.sparse as sp

    i, j = edges[:, 0], edges[:, 1]
    off = sp.coo_matrix(
        (np.concatenate([-weights, -weights]), (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(n, n)
    )
    deg = np.bincount(i, weights=weights, minlength=n) + np.bincount(j, weights=weights, minlength=n)
    return (off + sp.diags(deg)).tocsc()


# --------------------------------------------------------------------------- fitting


def normal_equations(
    scene: Scene, samples: SurfaceSamples, values: np.ndarray, valid: np.ndarray, alpha: float = 1.0
):
    """The normal equations of the module-doc energy, what :func:`fit_least_squares` solves:
    A (n, n) scipy.sparse csc, symmetric positive definite, and rhs (n,) or (n, c) float64.

    A couples only vertices that share a face, so it is block diagonal over the mesh's connected
    components (the level baker solves each block on its own)."""
    import scipy.sparse as sp

    if not (math.isfinite(alpha) and alpha >= 0):
        raise NeuralaoError(f"alpha must be a finite number >= 0, got {alpha}")
    values = np.asarray(values, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(values).reshape(len(values), -1).all(axis=1)
    n = len(scene.vertices)
    b = interpolation_matrix(scene, samples)[valid]
    w = samples.weights[valid]
    w = w / w.sum() if w.sum() > 0 else w
    f = values[valid]
    bw = b.T.multiply(w).tocsr()  # (n, k) B^T W
    a = (bw @ b).tocsc()
    rhs = bw @ f
    if alpha > 0:
        edges, ew = edge_weights(scene)
        a = a + (alpha * REG_SCALE) * edge_laplacian(n, edges, ew)
    prior = np.average(f, weights=w, axis=0) if len(f) else np.ones(f.shape[1:])
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
    from scipy.sparse.linalg import splu

    a, rhs = normal_equations(scene, samples, values, valid, alpha)
    if solver == "direct":
        v = splu(a).solve(rhs)
    elif solver == "cg":
        v = _solve_cg(a, rhs)
    elif solver == "amg":
        v = _solve_amg(a, rhs)
    else:
        raise NeuralaoError(f"solver must be 'direct', 'cg' or 'amg', got {solver!r}")
    return np.clip(v, 0.0, 1.0).astype(np.float32)


def _solve_cg(a, rhs: np.ndarray) -> np.ndarray:
    """Jacobi-preconditioned CG on the SPD normal equations, one column of ``rhs`` at a time."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import cg

    precond = sp.diags(1.0 / a.diagonal())
    cols = rhs.reshape(len(rhs), -1)
    out = np.empty_like(cols)
    for j in range(cols.shape[1]):
        out[:, j], info = cg(a, cols[:, j], rtol=1e-10, atol=0.0, maxiter=10000, M=precond)
        if info != 0:
            raise NeuralaoError(f"least-squares CG did not converge ({info} iterations)")
    return out.reshape(rhs.shape)


def _solve_amg(a, rhs: np.ndarray) -> np.ndarray:
    """CG on the SPD normal equations with a smoothed-aggregation AMG preconditioner (one hierarchy for
    every column of ``rhs``)."""
    import pyamg
    from scipy.sparse.linalg import cg

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
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

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


# --------------------------------------------------------------------------- baking


def bake_vertex(scene: Scene, labeller: Labeller, progress: bool = False) -> BakeResult:
    """AO sampled at every vertex along its vertex normal; invalid vertices filled from neighbours."""
    t0 = time.perf_counter()
    ao, valid = labeller.ao_at_points(scene.vertices, scene.vertex_normals, progress=progress)
    t_trace = time.perf_counter() - t0
    # Vertices no face uses are invisible; keep them out of the fill (their value is irrelevant).
    used = np.zeros(len(scene.vertices), bool)
    used[scene.faces.reshape(-1)] = True
    out = fill_invalid(scene, ao, valid | ~used)
    info = {
        "method": "vertex",
        "samples": int(len(ao)),
        "invalid_samples": int((~valid & used).sum()),
        "rays_traced": int(len(ao)) * labeller.settings.rays,
        "seconds_trace": t_trace,
        "seconds_solve": time.perf_counter() - t0 - t_trace,
    }
    return BakeResult(out, info)


def bake_least_squares(
    scene: Scene, labeller: Labeller, settings: BakeSettings, progress: bool = False
) -> BakeResult:
    """Least-squares vertex baking of stratified surface samples (module doc)."""
    t0 = time.perf_counter()
    total = settings.samples_per_vertex * len(scene.vertices)
    # The samples' arrays are allocated before anything else: their number must fit (pipeline.foundation.limits).
    check_count("--samples-per-vertex", math.ceil(min(total, 2.0**62)) + len(scene.faces), bytes_each=SAMPLE_BYTES,
                each="per surface sample", shown=f"{settings.samples_per_vertex:g} on {len(scene.vertices)} vertices")  # fmt: skip
    samples = surface_samples(scene, total, settings.samples_per_face_cap, settings.seed)
    t1 = time.perf_counter()
    ao, valid = labeller.ao_at_points(samples.points, samples.normals, progress=progress)
    t2 = time.perf_counter()
    out = fit_least_squares(scene, samples, ao, valid, settings.alpha)
    t3 = time.perf_counter()
    info = {
        "method": "least-squares",
        "samples": int(len(samples)),
        "invalid_samples": int((~valid).sum()),
        "rays_traced": int(len(samples)) * labeller.settings.rays,
        "seconds_sampling": t1 - t0,
        "seconds_trace": t2 - t1,
        "seconds_solve": t3 - t2,
    }
    return BakeResult(out, info)


def check_settings(settings: BakeSettings) -> None:
    if settings.method not in ("vertex", "least-squares"):
        raise NeuralaoError(f"method must be 'vertex' or 'least-squares', got {settings.method!r}")
    if not (math.isfinite(settings.alpha) and settings.alpha >= 0):
        raise NeuralaoError(f"--alpha must be a finite number >= 0, got {settings.alpha}")
    check_int_range("--samples-per-face-cap", settings.samples_per_face_cap, 1, MAX_CAP)
    if not (math.isfinite(settings.samples_per_vertex) and settings.samples_per_vertex > 0):
        raise NeuralaoError(f"--samples-per-vertex must be > 0, got {settings.samples_per_vertex}")
    check_seed("--seed", settings.seed)


def bake(
    scene: Scene, settings: BakeSettings | None = None, progress: bool = False, engine=None, store=None
) -> BakeResult:
    """Per-vertex AO of ``scene``: BakeResult.ao (n_vertices,) float32 in [0, 1].

    ``engine`` (:mod:`pipeline.engines.engine`, e.g. a RayEngine): trace the samples as chunk tasks on it
    (bit-identical result; ``store`` keeps finished chunks for a rerun); None: threads here.
    """
    settings = settings or BakeSettings()
    check_settings(settings)
    t0 = time.perf_counter()
    if engine is None:
        labeller = Labeller(scene, settings.label_settings())
    else:
        from pipeline.engines.engine import EngineLabeller

        labeller = EngineLabeller(scene, settings.label_settings(), engine, store)
    if settings.method == "vertex":
        result = bake_vertex(scene, labeller, progress)
    else:
        result = bake_least_squares(scene, labeller, settings, progress)
    result.info.update(
        seconds=time.perf_counter() - t0,
        vertices=int(len(scene.vertices)),
        faces=int(len(scene.faces)),
        max_distance=labeller.max_distance,
        settings=settings_to_dict(settings),
    )
    return result


# --------------------------------------------------------------------------- evaluation


def reference_at_samples(
    scene: Scene, samples: SurfaceSamples, settings: BakeSettings, rays: int = 1024, seed: int = 12345
) -> tuple[np.ndarray, np.ndarray]:
    """High-ray reference AO (k,) float32 and valid (k,) bool at ``samples`` (same kernel/distances)."""
    labeller = Labeller(scene, replace(settings.label_settings(), rays=rays, seed=seed))
    return labeller.ao_at_points(samples.points, samples.normals)


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


# --------------------------------------------------------------------------- files


def vertex_colours(ao: np.ndarray) -> np.ndarray:
    """(n, 4) uint8 grey RGBA: round(255 ao), alpha 255."""
    g = np.rint(np.clip(np.asarray(ao, np.float64), 0.0, 1.0) * 255.0).astype(np.uint8)
    return np.stack([g, g, g, np.full_like(g, 255)], axis=1)


def write_baked_mesh(path: str | Path, scene: Scene, ao: np.ndarray) -> Path:
    """Write ``scene`` with per-vertex AO (colours + float32 property, module doc) to .ply or .glb, atomically."""
    import trimesh

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise NeuralaoError(f"--out must end in .ply or .glb, got {path.name!r}")
    ao = np.asarray(ao, dtype=np.float32)
    if ao.shape != (len(scene.vertices),):
        raise NeuralaoError(f"ao must have one value per vertex ({len(scene.vertices)}), got {ao.shape}")
    mesh = trimesh.Trimesh(
        vertices=np.asarray(scene.vertices, np.float64),
        faces=np.asarray(scene.faces, np.int64),
        vertex_colors=vertex_colours(ao),
        process=False,
        validate=False,
    )
    key = "ao" if suffix == ".ply" else GLB_AO_ATTRIBUTE
    mesh.vertex_attributes[key] = ao
    data = mesh.export(file_type=suffix[1:])
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def read_baked_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read a baked .ply/.glb: vertices (n, 3) f64, faces (m, 3) i64, ao (n,) float32, colours (n, 4) uint8."""
    import trimesh

    path = Path(path)
    if path.is_file() and path.stat().st_size == 0:
        raise NeuralaoError(f"{path} is empty: it has no geometry")
    try:
        loaded = trimesh.load(str(path), process=False)
    except Exception as e:
        first = str(e).splitlines()[0][:200] if str(e) else ""
        raise NeuralaoError(f"cannot read {path}: {type(e).__name__}: {first}") from None
    if isinstance(loaded, trimesh.Scene):
        geoms = list(loaded.geometry.values())
        if not geoms:
            raise NeuralaoError(f"{path} has no geometry (no mesh in the file)")
        if len(geoms) != 1:
            raise NeuralaoError(f"{path} holds {len(geoms)} meshes, expected one")
        loaded = geoms[0]
    attrs = dict(loaded.vertex_attributes)
    # trimesh's PLY loader keeps extra vertex properties only in its raw element table.
    raw = loaded.metadata.get("_ply_raw", {}).get("vertex", {}).get("data")
    if raw is not None and raw.dtype.names and "ao" in raw.dtype.names:
        attrs["ao"] = raw["ao"]
    key = next((k for k in ("ao", GLB_AO_ATTRIBUTE) if k in attrs), None)
    if key is None:
        raise NeuralaoError(f"{path} has no per-vertex 'ao' property")
    colours = np.asarray(loaded.visual.vertex_colors, dtype=np.uint8)
    return (
        np.asarray(loaded.vertices, np.float64),
        np.asarray(loaded.faces, np.int64),
        np.asarray(attrs[key], np.float32).reshape(-1),
        colours,
    )


# --------------------------------------------------------------------------- command line


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = BakeSettings()
    p.add_argument(
        "mesh", help="mesh file (.obj .ply .gltf .glb .stl .off), glTF folder, or a bare test-mesh name"
    )
    p.add_argument("--rays", type=int, default=d.rays, help=f"AO rays per sample (default {d.rays})")
    p.add_argument(
        "--max-distance",
        type=float,
        default=None,
        help="longest AO ray, scene units (default 0.25 x diagonal)",
    )
    p.add_argument(
        "--kernel", choices=("binary", "obscurance"), default=d.kernel, help="AO kernel (default binary)"
    )
    p.add_argument("--half-distance", type=float, default=None,
                   help="obscurance: distance at which a hit counts half, scene units (default 0.05 x diagonal)")  # fmt: skip
    p.add_argument("--method", choices=("vertex", "least-squares"), default=d.method,
                   help="sample at vertices, or fit vertex values to surface samples (default least-squares)")  # fmt: skip
    p.add_argument(
        "--alpha", type=float, default=d.alpha, help="least-squares edge regulariser weight (default 1)"
    )
    p.add_argument("--samples-per-vertex", type=float, default=d.samples_per_vertex,
                   help=f"least-squares surface sample budget per vertex (default {d.samples_per_vertex:g})")  # fmt: skip
    p.add_argument("--samples-per-face-cap", type=int, default=d.samples_per_face_cap,
                   help=f"least-squares: at most this many samples on one face (default {d.samples_per_face_cap})")  # fmt: skip
    p.add_argument(
        "--seed", type=int, default=0, help="seed of sample positions and ray directions (default 0)"
    )
    p.add_argument("--workers", type=int, default=2, help="tracing threads (default 2)")
    p.add_argument("--config", default=None, metavar="CONFIG.json",
                   help="bake a game level (.gltf/.glb with roles in node extras) with these level settings "
                        "(pipeline.bakes.level.LevelBakeSettings); --out is then a folder")  # fmt: skip
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="with --config: override a level setting, e.g. trace.rays=64 (repeatable)")  # fmt: skip
    p.add_argument("--to", choices=("vertex", "texture"), default="vertex",
                   help="per-vertex AO, or an AO texture map (occlusionTexture of OUT.glb + OUT.ao.png; "
                        "pipeline.bakes.texture) (default vertex)")  # fmt: skip
    from pipeline.bakes.texture import add_arguments as add_texture_arguments

    add_texture_arguments(p)
    p.add_argument("--out", required=True, metavar="OUT.ply|OUT.glb|DIR",
                   help="output mesh with per-vertex AO (a folder with --config)")  # fmt: skip
    from pipeline.engines.engine import add_engine_arguments

    add_engine_arguments(p, chunks=True)


def settings_from_args(args: argparse.Namespace) -> BakeSettings:
    check_label_args(args)
    settings = BakeSettings(
        rays=args.rays,
        max_distance=args.max_distance,
        kernel=args.kernel,
        half_distance=args.half_distance,
        method=args.method,
        alpha=args.alpha,
        samples_per_vertex=args.samples_per_vertex,
        samples_per_face_cap=args.samples_per_face_cap,
        seed=args.seed,
        workers=args.workers,
    )
    check_settings(settings)
    return settings


# Single-mesh flags that have no meaning for a level (its settings come from --config and --set).
_MESH_ONLY_FLAGS = ("rays", "max_distance", "kernel", "half_distance", "method", "alpha",
                    "samples_per_vertex", "samples_per_face_cap", "seed", "workers",
                    "to", "resolution", "margin", "uv")  # fmt: skip
# Flags of the vertex bake only, and of the texture bake only (refused with the other --to).
_VERTEX_ONLY_FLAGS = ("method", "alpha", "samples_per_vertex", "samples_per_face_cap")
_TEXTURE_ONLY_FLAGS = ("resolution", "margin", "uv")


def _refused_flag(args: argparse.Namespace) -> str | None:
    """The first flag given that the chosen ``--to`` has no use for, or None."""
    defaults = argparse.ArgumentParser()
    add_arguments(defaults)
    base = defaults.parse_args([args.mesh, "--out", args.out])
    other = _VERTEX_ONLY_FLAGS if args.to == "texture" else _TEXTURE_ONLY_FLAGS
    return next((f for f in other if getattr(args, f) != getattr(base, f)), None)


def run(args: argparse.Namespace) -> int:
    if getattr(args, "config", None) is not None:
        from pipeline.bakes.level import run_level

        if Path(args.mesh).suffix.lower() not in (".gltf", ".glb"):
            raise NeuralaoError(f"--config bakes a level: expected a .gltf or .glb file, got {args.mesh!r}")
        defaults = argparse.ArgumentParser()
        add_arguments(defaults)
        base = defaults.parse_args([args.mesh, "--out", args.out])
        given = [f for f in _MESH_ONLY_FLAGS if getattr(args, f) != getattr(base, f)]
        if given:
            raise NeuralaoError(
                f"--{given[0].replace('_', '-')} does not apply to a level; use --set trace.KEY=VALUE"
            )
        return run_level(args)  # --engine ray: the trace blocks become tasks (pipeline.bakes.level)
    if args.set:
        raise NeuralaoError("--set needs --config (level bakes only)")
    if _refused_flag(args) is not None:
        raise NeuralaoError(f"--{_refused_flag(args).replace('_', '-')} does not apply to --to {args.to}")
    if args.to == "texture":
        if getattr(args, "engine", "local") != "local":
            raise NeuralaoError("texture bakes run locally (--engine ray is for vertex bakes and datasets)")
        from pipeline.bakes.texture import run_texture

        return run_texture(args)
    settings = settings_from_args(args)
    out = Path(args.out)
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise NeuralaoError(f"--out must end in .ply or .glb, got {out.name!r}")
    if out.exists() and out.is_dir():
        raise NeuralaoError(f"--out {out} is a folder")
    from pipeline.bakes.gltf_scene import bakes_as_scene, read_gltf_scene, write_vertex_scene
    from pipeline.engines.engine import ResultStore, engine_from_args

    engine = engine_from_args(args)
    # a glTF to a .glb is baked as a scene (pipeline.bakes.gltf_scene): nodes, materials and textures kept
    gltf = read_gltf_scene(args.mesh) if bakes_as_scene(args.mesh, out) else None
    scene = load_scene(args.mesh) if gltf is None else gltf.world
    if engine.name == "local":  # threads in this process, exactly as before engines existed
        result = bake(scene, settings, progress=True)
    else:  # chunks on the cluster; finished ones kept beside OUT until it is written (resume)
        store = ResultStore(out.parent / f".{out.name}.chunks")
        with engine:
            result = bake(scene, settings, progress=True, engine=engine, store=store)
    if gltf is None:
        write_baked_mesh(out, scene, result.ao)
    else:
        write_vertex_scene(out, gltf, result.ao, {"settings": result.info["settings"]})
    if engine.name != "local":
        store.clear()
    i = result.info
    log.info(
        "baked %s (%d vertices, %s, %d samples, %d invalid) in %.1f s -> %s",
        scene.name, i["vertices"], i["method"], i["samples"], i["invalid_samples"], i["seconds"], out,
    )  # fmt: skip
    return 0
