"""Level files: the seeded generator, the glTF reader (EXT_mesh_gpu_instancing, roles in extras) and
its one-line errors for bad levels."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from neuralao.pipeline.geometry.level_files import GltfWriter, decompose, read_level, trs_matrices
from neuralao.pipeline.geometry.level_gen import settings_for, write_level
from neuralao.runtime.foundation.errors import NeuralaoError


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("tiny")
    write_level(out, settings_for("tiny", seed=3), "tiny")
    return out / "level.gltf"


def test_generator_is_deterministic_and_seeded(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    for d, seed in ((a, 1), (b, 1), (c, 2)):
        write_level(d, settings_for("tiny", seed=seed), "tiny")
    assert (a / "level.bin").read_bytes() == (b / "level.bin").read_bytes()
    assert (a / "level.gltf").read_bytes() == (b / "level.gltf").read_bytes()
    assert (a / "level.bin").read_bytes() != (c / "level.bin").read_bytes()


def test_reader_roles_counts_and_instancing(tiny):
    level = read_level(tiny)
    roles = {n.role for n in level.nodes}
    assert roles == {"static", "blocker", "tree", "shrub", "grass"}
    s = settings_for("tiny", seed=3)
    counts = level.counts()
    assert counts["tree_instances"] == s.trees and counts["shrub_instances"] == s.shrubs
    assert counts["grass_instances"] == s.grass
    assert counts["static_faces"] == 2 * s.terrain_cells**2 + s.houses * s.house_boxes * 12 + 36
    tree = level.nodes_with("tree")[0]
    assert tree.params == {"transmission": 0.5}
    assert level.nodes_with("shrub")[0].params == {"density": s.shrub_density}


def test_a_level_pickles_its_nodes_in_band_and_reads_back_the_same(tiny):
    """A level travels to workers pickled (protocol 5, Ray's object store): its nodes' matrices come back
    the same bits, writable, and go in the pickle's own bytes, not an out-of-band buffer a node (only the
    meshes' arrays are buffers)."""
    import pickle

    level = read_level(tiny)
    buffers: list = []
    back = pickle.loads(pickle.dumps(level, protocol=5, buffer_callback=buffers.append), buffers=buffers)
    mesh_bytes = sum(m.vertices.nbytes + m.faces.nbytes for m in level.meshes)
    assert sum(memoryview(b).nbytes for b in buffers) == mesh_bytes and len(buffers) <= 2 * len(level.meshes)
    for a, b in zip(level.nodes, back.nodes, strict=True):
        assert (a.index, a.name, a.role, a.mesh, a.params) == (b.index, b.name, b.role, b.mesh, b.params)
        assert a.transforms.dtype == b.transforms.dtype and a.transforms.tobytes() == b.transforms.tobytes()
        assert a.transforms.shape == b.transforms.shape and b.transforms.flags.writeable


def test_instance_transforms_match_an_independent_quaternion_convention(tiny):
    """The reader's TRS (glTF quaternion x, y, z, w) against trimesh.transformations (w, x, y, z)."""
    doc = json.loads(tiny.read_text())
    node = next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "tree")
    blob = tiny.with_suffix(".bin").read_bytes()

    def acc(i):
        a = doc["accessors"][i]
        v = doc["bufferViews"][a["bufferView"]]
        w = {"VEC3": 3, "VEC4": 4}[a["type"]]
        return (
            np.frombuffer(blob, np.float32, a["count"] * w, v["byteOffset"]).reshape(-1, w).astype(np.float64)
        )

    attrs = node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]
    t, q, s = acc(attrs["TRANSLATION"]), acc(attrs["ROTATION"]), acc(attrs["SCALE"])
    expected = []
    for ti, qi, si in zip(t, q, s, strict=True):
        m = trimesh.transformations.quaternion_matrix([qi[3], qi[0], qi[1], qi[2]])
        m[:3, :3] = m[:3, :3] * si
        m[:3, 3] = ti
        expected.append(m)
    level = read_level(tiny)
    np.testing.assert_allclose(level.nodes_with("tree")[0].transforms, np.array(expected), atol=1e-6)
    t2, q2, s2 = decompose(level.nodes_with("tree")[0].transforms)
    np.testing.assert_allclose(trs_matrices(t2, q2, s2, len(t2)), np.array(expected), atol=1e-6)


