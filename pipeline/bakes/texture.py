"""`neuralao bake MESH --to texture`: AO texture maps (the glTF ``occlusionTexture`` slot).

Steps
-----
1. **UVs.** The mesh's own UVs when it is one textured geometry whose UVs lie in [0, 1] and do not
   overlap (``--uv auto`` checks both; ``--uv mesh`` insists on them), otherwise a fresh atlas from
   xatlas (``--uv xatlas``): charts packed at the bake resolution with ``margin`` texels of padding,
   so the gutters have room.
2. **Texels to surface points.** Every UV triangle is rasterised on the texel grid: a texel whose
   *centre* lies inside a triangle (barycentric coordinates >= 0) maps to the surface point with the
   same barycentric coordinates on the 3-D triangle, with the triangle's geometric normal. A texel
   covered by several triangles (shared edges) takes the one it lies deepest inside.
3. **Labels.** Those points go through the project's Embree labeller
   (:class:`neuralao.pipeline.tracing.labeller.Labeller`: cosine-weighted rays, the back-face rule, the
   origin offset relative to the diagonal), seeded by texel index, so a texel's value never depends on the
   batch it is traced in.
4. **Holes and gutters.** Texels that are covered but invalid (back-face rule: inside geometry) and
   the uncovered texels within ``margin`` of a covered one are filled by repeated 8-neighbour
   averaging from the valid texels (dilation). Without the gutter, bilinear filtering and mip-maps
   near a chart edge mix in the background; with it they mix in the chart's own values.
5. **Files.** ``OUT.glb``: the mesh with TEXCOORD_0 and a PBR material whose ``occlusionTexture`` is the
   AO map (8-bit PNG; grey, so AO is in the red channel as glTF 2.0 reads it). With the mesh's own UVs
   the mesh's material (base colour, textures, factors) is kept and only the occlusion slot is set; with
   an xatlas atlas the UV-dependent textures of the source would be wrong, so only its factors are kept
   (a warning says so). ``OUT.ao.png`` beside it: the same image on its own.

Image conventions: row 0 at the top, texel (r, c) has its centre at u = (c + 0.5) / N,
v = 1 - (r + 0.5) / N in trimesh's UV convention (origin bottom left; trimesh flips V to and from
glTF's top-left origin), so the PNG is the image a glTF viewer samples.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import xatlas
from PIL import Image

from neuralao.pipeline.geometry.gltf import check_gltf
from neuralao.pipeline.geometry.scene import Scene, load_scene, resolve_mesh_path, scene_from_arrays
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_path
from neuralao.runtime.foundation.limits import SAMPLE_BYTES, check_count
from neuralao.runtime.foundation.settings import settings_to_dict

log = logging.getLogger(__name__)

# Candidate (triangle, texel) pairs tested per rasterisation block: bounds the memory of the
# vectorised barycentric test (~100 bytes a pair) whatever the triangle sizes.
_RASTER_BLOCK = 1 << 21
# A texel is "strictly inside" a triangle when every barycentric coordinate exceeds this; two
# triangles holding one texel strictly means the UV charts overlap (shared edges do not count).
_INSIDE_STRICT = 1e-6
# Fraction of covered texels that may be held strictly by two triangles before ``--uv auto``
# decides the mesh's UVs overlap (mirrored or reused UV islands) and generates an atlas instead.
OVERLAP_LIMIT = 0.005
# Slack on the [0, 1] UV range (float noise in exported files) before UVs count as tiling.
UV_RANGE_SLACK = 1e-6


@dataclass
class TextureBakeSettings:
    # Texture width = height in texels.
    resolution: int = 512
    # Gutter: uncovered texels within this many texels of a chart are dilated (also xatlas padding).
    margin: int = 4
    # "auto": the mesh's UVs when usable, else xatlas; "mesh": the mesh's UVs or an error; "xatlas".
    uv: Literal["auto", "mesh", "xatlas"] = "auto"
    # Rays per texel (cosine-weighted hemisphere, as the labeller).
    rays: int = 256
    # Longest AO ray in scene units; None -> max_distance_rel * diagonal.
    max_distance: float | None = None
    # Default max distance as a fraction of the bounding-box diagonal.
    max_distance_rel: float = 0.25
    # "binary" or "obscurance" (Sloan et al. 2013 rho(d)).
    kernel: Literal["binary", "obscurance"] = "binary"
    # Obscurance half distance, scene units; None -> half_distance_rel * diagonal.
    half_distance: float | None = None
    # Default half distance as a fraction of the diagonal.
    half_distance_rel: float = 0.05
    # Back-face rule threshold (Sloan et al.: 0.25); None disables it.
    backface_threshold: float | None = 0.25
    # Seed of the ray directions (and of nothing else: texel positions are fixed).
    seed: int = 0
    # Tracing threads.
    workers: int = 2

    def label_settings(self) -> LabelSettings:
        return LabelSettings.shared_with(self)


def check_settings(s: TextureBakeSettings) -> None:
    if isinstance(s.resolution, bool) or not isinstance(s.resolution, int) or not 4 <= s.resolution <= 8192:
        raise NeuralaoError(f"--resolution must be an integer in [4, 8192], got {s.resolution!r}")
    check_count(
        "--resolution", s.resolution**2, bytes_each=SAMPLE_BYTES, each="per texel", shown=str(s.resolution)
    )
    if isinstance(s.margin, bool) or not isinstance(s.margin, int) or not 0 <= s.margin <= s.resolution // 4:
        raise NeuralaoError(f"--margin must be an integer in [0, resolution / 4], got {s.margin!r}")
    if s.uv not in ("auto", "mesh", "xatlas"):
        raise NeuralaoError(f"--uv must be 'auto', 'mesh' or 'xatlas', got {s.uv!r}")


@dataclass
class UVMesh:
    """A mesh with one UV per vertex, ready to bake and write.

    vertices : (n, 3) float64 scene units
    faces    : (m, 3) int64
    uv       : (n, 2) float64 in [0, 1], trimesh convention (v up)
    material : trimesh material of the source (or None); kept in the output
    uv_source: "mesh" or "xatlas"
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    material: object | None = None
    uv_source: str = "mesh"
    name: str = "mesh"

    def scene(self) -> Scene:
        return Scene(self.vertices, self.faces, self.name)


