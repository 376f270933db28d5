"""Is the DIC engine compiled yet? A cheap look at numba's on-disk cache.

The kernels of :mod:`dicblur.dic.kernels` are compiled by numba on their first call
(``cache=True``: once per installation and kernel source, then loaded from disk in about a
second). The first run after an install therefore spends about 20 s compiling; the CLI
says so before it starts (:func:`kernels_cached`). Only the kernels of the requested shape
function are compiled: numba compiles lazily, per kernel and argument types.
"""

from __future__ import annotations

from typing import Literal

__all__ = ["COMPILE_NOTICE", "compile_kernels", "kernels_cached"]

#: The line the CLI prints on stderr before a cold compile.
COMPILE_NOTICE = "compiling the DIC kernels, first run only (~20 s)"

# The entry points a correlation calls, per shape function (their callees are inlined or
# cached with them).
_ENTRY = {
    "translation": (
        ("translation", "icgn_translation"),
        ("translation", "pack_reference"),
        ("prefilter", "_rows_block"),
        ("prefilter", "_columns_block"),
        ("prefilter", "_margin"),
    ),
    "affine": (
        ("affine", "_affine_points"),
        ("prefilter", "_rows_block"),
        ("prefilter", "_columns_block"),
        ("prefilter", "_margin"),
    ),
}


def kernels_cached(shape: Literal["affine", "translation"] = "affine") -> bool:
    """True when numba's cache holds compiled code of this kernel source for every entry
    point a correlation with ``shape`` calls.

    Reads only the cache index files (a few ms; no compilation). Stale entries (another
    kernel source) do not count. If the cache cannot be inspected (another numba layout)
    the answer is True: the notice is then left out rather than printed wrongly.
    """
    import importlib

    try:
        for module, name in _ENTRY[shape]:
            kernel = getattr(importlib.import_module(f"{__package__}.kernels.{module}"), name)
            cache = kernel._cache
            if not cache._cache_file._load_index():  # {signature key: file}; {} when cold
                return False
    except Exception:  # numba internals differ: do not guess
        return True
    return True


_COMPILE = """
import numpy as np
from dicblur.dic import Correlator
rng = np.random.default_rng(0)
img = rng.normal(128.0, 30.0, (64, 64))
cur = np.roll(img, 1, axis=1)
for shape in {shapes!r}:
    c = Correlator(img, subset=11, step=12, shape=shape)
    c.warmup()
    c.correlate(cur)  # the FFT-CC initial guess and the retry paths too
"""


def compile_kernels(
    shapes: tuple[str, ...] = ("translation", "affine"), *, timeout: float = 1800.0
) -> bool:
    """Compile the DIC kernels of ``shapes`` into numba's cache in a subprocess, if the
    cache is cold; return whether it compiled.

    Afterwards this process and every worker load the same cached machine code. The
    kernels reassociate their reductions (fast-math ``reassoc``, see ``kernels``), and a
    kernel compiled in the process that runs it can differ in the last bits from one loaded
    from the cache: a campaign resumed on an empty cache would then not be bit-identical.
    """
    import subprocess
    import sys

    cold = tuple(s for s in shapes if not kernels_cached(s))  # type: ignore[arg-type]
    if not cold:
        return False
    subprocess.run(
        [sys.executable, "-c", _COMPILE.format(shapes=cold)],
        check=True,
        timeout=timeout,
        capture_output=True,
    )
    return True
