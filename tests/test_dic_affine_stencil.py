"""The affine IC-GN's 4x4 stencil path against its 5x5 path (the same sums)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from dicblur.dic.kernels import affine


def _sums(kernel, p, *, fast=None):
    rng = np.random.default_rng(5)
    coef = rng.normal(100.0, 30.0, (64, 80)).astype(np.float32)
    f, gx, gy = (rng.normal(0.0, 20.0, (48, 48)).astype(np.float32) for _ in range(3))
    half, tw = 10, 24
    dxs = (np.arange(tw) - half).astype(np.float32)
    mask = np.zeros(tw, np.float32)
    mask[: 2 * half + 1] = 1.0
    cx = [p[0] + p[1] * x + p[2] * y for x in (-half, half) for y in (-half, half)]
    cy = [p[3] + p[4] * x + p[5] * y for x in (-half, half) for y in (-half, half)]
    bx, by = math.floor(min(cx)), math.floor(min(cy))
    q = np.zeros(6)
    args = (bx, by, half, 12, 12, dxs, np.float32(97.0), mask, f, gx, gy, q)
    if fast is None:
        s = kernel(coef, np.asarray(p, float), *args)
    else:
        s = kernel(coef, np.asarray(p, float), fast, *args)
    return np.array([*s, *q]), max(cx) - bx, max(cy) - by


@pytest.mark.parametrize(
    "p",
    [
        (0.3, 1e-3, -5e-4, -0.2, 2e-4, 1e-3),
        (-1.7, -2e-3, 1e-3, 2.45, 1e-3, -2e-3),
        (0.02, 0.0, 0.0, 0.97, 0.0, 0.0),
    ],
)
def test_four_tap_path_equals_five_tap_path(p):
    four, spanx, spany = _sums(affine._subset_affine_cubic4, p)
    assert spanx < affine.CELL and spany < affine.CELL  # the case the 4x4 path is for
    five, _, _ = _sums(affine._subset_affine_cubic, p, fast=True)
    # float32 row sums in another order: equal to float32 rounding, not to the bit
    assert_allclose(four, five, rtol=2e-6, atol=1e-6 * np.abs(five).max())
