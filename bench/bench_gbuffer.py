"""Benchmark the float G-buffer renderer against pyrender's own OffscreenRenderer on the same views.

    .venv/bin/python bench/bench_gbuffer.py --out build/bench [--size 512] [--views 8]
        [--meshes spot bunny ...]

For each mesh and the same ``views`` orbit cameras at ``size`` x ``size``:

* (a) ``GBufferRenderer.render``: one MRT pass (RGBA32F x 3 + R32I + float depth) and the readback of
  every channel (depth, two normals, position, triangle id, mask) into the frame dict;
* (b) ``pyrender.OffscreenRenderer.render``: pyrender's default shaded pass (one directional light,
  smooth normals) with its 8-bit RGB colour and float depth readback - what one gets from pyrender
  without our own program.

Both run in the same process on the same GL platform, interleaved round by round (``--repeats``
rounds, the best round kept, since other processes share the two cores). Also reported: the time to
upload each scene and render its first frame, the G-buffer's draw vs readback split, and the
fraction of pixels on which both agree about foreground vs background (a sanity check). Writes
DIR/gbuffer.json and DIR/gbuffer.md.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer, reversed_z_projection  # noqa: E402
from neuralao.pipeline.geometry.camera import orbit  # noqa: E402
from neuralao.pipeline.geometry.scene import load_scene  # noqa: E402
from neuralao.runtime import gl as rgl  # noqa: E402
from neuralao.runtime.foundation.io import write_json, write_text  # noqa: E402
from neuralao.runtime.foundation.machine import cpu_name  # noqa: E402

DEFAULT_MESHES = ("spot", "bunny", "2CylinderEngine")


class PyrenderBaseline:
    """pyrender's OffscreenRenderer on one scene: shaded 8-bit colour + float depth per camera."""

    def __init__(self, scene, size: int):
        import pyrender
        import trimesh

        self.pyrender = pyrender
        mesh = trimesh.Trimesh(scene.vertices, scene.faces, process=False)
        self.scene = pyrender.Scene(ambient_light=(0.3, 0.3, 0.3), bg_color=(0, 0, 0, 0))
        self.scene.add(pyrender.Mesh.from_trimesh(mesh, smooth=True))
        self.camera = pyrender.PerspectiveCamera(yfov=1.0, znear=0.1, zfar=10.0, aspectRatio=1.0)
        self.cam_node = self.scene.add(self.camera, pose=np.eye(4))
        self.light_node = self.scene.add(pyrender.DirectionalLight(intensity=3.0), pose=np.eye(4))
        self.renderer = pyrender.OffscreenRenderer(size, size)

    def render(self, cam) -> tuple[np.ndarray, np.ndarray]:
        self.camera.yfov, self.camera.znear, self.camera.zfar = cam.yfov, cam.znear, cam.zfar
        self.scene.set_pose(self.cam_node, cam.pose)
        self.scene.set_pose(self.light_node, cam.pose)  # headlight
        return self.renderer.render(self.scene)

    def close(self) -> None:
        self.renderer.delete()


def time_views(fn, cams) -> float:
    """Seconds per frame over ``cams`` (results forced to host memory by the callee)."""
    start = time.perf_counter()
    for cam in cams:
        fn(cam)
    return (time.perf_counter() - start) / len(cams)


def split_draw_readback(renderer: GBufferRenderer, cams) -> tuple[float, float]:
    """Seconds per frame for the draw (to glFinish) and for the readback, measured separately."""
    draw = read = 0.0
    for cam in cams:
        w, h = cam.width, cam.height
        pose = np.asarray(cam.pose, dtype=np.float64)
        view = np.linalg.inv(pose)
        to_world = np.eye(4)
        to_world[:3, 3] = renderer.center
        renderer.ctx.make_current()
        t0 = time.perf_counter()
        renderer._draw(view @ to_world, reversed_z_projection(cam), view[:3, :3], w, h)
        rgl.finish()
        t1 = time.perf_counter()
        renderer._read_back(cam, pose, w, h)
        t2 = time.perf_counter()
        draw += t1 - t0
        read += t2 - t1
    return draw / len(cams), read / len(cams)


