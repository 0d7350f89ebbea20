"""bench/ao_visibility_bound.py's screen-space marcher against closed forms, on G-buffers ray-cast by Embree
from small analytic scenes (no rendering): a floor beside a thick wall (binary AO ``1 - segment_fraction(h /
r)`` at distance h from it), a bare floor (AO 1: no self-occlusion from the layers), and a floor under a
floating plate the camera sees in front of it (AO 1, which two layers get and the height field does not)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import trimesh
from helpers import box, floor_quad, merge, quad, segment_fraction

from neuralao.pipeline.geometry.camera import Camera, look_at
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location(
    "ao_visibility_bound", ROOT / "bench" / "ao_visibility_bound.py"
)
vb = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = vb  # its dataclasses look their module up
_spec.loader.exec_module(vb)

SIZE = 128
R = 1.0  # the AO radius, scene units


def _slab(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Closed box [lo, hi] (outward normals)."""
    v, f = box(0.5, inward=False)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return (v + 0.5) * (hi - lo) + lo, f


def _gbuffer(lab: Labeller, eye, target, yfov: float = 1.2217) -> dict:
    """tri_id, depth, pose, yfov (radians; 70 degrees) of a camera, from Embree's first hits through the
    pixel centres."""
    pose = look_at(np.asarray(eye, float), np.asarray(target, float), up=np.array([0.0, 0.0, 1.0]))
    cam = Camera(pose, SIZE, SIZE, float(yfov))
    _, d = cam.pixel_rays()
    prim, t = vb._cast(lab, np.broadcast_to((pose[:3, 3] - lab.center) / lab.scale, d.shape), d)
    depth = np.where(prim >= 0, t * lab.scale * (d @ -pose[:3, 2]), 0.0)
    return {
        "tri_id": prim.reshape(SIZE, SIZE).astype(np.int32),
        "depth": depth.reshape(SIZE, SIZE).astype(np.float32),
        "pose": pose,
        "yfov": float(yfov),
    }


def _march(scene, eye, target, rays: int, steps: int, pick):
    """The variants' AO, mesh AO with the same rays, and the labels' points of the pixels ``pick`` selects
    (a function of the points (k, 3) and their triangles (k,) -> bool (k,))."""
    lab = Labeller(scene, LabelSettings(rays=rays, seed=3))
    frame = _gbuffer(lab, eye, target)
    normals = np.nan_to_num(np.asarray(scene.unit_face_normals(), float))
    layers = vb.frame_layers(lab, normals, frame)
    tri = frame["tri_id"].reshape(-1)[layers.pix]
    sel = np.flatnonzero(pick(layers.points, tri))
    assert len(sel) >= 20
    org, dirs, blocked = vb.frame_rays(lab, layers, sel, radii=[R])
    jitter = vb.step_jitter(3, layers.pix[sel], rays)
    ao, oracle, off, _ = vb.march(layers.screen, org, dirs, jitter, R / lab.scale, steps, blocked[..., 0])
    mesh, _ = lab.ao_radii_at_points(layers.points[sel], layers.normals[sel], radii=[R], ids=layers.pix[sel])
    # the marched rays are the labeller's: their own mesh hits give its AO exactly
    assert np.array_equal(1.0 - blocked[..., 0].sum(axis=1) / rays, mesh[:, 0])
    # off screen the oracle takes the mesh's answer, on screen the variant's
    assert np.all(np.abs(oracle - ao) <= (off > 0)[:, None])
    return dict(zip(vb.VARIANTS, ao.T, strict=True)), mesh[:, 0], layers, sel, off, lab


