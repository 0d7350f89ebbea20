"""The least-squares normal equations of a big connected component solved in spatial subdomains, each
subdomain's work a task of an engine, converging to the global solution.

Method: conjugate gradients on the global system ``A v = b`` (:mod:`neuralao.pipeline.geometry.least_squares`:
sparse, symmetric positive definite), preconditioned by two-level additive Schwarz in its balancing form
(the BNN-type two-level preconditioner of Tang, Nabben, Vuik and Erlangga 2009 with Dirichlet subdomain
solves as its one-level part; of the coarse-correction variants they compare, it stays robust under
rounding and inexact coarse solves):

    M^-1 r = Q r + (I - Q A) S (I - A Q) r,   S = sum_i R_i^T A_i^-1 R_i,   Q = Z (Z^T A Z)^-1 Z^T

* subdomains: recursive coordinate bisection of the vertex positions into k cores of equal counts (each cut
  across the longest side of the bounding box, a stable sort: deterministic), each grown by ``overlap``
  rings of the matrix's graph, or of the mesh's faces before the matrix exists (:func:`mesh_partition`:
  with a regulariser the two graphs are one). Rings follow faces, not distances: a core vertex's every
  neighbour in ``A`` lies inside its subdomain whatever the faces' size (the houses' boxes are faces metres
  wide);
* local solves ``A_i = R_i A R_i^T`` (the subdomain's principal block: zero Dirichlet data outside), a
  SuperLU factor made once per subdomain with its system, where its tasks run, and reused by every
  iteration (a solve with a ridge factors A_i plus the ridge of A_i's own largest diagonal entry: the
  solve's needs every subdomain's, and the preconditioner need not hold it exactly);
* coarse space ``Z``: one aggregate per (subdomain core, connected component) pair, the indicator of its
  vertices. It holds each component's constant, the mode that a part without valid samples keeps only
  through the 1e-9 ridge (a condition number of 1e9 no local solve reaches). Measured at 32 subdomains
  (bench/bench_partitioned_solve.py): on soup it is what converges (per core only: 58-72 iterations and
  1.7e-3 off; one aggregate: 3.1e-3 off once CG's residual test passes; per core and component: 25
  iterations, 7.6e-7); on one component (terrain, bunny) the data term keeps the operator local and any
  of the three takes 19-20 / 36-37 iterations.

Why this and not the alternatives: the local solves alone, as tiles, are wrong at a tile's boundary by the
tile's own solution whatever its overlap (docs/results.md, "Spatial tiles ... rejected": up to 0.48 on the
houses' soup); iterated inside CG the same solves converge to the global solution, and the coarse space
keeps the iteration count bounded as subdomains are added (tests/test_least_squares_partitioned.py).
Restricted additive Schwarz converges faster per iteration but is not symmetric (CG needs a symmetric
preconditioner). Multigrid CG (the level's default for a big component) is one task: its V-cycle touches
every vertex each iteration.

The equations are made where they are used. The first wave makes each subdomain's system on its worker,
which keeps it for the CG's steps: its rows of A and b, cut from a matrix the caller holds
(:func:`solve_partitioned`) or made by a source of rows from what the worker holds (:func:`solve_subdomains`:
a level's piece makes them from its samples on the faces that touch the subdomain, so no process ever holds
the whole matrix), and from them its neighbours (which of its vertices each other subdomain holds) and its
core's shares of the coarse matrix Z^T A Z, of Z^T b and of the largest diagonal entry. The driver adds the
shares in subdomain order, adds the ridge that :func:`neuralao.pipeline.geometry.least_squares.
normal_equations` would (its size needs the largest diagonal entry of all), and factors the coarse system.

The vectors stay with the subdomains. The CG runs in Chronopoulos and Gear's form (r.u and A u.u summed
together, one reduction an iteration) and each subdomain's worker (the same one every step where the
engine can: :class:`Subdomains`) keeps its core's part of x and of the search direction, and r and A p on
its whole subdomain. An iteration is two waves of one task per subdomain: the update and the local solve
(each task returns the parts of its solution that its neighbours' subdomains hold, and its shares of r.r
and of the second coarse right-hand side, (A Z)^T y = sum_i (A Z)_i^T v_i), then the sum of those parts at
each subdomain, the preconditioned residual u and its product with A (returning its shares of r.u, A u.u
and Z^T A u). The driver keeps only the coarse vectors: it adds the tasks' shares, solves the coarse
system (Z^T r by its recurrence, so the next local solves need no wave of their own) and routes the
neighbours' parts. A vertex in several subdomains has its r computed alike by each of them (the same row,
the same sums in the same order), so the copies are the same bits and no step needs a neighbour's r.

CG stops at a relative residual of ``rtol`` per column (default 1e-10, the level's multigrid CG's). Every
sum runs in a fixed order (subdomains in order, numpy's pairwise sums within one, no threaded BLAS): the
same inputs give the same bytes whichever engine, worker, thread count or completion order.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu

from neuralao.pipeline.engines.engine import Context, Shared, Task, no_state
from neuralao.pipeline.geometry.least_squares import ridge_of
from neuralao.pipeline.geometry.surface import vertex_components
from neuralao.runtime.foundation.errors import NeuralaoError

# Relative residual (2-norm, per column) at which CG stops: the level's multigrid CG's. Measured max abs
# error against SuperLU at it (bench/bench_partitioned_solve.py): 1.5-3e-7 on the Table 1 terrain, 1e-7 on
# the bunny; 1.4e-5 on the soup, in a ribbon without valid samples that every cut crosses (its rows, held by
# the regulariser alone, are 20x less stiff than sampled ones, so their residual weighs little). 1e-12
# takes that to 3.3e-7 at 30-40% more iterations. Half an 8-bit output step is 2e-3.
RTOL = 1e-10
# Rings of graph neighbours each subdomain core grows by. Measured at 16 subdomains, iterations for 1 / 2 / 3
# rings: terrain (301^2 vertices) 22 / 17 / 16, soup 32 / 25 / 23, bunny 39 / 32 / 29; a third ring grows
# each subdomain by another 5-13% and costs as much CPU as it saves.
OVERLAP = 2
# Iterations after which the solve gives up (measured: at most 36; a stalled CG is a bug, not slowness).
MAX_ITERATIONS = 500
# Times a solve starts again when a worker lost its subdomains' vectors (an actor restarted after a crash).
RESTARTS = 2


@dataclass(frozen=True)
class Partition:
    """Subdomains of a system's n unknowns (vertices).

    core   : (n,) int64 subdomain owning each vertex (non-overlapping, 0..k-1)
    parts  : k arrays (n_i,) int64, ascending: each subdomain's vertices (its core and ``overlap`` rings)
    coarse : (n,) int64 coarse aggregate of each vertex (one per core x connected component, 0..m-1)
    """

    core: np.ndarray
    parts: list[np.ndarray]
    coarse: np.ndarray

    @cached_property
    def cores(self) -> list[np.ndarray]:
        """Each subdomain's core vertices, ascending."""
        return _members(self.core, len(self.parts))


