"""The compiled post-processing of ``dicblur.track`` against plain-numpy references.

Each reference below is the numpy formula the kernel replaced, written out here on its own
(the kernels are the package's one home of these formulas); random data with NaN, missing
table nodes and values on and beyond the node edges. Where the kernel performs the same
floating-point operations in the same order the results are compared bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from dicblur.track.uncertainty import ANGLE_STEP, BlurTable

# ------------------------------------------------------------------- numpy references


def _ref_lookup(table: BlurTable, w: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Linear in W**2 between the W nodes, linear between the two direction nodes around
    the angle when both were computed, else the computed node nearest the nearer one."""
    n = w.shape[1]
    a = table.angles.size
    wq = np.where(np.isfinite(w), w, 0.0)
    s2 = wq**2
    b2 = table.blur**2
    i1 = np.clip(np.searchsorted(b2, s2, side="right"), 1, b2.size - 1)
    i0 = i1 - 1
    tw = np.clip((s2 - b2[i0]) / (b2[i1] - b2[i0]), 0.0, 1.0)[..., None]
    th = np.mod(np.where(np.isfinite(angle), angle, 0.0) - table.angles[0], 180.0) / ANGLE_STEP
    j0 = np.floor(th).astype(np.intp) % a
    j1 = (j0 + 1) % a
    ta = th - np.floor(th)
    idx = np.flatnonzero(table.available)
    d = np.abs(np.arange(a)[:, None] - idx[None, :])
    near = idx[np.argmin(np.minimum(d, a - d), axis=1)]
    both = table.available[j0] & table.available[j1]
    k0 = np.where(both, j0, near[np.where(ta < 0.5, j0, j1)])
    k1 = np.where(both, j1, k0)
    ta = np.where(both, ta, 0.0)[..., None]
    p = np.arange(n)

    def at(j: np.ndarray) -> np.ndarray:
        lo = table.values[j, i0, p]
        hi = table.values[j, i1, p]
        return (hi - lo) * tw + lo

    out = at(k0)
    out = np.where(both[..., None], out + ta * (at(k1) - out), out)
    out[~np.isfinite(w) | (w > table.blur[-1] + 1e-9)] = np.nan
    return out


def _random_table(rng: np.random.Generator, n: int, available: np.ndarray) -> BlurTable:
    a = available.size
    blur = np.arange(0.0, 5.0)
    values = rng.normal(size=(a, blur.size, n, 6))
    values[..., 2:] = np.abs(values[..., 2:])
    values[~available] = np.nan
    values[:, :, 0] = np.nan  # a point without gradient
    values[:, 1:, 1, :2] = np.nan  # one that breaks down beyond W = 0
    return BlurTable(
        blur=blur, angles=3.7 + ANGLE_STEP * np.arange(a), available=available, values=values
    )


def _random_samples(rng, frames, n, dtype):
    w = rng.uniform(0.0, 4.6, size=(frames, n)).astype(dtype)
    ang = rng.uniform(-200.0, 400.0, size=(frames, n)).astype(dtype)
    w[0, :4] = [0.0, 1.0, 4.0, 4.0 + 5e-10]  # on nodes, at the last, just beyond it
    ang[1, :4] = [3.7, 3.7 + 180.0, 18.7, -176.3]  # on direction nodes
    w[rng.random(w.shape) < 0.05] = np.nan
    ang[rng.random(w.shape) < 0.05] = np.nan
    return w, ang


AVAILABLE = [
    np.ones(12, bool),
    np.isin(np.arange(12), [0, 1, 5]),  # gaps: nearest computed node
    np.isin(np.arange(12), [7]),  # a single direction (1-d motion)
]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("available", AVAILABLE)
def test_lookup_equals_the_numpy_interpolation(dtype, available):
    rng = np.random.default_rng(3)
    table = _random_table(rng, 9, available)
    w, ang = _random_samples(rng, 40, 9, dtype)
    got = table.lookup(w, ang)
    ref = _ref_lookup(table, w, ang)
    assert got.dtype == np.float64 and got.shape == (40, 9, 6)
    np.testing.assert_array_equal(got, ref)  # bit for bit, NaN where NaN


@pytest.mark.parametrize("available", AVAILABLE)
def test_predict_into_equals_the_numpy_sigma_parts(available):
    rng = np.random.default_rng(5)
    n_all = 11
    cols = np.array([0, 1, 2, 4, 5, 6, 7, 8, 10])  # the table's points among all
    table = _random_table(rng, cols.size, available)
    w, ang = _random_samples(rng, 30, n_all, np.float32)
    var = rng.uniform(0.5, 30.0, cols.size)
    rows = np.array([0, 1, 3, 4, 9, 20, 29])
    out = tuple(np.full((30, n_all), -1.0, np.float32) for _ in range(4))
    table.predict_into(w, ang, var, rows, cols, out)
    look = _ref_lookup(table, w[:, cols], ang[:, cols])
    ref = (
        np.sqrt(var * look[..., 2] + var * var * look[..., 4]),
        np.sqrt(var * look[..., 3] + var * var * look[..., 5]),
        np.abs(look[..., 0]),
        np.abs(look[..., 1]),
    )
    for o, r in zip(out, ref, strict=True):
        np.testing.assert_array_equal(o[np.ix_(rows, cols)], r[rows].astype(np.float32))
        untouched = np.ones(o.shape, bool)
        untouched[np.ix_(rows, cols)] = False
        assert np.all(o[untouched] == -1.0)
