"""Units of the blur: the blur length ``W`` from the target's speed, the exposure time and
the image scale."""

from __future__ import annotations

from ..checks import check_finite_number, check_positive

__all__ = ["blur_length"]


def blur_length(velocity: float, exposure: float, scale: float) -> float:
    """Blur length W (px) travelled during one exposure.

    ``W = |velocity| * exposure / scale``.

    Parameters
    ----------
    velocity : float
        Speed of the target in length units per second (e.g. mm/s).
    exposure : float
        Exposure time, s (>= 0).
    scale : float
        Object-space size of one pixel in the same length unit per px (e.g. mm/px), > 0.

    Returns
    -------
    float
        W in px.

    Examples
    --------
    >>> blur_length(100.0, 1e-3, 0.05)   # 100 mm/s, 1 ms, 0.05 mm/px
    2.0
    """
    v = abs(check_finite_number(velocity, "velocity"))
    t = check_positive(exposure, "exposure", allow_zero=True)
    s = check_positive(scale, "scale")
    return v * t / s
