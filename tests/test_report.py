"""`neuralao report` and `neuralao select` on a tiny dataset and tiny exports built here.

The MLP exports are networks whose last layer is a constant (weights 0, bias c), so their AO is
known exactly: the report's SSIM / RMSE for them are checked against metrics computed here from
the cached ground truth. The selection is checked against a brute-force pick.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import flip_evaluator
import numpy as np
import pytest
import torch
from PIL import Image

from neuralao.pipeline import cli
from neuralao.pipeline.datasets.dataset import DatasetSettings, SceneSpec, build_dataset, open_dataset
from neuralao.pipeline.evaluation.selection import choose, select_from_results
from neuralao.pipeline.tracing.labeller import LabelSettings
from neuralao.runtime.foundation.io import read_npz
from neuralao.runtime.foundation.metrics import masked_rmse, masked_ssim

# (name, hidden sizes, constant output)
MLPS = (("mlp-16x8", (16, 8), 0.9), ("mlp-32x16", (32, 16), 0.97))
FAST = [
    "--gt-rays",
    "32",
    "--frames-per-scene",
    "2",
    "--time-size",
    "40",
    "32",
    "--repeats",
    "1",
    "--set",
    "trace_rays=[2,4]",
    "--set",
    "bake_rays=8",
    "--set",
    "bake_samples_per_vertex=2",
]


def constant_mlp_checkpoint(path: Path, hidden, value: float, scene: str) -> None:
    from neuralao.pipeline.models.mlp import KIND, BakedMLP, model_args_dict

    model = BakedMLP(hidden=hidden)
    last = [m for m in model.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.fill_(value)
    torch.save(
        {
            "kind": KIND,
            "format_version": 1,
            "model_args": model_args_dict(model),
            "config": {},
            "state_dict": model.state_dict(),
            "scene": scene,
            "mesh": scene,
            "metrics": {},
        },
        path,
    )


def tiny_unet_checkpoint(path: Path) -> None:
    from neuralao.pipeline.models.unet import UNetArgs, build_model, model_args_dict
    from neuralao.pipeline.models.unet_train import KIND

    torch.manual_seed(0)
    args = UNetArgs(widths=[2, 4])
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


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """A dataset of two scenes (one train orbit, one val interior) at 32x32 and an export folder:
    two constant MLPs for spot, a tiny untrained U-Net, a broken export, and no mlp-64x32."""
    root = tmp_path_factory.mktemp("report")
    data = root / "dataset"
    settings = DatasetSettings(
        name="tiny",
        scenes=[
            SceneSpec("spot", "spot", views=4, split="train"),
            SceneSpec("box", "cornell_box", cameras="interior", views=2, split="val"),
        ],
        size=(32, 32),
        labels=LabelSettings(rays=8),
        holdout_every=2,
        frames_per_shard=4,
    )
    build_dataset(settings, data, progress=False)
    exports = root / "export"
    from neuralao.export.mlp import export_checkpoint as export_mlp
    from neuralao.export.unet import export_checkpoint as export_unet

    for name, hidden, value in MLPS:
        ckpt = root / f"{name}.pt"
        constant_mlp_checkpoint(ckpt, hidden, value, "spot")
        export_mlp(ckpt, exports / name)
    tiny_unet_checkpoint(root / "unet.pt")
    export_unet(root / "unet.pt", exports / "unet")
    from neuralao.export.field import export_checkpoint as export_field
    from neuralao.pipeline.models.field import FieldSettings
    from neuralao.pipeline.models.field import train as train_field

    fs = FieldSettings(
        hidden=[8, 4],
        octaves=4,
        samples=2048,
        steps=40,
        check_every=20,
        holdout_views=1,
        holdout_size=(32, 32),
        labels=LabelSettings(rays=8),
    )
    for scene in ("spot", "box"):  # one field per mesh; the report shows them as one row per size
        train_field(fs, root / f"field-{scene}.pt", data=data, scene=scene)
        export_field(root / f"field-{scene}.pt", exports / f"field-{scene}-8x4")
    (exports / "mlp-broken").mkdir()
    (exports / "mlp-broken" / "manifest.json").write_text("{not json")
    return root, data, exports


@pytest.fixture(scope="module")
def report(workspace):
    root, data, exports = workspace
    out = root / "out"
    assert cli.main(["report", "--data", str(data), "--exports", str(exports), "--out", str(out), *FAST]) == 0
    return out, json.loads((out / "report.json").read_text())


def test_report_lists_every_method(report):
    out, r = report
    ms = r["methods"]
    for name in (
        "ssao",
        "gtao",
        "vertex-sampled",
        "vertex-lsq",
        "trace-2",
        "trace-4",
        "mlp-16x8",
        "mlp-32x16",
        "unet",
        "field-8x4",
        "vertex-lsq-8bit",
    ):
        assert ms[name]["available"], (name, ms[name].get("reason"))
        assert np.isfinite(ms[name]["ssim"]) and np.isfinite(ms[name]["rmse"]) and ms[name]["seconds"] > 0
    assert not ms["mlp-64x32"]["available"] and "no export" in ms["mlp-64x32"]["reason"]
    assert not ms["mlp-broken"]["available"]
    md = (out / "report.md").read_text()
    assert "mlp-64x32: no export" in md and "## Model selection" in md
    assert ms["mlp-16x8"]["scope"] == "spot" and set(ms["mlp-16x8"]["per_scene"]) == {"spot"}
    assert set(ms["unet"]["per_scene"]) == {"spot", "box"}
    assert ms["field-8x4"]["scope"] == "box, spot" and ms["field-8x4"]["family"] == "field"
    assert set(ms["field-8x4"]["per_scene"]) == {"spot", "box"} and "field-spot-8x4" not in ms
    assert ms["field-8x4"]["bytes"] == 4 * ((30 * 8 + 8) + (8 * 4 + 4) + (4 + 1) + 6 + 12)
    assert ms["field-8x4"]["two_sided"] and not ms["vertex-lsq"]["two_sided"]
    assert "Single-sided surfaces: vertex-sampled, vertex-lsq, vertex-lsq-8bit" in md
    # 8-bit storage: a quarter of the bytes, and the error moves by at most half a step of 1/255
    for scene, ps in ms["vertex-lsq"]["per_scene"].items():
        assert (
            ms["vertex-lsq-8bit"]["per_scene"][scene]["bytes"] * 4
            == ps["bytes"]
            == 4 * r["scenes"][scene]["vertices"]
        )
    assert abs(ms["vertex-lsq-8bit"]["rmse"] - ms["vertex-lsq"]["rmse"]) <= 0.5 / 255 + 1e-7


def test_report_metrics_match_an_independent_computation(report, workspace):
    """Constant-output MLPs: their report metrics equal masked metrics of the constant image against
    the cached ground truth; the frames are exactly the held-back ones (+ val-scene top-up)."""
    out, r = report
    _, data, _ = workspace
    ds = open_dataset(data)
    frames = {(f["scene"], f["view"]): f for f in ds.frames()}
    spot_rows = [f for f in r["frames"] if f["scene"] == "spot"]
    assert [f["view"] for f in spot_rows] == [1, 3] and all(f["holdout"] for f in spot_rows)
    box_rows = [f for f in r["frames"] if f["scene"] == "box"]
    assert sorted(f["view"] for f in box_rows) == [0, 1]  # val scene: held-back view 1, topped up with view 0
    for name, _, value in MLPS:
        ssim, rmse, flip = [], [], []
        for row in spot_rows:
            frame = frames[("spot", row["view"])]
            (gt_file,) = (out / "gt").glob(f"spot-{row['view']:04d}-*.npz")
            gt = read_npz(gt_file)
            mask = frame["mask"] & gt["valid"]
            pred = np.where(frame["mask"], np.float32(value), np.float32(1.0))
            ssim.append(masked_ssim(pred, gt["ao"], mask))
            rmse.append(masked_rmse(pred, gt["ao"], mask))
            # FLIP straight from flip-evaluator: grey -> RGB, background 1 in both, mean over the mask
            rgb = lambda a, m=mask: np.repeat(np.where(m, a, 1.0)[..., None], 3, 2).astype(np.float32)  # noqa: E731
            error = flip_evaluator.evaluate(rgb(gt["ao"]), rgb(pred), "LDR", applyMagma=False)[0][..., 0]
            flip.append(float(error[mask].mean()))
        assert abs(r["methods"][name]["ssim"] - np.mean(ssim)) < 1e-5
        assert abs(r["methods"][name]["rmse"] - np.mean(rmse)) < 1e-5
        assert abs(r["methods"][name]["flip"] - np.mean(flip)) < 1e-5


def test_ratios_are_over_ssao_on_the_same_frames(report):
    _, r = report
    ms = r["methods"]
    assert ms["ssao"]["time_ratio_vs_ssao"] == pytest.approx(1.0)
    # MLP: its own scene only -> SSAO's error on spot's frames, not over all scenes
    spot_ssao = ms["ssao"]["per_scene"]["spot"]["rmse"]
    assert ms["mlp-16x8"]["rmse_ratio_vs_ssao"] == pytest.approx(ms["mlp-16x8"]["rmse"] / spot_ssao)
    assert ms["gtao"]["time_ratio_vs_ssao"] == pytest.approx(ms["gtao"]["seconds"] / ms["ssao"]["seconds"])
    front = r["pareto"]
    assert front, "the Pareto front is never empty"
    pts = {n: (ms[n]["seconds"], ms[n]["rmse_ratio_vs_ssao"]) for n in front}
    for t, e in pts.values():  # no front member dominates another
        assert not any(t2 <= t and e2 <= e and (t2, e2) != (t, e) for t2, e2 in pts.values())


def test_figures_are_real_pngs(report):
    out, r = report
    for name in ["speed_vs_error.png", "contact_spot.png", "contact_box.png"]:
        with Image.open(out / name) as im:
            assert im.format == "PNG" and im.size[0] > 200 and im.size[1] > 200
    assert r["figures"]["scatter"] == "speed_vs_error.png"
    # report.html links a viewer page per scene: its least-squares bake and the scene's MLP / field shaders
    page = (out / "report.html").read_text()
    assert "report.md" in page and "<th>FLIP</th>" in page
    for scene in ("spot", "box"):
        link = r["figures"]["viewer"][scene]
        assert f'href="{link}"' in page and (out / link).is_file()
        kinds = [m["name"] for m in json.loads((out / link).with_name("scene.json").read_text())["methods"]]
        assert kinds[0] == "vertex-lsq (report bake)" and any(k.startswith("field-8x4") for k in kinds), kinds
    spot = json.loads((out / r["figures"]["viewer"]["spot"]).with_name("scene.json").read_text())["methods"]
    assert {"mlp-16x8 ES 3.00 shader", "mlp-32x16 ES 3.00 shader"} <= {m["name"] for m in spot}


def _expected_choice(r: dict, scene: str, target: float) -> tuple[str, bool, list[str]]:
    """Brute force: every non-traced representation measured on the scene, by (bytes, time, name)."""
    rows = []
    for n, e in r["methods"].items():
        ps = e.get("per_scene", {}).get(scene) if e.get("available") else None
        if ps is None or e["family"] == "traced":
            continue
        b = ps.get("bytes", e["bytes"])
        rows.append((math.inf if b is None else b, ps["seconds"], n, ps["ssim"]))
    rows.sort()
    passing = [row for row in rows if row[3] >= target]
    chosen = passing[0][2] if passing else max(rows, key=lambda row: row[3])[2]
    return chosen, bool(passing), [row[2] for row in rows]


def test_select_picks_the_cheapest_representation_meeting_the_target(report, workspace, tmp_path):
    out, r = report
    root, data, exports = workspace
    for scene in ("spot", "box"):
        ssims = sorted(
            e["per_scene"][scene]["ssim"]
            for e in r["methods"].values()
            if e.get("available") and scene in e.get("per_scene", {}) and e["family"] != "traced"
        )
        for target in [0.0, *ssims, 1.0]:
            sel = select_from_results(r, target)["scenes"][scene]
            chosen, met, order = _expected_choice(r, scene, target)
            assert sel["chosen"] == chosen and sel["met_target"] == met, (scene, target)
            assert [c["name"] for c in sel["tried"]] == order[: len(sel["tried"])]
    assert sorted(r["select_at"]) == ["0.9", "0.95"]
    for t, sel in r["select_at"].items():
        assert sel["scenes"] == select_from_results(r, float(t))["scenes"]
    assert "## Selection at several targets" in (out / "report.md").read_text()
    spot = select_from_results(r, 0.0)["scenes"]["spot"]
    assert {"ssao", "gtao", "vertex-lsq-8bit", "mlp-16x8", "field-8x4", "unet"} <= set(
        _expected_choice(r, "spot", 0)[2]
    )
    assert spot["bytes_saved"] == spot["largest_bytes"] - spot["bytes"]
    # the CLI: from the report's numbers, and measuring by itself (same ground truth settings)
    sel_path = tmp_path / "select.json"
    assert (
        cli.main(
            [
                "select",
                "--data",
                str(data),
                "--exports",
                str(exports),
                "--out",
                str(sel_path),
                "--report",
                str(out / "report.json"),
                "--target",
                "0.5",
            ]
        )
        == 0
    )
    from_report = json.loads(sel_path.read_text())
    measured = tmp_path / "measured.json"
    assert (
        cli.main(
            [
                "select",
                "--data",
                str(data),
                "--exports",
                str(exports),
                "--out",
                str(measured),
                "--target",
                "0.5",
                "--set",
                "gt_rays=32",
                "--set",
                "frames_per_scene=2",
                "--set",
                "time_size=[40,32]",
                "--set",
                "repeats=1",
                "--set",
                "bake_rays=8",
                "--set",
                "bake_samples_per_vertex=2",
                "--set",
                "trace_rays=[2,4]",
            ]
        )
        == 0
    )
    again = json.loads(measured.read_text())
    for scene in ("spot", "box"):
        a, b = from_report["scenes"][scene], again["scenes"][scene]
        assert a["chosen"] == b["chosen"] and a["ssim"] == pytest.approx(b["ssim"], abs=1e-6)


def test_report_and_select_do_not_import_each_other():
    """The report's modules never import the select command; the selection rule imports neither."""
    import ast

    evaluation = Path(__file__).parents[1] / "pipeline" / "evaluation"

    def imported(path: Path) -> set[str]:
        tree = ast.parse(path.read_text())
        return {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}

    reports = sorted(evaluation.glob("report*.py"))
    assert reports
    for path in reports:
        assert "neuralao.pipeline.cli.select" not in imported(path), path.name
    selection = imported(evaluation / "selection.py")
    assert not {
        n for n in selection if n.startswith(("neuralao.pipeline.evaluation.report", "neuralao.pipeline.cli"))
    }


