"""Command lines the CLI tests (and ``benchmarks/bench_trust.py``) run more than once.

Each is a tuple of arguments to splice into an argv: ``main(["plan", model, *CAMERA_PLAN])``.
"""

from __future__ import annotations

from pathlib import Path

# 120 mm/s at 0.05 mm/px: 2400 px/s of motion on the sensor
MOTION = ("--velocity", "120mm/s", "--scale", "0.05mm/px")
# the camera the plan tests run: 20000 e- full well, 5 e- read noise, 4e6 e-/s
CAMERA = ("--full-well", "20000", "--read-noise", "5", "--flux", "4e6")
# a camera plan: the exposure that minimises the predicted u_e
CAMERA_PLAN = (*MOTION, *CAMERA)
# a target plan: the longest exposure that keeps u_e <= 0.01 px at 2 GL of noise
TARGET_PLAN = (*MOTION, "--target", "0.01px", "--noise", "2")


def calibrate_args(out: Path | str, *, blur: str = "0:6:0.5", size: int = 128) -> list[str]:
    """``dicblur calibrate`` on a ``size`` x ``size`` paper4 pattern at 2 GL, subset 21,
    serial, quiet (at 128 px a small calibration of about 10 s)."""
    return [
        "calibrate",
        "paper4",
        "--size",
        f"{size}x{size}",
        "--noise",
        "2",
        "--subset",
        "21",
        "--blur",
        blur,
        "-o",
        str(out),
        "--serial",
        "-q",
    ]