def test_glb_and_gltf_read_the_same(tmp_path):
    w = GltfWriter()
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    w.node(
        "tri",
        w.mesh("tri", v, np.array([[0, 1, 2]])),
        matrix=np.diag([2.0, 2.0, 2.0, 1.0]),
        extras={"role": "static"},
    )
    a = read_level(w.write(tmp_path / "x.glb"))
    b = read_level(w.write(tmp_path / "x.gltf"))
    np.testing.assert_array_equal(a.nodes[0].transforms, b.nodes[0].transforms)
    np.testing.assert_array_equal(a.meshes[0].vertices, v)
    assert a.nodes[0].transforms[0, 0, 0] == 2.0


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_spilled_writer_writes_the_same_bytes(tmp_path, suffix):
    """A writer whose binary data goes to a spill file as it is added (a level's glTF of gigabytes) writes
    the bytes the in-memory writer writes, and removes its spill."""
    rng = np.random.default_rng(0)
    meshes = [rng.uniform(-1, 1, (7 + k, 3)) for k in range(3)]  # odd sizes: padding between views
    for name, spill in (("memory", None), ("spill", tmp_path / "x.part")):
        w = GltfWriter(spill=spill)
        for k, v in enumerate(meshes):
            ao = np.linspace(0, 1, len(v), dtype=np.float32)
            w.node(f"n{k}", w.mesh(f"m{k}", v, np.array([[0, 1, 2], [2, 3, 4]]), {"_AO": ao}))
        w.write(tmp_path / name / f"level{suffix}")
        assert spill is None or not spill.exists()
    for f in [f"level{suffix}"] + (["level.bin"] if suffix == ".gltf" else []):
        assert (tmp_path / "memory" / f).read_bytes() == (tmp_path / "spill" / f).read_bytes()


def _piece(w: GltfWriter, rng, k: int) -> None:
    """A piece's meshes and nodes as a level bake writes them (odd sizes: padding between views)."""
    for m in range(1 + k % 3):
        v = rng.uniform(-1, 1, (5 + 2 * k + m, 3))
        attrs = {
            "COLOR_0": rng.integers(0, 255, (len(v), 4), dtype=np.uint8),
            "_AO": rng.uniform(size=len(v)),
        }
        mesh = w.mesh(f"m{k}_{m}", v, np.array([[0, 1, 2], [2, 3, 4]]), attrs)
        w.node(f"n{k}_{m}", mesh, extras={"role": "static", "instance": m})


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_parts_made_elsewhere_splice_into_the_bytes_of_one_writer(tmp_path, suffix):
    """Pieces written by other writers for their place (as a level bake's workers do), spliced in order as
    JSON text, then the driver's own meshes and instanced nodes: the bytes of one writer making it all."""

    def driver_items(w: GltfWriter) -> None:
        tree = w.mesh("tree", np.eye(3), np.array([[0, 1, 2]]))
        w.node("trees", tree, instances={"TRANSLATION": np.zeros((4, 3)), "_AO_GLOBAL": np.ones((4, 4))})

    one = GltfWriter(spill=tmp_path / "one.spill")
    rng = np.random.default_rng(5)
    for k in range(4):
        _piece(one, rng, k)
    driver_items(one)
    one.write(tmp_path / "one" / f"level{suffix}")

    spliced, place = GltfWriter(spill=tmp_path / "two.spill"), np.zeros(5, np.int64)
    rng = np.random.default_rng(5)
    for k in range(4):
        part = GltfWriter.positioned(place)
        _piece(part, rng, k)
        fragments = part.fragments()
        spliced.splice(fragments)
        place = place + [*fragments["counts"], 0]
        place[4] += -(-len(fragments["blob"]) // 4) * 4  # the next part starts 4-byte aligned
    driver_items(spliced)
    spliced.write(tmp_path / "two" / f"level{suffix}")
    for f in [f"level{suffix}"] + (["level.bin"] if suffix == ".gltf" else []):
        assert (tmp_path / "one" / f).read_bytes() == (tmp_path / "two" / f).read_bytes()


def test_a_part_made_for_another_place_is_refused():
    w = GltfWriter()
    _piece(w, np.random.default_rng(1), 0)
    part = GltfWriter.positioned(np.zeros(5, np.int64))  # made for the start, which is taken
    _piece(part, np.random.default_rng(2), 1)
    with pytest.raises(NeuralaoError, match="made for place"):
        w.splice(part.fragments())
    with pytest.raises(NeuralaoError, match="4-byte aligned"):
        GltfWriter.positioned([0, 0, 0, 0, 6])


def _edit(path, fn):
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def _bad_mesh_index(doc):
    doc["nodes"][0]["mesh"] = 99


def _bad_role(doc):
    doc["nodes"][0]["extras"] = {"role": "bush"}


def _typo(doc):
    next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "shrub")["extras"]["densty"] = 1.0


