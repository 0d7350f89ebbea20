"""The level LOD simplified per piece at one shared quadric error (``lod.max_error``): the error stop on
closed and split-vertex meshes, and per-piece bakes of the tiny level against its unsimplified bake."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import trimesh

from neuralao.pipeline.bakes.level import bake_level
from neuralao.pipeline.bakes.level_pieces import index_level, piece_scene
from neuralao.pipeline.bakes.level_settings import load_level_settings
from neuralao.pipeline.bakes.level_stages import simplify_to_error, tile_cells
from neuralao.pipeline.geometry.level_files import read_level
from neuralao.pipeline.geometry.level_gen import settings_for, write_level
from neuralao.pipeline.geometry.scene import scene_from_arrays
from neuralao.runtime.foundation.io import read_npz


def test_the_error_stop_bounds_how_far_a_sphere_moves():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=1.0)  # 5,120 faces
    kept = []
    for max_error in (1e-6, 1e-4, 1e-2):
        v, f = simplify_to_error(sphere.vertices, sphere.faces.astype(np.int64), max_error)
        kept.append(len(f))
        # A vertex's quadric error is its summed squared distance to the planes it replaced, so no vertex
        # leaves the planes of the sphere's faces by more than sqrt(max_error); a sphere's faces lie within
        # 1 - cos(edge angle) of its surface, which the bound below allows for.
        off_planes = np.abs(np.linalg.norm(v, axis=1) - 1.0)
        assert off_planes.max() <= np.sqrt(max_error) + 2e-3, max_error
    assert kept[0] > kept[1] > kept[2]  # a larger error removes more
    assert kept[0] > 0.9 * len(sphere.faces)  # 1e-6: the sphere's curvature costs more than that


def test_a_split_vertex_box_keeps_its_faces():
    box = trimesh.creation.box(extents=(4.0, 3.0, 5.0))
    v = box.vertices[box.faces].reshape(-1, 3)  # every face its own vertices, as the level's houses
    f = np.arange(len(v)).reshape(-1, 3)
    out_v, out_f = simplify_to_error(v, f, 1.0)
    assert len(out_f) == 12  # a quadric sees no cost in folding an open quad to a line: borders are kept
    np.testing.assert_allclose(np.sort(out_v, axis=0), np.sort(v, axis=0))


def test_tiles_cover_a_piece_once_and_keep_their_cuts():
    n = 24  # a flat 24 x 24 grid in x-z: every interior collapse is free, its border is kept
    x, z = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0), indexing="ij")
    v = np.c_[x.ravel(), np.zeros(x.size), z.ravel()]
    q = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    f = np.r_[np.c_[q, q + 1, q + n + 1], np.c_[q + 1, q + n + 2, q + n + 1]]
    scene = scene_from_arrays(v, f, "grid")
    cells = tile_cells(scene, 4)
    tiles = [np.flatnonzero(cells == t) for t in range(4)]
    np.testing.assert_array_equal(np.sort(np.concatenate(tiles)), np.arange(len(f)))
    assert min(map(len, tiles)) == max(map(len, tiles))  # 2 x 2 equal cells
    whole_v, whole_f = simplify_to_error(v, f, 1e-6)
    kept_v = []
    for t in tiles:
        used, local = np.unique(f[t], return_inverse=True)
        tv, _ = simplify_to_error(v[used], local.reshape(-1, 3), 1e-6)
        kept_v.append(tv)
    # The cut at x = 12 is an open border of both tiles next to it: its 25 grid vertices all stay.
    on_cut = np.concatenate(kept_v)[:, 0] == 12.0
    assert len(np.unique(np.concatenate(kept_v)[on_cut][:, 2])) == n + 1
    assert len(whole_f) < len(f) // 4  # untiled, the flat interior goes


def test_tiles_hold_equal_face_counts_where_faces_crowd():
    """A grid with a 40 x 40 grid over one of its cells (most of the faces, crowded in a corner): the tiles
    still hold as many faces as each other, to one (a uniform grid of cells gave one tile most of them)."""
    parts_v, parts_f = [], []
    for size, m in ((8.0, 8), (1.0, 40)):  # an 8 x 8 grid of unit cells, then a fine one over its corner
        gx, gz = np.meshgrid(np.linspace(0, size, m + 1), np.linspace(0, size, m + 1), indexing="ij")
        q = (np.arange(m)[:, None] * (m + 1) + np.arange(m)[None, :]).ravel()
        faces = np.r_[np.c_[q, q + 1, q + m + 1], np.c_[q + 1, q + m + 2, q + m + 1]]
        parts_f.append(faces + sum(len(v) for v in parts_v))
        parts_v.append(np.c_[gx.ravel(), np.full(gx.size, 0.5 * len(parts_v)), gz.ravel()])
    scene = scene_from_arrays(np.concatenate(parts_v), np.concatenate(parts_f), "crowded")
    for tiles in (3, 4, 7):
        counts = np.bincount(tile_cells(scene, tiles), minlength=tiles)
        assert counts.sum() == len(scene.faces) and counts.max() - counts.min() <= 1, (tiles, counts)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("level_lod")
    level, cfg = write_level(root / "in", settings_for("tiny", seed=2), "tiny")
    common = ["trace.rays=32", "decorators.local_rays=16", "lod.holdout_samples=1000"]

    def bake(name, max_error):
        settings = load_level_settings(cfg, [*common, f"lod.max_error={max_error}"])
        return bake_level(level, settings, root / name)

    # 1e-9: below any collapse of this level (its LOD is its own mesh); 1.0: a third of its faces go.
    return root, level, bake("unsimplified", 1e-9), bake("simplified", 1.0)


def test_an_error_below_every_collapse_keeps_each_piece_whole(tiny):
    root, level, unsimplified, _ = tiny
    lv = read_level(level)
    index = index_level(lv, unsimplified["settings"]["piece_faces"])
    for p in index.pieces:
        source = piece_scene(lv, index, p)
        lod = read_npz(root / "unsimplified" / "stages" / "lod_meshes" / f"p{p.index:05d}.npz")
        assert len(lod["faces"]) == len(source.faces)
        np.testing.assert_allclose(np.sort(lod["vertices"], axis=0), np.sort(source.vertices, axis=0))


def test_the_simplified_lod_keeps_the_unsimplified_error(tiny):
    _, _, unsimplified, simplified = tiny
    full = next(s for s in unsimplified["stages"] if s["stage"] == "lod")
    lod = next(s for s in simplified["stages"] if s["stage"] == "lod")
    assert lod["lod_faces"] < 0.75 * full["lod_faces"]
    a, b = unsimplified["errors"]["lod"], simplified["errors"]["lod"]
    # Held-out points drawn on each LOD by area against the same traced samples: the simplified LOD's AO
    # is no more than 15% off the unsimplified mesh's own (measured: 0.84x at its vertices, 0.96x by least
    # squares; its longer edges widen the resampling sphere), and well below one constant.
    for k in ("rmse_vertex", "rmse_least_squares"):
        assert b[k] <= 1.15 * a[k], (k, a[k], b[k])
        assert b[k] < 0.8 * b["rmse_constant"]


def test_the_simplifications_run_in_the_solve_s_wave_or_in_the_lod_s_own(tiny, tmp_path):
    """The per-piece LOD's simplifications need no solved value: a fresh bake runs them in the solve's first
    wave (the LOD stage runs none), each a task of the solve's row; a bake whose solve is stored runs them
    in the LOD stage, and both write the same bytes."""
    root, level, _, simplified = tiny
    solve = next(s for s in simplified["stages"] if s["stage"] == "solve")
    lod = next(s for s in simplified["stages"] if s["stage"] == "lod")
    assert lod["simplify_tasks"] == 0 and lod["simplified_beside"] == 1
    # one piece: its solve and its simplification (one tile), in one wave
    assert simplified["counts"]["pieces"] == 1 and solve["tasks"] == 2
    assert simplified["task_waves"]["solve"] == [0, 0]
    out = tmp_path / "again"
    shutil.copytree(root / "simplified", out)
    for name in ("lod", "lod_meshes", "lod_resample"):
        shutil.rmtree(out / "stages" / name, ignore_errors=True)
    for name in ("lod.npz", "lod_check.npz", "decorators.npz"):
        (out / "stages" / name).unlink(missing_ok=True)
    (out / "level_baked.glb").unlink()
    cfg = root / "in" / "bake.json"
    common = ["trace.rays=32", "decorators.local_rays=16", "lod.holdout_samples=1000", "lod.max_error=1.0"]
    again = bake_level(level, load_level_settings(cfg, common), out)
    rows = {s["stage"]: s for s in again["stages"]}
    assert rows["solve"]["reused"] and not rows["lod"]["reused"] and rows["lod"]["simplify_tasks"] == 1
    assert rows["lod"]["simplified_beside"] == 0
    assert (out / "level_baked.glb").read_bytes() == (root / "simplified" / "level_baked.glb").read_bytes()


def test_a_resampling_block_makes_the_piece_s_points(tmp_path):
    """A resampling task's points (made from the faces under them) are the piece's LOD vertices then its
    samples, lo..hi of them, bit for bit, wherever the block starts and ends."""
    from neuralao.pipeline.bakes.level_stages import lod_block_points, lod_points

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    mesh = {"vertices": np.asarray(sphere.vertices), "faces": sphere.faces.astype(np.int64)}
    level, cfg = write_level(tmp_path, settings_for("tiny", seed=1), "tiny")
    s = load_level_settings(cfg, [])
    piece = index_level(read_level(level), 10**9).pieces[0]
    lod, samples = lod_points(mesh["vertices"], mesh["faces"], piece, s)
    every = np.r_[lod.vertices, samples.points]
    nv = len(lod.vertices)
    rng = np.random.default_rng(2)
    cuts = [
        (0, len(every)),
        (0, nv),
        (nv, nv + 1),
        (nv - 3, nv + 5),
        (7, 7),
        *rng.integers(0, len(every), (12, 2)),
    ]
    for lo, hi in cuts:
        lo, hi = int(min(lo, hi)), int(max(lo, hi))
        np.testing.assert_array_equal(
            lod_block_points("k", mesh, piece, lo, hi, s), every[lo:hi], err_msg=f"{lo}:{hi}"
        )


def test_the_lod_error_sums_are_the_whole_pieces_gold_standard(tiny):
    """The gold standard at a piece's held-out LOD points, summed a trace block at a time by its tasks, is
    the one computed from all of the piece's traced samples at once (the sphere, the normal test and the
    distance weights, here written out directly), and so are the piece's error sums."""
    from scipy.spatial import cKDTree

    from neuralao.pipeline.bakes.level_pieces import cached_piece, sample_rule
    from neuralao.pipeline.bakes.level_settings import LevelBakeSettings, blend
    from neuralao.pipeline.bakes.level_stages import (
        LOD_HELD_OUT,
        TaskFiles,
        lod_error_sums,
        lod_piece_errors,
        lod_reference_stems,
        piece_trace,
    )
    from neuralao.runtime.foundation.settings import from_dict

    root, level_path, _, info = tiny
    s = from_dict(LevelBakeSettings, info["settings"])
    level = read_level(level_path)
    index = index_level(level, s.piece_faces)
    t = s.trace
    rule, pieces = sample_rule(
        level, index, t.samples_per_vertex, t.min_samples_per_face, t.samples_per_face_cap, s.seed
    )
    stages = root / "simplified" / "stages"
    lod_files, reference = (
        TaskFiles(stages / "lod", info["keys"]["lod"]),
        TaskFiles(stages / "lod_reference", info["keys"]["lod_check"]),
    )
    radius, checked = float(info["errors"]["lod"]["radius"]), 0
    for p in pieces:
        r = lod_files.get(f"p{p.index:05d}", LOD_HELD_OUT)
        if len(r["hold_points"]) == 0:
            continue
        _, samples = cached_piece(info["keys"]["geometry"], level, index, p, rule)
        ao, valid = piece_trace(TaskFiles(stages / "trace", info["keys"]["trace"]), p, t.block_samples)
        f = blend(ao[:, 0], ao[:, 1], s.blend).astype(np.float64)[valid]
        pts, nrm, sw = samples.points[valid], samples.normals[valid], samples.weights[valid]
        sums = np.zeros((len(r["hold_points"]), 2))
        for i, nb in enumerate(cKDTree(pts).query_ball_point(r["hold_points"], radius)):
            nb = np.asarray(nb, np.int64)
            w = sw[nb] * np.maximum(radius - np.linalg.norm(pts[nb] - r["hold_points"][i], axis=1), 0)
            w = w * (nrm[nb] @ r["hold_normals"][i] > 0.5)
            sums[i] = w.sum(), np.sum(w * f[nb])
        expected = lod_error_sums(r, sums)
        got = lod_piece_errors(r, reference, lod_reference_stems(p, t.block_samples))
        assert expected[5] > 0
        np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-15)
        checked += 1
    assert checked > 0
