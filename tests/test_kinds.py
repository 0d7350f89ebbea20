"""The registry of model kinds (:mod:`neuralao.runtime.kinds`) is the one place a kind is listed: every role
of the real kinds names an existing object, and a test-only kind added to :data:`KINDS` alone reaches
`neuralao infer`'s predictor lookup, `neuralao train` and `neuralao export`, `neuralao parity`, the
report's rows (building, GLSL and onnxruntime runs, timing, order, colour) and the selection."""

from __future__ import annotations

import json
import sys
import types
from dataclasses import fields
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, helper

from neuralao.pipeline import cli
from neuralao.pipeline.evaluation.report_baselines import (
    family_colour,
    family_order,
    family_two_sided,
    radius_families,
)
from neuralao.pipeline.evaluation.report_gl import GLPath, predict_model, prepare_model, time_model
from neuralao.pipeline.evaluation.report_rows import discover_exports
from neuralao.pipeline.evaluation.report_settings import Method
from neuralao.pipeline.evaluation.report_writing import method_order
from neuralao.pipeline.evaluation.selection import candidate_families
from neuralao.runtime import kinds
from neuralao.runtime.infer import infer

TOY = "toy"
MODULE = "neuralao_test_toy_kind"  # the test kind's own module, put in sys.modules by the fixture
AO = 0.25  # the toy network's constant AO


def _roles() -> list[str]:
    """The ModelKind fields that name an object (every optional string, and parity)."""
    return [f.name for f in fields(kinds.ModelKind) if f.type == "str | None" or f.name == "parity"]


def test_every_role_of_every_kind_names_an_object():
    for name, kind in kinds.KINDS.items():
        for role in _roles():
            if getattr(kind, role) is not None:
                assert kinds.role(name, role) is not None, (name, role)


def test_the_views_follow_the_registry():
    assert list(kinds.trained()) == ["mlp", "unet", "field"]
    assert list(kinds.reported()) == ["mlp", "field", "unet"]  # report order
    assert sorted(kinds.predicted()) == ["field", "mlp", "unet"]
    assert radius_families() == ("screen-space", "unet")


def _toy_module(calls: list) -> types.ModuleType:
    """What a new kind writes in its own modules: predictor, trainer flags and run, exporter, parity,
    report row and GL path."""
    mod = types.ModuleType(MODULE)

    def predictor(onnx_path, **options):
        calls.append(("predictor", Path(onnx_path).name, options))

        def predict(frame, radius=None):
            calls.append(("predict", radius))
            return np.full(np.shape(frame["mask"]), AO, np.float32)

        return predict

    def add_arguments(p):
        p.add_argument("--out", required=True)
        p.add_argument("--steps", type=int, default=1)

    def run(args):
        calls.append(("train", args.steps))
        torch.save({"kind": TOY, "steps": args.steps}, args.out)
        return 0

    def export_checkpoint(ckpt_path, out_dir):
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        manifest = {"kind": TOY, "onnx": "model.onnx", "glsl": "glsl", "scene": None, "parameter_bytes": 12}
        (out / "manifest.json").write_text(json.dumps(manifest))
        calls.append(("export", Path(ckpt_path).name))
        return manifest

    def parity(export_dir, frames=None):
        calls.append(("parity", Path(export_dir).name, frames))
        return {"passed": True, "max_abs_err": 0.0}

    def row(name, d, manifest, scenes):
        return Method(
            name, TOY, "a toy network", "toy GL", "toy GL", bytes=manifest["parameter_bytes"], export=d
        )

    mod.predictor = predictor
    mod.add_arguments = add_arguments
    mod.run = run
    mod.export_checkpoint = export_checkpoint
    mod.parity = parity
    mod.row = row
    mod.GL = GLPath(
        load=lambda folder: ("program", Path(folder).name),
        run=lambda program, frame: np.full(np.shape(frame["mask"]), AO, np.float32),
        seconds=lambda program, w, h, n: 1e-3,
        ort_repeats=lambda n: 1,
        ort_options={"option": 1},
    )
    return mod


