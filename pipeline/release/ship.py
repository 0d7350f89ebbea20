"""Train, export, check and install the release models under ``runtime/models/`` (`neuralao ship`).

One committed config (``configs/models.json``) names the corpus and every shipped model with its
training settings (budget, widths, resolution, which model initialises it). For each model, in order:

1. train (resumable; checkpoints under ``checkpoints``, never in the repository);
2. export (ONNX + GLSL + manifest, with the torch / onnxruntime / OpenCV checks of ``neuralao.export.unet``);
3. parity of the generated GLSL against onnxruntime on real test frames (<= TOL.parity_unet_fp32);
4. error on the test split (meshes no training scene uses) at every label radius, next to SSAO
   and GTAO at the same radius (``neuralao.pipeline.evaluation.test_split``), and GL time at ``time_sizes``
   next to SSAO's and GTAO's on the same G-buffer;
5. provenance (dataset hash, commit, epochs, budget, wall time, validation and test metrics) into
   the manifest AND the ONNX metadata; the folder must stay under ``max_bytes``;
6. installed atomically: written to a temporary folder beside the target, then renamed onto it.

Everything the config holds is checked before the first model trains (:func:`check_settings`).

``runtime/models/index.json`` lists the models, the defaults per kind (``neuralao infer`` and
``neuralao report`` use them when given no export) and the baselines' figures of the same run.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from neuralao.export.onnx_io import get_metadata, load_onnx, save_onnx
from neuralao.export.unet import (
    FRAME_TARGETS,
    export_checkpoint,
    parity,
    parity_fp16,
    write_glsl,
    write_internal_passes_of,
)
from neuralao.pipeline.datasets.dataset import open_dataset, scene_of
from neuralao.pipeline.evaluation.report_baselines import timing_frame as report_timing_frame
from neuralao.pipeline.evaluation.report_settings import ReportSettings
from neuralao.pipeline.evaluation.test_split import evaluate_split, screen_space_predictor, unet_predictor
from neuralao.pipeline.models.unet_frames import load_dataset_frames
from neuralao.pipeline.models.unet_train import UNetTrainSettings, train
from neuralao.pipeline.models.unet_train import check_settings as check_train_settings
from neuralao.runtime.baselines import time_screen_space
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import atomic_folder, sha256_file, write_json
from neuralao.runtime.foundation.limits import MAX_CAP, check_int_range, check_pixels
from neuralao.runtime.foundation.manifest import read_json
from neuralao.runtime.foundation.metadata import MAX_INTERNAL_HEIGHT, MIN_INTERNAL_HEIGHT
from neuralao.runtime.foundation.paths import FOLDER, check_output, check_plain_name
from neuralao.runtime.foundation.settings import from_dict, settings_to_dict
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.glsl_runner import time_compute
from neuralao.runtime.internal_resolution import internal_size
from neuralao.runtime.unet_input import scales_up

log = logging.getLogger(__name__)

REPO = Path(__file__).resolve().parents[2]


@dataclass
class ShippedModel:
    """One release model: its name (folder), what initialises it, its training settings."""

    name: str = ""
    kind: str = "unet"
    init: str = ""  # name of an earlier model of this config whose checkpoint initialises this one
    # or a checkpoint file that does (relative to the repository): e.g. a learning-curve snapshot whose
    # constant-rate phase this model continues with its own schedule
    init_checkpoint: str = ""
    train: dict = field(default_factory=dict)  # UNetTrainSettings fields
    # the rows its export runs the network at (neuralao export --internal-height); 0: the rows it trained at
    internal_height: int = 0


@dataclass
class ShipSettings:
    """Settings of `neuralao ship` (configs/models.json)."""

    dataset: str = "build/full/dataset"  # the corpus (neuralao dataset), relative to the repository
    checkpoints: str = "build/ship"  # where training checkpoints go (never committed)
    out: str = "runtime/models"  # where the release exports are installed
    default: dict = field(default_factory=dict)  # kind -> model name used when no export is given
    models: list[dict] = field(default_factory=list)  # ShippedModel fields
    test_split: str = "test"
    test_frames: int = 0  # evaluate on about this many test frames (0 = all)
    parity_frames: int = 2  # real test frames for the GLSL parity (plus a crop of each)
    time_sizes: list[list[int]] = field(default_factory=lambda: [[512, 512], [1920, 1080]])
    time_repeats: int = 3
    # each installed folder must be smaller (glsl/, vulkan/ and wgsl/ each carry the weights, so that an
    # engine copies one folder)
    max_bytes: int = 4 << 20


def git_commit() -> str:
    """The repository's HEAD commit, with "+dirty" when tracked files differ from it ("unknown" outside
    git)."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def _path(p: str) -> Path:
    q = Path(p)
    return q if q.is_absolute() else REPO / q


