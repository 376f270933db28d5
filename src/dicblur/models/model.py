"""The fitted blur-uncertainty model as a value: predictions, limits, report, JSON."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, fields
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import optimize

from ..arrays import BoolArray, Float64Array
from ..checks import as_vector, check_positive
from ..errors import FitError, InputError
from ._result import FitResult, t_quantile
from .decay import mbrf as _mbrf
from .decay import sssig_decay
from .domain import COMPENSATIONS, ValidityDomain, compensation_label
from .mismatch import mismatch_terms
from .model_schema import SCHEMA, SCHEMA_V1, validate_model_dict
from .scaled import static_variance

__all__ = ["BlurUncertaintyModel", "ModelKind", "Prediction"]

ModelKind = Literal["mismatch", "power_law", "static"]
_KINDS = ("mismatch", "power_law", "static")


@dataclass(frozen=True)
class Prediction:
    """Predicted uncertainty over blur lengths, with a prediction interval.

    Attributes
    ----------
    blur : ndarray, shape (n,)
        W (px).
    u_e : ndarray, shape (n,)
        Predicted random error along the motion (px).
    low, high : ndarray, shape (n,)
        Prediction interval (level ``confidence``) for a new measurement: parameter
        covariance (delta method, in log space) plus the fit's residual scatter.
    u_noise, u_blur : ndarray or None
        The noise and blur-mismatch terms of the mismatch model or the static kind (px;
        ``None`` for the power law).
    sigma : float or None
        Noise std (GL) the prediction is for.
    model : str
    confidence : float
    u_floor : float or None
        Noise-independent floor ``u_0`` of the mismatch model (px), if fitted.
    inside_domain : ndarray of bool, shape (n,)
        Per W: inside the model's validity domain (fitted blur range, and the noise inside
        the fitted noise range).
    broken_down : ndarray of bool, shape (n,)
        Per W: at or beyond the blur length where DIC broke down; ``u_e``, ``low`` and
        ``high`` are NaN there (no prediction, see ``notes``).
    extrapolated : bool
        Some W (or the noise) lies outside the domain.
    notes : tuple of str
        One line per reason (extrapolation, breakdown).
    compensation : str
        Matcher mode of the model (``"none"``: plain; ``"given"``, ``"estimate"``:
        blur-compensated; ``"deblur"``), from its validity domain.
    """

    blur: Float64Array
    u_e: Float64Array
    low: Float64Array
    high: Float64Array
    u_noise: Float64Array | None
    u_blur: Float64Array | None
    sigma: float | None
    model: str
    confidence: float
    u_floor: float | None = None
    inside_domain: BoolArray | None = None
    broken_down: BoolArray | None = None
    extrapolated: bool = False
    notes: tuple[str, ...] = ()
    compensation: str = "none"


@dataclass(frozen=True)
class BlurUncertaintyModel:
    """Fitted uncertainty model of one pattern / subset / DIC setting (see fit_blur_model).

    Attributes
    ----------
    default : {"mismatch", "power_law", "static"}
        Model used by :meth:`predict`, :meth:`max_blur` and planning when none is named:
        ``static`` when the calibration had the pattern image (``dicblur calibrate``),
        else ``mismatch`` unless asked otherwise (the power law cannot follow the noise).
    decay : FitResult
        SSSIG(W) decay, eq. 18 (``sssig0`` (GL/px)**2, ``beta`` 1/px**2).
    power_law : FitResult
        Eq. 17 on the edge-driven range, as ``u_e = u_ref (SSSIG / sssig_ref)**-alpha``
        (``u_ref`` px, ``alpha``[, ``kappa``]; ``extra["sssig_ref"]`` = SSSIG_0).
    mismatch : FitResult or None
        Noise + blur-mismatch model (``a`` or ``k``, [``gamma``], ``c`` px/px**2, [``c4``]).
    fit_range : (float, float)
        W range (px) of the power-law fit; ``range_rule`` says how it was chosen.
    noise_sigma : float or None
        Reference noise std (GL): the single level of the data, or None (unknown or several).
    noise_levels : tuple of float
    subset : int or None
    mean_level : float or None
        Mean grey level of the reference images (GL), used by exposure planning.
    c_static : float or None
        Blur sensitivity predicted from the static image (px/px**2), if supplied.
    data : dict
        The fitted data and diagnostics per point: ``blur``, ``sssig``, ``u_e``, optional
        ``noise`` and ``contrast_ratio``, and the relative model errors ``err_power_law``
        (eq. 17 at the measured SSSIG) and ``err_mismatch`` (the paper's Fig. 8 data).
    comparison : dict or None
        Held-out comparison of the two models (:func:`compare_models`).
    provenance : dict
        Pattern hash or generator settings, DIC settings, ... (JSON-ready).
    version : str
        dicblur version that fitted the model.
    confidence : float
        Level of every confidence and prediction interval.
    domain : ValidityDomain
        Blur and noise ranges, subset, shape, pattern and breakdown blur of the fitted
        data (filled from the other fields for models built without it).
    static : FitResult or None
        The static kind (:mod:`dicblur.models.scaled`): scales ``k_noise`` and ``k_blur``
        of the static prediction's noise and noise-free terms, whose table (computed
        once from the reference pattern) is in ``static.extra``.
    """

    default: str
    decay: FitResult
    power_law: FitResult
    mismatch: FitResult | None
    fit_range: tuple[float, float]
    range_rule: str
    noise_sigma: float | None
    noise_levels: tuple[float, ...]
    subset: int | None
    mean_level: float | None
    c_static: float | None
    data: dict[str, tuple[float, ...]]
    comparison: dict[str, Any] | None
    provenance: dict[str, Any]
    version: str
    confidence: float
    domain: ValidityDomain | None = None
    static: FitResult | None = None

    def __post_init__(self) -> None:
        if self.domain is None:
            object.__setattr__(self, "domain", _domain_from_fields(self))

    # ------------------------------------------------------------------ parameters
    @property
    def alpha(self) -> float:
        return self.power_law["alpha"]

    @property
    def beta(self) -> float:
        return self.decay["beta"]

    @property
    def u_ref(self) -> float:
        """Power law's u_e (px) at ``sssig_ref`` (= SSSIG_0: its static u_e(0))."""
        return self.power_law["u_ref"]

    @property
    def sssig_ref(self) -> float:
        """Reference SSSIG ((GL/px)**2) of the power law's ``u_ref``."""
        return float(self.power_law.extra["sssig_ref"])

    @property
    def eta(self) -> float:
        """The paper's ``eta = u_ref sssig_ref**alpha`` (px (GL/px)**(2 alpha)), derived."""
        return self.u_ref * self.sssig_ref**self.alpha

    @property
    def mbrf(self) -> float:
        """Motion blur rejection factor ``2 alpha beta`` (1/px**2), paper eq. 22."""
        return _mbrf(self.alpha, self.beta)

    @property
    def compensation(self) -> str:
        """Matcher mode the model was fitted on (``domain.compensation``): ``"none"`` (the
        plain matcher), ``"given"`` / ``"estimate"`` (blur-compensated), ``"deblur"``."""
        assert self.domain is not None
        return self.domain.compensation

    @property
    def matcher(self) -> str:
        """The matcher mode in words (``"blur-compensated matcher (blur given)"``)."""
        return compensation_label(self.compensation)

    @property
    def c(self) -> float | None:
        """Fitted blur-mismatch coefficient (px / px**2), or None."""
        return None if self.mismatch is None else self.mismatch["c"]

    def sssig(self, blur: ArrayLike) -> Float64Array:
        """SSSIG(W) from the eq. 18 fit, (GL/px)**2."""
        return sssig_decay(blur, self.decay["sssig0"], self.decay["beta"])

    # ------------------------------------------------------------------ evaluation
    def _kind(self, model: str | None) -> str:
        kind = self.default if model is None else model
        if kind not in _KINDS:
            raise InputError(f"model={model!r}: choose 'mismatch', 'power_law' or 'static'")
        if kind == "mismatch" and self.mismatch is None:
            raise InputError("model='mismatch': this model has no mismatch fit; use 'power_law'")
        if kind == "static" and self.static is None:
            raise InputError(
                "model='static': this model has no static kind (made by dicblur calibrate "
                "from the pattern image); use 'mismatch'"
            )
        return kind

    def _fit(self, kind: str) -> FitResult:
        if kind == "static":
            assert self.static is not None
            return self.static
        fit = self.mismatch if kind == "mismatch" else self.power_law
        assert fit is not None
        return fit

    def _log_u(
        self, kind: str, w: Float64Array, sigma: float | None, theta: Float64Array
    ) -> Float64Array:
        fit = self._fit(kind)
        nf = len(fit.names)
        p = dict(zip(fit.names, theta[:nf], strict=True))
        s = sssig_decay(w, theta[nf], theta[nf + 1])
        if kind == "power_law":
            alpha = p["alpha"]
            kappa = p.get("kappa", 2.0 * alpha)
            ref = fit.extra.get("sigma_ref")
            lu = np.log(p["u_ref"]) - alpha * np.log(s / fit.extra["sssig_ref"])
            if sigma is not None and ref is not None:
                lu = lu + kappa * math.log(sigma / ref)
            return lu
        if kind == "static":
            assert sigma is not None
            noise, blur2 = static_variance(fit.extra, w, sigma, p["k_noise"], p["k_blur"])
            return 0.5 * np.log(noise + blur2)
        noise, blur2 = self._mismatch_terms(p, w, s, sigma)
        return 0.5 * np.log(noise + p.get("floor", 0.0) ** 2 + blur2)

    def _mismatch_terms(
        self,
        p: dict[str, float],
        w: Float64Array,
        s: Float64Array,
        sigma: float | None,
    ) -> tuple[Float64Array, Float64Array]:
        gamma = p.get("gamma", self.mismatch.fixed.get("gamma", 1.0) if self.mismatch else 1.0)
        if "k" in p:
            return mismatch_terms(
                w,
                s,
                None,
                k=p["k"],
                c=p["c"],
                c4=p.get("c4", 0.0),
                noise_blur=p.get("noise_blur", 0.0),
                cross=p.get("cross", 0.0),
                noise_blur2=p.get("noise_blur2", 0.0),
            )
        assert sigma is not None
        return mismatch_terms(
            w,
            s,
            sigma,
            a=p["a"],
            gamma=gamma,
            c=p["c"],
            c4=p.get("c4", 0.0),
            noise_blur=p.get("noise_blur", 0.0),
            cross=p.get("cross", 0.0),
            noise_blur2=p.get("noise_blur2", 0.0),
        )

    def _sigma(self, kind: str, sigma: float | None) -> float | None:
        if sigma is not None:
            sigma = check_positive(sigma, "sigma")
        fit = self._fit(kind)
        has_noise = (
            (kind == "power_law" and fit.extra.get("sigma_ref") is not None)
            or (kind == "mismatch" and "a" in fit.names)
            or kind == "static"
        )
        if sigma is not None and not has_noise:
            raise InputError(
                f"sigma={sigma!r}: the model was fitted without noise levels, so it cannot "
                "predict at another noise; refit with noise_sigma or use sigma=None"
            )
        if sigma is not None and kind == "power_law":
            self._check_power_law_noise(sigma)
        if sigma is None and has_noise:
            if self.noise_sigma is None:
                levels = [float(v) for v in self.noise_levels]
                raise InputError(
                    f"sigma: the model was fitted on several noise levels ({levels} GL); "
                    f"give the noise of your images, e.g. sigma={levels[-1]:g}"
                )
            return float(self.noise_sigma)
        return sigma

    def _check_power_law_noise(self, sigma: float) -> None:
        """Refuse a power-law prediction away from the noise it was fitted at."""
        levels = [float(v) for v in self.power_law.extra.get("noise_levels", [])]
        if not levels:
            return
        lo, hi = min(levels), max(levels)
        if lo * (1 - 1e-6) <= sigma <= hi * (1 + 1e-6) and (
            len(levels) > 1 or math.isclose(sigma, lo)
        ):
            return
        where = f"{lo:g} GL" if len(levels) == 1 else f"{lo:g}..{hi:g} GL"
        raise InputError(
            f"sigma={sigma:g} GL: the power law (eq. 17) was fitted at noise {where} and "
            "its noise dependence is not measured (one level: u_e would scale as "
            f"sigma^(2 alpha) = sigma^{2 * self.alpha:.2g}); use model='mismatch' "
            "(CLI: --model mismatch), the noise + blur-mismatch model, to predict at "
            "another noise level"
        )

    def _theta(self, kind: str) -> tuple[Float64Array, Float64Array]:
        fit = self._fit(kind)
        theta = np.array([*fit.values, *self.decay.values])
        nf = len(fit.names)
        cov = np.zeros((theta.size, theta.size))
        cov[:nf, :nf] = fit.cov_array
        cov[nf:, nf:] = self.decay.cov_array
        return theta, cov

    def predict(
        self, blur: ArrayLike, sigma: float | None = None, *, model: str | None = None
    ) -> Prediction:
        """Predict u_e (px) at blur lengths ``blur`` (px) and noise ``sigma`` (GL).

        Parameters
        ----------
        blur : float or array_like, shape (n,)
            W >= 0, px.
        sigma : float, optional
            Noise std (GL). Default: the noise of the fitted data (single level).
        model : {"mismatch", "power_law", "static"}, optional
            Default: ``self.default``. The power law uses eq. 19 (eq. 17 with SSSIG from
            eq. 18) and, at another noise, the scale-consistent factor
            ``(sigma / sigma_ref)**kappa``; ``static`` interpolates the static
            prediction's tabulated terms (:mod:`dicblur.models.scaled`).

        Returns
        -------
        Prediction
        """
        w = as_vector(blur, "blur")
        if np.any(w < 0):
            raise InputError(
                f"blur: negative blur length {float(w[w < 0][0])!r} px; W must be >= 0"
            )
        kind = self._kind(model)
        sig = self._sigma(kind, sigma)
        lu, half, u_noise, u_blur, u_floor = self._evaluate(kind, w, sig)
        dom = self.domain
        assert dom is not None
        inside = dom.inside_blur(w) & dom.inside_noise(sig)
        broken = dom.broken_down(w)
        notes = []
        reason = dom.outside_reason(w[~broken], sig)
        if reason is not None:
            notes.append(reason)
        if kind == "power_law":
            # the power law was fitted on its edge-driven range only
            lo, hi = self.fit_range
            in_fit = (w >= lo - 1e-9) & (w <= hi + 1e-9)
            if (~in_fit & inside).any():
                out = w[~in_fit & inside]
                notes.append(
                    f"W = {', '.join(f'{x:.3g}' for x in out[:3])}"
                    f"{' ...' if out.size > 3 else ''} px outside the power law's "
                    f"fit range (W {lo:g}..{hi:g} px): extrapolated"
                )
            inside &= in_fit
        if broken.any():
            notes.append(self.breakdown_note(w[broken]))
            for arr in (lu, half):
                arr[broken] = np.nan
            if u_noise is not None and u_blur is not None:
                u_noise[broken] = np.nan
                u_blur[broken] = np.nan
        # an unidentified parameter gives an unbounded interval: exp(inf) = inf is meant
        with np.errstate(over="ignore"):
            low, high = np.exp(lu - half), np.exp(lu + half)
        return Prediction(
            blur=w,
            u_e=np.exp(lu),
            low=low,
            high=high,
            u_noise=u_noise,
            u_blur=u_blur,
            sigma=sig,
            model=kind,
            confidence=self.confidence,
            u_floor=u_floor,
            inside_domain=inside & ~broken,
            broken_down=broken,
            extrapolated=bool((~inside & ~broken).any()),
            notes=tuple(notes),
            compensation=dom.compensation,
        )

    def breakdown_note(self, blur: Float64Array) -> str:
        """The one-line reason why no prediction is made at ``blur`` (px)."""
        dom = self.domain
        assert dom is not None and dom.breakdown_blur is not None
        return (
            f"no prediction at W = {', '.join(f'{x:.3g}' for x in blur[:3])}"
            f"{' ...' if blur.size > 3 else ''} px: DIC breaks down from W = "
            f"{dom.breakdown_blur:g} px ({dom.breakdown_rule or 'breakdown'})"
        )

    def _evaluate(
        self, kind: str, w: Float64Array, sig: float | None
    ) -> tuple[
        Float64Array,
        Float64Array,
        Float64Array | None,
        Float64Array | None,
        float | None,
    ]:
        """log u_e, the half-width of its prediction interval and the mismatch terms."""
        theta, cov = self._theta(kind)
        lu = self._log_u(kind, w, sig, theta)
        grad = np.empty((w.size, theta.size))
        for j in range(theta.size):
            h = 1e-6 * max(abs(theta[j]), 1e-12)
            tp = theta.copy()
            tp[j] += h
            grad[:, j] = (self._log_u(kind, w, sig, tp) - lu) / h
        fit = self._fit(kind)
        with np.errstate(invalid="ignore"):
            var = np.einsum("ni,ij,nj->n", grad, cov, grad) + fit.residual_std**2
        if not np.all(np.isfinite(cov)):
            var = np.full(w.size, np.inf)  # unidentified parameters: unbounded interval
        tq = t_quantile(self.confidence, fit.dof)
        half = tq * np.sqrt(np.clip(var, 0.0, None))
        u_noise = u_blur = None
        u_floor: float | None = None
        if kind == "mismatch":
            nf = len(fit.names)
            p = dict(zip(fit.names, theta[:nf], strict=True))
            noise, blur2 = self._mismatch_terms(p, w, self.sssig(w), sig)
            u_noise, u_blur = np.sqrt(noise), np.sqrt(blur2)
            u_floor = float(p["floor"]) if "floor" in p else None
        elif kind == "static":
            assert sig is not None
            nv, bv = static_variance(fit.extra, w, sig, fit["k_noise"], fit["k_blur"])
            u_noise, u_blur = np.sqrt(nv), np.sqrt(bv)
        return lu, half, u_noise, u_blur, u_floor

    def taylor(self, blur: ArrayLike) -> Float64Array:
        """Small-W expansion of eq. 19 at the fit noise: ``u_e(0) (1 + alpha beta W**2)``."""
        w = as_vector(blur, "blur")
        u0 = float(self.predict([0.0], model="power_law").u_e[0])
        return u0 * (1.0 + self.alpha * self.beta * w * w)

    def max_blur(
        self, target: float, sigma: float | None = None, *, model: str | None = None
    ) -> float:
        """Largest blur length W (px) whose predicted u_e stays <= ``target`` (px).

        Capped at the domain's breakdown blur (DIC fails beyond it): if the target still
        holds there, that W is returned. The W may lie outside the fitted blur range
        (check ``domain.inside_blur``).

        Raises
        ------
        InputError
            If ``target <= 0`` or the static uncertainty u_e(0) already exceeds it.
        """
        target = check_positive(target, "target")
        kind = self._kind(model)
        sig = self._sigma(kind, sigma)

        def f(wv: float) -> float:
            return float(np.exp(self._evaluate(kind, np.array([wv]), sig)[0][0])) - target

        u0 = f(0.0) + target
        if u0 > target:
            raise InputError(
                f"target={target:g} px: below the static uncertainty u_e(0) = {u0:.3g} px of "
                "this pattern and noise; no blur length meets it (raise the target, lower "
                "the noise or use a larger subset)"
            )
        assert self.domain is not None
        w_break = self.domain.breakdown_blur
        if w_break is not None and f(w_break) < 0:
            # DIC breaks down before the target is reached: the last W before it
            return float(np.nextafter(w_break, 0.0))
        hi = 1.0
        while f(hi) < 0:
            hi *= 2.0
            if hi > 1e6:
                raise FitError(f"target={target:g} px: the model never reaches it (W < 1e6 px)")
        return float(optimize.brentq(f, 0.0, hi, xtol=1e-12, rtol=1e-12))

    # ------------------------------------------------------------------ text and JSON
    def report(self) -> str:
        """Readable summary: parameters with CIs, R^2, fit ranges, comparison, provenance."""
        pct = f"{100 * self.confidence:g}%"
        lines = [
            f"dicblur blur-uncertainty model (dicblur {self.version}); default: {self.default}",
            f"matcher: {self.matcher}",
            f"subset {'unknown' if self.subset is None else f'{self.subset} px'}; noise "
            f"levels {list(self.noise_levels) or 'unknown'} GL; "
            f"{len(self.data['blur'])} points, W {min(self.data['blur']):g}..."
            f"{max(self.data['blur']):g} px",
            f"validity domain: {self.domain.describe() if self.domain else 'unknown'}"
            + (
                f"; DIC breaks down from W = {self.domain.breakdown_blur:g} px"
                if self.domain and self.domain.breakdown_blur is not None
                else ""
            ),
            "",
            f"SSSIG decay (eq. 18), R^2 = {self.decay.r2:.4f} [{self.decay.ci_method} {pct} CI]",
        ]

        def block(fit: FitResult) -> None:
            how = "" if fit.ci_method in ("covariance", "none") else f" ({fit.ci_method})"
            for p in fit.parameters:
                ci = "fixed" if p.fixed else f"[{p.low:.4g}, {p.high:.4g}]{how}"
                if not p.fixed and not (math.isfinite(p.low) and math.isfinite(p.high)):
                    ci = f"no bounded interval{how}: the data do not constrain it"
                lines.append(f"  {p.name:7s} = {p.value:.5g}  {ci}")

        block(self.decay)
        lines += [
            f"power law (eq. 17) on W {self.fit_range[0]:g}..{self.fit_range[1]:g} px "
            f"({self.range_rule}), R^2 (log) = {self.power_law.r2:.4f}"
        ]
        lines.append(
            f"  u_e = u_ref (SSSIG / {self.sssig_ref:.4g})^-alpha; the paper's eta = "
            f"u_ref sssig_ref^alpha = {self.eta:.4g} (units depend on alpha); "
            "predicts only at the noise it was fitted at"
        )
        block(self.power_law)
        lines.append(
            f"  MBRF = 2 alpha beta = {self.mbrf:.4g} 1/px^2 "
            f"(u_e ~ u_e(0) (1 + {self.alpha * self.beta:.4g} W^2))"
        )
        if self.power_law.extra.get("kappa_rule") == "fitted":
            lines.append(
                f"  scale consistency: kappa = {self.power_law['kappa']:.3g} vs "
                f"2 alpha = {2 * self.alpha:.3g}"
            )
        if self.mismatch is not None:
            lines.append(
                f"noise + blur mismatch, R^2 (log) = {self.mismatch.r2:.4f}, "
                f"residual {100 * self.mismatch.residual_std:.2g}% rms"
            )
            block(self.mismatch)
            if self.c_static is not None:
                lines.append(
                    f"  c predicted from the static image = {self.c_static:.4g} "
                    f"(fitted / predicted = {self.mismatch['c'] / self.c_static:.3f})"
                )
        if self.static is not None:
            st = self.static
            tab = st.extra["table_blur"]
            brk = st.extra.get("table_breakdown_blur")
            lines.append(
                f"static kind (static prediction x 2 scales), R^2 (log) = {st.r2:.4f}, "
                f"residual {100 * st.residual_std:.2g}% rms; table W {tab[0]:g}..{tab[-1]:g} "
                f"px ({len(tab)} points, offset {st.extra.get('subpixel')})"
                + ("" if brk is None else f", static breakdown W {brk:g} px")
            )
            block(st)
        if self.comparison:
            cmp_ = self.comparison
            static_rms = cmp_["rms_log_error"].get("static")
            lines.append(
                f"held-out comparison ({cmp_['n_test']} points): rms log error power law "
                f"{cmp_['rms_log_error']['power_law']:.3g}, mismatch "
                f"{cmp_['rms_log_error']['mismatch']:.3g}"
                + ("" if static_rms is None else f", static {static_rms:.3g}")
                + f" -> {cmp_['better']}"
            )
        if self.provenance:
            lines.append("provenance: " + json.dumps(self.provenance, sort_keys=True))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"schema": SCHEMA}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, FitResult | ValidityDomain):
                v = v.to_dict()
            elif f.name == "data":
                v = {k: list(x) for k, x in v.items()}
            elif isinstance(v, tuple):
                v = list(v)
            d[f.name] = v
        return d

    def to_json(self, path: str | None = None) -> str:
        """JSON text (floats written with repr: the round trip is bit-exact); no pickle.

        With ``path``, also write it to that file.
        """
        text = json.dumps(self.to_dict(), indent=1)
        if path is not None:
            from pathlib import Path

            from ..io import write_text

            write_text(Path(path), text + "\n")
        return text

    @classmethod
    def from_json(cls, text: str) -> BlurUncertaintyModel:
        """Rebuild a model from :meth:`to_json` text (or a path to a ``.json`` file).

        Files of schema /1 (power law as ``eta``, no domain) load too (:func:`model_kwargs`).
        The content is checked against the schema table of
        :mod:`dicblur.models.model_schema` first: a damaged file (missing key, wrong type,
        NaN parameter, binary data) raises one ``InputError`` naming the key.
        """
        source = "model"
        if not text.lstrip().startswith("{"):
            from pathlib import Path

            p = Path(text)
            source = f"model={text!r}"
            if not p.is_file():
                why = "is a directory" if p.is_dir() else "no such file"
                raise InputError(
                    f"{source}: {why}; give a model .json written by dicblur fit "
                    "(or dicblur pattern predict -o)"
                )
            try:
                text = p.read_bytes().decode("utf-8-sig")  # a BOM from a text editor
            except UnicodeDecodeError:
                raise InputError(
                    f"{source}: binary data, not a JSON text file; give a model "
                    ".json written by dicblur fit"
                ) from None
            except OSError as exc:
                raise InputError(f"{source}: cannot be read ({exc.strerror})") from exc
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(
                f"{source}: invalid JSON ({exc.msg} at line {exc.lineno}); the "
                "file is truncated or not a model file"
            ) from exc
        validate_model_dict(d, source)
        return cls(**model_kwargs(d))


