"""The DIC kernels' fast-math flags: NaN/inf semantics kept (status tests by NaN). The
reductions reassociate (for speed); a campaign compiles a cold cache in a subprocess first
so that every process runs the same cached code (tested end to end by
test_campaign_interrupts' empty-cache resume, and below)."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur.dic.kernels import affine, blur, common, prefilter, spline, translation
from dicblur.dic.status import PointStatus


def _compiled_kernels():
    for module in (affine, blur, common, prefilter, spline, translation):
        for name in dir(module):
            obj = getattr(module, name)
            if hasattr(obj, "targetoptions") and hasattr(obj, "py_func"):
                yield f"{module.__name__}.{name}", obj


def test_no_kernel_assumes_finite_values():
    found = list(_compiled_kernels())
    assert len(found) >= 15
    for name, fn in found:
        fm = fn.targetoptions.get("fastmath", False)
        flags = {"fast"} if fm is True else set(fm or ())
        assert not flags & {"fast", "nnan", "ninf"}, (name, flags)


def test_compile_kernels_fills_a_cold_cache_in_a_subprocess(tmp_path, monkeypatch):
    from dicblur.dic import cache

    calls = []
    monkeypatch.setattr(cache, "kernels_cached", lambda shape: bool(calls))
    import subprocess

    monkeypatch.setattr(subprocess, "run", lambda *a, **k: calls.append(a[0]))
    assert cache.compile_kernels(("translation",)) is True
    assert "Correlator" in calls[0][-1] and "'translation'" in calls[0][-1]
    assert cache.compile_kernels(("translation",)) is False  # warm: nothing to do


@pytest.mark.parametrize("shape", ["translation", "affine"])
def test_non_finite_subsets_get_a_failure_status(shape):
    # A float32 overflow (1e20 GL, the largest value the loaders accept) makes the
    # prefiltered coefficients inf / NaN around it:
    # the status must come from the NaN tests (`not dg2 > ...`, `math.isfinite(u)`), never
    # a "converged" NaN displacement.
    img = dicblur.speckle_pattern((96, 96), speckle_size=4.0, seed=1)
    cur = img.copy()
    cur[44:47, 44:47] = 1e20
    with np.errstate(all="ignore"):
        res = dicblur.correlate(img, cur, subset=15, step=12, shape=shape)
    st = np.asarray(res.status)
    # the subsets that hold the spot diverge with a NaN displacement; no other point is
    # "converged" with a non-finite value
    hit = (np.abs(res.rows - 45) <= 7) & (np.abs(res.cols - 45) <= 7)
    assert hit.any() and (st[hit] == PointStatus.DIVERGED).all()
    assert np.isnan(res.u[hit]).all() and np.isnan(res.v[hit]).all()
    ok = st == PointStatus.CONVERGED
    assert np.isfinite(res.u[ok]).all() and np.isfinite(res.v[ok]).all()
    clean = dicblur.correlate(img, img, subset=15, step=12, shape=shape)
    assert (np.asarray(clean.status) == PointStatus.CONVERGED).all()
