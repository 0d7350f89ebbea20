"""Headless OpenGL 4.5 core context (OSMesa or EGL, created with PyOpenGL) and small GL helpers.

The platform follows ``PYOPENGL_PLATFORM`` (``osmesa`` default, ``egl`` for surfaceless llvmpipe on
Mesa >= 25.1 where OSMesa is gone; ``EGL_DEVICE_ID`` picks the EGL device, 0 by default). One context
per process, created lazily and kept current; all renderers and shader runners in neuralao share it.
The context is requested with the attributes pyrender's platforms use (so the driver hands out the
same context), without pyrender itself: a consumer runs this module with PyOpenGL alone.
"""

from __future__ import annotations

import ctypes
import os
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

from OpenGL import GL  # noqa: E402  (must follow PYOPENGL_PLATFORM)

_CONTEXT = None


@dataclass
class GLInfo:
    platform: str
    version: str
    renderer: str


# OSMesa renders into a caller-owned buffer: a tiny RGBA one, since every pass draws into its own FBO.
_OSMESA_SIZE = 8


class _OSMesa:
    """An OSMesa core-profile context (3.3 requested; Mesa gives its highest core version)."""

    def __init__(self) -> None:
        from OpenGL import arrays, osmesa  # the platform module exists only for PYOPENGL_PLATFORM=osmesa

        attrs = arrays.GLintArray.asArray(
            [
                osmesa.OSMESA_FORMAT,
                osmesa.OSMESA_RGBA,
                osmesa.OSMESA_DEPTH_BITS,
                24,
                osmesa.OSMESA_PROFILE,
                osmesa.OSMESA_CORE_PROFILE,
                osmesa.OSMESA_CONTEXT_MAJOR_VERSION,
                3,
                osmesa.OSMESA_CONTEXT_MINOR_VERSION,
                3,
                0,
            ]
        )
        self._make = osmesa.OSMesaMakeCurrent
        self._context = osmesa.OSMesaCreateContextAttribs(attrs, None)
        if not self._context:
            raise RuntimeError("OSMesaCreateContextAttribs returned no context")
        self._buffer = arrays.GLubyteArray.zeros((_OSMESA_SIZE, _OSMESA_SIZE, 4))

    def make_current(self) -> None:
        if not self._make(self._context, self._buffer, GL.GL_UNSIGNED_BYTE, _OSMESA_SIZE, _OSMESA_SIZE):
            raise RuntimeError("OSMesaMakeCurrent failed")


# EGL_EXT_platform_device / EGL_EXT_device_query constants PyOpenGL does not define.
_EGL_PLATFORM_DEVICE_EXT = 0x313F


