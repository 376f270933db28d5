"""Markdown verdict generated from the numbers of a pulse study (no plotting, no I/O)."""

from __future__ import annotations

import math
from typing import Any

import xarray as xr

from .records import DependenceRow, LogLogFit

__all__ = ["verdict_text"]

_SEG_NOTE = {
    "a": "edges soften (m = w)",
    "b": "contrast loss, ramps still cover the reference edges",
    "b'": "ramps leave the reference edges (C halves, then vanishes)",
    "c'": "pulses merge (w >= du - dp)",
    "e'": "window longer than a period (contrast reversal)",
}


def _f(x: float, nd: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.{nd}g}"


def _nscale(rows: tuple[DependenceRow, ...]) -> str:
    four = sorted(
        (
            r
            for r in rows
            if r.interpolation == "fourier"
            and r.shifted == "blurred"
            and r.dp == 6.0
            and r.x0 == -0.5
        ),
        key=lambda r: r.n_periods,
    )
    return ", ".join(f"{r.u_e_w5 * math.sqrt(r.n_periods):.3f} (N = {r.n_periods})" for r in four)


def _phase(rows: tuple[DependenceRow, ...]) -> str:
    r = next((r for r in rows if r.interpolation == "fourier" and r.x0 != -0.5), None)
    if r is None:
        return ""
    return (
        f"Moving the pulse edges off the pixel boundaries (x0 = {r.x0:g}) makes the sampled "
        f"reference non-binary: u_e(1) becomes {r.u_e_w1:.3g} px and the regime-(a) slope "
        f"{r.slope_a:.2f}, but u_e(5) is still {r.ratio_first_principles_w5:.2f} x the "
        f"sqrt law and {r.ratio_derived_pixel_w5:.2f} x the derived law."
    )


#: Correlators compared in the dependence study, by interpolation name.
CORRELATORS = {
    "fourier": "spectral (exact Fourier shift)",
    "bspline": "cubic B-spline IC-GN (as the 2-D engine)",
    "keys": "Keys interpolation + central differences",
    "analytic": "template (noise-free blurred model moved)",
}


def correlator_rows(rows: tuple[DependenceRow, ...]) -> list[DependenceRow]:
    """The dependence rows that compare correlators on the paper's signal (shift blurred,
    N = 10, dp = 6, edges on pixel boundaries), one per correlator, in CORRELATORS order."""
    out = []
    for kind in CORRELATORS:
        r = next(
            (
                r
                for r in rows
                if r.interpolation == kind
                and r.shifted == "blurred"
                and r.n_periods == 10
                and r.dp == 6.0
                and r.x0 == -0.5
            ),
            None,
        )
        if r is not None:
            out.append(r)
    return out


def _far(ds: xr.Dataset) -> float:
    if "u" not in ds:
        return float(ds["outlier_fraction"].isel(w=-1))
    u = ds["u"].isel(w=-1).values
    return float(abs(abs(u) - ds.attrs["du"] / 2).__le__(1.0).mean())


def _follows(fit: LogLogFit) -> str:
    lo, hi = fit.slope_ci
    if lo <= 0.5 <= hi and not lo <= 1.0 <= hi:
        return "sqrt"
    if lo <= 1.0 <= hi and not lo <= 0.5 <= hi:
        return "linear"
    if hi < 0.5:
        return "flatter than sqrt"
    if lo > 1.0:
        return "steeper than linear"
    return "between sqrt and linear"


