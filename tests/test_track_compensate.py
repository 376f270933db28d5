"""dicblur track --compensate-blur (issue 18): the compensated matcher on a recording."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur.track.compensate import (
    MATCHER_COMPENSATED,
    build_compensated_table,
    group_vectors,
)
from dicblur.track.uncertainty import build_blur_table
from helpers.track import track_pattern, vibrating_target


def _target(n=128, seed=5):
    # peak W = A 2 pi f T = 5.7 px
    p = track_pattern(n, seed=seed)
    return vibrating_target(p, exposure=0.45e-3, amplitude=10.0, static=6, seed=21)


def _groups(tgt, ds, edges):
    """Per W group: (rms of the error's scatter over points, rms predicted sigma), along x
    and y (the frame's mean error removed: the scatter sigma predicts)."""
    tu, tv, bu, bv = tgt.truth(ds["frame"].values)
    valid = ds["valid"].values.astype(bool)
    w = np.broadcast_to(np.hypot(bu, bv)[:, None], valid.shape)
    out = []
    for lo, hi in edges:
        row = []
        for c, truth in (("u", tu), ("v", tv)):
            e = ds[c].values - truth[:, None]
            e = e - np.nanmean(np.where(valid, e, np.nan), axis=1, keepdims=True)
            sel = valid & (w >= lo) & (w < hi)
            assert sel.sum() > 300
            rms = float(np.sqrt(np.mean(e[sel] ** 2)))
            row.append((rms, float(np.sqrt(np.mean(ds[f"sigma_{c}"].values[sel] ** 2)))))
        out.append(row)
    return out


@pytest.fixture(scope="module")
def both():
    tgt = _target()
    rec = tgt.recording(26)
    kw = {"static": "0:6", "subset": 21, "step": 10, "advice": False}
    return tgt, dicblur.track(rec, **kw), dicblur.track(rec, compensate_blur=True, **kw)


def test_compensation_lowers_the_error_and_sigma_follows(both):
    """A 128^2 target vibrating 10 px at 200 Hz, T = 0.45 ms (W up to 5.7 px): at W = 4-6 px
    the compensated matcher's scatter is < 1/3 of the plain one's (measured along x / y:
    0.0576 / 0.0398 px plain, 0.0081 / 0.0064 px compensated), and its predicted sigma
    matches the scatter within 20 % per group of W (measured 0.89-1.16, the plain
    matcher's 0.89-1.16)."""
    tgt, plain, comp = both
    assert plain.attrs["matcher"] == "plain" and comp.attrs["matcher"] == MATCHER_COMPENSATED
    assert comp.attrs["compensation_passes"] == 2  # the plain track's blur moved > 0.01 px
    edges = [(0.0, 1.0), (1.0, 4.0), (4.0, 6.0)]
    gp, gc = _groups(tgt, plain, edges), _groups(tgt, comp, edges)
    (pu, _), (pv, _) = gp[2]
    (cu, _), (cv, _) = gc[2]
    assert cu < pu / 3 and cv < pv / 3, (gp[2], gc[2])
    for groups in (gp, gc):
        for row in groups:
            for meas, pred in row:
                assert 0.8 <= pred / meas <= 1.2, groups
    # with compensation the mismatch part is gone; the noise part carries the blur
    valid = comp["valid"].values.astype(bool)
    assert np.all(comp["sigma_u_blur"].values[valid] == 0)
    assert np.nanmax(comp["blur_dominated_share"].values) == 0
    assert comp.sizes == plain.sizes and valid.mean() > 0.8


def test_compensated_table_at_zero_blur_equals_the_plain_noise_term():
    """At W = 0 the compensated matcher is the plain one: its noise term per point (both
    images' noise) equals the plain table's within 1 %."""
    img = _target(96).pattern
    pts = np.array([[r, c] for r in range(20, 80, 12) for c in range(20, 80, 12)])
    w = np.zeros((1, len(pts)))
    ang = np.zeros((1, len(pts)))
    for shape in ("translation", "affine"):
        plain = build_blur_table(img, pts, subset=21, shape=shape, blur=w, angle=ang)
        comp = build_compensated_table(img, pts, subset=21, shape=shape, blur=w, angle=ang)
        a = plain.lookup(w, ang)[0]
        b = comp.lookup(w, ang)[0]
        np.testing.assert_allclose(b[:, 2:4], a[:, 2:4], rtol=0.01)
        assert np.all(b[:, :2] == 0) and np.all(b[:, 4:] == 0)
        # the interaction the compensated table leaves out is small against the noise term
        assert np.all(a[:, 4:] * 4.0 < 1e-2 * a[:, 2:4])


def test_group_vectors_rounds_and_caps():
    rng = np.random.default_rng(0)
    vec = np.stack([1.0 + 0.01 * rng.standard_normal(50), 3.0 + 0.3 * rng.standard_normal(50)], 1)
    vec[3] = np.nan
    vec[4] = (0.0, 30.0)  # longer than the subset
    # a near-uniform frame: one vector (the median), for every point
    near = np.stack([1.0 + 0.02 * rng.uniform(-1, 1, 50), 3.0 + 0.02 * rng.uniform(-1, 1, 50)], 1)
    flat, _ = group_vectors(near, subset=21)
    assert np.unique(flat, axis=0).shape[0] == 1
    assert np.max(np.abs(flat - near)) < 0.1
    out, n_zero = group_vectors(vec, subset=21, max_groups=4)
    assert n_zero == 2 and np.all(out[4] == 0)  # too long: the plain matcher
    assert np.max(np.abs(out[3] - np.nanmedian(vec[np.arange(50) != 4], axis=0))) < 0.4
    assert np.unique(out, axis=0).shape[0] <= 4
    keep = np.ones(50, bool)
    keep[[3, 4]] = False
    assert np.max(np.abs(out[keep] - vec[keep])) <= 0.4
    fine, _ = group_vectors(vec[keep], subset=21, max_groups=100)
    assert np.max(np.abs(fine - vec[keep])) <= 0.1 + 0.025 + 1e-12  # UNIFORM_PX + QUANTUM / 2


def test_cli_compensate_blur_report_shows_the_matcher(tmp_path, capsys):
    import xarray as xr

    from dicblur.cli import main

    tgt = _target(96)
    folder = tmp_path / "frames"
    folder.mkdir()
    for k in range(12):
        dicblur.save_image(folder / f"f{k}.png", tgt.render(k), bit_depth=8)
    out = tmp_path / "out"
    args = [
        "track", str(folder), "--exposure", "0.45ms", "--fps", "2kHz", "--static", "0:6",
        "--step", "12", "--shape", "translation", "--compensate-blur", "--chunk-frames", "6",
        "-o", str(out),
    ]  # fmt: skip
    assert main(args) == 0
    assert "compensated" in capsys.readouterr().out
    ds = xr.open_dataset(out / "track.nc", engine="scipy")
    assert ds.attrs["matcher"] == MATCHER_COMPENSATED and ds.attrs["chunks_n_chunks"] == 2
    ds.close()
    page = (out / "report.html").read_text()
    assert "blur-compensated, blur vector per point from the track" in page
    assert "2 chunks of 6 frames (serial, 0 resumed)" in page
