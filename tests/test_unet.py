"""DeepAO U-Net (pipeline/models/unet.py, pipeline/models/unet_train.py, export/unet.py): model
shapes and size, the masked SSIM loss, training on a tiny real dataset (NaN stop, resumption),
checkpoints, and the export through onnxruntime, OpenCV dnn and the generated GLSL on Mesa.

One tiny dataset (spot for training, a Cornell-box interior for validation, 40x36 px, 8 rays) and
one tiny trained U-Net (widths 2/4/8, pad multiple 4) are shared by the module.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest
import torch
from helpers import onnx_vs_torch_tol

from neuralao.pipeline.models.checkpoint import count_parameters
from neuralao.pipeline.models.unet import PaddedUNet, UNet, UNetArgs, build_model, model_args_dict, predict
from neuralao.pipeline.models.unet_frames import FrameSet, load_dataset_frames
from neuralao.pipeline.models.unet_train import (
    KIND,
    UNetTrainSettings,
    load_checkpoint,
    masked_ssim_loss,
    model_from_checkpoint,
    partial_path,
    ssim_map,
    train,
    training_loss,
)
from neuralao.runtime.foundation import metrics
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.unet_input import PREPROCESS_VERSION, preprocess, radius_param

# Tiny but real: ~20 ms per epoch on one thread; threads=1 makes runs bitwise reproducible.
TINY = UNetTrainSettings(
    epochs=30, batch_size=4, lr=1e-2, crop=16, crops_per_frame=4, widths=[2, 4, 8], threads=1
)
FRAME_SIZE = (40, 36)  # width, height: not powers of two
RHO = 0.3  # a radius parameter (rho = R / (mean depth tan(yfov/2))) for the model-only tests


def _t(a) -> torch.Tensor:
    """(H, W) array -> (1, 1, H, W) float32 tensor."""
    return torch.from_numpy(np.asarray(a, dtype=np.float32))[None, None]


def _random_x(h: int, w: int, seed: int = 0) -> np.ndarray:
    """(4, H, W) float32 network input: depth around 1, unit normals facing the viewer."""
    rng = np.random.default_rng(seed)
    depth = 1.0 + 0.2 * rng.standard_normal((h, w))
    n = rng.standard_normal((3, h, w))
    n[2] = np.abs(n[2]) + 0.3
    n /= np.linalg.norm(n, axis=0, keepdims=True)
    return np.concatenate([depth[None], n]).astype(np.float32)


def _expected_parameters(widths, in_channels: int = 5) -> int:
    """Hand count: 3x3 convs (9 cin cout + cout), batch-norm scale + shift, the 1x1 output conv."""
    w = list(widths)
    down = sum(9 * (in_channels if i == 0 else w[i - 1]) * w[i] + w[i] for i in range(len(w)))
    up = sum(9 * w[i + 1] * w[i] + w[i] + 2 * w[i] for i in range(len(w) - 1))
    fuse = sum(9 * 2 * w[i] * w[i] + w[i] for i in range(len(w) - 1))
    return down + up + fuse + w[0] + 1


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset
    from neuralao.pipeline.tracing.labeller import LabelSettings

    out = tmp_path_factory.mktemp("unet-ds")
    settings = DatasetSettings(
        name="tiny-unet",
        scenes=[
            SceneSpec("spot", "spot", views=4, split="train"),
            SceneSpec("box", "cornell_box", cameras="interior", views=2, split="val"),
        ],
        size=FRAME_SIZE,
        labels=LabelSettings(rays=8, radii_rel=[0.125, 0.25]),
        holdout_every=4,
        frames_per_shard=4,
    )
    build_dataset(settings, out, progress=False)
    return out


@pytest.fixture(scope="module")
def frames(dataset):
    """(train FrameSet, val FrameSet, dataset info) of the tiny dataset."""
    return load_dataset_frames(dataset)


@pytest.fixture(scope="module")
def trained(frames, tmp_path_factory):
    train_set, val_set, info = frames
    out = tmp_path_factory.mktemp("unet-ckpt") / "unet.pt"
    ckpt = train(TINY, train_set, val_set, out, info)
    return out, ckpt


@pytest.fixture(scope="module")
def exported(trained, tmp_path_factory):
    from neuralao.export.unet import export_checkpoint

    path, _ = trained
    out = tmp_path_factory.mktemp("unet-export") / "unet"
    manifest = export_checkpoint(path, out)
    return out, manifest


# ----------------------------------------------------------------------------------------------- model


@pytest.mark.parametrize(("h", "w"), [(8, 8), (37, 53), (53, 37), (9, 8), (64, 48), (15, 17)])
def test_output_has_the_input_size_and_lies_in_unit_interval(h, w):
    torch.manual_seed(0)
    model = UNet().eval()  # default widths 4/8/16/32: pad multiple 8
    assert model.pad_multiple == 8
    x = torch.from_numpy(np.stack([_random_x(h, w, 1), _random_x(h, w, 2)]))
    r = torch.full((2, 1, 1, 1), RHO)
    with torch.no_grad():
        y = PaddedUNet(model)(x, r)
    assert y.shape == (2, 1, h, w) and y.dtype == torch.float32
    assert torch.isfinite(y).all() and y.min() >= 0.0 and y.max() <= 1.0
    # Samples of a batch are independent (eval mode): batch row 1 == the second image alone.
    tol = onnx_vs_torch_tol(y.numpy(), model)  # same math, kernels picked per batch size: fp32 rounding only
    np.testing.assert_allclose(y[1, 0].numpy(), predict(model, x[1].numpy(), RHO), rtol=0, atol=tol)
    # The pad/crop wrapper == numpy reflect padding (bottom/right) + the raw network + crop.
    ph, pw = (-h) % 8, (-w) % 8
    xp = np.pad(x[0].numpy(), [(0, 0), (0, ph), (0, pw)], mode="reflect")
    with torch.no_grad():
        raw = model(torch.from_numpy(xp)[None], r[:1])
    assert raw.shape == (1, 1, h + ph, w + pw)
    # (batch of 1 vs batch of 2: same math, torch may pick other kernels -> fp32 rounding only)
    np.testing.assert_allclose(raw[0, 0, :h, :w].numpy(), y[0, 0].numpy(), rtol=0, atol=tol)


@pytest.mark.parametrize(("h", "w"), [(1, 1), (7, 40), (40, 7)])
def test_images_smaller_than_the_pad_multiple_are_a_clear_error(h, w):
    model = UNet().eval()
    with pytest.raises(NeuralaoError, match="smaller than the U-Net's pad multiple 8"):
        predict(model, _random_x(h, w), RHO)


def test_parameter_count_matches_a_hand_count():
    # 4/8/16/32 by hand (5 input channels: G-buffer + radius): down 184+296+1168+4640,
    # up (conv+BN) 300+1176+4656, fuse 292+1160+4624, out 5.
    assert count_parameters(UNet()) == _expected_parameters([4, 8, 16, 32]) == 18501
    for widths in ([2, 4], [3, 5, 7], [2, 4, 8, 16, 32]):
        model = build_model(model_args_dict(UNetArgs(widths=widths)))  # via the checkpoint dict path
        assert count_parameters(model) == _expected_parameters(widths)
        assert model.pad_multiple == 2 ** (len(widths) - 1)
    for bad in ([4], [4, 0], []):
        with pytest.raises(NeuralaoError, match="widths"):
            UNet(UNetArgs(widths=bad))


@pytest.mark.parametrize("version", [2, 3])
def test_preprocess_is_scale_invariant_and_zeroes_background(version):
    """Scaling depth and the radius together leaves what the network sees unchanged: version 2's depth
    over the mean; version 3's log depth minus rho (what its graph feeds the network)."""
    rng = np.random.default_rng(0)
    depth = rng.uniform(2.0, 5.0, (9, 11)).astype(np.float32)
    normals = rng.standard_normal((9, 11, 3)).astype(np.float32)
    mask = rng.uniform(size=(9, 11)) < 0.7
    depth[~mask] = 0.0
    x = preprocess(depth, normals, mask, version)
    assert x.shape == (4, 9, 11) and x.dtype == np.float32
    assert np.all(x[:, ~mask] == 0.0)
    scaled = preprocess(depth * 37.0, normals, mask, version)
    rho, rho_scaled = (
        radius_param(r, d, mask, 0.8, version) for r, d in ((0.5, depth), (18.5, depth * 37.0))
    )
    if version == 2:
        assert float(x[0][mask].mean()) == pytest.approx(1.0, abs=1e-6)  # depth / mean foreground depth
        np.testing.assert_allclose(scaled, x, rtol=1e-6)
        assert rho_scaled == pytest.approx(rho, rel=1e-6)
    else:
        np.testing.assert_allclose(x[0][mask], np.log(depth[mask]), rtol=1e-6)
        np.testing.assert_allclose(scaled[0][mask] - rho_scaled, x[0][mask] - rho, atol=1e-6)
        np.testing.assert_array_equal(scaled[1:], x[1:])
    with pytest.raises(NeuralaoError, match="shapes"):
        preprocess(depth, normals[..., :2], mask, version)


