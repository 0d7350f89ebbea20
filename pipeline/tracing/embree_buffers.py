"""A triangle mesh handed to an embreex scene as whole buffers.

embreex's ``TriangleMesh`` copies the vertices and indices into Embree's buffers one element at a time
through numpy's Python-level indexing: 43 s for the 18.2M triangles of a ten-times-Table-1 level, against
17 s for Embree's own BVH build (docs/results.md, "The 10x world on the loopback cluster"). Here the same
geometry is made through Embree's C API (the library embreex ships): ``rtcNewGeometry``, one
``rtcSetNewGeometryBuffer`` per buffer written in one numpy assignment, ``rtcCommitGeometry``,
``rtcAttachGeometry``. Embree then sees the same buffers in the same geometry slot (id 0), so the scene it
builds and every ray's answer are the ones the binding's path gives (tests/test_embree_buffers.py).

The scene's handle is a private field of embreex's ``EmbreeScene``. Its place is found, not assumed: the
public ``is_committed`` is set to a marker and looked for right after the handle, and the handle must give,
through ``rtcGetSceneDevice``, the device that the scene's ``EmbreeDevice`` holds. When anything does not
match (another embreex build), :func:`attach_triangles` returns False and :func:`add_triangles` uses
``TriangleMesh``.
"""

from __future__ import annotations

import ctypes
from functools import cache
from pathlib import Path

import numpy as np

# Embree 4's enums (rtcore_common.h, rtcore_buffer.h, rtcore_geometry.h).
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX = 0
_BUFFER_TYPE_VERTEX = 1
_FORMAT_UINT3 = 0x5003
_FORMAT_FLOAT3 = 0x9003
_BUILD_QUALITY_HIGH = 2

_PTR = ctypes.sizeof(ctypes.c_void_p)
_HEAD = 2 * _PTR  # PyObject_HEAD: reference count and type
_MARK = 0x2B5E1D07


@cache
def _library() -> ctypes.CDLL | None:
    """Embree as embreex loaded it (its wheel's ``embreex.libs``), or None."""
    from embreex import rtcore_scene  # loads the library into this process

    libs = Path(rtcore_scene.__file__).resolve().parent.parent / "embreex.libs"
    found = sorted(libs.glob("libembree4*.so*")) if libs.is_dir() else []
    if len(found) != 1:
        return None
    lib = ctypes.CDLL(str(found[0]))
    vp, u32, sz = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
    for name, res, args in (
        ("rtcGetSceneDevice", vp, [vp]),
        ("rtcReleaseDevice", None, [vp]),
        ("rtcNewGeometry", vp, [vp, ctypes.c_int]),
        ("rtcSetNewGeometryBuffer", vp, [vp, ctypes.c_int, u32, ctypes.c_int, sz, sz]),
        ("rtcCommitGeometry", None, [vp]),
        ("rtcAttachGeometry", u32, [vp, vp]),
        ("rtcReleaseGeometry", None, [vp]),
        ("rtcSetSceneBuildQuality", None, [vp, ctypes.c_int]),
    ):
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = res, args
    return lib


def _read_pointer(address: int) -> int:
    return ctypes.c_void_p.from_address(address).value or 0


def scene_handle(scene) -> tuple[ctypes.CDLL, int, int] | None:
    """(Embree, the RTCScene, its RTCDevice) of an uncommitted embreex ``EmbreeScene``, or None where the
    layout is not the one checked for. The handles are the scene's own (no reference is taken)."""
    lib = _library()
    if lib is None or type(scene).__name__ != "EmbreeScene" or scene.is_committed:
        return None
    base = id(scene)
    scene.is_committed = _MARK
    try:
        if ctypes.c_int.from_address(base + _HEAD + _PTR).value != _MARK:
            return None
    finally:
        scene.is_committed = 0
    handle = _read_pointer(base + _HEAD)
    device_object = _read_pointer(base + _HEAD + 2 * _PTR)
    if not handle or not device_object:
        return None
    if ctypes.cast(device_object, ctypes.py_object).value.__class__.__name__ != "EmbreeDevice":
        return None
    device = _read_pointer(device_object + _HEAD)
    held = lib.rtcGetSceneDevice(handle)  # takes a reference to the device: given back at once
    if held:
        lib.rtcReleaseDevice(held)
    if not device or held != device:
        return None
    return lib, handle, device


def attach_triangles(scene, vertices: np.ndarray, faces: np.ndarray) -> bool:
    """Add the triangles ``faces`` (m, 3) over ``vertices`` (n, 3) to the uncommitted embreex ``scene`` as
    its next geometry, cast to float32 and uint32 as they are written into Embree's buffers; False (nothing
    added) where the scene's layout is not the checked one."""
    found = scene_handle(scene)
    if found is None:
        return False
    lib, handle, device = found
    n, m = len(vertices), len(faces)
    geom = lib.rtcNewGeometry(device, _GEOMETRY_TYPE_TRIANGLE)
    if not geom:
        return False
    try:
        # 16-byte vertices, as the binding lays them out (x, y, z and an unused fourth float, zeroed here)
        vbuf = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_VERTEX, 0, _FORMAT_FLOAT3, 16, n)
        ibuf = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_TYPE_INDEX, 0, _FORMAT_UINT3, 12, m)
        if (n and not vbuf) or (m and not ibuf):
            return False
        if n:
            dst = np.ctypeslib.as_array((ctypes.c_float * (4 * n)).from_address(vbuf)).reshape(n, 4)
            dst[:, :3] = vertices
            dst[:, 3] = 0.0
        if m:
            np.ctypeslib.as_array((ctypes.c_uint32 * (3 * m)).from_address(ibuf)).reshape(m, 3)[:] = faces
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(handle, geom)
    finally:
        lib.rtcReleaseGeometry(geom)
    return True


def high_quality(scene) -> bool:
    """Ask Embree for its high-quality BVH of the uncommitted embreex ``scene`` (a SAH build with spatial
    splits: slower to build, faster to traverse; Embree uses it only on a scene made without the robust
    flag). False where the scene's layout is not the checked one (the scene keeps the default quality)."""
    found = scene_handle(scene)
    if found is None:
        return False
    lib, handle, _ = found
    lib.rtcSetSceneBuildQuality(handle, _BUILD_QUALITY_HIGH)
    return True


def add_triangles(scene, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Add the triangles to the uncommitted embreex ``scene``: written straight into Embree's buffers where
    the scene's layout is the checked one, else through embreex's ``TriangleMesh`` (the same geometry,
    element by element)."""
    if not attach_triangles(scene, vertices, faces):
        from embreex.mesh_construction import TriangleMesh

        TriangleMesh(scene, np.asarray(vertices, np.float32), np.asarray(faces, np.int32))
