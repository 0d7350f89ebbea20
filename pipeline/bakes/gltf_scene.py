"""`neuralao bake SCENE.gltf|SCENE.glb --out OUT.glb`: AO baked into a glTF scene, the scene kept.

A glTF file is a scene, not a mesh: nodes in a hierarchy with names and transforms, meshes that
several nodes may share, primitives with their own materials and textures. It is baked as one:

1. **Read.** The default scene's nodes are walked depth first; every triangle primitive (mode 4, 5
   or 6) of every node with a mesh is a *piece*: the primitive's positions under the node's world
   matrix (a mirroring matrix reverses the winding, as glTF specifies; a skinned mesh is taken in
   its bind pose, with a warning; a zero scale, glTF's way to hide a node, keeps the node and drops the
   faces it collapses as degenerate, with a warning, as the flattened reader does). A node with
   ``EXT_mesh_gpu_instancing`` adds each instance as an occluder but is not written (per-instance AO
   of instanced decorations is the level bake's job, ``--config``). Points and lines are skipped.
2. **Trace.** The pieces form one world-space :class:`~neuralao.pipeline.geometry.scene.Scene` in one Embree
   scene, so every object occludes every other, and the distances relative to the diagonal are the whole
   scene's. The per-vertex bake is :func:`neuralao.pipeline.bakes.vertex.bake` itself (``vertex`` or
   ``least-squares``) on that scene; the texture bake rasterises each primitive's UVs
   (:mod:`neuralao.pipeline.bakes.texture`) and labels every texel of every piece with one labeller, seeded
   per (piece, texel).
3. **Write** by editing the input document, so what the bake does not touch (node names, hierarchy,
   transforms, materials, textures, samplers, animations, skins, extensions, extras) passes through;
   the buffers become the GLB's one binary chunk and external images are embedded.

   * ``--to vertex``: every primitive gets ``COLOR_0`` (RGBA8 normalised grey AO; multiplied into the
     primitive's own ``COLOR_0`` where it had one, since glTF multiplies the base colour by it) and
     ``_AO`` (float32; glTF names application attributes with a leading underscore). Materials are
     untouched.
   * ``--to texture``: every primitive gets its own map as its material's ``occlusionTexture`` (8-bit
     grey PNG, AO in the red channel, LINEAR filtering, CLAMP_TO_EDGE). It uses the primitive's
     ``TEXCOORD_0`` when those UVs lie in [0, 1] without overlap (``--uv auto``; ``--uv mesh`` insists),
     else a lightmap set from xatlas added as the next free ``TEXCOORD_n``: the primitive's vertices
     are split along the atlas seams and every attribute (and morph target) is remapped, so the
     material's other textures keep their own UVs. The material keeps every other field
     (baseColorFactor and texture, metallic / roughness, normal map, emissive, extensions); a material
     that several primitives share is copied for each further one (each has its own map), and a
     primitive without a material gets a plain white one.

4. **Instances.** A mesh that several nodes reference is baked per instance (each sees its own
   surroundings). Instances with identical results keep sharing the mesh; each further result gets
   a copy of the mesh entry that shares every accessor except the AO (vertex) or the material
   (texture), so the file grows only by what differs.

The resolved settings are saved in ``asset.extras.neuralao`` (the file describes itself). A glTF
baked to ``.ply`` is still flattened into one mesh (:mod:`neuralao.pipeline.bakes.vertex`); PLY has no scene.
"""

from __future__ import annotations

import base64
import copy
import io
import logging
import math
import mimetypes
import time
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from neuralao.pipeline.bakes.texture import (
    OVERLAP_LIMIT,
    UV_RANGE_SLACK,
    check_settings,
    quantise,
    rasterise,
    texel_image,
    xatlas_layout,
)
from neuralao.pipeline.bakes.vertex import GLB_AO_ATTRIBUTE
from neuralao.pipeline.geometry.gltf import GltfFile, gltf_label
from neuralao.pipeline.geometry.level_files import (
    GltfWriter,
    _instances,
    check_finite_transforms,
    node_matrix,
    singular_transforms,
)
from neuralao.pipeline.geometry.scene import MAX_COORDINATE, Scene, resolve_mesh_path, scene_from_arrays
from neuralao.pipeline.geometry.surface import vertex_colours
from neuralao.pipeline.tracing.labeller import Labeller
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import settings_to_dict

