"""The affine predicted-imprecise subsets started from their precise neighbours' field
(issue 26: one pass after the precise POIs instead of a reduced pass and a retry)."""

from __future__ import annotations

import numpy as np
import pytest

from dicblur import Correlator, PointStatus
from dicblur.dic.screening import grow_start
from helpers.dic import blobs, fourier_shift, hard_dots

TRUE_U, TRUE_V = 0.3, -0.2


def test_grow_start_fills_a_region_inwards_and_counts_the_steps():
    ny, nx, k = 7, 7, 2
    grid = np.full((k, ny, nx), 1.5)
    grid[1] = -0.25
    hole = [(r, c) for r in range(2, 5) for c in range(2, 5)]
    for r, c in hole:
        grid[:, r, c] = np.nan
    cells = np.array([r * nx + c for r, c in hole])
    start = np.full((cells.size, k), np.nan)
    rounds = grow_start(grid, cells, start)
    np.testing.assert_allclose(start, np.tile([1.5, -0.25], (cells.size, 1)))
    # the ring next to the known field first, the centre one step later
    want = np.ones(cells.size, int)
    want[hole.index((3, 3))] = 2
    np.testing.assert_array_equal(rounds, want)
    # nothing known: nothing filled
    empty = np.full((cells.size, k), np.nan)
    rounds = grow_start(np.full((k, ny, nx), np.nan), cells, empty)
    assert np.all(rounds == -1) and np.all(np.isnan(empty))


def _pair(name):
    shape = (512, 512)
    if name == "blobs":
        img = blobs(shape)
        ref, cur = img, fourier_shift(img, TRUE_V, TRUE_U)
    else:
        ref, cur = hard_dots(shape), hard_dots(shape, (TRUE_V, TRUE_U))
    rng = np.random.default_rng([2024, 99])
    return ref + rng.normal(0, 2, shape), cur + rng.normal(0, 2, shape)


@pytest.mark.parametrize("name", ["blobs", "dots"])
def test_hard_images_default_affine_no_gross_error_few_correct_flagged(name):
    # before (a reduced pass from the seed start, then the check's retry): one gross error
    # left CONVERGED on each image, 1.9 % (blobs) and 1.8 % (dots) of the correct interior
    # points flagged, 3.3 and 3.2 IC-GN iterations per POI
    ref, cur = _pair(name)
    corr = Correlator(ref, subset=21, step=10, shape="affine")
    res = corr.correlate(cur)
    err = np.hypot(res.u - TRUE_U, res.v - TRUE_V)
    inner = (corr.rows >= 15) & (corr.rows < 497) & (corr.cols >= 15) & (corr.cols < 497)
    conv = res.status == PointStatus.CONVERGED
    assert not np.any(inner & conv & (err > 0.1))
    with np.errstate(invalid="ignore"):
        flagged_ok = inner & ~conv & (err <= 0.1)
    assert flagged_ok.sum() <= 0.016 * inner.sum()
    assert res.iterations.mean() < 3.13
    # every predicted-imprecise POI flagged keeps an estimate to inspect
    imp = res.status == PointStatus.IMPRECISE
    assert imp.any() and np.all(np.isfinite(res.u[imp]))
