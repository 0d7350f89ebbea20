"""What each command does with the inputs and outputs users hand it: one validated reader per input kind
(glTF by the specification's rules, camera files, configs, volume and regions files, arrays), generator
parameters bounded before allocation, outputs checked before any work and written with the umask's
permissions, export folders replaced whole, Ctrl-C and SIGTERM ending in one line. Every command runs for
real, in-process with Python warnings turned into errors (a warning would reach a user's stderr), or as a
process where a signal is sent to it.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import with_changes

from neuralao.pipeline.cli.main import main
from neuralao.runtime.foundation.io import read_npz

TET = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
ROOT = Path(__file__).resolve().parents[1]
NEURALAO = [str(Path(sys.executable).with_name("neuralao"))]  # the command as users run it


def run(capsys, argv: list[str]) -> tuple[int, list[str]]:
    """``neuralao argv`` in-process with every Python warning an error; (exit status, stderr lines)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        try:
            rc = main(argv)
        except SystemExit as e:
            rc = e.code
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip() and "[00:" not in ln]
    return rc, [ln for ln in err if not ln.startswith(("INFO ", "WARNING "))]


def refusal(capsys, argv: list[str]) -> str:
    """The one stderr line of a refusal (exit 2, no traceback)."""
    rc, err = run(capsys, argv)
    assert rc == 2 and len(err) == 1, (rc, err)
    assert err[0].startswith("neuralao") and ": error: " in err[0]
    return err[0]


def temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".*") if ".tmp" in p.name]