def verdict_text(
    *,
    dataset: xr.Dataset,
    fits: tuple[LogLogFit, ...],
    knee: float,
    knee_predicted: float,
    knee_paper: float,
    dependence: tuple[DependenceRow, ...],
    settings: dict[str, Any],
    elapsed_s: float,
    **_: Any,
) -> str:
    """Markdown verdict on linear vs sqrt growth and on the knee, from a pulse study."""
    ds = dataset
    at = ds.attrs
    u = ds["u_e"]

    def val(name: str, w: float) -> float:
        return float(ds[name].sel(w=w))

    fa = next((f for f in fits if f.segment == "a"), fits[0])
    fb = next((f for f in fits if f.segment == "b"), None)
    w_hi = fa.w_max
    r_fp = val("u_e", w_hi) / val("u_first_principles", w_hi)
    r_pl = val("u_e", w_hi) / val("u_paper_linear", w_hi)
    r_in = val("u_e", w_hi) / val("u_pixel_linearised", w_hi)
    ident = [f for f in fits if not f.segment.endswith("'")]
    w_last_ok = max(f.w_max for f in ident)
    worst_in = max(
        abs(float(ds["u_e"].sel(w=w)) / float(ds["u_pixel_linearised"].sel(w=w)) - 1)
        for w in ds["w"].values
        if w <= w_last_ok
    )
    lines = [
        "# Verdict: the 1-D pulse Monte Carlo (paper Section V-B)",
        "",
        f"Run: a = {at['a']:g}, dp = {at['dp']:g}, du = {at['du']:g}, sigma = "
        f"{at['sigma']:g}, N = {at['n_periods']} periods ({int(at['n_periods'] * at['du'])} "
        f"px), w = {ds['w'].values.min():g}..{ds['w'].values.max():g}, {at['trials']} trials "
        f"per w, seed {at['seed']}, imposed displacement {at['displacement']:g} px, noise in "
        f"both signals. Estimator: global SSD minimiser over |xi| <= du/2, "
        f"{at['interpolation']} interpolation of the {at['shifted']} signal (exact "
        "band-limited shift, noise included), Newton refinement to 1e-11 px. "
        f"Monte Carlo time {elapsed_s:.2f} s. dicblur {at['dicblur_version']}.",
        "",
        "## Answer",
        "",
        f"- **Regime (a), spectral correlator of the main run** (w = {fa.w_min:g}.."
        f"{fa.w_max:g}): log-log slope "
        f"**{fa.slope:.3f}** (95% CI {fa.slope_ci[0]:.3f}..{fa.slope_ci[1]:.3f}), "
        f"i.e. {_follows(fa)}. The first-principles sqrt law (slope 0.5) is "
        f"{'rejected' if not fa.slope_ci[0] <= 0.5 <= fa.slope_ci[1] else 'not rejected'}; "
        f"at w = {w_hi:g} the data are {r_fp:.2f} x sigma sqrt(w/N)/a and "
        f"{r_pl:.2f} x the paper's linear reading (sigma w / (a sqrt N), anchored at w = 1).",
    ]
    if fb is not None:
        lines.append(
            f"- **Regime (b), ramps on the edges** (w = {fb.w_min:g}..{fb.w_max:g}): slope "
            f"{fb.slope:.3f} ({fb.slope_ci[0]:.3f}..{fb.slope_ci[1]:.3f}); here the sqrt law "
            f"itself has slope {fb.slopes_pred.get('u_first_principles', math.nan):.2f} "
            f"but the data are {fb.ratio_pred.get('u_first_principles', math.nan):.2f} x its "
            "level."
        )
    corr = correlator_rows(dependence)
    lines += [
        "- **The law is the estimator's, not the signal's.** Linearising the correlator's "
        "fixed point gives u_e = sigma sqrt(S_o + S_b) / |C|, with S_o = sum (D p_o)^2, "
        "S_b = sum (D p_b)^2 and C = sum D p_o D p_b computed with the correlator's own "
        "derivative D (spectral for an exact Fourier shift; the B-spline interpolant's "
        "derivative for IC-GN; central differences with Keys interpolation). In the "
        "continuous limit of regime (a) it is sigma sqrt(w (w + 1) / (2 N)) / a: sqrt-like at "
        "w ~ 1, linear for w >> 1. For the spectral correlator of this run it matches the "
        f"Monte Carlo within {100 * worst_in:.1f}% for every w <= {w_last_ok:g} (at "
        f"w = {w_hi:g}: ratio {r_in:.3f}).",
    ]
    if corr:
        lines.append(
            "- **Regime-(a) slope by correlator** (dependence runs): "
            + "; ".join(
                f"{CORRELATORS[r.interpolation]} {r.slope_a:.2f} ({r.slope_a_ci[0]:.2f}.."
                f"{r.slope_a_ci[1]:.2f}), u_e(5) / law {r.ratio_derived_pixel_w5:.2f}"
                if r.interpolation != "analytic"
                else f"{CORRELATORS[r.interpolation]} {r.slope_a:.2f} ({r.slope_a_ci[0]:.2f}.."
                f"{r.slope_a_ci[1]:.2f}), u_e(5) / sqrt law {r.ratio_first_principles_w5:.2f}"
                for r in corr
            )
            + ". There is no single slope to quote: the paper's 'linear' reading holds for "
            "the spectral correlator only, and the sqrt law for the template estimator, whose "
            "u_e = sqrt(2 sigma^2 / S_b) is the static match score with the blurred SSSIG."
        )
    lines += [
        f"- **Knee**: u_e jumps at w = **{_f(knee)}** (first local log-log slope > 3; "
        f"u_e({_f(knee - 1)}) = {_f(val('u_e', knee - 1) if math.isfinite(knee) else math.nan)}"
        f" px, u_e({_f(knee)}) = {_f(val('u_e', knee) if math.isfinite(knee) else math.nan)}"
        f" px), not at w = du - dp = {knee_paper:g}. The predicted knee is w = 2 min(dp, g) = "
        f"{knee_predicted:g}: there the blurred ramps start to leave the sharp reference's "
        f"edges, C halves (and vanishes at w = {knee_predicted + 1:g}), and the noise-free SSD "
        "gets a flat bottom of width ~ w - 2 dp, so noise moves the minimum across it "
        "(gross errors: outlier fraction "
        f"{val('outlier_fraction', min(15.0, float(ds['w'].max()))):.2f} at w = 15). "
        f"Nothing happens at w = {knee_paper:g}: u_e({knee_paper - 1:g}) = "
        f"{val('u_e', knee_paper - 1):.3g}, u_e({knee_paper:g}) = {val('u_e', knee_paper):.3g}"
        f" px. For w >= du the window spans a period and the blurred pattern reappears "
        f"shifted by du/2 (contrast reversal): at w = {float(ds['w'].max()):g}, "
        f"{100 * _far(ds):.0f}% of the estimates sit within 1 px of +-du/2, so u_e ~ du/2.",
        "",
        "## Why",
        "",
        "Linearising the fixed point of a correlator that moves the measured (noisy) "
        "blurred signal g = p_b + tau_b against the noisy reference f = p_o + tau_o, "
        "sum D f (g - f) = 0 (IC-GN; for an exact Fourier shift the SSD minimiser has the "
        "same form), gives xi = -[sum D p_o (tau_b - tau_o) + sum D tau_o (p_b - p_o)] / "
        "sum D p_o D p_b. With D antisymmetric the two noise terms combine to "
        "sum D p_o tau_b - sum D p_b tau_o: the blurred signal's noise is projected on the "
        "*sharp* reference's gradient, whose energy S_o does not fall with blur, while the "
        "curvature C does. How fast C falls against S_o depends on D: a spectral derivative "
        "keeps the sharp edges' full gradient energy (slope ~1), a smoothing derivative "
        "(B-spline, central differences) loses part of it and the slope is lower. A template "
        "estimator that moves a noise-free model of the blurred signal has only "
        "sum p_b' (tau_b - tau_o) in the numerator and follows sigma sqrt(w/N)/a (slope "
        "1/2). The paper's eq. 16 takes its noise score Q as independent of w and a, which "
        "none of these estimators has: the growth comes from C falling against S_o.",
        "",
        "## Fits per segment (main Monte Carlo)",
        "",
        "Segments: regime letter; ' = the blurred ramps start to leave the reference edges "
        "(w > 2 min(dp, g) - 1: C halves at w = 2 min(dp, g) and vanishes one px later). "
        "Ratios are geometric means of MC / prediction.",
        "",
        "| segment | w | slope (95% CI) | sqrt law slope | MC / sqrt law | MC / paper linear "
        "| MC / law (pixel, own D) | law slope |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for f in fits:
        lines.append(
            f"| {f.segment} | {f.w_min:g}-{f.w_max:g} | {f.slope:.3f} ({f.slope_ci[0]:.3f}.."
            f"{f.slope_ci[1]:.3f}) | {_f(f.slopes_pred.get('u_first_principles', math.nan))} "
            f"| {_f(f.ratio_pred.get('u_first_principles', math.nan))} "
            f"| {_f(f.ratio_pred.get('u_paper_linear', math.nan))} "
            f"| {_f(f.ratio_pred.get('u_pixel_linearised', math.nan))} "
            f"| {_f(f.slopes_pred.get('u_pixel_linearised', math.nan))} |"
        )
    lines += [
        "",
        "## u_e(w), px",
        "",
        "| w | regime | u_e (95% CI) | mean | outliers | sqrt law | paper linear | "
        "law (pixel, own D) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for w in ds["w"].values:
        s = ds.sel(w=w)
        lines.append(
            f"| {w:g} | {s['regime'].item()} | {float(s['u_e']):.4g} ({float(s['u_e_ci_low']):.4g}"
            f"..{float(s['u_e_ci_high']):.4g}) | {float(s['mean']):+.2g} | "
            f"{float(s['outlier_fraction']):.3f} | {float(s['u_first_principles']):.4g} | "
            f"{float(s['u_paper_linear']):.4g} | {_f(float(s['u_pixel_linearised']), 4)} |"
        )
    if dependence:
        lines += [
            "",
            "## Dependence on choices the paper leaves open",
            "",
            f"{settings.get('dependence_trials')} trials per w (fewer than the main run),"
            " same seed. Slope over regime (a); ratios at w = 5.",
            "",
            "| variant | slope (a) (95% CI) | u_e(1) | u_e(5) | / sqrt law | "
            "/ law (own D) | knee (pred. 2 min(dp,g)) |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in dependence:
            lines.append(
                f"| {r.name} | {r.slope_a:.3f} ({r.slope_a_ci[0]:.3f}..{r.slope_a_ci[1]:.3f})"
                f" | {r.u_e_w1:.4g} | {r.u_e_w5:.4g} | {r.ratio_first_principles_w5:.2f} | "
                f"{r.ratio_derived_pixel_w5:.2f} | {_f(r.knee)} ({r.knee_predicted:g}) |"
            )
        lines += [
            "",
            f"Reading: N scales u_e roughly as 1/sqrt(N) (u_e(5) sqrt(N) = {_nscale(dependence)}"
            " px for the Fourier rows, in order of N) and leaves the slope unchanged; few "
            "periods make the estimator slightly more non-linear. "
            + _phase(dependence)
            + " With an exact Fourier "
            "shift it does not matter which signal is moved (the shift is unitary). Linear "
            "interpolation makes the SSD kinked at integer shifts and the estimator locks to "
            "the pixel grid for some w (tiny u_e) and scatters for others: it is not a proper "
            "sub-pixel method here. Moving a noise-free model ('template') gives the sqrt law "
            "when its kinks are off the pixel centres (edges at 1/4 px); with edges on pixel "
            "boundaries and odd w the model's kinks sit on pixel centres and the minimum "
            "locks at 0. Moving a noise-free model of the *sharp* reference gives a kinked, "
            "plateaued SSD and large scatter. The knee follows 2 min(dp, g), not du - dp "
            "(dp = 4 row).",
        ]
    lines += [
        "",
        "## In two sentences",
        "",
        "u_e of the 1-D pulse correlation follows sigma sqrt(S_o + S_b)/|C| computed with "
        "the correlator's own derivative, so its growth with w depends on the estimator: "
        f"slope {fa.slope:.2f} ({fa.slope_ci[0]:.2f}..{fa.slope_ci[1]:.2f}) in regime (a) "
        "for the spectral correlator"
        + (
            "".join(
                f", {r.slope_a:.2f} for {CORRELATORS[r.interpolation]}"
                for r in corr
                if r.interpolation != "fourier"
            )
        )
        + "; the paper's 'linear' reading and the first-principles sqrt law are each right "
        "for one estimator only. "
        f"The steep rise starts at w = {_f(knee)} = 2 dp (the blurred ramps leave the "
        f"reference edges and the SSD minimum turns flat), not at du - dp = {knee_paper:g}.",
        "",
    ]
    del u
    return "\n".join(lines)
