"""Screen-space AO baselines (real GLSL on Mesa), baked vertex AO per pixel, low-ray tracing.

References are independent of the shaders: the analytic AO of an open plane (1), Embree labels for
"a corner is darker than open floor", a linear function for the barycentric interpolation.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import floor_quad, merge, wall_quad

from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.camera import Camera, look_at
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime.baselines import (
    GTAOSettings,
    SSAOSettings,
    camera_space_position,
    run_gtao,
    run_gtao_both,
    run_screen_space,
    run_ssao,
    time_screen_space,
    traced_ao,
    vertex_ao_image,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL

METHODS = ("ssao", "gtao")


def grid_plane(half: float = 1.0, n: int = 8):
    """Square [-half, half]^2 at z = 0, normal +z, as an n x n grid of quads (vertices, faces)."""
    t = np.linspace(-half, half, n + 1)
    xx, yy = np.meshgrid(t, t, indexing="ij")
    v = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return v, f


@pytest.fixture(scope="module")
def plane_frame():
    """A plane seen head-on, filling the whole 64x48 frame (no background)."""
    scene = merge(grid_plane(2.0), name="plane")
    cam = Camera(look_at(np.array([0.0, 0.0, 1.5]), np.zeros(3)), 64, 48, np.radians(40.0), 0.1, 10.0)
    frame = GBufferRenderer(scene).render(cam)
    assert frame["mask"].all()
    return scene, frame


@pytest.fixture(scope="module")
def corner():
    """Floor (z = 0, [-1, 1]^2) and a wall at x = 0.5 facing -x, seen from the open side, above."""
    scene = merge(floor_quad(1.0), wall_quad(0.5, 1.0, 1.0, facing_minus_x=True), name="corner")
    cam = Camera(
        look_at(np.array([-1.2, 0.0, 1.6]), np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])),
        80,
        64,
        np.radians(50.0),
        0.05,
        10.0,
    )
    frame = GBufferRenderer(scene).render(cam)
    radius = 0.25 * scene.diagonal
    labeller = Labeller(scene, LabelSettings(rays=256, max_distance=radius))
    gt, valid = labeller.label_frame(frame)
    return scene, frame, radius, gt, valid


@pytest.mark.parametrize("method", METHODS)
def test_plane_facing_camera_is_open(plane_frame, method):
    scene, frame = plane_frame
    ao = run_screen_space(frame, method, 0.25 * scene.diagonal)
    assert ao.shape == frame["mask"].shape and ao.dtype == np.float32
    assert np.isfinite(ao).all()
    # Open plane: exact AO = 1. SSAO's kernel never goes below the plane -> exactly 1; GTAO's
    # few jittered slices integrate the tilted (off-axis) view hemisphere only approximately.
    tol = TOL.ssao_open_plane if method == "ssao" else TOL.gtao_open_plane
    assert np.abs(ao - 1.0).max() <= tol, (method, float(ao.min()), float(ao.max()))


@pytest.mark.parametrize("method", METHODS)
def test_inside_corner_darker_than_open_floor(corner, method):
    scene, frame, radius, gt, valid = corner
    ao = run_screen_space(frame, method, radius)
    pos = frame["position"]
    floor = frame["mask"] & valid & (np.abs(pos[..., 2]) < 1e-4)
    near = floor & (pos[..., 0] > 0.5 - 0.15 * radius)  # floor close to the wall's foot
    far = floor & (pos[..., 0] < 0.5 - 1.2 * radius)  # floor out of the wall's reach
    assert near.sum() > 20 and far.sum() > 20
    # The independent reference (Embree) agrees on the geometry of the test...
    assert gt[near].mean() < gt[far].mean() - 0.2
    assert gt[far].min() == 1.0
    # ... and the screen-space method must darken the corner too.
    assert ao[near].mean() < ao[far].mean() - TOL.screen_space_corner_contrast, (
        ao[near].mean(),
        ao[far].mean(),
    )
    assert ao[far].mean() > 0.95


@pytest.mark.parametrize("method", METHODS)
def test_background_grazing_and_tiny_images_are_finite(method):
    scene = merge(grid_plane(1.0, 4), name="plane")
    for eye in ([0.0, -3.0, 0.02], [0.0, -3.0, 0.3], [0.4, 0.2, 3.0]):  # edge-on, grazing, head-on
        for w, h in ((1, 1), (2, 3), (33, 17)):
            cam = Camera(look_at(np.array(eye), np.zeros(3)), w, h, np.radians(45.0), 0.05, 20.0)
            frame = GBufferRenderer(scene).render(cam)
            ao = run_screen_space(frame, method, 0.5)
            assert ao.shape == (h, w)
            assert np.isfinite(ao).all() and (ao >= 0).all() and (ao <= 1).all()
            assert (ao[~frame["mask"]] == 1.0).all()


def test_background_only_frame_is_one():
    frame = {
        "depth": np.zeros((5, 7), np.float32),
        "normal_cam": np.zeros((5, 7, 3), np.float32),
        "mask": np.zeros((5, 7), bool),
        "yfov": 0.8,
    }
    for method in METHODS:
        assert (run_screen_space(frame, method, 1.0) == 1.0).all()


def test_settings_change_the_result_and_are_checked(corner):
    scene, frame, radius, _, _ = corner
    a = run_ssao(frame, radius, SSAOSettings(samples=8, seed=1))
    b = run_ssao(frame, radius, SSAOSettings(samples=8, seed=1))
    c = run_ssao(frame, radius, SSAOSettings(samples=8, seed=2))
    assert np.array_equal(a, b)  # seeded: deterministic
    assert not np.array_equal(a, c)
    g = run_gtao(frame, radius, GTAOSettings(slices=2, steps=4, blur=False))
    assert np.isfinite(g).all()
    with pytest.raises(NeuralaoError):
        run_ssao(frame, -1.0)
    with pytest.raises(NeuralaoError):
        run_screen_space(frame, "hbao+", radius)
    assert time_screen_space(frame, "ssao", radius, repeats=2, warmup=1) > 0


def test_gtao_both_is_one_draw_of_the_two_gtao_passes(corner):
    """One draw's blurred and unblurred images are, bit for bit, the two separate runs (which differ)."""
    _, frame, radius, _, _ = corner
    blurred, raw = run_gtao_both(frame, radius)
    assert np.array_equal(blurred, run_gtao(frame, radius))
    assert np.array_equal(raw, run_gtao(frame, radius, GTAOSettings(blur=False)))
    assert not np.array_equal(blurred, raw)
    with pytest.raises(NeuralaoError, match="blur"):
        run_gtao_both(frame, radius, GTAOSettings(blur=False))


