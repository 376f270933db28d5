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


def _ref_bias(values, available, phase, kappa3, axis):
    """The coefficients linear between the two direction nodes around the axis (the
    nearest computed node when one is missing), times kappa3 (NaN where not finite)."""
    a = values.shape[0]
    n = axis.shape[1]
    th = np.mod(np.where(np.isfinite(axis), axis, 0.0) - phase, 180.0) / ANGLE_STEP
    j0 = np.floor(th).astype(np.intp) % a
    j1 = (j0 + 1) % a
    ta = th - np.floor(th)
    idx = np.flatnonzero(available)
    d = np.abs(np.arange(a)[:, None] - idx[None, :])
    near = idx[np.argmin(np.minimum(d, a - d), axis=1)]
    both = available[j0] & available[j1]
    k0 = np.where(both, j0, near[np.where(ta < 0.5, j0, j1)])
    k1 = np.where(both, j1, k0)
    ta = np.where(both, ta, 0.0)[..., None]
    p = np.arange(n)
    q = (1 - ta) * values[k0, p] + ta * values[k1, p]
    return q * np.where(np.isfinite(kappa3), kappa3, np.nan)[..., None]


@pytest.mark.parametrize("available", AVAILABLE)
def test_skew_bias_equals_the_numpy_interpolation(available):
    from dicblur.track.uncertainty import SkewTable

    rng = np.random.default_rng(7)
    n_all, cols = 8, np.array([0, 2, 3, 4, 5, 7])
    values = rng.normal(size=(12, cols.size, 2))
    values[~available] = np.nan
    table = SkewTable(angles=2.5 + ANGLE_STEP * np.arange(12), available=available, values=values)
    k3 = rng.normal(size=(25, n_all))
    axis = rng.uniform(-10.0, 190.0, size=(25, n_all))
    axis[0, :3] = [2.5, 182.5, 17.5]  # on nodes
    k3[rng.random(k3.shape) < 0.1] = np.nan
    k3[1, 0] = np.inf
    axis[rng.random(k3.shape) < 0.1] = np.nan
    rows = np.arange(3, 25)
    out = np.full((25, n_all, 2), -1.0, np.float32)
    table.bias_into(k3, axis, rows, cols, out)
    ref = _ref_bias(values, available, 2.5, k3[:, cols], axis[:, cols])
    np.testing.assert_array_equal(out[np.ix_(rows, cols)], ref[rows].astype(np.float32))
    assert np.all(out[:3] == -1.0) and np.all(out[:, [1, 6]] == -1.0)


def _track(rng, n_f=60, n_p=7):
    t = np.arange(n_f)[:, None] / 40.0
    u = 3 * np.sin(2 * np.pi * t + rng.uniform(0, 6, n_p)) + rng.normal(0, 0.01, (n_f, n_p))
    v = 2 * np.cos(2 * np.pi * 1.3 * t + rng.uniform(0, 6, n_p)) + 0.5 * t
    u[rng.random(u.shape) < 0.03] = np.nan
    v[5, 2] = np.inf
    valid = rng.random(u.shape) > 0.03
    return u, v, valid


