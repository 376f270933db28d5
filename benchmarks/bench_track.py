"""Benchmark: ``dicblur track`` on synthetic recordings with known truth (issue 17).

Accuracy: a speckle target (speckle 4 px, softness 0.5, 30..210 GL) vibrating as
``x(t) = A (1 - cos 2 pi f t)`` (A = 10 px, f = 200 Hz) along 20 deg, filmed at 2000 fps
(10 frames per cycle) with exposures 0.1 .. 0.45 ms (peak W 1.3 .. 5.7 px); every frame
is the pattern moved along its own stretch of the trajectory (dicblur.motion_blur, the
continuous limit) through a Poisson-Gaussian camera (read noise 2 GL, full well 20,000
e-, 8 bit). 10 static frames give the noise. 3 % of the moving frames get two 24 px
patches of foreign texture (debris) to make gross errors. Over bins of 0.5 px in W, the
quadratic mean of the predicted sigma is set against

- ``std``: the scatter of the error over points (each frame's common offset removed,
  pooled over the frames in the bin): the criterion, within 15 %;
- ``rms``: the error itself, common offset included (the deterministic bias of an
  accelerating blur, which a centred-box prediction does not hold).

Gross errors: of the points whose error exceeds 10 predicted sigma, the share flagged
(normalised median test or a non-converged status); false flags: the share of points
within 3 sigma that the median test flags.

Speed (``--part speed``): a 1,000-frame recording (512^2, 8-bit Photron .mraw written
here, read lazily) tracked at subset 21, step 10 (2,401 POIs), both shapes, 1 and 2 kernel
threads (``--threads``, ``--shapes``): end-to-end frames/s and POI/s of ``dicblur.track``
(reading, guesses, correlation, flags, blur, sigma, advice), of its tracking loop, and in
the same run the engine alone (one Correlator on 100 of the frames in memory, each started
from the field track measured: the kernel with the best guesses), so that the ratio
end-to-end / engine is meaningful on a loaded machine; the time of each stage;
``--modes kernel,chunks``: the serial loop on kernel threads and/or chunks of 100 frames on
``--threads`` threads of the process (``ChunkedRun(threads=N)``).

Memory (``--memory`` or ``--part memory``): peak RSS of tracking a 2,000-frame 1024^2
.mraw at step 20 (2,601 POIs, translation, no advice) in a child process.

Run: ``NUMBA_NUM_THREADS=2 .venv/bin/python benchmarks/bench_track.py [--part speed] [--quick]``
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from _harness import use_tests_dir

import dicblur
from dicblur.sequence import Recording, open_recording
from dicblur.track.synthetic import VibratingTarget

use_tests_dir()
from helpers.track import track_pattern, vibrating_target  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "track.json"


def _commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            cwd=Path(__file__).parent,
            check=False,
        ).stdout.strip()
    except OSError:
        return "unknown"


def _with_debris(
    tgt: VibratingTarget, n_frames: int, share: float, seed: int
) -> tuple[Recording, set[int]]:
    rng = np.random.default_rng(seed)
    moving = np.arange(tgt.static, n_frames)
    hit = set(rng.choice(moving, max(1, round(share * moving.size)), replace=False).tolist())
    foreign = track_pattern(tgt.pattern.shape[0], seed=seed + 100)
    n = tgt.pattern.shape[0]
    spots = {k: rng.integers(30, n - 54, size=(2, 2)) for k in hit}

    def read(k: int) -> np.ndarray:
        img = tgt.render(k)
        for r, c in spots.get(k, []):
            img[r : r + 24, c : c + 24] = foreign[r : r + 24, c : c + 24]
        return img

    rec = Recording(
        source="vibrating target + debris",
        kind="synthetic",
        n_frames=n_frames,
        shape=tgt.pattern.shape,
        bit_depth=8,
        fps=tgt.fps,
        exposure=tgt.exposure,
        names=[f"frame {i}" for i in range(n_frames)],
        _read=read,
    )
    return rec, hit


def accuracy(n: int, n_frames: int, exposures: list[float], shape: str) -> dict:
    pat = track_pattern(n)
    pooled: dict[str, list[np.ndarray]] = {
        k: [] for k in ("w", "du", "dv", "eu", "ev", "su", "sv", "bu", "bv")
    }
    gross = {
        "n_gross": 0,
        "caught": 0,
        "n_clean": 0,
        "false": 0,
        "n_gross_raw": 0,
        "caught_raw": 0,
        "n_gross_bias": 0,
        "caught_bias": 0,
    }
    runs = []
    for i, t in enumerate(exposures):
        tgt = vibrating_target(pat, exposure=t, amplitude=10.0, static=10, seed=10 + i)
        rec, _ = _with_debris(tgt, n_frames, 0.03, seed=i)
        t0 = time.perf_counter()
        ds = dicblur.track(rec, static="0:10", subset=21, step=10, shape=shape)  # type: ignore[arg-type]
        wall = time.perf_counter() - t0
        tu, tv, bu, bv = tgt.truth(ds["frame"].values)
        eu = ds["u"].values - tu[:, None]
        ev = ds["v"].values - tv[:, None]
        su, sv = ds["sigma_u"].values, ds["sigma_v"].values
        valid = ds["valid"].values.astype(bool)
        conv = ds["status"].values == 0
        out = ds["outlier"].values.astype(bool)
        w_true = np.broadcast_to(np.hypot(bu, bv)[:, None], eu.shape)
        # points without a sigma of their own (flagged, so their blur is unknown) are
        # judged against the frame's median sigma
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            su = np.where(np.isfinite(su), su, np.nanmedian(su, axis=1, keepdims=True))
            sv = np.where(np.isfinite(sv), sv, np.nanmedian(sv, axis=1, keepdims=True))
        with np.errstate(invalid="ignore"):
            mu = np.nanmean(np.where(valid, eu, np.nan), axis=1, keepdims=True)
            mv = np.nanmean(np.where(valid, ev, np.nan), axis=1, keepdims=True)
            z_raw = np.fmax(np.abs(eu) / su, np.abs(ev) / sv)
            # the error about the frame's common offset (the deterministic bias of an
            # accelerating blur, the same for every point, is not in sigma: see docs)
            z = np.fmax(np.abs(eu - mu) / su, np.abs(ev - mv) / sv)
            # the error about the predicted bias of the accelerating blur
            z_b = np.fmax(
                np.abs(eu - np.nan_to_num(ds["bias_u"].values)) / su,
                np.abs(ev - np.nan_to_num(ds["bias_v"].values)) / sv,
            )
        for key, arr in (
            ("w", w_true),
            ("du", eu - mu),
            ("dv", ev - mv),
            ("eu", eu),
            ("ev", ev),
            ("su", su),
            ("sv", sv),
            ("bu", ds["bias_u"].values),
            ("bv", ds["bias_v"].values),
        ):
            pooled[key].append(arr[valid])
        has_sigma = np.isfinite(su) & np.isfinite(sv) & np.isfinite(eu) & np.isfinite(ev)
        g_raw = has_sigma & np.isfinite(z_raw) & (z_raw > 10)
        gross["n_gross_raw"] += int(g_raw.sum())
        gross["caught_raw"] += int((g_raw & (out | ~conv)).sum())
        g_b = has_sigma & np.isfinite(z_b) & (z_b > 10)
        gross["n_gross_bias"] += int(g_b.sum())
        gross["caught_bias"] += int((g_b & (out | ~conv)).sum())
        g = has_sigma & np.isfinite(z) & (z > 10)
        gross["n_gross"] += int(g.sum())
        gross["caught"] += int((g & (out | ~conv)).sum())
        clean = has_sigma & conv & np.isfinite(z) & (z < 3)
        gross["n_clean"] += int(clean.sum())
        gross["false"] += int((clean & out).sum())
        w_meas = np.nanmedian(np.where(valid, ds["W"].values, np.nan), axis=1)
        inner = slice(13, -3)
        runs.append(
            {
                "exposure": t,
                "peak_W": float(np.hypot(bu, bv).max()),
                "W_error_max": float(np.nanmax(np.abs(w_meas - np.hypot(bu, bv))[inner])),
                "valid_share": float(valid.mean()),
                "wall_s": wall,
                "tracking_s": float(ds.attrs["tracking_time_s"]),
                "prediction_s": float(ds.attrs["prediction_time_s"]),
                "noise_sigma": float(ds.attrs["noise_sigma"]),
                "advice": ds.attrs.get("advice_sentence", ""),
            }
        )
        print(
            f"exposure {t * 1e3:.2f} ms: peak W {runs[-1]['peak_W']:.2f} px, W error "
            f"{runs[-1]['W_error_max']:.3f} px, valid {runs[-1]['valid_share']:.3f}, "
            f"{wall:.1f} s",
            flush=True,
        )
    cat = {k: np.concatenate(v) for k, v in pooled.items()}
    rows = []
    for lo in np.arange(0.0, 6.0, 0.5):
        sel = (cat["w"] >= lo) & (cat["w"] < lo + 0.5)
        if sel.sum() < 200:
            continue
        row = {"W_lo": float(lo), "W_hi": float(lo + 0.5), "n": int(sel.sum())}
        for c in ("u", "v"):
            pred = float(np.sqrt(np.mean(cat["s" + c][sel] ** 2)))
            std = float(np.sqrt(np.mean(cat["d" + c][sel] ** 2)))
            rms = float(np.sqrt(np.mean(cat["e" + c][sel] ** 2)))
            res_b = cat["e" + c][sel] - np.nan_to_num(cat["b" + c][sel])
            rms_b = float(np.sqrt(np.mean(res_b**2)))
            row.update(
                {
                    f"pred_{c}": pred,
                    f"std_{c}": std,
                    f"rms_{c}": rms,
                    f"ratio_{c}": pred / std,
                    f"rms_minus_bias_{c}": rms_b,
                }
            )
        rows.append(row)
    g = gross
    return {
        "runs": runs,
        "bins": rows,
        "gross": {
            **g,
            "catch_rate": g["caught"] / g["n_gross"] if g["n_gross"] else None,
            "catch_rate_raw": (g["caught_raw"] / g["n_gross_raw"] if g["n_gross_raw"] else None),
            "catch_rate_bias": (
                g["caught_bias"] / g["n_gross_bias"] if g["n_gross_bias"] else None
            ),
            "false_rate": g["false"] / g["n_clean"] if g["n_clean"] else None,
        },
    }


def _write_mraw(path: Path, n: int, n_frames: int, exposure: float) -> Path:
    """A periodic recording as 8-bit .mraw: the 10 blurred phases of one cycle rendered
    once, camera noise drawn per frame."""
    tgt = vibrating_target(track_pattern(n), exposure=exposure, amplitude=10.0, static=10)
    from dicblur.blur import motion_blur

    dy, dx = math.sin(math.radians(20.0)), math.cos(math.radians(20.0))
    phases = {}
    for k in range(10, 20):
        t0 = k / tgt.fps

        def path_fn(tau, t0=t0):
            s = tgt.position(t0 + exposure * np.asarray(tau))
            return np.stack([s * dy, s * dx], axis=1)

        phases[k % 10] = motion_blur(tgt.pattern, None, substeps=None, trajectory=path_fn)
    rng = np.random.default_rng(0)
    with path.with_suffix(".mraw").open("wb") as fh:
        for k in range(n_frames):
            img = tgt.pattern if k < 10 else phases[k % 10]
            fh.write(tgt.camera.capture(img, rng=rng).astype(np.uint8).tobytes())
    head = path.with_suffix(".cih")
    head.write_text(
        "#Camera Information Header\n"
        + "".join(
            f"{k} : {v}\n"
            for k, v in {
                "Record Rate(fps)": 2000,
                "Shutter Speed(s)": exposure,
                "Total Frame": n_frames,
                "Original Total Frame": n_frames,
                "Image Width": n,
                "Image Height": n,
                "Color Type": "Mono",
                "Color Bit": 8,
                "File Format": "MRaw",
                "EffectiveBit Depth": 8,
                "EffectiveBit Side": "Lower",
            }.items()
        )
    )
    return head


def _engine_only(rec: Recording, ds, shape: str, step: int, workers: int, n_sample: int) -> dict:
    """The engine alone on the same frames: one prepared Correlator, frames in memory, each
    started from the field ``track`` measured there (the kernel's speed with the best
    guesses; no reading, extrapolation, fallback or prediction)."""
    kw: dict = {"subset": 21, "step": step, "shape": shape, "workers": workers}
    corr = dicblur.Correlator(rec.frame(0), **kw)
    frames = np.linspace(10, len(rec) - 1, n_sample).astype(int)
    imgs = [rec.frame(int(k)) for k in frames]
    guesses = []
    for k in frames:
        g = np.stack([ds["u"].sel(frame=k).values, ds["v"].sel(frame=k).values], axis=1)
        bad = ~np.isfinite(g).all(axis=1)
        g[bad] = np.median(g[~bad], axis=0)
        guesses.append(g)
    corr.correlate(imgs[0], initial=guesses[0])
    t0 = time.perf_counter()
    c0 = time.process_time()
    for img, g in zip(imgs, guesses, strict=True):
        corr.correlate(img, initial=g)
    dt = time.perf_counter() - t0
    cpu = time.process_time() - c0
    return {
        "frames": len(imgs),
        "seconds": dt,
        "frames_per_s": len(imgs) / dt,
        "cpu_s": cpu,
        "frames_per_cpu_s": len(imgs) / cpu,
    }


def speed(
    rec: Recording,
    shape: str,
    workers: int,
    step: int = 10,
    n_sample: int = 100,
    mode: str = "kernel",
) -> dict:
    """End to end (``dicblur.track`` as a user calls it: reading, guesses, correlation,
    flags, kinematics, sigma and the advice) against the engine alone in the same run.
    ``mode`` "kernel": the serial loop on ``workers`` kernel threads; "chunks": chunks of
    100 frames on ``workers`` threads of this process (``ChunkedRun(threads=workers)``,
    single-threaded kernels)."""
    from dicblur.track.parallel import ChunkedRun

    n_frames = len(rec)
    dicblur.Correlator(rec.frame(0), subset=21, step=step, shape=shape).warmup()  # type: ignore[arg-type]
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    c0 = time.process_time()
    kw: dict = {"subset": 21, "step": step, "shape": shape, "workers": workers}
    if mode == "chunks":
        kw["chunks"] = ChunkedRun(threads=workers)
    ds = dicblur.track(rec, static="0:10", **kw)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    eng = _engine_only(rec, ds, shape, step, workers, n_sample)
    tr = float(ds.attrs["tracking_time_s"])
    n_p = ds.sizes["point"]
    stages = {
        k: float(ds.attrs[k])
        for k in (
            "tracking_time_s",
            "correlation_time_s",
            "median_time_s",
            "blur_table_time_s",
            "prediction_time_s",
            "advice_time_s",
        )
        if k in ds.attrs
    }
    out = {
        "size": rec.shape[0],
        "frames": n_frames,
        "points": n_p,
        "shape": shape,
        "workers": workers,
        "mode": mode,
        "step": step,
        "tracking_s": tr,
        "frames_per_s": n_frames / tr,
        "poi_per_s": n_frames * n_p / tr,
        "end_to_end_s": wall,
        "end_to_end_frames_per_s": n_frames / wall,
        "end_to_end_poi_per_s": n_frames * n_p / wall,
        "engine_frames_per_s": eng["frames_per_s"],
        "engine_poi_per_s": eng["frames_per_s"] * n_p,
        "loop_over_engine": (n_frames / tr) / eng["frames_per_s"],
        "end_to_end_over_engine": (n_frames / wall) / eng["frames_per_s"],
        "fallback_frames": int(ds["fallback"].values.sum()),
        "stages_s": stages,
        "cpu_s": cpu,
        "frames_per_cpu_s": n_frames / cpu,
        "engine_frames_per_cpu_s": eng["frames_per_cpu_s"],
        # the same ratio in CPU time: less sensitive to the other processes' load
        "end_to_end_over_engine_cpu": (n_frames / cpu) / eng["frames_per_cpu_s"],
        "load_start": load0,
        "load_end": os.getloadavg()[0],
        "valid_share": float(ds["valid"].values.mean()),
        "tolerance_px": float(ds.attrs.get("tolerance", float("nan"))),
    }
    print(
        f"speed {out['size']}^2 x {n_frames} frames, {n_p} POIs ({shape}, {workers} "
        f"thread(s), {mode}): end to end {wall:.1f} s = "
        f"{out['end_to_end_frames_per_s']:.1f} frames/s "
        f"= {out['end_to_end_poi_per_s']:.0f} POI/s; tracking loop "
        f"{out['frames_per_s']:.1f} frames/s; engine alone {eng['frames_per_s']:.1f} frames/s; "
        f"end to end / engine {out['end_to_end_over_engine']:.2f}, loop / engine "
        f"{out['loop_over_engine']:.2f}; CPU: end to end {out['frames_per_cpu_s']:.1f}, engine "
        f"{eng['frames_per_cpu_s']:.1f} frames per CPU-s, ratio "
        f"{out['end_to_end_over_engine_cpu']:.2f}; stages "
        f"{', '.join(f'{k[:-7]} {v:.1f}' for k, v in stages.items())} s; "
        f"fallback {out['fallback_frames']}; load {load0:.1f} -> {out['load_end']:.1f}",
        flush=True,
    )
    del ds
    return out


def memory_child(head: str, step: int) -> None:
    rec = open_recording(head)
    t0 = time.perf_counter()
    ds = dicblur.track(rec, static="0:10", subset=21, step=step, shape="translation", advice=False)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(
        json.dumps(
            {
                "peak_rss_mb": peak,
                "frames": ds.sizes["frame"],
                "points": ds.sizes["point"],
                "seconds": time.perf_counter() - t0,
            }
        )
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--memory", action="store_true")
    ap.add_argument(
        "--part",
        choices=("all", "accuracy", "speed", "memory"),
        default="all",
        help="accuracy -> results/track.json, speed (and --memory) -> "
        "results/track_speed.json; memory alone -> results/track_memory.json",
    )
    ap.add_argument("--threads", default="1,2", help="speed: kernel threads (<= NUMBA_NUM_THREADS)")
    ap.add_argument("--shapes", default="affine,translation", help="speed: subset shapes")
    ap.add_argument(
        "--modes",
        default="kernel,chunks",
        help="speed: kernel (serial loop, --threads kernel threads) and/or chunks (chunks "
        "of 100 frames on --threads threads of the process)",
    )
    ap.add_argument("--memory-child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.memory_child:
        memory_child(args.memory_child[0], int(args.memory_child[1]))
        return
    n, frames = (256, 40) if args.quick else (512, 60)
    exposures = [0.1e-3, 0.25e-3, 0.45e-3] if args.quick else [0.1e-3, 0.2e-3, 0.3e-3, 0.45e-3]
    res: dict = {
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load": os.getloadavg(),
            "numba_threads": os.environ.get("NUMBA_NUM_THREADS"),
        },
        "commit": _commit(),
        "version": dicblur.__version__,
        "quick": args.quick,
    }
    tag = "_quick" if args.quick else ""
    if args.part in ("all", "accuracy"):
        res["accuracy"] = accuracy(n, frames, exposures, "affine")
        print(
            "\n| W (px) | n | pred u | std u | ratio u | rms u | rms u - bias | pred v | "
            "std v | ratio v | rms v | rms v - bias |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in res["accuracy"]["bins"]:
            print(
                f"| {r['W_lo']:.1f}-{r['W_hi']:.1f} | {r['n']} | {r['pred_u']:.4f} | "
                f"{r['std_u']:.4f} | {r['ratio_u']:.3f} | {r['rms_u']:.4f} | "
                f"{r['rms_minus_bias_u']:.4f} | {r['pred_v']:.4f} | {r['std_v']:.4f} | "
                f"{r['ratio_v']:.3f} | {r['rms_v']:.4f} | {r['rms_minus_bias_v']:.4f} |"
            )
        g = res["accuracy"]["gross"]
        print(
            f"\ngross errors > 10 sigma (about the frame's common offset): {g['n_gross']}, "
            f"caught {g['catch_rate']}; false flags {g['false']} of {g['n_clean']} "
            f"({g['false_rate']}); raw errors > 10 sigma: {g['n_gross_raw']}, caught "
            f"{g['catch_rate_raw']}; about the predicted bias: {g['n_gross_bias']}, "
            f"caught {g['catch_rate_bias']}"
        )
        _write(OUT.with_name(f"track{tag}.json"), res)
    if args.part in ("all", "speed"):
        out: dict = {k: res[k] for k in ("machine", "commit", "version", "quick")}
        with tempfile.TemporaryDirectory(dir="/tmp") as tmp:
            sn, sf = (256, 200) if args.quick else (512, 1000)
            rec = open_recording(_write_mraw(Path(tmp) / "speed", sn, sf, 0.2e-3))
            threads = [int(t) for t in args.threads.split(",")]
            # imported once per process, not per recording: outside the timing
            importlib.import_module("dicblur.track")

            out["speed"] = [
                speed(rec, shape, t, mode=m)
                for shape in args.shapes.split(",")
                for m in args.modes.split(",")
                for t in threads
                if not (m == "chunks" and t == 1 and "kernel" in args.modes)
            ]
            rec.close()
            if args.memory:
                out["memory"] = _memory(Path(tmp))
        _write(OUT.with_name(f"track_speed{tag}.json"), out)
    if args.part == "memory":
        with tempfile.TemporaryDirectory(dir="/tmp") as tmp:
            mem = {k: res[k] for k in ("machine", "commit", "version")}
            mem["memory"] = _memory(Path(tmp))
        _write(OUT.with_name("track_memory.json"), mem)


def _memory(folder: Path) -> dict:
    head = _write_mraw(folder / "mem", 1024, 2000, 0.2e-3)
    r = subprocess.run(
        [sys.executable, __file__, "--memory-child", str(head), "20"],
        capture_output=True,
        text=True,
        check=True,
    )
    out = json.loads(r.stdout.strip().splitlines()[-1])
    print(f"memory: {out}")
    return out


def _write(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, default=float))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