def test_camera_space_position_matches_world_position(corner):
    """Depth-reconstructed camera-space points == the G-buffer's world positions moved to the camera."""
    _, frame, _, _, _ = corner
    m = frame["mask"]
    view = np.linalg.inv(frame["pose"])
    world = frame["position"][m].astype(np.float64)
    ref = world @ view[:3, :3].T + view[:3, 3]
    got = camera_space_position(frame)[m]
    assert np.abs(got - ref).max() <= TOL.gbuffer_depth_rel * 10 * np.abs(ref).max()


def test_vertex_ao_image_interpolates_barycentrically(corner):
    """A per-vertex field linear in position must come back as that linear function at each pixel."""
    scene, frame, _, _, _ = corner
    coef = np.array([0.1, -0.2, 0.15])
    vertex_ao = 0.5 + scene.vertices @ coef
    img = vertex_ao_image(scene, vertex_ao, frame)
    m = frame["mask"]
    ref = 0.5 + frame["position"][m].astype(np.float64) @ coef
    assert np.abs(img[m] - ref).max() < 1e-5
    assert (img[~m] == 1.0).all()
    with pytest.raises(NeuralaoError):
        vertex_ao_image(scene, vertex_ao[:-1], frame)


def test_low_ray_tracing_error_falls_with_rays(corner):
    scene, frame, radius, gt, valid = corner
    labeller = Labeller(scene, LabelSettings(rays=256, max_distance=radius))
    m = frame["mask"] & valid
    errors = {}
    for rays in (4, 64):
        ao, v, seconds = traced_ao(labeller, frame, rays, seed=5)
        assert seconds > 0 and ao.shape == gt.shape
        errors[rays] = float(np.sqrt(np.mean((ao[m] - gt[m]) ** 2)))
    assert labeller.settings.rays == 256  # restored
    # Error ~ 1/sqrt(rays): 4 -> 64 rays is 4x less; demand at least 2x.
    assert errors[64] < errors[4] / 2, errors


@pytest.mark.skipif(
    not __import__("shutil").which("glslangValidator"), reason="glslangValidator not installed"
)
def test_shaders_pass_glslang():
    """The baseline shaders are valid GLSL for a second compiler too (not only Mesa's)."""
    from neuralao.export.glsl import validate_glsl
    from neuralao.runtime.baseline_templates import fill
    from neuralao.runtime.baselines import blur_source, fragment_source

    validate_glsl(fill("fullscreen_vertex"), "vert")
    validate_glsl(fragment_source("ssao", SSAOSettings()), "frag")
    validate_glsl(fragment_source("gtao", GTAOSettings()), "frag")
    validate_glsl(blur_source(4), "frag")
