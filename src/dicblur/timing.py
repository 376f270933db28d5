"""Wall time of the phases of a long run (the calibration's, the 1-D study's), for the
``timings`` their results carry: the lowest layer, so campaign and pulse share it."""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["lap_timer"]


def lap_timer(timings: dict[str, float]) -> Callable[[str], None]:
    """A ``lap(name)`` that sets ``timings[name]`` to the wall time, s, since the previous
    lap (the first: since this call)."""
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[name] = now - clock
        clock = now

    return lap
