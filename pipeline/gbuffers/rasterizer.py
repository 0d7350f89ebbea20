"""Float32 G-buffers: our own GLSL program into a float framebuffer on pyrender's headless GL context.

How the channels are produced
-----------------------------
pyrender reads colour back as 8 bits and shades normals only through its own shaders, so neuralao
uses pyrender only for the context (:mod:`neuralao.runtime.gl`, OSMesa or EGL) and draws every scene with
one program of its own into a framebuffer with five colour attachments written in one pass (MRT):

* attachment 0, ``R32F``: linear depth;
* attachments 1-3, ``RGBA32F`` (read back as RGB): world position, object-space normal,
  camera-space normal;
* attachment 4, ``R32I``: ``gl_PrimitiveID``, exact in an integer target. All faces are drawn with
  one ``glDrawArrays`` call in ``scene.faces`` order, so the primitive id *is* the index into
  ``scene.faces``;
* a ``DEPTH_COMPONENT32F`` depth buffer used only for the depth test, with *reversed Z*
  (``glClipControl(ZERO_TO_ONE)``, near plane -> 1, far -> 0, test ``GREATER``): the float32
  exponent then cancels the 1/z compression, giving roughly constant *relative* depth resolution
  (~1e-7) from near to far plane instead of all of it at the near plane, so ids do not z-fight.

Precision: the scene is uploaded once as float32 offsets from its centre (``vertices - center``
computed in float64), and for each camera the model-view matrix ``view @ translate(center)`` is
composed in float64 before the float32 cast. No large coordinate ever reaches the GPU, so a scene
moved by 1e6 renders the same depths and ids as the original (the tests check it). Linear depth is
``-z`` of the interpolated camera-space position (not read back from the depth buffer); world
position is the interpolated centre-relative position plus the centre, the centre passed as a
float32 hi + lo pair and summed with ``precise`` (within one float32 ulp of the exact sum; the
float64 add on the CPU it replaces cost ~10 ms per 512x512 frame).

Normals (``normals="smooth"``, the default): the area-weighted vertex normals of
:attr:`Scene.vertex_normals`, each corner's normal first turned to the side of its own triangle's
geometric normal (so inconsistently wound triangle soup does not mix opposite signs within one
triangle), interpolated perspective-correctly, renormalised (a zero-length result falls back to
the face normal), then negated on back-facing fragments (``gl_FrontFacing``) so it faces the
viewer. ``normals="flat"`` writes the geometric face normal with the same flip. The camera-space
normal is the object-space one rotated by the view matrix. Pixel centres are sampled exactly as
:meth:`Camera.pixel_rays` shoots them. Background: depth, normals and position 0, mask False,
``tri_id`` -1.
"""

from __future__ import annotations

import ctypes
import math
from typing import Literal

import numpy as np

from neuralao.pipeline.geometry.camera import Camera
from neuralao.pipeline.geometry.scene import Scene
from neuralao.runtime import gl as rgl  # sets PYOPENGL_PLATFORM before PyOpenGL is first imported
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.frame import FrameLike

GL = rgl.GL
# PyOpenGL binds some GL 4.5 core entry points only when the library exports them (libOSMesa does
# not export glClipControl); the ARB_clip_control binding resolves it through GetProcAddress.
from OpenGL.GL.ARB.clip_control import glClipControl  # noqa: E402

_VERTEX = """#version 450 core
layout(location = 0) in vec3 a_pos;     // vertex - scene centre (float64 difference cast to float32)
layout(location = 1) in vec3 a_normal;  // vertex normal, turned to its triangle's side
layout(location = 2) in vec3 a_face;    // geometric face normal (same on all three corners)
uniform mat4 u_modelview;               // centre-relative -> camera, composed in float64
uniform mat4 u_projection;              // reversed-Z, zero-to-one clip depth
out vec3 v_local;
out vec3 v_cam;
out vec3 v_normal;
flat out vec3 v_face;
void main() {
    vec4 pc = u_modelview * vec4(a_pos, 1.0);
    v_local = a_pos;
    v_cam = pc.xyz;
    v_normal = a_normal;
    v_face = a_face;
    gl_Position = u_projection * pc;
}
"""

