"""Bad settings of `neuralao train` and hostile checkpoints given to `neuralao export`: one line, exit 2,
refused before any work (no prepared frames, no checkpoint, no export folder), never an internal error,
a Python warning or a logging traceback; and a U-Net export that prints nothing of OpenCV's. Every command
runs for real, in-process (``run`` / ``refusal`` of test_user_inputs: Python warnings are errors there).
"""

from __future__ import annotations

import logging
import os
import pickle
import shutil
from pathlib import Path

import cv2
import pytest
import torch
from test_user_inputs import TET, refusal, run

from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset
from neuralao.pipeline.models.unet import UNet, UNetArgs, model_args_dict
from neuralao.pipeline.tracing.labeller import LabelSettings

TOO_MANY_THREADS = (os.cpu_count() or 1) + 1
UNET = ["--no-progress", "--set", "epochs=1", "--set", "crop=16", "--set", "batch_size=2"]
UNET += ["--set", "widths=[2,4]", "--set", "internal_height=16", "--set", "threads=1"]


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """A dataset of a training scene of two 16x16 views and a validation scene of one, at one radius."""
    root = tmp_path_factory.mktemp("train_inputs") / "dataset"
    settings = DatasetSettings(
        name="tiny",
        scenes=[
            SceneSpec("box", "cornell_box", cameras="interior", views=2, split="train"),
            SceneSpec("suz", "suzanne", views=1, split="val"),
        ],
        size=(16, 16),
        labels=LabelSettings(rays=8, radii_rel=[0.125]),
        frames_per_shard=2,
    )
    build_dataset(settings, root, progress=False)
    return root


@pytest.mark.parametrize(
    "setting, words",
    [
        ("lr=-1", "lr must be > 0"),
        ("weight_decay=-1", "weight_decay must be a number in [0, 1]"),
        ("crop=-16", "crop must be an integer in [0, "),
        ("crop=15", "crop 15 must be a multiple of 2"),
        ("threads=-1", "threads must be an integer in [0, "),
        (f"threads={TOO_MANY_THREADS}", f"threads must be an integer in [0, {TOO_MANY_THREADS - 1}]"),
        ("ssim_window=0", "ssim_window must be an odd number of pixels in [3, 16]"),
        ("ssim_window=4", "ssim_window must be an odd number of pixels in [3, 16]"),
        ("ssim_window=1000", "ssim_window must be an odd number of pixels in [3, 16]"),
        ("widths=[100000,100000]", "widths [100000, 100000] ("),
        ("widths=[4]", "widths must list at least two"),
        (
            "internal_height=100000",
            "internal_height must be 0 (every frame at its own size) or an integer in [16, 16384]",
        ),
        ("internal_height=-1", "internal_height must be 0 (every frame at its own size) or an integer in"),
        ("seed=-1", "seed must be an integer in [0, 2^63 - 1]"),
        ("negative_slope=-5", "negative_slope must be a number in [0, 1)"),
        ("negative_slope=1", "negative_slope must be a number in [0, 1)"),
        ("warmup_steps=-1", "warmup_steps must be an integer in [0, "),
        ("min_lr_ratio=2", "min_lr_ratio must be a number in [0, 1]"),
        ("val_frames=-1", "val_frames must be an integer in [0, "),
        ("min_foreground=2", "min_foreground must be a number in [0, 1]"),
        ("ssim_sigma=-1", "ssim_sigma must be > 0"),
        ("ssim_c2=0", "ssim_c2 must be a number in (0, 1]"),
        ("batch_size=100000000000", "batch_size 100000000000 (crops of 16x16) is more than this machine"),
        ("epochs=100000000000000000", "epochs 100000000000000000 is more than this machine"),
        ("preprocess_version=99", "preprocess_version"),
        ("init=missing.pt", "checkpoint not found: missing.pt"),
    ],
)
def test_unet_settings_are_refused_before_any_frame_is_prepared(data, tmp_path, capsys, setting, words):
    out = tmp_path / "u.pt"
    line = refusal(capsys, ["train", "unet", "--data", str(data), *UNET, "--set", setting, "--out", str(out)])
    assert words in line, line
    assert not out.exists() and not Path(f"{out}.partial").exists()
    assert not data.with_name(f"{data.name}.prepared").exists()  # no cache folder of a refused run


