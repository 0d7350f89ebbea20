"""Baselines for the speed-vs-error report, run on the same G-buffer frames as the neural models.

* **SSAO**: classic Crytek-style screen-space AO in its normal-oriented hemisphere form (kernel of
  ``samples`` points, seeded; 4x4 tile of seeded random rotations; range check; depth bias), then a
  4x4 foreground-only blur (the pass that removes the rotation pattern, part of the method's cost).
* **GTAO** (Jimenez et al. 2016, as Intel's XeGTAO structures it): horizon search along ``slices``
  screen directions, cosine-weighted visibility integrated analytically per slice; same noise tile
  and blur.
* **Baked vertex AO** shown per pixel: per-vertex values interpolated with the barycentric
  coordinates of each pixel's surface point in its triangle (``tri_id`` + world position), i.e.
  what a vertex-colour draw of the mesh shows; its cost is timed with a real GL vertex-colour draw
  (:func:`neuralao.runtime.glsl_runner.time_vertex_colour`).
* **Just trace it**: Embree AO of every pixel at a low ray count (4, 16, 64) through
  :class:`neuralao.pipeline.tracing.labeller.Labeller` (CPU, ``workers`` threads): the quality a real-time
  ray tracer at that budget would reach, timed on this machine's CPU.

Both screen-space passes are GLSL fragment shaders (text in :mod:`neuralao.runtime.baseline_templates`)
run in the same headless GL context as the generated neural shaders, reading RGBA32F textures:
camera-space position (xyz) + foreground mask (w), and the camera-space normal. Their radius is in
scene units; the report passes the labels' ``max_distance`` (``max_distance_rel`` x the scene's
bounding-box diagonal), so every method is asked for the same AO. Output: (H, W) float32
accessibility, 1 on background.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from neuralao.export.glsl import glsl_float
from neuralao.runtime import gl
from neuralao.runtime.baseline_templates import fill
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.gl import GL
from neuralao.runtime.glsl_runner import time_vertex_colour

Method = Literal["ssao", "gtao"]


@dataclass
class SSAOSettings:
    # Hemisphere kernel size (Crytek's original used 16).
    samples: int = 16
    # Depth bias as a fraction of the radius (avoids self-occlusion acne on flat surfaces).
    bias_rel: float = 0.02
    # Side of the rotation-noise tile; the blur window has the same size.
    noise_size: int = 4
    # Run the noise-removing blur pass (the classic pipeline does).
    blur: bool = True
    # Seed of the kernel and of the rotation noise.
    seed: int = 0


@dataclass
class GTAOSettings:
    # Slice directions per pixel (rotated per pixel by the noise tile).
    slices: int = 4
    # Horizon samples per side of each slice.
    steps: int = 8
    # Fraction of the radius over which an occluder's weight fades to zero (binary labels: small).
    falloff: float = 0.2
    # Side of the noise tile; the blur window has the same size.
    noise_size: int = 4
    # Run the noise-removing blur pass.
    blur: bool = True
    # Seed of the noise tile.
    seed: int = 0
    # Thickness heuristic of Jimenez et al. 2016 (sec. 4.3), the blend beta in [0, 1): walking a slice
    # side's samples from near to far, a sample below the current horizon pulls the horizon toward it,
    # h = mix(h, h_sample, beta) (a sample above still raises it to h_sample), on the assumption that an
    # occluder that rose above is thin; h_sample is the falloff-weighted horizon cosine the max takes
    # (background and off-screen samples are still skipped). 0: off, plain GTAO's exact shader.
    # Against the evaluation's ray-traced labels it raised RMSE at every beta tried, most on isolated
    # objects (bench/gtao_thickness.py): GTAO here under-occludes on average, and the heuristic cannot
    # tell a thin occluder from a bump.
    thickness_blend: float = 0.0
    # XeGTAO's thin occluder compensation c >= 0: an occluder's falloff distance is measured with its
    # depth offset (camera-space z) stretched by 1 + c, so samples far in front of or behind the pixel
    # fade out sooner (XeGTAO suggests 0 to 0.7). 0: off. Also raised RMSE (bench/gtao_thickness.py).
    thin_occluder_compensation: float = 0.0


# --------------------------------------------------------------------------- inputs


def projection_scale(yfov: float, width: int, height: int) -> tuple[float, float]:
    """(P00, P11) of the OpenGL perspective matrix: (f / aspect, f), f = 1 / tan(yfov / 2)."""
    f = 1.0 / math.tan(float(yfov) / 2.0)
    return f / (width / height), f


def camera_space_position(frame: FrameLike) -> np.ndarray:
    """(H, W, 3) float32 camera-space points of the pixel-centre rays at the frame's linear depth
    (OpenGL camera, -z forward; zero on background)."""
    depth = np.asarray(frame["depth"], dtype=np.float64)
    h, w = depth.shape
    t = math.tan(float(frame["yfov"]) / 2.0)
    x = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) * t * (w / h)
    y = (1.0 - (np.arange(h) + 0.5) / h * 2.0) * t
    pos = np.stack([x[None, :] * depth, y[:, None] * depth, -depth], axis=-1)
    return pos.astype(np.float32)


def gbuffer_textures(frame: FrameLike) -> tuple[np.ndarray, np.ndarray]:
    """The two RGBA32F inputs: position (H, W, 4) = camera-space xyz + mask, normal (H, W, 4)."""
    for key in ("depth", "normal_cam", "mask", "yfov"):
        if key not in frame:
            raise NeuralaoError(f"frame has no {key!r} channel")
    mask = np.asarray(frame["mask"], dtype=bool)
    if mask.ndim != 2 or mask.shape[0] < 1 or mask.shape[1] < 1:
        raise NeuralaoError(f"frame mask must be (H, W) with H, W >= 1, got {mask.shape}")
    pos = np.zeros((*mask.shape, 4), np.float32)
    pos[..., :3] = np.where(mask[..., None], camera_space_position(frame), 0.0)
    pos[..., 3] = mask
    nrm = np.zeros((*mask.shape, 4), np.float32)
    nrm[..., :3] = np.where(mask[..., None], np.nan_to_num(np.asarray(frame["normal_cam"], np.float32)), 0.0)
    return pos, nrm


def ssao_kernel(samples: int, seed: int = 0) -> np.ndarray:
    """(samples, 3) float32 points in the unit hemisphere around +z (Chapman 2013): random directions
    with z > 0.05 (no grazing samples that only measure the bias), random length, then scaled by
    lerp(0.1, 1, (i / samples)^2) so samples cluster near the centre."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(samples, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    low = d[:, 2] < 0.05
    d[low, 2] = 0.05
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    length = rng.uniform(0.0, 1.0, samples)
    scale = 0.1 + 0.9 * (np.arange(samples) / samples) ** 2
    return (d * (length * scale)[:, None]).astype(np.float32)