def _negative_density(doc):
    next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "shrub")["extras"]["density"] = -1.0


def _transmission(doc):
    next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "tree")["extras"]["transmission"] = 1.5


def _extras_not_object(doc):
    doc["nodes"][0]["extras"] = "static"


def _zero_scale_node(doc):
    doc["nodes"][1]["scale"] = [1.0, 0.0, 1.0]
    doc["nodes"][1].pop("matrix", None)


def _no_static(doc):
    for n in doc["nodes"]:
        if n.get("extras", {}).get("role") == "static":
            n["extras"]["role"] = "blocker"


def _missing_buffer(doc):
    doc["buffers"][0]["uri"] = "gone.bin"


@pytest.mark.parametrize(
    "edit, message",
    [
        (_bad_mesh_index, "references mesh 99"),
        (_bad_role, "unknown role 'bush'"),
        (_typo, "unknown key(s) in extras: densty"),
        (_negative_density, "density must be >= 0"),
        (_transmission, "transmission must be in [0, 1]"),
        (_extras_not_object, "extras must be a JSON object"),
        (_zero_scale_node, "zero scale"),
        (_no_static, "no static node"),
        (_missing_buffer, "file not found: gone.bin"),
    ],
)
def test_bad_level_files_are_one_line_errors(tiny, tmp_path, edit, message):
    path = tmp_path / "level.gltf"
    path.write_bytes(tiny.read_bytes())
    (tmp_path / "level.bin").write_bytes(tiny.with_suffix(".bin").read_bytes())
    _edit(path, edit)
    with pytest.raises(NeuralaoError) as e:
        read_level(path)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_zero_scale_instance_and_truncated_buffer(tiny, tmp_path):
    doc = json.loads(tiny.read_text())
    blob = bytearray(tiny.with_suffix(".bin").read_bytes())
    node = next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "grass")
    acc = doc["accessors"][node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["SCALE"]]
    off = doc["bufferViews"][acc["bufferView"]]["byteOffset"] + 12 * 5  # instance 5
    blob[off : off + 12] = np.zeros(3, np.float32).tobytes()
    (tmp_path / "level.bin").write_bytes(bytes(blob))
    (tmp_path / "level.gltf").write_text(json.dumps(doc))
    with pytest.raises(NeuralaoError, match="instance 5 has a zero scale"):
        read_level(tmp_path / "level.gltf")
    (tmp_path / "level.bin").write_bytes(bytes(blob[: len(blob) // 2]))
    with pytest.raises(NeuralaoError, match="buffer 0 has"):
        read_level(tmp_path / "level.gltf")


def test_cli_bad_level_exits_2_with_one_line(tiny, tmp_path):
    path = tmp_path / "level.gltf"
    path.write_bytes(tiny.read_bytes())
    (tmp_path / "level.bin").write_bytes(tiny.with_suffix(".bin").read_bytes())
    _edit(path, _bad_role)
    cfg = tmp_path / "bake.json"
    cfg.write_text("{}")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "neuralao.pipeline.cli",
            "bake",
            str(path),
            "--config",
            str(cfg),
            "--out",
            str(tmp_path / "out"),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("neuralao bake: error:") and "unknown role" in lines[0]
    assert not (tmp_path / "out" / "level_baked.glb").exists()


def test_cli_rejects_single_mesh_flags_and_bad_config_keys(tiny, tmp_path):
    cfg = tmp_path / "bake.json"
    cfg.write_text(json.dumps({"trace": {"rayz": 4}}))
    for extra, msg in (
        (["--rays", "8"], "--rays does not apply to a level"),
        ([], "unknown setting(s) trace.rayz"),
    ):
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "neuralao.pipeline.cli",
                "bake",
                str(tiny),
                "--config",
                str(cfg),
                "--out",
                str(tmp_path / "o"),
                *extra,
            ],
            capture_output=True,
            text=True,
        )
        assert r.returncode == 2 and msg in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_quaternion_round_trip():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0] *= -1
    m = trs_matrices(rng.normal(size=(50, 3)), q, rng.uniform(0.5, 2, (50, 3)), 50)
    t, q2, s = decompose(m)
    np.testing.assert_allclose(q2, q, atol=1e-9)
    assert math.isclose(float(np.abs(trs_matrices(t, q2, s, 50) - m).max()), 0.0, abs_tol=1e-9)
