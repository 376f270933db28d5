"""One way to spread work over threads of this process (the static prediction's chunks of
subsets, the track's post-processing): the lowest layer, so models and track share it."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

__all__ = ["each"]


def each(fn: Callable[[Any], Any], items: Iterable[Any], threads: int) -> None:
    """``fn(item)`` for every item, on ``threads`` threads (numpy and the nogil kernels
    release the GIL; each item must write only its own part of the outputs, so the result
    is the same on any number of threads). The first exception raised is re-raised."""
    items = list(items)
    if threads <= 1 or len(items) <= 1:
        for it in items:
            fn(it)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=min(threads, len(items))) as pool:
        for _ in pool.map(fn, items):
            pass