def test_choose_handles_no_candidate_meeting_the_target():
    cands = [
        {"name": "a", "family": "mlp", "bytes": 10, "ssim": 0.5, "rmse": 0.1, "seconds": 1.0, "frames": 1},
        {"name": "b", "family": "unet", "bytes": 100, "ssim": 0.7, "rmse": 0.1, "seconds": 4.0, "frames": 1},
    ]
    e = choose(cands, 0.9)
    assert e["chosen"] == "b" and not e["met_target"] and e["bytes_saved"] == 0
    e = choose(cands, 0.6)
    assert e["chosen"] == "b" and e["met_target"]
    e = choose(cands, 0.4)
    assert e["chosen"] == "a" and e["bytes_saved"] == 90 and e["time_ratio"] == pytest.approx(0.25)


def test_report_without_exports_and_bad_input(tmp_path, workspace, capsys):
    _, data, _ = workspace
    out = tmp_path / "r"
    (tmp_path / "none").mkdir()  # an empty export folder: every expected export is "not available"
    assert (
        cli.main(
            [
                "report",
                "--data",
                str(data),
                "--exports",
                str(tmp_path / "none"),
                "--out",
                str(out),
                *FAST,
                "--set",
                "contact_sheets=false",
            ]
        )
        == 0
    )
    r = json.loads((out / "report.json").read_text())
    assert all(not r["methods"][n]["available"] for n in ("mlp-16x8", "mlp-32x16", "mlp-64x32", "unet"))
    assert all(
        c["family"] in ("screen-space", "baked")
        for e in r["select"]["scenes"].values()
        for c in [r["methods"][t["name"]] for t in e["tried"]]
    )
    assert cli.main(["report", "--data", str(tmp_path / "nothing"), "--out", str(out)]) == 2
    assert cli.main(["report", "--data", str(data), "--out", str(out), "--set", "bogus=1"]) == 2
    assert cli.main(["select", "--data", str(data), "--out", str(tmp_path / "s.txt")]) == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert len(errors) == 3 and all(line.startswith("neuralao ") for line in errors)
