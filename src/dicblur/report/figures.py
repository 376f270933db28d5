"""Figures of the reproduce report (the paper's Figs. 1, 2, 7-11 and our additions).

Each function takes plain arrays / dicts and returns a detached matplotlib ``Figure`` (no
pyplot); matplotlib is imported inside the functions, so importing this module stays cheap.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ._figure import subplots

__all__ = [
    "fig_contrast_error",
    "fig_loglog",
    "fig_mbrf_mig",
    "fig_mismatch",
    "fig_patterns",
    "fig_sssig_decay",
    "fig_sssig_pan",
    "fig_ue_blur",
]

_COLORS = ("#d1495b", "#edae49", "#00798c", "#30638e", "#6a4c93", "#8ac926")


def _layout(fig: Any, *, rows: int = 1, twin: bool = False) -> None:
    """Fixed margins (tight_layout measures every text and is the slowest step)."""
    h = fig.get_figheight()
    fig.subplots_adjust(
        left=0.09,
        right=0.88 if twin else 0.97,
        top=1 - 0.45 / h,
        bottom=0.55 / h,
        hspace=0.75 / max(rows, 1) + 0.25,
        wspace=0.45 if twin else 0.3,
    )


def _panel(ax: Any, title: str, xlabel: str, ylabel: str, *, legend: float) -> None:
    """Title, axis labels and legend (font size ``legend``) of one pattern's panel."""
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=legend)


