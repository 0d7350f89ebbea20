"""bench/ao_error_bands.py's edge distances, bands and oracle against closed forms on synthetic depth images
(no rendering): a square of foreground on background, split by a depth step, has its distances to the
nearest boundary pixel along the axes; a step under the jump threshold is no edge."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("ao_error_bands", ROOT / "bench" / "ao_error_bands.py")
eb = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(eb)

H, W = 80, 90
R0, R1, C0, C1 = 10, 69, 15, 84  # the square's first and last rows and columns (inclusive)
SPLIT = 50  # columns >= SPLIT lie behind a depth step


def _square(far: float) -> tuple[np.ndarray, np.ndarray]:
    depth = np.zeros((H, W), np.float32)
    depth[R0 : R1 + 1, C0 : C1 + 1] = 2.0
    depth[R0 : R1 + 1, SPLIT : C1 + 1] = 2.0 * far
    return depth, depth > 0


def _reference(step_is_edge: bool) -> np.ndarray:
    """Distance of each square pixel to the nearest boundary pixel, in closed form: the boundary is the
    square's outer ring (and the two columns beside the step), so the nearest one lies along an axis."""
    ref = np.full((H, W), np.nan)
    for i in range(R0, R1 + 1):
        for j in range(C0, C1 + 1):
            d = [i - R0, R1 - i, j - C0, C1 - j]
            if step_is_edge:
                d += [abs(j - (SPLIT - 1)), abs(j - SPLIT)]
            ref[i, j] = min(d)
    return ref


@pytest.mark.parametrize(
    ("far", "step_is_edge"), [(1.052, True), (1.048, False), (1 / 1.052, True), (1.5, True)]
)
def test_edge_distance_matches_closed_form(far, step_is_edge):
    depth, fg = _square(far)
    dist = eb.edge_distance(depth, fg, jump=0.05)
    ref = _reference(step_is_edge)
    np.testing.assert_allclose(dist[fg], ref[fg], atol=1e-9)
    # the boundary pixels: the ring, plus both columns of the step when it is an edge
    assert int((dist[fg] == 0).sum()) == 2 * (R1 - R0 + 1) + 2 * (C1 - C0 - 1) + (
        2 * (R1 - R0 - 1) if step_is_edge else 0
    )


def test_border_is_an_edge_only_when_asked():
    depth = np.full((20, 30), 3.0, np.float32)  # all foreground, one plane: no boundary at all
    fg = depth > 0
    assert np.isinf(eb.edge_distance(depth, fg)).all()
    dist = eb.edge_distance(depth, fg, border=True)
    i, j = np.mgrid[0:20, 0:30]
    np.testing.assert_allclose(dist, np.minimum.reduce([i, 19 - i, j, 29 - j]))


def test_bands_and_sums():
    dist = np.array([0.0, 1.0, np.sqrt(2), 1.999, 2.0, 7.9, 8.0, 31.99, 32.0, 100.0, np.inf])
    np.testing.assert_array_equal(eb.band_index(dist), [0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 3])
    rng = np.random.default_rng(0)
    err2 = rng.random(dist.shape)
    mask = np.ones(dist.shape, bool)
    mask[3] = False
    se, n = eb.band_sums(err2, eb.band_index(dist), mask)
    bands = eb.band_index(dist)
    for b in range(4):
        sel = (bands == b) & mask
        assert n[b] == int(sel.sum())
        assert se[b] == pytest.approx(float(err2[sel].sum()))


def test_oracle_keeps_only_the_silhouette_bands():
    rows = [
        {"category": "c", "method": "gtao", "se": [4.0, 2.0, 1.0, 1.0], "n": [10, 10, 10, 10]},
        {"category": "c", "method": "m", "se": [3.0, 1.0, 0.5, 0.0], "n": [10, 10, 10, 10]},
    ]
    fig = eb.summarise(rows, ["m", "gtao"])["c"]["m"]
    gtao = np.sqrt(8.0 / 40)
    assert fig["rmse"] == pytest.approx(np.sqrt(4.5 / 40))
    assert fig["ratio"] == pytest.approx(np.sqrt(4.5 / 40) / gtao)
    assert fig["silhouette_oracle"] == pytest.approx(np.sqrt(4.0 / 40) / gtao)
    assert fig["interior_oracle"] == pytest.approx(np.sqrt(0.5 / 40) / gtao)
    assert fig["bands"]["0-2"]["error_share"] == pytest.approx(3.0 / 4.5)
    assert fig["bands"]["2-8"]["rmse"] == pytest.approx(np.sqrt(0.1))
