"""Start-up: what each entry point imports (issue 16). Counted in a fresh interpreter from
``sys.modules``, never timed (times belong to benchmarks/bench_startup.py)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = (
    "numpy",
    "scipy",
    "numba",
    "xarray",
    "pandas",
    "dask",
    "distributed",
    "zarr",
    "matplotlib",
    "PIL",
    "tifffile",
    "imageio",
)


def imported_after(code: str) -> set[str]:
    """Modules present in ``sys.modules`` after running ``code`` in a new interpreter."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    proc = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=300
    )
    return set(json.loads(proc.stdout.strip().splitlines()[-1]))


def top(mods: set[str]) -> set[str]:
    return {m.split(".")[0] for m in mods}


def test_import_dicblur_imports_no_subpackage():
    mods = imported_after("import dicblur")
    assert {m for m in mods if m.startswith("dicblur")} == {"dicblur", "dicblur._version"}
    assert not top(mods) & set(HEAVY)


def test_import_dicblur_dic_pulls_neither_labelled_nor_distributed_nor_models():
    mods = imported_after("import dicblur.dic")
    assert not top(mods) & {"xarray", "pandas", "dask", "distributed", "zarr", "matplotlib"}
    ours = {m for m in mods if m.startswith("dicblur.")}
    for stage in ("models", "campaign", "design", "pulse", "report", "cli"):
        assert not {m for m in ours if m.startswith(f"dicblur.{stage}")}, stage


def test_metrics_and_checks_stay_below_the_models_and_the_engine():
    # pattern_metrics reports image measurements only: the model's blur sensitivity c
    # (which needs the DIC interpolant) is asked of dicblur.models (issue 16)
    mods = imported_after("import dicblur.metrics, dicblur.checks")
    ours = {m for m in mods if m.startswith("dicblur.")}
    assert not {m for m in ours if m.startswith(("dicblur.models", "dicblur.dic"))}
    assert "numba" not in top(mods)


@pytest.mark.parametrize("argv", [["--version"], ["--help"]])
def test_cli_version_and_help_import_only_the_cli(argv):
    mods = imported_after(
        "import contextlib, io\nfrom dicblur.cli import main\n"
        f"with contextlib.redirect_stdout(io.StringIO()):\n    assert main({argv!r}) == 0"
    )
    assert not top(mods) & set(HEAVY)
    ours = {m for m in mods if m.startswith("dicblur")}
    assert ours - {"dicblur", "dicblur._version", "dicblur.errors"} == {
        m for m in ours if m.startswith("dicblur.cli")
    }


def test_version_is_the_package_literal_and_the_cli_prints_it(capsys):
    import dicblur
    from dicblur._version import __version__
    from dicblur.cli import main

    assert dicblur.__version__ == __version__
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"dicblur {__version__}"


def test_every_public_name_resolves_and_is_listed_by_dir():
    import dicblur

    listed = dir(dicblur)
    for name in dicblur.__all__:
        assert name in listed
        assert getattr(dicblur, name) is not None
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        dicblur.not_a_name  # noqa: B018