def tet_gltf(**changes) -> dict:
    """A tetrahedron as glTF (positions and uint16 indices in one data-URI buffer)."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    idx = np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], np.uint16)
    blob = pos.tobytes() + idx.tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": 4,
                "type": "VEC3",
                "min": [0] * 3,
                "max": [1] * 3,
            },
            {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"},
        ],
        "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 24}],
        "buffers": [{"uri": "data:;base64," + base64.b64encode(blob).decode(), "byteLength": len(blob)}],
    }
    return with_changes(doc, changes)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    (d / "tet.obj").write_text(TET)
    (d / "tet.gltf").write_text(json.dumps(tet_gltf()))
    argv = ["render", str(d / "tet.obj"), "--views", "1", "--size", "16", "16", "--rays", "2"]
    assert main([*argv, "--out", str(d / "render")]) == 0
    sets = ["samples=2", "directions=16", "grid=2", "cell_rays=4"]
    assert (
        main(
            [
                "volumes",
                str(d / "tet.obj"),
                *(a for s in sets for a in ("--set", s)),
                "--out",
                str(d / "vol.json"),
            ]
        )
        == 0
    )
    rng = np.random.default_rng(0)
    np.save(d / "p.npy", rng.uniform(0, 1, (6, 3)))
    np.save(d / "n.npy", rng.normal(size=(6, 3)))
    level = [
        "buildings=[]",
        "terrain_cells=3",
        "crown_subdivisions=0",
        "houses=1",
        "trees=1",
        "shrubs=2",
        "grass=2",
    ]
    assert main(["level", *(a for s in level for a in ("--set", s)), "--out", str(d / "level")]) == 0
    fast = {
        "trace": {"rays": 4, "samples_per_vertex": 1.0, "samples_per_face_cap": 2},
        "decorators": {"samples_per_instance": 16, "holdout_samples": 16, "local_rays": 4},
        "grass": {"rays": 4},
        "lod": {"enabled": False},
    }
    (d / "level" / "fast.json").write_text(json.dumps(fast))
    return d


# --------------------------------------------------------------------------- glTF: the specification's rules

GLTF_BREAKS = [
    ({"accessors.0.count": -3}, "accessors[0].count"),
    ({"bufferViews.0.byteStride": 4}, "byteStride"),
    ({"bufferViews.1.byteOffset": 1 << 40}, "bufferViews[1]"),
    ({"accessors.1.byteOffset": 1}, "accessors[1].byteOffset"),
    ({"accessors.0.count": 400}, "accessors[0]"),
    ({"extensionsRequired": ["KHR_not_implemented"]}, "KHR_not_implemented"),
    ({"accessors.0.componentType": 5130}, "componentType"),
    ({"meshes.0.primitives.0.indices": 9}, "indices"),
]


@pytest.mark.parametrize("command", ["bake", "render"])
@pytest.mark.parametrize("changes,key", GLTF_BREAKS)
def test_every_reader_refuses_a_gltf_that_breaks_the_specification(
    files, tmp_path, capsys, command, changes, key
):
    # bake reads the scene itself, render through trimesh: both check the same rules first
    (tmp_path / "bad.gltf").write_text(json.dumps(tet_gltf(**changes)))
    out = tmp_path / ("out.glb" if command == "bake" else "out")
    tail = ["--rays", "2"] if command == "bake" else ["--views", "1", "--size", "8", "8", "--rays", "1"]
    msg = refusal(capsys, [command, str(tmp_path / "bad.gltf"), *tail, "--out", str(out)])
    assert "bad.gltf" in msg and key in msg
    assert not out.exists()


def test_a_valid_gltf_still_bakes_and_renders(files, tmp_path, capsys):
    assert (
        run(capsys, ["bake", str(files / "tet.gltf"), "--rays", "2", "--out", str(tmp_path / "b.glb")])[0]
        == 0
    )
    argv = ["render", str(files / "tet.gltf"), "--views", "1", "--size", "8", "8", "--rays", "1"]
    assert run(capsys, [*argv, "--out", str(tmp_path / "r")])[0] == 0


def test_json_nested_past_the_parser_is_one_line_everywhere(files, tmp_path, capsys):
    deep = "[" * 100_000 + "]" * 100_000
    (tmp_path / "deep.gltf").write_text(json.dumps(tet_gltf(extras="@")).replace('"@"', deep))
    (tmp_path / "deep.json").write_text('{"trace": ' + deep + "}")
    p, n = str(files / "p.npy"), str(files / "n.npy")
    cases = [
        ["bake", str(tmp_path / "deep.gltf"), "--out", str(tmp_path / "o.glb")],
        [
            "bake",
            str(files / "level" / "level.gltf"),
            "--config",
            str(tmp_path / "deep.json"),
            "--out",
            str(tmp_path / "lb"),
        ],
        [
            "probe",
            str(tmp_path / "deep.json"),
            "--points",
            p,
            "--normals",
            n,
            "--out",
            str(tmp_path / "a.npy"),
        ],
        [
            "volumes",
            str(files / "tet.obj"),
            "--regions",
            str(tmp_path / "deep.json"),
            "--out",
            str(tmp_path / "v.json"),
        ],
        [
            "render",
            str(files / "tet.obj"),
            "--cameras",
            str(tmp_path / "deep.json"),
            "--out",
            str(tmp_path / "r"),
        ],
        ["level", "--set", "houses=" + deep, "--out", str(tmp_path / "l")],
    ]
    for argv in cases:
        msg = refusal(capsys, argv)
        assert "nests deeper than 64 levels" in msg, msg


def test_a_level_node_of_zero_instances_is_named(files, tmp_path, capsys):
    doc = json.loads((files / "level" / "level.gltf").read_text())
    tree = next(n for n in doc["nodes"] if n.get("extras", {}).get("role") == "tree")
    for a in tree["extensions"]["EXT_mesh_gpu_instancing"]["attributes"].values():
        doc["accessors"][a]["count"] = 0
    (tmp_path / "level.bin").write_bytes((files / "level" / "level.bin").read_bytes())
    (tmp_path / "zero.gltf").write_text(json.dumps(doc))
    config = str(files / "level" / "fast.json")
    msg = refusal(
        capsys, ["bake", str(tmp_path / "zero.gltf"), "--config", config, "--out", str(tmp_path / "o")]
    )
    assert "'trees'" in msg and "0 instances" in msg and not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- configs, settings, generators


def test_a_config_that_is_not_utf8_or_holds_nan_is_refused_before_any_work(files, tmp_path, capsys):
    level, out = str(files / "level" / "level.gltf"), tmp_path / "out"
    (tmp_path / "latin1.json").write_bytes('{"output": "caf\xe9.glb"}'.encode("latin-1"))
    msg = refusal(capsys, ["bake", level, "--config", str(tmp_path / "latin1.json"), "--out", str(out)])
    assert "latin1.json" in msg and "not UTF-8" in msg
    (tmp_path / "nan.json").write_text('{"trace": {"alpha": NaN}}')
    msg = refusal(capsys, ["bake", level, "--config", str(tmp_path / "nan.json"), "--out", str(out)])
    assert "nan.json" in msg and "'trace.alpha'" in msg
    config = str(files / "level" / "fast.json")
    for bad in ("trace.alpha=NaN", "decorators.local_samples_per_vertex=0", "lod.radius=-1", "seed=-1"):
        msg = refusal(capsys, ["bake", level, "--config", config, "--set", bad, "--out", str(out)])
        assert bad.split("=")[0] in msg
    assert not out.exists()  # nothing traced, no folder made


@pytest.mark.parametrize(
    "setting,words",
    [
        ("terrain_cells=1000000", "at most"),
        ("houses=1000000000", "at most"),
        ("house_boxes=100000000", "at most"),
        ("grass=100000000000", "at most"),
        ("crown_subdivisions=40", "[0, 10]"),
        ("terrain_size=1e300", "float32"),
        ("tree_transmission=2", "[0, 1]"),
    ],
)
def test_generator_parameters_are_bounded_before_allocation(tmp_path, capsys, setting, words):
    t0 = time.perf_counter()
    msg = refusal(capsys, ["level", "--set", setting, "--out", str(tmp_path / "l")])
    assert setting.split("=")[0] in msg and words in msg
    assert time.perf_counter() - t0 < 5 and not (tmp_path / "l").exists()  # refused, not attempted


def test_float_flags_past_float32_are_refused_naming_the_flag(files, tmp_path, capsys):
    for value in ("1e300", "nan", "-inf", "1e-300"):
        argv = ["bake", str(files / "tet.obj"), "--max-distance", value, "--out", str(tmp_path / "b.ply")]
        assert "--max-distance" in refusal(capsys, argv)
    # a distance float32 holds as 0 (or without its digits) is no distance: refused, not a bake of AO 1
    obscurance = ["--kernel", "obscurance", "--half-distance", "1e-40"]
    msg = refusal(capsys, ["bake", str(files / "tet.obj"), *obscurance, "--out", str(tmp_path / "b.ply")])
    assert "--half-distance" in msg and "too small" in msg and not (tmp_path / "b.ply").exists()
    msg = refusal(
        capsys, ["volumes", str(files / "tet.obj"), "--set", "beta=1e39", "--out", str(tmp_path / "v.json")]
    )
    assert "'beta'" in msg and "float32" in msg


# --------------------------------------------------------------------------- camera files


@pytest.mark.parametrize(
    "camera,words",
    [
        ({"eye": [2, 1.5, 2], "target": [0.3, 0.3, 0.3], "fov": 50}, "unknown key 'fov'"),
        ({"pose": [[2, 0, 0, 2], [0, 2, 0, 2], [0, 0, 2, 3], [0, 0, 0, 1]]}, "must be rigid"),
        ({"pose": [[1, 0.5, 0, 2], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]}, "must be rigid"),
        ({"pose": [[1, 0, 0, 2], [0, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]}, "singular"),
        ({"eye": [1, 1, 1], "target": [1, 1, 1]}, "same point"),
        ({"eye": [2, 1, 2], "target": [0, 0, 0], "yfov_deg": 180}, "'yfov_deg'"),
        ({"eye": [2, 1, 2], "target": [0, 0, 0], "znear": 5, "zfar": 1}, "znear"),
        ({"eye": [2, 1e300, 2], "target": [0, 0, 0]}, "'eye'"),
        ({"eye": [2, 1, "2"], "target": [0, 0, 0]}, "'eye'"),  # numpy would read the string as 2
        ({"eye": [2, 1, 2], "target": [0, 0, True]}, "'target'"),  # and true as 1
        ({"eye": [2, 1, 2], "target": [0, 0, 0], "yfov_deg": 1e-5}, "'yfov_deg'"),
    ],
)
def test_camera_files_are_checked_key_by_key(files, tmp_path, capsys, camera, words):
    (tmp_path / "cams.json").write_text(json.dumps({"cameras": [camera]}))
    argv = ["render", str(files / "tet.obj"), "--cameras", str(tmp_path / "cams.json"), "--size", "8", "8"]
    msg = refusal(capsys, [*argv, "--rays", "1", "--out", str(tmp_path / "r")])
    assert "cams.json" in msg and "camera 0" in msg and words in msg


@pytest.mark.parametrize("flag,value", [("--yfov", "178"), ("--yfov", "1e-5"), ("--yfov-rad", "3.1")])
def test_a_field_of_view_no_pinhole_camera_has_is_refused(files, tmp_path, capsys, flag, value):
    # 178 degrees leaves a fitted object no pixel, 1e-5 puts the camera where float32 depth cannot resolve it
    argv = ["render", str(files / "tet.obj"), "--views", "1", "--size", "8", "8", "--rays", "1", flag, value]
    msg = refusal(capsys, [*argv, "--out", str(tmp_path / "r")])
    assert flag in msg and "must be within" in msg and not (tmp_path / "r").exists()


def test_a_mesh_smaller_than_float32_positions_resolve_is_refused(tmp_path, capsys):
    (tmp_path / "small.obj").write_text(
        "".join(f"v {x * 1e-35} {y * 1e-35} {z * 1e-35}\n" for x, y, z in [(0, 0, 0), (1, 0, 0), (0, 1, 0)])
        + "f 1 2 3\n"
    )
    msg = refusal(capsys, ["bake", str(tmp_path / "small.obj"), "--out", str(tmp_path / "b.ply")])
    assert "small.obj" in msg and "spans" in msg and not (tmp_path / "b.ply").exists()


def test_flags_that_do_not_apply_are_refused_not_ignored(files, tmp_path, capsys):
    bake = ["bake", str(files / "tet.obj"), "--method", "vertex", "--rays", "2"]
    assert "--alpha" in refusal(capsys, [*bake, "--alpha", "5", "--out", str(tmp_path / "b.ply")])
    assert main([*bake, "--out", str(tmp_path / "b.ply")]) == 0
    view = ["view", str(tmp_path / "b.ply"), "--out", str(tmp_path / "v")]
    assert "--screen-space-radius" in refusal(capsys, [*view, "--screen-space-radius", "0.1"])
    assert "--mesh" in refusal(capsys, [*view, "--mesh", str(files / "tet.obj")])
    assert not (tmp_path / "v").exists()


def test_a_full_disk_is_one_line_naming_the_file_and_leaves_no_output(files, tmp_path):
    """The kernel refuses the write (a file-size limit: EFBIG, as a full disk's ENOSPC would) on the second
    of a texture bake's two files: one line naming it, exit 2, and neither file left."""
    import resource

    argv = [*NEURALAO, "bake", str(files / "tet.obj"), "--to", "texture", "--resolution", "64", "--rays", "2"]
    assert subprocess.run([*argv, "--out", str(tmp_path / "ok.glb")], capture_output=True).returncode == 0
    png, glb = (tmp_path / "ok.ao.png").stat().st_size, (tmp_path / "ok.glb").stat().st_size
    assert png < glb

    def limit() -> None:  # Python ignores SIGXFSZ, so the write fails with EFBIG instead of killing it
        resource.setrlimit(resource.RLIMIT_FSIZE, ((png + glb) // 2, resource.RLIM_INFINITY))

    out = tmp_path / "full" / "t.glb"
    proc = subprocess.run([*argv, "--out", str(out)], capture_output=True, text=True, preexec_fn=limit)
    err = [ln for ln in proc.stderr.replace("\r", "\n").splitlines() if ln.strip() and "%|" not in ln]
    err = [ln for ln in err if not ln.startswith(("INFO ", "WARNING "))]
    assert proc.returncode == 2 and len(err) == 1 and str(out) in err[0], (proc.returncode, err)
    assert sorted(p.name for p in out.parent.iterdir()) == []  # neither file, no temporary


def test_a_rigid_pose_typed_to_six_digits_is_accepted(files, tmp_path, capsys):
    c, s = round(np.cos(0.3), 6), round(np.sin(0.3), 6)
    pose = [[c, 0, s, 2.0], [0, 1, 0, 0.5], [-s, 0, c, 3.0], [0, 0, 0, 1]]
    (tmp_path / "cams.json").write_text(json.dumps([{"pose": pose}]))
    argv = ["render", str(files / "tet.obj"), "--cameras", str(tmp_path / "cams.json"), "--size", "8", "8"]
    assert run(capsys, [*argv, "--rays", "1", "--out", str(tmp_path / "r")])[0] == 0


# --------------------------------------------------------------------------- arrays and frames


def test_probe_refuses_complex_and_non_finite_arrays_by_flag(files, tmp_path, capsys):
    n = np.load(files / "n.npy")
    np.save(tmp_path / "nan_n.npy", np.where(np.arange(6)[:, None] == 2, np.nan, n))
    np.save(tmp_path / "cplx_p.npy", np.load(files / "p.npy") + 0j)
    base = ["probe", str(files / "vol.json"), "--out", str(tmp_path / "ao.npy")]
    msg = refusal(capsys, [*base, "--points", str(files / "p.npy"), "--normals", str(tmp_path / "nan_n.npy")])
    assert "--normals" in msg and "NaN" in msg
    msg = refusal(
        capsys, [*base, "--points", str(tmp_path / "cplx_p.npy"), "--normals", str(files / "n.npy")]
    )
    assert "cplx_p.npy" in msg and "complex128" in msg
    np.save(tmp_path / "long_n.npy", n * 1e20)  # long normals are only directions: normalised, finite AO
    assert (
        run(capsys, [*base, "--points", str(files / "p.npy"), "--normals", str(tmp_path / "long_n.npy")])[0]
        == 0
    )
    assert np.isfinite(np.load(tmp_path / "ao.npy")).all()


def _npz_with_member(path: Path, arrays: dict, key: str, shape: tuple[int, ...]) -> None:
    """``arrays`` and a member ``key`` whose header declares ``shape`` of float64 but stores a few bytes."""
    import io
    import struct
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for k, v in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, v)
            zf.writestr(f"{k}.npy", buf.getvalue())
        header = f"{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}"
        header += " " * (-(len(header) + 11) % 64) + "\n"
        zf.writestr(
            f"{key}.npy", b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + bytes(64)
        )


def test_frames_blame_the_input_not_the_model(files, tmp_path, capsys):
    frame = read_npz(files / "render" / "view_0000.npz")
    np.savez(tmp_path / "long.npz", **{**frame, "normal_cam": frame["normal_cam"] * np.float32(1e20)})
    msg = refusal(capsys, ["infer", str(tmp_path / "long.npz"), "--out", str(tmp_path / "ao.png")])
    assert "'normal_cam'" in msg and "long.npz" in msg and "model" not in msg
    # a member nothing reads is never inflated; one that is read and cannot fit is named as such
    _npz_with_member(tmp_path / "extra.npz", frame, "albedo", (1 << 40,))
    assert run(capsys, ["infer", str(tmp_path / "extra.npz"), "--out", str(tmp_path / "ao.png")])[0] == 0
    _npz_with_member(
        tmp_path / "big.npz", {k: v for k, v in frame.items() if k != "depth"}, "depth", (1 << 20,) * 2
    )
    msg = refusal(capsys, ["infer", str(tmp_path / "big.npz"), "--out", str(tmp_path / "ao2.png")])
    assert "'depth'" in msg and "memory available" in msg and "corrupt" not in msg


# --------------------------------------------------------------------------- volume and regions files


def test_volume_and_regions_files_refuse_unknown_keys(files, tmp_path, capsys):
    vol = json.loads((files / "vol.json").read_text())
    (tmp_path / "typo.json").write_text(json.dumps({**vol, "blnd": 0.5}))
    base = [
        "--points",
        str(files / "p.npy"),
        "--normals",
        str(files / "n.npy"),
        "--out",
        str(tmp_path / "a.npy"),
    ]
    assert "unknown key 'blnd'" in refusal(capsys, ["probe", str(tmp_path / "typo.json"), *base])
    (tmp_path / "latin1.json").write_bytes(
        json.dumps({**vol, "scene": {"name": "caf\xe9"}}, ensure_ascii=False).encode("latin-1")
    )
    assert "not UTF-8" in refusal(capsys, ["probe", str(tmp_path / "latin1.json"), *base])
    (tmp_path / "regions.json").write_text(json.dumps({"regions": [{"min": [0, 0, 0], "mx": [1, 1, 1]}]}))
    argv = [
        "volumes",
        str(files / "tet.obj"),
        "--regions",
        str(tmp_path / "regions.json"),
        "--out",
        str(tmp_path / "v.json"),
    ]
    assert "'mx'" in refusal(capsys, argv)


# --------------------------------------------------------------------------- outputs


def test_outputs_that_cannot_be_written_are_refused_before_any_work(files, tmp_path, capsys):
    bake = ["bake", str(files / "tet.obj"), "--rays", "2", "--out"]
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "a_folder.ply").mkdir()
    for out, words in (
        (tmp_path / "a_file" / "b.ply", "which is a file"),
        (Path("/proc/neuralao-test/b.ply"), "cannot create files"),
        (tmp_path / "a_folder.ply", "is a folder"),
        (files / "tet.obj", "also an input"),
        (tmp_path / ("x" * 300 + ".ply"), "more than the 255"),
    ):
        msg = refusal(capsys, [*bake, str(out)])
        assert "--out" in msg and words in msg, msg
    assert (files / "tet.obj").read_text() == TET
    msg = refusal(capsys, ["render", str(files / "tet.obj"), "--out", str(tmp_path / "a_file")])
    assert "a folder is wanted" in msg
    msg = refusal(capsys, ["render", str(tmp_path / ("m" * 300 + ".obj")), "--out", str(tmp_path / "r")])
    assert msg.startswith("neuralao render: error: MESH") and "more than the 255" in msg
    frame = str(files / "render" / "view_0000.npz")
    same = str(tmp_path / "x.png")
    msg = refusal(capsys, ["infer", frame, "--out", same, "--composite", same])
    assert "--out and --composite" in msg and not Path(same).exists()


def _gltf_with_files_beside(folder: Path, buffer: str, image: str) -> dict[Path, bytes]:
    """A tetrahedron glTF in ``folder`` whose buffer and image are the files ``buffer`` and ``image`` beside
    it (named by percent-encoded uris, as the specification has them); its files -> their bytes."""
    import urllib.parse

    folder.mkdir(parents=True, exist_ok=True)
    blob = base64.b64decode(tet_gltf()["buffers"][0]["uri"].split(",", 1)[1])
    doc = tet_gltf(**{"buffers.0.uri": urllib.parse.quote(buffer)})
    doc["images"] = [{"uri": urllib.parse.quote(image)}]
    (folder / "scene.gltf").write_text(json.dumps(doc))
    (folder / buffer).write_bytes(blob)
    (folder / image).write_bytes(b"\x89PNG not decoded by a bake")
    return {p: p.read_bytes() for p in folder.iterdir()}


# Settings that keep a run short where a command is not refused (as before these refusals).
_QUICK_MLP = [
    "train",
    "mlp",
    "--views",
    "1",
    "--resolution",
    "8",
    "8",
    "--rays",
    "2",
    "--set",
    "max_iterations=1",
]
_QUICK_VOLUMES = [
    "volumes",
    *(a for s in ("samples=2", "directions=16", "grid=2", "cell_rays=4") for a in ("--set", s)),
]
# (command before the mesh, the mesh as given: a file, a glTF folder or a bare name, what --out hits, words)
BESIDE_GLTF = [
    (["bake", "--rays", "2"], "scene.gltf", "geometry.glb", "buffer 0 of MESH"),
    (["bake", "--to", "texture", "--rays", "2"], "folder", "tex ao.glb", "image 0 of MESH"),
    ([*_QUICK_MLP, "--mesh"], "scene.gltf", "geometry.bin", "buffer 0 of --mesh"),
    ([*_QUICK_MLP, "--mesh"], "folder", "tex ao.png", "image 0 of --mesh"),
    (_QUICK_VOLUMES, "bare name", "geometry.json", "buffer 0 of LEVEL"),
]


@pytest.mark.parametrize("command,given,hit,words", BESIDE_GLTF)
def test_an_output_on_a_file_a_gltf_reads_beside_it_is_refused(
    tmp_path, capsys, monkeypatch, command, given, hit, words
):
    """A glTF's buffers and images are inputs as much as the .gltf: an output on one (or a link to one) is
    refused before any work, naming both, and every file of the mesh is left as it was."""
    folder = tmp_path / "scene"
    names = {"buffer": "geometry.bin", "image": "tex ao.png"}
    names["image" if "image" in words else "buffer"] = hit
    before = _gltf_with_files_beside(folder, names["buffer"], names["image"])
    monkeypatch.setenv("NEURALAO_MESHES", str(tmp_path))
    mesh = {"scene.gltf": str(folder / "scene.gltf"), "folder": str(folder), "bare name": "scene"}[given]
    (tmp_path / "link").symlink_to(folder / hit)
    for out in (folder / hit, tmp_path / "link"):
        argv = [*command, mesh, "--out", str(out)]
        if command[0] == "volumes":
            argv = [*command, "--out", str(out), mesh]
        msg = refusal(capsys, argv)
        assert f"--out {out} is also an input ({words} " in msg and "scene.gltf" in msg, msg
    assert {p: p.read_bytes() for p in folder.iterdir()} == before


@pytest.mark.parametrize(
    "hit,words", [("tet lib.mtl", "material library"), ("wood.png", "texture of tet lib.mtl")]
)
def test_an_output_on_an_objs_material_library_or_texture_is_refused(tmp_path, capsys, hit, words):
    """An OBJ's material library (its ``mtllib``) and that library's textures are read with it: an output on
    one, or on a link to one, is refused before any work, naming both, and the files are left as they were."""
    folder = tmp_path / "obj"
    folder.mkdir()
    (folder / "tet.obj").write_text("mtllib tet lib.mtl\nusemtl wood\n" + TET)
    (folder / "tet lib.mtl").write_text("newmtl wood\nKd 0.8 0.6 0.4\nmap_Kd wood.png\n")
    (folder / "wood.png").write_bytes(b"\x89PNG not decoded by a bake")
    before = {p: p.read_bytes() for p in folder.iterdir()}
    (tmp_path / "link").symlink_to(folder / hit)
    for out in (folder / hit, tmp_path / "link"):
        msg = refusal(capsys, ["bake", str(folder / "tet.obj"), "--rays", "2", "--out", str(out)])
        assert f"--out {out} is also an input ({words} of MESH " in msg and "tet.obj" in msg, msg
    assert {p: p.read_bytes() for p in folder.iterdir()} == before


def test_the_texture_maps_file_beside_the_glb_is_checked_before_any_work(files, tmp_path, capsys):
    """A texture bake writes OUT.ao.png beside OUT.glb: a folder there, or a link to the mesh, is refused
    before any bake as --out itself would be."""
    (tmp_path / "a.ao.png").mkdir()
    (tmp_path / "b.ao.png").symlink_to(files / "tet.obj")
    bake = ["bake", str(files / "tet.obj"), "--to", "texture", "--rays", "2", "--out"]
    msg = refusal(capsys, [*bake, str(tmp_path / "a.glb")])
    assert msg.endswith(f"the map beside --out {tmp_path / 'a.ao.png'} is a folder; a file is wanted here"), (
        msg
    )
    msg = refusal(capsys, [*bake, str(tmp_path / "b.glb")])
    assert f"the map beside --out {tmp_path / 'b.ao.png'} is also an input (MESH)" in msg, msg
    assert (files / "tet.obj").read_text() == TET
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.ao.png", "b.ao.png"]


def test_outputs_get_the_umasks_permissions(files, tmp_path, capsys):
    old = os.umask(0o027)
    try:
        assert (
            run(capsys, ["bake", str(files / "tet.obj"), "--rays", "2", "--out", str(tmp_path / "b.ply")])[0]
            == 0
        )
        assert (
            run(capsys, ["glsl", str(_relu(tmp_path)), "--target", "image", "--out", str(tmp_path / "g")])[0]
            == 0
        )
    finally:
        os.umask(old)
    assert (tmp_path / "b.ply").stat().st_mode & 0o777 == 0o640
    modes = {p.stat().st_mode & 0o777 for p in (tmp_path / "g").rglob("*") if p.is_file()}
    assert modes == {0o640}


def _relu(folder: Path, weights_beside: bool = False) -> Path:
    """A 1x1 convolution + relu ONNX model (its weights in a file beside it with ``weights_beside``)."""
    import onnx
    from onnx import TensorProto, numpy_helper
    from onnx import helper as oh

    x = oh.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4, "h", "w"])
    y = oh.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4, "h", "w"])
    w = numpy_helper.from_array(np.random.default_rng(0).normal(size=(4, 4, 1, 1)).astype(np.float32), "w")
    nodes = [oh.make_node("Conv", ["x", "w"], ["c"], name="c"), oh.make_node("Relu", ["c"], ["y"], name="r")]
    model = oh.make_model(oh.make_graph(nodes, "g", [x], [y], [w]), opset_imports=[oh.make_opsetid("", 19)])
    path = folder / ("conv_ext.onnx" if weights_beside else "conv.onnx")
    onnx.save(model, path, save_as_external_data=weights_beside, location="conv.weights", size_threshold=0)
    return path


