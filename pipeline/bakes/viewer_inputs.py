"""What ``neuralao view`` shows, read from bakes and exports: one
:class:`neuralao.runtime.viewer.ViewerMethod` per vertex bake (.ply/.glb), texture bake (.glb), scene bake
(.glb) or MLP / field export folder.

These readers live with the bakers, not in :mod:`neuralao.runtime.viewer`: they read bakes with the bakers'
own readers (trimesh-based) and load the export's mesh
(:func:`neuralao.pipeline.geometry.scene.load_scene`), which a consumer that only writes the page from
arrays does not need.
"""

from __future__ import annotations

import io
import struct
from pathlib import Path

import numpy as np
from PIL import Image

from neuralao.export.glsl import load_compute_export, load_mlp_export
from neuralao.pipeline.bakes.gltf_scene import read_gltf_scene
from neuralao.pipeline.bakes.texture import read_texture_glb
from neuralao.pipeline.bakes.vertex import read_baked_mesh
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.manifest import parse_json, read_manifest
from neuralao.runtime.frame_runner import frame_program
from neuralao.runtime.onnx_io import load_onnx
from neuralao.runtime.predict import check_unet_onnx
from neuralao.runtime.shipped import default_export, shipped_models
from neuralao.runtime.viewer import ViewerMethod, b64, corner_arrays


def method_from_bake(path: Path) -> ViewerMethod:
    """A vertex bake (.ply/.glb with float AO) or a texture bake (.glb with an occlusionTexture)."""
    if path.suffix.lower() == ".glb":
        if _is_scene_bake(path):
            return method_from_scene_bake(path)
        try:
            mesh, red = read_texture_glb(path)
        except NeuralaoError:
            mesh = None
        if mesh is not None:
            pos, nrm = corner_arrays(mesh.vertices, mesh.faces)
            uv = mesh.uv[mesh.faces].reshape(-1, 2)
            uv_gltf = np.c_[uv[:, 0], 1.0 - uv[:, 1]].astype(np.float32)
            buf = io.BytesIO()
            Image.fromarray(np.rint(red * 255).astype(np.uint8), mode="L").save(buf, format="PNG")
            return ViewerMethod(
                f"texture bake {red.shape[1]}x{red.shape[0]} ({path.name})",
                "texture",
                pos,
                nrm,
                uv=uv_gltf,
                texture=buf.getvalue(),
            )
    vertices, faces, ao, _ = read_baked_mesh(path)
    pos, nrm = corner_arrays(vertices, faces)
    return ViewerMethod(
        f"vertex bake ({path.name})", "vertex", pos, nrm, ao=ao[faces].reshape(-1).astype(np.float32)
    )


def _is_scene_bake(path: Path) -> bool:
    """Whether a .glb's JSON says it is a scene bake (``asset.extras.neuralao.bake == "scene"``)."""
    with open(path, "rb") as f:
        head = f.read(20)
        if len(head) < 20 or head[:4] != b"glTF":
            return False
        try:
            doc = parse_json(f.read(struct.unpack_from("<I", head, 12)[0]), path, "GLB JSON chunk")
        except NeuralaoError:
            return False
    extras = doc.get("asset", {}).get("extras", {}) if isinstance(doc, dict) else {}
    return (
        isinstance(extras, dict)
        and isinstance(extras.get("neuralao"), dict)
        and extras["neuralao"].get("bake") == "scene"
    )


