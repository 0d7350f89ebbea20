"""The heavy stages of a level bake as tasks of an engine, one piece
(:mod:`neuralao.pipeline.bakes.level_pieces`) or a block of one piece's samples at a time.

Every task is a pure function of its arguments and of the worker's state (the opaque level's labeller,
built from the level's meshes and instance transforms where the task runs), so a local and a Ray bake write
the same bytes. The driver sends each task what only it holds (a piece's traced values, its vertex AO),
writes each result to ``OUT/stages/<stage>/`` as it arrives, and keeps none of them: a killed bake's rerun
skips the files it finds, and the driver's memory is one piece's, not the level's.
"""

from __future__ import annotations

import copy
import heapq
import itertools
import threading
import time
import zipfile
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu
from tqdm import tqdm

from neuralao.pipeline.bakes.level_pieces import (
    Piece,
    PieceIndex,
    SampleRule,
    cached_block,
    cached_piece,
    face_samples,
    instance_vertices,
    remembered,
)
from neuralao.pipeline.bakes.level_settings import LevelBakeSettings, TraceSettings, blend, halves
from neuralao.pipeline.engines.engine import Context, LocalEngine, Shared, Task, content_key, no_state
from neuralao.pipeline.geometry.least_squares import (
    Whole,
    fit_least_squares,
    normal_equations,
    ridge_of,
    solve_amg,
    touching_faces,
    vertex_equations,
    with_ridge,
)
from neuralao.pipeline.geometry.level_files import GltfWriter, Level, flatten
from neuralao.pipeline.geometry.partitioned_solve import (
    Partition,
    SolveInfo,
    mesh_partition,
    solve_partitioned,
    solve_subdomains,
)
from neuralao.pipeline.geometry.scene import Scene, scene_from_arrays
from neuralao.pipeline.geometry.surface import (
    face_areas,
    interpolate,
    samples_in_range,
    samples_per_face,
    surface_samples,
    vertex_colours,
    vertex_components,
)
from neuralao.pipeline.tracing.labeller import LabelSettings
from neuralao.pipeline.tracing.level_tracer import LevelLabeller, resample_in_spheres
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import remove_stale_temporaries, write_npz

# --------------------------------------------------------------------------- scenes and worker state


def opaque_scene(level: Level) -> Scene:
    """Every static instance (first, in flatten order), then every blocker instance, as one scene."""
    rv, rf, _ = flatten(level, level.nodes_with("static"))
    bv, bf, _ = flatten(level, level.nodes_with("blocker"))
    return scene_from_arrays(
        np.concatenate([rv, bv]),
        np.concatenate([rf, bf + len(rv)]),
        "opaque",
        level.source,
        drop_degenerate=False,
    )


def gold_scene(level: Level) -> Scene:
    """The decorators' gold standard scene: the opaque level plus every tree instance, opaque."""
    opaque = opaque_scene(level)
    tv, tf, _ = flatten(level, level.nodes_with("tree"))
    return scene_from_arrays(
        np.concatenate([opaque.vertices, tv]),
        np.concatenate([opaque.faces, tf + len(opaque.vertices)]),
        "gold",
        drop_degenerate=False,
    )


@dataclass
class PieceState:
    """What a worker holds for a bake: the opaque labeller and the level it cuts pieces from (the foliage
    travels with the tasks that trace it: :func:`shared_foliage`)."""

    labeller: LevelLabeller | None  # None: a state for tasks that trace nothing
    level: Level
    index: PieceIndex
    key: str


def _opaque_state(payload) -> PieceState:
    level, index, settings, bvh, key = payload
    return PieceState(LevelLabeller(opaque_scene(level), settings, bvh), level, index, key)


class LabellerFrame:
    """The local frame (``center``, ``scale``) and label settings of the opaque labeller, without its scene:
    what the driver needs to build the foliage in the frame the workers trace in."""

    def __init__(self, center: np.ndarray, scale: float, settings: LabelSettings):
        self.center, self.scale, self.settings = np.asarray(center, np.float64), float(scale), settings
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise NeuralaoError(f"the level has no extent (diagonal {self.scale})")


def worker_settings(settings: LabelSettings, engine) -> LabelSettings:
    """``settings`` with the engine's threads per task (where it sets them)."""
    if engine is not None and engine.threads is not None:
        return replace(settings, workers=engine.threads)
    return settings


def opaque_context(
    key: str,
    level: Level,
    index: PieceIndex,
    settings: LabelSettings,
    bvh: str = "fast",
) -> Context:
    """The engine context of the opaque labeller: workers build it from the level's meshes and transforms
    (heavy: a worker holds no other big state beside it); ``bvh``: its Embree scene (``Labeller.bvh``).
    ``key``: the level's and its pieces' (:func:`shared_level`). The foliage is not in it, so its build can
    start as soon as the level is cut into pieces: the tasks that trace the foliage carry it
    (:func:`shared_foliage`)."""
    payload = (*shared_level(key, level, index), settings, bvh, key)
    return Context(f"level-trace/{content_key(key, settings, bvh)}", _opaque_state, payload, heavy=True)


def shared_foliage(foliage, settings: LabelSettings, foliage_key: str) -> Shared | None:
    """The foliage as an item of the opaque trace's tasks' args: it travels to a worker once and is held
    there beside the opaque BVH, for every task that traces it (None: no foliage). ``foliage_key``: a hash
    of what made it; ``settings``: the labeller's, whose frame it was built in."""
    if foliage is None:
        return None
    return Shared(f"foliage/{content_key(foliage_key, settings)}", foliage)


def shared_level(key: str, level: Level, index: PieceIndex | None) -> tuple[Shared, Shared]:
    """The level and its pieces as items of the level's contexts' payloads: each travels to a worker once
    and is held once there, whichever of the contexts it builds (``key``: a hash of the level's bytes and
    its cut into pieces, the bake's geometry key)."""
    return Shared(f"level/{key}", level), Shared(f"pieces/{key}", index)


def _pieces_state(payload) -> PieceState:
    level, index, key = payload
    return PieceState(None, level, index, key)


def pieces_context(key: str, level: Level, index: PieceIndex, heavy: bool = False) -> Context:
    """The level and its pieces without a BVH: the state of the tasks that trace nothing (solve, output).
    ``heavy``: for the LOD's one simplification of the flattened level (gigabytes on its worker for a big
    world), which has its worker drop the opaque BVH first."""
    name = "level-simplify" if heavy else "level-pieces"
    return Context(f"{name}/{key}", _pieces_state, (*shared_level(key, level, index), key), heavy=heavy)


