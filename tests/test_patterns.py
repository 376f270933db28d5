import numpy as np
import pytest

from dicblur import InputError, gaussian_mask, paper_pattern4, speckle_pattern, speckle_size


def test_same_seed_same_bytes():
    a = speckle_pattern((128, 96), speckle_size=3, softness=0.7, seed=11)
    b = speckle_pattern((128, 96), speckle_size=3, softness=0.7, seed=11)
    c = speckle_pattern((128, 96), speckle_size=3, softness=0.7, seed=12)
    assert a.tobytes() == b.tobytes()
    assert a.tobytes() != c.tobytes()
    g = np.random.default_rng(5)
    assert speckle_pattern(64, seed=g).shape == (64, 64)


@pytest.mark.parametrize("density", [0.2, 0.5, 0.8])
def test_density_and_levels(density):
    img = speckle_pattern((200, 150), speckle_size=4, density=density, seed=1)
    assert set(np.unique(img)) <= {0.0, 255.0}
    assert abs(np.mean(img == 0.0) - density) < 1.0 / img.size + 1e-12


def test_contrast_and_levels():
    img = speckle_pattern(64, speckle_size=3, contrast=0.5, levels=(20, 220), seed=2)
    np.testing.assert_allclose(sorted(np.unique(img)), [70.0, 170.0])


@pytest.mark.parametrize("size", [2.5, 3, 4, 6, 8, 12])
@pytest.mark.parametrize("density", [0.35, 0.5, 0.65])
def test_speckle_size_within_15_percent(size, density):
    img = speckle_pattern(384, speckle_size=size, density=density, seed=7)
    measured = speckle_size(img)
    assert abs(measured / size - 1) < 0.15, measured


def test_softness_and_supersample_widen_but_keep_range():
    hard = speckle_pattern(256, speckle_size=5, seed=3)
    soft = speckle_pattern(256, speckle_size=5, softness=1.0, seed=3)
    ss = speckle_pattern(256, speckle_size=5, supersample=4, seed=3)
    assert speckle_size(soft) > speckle_size(hard)
    assert soft.min() >= 0 and soft.max() <= 255
    # Pixel integration keeps the black fraction as mean grey level.
    assert abs(ss.mean() - 127.5) < 0.5


def test_periodic_pattern_tiles_without_seam():
    img = speckle_pattern(128, speckle_size=6, softness=1.5, seed=4)
    # Across the seam the jump statistics equal those inside the image.
    seam = np.abs(img[:, 0] - img[:, -1]).mean()
    inside = np.abs(np.diff(img, axis=1)).mean()
    assert seam < 2.5 * inside


def test_gaussian_mask_matches_matlab_fspecial():
    # fspecial('gaussian', 4, 0.5), computed by hand: 1-D taps at +-0.5 and +-1.5 px.
    w_in, w_out = np.exp(-0.5), np.exp(-4.5)
    one_d = np.array([w_out, w_in, w_in, w_out]) / (2 * (w_in + w_out))
    np.testing.assert_allclose(gaussian_mask(4, 0.5), np.outer(one_d, one_d), rtol=1e-14)
    assert gaussian_mask(4, 0.5)[1, 1] == pytest.approx(0.24108, abs=1e-5)


def test_paper_pattern4_is_smoothed_binary_pattern():
    p4 = paper_pattern4((128, 128), seed=9)
    base = speckle_pattern((128, 128), speckle_size=4, seed=9)
    assert p4.min() >= 0 and p4.max() <= 255
    assert abs(p4.mean() - base.mean()) < 1e-6  # a normalised mask keeps the mean
    assert len(np.unique(p4)) > 10  # grey edges now
    # Direct convolution with the mask (circular) at one pixel.
    m = gaussian_mask(4, 0.5)
    r, c = 40, 50
    direct = sum(m[i, j] * base[(r - i) % 128, (c - j) % 128] for i in range(4) for j in range(4))
    assert p4[r, c] == pytest.approx(min(max(direct, 0), 255), abs=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"speckle_size": 0}, "speckle_size"),
        ({"speckle_size": 200}, "speckle_size"),
        ({"density": 1.0}, "density"),
        ({"density": float("nan")}, "density"),
        ({"softness": -1}, "softness"),
        ({"contrast": 1.5}, "contrast"),
        ({"supersample": 0}, "supersample"),
        ({"seed": "abc"}, "seed"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(InputError, match=match):
        speckle_pattern((64, 64), **kwargs)


def test_bad_shape():
    with pytest.raises(InputError, match="shape"):
        speckle_pattern((1, 64))
    with pytest.raises(InputError, match="shape"):
        speckle_pattern("big")
