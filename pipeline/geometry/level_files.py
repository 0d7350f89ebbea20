"""Game levels as glTF 2.0: reading, validation and a small deterministic glTF writer.

A level is a glTF scene whose nodes reference shared meshes, instanced through the node hierarchy
and through ``EXT_mesh_gpu_instancing`` (per-instance TRANSLATION / ROTATION / SCALE accessors,
composed after the node's world matrix, as the extension specifies). Each node carries its role in
``extras`` (inherited by its children unless they set their own):

==========  ==================================================================================
role        meaning in the bake (Sloan et al. 2013)
==========  ==================================================================================
static      terrain and buildings: opaque, baked per vertex (least squares), written with AO
blocker     opaque occluder that receives no AO and is not written (collision, distant skyline)
tree        large decorator: semi-transparent to other surfaces (``transmission`` per hit,
            default 0.5); its own AO is local AO per model x a per-instance linear global fit
shrub       small decorator: a box of participating media (``density`` per scene unit, default
            1.0) in the foliage BVH; gets one AO scalar per instance, resampled from the terrain
grass       small decorator: not an occluder; one AO scalar per clump resampled from the terrain
==========  ==================================================================================

Everything the reader rejects is a one-line :class:`NeuralaoError` naming the node, mesh or
accessor: a missing or truncated buffer, a mesh index outside the file, a non-triangle primitive,
unknown roles or parameters in ``extras``, a non-finite or zero-scale (singular) transform, an instance
reaching past ``MAX_COORDINATE``, or one too small next to the level for float64 coordinates to resolve.
"""

from __future__ import annotations

import json
import os
import shutil
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from neuralao.pipeline.geometry.gltf import (
    BIN_CHUNK,
    COMPONENT,
    GLB_MAGIC,
    INSTANCING,
    JSON_CHUNK,
    GltfFile,
    gltf_label,
    json_number,
    trs_matrices,
)
from neuralao.pipeline.geometry.scene import MAX_COORDINATE
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path

ROLES = ("static", "blocker", "tree", "shrub", "grass")
# Parameters each role accepts in extras, with their defaults (Sloan et al.: trees attenuate 50%).
ROLE_PARAMS: dict[str, dict[str, float]] = {
    "static": {},
    "blocker": {},
    "tree": {"transmission": 0.5},
    "shrub": {"density": 1.0},
    "grass": {},
}
# Keys of a node's extras the reader understands (anything else there is an error: a typo such as
# "densty" would otherwise silently bake with the default).
_EXTRAS_KEYS = {"role", "transmission", "density", "name"}
# An instance whose |det| of the 3x3 part is below this fraction of (its largest axis scale)^3 is
# singular (a zero scale on some axis): its normals and its box would be undefined.
_SINGULAR_REL = 1e-9
# The smallest an instance may span next to the level's reach (its largest |world coordinate|): at 2^-36 a
# float64 coordinate still has 2^16 steps across the instance; far below it (a 1 m shrub beside a terrain
# scaled to 1e21 m) its triangles collapse in the bake's float64 arithmetic and their normals are 0 / 0.
MIN_INSTANCE_REL = 2.0**-36


