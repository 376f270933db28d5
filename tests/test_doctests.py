"""The docstring examples run and print what they show (the runnable, fast ones)."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "dicblur.blur.synthesis",
    "dicblur.blur.units",
    "dicblur.patterns",
    "dicblur.metrics",
    "dicblur.dic.correlator",
    "dicblur.dic.state",
    "dicblur.dic.settings",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(
        module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False
    )
    assert result.attempted > 0, f"{name} has no examples to run"
    assert result.failed == 0