def test_evaluate_refuses_two_models_one_column_would_hold(tmp_path, capsys):
    """The tables name a model by its folder: two folders of one name (or one named like a baseline)
    are refused before any frame is rendered, instead of one model's scores silently replacing the other's."""
    from neuralao.runtime.shipped import default_export

    config = tmp_path / "eval.json"
    config.write_text(
        json.dumps(
            {
                "name": "t",
                "categories": [{"name": "scans", "meshes": ["horse"]}],
                "resolutions": [{"size": [32, 32]}],
            }
        )
    )
    for where in ("a/1h", "b/1h", "gtao"):
        shutil.copytree(default_export("unet"), tmp_path / where)
    out = tmp_path / "out"
    line = refusal(
        capsys,
        [
            "evaluate",
            str(config),
            "--models",
            str(tmp_path / "a/1h"),
            str(tmp_path / "b/1h"),
            "--out",
            str(out),
        ],
    )
    assert "same folder name" in line and f"{tmp_path / 'a/1h'}" in line and f"{tmp_path / 'b/1h'}" in line
    line = refusal(capsys, ["evaluate", str(config), "--models", str(tmp_path / "gtao"), "--out", str(out)])
    assert "baseline" in line
    assert not out.exists()


def test_an_export_folder_is_replaced_whole_never_merged(tmp_path, capsys):
    src = tmp_path / "src"
    src.mkdir()
    out = tmp_path / "export"
    assert run(capsys, ["glsl", str(_relu(src)), "--target", "image", "--out", str(out)])[0] == 0
    (out / "glsl" / "old_pass.comp").write_text("// an earlier model's shader\n")
    assert run(capsys, ["glsl", str(_relu(src)), "--target", "image", "--out", str(out)])[0] == 0
    assert not (out / "glsl" / "old_pass.comp").exists() and (out / "manifest.json").is_file()
    assert not temporaries(tmp_path)
    user = tmp_path / "mine"
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    msg = refusal(capsys, ["glsl", str(_relu(src)), "--target", "image", "--out", str(user)])
    assert "--force" in msg and (user / "notes.txt").is_file()
    assert run(capsys, ["glsl", str(_relu(src)), "--target", "image", "--out", str(user), "--force"])[0] == 0
    assert not (user / "notes.txt").exists()
    msg = refusal(capsys, ["glsl", str(_relu(src)), "--target", "image", "--out", str(src)])
    assert "delete it" in msg and (src / "conv.onnx").is_file()


