"""``dicblur design`` CLI: outputs and exit codes."""

from __future__ import annotations

import json

import pytest

from dicblur.cli import main

FAST = [
    "--image-size",
    "128",
    "--grid",
    "2x1x2",
    "--density-range",
    "0.5..0.5",
    "--max-refine",
    "2",
    "--confirm",
    "2",
    "--realisations",
    "1",
]


@pytest.mark.slow
def test_design_cli_writes_everything(tmp_path, capsys):
    out = tmp_path / "d"
    rc = main(
        [
            "design",
            "--blur",
            "2",
            "--scale",
            "0.05",
            "--print-size",
            "20x30",
            "--dpi",
            "300",
            "-o",
            str(out),
            "--json",
            *FAST,
        ]
    )
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_campaigns"] >= 4 + 3 and summary["n_points"] > 0
    assert summary["speckle_size_mm"] == pytest.approx(summary["best"]["speckle_size"] * 0.05)
    # every file on disk is counted, the report's figures included
    on_disk = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert summary["files"] == on_disk and any(f.startswith("figures") for f in on_disk)
    for name in (
        "design.json",
        "evaluations.csv",
        "best_pattern.png",
        "pattern.png",
        "pattern.pdf",
        "pattern.json",
        "report.html",
        "planner.html",
    ):
        assert (out / name).is_file(), name
    assert "dicblur-models" in (out / "planner.html").read_text()  # the planner page (#19)
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64") >= 6
    doc = json.loads((out / "design.json").read_text())
    assert doc["problem"]["blurs"] == [2.0] and len(doc["evaluations"]) >= 4
    rows = (out / "evaluations.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + len(doc["evaluations"])
    from dicblur.report import check_in_browser, find_browser

    if find_browser() is None:
        pytest.skip("no Chromium-family browser on PATH to open the report")
    check = check_in_browser(out / "report.html")
    assert check.images_ok and check.image_count >= 6


@pytest.mark.parametrize(
    "args, match",
    [
        (["--blur-range", "5..1"], "inverted"),
        (["--blur", "-2"], ">= 0"),
        (["--blur", "2", "--dpi", "0"], "dpi"),
        (["--blur", "2", "--print-size", "0x10"], "print-size"),
        (["--blur-range", "1-5"], "LO..HI"),
        (["--blur", "2", "--subset", "30"], "subset"),
        (["--blur", "2", "--grid", "3x3"], "grid"),
        (["--blur-dist", "1-2"], "W:weight"),
        (["--blur-dist", "1:0,2:0"], "--blur-dist"),
        (["--amplitude", "1", "--frequency", "10"], "--amplitude"),
    ],
)
def test_design_cli_bad_input_exit_2(tmp_path, capsys, args, match):
    rc = main(["design", "-o", str(tmp_path / "x"), *FAST, *args])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and match in err


def test_design_cli_usage_error(capsys):
    assert main(["design", "--blur", "2"]) == 2  # missing -o
    assert "--out" in capsys.readouterr().err


@pytest.mark.slow  # 7-11 s: keeps the README's test command under 4 min (CI runs it)
def test_design_cli_velocity_and_range(tmp_path, capsys):
    out = tmp_path / "v"
    assert (
        main(
            [
                "design",
                "--velocity",
                "100",
                "--exposure",
                "1e-3",
                "--scale",
                "0.05",
                "--dpi",
                "300",
                "--print-size",
                "20",
                "-o",
                str(out),
                "--no-report",
                "--json",
                *FAST,
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    doc = json.loads((out / "design.json").read_text())
    assert doc["problem"]["blurs"] == [pytest.approx(2.0)]  # 100 mm/s * 1 ms / 0.05 mm/px
    assert not (out / "report.html").exists()
    # the files it reports are the files it wrote (a fresh folder: all of them)
    assert summary["files"] == sorted(
        str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()
    )
    out2 = tmp_path / "r"
    assert (
        main(
            [
                "design",
                "--blur-range",
                "1..3",
                "-o",
                str(out2),
                "--no-report",
                "--json",
                *FAST,
                "--confirm",
                "0",
            ]
        )
        == 0
    )
    s = json.loads(capsys.readouterr().out)
    assert s["target"].startswith("mean over W = 1..3 px") and "pattern.png" not in s["files"]


def test_design_cli_takes_unit_strings_and_says_the_winner_in_words(tmp_path, capsys):
    out = tmp_path / "u"
    assert (
        main(
            [
                "design",
                "--velocity",
                "0.2m/s",
                "--exposure",
                "0.5ms",
                "--scale",
                "20px/mm",
                "-o",
                str(out),
                "--no-report",
                *FAST,
                "--max-refine",
                "0",
                "--confirm",
                "0",
                "--print-size",
                "20",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    doc = json.loads((out / "design.json").read_text())
    assert doc["problem"]["blurs"] == [pytest.approx(2.0)]  # 200 mm/s * 0.5 ms * 20 px/mm
    best = doc["summary"]["best"]
    words = (
        f"best pattern: speckle {best['speckle_size']:.2g} px, density "
        f"{best['density']:.2f}, edge softness {best['softness']:.2g} px"
    )
    assert words in text
    n = sum(1 for p in out.rglob("*") if p.is_file())
    assert f"wrote {n} files to {out}" in text
