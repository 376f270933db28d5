"""Draw docs/images/plan.png, the README's picture, with the CLI a user runs.

    PYTHONPATH=src python docs/images/make_plan_figure.py

A 512^2 speckle pattern, its static prediction as a model (no simulation), and the camera
plan for a target moving at 120 mm/s seen at 0.05 mm/px: u_e against the exposure, its
optimum, the 0.02 px rule of thumb and the 0.01 px target (dicblur.report.plots.plan_figure).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from dicblur.cli import main

OUT = Path(__file__).resolve().parent / "plan.png"


def run(*argv: str) -> None:
    code = main(list(argv))
    if code:
        sys.exit(code)


with tempfile.TemporaryDirectory() as tmp:
    pattern, model = f"{tmp}/pattern.tif", f"{tmp}/model.json"
    run("pattern", "generate", pattern, "--size", "512x512", "--speckle-size", "4")
    run("pattern", "predict", pattern, "--noise", "2", "--subset", "31", "-o", model)
    run(
        "plan", model, "--velocity", "120mm/s", "--scale", "0.05mm/px", "--target", "0.01px",
        "--full-well", "20000", "--read-noise", "5", "--flux", "4e6", "--plot", str(OUT),
    )
print(f"wrote {OUT} ({OUT.stat().st_size // 1024} KB)")
