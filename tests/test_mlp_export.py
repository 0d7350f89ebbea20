"""MLP export (export/mlp.py): ONNX vs torch vs OpenCV, generated GLSL vs onnxruntime on real frames,
`neuralao infer`."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import onnx
import pytest
import torch
from helpers import onnx_vs_torch_tol

from neuralao.export.mlp import (
    CHECK_BATCHES,
    INPUT,
    OUTPUT,
    check_backends,
    export_checkpoint,
    onnx_bytes,
    parity,
    random_normals,
    render_parity_frames,
)
from neuralao.export.onnx_io import get_metadata, run_onnxruntime, run_opencv
from neuralao.pipeline.cli.main import main as cli_main
from neuralao.pipeline.models.mlp import (
    BakedMLP,
    MLPSettings,
    load_checkpoint,
    model_from_checkpoint,
    predict,
    radius_zero_inputs,
    train,
)
from neuralao.pipeline.tracing.labeller import LabelSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.io import write_npz
from neuralao.runtime.foundation.tolerances import TOL
from neuralao.runtime.predict import mlp_infer_frame as infer_frame

SMALL = MLPSettings(
    hidden=[16, 8],
    views=8,
    size=(96, 96),
    holdout_views=1,
    holdout_size=(64, 64),
    max_iterations=60,
    labels=LabelSettings(rays=16),
)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A trained 16x8 checkpoint of spot, exported: (checkpoint path, export dir, manifest)."""
    root = tmp_path_factory.mktemp("mlp_export")
    ckpt = root / "spot-16x8.pt"
    train(SMALL, ckpt, mesh="spot")
    out = root / "export"
    manifest = export_checkpoint(ckpt, out)
    return ckpt, out, manifest


@pytest.fixture(scope="module")
def spot_frame():
    return render_parity_frames("spot", views=1, size=(80, 64))[0]


def test_export_layout_and_manifest(exported):
    ckpt, out, manifest = exported
    for name in ("model.onnx", "manifest.json", "glsl/manifest.json", "glsl/mlp.frag", "glsl/mlp_es300.frag"):
        assert (out / name).is_file(), name
    on_disk = json.loads((out / "manifest.json").read_text())
    assert on_disk == json.loads(json.dumps(manifest))
    assert manifest["kind"] == "mlp" and manifest["parameters"] == 929 and manifest["parameter_bytes"] == 3716
    assert manifest["model_size"] == "16x8" and manifest["mesh"] == "spot"
    checks = manifest["checks"]
    assert checks["onnxruntime_vs_torch"] <= checks["tolerance"]["onnxruntime_vs_torch"]
    # the rule at the graph's depth, for outputs of magnitude 1 to 2 (unclamped AO)
    rule = [onnx_vs_torch_tol(peak, out / "model.onnx") for peak in (1.0, 2.0)]
    assert rule[0] <= checks["tolerance"]["onnxruntime_vs_torch"] <= rule[1]
    assert manifest["checks"]["opencv_vs_onnxruntime"] <= TOL.opencv_vs_onnx
    assert not list(out.rglob(".*.tmp*"))


def test_onnx_graph_and_metadata(exported):
    _, out, _ = exported
    proto = onnx.load(str(out / "model.onnx"))
    assert {n.op_type for n in proto.graph.node} <= {"Gemm", "Tanh"}
    (inp,) = proto.graph.input
    (outp,) = proto.graph.output
    assert inp.name == INPUT and outp.name == OUTPUT
    dims = [d.dim_param or d.dim_value for d in inp.type.tensor_type.shape.dim]
    assert dims[1] == 48 and isinstance(dims[0], str)  # dynamic N
    meta = get_metadata(proto)
    assert (
        meta["neuralao_kind"] == "mlp" and meta["training_mesh"] == "spot" and meta["parameter_bytes"] == 3716
    )
    assert "unclamped" in meta["output"].lower() or "not clamped" in meta["output"].lower()
    assert "holdout_ssim" in meta["measured_error"]


