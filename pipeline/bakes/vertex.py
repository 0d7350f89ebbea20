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
Sloan, Tranchida, Chen, Kavan 2013): stratified surface samples spread by area
(:func:`neuralao.pipeline.geometry.surface.surface_samples`), each with the AO traced along its face's
geometric normal; the per-vertex values are the area-weighted least-squares fit with an edge
regulariser (:mod:`neuralao.pipeline.geometry.least_squares`, where the energy and the solver are described).
Samples invalidated by the back-face rule (Sloan et al. 2013: more than 25% of a sample's rays hit
back faces, i.e. it lies inside geometry) are left out of the data term.

Samples: every face gets ``round(density * area)`` samples, at least 1 and at most
``samples_per_face_cap``, with ``density = samples_per_vertex * n_vertices / total_area``.

Output (PLY or GLB): the scene's vertices and faces as loaded (glTF nodes flattened), per-vertex
colour = grey ``round(255 * ao)`` (RGBA8, alpha 255) AND the exact float32 value:

* PLY: a custom vertex property ``property float ao`` (trimesh's PLY exporter writes
  ``vertex_attributes`` as extra vertex properties, and its loader reads them back);
* GLB: glTF 2.0 allows application-specific vertex attributes only with a leading underscore, so
  the float is the attribute ``_AO`` (FLOAT SCALAR accessor), beside ``COLOR_0``.

Error against a reference is measured over surface samples
(:func:`neuralao.pipeline.geometry.surface.surface_error`), never at the vertices (where vertex sampling is
exact by construction).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from neuralao.pipeline.engines.engine import LocalEngine
from neuralao.pipeline.geometry.gltf import check_gltf
from neuralao.pipeline.geometry.least_squares import fill_invalid, fit_least_squares
from neuralao.pipeline.geometry.scene import Scene
from neuralao.pipeline.geometry.surface import SurfaceSamples, surface_samples, vertex_colours
from neuralao.pipeline.tracing.engine_labeller import EngineLabeller
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path
from neuralao.runtime.foundation.limits import MAX_CAP, SAMPLE_BYTES, check_count, check_int_range, check_seed
from neuralao.runtime.foundation.settings import settings_to_dict

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
    # Weight of the edge regulariser (least-squares), in units of least_squares.REG_SCALE.
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
        return LabelSettings.shared_with(self)


@dataclass
class BakeResult:
    """ao (n_vertices,) float32 in [0, 1]; info: counts, timings, settings."""

    ao: np.ndarray
    info: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- baking


def bake_vertex(scene: Scene, labeller: Labeller | EngineLabeller, progress: bool = False) -> BakeResult:
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
    scene: Scene, labeller: Labeller | EngineLabeller, settings: BakeSettings, progress: bool = False
) -> BakeResult:
    """Least-squares vertex baking of stratified surface samples (module doc)."""
    t0 = time.perf_counter()
    total = settings.samples_per_vertex * len(scene.vertices)
    # The samples' arrays are allocated before anything else: their number must fit
    # (neuralao.runtime.foundation.limits).
    check_count(
        "--samples-per-vertex",
        math.ceil(min(total, 2.0**62)) + len(scene.faces),
        bytes_each=SAMPLE_BYTES,
        each="per surface sample",
        shown=f"{settings.samples_per_vertex:g} on {len(scene.vertices)} vertices",
    )
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

    The samples are traced as chunk tasks on ``engine`` (:mod:`neuralao.pipeline.engines.engine`; None: a
    LocalEngine, ``settings.workers`` threads in this process; a RayEngine: its cluster), with the same
    bits wherever they run; ``store`` keeps finished chunks for a rerun.
    """
    settings = settings or BakeSettings()
    check_settings(settings)
    t0 = time.perf_counter()
    labeller = EngineLabeller(scene, settings.label_settings(), engine or LocalEngine(), store)
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


# --------------------------------------------------------------------------- files


def write_baked_mesh(path: str | Path, scene: Scene, ao: np.ndarray) -> Path:
    """Write ``scene`` with per-vertex AO (colours + float32 property, module doc) to .ply or .glb,
    atomically."""
    import trimesh  # measured: ~1 s to import; only the file readers and writers need it

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
    """Read a baked .ply/.glb: vertices (n, 3) f64, faces (m, 3) i64, ao (n,) float32,
    colours (n, 4) uint8."""
    import trimesh  # measured: ~1 s to import; only the file readers and writers need it

    path = Path(path)
    if path.is_file() and path.stat().st_size == 0:
        raise NeuralaoError(f"{path} is empty: it has no geometry")
    if path.suffix.lower() in (".gltf", ".glb") and path.is_file() and path.stat().st_size:
        check_gltf(path)  # the specification's rules before trimesh reads it
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
