"""A level in pieces, so that a bake's driver never holds the flattened level.

The static instances, in flatten order (node by node, instance by instance: the order of
:func:`neuralao.pipeline.geometry.level_files.flatten`), are cut into *pieces*: runs of whole instances of
about
``piece_faces`` faces (an instance bigger than that is a piece of its own). Instances share no vertices,
so everything per vertex (the least-squares solve, the LOD) depends on one piece alone. Global face,
vertex and sample numbers are a piece's offsets plus its own, so a piece's samples and their rays are
exactly those of the whole level flattened at once (tested), whichever machine makes them.

Sample counts follow :func:`water_fill` (a density under the per-face floor and cap, found on a
histogram of face areas that every piece adds to) and stochastic rounding whose uniforms are one seeded
stream indexed by global face number (each piece skips ahead to its first face).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from neuralao.pipeline.geometry.level_files import Level, LevelNode, transform_points
from neuralao.pipeline.geometry.scene import Scene, scene_from_arrays
from neuralao.pipeline.geometry.surface import SurfaceSamples, face_areas, samples_in_range, surface_samples
from neuralao.runtime.foundation.errors import NeuralaoError

# Faces per run of a piece's sample ranges (``Piece.ranges``): a trace block's task counts the samples of
# its runs' faces, not of the whole piece's.
SAMPLE_RANGE_FACES = 65536
# Area histogram: bins per octave of face area and the octaves covered (areas outside are clamped in).
_BINS_PER_OCTAVE = 64
_OCTAVES = (-80, 80)


@dataclass(frozen=True)
class Piece:
    """Static instance rows [first, stop) of the :class:`PieceIndex` table; their first global vertex,
    face and sample and their counts."""

    index: int
    first: int
    stop: int
    v0: int
    f0: int
    nv: int
    nf: int
    s0: int = 0
    ns: int = 0
    # (first face, first sample) of each run of SAMPLE_RANGE_FACES of the piece's faces, from the samples'
    # second pass; empty: not known (a block task then counts the samples of every face of the piece)
    ranges: tuple[tuple[int, int], ...] = ()
    area: float = 0.0  # of its faces, from the samples' second pass (its ranges' sums added in order)


@dataclass
class PieceIndex:
    """The static instances (``table`` rows: node position in ``nodes``, instance, first vertex, first
    face, vertices, faces) cut into pieces, and the opaque level's bounds (static and blocker instances)."""

    nodes: list[LevelNode]
    table: np.ndarray
    pieces: list[Piece]
    bounds: np.ndarray

    @property
    def vertices(self) -> int:
        return int(self.table[:, 4].sum()) if len(self.table) else 0

    @property
    def faces(self) -> int:
        return int(self.table[:, 5].sum()) if len(self.table) else 0

    @property
    def center(self) -> np.ndarray:
        return self.bounds.mean(0)

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.bounds[1] - self.bounds[0]))


def instance_table(level: Level, nodes: list[LevelNode]) -> np.ndarray:
    """(i, 6) int64 rows (node position, instance, first vertex, first face, vertices, faces) of every
    instance of ``nodes`` in flatten order."""
    rows, nv, nf = [], 0, 0
    for k, node in enumerate(nodes):
        mesh = level.meshes[node.mesh]
        for j in range(len(node.transforms)):
            rows.append((k, j, nv, nf, len(mesh.vertices), len(mesh.faces)))
            nv += len(mesh.vertices)
            nf += len(mesh.faces)
    return np.array(rows, np.int64).reshape(-1, 6)


def cut_pieces(table: np.ndarray, piece_faces: int) -> list[Piece]:
    """Runs of whole instances of at most ``piece_faces`` faces (a bigger instance alone)."""
    pieces: list[Piece] = []
    first = 0
    for i in range(len(table) + 1):
        if i > first and (i == len(table) or table[first:i, 5].sum() + table[i, 5] > piece_faces):
            v0, f0 = int(table[first, 2]), int(table[first, 3])
            nv, nf = int(table[first:i, 4].sum()), int(table[first:i, 5].sum())
            pieces.append(Piece(len(pieces), first, i, v0, f0, nv, nf))
            first = i
    return pieces


def instance_vertices(level: Level, node: LevelNode, j: int) -> np.ndarray:
    """World-space vertices (n, 3) float64 of instance ``j`` of ``node`` (as :func:`flatten` makes them)."""
    return transform_points(level.meshes[node.mesh].vertices, node.transforms[j])


# World vertices made at once when a node's instances are bounded (a batch of its instances: 48 MiB).
_BOUNDS_BATCH = 1 << 21


