"""Bad arguments of the DIC API raise InputError naming the parameter, the value and the
fix (not a numpy TypeError/ValueError, not a silent truncation)."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur import Correlator
from dicblur.errors import InputError


@pytest.fixture(scope="module")
def ref():
    return dicblur.speckle_pattern((96, 96), speckle_size=4, seed=1)


@pytest.mark.parametrize("method", ["fftcc", "zero"])
def test_correlate_initial_method_name_points_to_the_constructor(ref, method):
    # before: ValueError "could not convert string to float"
    corr = Correlator(ref, subset=21, step=20)
    with pytest.raises(InputError, match=rf"initial='{method}'.*Correlator\(\.\.\., initial="):
        corr.correlate(ref, initial=method)


def test_correlate_and_refine_non_numeric_guesses(ref):
    corr = Correlator(ref, subset=21, step=20)
    with pytest.raises(InputError, match=r"initial=\['a', 'b'\]: expected finite \(u, v\) px"):
        corr.correlate(ref, initial=["a", "b"])
    with pytest.raises(InputError, match=r"start='abc': expected finite \(u, v\) px"):
        corr.refine(corr.prefilter(ref), "abc")


def test_non_numeric_points(ref):
    # before: TypeError from np.isfinite
    with pytest.raises(InputError, match=r"points=\[\['a', 'b'\]\]: expected an \(n, 2\) array"):
        Correlator(ref, subset=21, points=[["a", "b"]])


def test_fractional_roi_is_refused_not_truncated(ref):
    # before: (0.5, 90.7, ...) silently became (0, 90, ...)
    with pytest.raises(InputError, match=r"roi=\(0.5, 90.7, 0, 90\): the bounds must be whole"):
        Correlator(ref, subset=21, roi=(0.5, 90.7, 0, 90))
    corr = Correlator(ref, subset=21, step=20, roi=(0.0, 90.0, 0, 90))  # whole floats: fine
    assert corr.n_points > 0


def test_summary_true_displacement_not_a_number(ref):
    res = Correlator(ref, subset=21, step=20).correlate(np.roll(ref, 1, axis=1))
    with pytest.raises(InputError, match=r"true_u='a': expected the true displacement"):
        res.summary(true_u="a")
    assert res.summary(true_u=1.0)["bias_u"] == pytest.approx(0.0, abs=0.01)
