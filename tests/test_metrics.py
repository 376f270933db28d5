import math

import numpy as np
import pytest

import dicblur
from dicblur import (
    InputError,
    estimate_noise,
    gradient_variance,
    michelson_contrast,
    mig,
    pattern_metrics,
    rms_contrast,
    speckle_pattern,
    sssig,
    subset_centres,
)

K = 4 * math.pi / 31
A = 50.0


def sine_image(rows=100, cols=124, axis=1):
    x = np.arange(cols if axis == 1 else rows, dtype=float)
    line = 100.0 + A * np.sin(K * x)
    return np.tile(line, (rows, 1)) if axis == 1 else np.tile(line[:, None], (1, cols))


def test_sssig_sine_closed_form():
    img = sine_image()
    sx = sssig(img, subset=31, step=5, direction="x")
    sy = sssig(img, subset=31, step=5, direction="y")
    # central difference of A sin(kx) is A sin(k) cos(kx); 31 px hold two full periods.
    expected = A**2 * math.sin(K) ** 2 * 31**2 / 2
    np.testing.assert_allclose(sx, expected, rtol=1e-12)
    np.testing.assert_allclose(sy, 0.0, atol=1e-9)


def test_sssig_direction_y_and_points():
    img = sine_image(rows=124, cols=60, axis=0)
    pts = np.array([[40, 20], [70, 30], [80, 25]])
    sy = sssig(img, subset=31, points=pts, direction="y")
    np.testing.assert_allclose(sy, A**2 * math.sin(K) ** 2 * 31**2 / 2, rtol=1e-12)
    assert sy.shape == (3,)


def test_sssig_matches_direct_sum_on_random_image():
    img = np.random.default_rng(0).normal(size=(40, 50))
    pts = np.array([[10, 12], [20, 30]])
    vals = sssig(img, subset=9, points=pts, direction="x")
    for (r, c), v in zip(pts, vals, strict=True):
        sub = img[r - 4 : r + 5, c - 5 : c + 6]
        gx = (sub[:, 2:] - sub[:, :-2]) / 2
        assert v == pytest.approx(np.sum(gx**2), rel=1e-12)


def test_mig_and_gradient_variance_sine():
    img = sine_image()
    x = np.arange(1, img.shape[1] - 1)
    g = A * math.sin(K) * np.cos(K * x)  # exact central difference on interior columns
    assert mig(img) == pytest.approx(np.mean(np.abs(g)), rel=1e-12)
    assert gradient_variance(img, direction="x") == pytest.approx(np.var(g), rel=1e-10)
    assert gradient_variance(img) == pytest.approx(np.var(np.abs(g)), rel=1e-10)


def test_linear_ramp_gradients_both_operators():
    rr, cc = np.mgrid[0:30, 0:40].astype(float)
    img = 3.0 * cc + 2.0 * rr
    for grad in ("central", "sobel"):
        assert mig(img, gradient=grad) == pytest.approx(math.hypot(3, 2), rel=1e-12)
        assert gradient_variance(img, gradient=grad) == pytest.approx(0.0, abs=1e-9)
        s = sssig(img, subset=11, step=7, gradient=grad)
        np.testing.assert_allclose(s, 9.0 * 121, rtol=1e-12)


def test_subset_centres_grid():
    c = subset_centres((100, 80), subset=21, step=10)
    assert c[0].tolist() == [11, 11]
    assert c[:, 0].max() + 10 <= 100 - 2 and c[:, 1].max() + 10 <= 80 - 2
    assert len(np.unique(c[:, 0])) * len(np.unique(c[:, 1])) == len(c)


def test_contrast_measures():
    img = np.where(np.arange(100)[None, :] % 2 == 0, 50.0, 150.0) * np.ones((10, 1))
    assert michelson_contrast(img, percentile=0) == pytest.approx(0.5)
    assert rms_contrast(img) == pytest.approx(50.0 / 100.0)


def test_estimate_noise_synthetic():
    rng = np.random.default_rng(3)
    base = speckle_pattern(256, speckle_size=4, seed=1)
    a = base + rng.normal(0, 1.5, base.shape)
    b = base + 4.0 + rng.normal(0, 1.5, base.shape)  # offset (flicker) removed
    assert estimate_noise(a, b) == pytest.approx(1.5, rel=0.02)


def test_estimate_noise_real_pair(real_data):
    folder = real_data / "dicchallenge1_sample3"
    a = dicblur.load_image(folder / "Sample3_Reference.tif")
    b = dicblur.load_image(folder / "Sample3-000_X0.00_Y0.00_N2_C0_R0.tif")
    assert estimate_noise(a, b) == pytest.approx(1.1, abs=0.1)


def test_pattern_metrics_consistency():
    img = speckle_pattern(256, speckle_size=4, softness=0.8, seed=5)
    pm = pattern_metrics(img, subset=31, noise_sigma=2.0)
    sx = sssig(img, subset=31, direction="x")
    assert pm.sssig_x_mean == pytest.approx(sx.mean())
    assert pm.match_score_x_mean == pytest.approx(np.mean(np.sqrt(8.0 / sx)))
    assert pm.pan_u == pytest.approx(math.sqrt(2) * 2.0 / (31 * pm.mig))
    assert pm.pan_sssig == pytest.approx(31**2 * pm.mig**2)
    assert pm.pan_over_match_score == pytest.approx(pm.pan_u / pm.match_score_x_mean)
    assert 4.0 < pm.speckle_size < 7.0
    d = pm.to_dict()
    assert d["shape"] == [256, 256] and d["noise_sigma"] == 2.0
    assert pattern_metrics(img, subset=31).pan_u is None


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: sssig(np.full((1, 1), 3.0), subset=3), "at least"),
        (lambda: sssig(np.zeros((20, 20)), subset=31), "subset=31"),
        (lambda: sssig(np.zeros((20, 20)), subset=10), "odd"),
        (lambda: sssig(np.zeros((20, 20)), subset=-5), "odd"),
        (lambda: sssig(np.zeros((20, 20)), subset=5, direction="z"), "direction"),
        (lambda: mig(np.zeros((20, 20)), gradient="prewitt"), "gradient"),
        (lambda: mig(np.full((20, 20), np.nan)), "NaN"),
        (lambda: mig(np.zeros(20)), "2-D"),
        (lambda: sssig(np.zeros((20, 20)), subset=5, points=[[1, 1]]), "leaves"),
        (lambda: estimate_noise(np.zeros((5, 5)), np.zeros((5, 6))), "shape"),
        (lambda: pattern_metrics(np.zeros((40, 40)), subset=5, noise_sigma=-1), "noise_sigma"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()