@dataclass
class SolveInfo:
    """What a partitioned solve measured (filled in by :func:`solve_partitioned`)."""

    iterations: list[int] = field(default_factory=list)  # CG iterations per column
    residuals: list[float] = field(default_factory=list)  # final relative residual per column
    subdomain_vertices: list[int] = field(default_factory=list)  # unknowns of each subdomain (with overlap)
    coarse_size: int = 0  # coarse aggregates
    seconds_setup: float = 0.0  # driver: partition, subdomain blocks, coarse factor
    # each local task's (a subdomain's first, its assembly, includes its factor)
    seconds_tasks: list[float] = field(default_factory=list)
    seconds_driver: float = 0.0  # driver: the iterations' own work (coarse solves, sums), not the tasks'
    restarts: int = 0  # times the solve started again because a worker lost its subdomains' vectors

    @property
    def largest_task(self) -> float:
        return max(self.seconds_tasks, default=0.0)


# --------------------------------------------------------------------------- partition


def _members(part: np.ndarray, count: int) -> list[np.ndarray]:
    """The indices of ``part`` (n,) int64 equal to each of 0..count-1, each list ascending."""
    order = np.argsort(part, kind="stable")
    return np.split(order, np.cumsum(np.bincount(part, minlength=count))[:-1])


def bisect(points: np.ndarray, count: int) -> np.ndarray:
    """Recursive coordinate bisection: (n,) int64 part of each of ``points`` (n, 3) float, in 0..count-1;
    parts of equal size (to one point), each cut across the longest side of its points' bounding box. A
    cut takes the points below the cut's value (numpy's selection finds it in linear time: the value is the
    same whichever algorithm finds it) and, of the points at that value, the lowest-numbered."""
    xyz = np.ascontiguousarray(np.asarray(points, np.float64).T)  # (3, n): contiguous rows reduce fast
    part = np.zeros(xyz.shape[1], np.int64)
    # (points' indices, their x, y and z: 1-D arrays, cut by masks, never gathered by index), parts, first
    stack = [(np.arange(xyz.shape[1]), tuple(xyz), count, 0)]
    while stack:
        idx, rows, k, first = stack.pop()
        if k == 1 or len(idx) == 0:
            part[idx] = first
            continue
        axis = int(np.argmax([r.max() - r.min() for r in rows]))
        low = k // 2
        cut = (len(idx) * low) // k
        take = np.zeros(len(idx), bool)
        if cut > 0:
            q = rows[axis]
            value = np.partition(q, cut - 1)[cut - 1]  # the cut-th smallest
            take = q < value
            ties = np.flatnonzero(q == value)
            take[ties[: cut - int(np.count_nonzero(take))]] = True
        rest = ~take
        stack.append((idx[rest], tuple(r[rest] for r in rows), k - low, first + low))
        stack.append((idx[take], tuple(r[take] for r in rows), low, first))
    return part


