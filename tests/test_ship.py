"""`neuralao ship` (pipeline/release/ship.py): train -> export -> parity -> test-split error -> provenance ->
atomic install under runtime/models, on a tiny real dataset with train / val / test splits by mesh.
Also the shipped models themselves (runtime/models): the radius input behaves like a radius."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.tolerances import TOL

TINY_TRAIN = {
    "widths": [2, 4],
    "epochs": 3,
    "internal_height": 40,
    "batch_size": 4,
    "lr": 0.01,
    "crop": 16,
    "crops_per_frame": 2,
    "threads": 1,
    "lr_schedule": "cosine",
    "budget_minutes": 30.0,
}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset
    from neuralao.pipeline.tracing.labeller import LabelSettings

    out = tmp_path_factory.mktemp("ship-ds")
    settings = DatasetSettings(
        name="tiny-ship",
        scenes=[
            SceneSpec("spot", "spot", views=4, split="train"),
            SceneSpec("box", "cornell_box", cameras="interior", views=2, split="val"),
            SceneSpec("cow", "cow", views=2, split="test"),
        ],
        size=(48, 40),
        labels=LabelSettings(rays=8, radii_rel=[0.0625, 0.25]),
        holdout_every=4,
        frames_per_shard=4,
    )
    build_dataset(settings, out, progress=False)
    return out


def _settings(corpus: Path, tmp: Path, **kw):
    from neuralao.pipeline.release.ship import ShipSettings

    base = dict(
        dataset=str(corpus),
        checkpoints=str(tmp / "ckpt"),
        out=str(tmp / "models"),
        default={"unet": "u-full"},
        time_sizes=[[32, 32]],
        time_repeats=1,
        models=[
            {"name": "u-full", "train": dict(TINY_TRAIN)},
            {"name": "u-half", "init": "u-full", "train": {**TINY_TRAIN, "scale": 2, "epochs": 2}},
        ],
    )
    base.update(kw)
    return ShipSettings(**base)


@pytest.fixture(scope="module")
def shipped(corpus, tmp_path_factory):
    from neuralao.pipeline.release.ship import ship

    tmp = tmp_path_factory.mktemp("ship")
    settings = _settings(corpus, tmp)
    return settings, ship(settings), tmp


def test_ship_installs_self_describing_exports(shipped, corpus):
    from neuralao.export.onnx_io import get_metadata, load_onnx
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.runtime.shipped import default_export, default_model, shipped_models

    settings, index, tmp = shipped
    models = Path(settings.out)
    assert sorted(shipped_models(models)) == ["u-full", "u-half"]
    assert default_export("unet", models) == models / "u-full"
    assert default_model("unet", models) == models / "u-full" / "model.onnx"
    assert not list(models.glob(".*"))  # no temporary or old folders left behind
    ds_hash = open_dataset(corpus).manifest["dataset_hash"]
    for name in ("u-full", "u-half"):
        manifest = json.loads((models / name / "manifest.json").read_text())
        prov = manifest["provenance"]
        assert (
            prov["dataset_hash"] == ds_hash
            and prov["commit"]
            and prov["epochs"] == (3 if name == "u-full" else 2)
        )
        assert prov["budget_minutes"] == 30.0 and prov["plan"]["epochs"] == prov["epochs"]
        assert prov["test_scenes"] == ["cow"] and "spot" not in prov["test_per_scene"]  # split by mesh
        assert 0 < prov["test"]["ssim"] <= 1 and set(prov["test"]["per_radius"]) == {"0.0625", "0.25"}
        assert prov["parity"]["glsl_vs_onnxruntime"] <= TOL.parity_unet_fp32
        assert prov["parity"]["onnxruntime_vs_torch"] <= prov["parity"]["tolerance_onnx"]
        assert len(prov["history"]) == prov["epochs"] and prov["gl_seconds"]["32x32"] > 0
        fp16 = manifest["fp16"]  # the bound a user's fp16 build is held to, from the model's own error
        assert 0 < fp16["max_abs_err"] <= fp16["bound"] and fp16["bound"] >= TOL.parity_fp16
        assert fp16["fp32_max_abs_err"] <= TOL.frame_passes_vs_reference and fp16["checks"] > 0
        meta = get_metadata(load_onnx(models / name / "model.onnx"))
        assert meta["provenance"]["dataset_hash"] == ds_hash and meta["provenance"]["test"] == prov["test"]
        assert (
            sum(f.stat().st_size for f in (models / name).rglob("*") if f.is_file())
            == index["models"][name]["bytes"]
        )
        assert index["models"][name]["bytes"] < settings.max_bytes
    assert json.loads((models / "u-half" / "manifest.json").read_text())["metadata"]["scale"] == 2
    assert set(index["baselines"]) == {"ssao", "gtao"} and index["baselines"]["gtao"]["test"]["pairs"] > 0


def test_ship_test_figures_are_the_installed_models_own(shipped, corpus):
    """Recompute the test error of the installed ONNX file independently of the ship run."""
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.evaluation.test_split import unet_predictor
    from neuralao.runtime.foundation.metrics import masked_ssim

    settings, _, _ = shipped
    onnx = Path(settings.out) / "u-full" / "model.onnx"
    prov = json.loads((onnx.parent / "manifest.json").read_text())["provenance"]
    predict = unet_predictor(onnx)
    scores = []
    for f in open_dataset(corpus).frames(split="test"):
        for j, r in enumerate(f["radii"]):
            mask = f["mask"] & f["valid_radii"][..., j]
            scores.append(masked_ssim(predict(f, float(r)), f["ao_radii"][..., j], mask))
    assert prov["test"]["ssim"] == pytest.approx(float(np.mean(scores)), abs=1e-12)


def test_ship_rerun_resumes_and_writes_the_same_onnx(shipped, corpus):
    from neuralao.pipeline.release.ship import ship

    settings, _, _ = shipped
    path = Path(settings.out) / "u-half" / "model.onnx"
    before = path.read_bytes()
    ship(settings, only=["u-half"])  # the checkpoint is complete: no training, same weights and metadata
    assert path.read_bytes() == before


def test_ship_refuses_bad_configs_and_oversized_exports(corpus, tmp_path):
    from neuralao.pipeline.release.ship import ship

    with pytest.raises(NeuralaoError, match="is not one of"):
        ship(_settings(corpus, tmp_path, default={"unet": "nope"}))
    with pytest.raises(NeuralaoError, match="not an earlier model"):
        ship(
            _settings(corpus, tmp_path, default={}, models=[{"name": "a", "init": "b", "train": TINY_TRAIN}])
        )
    with pytest.raises(NeuralaoError, match="no corpus"):
        ship(_settings(tmp_path / "none", tmp_path))
    small = _settings(
        corpus,
        tmp_path,
        max_bytes=1000,
        default={},
        models=[{"name": "u", "train": {**TINY_TRAIN, "epochs": 1}}],
    )
    with pytest.raises(NeuralaoError, match="over the 1000 limit"):
        ship(small)
    assert not (tmp_path / "models" / "u").exists() and not list((tmp_path / "models").glob(".*"))


def test_shipped_model_mean_ao_does_not_increase_with_the_radius():
    """The shipped default U-Net on real test-split frames: a larger radius input never brightens the
    frame on average (more geometry can occlude)."""
    from neuralao.runtime.shipped import MODELS_DIR, pure_unet_export

    if not (MODELS_DIR / "index.json").is_file():
        pytest.skip("no model shipped yet (make models)")
    from neuralao.export.onnx_io import load_onnx
    from neuralao.pipeline.gbuffers.rasterizer import render_gbuffer
    from neuralao.pipeline.geometry.camera import orbit
    from neuralao.pipeline.geometry.scene import load_scene
    from neuralao.runtime.predict import check_unet_onnx, ort_runner, run_padded
    from neuralao.runtime.unet_input import preprocess_frame, radius_param

    onnx = pure_unet_export() / "model.onnx"
    proto = load_onnx(onnx)
    m = int(check_unet_onnx(proto, onnx)["pad_multiple"])
    run = ort_runner(proto.SerializeToString())
    for mesh in ("lucy", "KnightArmor"):  # test-split meshes (configs/full.json)
        scene = load_scene(mesh)
        frame = render_gbuffer(scene, orbit(scene, 3, 128, 128, seed=3)[0])
        x, fg = preprocess_frame(frame), frame["mask"]
        means = []
        for rel in (1 / 32, 1 / 16, 1 / 8, 1 / 4):
            rho = radius_param(rel * scene.diagonal, frame["depth"], fg, frame["yfov"])
            means.append(float(run_padded(run, x, m, rho)[fg].mean()))
        assert np.all(np.diff(means) <= 1e-4), (mesh, means)


def test_infer_uses_the_shipped_default_when_given_only_a_frame(shipped, corpus, tmp_path, monkeypatch):
    import neuralao.runtime.shipped as sh
    from neuralao.pipeline.cli.main import main
    from neuralao.pipeline.datasets.dataset import open_dataset
    from neuralao.pipeline.evaluation.test_split import unet_predictor
    from neuralao.runtime.foundation.io import write_npz

    settings, _, _ = shipped
    frame = next(iter(open_dataset(corpus).frames(split="test")))
    path = tmp_path / "frame.npz"
    write_npz(path, **{k: np.asarray(v) for k, v in frame.items() if k not in ("scene", "split", "holdout")})
    monkeypatch.setattr(sh, "MODELS_DIR", tmp_path / "nothing")
    assert (
        main(["infer", str(path), "--out", str(tmp_path / "none.png")]) == 2
    )  # one-line error: none shipped
    monkeypatch.setattr(sh, "MODELS_DIR", Path(settings.out))
    radius = float(frame["radii"][0])
    assert main(["infer", str(path), "--radius", str(radius), "--out", str(tmp_path / "ao.png")]) == 0
    from PIL import Image

    got = np.asarray(Image.open(tmp_path / "ao.png"), dtype=np.float32) / 255.0
    want = unet_predictor(Path(settings.out) / "u-full" / "model.onnx")(frame, radius)
    assert np.abs(got - want).max() <= 0.5 / 255 + 1e-6  # the 8-bit PNG of the default model's AO


def test_ship_installs_a_hybrid_at_its_internal_height(corpus, tmp_path):
    """A GTAO-refining U-Net trained at an internal height goes through the whole release path: its
    parity runs on five-channel frames with real GTAO, its test split is scored with GTAO run first,
    and its export carries the internal-resolution passes."""
    from neuralao.pipeline.release.ship import ship

    hybrid = {**TINY_TRAIN, "gtao_input": True, "internal_height": 32, "epochs": 2}
    settings = _settings(
        corpus, tmp_path, default={"unet": "u-gtao"}, models=[{"name": "u-gtao", "train": hybrid}]
    )
    index = ship(settings)
    entry = index["models"]["u-gtao"]
    manifest = json.loads((tmp_path / "models" / "u-gtao" / "manifest.json").read_text())
    assert manifest["metadata"]["input_channels"].endswith(",gtao") and manifest["internal_height"] == 32
    assert (tmp_path / "models" / "u-gtao" / "glsl" / "internal" / "upsample.frag").is_file()
    assert manifest["provenance"]["parity"]["glsl_vs_onnxruntime"] <= TOL.parity_unet_fp32
    assert np.isfinite(entry["test"]["ssim"]) and np.isfinite(entry["test"]["rmse"])


def test_shaders_only_regenerates_from_the_onnx_and_keeps_the_model(shipped, tmp_path):
    """`neuralao ship --shaders-only`: a damaged shader folder is rewritten from model.onnx, byte-equal to
    what ship wrote; the ONNX and the training figures stay; a model that is not installed is an error."""
    import shutil

    from neuralao.pipeline.release.ship import ShipSettings, refresh_shipped

    settings, _, _ = shipped
    models = tmp_path / "models"
    shutil.copytree(settings.out, models)
    copy = ShipSettings(**{**settings.__dict__, "out": str(models)})
    before = {p.relative_to(models): p.read_bytes() for p in models.rglob("*") if p.is_file()}
    (models / "u-full" / "glsl" / "p02_conv.comp").write_text("damaged")
    shutil.rmtree(models / "u-full" / "wgsl")
    figures = refresh_shipped(copy, ["u-full"])
    assert figures["u-full"]["passed"] and figures["u-full"]["max_abs_err"] <= TOL.parity_unet_fp32
    after = {p.relative_to(models): p.read_bytes() for p in models.rglob("*") if p.is_file()}
    changed = {p for p in before.keys() | after.keys() if before.get(p) != after.get(p)}
    folders = {Path("u-full") / f / "manifest.json" for f in ("glsl", "vulkan", "wgsl")}
    assert changed <= {Path("u-full/manifest.json"), Path("index.json")} | folders, sorted(map(str, changed))
    for path in folders & changed:  # ship wrote these before it added the provenance to the ONNX metadata
        new, old = (json.loads(m[path]) for m in (after, before))
        assert new.pop("source_model_metadata")["provenance"] and "provenance" not in old.pop(
            "source_model_metadata"
        )
        assert new == old, path
    manifest = json.loads((models / "u-full" / "manifest.json").read_text())
    old = json.loads(before[Path("u-full/manifest.json")])
    assert manifest["onnx_sha256"] == old["onnx_sha256"] and manifest["metrics"] == old["metrics"]
    assert manifest["shaders"]["folders"] == ["glsl", "vulkan", "wgsl"]
    assert not list(models.glob(".*"))
    with pytest.raises(NeuralaoError, match="no installed model nope"):
        refresh_shipped(copy, ["nope"])


def test_init_checkpoint_continues_a_snapshot_and_names_it(shipped, corpus, tmp_path):
    """A model may start from a checkpoint file (a learning-curve snapshot): its provenance names the file
    and its hash; a missing file is a one-line error before any training."""
    from neuralao.pipeline.release.ship import ship
    from neuralao.runtime.foundation.io import sha256_file

    settings, _, _ = shipped
    snapshot = Path(settings.checkpoints) / "u-full.pt"
    spec = {"name": "u-cont", "init_checkpoint": str(snapshot), "train": {**TINY_TRAIN, "epochs": 1}}
    index = ship(_settings(corpus, tmp_path, default={}, models=[spec]))
    assert index["models"]["u-cont"]["epochs"] == 1
    prov = json.loads((tmp_path / "models" / "u-cont" / "manifest.json").read_text())["provenance"]
    assert prov["init_checkpoint"]["sha256"] == sha256_file(snapshot)
    assert prov["init_checkpoint"]["epoch"] == 3
    missing = {**spec, "name": "u-none", "init_checkpoint": str(tmp_path / "nope.pt")}
    with pytest.raises(NeuralaoError, match="nope.pt does not exist"):
        ship(_settings(corpus, tmp_path / "b", default={}, models=[missing]))
