"""A real-time screen-space ray trace with a thickness prior, scored against GTAO on evaluate's frames.

    PYOPENGL_PLATFORM=osmesa .venv/bin/python bench/ssrt_thickness.py \
        [--frames build/bench/error_bands/frames/256x256] [--rays 8 16] [--steps 8] \
        [--thickness 1 0.25] [--time-size 1920 1080] [--out build/bench/ssrt_thickness]

The question it answers: `bench/ao_visibility_bound.py` found that the depth buffer, read with a fixed
thickness prior, holds enough for about 0.6x GTAO's RMSE on isolated objects (64 of the labels' rays,
32 steps each, no real-time budget). This is the same idea as a GL fragment pass an engine could run:
per pixel ``rays`` cosine-weighted directions about the normal (a Hammersley set rotated per pixel by
the 4x4 noise tile), ``steps`` jittered samples along each up to the label radius, starting 1.3 pixels
out; a sample is occluded where it lies behind the depth buffer's surface at its pixel by more than
2% and less than ``thickness`` of the radius; off screen or behind the camera is open; background is
passed through. AO = the share of open rays, then the baselines' 4x4 foreground-only blur. With
``--facets`` also each variant about the normal of the facet the depth buffer shows at the pixel (the
labels' rays leave the triangle's geometric normal; the G-buffer's normals are smooth).

Scored as `neuralao evaluate` scores (valid foreground pixels per (frame, radius), mean over pairs),
held-aside categories left out; RMSE and SSIM as ratios to GTAO's; and the GL time at ``--time-size``
on the frame of ``--mesh`` beside GTAO's (llvmpipe here: ratios only). An experiment: the pass is not
one of the runtime's baselines.
"""

from __future__ import annotations

import argparse
import importlib.util
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from neuralao.pipeline.datasets.dataset import open_dataset
from neuralao.pipeline.evaluation.categories import EvalSettings, category_of
from neuralao.pipeline.evaluation.test_split import score_frame, screen_space_predictor
from neuralao.runtime import gl
from neuralao.runtime.baseline_templates import fill
from neuralao.runtime.baselines import ScreenSpaceAO, SSAOSettings, projection_scale
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_json, write_text
from neuralao.runtime.foundation.settings import load_settings
from neuralao.runtime.gl import GL

log = logging.getLogger(__name__)

