"""Real spherical harmonics up to band 2 (quadratic SH), projection and the clamped-cosine convolution.

Basis order (9 functions, Sloan's "Stupid SH tricks" convention), for a unit direction (x, y, z):

    0: Y00  = 1/2 sqrt(1/pi)                      band 0
    1: Y1-1 = sqrt(3/(4 pi)) y                    band 1
    2: Y10  = sqrt(3/(4 pi)) z
    3: Y11  = sqrt(3/(4 pi)) x
    4: Y2-2 = 1/2 sqrt(15/pi) x y                 band 2
    5: Y2-1 = 1/2 sqrt(15/pi) y z
    6: Y20  = 1/4 sqrt(5/pi) (3 z^2 - 1)
    7: Y21  = 1/2 sqrt(15/pi) x z
    8: Y22  = 1/4 sqrt(15/pi) (x^2 - y^2)

The basis is orthonormal over the sphere, so for two functions with coefficients a, b the integral
of (f_a - f_b)^2 over all directions is ``sum (a - b)^2``: a least-squares fit in coefficient space is
a least-squares fit of the function over every normal.

AO for a normal n from a spherical visibility V (Sloan et al. 2013 eq. 1 with the kernel folded in):
``AO(n) = 1/pi * integral V(w) max(0, n.w) dw``. The clamped cosine is zonal, so by Funk-Hecke the
integral is a per-band scale of V's coefficients: A0 = pi, A1 = 2 pi / 3, A2 = pi / 4 (A3 = 0 and every
odd band above 1 vanishes). :func:`convolve_clamped_cosine` applies A_l / pi, after which
``AO(n) = evaluate(coefficients, n)`` (a dot product with the basis).
"""

from __future__ import annotations

import math

import numpy as np

from neuralao.runtime.foundation.errors import NeuralaoError

LINEAR = 4  # coefficients of bands 0-1
QUADRATIC = 9  # coefficients of bands 0-2
_BAND_OF = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2])
# Clamped cosine max(0, cos) in zonal SH, per band: A_l (Ramamoorthi & Hanrahan 2001).
CLAMPED_COSINE = np.array([math.pi, 2.0 * math.pi / 3.0, math.pi / 4.0])

_C0 = 0.5 * math.sqrt(1.0 / math.pi)
_C1 = math.sqrt(3.0 / (4.0 * math.pi))
_C2 = 0.5 * math.sqrt(15.0 / math.pi)
_C20 = 0.25 * math.sqrt(5.0 / math.pi)
_C22 = 0.25 * math.sqrt(15.0 / math.pi)
# Y_j(n) = NORMALISATION[j] * polynomial_j(n), polynomials (1, y, z, x, xy, yz, 3z^2 - 1, xz, x^2 - y^2).
NORMALISATION = np.array([_C0, _C1, _C1, _C1, _C2, _C2, _C20, _C2, _C22])


def basis(directions: np.ndarray, count: int = QUADRATIC) -> np.ndarray:
    """SH basis values (..., count) float64 of unit directions (..., 3); count 1, 4 or 9."""
    if count not in (1, LINEAR, QUADRATIC):
        raise NeuralaoError(f"SH coefficient count must be 1, 4 or 9, got {count}")
    d = np.asarray(directions, dtype=np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    out = np.empty((*d.shape[:-1], count))
    out[..., 0] = _C0
    if count > 1:
        np.multiply(_C1, y, out=out[..., 1])
        np.multiply(_C1, z, out=out[..., 2])
        np.multiply(_C1, x, out=out[..., 3])
    if count > LINEAR:
        np.multiply(_C2 * x, y, out=out[..., 4])
        np.multiply(_C2 * y, z, out=out[..., 5])
        np.multiply(_C20, 3.0 * z * z - 1.0, out=out[..., 6])
        np.multiply(_C2 * x, z, out=out[..., 7])
        np.multiply(_C22, x * x - y * y, out=out[..., 8])
    return out


def project_uniform(values: np.ndarray, directions: np.ndarray, count: int = QUADRATIC) -> np.ndarray:
    """Monte-Carlo projection of spherical functions sampled at uniformly distributed directions.

    values     : (n, k) or (n, k, c) samples of n functions (c channels each) at k directions
    directions : (n, k, 3) unit directions, each marginally uniform on the sphere
    Returns (n, count) or (n, c, count) float64: ``4 pi / k * sum_i values_i Y(w_i)``.
    """
    y = basis(directions, count)  # (n, k, count)
    v = np.asarray(values, dtype=np.float64)
    scale = 4.0 * math.pi / directions.shape[1]
    # batched matrix products (BLAS), ~10x faster than the equivalent einsum here
    if v.ndim == 2:
        return scale * np.matmul(v[:, None, :], y)[:, 0, :]
    return scale * np.matmul(v.transpose(0, 2, 1), y)


def convolve_clamped_cosine(coefficients: np.ndarray) -> np.ndarray:
    """Coefficients (..., count) of V -> coefficients of AO(n) = 1/pi integral V max(0, n.w) dw."""
    c = np.asarray(coefficients, dtype=np.float64)
    count = c.shape[-1]
    return c * (CLAMPED_COSINE[_BAND_OF[:count]] / math.pi)


def evaluate(coefficients: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """sum_j coefficients[..., j] Y_j(n): coefficients (..., count), normals (..., 3) unit -> (...,)."""
    c = np.asarray(coefficients, dtype=np.float64)
    return np.einsum("...j,...j->...", c, basis(normals, c.shape[-1]))


def sphere_directions(count: int, shift_z: np.ndarray, shift_phi: np.ndarray) -> np.ndarray:
    """Jittered spherical Fibonacci directions, one randomised set per point: (n, count, 3) float64.

    Direction i of point p: ``z = 1 - 2 (i + shift_z[p]) / count`` (every z stratum jittered by the
    same amount) and ``phi = 2 pi (i / golden + shift_phi[p])``. With shifts uniform in [0, 1) each
    direction is marginally uniform on the sphere (the projection is unbiased) and the set keeps the
    Fibonacci stratification (low error); shifts come from the seeded per-point hash of the labeller.
    """
    i = np.arange(count, dtype=np.float64)
    sz = np.asarray(shift_z, dtype=np.float64)[:, None]
    sp = np.asarray(shift_phi, dtype=np.float64)[:, None]
    z = 1.0 - 2.0 * (i[None, :] + sz) / count
    z = np.clip(z, -1.0, 1.0)
    golden = (1.0 + math.sqrt(5.0)) / 2.0
    a = 2.0 * math.pi * np.mod(i / golden, 1.0)[None, :]  # shared azimuths
    b = 2.0 * math.pi * sp  # per-point rotation: cos / sin of a + b by the angle-sum rule
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    out = np.empty((len(sz), count, 3))
    np.multiply(r, ca * cb - sa * sb, out=out[..., 0])
    np.multiply(r, sa * cb + ca * sb, out=out[..., 1])
    out[..., 2] = z
    return out
