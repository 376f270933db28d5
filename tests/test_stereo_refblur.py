"""The blur mismatch of a stereo track is predicted against the reference's own blur
(docs/stereo.md, "Uncertainty"): a reference frame that moves during its exposure (a
vibration opening at rest) is blurred too, and a frame blurred as it is has almost no
mismatch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicblur.camera import Camera
from dicblur.stereo import CameraModel, track
from dicblur.stereo.synthetic import SpeckleTarget, StereoLab, symmetric_rig

pytestmark = pytest.mark.slow  # rendering 9 pairs and the blur tables: ~10-20 s

FPS, SIZE, FRAMES = 2000.0, 128, 9


def test_frames_blurred_as_the_reference_have_a_small_predicted_mismatch():
    cam = CameraModel(
        2000.0, 2000.0, (SIZE - 1) / 2, (SIZE - 1) / 2, (-0.05, 0, 0, 0, 0), (SIZE, SIZE)
    )
    rig = symmetric_rig(stereo_angle=15.0, distance=400.0, camera=cam)
    tgt = SpeckleTarget.speckled(
        rig=rig, origin=(0.0, 0.0, 400.0), size=80.0, speckle_size=1.0, seed=11
    )
    axis = tgt.frame()[0]
    f = FPS / (FRAMES - 1)  # 8 frames per cycle: frames 0, 3, 4, 7, 8 share one blur length

    def traj(t):
        return 1.0 * (1 - np.cos(2 * math.pi * f * t))[:, None] * axis[None, :]

    lab = StereoLab(
        rig,
        tgt,
        traj,
        exposure=1 / FPS,
        fps=FPS,
        camera=Camera(read_noise=2.0, bit_depth=None),
        supersample=2,
    )
    fr = [lab.render(k, noise=False) for k in range(FRAMES)]
    ds = track(
        np.array([a for a, _ in fr]),
        np.array([b for _, b in fr]),
        rig,
        exposure=lab.exposure,
        fps=FPS,
        noise=2.0,
        subset=21,
        step=10,
        threads=2,
    )
    valid = ds["valid"].values.astype(bool)
    # the reference frame's mismatch against itself is none
    np.testing.assert_array_equal(ds["sigma_U_blur"].values[0][valid[0]], 0.0)
    w0 = float(np.nanmedian(ds["W_left"].values[0]))
    assert w0 > 1.0, w0  # the reference itself is blurred
    for k in (3, 4):
        v = valid[k]
        d = lab.mean_displacement(k) - lab.mean_displacement(0)
        e = np.stack([ds[c].values[k][v] for c in ("U", "V")], axis=1) - d[:2]
        meas = np.sqrt(np.mean((e - e.mean(axis=0)) ** 2, axis=0))
        pred = np.array([np.sqrt(np.mean(ds[f"sigma_{c}_blur"].values[k][v] ** 2)) for c in "UV"])
        # against a sharp reference the prediction was 4-5x the noise-free scatter; against
        # the blurred reference 2.3-2.6x (the reference's W read 30 % low from its one-sided
        # stencil, docs/stereo.md)
        assert np.all(pred < 3.2 * meas), (k, pred, meas)