def _piece_fn(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: ``fn(level, index, piece, *rest)`` of a piece function of
    :mod:`neuralao.pipeline.bakes.level_pieces` on the worker's copy of the level."""
    fn, piece, *rest = args
    return fn(state.level, state.index, piece, *rest)


def engine_each(runner, ctx: Context) -> Callable:
    """``each(fn, jobs, *args)`` for :func:`neuralao.pipeline.bakes.level_pieces.sample_rule`: a task per
    job (piece, first face, stop face) on ``runner``, the results yielded in job order (they arrive in
    any)."""

    def each(fn, jobs, *args):
        results = dict(runner.map(Task(ctx, _piece_fn, (fn, *job, *args)) for job in jobs))
        return (results.pop(i) for i in range(len(jobs)))

    return each


# --------------------------------------------------------------------------- per-task files


class TaskFiles:
    """A stage's task results, one npz each under ``folder`` (``STEM.npz``) stamped with the bake's key:
    written as each arrives and kept for the later stages; a missing, partial or stale one is redone."""

    def __init__(self, folder: Path, key: str):
        self.folder, self.key = Path(folder), key
        self.folder.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(self.folder)

    def path(self, stem: str) -> Path:
        return self.folder / f"{stem}.npz"

    def get(self, stem: str, keys: Iterable[str] | None = None) -> dict[str, np.ndarray] | None:
        """The result of task ``stem``: every array, or those of ``keys`` (the others are not read); None
        if it is missing, unreadable, of another bake or without one of ``keys``."""
        try:
            with np.load(self.path(stem), allow_pickle=False) as z:
                names = [k for k in z.files if k != "_key"] if keys is None else list(keys)
                if str(z["_key"]) != self.key or not set(names) <= set(z.files):
                    return None
                return {k: z[k] for k in names}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return None

    def has(self, stem: str, keys: Iterable[str] = ()) -> bool:
        """Whether task ``stem``'s result of this bake is here, with ``keys`` among its arrays."""
        try:
            with np.load(self.path(stem), allow_pickle=False) as z:
                return str(z["_key"]) == self.key and set(keys) <= set(z.files)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return False

    def put(self, stem: str, data: dict[str, np.ndarray]) -> None:
        # not flushed to the disk: a file a power cut leaves unreadable is redone, like a missing one
        write_npz(self.path(stem), sync=False, _key=np.array(self.key), **data)

    def keep_only(self, stems: set[str]) -> None:
        """Remove the files of tasks this bake does not have (an earlier bake's pieces)."""
        for p in self.folder.glob("*.npz"):
            if p.stem not in stems:
                p.unlink()


def run_to_files(
    files: TaskFiles,
    runner,
    jobs: list[tuple[str, Callable[[], Task]]],
    desc: str,
    progress: bool,
    keep: frozenset[str] = frozenset(),
    keys: tuple[str, ...] | None = None,
    aside: tuple[TaskFiles, list] | None = None,
) -> Iterator[tuple[str, dict[str, np.ndarray], bool]]:
    """Run the jobs (file stem, task maker) a file does not hold yet on ``runner``, writing each result as it
    arrives; then yield (stem, result, reused) for every job in order, one file read at a time. ``keep``:
    stems of files the stage writes otherwise (left in place). ``keys``: the arrays of each result to read
    back (None: all; a file without one of them is redone). ``aside``: (files, jobs) of another stage's
    tasks run first in the same wave (``Task.aside``), each result put in those files."""
    files.keep_only({stem for stem, _ in jobs} | keep)
    pending = unfinished(files, jobs, keys)
    other_files, other = aside or (None, [])
    tasks = itertools.chain(
        (replace(make(), aside=True) for _, make in other), (make() for _, make in pending)
    )
    with tqdm(total=len(pending), desc=desc, disable=not progress, leave=False) as bar:
        for i, r in runner.map(tasks):
            if i < len(other):
                other_files.put(other[i][0], r)
                continue
            files.put(pending[i - len(other)][0], r)
            bar.update(1)
    fresh = {stem for stem, _ in pending}
    for stem, _ in jobs:
        data = files.get(stem, keys)
        if data is None:
            raise NeuralaoError(f"{files.path(stem)} could not be read back: is the disk full?")
        yield stem, data, stem not in fresh


def unfinished(files: TaskFiles, jobs, keys: tuple[str, ...] | None = None) -> list:
    """The jobs (file stem, task maker) whose file ``files`` does not hold with ``keys`` (None: any)."""
    return [(stem, make) for stem, make in jobs if not files.has(stem, keys or ())]


def piece_stem(piece: Piece) -> str:
    return f"p{piece.index:05d}"


# --------------------------------------------------------------------------- trace


def trace_jobs(ctx: Context, pieces: list[Piece], rule: SampleRule, s: LevelBakeSettings, foliage=None):
    """(stem, task maker) per block of ``trace.block_samples`` samples of each piece; ``foliage``: the
    :func:`shared_foliage` its rays cross (None: none)."""
    block, jobs = s.trace.block_samples, []
    for p in pieces:
        for lo in range(0, p.ns, block):
            args = (p, rule, lo, min(lo + block, p.ns), halves(s), foliage)
            jobs.append((f"{piece_stem(p)}_{lo // block:05d}", lambda a=args: Task(ctx, _trace_block, a)))
    return jobs


def _trace_block(state: PieceState, args) -> dict[str, np.ndarray]:
    piece, rule, lo, hi, half, foliage = args
    _, samples = cached_block(state.key, state.level, state.index, piece, rule, lo, hi)
    ids = np.arange(piece.s0 + lo, piece.s0 + hi, dtype=np.int64)
    ao, valid = state.labeller.obscurance(samples.points, samples.normals, half, foliage, ids=ids)
    # The valid samples' weight and weighted values: every piece's least squares takes the level's.
    w = samples.weights[valid]
    return {
        "ao": ao,
        "valid": valid,
        "weight": np.array(w.sum()),
        "weighted": w @ ao[valid].astype(np.float64),
    }


def trace_blocks(files: TaskFiles, piece: Piece, block: int) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """(first sample, (m, 2) float32 obscurance, (m,) valid flags) of each traced block of a piece, from its
    block files, in sample order."""
    for lo in range(0, piece.ns, block):
        data = files.get(f"{piece_stem(piece)}_{lo // block:05d}")
        if data is None:
            raise NeuralaoError(
                f"trace block {lo // block} of piece {piece.index} is missing from {files.folder}"
            )
        yield lo, data["ao"], data["valid"]


def piece_trace(files: TaskFiles, piece: Piece, block: int) -> tuple[np.ndarray, np.ndarray]:
    """The traced (ns, 2) float32 obscurance and (ns,) valid flags of a piece, from its block files."""
    ao, valid = np.zeros((piece.ns, 2), np.float32), np.zeros(piece.ns, bool)
    for lo, a, v in trace_blocks(files, piece, block):
        ao[lo : lo + len(v)], valid[lo : lo + len(v)] = a, v
    return ao, valid


# --------------------------------------------------------------------------- least squares


def _solve_piece(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: the least-squares vertex values of one piece (both distances)."""
    piece, rule, ao, valid, t, whole = args
    scene, samples = cached_piece(state.key, state.level, state.index, piece, rule)
    return _piece_values(scene, samples, ao, valid, t, whole)


def _piece_values(scene, samples, ao, valid, t: TraceSettings, whole, engine=None, context=None):
    """A piece's solve result: its "short" and "long" vertex values and the solve's seconds."""
    timing: dict[str, float] = {}
    v = fit_level(scene, samples, ao, valid, t, engine=engine, timing=timing, whole=whole, context=context)
    return {"short": v[:, 0], "long": v[:, 1], **{f"seconds_{k}": np.array(x) for k, x in timing.items()}}


def solve_jobs(ctx, pieces, rule, trace_files: TaskFiles, s: LevelBakeSettings, whole: Whole):
    def make(p: Piece) -> Task:
        ao, valid = piece_trace(trace_files, p, s.trace.block_samples)
        return Task(ctx, _solve_piece, (p, rule, ao, valid, s.trace, whole))

    return [(piece_stem(p), lambda p=p: make(p)) for p in pieces]


def solve_stage(
    files: TaskFiles,
    runner,
    ctx: Context,
    pieces,
    rule,
    trace_files: TaskFiles,
    s,
    whole,
    progress: bool,
    plans: TaskFiles,
    keys: tuple[str, ...] | None = None,
    aside: tuple[TaskFiles, list] | None = None,
) -> Iterator[tuple[str, dict[str, np.ndarray], bool]]:
    """(stem, result, reused) of every piece's least squares. With ``trace.subdomains`` > 1 a piece with a
    connected component of at least ``trace.component_vertices`` vertices is solved from here in subdomains
    (:func:`_solve_piece_here`, cut by its plan: :func:`solve_plans`, whose ``plans`` files the trace's wave
    may have made already): each subdomain's worker makes its rows of the equations, and the iteration
    runs here (:mod:`neuralao.pipeline.geometry.partitioned_solve`), its steps tasks of ``runner`` under
    ``ctx`` (its workers hold it already); a piece of that many vertices in smaller components only, in groups
    of them (:class:`GroupSolve`). Every other piece is one task. The results are the same bytes with
    any engine: each task is a pure function of its arguments, and the driver adds the results in a fixed
    order. ``keys``: the arrays of each result read back (None: all). ``aside``: (files, jobs (stem, task
    maker)) of another stage's tasks that need nothing of this one, run in its first wave, each result put in
    those files."""
    t = s.trace
    big = [p for p in pieces if splits(t) and p.nv >= t.component_vertices]
    # a piece whose result is stored is read back wherever it was solved: only the others are looked at
    todo = [p for p in big if not files.has(piece_stem(p))]
    made = solve_plans(plans, runner, ctx, todo, t)
    found = {i for i, plan in made.items() if int(plan["largest"]) >= t.component_vertices}
    here = [p for p in big if p.index in found or files.has(piece_stem(p))]
    # A big piece of small components only (a soup, a piece of many instances): its components in groups,
    # a task each (they share no vertex: each group's equations are its own).
    grouped = [p for p in todo if p.index not in found]
    stems = frozenset(piece_stem(p) for p in here + grouped)
    rest = [p for p in pieces if piece_stem(p) not in stems]
    jobs = solve_jobs(ctx, rest, rule, trace_files, s, whole)
    files.keep_only({piece_stem(p) for p in pieces})
    # The other pieces' solves and the groups run beside the first big piece's assembly, in one wave: on many
    # machines they then take no wave of their own after the big pieces' iterations. A group's result is
    # kept here until its piece's are all in (then written as the piece's: a rerun redoes a piece's groups).
    groups = GroupSolve(ctx, grouped, rule, trace_files, s, whole, files.key)
    pending = unfinished(files, jobs, keys) + groups.jobs("rows")
    others = len(pending)
    other_files, other_jobs = aside or (None, [])
    pending += other_jobs
    first = tuple(stem for stem, _ in pending)  # the first wave's, in order

    def deliver(i: int, result: dict[str, np.ndarray]) -> None:
        stem = first[i]
        if i >= others:
            other_files.put(stem, result)
        elif not groups.take(stem, result):
            files.put(stem, result)

    fresh = {stem for stem, _ in pending[:others] if not groups.owns(stem)} | {piece_stem(p) for p in grouped}
    for p in here:
        if not files.has(piece_stem(p)):
            here_args = (rule, trace_files, s, whole, plan_partition(made[p.index]), pending, deliver)
            result = _solve_piece_here(runner, ctx, p, *here_args)
            files.put(piece_stem(p), result)
            fresh.add(piece_stem(p))
            pending = []
    if pending:
        with tqdm(total=len(pending), desc="solve", disable=not progress, leave=False) as bar:
            for i, result in runner.map(make() for _, make in pending):
                deliver(i, result)
                bar.update(1)
    if grouped:  # each group solved with its piece's ridge, from its groups' largest diagonal entries
        solves = groups.jobs("solve")
        for i, result in runner.map(make() for _, make in solves):
            groups.take(solves[i][0], result)
        for p in grouped:
            files.put(piece_stem(p), groups.joined(p))
    for p in pieces:
        stem = piece_stem(p)
        if (data := files.get(stem, keys)) is None:
            raise NeuralaoError(f"{files.path(stem)} could not be read back: is the disk full?")
        yield stem, data, stem not in fresh


def group_stem(piece: Piece, group: int) -> str:
    return f"{piece_stem(piece)}_g{group:04d}"


class GroupSolve:
    """The least squares of big pieces of small components only (:func:`solve_stage`), each in
    :func:`group_count` groups of whole components (:func:`component_groups`), two waves of a task per group:
    its rows made where it runs (:class:`PieceRows`, kept there for the next) and their largest diagonal
    entry; then, with the piece's ridge (from the largest of its groups': the one the piece's one-task solve
    adds, so the values are that solve's), a sparse direct solve (:func:`_group_step`). The piece's traces
    travel to each worker once (a :class:`Shared` item under the solve's ``key`` and the piece); a group's
    two tasks go to one worker (``Task.affinity``), and one that lost its rows makes them again. Results are
    kept here until a piece's are all in (:meth:`joined`: a rerun redoes a piece's groups)."""

    def __init__(self, ctx, pieces, rule, trace_files: TaskFiles, s: LevelBakeSettings, whole: Whole, key):
        self.ctx, self.rule, self.trace_files = ctx, rule, trace_files
        self.s, self.whole, self.key = s, whole, key
        self.count = {p.index: group_count(p, s.trace) for p in pieces}
        self.owner = {group_stem(p, g): (p, g) for p in pieces for g in range(self.count[p.index])}
        self.largest: dict[int, float] = {}  # piece -> largest diagonal entry of its groups so far
        self.assembly: dict[int, float] = {}  # piece -> its groups' seconds making their rows
        self.parts: dict[int, list] = {p.index: [] for p in pieces}
        self._last: dict[str, Any] = {}

    def owns(self, stem: str) -> bool:
        return stem in self.owner

    def _source(self, p: Piece) -> Shared:
        if self._last.get("piece") != p.index:
            ao, valid = piece_trace(self.trace_files, p, self.s.trace.block_samples)
            rows = PieceRows(p, self.rule, ao, valid, self.s.trace.alpha, self.whole)
            shared = Shared(content_key(self.key, "groups", piece_stem(p)), rows)
            self._last.update(piece=p.index, source=shared)
        return self._last["source"]

    def jobs(self, step: str) -> list[tuple[str, Callable[[], Task]]]:
        """(stem, task maker) per group of every piece: its "rows", or its "solve" (after every "rows")."""
        out = []
        for i, (stem, (p, g)) in enumerate(self.owner.items()):
            ridge = ridge_of(self.largest[p.index]) if step == "solve" else None

            def make(p=p, g=g, ridge=ridge, i=i) -> Task:
                args = (self._source(p), self.key, g, self.count[p.index], ridge)
                return Task(self.ctx, _group_step, args, affinity=i)

            out.append((stem, make))
        return out

    def take(self, stem: str, result: dict[str, np.ndarray]) -> bool:
        """Keep a group's result (False: ``stem`` is no group's)."""
        if stem not in self.owner:
            return False
        p, _ = self.owner[stem]
        if "diagonal" in result:
            self.largest[p.index] = max(self.largest.get(p.index, -np.inf), float(result["diagonal"]))
            self.assembly[p.index] = self.assembly.get(p.index, 0.0) + float(result["seconds_assembly"])
        else:
            self.parts[p.index].append(result)
        return True

    def joined(self, piece: Piece) -> dict[str, np.ndarray]:
        """The piece's solve result (as :func:`_solve_piece`'s) from its groups'."""
        v = np.full((piece.nv, 2), np.nan, np.float32)
        times = dict.fromkeys(("assembly", "blocks", "driver", "largest_block"), 0.0)
        times["assembly"] = self.assembly.pop(piece.index, 0.0)
        for r in self.parts.pop(piece.index):
            v[r["vertices"]] = r["v"]
            for k in ("assembly", "blocks", "driver"):
                times[k] += float(r[f"seconds_{k}"])
            times["largest_block"] = max(times["largest_block"], float(r["seconds_largest_block"]))
        if np.isnan(v).any():
            raise NeuralaoError(f"piece {piece.index}: its component groups do not cover its vertices")
        return {"short": v[:, 0], "long": v[:, 1], **{f"seconds_{k}": np.array(x) for k, x in times.items()}}


