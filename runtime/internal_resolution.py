"""Screen-space AO at an internal resolution: point-sample the G-buffer down, run the network there,
upsample its AO with a depth- and normal-aware (joint bilateral) filter.

Why: the U-Net's receptive field is fixed in pixels, while its radius input is measured in units of
half the screen height. Trained on frames ``internal_height`` pixels tall, it has learned how many
pixels a radius covers at that height. At 1920x1080 the same radius covers about four times more
pixels, at 128x128 half as many. Running the network on a G-buffer resampled to the height it was
trained at (down, or up for shorter frames) shows it the geometry at the scale it knows, at any
output resolution, and at 1080p it costs the network a sixteenth of the pixels. Measured with the
shipped default at 128x128 on the test categories: SSIM 0.728 / RMSE 0.119 run as is, 0.773 / 0.104
point-sampled up to 256 rows.

Conventions (the same in the numpy reference here and in the GLSL pass of
:mod:`neuralao.runtime.baseline_templates` ``upsample_fragment``, which the tests hold to each other):

* low-resolution texel ``t`` of an axis of ``n`` texels is the high-resolution pixel
  ``floor((t + 0.5) * N / n)`` of that axis of ``N`` pixels, counted in GL order (row 0 at the
  bottom), so the low G-buffer holds exact samples, never blends across edges;
* a high-resolution pixel blends the 4 x 4 nearest low texels: weight = spatial Gaussian (in low
  texels) x (floor + tangent-plane agreement x normal agreement), background texels excluded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from neuralao.runtime import gl
from neuralao.runtime.baseline_templates import fill
from neuralao.runtime.baselines import _program, camera_space_position, gbuffer_textures
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.frame import FrameLike
from neuralao.runtime.gl import GL  # neuralao.runtime.gl sets PYOPENGL_PLATFORM before PyOpenGL loads


@dataclass(frozen=True)
class UpsampleSettings:
    """Weights of the joint bilateral upsampling (shared by the numpy reference and the GLSL pass)."""

    spatial_sigma: float = 0.6  # Gaussian sigma of the distance to a low texel, in low texels
    plane_sigma: float = 0.03  # tangent-plane distance (relative to depth) at which weight drops by 1/e
    normal_power: float = 8.0  # exponent of the normals' cosine
    floor: float = 1e-3  # share of the spatial weight kept where geometry disagrees (thin parts)


def internal_size(width: int, height: int, internal_height: int | None, up: bool = True) -> tuple[int, int]:
    """(w, h) the network runs at for a ``width`` x ``height`` frame: ``internal_height`` rows (same
    aspect ratio, at least 1 column), whether the frame is taller or shorter (shorter frames are
    point-sampled *up*), so the network always sees a radius cover the same number of pixels;
    None -> the frame's own size. ``up`` False (a network told its pixel scale, input contract 5):
    ``internal_height`` is the most rows it runs at, and shorter frames keep their own size."""
    if internal_height is None:
        return int(width), int(height)
    if internal_height < 1:
        raise NeuralaoError(f"internal height must be >= 1, got {internal_height}")
    if not up and height <= internal_height:
        return int(width), int(height)
    return max(1, round(width * internal_height / height)), int(internal_height)


def sample_index(low: int, high: int) -> np.ndarray:
    """(low,) int: the high-resolution pixel each low texel samples along one axis (GL order)."""
    return ((2 * np.arange(low, dtype=np.int64) + 1) * high) // (2 * low)


def downsample_frame(frame: FrameLike, width: int, height: int) -> dict:
    """Point-sample every image channel of ``frame`` to ``width`` x ``height`` (scalars kept).

    Rows are counted in GL order (bottom up) to match the GLSL pass, so numpy's top-down rows are
    flipped around the sampling.
    """
    h, w = np.shape(frame["depth"])
    rows = h - 1 - sample_index(height, h)[::-1]  # GL-order sampling, expressed in top-down rows
    cols = sample_index(width, w)
    out = {}
    for k, v in frame.items():
        if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[:2] == (h, w):
            out[k] = np.ascontiguousarray(v[rows][:, cols])
        else:
            out[k] = v
    return out


def _positions(frame: FrameLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera-space positions (H, W, 3), unit normals (H, W, 3) and mask (H, W) of a frame, float64."""
    mask = np.asarray(frame["mask"], bool)
    pos = np.where(mask[..., None], camera_space_position(frame), 0.0).astype(np.float64)
    n = np.nan_to_num(np.asarray(frame["normal_cam"], np.float64))
    return pos, np.where(mask[..., None], n, 0.0), mask