# ----------------------------------------------------------------------------------------------- loss


def _loss(pred, ref, mask) -> float:
    return float(masked_ssim_loss(_t(pred), _t(ref), _t(mask)))


def test_ssim_loss_is_zero_for_identical_images_and_matches_numpy_ssim():
    rng = np.random.default_rng(1)
    h, w = 23, 31
    for seed in range(3):
        ref = rng.uniform(0, 1, (h, w)).astype(np.float32)
        pred = np.clip(ref + rng.normal(0, 0.2, (h, w)), 0, 1).astype(np.float32)
        mask = rng.uniform(size=(h, w)) < 0.6
        assert _loss(ref, ref, mask) == 0.0, seed  # numerator and denominator are the same float ops
        # Per-pixel map and masked mean agree with the float64 numpy metric used by every report.
        map32 = ssim_map(_t(pred), _t(ref))[0, 0].numpy()
        assert np.abs(map32 - metrics.ssim_map(pred, ref)).max() <= TOL.ssim_fp32_vs_fp64
        want = metrics.masked_ssim(pred, ref, mask)
        assert abs((1.0 - _loss(pred, ref, mask)) - want) <= TOL.ssim_fp32_vs_fp64
        assert 0.0 < want < 1.0  # not a degenerate comparison
    # A batch: 1 - loss is the pixel-weighted mean of the per-image masked SSIMs.
    refs = rng.uniform(0, 1, (2, h, w)).astype(np.float32)
    preds = np.clip(refs + rng.normal(0, 0.3, (2, h, w)), 0, 1).astype(np.float32)
    masks = np.stack([rng.uniform(size=(h, w)) < 0.2, rng.uniform(size=(h, w)) < 0.9])
    loss = float(
        masked_ssim_loss(*(torch.from_numpy(a.astype(np.float32))[:, None] for a in (preds, refs, masks)))
    )
    per = [metrics.masked_ssim(preds[i], refs[i], masks[i]) for i in range(2)]
    want = (per[0] * masks[0].sum() + per[1] * masks[1].sum()) / masks.sum()
    assert abs((1.0 - loss) - want) <= TOL.ssim_fp32_vs_fp64


