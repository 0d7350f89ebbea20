"""Per-region volume AO models for dynamic objects (Sloan et al. 2013, section 2.3).

References are independent of the code under test: closed forms (a ground plane at unbounded distance
is exactly (1 + n.z) / 2; ray distances to a plane), Gauss-Legendre quadrature of the AO integral at
finite distances, Embree-traced cosine-weighted AO from the labeller, hand-built models whose temporal
blend has a closed form, and the GLSL function run on Mesa against the numpy evaluator.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh
from helpers import box, floor_quad, merge

from neuralao.pipeline import cli
from neuralao.pipeline.bakes.volumes import (
    bake_volumes,
    free_space_regions,
    make_labeller,
    read_regions,
    spherical_ao,
)
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime.foundation import sh
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.probe import TemporalBlend, VolumeProbe, blended_path
from neuralao.runtime.volumes import Edge, Region, RegionModel, Volumes, VolumeSettings, read_volumes

FAST = VolumeSettings(samples=4, directions=256)


def unit_vectors(n: int, seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def points_in(region: Region, n: int, seed: int, margin: float = 0.0) -> np.ndarray:
    lo, hi = np.asarray(region.lo) + margin, np.asarray(region.hi) - margin
    return np.random.default_rng(seed).uniform(lo, hi, size=(n, 3))


def plane_ao_quadrature(
    height: float, half: float, normals: np.ndarray, order: int | None = None
) -> np.ndarray:
    """Exact obscurance AO above an infinite plane z = 0 at ``height``, half distance ``half``, for unit
    normals (n, 3), by Gauss-Legendre (cos theta, split at the horizon) x uniform phi quadrature; with
    ``order`` (4 or 9) the AO of V's exact SH projection of that many terms instead."""
    g, w = np.polynomial.legendre.leggauss(96)
    mu = np.concatenate([(g - 1) / 2, (g + 1) / 2])  # [-1, 0] and [0, 1]
    wmu = np.concatenate([w / 2, w / 2])
    phi = (np.arange(720) + 0.5) * 2 * np.pi / 720
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - m * m)
    dirs = np.stack([s * np.cos(p), s * np.sin(p), m], axis=-1).reshape(-1, 3)
    weight = (wmu[:, None] * np.full_like(p, 2 * np.pi / 720)).reshape(-1)
    with np.errstate(divide="ignore", over="ignore"):
        v = np.where(dirs[:, 2] >= 0, 1.0, 1.0 - np.exp2(-height / (np.abs(dirs[:, 2]) * half)))
    if order is not None:
        c = (weight * v) @ sh.basis(dirs, order)
        return sh.evaluate(sh.convolve_clamped_cosine(c)[None, :].repeat(len(normals), 0), normals)
    return (np.maximum(normals @ dirs.T, 0.0) * (weight * v)).sum(axis=1) / math.pi


# --------------------------------------------------------------------------- SH and rays


def test_sh_constants_reproduce_closed_forms():
    # Constant visibility -> AO 1 for every normal; the upper-hemisphere step -> (1 + n.z) / 2 exactly
    # with bands 0-1 (band 2 of a step vanishes; the clamped cosine kills odd bands above 1).
    n = unit_vectors(200, 0)
    open_everywhere = plane_ao_quadrature(1.0, 1e-300, n)  # half distance -> 0: every hit counts 1
    assert np.allclose(open_everywhere, 1.0, atol=1e-9)
    g, w = np.polynomial.legendre.leggauss(64)
    mu = (g + 1) / 2
    # upper hemisphere step, projected exactly (zonal: phi integrates to 2 pi, only m = 0 terms survive)
    c = np.zeros(sh.QUADRATIC)
    zonal = sh.basis(np.stack([np.sqrt(1 - mu**2), 0 * mu, mu], axis=1))
    for j in (0, 2, 6):
        c[j] = 2 * np.pi * (w / 2) @ zonal[:, j]
    ao = sh.evaluate(np.tile(sh.convolve_clamped_cosine(c), (len(n), 1)), n)
    assert abs(c[6]) < 1e-12
    assert np.allclose(ao, (1 + n[:, 2]) / 2, atol=1e-12)