def _stencils(n_f, width):
    return np.array([min(max(k - width // 2, 0), n_f - width) for k in range(n_f)])


@pytest.mark.parametrize("half_window", [1, 2, 3])
def test_exposure_motion_equals_the_banded_matrix_product(half_window):
    from dicblur.track.kinematics import blur_weights, exposure_motion

    rng = np.random.default_rng(half_window)
    u, v, valid = _track(rng)
    kw = dict(fps=40.0, exposure=0.02, half_window=half_window, valid=valid)
    wu, wv = exposure_motion(u, v, **kw, threads=2, block=7)
    m = blur_weights(u.shape[0], 0.8, half_window=half_window)
    width = 2 * half_window + 1
    st = _stencils(u.shape[0], width)
    idx = st[:, None] + np.arange(width)
    for got, x in ((wu, u), (wv, v)):
        xm = np.where(valid, x, np.nan)
        both = np.isfinite(np.where(valid, u, np.nan)) & np.isfinite(np.where(valid, v, np.nan))
        complete = both[idx].all(axis=1)
        ref = np.where(complete, m @ np.where(np.isfinite(xm), xm, 0.0), np.nan)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    # float32 outputs: the float64 values rounded
    w32 = exposure_motion(u, v, **kw, dtype=np.float32)
    np.testing.assert_array_equal(w32[0], wu.astype(np.float32))


def _ref_moments(wts, um, vm):
    """Positions at the Gauss nodes, centred; principal axis; third moment along it."""
    from dicblur.track.kinematics import _WEIGHTS

    xs = np.einsum("fgk,fkn->fgn", wts, um)
    ys = np.einsum("fgk,fkn->fgn", wts, vm)
    gw = 0.5 * _WEIGHTS
    xs -= np.einsum("g,fgn->fn", gw, xs)[:, None]
    ys -= np.einsum("g,fgn->fn", gw, ys)[:, None]
    cxx, cyy, cxy = (np.einsum("g,fgn->fn", gw, a * b) for a, b in ((xs, xs), (ys, ys), (xs, ys)))
    th = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
    s = xs * np.cos(th)[:, None] + ys * np.sin(th)[:, None]
    return np.einsum("g,fgn->fn", gw, s**3), np.mod(np.degrees(th), 180.0)


def test_exposure_skew_equals_the_numpy_moments():
    from dicblur.track.kinematics import _node_weights, exposure_skew

    rng = np.random.default_rng(11)
    u, v, valid = _track(rng, n_f=50, n_p=300)  # more points than one block of the kernel
    k3, axis = exposure_skew(u, v, fps=40.0, exposure=0.02, valid=valid, threads=2, block=9)
    starts, wts = _node_weights(u.shape[0], 0.8, 2)
    idx = starts[:, None] + np.arange(wts.shape[2])
    um, vm = np.where(valid, u, np.nan)[idx], np.where(valid, v, np.nan)[idx]  # (F, 5, n)
    with np.errstate(invalid="ignore"):  # inf - inf in a stencil: NaN, as the kernel's
        ref_k3, ref_axis = _ref_moments(wts, um, vm)
    missing = ~np.isfinite(ref_k3)
    assert missing.any() and (~missing).any()
    np.testing.assert_array_equal(np.isnan(k3), missing)
    np.testing.assert_array_equal(np.isnan(axis), missing)
    # the sums in another order: the float32 values agree to their last digit or so
    scale = np.nanmax(np.abs(ref_k3))
    np.testing.assert_allclose(k3, ref_k3, rtol=1e-6, atol=1e-6 * scale)
    d = np.abs(axis - ref_axis)
    np.testing.assert_array_less(np.nan_to_num(np.minimum(d, 180 - d)), 1e-4)


def _ref_direction_nodes(blur, angle, min_blur, tolerance):
    """Nodes every ANGLE_STEP with one on the blur-weighted dominant direction of the
    samples with blur >= min_blur (all finite ones when none is); the nearest node of each
    such direction when the blur across it is <= tolerance, else the two around it."""
    a = round(180.0 / ANGLE_STEP)
    w, t = np.ravel(blur).astype(float), np.ravel(angle).astype(float)
    fin = np.isfinite(w) & np.isfinite(t)
    big = fin & (w >= min_blur)
    use = big if big.any() else fin
    r2 = np.deg2rad(2.0 * t[use])
    c, s = np.sum((w[use] + 1e-12) * np.cos(r2)), np.sum((w[use] + 1e-12) * np.sin(r2))
    dom = (np.degrees(np.arctan2(s, c)) / 2.0) % 180.0 if (c or s) else 0.0
    phase = dom % ANGLE_STEP
    angles = phase + np.arange(a) * ANGLE_STEP
    need = np.zeros(a, bool)
    if not big.any():
        need[round((dom - phase) / ANGLE_STEP) % a] = True
        return angles, need
    th = np.mod(t[big] - phase, 180.0) / ANGLE_STEP
    near = np.rint(th)
    one = w[big] * np.abs(np.sin(np.deg2rad((th - near) * ANGLE_STEP))) <= tolerance
    need[near[one].astype(int) % a] = True
    lo = np.floor(th[~one]).astype(int) % a
    need[lo] = True
    need[(lo + 1) % a] = True
    return angles, need


@pytest.mark.parametrize("case", ["spread", "one axis", "none big", "empty"])
def test_direction_nodes_equal_the_numpy_selection(case):
    from dicblur.track.uncertainty import direction_nodes

    rng = np.random.default_rng(13)
    w = rng.uniform(0.0, 4.0, (70, 40)).astype(np.float32)
    t = rng.uniform(-30.0, 200.0, (70, 40)).astype(np.float32)
    if case == "one axis":  # a 1-d motion: within the tolerance of one node
        t = np.full(t.shape, 21.3, np.float32) + rng.normal(0, 1e-4, t.shape).astype(np.float32)
    if case == "none big":
        w *= 0.1
    if case == "empty":
        w[:] = np.nan
    w[rng.random(w.shape) < 0.05] = np.nan
    t[rng.random(w.shape) < 0.05] = np.nan
    for threads in (1, 2):
        got = direction_nodes(w, t, min_blur=0.5, threads=threads)
        ref = _ref_direction_nodes(w, t, 0.5, 0.05)
        # the sums in another order: the dominant direction to rounding
        np.testing.assert_allclose(got[0], ref[0], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(got[1], ref[1])