log = logging.getLogger(__name__)

GLTF_SUFFIXES = (".gltf", ".glb")
_LINEAR, _CLAMP = 9729, 33071
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


@dataclass
class Piece:
    """One triangle primitive of one node instance.

    node, instance, mesh, primitive : glTF indices (instance: the EXT_mesh_gpu_instancing row, else 0)
    matrix   : (4, 4) float64 object -> world
    vertices : (n, 3) float64 the primitive's POSITION, object space
    faces    : (m, 3) int64 triangles into ``vertices``, winding as authored
    used     : (u,) int64 sorted vertices the triangles use (only they enter the world scene)
    v0       : index of ``used[0]`` in the world scene's vertices
    written  : False for occluder-only instances (EXT_mesh_gpu_instancing)
    """

    node: int
    instance: int
    mesh: int
    primitive: int
    matrix: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    used: np.ndarray
    v0: int = 0
    written: bool = True

    @property
    def mirrored(self) -> bool:
        return bool(np.linalg.slogdet(self.matrix[:3, :3])[0] < 0)  # its sign: a det may pass float64

    def world_vertices(self) -> np.ndarray:
        """(n, 3) float64 every vertex of the primitive in world space."""
        return self.vertices @ self.matrix[:3, :3].T + self.matrix[:3, 3]


@dataclass
class GltfScene:
    """A glTF file read for baking: the parsed document, its pieces and their world scene."""

    path: Path
    gltf: GltfFile
    pieces: list[Piece]
    world: Scene
    skipped: dict[str, int] = field(default_factory=dict)

    @property
    def doc(self) -> dict:
        return self.gltf.doc


# --------------------------------------------------------------------------- reading


def bakes_as_scene(mesh: str, out: str | Path) -> bool:
    """True when ``neuralao bake MESH --out OUT`` bakes a glTF scene (a glTF in, a .glb out)."""
    return Path(out).suffix.lower() == ".glb" and resolve_mesh_path(mesh).suffix.lower() in GLTF_SUFFIXES


def triangles(index: np.ndarray, mode: int, where: str) -> np.ndarray | None:
    """(m, 3) int64 triangles of a primitive's index list for glTF ``mode`` 4, 5 or 6; None otherwise."""
    index = np.asarray(index, np.int64)
    if mode == 4:
        if len(index) % 3:
            raise NeuralaoError(f"{where}: index count {len(index)} is not a multiple of 3")
        return index.reshape(-1, 3)
    if mode in (5, 6) and len(index) >= 3:
        i = np.arange(len(index) - 2)
        if mode == 5:  # strip: every other triangle swaps its first two corners to keep the winding
            odd = i % 2 == 1
            return np.stack(
                [np.where(odd, index[i + 1], index[i]), np.where(odd, index[i], index[i + 1]), index[i + 2]],
                axis=1,
            )
        return np.stack([np.full_like(i, index[0]), index[i + 1], index[i + 2]], axis=1)
    return None if mode not in (4, 5, 6) else np.zeros((0, 3), np.int64)