_FRAGMENT = """#version 450 core
in vec3 v_local;
in vec3 v_cam;
in vec3 v_normal;
flat in vec3 v_face;
uniform mat3 u_rotation;  // world -> camera rotation
uniform vec3 u_center_hi; // scene centre = hi + lo (float32 pair of the float64 centre)
uniform vec3 u_center_lo;
uniform int u_flat;       // 1: geometric face normals
layout(location = 0) out float o_depth;
layout(location = 1) out vec4 o_position;
layout(location = 2) out vec4 o_normal_obj;
layout(location = 3) out vec4 o_normal_cam;
layout(location = 4) out int o_tri_id;
void main() {
    vec3 n = v_face;
    float len = length(v_normal);
    // Guard: corner normals that cancel (or are zero) leave no direction; use the face normal.
    if (u_flat == 0 && len > 1e-12) n = v_normal / len;
    if (!gl_FrontFacing) n = -n;
    precise vec3 world = (v_local + u_center_hi) + u_center_lo;
    o_depth = -v_cam.z;
    o_position = vec4(world, 1.0);
    o_normal_obj = vec4(n, gl_FrontFacing ? 1.0 : -1.0);  // w: the facing the back layer compares
    o_normal_cam = vec4(normalize(u_rotation * n), 0.0);
    o_tri_id = gl_PrimitiveID;
}
"""

# The back layer (``back_layer=True``): every face drawn again, keeping the nearest fragment behind the
# visible one (not its own triangle, more than BACK_LAYER_GAP relative depth behind). Where that next
# surface faces the camera ray the other way from the visible one, the ray leaves the solid it entered
# there: its depth is the back layer. Where it faces the same way (a sheet in front of another part) or
# nothing lies behind, the visible surface is thin: 0, as on background.
BACK_LAYER_GAP = 1e-5
_BACK_FRAGMENT = """#version 450 core
in vec3 v_local;
in vec3 v_cam;
in vec3 v_normal;
flat in vec3 v_face;
uniform sampler2D u_front_depth;   // the first pass's linear depth
uniform sampler2D u_front_normal;  // its object-space normal, w = its facing (+1 front, -1 back)
uniform isampler2D u_front_tri;    // its triangle, -1 on background
layout(location = 0) out float o_depth_back;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    float front = texelFetch(u_front_depth, p, 0).r;
    int tri = texelFetch(u_front_tri, p, 0).r;
    float z = -v_cam.z;
    if (tri < 0 || gl_PrimitiveID == tri || z <= front * (1.0 + GAP)) discard;
    float facing = gl_FrontFacing ? 1.0 : -1.0;
    o_depth_back = facing != texelFetch(u_front_normal, p, 0).w ? z : 0.0;
}
""".replace("GAP", f"{BACK_LAYER_GAP:.1e}")

# Colour attachments: depth, position, normal_obj, normal_cam, tri_id (same order as the outputs).
_TARGETS = (
    ("depth", rgl.GL.GL_R32F),
    ("position", rgl.GL.GL_RGBA32F),
    ("normal_obj", rgl.GL.GL_RGBA32F),
    ("normal_cam", rgl.GL.GL_RGBA32F),
    ("tri_id", rgl.GL.GL_R32I),
)
_TRI = len(_TARGETS) - 1


def reversed_z_projection(camera: Camera) -> np.ndarray:
    """(4, 4) float64 perspective with reversed zero-to-one depth: near plane -> 1, far plane -> 0.

    x and y rows equal :attr:`Camera.projection` (same pixels); clip z = n (z + f) / (f - n), w = -z.
    """
    p = np.array(camera.projection, dtype=np.float64)
    n, f = float(camera.znear), float(camera.zfar)
    p[2] = [0.0, 0.0, n / (f - n), n * f / (f - n)]
    return p


