"""Odd recordings through :func:`dicblur.track`: duplicated frames, zero motion, mixed
frame types, saturation (synthetic data built here)."""

from __future__ import annotations

import numpy as np
import pytest

import dicblur
from dicblur.errors import InputError
from dicblur.sequence import Recording
from dicblur.track.noise import estimate_static_noise
from helpers.track import track_pattern


def _memory(frames: list[np.ndarray], *, fps: float = 1000.0, exposure: float = 1e-4) -> Recording:
    arr = [np.asarray(f, dtype=np.float64) for f in frames]
    return Recording(
        source="test",
        kind="memory",
        n_frames=len(arr),
        shape=arr[0].shape,
        bit_depth=8,
        fps=fps,
        exposure=exposure,
        names=[f"frame {i}" for i in range(len(arr))],
        _read=lambda i: arr[i],
    )


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
    for static in ("0:4", None):
        ds = dicblur.track(rec, static=static, step=16, shape="translation")
        assert "no noise estimate" in ds.attrs["notes"]
        assert "noise_sigma" not in ds.attrs and ds["sigma_u"].isnull().all()
        assert not ds["valid"].values.any()
        conv = ds["status"].values == 0
        assert np.abs(ds["u"].values[conv]).max() < 1e-6
        assert np.abs(ds["v"].values[conv]).max() < 1e-6