@dataclass
class Texels:
    """Covered texels of a UV layout.

    pixel : (k,) int64 flat texel index r * N + c
    face  : (k,) int64 face holding the texel centre
    bary  : (k, 3) float64 barycentric coordinates of the centre in that face
    overlap : fraction of covered texels held strictly inside by more than one face
    """

    pixel: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    overlap: float


@dataclass
class TextureBakeResult:
    """ao (N, N) float32 in [0, 1] (row 0 at the top); covered (N, N) bool; info: counts, timings."""

    ao: np.ndarray
    covered: np.ndarray
    info: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- UVs


def _single_geometry(path: Path):
    """The one trimesh.Trimesh of a file, with its transform applied, or None when there are several."""
    import trimesh  # measured: ~1 s to import; only the file readers and writers need it

    try:
        loaded = trimesh.load(str(path), process=False)
    except Exception:
        return None  # load_scene reports unreadable files with its own one-line errors
    if isinstance(loaded, trimesh.Scene):
        if len(loaded.graph.nodes_geometry) != 1:
            return None
        node = loaded.graph.nodes_geometry[0]
        transform, name = loaded.graph[node]
        mesh = loaded.geometry[name].copy()
        mesh.apply_transform(transform)
        return mesh
    return loaded if isinstance(loaded, trimesh.Trimesh) else None


def _mesh_uvs(mesh) -> tuple[np.ndarray | None, str]:
    """(n, 2) float64 UVs of a trimesh mesh, or None and why they are unusable."""
    uv = getattr(mesh.visual, "uv", None)
    if uv is None or len(uv) != len(mesh.vertices):
        return None, "the mesh has no UVs"
    uv = np.asarray(uv, np.float64)
    if not np.isfinite(uv).all():
        return None, "the mesh's UVs are not finite"
    if uv.min() < -UV_RANGE_SLACK or uv.max() > 1 + UV_RANGE_SLACK:
        return None, "the mesh's UVs leave [0, 1] (tiling)"
    return np.clip(uv, 0.0, 1.0), ""


