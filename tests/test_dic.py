"""Subset DIC engine: known answers, statistics, statuses and bad inputs (issue 4)."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from numpy.testing import assert_allclose

import dicblur
from dicblur import Correlator, DICResult, InputError, PointStatus, correlate
from dicblur.dic.cache import kernels_cached
from dicblur.dic.initial import global_shift, subset_fftcc
from helpers.dic import affine_warp, fourier_shift, pattern


@pytest.fixture(scope="module")
def ref128():
    return pattern(128, seed=1)


@pytest.mark.parametrize("shape", ["translation", "affine"])
def test_forks_correlate_on_threads_as_fresh_correlators(ref128, shape):
    # Correlator.fork shares the prepared reference: forks correlating at the same time
    # on several threads (unprepared images: each writes its own coefficient buffer) give
    # the results of a Correlator built anew, bit for bit
    from concurrent.futures import ThreadPoolExecutor

    kw = {"subset": 21, "step": 8, "shape": shape, "noise_sigma": 2.0}
    base = Correlator(ref128, workers=2, **kw)
    fresh = Correlator(ref128, workers=1, **kw)
    rng = np.random.default_rng(3)
    cur = [
        fourier_shift(ref128, 0.3 * k, -0.2 * k) + rng.normal(0, 2, ref128.shape) for k in range(6)
    ]
    want = [fresh.correlate(c) for c in cur]
    forks = [base.fork(workers=1) for _ in range(3)]
    assert forks[0].workers == 1 and base.workers == 2 and base.fork().workers == 2
    assert forks[0]._f32 is base._f32 and forks[0]._coef_buf is not base._coef_buf

    def run(j):  # one fork per thread, each through all images from a different one
        order = np.roll(np.arange(len(cur)), j)
        return order, [forks[j].correlate(cur[i]) for i in order]

    with ThreadPoolExecutor(3) as pool:
        got = list(pool.map(run, range(3)))
    for order, res in got:
        for i, r in zip(order, res, strict=True):
            for name in ("u", "v", "zncc", "params", "iterations", "status"):
                np.testing.assert_array_equal(getattr(r, name), getattr(want[i], name), name)
    np.testing.assert_array_equal(base.correlate(cur[1]).u, want[1].u)


@pytest.mark.parametrize("shape", ["translation", "affine"])
@pytest.mark.parametrize("screen", [False, True])
def test_refine_equals_correlate_from_the_same_start(ref128, shape, screen):
    # Correlator.refine: the numbers of correlate(prepared, initial=start) without the
    # DICResult, the statuses screened the same way (residual, median test, imprecise)
    kw: dict = {"subset": 21, "step": 8, "shape": shape}
    if screen:
        c0 = Correlator(ref128, noise_sigma=2.0, **kw)
        sig = np.hypot(c0.predicted_sigma_u, c0.predicted_sigma_v)
        # about half the points predicted imprecise
        kw.update(noise_sigma=2.0, max_residual=3.0, median_test=True)
        kw.update(max_predicted_sigma=float(np.nanmedian(sig)))
    corr = Correlator(ref128, **kw)
    rng = np.random.default_rng(5)
    cur = fourier_shift(ref128, 1.3, -0.6) + rng.normal(0, 2, ref128.shape)
    img = corr.prefilter(cur)
    n = corr.n_points
    first = corr.correlate(img)
    starts = [np.nan_to_num(np.stack([first.u, first.v], axis=1)) + rng.normal(0, 0.2, (n, 2))]
    if shape == "affine":
        full = np.zeros((n, 6))
        full[:, 0], full[:, 3] = starts[0][:, 0], starts[0][:, 1]
        full[:, [1, 2, 4, 5]] = rng.normal(0, 1e-3, (n, 4))
        starts.append(full)
    for start in starts:
        want = corr.correlate(img, initial=start)
        got = corr.refine(img, start)
        np.testing.assert_array_equal(got.params, want.params)
        np.testing.assert_array_equal(got.zncc, want.zncc)
        np.testing.assert_array_equal(got.iterations, want.iterations)
        np.testing.assert_array_equal(got.status, want.status)
    if screen:
        assert (got.status == PointStatus.IMPRECISE).any()
    bad = starts[0].copy()
    bad[3, 0] = np.nan
    with pytest.raises(InputError, match="start"):
        corr.refine(img, bad)
    with pytest.raises(InputError, match="start"):
        corr.refine(img, starts[0][:-1])
    with pytest.raises(InputError, match="PreparedImage"):
        corr.refine(cur, starts[0])  # type: ignore[arg-type]
    with pytest.raises(InputError, match="blur"):
        Correlator(ref128, subset=21, step=16, blur="given").refine(img, starts[0][:1])


@pytest.mark.parametrize("shape", ["translation", "affine"])
def test_integer_translation(ref128, shape):
    cur = np.roll(ref128, (-2, 3), axis=(0, 1))  # content moves +3 px in x, -2 px in y
    res = correlate(ref128, cur, subset=21, step=15, shape=shape)
    inside = (res.rows - 10 - 2 >= 0) & (res.cols + 10 + 3 <= 127)
    assert res.converged[inside].all()
    assert (res.status[~inside] == PointStatus.OUT_OF_BOUNDS).all()
    assert_allclose(res.u[inside], 3.0, atol=1e-3)
    assert_allclose(res.v[inside], -2.0, atol=1e-3)


@pytest.mark.parametrize("shape", ["translation", "affine"])
@pytest.mark.parametrize("interp", ["bspline3", "bspline5"])
def test_subpixel_translation(ref128, shape, interp):
    cur = fourier_shift(ref128, -0.2, 0.3)
    # keep subsets 6 px off the border: the mirror boundary of the spline prefilter is not
    # the periodic continuation of a Fourier-shifted image (edge error ~0.01 px)
    res = correlate(
        ref128, cur, subset=21, step=15, shape=shape, interpolation=interp, roi=(6, 122, 6, 122)
    )
    assert res.converged.all()
    assert_allclose(res.u, 0.3, atol=0.01)
    assert_allclose(res.v, -0.2, atol=0.01)
    s = res.summary(true_u=0.3, true_v=-0.2)
    assert abs(s["bias_u"]) < 0.003 and abs(s["bias_v"]) < 0.003


def test_affine_strain_and_rotation():
    ref = pattern(160, seed=2)
    th = np.deg2rad(0.5)
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    a = rot @ np.diag([1.01, 1.01])
    cur = affine_warp(ref, a)
    res = correlate(ref, cur, subset=25, step=20, shape="affine", roi=(20, 140, 20, 140))
    assert res.converged.all()
    c = (160 - 1) / 2
    du = (a[0, 0] - 1) * (res.cols - c) + a[0, 1] * (res.rows - c)
    dv = a[1, 0] * (res.cols - c) + (a[1, 1] - 1) * (res.rows - c)
    assert_allclose(res.u, du, atol=0.02)
    assert_allclose(res.v, dv, atol=0.02)
    grads = np.median(res.params[:, [1, 2, 4, 5]], axis=0)
    assert_allclose(grads, [a[0, 0] - 1, a[0, 1], a[1, 0], a[1, 1] - 1], atol=1e-3)
    # the translation shape cannot follow the rotation as well: larger residual
    res_t = correlate(ref, cur, subset=25, step=20, shape="translation", roi=(20, 140, 20, 140))
    assert np.std(res_t.u - du) > np.std(res.u - du)


def test_large_rigid_shift_via_global_fftcc():
    ref = pattern(160, seed=5)
    cur = fourier_shift(ref, -7.6, 23.4)
    u, v, peak = global_shift(ref, cur)
    assert (u, v) == (23, -8) and peak > 0.3
    res = correlate(ref, cur, subset=21, step=20, shape="translation")
    ok = res.converged
    inside = (res.cols + 24 + 10 < 160) & (res.rows - 8 - 10 >= 0)
    assert ok[inside].all()
    assert_allclose(res.u[ok], 23.4, atol=0.01)
    assert_allclose(res.v[ok], -7.6, atol=0.01)


def test_subset_fftcc_finds_half_subset_and_more(ref128):
    # per-POI different integer shifts (two halves moving in opposite directions)
    cur = np.roll(ref128, 11, axis=1)
    rows = np.array([40, 64, 90])
    cols = np.array([40, 64, 90])
    u, v, z = subset_fftcc(ref128, cur, rows, cols, 10)
    assert_allclose(u, 11) and assert_allclose(v, 0)
    assert np.all(z > 0.99)
    u2, v2, _ = subset_fftcc(
        ref128,
        np.roll(ref128, (-12, 0), axis=(0, 1)),
        rows,
        cols,
        10,
        guess_u=np.zeros(3),
        guess_v=np.full(3, -3.0),
    )
    assert_allclose(v2, -12) and assert_allclose(u2, 0)
    res = correlate(ref128, cur, subset=21, step=20, shape="translation", initial="subset")
    assert_allclose(res.u[res.converged], 11.0, atol=1e-3)
    assert res.converged.mean() > 0.5


@pytest.mark.parametrize("shape", ["translation", "affine"])
def test_normalised_random_error_is_one(shape):
    # seeded Monte Carlo: noise sigma = 2 GL in both images; the per-point predicted sigma
    # (match score or Fisher bound) must explain the scatter within 10 %
    ref = pattern(256, seed=11)
    rng = np.random.default_rng(12)
    cur = fourier_shift(ref, -0.2, 0.3) + rng.normal(0, 2.0, ref.shape)
    ref_n = ref + rng.normal(0, 2.0, ref.shape)
    res = correlate(ref_n, cur, subset=21, step=10, shape=shape, noise_sigma=2.0)
    s = res.summary(true_u=0.3, true_v=-0.2)
    assert s["converged_fraction"] == 1.0
    assert 0.9 <= s["normalised_std_u"] <= 1.1
    assert 0.9 <= s["normalised_std_v"] <= 1.1
    if shape == "affine":  # four more parameters: the bound is larger than eq. 2
        res_t = correlate(ref_n, cur, subset=21, step=10, shape="translation", noise_sigma=2.0)
        assert np.all(res.predicted_sigma_u > res_t.predicted_sigma_u)


def test_predicted_sigma_is_match_score(ref128):
    pts = np.array([[30, 30], [64, 70], [100, 90]])
    corr = Correlator(ref128, points=pts, subset=21, shape="translation", noise_sigma=2.0)
    sx = dicblur.sssig(ref128, subset=21, points=pts, direction="x")
    sy = dicblur.sssig(ref128, subset=21, points=pts, direction="y")
    assert_allclose(corr.predicted_sigma_u, dicblur.match_score_sigma(sx, 2.0), rtol=1e-9)
    assert_allclose(corr.predicted_sigma_v, dicblur.match_score_sigma(sy, 2.0), rtol=1e-9)


def test_statuses_low_texture_and_out_of_bounds(ref128):
    ref = ref128.copy()
    ref[:, :50] = 120.0  # textureless band
    pts = np.array([[64, 20], [64, 90], [5, 90], [64, 125]])
    corr = Correlator(ref, points=pts, subset=21, shape="affine", noise_sigma=1.0)
    res = corr.correlate(np.roll(ref, 1, axis=1))
    assert res.status.tolist() == [
        PointStatus.LOW_TEXTURE,
        PointStatus.CONVERGED,
        PointStatus.OUT_OF_BOUNDS,
        PointStatus.OUT_OF_BOUNDS,
    ]
    assert np.isnan(res.u[[0, 2, 3]]).all() and np.isfinite(res.u[1])
    assert np.isnan(res.predicted_sigma_u[[0, 2, 3]]).all()
    # a displacement that carries the subset out of the current image
    res2 = Correlator(ref128, points=[[64, 100]], subset=21, shape="translation").correlate(
        ref128, initial=[30.0, 0.0]
    )
    assert res2.status[0] == PointStatus.OUT_OF_BOUNDS


def test_pure_noise_current_is_not_converged(ref128):
    noise = np.random.default_rng(3).normal(128, 40, ref128.shape)
    for shape in ("translation", "affine"):
        res = correlate(ref128, noise, subset=21, step=20, shape=shape)
        assert not res.converged.any()
        assert set(np.unique(res.status)) <= {int(s) for s in PointStatus} - {0}
        # every NaN carries a non-converged status; values are never silently NaN
        assert np.all(np.isfinite(res.u) | (res.status != 0))


def test_bad_inputs(ref128):
    with pytest.raises(InputError, match="subset=20"):
        Correlator(ref128, subset=20)
    with pytest.raises(InputError, match="subset=201"):
        Correlator(ref128, subset=201)
    with pytest.raises(InputError, match="current: shape"):
        correlate(ref128, ref128[:100])
    bad = ref128.copy()
    bad[3, 4] = np.nan
    with pytest.raises(InputError, match="NaN"):
        correlate(ref128, bad)
    with pytest.raises(InputError, match="NaN"):
        Correlator(bad)
    with pytest.raises(InputError, match="real grey levels"):
        Correlator(ref128.astype(complex))
    with pytest.raises(InputError, match="2-D"):
        Correlator(np.zeros((4, 64, 64)))
    with pytest.raises(InputError, match="shape="):
        Correlator(ref128, shape="quadratic")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="interpolation="):
        Correlator(ref128, interpolation="bilinear")
    with pytest.raises(InputError, match="step="):
        Correlator(ref128, step=0)
    with pytest.raises(InputError, match="roi="):
        Correlator(ref128, roi=(0, 500, 0, 10))
    with pytest.raises(InputError, match="points="):
        Correlator(ref128, points=[[1.5, 3.0]])
    with pytest.raises(InputError, match="initial="):
        Correlator(ref128, step=40).correlate(ref128, initial=np.zeros((3, 2)))
    with pytest.raises(InputError, match="noise_sigma="):
        Correlator(ref128, noise_sigma=-1.0)
    # integer images are fine
    res = correlate(
        ref128.astype(np.uint8),
        np.roll(ref128, 1, 1).astype(np.uint8),
        step=40,
        shape="translation",
    )
    assert_allclose(res.u[res.converged], 1.0, atol=1e-3)


def test_result_exports(ref128, tmp_path):
    cur = fourier_shift(ref128, 0.0, 0.5)
    corr = Correlator(ref128, subset=21, step=30, shape="affine", noise_sigma=2.0)
    res = corr.correlate(cur)
    assert isinstance(res, DICResult) and res.params.shape == (len(res), 6)
    assert res.status.dtype == np.uint8 and res.rows.shape == res.u.shape
    again = corr.correlate(cur)  # prepared reference reused: identical bytes
    assert np.array_equal(again.params, res.params)
    ds = res.to_xarray()
    assert_allclose(ds["u"].values, res.u)
    assert list(ds["param"].values) == ["u", "du_dx", "du_dy", "v", "dv_dx", "dv_dy"]
    path = tmp_path / "f.nc"
    ds.to_netcdf(path, engine="scipy")
    import xarray as xr

    with xr.open_dataset(path, engine="scipy") as back:
        assert_allclose(back["v"].values, res.v)
        assert int(back.attrs["subset"]) == 21
    res.to_csv(tmp_path / "f.csv")
    with (tmp_path / "f.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(res)
    assert float(rows[0]["u"]) == pytest.approx(res.u[0])
    assert rows[0]["status_name"] == "converged"
    s = res.summary(true_u=0.5, true_v=0.0)
    assert s["n_points"] == len(res) and abs(s["bias_u"]) < 0.005
    assert s["predicted_sigma_u"] > 0
    assert set(corr.last_timings) >= {"prefilter_s", "icgn_s"}
    corr.warmup()  # compiles (or loads) this configuration's kernels: now in numba's cache
    assert kernels_cached(corr.shape)


def test_prefilter_shared_between_correlators():
    # issue 17: one prefilter per frame for several Correlators of the same layout (the
    # track's seed points and its frame): the same bytes as correlating the array
    from dicblur.dic import PreparedImage

    ref = pattern(96, seed=3)
    cur = np.roll(ref, (1, 2), axis=(0, 1))
    corr = Correlator(ref, subset=21, step=12, shape="affine", workers=1)
    seeds = Correlator(ref, points=[[40, 40], [52, 64]], subset=21, shape="affine", workers=1)
    prep = corr.prefilter(cur)
    assert isinstance(prep, PreparedImage)
    for c in (corr, seeds):
        a = c.correlate(cur, initial=(2.0, 1.0))
        b = c.correlate(prep, initial=(2.0, 1.0))
        assert np.array_equal(a.params, b.params, equal_nan=True)
        assert np.array_equal(a.status, b.status)
    # a Correlator of another layout refuses it, naming the fix
    other = Correlator(ref, subset=31, step=12, workers=1)
    with pytest.raises(InputError, match="prefilter"):
        other.correlate(prep)
    with pytest.raises(InputError, match="prefilter"):
        Correlator(ref[:80], subset=21, step=12, workers=1).correlate(prep)