def noise_tile(size: int, seed: int = 0, kind: Method = "ssao") -> np.ndarray:
    """(size, size, 4) float32. SSAO: random unit vectors in the xy plane (rotation about the normal);
    GTAO: (slice rotation, step jitter) as a stratified shuffle of [0, 1) in x and uniform in y."""
    rng = np.random.default_rng(seed + 7919)
    tile = np.zeros((size, size, 4), np.float32)
    if kind == "ssao":
        a = rng.uniform(0.0, 2.0 * np.pi, (size, size))
        tile[..., 0], tile[..., 1] = np.cos(a), np.sin(a)
    else:
        n = size * size
        tile[..., 0] = ((rng.permutation(n) + rng.uniform(0.0, 1.0, n)) / n).reshape(size, size)
        tile[..., 1] = rng.uniform(0.0, 1.0, (size, size))
    return tile


# --------------------------------------------------------------------------- GL passes

_PROGRAMS: dict[tuple[str, str], int] = {}


def _program(fragment: str) -> int:
    key = (fill("fullscreen_vertex"), fragment)
    if key not in _PROGRAMS:
        _PROGRAMS[key] = gl.compile_program(vertex=key[0], fragment=fragment)
    return _PROGRAMS[key]


def fragment_source(method: Method, settings: SSAOSettings | GTAOSettings) -> str:
    """The AO fragment shader of ``method`` with ``settings`` baked in."""
    inputs, surface = fill("gbuffer_inputs"), fill("surface_at_pixel")
    if method == "ssao":
        return fill(
            "ssao_fragment",
            samples=settings.samples,
            noise_size=settings.noise_size,
            inputs=inputs,
            surface=surface,
        )
    if method == "gtao":
        return fill(
            "gtao_fragment",
            slices=settings.slices,
            steps=settings.steps,
            noise_size=settings.noise_size,
            inputs=inputs,
            surface=surface,
            **_gtao_thickness_fields(settings),
        )
    raise NeuralaoError(f"unknown screen-space AO method {method!r} (ssao or gtao)")