SHIPPED_KINDS = ("unet",)  # the model kinds `neuralao ship` trains and installs


def _within(inner: Path, outer: Path) -> bool:
    """Whether ``inner`` is ``outer`` or a path below it (links resolved)."""
    a, b = os.path.realpath(inner), os.path.realpath(outer)
    return a == b or a.startswith(b.rstrip(os.sep) + os.sep)


def _check_folders(settings: ShipSettings) -> None:
    """``out`` and ``checkpoints`` can be written as folders, and the three folders are apart: each model
    replaces ``out/NAME`` whole and writes ``checkpoints/NAME.pt``, so one inside another would write
    into (or replace) the corpus or the checkpoints."""
    folders = {key: _path(getattr(settings, key)) for key in ("dataset", "checkpoints", "out")}
    for key in ("out", "checkpoints"):
        check_output(key, folders[key], FOLDER)
    for a, b in (("out", "dataset"), ("checkpoints", "dataset"), ("checkpoints", "out")):
        for x, y in ((a, b), (b, a)):
            if _within(folders[x], folders[y]):
                where = "is the same folder as" if _within(folders[y], folders[x]) else "is inside"
                raise NeuralaoError(
                    f"{x} {folders[x]} {where} {y} {folders[y]}: give each of dataset, checkpoints and out "
                    "a folder of its own (a model replaces out/NAME whole)"
                )


def _check_model(i: int, entry: object, earlier: list[str]) -> ShippedModel:
    """One entry of ``models``: its fields, a plain name (it becomes ``out/NAME`` and ``NAME.pt``), a kind
    ship installs, an ``init`` that is an earlier model, and training settings that train would accept."""
    if not isinstance(entry, dict):
        raise NeuralaoError(f"models[{i}] must be an object of ShippedModel fields, got {entry!r}")
    spec = from_dict(ShippedModel, entry, prefix=f"models[{i}].")
    check_plain_name(f"models[{i}].name", spec.name)
    if spec.name == "index.json":
        raise NeuralaoError(f"models[{i}].name 'index.json' is the index's file name under out; rename it")
    if spec.kind not in SHIPPED_KINDS:
        raise NeuralaoError(
            f"model {spec.name}: kind {spec.kind!r} cannot be shipped (only {', '.join(SHIPPED_KINDS)})"
        )
    if spec.init and spec.init not in earlier:
        raise NeuralaoError(f"model {spec.name}: init {spec.init!r} is not an earlier model of this config")
    if spec.init_checkpoint and not _path(spec.init_checkpoint).is_file():
        raise NeuralaoError(
            f"model {spec.name}: init_checkpoint {_path(spec.init_checkpoint)} does not exist"
        )
    if not isinstance(spec.train, dict):
        raise NeuralaoError(
            f"model {spec.name}: train must be an object of training settings, got {spec.train!r}"
        )
    if spec.internal_height != 0:
        check_int_range(
            f"model {spec.name}: internal_height",
            spec.internal_height,
            MIN_INTERNAL_HEIGHT,
            MAX_INTERNAL_HEIGHT,
        )
    ts = from_dict(UNetTrainSettings, dict(spec.train), prefix=f"models.{spec.name}.train.")
    try:
        check_train_settings(ts)  # train's own check: ranges, the model and a batch within the memory
    except NeuralaoError as e:
        raise NeuralaoError(f"model {spec.name}: train: {e}") from None
    return spec


