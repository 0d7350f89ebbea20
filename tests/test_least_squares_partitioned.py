"""The partitioned least-squares solve (neuralao.pipeline.geometry.partitioned_solve) against SuperLU of the
same normal equations: a terrain grid with house footprints left unsampled, triangle soup (houses' boxes,
duplicated and interpenetrating triangles, a part without valid samples), the tiny level traced (real
back-face rejections), and the closed bunny; at 1 to 16 subdomains, with bounded iterations and the same
bytes on every run and engine."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import kill_a_worker_mid_run, smooth_values, soup_scene, under_footprints
from scipy.sparse.linalg import splu

from neuralao.pipeline.bakes.level_pieces import scene_samples
from neuralao.pipeline.bakes.level_settings import TraceSettings, halves, label_settings, load_level_settings
from neuralao.pipeline.bakes.level_stages import fit_level, opaque_scene
from neuralao.pipeline.engines.engine import Context, LocalEngine
from neuralao.pipeline.geometry.least_squares import (
    Whole,
    fit_least_squares,
    normal_equations,
    solve_amg,
    touching_faces,
    usable,
    vertex_equations,
)
from neuralao.pipeline.geometry.level_files import flatten, read_level
from neuralao.pipeline.geometry.level_gen import LevelGenSettings, settings_for, terrain
from neuralao.pipeline.geometry.level_gen import write_level as write_generated_level
from neuralao.pipeline.geometry.partitioned_solve import (
    RTOL,
    SolveInfo,
    factorise,
    mesh_partition,
    partition,
    solve_partitioned,
    solve_subdomains,
)
from neuralao.pipeline.geometry.scene import load_scene, scene_from_arrays
from neuralao.pipeline.geometry.surface import face_areas, surface_samples
from neuralao.runtime.foundation.errors import NeuralaoError

# Largest allowed |partitioned - SuperLU| (float64, before clipping). Measured: at most 7.8e-7 here (the
# soup's ribbon without samples), 1e-8 to 1e-7 on the rest. One 8-bit output step is 3.9e-3.
MAX_ABS = 1e-4
# Most CG iterations allowed per column at any subdomain count. Measured: at most 33 here (bunny and soup at
# 16 subdomains), 20 on the Table 1 terrain at 32 (bench/bench_partitioned_solve.py). Without the coarse
# space's per-component aggregates the soup fails one bound or the other: 66 iterations with one aggregate
# per core, 2e-3 off with one for everything.
MAX_ITERATIONS = 40
SUBDOMAINS = (1, 2, 4, 8, 16)


def _case(scene, samples, values, valid):
    a, rhs = normal_equations(scene, samples, values, valid)
    return SimpleNamespace(scene=scene, samples=samples, values=values, valid=valid, a=a, rhs=rhs)


@pytest.fixture(scope="module")
def terrain_case():
    """A terrain heightfield (91^2 vertices) sampled by Table 1's rule (1.25 samples a vertex, at most 2 a
    face, small faces none), its samples under 60 house footprints invalid."""
    rng = np.random.default_rng(3)
    s = LevelGenSettings(terrain_size=120.0, terrain_cells=90, terrain_height=6.0)
    scene = scene_from_arrays(
        *terrain(s, rng.uniform(0, 2 * math.pi, (4, 2))), "terrain", drop_degenerate=False
    )
    samples = scene_samples(scene, 1.25, 0, 2, seed=0)
    valid = ~under_footprints(samples.points, rng, 60, 52.0)
    return _case(scene, samples, smooth_values(samples.points, rng), valid)


@pytest.fixture(scope="module")
def soup_case():
    """Triangle soup (helpers.soup_scene: houses' boxes, interpenetrating, duplicated and fanned triangles,
    ellipsoids, ribbons across it all). The samples inside a sphere are invalid and so are all of one
    ribbon's: parts whose only hold is the ridge, some cut by every subdomain boundary."""
    rng = np.random.default_rng(4)
    scene, ribbon = soup_scene(rng)
    samples = surface_samples(scene, 3 * len(scene.vertices), 8, seed=0)
    valid = (rng.uniform(size=len(samples)) > 0.2) & (
        np.linalg.norm(samples.points - [10, 0, 10], axis=1) > 15
    )
    valid &= (samples.face < ribbon) | (samples.face >= ribbon + 300)
    return _case(scene, samples, smooth_values(samples.points, rng), valid)


