"""Odd recordings through :func:`dicblur.track`: duplicated frames, zero motion, mixed
frame types, saturation (synthetic data built here)."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur.errors import InputError
from dicblur.sequence import Recording
from dicblur.track.noise import estimate_static_noise
from helpers.track import memory_recording, track_pattern


def _memory(frames: list[np.ndarray], *, fps: float = 1000.0, exposure: float = 1e-4) -> Recording:
    return memory_recording(frames, fps=fps, exposure=exposure)


def _noisy(n: int, size: int = 64, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    img = track_pattern(size)
    return [img + rng.normal(0, 2.0, img.shape) for _ in range(n)]


def test_static_noise_skips_duplicated_frames_and_refuses_all_identical():
    frames = _noisy(5)
    clean = estimate_static_noise(frames, 0, 5)
    dup = [frames[0], frames[0], frames[1], frames[2], frames[2], frames[3], frames[4]]
    est = estimate_static_noise(dup, 0, 7)  # two duplicated frames (a camera repeating one)
    assert est.sigma == pytest.approx(clean.sigma, rel=1e-12) and est.pairs == 4
    assert "2 duplicated" in est.source
    with pytest.raises(InputError, match="identical"):
        estimate_static_noise([frames[0]] * 4, 0, 4)


def test_track_of_one_frame_repeated_says_so_and_does_not_crash():
    # the same frame, bit for bit, 6 times: no noise to measure, zero motion
    rec = _memory([_noisy(1)[0]] * 6)
    with pytest.raises(InputError, match="static=0:4: the frames are identical"):
        dicblur.track(rec, static="0:4", step=16, shape="translation")
    for noise in (None, 2.0):
        ds = dicblur.track(rec, noise=noise, step=16, shape="translation")
        if noise is not None:
            assert ds.attrs["noise_sigma"] == 2.0 and ds["valid"].values.any()
            continue
        assert "no noise estimate" in ds.attrs["notes"]
        assert "noise_sigma" not in ds.attrs and ds["sigma_u"].isnull().all()
        assert not ds["valid"].values.any()
        conv = ds["status"].values == 0
        assert np.abs(ds["u"].values[conv]).max() < 1e-6
        assert np.abs(ds["v"].values[conv]).max() < 1e-6


def test_bad_static_points_and_subset_fail_before_tracking():
    rec = _memory(_noisy(5))
    with pytest.raises(InputError, match="static='0:1'"):
        dicblur.track(rec, static="0:1", step=16)
    with pytest.raises(InputError, match=r"points=.*\(500, 10\).*64x64"):
        dicblur.track(rec, points=[[20, 20], [500, 10]], noise=2.0)
    with pytest.raises(InputError, match=r"^subset=71: .*64x64"):
        dicblur.track(rec, subset=71, noise=2.0)


def test_frame_of_another_dtype_mid_folder_is_named(tmp_path):
    from dicblur.errors import ImageReadError
    from dicblur.sequence import open_recording

    frames = _noisy(4)
    for k, f in enumerate(frames):
        dicblur.save_image(tmp_path / f"f{k}.tif", f * (256 if k == 2 else 1),
                           bit_depth=16 if k == 2 else 8)  # fmt: skip
    rec = open_recording(tmp_path)
    assert rec.frame(1).max() < 256
    with pytest.raises(ImageReadError, match=r"frame 2 \(f2.tif\): 16-bit.*8-bit"):
        rec.frame(2)


def test_cli_names_an_uncreatable_out_and_prints_the_notes(tmp_path, capsys):
    from dicblur.cli import main

    folder = tmp_path / "frames"
    folder.mkdir()
    for k, f in enumerate([_noisy(1)[0]] * 4):
        dicblur.save_image(folder / f"f{k}.png", f, bit_depth=8)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    args = ["track", str(folder), "--exposure", "0.1ms", "--fps", "1000", "--step", "16"]
    rc = main([*args, "-o", str(blocker / "sub")])
    err = capsys.readouterr().err
    assert rc == 2 and "--out=" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    # one frame repeated, no --static or --noise: no noise estimate, and the CLI says why
    rc = main([*args, "--no-report", "-o", str(tmp_path / "out")])
    out = capsys.readouterr().out
    assert rc == 0 and "no noise estimate" in out and "--noise" in out


def test_lzw_tiff_stack_reads_without_imagecodecs(tmp_path):
    # LZW (the default of many camera programs) needs imagecodecs in tifffile, which is
    # not a dependency: the pages are read through Pillow then
    from PIL import Image

    from dicblur.sequence import open_recording

    frames = [np.clip(np.rint(f), 0, 255).astype(np.uint8) for f in _noisy(3, size=32)]
    ims = [Image.fromarray(f) for f in frames]
    ims[0].save(tmp_path / "s.tif", save_all=True, append_images=ims[1:], compression="tiff_lzw")
    with open_recording(tmp_path / "s.tif") as rec:
        assert rec.kind == "tiff-stack" and len(rec) == 3 and rec.bit_depth == 8
        for k in (2, 0, 1):
            np.testing.assert_array_equal(rec.frame(k), frames[k])


@pytest.mark.slow
def test_real_sample3_shifted_recording_error_matches_its_sigma(real_data):
    """Sample 3's first image as a recording: 4 still frames, then a known sub-pixel
    motion per frame (exact Fourier shifts), motion blur over a half-interval exposure,
    1.5 GL of fresh noise per frame. The error against that truth is what track predicts."""
    from scipy.ndimage import fourier_shift

    found = sorted((real_data / "dicchallenge1_sample3").glob("Sample3-000*.tif"))
    if not found:
        pytest.skip("DIC Challenge sample 3 not among the real images")
    src = found[0]
    img = np.asarray(dicblur.load_image(src), float)
    pat = img[128:384, 128:384]
    fps, t_exp = 1000.0, 0.5e-3
    vel = np.array([0.9, 0.55]) * fps  # (dy, dx) px/s
    rng = np.random.default_rng(7)
    frames, truth = [], []
    for k in range(12):
        p = vel * max(k - 4, 0) / fps
        sh = np.real(np.fft.ifft2(fourier_shift(np.fft.fft2(pat), p)))
        if k >= 4:
            sh, p = dicblur.motion_blur(sh, vel * t_exp, substeps=None), p + vel * t_exp / 2
        frames.append(sh + rng.normal(0, 1.5, sh.shape))
        truth.append(p)
    tv, tu = np.array(truth).T
    rec = _memory(frames, fps=fps, exposure=t_exp)
    ds = dicblur.track(rec, static="0:4", roi=(24, 232, 24, 232), step=12, subset=21)
    assert ds.attrs["noise_sigma"] == pytest.approx(1.5, rel=0.05)
    val = ds["valid"].values.astype(bool)
    assert val.mean() > 0.99 and ds["outlier"].values.mean() < 0.005
    moving = val & (np.arange(12) >= 6)[:, None]
    w = ds["W"].values[moving]
    assert np.median(w) == pytest.approx(np.hypot(*(vel * t_exp)), rel=0.05)
    for comp, t in (("u", tu), ("v", tv)):
        z = (ds[comp].values - t[:, None]) / ds[f"sigma_{comp}"].values
        assert 0.8 < np.sqrt(np.mean(z[val] ** 2)) < 1.3


def test_cli_stereo_track_names_an_uncreatable_out(tmp_path, capsys):
    from dicblur.cli import main
    from dicblur.stereo import CameraModel, save_rig
    from dicblur.stereo.synthetic import symmetric_rig

    cam = CameraModel(2000.0, 2000.0, 31.5, 31.5, (0, 0, 0, 0, 0), (64, 64))
    save_rig(symmetric_rig(stereo_angle=30.0, distance=400.0, camera=cam), tmp_path / "r.json")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc = main(
        ["stereo", "track", str(tmp_path), str(tmp_path), "--rig", str(tmp_path / "r.json"),
         "--noise", "2", "-o", str(blocker / "sub")]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and "--out=" in err and len(err.strip().splitlines()) == 1


def test_subsets_with_clipped_pixels_are_not_valid():
    # a bright region clipped at 255 (over-exposed): the noise and blur model of those
    # subsets does not hold (no noise, no blur where clipped), so their sigma is no
    # error bar: they are marked, those mostly clipped left out of `valid`
    from dicblur.track.saturation import saturation_level

    frames = _noisy(6, size=80, seed=4)
    for f in frames:
        f[20:34, 20:34] = 255.0  # a clipped patch in every frame
    rec = _memory(frames)
    ds = dicblur.track(rec, static="0:6", step=12, subset=21, shape="translation", advice=False)
    sat = ds["saturated"].values
    rows, cols = ds["row"].values, ds["col"].values
    touches = (rows + 10 >= 20) & (rows - 10 <= 33) & (cols + 10 >= 20) & (cols - 10 <= 33)
    assert touches.any() and np.array_equal(sat > 0, touches)
    assert 0 < sat.max() <= 196 / 441 + 1e-6
    # over a quarter of the subset clipped: no sigma there; a few clipped pixels leave the
    # sigma true (track.saturation.SATURATION_MAX_SHARE) and the point valid
    from dicblur.track.saturation import SATURATION_MAX_SHARE

    over = sat > SATURATION_MAX_SHARE
    assert over.any() and (touches & ~over).any()
    valid = ds["valid"].values.astype(bool)
    assert not valid[:, over].any() and valid[:, ~over].mean() > 0.9
    assert ds.attrs["saturation_level"] == 255.0 and "clipped" in ds.attrs["notes"]
    # a clean frame has no clipped plateau; a few pixels at the top of a tail are not one
    assert saturation_level(_noisy(1, size=80)[0]) is None
    img = np.arange(256.0).reshape(16, 16)
    img[0, :3] = 255.0
    assert saturation_level(img) is None
    # a noise-free pattern's flat white below a top code is no clipping; 12-bit data in
    # 16-bit files, and 8-bit data scaled into 16 bits, clip at their own top
    assert saturation_level(track_pattern(64)) is None
    noisy = _noisy(1, size=64)[0]
    assert saturation_level(np.minimum(np.rint(noisy * 20), 4095)) == 4095
    assert saturation_level(np.minimum(np.rint(noisy * 1.3), 255) * 256) == 65280


def test_folder_skips_hidden_files(tmp_path):
    # macOS copies leave '._name' AppleDouble files beside each frame (same suffix, not
    # an image); a glob '*' skips hidden files, and so does a folder
    from dicblur.sequence import open_recording

    for k, f in enumerate(_noisy(3, size=32)):
        dicblur.save_image(tmp_path / f"f{k}.png", f, bit_depth=8)
        (tmp_path / f"._f{k}.png").write_bytes(b"\x00\x05\x16\x07 not an image")
    rec = open_recording(tmp_path)
    assert rec.names == ["f0.png", "f1.png", "f2.png"]
    assert rec.frame(0).shape == (32, 32)


@pytest.mark.filterwarnings("ignore:.*metadata says:UserWarning")
def test_exposure_longer_than_the_interval_names_where_it_came_from():
    rec = _memory(_noisy(4), fps=2000.0, exposure=1e-3)  # a header's shutter of 1 ms
    with pytest.raises(InputError, match=r"^the recording's metadata: exposure 0.001 s"):
        dicblur.track(rec, noise=2.0, step=16)
    with pytest.raises(InputError, match=r"^exposure='0.8ms' \(given\)"):
        dicblur.track(rec, exposure="0.8ms", noise=2.0, step=16)
    with pytest.raises(InputError, match=r"^exposure=0.001 s from the metadata.*fps=1500"):
        dicblur.track(rec, fps=1500, noise=2.0, step=16)


def test_constant_reference_frame_is_named_with_the_fix():
    # a dropped (all black) first frame as the default reference
    frames = _noisy(5)
    frames[0] = np.zeros_like(frames[0])
    with pytest.raises(InputError, match=r"^reference=0 \(frame 0\): the frame is constant") as e:
        dicblur.track(_memory(frames), noise=2.0, step=16)
    assert "--reference 1" in str(e.value)


def test_foreign_frame_matches_are_flagged_not_valid():
    # a frame of another scene in the middle (a frame of another recording, a flash):
    # the few subsets that "converge" there are wrong by up to ~20 px; the ZNCC test
    # normalised by that frame's own median (those same few points) let them through
    rng = np.random.default_rng(0)
    img, other = track_pattern(96), track_pattern(96, seed=9)
    frames = [np.roll(img, k // 2, axis=1) + rng.normal(0, 1, img.shape) for k in range(10)]
    frames[6] = other + rng.normal(0, 1, img.shape)
    ds = dicblur.track(_memory(frames), noise=1.0, step=12, shape="affine", advice=False)
    st, out = ds["status"].values[6], ds["outlier"].values[6].astype(bool)
    wrong = np.abs(ds["u"].values[6] - 3) > 0.5
    assert not ((st == 0) & wrong & ~out).any()
    assert not ds["valid"].values[6].any()
    # the clean frames keep their points
    assert ds["outlier"].values[[0, 1, 2, 3, 9]].sum() == 0


def test_zncc_test_of_a_frame_where_most_subsets_fail():
    # the flags themselves (the engine's own neighbour screening may catch such matches
    # first): frame 2 has 3 of 40 points converged, at a ZNCC of a foreign texture
    from dicblur.track.flags import zncc_flags

    rng = np.random.default_rng(1)
    zn = 1.0 - rng.uniform(0.9, 1.1, (4, 40)) * 1e-3
    conv = np.ones((4, 40), bool)
    conv[2, 3:] = False
    zn[2, :3] = 0.7
    ok = np.ones((4, 40), bool)
    flags = zncc_flags(zn, conv, correlatable=ok)
    assert flags[2, :3].all() and flags.sum() == 3
    # without the correlatable points, its own median (of those 3) hides them
    assert not zncc_flags(zn, conv)[2].any()


def test_folder_of_two_image_formats_is_refused_with_a_glob_as_the_fix(tmp_path):
    # the same frames exported twice (f0.png and f0.tif): each frame would be tracked
    # twice, at the wrong time
    from dicblur.errors import ImageReadError
    from dicblur.sequence import open_recording

    for k, f in enumerate(_noisy(3, size=32)):
        dicblur.save_image(tmp_path / f"f{k}.png", f, bit_depth=8)
        dicblur.save_image(tmp_path / f"f{k}.tif", f, bit_depth=8)
    with pytest.raises(ImageReadError, match=r"3 \.png and 3 \.tif.*\*\.png"):
        open_recording(tmp_path)
    assert len(open_recording(str(tmp_path / "*.tif"))) == 3
    (tmp_path / "f0.png").unlink()
    for k in (1, 2):
        (tmp_path / f"f{k}.png").unlink()
    (tmp_path / "f3.TIFF").write_bytes((tmp_path / "f2.tif").read_bytes())
    assert len(open_recording(tmp_path)) == 4  # .tif and .TIFF are one format


def test_cli_plot_points_checked_before_tracking(tmp_path, capsys):
    from dicblur.cli import main

    folder = tmp_path / "frames"
    folder.mkdir()
    for k, f in enumerate(_noisy(4)):
        dicblur.save_image(folder / f"f{k}.png", f, bit_depth=8)
    args = ["track", str(folder), "--exposure", "0.1ms", "--fps", "1000", "--noise", "2"]
    for bad in ("-3", "9"):  # 64 px, step 16: 9 points (0..8)
        rc = main([*args, "--step", "16", "--plot-points", bad, "-o", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert rc == 2 and "--plot-points" in err and "0..8" in err
        assert not (tmp_path / "o" / "track.nc").exists()
