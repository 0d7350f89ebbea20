"""`neuralao render` end to end: files, frame format, consistency with the components, bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from neuralao.pipeline.cli.main import main
from neuralao.pipeline.cli.render import view_seed
from neuralao.pipeline.gbuffers.rasterizer import GBufferRenderer
from neuralao.pipeline.geometry.camera import Camera
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.pipeline.tracing.labeller import Labeller, LabelSettings
from neuralao.runtime.foundation.io import read_npz

W, H, VIEWS, RAYS = 40, 28, 2, 16
FRAME = {
    "depth": ((H, W), np.float32),
    "normal_cam": ((H, W, 3), np.float32),
    "normal_obj": ((H, W, 3), np.float32),
    "position": ((H, W, 3), np.float32),
    "mask": ((H, W), np.bool_),
    "tri_id": ((H, W), np.int32),
    "ao": ((H, W), np.float32),
    "valid": ((H, W), np.bool_),
    "pose": ((4, 4), np.float64),
}


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("render") / "out"
    argv = [
        "render",
        "spot",
        "--views",
        str(VIEWS),
        "--size",
        str(W),
        str(H),
        "--rays",
        str(RAYS),
        "--seed",
        "3",
    ]
    assert main([*argv, "--out", str(out)]) == 0
    return out


def test_writes_every_view_and_preview(rendered):
    names = sorted(p.name for p in rendered.iterdir())
    expected = ["render.json"] + [
        f"view_{k:04d}{s}" for k in range(VIEWS) for s in (".npz", "_ao.png", "_depth.png", "_normal.png")
    ]
    assert names == sorted(expected)  # and no temporary files left behind
    for k in range(VIEWS):
        for kind in ("ao", "normal", "depth"):
            img = Image.open(rendered / f"view_{k:04d}_{kind}.png")
            assert img.size == (W, H) and img.mode == "RGB"


def test_frames_follow_the_format_and_conventions(rendered):
    record = json.loads((rendered / "render.json").read_text())
    assert record["settings"]["size"] == [W, H] and record["settings"]["views"] == VIEWS
    assert record["settings"]["labels"]["rays"] == RAYS and record["settings"]["labels"]["max_distance"] > 0
    scene = load_scene("spot")
    assert record["scene"]["faces"] == len(scene.faces)
    for k in range(VIEWS):
        f = read_npz(rendered / f"view_{k:04d}.npz")
        for key, (shape, dtype) in FRAME.items():
            assert f[key].shape == shape and f[key].dtype == dtype, key
        for key in ("yfov", "znear", "zfar"):
            assert f[key].shape == () and np.isfinite(f[key])
        bg = ~f["mask"]
        assert bg.any() and f["mask"].any()
        assert (f["ao"][bg] == 1).all() and not f["valid"][bg].any() and (f["tri_id"][bg] == -1).all()
        assert (f["ao"] >= 0).all() and (f["ao"] <= 1).all()
        assert f["tri_id"].max() < len(scene.faces)
        view = record["views"][k]
        assert view["file"] == f"view_{k:04d}.npz" and view["foreground_px"] == int(f["mask"].sum())
        assert np.allclose(view["pose"], f["pose"])


def test_stored_frames_reproduce_from_the_components(rendered):
    # The CLI's output must equal an independent render + label of the stored camera with the
    # documented per-view seed: nothing is lost or reordered on the way to disk.
    scene = load_scene("spot")
    renderer = GBufferRenderer(scene)
    record = json.loads((rendered / "render.json").read_text())
    settings = LabelSettings(rays=RAYS, seed=3)
    for k in range(VIEWS):
        f = read_npz(rendered / f"view_{k:04d}.npz")
        cam = Camera(f["pose"], W, H, float(f["yfov"]), float(f["znear"]), float(f["zfar"]))
        g = renderer.render(cam)
        for key in ("depth", "normal_cam", "normal_obj", "position", "mask", "tri_id"):
            assert np.array_equal(g[key], f[key]), key
        assert record["views"][k]["label_seed"] == view_seed(3, k)
        ao, valid = Labeller(scene, replace(settings, seed=view_seed(3, k))).label_frame(g)
        assert np.array_equal(ao, f["ao"]) and np.array_equal(valid, f["valid"])
        # Previews show the data: the normal PNG decodes back to normal_cam within 8-bit rounding.
        png = np.asarray(Image.open(rendered / f"view_{k:04d}_normal.png"), np.float32) / 255.0
        assert np.abs(png[f["mask"]] * 2 - 1 - f["normal_cam"][f["mask"]]).max() <= 2.0 / 255 + 1e-6
    # Different views get different label seeds (no shared sampling pattern).
    assert len({v["label_seed"] for v in record["views"]}) == VIEWS


def test_camera_file_and_obscurance_kernel(tmp_path):
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps([{"eye": [0.0, 1.0, 0.9], "target": [0.0, 0.8, -1.0], "yfov_deg": 50}]))
    out = tmp_path / "out"
    argv = ["render", "cornell_box", "--cameras", str(poses), "--size", "24", "16", "--rays", "8"]
    assert main([*argv, "--kernel", "obscurance", "--half-distance", "0.2", "--out", str(out)]) == 0
    record = json.loads((out / "render.json").read_text())
    assert record["settings"]["cameras"] == "file" and record["settings"]["views"] == 1
    assert record["settings"]["labels"]["kernel"] == "obscurance"
    assert record["settings"]["labels"]["half_distance"] == 0.2
    f = read_npz(out / "view_0000.npz")
    assert f["mask"].all()  # inside the box every pixel sees a wall
    assert np.allclose(f["pose"][:3, 3], [0.0, 1.0, 0.9])
    assert abs(float(f["yfov"]) - np.radians(50)) < 1e-12
    # Obscurance is continuous: most pixels are strictly between 0 and 1 with few rays, unlike binary.
    assert ((f["ao"] > 0) & (f["ao"] < 1)).mean() > 0.2


def _bad_inputs(tmp_path):
    nan_obj = tmp_path / "nan.obj"
    nan_obj.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    empty = tmp_path / "empty.obj"
    empty.write_text("")
    bad_json = tmp_path / "poses.json"
    bad_json.write_text("{not json")
    base = ["--size", "8", "8", "--rays", "4"]
    return {
        "missing": ["render", str(tmp_path / "missing.obj"), *base],
        "nan": ["render", str(nan_obj), *base],
        "empty": ["render", str(empty), *base],
        "views0": ["render", "spot", "--views", "0", *base],
        "size0": ["render", "spot", "--size", "0", "8", "--rays", "4"],
        "rays0": ["render", "spot", "--size", "8", "8", "--rays", "0"],
        "maxdist": ["render", "spot", *base, "--max-distance", "nan"],
        "halfdist_binary": ["render", "spot", *base, "--half-distance", "0.1"],
        "cameras": ["render", "spot", *base, "--cameras", str(bad_json)],
    }


@pytest.mark.parametrize(
    "case", ["missing", "nan", "empty", "views0", "size0", "rays0", "maxdist", "halfdist_binary", "cameras"]
)
def test_bad_input_is_a_one_line_error_and_writes_nothing(tmp_path, capsys, case):
    argv = _bad_inputs(tmp_path)[case]
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("neuralao render: error: "), err
    assert not out.exists() or not any(out.iterdir())


def test_entry_point_subprocess_reports_nan_mesh(tmp_path):
    # The real process: exit status 2, one stderr line, nothing written.
    nan_obj = tmp_path / "nan.obj"
    nan_obj.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "neuralao.pipeline.cli",
        "render",
        str(nan_obj),
        "--size",
        "8",
        "8",
        "--out",
        str(out),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines == [lines[-1]] and "NaN" in lines[-1], proc.stderr
    assert not out.exists()
