"""Options of :func:`dicblur.track.track`: the frame rate and frame range parsers, the
exposure / rate resolution against the recording's metadata, and the automatic IC-GN
tolerance (:func:`auto_tolerance`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..arrays import Float64Array, IndexArray
from ..dic import MatcherSettings
from ..errors import InputError
from ..metrics import box_sssig, image_gradients, match_score_sigma
from ..models.units import parse_quantity
from .noise import NoiseEstimate, subset_levels


def parse_rate(value: float | str, name: str = "fps") -> float:
    """Frame rate from a number (Hz) or ``"5000"``, ``"5000fps"``, ``"5kHz"``, ``"2000Hz"``."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        x = float(value)
    else:
        text = str(value).strip().lower().replace(" ", "")
        mult = 1.0
        for suffix, m in (("khz", 1e3), ("mhz", 1e6), ("hz", 1.0), ("fps", 1.0)):
            if text.endswith(suffix):
                text, mult = text[: -len(suffix)], m
                break
        try:
            x = float(text) * mult
        except ValueError as exc:
            raise InputError(
                f"{name}={value!r}: expected a frame rate such as 5000, '5000fps' or '5kHz'"
            ) from exc
    if not math.isfinite(x) or x <= 0:
        raise InputError(f"{name}={value!r}: the frame rate must be > 0 Hz, e.g. 5000")
    return x


def parse_frame_range(
    text: str | Sequence[int], n_frames: int, name: str = "static"
) -> tuple[int, int]:
    """``"0:20"`` (half-open, Python style; negative counts from the end) -> (0, 20)."""
    if isinstance(text, str):
        parts = text.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            a = int(parts[0]) if parts[0] else 0
            b = int(parts[1]) if parts[1] else n_frames
        except ValueError as exc:
            raise InputError(
                f"{name}={text!r}: expected START:STOP frame numbers, e.g. 0:20"
            ) from exc
    else:
        a, b = (int(x) for x in text)
    a = a + n_frames if a < 0 else a
    b = b + n_frames if b < 0 else b
    if not 0 <= a < b <= n_frames:
        raise InputError(
            f"{name}={text!r}: must satisfy 0 <= START < STOP <= {n_frames} "
            "(the recording's frames)"
        )
    return a, b


def resolve(value: Any, meta: float | None, kind: str, name: str, flag: str, example: str) -> float:
    given = None
    if value is not None:
        given = (
            parse_rate(value, name) if kind == "rate" else parse_quantity(value, "time", name=name)
        )
        if given <= 0:
            raise InputError(f"{name}={value!r}: must be > 0, e.g. {example}")
    if given is not None and meta is not None and abs(given - meta) > 0.01 * meta:
        warnings.warn(
            f"{flag}={value}: the recording's metadata says {meta:g} "
            f"{'Hz' if kind == 'rate' else 's'}; using the value given",
            UserWarning,
            stacklevel=3,
        )
    out = given if given is not None else meta
    if out is None:
        raise InputError(
            f"{flag}: the recording has no {name} in its metadata; give "
            f"{flag} (e.g. {flag} {example})"
        )
    return float(out)


#: ``tolerance="auto"``: the IC-GN tolerance is this share of the smallest predicted
#: noise floor (the :data:`TOLERANCE_QUANTILE` of the points' ``sqrt(2 sigma**2 /
#: SSSIG)``), within [:data:`TOLERANCE_MIN`, :data:`TOLERANCE_MAX`] px. The error a
#: converged point keeps is 0.2-0.6 x the tolerance (rms against a 1e-6 px run; 0.2 on the
#: speed recording of benchmarks/bench_track.py, 0.6 on a 3 px blur), so at most ~15 % of
#: that floor: it adds about 1 % to the predicted sigma (in quadrature), for a quarter
#: fewer IC-GN iterations than 1e-4 px (affine, 2.76 -> 2.09 per point).
TOLERANCE_SHARE = 0.25
#: Quantile of the points' noise floors that sets ``tolerance="auto"``.
TOLERANCE_QUANTILE = 0.05
#: Bounds of ``tolerance="auto"`` (px): never tighter than the engine's default, never
#: looser than the 0.001 px of the IC-GN literature (Pan et al., Exp. Mech. 53, 2013).
TOLERANCE_MIN = MatcherSettings().tolerance
TOLERANCE_MAX = 1e-3


def auto_tolerance(
    reference: Float64Array,
    centres: IndexArray,
    subset: int,
    noise: NoiseEstimate | None,
) -> float:
    """IC-GN convergence tolerance (px) for tracking the POIs ``centres`` (n, 2) (row,
    col) of ``reference`` at ``subset`` px under ``noise`` (None: the engine default).

    The tolerance bounds the error left in each converged result, so it only needs to be
    small against the random error the track predicts: :data:`TOLERANCE_SHARE` x the
    :data:`TOLERANCE_QUANTILE` of the points' static noise floor, the match-score model
    ``sqrt(2 sigma**2 / SSSIG)`` (paper eq. 2) along the better-textured of x and y at each
    subset's noise level, within [:data:`TOLERANCE_MIN`, :data:`TOLERANCE_MAX`]. Points
    whose subset leaves the image (1-px border) are left out.
    """
    if noise is None:
        return TOLERANCE_MIN
    h = subset // 2
    r, c = centres[:, 0], centres[:, 1]
    inside = (r - h >= 1) & (c - h >= 1) & (r + h < reference.shape[0] - 1)
    inside &= c + h < reference.shape[1] - 1
    pts = centres[inside]
    if pts.shape[0] == 0:
        return TOLERANCE_MIN
    gy, gx = image_gradients(reference)
    s_x = box_sssig(gy, gx, pts, subset=subset, angle=0.0)
    s_y = box_sssig(gy, gx, pts, subset=subset, angle=90.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = match_score_sigma(np.maximum(s_x, s_y), 1.0)  # px per GL of noise
    floor = unit * np.sqrt(noise.variance(subset_levels(reference, pts, subset)))
    floor = floor[np.isfinite(floor)]
    if floor.size == 0:
        return TOLERANCE_MIN
    tol = TOLERANCE_SHARE * float(np.quantile(floor, TOLERANCE_QUANTILE))
    return float(min(max(tol, TOLERANCE_MIN), TOLERANCE_MAX))
