"""Image metrics on foreground pixels only: masked SSIM and RMSE of AO images (numpy, float64 inside).

SSIM (Wang et al. 2004) with a **Gaussian window of 11 taps, sigma 1.5** (the window DeepAO trains
with and the one ``neuralao.pipeline.models.unet_train.ssim_map`` uses, so training loss and reported metric
agree),
``C1 = 1e-4`` and ``C2 = 9e-4`` (``(0.01 L)^2``, ``(0.03 L)^2`` with dynamic range ``L = 1``), and
replicate (``nearest``) padding at the image border.

"Masked" means two things, both needed so that background can neither help nor hurt a score:

* outside the mask the prediction is replaced by the reference before any window statistic is
  computed, so background pixels contribute identical values to both images (a wrong background
  value cannot lower the score, and a huge easy background cannot raise it: it is not averaged);
* the SSIM map is averaged over mask pixels only.

This is stricter than whole-image SSIM (as MATLAB's ``ssim`` computes it, and as the MLP paper most
likely reported): background pixels have SSIM 1 and would pull a whole-image mean towards 1.
"""

from __future__ import annotations

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError

SSIM_WINDOW = 11  # Gaussian window side in pixels (radius 5)
SSIM_SIGMA = 1.5  # Gaussian sigma in pixels
SSIM_C1 = 1e-4  # (0.01 * L)^2, L = 1
SSIM_C2 = 9e-4  # (0.03 * L)^2, L = 1


def _check(pred: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pred = np.asarray(pred, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    if pred.ndim != 2 or pred.shape != ref.shape or mask.shape != pred.shape:
        raise NeuralaoError(
            f"metrics need three (H, W) images of one size; got {pred.shape}, {ref.shape}, {mask.shape}"
        )
    if not mask.any():
        raise NeuralaoError("metrics: the mask selects no pixel")
    return pred, ref, mask


def _blur(img: np.ndarray, window: int, sigma: float) -> np.ndarray:
    """Separable normalised Gaussian of ``window`` taps, replicate padding. (H, W) float64 -> same."""
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(img, sigma=sigma, radius=window // 2, mode="nearest")


def ssim_map(
    pred: np.ndarray,
    ref: np.ndarray,
    window: int = SSIM_WINDOW,
    sigma: float = SSIM_SIGMA,
    c1: float = SSIM_C1,
    c2: float = SSIM_C2,
) -> np.ndarray:
    """Per-pixel SSIM of two (H, W) images -> (H, W) float64 (no masking)."""
    x = np.asarray(pred, dtype=np.float64)
    y = np.asarray(ref, dtype=np.float64)
    mx, my = _blur(x, window, sigma), _blur(y, window, sigma)
    vx = _blur(x * x, window, sigma) - mx * mx
    vy = _blur(y * y, window, sigma) - my * my
    cxy = _blur(x * y, window, sigma) - mx * my
    return ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))


def masked_ssim(pred: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    """Mean SSIM over mask pixels (see the module docstring).

    pred, ref : (H, W) float images (AO in [0, 1]); mask : (H, W) bool, at least one True.
    """
    pred, ref, mask = _check(pred, ref, mask)
    return float(ssim_map(np.where(mask, pred, ref), ref)[mask].mean())


def masked_rmse(pred: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    """Root mean squared difference over mask pixels. pred, ref : (H, W) float; mask : (H, W) bool."""
    pred, ref, mask = _check(pred, ref, mask)
    return float(np.sqrt(np.mean((pred[mask] - ref[mask]) ** 2)))


def image_ssim(pred: np.ndarray, ref: np.ndarray) -> float:
    """Whole-image mean SSIM (background included, as MATLAB's ``ssim``): for comparison with papers only.

    pred, ref : (H, W) float images with background = 1 in both. Background pixels score ~1, so this
    grows with the background's share of the frame; use :func:`masked_ssim` to measure a method.
    """
    pred = np.asarray(pred, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    if pred.ndim != 2 or pred.shape != ref.shape:
        raise NeuralaoError(f"image_ssim needs two (H, W) images of one size; got {pred.shape}, {ref.shape}")
    return float(ssim_map(pred, ref).mean())


def masked_flip(pred: np.ndarray, ref: np.ndarray, mask: np.ndarray, ppd: float | None = None) -> float:
    """Mean NVIDIA FLIP error (Andersson et al. 2020; the ``flip-evaluator`` package, LDR) over mask pixels.

    pred, ref : (H, W) float AO in [0, 1]; mask : (H, W) bool. FLIP compares *displayed* images in
    [0, 1], so the AO values are taken as the grey an AO buffer shows (replicated to RGB, sRGB-encoded
    as FLIP's LDR mode assumes), clipped to [0, 1], with the background set to 1 (open) in *both*
    images: like :func:`masked_ssim`, background can neither help nor hurt, and FLIP's spatial filters
    see the same surround in both. The error map (0 = identical, 1 = maximal) is averaged over the mask
    only. ``ppd``: pixels per degree of visual angle; None: FLIP's default (67.02, a 0.7 m view of a 0.7 m
    wide 3840-pixel monitor).
    """
    import flip_evaluator

    pred, ref, mask = _check(pred, ref, mask)
    as_rgb = lambda a: np.repeat(np.clip(np.where(mask, a, 1.0), 0.0, 1.0)[..., None], 3, axis=2)  # noqa: E731
    error, _, _ = flip_evaluator.evaluate(
        as_rgb(ref).astype(np.float32),
        as_rgb(pred).astype(np.float32),
        "LDR",
        applyMagma=False,
        computeMeanError=False,
        parameters={} if ppd is None else {"ppd": float(ppd)},
    )
    return float(np.asarray(error, np.float64).reshape(mask.shape)[mask].mean())
