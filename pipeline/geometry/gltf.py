"""The one reader of glTF 2.0 files (.gltf with external or data-URI buffers, .glb): the document, checked
against the specification's rules before any accessor is read, and its buffers.

Every command that takes a glTF reads it here first: the bakers through :class:`GltfFile` itself, and the
commands whose geometry comes from trimesh (render, volumes, datasets, training) through
:func:`check_gltf`, which runs the same checks without keeping the buffers. What is checked (each refusal
is one line naming the file, the item and the rule):

* the JSON: UTF-8, bounded in size and nesting (``neuralao.runtime.foundation.manifest.parse_json``), a GLB's
  header and chunks whole;
* ``extensionsRequired``: only extensions the reader implements (a required extension changes what the
  file means; one that is not implemented would be silently misread);
* buffers: ``byteLength`` an integer >= 0, the data (GLB chunk, file beside the glTF, data URI) at least
  that long, a file never outside the glTF's folder;
* bufferViews: ``buffer`` an index of the file, ``byteOffset`` >= 0, ``byteLength`` >= 1, the range inside
  its buffer, ``byteStride`` a multiple of 4 in [4, 252];
* accessors: a known ``componentType`` and ``type``, ``count`` an integer >= 0, ``byteOffset`` >= 0 and a
  multiple of the component size, a ``byteStride`` no smaller than the element, every element inside its
  bufferView;
* meshes, nodes, scenes: every index they hold (attributes, indices, mesh, children, scene nodes, the
  default ``scene``) inside the file; ``indices`` accessors SCALAR unsigned integers, ``POSITION`` accessors
  VEC3 floats (integers only with ``KHR_mesh_quantization`` in ``extensionsUsed``);
* node transforms: ``matrix`` 16 numbers whose last row is [0 0 0 1] (a glTF matrix decomposes into TRS),
  or ``translation`` / ``rotation`` / ``scale`` of 3 / 4 / 3 numbers (rotation components in [-1, 1], not
  all 0), never both; numbers are JSON numbers, finite (no strings, no true / false); and every node with a
  mesh has a finite world transform (its parents' transforms times its own: nested scales overflow).
"""

from __future__ import annotations

import base64
import math
import os
import struct
from pathlib import Path
from typing import Any
from urllib.parse import unquote

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError, reading
from neuralao.runtime.foundation.manifest import parse_json

COMPONENT = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
GLB_MAGIC, JSON_CHUNK, BIN_CHUNK = 0x46546C67, 0x4E4F534A, 0x004E4942
INSTANCING = "EXT_mesh_gpu_instancing"
QUANTIZATION = "KHR_mesh_quantization"
# Geometry compression: the primitives' accessors hold no readable data without a decoder.
COMPRESSION = ("KHR_draco_mesh_compression", "EXT_meshopt_compression")
# Extensions that change only how a file shades (materials, textures, lights): AO is geometry, and a bake
# passes them through untouched, so a file that requires one is read correctly without them.
SHADING_EXTENSION_PREFIXES = ("KHR_materials_", "KHR_texture_", "KHR_lights_", "EXT_texture_", "EXT_lights_")
# What the bakers' reader implements besides those: instancing and quantised attributes (integer
# positions, normalised or not, dequantised by the node transforms it applies).
BAKER_EXTENSIONS = frozenset({INSTANCING, QUANTIZATION})
# What the trimesh-based readers implement besides those: nothing of geometry (trimesh ignores instancing
# and does not dequantise normalised positions).
TRIMESH_EXTENSIONS: frozenset[str] = frozenset()
# Component types of a primitive's indices (unsigned integers) and of its positions: floats, and with
# KHR_mesh_quantization also (normalised or not) 8- and 16-bit integers (glTF 2.0, 3.7.2.1 and the extension).
INDEX_COMPONENTS = (5121, 5123, 5125)
POSITION_COMPONENTS = (5126,)
QUANTIZED_POSITION_COMPONENTS = (5120, 5121, 5122, 5123, 5126)
# A node's TRS properties: their lengths (a matrix holds 16 numbers).
TRS = {"translation": 3, "rotation": 4, "scale": 3}
# A node whose world matrix entries may pass 1e300 by a bound on the product of its own and its
# parents' numbers has its world matrix composed to be sure it is finite (float64 ends near 1.8e308).
WORLD_BOUND_LOG10 = 300.0