def _gtao_thickness_fields(s: GTAOSettings) -> dict[str, str]:
    """The GTAO template's ``thin0`` / ``thin1`` (slice sides 0, 1): GLSL run after an occluder sample's
    falloff weight ``w`` and before the horizon update ``hc = max(hc, mix(low, shc, w))``. Empty with both
    heuristics off, so the shader is plain GTAO's text exactly."""
    out = {}
    for side in "01":
        hc, low, pad = f"hc{side}", f"low{side}", "\n" + " " * 24
        thin = ""
        if s.thin_occluder_compensation > 0:  # XeGTAO: the falloff distance with z stretched by 1 + c
            stretched = f"length(vec3(d.xy, d.z * {glsl_float(1.0 + s.thin_occluder_compensation)}))"
            thin += f"{pad}w = clamp({stretched} * falloff_mul + falloff_add, 0.0, 1.0);"
        if s.thickness_blend > 0:
            # Jimenez et al.: h = shc > h ? shc : mix(h, shc, beta), shc the weighted sample as the max
            # takes it. Pulled toward a lower sample here, the max that follows keeps the pull (mix(h,
            # shc, beta) >= shc) or raises h to a higher sample (the pull then a no-op).
            shc = f"mix({low}, dot(d / dist, view_v), w)"
            thin += f"{pad}{hc} = mix({hc}, min({hc}, {shc}), {glsl_float(s.thickness_blend)});"
        out[f"thin{side}"] = thin
    return out


