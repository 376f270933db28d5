"""The fit-result value shared by the model fits, and the confidence-interval machinery.

Confidence intervals
--------------------
``ci="covariance"`` (default): the asymptotic covariance of the least-squares estimate,
``s**2 (J^T J)^-1`` with ``s**2 = SSR / dof``, and Student-t intervals with ``dof`` degrees
of freedom (exact for the linear power-law fit with Gaussian residuals in log space).
Positive scale factors (``eta``, the noise factor ``a`` or ``k``) get the interval
symmetric in their logarithm, ``value * exp(+-t se / value)``.
``ci="bootstrap"``: pairs bootstrap over the measured points (resampled with replacement,
refitted ``n_boot`` times) and percentile intervals; the covariance is then the bootstrap
covariance. Each refit starts from the fit to all points (``refit_from``), to a tolerance
far below the bootstrap's own Monte Carlo error; a refit that does not converge within its
budget is not a replicate, and a model that most resamples cannot refit gets no bootstrap
interval (``ci_method = "unidentified"``, or a FitError with ``ci="bootstrap"``) instead of
minutes of refits that crawl along a valley the data do not constrain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Protocol

import numpy as np
from scipy import stats

from ..arrays import Float64Array, IndexArray
from ..errors import FitError, InputError

__all__ = ["BOOT_GIVE_UP", "FitOnce", "FitResult", "ParameterEstimate"]

#: The bootstrap stops, with no interval, once this many refits failed and they are more
#: than a quarter of those tried: the resamples do not identify the model (a degenerate
#: fit), and percentiles of the refits that did converge would be biased towards them.
BOOT_GIVE_UP = 20


class FitOnce(Protocol):
    """One least-squares fit of a model to the points ``idx``: ``(values, jacobian,
    residuals)``, the Jacobian of the residual vector at the solution (rows: points).
    ``refit_from``: the values of the fit to all points, given for a bootstrap refit (start
    there, to a looser tolerance, where the fit is iterative; raise
    :class:`~dicblur.errors.FitError` when the refit does not converge within its budget)."""

    def __call__(
        self, idx: IndexArray, refit_from: Float64Array | None = None
    ) -> tuple[Float64Array, ...]: ...


@dataclass(frozen=True)
class ParameterEstimate:
    """One fitted parameter: value, standard error and confidence interval."""

    name: str
    value: float
    stderr: float
    low: float
    high: float
    fixed: bool = False


@dataclass(frozen=True)
class FitResult:
    """Result of one model fit (a value: JSON-ready, compared field by field).

    Attributes
    ----------
    model : str
        ``"power_law"`` (eq. 17), ``"sssig_decay"`` (eq. 18) or ``"mismatch"``.
    names : tuple of str
        Free parameter names, in the order of ``values`` and ``covariance``.
    values : tuple of float
    covariance : tuple of tuple of float
        Parameter covariance (see module docstring for the method).
    low, high : tuple of float
        Confidence interval of each free parameter at level ``confidence``.
    fixed : dict
        Parameters held fixed (name -> value), e.g. a noise exponent at its theoretical value.
    r2 : float
        Coefficient of determination in the space the fit minimises (log u_e for the
        uncertainty models, SSSIG for the decay, as the paper reports it).
    residual_std : float
        ``sqrt(SSR / dof)`` in that space.
    residuals : tuple of float
        Residuals (data - model) of the fitted points, in that space.
    dof : int
        Degrees of freedom ``n_points - len(names)``.
    n_points : int
    blur_range : tuple of float
        Smallest and largest blur length W (px) of the fitted points.
    confidence : float
    ci_method : str
        ``"covariance"`` or ``"bootstrap"``.
    extra : dict
        Model-specific constants (e.g. the reference noise level), JSON-ready.
    """

    model: str
    names: tuple[str, ...]
    values: tuple[float, ...]
    covariance: tuple[tuple[float, ...], ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    fixed: dict[str, float]
    r2: float
    residual_std: float
    residuals: tuple[float, ...]
    dof: int
    n_points: int
    blur_range: tuple[float, float]
    confidence: float
    ci_method: str
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def t_quantile(self) -> float:
        """Two-sided Student-t quantile of this fit's intervals (level ``confidence``,
        ``dof`` degrees of freedom): the half-width factor of its prediction intervals."""
        return t_quantile(self.confidence, self.dof)

    def __getitem__(self, name: str) -> float:
        """Value of a free or fixed parameter."""
        if name in self.names:
            return self.values[self.names.index(name)]
        if name in self.fixed:
            return self.fixed[name]
        raise KeyError(f"{name!r}: not a parameter of the {self.model} fit ({self.names})")

    def __contains__(self, name: object) -> bool:
        return name in self.names or name in self.fixed

    def parameter(self, name: str) -> ParameterEstimate:
        """Value, standard error and CI of one parameter (fixed ones have zero width)."""
        if name in self.fixed:
            v = self.fixed[name]
            return ParameterEstimate(name, v, 0.0, v, v, fixed=True)
        i = self.names.index(name) if name in self.names else -1
        if i < 0:
            raise KeyError(f"{name!r}: not a parameter of the {self.model} fit ({self.names})")
        se = math.sqrt(max(self.covariance[i][i], 0.0))
        return ParameterEstimate(name, self.values[i], se, self.low[i], self.high[i])

    @property
    def parameters(self) -> tuple[ParameterEstimate, ...]:
        """Every parameter, free then fixed."""
        return tuple(self.parameter(n) for n in (*self.names, *self.fixed))

    @property
    def cov_array(self) -> Float64Array:
        return np.array(self.covariance, dtype=np.float64).reshape(len(self.names), -1)

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["covariance"] = [list(r) for r in self.covariance]
        for k in ("names", "values", "low", "high", "residuals", "blur_range"):
            d[k] = list(d[k])
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FitResult:
        kw = dict(d)
        kw["covariance"] = tuple(tuple(float(x) for x in r) for r in d["covariance"])
        for k in ("values", "low", "high", "residuals"):
            kw[k] = tuple(float(x) for x in d[k])
        kw["names"] = tuple(d["names"])
        kw["blur_range"] = (float(d["blur_range"][0]), float(d["blur_range"][1]))
        kw["fixed"] = {k: float(v) for k, v in d["fixed"].items()}
        return cls(**kw)


def t_quantile(confidence: float, dof: int) -> float:
    """Two-sided Student-t quantile (normal when dof is large)."""
    return float(stats.t.ppf(0.5 + confidence / 2.0, max(dof, 1)))


@dataclass(frozen=True)
class CIOptions:
    """How a fit's confidence intervals are made: the ``confidence, ci, n_boot, seed``
    keywords every public fit takes (module docstring), checked on construction and passed
    down to :func:`make_result` as one record.

    Attributes
    ----------
    confidence : float
        Interval level, in (0, 1).
    ci : {"covariance", "bootstrap"}
        Interval method.
    n_boot : int
        Bootstrap resamples (>= 20 with ``ci="bootstrap"``).
    seed : int, numpy Generator or None
        Seed of the bootstrap (a Generator is used as is, not copied).
    """

    confidence: float = 0.95
    ci: str = "covariance"
    n_boot: int = 500
    seed: int | np.random.Generator | None = None

    def __post_init__(self) -> None:
        if self.ci not in ("covariance", "bootstrap"):
            raise InputError(f"ci={self.ci!r}: choose 'covariance' or 'bootstrap'")
        if not (isinstance(self.confidence, float | int) and 0.0 < float(self.confidence) < 1.0):
            raise InputError(f"confidence={self.confidence!r}: must be in (0, 1), e.g. 0.95")
        if self.ci == "bootstrap" and (not isinstance(self.n_boot, int) or self.n_boot < 20):
            raise InputError(f"n_boot={self.n_boot!r}: use an integer >= 20 (e.g. 500)")


def make_result(
    *,
    model: str,
    names: tuple[str, ...],
    fit_once: FitOnce,
    n: int,
    data_space: Float64Array,
    blur: Float64Array,
    fixed: dict[str, float],
    ci_options: CIOptions,
    extra: dict[str, Any] | None = None,
    log_params: tuple[str, ...] = (),
    nonneg: tuple[str, ...] = (),
    intervals: bool = True,
) -> FitResult:
    """Run ``fit_once`` on all points and build the result with CIs.

    ``fit_once(idx)`` fits the points ``idx`` and returns ``(values, jacobian, residuals)``
    with the Jacobian of the residual vector at the solution (rows: points).
    ``log_params``: positive scale factors (interval symmetric in the logarithm);
    ``nonneg``: parameters bounded below by 0 (interval clipped there). With
    ``ci="covariance"`` and a degenerate covariance (module docstring) the intervals come
    from a seeded bootstrap (``ci_method = "bootstrap"``). ``intervals=False`` skips
    the intervals (zero covariance, ``ci_method = "none"``): for model selection.
    """
    confidence, ci, n_boot = ci_options.confidence, ci_options.ci, ci_options.n_boot
    seed = ci_options.seed
    p = len(names)
    dof = n - p
    if dof < 1:
        raise FitError(
            f"{model}: {n} point(s) for {p} parameter(s); at least {p + 1} are needed "
            "(add blur levels or fix a parameter)"
        )
    idx_all = np.arange(n)
    values, jac, res = fit_once(idx_all)
    ssr = float(res @ res)
    s2 = ssr / dof
    ss_tot = float(np.sum((data_space - data_space.mean()) ** 2))
    r2 = 1.0 - ssr / ss_tot if ss_tot > 0 else math.nan
    low = high = cov = None
    method = ci if intervals else "none"
    if method == "none":
        low, high, cov = values.copy(), values.copy(), np.zeros((p, p))
    elif ci == "covariance":
        low, high, cov = _wald(values, jac, s2, names, log_params, nonneg, confidence, dof)
        if low is None:
            # degenerate Gaussian covariance (a parameter the data do not constrain, or
            # one on its bound): a seeded pairs bootstrap instead (docs/models.md s. 5)
            method = "bootstrap"
            seed = 0 if seed is None else seed
    if method == "bootstrap":
        boot = _bootstrap(fit_once, values, n, p, blur, confidence, n_boot, seed)
        if boot is not None:
            low, high, cov = boot
        else:
            if ci == "bootstrap":
                raise FitError(
                    f"{model}: bootstrap failed (too few valid resamples); use ci='covariance'"
                )
            # neither works: say so with unbounded intervals rather than a false width
            method = "unidentified"
            cov = np.full((p, p), np.inf)
            low = np.where([nm in log_params or nm in nonneg for nm in names], 0.0, -np.inf)
            high = np.full(p, np.inf)
    assert low is not None and high is not None and cov is not None
    if nonneg:
        low = np.array(
            [max(lo, 0.0) if nm in nonneg else lo for lo, nm in zip(low, names, strict=True)]
        )
    return FitResult(
        model=model,
        names=names,
        values=tuple(float(v) for v in values),
        covariance=tuple(tuple(float(x) for x in r) for r in cov),
        low=tuple(float(v) for v in low),
        high=tuple(float(v) for v in high),
        fixed=dict(fixed),
        r2=float(r2),
        residual_std=math.sqrt(s2),
        residuals=tuple(float(r) for r in -res),
        dof=int(dof),
        n_points=int(n),
        blur_range=(float(blur.min()), float(blur.max())),
        confidence=float(confidence),
        ci_method=method,
        extra=dict(extra or {}),
    )


_MAX_COND = 1e12
"""Condition number of the column-scaled ``J^T J`` above which the covariance is degenerate."""


def _wald(
    values: Float64Array,
    jac: Float64Array,
    s2: float,
    names: tuple[str, ...],
    log_params: tuple[str, ...],
    nonneg: tuple[str, ...],
    confidence: float,
    dof: int,
) -> tuple[Any, Any, Any]:
    """Student-t intervals from ``s**2 (J^T J)^-1``; ``(None, None, None)`` if degenerate:
    a singular (column-scaled) ``J^T J``, a zero standard error, or a parameter bounded at
    0 whose interval reaches below it.

    The Jacobian's columns are scaled to unit norm before the inversion, so the units of a
    parameter (``c`` ~ 1e-4 px/px**2 next to ``gamma`` ~ 1) do not make ``pinv`` drop it.
    """
    norms = np.linalg.norm(jac, axis=0)
    if not np.all(np.isfinite(norms)) or np.any(norms == 0):
        return None, None, None
    js = jac / norms
    jtj = js.T @ js
    cond = np.linalg.cond(jtj)
    if not math.isfinite(cond) or cond > _MAX_COND:
        return None, None, None
    cov = np.linalg.inv(jtj) / np.outer(norms, norms) * s2
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if s2 > 0 and np.any(se == 0):
        return None, None, None
    tq = t_quantile(confidence, dof)
    low, high = values - tq * se, values + tq * se
    if any(nm in nonneg and lo < 0 for nm, lo in zip(names, low, strict=True)):
        # a parameter within reach of its bound (e.g. a cross term fitted at ~0): the
        # likelihood is truncated there and the Gaussian interval is not valid
        return None, None, None
    for i, name in enumerate(names):
        if name in log_params and values[i] > 0:
            # positive scale factor: symmetric in log (exact for the power law's u_ref,
            # fitted as log u_ref); a relative error beyond e^700 is (0, inf)
            rel = min(tq * se[i] / values[i], 700.0)
            low[i], high[i] = values[i] * np.exp(-rel), values[i] * np.exp(rel)
            if rel == 700.0:
                low[i], high[i] = 0.0, np.inf
    return low, high, cov


def _bootstrap(
    fit_once: FitOnce,
    values: Float64Array,
    n: int,
    p: int,
    blur: Float64Array,
    confidence: float,
    n_boot: int,
    seed: int | np.random.Generator | None,
) -> tuple[Any, Any, Any] | None:
    """Pairs bootstrap percentile intervals and covariance, or None if it fails (fewer
    than 10 replicates, or :data:`BOOT_GIVE_UP` failed refits, over a quarter of those tried)."""
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    boots = []
    failed = 0
    for _ in range(n_boot):
        idx = np.sort(rng.integers(0, n, n))
        if np.unique(blur[idx]).size < p + 1:
            continue
        try:
            boots.append(fit_once(idx, refit_from=values)[0])
        except (FitError, np.linalg.LinAlgError, ValueError):
            failed += 1
            if failed >= BOOT_GIVE_UP and 4 * failed > failed + len(boots):
                return None
            continue
    if len(boots) < 10:
        return None
    b = np.array(boots)
    cov = np.atleast_2d(np.cov(b, rowvar=False))
    a = (1.0 - confidence) / 2.0
    return np.quantile(b, a, axis=0), np.quantile(b, 1.0 - a, axis=0), cov
