"""What `dataset`, level files and the `level` generator do with input they cannot use: scene names that
would write outside --out, config rules checked before anything is made, a folder of another config started
over cleanly, level glTFs held to the specification and to coordinates a bake resolves, generator settings
whose level its own bake takes. Every command runs for real, in-process, with warnings as errors
(:func:`test_user_inputs.run`)."""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pytest
from helpers import with_changes
from test_user_inputs import TET, refusal, run, tet_gltf

from neuralao.pipeline.cli.main import main
from neuralao.pipeline.geometry.gltf import GltfFile
from neuralao.pipeline.geometry.level_files import read_level
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.runtime.foundation.errors import NeuralaoError

# --------------------------------------------------------------------------- dataset configs


def _config(tmp_path: Path, **changes) -> dict:
    """A one-scene dataset config of the tetrahedron (8x8 frames, 2 rays): a run takes a second."""
    (tmp_path / "tet.obj").write_text(TET)
    scene = {"name": "tet", "mesh": "tet.obj", "views": 2, "split": "train"}
    config = {"name": "t", "size": [8, 8], "frames_per_shard": 1, "labels": {"rays": 2}, "scenes": [scene]}
    return with_changes(config, changes)


def _argv(tmp_path: Path, config: dict, out: Path) -> list[str]:
    """``neuralao dataset`` of ``config`` (written to d.json) into ``out``."""
    (tmp_path / "d.json").write_text(json.dumps(config))
    return ["dataset", str(tmp_path / "d.json"), "--no-progress", "--out", str(out)]


@pytest.mark.parametrize("name", ["../../evil", "a/b", "/tmp/x", "", "a\x00b"])
def test_a_scene_name_that_is_not_plain_is_refused_before_any_work(tmp_path, capsys, name):
    out = tmp_path / "deep" / "er" / "out"
    msg = refusal(capsys, _argv(tmp_path, _config(tmp_path, **{"scenes.0.name": name}), out))
    assert "d.json" in msg and "scenes[0].name" in msg and "not a plain name" in msg
    assert not (tmp_path / "deep").exists() and not list(tmp_path.rglob("*.npz"))


@pytest.mark.parametrize(
    "changes,words",
    [
        ({"labels.rays": 0}, "rays"),
        ({"labels.workers": 0}, "workers"),
        ({"labels.radii_rel": [-0.1]}, "labels.radii_rel"),
        ({"labels.radii_rel": [0.9]}, "beyond labels.max_distance_rel"),
        ({"labels.max_distance": 1.0, "labels.max_distance_rel": 0.25}, "give one"),
        ({"scenes.0.yfov_deg": 0}, "scenes[0].yfov_deg"),
        ({"scenes.0.yfov_deg": 180}, "scenes[0].yfov_deg"),
        ({"yfov_range_deg": [0.01, 30]}, "yfov_range_deg[0]"),
        ({"scenes.0.cameras": "file"}, "poses"),
        ({"scenes.0.cameras": "file", "scenes.0.poses": "nope.json"}, "scenes[0].poses"),
    ],
)
def test_a_config_refused_after_the_first_checks_makes_nothing(tmp_path, capsys, changes, words):
    out = tmp_path / "out"
    msg = refusal(capsys, _argv(tmp_path, _config(tmp_path, **changes), out))
    assert "d.json" in msg and words in msg, msg
    assert not out.exists()  # not even an empty shards/ folder


def test_a_folder_of_another_config_starts_over_and_keeps_only_its_own_shards(tmp_path, capsys):
    out = tmp_path / "out"
    assert run(capsys, _argv(tmp_path, _config(tmp_path, **{"scenes.0.views": 3}), out))[0] == 0
    assert len(list((out / "shards").glob("*.npz"))) == 3
    smaller = _config(tmp_path, **{"scenes.0.views": 1, "scenes.0.name": "tiny"})
    assert run(capsys, _argv(tmp_path, smaller, out))[0] == 0
    manifest = json.loads((out / "manifest.json").read_text())
    listed = sorted(Path(s["file"]).name for s in manifest["shards"])
    assert sorted(p.name for p in (out / "shards").iterdir()) == listed == ["tiny-0000.npz"]
    # the same config again keeps every shard as it is
    stamp = (out / "shards" / "tiny-0000.npz").stat().st_mtime_ns
    assert run(capsys, _argv(tmp_path, smaller, out))[0] == 0
    assert (out / "shards" / "tiny-0000.npz").stat().st_mtime_ns == stamp
    assert json.loads((out / "manifest.json").read_text()) == manifest


