"""The whole Section-V study in one call: Table II, Fig. 5 data, the Monte Carlo, log-log
fits per regime, the knee, the dependence on open choices, and a verdict text.

:func:`run_pulse_study` returns a frozen :class:`PulseStudy` that the CLI
(``dicblur pulse``) and the report stage reuse; nothing here plots or prints.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from ..arrays import Float64Array
from ..checks import describe
from ..errors import InputError
from ..patterns import SeedLike
from ..timing import lap_timer
from .correlation import chi2_regime_a, min_chi2
from .montecarlo import PAPER_TRAIN, PAPER_WIDTHS, simulate
from .records import DependenceRow, LogLogFit
from .signal import (
    REGIMES,
    PulseTrain,
    closed_form_metrics,
    numeric_metrics,
    pixel_metrics,
    regime,
)

__all__ = [
    "FIG5_TRAIN",
    "DependenceRow",
    "LogLogFit",
    "PulseStudy",
    "find_knee",
    "fit_loglog",
    "run_pulse_study",
    "segments",
    "table_ii",
]

#: The paper's Fig. 5 signal: a = 1, du = 20, dp = 10 (w = 1..21).
FIG5_TRAIN = PulseTrain(a=1.0, dp=10.0, du=20.0)
#: A dense train (dp > g) that shows regime (d) in Table II and Fig. 4.
DENSE_TRAIN = PulseTrain(a=1.0, dp=16.0, du=22.0)

_Z95 = 1.959963984540054


@dataclass(frozen=True)
class PulseStudy:
    """Everything ``dicblur pulse`` writes, as values.

    Attributes
    ----------
    dataset : xarray.Dataset
        Main Monte Carlo (see :func:`~dicblur.pulse.simulate`), dim ``w`` (px).
    table : tuple of dict
        Table II rows: closed form next to numerical (continuous limit) and pixel values.
    fig5 : xarray.Dataset
        ``min_chi2`` (numeric, exact continuous), ``chi2_law`` (regime-a law ``N a^2 w/6``)
        and ``xi_min`` against ``w`` for the paper's Fig. 5 signal.
    fits : tuple of LogLogFit
        One per segment of the main Monte Carlo.
    knee, knee_predicted, knee_paper : float
        Observed knee (first w where the local log-log slope exceeds 3), the predicted one
        (``2 min(dp, g)``: the blurred ramps leave the reference edges) and the paper's
        (``du - dp``), px.
    dependence : tuple of DependenceRow
    verdict : str
        Markdown text generated from the numbers above.
    elapsed_s : float
        Wall time of the main Monte Carlo, seconds.
    timings : dict of str to float
        Wall time of each phase, s: ``montecarlo`` (the main one, = ``elapsed_s``),
        ``fits``, ``dependence`` (its Monte Carlo runs), ``table_ii``, ``fig5`` and
        ``verdict``; ``benchmarks/bench_budgets.py`` prints them.
    """

    dataset: xr.Dataset
    table: tuple[dict[str, Any], ...]
    fig5: xr.Dataset
    fits: tuple[LogLogFit, ...]
    knee: float
    knee_predicted: float
    knee_paper: float
    dependence: tuple[DependenceRow, ...]
    verdict: str
    elapsed_s: float
    settings: dict[str, Any]
    timings: dict[str, float] = field(default_factory=dict)


# --------------------------------------------------------------------------------------
def table_ii(*, supersample: int = 64, n_periods: int = 1) -> tuple[dict[str, Any], ...]:
    """Table II of the paper, closed form next to numerical convolution and pixel samples.

    One example per regime: (a) w = 3, (b) w = 10, (c) w = 19 on the paper's Monte Carlo
    signal (a = 1, dp = 6, du = 22), (d) w = 10 on a dense train (dp = 16, du = 22), where
    (d) exists (it needs dp > g).
    """
    cases = (
        ("a", PAPER_TRAIN, 3.0),
        ("b", PAPER_TRAIN, 10.0),
        ("c", PAPER_TRAIN, 19.0),
        ("d", DENSE_TRAIN, 10.0),
    )
    exprs = {"a": "w", "b": "dp", "c": "du - w", "d": "g"}
    rows = []
    for reg, train, w in cases:
        cf = closed_form_metrics(train, [w], n_periods=n_periods)
        nm = numeric_metrics(train, [w], n_periods=n_periods, supersample=supersample)
        px = pixel_metrics(train, [w], n_periods=n_periods, gradient="forward")
        row: dict[str, Any] = {
            "regime": reg,
            "condition": REGIMES[reg].split(":")[0],
            "m": exprs[reg],
            "dp": train.dp,
            "du": train.du,
            "w": w,
            "m_value": float(cf.m[0]),
        }
        for q in ("mig", "gradient_variance", "contrast", "sssig"):
            row[f"{q}_closed"] = float(getattr(cf, q)[0])
            row[f"{q}_numeric"] = float(getattr(nm, q)[0])
            row[f"{q}_pixel"] = float(getattr(px, q)[0])
        rows.append(row)
    return tuple(rows)


def segments(train: PulseTrain, w: Float64Array, w_ref: float = 1.0) -> list[str]:
    """Segment label per width: the regime letter, with ``'`` appended where the blurred
    ramps no longer cover the reference edges (``w > 2 min(dp, g) - w_ref``: the noise-free
    SSD curvature at zero shift has dropped, the minimum turns flat)."""
    lim = 2 * min(train.dp, train.g) - w_ref
    return [regime(train, float(x)) + ("'" if x > lim + 1e-9 else "") for x in w]


def fit_loglog(
    ds: xr.Dataset,
    w_min: float,
    w_max: float,
    *,
    var: str = "u_e",
    segment: str = "",
    predictions: tuple[str, ...] = (
        "u_first_principles",
        "u_paper_linear",
        "u_interpolated_noise",
        "u_pixel_linearised",
    ),
) -> LogLogFit:
    """Fit ``log u_e`` against ``log w`` over ``w_min <= w <= w_max`` (see :class:`LogLogFit`).

    Widths where ``u_e == 0`` (an estimator locked to the pixel grid) are left out.
    """
    sel = ds.sel(w=slice(w_min, w_max))
    sel = sel.isel(w=np.flatnonzero(sel[var].values > 0))  # locked estimators give u_e = 0
    w = sel["w"].values
    u = sel[var].values
    if w.size < 2:
        raise InputError(
            f"w_min={w_min}, w_max={w_max}: need >= 2 widths with {var} > 0 to fit a slope"
        )
    x, y = np.log(w), np.log(u)
    if f"{var}_ci_low" in sel:
        se = (sel[f"{var}_ci_high"].values - sel[f"{var}_ci_low"].values) / (2 * _Z95 * u)
        se = np.where(se > 0, se, np.nanmax(se) if np.any(se > 0) else 1.0)
    else:
        se = np.ones_like(y)
    wt = 1 / se**2
    xm = np.sum(wt * x) / np.sum(wt)
    ym = np.sum(wt * y) / np.sum(wt)
    sxx = float(np.sum(wt * (x - xm) ** 2))
    slope = float(np.sum(wt * (x - xm) * (y - ym)) / sxx)
    icpt = ym - slope * xm
    if w.size > 2:
        red = float(np.sum(wt * (y - icpt - slope * x) ** 2) / (w.size - 2))
        sslope = math.sqrt(max(red, 1.0) / sxx)
        from scipy import stats

        tq = float(stats.t.ppf(0.975, w.size - 2)) if red > 1 else _Z95
    else:
        sslope, tq = math.sqrt(1 / sxx), _Z95
    slopes, ratios = {}, {}
    for p in predictions:
        if p not in sel:
            continue
        pv = sel[p].values
        ok = np.isfinite(pv) & (pv > 0)
        if ok.sum() >= 2:
            slopes[p] = float(np.polyfit(x[ok], np.log(pv[ok]), 1)[0])
        if ok.any():
            ratios[p] = float(np.exp(np.mean(y[ok] - np.log(pv[ok]))))
    regs = sorted(set(str(r) for r in sel["regime"].values)) if "regime" in sel else []
    return LogLogFit(
        segment=segment,
        regime="".join(regs),
        w_min=float(w.min()),
        w_max=float(w.max()),
        n=int(w.size),
        slope=slope,
        slope_ci=(slope - tq * sslope, slope + tq * sslope),
        prefactor=float(np.exp(icpt)),
        slopes_pred=slopes,
        ratio_pred=ratios,
    )


def find_knee(ds: xr.Dataset, *, var: str = "u_e", threshold: float = 3.0) -> float:
    """First width whose local log-log slope (from the previous width) exceeds
    ``threshold`` (a linear law has 1): where u_e turns abruptly upwards. NaN if none."""
    w = ds["w"].values
    u = ds[var].values
    with np.errstate(divide="ignore", invalid="ignore"):
        local = np.diff(np.log(u)) / np.diff(np.log(w))
    idx = np.flatnonzero(local > threshold)
    return float(w[idx[0] + 1]) if idx.size else math.nan


def _segment_fits(ds: xr.Dataset, train: PulseTrain, w_ref: float) -> tuple[LogLogFit, ...]:
    w = ds["w"].values
    labels = segments(train, w, w_ref)
    fits = []
    start = 0
    for i in range(1, w.size + 1):
        if i == w.size or labels[i] != labels[start]:
            if i - start >= 2:
                fits.append(fit_loglog(ds, float(w[start]), float(w[i - 1]), segment=labels[start]))
            start = i
    return tuple(fits)


def _fig5(n_periods: int = 1) -> xr.Dataset:
    w = np.arange(1.0, 22.0)
    val, loc = min_chi2(FIG5_TRAIN, w, w_ref=0.0, n_periods=n_periods)
    law = chi2_regime_a(0.0 * w, w, a=FIG5_TRAIN.a, n_periods=n_periods)
    return xr.Dataset(
        {"min_chi2": ("w", val), "xi_min": ("w", loc), "chi2_law": ("w", law)},
        coords={"w": w},
        attrs={
            "a": FIG5_TRAIN.a,
            "dp": FIG5_TRAIN.dp,
            "du": FIG5_TRAIN.du,
            "n_periods": n_periods,
            "w_ref": 0.0,
        },
    )


def _dependence(trials: int, seed: SeedLike, sigma: float) -> tuple[DependenceRow, ...]:
    widths = np.arange(1.0, 28.0)
    variants = [
        ("main: Fourier, shift blurred, N = 10", "fourier", "blurred", 10, PAPER_TRAIN),
        ("Fourier, shift reference", "fourier", "reference", 10, PAPER_TRAIN),
        (
            "Fourier, edges at 1/4 px (sampling phase)",
            "fourier",
            "blurred",
            10,
            PulseTrain(a=1.0, dp=6.0, du=22.0, x0=-0.25),
        ),
        ("Fourier, N = 1", "fourier", "blurred", 1, PAPER_TRAIN),
        ("Fourier, N = 3", "fourier", "blurred", 3, PAPER_TRAIN),
        ("Fourier, N = 30", "fourier", "blurred", 30, PAPER_TRAIN),
        ("linear interpolation, shift blurred", "linear", "blurred", 10, PAPER_TRAIN),
        ("linear interpolation, shift reference", "linear", "reference", 10, PAPER_TRAIN),
        ("B-spline IC-GN (engine-like), shift blurred", "bspline", "blurred", 10, PAPER_TRAIN),
        (
            "Keys interpolation + central differences, shift blurred",
            "keys",
            "blurred",
            10,
            PAPER_TRAIN,
        ),
        (
            "template (noise-free blurred model moved), shift blurred",
            "analytic",
            "blurred",
            10,
            PAPER_TRAIN,
        ),
        (
            "template, shift blurred, edges at 1/4 px",
            "analytic",
            "blurred",
            10,
            PulseTrain(a=1.0, dp=6.0, du=22.0, x0=-0.25),
        ),
        ("template, shift reference", "analytic", "reference", 10, PAPER_TRAIN),
        (
            "Fourier, dp = 4 (knee check)",
            "fourier",
            "blurred",
            10,
            PulseTrain(a=1.0, dp=4.0, du=22.0),
        ),
    ]
    rows = []
    for name, interp, shifted, n, train in variants:
        ds = simulate(
            train,
            widths=widths,
            sigma=sigma,
            n_periods=n,
            trials=trials,
            seed=seed,
            interpolation=interp,  # type: ignore[arg-type]
            shifted=shifted,  # type: ignore[arg-type]
        )
        wa = min(train.dp, train.g)
        try:
            fa = fit_loglog(ds, 1.0, float(np.max(widths[widths < wa])))
            slope, ci = fa.slope, fa.slope_ci
        except InputError:
            slope, ci = math.nan, (math.nan, math.nan)
        u5 = float(ds["u_e"].sel(w=5.0))
        rows.append(
            DependenceRow(
                name=name,
                interpolation=interp,
                shifted=shifted,
                n_periods=n,
                dp=train.dp,
                du=train.du,
                x0=train.x0,
                slope_a=slope,
                slope_a_ci=ci,
                u_e_w1=float(ds["u_e"].sel(w=1.0)),
                u_e_w5=u5,
                ratio_first_principles_w5=u5 / float(ds["u_first_principles"].sel(w=5.0)),
                ratio_derived_pixel_w5=u5 / float(ds["u_pixel_linearised"].sel(w=5.0)),
                knee=find_knee(ds),
                knee_predicted=2 * min(train.dp, train.g),
            )
        )
    return tuple(rows)


def run_pulse_study(
    *,
    trials: int = 10_000,
    seed: SeedLike = 1,
    n_periods: int = 10,
    sigma: float = 0.05,
    dependence_trials: int | None = 2000,
) -> PulseStudy:
    """Run the Section-V study with the paper's parameters (a = 1, dp = 6, du = 22,
    sigma = 0.05, w = 1..27) and return a :class:`PulseStudy`.

    Parameters
    ----------
    trials : int
        Noise realisations per width in the main Monte Carlo.
    seed : int or None
        Seed of every Monte Carlo (same seed, same numbers).
    n_periods : int
        Periods in the correlated signal (N).
    sigma : float
        Noise std, grey levels.
    dependence_trials : int or None
        Trials per width for the dependence study (``min(trials, dependence_trials)``);
        ``None`` skips it.
    """
    if not isinstance(trials, int | np.integer) or trials < 2:
        raise InputError(f"trials={describe(trials)}: expected an int >= 2 (default 10000)")
    from .._version import __version__

    t0 = time.perf_counter()
    ds = simulate(
        PAPER_TRAIN,
        widths=PAPER_WIDTHS,
        sigma=sigma,
        n_periods=n_periods,
        trials=trials,
        seed=seed,
        keep_samples=True,
    )
    elapsed = time.perf_counter() - t0
    timings = {"montecarlo": elapsed}
    lap = lap_timer(timings)
    fits = _segment_fits(ds, PAPER_TRAIN, 1.0)
    knee = find_knee(ds)
    lap("fits")
    dep: tuple[DependenceRow, ...] = ()
    if dependence_trials is not None:
        dep = _dependence(int(min(trials, dependence_trials)), seed, sigma)
    lap("dependence")
    table = table_ii()
    lap("table_ii")
    fig5 = _fig5()
    lap("fig5")
    study_kw = dict(
        dataset=ds,
        table=table,
        fig5=fig5,
        fits=fits,
        knee=knee,
        knee_predicted=2 * min(PAPER_TRAIN.dp, PAPER_TRAIN.g),
        knee_paper=PAPER_TRAIN.g,
        dependence=dep,
        elapsed_s=elapsed,
        settings={
            "trials": int(trials),
            "seed": seed,
            "n_periods": n_periods,
            "sigma": sigma,
            "dependence_trials": dependence_trials,
            "dicblur_version": __version__,
        },
    )
    from .verdict import verdict_text

    verdict = verdict_text(**study_kw)  # type: ignore[arg-type]
    lap("verdict")
    return PulseStudy(verdict=verdict, timings=timings, **study_kw)  # type: ignore[arg-type]
