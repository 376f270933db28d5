"""A plane-fit window no point of the grid can hold is a bad argument, not a field of
reduced windows (dicblur.strain.field.check_window_fits)."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur.dic import DICResult
from dicblur.errors import InputError
from dicblur.strain import StrainStatus


def _result(ny: int, nx: int, step: int = 10, subset: int = 21) -> DICResult:
    r, c = np.meshgrid(np.arange(ny) * step + 30, np.arange(nx) * step + 30, indexing="ij")
    r, c = r.ravel(), c.ravel()
    k = r.size
    return DICResult(
        rows=r,
        cols=c,
        u=2e-3 * c.astype(float),
        v=np.zeros(k),
        params=np.zeros((k, 2)),
        zncc=np.ones(k),
        iterations=np.ones(k, int),
        status=np.zeros(k, np.uint8),
        info={"subset": subset, "step": step},
    )


def test_window_larger_than_the_grid_is_refused_with_the_largest_that_fits():
    # before: every point silently took a 3 x 3 window (REDUCED_WINDOW)
    with pytest.raises(InputError, match=r"window=11: larger than the POI grid \(7 x 9 points\)"):
        dicblur.strain(_result(7, 9), window=11)
    with pytest.raises(InputError, match=r"use window <= 7 \(VSG 81 px\)"):
        dicblur.strain(_result(8, 9), window=9)


def test_a_grid_narrower_than_three_points_is_refused():
    # before: every point NO_WINDOW, every strain NaN
    with pytest.raises(InputError, match="at least 3 x 3 points"):
        dicblur.strain(_result(1, 12), window=3)


def test_the_largest_window_that_fits_still_gives_its_full_window():
    s = dicblur.strain(_result(7, 9), window=7, kind="small")
    ok = s.status == StrainStatus.OK
    assert ok.sum() == 3  # the centre row's three points with a complete 7 x 7 window
    assert np.allclose(s.exx[ok], 2e-3)


def test_the_subsets_own_gradients_need_no_window():
    res = _result(1, 5)
    res = DICResult(**{**res.__dict__, "params": np.zeros((5, 6))})
    s = dicblur.strain(res, window=21, method="subset")
    assert np.all(s.status == StrainStatus.OK)
