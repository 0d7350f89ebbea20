"""Dataset stage: same config -> same hash; an interrupted run resumes to the same bytes; corrupt shards are caught."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pipeline.dataset import open_dataset
from pipeline.errors import NeuralaoError

CONFIG = {
    "name": "tiny",
    "seed": 7,
    "size": [32, 24],
    "holdout_every": 2,
    "frames_per_shard": 1,
    "labels": {"rays": 16},
    "scenes": [
        {"name": "suzanne", "mesh": "suzanne", "cameras": "orbit", "views": 3, "split": "train"},
        {"name": "box", "mesh": "cornell_box", "cameras": "interior", "views": 2, "split": "val"},
    ],
}


def _run(config: Path, out: Path, **kw) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "pipeline.cli", "dataset", str(config), "--out", str(out), "--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds")
    cfg = root / "tiny.json"
    cfg.write_text(json.dumps(CONFIG))
    p = _run(cfg, root / "a")
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    return root, cfg, json.loads((root / "a" / "manifest.json").read_text())


def test_manifest_and_frames(reference):
    root, _, manifest = reference
    assert manifest["frames"] == 5 and len(manifest["shards"]) == 5
    ds = open_dataset(root / "a")
    frames = list(ds.frames())
    assert [f["scene"] for f in frames] == ["suzanne"] * 3 + ["box"] * 2
    assert [f["holdout"] for f in frames] == [False, True, False, False, True]
    for f in frames:
        assert f["depth"].shape == (24, 32) and f["normal_cam"].shape == (24, 32, 3)
        assert np.all(f["ao"][~f["mask"]] == 1.0) and np.all((f["ao"] >= 0) & (f["ao"] <= 1))
        assert f["mask"].any()
    assert len(list(ds.frames(split="val"))) == 2


def test_same_config_same_hash(reference, tmp_path):
    root, cfg, manifest = reference
    p = _run(cfg, tmp_path / "b")
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    again = json.loads((tmp_path / "b" / "manifest.json").read_text())
    assert again["dataset_hash"] == manifest["dataset_hash"]


def test_interrupted_run_resumes_to_identical_output(reference, tmp_path):
    root, cfg, manifest = reference
    out = tmp_path / "c"
    p = _run(cfg, out, start_new_session=True)
    progress = out / "progress.json"
    deadline = time.time() + 240
    while time.time() < deadline and p.poll() is None:
        if progress.exists() and len(json.loads(progress.read_text() or "{}").get("shards", {})) >= 2:
            break
        time.sleep(0.05)
    if p.poll() is None:
        os.killpg(p.pid, signal.SIGKILL)
    p.wait()
    assert not (out / "manifest.json").exists() or p.returncode == 0
    with pytest.raises(NeuralaoError, match="interrupted"):
        if not (out / "manifest.json").exists():
            open_dataset(out)
        else:  # finished before the kill: still exercise the message path
            raise NeuralaoError("interrupted run finished early")
    p = _run(cfg, out)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    resumed = json.loads((out / "manifest.json").read_text())
    assert resumed["dataset_hash"] == manifest["dataset_hash"]
    assert not progress.exists() and not list(out.rglob("*.tmp*"))


def test_corrupt_shard_detected(reference, tmp_path):
    import shutil

    root, _, manifest = reference
    copy = tmp_path / "d"
    shutil.copytree(root / "a", copy)
    shard = copy / manifest["shards"][0]["file"]
    data = shard.read_bytes()
    shard.write_bytes(data[: len(data) // 2])  # truncated
    with pytest.raises(NeuralaoError, match="corrupt"):
        list(open_dataset(copy).frames())
