"""Level bakes end to end on the tiny generated level: outputs, resumable stages, determinism, the
decorator vertex shader on Mesa, and the error tables' direction."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import trimesh

from neuralao.pipeline import cli
from neuralao.pipeline.bakes.level import bake_level
from neuralao.pipeline.bakes.level_settings import load_level_settings
from neuralao.pipeline.geometry.gltf import quat_to_matrix
from neuralao.pipeline.geometry.level_files import read_gltf_json
from neuralao.pipeline.geometry.level_gen import settings_for, write_level
from neuralao.pipeline.geometry.surface import interpolate, vertex_colours


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    root = tmp_path_factory.mktemp("level")
    level, cfg = write_level(root / "in", settings_for("tiny", seed=2), "tiny")
    info = bake_level(level, load_level_settings(cfg), root / "out")
    return root, level, cfg, info


def _static_ao(path) -> dict[str, np.ndarray]:
    doc, get = read_gltf_json(path)
    return {
        n["name"]: get(doc["meshes"][n["mesh"]]["primitives"][0]["attributes"]["_AO"])
        for n in doc["nodes"]
        if n.get("extras", {}).get("role") == "static" and "lod" not in n["extras"]
    }


def _assert_same_static_ao(one, other, atol: float) -> None:
    """Every static node of the bakes in folders ``one`` and ``other`` has the same AO within ``atol``."""
    a, b = _static_ao(one / "level_baked.glb"), _static_ao(other / "level_baked.glb")
    assert a.keys() == b.keys()
    for name, ao in a.items():
        np.testing.assert_allclose(b[name], ao, atol=atol, err_msg=name)


def test_a_bake_in_pieces_is_the_bake_of_the_whole_level(baked, tmp_path):
    """Cut into three pieces (the terrain, then the buildings), every task runs per piece, yet each static
    vertex gets the AO of the one-piece bake: the samples and rays are the same, and each piece's least
    squares is the level's block (its weights and prior are the level's). The bake log lists every
    task's seconds."""
    root, level, cfg, info = baked
    pieces = bake_level(level, load_level_settings(cfg, ["piece_faces=100"]), tmp_path / "pieces")
    assert info["counts"]["pieces"] == 1 and pieces["counts"]["pieces"] == 3
    assert pieces["counts"]["samples"] == info["counts"]["samples"]
    _assert_same_static_ao(root / "out", tmp_path / "pieces", atol=1e-5)
    blocks = {s["stage"]: s.get("tasks", 0) for s in pieces["stages"]}
    assert blocks["solve"] == 3 and blocks["output"] == 3 and blocks["trace"] >= 3
    assert len(pieces["task_seconds"]["trace"]) == blocks["trace"]
    assert all(t >= 0 for ts in pieces["task_seconds"].values() for t in ts)


def test_two_tasks_at_a_time_bake_the_bytes_of_one_at_a_time(baked, tmp_path):
    """A local bake runs ``workers`` tasks at once on threads, each tracing on one (three pieces: several
    tasks per stage); one worker, one task at a time, writes the same glTF bytes."""
    root, level, cfg, info = baked
    two = bake_level(level, load_level_settings(cfg, ["piece_faces=100"]), tmp_path / "two")
    one = bake_level(level, load_level_settings(cfg, ["piece_faces=100", "workers=1"]), tmp_path / "one")
    assert two["counts"]["pieces"] == 3 and two["tasks_at_once"] == 2 and one["tasks_at_once"] == 1
    assert two["task_threads"] == one["task_threads"] == 1
    assert (tmp_path / "two" / "level_baked.glb").read_bytes() == (
        tmp_path / "one" / "level_baked.glb"
    ).read_bytes()


def test_robust_bvh_bakes_the_fast_ones_ao(baked, tmp_path):
    """``trace.bvh=robust`` (the watertight scene, for farms whose machines trace little each) bakes what the
    default fast scene bakes: every static vertex's AO within 1e-3 (the same hits but for rare grazing rays
    and ties between coincident faces)."""
    root, level, cfg, info = baked
    bake_level(level, load_level_settings(cfg, ["trace.bvh=robust"]), tmp_path / "robust")
    _assert_same_static_ao(root / "out", tmp_path / "robust", atol=1e-3)


def _glb(root):
    doc, get = read_gltf_json(root / "out" / "level_baked.glb")
    return doc, get


