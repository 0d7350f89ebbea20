"""Vertex AO baking: least-squares (Kavan et al. 2011) against per-vertex sampling, files, CLI.

Errors are measured the way the renderer shows baked AO: vertex values interpolated across faces,
compared with an independent high-ray Embree reference at held-out surface samples.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh
from helpers import box, merge

from neuralao.pipeline import cli
from neuralao.pipeline.bakes.vertex import (
    BakeSettings,
    bake,
    read_baked_mesh,
    reference_at_samples,
    write_baked_mesh,
)
from neuralao.pipeline.geometry.least_squares import fit_least_squares
from neuralao.pipeline.geometry.scene import scene_from_arrays
from neuralao.pipeline.geometry.surface import (
    interpolate,
    interpolation_matrix,
    surface_error,
    surface_samples,
)
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL


def grid_plane(half: float = 1.0, n: int = 2):
    """Square [-half, half]^2 at z = 0, normal +z, as an n x n grid of quads (vertices, faces)."""
    t = np.linspace(-half, half, n + 1)
    xx, yy = np.meshgrid(t, t, indexing="ij")
    v = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


@pytest.fixture(scope="module")
def contact_scene():
    """A coarse floor (2x2 quads) with a closed box standing in it (sunk 0.05: floor samples inside
    the box see its back faces and are invalid; the floor around it has contact shadows)."""
    bv, bf = box(0.3, inward=False)
    return merge(grid_plane(1.0, 2), (bv + np.array([0.1, 0.05, 0.25]), bf), name="contact")


@pytest.fixture(scope="module")
def sphere():
    m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    return scene_from_arrays(m.vertices, m.faces, "sphere")


def test_least_squares_beats_vertex_sampling_on_a_contact(contact_scene):
    scene = contact_scene
    settings = BakeSettings(rays=256, samples_per_vertex=64)
    held = surface_samples(scene, 4000, cap=1000, seed=99)  # held out: other positions, other rays
    ref, ref_valid = reference_at_samples(scene, held, settings, rays=1024)
    vertex = bake(scene, replace(settings, method="vertex"))
    lsq = bake(scene, settings)
    e_vertex = surface_error(scene, vertex.ao, held, ref, ref_valid)
    e_lsq = surface_error(scene, lsq.ao, held, ref, ref_valid)
    assert lsq.info["invalid_samples"] > 0  # the floor inside the box
    assert e_vertex["rmse"] > 0.05  # the case is hard for vertex sampling ...
    assert e_lsq["rmse"] < TOL.bake_lsq_vs_vertex_ratio * e_vertex["rmse"], (e_lsq, e_vertex)
    for r in (vertex, lsq):
        assert r.ao.dtype == np.float32 and r.ao.shape == (len(scene.vertices),)
        assert (r.ao >= 0).all() and (r.ao <= 1).all()


def test_constant_ao_gives_one_for_both_methods(sphere):
    """An isolated convex mesh with a long max distance: every ray escapes, AO = 1 everywhere."""
    for method in ("vertex", "least-squares"):
        for kernel in ("binary", "obscurance"):
            r = bake(sphere, BakeSettings(rays=32, max_distance=10.0, kernel=kernel, method=method))
            assert r.info["invalid_samples"] == 0
            assert np.abs(r.ao - 1.0).max() <= 1e-6, (method, kernel)


def test_invalid_samples_are_left_out(contact_scene):
    scene = contact_scene
    samples = surface_samples(scene, 600, cap=32, seed=3)
    rng = np.random.default_rng(0)
    values = rng.uniform(0.3, 1.0, len(samples))
    valid = rng.uniform(size=len(samples)) > 0.2
    a = fit_least_squares(scene, samples, values, valid)
    garbage = values.copy()
    garbage[~valid] = rng.choice([0.0, 1.0, np.nan], size=(~valid).sum())
    b = fit_least_squares(scene, samples, garbage, valid)
    assert np.array_equal(a, b)
    # ... and they matter when included (the test can fail).
    c = fit_least_squares(scene, samples, np.where(valid, values, 0.0), np.ones(len(samples), bool))
    assert np.abs(c - a).max() > 0.01


def test_least_squares_reproduces_linear_fields(contact_scene):
    """Noise-free samples of a field linear on every face: the fit recovers the vertex values
    (alpha = 0: exact; alpha = 1: within the small regulariser bias)."""
    scene = contact_scene
    samples = surface_samples(scene, 2000, cap=64, seed=1)
    truth = 0.5 + 0.2 * scene.vertices[:, 0] - 0.1 * scene.vertices[:, 2]
    values = interpolate(scene, truth, samples.face, samples.bary)
    assert np.allclose(interpolation_matrix(scene, samples) @ truth, values)
    exact = fit_least_squares(scene, samples, values, np.ones(len(samples), bool), alpha=0.0)
    assert np.abs(exact - truth).max() < 1e-5
    soft = fit_least_squares(scene, samples, values, np.ones(len(samples), bool), alpha=1.0)
    assert np.abs(soft - truth).max() < 0.05


def test_surface_samples_are_stratified_and_area_weighted(contact_scene):
    scene = contact_scene
    s = surface_samples(scene, 500, cap=7, seed=2)
    counts = np.bincount(s.face, minlength=len(scene.faces))
    assert counts.min() >= 1 and counts.max() <= 7
    assert np.allclose(s.bary.sum(1), 1.0) and (s.bary >= -1e-12).all()
    assert np.isclose(s.weights.sum(), 1.0)
    assert np.allclose(s.points, np.einsum("kc,kcd->kd", s.bary, scene.triangles[s.face]))
    again = surface_samples(scene, 500, cap=7, seed=2)
    assert np.array_equal(s.points, again.points)  # seeded


def test_bake_is_scale_invariant(contact_scene):
    settings = BakeSettings(rays=64, samples_per_vertex=16)
    a = bake(contact_scene, settings).ao
    b = bake(contact_scene.scaled(1000.0, 1e5), settings).ao
    assert np.abs(a - b).max() < 1e-3


@pytest.mark.parametrize("suffix", [".ply", ".glb"])
def test_file_round_trip_keeps_ao(tmp_path, contact_scene, suffix):
    ao = np.random.default_rng(4).uniform(0, 1, len(contact_scene.vertices)).astype(np.float32)
    path = write_baked_mesh(tmp_path / f"baked{suffix}", contact_scene, ao)
    verts, faces, got, colours = read_baked_mesh(path)
    assert got.dtype == np.float32 and np.array_equal(got, ao)
    assert np.array_equal(faces, contact_scene.faces)
    assert np.allclose(verts, contact_scene.vertices, atol=1e-6)
    assert np.array_equal(colours[:, 0], np.rint(ao * 255).astype(np.uint8))
    assert (colours[:, 3] == 255).all()
    assert [p.name for p in tmp_path.iterdir()] == [f"baked{suffix}"]  # no temporary left behind


def test_cli_bakes_a_mesh_file(tmp_path, capsys):
    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    mesh = tmp_path / "cube.obj"
    m.export(mesh)
    out = tmp_path / "cube_ao.ply"
    args = [
        "bake",
        str(mesh),
        "--rays",
        "16",
        "--method",
        "least-squares",
        "--samples-per-vertex",
        "4",
        "--out",
        str(out),
    ]
    assert cli.main(args) == 0
    _, _, ao, _ = read_baked_mesh(out)
    assert ao.shape == (8,) and np.isfinite(ao).all() and (ao > 0.99).all()  # an isolated convex cube


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.obj", "--rays", "8", "--out", "x.ply"], "not found"),
        (["CUBE", "--rays", "0", "--out", "x.ply"], "--rays"),
        (["CUBE", "--rays", "8", "--out", "x.obj"], ".ply or .glb"),
        (["CUBE", "--rays", "8", "--alpha", "-1", "--out", "x.ply"], "--alpha"),
        (["CUBE", "--rays", "8", "--samples-per-face-cap", "0", "--out", "x.ply"], "cap"),
        (["CUBE", "--rays", "8", "--half-distance", "0.1", "--out", "x.ply"], "obscurance"),
    ],
)
def test_cli_bad_input_is_a_one_line_error(tmp_path, capsys, args, message):
    mesh = tmp_path / "cube.obj"
    trimesh.creation.box().export(mesh)
    args = [str(mesh) if a == "CUBE" else a for a in args]
    args = [str(tmp_path / a) if a.startswith("x.") else a for a in args]
    assert cli.main(["bake", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not list(tmp_path.glob("x.*"))


def test_settings_are_checked():
    with pytest.raises(NeuralaoError):
        fit_least_squares(None, None, np.zeros(1), np.ones(1, bool), alpha=float("nan"))