def test_onnxruntime_and_opencv_match_torch(exported):
    ckpt, out, _ = exported
    model = model_from_checkpoint(load_checkpoint(ckpt))
    for n in (*CHECK_BATCHES, 33):
        for rz in (False, True):
            x = random_normals(n, seed=100 + n, radius_zero=rz)
            ref = predict(model, x)
            (y_ort,) = run_onnxruntime(out / "model.onnx", {INPUT: x})
            y_cv = run_opencv(out / "model.onnx", {INPUT: x})
            assert y_ort.shape == (n, 1)
            assert np.abs(y_ort[:, 0] - ref).max() <= onnx_vs_torch_tol(ref, out / "model.onnx")
            assert np.abs(y_cv.reshape(-1) - y_ort[:, 0]).max() <= TOL.opencv_vs_onnx


def test_backend_check_fails_on_a_different_model(tmp_path):
    torch.manual_seed(0)
    a, b = BakedMLP([16, 8]), BakedMLP([16, 8])
    path = tmp_path / "b.onnx"
    path.write_bytes(onnx_bytes(b))
    with pytest.raises(NeuralaoError, match="differs from torch"):
        check_backends(a, path)


def test_glsl_matches_onnxruntime_on_a_real_frame(exported, spot_frame):
    _, out, _ = exported
    result = parity(out, [spot_frame])
    assert result["passed"], result
    assert result["max_abs_err"] <= TOL.parity_mlp_fp32
    assert result["max_abs_err_es300"] is not None and result["max_abs_err_es300"] <= TOL.parity_mlp_fp32
    assert result["max_abs_err_fp16"] <= TOL.parity_fp16
    assert result["background_max_abs_err"] == 0.0
    assert {r["dialect"] for r in result["checks"]} == {"glsl330", "es300"}
    assert all(r["foreground_pixels"] > 500 for r in result["checks"])


def test_parity_fails_when_the_shader_is_not_the_model(exported, spot_frame, tmp_path):
    """Swap model.onnx for another network's: the shipped shader no longer matches, parity must say so."""
    _, out, _ = exported
    bad = tmp_path / "bad"
    shutil.copytree(out, bad)
    proto = onnx.load(str(bad / "model.onnx"))
    for init in proto.graph.initializer:
        if init.dims == [8, 16] or tuple(init.dims) == (16, 48):
            arr = onnx.numpy_helper.to_array(init).copy()
            arr[0, 0] += 1e-3
            init.CopyFrom(onnx.numpy_helper.from_array(arr, init.name))
            break
    onnx.save(proto, str(bad / "model.onnx"))
    result = parity(bad, [spot_frame], fp16=False)
    assert not result["passed"] and result["max_abs_err"] > TOL.parity_mlp_fp32


def test_infer_frame_matches_network(exported, spot_frame):
    ckpt, out, _ = exported
    model = model_from_checkpoint(load_checkpoint(ckpt))
    ao = infer_frame(out / "model.onnx", spot_frame)
    mask = spot_frame["mask"]
    want = np.clip(predict(model, radius_zero_inputs(spot_frame["normal_obj"][mask])), 0, 1)
    assert ao.shape == mask.shape and ao.dtype == np.float32
    assert np.abs(ao[mask] - want).max() <= onnx_vs_torch_tol(want, out / "model.onnx")
    assert (ao[~mask] == 1.0).all()