FRAGMENT = """#version 430 core
// Screen-space ray trace with a thickness prior: RAYS cosine-weighted rays x STEPS samples.
uniform vec2 u_proj;
uniform float u_radius;
uniform float u_thickness;
uniform float u_bias;
uniform float u_pixels_per_unit;
uniform vec3 u_dirs[RAYS];
layout(binding = 4) uniform sampler2D u_back;  // the back layer's linear depth (BACK), 0 where thin
${inputs}

void main() {
${surface}
    if (FACETS) {  // the facet seen at this pixel, from the depth buffer (the labels' rays leave it)
        vec4 xr = texelFetch(u_position, min(px + ivec2(1, 0), size - 1), 0);
        vec4 xl = texelFetch(u_position, max(px - ivec2(1, 0), ivec2(0)), 0);
        vec4 yu = texelFetch(u_position, min(px + ivec2(0, 1), size - 1), 0);
        vec4 yd = texelFetch(u_position, max(px - ivec2(0, 1), ivec2(0)), 0);
        bool use_r = xr.w > 0.5 && (xl.w < 0.5 || abs(xr.z - p.z) < abs(xl.z - p.z));
        bool use_u = yu.w > 0.5 && (yd.w < 0.5 || abs(yu.z - p.z) < abs(yd.z - p.z));
        vec3 dx = use_r ? xr.xyz - p : p - xl.xyz;
        vec3 dy = use_u ? yu.xyz - p : p - yd.xyz;
        vec3 f = cross(dx, dy);
        if ((xr.w > 0.5 || xl.w > 0.5) && (yu.w > 0.5 || yd.w > 0.5) && dot(f, f) > 0.0) {
            f = normalize(f);
            n = dot(f, -p) >= 0.0 ? f : -f;
        }
    }
    vec4 r = texelFetch(u_noise, px % 4, 0);
    vec3 t = vec3(r.xy, 0.0) - n * dot(vec3(r.xy, 0.0), n);
    if (dot(t, t) < 1e-8) t = abs(n.x) < 0.9 ? cross(n, vec3(1.0, 0.0, 0.0)) : cross(n, vec3(0.0, 1.0, 0.0));
    t = normalize(t);
    mat3 tbn = mat3(t, cross(n, t), n);
    float radius_px = u_radius * u_pixels_per_unit / max(-p.z, 1e-30);
    if (!(radius_px > 1.0)) { o_ao = 1.0; return; }
    float min_s = min(START_PX / radius_px, 0.5);
    float hits = 0.0;
    for (int i = 0; i < RAYS; ++i) {
        vec3 d = tbn * u_dirs[i];
        float prev_z = p.z;                            // the last sample looked up (the origin first)
        for (int k = 0; k < STEPS; ++k) {
            float s = min_s + (1.0 - min_s) * (float(k) + r.z) / float(STEPS);
            vec3 q3 = p + d * (s * u_radius);
            if (q3.z >= -1e-20) break;                 // behind the camera: open
            ivec2 q = to_pixel(q3, size);
            if (!inside(q, size)) break;               // off screen: open
            vec4 sw = texelFetch(u_position, q, 0);
            if (sw.w < 0.5) continue;                  // background: nothing there
            float behind = sw.z - q3.z;                // > 0: the sample is behind the surface seen there
            float back = BACK ? texelFetch(u_back, q, 0).r : 0.0;
            // with the back layer: inside the solid from its front to where the pixel's ray leaves it;
            // where the layer says thin (or without it), the thickness prior
            float deep = back > 0.0 ? back + sw.z : u_thickness;
            // crossing: the previous sample was in front of the surface seen here, so the ray passed
            // through it between the two samples, however deep behind it the sample now lies
            bool crossed = CROSSING && prev_z > sw.z;
            if (behind > u_bias && (behind < deep || crossed)) { hits += 1.0; break; }
            prev_z = q3.z;
        }
    }
    o_ao = 1.0 - hits / float(RAYS);
}
"""


def _sibling(name: str):
    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parent / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_bands = _sibling("ao_error_bands")


def directions(rays: int) -> np.ndarray:
    """(rays, 3) float32 cosine-weighted unit directions about +z (Hammersley)."""
    i = np.arange(rays)
    u1 = (i + 0.5) / rays
    u2 = np.array([int(f"{k:032b}"[::-1], 2) / 2.0**32 for k in i])
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - u1)], -1).astype(np.float32)


class ScreenSpaceTrace(ScreenSpaceAO):
    """The trace above in the baselines' pipeline (their G-buffer upload, noise texture and blur)."""

    def __init__(
        self,
        width: int,
        height: int,
        radius: float,
        rays: int,
        steps: int,
        thickness: float,
        facets: bool,
        back_layer: bool = False,
        crossing: bool = False,
        bias: float = 0.02,
        blur: bool = True,
        start_px: float = 1.3,
    ):
        super().__init__("ssao", width, height, radius, SSAOSettings(noise_size=4, blur=blur))
        rng = np.random.default_rng(11)
        a = rng.uniform(0.0, 2.0 * np.pi, (4, 4))
        tile = np.stack([np.cos(a), np.sin(a), rng.uniform(0.0, 1.0, (4, 4)), np.zeros((4, 4))], -1)
        gl.upload_texture(self.noise, tile.astype(np.float32), GL.GL_RGBA32F)
        source = fill("gbuffer_inputs"), fill("surface_at_pixel")
        text = FRAGMENT.replace("RAYS", str(rays)).replace("STEPS", str(steps))
        text = text.replace("FACETS", "true" if facets else "false").replace("START_PX", f"{start_px:.6f}")
        text = text.replace("CROSSING &&", "true &&" if crossing else "false &&")
        text = text.replace("BACK ?", "true ?" if back_layer else "false ?")
        self.back_layer = back_layer
        self.back = gl.create_texture(self.w, self.h, GL.GL_R32F)
        text = text.replace("${inputs}", source[0]).replace("${surface}", source[1])
        self.prog = gl.compile_program(vertex=fill("fullscreen_vertex"), fragment=text)
        self.dirs, self.thickness, self.bias = directions(rays), float(thickness), float(bias)

    def _uniforms(self) -> None:
        prog = self.prog
        p00, p11 = projection_scale(self.yfov, self.w, self.h)
        GL.glUniform2f(GL.glGetUniformLocation(prog, "u_proj"), p00, p11)
        GL.glUniform1f(GL.glGetUniformLocation(prog, "u_radius"), self.radius)
        GL.glUniform1f(GL.glGetUniformLocation(prog, "u_thickness"), self.thickness * self.radius)
        GL.glUniform1f(GL.glGetUniformLocation(prog, "u_bias"), self.bias * self.radius)
        GL.glUniform1f(GL.glGetUniformLocation(prog, "u_pixels_per_unit"), 0.5 * self.h * p11)
        GL.glUniform3fv(GL.glGetUniformLocation(prog, "u_dirs"), len(self.dirs), self.dirs)

    def upload(self, frame) -> None:
        super().upload(frame)
        if self.back_layer:
            gl.upload_texture(self.back, np.asarray(frame["depth_back"], np.float32), GL.GL_R32F)

    def draw(self) -> None:
        GL.glActiveTexture(GL.GL_TEXTURE4)
        GL.glBindTexture(GL.GL_TEXTURE_2D, self.back)
        super().draw()

    def release(self) -> None:
        GL.glDeleteProgram(self.prog)
        GL.glDeleteTextures(1, [self.back])
        super().release()


