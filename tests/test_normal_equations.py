"""The least-squares normal equations, assembled per face and in shares (a share per trace block, each a task
of a level bake), against a dense reference built sample by sample from the energy's definition; and the
level bake's choice of which pieces its driver coordinates.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import soup_scene

from neuralao.pipeline.geometry.least_squares import (
    REG_SCALE,
    RIDGE_REL,
    Whole,
    equation_share,
    normal_equations,
    sum_shares,
    touching_faces,
    vertex_equations,
)
from neuralao.pipeline.geometry.scene import Scene
from neuralao.pipeline.geometry.surface import SurfaceSamples, surface_samples, vertex_components

# Entries are sums of a few hundred float64 products of one sign per term: a relative 1e-12 of the largest
# entry leaves room for any summation order, and is far below what a different matrix would change.
REL = 1e-12


def dense_reference(scene, samples, values, valid, alpha, weight, area, prior, ridge=True):
    """A and rhs from the energy sample by sample and edge by edge (module doc of least_squares), dense;
    without the ridge when not ``ridge``."""
    n = len(scene.vertices)
    a, rhs = np.zeros((n, n)), np.zeros((n,) + values.shape[1:])
    for s in np.flatnonzero(valid):
        corners = scene.faces[samples.face[s]]
        w = samples.weights[s] / weight
        for i in range(3):
            rhs[corners[i]] += w * samples.bary[s, i] * values[s]
            for j in range(3):
                a[corners[i], corners[j]] += w * samples.bary[s, i] * samples.bary[s, j]
    edges = {}
    for tri in scene.faces:
        v = scene.vertices[tri]
        third = 0.5 * np.linalg.norm(np.cross(v[1] - v[0], v[2] - v[0])) / 3.0
        for i, j in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            if i != j:
                key = (min(i, j), max(i, j))
                edges[key] = edges.get(key, 0.0) + third / area
    for (i, j), e in edges.items():
        k = alpha * REG_SCALE * e
        a[i, i] += k
        a[j, j] += k
        a[i, j] -= k
        a[j, i] -= k
    if not ridge:
        return a, rhs
    ridge = RIDGE_REL * a.diagonal().max()
    return a + ridge * np.eye(n), rhs + ridge * prior


@pytest.fixture(scope="module")
def soup():
    rng = np.random.default_rng(11)
    scene, _ = soup_scene(rng, houses=3, half=10.0)
    samples = surface_samples(scene, 2 * len(scene.vertices), 4, seed=1)
    values = rng.uniform(0, 1, (len(samples), 2))
    valid = rng.uniform(size=len(samples)) > 0.25
    values[rng.uniform(size=len(samples)) < 0.01] = np.nan  # non-finite values leave the data term too
    return scene, samples, values, valid


def _close(a, ref, rhs, ref_rhs):
    scale = np.abs(ref).max()
    assert np.abs(a.toarray() - ref).max() <= REL * scale
    assert np.abs(rhs - ref_rhs).max() <= REL * np.abs(ref_rhs).max()


def test_normal_equations_are_the_energy_s(soup):
    scene, samples, values, valid = soup
    ok = valid & np.isfinite(values).all(axis=1)
    weight = samples.weights[ok].sum()
    area = 0.5 * np.linalg.norm(scene.face_cross(), axis=1).sum()
    prior = np.average(values[ok], axis=0, weights=samples.weights[ok])
    ref, ref_rhs = dense_reference(scene, samples, values, ok, 0.7, weight, area, prior)
    a, rhs = normal_equations(scene, samples, values, valid, 0.7)
    _close(a, ref, rhs, ref_rhs)


@pytest.mark.parametrize("compact", [False, True])
@pytest.mark.parametrize("cuts", [[0.5], [0.1, 0.37, 0.8], list(np.linspace(0.01, 0.99, 17))])
def test_shares_of_blocks_add_up_to_the_whole_equations(soup, cuts, compact):
    """Blocks of samples cut anywhere (a face's samples may straddle two blocks), each with the faces from
    its first sample's onward: their shares add up to the equations of a piece of a bigger surface. Compact
    shares (each entry once) add up the same."""
    scene, samples, values, valid = soup
    whole = Whole(weight=3.0, area=900.0, prior=np.array([0.4, 0.6]))
    ref, ref_rhs = dense_reference(
        scene, samples, values, valid & np.isfinite(values).all(1), 1.0, 3.0, 900.0, whole.prior
    )
    bounds = [0, *(int(c * len(samples)) for c in cuts), len(samples)]
    shares = []
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        block = SurfaceSamples(
            *(getattr(samples, k)[lo:hi] for k in ("face", "bary", "points", "normals", "weights"))
        )
        first = 0 if lo == 0 else int(samples.face[lo])
        stop = len(scene.faces) if hi == len(samples) else int(samples.face[hi])
        shares.append(
            equation_share(scene, block, values[lo:hi], valid[lo:hi], 1.0, whole, (first, stop), compact)
        )
    if compact:  # each (row, column) and each right-hand side's vertex once per share
        for share in shares:
            assert len(np.unique(share["rows"] * len(scene.vertices) + share["cols"])) == len(share["rows"])
            assert len(np.unique(share["rhs_rows"])) == len(share["rhs_rows"])
    a, rhs = sum_shares(len(scene.vertices), shares, whole.prior)
    _close(a, ref, rhs, ref_rhs)
    whole_a, whole_rhs = normal_equations(scene, samples, values, valid, 1.0, whole)
    _close(whole_a, ref, whole_rhs, ref_rhs)


def test_faces_without_samples_still_get_the_regulariser(soup):
    """A share with no valid sample is the regulariser of its faces alone (a piece without samples)."""
    scene, samples, values, valid = soup
    whole = Whole(weight=1.0, area=50.0, prior=np.array([0.5, 0.5]))
    none = np.zeros(len(samples), bool)
    ref, ref_rhs = dense_reference(scene, samples, values, none, 2.0, 1.0, 50.0, whole.prior)
    for compact in (False, True):
        share = equation_share(scene, samples, values, none, 2.0, whole, (0, len(scene.faces)), compact)
        a, rhs = sum_shares(len(scene.vertices), [share], whole.prior)
        _close(a, ref, rhs, ref_rhs)
    empty = equation_share(scene, samples, values, none, 0.0, whole, (0, 0), compact=True)
    assert all(len(v) == 0 for v in empty.values())  # no sample, no face: nothing


def _rows_of(soup, vertices, alpha, whole):
    """vertex_equations of ``vertices`` from the faces touching them and their samples alone."""
    scene, samples, values, valid = soup
    faces = touching_faces(scene.faces, vertices, len(scene.vertices))
    on = np.isin(samples.face, faces)
    return vertex_equations(scene, faces, samples[on], values[on], valid[on], alpha, whole, vertices)


@pytest.mark.parametrize("share", [0.03, 0.4, 1.0])
def test_rows_made_from_the_faces_that_touch_them_are_the_energy_s(soup, share):
    """The rows of any vertices, made from the faces that touch them and those faces' samples alone (what a
    subdomain's worker makes), are the dense reference's rows (without the ridge), with every neighbour among
    their columns and every diagonal entry stored (a vertex in no face: a zero, where the ridge goes)."""
    scene, samples, values, valid = soup
    whole = Whole(weight=3.0, area=900.0, prior=np.array([0.4, 0.6]))
    ok = valid & np.isfinite(values).all(1)
    ref, ref_rhs = dense_reference(scene, samples, values, ok, 0.7, 3.0, 900.0, whole.prior, ridge=False)
    n = len(scene.vertices)
    vertices = np.flatnonzero(np.random.default_rng(5).uniform(size=n) < share)
    columns, rows, rhs = _rows_of(soup, vertices, 0.7, whole)
    assert rows.shape == (len(vertices), len(columns)) and np.array_equal(columns, np.unique(columns))
    dense = np.zeros((len(vertices), n))
    dense[:, columns] = rows.toarray()
    assert np.abs(dense - ref[vertices]).max() <= REL * np.abs(ref).max()
    assert np.abs(rhs - ref_rhs[vertices]).max() <= REL * np.abs(ref_rhs).max()
    assert np.isin(np.flatnonzero(ref[vertices].any(0)), columns).all()
    at = np.searchsorted(columns, vertices)
    assert all(at[r] in rows.indices[rows.indptr[r] : rows.indptr[r + 1]] for r in range(len(vertices)))
    lone = Scene(np.vstack([scene.vertices, [[0.0, 99.0, 0.0]]]), scene.faces)  # a vertex in no face
    columns, rows, rhs = _rows_of((lone, samples, values, valid), np.array([n]), 0.7, whole)
    assert columns.tolist() == [n] and rows.toarray().tolist() == [[0.0]] and not rhs.any()


def test_a_vertex_s_row_is_the_same_bits_whatever_is_asked_with_it(soup):
    """Two subdomains that both hold a vertex make its row and right-hand side alike, bit for bit: the
    copies of a partitioned solve's residual are the same bits only then."""
    scene = soup[0]
    whole = Whole(weight=3.0, area=900.0, prior=np.array([0.4, 0.6]))
    n = len(scene.vertices)
    first, second = np.arange(0, 2 * n // 3), np.arange(n // 3, n)
    a = _rows_of(soup, first, 1.0, whole)
    b = _rows_of(soup, second, 1.0, whole)
    for u in range(n // 3, 2 * n // 3):
        rows = []
        for (columns, m, rhs), vertices in ((a, first), (b, second)):
            r = int(np.searchsorted(vertices, u))
            span = slice(m.indptr[r], m.indptr[r + 1])
            rows.append((columns[m.indices[span]].tobytes(), m.data[span].tobytes(), rhs[r].tobytes()))
        assert rows[0] == rows[1], u


def test_vertex_components_join_vertices_by_faces():
    faces = np.array([[0, 1, 2], [2, 3, 4], [5, 6, 7], [8, 8, 9]])
    sizes = sorted(np.bincount(vertex_components(faces, 12)).tolist())
    assert sizes == [1, 1, 2, 3, 5]  # 0-4; then 5-7, 8-9, and 10, 11 in no face
    assert np.bincount(vertex_components(np.zeros((0, 3), np.int64), 3)).tolist() == [1, 1, 1]
    assert len(vertex_components(np.zeros((0, 3), np.int64), 0)) == 0


def test_the_driver_coordinates_only_pieces_with_a_big_component(tmp_path):
    """With ``trace.subdomains``, a piece of many vertices made of small meshes (houses) is one task like any
    other; the terrain's piece is coordinated by the driver, its equations made by its subdomains' tasks;
    both bakes write the vertex AO of the default solve."""
    from neuralao.pipeline.bakes.level import bake_level
    from neuralao.pipeline.bakes.level_pieces import index_level
    from neuralao.pipeline.bakes.level_settings import load_level_settings
    from neuralao.pipeline.bakes.level_stages import TaskFiles, pieces_context, plan_partition, solve_plans
    from neuralao.pipeline.engines.engine import LocalEngine
    from neuralao.pipeline.geometry.level_files import read_level
    from neuralao.pipeline.geometry.level_gen import settings_for, write_level

    level, cfg = write_level(tmp_path / "in", settings_for("tiny", seed=3), "tiny")
    base = ["lod.enabled=false", "trace.rays=8", "piece_faces=400"]
    bake_level(level, load_level_settings(cfg, base), tmp_path / "plain")
    split = ["trace.subdomains=4", "trace.component_vertices=200", "trace.block_samples=128"]
    sub = bake_level(level, load_level_settings(cfg, [*base, *split]), tmp_path / "sub")
    files = sorted((tmp_path / "sub" / "stages" / "solve").glob("*.npz"))
    here = [f.stem for f in files if float(np.load(f)["seconds_driver"]) > 0]
    assert len(here) == 1, here  # the terrain's piece, in subdomains
    a, b = (np.load(tmp_path / d / "stages" / "solve" / f"{here[0]}.npz") for d in ("plain", "sub"))
    np.testing.assert_allclose(b["short"], a["short"], atol=1e-6)
    np.testing.assert_allclose(b["long"], a["long"], atol=1e-6)
    solve = next(st for st in sub["stages"] if st["stage"] == "solve")
    assert solve["seconds_blocks"] > 0 and solve["tasks"] > len(files)
    # which pieces the driver coordinates: those with a component of 200 vertices, not every piece that big
    lv = read_level(level)
    index = index_level(lv, 400)
    ctx = pieces_context("k", lv, index)
    many = [p for p in index.pieces if p.nv >= 200]
    t = load_level_settings(cfg, [*base, *split]).trace
    plans = solve_plans(TaskFiles(tmp_path / "plans", "k"), LocalEngine(), ctx, many, t)
    chosen = sorted(i for i, plan in plans.items() if int(plan["largest"]) >= 200)
    assert len(many) == 2 and [f"p{i:05d}" for i in chosen] == here, (many, chosen)
    # the chosen piece's plan: 4 subdomains whose cores cover its vertices once, grown inside it
    part = plan_partition(plans[chosen[0]])
    nv = next(p.nv for p in many if p.index == chosen[0])
    assert len(part.parts) == 4 and np.bincount(part.core, minlength=4).sum() == nv
    assert all(np.isin(c, q).all() for c, q in zip(part.cores, part.parts, strict=True))
    # the plans were made in the trace's wave, beside its blocks (its log names them), not by the solve
    assert len(sub["task_aside"]["trace"]) == len(plans) and "solve" not in sub["task_aside"]
