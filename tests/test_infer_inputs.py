"""`neuralao infer` on inputs it cannot use: frames that lack a channel, U-Net exports whose metadata was
tampered with, depths and radii outside the range where AO is computed exactly, an export folder or a
frame given as the model. Each is one line naming the culprit and exit status 2; the command runs for real,
in-process, with Python warnings as errors (``run`` / ``refusal`` of test_user_inputs).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import pytest
from test_user_inputs import ROOT, refusal, run

from neuralao.runtime.frame import DEPTH_RANGE

MODELS = ROOT / "runtime" / "models"
H, W = 48, 64
RADIUS = 2.0


def _frame(path: Path, scale: float = 1.0, **arrays) -> Path:
    """A 64x48 frame: a wall at depth 4 with a box at depth 3 in front, facing the camera; ``arrays``
    replace channels (None removes one)."""
    depth = np.full((H, W), 4.0, np.float32)
    depth[10:30, 20:40] = 3.0
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 2] = 1.0
    channels = {"depth": depth * np.float32(scale), "normal_cam": normal} | arrays
    np.savez(path, **{k: v for k, v in channels.items() if v is not None})
    return path


def _infer(tmp_path: Path, *paths: Path | str, radius: float = RADIUS, out: str = "ao.npy") -> list[str]:
    return ["infer", *map(str, paths), "--yfov", "60", "--radius", repr(radius), "--out", str(tmp_path / out)]


def _tampered(path: Path, **changes: str | None) -> Path:
    """The shipped hybrid U-Net with metadata ``changes`` (None removes a key)."""
    model = onnx.load(str(MODELS / "unet-gtao" / "model.onnx"))
    props = {p.key: p.value for p in model.metadata_props} | changes
    del model.metadata_props[:]
    onnx.helper.set_model_props(model, {k: v for k, v in props.items() if v is not None})
    onnx.save(model, str(path))
    return path


# ------------------------------------------------------------------------------------------ frames


@pytest.mark.parametrize(
    "missing, arrays",
    [
        ("depth", {"depth": None}),  # normal_cam only: no mask to take from depth either
        ("depth", {"depth": None, "mask": np.ones((H, W), bool)}),
        ("normal_cam", {"normal_cam": None}),
    ],
)
def test_a_frame_without_a_channel_the_unet_reads_is_named(tmp_path, capsys, missing, arrays):
    frame = _frame(tmp_path / "f.npz", **arrays)
    for model in ([], [MODELS / "unet-fast" / "model.onnx"]):  # the hybrid runs GTAO first, the pure not
        msg = refusal(capsys, _infer(tmp_path, *model, frame))
        assert f"has no {missing!r} channel" in msg and "f.npz" in msg


# ------------------------------------------------------------------------------------------ metadata

TAMPERED = [
    ({"pad_multiple": "0"}, "pad_multiple 0 must be positive"),
    ({"pad_multiple": "-8"}, "pad_multiple -8 must be positive"),
    ({"pad_multiple": "nan"}, "pad_multiple 'nan' is not an integer"),
    ({"pad_multiple": "8.0"}, "pad_multiple '8.0' is not an integer"),
    ({"pad_multiple": "9" * 5000}, "is more than 4096"),
    ({"pad_multiple": None}, "metadata has no pad_multiple"),
    ({"internal_height": "100000000"}, "internal_height 100000000 is more than 16384"),
    ({"internal_height": "4"}, "internal_height 4 must be >= 16"),
    ({"internal_height": "1e3"}, "internal_height '1e3' is not an integer"),
    ({"pad_mode": "bogus"}, "pad_mode 'bogus' is not 'reflect'"),
    ({"pad_mode": None}, "metadata has no pad_mode"),
    ({"gtao_blur": "sometimes"}, "metadata gtao_blur must be true or false"),
]


@pytest.mark.parametrize("changes, words", TAMPERED, ids=[w for _, w in TAMPERED])
def test_tampered_unet_metadata_is_named(tmp_path, capsys, changes, words):
    model = _tampered(tmp_path / "u.onnx", **changes)
    msg = refusal(capsys, _infer(tmp_path, model, _frame(tmp_path / "f.npz")))
    assert words in msg and "u.onnx" in msg


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"pad_multiple": "0"}, "metadata pad_multiple 0 must be positive"),
        ({"internal_height": "100000000"}, "metadata internal_height 100000000 is more than 16384"),
        (
            {"pad_mode": "bogus"},
            "metadata pad_mode 'bogus' is not 'reflect', the only padding its consumers do",
        ),
    ],
)
def test_glsl_and_infer_refuse_a_padding_contract_with_one_check(tmp_path, capsys, changes, words):
    model = _tampered(tmp_path / "u.onnx", **changes)
    glsl = refusal(capsys, ["glsl", str(model), "--target", "image", "--out", str(tmp_path / "g")])
    infer = refusal(capsys, _infer(tmp_path, model, _frame(tmp_path / "f.npz")))
    assert glsl.endswith(words) and infer.endswith(words) and not (tmp_path / "g").exists()


def test_an_opset_newer_than_onnx_knows_is_refused(tmp_path, capsys):
    model = onnx.load(str(MODELS / "unet-fast" / "model.onnx"))
    model.opset_import[0].version = 99
    onnx.save(model, str(tmp_path / "u.onnx"))
    argv = ["glsl", str(tmp_path / "u.onnx"), "--target", "image", "--out", str(tmp_path / "g")]
    msg = refusal(capsys, argv)
    assert "u.onnx" in msg and "opset 99" in msg and not (tmp_path / "g").exists()


def test_a_frame_whose_network_input_cannot_fit_is_refused_before_allocating(tmp_path, capsys):
    # one row, 65536 columns: at the shipped internal height of 256 rows, 16.8M columns
    normal = np.tile(np.float32([0, 0, 1]), (1, 65536, 1))
    strip = _frame(tmp_path / "strip.npz", depth=np.full((1, 65536), 4.0, np.float32), normal_cam=normal)
    msg = refusal(capsys, _infer(tmp_path, strip))
    assert "65536x1 frame" in msg and "internal_height 256" in msg and "memory available" in msg


# ------------------------------------------------------------------------------------------ depth range


def _ao(tmp_path: Path, capsys, scale: float) -> np.ndarray:
    frame = _frame(tmp_path / f"f{scale:g}.npz", scale)
    rc, err = run(capsys, _infer(tmp_path, frame, radius=RADIUS * scale, out=f"ao{scale:g}.npy"))
    assert rc == 0 and not err, err
    return np.load(tmp_path / f"ao{scale:g}.npy")


def test_ao_is_unchanged_across_the_accepted_depth_range(tmp_path, capsys):
    """The frame and its radius scaled alike, from the bottom of the range to its top, give the AO of the
    unscaled frame (the shipped hybrid, whose GTAO works in float32, failed past 1e-19 and 1e19)."""
    low, high = DEPTH_RANGE
    reference = _ao(tmp_path, capsys, 1.0)
    assert reference.min() < 0.9  # the wall around the box is occluded: a broken scale would show
    for scale in (low / RADIUS * 1.01, 1e-6, 1e6, high / 4.0):  # radius at the bottom, depth 4 at the top
        np.testing.assert_allclose(_ao(tmp_path, capsys, scale), reference, atol=1e-4, err_msg=f"{scale:g}")


@pytest.mark.parametrize("scale", [1e-20, 1e-13, 1e13, 1e19, 1e-42])
def test_depths_outside_the_range_are_refused(tmp_path, capsys, scale):
    frame = _frame(tmp_path / "f.npz", scale)
    msg = refusal(capsys, _infer(tmp_path, frame))  # the radius in range: the depth is named
    assert "f.npz: 'depth'" in msg and "foreground value(s)" in msg and "[1e-12, 1e+12]" in msg
    if scale > 1e-38:  # the radius alike is refused first, by name (a float32 denormal is the depth's case)
        msg = refusal(capsys, _infer(tmp_path, frame, radius=RADIUS * scale))
        assert "--radius" in msg and "[1e-12, 1e+12]" in msg


# ------------------------------------------------------------------------------------------ radius


@pytest.mark.parametrize("radius", [1e-300, 5e-13, 0.0, -1.0, 2e12])
def test_radii_outside_the_range_are_refused(tmp_path, capsys, radius):
    msg = refusal(capsys, _infer(tmp_path, _frame(tmp_path / "f.npz"), radius=radius))
    assert msg.startswith("neuralao infer: error: --radius")


def test_a_radius_far_past_the_screen_is_refused_in_pixels(tmp_path, capsys):
    """In range, but 1e11 scene units at depth 3 is 1.4e12 pixels: past what GTAO steps exactly."""
    msg = refusal(capsys, _infer(tmp_path, _frame(tmp_path / "f.npz"), radius=1e11))
    assert "--radius 1e+11 spans" in msg and "pixels" in msg
    assert run(capsys, _infer(tmp_path, _frame(tmp_path / "f.npz"), radius=1e7))[0] == 0


def test_a_frames_label_radius_outside_the_range_is_named(tmp_path, capsys):
    frame = _frame(tmp_path / "f.npz", radii=np.float32([1e-30]), yfov=np.float64(1.0))
    msg = refusal(capsys, ["infer", str(frame), "--out", str(tmp_path / "ao.png")])
    assert "'radii'" in msg and "out of range" in msg


# ------------------------------------------------------------------------------------------ the model


def test_an_export_folder_is_taken_as_its_model(tmp_path, capsys):
    frame = _frame(tmp_path / "f.npz")
    folder = MODELS / "unet-fast"
    assert run(capsys, _infer(tmp_path, folder, frame, out="folder.npy"))[0] == 0
    assert run(capsys, _infer(tmp_path, folder / "model.onnx", frame, out="file.npy"))[0] == 0
    np.testing.assert_array_equal(np.load(tmp_path / "folder.npy"), np.load(tmp_path / "file.npy"))


def test_what_is_not_a_model_is_named_as_the_model_it_was_taken_for(tmp_path, capsys):
    frame = _frame(tmp_path / "f.npz")
    other = _frame(tmp_path / "g.npz")
    msg = refusal(capsys, _infer(tmp_path, frame, other))
    assert "f.npz was taken as the model" in msg and "MODEL FRAME.npz" in msg
    (tmp_path / "plain").mkdir()
    msg = refusal(capsys, _infer(tmp_path, tmp_path / "plain", frame))
    assert "plain is a folder but not an export" in msg
    msg = refusal(capsys, _infer(tmp_path, MODELS / "unet-fast"))
    assert "unet-fast is a model; give the frame after it" in msg
