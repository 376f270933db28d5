"""CLI tests of ``dicblur fit``, ``predict`` and ``plan`` (in-process, no subprocess)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from dicblur.cli import main
from dicblur.models import BlurUncertaintyModel, mismatch_model, sssig_decay
from helpers.cli import CAMERA, TARGET_PLAN


@pytest.fixture
def results_csv(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "results.csv"
    w = np.arange(0.0, 10.01, 1.0)
    with path.open("w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(
            ["pattern", "noise", "blur", "rep", "sssig", "u_e", "contrast_ref", "contrast"]
        )
        for noise in (1.0, 2.0):
            for rep in range(2):
                s = sssig_decay(w, 1.85e5, 0.022)
                u = mismatch_model(w, s, noise, c=7e-4) * np.exp(rng.normal(0, 0.02, w.size))
                for row in zip(w, s, u, strict=True):
                    out.writerow(
                        ["p1", noise, row[0], rep, row[1], row[2], 0.9, 0.9 / (1 + 0.01 * row[0])]
                    )
    return path


def test_fit_predict_plan(results_csv, tmp_path, capsys):
    model_path = tmp_path / "model.json"
    assert main(["fit", str(results_csv), "-o", str(model_path)]) == 0
    out = capsys.readouterr().out
    assert "SSSIG decay" in out and "gamma" in out and "wrote" in out
    model = BlurUncertaintyModel.from_json(str(model_path))
    assert model.noise_levels == (1.0, 2.0)
    assert model.mismatch["c"] == pytest.approx(7e-4, rel=0.05)

    assert main(["predict", str(model_path), "--blur", "3", "--noise", "2", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    expect = model.predict([3.0], 2.0).u_e[0]
    assert got["predictions"][0]["u_e_px"] == pytest.approx(expect, rel=1e-12)
    # 120 mm/s x 1 ms / 0.05 mm/px = 2.4 px
    assert (
        main(
            [
                "predict",
                str(model_path),
                "--velocity",
                "120mm/s",
                "--exposure",
                "1ms",
                "--scale",
                "0.05mm/px",
                "--noise",
                "2",
                "--json",
            ]
        )
        == 0
    )
    got = json.loads(capsys.readouterr().out)
    assert got["predictions"][0]["blur_px"] == pytest.approx(2.4)

    assert main(["plan", str(model_path), *TARGET_PLAN]) == 0
    assert "rule of thumb" in capsys.readouterr().out
    fig = tmp_path / "plan.png"
    # the scale as its inverse, 20 px/mm = 0.05 mm/px
    motion = ["--velocity", "120mm/s", "--scale", "20px/mm"]
    assert main(["plan", str(model_path), *motion, *CAMERA, "--plot", str(fig), "--json"]) == 0
    text = capsys.readouterr().out
    plan = json.loads(text[: text.rindex("}") + 1])
    assert plan["optimal"] and plan["exposure"] > 0
    assert fig.stat().st_size > 1000


def test_fit_takes_the_papers_column_names_in_any_case(results_csv, tmp_path, capsys):
    # W, SSSIG, u_e (the paper's names, as the models issue wrote them) = blur, sssig, u_e
    rows = results_csv.read_text().splitlines()
    header = rows[0].replace("blur", "W").replace("sssig", "SSSIG").replace("u_e", "U_E")
    paper = tmp_path / "paper.csv"
    paper.write_text("\n".join([header, *rows[1:]]) + "\n")
    assert main(["fit", str(results_csv), "-o", str(tmp_path / "a.json")]) == 0
    assert main(["fit", str(paper), "-o", str(tmp_path / "b.json"), "--select", "PATTERN=p1"]) == 0
    a = BlurUncertaintyModel.from_json(str(tmp_path / "a.json"))
    b = BlurUncertaintyModel.from_json(str(tmp_path / "b.json"))
    assert b.decay["beta"] == a.decay["beta"] and b.mismatch["c"] == a.mismatch["c"]
    both = tmp_path / "both.csv"
    both.write_text("W,blur,sssig,u_e\n1,1,2,3\n")
    capsys.readouterr()
    assert main(["fit", str(both), "-o", str(tmp_path / "c.json")]) == 2
    assert "both mean 'blur'" in capsys.readouterr().err


def test_fit_from_netcdf(tmp_path, capsys):
    import xarray as xr

    w = np.arange(0.0, 8.01, 1.0)
    s = sssig_decay(w, 1e5, 0.03)
    u = mismatch_model(w, s, 2.0, c=5e-4)
    ds = xr.Dataset({"u_e": ("blur", u), "sssig": ("blur", s)}, coords={"blur": w})
    path = tmp_path / "r.nc"
    ds.to_netcdf(path)
    assert main(["fit", str(path), "-o", str(tmp_path / "m.json"), "--noise", "2"]) == 0
    model = BlurUncertaintyModel.from_json(str(tmp_path / "m.json"))
    assert model.mismatch["c"] == pytest.approx(5e-4, rel=1e-6)


@pytest.mark.filterwarnings("ignore::UserWarning", "ignore:The data type")  # zarr v3 notes
def test_fit_from_campaign_zarr(tmp_path, capsys):
    # the campaign layout: dims (pattern, angle, subset, noise, blur, rep), effective noise
    import xarray as xr

    w = np.arange(0.0, 8.01, 1.0)
    s = sssig_decay(w, 1e5, 0.03)
    dims = ("pattern", "angle", "subset", "noise", "blur", "rep")
    shape = (2, 1, 1, 2, w.size, 2)
    eff = np.array([1.0, 2.0]) / np.sqrt(101)  # per-subframe noise, K = 100
    u = np.empty(shape)
    for p in range(2):
        for j in range(2):
            u[p, 0, 0, j] = mismatch_model(w, s, eff[j], c=5e-4 * (p + 1))[:, None]
    ds = xr.Dataset(
        {
            "u_e": (dims, u),
            "sssig": (dims, np.broadcast_to(s[:, None], shape)),
            "noise_effective": (dims, np.broadcast_to(eff[None, None, None, :, None, None], shape)),
        },
        coords={
            "pattern": ["a", "b"],
            "angle": [0.0],
            "subset": [31],
            "noise": [1.0, 2.0],
            "blur": w,
            "rep": [0, 1],
        },
    )
    path = tmp_path / "results.zarr"
    ds.to_zarr(path)
    out = tmp_path / "m.json"
    assert main(["fit", str(path), "-o", str(out)]) == 2
    assert "--select pattern=" in capsys.readouterr().err
    assert main(["fit", str(path), "-o", str(out), "--select", "pattern=b"]) == 0
    model = BlurUncertaintyModel.from_json(str(out))
    assert model.subset == 31
    np.testing.assert_allclose(model.noise_levels, eff, rtol=1e-12)
    assert model.mismatch["c"] == pytest.approx(1e-3, rel=1e-6)


def test_cli_errors(results_csv, tmp_path, capsys):
    assert main(["fit", str(tmp_path / "none.csv"), "-o", str(tmp_path / "m.json")]) == 2
    assert "no such file" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("blur,u_e\n0,1\n")
    assert main(["fit", str(bad), "-o", str(tmp_path / "m.json")]) == 2
    assert "sssig" in capsys.readouterr().err
    model_path = tmp_path / "model.json"
    assert main(["fit", str(results_csv), "-o", str(model_path)]) == 0
    capsys.readouterr()
    assert (
        main(
            [
                "plan",
                str(model_path),
                "--velocity",
                "0mm/s",
                "--scale",
                "0.05mm/px",
                "--target",
                "0.01px",
                "--noise",
                "2",
            ]
        )
        == 2
    )
    assert "velocity" in capsys.readouterr().err
    assert main(["predict", str(model_path), "--velocity", "1m/s"]) == 2
    assert "all three" in capsys.readouterr().err
    assert (
        main(
            [
                "plan",
                str(model_path),
                "--velocity",
                "1m/s",
                "--scale",
                "0.05mm/px",
                "--full-well",
                "1e4",
            ]
        )
        == 2
    )
    assert "--flux" in capsys.readouterr().err


def test_plan_shot_noise_at_reference_level(results_csv, tmp_path, capsys):
    # --reference: the camera's shot noise at the image's gradient-weighted level (relative
    # to its mean, on the model's scale), the same plan as the API with noise_level=
    from dicblur import save_image, speckle_pattern
    from dicblur.models import PoissonGaussianCamera, gradient_weighted_level, plan_exposure

    model_path = tmp_path / "model.json"
    assert main(["fit", str(results_csv), "-o", str(model_path)]) == 0
    model = BlurUncertaintyModel.from_json(str(model_path))
    img = 0.5 * speckle_pattern((96, 96), speckle_size=4.0, seed=3) + 40.0  # dim, offset
    ref = tmp_path / "ref.tif"
    save_image(ref, img, bit_depth=16)
    cam_args = ["--full-well", "20000", "--read-noise", "5", "--flux", "4e6"]
    base = ["plan", str(model_path), "--velocity", "120mm/s", "--scale", "0.05mm/px"]
    capsys.readouterr()
    assert main([*base, *cam_args, "--reference", str(ref), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    from dicblur import load_image

    loaded = load_image(ref)
    # the model records no mean level: the reference's own mean is the scale
    assert model.mean_level is None
    level = gradient_weighted_level(loaded)
    cam = PoissonGaussianCamera(full_well=2e4, read_noise=5.0, flux=4e6)
    expect = plan_exposure(
        model,
        velocity="120mm/s",
        scale="0.05mm/px",
        camera=cam,
        noise_level=level,
        mean_level=float(loaded.mean()),
    )
    assert got["exposure"] == pytest.approx(expect.exposure, rel=1e-12)
    # --noise-level is a grey level on the model's scale (127.5 GL assumed here)
    assert main([*base, *cam_args, "--noise-level", str(level), "--json"]) == 0
    same = plan_exposure(
        model, velocity="120mm/s", scale="0.05mm/px", camera=cam, noise_level=level
    )
    assert json.loads(capsys.readouterr().out)["exposure"] == pytest.approx(
        same.exposure, rel=1e-12
    )
    # fixed noise has no shot noise to place; both options at once are ambiguous
    assert main([*base, "--target", "0.01px", "--noise", "2", "--noise-level", "100"]) != 0
    assert main([*base, *cam_args, "--reference", str(ref), "--noise-level", "100"]) != 0


def test_plan_html_from_a_model_of_several_noise_levels(results_csv, tmp_path, capsys):
    """Issue 26 item 6: a model fitted on two noise levels (noise_sigma None) writes the
    planner page with velocity and scale given and no --noise (exit 0, was 2): the page
    chooses the noise, and the text plan says which noise it used; without --html the plan
    still asks for it."""
    model_path = tmp_path / "model.json"
    assert main(["fit", str(results_csv), "-o", str(model_path)]) == 0
    model = BlurUncertaintyModel.from_json(str(model_path))
    assert model.noise_sigma is None and model.noise_levels == (1.0, 2.0)
    capsys.readouterr()
    page = tmp_path / "planner.html"
    args = ["plan", str(model_path), "--velocity", "100mm/s", "--scale", "0.05mm/px"]
    args += ["--target", "0.01px"]
    assert main([*args, "--html", str(page)]) == 0
    cap = capsys.readouterr()
    assert page.stat().st_size > 1000 and "longest exposure" in cap.out
    assert "--noise 1 " in cap.err and "calibrated at 1, 2 GL" in cap.err
    # the same plan as asked with --noise 1, and --noise sets the page's start value
    assert main([*args, "--noise", "1"]) == 0
    assert capsys.readouterr().out == cap.out.replace(f"wrote {page}\n", "")
    assert main([*args, "--noise", "2", "--html", str(page)]) == 0
    assert 'id="sigma" min="0" step="any" value="2"' in page.read_text()
    assert "note:" not in capsys.readouterr().err
    assert main(args) == 2
    assert "--noise" in capsys.readouterr().err