def bench_mesh(name: str, size: int, views: int, repeats: int) -> dict:
    scene = load_scene(name)
    cams = orbit(scene, views, size, size, seed=1)
    t0 = time.perf_counter()
    gb = GBufferRenderer(scene)
    gb.render(cams[0])  # first frame also creates the framebuffer
    upload_gb = time.perf_counter() - t0
    t0 = time.perf_counter()
    pr = PyrenderBaseline(scene, size)
    pr.render(cams[0])
    upload_pr = time.perf_counter() - t0
    best_gb = best_pr = math.inf
    for _ in range(repeats):  # interleaved rounds: both see the same machine load
        best_gb = min(best_gb, time_views(gb.render, cams))
        best_pr = min(best_pr, time_views(pr.render, cams))
    draw, read = split_draw_readback(gb, cams)
    frame = gb.render(cams[0])
    color, depth = pr.render(cams[0])
    # Sanity: both see the same silhouette (pyrender depth 0 on background).
    agree = float(np.mean(frame["mask"] == (depth > 0)))
    gb.close()
    pr.close()
    return {
        "mesh": name,
        "faces": int(len(scene.faces)),
        "views": views,
        "gbuffer_ms": best_gb * 1e3,
        "gbuffer_fps": 1.0 / best_gb,
        "gbuffer_draw_ms": draw * 1e3,
        "gbuffer_readback_ms": read * 1e3,
        "pyrender_ms": best_pr * 1e3,
        "pyrender_fps": 1.0 / best_pr,
        "ratio_gbuffer_over_pyrender_fps": best_pr / best_gb,
        "upload_s": {"gbuffer": upload_gb, "pyrender": upload_pr},
        "readback_bytes": {
            "gbuffer": 3 * 16 * size * size + 4 * size * size,
            "pyrender": 3 * size * size + 4 * size * size,
        },
        "silhouette_agreement": agree,
    }


def markdown(result: dict) -> str:
    s = result["size"]
    lines = [
        f"# G-buffer vs pyrender ({s}x{s}, {result['gl']['platform']}, {result['gl']['renderer']})",
        "",
        f"CPU: {result['cpu']} ({result['cores']} cores). Best of {result['repeats']} interleaved rounds "
        f"over {result['views']} orbit views.",
        "",
        "G-buffer = our MRT pass + readback of every float channel and the triangle ids; "
        "pyrender = `OffscreenRenderer.render` (shaded 8-bit colour + float depth).",
        "",
        "| mesh | faces | G-buffer ms (fps) | draw / readback ms | pyrender ms (fps) | "
        "G-buffer fps / pyrender fps | upload s (ours / pyrender) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["meshes"]:
        lines.append(
            f"| {r['mesh']} | {r['faces']:,} | {r['gbuffer_ms']:.1f} ({r['gbuffer_fps']:.1f}) "
            f"| {r['gbuffer_draw_ms']:.1f} / {r['gbuffer_readback_ms']:.1f} | "
            f"{r['pyrender_ms']:.1f} ({r['pyrender_fps']:.1f}) | "
            f"{r['ratio_gbuffer_over_pyrender_fps']:.2f}x | {r['upload_s']['gbuffer']:.2f} / "
            f"{r['upload_s']['pyrender']:.2f} |"
        )
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="output folder for gbuffer.json / gbuffer.md")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--views", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--meshes", nargs="+", default=list(DEFAULT_MESHES))
    args = ap.parse_args(argv)
    info = rgl.context().info
    result = {
        "size": args.size,
        "views": args.views,
        "repeats": args.repeats,
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "gl": {"platform": info.platform, "version": info.version, "renderer": info.renderer},
        "meshes": [],
    }
    for name in args.meshes:
        r = bench_mesh(name, args.size, args.views, args.repeats)
        print(
            f"{name}: G-buffer {r['gbuffer_ms']:.1f} ms, pyrender {r['pyrender_ms']:.1f} ms, "
            f"ratio {r['ratio_gbuffer_over_pyrender_fps']:.2f}x",
            flush=True,
        )
        result["meshes"].append(r)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "gbuffer.json", result)
    write_text(args.out / "gbuffer.md", markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