def _check_split(settings: ShipSettings, data: Path) -> None:
    """The corpus is a dataset whose ``test_split`` has frames (parity and the test figures read them)."""
    if not (data / "manifest.json").is_file():
        raise NeuralaoError(f"no corpus at {data} (run `make corpus` first)")
    counts: dict[str, int] = {}
    for entry in open_dataset(data).manifest.get("shards", []):
        counts[entry["split"]] = counts.get(entry["split"], 0) + len(entry["views"])
    if not counts.get(settings.test_split):
        held = ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none"
        raise NeuralaoError(
            f"test_split {settings.test_split!r} has no frames in the corpus {data} (frames by split: {held})"
        )


def check_settings(
    settings: ShipSettings, only: list[str] | None = None, corpus: bool = True
) -> list[ShippedModel]:
    """Everything of a ship config that can be checked before any model trains (each refusal names the
    key and its value): the models and their training settings, the defaults, the counts and sizes, the
    folders, ``only``, and with ``corpus`` the corpus and its test split. Returns the models."""
    if not isinstance(settings.models, list) or not settings.models:
        raise NeuralaoError("the config lists no models")
    specs: list[ShippedModel] = []
    for i, entry in enumerate(settings.models):
        names = [s.name for s in specs]
        spec = _check_model(i, entry, names)
        if spec.name in names:
            raise NeuralaoError(f"model names must be unique, got {spec.name!r} twice")
        specs.append(spec)
    names = [s.name for s in specs]
    for kind, name in settings.default.items():
        if kind not in SHIPPED_KINDS:
            raise NeuralaoError(
                f"default names kind {kind!r}; ship installs {', '.join(SHIPPED_KINDS)} models only"
            )
        if name not in names:
            raise NeuralaoError(f"default {kind} model {name!r} is not one of {names}")
    unknown = [n for n in only or [] if n not in names]
    if unknown:
        raise NeuralaoError(f"--only {', '.join(unknown)}: not a model of this config (its models: {names})")
    check_int_range("test_frames", settings.test_frames, 0, MAX_CAP)
    check_int_range("parity_frames", settings.parity_frames, 1, MAX_CAP)
    check_int_range("time_repeats", settings.time_repeats, 1, MAX_CAP)
    check_int_range("max_bytes", settings.max_bytes, 1, MAX_CAP)
    for i, size in enumerate(settings.time_sizes):
        if len(size) != 2:
            raise NeuralaoError(f"time_sizes[{i}] must be [width, height], got {size}")
        check_pixels(f"time_sizes[{i}]", *size)
    _check_folders(settings)
    if corpus:
        _check_split(settings, _path(settings.dataset))
    return specs


def folder_bytes(folder: Path) -> int:
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())


def _checkpoint_provenance(path: str) -> dict | None:
    """The init checkpoint a model continued from: its path, hash and the training it holds."""
    if not path:
        return None
    import torch

    ckpt = torch.load(_path(path), map_location="cpu", weights_only=False)
    return {
        "path": path,
        "sha256": sha256_file(_path(path)),
        "epoch": ckpt.get("epoch"),
        "wall_seconds": ckpt.get("wall_seconds"),
        "threads": (ckpt.get("config") or {}).get("threads"),
    }


def timing_frame(data: Path, split: str, size: tuple[int, int]) -> tuple[dict, float]:
    """A G-buffer at ``size`` (W, H) from the pose of the split's first frame, and its label radius."""
    ds = open_dataset(data)
    frame = next(iter(ds.frames(split=split)))
    gbuffer, _ = report_timing_frame(scene_of(ds.manifest, frame["scene"]), frame, size)
    return gbuffer, float(np.max(frame["radii"]))


def baseline_figures(settings: ShipSettings, data: Path) -> dict:
    """SSAO and GTAO on the test split (every radius) and their GL time at ``time_sizes``."""
    rs = ReportSettings()
    methods = {
        "ssao": screen_space_predictor("ssao", rs.ssao),
        "gtao": screen_space_predictor("gtao", rs.gtao),
    }
    test = evaluate_split(data, settings.test_split, methods, settings.test_frames)
    times: dict[str, dict[str, float]] = {"ssao": {}, "gtao": {}}
    for w, h in settings.time_sizes:
        frame, radius = timing_frame(data, settings.test_split, (w, h))
        for name in times:
            times[name][f"{w}x{h}"] = time_screen_space(
                frame, name, radius, getattr(rs, name), repeats=settings.time_repeats * 4
            )
    return {
        name: {
            "test": {k: v for k, v in test["methods"][name].items() if k != "per_scene"},
            "gl_seconds": times[name],
        }
        for name in methods
    }


