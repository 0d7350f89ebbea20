"""neuralao.runtime.foundation.metrics.masked_flip against the flip-evaluator package (NVIDIA FLIP, LDR) it
wraps.

The wrapper's job: grey AO to RGB, background set to 1 in both images, the error map averaged over
the mask. Checked against direct flip_evaluator calls on hand-built RGB images, and for the
properties FLIP promises: 0 for identical images, near 1 for black against white, growing with the
difference.
"""

from __future__ import annotations

import flip_evaluator
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.metrics import masked_flip


def _ao(h, w, seed):
    rng = np.random.default_rng(seed)
    return np.clip(gaussian_filter(rng.random((h, w)), 3.0) * 4 - 1.5, 0, 1)


def _mask(h, w):
    yy, xx = np.mgrid[:h, :w]
    return (yy - h / 2) ** 2 + (xx - w / 2) ** 2 < (0.4 * min(h, w)) ** 2


def test_identical_images_score_zero_whatever_the_background():
    ref = _ao(48, 64, 0)
    mask = _mask(48, 64)
    pred = np.where(mask, ref, np.random.default_rng(1).random(ref.shape))  # background garbage
    assert masked_flip(pred, ref, mask) == 0.0


def test_equals_flip_evaluator_on_the_composited_images():
    ref, mask = _ao(40, 56, 2), _mask(40, 56)
    pred = np.clip(ref + np.random.default_rng(3).normal(0, 0.1, ref.shape), 0, 1)
    rgb = lambda a: np.repeat(np.where(mask, a, 1.0)[..., None], 3, axis=2).astype(np.float32)  # noqa: E731
    error, mean_all, _ = flip_evaluator.evaluate(rgb(ref), rgb(pred), "LDR", applyMagma=False)
    error = error[..., 0]
    assert abs(masked_flip(pred, ref, mask) - float(np.mean(error[mask]))) < 1e-6
    # the full-image mean (background included, zero there) is smaller: background is not averaged
    assert mean_all < masked_flip(pred, ref, mask)


def test_black_against_white_is_near_the_maximum():
    ones = np.ones((32, 32), bool)
    assert masked_flip(np.zeros((32, 32)), np.ones((32, 32)), ones) > 0.9


@pytest.mark.parametrize("kind", ["offset", "noise"])
def test_flip_grows_with_the_difference(kind):
    ref, mask = _ao(64, 64, 4), _mask(64, 64)
    noise = np.random.default_rng(5).normal(0, 1, ref.shape)
    scores = []
    for a in (0.0, 0.02, 0.05, 0.1, 0.2):
        pred = ref + a if kind == "offset" else ref + a * noise
        scores.append(masked_flip(np.clip(pred, 0, 1), ref, mask))
    assert scores[0] == 0.0 and all(b > a for a, b in zip(scores, scores[1:], strict=False)), scores


def test_bad_shapes_are_one_line_errors():
    with pytest.raises(NeuralaoError, match="three"):
        masked_flip(np.zeros((4, 4)), np.zeros((4, 5)), np.ones((4, 4), bool))
    with pytest.raises(NeuralaoError, match="no pixel"):
        masked_flip(np.zeros((4, 4)), np.zeros((4, 4)), np.zeros((4, 4), bool))
