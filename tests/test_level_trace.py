"""Level tracing: two distances from one trace, foliage closed forms, sphere resampling, the
per-instance linear global fit (equation 3 of Sloan et al. 2013)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import floor_quad, mc_bound, merge
from scipy.special import expn

from neuralao.pipeline.bakes.level_decorators import FoliageSettings, build_foliage, fit_global, linear_basis
from neuralao.pipeline.bakes.level_pieces import (
    cached_block,
    face_counts,
    face_samples,
    index_level,
    piece_samples,
    piece_scene,
    sample_rule,
    scene_samples,
)
from neuralao.pipeline.bakes.level_settings import TraceSettings
from neuralao.pipeline.bakes.level_stages import component_blocks, fit_level, opaque_scene
from neuralao.pipeline.geometry.least_squares import fit_least_squares
from neuralao.pipeline.geometry.level_files import flatten, read_level
from neuralao.pipeline.geometry.level_gen import settings_for, write_level
from neuralao.pipeline.geometry.scene import scene_from_arrays
from neuralao.pipeline.geometry.surface import face_areas, surface_samples
from neuralao.pipeline.tracing.foliage import Foliage, overlap_reduced
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.pipeline.tracing.level_tracer import LevelLabeller, resample_in_spheres, sphere_directions
from neuralao.runtime.foundation.errors import NeuralaoError


@pytest.fixture(scope="module")
def tiny_geometry(tmp_path_factory):
    """The tiny level whole: its receivers (static instances), its opaque scene and the level."""
    out = tmp_path_factory.mktemp("lv")
    write_level(out, settings_for("tiny", seed=1), "tiny")
    level = read_level(out / "level.gltf")
    rv, rf, _ = flatten(level, level.nodes_with("static"))
    return SimpleNamespace(
        level=level, receivers=scene_from_arrays(rv, rf, drop_degenerate=False), opaque=opaque_scene(level)
    )


def receiver_samples(scene, t: TraceSettings, seed: int):
    return scene_samples(scene, t.samples_per_vertex, t.min_samples_per_face, t.samples_per_face_cap, seed)


@pytest.mark.parametrize("piece_faces", [100, 600, 10**9])
def test_pieces_make_the_samples_of_the_whole_level(tiny_geometry, piece_faces):
    """Samples made piece by piece (global face numbers, the shared rounding stream skipped ahead, the
    level's area as the weights' normaliser) are the samples of the flattened level, bit for bit."""
    g = tiny_geometry
    index = index_level(g.level, piece_faces)
    assert len(index.pieces) == {100: 3, 600: 2, 10**9: 1}[piece_faces]
    np.testing.assert_array_equal(index.bounds, g.opaque.bounds)
    rule, pieces = sample_rule(g.level, index, 2.0, 1, 4, seed=7)
    whole = scene_samples(g.receivers, 2.0, 1, 4, seed=7)
    parts = [piece_samples(piece_scene(g.level, index, p), p, rule) for p in pieces]
    assert [len(s) for s in parts] == [p.ns for p in pieces] and sum(p.ns for p in pieces) == len(whole)
    np.testing.assert_array_equal(np.concatenate([s.points for s in parts]), whole.points)
    np.testing.assert_array_equal(
        np.concatenate([s.face + p.f0 for s, p in zip(parts, pieces, strict=True)]), whole.face
    )
    np.testing.assert_allclose(np.concatenate([s.weights for s in parts]), whole.weights, rtol=1e-12)


def test_a_block_s_samples_are_the_piece_s_made_from_its_faces_alone(tiny_geometry):
    """A trace block's samples (a task makes them from the faces under them, not the piece's all) are the
    piece's samples lo..hi, bit for bit, wherever the block starts and ends (inside a face's run too); a
    piece whose sample ranges are not known counts the samples of all its faces."""
    g = tiny_geometry
    index = index_level(g.level, 10**9)
    rule, pieces = sample_rule(g.level, index, 2.0, 0, 4, seed=7)
    piece = pieces[0]
    scene = piece_scene(g.level, index, piece)
    whole = piece_samples(scene, piece, rule)
    ends = np.cumsum(face_counts(face_areas(scene), piece.f0, rule))
    assert (np.diff(ends, prepend=0) == 0).any() and (np.diff(ends, prepend=0) > 1).any()  # empty, multi
    unranged = replace(piece, ranges=())
    _assert_blocks_are_slices(
        whole, lambda lo, hi: cached_block("unranged", g.level, index, unranged, rule, lo, hi)[1], seed=0
    )


def _assert_blocks_are_slices(whole, block, seed: int) -> None:
    """``block(lo, hi)`` is ``whole[lo:hi]`` bit for bit: the whole, one sample at each end, an empty block
    and 20 random ones."""
    ns = len(whole)
    rng = np.random.default_rng(seed)
    for lo, hi in [(0, ns), (0, 1), (ns - 1, ns), (5, 5), *rng.integers(0, ns, (20, 2))]:
        lo, hi = int(min(lo, hi)), int(max(lo, hi))
        got = block(lo, hi)
        for k in ("face", "bary", "points", "normals", "weights"):
            np.testing.assert_array_equal(getattr(got, k), getattr(whole, k)[lo:hi], err_msg=f"{k} {lo}:{hi}")


@pytest.mark.parametrize("run", [3, 10, 10**6])
def test_a_block_counts_only_its_sample_ranges_and_makes_the_piece_s_samples(tiny_geometry, monkeypatch, run):
    """With the piece's sample ranges (the samples' second pass notes the first sample of every ``run``
    faces), a block task counts the samples of its ranges' faces alone; its samples are still the piece's
    lo..hi, bit for bit, across ranges, inside a face's run and over ranges of faces without samples."""
    import neuralao.pipeline.bakes.level_pieces as level_pieces

    monkeypatch.setattr(level_pieces, "SAMPLE_RANGE_FACES", run)
    g = tiny_geometry
    index = index_level(g.level, 10**9)
    rule, pieces = sample_rule(g.level, index, 2.0, 0, 4, seed=7)
    piece = pieces[0]
    assert len(piece.ranges) == -(-piece.nf // run) and piece.ranges[0] == (0, 0)
    whole = piece_samples(piece_scene(g.level, index, piece), piece, rule)
    _assert_blocks_are_slices(
        whole,
        lambda lo, hi: level_pieces.cached_block(f"r{run}", g.level, index, piece, rule, lo, hi)[1],
        seed=1,
    )
    # ranges that disagree with the faces (a stale piece table) are an error, not other samples
    bad = replace(piece, ranges=tuple((f, s + 1) for f, s in piece.ranges[:1]) + piece.ranges[1:])
    if len(piece.ranges) > 1:
        with pytest.raises(NeuralaoError, match="sample ranges"):
            level_pieces.cached_block(f"bad{run}", g.level, index, bad, rule, 0, 1)


@pytest.mark.parametrize("run", [3, 10, 10**6, None])
def test_the_samples_of_any_faces_are_the_piece_s_on_them(tiny_geometry, monkeypatch, run):
    """A subdomain's worker makes the samples of the faces that touch its vertices (scattered over the piece)
    from its sample ranges' counts: they are the piece's samples on those faces, bit for bit, and their
    numbers are the piece's (``run`` None: the ranges not known, every face counted)."""
    import neuralao.pipeline.bakes.level_pieces as level_pieces

    if run is not None:
        monkeypatch.setattr(level_pieces, "SAMPLE_RANGE_FACES", run)
    g = tiny_geometry
    index = index_level(g.level, 10**9)
    rule, pieces = sample_rule(g.level, index, 2.0, 0, 4, seed=7)
    piece = pieces[0] if run is not None else replace(pieces[0], ranges=())
    scene = piece_scene(g.level, index, piece)
    whole = piece_samples(scene, piece, rule)
    rng = np.random.default_rng(2)
    nf = len(scene.faces)
    picks = [np.arange(nf), np.arange(0), np.array([nf - 1]), np.arange(nf // 3, nf // 2)]
    picks += [np.flatnonzero(rng.uniform(size=nf) < share) for share in (0.02, 0.3, 0.9)]
    for faces in picks:
        got, numbers = face_samples(scene, piece, rule, faces)
        on = np.flatnonzero(np.isin(whole.face, faces))
        np.testing.assert_array_equal(numbers, on)
        for k in ("face", "bary", "points", "normals", "weights"):
            np.testing.assert_array_equal(
                getattr(got, k), getattr(whole, k)[on], err_msg=f"{k}, {len(faces)}"
            )
    if len(piece.ranges) > 1:  # ranges that disagree with the faces they count: an error, not other samples
        bad = replace(piece, ranges=((0, 1), *piece.ranges[1:]))
        with pytest.raises(NeuralaoError, match="sample ranges"):
            face_samples(scene, bad, rule, np.arange(nf))


def test_two_distances_from_one_trace_equal_two_separate_traces(tiny_geometry):
    g = tiny_geometry
    samples = receiver_samples(g.receivers, TraceSettings(samples_per_vertex=1.0), seed=0)
    st = LabelSettings(rays=32, kernel="obscurance", max_distance=g.opaque.diagonal, seed=5, workers=2)
    for bvh in ("fast", "robust"):  # the level's BVH and the labels' one
        lab = LevelLabeller(g.opaque, st, bvh=bvh)
        ao, valid = lab.obscurance(samples.points, samples.normals, [2.0, 300.0])
        for j, h in enumerate((2.0, 300.0)):
            one = Labeller(g.opaque, replace(st, half_distance=h), bvh=bvh)
            a, v = one.ao_at_points(samples.points, samples.normals)
            np.testing.assert_array_equal(valid, v)
            # valid samples: bit for bit (rejected ones stop tracing early, their AO is not used)
            np.testing.assert_array_equal(ao[valid, j], a[valid])
        assert (ao[:, 0] >= ao[:, 1]).all()  # a longer half distance only darkens
        assert (~valid).any()  # the tiny level's soup (houses, sunk buildings) has invalid samples


def test_fast_bvh_finds_the_robust_bvhs_hits(tiny_geometry):
    """The level's BVH (Embree's high-quality build, no robust flag) against the watertight default on the
    same rays over the tiny level's soup: the same rays hit (at most one in 10^5 may differ, grazing an
    edge), at the same distances within float32 rounding of the local frame but for rare near-coincident
    faces (within the ray offset); ties between coincident faces may name either face."""
    g = tiny_geometry
    samples = receiver_samples(g.receivers, TraceSettings(samples_per_vertex=2.0), seed=1)
    st = LabelSettings(rays=64, kernel="obscurance", max_distance=g.opaque.diagonal, seed=3)
    fast, robust = Labeller(g.opaque, st, bvh="fast"), Labeller(g.opaque, st, bvh="robust")
    o, d = robust.rays(samples.points, samples.normals)
    tmax = np.full(len(o), robust.r_local, np.float32)
    a = fast.embree.run(o, d, query="INTERSECT", dists=tmax.copy(), output=1)
    b = robust.embree.run(o, d, query="INTERSECT", dists=tmax.copy(), output=1)
    hit_a, hit_b = a["primID"] >= 0, b["primID"] >= 0
    assert len(o) > 100_000 and hit_b.mean() > 0.3
    assert np.count_nonzero(hit_a != hit_b) <= len(o) * 1e-5
    both = hit_a & hit_b
    dt = np.abs(a["tfar"][both] - b["tfar"][both])
    # float32 rounding (local units: the level's diagonal is 1) but for rare near-coincident faces of the
    # soup, whose gap is within the ray offset (1e-5)
    assert np.count_nonzero(dt > 4 * np.finfo(np.float32).eps) <= len(o) * 1e-4
    assert dt.max() < 1e-5
    with pytest.raises(NeuralaoError, match="bvh"):
        Labeller(g.opaque, st, bvh="quick")


@pytest.mark.parametrize("rays, threshold", [(32, 0.25), (64, 0.1), (48, 0.5)])
def test_back_face_early_out_changes_no_valid_sample(tiny_geometry, rays, threshold):
    """The early out of the back-face rule (rounds of rays, rejected samples stop) gives the same valid
    flags and bit-identical AO of every valid sample as tracing every ray, with foliage on."""
    g = tiny_geometry
    samples = receiver_samples(g.receivers, TraceSettings(samples_per_vertex=1.0), seed=3)
    st = LabelSettings(
        rays=rays,
        kernel="obscurance",
        max_distance=g.opaque.diagonal,
        seed=2,
        backface_threshold=threshold,
        workers=2,
    )
    fast, full = LevelLabeller(g.opaque, st), LevelLabeller(g.opaque, st)
    full.early_out = False
    assert len(fast._checkpoints(rays)) > 1 and full._checkpoints(rays) == [rays]
    fol = build_foliage(g.level, fast, FoliageSettings())
    a, v = fast.obscurance(samples.points, samples.normals, [2.0, 300.0], fol)
    b, w = full.obscurance(samples.points, samples.normals, [2.0, 300.0], fol)
    np.testing.assert_array_equal(v, w)
    assert (~v).any() and v.any()
    np.testing.assert_array_equal(a[v], b[v])
    assert np.isfinite(a).all() and (a >= 0).all() and (a <= 1).all()


def test_foliage_attenuates_only_where_there_is_foliage(tiny_geometry):
    g = tiny_geometry
    samples = receiver_samples(g.receivers, TraceSettings(samples_per_vertex=1.0), seed=0)
    lab = LevelLabeller(g.opaque, LabelSettings(rays=32, kernel="obscurance", max_distance=g.opaque.diagonal))
    plain, _ = lab.obscurance(samples.points, samples.normals, [2.0, 300.0])
    fol, _ = lab.obscurance(
        samples.points, samples.normals, [2.0, 300.0], build_foliage(g.level, lab, FoliageSettings())
    )
    assert (fol <= plain + 1e-7).all()
    darker = (plain - fol).max(axis=1) > 1e-3
    assert 0 < darker.sum() < len(samples)


def _slab_scene(half=200.0):
    return merge(floor_quad(half, 0.0), name="floor")


@pytest.mark.parametrize("sigma_h", [0.3, 1.0, 2.5])
def test_point_inside_a_wide_slab_of_media_closed_form(sigma_h):
    """Obscurance with no opaque occluder at the bottom of a slab of thickness H, density sigma:
    AO = (1/pi) int exp(-sigma H / cos) cos dw = 2 E_3(sigma H)."""
    scene = _slab_scene()
    lab = LevelLabeller(scene, LabelSettings(rays=256, kernel="obscurance", max_distance=2 * scene.diagonal))
    h, half = 1.0, 200.0
    fol = Foliage(
        [[-half, -half, -0.01]],
        [[half, half, h]],
        [sigma_h / h],
        np.zeros((0, 3)),
        np.zeros((0, 3), int),
        np.zeros(0),
        lab.center,
        lab.scale,
        max_hits=8,
    )
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-5, 5, (16, 2)), np.zeros(16)]
    ao, _ = lab.obscurance(pts, np.tile([0.0, 0.0, 1.0], (16, 1)), [1.0], fol)
    expected = 2 * expn(3, sigma_h)
    assert np.abs(ao[:, 0] - expected).max() < mc_bound(expected, 256)
    assert abs(ao[:, 0].mean() - expected) < mc_bound(expected, 256 * 16)
    # Above the slab, facing up: no ray crosses it, visibility is exactly 1.
    above, _ = lab.obscurance(pts + [0, 0, 2 * h], np.tile([0.0, 0.0, 1.0], (16, 1)), [1.0], fol)
    assert (above == 1.0).all()


def _box_foliage(lo, hi, density, max_hits=8):
    return Foliage(
        np.atleast_2d(lo),
        np.atleast_2d(hi),
        np.atleast_1d(density),
        np.zeros((0, 3)),
        np.zeros((0, 3), int),
        np.zeros(0),
        np.zeros(3),
        1.0,
        max_hits,
    )


@pytest.mark.parametrize(
    "origin, end, length",
    [
        ((-5, 0.1, 0.2), 10.0, 2.0),
        ((-5, 0.1, 0.2), 5.0, 1.0),
        ((-5, 0.1, 0.2), 3.0, 0.0),
        ((0, 0.1, 0.2), 10.0, 1.0),
        ((0, 0.1, 0.2), 0.5, 0.5),
    ],
)
def test_one_box_of_known_density_and_length(origin, end, length):
    """exp(-density x length inside the box) for a ray in +x through [-1, 1]^3 (scaled down into local
    units), starting outside or inside, ending before, inside or after the box."""
    k = 0.05  # keep the box inside the local frame's unit scale
    fol = _box_foliage([-k, -k, -k], [k, k, k], 1.7 / k)
    o = np.array([origin], np.float32) * k
    start = fol.origin_density(o)
    t = fol.transmittance(o, np.array([[1, 0, 0]], np.float32), np.array([end * k]), start)
    np.testing.assert_allclose(t, np.exp(-1.7 * length), rtol=1e-4, atol=1e-6)


def test_overlapping_boxes_have_reduced_densities_and_add_up_along_a_ray():
    """Two overlapping boxes: each density becomes sigma / (1 + shared fraction); a ray in +x from outside
    crosses 2k of each, one from inside both crosses k of one and 1.5k of the other."""
    k = 0.05
    lo = np.array([[-k, -k, -k], [-0.5 * k, -0.9 * k, -1.1 * k]])  # no shared planes
    hi = lo + 2 * k
    dens = overlap_reduced(lo, hi, np.array([3.0, 3.0]) / k)
    share = 1.5 * 1.9 * 1.9 / 8  # intersection 1.5k x 1.9k x 1.9k of two 8k^3 boxes
    np.testing.assert_allclose(dens, 3.0 / k / (1 + share))
    fol = Foliage(lo, hi, dens, np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros(0), np.zeros(3), 1.0)
    o = np.array([[-0.2, 0.001, 0.002], [0.0, 0.001, 0.002]], np.float32)  # outside; inside both
    d = np.array([[1, 0, 0], [1, 0, 0]], np.float32)
    t = fol.transmittance(o, d, np.array([1.0, 1.0]), fol.origin_density(o))
    np.testing.assert_allclose(t, np.exp(-np.array([4.0, 1.0 + 1.5]) * 3.0 / (1 + share)), rtol=1e-5)
    # Disjoint boxes keep their density.
    np.testing.assert_array_equal(
        overlap_reduced(lo + [[0, 0, 0], [5, 0, 0]], hi + [[0, 0, 0], [5, 0, 0]], np.array([3.0, 3.0])),
        [3.0, 3.0],
    )


@pytest.mark.parametrize("layers, expected", [(1, 0.5), (2, 0.25), (3, 0.125)])
def test_trees_attenuate_by_their_transmission_per_hit(layers, expected):
    """Tree triangles (here wide horizontal sheets over the point) multiply visibility by 0.5 per hit."""
    scene = _slab_scene()
    lab = LevelLabeller(scene, LabelSettings(rays=64, kernel="obscurance", max_distance=2 * scene.diagonal))
    sheets = [floor_quad(150.0, 1.0 + i, up=bool(i % 2)) for i in range(layers)]
    tv = np.concatenate([v for v, _ in sheets])
    tf = np.concatenate([f + 4 * i for i, (_, f) in enumerate(sheets)])
    fol = Foliage(
        np.zeros((0, 3)),
        np.zeros((0, 3)),
        np.zeros(0),
        tv,
        tf,
        np.full(len(tf), 0.5),
        lab.center,
        lab.scale,
    )
    ao, _ = lab.obscurance(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]), [3.0], fol)
    # Rays escaping below the sheets' rim (at most atan(1 / 150) from the horizon) see fewer layers.
    assert abs(ao[0, 0] - expected) < 2e-3


