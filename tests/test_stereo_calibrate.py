"""Calibration (issue 29): checkerboard pairs rendered through a known rig are calibrated
back to it, by the API and by ``dicblur stereo calibrate``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicblur.cli import main
from dicblur.stereo import CameraModel, load_rig
from dicblur.stereo.calibrate import calibrate_rig
from dicblur.stereo.synthetic import SpeckleTarget, StereoLab, symmetric_rig

pytestmark = pytest.mark.slow  # ~12 s: the rendering of 16 views

BOARD = (9, 6)
TILTS = [
    (0.0, 0.0),
    (0.3, 0.0),
    (-0.3, 0.05),
    (0.0, 0.3),
    (0.05, -0.3),
    (0.25, 0.25),
    (-0.25, -0.2),
    (0.2, -0.25),
]


def _pairs():
    cam = CameraModel(800.0, 800.0, 159.5, 119.5, (-0.08, 0.0, 0.0, 0.0, 0.0), (240, 320))
    rig = symmetric_rig(stereo_angle=20.0, distance=300.0, camera=cam)
    still = lambda t: np.zeros((len(t), 3))  # noqa: E731
    out = []
    for k, (tx, ty) in enumerate(TILTS):
        board = SpeckleTarget.checkerboard(
            board=BOARD,
            square=8.0,
            origin=(4.0 * (k % 3 - 1), 3.0 * (k % 2), 290 + 10 * (k % 3)),
            normal=(math.sin(tx), math.sin(ty), -1.0),
            texel=0.1,
        )
        lab = StereoLab(rig, board, still, exposure=0.0, fps=100.0, supersample=2, substeps=1)
        out.append(lab.render(0, seed=k))
    return rig, out


@pytest.fixture(scope="module")
def rendered():
    return _pairs()


def test_calibration_recovers_the_rig(rendered):
    rig, pairs = rendered
    got = calibrate_rig(pairs, board=BOARD, square=8.0)
    assert got.rms < 0.2
    assert got.left.fx == pytest.approx(800.0, rel=0.02)
    assert got.right.fy == pytest.approx(800.0, rel=0.02)
    assert got.stereo_angle == pytest.approx(rig.stereo_angle, abs=0.3)
    assert got.baseline == pytest.approx(rig.baseline, rel=0.02)
    # the recovered rig triangulates the truth's points where the truth does
    from dicblur.stereo import triangulate

    x = np.random.default_rng(0).normal([0.0, 0.0, 300.0], [10.0, 10.0, 3.0], (50, 3))
    pl, pr = rig.project(x)
    xt, _ = triangulate(got, pl, pr)
    assert np.abs(xt - x).max() < 0.02 * 300


def test_cli_calibrate_writes_the_rig(rendered, tmp_path, capsys):
    from dicblur.io import save_image

    _, pairs = rendered
    for i, (a, b) in enumerate(pairs):
        save_image(tmp_path / f"left_{i:02d}.png", a)
        save_image(tmp_path / f"right_{i:02d}.png", b)
    files = [str(p) for p in sorted(tmp_path.glob("*.png"))]
    out = tmp_path / "rig.yml"
    assert (
        main(["stereo", "calibrate", *files, "--board", "9x6", "--square", "8mm", "-o", str(out)])
        == 0
    )
    assert "rms" in capsys.readouterr().out
    rig = load_rig(out)
    assert rig.rms < 0.3
    assert rig.stereo_angle == pytest.approx(20.0, abs=0.5)