def upsample_ao(
    ao_low: np.ndarray, frame: FrameLike, settings: UpsampleSettings = UpsampleSettings(), empty: float = 1.0
) -> np.ndarray:
    """Joint bilateral upsampling of ``ao_low`` (h, w), computed on the point-sampled ``frame``
    (:func:`downsample_frame`), to ``frame``'s resolution. Returns (H, W) float32, 1 on background.

    The numpy reference of the ``upsample_fragment`` GLSL pass (same taps, weights and integer
    sampling), in float64. A low texel's position and normal are those of the high pixel it sampled.
    ``empty``: the value of a foreground pixel with no foreground texel in reach (1: open AO; 0 for an
    upsampled correction).
    """
    hp, hn, hm = _positions(frame)
    # GL order (row 0 at the bottom) throughout, as the fragment shader sees it.
    hp, hn, hm = hp[::-1], hn[::-1], hm[::-1]
    a_low = np.asarray(ao_low, np.float64)[::-1]
    H, W = hm.shape
    h, w = a_low.shape
    rows, cols = sample_index(h, H), sample_index(w, W)
    lp, ln, lm = (a[rows][:, cols] for a in (hp, hn, hm))
    v = (np.arange(H) + 0.5) * h / H - 0.5
    u = (np.arange(W) + 0.5) * w / W - 0.5
    # floor(v), floor(u) in integers, as the shader computes them
    by = ((2 * np.arange(H, dtype=np.int64) + 1) * h - H) // (2 * H) - 1
    bx = ((2 * np.arange(W, dtype=np.int64) + 1) * w - W) // (2 * W) - 1
    depth = np.maximum(-hp[..., 2], 1e-30)
    s = settings
    total = np.zeros((H, W))
    acc = np.zeros((H, W))
    for ty in range(4):
        qy_raw = by + ty
        qy = np.clip(qy_raw, 0, h - 1)
        dy = (qy_raw - v)[:, None]
        for tx in range(4):
            qx_raw = bx + tx
            qx = np.clip(qx_raw, 0, w - 1)
            dx = (qx_raw - u)[None, :]
            spatial = np.exp(-(dx * dx + dy * dy) / (2.0 * s.spatial_sigma**2))
            q_pos, q_n = lp[qy][:, qx], ln[qy][:, qx]
            plane = np.abs(np.sum(q_n * (hp - q_pos), axis=-1)) / (s.plane_sigma * depth)
            agree = np.maximum(np.sum(q_n * hn, axis=-1), 0.0) ** s.normal_power
            weight = spatial * (s.floor + np.exp(-plane * plane) * agree) * lm[qy][:, qx]
            acc += weight * a_low[qy][:, qx]
            total += weight
    out = np.where(total > 0, acc / np.where(total > 0, total, 1.0), empty)
    return np.where(hm, out, 1.0)[::-1].astype(np.float32)


def at_internal_resolution(
    predict,
    internal_height: int | None,
    settings: UpsampleSettings = UpsampleSettings(),
    residual_of: str | None = None,
    up: bool = True,
):
    """Wrap ``predict(frame, radius) -> ao (H, W)`` so it runs at ``internal_height`` rows and is
    resampled to the frame's size (frames shorter than that are point-sampled up, and the AO
    resampled back down with the same filter).

    ``residual_of``: the key of a full-resolution AO image in the frame that ``predict`` refines (a
    hybrid's "gtao"): then the network's *correction* (its AO minus the point-sampled input) is what
    is upsampled, and it is added to the full-resolution image, so the input's own detail survives.
    ``up``: see :func:`internal_size`.
    """

    def scaled(frame: FrameLike, radius: float) -> np.ndarray:
        h, w = np.shape(frame["depth"])
        lw, lh = internal_size(w, h, internal_height, up)
        if (lw, lh) == (w, h):
            return predict(frame, radius)
        low = downsample_frame(frame, lw, lh)
        if residual_of is None:
            return upsample_ao(predict(low, radius), frame, settings)
        correction = predict(low, radius) - np.asarray(low[residual_of], np.float32)
        lifted = upsample_ao(correction, frame, settings, empty=0.0)
        ao = np.clip(np.asarray(frame[residual_of], np.float32) + lifted, 0.0, 1.0)
        return np.where(np.asarray(frame["mask"], bool), ao, np.float32(1.0)).astype(np.float32)

    return scaled