def xatlas_layout(
    vertices: np.ndarray, faces: np.ndarray, resolution: int, margin: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Generate an atlas: vmapping (n',) int64 into ``vertices``, faces (m, 3) int64, uv (n', 2) float64.

    Charts are packed for a ``resolution``-texel square with ``margin`` texels between them.
    """
    atlas = xatlas.Atlas()
    # xatlas works in float32: centred and scaled to a unit box, so a mesh at 1e38 (whose float32 face
    # normals overflow, and on which xatlas never returns) or at 1e-30 charts like one at 1. The atlas
    # does not depend on the mesh's scale or position.
    v = np.asarray(vertices, np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    half = (hi / 2.0 - lo / 2.0).max()  # halves first: finite even for a mesh spanning -1e308..1e308
    unit = (v - (lo / 2.0 + hi / 2.0)) / max(float(half), 1e-300)
    atlas.add_mesh(unit.astype(np.float32), np.asarray(faces, np.uint32))
    pack = xatlas.PackOptions()
    pack.resolution = int(resolution)
    pack.padding = int(margin)
    pack.bilinear = True
    pack.bruteForce = False
    atlas.generate(xatlas.ChartOptions(), pack)
    vmapping, indices, uvs = atlas[0]
    return vmapping.astype(np.int64), indices.astype(np.int64), uvs.astype(np.float64)


def load_uv_mesh(path: str | Path, settings: TextureBakeSettings) -> UVMesh:
    """Load ``path`` with UVs per ``settings.uv`` (module doc, step 1)."""
    path = resolve_mesh_path(path)
    scene = load_scene(path)  # the project's checks: readable, finite, faces; degenerate faces dropped
    mesh = _single_geometry(path) if settings.uv != "xatlas" else None
    material = getattr(getattr(mesh, "visual", None), "material", None)
    why = "multiple geometries (flattened)" if mesh is None else ""
    same = mesh is not None and np.shape(mesh.vertices) == scene.vertices.shape
    if same and np.allclose(mesh.vertices, scene.vertices, rtol=0, atol=1e-9 * scene.diagonal):
        uv, why = _mesh_uvs(mesh)
        if uv is not None:
            candidate = UVMesh(scene.vertices, scene.faces, uv, material, "mesh", scene.name)
            texels = rasterise(uv, scene.faces, settings.resolution)
            if texels.overlap <= OVERLAP_LIMIT:
                return candidate
            why = f"the mesh's UVs overlap ({100 * texels.overlap:.1f}% of texels)"
    elif mesh is not None:
        why = "the mesh's vertices differ from the flattened scene"
    if settings.uv == "mesh":
        raise NeuralaoError(f"--uv mesh: cannot use the UVs of {path.name}: {why}")
    if settings.uv == "auto":
        log.info("%s: generating UVs with xatlas (%s)", scene.name, why or "asked for")
    vmap, faces, uv = xatlas_layout(scene.vertices, scene.faces, settings.resolution, settings.margin)
    if material is not None:
        material = _factors_only(material)
    return UVMesh(scene.vertices[vmap], faces, uv, material, "xatlas", scene.name)


def _factors_only(material):
    """The source material without its UV-dependent textures (their UVs are not the atlas's)."""
    pbr = material.to_pbr() if hasattr(material, "to_pbr") else material
    pbr = pbr.copy()
    dropped = []
    for key in (
        "baseColorTexture",
        "metallicRoughnessTexture",
        "normalTexture",
        "emissiveTexture",
        "occlusionTexture",
    ):
        if getattr(pbr, key, None) is not None:
            setattr(pbr, key, None)
            dropped.append(key)
    if dropped:
        log.warning("xatlas UVs: dropped the source's %s (they use the mesh's own UVs)", ", ".join(dropped))
    return pbr


# --------------------------------------------------------------------------- rasterisation


def texel_coordinates(uv: np.ndarray, resolution: int) -> np.ndarray:
    """(n, 2) float64 image coordinates (x right, y down, texel centres at +0.5) of trimesh UVs."""
    uv = np.asarray(uv, np.float64)
    return np.stack([uv[:, 0] * resolution, (1.0 - uv[:, 1]) * resolution], axis=1)


def rasterise(uv: np.ndarray, faces: np.ndarray, resolution: int) -> Texels:
    """Texels whose centre lies inside a UV triangle (module doc, step 2).

    uv (n, 2) float64 trimesh UVs, faces (m, 3) int64 -> :class:`Texels`.
    """
    n = int(resolution)
    p = texel_coordinates(uv, n)[np.asarray(faces, np.int64)]  # (m, 3, 2)
    lo = np.clip(np.ceil(p.min(axis=1) - 0.5), 0, n - 1).astype(np.int64)  # first centre >= min
    hi = np.clip(np.floor(p.max(axis=1) - 0.5), -1, n - 1).astype(np.int64)
    w = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    h = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    area2 = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 1, 1] - p[:, 0, 1]) * (
        p[:, 2, 0] - p[:, 0, 0]
    )
    count = np.where(np.abs(area2) > 1e-12, w * h, 0)
    pixels, faces_out, barys, strict = [], [], [], []
    ends = np.cumsum(count)
    start = 0
    while start < len(count):
        # a block of whole triangles with at most _RASTER_BLOCK candidates (at least one triangle)
        base = ends[start - 1] if start else 0
        stop = max(int(np.searchsorted(ends, base + _RASTER_BLOCK, side="right")), start + 1)
        idx = np.arange(start, stop)
        c = count[idx]
        tri = np.repeat(idx, c)
        local = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
        col = lo[tri, 0] + local % w[tri]
        row = lo[tri, 1] + local // w[tri]
        q = np.stack([col + 0.5, row + 0.5], axis=1)
        a, b, d = p[tri, 0], p[tri, 1], p[tri, 2]
        l1 = ((q[:, 0] - a[:, 0]) * (d[:, 1] - a[:, 1]) - (q[:, 1] - a[:, 1]) * (d[:, 0] - a[:, 0])) / area2[
            tri
        ]
        l2 = ((b[:, 0] - a[:, 0]) * (q[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (q[:, 0] - a[:, 0])) / area2[
            tri
        ]
        bary = np.stack([1.0 - l1 - l2, l1, l2], axis=1)
        inside = bary.min(axis=1) >= -1e-12
        pixels.append(row[inside] * n + col[inside])
        faces_out.append(tri[inside])
        barys.append(np.clip(bary[inside], 0.0, 1.0))
        strict.append(bary[inside].min(axis=1))
        start = stop
    if not pixels:
        return Texels(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), 0.0)
    pixel = np.concatenate(pixels)
    face = np.concatenate(faces_out)
    bary = np.concatenate(barys)
    depth = np.concatenate(strict)
    # per texel keep the face it lies deepest inside (ties: lowest face index; deterministic)
    order = np.lexsort((face, -depth, pixel))
    first = np.ones(len(order), bool)
    first[1:] = pixel[order][1:] != pixel[order][:-1]
    keep = order[first]
    held = np.bincount(pixel[depth > _INSIDE_STRICT], minlength=n * n)
    overlap = float((held > 1).sum()) / max(len(keep), 1)
    bary = bary[keep] / bary[keep].sum(axis=1, keepdims=True)
    return Texels(pixel[keep], face[keep], bary, overlap)


def dilate(values: np.ndarray, known: np.ndarray, target: np.ndarray, fill: float) -> np.ndarray:
    """Fill ``target & ~known`` texels by repeated 8-neighbour means of known ones (module doc, step 4).

    values (N, N) float, known / target (N, N) bool -> (N, N) float32; texels no known texel reaches
    (or outside ``target``) get ``fill``.
    """
    val = np.where(known, values, 0.0).astype(np.float64)
    known = known.copy()
    for _ in range(2 * max(values.shape)):
        missing = target & ~known
        if not missing.any():
            break
        vp = np.pad(val * known, 1)
        kp = np.pad(known.astype(np.float64), 1)
        s = np.zeros_like(val)
        c = np.zeros_like(val)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                if dy == 1 and dx == 1:
                    continue
                s += vp[dy : dy + val.shape[0], dx : dx + val.shape[1]]
                c += kp[dy : dy + val.shape[0], dx : dx + val.shape[1]]
        grow = missing & (c > 0)
        if not grow.any():
            break
        val[grow] = s[grow] / c[grow]
        known |= grow
    val[~known] = fill
    return val.astype(np.float32)


def _grow_mask(mask: np.ndarray, steps: int) -> np.ndarray:
    """``mask`` grown by ``steps`` texels (8-neighbourhood)."""
    out = mask.copy()
    for _ in range(steps):
        p = np.pad(out, 1)
        grown = np.zeros_like(out)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                grown |= p[dy : dy + out.shape[0], dx : dx + out.shape[1]]
        out = grown
    return out


# --------------------------------------------------------------------------- baking


def texel_image(
    n: int, pixel: np.ndarray, ao: np.ndarray, valid: np.ndarray, margin: int
) -> tuple[np.ndarray, np.ndarray]:
    """The AO map from labelled texels (module doc, step 4): image (n, n) float32, covered (n, n) bool.

    pixel (k,) int64 flat texel indices, ao (k,) float, valid (k,) bool. Invalid texels and the gutter
    of ``margin`` texels are dilated from the valid ones; texels outside every chart and gutter are 1.
    """
    flat = np.zeros(n * n, np.float64)
    known = np.zeros(n * n, bool)
    flat[pixel] = ao
    known[pixel] = valid
    covered = np.zeros(n * n, bool)
    covered[pixel] = True
    covered = covered.reshape(n, n)
    target = _grow_mask(covered, margin)
    fill = float(ao[valid].mean()) if valid.any() else 1.0
    image = dilate(flat.reshape(n, n), known.reshape(n, n), target, fill)
    image[~target] = 1.0  # outside every chart and gutter: open (never sampled)
    return image, covered


def bake_texture(
    mesh: UVMesh, settings: TextureBakeSettings | None = None, progress: bool = False
) -> TextureBakeResult:
    """AO texture of ``mesh`` (module doc, steps 2-4)."""
    settings = settings or TextureBakeSettings()
    check_settings(settings)
    n = settings.resolution
    t0 = time.perf_counter()
    scene = mesh.scene()
    texels = rasterise(mesh.uv, mesh.faces, n)
    if len(texels.pixel) == 0:
        raise NeuralaoError(
            f"no texel centre falls inside a UV triangle at resolution {n}; raise --resolution"
        )
    textured = len(np.unique(texels.face))
    if textured < len(mesh.faces) // 4:  # the map holds the AO of few of the faces
        log.warning(
            "at %dx%d only %d of the %d faces hold a texel centre; the others take their neighbours' AO "
            "(raise --resolution)",
            n,
            n,
            textured,
            len(mesh.faces),
        )
    t1 = time.perf_counter()
    tri = scene.triangles[texels.face]
    points = np.einsum("kc,kcd->kd", texels.bary, tri)
    labeller = Labeller(scene, settings.label_settings())
    ao, valid = labeller.ao_at_points(
        points, scene.face_normals[texels.face], progress=progress, ids=texels.pixel
    )
    t2 = time.perf_counter()
    image, covered = texel_image(n, texels.pixel, ao, valid, settings.margin)
    info = {
        "resolution": n,
        "uv_source": mesh.uv_source,
        "texels_covered": int(covered.sum()),
        "coverage": float(covered.mean()),
        "invalid_texels": int((~valid).sum()),
        "uv_overlap": texels.overlap,
        "rays_traced": int(len(ao)) * settings.rays,
        "max_distance": labeller.max_distance,
        "seconds_raster": t1 - t0,
        "seconds_trace": t2 - t1,
        "seconds": time.perf_counter() - t0,
        "vertices": int(len(mesh.vertices)),
        "faces": int(len(mesh.faces)),
        "settings": settings_to_dict(settings),
    }
    return TextureBakeResult(image, covered, info)


# --------------------------------------------------------------------------- sampling and error


def point_uvs(mesh: UVMesh, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(k, 2) float64 UVs of surface points given by face (k,) and barycentrics (k, 3)."""
    return np.einsum("kc,kcd->kd", bary, mesh.uv[mesh.faces[face]])


def sample_bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup as a GL sampler does it (LINEAR, CLAMP_TO_EDGE): image (N, N), uv (k, 2)
    -> (k,) float64."""
    img = np.asarray(image, np.float64)
    h, w = img.shape
    uv = np.asarray(uv, np.float64)
    x = np.clip(uv[:, 0] * w - 0.5, 0.0, w - 1.0)
    y = np.clip((1.0 - uv[:, 1]) * h - 0.5, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), w - 2) if w > 1 else np.zeros(len(x), np.int64)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2) if h > 1 else np.zeros(len(y), np.int64)
    fx, fy = x - x0, y - y0
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    top = img[y0, x0] * (1 - fx) + img[y0, x1] * fx
    bottom = img[y1, x0] * (1 - fx) + img[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def quantise(image: np.ndarray) -> np.ndarray:
    """(N, N) uint8 round(255 ao): what the PNG and the .glb hold."""
    return np.rint(np.clip(np.asarray(image, np.float64), 0.0, 1.0) * 255.0).astype(np.uint8)


# --------------------------------------------------------------------------- files


def png_path_for(out: str | Path) -> Path:
    """The stand-alone PNG beside OUT.glb: OUT.ao.png."""
    out = Path(out)
    return out.with_name(out.stem + ".ao.png")


def write_texture_glb(path: str | Path, mesh: UVMesh, image: np.ndarray) -> Path:
    """Write ``mesh`` with UVs and the AO map as its material's occlusionTexture to .glb, atomically."""
    path = Path(path)
    if path.suffix.lower() != ".glb":
        raise NeuralaoError(f"--to texture writes a .glb, got {path.name!r}")
    data = texture_glb_bytes(mesh, image)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def texture_glb_bytes(mesh: UVMesh, image: np.ndarray) -> bytes:
    """The .glb of :func:`write_texture_glb` in memory."""
    import trimesh  # measured: ~1 s to import; only the file readers and writers need it
    from trimesh.visual.material import PBRMaterial

    grey = Image.fromarray(quantise(image), mode="L")
    if mesh.material is not None:
        material = mesh.material.to_pbr() if hasattr(mesh.material, "to_pbr") else mesh.material
        material = material.copy()
    else:
        material = PBRMaterial(
            name="neuralao_ao", baseColorFactor=[255, 255, 255, 255], metallicFactor=0.0, roughnessFactor=1.0
        )
    material.occlusionTexture = grey
    tm = trimesh.Trimesh(
        vertices=np.asarray(mesh.vertices, np.float64),
        faces=np.asarray(mesh.faces, np.int64),
        visual=trimesh.visual.TextureVisuals(uv=np.asarray(mesh.uv, np.float64), material=material),
        process=False,
        validate=False,
    )
    return tm.export(file_type="glb")


def read_texture_glb(path: str | Path) -> tuple[UVMesh, np.ndarray]:
    """Read a texture bake: the mesh with its UVs and the occlusion map's red channel (N, N) float32
    in [0, 1]."""
    import trimesh  # measured: ~1 s to import; only the file readers and writers need it

    path = Path(path)
    if path.suffix.lower() in (".gltf", ".glb") and path.is_file() and path.stat().st_size:
        check_gltf(path)  # the specification's rules before trimesh reads it
    try:
        loaded = trimesh.load(str(path), process=False)
    except Exception as e:
        raise NeuralaoError(f"cannot read {path}: {type(e).__name__}: {e}") from None
    if isinstance(loaded, trimesh.Scene):
        geoms = list(loaded.geometry.values())
        if len(geoms) != 1:
            raise NeuralaoError(f"{path} holds {len(geoms)} meshes, expected one")
        loaded = geoms[0]
    material = getattr(loaded.visual, "material", None)
    tex = getattr(material, "occlusionTexture", None)
    uv = getattr(loaded.visual, "uv", None)
    if tex is None or uv is None:
        raise NeuralaoError(f"{path} has no occlusionTexture with UVs (not a texture bake)")
    red = np.asarray(tex.convert("RGB"), np.float32)[:, :, 0] / 255.0
    mesh = UVMesh(
        np.asarray(loaded.vertices, np.float64),
        np.asarray(loaded.faces, np.int64),
        np.asarray(uv, np.float64),
        material,
        "file",
        path.stem,
    )
    return mesh, red


def scene_with_uvs(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, name: str = "mesh") -> UVMesh:
    """A :class:`UVMesh` from arrays (tests, benchmarks), with the scene's validity checks."""
    scene = scene_from_arrays(vertices, faces, name)
    return UVMesh(scene.vertices, scene.faces, np.asarray(uv, np.float64), None, "mesh", name)
