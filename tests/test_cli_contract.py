"""The command-line contract on inputs that used to get through: non-finite G-buffers, output formats,
counts past what the machine can hold, probe points far from the level, help text defaults, and
messages a command-line user can act on. Each test runs the real command in-process
(:func:`neuralao.pipeline.cli.main.main`) and checks the exit status, the one stderr line and the files left
behind.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from neuralao.pipeline.cli.main import main
from neuralao.runtime.foundation import sh
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import read_npz

TET = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
UNET = "runtime/models/unet-fast/model.onnx"


def refusal(capsys, argv: list[str]) -> str:
    """Run ``neuralao argv``; it must exit 2 with exactly one stderr line, which is returned."""
    try:
        rc = main(argv)
    except SystemExit as e:
        rc = e.code
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip() and "[00:" not in ln]
    assert rc == 2 and len(err) == 1, (rc, err)
    assert err[0].startswith("neuralao") and ": error: " in err[0] and "Traceback" not in err[0]
    return err[0]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("contract")
    (d / "tet.obj").write_text(TET)
    assert (
        main(
            [
                "render",
                str(d / "tet.obj"),
                "--views",
                "1",
                "--size",
                "16",
                "16",
                "--rays",
                "2",
                "--out",
                str(d / "render"),
            ]
        )
        == 0
    )
    return d


# --------------------------------------------------------------------------- 1. non-finite G-buffers


@pytest.mark.parametrize("channel", ["depth", "normal_cam", "position"])
def test_infer_refuses_a_non_finite_gbuffer_channel_by_name(files, tmp_path, capsys, channel):
    frame = read_npz(files / "render" / "view_0000.npz")
    frame[channel] = np.full_like(frame[channel], np.nan)
    np.savez(tmp_path / "nan.npz", **frame)
    out = tmp_path / "ao.png"
    msg = refusal(capsys, ["infer", UNET, str(tmp_path / "nan.npz"), "--out", str(out)])
    assert f"'{channel}'" in msg and "nan.npz" in msg and "non-finite" in msg
    assert not out.exists() and not list(tmp_path.glob(".*tmp*"))  # no black PNG, no temporary


def test_infer_refuses_channels_of_different_shapes(files, tmp_path, capsys):
    frame = read_npz(files / "render" / "view_0000.npz")
    frame["normal_cam"] = frame["normal_cam"][:, :, :2]
    np.savez(tmp_path / "bad.npz", **frame)
    msg = refusal(capsys, ["infer", UNET, str(tmp_path / "bad.npz"), "--out", str(tmp_path / "ao.png")])
    assert "bad.npz" in msg and "'normal_cam'" in msg


def test_render_checks_every_frame_it_writes_is_finite(files):
    # The guard behind the renderer: every float channel of every written frame is finite.
    for k, a in read_npz(files / "render" / "view_0000.npz").items():
        assert a.dtype.kind != "f" or np.isfinite(a).all(), k


def test_meshes_beyond_the_float32_range_are_refused_not_rendered_empty(tmp_path, capsys):
    # At 1e38 the float32 transforms overflowed and render wrote frames with no foreground at all.
    (tmp_path / "huge.obj").write_text(
        re.sub(r"v (\d) (\d) (\d)", lambda m: "v " + " ".join(f"{int(g) * 1e38:g}" for g in m.groups()), TET)
    )
    out = tmp_path / "out"
    msg = refusal(
        capsys,
        [
            "render",
            str(tmp_path / "huge.obj"),
            "--views",
            "1",
            "--size",
            "8",
            "8",
            "--rays",
            "1",
            "--out",
            str(out),
        ],
    )
    assert "huge.obj" in msg and "1e+30" in msg
    assert not (out / "render.json").exists()


# --------------------------------------------------------------------------- 2. output formats


def test_infer_writes_real_float_exr_and_npy(files, tmp_path):
    import OpenEXR

    frame = str(files / "render" / "view_0000.npz")
    assert (
        main(
            ["infer", UNET, frame, "--out", str(tmp_path / "ao.npy"), "--composite", str(tmp_path / "c.exr")]
        )
        == 0
    )
    assert main(["infer", UNET, frame, "--out", str(tmp_path / "ao.exr")]) == 0
    ao = np.load(tmp_path / "ao.npy")
    assert ao.shape == (16, 16) and ao.dtype == np.float32
    with OpenEXR.File(str(tmp_path / "ao.exr")) as f:  # the reference OpenEXR library reads it back
        assert f.header()["compression"] == OpenEXR.NO_COMPRESSION
        y = f.channels()["Y"].pixels
    assert y.dtype == np.float32 and np.array_equal(y, ao)  # the float AO as computed, bit for bit
    with OpenEXR.File(str(tmp_path / "c.exr"), separate_channels=True) as f:
        assert sorted(f.channels()) == ["B", "G", "R"] and f.channels()["R"].pixels.shape == (16, 16)


@pytest.mark.parametrize("name", ["ao.jpg", "ao", "ao.png.bak"])
def test_infer_refuses_unknown_output_formats_with_the_supported_ones(files, tmp_path, capsys, name):
    out = tmp_path / name
    msg = refusal(capsys, ["infer", UNET, str(files / "render" / "view_0000.npz"), "--out", str(out)])
    assert "--out" in msg and ".png" in msg and ".npy" in msg and ".exr" in msg
    assert not out.exists()


# --------------------------------------------------------------------------- 3. counts past the machine


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["bake", "@tet.obj", "--rays", "1000000000000", "--out", "@o.ply"], "--rays"),
        (
            ["bake", "@tet.obj", "--rays", "2", "--samples-per-vertex", "1e15", "--out", "@o.ply"],
            "--samples-per-vertex",
        ),
        (["bake", "@tet.obj", "--rays", "2", "--workers", "1000000000", "--out", "@o.ply"], "--workers"),
        (
            [
                "bake",
                "@tet.obj",
                "--rays",
                "2",
                "--samples-per-face-cap",
                "99999999999999999999",
                "--out",
                "@o.ply",
            ],
            "--samples-per-face-cap",
        ),
        (
            [
                "render",
                "@tet.obj",
                "--views",
                "1000000000000",
                "--size",
                "8",
                "8",
                "--rays",
                "1",
                "--out",
                "@r",
            ],
            "--views",
        ),
        (
            [
                "render",
                "@tet.obj",
                "--views",
                "1",
                "--size",
                "8",
                "8",
                "--rays",
                "9223372036854775808",
                "--out",
                "@r",
            ],
            "--rays",
        ),
        (["render", "@tet.obj", "--views", "1", "--size", "8", "8", "--seed", "-1", "--out", "@r"], "--seed"),
        (["volumes", "@tet.obj", "--set", "grid=1000000", "--out", "@v.json"], "grid"),
        (["volumes", "@tet.obj", "--set", "samples=100000", "--out", "@v.json"], "samples"),
        (["volumes", "@tet.obj", "--set", "directions=1000000000000", "--out", "@v.json"], "directions"),
        (
            ["train", "field", "--mesh", "@tet.obj", "--set", "samples=1000000000000000", "--out", "@f.pt"],
            "samples",
        ),
        (["train", "field", "--mesh", "@tet.obj", "--set", "batch=1000000000000", "--out", "@f.pt"], "batch"),
        (
            [
                "train",
                "field",
                "--mesh",
                "@tet.obj",
                "--set",
                "steps=2147483648",
                "--set",
                "check_every=1",
                "--out",
                "@f.pt",
            ],
            "steps",
        ),
        (["volumes", "@tet.obj", "--set", "iterations=1000000000000", "--out", "@v.json"], "iterations"),
        (["train", "mlp", "--mesh", "@tet.obj", "--views", "1000000000000", "--out", "@m.pt"], "views"),
        (["train", "mlp", "--mesh", "@tet.obj", "--resolution", "8", "100000", "--out", "@m.pt"], "size"),
        (
            ["train", "field", "--mesh", "@tet.obj", "--set", "holdout_views=100000000", "--out", "@f.pt"],
            "holdout_size",
        ),
        (["dataset", "@big.json", "--out", "@d"], "views"),
        (["dataset", "@data.json", "--set", "size=[8,100000]", "--out", "@d"], "size"),
        (["dataset", "@data.json", "--set", "scenes.0.views=1000000000000", "--out", "@d"], "views"),
    ],
)
def test_counts_past_what_the_machine_holds_are_refused_before_allocation(tmp_path, capsys, argv, flag):
    (tmp_path / "tet.obj").write_text(TET)
    scene = {
        "name": "tet",
        "mesh": str(tmp_path / "tet.obj"),
        "cameras": "orbit",
        "views": 1,
        "split": "train",
    }
    config = {"size": [8, 8], "labels": {"rays": 2}, "scenes": [scene]}
    (tmp_path / "data.json").write_text(json.dumps(config))
    (tmp_path / "big.json").write_text(json.dumps({**config, "scenes": [{**scene, "views": 10**15}]}))
    argv = [str(tmp_path / a[1:]) if a.startswith("@") else a for a in argv]
    msg = refusal(capsys, argv)
    assert flag in msg, msg
    if "--seed" not in flag:
        assert re.search(r"at most \d+|in \[\d+, \d+\]|between 1 and \d+", msg), msg  # the bound is stated
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "big.json",
        "data.json",
        "tet.obj",
    ]  # nothing written


def test_set_overrides_reach_into_lists_by_index_and_refuse_bad_indices(tmp_path, capsys):
    (tmp_path / "tet.obj").write_text(TET)
    scene = {
        "name": "tet",
        "mesh": str(tmp_path / "tet.obj"),
        "cameras": "orbit",
        "views": 1,
        "split": "train",
    }
    (tmp_path / "d.json").write_text(json.dumps({"size": [8, 8], "labels": {"rays": 1}, "scenes": [scene]}))
    out = tmp_path / "out"
    argv = ["dataset", str(tmp_path / "d.json"), "--no-progress", "--out", str(out), "--set"]
    assert main([*argv, "scenes.0.views=2"]) == 0
    assert json.loads((out / "manifest.json").read_text())["frames"] == 2
    assert "scenes.3.views" in refusal(capsys, [*argv, "scenes.3.views=2"])


def test_usage_errors_and_a_missing_command_are_one_line(capsys):
    assert "--rays" in refusal(capsys, ["bake", "spot", "--rays", "1e12", "--out", "x.ply"])
    assert "no command" in refusal(capsys, [])


# --------------------------------------------------------------------------- 4. probe far away


def _two_regions(slope: float = 0.0):
    """Boxes x in [-1, 0] and [0.5, 1.5] with constant AO 0.2 and 0.9 (``slope``: d AO / dx on the right)."""
    from neuralao.runtime.volumes import Edge, Region, RegionModel, Volumes, VolumeSettings

    regions = [Region("left", (-1, -1, -1), (0, 1, 1)), Region("right", (0.5, -1, -1), (1.5, 1, 1))]
    y0 = sh.basis(np.eye(3)[:1], 1)[0, 0]
    models = []
    for value, centre in ((0.2, (-0.5, 0, 0)), (0.9, (1.0, 0, 0))):
        c = np.zeros((7, 2, 9))
        c[0, :, 0] = value / y0
        c[1, :, 0] = slope / y0 if value == 0.9 else 0.0
        models.append(RegionModel(np.array(centre, float), c))
    return Volumes(regions, [Edge(0, 1, 4.0, (0.25, 0.0, 0.0))], models, (1.0, 1.0), 0.97, VolumeSettings())


@pytest.mark.parametrize("distance", [1e3, 1e6, 1e15, 1e30, 1e150, 1e300])
def test_probe_far_from_the_level_uses_the_nearest_region(distance):
    from neuralao.runtime.probe import VolumeProbe

    probe = VolumeProbe(_two_regions())
    p = np.array([[distance, 0.3, 0.1], [-distance, 0.2, 0.0]])
    n = np.array([[0.0, 0.0, 1.0]] * 2)
    # Far along +x the right box is nearer, along -x the left one, at every distance: squared distances
    # of 1e60 and more tied (or overflowed) and the first box won.
    assert probe.region_of(p).tolist() == [1, 0]
    assert np.allclose(probe.ao(p, n), [0.9, 0.2], atol=1e-6)


def test_probe_refuses_points_where_the_model_overflows(tmp_path, capsys):
    from neuralao.runtime.foundation.io import write_json
    from neuralao.runtime.probe import VolumeProbe
    from neuralao.runtime.volumes import to_json

    # The runtime (an engine's own points, float64): the point whose model overflows is named.
    with pytest.raises(NeuralaoError, match=r"point 1 .*'right'"):
        VolumeProbe(_two_regions(slope=3.0)).ao(np.array([[1.0, 0, 0], [1.7e308, 0, 0]]), np.eye(3)[[2, 2]])
    # The command: points past float32 (the models' precision) are refused before any model is evaluated.
    write_json(tmp_path / "v.json", to_json(_two_regions(slope=3.0)))
    np.save(tmp_path / "p.npy", np.array([[1.0, 0, 0], [1.7e308, 0, 0]]))
    np.save(tmp_path / "n.npy", np.array([[0, 0, 1.0]] * 2))
    out = tmp_path / "ao.npy"
    msg = refusal(
        capsys,
        [
            "probe",
            str(tmp_path / "v.json"),
            "--points",
            str(tmp_path / "p.npy"),
            "--normals",
            str(tmp_path / "n.npy"),
            "--out",
            str(out),
        ],
    )
    assert "--points" in msg and "1 row(s)" in msg and "float32" in msg and not out.exists()


# --------------------------------------------------------------------------- 5. help defaults


@pytest.mark.parametrize("model", ["field", "mlp"])
def test_train_help_states_the_real_defaults(capsys, model):
    from neuralao.pipeline.models.field import FieldSettings
    from neuralao.pipeline.models.mlp import MLPSettings, size_name

    with pytest.raises(SystemExit):
        main(["train", model, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    d = FieldSettings() if model == "field" else MLPSettings()
    assert f"(default {size_name(d.hidden)})" in text and f"(default {d.labels.rays})" in text
    if model == "field":
        assert f"frequency bands (default {d.octaves})" in text
    else:
        assert f"(default {d.views})" in text and f"(default {d.size[0]} {d.size[1]})" in text


# --------------------------------------------------------------------------- 6. messages


def _gltf(uri: str, nodes: list[dict]) -> dict:
    import base64

    buf = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32).tobytes()
    buf += np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], np.uint16).tobytes()
    uri = uri or "data:application/octet-stream;base64," + base64.b64encode(buf).decode()
    return {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": 4,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1, 1],
            },
            {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"},
        ],
        "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 24}],
        "buffers": [{"uri": uri, "byteLength": 72}],
    }


def test_a_gltf_reaching_outside_its_folder_gets_advice_a_cli_user_can_follow(tmp_path, capsys):
    (tmp_path / "secret.bin").write_bytes(bytes(72))
    (tmp_path / "level").mkdir()
    gltf = tmp_path / "level" / "scene.gltf"
    gltf.write_text(json.dumps(_gltf("../secret.bin", [{"mesh": 0}])))
    for argv in (
        ["render", str(gltf), "--views", "1", "--size", "8", "8", "--out", str(tmp_path / "r")],
        ["bake", str(gltf), "--rays", "1", "--out", str(tmp_path / "b.glb")],  # the glTF scene reader
        ["volumes", str(gltf), "--out", str(tmp_path / "v.json")],
    ):
        msg = refusal(capsys, argv)
        assert "'../secret.bin'" in msg and "outside its folder" in msg and "FilePathResolver" not in msg, msg
    assert sorted(p.name for p in tmp_path.iterdir()) == ["level", "secret.bin"]


def test_unnamed_gltf_nodes_are_named_one_way_in_every_message(tmp_path, capsys):
    nodes = [
        {"mesh": 0, "extras": {"role": "static"}},
        {"mesh": 0, "extras": {"role": "bogus"}},
        {"mesh": 0, "name": "Chair", "scale": [1e31, 1e31, 1e31]},  # past the coordinates' range
    ]
    (tmp_path / "level.gltf").write_text(json.dumps(_gltf("", nodes)))
    level = refusal(capsys, ["volumes", str(tmp_path / "level.gltf"), "--out", str(tmp_path / "v.json")])
    assert "node 1 (unnamed)" in level, level  # was "node 1 ('node1')"
    nodes[1] = {"mesh": 0, "scale": [1e31, 1e31, 1e31]}
    (tmp_path / "scene.gltf").write_text(json.dumps(_gltf("", nodes)))
    scene = refusal(
        capsys, ["bake", str(tmp_path / "scene.gltf"), "--rays", "1", "--out", str(tmp_path / "b.glb")]
    )
    assert "node 1 (unnamed)" in scene, scene  # was "node 1 ('')"
    nodes[1] = {"mesh": 0}
    (tmp_path / "scene.gltf").write_text(json.dumps(_gltf("", nodes)))
    named = refusal(
        capsys, ["bake", str(tmp_path / "scene.gltf"), "--rays", "1", "--out", str(tmp_path / "b.glb")]
    )
    assert "node 2 'Chair'" in named, named


@pytest.mark.parametrize("content", [b"", "no meshes"])
def test_view_of_a_bake_without_geometry_says_so(tmp_path, capsys, content):
    from neuralao.pipeline.geometry.level_files import GltfWriter

    path = tmp_path / "empty.glb"
    if content:
        w = GltfWriter()
        w.node("n", None)
        w.write(path)
    else:
        path.write_bytes(content)
    msg = refusal(capsys, ["view", str(path), "--out", str(tmp_path / "page")])
    assert "empty.glb" in msg and "no geometry" in msg and "IndexError" not in msg


def test_texture_bake_of_a_mesh_at_float32_limits_finishes(tmp_path):
    # xatlas (float32) never returned on a mesh whose face normals overflow; the atlas is now computed
    # on the mesh scaled to a unit box. A subprocess, so a regression fails on the timeout, not hangs.
    big = re.sub(
        r"v (\d) (\d) (\d)", lambda m: "v " + " ".join(f"{int(g) * 1e25:g}" for g in m.groups()), TET
    )
    (tmp_path / "big.obj").write_text(big)
    cmd = [
        sys.executable,
        "-m",
        "neuralao.pipeline.cli",
        "bake",
        str(tmp_path / "big.obj"),
        "--to",
        "texture",
        "--uv",
        "xatlas",
        "--resolution",
        "16",
        "--rays",
        "1",
        "--out",
        str(tmp_path / "t.glb"),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-500:]
    assert (tmp_path / "t.glb").stat().st_size > 0


def test_fuzz_findings_are_one_line_refusals(tmp_path, capsys):
    # Found by make fuzz: a negative parity seed reached numpy (ValueError traceback); a huge --octaves
    # was reported as an impossible batch.
    from onnx import TensorProto
    from onnx import helper as oh

    x = oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4, "h", "w"])
    y = oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4, "h", "w"])
    graph = oh.make_graph([oh.make_node("Relu", ["x"], ["y"], name="relu")], "g", [x], [y])
    (tmp_path / "relu.onnx").write_bytes(
        oh.make_model(graph, opset_imports=[oh.make_opsetid("", 19)]).SerializeToString()
    )
    assert (
        main(["glsl", str(tmp_path / "relu.onnx"), "--target", "image", "--out", str(tmp_path / "export")])
        == 0
    )
    assert "--seed" in refusal(capsys, ["parity", str(tmp_path / "export"), "--seed", "-1"])
    (tmp_path / "tet.obj").write_text(TET)
    msg = refusal(
        capsys,
        [
            "train",
            "field",
            "--mesh",
            str(tmp_path / "tet.obj"),
            "--octaves",
            "1000000000000",
            "--out",
            str(tmp_path / "f.pt"),
        ],
    )
    assert "octaves" in msg and "batch" not in msg
