"""The real campaign task (blur + noise + DIC + metrics) against closed forms, and on Dask."""

from __future__ import annotations

import math

import numpy as np
import pytest

import dicblur
from dicblur.campaign import (
    VARIABLES,
    iter_batches,
    make_pattern,
    open_results,
    parse_spec,
    run_campaign,
    simulate_batch,
)

N = 105
# Whole periods in the image (periodic, exactly shiftable) and in a 21-px subset (periods
# 7 and 21 px): the subset sum of a squared sinusoid is then independent of its phase.
KX, KY = 15, 5


def sinusoid() -> np.ndarray:
    """f = 128 + 50 sin(2 pi KX x / N) + 50 sin(2 pi KY y / N + 0.3), grey levels."""
    y, x = np.mgrid[0:N, 0:N].astype(float)
    return (
        128.0 + 50.0 * np.sin(2 * np.pi * KX * x / N) + 50.0 * np.sin(2 * np.pi * KY * y / N + 0.3)
    )


@pytest.fixture(scope="module")
def sinusoid_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("sin") / "sin.tif"
    # 16-bit, x200: quantisation changes SSSIG by ~1e-9 relative
    dicblur.save_image(path, sinusoid() * 200.0, bit_depth=16)
    return path


def sinusoid_spec(path, *, angle: float, noise: float) -> dicblur.CampaignSpec:
    return parse_spec(
        {
            "campaign": {"seed": 11},
            "pattern": [{"name": "sin", "path": str(path)}],
            "blur": {"lengths": [0.0, 1.0, 2.5], "angles": [angle], "substeps": 0},
            "noise": {"model": "per-exposure", "levels": [noise]},
            "dic": {"subsets": [21], "step": 7},
        }
    )


@pytest.mark.parametrize(("angle", "period"), [(0.0, N / KX), (90.0, N / KY)])
def test_sinusoid_matches_closed_forms(sinusoid_file, angle, period):
    # Continuous linear blur of length W multiplies a sinusoid of period p by
    # sinc(W / p) and shifts it by W / 2 (paper Algorithm 1, K -> infinity): the SSSIG
    # along the motion scales by sinc^2 exactly, subset by subset, and ZNSSD DIC, blind to
    # the amplitude change, must find W / 2 along the motion without bias (shifts stay
    # well below half the 7-px period: no periodic ambiguity). (Subsets hold
    # whole periods, so the blur's W / 2 shift does not change the subset sums.)
    spec = sinusoid_spec(sinusoid_file, angle=angle, noise=20.0)
    image = make_pattern(spec, spec.patterns[0])
    (batch,) = iter_batches(spec)
    out = simulate_batch(image, batch, spec)
    w = np.array(batch.blur)
    np.testing.assert_allclose(out["sssig"] / out["sssig_ref"], np.sinc(w / period) ** 2, rtol=1e-6)
    assert (out["converged_fraction"] == 1.0).all()
    assert np.all(np.abs(out["bias"]) < 0.01), out["bias"]
    # random error at W = 0 against the match-score model (eq. 2), noise in both images
    pred = math.sqrt(2.0) * 20.0 / math.sqrt(out["sssig_ref"][0])
    assert out["u_match_score"][0] == pytest.approx(pred, rel=1e-12)
    assert 0.75 < out["u_e"][0] / pred < 1.3, (out["u_e"][0], pred)
    assert np.all(out["noise_effective"] == 20.0)
    assert set(out) == set(VARIABLES)


def test_per_subframe_noise_is_the_papers(sinusoid_file):
    spec = parse_spec(
        {
            "campaign": {"seed": 11},
            "pattern": [{"name": "sin", "path": str(sinusoid_file)}],
            "blur": {"lengths": [1.0], "substeps": 100},
            "noise": {"model": "per-subframe", "levels": [400.0]},
            "dic": {"subsets": [21], "step": 6},
        }
    )
    (batch,) = iter_batches(spec)
    out = simulate_batch(make_pattern(spec, spec.patterns[0]), batch, spec)
    assert out["noise_effective"][0] == pytest.approx(400.0 / math.sqrt(101.0))


def _one_pattern_spec(
    *, speckle_size: float, softness: float, blur: dict, noise: float, **sections: object
) -> dicblur.CampaignSpec:
    """Two repetitions of one 64x64 speckle pattern (seed 3) at one noise level, subset 21
    every 10 px, sweeping ``blur``; ``sections`` added as they are."""
    return parse_spec(
        {
            "campaign": {"seed": 5, "repetitions": 2},
            "pattern": [
                {
                    "name": "p",
                    "generator": "speckle",
                    "shape": [64, 64],
                    "speckle_size": speckle_size,
                    "softness": softness,
                    "seed": 3,
                }
            ],
            "blur": blur,
            "noise": {"model": "per-exposure", "levels": [noise]},
            "dic": {"subsets": [21], "step": 10},
            **sections,
        }
    )


def small_real_spec(**blur: object) -> dicblur.CampaignSpec:
    return _one_pattern_spec(
        speckle_size=4.0,
        softness=0.7,
        blur={"lengths": [0.0, 1.5, 3.0], "angles": [0.0, 30.0], **blur},
        noise=2.0,
        run={"blur_chunk": 2},
    )


