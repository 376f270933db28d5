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
        (errors.ConvergenceError, RuntimeError),
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