def test_outputs_hold_every_signal(baked):
    root, level, cfg, info = baked
    doc, get = _glb(root)
    assert "EXT_mesh_gpu_instancing" in doc["extensionsUsed"]
    statics = [
        n for n in doc["nodes"] if n.get("extras", {}).get("role") == "static" and "lod" not in n["extras"]
    ]
    verts = 0
    for n in statics:
        attrs = doc["meshes"][n["mesh"]]["primitives"][0]["attributes"]
        ao, colour = get(attrs["_AO"]), get(attrs["COLOR_0"])
        short, long_ = get(attrs["_AO_SHORT"]), get(attrs["_AO_LONG"])
        np.testing.assert_array_equal(np.rint(colour[:, 0] * 255), vertex_colours(ao)[:, 0])
        np.testing.assert_allclose(
            ao, np.clip(0.97 * long_ + 0.03 * short, 0, 1), atol=1e-6
        )  # the per-level blend
        assert short.mean() > long_.mean()  # per vertex only on average: least squares may overshoot
        verts += len(ao)
    assert verts == info["counts"]["receiver_vertices"]
    # Per sample, 2 m obscurance is never darker than 300 m (rho_short(d) >= rho_long(d) for every ray).
    from neuralao.runtime.foundation.io import read_npz

    blocks = sorted((root / "out" / "stages" / "trace").glob("*.npz"))
    traced = np.concatenate([read_npz(f)["ao"] for f in blocks])
    assert len(traced) == info["counts"]["samples"] and (traced[:, 0] >= traced[:, 1]).all()
    trees = [n for n in doc["nodes"] if n.get("extras", {}).get("role") == "tree"]
    inst = trees[0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]
    assert get(inst["_AO_GLOBAL"]).shape == (3, 4)
    local = get(doc["meshes"][trees[0]["mesh"]]["primitives"][0]["attributes"]["_AO_LOCAL"])
    assert ((local >= 0) & (local <= 1)).all() and local.std() > 0.01
    grass = next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "grass")
    g_ao = get(grass["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["_AO"])
    assert g_ao.shape == (20,) and ((g_ao > 0) & (g_ao <= 1)).all()
    assert any(n.get("extras", {}).get("lod") == 1 for n in doc["nodes"])
    # A second consumer reads it: trimesh loads every mesh.
    loaded = trimesh.load(root / "out" / "level_baked.glb", force="scene")
    assert len(loaded.geometry) == len(doc["meshes"])
    stages = [s["stage"] for s in info["stages"]]
    for name in (
        "geometry",
        "samples",
        "bvh",
        "foliage",
        "trace",
        "decorators",
        "solve",
        "small_decorators",
        "lod",
        "output",
    ):
        assert name in stages
    assert (root / "out" / "bake_log.md").read_text().count("|") > 40


def test_grass_matches_the_terrain_under_it(baked):
    """A clump's scalar is the terrain AO near its base: compare with the baked terrain interpolated at
    the clump's foot (vertical projection onto the terrain grid)."""
    root, level, cfg, info = baked
    doc, get = _glb(root)
    terrain = next(n for n in doc["nodes"] if n["name"] == "terrain")
    attrs = doc["meshes"][terrain["mesh"]]["primitives"][0]["attributes"]
    v, ao = get(attrs["POSITION"]).astype(np.float64), get(attrs["_AO"])
    grass = next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "grass")
    ia = grass["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]
    pos, g_ao = get(ia["TRANSLATION"]), get(ia["_AO"])
    nearest = np.argmin(np.linalg.norm(v[None, :, [0, 2]] - pos[:, None, [0, 2]], axis=2), axis=1)
    assert np.abs(g_ao - ao[nearest]).mean() < 0.05


def test_decorator_shader_on_mesa_matches_the_model(baked):
    """The generated vertex shader, run by transform feedback, against numpy evaluating the glTF's own
    attributes: local AO x (y0 + y . (p_world - t)), with p_world from an independent quaternion."""
    from neuralao.runtime.decorator_runner import run_decorator_vertex_shader

    root, *_ = baked
    doc, get = _glb(root)
    tree = next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "tree")
    prim = doc["meshes"][tree["mesh"]]["primitives"][0]["attributes"]
    ia = tree["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]
    p, local = get(prim["POSITION"]), get(prim["_AO_LOCAL"])
    t, q, s, y = get(ia["TRANSLATION"]), get(ia["ROTATION"]), get(ia["SCALE"]), get(ia["_AO_GLOBAL"])
    source = (root / "out" / "shaders" / "decorator.vert").read_text()
    ao, world = run_decorator_vertex_shader(source, p, local, t, q, s, y)
    for j in range(len(t)):
        m = trimesh.transformations.quaternion_matrix([q[j, 3], q[j, 0], q[j, 1], q[j, 2]])[:3, :3]
        w = (p * s[j]) @ m.T + t[j]
        np.testing.assert_allclose(world[j], w, atol=1e-4)
        expected = np.clip(local * (y[j, 0] + (w - t[j]) @ y[j, 1:]), 0, 1)
        np.testing.assert_allclose(ao[j], expected, atol=1e-5)
    np.testing.assert_allclose(
        quat_to_matrix(q[:1])[0],
        trimesh.transformations.quaternion_matrix([q[0, 3], q[0, 0], q[0, 1], q[0, 2]])[:3, :3],
        atol=1e-6,
    )


def test_error_tables_point_the_right_way(baked):
    *_, info = baked
    e = info["errors"]
    d = e["decorators"]
    assert d["instances"] == 3
    assert d["local_x_global"]["mean"] < d["global_only"]["mean"]  # the local AO helps
    assert d["in_place"]["mean"] < d["local_x_global"]["mean"]  # per-vertex per-instance is the gold standard
    # Both LOD transfers carry the signal (well below one constant); which of the two wins is measured
    # (README), not assumed: on this 1.3k-face level they are within 10% of each other.
    assert max(e["lod"]["rmse_least_squares"], e["lod"]["rmse_vertex"]) < 0.6 * e["lod"]["rmse_constant"]
    assert e["blend"]["same_rays_max_abs"] < 1e-6  # the mean is linear: blend == blended kernel


def test_a_bake_without_error_tables_writes_the_same_level(baked, tmp_path):
    """``error_tables=false`` (a production bake): no check stage runs and the baked level is the default
    bake's, byte for byte; a rerun that asks for them reuses every stage and makes only the checks."""
    root, level, cfg, info = baked
    lean = bake_level(level, load_level_settings(cfg, ["error_tables=false"]), tmp_path / "lean")
    stages = [st["stage"] for st in lean["stages"]]
    assert "lod" in stages and not {"lod_check", "blend_check"} & set(stages)
    assert set(lean["errors"]) == {"decorators"}  # the trees' fits are the bake's, not a check
    assert (tmp_path / "lean" / "level_baked.glb").read_bytes() == (
        root / "out" / "level_baked.glb"
    ).read_bytes()
    full = bake_level(level, load_level_settings(cfg), tmp_path / "lean")
    fresh = {st["stage"] for st in full["stages"] if not st["reused"]}
    assert {"lod_check", "blend_check"} <= fresh
    assert not fresh & {"trace", "solve", "small_decorators", "lod", "decorators"}  # stored: reused
    assert (
        full["errors"]["lod"] == info["errors"]["lod"] and full["errors"]["blend"] == info["errors"]["blend"]
    )


def test_rerun_reuses_stages_and_resumes_to_identical_bytes(baked, tmp_path):
    root, level, cfg, info = baked
    out = tmp_path / "out"
    shutil.copytree(root / "out", out)
    again = bake_level(level, load_level_settings(cfg), out)
    reused = {s["stage"] for s in again["stages"] if s["reused"]}
    assert reused == {"trace", "decorators", "solve", "small_decorators", "lod", "lod_check", "blend_check"}
    assert (out / "level_baked.glb").read_bytes() == (root / "out" / "level_baked.glb").read_bytes()
    # A run killed mid-way: a trace block, the solve and the output gone, a temporary left behind.
    (out / "stages" / "solve.npz").unlink()
    (out / "stages" / "trace.npz").unlink()
    (out / "stages" / "trace" / "p00000_00000.npz").unlink()
    (out / "level_baked.glb").unlink()
    (out / "stages" / ".solve.npz.abc.tmp.npz").write_bytes(b"partial")
    (out / ".level_baked.glb.spill.tmp").write_bytes(b"partial")  # a killed output stage's glTF spill
    third = bake_level(level, load_level_settings(cfg), out)
    assert not (out / "stages" / ".solve.npz.abc.tmp.npz").exists()
    assert not (out / ".level_baked.glb.spill.tmp").exists()
    assert {s["stage"] for s in third["stages"] if s["reused"]} == reused - {"trace", "solve"}
    assert (out / "level_baked.glb").read_bytes() == (root / "out" / "level_baked.glb").read_bytes()


def test_subdomain_solve_bakes_the_component_solve_and_resumes(baked, tmp_path):
    """``trace.subdomains``: the terrain's component (625 vertices, over ``component_vertices``) is solved
    in 4 subdomains, a task each per step of the CG (two an iteration), the other pieces' solves beside its
    subdomains' assembly, and every static vertex gets the default bake's AO; a rerun reuses the driver-solved
    piece's file and writes the same bytes. The bake log gives each task's wave (map call)."""
    root, level, cfg, info = baked
    s, out, sub = _bake_split(baked, tmp_path / "sub", 200)
    _assert_same_static_ao(tmp_path / "components", out, atol=1e-6)
    solve = next(st for st in sub["stages"] if st["stage"] == "solve")
    assert solve["tasks"] > 4 * 5 and solve["seconds_driver"] > 0  # subdomain tasks, >= 5 iterations
    waves = sub["task_waves"]["solve"]
    assert len(waves) == solve["tasks"] and waves == sorted(waves) and waves[0] == 0
    per_wave = np.bincount(waves)
    # the subdomains' assembly with the other two pieces' solves, then 4 tasks a step (the terrain's plan,
    # its components and subdomains, was made beside the trace's blocks)
    assert sub["counts"]["pieces"] == 3 and per_wave[0] == 4 + 2 and set(per_wave[1:]) == {4}
    assert len(sub["task_aside"]["trace"]) == 1
    first = (out / "level_baked.glb").read_bytes()
    (out / "stages" / "solve.npz").unlink()
    (out / "level_baked.glb").unlink()
    again = bake_level(level, s, out)
    solve = next(st for st in again["stages"] if st["stage"] == "solve")
    assert not solve["reused"] and solve.get("tasks", 0) == 0  # the piece's file was kept and read back
    assert (out / "level_baked.glb").read_bytes() == first


def test_a_rerun_with_the_trace_stored_makes_the_solve_plans_in_the_solve(baked, tmp_path):
    """With the trace stored, a rerun that solves in subdomains redoes the solve only: the plans a fresh
    bake makes beside its trace's blocks are the rerun's solve's first wave, and both write the same bytes;
    the plans' files go once the solve is stored."""
    again, fresh = _rerun_and_fresh(baked, tmp_path, ["trace.subdomains=4", "trace.component_vertices=200"])
    assert "trace" in _reused(again) and "solve" not in _reused(again)
    plans = len(fresh["task_aside"]["trace"])
    assert plans >= 1 and "trace" not in again["task_aside"]
    assert np.bincount(again["task_waves"]["solve"])[0] == plans
    assert not (tmp_path / "rerun" / "stages" / "solve_plan").exists()


def _bake_split(baked, out, component_vertices: int) -> tuple:
    """The module's level in pieces of 100 faces without its LOD, baked into ``out`` with the solve in 4
    subdomains (or groups) from ``component_vertices`` and into ``out``'s sibling ``components`` without
    them: (the first's settings, ``out``, its log)."""
    _, level, cfg, _ = baked
    split = ["trace.subdomains=4", f"trace.component_vertices={component_vertices}"]
    common = ["lod.enabled=false", "piece_faces=100"]
    s = load_level_settings(cfg, split + common)
    log = bake_level(level, s, out)
    bake_level(level, load_level_settings(cfg, common), out.parent / "components")
    return s, out, log


def test_a_big_piece_of_small_components_is_solved_in_groups_of_them(baked, tmp_path):
    """With ``trace.subdomains``, a piece of at least ``component_vertices`` vertices none of whose
    components is that big (the first buildings' piece: 144 vertices, 36 components of 4) is solved as
    ``subdomains`` tasks, each a group of whole components, beside the terrain's subdomains' assembly, then
    a wave of their solves with the piece's ridge; every static vertex gets the AO of the pieces' one-task
    solves, the groups' results are written as the
    piece's one file, and a rerun reads that file back and writes the same bytes."""
    root, level, cfg, info = baked
    s, out, grouped = _bake_split(baked, tmp_path / "groups", 100)
    # to a float32 step or two: each group takes its piece's ridge (a group's own moved these by 3e-7)
    _assert_same_static_ao(tmp_path / "components", out, atol=1e-7)
    per_wave = np.bincount(grouped["task_waves"]["solve"])
    # the terrain's plan (its components and subdomains) was made beside the trace's blocks (the buildings'
    # meshes are smaller than 100 vertices: they need none); then the terrain's 4 subdomains' assembly
    # beside the buildings' 4 groups' rows and the last piece's solve, 4 tasks a step of the terrain's CG,
    # and last the 4 groups' solves
    assert len(grouped["task_aside"]["trace"]) == 1
    assert per_wave[0] == 4 + 4 + 1 and set(per_wave[1:]) == {4}
    assert sorted(f.name for f in (out / "stages" / "solve").glob("*.npz")) == [
        "p00000.npz",
        "p00001.npz",
        "p00002.npz",
    ]
    first = (out / "level_baked.glb").read_bytes()
    (out / "stages" / "solve.npz").unlink()
    (out / "level_baked.glb").unlink()
    again = bake_level(level, s, out)
    assert _row(again, "solve").get("tasks", 0) == 0  # every piece's file read back
    assert (out / "level_baked.glb").read_bytes() == first


def test_component_groups_pack_whole_components_evenly():
    """Components packed largest first into the emptiest group: sizes 5, 4, 3, 3, 1 in two groups give 8 and
    8; a component is never split; with more groups than components the others stay empty."""
    from neuralao.pipeline.bakes.level_stages import component_groups

    components = np.repeat(np.arange(5), [3, 5, 1, 4, 3])  # component c's vertices, sizes 3 5 1 4 3
    groups = component_groups(components, 2)
    assert np.bincount(groups).tolist() == [8, 8]
    for c in range(5):
        assert len(set(groups[components == c])) == 1
    assert np.bincount(component_groups(components, 8), minlength=8).tolist() == [5, 4, 3, 3, 1, 0, 0, 0]


# The stages a bake stores under OUT/stages/ (each with its own key).
STORED = {"trace", "solve", "small_decorators", "lod", "lod_check", "blend_check", "decorators"}


def _reused(info) -> set[str]:
    return {st["stage"] for st in info["stages"] if st["reused"]}


def _row(info, stage: str) -> dict:
    return next(st for st in info["stages"] if st["stage"] == stage)


def _rerun_and_fresh(baked, tmp_path, overrides: list[str], engine=None) -> tuple[dict, dict]:
    """The module's bake copied to ``rerun/`` and baked again there with ``overrides``, and a bake with them
    into the empty ``fresh/``: their logs, the two glTFs checked to be the same bytes."""
    root, level, cfg, _ = baked
    shutil.copytree(root / "out", tmp_path / "rerun")
    s = load_level_settings(cfg, overrides)
    again = bake_level(level, s, tmp_path / "rerun", engine=engine)
    fresh = bake_level(level, s, tmp_path / "fresh")
    assert (tmp_path / "rerun" / "level_baked.glb").read_bytes() == (
        tmp_path / "fresh" / "level_baked.glb"
    ).read_bytes()
    assert again["errors"] == fresh["errors"]
    return again, fresh


def _stage_arrays(out) -> dict[str, np.ndarray]:
    """Every array of every stored stage and task file but the timings, the tasks counted as done by an
    earlier run and the LOD's resampling blocks (sized by ``task_rays``; their values reach the LOD's)."""
    from neuralao.runtime.foundation.io import read_npz

    arrays = {}
    for f in sorted((out / "stages").rglob("*.npz")):
        if f.parent.name != "lod_resample":
            for k, v in read_npz(f).items():
                if not k.startswith("seconds_") and k not in ("reused_tasks", "resample_tasks"):
                    arrays[f"{f.relative_to(out / 'stages').with_suffix('')}/{k}"] = v
    return arrays


def test_every_setting_keys_the_stages_that_read_it_or_none():
    """Each setting is read by a stage's key (a section's name covers its keys) or named as changing no
    result; every name the keys read is a setting, and each stage's key reads only stages before it."""
    from neuralao.pipeline.bakes.level import STAGE_INPUTS, UNKEYED, setting_value
    from neuralao.pipeline.bakes.level_settings import LevelBakeSettings
    from neuralao.runtime.foundation.settings import settings_to_dict

    def leaves(d, prefix=""):
        for k, v in d.items():
            yield from leaves(v, f"{prefix}{k}.") if isinstance(v, dict) else [f"{prefix}{k}"]

    values = settings_to_dict(LevelBakeSettings())
    keyed = {name for reads, _ in STAGE_INPUTS.values() for name in reads}
    for name in keyed | set(UNKEYED):
        setting_value(values, name)  # a KeyError names one that is not a setting
    for name in leaves(values):
        hits = [k for k in keyed if name == k or name.startswith(k + ".")] + [u for u in UNKEYED if u == name]
        assert hits, f"{name} is in no stage's key and not named as unkeyed"
        assert name not in UNKEYED or len(hits) == 1, name
    stages = list(STAGE_INPUTS)
    for i, (_, after) in enumerate(STAGE_INPUTS.values()):
        assert set(after) <= set(stages[:i]), stages[i]


def test_a_changed_lod_setting_redoes_only_the_lod(baked, tmp_path):
    """A rerun with another LOD reduction reuses the trace, the solve and every other stage that does not
    read the LOD (no task of theirs runs), redoes the LOD and its check, and writes the bytes of a fresh bake
    with that setting."""
    again, _ = _rerun_and_fresh(baked, tmp_path, ["lod.target_reduction=0.4"])
    assert _reused(again) == STORED - {"lod", "lod_check"}
    assert "tasks" not in _row(again, "trace") and "tasks" not in _row(again, "solve")
    assert _row(again, "lod")["tasks"] > 0


def test_changed_subdomains_redo_the_solve_on_the_same_trace(baked, tmp_path):
    """``trace.subdomains`` is read by the solve, not the trace: a rerun with the terrain's component solved
    in 4 subdomains reuses the trace blocks, redoes the solve and the stages that read its values, and
    writes the bytes of a fresh bake with those settings."""
    again, _ = _rerun_and_fresh(baked, tmp_path, ["trace.subdomains=4", "trace.component_vertices=200"])
    assert _reused(again) == {"trace", "decorators"}
    assert _row(again, "solve")["tasks"] > 4 * 5  # subdomain tasks, >= 5 iterations


def test_changed_rays_redo_the_trace_and_every_stage_after_it(baked, tmp_path):
    """``trace.rays`` is read by the trace (and the trees' gold standard): a rerun redoes every stored stage
    and writes the bytes of a fresh bake."""
    again, _ = _rerun_and_fresh(baked, tmp_path, ["trace.rays=48"])
    assert not _reused(again) & STORED
    assert _row(again, "trace")["tasks"] > 0 and _row(again, "solve")["tasks"] > 0


def test_scheduling_settings_change_no_result_and_a_rerun_reuses_every_stage(baked, tmp_path):
    """``workers``, ``task_rays`` and the engine's threads schedule the tasks and change no result: a bake
    with other values (smaller resampling tasks, three at once, the trees' and the blend check's traces on
    three threads) stores the same arrays in every stage and task file, the same error tables and glTF
    bytes; and a rerun with them, on an engine of two-thread tasks, reuses every stage."""
    from neuralao.pipeline.engines.engine import LocalEngine

    root, level, cfg, info = baked
    overrides = ["workers=3", "task_rays=4096"]
    again, fresh = _rerun_and_fresh(baked, tmp_path, overrides, engine=LocalEngine(workers=3, threads=2))
    assert _reused(again) == STORED and again["keys"] == info["keys"]
    assert (tmp_path / "fresh" / "level_baked.glb").read_bytes() == (
        root / "out" / "level_baked.glb"
    ).read_bytes()
    assert fresh["errors"] == info["errors"]
    assert (
        fresh["tasks_at_once"] == 3
        and _row(fresh, "lod")["resample_tasks"] > _row(info, "lod")["resample_tasks"]
    )
    mine, theirs = _stage_arrays(tmp_path / "fresh"), _stage_arrays(root / "out")
    assert mine.keys() == theirs.keys() and "decorators/coefficients" in mine
    for k, v in theirs.items():
        np.testing.assert_array_equal(mine[k], v, err_msg=k)


def test_a_changed_blend_redoes_the_stages_that_read_it(baked, tmp_path):
    """Another blend weight reuses the trace and the solve (they store both distances) and redoes the
    stages that blend them; the baked AO is the new blend."""
    root, level, cfg, _ = baked
    out = tmp_path / "out"
    shutil.copytree(root / "out", out)
    s = load_level_settings(cfg, ["blend.long_weight=0.5", "lod.enabled=false"])
    info = bake_level(level, s, out)
    assert _reused(info) == {"trace", "solve"}
    doc, get = read_gltf_json(out / "level_baked.glb")
    terrain = next(n for n in doc["nodes"] if n["name"] == "terrain")
    a = doc["meshes"][terrain["mesh"]]["primitives"][0]["attributes"]
    np.testing.assert_allclose(
        get(a["_AO"]), np.clip(0.5 * get(a["_AO_LONG"]) + 0.5 * get(a["_AO_SHORT"]), 0, 1), atol=1e-6
    )
    assert not any(n.get("extras", {}).get("lod") for n in doc["nodes"])


def test_a_rerun_killed_in_a_redone_stage_never_reuses_its_stale_result(baked, tmp_path, monkeypatch):
    """A rerun with another solve killed after it rewrote the solve's first piece: the folder keeps no stored
    solve that would vouch for its files, so a bake with the first settings solves again and writes the
    first bake's bytes."""
    from neuralao.pipeline.bakes import level as level_bake

    class Killed(Exception):
        pass

    def killed(*args, **kwargs):
        for _ in solve_stage(*args, **kwargs):
            raise Killed  # after the piece's file is written

    root, level, cfg, _ = baked
    out = tmp_path / "out"
    shutil.copytree(root / "out", out)
    solve_stage = level_bake.solve_stage
    monkeypatch.setattr(level_bake, "solve_stage", killed)
    with pytest.raises(Killed):
        bake_level(level, load_level_settings(cfg, ["trace.alpha=2.0"]), out)
    monkeypatch.undo()
    again = bake_level(level, load_level_settings(cfg), out)
    assert "solve" not in _reused(again) and _row(again, "solve")["tasks"] == 1
    assert (out / "level_baked.glb").read_bytes() == (root / "out" / "level_baked.glb").read_bytes()


def test_remap_curve_is_applied_after_the_blend(baked, tmp_path):
    root, level, cfg, _ = baked
    s = load_level_settings(cfg, ["blend.remap=[[0, 0], [0.5, 0.8], [1, 1]]", "lod.enabled=false"])
    bake_level(level, s, tmp_path / "o")
    doc, get = read_gltf_json(tmp_path / "o" / "level_baked.glb")
    terrain = next(n for n in doc["nodes"] if n["name"] == "terrain")
    a = doc["meshes"][terrain["mesh"]]["primitives"][0]["attributes"]
    b = np.clip(0.97 * get(a["_AO_LONG"]).astype(np.float64) + 0.03 * get(a["_AO_SHORT"]), 0, 1)
    np.testing.assert_allclose(get(a["_AO"]), np.interp(b, [0, 0.5, 1], [0, 0.8, 1]), atol=1e-6)


@pytest.mark.parametrize(
    "override, message",
    [
        ("trace.rays=0", "trace.rays must be >= 1"),
        ("blend.long_weight=1.5", "blend.long_weight must be in [0, 1]"),
        ("blend.remap=[[0.2, 0], [1, 1]]", "cover [0, 1]"),
        ("output=../x.glb", "output must be a file name"),
        ("trace.solver=lu", "is not one of"),
        ("trace.bvh=quick", "is not one of"),
    ],
)
def test_bad_settings_are_one_line_errors(baked, override, message, capsys):
    root, level, cfg, _ = baked
    code = cli.main(["bake", str(level), "--config", str(cfg), "--set", override, "--out", str(root / "bad")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0]


def test_cli_level_bake_matches_the_library(baked, tmp_path):
    root, level, cfg, _ = baked
    assert cli.main(["bake", str(level), "--config", str(cfg), "--out", str(tmp_path / "cli")]) == 0
    assert (tmp_path / "cli" / "level_baked.glb").read_bytes() == (
        root / "out" / "level_baked.glb"
    ).read_bytes()
    log = json.loads((tmp_path / "cli" / "bake_log.json").read_text())
    assert log["counts"]["samples"] > 0 and log["peak_rss_bytes"] > 0


def test_lod_least_squares_interpolates_the_fit(baked):
    """The LOD's stored values reproduce what least squares fitted (sanity of the stage's arrays)."""
    root, *_ = baked
    from neuralao.pipeline.geometry.scene import scene_from_arrays
    from neuralao.runtime.foundation.io import read_npz

    lod = read_npz(root / "out" / "stages" / "lod" / "p00000.npz")
    mesh = read_npz(root / "out" / "stages" / "lod_meshes" / "p00000.npz")
    scene = scene_from_arrays(mesh["vertices"], mesh["faces"], "lod", drop_degenerate=False)
    assert len(scene.faces) < 0.6 * 1260 + 10
    vals = interpolate(
        scene, lod["ao_least_squares"], np.arange(len(scene.faces)), np.full((len(scene.faces), 3), 1 / 3)
    )
    assert ((vals >= 0) & (vals <= 1)).all()


def test_world10x_preset_is_ten_times_table1():
    """The 10x world keeps table1's mix (terrain, houses, buildings, trees, shrubs, grass) at ten times the
    counts and area, ~18M faces, without generating it: faces from the settings and the shared meshes."""
    from neuralao.pipeline.geometry.level_gen import BAKE_CONFIGS
    from neuralao.pipeline.geometry.scene import load_scene

    def faces(s):
        buildings = sum(len(load_scene(b.mesh).faces) * b.count for b in s.buildings)
        return 2 * s.terrain_cells**2 + s.houses * s.house_boxes * 12 + buildings

    t, w = settings_for("table1"), settings_for("world10x")
    assert faces(t) == 1_823_058  # Table 1's row, as baked
    assert 18_000_000 <= faces(w) <= 18_500_000
    for name in ("houses", "trees", "shrubs", "grass"):
        assert getattr(w, name) == 10 * getattr(t, name), name
    assert abs((w.terrain_size / t.terrain_size) ** 2 - 10) < 0.01
    assert (
        load_level_settings_dict(BAKE_CONFIGS["world10x"]).trace
        == load_level_settings_dict(BAKE_CONFIGS["table1"]).trace
    )


def load_level_settings_dict(data):
    from neuralao.pipeline.bakes.level_settings import LevelBakeSettings, check_settings
    from neuralao.runtime.foundation.settings import from_dict

    s = from_dict(LevelBakeSettings, data)
    check_settings(s)
    return s


def test_workers_of_several_threads_take_bigger_resampling_tasks_and_bake_the_same_bytes(baked, tmp_path):
    """Workers of 3 tracing threads get 3x the rays in each LOD resampling and grass task (a third of the
    tasks) and write the same glTF bytes: a point's value depends on its own rays alone."""
    from neuralao.pipeline.engines.engine import LocalEngine

    root, level, cfg, info = baked
    settings = load_level_settings(cfg, ["task_rays=2048"])
    one = bake_level(level, settings, tmp_path / "one")
    three = bake_level(level, settings, tmp_path / "three", engine=LocalEngine(threads=3))
    assert three["task_threads"] == 3 and one["task_threads"] == 1
    lod = {r["stage"]: r for r in one["stages"]}["lod"], {r["stage"]: r for r in three["stages"]}["lod"]
    assert lod[0]["resample_tasks"] > 2 and lod[1]["resample_tasks"] == -(-lod[0]["resample_tasks"] // 3)
    assert (tmp_path / "one" / "level_baked.glb").read_bytes() == (
        tmp_path / "three" / "level_baked.glb"
    ).read_bytes()


def test_the_opaque_bvh_is_prepared_once_before_the_foliage_is_made(baked, tmp_path, monkeypatch):
    """The opaque BVH's state holds no foliage, so the workers start building it once the level is cut into
    pieces: its one prepare call comes before the foliage stage begins, the foliage travels with the tasks
    that trace it, and the bytes are the local bake's."""
    from neuralao.pipeline.bakes import level as level_module
    from neuralao.pipeline.engines.engine import LocalEngine

    class Recording(LocalEngine):
        def __init__(self):
            super().__init__()
            self.prepared: list[str] = []

        def prepare(self, context):
            self.prepared.append(context.key)
            super().prepare(context)

    engine, seen = Recording(), []
    make_foliage = level_module._shrubs_and_foliage

    def foliage_after_prepares(*args):
        seen.append(list(engine.prepared))  # what was prepared when the foliage stage began
        return make_foliage(*args)

    monkeypatch.setattr(level_module, "_shrubs_and_foliage", foliage_after_prepares)
    root, level, cfg, info = baked
    log = bake_level(level, load_level_settings(cfg), tmp_path / "engine", engine=engine)
    opaque = [k for k in engine.prepared if k.startswith("level-trace/")]
    assert len(opaque) == 1 and seen == [opaque]
    order = [st["stage"] for st in log["stages"]]
    assert order.index("geometry") + 1 == order.index("prepare_opaque") < order.index("foliage")
    assert (tmp_path / "engine" / "level_baked.glb").read_bytes() == (
        root / "out" / "level_baked.glb"
    ).read_bytes()