def test_sphere_resampling_recovers_a_planted_linear_function():
    """Per-vertex values a + b x + c y on the plane z = 0; a sphere centred at height h: the hits of the
    sign-symmetric direction set lie symmetrically about the foot point, so the weighted mean is exactly
    the value there; and every hit equals the analytic ray-plane intersection."""
    n = 20
    t = np.linspace(-3, 3, n + 1)
    xx, yy = np.meshgrid(t, t, indexing="ij")
    v = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    plane = scene_from_arrays(v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]), "plane")
    f = 0.3 + 0.05 * v[:, 0] - 0.02 * v[:, 1]
    lab = LevelLabeller(plane, LabelSettings(rays=8))
    centres = np.array([[0.31, -0.47, 0.2], [1.1, 0.9, -0.35], [-2.0, 1.3, 0.0]])
    r = 0.75
    got, weight = resample_in_spheres(lab, f, centres, r, rays=64)
    np.testing.assert_allclose(got, 0.3 + 0.05 * centres[:, 0] - 0.02 * centres[:, 1], atol=1e-9)
    # Independent reference: the analytic hits c + s u (s = -h / u_z) of the rays from c + r u toward c,
    # weighted by r - |s|.
    u = sphere_directions(64)
    for ci, w_sum in zip(centres, weight, strict=True):
        ok = np.abs(u[:, 2]) > 1e-12
        s = -ci[2] / u[ok, 2]  # hit = c + s u
        inside = np.abs(s) <= r
        w = r - np.abs(s[inside])
        np.testing.assert_allclose(w_sum, w.sum(), rtol=1e-6)


