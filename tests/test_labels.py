"""AO labeller against closed forms, scale/offset invariance, back-face rule, determinism.

Closed forms use Malley's method: for cosine-weighted directions about a normal, the direction's
projection (x, y) onto the tangent plane is uniform on the unit disk (density 1/pi), and
cos(theta) = sqrt(1 - x^2 - y^2). So a question about "which rays hit" becomes an area on the disk.
Monte-Carlo bounds: :func:`helpers.mc_bound` (TOL.mc_sigmas binomial standard errors).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from helpers import (
    box,
    floor_quad,
    mc_bound,
    merge,
    random_rotation,
    segment_fraction,
    transformed,
    wall_quad,
)
from scipy.integrate import quad as integrate

from neuralao.pipeline.geometry.camera import orbit
from neuralao.pipeline.geometry.scene import Scene, load_scene
from neuralao.pipeline.tracing.labeller import (
    Labeller,
    LabelSettings,
    normalize_normals,
    onb,
    pixel_directions,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import load_settings
from neuralao.runtime.foundation.tolerances import TOL

RAYS = 256
N_POINTS = 200


def _floor_points(n: int, spread: float, seed: int = 0) -> np.ndarray:
    """(n, 3) points on z = 0 with x, y uniform in [-spread, spread]."""
    rng = np.random.default_rng(seed)
    return np.c_[rng.uniform(-spread, spread, (n, 2)), np.zeros(n)]


def _up(n: int) -> np.ndarray:
    return np.tile([0.0, 0.0, 1.0], (n, 1))


# ----------------------------------------------------------------------------- closed forms


def _parallel_planes(h: float, R: float) -> Scene:
    # Floor (the points lie on it) and a ceiling at height h facing down, both extending beyond
    # R + spread so every ray that could hit within R does: "infinite" planes for this R.
    return merge(floor_quad(4 * R), floor_quad(4 * R, z=h, up=False))


@pytest.mark.parametrize("h, R", [(1.0, 2.0), (1.0, 4.0)])
def test_parallel_planes_binary_is_h_over_R_squared(h, R):
    # A ray at polar angle theta escapes within R iff h / cos(theta) > R, i.e. cos(theta) < h / R;
    # under cosine weighting P(cos(theta) < c) = c^2 (disk: radius^2 > 1 - c^2).
    lab = Labeller(_parallel_planes(h, R), LabelSettings(rays=RAYS, max_distance=R))
    ao, valid = lab.ao_at_points(_floor_points(N_POINTS, 0.5), _up(N_POINTS))
    expected = (h / R) ** 2
    assert valid.all()  # the ceiling faces the points: no back-face hits
    assert abs(ao.mean() - expected) <= mc_bound(expected, N_POINTS * RAYS)
    assert np.all(np.abs(ao - expected) <= mc_bound(expected, RAYS))


def test_parallel_planes_obscurance_matches_quadrature():
    # Ray with mu = cos(theta) (density 2 mu) hits at d = h / mu; rho = 1 - 2^(-d / d_half) when
    # d < R, else 1.  AO = int_0^1 2 mu rho(h / mu) dmu, split at mu0 = h / R.
    h, R, d_half = 1.0, 2.0, 0.5
    lab = Labeller(
        _parallel_planes(h, R),
        LabelSettings(rays=RAYS, max_distance=R, kernel="obscurance", half_distance=d_half),
    )
    ao, valid = lab.ao_at_points(_floor_points(N_POINTS, 0.5), _up(N_POINTS))
    mu0 = h / R
    occluded, _ = integrate(
        lambda mu: 2 * mu * (1 - 2.0 ** (-h / mu / d_half)), mu0, 1.0, epsabs=1e-12, epsrel=1e-12
    )
    expected = mu0**2 + occluded
    assert valid.all()
    assert abs(ao.mean() - expected) <= mc_bound(expected, N_POINTS * RAYS)
    assert np.all(np.abs(ao - expected) <= mc_bound(expected, RAYS))
    # Guard against a kernel mix-up: the binary answer would be (h/R)^2 = 0.25, far outside the bound.
    assert abs(expected - mu0**2) > 10 * mc_bound(expected, N_POINTS * RAYS)


def _wall_scene(d: float, R: float, facing_point: bool = True) -> Scene:
    # Points on the floor near the origin, a wall at x = d, wider and taller than R.
    return merge(floor_quad(4 * R), wall_quad(d, half_width=2 * R, height=2 * R, facing_minus_x=facing_point))


def wall_binary_reference(c: float) -> float:
    """Accessibility next to an infinite wall at distance d, max distance R, c = d / R.

    Derivation: a ray with tangent-plane projection (x, y) (x towards the wall) travels
    t = d / x to reach the wall plane, so it hits within R iff x > c; the wall is tall and wide
    enough that every such ray meets it (height t cos(theta) <= R, lateral |t y| <= R). With (x, y)
    uniform on the unit disk, P(hit) = area{x > c} / pi = (acos c - c sqrt(1 - c^2)) / pi.
    """
    return 1.0 - segment_fraction(c)


def wall_obscurance_reference(d: float, R: float, d_half: float) -> float:
    """Obscurance next to the wall: 1 - E[(1 - rho) 1{hit}], with the disk strip at x having
    height 2 sqrt(1 - x^2): AO = 1 - (1/pi) int_c^1 2 sqrt(1 - x^2) 2^(-(d / x) / d_half) dx."""
    c = d / R
    lost, _ = integrate(
        lambda x: 2 * math.sqrt(1 - x * x) * 2.0 ** (-(d / x) / d_half), c, 1.0, epsabs=1e-12, epsrel=1e-12
    )
    return 1.0 - lost / math.pi


@pytest.mark.parametrize("orientation", ["identity", "upside_down", "random"])
@pytest.mark.parametrize("kernel", ["binary", "obscurance"])
def test_wall_matches_disk_formula(kernel, orientation):
    # Rotating the whole configuration exercises the tangent frame for arbitrary normals, including
    # n = -z exactly (the one place the Duff et al. frame switches branch).
    d, R, d_half = 0.5, 2.0, 0.4
    rot = {"identity": np.eye(3), "upside_down": np.diag([1.0, -1.0, -1.0]), "random": random_rotation(3)}[
        orientation
    ]
    scene = transformed(_wall_scene(d, R), rot)
    settings = LabelSettings(rays=RAYS, max_distance=R, kernel=kernel, half_distance=d_half)
    # Points at distance exactly d from the wall: x = 0, y spread along the wall.
    pts = np.c_[np.zeros(N_POINTS), np.linspace(-0.5, 0.5, N_POINTS), np.zeros(N_POINTS)]
    ao, valid = Labeller(scene, settings).ao_at_points(pts @ rot.T, _up(N_POINTS) @ rot.T)
    expected = wall_binary_reference(d / R) if kernel == "binary" else wall_obscurance_reference(d, R, d_half)
    if kernel == "binary":  # the closed form against quadrature of the same disk integral
        assert abs(expected - wall_obscurance_reference(d, R, 1e15)) < 1e-9  # d_half -> inf: rho = 0 on hit
    assert valid.all()
    assert abs(ao.mean() - expected) <= mc_bound(expected, N_POINTS * RAYS)
    assert np.all(np.abs(ao - expected) <= mc_bound(expected, RAYS))


# ----------------------------------------------------------------------------- back faces


@pytest.mark.parametrize("kernel", ["binary", "obscurance"])
def test_point_inside_closed_box_outward_normals_is_invalid(kernel):
    pts = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.1]])
    normals = np.array([[0.0, 0.0, 1.0], [0.2, 0.5, -1.0]])
    settings = LabelSettings(rays=RAYS, max_distance=10.0, kernel=kernel)
    outward = merge(box(1.0, inward=False))
    assert np.all(np.einsum("ij,ij->i", outward.face_normals, outward.triangles.mean(1)) > 0)
    ao, valid = Labeller(outward, settings).ao_at_points(pts, normals)
    assert not valid.any()
    assert np.isfinite(ao).all() and np.all((ao >= 0) & (ao <= 1))
    if kernel == "binary":
        assert np.all(ao == 0.0)  # every ray hits a wall within 10
    ao_in, valid_in = Labeller(merge(box(1.0, inward=True)), settings).ao_at_points(pts, normals)
    assert valid_in.all()
    assert np.array_equal(ao_in, ao)  # the rule changes validity, never the ao value
    # Disabled rule: everything valid.
    for off in (None, -1.0):
        _, v = Labeller(outward, replace(settings, backface_threshold=off)).ao_at_points(pts, normals)
        assert v.all()


def test_backface_fraction_threshold():
    # Wall turned away from the points: every ray that hits it hits a back face, a fraction
    # segment_fraction(d/R) of all rays (~0.37 for c = 0.2, QMC error << 0.05 per point).
    d, R = 0.4, 2.0
    frac = segment_fraction(d / R)
    assert 0.3 < frac < 0.45
    scene = _wall_scene(d, R, facing_point=False)
    pts, up = _floor_points(50, 0.0), _up(50)
    for threshold, expect_valid in [(frac - 0.05, False), (frac + 0.05, True)]:
        _, valid = Labeller(
            scene, LabelSettings(rays=RAYS, max_distance=R, backface_threshold=threshold)
        ).ao_at_points(pts, up)
        assert np.all(valid == expect_valid), threshold


# ----------------------------------------------------------------------------- scale, offset, speckle


SCALES = [(1e-3, 0.0), (1e4, 0.0), (1.0, 1e6), (1e4, 1e6)]


@pytest.mark.parametrize("bvh", ["robust", "fast"])
@pytest.mark.parametrize("kernel", ["binary", "obscurance"])
@pytest.mark.parametrize("scale, offset", [(1.0, 0.0), *SCALES])
def test_open_tilted_plane_has_no_self_hits(kernel, scale, offset, bvh):
    # A single tilted, finely triangulated plane: the only thing a ray can hit is the surface it
    # leaves from, so any hit is self-intersection speckle. ao must be exactly 1 everywhere,
    # including points on triangle edges and vertices.
    rot = random_rotation(7)
    g = np.linspace(-1, 1, 11)
    xx, yy = np.meshgrid(g, g)
    verts = np.c_[xx.ravel(), yy.ravel(), np.zeros(xx.size)]
    idx = np.arange(121).reshape(11, 11)
    a, b, c, e = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.r_[np.c_[a, b, c], np.c_[a, c, e]]
    scene = Scene(verts @ rot.T * scale + offset, faces)
    rng = np.random.default_rng(1)
    local = np.r_[
        np.c_[rng.uniform(-0.9, 0.9, (300, 2)), np.zeros(300)],
        verts[12:109:5],
        (verts[12:108:5] + verts[13:109:5]) / 2,
    ]
    pts = local @ rot.T * scale + offset
    normals = np.tile(rot[:, 2], (len(pts), 1))
    settings = LabelSettings(rays=RAYS, kernel=kernel, max_distance_rel=1.0)
    ao, valid = Labeller(scene, settings, bvh=bvh).ao_at_points(pts, normals)
    assert valid.all()
    assert np.all(ao == 1.0), f"{np.count_nonzero(ao < 1)} points see their own surface"


@pytest.fixture(scope="module")
def spot() -> Scene:
    return load_scene("spot")


@pytest.fixture(scope="module")
def spot_samples(spot):
    rng = np.random.default_rng(0)
    idx = rng.choice(len(spot.faces), 400, replace=False)
    bary = rng.dirichlet([1, 1, 1], 400)
    return np.einsum("ij,ijk->ik", bary, spot.triangles[idx]), spot.face_normals[idx]


@pytest.mark.parametrize("kernel", ["binary", "obscurance"])
@pytest.mark.parametrize("scale, offset", SCALES)
def test_points_scale_and_offset_invariant(spot, spot_samples, kernel, scale, offset):
    pts, normals = spot_samples
    settings = LabelSettings(rays=RAYS, kernel=kernel)
    ao0, valid0 = Labeller(spot, settings).ao_at_points(pts, normals)
    ao1, valid1 = Labeller(spot.scaled(scale, offset), settings).ao_at_points(pts * scale + offset, normals)
    p = np.clip(ao0.astype(np.float64), 0, 1)
    # Same seed, same rays up to float rounding: differences must stay within MC noise of a
    # difference of two estimates (variance 2 p (1 - p) / n).
    assert np.all(np.abs(ao1 - ao0) <= mc_bound(p, RAYS / 2))
    assert abs(ao1.mean() - ao0.mean()) <= mc_bound(p.mean(), len(p) * RAYS / 2)
    assert np.mean(valid1 != valid0) <= 0.01


def _spot_frame(spot: Scene, size: int = 64) -> dict:
    from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer

    return render_gbuffer(spot, orbit(spot, 3, size, size, seed=1)[0])


def _moved_frame(frame: dict, scale: float, offset: float) -> dict:
    pose = frame["pose"].copy()
    pose[:3, 3] = pose[:3, 3] * scale + offset
    return {**frame, "pose": pose}


def test_label_frame_agrees_with_points_and_is_scale_and_offset_invariant(spot):
    frame = _spot_frame(spot)
    settings = LabelSettings(rays=RAYS)
    lab = Labeller(spot, settings)
    ao, valid = lab.label_frame(frame)
    fg = frame["tri_id"] >= 0
    assert ao.dtype == np.float32 and valid.dtype == bool and ao.shape == fg.shape
    assert np.all(ao[~fg] == 1.0) and not valid[~fg].any()
    assert fg.sum() > 500 and valid[fg].mean() > 0.95

    # Independent geometry: the G-buffer's own (float32, rasterised) positions with the same
    # triangle's normal facing the camera and the same per-pixel ids give the same labels up to MC noise.
    pix = np.flatnonzero(fg)
    tri = frame["tri_id"].reshape(-1)[pix]
    n = spot.face_normals[tri]
    to_cam = frame["pose"][:3, 3] - frame["position"].reshape(-1, 3)[pix]
    n = np.where((np.einsum("ij,ij->i", n, to_cam) < 0)[:, None], -n, n)
    ao_pts, _ = lab.ao_at_points(frame["position"].reshape(-1, 3)[pix].astype(np.float64), n, ids=pix)
    p = ao.reshape(-1)[pix].astype(np.float64)
    assert abs(ao_pts.mean() - p.mean()) <= mc_bound(p.mean(), len(p) * RAYS / 2)

    for scale, offset in SCALES:
        moved = Labeller(spot.scaled(scale, offset), settings)
        ao1, valid1 = moved.label_frame(_moved_frame(frame, scale, offset))
        assert np.all(ao1[~fg] == 1.0)
        d = np.abs(ao1 - ao)[fg]
        assert np.all(d <= mc_bound(ao[fg].astype(np.float64), RAYS / 2)), (scale, offset)
        assert abs(ao1[fg].mean() - ao[fg].mean()) <= mc_bound(ao[fg].mean(), fg.sum() * RAYS / 2)
        assert np.mean(valid1[fg] != valid[fg]) <= 0.01


@pytest.mark.parametrize("view", ["floor_from_above", "ceiling_from_below", "floor_from_below"])
def test_label_frame_closed_form_between_planes(view):
    # Parallel planes at z = 0 (normal +z) and z = h (normal -z). Seen from between them, every
    # visible point has the closed form (h/R)^2 (the ceiling by symmetry). Seen from below the
    # floor, the camera sees the floor's back face: its normal must be flipped to face the camera
    # (-z), where nothing occludes, so ao = 1 exactly.
    from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
    from neuralao.pipeline.geometry.camera import Camera, look_at

    h, R = 1.0, 2.0
    scene = merge(floor_quad(50.0), floor_quad(50.0, z=h, up=False))
    eye, target = {
        "floor_from_above": ([0.0, 0.0, 0.5], [0.1, 0.2, 0.0]),
        "ceiling_from_below": ([0.0, 0.0, 0.5], [0.1, -0.2, 1.0]),
        "floor_from_below": ([0.0, 0.0, -0.5], [0.1, 0.2, 0.0]),
    }[view]
    camera = Camera(look_at(np.array(eye), np.array(target)), 24, 20, math.radians(40.0), 0.01, 10.0)
    frame = render_gbuffer(scene, camera)
    fg = frame["tri_id"] >= 0
    assert fg.all()
    ao, valid = Labeller(scene, LabelSettings(rays=RAYS, max_distance=R)).label_frame(frame)
    assert valid.all()
    if view == "floor_from_below":
        assert np.all(ao == 1.0)
    else:
        expected = (h / R) ** 2
        assert np.all(np.abs(ao - expected) <= mc_bound(expected, RAYS))
        assert abs(ao.mean() - expected) <= mc_bound(expected, ao.size * RAYS)


def test_label_frame_background_only_and_bad_input(spot):
    lab = Labeller(spot, LabelSettings(rays=8))
    frame = {"tri_id": np.full((4, 5), -1, np.int32), "pose": np.eye(4), "yfov": 0.8}
    ao, valid = lab.label_frame(frame)
    assert np.all(ao == 1.0) and not valid.any() and ao.shape == (4, 5)
    with pytest.raises(NeuralaoError, match="tri_id"):
        lab.label_frame({"pose": np.eye(4), "yfov": 0.8})
    with pytest.raises(NeuralaoError, match="outside"):
        lab.label_frame({**frame, "tri_id": np.full((4, 5), len(spot.faces), np.int32)})


# ----------------------------------------------------------------------------- determinism, inputs


def test_deterministic_whatever_the_workers_and_batching(spot, spot_samples):
    pts, normals = spot_samples
    for kernel, backface in [("binary", None), ("binary", 0.25), ("obscurance", 0.25)]:
        settings = LabelSettings(rays=64, kernel=kernel, backface_threshold=backface, seed=5)
        lab = Labeller(spot, replace(settings, workers=1))
        ref = lab.ao_at_points(pts, normals)
        lab2 = Labeller(spot, replace(settings, workers=2))
        lab2._chunk_points = 7  # many uneven chunks, finished in any order
        got = lab2.ao_at_points(pts, normals)
        assert np.array_equal(ref[0], got[0]) and np.array_equal(ref[1], got[1])
        # A point's rays depend on (seed, id), not on its position in the batch.
        perm = np.random.default_rng(0).permutation(len(pts))
        ao_p, valid_p = lab2.ao_at_points(pts[perm], normals[perm], ids=perm)
        assert np.array_equal(ao_p, ref[0][perm]) and np.array_equal(valid_p, ref[1][perm])
        other = Labeller(spot, replace(settings, seed=6)).ao_at_points(pts, normals)[0]
        assert np.mean(other != ref[0]) > 0.5


def test_zero_nan_and_unnormalised_normals_give_finite_results(spot, spot_samples):
    pts, normals = (a[:6] for a in spot_samples)
    bad = normals.copy()
    bad[0] = 0.0
    bad[1] = np.nan
    bad[2] = [np.inf, 0.0, 1.0]
    bad[3] = normals[3] * 4.0  # power of two: exactly the same unit normal
    bad[4] = normals[4] * 1e-300
    bad[5] = normals[5] * 1e300
    points = np.r_[pts, [[np.nan, 0.0, 0.0]]]
    for kernel in ("binary", "obscurance"):
        lab = Labeller(spot, LabelSettings(rays=64, kernel=kernel))
        ao, valid = lab.ao_at_points(points, np.r_[bad, normals[:1]])
        assert np.isfinite(ao).all() and np.all((ao >= 0) & (ao <= 1))
        assert valid.tolist()[:3] == [False, False, False] and not valid[6]
        assert ao[6] == 1.0
        ref, ref_valid = lab.ao_at_points(pts, normals)
        assert ao[3] == ref[3] and valid[3] == ref_valid[3]
        assert np.all(np.abs(ao[4:6] - ref[4:6]) <= mc_bound(ref[4:6].astype(np.float64), 32))


def test_tangent_frame_is_orthonormal_everywhere():
    rng = np.random.default_rng(0)
    n = np.r_[rng.normal(size=(1000, 3)), np.eye(3), -np.eye(3), [[0.0, 0.0, -0.0], [1e-300, 0, -1]]]
    unit, ok = normalize_normals(n)
    assert ok.tolist()[-2:] == [False, True]
    t, b = onb(unit)
    for u, v in [(t, b), (t, unit), (b, unit)]:
        assert np.abs(np.einsum("ij,ij->i", u, v)).max() < 1e-12
    for u in (t, b, unit):
        assert np.abs(np.linalg.norm(u, axis=1) - 1).max() < 1e-12
    assert np.abs(np.cross(t, b) - unit).max() < 1e-12


def test_settings_resolve_relative_to_diagonal_and_reject_bad_values(spot):
    lab = Labeller(spot.scaled(10.0), LabelSettings())
    d = spot.diagonal * 10.0
    assert lab.max_distance == pytest.approx(0.25 * d) and lab.half_distance == pytest.approx(0.05 * d)
    assert lab.offset == pytest.approx(1e-5 * d)
    assert Labeller(spot, LabelSettings(max_distance=0.5)).max_distance == 0.5
    s = load_settings(LabelSettings, None, ["kernel=obscurance", "rays=16", "backface_threshold=null"])
    assert s.kernel == "obscurance" and s.rays == 16 and s.backface_threshold is None
    for bad in [{"kernel": "nope"}, {"rays": 0}, {"max_distance": -1.0}, {"workers": 0}, {"offset_rel": 0.5}]:
        with pytest.raises(NeuralaoError):
            Labeller(spot, replace(LabelSettings(), **bad))
    with pytest.raises(NeuralaoError):
        load_settings(LabelSettings, None, ["kernel=nope"])


def test_binary_mean_matches_tol_scale():
    # Sanity of the bound itself: 5 sigma of a binomial mean; keeps the tests above meaningful.
    assert TOL.mc_sigmas >= 3 and mc_bound(0.5, 10_000) < 0.03


def test_pixel_directions_match_camera_pixel_rays(spot):
    cam = orbit(spot, 2, 13, 7, seed=3)[1]
    _, ref = cam.pixel_rays()
    pix = np.array([0, 5, 12, 13, 50, 90])
    assert np.abs(pixel_directions(cam, pix) - ref[pix]).max() < 1e-14


def test_rays_are_unit_and_cosine_distributed(spot):
    # Cosine-weighted hemisphere: E[cos] = 2/3, E[cos^2] = 1/2, every direction above the surface;
    # origins sit offset_rel (in local units: fraction of the diagonal) along the normal.
    rng = np.random.default_rng(4)
    normals = rng.normal(size=(50, 3))
    points = spot.center + rng.uniform(-0.1, 0.1, (50, 3))
    lab = Labeller(spot, LabelSettings(rays=RAYS))
    origins, dirs = lab.rays(points, normals)
    unit = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    cos = np.einsum("ij,ij->i", dirs.astype(np.float64), np.repeat(unit, RAYS, axis=0))
    assert np.abs(np.linalg.norm(dirs, axis=1) - 1).max() < 1e-6
    assert cos.min() > -1e-6
    assert abs(cos.mean() - 2 / 3) <= mc_bound(2 / 3, cos.size)
    assert abs((cos**2).mean() - 1 / 2) <= mc_bound(1 / 2, cos.size)
    expect = (points - spot.center) / spot.diagonal + 1e-5 * unit
    assert np.abs(origins[::RAYS] - expect).max() < 1e-6


def test_label_frame_equals_visible_points_then_ao_at_points(spot):
    # The contract other stages rely on (labelling only some pixels): bit-identical results.
    frame = _spot_frame(spot, 32)
    lab = Labeller(spot, LabelSettings(rays=32, seed=9))
    ao, valid = lab.label_frame(frame)
    points, normals, pix, exact = lab.visible_points(frame)
    sub = pix[::3]
    a, v = lab.ao_at_points(points[::3], normals[::3], ids=sub)
    assert np.array_equal(a, ao.reshape(-1)[sub]) and np.array_equal(v & exact[::3], valid.reshape(-1)[sub])


# ----------------------------------------------------------------------------- several radii, one trace

RADII_REL = [0.02, 0.05, 0.1, 0.25, 0.6]


@pytest.mark.parametrize("kernel", ["binary", "obscurance"])
@pytest.mark.parametrize("threshold", [0.25, None])
def test_radii_from_one_trace_equal_separate_traces(spot, spot_samples, kernel, threshold):
    # One INTERSECT to the largest radius, then per radius: bit-identical to a separate trace with
    # max_distance = r (the same rays, the same hit test, the same arithmetic), ao and validity.
    pts, normals = spot_samples
    settings = LabelSettings(
        rays=64, kernel=kernel, backface_threshold=threshold, seed=3, radii_rel=RADII_REL
    )
    lab = Labeller(spot, settings)
    ao, valid = lab.ao_radii_at_points(pts, normals)
    assert ao.shape == valid.shape == (len(pts), len(RADII_REL)) and ao.dtype == np.float32
    assert lab.radii == tuple(r * spot.diagonal for r in RADII_REL)
    for j, r in enumerate(lab.radii):
        lab.settings = replace(settings, max_distance=r)
        ao_r, valid_r = lab.ao_at_points(pts, normals)
        assert np.array_equal(ao[:, j], ao_r), f"radius {j}: {np.count_nonzero(ao[:, j] != ao_r)} differ"
        assert np.array_equal(valid[:, j], valid_r)
    # Something actually varies with the radius (else the equality above would be vacuous).
    assert ao[:, 0].mean() > ao[:, -1].mean() + 0.02


@pytest.mark.parametrize("kernel", ["binary", "obscurance"])
def test_ao_does_not_increase_with_radius(spot, kernel):
    # A ray blocked within r is blocked within any r' > r (binary); rho only drops as hits within
    # reach are added (obscurance): so per pixel, and so on average, AO cannot rise with the radius.
    frame = _spot_frame(spot, 32)
    lab = Labeller(spot, LabelSettings(rays=32, kernel=kernel, seed=2, radii_rel=RADII_REL))
    ao, valid = lab.label_frame_radii(frame)
    fg = frame["tri_id"] >= 0
    assert ao.shape == (*fg.shape, len(RADII_REL)) and np.all(ao[~fg] == 1.0) and not valid[~fg].any()
    assert np.all(np.diff(ao, axis=-1) <= 0)
    means = ao[fg].mean(axis=0)
    assert np.all(np.diff(means) < 0), means
    # The frame version is the points version on the visible points (as label_frame is).
    points, normals, pix, exact = lab.visible_points(frame)
    a, v = lab.ao_radii_at_points(points, normals, ids=pix)
    assert np.array_equal(a, ao.reshape(-1, len(RADII_REL))[pix])
    assert np.array_equal(v & exact[:, None], valid.reshape(-1, len(RADII_REL))[pix])


def test_radii_settings_are_validated(spot):
    lab = Labeller(spot, LabelSettings(rays=8))
    assert lab.radii is None
    with pytest.raises(NeuralaoError, match="radii"):
        lab.ao_radii_at_points(np.zeros((1, 3)), np.ones((1, 3)))
    for bad in ([], [0.1, -0.2], [float("nan")]):
        with pytest.raises(NeuralaoError, match="radi"):
            Labeller(spot, LabelSettings(rays=8, radii_rel=bad))
    # Explicit radii (scene units) override the settings and need not be sorted.
    a, _ = lab.ao_radii_at_points(spot.vertices[:5], spot.vertex_normals[:5], radii=[0.5, 0.1])
    assert a.shape == (5, 2) and np.all(a[:, 0] <= a[:, 1])
