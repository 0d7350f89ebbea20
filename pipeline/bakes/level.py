"""`neuralao bake LEVEL.gltf --config CONFIG --out DIR`: ambient obscurance for a game level.

The system of Sloan, Tranchida, Chen, Kavan 2013 ("Ambient Obscurance Baking on the GPU") on
Embree, stage by stage (the rows of their Table 1; the bake log times each one):

1. **geometry**: read and validate the level (:mod:`pipeline.geometry.level_files`), flatten every instance of
   ``static`` (receivers, first) and ``blocker`` nodes into one opaque scene;
2. **samples**: stratified surface samples on the receivers, a per-face cap (bake.surface_samples);
3. **foliage**: shrub instances -> world bounding boxes with overlap-reduced densities, tree
   instances -> triangles with their transmission (:mod:`pipeline.tracing.foliage`);
4. **bvh**: the opaque Embree scene and the foliage scene;
5. **trace**: obscurance at the short and the long half distance from one trace, attenuated by the
   foliage (:class:`pipeline.tracing.level_tracer.LevelLabeller`); resumable in blocks of samples;
6. **decorators**: per tree model, local AO baked in isolation; per tree instance, the gold standard
   (samples on the instance traced in place, trees opaque) and the 4 coefficients of the linear
   global function of equation 3 (local x global), with global-only and in-place errors;
7. **solve**: least-squares vertex values (Kavan et al. 2011) of both distances;
8. **small decorators**: one scalar per grass clump and shrub, resampled from the baked terrain in
   a small sphere (section 2.2.1);
9. **lod**: a simplified LOD (fast-simplification) with AO transferred by resampling at its vertices
   and by least squares over resampled surface samples, both measured against the gold standard;
10. **output**: glTF (per-vertex COLOR_0 + float attributes, per-instance instancing attributes,
   per-model local AO), the decorator vertex shader, the bake log (JSON + a markdown table).

Resumability: stages 5-9 store their results under ``OUT/stages/`` (atomic npz files keyed by a
hash of the level's bytes and the resolved settings); a rerun reuses every stage whose key matches
and recomputes the rest, and ends with the same bytes as an uninterrupted run. The other stages are
pure functions of their inputs and only cost seconds.
"""

from __future__ import annotations

import json
import logging
import math
import os
import resource
import shutil
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Literal

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu
from tqdm import tqdm

from pipeline.bakes.level_output import write_outputs
from pipeline.engines.engine import Context, LocalEngine, ResultStore, Shared, Task, content_key
from pipeline.foundation.errors import NeuralaoError
from pipeline.foundation.io import (
    read_npz,
    remove_stale_temporaries,
    sha256_file,
    sha256_json,
    write_json,
    write_npz,
    write_text,
)
from pipeline.foundation.settings import load_settings, settings_to_dict
from pipeline.geometry.least_squares import fit_least_squares, normal_equations, solve_amg
from pipeline.geometry.level_files import Level, LevelNode, flatten, read_level
from pipeline.geometry.scene import Scene, scene_from_arrays, slim_scene
from pipeline.geometry.surface import SurfaceSamples, face_areas, interpolate, surface_samples
from pipeline.tracing.foliage import Foliage, overlap_reduced
from pipeline.tracing.labeller import LabelSettings
from pipeline.tracing.level_tracer import LevelLabeller, resample_in_spheres, sphere_directions

log = logging.getLogger(__name__)


@dataclass
class TraceSettings:
    # Rays per surface sample, cosine-weighted (the paper: 256).
    rays: int = 256
    # Obscurance half distances in scene units (the paper: 2 m and 300 m), stored separately.
    half_distance_short: float = 2.0
    half_distance_long: float = 300.0
    # Longest ray, scene units; None -> the level's bounding-box diagonal (nothing is out of reach).
    max_distance: float | None = None
    # Sample budget in samples per receiver vertex, spread over faces by area.
    samples_per_vertex: float = 4.0
    # At most this many samples on one face (Sloan et al.'s cap)...
    samples_per_face_cap: int = 16
    # ... and at least this many (0: the smallest faces may get none; the edge regulariser fills them).
    min_samples_per_face: int = 1
    # Least-squares edge regulariser weight (units of least_squares.REG_SCALE; the paper: alpha = 1).
    alpha: float = 1.0
    # Back-face rule threshold (the paper: 25%); None disables it.
    backface_threshold: float | None = 0.25
    # Samples per resumable trace block (one npz under OUT/stages/trace/ each).
    block_samples: int = 262144
    # Sparse solver of the least-squares systems: "components" (exact: the system is block diagonal over
    # connected components; each block a task, SuperLU below component_vertices and multigrid CG above);
    # or one solve of the whole system: "direct" (SuperLU), "cg" (Jacobi CG), "amg" (multigrid CG).
    solver: Literal["components", "direct", "cg", "amg"] = "components"
    # "components": blocks of at least this many vertices use multigrid CG (SuperLU's fill-in grows
    # faster than linearly on a terrain grid), and smaller components are packed into tasks of this size.
    component_vertices: int = 100_000


@dataclass
class BlendSettings:
    # Weight of the long distance in the blend (the paper: 97% long, 3% short).
    long_weight: float = 0.97
    # Optional remap curve applied after the blend: [[x, y], ...], x increasing over [0, 1].
    remap: list[list[float]] | None = None


@dataclass
class FoliageSettings:
    # Shrubs as media boxes and trees as semi-transparent triangles in a second BVH.
    enabled: bool = True
    # Divide each box's density by 1 + its overlap with the other boxes (foliage module doc).
    reduce_overlaps: bool = True
    # Most foliage crossings followed along one ray (later ones are ignored).
    max_hits: int = 32


@dataclass
class DecoratorSettings:
    # Surface samples per tree instance for the gold standard and the fit of equation 3.
    samples_per_instance: int = 2048
    # Held-out samples per instance for the error table.
    holdout_samples: int = 1024
    # Rays of the local bake (model in isolation) and its sample budget per vertex.
    local_rays: int = 256
    local_samples_per_vertex: float = 8.0


@dataclass
class SmallDecoratorSettings:
    # Radius of the resampling sphere around each grass clump / shrub base (scene units).
    radius: float = 0.75
    # Rays from the sphere's boundary toward its centre (an antipodally symmetric set).
    rays: int = 32


@dataclass
class LodSettings:
    # Make and bake one lower LOD of the receivers.
    enabled: bool = True
    # Fraction of faces the simplifier removes (the paper's LOD: 1.8M -> 0.8M faces, 0.55).
    target_reduction: float = 0.55
    # Resampling sphere radius, scene units; None -> 1.5 x the LOD's median edge length.
    radius: float | None = None
    # Rays per resampling sphere.
    rays: int = 16
    # Least-squares samples per LOD vertex.
    samples_per_vertex: float = 4.0
    # Held-out LOD samples for the error table.
    holdout_samples: int = 4000


@dataclass
class LevelBakeSettings:
    trace: TraceSettings = field(default_factory=TraceSettings)
    blend: BlendSettings = field(default_factory=BlendSettings)
    foliage: FoliageSettings = field(default_factory=FoliageSettings)
    decorators: DecoratorSettings = field(default_factory=DecoratorSettings)
    grass: SmallDecoratorSettings = field(default_factory=SmallDecoratorSettings)
    lod: LodSettings = field(default_factory=LodSettings)
    # Seed of every sample position and ray direction.
    seed: int = 0
    # Tracing threads (embreex releases the GIL).
    workers: int = 2
    # Rays per resampling task (LOD, grass, shrubs) on an engine: scheduling only, never the result.
    task_rays: int = 1 << 20
    # File name of the baked level inside --out (.glb or .gltf).
    output: str = "level_baked.glb"