def upsample_source(settings: UpsampleSettings = UpsampleSettings(), empty: float = 1.0) -> str:
    """The GLSL fragment shader of the upsampling pass with ``settings`` baked in; ``empty`` is the value
    of a foreground pixel with no foreground texel in reach (as in :func:`upsample_ao`: 1.0 for AO, 0.0
    for a hybrid's correction)."""
    lit = lambda x: repr(float(x))  # noqa: E731  (a float literal GLSL accepts: 0.6, 1e-3, 8.0)
    for name in ("spatial_sigma", "plane_sigma"):
        if not (math.isfinite(getattr(settings, name)) and getattr(settings, name) > 0):
            raise NeuralaoError(f"upsample {name} must be a positive number, got {getattr(settings, name)}")
    return fill(
        "upsample_fragment",
        spatial_sigma=lit(settings.spatial_sigma),
        plane_sigma=lit(settings.plane_sigma),
        normal_power=lit(settings.normal_power),
        floor=lit(settings.floor),
        empty=lit(empty),
    )


class UpsamplePass:
    """The GLSL upsampling pass for one (low, high) pair of sizes, on the headless GL context: its
    textures (high G-buffer, low AO, low G-buffer targets) and program. :class:`ScalingPasses` fills
    the textures; ``draw()`` runs the pass, ``read()`` returns (H, W) float32 in top-down rows."""

    def __init__(
        self,
        low_size: tuple[int, int],
        size: tuple[int, int],
        settings: UpsampleSettings = UpsampleSettings(),
        empty: float = 1.0,
    ):
        gl.context()
        self.GL, self.gl = GL, gl
        (self.lw, self.lh), (self.w, self.h) = (int(v) for v in low_size), (int(v) for v in size)
        self.prog = _program(upsample_source(settings, empty))
        self.vao = gl.context().empty_vao
        make = lambda w, h, fmt: gl.create_texture(w, h, fmt)  # noqa: E731
        self.position, self.normal = make(self.w, self.h, GL.GL_RGBA32F), make(self.w, self.h, GL.GL_RGBA32F)
        self.low_ao = make(self.lw, self.lh, GL.GL_R32F)
        self.low_position = make(self.lw, self.lh, GL.GL_RGBA32F)
        self.low_normal = make(self.lw, self.lh, GL.GL_RGBA32F)
        self.out = make(self.w, self.h, GL.GL_R32F)
        self.fbo = gl.create_framebuffer([self.out], self.w, self.h, depth=False)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)

    def draw(self) -> None:
        GL = self.GL
        for cap in (GL.GL_DEPTH_TEST, GL.GL_BLEND, GL.GL_CULL_FACE, GL.GL_SCISSOR_TEST):
            GL.glDisable(cap)
        GL.glViewport(0, 0, self.w, self.h)
        GL.glBindVertexArray(self.vao)
        units = (
            (0, self.position),
            (1, self.normal),
            (4, self.low_ao),
            (5, self.low_position),
            (6, self.low_normal),
        )
        for unit, tex in units:
            GL.glActiveTexture(GL.GL_TEXTURE0 + unit)
            GL.glBindTexture(GL.GL_TEXTURE_2D, tex)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self.fbo)
        GL.glUseProgram(self.prog)
        GL.glDrawArrays(GL.GL_TRIANGLES, 0, 3)
        GL.glActiveTexture(GL.GL_TEXTURE0)
        GL.glUseProgram(0)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)

    def read(self) -> np.ndarray:
        return self.gl.read_texture(self.out, self.w, self.h, self.GL.GL_R32F)[..., 0].copy()

    def release(self) -> None:
        GL = self.GL
        GL.glDeleteFramebuffers(1, [self.fbo])
        GL.glDeleteTextures(
            6, [self.position, self.normal, self.low_ao, self.low_position, self.low_normal, self.out]
        )

    def __enter__(self) -> UpsamplePass:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def vertex_source() -> str:
    """The full-screen-triangle vertex shader both passes draw with (3 vertices, empty VAO)."""
    return fill("fullscreen_vertex")


def downsample_source() -> str:
    """The GLSL fragment shader that point-samples the G-buffer to the internal resolution (two
    targets; ``uniform ivec2 u_low_size`` = that resolution)."""
    return fill("downsample_fragment")