def test_an_export_carries_weights_its_onnx_kept_as_external_data(tmp_path, capsys):
    import onnx

    model = _relu(tmp_path, weights_beside=True)
    out = tmp_path / "export"
    assert run(capsys, ["glsl", str(model), "--target", "image", "--out", str(out)])[0] == 0
    assert not (out / "conv.weights").exists()
    onnx.checker.check_model(onnx.load(str(out / "model.onnx"), load_external_data=False), full_check=True)
    rc, err = run(capsys, ["parity", str(out), "--size", "8", "8", "--out", str(tmp_path / "parity.json")])
    assert rc == 0, err
    assert json.loads((tmp_path / "parity.json").read_text())["passed"]


def test_parity_refuses_non_finite_inputs_naming_the_array(tmp_path, capsys):
    out = tmp_path / "export"
    assert run(capsys, ["glsl", str(_relu(tmp_path)), "--target", "image", "--out", str(out)])[0] == 0
    x = np.random.default_rng(0).normal(size=(1, 4, 8, 8)).astype(np.float32)
    x[0, 1, 2, 3] = np.nan
    np.savez(tmp_path / "in.npz", x=x)
    msg = refusal(capsys, ["parity", str(out), "--inputs", str(tmp_path / "in.npz")])
    assert "--inputs" in msg and "'x'" in msg and "non-finite" in msg


