"""Headless OpenGL 4.5 core context (pyrender's OSMesa or EGL platform) and small GL helpers.

The platform follows ``PYOPENGL_PLATFORM`` (``osmesa`` default, ``egl`` for surfaceless llvmpipe on
Mesa >= 25.1 where OSMesa is gone). One context per process, created lazily and kept current; all
renderers and shader runners in neuralao share it.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.foundation.errors import NeuralaoError

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

from OpenGL import GL  # noqa: E402  (must follow PYOPENGL_PLATFORM)

_CONTEXT = None


@dataclass
class GLInfo:
    platform: str
    version: str
    renderer: str


class _Context:
    def __init__(self) -> None:
        import pyrender

        platform = os.environ.get("PYOPENGL_PLATFORM", "osmesa")
        try:
            # pyrender owns context creation (OSMesaCreateContextAttribs / EGL surfaceless);
            # we only use the context, rendering into our own float framebuffers.
            self.renderer = pyrender.OffscreenRenderer(8, 8)
        except Exception as e:
            raise NeuralaoError(
                f"cannot create a headless GL context with PYOPENGL_PLATFORM={platform}: {e}"
            ) from None
        self.platform = platform
        self.make_current()
        self.info = GLInfo(
            platform,
            GL.glGetString(GL.GL_VERSION).decode(),
            GL.glGetString(GL.GL_RENDERER).decode(),
        )
        # A core profile needs a bound VAO for any draw call, even attribute-less ones.
        self.empty_vao = GL.glGenVertexArrays(1)

    def make_current(self) -> None:
        self.renderer._platform.make_current()


def context() -> _Context:
    """The process-wide GL context, made current."""
    global _CONTEXT
    if _CONTEXT is None:
        _CONTEXT = _Context()
    else:
        _CONTEXT.make_current()
    return _CONTEXT


_STAGES = {
    "vertex": GL.GL_VERTEX_SHADER,
    "fragment": GL.GL_FRAGMENT_SHADER,
    "compute": GL.GL_COMPUTE_SHADER,
    "geometry": GL.GL_GEOMETRY_SHADER,
}


def compile_program(feedback: tuple[str, ...] = (), **sources: str) -> int:
    """Compile and link a program from stage sources, e.g. ``compile_program(vertex=..., fragment=...)``;
    ``feedback`` names vertex outputs captured by transform feedback (interleaved, set before linking).

    Raises :class:`NeuralaoError` with the first line of the driver's log on failure.
    """
    context()
    prog = GL.glCreateProgram()
    shaders = []
    for stage, src in sources.items():
        sh = GL.glCreateShader(_STAGES[stage])
        GL.glShaderSource(sh, src)
        GL.glCompileShader(sh)
        if not GL.glGetShaderiv(sh, GL.GL_COMPILE_STATUS):
            log = GL.glGetShaderInfoLog(sh).decode(errors="replace").strip()
            raise NeuralaoError(f"{stage} shader failed to compile: {log.splitlines()[0] if log else '?'}")
        GL.glAttachShader(prog, sh)
        shaders.append(sh)
    if feedback:
        import ctypes

        names = [ctypes.create_string_buffer(n.encode()) for n in feedback]
        ptrs = (ctypes.c_char_p * len(names))(*[ctypes.addressof(b) for b in names])
        ptrs = ctypes.cast(ptrs, ctypes.POINTER(ctypes.POINTER(ctypes.c_char)))
        GL.glTransformFeedbackVaryings(prog, len(names), ptrs, GL.GL_INTERLEAVED_ATTRIBS)
    GL.glLinkProgram(prog)
    for sh in shaders:
        GL.glDeleteShader(sh)
    if not GL.glGetProgramiv(prog, GL.GL_LINK_STATUS):
        log = GL.glGetProgramInfoLog(prog).decode(errors="replace").strip()
        raise NeuralaoError(f"program failed to link: {log.splitlines()[0] if log else '?'}")
    return prog


_FORMATS = {
    # internal format: (format, type, channels, numpy dtype)
    GL.GL_R32F: (GL.GL_RED, GL.GL_FLOAT, 1, np.float32),
    GL.GL_RG32F: (GL.GL_RG, GL.GL_FLOAT, 2, np.float32),
    GL.GL_RGBA32F: (GL.GL_RGBA, GL.GL_FLOAT, 4, np.float32),
    GL.GL_RGBA16F: (GL.GL_RGBA, GL.GL_FLOAT, 4, np.float32),
    GL.GL_R16F: (GL.GL_RED, GL.GL_FLOAT, 1, np.float32),
    GL.GL_R32I: (GL.GL_RED_INTEGER, GL.GL_INT, 1, np.int32),
    GL.GL_RGBA8: (GL.GL_RGBA, GL.GL_UNSIGNED_BYTE, 4, np.uint8),
}


def create_texture(width: int, height: int, internal=GL.GL_RGBA32F, data: np.ndarray | None = None) -> int:
    """A 2-D texture with nearest filtering and clamped edges (no hardware filtering anywhere).

    data : (H, W, C) or (H, W) array, row 0 at the TOP (flipped here to GL's bottom-up order).
    """
    context()
    fmt, typ, ch, dt = _FORMATS[internal]
    tex = GL.glGenTextures(1)
    GL.glBindTexture(GL.GL_TEXTURE_2D, tex)
    GL.glTexStorage2D(GL.GL_TEXTURE_2D, 1, internal, width, height)
    for p, v in (
        (GL.GL_TEXTURE_MIN_FILTER, GL.GL_NEAREST),
        (GL.GL_TEXTURE_MAG_FILTER, GL.GL_NEAREST),
        (GL.GL_TEXTURE_WRAP_S, GL.GL_CLAMP_TO_EDGE),
        (GL.GL_TEXTURE_WRAP_T, GL.GL_CLAMP_TO_EDGE),
    ):
        GL.glTexParameteri(GL.GL_TEXTURE_2D, p, v)
    if data is not None:
        upload_texture(tex, data, internal)
    return tex


def upload_texture(tex: int, data: np.ndarray, internal=GL.GL_RGBA32F) -> None:
    fmt, typ, ch, dt = _FORMATS[internal]
    arr = np.asarray(data, dtype=dt)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.shape[2] != ch:
        pad = np.zeros((*arr.shape[:2], ch), dtype=dt)
        pad[..., : min(ch, arr.shape[2])] = arr[..., :ch]
        arr = pad
    h, w = arr.shape[:2]
    GL.glPixelStorei(GL.GL_UNPACK_ALIGNMENT, 1)
    GL.glBindTexture(GL.GL_TEXTURE_2D, tex)
    GL.glTexSubImage2D(GL.GL_TEXTURE_2D, 0, 0, 0, w, h, fmt, typ, np.ascontiguousarray(arr[::-1]))


def read_texture(tex: int, width: int, height: int, internal=GL.GL_RGBA32F) -> np.ndarray:
    """(H, W, C) array, row 0 at the top."""
    fmt, typ, ch, dt = _FORMATS[internal]
    GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
    GL.glBindTexture(GL.GL_TEXTURE_2D, tex)
    buf = np.empty((height, width, ch), dtype=dt)
    GL.glGetTexImage(GL.GL_TEXTURE_2D, 0, fmt, typ, buf)
    return buf[::-1].copy()


def create_framebuffer(color_textures: list[int], width: int, height: int, depth: bool = True) -> int:
    """FBO with the given colour attachments (0..n-1) and an optional 32-bit float depth buffer."""
    context()
    fbo = GL.glGenFramebuffers(1)
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fbo)
    for k, tex in enumerate(color_textures):
        GL.glFramebufferTexture2D(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0 + k, GL.GL_TEXTURE_2D, tex, 0)
    if depth:
        rb = GL.glGenRenderbuffers(1)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
        GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_DEPTH_COMPONENT32F, width, height)
        GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_RENDERBUFFER, rb)
    GL.glDrawBuffers(len(color_textures), [GL.GL_COLOR_ATTACHMENT0 + k for k in range(len(color_textures))])
    status = GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER)
    if status != GL.GL_FRAMEBUFFER_COMPLETE:
        raise NeuralaoError(f"framebuffer incomplete (status 0x{int(status):x})")
    return fbo


def create_buffer(
    data: np.ndarray | None = None, nbytes: int | None = None, target=GL.GL_SHADER_STORAGE_BUFFER
) -> int:
    """A buffer object (SSBO by default) filled with ``data`` or ``nbytes`` zero bytes."""
    context()
    buf = GL.glGenBuffers(1)
    GL.glBindBuffer(target, buf)
    if data is not None:
        arr = np.ascontiguousarray(data)
        GL.glBufferData(target, arr.nbytes, arr, GL.GL_DYNAMIC_DRAW)
    else:
        GL.glBufferData(target, int(nbytes or 0), None, GL.GL_DYNAMIC_DRAW)
    return buf


def read_buffer(buf: int, nbytes: int, dtype=np.float32, target=GL.GL_SHADER_STORAGE_BUFFER) -> np.ndarray:
    GL.glBindBuffer(target, buf)
    out = np.empty(nbytes // np.dtype(dtype).itemsize, dtype=dtype)
    GL.glGetBufferSubData(target, 0, nbytes, out)
    return out


def finish() -> None:
    """Block until the GL has finished (for timing)."""
    GL.glFinish()


def median_frame_seconds(frame: Callable[[], None], repeats: int, warmup: int) -> float:
    """Median wall seconds of ``frame()`` (GL work issued by it), after ``warmup`` untimed calls; each
    timed call ends with ``glFinish`` so the GPU's work is inside the measurement."""
    for _ in range(warmup):
        frame()
    finish()
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        frame()
        finish()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))