class GBufferRenderer:
    """Uploads one scene once; :meth:`render` draws any number of cameras at any resolution.

    normals : "smooth" (interpolated vertex normals) or "flat" (geometric face normals).
    back_layer : also render ``depth_back`` (a second pass; see :data:`BACK_LAYER_GAP`).
    """

    def __init__(self, scene: Scene, normals: Literal["smooth", "flat"] = "smooth", back_layer: bool = False):
        if normals not in ("smooth", "flat"):
            raise NeuralaoError(f"normals must be 'smooth' or 'flat', got {normals!r}")
        faces = np.asarray(scene.faces, dtype=np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise NeuralaoError(f"scene {scene.name} has no faces to render")
        if len(faces) * 3 >= 2**31:
            raise NeuralaoError(f"scene {scene.name} has too many faces for one draw call ({len(faces)})")
        self.scene = scene
        self.normals = normals
        self.center = np.asarray(scene.center, dtype=np.float64)
        self._center_hi = self.center.astype(np.float32)
        self._center_lo = (self.center - self._center_hi.astype(np.float64)).astype(np.float32)
        self.ctx = rgl.context()
        max_size = int(GL.glGetIntegerv(GL.GL_MAX_RENDERBUFFER_SIZE))
        self.max_size = min(max_size, int(GL.glGetIntegerv(GL.GL_MAX_TEXTURE_SIZE)))
        self._program = rgl.compile_program(vertex=_VERTEX, fragment=_FRAGMENT)
        self._uniforms = {
            name: GL.glGetUniformLocation(self._program, name)
            for name in ("u_modelview", "u_projection", "u_rotation", "u_center_hi", "u_center_lo", "u_flat")
        }
        self.back_layer = bool(back_layer)
        self._back_program = None
        if self.back_layer:
            self._back_program = rgl.compile_program(vertex=_VERTEX, fragment=_BACK_FRAGMENT)
            self._back_uniforms = {
                name: GL.glGetUniformLocation(self._back_program, name)
                for name in ("u_modelview", "u_projection", "u_front_depth", "u_front_normal", "u_front_tri")
            }
        self._count = 3 * len(faces)
        self._vao, self._vbo = self._upload(scene, faces)
        self._fbo: int | None = None
        self._targets: list[int] = []
        self._depth_rb: int | None = None
        self._back_fbo: int | None = None  # the back layer's target and depth buffer
        self._back_target: int | None = None
        self._back_rb: int | None = None
        self._size: tuple[int, int] | None = None
        self._raw: dict[int, np.ndarray] = {}  # reused readback buffers per attachment

    # ------------------------------------------------------------------ set-up

    def _upload(self, scene: Scene, faces: np.ndarray) -> tuple[int, int]:
        """One interleaved float32 buffer, three corners per face in ``scene.faces`` order:
        (3m, 9) = centre-relative position, side-corrected vertex normal, face normal."""
        verts = np.asarray(scene.vertices, dtype=np.float64)
        local = (verts - self.center)[faces]  # (m, 3, 3) float64, differences before the cast
        face_n = np.nan_to_num(np.asarray(scene.face_normals, dtype=np.float64))  # degenerate -> 0
        vn = np.asarray(scene.vertex_normals, dtype=np.float64)[faces]  # (m, 3, 3)
        side = np.einsum("mkc,mc->mk", vn, face_n)
        vn = np.where((side < 0)[..., None], -vn, vn)
        data = np.empty((len(faces), 3, 9), dtype=np.float32)
        data[..., 0:3] = local
        data[..., 3:6] = vn
        data[..., 6:9] = face_n[:, None, :]
        data = np.ascontiguousarray(data.reshape(-1, 9))
        vao = GL.glGenVertexArrays(1)
        GL.glBindVertexArray(vao)
        vbo = GL.glGenBuffers(1)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, vbo)
        GL.glBufferData(GL.GL_ARRAY_BUFFER, data.nbytes, data, GL.GL_STATIC_DRAW)
        stride = 9 * 4
        for loc in range(3):
            GL.glEnableVertexAttribArray(loc)
            GL.glVertexAttribPointer(loc, 3, GL.GL_FLOAT, GL.GL_FALSE, stride, ctypes.c_void_p(12 * loc))
        GL.glBindVertexArray(0)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)
        return vao, vbo

    def _ensure_framebuffer(self, width: int, height: int) -> None:
        if self._size == (width, height):
            return
        self._release_framebuffer()
        self._targets = [rgl.create_texture(width, height, internal) for _, internal in _TARGETS]
        self._fbo = rgl.create_framebuffer(self._targets, width, height, depth=True)
        self._depth_rb = int(
            GL.glGetFramebufferAttachmentParameteriv(
                GL.GL_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_FRAMEBUFFER_ATTACHMENT_OBJECT_NAME
            )
        )
        if self.back_layer:
            self._back_target = rgl.create_texture(width, height, GL.GL_R32F)
            self._back_fbo = rgl.create_framebuffer([self._back_target], width, height, depth=True)
            self._back_rb = int(
                GL.glGetFramebufferAttachmentParameteriv(
                    GL.GL_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_FRAMEBUFFER_ATTACHMENT_OBJECT_NAME
                )
            )
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        self._size = (width, height)

    def _release_framebuffer(self) -> None:
        if self._fbo is not None:
            GL.glDeleteFramebuffers(1, [self._fbo])
            GL.glDeleteTextures(len(self._targets), self._targets)
            if self._depth_rb:
                GL.glDeleteRenderbuffers(1, [self._depth_rb])
        if self._back_fbo is not None:
            GL.glDeleteFramebuffers(1, [self._back_fbo])
            GL.glDeleteTextures(1, [self._back_target])
            if self._back_rb:
                GL.glDeleteRenderbuffers(1, [self._back_rb])
        self._back_fbo = self._back_target = self._back_rb = None
        self._fbo, self._targets, self._depth_rb, self._size = None, [], None, None
        self._raw = {}

    def close(self) -> None:
        """Free the GL objects (the shared context stays)."""
        if self._vao is None:
            return
        self.ctx.make_current()
        self._release_framebuffer()
        GL.glDeleteBuffers(1, [self._vbo])
        GL.glDeleteVertexArrays(1, [self._vao])
        GL.glDeleteProgram(self._program)
        if self._back_program is not None:
            GL.glDeleteProgram(self._back_program)
        self._vao = self._vbo = None

    def __del__(self) -> None:
        # Callers that drop a renderer without close() (one per scene in a long dataset run) must not
        # leak its vertex buffer; at interpreter exit the context may already be gone.
        try:
            self.close()
        except Exception:
            pass

    def __enter__(self) -> GBufferRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ rendering

    def _check_camera(self, camera: Camera) -> tuple[int, int]:
        w, h = camera.width, camera.height
        if not (isinstance(w, int | np.integer) and isinstance(h, int | np.integer)) or w < 1 or h < 1:
            raise NeuralaoError(f"image size must be positive integers, got {w}x{h}")
        if w > self.max_size or h > self.max_size:
            raise NeuralaoError(f"image size {w}x{h} exceeds this GL's limit of {self.max_size}")
        pose = np.asarray(camera.pose, dtype=np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise NeuralaoError("camera pose must be a finite 4x4 matrix")
        if not (0 < camera.yfov < math.pi) or not (0 < camera.znear < camera.zfar < math.inf):
            raise NeuralaoError(
                f"camera needs 0 < yfov < pi and 0 < znear < zfar, got yfov={camera.yfov}, "
                f"znear={camera.znear}, zfar={camera.zfar}"
            )
        return int(w), int(h)

    def render(self, camera: Camera) -> dict[str, np.ndarray]:
        """The G-buffer frame of ``camera`` (see the module docstring), row 0 at the top.

        Returns depth (H, W) f32, normal_cam / normal_obj / position (H, W, 3) f32, mask (H, W) bool,
        tri_id (H, W) i32, pose (4, 4) f64, yfov / znear / zfar float; with ``back_layer`` also
        depth_back (H, W) f32 (0 where the visible surface is thin, and on background).
        """
        if self._vao is None:
            raise NeuralaoError("this GBufferRenderer has been closed")
        w, h = self._check_camera(camera)
        self.ctx.make_current()
        self._ensure_framebuffer(w, h)
        pose = np.asarray(camera.pose, dtype=np.float64)
        view = np.linalg.inv(pose)
        to_world = np.eye(4)
        to_world[:3, 3] = self.center
        modelview = view @ to_world  # float64: large offsets cancel here, not on the GPU
        projection = reversed_z_projection(camera)
        self._draw(modelview, projection, view[:3, :3], w, h)
        frame = self._read_back(camera, pose, w, h)
        if self.back_layer:
            self._draw_back(modelview, projection, view[:3, :3], w, h)
            raw = self._read_raw(
                len(_TARGETS), GL.GL_RED, GL.GL_FLOAT, 1, np.float32, w, h, self._back_target
            )
            frame["depth_back"] = raw[..., 0][::-1].copy()
            GL.glBindTexture(GL.GL_TEXTURE_2D, 0)
        return frame

    def _begin(self, fbo: int, targets: int, rotation: np.ndarray, w: int, h: int) -> None:
        """Bind ``fbo`` with ``targets`` colour attachments and set every piece of state a pass depends on:
        pyrender shares this context and leaves culling, blending, polygon mode and its own depth convention
        behind."""
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fbo)
        GL.glDrawBuffers(targets, [GL.GL_COLOR_ATTACHMENT0 + k for k in range(targets)])
        GL.glViewport(0, 0, w, h)
        for cap in (GL.GL_CULL_FACE, GL.GL_BLEND, GL.GL_SCISSOR_TEST, GL.GL_MULTISAMPLE, GL.GL_STENCIL_TEST):
            GL.glDisable(cap)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDepthMask(GL.GL_TRUE)
        GL.glColorMask(GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE)
        GL.glPolygonMode(GL.GL_FRONT_AND_BACK, GL.GL_FILL)
        # A mirroring pose (det < 0) swaps screen-space winding; keep "front" = right-handed normal.
        GL.glFrontFace(GL.GL_CCW if np.linalg.det(rotation) > 0 else GL.GL_CW)
        glClipControl(GL.GL_LOWER_LEFT, GL.GL_ZERO_TO_ONE)
        GL.glDepthFunc(GL.GL_GREATER)

    def _draw_all(self, modelview: np.ndarray, projection: np.ndarray, uniforms: dict) -> None:
        """Every face with the program in use (its matrices set; GL matrices are column-major: row-major
        float32 with transpose = GL_TRUE), then the defaults pyrender relies on restored (its projection
        maps depth to [-1, 1], test LESS)."""
        GL.glUniformMatrix4fv(uniforms["u_modelview"], 1, GL.GL_TRUE, modelview.astype(np.float32))
        GL.glUniformMatrix4fv(uniforms["u_projection"], 1, GL.GL_TRUE, projection.astype(np.float32))
        GL.glBindVertexArray(self._vao)
        GL.glDrawArrays(GL.GL_TRIANGLES, 0, self._count)
        GL.glBindVertexArray(0)
        GL.glUseProgram(0)
        glClipControl(GL.GL_LOWER_LEFT, GL.GL_NEGATIVE_ONE_TO_ONE)
        GL.glDepthFunc(GL.GL_LESS)
        GL.glFrontFace(GL.GL_CCW)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)

    def _draw(
        self, modelview: np.ndarray, projection: np.ndarray, rotation: np.ndarray, w: int, h: int
    ) -> None:
        self._begin(self._fbo, len(_TARGETS), rotation, w, h)
        zero = np.zeros(4, dtype=np.float32)
        for k in range(_TRI):
            GL.glClearBufferfv(GL.GL_COLOR, k, zero)
        GL.glClearBufferiv(GL.GL_COLOR, _TRI, np.array([-1, 0, 0, 0], dtype=np.int32))
        GL.glClearBufferfv(GL.GL_DEPTH, 0, np.zeros(1, dtype=np.float32))  # reversed Z: far = 0
        GL.glUseProgram(self._program)
        u = self._uniforms
        GL.glUniformMatrix3fv(u["u_rotation"], 1, GL.GL_TRUE, rotation.astype(np.float32))
        GL.glUniform3fv(u["u_center_hi"], 1, self._center_hi)
        GL.glUniform3fv(u["u_center_lo"], 1, self._center_lo)
        GL.glUniform1i(u["u_flat"], 1 if self.normals == "flat" else 0)
        self._draw_all(modelview, projection, u)

    def _draw_back(
        self, modelview: np.ndarray, projection: np.ndarray, rotation: np.ndarray, w: int, h: int
    ) -> None:
        """The back layer's pass (:data:`BACK_LAYER_GAP`), reading the first pass's depth, normal and
        triangle targets into one colour target."""
        self._begin(self._back_fbo, 1, rotation, w, h)
        GL.glClearBufferfv(GL.GL_COLOR, 0, np.zeros(4, dtype=np.float32))
        GL.glClearBufferfv(GL.GL_DEPTH, 0, np.zeros(1, dtype=np.float32))
        GL.glUseProgram(self._back_program)
        u = self._back_uniforms
        sources = (("u_front_depth", 0), ("u_front_normal", 2), ("u_front_tri", _TRI))
        for unit, (name, k) in enumerate(sources):
            GL.glActiveTexture(GL.GL_TEXTURE0 + unit)
            GL.glBindTexture(GL.GL_TEXTURE_2D, self._targets[k])
            GL.glUniform1i(u[name], unit)
        self._draw_all(modelview, projection, u)
        for unit in reversed(range(len(sources))):
            GL.glActiveTexture(GL.GL_TEXTURE0 + unit)
            GL.glBindTexture(GL.GL_TEXTURE_2D, 0)

    def _read_raw(
        self, k: int, fmt: int, typ: int, ch: int, dtype, w: int, h: int, tex: int | None = None
    ) -> np.ndarray:
        """Attachment k as (H, W, ch) into a reused buffer, GL row order (row 0 at the bottom).

        RGBA targets are read as RGB (GL drops the unused channel while packing, far cheaper than a
        strided copy), and reused buffers avoid a page fault per 4 KB on every frame; the caller's
        arrays are fresh contiguous copies made while flipping the rows.
        """
        buf = self._raw.get(k)
        if buf is None or buf.shape != (h, w, ch):
            buf = self._raw[k] = np.empty((h, w, ch), dtype=dtype)
        GL.glBindTexture(GL.GL_TEXTURE_2D, self._targets[k] if tex is None else tex)
        GL.glGetTexImage(GL.GL_TEXTURE_2D, 0, fmt, typ, buf)
        return buf

    def _read_back(self, camera: Camera, pose: np.ndarray, w: int, h: int) -> dict[str, np.ndarray]:
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        frame: FrameLike = {}
        for k, (name, internal) in enumerate(_TARGETS):
            if internal == GL.GL_RGBA32F:
                raw = self._read_raw(k, GL.GL_RGB, GL.GL_FLOAT, 3, np.float32, w, h)
            elif internal == GL.GL_R32F:
                raw = self._read_raw(k, GL.GL_RED, GL.GL_FLOAT, 1, np.float32, w, h)[..., 0]
            else:
                raw = self._read_raw(k, GL.GL_RED_INTEGER, GL.GL_INT, 1, np.int32, w, h)[..., 0]
            frame[name] = raw[::-1].copy()
        GL.glBindTexture(GL.GL_TEXTURE_2D, 0)
        frame["mask"] = frame["tri_id"] >= 0
        frame.update(
            pose=pose.copy(), yfov=float(camera.yfov), znear=float(camera.znear), zfar=float(camera.zfar)
        )
        return frame


def render_gbuffer(
    scene: Scene, camera: Camera, normals: Literal["smooth", "flat"] = "smooth", back_layer: bool = False
) -> dict[str, np.ndarray]:
    """One frame of one camera (uploads the scene each call: use :class:`GBufferRenderer` for many)."""
    with GBufferRenderer(scene, normals=normals, back_layer=back_layer) as renderer:
        return renderer.render(camera)
