"""MatcherSettings (issue 16): one frozen record of the matcher's settings, shared by the
Correlator, the campaigns and the predictions; and the compiled kernels' signatures."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dicblur import speckle_pattern
from dicblur.dic import Correlator, MatcherSettings, correlate
from dicblur.errors import InputError


@pytest.fixture(scope="module")
def pair():
    ref = speckle_pattern((96, 96), speckle_size=4, softness=1.0, seed=3)
    return ref, np.roll(ref, (1, 2), axis=(0, 1))


def test_defaults_are_the_correlators():
    s = MatcherSettings()
    assert (s.subset, s.step, s.shape, s.interpolation, s.initial) == (
        21,
        10,
        "affine",
        "bspline3",
        "fftcc",
    )
    assert (s.max_iterations, s.tolerance, s.min_zncc, s.max_residual, s.median_test) == (
        50,
        1e-4,
        0.6,
        2.0,
        False,
    )
    assert s.order == 3 and s.half == 10
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.subset = 31  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kwargs", "text"),
    [
        ({"subset": 20}, "subset=20"),
        ({"step": 0}, "step=0"),
        ({"shape": "quadratic"}, "shape='quadratic'"),
        ({"interpolation": "linear"}, "interpolation='linear'"),
        ({"initial": "guess"}, "initial='guess'"),
        ({"max_iterations": 0}, "max_iterations=0"),
        ({"tolerance": -1.0}, "tolerance=-1"),
        ({"min_zncc": 2.0}, "min_zncc=2.0"),
        ({"max_residual": 0.0}, "max_residual=0"),
        ({"median_test": "yes"}, "median_test="),
    ],
)
def test_bad_values_raise_the_correlators_messages(pair, kwargs, text):
    with pytest.raises(InputError) as a:
        MatcherSettings(**kwargs)
    with pytest.raises(InputError) as b:
        Correlator(pair[0], **kwargs)
    assert str(a.value) == str(b.value)
    assert text in str(a.value)


def test_correlator_takes_settings_and_keywords_override_them(pair):
    ref, cur = pair
    s = MatcherSettings(subset=19, step=12, shape="translation")
    by_settings = Correlator(ref, settings=s)
    by_keywords = Correlator(ref, subset=19, step=12, shape="translation")
    assert by_settings.settings == by_keywords.settings == s
    a, b = by_settings.correlate(cur), by_keywords.correlate(cur)
    np.testing.assert_array_equal(a.params, b.params)
    assert a.info == b.info
    over = Correlator(ref, settings=s, step=20, max_residual=None)
    assert over.settings == dataclasses.replace(s, step=20, max_residual=None)
    assert over.step == 20 and over.max_residual is None and over.shape == "translation"
    res = correlate(ref, cur, settings=s)
    np.testing.assert_array_equal(res.params, a.params)


def test_settings_of_another_type_are_refused(pair):
    with pytest.raises(InputError, match="settings="):
        Correlator(pair[0], settings={"subset": 21})  # type: ignore[arg-type]


def test_campaign_spec_builds_the_matcher_settings():
    from dicblur.campaign.spec import CampaignSpec, PatternSpec

    spec = CampaignSpec(
        name="t",
        seed=1,
        patterns=(PatternSpec(name="p", generator="speckle", settings={"shape": [64, 64]}),),
        blur=(0.0,),
        subsets=(21, 31),
        step=8,
        dic_shape="affine",
        interpolation="bspline5",
        max_iterations=30,
        tolerance=1e-5,
    )
    m = spec.matcher(31)
    assert m == MatcherSettings(
        subset=31,
        step=8,
        shape="affine",
        interpolation="bspline5",
        max_iterations=30,
        tolerance=1e-5,
    )


def test_predict_from_pattern_takes_settings(pair):
    from dicblur.models import predict_from_pattern

    ref = pair[0]
    s = MatcherSettings(subset=21, step=16, shape="translation")
    a = predict_from_pattern(ref, [0.0, 2.0], noise_sigma=2.0, settings=s)
    b = predict_from_pattern(
        ref, [0.0, 2.0], noise_sigma=2.0, subset=21, step=16, shape="translation"
    )
    np.testing.assert_array_equal(a.u_e, b.u_e)
    with pytest.raises(InputError, match="subset=None"):
        predict_from_pattern(ref, [0.0], noise_sigma=2.0)


_SIGNATURES = """
import json, numpy as np
from dicblur import speckle_pattern
from dicblur.dic import Correlator
from dicblur.dic.kernels import affine, prefilter, translation
ref = speckle_pattern((96, 96), speckle_size=4, softness=1.0, seed=3)
for shape in ("affine", "translation"):
    Correlator(ref, subset=21, step=12, shape=shape).correlate(np.roll(ref, 2, axis=1))
print(json.dumps({f.__name__: len(f.signatures) for f in (
    affine._affine_points, translation._point_translation, translation._points_translation,
    prefilter._columns_block, prefilter._rows_block)}))
"""


@pytest.mark.slow
def test_each_compiled_kernel_has_one_signature_per_call_path(tmp_path):
    """Issue 16, cold compile: a parfor's own loop index is unsigned, so passing it on
    compiled the serial callee twice (int64 and uint64), and the translation kernel had two
    call sites of its per-point function (two signatures); each now compiles once. Run on
    an empty numba cache (a cache load leaves the callees without signatures), all in this
    process (no background compile of the IC-GN kernel)."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), DICBLUR_COMPILE_CHILD="0")
    out = subprocess.run(
        [sys.executable, "-c", _SIGNATURES], env=env, capture_output=True, text=True, check=True
    )
    n = json.loads(out.stdout.strip().splitlines()[-1])
    assert n["_affine_points"] == 1
    assert n["_point_translation"] == 1
    assert n["_points_translation"] == 1
    # float32 (current image) and float64 (reference): one each
    assert n["_columns_block"] == 2
    assert n["_rows_block"] == 2
