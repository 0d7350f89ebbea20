"""`neuralao report` at several AO radii, with the shipped U-Nets of a models folder and their plots.

A tiny dataset labelled at two radii (1/16 and 1/4 of the diagonal, the max distance), a tiny
untrained U-Net exported at full and at half resolution and installed in a models folder written
here (index.json + manifests with a synthetic training history), and a purely synthetic index for
the corpus-size plot. The ground truth of the report at several radii is checked against separate
traces (bit for bit), the per-radius SSAO figures against metrics computed here at that radius.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset, open_dataset
from neuralao.pipeline.tracing.labeller import LabelSettings
from neuralao.runtime.foundation.metrics import masked_rmse, masked_ssim

RADII = [0.0625, 0.25]  # the dataset's labels.radii_rel; max_distance_rel is 0.25


def _fast_settings(**kw):
    from neuralao.pipeline.evaluation.report_settings import ReportSettings

    base = dict(
        gt_rays=16,
        frames_per_scene=2,
        time_size=(32, 32),
        repeats=1,
        trace_rays=[2],
        bake_rays=8,
        bake_samples_per_vertex=2.0,
        contact_sheets=False,
    )
    base.update(kw)
    return ReportSettings(**base)


def _history(minutes: float, epochs: int, top: float) -> list[dict]:
    return [
        {"epoch": e, "wall_seconds": 60.0 * minutes * e / epochs, "val_ssim": top * (1 - 0.5 / e), "lr": 1e-3}
        for e in range(1, epochs + 1)
    ]


def _tiny_unet(path: Path, scale: int) -> None:
    from neuralao.pipeline.models.unet import UNetArgs, build_model, model_args_dict
    from neuralao.pipeline.models.unet_train import KIND

    torch.manual_seed(0)
    args = UNetArgs(widths=[2, 4], scale=scale)
    model = build_model(args).eval()
    torch.save(
        {
            "kind": KIND,
            "format_version": 1,
            "model_args": model_args_dict(args),
            "config": {},
            "state_dict": model.state_dict(),
            "metrics": {},
        },
        path,
    )


def _install(models: Path, name: str, export: Path, provenance: dict, config: dict) -> None:
    shutil.copytree(export, models / name)
    manifest = json.loads((models / name / "manifest.json").read_text())
    manifest.update(name=name, provenance=provenance, config={**manifest.get("config", {}), **config})
    (models / name / "manifest.json").write_text(json.dumps(manifest))


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """Dataset (spot orbit + a val interior, 32x32, two radii) and a models folder with two U-Nets."""
    from neuralao.export.unet import export_checkpoint

    root = tmp_path_factory.mktemp("report-radii")
    data = root / "dataset"
    build_dataset(
        DatasetSettings(
            name="tiny-radii",
            size=(32, 32),
            holdout_every=2,
            frames_per_shard=4,
            labels=LabelSettings(rays=8, radii_rel=list(RADII)),
            scenes=[
                SceneSpec("spot", "spot", views=4, split="train"),
                SceneSpec("box", "cornell_box", cameras="interior", views=2, split="val"),
            ],
        ),
        data,
        progress=False,
    )
    models = root / "models"
    models.mkdir()
    for name, scale, minutes in (("u-30", 1, 30), ("u-90-half", 2, 90)):
        _tiny_unet(root / f"{name}.pt", scale)
        export_checkpoint(root / f"{name}.pt", root / "export" / name)
        prov = {
            "budget_minutes": minutes,
            "history": _history(minutes, 6, 0.8),
            "test": {"ssim": 0.7, "rmse": 0.1},
        }
        _install(models, name, root / "export" / name, prov, {"train_fraction": 1.0})
    index = {
        "models": {
            "u-30": {
                "kind": "unet",
                "scale": 1,
                "bytes": 1000,
                "test": {"ssim": 0.71, "rmse": 0.11},
                "gl_seconds": {"512x512": 0.05},
            },
            "u-90-half": {
                "kind": "unet",
                "scale": 2,
                "bytes": 1200,
                "test": {"ssim": 0.72, "rmse": 0.1},
                "gl_seconds": {"512x512": 0.02},
            },
        },
        "default": {"unet": "u-30"},
        "baselines": {
            "ssao": {"test": {"ssim": 0.6, "rmse": 0.2}, "gl_seconds": {"512x512": 0.01}},
            "gtao": {"test": {"ssim": 0.75, "rmse": 0.12}, "gl_seconds": {"512x512": 0.03}},
        },
    }
    (models / "index.json").write_text(json.dumps(index))
    return root, data, models


@pytest.fixture(scope="module")
def result(workspace):
    from neuralao.pipeline.evaluation.report import evaluate
    from neuralao.pipeline.evaluation.report_writing import write_report

    root, data, models = workspace
    out = root / "out"
    out.mkdir()
    settings = _fast_settings()
    r = evaluate(data, None, settings, out, families={"screen-space", "unet"}, progress=False, shipped=models)
    write_report(r, out, settings)
    return out, json.loads((out / "report.json").read_text())


def test_ground_truth_at_several_radii_equals_separate_traces(workspace):
    """One trace at 1/16, 1/8 and 1/4 of the diagonal = three traces with max_distance = r, bit for bit;
    the cache holds the same arrays and is keyed on the radii."""
    from dataclasses import replace

    from neuralao.pipeline.datasets.dataset import scene_of
    from neuralao.pipeline.evaluation.report_truth import frame_key_seed, ground_truth, label_settings_of
    from neuralao.pipeline.tracing.labeller import Labeller

    root, data, _ = workspace
    ds = open_dataset(data)
    frame = next(ds.frames(scene="spot", holdout=True))
    settings = _fast_settings()
    labeller = Labeller(scene_of(ds.manifest, "spot"), label_settings_of(ds, 1))
    diag = labeller.scene.diagonal
    radii = (0.0625 * diag, 0.125 * diag, labeller.max_distance)
    cache = root / "gt-cache"
    truth = ground_truth(labeller, frame, 8, settings, cache, {"k": 1}, radii, main=2)
    assert truth.ao.shape == (32, 32, 3) and truth.source.startswith("relabelled")
    seed = frame_key_seed(settings.seed, "gt", "spot", frame["view"])
    saved = labeller.settings
    for j, r in enumerate(radii):
        labeller.settings = replace(saved, rays=settings.gt_rays, seed=seed, max_distance=r)
        ao, valid = labeller.label_frame(frame)
        np.testing.assert_array_equal(truth.ao[..., j], ao)
        np.testing.assert_array_equal(truth.valid[..., j], valid)
    labeller.settings = saved
    fg = frame["mask"] & truth.valid.all(axis=-1)
    assert truth.ao[..., 0][fg].mean() > truth.ao[..., 2][fg].mean()  # a larger radius sees more occluders
    again = ground_truth(labeller, frame, 8, settings, cache, {"k": 1}, radii, main=2)
    assert again.source.endswith("(cached)") and np.array_equal(again.ao, truth.ao)
    other = ground_truth(labeller, frame, 8, settings, cache, {"k": 1}, radii[1:], main=1)
    assert not other.source.endswith("(cached)") and len(list(cache.glob("*.npz"))) == 2
    np.testing.assert_array_equal(other.ao, truth.ao[..., 1:])
    # enough rays in the dataset: its own labels at its radii; a radius it lacks -> relabelled
    own = ground_truth(labeller, frame, 16, settings, None, {}, (radii[0], radii[2]), main=1)
    assert own.source.startswith("dataset labels")
    np.testing.assert_array_equal(own.ao, np.stack([frame["ao_radii"][..., 0], frame["ao"]], axis=-1))
    assert ground_truth(labeller, frame, 16, settings, None, {}, radii, main=2).source.startswith(
        "relabelled"
    )


def test_every_radius_method_is_scored_at_every_radius(result, workspace):
    out, r = result
    ms = r["methods"]
    assert r["radii_rel"] == RADII
    for name in ("ssao", "gtao", "shipped:u-30", "shipped:u-90-half"):
        assert ms[name]["available"], (name, ms[name].get("reason"))
        assert sorted(ms[name]["per_radius"], key=float) == ["0.0625", "0.25"]
        # the max distance is one of the radii: its per-radius figures are the main ones
        assert ms[name]["per_radius"]["0.25"]["ssim"] == pytest.approx(ms[name]["ssim"], abs=1e-12)
        assert ms[name]["per_radius"]["0.25"]["rmse"] == pytest.approx(ms[name]["rmse"], abs=1e-12)
    assert ms["shipped:u-90-half"]["scale"] == 2 and ms["shipped:u-30"]["scale"] == 1
    assert ms["shipped:u-30"]["shipped"] == "u-30"
    assert ms["ssao"]["per_radius"]["0.0625"]["rmse_ratio_vs_ssao"] == pytest.approx(1.0)
    md = (out / "report.md").read_text()
    assert "## Per radius" in md and "| r = 0.0625 | r = 0.25 |" in md
    assert "| shipped:u-90-half |" in md and "## Shipped models" in md


def test_ssao_gets_the_radius_it_is_scored_at(result, workspace):
    """Per-radius SSAO figures = SSAO run here at r x diagonal against the cached ground truth at r;
    GTAO at the larger radius is darker on average, as the ground truth is. (This SSAO is not: at a
    radius of a pixel or two its fixed relative depth bias lets tilted neighbours self-occlude, so its
    mean AO rises with the radius on these 32x32 frames; the per-radius table shows that.)"""
    from neuralao.runtime.baselines import run_screen_space
    from neuralao.runtime.foundation.io import read_npz

    out, r = result
    _, data, _ = workspace
    ds = open_dataset(data)
    frames = {(f["scene"], f["view"]): f for f in ds.frames()}
    ssim, rmse, means = [], [], {k: [] for k in RADII}
    for row in (row for row in r["frames"] if "skipped" not in row):
        frame = frames[(row["scene"], row["view"])]
        (gt_file,) = (out / "gt").glob(f"{row['scene']}-{row['view']:04d}-*.npz")
        gt = read_npz(gt_file)
        diag = r["scenes"][row["scene"]]["radii"][0] / RADII[0]
        np.testing.assert_allclose(gt["radii"], np.array(RADII) * diag, rtol=1e-12)
        for j, rel in enumerate(RADII):
            pred = run_screen_space(frame, "ssao", rel * diag, _fast_settings().ssao)
            mask = frame["mask"] & gt["valid_radii"][..., j]
            means[rel].append(float(run_screen_space(frame, "gtao", rel * diag)[frame["mask"]].mean()))
            if j == 0:
                ssim.append(masked_ssim(pred, gt["ao_radii"][..., 0], mask))
                rmse.append(masked_rmse(pred, gt["ao_radii"][..., 0], mask))
    e = r["methods"]["ssao"]["per_radius"]["0.0625"]
    assert e["frames"] == len(ssim) and e["ssim"] == pytest.approx(np.mean(ssim), abs=1e-6)
    assert e["rmse"] == pytest.approx(np.mean(rmse), abs=1e-6)
    assert np.mean(means[0.25]) < np.mean(means[0.0625])


def test_shipped_plots_are_pngs_and_listed(result):
    out, r = result
    figs = r["figures"]
    assert figs["learning_curves"] == "learning_curves.png" and figs["shipped_front"] == "shipped_front.png"
    assert "corpus_size" not in figs  # both models have train_fraction 1: no corpus-size study
    for name in ("learning_curves.png", "shipped_front.png"):
        with Image.open(out / name) as im:
            assert im.format == "PNG" and im.size[0] > 300
    md = (out / "report.md").read_text()
    assert "![learning curves" in md and "(test SSIM against corpus size: no data" in md
    assert r["shipped"]["models"]["u-90-half"]["budget_minutes"] == 90
    assert len(r["shipped"]["models"]["u-30"]["history"]) == 6


def test_corpus_size_plot_from_a_synthetic_index(tmp_path):
    """Three models differing only in train_fraction -> one series of three points; learning curves from
    the index entries' own history; a model without data adds nothing."""
    from neuralao.pipeline.evaluation.plots import corpus_size_series, shipped_summary, write_shipped_plots

    models = tmp_path / "models"
    index = {"models": {}, "default": {"unet": "full"}}
    for name, frac, scenes, ssim in (
        ("quarter", 0.25, 2, 0.6),
        ("half", 0.5, 4, 0.66),
        ("full", 1.0, 8, 0.7),
    ):
        (models / name).mkdir(parents=True)
        manifest = {
            "kind": "unet",
            "config": {"train_fraction": frac, "budget_minutes": 15},
            "metadata": {"scale": "1", "training_scenes": [f"s{i}" for i in range(scenes)]},
            "provenance": {"budget_minutes": 15, "test": {"ssim": ssim, "rmse": 0.1}},
        }
        (models / name / "manifest.json").write_text(json.dumps(manifest))
        index["models"][name] = {
            "kind": "unet",
            "scale": 1,
            "widths": [8, 16],
            "history": _history(15, 4, ssim),
        }
    index["models"]["bare"] = {"kind": "unet"}  # no manifest, no figures
    (models / "index.json").write_text(json.dumps(index))
    shipped = shipped_summary(models)
    assert shipped["note"] is None and shipped["models"]["half"]["corpus_unit"] == "training scenes"
    (series,) = corpus_size_series(shipped).values()
    assert [(x, n) for x, _, n in series] == [(2.0, "quarter"), (4.0, "half"), (8.0, "full")]
    figs = write_shipped_plots(shipped, tmp_path)
    assert set(figs) == {"learning_curves", "corpus_size"}  # no GL time in the index: no front plot
    with Image.open(tmp_path / "corpus_size.png") as im:
        assert im.format == "PNG"