class _MatrixGraph:
    """The neighbours of vertices in the graph of a sparse matrix: the columns of their rows."""

    def __init__(self, a: sp.csr_matrix):
        self.a, self.n = a, a.shape[0]

    def __call__(self, vertices: np.ndarray) -> np.ndarray:
        return self.a[vertices].indices

    def border(self, part: np.ndarray) -> np.ndarray:
        """(n,) bool: the vertices with a neighbour in another part of ``part`` (n,)."""
        rows = np.repeat(np.arange(self.n), np.diff(self.a.indptr))
        out = np.zeros(self.n, bool)
        out[rows[part[rows] != part[self.a.indices]]] = True
        return out


class _FaceGraph:
    """The neighbours of vertices in a mesh's graph, the corners of their faces (with repeats): the graph of
    its least-squares normal equations (every face couples its corners), known before they are made."""

    def __init__(self, faces: np.ndarray, n: int):
        m = len(faces)
        self.faces, self.n = np.asarray(faces), n
        # each vertex's faces: the face-to-corner incidence transposed (a counting sort, linear)
        by_face = sp.csr_matrix(
            (np.ones(3 * m, np.int8), self.faces.reshape(-1), np.arange(0, 3 * m + 1, 3)), shape=(m, n)
        ).tocsc()
        self.faces_of = sp.csr_matrix((by_face.data, by_face.indices, by_face.indptr), shape=(n, m))

    def __call__(self, vertices: np.ndarray) -> np.ndarray:
        return self.faces[self.faces_of[vertices].indices].reshape(-1)

    def border(self, part: np.ndarray) -> np.ndarray:
        """(n,) bool: the vertices with a neighbour in another part of ``part`` (n,): the corners of the faces
        whose corners lie in different parts."""
        label = part[self.faces]
        out = np.zeros(self.n, bool)
        out[self.faces[(label[:, 0] != label[:, 1]) | (label[:, 1] != label[:, 2])].reshape(-1)] = True
        return out


def grow(
    graph,
    vertices: np.ndarray,
    rings: int,
    scratch: np.ndarray | None = None,
    border: np.ndarray | None = None,
) -> np.ndarray:
    """(ascending int64) ``vertices`` (distinct) and every vertex within ``rings`` edges of them in ``graph``
    (:class:`_MatrixGraph` or :class:`_FaceGraph`). ``scratch``: an (n,) bool array of False to use (and
    leave False) instead of making one. ``border``: those of ``vertices`` that may have a neighbour outside
    them (None: any), the only ones the first ring grows from (of a subdomain's core: its edge)."""
    inside = np.zeros(graph.n, bool) if scratch is None else scratch
    frontier = np.asarray(vertices, np.int64)
    inside[frontier] = True
    found = [frontier]
    frontier = frontier if border is None else np.asarray(border, np.int64)
    for _ in range(rings):
        reach = graph(frontier)
        frontier = np.unique(reach[~inside[reach]])  # a ring: small
        if len(frontier) == 0:
            break
        inside[frontier] = True
        found.append(frontier)
    have = np.sort(np.concatenate(found))
    if scratch is not None:
        inside[have] = False
    return have


def partition(
    a, points: np.ndarray, count: int, overlap: int = OVERLAP, connected: bool = False
) -> Partition:
    """Subdomains of the system ``a`` (n, n) sparse, its unknowns at ``points`` (n, 3): ``count`` cores by
    :func:`bisect` (at most one per unknown), grown by ``overlap`` rings of ``a``'s graph, and the coarse
    aggregates. ``connected``: ``a`` is known to be one connected component."""
    a = sp.csr_matrix(a)
    component = None if connected else connected_components(a, directed=False)[1]
    return _partition(points, count, overlap, _MatrixGraph(a), component)


def mesh_partition(
    points: np.ndarray,
    faces: np.ndarray,
    count: int,
    overlap: int = OVERLAP,
    connected: bool = False,
    components: np.ndarray | None = None,
) -> Partition:
    """:func:`partition` of the least-squares normal equations of the mesh ``points`` (n, 3), ``faces``
    (f, 3), from the mesh alone, before the equations are made: with a regulariser their matrix couples the
    corners of every face, so its graph is the faces' (a face of zero area adds only zeros, but here it
    joins its corners). ``connected``: every vertex is in one connected component; ``components``: the
    vertices' (:func:`neuralao.pipeline.geometry.surface.vertex_components`), if found already."""
    graph = _FaceGraph(faces, len(points))
    if components is None and not connected:
        components = vertex_components(faces, len(points))
    return _partition(points, count, overlap, graph, None if connected else components)


def _partition(
    points: np.ndarray, count: int, overlap: int, graph, component: np.ndarray | None
) -> Partition:
    """The partition of ``graph``'s n vertices at ``points``; ``component`` (n,) of each (None: one)."""
    n = graph.n
    if len(points) != n:
        raise NeuralaoError(f"{len(points)} vertex positions for a system of {n} unknowns")
    if count < 1 or overlap < 0:
        raise NeuralaoError(f"need subdomains >= 1 and overlap >= 0, got {count} and {overlap}")
    core = bisect(points, max(1, min(count, n)))
    cores = _members(core, int(core.max(initial=0)) + 1)
    scratch = np.zeros(n, bool)
    edge = graph.border(core)  # a core's first ring grows from its vertices on this border alone
    parts = [grow(graph, c, overlap, scratch, c[edge[c]]) for c in cores]
    if component is None:  # one connected component: no need to find them
        ncomp, component = 1, np.zeros(n, np.int64)
    else:
        ncomp = int(component.max(initial=0)) + 1
    _, coarse = np.unique(core * ncomp + component, return_inverse=True)
    out = Partition(core, parts, coarse.reshape(-1).astype(np.int64))
    out.__dict__["cores"] = cores  # made above: the cached property's value
    return out