def test_hits_along_match_distances_to_a_plane_and_flag_back_faces():
    scene = merge(floor_quad(50.0))
    lab = Labeller(scene, LabelSettings(max_distance_rel=4.0))
    dirs = unit_vectors(300, 1)
    pts = np.array([[0.3, -0.2, 0.7], [0.1, 0.4, -0.5]])
    dist, back = lab.hits_along(pts, np.stack([dirs, dirs]))
    down = dirs[:, 2] < -0.2  # these all land well inside the 100 x 100 plane
    assert np.allclose(dist[0, down], 0.7 / -dirs[down, 2], rtol=1e-5)
    assert np.isinf(dist[0, dirs[:, 2] > 0]).all() and not back[0].any()
    up = dirs[:, 2] > 0.2
    assert np.allclose(dist[1, up], 0.5 / dirs[up, 2], rtol=1e-5) and back[1, up].all()


# --------------------------------------------------------------------------- where the paper claims exactness


def test_ground_plane_at_unbounded_distance_is_exactly_linear_sh():
    scene = merge(floor_quad(1000.0))
    region = Region("above", (-0.5, -0.5, 0.05), (0.5, 0.5, 0.55))
    s = VolumeSettings(samples=4, directions=1024, half_distances=(1e12, 1e12))
    vol, extra = bake_volumes(scene, s, [region])
    probe = VolumeProbe(vol)
    p, n = points_in(region, 400, 2), unit_vectors(400, 3)
    exact = (1 + n[:, 2]) / 2
    lin = probe.ao(p, n, order="linear")
    quad_ = probe.ao(p, n, order="quadratic")
    # Stratified 1024-direction projection of a step: measured max error 1.1e-3 (linear), 1.2e-3 (quadratic).
    assert np.abs(lin - exact).max() < 5e-3
    assert np.abs(quad_ - exact).max() < 5e-3
    # band 2 and every derivative are zero up to the projection noise
    c = vol.models[0].coefficients
    assert np.abs(c[0, :, 4:]).max() < 5e-3 and np.abs(c[1:]).max() < 1e-2  # measured 6.6e-4, 3.2e-3


def test_ground_plane_finite_distance_matches_quadrature():
    scene = merge(floor_quad(1000.0))
    lab = make_labeller(scene, VolumeSettings())
    h, z = 0.2, 0.2
    s = VolumeSettings(directions=1024)
    coeffs, valid = spherical_ao(lab, np.array([[0.0, 0.0, z]] * 4), np.arange(4), (h, h), s)
    assert valid.all()
    n = unit_vectors(300, 4)
    exact = plane_ao_quadrature(z, h, n)
    for count in (sh.LINEAR, sh.QUADRATIC):
        traced = sh.evaluate(np.repeat(coeffs[:1, 0, :count], len(n), 0), n)
        projected = plane_ao_quadrature(z, h, n, order=count)
        assert np.abs(traced - projected).max() < 5e-3  # MC vs exact projection: measured 5.3e-4, 7.5e-4
    err_lin = np.abs(plane_ao_quadrature(z, h, n, 4) - exact).max()
    err_quad = np.abs(plane_ao_quadrature(z, h, n, 9) - exact).max()
    assert err_quad < 0.2 * err_lin  # finite distances need band 2: measured 0.048 vs 0.0031 (README)


def closed_room():
    return merge(box(1.0, inward=True), name="room")


