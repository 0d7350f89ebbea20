"""Deterministic low-discrepancy numbers shared by the surface sampler and the AO labeller.

* :func:`sample_shifts`: two uniforms per sample hashed (splitmix64) from ``(seed, id)``, so a
  sample's randomisation depends only on its id, never on how samples are split across workers;
* :func:`hammersley`: the Hammersley set ``(i, radical_inverse_2(i))``.
"""

from __future__ import annotations

import numpy as np


def _splitmix64(x: np.ndarray) -> np.ndarray:
    """(n,) uint64 -> (n,) uint64 well-mixed hash (Steele et al. 2014); wraps modulo 2^64."""
    z = x + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def _to_unit(h: np.ndarray) -> np.ndarray:
    """(n,) uint64 hash -> (n,) float64 uniform in [0, 1) (top 53 bits)."""
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def sample_shifts(seed: int, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample randomisation from (seed, id): two (n,) float64 uniforms in [0, 1)."""
    seed_key = _splitmix64(np.array([int(seed) & 0xFFFFFFFFFFFFFFFF], dtype=np.uint64))[0]
    key = _splitmix64(np.asarray(ids, dtype=np.int64).astype(np.uint64) ^ seed_key)
    h1 = _splitmix64(key)
    h2 = _splitmix64(h1)
    return _to_unit(h1), _to_unit(h2)


def hammersley(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The Hammersley set: i (n,) float64 (stratum index) and radical_inverse_2(i) (n,) float64 in [0, 1)."""
    i = np.arange(n, dtype=np.uint64)
    r = i.copy()
    # 32-bit bit reversal
    r = ((r & np.uint64(0x55555555)) << np.uint64(1)) | ((r >> np.uint64(1)) & np.uint64(0x55555555))
    r = ((r & np.uint64(0x33333333)) << np.uint64(2)) | ((r >> np.uint64(2)) & np.uint64(0x33333333))
    r = ((r & np.uint64(0x0F0F0F0F)) << np.uint64(4)) | ((r >> np.uint64(4)) & np.uint64(0x0F0F0F0F))
    r = ((r & np.uint64(0x00FF00FF)) << np.uint64(8)) | ((r >> np.uint64(8)) & np.uint64(0x00FF00FF))
    r = ((r & np.uint64(0x0000FFFF)) << np.uint64(16)) | ((r >> np.uint64(16)) & np.uint64(0x0000FFFF))
    return i.astype(np.float64), r.astype(np.float64) / 2.0**32