def test_a_folder_holding_another_kind_of_manifest_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "manifest.json").write_text('{"kind": "unet"}')
    msg = refusal(capsys, _argv(tmp_path, _config(tmp_path), out))
    assert "manifest.json" in msg and "not a dataset" in msg
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json"]


# --------------------------------------------------------------------------- level files

TINY_LEVEL = ["buildings=[]", "terrain_cells=3", "crown_subdivisions=0", "houses=1", "trees=1", "shrubs=2"]


@pytest.fixture(scope="module")
def level(tmp_path_factory) -> Path:
    """A tiny generated level (level.gltf + level.bin) and a fast bake config beside it."""
    d = tmp_path_factory.mktemp("level")
    assert main(["level", *(a for s in [*TINY_LEVEL, "grass=2"] for a in ("--set", s)), "--out", str(d)]) == 0
    fast = {
        "trace": {"rays": 4, "samples_per_vertex": 1.0, "samples_per_face_cap": 2},
        "decorators": {"samples_per_instance": 16, "holdout_samples": 16, "local_rays": 4},
        "grass": {"rays": 4},
        "lod": {"enabled": False},
    }
    (d / "fast.json").write_text(json.dumps(fast))
    return d


def _node(doc: dict, name: str) -> dict:
    return next(n for n in doc["nodes"] if n.get("name") == name)


def _first_primitive(doc: dict) -> dict:
    return doc["meshes"][_node(doc, "terrain")["mesh"]]["primitives"][0]


def _edit(key: str, doc: dict) -> None:
    """One hostile change to a level's JSON."""
    if key == "density_int":  # an integer past float64, as JSON allows
        _node(doc, "shrubs")["extras"]["density"] = 10**400
    elif key == "indices_float":
        doc["accessors"][_first_primitive(doc)["indices"]]["componentType"] = 5126
    elif key == "position_ubyte":
        doc["accessors"][_first_primitive(doc)["attributes"]["POSITION"]]["componentType"] = 5121
    elif key == "terrain_scale_1e20":
        _node(doc, "terrain")["scale"] = [1e20] * 3
    elif key == "matrix_1e300":
        _node(doc, "house_0")["matrix"] = [1e300, 0, 0, 0, 0, 1e300, 0, 0, 0, 0, 1e300, 0, 0, 0, 0, 1]
    elif key == "matrix_strings":
        node = _node(doc, "house_0")
        node["matrix"] = [str(float(x)) for x in node["matrix"]]
    elif key == "matrix_bools":
        _node(doc, "house_0")["matrix"] = [True, False, False, False] * 3 + [False, False, False, True]
    elif key == "matrix_projective":
        _node(doc, "house_0")["matrix"][3] = 0.5
    elif key in ("translation", "rotation", "scale"):
        _node(doc, "terrain")[key] = ["1"] * (4 if key == "rotation" else 3)
    elif key == "scene_false":
        doc["scene"] = False