def test_infer_cli_end_to_end_and_bad_input(exported, spot_frame, tmp_path, capsys):
    from PIL import Image

    _, out, _ = exported
    frame_path = tmp_path / "frame.npz"
    write_npz(frame_path, **{k: np.asarray(v) for k, v in spot_frame.items() if k != "scene"})
    ao_png, comp_png = tmp_path / "ao.png", tmp_path / "composite.png"
    rc = cli_main(
        [
            "infer",
            str(out / "model.onnx"),
            str(frame_path),
            "--out",
            str(ao_png),
            "--composite",
            str(comp_png),
        ]
    )
    assert rc == 0
    ao = np.asarray(Image.open(ao_png))
    comp = np.asarray(Image.open(comp_png))
    want = infer_frame(out / "model.onnx", spot_frame)
    assert ao.shape == spot_frame["mask"].shape and comp.shape == (*spot_frame["mask"].shape, 3)
    assert np.abs(ao.astype(float) - (want * 255 + 0.5).astype(np.uint8)).max() <= 1
    assert (ao[~spot_frame["mask"]] == 255).all()
    # Composite: shaded foreground darker than the background; AO darkens it further where AO < 1.
    assert comp[spot_frame["mask"]].mean() < comp[~spot_frame["mask"]].mean()

    def fails(argv: list[str], match: str) -> None:
        assert cli_main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and match in err[0], err

    bad = dict(spot_frame)
    bad["normal_obj"] = np.zeros((64, 80, 4), np.float32)
    write_npz(tmp_path / "bad.npz", **{k: np.asarray(v) for k, v in bad.items() if k != "scene"})
    fails(
        ["infer", str(out / "model.onnx"), str(tmp_path / "bad.npz"), "--out", str(tmp_path / "x.png")],
        "(H, W, 3)",
    )
    stacked = {k: np.stack([np.asarray(v)] * 2) for k, v in spot_frame.items() if k != "scene"}
    write_npz(tmp_path / "shard.npz", **stacked)
    fails(
        ["infer", str(out / "model.onnx"), str(tmp_path / "shard.npz"), "--out", str(tmp_path / "x.png")],
        "--index",
    )
    assert (
        cli_main(
            [
                "infer",
                str(out / "model.onnx"),
                str(tmp_path / "shard.npz"),
                "--index",
                "1",
                "--out",
                str(tmp_path / "y.png"),
            ]
        )
        == 0
    )
    unknown = tmp_path / "plain.onnx"
    unknown.write_bytes(onnx_bytes(BakedMLP([4, 2])))  # no neuralao metadata
    fails(["infer", str(unknown), str(frame_path), "--out", str(tmp_path / "x.png")], "unknown model kind")
    (tmp_path / "broken.npz").write_bytes(b"PK\x03\x04 truncated")
    fails(
        ["infer", str(out / "model.onnx"), str(tmp_path / "broken.npz"), "--out", str(tmp_path / "x.png")],
        "corrupt",
    )
    assert not (tmp_path / "x.png").exists()


def test_export_cli_and_wrong_checkpoint_kind(exported, tmp_path, capsys):
    ckpt, _, _ = exported
    assert cli_main(["export", str(ckpt), "--out", str(tmp_path / "e")]) == 0
    assert (tmp_path / "e" / "manifest.json").is_file()
    other = tmp_path / "other.pt"
    torch.save({"kind": "something", "state_dict": {}}, other)
    assert cli_main(["export", str(other), "--out", str(tmp_path / "f")]) == 2
    assert "not a neuralao checkpoint" in capsys.readouterr().err
    from neuralao.export.mlp import export_checkpoint as export_mlp

    torch.save({"kind": "unet", "model_args": {}, "state_dict": {}, "config": {}}, other)
    with pytest.raises(NeuralaoError, match="not an MLP checkpoint"):
        export_mlp(other, tmp_path / "g")
    assert not (tmp_path / "g" / "manifest.json").exists()


def test_parity_renders_frames_of_the_training_mesh_by_default(exported):
    _, out, _ = exported
    result = parity(out, None, fp16=False)
    assert result["passed"] and "spot" in result["frame_source"] and result["frames"] == 2


def test_any_size_exports_and_matches(tmp_path, spot_frame):
    """A non-paper size (5x3) and a wider one (20x12: layers of 5 and 3 vec4s) through the whole chain.
    (64x32 is exported and checked by the benchmark: llvmpipe needs minutes to compile it uncached.)"""
    from neuralao.pipeline.models.mlp import make_checkpoint, save_checkpoint

    for hidden in ([5, 3], [20, 12]):
        torch.manual_seed(1)
        model = BakedMLP(hidden).eval()
        samples_info = {"scene": "spot", "mesh": "spot"}
        ckpt = make_checkpoint(
            model, replace(MLPSettings(), hidden=hidden), _FakeSamples(samples_info), {}, {"seconds": 0.0}
        )
        path = tmp_path / f"m{hidden[0]}.pt"
        save_checkpoint(path, ckpt)
        out = tmp_path / f"e{hidden[0]}"
        manifest = export_checkpoint(path, out)
        assert manifest["parameters"] == sum(p.numel() for p in model.parameters())
        result = parity(out, [spot_frame], fp16=False)
        assert result["passed"], result


class _FakeSamples:
    def __init__(self, info: dict):
        self.info = info
