"""Stereo tracking (issue 29) on the synthetic laboratory: the triangulated shape and the
3-D displacement match the truth, the predicted sigma the measured scatter; the CLI writes
its outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dicblur.camera import Camera
from dicblur.cli import main
from dicblur.stereo import CameraModel, save_rig, track
from dicblur.stereo.synthetic import SpeckleTarget, StereoLab, symmetric_rig

pytestmark = pytest.mark.slow  # rendering and the blur tables: ~10-20 s per case

FPS, EXPOSURE = 2000.0, 0.4e-3


def _lab(kind: str, size: int = 160) -> StereoLab:
    cam = CameraModel(
        2000.0, 2000.0, (size - 1) / 2, (size - 1) / 2, (-0.05, 0, 0, 0, 0), (size, size)
    )
    rig = symmetric_rig(stereo_angle=30.0, distance=400.0, camera=cam)
    tgt = SpeckleTarget.speckled(
        kind=kind,
        rig=rig,
        origin=(0.0, 0.0, 400.0),
        size=40.0,
        radius=40.0,
        speckle_size=0.8,
        seed=5,
    )

    def traj(t):  # out-of-plane and in-plane vibration: W up to ~0.8 px
        w = 2 * np.pi * 150.0 * t
        return np.stack([0.4 * np.sin(w), 0.12 * np.sin(w), 1.0 * (1 - np.cos(w))], axis=1)

    return StereoLab(
        rig, tgt, traj, exposure=EXPOSURE, fps=FPS, camera=Camera(read_noise=2.0, bit_depth=None)
    )


def _frames(lab: StereoLab, n: int):
    fr = [lab.render(k, seed=100 + k) for k in range(n)]
    return np.array([f[0] for f in fr]), np.array([f[1] for f in fr])


@pytest.mark.parametrize("kind", ["plane", "cylinder"])
def test_shape_and_displacement_match_the_truth(kind):
    lab = _lab(kind)
    left, right = _frames(lab, 8)
    ds = track(left, right, lab.rig, exposure=EXPOSURE, fps=FPS, noise=2.0, subset=21, step=12)
    ok = ds["status_stereo"].values == 0
    assert ok.mean() > 0.95
    rc = np.stack([ds["row"].values, ds["col"].values], axis=1)
    truth = lab.surface_point(rc, frame=0)  # the reference pair shows its mean position
    err = np.stack([ds["X"].values, ds["Y"].values, ds["Z"].values], axis=1) - truth
    pred = np.stack([ds[f"sigma_{c}"].values for c in "XYZ"], axis=1)
    p_rms = np.sqrt(np.mean(pred[ok] ** 2, axis=0))
    if kind == "plane":
        # the shape's scatter is its predicted noise (X: 0.05 um of floor, the reference
        # pair's own blur mismatch, not in the noise sigma); its mean error (a common offset
        # of the match, ~0.01 px of disparity: docs/stereo.md) under 2 sigma
        assert np.all(err[ok].std(axis=0) < 1.4 * p_rms + 5e-5), (err[ok].std(axis=0), p_rms)
        assert np.all(err[ok].std(axis=0) > 0.6 * p_rms), (err[ok].std(axis=0), p_rms)
        assert np.all(np.abs(err[ok].mean(axis=0)) < 2.0 * p_rms), (err[ok].mean(axis=0), p_rms)
    else:
        # a curved surface: the affine subset misses its curvature (docs/stereo.md), an
        # error of the model beyond the noise; still within 0.05 mm (0.25 px) of depth
        assert np.sqrt(np.mean(err[ok] ** 2, axis=0)).max() < 0.05, err[ok].std(axis=0)
    valid = ds["valid"].values.astype(bool)
    assert valid[1:].mean() > 0.9
    e_all, s_all = [], []
    for k in range(1, 8):
        d0 = lab.mean_displacement(k) - lab.mean_displacement(0)
        v = valid[k]
        e = np.stack([ds["U"].values[k], ds["V"].values[k], ds["W3"].values[k]], 1)[v] - d0
        s = np.stack([ds[f"sigma_{c}"].values[k] for c in ("U", "V", "W3")], 1)[v]
        e_all.append(e)
        s_all.append(s)
        # no bias beyond a fraction of the single-point sigma
        assert np.all(np.abs(e.mean(axis=0)) < 1.5 * np.sqrt(np.mean(s**2, axis=0)))
    e, s = np.concatenate(e_all), np.concatenate(s_all)
    ratio = np.sqrt(np.mean(s**2, axis=0)) / e.std(axis=0)
    assert np.all((ratio > 0.7) & (ratio < 1.4)), ratio
    assert float(np.nanmax(ds["W_left"].values)) > 0.6  # the case has blur in it


def test_cli_track_writes_dataset_csv_and_report(tmp_path, capsys):
    import xarray as xr

    from dicblur.io import save_image

    lab = _lab("plane", size=128)
    left, right = _frames(lab, 5)
    for side, fr in (("L", left), ("R", right)):
        (tmp_path / side).mkdir()
        for k, img in enumerate(fr):
            save_image(tmp_path / side / f"f{k:03d}.tif", np.clip(img, 0, 255) * 256, bit_depth=16)
    save_rig(lab.rig, tmp_path / "rig.json")
    out = tmp_path / "out"
    code = main(
        [
            "stereo",
            "track",
            str(tmp_path / "L"),
            str(tmp_path / "R"),
            "--rig",
            str(tmp_path / "rig.json"),
            "--exposure",
            "0.4ms",
            "--fps",
            "2kHz",
            "--noise",
            "512",
            "--step",
            "12",
            "--csv",
            "-o",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    ds = xr.open_dataset(out / "stereo.nc", engine="scipy")
    assert {"X", "Y", "Z", "U", "V", "W3", "sigma_U", "sigma_V", "sigma_W3", "status"} <= set(
        ds.data_vars
    )
    assert ds["valid"].values.mean() > 0.8
    header = (out / "stereo.csv").read_text().splitlines()[0].split(",")
    assert header[:5] == ["frame", "time", "point", "row", "col"] and "sigma_W3" in header
    page = (out / "report.html").read_text()
    assert 'id="fig-shape' in page and "data:image/png;base64" in page
    json.dumps(dict(ds.attrs), default=str)


def test_bad_frame_keeps_the_pairs_tracked_before_it(tmp_path, capsys):
    """A frame of another size in the right recording's middle: the pairs tracked before
    it are kept (complete = 0) and written by the CLI, as dicblur track does (they were
    lost: one error line and no output)."""
    import xarray as xr

    from dicblur.errors import ImageReadError
    from dicblur.io import save_image
    from dicblur.track import TrackInterrupted

    lab = _lab("plane", size=128)
    left, right = _frames(lab, 7)
    for side, fr in (("L", left), ("R", right)):
        (tmp_path / side).mkdir()
        for k, img in enumerate(fr):
            a = np.clip(img, 0, 255) * 256
            save_image(tmp_path / side / f"f{k}.tif", a[:-4] if (side, k) == ("R", 5) else a,
                       bit_depth=16)  # fmt: skip
    save_rig(lab.rig, tmp_path / "rig.json")
    kw = {"exposure": EXPOSURE, "fps": FPS, "noise": 512.0, "step": 12}
    with pytest.raises(TrackInterrupted, match="after 5 of 7 frames") as info:
        track(str(tmp_path / "L"), str(tmp_path / "R"), lab.rig, **kw)
    ds = info.value.dataset
    assert isinstance(info.value.__cause__, ImageReadError)
    assert ds["frame"].values.tolist() == [0, 1, 2, 3, 4] and int(ds.attrs["complete"]) == 0
    assert ds["valid"].values[:3].mean() > 0.8
    code = main(
        ["stereo", "track", str(tmp_path / "L"), str(tmp_path / "R"), "--rig",
         str(tmp_path / "rig.json"), "--exposure", "0.4ms", "--fps", "2kHz", "--noise", "512",
         "--step", "12", "--no-report", "-o", str(tmp_path / "out")]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "f5.tif" in err and "Traceback" not in err
    part = xr.open_dataset(tmp_path / "out" / "stereo.nc", engine="scipy")
    assert part.sizes["frame"] == 5 and int(part.attrs["complete"]) == 0


def test_subsets_with_clipped_pixels_in_either_camera_are_not_valid():
    """A clipped (over-exposed) patch in the right camera: the points whose right subset
    holds clipped pixels are marked, those over a quarter clipped are not valid, the others
    stay valid (as dicblur track's `saturated`)."""
    lab = _lab("plane", size=128)
    left, right = _frames(lab, 5)
    right[:, 40:60, 40:60] = 255.0  # the sensor's top level
    left = np.clip(left, 0, 254.0)
    ds = track(left, right, lab.rig, exposure=EXPOSURE, fps=FPS, noise=2.0, subset=21, step=12)
    sat_r, sat_l = ds["saturated_right"].values, ds["saturated_left"].values
    rr, rc = ds["right_row"].values, ds["right_col"].values
    h = 10
    touches = (rr + h >= 39.5) & (rr - h <= 59.5) & (rc + h >= 39.5) & (rc - h <= 59.5)
    touches &= np.isfinite(rr)
    assert (sat_r > 0).sum() >= 4 and not (sat_l > 0).any()
    # the right subset sits at the rounded match: a half-pixel margin at the patch's edge
    assert np.all(touches[sat_r > 0])
    from dicblur.track.saturation import SATURATION_MAX_SHARE

    over = sat_r > SATURATION_MAX_SHARE  # a few clipped pixels leave the sigma true
    assert over.any()
    valid = ds["valid"].values.astype(bool)
    assert not valid[:, over].any()
    assert valid[:, ~over & (ds["status_stereo"].values == 0)].mean() > 0.9
    assert "clipped" in ds.attrs["notes"]