def test_box_room_is_brightest_at_the_centre_and_darkens_towards_every_wall():
    scene = closed_room()
    region = Region("room", (-0.9,) * 3, (0.9,) * 3)
    s = VolumeSettings(samples=8, directions=512, half_distances=(0.3, 1.5))
    vol, _ = bake_volumes(scene, s, [region])
    probe = VolumeProbe(vol)
    ts = np.linspace(0.0, 0.75, 6)  # the outermost samples sit at 0.79: no extrapolation
    lab = Labeller(scene, LabelSettings(rays=1024, kernel="obscurance", max_distance_rel=4.0))
    for axis in range(3):
        for sign in (1.0, -1.0):
            pts = np.zeros((len(ts), 3))
            pts[:, axis] = sign * ts
            facing = np.zeros_like(pts)
            facing[:, axis] = sign
            # mean over normals (the DC term) and AO of a normal facing the wall: strictly decreasing
            dc = (
                probe.sh_at(pts)[:, :, 0]
                @ np.array([1 - vol.blend, vol.blend])
                * sh.basis(np.eye(3)[:1], 1)[0, 0]
            )
            ao = probe.ao(pts, facing)
            assert (np.diff(dc) < 0).all() and (np.diff(ao) < 0).all(), (axis, sign)
            # the traced reference agrees with the model
            ref = np.zeros(len(ts))
            for k, half in enumerate(vol.half_distances):
                lab.settings = LabelSettings(
                    rays=1024, kernel="obscurance", max_distance_rel=4.0, half_distance=half
                )
                ref += (vol.blend if k else 1 - vol.blend) * lab.ao_at_points(pts, facing)[0]
            assert (np.diff(ref) < 0).all()
            # piecewise-linear in position: AO curves near a wall
            # (measured max 0.080 at 0.25 from it, mean 0.039)
            assert np.abs(ao - ref).max() < 0.1 and np.abs(ao - ref).mean() < 0.05


def room_with_crate():
    crate_v, crate_f = box(0.25, inward=False)
    return merge(box(1.0, inward=True), (crate_v + [0.5, 0.5, -0.75], crate_f), name="room+crate")


def four_regions():
    return [
        Region(f"q{i}{j}", (-0.95 + 0.95 * i, -0.95 + 0.95 * j, -0.95), (0.95 * i, 0.95 * j, 0.95))
        for i in range(2)
        for j in range(2)
    ]


def test_model_tracks_traced_ao_and_regularisation_trades_fit_for_continuity():
    scene = room_with_crate()
    regions = four_regions()
    s = VolumeSettings(samples=6, directions=512, beta=4.0, boundary_grid=1, half_distances=(0.3, 1.5))
    vol, extra = bake_volumes(scene, s, regions)
    energy = vol.stats["energy"]
    assert all(b <= a * (1 + 1e-12) for a, b in zip(energy, energy[1:], strict=False))
    assert len(vol.edges) == 4  # a 2 x 2 grid of boxes: 4 shared faces
    before, after = extra["jumps_before"], extra["jumps_after"]
    assert after.sum() < 0.1 * before.sum()  # the paper's b_ij: measured 0.03 -> 5e-5 at the centres
    # agreement on a 3 x 3 grid over each face lowers the jump across the whole face (8 x 8 grid)
    s3 = VolumeSettings(samples=6, directions=512, half_distances=(0.3, 1.5))
    vol3, _ = bake_volumes(scene, s3, regions)
    face = vol3.stats["face_jump_before"]["mean"], vol3.stats["face_jump_after"]["mean"]
    assert face[1] < 0.7 * face[0], face  # measured 0.029 -> 0.014
    # accuracy against traced AO at random valid probes (traced with the blend of both distances)
    probe = VolumeProbe(vol)
    unreg = VolumeProbe(
        Volumes(regions, vol.edges, extra["models_unregularised"], vol.half_distances, vol.blend, s)
    )
    pts = np.concatenate([points_in(r, 40, 10 + k, margin=0.05) for k, r in enumerate(regions)])
    lab = make_labeller(scene, s)
    _, valid = spherical_ao(lab, pts, np.arange(len(pts)), vol.half_distances, s)
    pts, n = pts[valid], unit_vectors(int(valid.sum()), 5)
    ref = np.zeros(len(pts))
    for k, half in enumerate(vol.half_distances):
        lab.settings = LabelSettings(rays=512, kernel="obscurance", max_distance_rel=4.0, half_distance=half)
        ref += (vol.blend if k else 1 - vol.blend) * lab.ao_at_points(pts, n)[0]
    rmse = {
        name: float(np.sqrt(np.mean((p.ao(pts, n) - ref) ** 2)))
        for name, p in (("reg", probe), ("raw", unreg))
    }
    assert rmse["raw"] < 0.03 and rmse["reg"] < 0.03, rmse  # measured 0.0205 and 0.0219


