"""Unit normals from any (n, 3) input, scale-safe and total: the labeller's and the volume probe's."""

from __future__ import annotations

import numpy as np


def normalize_normals(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) any finite/non-finite normals -> (unit (n, 3) float64, ok (n,) bool).

    Scale-safe (divides by the largest component first, so 1e-300 or 1e300 lengths work);
    zero or non-finite normals become +z with ok = False.
    """
    normals = np.asarray(normals, dtype=np.float64)
    big = np.abs(normals).max(axis=1) if len(normals) else np.zeros(0)
    ok = np.isfinite(normals).all(axis=1) & (big > 0)
    safe = np.where(ok[:, None], normals / np.where(ok, big, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
    # Explicit sum (not np.linalg.norm): elementwise, so bits never depend on the batch shape.
    length = np.sqrt(safe[:, 0] * safe[:, 0] + safe[:, 1] * safe[:, 1] + safe[:, 2] * safe[:, 2])
    return safe / length[:, None], ok