_LOADED: dict = {}  # the training / validation frames (train_fraction 1) of the last dataset loaded


def _fp16_figures(name: str, onnx_path: Path) -> dict:
    """What the export's fp16 option costs this model (:func:`parity_fp16`, without the per-check rows): the
    bound its manifest states, which the tests and a user's fp16 build are held to."""
    fig = parity_fp16(onnx_path)
    if fig["visible_in_8_bit"]:
        log.warning("%s: fp16 moves the AO by %.3g, more than half an 8-bit step", name, fig["max_abs_err"])
    return {k: v for k, v in fig.items() if k != "checks"} | {"checks": len(fig["checks"])}


def ship_model(
    settings: ShipSettings, spec: ShippedModel, data: Path, checkpoints: dict[str, Path], commit: str
) -> dict:
    """Train, export, check and install one model; returns its index entry."""
    if spec.kind != "unet":
        raise NeuralaoError(f"model {spec.name}: only kind 'unet' can be shipped, got {spec.kind!r}")
    train_cfg = dict(spec.train)
    if spec.init:
        if spec.init not in checkpoints:
            raise NeuralaoError(
                f"model {spec.name}: init {spec.init!r} is not an earlier model of this config"
            )
        train_cfg["init"] = str(checkpoints[spec.init])
    elif spec.init_checkpoint:
        path = _path(spec.init_checkpoint)
        if not path.is_file():
            raise NeuralaoError(f"model {spec.name}: init_checkpoint {path} does not exist")
        train_cfg["init"] = str(path)
    ts = from_dict(UNetTrainSettings, train_cfg, prefix=f"models.{spec.name}.train.")
    ckpt_path = _path(settings.checkpoints) / f"{spec.name}.pt"
    ckpt_path.parent.mkdir(parents=True, exist_ok=True)
    # the corpus is ~13 GB on disk: read it once per way of reading it (internal height, GTAO input,
    # input contract, GTAO's blur)
    key = (
        str(data),
        int(ts.internal_height),
        bool(ts.gtao_input),
        int(ts.preprocess_version),
        bool(ts.gtao_blur),
        bool(ts.gtao_raw_input),
    )
    if _LOADED.get("key") != key:
        _LOADED.clear()
        sets = load_dataset_frames(
            data, internal_height=key[1], gtao=key[2], version=key[3], gtao_blur=key[4], gtao_raw=key[5]
        )
        _LOADED.update(key=key, sets=sets)
    train_set, val_set, info = _LOADED["sets"]
    if ts.train_fraction != 1.0:  # the corpus-size models: a subset cut from the frames in memory
        train_set, val_set, info = load_dataset_frames(
            data,
            ts.train_fraction,
            loaded=_LOADED["sets"],
            internal_height=key[1],
            gtao=key[2],
            version=key[3],
            gtao_blur=key[4],
            gtao_raw=key[5],
        )
    log.info("%s: %d training frames, %d validation frames", spec.name, len(train_set), len(val_set))
    ckpt = train(ts, train_set, val_set, ckpt_path, info, progress=False)
    checkpoints[spec.name] = ckpt_path

    with atomic_folder(_path(settings.out) / spec.name) as tmp:  # replaces the installed folder whole
        return _export(settings, spec, data, ckpt, ckpt_path, info, ts, tmp, commit)