@dataclass
class LevelMesh:
    """One shared mesh: vertices (n, 3) float64 object space, faces (m, 3) int64."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray


@dataclass
class LevelNode:
    """A node with a mesh: its role, parameters and world matrices (one per instance).

    transforms : (k, 4, 4) float64 object -> world (k = 1 without EXT_mesh_gpu_instancing)
    """

    index: int
    name: str
    role: str
    mesh: int
    transforms: np.ndarray
    params: dict[str, float] = field(default_factory=dict)

    def __reduce__(self):
        # Its matrices go in the pickle's own bytes: Ray's object store takes every numpy array out of band,
        # a buffer each, and a level's tens of thousands of nodes made the 10x world's put 1.0 s (0.66 s so).
        t = np.ascontiguousarray(self.transforms)
        matrices = (t.tobytes(), t.dtype.str, t.shape)
        return _node, (self.index, self.name, self.role, self.mesh, *matrices, self.params)


def _node(index: int, name: str, role: str, mesh: int, data: bytes, dtype: str, shape, params) -> LevelNode:
    """A :class:`LevelNode` from its pickle (:meth:`LevelNode.__reduce__`)."""
    transforms = np.frombuffer(data, dtype).reshape(shape).copy()
    return LevelNode(index, name, role, mesh, transforms, params)


@dataclass
class Level:
    meshes: list[LevelMesh]
    nodes: list[LevelNode]
    source: str = ""
    extras: dict[str, Any] = field(default_factory=dict)

    def nodes_with(self, *roles: str) -> list[LevelNode]:
        return [n for n in self.nodes if n.role in roles]

    def counts(self) -> dict[str, int]:
        """Instances and flattened vertices / faces per role."""
        out: dict[str, int] = {}
        for n in self.nodes:
            m, k = self.meshes[n.mesh], len(n.transforms)
            for key, v in (("instances", k), ("vertices", k * len(m.vertices)), ("faces", k * len(m.faces))):
                out[f"{n.role}_{key}"] = out.get(f"{n.role}_{key}", 0) + v
        return out


# --------------------------------------------------------------------------- transforms


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """Rotation matrices (k, 3, 3) -> unit quaternions (k, 4) [x, y, z, w] with w >= 0 (Shepperd)."""
    r = np.asarray(r, np.float64).reshape(-1, 3, 3)
    tr = np.trace(r, axis1=1, axis2=2)
    cand = np.stack(
        [
            np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1], 1 + tr], -1),
            np.stack(
                [
                    1 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2],
                    r[:, 0, 1] + r[:, 1, 0],
                    r[:, 0, 2] + r[:, 2, 0],
                    r[:, 2, 1] - r[:, 1, 2],
                ],
                -1,
            ),
            np.stack(
                [
                    r[:, 0, 1] + r[:, 1, 0],
                    1 + r[:, 1, 1] - r[:, 0, 0] - r[:, 2, 2],
                    r[:, 1, 2] + r[:, 2, 1],
                    r[:, 0, 2] - r[:, 2, 0],
                ],
                -1,
            ),
            np.stack(
                [
                    r[:, 0, 2] + r[:, 2, 0],
                    r[:, 1, 2] + r[:, 2, 1],
                    1 + r[:, 2, 2] - r[:, 0, 0] - r[:, 1, 1],
                    r[:, 1, 0] - r[:, 0, 1],
                ],
                -1,
            ),
        ],
        axis=1,
    )
    diag = np.stack([tr, r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], -1)
    q = cand[np.arange(len(r)), np.argmax(diag, axis=1)]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, 3:] < 0, -q, q)


def decompose(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k, 4, 4) TRS matrices -> translations (k, 3), quaternions (k, 4), scales (k, 3) float64.

    Exact for T @ R @ S with positive scales (what the reader and the generator produce); a matrix
    with shear or a reflection is a :class:`NeuralaoError` (EXT_mesh_gpu_instancing cannot hold it).
    """
    m = np.asarray(m, np.float64).reshape(-1, 4, 4)
    a = m[:, :3, :3]
    s = np.linalg.norm(a, axis=1)
    rot = a / s[:, None, :]
    if (
        not np.allclose(np.einsum("kji,kjl->kil", rot, rot), np.eye(3), atol=1e-6)
        or (np.linalg.det(rot) < 0).any()
    ):
        raise NeuralaoError("an instance transform has shear or a reflection; it cannot be written as TRS")
    return m[:, :3, 3].copy(), matrix_to_quat(rot), s


def node_matrix(node: dict, where: str) -> np.ndarray:
    """The local 4x4 of a glTF node (``matrix`` column-major, or TRS): finite JSON numbers (the glTF
    reader's rules, :class:`GltfFile`), each within +-``MAX_COORDINATE`` (no coordinate lies past it, so no
    factor of one may)."""
    counts = {"matrix": 16, "translation": 3, "rotation": 4, "scale": 3}
    values = {}
    for key in counts:
        if key not in node:
            continue
        raw = node[key]
        numbers = [json_number(v) for v in raw] if isinstance(raw, list) else []
        if len(numbers) != counts[key] or any(v is None for v in numbers):
            raise NeuralaoError(f"{where}: {key} must be a list of {counts[key]} finite numbers")
        if any(abs(v) > MAX_COORDINATE for v in numbers):
            raise NeuralaoError(
                f"{where}: {key} holds {max(numbers, key=abs):g}; a node's transform numbers lie within "
                f"+-{MAX_COORDINATE:g}, as every coordinate of a level does (float32 G-buffers and ray "
                "distances overflow past it)"
            )
        values[key] = numbers
    if "matrix" in values:
        return np.asarray(values["matrix"], np.float64).reshape(4, 4).T
    try:
        return trs_matrices(values.get("translation"), values.get("rotation"), values.get("scale"))[0]
    except NeuralaoError as e:
        raise NeuralaoError(f"{where}: {e}") from None


