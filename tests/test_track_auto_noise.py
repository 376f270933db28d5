"""``dicblur.track`` without static frames or a noise value estimates the noise from the
frames' residuals (issue 26, item 1)."""

from __future__ import annotations

import dicblur
from helpers.track import track_pattern, vibrating_target


def test_track_estimates_noise_without_static_frames() -> None:
    tgt = vibrating_target(track_pattern(96), exposure=0.4e-3, amplitude=3.0, static=10, seed=4)
    kw = {"subset": 21, "step": 12, "advice": False, "frames": "0:12"}
    ref = dicblur.track(tgt.recording(12), static="0:10", **kw)
    auto = dicblur.track(tgt.recording(12), **kw)
    a = auto.attrs
    assert a["noise_estimated"] == 1 and ref.attrs["noise_estimated"] == 0
    assert a["noise_source"].startswith("estimated from the residuals of frames")
    assert a["noise_sigma_low"] <= a["noise_sigma"] <= a["noise_sigma_high"]
    # the camera's 2 GL read noise plus its shot noise: the static frames' pairwise estimate
    assert abs(a["noise_sigma"] / ref.attrs["noise_sigma"] - 1) < 0.1
    assert auto["sigma_u"].notnull().any()
    given = dicblur.track(tgt.recording(12), noise=3.0, **kw)  # still overrides
    assert given.attrs["noise_sigma"] == 3.0 and given.attrs["noise_estimated"] == 0
