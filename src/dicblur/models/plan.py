"""Exposure planning: how long may the shutter stay open for a target uncertainty?

``W = velocity * exposure / scale`` (px). Two cases:

- fixed noise (``camera=None``): the noise does not depend on the exposure; the answer is
  the longest exposure whose predicted u_e stays under ``target``.
- Poisson-Gaussian camera: the signal grows with the exposure ``t`` (``flux * t``
  electrons at the mean grey level), shot noise with its square root, read noise is
  constant, and saturation caps ``t`` (the brightest pixels, ``peak_to_mean`` times the
  mean, reach the full well). The noise seen by the model, in the grey levels of the
  fitted reference images (mean ``mean_level``), is
  ``sigma(t) = mean_level sqrt(flux t + read**2) / (flux t)``; because the models depend
  on noise only through ``SSSIG / sigma**2`` this is the same as working in electrons.
  Longer exposures lower the relative noise and raise the blur: u_e(t) has a minimum.

With signal-dependent noise the match-score error of a subset is
``sum g**2 (var_ref + var_cur) / (sum g**2)**2`` with ``var = gain I + read**2``: the shot
noise counts at the gradient-weighted intensity ``sum(g**2 I) / sum(g**2)``
(:func:`gradient_weighted_level`, ``noise_level`` of :func:`plan_exposure`), not at the
mean. On the generated speckle patterns the two differ by < 1 % (docs/models.md s. 8).

The closed-form optimum of docs/models.md (shot-noise limit, no saturation) is what the
tests check the numerical optimum against.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy import optimize

from ..arrays import Float64Array
from ..checks import as_image, check_positive, check_textured
from ..errors import InputError
from .domain import ValidityDomain, compensation_label
from .model import BlurUncertaintyModel, Prediction
from .units import parse_quantity

__all__ = [
    "RULE_OF_THUMB_BLUR",
    "ExposurePlan",
    "PoissonGaussianCamera",
    "gradient_weighted_level",
    "plan_exposure",
]

RULE_OF_THUMB_BLUR = 0.02
"""The common rule of thumb: keep the motion during the exposure under 0.02 px."""


@dataclass(frozen=True)
class PoissonGaussianCamera:
    """Poisson-Gaussian sensor for exposure planning (Foi et al. 2008).

    Attributes
    ----------
    full_well : float
        Full-well capacity, electrons.
    read_noise : float
        Read noise std, electrons.
    flux : float
        Electrons per second collected by a pixel at the pattern's mean grey level.
    peak_to_mean : float
        Brightest / mean grey level of the pattern (saturation onset), >= 1.
    """

    full_well: float
    read_noise: float
    flux: float
    peak_to_mean: float = 2.0

    def __post_init__(self) -> None:
        check_positive(self.full_well, "full_well")
        check_positive(self.read_noise, "read_noise", allow_zero=True)
        check_positive(self.flux, "flux")
        if check_positive(self.peak_to_mean, "peak_to_mean") < 1:
            raise InputError(f"peak_to_mean={self.peak_to_mean!r}: must be >= 1")

    @classmethod
    def from_camera(
        cls, camera: Any, *, nominal_exposure: float, mean_level: float, peak_to_mean: float = 2.0
    ) -> PoissonGaussianCamera:
        """Build from a :class:`dicblur.Camera` (grey-level units) and its nominal exposure.

        ``Camera`` maps an irradiance image in grey levels at the nominal exposure to
        electrons with ``gain`` (GL/e-; derived from ``full_well`` and ``bit_depth`` when
        None), adds read noise in GL and saturates at ``full_well`` (or the ADC top level).

        Parameters
        ----------
        camera : dicblur.Camera
        nominal_exposure : float
            Exposure (s) at which the camera's input image has its grey levels
            (``exposure_scale = 1``).
        mean_level : float
            Mean grey level of the pattern at the nominal exposure (GL).
        """
        t0 = check_positive(nominal_exposure, "nominal_exposure")
        level = check_positive(mean_level, "mean_level")
        gain = getattr(camera, "gain", None)
        full_well = getattr(camera, "full_well", None)
        bits = getattr(camera, "bit_depth", None)
        if gain is None and full_well is not None and bits is not None:
            gain = (2**bits - 1) / full_well
        if gain is None:
            raise InputError(
                "camera: without gain or full_well it has no shot noise, so no optimum "
                "exposure exists; set gain (GL/e-) or full_well"
            )
        if full_well is None:
            full_well = (2**bits - 1) / gain if bits is not None else 1e30
        # exposure_scale is the camera's own exposure knob: the plan sets the exposure
        return cls(
            full_well=float(full_well),
            read_noise=float(camera.read_noise) / gain,
            flux=level / (gain * t0),
            peak_to_mean=peak_to_mean,
        )

    @property
    def saturation_exposure(self) -> float:
        """Exposure (s) at which the brightest pixels reach the full well."""
        return self.full_well / (self.flux * self.peak_to_mean)

    def noise_gl(
        self, exposure: Float64Array | float, mean_level: float, level: float | None = None
    ) -> Float64Array:
        """Noise std in grey levels of images normalised to ``mean_level`` (see module).

        ``level`` (GL, same images): intensity at which the shot noise is evaluated
        (default ``mean_level``; the gradient-weighted level for DIC, see
        :func:`gradient_weighted_level`).
        """
        e = self.flux * np.asarray(exposure, dtype=np.float64)
        ratio = 1.0 if level is None else level / mean_level
        return np.asarray(mean_level * np.sqrt(e * ratio + self.read_noise**2) / e)


def gradient_weighted_level(image: Any, *, motion: tuple[float, float] = (0.0, 1.0)) -> float:
    """Intensity at which signal-dependent noise enters the DIC error (GL).

    ``sum(g**2 I) / sum(g**2)`` over the image, ``g`` the central-difference derivative
    along the motion direction (dy, dx). The linearised least-squares displacement of a
    subset has variance ``sum g**2 (var_ref + var_cur) / (sum g**2)**2``; with
    ``var = gain I + read**2`` this is the match-score formula (eq. 2) at this intensity.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Noise-free (or low-noise) reference image, grey levels.
    motion : (dy, dx)
        Motion direction (only the direction matters).

    Returns
    -------
    float
    """
    img = as_image(image, "image", min_size=3)
    check_textured(img)
    dy, dx = (float(motion[0]), float(motion[1]))
    norm = math.hypot(dy, dx)
    if not math.isfinite(norm) or norm == 0:
        raise InputError(f"motion={motion!r}: give a non-zero direction (dy, dx), e.g. (0, 1)")
    g = np.zeros_like(img)
    g[1:-1, 1:-1] = (
        0.5 * dy * (img[2:, 1:-1] - img[:-2, 1:-1]) + 0.5 * dx * (img[1:-1, 2:] - img[1:-1, :-2])
    ) / norm
    g2 = g * g
    total = float(g2.sum())
    if total <= 0:
        raise InputError("image: no intensity gradient along the motion; use a textured image")
    return float((g2 * img).sum() / total)


@dataclass(frozen=True)
class ExposurePlan:
    """Result of :func:`plan_exposure` (times in s, lengths in mm, blur and u_e in px).

    ``inside_domain``: the planned blur (and, with a camera, the noise there) lies inside
    the model's validity domain; ``extrapolated`` is its negation. ``limited_by_breakdown``:
    the answer is capped at the blur length where DIC breaks down. ``domain`` is the
    model's :class:`~dicblur.models.ValidityDomain` as a dict. ``notes`` says all of it in
    words. ``compensation``: the model's matcher mode (``"none"``: the plain matcher;
    ``"given"``, ``"estimate"``: blur-compensated; ``"deblur"``).
    """

    model: str
    velocity: float
    scale: float
    velocity_px: float
    target: float | None
    exposure: float
    blur: float
    u_e: float
    u_e_low: float
    u_e_high: float
    max_exposure: float | None
    min_exposure: float | None
    optimal: bool
    saturation_exposure: float | None
    rule_of_thumb_exposure: float
    rule_of_thumb_u_e: float
    curve_exposure: Float64Array = field(repr=False)
    curve_blur: Float64Array = field(repr=False)
    curve_u_e: Float64Array = field(repr=False)
    notes: tuple[str, ...] = ()
    camera: dict[str, float] | None = None
    inside_domain: bool = True
    extrapolated: bool = False
    limited_by_breakdown: bool = False
    domain: dict[str, Any] | None = None
    compensation: str = "none"

    def summary(self) -> str:
        """A readable answer."""
        lines = [
            f"motion {self.velocity:g} mm/s at {self.scale:g} mm/px = {self.velocity_px:g} px/s "
            f"(model: {self.model}; {compensation_label(self.compensation)})",
        ]
        kind = "optimal exposure" if self.optimal else "longest exposure under the target"
        lines.append(
            f"{kind}: {format_time(self.exposure)} -> blur {self.blur:.3g} px, "
            f"u_e {self.u_e:.3g} px [{self.u_e_low:.3g}, {self.u_e_high:.3g}] "
            f"= {self.u_e * self.scale * 1e3:.3g} um"
        )
        if self.target is not None:
            if self.max_exposure is None:
                lines.append(f"target {self.target:g} px: not reachable at any exposure")
            else:
                lo = "" if self.min_exposure is None else f"{format_time(self.min_exposure)} .. "
                lines.append(
                    f"target {self.target:g} px met for exposures {lo}"
                    f"{format_time(self.max_exposure)}"
                )
        lines.append(
            f"rule of thumb (blur <= {RULE_OF_THUMB_BLUR} px): exposure "
            f"{format_time(self.rule_of_thumb_exposure)}, u_e {self.rule_of_thumb_u_e:.3g} px; "
            f"planned exposure = {self.exposure / self.rule_of_thumb_exposure:.3g} x that"
        )
        lines += list(self.notes)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("curve_exposure", "curve_blur", "curve_u_e"):
            d[k] = [float(x) for x in d[k]]
        d["notes"] = list(self.notes)
        return d


def format_time(t: float) -> str:
    """An exposure time (s) in s, ms or us, four significant digits."""
    if t >= 1:
        return f"{t:.4g} s"
    if t >= 1e-3:
        return f"{t * 1e3:.4g} ms"
    return f"{t * 1e6:.4g} us"


def domain_note(what: str, inside: bool, domain: ValidityDomain) -> str:
    """The plan's note on whether ``what`` (a planned W) lies inside the model's
    validity domain."""
    return (
        f"{what} lies {'inside' if inside else 'outside'} the model's validity domain "
        f"({domain.describe()})" + ("" if inside else ": extrapolated")
    )


def plan_exposure(
    model: BlurUncertaintyModel,
    *,
    velocity: float | str,
    scale: float | str,
    target: float | str | None = None,
    camera: PoissonGaussianCamera | None = None,
    sigma: float | None = None,
    which: str | None = None,
    n_curve: int = 200,
    noise_level: float | None = None,
    mean_level: float | None = None,
) -> ExposurePlan:
    """Choose the exposure time for a moving target.

    Parameters
    ----------
    model : BlurUncertaintyModel
    velocity : float or str
        Target speed in the image plane: mm/s, or a string (``"120mm/s"``, ``"0.1m/s"``,
        ``"800px/s"``).
    scale : float or str
        Image scale, mm/px (``"0.05mm/px"`` or ``"20px/mm"``).
    target : float or str, optional
        Largest acceptable u_e: px (``"0.01px"``) or a length (``"0.5um"``). Required without
        a camera.
    camera : PoissonGaussianCamera, optional
        With a camera the noise follows the exposure and the optimum is returned.
    sigma : float, optional
        Fixed-noise case: noise std (GL); default the model's.
    which : {"mismatch", "power_law", "static"}, optional
        Model to use (default: the model's default).
    n_curve : int
        Points of the returned u_e(t) curve.
    noise_level : float, optional
        Intensity (GL of the fitted reference images) at which the camera's shot noise is
        evaluated: :func:`gradient_weighted_level` of the reference image. Default: the
        model's mean level.
    mean_level : float, optional
        Mean grey level (GL) of the images the model was fitted on, when the model does not
        record it (e.g. the mean of the reference image given with ``noise_level``);
        default the model's, else 127.5 GL with a note.

    Returns
    -------
    ExposurePlan
    """
    if not isinstance(model, BlurUncertaintyModel):
        raise InputError("model: expected a BlurUncertaintyModel (dicblur.fit_blur_model)")
    sc = parse_quantity(scale, "scale", name="scale")
    if sc <= 0:
        raise InputError(f"scale={scale!r}: must be > 0 (mm/px), e.g. '0.05mm/px'")
    v = parse_quantity(velocity, "velocity", name="velocity", scale=sc)
    if v == 0:
        raise InputError(
            f"velocity={velocity!r}: zero speed means no blur; any exposure works (give the "
            "target's speed, e.g. '120mm/s')"
        )
    v = abs(v)
    v_px = v / sc
    tgt = None if target is None else parse_quantity(target, "blur", name="target", scale=sc)
    if tgt is not None and tgt <= 0:
        raise InputError(f"target={target!r}: must be > 0 px, e.g. '0.01px'")
    if not isinstance(n_curve, int) or n_curve < 10:
        raise InputError(f"n_curve={n_curve!r}: use an integer >= 10")
    kind = model._kind(which)
    notes: list[str] = []
    t_rule = RULE_OF_THUMB_BLUR / v_px
    dom = model.domain
    assert dom is not None
    w_break = dom.breakdown_blur

    def planned(at: Prediction, inside: bool, limited: bool, **chosen: Any) -> ExposurePlan:
        """The plan of the ``chosen`` exposure (its own fields) with the fields both
        planners fill alike: the request, the prediction ``at`` the chosen blur, the rule
        of thumb's exposure, the notes and the validity domain."""
        return ExposurePlan(
            model=kind,
            velocity=v,
            scale=sc,
            velocity_px=v_px,
            target=tgt,
            u_e=float(at.u_e[0]),
            u_e_low=float(at.low[0]),
            u_e_high=float(at.high[0]),
            rule_of_thumb_exposure=t_rule,
            notes=tuple(notes),
            inside_domain=inside,
            extrapolated=not inside,
            limited_by_breakdown=limited,
            domain=dom.to_dict(),
            compensation=dom.compensation,
            **chosen,
        )

    if camera is None:
        if tgt is None:
            raise InputError(
                "target: give a target u_e (e.g. '0.01px') or a camera "
                "(full_well, read_noise, flux) to plan an exposure"
            )
        w_max = model.max_blur(tgt, sigma, model=kind)
        t_fix = w_max / v_px
        limited = w_break is not None and w_max >= w_break * (1.0 - 1e-12)
        if limited:
            notes.append(
                f"the target holds up to W = {w_break:g} px, where DIC breaks down "
                f"({dom.breakdown_rule}); no longer exposure is planned"
            )
        t = np.linspace(0.0, 2.0 * max(t_fix, t_rule), n_curve)
        pred = model.predict(t * v_px, sigma, model=kind)
        at = model.predict([w_max], sigma, model=kind)
        u_rule = float(model.predict([RULE_OF_THUMB_BLUR], sigma, model=kind).u_e[0])
        if t_fix > t_rule:
            notes.append(f"the model allows {t_fix / t_rule:.3g}x the rule-of-thumb exposure")
        else:
            notes.append("the rule of thumb is not conservative enough for this target")
        sig_used = at.sigma
        assert at.inside_domain is not None
        inside = bool(at.inside_domain[0])  # blur and noise range (power law: fit range)
        notes.append(
            domain_note(
                f"planned W = {w_max:.3g} px"
                + ("" if dom.inside_noise(sig_used) else f" at noise {sig_used:.3g} GL"),
                inside,
                dom,
            )
        )
        return planned(
            at,
            inside,
            limited,
            exposure=t_fix,
            blur=w_max,
            max_exposure=t_fix,
            min_exposure=None,
            optimal=False,
            saturation_exposure=None,
            rule_of_thumb_u_e=u_rule,
            curve_exposure=t,
            curve_blur=t * v_px,
            curve_u_e=pred.u_e,
        )

    for attr in ("full_well", "read_noise", "flux"):
        if not hasattr(camera, attr):
            raise InputError(
                f"camera: needs a {attr!r} attribute; use PoissonGaussianCamera (or "
                "PoissonGaussianCamera.from_camera for a dicblur.Camera)"
            )
    if sigma is not None:
        raise InputError("sigma: with a camera the noise follows the exposure; omit sigma")
    fit = model._fit(kind)
    if kind == "power_law":
        raise InputError(
            "camera: with a camera the noise follows the exposure, and the power law "
            "(eq. 17) predicts only at the noise it was fitted at; plan with "
            "which='mismatch' (CLI: --model mismatch), the noise + blur-mismatch model"
        )
    if kind == "mismatch" and "a" not in fit.names:
        raise InputError(
            "camera: the model was fitted without a noise level, so it cannot follow the "
            "noise with the exposure; refit with noise_sigma"
        )
    if mean_level is not None:
        mean_level = check_positive(mean_level, "mean_level")
    elif model.mean_level is not None:
        mean_level = model.mean_level
    else:
        mean_level = 127.5
        notes.append("mean grey level of the reference images unknown: assumed 127.5 GL")
    t_sat = float(getattr(camera, "saturation_exposure", math.inf))
    theta, _ = model._theta(kind)
    if noise_level is not None:
        noise_level = check_positive(noise_level, "noise_level")

    def noise(tt: Float64Array | float) -> Float64Array:
        if noise_level is None:
            return np.asarray(camera.noise_gl(tt, mean_level))
        return np.asarray(camera.noise_gl(tt, mean_level, noise_level))

    def log_u(tt: Float64Array) -> Float64Array:
        sig = noise(tt)
        return np.array(
            [
                model._log_u(kind, np.array([ti * v_px]), float(si), theta)[0]
                for ti, si in zip(tt, sig, strict=True)
            ]
        )

    # search blur lengths 1e-4 .. 1e4 px, capped by saturation and by DIC's breakdown
    t_lo = 1e-4 / v_px
    t_hi = min(t_sat, 1e4 / v_px)
    limited = False
    if w_break is not None and w_break / v_px < t_hi:
        t_hi = w_break / v_px * (1.0 - 1e-9)
        limited = True
    if t_hi <= t_lo:
        raise InputError(
            f"camera: the sensor saturates after {t_sat:.3g} s, before the target moves "
            "1e-4 px; lower the flux (light) or check the camera numbers"
        )
    grid = np.geomspace(t_lo, t_hi, 600)
    lg = log_u(grid)
    i = int(np.argmin(lg))
    if 0 < i < grid.size - 1:
        r = optimize.minimize_scalar(
            lambda x: float(log_u(np.array([math.exp(x)]))[0]),
            bounds=(math.log(grid[i - 1]), math.log(grid[i + 1])),
            method="bounded",
            options={"xatol": 1e-10},
        )
        t_opt = float(math.exp(r.x))
    else:
        t_opt = float(grid[i])
        if i == grid.size - 1 and limited:
            notes.append(
                f"u_e still falls at W = {w_break:g} px, where DIC breaks down "
                f"({dom.breakdown_rule}): the plan stops there"
            )
        else:
            notes.append(
                "the optimum is at the saturation limit (brighter light or a "
                "shorter exposure range changes the answer)"
                if i == grid.size - 1
                else "the optimum is at the shortest exposure searched"
            )
    limited = limited and i == grid.size - 1
    sig_opt = float(noise(t_opt))
    levels = model.noise_levels
    if (
        kind == "mismatch"
        and len(levels) == 1
        and not (0.5 <= sig_opt / levels[0] <= 2.0)
        and "floor" not in fit.names
    ):
        notes.append(
            f"the noise term is extrapolated from one calibration noise level ({levels[0]:g} "
            f"GL) to {sig_opt:.3g} GL at the optimum; a noise-independent floor (sub-pixel "
            "interpolation bias) cannot be separated at one level and inflates the "
            "extrapolated noise: calibrate at >= 2 noise levels (docs/models.md s. 4)"
        )
    at = model.predict([t_opt * v_px], sig_opt, model=kind)
    t_curve = np.geomspace(max(t_lo, t_opt / 100), min(t_hi, t_opt * 100), n_curve)
    u_curve = np.exp(log_u(t_curve))
    u_rule = float(np.exp(log_u(np.array([t_rule]))[0]))
    t_min: float | None = None
    t_max: float | None = None
    if tgt is not None:
        ok = np.exp(lg) <= tgt
        if ok.any():

            def f(x: float) -> float:
                return float(log_u(np.array([math.exp(x)]))[0]) - math.log(tgt)

            j0, j1 = int(np.argmax(ok)), int(ok.size - 1 - np.argmax(ok[::-1]))
            t_min = (
                float(math.exp(optimize.brentq(f, math.log(grid[j0 - 1]), math.log(grid[j0]))))
                if j0 > 0
                else float(grid[0])
            )
            t_max = (
                float(math.exp(optimize.brentq(f, math.log(grid[j1]), math.log(grid[j1 + 1]))))
                if j1 < grid.size - 1
                else float(grid[-1])
            )
        else:
            notes.append(
                f"target {tgt:g} px is below the best achievable u_e {float(at.u_e[0]):.3g} px"
            )
    notes.append(
        f"rule of thumb gives u_e {u_rule:.3g} px vs {float(at.u_e[0]):.3g} px at the optimum"
    )
    w_opt = t_opt * v_px
    assert at.inside_domain is not None
    inside = bool(at.inside_domain[0])
    notes.append(
        domain_note(f"the optimum (W = {w_opt:.3g} px, noise {sig_opt:.3g} GL)", inside, dom)
    )
    return planned(
        at,
        inside,
        limited,
        exposure=t_opt,
        blur=t_opt * v_px,
        max_exposure=t_max,
        min_exposure=t_min,
        optimal=True,
        saturation_exposure=t_sat if math.isfinite(t_sat) else None,
        rule_of_thumb_u_e=u_rule,
        curve_exposure=t_curve,
        curve_blur=t_curve * v_px,
        curve_u_e=u_curve,
        camera={
            k: float(getattr(camera, k))
            for k in ("full_well", "read_noise", "flux", "peak_to_mean")
            if hasattr(camera, k)
        },
    )
