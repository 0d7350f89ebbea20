"""`neuralao view`: a self-contained static WebGL2 page that shows a mesh with its AO.

    neuralao view INPUT [INPUT ...] [--mesh MESH] --out DIR [--size W H] [--serve [--port P]]

Each INPUT becomes one entry of the page's method switch:

* a **vertex bake** (``neuralao bake ... --out X.ply|X.glb``): per-vertex float AO, interpolated;
* a **texture bake** (``neuralao bake ... --to texture --out X.glb``): the occlusionTexture sampled
  bilinearly (LINEAR, CLAMP_TO_EDGE) at the mesh's TEXCOORD_0, red channel;
* a **scene bake** (``neuralao bake SCENE.gltf|SCENE.glb ... --out X.glb``, pipeline/bakes/gltf_scene.py): every
  node's primitives in world space, each drawn with its material's base colour (factor x texture)
  times its AO (``_AO`` per vertex, or the occlusionTexture on its TEXCOORD set), so the page shows the
  materials the bake kept;
* an **MLP or field export folder** (``neuralao export``): its generated GLSL ES 3.00 fragment shader
  (``glsl/mlp_es300.*``) run unchanged as a full-screen pass over the page's own float G-buffer, with its
  uniform blocks (if any) bound by name as its manifest says. Its mesh is ``--mesh``, else the mesh
  recorded in the export's manifest.

The page (``DIR/index.html`` + ``viewer.js`` + ``scene.js``, no network access, no CDN: plain WebGL2,
no third-party code) draws every frame in three passes:

1. G-buffer: the mesh into RGBA32F targets (``EXT_color_buffer_float``): object-space position
   (w = 1 on the foreground) and the object-space normal (area-weighted vertex normals turned to each
   triangle's side, interpolated, renormalised, negated on back faces: the project's G-buffer
   convention, pipeline/gbuffers/rasterizer.py), plus the AO of the baked methods;
2. AO: for a shader method the generated pass; its input texture named ``position`` in the manifest
   reads the position target, any other (``normal``, the MLP's ``gbuffer``) the normal target (xyz normal, w mask);
3. display: AO as grey on a dark background, to the canvas (a scene bake: base colour x AO, sRGB).

An orbit camera (drag to rotate, wheel to zoom, keys 1-9 pick a method) and, for tests, a small API on
``window.neuralao``: ``setPose(azimuth_deg, elevation_deg, distance_in_diagonals)``, ``setMethod(i)`` and
``capture()``, which renders and returns the float targets (position, normal, AO; bottom row first) as
base64 float32. All data (geometry, textures, shader sources, weights) is inlined as base64 in
``scene.js``, so the page works from ``file://`` as well as over ``--serve``.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.foundation.errors import NeuralaoError
from pipeline.foundation.io import write_text

log = logging.getLogger(__name__)

ASSETS = Path(__file__).resolve().parent / "viewer"
STATIC_FILES = ("index.html", "viewer.js")
FORMAT = "neuralao-viewer"
FORMAT_VERSION = 1


@dataclass
class ViewerMethod:
    """One entry of the method switch.

    positions : (3m, 3) float32 corners of the de-indexed triangles (object space)
    normals   : (3m, 3) float32 vertex normals turned to their triangle's side
    ao        : (3m,) float32 per-corner AO (vertex bakes) or None
    uv        : (3m, 2) float32 glTF UVs (origin top left) or None; texture : PNG bytes or None
    shader    : {"vertex", "fragment", "inputs", "blocks"} of a generated pass, or None
    uv_base   : (3m, 2) float32 glTF UVs of the base colour textures (scene bakes) or None
    parts     : scene bakes: one draw per primitive, {"first", "count", "factor" (RGBA base colour
                factor), "base" / "occlusion" (PNG or JPEG data URIs, or absent)}; None otherwise
    """

    name: str
    kind: str  # vertex | texture | shader
    positions: np.ndarray
    normals: np.ndarray
    ao: np.ndarray | None = None
    uv: np.ndarray | None = None
    texture: bytes | None = None
    shader: dict | None = None
    info: dict = field(default_factory=dict)
    uv_base: np.ndarray | None = None
    parts: list[dict] | None = None


# --------------------------------------------------------------------------- geometry


def corner_arrays(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """De-indexed corners (3m, 3) float32 and their normals (3m, 3) float32 (module doc, pass 1)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    t = v[f]
    fn = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])  # area weighted
    vn = np.zeros_like(v)
    for k in range(3):
        np.add.at(vn, f[:, k], fn)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
    corner_n = vn[f]  # (m, 3, 3)
    side = np.sign(np.einsum("mkd,md->mk", corner_n, fn))
    corner_n = corner_n * np.where(side < 0, -1.0, 1.0)[..., None]
    unit_fn = fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    zero = np.linalg.norm(corner_n, axis=2) < 1e-12
    corner_n[zero] = np.broadcast_to(unit_fn[:, None, :], corner_n.shape)[zero]
    return t.reshape(-1, 3).astype(np.float32), corner_n.reshape(-1, 3).astype(np.float32)


