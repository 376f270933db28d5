"""``dicblur calibrate``: the paper's sweep on one pattern, the model fits, the figures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dicblur.campaign import open_results
from dicblur.campaign.calibrate import calibrate, calibration_spec
from dicblur.cli import main
from dicblur.errors import InputError
from helpers.cli import calibrate_args

REAL = (
    Path(__file__).resolve().parents[1].parent
    / "shared"
    / "data"
    / "real"
    / "dicchallenge1_sample3"
    / "Sample3_Reference.tif"
)
PNG = b"\x89PNG\r\n\x1a\n"


def test_calibration_spec_is_the_papers_sweep(tmp_path):
    spec = calibration_spec("paper4", noise=2.0, subset=31)
    assert len(spec.blur) == 100 and spec.blur[0] == 0.1 and spec.blur[-1] == 10.0
    assert spec.subsets == (31,) and spec.step == 10 and spec.noise_levels == (2.0,)
    assert spec.boundary == "periodic" and spec.patterns[0].generator == "paper4"
    img = tmp_path / "p.png"
    img.write_bytes(b"")  # existence decides file vs generator; content is read later
    assert calibration_spec(img).boundary == "reflect"
    with pytest.raises(InputError, match="no such file"):
        calibration_spec(tmp_path / "missing.tif")


@pytest.mark.slow
def test_calibrate_generated_pattern(tmp_path, capsys):
    out = tmp_path / "calib"
    code = main(calibrate_args(out))
    assert code == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "R^2 of the SSSIG fit" in text
    model = json.loads((out / "model.json").read_text())
    assert model["subset"] == 21 and model["provenance"]["source"] == "dicblur calibrate"
    for name in ("ue_vs_blur.png", "sssig_vs_blur.png", "ue_vs_sssig.png"):
        assert (out / name).read_bytes()[:8] == PNG
    ds = open_results(out / "results.zarr")
    assert ds.sizes["blur"] == 13 and (ds["done"] == 1).all()
    from dicblur.models import BlurUncertaintyModel

    m = BlurUncertaintyModel.from_json((out / "model.json").read_text())
    # eq. 18 fit against the stored data: SSSIG_0 near the W = 0 value, R^2 recomputed
    s = ds["sssig"].isel(pattern=0, angle=0, subset=0, noise=0, rep=0).values
    w = ds["blur"].values
    fit = m.decay["sssig0"] / (m.decay["beta"] * w**2 + 1.0)
    r2 = 1.0 - np.sum((s - fit) ** 2) / np.sum((s - s.mean()) ** 2)
    assert r2 == pytest.approx(m.decay.r2, abs=1e-6)
    assert m.decay["sssig0"] == pytest.approx(s[0], rel=0.1)
    # rerun resumes: nothing left to compute, same model
    again = calibrate(
        "paper4",
        out,
        noise=2.0,
        subset=21,
        size=(128, 128),
        blur={"start": 0.0, "stop": 6.0, "step": 0.5},
        serial=True,
    )
    assert again is not None and again.figures == ()  # the campaign stage draws nothing
    assert again.model.decay["beta"] == pytest.approx(m.decay["beta"], rel=1e-12)


@pytest.mark.slow
def test_calibrate_dic_challenge_sample3(tmp_path):
    if not REAL.is_file():
        pytest.skip(f"real image not available: {REAL}")
    from dicblur.report.plots import calibration_figures

    res = calibrate(REAL, tmp_path / "s3", noise=2.0, subset=31, workers=2)
    assert res is not None
    print(
        f"Sample 3: SSSIG decay (eq. 18) R^2 = {res.sssig_r2:.4f}, beta = "
        f"{res.model.decay['beta']:.4g} 1/px^2, alpha = {res.model.alpha:.3f}"
    )
    assert res.sssig_r2 > 0.92  # the paper's figure for its patterns #2-#4
    figures = calibration_figures(res)
    assert len(figures) == 3 and all(p.is_file() for p in figures)