@pytest.mark.parametrize(
    "key,words",
    [
        ("density_int", "density must be a finite number"),
        ("indices_float", "unsigned integer componentType"),
        ("position_ubyte", "KHR_mesh_quantization"),
        ("terrain_scale_1e20", "less than 2^-36 of the level's reach"),
        ("matrix_1e300", "within +-1e+30"),
        ("matrix_strings", "matrix must be a list of 16 finite numbers"),
        ("matrix_bools", "matrix must be a list of 16 finite numbers"),
        ("matrix_projective", "last row [0.5, 0.0, 0.0, 1.0]"),
        ("translation", "translation must be a list of 3 finite numbers"),
        ("rotation", "rotation must be a list of 4 finite numbers"),
        ("scale", "scale must be a list of 3 finite numbers"),
        ("scene_false", "scene False is not a scene"),
    ],
)
def test_a_level_file_the_bake_cannot_use_is_one_line_naming_it(level, tmp_path, capsys, key, words):
    doc = json.loads((level / "level.gltf").read_text())
    _edit(key, doc)
    (tmp_path / "level.bin").write_bytes((level / "level.bin").read_bytes())
    (tmp_path / "bad.gltf").write_text(json.dumps(doc))
    out = tmp_path / "out"
    argv = ["bake", str(tmp_path / "bad.gltf"), "--config", str(level / "fast.json"), "--out", str(out)]
    msg = refusal(capsys, argv)
    assert "bad.gltf" in msg and words in msg, msg
    assert not out.exists()


def test_quantized_positions_are_read_when_the_file_declares_the_extension(level, tmp_path):
    doc = json.loads((level / "level.gltf").read_text())
    _edit("position_ubyte", doc)
    doc["extensionsUsed"] = [*doc.get("extensionsUsed", []), "KHR_mesh_quantization"]
    (tmp_path / "level.bin").write_bytes((level / "level.bin").read_bytes())
    (tmp_path / "q.gltf").write_text(json.dumps(doc))
    GltfFile(tmp_path / "q.gltf")  # the rule is the specification's: with the extension, integers are valid


@pytest.mark.parametrize(
    "changes,words",
    [
        ({"nodes.0.matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0.5, 0, 0, 0, 1]}, "last row"),
        ({"nodes.0.rotation": [0, 0, 2, 1]}, "unit quaternion"),
        ({"nodes.0.matrix": [1, 0, 0, 0] * 3 + [0, 0, 0, 1], "nodes.0.scale": [1, 1, 1]}, "give one"),
        ({"scene": True}, "scene True"),
        ({"nodes.0.rotation": [0, 0, 0, 0]}, "unit quaternion"),
        ({"nodes.0.matrix": [float("nan")] + [0] * 14 + [1]}, "matrix must be a list of 16 finite numbers"),
        ({"nodes.0.scale": [float("inf"), 1, 1]}, "scale must be a list of 3 finite numbers"),
    ],
)
def test_every_reader_holds_node_transforms_to_the_specification(tmp_path, capsys, changes, words):
    # render reads through trimesh after the same checks the bakers' reader runs
    (tmp_path / "bad.gltf").write_text(json.dumps(tet_gltf(**changes)))
    out = tmp_path / "r"
    argv = ["render", str(tmp_path / "bad.gltf"), "--views", "1", "--size", "8", "8", "--rays", "1"]
    msg = refusal(capsys, [*argv, "--out", str(out)])
    assert "bad.gltf" in msg and words in msg, msg
    assert not out.exists()


def nested_tet(scales: list[float], size: float = 1.0) -> dict:
    """The tetrahedron ``size`` across under a chain of nodes, each scaling its child by the next of
    ``scales``."""
    chain = [{"name": f"n{i}", "scale": [s] * 3, "children": [i + 1]} for i, s in enumerate(scales)]
    doc = tet_gltf(nodes=[*chain, {"name": "Box", "mesh": 0}])
    blob = bytearray(base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1]))
    blob[:48] = (np.frombuffer(blob[:48], np.float32) * np.float32(size)).tobytes()  # the 4 positions
    doc["buffers"][0]["uri"] = "data:;base64," + base64.b64encode(bytes(blob)).decode()
    doc["accessors"][0]["max"] = [size] * 3
    return doc


