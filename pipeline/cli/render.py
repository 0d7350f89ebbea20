"""`neuralao render`: G-buffers + ray-traced AO labels for views of one mesh, with PNG previews.

Output folder::

    view_0000.npz          every G-buffer channel + ao + valid + pose / yfov / znear / zfar (frame format)
    view_0000_ao.png       AO in grey (invalid pixels tinted red), background neutral grey
    view_0000_normal.png   camera-space normal mapped to colour (0.5 + 0.5 n), background grey
    view_0000_depth.png    linear depth normalised over the foreground (near = bright), background grey
    render.json            resolved settings, scene statistics, GL platform, per-view summary

Each view's labeller seed is derived from ``--seed`` and the view index (the same rule as the dataset
stage), so reruns are identical and views do not share sampling patterns. Every file is written
atomically; ``render.json`` is written last, so its presence marks a complete run.
"""

from __future__ import annotations

import argparse
import logging
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from neuralao.pipeline.datasets.dataset import frame_seed
from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.camera import Camera, load_poses, orbit
from neuralao.pipeline.geometry.scene import Scene, load_scene
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings, check_label_args, label_fields
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json, write_png
from neuralao.runtime.foundation.limits import (
    PIXEL_DISK_BYTES,
    check_count,
    check_disk,
    check_finite_arrays,
    check_pixels,
    check_seed,
)
from neuralao.runtime.foundation.paths import FOLDER
from neuralao.runtime.foundation.settings import settings_to_dict
from neuralao.runtime.frame import Frame, FrameLike, check_yfov, write_frame
from neuralao.runtime.gl import context

log = logging.getLogger(__name__)

# What the command writes (dest -> a file or a folder) and reads: checked before it runs, by
# neuralao.pipeline.cli.main.check_arguments (writable, not an input, not each other).
OUTPUTS = {"out": FOLDER}
INPUTS = ("mesh", "cameras")
MESH_INPUTS = ("mesh",)  # mesh names: a file, a glTF folder or a bare name
# PyOpenGL logs "No OpenGL_accelerate module loaded" at INFO on import; it is expected and not news.
logging.getLogger("OpenGL.acceleratesupport").setLevel(logging.WARNING)

FORMAT_VERSION = 1
# Preview colours: one neutral grey for every background (the zero normal maps to it too).
BACKGROUND = np.array([0.5, 0.5, 0.5], dtype=np.float32)
INVALID_TINT = np.array([0.9, 0.15, 0.1], dtype=np.float32)
MAX_SIZE = 8192
DEFAULT_YFOV_DEG = 40.0  # orbit cameras' vertical field of view


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "mesh", help="mesh file (.obj .ply .gltf .glb .stl .off), glTF folder, or a bare test-mesh name"
    )
    p.add_argument(
        "--views", type=int, default=8, help="number of orbit views (ignored with --cameras; default 8)"
    )
    p.add_argument(
        "--size",
        type=int,
        nargs=2,
        metavar=("W", "H"),
        default=(256, 256),
        help="image size (default 256 256)",
    )
    p.add_argument("--rays", type=int, default=256, help="AO rays per pixel (default 256)")
    p.add_argument(
        "--max-distance",
        type=float,
        default=None,
        help="longest AO ray, scene units (default 0.25 x bounding-box diagonal)",
    )
    p.add_argument(
        "--kernel", choices=("binary", "obscurance"), default="binary", help="AO kernel (default binary)"
    )
    p.add_argument(
        "--half-distance",
        type=float,
        default=None,
        help="obscurance: distance at which a hit counts half, scene units (default 0.05 x diagonal)",
    )
    p.add_argument(
        "--cameras", metavar="POSES.json", default=None, help="explicit camera poses instead of an orbit"
    )
    p.add_argument(
        "--yfov",
        type=float,
        default=None,
        metavar="DEG",
        help="orbit vertical field of view in degrees (default 40)",
    )
    p.add_argument("--yfov-rad", type=float, default=None, metavar="RAD", help="the same in radians")
    p.add_argument(
        "--normals", choices=("smooth", "flat"), default="smooth", help="G-buffer normals (default smooth)"
    )
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the orbit rotation and the AO ray directions (default 0)"
    )
    p.add_argument(
        "--back-layer",
        action="store_true",
        help="also write depth_back, the G-buffer's back layer (what a U-Net of input version 4 reads)",
    )
    p.add_argument("--workers", type=int, default=2, help="labelling threads (default 2)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")


