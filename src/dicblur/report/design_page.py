"""The design report: one self-contained HTML page (dicblur.report.HtmlReport).

Maps of predicted u_e, u_ref (the power law's u_e(0), px) and MBRF over the family (the
generalisation of the paper's Fig. 11, which plots eta), u_ref and MBRF against MIG_0, the
search trace, the surrogate against the measured objective, the u_e(W) curves of the best,
default and worst patterns, the confirmation and the export. matplotlib is imported
inside the functions (detached ``Figure`` objects, no pyplot).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..arrays import Float64Array
from ..design.export import PrintExport
from ..design.search import DesignResult
from ._data import spearman
from ._figure import subplots

__all__ = ["spearman", "write_design_report"]


def _grid_array(result: DesignResult, attr: str) -> Float64Array:
    fam = result.family
    axes = [fam.axis(i) for i in range(3)]
    out = np.full([len(a) for a in axes], np.nan)
    for e in result.grid:
        c = e.candidate
        idx = tuple(
            int(np.argmin(np.abs(axes[i] - v)))
            for i, v in enumerate((c.speckle_size, c.density, c.softness))
        )
        out[idx] = getattr(e, attr)
    return out


def _maps(result: DesignResult, attr: str, title: str, *, log: bool) -> Any:
    fam = result.family
    d_ax, p_ax, s_ax = (fam.axis(i) for i in range(3))
    arr = _grid_array(result, attr)
    vals = np.log10(arr) if log else arr
    finite = vals[np.isfinite(vals)]
    vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    n = len(p_ax)
    fig, axes = subplots(1, n, figsize=(3.6 * n + 0.8, 3.4), squeeze=False)
    im: Any = None
    for k, p in enumerate(p_ax):
        ax = axes[0, k]
        im = ax.imshow(
            vals[:, k, :], origin="lower", aspect="auto", vmin=vmin, vmax=vmax, cmap="viridis"
        )
        ax.set_xticks(range(len(s_ax)), [f"{v:.2g}" for v in s_ax])
        ax.set_yticks(range(len(d_ax)), [f"{v:.2g}" for v in d_ax])
        ax.set_xlabel("softness (px)")
        if k == 0:
            ax.set_ylabel("speckle size D (px)")
        ax.set_title(f"density {p:.2g}")
        for i in range(len(d_ax)):
            for j in range(len(s_ax)):
                v = arr[i, k, j]
                if np.isfinite(v):
                    frac = (vals[i, k, j] - vmin) / (vmax - vmin) if vmax > vmin else 0.0
                    ax.text(
                        j,
                        i,
                        f"{v:.2g}",
                        ha="center",
                        va="center",
                        fontsize=7,
                        color="k" if frac > 0.6 else "w",
                    )
    fig.colorbar(im, ax=axes[0, :].tolist(), label=("log10 " if log else "") + title)
    return fig


def _fig11(result: DesignResult) -> Any:
    grid = result.grid
    mig0 = np.array([e.mig0 for e in grid])
    obj = np.array([e.objective for e in grid])
    fig, axes = subplots(1, 2, figsize=(10, 3.8))
    for ax, attr, lab in (
        (axes[0], "u_ref", "u_ref = eq. 17 u_e(0) (px)"),
        (axes[1], "mbrf", "MBRF = 2 alpha beta (1/px^2)"),
    ):
        y = np.array([getattr(e, attr) for e in grid])
        sc = ax.scatter(mig0, y, c=np.log10(obj), cmap="viridis_r", s=28)
        ax.set_xlabel("MIG_0 (GL/px)")
        ax.set_ylabel(lab)
        if attr == "u_ref":
            ax.set_yscale("log")
    fig.colorbar(sc, ax=axes.tolist(), label="log10 predicted u_e (px)")
    return fig


def _trace(result: DesignResult) -> Any:
    fig, ax = subplots(figsize=(7, 3.4))
    objs = np.array([e.objective for e in result.evaluations])
    stages = [e.stage for e in result.evaluations]
    idx = np.arange(1, objs.size + 1)
    for st, col in (("grid", "tab:blue"), ("refine", "tab:orange")):
        m = np.array([s == st for s in stages])
        if m.any():
            ax.scatter(idx[m], objs[m], s=18, color=col, label=st)
    ax.plot(idx, np.minimum.accumulate(objs), "k-", lw=1, label="best so far")
    ax.axhline(result.reference.objective, color="tab:red", ls="--", lw=1, label="default pattern")
    ax.set_yscale("log")
    ax.set_xlabel("campaign (evaluation) number")
    ax.set_ylabel("predicted u_e (px)")
    ax.legend(fontsize=8)
    return fig


def _surrogate(result: DesignResult) -> Any:
    fig, ax = subplots(figsize=(4.6, 4.2))
    x = np.array([e.surrogate for e in result.evaluations])
    y = np.array([e.objective for e in result.evaluations])
    ax.loglog(x, y, "o", ms=4)
    lo, hi = float(np.nanmin([x, y])), float(np.nanmax([x, y]))
    ax.plot([lo, hi], [lo, hi], "k:", lw=1)
    ax.set_xlabel("static surrogate u_e (px)")
    ax.set_ylabel("predicted u_e from DIC campaign (px)")
    return fig


def _curves(result: DesignResult) -> Any:
    fig, ax = subplots(figsize=(6.4, 4))
    for e, lab, col in (
        (result.best, "best", "tab:green"),
        (result.reference, "default", "tab:red"),
        (result.worst, "worst of grid", "tab:gray"),
    ):
        ax.plot(e.fit_blurs, e.u_e, "o-", color=col, label=f"{lab}: {e.candidate.label()}")
        ax.plot(result.problem.blurs, e.predicted, "x", color=col, ms=9)
    conf = result.confirmation
    if conf is not None:
        w = result.problem.blur_array
        for k, (lab, col) in enumerate(
            (("best", "tab:green"), ("default", "tab:red"), ("worst", "tab:gray"))
        ):
            u = np.asarray(conf.u_e[conf.labels.index(lab)])
            se = u.std(axis=0, ddof=1) / math.sqrt(u.shape[0])
            ax.errorbar(
                w + 0.04 * (k - 1),
                u.mean(axis=0),
                yerr=2 * se,
                fmt="s",
                mfc="none",
                color=col,
                capsize=3,
            )
    ax.set_yscale("log")
    ax.set_xlabel("blur length W (px)")
    ax.set_ylabel("u_e (px)")
    ax.set_title("o: search campaign, x: model prediction, □: confirmation (±2 SE)", fontsize=8)
    ax.legend(fontsize=7)
    return fig


def _patterns(result: DesignResult) -> Any:
    from ..patterns import speckle_pattern

    n = min(128, result.problem.image_size)
    fig, axes = subplots(1, 3, figsize=(10, 3.6))
    for ax, e, lab in (
        (axes[0], result.best, "best"),
        (axes[1], result.reference, "default"),
        (axes[2], result.worst, "worst of grid"),
    ):
        c = e.candidate
        img = speckle_pattern(
            n,
            speckle_size=c.speckle_size,
            density=c.density,
            softness=c.softness,
            seed=result.problem.seed,
        )
        ax.imshow(img, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        ax.set_title(f"{lab}\n{c.label()}", fontsize=9)
        ax.set_axis_off()
    return fig


def _row(e: Any, rank: int | None = None) -> dict[str, Any]:
    c = e.candidate
    row: dict[str, Any] = {}
    if rank is not None:
        row["rank"] = rank
    row.update(
        {
            "stage": e.stage,
            "D (px)": c.speckle_size,
            "density": c.density,
            "softness (px)": c.softness,
            "predicted u_e (px)": e.objective,
            "surrogate (px)": e.surrogate,
            "MIG_0": e.mig0,
            "MBRF": e.mbrf,
            "c fit": e.c_fit,
            "c static": e.c_static,
        }
    )
    return row


def write_design_report(
    result: DesignResult,
    folder: str | Path,
    *,
    export: PrintExport | None = None,
    command: str | None = None,
) -> Path:
    """Write ``folder/report.html`` (+ figures as PNG and SVG) and return its path."""
    from .html import HtmlReport

    folder = Path(folder)
    rep = HtmlReport("dicblur design: the speckle pattern for your blur", folder)
    prob, s = result.problem, result.summary()
    rep.section("Result")
    rep.paragraph(
        f"Target: {prob.describe_target()}, noise {prob.noise:g} GL per exposure, subset "
        f"{prob.subset} px, step {prob.step} px, {prob.dic_shape} shape function. Best "
        f"pattern: **{result.best.candidate.label()}** (D = speckle size, p = black-area "
        f"fraction, s = edge softness, all in camera px), predicted u_e "
        f"{result.best.objective:.4g} px against {result.reference.objective:.4g} px for "
        f"the default pattern and {result.worst.objective:.4g} px for the worst of the grid."
    )
    rows = [{"quantity": k, "value": v} for k, v in s.items() if not isinstance(v, dict)]
    rep.table(rows, left=["quantity"], caption="Summary (u_e in px)")
    if result.confirmation is not None:
        conf = result.confirmation
        crow = []
        for lab, cand in zip(conf.labels, conf.candidates, strict=True):
            crow.append(
                {
                    "pattern": lab,
                    "settings": cand.label(),
                    "measured u_e (px)": conf.mean(lab),
                    "standard error (px)": conf.stderr(lab),
                    "realisations": len(conf.objective[0]),
                }
            )
        rep.table(
            crow,
            left=["pattern", "settings"],
            caption="Confirmation on fresh pattern and noise seeds (measured DIC u_e "
            "at the design blur, no model)",
        )
        d, se = conf.difference("best", "default")
        rep.paragraph(
            f"Measured improvement over the default pattern: {d:.4g} px "
            f"({100 * s['gain_vs_default']:.1f} %), paired standard error "
            f"{se:.2g} px ({d / se if se > 0 else float('inf'):.1f} standard "
            "errors)."
        )
    if command:
        rep.preformatted(command)
    rep.section("Maps over the family (generalising the paper's Fig. 11)")
    rep.paragraph(
        "Each cell is one candidate of the coarse grid: its own campaign over the "
        f"W grid {list(prob.fit_blurs)} px and its own blur-model fit."
    )
    rep.figure(
        _maps(result, "objective", "predicted u_e (px)", log=True),
        "map_u_e",
        f"Predicted u_e at {prob.describe_target()} over speckle size, softness and density.",
    )
    rep.figure(
        _maps(result, "u_ref", "u_ref (px)", log=True),
        "map_u_ref",
        "u_ref of the power law u_e = u_ref (SSSIG / SSSIG_0)^-alpha (eq. 17 around "
        "SSSIG_0: its u_e at W = 0, px), fitted over the whole W grid.",
    )
    rep.figure(
        _maps(result, "mbrf", "MBRF (1/px^2)", log=False),
        "map_mbrf",
        "Motion blur rejection factor MBRF = 2 alpha beta (eq. 22).",
    )
    rep.figure(
        _fig11(result),
        "fig11_family",
        "u_ref and MBRF against the static MIG_0, coloured by predicted u_e: the "
        "paper's Fig. 11 over the whole family.",
    )
    rep.section("Search")
    n_ref = s["n_refine"]
    rep.paragraph(
        f"{s['n_grid']} grid campaigns, then {n_ref} refinement campaigns "
        "(bounded Nelder-Mead in log speckle size, density and softness), "
        f"{result.n_campaigns} campaigns and {result.n_points} campaign points "
        f"(DIC runs) in all, {result.wall_s:.1f} s."
    )
    rep.figure(_trace(result), "search_trace", "Predicted u_e of every campaign, in order.")
    rho = spearman(
        [e.surrogate for e in result.evaluations], [e.objective for e in result.evaluations]
    )
    rep.figure(
        _surrogate(result),
        "surrogate",
        f"Static surrogate (no DIC) against the campaign prediction; Spearman rank "
        f"correlation {rho:.3f}.",
    )
    rep.figure(_curves(result), "u_e_curves", "u_e(W) of the best, default and worst patterns.")
    rep.figure(_patterns(result), "patterns", "The three patterns (128 px crops).")
    ranking = result.ranking()
    rep.table(
        [_row(e, i + 1) for i, e in enumerate(ranking[:10])],
        left=["stage"],
        caption="Ten best candidates",
    )
    if export is not None:
        rep.section("Export")
        rep.table(
            [
                {
                    "quantity": k,
                    "value": " x ".join(f"{x:.5g}" for x in v) if isinstance(v, list) else v,
                }
                for k, v in export.to_dict().items()
                if not isinstance(v, dict)
            ],
            left=["quantity", "value"],
            caption="Print-ready files",
        )
        rep.paragraph(
            f"Speckle size on the specimen {export.speckle_size_mm:.3g} mm "
            f"({export.speckle_size_dots:.3g} printed dots at {export.dpi:g} "
            "DPI). Regenerate with dicblur.speckle_pattern(**generator) from the "
            "JSON file."
        )
    return rep.write()