def test_floor_beside_thick_wall_matches_segment_fraction():
    # Floor z = 0 up to a closed wall block x in [0.5, 2.5]; a floor point at distance h < R from the wall
    # has binary AO 1 - segment_fraction(h / R): cosine-weighted directions project uniformly onto the disk.
    floor = quad([[-6, -6, 0], [0.5, -6, 0], [0.5, 6, 0], [-6, 6, 0]])
    scene = merge(floor, _slab([0.5, -6, 0], [2.5, 6, 4]))
    ao, mesh, layers, sel, off, lab = _march(
        scene,
        eye=[-2.2, 0.3, 1.6],
        target=[0.2, 0, 0.3],
        rays=256,
        steps=64,
        pick=lambda p, tri: (tri < 2) & (np.abs(p[:, 1]) < 0.3) & (p[:, 0] > -0.3) & (p[:, 0] < 0.3),
    )
    h = 0.5 - layers.points[sel, 0]
    expected = np.array([1.0 - segment_fraction(v / R) for v in h])
    assert off.sum() == 0  # everything the rays can meet is on screen
    assert np.abs(mesh - expected).mean() < 0.01  # the closed form is the labels' (sanity)
    assert np.all(layers.screen.table[layers.pix[sel], vb._OPEN] == 1)  # the floor is open (a single quad)
    for name in ("1L-inf", "1L-T=r", "1L-T=r/4", "2L-thin", "2L-inf"):
        # the same rays as the mesh: only the marching differs (a hit within the last step is missed)
        assert np.abs(ao[name] - mesh).max() <= 4 / 256, name
        assert abs(np.mean(ao[name] - expected)) < 0.01, name
    # the wall's front pixels are closed, their back layer the block's far face x = 2.5: the point where the
    # camera ray through the pixel centre leaves the block lies on the back plane
    wall = np.flatnonzero((np.abs(layers.points[:, 0] - 0.5) < 1e-9) & (layers.points[:, 2] > 1e-6))
    table = layers.screen.table[layers.pix[wall]]
    assert len(wall) > 100 and np.all(table[:, vb._OPEN] == 0)
    eye = layers.cam_local * lab.scale + lab.center
    ray = layers.points[wall] - eye
    leave = eye + ray * ((2.5 - eye[0]) / ray[:, :1])
    far = (leave[:, 2] > 0) & (leave[:, 2] < 4) & (np.abs(leave[:, 1]) < 6)  # not out by another face
    y = ((leave[far] - lab.center) / lab.scale - layers.cam_local) @ layers.to_cam
    assert far.sum() > 100
    assert np.abs(np.sum(table[far, 4:7] * y, axis=1) - table[far, 7]).max() < 1e-5


def test_bare_floor_is_unoccluded():
    scene = merge(floor_quad(6.0))
    ao, mesh, *_ = _march(
        scene, eye=[-3, 0.5, 1.2], target=[1, 0, 0], rays=64, steps=32, pick=lambda p, tri: tri >= 0
    )
    assert np.all(mesh == 1.0)
    for name in ("1L-inf", "1L-T=r", "1L-T=r/4", "2L-thin", "2L-inf"):
        assert np.all(ao[name] == 1.0), name  # a sample over a flat layer is never behind it


def test_plate_above_floor_hides_nothing_from_two_layers():
    # A plate z in [2, 2.1] floats out of reach (R = 1) of the floor; the camera sees it in front of the floor
    # around its image. Exact AO is 1 on the floor: two layers (the plate's bottom is its back) find nothing,
    # while the height field takes the space under the plate for solid.
    scene = merge(floor_quad(6.0), _slab([-1, -1, 2.0], [1, 1, 2.1]))
    ao, mesh, *_ = _march(
        scene,
        eye=[-4, 0, 5],
        target=[0.5, 0, 0],
        rays=64,
        steps=32,
        pick=lambda p, tri: (tri < 2) & (np.abs(p[:, 2]) < 1e-9) & (np.abs(p[:, 1]) < 1.5),
    )
    assert np.all(mesh == 1.0)
    for name in ("2L-thin", "2L-inf", "1L-T=r/4"):
        assert np.all(ao[name] == 1.0), name
    assert ao["1L-inf"].min() < 0.8  # the height field is occluded behind the plate's image
    assert np.mean(ao["1L-inf"] < 1.0) > 0.05


