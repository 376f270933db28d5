"""Bad arguments of the model API raise InputError naming the parameter and the fix."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur.errors import InputError

W = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
SSSIG = 4e5 / (1 + 0.3 * W**2)
U_E = np.sqrt(2 * 4 / SSSIG) + 0.002 * W**2


@pytest.mark.parametrize("subset", [20, 1, -21])
def test_fit_blur_model_refuses_a_subset_no_matcher_has(subset):
    # before: subset=20 was recorded in the model's validity domain as is
    with pytest.raises(InputError, match=rf"subset={subset}: the subset size must be an odd"):
        dicblur.fit_blur_model(W, SSSIG, U_E, noise_sigma=2.0, subset=subset)


@pytest.mark.filterwarnings("ignore:edge-driven range")
def test_fit_blur_model_keeps_an_odd_subset():
    m = dicblur.fit_blur_model(W, SSSIG, U_E, noise_sigma=2.0, subset=21.0)
    assert m.domain is not None and m.domain.subset == 21