def test_linear_global_fit_recovers_a_planted_function_exactly():
    rng = np.random.default_rng(4)
    pts = rng.uniform(-3, 3, (500, 3)) + [10.0, 2.0, -7.0]
    origin = np.array([10.0, 2.0, -7.0])
    local = rng.uniform(0.2, 1.0, 500)
    y = np.array([0.7, 0.03, -0.05, 0.01])
    f = local * (linear_basis(pts, origin) @ y)
    np.testing.assert_allclose(fit_global(pts, origin, local, f, rng.uniform(0.5, 1.5, 500)), y, atol=1e-12)
    # And with L = 1 (global only) it is an ordinary linear fit.
    np.testing.assert_allclose(
        fit_global(pts, origin, np.ones(500), linear_basis(pts, origin) @ y, np.ones(500)), y, atol=1e-12
    )


def test_least_squares_columns_cg_and_amg_match_separate_direct_fits(tiny_geometry):
    g = tiny_geometry
    samples = surface_samples(g.receivers, 4 * len(g.receivers.vertices), 8, 0)
    rng = np.random.default_rng(0)
    vals = rng.uniform(0, 1, (len(samples), 2))
    valid = rng.uniform(size=len(samples)) > 0.1
    both = fit_least_squares(g.receivers, samples, vals, valid)
    for j in range(2):
        np.testing.assert_array_equal(both[:, j], fit_least_squares(g.receivers, samples, vals[:, j], valid))
    for solver in ("cg", "amg"):
        np.testing.assert_allclose(
            fit_least_squares(g.receivers, samples, vals, valid, solver=solver),
            both,
            atol=1e-5,
            err_msg=solver,
        )


