"""Is the DIC engine compiled yet? A cheap look at numba's on-disk cache.

The kernels of :mod:`dicblur.dic.kernels` are compiled by numba on their first call
(``cache=True``: once per installation and kernel source, then loaded from disk in about a
second). The first run after an install therefore spends 20 s or more compiling; the CLI
says so before it starts (:func:`kernels_cached`). Only the kernels of the requested shape
function are compiled: numba compiles lazily, per kernel and argument types.
"""

from __future__ import annotations

from typing import Literal

__all__ = ["COMPILE_NOTICE", "kernels_cached"]

#: The line the CLI prints on stderr before a cold compile.
COMPILE_NOTICE = "compiling the DIC kernels, first run only (~20 s)"

# The entry points a correlation calls, per shape function (their callees are inlined or
# cached with them).
_ENTRY = {
    "translation": ("icgn_translation", "pack_reference", "_filter_axis0", "_filter_axis1"),
    "affine": ("icgn_affine", "_filter_axis0", "_filter_axis1"),
}


def kernels_cached(shape: Literal["affine", "translation"] = "affine") -> bool:
    """True when numba's cache holds compiled code of this kernel source for every entry
    point a correlation with ``shape`` calls.

    Reads only the cache index files (a few ms; no compilation). Stale entries (another
    kernel source) do not count. If the cache cannot be inspected (another numba layout)
    the answer is True: the notice is then left out rather than printed wrongly.
    """
    from . import kernels

    try:
        for name in _ENTRY[shape]:
            cache = getattr(kernels, name)._cache
            if not cache._cache_file._load_index():  # {signature key: file}; {} when cold
                return False
    except Exception:  # numba internals differ: do not guess
        return True
    return True