def method_from_scene_bake(path: Path) -> ViewerMethod:
    """A scene bake: one part per primitive of every written node, in world space (module doc)."""
    gs = read_gltf_scene(path)
    doc, to = gs.doc, gs.doc["asset"]["extras"]["neuralao"].get("to", "vertex")
    pos, nrm, ao, uv, uv_base, parts = [], [], [], [], [], []
    for p in (p for p in gs.pieces if p.written):
        prim = doc["meshes"][p.mesh]["primitives"][p.primitive]
        attrs = prim["attributes"]
        faces = p.faces[:, ::-1] if p.mirrored else p.faces  # front faces as glTF defines them
        a, n = corner_arrays(p.world_vertices(), faces)
        material = doc.get("materials", [])[prim["material"]] if "material" in prim else {}
        pbr = material.get("pbrMetallicRoughness", {})
        part = {
            "first": sum(len(x) for x in pos),
            "count": len(a),
            "factor": pbr.get("baseColorFactor", [1.0] * 4),
        }
        ao.append(_corners(gs, attrs, "_AO", faces, 1, 1.0)[:, 0])
        uv.append(np.zeros((len(a), 2), np.float32))
        uv_base.append(np.zeros((len(a), 2), np.float32))
        for key, slot, out in (
            ("occlusion", material.get("occlusionTexture"), uv),
            ("base", pbr.get("baseColorTexture"), uv_base),
        ):
            if slot is not None:
                part[key] = _texture_uri(gs, slot["index"])
                out[-1] = _corners(gs, attrs, f"TEXCOORD_{slot.get('texCoord', 0)}", faces, 2, 0.0)
        pos.append(a)
        nrm.append(n)
        parts.append(part)
    return ViewerMethod(
        f"scene {to} bake, {len(parts)} primitives ({path.name})",
        "scene",
        np.concatenate(pos),
        np.concatenate(nrm),
        ao=np.concatenate(ao),
        uv=np.concatenate(uv),
        uv_base=np.concatenate(uv_base),
        parts=parts,
        info={"bake": str(path), "to": to},
    )


def _corners(gs, attrs: dict, name: str, faces: np.ndarray, width: int, default: float) -> np.ndarray:
    """(3m, width) float32 attribute ``name`` at the corners of ``faces`` (m, 3), or ``default``."""
    if name not in attrs:
        return np.full((3 * len(faces), width), default, np.float32)
    values = np.asarray(gs.gltf.accessor(attrs[name], f"{gs.path.name} {name}"), np.float32)
    return values[faces].reshape(-1, width)


def _texture_uri(gs, texture: int) -> str:
    """A data URI of texture ``texture``'s image (embedded in a bufferView or a data URI)."""
    image = gs.doc["images"][gs.doc["textures"][texture]["source"]]
    if "uri" in image:
        if not image["uri"].startswith("data:"):
            raise NeuralaoError(f"{gs.path.name}: image {image['uri']!r} is not embedded")
        return image["uri"]
    view = gs.doc["bufferViews"][image["bufferView"]]
    start = int(view.get("byteOffset", 0))
    data = gs.gltf.buffers[view.get("buffer", 0)][start : start + int(view["byteLength"])]
    return f"data:{image.get('mimeType', 'image/png')};base64," + b64(data)


def method_from_export(folder: Path, mesh: str | None) -> ViewerMethod:
    """An MLP or field export: its ES 3.00 fragment pass, on ``mesh`` (default: the export's own mesh)."""
    if not (folder / "manifest.json").is_file():
        raise NeuralaoError(f"{folder} is not an export folder (no manifest.json)")
    top = read_manifest(folder)
    glsl_dir = folder / "glsl"
    if not (glsl_dir / "manifest.json").exists():
        raise NeuralaoError(
            f"{folder} has no glsl/ fragment export (only MLP and field exports can be viewed)"
        )
    shader = load_mlp_export(glsl_dir, dialect="es300")
    manifest = shader.manifest
    mesh_path = mesh or top.get("mesh") or manifest.get("source_model_metadata", {}).get("training_mesh")
    if not mesh_path:
        raise NeuralaoError(f"{folder}: no mesh recorded in the export; pass --mesh")
    scene = load_scene(mesh_path)
    pos, nrm = corner_arrays(scene.vertices, scene.faces)
    inputs = [
        {
            "sampler": i["sampler"],
            "unit": int(i["unit"]),
            "source": "position" if i["texture"] == "position" else "normal",
        }
        for i in manifest["passes"][0]["inputs"]
    ]
    blocks = [
        {"name": name, "binding": int(binding), "data": b64(np.ascontiguousarray(arr, "<f4").tobytes())}
        for name, binding, arr in shader.uniform_blocks
    ]
    kind = manifest.get("kind") or top.get("kind") or "mlp"
    size = top.get("model_size") or top.get("size") or ""
    return ViewerMethod(
        f"{kind} {size} ES 3.00 shader ({folder.name})".replace("  ", " "),
        "shader",
        pos,
        nrm,
        shader={
            "vertex": shader.vertex_source,
            "fragment": shader.fragment_source,
            "inputs": inputs,
            "blocks": blocks,
        },
        info={"export": str(folder), "mesh": str(mesh_path), "onnx": str(folder / "model.onnx")},
    )