@pytest.fixture(scope="module")
def level_case(tmp_path_factory):
    """The tiny generated level's static instances (terrain, box-soup houses, a Cornell box), traced: its
    invalid samples are the back-face rule's (terrain inside houses, faces inside boxes)."""
    from neuralao.pipeline.tracing.level_tracer import LevelLabeller

    out = tmp_path_factory.mktemp("level")
    level_path, cfg = write_generated_level(out, settings_for("tiny", seed=1, overrides=["houses=8"]), "tiny")
    level = read_level(level_path)
    s = load_level_settings(cfg, ["trace.rays=32"])
    rv, rf, _ = flatten(level, level.nodes_with("static"))
    scene = scene_from_arrays(rv, rf, "receivers", drop_degenerate=False)
    samples = scene_samples(scene, 4.0, 1, 8, seed=0)
    opaque = opaque_scene(level)
    ao, valid = LevelLabeller(opaque, label_settings(s, opaque.diagonal)).obscurance(
        samples.points, samples.normals, halves(s)
    )
    assert 0 < (~valid).sum() < len(valid) // 2
    return _case(scene, samples, ao.astype(np.float64), valid)


@pytest.fixture(scope="module")
def bunny_case():
    """The closed bunny (34,834 vertices), its samples within 0.3 of the extent of one point invalid (a
    patch the regulariser alone fills) and a fifth of the rest at random."""
    rng = np.random.default_rng(5)
    scene = load_scene("bunny")
    samples = surface_samples(scene, 3 * len(scene.vertices), 8, seed=0)
    p = samples.points
    hole = np.linalg.norm(p - p[0], axis=1) < 0.3 * np.ptp(p, axis=0).max()
    valid = ~hole & (rng.uniform(size=len(p)) > 0.2)
    return _case(scene, samples, smooth_values(p * 20 / np.ptp(p, axis=0).max(), rng), valid)


CASES = ("terrain_case", "soup_case", "level_case", "bunny_case")


def _direct(case) -> np.ndarray:
    if not hasattr(case, "direct"):
        case.direct = splu(case.a.tocsc()).solve(case.rhs)
    return case.direct


@pytest.mark.parametrize("name", CASES)
def test_partitioned_solve_is_the_global_solve(name, request):
    """At every subdomain count the CG converges to SuperLU's solution of the same normal equations within
    MAX_ABS, in at most MAX_ITERATIONS iterations, and each column's residual meets the tolerance."""
    case = request.getfixturevalue(name)
    direct = _direct(case)
    for k in SUBDOMAINS:
        info = SolveInfo()
        v = solve_partitioned(case.a, case.rhs, case.scene.vertices, k, info=info)
        err = float(np.abs(v - direct).max())
        assert err <= MAX_ABS, f"{name}, {k} subdomains: max abs {err:.2e}"
        assert max(info.iterations) <= MAX_ITERATIONS, f"{name}, {k} subdomains: {info.iterations} iterations"
        assert max(info.residuals) <= RTOL
        # a wave of k tasks for each of an iteration's two steps, the subdomains' assembly, the first local
        # solves and the collection
        waves = 2 * max(info.iterations) + 3
        assert len(info.subdomain_vertices) == k and len(info.seconds_tasks) == k * waves


class SampleRows:
    """The rows of a case's normal equations made per subdomain, from the faces that touch it and their
    samples alone (what a level's piece makes on its workers), the whole surface's weights and prior those
    :func:`normal_equations` takes."""

    def __init__(self, case):
        self.case = case
        ok = usable(case.values, case.valid)
        w, f = case.samples.weights[ok], case.values.reshape(len(case.values), -1)[ok]
        self.whole = Whole(float(w.sum()), float(face_areas(case.scene).sum()), np.average(f, 0, weights=w))

    def rows(self, state, vertices):
        c = self.case
        faces = touching_faces(c.scene.faces, vertices, len(c.scene.vertices))
        on = np.isin(c.samples.face, faces)
        return vertex_equations(
            c.scene, faces, c.samples[on], c.values[on], c.valid[on], 1.0, self.whole, vertices
        )


@pytest.mark.parametrize("name", CASES)
def test_subdomains_that_make_their_own_rows_solve_the_global_system(name, request):
    """Cut from the mesh before any equation is made (:func:`mesh_partition`: the same subdomains and
    aggregates as cut from the matrix), each subdomain's rows made where its tasks run and the ridge added
    from their largest diagonal entry: the CG converges to SuperLU's solution of :func:`normal_equations`
    within MAX_ABS in at most MAX_ITERATIONS iterations, soup included."""
    case = request.getfixturevalue(name)
    direct = _direct(case)
    source = SampleRows(case)
    for k in (1, 4, 16):
        part = mesh_partition(case.scene.vertices, case.scene.faces, k)
        ref = partition(case.a, case.scene.vertices, k)
        assert np.array_equal(part.core, ref.core) and np.array_equal(part.coarse, ref.coarse)
        assert all(np.array_equal(x, y) for x, y in zip(part.parts, ref.parts, strict=True))
        info = SolveInfo()
        v = solve_subdomains(source, part, info=info, ridge=source.whole.prior)
        err = float(np.abs(v - direct).max())
        assert err <= MAX_ABS, f"{name}, {k} subdomains: max abs {err:.2e}"
        assert max(info.iterations) <= MAX_ITERATIONS and max(info.residuals) <= RTOL
        assert len(info.seconds_tasks) == k * (2 * max(info.iterations) + 3)


