"""The ZNSSD algebra of IC-GN's per-subset preparation (dicblur.dic.icgn) against its
direct formulas: ``Jh = (J_c - fh a^T) / Df``, ``H = Jh^T Jh`` (the module docstring)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from dicblur.dic.icgn import (
    N_PARAMS,
    centre_subsets,
    gauss_newton_matrix,
    raw_jacobian,
    regular,
    scaled_inverse,
    uv_columns,
)


@pytest.mark.parametrize("shape", ["translation", "affine"])
def test_gauss_newton_matrix_is_the_normalised_models(shape):
    rng = np.random.default_rng(7)
    half, n = 4, 5
    npx = (2 * half + 1) ** 2
    fp = rng.normal(100.0, 20.0, (n, npx))
    fp[0] = 50.0  # a flat subset: Df = 0
    jac = raw_jacobian(rng.normal(0, 5, (n, npx)), rng.normal(0, 5, (n, npx)), half, shape)
    c = centre_subsets(fp, jac)
    avec, gram, big = gauss_newton_matrix(c.jc, c.fh)
    bad = ~((c.fnorm > 0) & regular(big))
    hinv, big_inv = scaled_inverse(big, bad, c.safe)
    assert bad.tolist() == [True] + [False] * (n - 1)
    for i in range(1, n):
        fcen = fp[i] - fp[i].mean()
        df = np.linalg.norm(fcen)
        fh = fcen / df
        jc = jac[i] - jac[i].mean(axis=0)
        jh = (jc - np.outer(fh, jc.T @ fh)) / df
        assert_allclose(c.fnorm[i], df, rtol=1e-12)
        assert_allclose(avec[i], jc.T @ fh, rtol=1e-10, atol=1e-9)
        assert_allclose(gram[i], jc.T @ jc, rtol=1e-10)
        assert_allclose(big[i], df**2 * (jh.T @ jh), rtol=1e-8, atol=1e-8)
        assert_allclose(hinv[i], np.linalg.inv(jh.T @ jh), rtol=1e-6)
        assert_allclose(big_inv[i], np.linalg.inv(big[i]), rtol=1e-6)
    k = N_PARAMS[shape]
    assert np.all(hinv[0] == 0.0) and np.array_equal(big_inv[0], np.eye(k))


def test_regular_flags_a_rank_deficient_matrix():
    a = np.random.default_rng(1).normal(size=(3, 6))
    good = a.T @ a + np.eye(6)
    low = a.T @ a  # rank 3 of 6
    assert regular(np.stack([good, low])).tolist() == [True, False]


def test_uv_columns_follow_the_parameter_order():
    # translation (u, v); affine (u, ux, uy, v, vx, vy)
    assert uv_columns(N_PARAMS["translation"]) == (0, 1)
    assert uv_columns(N_PARAMS["affine"]) == (0, 3)
