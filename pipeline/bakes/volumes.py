"""AO for dynamic objects: per-region volume models (Sloan et al. 2013, section 2.3).

A level's playable space is covered by axis-aligned boxes (*regions*) joined by a connectivity graph.
A character or prop moving through the level takes its AO from the model of the region it is in,
evaluated per vertex for the vertex's world position and normal.

Pipeline (:func:`bake_volumes`)
-------------------------------
1. **Regions** from JSON (:func:`read_regions`) or from the level's free space
   (:func:`free_space_regions`: a grid of cells, a cell is occupied when a triangle crosses it or its
   centre lies inside geometry, free cells merged greedily into boxes). Neighbours are boxes that touch
   or overlap over a positive area (:func:`connect`); each edge carries the area ``w`` and the centre
   ``b`` of the shared boundary.
2. **Samples**: ``samples^3`` (8 x 8 x 8) cell centres per region. From each, ``directions`` (1024)
   jittered spherical-Fibonacci rays (uniform on the sphere) are traced with Embree
   (:meth:`neuralao.pipeline.tracing.labeller.Labeller.hits_along`). A sample is *valid* when at most
   ``backface_threshold`` (25%) of its rays hit back faces (the back-face rule of the labeller, over
   the whole sphere): points inside closed geometry or behind single-sided walls are dropped.
3. **Spherical obscurance** at two half distances (short, long): each ray gives
   ``rho(d) = 1 - 2^(-d / h)`` (= 1 - exp(a d), a = ln 0.5 / h) for a hit at distance d, 1 for a miss;
   projected to quadratic SH (9 coefficients per distance, 18 channels; ``rho - 1`` is projected and the
   exact SH of V = 1 added, so open space is exactly AO 1) and convolved with the clamped cosine
   (:mod:`neuralao.runtime.foundation.sh`), so ``AO(n) = sum_j f_j Y_j(n)`` for any unit normal n.
4. **The compact model** (eq. 4): ``f(p) = v_mean + sum_i (p - c)_i v_{2i + s_i}`` with ``s_i = 0``
   where ``(p - c)_i >= 0`` and 1 otherwise; 7 vectors of 18 channels and a centre c. For a fixed c the
   7 vectors are a linear least-squares fit to the valid samples (one design matrix, 18 right-hand
   sides); both candidate centres (centroid of the valid samples, centre of the box) are fitted and the
   one with the smaller residual is kept. Coefficients are AO-space SH, so the residual in coefficient
   space is the L2 error of AO integrated over every normal.
5. **Neighbour regularisation**: ``E = sum_i |M_i - M_orig,i|^2 + beta sum_{j in N(i)} w_ij
   |M_i(b_ij) - M_j(b_ij)|^2``. ``|M_i - M_orig,i|^2`` is measured where it matters, as the mean squared
   difference of the two models over region i's valid samples (``(t - t0)^T G_i (t - t0)``, G_i the
   normalised Gram matrix of the design); ``w_ij`` are boundary areas divided by their mean (scale
   free). Block coordinate descent: each sweep minimises E exactly over one region's 7 x 18 block with
   the others fixed (a 7 x 7 solve), in region order; E never increases (tested). The paper's b_ij is
   the boundary centre (``boundary_grid = 1``): the models then agree at that one point and not across
   the rest of the face (measured: the jump over the face does not drop), so by default the agreement
   term is spread over a 3 x 3 grid on each shared face, each point weighted w_ij / 9.

Levels: ``neuralao volumes LEVEL`` takes a glTF level of the level bake (pipeline/geometry/level_files.py; its
static and blocker instances are the occluders, foliage is not) or any mesh file (pipeline/geometry/scene.py).

Bad input and fallbacks (never NaN)
-----------------------------------
* No regions, a non-finite box, a box with an extent <= 0 (degenerate), an edge between boxes that do
  not touch, a region index out of range: one-line :class:`NeuralaoError`.
* A region with no valid sample (fully inside geometry, or behind walls): ``fallback = "neighbours"``,
  a constant model equal to the area-weighted mean of its resolved neighbours' models at the shared
  boundary centres (propagated from neighbour to neighbour); with no resolved neighbour at all
  ``fallback = "open"`` (AO = 1 for every normal), with a warning. Fallback regions take no part in the
  regularisation.
* A region with fewer valid samples than the 7 unknowns, or all on one side of the centre on an axis:
  the minimum-norm least-squares solution (undetermined derivatives are 0: flat extrapolation).
* Every region invalid: one-line error (the level has no free space the model could describe).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from neuralao.pipeline.geometry.gltf import INSTANCING
from neuralao.pipeline.geometry.level_files import read_gltf_json, read_level
from neuralao.pipeline.geometry.scene import Scene, load_scene, resolve_mesh_path
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings, sample_shifts
from neuralao.runtime.foundation import sh
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import THREAD_BYTES, check_count, check_seed
from neuralao.runtime.foundation.manifest import read_json

# The file format and the model of eq. 4 are the consumer runtime's; re-exported for the baker's callers.
from neuralao.runtime.volumes import (
    Edge,
    Region,
    RegionModel,
    Volumes,
    VolumeSettings,
    check_regions,
    design,
    model_at,
)

log = logging.getLogger(__name__)

# Relative tolerance (of the level diagonal) under which two box faces count as touching.
_TOUCH_REL = 1e-9
# Ridge added to the normalised Gram matrices (scale-free): keeps the 7 x 7 solves regular for
# regions whose samples leave a derivative undetermined; 1e-9 moves a well-posed fit by ~1e-9.
_RIDGE = 1e-9


# --------------------------------------------------------------------------- regions


def read_regions(path: str | Path) -> tuple[list[Region], list[tuple[int, int]] | None]:
    """Regions from JSON: ``{"regions": [{"name": ..., "min": [x, y, z], "max": [x, y, z]}, ...],
    "edges": [[i, j], ...]}`` (or a bare list of regions; edges optional, else from the geometry)."""
    path = Path(path)
    data = read_json(path, "regions file")
    if isinstance(data, dict) and set(data) - {"regions", "edges"}:
        unknown = sorted(set(data) - {"regions", "edges"})[0]
        raise NeuralaoError(f"regions file {path}: unknown key {unknown!r} (known: regions, edges)")
    items = data if isinstance(data, list) else data.get("regions") if isinstance(data, dict) else None
    if not isinstance(items, list):
        raise NeuralaoError(f"regions file {path} must hold a list of regions or {{'regions': [...]}}")
    regions = []
    for k, item in enumerate(items):
        unknown = sorted(set(item) - {"name", "min", "max"}) if isinstance(item, dict) else []
        if unknown:  # before the missing keys: a misspelt "mx" is named as what it is
            raise NeuralaoError(f"{path}: region {k}: unknown key {unknown[0]!r} (known: name, min, max)")
        if not isinstance(item, dict) or "min" not in item or "max" not in item:
            raise NeuralaoError(f"{path}: region {k} needs 'min' and 'max'")
        try:
            lo = tuple(float(v) for v in item["min"])
            hi = tuple(float(v) for v in item["max"])
        except (TypeError, ValueError):
            raise NeuralaoError(f"{path}: region {k} min / max must be lists of numbers") from None
        if len(lo) != 3 or len(hi) != 3:
            raise NeuralaoError(f"{path}: region {k} min / max must have 3 values")
        regions.append(Region(str(item.get("name", f"r{k}")), lo, hi))
    check_regions(regions, str(path))
    edges = data.get("edges") if isinstance(data, dict) else None
    if edges is None:
        return regions, None
    pairs = []
    for e in edges:
        if not (isinstance(e, list | tuple) and len(e) == 2 and all(isinstance(v, int) for v in e)):
            raise NeuralaoError(f"{path}: each edge must be [i, j] with integer region indices, got {e!r}")
        i, j = e
        if not (0 <= i < len(regions) and 0 <= j < len(regions)) or i == j:
            raise NeuralaoError(f"{path}: edge {e} must join two different regions in [0, {len(regions)})")
        pairs.append((min(i, j), max(i, j)))
    return regions, sorted(set(pairs))


def _shared_boundary(a: Region, b: Region, tol: float) -> tuple[float, np.ndarray] | None:
    """Area and centre of the boundary two boxes share, or None when they do not meet over an area.

    Touching boxes share a face rectangle; overlapping boxes (conservative regions do overlap) share
    the overlap box, whose boundary is taken as its cross-section across its thinnest axis.
    """
    lo = np.maximum(a.lo, b.lo)
    hi = np.minimum(a.hi, b.hi)
    ext = hi - lo
    if (ext < -tol).any():
        return None
    ext = np.maximum(ext, 0.0)
    thin = int(np.argmin(ext))
    others = [k for k in range(3) if k != thin]
    area = float(ext[others[0]] * ext[others[1]])
    if area <= tol * tol:
        return None  # an edge or a corner: nothing to agree across
    return area, (lo + hi) / 2.0


def connect(
    regions: list[Region], pairs: list[tuple[int, int]] | None = None, diagonal: float = 1.0
) -> list[Edge]:
    """The connectivity graph: every pair of boxes that meet over a positive area (or the given
    ``pairs``, each of which must). Sorted by (i, j)."""
    tol = _TOUCH_REL * max(diagonal, 1e-300)
    edges = []
    candidates = (
        pairs
        if pairs is not None
        else [(i, j) for i in range(len(regions)) for j in range(i + 1, len(regions))]
    )
    for i, j in candidates:
        shared = _shared_boundary(regions[i], regions[j], tol)
        if shared is None:
            if pairs is not None:
                raise NeuralaoError(
                    f"edge [{i}, {j}]: regions {regions[i].name} and {regions[j].name} do not touch"
                )
            continue
        edges.append(Edge(i, j, shared[0], tuple(float(v) for v in shared[1])))
    return edges


def _triangles_cross_cells(scene: Scene, lo: np.ndarray, cell: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(nx, ny, nz) bool: cells that a triangle crosses (separating-axis test, Akenine-Moeller 2001).

    A triangle lying exactly on the outer faces of the grid (the walls and floor of a level whose
    bounds they are) does not occupy the cells inside them: those cell faces are pulled in by 1e-6 of
    a cell. Triangles on interior cell faces occupy both neighbours (regions never span a wall).
    """
    tri = scene.triangles
    # ceil - 1: a triangle exactly on a cell face is a candidate for the cells on both sides
    tmin = (np.ceil((tri.min(axis=1) - lo) / cell) - 1).astype(np.int64)
    tmax = np.floor((tri.max(axis=1) - lo) / cell).astype(np.int64)
    tmin = np.clip(tmin, 0, counts - 1)
    tmax = np.clip(tmax, 0, counts - 1)
    span = tmax - tmin + 1
    per = span.prod(axis=1)
    tri_idx = np.repeat(np.arange(len(tri)), per)
    local = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)
    sx, sy = span[tri_idx, 0], span[tri_idx, 1]
    ijk = tmin[tri_idx] + np.stack([local % sx, (local // sx) % sy, local // (sx * sy)], axis=1)
    occupied = np.zeros(tuple(counts), dtype=bool)
    eps = 1e-6 * cell
    for start in range(0, len(tri_idx), 1 << 18):
        t_i, c_i = tri_idx[start : start + (1 << 18)], ijk[start : start + (1 << 18)]
        box_lo = lo + c_i * cell
        box_hi = box_lo + cell
        box_lo = np.where(c_i == 0, box_lo + eps, box_lo)
        box_hi = np.where(c_i == counts - 1, box_hi - eps, box_hi)
        centre, half = (box_lo + box_hi) / 2.0, (box_hi - box_lo) / 2.0
        v = tri[t_i] - centre[:, None, :]  # (m, 3 corners, 3)
        sep = (v.min(axis=1) > half).any(axis=1) | (v.max(axis=1) < -half).any(axis=1)
        edges = [v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]]
        normal = np.cross(edges[0], edges[1])
        r = (np.abs(normal) * half).sum(axis=1)
        sep |= np.abs((normal * v[:, 0]).sum(axis=1)) > r
        for e in edges:
            for k in range(3):
                axis = np.cross(np.eye(3)[k], e)
                p = (v * axis[:, None, :]).sum(axis=2)
                r = (np.abs(axis) * half).sum(axis=1)
                sep |= (p.min(axis=1) > r) | (p.max(axis=1) < -r)
        hit = c_i[~sep]
        occupied[hit[:, 0], hit[:, 1], hit[:, 2]] = True
    return occupied


def free_space_regions(scene: Scene, labeller: Labeller, settings: VolumeSettings) -> list[Region]:
    """Regions covering the level's free space: grid cells (``grid`` along the longest axis of the
    bounds, axes thinner than ``min_cells`` cells padded to it on both sides) that no triangle crosses and
    whose centre is not inside geometry (back-face rule over ``cell_rays`` directions), merged greedily
    (x, then y, then z runs, at most ``max_region_cells`` cells per axis) into boxes. Deterministic."""
    if settings.grid < 1 or settings.max_region_cells < 1:
        raise NeuralaoError("grid and max_region_cells must be >= 1")
    lo, hi = scene.bounds
    ext = hi - lo
    size = float(ext.max()) / settings.grid
    thin = settings.min_cells * size
    pad = np.where(ext < thin, (thin - ext) / 2.0, 0.0)
    lo, hi = lo - pad, hi + pad
    counts = np.maximum(1, np.round((hi - lo) / size)).astype(np.int64)
    cell = (hi - lo) / counts
    occupied = _triangles_cross_cells(scene, lo, cell, counts)
    free_idx = np.argwhere(~occupied)
    if len(free_idx):
        centres = lo + (free_idx + 0.5) * cell
        ids = np.arange(len(centres), dtype=np.int64)
        s1, s2 = sample_shifts(settings.seed + 1, ids)
        _, back = labeller.hits_along(centres, sh.sphere_directions(settings.cell_rays, s1, s2))
        inside = back.mean(axis=1) > settings.backface_threshold
        occupied[tuple(free_idx[inside].T)] = True
    free = ~occupied
    taken = np.zeros_like(free)
    m = settings.max_region_cells
    regions = []
    nx, ny, nz = counts
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                if not free[x, y, z] or taken[x, y, z]:
                    continue
                x1 = x + 1
                while x1 < nx and x1 - x < m and free[x1, y, z] and not taken[x1, y, z]:
                    x1 += 1
                y1 = y + 1
                while y1 < ny and y1 - y < m and (free[x:x1, y1, z] & ~taken[x:x1, y1, z]).all():
                    y1 += 1
                z1 = z + 1
                while z1 < nz and z1 - z < m and (free[x:x1, y:y1, z1] & ~taken[x:x1, y:y1, z1]).all():
                    z1 += 1
                taken[x:x1, y:y1, z:z1] = True
                a = lo + np.array([x, y, z]) * cell
                b = lo + np.array([x1, y1, z1]) * cell
                regions.append(Region(f"r{len(regions)}", tuple(a.tolist()), tuple(b.tolist())))
    if not regions:
        raise NeuralaoError(
            f"level {scene.name} has no free grid cell at grid {settings.grid} "
            "(try another grid or --regions)"
        )
    return regions


# --------------------------------------------------------------------------- samples


def half_distances(settings: VolumeSettings, diagonal: float) -> tuple[float, float]:
    """The two half distances (short, long), scene units, checked positive and finite."""
    hd = settings.half_distances
    values = hd if hd is not None else tuple(r * diagonal for r in settings.half_distances_rel)
    if len(values) != 2 or not all(math.isfinite(v) and v > 0 for v in values):
        raise NeuralaoError(f"half distances must be two positive finite distances, got {values!r}")
    return float(values[0]), float(values[1])


def region_points(region: Region, samples: int) -> np.ndarray:
    """(samples^3, 3) float64 cell centres of a samples x samples x samples grid over the box."""
    t = (np.arange(samples) + 0.5) / samples
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.asarray(region.lo) + g * region.size


def spherical_ao(
    labeller: Labeller,
    points: np.ndarray,
    ids: np.ndarray,
    halves: tuple[float, float],
    settings: VolumeSettings,
    progress: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """AO-space quadratic SH of spherical obscurance at points in free space.

    points (n, 3) float64, ids (n,) int64 (direction jitter ids) -> coefficients (n, 2, 9) float64
    (distance, SH; clamped cosine applied) and valid (n,) bool (back-face rule over the sphere).
    """
    s1, s2 = sample_shifts(settings.seed, ids)
    dirs = sh.sphere_directions(settings.directions, s1, s2)
    dist, back = labeller.hits_along(points, dirs, progress=progress)
    d = dist.astype(np.float64)[..., None]
    h = np.asarray(halves, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        rho = np.where(np.isfinite(d), 1.0 - np.exp2(-d / h), 1.0)  # (n, k, 2)
    # Control variate: the SH of V = 1 is known exactly (AO 1), so only rho - 1 (non-zero on hits) is
    # projected by Monte Carlo: open space is exactly AO 1 and the projection noise shrinks with the
    # fraction of rays that hit something.
    coeffs = sh.convolve_clamped_cosine(sh.project_uniform(rho - 1.0, dirs)) + open_coefficients()
    valid = back.mean(axis=1) <= settings.backface_threshold
    return coeffs, valid


# --------------------------------------------------------------------------- the model (eq. 4)


def _column_scale(region: Region) -> np.ndarray:
    """(7,) column scales that make the design scale free (derivatives per half box size)."""
    h = np.maximum(region.size / 2.0, 1e-300)
    return np.array([1.0, h[0], h[0], h[1], h[1], h[2], h[2]])


def _solve(x: np.ndarray, y: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Minimum-norm least squares of x (n, 7) theta = y (n, c) with columns scaled by 1/scale."""
    xs = x * scale
    theta, *_ = np.linalg.lstsq(xs, y, rcond=1e-10)
    return theta * scale[:, None]


def fit_region(region: Region, points: np.ndarray, coeffs: np.ndarray, valid: np.ndarray) -> RegionModel:
    """Fit eq. 4 at both candidate centres (centroid of the valid samples, box centre), keep the better.

    points (S, 3), coeffs (S, 2, 9), valid (S,) -> :class:`RegionModel` (fallback None). Needs >= 1
    valid sample (regions without one get a fallback in :func:`bake_volumes`).
    """
    p = points[valid]
    y = coeffs[valid].reshape(len(p), -1)
    scale = _column_scale(region)
    best = None
    for choice, c in (("centroid", p.mean(axis=0)), ("box", region.centre)):
        x = design(p, c)
        theta = _solve(x, y, scale)
        sse = float(((x @ theta - y) ** 2).sum())
        if best is None or sse < best[0] - 1e-15 * max(1.0, best[0]):
            best = (sse, choice, c, theta)
    sse, choice, c, theta = best
    # Mean over samples of the integral over normals of (AO error)^2, / 4 pi -> RMS AO error per normal.
    rmse = math.sqrt(sse / len(p) / (4.0 * math.pi) / 2.0)
    return RegionModel(np.asarray(c, np.float64), theta.reshape(7, 2, -1), choice, int(len(p)), rmse)


def _gram(region: Region, model: RegionModel, points: np.ndarray) -> np.ndarray:
    """(7, 7) normalised Gram matrix of the design at the region's valid samples, plus a tiny ridge."""
    x = design(points, model.centre)
    g = x.T @ x / max(len(points), 1)
    scale = _column_scale(region)
    return g + _RIDGE * np.diag(1.0 / scale**2)


def regularise(
    regions: list[Region],
    edges: list[Edge],
    models: list[RegionModel],
    grams: list[np.ndarray | None],
    beta: float,
    iterations: int,
    boundary_grid: int = 1,
) -> tuple[list[RegionModel], list[float]]:
    """Block coordinate descent on E (module doc). Regions with ``grams[i] is None`` (fallbacks) are
    neither updated nor used as neighbours. ``boundary_grid`` k: the agreement term at the boundary
    centre (k = 1, the paper's b_ij) or at a k x k grid over the shared face (:func:`boundary_points`),
    each point weighted w_ij / k^2. Returns new models and E before and after every sweep."""
    if beta < 0 or not math.isfinite(beta):
        raise NeuralaoError(f"beta must be a finite number >= 0, got {beta!r}")
    active = [g is not None for g in grams]
    live = [e for e in edges if active[e.i] and active[e.j]]
    mean_area = float(np.mean([e.area for e in live])) if live else 1.0
    nbrs: list[list[tuple[int, float, np.ndarray]]] = [[] for _ in regions]
    for e in live:
        pts = (
            np.asarray(e.centre)[None, :]
            if boundary_grid <= 1
            else boundary_points(regions[e.i], regions[e.j], boundary_grid)
        )
        w = e.area / mean_area / len(pts)
        nbrs[e.i].append((e.j, w, pts))
        nbrs[e.j].append((e.i, w, pts))
    orig = [m.coefficients.reshape(7, -1) for m in models]
    theta = [t.copy() for t in orig]

    def rows(i: int, b: np.ndarray) -> np.ndarray:
        return design(b, models[i].centre)

    def energy() -> float:
        e = 0.0
        for i, g in enumerate(grams):
            if g is None:
                continue
            d = theta[i] - orig[i]
            e += float(np.einsum("tc,ts,sc->", d, g, d))
            for j, w, b in nbrs[i]:
                e += beta * w * float(((rows(i, b) @ theta[i] - rows(j, b) @ theta[j]) ** 2).sum())
        return e

    history = [energy()]
    for _ in range(iterations if beta > 0 else 0):
        for i, g in enumerate(grams):
            if g is None or not nbrs[i]:
                continue
            # d/d theta_i of E: region i's own sum and each neighbour's sum hold the edge: weight 2 beta.
            a = g.copy()
            rhs = g @ orig[i]
            for j, w, b in nbrs[i]:
                r = rows(i, b)
                a += 2.0 * beta * w * (r.T @ r)
                rhs += 2.0 * beta * w * (r.T @ (rows(j, b) @ theta[j]))
            theta[i] = np.linalg.solve(a, rhs)
        history.append(energy())
    out = [replace(m, coefficients=theta[i].reshape(m.coefficients.shape)) for i, m in enumerate(models)]
    return out, history


def open_coefficients() -> np.ndarray:
    """(2, 9) AO-space SH of a fully open point: AO = 1 for every normal."""
    c = np.zeros((2, sh.QUADRATIC))
    c[:, 0] = 1.0 / sh.basis(np.array([0.0, 0.0, 1.0]), 1)[0]
    return c


def fill_fallbacks(
    regions: list[Region], edges: list[Edge], models: list[RegionModel | None], warn: bool = True
) -> list[RegionModel]:
    """Constant models for the regions whose model is None (no valid sample; module doc): sweeps in
    region order fill each one that has a model next to it, until nothing changes; the rest are open."""
    out = list(models)
    changed = True
    while changed:
        changed = False
        for i, m in enumerate(out):
            if m is not None:
                continue
            acc, total = np.zeros((2, sh.QUADRATIC)), 0.0
            for e in edges:
                j = e.j if e.i == i else e.i if e.j == i else None
                if j is None or out[j] is None:
                    continue
                acc += e.area * model_at(out[j], np.asarray(e.centre)[None, :])[0]
                total += e.area
            if total > 0:
                coeffs = np.zeros((7, 2, sh.QUADRATIC))
                coeffs[0] = acc / total
                out[i] = RegionModel(regions[i].centre, coeffs, "fallback", 0, 0.0, "neighbours")
                changed = True
    for i, m in enumerate(out):
        if m is None:
            if warn:
                log.warning(
                    "region %d (%s) has no valid sample and no resolved neighbour: AO 1", i, regions[i].name
                )
            coeffs = np.zeros((7, 2, sh.QUADRATIC))
            coeffs[0] = open_coefficients()
            out[i] = RegionModel(regions[i].centre, coeffs, "fallback", 0, 0.0, "open")
    return out


def boundary_points(a: Region, b: Region, k: int = 5) -> np.ndarray:
    """(k * k, 3) float64: a k x k grid of cell centres over the boundary two boxes share (the face
    they touch on, or the overlap's cross-section across its thinnest axis, as :func:`connect`)."""
    lo, hi = np.maximum(a.lo, b.lo), np.minimum(a.hi, b.hi)
    thin = int(np.argmin(np.maximum(hi - lo, 0.0)))
    u, v = (ax for ax in range(3) if ax != thin)
    t = (np.arange(k) + 0.5) / k
    tu, tv = np.meshgrid(t, t, indexing="ij")
    pts = np.tile((lo + hi) / 2.0, (k * k, 1))
    pts[:, u] = lo[u] + tu.ravel() * (hi[u] - lo[u])
    pts[:, v] = lo[v] + tv.ravel() * (hi[v] - lo[v])
    return pts


def face_jumps(
    regions: list[Region],
    edges: list[Edge],
    models: list[RegionModel],
    blend: float,
    count: int = sh.QUADRATIC,
) -> np.ndarray:
    """(len(edges),) like :func:`boundary_jumps`, averaged (RMS) over an 8 x 8 grid on each shared face
    instead of its centre only (8: no grid point is the centre or a 3 x 3 regularisation point): the
    popping a character crossing anywhere on the face sees."""
    out = np.zeros(len(edges))
    w = np.array([1.0 - blend, blend])
    for k, e in enumerate(edges):
        pts = boundary_points(regions[e.i], regions[e.j], 8)
        diff = model_at(models[e.i], pts) - model_at(models[e.j], pts)
        f = np.einsum("d,ndj->nj", w, diff)[:, :count]
        out[k] = math.sqrt(float((f**2).sum(axis=1).mean()) / (4.0 * math.pi))
    return out


def boundary_jumps(
    edges: list[Edge], models: list[RegionModel], blend: float, count: int = sh.QUADRATIC
) -> np.ndarray:
    """(len(edges),) RMS over all normals of the blended-AO difference of the two models at each
    boundary centre: ``sqrt(sum_j (f_i - f_j)_j^2 / 4 pi)`` (orthonormal SH), with ``count`` SH terms."""
    out = np.zeros(len(edges))
    w = np.array([1.0 - blend, blend])
    for k, e in enumerate(edges):
        b = np.asarray(e.centre)[None, :]
        diff = model_at(models[e.i], b)[0] - model_at(models[e.j], b)[0]
        f = np.einsum("d,dj->j", w, diff)[:count]
        out[k] = math.sqrt(float((f**2).sum()) / (4.0 * math.pi))
    return out


# --------------------------------------------------------------------------- the bake


def check_settings(s: VolumeSettings) -> None:
    for name in (
        "samples",
        "directions",
        "iterations",
        "boundary_grid",
        "grid",
        "max_region_cells",
        "min_cells",
        "cell_rays",
        "workers",
    ):
        v = getattr(s, name)
        if isinstance(v, bool) or not isinstance(v, int) or v < (0 if name == "iterations" else 1):
            raise NeuralaoError(f"{name} must be a positive integer, got {v!r}")
    # What each count allocates (neuralao.runtime.foundation.limits), checked before any of it is: a region's
    # samples^3 points trace `directions` rays each (directions, distances, the obscurance and its SH
    # projection, ~256 B a ray); the free-space grid is up to grid^3 cells, each tracing cell_rays rays.
    check_count("iterations", s.iterations, low=0, bytes_each=64, each="an energy record of the history")
    check_count("workers", s.workers, bytes_each=THREAD_BYTES, each="per tracing thread")
    check_count("directions", s.directions, bytes_each=256, each="per ray of one sample")
    check_count(
        "samples",
        s.samples**3,
        bytes_each=256 * s.directions,
        shown=f"{s.samples} ({s.samples**3} per region)",
        each=f"per sample of {s.directions} directions",
    )
    check_count("cell_rays", s.cell_rays, bytes_each=32, each="per ray of one cell")
    check_count(
        "grid",
        s.grid**3,
        bytes_each=64 + 32 * s.cell_rays,
        shown=f"{s.grid} (up to {s.grid**3} cells)",
        each=f"per cell of {s.cell_rays} rays",
    )
    check_count(
        "boundary_grid",
        s.boundary_grid**2,
        bytes_each=1024,
        shown=str(s.boundary_grid),
        each="per boundary point",
    )
    check_count("max_region_cells", s.max_region_cells, bytes_each=1)
    check_count(
        "min_cells", s.min_cells**3, bytes_each=64 + 32 * s.cell_rays, shown=str(s.min_cells), each="per cell"
    )
    check_seed("seed", s.seed)
    if not (math.isfinite(s.beta) and s.beta >= 0):
        raise NeuralaoError(f"beta must be a finite number >= 0, got {s.beta!r}")
    if not (0.0 <= s.blend <= 1.0):
        raise NeuralaoError(f"blend must be in [0, 1], got {s.blend!r}")
    if not (math.isfinite(s.max_distance_rel) and s.max_distance_rel > 0):
        raise NeuralaoError(f"max_distance_rel must be positive, got {s.max_distance_rel!r}")
    if not (0.0 <= s.backface_threshold <= 1.0):
        raise NeuralaoError(f"backface_threshold must be in [0, 1], got {s.backface_threshold!r}")


def make_labeller(scene: Scene, settings: VolumeSettings) -> Labeller:
    """The Embree scene the volumes trace (rays to ``max_distance_rel`` x diagonal)."""
    return Labeller(
        scene,
        LabelSettings(
            max_distance_rel=settings.max_distance_rel, seed=settings.seed, workers=settings.workers
        ),
    )


def bake_volumes(
    scene: Scene,
    settings: VolumeSettings | None = None,
    regions: list[Region] | None = None,
    pairs: list[tuple[int, int]] | None = None,
    progress: bool = False,
    labeller: Labeller | None = None,
) -> tuple[Volumes, dict]:
    """Regions (given, or from free space) -> sampled, fitted, regularised models.

    Returns the :class:`Volumes` and ``extras``: per-region samples (``points``, ``coeffs``, ``valid``),
    the per-region fits (``fits``, None without a valid sample) and Gram matrices (``grams``) to
    regularise again with another beta, the unregularised models with fallbacks
    (``models_unregularised``) and the boundary jumps (``jumps_before``, ``jumps_after``).
    """
    s = settings or VolumeSettings()
    check_settings(s)
    t0 = time.perf_counter()
    labeller = labeller or make_labeller(scene, s)
    halves = half_distances(s, scene.diagonal)
    generated = regions is None
    if regions is None:
        regions = free_space_regions(scene, labeller, s)
    check_regions(regions)
    edges = connect(regions, pairs, scene.diagonal)
    t_regions = time.perf_counter() - t0
    per = s.samples**3
    samples, fits, grams = [], [], []
    t_trace = t_fit = 0.0
    for k, region in enumerate(
        tqdm(regions, desc="volume regions", unit="region", disable=not progress, leave=False)
    ):
        t1 = time.perf_counter()
        pts = region_points(region, s.samples)
        coeffs, valid = spherical_ao(labeller, pts, k * per + np.arange(per, dtype=np.int64), halves, s)
        t2 = time.perf_counter()
        samples.append({"points": pts, "coeffs": coeffs, "valid": valid})
        if valid.any():
            m = fit_region(region, pts, coeffs, valid)
            fits.append(m)
            grams.append(_gram(region, m, pts[valid]))
        else:
            fits.append(None)
            grams.append(None)
        t_fit += time.perf_counter() - t2
        t_trace += t2 - t1
    if not any(m is not None for m in fits):
        raise NeuralaoError(f"level {scene.name}: no region has a valid sample (all inside geometry?)")
    t3 = time.perf_counter()
    placeholder = [
        m if m is not None else RegionModel(r.centre, np.zeros((7, 2, 9)))
        for m, r in zip(fits, regions, strict=True)
    ]
    regular, history = regularise(regions, edges, placeholder, grams, s.beta, s.iterations, s.boundary_grid)
    unreg = fill_fallbacks(regions, edges, fits, warn=False)
    final = fill_fallbacks(
        regions, edges, [m if g is not None else None for m, g in zip(regular, grams, strict=True)]
    )
    t_reg = time.perf_counter() - t3
    jumps_before = boundary_jumps(edges, unreg, s.blend)
    jumps_after = boundary_jumps(edges, final, s.blend)
    for m in final:
        if not np.isfinite(m.coefficients).all():  # defensive: the solves above are all regular
            raise NeuralaoError("volume model has non-finite coefficients")
    total = time.perf_counter() - t0
    stats = {
        "regions": len(regions),
        "generated_regions": generated,
        "edges": len(edges),
        "samples_per_region": per,
        "directions": s.directions,
        "rays": int(per * len(regions) * s.directions),
        "valid_samples": int(sum(int(x["valid"].sum()) for x in samples)),
        "fallback_regions": int(sum(m.fallback is not None for m in final)),
        "energy": history,
        "jump_before": _summary(jumps_before, edges),
        "jump_after": _summary(jumps_after, edges),
        "face_jump_before": _summary(face_jumps(regions, edges, unreg, s.blend), edges),
        "face_jump_after": _summary(face_jumps(regions, edges, final, s.blend), edges),
        "seconds": {
            "regions": t_regions,
            "trace": t_trace,
            "fit": t_fit,
            "regularise": t_reg,
            "total": total,
        },
    }
    vol = Volumes(
        regions,
        edges,
        final,
        halves,
        s.blend,
        s,
        scene={
            "name": scene.name,
            "source": scene.source,
            "diagonal": scene.diagonal,
            "bounds": scene.bounds.tolist(),
            "faces": int(len(scene.faces)),
        },
        stats=stats,
    )
    return vol, {
        "samples": samples,
        "fits": fits,
        "grams": grams,
        "models_unregularised": unreg,
        "jumps_before": jumps_before,
        "jumps_after": jumps_after,
    }


def _summary(jumps: np.ndarray, edges: list[Edge]) -> dict:
    if not len(jumps):
        return {"mean": 0.0, "area_weighted": 0.0, "max": 0.0}
    a = np.array([e.area for e in edges])
    return {
        "mean": float(jumps.mean()),
        "area_weighted": float((jumps * a).sum() / a.sum()),
        "max": float(jumps.max()),
    }


# --------------------------------------------------------------------------- files


# --------------------------------------------------------------------------- command line


def is_level(path: Path) -> bool:
    """A glTF level of the level bake (pipeline/geometry/level_files.py): some node sets a ``role`` in its
    extras, or the file uses EXT_mesh_gpu_instancing (which plain mesh loading does not expand)."""
    if path.suffix.lower() not in (".gltf", ".glb"):
        return False

    doc, _ = read_gltf_json(path)
    roles = any(isinstance(n.get("extras"), dict) and "role" in n["extras"] for n in doc.get("nodes", []))
    return roles or INSTANCING in doc.get("extensionsUsed", [])


def load_level_scene(level: str | Path) -> Scene:
    """The occluders a dynamic object sees: for a level (:func:`is_level`) its opaque geometry, every
    static and blocker instance (neuralao.pipeline.bakes.level_stages.opaque_scene; trees, shrubs and grass
    are not opaque and are left out); for any other mesh file, glTF folder or test-mesh name the whole mesh
    (neuralao.pipeline.geometry.scene.load_scene)."""
    path = resolve_mesh_path(level)
    if is_level(path):
        # Lazy: the level-bake stack costs 0.3 s measured on `neuralao volumes`; only a level needs it
        from neuralao.pipeline.bakes.level_stages import opaque_scene

        return opaque_scene(read_level(path))
    return load_scene(path)
