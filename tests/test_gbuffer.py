"""Float G-buffer (our GLSL program on pyrender's context) against Embree primary rays.

The reference is independent of the rasteriser: embreex intersects :meth:`Camera.pixel_rays` with
the scene (built in float32 centre-relative coordinates, as a careful ray tracer would), giving the
first-hit triangle, its distance and barycentrics; depth = t * dot(dir, forward), smooth normals are
the vertex normals interpolated in float64 with Embree's (u, v).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer, render_gbuffer
from neuralao.pipeline.geometry.camera import Camera, interior, look_at, orbit
from neuralao.pipeline.geometry.scene import Scene, load_scene, scene_from_arrays
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL

W, H = 96, 64
FRAME_KEYS = ("depth", "normal_cam", "normal_obj", "position", "mask", "tri_id")


class EmbreeReference:
    """Primary-ray hits of one scene: prim (H, W) i32 (-1 miss), depth (H, W) f64, dirs (H, W, 3), u, v."""

    def __init__(self, scene: Scene):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.scene = scene
        self.embree = rtcore_scene.EmbreeScene()
        TriangleMesh(
            self.embree, (scene.vertices - scene.center).astype(np.float32), scene.faces.astype(np.int32)
        )

    def cast(self, cam: Camera) -> dict[str, np.ndarray]:
        """Rays start on the near plane and end on the far plane, like the rasteriser's clipping."""
        o, d = cam.pixel_rays()
        fwd = -cam.pose[:3, 2] / np.linalg.norm(cam.pose[:3, 2])
        cos = d @ fwd
        t_near, t_far = cam.znear / cos, cam.zfar / cos
        start = o + t_near[:, None] * d - self.scene.center  # float64, then float32
        out = self.embree.run(
            start.astype(np.float32),
            d.astype(np.float32),
            query="INTERSECT",
            output=1,
            dists=(t_far - t_near).astype(np.float32),
        )
        shape = (cam.height, cam.width)
        prim = out["primID"]
        t = np.where(prim >= 0, out["tfar"].astype(np.float64) + t_near, np.inf)
        return {
            "prim": prim.reshape(shape),
            "t": t.reshape(shape),
            "depth": (t * cos).reshape(shape),
            "dirs": d.reshape(*shape, 3),
            "u": out["u"].astype(np.float64).reshape(shape),
            "v": out["v"].astype(np.float64).reshape(shape),
        }


