import numpy as np
import pytest

from dicblur import InputError, pattern_metrics, save_image, speckle_pattern
from dicblur.report.study import (
    central_crop,
    emulated_camera_pattern3,
    load_user_pattern,
    numerical_pattern4,
    stand_in_pattern1,
    stand_in_pattern2,
)


def test_central_crop_states_window():
    img = np.arange(20 * 30, dtype=float).reshape(20, 30)
    crop, text = central_crop(img, 10)
    np.testing.assert_array_equal(crop, img[5:15, 10:20])
    assert text == "rows 5:15, cols 10:20"
    with pytest.raises(InputError, match="smaller"):
        central_crop(img, 25)


def test_user_pattern_provenance(tmp_path):
    save_image(tmp_path / "u.tif", speckle_pattern((80, 100), speckle_size=3, seed=1))
    p = load_user_pattern("p2", "#2 user", tmp_path / "u.tif", 64)
    assert p.image.shape == (64, 64) and not p.synthetic
    assert len(p.sha256) == 64 and "rows 8:72, cols 18:82" in p.source


def test_stand_ins_have_the_character_of_the_samples():
    m1 = pattern_metrics(stand_in_pattern1(256, 1), subset=31)
    m2 = pattern_metrics(stand_in_pattern2(256, 2), subset=31)
    # #1: fine, soft, low contrast; #2: larger speckles, higher contrast.
    assert m1.speckle_size < m2.speckle_size
    assert m1.rms_contrast < 0.35 < m2.rms_contrast
    assert np.array_equal(stand_in_pattern1(64, 5), stand_in_pattern1(64, 5))


def test_pattern3_is_a_noisy_camera_image_of_the_pattern4_recipe():
    p3 = emulated_camera_pattern3(128, 7)
    p4 = numerical_pattern4(128, 7)
    assert p3.key == "p3" and p4.key == "p4"
    assert np.all(p3.image == np.round(p3.image)) and 0 <= p3.image.min() <= p3.image.max() <= 255
    assert np.array_equal(p3.image, emulated_camera_pattern3(128, 7).image)
    # Same speckle recipe: similar speckle size; softer and lower contrast than #4.
    m3 = pattern_metrics(p3.image, subset=31)
    m4 = pattern_metrics(p4.image, subset=31)
    assert abs(m3.speckle_size / m4.speckle_size - 1) < 0.3
    assert m3.mig < m4.mig