def test_sphere_on_floor_two_layers_match_the_mesh():
    # A closed sphere resting on a floor: everything a ray can meet is on screen and either visible or
    # inside the sphere's [front, back] slab, so two layers must give the mesh's AO with the same rays up
    # to marching error. Fine steps must not add false hits near the origin, where a neighbouring pixel's
    # facet plane misplaces a curved surface (without the near-origin rule: RMSE 0.015 at 64 steps).
    ico = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    scene = merge(floor_quad(6.0), (np.asarray(ico.vertices) + [0.0, 0.0, 1.0], np.asarray(ico.faces)))
    ao, mesh, *_ = _march(
        scene,
        eye=[-3.5, 0.4, 2.5],
        target=[0, 0, 0.8],
        rays=64,
        steps=64,
        pick=lambda p, tri: np.arange(len(tri)) % 3 == 0,
    )
    assert mesh.min() < 0.5  # the contact is dark
    err = ao["2L-thin"] - mesh
    assert np.sqrt(np.mean(err**2)) < 0.011
    assert abs(np.mean(err)) < 0.005
    assert np.sqrt(np.mean((ao["1L-inf"] - mesh) ** 2)) > 0.04  # the height field fills the far side


def _plane_depth(n: np.ndarray, c: float, w: int, h: int, yfov: float) -> np.ndarray:
    """(H, W) view depth of the camera-space plane n . x = c along each pixel-centre ray (closed form)."""
    q = vb.pixel_rays_cam(w, h, yfov, np.arange(w * h))
    return (c / (q @ n)).reshape(h, w)


def test_depth_planes_rebuild_a_tilted_plane_from_its_depth_alone():
    w, h, yfov = 24, 16, 1.0
    n = np.array([0.3, -0.5, 0.81])
    n /= np.linalg.norm(n)
    depth = _plane_depth(n, -2.0, w, h, yfov)  # the plane 2 units in front, seen at a slant
    assert (depth > 0).all()
    depth[:, :5] = np.nan  # background to the left: those edge pixels take their other neighbour
    pix = np.flatnonzero(np.isfinite(depth).reshape(-1))
    planes = vb.depth_planes(depth, yfov, pix, "depth")
    # n . x = -2 already has the camera (the origin) on its positive side, so the plane keeps its sign
    np.testing.assert_allclose(planes[:, :3], np.broadcast_to(n, (len(pix), 3)), atol=1e-9)
    np.testing.assert_allclose(planes[:, 3], -2.0, rtol=1e-9)
    flat = vb.depth_planes(depth, yfov, pix, "center")  # constant depth through each pixel centre
    np.testing.assert_allclose(flat[:, :3], np.broadcast_to([0.0, 0.0, 1.0], (len(pix), 3)), atol=0)
    row, col = np.divmod(pix, w)
    np.testing.assert_allclose(flat[:, 3], -depth[row, col], rtol=1e-12)


def test_depth_planes_take_the_nearer_side_at_a_depth_jump():
    """A pixel on a near plane beside a far one keeps its own facet: the neighbour nearer in depth."""
    w, h, yfov = 20, 12, 1.0
    near = _plane_depth(np.array([0.0, 0.0, 1.0]), -1.0, w, h, yfov)
    tilt = np.array([0.6, 0.0, 0.8])
    far = _plane_depth(tilt, -5.0, w, h, yfov)
    depth = np.where(np.arange(w)[None, :] < w // 2, near, far)
    pix = np.arange(w * h)
    planes = vb.depth_planes(depth, yfov, pix, "depth")
    col = pix % w
    np.testing.assert_allclose(
        planes[col < w // 2, :3], np.broadcast_to([0, 0, 1.0], ((col < w // 2).sum(), 3)), atol=1e-9
    )
    np.testing.assert_allclose(
        planes[col >= w // 2, :3], np.broadcast_to(tilt, ((col >= w // 2).sum(), 3)), atol=1e-9
    )