def blur_source(size: int) -> str:
    return fill("blur_fragment", size=size, half=size // 2)


def default_settings(method: Method) -> SSAOSettings | GTAOSettings:
    if method == "ssao":
        return SSAOSettings()
    if method == "gtao":
        return GTAOSettings()
    raise NeuralaoError(f"unknown screen-space AO method {method!r} (ssao or gtao)")


def _check(method: Method, settings: SSAOSettings | GTAOSettings, radius: float) -> None:
    if not (math.isfinite(radius) and radius > 0):
        raise NeuralaoError(f"AO radius must be a positive finite distance, got {radius}")
    if settings.noise_size < 1:
        raise NeuralaoError(f"noise_size must be >= 1, got {settings.noise_size}")
    counts = ("samples",) if method == "ssao" else ("slices", "steps")
    for name in counts:
        if getattr(settings, name) < 1:
            raise NeuralaoError(f"{method} {name} must be >= 1, got {getattr(settings, name)}")
    if method == "gtao":
        beta, c = settings.thickness_blend, settings.thin_occluder_compensation
        if not (math.isfinite(beta) and 0.0 <= beta < 1.0):
            raise NeuralaoError(f"gtao thickness_blend must be a finite blend in [0, 1), got {beta}")
        if not (math.isfinite(c) and c >= 0.0):
            raise NeuralaoError(f"gtao thin_occluder_compensation must be finite and >= 0, got {c}")


class ScreenSpaceAO:
    """One screen-space AO pipeline (AO pass + optional blur) sized for one resolution.

    ``upload(frame)`` sends the G-buffer, ``draw()`` runs the passes on the GPU, ``read()`` returns
    (H, W) float32. Release GL objects with :meth:`release` (or use it as a context manager).
    """

    def __init__(self, method: Method, width: int, height: int, radius: float, settings=None):
        settings = settings if settings is not None else default_settings(method)
        _check(method, settings, radius)
        gl.context()
        self.method, self.settings, self.radius = method, settings, float(radius)
        self.w, self.h = int(width), int(height)
        self.vao = gl.context().empty_vao
        self.prog = _program(fragment_source(method, settings))
        self.blur = _program(blur_source(settings.noise_size)) if settings.blur else None
        self.position = gl.create_texture(self.w, self.h, GL.GL_RGBA32F)
        self.normal = gl.create_texture(self.w, self.h, GL.GL_RGBA32F)
        self.noise = gl.create_texture(
            settings.noise_size,
            settings.noise_size,
            GL.GL_RGBA32F,
            noise_tile(settings.noise_size, settings.seed, method),
        )
        self.raw = gl.create_texture(self.w, self.h, GL.GL_R32F)
        self.raw_fbo = gl.create_framebuffer([self.raw], self.w, self.h, depth=False)
        if self.blur is not None:
            self.out = gl.create_texture(self.w, self.h, GL.GL_R32F)
            self.out_fbo = gl.create_framebuffer([self.out], self.w, self.h, depth=False)
        else:
            self.out, self.out_fbo = self.raw, None
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        self.yfov: float | None = None

    def upload(self, frame: FrameLike) -> None:
        pos, nrm = gbuffer_textures(frame)
        if pos.shape[:2] != (self.h, self.w):
            raise NeuralaoError(
                f"frame is {pos.shape[1]}x{pos.shape[0]}, this pass was made for {self.w}x{self.h}"
            )
        gl.upload_texture(self.position, pos, GL.GL_RGBA32F)
        gl.upload_texture(self.normal, nrm, GL.GL_RGBA32F)
        self.yfov = float(frame["yfov"])

    def _uniforms(self) -> None:
        prog, s = self.prog, self.settings
        p00, p11 = projection_scale(self.yfov, self.w, self.h)
        GL.glUniform2f(GL.glGetUniformLocation(prog, "u_proj"), p00, p11)
        GL.glUniform1f(GL.glGetUniformLocation(prog, "u_radius"), self.radius)
        if self.method == "ssao":
            GL.glUniform1f(GL.glGetUniformLocation(prog, "u_bias"), s.bias_rel * self.radius)
            kernel = ssao_kernel(s.samples, s.seed)
            GL.glUniform3fv(GL.glGetUniformLocation(prog, "u_kernel"), s.samples, kernel)
        else:
            GL.glUniform1f(GL.glGetUniformLocation(prog, "u_falloff"), s.falloff)
            GL.glUniform1f(GL.glGetUniformLocation(prog, "u_pixels_per_unit"), 0.5 * self.h * p11)

    def draw(self) -> None:
        if self.yfov is None:
            raise NeuralaoError("upload a frame before drawing")
        for cap in (GL.GL_DEPTH_TEST, GL.GL_BLEND, GL.GL_CULL_FACE, GL.GL_SCISSOR_TEST):
            GL.glDisable(cap)
        GL.glViewport(0, 0, self.w, self.h)
        GL.glBindVertexArray(self.vao)
        for unit, tex in ((0, self.position), (1, self.normal), (2, self.noise)):
            GL.glActiveTexture(GL.GL_TEXTURE0 + unit)
            GL.glBindTexture(GL.GL_TEXTURE_2D, tex)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self.raw_fbo)
        GL.glUseProgram(self.prog)
        self._uniforms()
        GL.glDrawArrays(GL.GL_TRIANGLES, 0, 3)
        if self.blur is not None:
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self.out_fbo)
            GL.glActiveTexture(GL.GL_TEXTURE3)
            GL.glBindTexture(GL.GL_TEXTURE_2D, self.raw)
            GL.glUseProgram(self.blur)
            GL.glDrawArrays(GL.GL_TRIANGLES, 0, 3)
        GL.glActiveTexture(GL.GL_TEXTURE0)
        GL.glUseProgram(0)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)

    def read(self) -> np.ndarray:
        return gl.read_texture(self.out, self.w, self.h, GL.GL_R32F)[..., 0].copy()

    def read_raw(self) -> np.ndarray:
        """The AO pass before its blur (what :meth:`read` gives where the settings have no blur)."""
        return gl.read_texture(self.raw, self.w, self.h, GL.GL_R32F)[..., 0].copy()

    def release(self) -> None:
        fbos = [f for f in (self.raw_fbo, self.out_fbo) if f is not None]
        GL.glDeleteFramebuffers(len(fbos), fbos)
        texs = [self.position, self.normal, self.noise, self.raw] + (
            [self.out] if self.out != self.raw else []
        )
        GL.glDeleteTextures(len(texs), texs)

    def __enter__(self) -> ScreenSpaceAO:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def gtao_settings_entry(settings: GTAOSettings) -> dict:
    """``settings`` as JSON-ready data, a thickness heuristic only when it is on (so plain GTAO's entry,
    and every key or manifest made from it, is what it was before the heuristics existed)."""
    s = settings
    entry = {
        "slices": s.slices,
        "steps": s.steps,
        "falloff": s.falloff,
        "noise_size": s.noise_size,
        "blur": s.blur,
        "seed": s.seed,
    }
    for name in ("thickness_blend", "thin_occluder_compensation"):
        if getattr(s, name) != 0:
            entry[name] = float(getattr(s, name))
    return entry