def check_finite_transforms(m: np.ndarray, where: str) -> None:
    """Finite 4x4 matrices (k, 4, 4)."""
    if not np.isfinite(m).all():
        bad = int(np.flatnonzero(~np.isfinite(m).reshape(len(m), -1).all(axis=1))[0])
        raise NeuralaoError(f"{where}: instance {bad} has a non-finite transform")


def singular_transforms(m: np.ndarray) -> np.ndarray:
    """(k,) bool: which of the finite matrices ``m`` (k, 4, 4) are singular (a zero scale on some axis)."""
    a = m[:, :3, :3]
    # The rule is scale-free: judged on each matrix over its largest entry, so no product overflows.
    top = np.abs(a).max(axis=(1, 2))
    a = a / np.where(top > 0, top, 1.0)[:, None, None]
    det = np.abs(np.linalg.det(a))
    big = np.linalg.norm(a, axis=1).max(axis=1)
    return ~(det > _SINGULAR_REL * big**3) | (big == 0)


def check_transforms(m: np.ndarray, where: str) -> None:
    """Finite and non-singular (no zero-scale axis) 4x4 matrices (k, 4, 4)."""
    check_finite_transforms(m, where)
    singular = singular_transforms(m)
    if singular.any():
        raise NeuralaoError(
            f"{where}: instance {int(np.flatnonzero(singular)[0])} has a zero scale (singular transform)"
        )


