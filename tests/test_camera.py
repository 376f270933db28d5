"""Tests of dicblur.camera: noise statistics against closed forms, determinism, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from dicblur import Camera, InputError, add_gaussian_noise


def test_per_subframe_noise_std_is_sigma_over_sqrt_k_plus_1() -> None:
    img = np.full((1024, 1024), 100.0)
    out = add_gaussian_noise(img, 2.0, model="per-subframe", substeps=100, seed=1)
    assert np.std(out - img) == pytest.approx(2.0 / math.sqrt(101), rel=0.02)
    assert abs(np.mean(out - img)) < 0.01


def test_per_subframe_equals_literal_average_of_noisy_subframes() -> None:
    # Algorithm 1, step 9: noise of std sigma on each of K + 1 sub-frames, then averaged.
    rng = np.random.default_rng(5)
    k, sigma = 100, 2.0
    literal = np.mean([rng.normal(0.0, sigma, (256, 256)) for _ in range(k + 1)], axis=0)
    single = add_gaussian_noise(
        np.zeros((256, 256)), sigma, model="per-subframe", substeps=k, seed=6
    )
    assert np.std(literal) == pytest.approx(np.std(single), rel=0.03)


def test_per_exposure_noise_std_is_sigma() -> None:
    out = add_gaussian_noise(np.zeros((512, 512)), 3.0, seed=2)
    assert np.std(out) == pytest.approx(3.0, rel=0.01)


def test_noise_same_seed_same_bytes() -> None:
    img = np.zeros((32, 32))
    a = add_gaussian_noise(img, 1.0, seed=3)
    b = add_gaussian_noise(img, 1.0, rng=np.random.default_rng(3))
    assert a.tobytes() == b.tobytes()
    assert a.tobytes() != add_gaussian_noise(img, 1.0, seed=4).tobytes()


@pytest.mark.parametrize("scale", [1.0, 2.5])
def test_poisson_gaussian_variance(scale: float) -> None:
    cam = Camera(read_noise=1.5, gain=0.2, exposure_scale=scale, bit_depth=None)
    for level in (10.0, 60.0, 180.0):
        out = cam.capture(np.full((400, 400), level), seed=int(level))
        signal = level * scale
        assert np.mean(out) == pytest.approx(signal, rel=0.005)
        assert np.var(out) == pytest.approx(0.2 * signal + 1.5**2, rel=0.02)
        assert float(cam.variance(level)) == pytest.approx(0.2 * signal + 1.5**2)


def test_full_well_sets_gain_and_saturates() -> None:
    cam = Camera(full_well=1000.0, bit_depth=8)
    assert cam.effective_gain == pytest.approx(255.0 / 1000.0)
    out = cam.capture(np.array([[0.0, 100.0], [400.0, 1e4]]), seed=1)
    assert out[0, 0] == 0.0
    assert out[1, 0] == 255.0 and out[1, 1] == 255.0


def test_full_well_clips_electrons_without_bit_depth() -> None:
    cam = Camera(gain=1.0, full_well=50.0, bit_depth=None)
    out = cam.capture(np.full((50, 50), 500.0), seed=2)
    assert out.max() == 50.0


def test_gaussian_camera_quantises_and_clips() -> None:
    cam = Camera(read_noise=2.0, bit_depth=8)
    out = cam.capture(np.full((256, 256), 128.0), seed=3)
    assert np.array_equal(out, np.rint(out))
    assert np.std(out) == pytest.approx(math.sqrt(4.0 + 1.0 / 12.0), rel=0.03)
    sat = cam.capture(np.array([[-50.0, 400.0]]), seed=3)
    assert sat[0, 0] == 0.0 and sat[0, 1] == 255.0


def test_camera_same_seed_same_bytes() -> None:
    cam = Camera(read_noise=1.0, full_well=2000.0, bit_depth=12)
    img = np.linspace(0, 4000, 64 * 64).reshape(64, 64)
    assert cam.capture(img, seed=9).tobytes() == cam.capture(img, seed=9).tobytes()


def test_camera_is_frozen() -> None:
    cam = Camera()
    with pytest.raises(AttributeError):
        cam.read_noise = 3.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"read_noise": -1.0}, "read_noise"),
        ({"gain": 0.0}, "gain"),
        ({"full_well": float("nan")}, "full_well"),
        ({"bit_depth": 0}, "bit_depth"),
        ({"bit_depth": 8.0}, "bit_depth"),
        ({"exposure_scale": 0.0}, "exposure_scale"),
        ({"full_well": 100.0, "bit_depth": None}, "gain"),
    ],
)
def test_bad_camera(kwargs, match) -> None:
    with pytest.raises(InputError, match=match):
        Camera(**kwargs)


def test_bad_noise_arguments() -> None:
    img = np.zeros((8, 8))
    with pytest.raises(InputError, match="sigma"):
        add_gaussian_noise(img, -1.0)
    with pytest.raises(InputError, match="model"):
        add_gaussian_noise(img, 1.0, model="per-frame")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="substeps"):
        add_gaussian_noise(img, 1.0, model="per-subframe", substeps=-1)
    with pytest.raises(InputError, match="not both"):
        add_gaussian_noise(img, 1.0, rng=np.random.default_rng(1), seed=1)
    with pytest.raises(InputError, match="NaN"):
        add_gaussian_noise(np.full((4, 4), np.nan), 1.0)
    with pytest.raises(InputError, match="2-D"):
        Camera().capture(np.zeros(5))


def test_capture_matches_variance_model_on_blurred_pattern() -> None:
    # Poisson-Gaussian noise on a non-flat image: the standardised residual has unit
    # variance when divided by the model's per-pixel std.
    rng = np.random.default_rng(4)
    img = rng.uniform(20, 200, (300, 300))
    cam = Camera(read_noise=2.0, gain=0.5, bit_depth=None)
    out = cam.capture(img, seed=11)
    z = (out - img) / np.sqrt(cam.variance(img))
    assert np.var(z) == pytest.approx(1.0, rel=0.02)
    assert_allclose(np.mean(z), 0.0, atol=0.01)