def gtao_pass_description(settings: GTAOSettings | None = None) -> dict:
    """How an engine runs :class:`ScreenSpaceAO`'s GTAO exactly as it runs here (an export's manifest
    entry beside the shaders of :func:`fragment_source` and :func:`blur_source`): texture bindings,
    the noise tile's texels, and each uniform as a number or the formula :meth:`ScreenSpaceAO._uniforms`
    computes. JSON-ready; float32 values survive JSON exactly (a double holds every float32)."""
    s = settings if settings is not None else GTAOSettings()
    _check("gtao", s, 1.0)
    # GL rows bottom up, the order glTexImage2D takes (gl.upload_texture flips the top-down tile)
    tile = noise_tile(s.noise_size, s.seed, "gtao")[::-1]
    return {
        "settings": gtao_settings_entry(s),
        "textures": {"u_position": 0, "u_normal": 1, "u_noise": 2},
        "noise": {
            "binding": 2,
            "width": s.noise_size,
            "height": s.noise_size,
            "format": "RGBA32F",
            "texels": [float(v) for v in tile.reshape(-1)],
            "order": "RGBA per texel, row 0 = GL row 0 (as glTexImage2D takes it); nearest, fetched "
            "with texelFetch at pixel % noise_size",
        },
        "uniforms": {
            "u_proj": {"type": "vec2", "formula": "(P00, P11) = (f * H / W, f), f = 1 / tan(yfov / 2)"},
            "u_radius": {
                "type": "float",
                "formula": "R, the AO radius in scene units (the network's radius input rho is R / (m * "
                "tan(yfov / 2)), m the mean foreground depth of the G-buffer the network reads)",
            },
            "u_falloff": {"type": "float", "value": float(s.falloff)},
            "u_pixels_per_unit": {"type": "float", "formula": "0.5 * H * P11 (H: this pass's height)"},
        },
        "output": "R32F: accessibility in [0, 1], 1 on background",
        "blur": {"textures": {"u_position": 0, "u_raw": 3}, "window": s.noise_size} if s.blur else None,
    }


def run_screen_space(frame: FrameLike, method: Method, radius: float, settings=None) -> np.ndarray:
    """AO (H, W) float32 of ``method`` ("ssao" | "gtao") on a G-buffer frame; 1 on background.

    frame : depth (H, W), normal_cam (H, W, 3), mask (H, W), yfov; radius : scene units.
    """
    h, w = np.shape(frame["mask"])
    with ScreenSpaceAO(method, w, h, radius, settings) as p:
        p.upload(frame)
        p.draw()
        out = p.read()
    return np.where(np.asarray(frame["mask"], bool), out, np.float32(1.0)).astype(np.float32)


def run_ssao(frame: FrameLike, radius: float, settings: SSAOSettings | None = None) -> np.ndarray:
    """Normal-oriented hemisphere SSAO of ``frame``: (H, W) float32, 1 on background."""
    return run_screen_space(frame, "ssao", radius, settings)


def run_gtao(frame: FrameLike, radius: float, settings: GTAOSettings | None = None) -> np.ndarray:
    """GTAO of ``frame``: (H, W) float32, 1 on background."""
    return run_screen_space(frame, "gtao", radius, settings)