@pytest.mark.slow
@pytest.mark.numba_cache
def test_real_campaign_on_local_cluster_equals_serial(tmp_path):
    spec = small_real_spec()
    run_campaign(spec, tmp_path / "s.zarr", serial=True)
    summary = run_campaign(spec, tmp_path / "d.zarr", workers=2)
    assert summary.complete and summary.workers == 2
    a, b = open_results(tmp_path / "s.zarr"), open_results(tmp_path / "d.zarr")
    for name in VARIABLES:
        if name != "time_s":
            assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name
    assert np.isfinite(a["u_e"].values).all()
    assert (a["converged_fraction"].values > 0.9).all()
    # blur lowers the SSSIG along the motion and the contrast, never raises them
    s = a["sssig"].mean("rep").isel(pattern=0, subset=0, noise=0)
    assert (s.diff("blur") < 0).all()


def test_reflect_boundary_uses_trustworthy_points(tmp_path):
    img = dicblur.speckle_pattern((80, 80), speckle_size=4, softness=0.7, seed=9)
    path = tmp_path / "p.tif"
    dicblur.save_image(path, img * 200.0, bit_depth=16)
    spec = parse_spec(
        {
            "campaign": {"seed": 1},
            "pattern": [{"name": "p", "path": str(path)}],
            "blur": {"lengths": [0.0, 6.0], "boundary": "reflect"},
            "noise": {"model": "per-exposure", "levels": [100.0]},
            "dic": {"subsets": [21], "step": 10},
        }
    )
    (batch,) = iter_batches(spec)
    out = simulate_batch(make_pattern(spec, spec.patterns[0]), batch, spec)
    all_points = dicblur.subset_centres((80, 80), subset=21, step=10)
    # trustworthy region for a 6 px motion along +x (docs/blur.md): cols 6 + 2 guard px
    # .. 80 - 2, rows 2 .. 80 - 2; every pixel of a kept subset lies inside it
    h = 10
    r, c = all_points[:, 0], all_points[:, 1]
    keep = (r - h >= 2) & (r + h < 78) & (c - h >= 8) & (c + h < 78)
    assert out["n_points"][0] == keep.sum() < len(all_points)
    assert (out["converged_fraction"] == 1.0).all()
    assert abs(out["bias"][1]) < 0.05


def test_blurred_image_metrics_equal_the_metrics_module(sinusoid_file):
    # the task computes SSSIG and MIG from one gradient pass: compare with dicblur.metrics
    # on the blurred image rebuilt independently (continuous sinc blur of each sinusoid)
    spec = sinusoid_spec(sinusoid_file, angle=0.0, noise=20.0)
    image = make_pattern(spec, spec.patterns[0])
    (batch,) = iter_batches(spec)
    out = simulate_batch(image, batch, spec)
    w = batch.blur[2]
    blurred = dicblur.motion_blur(image, (0.0, w), substeps=None)
    assert out["mig"][2] == pytest.approx(dicblur.mig(blurred), rel=1e-12)
    assert out["contrast"][2] == pytest.approx(dicblur.michelson_contrast(blurred), rel=1e-12)
    pts = dicblur.subset_centres(image.shape, subset=21, step=7)
    assert out["sssig"][2] == pytest.approx(
        dicblur.sssig(blurred, subset=21, points=pts).mean(), rel=1e-12
    )
    assert out["mig_ref"][0] == pytest.approx(dicblur.mig(image), rel=1e-12)


def _smooth_spec(method: str) -> dicblur.CampaignSpec:
    blur = {"lengths": [0.0, 2.0, 4.0], "angles": [0.0, 30.0], "method": method}
    return _one_pattern_spec(
        speckle_size=8.0,
        softness=2.0,
        blur={**blur, "supersample": 4, "substeps": 64},
        noise=1.0,
    )


def test_rendered_method_agrees_with_the_transfer_method(tmp_path):
    # "rendered" draws the pattern 4x finer, moves it in whole fine pixels and bins (the
    # camera's pixel integration); "transfer" blurs the binned pattern by its transfer
    # function, which assumes a band-limited image. On a smooth, nearly band-limited
    # pattern the two must agree: the same SSSIG loss, the same W/2 displacement (the
    # rendered path's positions are rounded to the fine grid and the bias is measured
    # against those) and errors at the noise level. (On sharp 4 px speckles the SSSIG loss
    # differs by 4-14 % at W = 2-4 px: aliasing, which only the rendered method models.)
    run_campaign(_smooth_spec("rendered"), tmp_path / "r.zarr", serial=True)
    run_campaign(_smooth_spec("transfer"), tmp_path / "t.zarr", serial=True)
    r, t = open_results(tmp_path / "r.zarr"), open_results(tmp_path / "t.zarr")
    assert (r["converged_fraction"].values >= t["converged_fraction"].values - 0.1).all()
    # the rendered reference is the fine pattern binned 4x4 (17 % less SSSIG than the
    # pattern the transfer method blurs), so the relative losses agree to a few per cent
    # only (2-5 % at W = 2-4 px); a wrong blur length (W/2 or 2 W) would be 30-60 % off
    ratio = (r["sssig"] / r["sssig_ref"]) / (t["sssig"] / t["sssig_ref"])
    np.testing.assert_allclose(ratio.values, 1.0, rtol=0.06)
    assert np.abs(r["bias"].values).max() < 0.02
    assert np.abs(r["bias"].values).max() < 3 * np.abs(t["bias"].values).max() + 0.005
    # without blur the error is the noise's on nearly the same texture (with blur the
    # mismatch term of the two different reference images differs, up to 2x at W = 4 px)
    # (mean over angles and repetitions: each u_e is a std over 25 POIs, +-14 %)
    assert float(r["u_e"].isel(blur=0).mean()) == pytest.approx(
        float(t["u_e"].isel(blur=0).mean()), rel=0.3
    )
