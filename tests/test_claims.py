"""The claims' verdicts are computed from data, with intervals (issue #14, item 6)."""

from __future__ import annotations

import ast
import inspect

import numpy as np
import pytest

from dicblur import speckle_pattern
from dicblur.report import claims
from dicblur.report.claims import judge_interval, ratio_interval, spearman_interval
from dicblur.report.experiments import algorithm1_translation
from dicblur.report.html import markdown_to_html


def test_no_claim_has_a_constant_verdict():
    """Every _claim(...) call computes its verdict (6th argument): no string literal."""
    tree = ast.parse(inspect.getsource(claims))
    calls = [
        n
        for n in ast.walk(tree)
        if isinstance(n, ast.Call) and getattr(n.func, "id", None) == "_claim"
    ]
    assert len(calls) >= 21
    literal = [ast.literal_eval(c.args[0]) for c in calls if isinstance(c.args[5], ast.Constant)]
    assert literal == [], f"claims with a hard-coded verdict: {literal}"


def test_no_internal_wording_in_claims():
    src = inspect.getsource(claims)
    for word in ("brief s.", "extraction", "garbled"):
        assert word not in src


@pytest.mark.parametrize(
    ("low", "high", "accept", "verdict"),
    [
        (0.9, 1.1, (0.85, 1.15), "agrees"),
        (0.8, 1.1, (0.85, 1.15), "inconclusive"),
        (1.2, 1.4, (0.85, 1.15), "differs"),
        (0.2, 0.6, (0.0, 1.0), "agrees"),
        (0.7, 1.3, (0.0, 1.0), "inconclusive"),
        (float("nan"), 1.0, (0.0, 1.0), "inconclusive"),
    ],
)
def test_judge_interval(low, high, accept, verdict):
    assert judge_interval(low, high, accept=accept) == verdict


def test_ratio_interval_covers_the_true_ratio():
    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(200):
        den = rng.lognormal(0.0, 0.1, 8)
        num = 1.2 * den * rng.lognormal(0.0, 0.05, 8)
        r, lo, hi = ratio_interval(num, den)
        assert lo <= r <= hi
        hits += lo <= 1.2 <= hi
    assert 180 <= hits <= 200  # nominal 95 %


def test_spearman_interval_is_wide_for_five_points():
    _, lo, hi = spearman_interval([1, 2, 3, 4, 5], [2, 1, 4, 3, 5])
    assert lo < 0.5 < hi  # five patterns cannot settle a 0.5 criterion
    _, lo, hi = spearman_interval(np.arange(40), np.arange(40) + 0.1)
    assert lo > 0.9
    # a perfect order of five points is no certainty
    rho, lo, hi = spearman_interval([1, 2, 3, 4, 5], [5, 4, 3, 2, 1])
    assert rho == pytest.approx(-1.0) and hi - lo > 0.5 and hi > -0.5


def test_algorithm1_translates_by_half_the_motion_on_the_image():
    img = speckle_pattern((64, 96), speckle_size=4, density=0.5, softness=0.5, seed=1)
    for w in (1.0, 3.5, 7.0):
        r = algorithm1_translation(img, w)
        assert abs(r.translation - w / 2) < 1e-9
        assert r.asymmetry < 1e-9


def test_algorithm1_check_detects_an_off_centre_kernel(monkeypatch):
    """The check can fail: an Algorithm 1 with K substeps instead of K + 1 (positions
    k/K, k = 0..K-1) translates by X (K - 1) / (2 K) and is caught."""
    import dicblur.blur as blur

    real = blur.motion_blur

    def off_centre(image, motion, **kw):
        k = 10
        t = np.arange(k) / k
        path = np.stack([t * motion[0], t * motion[1]], axis=1)
        return real(image, None, trajectory=path)

    monkeypatch.setattr(blur, "motion_blur", off_centre)
    img = speckle_pattern((64, 96), speckle_size=4, density=0.5, softness=0.5, seed=1)
    r = algorithm1_translation(img, 4.0)
    assert abs(r.translation - 2.0) > 0.1


def test_markdown_renders_as_html_not_pre():
    text = "# Title\n\nSome **bold** text.\n\n- a\n- b\n\n| x | y |\n|---|---|\n| 1 | 2 |\n"
    out = markdown_to_html(text, heading_offset=1)
    assert "<pre>" not in out and "<h3>Title</h3>" in out
    assert "<strong>bold</strong>" in out and "<li>a</li>" in out
    assert "<td>1</td>" in out and "|---|" not in out
