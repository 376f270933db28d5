import pickle

import pytest

from dicblur import errors


@pytest.mark.parametrize(
    ("cls", "builtin"),
    [
        (errors.InputError, ValueError),
        (errors.ImageReadError, OSError),
        (errors.ConfigError, ValueError),
        (errors.FitError, RuntimeError),
        (errors.StoreError, RuntimeError),
    ],
)
def test_hierarchy_and_pickling(cls, builtin):
    exc = cls("subset=20: must be odd")
    assert isinstance(exc, errors.DicblurError)
    assert isinstance(exc, builtin)
    back = pickle.loads(pickle.dumps(exc))
    assert type(back) is cls
    assert str(back) == "subset=20: must be odd"


def test_the_dic_interpolant_raises_dicblur_errors_not_bare_builtins():
    import numpy as np

    from dicblur.dic.interpolation import bspline_coefficients

    img = np.zeros((16, 16))
    with pytest.raises(errors.InputError, match="order=4: the B-spline order must be 3 or 5"):
        bspline_coefficients(img, order=4)
    with pytest.raises(errors.InputError, match="out=None"):
        bspline_coefficients(img, out=np.empty((3, 3), np.float32))
