"""Settings loader: unknown keys and wrong types are rejected; overrides nest; presets resolve."""

from __future__ import annotations

import json

import pytest

from neuralao.pipeline.datasets.dataset import DatasetSettings
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import load_settings, settings_to_dict


def test_demo_preset_resolves():
    s = load_settings(DatasetSettings, "configs/demo.json", ["labels.rays=8", "seed=3"])
    assert s.labels.rays == 8 and s.seed == 3 and s.size == (128, 128)
    assert all(sc.split in ("train", "val", "test") for sc in s.scenes)
    assert json.loads(json.dumps(settings_to_dict(s)))["labels"]["rays"] == 8


@pytest.mark.parametrize(
    "override,message",
    [
        ("rayz=3", "unknown setting"),
        ("labels.rayz=3", "unknown setting"),
        ("seed=1.5", "integer"),
        ("labels.kernel=gaussian", "not one of"),
        ("size=[1,2,3]", "expected 2 values"),
        ("seed", "key=value"),
    ],
)
def test_bad_overrides_rejected(override, message):
    with pytest.raises(NeuralaoError, match=message):
        load_settings(DatasetSettings, "configs/demo.json", [override])


def test_missing_and_corrupt_preset(tmp_path):
    with pytest.raises(NeuralaoError, match="not found"):
        load_settings(DatasetSettings, tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    with pytest.raises(NeuralaoError, match="not valid JSON"):
        load_settings(DatasetSettings, bad)