def check_settings(s: LevelBakeSettings) -> None:
    t = s.trace
    for name, v in (
        ("trace.rays", t.rays),
        ("trace.block_samples", t.block_samples),
        ("workers", s.workers),
        ("task_rays", s.task_rays),
        ("trace.component_vertices", t.component_vertices),
        ("grass.rays", s.grass.rays),
        ("lod.rays", s.lod.rays),
        ("decorators.local_rays", s.decorators.local_rays),
        ("decorators.samples_per_instance", s.decorators.samples_per_instance),
        ("decorators.holdout_samples", s.decorators.holdout_samples),
        ("foliage.max_hits", s.foliage.max_hits),
    ):
        if v < 1:
            raise NeuralaoError(f"{name} must be >= 1, got {v}")
    for name, v in (
        ("trace.half_distance_short", t.half_distance_short),
        ("trace.half_distance_long", t.half_distance_long),
        ("trace.samples_per_vertex", t.samples_per_vertex),
        ("grass.radius", s.grass.radius),
        ("lod.samples_per_vertex", s.lod.samples_per_vertex),
    ):
        if not (math.isfinite(v) and v > 0):
            raise NeuralaoError(f"{name} must be a positive number, got {v}")
    if t.max_distance is not None and not (math.isfinite(t.max_distance) and t.max_distance > 0):
        raise NeuralaoError(f"trace.max_distance must be positive, got {t.max_distance}")
    if not 0 <= t.min_samples_per_face <= t.samples_per_face_cap or t.samples_per_face_cap < 1:
        raise NeuralaoError("need 0 <= trace.min_samples_per_face <= trace.samples_per_face_cap, cap >= 1")
    if not 0.0 <= s.blend.long_weight <= 1.0:
        raise NeuralaoError(f"blend.long_weight must be in [0, 1], got {s.blend.long_weight}")
    if s.blend.remap is not None:
        curve = np.asarray(s.blend.remap, np.float64)
        if curve.ndim != 2 or curve.shape[1] != 2 or len(curve) < 2 or not np.isfinite(curve).all():
            raise NeuralaoError("blend.remap must be a list of at least two [x, y] pairs")
        if not (np.diff(curve[:, 0]) > 0).all() or curve[0, 0] > 0 or curve[-1, 0] < 1:
            raise NeuralaoError("blend.remap x values must increase and cover [0, 1]")
    if not 0.0 < s.lod.target_reduction < 1.0:
        raise NeuralaoError(f"lod.target_reduction must be in (0, 1), got {s.lod.target_reduction}")
    if Path(s.output).suffix.lower() not in (".glb", ".gltf") or Path(s.output).name != s.output:
        raise NeuralaoError(f"output must be a file name ending in .glb or .gltf, got {s.output!r}")


def blend(short: np.ndarray, long: np.ndarray, s: BlendSettings) -> np.ndarray:
    """Per-level blend (long_weight * long + (1 - long_weight) * short) and the optional remap curve."""
    b = s.long_weight * np.asarray(long, np.float64) + (1.0 - s.long_weight) * np.asarray(short, np.float64)
    if s.remap is not None:
        curve = np.asarray(s.remap, np.float64)
        b = np.interp(b, curve[:, 0], curve[:, 1])
    return np.clip(b, 0.0, 1.0).astype(np.float32)


# --------------------------------------------------------------------------- bake log and stages


class BakeLog:
    """Timed stages, each stored (or not) under OUT/stages/ with the bake's key."""

    def __init__(self, out: Path, key: str):
        self.out, self.key = out, key
        self.stages: list[dict[str, Any]] = []
        self.dir = out / "stages"
        self.dir.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(self.dir)
        remove_stale_temporaries(out)

    def timed(self, name: str, description: str, fn, **counts):
        _reset_peak_rss()
        t0, c0 = time.perf_counter(), _cpu_seconds()
        result = fn()
        self._record(name, description, t0, c0, False, counts)
        return result

    def stored(self, name: str, description: str, fn, **counts) -> dict[str, np.ndarray]:
        """``fn() -> dict of arrays``, stored as stages/NAME.npz; reused when its key matches."""
        path = self.dir / f"{name}.npz"
        _reset_peak_rss()
        t0, c0 = time.perf_counter(), _cpu_seconds()
        if path.is_file():
            data = read_npz(path)
            if str(data.pop("_key", "")) == self.key:
                self._record(name, description, t0, c0, True, counts)
                return data
        data = fn()
        write_npz(path, _key=np.array(self.key), **data)
        self._record(name, description, t0, c0, False, counts)

        shutil.rmtree(self.dir / f"{name}.parts", ignore_errors=True)  # its task results (parts)
        return data

    def parts(self, name: str):
        """The :class:`pipeline.engines.engine.ResultStore` of stage ``name``'s task results: each is written
        as it arrives, so a killed bake's rerun skips them; removed once the stage's own file is written."""

        return ResultStore(self.dir / f"{name}.parts")

    def _record(self, name, description, t0, c0, reused, counts) -> None:
        self.stages.append(
            {
                "stage": name,
                "description": description,
                "seconds": time.perf_counter() - t0,
                "cpu_seconds": _cpu_seconds() - c0,
                "reused": reused,
                **counts,
            }
        )
        if (peak := _peak_rss()) is not None:
            self.stages[-1]["peak_rss_bytes"] = peak

    def note(self, name: str, **counts) -> None:
        for st in self.stages:
            if st["stage"] == name:
                st.update(counts)


def _peak_rss() -> int | None:
    """This process's peak resident memory (bytes) since the last :func:`_reset_peak_rss` (Linux's
    VmHWM); None where /proc does not tell it."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _reset_peak_rss() -> None:
    """Start a new peak (Linux: writing 5 to clear_refs resets VmHWM), so each stage reports its own."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _cpu_seconds() -> float:
    """User + system CPU seconds of this process, all threads (on a shared machine, CPU time / cores
    estimates the wall time the same work would take with the cores to itself)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def level_key(path: Path, settings: LevelBakeSettings) -> str:
    """Hash of the level's bytes (the .gltf / .glb and every external buffer) and the settings."""

    files = [sha256_file(path)]
    if path.suffix.lower() == ".gltf":
        try:
            doc = json.loads(path.read_text())
            for b in doc.get("buffers", []):
                uri = b.get("uri", "")
                if uri and not uri.startswith("data:") and (path.parent / uri).is_file():
                    files.append(sha256_file(path.parent / uri))
        except (json.JSONDecodeError, UnicodeDecodeError, AttributeError):
            pass  # read_level reports it
    return sha256_json({"files": files, "settings": settings_to_dict(settings), "version": 1})


# --------------------------------------------------------------------------- geometry


@dataclass
class LevelGeometry:
    level: Level
    receivers: Scene  # static instances (vertex / face order = flatten order)
    opaque: Scene  # receivers first, then blockers
    static_spans: list  # (node k, instance j, first vertex, first face) per static instance
    static_nodes: list[LevelNode]
    trees: list[LevelNode]
    shrubs: list[LevelNode]
    grass: list[LevelNode]


