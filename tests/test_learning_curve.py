"""bench/learning_curve.py on a tiny dataset: one run passes through its points, each point is scored on
the validation split and the evaluation categories against GTAO, the table and plot are written, and a
rerun finds everything done (the snapshots are kept, nothing is trained or scored again); every point's
figures are kept beside the results, so a run measured elsewhere, or whose folder is gone, stays in the
table."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset
from neuralao.pipeline.tracing.labeller import LabelSettings

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_learning_curve_trains_snapshots_scores_and_resumes(tmp_path):
    data = tmp_path / "data"
    build_dataset(
        DatasetSettings(
            name="tiny-curve",
            scenes=[
                SceneSpec("spot", "spot", views=4, split="train"),
                SceneSpec("box", "cornell_box", cameras="interior", views=2, split="val"),
            ],
            size=(48, 40),
            labels=LabelSettings(rays=8, radii_rel=[0.125, 0.25]),
            frames_per_shard=4,
        ),
        data,
        progress=False,
    )
    cfg = {
        "dataset": str(data),
        "eval": {
            "name": "tiny",
            "radii_rel": [0.125, 0.25],
            "max_distance_rel": 0.25,
            "categories": [{"name": "scans", "meshes": ["horse"], "cameras": "orbit"}],
            "resolutions": [{"size": [32, 32], "rays": 16, "views": 1}],
        },
        "points_hours": [0.0005, 0.001],
        "base": {
            "widths": [2, 4],
            "internal_height": 0,
            "epochs": 6,
            "crop": 16,
            "batch_size": 4,
            "threads": 1,
        },
        "runs": [
            {"name": "main", "hours": 0.001, "train": {}},
            # 8 steps in 0.001 h, one an epoch (4 frames of one crop, batches of 4): 4 at the first point
            {"name": "fixed", "hours": 0.001, "steps_per_hour": 8000, "train": {}},
        ],
    }
    (tmp_path / "curve.json").write_text(json.dumps(cfg))
    results = tmp_path / "results.md"
    results.write_text(
        "# Results\n\n<!-- learning-curve:begin -->\nold\n<!-- learning-curve:end -->\n\nafter\n"
    )
    elsewhere = {"run": "elsewhere", "hours": 1.0, "steps": None, "val_ssim": None, "val_rmse": 0.5}
    elsewhere["rmse_to_gtao"] = {"scans": 0.75}
    (tmp_path / "learning_curve.json").write_text(json.dumps({"records": [elsewhere]}))
    argv = [
        sys.executable,
        str(ROOT / "bench" / "learning_curve.py"),
        "--config",
        str(tmp_path / "curve.json"),
    ]
    argv += ["--out", str(tmp_path / "out"), "--results", str(results)]
    env = os.environ | {"PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "osmesa")}
    first = subprocess.run(argv, capture_output=True, text=True, timeout=600, env=env)
    assert first.returncode == 0, first.stderr[-3000:]
    out = json.loads((tmp_path / "out" / "curve.json").read_text())
    fixed = [(r["hours"], r["steps"]) for r in out["records"] if r["run"] == "fixed"]
    assert fixed == [(0.0005, 4), (0.001, 8)]  # whatever the machine's speed
    records = [r for r in out["records"] if r["run"] == "main"]
    assert [r["hours"] for r in records] == [0.0005, 0.001]
    assert records[0]["steps"] <= records[1]["steps"] and all(r["val_rmse"] is not None for r in records)
    for r in records:
        assert {"model", "gtao"} <= set(r["categories"]) and "scans" in r["categories"]["model"]
    text = results.read_text()
    assert "old" not in text and "| main | 0.001 |" in text and text.endswith("after\n")
    assert (tmp_path / "learning_curve.png").stat().st_size > 0
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "out" / "main").glob("*.pt")}
    second = subprocess.run(argv, capture_output=True, text=True, timeout=600, env=env)
    assert second.returncode == 0, second.stderr[-3000:]
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps  # nothing trained again
    again = json.loads((tmp_path / "out" / "curve.json").read_text())["records"]
    assert [r for r in again if r["run"] == "main"] == records
    assert "| elsewhere | 1 | - | - | 0.5000 | 0.750 |" in results.read_text()
    kept = json.loads((tmp_path / "learning_curve.json").read_text())["records"]
    assert sorted((r["run"], r["hours"]) for r in kept) == [
        ("elsewhere", 1.0),
        ("fixed", 0.0005),
        ("fixed", 0.001),
        ("main", 0.0005),
        ("main", 0.001),
    ]
    # The run's folder gone: its points come from the kept figures, the table unchanged.
    table = results.read_text()
    gone = argv[:-4] + ["--out", str(tmp_path / "gone"), "--results", str(results), "--report-only"]
    third = subprocess.run(gone, capture_output=True, text=True, timeout=600, env=env)
    assert third.returncode == 0, third.stderr[-3000:]
    assert results.read_text() == table
    # a step rate that is not a positive number: one line, no traceback
    cfg["runs"] = [{"name": "bad", "hours": 0.001, "steps_per_hour": "fast", "train": {}}]
    (tmp_path / "bad.json").write_text(json.dumps(cfg))
    bad = argv[:2] + ["--config", str(tmp_path / "bad.json"), "--out", str(tmp_path / "bad")]
    fourth = subprocess.run(bad, capture_output=True, text=True, timeout=600, env=env)
    assert fourth.returncode != 0 and "steps_per_hour" in fourth.stderr and "Traceback" not in fourth.stderr
