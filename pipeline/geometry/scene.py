"""Scenes: load OBJ / PLY / glTF / GLB meshes with trimesh into one flat triangle soup.

A :class:`Scene` is deliberately plain: float64 vertices, int64 faces, all glTF nodes flattened
with their transforms applied. Nothing is merged or re-wound, so triangle soup, back faces and
interpenetrating parts reach the renderer and the labeller exactly as authored.
"""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from neuralao.pipeline.geometry.gltf import check_gltf, outside_folder_message
from neuralao.runtime.foundation.errors import NeuralaoError

log = logging.getLogger(__name__)

SUPPORTED_SUFFIXES = (".obj", ".ply", ".gltf", ".glb", ".stl", ".off")
# Where scene names in configs are looked up (``spot`` -> <root>/spot.obj, ``BrainStem`` -> glTF dir).
DEFAULT_MESH_ROOT = Path(__file__).resolve().parents[3] / "shared" / "assets" / "meshes"


def mesh_root() -> Path:
    return Path(os.environ.get("NEURALAO_MESHES", DEFAULT_MESH_ROOT))


def corner_cross(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3) float64 (v1 - v0) x (v2 - v0) of ``faces`` (m, 3) into ``vertices`` (n, 3): ``np.cross``'s
    products and differences, bit for bit, on one coordinate column at a time (1.5x faster on the 8.7M
    faces of a big terrain: no (m, 3) temporaries gathered by rows)."""
    f = np.ascontiguousarray(np.asarray(faces).T)
    d1, d2 = [], []
    for k in range(3):
        x = np.ascontiguousarray(vertices[:, k])
        x0 = x[f[0]]
        d1.append(x[f[1]] - x0)
        d2.append(x[f[2]] - x0)
    out = np.empty((f.shape[1], 3))
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        np.subtract(d1[i] * d2[j], d1[j] * d2[i], out=out[:, k])
    return out


@dataclass
class Scene:
    """A flattened triangle mesh.

    vertices : (n, 3) float64, scene units
    faces    : (m, 3) int64 indices into ``vertices``; face i is triangle id i everywhere
    name     : short name used in datasets and reports
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = "scene"
    source: str = ""
    dropped_faces: int = field(default=0)

    @cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: min and max corner."""
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    @cached_property
    def diagonal(self) -> float:
        """Length of the bounding-box diagonal: every scale-dependent default is relative to it."""
        return float(np.linalg.norm(self.bounds[1] - self.bounds[0]))

    @cached_property
    def center(self) -> np.ndarray:
        return self.bounds.mean(0)

    @cached_property
    def triangles(self) -> np.ndarray:
        """(m, 3, 3) float64 corner positions."""
        return self.vertices[self.faces]

    def face_cross(self) -> np.ndarray:
        """(m, 3) float64 (v1 - v0) x (v2 - v0) per face: twice the area along the normal. Computed from the
        vertices each time, never from :attr:`triangles`, so a big scene keeps no (m, 3, 3) copy."""
        return corner_cross(self.vertices, self.faces)

    def unit_face_normals(self) -> np.ndarray:
        """(m, 3) float64 unit geometric normals (right-handed winding; NaN for a degenerate face), made
        anew: :attr:`face_normals` is the cached copy, this one is for callers that keep only a cast."""
        n = self.face_cross()
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(m, 3) float64 unit geometric normals (right-handed winding)."""
        return self.unit_face_normals()

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """(n, 3) float64 area-weighted vertex normals; a vertex whose normals cancel gets +z."""
        n = self.face_cross()  # area weighted
        vn = np.zeros_like(self.vertices)
        for k in range(3):
            np.add.at(vn, self.faces[:, k], n)
        length = np.linalg.norm(vn, axis=1, keepdims=True)
        bad = length[:, 0] <= 1e-300
        vn[bad] = (0.0, 0.0, 1.0)
        length[bad] = 1.0
        return vn / length

    def scaled(self, factor: float, offset: np.ndarray | float = 0.0) -> Scene:
        """A copy with vertices * factor + offset (for scale-invariance tests)."""
        return Scene(self.vertices * factor + offset, self.faces.copy(), self.name, self.source)


def slim_scene(scene: Scene) -> Scene:
    """The scene's vertices, faces and name only (no cached triangles / normals): what a worker needs."""
    return Scene(np.asarray(scene.vertices, np.float64), np.asarray(scene.faces, np.int64), scene.name)


def _read_geometries(path: Path) -> list:
    """Every geometry of the file with its node transforms applied (``dump(concatenate=False)`` keeps
    instanced geometry). Reading *and* flattening are guarded: a truncated OBJ whose last vertex
    line lost coordinates parses, then fails inside trimesh's transform code."""
    import trimesh  # measured: ~1 s to import; only the file readers and writers need it

    if path.suffix.lower() in (".gltf", ".glb"):
        check_gltf(path)  # the specification's rules first: trimesh reads some broken files as nonsense
    try:
        # positions a transform takes past float64 come back inf or NaN, refused by scene_from_arrays
        with np.errstate(over="ignore", invalid="ignore"):
            loaded = trimesh.load(str(path), force="scene", process=False)
            return list(loaded.dump(concatenate=False) if hasattr(loaded, "dump") else [loaded])
    except Exception as e:  # trimesh raises many types for corrupt files
        # trimesh's resolver refused a file outside the glTF's folder (its text names its own Python API)
        escaped = _ESCAPED.match(str(e))
        if escaped:
            raise NeuralaoError(outside_folder_message(path, escaped.group(1))) from None
        first = str(e).splitlines()[0][:200] if str(e) else ""
        raise NeuralaoError(f"cannot read mesh {path}: {type(e).__name__}: {first}") from None


