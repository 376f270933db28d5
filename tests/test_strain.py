"""Strain fields and their uncertainty (issue 28, docs/strain.md)."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur.dic import DICResult
from dicblur.errors import InputError
from dicblur.strain import (
    StrainStatus,
    gradient_factor,
    overlap_correlation,
    strain_on_grid,
    window_from_vsg,
)
from dicblur.strain.covariance import window_correlation


def grid_result(u_of, v_of, *, n=9, step=10, subset=21, sigma=None, status=None):
    r, c = np.meshgrid(np.arange(n) * step + 30, np.arange(n) * step + 30, indexing="ij")
    r, c = r.ravel(), c.ravel()
    k = r.size
    return DICResult(
        rows=r,
        cols=c,
        u=u_of(c.astype(float), r.astype(float)),
        v=v_of(c.astype(float), r.astype(float)),
        params=np.zeros((k, 2)),
        zncc=np.ones(k),
        iterations=np.ones(k, int),
        status=np.zeros(k, np.uint8) if status is None else status,
        predicted_sigma_u=None if sigma is None else np.full(k, sigma),
        predicted_sigma_v=None if sigma is None else np.full(k, sigma),
        info={"subset": subset, "step": step},
    )


A = (2e-3, -1e-3, 5e-4, 3e-3)  # ux, uy, vx, vy


def affine(x, y):
    return A[0] * x + A[1] * y + 0.3, A[2] * x + A[3] * y - 0.2


def test_affine_field_gives_its_strain_exactly():
    res = grid_result(lambda x, y: affine(x, y)[0], lambda x, y: affine(x, y)[1])
    small = dicblur.strain(res, kind="small")
    gl = dicblur.strain(res, kind="green-lagrange")
    ok = small.status == StrainStatus.OK
    assert ok.sum() == 25  # 9 x 9 grid, window 5: the 5 x 5 interior
    ux, uy, vx, vy = A
    np.testing.assert_allclose(small.exx[ok], ux, rtol=1e-9)
    np.testing.assert_allclose(small.eyy[ok], vy, rtol=1e-9)
    np.testing.assert_allclose(small.exy[ok], 0.5 * (uy + vx), rtol=1e-9)
    np.testing.assert_allclose(gl.exx[ok], ux + 0.5 * (ux**2 + vx**2), rtol=1e-9)
    np.testing.assert_allclose(gl.eyy[ok], vy + 0.5 * (uy**2 + vy**2), rtol=1e-9)
    np.testing.assert_allclose(gl.exy[ok], 0.5 * (uy + vx + ux * uy + vx * vy), rtol=1e-9)
    # GL and small strain differ by the quadratic terms, here ~1e-6
    assert np.all(np.abs(gl.exx[ok] - small.exx[ok]) > 1e-6)
    assert small.vsg == 4 * 10 + 21
    assert small.sigma_exx is None  # no displacement sigma: no strain sigma


def test_principal_strains_of_a_rotated_tension():
    th = np.deg2rad(30.0)
    e = 1e-3  # uniaxial tension along th: exx, eyy, exy of the rotated tensor
    exx, eyy, exy = e * np.cos(th) ** 2, e * np.sin(th) ** 2, e * np.sin(th) * np.cos(th)
    res = grid_result(lambda x, y: exx * x + exy * y, lambda x, y: exy * x + eyy * y, sigma=0.01)
    s = dicblur.strain(res, kind="small")
    ok = s.status == StrainStatus.OK
    np.testing.assert_allclose(s.e1[ok], e, rtol=1e-9)
    np.testing.assert_allclose(s.e2[ok], 0.0, atol=1e-12)
    np.testing.assert_allclose(s.angle[ok], th, rtol=1e-9)
    assert np.all(np.isfinite(s.sigma_e1[ok])) and np.all(s.sigma_angle[ok] > 0)


def test_failed_neighbour_shrinks_the_window_never_spans_it():
    n = 11
    st = np.zeros(n * n, np.uint8)
    centre = 5 * n + 5
    st[centre] = 4  # DIVERGED
    res = grid_result(
        lambda x, y: affine(x, y)[0], lambda x, y: affine(x, y)[1], n=n, status=st, sigma=0.01
    )
    u = res.u.copy()
    u[centre] = 1e3  # a wild value at the failed point must not leak anywhere
    res = DICResult(**{**res.__dict__, "u": u})
    s = dicblur.strain(res, kind="small", window=5)
    status = s.status.reshape(n, n)
    assert status[5, 5] == StrainStatus.POINT_FAILED and np.isnan(s.exx[centre])
    # points within 2 of the failed one: reduced windows (3 x 3 where it fits) or none
    near = status[3:8, 3:8].ravel()
    assert set(near.tolist()) <= {
        StrainStatus.REDUCED_WINDOW,
        StrainStatus.NO_WINDOW,
        StrainStatus.POINT_FAILED,
    }
    assert status[2, 2] == StrainStatus.OK and status[5, 2] == StrainStatus.OK
    fine = np.isfinite(s.exx)
    np.testing.assert_allclose(s.exx[fine], A[0], rtol=1e-9)
    red = s.status == StrainStatus.REDUCED_WINDOW
    assert red.any() and np.all(s.window[red] == 3)
    # a smaller window: a larger sigma
    assert np.all(s.sigma_exx[red] > np.nanmax(s.sigma_exx[s.status == StrainStatus.OK]))
    # the grid's border has no symmetric window
    assert np.all(status[0] == StrainStatus.NO_WINDOW)


def test_sigma_independent_points_matches_closed_form():
    # subset <= step: no shared pixels, independent errors (paper brief s. 11)
    sigma, step, n_win = 0.02, 25, 5
    res = grid_result(lambda x, y: 0 * x, lambda x, y: 0 * x, step=step, subset=25, sigma=sigma)
    s = dicblur.strain(res, kind="small", window=n_win)
    ok = s.status == StrainStatus.OK
    expect = sigma * np.sqrt(12) / (step * n_win * np.sqrt(n_win**2 - 1))
    np.testing.assert_allclose(s.sigma_exx[ok], expect, rtol=1e-12)
    np.testing.assert_allclose(s.sigma_eyy[ok], expect, rtol=1e-12)
    np.testing.assert_allclose(s.sigma_exy[ok], expect / np.sqrt(2), rtol=1e-12)
    # overlapping subsets: positively correlated neighbours make it larger
    assert gradient_factor(2, 10.0, 21) > 1.3 * np.sqrt(12) / (10 * 5 * np.sqrt(24))


def test_overlap_correlation_is_the_shared_area():
    assert overlap_correlation(0, 0, 21) == 1.0
    assert overlap_correlation(0, 10, 21) == pytest.approx(11 / 21)
    assert overlap_correlation(10, 10, 21) == pytest.approx((11 / 21) ** 2)
    assert overlap_correlation(0, 21, 21) == 0.0
    r = window_correlation(2, 10.0, 21)
    assert np.all(np.linalg.eigvalsh(r) > -1e-12)  # a valid correlation matrix


def test_sigma_matches_monte_carlo_of_correlated_errors():
    # displacement errors drawn with the overlap correlation (Cholesky): the predicted
    # strain sigma is the scatter of the strains they give
    n, step, subset, sigma = 9, 10, 21, 0.01
    r, c = np.meshgrid(np.arange(n) * step, np.arange(n) * step, indexing="ij")
    d_r = r.ravel()[:, None] - r.ravel()[None, :]
    d_c = c.ravel()[:, None] - c.ravel()[None, :]
    chol = np.linalg.cholesky(overlap_correlation(d_r, d_c, subset) + 1e-12 * np.eye(n * n))
    rng = np.random.default_rng(3)
    trials = 4000
    eu = sigma * (chol @ rng.standard_normal((n * n, trials))).T.reshape(trials, n, n)
    ev = sigma * (chol @ rng.standard_normal((n * n, trials))).T.reshape(trials, n, n)
    s = strain_on_grid(
        eu,
        ev,
        np.ones(eu.shape, bool),
        step=step,
        subset=subset,
        kind="small",
        sigma_u=np.full(eu.shape, sigma),
        sigma_v=np.full(eu.shape, sigma),
    )
    centre = (n // 2) * n + n // 2
    for name in ("exx", "eyy", "exy"):
        measured = np.std(getattr(s, name)[:, centre])
        predicted = getattr(s, f"sigma_{name}")[0, centre]
        assert measured == pytest.approx(predicted, rel=0.05), name
    cov = np.cov(np.stack([s.exx[:, centre], s.exy[:, centre]]))
    assert abs(cov[0, 1]) < 0.1 * cov[0, 0]  # uncorrelated here; predicted 0
    assert abs(s.cov[0, centre, 0, 2]) < 1e-3 * s.cov[0, centre, 0, 0]


def test_blur_shift_enters_as_its_own_gradient():
    # a signed blur shift that ramps along x by k px/px adds k to exx, not in quadrature
    n, step = 9, 10
    _r, c = np.meshgrid(np.arange(n) * step, np.arange(n) * step, indexing="ij")
    zero = np.zeros((n, n))
    k = 2e-4
    s = strain_on_grid(
        zero,
        zero,
        np.ones((n, n), bool),
        step=step,
        subset=21,
        kind="small",
        sigma_u=zero + 0.01,
        sigma_v=zero + 0.01,
        shift_u=0.05 + k * c,
        shift_v=zero,
    )
    ok = s.status == StrainStatus.OK
    np.testing.assert_allclose(s.sigma_exx_blur[ok], k, rtol=1e-9)
    # a common offset (uniform shift) cancels in the gradient
    s0 = strain_on_grid(
        zero, zero, np.ones((n, n), bool), step=step, subset=21, sigma_u=zero + 0.01,
        sigma_v=zero + 0.01, shift_u=zero + 0.05, shift_v=zero + 0.05,
    )  # fmt: skip
    np.testing.assert_allclose(s0.sigma_exx_blur[ok], 0.0, atol=1e-15)
    np.testing.assert_allclose(s.sigma_exx[ok], np.hypot(s.sigma_exx_noise[ok], k), rtol=1e-9)


def test_subset_method_uses_the_affine_gradients():
    res = grid_result(lambda x, y: affine(x, y)[0], lambda x, y: affine(x, y)[1], sigma=0.01)
    p = np.zeros((res.u.size, 6))
    p[:, 0], p[:, 3] = res.u, res.v
    p[:, 1], p[:, 2], p[:, 4], p[:, 5] = A
    res = DICResult(**{**res.__dict__, "params": p})
    s = dicblur.strain(res, kind="small", method="subset")
    assert s.vsg == 21 and np.all(s.status == StrainStatus.OK)
    np.testing.assert_allclose(s.exx, A[0])
    h = 10
    np.testing.assert_allclose(s.sigma_exx, 0.01 / np.sqrt(h * (h + 1) / 3))
    with pytest.raises(InputError, match="affine"):
        dicblur.strain(grid_result(lambda x, y: x, lambda x, y: y), method="subset")


def test_bad_arguments():
    res = grid_result(lambda x, y: 0 * x, lambda x, y: 0 * x)
    with pytest.raises(InputError, match="window=4"):
        dicblur.strain(res, window=4)
    with pytest.raises(InputError, match="kind="):
        dicblur.strain(res, kind="engineering")  # type: ignore[arg-type]
    pts = DICResult(**{**res.__dict__, "rows": res.rows[::-1].copy()})
    with pytest.raises(InputError, match="regular grid"):
        dicblur.strain(pts)
    assert window_from_vsg("41px", step=10, subset=21) == 3
    assert window_from_vsg("5", step=10, subset=21) == 5
    with pytest.raises(InputError, match="--vsg='45px'"):
        window_from_vsg("45px", step=10, subset=21)
    with pytest.raises(InputError, match="odd"):
        window_from_vsg("6", step=10, subset=21)


def test_field_variables_shape_and_names():
    # the Dataset/CSV names beside u, v
    res = grid_result(lambda x, y: affine(x, y)[0], lambda x, y: affine(x, y)[1], sigma=0.01)
    s = dicblur.strain(res)
    names = s.variables()
    assert {"exx", "sigma_exx", "cov_exx_eyy", "strain_status"} <= set(names)
    assert all(np.asarray(a).shape == (res.u.size,) for a in names.values())