# Memory one orbit view takes before anything is rendered (its Camera and its summary in render.json).
VIEW_BYTES = 4096


def _check_args(args: argparse.Namespace) -> None:
    w, h = args.size
    check_pixels("--size", w, h, max_side=MAX_SIZE)
    if args.cameras is None:
        check_count("--views", args.views, bytes_each=VIEW_BYTES, each="a camera and its summary")
        check_disk("--views", args.views * w * h * PIXEL_DISK_BYTES, args.out, f"{args.views} at {w} {h}")
    check_seed("--seed", args.seed)
    check_label_args(args)
    if args.yfov is not None and args.yfov_rad is not None:
        raise NeuralaoError("give the field of view once: --yfov DEG or --yfov-rad RAD")
    if args.yfov_rad is not None:
        args.yfov = check_yfov("--yfov-rad", args.yfov_rad, radians=True)
    if args.yfov is None:
        args.yfov = DEFAULT_YFOV_DEG
    check_yfov("--yfov", args.yfov)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise NeuralaoError(f"--out {out} exists and is not a folder")


def run(args: argparse.Namespace) -> int:
    _check_args(args)
    w, h = args.size
    scene = load_scene(args.mesh)
    if args.cameras is not None:
        cameras = load_poses(args.cameras, scene, w, h)
    else:
        cameras = orbit(scene, args.views, w, h, yfov_deg=args.yfov, seed=args.seed)
    settings = LabelSettings(**label_fields(args))
    start = time.perf_counter()
    summary = render_views(
        scene, cameras, settings, args.out, progress=True, normals=args.normals, back_layer=args.back_layer
    )
    log.info(
        "%s: %d view(s) in %.1f s -> %s", scene.name, len(cameras), time.perf_counter() - start, args.out
    )
    record = {
        "format": "neuralao-render",
        "version": FORMAT_VERSION,
        "mesh": str(Path(scene.source).resolve()) if scene.source else str(args.mesh),
        "scene": scene_stats(scene),
        "settings": {
            "size": [w, h],
            "cameras": "file" if args.cameras else "orbit",
            "poses": str(Path(args.cameras).resolve()) if args.cameras else None,
            "views": len(cameras),
            "yfov_deg": None if args.cameras else args.yfov,
            "normals": args.normals,
            "seed": args.seed,
            "labels": summary["labels"],
        },
        "gl": summary["gl"],
        "views": summary["views"],
        "conventions": {
            "ao": "accessibility in [0,1], 1 = open; 1 on background",
            "valid": "foreground and not invalidated by the back-face rule",
            "depth": "linear camera-space depth (-z_cam), 0 on background",
            "normals": "unit, flipped to face the viewer; camera space (OpenGL: -z forward) and object space",
            "tri_id": "index into the scene's faces, -1 on background",
            "rows": "row 0 at the top",
        },
    }
    write_json(Path(args.out) / "render.json", record)
    return 0


def scene_stats(scene: Scene) -> dict:
    """JSON-able summary of a scene (counts, bounds, diagonal)."""
    return {
        "name": scene.name,
        "vertices": int(len(scene.vertices)),
        "faces": int(len(scene.faces)),
        "dropped_degenerate_faces": int(scene.dropped_faces),
        "bounds": scene.bounds.tolist(),
        "diagonal": float(scene.diagonal),
    }


def view_seed(seed: int, view: int) -> int:
    """Labeller seed of one view (the dataset stage's rule, scene index 0)."""
    return frame_seed(seed, 0, view)


def render_and_label(renderer, labeller, camera: Camera) -> dict[str, np.ndarray]:
    """One view: the G-buffer frame of ``camera`` plus ``ao`` (H, W) f32 and ``valid`` (H, W) bool.

    renderer : :class:`neuralao.pipeline.gbuffers.rasterizer.GBufferRenderer`;
    labeller : :class:`neuralao.pipeline.tracing.labeller.Labeller` (its current settings, seed included,
    are used as they are).
    """
    frame = renderer.render(camera)
    frame["ao"], frame["valid"] = labeller.label_frame(frame)
    return frame