def test_no_shipped_model_is_one_line(tmp_path, workspace):
    from neuralao.pipeline.evaluation.report import evaluate
    from neuralao.pipeline.evaluation.report_writing import render_markdown

    _, data, _ = workspace
    r = evaluate(
        data,
        None,
        _fast_settings(frames_per_scene=1),
        None,
        families={"screen-space"},
        progress=False,
        keep_images=False,
        shipped=tmp_path / "empty",
    )
    r.pop("_sheets")
    assert r["shipped"]["models"] == {} and "index.json is missing" in r["shipped"]["note"]
    md = render_markdown(r, None, {})
    assert sum("No shipped model" in line for line in md.splitlines()) == 1


def test_shipped_models_are_the_default_without_exports(tmp_path):
    from neuralao.pipeline.cli.report import add_arguments, shipped_folder
    from neuralao.runtime.shipped import MODELS_DIR

    parser = argparse.ArgumentParser()
    add_arguments(parser)

    def folder(*args):
        return shipped_folder(parser.parse_args(["--data", "d", "--out", "o", *args]))

    assert folder() == MODELS_DIR and folder("--shipped") == MODELS_DIR
    assert folder("--exports", "x") is None and folder("--no-shipped") is None
    assert folder("--exports", "x", "--shipped", "--models", str(tmp_path)) == tmp_path


def test_radii_setting_is_checked(tmp_path, capsys):
    from neuralao.pipeline import cli

    assert (
        cli.main(
            ["report", "--data", str(tmp_path), "--out", str(tmp_path / "r"), "--set", "radii_rel=[0.1,-1]"]
        )
        == 2
    )
    assert "radii_rel must be positive" in capsys.readouterr().err