def test_edge_weights_match_unique_rows(tiny_geometry):
    """The 1-D keyed edge list (the fast path) is the lexicographic unique-rows one, weights bit for bit."""
    from neuralao.pipeline.geometry.surface import edge_weights, face_areas

    sc = tiny_geometry.receivers
    e = np.concatenate([sc.faces[:, [0, 1]], sc.faces[:, [1, 2]], sc.faces[:, [2, 0]]])
    w = np.tile(face_areas(sc) / 3.0, 3)
    e.sort(axis=1)
    keep = e[:, 0] != e[:, 1]
    rows, inverse = np.unique(e[keep], axis=0, return_inverse=True)
    ref = np.bincount(inverse.reshape(-1), weights=w[keep], minlength=len(rows))
    edges, weights = edge_weights(sc)
    np.testing.assert_array_equal(edges, rows)
    np.testing.assert_array_equal(weights, ref / ref.sum())


def test_component_solve_is_the_global_solve(tiny_geometry):
    """The normal equations are block diagonal over connected components: solving the blocks (SuperLU, or
    multigrid CG for blocks of at least component_vertices) gives the global SuperLU solution."""
    from scipy.sparse.csgraph import connected_components

    from neuralao.pipeline.geometry.least_squares import normal_equations

    g = tiny_geometry
    samples = surface_samples(g.receivers, 4 * len(g.receivers.vertices), 8, 0)
    rng = np.random.default_rng(1)
    vals = rng.uniform(0, 1, (len(samples), 2))
    valid = rng.uniform(size=len(samples)) > 0.3
    direct = fit_least_squares(g.receivers, samples, vals, valid)
    a, _ = normal_equations(g.receivers, samples, vals, valid)
    count = connected_components(a, directed=False)[0]
    blocks = component_blocks(a, 200)
    assert count > 3 and [m for _, m in blocks].count("amg") >= 1  # the terrain (625 vertices)
    assert np.array_equal(
        np.sort(np.concatenate([i for i, _ in blocks])), np.arange(len(g.receivers.vertices))
    )
    np.testing.assert_array_equal(fit_level(g.receivers, samples, vals, valid, TraceSettings()), direct)
    split = fit_level(g.receivers, samples, vals, valid, TraceSettings(component_vertices=200))
    np.testing.assert_allclose(split, direct, atol=1e-6)