# --------------------------------------------------------------------------- signals


def _interrupt(argv: list[str], sig: int, after: float, cwd: Path) -> tuple[int, list[str]]:
    """Run ``neuralao argv`` as a process (default signal handling), send ``sig`` after ``after`` s."""
    env = {**os.environ, "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "osmesa")}
    proc = subprocess.Popen(
        [*NEURALAO, *argv],
        cwd=cwd,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: [signal.signal(s, signal.SIG_DFL) for s in (signal.SIGINT, signal.SIGTERM)],
    )
    time.sleep(after)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip() and "%|" not in ln]
    return proc.returncode, [ln for ln in lines if not ln.startswith("INFO ")]


@pytest.mark.parametrize(
    "sig,after,code,words",
    [
        (signal.SIGINT, 1.0, 130, "interrupted (Ctrl-C)"),  # while the command's modules are imported
        (signal.SIGINT, 6.0, 130, "interrupted (Ctrl-C)"),  # while it traces
        (signal.SIGTERM, 6.0, 143, "terminated (SIGTERM)"),
    ],
)
def test_ctrl_c_and_sigterm_end_in_one_line_and_leave_nothing(tmp_path, sig, after, code, words):
    (tmp_path / "tet.obj").write_text(TET)
    argv = ["bake", "tet.obj", "--rays", "2000000", "--samples-per-vertex", "64", "--out", "out.ply"]
    rc, err = _interrupt(argv, sig, after, tmp_path)
    assert rc == code and len(err) == 1 and words in err[0], (rc, err)
    assert "Traceback" not in err[0] and not (tmp_path / "out.ply").exists() and not temporaries(tmp_path)