def instance_reach(m: np.ndarray, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The largest |world coordinate| (k,) and the world extent (k,) (bounding-box diagonal, an upper bound)
    of a mesh of ``vertices`` (n, 3) under each of ``m`` (k, 4, 4), without transforming its vertices;
    inf where a product passes float64."""
    a = np.abs(m[:, :3, :3])
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        reach = (a @ np.maximum(np.abs(lo), np.abs(hi)) + np.abs(m[:, :3, 3])).max(axis=1)
        extent = np.sqrt(((a @ (hi - lo)) ** 2).sum(axis=1))
    return np.nan_to_num(reach, nan=np.inf), np.nan_to_num(extent, nan=np.inf)


def check_reach(reach: np.ndarray, where: str) -> None:
    """Every instance of a node within +-``MAX_COORDINATE`` (``reach`` from :func:`instance_reach`)."""
    far = np.flatnonzero(~(reach <= MAX_COORDINATE))
    if len(far):
        raise NeuralaoError(
            f"{where}: instance {int(far[0])} reaches {reach[far[0]]:.3g}; a level's coordinates lie within "
            f"+-{MAX_COORDINATE:g} (float32 G-buffers and ray distances overflow past it): scale it down"
        )


def check_resolution(placed: list[tuple[str, str, np.ndarray, np.ndarray]]) -> None:
    """Every instance spans at least ``MIN_INSTANCE_REL`` of the level's reach; ``placed`` holds each node's
    message prefix and label, its instances' reaches and extents (:func:`instance_reach`)."""
    if not placed:
        return
    _, widest, reaches, _ = max(placed, key=lambda p: p[2].max())
    reach = float(reaches.max())
    for where, _, _, extent in placed:
        small = np.flatnonzero(extent < MIN_INSTANCE_REL * reach)
        if len(small):
            raise NeuralaoError(
                f"{where}: instance {int(small[0])} spans {extent[small[0]]:.3g}, less than 2^-36 of the "
                f"level's reach {reach:.3g} (at {widest}): float64 coordinates cannot resolve it next to the "
                "rest; scale the level's nodes alike"
            )


# --------------------------------------------------------------------------- reading


def _role_and_params(node: dict, inherited: tuple[str, dict] | None, where: str) -> tuple[str, dict]:
    extras = node.get("extras", {})
    if not isinstance(extras, dict):
        raise NeuralaoError(f"{where}: extras must be a JSON object, got {type(extras).__name__}")
    unknown = sorted(set(extras) - _EXTRAS_KEYS)
    if unknown:
        raise NeuralaoError(
            f"{where}: unknown key(s) in extras: {', '.join(unknown)} "
            f"(known: {', '.join(sorted(_EXTRAS_KEYS))})"
        )
    if "role" not in extras:
        role, params = inherited if inherited else ("static", {})
        if set(extras) & {"transmission", "density"}:
            raise NeuralaoError(f"{where}: extras set parameters but no role")
        return role, params
    role = extras["role"]
    if role not in ROLES:
        raise NeuralaoError(f"{where}: unknown role {role!r} in extras (one of {', '.join(ROLES)})")
    params = dict(ROLE_PARAMS[role])
    for key in ("transmission", "density"):
        if key not in extras:
            continue
        if key not in params:
            raise NeuralaoError(f"{where}: role {role!r} takes no {key!r}")
        v = json_number(extras[key])
        if v is None:
            shown = repr(extras[key])
            shown = shown if len(shown) <= 40 else f"{shown[:24]}... ({len(shown)} characters)"
            raise NeuralaoError(f"{where}: {key} must be a finite number float64 holds, got {shown}")
        if key == "transmission" and not 0.0 <= v <= 1.0:
            raise NeuralaoError(f"{where}: transmission must be in [0, 1], got {v}")
        if key == "density" and v < 0:
            raise NeuralaoError(f"{where}: density must be >= 0, got {v}")
        params[key] = v
    return role, params


def _instances(g: GltfFile, node: dict, where: str) -> np.ndarray | None:
    ext = node.get("extensions", {}).get(INSTANCING)
    if ext is None:
        return None
    attrs = ext.get("attributes", {}) if isinstance(ext, dict) else None
    known = {"TRANSLATION", "ROTATION", "SCALE"}
    if not isinstance(attrs, dict) or not (set(attrs) & known):
        raise NeuralaoError(f"{where}: {INSTANCING} has no TRANSLATION, ROTATION or SCALE attribute")
    arrays = {k: g.accessor(attrs[k], f"{where} {INSTANCING}.{k}") for k in known if k in attrs}
    counts = {len(v) for v in arrays.values()}
    if len(counts) != 1:
        raise NeuralaoError(f"{where}: {INSTANCING} attributes have different counts {sorted(counts)}")
    count = counts.pop()
    if count == 0:  # a node of no instances: nothing to place, bake or fit (each step needs one)
        raise NeuralaoError(
            f"{where}: {INSTANCING} has 0 instances; give the node instances or remove it from the level"
        )
    for k, w in (("TRANSLATION", 3), ("ROTATION", 4), ("SCALE", 3)):
        if k in arrays and arrays[k].shape != (count, w):
            raise NeuralaoError(f"{where}: {INSTANCING}.{k} must be VEC{w}")
    try:
        return trs_matrices(arrays.get("TRANSLATION"), arrays.get("ROTATION"), arrays.get("SCALE"), count)
    except NeuralaoError as e:
        raise NeuralaoError(f"{where}: {INSTANCING}: {e}") from None


def _mesh(g: GltfFile, index: int, where: str) -> LevelMesh:
    spec = g.doc["meshes"][index]
    name = str(spec.get("name", f"mesh{index}"))
    verts, faces, offset = [], [], 0
    for p, prim in enumerate(spec.get("primitives", [])):
        w = f"{where} {gltf_label('mesh', index, spec)} primitive {p}"
        mode = prim.get("mode", 4)
        if mode != 4:
            raise NeuralaoError(f"{w}: mode {mode} is not supported (triangles only, mode 4)")
        if "POSITION" not in prim.get("attributes", {}):
            raise NeuralaoError(f"{w}: no POSITION attribute")
        v = g.accessor(prim["attributes"]["POSITION"], w).astype(np.float64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise NeuralaoError(f"{w}: POSITION must be VEC3")
        f = g.accessor(prim["indices"], w).astype(np.int64) if "indices" in prim else np.arange(len(v))
        if f.ndim != 1 or len(f) % 3:
            raise NeuralaoError(f"{w}: index count {len(f)} is not a multiple of 3")
        if len(f) and (f.min() < 0 or f.max() >= len(v)):
            raise NeuralaoError(f"{w}: indices outside [0, {len(v)})")
        if not np.isfinite(v).all():
            raise NeuralaoError(f"{w}: POSITION has NaN or inf")
        verts.append(v)
        faces.append(f.reshape(-1, 3) + offset)
        offset += len(v)
    if not faces or offset == 0 or sum(len(f) for f in faces) == 0:
        raise NeuralaoError(f"{where}: mesh {name!r} has no triangles")
    return LevelMesh(name, np.concatenate(verts), np.concatenate(faces))


def read_level(path: str | Path) -> Level:
    """Read and validate a level (.gltf or .glb). Nodes with meshes become :class:`LevelNode` entries
    in depth-first order of the default scene (or of all root nodes when no scene is given)."""
    path = Path(path)
    if path.suffix.lower() not in (".gltf", ".glb"):
        raise NeuralaoError(f"a level must be a .gltf or .glb file, got {path.name!r}")
    if not path.is_file():
        raise NeuralaoError(f"level file not found: {path}")
    g = GltfFile(path)
    doc = g.doc
    nodes = doc.get("nodes", [])
    n_meshes = len(doc.get("meshes", []))
    scenes = doc.get("scenes", [])
    if scenes:
        si = doc.get("scene", 0)
        if isinstance(si, bool) or not isinstance(si, int) or not 0 <= si < len(scenes):
            raise NeuralaoError(f"level {path}: scene {si!r} is not in the file")
        roots = scenes[si].get("nodes", [])
    else:
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    meshes: dict[int, LevelMesh] = {}
    out: list[LevelNode] = []
    placed: list[tuple[str, str, np.ndarray, np.ndarray]] = []  # per node: where, label, reaches, extents
    seen: set[int] = set()
    stack = [(r, np.eye(4), None) for r in reversed(roots)]
    while stack:
        i, parent, inherited = stack.pop()
        if not isinstance(i, int) or not 0 <= i < len(nodes):
            raise NeuralaoError(f"level {path}: node {i!r} is not in the file ({len(nodes)} nodes)")
        if i in seen:
            raise NeuralaoError(f"level {path}: node {i} is reached twice (a cycle or a shared child)")
        seen.add(i)
        node = nodes[i]
        name = str(node.get("name", f"node{i}"))
        where = f"level {path.name} {gltf_label('node', i, node)}"
        with np.errstate(over="ignore", invalid="ignore"):  # past float64: refused by check_reach
            world = parent @ node_matrix(node, where)
        role, params = _role_and_params(node, inherited, where)
        if "mesh" in node:
            mi = node["mesh"]
            if not isinstance(mi, int) or not 0 <= mi < n_meshes:
                raise NeuralaoError(f"{where}: references mesh {mi!r}, the file has {n_meshes}")
            if mi not in meshes:
                meshes[mi] = _mesh(g, mi, where)
            inst = _instances(g, node, where)
            with np.errstate(over="ignore", invalid="ignore"):
                transforms = world[None] if inst is None else world[None] @ inst
            reach, extent = instance_reach(transforms, meshes[mi].vertices)
            if np.isfinite(transforms).all():  # a NaN or inf is named as such by check_transforms
                check_reach(reach, where)
            check_transforms(transforms, where)
            placed.append((where, gltf_label("node", i, node), reach, extent))
            out.append(LevelNode(i, name, role, mi, transforms, params))
        elif node.get("extensions", {}).get(INSTANCING) is not None:
            raise NeuralaoError(f"{where}: {INSTANCING} on a node without a mesh")
        for c in reversed(node.get("children", [])):
            stack.append((c, world, (role, params)))
    if not out:
        raise NeuralaoError(f"level {path} has no node with a mesh")
    check_resolution(placed)
    # Re-index meshes densely in first-use order.
    order = {mi: k for k, mi in enumerate(dict.fromkeys(n.mesh for n in out))}
    for n in out:
        n.mesh = order[n.mesh]
    level_meshes = [meshes[mi] for mi in order]
    if not any(n.role == "static" for n in out):
        raise NeuralaoError(f"level {path} has no static node (nothing to bake)")
    extras = doc.get("extras", {}) if isinstance(doc.get("extras", {}), dict) else {}
    return Level(level_meshes, out, str(path), extras)


def transform_points(points: np.ndarray, m: np.ndarray) -> np.ndarray:
    """(n, 3) float64 ``points`` (n, 3) under the affine transforms ``m`` (4, 4), or (k, n, 3) under a
    stack (k, 4, 4). Row by row in plain multiplies and adds (x m00 + y m01 + z m02 + m03, in that order),
    not a matrix product: a BLAS picks its kernel by the matrix's shape and the CPU, so a point's bits
    could depend on how many points came with it; these do not (a task that transforms some of an
    instance's vertices gets those of the whole instance)."""
    p = np.asarray(points, np.float64)
    m = np.asarray(m, np.float64)
    if m.ndim == 3:  # a stack: (k, 1) coefficients against the (n,) columns
        m = m[:, None]
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    return np.stack(
        [x * m[..., r, 0] + y * m[..., r, 1] + z * m[..., r, 2] + m[..., r, 3] for r in range(3)], axis=-1
    )


def flatten(
    level: Level, nodes: list[LevelNode]
) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, int, int]]]:
    """World-space vertices (n, 3) float64, faces (m, 3) int64 of every instance of ``nodes``, and
    per instance (node index in ``level.nodes`` order of ``nodes``, instance, first vertex, first face)."""
    verts, faces, spans = [], [], []
    nv = nf = 0
    for k, node in enumerate(nodes):
        mesh = level.meshes[node.mesh]
        for j, m in enumerate(node.transforms):
            verts.append(transform_points(mesh.vertices, m))
            faces.append(mesh.faces + nv)
            spans.append((k, j, nv, nf))
            nv += len(mesh.vertices)
            nf += len(mesh.faces)
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), []
    return np.concatenate(verts), np.concatenate(faces), spans


