"""The G-buffer frame format of docs/formats.md, from both sides: a frame written by `neuralao render`
is read by `neuralao infer` unchanged, and so is a frame a user's own exporter writes from the
documented keys alone (depth, normal_cam; yfov and the radius on the command line). One unit for the
field of view on the command line: degrees (`--yfov`), radians only when asked (`--yfov-rad`)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from neuralao.pipeline import cli

H, W = 40, 48


def _infer(args: list[str]) -> int:
    return cli.main(["infer", *args])


def _user_frame(path, **extra) -> dict:
    """A floor 4 units away with a box top 1 unit closer, every pixel foreground: only the keys the
    format says a user must write (depth: linear -z_cam in scene units; normal_cam: unit, facing the
    viewer), plus ``extra``."""
    depth = np.full((H, W), 4.0, np.float32)
    depth[12:28, 16:32] = 3.0
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 2] = 1.0
    arrays = {"depth": depth, "normal_cam": normal, **extra}
    np.savez(path, **arrays)
    return arrays


def test_a_frame_written_by_render_is_read_by_infer_unchanged(tmp_path):
    out = tmp_path / "r"
    assert (
        cli.main(
            [
                "render",
                "spot",
                "--views",
                "1",
                "--size",
                str(W),
                str(H),
                "--rays",
                "8",
                "--yfov",
                "50",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    frame = np.load(out / "view_0000.npz")
    assert math.isclose(float(frame["yfov"]), math.radians(50))  # the frame stores radians
    assert json.loads((out / "render.json").read_text())["settings"]["yfov_deg"] == 50
    assert _infer([str(out / "view_0000.npz"), "--out", str(tmp_path / "ao.npy")]) == 0
    ao = np.load(tmp_path / "ao.npy")
    mask = frame["mask"]
    assert ao.shape == (H, W) and np.isfinite(ao).all() and mask.any()
    assert ao.min() >= 0 and ao.max() <= 1 and (ao[~mask] == 1).all()


def test_a_frame_from_the_documented_keys_alone_is_read_by_infer(tmp_path):
    _user_frame(tmp_path / "mine.npz")
    args = ["--radius", "0.5", "--out"]
    assert _infer([str(tmp_path / "mine.npz"), "--yfov", "60", *args, str(tmp_path / "a.npy")]) == 0
    a = np.load(tmp_path / "a.npy")
    assert a.shape == (H, W) and np.isfinite(a).all() and a.min() >= 0 and a.max() <= 1
    assert np.ptp(a) > 0  # the box's edges change the AO: the depth really went in
    # the same field of view in radians, on the command line or stored in the frame as render stores it
    assert (
        _infer(
            [str(tmp_path / "mine.npz"), "--yfov-rad", repr(math.radians(60)), *args, str(tmp_path / "b.npy")]
        )
        == 0
    )
    _user_frame(tmp_path / "with_fov.npz", yfov=np.float64(math.radians(60)), mask=np.ones((H, W), bool))
    assert _infer([str(tmp_path / "with_fov.npz"), *args, str(tmp_path / "c.npy")]) == 0
    np.testing.assert_allclose(np.load(tmp_path / "b.npy"), a, atol=1e-6)
    np.testing.assert_allclose(np.load(tmp_path / "c.npy"), a, atol=1e-6)


def test_a_missing_field_of_view_or_radius_names_the_flag(tmp_path, capsys):
    _user_frame(tmp_path / "mine.npz")
    assert _infer([str(tmp_path / "mine.npz"), "--radius", "0.5", "--out", str(tmp_path / "a.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--yfov" in err
    assert _infer([str(tmp_path / "mine.npz"), "--yfov", "60", "--out", str(tmp_path / "a.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--radius" in err
    assert not (tmp_path / "a.png").exists()


@pytest.mark.parametrize(
    "flags", [["--yfov", "180"], ["--yfov", "0"], ["--yfov-rad", "3.2"], ["--yfov", "60", "--yfov-rad", "1"]]
)
def test_bad_fields_of_view_are_one_line_errors(tmp_path, capsys, flags):
    _user_frame(tmp_path / "mine.npz")
    assert (
        _infer([str(tmp_path / "mine.npz"), *flags, "--radius", "0.5", "--out", str(tmp_path / "a.png")]) == 2
    )
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not (tmp_path / "a.png").exists()


def test_render_takes_the_field_of_view_in_degrees_or_radians(tmp_path, capsys):
    base = ["render", "spot", "--views", "1", "--size", "16", "16", "--rays", "4"]
    assert cli.main([*base, "--yfov-rad", repr(math.radians(30)), "--out", str(tmp_path / "rad")]) == 0
    assert cli.main([*base, "--yfov", "30", "--out", str(tmp_path / "deg")]) == 0
    for name in ("rad", "deg"):
        assert math.isclose(float(np.load(tmp_path / name / "view_0000.npz")["yfov"]), math.radians(30))
    capsys.readouterr()
    assert cli.main([*base, "--yfov", "30", "--yfov-rad", "0.5", "--out", str(tmp_path / "both")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


# ------------------------------------------------------------------------------ the one frame reader


def _refused(tmp_path, capsys, **arrays) -> str:
    """`neuralao infer` of a frame holding ``arrays``: exit 2 and the one stderr line."""
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    assert _infer([str(path), "--yfov", "50", "--radius", "0.5", "--out", str(tmp_path / "ao.png")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and not (tmp_path / "ao.png").exists()
    return lines[0]


def _good() -> dict:
    depth = np.full((H, W), 4.0, np.float32)
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 2] = 1.0
    return {"depth": depth, "normal_cam": normal}


def test_depth_holding_z_cam_is_refused_by_name(tmp_path, capsys):
    """z_cam (negative in front of an OpenGL camera) instead of -z_cam, even under an explicit mask."""
    g = _good()
    err = _refused(
        tmp_path, capsys, depth=-g["depth"], normal_cam=g["normal_cam"], mask=np.ones((H, W), bool)
    )
    assert "'depth'" in err and "z_cam" in err


def test_a_mask_over_background_depth_is_refused(tmp_path, capsys):
    g = _good()
    g["depth"][:5] = 0.0
    err = _refused(tmp_path, capsys, **g, mask=np.ones((H, W), bool))
    assert "'mask'" in err and f"{5 * W} pixel" in err


@pytest.mark.parametrize(
    ("key", "value", "words"),
    [
        ("depth", np.zeros((H, W), dtype=[("a", "f4"), ("b", "f4")]), "'depth' holds"),
        ("depth", np.ones((H, W), np.complex64), "'depth' holds complex64"),
        ("yfov", np.array([0.8, 0.9]), "'yfov' must be one number"),
        ("yfov", np.float64(4.0), "must be within [0.001745, 2.967] radians"),
        ("depth", np.ones((H, W, 1), np.float32), "'depth' has shape"),
        ("normal_cam", np.zeros((H, W + 1, 3), np.float32), "'normal_cam' has shape"),
        ("fov", np.float64(0.8), "unknown frame key 'fov'"),
    ],
)
def test_malformed_frames_name_the_key_and_the_rule(tmp_path, capsys, key, value, words):
    arrays = _good() | {key: value}
    assert words in _refused(tmp_path, capsys, **arrays)


def test_an_empty_frame_is_refused_before_the_model(tmp_path, capsys):
    err = _refused(
        tmp_path, capsys, depth=np.zeros((0, 0), np.float32), normal_cam=np.zeros((0, 0, 3), np.float32)
    )
    assert "0x0 pixels" in err


def test_frame_round_trip_and_mapping_reads(tmp_path):
    """write_frame then read_frame gives the same arrays; channels read by name like the file's keys."""
    from neuralao.runtime.frame import Frame, read_frame, write_frame

    g = _good()
    frame = Frame.from_arrays(g | {"yfov": 0.8, "radii": np.array([0.5], np.float32)})
    write_frame(tmp_path / "f.npz", frame)
    back = read_frame(tmp_path / "f.npz")
    assert set(back) == {"depth", "normal_cam", "yfov", "radii"} and back.size == (W, H)
    for k in back:
        np.testing.assert_array_equal(np.asarray(back[k]), np.asarray(frame[k]))
    assert "mask" not in back and back.get("mask") is None and back.yfov == 0.8
    assert back.replace(mask=g["depth"] > 0).mask.all()