# trimesh's FilePathResolver: "'NAME' escapes resolver root 'ROOT' ..."
_ESCAPED = re.compile(r"^'(.*)' escapes resolver root ")


def load_scene(path: str | os.PathLike, name: str | None = None, drop_degenerate: bool = True) -> Scene:
    """Load a mesh file (or a glTF folder) into a :class:`Scene`.

    Raises :class:`NeuralaoError` for a missing, unreadable or empty file, NaN/inf vertices or no
    faces. Degenerate faces (zero area or repeated indices) are dropped with a warning.
    """
    path = resolve_mesh_path(path)
    verts, faces, offset = [], [], 0
    for g in _read_geometries(path):
        if not hasattr(g, "faces") or g.faces is None or len(g.faces) == 0:
            continue
        v = np.asarray(g.vertices, dtype=np.float64)
        f = np.asarray(g.faces, dtype=np.int64)
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    if not faces:
        raise NeuralaoError(f"mesh {path} has no faces")
    vertices = np.concatenate(verts)
    faces_arr = np.concatenate(faces)
    return scene_from_arrays(vertices, faces_arr, name or path.stem, str(path), drop_degenerate)


# Largest |coordinate| of a mesh: the G-buffer's float32 transforms render meshes up to 1e30 across at
# any offset within it and draw nothing at 1e38; ray distances in scene units are float32 too (measured).
MAX_COORDINATE = 1e30
# Smallest extent (bounding-box diagonal) of a mesh: float32 positions below about 1e-38 are subnormal and
# lose their digits (a mesh 1e-44 across comes out of a bake with a quarter of its faces collapsed), so the
# scale a mesh may have is bounded below as it is above.
MIN_EXTENT = 1e-30


def scene_from_arrays(
    vertices: np.ndarray,
    faces: np.ndarray,
    name: str = "scene",
    source: str = "",
    drop_degenerate: bool = True,
) -> Scene:
    """Validate arrays and build a :class:`Scene` (same checks as :func:`load_scene`)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    what = source or name
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        raise NeuralaoError(f"mesh {what} has no vertices")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise NeuralaoError(f"mesh {what} has no faces")
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices)).any(axis=1).sum())
        raise NeuralaoError(f"mesh {what} has {bad} vertices with NaN or inf coordinates")
    reach = float(np.abs(vertices).max())
    if reach > MAX_COORDINATE:
        raise NeuralaoError(
            f"mesh {what} has coordinates up to {reach:.3g}: meshes must lie within +-{MAX_COORDINATE:g} "
            "(float32 G-buffers and ray distances overflow past it); rescale the mesh"
        )
    extent = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    if 0 < extent < MIN_EXTENT:
        raise NeuralaoError(
            f"mesh {what} spans {extent:.3g}: meshes must span at least {MIN_EXTENT:g} (float32 positions "
            "lose their digits below it); rescale the mesh"
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise NeuralaoError(f"mesh {what} has face indices outside [0, {len(vertices)})")
    dropped = 0
    if drop_degenerate:
        t = vertices[faces]
        cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        # Relative to the scene scale so the rule is scale invariant; 1e-12 of diag^2 is far
        # below any visible triangle but catches collapsed ones and repeated indices.
        diag = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
        keep = (area2 > 1e-12 * diag * diag) & np.isfinite(area2)
        dropped = int((~keep).sum())
        if dropped:
            log.warning("%s: dropped %d degenerate face(s) of %d", what, dropped, len(faces))
            faces = faces[keep]
        if len(faces) == 0:
            raise NeuralaoError(f"mesh {what} has only degenerate faces")
    return Scene(vertices, faces, name, source, dropped)


def resolve_mesh_path(path: str | os.PathLike) -> Path:
    """A file path, a glTF folder (its single .gltf/.glb) or a bare name under :func:`mesh_root`."""
    p = Path(path)
    if not p.exists() and not p.is_absolute():
        for cand in (mesh_root() / p, *(mesh_root() / (str(p) + s) for s in SUPPORTED_SUFFIXES)):
            if cand.exists():
                p = cand
                break
    if p.is_dir():
        found = sorted([*p.rglob("*.gltf"), *p.rglob("*.glb")])
        if not found:
            raise NeuralaoError(f"folder {p} holds no .gltf or .glb file")
        p = found[0]
    if not p.exists():
        raise NeuralaoError(f"mesh file not found: {path}")
    if p.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise NeuralaoError(
            f"unsupported mesh format {p.suffix!r} for {p} (use one of {', '.join(SUPPORTED_SUFFIXES)})"
        )
    if p.stat().st_size == 0:
        raise NeuralaoError(f"mesh file {p} is empty")
    return p