# --------------------------------------------------------------------------- regions


def partitioned_rooms():
    """Box [-1, 1]^3 (inward) split at x = 0 by a closed wall 0.02 thick: two closed rooms."""
    v, f = box(1.0, inward=False)
    return merge(box(1.0, inward=True), (v * [0.01, 1.0, 1.0], f), name="two-rooms")


def test_free_space_regions_cover_free_cells_and_never_cross_a_wall():
    scene = partitioned_rooms()
    s = VolumeSettings(grid=8, max_region_cells=4)
    regions = free_space_regions(scene, make_labeller(scene, s), s)
    lo = np.array([r.lo for r in regions])
    hi = np.array([r.hi for r in regions])
    assert not ((lo[:, 0] < -1e-9) & (hi[:, 0] > 1e-9)).any()  # nothing spans the partition
    # cells of 0.25: the partition occupies the layer on each side; outer walls occupy nothing
    assert math.isclose(float((hi - lo).prod(axis=1).sum()), 2 * 0.75 * 2 * 2, rel_tol=1e-9)
    # independent check: no surface point lies strictly inside any region
    mesh = trimesh.Trimesh(scene.vertices, scene.faces, process=False)
    surface, _ = trimesh.sample.sample_surface(mesh, 20000, seed=0)
    inside = ((surface[:, None] > lo[None] + 1e-9) & (surface[:, None] < hi[None] - 1e-9)).all(axis=2)
    assert not inside.any()
    # regions of the two rooms are never neighbours
    from neuralao.pipeline.bakes.volumes import connect

    for e in connect(regions, diagonal=scene.diagonal):
        assert (lo[e.i, 0] >= 0) == (lo[e.j, 0] >= 0)


def test_regions_json_and_bad_boxes_are_one_line_errors(tmp_path):
    f = tmp_path / "r.json"
    f.write_text(
        json.dumps(
            {
                "regions": [
                    {"name": "a", "min": [0, 0, 0], "max": [1, 1, 1]},
                    {"name": "b", "min": [1, 0, 0], "max": [2, 1, 1]},
                ]
            }
        )
    )
    regions, edges = read_regions(f)
    assert [r.name for r in regions] == ["a", "b"] and edges is None
    cases = {
        "no regions": {"regions": []},
        "degenerate": {"regions": [{"min": [0, 0, 0], "max": [1, 0, 1]}]},
        "degenerate": {"regions": [{"min": [0, 0, 0], "max": [1, -1, 1]}]},  # noqa: F601
        "finite": {"regions": [{"min": [0, 0, float("nan")], "max": [1, 1, 1]}]},
        "3 values": {"regions": [{"min": [0, 0], "max": [1, 1]}]},
        "do not touch": {
            "regions": [{"min": [0, 0, 0], "max": [1, 1, 1]}, {"min": [3, 0, 0], "max": [4, 1, 1]}],
            "edges": [[0, 1]],
        },
        "two different regions": {"regions": [{"min": [0, 0, 0], "max": [1, 1, 1]}], "edges": [[0, 5]]},
    }
    for message, data in cases.items():
        f.write_text(json.dumps(data).replace("NaN", "NaN"))
        with pytest.raises(NeuralaoError, match=message):
            r, e = read_regions(f)
            from neuralao.pipeline.bakes.volumes import connect

            connect(r, e)
    f.write_text("{not json")
    with pytest.raises(NeuralaoError, match="not valid JSON"):
        read_regions(f)