# A group of a big piece's small components holds about component_vertices / GROUP_SHARE vertices (at most
# trace.subdomains groups): Table 1's Sponza (175,688 vertices, 6,132 components) in 8, none longer than a
# terrain subdomain's assembly; the 10x world's pieces of houses (524,280) in 21. Smaller groups only add
# tasks (two each) to the driver's work and, as each finds its piece's components, to one machine's.
GROUP_SHARE = 4


def group_count(piece: Piece, t: TraceSettings) -> int:
    """How many groups of its components :class:`GroupSolve` solves ``piece`` in."""
    return max(1, min(t.subdomains, -(-GROUP_SHARE * piece.nv // t.component_vertices)))


def component_groups(components: np.ndarray, count: int) -> np.ndarray:
    """(n,) int64: the group of each vertex, given its connected component (``components`` (n,)): the
    components packed, largest first, each into the group of fewest vertices so far (the lowest of equal
    ones), ``count`` groups whose sizes differ by at most the largest component's."""
    sizes = np.bincount(components)
    heap = [(0, g) for g in range(count)]
    of = np.empty(len(sizes), np.int64)
    for c in np.argsort(-sizes, kind="stable"):
        load, g = heapq.heappop(heap)
        of[c] = g
        heapq.heappush(heap, (load + int(sizes[c]), g))
    return of[components]


# A worker's latest pieces' component groups, by (bake, piece, group count); and the rows of the groups
# whose first task ran here, by (solve key, piece, group), until their second takes them.
_GROUPS: OrderedDict[tuple, np.ndarray] = OrderedDict()
_GROUP_ROWS: dict[tuple, tuple] = {}
_GROUP_LOCK = threading.Lock()


def _group_step(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: one group of whole connected components of a piece (:class:`GroupSolve`). Without a
    ridge: its vertices' rows (:class:`PieceRows`), kept here, and their largest diagonal entry. With one:
    the group's values by one sparse direct solve of its rows (kept, or made again) with that ridge: "v"
    (vertices, 2) float32 in [0, 1] and "vertices" (the piece's numbers, ascending)."""
    source, key, group, count, ridge = args
    t0 = time.perf_counter()
    piece = source.piece
    mine = (key, piece.index, group)
    with _GROUP_LOCK:
        made = _GROUP_ROWS.pop(mine, None) if ridge is not None else None
    if made is None:
        made = _group_rows(state, source, group, count)
    vertices, rows, rhs = made
    t1 = time.perf_counter()
    if ridge is None:
        with _GROUP_LOCK:
            _GROUP_ROWS[mine] = made
        diagonal = float(rows.diagonal().max()) if len(vertices) else -np.inf
        return {"diagonal": np.array(diagonal), "seconds_assembly": np.array(t1 - t0)}
    v = np.zeros((0, 2))
    if len(vertices):
        a, b = with_ridge(rows, rhs, source.whole.prior, ridge)
        v = splu(a).solve(b)
    took = time.perf_counter() - t1
    return {
        "vertices": vertices,
        "v": np.clip(v, 0.0, 1.0).astype(np.float32),
        "seconds_assembly": np.array(t1 - t0),
        "seconds_blocks": np.array(took),
        "seconds_largest_block": np.array(took),
        "seconds_driver": np.array(0.0),
    }


def _group_rows(state: PieceState, source: PieceRows, group: int, count: int) -> tuple:
    """(vertices, their rows (csr, square: whole components), rhs (vertices, c)) of one group."""
    piece = source.piece
    scene, _ = cached_piece(state.key, state.level, state.index, piece, None)
    labels = remembered(
        _GROUPS,
        (state.key, piece.index, count),
        lambda: component_groups(vertex_components(scene.faces, len(scene.vertices)), count),
    )
    vertices = np.flatnonzero(labels == group)
    if not len(vertices):
        return vertices, None, np.zeros((0, 2))
    columns, rows, rhs = source.rows(state, vertices)
    if not np.array_equal(columns, vertices):  # whole components couple to nothing outside them
        raise NeuralaoError(f"piece {piece.index}: a group of whole components has rows outside it")
    return vertices, rows, np.asarray(rhs, np.float64).reshape(len(vertices), -1)


def meshes(index: PieceIndex, piece: Piece) -> set[int]:
    """The meshes of a piece's instances."""
    return {index.nodes[k].mesh for k in index.table[piece.first : piece.stop, 0]}


def splits(t: TraceSettings) -> bool:
    """Whether the solve cuts pieces of at least ``component_vertices`` vertices (:func:`solve_stage`). The
    subdomains are cut from the mesh before the equations exist: their graph is the faces' when the
    regulariser couples every face. Without one (alpha 0) a big piece is one task, in subdomains there."""
    return t.solver == "components" and t.subdomains > 1 and t.alpha > 0


def plan_jobs(ctx: Context, pieces: list[Piece], t: TraceSettings) -> list[tuple[str, Callable[[], Task]]]:
    """(stem, task maker) of the solve's plan (:func:`_solve_plan`) of each of the ``pieces`` that may be
    solved in subdomains (:func:`solve_stage`: ``trace.subdomains`` > 1, the components solver with a
    regulariser, at least ``trace.component_vertices`` vertices) and has a mesh of that many vertices (a
    piece's instances share no vertex: a component that big lies in one of its meshes)."""
    if not splits(t):
        return []
    level, index, _ = ctx.value()
    at_least = t.component_vertices
    return [
        (piece_stem(p), lambda p=p: Task(ctx, _solve_plan, (p, at_least, t.subdomains)))
        for p in pieces
        if p.nv >= at_least and any(len(level.meshes[m].vertices) >= at_least for m in meshes(index, p))
    ]


def _solve_plan(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: a piece's plan for the partitioned solve, made from its mesh alone: "largest", the
    vertices of its largest connected component, and if that is at least ``at_least``, its subdomains
    (:func:`neuralao.pipeline.geometry.partitioned_solve.mesh_partition`: "core", "coarse", the parts joined
    in "parts" with their "part_sizes"; int32)."""
    piece, at_least, subdomains = args
    scene, _ = cached_piece(state.key, state.level, state.index, piece, None)
    components = vertex_components(scene.faces, len(scene.vertices))
    largest = int(np.bincount(components).max(initial=0))
    out = {"largest": np.array(largest)}
    if largest >= at_least:
        part = mesh_partition(scene.vertices, scene.faces, subdomains, components=components)
        out.update(
            core=part.core.astype(np.int32),
            coarse=part.coarse.astype(np.int32),
            parts=np.concatenate(part.parts).astype(np.int32),
            part_sizes=np.array([len(x) for x in part.parts], np.int64),
        )
    return out


def plan_partition(plan: dict[str, np.ndarray]) -> Partition:
    """The :class:`Partition` of a piece's plan (:func:`_solve_plan`)."""
    parts = np.split(plan["parts"].astype(np.int64), np.cumsum(plan["part_sizes"])[:-1])
    return Partition(plan["core"].astype(np.int64), parts, plan["coarse"].astype(np.int64))


def solve_plans(files: TaskFiles, runner, ctx: Context, pieces: list[Piece], t: TraceSettings) -> dict:
    """{piece index: plan} (:func:`_solve_plan`) of the ``pieces`` that may be solved in subdomains
    (:func:`plan_jobs`; the others have none): read from ``files`` (the trace's wave makes them beside its
    blocks), the missing ones made by a wave of ``runner`` (workers hold the level) and put there."""
    index = {piece_stem(p): p.index for p in pieces}
    return {
        index[stem]: plan
        for stem, plan, _ in run_to_files(files, runner, plan_jobs(ctx, pieces, t), "", False)
    }


def _solve_piece_here(
    runner,
    ctx: Context,
    piece: Piece,
    rule,
    trace_files: TaskFiles,
    s,
    whole,
    part: Partition,
    beside=(),
    deliver=None,
):
    """:func:`_solve_piece` with the driver as the coordinator, its equations never whole anywhere: the
    subdomains ``part`` (the piece's plan, :func:`solve_plans`) cut from the piece's mesh, each subdomain's
    worker makes its rows from the piece's samples on the faces that touch it (:class:`PieceRows`, the first
    wave) and keeps them for the CG's steps, and the coarse system is added up here from their shares. The
    driver reads the piece's traces, not its mesh or samples, and drops everything with the result.
    ``beside``: jobs (stem, task maker) of other pieces run in the first wave, each result handed to
    ``deliver(index in beside, result)`` as it arrives."""
    t0 = time.perf_counter()
    ao, valid = piece_trace(trace_files, piece, s.trace.block_samples)
    source = PieceRows(piece, rule, ao, valid, s.trace.alpha, whole)
    assembly = time.perf_counter() - t0
    info = SolveInfo()
    x = solve_subdomains(
        source,
        part,
        runner,
        ctx,
        info=info,
        ridge=whole.prior,
        beside=(make() for _, make in beside),
        aside=deliver,
    )
    v = np.clip(x, 0.0, 1.0).astype(np.float32)
    timing = {
        "assembly": assembly,
        "blocks": sum(info.seconds_tasks),
        "largest_block": info.largest_task,
        "driver": info.seconds_setup + info.seconds_driver,
    }
    return {"short": v[:, 0], "long": v[:, 1], **{f"seconds_{k}": np.array(x) for k, x in timing.items()}}


@dataclass(frozen=True)
class PieceRows:
    """The rows of a piece's normal equations, made where a subdomain's tasks run (the source of
    :func:`neuralao.pipeline.geometry.partitioned_solve.solve_subdomains`): from the worker's copy of the
    piece, the piece's samples on the faces that touch the subdomain (made there, bit for bit those the
    trace made: :func:`neuralao.pipeline.bakes.level_pieces.face_samples`) and their traced values."""

    piece: Piece
    rule: SampleRule
    ao: np.ndarray  # (ns, 2) float32: the piece's traced obscurance, both distances
    valid: np.ndarray  # (ns,) bool
    alpha: float
    whole: Whole

    def rows(self, state: PieceState, vertices: np.ndarray) -> tuple[np.ndarray, Any, np.ndarray]:
        """:func:`neuralao.pipeline.geometry.least_squares.vertex_equations` of the piece's ``vertices``."""
        scene, _ = cached_piece(state.key, state.level, state.index, self.piece, None)
        faces = touching_faces(scene.faces, vertices, len(scene.vertices))
        samples, numbers = face_samples(scene, self.piece, self.rule, faces, state.key)
        ao, valid = self.ao[numbers], self.valid[numbers]
        return vertex_equations(scene, faces, samples, ao, valid, self.alpha, self.whole, vertices)


def fit_level(
    scene: Scene,
    samples,
    values: np.ndarray,
    valid: np.ndarray,
    t: TraceSettings,
    engine=None,
    store=None,
    tag: str = "",
    timing: dict | None = None,
    whole: Whole | None = None,
    context: Context | None = None,
) -> np.ndarray:
    """:func:`neuralao.pipeline.geometry.least_squares.fit_least_squares` with the level's solver
    (``t.solver``, ``t.alpha``).

    "components": the normal equations are assembled here, split into their connected components (the
    matrix couples only vertices that share a face, so the blocks' solutions are the global solution),
    and each block, or a pack of small ones, is a task of ``engine`` (None: this process), its result
    kept in ``store`` (keys: ``tag`` and the block) as it arrives; with ``t.subdomains`` > 1 a big block is
    solved here by :func:`neuralao.pipeline.geometry.partitioned_solve.solve_partitioned`, its subdomain
    solves tasks of ``engine``. The tasks run under ``context`` (they read no state; None: a stateless
    one). Returns (n,) or (n, c) float32. ``timing`` (a dict, filled in): seconds of the assembly here, of
    all tasks, of the largest task (each task times itself, a stored one as it took then) and of the
    partitioned solves' own work here ("driver"). ``whole``: see
    :func:`neuralao.pipeline.geometry.least_squares.normal_equations` (a piece of a level)."""

    if t.solver != "components":
        t0 = time.perf_counter()
        v = fit_least_squares(scene, samples, values, valid, t.alpha, t.solver, whole)
        if timing is not None:
            took = time.perf_counter() - t0
            timing.update(assembly=0.0, blocks=took, largest_block=took, driver=0.0)
        return v
    t0 = time.perf_counter()
    a, rhs = normal_equations(scene, samples, values, valid, t.alpha, whole)
    timing = {} if timing is None else timing
    timing.update(assembly=time.perf_counter() - t0, blocks=0.0, largest_block=0.0, driver=0.0)
    return solve_equations(a, rhs, scene.vertices, t, engine, store, tag, timing, context)


def solve_equations(
    a, rhs: np.ndarray, points: np.ndarray, t: TraceSettings, engine, store, tag: str, timing: dict, context
) -> np.ndarray:
    """The "components" solve of :func:`fit_level` of the normal equations ``a`` (n, n) sparse, ``rhs``,
    their unknowns at ``points`` (n, 3); ``timing`` (keys as there) is added to (finding the components
    counts as assembly). Returns (n,) or (n, c) float32 in [0, 1]."""
    t0 = time.perf_counter()
    blocks = component_blocks(a, t.component_vertices, t.subdomains)
    a = a.tocsr()
    timing["assembly"] += time.perf_counter() - t0
    ctx = context or Context("level-solve", no_state, None)
    tasked = [b for b in blocks if b[1] != "partitioned"]

    def tasks():
        for idx, method in tasked:
            sub = a[idx][:, idx].tocsc()
            yield Task(
                ctx,
                _solve_block,
                (sub, rhs[idx], method),
                content_key("solve", tag, idx, method, sub.data, rhs[idx]),
            )

    out = np.empty(rhs.shape)
    for i, r in (engine or LocalEngine()).map(tasks(), store):
        out[tasked[i][0]] = r["v"]
        took = float(r.get("seconds", 0.0))
        timing["blocks"] += took
        timing["largest_block"] = max(timing["largest_block"], took)
    for idx, method in blocks:
        if method == "partitioned":
            info = SolveInfo()
            single = len(idx) == a.shape[0]  # one component (a terrain's piece): no copy of its block
            out[idx] = solve_partitioned(
                a if single else a[idx][:, idx],
                rhs if single else rhs[idx],
                points if single else points[idx],
                t.subdomains,
                engine=engine,
                context=ctx,
                info=info,
                connected=True,  # each block is a connected component
            )
            timing["blocks"] += sum(info.seconds_tasks)
            timing["largest_block"] = max(timing["largest_block"], info.largest_task)
            timing["driver"] += info.seconds_setup + info.seconds_driver
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def component_blocks(a, big: int, subdomains: int = 1) -> list[tuple[np.ndarray, str]]:
    """The connected components of the sparse symmetric ``a`` as solves: (vertex indices (ascending) int64,
    "amg" | "partitioned" | "direct"). A component of at least ``big`` vertices is a solve of its own: one
    multigrid-CG task, or with ``subdomains`` > 1 a partitioned CG; smaller ones (SuperLU) are packed,
    largest first, into tasks of about ``big`` vertices."""
    _, label = connected_components(a, directed=False)
    sizes = np.bincount(label)
    members = np.split(np.argsort(label, kind="stable"), np.cumsum(sizes)[:-1])
    blocks, pack, packed = [], [], 0
    for c in np.argsort(-sizes, kind="stable"):
        if sizes[c] >= big:
            blocks.append((members[c], "amg" if subdomains <= 1 else "partitioned"))
            continue
        pack.append(members[c])
        packed += sizes[c]
        if packed >= big:
            blocks.append((np.sort(np.concatenate(pack)), "direct"))
            pack, packed = [], 0
    if pack:
        blocks.append((np.sort(np.concatenate(pack)), "direct"))
    return blocks


def _solve_block(state, args) -> dict[str, np.ndarray]:
    """Engine task: one block of the normal equations (csc matrix, rhs, "direct" | "amg")
    -> {"v": solution}."""
    a, rhs, method = args
    t0 = time.perf_counter()
    v = splu(a).solve(rhs) if method == "direct" else solve_amg(a, rhs)
    return {"v": v, "seconds": np.array(time.perf_counter() - t0)}


# --------------------------------------------------------------------------- LOD (section 2.2.1)


def simplify(scene: Scene, reduction: float | None = None, target_count: int | None = None) -> Scene:
    """Quadric-error simplification (fast-simplification) to a fraction removed or a face count."""
    import fast_simplification  # measured: ~0.3 s to import; only the LOD stage needs it

    with _SIMPLIFY_LOCK:
        v, f = fast_simplification.simplify(
            scene.vertices.astype(np.float32),
            scene.faces.astype(np.int32),
            target_reduction=reduction,
            target_count=target_count,
        )
    if len(f) == 0:  # nothing left: the mesh is its own LOD
        return scene
    return scene_from_arrays(np.asarray(v, np.float64), np.asarray(f, np.int64), "lod1", scene.source)


# fast-simplification's passes: pass i collapses every edge whose quadric error is below
# 1e-9 (i + 3) ** agg (its Simplify.h); there are 100, so the last threshold is 1e-9 * 102 ** agg.
_PASS_THRESHOLD, _LAST_PASS_BASE = 1e-9, 102.0
# The simplifier keeps its mesh in module globals: one simplification at a time per process.
_SIMPLIFY_LOCK = threading.Lock()


def simplify_to_error(vertices: np.ndarray, faces: np.ndarray, max_error: float):
    """Quadric-error simplification that stops at an error instead of a face count.

    vertices : (n, 3) float64, faces : (m, 3) int64 -> (vertices (n', 3) float64, faces (m', 3) int64).
    No collapse is made whose quadric error (the sum of squared distances from the new vertex to the
    planes of the original faces merged into it, scene units squared) exceeds ``max_error``, and no
    vertex of an open border moves: a quadric does not see a border pulled in (a house's split-vertex box
    is six open quads, each of which folds to a line at zero error and vanishes), so borders are kept.
    fast-simplification has no error stop but raises its threshold over a fixed number of passes: asked
    for zero faces with ``agg`` chosen so that the last pass's threshold is ``max_error``, it stops there."""
    import fast_simplification  # measured: ~0.3 s to import; only the LOD stage needs it

    agg = max(np.log(max_error / _PASS_THRESHOLD) / np.log(_LAST_PASS_BASE), 0.0)
    with _SIMPLIFY_LOCK:
        v, f = fast_simplification.simplify(
            vertices, faces.astype(np.int32), target_count=0, agg=agg, preserve_border=True
        )
    return np.asarray(v, np.float64), np.asarray(f, np.int64).reshape(-1, 3)


def lod_tiles(piece: Piece, tile_faces: int) -> int:
    """How many spatial tiles the per-piece LOD cuts ``piece`` into (1: the piece whole)."""
    return max(1, -(-piece.nf // tile_faces))


def tile_cells(scene: Scene, tiles: int) -> np.ndarray:
    """(m,) int64 tile of each face of ``scene`` among ``tiles``: ceil(sqrt(tiles)) columns across x, each cut
    across z into rows, by the ranks of the face centroids' x, then z (numpy's selection, linear time), so
    that tile t holds the faces of ranks floor(m t / tiles) .. floor(m (t + 1) / tiles): equal face counts, to
    one, however the faces crowd (a Sponza's middle is as many tiles as its faces make). The centroids' x and
    z only, a column at a time: the 10x world's terrain (8.7M faces) in 1.2 s."""
    if tiles == 1:
        return np.zeros(len(scene.faces), np.int64)
    f = np.ascontiguousarray(scene.faces.T)
    cx, cz = (
        (x[f[0]] + x[f[1]] + x[f[2]]) / 3.0  # the corners' mean, as numpy's mean adds and divides
        for x in (np.ascontiguousarray(scene.vertices[:, k]) for k in (0, 2))
    )
    m = len(cx)
    bound = [(m * t) // tiles for t in range(tiles + 1)]  # tile t's first rank
    columns = int(np.ceil(np.sqrt(tiles)))
    # column c holds tiles first[c] .. first[c + 1] - 1 (the first tiles % columns columns one row more)
    first = np.cumsum([0] + [tiles // columns + (c < tiles % columns) for c in range(columns)])
    by_x = _ranked(cx, [bound[t] for t in first[1:-1]])
    out = np.empty(m, np.int64)
    for c in range(columns):
        lo, hi = bound[first[c]], bound[first[c + 1]]
        mine = by_x[lo:hi]
        by_z = mine[_ranked(cz[mine], [bound[t] - lo for t in range(first[c] + 1, first[c + 1])])]
        for t in range(first[c], first[c + 1]):
            out[by_z[bound[t] - lo : bound[t + 1] - lo]] = t
    return out


def _ranked(values: np.ndarray, cuts: list[int]) -> np.ndarray:
    """Indices of ``values`` with the ``cuts`` (ranks) in place: every index before a cut has a value at most
    every one after it (:func:`numpy.argpartition`)."""
    cuts = [c for c in cuts if 0 < c < len(values)]
    return np.argpartition(values, cuts) if cuts else np.arange(len(values))


def simplify_piece(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: LOD 1 of one piece, or of one spatial tile of a big one (:func:`tile_cells`),
    simplified alone to the level's shared quadric error (:func:`simplify_to_error`; a tile's cut is an
    open border, kept). Returns vertices, faces and every face's first-edge length (float32: the driver
    takes the level's median for the resampling radius)."""
    piece, tiles, tile, max_error = args
    scene, _ = cached_piece(state.key, state.level, state.index, piece, None)
    # the piece's cells, made by a worker's first tile of it and kept for its next ones
    cells = remembered(_TILE_CACHE, (state.key, piece.index, tiles), lambda: tile_cells(scene, tiles))
    mine = scene.faces[cells == tile]
    used, local = np.unique(mine, return_inverse=True)
    v, f = simplify_to_error(scene.vertices[used], local.reshape(-1, 3), max_error)
    if len(f):  # the same faces the LOD's own scene keeps (degenerate ones dropped)
        lod = scene_from_arrays(v, f, f"lod{piece.index}", state.level.source)
        used, local = np.unique(lod.faces, return_inverse=True)
        v, f = lod.vertices[used], local.reshape(-1, 3)
    edges = np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1) if len(f) else np.zeros(0)
    return {"vertices": v, "faces": f, "edges": edges.astype(np.float32)}


# A worker's latest pieces' tile cells (:func:`tile_cells`), by bake, piece and tile count.
_TILE_CACHE: OrderedDict[tuple, np.ndarray] = OrderedDict()


def join_tiles(tiles: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """One piece's LOD from its tiles' (vertices, faces), in tile order (vertices renumbered)."""
    offsets = np.cumsum([0] + [len(t["vertices"]) for t in tiles])
    return {
        "vertices": np.concatenate([t["vertices"] for t in tiles]).reshape(-1, 3),
        "faces": np.concatenate([t["faces"] + o for t, o in zip(tiles, offsets, strict=False)]).reshape(
            -1, 3
        ),
    }


def simplify_level(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: LOD 1 of the level's static instances, one quadric simplification of them all flattened
    (the simplifier's error threshold is the whole level's: flat house walls go before a curved terrain),
    and the piece of every LOD face. Collapses never join two components, so each LOD component comes from
    one instance: its piece is the one most of its vertices' nearest original vertices belong to.
    Returns vertices, faces, face_piece and the LOD's median edge length."""
    from scipy.sparse import coo_matrix
    from scipy.spatial import cKDTree  # measured: ~0.8 s to import; only this step needs it

    (reduction,) = args
    level, index = state.level, state.index
    rv, rf, _ = flatten(level, index.nodes)
    lod = simplify(scene_from_arrays(rv, rf, "receivers", level.source, drop_degenerate=False), reduction)
    del rf
    starts = np.array([p.v0 for p in index.pieces])
    _, near = cKDTree(rv).query(lod.vertices)
    del rv
    owner = np.searchsorted(starts, near, side="right") - 1
    f = lod.faces
    n = len(lod.vertices)
    graph = coo_matrix(
        (np.ones(2 * len(f)), (np.r_[f[:, 0], f[:, 1]], np.r_[f[:, 1], f[:, 2]])), shape=(n, n)
    )
    _, comp = connected_components(graph, directed=False)
    votes = np.bincount(comp * len(starts) + owner, minlength=(comp.max() + 1) * len(starts))
    comp_piece = votes.reshape(-1, len(starts)).argmax(axis=1)
    v = lod.vertices
    return {
        "vertices": v,
        "faces": f,
        "face_piece": comp_piece[comp[f[:, 0]]],
        "median_edge": np.array(float(np.median(np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1)))),
    }


def split_lod(result: dict[str, np.ndarray], pieces: list[Piece]):
    """(stem, {"vertices", "faces"}) of each piece's part of the level's LOD (vertices renumbered)."""
    for p in pieces:
        f = result["faces"][result["face_piece"] == p.index]
        used, local = np.unique(f, return_inverse=True)
        yield piece_stem(p), {"vertices": result["vertices"][used], "faces": local.reshape(-1, 3)}


def holdout_counts(scene: Scene, total: int, seed: int) -> np.ndarray:
    """Held-out sample counts: ``total`` faces drawn by area (seeded), one sample each."""
    areas = face_areas(scene)
    counts = np.zeros(len(areas), np.int64)
    if total <= 0 or areas.sum() <= 0:
        return counts
    rng = np.random.default_rng(seed + 99)
    pick = rng.choice(
        len(areas), size=min(total, int((areas > 0).sum())), replace=False, p=areas / areas.sum()
    )
    counts[pick] = 1
    return counts


def lod_sample_counts(lod: Scene, s: LevelBakeSettings) -> np.ndarray:
    """(m,) int64 least-squares samples per face of a piece's LOD scene (at most 16 a face)."""
    return samples_per_face(face_areas(lod), s.lod.samples_per_vertex * len(lod.vertices), 16)


def lod_points(vertices: np.ndarray, faces: np.ndarray, piece: Piece, s: LevelBakeSettings):
    """A piece's LOD scene and its least-squares surface samples (seeded, numbered from the piece's first
    face); the resampling points are the LOD's vertices, then these samples."""
    lod = scene_from_arrays(vertices, faces, f"lod{piece.index}", drop_degenerate=False)
    samples = surface_samples(lod, 0, seed=s.seed + 3, counts=lod_sample_counts(lod, s), face_offset=piece.f0)
    return lod, samples


def task_rays(s: LevelBakeSettings, runner) -> int:
    """Rays per resampling task: ``task_rays`` per tracing thread of the engine's workers. A worker of 16
    threads (``--ray-threads 16``) gets 16x the rays in a task, the same seconds as one thread's, and the
    driver a sixteenth of the tasks to send and of the files to write and read (the 10x world's LOD: 677
    blocks at about 6 ms of the driver's each). A point's value depends on its own rays alone, so the bytes
    do not depend on it."""
    return s.task_rays * max(1, getattr(runner, "threads", None) or 1)


def lod_resample_jobs(
    ctx, pieces, values, lod_meshes: TaskFiles, radius: float, s: LevelBakeSettings, per_block: int
):
    """(stem, task maker) per block of ``per_block`` resampling points of each piece (its LOD's vertices,
    then its samples), and per piece its point count. A block's task makes its own points from the
    piece's LOD mesh, which travels to each worker once."""
    jobs, counts, last = [], {}, {}

    def mesh(p: Piece) -> Shared:
        if last.get("piece") != p.index:
            key = content_key(lod_meshes.key, piece_stem(p))
            last.update(piece=p.index, mesh=Shared(key, (key, lod_meshes.get(piece_stem(p)))))
        return last["mesh"]

    for p in pieces:
        m = lod_meshes.get(piece_stem(p))
        if len(m["faces"]) == 0:
            counts[p.index] = 0
            continue
        # The count only: the LOD's vertices and its samples, as surface_samples spreads them.
        lod = scene_from_arrays(m["vertices"], m["faces"], f"lod{p.index}", drop_degenerate=False)
        counts[p.index] = n = len(lod.vertices) + int(lod_sample_counts(lod, s).sum())
        del lod, m
        for b, lo in enumerate(range(0, n, per_block)):
            hi = min(lo + per_block, n)

            def make(p=p, lo=lo, hi=hi) -> Task:
                return Task(ctx, _resample_points, (values, mesh(p), p, lo, hi, radius, s))

            jobs.append((f"{piece_stem(p)}_{b:05d}", make))
    return jobs, counts


def lod_block_points(key: str, mesh: dict[str, np.ndarray], piece: Piece, lo: int, hi: int, s) -> np.ndarray:
    """Resampling points ``lo`` .. ``hi`` of a piece's LOD (its vertices, then :func:`lod_points`'
    samples), the same bits, made from the faces under them alone; the LOD scene and its face counts come
    from this process's small cache (by ``key``, the mesh's) when a block of the same piece ran here last."""

    def make():
        lod = scene_from_arrays(mesh["vertices"], mesh["faces"], f"lod{piece.index}", drop_degenerate=False)
        counts = lod_sample_counts(lod, s)
        return lod, np.cumsum(counts), float(face_areas(lod)[counts > 0].sum())

    lod, ends, area = remembered(_LOD_CACHE, key, make)
    nv = len(lod.vertices)
    points = [lod.vertices[lo : min(hi, nv)]]
    if hi > nv:
        points.append(
            samples_in_range(lod, ends, max(lo - nv, 0), hi - nv, s.seed + 3, piece.f0, area).points
        )
    return np.concatenate(points)


# A worker's latest LOD pieces (scene, running face counts, sampled area), by their mesh's content key.
_LOD_CACHE: OrderedDict[str, tuple] = OrderedDict()


def _resample_points(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: :func:`resample_in_spheres` of one block of a piece's LOD points on the opaque
    labeller."""
    values, (key, mesh), piece, lo, hi, radius, s = args
    points = lod_block_points(key, mesh, piece, lo, hi, s)
    v, _ = resample_in_spheres(state.labeller, values, points, radius, s.lod.rays)
    return {"values": v}


def piece_resampled(files: TaskFiles, piece: Piece, count: int, per_block: int) -> np.ndarray:
    """The resampled values of a piece's LOD points, from its block files."""
    out = np.full(count, np.nan)
    for b, lo in enumerate(range(0, count, per_block)):
        out[lo : lo + per_block] = files.get(f"{piece_stem(piece)}_{b:05d}")["values"]
    return out


def lod_mesh_files(lod_files: TaskFiles) -> TaskFiles:
    """The LOD's meshes, a file per piece beside the LOD's results (which do not repeat them)."""
    return TaskFiles(lod_files.folder.parent / "lod_meshes", lod_files.key)


def lod_jobs(ctx, pieces, rule, lod_meshes: TaskFiles, resampled, radius: float, s: LevelBakeSettings):
    """One task per piece: the LOD's least squares over its resampled samples, its AO at the vertices, and
    its held-out points (``lod.holdout_samples`` spread by area over the level) with both AOs there.
    ``resampled(piece)``: the piece's resampled values (vertices, then samples)."""

    def make(p: Piece) -> Task:
        mesh = lod_meshes.get(piece_stem(p))
        return Task(ctx, _lod_piece, (p, rule, mesh["vertices"], mesh["faces"], resampled(p), radius, s))

    return [(piece_stem(p), lambda p=p: make(p)) for p in pieces]


# What the error sums read of each LOD piece's result (its held-out points and both AOs there).
LOD_HELD_OUT = ("share", "hold_points", "hold_normals", "hold_weights", "hold_ao")


def _lod_piece(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: LOD 1 of one piece and its AO by (a) resampling at its vertices, (b) least squares over
    resampled surface samples; and its held-out points with (a) and (b) there, which
    :func:`lod_reference_jobs` compare with the gold standard."""
    piece, rule, lod_vertices, lod_faces, resampled, radius, s = args
    share = piece.area / rule.area_all if rule.area_all > 0 else 0.0
    empty = np.zeros((0, 3))
    held = {
        "hold_points": empty,
        "hold_normals": empty,
        "hold_weights": np.zeros(0),
        "hold_ao": np.zeros((0, 2)),
    }
    if len(lod_faces) == 0:  # the simplification left nothing of this piece
        out = {"radius": np.array(radius)}
        out.update(ao_vertex=np.zeros(0, np.float32), ao_least_squares=np.zeros(0, np.float32))
        out.update(resample_points=np.array(0), sizes=np.zeros(2, np.int64), share=np.array(share))
        return out | held | {k: np.array(0.0) for k in ("seconds_solve", "seconds_reference")}
    t2 = time.perf_counter()
    lod, lod_samples = lod_points(lod_vertices, lod_faces, piece, s)
    at_vertices, at_samples = resampled[: len(lod.vertices)], resampled[len(lod.vertices) :]
    ok = np.isfinite(at_samples)
    # The piece's block of the whole LOD's least squares: its sample weights (shares of the piece's area)
    # and edge weights scaled by the piece's share of the level's area.
    lsq = fit_level(
        lod,
        lod_samples,
        np.where(ok, at_samples, 0.0),
        ok,
        s.trace,
        whole=Whole(1.0 / share, float(face_areas(lod).sum()) / share) if share else None,
    )
    fill = float(np.nanmean(at_vertices)) if np.isfinite(at_vertices).any() else 1.0
    vert = np.where(np.isfinite(at_vertices), at_vertices, fill).astype(np.float32)
    t3 = time.perf_counter()
    count = int(round(s.lod.holdout_samples * share))
    if count > 0:
        hold = surface_samples(
            lod,
            count,
            4,
            s.seed + 4,
            counts=holdout_counts(lod, count, s.seed + piece.f0),
            face_offset=piece.f0,
        )
        ao = [interpolate(lod, x, hold.face, hold.bary) for x in (vert, lsq)]
        held = {
            "hold_points": hold.points,
            "hold_normals": hold.normals,
            "hold_weights": hold.weights,
            "hold_ao": np.stack(ao, axis=1).astype(np.float64),
        }
    if len(lod.vertices) != len(lod_vertices) or len(lod.faces) != len(lod_faces):
        raise NeuralaoError(f"piece {piece.index}'s LOD mesh changed when it was read back")
    return {
        "ao_vertex": vert,
        "ao_least_squares": lsq,
        "radius": np.array(radius),
        "resample_points": np.array(len(lod.vertices) + len(lod_samples)),
        "sizes": np.array([len(lod.vertices), len(lod.faces)], np.int64),
        "share": np.array(share),
        **held,
        "seconds_solve": np.array(t3 - t2),
        "seconds_reference": np.array(time.perf_counter() - t3),
    }


def lod_reference_jobs(ctx, pieces, rule, lod_files: TaskFiles, trace_files: TaskFiles, radius, s):
    """(stem, task maker) per trace block of each piece with held-out LOD points: the gold standard's sums
    there from the block's traced samples (:func:`_lod_reference_block`)."""
    jobs = []
    block = s.trace.block_samples
    for p in pieces:
        held = lod_files.get(piece_stem(p), ("hold_points", "hold_normals"))
        if held is None or len(held["hold_points"]) == 0:
            continue
        for lo, stem in zip(range(0, p.ns, block), lod_reference_stems(p, block), strict=True):

            def make(p=p, lo=lo, stem=stem, held=held) -> Task:
                data = trace_files.get(stem)  # the trace block's file has the same stem
                if data is None:
                    raise NeuralaoError(f"trace block {lo // block} of piece {p.index} is missing")
                args = (p, rule, lo, data["ao"], data["valid"], held["hold_points"], held["hold_normals"])
                return Task(ctx, _lod_reference_block, (*args, radius, s.blend))

            jobs.append((stem, make))
    return jobs


def _lod_reference_block(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: the gold standard's sums at a piece's held-out LOD points from one trace block of its
    samples: per point, over the block's valid samples within the resampling sphere and facing within 60
    degrees of the point's normal, the sum of the weights w (the sample's area weight times its distance to
    the sphere's boundary) and of w times the sample's blended AO. Added over the piece's blocks and
    divided, they are the traced AO near each point (no vertex bake, no resampling rays)."""
    from scipy.spatial import cKDTree  # measured: ~0.8 s to import; only this step needs it

    piece, rule, lo, ao, valid, points, normals, radius, blend_settings = args
    _, samples = cached_block(state.key, state.level, state.index, piece, rule, lo, lo + len(valid))
    f = blend(ao[:, 0], ao[:, 1], blend_settings).astype(np.float64)[valid]
    pts, nrm, sw = samples.points[valid], samples.normals[valid], samples.weights[valid]
    sums = np.zeros((len(points), 2))
    if len(pts):
        for i, nb in enumerate(cKDTree(pts).query_ball_point(points, radius)):
            if nb:
                nb = np.asarray(nb)
                w = sw[nb] * np.maximum(radius - np.linalg.norm(pts[nb] - points[i], axis=1), 0)
                w = w * (nrm[nb] @ normals[i] > 0.5)
                sums[i] = w.sum(), np.sum(w * f[nb])
    return {"sums": sums}


def lod_reference_stems(piece: Piece, block: int) -> list[str]:
    """The stems of a piece's gold-standard sums (:func:`lod_reference_jobs`), one per trace block."""
    return [f"{piece_stem(piece)}_{lo // block:05d}" for lo in range(0, piece.ns, block)]


def lod_piece_errors(piece_result: dict[str, np.ndarray], reference_files: TaskFiles, stems: list[str]):
    """(6,) a piece's LOD error sums (:func:`lod_error_sums`) from its result (:data:`LOD_HELD_OUT`) and the
    gold-standard sums of its trace blocks (``stems``: :func:`lod_reference_stems`), added in block order;
    zeros for a piece without held-out points."""
    if len(piece_result["hold_points"]) == 0:
        return np.zeros(6)
    total = np.zeros((len(piece_result["hold_points"]), 2))
    for stem in stems:
        r = reference_files.get(stem, ("sums",))
        if r is None:
            raise NeuralaoError(f"{reference_files.path(stem)} could not be read back: is the disk full?")
        total += r["sums"]
    return lod_error_sums(piece_result, total)


def lod_error_sums(piece_result: dict[str, np.ndarray], sums: np.ndarray) -> np.ndarray:
    """(6,) a piece's weighted error sums (sum w, w e_vertex^2, w e_lsq^2, w ref, w ref^2, held-out points)
    from its held-out points (:data:`LOD_HELD_OUT`) and the gold standard's sums there, added over its
    blocks ((h, 2): sum w, sum w f)."""
    ref = np.full(len(sums), np.nan)
    hit = sums[:, 0] > 0
    ref[hit] = sums[hit, 1] / sums[hit, 0]
    m = np.isfinite(ref)
    if not m.any():
        return np.zeros(6)
    weights = piece_result["hold_weights"][m]
    w = weights / weights.sum() * float(piece_result["share"])
    ev, el = (piece_result["hold_ao"][m, k] - ref[m] for k in (0, 1))
    return np.array(
        [w.sum(), (w * ev**2).sum(), (w * el**2).sum(), (w * ref[m]).sum(), (w * ref[m] ** 2).sum(), m.sum()]
    )


# --------------------------------------------------------------------------- blend check


def blend_piece(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: at the picked samples of one piece, (a) the blended-kernel trace on the bake's rays,
    (b) a 4x-ray blended reference (its own seed; the labeller's BVH is shared), the per-vertex blend
    interpolated; with ``gap``, (c) the largest gap between the per-vertex blend and least squares of the
    blended samples over the piece."""
    piece, rule, picks, order, short, long_, ao, valid, s, ref_settings, gap, whole, foliage = args
    scene, samples = cached_piece(state.key, state.level, state.index, piece, rule)
    pts, nrm = samples.points[picks], samples.normals[picks]
    kern = blended_kernel_trace(state.labeller, foliage, pts, nrm, s, ids=piece.s0 + picks)
    reference = copy.copy(state.labeller)
    reference.settings = ref_settings
    ref_two, ref_valid = reference.obscurance(pts, nrm, halves(s), foliage, ids=order)
    plain = replace(s.blend, remap=None)
    per_vertex = blend(short, long_, plain)
    pred = interpolate(scene, per_vertex, samples.face[picks], samples.bary[picks])
    worst = np.nan
    if gap:
        lsq = fit_level(scene, samples, blend(ao[:, 0], ao[:, 1], plain), valid, s.trace, whole=whole)
        worst = float(np.abs(per_vertex - lsq).max(initial=0.0))
    return {"kern": kern, "ref_two": ref_two, "ref_valid": ref_valid, "pred": pred, "gap": np.array(worst)}


def blended_kernel_trace(
    labeller: LevelLabeller, foliage, points, normals, s: LevelBakeSettings, ids
) -> np.ndarray:
    """One trace with the blended kernel rho_b(d) = w (1 - 2^(-d/h_long)) + (1 - w) (1 - 2^(-d/h_short))
    per ray (escaped rays: 1), averaged per sample: a separate path from :meth:`LevelLabeller.obscurance`
    that shares only the rays (:meth:`Labeller.rays`)."""
    orig, dirs = labeller.rays(points, normals, ids=ids)
    r = labeller.r_local
    out = labeller.embree.run(
        orig, dirs, query="INTERSECT", dists=np.full(len(orig), r, np.float32), output=1
    )
    t = out["tfar"].astype(np.float64)
    hs, hl = (h / labeller.scale for h in halves(s))
    w = s.blend.long_weight
    rho = np.where(t < r, w * (1 - 2.0 ** (-t / hl)) + (1 - w) * (1 - 2.0 ** (-t / hs)), 1.0)
    if foliage is not None and not foliage.empty:
        start = np.repeat(foliage.origin_density(orig[:: labeller.settings.rays]), labeller.settings.rays)
        rho = rho * foliage.transmittance(orig, dirs, np.minimum(out["tfar"], r), start)
    return rho.reshape(len(points), -1).mean(axis=1)


# --------------------------------------------------------------------------- output


def output_jobs(
    ctx, pieces, index: PieceIndex, solve_files: TaskFiles, s: LevelBakeSettings
) -> Iterator[Task]:
    """A task per piece, in piece order: its instances' glTF part from its solved vertex AO (each piece's
    values read when its task is made), made for its place in the glTF (:func:`part_places`)."""
    for p, base in zip(pieces, part_places(pieces, index.table), strict=True):
        r = solve_files.get(piece_stem(p))
        yield Task(ctx, _output_piece, (p, base, r["short"], r["long"], s.blend))


# What each static instance adds to the glTF (:func:`_output_piece`): a node, a mesh, and a view and an
# accessor for each of POSITION (float32 x 3), COLOR_0 (uint8 x 4), _AO, _AO_SHORT, _AO_LONG (float32)
# and the indices (uint32 x 3 per face), none of which needs padding.
_INSTANCE_ACCESSORS = 6
_VERTEX_BYTES = 12 + 4 + 3 * 4
_FACE_BYTES = 12


def part_places(pieces, table: np.ndarray) -> list[np.ndarray]:
    """Where each piece's glTF part goes in the baked glTF, the pieces' parts first and in piece order:
    the bufferViews, accessors, meshes and nodes before it, then its first byte (what
    :meth:`GltfWriter.positioned` takes). A part that is not the size counted here is refused where it is
    spliced, so the glTF is right or not written."""
    base, places = np.zeros(5, np.int64), []
    for p in pieces:
        rows = table[p.first : p.stop]
        places.append(base.copy())
        k = len(rows)
        base += [_INSTANCE_ACCESSORS * k, _INSTANCE_ACCESSORS * k, k, k, 0]
        base[4] += int(rows[:, 4].sum()) * _VERTEX_BYTES + int(rows[:, 5].sum()) * _FACE_BYTES
    return places


def _output_piece(state: PieceState, args) -> dict[str, np.ndarray]:
    """Engine task: one piece's static instances as a glTF part made for its place (:meth:`GltfWriter.
    positioned`, :meth:`GltfWriter.fragments`): a mesh and a node per instance in instance order (world
    positions, faces, COLOR_0 and the three AO attributes); the driver splices the parts in piece order, so
    the glTF's bytes are those of one writer."""
    piece, base, short, long_, blend_settings = args
    final = blend(short, long_, blend_settings)
    colour = vertex_colours(final)
    short, long_ = np.asarray(short, np.float32), np.asarray(long_, np.float32)
    level, index = state.level, state.index
    w = GltfWriter.positioned(base)
    for k, j, v0, _, nv, _ in index.table[piece.first : piece.stop]:
        node = index.nodes[k]
        sl = slice(v0 - piece.v0, v0 - piece.v0 + nv)
        attrs = {"COLOR_0": colour[sl], "_AO": final[sl], "_AO_SHORT": short[sl], "_AO_LONG": long_[sl]}
        positions = instance_vertices(level, node, int(j)).astype(np.float32)
        mi = w.mesh(f"{node.name}_{j}", positions, level.meshes[node.mesh].faces.astype(np.uint32), attrs)
        w.node(
            f"{node.name}_{j}" if len(node.transforms) > 1 else node.name,
            mi,
            extras={"role": "static", "source_node": node.index, "instance": int(j)},
        )
    return w.fragments()
