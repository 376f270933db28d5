"""Numba's cache of the kernels is keyed by all the package's sources: a change to an
inlined helper in another file must not leave its callers' stale machine code in use."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from dicblur.dic.kernels.source_key import source_key

CALLER = """
import numba as nb
from .helper import h

@nb.njit(cache=True)
def f():
    return h()
"""

INIT = """
from pathlib import Path
from dicblur.dic.kernels.source_key import keyed_cache
with keyed_cache(Path(__file__).parent):
    from .caller import f
"""


def test_the_key_follows_every_source_file_and_nothing_else(tmp_path: Path) -> None:
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "b.py").write_text("y = 2\n")
    key = source_key(tmp_path)
    (tmp_path / "notes.txt").write_text("not a source")
    assert source_key(tmp_path) == key
    (tmp_path / "b.py").write_text("y = 3\n")
    assert source_key(tmp_path) != key


def _run(root: Path, env: dict[str, str]) -> list[str]:
    code = (
        "import numba.core.config as c, pkg; "
        "print(pkg.f()); print(pkg.f._cache._cache_path); print(repr(c.CACHE_DIR))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


@pytest.mark.slow
@pytest.mark.parametrize("user_dir", [False, True])
def test_a_changed_helper_recompiles_its_caller(tmp_path: Path, user_dir: bool) -> None:
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(textwrap.dedent(INIT))
    (pkg / "caller.py").write_text(textwrap.dedent(CALLER))
    helper = "import numba as nb\n\n@nb.njit(cache=True)\ndef h():\n    return {}\n"
    (pkg / "helper.py").write_text(helper.format(1))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), *sys.path]))
    env.pop("NUMBA_CACHE_DIR", None)
    if user_dir:
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "user-cache")

    value, path, setting = _run(tmp_path, env)
    assert value == "1"
    parent = tmp_path / "user-cache" / "dicblur" if user_dir else pkg / "__pycache__"
    assert Path(path).is_relative_to(parent / f"kernels-{source_key(pkg)}")
    assert setting == repr(str(tmp_path / "user-cache") if user_dir else "")  # restored
    assert _run(tmp_path, env)[0] == "1"  # loaded from the cache

    # Only the helper changes (same size): the caller's own file is untouched.
    (pkg / "helper.py").write_text(helper.format(2))
    assert _run(tmp_path, env)[0] == "2"


def test_the_engine_kernels_use_the_keyed_directory() -> None:
    import dicblur.dic.kernels as kernels
    from dicblur.dic.kernels import affine, blur, prefilter, translation

    key = f"kernels-{source_key(Path(kernels.__file__).parent)}"
    for kernel in (
        affine._affine_points,
        translation.icgn_translation,
        prefilter._rows_block,
        blur._sample,
    ):
        assert key in Path(kernel._cache._cache_path).parts