def test_fast_resampling_matches_the_geometric_reference(tiny_geometry):
    """The trace-speed weighting (Embree's barycentrics, weight r - |r - t|, row sums) against projected
    world hit points and bincount, on the tiny level with blockers (NaN values) in reach."""
    from neuralao.pipeline.tracing.level_tracer import _resample_block, _resample_block_geometric

    g = tiny_geometry
    lab = LevelLabeller(g.opaque, LabelSettings(rays=8))
    rng = np.random.default_rng(3)
    vals = np.r_[
        rng.uniform(0, 1, (len(g.receivers.vertices), 2)),
        np.full((len(g.opaque.vertices) - len(g.receivers.vertices), 2), np.nan),
    ]
    centres = g.receivers.vertices[rng.choice(len(g.receivers.vertices), 300, replace=False)]
    rad, u = np.full(300, 0.9), sphere_directions(32)
    got, w = _resample_block(lab, vals, centres, rad, u)
    ref, w_ref = _resample_block_geometric(lab, vals, centres, rad, u)
    np.testing.assert_array_equal(np.isfinite(got), np.isfinite(ref))
    assert np.isfinite(got).mean() > 0.9
    np.testing.assert_allclose(w, w_ref, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(got[np.isfinite(got)], ref[np.isfinite(ref)], atol=1e-4)  # float32 hits


def test_origin_density_matches_brute_force_with_crowded_boxes():
    """The KD-tree candidates (vectorised nearest 8, exact fallback beyond) against testing every box."""
    rng = np.random.default_rng(9)
    lo = rng.uniform(-0.1, 0.05, (60, 3))
    hi = lo + rng.uniform(0.02, 0.12, (60, 3))
    dens = rng.uniform(0.5, 2.0, 60)
    fol = Foliage(lo, hi, dens, np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros(0), np.zeros(3), 1.0)
    pts = rng.uniform(-0.1, 0.15, (500, 3))
    inside = ((lo[None] <= pts[:, None]) & (pts[:, None] <= hi[None])).all(axis=2)
    brute = (inside * dens[None]).sum(axis=1)
    assert inside.sum(axis=1).max() > 8  # the slow path is exercised
    np.testing.assert_allclose(fol.origin_density(pts), brute, rtol=1e-12)


def test_small_faces_keep_their_share_of_samples():
    """With no per-face floor, a fine grid beside one big quad gets samples in proportion to its area
    (stochastic rounding); plain rounding would give every grid face 0."""
    fine = floor_quad(1.0)  # 2 faces of area 2
    n = 40
    t = np.linspace(0, 1, n + 1)
    xx, yy = np.meshgrid(t, t, indexing="ij")
    v = np.stack([xx.ravel() + 5, yy.ravel(), np.zeros(xx.size)], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    grid = (v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]))
    scene = merge(fine, grid)
    total_area = 4.0 + 1.0
    settings = TraceSettings(
        samples_per_vertex=800 / len(scene.vertices), samples_per_face_cap=1000, min_samples_per_face=0
    )
    s = receiver_samples(scene, settings, seed=0)
    on_grid = (s.face >= 2).sum()
    expected = 800 * 1.0 / total_area  # 0.05 per grid face, 160 in all
    assert abs(on_grid - expected) < 5 * np.sqrt(expected)


