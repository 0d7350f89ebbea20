"""The U-Net's frame-local input contract (version 3, and 4 with the back layer), end to end through the
exported ONNX file and the runtime predictor: a pixel's AO depends only on its receptive field (geometry
far away leaves it unchanged to float tolerance), and scaling the whole scene, depth and AO radius
together, leaves the AO unchanged. Version 2 (depth over the frame's mean depth) is run beside it to show
that the first check can fail: there a far patch moves the object's AO."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from neuralao.export.unet import export_onnx, onnx_metadata
from neuralao.pipeline.models.unet import UNet, UNetArgs
from neuralao.runtime.frame import Frame
from neuralao.runtime.predict import unet_predictor
from neuralao.runtime.unet_input import preprocess, radius_of_param, radius_param

H, W = 48, 320
OBJECT = slice(0, 56)  # the columns whose AO is compared
YFOV = 0.9
RADIUS = 0.6
# Float tolerance of one pixel's AO when nothing within its receptive field changed: onnxruntime's
# convolutions sum each output's taps in a fixed order, so the measured difference is 0; 1e-6 allows
# for a kernel that blocks rows differently.
LOCAL_TOL = 1e-6


def _frame(far_patch: bool) -> Frame:
    """A tilted floor (depth 4-6) with a box on it at the left; ``far_patch`` adds a second box 200
    pixels to the right of the compared columns, beyond the network's ~70-pixel receptive radius."""
    rows = np.linspace(4.0, 6.0, H, dtype=np.float32)[:, None]
    depth = np.repeat(rows, W, axis=1)
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 1], normal[..., 2] = 0.6, 0.8
    boxes = [(slice(14, 34), slice(16, 40))] + ([(slice(6, 44), slice(256, 310))] if far_patch else [])
    back = np.zeros_like(depth)  # the back layer (version 4): each box 0.8 deep, the floor thin
    for r, c in boxes:
        depth[r, c] -= 1.5
        normal[r, c] = (0.0, 0.0, 1.0)
        back[r, c] = depth[r, c] + 0.8
    return Frame.from_arrays(
        {"depth": depth, "normal_cam": normal, "mask": depth > 0, "yfov": YFOV, "depth_back": back}
    )


def _export(tmp_path, version: int):
    torch.manual_seed(3)
    model = UNet(UNetArgs(in_channels=5 if version >= 4 else 4, preprocess_version=version)).eval()
    path = tmp_path / f"v{version}.onnx"
    export_onnx(model, path, onnx_metadata(model))
    return unet_predictor(path, internal_height=None)


@pytest.mark.parametrize("version", [2, 3, 4])
def test_a_far_patch_moves_the_objects_ao_only_under_the_whole_frame_contract(tmp_path, version):
    predict = _export(tmp_path, version)
    near = predict(_frame(False), RADIUS)[:, OBJECT]
    far = predict(_frame(True), RADIUS)[:, OBJECT]
    moved = float(np.abs(far - near).max())
    if version >= 3:
        assert moved <= LOCAL_TOL
    else:  # the mean depth over the whole frame couples the object to the far box
        assert moved > 10 * LOCAL_TOL  # measured 1.2e-4 with this seed


@pytest.mark.parametrize("version", [3, 4])
@pytest.mark.parametrize("scale", [1e-3, 7.5, 1e4])
def test_scaling_the_scene_and_the_radius_leaves_the_ao_unchanged(tmp_path, scale, version):
    predict = _export(tmp_path, version)
    frame = _frame(True)
    ref = predict(frame, RADIUS)
    s = np.float32(scale)
    scaled = predict(frame.replace(depth=frame.depth * s, depth_back=frame.depth_back * s), RADIUS * scale)
    # log(s z) - log(s R) rounds in float32: ~1e-7 relative on inputs of magnitude ~2, through the net
    assert float(np.abs(scaled - ref).max()) <= 1e-5


def test_version_3_input_needs_no_statistic_of_the_frame():
    """Each input pixel is a function of that pixel (log depth, its normal) and rho of the radius and
    the projection alone; rho maps back to the radius exactly."""
    f = _frame(True)
    x = preprocess(f.depth, f.normal_cam, f.mask, version=3)
    np.testing.assert_allclose(x[0], np.log(f.depth), rtol=1e-6)
    part = preprocess(f.depth[:, :60], f.normal_cam[:, :60], f.mask[:, :60], version=3)
    np.testing.assert_array_equal(part, x[:, :, :60])
    rho = radius_param(RADIUS, f.depth, f.mask, YFOV, version=3)
    assert rho == pytest.approx(np.log(RADIUS / np.tan(YFOV / 2)), rel=1e-12)
    assert radius_param(RADIUS, f.depth[:5], f.mask[:5], YFOV, version=3) == rho
    assert radius_of_param(rho, f.depth, f.mask, YFOV, 3) == pytest.approx(RADIUS, rel=1e-12)
