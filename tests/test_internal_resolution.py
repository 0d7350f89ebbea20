"""Screen-space AO at an internal resolution (neuralao.runtime.internal_resolution): the GL passes against the
numpy reference, the upsampling against closed forms, and the shipped U-Net's resolution independence.

Resolution independence is the property a user needs: the same view rendered at 256 and at 1024
pixels gives the same AO once the 1024 result is averaged down to 256. Measured with the shipped
default model on three test meshes (horse, KnightArmor, Cornell box), mean |difference| over
foreground blocks: 0.005 / 0.019 / 0.0008 at the internal height 256, against 0.050 / 0.121 / 0.036
when the network runs at the frame's own resolution (GTAO: 0.005 / 0.032 / 0.003).
"""

from __future__ import annotations

import numpy as np
import onnx
import pytest

from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
from neuralao.pipeline.geometry.camera import interior, orbit
from neuralao.pipeline.geometry.scene import load_scene
from neuralao.runtime.baselines import gbuffer_textures
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.internal_resolution import (
    ScalingPasses,
    at_internal_resolution,
    downsample_frame,
    internal_size,
    run_upsample_gl,
    sample_index,
    upsample_ao,
)
from neuralao.runtime.shipped import default_model, pure_unet_export

CASES = [
    ("spot", orbit, (200, 150), 64),
    ("cornell_box", interior, (300, 300), 100),
    ("sponza_partial", interior, (480, 270), 64),
]


@pytest.fixture(scope="module")
def frames():
    out = {}
    for name, cams, size, _ in CASES:
        scene = load_scene(name)
        out[name] = render_gbuffer(scene, cams(scene, 3, *size, seed=0)[1])
    return out


def test_sample_index_is_the_pixel_under_each_texel_centre():
    for low, high in ((256, 1080), (455, 1920), (3, 7), (64, 64), (100, 300)):
        idx = sample_index(low, high)
        centre = (np.arange(low) + 0.5) * high / low
        assert idx.min() >= 0 and idx.max() < high
        assert np.all(idx <= centre) and np.all(centre < idx + 1)  # floor of the centre, exactly


def test_internal_size_keeps_aspect_both_ways():
    assert internal_size(1920, 1080, 256) == (455, 256)
    assert internal_size(128, 128, 256) == (256, 256)
    assert internal_size(640, 480, None) == (640, 480)


@pytest.mark.parametrize("name,internal", [(c[0], c[3]) for c in CASES])
def test_gl_point_sampling_matches_numpy(frames, name, internal):
    frame = frames[name]
    h, w = frame["mask"].shape
    lw, lh = internal_size(w, h, internal)
    low = downsample_frame(frame, lw, lh)
    with ScalingPasses((lw, lh), (w, h)) as p:
        p.upload(frame)
        p.downsample()
        got_pos, got_nrm = p.read_low()
    hp, hn = gbuffer_textures(frame)
    rows = h - 1 - sample_index(lh, h)[::-1]
    cols = sample_index(lw, w)
    np.testing.assert_array_equal(got_pos, hp[rows][:, cols])  # exact copies, never blends
    np.testing.assert_array_equal(got_nrm, hn[rows][:, cols])
    np.testing.assert_array_equal(got_pos[..., 3] > 0.5, low["mask"])


@pytest.mark.parametrize("name,internal", [(c[0], c[3]) for c in CASES])
def test_gl_upsampling_matches_numpy(frames, name, internal):
    frame = frames[name]
    h, w = frame["mask"].shape
    lw, lh = internal_size(w, h, internal)
    ao_low = np.random.default_rng(1).uniform(0, 1, (lh, lw)).astype(np.float32)
    ref, got = upsample_ao(ao_low, frame), run_upsample_gl(ao_low, frame)
    assert got.shape == ref.shape == (h, w) and got.dtype == np.float32
    assert np.abs(got - ref).max() <= TOL.upsample_glsl_vs_numpy
    np.testing.assert_array_equal(got[~frame["mask"]], 1.0)


@pytest.mark.parametrize("value", [0.0, 0.37, 1.0])
def test_upsampling_a_constant_gives_the_constant(frames, value):
    """Weights are normalised: constant AO stays constant on every foreground pixel (closed form)."""
    frame = frames["cornell_box"]
    lw, lh = internal_size(300, 300, 100)
    out = upsample_ao(np.full((lh, lw), value, np.float32), frame)
    np.testing.assert_allclose(out[frame["mask"]], value, atol=1e-6)


