"""Packages that are called as their entry point: ``dicblur.track(...)``,
``dicblur.strain(...)``."""

from __future__ import annotations

import sys
import types
from typing import Any

__all__ = ["make_callable"]


def make_callable(package: str, entry: str) -> None:
    """Make the module object of ``package`` (its ``__name__``) callable as its attribute
    ``entry``, looked up at each call.

    ``dicblur.<name>(...)`` then works whether the name resolves to the function (the lazy
    attribute of :mod:`dicblur`) or to the package (the import system sets an imported
    subpackage as its parent's attribute)."""

    class CallableModule(types.ModuleType):
        def __call__(self, *args: Any, **kwargs: Any) -> Any:
            return getattr(self, entry)(*args, **kwargs)

    sys.modules[package].__class__ = CallableModule