def test_unet_settings_accepted_train(data, tmp_path, capsys):
    """The settings the refusals start from train (so each refusal is its one setting's); on a copy of the
    dataset, whose prepared frames would otherwise sit beside the refusals' dataset."""
    copy = shutil.copytree(data, tmp_path / "dataset")
    out = tmp_path / "u.pt"
    rc, err = run(capsys, ["train", "unet", "--data", str(copy), *UNET, "--out", str(out)])
    assert (rc, err) == (0, []) and out.exists()


@pytest.fixture(scope="module")
def tet(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("train_mesh") / "tet.obj"
    path.write_text(TET)
    return path


MLP = ["--views", "1", "--resolution", "16", "16", "--rays", "4", "--no-progress"]
MLP += ["--set", "max_iterations=2", "--set", "holdout_views=0"]
FIELD = ["--rays", "4", "--size", "4x2", "--no-progress", "--set", "steps=4", "--set", "samples=64"]
FIELD += ["--set", "batch=16", "--set", "check_every=2", "--set", "holdout_views=0"]


@pytest.mark.parametrize(
    "model, setting, words",
    [
        ("mlp", "hidden=[-4]", "hidden must list positive widths, got [-4]"),
        ("mlp", "lbfgs_history=0", "lbfgs_history must be an integer in [1, "),
        ("mlp", "yfov_deg=0", "yfov_deg must be within [0.1, 170] degrees"),
        ("mlp", "radius_px=-1", "radius_px must be a number in [0, 8192]"),
        ("mlp", "radius_px=1e30", "radius_px must be a number in [0, 8192]"),
        ("mlp", "adam_lr=1e30", "adam_lr must be a number in (0, 1]"),
        ("mlp", "split=[0.5,0.5,0.5]", "split must be three fractions"),
        ("mlp", f"threads={TOO_MANY_THREADS}", "threads must be an integer in [0, "),
        ("field", "yfov_deg=0", "yfov_deg must be within [0.1, 170] degrees"),
        ("field", "lr=1e30", "lr must be a number in (0, 1]"),
        ("field", "lr_final_fraction=2", "lr_final_fraction must be a number in [0, 1]"),
        ("field", "val_fraction=1", "val_fraction must be a number in [0, 1)"),
        ("field", "hidden=[-4]", "hidden widths must be positive"),
        ("field", f"threads={TOO_MANY_THREADS}", "threads must be an integer in [0, "),
    ],
)
def test_per_mesh_settings_are_refused_before_the_mesh_is_read(tet, tmp_path, capsys, model, setting, words):
    out = tmp_path / "m.pt"
    flags = MLP if model == "mlp" else FIELD
    line = refusal(capsys, ["train", model, "--mesh", str(tet), *flags, "--set", setting, "--out", str(out)])
    assert words in line, line
    assert not out.exists()


def test_a_field_without_a_validation_split_trains_and_says_so(tet, tmp_path, capsys, caplog):
    """val_fraction 0: every sample trains; the closing line shows "-" for the validation RMSE (it formatted
    None with %f, a logging traceback on stderr)."""
    out = tmp_path / "f.pt"
    argv = ["train", "field", "--mesh", str(tet), *FIELD, "--set", "val_fraction=0", "--out", str(out)]
    with caplog.at_level(logging.INFO):  # the closing line formatted, as on a user's terminal
        rc, err = run(capsys, argv)
    assert (rc, err) == (0, []) and out.exists()
    assert any("val RMSE - (constant -)" in r.getMessage() for r in caplog.records)
    metrics = torch.load(out, weights_only=True)["metrics"]
    assert metrics["val_samples"] == 0 and metrics["val_rmse"] is None


def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes)."""
    return {str(f.relative_to(folder)): f.read_bytes() for f in sorted(folder.rglob("*")) if f.is_file()}


@pytest.mark.parametrize("model", ["unet", "mlp", "field"])
@pytest.mark.parametrize("name", ["manifest.json", "shards/box-0000.npz", "model.pt"])
def test_a_checkpoint_is_never_written_inside_the_dataset(data, tmp_path, capsys, model, name):
    """The dataset is read whole: a checkpoint written over its manifest or a shard destroys it (mlp and field
    wrote theirs there), and one beside them mixes into it; refused before any work, on a copy."""
    copy = shutil.copytree(data, tmp_path / "dataset")
    before = tree(copy)
    out = copy / name
    steps = {
        "unet": UNET,
        "mlp": ["--set", "max_iterations=2"],
        "field": ["--size", "4x2", "--set", "steps=4"],
    }
    flags = steps[model] if model == "unet" else ["--scene", "box", "--no-progress", *steps[model]]
    line = refusal(capsys, ["train", model, "--data", str(copy), *flags, "--out", str(out)])
    assert f"--out {out} is inside --data {copy}, a folder the command reads" in line, line
    assert tree(copy) == before and not Path(f"{out}.partial").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dataset"]  # no prepared frames beside it


# ----------------------------------------------------------------------------------------------- export


def unet_checkpoint(path: Path, **change) -> Path:
    """A finished U-Net checkpoint of widths [2, 4] (untrained weights), with ``change`` applied."""
    args = UNetArgs(widths=[2, 4])
    model = UNet(args)
    ckpt = {
        "kind": "unet",
        "format_version": 1,
        "model_args": model_args_dict(args),
        "state_dict": model.state_dict(),
        "config": {},
        "epoch": 3,
        "plan": {"epochs": 3},
        "complete": True,
        **change,
    }
    torch.save(ckpt, path)
    return path


def _evil(path: Path) -> Path:
    class Evil:
        def __reduce__(self):
            return (os.system, ("true",))

    path.write_bytes(pickle.dumps(Evil()))  # protocol 4: torch warns about it before it refuses
    return path


def _shapes(path: Path) -> Path:
    state = UNet(UNetArgs(widths=[2, 4])).state_dict()
    first = next(iter(state))
    return unet_checkpoint(path, state_dict={**state, first: torch.zeros(3)})


def _extra(path: Path) -> Path:
    return unet_checkpoint(
        path, state_dict={**UNet(UNetArgs(widths=[2, 4])).state_dict(), "x.w": torch.ones(1)}
    )


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda p: unet_checkpoint(p, model_args="abc"), "'model_args' must be a mapping, got str"),
        (lambda p: unet_checkpoint(p, model_args={"widths": [100000, 100000]}), "more than this machine"),
        (lambda p: unet_checkpoint(p, model_args={"widths": [2, 4], "depth": 9}), "unknown setting(s) depth"),
        (_evil, "is not a neuralao checkpoint"),
        (lambda p: unet_checkpoint(p, state_dict={}), "tensor 'down.0.0.weight' is missing (and "),
        (_shapes, "has shape (3,), the model_args make it (2, 5, 3, 3)"),
        (_extra, "tensor 'x.w' is not one of the model's"),
        (lambda p: (p.write_bytes(b"not a checkpoint"), p)[1], "is not a neuralao checkpoint"),
        (lambda p: unet_checkpoint(p, format_version=999), "checkpoint format 999, which this neuralao"),
        (lambda p: unet_checkpoint(p, complete=False, epoch=1), "has not finished (epoch 1 of 3)"),
        (lambda p: unet_checkpoint(p.with_name("u.pt.partial")), "has not finished (epoch 3 of 3)"),
    ],
)
def test_export_refuses_a_hostile_or_unfinished_checkpoint_in_one_line(tmp_path, capsys, make, words):
    ckpt = make(tmp_path / "u.pt")
    out = tmp_path / "exports" / "u"
    line = refusal(capsys, ["export", str(ckpt), "--out", str(out)])
    assert words in line, line
    assert "weights_only` set to `False`" not in line  # torch's advice is not the user's to follow
    assert not out.parent.exists()  # refused before the export folder (or its parent) is made


def test_a_unet_export_prints_nothing_of_opencv(tmp_path, capfd):
    """OpenCV's dnn writes a ``[ WARN:0@...] setPreferableTarget`` line per network at its warning level
    (fd 2, not sys.stderr); the export runs it at errors only and restores the level after."""
    logs = cv2.utils.logging
    previous = logs.getLogLevel()
    logs.setLogLevel(logs.LOG_LEVEL_WARNING)
    try:
        rc, err = run(
            capfd, ["export", str(unet_checkpoint(tmp_path / "u.pt")), "--out", str(tmp_path / "e")]
        )
        assert (rc, err) == (0, []), err
        assert logs.getLogLevel() == logs.LOG_LEVEL_WARNING
    finally:
        logs.setLogLevel(previous)
