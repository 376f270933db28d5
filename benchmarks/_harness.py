"""Shared harness of the benchmark scripts: provenance of a run and where it is written.

Every result file records the same block (:func:`provenance`): the git commit (and whether
the tree had uncommitted changes), the dicblur version, the machine (CPU model and count),
the thread settings and the load average at the start and the end of the run (a number
without its load is not comparable). ``python -m benchmarks.report`` turns the result
files into BENCHMARKS.md. Use::

    from _harness import Run

    run = Run("dic")                # records the start (load, time)
    ...                             # measure
    run.write({"cases": rows})      # benchmarks/results/dic.json with a "provenance" block

Scripts run as ``python benchmarks/bench_x.py``, so this module is imported by its bare name.
A benchmark that measures what a test checks imports the test's computation from
``tests/helpers`` (one function for both) after :func:`use_tests_dir`.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
TESTS = ROOT / "tests"


def use_tests_dir() -> None:
    """Put the repository's ``tests/`` on ``sys.path`` (as pytest does), so that a script
    imports the synthetic data and computations the tests share (``helpers.models``, ...)."""
    if str(TESTS) not in sys.path:
        sys.path.insert(0, str(TESTS))


def load_average() -> list[float] | None:
    """1, 5 and 15 min load averages, or None where the OS has none."""
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:  # pragma: no cover - Windows
        return None


def load_1min() -> float:
    """The 1 min load average, NaN where the OS has none."""
    avg = load_average()
    return float("nan") if avg is None else avg[0]


def git_commit() -> dict[str, Any]:
    """The checkout's commit and whether it had uncommitted changes (None outside git)."""

    def git(*args: str) -> str | None:
        try:
            return subprocess.run(
                ["git", *args], cwd=ROOT, capture_output=True, text=True, check=True, timeout=10
            ).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return None

    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": git("rev-parse", "HEAD"), "dirty": None if status is None else bool(status)}


def dicblur_version() -> str | None:
    """The version of the dicblur imported (its literal, not installed metadata that an
    editable install leaves stale), or None when it cannot be imported."""
    try:
        from dicblur._version import __version__

        return __version__
    except Exception:  # pragma: no cover - not importable
        return None


def cpu_model() -> str | None:
    """The CPU's model name (Linux ``/proc/cpuinfo``), or None where it cannot be read."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def machine() -> dict[str, Any]:
    """Platform, CPU model and count, Python and the thread settings that change timings."""
    return {
        "platform": platform.platform(),
        "cpu": cpu_model(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "threads": {
            k: os.environ.get(k)
            for k in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")
        },
    }


def provenance(start_load: list[float] | None = None) -> dict[str, Any]:
    """The provenance block every result file carries."""
    return {
        **git_commit(),
        "dicblur_version": dicblur_version(),
        "machine": machine(),
        "load_start": start_load,
        "load_end": load_average(),
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "argv": sys.argv,
    }


class Run:
    """One benchmark run: remembers the start load; writes the result with its provenance."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.load_start = load_average()
        self.t0 = time.perf_counter()

    def record(self, result: dict[str, Any]) -> dict[str, Any]:
        """``result`` plus the ``provenance`` block and the run's wall time."""
        return {
            **result,
            "provenance": provenance(self.load_start),
            "run_wall_s": round(time.perf_counter() - self.t0, 3),
        }

    def write(self, result: dict[str, Any], path: Path | str | None = None) -> Path:
        """Write ``result`` (with provenance) as JSON; default ``results/<name>.json``."""
        out = Path(path) if path is not None else RESULTS / f"{self.name}.json"
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(self.record(result), indent=2, default=str) + "\n")
        return out
