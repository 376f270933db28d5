"""The architecture contracts of docs/architecture.md (issue 16).

The layers, "only report draws", "only campaign uses dask" and "no import cycle" are
import-linter contracts in pyproject.toml; this runs them on the source tree, and runs them
again on copies with one violation planted, so a contract that checks nothing fails here.
"No private name imported across modules" is checked from the syntax trees.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "dicblur"

# Private names still imported across modules, each with its reason (none left: keep it so).
PRIVATE_ALLOWED: set[tuple[str, str]] = set()


def lint(src_parent: Path | None = None) -> subprocess.CompletedProcess[str]:
    """``lint-imports`` with the repository's contracts, on ``src_parent/dicblur``."""
    env = dict(os.environ)
    if src_parent is not None:
        env["PYTHONPATH"] = str(src_parent)
    code = (
        "import sys; from importlinter.cli import lint_imports; "
        f"sys.exit(lint_imports(config_filename={str(ROOT / 'pyproject.toml')!r}, "
        "no_cache=True, no_logo=True))"
    )
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=300
    )


def test_import_contracts_hold():
    proc = lint()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "0 broken" in proc.stdout


@pytest.mark.parametrize(
    ("module", "line", "broken"),
    [
        ("dic/status.py", "import matplotlib.figure", "only report draws"),
        ("models/units.py", "import dask", "only campaign uses dask"),
        ("dic/status.py", "from ..models import units", "dependencies point down"),
        ("pulse/records.py", "from . import study", "no import cycle"),
    ],
)
def test_a_planted_violation_breaks_its_contract(tmp_path, module, line, broken):
    shutil.copytree(SRC, tmp_path / "dicblur", ignore=shutil.ignore_patterns("__pycache__"))
    target = tmp_path / "dicblur" / module
    target.write_text(target.read_text() + f"\n{line}  # planted by the test\n")
    proc = lint(tmp_path)
    assert proc.returncode == 1, proc.stdout
    assert f"{broken}" in proc.stdout and "BROKEN" in proc.stdout


def private_imports(path: Path) -> list[tuple[str, str]]:
    """(module, name) of each ``from dicblur-module import _private`` in ``path``."""
    rel = path.relative_to(SRC).as_posix()
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module != "__future__":
            internal = node.level > 0 or (node.module or "").startswith("dicblur")
            for alias in node.names:
                name = alias.name
                if internal and name.startswith("_") and not name.startswith("__"):
                    found.append((rel, name))
    return found


def test_no_private_name_is_imported_across_modules():
    found = {hit for p in sorted(SRC.rglob("*.py")) for hit in private_imports(p)}
    assert found - PRIVATE_ALLOWED == set()
    # the allowances are live (an entry that no longer matches must be removed)
    assert PRIVATE_ALLOWED <= found


def test_the_library_never_picks_a_matplotlib_backend_or_uses_pyplot():
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                assert not any(a.name == "matplotlib.pyplot" for a in node.names), path
            elif isinstance(node, ast.ImportFrom):
                assert node.module != "matplotlib.pyplot", path
                assert not (
                    node.module == "matplotlib" and any(a.name == "pyplot" for a in node.names)
                ), path
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                owner = node.func.value
                assert not (
                    node.func.attr == "use"
                    and isinstance(owner, ast.Name)
                    and owner.id == "matplotlib"
                ), f"{path}:{node.lineno}"
