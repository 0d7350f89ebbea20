"""`neuralao view`: a self-contained static WebGL2 page that shows a mesh with its AO.

    neuralao view INPUT [INPUT ...] [--mesh MESH] --out DIR [--size W H] [--serve [--port P]]

Each INPUT becomes one entry of the page's method switch:

* a **vertex bake** (``neuralao bake ... --out X.ply|X.glb``): per-vertex float AO, interpolated;
* a **texture bake** (``neuralao bake ... --to texture --out X.glb``): the occlusionTexture sampled
  bilinearly (LINEAR, CLAMP_TO_EDGE) at the mesh's TEXCOORD_0, red channel;
* a **scene bake** (``neuralao bake SCENE.gltf|SCENE.glb ... --out X.glb``, pipeline/bakes/gltf_scene.py):
  every node's primitives in world space, each drawn with its material's base colour (factor x texture)
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
   reads the position target, any other (``normal``, the MLP's ``gbuffer``) the normal target
   (xyz normal, w mask); for a **screen-space U-Net** (``neuralao view --screen-space``) a camera-space
   G-buffer (position, -z = linear depth, w mask; camera-space normal, as pipeline/gbuffers/rasterizer.py)
   is read back, its depth and normal uploaded to WebGPU, and the export's whole frame (``wgsl.js``
   ``runFrame``: the manifest's ``frame.steps``, GTAO for a hybrid, point sampling to the internal height,
   the input contract, the network, upsampling) runs there, as runtime/frame_runner.py does through
   wgpu; asynchronous: a frame shows the latest finished AO. Without WebGPU the page says so and the
   other methods still work;
3. display: AO as grey on a dark background, to the canvas (a scene bake: base colour x AO, sRGB).

An orbit camera (drag to rotate, wheel to zoom, keys 1-9 pick a method) and, for tests, a small API on
``window.neuralao``: ``setPose(azimuth_deg, elevation_deg, distance_in_diagonals)``, ``setMethod(i)`` and
``capture()``, which renders and returns the float targets (position, normal, AO; bottom row first) as
base64 float32, ``captureNetwork()``, a promise of the U-Net's camera-space G-buffer and AO, and
``readNetworkTexture(id)``, a promise of any texture of its latest frame (e.g. ``gtao``). All
data (geometry, textures, shader sources, weights) is inlined as base64 in
``scene.js``, so the page works from ``file://`` as well as over ``--serve``.
"""

from __future__ import annotations

import base64
import functools
import hashlib
import http.server
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_text

log = logging.getLogger(__name__)

ASSETS = Path(__file__).resolve().parent / "viewer"
STATIC_FILES = ("index.html", "viewer.js", "wgsl.js")
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
    network   : screen-space U-Nets: {"manifest", "sources" (a WGSL compute export with frame passes),
                "weights" (base64), "radius" (scene units), "model"}; None otherwise
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
    network: dict | None = None


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


# --------------------------------------------------------------------------- page


def b64(data: bytes) -> str:
    """Base64 text of ``data`` (how the page embeds binary arrays and images)."""
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
            geometries.append({"count": len(m.positions), "positions": b64(pos), "normals": b64(nrm)})
        e = {"name": m.name, "kind": m.kind, "geometry": index[key]}
        if m.ao is not None:
            e["ao"] = b64(m.ao.astype("<f4").tobytes())
        if m.uv is not None:
            e["uv"] = b64(m.uv.astype("<f4").tobytes())
        if m.texture is not None:
            e["texture"] = "data:image/png;base64," + b64(m.texture)
        if m.parts is not None:
            e["parts"] = m.parts
            e["uv_base"] = b64(m.uv_base.astype("<f4").tobytes())
        if m.shader is not None:
            e["shader"] = m.shader
        if m.network is not None:
            e["network"] = m.network
        e["info"] = m.info
        out.append(e)
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "methods": out,
        "geometries": geometries,
        "bounds": [lo.tolist(), hi.tolist()],
        "size": [int(size[0]), int(size[1])],
    }


def write_page(methods: list[ViewerMethod], out: Path, size: tuple[int, int] = (640, 480)) -> Path:
    """index.html + viewer.js (static, from runtime/viewer/) + scene.js (the data); returns index.html."""
    if not methods:
        raise NeuralaoError("nothing to view")
    out.mkdir(parents=True, exist_ok=True)
    payload = scene_payload(methods, size)
    write_text(out / "scene.js", "window.NEURALAO_SCENE = " + json.dumps(payload) + ";\n")
    for name in STATIC_FILES:
        write_text(out / name, (ASSETS / name).read_text())
    write_text(
        out / "scene.json",
        json.dumps(
            {k: v for k, v in payload.items() if k not in ("methods", "geometries")}
            | {"methods": [{"name": m.name, "kind": m.kind, **m.info} for m in methods]},
            indent=2,
        )
        + "\n",
    )
    return out / "index.html"


def serve(folder: Path, port: int) -> None:
    """Serve ``folder`` on http://127.0.0.1:PORT until interrupted."""
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(folder))
    with http.server.ThreadingHTTPServer(("127.0.0.1", port), handler) as httpd:
        log.info(
            "serving %s on http://127.0.0.1:%d/index.html (Ctrl-C stops)", folder, httpd.server_address[1]
        )
        httpd.serve_forever()
