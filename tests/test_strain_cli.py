"""``--strain`` of ``dicblur correlate`` and ``dicblur track`` (issue 28)."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import xarray as xr

from dicblur import save_image
from dicblur.cli import main
from helpers.dic import affine_warp, pattern


@pytest.fixture
def pair(tmp_path):
    ref = pattern(128, seed=5)
    cur = affine_warp(ref, np.array([[1.002, 0.0], [0.0, 1.0]]))  # exx = 2e-3
    save_image(tmp_path / "ref.tif", ref, bit_depth=16)
    save_image(tmp_path / "cur.tif", cur, bit_depth=16)
    return tmp_path / "ref.tif", tmp_path / "cur.tif"


@pytest.mark.slow
def test_correlate_strain_csv_and_netcdf(pair, tmp_path, capsys):
    ref, cur = pair
    base = ["correlate", str(ref), str(cur), "--subset", "21", "--step", "10", "--noise", "1"]
    out = tmp_path / "field.csv"
    assert main([*base, "--strain", "--vsg", "41px", "-o", str(out)]) == 0
    assert "strain_vsg" in capsys.readouterr().out
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    assert {"u", "exx", "sigma_exx", "strain_status"} <= set(rows[0])
    ok = [r for r in rows if r["strain_status"] == "0"]
    exx = np.array([float(r["exx"]) for r in ok])
    sig = np.array([float(r["sigma_exx"]) for r in ok])
    assert len(ok) > 20 and np.all(sig > 0)
    # Green-Lagrange of a 2e-3 stretch: 2e-3 + 2e-6
    assert abs(np.mean(exx) - 2.002e-3) < 3 * np.mean(sig)
    nc = tmp_path / "field.nc"
    assert main([*base, "--strain", "-o", str(nc)]) == 0
    with xr.open_dataset(nc, engine="scipy") as ds:
        assert ds.attrs["strain_vsg"] == 61.0 and "sigma_eyy" in ds


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--strain", "--vsg", "4"], "--vsg='4'"),
        (["--strain", "--vsg", "45px"], "--vsg='45px'"),
        (["--vsg", "7"], "only used with --strain"),
        (["--strain", "--vsg", "five"], "--vsg='five'"),
    ],
)
def test_correlate_strain_bad_input_exit_2(pair, capsys, extra, needle):
    ref, cur = pair
    code = main(["correlate", str(ref), str(cur), *extra])
    err = capsys.readouterr().err
    assert code == 2 and needle in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_track_strain_bad_input_exit_2(tmp_path, capsys):
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(3):
        save_image(frames / f"f{i}.tif", pattern(64, seed=1), bit_depth=16)
    code = main(
        [
            "track", str(frames), "--exposure", "1ms", "--fps", "500", "--noise", "1",
            "--strain", "--points", "30,30", "-o", str(tmp_path / "out"),
        ]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "--strain" in err and "--points" in err


def test_correlate_vsg_larger_than_the_grid_is_refused_before_the_work(pair, tmp_path, capsys):
    # 128^2 image, subset 21, step 10: an 11 x 11 grid; VSG 201 px needs 19 points a side.
    # The message speaks of --vsg in px, as typed, not of the API's window in points.
    ref, cur = pair
    out = tmp_path / "field.nc"
    code = main(["correlate", str(ref), str(cur), "--strain", "--vsg", "201px", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "--vsg=201px" in err and "use --vsg <= 121px" in err
    assert "window=" not in err and "Traceback" not in err and not out.exists()
