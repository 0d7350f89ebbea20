"""Baked MLP (pipeline/models/mlp.py): sizes, circle sampling, samples from meshes and datasets, training,
checkpoints."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from neuralao.pipeline.cli.main import main as cli_main
from neuralao.pipeline.models.mlp import (
    INPUTS,
    BakedMLP,
    MLPSettings,
    Samples,
    build_model,
    circle_inputs,
    circle_offsets,
    label_pixels,
    load_checkpoint,
    model_from_checkpoint,
    parameter_bytes,
    parse_size,
    predict,
    radius_zero_inputs,
    samples_from_dataset,
    samples_from_mesh,
    split_samples,
    train,
    train_model,
)
from neuralao.pipeline.tracing.labeller import LabelSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import load_settings

# A tiny mesh-source problem: spot, 12 views at 96x96 (6,144 samples), 32 rays; 2 held-back views at 64x64.
TINY = MLPSettings(
    views=12,
    size=(96, 96),
    holdout_views=2,
    holdout_size=(64, 64),
    samples_per_view=512,
    max_iterations=300,
    labels=LabelSettings(rays=32),
)


@pytest.fixture(scope="module")
def spot_samples() -> Samples:
    return samples_from_mesh("spot", TINY)


@pytest.fixture(scope="module")
def spot_checkpoint(spot_samples, tmp_path_factory):
    out = tmp_path_factory.mktemp("mlp") / "spot-16x8.pt"
    ckpt = train(TINY, out, samples=spot_samples)
    return out, ckpt


# ----------------------------------------------------------------------------------------------- model


@pytest.mark.parametrize(
    ("size", "params", "nbytes"), [("16x8", 929, 3716), ("32x16", 2113, 8452), ("64x32", 5249, 20996)]
)
def test_paper_sizes_parameter_bytes(size, params, nbytes):
    model = BakedMLP(parse_size(size))
    assert sum(p.numel() for p in model.parameters()) == params
    assert parameter_bytes(model) == nbytes
    # Independent count: 48*X + X + X*Y + Y + Y + 1.
    x, y = parse_size(size)
    assert 4 * (INPUTS * x + x + x * y + y + y + 1) == nbytes


def test_any_size_and_bad_sizes():
    assert parse_size("7x3") == [7, 3]
    assert BakedMLP([7, 3])(torch.zeros(5, INPUTS)).shape == (5, 1)
    for bad in ("16-8", "0x8", "x", "abc"):
        with pytest.raises(NeuralaoError):
            parse_size(bad)
    with pytest.raises(NeuralaoError):
        build_model({"inputs": 47, "hidden": [16, 8]})


# ----------------------------------------------------------------------------------------------- inputs


def test_circle_offsets_are_nearest_pixels_on_the_circle():
    off = circle_offsets(10.0, 16)
    assert off.shape == (16, 2)
    a = np.arange(16) * 2 * math.pi / 16
    exact = np.stack([-10 * np.sin(a), 10 * np.cos(a)], axis=1)  # (row, col), row grows downwards
    assert np.abs(off - exact).max() <= 0.5  # nearest pixel
    assert off[0].tolist() == [0, 10] and off[4].tolist() == [-10, 0]  # angle 0: right; pi/2: up


def test_circle_inputs_substitute_centre_normal_on_background_and_off_screen():
    h, w = 40, 50
    rng = np.random.default_rng(0)
    normals = rng.standard_normal((h, w, 3)).astype(np.float32)
    mask = np.zeros((h, w), bool)
    mask[5:30, 3:30] = True  # foreground block; right of column 30 is background
    rows = np.array([15, 2 + 3, 25])  # mid-block; near the top edge (circle goes off-screen); bottom-right
    cols = np.array([15, 4, 28])
    x, substituted = circle_inputs(normals, mask, rows, cols, radius=10.0)
    assert x.shape == (3, 48) and x.dtype == np.float32
    off = circle_offsets(10.0, 16)
    for i, (r, c) in enumerate(zip(rows, cols, strict=True)):
        for k, (dr, dc) in enumerate(off):
            rr, cc = r + dr, c + dc
            on = 0 <= rr < h and 0 <= cc < w and mask[rr, cc]
            want = normals[rr, cc] if on else normals[r, c]
            np.testing.assert_array_equal(x[i, 3 * k : 3 * k + 3], want)
            assert substituted[i, k] == (not on)
    assert substituted[0].sum() == 0  # fully inside the block
    assert substituted[1].any() and substituted[2].any()  # off-screen / background cases really occur


def test_radius_zero_inputs_repeat_the_normal():
    n = np.array([[0.0, 0.6, 0.8], [1.0, 0.0, 0.0]], np.float32)
    x = radius_zero_inputs(n)
    assert x.shape == (2, 48)
    np.testing.assert_array_equal(x.reshape(2, 16, 3), np.repeat(n[:, None], 16, axis=1))


# ----------------------------------------------------------------------------------------------- samples


def test_mesh_source_labels_equal_label_frame(spot_samples):
    """Labelling only drawn pixels gives exactly what labelling the whole frame gives there."""
    from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
    from neuralao.pipeline.geometry.camera import orbit
    from neuralao.pipeline.geometry.scene import load_scene
    from neuralao.pipeline.tracing.labeller import Labeller

    scene = load_scene("spot")
    frame = render_gbuffer(scene, orbit(scene, 3, 48, 48)[1])
    labeller = Labeller(scene, LabelSettings(rays=32, seed=11))
    full_ao, full_valid = labeller.label_frame(frame)
    pix = np.flatnonzero(frame["mask"].reshape(-1))[::7]
    ao, valid = label_pixels(Labeller(scene, LabelSettings(rays=32)), frame, pix, seed=11)
    np.testing.assert_array_equal(ao, full_ao.reshape(-1)[pix])
    np.testing.assert_array_equal(valid, full_valid.reshape(-1)[pix])
    with pytest.raises(NeuralaoError):
        label_pixels(labeller, frame, np.array([0]), seed=11)  # corner pixel: background


def test_mesh_samples_shapes_split_and_determinism(spot_samples):
    s = spot_samples
    n = len(s.targets)
    assert s.inputs.shape == (n, 48) and s.centre.shape == (n, 3) and n <= TINY.views * TINY.samples_per_view
    assert n > 0.9 * TINY.views * TINY.samples_per_view  # spot is closed: nearly every drawn pixel is valid
    assert np.all((s.targets >= 0) & (s.targets <= 1))
    np.testing.assert_allclose(np.linalg.norm(s.centre, axis=1), 1.0, atol=1e-4)
    counts = np.bincount(s.split, minlength=3)
    assert counts[0] == n // 2 and counts[1] == n // 4 and counts.sum() == n
    assert len(s.holdout) == TINY.holdout_views and s.holdout[0]["ao"].shape == (64, 64)
    again = samples_from_mesh("spot", replace(TINY, holdout_views=0))  # seeded: same samples
    np.testing.assert_array_equal(again.inputs, s.inputs)
    np.testing.assert_array_equal(again.targets, s.targets)
    np.testing.assert_array_equal(again.split, s.split)


def test_split_is_seeded_and_validated():
    a, b, c = (
        split_samples(101, [0.5, 0.25, 0.25], 0),
        split_samples(101, [0.5, 0.25, 0.25], 0),
        split_samples(101, [0.5, 0.25, 0.25], 1),
    )
    np.testing.assert_array_equal(a, b)
    assert (a != c).any()
    with pytest.raises(NeuralaoError):
        split_samples(10, [0.5, 0.5, 0.5], 0)


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset

    out = tmp_path_factory.mktemp("ds")
    settings = DatasetSettings(
        scenes=[SceneSpec(name="spot", mesh="spot", views=8)],
        size=(48, 48),
        labels=LabelSettings(rays=16),
        holdout_every=4,
    )
    build_dataset(settings, out, progress=False)
    return out


def test_dataset_source_never_samples_held_back_views(tiny_dataset):
    from neuralao.pipeline.datasets.dataset import open_dataset

    settings = replace(TINY, samples_per_view=64)
    s = samples_from_dataset(tiny_dataset, "spot", settings)
    held = {3, 7}  # holdout_every=4: views 3 and 7
    assert set(np.unique(s.view)) == set(range(8)) - held
    assert sorted(f["view"] for f in s.holdout) == sorted(held)
    # Targets are the labelled frame's AO at the drawn (valid) centre pixels; inputs are its normals.
    frames = {f["view"]: f for f in open_dataset(tiny_dataset).frames(scene="spot")}
    for v in (0, 5):
        f = frames[v]
        sel = s.view == v
        assert sel.sum() == min(64, int(f["valid"].sum()))
        ao_valid = f["ao"][f["valid"]]
        assert np.isin(s.targets[sel], ao_valid).all()
        normals_valid = f["normal_obj"][f["valid"]]
        for c in s.centre[sel][:5]:
            assert (np.abs(normals_valid - c).max(axis=1) == 0).any()
    with pytest.raises(NeuralaoError, match="not in dataset"):
        samples_from_dataset(tiny_dataset, "bunny", settings)


# ----------------------------------------------------------------------------------------------- training


def test_training_fits_a_known_function_far_better_than_a_constant():
    """Tiny problem with a known answer: target = 0.6 + 0.3 * (n_z of the mean circle normal)."""
    rng = np.random.default_rng(3)
    n = 2000
    v = rng.standard_normal((n, 16, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    y = (0.6 + 0.3 * v[:, :, 2].mean(axis=1)).astype(np.float32)
    s = Samples(
        v.reshape(n, 48).astype(np.float32),
        v[:, 0].astype(np.float32),
        y,
        np.zeros(n, np.int32),
        split_samples(n, [0.5, 0.25, 0.25], 0),
        [],
        {"scene": "synthetic"},
    )
    model, info = train_model(s, replace(MLPSettings(), max_iterations=300))
    x_test, y_test = s.part("test")
    rmse = float(np.sqrt(np.mean((predict(model, x_test) - y_test) ** 2)))
    constant = float(np.sqrt(np.mean((y_test - s.part("train")[1].mean()) ** 2)))
    assert rmse < 0.1 * constant, (rmse, constant)


def test_training_on_a_real_mesh_beats_the_constant_predictor(spot_checkpoint):
    _, ckpt = spot_checkpoint
    m = ckpt["metrics"]
    # A 16x8 net on 12 views of spot: ~0.7x the constant's RMSE at 32 rays; 0.85 leaves room for noise.
    assert m["test_rmse"] < 0.85 * m["constant_test_rmse"], m
    assert m["holdout_frames"] == 2 and 0 < m["holdout_ssim"] <= 1 and 0 < m["holdout_rmse"] < 0.5
    assert ckpt["training"]["best_iteration"] > 0


def test_training_is_seeded(spot_samples):
    s = replace(TINY, max_iterations=20)
    a, _ = train_model(spot_samples, s)
    b, _ = train_model(spot_samples, s)
    c, _ = train_model(spot_samples, replace(s, seed=1))
    x = spot_samples.inputs[:50]
    np.testing.assert_array_equal(predict(a, x), predict(b, x))
    assert not np.array_equal(predict(a, x), predict(c, x))


def test_adam_optimiser_runs(spot_samples):
    model, info = train_model(
        spot_samples, replace(TINY, optimizer="adam", max_iterations=3, train_dtype="float32")
    )
    assert info["optimizer"] == "adam" and info["iterations"] == 3


# ----------------------------------------------------------------------------------------------- checkpoints


def test_checkpoint_round_trip(spot_checkpoint, spot_samples):
    path, ckpt = spot_checkpoint
    raw = torch.load(path, map_location="cpu", weights_only=True)  # plain data only
    assert raw["kind"] == "mlp" and raw["model_args"] == {"inputs": 48, "hidden": [16, 8]}
    for key in ("state_dict", "config", "metrics", "scene", "training_time_s"):
        assert key in raw
    assert (
        raw["scene"] == "spot" and raw["config"]["size"] == [96, 96] and raw["config"]["labels"]["rays"] == 32
    )
    loaded = model_from_checkpoint(load_checkpoint(path))
    x = spot_samples.inputs[:100]
    want = predict(model_from_checkpoint(ckpt), x)
    np.testing.assert_array_equal(predict(loaded, x), want)
    # The stored config rebuilds the settings exactly (strict loader, no unknown keys).
    assert load_settings(
        MLPSettings, None, [f"{k}={_json(v)}" for k, v in raw["config"].items() if k != "labels"]
    )


def _json(v) -> str:
    import json

    return json.dumps(v)


def test_wrong_checkpoint_kind_and_corrupt_file(tmp_path):
    other = tmp_path / "unet.pt"
    torch.save({"kind": "unet", "model_args": {}, "state_dict": {}, "config": {}}, other)
    with pytest.raises(NeuralaoError, match="not an MLP checkpoint"):
        load_checkpoint(other)
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(NeuralaoError, match="cannot read checkpoint"):
        load_checkpoint(junk)
    with pytest.raises(NeuralaoError, match="not found"):
        load_checkpoint(tmp_path / "missing.pt")


def test_train_cli_end_to_end_and_bad_input(tmp_path, capsys):
    out = tmp_path / "m.pt"
    argv = [
        "train",
        "mlp",
        "--mesh",
        "suzanne",
        "--views",
        "3",
        "--resolution",
        "48",
        "48",
        "--rays",
        "16",
        "--size",
        "8x4",
        "--out",
        str(out),
        "--no-progress",
        "--set",
        "holdout_views=1",
        "--set",
        "holdout_size=[48,48]",
        "--set",
        "max_iterations=30",
    ]
    assert cli_main(argv) == 0
    ckpt = load_checkpoint(out)
    assert ckpt["model_args"]["hidden"] == [8, 4] and ckpt["config"]["views"] == 3
    assert not list(tmp_path.glob(".*tmp*"))  # atomic: no temporary left behind
    for bad in (
        [
            "train",
            "mlp",
            "--mesh",
            "suzanne",
            "--size",
            "8x4",
            "--out",
            str(tmp_path / "x.pt"),
            "--set",
            "nope=1",
        ],
        ["train", "mlp", "--size", "8x4", "--out", str(tmp_path / "x.pt")],
        ["train", "mlp", "--mesh", "no_such_mesh", "--out", str(tmp_path / "x.pt")],
        ["train", "mlp", "--mesh", "suzanne", "--size", "8-4", "--out", str(tmp_path / "x.pt")],
    ):
        assert cli_main(bad) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "error" in err[0]
    assert not (tmp_path / "x.pt").exists()


def test_train_cli_from_a_dataset(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "d.pt"
    argv = [
        "train",
        "mlp",
        "--data",
        str(tiny_dataset),
        "--scene",
        "spot",
        "--size",
        "8x4",
        "--out",
        str(out),
        "--no-progress",
        "--set",
        "max_iterations=20",
        "--set",
        "samples_per_view=64",
    ]
    assert cli_main(argv) == 0
    ckpt = load_checkpoint(out)
    assert ckpt["samples"]["source"] == "dataset" and ckpt["scene"] == "spot" and ckpt["mesh"] == "spot"
    assert ckpt["metrics"]["holdout_frames"] == 2  # views 3 and 7 of 8 are held back
    assert (
        cli_main(
            [
                "train",
                "mlp",
                "--data",
                str(tiny_dataset),
                "--scene",
                "spot",
                "--views",
                "3",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "--mesh only" in capsys.readouterr().err
