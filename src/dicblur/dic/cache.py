"""Is the DIC engine compiled yet? A cheap look at numba's on-disk cache.

The kernels of :mod:`dicblur.dic.kernels` are compiled by numba on their first call
(``cache=True``: once per installation and kernel source, then loaded from disk in about a
second). The first run after an install therefore spends 10-15 s compiling on a quiet
2-core machine (``dicblur track`` about 15 s more: its own compiled passes); the CLI says
so before it starts (:func:`kernels_cached`). Only the kernels of the requested shape
function are compiled: numba compiles lazily, per kernel and argument types; with a second
core the IC-GN kernel is compiled by a child process meanwhile
(:func:`compile_in_background`).
"""

from __future__ import annotations

import threading
from typing import Any, Literal

__all__ = [
    "COMPILE_NOTICE",
    "compile_in_background",
    "compile_kernels",
    "kernels_cached",
    "wait_for_background",
]

#: The line the CLI prints on stderr before a cold compile.
COMPILE_NOTICE = "compiling the kernels, first run only (~10-30 s)"

# The entry points a correlation calls, per shape function (their callees are inlined or
# cached with them).
_ENTRY = {
    "translation": (
        ("translation", "icgn_translation"),
        ("translation", "pack_reference"),
        ("prefilter", "_rows_block"),
        ("prefilter", "_columns_block"),
    ),
    "affine": (
        ("affine", "_affine_points"),
        ("prefilter", "_rows_block"),
        ("prefilter", "_columns_block"),
    ),
}


def kernels_cached(shape: Literal["affine", "translation"] = "affine") -> bool:
    """True when numba's cache holds compiled code of this kernel source for every entry
    point a correlation with ``shape`` calls.

    Reads only the cache index files (a few ms; no compilation). Stale entries (another
    kernel source) do not count. If the cache cannot be inspected (another numba layout)
    the answer is True: the notice is then left out rather than printed wrongly.
    """
    return _cached(_ENTRY[shape])


def _cached(entries: tuple[tuple[str, str], ...]) -> bool:
    """Whether numba's cache holds code of every kernel ``(module, name)`` listed."""
    import importlib

    try:
        for module, name in entries:
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


# ------------------------------------------------------------------ background compile
# On a cold cache the IC-GN kernel (about half of the first-run compile) is compiled by a
# child process while this one compiles the prefilter and prepares the reference; this
# process then loads the IC-GN kernel from numba's cache (issue 16: first-run wall time).
_CHILD = "from dicblur.dic.kernels.{module} import compile_icgn; compile_icgn()"
_BACKGROUND: dict[str, Any] = {}  # shape -> subprocess.Popen, until waited for
_CHECKED: set[str] = set()
_LOCK = threading.Lock()
#: What the background compiles did in this process (benchmarks/bench_startup.py reads it):
#: per child ``shape``, this process's CPU time (s) at its start and at the wait, the
#: child's CPU time and whether it compiled.
BACKGROUND_LOG: list[dict[str, Any]] = []


def _icgn_dispatcher(shape: str) -> Any:
    import importlib

    module, name = _ENTRY[shape][0]
    return getattr(importlib.import_module(f"{__package__}.kernels.{module}"), name)


def compile_in_background(shape: Literal["affine", "translation"] = "affine") -> bool:
    """Start compiling the IC-GN kernel of ``shape`` into numba's cache in a child
    process, when the cache is cold and this process has not compiled it; return whether
    a child was started.

    Called as early as possible (the CLI, :class:`~dicblur.dic.Correlator`); the kernel's
    first call waits for the child (:func:`wait_for_background`) and then loads the
    kernel from the cache. Nothing is started on a single core, when the cache cannot be
    inspected, or with ``DICBLUR_COMPILE_CHILD=0`` in the environment. The child writes
    other files of numba's cache than this process (other kernels), and numba writes each
    file atomically (a temporary file renamed): no race; if the child fails, this process
    compiles the kernel itself.
    """
    import os

    with _LOCK:  # Correlators made in several threads at once: one check, one child
        if shape in _CHECKED or os.environ.get("DICBLUR_COMPILE_CHILD", "1") == "0":
            return False
        _CHECKED.add(shape)  # once per process: the look at the cache costs a few ms
        return _start_child(shape)


def _start_child(shape: str) -> bool:
    import os
    import subprocess
    import sys

    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    if cores < 2 or _cached(_ENTRY[shape][:1]):
        return False
    if _icgn_dispatcher(shape).overloads:  # already compiled (or loaded) here
        return False
    module = _ENTRY[shape][0][0]
    import time

    BACKGROUND_LOG.append({"shape": shape, "start_cpu_s": time.process_time()})
    # the child imports this very dicblur (the cache is per source file)
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    path = os.environ.get("PYTHONPATH")
    env = dict(os.environ, PYTHONPATH=root + (os.pathsep + path if path else ""))
    try:
        _BACKGROUND[shape] = subprocess.Popen(
            [sys.executable, "-c", _CHILD.format(module=module)],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except OSError:
        return False
    if len(_BACKGROUND) == 1:
        import atexit

        atexit.register(_stop_background)
    return True


def wait_for_background(shape: str, *, timeout: float = 900.0) -> bool:
    """Wait for the child started by :func:`compile_in_background` for ``shape`` (if any)
    and return whether it compiled the kernel into the cache. A child that has not
    finished after ``timeout`` s is killed (this process then compiles the kernel)."""
    import subprocess

    proc = _BACKGROUND.pop(shape, None)
    if proc is None:
        return False
    import resource
    import time

    log: dict[str, Any] = next((r for r in reversed(BACKGROUND_LOG) if r["shape"] == shape), {})
    log["wait_cpu_s"] = time.process_time()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        ok = proc.wait(timeout=timeout) == 0
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        ok = False
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    log["child_cpu_s"] = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    log["compiled"] = ok
    return ok


def _stop_background() -> None:
    """At exit: end the children not waited for (a Correlator that never correlated)."""
    for shape in list(_BACKGROUND):
        proc = _BACKGROUND.pop(shape)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
