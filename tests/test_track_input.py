"""Frames with non-finite pixels and JPEG folders through :func:`dicblur.track` (synthetic
data built here)."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur.dic import PointStatus
from dicblur.sequence import open_recording
from helpers.track import track_pattern


def _float_tiffs(folder, n=6, *, nan_at=None, size=72, seed=0):
    import tifffile

    rng = np.random.default_rng(seed)
    img = track_pattern(size)
    for k in range(n):
        f = (img + rng.normal(0, 2.0, img.shape)).astype(np.float32)
        for frame, r, c in nan_at or ():
            if frame == k:
                f[r : r + 2, c : c + 2] = np.nan
                f[r, c] = np.inf
        tifffile.imwrite(folder / f"f{k}.tif", f)


def _touching(ds, r, c, subset, margin=2):
    """Points whose subset (half-width + margin) reaches the 2 x 2 pixels at (r, c)."""
    h = subset // 2 + margin
    rows, cols = ds["row"].values, ds["col"].values
    return (rows + h >= r) & (rows - h <= r + 1) & (cols + h >= c) & (cols - h <= c + 1)


def test_non_finite_pixels_fail_only_the_points_they_touch(tmp_path):
    # a float TIFF frame with a few NaN (and one inf) pixels: before, the whole track
    # stopped on that frame ("pixels are not finite"); now its touching points fail
    _float_tiffs(tmp_path, nan_at=[(4, 30, 40)])
    rec = open_recording(tmp_path)
    kw = dict(fps=1000, exposure="0.1ms", static="0:4", step=12, subset=21, advice=False)
    ds = dicblur.track(rec, shape="translation", **kw)
    assert ds.attrs["complete"] == 1 and ds.sizes["frame"] == 6
    hit = _touching(ds, 30, 40, 21)
    assert 0 < hit.sum() < hit.size
    st = ds["status"].values
    assert np.all(st[4, hit] == PointStatus.DIVERGED)
    assert np.isnan(ds["u"].values[4, hit]).all() and not ds["valid"].values[4, hit].any()
    assert ds["valid"].values[4, ~hit].mean() > 0.9  # the rest of the frame is measured
    assert (st[[0, 1, 2, 3, 5]] != PointStatus.DIVERGED).all()  # the other frames untouched
    assert "frame 4 (f4.tif): 4 non-finite pixels" in ds.attrs["notes"]
    assert f"the {int(hit.sum())} points" in ds.attrs["notes"]


def test_non_finite_pixels_in_the_reference_fail_those_points_in_every_frame(tmp_path):
    _float_tiffs(tmp_path, nan_at=[(0, 12, 14)])
    ds = dicblur.track(
        open_recording(tmp_path), fps=1000, exposure="0.1ms", noise=2.0, step=12, subset=21,
        shape="translation", advice=False,
    )  # fmt: skip
    hit = _touching(ds, 12, 14, 21)
    assert hit.any() and (ds["status"].values[:, hit] == PointStatus.DIVERGED).all()
    assert ds["valid"].values[:, ~hit].mean() > 0.9
    assert "it is the reference" in ds.attrs["notes"]


def test_frame_without_a_finite_pixel_is_still_refused(tmp_path):
    import tifffile

    from dicblur.errors import ImageReadError

    _float_tiffs(tmp_path, n=3, size=48)
    tifffile.imwrite(tmp_path / "f1.tif", np.full((48, 48), np.nan, np.float32))
    seen = []
    rec = open_recording(tmp_path).with_non_finite_filled(lambda i, m: seen.append(i))
    assert np.isfinite(rec.frame(0)).all() and not seen
    with pytest.raises(ImageReadError, match=r"frame 1 \(f1.tif\): no pixel is finite"):
        rec.frame(1)
    with pytest.raises(ImageReadError, match="not finite"):
        open_recording(tmp_path).frame(1)  # the plain reader refuses them as before


def _jpegs(folder, n=5, size=64, suffix=".jpg"):
    from PIL import Image

    rng = np.random.default_rng(3)
    img = track_pattern(size)
    for k in range(n):
        f = np.clip(np.rint(img + rng.normal(0, 2.0, img.shape)), 0, 255).astype(np.uint8)
        Image.fromarray(f).save(folder / f"f{k}{suffix if k % 2 else suffix.upper()}", quality=95)


def test_jpeg_folder_opens_as_its_glob_does_and_the_track_says_it_is_lossy(tmp_path):
    # a folder of .jpg frames was refused ("no TIFF/PNG/BMP images") while 'dir/*.jpg'
    # opened: both open now, and the track's notes say the noise model misses JPEG's error
    _jpegs(tmp_path)
    (tmp_path / "f5.jpeg").write_bytes((tmp_path / "f4.JPG").read_bytes())
    rec = open_recording(tmp_path)
    assert rec.names == ["f0.JPG", "f1.jpg", "f2.JPG", "f3.jpg", "f4.JPG", "f5.jpeg"]
    assert rec.bit_depth == 8 and rec.meta["lossy"] == "JPEG"
    glob = open_recording(str(tmp_path / "*.[jJ]*"))
    np.testing.assert_array_equal(glob.frame(3), rec.frame(3))
    assert glob.meta["lossy"] == "JPEG"
    ds = dicblur.track(rec, fps=1000, exposure="0.1ms", noise=2.0, step=16, advice=False,
                       shape="translation")  # fmt: skip
    assert "JPEG" in ds.attrs["notes"] and "noise model" in ds.attrs["notes"]
    png = tmp_path / "png"
    png.mkdir()
    dicblur.save_image(png / "a.png", rec.frame(0), bit_depth=8)
    dicblur.save_image(png / "b.png", rec.frame(1), bit_depth=8)
    assert "lossy" not in open_recording(png).meta


@pytest.mark.slow
def test_non_finite_pixels_in_chunks_on_workers_fail_the_same_points(tmp_path):
    # workers re-open the files (their frames' NaN filled there too) and report the
    # frames that had any; the points failed are those of the serial run
    from dicblur.track.parallel import ChunkedRun

    _float_tiffs(tmp_path, n=8, nan_at=[(5, 30, 40)])
    kw = dict(fps=1000, exposure="0.1ms", static="0:4", step=12, subset=21, advice=False,
              shape="translation")  # fmt: skip
    serial = dicblur.track(open_recording(tmp_path), **kw)
    workers = dicblur.track(
        open_recording(tmp_path), chunks=ChunkedRun(workers=2, chunk_frames=3), **kw
    )
    st = workers["status"].values
    np.testing.assert_array_equal(st == PointStatus.DIVERGED, serial["status"].values == 4)
    assert (st[5] == PointStatus.DIVERGED).sum() == _touching(workers, 30, 40, 21).sum()
    assert "frame 5 (f5.tif): 4 non-finite pixels" in workers.attrs["notes"]