def _primitive_pieces(
    g: GltfFile, node: int, mi: int, transforms: np.ndarray, written: bool, skipped: dict[str, int]
) -> list[Piece]:
    mesh = g.doc["meshes"][mi]
    out = []
    for k, prim in enumerate(mesh.get("primitives", [])):
        where = f"{g.path.name} {gltf_label('mesh', mi, mesh)} primitive {k}"
        attrs = prim.get("attributes", {})
        if "POSITION" not in attrs:
            raise NeuralaoError(f"{where}: no POSITION attribute")
        v = np.asarray(g.accessor(attrs["POSITION"], where), np.float64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise NeuralaoError(f"{where}: POSITION must be VEC3")
        if not np.isfinite(v).all():
            raise NeuralaoError(f"{where}: POSITION has NaN or inf")
        index = g.accessor(prim["indices"], where) if "indices" in prim else np.arange(len(v))
        faces = triangles(np.asarray(index).reshape(-1), int(prim.get("mode", 4)), where)
        if faces is None:
            skipped["points or lines"] = skipped.get("points or lines", 0) + 1
            continue
        if len(faces) and (faces.min() < 0 or faces.max() >= len(v)):
            raise NeuralaoError(f"{where}: indices outside [0, {len(v)})")
        if len(faces) == 0:
            continue
        used = np.unique(faces)
        out += [Piece(node, j, mi, k, m, v, faces, used, written=written) for j, m in enumerate(transforms)]
    return out


def read_gltf_scene(path: str | Path) -> GltfScene:
    """Read a .gltf/.glb for baking (module doc, step 1); one-line :class:`NeuralaoError` on bad input."""
    path = resolve_mesh_path(path)
    g = GltfFile(path)
    doc = g.doc
    nodes, meshes, scenes = doc.get("nodes", []), doc.get("meshes", []), doc.get("scenes", [])
    if scenes:
        si = doc.get("scene", 0)
        if not isinstance(si, int) or not 0 <= si < len(scenes):
            raise NeuralaoError(f"{path.name}: scene {si!r} is not in the file")
        roots = scenes[si].get("nodes", [])
    else:
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    pieces: list[Piece] = []
    skipped: dict[str, int] = {}
    seen: set[int] = set()
    stack = [(r, np.eye(4)) for r in reversed(roots)]
    while stack:
        i, parent = stack.pop()
        if not isinstance(i, int) or not 0 <= i < len(nodes):
            raise NeuralaoError(f"{path.name}: node {i!r} is not in the file ({len(nodes)} nodes)")
        if i in seen:
            raise NeuralaoError(f"{path.name}: node {i} is reached twice (a cycle or a shared child)")
        seen.add(i)
        node = nodes[i]
        where = f"{path.name} {gltf_label('node', i, node)}"
        # GltfFile refuses a node with a mesh whose world transform is not finite; one without is harmless
        with np.errstate(over="ignore", invalid="ignore"):
            world = parent @ node_matrix(node, where)
        if "mesh" in node:
            mi = node["mesh"]
            if not isinstance(mi, int) or not 0 <= mi < len(meshes):
                raise NeuralaoError(f"{where}: references mesh {mi!r}, the file has {len(meshes)}")
            inst = _instances(g, node, where)
            with np.errstate(over="ignore", invalid="ignore"):  # instances past float64: refused next
                transforms = world[None] if inst is None else world[None] @ inst
            check_finite_transforms(transforms, where)
            _warn_collapsed(transforms, inst is not None, where)
            if inst is not None:
                skipped["instanced nodes (occluders only)"] = (
                    skipped.get("instanced nodes (occluders only)", 0) + 1
                )
            if "skin" in node:  # glTF poses a skinned mesh by its joints; the bake sees the bind pose
                log.warning("%s: skinned; baked in its bind pose under the node's transform", where)
            pieces += _primitive_pieces(g, i, mi, transforms, inst is None, skipped)
        for c in reversed(node.get("children", [])):
            stack.append((c, world))
    if not any(p.written for p in pieces):
        raise NeuralaoError(f"{path.name} has no node with a triangle mesh in its scene")
    for what, count in skipped.items():
        log.warning("%s: %d %s not baked", path.name, count, what)
    return GltfScene(path, g, pieces, _world_scene(pieces, path, doc), skipped)


def _warn_collapsed(transforms: np.ndarray, instanced: bool, where: str) -> None:
    """Say so where a zero scale (glTF's way to hide a node) collapses a node or some of its instances
    (``transforms`` (k, 4, 4) float64): they are kept, and the faces they collapse are dropped as degenerate,
    as the flattened reader (:func:`~neuralao.pipeline.geometry.scene.load_scene`) drops them."""
    collapsed = int(singular_transforms(transforms).sum())
    if collapsed:
        what = f"{collapsed} of its {len(transforms)} instances" if instanced else "it"
        log.warning(
            "%s: a zero scale collapses %s; its collapsed faces are dropped as degenerate", where, what
        )


def _check_placed(world: np.ndarray, p: Piece, path: Path, doc: dict) -> None:
    """A piece's world vertices ``world`` (u, 3) float64 finite and within +-``MAX_COORDINATE`` (the rule
    :func:`~neuralao.pipeline.geometry.scene.scene_from_arrays` holds the whole scene to), else a one-line
    error naming its node: a world transform each of whose factors is legal may still place the positions
    past float64 or past what the G-buffers hold."""
    reach = float(np.abs(world).max()) if np.isfinite(world).all() else math.inf
    if reach > MAX_COORDINATE:
        where = f"{path.name} {gltf_label('node', p.node, doc['nodes'][p.node])}"
        where += "" if p.written else f" instance {p.instance}"
        what = f"{gltf_label('mesh', p.mesh, doc['meshes'][p.mesh])} primitive {p.primitive}"
        up_to = f"up to {reach:.3g}" if math.isfinite(reach) else "past float64's range"
        raise NeuralaoError(
            f"{where}: its world transform places {what} at coordinates {up_to}; a scene's coordinates lie "
            f"within +-{MAX_COORDINATE:g} (float32 G-buffers and ray distances overflow past it): scale it "
            "down"
        )


def _world_scene(pieces: list[Piece], path: Path, doc: dict) -> Scene:
    """Every piece's used vertices in world space, one :class:`Scene` (sets ``Piece.v0``)."""
    verts, faces, nv = [], [], 0
    for p in pieces:
        remap = np.full(len(p.vertices), -1, np.int64)
        remap[p.used] = np.arange(len(p.used))
        f = remap[p.faces] + nv
        with np.errstate(over="ignore", invalid="ignore"):  # past float64: refused next, naming the node
            world = p.world_vertices()[p.used]
        _check_placed(world, p, path, doc)
        verts.append(world)
        faces.append(f[:, ::-1] if p.mirrored else f)  # glTF: a negative determinant flips the front face
        p.v0 = nv
        nv += len(p.used)
    return scene_from_arrays(np.concatenate(verts), np.concatenate(faces), path.stem, str(path))


# --------------------------------------------------------------------------- baking


def vertex_ao(gs: GltfScene, world_ao: np.ndarray) -> list[np.ndarray]:
    """Per piece (n,) float32 AO of every primitive vertex from the world scene's per-vertex AO
    (vertices no triangle uses get 1: they are never drawn)."""
    out = []
    for p in gs.pieces:
        ao = np.ones(len(p.vertices), np.float32)
        ao[p.used] = world_ao[p.v0 : p.v0 + len(p.used)]
        out.append(ao)
    return out


@dataclass
class Layout:
    """The UVs an AO map of one primitive is baked on.

    uv       : (n', 2) float64 in [0, 1], trimesh convention (v up)
    faces    : (m, 3) int64 into ``uv``
    vmap     : (n',) int64 primitive vertex of each UV vertex, or None (the primitive's own TEXCOORD_0)
    texcoord : the TEXCOORD_n set the map reads
    """

    uv: np.ndarray
    faces: np.ndarray
    vmap: np.ndarray | None
    texcoord: int


def primitive_layout(gs: GltfScene, piece: Piece, settings) -> Layout:
    """Own UVs when usable (``settings.uv``: auto / mesh / xatlas; neuralao.pipeline.bakes.texture), else
    xatlas."""
    prim = gs.doc["meshes"][piece.mesh]["primitives"][piece.primitive]
    attrs = prim.get("attributes", {})
    where = f"{gltf_label('mesh', piece.mesh, gs.doc['meshes'][piece.mesh])} primitive {piece.primitive}"
    why = "it has no TEXCOORD_0"
    if settings.uv != "xatlas" and "TEXCOORD_0" in attrs:
        st = np.asarray(gs.gltf.accessor(attrs["TEXCOORD_0"], where), np.float64)
        uv = np.c_[st[:, 0], 1.0 - st[:, 1]] if st.ndim == 2 and st.shape[1] == 2 else None
        if uv is None or len(uv) != len(piece.vertices) or not np.isfinite(uv).all():
            why = "its TEXCOORD_0 is not one finite VEC2 per vertex"
        elif uv.min() < -UV_RANGE_SLACK or uv.max() > 1 + UV_RANGE_SLACK:
            why = "its UVs leave [0, 1] (tiling)"
        else:
            uv = np.clip(uv, 0.0, 1.0)
            overlap = rasterise(uv, piece.faces, settings.resolution).overlap
            if overlap <= OVERLAP_LIMIT:
                return Layout(uv, piece.faces, None, 0)
            why = f"its UVs overlap ({100 * overlap:.1f}% of texels)"
    if settings.uv == "mesh":
        raise NeuralaoError(f"--uv mesh: cannot use the UVs of {where}: {why}")
    if settings.uv == "auto":
        log.info("%s: generating lightmap UVs with xatlas (%s)", where, why)
    vmap, faces, uv = xatlas_layout(piece.vertices, piece.faces, settings.resolution, settings.margin)
    k = 0
    while f"TEXCOORD_{k}" in attrs:
        k += 1
    return Layout(uv, faces, vmap, k)


def bake_texture_scene(
    gs: GltfScene, settings, progress: bool = False
) -> tuple[list[np.ndarray | None], dict, dict]:
    """AO maps of every written piece (module doc, step 2): images (N, N) float32 per piece (None for
    occluder-only pieces), the layouts per (mesh, primitive), and info (counts, timings)."""
    check_settings(settings)
    n = settings.resolution
    t0 = time.perf_counter()
    layouts: dict[tuple[int, int], Layout] = {}
    texels: dict[tuple[int, int], object] = {}
    points, normals, ids, spans = [], [], [], []
    for i, p in enumerate(gs.pieces):
        if not p.written:
            spans.append(None)
            continue
        key = (p.mesh, p.primitive)
        if key not in layouts:
            layouts[key] = primitive_layout(gs, p, settings)
            texels[key] = rasterise(layouts[key].uv, layouts[key].faces, n)
        lay, tx = layouts[key], texels[key]
        wv = p.world_vertices()
        wv = wv if lay.vmap is None else wv[lay.vmap]
        tri = wv[lay.faces[tx.face]]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        points.append(np.einsum("kc,kcd->kd", tx.bary, tri))
        normals.append(-nrm if p.mirrored else nrm)
        ids.append(i * n * n + tx.pixel)
        spans.append(tx.pixel)
    t1 = time.perf_counter()
    labeller = Labeller(gs.world, settings.label_settings())
    ao, valid = labeller.ao_at_points(
        np.concatenate(points), np.concatenate(normals), progress=progress, ids=np.concatenate(ids)
    )
    t2 = time.perf_counter()
    images: list[np.ndarray | None] = []
    start, covered = 0, 0
    for pixel in spans:
        if pixel is None:
            images.append(None)
            continue
        sl = slice(start, start + len(pixel))
        image, cov = texel_image(n, pixel, ao[sl], valid[sl], settings.margin)
        images.append(image)
        covered += int(cov.sum())
        start += len(pixel)
    if covered == 0:
        raise NeuralaoError(
            f"no texel centre falls inside a UV triangle at resolution {n}; raise --resolution"
        )
    info = {
        "resolution": n,
        "maps": sum(im is not None for im in images),
        "texels_covered": covered,
        "invalid_texels": int((~valid).sum()),
        "rays_traced": int(len(ao)) * settings.rays,
        "uv_sources": {
            f"{m}/{k}": ("mesh" if lay.vmap is None else "xatlas") for (m, k), lay in layouts.items()
        },
        "max_distance": labeller.max_distance,
        "seconds_raster": t1 - t0,
        "seconds_trace": t2 - t1,
        "seconds": time.perf_counter() - t0,
        "settings": settings_to_dict(settings),
    }
    return images, layouts, info


# --------------------------------------------------------------------------- writing


def _merged_writer(gs: GltfScene) -> GltfWriter:
    """A writer on a copy of the document whose buffers are merged into one (buffer 0) and whose
    images are all embedded (bufferViews), so the .glb stands alone wherever it is written."""
    doc = copy.deepcopy(gs.doc)
    blob, offsets = bytearray(), []
    for spec, data in zip(doc.get("buffers", []), gs.gltf.buffers, strict=True):
        while len(blob) % 8:
            blob.append(0)
        offsets.append(len(blob))
        blob.extend(data[: int(spec.get("byteLength", len(data)))])
    for view in doc.get("bufferViews", []):
        view["byteOffset"] = offsets[view.get("buffer", 0)] + int(view.get("byteOffset", 0))
        view["buffer"] = 0
    w = GltfWriter.from_document(doc, bytes(blob))
    for i, image in enumerate(doc.get("images", [])):
        uri = image.get("uri")
        if not isinstance(uri, str):
            continue
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            data = (
                base64.b64decode(payload)
                if head.endswith(";base64")
                else urllib.parse.unquote_to_bytes(payload)
            )
            mime = head[5:].split(";")[0] or None
        else:
            folder = gs.path.parent.resolve()
            source = (folder / urllib.parse.unquote(uri)).resolve()
            if not source.is_relative_to(folder) or not source.is_file():  # never a file outside the folder
                log.warning(
                    "%s: image %d (%s) not found beside the file; its uri is kept", gs.path.name, i, uri
                )
                continue
            data, mime = source.read_bytes(), mimetypes.guess_type(source.name)[0]
        image.pop("uri")
        image["bufferView"] = w.buffer_view(data)
        image["mimeType"] = image.get("mimeType") or mime or "image/png"
    return w


def _instances_by_mesh(gs: GltfScene) -> dict[int, list[tuple[int, int]]]:
    """mesh -> its written (node, instance) keys in scene order."""
    out: dict[int, list[tuple[int, int]]] = {}
    for p in gs.pieces:
        if p.written and (p.node, p.instance) not in out.setdefault(p.mesh, []):
            out[p.mesh].append((p.node, p.instance))
    return out


def _mesh_slots(gs: GltfScene, w: GltfWriter, results: dict[tuple[int, int, int], bytes]) -> dict:
    """Per mesh: groups of its instances with identical results, each with the mesh index it is
    written to (module doc, step 4). Returns {mesh: [(mesh_index, [(node, instance), ...]), ...]}
    and points every node to its group's mesh."""
    doc = w.doc
    unwritten = {p.mesh for p in gs.pieces if not p.written}
    slots = {}
    for mi, keys in _instances_by_mesh(gs).items():
        groups: dict[tuple, list[tuple[int, int]]] = {}
        prims = range(len(gs.doc["meshes"][mi].get("primitives", [])))
        for key in keys:
            groups.setdefault(tuple(results.get((*key, k), b"") for k in prims), []).append(key)
        slots[mi] = []
        for g, members in enumerate(groups.values()):
            target = mi
            # the original entry stays with the first group, unless an occluder-only node keeps it
            if g > 0 or mi in unwritten:
                doc["meshes"].append(copy.deepcopy(gs.doc["meshes"][mi]))
                target = len(doc["meshes"]) - 1
            for node, _ in members:
                doc["nodes"][node]["mesh"] = target
            slots[mi].append((target, members))
    return slots


def write_vertex_scene(
    path: str | Path, gs: GltfScene, world_ao: np.ndarray, info: dict | None = None
) -> Path:
    """Write the scene with per-vertex AO on every primitive (module doc, step 3, ``--to vertex``)."""
    per_piece = vertex_ao(gs, np.asarray(world_ao, np.float32))
    by_key = {
        (p.node, p.instance, p.primitive): ao for p, ao in zip(gs.pieces, per_piece, strict=True) if p.written
    }
    w = _merged_writer(gs)
    for mi, groups in _mesh_slots(gs, w, {k: v.tobytes() for k, v in by_key.items()}).items():
        for target, members in groups:
            node, inst = members[0]
            for k, prim in enumerate(w.doc["meshes"][target].get("primitives", [])):
                ao = by_key.get((node, inst, k))
                if ao is None:
                    continue
                colour = vertex_colours(ao)
                attrs = prim["attributes"]
                if "COLOR_0" in attrs:  # keep the authored vertex colour, darkened by the AO
                    own = np.asarray(gs.gltf.accessor(attrs["COLOR_0"], f"mesh {mi} COLOR_0"), np.float64)
                    rgb = np.clip(own[:, :3] * ao[:, None], 0.0, 1.0)
                    alpha = own[:, 3] if own.shape[1] == 4 else np.ones(len(own))
                    colour = np.rint(np.c_[rgb, alpha] * 255.0).astype(np.uint8)
                attrs["COLOR_0"] = w.accessor(colour, normalized=True, target=_ARRAY_BUFFER)
                attrs[GLB_AO_ATTRIBUTE] = w.accessor(ao.astype(np.float32), target=_ARRAY_BUFFER)
    _describe(w, "vertex", info)
    return w.write(_glb(path))


def write_texture_scene(
    path: str | Path, gs: GltfScene, images: list[np.ndarray | None], layouts: dict, info: dict | None = None
) -> Path:
    """Write the scene with an AO map per primitive as its material's occlusionTexture (module doc,
    step 3, ``--to texture``)."""
    by_key = {
        (p.node, p.instance, p.primitive): quantise(im)
        for p, im in zip(gs.pieces, images, strict=True)
        if im is not None
    }
    w = _merged_writer(gs)
    doc = w.doc
    slots = _mesh_slots(gs, w, {k: v.tobytes() for k, v in by_key.items()})
    first = {target: members[0] for groups in slots.values() for target, members in groups}
    # materials that some primitive keeps as they are (no map for it): never edited in place
    reserved = {
        prim["material"]
        for mi, mesh in enumerate(doc["meshes"])
        for k, prim in enumerate(mesh.get("primitives", []))
        if "material" in prim and (mi not in first or (*first[mi], k) not in by_key)
    }
    doc.setdefault("samplers", []).append(
        {"magFilter": _LINEAR, "minFilter": _LINEAR, "wrapS": _CLAMP, "wrapT": _CLAMP}
    )
    sampler = len(doc["samplers"]) - 1
    remapped: dict[tuple[int, int], dict] = {}
    claimed: set[int] = set()
    for mi, groups in slots.items():
        for target, members in groups:
            node, inst = members[0]
            for k, prim in enumerate(doc["meshes"][target].get("primitives", [])):
                grey = by_key.get((node, inst, k))
                if grey is None:
                    continue
                lay = layouts[(mi, k)]
                if lay.vmap is not None:
                    if (mi, k) not in remapped:
                        remapped[(mi, k)] = _remapped_primitive(gs, w, mi, k, lay)
                    prim.update(copy.deepcopy(remapped[(mi, k)]))
                buf = io.BytesIO()
                Image.fromarray(grey, mode="L").save(buf, format="PNG")
                doc.setdefault("images", []).append(
                    {
                        "bufferView": w.buffer_view(buf.getvalue()),
                        "mimeType": "image/png",
                        "name": f"ao_{doc['nodes'][node].get('name', node)}_{k}",
                    }
                )
                doc.setdefault("textures", []).append({"sampler": sampler, "source": len(doc["images"]) - 1})
                occlusion = {"index": len(doc["textures"]) - 1}
                if lay.texcoord:
                    occlusion["texCoord"] = lay.texcoord
                src = prim.get("material")
                if src is None:
                    material = {
                        "name": "neuralao_ao",
                        "pbrMetallicRoughness": {
                            "baseColorFactor": [1, 1, 1, 1],
                            "metallicFactor": 0.0,
                            "roughnessFactor": 1.0,
                        },
                    }
                else:
                    material = copy.deepcopy(gs.doc["materials"][src])
                material["occlusionTexture"] = occlusion
                if src is not None and src not in reserved and src not in claimed:
                    doc["materials"][src] = material
                    claimed.add(src)
                else:
                    doc.setdefault("materials", []).append(material)
                    prim["material"] = len(doc["materials"]) - 1
    _describe(w, "texture", info)
    return w.write(_glb(path))


def _remapped_primitive(gs: GltfScene, w: GltfWriter, mi: int, k: int, lay: Layout) -> dict:
    """attributes / indices / targets / mode of primitive k of mesh mi split along the atlas seams
    (every attribute gathered through ``lay.vmap``) plus the lightmap set TEXCOORD_n."""
    src = gs.doc["meshes"][mi]["primitives"][k]
    where = f"mesh {mi} primitive {k}"

    def gather(accessor: int) -> int:
        spec = gs.doc["accessors"][accessor]
        raw = gs.gltf.accessor(accessor, where, normalize=False)
        return w.accessor(
            raw[lay.vmap], kind=spec["type"], normalized=bool(spec.get("normalized")), target=_ARRAY_BUFFER
        )

    attrs = {name: gather(a) for name, a in src.get("attributes", {}).items()}
    st = np.c_[lay.uv[:, 0], 1.0 - lay.uv[:, 1]].astype(np.float32)  # glTF: v down
    attrs[f"TEXCOORD_{lay.texcoord}"] = w.accessor(st, target=_ARRAY_BUFFER)
    out = {
        "attributes": attrs,
        "mode": 4,
        "indices": w.accessor(lay.faces.astype(np.uint32).reshape(-1), target=_ELEMENT_ARRAY_BUFFER),
    }
    if "targets" in src:
        out["targets"] = [{name: gather(a) for name, a in t.items()} for t in src["targets"]]
    return out


def _describe(w: GltfWriter, to: str, info: dict | None) -> None:
    asset = w.doc.setdefault("asset", {"version": "2.0"})
    extras = asset.setdefault("extras", {})
    if isinstance(extras, dict):
        extras["neuralao"] = {"bake": "scene", "to": to, **(info or {})}


def _glb(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() != ".glb":
        raise NeuralaoError(f"a scene bake writes a .glb, got {path.name!r}")
    return path