@pytest.fixture
def toy(monkeypatch):
    """The test kind registered by one entry in KINDS (and its module importable); the calls its roles
    got."""
    calls: list = []
    monkeypatch.setitem(sys.modules, MODULE, _toy_module(calls))
    entry = kinds.ModelKind(
        TOY,
        parity=f"{MODULE}:parity",
        predictor=f"{MODULE}:predictor",
        exporter=f"{MODULE}:export_checkpoint",
        trainer=MODULE,
        train_flags=f"{MODULE}:add_arguments",
        train_run=f"{MODULE}:run",
        train_help="a toy kind of this test",
        report_row=f"{MODULE}:row",
        report_gl=f"{MODULE}:GL",
        report_order=6,
        colour="tab:olive",
        radius_input=True,
        two_sided=False,
    )
    monkeypatch.setitem(kinds.KINDS, TOY, entry)
    return calls


def _onnx_of_kind(path: Path, kind: str) -> Path:
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "toy", [x], [y])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    helper.set_model_props(model, {"neuralao_kind": kind})
    onnx.save(model, str(path))
    return path


def test_infer_finds_the_predictor_of_a_new_kind(toy, tmp_path):
    onnx_path = _onnx_of_kind(tmp_path / "model.onnx", TOY)
    frame = {"mask": np.ones((3, 4), bool), "depth": np.ones((3, 4), np.float32)}
    ao = infer(onnx_path, frame, radius=2.0)
    assert ao.shape == (3, 4) and np.all(ao == AO)
    assert ("predict", 2.0) in toy  # radius_input: the radius reaches it


def test_train_export_and_parity_find_a_new_kind(toy, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["train", "--help"])
    assert e.value.code == 0 and TOY in capsys.readouterr().out
    ckpt = tmp_path / "toy.pt"
    assert cli.main(["train", TOY, "--out", str(ckpt), "--steps", "3"]) == 0
    assert ("train", 3) in toy
    out = tmp_path / "export"
    assert cli.main(["export", str(ckpt), "--out", str(out)]) == 0
    assert ("export", "toy.pt") in toy
    assert cli.main(["parity", str(out)]) == 0
    assert ("parity", "export", None) in toy
    # checked on frames, not on seeded inputs: --size is refused for it as for the other frame kinds
    assert cli.main(["parity", str(out), "--size", "8", "8"]) == 2
    assert "--size and --inputs apply" in capsys.readouterr().err


def test_the_report_builds_runs_and_times_rows_of_a_new_kind(toy, tmp_path):
    export = tmp_path / "exports" / "toy-a"
    export.mkdir(parents=True)
    (export / "manifest.json").write_text(json.dumps({"kind": TOY, "parameter_bytes": 12}))
    (m,) = discover_exports(tmp_path / "exports", ["scene"], expected=[])
    assert (m.name, m.family, m.available, m.bytes) == ("toy-a", TOY, True, 12)
    prepare_model(m)
    assert m.available, m.reason
    assert m.program == ("program", "glsl") and ("predictor", "model.onnx", {"option": 1}) in toy
    frame = {"mask": np.ones((2, 3), bool), "scene": "scene"}
    assert np.all(predict_model(m, frame, radius=1.5) == AO)  # through its GL path's run
    times = time_model(m, (4, 2), repeats=3)
    assert times["seconds"] == 1e-3 and times["seconds_onnxruntime"] >= 0.0
    assert ("predict", 1.0) in toy  # timed with a radius: it takes one
    # its order, colour, sides and radius input, as the tables, plots and selection read them
    assert family_order(TOY) == 6 and family_colour(TOY) == "tab:olive" and not family_two_sided(TOY)
    assert radius_families() == ("screen-space", "unet", TOY)
    assert TOY in candidate_families()
    rows = {"toy-a": {"family": TOY, "bytes": 12}, "unet": {"family": "unet", "bytes": 1}}
    assert method_order({**rows, "ssao": {"family": "screen-space"}}) == ["ssao", "unet", "toy-a"]


def test_a_missing_or_broken_export_of_a_new_kind_is_a_row_of_that_kind(toy, tmp_path):
    broken = tmp_path / "exports" / "toy-broken"
    broken.mkdir(parents=True)
    (broken / "manifest.json").write_text("{not json")
    rows = discover_exports(tmp_path / "exports", ["scene"], expected=["toy-b", "nothing"])
    got = {m.name: (m.family, m.available) for m in rows}
    assert got == {"toy-b": (TOY, False), "nothing": ("unknown", False), "toy-broken": (TOY, False)}