class _EGL:
    """A surfaceless EGL OpenGL 4.1 core context on device ``EGL_DEVICE_ID`` (default 0)."""

    def __init__(self) -> None:
        from OpenGL import EGL, arrays  # EGL bindings load libEGL: only for PYOPENGL_PLATFORM=egl

        self._egl = EGL
        self._display = self._display_of(int(os.environ.get("EGL_DEVICE_ID", "0")))
        major, minor, count = ctypes.c_long(), ctypes.c_long(), ctypes.c_long()
        configs = (EGL.EGLConfig * 1)()
        config_attrs = arrays.GLintArray.asArray(
            [
                EGL.EGL_SURFACE_TYPE,
                EGL.EGL_PBUFFER_BIT,
                EGL.EGL_BLUE_SIZE,
                8,
                EGL.EGL_RED_SIZE,
                8,
                EGL.EGL_GREEN_SIZE,
                8,
                EGL.EGL_DEPTH_SIZE,
                24,
                EGL.EGL_COLOR_BUFFER_TYPE,
                EGL.EGL_RGB_BUFFER,
                EGL.EGL_RENDERABLE_TYPE,
                EGL.EGL_OPENGL_BIT,
                EGL.EGL_CONFORMANT,
                EGL.EGL_OPENGL_BIT,
                EGL.EGL_NONE,
            ]
        )
        context_attrs = arrays.GLintArray.asArray(
            [
                EGL.EGL_CONTEXT_MAJOR_VERSION,
                4,
                EGL.EGL_CONTEXT_MINOR_VERSION,
                1,
                EGL.EGL_CONTEXT_OPENGL_PROFILE_MASK,
                EGL.EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                EGL.EGL_NONE,
            ]
        )
        if not EGL.eglInitialize(self._display, major, minor):
            raise RuntimeError("eglInitialize failed")
        if not EGL.eglChooseConfig(self._display, config_attrs, configs, 1, count) or count.value < 1:
            raise RuntimeError("eglChooseConfig found no OpenGL config")
        if not EGL.eglBindAPI(EGL.EGL_OPENGL_API):
            raise RuntimeError("eglBindAPI(EGL_OPENGL_API) failed")
        self._context = EGL.eglCreateContext(self._display, configs[0], EGL.EGL_NO_CONTEXT, context_attrs)
        if not self._context:
            raise RuntimeError("eglCreateContext returned no context")

    def _display_of(self, device_id: int):
        """The display of EGL device ``device_id`` (EGL_EXT_device_enumeration), else the default one;
        ``DISPLAY`` is hidden meanwhile so Mesa does not pick an X11 display."""
        EGL = self._egl
        query = _egl_function("eglQueryDevicesEXT", EGL.EGLBoolean)
        platform_display = _egl_function("eglGetPlatformDisplayEXT", EGL.EGLDisplay)
        x_display = os.environ.pop("DISPLAY", None)
        try:
            if query is None or platform_display is None:
                if device_id != 0:
                    raise RuntimeError(f"EGL device {device_id} requested but devices cannot be queried")
                return EGL.eglGetDisplay(EGL.EGL_DEFAULT_DISPLAY)
            from OpenGL._opaque import opaque_pointer_cls

            device_type = opaque_pointer_cls("EGLDeviceEXT")
            n = EGL.EGLint()
            if not query(0, None, ctypes.pointer(n)) or n.value < 1:
                raise RuntimeError("no EGL device found")
            devices = (device_type * n.value)()
            query(n.value, devices, ctypes.pointer(n))
            if not 0 <= device_id < n.value:
                raise RuntimeError(f"EGL_DEVICE_ID {device_id} is outside 0..{n.value - 1}")
            return platform_display(_EGL_PLATFORM_DEVICE_EXT, devices[device_id], None)
        finally:
            if x_display is not None:
                os.environ["DISPLAY"] = x_display

    def make_current(self) -> None:
        EGL = self._egl
        if not EGL.eglMakeCurrent(self._display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, self._context):
            raise RuntimeError("eglMakeCurrent failed")


def _egl_function(name: str, restype, *argtypes):
    """An EGL extension function by name (ctypes), or None where the driver lacks it."""
    from OpenGL import EGL

    address = EGL.eglGetProcAddress(name)
    if address is None:
        return None
    proto = ctypes.CFUNCTYPE(restype)
    proto.argtypes = argtypes
    return proto(address)


_PLATFORMS = {"osmesa": _OSMesa, "egl": _EGL}


class _Context:
    def __init__(self) -> None:
        platform = os.environ.get("PYOPENGL_PLATFORM", "osmesa")
        try:
            if platform not in _PLATFORMS:
                raise ValueError(f"Unsupported PyOpenGL platform: {platform}")
            # We only use the context, rendering into our own float framebuffers.
            self._platform = _PLATFORMS[platform]()
            self.make_current()
        except Exception as e:
            raise NeuralaoError(
                f"cannot create a headless GL context with PYOPENGL_PLATFORM={platform}: {e}"
            ) from None
        self.platform = platform
        self.info = GLInfo(
            platform,
            GL.glGetString(GL.GL_VERSION).decode(),
            GL.glGetString(GL.GL_RENDERER).decode(),
        )
        # A core profile needs a bound VAO for any draw call, even attribute-less ones.
        self.empty_vao = GL.glGenVertexArrays(1)

    def make_current(self) -> None:
        self._platform.make_current()


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
    GL.GL_R16: (GL.GL_RED, GL.GL_FLOAT, 1, np.float32),  # 16-bit unsigned normalised: GL converts [0, 1]
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
