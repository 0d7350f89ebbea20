"""neuralao.runtime.foundation.metrics against scikit-image's structural_similarity, the reference
implementation.

Same Gaussian window (sigma 1.5, truncate 3.5 -> 11 taps), K1 = 0.01, K2 = 0.03, data range 1,
population covariance. The two differ only in the border: scikit-image pads by reflection and drops
the outer (11 - 1) / 2 = 5 pixels from its mean, neuralao.runtime.foundation.metrics replicates the edge and
keeps them. So the per-pixel maps must agree to rounding in the interior, and the whole-image means by no
more than what the border band can move.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter
from skimage.metrics import structural_similarity

from neuralao.runtime.foundation.metrics import SSIM_SIGMA, image_ssim, masked_ssim, ssim_map

PAD = 5


def _ao_pair(h, w, seed):
    """Smooth AO-like reference in [0, 1] and a noisy, biased prediction of it."""
    rng = np.random.default_rng(seed)
    ref = np.clip(gaussian_filter(rng.random((h, w)), 3.0) * 4 - 1.5, 0, 1)
    pred = np.clip(ref + rng.normal(0, 0.08, (h, w)) + 0.05, 0, 1)
    return pred, ref


def _skimage(pred, ref):
    return structural_similarity(
        pred,
        ref,
        data_range=1.0,
        gaussian_weights=True,
        sigma=SSIM_SIGMA,
        use_sample_covariance=False,
        full=True,
    )


@pytest.mark.parametrize("shape,seed", [((64, 80), 0), ((121, 97), 1), ((1080 // 8, 1920 // 8), 2)])
def test_ssim_map_equals_skimage_in_the_interior(shape, seed):
    pred, ref = _ao_pair(*shape, seed)
    mean_sk, map_sk = _skimage(pred, ref)
    ours = ssim_map(pred, ref)
    inner = (slice(PAD, -PAD), slice(PAD, -PAD))
    assert float(np.abs(ours[inner] - map_sk[inner]).max()) < 1e-9
    # skimage's mean is its interior mean: ours over the same pixels is the same number
    assert abs(float(ours[inner].mean()) - mean_sk) < 1e-9
    # whole-image means differ only through the border band (its share of pixels x the largest gap)
    band = 1.0 - ((shape[0] - 2 * PAD) * (shape[1] - 2 * PAD)) / (shape[0] * shape[1])
    assert abs(image_ssim(pred, ref) - mean_sk) <= band * 2.0


def test_masked_ssim_is_the_map_mean_over_the_mask_and_ignores_background():
    pred, ref = _ao_pair(70, 90, 3)
    mask = np.zeros_like(ref, bool)
    mask[10:60, 15:80] = True
    _, map_sk = _skimage(np.where(mask, pred, ref), ref)
    inner = np.zeros_like(mask)
    inner[PAD:-PAD, PAD:-PAD] = True
    ours = masked_ssim(pred, ref, mask)
    assert abs(ours - float(map_sk[mask & inner].mean())) < 1e-9  # the mask lies inside the interior
    junk = np.where(mask, pred, 1e3)  # any background value gives the same score
    assert masked_ssim(junk, ref, mask) == ours
