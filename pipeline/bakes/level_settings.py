"""Settings of a level bake (``neuralao bake LEVEL --config CONFIG``): what each stage does, checked
before anything runs, and the blend of the two obscurance distances."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from neuralao.pipeline.tracing.labeller import LabelSettings, check_rays
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import (
    MAX_CAP,
    RAY_BYTES,
    SAMPLE_BYTES,
    THREAD_BYTES,
    check_count,
    check_int_range,
    check_seed,
)
from neuralao.runtime.foundation.settings import load_settings


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
    # Embree's scene for the level's rays: "fast" (its high-quality BVH without the robust flag: 1.4x the
    # rays per second, a build 2-3x longer) or "robust" (watertight, the labels' own; its quicker build pays
    # where every single-CPU actor of a large farm builds its own and traces little). The two find the same
    # hits but for about one ray in ten million grazing an edge.
    bvh: Literal["fast", "robust"] = "fast"
    # Samples per resumable trace block (one npz under OUT/stages/trace/ each), a task each: 16.8M rays at
    # 256 rays a sample, a few seconds on one core, so the last blocks of a stage keep every core busy.
    block_samples: int = 65536
    # Sparse solver of the least-squares systems: "components" (exact: the system is block diagonal over
    # connected components; each block a task, SuperLU below component_vertices and multigrid CG above);
    # or one solve of the whole system: "direct" (SuperLU), "cg" (Jacobi CG), "amg" (multigrid CG).
    solver: Literal["components", "direct", "cg", "amg"] = "components"
    # "components": blocks of at least this many vertices use multigrid CG (SuperLU's fill-in grows
    # faster than linearly on a terrain grid), and smaller components are packed into tasks of this size.
    component_vertices: int = 100_000
    # "components": a block of at least component_vertices is cut into this many spatial subdomains, solved
    # as separate tasks (two waves an iteration) by Schwarz-preconditioned CG, each subdomain's factor and
    # vectors kept by its worker (neuralao.pipeline.geometry.partitioned_solve; 3e-7 from SuperLU on Table
    # 1's terrain). 1: the block is one multigrid-CG task. The Ray engine gives each actor two subdomains in
    # turn (its two task slots), so 2 x its actors uses them all.
    subdomains: int = 1


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
    # Fraction of faces the simplifier removes (the paper's LOD: 1.8M -> 0.8M faces, 0.55), in one
    # simplification of the whole level (one task: what a cluster cannot split).
    target_reduction: float = 0.55
    # Instead, each piece simplified on its own (a task each) down to this shared quadric error, scene
    # units squared (the sum of squared distances from a collapsed vertex to the planes it replaces;
    # coincident vertices welded first, so houses keep their boxes). None: the one global pass above.
    max_error: float | None = None
    # With max_error: a piece of more faces than this is simplified in spatial tiles of about this many
    # (a task each; the cuts between tiles are kept, as borders are), so no piece is one long task.
    tile_faces: int = 262144
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
    # Tasks a local bake runs at once, on threads, each tracing on one (on Ray: an actor's --ray-threads):
    # scheduling only, never the result (a rerun with another value reuses every stage).
    workers: int = 2
    # Rays per resampling task (grass, shrubs, the LOD) and tracing thread of the engine's workers:
    # scheduling only, never the result (a rerun with another value reuses every stage).
    task_rays: int = 1 << 20
    # Faces per piece: the static instances are cut into runs of whole instances of about this many
    # faces (a bigger instance is a piece of its own); the solve, the LOD and the output are one task
    # per piece, and the driver holds one piece at a time.
    piece_faces: int = 262144
    # File name of the baked level inside --out (.glb or .gltf; written by every run, in no stage's key).
    output: str = "level_baked.glb"
    # Make the error tables (the LOD's at held-out points, the two-distance blend's against a 4x-ray
    # reference): checks of the bake that write nothing into the baked level. A production bake on a farm
    # can leave them out (false); a rerun with them reuses every stage already made.
    error_tables: bool = True


def check_settings(s: LevelBakeSettings) -> None:
    t = s.trace
    for name, v in (
        ("trace.rays", t.rays),
        ("trace.block_samples", t.block_samples),
        ("workers", s.workers),
        ("task_rays", s.task_rays),
        ("piece_faces", s.piece_faces),
        ("trace.component_vertices", t.component_vertices),
        ("trace.subdomains", t.subdomains),
        ("grass.rays", s.grass.rays),
        ("lod.rays", s.lod.rays),
        ("lod.tile_faces", s.lod.tile_faces),
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
    _check_ranges(s)


def _check_ranges(s: LevelBakeSettings) -> None:
    """What the checks above leave: the seed, the remaining weights and fractions, and every count a
    stage allocates per unit of, against the memory (each refusal names the setting and its bound)."""
    t = s.trace
    check_seed("seed", s.seed)
    check_count("workers", s.workers, bytes_each=THREAD_BYTES, each="per tracing thread")
    for name, rays in (
        ("trace.rays", t.rays),
        ("grass.rays", s.grass.rays),
        ("lod.rays", s.lod.rays),
        ("decorators.local_rays", s.decorators.local_rays),
    ):
        check_rays(name, rays, s.workers)
    for name, count in (
        ("trace.block_samples", t.block_samples),
        ("decorators.samples_per_instance", s.decorators.samples_per_instance),
        ("decorators.holdout_samples", s.decorators.holdout_samples),
        ("lod.holdout_samples", s.lod.holdout_samples),
    ):
        check_count(name, count, bytes_each=SAMPLE_BYTES, each="per surface sample")
    check_count("foliage.max_hits", s.foliage.max_hits, bytes_each=RAY_BYTES, each="per crossing of a ray")
    check_int_range("trace.samples_per_face_cap", t.samples_per_face_cap, 1, MAX_CAP)
    if not t.alpha >= 0:
        raise NeuralaoError(f"trace.alpha must be >= 0, got {t.alpha}")
    if not s.decorators.local_samples_per_vertex > 0:
        raise NeuralaoError(
            f"decorators.local_samples_per_vertex must be > 0, got {s.decorators.local_samples_per_vertex}"
        )
    if t.backface_threshold is not None and not 0 <= t.backface_threshold <= 1:
        raise NeuralaoError(f"trace.backface_threshold must be in [0, 1] or null, got {t.backface_threshold}")
    if s.lod.max_error is not None and not (math.isfinite(s.lod.max_error) and s.lod.max_error > 0):
        raise NeuralaoError(f"lod.max_error must be a positive number (or null), got {s.lod.max_error}")
    if s.lod.radius is not None and not s.lod.radius > 0:
        raise NeuralaoError(f"lod.radius must be > 0 (or null), got {s.lod.radius}")


def blend(short: np.ndarray, long: np.ndarray, s: BlendSettings) -> np.ndarray:
    """Per-level blend (long_weight * long + (1 - long_weight) * short) and the optional remap curve."""
    b = s.long_weight * np.asarray(long, np.float64) + (1.0 - s.long_weight) * np.asarray(short, np.float64)
    if s.remap is not None:
        curve = np.asarray(s.remap, np.float64)
        b = np.interp(b, curve[:, 0], curve[:, 1])
    return np.clip(b, 0.0, 1.0).astype(np.float32)


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


def load_level_settings(config: str | Path, overrides: list[str] | None = None) -> LevelBakeSettings:
    s = load_settings(LevelBakeSettings, config, overrides)
    check_settings(s)
    return s