def trace_predictor(rays: int, steps: int, thickness: float, facets: bool, **options):
    """The trace as a predictor; ``options``: :class:`ScreenSpaceTrace`'s keywords (back_layer, crossing,
    bias, blur, start_px)."""

    def run(frame, radius: float) -> np.ndarray:
        h, w = np.shape(frame["mask"])
        with ScreenSpaceTrace(w, h, radius, rays, steps, thickness, facets, **options) as p:
            p.upload(frame)
            p.draw()
            out = p.read()
        return np.where(np.asarray(frame["mask"], bool), out, np.float32(1.0)).astype(np.float32)

    return run


def _add_back_layer(frames: Path) -> None:
    """The frames' dataset with its back layer (rendered beside its shards if it lacks one)."""
    from neuralao.pipeline.datasets.dataset import DatasetSettings, build_dataset
    from neuralao.runtime.foundation.settings import from_dict

    ds = open_dataset(frames)
    if ds.back_layer is None:
        settings = from_dict(DatasetSettings, ds.manifest["config"])
        build_dataset(replace(settings, back_layer=True), frames, Path("."), progress=False)


def time_pass(make, frame, repeats: int) -> float:
    """Median seconds of draw + glFinish, the G-buffer resident."""
    with make() as p:
        p.upload(frame)
        for _ in range(2):
            p.draw()
        GL.glFinish()
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            p.draw()
            GL.glFinish()
            times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", default="configs/eval.json")
    p.add_argument("--frames", default="build/bench/error_bands/frames/256x256", type=Path)
    p.add_argument("--rays", nargs="+", type=int, default=[8, 16])
    p.add_argument("--steps", type=int, default=8)
    p.add_argument("--thickness", nargs="+", type=float, default=[1.0, 0.25], help="x the radius")
    p.add_argument("--facets", action="store_true", help="also with normals of the facets the depth shows")
    p.add_argument(
        "--back-layer",
        action="store_true",
        help="also with the G-buffer's back layer as each pixel's thickness (the prior where it is thin); "
        "adds the layer to the frames if they lack it",
    )
    p.add_argument(
        "--crossing",
        action="store_true",
        help="also with the crossing test (a sample behind the surface seen at its pixel counts however deep "
        "when the previous sample was in front of it)",
    )
    p.add_argument(
        "--bias",
        type=float,
        default=0.02,
        help="x the radius: depth behind a surface that is not yet occlusion",
    )
    p.add_argument("--no-blur", action="store_true", help="also without the 4x4 blur")
    p.add_argument("--start-px", type=float, default=1.3, help="pixels from the origin to the first sample")
    p.add_argument("--time-size", nargs=2, type=int, default=[1920, 1080], metavar=("W", "H"))
    p.add_argument("--mesh", default="sponza_partial", help="scene of the timed frame")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", default="build/bench/ssrt_thickness", type=Path)
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        return run(args)
    except NeuralaoError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1


