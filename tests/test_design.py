"""Pattern design: family, problem, evaluation, search, confirmation, export."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from dicblur import blur_length, speckle_pattern, speckle_size, sssig
from dicblur.design import (
    DEFAULT_CANDIDATE,
    Candidate,
    PatternFamily,
    design_pattern,
    design_problem,
    evaluate_candidate,
    export_pattern,
    regenerate,
    sine_blur_distribution,
    surrogate,
)
from dicblur.design import search as search_mod
from dicblur.design.evaluate import Evaluation
from dicblur.errors import InputError
from dicblur.report.design_page import spearman

SMALL = {"noise": 2.0, "subset": 31, "step": 10, "image_size": 128, "realisations": 2}


def small_family(grid=(3, 1, 2)) -> PatternFamily:
    return PatternFamily(
        speckle_size=(2.0, 8.0), density=(0.5, 0.5), softness=(0.0, 1.5), grid=grid
    )


# --------------------------------------------------------------------------- family
def test_family_grid_and_unit_mapping():
    fam = PatternFamily(
        speckle_size=(2.0, 8.0), density=(0.3, 0.7), softness=(0.0, 2.0), grid=(3, 2, 3)
    )
    np.testing.assert_allclose(fam.axis(0), [2.0, 4.0, 8.0])  # geometric
    np.testing.assert_allclose(fam.axis(2), [0.0, 1.0, 2.0])
    cands = fam.grid_candidates()
    assert len(cands) == 18 and all(fam.contains(c) for c in cands)
    c = Candidate(4.0, 0.6, 0.5)
    np.testing.assert_allclose(fam.to_unit(c), [0.5, 0.75, 0.25])
    back = fam.from_unit(fam.to_unit(c))
    assert back.key() == c.key()
    assert fam.from_unit([2.0, -1.0, 0.5]).key() == Candidate(8.0, 0.3, 1.0).key()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"speckle_size": (5.0, 3.0)}, "speckle_size"),
        ({"density": (0.0, 0.5)}, "density"),
        ({"softness": (-1.0, 1.0)}, "softness"),
        ({"grid": (3, 0, 2)}, "grid"),
    ],
)
def test_family_bad_bounds(kwargs, match):
    with pytest.raises(InputError, match=match):
        PatternFamily(**kwargs)


def test_family_for_subset_caps_speckle_size():
    assert PatternFamily.for_subset(21).speckle_size == (2.0, 7.0)
    assert PatternFamily.for_subset(61).speckle_size == (2.0, 10.0)


# --------------------------------------------------------------------------- problem
def test_problem_targets():
    p = design_problem(blur=3.0)
    assert p.blurs == (3.0,) and p.weights == (1.0,)
    assert p.fit_blurs[0] == 0.0 and p.fit_blurs[-1] == pytest.approx(3.75)
    r = design_problem(blur_range=(1.0, 5.0), range_points=5)
    assert r.blurs == (1.0, 2.0, 3.0, 4.0, 5.0)
    assert r.objective(np.array([1.0, 2.0, 3.0, 4.0, 5.0])) == pytest.approx(3.0)
    v = design_problem(velocity=100.0, exposure=1e-3, scale=0.05)
    assert v.blurs[0] == pytest.approx(100.0 * 1e-3 / 0.05)
    assert v.blurs[0] == pytest.approx(blur_length(100.0, 1e-3, 0.05))
    d = design_problem(blurs=[4.0, 2.0], weights=[1.0, 3.0])
    assert d.blurs == (2.0, 4.0) and d.weights == (0.75, 0.25)


def test_sine_blur_distribution_matches_sampled_phases():
    """Against W = |x(t + T) - x(t)| of the sine motion sampled at random trigger times."""
    amp, f, t_exp = 5.0, 20.0, 2e-3
    w, wt = sine_blur_distribution(amp, f, t_exp, points=41)
    t = np.random.default_rng(0).uniform(0.0, 1.0 / f, 200_000)
    x = lambda s: amp * np.sin(2 * np.pi * f * s)  # noqa: E731
    sampled = np.abs(x(t + t_exp) - x(t))
    assert w.max() == pytest.approx(sampled.max(), rel=1e-3)
    assert np.dot(wt, w) == pytest.approx(sampled.mean(), rel=0.01)
    assert np.quantile(sampled, 0.5) == pytest.approx(np.median(w), rel=0.03)
    assert wt.sum() == pytest.approx(1.0) and np.all(np.diff(w) >= 0)
    p = design_problem(blurs=w, weights=wt)
    assert len(p.blurs) == 41 and p.fit_blurs[-1] == pytest.approx(1.25 * w.max(), abs=1e-3)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"blur_range": (5.0, 1.0)}, "inverted"),
        ({"blur": -1.0}, ">= 0"),
        ({"blur_range": (-1.0, 2.0)}, ">= 0"),
        ({"blur": float("nan")}, "blur"),
        ({"blur": 3.0, "blur_range": (0.0, 5.0)}, "exactly one"),
        ({}, "exactly one"),
        ({"velocity": 10.0, "exposure": 1e-3}, "all three"),
        ({"blur": 3.0, "noise": 0.0}, "noise"),
        ({"blur": 3.0, "subset": 30}, "subset"),
        ({"blur": 3.0, "image_size": 64}, "image_size"),
        ({"blur": 3.0, "dic_shape": "quadratic"}, "dic_shape"),
        ({"blur": 80.0}, "quarter"),
        ({"blurs": [1.0, 2.0], "weights": [0.0, 0.0]}, "weights"),
    ],
)
def test_problem_bad_input(kwargs, match):
    with pytest.raises(InputError, match=match):
        design_problem(**kwargs)


# --------------------------------------------------------------------------- evaluation
def test_surrogate_static_limit_is_match_score():
    """At W = 0 the surrogate is sqrt(2 sigma^2 / SSSIG) with SSSIG from dicblur.sssig."""
    p = design_problem(blurs=[0.0], **SMALL)
    img = speckle_pattern(128, speckle_size=4.0, density=0.5, softness=0.5, seed=3)
    u, c = surrogate(img[None], p)
    s = sssig(img, subset=31, step=10, direction="x")
    assert u[0] == pytest.approx(math.sqrt(2 * 4.0 / np.mean(s)), rel=1e-9)
    assert c > 0


def test_evaluation_static_error_follows_match_score():
    """Measured u_e at W = 0 agrees with the match-score model (Wang & Pan 2015) to 30 %."""
    p = design_problem(blur=2.0, **SMALL)
    e = evaluate_candidate(DEFAULT_CANDIDATE, p)
    predicted0 = math.sqrt(2 * p.noise**2 / e.sssig[0])
    assert e.u_e[0] == pytest.approx(predicted0, rel=0.3)
    # blur raises the error and lowers SSSIG; the model fit succeeded
    assert e.u_e[-1] > 2 * e.u_e[0] and e.sssig[-1] < e.sssig[0]
    assert e.fit_ok and e.mbrf > 0 and e.n_points == 2 * len(p.fit_blurs)
    # the fitted model reproduces the measured u_e at the design blur (interpolation)
    measured = float(np.interp(2.0, p.fit_blurs, e.u_e))
    assert e.objective == pytest.approx(measured, rel=0.25)


def test_measurement_is_the_campaign_engines(tmp_path):
    """The in-process candidate campaign stores the same numbers as run_campaign."""
    from dicblur import campaign
    from dicblur.design.evaluate import campaign_spec, measure_candidate

    p = design_problem(blur=2.0, **SMALL)
    cand = Candidate(3.0, 0.45, 0.5)
    spec = campaign_spec(cand, p)
    m = measure_candidate(spec)
    campaign.run_campaign(spec, tmp_path / "c.zarr", serial=True)
    ds = campaign.open_results(tmp_path / "c.zarr")
    for name in ("u_e", "sssig", "mig_ref"):
        stored = (
            ds[name]
            .squeeze(["angle", "subset", "noise", "rep"])
            .transpose("pattern", "blur")
            .values
        )
        np.testing.assert_array_equal(stored, m[name])


# --------------------------------------------------------------------------- search
@pytest.mark.slow
def test_ranking_stable_across_seeds():
    fam = small_family()
    ranks = []
    for seed in (0, 1):
        p = design_problem(blur=3.0, seed=seed, **SMALL)
        r = design_pattern(p, fam, max_refine=0, confirm_realisations=0)
        ranks.append({e.candidate.key(): e.objective for e in r.grid})
        assert r.n_campaigns == 6  # the default pattern (4, 0.5, 0) is a grid member
        assert r.reference.stage == "grid"
    keys = list(ranks[0])
    rho = spearman([ranks[0][k] for k in keys], [ranks[1][k] for k in keys])
    assert rho >= 0.8
    assert min(ranks[0], key=ranks[0].get) == min(ranks[1], key=ranks[1].get)


@pytest.mark.slow
def test_design_beats_default_by_more_than_measurement_uncertainty():
    p = design_problem(blur=3.0, **SMALL)
    r = design_pattern(p, small_family(), max_refine=3, confirm_realisations=4)
    assert sum(e.stage == "refine" for e in r.evaluations) <= 3
    assert r.best.objective <= min(e.objective for e in r.grid)
    conf = r.confirmation
    assert conf is not None and conf.labels == ("best", "default", "worst")
    diff, se = conf.difference("best", "default")
    assert diff > 0 and diff > 3 * se
    # independent check of the paired statistics
    d = np.asarray(conf.objective[1]) - np.asarray(conf.objective[0])
    assert diff == pytest.approx(d.mean()) and se == pytest.approx(d.std(ddof=1) / 2.0)
    assert conf.mean("best") < conf.mean("worst")
    s = r.summary()
    assert s["n_points"] == r.n_points > 0 and 0 < s["gain_vs_default"] < 1
    json.dumps(r.to_dict(), default=float)


def _fake_evaluation(c: Candidate, problem, *, stage="grid") -> Evaluation:
    # A smooth bowl with its minimum at D = 5, p = 0.45, s = 0.8 (inside the bounds).
    f = 1e-3 * (
        1
        + (math.log(c.speckle_size / 5.0)) ** 2
        + 4 * (c.density - 0.45) ** 2
        + 0.5 * (c.softness - 0.8) ** 2
    )
    nan = float("nan")
    return Evaluation(
        c, stage, f, (f,), (0.0,), (f,), (1.0,), nan, nan, nan, nan, nan, nan, nan, f, True, 1, 0.0
    )


def test_refinement_finds_interior_optimum(monkeypatch):
    """Grid + bounded Nelder-Mead finds a known optimum in tens of evaluations."""
    monkeypatch.setattr(search_mod, "evaluate_candidate", _fake_evaluation)
    fam = PatternFamily(
        speckle_size=(2.0, 10.0), density=(0.3, 0.7), softness=(0.0, 2.0), grid=(3, 3, 3)
    )
    p = design_problem(blur=3.0)
    r = design_pattern(p, fam, max_refine=30, confirm_realisations=0)
    b = r.best.candidate
    assert len(r.evaluations) <= 27 + 30
    assert b.speckle_size == pytest.approx(5.0, rel=0.1)
    assert b.density == pytest.approx(0.45, abs=0.04)
    assert b.softness == pytest.approx(0.8, abs=0.15)
    assert r.best.objective < min(e.objective for e in r.grid)


def test_design_rejects_bad_options():
    p = design_problem(blur=3.0, **SMALL)
    with pytest.raises(InputError, match="max_refine"):
        design_pattern(p, small_family(), max_refine=-1)
    with pytest.raises(InputError, match="confirm_realisations"):
        design_pattern(p, small_family(), confirm_realisations=1)


# --------------------------------------------------------------------------- export
def test_export_physical_size_and_dpi(tmp_path):
    from PIL import Image

    cand = Candidate(3.0, 0.5, 0.0)
    e = export_pattern(cand, tmp_path, scale=0.1, size_mm=(40.0, 25.0), dpi=300, seed=5)
    pitch = 25.4 / 300
    assert e.shape == (round(40.0 / pitch), round(25.0 / pitch)) == (472, 295)
    with Image.open(e.png) as im:
        assert im.size == (295, 472)  # (width, height)
        assert im.info["dpi"] == pytest.approx((300, 300), abs=0.01)
        arr = np.asarray(im)
    # physical size: dots / dpi, within half a dot of the request
    assert arr.shape[0] / 300 * 25.4 == pytest.approx(40.0, abs=pitch / 2)
    assert arr.shape[1] / 300 * 25.4 == pytest.approx(25.0, abs=pitch / 2)
    # speckle size on the print: 3 camera px * 0.1 mm/px = 0.3 mm = 3.54 dots
    assert e.speckle_size_mm == pytest.approx(0.3)
    assert speckle_size(arr.astype(float)) == pytest.approx(0.3 / pitch, rel=0.15)
    # PDF page of the same physical size (points = inches * 72)
    text = e.pdf.read_bytes()
    box = [float(v) for v in re.search(rb"MediaBox\s*\[([^\]]*)\]", text).group(1).split()]
    assert box[2] == pytest.approx(295 / 300 * 72, abs=0.01)
    assert box[3] == pytest.approx(472 / 300 * 72, abs=0.01)
    # the JSON regenerates the printed image exactly
    rec = json.loads(e.settings.read_text())
    assert rec["speckle_size_mm"] == pytest.approx(0.3) and rec["dpi"] == 300
    np.testing.assert_array_equal(regenerate(e.settings), arr)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"dpi": 0}, "dpi"),
        ({"dpi": -300}, "dpi"),
        ({"size_mm": 0.0}, "size_mm"),
        ({"size_mm": (10.0, -5.0)}, "size_mm"),
        ({"scale": 0.0}, "scale"),
        ({"dpi": 50}, "dpi >= "),  # 0.3 mm speckle < 1 dot at 50 dpi
        ({"size_mm": 0.5}, "larger area"),
        ({"size_mm": 1000.0, "dpi": 1200}, "max_pixels"),
    ],
)
def test_export_bad_input(tmp_path, kwargs, match):
    args = {"scale": 0.1, "size_mm": 20.0, "dpi": 300} | kwargs
    with pytest.raises(InputError, match=match):
        export_pattern(Candidate(3.0, 0.5, 0.0), tmp_path, **args)


def test_surrogate_screen_measures_only_the_best():
    p = design_problem(blur=3.0, **SMALL)
    r = design_pattern(p, small_family(), screen=3, max_refine=0, confirm_realisations=0)
    assert len(r.screened) == 6 and len(r.grid) == 3
    ranked = sorted(r.screened, key=lambda cs: cs[1])
    assert {c.key() for c, _ in ranked[:3]} == {e.candidate.key() for e in r.grid}
    # the screen (images from make_pattern) and the campaign path agree on the surrogate
    sur = {c.key(): s for c, s in r.screened}
    for e in r.grid:
        assert e.surrogate == pytest.approx(sur[e.candidate.key()], rel=1e-12)
    # the surrogate's worst member was measured for the comparison
    assert r.worst.candidate.key() == ranked[-1][0].key() or r.worst.stage == "grid"
    with pytest.raises(InputError, match="screen"):
        design_pattern(p, small_family(), screen=0)