# --------------------------------------------------------------------------- writing


class _SpillBuffer:
    """The binary buffer of a :class:`GltfWriter` kept in a file instead of memory (``append`` / ``extend``
    and ``len`` like the bytearray it stands for)."""

    def __init__(self, path: Path):
        self.path = path
        self._file = open(path, "wb")  # noqa: SIM115 (closed by GltfWriter.write)
        self._size = 0

    def __len__(self) -> int:
        return self._size

    def append(self, byte: int) -> None:
        self.extend(bytes([byte]))

    def extend(self, data) -> None:
        self._file.write(data)
        self._size += len(data)

    def copy_to(self, out) -> None:
        """Append the buffer's bytes to the open file ``out``: by the kernel where it can
        (``copy_file_range``: no pass through this process), else through memory."""
        self._file.flush()
        out.flush()
        with open(self.path, "rb") as f:
            left = self._size
            try:
                while left > 0:
                    copied = os.copy_file_range(f.fileno(), out.fileno(), min(left, 1 << 30))
                    if copied == 0:
                        break
                    left -= copied
            except (AttributeError, OSError):  # no such call here, or not between these files
                pass
            out.seek(0, os.SEEK_END)  # the buffered file takes up where the kernel left it
            f.seek(self._size - left)
            shutil.copyfileobj(f, out, 1 << 22)

    def close(self) -> None:
        self._file.close()
        self.path.unlink(missing_ok=True)


