"""CLI ``dicblur correlate`` (issue 4)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from dicblur import save_image
from dicblur.cli import main
from helpers.dic import fourier_shift, pattern


def test_correlate_cli_csv_and_netcdf(tmp_path, capsys):
    ref = pattern(96, seed=7)
    cur = fourier_shift(ref, 0.0, 1.0)
    save_image(tmp_path / "ref.tif", ref, bit_depth=16)
    save_image(tmp_path / "cur.tif", cur, bit_depth=16)
    out = tmp_path / "field.csv"
    code = main(
        [
            "correlate",
            str(tmp_path / "ref.tif"),
            str(tmp_path / "cur.tif"),
            "--subset",
            "21",
            "--step",
            "20",
            "--shape",
            "translation",
            "--noise",
            "2",
            "-o",
            str(out),
        ]
    )
    text = capsys.readouterr().out
    assert code == 0
    assert "mean_u" in text and "predicted_sigma_u" in text and "points_per_s" in text
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    u = np.array([float(r["u"]) for r in rows if r["status_name"] == "converged"])
    assert len(u) > 0 and np.allclose(u, 1.0, atol=0.02)
    code = main(
        [
            "correlate",
            str(tmp_path / "ref.tif"),
            str(tmp_path / "cur.tif"),
            "--step",
            "30",
            "-o",
            str(tmp_path / "field.nc"),
        ]
    )
    assert code == 0 and (tmp_path / "field.nc").exists()


def test_correlate_cli_errors(tmp_path, capsys):
    ref = pattern(64, seed=1)
    save_image(tmp_path / "a.tif", ref)
    code = main(
        [
            "correlate",
            str(tmp_path / "a.tif"),
            str(tmp_path / "a.tif"),
            "-o",
            str(tmp_path / "x.json"),
        ]
    )
    assert code == 2 and "--out" in capsys.readouterr().err
    code = main(["correlate", str(tmp_path / "a.tif"), str(tmp_path / "a.tif"), "--subset", "20"])
    assert code == 2 and "subset=20" in capsys.readouterr().err


def test_cold_kernel_cache_is_detected_without_compiling(tmp_path):
    # an empty numba cache folder: nothing compiled for this kernel source
    import os
    import subprocess
    import sys

    code = (
        "from dicblur.dic.cache import kernels_cached; "
        "print(kernels_cached('affine'), kernels_cached('translation'))"
    )
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    ).stdout.split()
    assert out == ["False", "False"]


def _correlate_itself(image: Path) -> list[str]:
    """``dicblur correlate`` of an image with itself: a few translation subsets."""
    return ["correlate", str(image), str(image), "--shape", "translation", "--step", "30"]


def test_correlate_says_when_it_compiles(tmp_path, capsys, monkeypatch):
    from dicblur.dic import cache

    ref = pattern(64, seed=3)
    save_image(tmp_path / "a.tif", ref, bit_depth=16)
    args = _correlate_itself(tmp_path / "a.tif")
    asked = []
    monkeypatch.setattr(cache, "kernels_cached", lambda shape: asked.append(shape) or False)
    assert main(args) == 0
    err = capsys.readouterr().err
    assert err.count(cache.COMPILE_NOTICE) == 1 and asked == ["translation"]
    monkeypatch.setattr(cache, "kernels_cached", lambda shape: True)
    assert main(args) == 0
    assert cache.COMPILE_NOTICE not in capsys.readouterr().err


@pytest.mark.slow
def test_first_correlate_after_install_prints_one_line_then_none(tmp_path):
    # a real cold start: a fresh numba cache folder, the CLI in a new process, twice
    import os
    import subprocess
    import sys

    from dicblur.dic.cache import COMPILE_NOTICE

    ref = pattern(64, seed=3)
    save_image(tmp_path / "a.tif", ref, bit_depth=16)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    cmd = [sys.executable, "-m", "dicblur", *_correlate_itself(tmp_path / "a.tif")]
    first = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert first.returncode == 0, first.stderr
    assert first.stderr.count(COMPILE_NOTICE) == 1
    second = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert second.returncode == 0 and COMPILE_NOTICE not in second.stderr