def test_region_inside_geometry_falls_back_to_its_neighbours_never_nan():
    crate_v, crate_f = box(0.4, inward=False)
    scene = merge(box(1.0, inward=True), (crate_v, crate_f))
    inside = Region("inside", (-0.3, -0.3, -0.3), (0.3, 0.3, 0.3))
    free = Region("free", (0.3, -0.3, -0.3), (0.9, 0.3, 0.3))  # touches "inside" at x = 0.3
    lonely = Region("lonely", (-0.3, -0.3, 0.35), (0.3, 0.3, 0.38))  # inside the crate, no neighbour
    vol, _ = bake_volumes(scene, FAST, [inside, free, lonely])
    m_in, m_free, m_lonely = vol.models
    assert m_in.fallback == "neighbours" and m_free.fallback is None and m_lonely.fallback == "open"
    assert np.allclose(m_in.coefficients[0], VolumeProbe(vol).sh_at(np.array([[0.3, 0.0, 0.0]]), [1])[0])
    assert np.allclose(m_in.coefficients[1:], 0.0)
    ao = VolumeProbe(vol).ao(points_in(inside, 50, 0), unit_vectors(50, 1))
    assert np.isfinite(ao).all()
    assert np.allclose(VolumeProbe(vol).ao(points_in(lonely, 20, 0), unit_vectors(20, 1)), 1.0)
    with pytest.raises(NeuralaoError, match="no region has a valid sample"):
        bake_volumes(scene, FAST, [inside])
    # an empty region (nothing around it to hit): valid, AO exactly 1 for every normal
    far = Region("far", (100.0, 100.0, 100.0), (101.0, 101.0, 101.0))  # beyond the longest ray
    vol, _ = bake_volumes(scene, FAST, [free, far])
    assert vol.models[1].fallback is None and vol.models[1].valid_samples == 64
    assert np.allclose(VolumeProbe(vol).ao(points_in(far, 20, 2), unit_vectors(20, 3)), 1.0, atol=1e-6)


# --------------------------------------------------------------------------- run time


def test_glsl_function_matches_the_numpy_evaluator_on_mesa():
    from neuralao.export.glsl.volume import pack_volumes, probe_shaders
    from neuralao.runtime.glsl_runner import run_vertex_feedback

    scene = room_with_crate()
    vol, _ = bake_volumes(scene, FAST, four_regions())
    probe = VolumeProbe(vol)
    for order in ("linear", "quadratic"):
        packed = pack_volumes(vol, order)
        for dialect in ("glsl330", "es300"):
            vert, frag = probe_shaders(order, vol.blend, dialect)
            for k, region in enumerate(vol.regions):
                p, n = points_in(region, 200, k), unit_vectors(200, k)
                got = run_vertex_feedback(vert, frag, [p, n], {"u_nao_volume": packed[k]})
                want = probe.ao(p, n, order=order, regions=np.full(len(p), k))
                assert np.abs(got - want).max() < TOL.glsl_op_fp32, (order, dialect, k)


def two_constant_regions(a: float, b: float) -> Volumes:
    """Regions x < 0 and x > 0 with constant models AO = a and b, both centred at the origin."""
    regions = [Region("left", (-1, -1, -1), (0, 1, 1)), Region("right", (0, -1, -1), (1, 1, 1))]
    models = []
    for value in (a, b):
        c = np.zeros((7, 2, 9))
        c[0, :, 0] = value / sh.basis(np.eye(3)[:1], 1)[0, 0]
        models.append(RegionModel(np.zeros(3), c))
    return Volumes(regions, [Edge(0, 1, 4.0, (0.0, 0.0, 0.0))], models, (1.0, 1.0), 0.97, VolumeSettings())


