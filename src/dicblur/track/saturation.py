"""Clipped (saturated) pixels in the reference subsets of :func:`dicblur.track.track`.

Where the sensor clips, a subset's grey levels carry neither the noise nor the blur the
per-point sigma assumes (a clipped pixel has no noise and stays at the top level while the
pattern under it moves), so that sigma is no error bar there: on a moving target whose
bright speckles clip, the error of such subsets ran 3-5x their predicted sigma (10 x at
worst) while the others stayed at 1.0-1.9x. The track marks them (``saturated``: the share
of clipped pixels in each point's reference subset) and leaves out of ``valid`` those over
:data:`SATURATION_MAX_SHARE`.

The clipping level is read from the reference itself, not from the file's bit depth
(12-bit data in 16-bit files clip at 4095, 8-bit data scaled into 16 bits at 65280): a
plateau at the image's maximum, held by at least :data:`SATURATION_MIN_PIXELS` pixels and
by more than the next level down (an unclipped, noisy distribution thins out towards its
maximum), at a top code of 8-16-bit data (:func:`top_codes`). A noise-free synthetic
pattern has such a plateau too (the flat inside of its white speckles): below a top code
(``track_pattern``'s 210) it is not taken for clipping; at one (a pattern stretched to
0-255) it is, as the camera would clip it.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter

from ..arrays import BoolArray, Float32Array, Float64Array, IndexArray

__all__ = [
    "SATURATION_MAX_SHARE",
    "SATURATION_MIN_PIXELS",
    "saturated_share",
    "saturation_level",
    "saturation_note",
    "too_saturated",
]

#: Fewest pixels at the maximum grey level that make it a clipping plateau.
SATURATION_MIN_PIXELS = 5
#: Largest share of clipped pixels a reference subset may hold and stay ``valid``. A few
#: clipped pixels leave the sigma true: on 256^2 vibrating targets (8-bit, 2 GL, subset 21)
#: the error over sigma of the points held 1.0-1.1 up to a 20 % share where only the noise
#: clipped, and 1.2-1.3 where 30 % of the speckles' brightness was cut flat; a quarter of
#: the subset clipped is texture the match and its noise model no longer see.
SATURATION_MAX_SHARE = 0.25


def top_codes() -> frozenset[float]:
    """The grey levels a sensor clips at: ``2**k - 1`` of k-bit data (k = 8..16) and the
    same left-aligned in 16 bits, ``(2**k - 1) 2**(16 - k)`` (65280 for 8-bit, 65520 for
    12-bit data)."""
    return frozenset(
        [float(2**k - 1) for k in range(8, 17)]
        + [float((2**k - 1) * 2 ** (16 - k)) for k in range(8, 16)]
    )


def saturation_level(image: Float64Array) -> float | None:
    """The grey level (GL) at which ``image`` (rows, cols) is clipped, or None when its
    maximum is no top code (:func:`top_codes`) or no plateau (fewer than
    :data:`SATURATION_MIN_PIXELS` pixels there, or no more than at the next level
    down)."""
    img = np.asarray(image, dtype=np.float64)
    top = float(img.max())
    if top not in top_codes():
        return None
    n_top = int(np.count_nonzero(img == top))
    if n_top < SATURATION_MIN_PIXELS:
        return None
    below = img[img < top]
    if below.size == 0:
        return None  # a flat image: no texture to clip
    n_next = int(np.count_nonzero(below == below.max()))
    return top if n_top > n_next else None


def too_saturated(share: Float32Array) -> BoolArray:
    """The points whose clipped share (:func:`saturated_share`) is over
    :data:`SATURATION_MAX_SHARE`: left out of ``valid``."""
    return np.asarray(share) > SATURATION_MAX_SHARE


def saturation_note(share: Float32Array, level: float | None, n: int, where: str = "") -> str:
    """The run's note on clipped reference subsets (``where``: e.g. ``" left"``)."""
    some = int(np.count_nonzero(np.asarray(share) > 0))
    out = int(np.count_nonzero(too_saturated(share)))
    return (
        f"{some} of {n} points have clipped pixels (at {level:g} GL) in their{where} "
        f"reference subset; the {out} with more than {SATURATION_MAX_SHARE:.0%} of it "
        "clipped are not valid (their noise and blur model does not hold there); lower the "
        "exposure or the lighting, or move the subsets"
    )


def saturated_share(
    image: Float64Array, centres: IndexArray, subset: int, level: float | None
) -> Float32Array:
    """Share (0-1) of the pixels at or above ``level`` in the ``subset`` px square
    around each of ``centres`` (n, 2) (row, col) of ``image``; zeros when ``level`` is
    None. Pixels outside the image count as not clipped."""
    n = len(centres)
    if level is None or n == 0:
        return np.zeros(n, np.float32)
    mask = (np.asarray(image) >= level).astype(np.float64)
    share = uniform_filter(mask, subset, mode="constant", cval=0.0)
    r = np.clip(centres[:, 0], 0, mask.shape[0] - 1)
    c = np.clip(centres[:, 1], 0, mask.shape[1] - 1)
    # the box mean of 0/1 values: round away the filter's summation error
    return (np.rint(share[r, c] * subset * subset) / (subset * subset)).astype(np.float32)
