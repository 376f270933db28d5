"""Strain and its predicted uncertainty under motion blur (issue 28, docs/strain.md).

Synthetic images with a known strain field (a uniform 1e-3 tension and a sinusoidal
exx of wavelength 100 px, amplitude 2e-3), the current image blurred along x by W px
(``dicblur.motion_blur``, exact box) with Gaussian noise in both images. Per (W, noise)
case: the measured scatter of the exx error over the points against the predicted
``sigma_exx`` (their quadratic means), and the mean error against ``sigma /
sqrt(points)``; the displacement sigma of each point from the reference subset as in
``dicblur track`` (``subset_blur_response``: noise part and signed mismatch shift).
Then the amplitude of the sinusoid each VSG recovers (spatial resolution), the speed of
strain + covariance on 2,401 points, and the track time per frame with and without
strains (side by side).

    PYTHONPATH=src python benchmarks/bench_strain.py [--quick]

Writes benchmarks/results/strain.json (``--quick``: strain_quick.json).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from _harness import Run
from scipy import ndimage

import dicblur
from dicblur.dic import Correlator, PointStatus
from dicblur.models.sensitivity import subset_blur_response
from dicblur.models.subset_algebra import SubsetMatcher
from dicblur.strain import StrainStatus, gradient_factor, strain_on_grid

SUBSET, STEP, WINDOW = 21, 10, 5
E_UNIFORM = 1e-3
SINE_AMP, SINE_WAVE = 2e-3, 100.0


def displacement(kind: str, x: np.ndarray, cx: float) -> np.ndarray:
    """u(x) of the field (px), x along columns."""
    if kind == "uniform":
        return E_UNIFORM * (x - cx)
    return SINE_AMP * SINE_WAVE / (2 * math.pi) * np.sin(2 * math.pi * (x - cx) / SINE_WAVE)


def exx_true(kind: str, x: np.ndarray, cx: float) -> np.ndarray:
    if kind == "uniform":
        return np.full(x.shape, E_UNIFORM)
    return SINE_AMP * np.cos(2 * math.pi * (x - cx) / SINE_WAVE)


def deformed(pattern: np.ndarray, kind: str) -> np.ndarray:
    """The pattern deformed by u(x): a material point at X appears at X + u(X); each
    pixel x samples X solving X + u(X) = x (fixed point), order-5 spline."""
    n_r, n_c = pattern.shape
    cx = (n_c - 1) / 2
    yy, xx = np.mgrid[0:n_r, 0:n_c].astype(float)
    big = xx.copy()
    for _ in range(8):
        big = xx - displacement(kind, big, cx)
    return ndimage.map_coordinates(pattern, [yy, big], order=5, mode="grid-wrap")


def one_case(ref0, cur0, kind, blur, noise, seed, response, expected):
    """Measured and predicted exx errors of one image pair; ``expected``: the strain the
    VSG measures without noise and blur (per point, NaN: unknown), None: the truth."""
    rng = np.random.default_rng(seed)
    ref = ref0 + rng.normal(0.0, noise, ref0.shape)
    cur = dicblur.motion_blur(cur0, (0.0, blur)) if blur > 0 else cur0
    cur = cur + rng.normal(0.0, noise, cur.shape)
    corr = Correlator(ref, subset=SUBSET, step=STEP, shape="affine", max_predicted_sigma=None)
    res = corr.correlate(cur)
    ny, nx = corr.grid_shape
    cx = (ref0.shape[1] - 1) / 2
    shift, cov, cov4 = response
    var_u = noise**2 * cov[0, :, 0, 0] + noise**4 * cov4[0, :, 0, 0]
    var_v = noise**2 * cov[0, :, 1, 1] + noise**4 * cov4[0, :, 1, 1]
    g = (ny, nx)
    s = strain_on_grid(
        res.u.reshape(g),
        res.v.reshape(g),
        (res.status == PointStatus.CONVERGED).reshape(g),
        step=STEP,
        subset=SUBSET,
        window=WINDOW,
        kind="small",
        sigma_u=np.sqrt(var_u).reshape(g),
        sigma_v=np.sqrt(var_v).reshape(g),
        shift_u=np.nan_to_num(shift[0, :, 0]).reshape(g),
        shift_v=np.nan_to_num(shift[0, :, 1]).reshape(g),
    )
    # the signed blur error of each strain: the plane fit of the shifts themselves
    signed = strain_on_grid(
        np.nan_to_num(shift[0, :, 0]).reshape(g),
        np.nan_to_num(shift[0, :, 1]).reshape(g),
        np.ones(g, bool),
        step=STEP,
        subset=SUBSET,
        window=WINDOW,
        kind="small",
    ).exx
    truth = exx_true(kind, res.cols.astype(float), cx) if expected is None else expected
    ok = (s.status == StrainStatus.OK) & np.isfinite(s.sigma_exx) & np.isfinite(truth)
    err = s.exx[ok] - truth[ok]
    return err, s.sigma_exx[ok], s.sigma_exx_noise[ok], s.sigma_exx_blur[ok], signed[ok]


def noise_free_strain(ref0, cur0):
    """exx of the noise-free, unblurred pair: what the VSG and the subsets measure of the
    field (the sinusoid attenuated), the reference of the random and blur errors."""
    corr = Correlator(ref0, subset=SUBSET, step=STEP, shape="affine", max_predicted_sigma=None)
    res = corr.correlate(cur0)
    g = corr.grid_shape
    ok = (res.status == PointStatus.CONVERGED).reshape(g)
    s = strain_on_grid(
        res.u.reshape(g), res.v.reshape(g), ok, step=STEP, subset=SUBSET, window=WINDOW,
        kind="small",
    )  # fmt: skip
    return np.where(s.status == StrainStatus.OK, s.exx, np.nan)


def resolution(ref0, cur_sine, noise_free_windows):
    """Amplitude of the sinusoidal exx recovered by each VSG (noise-free, W = 0) against
    the plane fit's own attenuation ``6 sum_j j sin(theta j) / (theta h (h+1) (2h+1))``
    (``theta = 2 pi step / wavelength``; the subset's own averaging comes on top)."""
    corr = Correlator(ref0, subset=SUBSET, step=STEP, shape="affine", max_predicted_sigma=None)
    res = corr.correlate(cur_sine)
    g = corr.grid_shape
    cx = (ref0.shape[1] - 1) / 2
    rows = []
    for n in noise_free_windows:
        s = strain_on_grid(
            res.u.reshape(g),
            res.v.reshape(g),
            (res.status == PointStatus.CONVERGED).reshape(g),
            step=STEP,
            subset=SUBSET,
            window=n,
            kind="small",
        )
        ok = s.status == StrainStatus.OK
        phase = 2 * math.pi * (res.cols[ok] - cx) / SINE_WAVE
        basis = np.stack([np.cos(phase), np.sin(phase), np.ones(phase.size)], axis=1)
        coef, *_ = np.linalg.lstsq(basis, s.exx[ok], rcond=None)
        h = n // 2
        theta = 2 * math.pi * STEP / SINE_WAVE
        j = np.arange(1, h + 1)
        fit_gain = 6 * np.sum(j * np.sin(theta * j)) / (theta * h * (h + 1) * (2 * h + 1))
        rows.append(
            {
                "window": n,
                "vsg_px": (n - 1) * STEP + SUBSET,
                "amplitude_ratio": float(math.hypot(coef[0], coef[1]) / SINE_AMP),
                "plane_fit_gain": float(fit_gain),
            }
        )
    return rows


def blur_factor(pattern, blurs=(2.0, 4.0), windows=(3, 5, 7)):
    """The strain factor of the signed mismatch shifts (``rms(g^T xi) / rms(xi)``) over the
    independent-points factor, per window, W and component: how far the shifts of
    neighbouring subsets are from independent (eq. 12; ``strain.plan`` uses the mean)."""
    corr = Correlator(pattern, subset=SUBSET, step=STEP, shape="affine")
    centres = np.stack([corr.rows, corr.cols], axis=1).astype(np.intp)
    g = corr.grid_shape
    shift, _, _ = subset_blur_response(
        pattern, list(blurs), centres, SUBSET, SubsetMatcher(shape="affine")
    )
    rows = []
    for m, w in enumerate(blurs):
        xu = np.nan_to_num(shift[m, :, 0]).reshape(g)
        xv = np.nan_to_num(shift[m, :, 1]).reshape(g)
        for n in windows:
            s = strain_on_grid(
                xu, xv, np.ones(g, bool), step=STEP, subset=SUBSET, window=n, kind="small"
            )
            ok = s.status == StrainStatus.OK
            ind = math.sqrt(12) / (STEP * n * math.sqrt(n * n - 1))
            rows.append(
                {
                    "W_px": w,
                    "window": n,
                    "exx_over_independent": float(
                        np.sqrt(np.mean(s.exx[ok] ** 2)) / np.sqrt(np.mean(xu**2)) / ind
                    ),
                    "eyy_over_independent": float(
                        np.sqrt(np.mean(s.eyy[ok] ** 2)) / np.sqrt(np.mean(xv**2)) / ind
                    ),
                    "noise_overlap_over_independent": gradient_factor(n // 2, STEP, SUBSET) / ind,
                }
            )
            r = rows[-1]
            print(
                f"blur factor W={w:g} N={n}: exx {r['exx_over_independent']:.3f}, eyy "
                f"{r['eyy_over_independent']:.3f} x independent (noise: "
                f"{r['noise_overlap_over_independent']:.3f})",
                flush=True,
            )
    return rows


def speed(repeats: int) -> dict[str, float]:
    rng = np.random.default_rng(0)
    n = 49
    u = rng.normal(0, 0.01, (n, n))
    sig = np.full((n, n), 0.01)
    args = {"step": STEP, "subset": SUBSET, "sigma_u": sig, "sigma_v": sig}
    strain_on_grid(u, u, np.ones((n, n), bool), **args)  # compile / load
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        strain_on_grid(u, u, np.ones((n, n), bool), shift_u=sig, shift_v=sig, **args)
        times.append(time.perf_counter() - t0)
    return {"points": n * n, "median_ms": 1e3 * float(np.median(times)), "min_ms": 1e3 * min(times)}


def track_overhead(size: int, frames: int, repeats: int) -> dict[str, float]:
    from dicblur.track.synthetic import VibratingTarget

    pat = dicblur.speckle_pattern(size, speckle_size=4.0, softness=1.0, seed=11)
    tgt = VibratingTarget(pat, fps=2000.0, exposure=0.3e-3, amplitude=5.0, static=5)
    rec = tgt.recording(frames)
    dicblur.track(rec, static="0:5", advice=False, strain=5)  # warm-up (compile, caches)
    per = {"plain": [], "strain": []}
    strain_s = []
    for _ in range(repeats):
        for mode in ("plain", "strain"):
            t0 = time.perf_counter()
            ds = dicblur.track(
                rec, static="0:5", advice=False, strain=5 if mode == "strain" else None
            )
            per[mode].append((time.perf_counter() - t0) / frames)
            if mode == "strain":
                strain_s.append(float(ds.attrs["strain_time_s"]) / frames)
    plain = float(np.median(per["plain"]))
    with_s = float(np.median(per["strain"]))
    return {
        "frames": frames,
        "points": int(ds.sizes["point"]),
        "plain_ms_per_frame": 1e3 * plain,
        "strain_ms_per_frame": 1e3 * with_s,
        "ratio": with_s / plain,
        "strain_step_ms_per_frame": 1e3 * float(np.median(strain_s)),
        "strain_step_share": float(np.median(strain_s)) / plain,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller image, fewer cases")
    opts = ap.parse_args()
    run = Run("strain_quick" if opts.quick else "strain")
    size = 256 if opts.quick else 400
    blurs = [0.0, 2.0, 4.0, 6.0] if opts.quick else [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    noises = [1.0, 4.0] if opts.quick else [1.0, 2.0, 4.0]
    seeds = 1 if opts.quick else 2
    pat = dicblur.speckle_pattern(size, speckle_size=4.0, softness=1.0, seed=3)
    cases = []
    for kind in ("uniform", "sine"):
        cur0 = deformed(pat, kind)
        expected = None if kind == "uniform" else noise_free_strain(pat, cur0)
        corr = Correlator(pat, subset=SUBSET, step=STEP, shape="affine")
        centres = np.stack([corr.rows, corr.cols], axis=1).astype(np.intp)
        for w in blurs:
            # the prediction from the (noise-free) reference, as dicblur track
            response = subset_blur_response(
                pat, [w], centres, SUBSET, SubsetMatcher(shape="affine"), max_shift=1.0
            )
            for noise in noises:
                parts = [
                    one_case(
                        pat,
                        cur0,
                        kind,
                        w,
                        noise,
                        [7, i, int(10 * w), int(noise)],
                        response,
                        expected,
                    )
                    for i in range(seeds)
                ]
                err = np.concatenate([p[0] for p in parts])
                sig = np.concatenate([p[1] for p in parts])
                sn = np.concatenate([p[2] for p in parts])
                sb = np.concatenate([p[3] for p in parts])
                signed = np.concatenate([p[4] for p in parts])
                pred = float(np.sqrt(np.mean(sig**2)))
                per_image = err.size // seeds
                row = {
                    "field": kind,
                    "W_px": w,
                    "noise_gl": noise,
                    "points": int(err.size),
                    "measured_scatter": float(np.std(err)),
                    "measured_rms": float(np.sqrt(np.mean(err**2))),
                    "predicted_sigma": pred,
                    "predicted_noise_part": float(np.sqrt(np.mean(sn**2))),
                    "predicted_blur_part": float(np.sqrt(np.mean(sb**2))),
                    "ratio_predicted_to_measured": pred / float(np.std(err)),
                    "mean_error": float(np.mean(err)),
                    "sigma_over_sqrt_points": pred / math.sqrt(per_image),
                    "mean_within": bool(abs(float(np.mean(err))) < pred / math.sqrt(per_image)),
                    "predicted_mean_blur_error": float(np.mean(signed)),
                }
                cases.append(row)
                r = row
                print(
                    f"{kind:8s} W={w:3.1f} noise={noise:3.1f}  measured "
                    f"{r['measured_scatter']:.3e}  predicted {pred:.3e} (noise "
                    f"{r['predicted_noise_part']:.2e}, blur {r['predicted_blur_part']:.2e})  "
                    f"ratio {r['ratio_predicted_to_measured']:.3f}  mean err "
                    f"{r['mean_error']:+.2e} vs {r['sigma_over_sqrt_points']:.1e} (blur "
                    f"predicts {r['predicted_mean_blur_error']:+.1e})",
                    flush=True,
                )
    bins = []
    for kind in ("uniform", "sine"):
        for w in blurs:
            sel = [c for c in cases if c["W_px"] == w and c["field"] == kind]
            m = math.sqrt(np.mean([c["measured_scatter"] ** 2 for c in sel]))
            p = math.sqrt(np.mean([c["predicted_sigma"] ** 2 for c in sel]))
            ratios = [c["ratio_predicted_to_measured"] for c in sel]
            bins.append(
                {
                    "field": kind,
                    "W_px": w,
                    "ratio_predicted_to_measured": p / m,
                    "ratio_range": [min(ratios), max(ratios)],
                    "within_15pct": bool(abs(p / m - 1) <= 0.15),
                }
            )
            print(f"bin {kind:8s} W={w:3.1f}: predicted / measured {p / m:.3f}", flush=True)
    cur_sine = deformed(pat, "sine")
    res_rows = resolution(pat, cur_sine, [3, 5, 7, 9])
    for r in res_rows:
        print(
            f"VSG {r['vsg_px']:4d} px: amplitude {r['amplitude_ratio']:.3f} "
            f"(plane fit alone {r['plane_fit_gain']:.3f})"
        )
    bf = blur_factor(pat)
    sp = speed(30)
    print(f"strain + covariance, {sp['points']} points: {sp['median_ms']:.2f} ms (median)")
    tr = track_overhead(
        256 if opts.quick else 320, 30 if opts.quick else 40, 1 if opts.quick else 2
    )
    print(
        f"track: {tr['plain_ms_per_frame']:.1f} ms/frame plain, "
        f"{tr['strain_ms_per_frame']:.1f} with --strain (ratio {tr['ratio']:.3f}; the strain "
        f"step {tr['strain_step_ms_per_frame']:.2f} ms/frame)"
    )
    factors = {
        f"window_{n}": {
            "vsg_px": (n - 1) * STEP + SUBSET,
            "sigma_exx_per_sigma_u": gradient_factor(n // 2, STEP, SUBSET),
            "independent": math.sqrt(12) / (STEP * n * math.sqrt(n * n - 1)),
        }
        for n in (3, 5, 7, 9)
    }
    out = run.write(
        {
            "settings": {
                "subset": SUBSET,
                "step": STEP,
                "window": WINDOW,
                "image": size,
                "seeds": seeds,
                "shape": "affine",
                "kind": "small",
                "pattern": "speckle 4 px, softness 1",
            },
            "cases": cases,
            "uniform_bins": bins,
            "resolution": res_rows,
            "speed_2401": sp,
            "blur_factor": bf,
            "track": tr,
            "gradient_factors": factors,
        }
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
