"""Benchmark: why the errors of a small vibrating-target track exceed its predicted sigma.

The case: a 96^2 target (``tests/helpers/track.py``: 4 px speckles, 8-bit camera, 2.3 GL
noise), 4 still frames then 6 px at 200 Hz, 2000 fps, 0.4 ms exposure (W <= 3 px), 24
frames, tracked from an 8-bit PNG folder and from memory (subset 21, step 12,
translation). Per component the table gives the rms of ``error / sigma`` over the valid
points: raw, after the reported kernel-skew bias ``bias_u``/``bias_v``, after the frame's
mean error (the scatter over points), on the still frames 1-3.

Then the cause of the rest: the pattern moved rigidly by an exact Fourier shift of
0.05..0.9 px along x (4 still frames first, Gaussian noise 0.5 and 2 GL), the frame's mean
error of the track against the interpolation bias the models predict at that offset
(``blur_mismatch_curve(subpixel=offset)``, W = 0; docs/models.md, "The target at a
sub-pixel position"), which the track's sigma table (aligned subsets) leaves out.

Run: ``python benchmarks/bench_track_subpixel_bias.py``
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from _harness import Run, use_tests_dir

use_tests_dir()

import dicblur  # noqa: E402
from dicblur.models.mismatch_prediction import blur_mismatch_curve  # noqa: E402
from dicblur.sequence import Recording, open_recording  # noqa: E402
from helpers.track import track_pattern, vibrating_target  # noqa: E402

KW = dict(subset=21, step=12, shape="translation", advice=False)


def z_rows(ds, tgt, n_static):
    tu, tv, _, _ = tgt.truth(ds["frame"].values)
    val = ds["valid"].values.astype(bool)
    still = val & (np.arange(ds.sizes["frame"]) < n_static)[:, None]
    still[0] = False  # the reference frame: no error by construction
    out = {}
    for c, t in (("u", tu), ("v", tv)):
        e = ds[c].values - t[:, None]
        s = ds[f"sigma_{c}"].values
        eb = e - ds[f"bias_{c}"].values
        mu = np.nanmean(np.where(val, eb, np.nan), axis=1, keepdims=True)
        out[c] = {
            "raw": float(np.sqrt(np.mean((e / s)[val] ** 2))),
            "minus_bias": float(np.sqrt(np.mean((eb / s)[val] ** 2))),
            "minus_frame_mean": float(np.sqrt(np.mean(((eb - mu) / s)[val] ** 2))),
            "still_frames": float(np.sqrt(np.mean((e / s)[still] ** 2))),
            "frame_mean_rms_px": float(np.sqrt(np.nanmean(mu[n_static:] ** 2))),
        }
    return out


def small_case():
    tgt = vibrating_target(track_pattern(96), exposure=0.4e-3, amplitude=6.0, static=4, seed=3)
    rec = tgt.recording(24)
    rows = {}
    with tempfile.TemporaryDirectory() as d:
        for k in range(24):
            dicblur.save_image(Path(d) / f"f{k:03d}.png", rec.frame(k), bit_depth=8)
        for name, r in (("png folder", open_recording(d)), ("memory", rec)):
            ds = dicblur.track(r, fps=2000.0, exposure=0.4e-3, static="0:4", **KW)
            rows[name] = z_rows(ds, tgt, 4)
    return rows


def offsets_case(noise):
    pat = track_pattern(96)
    rng = np.random.default_rng(1)
    offsets = [0.0] * 4 + [0.05, 0.1, 0.25, 0.4, 0.5, 0.6, 0.75, 0.9]
    frames = []
    for d in offsets:
        spec = np.fft.fft2(pat) * np.exp(-2j * np.pi * d * np.fft.fftfreq(96))[None, :]
        frames.append(np.real(np.fft.ifft2(spec)) + rng.normal(0, noise, pat.shape))
    rec = Recording(source="shifted", kind="memory", n_frames=len(frames), shape=pat.shape,
                    bit_depth=8, fps=1000.0, exposure=1e-5, names=[str(i) for i in offsets],
                    _read=lambda i: frames[i])  # fmt: skip
    ds = dicblur.track(rec, static="0:4", **KW)
    val = ds["valid"].values.astype(bool)
    pts = np.stack([ds["row"].values, ds["col"].values], axis=1)
    rows = []
    for i, d in enumerate(offsets[4:], start=4):
        e = ds["u"].values[i, val[i]] - d
        pred = blur_mismatch_curve(pat, [0.0], subset=21, points=pts, motion=(0.0, 1.0),
                                   subpixel=d).mean[0]  # fmt: skip
        sig = ds["sigma_u"].values[i, val[i]]
        rows.append({"offset_px": d, "noise_gl": noise, "mean_error_px": float(e.mean()),
                     "predicted_interpolation_bias_px": float(pred),
                     "sigma_u_rms_px": float(np.sqrt(np.mean(sig**2)))})  # fmt: skip
    return rows


def main() -> None:
    run = Run("track_subpixel_bias")
    small = small_case()
    print("rms of error / sigma, 96^2 vibrating target (24 frames, W <= 3 px)")
    head = ("source", "c", "raw", "-bias", "-mean", "still", "mean px")
    print("{:11s} {:2s} {:>6s} {:>6s} {:>6s} {:>6s} {:>8s}".format(*head))
    for name, r in small.items():
        for c, v in r.items():
            print(f"{name:11s} {c:2s} {v['raw']:6.3f} {v['minus_bias']:6.3f} "
                  f"{v['minus_frame_mean']:6.3f} {v['still_frames']:6.3f} "
                  f"{v['frame_mean_rms_px']:8.4f}")  # fmt: skip
    shifts = offsets_case(0.5) + offsets_case(2.0)
    print("\nrigid sub-pixel shift along x: frame's mean error vs predicted interpolation bias")
    print(f"{'noise GL':>8s} {'offset':>6s} {'mean err':>9s} {'predicted':>9s} {'sigma':>7s}")
    for r in shifts:
        print(f"{r['noise_gl']:8.1f} {r['offset_px']:6.2f} {r['mean_error_px']:+9.4f} "
              f"{r['predicted_interpolation_bias_px']:+9.4f} "
              f"{r['sigma_u_rms_px']:7.4f}")  # fmt: skip
    run.write({"small_case": small, "subpixel_shifts": shifts})


if __name__ == "__main__":
    main()