# --------------------------------------------------------------------------- inputs


def method_from_bake(path: Path) -> ViewerMethod:
    """A vertex bake (.ply/.glb with float AO) or a texture bake (.glb with an occlusionTexture)."""
    from pipeline.bakes.texture import read_texture_glb
    from pipeline.bakes.vertex import read_baked_mesh

    if path.suffix.lower() == ".glb":
        if _is_scene_bake(path):
            return method_from_scene_bake(path)
        try:
            mesh, red = read_texture_glb(path)
        except NeuralaoError:
            mesh = None
        if mesh is not None:
            import io

            from PIL import Image

            pos, nrm = corner_arrays(mesh.vertices, mesh.faces)
            uv = mesh.uv[mesh.faces].reshape(-1, 2)
            uv_gltf = np.c_[uv[:, 0], 1.0 - uv[:, 1]].astype(np.float32)
            buf = io.BytesIO()
            Image.fromarray(np.rint(red * 255).astype(np.uint8), mode="L").save(buf, format="PNG")
            return ViewerMethod(f"texture bake {red.shape[1]}x{red.shape[0]} ({path.name})", "texture", pos, nrm,
                                uv=uv_gltf, texture=buf.getvalue())  # fmt: skip
    vertices, faces, ao, _ = read_baked_mesh(path)
    pos, nrm = corner_arrays(vertices, faces)
    return ViewerMethod(
        f"vertex bake ({path.name})", "vertex", pos, nrm, ao=ao[faces].reshape(-1).astype(np.float32)
    )


def _is_scene_bake(path: Path) -> bool:
    """Whether a .glb's JSON says it is a scene bake (``asset.extras.neuralao.bake == "scene"``)."""
    import struct

    with open(path, "rb") as f:
        head = f.read(20)
        if len(head) < 20 or head[:4] != b"glTF":
            return False
        try:
            doc = json.loads(f.read(struct.unpack_from("<I", head, 12)[0]))
        except (json.JSONDecodeError, UnicodeDecodeError):
            return False
    extras = doc.get("asset", {}).get("extras", {}) if isinstance(doc, dict) else {}
    return (
        isinstance(extras, dict)
        and isinstance(extras.get("neuralao"), dict)
        and extras["neuralao"].get("bake") == "scene"
    )


def method_from_scene_bake(path: Path) -> ViewerMethod:
    """A scene bake: one part per primitive of every written node, in world space (module doc)."""
    from pipeline.bakes.gltf_scene import read_gltf_scene

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
        for key, slot, out in (("occlusion", material.get("occlusionTexture"), uv),
                               ("base", pbr.get("baseColorTexture"), uv_base)):  # fmt: skip
            if slot is not None:
                part[key] = _texture_uri(gs, slot["index"])
                out[-1] = _corners(gs, attrs, f"TEXCOORD_{slot.get('texCoord', 0)}", faces, 2, 0.0)
        pos.append(a)
        nrm.append(n)
        parts.append(part)
    return ViewerMethod(
        f"scene {to} bake, {len(parts)} primitives ({path.name})", "scene", np.concatenate(pos), np.concatenate(nrm),
        ao=np.concatenate(ao), uv=np.concatenate(uv), uv_base=np.concatenate(uv_base), parts=parts,
        info={"bake": str(path), "to": to},
    )  # fmt: skip


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
    return f"data:{image.get('mimeType', 'image/png')};base64," + _b64(data)