def test_subdomains_that_make_their_own_rows_are_the_same_bytes_on_every_engine(terrain_case):
    """In this process, as tasks, and as tasks on two threads: the same bytes."""
    c = terrain_case
    source = SampleRows(c)
    part = mesh_partition(c.scene.vertices, c.scene.faces, 8, connected=True)
    runs = [
        solve_subdomains(source, part, engine, ridge=source.whole.prior)
        for engine in (None, LocalEngine(), LocalEngine(workers=2))
    ]
    assert runs[0].tobytes() == runs[1].tobytes() == runs[2].tobytes()


@pytest.mark.parametrize("name", ["terrain_case", "soup_case"])
def test_subdomain_solves_alone_are_not_the_global_solve(name, request):
    """The control that gives the comparison teeth: the same subdomain factors used once, as tiles (each
    core takes its subdomain's solution), are off by far more than MAX_ABS; the iteration is what
    converges."""
    case = request.getfixturevalue(name)
    part = partition(case.a, case.scene.vertices, 8)
    a = case.a.tocsr()
    tiles = np.zeros_like(case.rhs)
    for i, idx in enumerate(part.parts):
        local = factorise(a[idx][:, idx]).solve(case.rhs[idx])
        mine = part.core[idx] == i
        tiles[idx[mine]] = local[mine]
    assert np.abs(tiles - _direct(case)).max() > 100 * MAX_ABS


def test_partition_cores_are_equal_and_overlap_holds_every_neighbour(soup_case):
    """Cores of equal size (to one vertex) cover every vertex once; each subdomain holds every neighbour of
    its core in the matrix's graph (a house box's far corner too, however wide the face)."""
    a = soup_case.a.tocsr()
    for k in (3, 7, 16):
        part = partition(a, soup_case.scene.vertices, k, overlap=1)
        sizes = np.bincount(part.core, minlength=k)
        assert sizes.sum() == a.shape[0] and sizes.max() - sizes.min() <= 1
        for i, idx in enumerate(part.parts):
            core = np.flatnonzero(part.core == i)
            assert np.isin(np.unique(a[core].indices), idx).all()
            assert np.array_equal(idx, np.sort(idx))


def test_same_inputs_same_bytes_on_every_engine(terrain_case):
    """Two runs, and the local engine's tasks under a caller's context, give the same bytes."""
    c = terrain_case
    first = solve_partitioned(c.a, c.rhs, c.scene.vertices, 8)
    again = solve_partitioned(c.a, c.rhs, c.scene.vertices, 8)
    ctx = Context("test-held", lambda payload: "held", None)
    tasks = solve_partitioned(c.a, c.rhs, c.scene.vertices, 8, engine=LocalEngine(), context=ctx)
    threads = solve_partitioned(c.a, c.rhs, c.scene.vertices, 8, engine=LocalEngine(workers=2))
    assert first.tobytes() == again.tobytes() == tasks.tobytes() == threads.tobytes()


@pytest.mark.parametrize("where", ["rhs", "matrix"])
def test_a_non_finite_equation_is_a_one_line_error(bunny_case, where):
    """A NaN in the right-hand side or the matrix is an error, not a column taken as converged (zeros)."""
    c = bunny_case
    a, rhs = c.a.tocsr(copy=True), c.rhs.copy()
    if where == "rhs":
        rhs[7] = np.nan
    else:
        a.data[a.indptr[5]] = np.inf
    with pytest.raises(NeuralaoError, match="non-finite value"):
        solve_partitioned(a, rhs, c.scene.vertices, 4)


def test_a_stalled_solve_is_a_one_line_error(bunny_case):
    c = bunny_case
    with pytest.raises(NeuralaoError, match="did not converge in 3 iterations"):
        solve_partitioned(c.a, c.rhs, c.scene.vertices, 8, max_iterations=3)


