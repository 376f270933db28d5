"""The fitted blur-uncertainty model as a value: predictions, limits, report, JSON."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, fields
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize

from .._validation import check_positive
from ..errors import FitError, InputError
from ._checks import as_vector
from ._result import FitResult, t_quantile
from .decay import mbrf as _mbrf
from .decay import sssig_decay
from .model_schema import SCHEMA, validate_model_dict

__all__ = ["BlurUncertaintyModel", "ModelKind", "Prediction"]

ModelKind = Literal["mismatch", "power_law"]
_KINDS = ("mismatch", "power_law")


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
        The noise and blur-mismatch terms of the mismatch model (px; ``None`` for the
        power law).
    sigma : float or None
        Noise std (GL) the prediction is for.
    model : str
    confidence : float
    u_floor : float or None
        Noise-independent floor ``u_0`` of the mismatch model (px), if fitted.
    """

    blur: NDArray[np.float64]
    u_e: NDArray[np.float64]
    low: NDArray[np.float64]
    high: NDArray[np.float64]
    u_noise: NDArray[np.float64] | None
    u_blur: NDArray[np.float64] | None
    sigma: float | None
    model: str
    confidence: float
    u_floor: float | None = None


@dataclass(frozen=True)
class BlurUncertaintyModel:
    """Fitted uncertainty model of one pattern / subset / DIC setting (see fit_blur_model).

    Attributes
    ----------
    default : {"mismatch", "power_law"}
        Model used by :meth:`predict`, :meth:`max_blur` and planning when none is named:
        the one that predicted held-out data better (``comparison``), else ``mismatch``.
    decay : FitResult
        SSSIG(W) decay, eq. 18 (``sssig0`` (GL/px)**2, ``beta`` 1/px**2).
    power_law : FitResult
        Eq. 17 on the edge-driven range (``eta`` px (GL/px)**(2 alpha), ``alpha``[, ``kappa``]).
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

    # ------------------------------------------------------------------ parameters
    @property
    def alpha(self) -> float:
        return self.power_law["alpha"]

    @property
    def beta(self) -> float:
        return self.decay["beta"]

    @property
    def eta(self) -> float:
        return self.power_law["eta"]

    @property
    def mbrf(self) -> float:
        """Motion blur rejection factor ``2 alpha beta`` (1/px**2), paper eq. 22."""
        return _mbrf(self.alpha, self.beta)

    @property
    def c(self) -> float | None:
        """Fitted blur-mismatch coefficient (px / px**2), or None."""
        return None if self.mismatch is None else self.mismatch["c"]

    def sssig(self, blur: ArrayLike) -> NDArray[np.float64]:
        """SSSIG(W) from the eq. 18 fit, (GL/px)**2."""
        return sssig_decay(blur, self.decay["sssig0"], self.decay["beta"])

    # ------------------------------------------------------------------ evaluation
    def _kind(self, model: str | None) -> str:
        kind = self.default if model is None else model
        if kind not in _KINDS:
            raise InputError(f"model={model!r}: choose 'mismatch' or 'power_law'")
        if kind == "mismatch" and self.mismatch is None:
            raise InputError("model='mismatch': this model has no mismatch fit; use 'power_law'")
        return kind

    def _fit(self, kind: str) -> FitResult:
        fit = self.mismatch if kind == "mismatch" else self.power_law
        assert fit is not None
        return fit

    def _log_u(self, kind: str, w: NDArray[np.float64], sigma: float | None,
               theta: NDArray[np.float64]) -> NDArray[np.float64]:
        fit = self._fit(kind)
        nf = len(fit.names)
        p = dict(zip(fit.names, theta[:nf], strict=True))
        s = sssig_decay(w, theta[nf], theta[nf + 1])
        if kind == "power_law":
            alpha = p["alpha"]
            kappa = p.get("kappa", 2.0 * alpha)
            ref = fit.extra.get("sigma_ref")
            lu = np.log(p["eta"]) - alpha * np.log(s)
            if sigma is not None and ref is not None:
                lu = lu + kappa * math.log(sigma / ref)
            return lu
        noise, blur2 = self._mismatch_terms(p, w, s, sigma)
        return 0.5 * np.log(noise + p.get("floor", 0.0) ** 2 + blur2)

    def _mismatch_terms(self, p: dict[str, float], w: NDArray[np.float64],
                        s: NDArray[np.float64], sigma: float | None
                        ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if "k" in p:
            noise = p["k"] / s
        else:
            assert sigma is not None
            gamma = p.get("gamma", self.mismatch.fixed.get("gamma", 1.0) if self.mismatch
                          else 1.0)
            noise = p["a"] * (s / sigma**2) ** (-gamma)
        noise = noise * (1.0 + p.get("noise_blur", 0.0) * w**4)
        ub = p["c"] * w * w + p.get("c4", 0.0) * w**4
        bw = p.get("cross", 0.0) * w
        return noise, ub * ub + bw * bw

    def _sigma(self, kind: str, sigma: float | None) -> float | None:
        if sigma is not None:
            sigma = check_positive(sigma, "sigma")
        fit = self._fit(kind)
        has_noise = (kind == "power_law" and fit.extra.get("sigma_ref") is not None) or (
            kind == "mismatch" and "a" in fit.names)
        if sigma is not None and not has_noise:
            raise InputError(
                f"sigma={sigma!r}: the model was fitted without noise levels, so it cannot "
                "predict at another noise; refit with noise_sigma or use sigma=None"
            )
        if sigma is None and has_noise:
            if self.noise_sigma is None:
                raise InputError(
                    "sigma=None: the model was fitted on several noise levels; give sigma "
                    f"(GL), e.g. one of {list(self.noise_levels)}"
                )
            return float(self.noise_sigma)
        return sigma

    def _theta(self, kind: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        fit = self._fit(kind)
        theta = np.array([*fit.values, *self.decay.values])
        nf = len(fit.names)
        cov = np.zeros((theta.size, theta.size))
        cov[:nf, :nf] = fit.cov_array
        cov[nf:, nf:] = self.decay.cov_array
        return theta, cov

    def predict(self, blur: ArrayLike, sigma: float | None = None, *,
                model: str | None = None) -> Prediction:
        """Predict u_e (px) at blur lengths ``blur`` (px) and noise ``sigma`` (GL).

        Parameters
        ----------
        blur : float or array_like, shape (n,)
            W >= 0, px.
        sigma : float, optional
            Noise std (GL). Default: the noise of the fitted data (single level).
        model : {"mismatch", "power_law"}, optional
            Default: ``self.default``. The power law uses eq. 19 (eq. 17 with SSSIG from
            eq. 18) and, at another noise, the scale-consistent factor
            ``(sigma / sigma_ref)**kappa``.

        Returns
        -------
        Prediction
        """
        w = as_vector(blur, "blur")
        if np.any(w < 0):
            raise InputError(f"blur: negative blur length {float(w[w < 0][0])!r} px; W must be "
                             ">= 0")
        kind = self._kind(model)
        sig = self._sigma(kind, sigma)
        theta, cov = self._theta(kind)
        lu = self._log_u(kind, w, sig, theta)
        grad = np.empty((w.size, theta.size))
        for j in range(theta.size):
            h = 1e-6 * max(abs(theta[j]), 1e-12)
            tp = theta.copy()
            tp[j] += h
            grad[:, j] = (self._log_u(kind, w, sig, tp) - lu) / h
        fit = self._fit(kind)
        var = np.einsum("ni,ij,nj->n", grad, cov, grad) + fit.residual_std**2
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
        return Prediction(blur=w, u_e=np.exp(lu), low=np.exp(lu - half), high=np.exp(lu + half),
                          u_noise=u_noise, u_blur=u_blur, sigma=sig, model=kind,
                          confidence=self.confidence, u_floor=u_floor)

    def taylor(self, blur: ArrayLike) -> NDArray[np.float64]:
        """Small-W expansion of eq. 19 at the fit noise: ``u_e(0) (1 + alpha beta W**2)``."""
        w = as_vector(blur, "blur")
        u0 = float(self.predict([0.0], model="power_law").u_e[0])
        return u0 * (1.0 + self.alpha * self.beta * w * w)

    def max_blur(self, target: float, sigma: float | None = None, *,
                 model: str | None = None) -> float:
        """Largest blur length W (px) whose predicted u_e stays <= ``target`` (px).

        Raises
        ------
        InputError
            If ``target <= 0`` or the static uncertainty u_e(0) already exceeds it.
        """
        target = check_positive(target, "target")
        kind = self._kind(model)

        def f(wv: float) -> float:
            return float(self.predict([wv], sigma, model=kind).u_e[0]) - target

        u0 = f(0.0) + target
        if u0 > target:
            raise InputError(
                f"target={target:g} px: below the static uncertainty u_e(0) = {u0:.3g} px of "
                "this pattern and noise; no blur length meets it (raise the target, lower "
                "the noise or use a larger subset)"
            )
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
            f"subset {self.subset} px; noise levels {list(self.noise_levels) or 'unknown'} GL; "
            f"{len(self.data['blur'])} points, W {min(self.data['blur']):g}..."
            f"{max(self.data['blur']):g} px",
            "",
            f"SSSIG decay (eq. 18), R^2 = {self.decay.r2:.4f} [{self.decay.ci_method} {pct} CI]",
        ]

        def block(fit: FitResult) -> None:
            for p in fit.parameters:
                ci = "fixed" if p.fixed else f"[{p.low:.4g}, {p.high:.4g}]"
                lines.append(f"  {p.name:7s} = {p.value:.5g}  {ci}")

        block(self.decay)
        lines += [f"power law (eq. 17) on W {self.fit_range[0]:g}..{self.fit_range[1]:g} px "
                  f"({self.range_rule}), R^2 (log) = {self.power_law.r2:.4f}"]
        block(self.power_law)
        lines.append(f"  MBRF = 2 alpha beta = {self.mbrf:.4g} 1/px^2 "
                     f"(u_e ~ u_e(0) (1 + {self.alpha * self.beta:.4g} W^2))")
        if self.power_law.extra.get("kappa_rule") == "fitted":
            lines.append(f"  scale consistency: kappa = {self.power_law['kappa']:.3g} vs "
                         f"2 alpha = {2 * self.alpha:.3g}")
        if self.mismatch is not None:
            lines.append(f"noise + blur mismatch, R^2 (log) = {self.mismatch.r2:.4f}, "
                         f"residual {100 * self.mismatch.residual_std:.2g}% rms")
            block(self.mismatch)
            if self.c_static is not None:
                lines.append(f"  c predicted from the static image = {self.c_static:.4g} "
                             f"(fitted / predicted = {self.mismatch['c'] / self.c_static:.3f})")
        if self.comparison:
            cmp_ = self.comparison
            lines.append(
                f"held-out comparison ({cmp_['n_test']} points): rms log error power law "
                f"{cmp_['rms_log_error']['power_law']:.3g}, mismatch "
                f"{cmp_['rms_log_error']['mismatch']:.3g} -> {cmp_['better']}")
        if self.provenance:
            lines.append("provenance: " + json.dumps(self.provenance, sort_keys=True))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"schema": SCHEMA}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, FitResult):
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
                raise InputError(f"{source}: {why}; give a model .json written by dicblur fit "
                                 "(or dicblur pattern predict -o)")
            try:
                text = p.read_bytes().decode("utf-8")
            except UnicodeDecodeError:
                raise InputError(f"{source}: binary data, not a JSON text file; give a model "
                                 ".json written by dicblur fit") from None
            except OSError as exc:
                raise InputError(f"{source}: cannot be read ({exc.strerror})") from exc
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"{source}: invalid JSON ({exc.msg} at line {exc.lineno}); the "
                             "file is truncated or not a model file") from exc
        validate_model_dict(d, source)
        kw = {k: v for k, v in d.items() if k != "schema"}
        kw["decay"] = FitResult.from_dict(d["decay"])
        kw["power_law"] = FitResult.from_dict(d["power_law"])
        kw["mismatch"] = None if d["mismatch"] is None else FitResult.from_dict(d["mismatch"])
        kw["fit_range"] = (float(d["fit_range"][0]), float(d["fit_range"][1]))
        kw["noise_levels"] = tuple(float(x) for x in d["noise_levels"])
        kw["data"] = {k: tuple(float(x) for x in v) for k, v in d["data"].items()}
        return cls(**kw)