@pytest.mark.parametrize("run", [3, 10, 10**6])
def test_a_sample_range_s_areas_are_the_piece_s(tiny_geometry, monkeypatch, run):
    """The samples' passes take a range's face areas from its own faces' vertices (an instance cut by the
    range transforms only the vertices it uses): the piece's areas, bit for bit, for pieces of one and of
    several instances; and each piece's area is their sum."""
    import neuralao.pipeline.bakes.level_pieces as level_pieces

    monkeypatch.setattr(level_pieces, "SAMPLE_RANGE_FACES", run)
    g = tiny_geometry
    for piece_faces in (100, 10**9):
        index = index_level(g.level, piece_faces)
        for piece in index.pieces:
            ranges = level_pieces.piece_ranges(piece)
            assert ranges[0][0] == 0 and ranges[-1][1] == piece.nf and len(ranges) == -(-piece.nf // run)
            got = np.concatenate([level_pieces.range_areas(g.level, index, piece, a, b) for a, b in ranges])
            np.testing.assert_array_equal(got, face_areas(piece_scene(g.level, index, piece)))
        # each piece's area (what the LOD weighs it by) is its faces' areas added
        _, pieces = sample_rule(g.level, index, 2.0, 0, 4, seed=7)
        for piece in pieces:
            areas = face_areas(piece_scene(g.level, index, piece))
            assert piece.area == pytest.approx(float(areas.sum()), rel=1e-12) and piece.area > 0
