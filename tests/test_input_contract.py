"""The U-Net's frame-local input contract (version 3, 4 with the back layer, 5 at any resolution), end to
end through the exported ONNX file and the runtime predictor: a pixel's AO depends only on its receptive
field (geometry far away leaves it unchanged to float tolerance), and scaling the whole scene, depth and
AO radius together, leaves the AO unchanged. Version 2 (depth over the frame's mean depth) is run beside
it to show that the first check can fail: there a far patch moves the object's AO."""

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
    model = UNet(UNetArgs(in_channels=5 if version == 4 else 4, preprocess_version=version)).eval()
    path = tmp_path / f"v{version}.onnx"
    export_onnx(model, path, onnx_metadata(model))
    return unet_predictor(path, internal_height=None)


@pytest.mark.parametrize("version", [2, 3, 4, 5])
def test_a_far_patch_moves_the_objects_ao_only_under_the_whole_frame_contract(tmp_path, version):
    predict = _export(tmp_path, version)
    near = predict(_frame(False), RADIUS)[:, OBJECT]
    far = predict(_frame(True), RADIUS)[:, OBJECT]
    moved = float(np.abs(far - near).max())
    if version >= 3:
        assert moved <= LOCAL_TOL
    else:  # the mean depth over the whole frame couples the object to the far box
        assert moved > 10 * LOCAL_TOL  # measured 1.2e-4 with this seed


@pytest.mark.parametrize("version", [3, 4, 5])
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


def test_version_5_states_the_pixel_scale_and_runs_shorter_frames_at_their_size(tmp_path):
    """Version 5's rho is version 3's plus log(H / 256), H the rows the network sees (so at 256 rows the two
    contracts give the same input); its export's internal height is a most: a shorter frame runs at its
    own size, a taller one at that height, and rho follows the rows the network runs at."""
    from neuralao.export.unet import export_onnx, onnx_metadata
    from neuralao.runtime.internal_resolution import at_internal_resolution, internal_size
    from neuralao.runtime.unet_input import REFERENCE_ROWS, frame_radius_param, preprocess_frame, scales_up

    f = _frame(True)
    v3 = radius_param(RADIUS, f.depth, f.mask, YFOV, version=3)
    assert radius_param(RADIUS, f.depth, f.mask, YFOV, version=5) == pytest.approx(
        v3 + np.log(H / REFERENCE_ROWS)
    )
    tall = np.zeros((REFERENCE_ROWS, 4), np.float32)
    assert radius_param(RADIUS, tall, tall > 0, YFOV, version=5) == pytest.approx(v3, abs=1e-12)
    rho = radius_param(RADIUS, f.depth, f.mask, YFOV, version=5)
    assert radius_of_param(rho, f.depth, f.mask, YFOV, 5) == pytest.approx(RADIUS, rel=1e-12)
    assert scales_up(3) and scales_up(4) and not scales_up(5)
    assert internal_size(320, 48, 32, up=False) == (213, 32) and internal_size(320, 48, 64, up=False) == (
        320,
        48,
    )
    assert internal_size(320, 48, 64) == (427, 64)  # versions 2-4 point-sample shorter frames up

    torch.manual_seed(3)
    model = UNet(UNetArgs(preprocess_version=5)).eval()
    path = tmp_path / "v5.onnx"
    meta = onnx_metadata(model)
    meta["internal_height"] = "32"
    export_onnx(model, path, meta)
    ort = unet_predictor(path, internal_height=None)  # the network at the frame's own size
    # shorter than the most rows: the frame's own size, with rho of its 48 rows
    np.testing.assert_array_equal(unet_predictor(path, internal_height=64)(f, RADIUS), ort(f, RADIUS))
    with torch.no_grad():
        x = torch.from_numpy(preprocess_frame(f, version=5))[None]
        pad = (-W) % 8, (-H) % 8
        x = torch.nn.functional.pad(x, (0, pad[0], 0, pad[1]), mode="reflect")
        rho_t = torch.full((1, 1, 1, 1), frame_radius_param(f, RADIUS, 5))
        want = model(x, rho_t)[0, 0, :H, :W].numpy()
    fg = f.mask
    np.testing.assert_allclose(ort(f, RADIUS)[fg], want[fg], atol=1e-5)
    # taller: point-sampled down to the most rows, rho of those rows
    got = unet_predictor(path)(f, RADIUS)  # the export's own internal height, 32
    np.testing.assert_array_equal(got, at_internal_resolution(ort, 32, up=False)(f, RADIUS))
