"""dicblur.checks: the one home of the input checks (issue 16), shared by the Python API
(InputError) and the campaign spec (ConfigError, named by the TOML key)."""

from __future__ import annotations

import numpy as np
import pytest

from dicblur import checks
from dicblur.campaign.spec import parse_spec
from dicblur.errors import ConfigError, InputError


def spec(**dic):
    return {
        "campaign": {"seed": 1},
        "pattern": [{"name": "p", "generator": "paper4", "shape": [64, 64]}],
        "blur": {"lengths": [0.0, 1.0]},
        "noise": {"levels": [2.0]},
        "dic": {"subsets": [21], **dic},
    }


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("tolerance", "1e-4", "dic.tolerance='1e-4': expected a number"),
        ("tolerance", True, "dic.tolerance=True: expected a number, not a bool"),
        ("tolerance", float("nan"), "dic.tolerance=nan: must be finite (not NaN or infinite)"),
        ("step", 2.5, "dic.step=2.5: expected an integer >= 1"),
        ("step", 0, "dic.step=0: must be an integer >= 1"),
        ("shape", "rigid", "dic.shape='rigid': unknown option; choose one of 'translation'"),
    ],
)
def test_the_spec_raises_the_shared_checks_as_config_errors(key, value, message):
    with pytest.raises(ConfigError) as info:
        parse_spec(spec(**{key: value}))
    assert str(info.value).startswith(message)


def test_one_checker_serves_the_api_and_the_spec():
    # the API converts a number given as text; the spec (parsed TOML) takes numbers only
    assert checks.check_finite_number("3", "x") == 3.0
    with pytest.raises(ConfigError, match="x='3': expected a number"):
        checks.check_finite_number("3", "x", strict=True, error=ConfigError)
    with pytest.raises(InputError, match="expected a real number"):
        checks.check_finite_number("three", "x")
    assert checks.check_integer(np.int64(4), "n", minimum=1) == 4
    assert checks.check_integer(4.0, "n", minimum=1) == 4
    with pytest.raises(InputError, match=r"n=0: must be an integer >= 1"):
        checks.check_integer(0, "n", minimum=1)
    with pytest.raises(ConfigError, match="unknown option; choose one of 'a', 'b'"):
        checks.check_choice("c", "k", ("a", "b"), error=ConfigError)
    err = checks.bad_value("k", np.arange(3), "why", error=ConfigError)
    assert isinstance(err, ConfigError)
    assert str(err) == "k=array(shape=(3,), dtype=int64): why"


def test_the_model_fit_and_subpixel_checks_live_in_checks():
    with pytest.raises(InputError, match="strictly increasing"):
        checks.as_blur([1.0, 0.5])
    with pytest.raises(InputError, match=r"u_e: value -1.0 at index 1 is <= 0"):
        checks.as_positive([1.0, -1.0], "u_e", 2)
    with pytest.raises(InputError, match=r"subpixel=1.5"):
        checks.check_subpixel(1.5)
    assert checks.check_subpixel(0.25) == 0.25