def _export(settings, spec, data, ckpt, ckpt_path, info, ts, tmp, commit) -> dict:
    """Export, check and time one trained model into the folder ``tmp``; returns its index entry."""
    manifest = export_checkpoint(ckpt_path, tmp, spec.internal_height or None)
    ds = open_dataset(data)
    frames = []
    for f in ds.frames(split=settings.test_split):
        if len(frames) >= settings.parity_frames:
            break
        frames.append(f)
    h0, w0 = frames[0]["depth"].shape
    par = parity(tmp, frames=frames, sizes=[(w0 - w0 // 4 - 1, h0 - h0 // 4 - 1)])  # plus an odd-sized crop
    if not par["passed"]:
        raise NeuralaoError(
            f"model {spec.name}: GLSL differs from onnxruntime by {par['max_abs_err']:.3g} > "
            f"{par['tolerance']:g}"
        )
    # the model as a user runs it: at the internal height it declares (frames of any size resampled to it)
    test = evaluate_split(
        data, settings.test_split, {"unet": unet_predictor(tmp / "model.onnx", "model")}, settings.test_frames
    )
    unet_test = test["methods"]["unet"]
    # the network's compute passes at the size it runs at for each frame size (its internal size when it
    # declares one; the scaling passes and a hybrid's GTAO pass are timed beside it by bench/bench_shipped.py)
    height = manifest.get("internal_height")
    gl_seconds = {
        f"{w}x{h}": time_compute(
            tmp / "glsl",
            *internal_size(w, h, height, scales_up(ts.preprocess_version))[::-1],
            repeats=settings.time_repeats,
        )
        for w, h in settings.time_sizes
    }
    provenance = {
        "dataset_hash": info.get("dataset_hash"),
        "dataset": str(settings.dataset),
        "train_frames": info.get("train_frames"),
        "train_fraction": info.get("train_fraction"),
        "training_scenes": len(info.get("training_scenes", [])),
        "commit": commit,
        "config": str(spec.name),
        "epochs": ckpt.get("epoch"),
        "budget_minutes": ts.budget_minutes,
        "wall_seconds": ckpt.get("wall_seconds"),
        "device": ckpt.get("device"),
        "plan": ckpt.get("plan", {}),
        "init": spec.init or None,
        "init_checkpoint": _checkpoint_provenance(spec.init_checkpoint),
        "validation": {k: v for k, v in ckpt.get("metrics", {}).items() if k != "per_scene"},
        "test": {k: v for k, v in unet_test.items() if k != "per_scene"},
        "test_per_scene": unet_test["per_scene"],
        "test_scenes": test["scenes"],
        "test_frames": test["frames"],
        "parity": {
            "glsl_vs_onnxruntime": par["max_abs_err"],
            "onnxruntime_vs_torch": manifest["checks"]["onnxruntime_vs_torch"],
            "tolerance_glsl": TOL.parity_unet_fp32,
            "tolerance_onnx": manifest["checks"]["tolerance"]["onnxruntime_vs_torch"],
        },
        "gl_seconds": gl_seconds,
        "history": [
            {k: h.get(k) for k in ("epoch", "wall_seconds", "val_ssim", "val_rmse", "train_loss", "lr")}
            for h in ckpt.get("history", [])
        ],
    }
    onnx_path = tmp / "model.onnx"
    proto = load_onnx(onnx_path)
    meta = get_metadata(proto)
    # (GL times are this machine's, not the model's: they stay in the manifest, so a rerun writes the same
    # ONNX bytes)
    meta["provenance"] = {
        k: v for k, v in provenance.items() if k not in ("history", "test_per_scene", "gl_seconds")
    }
    save_onnx(proto, onnx_path, meta)
    manifest.update(name=spec.name, onnx_sha256=sha256_file(onnx_path), metadata=meta, provenance=provenance)
    manifest["fp16"] = _fp16_figures(spec.name, onnx_path)  # the rendered check set, as a refresh
    manifest["checkpoint"] = {
        "file": ckpt_path.name,
        "sha256": sha256_file(ckpt_path),
        "epoch": ckpt.get("epoch"),
    }
    write_json(tmp / "manifest.json", manifest)
    size = folder_bytes(tmp)
    if size > settings.max_bytes:
        raise NeuralaoError(f"model {spec.name}: export is {size} bytes, over the {settings.max_bytes} limit")
    log.info(
        "%s: test SSIM %.4f RMSE %.4f, GL %s, %d bytes",
        spec.name,
        unet_test["ssim"],
        unet_test["rmse"],
        ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in gl_seconds.items()),
        size,
    )
    return {
        "kind": spec.kind,
        "bytes": size,
        "test": provenance["test"],
        "gl_seconds": gl_seconds,
        "epochs": ckpt.get("epoch"),
        "wall_seconds": ckpt.get("wall_seconds"),
        "scale": ckpt["model_args"].get("scale", 1),
        "widths": ckpt["model_args"].get("widths"),
        "init": spec.init or None,
    }


def ship(settings: ShipSettings, only: list[str] | None = None) -> dict:
    """Ship every model of ``settings`` (or those named in ``only``, which must keep their ``init`` order)."""
    specs = check_settings(settings, only)  # before anything trains
    data = _path(settings.dataset)
    commit = git_commit()
    out = _path(settings.out)
    index_path = out / "index.json"
    index = read_json(index_path, "model index") if index_path.is_file() else {}
    index.setdefault("models", {})
    checkpoints: dict[str, Path] = {}
    t0 = time.perf_counter()
    for spec in specs:
        if only and spec.name not in only:
            ckpt = _path(settings.checkpoints) / f"{spec.name}.pt"
            if ckpt.is_file():
                checkpoints[spec.name] = ckpt
            continue
        index["models"][spec.name] = ship_model(settings, spec, data, checkpoints, commit)
        index.update(default=dict(settings.default), commit=commit, settings=settings_to_dict(settings))
        write_json(index_path, index)  # after every model: a later failure keeps what was installed
    _LOADED.clear()
    index["baselines"] = baseline_figures(settings, data)
    index["seconds"] = time.perf_counter() - t0
    write_json(index_path, index)
    return index


def refresh_shaders(model_dir: Path, max_bytes: int, commit: str | None = None) -> dict:
    """Regenerate an installed model's shaders (glsl/ with HLSL and MSL, vulkan/, wgsl/, the internal
    passes) from its own model.onnx with this version of the generator, check the GLSL against
    onnxruntime on rendered frames, and reinstall the folder atomically. The ONNX bytes, the training
    provenance and the test figures stay as they were; the manifest records the commit that wrote the
    shaders. Returns the parity figures."""
    model_dir = Path(model_dir)
    manifest = read_json(model_dir / "manifest.json", "model manifest")
    onnx_path = model_dir / manifest.get("onnx", "model.onnx")
    proto = load_onnx(onnx_path)
    meta = get_metadata(proto)
    with atomic_folder(model_dir) as tmp:
        shutil.copy2(onnx_path, tmp / onnx_path.name)
        glsl_dir = write_glsl(proto, tmp / "glsl", "fp32")
        height = manifest.get("internal_height")
        internal = write_internal_passes_of(glsl_dir, int(height), meta) if height else None
        manifest.update(glsl=glsl_dir.name, internal_resolution=internal)
        manifest["shaders"] = {
            "commit": commit or git_commit(),
            "folders": [glsl_dir.name] + [folder for folder, _ in FRAME_TARGETS],
        }
        write_json(tmp / "manifest.json", manifest)
        par = parity(tmp)
        if not par["passed"]:
            raise NeuralaoError(
                f"{model_dir.name}: regenerated GLSL differs from onnxruntime by {par['max_abs_err']:.3g} > "
                f"{par['tolerance']:g}"
            )
        manifest.setdefault("provenance", {})["parity_shaders"] = {
            "glsl_vs_onnxruntime": par["max_abs_err"],
            "tolerance_glsl": par["tolerance"],
        }
        manifest["fp16"] = _fp16_figures(model_dir.name, tmp / onnx_path.name)
        write_json(tmp / "manifest.json", manifest)
        size = folder_bytes(tmp)
        if size > max_bytes:
            raise NeuralaoError(f"{model_dir.name}: export is {size} bytes, over the {max_bytes} limit")
    return par | {"bytes": size}


def refresh_shipped(settings: ShipSettings, only: list[str] | None = None) -> dict[str, dict]:
    """:func:`refresh_shaders` for every model of ``settings`` (or those in ``only``) installed under
    ``settings.out``; the index records each folder's new size. Returns the parity figures by name."""
    out = _path(settings.out)
    names = only or [m.get("name", "") for m in settings.models]
    missing = [n for n in names if not (out / n / "manifest.json").is_file()]
    if missing:
        raise NeuralaoError(f"no installed model {', '.join(missing)} under {out} (run `make models` first)")
    commit = git_commit()
    figures = {name: refresh_shaders(out / name, settings.max_bytes, commit) for name in names}
    index_path = out / "index.json"
    if index_path.is_file():
        index = read_json(index_path, "model index")
        for name, par in figures.items():
            if name in index.get("models", {}):
                index["models"][name]["bytes"] = par["bytes"]
        write_json(index_path, index)
    return figures