def test_level_solver_setting_partitions_big_components(level_case):
    """``trace.subdomains``: fit_level solves each component of at least ``component_vertices`` (the
    terrain) in subdomains, in this process or as tasks of an engine, and matches SuperLU of the whole
    level; with the default (1) it is today's solve, byte for byte."""
    c = level_case
    direct = fit_least_squares(c.scene, c.samples, c.values, c.valid)
    default = fit_level(c.scene, c.samples, c.values, c.valid, TraceSettings())
    np.testing.assert_array_equal(default, direct)
    t = TraceSettings(component_vertices=300, subdomains=4)
    timing: dict[str, float] = {}
    here = fit_level(c.scene, c.samples, c.values, c.valid, t, timing=timing)
    np.testing.assert_allclose(here, direct, atol=1e-6)
    assert timing["driver"] > 0 and timing["largest_block"] < timing["blocks"]
    engine = LocalEngine()
    tasks = fit_level(c.scene, c.samples, c.values, c.valid, t, engine=engine)
    assert here.tobytes() == tasks.tobytes() and len(engine.task_seconds) > 4


@pytest.fixture(scope="module")
def ray_engine():
    """Two Ray actors on a private local instance, shut down after this module."""
    ray = pytest.importorskip("ray")
    from neuralao.pipeline.engines.engine import RayEngine

    try:
        with RayEngine(None, workers=2) as engine:
            yield engine
    finally:
        ray.shutdown()


def test_ray_subdomain_tasks_give_the_local_bytes(level_case, ray_engine):
    """The local solves as tasks of two Ray actors: the bytes of this process's."""
    c = level_case
    t = TraceSettings(component_vertices=300, subdomains=4)
    here = fit_level(c.scene, c.samples, c.values, c.valid, t)
    remote = fit_level(c.scene, c.samples, c.values, c.valid, t, engine=ray_engine)
    assert ray_engine.completed == 4  # the last iteration's map: one task per subdomain
    assert here.tobytes() == remote.tobytes()


def test_a_worker_killed_mid_solve_restarts_it_to_the_same_bytes(bunny_case, ray_engine):
    """The subdomains' vectors live on the workers between the CG's steps: an actor SIGKILLed mid-solve is
    restarted without them, the solve starts again, and its bytes are those of this process."""
    c = bunny_case
    here = solve_partitioned(c.a, c.rhs, c.scene.vertices, 8)
    info = SolveInfo()
    v = kill_a_worker_mid_run(
        ray_engine,
        lambda: solve_partitioned(c.a, c.rhs, c.scene.vertices, 8, engine=ray_engine, info=info),
        lambda: len(info.seconds_tasks) >= 8 * 6,  # a few steps in
        "solve steps",
    )
    assert info.restarts == 1
    assert here.tobytes() == v.tobytes()


def test_ray_level_bake_with_subdomains_is_the_local_bake(tmp_path, ray_engine):
    """A level bake whose terrain is solved in subdomains writes the same glTF bytes locally and on Ray."""
    from neuralao.pipeline.bakes.level import bake_level

    level, cfg = write_generated_level(tmp_path / "in", settings_for("tiny", seed=2), "tiny")
    s = load_level_settings(cfg, ["trace.subdomains=4", "trace.component_vertices=200", "lod.enabled=false"])
    local = bake_level(level, s, tmp_path / "local")
    remote = bake_level(level, s, tmp_path / "ray", engine=ray_engine)
    solve = [next(st for st in info["stages"] if st["stage"] == "solve") for info in (local, remote)]
    assert solve[0]["tasks"] == solve[1]["tasks"] > 20
    assert (tmp_path / "local" / "level_baked.glb").read_bytes() == (
        tmp_path / "ray" / "level_baked.glb"
    ).read_bytes()


def test_amg_solve_is_the_same_bytes_whatever_numpys_global_stream():
    """pyamg draws its spectral-radius start vectors from numpy's global random stream: the solve seeds it
    for the hierarchy (the same bytes after any earlier draws) and gives the caller's stream back."""
    n = 60
    idx = np.arange(n * n).reshape(n, n)
    i, j = np.r_[idx[:-1].ravel(), idx[:, :-1].ravel()], np.r_[idx[1:].ravel(), idx[:, 1:].ravel()]
    w = np.random.default_rng(0).uniform(0.5, 2.0, len(i))
    lap = sp.coo_matrix((np.r_[-w, -w], (np.r_[i, j], np.r_[j, i])), shape=(n * n, n * n)).tocsr()
    a = (sp.diags(-np.asarray(lap.sum(axis=1)).ravel() + 1e-3) + lap).tocsr()
    rhs = np.random.default_rng(1).normal(size=(n * n, 2))
    results = []
    for seed in (1, 2):
        np.random.seed(seed)
        x = solve_amg(a, rhs)
        assert np.random.rand() == np.random.RandomState(seed).rand()  # the caller's stream, untouched
        results.append(x)
    np.testing.assert_array_equal(results[0], results[1])
    np.testing.assert_allclose(a @ results[0], rhs, atol=1e-8 * np.abs(rhs).max())
