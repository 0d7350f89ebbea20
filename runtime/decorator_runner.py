"""Run the generated decorator vertex shader (export/glsl/decorator.py) headless on Mesa.

The shader runs unchanged: every vertex of every instance is drawn as a point
(``glDrawArraysInstanced``) with the rasteriser discarded, and transform feedback captures its
outputs ``v_ao`` and ``v_world``. What an engine would interpolate across a triangle is exactly
these per-vertex values.
"""

from __future__ import annotations

import ctypes

import numpy as np
from OpenGL import GL

from neuralao.runtime import gl
from neuralao.runtime.foundation.errors import NeuralaoError


def _program(vertex: str, varyings: list[str]) -> int:
    gl.context()
    prog = GL.glCreateProgram()
    sh = GL.glCreateShader(GL.GL_VERTEX_SHADER)
    GL.glShaderSource(sh, vertex)
    GL.glCompileShader(sh)
    if not GL.glGetShaderiv(sh, GL.GL_COMPILE_STATUS):
        log = GL.glGetShaderInfoLog(sh).decode(errors="replace").strip()
        raise NeuralaoError(f"vertex shader failed to compile: {log.splitlines()[0] if log else '?'}")
    GL.glAttachShader(prog, sh)
    names = (ctypes.c_char_p * len(varyings))(*[v.encode() for v in varyings])
    GL.glTransformFeedbackVaryings(
        prog,
        len(varyings),
        ctypes.cast(names, ctypes.POINTER(ctypes.POINTER(GL.GLchar))),
        GL.GL_INTERLEAVED_ATTRIBS,
    )
    GL.glLinkProgram(prog)
    GL.glDeleteShader(sh)
    if not GL.glGetProgramiv(prog, GL.GL_LINK_STATUS):
        log = GL.glGetProgramInfoLog(prog).decode(errors="replace").strip()
        raise NeuralaoError(f"program failed to link: {log.splitlines()[0] if log else '?'}")
    return prog


def _read_mapped(buf: int, nbytes: int) -> np.ndarray:
    """(nbytes / 4,) float32 copy of a transform-feedback buffer, read through glMapBufferRange
    (PyOpenGL's glGetBufferSubData with an output array converted the array and corrupted the heap
    here: 'invalid value encountered in cast', then free(): invalid size)."""
    GL.glBindBuffer(GL.GL_TRANSFORM_FEEDBACK_BUFFER, buf)
    ptr = GL.glMapBufferRange(GL.GL_TRANSFORM_FEEDBACK_BUFFER, 0, nbytes, GL.GL_MAP_READ_BIT)
    if not ptr:
        raise NeuralaoError("cannot map the transform feedback buffer")
    try:
        return np.ctypeslib.as_array((ctypes.c_float * (nbytes // 4)).from_address(ptr)).copy()
    finally:
        GL.glUnmapBuffer(GL.GL_TRANSFORM_FEEDBACK_BUFFER)


def run_decorator_vertex_shader(
    vertex_source: str,
    positions: np.ndarray,
    local_ao: np.ndarray,
    translation: np.ndarray,
    rotation: np.ndarray,
    scale: np.ndarray,
    ao_global: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """positions (n, 3), local_ao (n,); per instance translation (k, 3), rotation (k, 4) [x, y, z, w],
    scale (k, 3), ao_global (k, 4). Returns v_ao (k, n) float32 and v_world (k, n, 3) float32."""
    ctx = gl.context()
    n, k = len(positions), len(translation)
    prog = _program(vertex_source, ["v_ao", "v_world"])
    vao = GL.glGenVertexArrays(1)
    GL.glBindVertexArray(vao)
    bufs = []
    for loc, arr, comps, divisor in (
        (0, positions, 3, 0),
        (1, local_ao, 1, 0),
        (2, translation, 3, 1),
        (3, rotation, 4, 1),
        (4, scale, 3, 1),
        (5, ao_global, 4, 1),
    ):
        buf = gl.create_buffer(np.ascontiguousarray(arr, np.float32), target=GL.GL_ARRAY_BUFFER)
        GL.glVertexAttribPointer(loc, comps, GL.GL_FLOAT, GL.GL_FALSE, 0, None)
        GL.glEnableVertexAttribArray(loc)
        GL.glVertexAttribDivisor(loc, divisor)
        bufs.append(buf)
    nbytes = n * k * 4 * 4
    tfb = gl.create_buffer(nbytes=nbytes, target=GL.GL_TRANSFORM_FEEDBACK_BUFFER)
    bufs.append(tfb)
    try:
        GL.glUseProgram(prog)
        GL.glUniformMatrix4fv(
            GL.glGetUniformLocation(prog, "u_view_projection"), 1, GL.GL_TRUE, np.eye(4, dtype=np.float32)
        )
        GL.glEnable(GL.GL_RASTERIZER_DISCARD)
        GL.glBindBufferBase(GL.GL_TRANSFORM_FEEDBACK_BUFFER, 0, tfb)
        GL.glBeginTransformFeedback(GL.GL_POINTS)
        GL.glDrawArraysInstanced(GL.GL_POINTS, 0, n, k)
        GL.glEndTransformFeedback()
        GL.glFinish()
        out = _read_mapped(tfb, nbytes).reshape(k, n, 4)
    finally:
        GL.glDisable(GL.GL_RASTERIZER_DISCARD)
        GL.glBindVertexArray(ctx.empty_vao)
        GL.glDeleteVertexArrays(1, [vao])
        GL.glDeleteBuffers(len(bufs), bufs)
        GL.glDeleteProgram(prog)
    return out[..., 0].copy(), out[..., 1:].copy()