def test_temporal_blending_decays_exponentially_across_a_region_switch():
    vol = two_constant_regions(0.2, 0.8)
    probe = VolumeProbe(vol)
    t = np.arange(60) / 30.0
    pos = np.stack([np.linspace(-0.9, 0.9, 60), 0 * t, 0 * t], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (60, 1))
    hard = blended_path(probe, pos, n, dt=1 / 30, tau=0.0)
    soft = blended_path(probe, pos, n, dt=1 / 30, tau=0.2)
    switch = int(np.argmax(pos[:, 0] >= 0))
    assert np.allclose(hard, np.where(np.arange(60) < switch, 0.2, 0.8), atol=1e-12)
    k = np.arange(60) - switch + 1
    expected = np.where(k > 0, 0.8 - 0.6 * np.exp(-np.maximum(k, 0) / 30.0 / 0.2), 0.2)
    assert np.allclose(soft, expected, atol=1e-12)
    assert np.abs(np.diff(soft)).max() < 0.2 * np.abs(np.diff(hard)).max()
    with pytest.raises(NeuralaoError, match="tau"):
        TemporalBlend(-1.0)


def test_anchored_blend_mixes_models_with_different_centres_exactly():
    # Two sloped models centred far apart: the anchored blend is exactly w f_new + (1 - w) f_old at the
    # object's position; blending the packed numbers (centre included) is not.
    vol = two_constant_regions(0.3, 0.6)
    y00 = sh.basis(np.eye(3)[:1], 1)[0, 0]
    for m, centre, slope in ((vol.models[0], (-0.5, 0, 0), 0.2), (vol.models[1], (0.7, 0, 0), -0.3)):
        m.centre = np.array(centre, dtype=float)
        m.coefficients[1, :, 0] = m.coefficients[2, :, 0] = slope / y00  # d AO / dx on both sides
    probe = VolumeProbe(vol)
    pos = np.stack([np.linspace(-0.9, 0.9, 40), np.zeros(40), np.zeros(40)], axis=1)
    n = np.tile([0.0, 1.0, 0.0], (40, 1))
    f_old = 0.3 + 0.2 * (pos[:, 0] + 0.5)
    f_new = 0.6 - 0.3 * (pos[:, 0] - 0.7)
    switch = int(np.argmax(pos[:, 0] >= 0))
    k = np.arange(40) - switch + 1
    w = np.where(k > 0, 1 - np.exp(-np.maximum(k, 0) * 0.05 / 0.25), 0.0)
    exact = w * f_new + (1 - w) * f_old
    assert np.allclose(blended_path(probe, pos, n, dt=0.05, tau=0.25), exact, atol=1e-12)
    params = blended_path(probe, pos, n, dt=0.05, tau=0.25, mode="parameters")
    assert np.abs(params - exact).max() > 0.01


