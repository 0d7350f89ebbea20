"""The held-aside meshes: in no frame of the larger corpus, accepted by `neuralao evaluate` only in a
category that says it holds them, and not scored there for a model that trained on them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from neuralao.pipeline.datasets.dataset import DatasetSettings, expand_scenes
from neuralao.pipeline.evaluation.categories import (
    EvalCategory,
    EvalResolution,
    EvalSettings,
    check_settings,
    trained_on_held_aside,
)
from neuralao.pipeline.geometry.splits import HELD_ASIDE
from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.settings import from_dict
from neuralao.runtime.shipped import shipped_models

ROOT = Path(__file__).resolve().parents[1]


def test_the_larger_corpus_holds_no_held_aside_mesh():
    cfg = json.loads((ROOT / "configs" / "corpus-large.json").read_text())
    settings = from_dict(DatasetSettings, cfg)
    meshes = {s.mesh for s in expand_scenes(settings) if s.compose is None}
    pools = [m for s in expand_scenes(settings) if s.compose is not None for m in (s.compose.meshes or [])]
    assert meshes and pools
    assert not (meshes | set(pools)) & set(HELD_ASIDE)
    for gen in cfg[
        "composed"
    ]:  # every generator of train rooms names its pool (none falls back to a split's)
        assert gen["split"] != "train" or "meshes" in gen["compose"]


def _settings(meshes: list[str], held_aside: bool) -> EvalSettings:
    cat = EvalCategory("held", meshes=meshes, held_aside=held_aside)
    return EvalSettings(categories=[cat], resolutions=[EvalResolution()])


def test_evaluate_takes_held_aside_meshes_only_in_a_held_aside_category():
    check_settings(_settings(list(HELD_ASIDE), True))
    with pytest.raises(NeuralaoError, match="train split"):
        check_settings(_settings([HELD_ASIDE[0]], False))
    with pytest.raises(NeuralaoError, match="is not held aside"):
        check_settings(_settings(["bunny"], True))


def test_a_model_that_trained_on_them_is_known():
    """The shipped models trained on the larger corpus, which holds none of the held-aside meshes; a model
    whose training scenes name one (alone or as its close-ups, as the first corpus did) is known."""
    manifests = [json.loads((d / "manifest.json").read_text()) for d in shipped_models().values()]
    assert manifests and not any(trained_on_held_aside(m) for m in manifests)
    assert all(m["metadata"]["training_scenes"] for m in manifests)
    assert not trained_on_held_aside(
        {"metadata": {"training_scenes": ["bunny", "bunny-close", "room-30000"]}}
    )
    for scene in (HELD_ASIDE[0], f"{HELD_ASIDE[-1]}-close"):
        assert trained_on_held_aside({"metadata": {"training_scenes": ["bunny", scene]}})