SWALLOWED = """
import importlib, os, signal, sys, types
from pathlib import Path
from neuralao.runtime.foundation.io import {writer}

def work(parser, args, command):
    try:  # what trimesh does around an optional import: the signal's exception is swallowed
        os.kill(os.getpid(), signal.{sig})
    except BaseException:
        pass
    with {writer}(Path("out")) as tmp:
        (tmp / "ao.txt" if tmp.is_dir() else tmp).write_text("done")
    return 0

cli = importlib.import_module("neuralao.pipeline.cli.main")
cli.build_parser = lambda load=None: types.SimpleNamespace(
    parse_args=lambda argv: types.SimpleNamespace(command=None)
)
cli._run = work
sys.exit(cli.main([]))
"""


@pytest.mark.parametrize("writer", ["atomic_path", "atomic_folder"])
@pytest.mark.parametrize("sig,code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_a_signal_a_library_swallows_still_stops_the_output(tmp_path, writer, sig, code):
    """A library catching BaseException eats the interrupt, the work goes on and finishes: the rename
    is where it must stop, so nothing is published and the command ends as interrupted."""
    script = SWALLOWED.format(sig=sig, writer=writer)
    proc = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == code and len(lines) == 1 and "Traceback" not in lines[0], (
        proc.returncode,
        lines,
    )
    assert not (tmp_path / "out").exists() and not temporaries(tmp_path)
