"""Exception hierarchy of dicblur.

Every error raised on purpose by dicblur derives from :class:`DicblurError`. Classes also
inherit the matching builtin (``ValueError``, ``OSError``, ``RuntimeError``) so that
callers who catch builtins keep working (the pattern of pint's errors). All classes take a
single message argument, so they pickle and cross Dask worker processes intact.

Messages name the parameter, the offending value and the fix, e.g.::

    subset=20: the subset size must be an odd integer >= 5 (use 19 or 21)
"""

from __future__ import annotations

__all__ = [
    "ConfigError",
    "DicblurError",
    "FitError",
    "ImageReadError",
    "InputError",
    "StoreError",
]


class DicblurError(Exception):
    """Base class of every error that dicblur raises deliberately."""


class InputError(DicblurError, ValueError):
    """An argument (array, number, option name) is invalid."""


class ImageReadError(DicblurError, OSError):
    """An image file is missing, empty, truncated or not an image."""


class ConfigError(DicblurError, ValueError):
    """A configuration file (campaign spec, model JSON) is malformed."""


class FitError(DicblurError, RuntimeError):
    """A model could not be fitted to the data given."""


class StoreError(DicblurError, RuntimeError):
    """A results store is corrupt or does not match the requested campaign."""
