"""The validity domain of a fitted model: the settings and ranges it was fitted on.

A model describes the data it was fitted to. Its domain records the blur range and noise
range of those data, the DIC subset and shape function, the pattern (name and hash), and
where DIC broke down (the first blur length at which too few subsets converged in the
calibration data, or at which the static prediction's linearised shift leaves too few
subsets). Predictions inside the ranges are interpolations; outside them they are flagged
as extrapolated; beyond the breakdown blur they are not made (docs/models.md s. 7).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..arrays import BoolArray, Float64Array

__all__ = ["COMPENSATIONS", "ValidityDomain", "compensation_label"]

#: The matcher modes a model can be fitted on (``compensation``, as the campaign key
#: ``dic.compensation`` and ``Correlator(blur=...)``): ``"none"`` the plain matcher (sharp
#: reference), ``"given"`` the blur-compensated matcher with the known blur vector,
#: ``"estimate"`` the blur-compensated matcher that estimates the blur length, ``"deblur"``
#: the plain matcher on Wiener-deblurred current images (the published baseline).
COMPENSATIONS = ("none", "given", "estimate", "deblur")
_LABELS = {
    "none": "plain matcher",
    "given": "blur-compensated matcher (blur given)",
    "estimate": "blur-compensated matcher (blur estimated)",
    "deblur": "plain matcher on Wiener-deblurred images",
}


def compensation_label(compensation: str) -> str:
    """Words for a matcher mode: ``"given"`` -> ``"blur-compensated matcher (blur given)"``."""
    return _LABELS.get(compensation, f"matcher {compensation!r}")


@dataclass(frozen=True)
class ValidityDomain:
    """Ranges and settings a model was fitted on.

    Attributes
    ----------
    blur_min, blur_max : float
        Blur lengths W of the fitted data (px).
    noise_min, noise_max : float or None
        Noise std of the fitted data (GL); None if unknown.
    subset : int or None
        DIC subset size (px).
    shape : str or None
        DIC shape function (``"translation"``, ``"affine"``).
    pattern : str or None
        Pattern name (generator name or image file stem).
    pattern_sha256 : str or None
        SHA-256 of the pattern image file (or of the generated image's bytes).
    breakdown_blur : float or None
        W (px) from which DIC breaks down (no prediction there and beyond); None if DIC
        converged over the whole fitted range.
    breakdown_rule : str or None
        How ``breakdown_blur`` was found (e.g. ``"converged fraction < 0.9"``).
    compensation : {"none", "given", "estimate", "deblur"}
        Matcher mode of the fitted data (:data:`COMPENSATIONS`): ``"none"``, the plain
        matcher, for files written before it was recorded.
    """

    blur_min: float
    blur_max: float
    noise_min: float | None = None
    noise_max: float | None = None
    subset: int | None = None
    shape: str | None = None
    pattern: str | None = None
    pattern_sha256: str | None = None
    breakdown_blur: float | None = None
    breakdown_rule: str | None = None
    compensation: str = "none"

    # tolerance of the range checks: W and sigma are read from files and units
    _REL = 1e-9

    def inside_blur(self, blur: Float64Array) -> BoolArray:
        """Per W: inside the fitted blur range (px)."""
        w = np.asarray(blur, dtype=np.float64)
        tol = self._REL * max(1.0, abs(self.blur_max))
        return (w >= self.blur_min - tol) & (w <= self.blur_max + tol)

    def broken_down(self, blur: Float64Array) -> BoolArray:
        """Per W: at or beyond the breakdown blur."""
        w = np.asarray(blur, dtype=np.float64)
        if self.breakdown_blur is None:
            return np.zeros(w.shape, dtype=bool)
        return w >= self.breakdown_blur

    def inside_noise(self, sigma: float | None) -> bool:
        """Whether noise ``sigma`` (GL) is inside the fitted noise range (True if unknown)."""
        if sigma is None or self.noise_min is None or self.noise_max is None:
            return True
        lo, hi = self.noise_min, self.noise_max
        return bool(lo * (1 - self._REL) <= sigma <= hi * (1 + self._REL))

    def describe(self) -> str:
        """``W 0.1..6 px, noise 2 GL, subset 31 px, translation, pattern paper4``."""
        parts = [f"W {self.blur_min:g}..{self.blur_max:g} px"]
        if self.noise_min is not None and self.noise_max is not None:
            parts.append(
                f"noise {self.noise_min:g} GL"
                if self.noise_min == self.noise_max
                else f"noise {self.noise_min:g}..{self.noise_max:g} GL"
            )
        if self.subset is not None:
            parts.append(f"subset {self.subset} px")
        if self.shape is not None:
            parts.append(self.shape)
        if self.pattern is not None:
            parts.append(f"pattern {self.pattern}")
        if self.compensation != "none":
            parts.append(compensation_label(self.compensation))
        return ", ".join(parts)

    def outside_reason(self, blur: Float64Array, sigma: float | None) -> str | None:
        """One-line reason why (blur, sigma) lies outside the domain, or None."""
        w = np.asarray(blur, dtype=np.float64)
        out = w[~self.inside_blur(w)]
        why = []
        if out.size:
            why.append(
                f"W = {', '.join(f'{x:.3g}' for x in out[:3])}{' ...' if out.size > 3 else ''} px"
            )
        if not self.inside_noise(sigma):
            why.append(f"noise {sigma:.3g} GL")
        if not why:
            return None
        return (
            f"{' and '.join(why)} outside the model's validity domain "
            f"({self.describe()}): extrapolated"
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ValidityDomain:
        def num(key: str) -> float | None:
            v = d.get(key)
            return None if v is None else float(v)

        bmin, bmax = num("blur_min"), num("blur_max")
        return cls(
            blur_min=0.0 if bmin is None else bmin,
            blur_max=math.inf if bmax is None else bmax,
            noise_min=num("noise_min"),
            noise_max=num("noise_max"),
            subset=None if d.get("subset") is None else int(d["subset"]),
            shape=d.get("shape"),
            pattern=d.get("pattern"),
            pattern_sha256=d.get("pattern_sha256"),
            breakdown_blur=num("breakdown_blur"),
            breakdown_rule=d.get("breakdown_rule"),
            compensation=d.get("compensation") or "none",
        )