def load_method(path: str, mesh: str | None) -> ViewerMethod:
    p = Path(path)
    if p.is_dir():
        return method_from_export(p, mesh)
    if not p.exists():
        raise NeuralaoError(f"no such file or folder: {path}")
    if p.suffix.lower() not in (".ply", ".glb"):
        raise NeuralaoError(f"{p.name}: expected a bake (.ply/.glb) or an export folder")
    return method_from_bake(p)


# ----------------------------------------------------------------------------- screen-space U-Net

# Default AO radius of the screen-space U-Net, as a fraction of the mesh's bounding-box diagonal (the
# unit of the training labels' radii_rel, 1/32 to 1/4: pipeline/datasets/dataset.py).
SCREEN_SPACE_RADIUS_REL = 0.125


def _unet_meta(folder: Path) -> dict:
    """ONNX metadata of the U-Net export in ``folder`` (checked: a U-Net, this preprocessing)."""
    path = folder / read_manifest(folder).get("onnx", "model.onnx")
    return check_unet_onnx(load_onnx(path), path)


def _screen_space_folder(model: str | None) -> Path:
    if model is None:
        return default_export("unet")
    if Path(model).is_dir():
        return Path(model)
    models = shipped_models()
    if model not in models:
        raise NeuralaoError(
            f"--screen-space {model}: not an export folder nor a shipped model ({', '.join(sorted(models))})"
        )
    return models[model]


def method_from_unet(
    model: str | None,
    positions: np.ndarray,
    normals: np.ndarray,
    radius_rel: float = SCREEN_SPACE_RADIUS_REL,
    conv_block: tuple[int, int, int] | None = None,
) -> ViewerMethod:
    """A screen-space U-Net (an export folder or a shipped model's name; None: the default shipped one,
    a hybrid) whose whole frame the page runs in WebGPU on the mesh ``positions`` / ``normals`` (3m, 3)
    float32 (corner_arrays).

    Its WGSL: the export's ``wgsl/`` folder if it has one with frame passes and ``conv_block`` is None,
    else the network generated from model.onnx (``conv_block`` None: the generator's default) with its
    frame passes (GTAO for a hybrid, resampling, the input contract, upsampling).
    """
    folder = _screen_space_folder(model)
    _unet_meta(folder)
    if not (np.isfinite(radius_rel) and radius_rel > 0):
        raise NeuralaoError(f"--screen-space-radius must be a positive fraction, got {radius_rel}")
    onnx_path = folder / read_manifest(folder).get("onnx", "model.onnx")
    wgsl = folder / "wgsl"
    if conv_block is None and (wgsl / "manifest.json").is_file() and "frame" in read_manifest(wgsl):
        program = load_compute_export(wgsl)
    else:
        block = {} if conv_block is None else {"conv_block": tuple(conv_block)}
        program = frame_program(load_onnx(onnx_path), "wgsl", **block)
    diagonal = float(np.linalg.norm(np.ptp(np.asarray(positions, np.float64), axis=0)))
    radius = radius_rel * diagonal
    network = {
        "manifest": program.manifest,
        "sources": program.sources,
        "weights": b64(program.weights),
        "radius": radius,
        "model": folder.name,
    }
    return ViewerMethod(
        f"screen-space U-Net {folder.name} (WebGPU)",
        "screen-space",
        positions,
        normals,
        network=network,
        info={"export": str(folder), "onnx": str(onnx_path), "radius": radius, "radius_rel": radius_rel},
    )


def screen_space_mesh(methods: list[ViewerMethod], mesh: str | None) -> tuple[np.ndarray, np.ndarray]:
    """The mesh the U-Net's page draws: ``mesh`` if given, else the first method's."""
    if mesh is not None:
        scene = load_scene(mesh)
        return corner_arrays(scene.vertices, scene.faces)
    if not methods:
        raise NeuralaoError("--screen-space needs a mesh: give a bake, an export or --mesh")
    return methods[0].positions, methods[0].normals
