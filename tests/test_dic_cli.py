"""CLI ``dicblur correlate`` (issue 4)."""

from __future__ import annotations

import csv

import numpy as np

from dicblur import save_image
from dicblur.cli import main
from helpers.dic import fourier_shift, pattern


def test_correlate_cli_csv_and_netcdf(tmp_path, capsys):
    ref = pattern(96, seed=7)
    cur = fourier_shift(ref, 0.0, 1.0)
    save_image(tmp_path / "ref.tif", ref, bit_depth=16)
    save_image(tmp_path / "cur.tif", cur, bit_depth=16)
    out = tmp_path / "field.csv"
    code = main(["correlate", str(tmp_path / "ref.tif"), str(tmp_path / "cur.tif"),
                 "--subset", "21", "--step", "20", "--shape", "translation", "--noise", "2",
                 "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert "mean_u" in text and "predicted_sigma_u" in text and "points_per_s" in text
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    u = np.array([float(r["u"]) for r in rows if r["status_name"] == "converged"])
    assert len(u) > 0 and np.allclose(u, 1.0, atol=0.02)
    code = main(["correlate", str(tmp_path / "ref.tif"), str(tmp_path / "cur.tif"),
                 "--step", "30", "-o", str(tmp_path / "field.nc")])
    assert code == 0 and (tmp_path / "field.nc").exists()


def test_correlate_cli_errors(tmp_path, capsys):
    ref = pattern(64, seed=1)
    save_image(tmp_path / "a.tif", ref)
    code = main(["correlate", str(tmp_path / "a.tif"), str(tmp_path / "a.tif"), "-o",
                 str(tmp_path / "x.json")])
    assert code == 2 and "--out" in capsys.readouterr().err
    code = main(["correlate", str(tmp_path / "a.tif"), str(tmp_path / "a.tif"),
                 "--subset", "20"])
    assert code == 2 and "subset=20" in capsys.readouterr().err
