"""The shipped examples/ run as written (small sizes) and produce what they describe."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dicblur.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run_script(name: str, out: Path) -> subprocess.CompletedProcess[str]:
    if shutil.which("bash") is None:
        pytest.skip("bash is not available to run the shell examples")
    # the dicblur console script of this interpreter's environment first on PATH
    env = dict(
        os.environ,
        PATH=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]),
    )
    return subprocess.run(
        ["bash", str(EXAMPLES / name), str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )


def test_campaign_spec_runs_and_fits(tmp_path, capsys):
    store, table = tmp_path / "results.zarr", tmp_path / "results.csv"
    assert (
        main(
            ["campaign", "run", str(EXAMPLES / "campaign.toml"), "-o", str(store), "--serial", "-q"]
        )
        == 0
    )
    assert main(["campaign", "export", str(store), "--csv", str(table)]) == 0
    # 2 patterns x 2 noise levels x 5 blur lengths, one repetition
    assert len(table.read_text().strip().splitlines()) == 1 + 2 * 2 * 5
    assert (
        main(["fit", str(table), "-o", str(tmp_path / "model.json"), "--select", "pattern=soft"])
        == 0
    )
    model = json.loads((tmp_path / "model.json").read_text())
    assert model["noise_levels"] == [1.0, 2.0]


@pytest.mark.slow  # 7-11 s: keeps the README's test command under 4 min (CI runs it)
def test_walkthrough_calibrates_predicts_and_plans(tmp_path):
    proc = run_script("walkthrough.sh", tmp_path / "w")
    assert proc.returncode == 0, proc.stderr
    cal = tmp_path / "w" / "calibration"
    for name in (
        "model.json",
        "results.csv",
        "ue_vs_blur.png",
        "sssig_vs_blur.png",
        "ue_vs_sssig.png",
    ):
        assert (cal / name).is_file(), name
    assert "W = 2.4 px: u_e =" in proc.stdout  # 120 mm/s x 1 ms / 0.05 mm/px
    assert "longest exposure under the target" in proc.stdout
    assert (tmp_path / "w" / "plan.png").stat().st_size > 1000


@pytest.mark.slow
def test_design_example_exports_a_print_ready_pattern(tmp_path):
    proc = run_script("design.sh", tmp_path / "d")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "d" / "design.json").read_text())
    assert doc["problem"]["blurs"] == [pytest.approx(4.0)]  # 200 mm/s x 1 ms / 0.05 mm/px
    for name in ("pattern.png", "pattern.pdf", "pattern.json", "report.html"):
        assert (tmp_path / "d" / name).is_file(), name
    assert "best pattern: speckle" in proc.stdout