# --------------------------------------------------------------------------- the subdomains' systems


def factorise(block) -> Any:
    """SuperLU factor of a symmetric positive definite block, told so: no pivoting and a minimum-degree
    ordering of A + A^T. On a 28k-vertex terrain subdomain: 0.18 s and 1.9M factor entries against
    0.38 s and 3.6M for SuperLU's default column ordering, each solve 7.5 ms against 17 ms."""
    return splu(
        sp.csc_matrix(block),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )


class MatrixRows:
    """The rows of a system held whole, ``a`` (n, n) sparse and its right-hand side ``b`` (n, c), for the
    subdomains to cut theirs from (:meth:`rows`). Its pattern is made symmetric (a transposed entry that is
    not stored is stored as a zero): two subdomains then agree on which of their vertices neighbour."""

    def __init__(self, a, b: np.ndarray):
        a = sp.csr_matrix(a)
        if not a.has_canonical_format:  # duplicates added once, in one order, before the zeros
            a = a.copy()
            a.sum_duplicates()
        c = a.tocoo()
        rows, cols = np.concatenate([c.row, c.col]), np.concatenate([c.col, c.row])
        data = np.concatenate([c.data, np.zeros(c.nnz)])
        self.a = sp.csr_matrix((data, (rows, cols)), shape=c.shape)  # each entry + 0.0: the same value
        self.b = np.asarray(b, np.float64).reshape(c.shape[0], -1)

    def rows(self, state, vertices: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
        """(columns E (e,) ascending: ``vertices`` and their rows' columns, their rows (p, e), rhs (p, c))."""
        r = self.a[vertices]
        columns = np.union1d(vertices, r.indices)
        local = sp.csr_matrix(
            (r.data, np.searchsorted(columns, r.indices), r.indptr), (len(vertices), len(columns))
        )
        return columns, local, np.ascontiguousarray(self.b[vertices])


@dataclass
class Subdomain:
    """Subdomain i's system, made where its tasks run (:meth:`Subdomains.step`, "assemble"). Its vertex lists,
    each ascending: ``C`` its core, ``P`` its subdomain (the core and its overlap), ``E`` P and P's graph
    neighbours (every column of P's rows). Positions index those lists."""

    token: str  # the attempt of the solve it was made for
    rows: sp.csr_matrix  # (|P|, |E|): A's rows of P, columns local to E (with the ridge once prepared)
    p_in_e: np.ndarray  # (|P|,) position in E of each vertex of P
    core_in_p: np.ndarray  # (|C|,) position in P of each core vertex
    core_in_e: np.ndarray  # (|C|,) position in E of each core vertex
    coarse_core: np.ndarray  # (|C|,) aggregate of each core vertex
    coarse_e: np.ndarray  # (|E|,) aggregate of each vertex of E
    rhs: np.ndarray  # (|P|, c): b on P (with the ridge once prepared)
    # (subdomain j, positions in E): the vertices of E that j's P holds, ascending j (its own P too)
    receives: list[tuple[int, np.ndarray]]
    # (subdomain j, positions in P): the part of this subdomain's local solution j receives, ascending j
    sends: list[tuple[int, np.ndarray]]
    az: sp.csr_matrix | None = None  # (|P|, m): (A Z)'s rows of P, made by the first local solve
    # SuperLU factor of A_i (P's rows at P's columns; with the solve's ridge, A_i plus its own: the ridge
    # rule on A_i's largest diagonal entry), made with the system: the local solves' preconditioner
    factor: Any = None


def _indicator(coarse: np.ndarray, m: int) -> sp.csr_matrix:
    """(len(coarse), m) csr: Z's rows of vertices in aggregates ``coarse``."""
    return sp.csr_matrix((np.ones(len(coarse)), (np.arange(len(coarse)), coarse)), shape=(len(coarse), m))


def _neighbours(
    i: int, parts: list[np.ndarray], columns: np.ndarray, p_in_e: np.ndarray, rows: sp.csr_matrix, n: int
) -> tuple[list, list]:
    """Subdomain i's receives and sends (:class:`Subdomain`) from every subdomain's P (``parts``), its E
    (``columns``) and its rows' pattern. A vertex u of P is in j's E when u or one of u's row's columns is in
    j's P: since the pattern is symmetric and a row's pattern the same in every subdomain that holds it, j
    finds the same vertices of i's E in its P as i does here."""
    inside = np.zeros(n, bool)
    pattern = sp.csr_matrix((np.ones(rows.nnz, np.int32), rows.indices, rows.indptr), shape=rows.shape)
    receives, sends = [], []
    for j, pj in enumerate(parts):
        inside[pj] = True
        hit = inside[columns]
        inside[pj] = False
        if not hit.any():
            continue
        receives.append((j, np.flatnonzero(hit)))
        if j != i:
            sends.append((j, np.flatnonzero(hit[p_in_e] | (pattern @ hit.astype(np.int32) > 0))))
    return receives, sends


def _dots(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(c,) column dot products of x, y (n, c), each by numpy's pairwise sum (no threaded BLAS)."""
    return np.array([np.add.reduce(x[:, j] * y[:, j]) for j in range(x.shape[1])])


def _per_aggregate(coarse: np.ndarray, x: np.ndarray, m: int) -> np.ndarray:
    """(m, c): Z^T x of x (n, c) whose vertices lie in aggregates ``coarse`` (n,)."""
    return np.stack([np.bincount(coarse, weights=x[:, j], minlength=m) for j in range(x.shape[1])], axis=1)


class Subdomains:
    """What the subdomains' tasks read: the partition and the source of the system's rows (``source.rows(
    state, vertices)`` -> (columns, rows, rhs), as :meth:`MatrixRows.rows`; ``state``: the task's context
    state), and, where their tasks run, what those tasks keep between the CG's steps: each subdomain's
    system (made by its first task) and its part of the CG's vectors. Travels to the workers once
    (:class:`neuralao.pipeline.engines.engine.Shared`), without what they keep; a worker that lost them
    (restarted, or evicted the object) answers "lost" and the driver starts the solve again.

    The vectors a subdomain keeps: x and the search direction p on its core, the residual r and the CG's
    A p (s) on P, kept on every subdomain that holds a vertex, each copy computed alike (the same rows, the
    same sums in the same order: the same bits as the owner's), so a step needs no neighbour's r."""

    def __init__(self, part: Partition, source, m: int, ridged: bool = False):
        self.part, self.source, self.m, self.ridged = part, source, m, ridged
        self.systems: dict[int, Subdomain] = {}
        self.vectors: dict[int, dict[str, Any]] = {}

    def __getstate__(self) -> dict:
        return {
            "part": self.part,
            "source": self.source,
            "m": self.m,
            "ridged": self.ridged,
            "systems": {},
            "vectors": {},
        }

    def step(self, state, i: int, token: str, phase: str, step: int, data) -> dict[str, Any]:
        """Subdomain i's part of the CG's ``phase`` at ``step`` (:func:`solve_subdomains`)."""
        if phase == "assemble":
            return self._assemble(state, i, token)
        s = self.systems.get(i)
        vec = self.vectors.get(i)
        if s is None or s.token != token:
            return {"lost": np.array(True)}
        if phase == "solve" and step == 0:
            self._prepare(s, data[3])
            vec = self.vectors[i] = {"token": token, "x": np.zeros((len(s.core_in_p), s.rhs.shape[1]))}
            vec["r"] = s.rhs.copy()
        elif vec is None or vec["token"] != token or (phase != "collect" and vec["next"] != (phase, step)):
            return {"lost": np.array(True)}
        vec["next"] = ("direction", step) if phase == "solve" else ("solve", step + 1)
        if phase == "solve":
            return self._solve(i, s, vec, *data[:3])
        if phase == "direction":
            return self._direction(i, s, vec, *data)
        del self.vectors[i], self.systems[i]
        return {"x": vec["x"]}

    def _assemble(self, state, i: int, token: str) -> dict[str, Any]:
        """Subdomain i's system from its rows (the source's), kept here; returns its core's shares of the
        coarse matrix Z^T A Z and of Z^T b, its diagonal's largest entry (all without the ridge) and its
        neighbours (whom it receives from and sends to, and how many values)."""
        part, m = self.part, self.m
        p = part.parts[i]
        columns, rows, rhs = self.source.rows(state, p)
        rhs = np.asarray(rhs, np.float64).reshape(len(p), -1)
        p_in_e = np.searchsorted(columns, p)
        core_in_p = np.flatnonzero(part.core[p] == i)
        core_in_e = p_in_e[core_in_p]
        coarse_e = part.coarse[columns]
        receives, sends = _neighbours(i, part.parts, columns, p_in_e, rows, len(part.core))
        s = Subdomain(
            token, rows, p_in_e, core_in_p, core_in_e, coarse_e[core_in_e], coarse_e, rhs, receives, sends
        )
        # The factor is made now, not by the first local solve: the solve's ridge needs every subdomain's
        # largest diagonal entry, so A_i takes its own (a preconditioner need not be the operator's block).
        block = rows[:, p_in_e]
        if self.ridged:
            block = block + ridge_of(block.diagonal().max(initial=0.0)) * sp.identity(len(p), format="csr")
        s.factor = factorise(block)
        self.systems[i] = s
        self.vectors.pop(i, None)
        core_rows = rows[core_in_p]
        diagonal = np.asarray(core_rows[np.arange(len(core_in_p)), core_in_e]).reshape(-1)
        return {
            "zaz": (_indicator(s.coarse_core, m).T @ (core_rows @ _indicator(coarse_e, m))).tocsr(),
            "ztb": _per_aggregate(s.coarse_core, rhs[core_in_p], m),
            "diagonal": np.array(diagonal.max(initial=-np.inf)),
            "receives": [(j, len(pos)) for j, pos in receives],
            "sends": [(j, len(pos)) for j, pos in sends],
        }

    def _prepare(self, s: Subdomain, ridge) -> None:
        """Before subdomain i's first local solve: the ridge (None, or (value, prior (c,))) on its diagonal
        and right-hand side, and (A Z)'s rows of P."""
        if ridge is not None:
            value, prior = ridge
            k = len(s.p_in_e)
            s.rows = s.rows + sp.csr_matrix((np.full(k, value), (np.arange(k), s.p_in_e)), shape=s.rows.shape)
            s.rhs = s.rhs + value * np.asarray(prior, np.float64).reshape(1, -1)
        s.az = (s.rows @ _indicator(s.coarse_e, self.m)).tocsr()

    def _solve(self, i, s: Subdomain, vec, alpha, beta, c) -> dict[str, Any]:
        """The previous step's update (x += alpha p, r -= alpha s after p = u + beta p, s = w + beta s), then
        the local solve of the coarse-corrected residual: v = A_i^-1 (r - A Z c) on P. Returns the parts of v
        the neighbours hold and this subdomain's shares of r.r (its core) and of (A Z)^T y (its v: y is the
        subdomains' v added)."""
        if alpha is not None:
            u, w = vec.pop("u"), vec.pop("w")
            vec["p"] = u if "p" not in vec else u + beta * vec["p"]
            vec["s"] = w if "s" not in vec else w + beta * vec["s"]
            vec["x"] += alpha * vec["p"]
            vec["r"] -= alpha * vec["s"]
        r = vec["r"]
        v = vec["v"] = s.factor.solve(np.ascontiguousarray(r - s.az @ c))
        rc = r[s.core_in_p]
        return {"rr": _dots(rc, rc), "azy": s.az.T @ v, "pieces": [v[pos] for _, pos in s.sends]}

    def _direction(self, i, s: Subdomain, vec, cd, pieces) -> dict[str, Any]:
        """y = S r' on E (every subdomain's local solution at E's vertices, added in subdomain order), then
        u = M^-1 r = Z (c - d) + y on E and w = A u on P; returns the core's shares of r.u, w.u, Z^T w."""
        v = vec.pop("v")
        y = np.zeros((len(s.coarse_e), v.shape[1]))
        for (j, pos), piece in zip(s.receives, pieces, strict=True):
            y[pos] += v if j == i else piece
        u = cd[s.coarse_e] + y
        w = s.rows @ u
        uc, wc = u[s.core_in_e], w[s.core_in_p]
        vec["u"], vec["w"] = uc, w
        return {
            "gamma": _dots(vec["r"][s.core_in_p], uc),
            "delta": _dots(wc, uc),
            "ztw": _per_aggregate(s.coarse_core, wc, self.m),
        }


def subdomain_step(state, args) -> dict[str, Any]:
    """Engine task: one step of one subdomain; args (subdomains, i, token, phase, step, data) ->
    :meth:`Subdomains.step`'s result and its "seconds". ``state``: what the source of the rows reads."""
    subdomains, i, token, phase, step, data = args
    t0 = time.perf_counter()
    out = subdomains.step(state, i, token, phase, step, data)
    out["seconds"] = np.array(time.perf_counter() - t0)
    return out


# A stateless context for the subdomain tasks of callers that pass none.
STATELESS = Context("schwarz", no_state, None)


# --------------------------------------------------------------------------- the solve


# Solves started by this process: with its id and the clock, each solve's name (:func:`solve_subdomains`).
_SOLVES = itertools.count()


class _Lost(Exception):
    """A subdomain's worker no longer holds the solve's system or vectors."""


class _Solve:
    """One partitioned solve: its subdomains' systems made where their tasks run (a wave), the coarse
    system added up from their shares, then the CG, each step a wave of one task per subdomain (module
    doc)."""

    def __init__(self, source, part: Partition, engine, context: Context, info, name: str, ridge):
        self.part, self.engine, self.context, self.info, self.prior = part, engine, context, info, ridge
        self.k, self.m = len(part.parts), int(part.coarse.max(initial=-1)) + 1
        self.counts = np.bincount(part.coarse, minlength=self.m).astype(np.float64)  # vertices per aggregate
        self.subdomains: Subdomains | Shared = Subdomains(part, source, self.m, ridge is not None)
        if engine is not None:  # sent once per worker, under the solve's own name
            self.subdomains = Shared(f"schwarz/{name}", self.subdomains)
        self.waited = 0.0  # wall seconds of the waves (tasks, sending, gathering)
        info.coarse_size = self.m
        info.subdomain_vertices = [len(p) for p in part.parts]

    def wave(
        self, token: str, phase: str, step: int, data: list, beside=(), aside=None
    ) -> list[dict[str, Any]]:
        """Every subdomain's ``phase`` at ``step``, subdomain i given data[i]; results in subdomain order.
        ``beside``: other tasks run in the same wave, each result handed to ``aside(index, result)``."""
        t0 = time.perf_counter()
        args = [(self.subdomains, i, token, phase, step, d) for i, d in enumerate(data)]
        if self.engine is None:
            results = [subdomain_step(None, x) for x in args]
        else:
            results = [None] * self.k
            # the same worker every step: it keeps the subdomain's system and vectors
            tasks = itertools.chain(
                (Task(self.context, subdomain_step, x, affinity=x[1]) for x in args), beside
            )
            for i, res in self.engine.map(tasks):
                if i < self.k:
                    results[i] = res
                else:
                    aside(i - self.k, res)
        self.info.seconds_tasks.extend(float(r["seconds"]) for r in results)
        self.waited += time.perf_counter() - t0
        if any("lost" in r for r in results):
            raise _Lost
        return results

    def total(self, results: list[dict[str, Any]], key: str) -> np.ndarray:
        """The subdomains' ``key`` shares added in subdomain order."""
        out = np.array(results[0][key], np.float64)
        for r in results[1:]:
            out = out + r[key]
        return out

    def setup(self, results: list[dict[str, Any]]):
        """From the subdomains' assembly: the routes of the local solutions between them, the ridge, the
        coarse system's factor and Z^T b. Returns (ridge: None or (value, prior), Z^T b (m, c))."""
        sends = {i: {j: (q, count) for q, (j, count) in enumerate(r["sends"])} for i, r in enumerate(results)}
        self.routes = []
        for i, r in enumerate(results):
            route = []
            for j, count in r["receives"]:
                if j != i and sends[j].get(i, (0, -1))[1] != count:
                    raise NeuralaoError(f"subdomains {j} and {i} disagree on the vertices they share (a bug)")
                route.append(None if j == i else (j, sends[j][i][0]))
            self.routes.append(route)
        coarse, ztb = results[0]["zaz"], self.total(results, "ztb")
        for r in results[1:]:
            coarse = coarse + r["zaz"]
        largest = max(float(r["diagonal"]) for r in results)
        ridge = None
        if self.prior is not None:  # normal_equations' ridge toward the prior, on A's largest diagonal entry
            value = ridge_of(largest)
            prior = np.asarray(self.prior, np.float64).reshape(-1)
            coarse = coarse + sp.diags(value * self.counts)
            ztb = ztb + value * self.counts[:, None] * prior[None, :]
            ridge = (value, prior)
        coarse = sp.csc_matrix(coarse)
        if not (np.isfinite(coarse.data).all() and np.isfinite(ztb).all() and np.isfinite(largest)):
            raise NeuralaoError("the partitioned least-squares solve met a non-finite value in its equations")
        self.coarse = factorise(coarse)
        return ridge, ztb

    def run(self, token: str, rtol: float, max_iterations: int, beside=(), aside=None):
        """The subdomains' systems made (a wave, with ``beside``), then preconditioned CG, Chronopoulos and
        Gear's form (one reduction of r.u and A u.u a step), on every column of b in lockstep; a converged
        column stops (its updates are zero). Returns (x (n, c), iterations, relative residuals)."""
        k = self.k
        ridge, ztr = self.setup(self.wave(token, "assemble", 0, [None] * k, beside, aside))  # Z^T r, then
        cols = ztr.shape[1]  # kept here by its recurrence
        active, residual = np.ones(cols, bool), np.ones(cols)
        iterations = np.zeros(cols, np.int64)
        c = self.coarse.solve(ztr)
        alpha = beta = gamma_old = alpha_old = zts = scale = None
        step = 0
        while True:
            res = self.wave(token, "solve", step, [(alpha, beta, c, ridge if step == 0 else None)] * k)
            norm = np.sqrt(self.total(res, "rr"))
            if scale is None:  # r = b at the first step
                scale = np.maximum(norm, 1e-300)
            if alpha is not None:
                iterations += active
            residual = np.where(active, norm / scale, residual)
            _check_finite(residual)
            active &= residual > rtol
            if not active.any():
                break
            if iterations.max() >= max_iterations:
                raise NeuralaoError(
                    f"the partitioned least-squares CG did not converge in {max_iterations} iterations "
                    f"(relative residuals {', '.join(f'{v:.1e}' for v in residual)}; tolerance {rtol:.0e})"
                )
            pieces = [
                [None if q is None else res[q[0]]["pieces"][q[1]] for q in route] for route in self.routes
            ]
            cd = c - self.coarse.solve(self.total(res, "azy"))
            res = self.wave(token, "direction", step, [(cd, p) for p in pieces])
            gamma, delta, ztw = (self.total(res, key) for key in ("gamma", "delta", "ztw"))
            with np.errstate(divide="ignore", invalid="ignore"):
                if step == 0:
                    beta, alpha = np.zeros(cols), gamma / delta
                else:
                    beta = gamma / gamma_old
                    alpha = gamma / (delta - beta * gamma / alpha_old)
            beta, alpha = np.where(active, beta, 0.0), np.where(active, alpha, 0.0)  # a stopped column: 0
            zts = ztw if zts is None else ztw + beta * zts  # Z^T s, s = A p
            ztr = ztr - alpha * zts
            c = self.coarse.solve(ztr)
            gamma_old, alpha_old = gamma, alpha
            step += 1
        x = np.zeros((len(self.part.core), cols))
        for core, r in zip(self.part.cores, self.wave(token, "collect", step, [None] * k), strict=True):
            x[core] = r["x"]
        return x, iterations.tolist(), residual.tolist()


def _check_finite(residual: np.ndarray) -> None:
    """A NaN or infinite residual (from the equations): an error, not a column taken as converged."""
    if not np.isfinite(residual).all():
        raise NeuralaoError("the partitioned least-squares solve met a non-finite value in its equations")


def solve_subdomains(
    source,
    part: Partition,
    engine=None,
    context: Context | None = None,
    rtol: float = RTOL,
    max_iterations: int = MAX_ITERATIONS,
    info: SolveInfo | None = None,
    ridge=None,
    beside: Iterable[Task] | None = None,
    aside: Callable[[int, Any], None] | None = None,
) -> np.ndarray:
    """Solve the system whose rows ``source`` makes (:class:`Subdomains`: ``source.rows(state, vertices)``,
    each subdomain's rows made by its first task, where it runs) by CG preconditioned by two-level Schwarz
    over the subdomains and coarse aggregates of ``part`` (module doc). Returns x (n, c) float64, not clipped.

    ``ridge`` (None, or the prior (c,)): add the ridge of
    :func:`neuralao.pipeline.geometry.least_squares.normal_equations` toward it, RIDGE_REL times the
    largest diagonal entry of the rows (the system is then the one normal_equations makes of the same
    rows). ``engine`` (None: this process) runs the subdomains' steps, a
    task per subdomain and step, under ``context`` (None: a stateless one; its state is what ``source.rows``
    reads); ``beside``: other tasks of ``engine`` run in the first wave, each result handed to
    ``aside(index, result)`` as it arrives. ``info`` (filled in): iterations, residuals, seconds of the
    driver and of every task."""
    info = SolveInfo() if info is None else info
    t0 = time.perf_counter()
    if engine is None and beside is not None:
        raise NeuralaoError("tasks beside a partitioned solve need an engine to run them")
    # This solve's name: its subdomains' key on the workers and, with the attempt, its systems' token.
    # Unique to the solve (no two solves share it), it need not hash the gigabytes its systems are cut from.
    name = f"{os.getpid()}-{time.time_ns()}-{next(_SOLVES)}"
    solve = _Solve(source, part, engine, context or STATELESS, info, name, ridge)
    info.seconds_setup += time.perf_counter() - t0
    t1 = time.perf_counter()
    for attempt in range(RESTARTS + 1):
        try:
            # the tasks beside run once: the first attempt's first wave finishes them before any "lost"
            x, info.iterations, info.residuals = solve.run(
                f"{name}/{attempt}", rtol, max_iterations, beside if attempt == 0 and beside else (), aside
            )
            break
        except _Lost:
            info.restarts += 1
    else:
        raise NeuralaoError(
            f"the partitioned least-squares solve lost its subdomains' systems {RESTARTS + 1} times "
            "(its workers were restarted or evicted them)"
        )
    info.seconds_driver = time.perf_counter() - t1 - solve.waited
    return x


def solve_partitioned(
    a,
    rhs: np.ndarray,
    points: np.ndarray,
    subdomains: int,
    overlap: int = OVERLAP,
    engine=None,
    context: Context | None = None,
    rtol: float = RTOL,
    max_iterations: int = MAX_ITERATIONS,
    info: SolveInfo | None = None,
    subdivision: Partition | None = None,
    connected: bool = False,
) -> np.ndarray:
    """Solve ``a v = rhs`` by CG preconditioned by two-level Schwarz over ``subdomains`` spatial subdomains
    (module doc), each subdomain's rows cut from ``a`` where its tasks run (:class:`MatrixRows`). Returns v
    like ``rhs``, float64, not clipped.

    a : (n, n) scipy.sparse, symmetric positive definite; rhs : (n,) or (n, c) float; points : (n, 3) float,
    the position of each unknown. ``engine`` (None: this process) runs the subdomains' steps, one task per
    subdomain and step, under ``context`` (None: a stateless one; a caller whose workers already hold a
    context passes it, so no state is built or evicted for the solve). ``info`` (filled in): iterations,
    residuals, seconds of the driver and of every task. ``subdivision``: subdomains and coarse aggregates to
    use instead of :func:`partition`'s (``subdomains`` and ``overlap`` are then ignored). ``connected``: the
    caller knows ``a`` is one connected component (its coarse aggregates are then the subdomains' cores)."""
    info = SolveInfo() if info is None else info
    t0 = time.perf_counter()
    a = sp.csr_matrix(a, dtype=np.float64)
    b = np.asarray(rhs, np.float64).reshape(a.shape[0], -1)
    if a.shape[0] == 0:
        return np.zeros(np.shape(rhs))
    part = subdivision or partition(a, points, subdomains, overlap, connected)
    source = MatrixRows(a, b)
    info.seconds_setup = time.perf_counter() - t0
    x = solve_subdomains(source, part, engine, context, rtol, max_iterations, info)
    return x.reshape(np.shape(rhs))
