"""First-run compile of the DIC kernels (issue 16): on a cold numba cache a child process
compiles the IC-GN kernel while this one compiles the prefilter, then this process loads
the kernel from the cache. The child must never hang the correlation nor change its
results."""

from __future__ import annotations

import os
import time
from types import SimpleNamespace

import pytest

from dicblur.dic import cache


@pytest.fixture
def cold(monkeypatch):
    """The background compile believes the cache is cold and the kernel not compiled."""
    monkeypatch.setattr(cache, "_CHECKED", set())
    monkeypatch.setattr(cache, "_BACKGROUND", {})
    monkeypatch.setattr(cache, "_cached", lambda entries: False)
    monkeypatch.setattr(cache, "_icgn_dispatcher", lambda shape: SimpleNamespace(overloads={}))
    monkeypatch.delenv("DICBLUR_COMPILE_CHILD", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    return monkeypatch


def test_a_child_that_fails_is_waited_for_and_reported(cold):
    cold.setattr(cache, "_CHILD", "import sys; sys.exit(3)  # {module}")
    assert cache.compile_in_background("affine") is True
    assert cache.compile_in_background("affine") is False  # once per process
    t0 = time.perf_counter()
    assert cache.wait_for_background("affine") is False  # this process compiles instead
    assert time.perf_counter() - t0 < 60
    assert cache.wait_for_background("affine") is False  # nothing left to wait for


def test_a_hung_child_is_killed_after_the_timeout(cold):
    cold.setattr(cache, "_CHILD", "import time; time.sleep(120)  # {module}")
    assert cache.compile_in_background("translation") is True
    proc = cache._BACKGROUND["translation"]
    t0 = time.perf_counter()
    assert cache.wait_for_background("translation", timeout=0.5) is False
    assert time.perf_counter() - t0 < 30 and proc.poll() is not None


def test_no_child_when_switched_off_or_on_one_core(cold):
    cold.setenv("DICBLUR_COMPILE_CHILD", "0")
    assert cache.compile_in_background("affine") is False
    cold.delenv("DICBLUR_COMPILE_CHILD")
    cold.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert cache.compile_in_background("affine") is False
    assert not cache._BACKGROUND


_COLD = """
import json, sys, numpy as np
from dicblur import Correlator, speckle_pattern
from dicblur.dic import cache
from dicblur.dic.kernels import affine, translation
ref = speckle_pattern((96, 96), speckle_size=4, softness=1.0, seed=3)
cur = np.roll(ref, 1, axis=1)
out = {}
kernels = {"affine": affine._affine_points, "translation": translation.icgn_translation}
for shape, kernel in kernels.items():
    res = Correlator(ref, subset=21, step=12, shape=shape).correlate(cur)
    out[shape] = {
        "hits": sum(kernel.stats.cache_hits.values()),
        "misses": sum(kernel.stats.cache_misses.values()),
        "params": res.params.tolist(),
        "iterations": res.iterations.tolist(),
    }
out["log"] = cache.BACKGROUND_LOG
print(json.dumps(out))
"""


@pytest.mark.slow
def test_cold_cache_compiles_the_icgn_kernel_in_a_child_with_the_same_results(tmp_path):
    # before: the first process compiled everything itself (no child, no cache hit)
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), NUMBA_NUM_THREADS="2")
    env.pop("DICBLUR_COMPILE_CHILD", None)
    runs = []
    for _ in range(2):  # cold, then warm
        out = subprocess.run(
            [sys.executable, "-c", _COLD], env=env, capture_output=True, text=True, timeout=900
        )
        assert out.returncode == 0, out.stderr[-3000:]
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    cold, warm = runs
    if len(os.sched_getaffinity(0)) >= 2:
        assert [r["shape"] for r in cold["log"]] == ["affine", "translation"]
        assert all(r["compiled"] for r in cold["log"])
        for shape in ("affine", "translation"):  # loaded from the child's cache entry
            assert cold[shape]["hits"] == 1 and cold[shape]["misses"] == 0
    assert warm["log"] == []  # a warm cache starts no child
    for shape in ("affine", "translation"):
        assert cold[shape]["params"] == warm[shape]["params"]
        assert cold[shape]["iterations"] == warm[shape]["iterations"]