def _grid(n: int) -> tuple[Any, Any]:
    cols = 2 if n > 1 else 1
    rows = (n + cols - 1) // cols
    fig, axes = subplots(rows, cols, figsize=(5.2 * cols, 3.6 * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()


def fig_patterns(images: Mapping[str, np.ndarray], *, crop: int = 128) -> Any:
    """Fig. 1: a crop of each study pattern."""
    fig, axes = subplots(1, len(images), figsize=(3.0 * len(images), 3.2))
    for ax, (label, img) in zip(np.atleast_1d(axes), images.items(), strict=True):
        ax.imshow(img[:crop, :crop], cmap="gray", interpolation="nearest")
        ax.set_title(label, fontsize=9)
        ax.set_axis_off()
    fig.subplots_adjust(left=0.01, right=0.99, top=0.9, bottom=0.02, wspace=0.05)
    return fig


def fig_sssig_pan(data: Mapping[str, Mapping[str, np.ndarray]], subset: int) -> Any:
    """Fig. 2: SSSIG of the blurred image vs W per pattern, with Pan's N^2 MIG(W)^2."""
    fig, axes = _grid(len(data))
    for ax, (label, d) in zip(axes, data.items(), strict=False):
        ax.semilogy(d["blur"], d["sssig"], "o", ms=3, color=_COLORS[2], label="SSSIG (data)")
        ax.semilogy(
            d["blur"], subset**2 * d["mig"] ** 2, "-", color=_COLORS[0], label=r"Pan: $N^2\,MIG^2$"
        )
        _panel(ax, label, "blur W (px)", r"SSSIG$_x$ (GL$^2$/px$^2$)", legend=8)
    _layout(fig, rows=len(axes) // 2)
    return fig


def fig_ue_blur(data: Mapping[str, Mapping[str, np.ndarray]]) -> Any:
    """Fig. 10 (and s. V): measured u_e vs W with eq. 19, the mismatch model, eq. 2."""
    fig, axes = _grid(len(data))
    for ax, (label, d) in zip(axes, data.items(), strict=False):
        ok = d.get("valid", np.ones(d["blur"].size, dtype=bool))
        ax.plot(d["blur"][ok], d["u_e"][ok], "o", ms=3, color="k", label="measured (DIC)")
        if not ok.all():
            ax.plot(
                d["blur"][~ok],
                d["u_e"][~ok],
                "o",
                ms=4,
                mfc="none",
                color="0.4",
                label="DIC breakdown (< 90 % converged), not fitted",
            )
        ax.plot(d["blur"], d["eq19"], "-", color=_COLORS[0], label="eq. 19 (power law)")
        if d.get("mismatch") is not None:
            ax.plot(d["blur"], d["mismatch"], "--", color=_COLORS[2], label="noise + blur mismatch")
        ax.plot(
            d["blur"], d["match_score"], ":", color=_COLORS[3], label="static match score, eq. 2"
        )
        _panel(ax, label, "blur W (px)", r"$u_e$ (px)", legend=7)
    _layout(fig, rows=len(axes) // 2)
    return fig


def fig_loglog(data: Mapping[str, Mapping[str, Any]]) -> Any:
    """Fig. 7: log u_e vs log SSSIG, with the eq. 17 fit over its range."""
    fig, axes = _grid(len(data))
    for ax, (label, d) in zip(axes, data.items(), strict=False):
        ax.loglog(d["sssig"], d["u_e"], "o", ms=3, color="k", label="data")
        inside = d["in_range"]
        s = np.sort(d["sssig"][inside])
        ax.loglog(
            s,
            d["u_ref"] * (s / d["sssig_ref"]) ** (-d["alpha"]),
            "-",
            color=_COLORS[0],
            lw=2,
            label=rf"eq. 17: $\alpha$={d['alpha']:.2f}, fit W $\leq$ {d['w_max']:.1f}",
        )
        _panel(ax, label, "SSSIG (GL$^2$/px$^2$)", r"$u_e$ (px)", legend=8)
        _readable_log_ticks(ax)
    _layout(fig, rows=len(axes) // 2)
    return fig


def _readable_log_ticks(ax: Any) -> None:
    """Log axes spanning less than a decade get minor-tick labels that overlap: label
    1-2-5 steps in compact scientific notation and leave the other minor ticks bare."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    def fmt(v: float, _pos: int) -> str:
        if v <= 0:
            return ""
        e = int(np.floor(np.log10(v) + 1e-12))
        m = v / 10.0**e
        return f"{m:.0f}e{e}" if abs(e) >= 3 else f"{v:g}"

    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(fmt))
        axis.set_minor_formatter(NullFormatter())
    ax.tick_params(axis="both", labelsize=8)


def fig_contrast_error(data: Mapping[str, Mapping[str, np.ndarray]]) -> Any:
    """Fig. 8: |model error| of eq. 17 and the contrast ratio (static / blurred) vs W."""
    fig, axes = _grid(len(data))
    for ax, (label, d) in zip(axes, data.items(), strict=False):
        ax.plot(
            d["blur"], 100 * np.abs(d["error"]), "--", color=_COLORS[0], label="|model error| (%)"
        )
        ax.set_xlabel("blur W (px)")
        ax.set_ylabel("|eq. 17 error| (%)", color=_COLORS[0])
        ax2 = ax.twinx()
        ax2.plot(d["blur"], d["contrast_ratio"], "-", color=_COLORS[3], label="contrast ratio")
        ax2.set_ylabel("contrast ratio static / blurred", color=_COLORS[3])
        ax.set_title(label, fontsize=10)
    _layout(fig, rows=len(axes) // 2, twin=True)
    return fig


def fig_sssig_decay(data: Mapping[str, Mapping[str, Any]]) -> Any:
    """Fig. 9: SSSIG vs W with the eq. 18 fit and its R^2."""
    fig, axes = _grid(len(data))
    for ax, (label, d) in zip(axes, data.items(), strict=False):
        ax.plot(d["blur"], d["sssig"], "o", ms=3, color="k", label="data")
        ax.plot(
            d["blur"],
            d["fit"],
            "-",
            color=_COLORS[2],
            label=rf"eq. 18: $\beta$={d['beta']:.3g}, $R^2$={d['r2']:.3f}",
        )
        _panel(ax, label, "blur W (px)", "SSSIG (GL$^2$/px$^2$)", legend=8)
    _layout(fig, rows=len(axes) // 2)
    return fig


def fig_mbrf_mig(study: Sequence[Mapping[str, Any]], family: Sequence[Mapping[str, Any]]) -> Any:
    """Fig. 11: u_ref (eq. 17 around SSSIG_0, px) and MBRF against MIG_0 (study patterns and
    a generated family). The paper plots eta, whose units depend on alpha."""
    fig, (a1, a2) = subplots(1, 2, figsize=(10.5, 3.9))
    panels = (
        (a1, "u_ref", r"$u_{ref}$ = eq. 17 $u_e$(0) (px)"),
        (a2, "mbrf", r"MBRF = 2$\alpha\beta$ (px$^{-2}$)"),
    )
    for ax, key, ylab in panels:
        fam = sorted(family, key=lambda r: r["mig0"])
        if fam:
            ax.plot(
                [r["mig0"] for r in fam],
                [r[key] for r in fam],
                "-o",
                ms=4,
                color=_COLORS[2],
                label="generated family (speckle size)",
            )
            for r in fam:
                ax.annotate(
                    f"{r['speckle_size']:g}px",
                    (r["mig0"], r[key]),
                    fontsize=7,
                    textcoords="offset points",
                    xytext=(3, 3),
                )
        for i, r in enumerate(study):
            ax.plot(r["mig0"], r[key], "s", ms=7, color=_COLORS[i % len(_COLORS)], label=r["label"])
        ax.set_xlabel(r"MIG$_0$ (GL/px)")
        ax.set_ylabel(ylab)
        ax.set_yscale("log")
        ax.legend(fontsize=7)
    _layout(fig)
    return fig


def fig_mismatch(data: Mapping[str, Mapping[str, Any]]) -> Any:
    """Beyond the paper: u_e vs W at each noise level, with the mismatch model."""
    fig, axes = _grid(len(data))
    for ax, (label, d) in zip(axes, data.items(), strict=False):
        static = d.get("static") or [None] * len(d["curves"])
        for j, ((sigma, u, model), st) in enumerate(zip(d["curves"], static, strict=True)):
            c = _COLORS[j % len(_COLORS)]
            ax.semilogy(d["blur"], u, "o", ms=3, color=c, label=f"σ = {sigma:g} GL")
            ax.semilogy(d["blur"], model, "-", color=c)
            if st is not None:
                ax.semilogy(
                    d["blur"], st, ":", color=c, label="static image, no fit" if j == 0 else None
                )
        ax.set_title(label, fontsize=10)
        ax.set_xlabel("blur W (px)")
        ax.set_ylabel(r"$u_e$ (px)")
        lowest = float(np.nanmin([np.nanmin(u) for _, u, _ in d["curves"]]))
        ax.set_ylim(bottom=max(1e-4, lowest / 2))
        ax.legend(fontsize=7)
    _layout(fig, rows=len(axes) // 2)
    return fig


def fig_compensation(data: Mapping[str, Any]) -> Any:
    """Beyond the paper (issue 18): u_e vs W with and without blur compensation."""
    fig, axes = _grid(1)
    ax = axes[0]
    w = np.asarray(data["blur"])
    ax.semilogy(w, data["plain"], "o", ms=3, color=_COLORS[0], label="plain (sharp reference)")
    ax.semilogy(w, data["deblur"], "s", ms=3, color=_COLORS[1], label="deblurred current (Wiener)")
    ax.semilogy(w, data["given"], "^", ms=3, color=_COLORS[2], label="blur-compensated")
    ax.semilogy(w, data["bound"], "-", color="0.3", label=r"static bound, eq. 2 at SSSIG(W)")
    ax.set_title(str(data["label"]), fontsize=10)
    ax.set_xlabel("blur W (px)")
    ax.set_ylabel(r"$u_e$ (px)")
    ax.legend(fontsize=7)
    _layout(fig)
    return fig