def test_upsampling_keeps_an_edge_between_surfaces():
    """Two planes at depths 1 and 3 with AO 0.2 and 0.9: the bilateral weights keep the step sharp
    (a plain bilinear upsampling blends it over the 4 x 4 texels around the edge)."""
    h, w = 60, 80
    depth = np.where(np.arange(w)[None, :] < 37, 1.0, 3.0) * np.ones((h, 1))
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    frame = {
        "depth": depth.astype(np.float32),
        "normal_cam": normal.astype(np.float32),
        "mask": np.ones((h, w), bool),
        "yfov": 0.8,
    }
    lw, lh = internal_size(w, h, 15)
    low = downsample_frame(frame, lw, lh)
    ao_low = np.where(low["depth"] < 2.0, 0.2, 0.9).astype(np.float32)
    out = upsample_ao(ao_low, frame)
    # The floor (1e-3 of the spatial weight) is all that leaks across: <= 1e-3 x (spatial weight of the
    # far side / near side, up to ~3 next to the edge) x the 0.7 step; a blending filter is off by ~0.35.
    np.testing.assert_allclose(out, np.where(depth < 2.0, 0.2, 0.9), atol=3e-3)


def _block_mean(a: np.ndarray, mask: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    h, w = a.shape
    total = (a * mask).reshape(h // k, k, w // k, k).sum((1, 3))
    count = mask.reshape(h // k, k, w // k, k).sum((1, 3))
    return total / np.maximum(count, 1), count == k * k


@pytest.fixture(scope="module", params=["default", "pure"])
def default_unet(request):
    """The shipped default U-Net (a hybrid: its predictor runs GTAO itself) and the shipped pure one, each
    at the frame's own size."""
    from neuralao.pipeline.evaluation.test_split import unet_predictor

    onnx = default_model("unet") if request.param == "default" else pure_unet_export() / "model.onnx"
    return unet_predictor(onnx)


@pytest.fixture(scope="module")
def pure_unet():
    from neuralao.pipeline.evaluation.test_split import unet_predictor

    return unet_predictor(pure_unet_export() / "model.onnx")


@pytest.mark.parametrize("name,cams", [("horse", orbit), ("cornell_box", interior)])
def test_shipped_unet_is_resolution_independent(default_unet, name, cams):
    """The same view at 256 and 1024 pixels, the 1024 AO averaged over 4 x 4 blocks of foreground:
    within TOL.resolution_independence_mean_abs at the internal height 256."""
    scene = load_scene(name)
    cam = cams(scene, 3, 256, 256, seed=1)[1]
    low, high = render_gbuffer(scene, cam), render_gbuffer(scene, cam.with_size(1024, 1024))
    predict = at_internal_resolution(default_unet, 256)
    radius = 0.0625 * scene.diagonal
    a, b = predict(low, radius), predict(high, radius)
    np.testing.assert_array_equal(a, default_unet(low, radius))  # a 256 frame runs as it is
    mean_b, full = _block_mean(b, high["mask"].astype(np.float64), 4)
    keep = full & low["mask"]
    assert keep.mean() > 0.05
    diff = np.abs(a - mean_b)[keep]
    assert diff.mean() <= TOL.resolution_independence_mean_abs, diff.mean()


def test_shipped_unet_mean_ao_does_not_increase_with_radius(default_unet):
    scene = load_scene("KnightArmor")
    frame = render_gbuffer(scene, orbit(scene, 3, 128, 128, seed=1)[1])
    means = [
        float(default_unet(frame, r * scene.diagonal)[frame["mask"]].mean())
        for r in (1 / 32, 1 / 16, 1 / 8, 1 / 4)
    ]
    assert all(b <= a for a, b in zip(means[:-1], means[1:], strict=True)), means


def test_infer_frame_follows_the_declared_internal_height(pure_unet, tmp_path):
    """`infer` runs a U-Net at the height its export declares (manifest ``internal_height``)."""
    import json

    from neuralao.runtime.predict import declared_internal_height
    from neuralao.runtime.predict import unet_infer_frame as infer_frame

    src = pure_unet_export() / "model.onnx"
    model = onnx.load(src)  # the export's own declaration (ONNX metadata, then manifest) says 64 rows
    for prop in model.metadata_props:
        if prop.key == "internal_height":
            prop.value = "64"
    onnx.save(model, tmp_path / "model.onnx")
    manifest = json.loads((src.parent / "manifest.json").read_text()) | {"internal_height": 64}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    assert declared_internal_height(tmp_path / "model.onnx") == 64
    scene = load_scene("spot")
    frame = render_gbuffer(scene, orbit(scene, 3, 192, 128, seed=1)[1])
    radius = 0.125 * scene.diagonal
    want = at_internal_resolution(pure_unet, 64)(frame, radius)
    np.testing.assert_array_equal(infer_frame(tmp_path / "model.onnx", frame, radius), want)
    np.testing.assert_array_equal(
        infer_frame(tmp_path / "model.onnx", frame, radius, internal_height=None), pure_unet(frame, radius)
    )