def run(args: argparse.Namespace) -> int:
    if min(args.rays) < 1 or args.steps < 1 or not min(args.thickness) > 0:
        raise NeuralaoError("--rays and --steps must be >= 1 and --thickness > 0")
    full = load_settings(EvalSettings, args.config)
    settings = _bands.select_categories(full, None, False)
    kept = {c.name for c in settings.categories}
    if not (args.frames / "manifest.json").is_file():
        raise NeuralaoError(f"no frames at {args.frames}: build them with bench/ao_error_bands.py first")
    if args.back_layer:
        _add_back_layer(args.frames)
    methods = {"gtao": screen_space_predictor("gtao")}
    for rays in args.rays:
        for t in args.thickness:
            for facets in (False, True) if args.facets else (False,):
                for back in (False, True) if args.back_layer else (False,):
                    for cross in (False, True) if args.crossing else (False,):
                        for blur in (True, False) if args.no_blur else (True,):
                            tags = ("-facets" if facets else "") + ("-2L" if back else "")
                            tags += ("-x" if cross else "") + ("" if blur else "-noblur")
                            name = f"trace-{rays}x{args.steps}-T{t:g}{tags}"
                            methods[name] = trace_predictor(
                                rays,
                                args.steps,
                                t,
                                facets,
                                back_layer=back,
                                crossing=cross,
                                bias=args.bias,
                                blur=blur,
                                start_px=args.start_px,
                            )
    rows = []
    for frame in open_dataset(args.frames).frames(split="test"):
        category = category_of(frame["scene"], full)
        if category in kept:
            for row in score_frame(frame, methods, flip=False):
                rows.append(row | {"category": category})
    if not rows:
        raise NeuralaoError("no (frame, radius) pair with valid foreground pixels")
    groups = _bands.camera_groups(settings) | {c: [c] for c in sorted(kept)}
    lines = ["| method | " + " | ".join(groups) + " |", "|---|" + "---:|" * len(groups)]
    summary = {}
    for m in methods:
        cells = []
        for g, cats in groups.items():
            mine = [r for r in rows if r["method"] == m and r["category"] in cats]
            ref = [r for r in rows if r["method"] == "gtao" and r["category"] in cats]
            rmse = np.mean([r["rmse"] for r in mine]) / np.mean([r["rmse"] for r in ref])
            ssim = np.mean([r["ssim"] for r in mine]) / np.mean([r["ssim"] for r in ref])
            summary.setdefault(m, {})[g] = {"rmse_ratio": float(rmse), "ssim_ratio": float(ssim)}
            cells.append(f"{rmse:.3f} / {ssim:.3f}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    times = {}
    if min(args.time_size) > 0:
        from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
        from neuralao.pipeline.geometry.camera import interior
        from neuralao.pipeline.geometry.scene import load_scene

        scene = load_scene(args.mesh)
        radius = 0.25 * scene.diagonal
        with GBufferRenderer(scene) as r:
            frame = r.render(interior(scene, 1, *args.time_size, seed=0)[0])
        times["gtao"] = time_pass(lambda: ScreenSpaceAO("gtao", *args.time_size, radius), frame, args.repeats)
        for rays in args.rays:
            times[f"trace-{rays}x{args.steps}"] = time_pass(
                lambda rays=rays: ScreenSpaceTrace(
                    *args.time_size, radius, rays, args.steps, 1.0, False, crossing=args.crossing
                ),
                frame,
                args.repeats,
            )
        lines += [
            "",
            f"GL time at {args.time_size[0]}x{args.time_size[1]} / GTAO's: "
            + ", ".join(f"{m} {t / times['gtao']:.2f}x" for m, t in times.items() if m != "gtao"),
        ]
    text = "RMSE / SSIM as ratios to GTAO's (mean over (frame, radius) pairs)\n\n" + "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "ssrt_thickness.json", {"summary": summary, "seconds": times, "rows": rows})
    write_text(args.out / "ssrt_thickness.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