def build_geometry(level: Level) -> LevelGeometry:
    static = level.nodes_with("static")
    rv, rf, spans = flatten(level, static)
    bv, bf, _ = flatten(level, level.nodes_with("blocker"))
    receivers = scene_from_arrays(rv, rf, "receivers", level.source, drop_degenerate=False)
    opaque = scene_from_arrays(
        np.concatenate([rv, bv]),
        np.concatenate([rf, bf + len(rv)]),
        "opaque",
        level.source,
        drop_degenerate=False,
    )
    return LevelGeometry(
        level,
        receivers,
        opaque,
        spans,
        static,
        level.nodes_with("tree"),
        level.nodes_with("shrub"),
        level.nodes_with("grass"),
    )


def receiver_samples(scene: Scene, t: TraceSettings, seed: int) -> SurfaceSamples:
    """bake.surface_samples with the level's per-face floor (0 allowed) and cap.

    Samples per unit area are water-filled: the density ``rho`` is chosen so that
    ``sum clip(rho * area, floor, cap) = total``, i.e. what the cap takes from large faces (big walls,
    distant geometry) goes to the rest, the playable area (Sloan et al.: "this causes more samples to
    be focused in the playable area"). A face's expected count is rounded *stochastically*
    (floor(x + u), u uniform, seeded), so faces that all expect fewer than half a sample (a finely
    tessellated terrain) still get their share on average instead of none at all.
    """
    areas = face_areas(scene)
    total = t.samples_per_vertex * len(scene.vertices)
    expected = _water_filled(areas, total, t.min_samples_per_face, t.samples_per_face_cap)
    u = np.random.default_rng(seed + 0x5A3).uniform(size=len(areas))
    counts = np.clip(np.floor(expected + u), t.min_samples_per_face, t.samples_per_face_cap).astype(np.int64)
    counts[areas <= 0] = 0
    return surface_samples(scene, total, t.samples_per_face_cap, seed, counts=counts)


def _water_filled(areas: np.ndarray, total: float, floor: int, cap: int) -> np.ndarray:
    """(m,) expected counts clip(rho * area, floor, cap) summing to ``total`` (bisection on rho; all
    faces at ``cap`` if even that is below ``total``)."""

    def count(rho: float) -> float:
        return float(np.clip(rho * areas, floor, cap).sum())

    lo, hi = 0.0, total / max(float(areas.sum()), 1e-300)
    while count(hi) < total and hi < 1e300:
        if count(hi) >= cap * len(areas):
            break
        hi *= 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if count(mid) < total else (lo, mid)
    return np.clip(hi * areas, floor, cap)


def instance_boxes(level: Level, nodes: list[LevelNode]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World AABBs lo (b, 3), hi (b, 3) of every instance of ``nodes`` and each one's density (b,)."""
    lo, hi, dens = [], [], []
    for node in nodes:
        v = level.meshes[node.mesh].vertices
        homo = np.c_[v, np.ones(len(v))]
        world = np.einsum("vc,krc->kvr", homo, node.transforms[:, :3])
        lo.append(world.min(axis=1))
        hi.append(world.max(axis=1))
        dens.append(np.full(len(node.transforms), node.params.get("density", 1.0)))
    if not lo:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(lo), np.concatenate(hi), np.concatenate(dens)


def build_foliage(
    g: LevelGeometry, labeller: LevelLabeller, s: FoliageSettings, include_trees: bool = True
) -> Foliage:
    lo, hi, dens = instance_boxes(g.level, g.shrubs)
    if s.reduce_overlaps:
        dens = overlap_reduced(lo, hi, dens)
    tv, tf, trans = np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0)
    if include_trees and g.trees:
        tv, tf, spans = flatten(g.level, g.trees)
        per_face = [
            np.full(len(g.level.meshes[g.trees[k].mesh].faces), g.trees[k].params["transmission"])
            for k, _, _, _ in spans
        ]
        trans = np.concatenate(per_face)
    return Foliage(lo, hi, dens, tv, tf, trans, labeller.center, labeller.scale, s.max_hits)


def label_settings(s: LevelBakeSettings, diagonal: float, rays: int | None = None) -> LabelSettings:
    return LabelSettings(
        rays=rays or s.trace.rays,
        max_distance=s.trace.max_distance or diagonal,
        kernel="obscurance",
        half_distance=s.trace.half_distance_long,
        backface_threshold=s.trace.backface_threshold,
        seed=s.seed,
        workers=s.workers,
    )


def halves(s: LevelBakeSettings) -> list[float]:
    return [s.trace.half_distance_short, s.trace.half_distance_long]


# --------------------------------------------------------------------------- trace (resumable blocks)


def trace_samples(
    log_: BakeLog,
    labeller: LevelLabeller | LabellerFrame,
    foliage,
    samples: SurfaceSamples,
    s: LevelBakeSettings,
    progress: bool,
    engine=None,
) -> dict[str, np.ndarray]:
    """Two-distance obscurance at every sample, in blocks stored under stages/trace/.

    The blocks not stored yet are tasks of ``engine`` (:mod:`pipeline.engines.engine`; None: this process
    with ``labeller``, a RayEngine: workers rebuild the labeller and the foliage from the object store);
    this process writes every block file as it arrives, so resume and bytes never depend on the engine."""
    block, n = s.trace.block_samples, len(samples)
    folder = log_.dir / "trace"
    folder.mkdir(exist_ok=True)
    remove_stale_temporaries(folder)
    ao = np.empty((n, 2), np.float32)
    valid = np.empty(n, bool)
    starts, pending = list(range(0, n, block)), []
    for lo in starts:
        hi = min(lo + block, n)
        path = folder / f"block_{lo // block:05d}.npz"
        data = read_npz(path) if path.is_file() else {}
        if str(data.get("_key", "")) == log_.key and len(data["valid"]) == hi - lo:
            ao[lo:hi], valid[lo:hi] = data["ao"], data["valid"]
        else:
            pending.append((lo, hi, path))
    ctx = opaque_context(log_.key, labeller, foliage, engine)
    if engine is None:  # the driver's own labeller and foliage are the context's state
        engine = LocalEngine(states={ctx.key: (labeller, foliage)})
    tasks = (
        Task(
            ctx,
            _trace_block,
            (samples.points[lo:hi], samples.normals[lo:hi], np.arange(lo, hi, dtype=np.int64), halves(s)),
        )
        for lo, hi, _ in pending
    )
    with tqdm(total=len(pending), desc="trace blocks", disable=not progress, leave=False) as bar:
        for i, r in engine.map(tasks):
            lo, hi, path = pending[i]
            write_npz(path, _key=np.array(log_.key), ao=r["ao"], valid=r["valid"])
            ao[lo:hi], valid[lo:hi] = r["ao"], r["valid"]
            bar.update(1)
    reused = len(starts) - len(pending)
    return {"ao": ao, "valid": valid, "reused_blocks": np.array(reused), "blocks": np.array(len(starts))}


def _level_tracer(payload) -> tuple[LevelLabeller, object]:
    scene, settings, foliage = payload
    return LevelLabeller(scene, settings), foliage


def _trace_block(state, args) -> dict[str, np.ndarray]:
    labeller, foliage = state
    points, normals, ids, half = args
    ao, valid = labeller.obscurance(points, normals, half, foliage, ids=ids)
    return {"ao": ao, "valid": valid}