def run_gtao_both(
    frame: FrameLike, radius: float, settings: GTAOSettings | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """GTAO of ``frame`` after and before its blur, from one draw: two (H, W) float32, 1 on background.
    The second is :func:`run_gtao` with the same settings but ``blur=False``."""
    s = settings if settings is not None else GTAOSettings()
    if not s.blur:
        raise NeuralaoError("run_gtao_both needs GTAO settings with the blur on")
    h, w = np.shape(frame["mask"])
    with ScreenSpaceAO("gtao", w, h, radius, s) as p:
        p.upload(frame)
        p.draw()
        out, raw = p.read(), p.read_raw()
    fg = np.asarray(frame["mask"], bool)
    return tuple(np.where(fg, a, np.float32(1.0)).astype(np.float32) for a in (out, raw))


def hybrid_gtao(
    frame: FrameLike, radius: float, blur: bool = True, raw: bool = False
) -> dict[str, np.ndarray]:
    """The GTAO images a hybrid reads at ``radius``: ``{"gtao": ...}`` (with or without GTAO's blur) and,
    with ``raw``, ``"gtao_raw"`` as well (the pass before the blur, from the same draw)."""
    if raw:
        blurred, before = run_gtao_both(frame, radius, GTAOSettings(blur=True))
        return {"gtao": blurred, "gtao_raw": before}
    return {"gtao": run_gtao(frame, radius, GTAOSettings(blur=blur))}


def time_screen_space(
    frame: FrameLike, method: Method, radius: float, settings=None, repeats: int = 20, warmup: int = 3
) -> float:
    """Median seconds per frame of the AO pass (+ blur) on the GPU, G-buffer already resident
    (as it is in an engine); each timed frame ends with ``glFinish``."""
    h, w = np.shape(frame["mask"])
    with ScreenSpaceAO(method, w, h, radius, settings) as p:
        p.upload(frame)
        return gl.median_frame_seconds(p.draw, repeats, warmup)


# --------------------------------------------------------------------------- baked vertex AO


def barycentric(scene, tri: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (k, 3) float64 of ``points`` (k, 3) in triangles ``tri`` (k,),
    clipped to >= 0 and renormalised (points on edges may round slightly outside)."""
    t = scene.triangles[tri]
    v0, v1, v2 = t[:, 0], t[:, 1], t[:, 2]
    e0, e1, d = v1 - v0, v2 - v0, np.asarray(points, np.float64) - v0
    d00 = np.einsum("kc,kc->k", e0, e0)
    d01 = np.einsum("kc,kc->k", e0, e1)
    d11 = np.einsum("kc,kc->k", e1, e1)
    d20 = np.einsum("kc,kc->k", d, e0)
    d21 = np.einsum("kc,kc->k", d, e1)
    den = d00 * d11 - d01 * d01
    den = np.where(np.abs(den) > 0, den, 1.0)
    b1 = (d11 * d20 - d01 * d21) / den
    b2 = (d00 * d21 - d01 * d20) / den
    bary = np.clip(np.stack([1.0 - b1 - b2, b1, b2], axis=1), 0.0, None)
    s = bary.sum(axis=1, keepdims=True)
    return np.where(s > 0, bary / np.where(s > 0, s, 1.0), 1.0 / 3.0)


def vertex_ao_image(scene, vertex_ao: np.ndarray, frame: FrameLike) -> np.ndarray:
    """Baked per-vertex AO as a vertex-colour draw shows it: (H, W) float32, 1 on background.

    Each foreground pixel interpolates the three corner values of triangle ``tri_id`` with the
    barycentric coordinates of its world ``position`` (perspective-correct, like GL's varyings).
    """
    tri_id = np.asarray(frame["tri_id"]).astype(np.int64)
    vertex_ao = np.asarray(vertex_ao, np.float64)
    if vertex_ao.shape != (len(scene.vertices),):
        raise NeuralaoError(
            f"vertex AO must have one value per vertex ({len(scene.vertices)}), got {vertex_ao.shape}"
        )
    out = np.ones(tri_id.shape, np.float32)
    fg = tri_id >= 0
    if fg.any():
        tri = tri_id[fg]
        if tri.max() >= len(scene.faces):
            raise NeuralaoError("frame tri_id does not belong to this scene")
        bary = barycentric(scene, tri, np.asarray(frame["position"], np.float64)[fg])
        out[fg] = np.einsum("kc,kc->k", bary, vertex_ao[scene.faces[tri]])
    return out


def time_vertex_ao(scene, camera, vertex_ao: np.ndarray | None = None, repeats: int = 20) -> float:
    """Median seconds per frame of the GL vertex-colour draw of the mesh (the engine's baked AO)."""
    # Import cost: neuralao.runtime.glsl_runner loads the GLSL generator and onnx (~1.7 s measured), which the
    # screen-space baselines never need.

    return time_vertex_colour(scene, camera, repeats=repeats, ao=vertex_ao)


# --------------------------------------------------------------------------- low-ray tracing


def traced_ao(labeller, frame: FrameLike, rays: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """Embree AO of every foreground pixel at ``rays`` rays (the labeller's kernel and distances).

    labeller : neuralao.pipeline.tracing.labeller.Labeller of the frame's scene (its settings are restored
    afterwards). Returns ao (H, W) float32 (1 on background), valid (H, W) bool and the wall seconds of the
    trace.
    """
    if rays < 1:
        raise NeuralaoError(f"rays must be >= 1, got {rays}")
    saved = labeller.settings
    labeller.settings = replace(saved, rays=int(rays), seed=int(seed))
    try:
        t0 = time.perf_counter()
        ao, valid = labeller.label_frame(frame)
        seconds = time.perf_counter() - t0
    finally:
        labeller.settings = saved
    return ao, valid, seconds
