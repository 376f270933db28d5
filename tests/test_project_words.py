"""The tracked files speak of dicblur, not of how it was made.

A user reads README, docs, BENCHMARKS and CHANGELOG (and a contributor src, tests,
benchmarks, examples): words of the making (a numbered work period, "the lead merged", "four other
helpers", "this host was quiet") mean nothing to them. A measurement names its date, commit
and machine (CPU, cores, load) only. The scan runs over ``git ls-files`` and skips outside a
git checkout (an sdist, an installed copy).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("README.md", "BENCHMARKS.md", "CHANGELOG.md", "docs", "src", "tests", "benchmarks")
SCANNED += ("examples",)
TEXT = (".py", ".md", ".toml", ".json", ".txt", ".cfg", ".yml", ".yaml", ".js", ".html", ".csv")

# Words of the making, each with why it is one (case-insensitive).
FORBIDDEN = (
    # "session" in the sense of a period of work: a process's session (start_new_session,
    # "its own session" for a process group) and pytest's Session object are code.
    r"\bsessions?\b(?<!own session)(?<!new session)(?<!pytest\.Session)(?!\.items)(?!: pytest)",
    r"session[_-]?\d",  # session6, session_6 in file and tag names
    r"\b(other|four|five|six|\d+) helpers\b",  # helpers as the people building the project
    r"\bhelper (session|branch|work)",
    r"\(lead[,)]|\bthe lead (merged|ran|measured|checked)|\blead's\b",
    r"\bagents?\b",
    # a diary of machines and days
    r"\b(this|that|the slow|the quiet|a slower|a quiet|the same kind of) host\b",
    r"\bhost was (quiet|busy|slow)|\bquiet day\b|\bduring the day\b",
    r"\bon the (quiet|busy|slow) day\b",
)
# The word itself, split so that this file does not trip a plain text search for it.
S = "sess" + "ion"

PATTERN = re.compile("|".join(f"(?:{p})" for p in FORBIDDEN), re.IGNORECASE)


def tracked_files() -> list[Path]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: no tracked files to scan")
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--", *SCANNED],
            cwd=ROOT,
            capture_output=True,
            check=True,
            timeout=30,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        pytest.skip("git ls-files failed: not a usable git checkout")
    files = [ROOT / name for name in out.decode().split("\0") if name]
    return [f for f in files if f.suffix in TEXT and f.is_file()]


def offending_lines(text: str) -> list[tuple[int, str]]:
    """(line number, line) of every line that speaks of how the project is made."""
    return [(n, line) for n, line in enumerate(text.splitlines(), 1) if PATTERN.search(line)]


@pytest.mark.parametrize(
    "line",
    [
        S.capitalize() + " 6 (2026-12-02, merged main)",
        "python benchmarks/bench_startup.py --tag session6",
        "the machine was shared with four other helpers",
        "Fast-math flags as merged (lead, 2026-12-01)",
        f"the slow host of this {S}",
        "in the runs where the host was quiet",
        "an agent wrote this",
    ],
)
def test_the_scan_finds_words_of_the_making(line: str) -> None:
    assert offending_lines(line) == [(1, line)]


@pytest.mark.parametrize(
    "line",
    [
        "def pytest_collection_finish(session: pytest.Session) -> None:",
        "if any(m for m in session.items):",
        "subprocess.Popen(cmd, start_new_session=True)  # its own session: the process group",
        "from helpers.campaign import shift_task",
        "lead = r['c_static'] * blurs**2 / ue  # the leading term",
        "--scheduler tcp://HOST:PORT",
    ],
)
def test_the_scan_lets_code_words_pass(line: str) -> None:
    assert offending_lines(line) == []


def test_no_tracked_file_speaks_of_how_the_project_is_made() -> None:
    found = []
    for path in tracked_files():
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        if path.name == Path(__file__).name:  # this file names the words it looks for
            continue
        rel = path.relative_to(ROOT)
        found += [f"{rel}:{n}: {line.strip()[:120]}" for n, line in offending_lines(text)]
    assert not found, "words of the making (name date, commit, machine instead):\n" + "\n".join(
        found
    )
