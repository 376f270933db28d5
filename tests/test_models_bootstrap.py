"""The bootstrap fallback of the fits: refits from the full fit, and no endless refits of a
model the resamples cannot identify (a planner page of a real image took minutes)."""

from __future__ import annotations

import numpy as np
import pytest

from dicblur.errors import FitError
from dicblur.models._result import BOOT_GIVE_UP, CIOptions, make_result

W = np.repeat(np.arange(1.0, 9.0), 2)  # 16 points at 8 blur levels


def _degenerate_full_fit(idx):
    """A two-parameter fit whose second column is zero: a degenerate covariance, so the
    covariance intervals fall back to the bootstrap."""
    jac = np.column_stack([np.ones(idx.size), np.zeros(idx.size)])
    return np.array([1.0, 2.0]), jac, np.full(idx.size, 0.1)


def _fit(fit_once, ci_options):
    """The fit result of a two-parameter test model over the 16 points of W."""
    return make_result(
        model="test",
        names=("a", "b"),
        fit_once=fit_once,
        n=W.size,
        data_space=np.zeros(W.size),
        blur=W,
        fixed={},
        ci_options=ci_options,
    )


def test_a_model_no_resample_can_refit_stops_the_bootstrap_early():
    calls = []

    def fit_once(idx, refit_from=None):
        if refit_from is None:
            return _degenerate_full_fit(idx)
        calls.append(refit_from)
        raise FitError("a refit that spent its budget")

    res = _fit(fit_once, CIOptions(seed=0))
    # it was 500 refits (n_boot), minutes for a mismatch fit crawling along its valley
    assert len(calls) == BOOT_GIVE_UP
    assert res.ci_method == "unidentified" and np.isinf(res.high).all()


def test_refits_start_from_the_fit_to_all_points_and_converged_ones_give_intervals():
    rng = np.random.default_rng(1)
    starts = []

    def fit_once(idx, refit_from=None):
        if refit_from is None:
            return _degenerate_full_fit(idx)
        starts.append(np.array(refit_from))
        return np.array([1.0, 2.0]) + rng.normal(0.0, 0.01, 2), None, None

    res = _fit(fit_once, CIOptions(seed=0, n_boot=50))
    assert res.ci_method == "bootstrap" and len(starts) > 10
    assert all(np.array_equal(s, [1.0, 2.0]) for s in starts)
    assert res.low[0] < 1.0 < res.high[0] and res.high[0] - res.low[0] == pytest.approx(
        0.04, rel=0.5
    )
