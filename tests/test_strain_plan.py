"""Planning for a strain target (issue 28, docs/strain.md "Planning")."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from dicblur.cli import main
from dicblur.models import BlurUncertaintyModel, mismatch_model, sssig_decay
from dicblur.strain.plan import factors, plan_strain, strain_sigma_curve


@pytest.fixture
def model_path(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "results.csv"
    w = np.arange(0.0, 10.01, 1.0)
    with path.open("w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["pattern", "noise", "blur", "rep", "sssig", "u_e"])
        for noise in (1.0, 2.0):
            for rep in range(2):
                s = sssig_decay(w, 1.85e5, 0.022)
                u = mismatch_model(w, s, noise, c=7e-4) * np.exp(rng.normal(0, 0.02, w.size))
                for row in zip(w, s, u, strict=True):
                    out.writerow(["p1", noise, row[0], rep, row[1], row[2]])
    model = tmp_path / "model.json"
    assert main(["fit", str(path), "-o", str(model)]) == 0
    return model


def test_plan_meets_the_target_at_the_planned_exposure(model_path):
    m = BlurUncertaintyModel.from_json(str(model_path))
    plan = plan_strain(
        m, velocity="120mm/s", scale="0.05mm/px", target="300microstrain", vsg="61px",
        step=10, subset=21, sigma=2.0,
    )  # fmt: skip
    assert plan.window == 5 and plan.vsg == 61
    assert plan.sigma_exx == pytest.approx(3e-4, rel=1e-6)
    assert plan.blur == pytest.approx(plan.exposure * 120 / 0.05, rel=1e-12)
    # eq. 11 from the model's own split at that W
    pred = m.predict([plan.blur], 2.0)
    k_n, k_b = factors(5, 10.0, 21)
    assert plan.sigma_exx == pytest.approx(
        math.hypot(k_n * pred.u_noise[0], k_b * pred.u_blur[0]), rel=1e-9
    )
    # a larger VSG averages more: a longer exposure meets the same target
    t = plan.tradeoff_exposure
    assert np.all(np.diff(t[np.isfinite(t)]) > 0)
    s, split = strain_sigma_curve(
        m, np.array([0.0, 2.0, 4.0]), window=5, step=10, subset=21, sigma=2.0
    )
    assert split and np.all(np.diff(s) > 0)


def test_plan_cli_strain_target(model_path, tmp_path, capsys):
    fig = tmp_path / "tradeoff.png"
    base = ["plan", str(model_path), "--velocity", "120mm/s", "--scale", "0.05mm/px"]
    args = [*base, "--target", "500microstrain", "--vsg", "41px", "--subset", "21"]
    assert main([*args, "--noise", "2", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["vsg"] == 41 and got["sigma_exx"] == pytest.approx(5e-4, rel=1e-6)
    assert main([*args, "--noise", "2", "--plot", str(fig)]) == 0
    assert fig.stat().st_size > 0 and "longest exposure" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--target", "100microstrain", "--vsg", "45px", "--subset", "21"], "--vsg='45px'"),
        (["--target", "0.01px", "--vsg", "5", "--subset", "21"], "strain unit"),
        (["--target", "100microstrain"], "--subset"),
        (["--target", "1microstrain", "--subset", "21"], "static strain uncertainty"),
        (["--target", "100microstrain", "--subset", "21", "--flux", "1e5"], "--flux"),
    ],
)
def test_plan_cli_strain_bad_input_exit_2(model_path, capsys, extra, needle):
    base = [
        "plan",
        str(model_path),
        "--velocity",
        "120mm/s",
        "--scale",
        "0.05mm/px",
        "--noise",
        "2",
    ]
    code = main([*base, *extra])
    err = capsys.readouterr().err
    assert code == 2 and needle in err and "Traceback" not in err
