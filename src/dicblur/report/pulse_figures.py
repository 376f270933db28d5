"""Figures of the pulse study (paper Fig. 4, 5, 6), drawn on detached matplotlib
``Figure`` objects (no pyplot); matplotlib is imported inside each function."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..io import atomic_path
from ..pulse.montecarlo import PAPER_TRAIN
from ..pulse.signal import PulseTrain
from ..pulse.study import DENSE_TRAIN, PulseStudy
from ._figure import subplots

__all__ = ["plot_min_chi2", "plot_regimes", "plot_uncertainty", "write_figures"]


def _save(fig: Any, out: Path | str) -> None:
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=120)


def plot_regimes(path: str | Path) -> Path:
    """Fig. 4: the sharp (dashed) and blurred (solid) train in the four regimes (PNG)."""
    cases = (
        ("(a) w < dp, w < g", PAPER_TRAIN, 3.0),
        ("(b) dp <= w < g", PAPER_TRAIN, 10.0),
        ("(c) w >= dp, w >= g", PAPER_TRAIN, 19.0),
        ("(d) g <= w < dp (dp = 16)", DENSE_TRAIN, 10.0),
    )
    fig, axes = subplots(2, 2, figsize=(9, 6), sharey=True)
    for ax, (title, train, w) in zip(axes.ravel(), cases, strict=True):
        x = np.linspace(-train.du / 2, 1.5 * train.du, 2000)
        ax.plot(x, train.value(x), "b--", lw=1, label="sharp p(x)")
        ax.plot(x, train.blurred(x, w), "r-", lw=1.6, label="blurred by the box of width w")
        ax.set_title(f"{title}: w = {w:g}, dp = {train.dp:g}, du = {train.du:g}", fontsize=9)
        ax.set_xlabel("x (px)")
        ax.set_ylim(-0.05, 1.1)
    axes[0, 0].set_ylabel("grey level")
    axes[1, 0].set_ylabel("grey level")
    # one legend below the panels: inside them it covered the signals
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    out = Path(path)
    _save(fig, out)
    return out


def plot_min_chi2(study: PulseStudy, path: str | Path) -> Path:
    """Fig. 5: minimum of the continuous SSD against w, with the regime-(a) law."""
    f5 = study.fig5
    train = PulseTrain(a=f5.attrs["a"], dp=f5.attrs["dp"], du=f5.attrs["du"])
    fig, ax = subplots(figsize=(6, 4))
    ax.plot(f5["w"], f5["min_chi2"], "ko", label="min over xi, exact continuous SSD")
    ax.plot(f5["w"], f5["chi2_law"], "r-", label="regime (a): N a^2 w / 6")
    ax.axvline(min(train.dp, train.g), color="grey", ls=":", lw=1)
    ax.set_xlabel("w (px)")
    ax.set_ylabel("min chi2 (GL^2 px)")
    ax.set_title(f"a = {train.a:g}, dp = {train.dp:g}, du = {train.du:g}, N = 1", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(path)
    _save(fig, out)
    return out


def plot_uncertainty(study: PulseStudy, path: str | Path) -> Path:
    """Fig. 6: Monte Carlo u_e(w) with its 95% CI and the three predictions (linear and
    log-log axes)."""
    ds = study.dataset
    w = ds["w"].values
    fig, axes = subplots(1, 2, figsize=(11, 5.0))
    for ax, log in zip(axes, (False, True), strict=True):
        err = np.vstack([ds["u_e"] - ds["u_e_ci_low"], ds["u_e_ci_high"] - ds["u_e"]])
        ax.errorbar(w, ds["u_e"], yerr=err, fmt="ko", ms=4, capsize=2, label="Monte Carlo (95% CI)")
        ax.plot(w, ds["u_first_principles"], "b-", label="sqrt law sigma sqrt(2/S_b)")
        ax.plot(w, ds["u_paper_linear"], "g--", label="paper: linear, sigma w/(a sqrt N)")
        # The linearisation is meaningless once the cross-gradient C has vanished.
        ok = np.isfinite(ds["u_pixel_linearised"]) & (ds["cross_gradient"] > 0)
        pix = np.where(ok, ds["u_pixel_linearised"], np.nan)
        ax.plot(w, pix, "r:", lw=2, label="derived sigma sqrt(S_o+S_b)/|C| (pixel)")
        ax.axvline(study.knee_predicted, color="m", lw=1, label="2 dp (predicted knee)")
        ax.axvline(study.knee_paper, color="grey", ls="--", lw=1, label="du - dp (paper)")
        ax.set_xlabel("w = 1 + W (px)")
        ax.set_ylabel("u_e (px)")
        if log:
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_title("all widths, log-log", fontsize=9)
        else:
            # zoom on the identifiable range, up to the predicted knee
            w_zoom = float(study.knee_predicted)
            top = max(
                float(ds["u_e_ci_high"].sel(w=slice(None, w_zoom)).max()),
                float(ds["u_paper_linear"].sel(w=slice(None, w_zoom)).max()),
            )
            ax.set_xlim(0.5, w_zoom + 0.5)
            ax.set_ylim(0, 1.1 * top)
            ax.set_title(
                f"zoom: w <= {w_zoom:g} (up to the predicted knee), linear axes", fontsize=9
            )
    # one legend below both panels: inside them it covered the Monte Carlo points
    handles, labels = axes[1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle(
        f"1-D pulse Monte Carlo: a = {ds.attrs['a']:g}, dp = {ds.attrs['dp']:g}, du = "
        f"{ds.attrs['du']:g}, sigma = {ds.attrs['sigma']:g}, N = {ds.attrs['n_periods']}, "
        f"{ds.attrs['trials']} trials",
        fontsize=9,
    )
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    out = Path(path)
    _save(fig, out)
    return out


def write_figures(study: PulseStudy, outdir: str | Path) -> list[Path]:
    """Write ``fig4_regimes.png``, ``fig5_min_chi2.png``, ``fig6_uncertainty.png``."""
    d = Path(outdir)
    return [
        plot_regimes(d / "fig4_regimes.png"),
        plot_min_chi2(study, d / "fig5_min_chi2.png"),
        plot_uncertainty(study, d / "fig6_uncertainty.png"),
    ]
