"""Dataset stage: same config -> same hash; an interrupted run resumes to the same bytes; corrupt shards are
caught."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from neuralao.pipeline.datasets.dataset import open_dataset
from neuralao.runtime.foundation.errors import NeuralaoError

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
        [
            sys.executable,
            "-m",
            "neuralao.pipeline.cli",
            "dataset",
            str(config),
            "--out",
            str(out),
            "--no-progress",
        ],
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
    if (out / "manifest.json").exists():  # it finished before the kill landed (a loaded machine): whole
        assert json.loads((out / "manifest.json").read_text())["dataset_hash"] == manifest["dataset_hash"]
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


# ---------------------------------------------------------------- sizes and fields of view

# Frames of three sizes (one per shard, drawn) and fields of view drawn per view, on an isolated orbit,
# an interior with its own sizes and a composed generator with its own range; one scene keeps yfov_deg.
MIXED = {
    "name": "mixed",
    "seed": 3,
    "size": [24, 24],
    "sizes": [[32, 24], [16, 16], [40, 16]],
    "yfov_range_deg": [30, 90],
    "holdout_every": 4,
    "frames_per_shard": 2,
    "labels": {"rays": 8, "radii_rel": [0.125, 0.25]},
    "scenes": [
        {"name": "suzanne", "mesh": "suzanne", "cameras": "orbit", "views": 6, "split": "train"},
        {"name": "spot", "mesh": "spot", "cameras": "orbit", "views": 2, "yfov_deg": 50, "split": "train"},
        {
            "name": "box",
            "mesh": "cornell_box",
            "cameras": "interior",
            "views": 2,
            "split": "val",
            "sizes": [[24, 16]],
        },
    ],
    "composed": [
        {
            "count": 1,
            "seed": 1,
            "views": 2,
            "cameras": ["closeup"],
            "yfov_range_deg": [40, 45],
            "compose": {"meshes": ["Fox", "beetle"], "objects": [2, 3]},
        }
    ],
}


class _Stop(Exception):
    pass


def _stopping_engine(after: int):
    """A local engine that dies after ``after`` shards (an interrupted run, in-process)."""
    from neuralao.pipeline.engines.engine import LocalEngine

    class Stopping(LocalEngine):
        def _run(self, pending):
            for k, item in enumerate(super()._run(pending)):
                if k == after:
                    raise _Stop
                yield item

    return Stopping()


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, build_dataset
    from neuralao.runtime.foundation.settings import from_dict

    root = tmp_path_factory.mktemp("mixed")
    build_dataset(from_dict(DatasetSettings, MIXED), root / "a", progress=False)
    return root


def test_mixed_sizes_and_fields_of_view(mixed):
    ds = open_dataset(mixed / "a")
    sizes = {tuple(s) for s in ds.manifest["sizes"]}
    assert len(sizes) >= 3 and sizes <= {(32, 24), (16, 16), (40, 16), (24, 16)}
    fovs = {}
    for entry in ds.manifest["shards"]:  # a shard holds one size, the one its entry names
        arrays = ds.load_shard(entry)
        w, h = entry["size"]
        assert arrays["depth"].shape[1:] == (h, w) and arrays["ao_radii"].shape[1:3] == (h, w)
        fovs.setdefault(entry["scene"], []).extend(np.degrees(arrays["yfov"]).tolist())
        if entry["scene"] == "box":
            assert entry["size"] == [24, 16]  # the scene's own sizes win over the dataset's
    assert len({s["size"][0] for s in ds.manifest["shards"] if s["scene"] == "suzanne"}) >= 2
    assert all(30 <= f <= 90 for f in fovs["suzanne"] + fovs["box"]) and len(set(fovs["suzanne"])) == 6
    assert np.allclose(fovs["spot"], 50.0)  # a scene's yfov_deg wins over the dataset's range
    assert all(40 <= f <= 45 for f in fovs["comp-0001"])  # the generator's own range
    for f in ds.frames(scene="suzanne"):  # every orbit view fits its own field of view: none is empty
        assert f["mask"].any() and not f["mask"].all()


def test_mixed_dataset_same_hash_twice_and_after_resume(mixed, tmp_path):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, build_dataset
    from neuralao.runtime.foundation.settings import from_dict

    reference = json.loads((mixed / "a" / "manifest.json").read_text())
    settings = from_dict(DatasetSettings, MIXED)
    assert (
        build_dataset(settings, tmp_path / "b", progress=False)["dataset_hash"] == reference["dataset_hash"]
    )
    out = tmp_path / "c"
    with pytest.raises(_Stop):
        build_dataset(settings, out, progress=False, engine=_stopping_engine(3))
    assert len(json.loads((out / "progress.json").read_text())["shards"]) == 3
    resumed = build_dataset(settings, out, progress=False)
    assert resumed["dataset_hash"] == reference["dataset_hash"] and resumed["shards"] == reference["shards"]


def test_loader_trains_on_mixed_sizes(mixed, tmp_path):
    from neuralao.pipeline.models.unet_frames import load_dataset_frames
    from neuralao.pipeline.models.unet_train import UNetTrainSettings, train

    train_set, val_set, info = load_dataset_frames(mixed / "a")
    assert len(set(train_set.sizes)) >= 2 and isinstance(train_set.x, list)
    assert [tuple(x.shape[-2:]) for x in train_set.x] == [tuple(y.shape[-2:]) for y in train_set.y]
    settings = UNetTrainSettings(epochs=1, batch_size=4, crop=16, crops_per_frame=1, widths=[4, 8], threads=1)
    ckpt = train(settings, train_set, val_set, tmp_path / "u.pt", info)
    assert np.isfinite(ckpt["history"][0]["train_loss"]) and np.isfinite(ckpt["metrics"]["val_ssim"])
    sub = train_set.subset([0, len(train_set) - 1])
    assert sub.sizes == [train_set.sizes[0], train_set.sizes[-1]]
    with pytest.raises(NeuralaoError, match="one size"):
        train(replace(settings, crop=0), train_set, val_set, tmp_path / "w.pt", info)
    with pytest.raises(NeuralaoError, match="larger than the frames"):
        train(replace(settings, crop=24), train_set, val_set, tmp_path / "w.pt", info)


def test_settings_unused_leave_config_and_cameras_as_before():
    """Configs without the size / field-of-view / pool settings keep their config hash and cameras."""
    from neuralao.pipeline.datasets.dataset import DatasetSettings, _config_dict, expand_scenes, view_look
    from neuralao.pipeline.geometry.camera import orbit
    from neuralao.pipeline.geometry.scene import load_scene
    from neuralao.runtime.foundation.settings import load_settings

    root = Path(__file__).resolve().parents[1] / "configs"
    for name in ("full.json", "demo.json"):
        settings = load_settings(DatasetSettings, root / name)
        text = json.dumps(_config_dict(settings))
        assert not any(k in text for k in ('"sizes"', '"yfov_range_deg"', '"pool"')), name
        assert all(view_look(settings, s, i) is None for i, s in enumerate(expand_scenes(settings)))
    scene = load_scene("suzanne")
    plain = orbit(scene, 5, 32, 24, 40.0, seed=9)
    framed = orbit(scene, 5, 0, 0, 0.0, seed=9, frames=[(32, 24, 40.0)] * 5)
    for a, b in zip(plain, framed, strict=True):
        assert np.array_equal(a.pose, b.pose) and a.to_dict() == b.to_dict()


def test_bad_sizes_and_ranges_are_rejected():
    from neuralao.pipeline.datasets.dataset import DatasetSettings, _validate, expand_scenes
    from neuralao.runtime.foundation.settings import from_dict

    def check(config):
        settings = from_dict(DatasetSettings, config)
        _validate(settings, expand_scenes(settings), Path("."))

    scene = {"name": "spot", "mesh": "spot"}
    with pytest.raises(NeuralaoError, match="unknown setting"):
        check({"scenes": [scene], "size_list": [[8, 8]]})
    with pytest.raises(NeuralaoError, match="does not match"):
        check({"scenes": [scene], "sizes": [[8, 8, 8]]})
    with pytest.raises(NeuralaoError, match="sizes"):
        check({"scenes": [{**scene, "sizes": []}]})
    with pytest.raises(NeuralaoError, match="yfov_range_deg"):
        check({"scenes": [scene], "yfov_range_deg": [90, 30]})
    with pytest.raises(NeuralaoError, match="poses"):
        check({"scenes": [{**scene, "cameras": "file", "poses": "p.json", "yfov_range_deg": [30, 60]}]})


# ---------------------------------------------------------------- the corpus config


def test_corpus_config_isolates_every_mesh_and_splits_by_mesh():
    """configs/corpus.json: every object mesh alone on an orbit (no floor) in its own split, interiors
    and composed rooms as configs/full.json, several sizes and fields of view; the split check holds."""
    from neuralao.pipeline.datasets.dataset import DatasetSettings, _validate, expand_scenes
    from neuralao.pipeline.geometry.splits import INTERIORS, OBJECTS, object_meshes
    from neuralao.runtime.foundation.settings import from_dict, load_settings

    root = Path(__file__).resolve().parents[1] / "configs"
    settings = load_settings(DatasetSettings, root / "corpus.json")
    specs = expand_scenes(settings)
    _validate(settings, specs, root)
    alone = {s.mesh: s.split for s in specs if s.compose is None and s.cameras == "orbit"}
    assert alone == {m: split for split, names in OBJECTS.items() for m in names}
    rooms = {s.mesh: s.split for s in specs if s.compose is None and s.cameras == "interior"}
    assert rooms == {m: split for split, names in INTERIORS.items() for m in names}
    composed = [s for s in specs if s.compose is not None]
    assert {s.split for s in composed} == {"train", "val", "test"} and {s.cameras for s in composed} == {
        "orbit",
        "interior",
        "closeup",
    }
    assert all(object_meshes(s.split, s.compose.pool) == OBJECTS[s.split] for s in composed)  # latest pool
    assert len(set(map(tuple, settings.sizes))) >= 4 and any(w != h for w, h in settings.sizes)
    assert settings.labels.rays == 256 and settings.labels.radii_rel == [0.03125, 0.0625, 0.125, 0.25]
    # The split stays by mesh: a val mesh alone in a train scene is refused, as in a composed pool.
    data = json.loads((root / "corpus.json").read_text())
    leak = next(s for s in data["scenes"] if s["mesh"] == "fandisk")
    leak["split"] = "train"
    bad = from_dict(DatasetSettings, data)
    with pytest.raises(NeuralaoError, match="fandisk.*split by mesh"):
        _validate(bad, expand_scenes(bad), root)
    data = {
        "scenes": [{"name": "Avocado", "mesh": "Avocado", "split": "val"}],
        "composed": [{"count": 1, "views": 1, "compose": {"pool": 2}}],
    }
    bad = from_dict(DatasetSettings, data)
    with pytest.raises(NeuralaoError, match="Avocado"):  # pool 2 holds the added props
        _validate(bad, expand_scenes(bad), root)
    data["composed"][0]["compose"]["pool"] = 1
    ok = from_dict(DatasetSettings, data)
    _validate(ok, expand_scenes(ok), root)


def test_the_disk_check_counts_the_sizes_drawn_and_the_shards_a_rerun_keeps(tmp_path, monkeypatch):
    """A corpus drawing its frame sizes per shard needs the expected bytes of those sizes, not every
    view at the largest; and a rerun needs room only for the shards it has still to write."""
    from neuralao.pipeline.datasets import dataset
    from neuralao.pipeline.datasets.dataset import DatasetSettings, check_counts
    from neuralao.runtime.foundation.limits import PIXEL_DISK_BYTES
    from neuralao.runtime.foundation.settings import from_dict

    scene = {"name": "tet", "mesh": "tetrahedron", "cameras": "orbit", "views": 100, "split": "train"}
    config = {"size": [64, 64], "sizes": [[64, 64], [64, 64], [64, 64], [256, 256]], "scenes": [scene]}
    settings = from_dict(DatasetSettings, config)
    expected = 100 * (3 * 64 * 64 + 256 * 256) / 4 * PIXEL_DISK_BYTES  # 100 views at the mean draw
    out = tmp_path / "d"
    calls: list[float] = []
    monkeypatch.setattr(dataset, "check_disk", _recording_disk_check(expected, calls))
    check_counts(settings, out)  # fits: the largest size for every view would not (4.0x the bytes)
    assert calls == [pytest.approx(expected)]
    (out / "shards").mkdir(parents=True)
    (out / "shards" / "tet-0000.npz").write_bytes(b"\0" * 1000)
    check_counts(settings, out)
    assert calls[-1] == pytest.approx(expected - 1000)  # what is written stays; only the rest is new


def _recording_disk_check(free: float, calls: list):
    from neuralao.runtime.foundation.limits import check_disk

    def check(name, nbytes, folder, shown):
        calls.append(nbytes)
        if nbytes > free:  # the real check's message, against a fixed free size
            check_disk(name, float("inf"), folder, shown)

    return check


def test_a_corpus_past_the_free_disk_is_refused_in_one_line(tmp_path, capsys):
    from neuralao.pipeline.cli.main import main

    scene = {"name": "tet", "mesh": "bunny", "cameras": "orbit", "views": 100000, "split": "train"}
    config = {"size": [4096, 4096], "frames_per_shard": 1, "labels": {"rays": 1}, "scenes": [scene]}
    (tmp_path / "c.json").write_text(json.dumps(config))  # 100,000 views of 4096x4096: about 100 TiB
    rc = main(["dataset", str(tmp_path / "c.json"), "--out", str(tmp_path / "d")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2 and len(err) == 1 and "free on the disk" in err[0], (rc, err)
    assert not (tmp_path / "d").exists()