@pytest.mark.parametrize(("a", "b"), [(0.0, 0.0), (1.0, 1.0), (0.3, 0.7), (0.0, 1.0), (0.5, 0.5)])
def test_ssim_loss_on_constant_crops_is_finite_and_exact(a, b):
    """Zero variance everywhere: SSIM = (2ab + C1) / (a^2 + b^2 + C1) (the C2 factor is 1)."""
    pred, ref = np.full((16, 16), a, np.float32), np.full((16, 16), b, np.float32)
    mask = np.ones((16, 16), bool)
    loss = _loss(pred, ref, mask)
    want = 1.0 - (2 * a * b + 1e-4) / (a * a + b * b + 1e-4)
    assert math.isfinite(loss)
    assert abs(loss - want) <= TOL.ssim_fp32_vs_fp64
    if a == b:
        assert loss == 0.0


def test_ssim_loss_ignores_the_prediction_outside_the_mask():
    rng = np.random.default_rng(2)
    h, w = 20, 24
    ref = rng.uniform(0, 1, (h, w)).astype(np.float32)
    ref[:, :8] = 1.0  # background label (AO 1 by convention)
    mask = np.zeros((h, w), bool)
    mask[:, 8:] = rng.uniform(size=(h, w - 8)) < 0.8  # background band + invalid foreground pixels
    pred = np.clip(ref + rng.normal(0, 0.2, (h, w)), 0, 1).astype(np.float32)
    base = _loss(pred, ref, mask)
    assert 0.0 < base < 1.0
    for junk in (0.0, 1e6, -1e6, np.nan, np.inf):
        p = torch.tensor(np.where(mask, pred, np.float32(junk)))[None, None].requires_grad_(True)
        loss = masked_ssim_loss(p, _t(ref), _t(mask))
        assert float(loss.detach()) == base, junk
        loss.backward()
        assert torch.isfinite(p.grad).all() and (p.grad[0, 0][torch.from_numpy(~mask)] == 0).all()
        assert (p.grad[0, 0][torch.from_numpy(mask)] != 0).any()  # the foreground does get gradient
    # No valid pixel at all: zero loss that still backpropagates.
    p = _t(pred).requires_grad_(True)
    loss = masked_ssim_loss(p, _t(ref), _t(np.zeros((h, w))))
    loss.backward()
    assert float(loss.detach()) == 0.0 and (p.grad == 0).all()


def test_the_squared_error_term_adds_the_weighted_masked_mse_and_sees_a_bias_ssim_hardly_sees():
    rng = np.random.default_rng(3)
    h, w = 20, 24
    ref = rng.uniform(0.4, 0.9, (h, w)).astype(np.float32)
    full = np.ones((h, w), bool)
    assert _loss(ref - 0.05, ref, full) < 0.005  # a bias of 0.05 costs SSIM almost nothing
    assert abs(float(training_loss(_t(ref - 0.05), _t(ref), _t(full), mse_weight=10.0)) - 0.025) < 0.005
    mask = rng.uniform(size=(h, w)) < 0.7
    pred = np.where(mask, ref - 0.05, np.float32(np.nan)).astype(np.float32)  # biased, junk outside
    p = _t(pred).requires_grad_(True)
    plain = training_loss(p, _t(ref), _t(mask))
    assert float(plain.detach()) == _loss(np.where(mask, pred, 0), ref, mask)  # weight 0: SSIM alone
    loss = training_loss(p, _t(ref), _t(mask), mse_weight=10.0)
    mse = float(np.mean((pred[mask].astype(np.float64) - ref[mask]) ** 2))
    assert abs(float(loss.detach()) - (float(plain.detach()) + 10.0 * mse)) <= 1e-6
    loss.backward()
    assert torch.isfinite(p.grad).all() and (p.grad[0, 0][torch.from_numpy(~mask)] == 0).all()
    empty = training_loss(_t(ref - 0.05), _t(ref), _t(np.zeros((h, w))), mse_weight=10.0)
    assert float(empty) == 0.0  # no valid pixel: no loss, as SSIM alone


# ----------------------------------------------------------------------------------------------- training


def test_training_lowers_the_loss_and_records_validation(trained, frames):
    path, ckpt = trained
    _, val_set, info = frames
    hist = ckpt["history"]
    assert [h["epoch"] for h in hist] == list(range(1, TINY.epochs + 1)) and ckpt["complete"]
    first = np.mean([h["train_loss"] for h in hist[:3]])
    last = np.mean([h["train_loss"] for h in hist[-3:]])
    assert last < 0.85 * first, (first, last)  # measured ~0.80 -> ~0.65
    for h in hist:
        assert 0.0 < h["val_ssim"] <= 1.0 and 0.0 <= h["val_rmse"] < 1.0 and h["val_frames"] == len(val_set)
    assert set(ckpt["metrics"]["per_scene"]) == {"box"} == set(info["val_scenes"])
    assert (
        ckpt["dataset"]["training_scenes"] == ["spot"]
        and ckpt["dataset"]["dataset_hash"] == info["dataset_hash"]
    )
    # The recorded validation metrics == neuralao.runtime.foundation.metrics on the composited prediction
    # (background 1).
    model = model_from_checkpoint(load_checkpoint(path))
    ssim, rmse = [], []
    for i in range(len(val_set)):
        x = val_set.x[i].numpy()
        for j in range(val_set.y.shape[1]):  # every label radius
            fg = np.any(x[1:4] != 0, axis=0)  # a zero normal is background; log depth can be <= 0
            pred = np.where(fg, predict(model, x, float(val_set.rho[i, j])), 1.0).astype(np.float32)
            ref, mask = val_set.y[i, j].float().numpy(), val_set.m[i, j].numpy()
            ssim.append(metrics.masked_ssim(pred, ref, mask))
            rmse.append(metrics.masked_rmse(pred, ref, mask))
    assert len(ckpt["metrics"]["per_radius"]) == val_set.y.shape[1] == 2
    assert ckpt["metrics"]["val_ssim"] == pytest.approx(np.mean(ssim), abs=1e-12)
    assert ckpt["metrics"]["val_rmse"] == pytest.approx(np.mean(rmse), abs=1e-12)
    assert hist[-1]["val_ssim"] == ckpt["metrics"]["val_ssim"]


