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
  rings of the matrix's graph. Rings follow faces, not distances: a core vertex's every neighbour in ``A``
  lies inside its subdomain whatever the faces' size (the houses' boxes are faces metres wide);
* local solves ``A_i = R_i A R_i^T`` (the subdomain's principal block: zero Dirichlet data outside), a
  SuperLU factor made once per subdomain where its tasks run and reused by every iteration;
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

CG stops at a relative residual of ``rtol`` per column (default 1e-10, the level's multigrid CG's). In each
iteration the driver sends subdomain ``i`` only its residual restricted to the subdomain (to the same
worker each iteration where the engine can: its factor is made once) and adds the results in subdomain
order, and every reduction is numpy's pairwise sum (no threaded BLAS): the same inputs
give the same bytes whichever engine, worker, thread count or completion order.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu

from neuralao.pipeline.engines.engine import Context, Shared, Task, content_key
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


@dataclass
class SolveInfo:
    """What a partitioned solve measured (filled in by :func:`solve_partitioned`)."""

    iterations: list[int] = field(default_factory=list)  # CG iterations per column
    residuals: list[float] = field(default_factory=list)  # final relative residual per column
    subdomain_vertices: list[int] = field(default_factory=list)  # unknowns of each subdomain (with overlap)
    coarse_size: int = 0  # coarse aggregates
    seconds_setup: float = 0.0  # driver: partition, subdomain blocks, coarse factor
    seconds_tasks: list[float] = field(default_factory=list)  # each local task (a subdomain's first: +factor)
    seconds_driver: float = 0.0  # driver: the iterations' own work (matvecs, coarse solves), not the local

    @property
    def largest_task(self) -> float:
        return max(self.seconds_tasks, default=0.0)


# --------------------------------------------------------------------------- partition


def bisect(points: np.ndarray, count: int) -> np.ndarray:
    """Recursive coordinate bisection: (n,) int64 part of each of ``points`` (n, 3) float, in 0..count-1;
    parts of equal size (to one point), each cut across the longest side of its points' bounding box. A
    cut takes the points below the cut's value (numpy's selection finds it in linear time: the value is the
    same whichever algorithm finds it) and, of the points at that value, the lowest-numbered."""
    xyz = np.ascontiguousarray(np.asarray(points, np.float64).T)  # (3, n): contiguous rows reduce fast
    part = np.zeros(xyz.shape[1], np.int64)
    stack = [(np.arange(xyz.shape[1]), count, 0)]
    while stack:
        idx, k, first = stack.pop()
        if k == 1 or len(idx) == 0:
            part[idx] = first
            continue
        p = xyz[:, idx]
        axis = int(np.argmax(p.max(axis=1) - p.min(axis=1)))
        low = k // 2
        cut = (len(idx) * low) // k
        take = np.zeros(len(idx), bool)
        if cut > 0:
            value = np.partition(p[axis], cut - 1)[cut - 1]  # the cut-th smallest
            take = p[axis] < value
            ties = np.flatnonzero(p[axis] == value)
            take[ties[: cut - int(take.sum())]] = True
        stack.append((idx[~take], k - low, first + low))
        stack.append((idx[take], low, first))
    return part


def grow(graph: sp.csr_matrix, vertices: np.ndarray, rings: int) -> np.ndarray:
    """(ascending int64) ``vertices`` and every vertex within ``rings`` edges of them in ``graph`` (n, n)."""
    inside = np.zeros(graph.shape[0], bool)
    inside[vertices] = True
    frontier = vertices
    for _ in range(rings):
        reach = graph[frontier].indices
        frontier = np.unique(reach[~inside[reach]])
        if len(frontier) == 0:
            break
        inside[frontier] = True
    return np.flatnonzero(inside)


def partition(
    a, points: np.ndarray, count: int, overlap: int = OVERLAP, connected: bool = False
) -> Partition:
    """Subdomains of the system ``a`` (n, n) sparse, its unknowns at ``points`` (n, 3): ``count`` cores by
    :func:`bisect` (at most one per unknown), grown by ``overlap`` rings of ``a``'s graph, and the coarse
    aggregates. ``connected``: ``a`` is known to be one connected component."""
    a = sp.csr_matrix(a)
    n = a.shape[0]
    if len(points) != n:
        raise NeuralaoError(f"{len(points)} vertex positions for a system of {n} unknowns")
    if count < 1 or overlap < 0:
        raise NeuralaoError(f"need subdomains >= 1 and overlap >= 0, got {count} and {overlap}")
    core = bisect(points, max(1, min(count, n)))
    parts = [grow(a, np.flatnonzero(core == i), overlap) for i in range(int(core.max(initial=0)) + 1)]
    if connected:  # the caller's system is one connected component: no need to find them
        ncomp, component = 1, np.zeros(n, np.int64)
    else:
        ncomp, component = connected_components(a, directed=False)
    _, coarse = np.unique(core * ncomp + component, return_inverse=True)
    return Partition(core, parts, coarse.reshape(-1).astype(np.int64))


# --------------------------------------------------------------------------- local solves (tasks)


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


class Subdomains:
    """The subdomain blocks of one partitioned system (k csc matrices (n_i, n_i)) and, where tasks ran, their
    factors: each made by the first task that needs it and kept for the later iterations. Travels to the
    workers once (:class:`neuralao.pipeline.engines.engine.Shared`), without its factors."""

    def __init__(self, blocks: list[sp.csc_matrix]):
        self.blocks = blocks
        self.factors: dict[int, Any] = {}

    def __getstate__(self) -> dict:
        return {"blocks": self.blocks, "factors": {}}  # a factor is remade where it is needed

    def solve(self, i: int, r: np.ndarray) -> np.ndarray:
        """A_i^-1 r for r (n_i, c) float64: a pure function of block i and r (the factor is a cache)."""
        if i not in self.factors:
            self.factors[i] = factorise(self.blocks[i])
        return self.factors[i].solve(np.ascontiguousarray(r, np.float64))


def local_solve(state, args) -> dict[str, np.ndarray]:
    """Engine task (reads no state): {"v": A_i^-1 r_i (n_i, c), "seconds"}; args (subdomains, i, r_i)."""
    subdomains, i, r = args
    t0 = time.perf_counter()
    v = subdomains.solve(i, r)
    return {"v": v, "seconds": np.array(time.perf_counter() - t0)}


def _no_state(payload) -> None:
    return None


# A stateless context for the local solves of callers that pass none.
STATELESS = Context("schwarz", _no_state, None)


# --------------------------------------------------------------------------- the solve


class _Preconditioner:
    """The balancing two-level Schwarz preconditioner (module doc) over a partition of ``a``; its local
    solves run as tasks of ``engine`` (None: in this process)."""

    def __init__(self, a: sp.csr_matrix, part: Partition, engine, context: Context, info: SolveInfo):
        self.part, self.engine, self.context, self.info = part, engine, context, info
        self.seconds_local = 0.0  # wall seconds of the local solves (tasks, sending, gathering)
        n, m = a.shape[0], int(part.coarse.max(initial=-1)) + 1
        self.m = m
        z = sp.csr_matrix((np.ones(n), (np.arange(n), part.coarse)), shape=(n, m))
        # A Z and (A Z)^T: the coarse terms' products with A cost a sparse (n, m) product, not a matvec of A.
        self.az = (a @ z).tocsr()
        self.azt = self.az.T.tocsr()
        self.coarse = factorise(z.T.tocsr() @ self.az)
        # Every subdomain's vertices end to end: one gather restricts a vector to them all, one bincount
        # adds the subdomains' results back (each vertex's terms in subdomain order, as one by one).
        self.joined = np.concatenate(part.parts) if part.parts else np.zeros(0, np.int64)
        self.splits = np.cumsum([len(p) for p in part.parts])[:-1]
        self.subdomains: Subdomains | Shared = Subdomains([a[idx][:, idx].tocsc() for idx in part.parts])
        if engine is not None:  # sent once per worker; the key covers everything the blocks are cut from
            key = content_key("schwarz", a.indptr, a.indices, a.data, *part.parts)
            self.subdomains = Shared(key, self.subdomains)
        info.coarse_size = m
        info.subdomain_vertices = [len(p) for p in part.parts]

    def local(self, rs: list[np.ndarray]) -> list[np.ndarray]:
        """S r of each vector of ``rs`` (n,): every subdomain's Dirichlet solve, added in subdomain order."""
        t0 = time.perf_counter()
        n = len(rs[0])
        gathered = np.empty((len(self.joined), len(rs)))
        for j, r in enumerate(rs):  # a column at a time: 4x faster than rows of a stacked array
            np.take(r, self.joined, out=gathered[:, j])
        restricted = np.split(gathered, self.splits)
        args = ((self.subdomains, i, r) for i, r in enumerate(restricted))
        if self.engine is None:
            results = [local_solve(None, a) for a in args]
        else:
            results = [None] * len(restricted)
            tasks = (Task(self.context, local_solve, a, affinity=a[1]) for a in args)  # same worker each time
            for i, res in self.engine.map(tasks):
                results[i] = res
        v = np.concatenate([res["v"] for res in results]) if results else np.zeros((0, len(rs)))
        out = [np.bincount(self.joined, weights=v[:, j], minlength=n) for j in range(len(rs))]
        self.info.seconds_tasks.extend(float(res["seconds"]) for res in results)
        self.seconds_local += time.perf_counter() - t0
        return out

    def __call__(self, rs: list[np.ndarray]) -> list[np.ndarray]:
        """M^-1 r of each vector of ``rs`` (n,)."""
        coarse = self.part.coarse  # Z x is x[coarse]; Z^T r is r summed per aggregate
        cs = [self.coarse.solve(np.bincount(coarse, weights=r, minlength=self.m)) for r in rs]  # Q r = Z c
        ys = self.local([r - self.az @ c for r, c in zip(rs, cs, strict=True)])
        return [(c - self.coarse.solve(self.azt @ y))[coarse] + y for c, y in zip(cs, ys, strict=True)]


def _dot(x: np.ndarray, y: np.ndarray) -> float:
    """x . y by numpy's pairwise sum, not a BLAS whose threads may split the sum differently."""
    return float(np.add.reduce(x * y))


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
    (module doc). Returns v like ``rhs``, float64, not clipped.

    a : (n, n) scipy.sparse, symmetric positive definite; rhs : (n,) or (n, c) float; points : (n, 3) float,
    the position of each unknown. ``engine`` (None: this process) runs the local solves, one task per
    subdomain and iteration, under ``context`` (None: a stateless one; a caller whose workers already hold
    a context passes it, so no state is built or evicted for the solve). ``info`` (filled in): iterations,
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
    precond = _Preconditioner(a, part, engine, context or STATELESS, info)
    info.seconds_setup = time.perf_counter() - t0
    t1 = time.perf_counter()
    x, info.iterations, info.residuals = _pcg(a, b, precond, rtol, max_iterations)
    info.seconds_driver = time.perf_counter() - t1 - precond.seconds_local
    return x.reshape(np.shape(rhs))


def _pcg(a, b: np.ndarray, precond, rtol: float, max_iterations: int):
    """Preconditioned CG on every column of ``b`` (n, c) in lockstep, so each iteration's local solves serve
    every column still running; a converged column stops. Returns (x (n, c), iterations, relative
    residuals)."""
    c = b.shape[1]
    x = [np.zeros(b.shape[0]) for _ in range(c)]
    r = [np.ascontiguousarray(b[:, j]) for j in range(c)]
    scale = [max(np.sqrt(_dot(v, v)), 1e-300) for v in r]
    residual = [np.sqrt(_dot(v, v)) / s for v, s in zip(r, scale, strict=True)]
    active = [j for j in range(c) if residual[j] > rtol]
    p: list[np.ndarray | None] = [None] * c
    rz = [0.0] * c
    iterations = [0] * c
    while active:
        if max(iterations) >= max_iterations:
            raise NeuralaoError(
                f"the partitioned least-squares CG did not converge in {max_iterations} iterations "
                f"(relative residuals {', '.join(f'{v:.1e}' for v in residual)}; tolerance {rtol:.0e})"
            )
        z = dict(zip(active, precond([r[j] for j in active]), strict=True))
        for j in active:
            rz_new = _dot(r[j], z[j])
            p[j] = z[j] if p[j] is None else z[j] + (rz_new / rz[j]) * p[j]
            rz[j] = rz_new
            q = a @ p[j]
            alpha = rz[j] / _dot(p[j], q)
            x[j] += alpha * p[j]
            r[j] -= alpha * q
            iterations[j] += 1
            residual[j] = np.sqrt(_dot(r[j], r[j])) / scale[j]
        active = [j for j in active if residual[j] > rtol]
    return np.stack(x, axis=1), iterations, [float(v) for v in residual]