def instance_batches(vertices: np.ndarray, transforms: np.ndarray) -> Iterator[np.ndarray]:
    """World-space vertices (k, n, 3) float64 of a mesh's ``vertices`` (n, 3) under its instances'
    ``transforms`` (m, 4, 4), a batch of k instances at a time (each as :func:`instance_vertices` makes
    it)."""
    if len(vertices) == 0:
        return
    step = max(1, _BOUNDS_BATCH // len(vertices))
    for a in range(0, len(transforms), step):
        yield transform_points(vertices, transforms[a : a + step])


def level_bounds(level: Level, nodes: list[LevelNode]) -> np.ndarray:
    """(2, 3) min and max corner of every instance of ``nodes``, a batch of instances of one mesh at a time
    (the nodes of a mesh together: a level's houses are thousands of nodes of a few meshes)."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    by_mesh: dict[int, list[np.ndarray]] = {}
    for node in nodes:
        by_mesh.setdefault(node.mesh, []).append(node.transforms)
    for mesh, transforms in sorted(by_mesh.items()):
        for world in instance_batches(level.meshes[mesh].vertices, np.concatenate(transforms)):
            lo, hi = np.minimum(lo, world.min(axis=(0, 1))), np.maximum(hi, world.max(axis=(0, 1)))
    return np.stack([lo, hi])


def index_level(level: Level, piece_faces: int) -> PieceIndex:
    static = level.nodes_with("static")
    table = instance_table(level, static)
    bounds = level_bounds(level, level.nodes_with("static", "blocker"))
    return PieceIndex(static, table, cut_pieces(table, piece_faces), bounds)


def piece_scene(level: Level, index: PieceIndex, piece: Piece) -> Scene:
    """The piece's instances flattened (vertex and face numbers local to the piece). A piece of one
    instance (a terrain) shares its mesh's faces: no copy of them."""
    verts, faces = [], []
    for k, j, v0, _, _, _ in index.table[piece.first : piece.stop]:
        node = index.nodes[k]
        verts.append(instance_vertices(level, node, int(j)))
        f = level.meshes[node.mesh].faces
        if v0 == piece.v0:  # the mesh's own array, read-only: a write to the scene's faces is an error
            f = f.view()
            f.flags.writeable = False
        faces.append(f + (v0 - piece.v0) if v0 != piece.v0 else f)
    return scene_from_arrays(
        verts[0] if len(verts) == 1 else np.concatenate(verts),
        faces[0] if len(faces) == 1 else np.concatenate(faces),
        f"piece{piece.index}",
        level.source,
        drop_degenerate=False,
    )


# --------------------------------------------------------------------------- sample counts


@dataclass(frozen=True)
class SampleRule:
    """What every piece's samples depend on: the water-filled density ``rho`` (samples per unit area),
    the per-face floor and cap, the seed, and the area of every face that got a sample (the weights'
    normaliser: each sample's weight is its share of that area); ``area_all``: every face's."""

    rho: float
    floor: int
    cap: int
    seed: int
    area_total: float = 0.0
    area_all: float = 0.0


class AreaHistogram:
    """Face counts and area sums on log2-spaced bins, added to piece by piece (O(bins) memory)."""

    def __init__(self) -> None:
        lo, hi = _OCTAVES
        self.edges = 2.0 ** np.linspace(lo, hi, (hi - lo) * _BINS_PER_OCTAVE + 1)
        self.count = np.zeros(len(self.edges) - 1)
        self.area = np.zeros(len(self.edges) - 1)

    def bins(self, areas: np.ndarray) -> dict[str, np.ndarray]:
        """The face count and area sum per bin of ``areas`` (what :meth:`add_bins` adds)."""
        b = np.clip(np.searchsorted(self.edges, areas, side="right") - 1, 0, len(self.count) - 1)
        return {
            "count": np.bincount(b, minlength=len(self.count)),
            "area": np.bincount(b, weights=areas, minlength=len(self.count)),
        }

    def add_bins(self, bins: dict[str, np.ndarray]) -> None:
        self.count += bins["count"]
        self.area += bins["area"]

    def add(self, areas: np.ndarray) -> None:
        self.add_bins(self.bins(areas))

    def expected(self, rho: float, floor: int, cap: int) -> float:
        """About sum(clip(rho * area, floor, cap)) over every face added: exact for bins wholly below the
        floor, above the cap or between, the bin's area sum clipped for the one or two bins across."""
        lo, hi = rho * self.edges[:-1], rho * self.edges[1:]
        linear = np.clip(rho * self.area, floor * self.count, cap * self.count)
        out = np.where(hi <= floor, floor * self.count, np.where(lo >= cap, cap * self.count, linear))
        return float(out.sum())


def water_fill(hist: AreaHistogram, total: float, floor: int, cap: int) -> float:
    """The density rho with sum clip(rho * area, floor, cap) = ``total`` (bisection; the histogram stands
    for the faces). What the cap takes from large faces goes to the rest."""
    area = float(hist.area.sum())
    lo, hi = 0.0, total / max(area, 1e-300)
    while hist.expected(hi, floor, cap) < total and hi < 1e300:
        if hist.expected(hi, floor, cap) >= cap * hist.count.sum():
            break
        hi *= 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if hist.expected(mid, floor, cap) < total else (lo, mid)
    return hi


def face_counts(areas: np.ndarray, f0: int, rule: SampleRule) -> np.ndarray:
    """(m,) int64 samples per face of faces f0 .. f0 + m: clip(rho * area, floor, cap) rounded
    stochastically (floor(x + u), u from one seeded stream indexed by global face number)."""
    expected = np.clip(rule.rho * areas, rule.floor, rule.cap)
    rng = np.random.default_rng(rule.seed + 0x5A3)
    rng.bit_generator.advance(int(f0))  # one 64-bit draw per uniform: u of face f0 onwards
    u = rng.uniform(size=len(areas))
    counts = np.clip(np.floor(expected + u), rule.floor, rule.cap).astype(np.int64)
    counts[areas <= 0] = 0
    return counts


def piece_samples(scene: Scene, piece: Piece, rule: SampleRule) -> SurfaceSamples:
    """The piece's samples (faces numbered within the piece), as the whole level's would be."""
    counts = face_counts(face_areas(scene), piece.f0, rule)
    return surface_samples(
        scene, 0, rule.cap, rule.seed, counts=counts, face_offset=piece.f0, area_total=rule.area_total
    )


# A worker's latest pieces (geometry and samples), reused by the next task of the same piece.
_CACHE: OrderedDict[tuple, tuple[Scene, Any]] = OrderedDict()
_CACHE_SIZE = 2
_CACHE_LOCK = threading.Lock()


def remembered(cache: OrderedDict, key, make: Callable[[], Any], size: int = _CACHE_SIZE) -> Any:
    """``cache[key]``, made by ``make()`` when absent; the ``size`` latest keys are kept (a worker's next
    task is most often another block of the same piece). Thread-safe: tasks of a local engine with several
    workers share it (two may make the same value at once; it is the same value)."""
    with _CACHE_LOCK:
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
    value = make()
    with _CACHE_LOCK:
        cache[key] = value
        while len(cache) > size:
            cache.popitem(last=False)
    return value


def cached_piece(
    key: str, level: Level, index: PieceIndex, piece: Piece, rule: SampleRule | None
) -> tuple[Scene, SurfaceSamples | None]:
    """(scene, samples or None) of ``piece``, from this process's small cache when a task of the same
    bake and piece ran here last (trace blocks of one big piece, then its solve)."""

    def make():
        scene = piece_scene(level, index, piece)
        return scene, None if rule is None else piece_samples(scene, piece, rule)

    return remembered(_CACHE, (key, piece.index, rule), make)


def cached_block(
    key: str, level: Level, index: PieceIndex, piece: Piece, rule: SampleRule, lo: int, hi: int
) -> tuple[Scene, SurfaceSamples]:
    """(scene, samples ``lo`` .. ``hi``) of ``piece``: ``piece_samples(scene, piece, rule)[lo:hi]``; the
    piece's geometry comes from this process's small cache when a block of the same piece ran here
    last. A block task makes its own samples, not the piece's (8 s for the 10x world's terrain), from the
    faces of the piece's sample ranges (``Piece.ranges``) it lies in: it counts the samples of those faces
    only (3.5 s for every face of that terrain, on each worker's first block of it)."""
    scene = remembered(_CACHE, (key, piece.index, "scene"), lambda: piece_scene(level, index, piece))
    ranges = piece.ranges or ((0, 0),)  # not known: one range, every face of the piece
    faces = np.array([f for f, _ in ranges] + [len(scene.faces)], np.int64)
    firsts = np.array([s for _, s in ranges] + [piece.ns], np.int64)
    a = int(np.searchsorted(firsts, lo, side="right")) - 1  # the range of sample lo
    b = max(a + 1, int(np.searchsorted(firsts, hi, side="left")))  # ranges a .. b - 1 hold lo .. hi - 1
    fa, fb = int(faces[a]), int(faces[b])
    part = Scene(scene.vertices, scene.faces[fa:fb], scene.name, scene.source)
    ends = np.cumsum(face_counts(face_areas(part), piece.f0 + fa, rule))
    if (ends[-1] if len(ends) else 0) != firsts[b] - firsts[a]:
        raise NeuralaoError(f"piece {piece.index}: its sample ranges do not match its faces' sample counts")
    block = samples_in_range(
        part, ends, lo - int(firsts[a]), hi - int(firsts[a]), rule.seed, piece.f0 + fa, rule.area_total
    )
    block.face = block.face + fa  # numbered in the piece's scene
    return scene, block


def face_samples(
    scene: Scene, piece: Piece, rule: SampleRule, faces: np.ndarray, key: str | None = None
) -> tuple[SurfaceSamples, np.ndarray]:
    """The samples of ``piece`` on its faces ``faces`` ((m,) int64 ascending, faces of its ``scene``):
    ``piece_samples(scene, piece, rule)`` restricted to them bit for bit, their ``face`` numbered in the
    scene, and (k,) int64 their numbers among the piece's samples. Only the piece's sample ranges
    (``Piece.ranges``) that hold one of ``faces`` are counted (a subdomain of the 10x world's terrain: an
    eighth of its faces, not all of them); with ``key`` (the bake's) each range's counts are kept for the
    next call in this process (:data:`RANGES_KEPT`: a worker's other subdomains of the piece)."""
    faces = np.asarray(faces, np.int64)
    ranges = piece.ranges or ((0, 0),)  # not known: one range, every face of the piece
    starts = np.array([f for f, _ in ranges] + [len(scene.faces)], np.int64)
    firsts = np.array([s for _, s in ranges] + [piece.ns], np.int64)
    run = np.searchsorted(starts, faces, side="right") - 1
    counts, first = np.zeros(len(faces), np.int64), np.zeros(len(faces), np.int64)
    cuts = np.flatnonzero(np.r_[True, run[1:] != run[:-1], True]) if len(faces) else np.zeros(1, np.int64)
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        r = int(run[a])
        fa, fb = int(starts[r]), int(starts[r + 1])

        def count(r=r, fa=fa, fb=fb):
            c = face_counts(face_areas(Scene(scene.vertices, scene.faces[fa:fb])), piece.f0 + fa, rule)
            if int(c.sum()) != firsts[r + 1] - firsts[r]:
                raise NeuralaoError(
                    f"piece {piece.index}: its sample ranges do not match its faces' sample counts"
                )
            return c, np.cumsum(c) - c

        c, before = (
            count() if key is None else remembered(_RANGES, (key, piece.index, rule, r), count, RANGES_KEPT)
        )
        local = faces[a:b] - fa
        counts[a:b], first[a:b] = c[local], firsts[r] + before[local]
    samples = surface_samples(
        Scene(scene.vertices, scene.faces[faces], scene.name, scene.source),
        0,
        seed=rule.seed,
        counts=counts,
        face_offset=piece.f0 + faces,
        area_total=rule.area_total,
    )
    samples.face = faces[samples.face]
    within = np.arange(len(samples), dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
    return samples, np.repeat(first, counts) + within


# A process's latest sample ranges' per-face counts and first samples (:func:`face_samples`): 64 ranges of
# SAMPLE_RANGE_FACES faces are 64 MB, the ranges a few subdomains of the 10x world's terrain touch.
_RANGES: OrderedDict[tuple, tuple[np.ndarray, np.ndarray]] = OrderedDict()
RANGES_KEPT = 64


def piece_ranges(piece: Piece) -> list[tuple[int, int]]:
    """Faces [a, b) of each of ``piece``'s sample ranges: runs of SAMPLE_RANGE_FACES faces (one, maybe
    empty, for a piece of no face)."""
    return [
        (a, min(a + SAMPLE_RANGE_FACES, piece.nf)) for a in range(0, max(piece.nf, 1), SAMPLE_RANGE_FACES)
    ]


def range_areas(level: Level, index: PieceIndex, piece: Piece, fa: int, fb: int) -> np.ndarray:
    """(fb - fa,) float64 areas of the piece's faces fa .. fb: those of ``face_areas(piece_scene(...))``
    bit for bit, from the world positions of these faces' vertices only (a 65,536-face run of the 10x
    world's terrain, not its 4.4M vertices)."""
    verts, faces, nv = [], [], 0
    for k, j, _, f0, _, nf in index.table[piece.first : piece.stop]:
        lo, hi = max(fa, f0 - piece.f0), min(fb, f0 - piece.f0 + nf)
        if lo >= hi:
            continue
        node = index.nodes[k]
        mesh = level.meshes[node.mesh]
        sub = mesh.faces[lo - (f0 - piece.f0) : hi - (f0 - piece.f0)]
        if hi - lo < nf:  # part of an instance: its faces' vertices only
            used, sub = np.unique(sub, return_inverse=True)
            world = transform_points(mesh.vertices[used], node.transforms[j])
        else:
            world = transform_points(mesh.vertices, node.transforms[j])
        verts.append(world)
        faces.append(sub.reshape(-1, 3) + nv)
        nv += len(world)
    if not faces:
        return np.zeros(0)
    scene = scene_from_arrays(
        np.concatenate(verts),
        np.concatenate(faces),
        f"piece{piece.index}",
        level.source,
        drop_degenerate=False,
    )
    return face_areas(scene)


def piece_area_bins(level: Level, index: PieceIndex, piece: Piece, fa: int, fb: int) -> dict[str, np.ndarray]:
    """The area histogram's bins of a piece's faces fa .. fb (the samples' first pass)."""
    return AreaHistogram().bins(range_areas(level, index, piece, fa, fb))


def piece_sample_count(
    level: Level, index: PieceIndex, piece: Piece, fa: int, fb: int, rule: SampleRule
) -> dict[str, np.ndarray]:
    """The sample count of a piece's faces fa .. fb and the areas of those with samples and of all (the
    second pass)."""
    areas = range_areas(level, index, piece, fa, fb)
    counts = face_counts(areas, piece.f0 + fa, rule)
    return {
        "samples": np.array(int(counts.sum())),
        "area_sampled": np.array(float(areas[counts > 0].sum())),
        "area": np.array(float(areas.sum())),
    }


def sample_rule(
    level: Level,
    index: PieceIndex,
    samples_per_vertex: float,
    floor: int,
    cap: int,
    seed: int,
    each: Callable | None = None,
):
    """The :class:`SampleRule` of the level and the pieces with their sample offsets, counts and ranges:
    two passes over the pieces' sample ranges (:func:`piece_ranges`: areas into the histogram; then
    counts), one range's faces in memory at a time.

    each : ``each(fn, jobs, *args)`` -> ``fn(level, index, piece, a, b, *args)`` of every job (piece, a,
    b), in job order (a bake's engine runs them as tasks); None: here, one after the other. The driver adds
    the ranges' sums in order either way, so the rule is the same to the last bit however they ran."""
    if each is None:

        def each(fn, jobs, *args):
            return (fn(level, index, *job, *args) for job in jobs)

    jobs = [(piece, a, b) for piece in index.pieces for a, b in piece_ranges(piece)]
    hist = AreaHistogram()
    for bins in each(piece_area_bins, jobs):
        hist.add_bins(bins)
    rho = water_fill(hist, samples_per_vertex * index.vertices, floor, cap)
    rule = SampleRule(rho, floor, cap, seed)
    counts: dict[int, list[int]] = {}
    areas = dict.fromkeys(range(len(index.pieces)), 0.0)
    area_total, area_all = 0.0, 0.0
    for (piece, _, _), r in zip(jobs, each(piece_sample_count, jobs, rule), strict=True):
        area_total += float(r["area_sampled"])
        area_all += float(r["area"])
        areas[piece.index] += float(r["area"])
        counts.setdefault(piece.index, []).append(int(r["samples"]))
    pieces, s0 = [], 0
    for piece in index.pieces:
        ns = np.asarray(counts[piece.index], np.int64)
        firsts = np.cumsum(ns) - ns  # each range's first sample
        ranges = tuple((a, int(first)) for (a, _), first in zip(piece_ranges(piece), firsts, strict=True))
        pieces.append(replace(piece, s0=s0, ns=int(ns.sum()), ranges=ranges, area=areas[piece.index]))
        s0 += int(ns.sum())
    return SampleRule(rho, floor, cap, seed, area_total, area_all), pieces


def scene_samples(scene: Scene, samples_per_vertex: float, floor: int, cap: int, seed: int) -> SurfaceSamples:
    """The samples a level bake makes on ``scene`` taken whole (one piece): water-filled under the per-face
    ``floor`` and ``cap``, stochastically rounded, seeded."""
    areas = face_areas(scene)
    hist = AreaHistogram()
    hist.add(areas)
    rule = SampleRule(
        water_fill(hist, samples_per_vertex * len(scene.vertices), floor, cap), floor, cap, seed
    )
    return surface_samples(scene, 0, cap, seed, counts=face_counts(areas, 0, rule))