def _poisoned(data: FrameSet, frame: int, where: str, value: float) -> FrameSet:
    x, y = data.x.clone(), data.y.clone()
    m = data.m[frame].all(0)  # valid at every radius
    r, c = (int(v) for v in torch.nonzero(m)[len(torch.nonzero(m)) // 2])  # a valid foreground pixel
    if where == "x":
        x[frame, 0, r, c] = value
    else:
        y[frame, :, r, c] = value
    return FrameSet(x, y, data.m, data.rho, data.radii, data.names, data.scenes)


@pytest.mark.parametrize(("where", "value"), [("x", float("nan")), ("y", float("inf"))])
def test_non_finite_batch_stops_training_naming_the_batch(frames, tmp_path, where, value):
    train_set, _, info = frames
    bad = 1
    data = _poisoned(train_set, bad, where, value)
    out = tmp_path / "nan.pt"
    settings = replace(TINY, epochs=2, batch_size=1, crop=0, crops_per_frame=1)  # whole frames, one per batch
    with pytest.raises(NeuralaoError) as e:
        train(settings, data, None, out, info)
    msg = str(e.value)
    assert "non-finite" in msg, msg
    m = re.search(r"epoch 1 batch (\d+)/(\d+) \(frames ([^)]*)\)", msg)
    assert m is not None, msg
    assert int(m.group(2)) == len(train_set) and m.group(3) == train_set.names[bad]
    assert not out.exists() and not partial_path(out).exists()  # nothing written for a failed epoch


def test_diverging_training_stops_on_a_non_finite_loss(frames, tmp_path):
    """lr 1e20: Adam's first step moves every weight by ~1e20, so the second batch's activations
    overflow float32 (inf - inf = NaN inside the network) although the data are finite."""
    train_set, _, info = frames
    settings = replace(TINY, epochs=1, batch_size=1, crop=0, crops_per_frame=1, lr=1e20)
    out = tmp_path / "diverged.pt"
    with pytest.raises(
        NeuralaoError, match=r"loss is (nan|inf) in epoch 1 batch 2/3 \(frames spot/\d+\); lower lr"
    ):
        train(settings, train_set, None, out, info)
    assert not out.exists() and not partial_path(out).exists()


class _Interrupted(Exception):
    pass


def _state_equal(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_interrupted_training_resumes_to_the_same_weights(frames, tmp_path):
    train_set, val_set, info = frames
    settings = replace(TINY, epochs=3, widths=[2, 4])
    reference = train(settings, train_set, val_set, tmp_path / "ref.pt", info)

    out = tmp_path / "run.pt"

    def stop_after_two(epoch, ckpt):
        if epoch == 2:
            raise _Interrupted

    with pytest.raises(_Interrupted):
        train(settings, train_set, val_set, out, info, on_epoch_end=stop_after_two)
    assert not out.exists()  # an interrupted run leaves no final checkpoint ...
    partial = load_checkpoint(partial_path(out))  # ... but a loadable partial one
    assert partial["epoch"] == 2 and not partial["complete"]

    seen = []
    resumed = train(settings, train_set, val_set, out, info, on_epoch_end=lambda e, c: seen.append(e))
    assert seen == [3]  # only the missing epoch ran
    assert resumed["history"][:2] == partial["history"]  # same records, wall times included: not retrained
    assert not partial_path(out).exists() and out.exists()
    assert _state_equal(resumed["state_dict"], reference["state_dict"])
    assert _state_equal(load_checkpoint(out)["state_dict"], reference["state_dict"])
    assert [h["train_loss"] for h in resumed["history"]] == [h["train_loss"] for h in reference["history"]]

    # A finished run continued to more epochs == one longer run.
    longer = tmp_path / "longer.pt"
    train(replace(settings, epochs=2), train_set, val_set, longer, info)
    continued = train(settings, train_set, val_set, longer, info)
    assert _state_equal(continued["state_dict"], reference["state_dict"])
    # Another config (seed) does not continue: it starts over and equals a fresh run.
    other = replace(settings, epochs=1, seed=1)
    restarted = train(other, train_set, val_set, longer, info)
    fresh = train(other, train_set, val_set, tmp_path / "fresh.pt", info)
    assert _state_equal(restarted["state_dict"], fresh["state_dict"])
    assert not _state_equal(
        fresh["state_dict"],
        train(replace(settings, epochs=1), train_set, val_set, tmp_path / "seed0.pt", info)["state_dict"],
    )


# ----------------------------------------------------------------------------------------------- checkpoints


def _mlp_checkpoint(path):
    from neuralao.pipeline.models.mlp import KIND as MLP_KIND
    from neuralao.pipeline.models.mlp import BakedMLP
    from neuralao.pipeline.models.mlp import model_args_dict as mlp_args

    model = BakedMLP(hidden=[8, 4])
    torch.save(
        {
            "kind": MLP_KIND,
            "format_version": 1,
            "model_args": mlp_args(model),
            "config": {},
            "state_dict": model.state_dict(),
            "metrics": {},
        },
        path,
    )


def test_checkpoint_is_plain_data_and_round_trips(trained, frames):
    path, ckpt = trained
    raw = torch.load(path, map_location="cpu", weights_only=True)  # plain data only
    assert raw["kind"] == KIND == "unet" and raw["model_args"]["widths"] == [2, 4, 8]
    assert raw["config"]["epochs"] == TINY.epochs and raw["epoch"] == TINY.epochs and raw["complete"]
    assert raw["preprocess"]["preprocess_version"] == str(PREPROCESS_VERSION)
    for key in ("state_dict", "optimizer", "rng", "history", "dataset", "metrics"):
        assert key in raw
    x = frames[1].x[0].numpy()
    np.testing.assert_array_equal(
        predict(model_from_checkpoint(load_checkpoint(path)), x, RHO),
        predict(model_from_checkpoint(ckpt), x, RHO),
    )


def test_wrong_kind_corrupt_unsafe_and_mismatched_checkpoints(tmp_path, frames, trained):
    mlp = tmp_path / "mlp.pt"
    _mlp_checkpoint(mlp)
    with pytest.raises(NeuralaoError, match="not a U-Net checkpoint"):
        load_checkpoint(mlp)
    from neuralao.export.unet import export_checkpoint

    with pytest.raises(NeuralaoError, match="not a U-Net checkpoint"):
        export_checkpoint(mlp, tmp_path / "exp")
    train_set, val_set, info = frames
    with pytest.raises(NeuralaoError, match="not a U-Net checkpoint"):  # train refuses to overwrite it
        train(replace(TINY, epochs=1), train_set, val_set, mlp, info)
    assert torch.load(mlp, weights_only=True)["kind"] == "mlp"  # the file is fine, only its kind is wrong

    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(NeuralaoError, match="cannot read checkpoint"):
        load_checkpoint(junk)
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(trained[0].read_bytes()[:2000])
    with pytest.raises(NeuralaoError, match="cannot read checkpoint"):
        load_checkpoint(truncated)
    unsafe = tmp_path / "unsafe.pt"  # a pickled object outside the weights_only allow-list
    torch.save({"kind": "unet", "model_args": {}, "state_dict": {}, "config": {}, "where": tmp_path}, unsafe)
    with pytest.raises(NeuralaoError, match="weights_only"):
        load_checkpoint(unsafe)
    with pytest.raises(NeuralaoError, match="not found"):
        load_checkpoint(tmp_path / "missing.pt")
    lacking = tmp_path / "lacking.pt"
    torch.save({"kind": "unet", "model_args": {}, "config": {}}, lacking)
    with pytest.raises(NeuralaoError, match="lacks 'state_dict'"):
        load_checkpoint(lacking)
    mismatched = tmp_path / "mismatched.pt"
    ckpt = dict(trained[1])
    ckpt["model_args"] = model_args_dict(UNetArgs(widths=[2, 4, 16]))
    torch.save(ckpt, mismatched)
    with pytest.raises(NeuralaoError, match="do not fit its model_args"):
        model_from_checkpoint(load_checkpoint(mismatched))


# ----------------------------------------------------------------------------------------------- export


def test_onnx_has_dynamic_size_and_metadata(exported, trained):
    from neuralao.export.onnx_io import get_metadata, load_onnx

    out, manifest = exported
    _, ckpt = trained
    proto = load_onnx(out / "model.onnx")
    (inp, rad), (outp,) = proto.graph.input, proto.graph.output
    assert inp.name == "gbuffer" and rad.name == "radius" and outp.name == "ao"
    for vi, channels in ((inp, 4), (outp, 1)):
        d = vi.type.tensor_type.shape.dim
        assert d[1].dim_value == channels
        assert (d[2].dim_param, d[3].dim_param) == ("height", "width") and not d[2].dim_value
    assert [d.dim_value for d in rad.type.tensor_type.shape.dim] == [1, 1, 1, 1]
    meta = get_metadata(proto)
    assert meta["neuralao_kind"] == "unet" and meta["pad_multiple"] == 4  # JSON-decoded
    assert int(meta["preprocess_version"]) == PREPROCESS_VERSION and meta["pad_mode"] == "reflect"
    assert int(meta["parameters"]) == _expected_parameters([2, 4, 8]) == manifest["parameters"]
    assert meta["training_scenes"] == ["spot"] and meta["validation_scenes"] == ["box"]
    assert meta["validation_error"]["val_ssim"] == pytest.approx(ckpt["metrics"]["val_ssim"])
    assert int(meta["epochs"]) == TINY.epochs and meta["dataset_hash"] == ckpt["dataset"]["dataset_hash"]
    assert "depth_units" in meta and "normal_space" in meta and "mask_convention" in meta
    assert "rho = log(R / tan(yfov/2))" in meta["radius_input"] and "u_radius" in meta["radius_glsl"]
    assert meta["trained_radii_rel"] == [0.125, 0.25]
    assert "BatchNormalization" not in manifest["ops"]  # the TorchScript exporter folds it
    checks = manifest["checks"]
    assert (out / "glsl").is_dir()
    assert checks["onnxruntime_vs_torch"] <= checks["tolerance"]["onnxruntime_vs_torch"]
    assert checks["tolerance"]["onnxruntime_vs_torch"] == onnx_vs_torch_tol(1.0, proto)  # AO in [0, 1]


@pytest.mark.parametrize(("w", "h"), [(40, 36), (37, 53), (16, 16), (5, 4), (101, 67)])
def test_onnxruntime_and_opencv_match_torch(exported, trained, w, h):
    from neuralao.export.onnx_io import run_onnxruntime, run_opencv
    from neuralao.export.unet import opencv_runner
    from neuralao.runtime.predict import ort_runner, run_padded

    out, _ = exported
    model = model_from_checkpoint(load_checkpoint(trained[0]))
    x = _random_x(h, w, seed=w * h)
    x[:, :, : w // 5] = 0.0  # background columns
    ref = predict(model, x, RHO)
    y_ort = run_padded(ort_runner(out / "model.onnx"), x, 4, RHO)
    y_cv = run_padded(opencv_runner(out / "model.onnx"), x, 4, RHO)
    assert y_ort.shape == y_cv.shape == ref.shape == (h, w)
    assert np.abs(y_ort - ref).max() <= onnx_vs_torch_tol(ref, out / "model.onnx")
    if min(h, w) > 4:
        # OpenCV dnn 5.0.0 returns garbage (all 1, varying from run to run) when a padded side equals
        # the pad multiple, i.e. the deepest feature map is 1 pixel high or wide: skip that case there.
        assert np.abs(y_cv - y_ort).max() <= TOL.opencv_vs_onnx
    assert np.ptp(ref) > 1e-3  # a non-constant output: the comparison means something
    if h % 4 == 0 and w % 4 == 0:  # the raw graph at this size, no padding involved
        feed = {"gbuffer": x[None], "radius": np.full((1, 1, 1, 1), RHO, np.float32)}
        raw = run_onnxruntime(out / "model.onnx", feed)[0]
        with torch.no_grad():
            want = model(torch.from_numpy(x)[None], torch.full((1, 1, 1, 1), RHO)).numpy()
        assert raw.shape == (1, 1, h, w)
        assert np.abs(raw - want).max() <= onnx_vs_torch_tol(want, out / "model.onnx")
        if min(h, w) > 4:
            assert np.abs(run_opencv(out / "model.onnx", feed) - raw).max() <= TOL.opencv_vs_onnx


def test_infer_frame_composites_background(exported, trained, frames):
    from neuralao.runtime.predict import unet_infer_frame as infer_frame

    out, _ = exported
    model = model_from_checkpoint(load_checkpoint(trained[0]))
    val = frames[1]
    fg = np.abs(val.x[0, 1:].numpy()).sum(axis=0) > 0
    depth = np.where(fg, np.exp(val.x[0, 0].numpy()) * 3.0, 0.0).astype(np.float32)  # log depth back
    frame = {
        "depth": depth,
        "normal_cam": np.moveaxis(val.x[0, 1:].numpy(), 0, -1),
        "mask": depth > 0,
        "yfov": 0.8,
    }
    fg = frame["mask"]
    with pytest.raises(NeuralaoError, match="--radius"):  # no label radii in the frame, none given
        infer_frame(out / "model.onnx", frame)
    ao = infer_frame(out / "model.onnx", frame, radius=0.5)
    assert ao.shape == depth.shape and np.all(ao[~frame["mask"]] == 1.0)
    rho = np.log(0.5 / np.tan(0.4))  # log(R / tan(yfov / 2))
    want = predict(model, preprocess(depth, frame["normal_cam"], fg), rho)[fg]
    assert np.abs(ao[fg] - want).max() <= onnx_vs_torch_tol(want, out / "model.onnx")


@pytest.fixture(scope="module")
def glsl_parity(exported, frames):
    """The export's own GLSL-vs-onnxruntime parity on the two validation frames (40x36) and a 37x29 crop."""
    from neuralao.export.unet import parity

    out, _ = exported
    val = frames[1]
    fr = []
    for i in range(len(val)):
        x = val.x[i].numpy()
        fr.append({"depth": x[0], "normal_cam": np.moveaxis(x[1:], 0, -1), "mask": x[0] > 0, "scene": "box"})
    return parity(out, frames=fr, sizes=[(37, 29)])


def test_glsl_matches_onnxruntime(glsl_parity):
    r = glsl_parity
    sizes = sorted({tuple(c["size"]) for c in r["checks"]})
    assert sizes == [(37, 29), (40, 36)] and all("max_abs_err" in c for c in r["checks"])
    assert r["passed"] and r["max_abs_err"] <= TOL.parity_unet_fp32
    assert r["tolerance"] == TOL.parity_unet_fp32


def test_out_of_range_inputs_stay_finite_everywhere(exported, trained, glsl_parity):
    """Network input depth 1e6 and normals of length 0 and 100 (sizes reuse the parity shaders)."""
    from neuralao.export.unet import glsl_runner
    from neuralao.runtime.predict import ort_runner, run_padded

    out, _ = exported
    model = model_from_checkpoint(load_checkpoint(trained[0]))
    h, w = 29, 37
    x = _random_x(h, w, seed=5)
    x[0] = 1e6
    x[1:, :, :12] = 0.0  # normal length 0
    x[1:, :, 12:25] *= 100.0  # normal length 100
    x[:, :4, :] = 0.0  # plus some background rows
    outputs = {
        "torch": predict(model, x, RHO),
        "onnxruntime": run_padded(ort_runner(out / "model.onnx"), x, 4, RHO),
        "glsl": run_padded(glsl_runner(out / "glsl"), x, 4, RHO),
    }
    for name, y in outputs.items():
        assert y.shape == (h, w), name
        assert np.all(np.isfinite(y)) and y.min() >= 0.0 and y.max() <= 1.0, (name, y.min(), y.max())


# ------------------------------------------------------------------------------------------- budget, schedule


def test_cosine_schedule_closed_form():
    from neuralao.pipeline.models.unet_train import lr_at

    s = replace(TINY, lr=1e-2, lr_schedule="cosine", warmup_steps=4, min_lr_ratio=0.1)
    total = 24
    lrs = [lr_at(s, k, total) for k in range(total)]
    assert lrs[:4] == pytest.approx([2.5e-3, 5e-3, 7.5e-3, 1e-2])  # linear warm-up
    assert lrs[4] == pytest.approx(1e-2) and lrs[-1] == pytest.approx(1e-3)  # lr ... lr * min_lr_ratio
    mid = 4 + (total - 4 - 1) / 2  # half-way through the decay: the mean of both ends
    assert lr_at(s, int(mid), total) == pytest.approx(1e-3 + 0.5 * 9e-3 * (1 + math.cos(math.pi * 9 / 19)))
    assert np.all(np.diff(lrs[4:]) <= 0)  # non-increasing after the warm-up
    assert lr_at(replace(s, lr_schedule="constant"), 17, total) == 1e-2
    with pytest.raises(NeuralaoError, match="lr_schedule"):
        lr_at(replace(s, lr_schedule="step"), 0, total)


def test_budget_plan_fits_the_budget():
    from neuralao.pipeline.models.unet_train import plan_budget

    s = replace(TINY, epochs=1000, budget_minutes=2.0)
    cal = {"seconds_per_step": 0.5, "val_seconds": 3.0}  # 10 steps + validation = 8 s an epoch
    assert plan_budget(s, 10, cal) == 15  # floor(120 / 8)
    assert plan_budget(replace(s, epochs=7), 10, cal) == 7  # epochs is an upper bound
    assert plan_budget(replace(s, budget_minutes=0.01), 10, cal) == 1  # at least one epoch


def test_budgeted_training_resumes_to_the_same_weights(frames, tmp_path, monkeypatch):
    """A budget run plans its epochs once (calibration), stores the plan, and an interrupted run
    resumed later follows the stored plan (no new calibration) to the weights of an uninterrupted run."""
    import neuralao.pipeline.models.unet_train as ut

    train_set, val_set, info = frames
    settings = replace(
        TINY, epochs=3, widths=[2, 4], budget_minutes=60.0, lr_schedule="cosine", warmup_steps=2
    )
    reference = train(settings, train_set, val_set, tmp_path / "ref.pt", info)
    plan = reference["plan"]
    assert plan["epochs"] == 3 and plan["seconds_data"] > 0 and plan["seconds_compute"] > 0
    # a step's cost counts its batch's reading (page faults where the frames do not fit in memory)
    assert plan["seconds_per_step"] == pytest.approx(plan["seconds_data"] + plan["seconds_compute"])
    assert [h["epoch"] for h in reference["history"]] == [1, 2, 3]
    wall = [h["wall_seconds"] for h in reference["history"]]
    assert wall == sorted(wall) and wall[-1] == pytest.approx(reference["wall_seconds"])
    lrs = [h["lr"] for h in reference["history"]]
    assert lrs[0] > lrs[1] > lrs[2] == pytest.approx(settings.lr * settings.min_lr_ratio)  # cosine to the end

    out = tmp_path / "run.pt"

    def stop_after_one(epoch, ckpt):
        if epoch == 1:
            raise _Interrupted

    with pytest.raises(_Interrupted):
        train(settings, train_set, val_set, out, info, on_epoch_end=stop_after_one)
    assert load_checkpoint(partial_path(out))["plan"]["epochs"] == 3

    def no_calibration(*a, **k):
        raise AssertionError("a resumed budget run must not calibrate again")

    monkeypatch.setattr(ut, "calibrate", no_calibration)
    resumed = train(settings, train_set, val_set, out, info)
    assert _state_equal(resumed["state_dict"], reference["state_dict"])
    assert [h["train_loss"] for h in resumed["history"]] == [h["train_loss"] for h in reference["history"]]


def test_constant_rate_budget_run_continues_to_a_larger_budget(frames, tmp_path, monkeypatch):
    """A constant-rate budget run asked for twice its budget continues from where it ended (no new
    calibration): its plan doubles, and it ends with the weights of one run of that many epochs."""
    import neuralao.pipeline.models.unet_train as ut

    train_set, val_set, info = frames
    settings = replace(TINY, epochs=100, widths=[2, 4], budget_minutes=1.0, lr_schedule="constant")
    reference = train(
        replace(settings, budget_minutes=0.0, epochs=4), train_set, val_set, tmp_path / "r.pt", info
    )

    monkeypatch.setattr(ut, "plan_budget", lambda s, steps, cal: 2)  # the budget buys two epochs
    out = tmp_path / "run.pt"
    first = train(settings, train_set, val_set, out, info)
    assert first["plan"]["epochs"] == 2 and first["complete"]

    def no_calibration(*a, **k):
        raise AssertionError("a continued budget run must not calibrate again")

    monkeypatch.setattr(ut, "calibrate", no_calibration)
    seen = []
    longer = train(
        replace(settings, budget_minutes=2.0),
        train_set,
        val_set,
        out,
        info,
        on_epoch_end=lambda e, c: seen.append(e),
    )
    assert seen == [3, 4] and longer["plan"]["epochs"] == 4 and longer["plan"]["extended_from"] == 2
    assert longer["history"][:2] == first["history"]
    assert _state_equal(longer["state_dict"], reference["state_dict"])
    # a cosine run's rate depends on where it ends: a larger budget starts it over
    assert ut.extended_plan(
        {"epochs": 2, "budget_minutes": 1.0}, replace(settings, lr_schedule="cosine", budget_minutes=2.0)
    ) == {
        "epochs": 2,
        "budget_minutes": 1.0,
    }


def test_reduced_resolution_variant_trains_and_starts_from_the_full_network(frames, trained, tmp_path):
    """scale=2: the U-Net runs at half resolution with a full-resolution refinement; ``init`` copies
    every weight of the full network whose shape matches (all but the refinement's)."""
    train_set, val_set, info = frames
    path, full = trained
    settings = replace(TINY, epochs=2, scale=2, crop=16, init=str(path))
    ckpt = train(settings, train_set, val_set, tmp_path / "half.pt", info)
    assert ckpt["model_args"]["scale"] == 2 and ckpt["init"]["tensors"] == len(full["state_dict"])
    model = model_from_checkpoint(ckpt)
    assert model.pad_multiple == 8  # 2 (scale) * 2**2 (two pooling steps)
    x = frames[1].x[0].numpy()
    y = predict(model, x, RHO)
    assert y.shape == x.shape[1:] and np.isfinite(y).all() and y.min() >= 0 and y.max() <= 1
    with pytest.raises(NeuralaoError, match="scale must be 1, 2 or 4"):
        UNet(UNetArgs(scale=3))


def test_corpus_fraction_cut_from_the_loaded_corpus_equals_a_fresh_load(tmp_path):
    """ship keeps one corpus in memory and cuts the corpus-size subsets from it: same frames, same order,
    same info as reading that fraction from disk."""
    from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset
    from neuralao.pipeline.tracing.labeller import LabelSettings

    settings = DatasetSettings(
        name="tiny-fractions",
        scenes=[SceneSpec(n, n, views=2, split="train") for n in ("spot", "cow", "bunny")]
        + [SceneSpec("box", "cornell_box", cameras="interior", views=1, split="val")],
        size=(32, 32),
        labels=LabelSettings(rays=4, radii_rel=[0.125, 0.25]),
        frames_per_shard=1,
    )
    build_dataset(settings, tmp_path, progress=False)
    full = load_dataset_frames(tmp_path)
    assert full[2]["training_scenes"] == ["bunny", "cow", "spot"]
    for fraction in (0.34, 0.5, 1.0):
        fresh, cut = (
            load_dataset_frames(tmp_path, fraction),
            load_dataset_frames(tmp_path, fraction, loaded=full),
        )
        assert cut[2] == fresh[2]
        for a, b in ((fresh[0], cut[0]), (fresh[1], cut[1])):
            assert a.names == b.names and a.scenes == b.scenes
            for k in ("x", "y", "m", "rho", "radii"):
                assert torch.equal(getattr(a, k), getattr(b, k)), k
    assert len(load_dataset_frames(tmp_path, 0.34)[2]["training_scenes"]) == 1
    with pytest.raises(NeuralaoError, match="train_fraction 1"):
        load_dataset_frames(tmp_path, 0.5, loaded=load_dataset_frames(tmp_path, 0.5))


def test_prepared_frames_match_the_frames_and_resume(dataset, frames, monkeypatch):
    """The frames prepared on disk and read back memory-mapped equal the frames converted in memory; a
    shard whose preparation was interrupted (no description) is prepared again, the others are read."""
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.models import unet_frames

    train, val, _ = frames
    ds = open_dataset(dataset)
    direct = unet_frames.frames_to_set(ds.frames(split="train", holdout=False))
    folder = next((dataset.parent / f"{dataset.name}.prepared").iterdir())
    described = sorted(folder.glob("*.json"))
    assert described and len(described) == len(list(folder.glob("*.bin")))
    described[0].unlink()
    monkeypatch.setattr(unet_frames, "STACK_BYTES", 0)  # one memory-mapped view per frame
    again, val_again, _ = load_dataset_frames(dataset)
    assert described[0].exists() and isinstance(again.x, list)
    for a, b in ((direct, train), (train, again), (val, val_again)):
        assert a.names == b.names and torch.equal(a.rho, b.rho) and torch.equal(a.radii, b.radii)
        for key in ("x", "y", "m"):
            assert all(torch.equal(getattr(a, key)[i], getattr(b, key)[i]) for i in range(len(a)))


def test_foreground_is_read_from_the_normal_under_every_contract():
    """Version 3's depth channel is log depth: 0 at depth 1 and negative nearer, so only the normal tells
    foreground from background (crop selection and validation read it so)."""
    from neuralao.pipeline.models.unet_frames import foreground
    from neuralao.runtime.unet_input import preprocess

    depth = np.array([[0.5, 1.0, 2.0, 0.0]], np.float32)
    normal = np.zeros((1, 4, 3), np.float32)
    normal[..., 2] = depth > 0
    for version in (2, 3):
        x = preprocess(depth, normal, depth > 0, version)
        assert foreground(x).tolist() == [[True, True, True, False]]
        assert foreground(torch.from_numpy(x)[None]).tolist() == [[[True, True, True, False]]]
    assert preprocess(depth, normal, depth > 0, 3)[0, 0, 1] == 0.0