def test_volumes_and_probe_commands_end_to_end(tmp_path):
    scene = room_with_crate()
    obj = tmp_path / "level.obj"
    trimesh.Trimesh(scene.vertices, scene.faces, process=False).export(obj)
    out, glsl = tmp_path / "v.json", tmp_path / "glsl"
    args = [
        "volumes",
        str(obj),
        "--out",
        str(out),
        "--set",
        "samples=4",
        "--set",
        "directions=128",
        "--set",
        "grid=6",
        "--glsl",
        str(glsl),
    ]
    assert cli.main(args) == 0
    vol = read_volumes(out)
    assert len(vol.regions) >= 2
    from neuralao.export.glsl.volume import volume_function

    assert (glsl / "nao_volume.glsl").read_text() == volume_function("linear", vol.blend)  # what Mesa ran
    manifest = json.loads((glsl / "manifest.json").read_text())
    assert (
        (glsl / "models.bin").stat().st_size
        == len(vol.regions) * manifest["bytes_per_region"]
        == len(vol.regions) * 128
    )
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.9, 0.9, size=(100, 3))
    n = unit_vectors(100, 7)
    n[0] = 0.0  # a zero normal: evaluated as +z, finite
    np.save(tmp_path / "p.npy", p)
    np.save(tmp_path / "n.npy", n)
    ao_path = tmp_path / "ao.npy"
    assert (
        cli.main(
            [
                "probe",
                str(out),
                "--points",
                str(tmp_path / "p.npy"),
                "--normals",
                str(tmp_path / "n.npy"),
                "--out",
                str(ao_path),
            ]
        )
        == 0
    )
    ao = np.load(ao_path)
    n[0] = (0, 0, 1)
    assert ao.shape == (100,) and np.isfinite(ao).all()
    assert np.allclose(ao, VolumeProbe(vol).ao(p, n), atol=1e-7)
    # same seed, other worker count: the same models
    cli.main(
        [
            *args[:3],
            str(tmp_path / "w.json"),
            "--set",
            "samples=4",
            "--set",
            "directions=128",
            "--set",
            "grid=6",
            "--set",
            "workers=1",
        ]
    )
    again = read_volumes(tmp_path / "w.json")
    assert all(
        np.array_equal(a.coefficients, b.coefficients) for a, b in zip(vol.models, again.models, strict=True)
    )
    # given regions and edges, settings from a preset file
    (tmp_path / "regions.json").write_text(
        json.dumps(
            {
                "regions": [{"name": r.name, "min": list(r.lo), "max": list(r.hi)} for r in four_regions()],
                "edges": [[0, 1], [0, 2]],
            }
        )
    )
    (tmp_path / "preset.json").write_text(json.dumps({"samples": 4, "directions": 64}))
    given = tmp_path / "given.json"
    assert (
        cli.main(
            [
                "volumes",
                str(obj),
                "--out",
                str(given),
                "--regions",
                str(tmp_path / "regions.json"),
                "--config",
                str(tmp_path / "preset.json"),
            ]
        )
        == 0
    )
    g = read_volumes(given)
    assert [r.name for r in g.regions] == [r.name for r in four_regions()]
    assert [(e.i, e.j) for e in g.edges] == [(0, 1), (0, 2)] and g.settings.directions == 64
    # bad input: one line, exit 2, nothing written
    assert cli.main(["volumes", str(obj), "--out", str(tmp_path / "x.json"), "--set", "beta=-1"]) == 2
    assert cli.main(["volumes", str(obj), "--out", str(tmp_path / "x.json"), "--set", "bogus=1"]) == 2
    assert not (tmp_path / "x.json").exists()
    np.save(tmp_path / "bad.npy", np.zeros((5, 2)))
    bad = tmp_path / "bad_ao.npy"
    probe_args = ["probe", str(out), "--normals", str(tmp_path / "n.npy"), "--out", str(bad), "--points"]
    assert cli.main([*probe_args, str(tmp_path / "bad.npy")]) == 2
    p[3] = np.nan
    np.save(tmp_path / "nan.npy", p)
    assert cli.main([*probe_args, str(tmp_path / "nan.npy")]) == 2
    (tmp_path / "junk.json").write_text("{}")
    assert (
        cli.main(
            [
                "probe",
                str(tmp_path / "junk.json"),
                "--points",
                str(tmp_path / "p.npy"),
                "--normals",
                str(tmp_path / "n.npy"),
                "--out",
                str(bad),
            ]
        )
        == 2
    )
    assert not bad.exists()


def test_volumes_of_a_generated_glTF_level_use_its_opaque_instances(tmp_path):
    from neuralao.pipeline.bakes.level_stages import opaque_scene
    from neuralao.pipeline.geometry.level_files import read_level
    from neuralao.pipeline.geometry.level_gen import settings_for, write_level

    path, _ = write_level(tmp_path / "lvl", settings_for("tiny"))
    out = tmp_path / "v.json"
    args = [
        "volumes",
        str(path),
        "--out",
        str(out),
        "--set",
        "samples=4",
        "--set",
        "directions=64",
        "--set",
        "grid=6",
    ]
    assert cli.main(args) == 0
    vol = read_volumes(out)
    opaque = opaque_scene(read_level(path))
    assert vol.scene["faces"] == len(opaque.faces)  # static + blocker instances, instancing expanded
    assert np.allclose(vol.scene["bounds"], opaque.bounds)
    assert all(np.isfinite(m.coefficients).all() for m in vol.models) and len(vol.regions) > 1
