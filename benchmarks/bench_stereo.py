"""Stereo DIC under motion blur on the synthetic laboratory (issue 29, docs/stereo.md).

Accuracy: a speckled plane facing the rig's bisector, 400 mm from a symmetric rig of
stereo angle 15, 30 or 45 deg (2000 px focal length, 0.2 mm/px), vibrating as
``A (1 - cos 2 pi f t)`` either in-plane (along the rig's x, in the target plane) or
out-of-plane (along its normal), with the peak blur in the more blurred camera near
``--peak-w`` px; the exposure is the whole frame interval, so a frame moves about its blur.
Each case renders its frames (supersampled ray casting, noise 2 GL) and tracks them with
``dicblur.stereo.track``. Reported per case: the shape error against the truth (mean and
scatter, against the predicted sigma), the 3-D displacement bias, and per bin of the
point's largest blur (of the two cameras) the predicted sigma_U, sigma_V, sigma_W3 (RMS over
the bin) against the measured scatter over points (rms of the error about its frame's mean;
the frame means apart, as bias).

Speed: 2 x ``--pairs`` frames of 512^2 (8 distinct renderings of a slow in-plane motion,
played back and forth so that the motion stays continuous), subset 21, step 10 (2,401
POIs), affine: frame pairs per second of the correlation loop and end to end.

Run: ``python benchmarks/bench_stereo.py [--quick]`` (results/stereo.json).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import itertools

from _harness import Run

from dicblur.camera import Camera
from dicblur.stereo import CameraModel, track
from dicblur.stereo.core import ArrayRecording
from dicblur.stereo.synthetic import SpeckleTarget, StereoLab, symmetric_rig

FPS = 2000.0
BINS = (0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.5)


def lab_for(
    angle: float, motion: str, size: int, peak_w: float, frames_per_cycle: int
) -> StereoLab:
    cam = CameraModel(
        2000.0, 2000.0, (size - 1) / 2, (size - 1) / 2, (-0.05, 0, 0, 0, 0), (size, size)
    )
    rig = symmetric_rig(stereo_angle=angle, distance=400.0, camera=cam)
    tgt = SpeckleTarget.speckled(
        rig=rig, origin=(0.0, 0.0, 400.0), size=80.0, speckle_size=1.0, seed=11
    )
    es, _, n = tgt.frame()
    axis = es if motion == "in-plane" else n
    # blur per mm of motion in each camera, at the target's centre
    x0 = np.asarray(tgt.origin)
    gain = max(
        float(np.linalg.norm(a - b))
        for a, b in zip(rig.project(x0 + 0.5 * axis), rig.project(x0 - 0.5 * axis), strict=True)
    )
    f = FPS / frames_per_cycle
    exposure = 1.0 / FPS
    # the peak motion during one exposure of A (1 - cos): 2 A sin(pi f T) at the fastest
    amp = peak_w / gain / (2 * math.sin(math.pi * f * exposure))

    def traj(t: np.ndarray) -> np.ndarray:
        return amp * (1 - np.cos(2 * np.pi * f * t))[:, None] * axis[None, :]

    return StereoLab(
        rig,
        tgt,
        traj,
        exposure=exposure,
        fps=FPS,
        camera=Camera(read_noise=2.0, bit_depth=None),
        supersample=2,
    )


def accuracy_case(angle: float, motion: str, *, size: int, frames: int, peak_w: float) -> dict:
    lab = lab_for(angle, motion, size, peak_w, frames_per_cycle=frames - 1)
    t0 = time.perf_counter()
    pairs = [lab.render(k, seed=1000 + k) for k in range(frames)]
    t_render = time.perf_counter() - t0
    left = np.array([p[0] for p in pairs])
    right = np.array([p[1] for p in pairs])
    ds = track(
        left,
        right,
        lab.rig,
        exposure=lab.exposure,
        fps=FPS,
        noise=2.0,
        subset=21,
        step=10,
        threads=2,
    )
    rc = np.stack([ds["row"].values, ds["col"].values], axis=1)
    ok = ds["status_stereo"].values == 0
    truth = lab.surface_point(rc, frame=0)
    shape = np.stack([ds[c].values for c in "XYZ"], axis=1)
    err_s = (shape - truth)[ok]
    pred_s = np.stack([ds[f"sigma_{c}"].values for c in "XYZ"], axis=1)[ok]
    valid = ds["valid"].values.astype(bool)
    errs, cen, sigs, wmax = [], [], [], []
    for k in range(1, frames):
        d = lab.mean_displacement(k) - lab.mean_displacement(0)
        v = valid[k]
        e = np.stack([ds[c].values[k] for c in ("U", "V", "W3")], axis=1)[v] - d
        s = np.stack([ds[f"sigma_{c}"].values[k] for c in ("U", "V", "W3")], axis=1)[v]
        errs.append(e)
        # sigma predicts the scatter over points; the frame's common error (the skewed
        # kernel of an accelerating blur, the interpolation's bias) is reported as bias
        cen.append(e - e.mean(axis=0))
        sigs.append(s)
        wmax.append(np.maximum(ds["W_left"].values[k][v], ds["W_right"].values[k][v]))
    e, s, w = np.concatenate(errs), np.concatenate(sigs), np.concatenate(wmax)
    ec = np.concatenate(cen)
    bins = []
    for lo, hi in itertools.pairwise(BINS):
        m = (w >= lo) & (w < hi)
        if m.sum() < 100:
            continue
        for j, comp in enumerate(("U", "V", "W3")):
            pred = float(np.sqrt(np.mean(s[m, j] ** 2)))
            meas = float(np.sqrt(np.mean(ec[m, j] ** 2)))
            bins.append(
                {
                    "W_lo": lo,
                    "W_hi": hi,
                    "n": int(m.sum()),
                    "component": comp,
                    "predicted": pred,
                    "measured": meas,
                    "ratio": pred / meas,
                    "bias": float(np.mean(e[m, j])),
                    "frame_bias_rms": float(np.sqrt(np.mean((e[m, j] - ec[m, j]) ** 2))),
                }
            )
    return {
        "stereo_angle": angle,
        "motion": motion,
        "size": size,
        "frames": frames,
        "peak_W": float(np.nanmax(w)) if w.size else float("nan"),
        "render_s": t_render,
        "track_s": float(ds.attrs["total_time_s"]),
        "stereo_matched": float(ok.mean()),
        "valid_share": float(valid[1:].mean()),
        "shape_error_mean_mm": err_s.mean(axis=0).tolist(),
        "shape_error_std_mm": err_s.std(axis=0).tolist(),
        "shape_sigma_pred_mm": np.sqrt(np.mean(pred_s**2, axis=0)).tolist(),
        "displacement_bias_mm": e.mean(axis=0).tolist(),
        "out_of_plane_over_in_plane_pred": float(
            np.sqrt(np.mean(s[:, 2] ** 2)) / np.sqrt(np.mean(s[:, 0] ** 2))
        ),
        "bins": bins,
    }


SPEED_SIZE = 512


def speed_rig():
    cam = CameraModel(2000.0, 2000.0, 255.5, 255.5, (-0.05, 0, 0, 0, 0), (SPEED_SIZE, SPEED_SIZE))
    return symmetric_rig(stereo_angle=30.0, distance=400.0, camera=cam)


def speed_frames(folder: Path) -> tuple[Path, float]:
    """The 8 distinct 512^2 pairs of the speed run (rendered once into ``folder``), and
    the render time (0 when reused)."""
    path = folder / "stereo_speed_frames.npz"
    if path.exists():
        return path, 0.0
    rig = speed_rig()
    tgt = SpeckleTarget.speckled(
        rig=rig, origin=(0.0, 0.0, 400.0), size=120.0, speckle_size=0.8, seed=3
    )
    es = tgt.frame()[0]

    def traj(t: np.ndarray) -> np.ndarray:  # 0.1 mm (0.5 px) per frame along the surface
        return (0.1 * FPS * t)[:, None] * es[None, :]

    lab = StereoLab(
        rig,
        tgt,
        traj,
        exposure=0.2 / FPS,
        fps=FPS,
        supersample=1,
        substeps=4,
        camera=Camera(read_noise=2.0, bit_depth=None),
    )
    t0 = time.perf_counter()
    base = [lab.render(k, seed=k) for k in range(8)]
    t_render = time.perf_counter() - t0
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / "stereo_speed_frames.tmp.npz"
    np.savez(tmp, left=np.array([p[0] for p in base]), right=np.array([p[1] for p in base]))
    tmp.replace(path)
    return path, t_render


def speed_run(frames: Path, pairs: int) -> dict:
    """One timed ``dicblur.stereo.track`` of ``pairs`` frame pairs (the 8 renderings played
    0..7..1 and again: a continuous motion) in this process, with whichever dicblur is on
    the path; its phases, CPU time and the write of the Dataset."""
    import os
    import tempfile

    with np.load(frames) as z:
        bl, br = z["left"], z["right"]
    order = [k % 14 for k in range(pairs)]
    order = [k if k < 8 else 14 - k for k in order]
    left = ArrayRecording([bl[k] for k in order], "left")
    right = ArrayRecording([br[k] for k in order], "right")
    c0, t0 = time.process_time(), time.perf_counter()
    ds = track(
        left,
        right,
        speed_rig(),
        exposure=0.2 / FPS,
        fps=FPS,
        noise=2.0,
        subset=21,
        step=10,
        threads=2,
    )
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    with tempfile.TemporaryDirectory() as tmp:
        tw = time.perf_counter()
        ds.to_netcdf(Path(tmp) / "stereo.nc")
        t_write = time.perf_counter() - tw
    a = ds.attrs
    track_s = float(a["tracking_time_s"])
    pred_s = float(a["prediction_time_s"])
    tri_s = float(a.get("triangulation_time_s", float("nan")))
    setup_s = float(a.get("setup_time_s", float("nan")))
    out = {
        "pairs": pairs,
        "points": int(ds.sizes["point"]),
        "setup_s": setup_s,
        "tracking_s": track_s,
        "triangulation_s": tri_s,
        "prediction_s": pred_s,
        "wall_s": wall,
        "write_s": t_write,
        "cpu_s": cpu,
        "pairs_per_s_tracking": pairs / track_s,
        "pairs_per_s_end_to_end": pairs / wall,
        "pairs_per_cpu_s": pairs / cpu,
        "valid_share": float(ds["valid"].values.mean()),
        "load": list(os.getloadavg()),
    }
    # the fields, for the comparison of two versions (within the convergence tolerance)
    out["_fields"] = {v: ds[v].values for v in ("U", "V", "W3", "sigma_W3", "status")}
    return out


def _child(frames: str, pairs: int, fields: str) -> None:
    r = speed_run(Path(frames), pairs)
    np.savez(fields, **r.pop("_fields"))
    print("RESULT " + json.dumps(r), flush=True)


def speed_side_by_side(pairs: int, *, baseline: str | None, repeat: int, folder: Path) -> dict:
    """The speed run of this source and, with ``baseline`` (the ``src`` folder of another
    version, e.g. ``git archive <commit> src | tar -x -C /tmp/base``), of that version,
    each in its own process, alternated ``repeat`` times (the machine is shared: the
    ratio of runs next to each other in time); the fields compared."""
    import os
    import subprocess

    frames, t_render = speed_frames(folder)
    here = str(Path(__file__).resolve().parents[1] / "src")
    versions = [("this", here)] + ([("baseline", baseline)] if baseline else [])
    runs: dict[str, list[dict]] = {name: [] for name, _ in versions}
    fields: dict[str, str] = {}
    for i in range(repeat):
        for name, src in versions if i % 2 == 0 else versions[::-1]:
            env = dict(os.environ, PYTHONPATH=src)
            if name == "baseline":
                env["NUMBA_CACHE_DIR"] = str(folder / "numba_baseline")
            fields[name] = str(folder / f"stereo_speed_{name}.npz")
            cmd = [sys.executable, __file__, "--speed-child", str(frames), "--pairs", str(pairs)]
            cmd += ["--fields", fields[name]]
            got = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
            line = [x for x in got.stdout.splitlines() if x.startswith("RESULT ")]
            if got.returncode != 0 or not line:
                raise RuntimeError(f"{name} speed run failed:\n{got.stderr[-3000:]}")
            r = json.loads(line[-1][7:])
            runs[name].append(r)
            print(
                f"speed {name:8s} run {i + 1}: {r['pairs_per_s_end_to_end']:.1f} pairs/s end to "
                f"end, {r['pairs_per_s_tracking']:.1f} in the loop, {r['pairs_per_cpu_s']:.1f} "
                f"per CPU s (setup {r['setup_s']:.2f} s, loop {r['tracking_s']:.2f} s, "
                f"triangulation {r['triangulation_s']:.2f} s, sigma {r['prediction_s']:.2f} s, "
                f"write {r['write_s']:.2f} s), load {r['load'][0]:.1f}",
                flush=True,
            )
    out: dict = {"size": SPEED_SIZE, "pairs": pairs, "render_s": t_render, "runs": runs}
    best = {k: max(v, key=lambda r: r["pairs_per_s_end_to_end"]) for k, v in runs.items()}
    out.update({k: best["this"][k] for k in best["this"] if k != "load"})
    if baseline:
        out["baseline_src"] = baseline
        ratios = {}
        for key in ("pairs_per_s_end_to_end", "pairs_per_s_tracking", "pairs_per_cpu_s"):
            ratios[key] = [
                a[key] / b[key] for a, b in zip(runs["this"], runs["baseline"], strict=True)
            ]
        out["ratio_this_over_baseline"] = ratios
        with np.load(fields["this"]) as a, np.load(fields["baseline"]) as b:
            same = a["status"] == b["status"]
            ok = same & (a["status"] == 0)
            out["status_agree"] = float(same.mean())
            out["max_abs_diff_mm"] = {
                v: float(np.nanmax(np.abs(a[v][ok] - b[v][ok]))) for v in ("U", "V", "W3")
            }
            out["max_abs_diff_sigma_W3_mm"] = float(
                np.nanmax(np.abs(a["sigma_W3"][ok] - b["sigma_W3"][ok]))
            )
        print(
            "speed this/baseline: end to end "
            + ", ".join(f"{x:.2f}" for x in ratios["pairs_per_s_end_to_end"])
            + "; loop "
            + ", ".join(f"{x:.2f}" for x in ratios["pairs_per_s_tracking"])
            + f"; statuses agree {out['status_agree']:.4f}, max |dU, dV, dW3| "
            + ", ".join(f"{x:.1e}" for x in out["max_abs_diff_mm"].values())
            + " mm",
            flush=True,
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller images, fewer frames")
    ap.add_argument("--part", choices=("all", "accuracy", "speed"), default="all")
    ap.add_argument("--peak-w", type=float, default=6.0, help="peak blur, px")
    ap.add_argument("--pairs", type=int, default=None, help="frame pairs of the speed run")
    ap.add_argument("--baseline", default=None, help="src folder of a version to compare")
    ap.add_argument("--repeat", type=int, default=2, help="alternated speed runs per version")
    ap.add_argument("--folder", default="/tmp/dicblur_bench_stereo", help="frames cache")
    ap.add_argument(
        "--report",
        default=None,
        help="folder of an HTML page with the predicted-vs-measured figure of the accuracy part",
    )
    ap.add_argument(
        "--from-json",
        default=None,
        help="with --report: draw it from an existing result (results/stereo.json), no run",
    )
    ap.add_argument("--speed-child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--fields", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    pairs = args.pairs or (60 if args.quick else 500)
    if args.speed_child:
        _child(args.speed_child, pairs, args.fields)
        return
    if args.from_json:
        if not args.report:
            ap.error("--from-json needs --report DIR")
        from dicblur.report.stereo import write_validation_report

        doc = json.loads(Path(args.from_json).read_text())
        print(f"wrote {write_validation_report(doc, Path(args.report))}")
        return
    run = Run("stereo" if args.part == "all" else f"stereo_{args.part}")
    size, frames = (128, 9) if args.quick else (192, 13)
    cases = []
    angles = (15.0, 45.0) if args.quick else (15.0, 30.0, 45.0)
    for angle in angles if args.part != "speed" else ():
        for motion in ("in-plane", "out-of-plane"):
            c = accuracy_case(angle, motion, size=size, frames=frames, peak_w=args.peak_w)
            cases.append(c)
            print(
                f"{angle:4.0f} deg {motion:13s} peak W {c['peak_W']:.2f} px, matched "
                f"{c['stereo_matched']:.3f}, valid {c['valid_share']:.3f}, shape std "
                f"{np.round(c['shape_error_std_mm'], 5)} pred "
                f"{np.round(c['shape_sigma_pred_mm'], 5)} mm, bias "
                f"{np.round(c['displacement_bias_mm'], 5)} mm",
                flush=True,
            )
            for b in c["bins"]:
                print(
                    f"   W {b['W_lo']:.0f}-{b['W_hi']:.1f} {b['component']:2s} n {b['n']:5d} "
                    f"pred {b['predicted']:.5f} meas {b['measured']:.5f} "
                    f"ratio {b['ratio']:.2f}",
                    flush=True,
                )
    speed = None
    if args.part != "accuracy":
        speed = speed_side_by_side(
            pairs, baseline=args.baseline, repeat=args.repeat, folder=Path(args.folder)
        )
    ratios = [b["ratio"] for c in cases for b in c["bins"]]
    summary = {
        "bins": len(ratios),
        "ratio_min": min(ratios) if ratios else None,
        "ratio_max": max(ratios) if ratios else None,
        "within_20_percent": sum(0.8 <= r <= 1.2 for r in ratios),
    }
    if ratios:
        print(
            f"predicted/measured over {summary['bins']} bins: {summary['ratio_min']:.2f}-"
            f"{summary['ratio_max']:.2f}, {summary['within_20_percent']} within 20 %"
        )
    doc = {"quick": args.quick, "cases": cases, "summary": summary}
    if speed is not None:
        doc["speed"] = speed
    out = run.write(doc)
    print(f"wrote {out}")
    if args.report and cases:
        from dicblur.report.stereo import write_validation_report

        print(f"wrote {write_validation_report(doc, Path(args.report))}")


if __name__ == "__main__":
    main()
