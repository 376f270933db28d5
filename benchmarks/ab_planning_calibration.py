"""Check quoted in BENCHMARKS.md (models, brute-force exposure planning): how much does the
planned optimum move with the calibration patterns?

Calibrates the two-level floor model (2 and 8 GL, W = 0..6 px, random sub-pixel shift) on
``N`` fresh patterns from seed ``SEED0`` exactly as ``bench_models.py --only planning``
does, and prints the planned optimum for all of them and for consecutive groups of 8.

Run: ``.venv/bin/python benchmarks/ab_planning_calibration.py [SEED0 N]`` (default 200 16).
"""

from __future__ import annotations

import sys

import numpy as np

import dicblur
from dicblur.blur import motion_blur
from dicblur.camera import Camera, add_gaussian_noise
from dicblur.dic import correlate
from dicblur.models import PoissonGaussianCamera, fit_blur_model, plan_exposure


def main() -> None:
    seed0 = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 16
    opts = {"subset": 31, "step": 12, "shape": "affine"}
    w_cal = np.arange(0.0, 6.01, 0.5)
    noise = (2.0, 8.0)
    rng = np.random.default_rng(99)
    kx = np.fft.fftfreq(192)[None, :]
    var = np.empty((2, w_cal.size, n))
    s_cal = np.empty((w_cal.size, n))
    levels = []
    for p in range(n):
        im = dicblur.speckle_pattern((192, 192), speckle_size=4.0, softness=0.5,
                                     seed=seed0 + p)
        levels.append(float(im.mean()))
        for i, wl in enumerate(w_cal):
            b = motion_blur(im, (0.0, float(wl)), substeps=None) if wl > 0 else im
            b = np.fft.ifft2(np.fft.fft2(b) * np.exp(-2j * np.pi * kx * rng.uniform())).real
            s_cal[i, p] = float(dicblur.sssig(b, subset=31, step=12).mean())
            for k, sg in enumerate(noise):
                sd = 7 * p + 100 * i + k
                r = correlate(add_gaussian_noise(im, sg, seed=sd),
                              add_gaussian_noise(b, sg, seed=sd + 50), **opts)
                var[k, i, p] = float(np.var(r.u[r.converged]))
    level = float(np.mean(levels))
    cam = Camera(read_noise=2.0, gain=0.05, full_well=None, bit_depth=None)
    pg = PoissonGaussianCamera.from_camera(cam, nominal_exposure=1e-3, mean_level=level)

    def plan(pats: np.ndarray) -> float:
        u = np.sqrt(var[:, :, pats].mean(axis=2)).ravel()
        s = np.tile(s_cal[:, pats].mean(axis=1), 2)
        w = np.tile(w_cal, 2)
        sig = np.repeat(noise, w_cal.size)
        m = fit_blur_model(w, s, u, noise_sigma=sig, mean_level=level, default="mismatch",
                           floor=True, noise_blur=False, compare=False)
        return plan_exposure(m, velocity=100.0, scale=0.05, camera=pg).exposure

    print(f"patterns {seed0}..{seed0 + n - 1}: planned {plan(np.arange(n)) * 1e3:.4g} ms")
    for h in range(0, n, 8):
        grp = np.arange(h, min(h + 8, n))
        print(f"  patterns {seed0 + h}..{seed0 + grp[-1]}: {plan(grp) * 1e3:.4g} ms")


if __name__ == "__main__":
    main()