@pytest.mark.parametrize(
    "command",
    [
        ["bake", "--rays", "4", "--out", "out.glb"],  # the scene bake's own reader
        ["bake", "--rays", "4", "--out", "out.ply"],  # flattened by trimesh (load_scene)
        ["render", "--views", "1", "--size", "8", "8", "--rays", "1", "--out", "out"],
    ],
)
def test_nested_scales_that_overflow_are_refused_naming_the_node(tmp_path, capsys, command):
    # each 1e30 is a legal scale; eleven of them multiply past float64 (1.8e308) into inf and NaN vertices
    (tmp_path / "bad.gltf").write_text(json.dumps(nested_tet([1e30] * 11)))
    out = tmp_path / command[-1]
    msg = refusal(capsys, [command[0], str(tmp_path / "bad.gltf"), *command[1:-1], str(out)])
    assert "bad.gltf node 11 'Box'" in msg and "world transform is not finite" in msg, msg
    assert not out.exists()
    with pytest.raises(NeuralaoError, match="node 11 'Box': its world transform is not finite"):
        read_level(tmp_path / "bad.gltf")


@pytest.mark.parametrize(
    "scales,size,words",
    [([1e30] * 2, 1.0, "coordinates up to 1e+60"), ([1e30] * 10, 1e10, "coordinates past float64's range")],
)
def test_a_world_transform_that_places_a_mesh_too_far_is_refused_naming_the_node(
    tmp_path, capsys, scales, size, words
):
    # every factor legal and their product finite: the positions under it pass the G-buffers' range or float64
    (tmp_path / "bad.gltf").write_text(json.dumps(nested_tet(scales, size)))
    out = tmp_path / "out.glb"
    msg = refusal(capsys, ["bake", str(tmp_path / "bad.gltf"), "--rays", "4", "--out", str(out)])
    assert f"bad.gltf node {len(scales)} 'Box': its world transform places mesh 0" in msg and words in msg, (
        msg
    )
    # flattened by trimesh, which names no node: the mesh is refused in one line, with no numpy warning
    flat = tmp_path / "out.ply"
    msg = refusal(capsys, ["bake", str(tmp_path / "bad.gltf"), "--rays", "4", "--out", str(flat)])
    assert "mesh " in msg and "bad.gltf has" in msg, msg
    assert not out.exists() and not flat.exists()


def test_nested_scales_that_cancel_are_read(tmp_path):
    # 1e30 and 1e-30 in turn: their running product stays near 1, however deep the chain
    (tmp_path / "ok.gltf").write_text(json.dumps(nested_tet([1e30, 1e-30] * 12)))
    scene = load_scene(tmp_path / "ok.gltf")
    np.testing.assert_allclose(np.sort(scene.vertices, axis=0), [[0, 0, 0]] * 3 + [[1, 1, 1]], atol=1e-12)


# --------------------------------------------------------------------------- the level generator


@pytest.mark.parametrize(
    "argv,words",
    [
        (["--seed", "5", "--set", "seed=7"], "given twice"),
        (["--set", "terrain_height=-1e30"], "terrain_height"),
        (["--set", "terrain_size=1e12"], "terrain_size"),
        (["--set", "blocker_height=-3"], "blocker_height"),
        (["--set", 'buildings=[{"mesh": "cornell_box", "scale": 1e9}]'], "lower the scale"),
        (["--set", 'buildings=[{"mesh": "cornell_box", "scale": 1e-12}]'], "raise the scale"),
    ],
)
def test_generator_settings_are_refused_naming_them(tmp_path, capsys, argv, words):
    msg = refusal(capsys, ["level", *argv, "--out", str(tmp_path / "l")])
    assert words in msg, msg
    assert not (tmp_path / "l").exists()


def test_a_level_at_the_generators_bounds_is_one_its_bake_reads(tmp_path, capsys):
    sets = [*TINY_LEVEL[1:], "grass=2", "terrain_size=1e9", "terrain_height=-1e9", "blocker_height=1e9"]
    sets.append('buildings=[{"mesh": "cornell_box", "scale": 1e8}]')
    argv = ["level", "--seed", "5", *(a for s in sets for a in ("--set", s)), "--out", str(tmp_path / "l")]
    assert run(capsys, argv)[0] == 0
    level = read_level(tmp_path / "l" / "level.gltf")  # the bake's reader: every instance resolvable
    assert {n.role for n in level.nodes} == {"static", "blocker", "tree", "shrub", "grass"}
    assert json.loads((tmp_path / "l" / "level.gltf").read_text())["extras"]["generator"]["seed"] == 5
