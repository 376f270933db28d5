"""End-to-end test of ``dicblur reproduce`` on small images (the real job is the same code).

Images of 128 px and a 21 px subset keep it to a few seconds after the DIC kernels compile;
the statistics are rough at that size, so the test checks structure, consistency and the
browser view, not the paper's numbers (the benchmark records those).
"""

from __future__ import annotations

import json

import pytest

from dicblur.cli import main
from dicblur.report import check_in_browser, find_browser
from dicblur.report.reproduce import ReproduceSettings, reproduce


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    settings = ReproduceSettings(
        out=out,
        quick=True,
        size=128,
        subset=21,
        serial=True,
        blur_step_px=1.0,
        family=(2.0, 4.0, 8.0),
        trials=400,
        pulse_dependence=False,
        command="pytest small run",
    )
    return settings, reproduce(settings)


@pytest.mark.slow
def test_outputs_exist_and_are_consistent(small_run):
    settings, res = small_run
    out = settings.out
    assert res.report.name == "report.html" and res.report.exists()
    data = json.loads(res.results_json.read_text())
    assert set(data["fits"]) == {"p1", "p2", "p3", "p4"}
    ids = [c["id"] for c in data["claims"]]
    assert ids == [f"C{i}" for i in range(1, 22)]
    assert {c["verdict"] for c in data["claims"]} <= {"agrees", "differs", "partly", "inconclusive"}
    c1 = next(c for c in data["claims"] if c["id"] == "C1")
    assert c1["verdict"] == "agrees" and "spectrum" in c1["ours"]  # Algorithm 1 itself
    c12 = next(c for c in data["claims"] if c["id"] == "C12")
    assert "2 xi^2 / w" in c12["claim"]
    for name in data["figures"]:
        assert (out / "figures" / f"{name}.png").stat().st_size > 1000
        assert (out / "figures" / f"{name}.svg").exists()
    # issue 18: the blur-compensated matcher and the deblur baseline beside the plain one
    assert "fig13_compensation" in data["figures"]
    comp = data["compensation"]
    assert comp["given"][0] == comp["plain"][0]  # W = 0: the same matcher
    assert comp["given"][-1] < comp["plain"][-1] / 2  # W = 10 px: no mismatch left
    assert len(data["figures"]) == 12  # 11 + the compensation figure (issue 18)
    assert (out / "campaign" / "study.zarr").is_dir()
    assert (out / "model_p4.json").exists() and (out / "command.txt").exists()
    # Every fitted eq. 18 reproduces the data it was fitted on reasonably (noise-free SSSIG).
    assert all(f["r2_decay"] > 0.8 for f in data["fits"].values())
    # The stand-ins are labelled as such.
    html = res.report.read_text()
    assert "synthetic stand-ins" in html and "data:image/png;base64," in html
    # the pulse verdict is rendered Markdown, not a preformatted block; no internal wording
    assert "<h3>Verdict" in html and "<pre># Verdict" not in html
    assert "brief s." not in html and "extraction" not in html
    # the stage-time table is complete
    assert "report (claims, figures, page)" in html and '<td class="l">total</td>' in html
    assert "stand-in (sharp)" not in html


@pytest.mark.slow
def test_rerun_reuses_campaign_results(small_run):
    settings, first = small_run
    assert first.campaign_runs["study"]["run"] == first.campaign_runs["study"]["tasks"]
    again = reproduce(settings)
    assert again.campaign_runs["study"]["run"] == 0
    assert again.campaign_runs["study"]["skipped"] == first.campaign_runs["study"]["tasks"]
    assert again.campaign_runs["family"]["run"] == 0
    assert [c["ours"] for c in again.claims] == [c["ours"] for c in first.claims]


@pytest.mark.skipif(
    find_browser() is None, reason="no Chromium on PATH; .ci/run installs Debian's chromium"
)
@pytest.mark.slow
def test_report_opens_in_headless_chromium(small_run):
    settings, res = small_run
    chk = check_in_browser(res.report, screenshot=settings.out / "screenshot.png")
    assert chk.images_ok, "a figure did not load in the browser"
    assert chk.image_count == 12
    assert chk.screenshot is not None and chk.screenshot.stat().st_size > 10_000


def test_cli_rejects_bad_arguments(tmp_path, capsys):
    assert (
        main(["reproduce", "--out", str(tmp_path), "--pattern1", str(tmp_path / "missing.tif")])
        == 2
    )
    assert "no such file" in capsys.readouterr().err