def render_views(
    scene: Scene,
    cameras: list[Camera],
    label_settings: LabelSettings,
    out_dir: str | Path,
    progress: bool = True,
    normals: str = "smooth",
    prefix: str = "view_",
    back_layer: bool = False,
) -> dict:
    """Render, label and write every camera's view: ``<prefix>NNNN.npz`` + three PNG previews each.

    The labeller seed of view k is :func:`view_seed` (``label_settings.seed``, k). Returns a dict with
    ``views`` (per-view file names and statistics), ``labels`` (resolved label settings, distances in
    scene units) and ``gl`` (platform, version, renderer). Bad settings raise :class:`NeuralaoError`
    before anything is written.
    """
    if not cameras:
        raise NeuralaoError("no cameras to render")
    labeller = Labeller(scene, label_settings)
    renderer = GBufferRenderer(scene, normals=normals, back_layer=back_layer)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    views = []
    try:
        for k, cam in enumerate(
            tqdm(cameras, desc=f"render {scene.name}", unit="view", disable=not progress)
        ):
            labeller.settings = replace(label_settings, seed=view_seed(label_settings.seed, k))
            frame = render_and_label(renderer, labeller, cam)
            check_finite_arrays(frame, f"{scene.name} view {k}", "G-buffer channel")
            frame["radii"] = np.array([labeller.max_distance], np.float32)  # the labels' AO radius
            views.append(write_view(out, f"{prefix}{k:04d}", frame, labeller.settings.seed))
    finally:
        renderer.close()
    info = context().info
    labels = settings_to_dict(label_settings)
    labels.update(
        max_distance=labeller.max_distance,
        half_distance=labeller.half_distance if label_settings.kernel == "obscurance" else None,
        offset=labeller.offset,
    )
    return {
        "views": views,
        "labels": labels,
        "gl": {"platform": info.platform, "version": info.version, "renderer": info.renderer},
    }


def write_view(out: Path, stem: str, frame: FrameLike, seed: int) -> dict:
    """Write ``stem.npz`` and the previews atomically; return the view's summary for render.json."""
    write_frame(out / f"{stem}.npz", Frame.from_arrays(frame, f"{out / stem}"))
    write_png(out / f"{stem}_ao.png", ao_preview(frame))
    write_png(out / f"{stem}_normal.png", normal_preview(frame))
    write_png(out / f"{stem}_depth.png", depth_preview(frame))
    mask, valid = frame["mask"], frame["valid"]
    fg = int(mask.sum())
    return {
        "file": f"{stem}.npz",
        "previews": [f"{stem}_ao.png", f"{stem}_normal.png", f"{stem}_depth.png"],
        "label_seed": int(seed),
        "foreground_px": fg,
        "valid_px": int(valid.sum()),
        "ao_mean_valid": float(frame["ao"][valid].mean()) if valid.any() else None,
        "depth_range": [float(frame["depth"][mask].min()), float(frame["depth"][mask].max())] if fg else None,
        "pose": np.asarray(frame["pose"]).tolist(),
        "yfov": float(frame["yfov"]),
        "znear": float(frame["znear"]),
        "zfar": float(frame["zfar"]),
    }


def _with_background(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = np.empty((*mask.shape, 3), dtype=np.float32)
    out[:] = BACKGROUND
    out[mask] = rgb[mask]
    return out


def ao_preview(frame: FrameLike) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1]: AO in grey; invalid foreground pixels tinted red; background grey."""
    ao = np.clip(np.asarray(frame["ao"], np.float32), 0.0, 1.0)
    rgb = np.repeat(ao[..., None], 3, axis=-1)
    invalid = frame["mask"] & ~frame["valid"]
    rgb[invalid] = 0.5 * rgb[invalid] + 0.5 * INVALID_TINT
    return _with_background(rgb, frame["mask"])


def normal_preview(frame: FrameLike) -> np.ndarray:
    """(H, W, 3) float32: camera-space normal as 0.5 + 0.5 n (facing the viewer is blue), background grey."""
    return _with_background(0.5 + 0.5 * np.asarray(frame["normal_cam"], np.float32), frame["mask"])


def depth_preview(frame: FrameLike) -> np.ndarray:
    """(H, W, 3) float32: depth normalised to the foreground's range (near = bright, magma), background
    grey."""
    from matplotlib import colormaps  # measured: ~0.5 s to import; only the depth preview needs it

    depth, mask = np.asarray(frame["depth"], np.float64), frame["mask"]
    rgb = np.zeros((*mask.shape, 3), dtype=np.float32)
    if mask.any():
        lo, hi = depth[mask].min(), depth[mask].max()
        t = (hi - depth) / (hi - lo) if hi > lo else np.ones_like(depth)
        rgb = colormaps["magma"](np.clip(0.1 + 0.9 * t, 0.0, 1.0))[..., :3].astype(np.float32)
    return _with_background(rgb, mask)
