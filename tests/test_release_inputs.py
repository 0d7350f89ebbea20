"""Bad input to `neuralao ship`, `neuralao evaluate` and `neuralao select`: one line, exit 2, refused
before any work (nothing trained, rendered or written), and never a write outside the output folder or
over an input. Each case runs the real command in-process on a tiny config."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_user_inputs import refusal

from neuralao.pipeline.evaluation.categories import EvalSettings, check_settings
from neuralao.pipeline.release.ship import ShipSettings
from neuralao.pipeline.release.ship import check_settings as check_ship
from neuralao.runtime.foundation.settings import from_dict

TRAIN = {"widths": [4, 8], "epochs": 1, "crop": 16, "batch_size": 4, "internal_height": 32, "threads": 1}


def corpus(folder: Path) -> Path:
    """A dataset manifest with train and val frames and no test frames (nothing reads the shards: every
    case is refused before)."""
    folder.mkdir(parents=True, exist_ok=True)
    shards = [
        {"file": f"shards/{s}-0000.npz", "scene": s, "split": split, "views": [0, 1], "holdout": [False] * 2}
        for s, split in (("cbox", "train"), ("suz", "val"))
    ]
    manifest = {"format": "neuralao-dataset", "scenes": {}, "shards": shards, "frames": 4}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


def ship_config(tmp: Path, **change) -> dict:
    config = {
        "dataset": str(corpus(tmp / "ds")),
        "checkpoints": str(tmp / "ck"),
        "out": str(tmp / "models"),
        "default": {"unet": "u"},
        "test_split": "val",
        "test_frames": 1,
        "parity_frames": 1,
        "time_sizes": [[16, 16]],
        "time_repeats": 1,
        "models": [{"name": "u", "train": dict(TRAIN)}],
    }
    return config | change


def ship_refusal(capsys, tmp: Path, config: dict) -> str:
    path = tmp / "ship.json"
    path.write_text(json.dumps(config))
    before = sorted(p.relative_to(tmp.parent) for p in tmp.parent.rglob("*"))
    msg = refusal(capsys, ["ship", str(path)])
    assert msg.startswith("neuralao ship: error: config file ") and str(path) in msg, msg
    assert sorted(p.relative_to(tmp.parent) for p in tmp.parent.rglob("*")) == before  # nothing written
    return msg


def test_a_valid_ship_config_passes_the_checks(tmp_path):
    specs = check_ship(from_dict(ShipSettings, ship_config(tmp_path)), ["u"])
    assert [s.name for s in specs] == ["u"]


@pytest.mark.parametrize("name", ["../../evilship", "a/b", "/abs", "..", "", "index.json"])
def test_ship_model_names_stay_inside_out_and_checkpoints(capsys, tmp_path, name):
    config = ship_config(tmp_path / "w", default={})
    config["models"][0]["name"] = name
    msg = ship_refusal(capsys, tmp_path / "w", config)
    assert "models[0].name" in msg and repr(name) in msg


@pytest.mark.parametrize(
    "where,expected",
    [
        ({"out": "@ds"}, "out @ds is the same folder as dataset"),
        ({"out": "@ds/models"}, "out @ds/models is inside dataset"),
        ({"checkpoints": "@ds/ck"}, "checkpoints @ds/ck is inside dataset"),
        ({"checkpoints": "@models"}, "checkpoints @models is the same folder as out"),
        ({"checkpoints": "@models/ck"}, "checkpoints @models/ck is inside out"),
        ({"out": "@file"}, "out @file is a file; a folder is wanted here"),
    ],
)
def test_ship_folders_are_apart_and_checked_before_work(capsys, tmp_path, where, expected):
    tmp = tmp_path / "w"
    (tmp / "models").mkdir(parents=True)
    (tmp / "file").write_text("not a folder")
    at = lambda v: v.replace("@", f"{tmp}/")  # noqa: E731
    msg = ship_refusal(capsys, tmp, ship_config(tmp, **{k: at(v) for k, v in where.items()}))
    assert at(expected) in msg, msg


@pytest.mark.parametrize(
    "change,expected",
    [
        ({"test_split": "bogus"}, "test_split 'bogus' has no frames in the corpus"),
        ({"test_split": "test"}, "(frames by split: train 2, val 2)"),
        ({"parity_frames": -1}, "parity_frames must be an integer in [1,"),
        ({"test_frames": -1}, "test_frames must be an integer in [0,"),
        ({"time_repeats": 0}, "time_repeats must be an integer in [1,"),
        ({"max_bytes": 0}, "max_bytes must be an integer in [1,"),
        ({"time_sizes": [[0, 0]]}, "time_sizes[0] must be between 1 and 8192"),
        ({"time_sizes": [[100000, 100000]]}, "time_sizes[0] must be between 1 and 8192"),
        ({"time_sizes": [[16]]}, "time_sizes[0] must be [width, height]"),
        ({"default": {"bogus": "u"}}, "default names kind 'bogus'"),
        ({"default": {"unet": "nope"}}, "default unet model 'nope' is not one of ['u']"),
        ({"models": []}, "the config lists no models"),
        ({"models": [1]}, "models[0] must be an object"),
        ({"models": [{"name": "u", "train": [1]}]}, "model u: train must be an object"),
        ({"models": [{"name": "u", "train": {**TRAIN, "lr": -1}}]}, "model u: train: lr "),
        ({"models": [{"name": "u", "train": {**TRAIN, "bogus": 1}}]}, "models.u.train.bogus"),
        ({"models": [{"name": "u", "kind": "mlp"}]}, "kind 'mlp' cannot be shipped"),
        ({"models": [{"name": "u", "init": "v"}]}, "init 'v' is not an earlier model"),
        ({"models": [{"name": "u"}, {"name": "u"}]}, "model names must be unique"),
    ],
)
def test_ship_config_values_are_refused_before_any_model_trains(capsys, tmp_path, change, expected):
    msg = ship_refusal(capsys, tmp_path / "w", ship_config(tmp_path / "w", **change))
    assert expected in msg, msg


def test_ship_only_names_a_model_of_the_config(capsys, tmp_path):
    tmp = tmp_path / "w"
    path = tmp / "ship.json"
    corpus(tmp / "ds")
    path.write_text(json.dumps(ship_config(tmp)))
    msg = refusal(capsys, ["ship", str(path), "--only", "nope"])
    assert "--only nope: not a model of this config" in msg
    assert not (tmp / "models").exists() and not (tmp / "ck").exists()


EVAL = {
    "name": "tiny",
    "radii_rel": [0.125],
    "max_distance_rel": 0.25,
    "allow_trained_meshes": True,
    "categories": [{"name": "box", "meshes": ["cornell_box"], "cameras": "interior"}],
    "resolutions": [{"size": [16, 16], "rays": 8, "views": 1}],
}


def test_a_valid_evaluation_config_passes_the_checks():
    check_settings(from_dict(EvalSettings, EVAL))


@pytest.mark.parametrize(
    "change,expected",
    [
        (
            {"categories": [{"name": "../../evilcat", "meshes": ["cornell_box"]}]},
            "category name '../../evilcat'",
        ),
        ({"categories": [{"name": "a/b", "meshes": ["cornell_box"]}]}, "is not a plain name"),
        (
            {"categories": [{"name": "box", "meshes": ["cornell_box"], "cameras": "drone"}]},
            "orbit, interior, closeup",
        ),
        (
            {"categories": [{"name": "r", "composed": 10**9}]},
            "category 'r': composed 1000000000 is more than",
        ),
        ({"categories": [{"name": "r", "composed": -1}]}, "category 'r': composed must be >= 0"),
        ({"resolutions": [{"size": [16, 16], "rays": 8, "views": 10**9}]}, "views 1000000000 is more than"),
        ({"resolutions": [{"size": [16, 16], "rays": 10**12}]}, "rays 1000000000000 is more than"),
        ({"resolutions": [{"size": [16, 16], "scenes_per_category": -1}]}, "scenes_per_category must be"),
        ({"seed": -1}, "seed must be an integer in [0, 2^63 - 1], got -1"),
    ],
)
def test_evaluate_bounds_counts_and_names_before_any_work(capsys, tmp_path, change, expected):
    path = tmp_path / "eval.json"
    path.write_text(json.dumps(EVAL | change))
    out = tmp_path / "out"
    msg = refusal(capsys, ["evaluate", str(path), "--models", str(tmp_path / "m"), "--out", str(out)])
    assert msg.startswith("neuralao evaluate: error: ") and expected in msg, msg
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eval.json"]  # no frames, inside or outside


def test_select_never_writes_inside_the_folders_it_reads(capsys, tmp_path):
    data = corpus(tmp_path / "ds")
    manifest = (data / "manifest.json").read_bytes()
    exports = tmp_path / "exports"
    exports.mkdir()
    report = tmp_path / "report.json"
    report.write_text("{}")
    base = ["select", "--data", str(data), "--exports", str(exports)]
    for out, source in ((data / "manifest.json", "--data"), (data / "new.json", "--data")):
        msg = refusal(capsys, [*base, "--out", str(out)])
        assert f"--out {out} is inside {source} {data}, a folder the command reads" in msg
    msg = refusal(capsys, [*base, "--out", str(exports / "s.json")])
    assert "is inside --exports" in msg
    msg = refusal(capsys, [*base, "--out", str(tmp_path / "s.json"), "--gt-cache", str(data / "gt")])
    assert f"--gt-cache {data / 'gt'} is inside --data" in msg
    msg = refusal(capsys, [*base, "--report", str(report), "--out", str(report)])
    assert "is also an input (--report)" in msg
    assert (data / "manifest.json").read_bytes() == manifest and sorted(p.name for p in data.iterdir()) == [
        "manifest.json"
    ]
    # outside the folders it reads, the output passes the check (the report is then refused as a report)
    msg = refusal(capsys, [*base, "--report", str(report), "--out", str(tmp_path / "s.json")])
    assert "is not a neuralao report.json" in msg and not (tmp_path / "s.json").exists()


@pytest.mark.parametrize("rows", [-1, 8, 100000, "512", 2.5])
def test_ship_refuses_an_export_height_out_of_range(capsys, tmp_path, rows):
    config = ship_config(tmp_path / "w")
    config["models"][0]["internal_height"] = rows
    msg = ship_refusal(capsys, tmp_path / "w", config)
    assert "internal_height" in msg, msg