# ---------------------------------------------------------------------- loading (schemas)
def model_kwargs(d: dict[str, Any]) -> dict[str, Any]:
    """Constructor arguments of a :class:`BlurUncertaintyModel` from its JSON dict.

    Schemas /2 and /3 (/3 adds the static kind) map field by field. Schema /1 (before
    the validity domain) is upgraded: the power law, stored as ``eta``, is refitted from
    the stored data on its fit range around ``sssig_ref = SSSIG_0`` (the same least
    squares, so ``alpha`` is unchanged and ``u_ref = eta SSSIG_0**-alpha``), and the
    domain is rebuilt from the data, the subset and the provenance.
    """
    kw = {k: v for k, v in d.items() if k != "schema"}
    kw["decay"] = FitResult.from_dict(d["decay"])
    kw["power_law"] = FitResult.from_dict(d["power_law"])
    kw["mismatch"] = None if d["mismatch"] is None else FitResult.from_dict(d["mismatch"])
    kw["static"] = None if d.get("static") is None else FitResult.from_dict(d["static"])
    kw["fit_range"] = (float(d["fit_range"][0]), float(d["fit_range"][1]))
    kw["noise_levels"] = tuple(float(x) for x in d["noise_levels"])
    kw["data"] = {k: tuple(float(x) for x in v) for k, v in d["data"].items()}
    dom = d.get("domain")
    kw["domain"] = None if dom is None else ValidityDomain.from_dict(dom)
    if d.get("schema") == SCHEMA_V1 and "eta" in kw["power_law"].names:
        kw["power_law"] = _refit_power_law_v1(kw)
    return kw


