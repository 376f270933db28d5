"""The default path's speed on hard images (issue 26, item 3): what removes the excess
keeps the results (the speeds themselves: benchmarks/bench_screening.py)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from dicblur import Correlator
from dicblur.dic import PointStatus
from dicblur.dic.passes import SERIAL_BELOW
from dicblur.dic.screening import pair_medians
from helpers.dic import blobs, fourier_shift

TRUE_U, TRUE_V = 0.3, -0.2


def _blobs(n: int, seed: int = 11) -> tuple[np.ndarray, np.ndarray]:
    img = blobs((n, n))
    rng = np.random.default_rng(seed)
    cur = fourier_shift(img, TRUE_V, TRUE_U)
    return img + rng.normal(0, 2.0, img.shape), cur + rng.normal(0, 2.0, img.shape)


@pytest.mark.slow  # a fresh interpreter importing numba: ~2.5 s
def test_openmp_waits_passively_unless_the_user_chose():
    # the GNU runtime's default spin cost 11 ms of CPU per translation kernel call; the
    # user's own OMP_WAIT_POLICY is kept
    code = (
        "import os, dicblur.dic.kernels; a = os.environ['OMP_WAIT_POLICY']; "
        "os.environ['OMP_WAIT_POLICY'] = 'ACTIVE'; import importlib, dicblur.dic.kernels.common "
        "as c; importlib.reload(c); print(a, os.environ['OMP_WAIT_POLICY'])"
    )
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.stdout.split() == ["PASSIVE", "ACTIVE"], out.stderr


def test_pair_medians_at_cells_equal_the_full_grid():
    rng = np.random.default_rng(3)
    ny, nx = 7, 9
    values = rng.normal(size=(6, ny * nx))
    values[:, rng.random(ny * nx) < 0.3] = np.nan
    full, pairs = pair_medians(values, (ny, nx))
    cells = np.array([0, 5, 17, 40, ny * nx - 1])
    at, n_at = pair_medians(values, (ny, nx), cells=cells)
    assert at.shape == (6, cells.size)
    np.testing.assert_array_equal(at, full.reshape(6, -1)[:, cells])
    np.testing.assert_array_equal(n_at, pairs.ravel()[cells])


def test_small_translation_calls_on_one_thread_give_the_same_bytes():
    # the neighbour check's few retries run below SERIAL_BELOW POIs on the calling thread
    ref, cur = _blobs(160)
    one = Correlator(ref, subset=21, step=10, shape="translation", workers=1).correlate(cur)
    two = Correlator(ref, subset=21, step=10, shape="translation", workers=2).correlate(cur)
    assert one.u.size > SERIAL_BELOW
    for a, b in ((one.u, two.u), (one.v, two.v), (one.status, two.status)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("shape", ["affine", "translation"])
def test_retry_reach_stops_a_wandering_start(shape):
    # max_step: a POI whose u or v leaves its start by more is DIVERGED, at once
    ref, cur = _blobs(128)
    c = Correlator(ref, subset=21, step=20, shape=shape)
    res = c.correlate(cur)
    ok = np.flatnonzero(res.converged)
    coef = c.prefilter(cur).coefficients
    start = res.params[ok].copy()
    start[:, 0] += 0.5  # half a pixel off: IC-GN moves u back by ~0.5 px
    st0 = np.zeros(ok.size, np.uint8)
    _, _, _, st_free = c._run_icgn(coef, start, st0, ok, 20)
    _, _, it, st_near = c._run_icgn(coef, start, st0, ok, 20, 0.1)
    assert np.mean(st_free == PointStatus.CONVERGED) > 0.9
    assert np.all(st_near == PointStatus.DIVERGED)
    assert it.max() <= 2
