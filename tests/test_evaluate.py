"""`neuralao evaluate`: screen-space AO by category x resolution on test meshes, beside SSAO and GTAO.

Small frames and few rays: the command's plumbing (frames per resolution, categories, radii, the
tables, the manifests, the refusal of trained meshes, resumption) against closed forms: a method
that returns the labels scores SSIM 1, RMSE 0 and FLIP 0 exactly.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from neuralao.pipeline.cli.main import main
from neuralao.pipeline.datasets.dataset import open_dataset
from neuralao.pipeline.evaluation.categories import EvalSettings, check_settings, score_frame
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import from_dict
from neuralao.runtime.shipped import default_export

CONFIG = {
    "name": "tiny",
    "radii_rel": [0.0625, 0.25],
    "categories": [
        {"name": "scans", "meshes": ["horse"]},
        {"name": "rooms", "composed": 1, "cameras": "interior"},
    ],
    "resolutions": [{"size": [48, 48], "rays": 16, "views": 1}, {"size": [80, 48], "rays": 16, "views": 1}],
}


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    root = tmp_path_factory.mktemp("evaluate")
    (root / "eval.json").write_text(json.dumps(CONFIG))
    model = root / "model"
    shutil.copytree(default_export("unet"), model)
    argv = [
        "evaluate",
        str(root / "eval.json"),
        "--models",
        str(model),
        "--internal",
        "model,native",
        "--out",
        str(root / "out"),
        "--write-manifest",
        "--no-progress",
    ]
    assert main(argv) == 0
    return root, model, json.loads((root / "out" / "evaluation.json").read_text())


def test_every_category_resolution_and_method_is_scored(evaluated):
    root, model, result = evaluated
    methods = result["methods"]
    assert set(methods) == {"model", "model@native", "ssao", "gtao"}
    for m in methods.values():
        assert set(m["cells"]) == {"scans", "rooms"}
        for cat in m["cells"].values():
            assert set(cat) == {"48x48", "80x48"}
            for cell in cat.values():
                assert (
                    0 < cell["pairs"] <= 2
                    and -1 <= cell["ssim"] <= 1
                    and 0 <= cell["rmse"] <= 1
                    and 0 <= cell["flip"] <= 1
                )
        assert set(m["per_radius"]) == {"0.0625", "0.25"}
    md = (root / "out" / "evaluation.md").read_text()
    assert "| scans | 80x48 |" in md and "beats GTAO" in md


def test_labels_scored_against_themselves_are_perfect(evaluated):
    root, _, _ = evaluated
    frame = next(open_dataset(root / "out" / "frames" / "48x48").frames(split="test"))
    oracle = {
        "oracle": lambda f, r: np.asarray(
            f["ao_radii"][..., list(np.asarray(f["radii"])).index(r)], np.float32
        )
    }
    rows = score_frame(frame, oracle)
    assert rows and all(
        r["ssim"] == pytest.approx(1.0) and r["rmse"] == 0.0 and r["flip"] == 0.0 for r in rows
    )


def test_manifest_gets_the_table_and_the_report_shows_it(evaluated):
    from neuralao.pipeline.evaluation.plots import shipped_markdown

    _, model, result = evaluated
    manifest = json.loads((model / "manifest.json").read_text())
    assert manifest["evaluation"]["methods"]["gtao"] == result["methods"]["gtao"]
    assert set(manifest["evaluation"]["methods"]) == {"model", "model@native", "ssao", "gtao"}
    lines = shipped_markdown({"folder": "x", "models": {"model": {"evaluation": manifest["evaluation"]}}}, {})
    assert any("where users run it" in line for line in lines) and any(
        "| rooms | 48x48 |" in line for line in lines
    )


def test_a_rerun_resumes_the_frames(evaluated):
    root, model, result = evaluated
    shards = sorted((root / "out" / "frames").rglob("*.npz"))
    before = {p: p.stat().st_mtime_ns for p in shards}
    argv = [
        "evaluate",
        str(root / "eval.json"),
        "--models",
        str(model),
        "--internal",
        "native",
        "--out",
        str(root / "out"),
        "--no-flip",
        "--no-progress",
    ]
    assert main(argv) == 0
    again = json.loads((root / "out" / "evaluation.json").read_text())
    assert again["methods"]["gtao"]["all"]["ssim"] == result["methods"]["gtao"]["all"]["ssim"]
    assert shards and {p: p.stat().st_mtime_ns for p in shards} == before  # nothing re-rendered or re-traced


@pytest.mark.parametrize(
    "change,match",
    [
        ({"categories": [{"name": "scans", "meshes": ["bunny"]}]}, "train split"),
        ({"resolutions": [{"size": [8, 8]}]}, "16..8192"),
        ({"radii_rel": [0.5]}, "radii_rel"),
        ({"categories": [{"name": "a", "meshes": ["horse"]}, {"name": "a", "meshes": ["lucy"]}]}, "unique"),
    ],
)
def test_bad_configs_are_one_line_errors(change, match):
    with pytest.raises(NeuralaoError, match=match) as e:
        check_settings(from_dict(EvalSettings, CONFIG | change))
    assert "\n" not in str(e.value)