def outside_folder_message(gltf: str | os.PathLike, uri: str) -> str:
    """The one-line refusal of a glTF resource (buffer or image) outside the glTF's own folder."""
    folder = Path(gltf).resolve().parent
    return (
        f"{Path(gltf).name} refers to {uri!r}, which is outside its folder {folder}: only files in the "
        "glTF's folder or below it are read; copy the file there and point the uri at it, or use a .glb"
    )


def gltf_resource(gltf: str | os.PathLike, uri: str) -> Path:
    """The file a glTF's relative ``uri`` names (percent-decoded), refused when it leaves the glTF's
    folder."""
    folder = Path(gltf).resolve().parent
    target = (folder / unquote(uri)).resolve()
    if not target.is_relative_to(folder):
        raise NeuralaoError(outside_folder_message(gltf, uri))
    return target


def gltf_label(kind: str, index: int, item: Any) -> str:
    """How every message names a glTF node, mesh or other indexed item: ``node 3 'Chair'`` when it
    has a name, ``node 3 (unnamed)`` when it has none (the index is always there: names repeat)."""
    name = item.get("name") if isinstance(item, dict) else None
    return f"{kind} {index} {str(name)!r}" if name not in (None, "") else f"{kind} {index} (unnamed)"


def _integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def json_number(value: Any) -> float | None:
    """``value`` as a finite float if it is a JSON number that one holds, else None (a string, true / false,
    NaN or inf, an integer past float64 such as 10**400)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def _numbers(value: Any, count: int) -> list[float] | None:
    """A list of ``count`` finite JSON numbers as floats, else None."""
    if not isinstance(value, list) or len(value) != count:
        return None
    numbers = [json_number(v) for v in value]
    return None if any(v is None for v in numbers) else numbers


# --------------------------------------------------------------------------- node transforms


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """glTF quaternions (k, 4) [x, y, z, w] -> rotation matrices (k, 3, 3) float64 (normalised first)."""
    q = np.asarray(q, np.float64).reshape(-1, 4)
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    if not (np.isfinite(q).all() and (norm > 0).all()):
        raise NeuralaoError("rotation quaternion is zero or not finite")
    x, y, z, w = (q / norm).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def trs_matrices(t=None, r=None, s=None, count: int = 1) -> np.ndarray:
    """(k, 4, 4) float64 = T @ R @ S from translations (k, 3), quaternions (k, 4), scales (k, 3)."""
    m = np.tile(np.eye(4), (count, 1, 1))
    rot = quat_to_matrix(r) if r is not None else np.tile(np.eye(3), (count, 1, 1))
    scale = np.ones((count, 3)) if s is None else np.asarray(s, np.float64).reshape(count, 3)
    m[:, :3, :3] = rot * scale[:, None, :]
    if t is not None:
        m[:, :3, 3] = np.asarray(t, np.float64).reshape(count, 3)
    return m


def local_matrix(node: dict) -> np.ndarray:
    """(4, 4) float64 local transform of a node whose numbers :class:`GltfFile` has checked: its ``matrix``
    (column-major), else T @ R @ S of its ``translation`` / ``rotation`` / ``scale``."""
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T
    return trs_matrices(node.get("translation"), node.get("rotation"), node.get("scale"))[0]


def _magnitude(node: dict) -> float:
    """log10 of an upper bound on a checked node's local matrix entries (rotations add nothing: their
    entries lie in [-1, 1]), at least 0."""
    numbers = node["matrix"] if "matrix" in node else [*node.get("translation", ()), *node.get("scale", ())]
    return math.log10(max([1.0, *(abs(float(v)) for v in numbers)]))


class GltfFile:
    """The checked document of a .gltf / .glb (module doc) and, with ``buffers``, its buffers' bytes.

    ``implemented``: the extensions the caller's reader implements beyond the shading ones (a file that
    requires another is refused)."""

    def __init__(self, path: str | os.PathLike, implemented: frozenset[str] = BAKER_EXTENSIONS, buffers=True):
        self.path = Path(path)
        with reading(self.path, "glTF file"):
            text, bin_span = self._read_document()
        self.doc = parse_json(text, self.path, "glTF JSON")
        if not isinstance(self.doc, dict):
            raise NeuralaoError(f"{self.path}: the glTF root must be a JSON object")
        asset = self.doc.get("asset")
        version = str(asset.get("version", "")) if isinstance(asset, dict) else ""
        if not version.startswith("2"):
            raise NeuralaoError(f"{self.path}: glTF asset.version must be 2.x, got {version!r}")
        self._check_extensions(implemented)
        specs = self._items("buffers")
        data = [self._buffer(i, b, bin_span, keep=buffers) for i, b in enumerate(specs)]
        self._check_views([b["byteLength"] for b in specs])
        self._check_accessors()
        self._check_indices()
        self._check_world_transforms()
        self.buffers: list[bytes] = data if buffers else []

    # ------------------------------------------------------------------ the document
    def _read_document(self) -> tuple[bytes, tuple[int, int] | None]:
        """The JSON bytes and, for a GLB, (offset, size) of its BIN chunk; a GLB is read chunk by chunk,
        so a large binary chunk is not read here."""
        with open(self.path, "rb") as f:
            head = f.read(12)
            if head[:4] != b"glTF":
                return head + f.read(), None
            size = os.fstat(f.fileno()).st_size
            if len(head) < 12:
                raise NeuralaoError(f"{self.path}: truncated GLB header")
            magic, version, length = struct.unpack("<III", head)
            if magic != GLB_MAGIC or version != 2 or length > size:
                raise NeuralaoError(f"{self.path}: bad or truncated GLB (version {version}, length {length})")
            pos, text, binary = 12, None, None
            while pos + 8 <= length:
                f.seek(pos)
                chunk_size, kind = struct.unpack("<II", f.read(8))
                if pos + 8 + chunk_size > length:
                    raise NeuralaoError(f"{self.path}: truncated GLB chunk")
                if kind == JSON_CHUNK and text is None:
                    text = f.read(chunk_size)
                elif kind == BIN_CHUNK and binary is None:
                    binary = (pos + 8, chunk_size)
                pos += 8 + chunk_size
        if text is None:
            raise NeuralaoError(f"{self.path}: GLB has no JSON chunk")
        return text, binary

    def _items(self, key: str) -> list[dict]:
        items = self.doc.get(key, [])
        if not isinstance(items, list) or not all(isinstance(x, dict) for x in items):
            raise NeuralaoError(f"{self.path.name}: {key} must be a list of JSON objects")
        return items

    def _fail(self, item: str, rule: str) -> NeuralaoError:
        return NeuralaoError(f"{self.path.name}: {item} {rule} (glTF 2.0)")

    def _check_extensions(self, implemented: frozenset[str]) -> None:
        required = self.doc.get("extensionsRequired", [])
        if not isinstance(required, list) or not all(isinstance(e, str) for e in required):
            raise self._fail("extensionsRequired", "must be a list of extension names")
        for ext in required:
            if ext in COMPRESSION:
                raise NeuralaoError(
                    f"{self.path.name}: compressed geometry ({ext}) is not supported; decompress it first"
                )
            if ext not in implemented and not ext.startswith(SHADING_EXTENSION_PREFIXES):
                known = ", ".join(sorted(implemented)) or "none that change geometry"
                raise NeuralaoError(
                    f"{self.path.name}: extensionsRequired names {ext!r}, which this reader does not "
                    f"implement (implemented: {known}, and material / texture / light extensions)"
                )

    def _buffer(self, index: int, spec: dict, bin_span: tuple[int, int] | None, keep: bool) -> bytes:
        length = spec.get("byteLength")
        if not _integer(length) or length < 0:  # the spec asks >= 1; an empty buffer nothing uses is harmless
            raise self._fail(f"buffers[{index}].byteLength", f"must be an integer >= 0, got {length!r}")
        uri = spec.get("uri")
        if uri is None:
            if bin_span is None:
                raise NeuralaoError(f"{self.path}: buffer {index} has no uri and there is no GLB chunk")
            data = self._read_span(*bin_span) if keep else b""
            size = bin_span[1]
        elif isinstance(uri, str) and uri.startswith("data:"):
            try:
                data = base64.b64decode(uri.split(",", 1)[1])
            except Exception:
                raise NeuralaoError(f"{self.path}: buffer {index} has a bad data URI") from None
            size = len(data)
        else:
            if not isinstance(uri, str):
                raise NeuralaoError(f"{self.path}: buffer {index} uri must be a string, got {uri!r}")
            p = gltf_resource(self.path, uri)  # never a file outside the glTF's folder
            if not p.is_file():
                raise NeuralaoError(f"{self.path}: buffer {index} file not found: {uri}")
            size = p.stat().st_size
            data = p.read_bytes() if keep else b""
        if size < length:
            raise NeuralaoError(f"{self.path}: buffer {index} has {size} bytes, byteLength says {length}")
        return data

    def _read_span(self, offset: int, size: int) -> bytes:
        with open(self.path, "rb") as f:
            f.seek(offset)
            return f.read(size)

    def _check_views(self, buffer_lengths: list[int]) -> None:
        for i, v in enumerate(self._items("bufferViews")):
            item = f"bufferViews[{i}]"
            b, offset, length = v.get("buffer"), v.get("byteOffset", 0), v.get("byteLength")
            if not _integer(b) or not 0 <= b < len(buffer_lengths):
                n = len(buffer_lengths)
                raise self._fail(f"{item}.buffer", f"{b!r} is not a buffer of the file ({n} buffers)")
            if not _integer(offset) or offset < 0:
                raise self._fail(f"{item}.byteOffset", f"must be an integer >= 0, got {offset!r}")
            if not _integer(length) or length < 1:
                raise self._fail(f"{item}.byteLength", f"must be an integer >= 1, got {length!r}")
            if offset + length > buffer_lengths[b]:
                raise self._fail(
                    item, f"runs past its buffer: bytes {offset}..{offset + length} of {buffer_lengths[b]}"
                )
            stride = v.get("byteStride")
            if stride is not None and (not _integer(stride) or not 4 <= stride <= 252 or stride % 4):
                raise self._fail(f"{item}.byteStride", f"must be a multiple of 4 in [4, 252], got {stride!r}")

    def _check_accessors(self) -> None:
        views = self._items("bufferViews")
        for i, a in enumerate(self._items("accessors")):
            item = f"accessors[{i}]"
            kind, type_, count = a.get("componentType"), a.get("type"), a.get("count")
            if kind not in COMPONENT or isinstance(kind, bool):
                raise self._fail(f"{item}.componentType", f"{kind!r} is not one of {sorted(COMPONENT)}")
            if type_ not in WIDTH:
                raise self._fail(f"{item}.type", f"{type_!r} is not one of {', '.join(WIDTH)}")
            if not _integer(count) or count < 0:
                raise self._fail(f"{item}.count", f"must be an integer >= 0, got {count!r}")
            offset = a.get("byteOffset", 0)
            if not _integer(offset) or offset < 0:
                raise self._fail(f"{item}.byteOffset", f"must be an integer >= 0, got {offset!r}")
            if "bufferView" not in a:
                continue  # zeros (or sparse): nothing to read from a buffer
            vi = a["bufferView"]
            if not _integer(vi) or not 0 <= vi < len(views):
                n = len(views)
                raise self._fail(f"{item}.bufferView", f"{vi!r} is not a bufferView of the file ({n} views)")
            size = np.dtype(COMPONENT[kind]).itemsize
            element = size * WIDTH[type_]
            if offset % size:
                raise self._fail(
                    f"{item}.byteOffset", f"{offset} is not a multiple of the component size {size}"
                )
            stride = views[vi].get("byteStride", element)
            if stride < element:
                raise self._fail(
                    f"bufferViews[{vi}].byteStride",
                    f"{stride} is smaller than the {element}-byte element of {item} ({type_} of {size}-byte "
                    "components): elements would overlap",
                )
            end = offset + (count - 1) * stride + element if count else offset
            if end > views[vi]["byteLength"]:
                raise self._fail(
                    item,
                    f"runs past its bufferView: {count} elements end at byte {end} of "
                    f"{views[vi]['byteLength']}",
                )

    def _check_indices(self) -> None:
        """Every index a mesh, node or scene holds is an item of the file."""
        n_acc, meshes, nodes = len(self._items("accessors")), self._items("meshes"), self._items("nodes")
        n_materials = len(self._items("materials"))

        def accessor(value: Any, item: str) -> None:
            if not _integer(value) or not 0 <= value < n_acc:
                raise self._fail(item, f"{value!r} is not an accessor of the file ({n_acc} accessors)")

        accessors = self._items("accessors")
        used = self.doc.get("extensionsUsed", [])
        if not isinstance(used, list) or not all(isinstance(e, str) for e in used):
            raise self._fail("extensionsUsed", "must be a list of extension names")
        positions = QUANTIZED_POSITION_COMPONENTS if QUANTIZATION in used else POSITION_COMPONENTS
        position_rule = (
            f"FLOAT (5126), or 8- / 16-bit integers with {QUANTIZATION}"
            if QUANTIZATION in used
            else f"FLOAT (5126) (integer positions need {QUANTIZATION} in extensionsUsed)"
        )

        def typed(value: int, item: str, kind: str, components: tuple[int, ...], rule: str) -> None:
            a = accessors[value]
            if a["type"] != kind or a["componentType"] not in components:
                got = f"{a['type']} of componentType {a['componentType']}"
                raise self._fail(item, f"names accessor {value}, {got}; it must be {kind} of {rule}")

        for m, mesh in enumerate(meshes):
            prims = mesh.get("primitives", [])
            if not isinstance(prims, list) or not all(isinstance(p, dict) for p in prims):
                raise self._fail(f"meshes[{m}].primitives", "must be a list of JSON objects")
            for k, prim in enumerate(prims):
                attrs = prim.get("attributes", {})
                if not isinstance(attrs, dict):
                    raise self._fail(f"meshes[{m}].primitives[{k}].attributes", "must be a JSON object")
                for name, value in attrs.items():
                    accessor(value, f"meshes[{m}].primitives[{k}].attributes.{name}")
                if "POSITION" in attrs:
                    item = f"meshes[{m}].primitives[{k}].attributes.POSITION"
                    typed(attrs["POSITION"], item, "VEC3", positions, position_rule)
                if "indices" in prim:
                    item = f"meshes[{m}].primitives[{k}].indices"
                    accessor(prim["indices"], item)
                    rule = "an unsigned integer componentType (5121, 5123 or 5125)"
                    typed(prim["indices"], item, "SCALAR", INDEX_COMPONENTS, rule)
                mode = prim.get("mode", 4)
                if not _integer(mode) or not 0 <= mode <= 6:
                    raise self._fail(
                        f"meshes[{m}].primitives[{k}].mode", f"must be an integer in [0, 6], got {mode!r}"
                    )
                material = prim.get("material")
                if material is not None and (not _integer(material) or not 0 <= material < n_materials):
                    raise self._fail(
                        f"meshes[{m}].primitives[{k}].material", f"{material!r} is not a material of the file"
                    )
        for i, node in enumerate(nodes):
            where = f"{self.path.name} {gltf_label('node', i, node)}"
            mi = node.get("mesh")
            if mi is not None and (not _integer(mi) or not 0 <= mi < len(meshes)):
                raise NeuralaoError(f"{where}: references mesh {mi!r}, the file has {len(meshes)}")
            for key in ("extensions", "extras"):
                if key in node and not isinstance(node[key], dict):
                    raise NeuralaoError(
                        f"{where}: {key} must be a JSON object, got {type(node[key]).__name__}"
                    )
            children = node.get("children", [])
            inside = isinstance(children, list) and all(_integer(c) and 0 <= c < len(nodes) for c in children)
            if not inside:
                raise NeuralaoError(f"{where}: children {children!r} are not all nodes of the file"[:300])
            self._check_transform(node, f"nodes[{i}]")
        scenes = self._items("scenes")
        for s, scene in enumerate(scenes):
            roots = scene.get("nodes", [])
            if not isinstance(roots, list) or not all(_integer(r) and 0 <= r < len(nodes) for r in roots):
                raise self._fail(f"scenes[{s}].nodes", f"are not all nodes of the file ({len(nodes)} nodes)")
        if "scene" in self.doc:
            default = self.doc["scene"]
            if not _integer(default) or not 0 <= default < len(scenes):
                raise self._fail("scene", f"{default!r} is not a scene of the file ({len(scenes)} scenes)")

    def _check_transform(self, node: dict, item: str) -> None:
        """A node's ``matrix`` (16 numbers, last row [0 0 0 1]) or TRS (3 / 4 / 3 numbers), not both."""
        if "matrix" in node:
            values = _numbers(node["matrix"], 16)
            if values is None:
                raise self._fail(f"{item}.matrix", "must be a list of 16 finite numbers (column-major)")
            if values[3::4] != [0.0, 0.0, 0.0, 1.0]:  # column-major: every 4th from the 4th is the last row
                raise self._fail(
                    f"{item}.matrix",
                    f"has the last row {values[3::4]}; it must be [0, 0, 0, 1] (decomposable to translation, "
                    "rotation and scale)",
                )
            given = sorted(set(TRS) & set(node))
            if given:
                raise self._fail(item, f"has a matrix and {', '.join(given)}; give one or the other")
        for key, count in TRS.items():
            if key in node and _numbers(node[key], count) is None:
                raise self._fail(f"{item}.{key}", f"must be a list of {count} finite numbers")
        rotation = node.get("rotation")
        # a length of 0 (all zeros, or squares that underflow) leaves no rotation to normalise to
        if rotation is not None and (any(abs(q) > 1 for q in rotation) or sum(q * q for q in rotation) == 0):
            raise self._fail(
                f"{item}.rotation",
                f"{rotation} is not a unit quaternion (components in [-1, 1], length above 0)",
            )

    def _check_world_transforms(self) -> None:
        """Every node with a mesh has a finite world transform. Each node's own numbers are finite, but their
        product down the hierarchy may pass float64 (eleven nested scales of 1e30 make inf and NaN
        vertices). A bound on the product (pure Python, no matrix per node: a level holds thousands of
        nodes) picks the few nodes whose world matrix is composed to be sure; a composed one starts the
        bound of its children afresh, so however deep a hierarchy, each node is composed at most once."""
        nodes = self._items("nodes")
        above: dict[int, int] = {}  # node -> the parent it is first reached from (a tree: each once)
        bound: dict[int, float] = {}  # node -> log10 of a bound on its world matrix entries
        worlds: dict[int, np.ndarray] = {}  # node -> its world matrix, where it was composed
        children = {c for n in nodes for c in n.get("children", [])}
        stack = [(i, -1) for i in reversed(range(len(nodes))) if i not in children]
        while stack:
            i, parent = stack.pop()
            if i in bound:
                continue  # a shared child or a cycle: the readers refuse the file, naming the node
            above[i] = parent
            # each entry of a product of 4x4 matrices sums 4 products of entries
            bound[i] = _magnitude(nodes[i]) + (bound[parent] + math.log10(4.0) if parent >= 0 else 0.0)
            if bound[i] > WORLD_BOUND_LOG10:
                world = self._world(nodes, i, above, worlds)
                finite = bool(np.isfinite(world).all())
                if not finite and "mesh" in nodes[i]:
                    depth, k = 0, i
                    while above[k] >= 0:
                        depth, k = depth + 1, above[k]
                    raise NeuralaoError(
                        f"{self.path.name} {gltf_label('node', i, nodes[i])}: its world transform is not "
                        f"finite (the transforms of the {depth} nodes above it multiply past float64's "
                        "range); scale the hierarchy down"
                    )
                bound[i] = math.log10(max(1.0, float(np.abs(world).max()))) if finite else math.inf
            stack += [(c, i) for c in reversed(nodes[i].get("children", []))]

    @staticmethod
    def _world(nodes: list[dict], i: int, above: dict[int, int], worlds: dict[int, np.ndarray]) -> np.ndarray:
        """Node ``i``'s world matrix (4, 4) float64, composed down from its nearest composed ancestor or its
        root (``above``: each node's parent, -1 at a root); every matrix composed on the way is kept in
        ``worlds``."""
        chain = [i]
        while above[chain[-1]] >= 0 and chain[-1] not in worlds:
            chain.append(above[chain[-1]])
        world = worlds.get(chain[-1], np.eye(4))
        with np.errstate(over="ignore", invalid="ignore"):  # inf and NaN are what is looked for
            for k in reversed(chain if chain[-1] not in worlds else chain[:-1]):
                world = worlds[k] = world @ local_matrix(nodes[k])
        return world

    # ------------------------------------------------------------------ data
    def accessor(self, index: Any, where: str, normalize: bool = True) -> np.ndarray:
        """Accessor ``index`` as a (count, width) or (count,) array (normalised integers -> float,
        unless ``normalize`` is False: then the stored integers, e.g. to copy an attribute as it is)."""
        accs = self.doc.get("accessors", [])
        if not isinstance(index, int) or not 0 <= index < len(accs):
            raise NeuralaoError(f"{where}: accessor {index!r} is not in the file ({len(accs)} accessors)")
        a = accs[index]
        if "bufferView" not in a or "sparse" in a:
            raise NeuralaoError(f"{where}: accessor {index} has no bufferView or is sparse (not supported)")
        dtype = np.dtype(COMPONENT[a["componentType"]]).newbyteorder("<")
        width, count = WIDTH[a["type"]], a["count"]
        view = self.doc["bufferViews"][a["bufferView"]]
        buf = self.buffers[view["buffer"]]
        offset = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        item = dtype.itemsize * width
        stride = view.get("byteStride", item)
        end = offset + (count - 1) * stride + item if count else offset
        if end > len(buf):
            raise NeuralaoError(f"{where}: accessor {index} runs past the end of its buffer (truncated?)")
        arr = np.lib.stride_tricks.as_strided(
            np.frombuffer(buf, dtype=dtype, count=max(0, (end - offset) // dtype.itemsize), offset=offset),
            shape=(count, width),
            strides=(stride, dtype.itemsize),
        ).copy()
        if normalize and a.get("normalized") and dtype.kind in "iu":
            arr = np.maximum(arr / float(np.iinfo(dtype).max), -1.0)
        return arr[:, 0] if width == 1 else arr


def check_gltf(path: str | os.PathLike, implemented: frozenset[str] = TRIMESH_EXTENSIONS) -> None:
    """Check a .gltf / .glb as :class:`GltfFile` does, without keeping its buffers (for readers that
    take the geometry from another library afterwards)."""
    GltfFile(path, implemented, buffers=False)