def ray_plane_depth(scene: Scene, cam: Camera, tri: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Depth (n,) f64 at which pixel rays dirs (n, 3) meet the planes of triangles tri (n,), in float64."""
    n = scene.face_normals[tri]
    v0 = scene.vertices[scene.faces[tri, 0]]
    t = np.einsum("ij,ij->i", n, v0 - cam.position) / np.einsum("ij,ij->i", n, dirs)
    fwd = -cam.pose[:3, 2]
    return t * (dirs @ fwd)


def compare_ids(scene: Scene, cam: Camera, frame: dict, ref: dict) -> tuple[np.ndarray, float]:
    """Pixels where both agree on the triangle (H, W) bool, and the fraction of foreground pixels that
    genuinely disagree. A differing id is not counted when the rasterised triangle's plane lies at the
    Embree hit depth (coplanar overlapping faces, e.g. the Cornell box light in its ceiling: both
    answers are a correct first hit)."""
    fg = frame["mask"] | (ref["prim"] >= 0)
    differ = fg & (frame["tri_id"] != ref["prim"])
    both = differ & frame["mask"] & (ref["prim"] >= 0)
    tie = np.zeros_like(differ)
    if both.any():
        dep = ray_plane_depth(scene, cam, frame["tri_id"][both], ref["dirs"][both])
        tie[both] = np.abs(dep - ref["depth"][both]) <= TOL.gbuffer_depth_rel * ref["depth"][both]
    agree = fg & (frame["tri_id"] == ref["prim"])
    return agree, float((differ & ~tie).sum() / max(1, fg.sum()))


def facing(normals: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """normals (n, 3) flipped so that dot(normal, ray dir) <= 0 (towards the camera)."""
    return np.where((np.einsum("ij,ij->i", normals, dirs) > 0)[:, None], -normals, normals)


def smooth_reference(
    scene: Scene, tri: np.ndarray, u: np.ndarray, v: np.ndarray, dirs: np.ndarray
) -> np.ndarray:
    """Interpolated vertex normals (n, 3) f64 at Embree's barycentrics, each corner turned to its face's
    side, renormalised, flipped towards the camera by the face orientation."""
    fn = scene.face_normals[tri]
    corners = scene.vertex_normals[scene.faces[tri]]  # (n, 3, 3)
    side = np.einsum("nkc,nc->nk", corners, fn)
    corners = np.where((side < 0)[..., None], -corners, corners)
    n = (1 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1] + v[:, None] * corners[:, 2]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    flip = np.einsum("ij,ij->i", fn, dirs) > 0
    return np.where(flip[:, None], -n, n)


CASES = [
    ("spot", "orbit"),
    ("beetle", "orbit"),  # triangle soup of 33 CAD pieces
    ("cornell_box", "interior"),  # seen from inside: back faces, coplanar light
    ("BrainStem", "orbit"),  # glTF, inconsistent winding
]


@pytest.fixture(scope="module")
def scenes() -> dict[str, Scene]:
    return {name: load_scene(name) for name, _ in CASES}


def cameras_for(scene: Scene, kind: str, views: int = 3, w: int = W, h: int = H) -> list[Camera]:
    return interior(scene, views, w, h, seed=1) if kind == "interior" else orbit(scene, views, w, h, seed=3)


@pytest.mark.parametrize("name,kind", CASES)
def test_gbuffer_matches_embree_primary_rays(scenes, name, kind):
    scene = scenes[name]
    ref_tracer = EmbreeReference(scene)
    flat = GBufferRenderer(scene, normals="flat")
    smooth = GBufferRenderer(scene)
    for cam in cameras_for(scene, kind):
        ref = ref_tracer.cast(cam)
        f = flat.render(cam)
        agree, mismatch = compare_ids(scene, cam, f, ref)
        assert mismatch <= TOL.gbuffer_id_mismatch_frac, (
            f"{name}: {mismatch:.4f} of pixels disagree on the triangle"
        )
        ok = agree & (ref["prim"] >= 0)
        assert ok.sum() > 0.5 * f["mask"].sum() > 0
        rel = np.abs(f["depth"][ok] - ref["depth"][ok]) / ref["depth"][ok]
        assert rel.max() <= TOL.gbuffer_depth_rel, f"{name}: depth rel error {rel.max():.2e}"
        # Flat normals: the geometric face normal, turned towards the camera.
        dirs = ref["dirs"][ok]
        fn = facing(scene.face_normals[ref["prim"][ok]], dirs)
        cos = np.einsum("ij,ij->i", fn, f["normal_obj"][ok])
        assert cos.min() >= TOL.gbuffer_normal_cos, f"{name}: flat normal cos {cos.min():.6f}"
        # Camera-space normal = view rotation of the object-space one.
        ncam = f["normal_obj"][ok] @ cam.view[:3, :3].T
        assert np.einsum("ij,ij->i", ncam, f["normal_cam"][ok]).min() >= TOL.gbuffer_normal_cos
        # World position = camera + t * dir.
        pos = cam.position + ref["t"][ok][:, None] * dirs
        assert np.abs(f["position"][ok] - pos).max() <= TOL.gbuffer_depth_rel * ref["depth"][ok].max()

        # Smooth normals at the same pixels: same ids and depth, normal = interpolated vertex normals.
        s = smooth.render(cam)
        assert np.array_equal(s["tri_id"], f["tri_id"]) and np.array_equal(s["depth"], f["depth"])
        nref = smooth_reference(scene, ref["prim"][ok], ref["u"][ok], ref["v"][ok], dirs)
        cos = np.einsum("ij,ij->i", nref, s["normal_obj"][ok])
        assert cos.min() >= TOL.gbuffer_normal_cos, f"{name}: smooth normal cos {cos.min():.6f}"
        for key in ("normal_obj", "normal_cam"):
            length = np.linalg.norm(s[key][s["mask"]], axis=1)
            assert np.all(np.abs(length - 1) < 1e-5), f"{name}: {key} not unit"
        # Facing the viewer: on the camera's side of the visible triangle's plane.
        assert (np.einsum("ij,ij->i", s["normal_obj"][ok], fn) >= 0).all()


def test_background_is_exactly_empty(scenes):
    scene = scenes["spot"]
    frame = render_gbuffer(scene, orbit(scene, 1, W, H)[0])
    bg = ~frame["mask"]
    assert 0 < bg.sum() < bg.size
    assert (frame["depth"][bg] == 0).all() and (frame["tri_id"][bg] == -1).all()
    for key in ("normal_cam", "normal_obj", "position"):
        assert (frame[key][bg] == 0).all()
    assert np.array_equal(frame["mask"], frame["tri_id"] >= 0)
    assert (frame["depth"][~bg] > 0).all()
    # dtypes and shapes of the frame format
    assert frame["depth"].dtype == np.float32 and frame["depth"].shape == (H, W)
    assert frame["tri_id"].dtype == np.int32 and frame["mask"].dtype == bool
    for key in ("normal_cam", "normal_obj", "position"):
        assert frame[key].dtype == np.float32 and frame[key].shape == (H, W, 3)
    assert frame["pose"].shape == (4, 4) and frame["pose"].dtype == np.float64
    # A camera looking away from the scene sees nothing at all.
    away = orbit(scene, 1, 8, 8)[0]
    pose = look_at(away.position, away.position + (away.position - scene.center))
    empty = render_gbuffer(scene, Camera(pose, 8, 8, away.yfov, away.znear, away.zfar))
    assert not empty["mask"].any() and (empty["tri_id"] == -1).all() and (empty["depth"] == 0).all()


@pytest.mark.parametrize("size", [(1, 1), (37, 5), (5, 41), (96, 64)])
def test_any_resolution_matches_embree(scenes, size):
    scene = scenes["spot"]
    renderer = GBufferRenderer(scene, normals="flat")
    tracer = EmbreeReference(scene)
    w, h = size
    # Looking straight at the centre so the single pixel of a 1x1 image is foreground.
    for cam in orbit(scene, 2, w, h, seed=5):
        f = renderer.render(cam)
        ref = tracer.cast(cam)
        assert f["depth"].shape == (h, w) and f["normal_obj"].shape == (h, w, 3)
        agree, mismatch = compare_ids(scene, cam, f, ref)
        if size != (1, 1):
            assert mismatch <= TOL.gbuffer_id_mismatch_frac
        else:
            assert agree.all() and f["mask"].all()
        ok = agree & (ref["prim"] >= 0)
        rel = np.abs(f["depth"][ok] - ref["depth"][ok]) / ref["depth"][ok]
        assert rel.max(initial=0) <= TOL.gbuffer_depth_rel


def test_one_renderer_switches_sizes_and_cameras(scenes):
    # The framebuffer is re-created on a size change; frames must not leak between sizes.
    scene = scenes["beetle"]
    r = GBufferRenderer(scene)
    cams = orbit(scene, 2, 40, 30)
    a = r.render(cams[0])
    r.render(cams[1].with_size(7, 90))
    b = r.render(cams[0])
    for key in FRAME_KEYS:
        assert np.array_equal(a[key], b[key])
    fresh = render_gbuffer(scene, cams[0])
    for key in FRAME_KEYS:
        assert np.array_equal(a[key], fresh[key])


def test_offset_scene_renders_like_the_original(scenes):
    # 1e6 offsets: positions are centre-relative on the GPU and the model-view is composed in float64.
    scene = scenes["spot"]
    off = np.array([1e6, -2e6, 3e6])
    moved = scene.scaled(1.0, off)
    r0, r1 = GBufferRenderer(scene), GBufferRenderer(moved)
    for cam in orbit(scene, 3, W, H, seed=2):
        pose = cam.pose.copy()
        pose[:3, 3] += off
        a = r0.render(cam)
        b = r1.render(Camera(pose, W, H, cam.yfov, cam.znear, cam.zfar))
        fg = a["mask"].sum()
        assert (a["tri_id"] != b["tri_id"]).sum() <= TOL.gbuffer_id_mismatch_frac * fg
        same = (a["tri_id"] == b["tri_id"]) & a["mask"]
        rel = np.abs(a["depth"][same] - b["depth"][same]) / a["depth"][same]
        assert rel.max() <= TOL.gbuffer_depth_rel
        assert (
            np.einsum("ij,ij->i", a["normal_cam"][same], b["normal_cam"][same]).min()
            >= TOL.gbuffer_normal_cos
        )
        # World positions at 3e6 are float32: within one float32 ulp (0.25) of the shifted original.
        expected = a["position"][same].astype(np.float64) + off
        ulp = np.spacing(np.abs(expected).astype(np.float32)).astype(np.float64)
        assert (np.abs(b["position"][same] - expected) <= ulp + TOL.gbuffer_depth_rel * scene.diagonal).all()


def test_zero_vertex_normals_fall_back_to_face_normals():
    # Vertex normals that cancel exactly give a zero interpolated normal: the guard must use the
    # face normal instead of producing NaN.
    verts = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    scene = scene_from_arrays(verts, np.array([[0, 1, 2]]), "tri")
    scene.__dict__["vertex_normals"] = np.zeros((3, 3))  # override the cached property
    cam = Camera(
        look_at(np.array([0.0, 0.0, -3.0]), np.zeros(3)), 16, 16, znear=0.1, zfar=10.0
    )  # sees the back
    f = render_gbuffer(scene, cam)
    assert f["mask"].sum() > 20
    assert np.isfinite(f["normal_obj"]).all()
    assert np.allclose(
        f["normal_obj"][f["mask"]], [0.0, 0.0, -1.0]
    )  # face normal +z, flipped to face the eye
    assert np.allclose(f["normal_cam"][f["mask"]], [0.0, 0.0, 1.0], atol=1e-6)


def test_big_cad_assembly_ids_match_embree():
    # 2CylinderEngine: ~110k faces after dropping degenerates; ids must index scene.faces.
    scene = load_scene("2CylinderEngine")
    cam = orbit(scene, 1, W, H, seed=7)[0]
    f = render_gbuffer(scene, cam, normals="flat")
    ref = EmbreeReference(scene).cast(cam)
    agree, mismatch = compare_ids(scene, cam, f, ref)
    assert mismatch <= TOL.gbuffer_id_mismatch_frac
    assert f["tri_id"].max() < len(scene.faces) and agree.sum() > 0.9 * f["mask"].sum()


def test_bad_cameras_and_options_raise(scenes):
    scene = scenes["spot"]
    cam = orbit(scene, 1, 8, 8)[0]
    with pytest.raises(NeuralaoError):
        GBufferRenderer(scene, normals="phong")
    r = GBufferRenderer(scene)
    for bad in (cam.with_size(0, 8), cam.with_size(8, -1), Camera(cam.pose * np.nan, 8, 8)):
        with pytest.raises(NeuralaoError):
            r.render(bad)
    with pytest.raises(NeuralaoError):
        r.render(Camera(cam.pose, 8, 8, cam.yfov, znear=1.0, zfar=0.5))
    r.close()
    with pytest.raises(NeuralaoError):
        r.render(cam)


_SUBPROCESS_RENDER = """
import json, sys
import numpy as np
from neuralao.pipeline.geometry.camera import orbit
from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.runtime.gl import context
scene = load_scene("spot")
frame = render_gbuffer(scene, orbit(scene, 2, {w}, {h}, seed=4)[1])
np.savez(sys.argv[1], **{{k: v for k, v in frame.items() if k in {keys!r}}})
print(json.dumps({{"platform": context().platform}}))
"""


def test_egl_and_osmesa_render_the_same_frame(tmp_path, scenes):
    # PYOPENGL_PLATFORM is read when PyOpenGL is imported, so the other platform runs in a subprocess.
    from neuralao.runtime.gl import context

    here = context().platform
    other = "egl" if here == "osmesa" else "osmesa"
    scene = scenes["spot"]
    mine = render_gbuffer(scene, orbit(scene, 2, W, H, seed=4)[1])
    out = tmp_path / "frame.npz"
    code = _SUBPROCESS_RENDER.format(w=W, h=H, keys=FRAME_KEYS)
    env = {**os.environ, "PYOPENGL_PLATFORM": other}
    proc = subprocess.run(
        [sys.executable, "-c", code, str(out)], env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout.strip().splitlines()[-1])["platform"] == other
    theirs = dict(np.load(out))
    fg = mine["mask"].sum()
    assert (mine["tri_id"] != theirs["tri_id"]).sum() <= TOL.gbuffer_id_mismatch_frac * fg
    same = (mine["tri_id"] == theirs["tri_id"]) & mine["mask"]
    rel = np.abs(mine["depth"][same] - theirs["depth"][same]) / mine["depth"][same]
    assert rel.max() <= TOL.gbuffer_depth_rel
    assert (
        np.einsum("ij,ij->i", mine["normal_obj"][same], theirs["normal_obj"][same]).min()
        >= TOL.gbuffer_normal_cos
    )