def _refit_power_law_v1(kw: dict[str, Any]) -> FitResult:
    from .powerlaw import fit_power_law

    data = kw["data"]
    w = np.array(data["blur"])
    lo, hi = kw["fit_range"]
    sel = (w >= lo) & (w <= hi)
    noise = np.array(data["noise"])[sel] if "noise" in data else None
    old = kw["power_law"]
    return fit_power_law(
        np.array(data["sssig"])[sel],
        np.array(data["u_e"])[sel],
        noise_sigma=noise,
        blur=w[sel],
        sssig_ref=kw["decay"]["sssig0"],
        fit_noise_exponent="kappa" in old.names,
        confidence=old.confidence,
    )


def _domain_from_fields(m: BlurUncertaintyModel) -> ValidityDomain:
    """The domain of a model built without one: the data's ranges and the recorded settings."""
    w = m.data.get("blur", (0.0,))
    levels = m.noise_levels
    prov = m.provenance or {}
    pat = prov.get("pattern")
    name = pat.get("name") if isinstance(pat, dict) else (pat if isinstance(pat, str) else None)
    hashes = prov.get("input_hashes")
    sha = prov.get("pattern_sha256")
    if sha is None and isinstance(hashes, dict) and len(hashes) == 1:
        sha = next(iter(hashes.values()))
    shape = prov.get("dic_shape", prov.get("shape"))
    comp = prov.get("compensation", "none")
    return ValidityDomain(
        blur_min=float(min(w)),
        blur_max=float(max(w)),
        noise_min=float(min(levels)) if levels else None,
        noise_max=float(max(levels)) if levels else None,
        subset=m.subset,
        shape=shape if isinstance(shape, str) else None,
        pattern=name if isinstance(name, str) else None,
        pattern_sha256=sha if isinstance(sha, str) else None,
        compensation=comp if comp in COMPENSATIONS else "none",
    )