class LabellerFrame:
    """The driver's stand-in for the opaque :class:`LevelLabeller` when an engine traces: the scene, its
    label settings and the local frame (``center``, ``scale``) the foliage is built in, no Embree scene."""

    def __init__(self, scene: Scene, settings: LabelSettings):
        self.scene, self.settings = scene, settings
        self.center = np.asarray(scene.center, dtype=np.float64)
        self.scale = float(scene.diagonal)
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise NeuralaoError(f"scene {scene.name} has no extent (diagonal {self.scale})")


def opaque_context(key: str, labeller: LevelLabeller | LabellerFrame, foliage, engine=None):
    """The engine context of the opaque labeller and the foliage (trace, resampling): workers rebuild
    both from the object store; with ``engine`` None, a context the driver's own state stands for."""

    if engine is None:
        return Context(f"level-trace/{key}/here", _level_tracer, None)
    settings = (
        labeller.settings if engine.threads is None else replace(labeller.settings, workers=engine.threads)
    )
    return Context(
        f"level-trace/{key}/{settings.workers}",
        _level_tracer,
        (slim_scene(labeller.scene), settings, foliage),
    )


# --------------------------------------------------------------------------- decorators (section 2.2)


def linear_basis(points: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(k, 4) rows [1, x - ox, y - oy, z - oz]: the 3-D linear global function's basis."""
    return np.c_[np.ones(len(points)), np.asarray(points) - np.asarray(origin)]


def fit_global(
    points: np.ndarray, origin: np.ndarray, local: np.ndarray, target: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Equation 3: y (4,) minimising sum_i w_i (f_i - G_y(s_i) L_i)^2, G_y(p) = y . [1, p - origin]."""
    a = linear_basis(points, origin) * np.asarray(local, np.float64)[:, None]
    sw = np.sqrt(np.asarray(weights, np.float64))
    y, *_ = np.linalg.lstsq(a * sw[:, None], np.asarray(target, np.float64) * sw, rcond=None)
    return y


def transform_samples(samples: SurfaceSamples, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Object-space samples -> world points (k, 3) and unit normals (k, 3) under the 4x4 ``m``."""
    p = samples.points @ m[:3, :3].T + m[:3, 3]
    n = samples.normals @ np.linalg.inv(m[:3, :3])
    return p, n / np.linalg.norm(n, axis=1, keepdims=True)


_DECORATOR_ERRORS = ("local_x_global", "global_only", "in_place", "local_only", "local_x_global_vs_in_place")


def gold_scene(g: LevelGeometry) -> Scene:
    """The decorators' gold standard scene: the opaque level plus every tree instance, opaque."""
    tv, tf, _ = flatten(g.level, g.trees)
    return scene_from_arrays(
        np.concatenate([g.opaque.vertices, tv]),
        np.concatenate([g.opaque.faces, tf + len(g.opaque.vertices)]),
        "gold",
        drop_degenerate=False,
    )


@dataclass
class _TreeModel:
    """What every in-place task of one tree model reads (a :class:`pipeline.engines.engine.Shared` value)."""

    model: Scene  # the model's mesh (object space)
    train: SurfaceSamples  # fit samples (object space)
    hold: SurfaceSamples  # held-out samples (object space)
    local: np.ndarray  # (v,) float32 local AO per model vertex (blended)
    l_train: np.ndarray  # (train,) float64 local AO at the fit samples


def _tree_model(g: LevelGeometry, mi: int, s: LevelBakeSettings) -> _TreeModel:
    """Local AO of tree model ``mi`` baked in isolation (both distances, least squares, blended)."""
    d = s.decorators
    mesh = g.level.meshes[mi]
    model = scene_from_arrays(mesh.vertices, mesh.faces, mesh.name, drop_degenerate=False)
    loc_lab = LevelLabeller(
        model,
        replace(
            label_settings(s, g.opaque.diagonal, d.local_rays),
            max_distance=s.trace.max_distance or g.opaque.diagonal,
        ),
    )
    loc_samples = surface_samples(model, d.local_samples_per_vertex * len(model.vertices), 32, s.seed)
    a, v = loc_lab.obscurance(loc_samples.points, loc_samples.normals, halves(s))
    local_two = fit_least_squares(model, loc_samples, a, v, s.trace.alpha)
    local = blend(local_two[:, 0], local_two[:, 1], s.blend)
    train = surface_samples(model, d.samples_per_instance, 64, s.seed + 1)
    hold = surface_samples(model, d.holdout_samples, 64, s.seed + 2)
    return _TreeModel(
        slim_scene(model), train, hold, local, interpolate(model, local, train.face, train.bary)
    )


def _tree_instance(state, args) -> dict[str, np.ndarray]:
    """Engine task: one tree instance traced in place (gold labeller + foliage without trees) and its
    equation-3 fits and errors. args: (_TreeModel (Shared), 4x4 transform, instance number, settings)."""
    gold_labeller, gold_foliage = state
    tm, m, uid, s = args
    model, train, hold, local, l_train = tm.model, tm.train, tm.hold, tm.local, tm.l_train
    pt, nt = transform_samples(train, m)
    ph, nh = transform_samples(hold, m)
    ids = np.arange(len(pt) + len(ph), dtype=np.int64) + uid * (1 << 24)
    ao, valid = gold_labeller.obscurance(np.r_[pt, ph], np.r_[nt, nh], halves(s), gold_foliage, ids=ids)
    f = blend(ao[:, 0], ao[:, 1], s.blend).astype(np.float64)
    ft, vt, fh, vh = f[: len(pt)], valid[: len(pt)], f[len(pt) :], valid[len(pt) :]
    origin = m[:3, 3]
    y = fit_global(pt[vt], origin, l_train[vt], ft[vt], train.weights[vt])
    y1 = fit_global(pt[vt], origin, np.ones(vt.sum()), ft[vt], train.weights[vt])
    # In place: the instance's own least-squares vertex bake (what per-vertex storage buys).
    inplace = fit_least_squares(model, train, ft, vt, s.trace.alpha)
    world_v = model.vertices @ m[:3, :3].T + m[:3, 3]
    # What the shader shows: the per-vertex product, interpolated by the rasteriser.
    prod = np.clip(local * (linear_basis(world_v, origin) @ y), 0, 1)
    w = hold.weights[vh] / hold.weights[vh].sum()
    preds = {
        "local_x_global": interpolate(model, prod, hold.face, hold.bary),
        "global_only": np.clip(linear_basis(ph, origin) @ y1, 0, 1),
        "in_place": interpolate(model, inplace, hold.face, hold.bary),
        "local_only": interpolate(model, local, hold.face, hold.bary),
    }
    err = {k: float(np.sqrt(np.sum(w * (p[vh] - fh[vh]) ** 2))) for k, p in preds.items()}
    err["local_x_global_vs_in_place"] = float(
        np.sqrt(np.sum(w * (preds["local_x_global"][vh] - preds["in_place"][vh]) ** 2))
    )
    return {"y": y, "y1": y1, "errors": np.array([err[k] for k in _DECORATOR_ERRORS])}


def bake_decorators(
    g: LevelGeometry,
    s: LevelBakeSettings,
    foliage_settings: FoliageSettings,
    engine=None,
    store=None,
    key: str = "",
) -> dict[str, np.ndarray]:
    """Local AO per tree model, gold standard per instance, equation-3 coefficients, errors.

    The local AO of each model is baked here; every instance's in-place trace and fits is a task of
    ``engine`` (None: this process, with the gold labeller built here), results kept in ``store``
    (:class:`pipeline.engines.engine.ResultStore`) as they arrive. Instances are numbered (and traced with
    ray ids) in a fixed order, so the result is the same bytes wherever the tasks run."""

    if not g.trees:
        return {"models": np.zeros(0, np.int64)}
    settings = label_settings(s, g.opaque.diagonal)
    gold = gold_scene(g)
    if engine is not None and engine.threads is not None:
        settings = replace(settings, workers=engine.threads)
    ctx_key = f"level-gold/{key or content_key(gold.vertices, gold.faces)}/{settings.workers}"
    if engine is None:
        # The gold standard sees the trees as opaque geometry (every instance baked in place).
        gold_labeller = LevelLabeller(gold, settings)
        gold_foliage = (
            build_foliage(g, gold_labeller, foliage_settings, include_trees=False)
            if foliage_settings.enabled
            else None
        )
        runner = LocalEngine(states={ctx_key: (gold_labeller, gold_foliage)})
        payload = None
    else:
        runner = engine
        # Foliage lives in a labeller's local frame: the gold labeller's (its scene's centre and
        # diagonal), without building its BVH here.
        frame = SimpleNamespace(center=np.asarray(gold.center, np.float64), scale=float(gold.diagonal))
        gold_foliage = (
            build_foliage(g, frame, foliage_settings, include_trees=False)
            if foliage_settings.enabled
            else None
        )
        payload = (slim_scene(gold), settings, gold_foliage)
    ctx = Context(ctx_key, _level_tracer, payload)
    models = sorted({n.mesh for n in g.trees})
    out: dict[str, Any] = {}
    jobs = []  # (shared model, transform, uid) in the order of the result rows
    for mi in models:
        tm = _tree_model(g, mi, s)
        out[f"local_{mi}"] = tm.local
        shared = Shared(content_key(key, "tree-model", mi), tm)
        for node in (n for n in g.trees if n.mesh == mi):
            for m in node.transforms:
                jobs.append((shared, np.asarray(m, np.float64), len(jobs)))

    def tasks():
        for shared, m, uid in jobs:
            yield Task(ctx, _tree_instance, (shared, m, uid, s), content_key(ctx_key, shared.key, m, uid))

    rows: list[dict | None] = [None] * len(jobs)
    for i, r in runner.map(tasks(), store):
        rows[i] = r
    out["models"] = np.array(models, np.int64)
    out["coefficients"] = np.array([r["y"] for r in rows])
    out["coefficients_global_only"] = np.array([r["y1"] for r in rows])
    errors = np.array([r["errors"] for r in rows]).reshape(len(rows), len(_DECORATOR_ERRORS))
    for j, k in enumerate(_DECORATOR_ERRORS):
        out[f"rmse_{k}"] = errors[:, j]
    return out


# --------------------------------------------------------------------------- LOD (section 2.2.1)


def simplify(scene: Scene, reduction: float) -> Scene:
    import fast_simplification  # measured: ~0.3 s to import; only the LOD stage needs it

    v, f = fast_simplification.simplify(
        scene.vertices.astype(np.float32), scene.faces.astype(np.int32), target_reduction=reduction
    )
    return scene_from_arrays(np.asarray(v, np.float64), np.asarray(f, np.int64), "lod1", scene.source)


def median_edge(scene: Scene) -> float:
    t = scene.triangles
    return float(np.median(np.linalg.norm(t[:, 1] - t[:, 0], axis=1)))


def bake_lod(
    g: LevelGeometry,
    resample: Resampler | LevelLabeller,
    high_ao: np.ndarray,
    samples: SurfaceSamples,
    traced: np.ndarray,
    traced_valid: np.ndarray,
    s: LevelBakeSettings,
) -> dict[str, np.ndarray]:
    """LOD1 of the receivers and its AO by (a) resampling at its vertices, (b) least squares over
    resampled surface samples; both against the gold standard at held-out LOD samples.

    ``resample``: a :class:`Resampler` (its blocks are engine tasks), or the opaque labeller (here)."""
    from scipy.spatial import cKDTree  # measured: ~0.8 s to import; only this step needs it

    if isinstance(resample, LevelLabeller):
        resample = Resampler.here(resample)
    t0 = time.perf_counter()
    lod = simplify(g.receivers, s.lod.target_reduction)
    t1 = time.perf_counter()
    radius = s.lod.radius or 1.5 * median_edge(lod)
    values = resample.share(np.r_[high_ao, np.full(len(g.opaque.vertices) - len(high_ao), np.nan)])
    at_vertices = resample(values, lod.vertices, radius, s.lod.rays, "lod-vertices")
    lod_samples = surface_samples(lod, s.lod.samples_per_vertex * len(lod.vertices), 16, s.seed + 3)
    at_samples = resample(values, lod_samples.points, radius, s.lod.rays, "lod-samples")
    ok = np.isfinite(at_samples)
    t2 = time.perf_counter()
    lsq = fit_level(
        lod, lod_samples, np.where(ok, at_samples, 0.0), ok, s.trace, resample.engine, resample.store, "lod"
    )
    fill = float(np.nanmean(at_vertices)) if np.isfinite(at_vertices).any() else 1.0
    vert = np.where(np.isfinite(at_vertices), at_vertices, fill).astype(np.float32)
    t3 = time.perf_counter()
    # Gold standard at held-out LOD points: the traced samples of the full-resolution surface within the
    # sphere and facing the same way, weighted by area and by distance to the boundary (no vertex bake,
    # no resampling rays).
    hold = surface_samples(
        lod, s.lod.holdout_samples, 4, s.seed + 4, counts=_holdout_counts(lod, s.lod.holdout_samples, s.seed)
    )
    f = blend(traced[:, 0], traced[:, 1], s.blend).astype(np.float64)
    pts, nrm = samples.points[traced_valid], samples.normals[traced_valid]
    fw, sw = f[traced_valid], samples.weights[traced_valid]
    tree = cKDTree(pts)
    ref = np.full(len(hold), np.nan)
    for i, nb in enumerate(tree.query_ball_point(hold.points, radius)):
        if nb:
            nb = np.asarray(nb)
            # The same surface only: samples facing within 60 degrees of the LOD point's normal (a
            # wall beside a terrain point is nearby but is not what the LOD face stands for).
            w = sw[nb] * np.maximum(radius - np.linalg.norm(pts[nb] - hold.points[i], axis=1), 0)
            w = w * (nrm[nb] @ hold.normals[i] > 0.5)
            if w.sum() > 0:
                ref[i] = np.sum(w * fw[nb]) / w.sum()
    m = np.isfinite(ref)
    w = hold.weights[m] / hold.weights[m].sum()
    errs = {
        k: float(np.sqrt(np.sum(w * (interpolate(lod, v, hold.face, hold.bary)[m] - ref[m]) ** 2)))
        for k, v in (("vertex", vert), ("least_squares", lsq))
    }
    # Baseline: one constant (the reference's mean) for the whole LOD.
    errs["constant"] = float(np.sqrt(np.sum(w * (ref[m] - np.sum(w * ref[m])) ** 2)))
    return {
        "vertices": lod.vertices,
        "faces": lod.faces,
        "ao_vertex": vert,
        "ao_least_squares": lsq,
        "radius": np.array(radius),
        "resample_points": np.array(len(lod.vertices) + len(lod_samples)),
        "rmse_vertex": np.array(errs["vertex"]),
        "rmse_constant": np.array(errs["constant"]),
        "rmse_least_squares": np.array(errs["least_squares"]),
        "holdout": np.array(int(m.sum())),
        "seconds_simplify": np.array(t1 - t0),
        "seconds_resample": np.array(t2 - t1),
        "seconds_solve": np.array(t3 - t2),
        "seconds_reference": np.array(time.perf_counter() - t3),
    }


def _holdout_counts(scene: Scene, total: int, seed: int) -> np.ndarray:
    """Held-out sample counts: ``total`` faces drawn by area (seeded), one sample each."""
    areas = face_areas(scene)
    rng = np.random.default_rng(seed + 99)
    pick = rng.choice(len(areas), size=min(total, len(areas)), replace=False, p=areas / areas.sum())
    counts = np.zeros(len(areas), np.int64)
    counts[pick] = 1
    return counts


# --------------------------------------------------------------------------- the bake


def bake_level(
    path: str | Path, settings: LevelBakeSettings, out: str | Path, progress: bool = False, engine=None
) -> dict:
    """Bake the level at ``path`` into the folder ``out``; returns the bake log (also OUT/bake_log.json).

    ``engine`` (:mod:`pipeline.engines.engine`): runs the trace stage's blocks, the trees' in-place traces and
    fits, and the resampling of grass, shrubs and the LOD as tasks (None: here, with threads)."""

    check_settings(settings)
    path, out = Path(path), Path(out)
    if out.exists() and not out.is_dir():
        raise NeuralaoError(f"--out {out} is a file; a level bake writes a folder")
    t_start, c_start = time.perf_counter(), _cpu_seconds()
    key = level_key(path, settings) if path.is_file() else ""
    level = read_level(path)
    out.mkdir(parents=True, exist_ok=True)
    blog = BakeLog(out, key)
    s = settings
    g = blog.timed("geometry", "Process geometry", lambda: build_geometry(level))
    blog.note(
        "geometry",
        vertices=len(g.receivers.vertices),
        faces=len(g.receivers.faces),
        occluder_faces=len(g.opaque.faces),
    )
    samples = blog.timed("samples", "Sample mesh", lambda: receiver_samples(g.receivers, s.trace, s.seed))
    blog.note("samples", samples=len(samples))
    # With an engine every trace runs on the workers, so the driver keeps no Embree scene (a few GiB for a
    # world of tens of millions of faces), only the opaque scene's frame.
    labeller = blog.timed(
        "bvh",
        "Embree BVH build (opaque)",
        lambda: (LevelLabeller if engine is None else LabellerFrame)(
            g.opaque, label_settings(s, g.opaque.diagonal)
        ),
    )
    foliage = None
    if s.foliage.enabled:
        foliage = blog.timed(
            "foliage",
            "Flatten trees, shrub 'fog' boxes + foliage BVH",
            lambda: build_foliage(g, labeller, s.foliage),
        )
        blog.note("foliage", trees=sum(len(n.transforms) for n in g.trees), shrub_boxes=foliage.n_boxes)
    traced = blog.stored(
        "trace",
        "Ray trace samples (2 distances, foliage)",
        lambda: trace_samples(blog, labeller, foliage, samples, s, progress, engine),
        samples=len(samples),
        rays=len(samples) * s.trace.rays,
    )
    deco = blog.stored(
        "decorators",
        "Trees: local AO, in-place gold standard, eq. 3 fits",
        lambda: bake_decorators(g, s, s.foliage, engine, blog.parts("decorators"), key),
        instances=sum(len(n.transforms) for n in g.trees),
    )
    solved = blog.stored(
        "solve",
        "Least squares solve (both distances)",
        lambda: _solve(g, samples, traced, s, engine, blog.parts("solve")),
        vertices=len(g.receivers.vertices),
    )
    blog.note("solve", **{k: float(v) for k, v in solved.items() if k.startswith("seconds_")})
    final = blend(solved["short"], solved["long"], s.blend)
    ctx = opaque_context(key, labeller, foliage, engine)

    def resampler(stage: str) -> Resampler:
        if engine is None:
            return Resampler.here(labeller, foliage, ctx.key, blog.parts(stage), s.task_rays)
        return Resampler(engine, ctx, blog.parts(stage), s.task_rays)

    small = blog.stored(
        "small_decorators",
        "Resample grass clumps and shrubs",
        lambda: _small_decorators(g, resampler("small_decorators"), final, s),
    )
    lod = None
    if s.lod.enabled:
        lod = blog.stored(
            "lod",
            "LOD: simplify, resample, least squares solve",
            lambda: bake_lod(g, resampler("lod"), final, samples, traced["ao"], traced["valid"], s),
        )
        blog.note(
            "lod",
            lod_vertices=len(lod["vertices"]),
            lod_faces=len(lod["faces"]),
            resample_points=int(lod["resample_points"]),
            **{
                k: float(lod[k])
                for k in ("seconds_simplify", "seconds_resample", "seconds_solve", "seconds_reference")
            },
        )
    blend_err = blog.stored(
        "blend_check",
        "Two-distance blend vs blended-kernel traces (error table)",
        lambda: _blend_check(g, labeller, foliage, samples, traced, solved, s, engine=engine, key=key),
    )
    blog.timed(
        "output",
        "Write glTF, shader, log",
        lambda: write_outputs(out / s.output, out, g, s, solved, final, deco, small, lod),
    )
    # ru_maxrss is the whole run's peak (the stages' own peaks are in their rows: VmHWM is reset per stage).
    peak = max(
        [resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024]
        + [st.get("peak_rss_bytes", 0) for st in blog.stages]
    )
    info = {
        "level": str(path),
        "key": key,
        "settings": settings_to_dict(s),
        "stages": blog.stages,
        "seconds_total": time.perf_counter() - t_start,
        "cpu_seconds_total": _cpu_seconds() - c_start,
        "peak_rss_bytes": int(peak),
        "counts": {
            **level.counts(),
            "receiver_vertices": len(g.receivers.vertices),
            "receiver_faces": len(g.receivers.faces),
            "samples": len(samples),
            "invalid_samples": int((~traced["valid"]).sum()),
        },
        "errors": _error_tables(deco, lod, blend_err),
        "load_average": list(os.getloadavg()),
        "cpu_count": os.cpu_count(),
    }
    write_json(out / "bake_log.json", info)
    write_text(out / "bake_log.md", bake_log_markdown(info))
    return info


def _solve(
    g: LevelGeometry, samples: SurfaceSamples, traced: dict, s: LevelBakeSettings, engine=None, store=None
) -> dict[str, np.ndarray]:
    timing: dict[str, float] = {}
    v = fit_level(
        g.receivers, samples, traced["ao"], traced["valid"], s.trace, engine, store, "receivers", timing
    )
    return {"short": v[:, 0], "long": v[:, 1], **{f"seconds_{k}": np.array(x) for k, x in timing.items()}}


def fit_level(
    scene: Scene,
    samples: SurfaceSamples,
    values: np.ndarray,
    valid: np.ndarray,
    t: TraceSettings,
    engine=None,
    store=None,
    tag: str = "",
    timing: dict | None = None,
) -> np.ndarray:
    """:func:`pipeline.geometry.least_squares.fit_least_squares` with the level's solver
    (``t.solver``, ``t.alpha``).

    "components": the normal equations are assembled here, split into their connected components (the
    matrix couples only vertices that share a face, so the blocks' solutions are the global solution),
    and each block, or a pack of small ones, is a task of ``engine`` (None: this process), its result
    kept in ``store`` (keys: ``tag`` and the block) as it arrives. Returns (n,) or (n, c) float32.
    ``timing`` (a dict, filled in): seconds of the assembly here, of all blocks, and of the largest
    block (what a cluster cannot split further; each task times itself, a stored one as it took then)."""

    if t.solver != "components":
        return fit_least_squares(scene, samples, values, valid, t.alpha, t.solver)
    t0 = time.perf_counter()
    a, rhs = normal_equations(scene, samples, values, valid, t.alpha)
    blocks = component_blocks(a, t.component_vertices)
    a = a.tocsr()
    timing = {} if timing is None else timing
    timing.update(assembly=time.perf_counter() - t0, blocks=0.0, largest_block=0.0)
    ctx = Context("level-solve", _no_state, None)

    def tasks():
        for idx, method in blocks:
            sub = a[idx][:, idx].tocsc()
            yield Task(
                ctx,
                _solve_block,
                (sub, rhs[idx], method),
                content_key("solve", tag, idx, method, sub.data, rhs[idx]),
            )

    out = np.empty(rhs.shape)
    for i, r in (engine or LocalEngine()).map(tasks(), store):
        out[blocks[i][0]] = r["v"]
        took = float(r.get("seconds", 0.0))
        timing["blocks"] += took
        timing["largest_block"] = max(timing["largest_block"], took)
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def component_blocks(a, big: int) -> list[tuple[np.ndarray, str]]:
    """The connected components of the sparse symmetric ``a`` as solve tasks: (vertex indices (ascending)
    int64, "amg" | "direct"). A component of at least ``big`` vertices is a task of its own solved by
    multigrid CG; smaller ones (SuperLU) are packed, largest first, into tasks of about ``big`` vertices."""
    _, label = connected_components(a, directed=False)
    sizes = np.bincount(label)
    members = np.split(np.argsort(label, kind="stable"), np.cumsum(sizes)[:-1])
    blocks, pack, packed = [], [], 0
    for c in np.argsort(-sizes, kind="stable"):
        if sizes[c] >= big:
            blocks.append((members[c], "amg"))
            continue
        pack.append(members[c])
        packed += sizes[c]
        if packed >= big:
            blocks.append((np.sort(np.concatenate(pack)), "direct"))
            pack, packed = [], 0
    if pack:
        blocks.append((np.sort(np.concatenate(pack)), "direct"))
    return blocks


def _no_state(payload) -> None:
    return None


def _solve_block(state, args) -> dict[str, np.ndarray]:
    """Engine task: one block of the normal equations (csc matrix, rhs, "direct" | "amg")
    -> {"v": solution}."""
    a, rhs, method = args
    t0 = time.perf_counter()
    v = splu(a).solve(rhs) if method == "direct" else solve_amg(a, rhs)
    return {"v": v, "seconds": np.array(time.perf_counter() - t0)}


def _small_decorators(
    g: LevelGeometry, resample: Resampler, final: np.ndarray, s: LevelBakeSettings
) -> dict[str, np.ndarray]:
    values = resample.share(np.r_[final, np.full(len(g.opaque.vertices) - len(final), np.nan)])
    out: dict[str, np.ndarray] = {}
    for role, nodes in (("grass", g.grass), ("shrub", g.shrubs)):
        for k, node in enumerate(nodes):
            centres = node.transforms[:, :3, 3]
            v = resample(values, centres, s.grass.radius, s.grass.rays, f"{role}-{k}")
            missing = ~np.isfinite(v)
            out[f"{role}_{k}"] = np.where(missing, 1.0, v).astype(np.float32)
            out[f"{role}_{k}_missing"] = np.array(int(missing.sum()))
    return out


def _resample_task(state, args) -> dict[str, np.ndarray]:
    """Engine task: :func:`resample_in_spheres` of one block of centres on the opaque labeller."""
    labeller, _ = state
    values, centers, radius, rays = args
    v, total = resample_in_spheres(labeller, values, centers, radius, rays)
    return {"values": v, "total": total}


class Resampler:
    """:func:`resample_in_spheres` with the centres split into blocks of ``task_rays`` rays,
    each a task of ``engine`` on the opaque labeller's context (the trace's, so workers reuse its state);
    a centre's value depends only on its own rays, so the bytes never depend on where blocks run.
    ``store``: finished blocks kept on disk (a killed bake's rerun skips them)."""

    def __init__(self, engine, context, store=None, task_rays: int = 1 << 20):
        self.engine, self.context, self.store, self.task_rays = engine, context, store, task_rays

    @classmethod
    def here(
        cls, labeller: LevelLabeller, foliage=None, key: str = "here", store=None, task_rays: int = 1 << 20
    ) -> Resampler:
        """Blocks run in this process on ``labeller`` (its threads)."""

        ctx = Context(key, _level_tracer, None)
        return cls(LocalEngine(states={key: (labeller, foliage)}), ctx, store, task_rays)

    @staticmethod
    def share(values: np.ndarray):
        """Per-vertex values of the opaque scene as a :class:`pipeline.engines.engine.Shared` (sent once)."""

        return Shared(content_key("opaque-values", values), np.asarray(values, np.float64))

    def __call__(self, values, centers: np.ndarray, radius: float, rays: int, tag: str) -> np.ndarray:
        """values: :meth:`share` of (n,) vertex values; centers (p, 3) -> (p,) float64 (NaN: no hit)."""

        centers = np.asarray(centers, np.float64).reshape(-1, 3)
        step = max(1, self.task_rays // len(sphere_directions(rays)))
        bounds = [(lo, min(lo + step, len(centers))) for lo in range(0, len(centers), step)]
        tasks = (
            Task(
                self.context,
                _resample_task,
                (values, centers[lo:hi], radius, rays),
                content_key(self.context.key, values.key, tag, lo, hi, radius, rays),
            )
            for lo, hi in bounds
        )
        out = np.full(len(centers), np.nan)
        for i, r in self.engine.map(tasks, self.store):
            lo, hi = bounds[i]
            out[lo:hi] = r["values"]
        return out


# Largest level on which the blend check also fits the blended samples by least squares.
_BLEND_LSQ_CHECK_VERTICES = 300_000


def _blend_check(
    g,
    labeller,
    foliage,
    samples,
    traced,
    solved,
    s: LevelBakeSettings,
    count: int = 2000,
    engine=None,
    key: str = "",
) -> dict:
    """The error table of the two-distance blend: (a) same rays (valid samples): blend of the two columns vs
    one trace whose kernel is the blend (rho_b = w rho_long + (1 - w) rho_short: the mean is linear, so any
    difference is float rounding); (b) the stored per-vertex blend vs a 4x-ray blended-kernel reference
    at held-out samples (the bake's error); (c) per-vertex blend vs least squares of blended samples.
    With ``engine`` the two traces are its tasks (the reference labeller is built on a worker)."""
    rng = np.random.default_rng(s.seed + 7)
    pick = np.sort(rng.choice(len(samples), size=min(count, len(samples)), replace=False))
    pts, nrm = samples.points[pick], samples.normals[pick]
    w = s.blend.long_weight
    plain = replace(s.blend, remap=None)
    two = blend(traced["ao"][pick, 0], traced["ao"][pick, 1], plain)
    ref_settings = replace(label_settings(s, g.opaque.diagonal, 4 * s.trace.rays), seed=s.seed + 1000)
    if engine is None:
        kern = _blended_kernel_trace(labeller, foliage, pts, nrm, s, ids=pick)
        ref_two, ref_valid = LevelLabeller(g.opaque, ref_settings).obscurance(pts, nrm, halves(s), foliage)
    else:
        if engine.threads is not None:
            ref_settings = replace(ref_settings, workers=engine.threads)
        ref_ctx = Context(
            f"level-reference/{key}/{ref_settings.workers}",
            _level_tracer,
            (slim_scene(g.opaque), ref_settings, foliage),
        )
        tasks = [
            Task(opaque_context(key, labeller, foliage, engine), _blend_kernel_task, (pts, nrm, pick, s)),
            Task(ref_ctx, _obscurance_task, (pts, nrm, halves(s))),
        ]
        done = dict(engine.map(tasks))
        kern, ref_two, ref_valid = done[0]["kern"], done[1]["ao"], done[1]["valid"]
    ref = w * ref_two[:, 1].astype(np.float64) + (1 - w) * ref_two[:, 0]
    per_vertex = blend(solved["short"], solved["long"], plain)
    pred = interpolate(g.receivers, per_vertex, samples.face[pick], samples.bary[pick])
    m = ref_valid & traced["valid"][pick]
    # (c) needs a third full least-squares solve: only on levels small enough for it to be cheap.
    vertex_gap = np.nan
    if len(g.receivers.vertices) <= _BLEND_LSQ_CHECK_VERTICES:
        blended_samples = blend(traced["ao"][:, 0], traced["ao"][:, 1], plain)
        lsq_blended = fit_level(g.receivers, samples, blended_samples, traced["valid"], s.trace)
        vertex_gap = float(np.abs(per_vertex - lsq_blended).max())
    return {
        # over valid samples: the trace stops early on samples the back-face rule rejects
        "same_rays_max_abs": np.array(float(np.abs(two - kern)[traced["valid"][pick]].max(initial=0.0))),
        "bake_rmse_vs_reference": np.array(float(np.sqrt(np.mean((pred[m] - ref[m]) ** 2)))),
        "samples_rmse_vs_reference": np.array(float(np.sqrt(np.mean((two[m] - ref[m]) ** 2)))),
        "per_vertex_blend_vs_lsq_of_blend_max_abs": np.array(vertex_gap),
        "count": np.array(int(m.sum())),
    }


def _blend_kernel_task(state, args) -> dict[str, np.ndarray]:
    labeller, foliage = state
    pts, nrm, ids, s = args
    return {"kern": _blended_kernel_trace(labeller, foliage, pts, nrm, s, ids=ids)}


def _obscurance_task(state, args) -> dict[str, np.ndarray]:
    labeller, foliage = state
    pts, nrm, half = args
    ao, valid = labeller.obscurance(pts, nrm, half, foliage)
    return {"ao": ao, "valid": valid}


def _blended_kernel_trace(
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


def _error_tables(deco: dict, lod: dict | None, blend_err: dict) -> dict:
    out: dict[str, Any] = {"blend": {k: float(v) for k, v in blend_err.items()}}
    if len(deco.get("models", [])):
        out["decorators"] = {
            k[5:]: {"mean": float(np.mean(v)), "max": float(np.max(v))}
            for k, v in deco.items()
            if k.startswith("rmse_")
        }
        out["decorators"]["instances"] = int(len(deco["coefficients"]))
    if lod is not None:
        out["lod"] = {
            "rmse_vertex": float(lod["rmse_vertex"]),
            "rmse_least_squares": float(lod["rmse_least_squares"]),
            "rmse_constant": float(lod["rmse_constant"]),
            "holdout": int(lod["holdout"]),
            "radius": float(lod["radius"]),
        }
    return out


def bake_log_markdown(info: dict) -> str:
    """A table like Table 1 of Sloan et al. 2013 (stage, counts, seconds) plus totals and errors."""
    c = info["counts"]
    lines = [
        f"Bake of {Path(info['level']).name}: {c['receiver_vertices']:,} V {c['receiver_faces']:,} F, "
        f"{c['samples']:,} samples, {info['settings']['trace']['rays']} rays",
        "",
        "| Description | Time (s) | CPU (s) | peak RSS (MiB) | reused |",
        "|---|---:|---:|---:|:---:|",
    ]
    skip = ("stage", "description", "seconds", "cpu_seconds", "reused", "peak_rss_bytes")
    for st in info["stages"]:
        extra = {k: v for k, v in st.items() if k not in skip}
        detail = ", ".join(
            f"{k} {v:,}" if isinstance(v, int) else f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}"
            for k, v in extra.items()
        )
        rss = f"{st['peak_rss_bytes'] / 2**20:,.0f}" if "peak_rss_bytes" in st else ""
        lines.append(
            f"| {st['description']}{' (' + detail + ')' if detail else ''} | {st['seconds']:.2f} | "
            f"{st['cpu_seconds']:.1f} | {rss} | {'yes' if st['reused'] else ''} |"
        )
    lines += [
        f"| **Total** | **{info['seconds_total']:.1f}** | **{info['cpu_seconds_total']:.1f}** | "
        f"**{info['peak_rss_bytes'] / 2**20:,.0f}** | |",
        "",
        f"Peak memory (RSS): {info['peak_rss_bytes'] / 2**30:.2f} GiB; "
        f"load average {info['load_average'][0]:.2f} "
        f"on {info['cpu_count']} cores (CPU s: all threads of this process).",
        "",
    ]
    e = info["errors"]
    if "decorators" in e:
        d = e["decorators"]
        lines += ["| decorators (trees, RMSE vs traced gold standard) | mean | max |", "|---|---:|---:|"]
        for k in ("in_place", "local_x_global", "global_only", "local_only", "local_x_global_vs_in_place"):
            lines.append(f"| {k.replace('_', ' ')} | {d[k]['mean']:.4f} | {d[k]['max']:.4f} |")
        lines.append("")
    if "lod" in e:
        lines += [
            "| LOD transfer (RMSE vs gold standard) | RMSE |",
            "|---|---:|",
            f"| resampled at LOD vertices | {e['lod']['rmse_vertex']:.4f} |",
            f"| least squares over resampled samples | {e['lod']['rmse_least_squares']:.4f} |",
            f"| (baseline: one constant) | {e['lod']['rmse_constant']:.4f} |",
            "",
        ]
    b = e["blend"]
    lines += [
        "| two-distance blend | value |",
        "|---|---:|",
        "| same rays: blend of two columns vs blended-kernel trace, max abs | "
        f"{b['same_rays_max_abs']:.2e} |",
        "| per-vertex blend vs least squares of blended samples, max abs | "
        f"{b['per_vertex_blend_vs_lsq_of_blend_max_abs']:.2e} |",
        f"| samples (blend) vs 4x-ray blended reference, RMSE | {b['samples_rmse_vs_reference']:.4f} |",
        f"| baked vertices (blend) vs 4x-ray blended reference, RMSE | {b['bake_rmse_vs_reference']:.4f} |",
        "",
    ]
    return "\n".join(lines)


# --------------------------------------------------------------------------- settings file


def load_level_settings(config: str | Path, overrides: list[str] | None = None) -> LevelBakeSettings:
    s = load_settings(LevelBakeSettings, config, overrides)
    check_settings(s)
    return s