# The lists of a glTF document a part adds to, in the order of a part's counts and place.
PART_LISTS = ("bufferViews", "accessors", "meshes", "nodes")


@dataclass(frozen=True)
class _Raw:
    """Items of a document's list spliced in as JSON text (``count`` of them, comma-separated)."""

    text: str
    count: int


def _dumps(value: Any) -> str:
    """The writer's JSON of one value (sorted keys, no spaces)."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def _dumps_list(value: Any) -> str:
    """:func:`_dumps`, with any :class:`_Raw` items of a list as their text."""
    if not isinstance(value, list) or not any(isinstance(x, _Raw) for x in value):
        return _dumps(value)
    return "[" + ",".join(x.text if isinstance(x, _Raw) else _dumps(x) for x in value) + "]"


class GltfWriter:
    """Accumulates meshes, nodes and binary data; writes .glb or .gltf + .bin atomically.

    Deterministic: the same calls give the same bytes (sorted JSON keys, 4-byte aligned views).
    ``spill``: a file to keep the binary data in as it is added (a level's glTF of gigabytes), instead of
    memory; :meth:`write` copies it into place and removes it. Same bytes either way.
    """

    def __init__(self, generator: str = "neuralao", spill: str | Path | None = None):
        self.doc: dict[str, Any] = {
            "asset": {"version": "2.0", "generator": generator},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "accessors": [],
            "bufferViews": [],
        }
        self._blob: bytearray | _SpillBuffer = bytearray() if spill is None else _SpillBuffer(Path(spill))
        self._n = dict.fromkeys(PART_LISTS, 0)  # items in each list (spliced parts' items counted)
        self._byte0 = 0  # bytes of the whole buffer before this writer's (a part's place in it)

    @classmethod
    def positioned(cls, base) -> GltfWriter:
        """A writer of a part of another writer's document, made elsewhere (a worker writes its piece of a
        level): ``base`` = the bufferViews, accessors, meshes and nodes, then the (4-byte aligned) bytes,
        that come before it there. Its indices and offsets are the final ones; :meth:`fragments` hands
        the part over, and the document's writer adds it with :meth:`splice`."""
        w = cls()
        *counts, w._byte0 = (int(x) for x in base)
        if w._byte0 % 4:
            raise NeuralaoError(f"a glTF part must start 4-byte aligned, not at byte {w._byte0}")
        w._n = dict(zip(PART_LISTS, counts, strict=True))
        return w

    def _add(self, key: str, item: dict[str, Any]) -> int:
        """Append ``item`` to the document's list ``key``; its index there."""
        self.doc.setdefault(key, []).append(item)
        self._n[key] += 1
        return self._n[key] - 1

    @classmethod
    def from_document(cls, doc: dict[str, Any], blob: bytes) -> GltfWriter:
        """A writer that edits an existing document: ``doc`` (JSON whose bufferViews all point into
        buffer 0) and ``blob`` (buffer 0's bytes); new data is appended after ``blob``."""
        w = cls()
        w.doc = doc
        for key in PART_LISTS:
            doc.setdefault(key, [])
        w._n = {key: len(doc[key]) for key in PART_LISTS}
        w._blob = bytearray(blob)
        return w

    def buffer_view(self, data: bytes) -> int:
        """A bufferView holding ``data`` as is (an image), 4-byte aligned; returns its index."""
        while len(self._blob) % 4:
            self._blob.append(0)
        view = {"buffer": 0, "byteOffset": self._byte0 + len(self._blob), "byteLength": len(data)}
        self._blob.extend(data)
        return self._add("bufferViews", view)

    def accessor(
        self, array: np.ndarray, kind: str | None = None, normalized: bool = False, target: int | None = None
    ) -> int:
        arr = np.ascontiguousarray(array)
        if arr.dtype == np.float64:
            arr = arr.astype(np.float32)
        if arr.dtype == np.int64:
            arr = arr.astype(np.uint32)
        code = {np.dtype(v): k for k, v in COMPONENT.items()}[arr.dtype]
        width = 1 if arr.ndim == 1 else arr.shape[1]
        kind = kind or {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}[width]
        while len(self._blob) % 4:
            self._blob.append(0)
        view: dict[str, Any] = {
            "buffer": 0,
            "byteOffset": self._byte0 + len(self._blob),
            "byteLength": arr.nbytes,
        }
        if target is not None:
            view["target"] = target
        self._blob.extend(arr.astype(arr.dtype.newbyteorder("<"), copy=False).tobytes())
        acc: dict[str, Any] = {
            "bufferView": self._add("bufferViews", view),
            "componentType": code,
            "count": int(arr.shape[0]),
            "type": kind,
        }
        if normalized:
            acc["normalized"] = True
        if kind == "VEC3" and code == 5126 and len(arr):  # POSITION needs min / max
            acc["min"] = [float(x) for x in arr.min(axis=0)]
            acc["max"] = [float(x) for x in arr.max(axis=0)]
        return self._add("accessors", acc)

    def mesh(
        self,
        name: str,
        vertices: np.ndarray,
        faces: np.ndarray,
        attributes: dict[str, np.ndarray] | None = None,
    ) -> int:
        """A one-primitive triangle mesh; ``attributes`` name -> (n,) or (n, c) arrays (uint8 ->
        normalised, e.g. COLOR_0)."""
        attrs = {"POSITION": self.accessor(np.asarray(vertices, np.float32), target=34962)}
        for key, arr in (attributes or {}).items():
            arr = np.asarray(arr)
            attrs[key] = self.accessor(arr, normalized=arr.dtype == np.uint8, target=34962)
        idx = self.accessor(np.asarray(faces, np.uint32).reshape(-1), target=34963)
        return self._add(
            "meshes", {"name": name, "primitives": [{"attributes": attrs, "indices": idx, "mode": 4}]}
        )

    def node(
        self,
        name: str,
        mesh: int | None = None,
        matrix: np.ndarray | None = None,
        extras: dict | None = None,
        instances: dict[str, np.ndarray] | None = None,
    ) -> int:
        """A root node; ``instances``: EXT_mesh_gpu_instancing attributes (TRANSLATION, ROTATION,
        SCALE and custom ``_NAME`` per-instance attributes)."""
        node: dict[str, Any] = {"name": name}
        if mesh is not None:
            node["mesh"] = mesh
        if matrix is not None and not np.allclose(matrix, np.eye(4)):
            node["matrix"] = [float(x) for x in np.asarray(matrix, np.float64).T.reshape(-1)]
        if extras:
            node["extras"] = extras
        if instances:
            attrs = {k: self.accessor(np.asarray(v, np.float32)) for k, v in instances.items()}
            node["extensions"] = {INSTANCING: {"attributes": attrs}}
            used = self.doc.setdefault("extensionsUsed", [])
            if INSTANCING not in used:
                used.append(INSTANCING)
        index = self._add("nodes", node)
        self.doc["scenes"][0]["nodes"].append(index)
        return index

    def fragments(self) -> dict[str, np.ndarray]:
        """This part's JSON and bytes (a :meth:`positioned` writer's): each of its lists as the text of its
        items (UTF-8), as they stand in the document's JSON, their counts, its place ("base"), the
        extensions it uses, and its bytes ("blob")."""
        out = {
            key: np.frombuffer(_dumps(self.doc.get(key, []))[1:-1].encode(), np.uint8) for key in PART_LISTS
        }
        return out | {
            "counts": np.array([len(self.doc.get(key, [])) for key in PART_LISTS], np.int64),
            "base": np.array(
                [self._n[key] - len(self.doc.get(key, [])) for key in PART_LISTS] + [self._byte0]
            ),
            "extensions": np.frombuffer(_dumps(self.doc.get("extensionsUsed", [])).encode(), np.uint8),
            "blob": np.frombuffer(bytes(self._blob), np.uint8),
        }

    def splice(self, part: dict[str, np.ndarray]) -> None:
        """Add a part's :meth:`fragments` at the end of the document: its JSON text as it is (no parsing),
        its bytes after this writer's. It must have been made for this place (its base: this writer's
        counts and bytes so far), so the document is the one the same calls made here would give."""
        while len(self._blob) % 4:
            self._blob.append(0)
        here = [self._n[key] for key in PART_LISTS] + [self._byte0 + len(self._blob)]
        if [int(x) for x in part["base"]] != here:
            raise NeuralaoError(f"a glTF part made for place {list(part['base'])} comes at {here}")
        for key, count in zip(PART_LISTS, part["counts"], strict=True):
            if count:
                self.doc.setdefault(key, []).append(_Raw(part[key].tobytes().decode(), int(count)))
                self._n[key] += int(count)
        first = here[PART_LISTS.index("nodes")]
        self.doc["scenes"][0]["nodes"].extend(
            range(first, first + int(part["counts"][PART_LISTS.index("nodes")]))
        )
        for ext in json.loads(part["extensions"].tobytes().decode()):
            if ext not in self.doc.setdefault("extensionsUsed", []):
                self.doc["extensionsUsed"].append(ext)
        self._blob.extend(memoryview(np.ascontiguousarray(part["blob"], np.uint8).reshape(-1)))

    def _json(self, uri: str | None) -> bytes:
        while len(self._blob) % 4:
            self._blob.append(0)
        buf: dict[str, Any] = {"byteLength": self._byte0 + len(self._blob)}
        if uri is not None:
            buf["uri"] = uri
        doc = dict(self.doc, buffers=[buf])
        # json.dumps(doc, sort_keys=True) but for the spliced parts' text, which goes in as it is
        fields = (f"{_dumps(key)}:{_dumps_list(doc[key])}" for key in sorted(doc))
        return ("{" + ",".join(fields) + "}").encode()

    def write(self, path: str | Path) -> Path:
        """Write ``path`` (.glb: one file; .gltf: the .bin next to it first, then the .gltf)."""
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in (".glb", ".gltf"):
            raise NeuralaoError(f"glTF output must end in .gltf or .glb, got {path.name!r}")
        try:
            if suffix == ".glb":
                text = self._json(None)
                text += b" " * (-len(text) % 4)
                total = 12 + 8 + len(text) + 8 + len(self._blob)
                with atomic_path(path) as tmp, open(tmp, "wb") as f:
                    f.write(struct.pack("<III", GLB_MAGIC, 2, total))
                    f.write(struct.pack("<II", len(text), JSON_CHUNK) + text)
                    f.write(struct.pack("<II", len(self._blob), BIN_CHUNK))
                    self._write_blob(f)
            else:
                bin_path = path.with_suffix(".bin")
                text = self._json(bin_path.name)
                with atomic_path(bin_path) as tmp, open(tmp, "wb") as f:
                    self._write_blob(f)
                with atomic_path(path) as tmp:
                    tmp.write_bytes(text)
        finally:
            if isinstance(self._blob, _SpillBuffer):
                self._blob.close()
        return path

    def close(self) -> None:
        """Remove the spill file (a no-op without one, or once written): for a write that never happens,
        such as an interrupted bake's."""
        if isinstance(self._blob, _SpillBuffer):
            self._blob.close()

    def _write_blob(self, f) -> None:
        if isinstance(self._blob, _SpillBuffer):
            self._blob.copy_to(f)
        else:
            f.write(self._blob)


def read_gltf_json(path: str | Path) -> tuple[dict, Any]:
    """The JSON of a .gltf/.glb and an accessor reader ``get(index) -> array`` (for outputs and tests)."""
    g = GltfFile(Path(path))
    return g.doc, lambda i: g.accessor(i, str(path))