class ScalingPasses:
    """Both GL passes around a network run at the internal resolution: the point-sampling pass (high
    G-buffer -> low position and normal targets) and the upsampling pass (low AO -> high AO). The
    network reads the low targets and writes ``low_ao``; :meth:`draw` runs both passes back to back,
    as a frame does (the network's own passes go between them)."""

    def __init__(
        self,
        low_size: tuple[int, int],
        size: tuple[int, int],
        settings: UpsampleSettings = UpsampleSettings(),
        empty: float = 1.0,
    ):
        self.up = UpsamplePass(low_size, size, settings, empty)
        self.GL, self.gl = GL, gl
        self.prog = _program(downsample_source())
        up = self.up
        self.fbo = gl.create_framebuffer([up.low_position, up.low_normal], up.lw, up.lh, depth=False)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)

    def upload(self, frame: FrameLike, ao_low: np.ndarray | None = None) -> None:
        pos, nrm = gbuffer_textures(frame)
        up, GL = self.up, self.GL
        if pos.shape[:2] != (up.h, up.w):
            raise NeuralaoError(
                f"frame is {pos.shape[1]}x{pos.shape[0]}, these passes were made for {up.w}x{up.h}"
            )
        self.gl.upload_texture(up.position, pos, GL.GL_RGBA32F)
        self.gl.upload_texture(up.normal, nrm, GL.GL_RGBA32F)
        if ao_low is not None:
            self.gl.upload_texture(up.low_ao, np.asarray(ao_low, np.float32)[..., None], GL.GL_R32F)

    def downsample(self) -> None:
        GL, up = self.GL, self.up
        for cap in (GL.GL_DEPTH_TEST, GL.GL_BLEND, GL.GL_CULL_FACE, GL.GL_SCISSOR_TEST):
            GL.glDisable(cap)
        GL.glViewport(0, 0, up.lw, up.lh)
        GL.glBindVertexArray(up.vao)
        for unit, tex in ((0, up.position), (1, up.normal)):
            GL.glActiveTexture(GL.GL_TEXTURE0 + unit)
            GL.glBindTexture(GL.GL_TEXTURE_2D, tex)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self.fbo)
        GL.glDrawBuffers(2, [GL.GL_COLOR_ATTACHMENT0, GL.GL_COLOR_ATTACHMENT1])
        GL.glUseProgram(self.prog)
        GL.glUniform2i(GL.glGetUniformLocation(self.prog, "u_low_size"), up.lw, up.lh)
        GL.glDrawArrays(GL.GL_TRIANGLES, 0, 3)
        GL.glUseProgram(0)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)

    def draw(self) -> None:
        self.downsample()
        self.up.draw()

    def read_low(self) -> tuple[np.ndarray, np.ndarray]:
        """(h, w, 4) position and normal targets of the point-sampling pass, top-down rows."""
        up, GL = self.up, self.GL
        return (
            self.gl.read_texture(up.low_position, up.lw, up.lh, GL.GL_RGBA32F),
            self.gl.read_texture(up.low_normal, up.lw, up.lh, GL.GL_RGBA32F),
        )

    def release(self) -> None:
        self.GL.glDeleteFramebuffers(1, [self.fbo])
        self.up.release()

    def __enter__(self) -> ScalingPasses:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def time_scaling_passes(
    frame: FrameLike, low_size: tuple[int, int], repeats: int = 10, warmup: int = 2
) -> float:
    """Median seconds of the point-sampling and upsampling passes on the GPU for ``frame``'s size
    (G-buffer resident, as in an engine; each timed frame ends with ``glFinish``)."""
    h, w = np.shape(frame["depth"])
    with ScalingPasses(low_size, (w, h)) as p:
        p.upload(frame, np.full((int(low_size[1]), int(low_size[0])), 0.5, np.float32))
        return p.gl.median_frame_seconds(p.draw, repeats, warmup)


def run_upsample_gl(
    ao_low: np.ndarray, frame: FrameLike, settings: UpsampleSettings = UpsampleSettings(), empty: float = 1.0
) -> np.ndarray:
    """:func:`upsample_ao` as the GL passes run it on Mesa (point sampling, then upsampling).
    Returns (H, W) float32, 1 on background."""
    h, w = np.shape(frame["depth"])
    lh, lw = np.shape(ao_low)
    with ScalingPasses((lw, lh), (w, h), settings, empty) as p:
        p.upload(frame, ao_low)
        p.draw()
        out = p.up.read()
    return np.where(np.asarray(frame["mask"], bool), out, np.float32(1.0)).astype(np.float32)