def method_from_export(folder: Path, mesh: str | None) -> ViewerMethod:
    """An MLP or field export: its ES 3.00 fragment pass, on ``mesh`` (default: the export's own mesh)."""
    from export.glsl.files import load_mlp_export
    from pipeline.geometry.scene import load_scene

    try:
        top = json.loads((folder / "manifest.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        raise NeuralaoError(f"{folder} is not an export folder (no readable manifest.json)") from None
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
        {"sampler": i["sampler"], "unit": int(i["unit"]), "source": "position" if i["texture"] == "position" else "normal"}
        for i in manifest["passes"][0]["inputs"]
    ]  # fmt: skip
    blocks = [
        {"name": name, "binding": int(binding), "data": _b64(np.ascontiguousarray(arr, "<f4").tobytes())}
        for name, binding, arr in shader.uniform_blocks
    ]
    kind = manifest.get("kind") or top.get("kind") or "mlp"
    size = top.get("model_size") or top.get("size") or ""
    return ViewerMethod(
        f"{kind} {size} ES 3.00 shader ({folder.name})".replace("  ", " "), "shader", pos, nrm,
        shader={"vertex": shader.vertex_source, "fragment": shader.fragment_source, "inputs": inputs,
                "blocks": blocks},
        info={"export": str(folder), "mesh": str(mesh_path), "onnx": str(folder / "model.onnx")},
    )  # fmt: skip


def load_method(path: str, mesh: str | None) -> ViewerMethod:
    p = Path(path)
    if p.is_dir():
        return method_from_export(p, mesh)
    if not p.exists():
        raise NeuralaoError(f"no such file or folder: {path}")
    if p.suffix.lower() not in (".ply", ".glb"):
        raise NeuralaoError(f"{p.name}: expected a bake (.ply/.glb) or an export folder")
    return method_from_bake(p)


# --------------------------------------------------------------------------- page


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def scene_payload(methods: list[ViewerMethod], size: tuple[int, int]) -> dict:
    """The page's data (scene.js): meshes (shared by the methods on them) and methods as base64 float32,
    the framing bounds, the canvas size."""
    allpos = np.concatenate([m.positions for m in methods])
    lo, hi = allpos.min(axis=0).astype(np.float64), allpos.max(axis=0).astype(np.float64)
    out, geometries, index = [], [], {}
    for m in methods:
        pos, nrm = m.positions.astype("<f4").tobytes(), m.normals.astype("<f4").tobytes()
        key = hashlib.sha256(pos + nrm).hexdigest()
        if key not in index:  # methods on the same mesh share one copy of it
            index[key] = len(geometries)
            geometries.append({"count": len(m.positions), "positions": _b64(pos), "normals": _b64(nrm)})
        e = {"name": m.name, "kind": m.kind, "geometry": index[key]}
        if m.ao is not None:
            e["ao"] = _b64(m.ao.astype("<f4").tobytes())
        if m.uv is not None:
            e["uv"] = _b64(m.uv.astype("<f4").tobytes())
        if m.texture is not None:
            e["texture"] = "data:image/png;base64," + _b64(m.texture)
        if m.parts is not None:
            e["parts"] = m.parts
            e["uv_base"] = _b64(m.uv_base.astype("<f4").tobytes())
        if m.shader is not None:
            e["shader"] = m.shader
        e["info"] = m.info
        out.append(e)
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "methods": out, "geometries": geometries,
            "bounds": [lo.tolist(), hi.tolist()], "size": [int(size[0]), int(size[1])]}  # fmt: skip


def write_page(methods: list[ViewerMethod], out: Path, size: tuple[int, int] = (640, 480)) -> Path:
    """index.html + viewer.js (static, from runtime/viewer/) + scene.js (the data); returns index.html."""
    if not methods:
        raise NeuralaoError("nothing to view")
    out.mkdir(parents=True, exist_ok=True)
    payload = scene_payload(methods, size)
    write_text(out / "scene.js", "window.NEURALAO_SCENE = " + json.dumps(payload) + ";\n")
    for name in STATIC_FILES:
        write_text(out / name, (ASSETS / name).read_text())
    write_text(out / "scene.json", json.dumps({k: v for k, v in payload.items() if k not in ("methods", "geometries")} |
                                              {"methods": [{"name": m.name, "kind": m.kind, **m.info} for m in methods]},
                                              indent=2) + "\n")  # fmt: skip
    return out / "index.html"


def serve(folder: Path, port: int) -> None:
    """Serve ``folder`` on http://127.0.0.1:PORT until interrupted."""
    import functools
    import http.server

    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(folder))
    with http.server.ThreadingHTTPServer(("127.0.0.1", port), handler) as httpd:
        log.info(
            "serving %s on http://127.0.0.1:%d/index.html (Ctrl-C stops)", folder, httpd.server_address[1]
        )
        httpd.serve_forever()


# --------------------------------------------------------------------------- command line


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("inputs", nargs="+", metavar="EXPORT_OR_BAKE",
                   help="vertex bakes (.ply/.glb), texture bakes (.glb), scene bakes (.glb) and MLP / field export folders: one method each")  # fmt: skip
    p.add_argument("--mesh", help="mesh of the export folders (default: the mesh each export records)")
    p.add_argument("--out", required=True, help="output folder: index.html, viewer.js, scene.js, scene.json")
    p.add_argument("--size", type=int, nargs=2, default=[640, 480], metavar=("W", "H"),
                   help="canvas size in pixels (default 640 480)")  # fmt: skip
    p.add_argument("--serve", action="store_true", help="serve the page on http://127.0.0.1:PORT afterwards")
    p.add_argument(
        "--port", type=int, default=8000, help="port for --serve (default 8000; 0 = any free port)"
    )


def run(args: argparse.Namespace) -> int:
    w, h = args.size
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise NeuralaoError(f"--size must be in 1..8192, got {w} {h}")
    if not 0 <= args.port <= 65535:
        raise NeuralaoError(f"--port must be in 0..65535, got {args.port}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise NeuralaoError(f"--out {out} is a file")
    methods = [load_method(i, args.mesh) for i in args.inputs]
    page = write_page(methods, out, (w, h))
    log.info("viewer: %d method(s) -> %s", len(methods), page)
    if args.serve:
        serve(out, args.port)
    return 0
