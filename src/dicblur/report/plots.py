"""Figures of the calibration (``dicblur calibrate``) and of an exposure plan
(``dicblur plan --plot``), drawn on detached matplotlib ``Figure`` objects (no pyplot)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._figure import subplots

__all__ = ["calibration_figures", "plan_figure"]


def _save(fig: Any, path: str | Path) -> None:
    """Write a figure atomically (a temporary file, then rename)."""
    from ..io import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)


def calibration_figures(result: Any, out: str | Path | None = None) -> tuple[Path, ...]:
    """The three figures of a calibration (:func:`dicblur.campaign.calibrate`).

    ``ue_vs_blur.png`` (u_e against W with the model and the static eq. 2 prediction),
    ``sssig_vs_blur.png`` (SSSIG against W with the eq. 18 fit) and ``ue_vs_sssig.png``
    (log u_e against log SSSIG with the eq. 17 fit), written into ``out`` (default: the
    folder of the result's ``model.json``). Returns their paths.
    """
    from ..models import sssig_decay

    dsn, model = result.curves, result.model
    out = Path(out) if out is not None else Path(result.model_path).parent
    if "noise" not in dsn.dims:
        dsn = dsn.expand_dims("noise")
    sigmas = (
        dsn["noise_effective_level"].values
        if "noise_effective_level" in dsn.coords
        else dsn["noise"].values
    )
    ds = dsn.isel(noise=0)  # SSSIG is noise-free; the log-log fit is at the first level

    w = ds["blur"].values
    ue = ds["u_e"].values
    s = ds["sssig"].values
    wf = np.linspace(0.0, float(w.max()), 200)
    paths = []

    fig, ax = subplots(figsize=(5.5, 4))
    for i, sig in enumerate(sigmas):
        col = f"C{i}"
        ax.plot(
            w,
            dsn["u_e"].isel(noise=i).values,
            "o",
            ms=3,
            color=col,
            label=f"campaign, noise {float(sig):.3g} GL",
        )
        for kind, style in (("static", "-."), ("mismatch", "-"), ("power_law", "--")):
            if (kind == "mismatch" and model.mismatch is None) or (
                kind == "static" and getattr(model, "static", None) is None
            ):
                continue
            if kind == "power_law" and i > 0:
                continue  # the power law predicts at its fitted noise only
            pred = model.predict(wf, float(sig), model=kind)  # NaN where DIC breaks down
            ax.plot(
                wf,
                pred.u_e,
                style,
                color=col,
                label=(
                    {
                        "static": "static prediction, 2 fitted scales",
                        "mismatch": "noise + blur mismatch",
                        "power_law": "power law, eq. 19",
                    }[kind]
                    + (" (default)" if kind == model.default else "")
                )
                if i == 0
                else None,
            )
        ax.plot(
            w,
            dsn["u_match_score"].isel(noise=i).values,
            ":",
            color=col,
            label="static match score, eq. 2" if i == 0 else None,
        )
    ax.set(xlabel="blur length W (px)", ylabel="u_e (px)", title="random error vs blur")
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out / "ue_vs_blur.png")
    _save(fig, paths[-1])

    fig, ax = subplots(figsize=(5.5, 4))
    ax.plot(w, s, "o", ms=3, label="campaign (mean over POIs)")
    ax.plot(
        wf,
        sssig_decay(wf, model.decay["sssig0"], model.decay["beta"]),
        "-",
        label=f"eq. 18 fit, R^2 = {model.decay.r2:.3f}",
    )
    ax.set(
        xlabel="blur length W (px)",
        ylabel="SSSIG along the motion ((GL/px)^2)",
        title="SSSIG vs blur",
    )
    ax.legend()
    fig.tight_layout()
    paths.append(out / "sssig_vs_blur.png")
    _save(fig, paths[-1])

    fig, ax = subplots(figsize=(5.5, 4))
    ax.loglog(s, ue, "o", ms=3, label="campaign")
    sf = np.geomspace(float(s.min()), float(s.max()), 100)
    pl = model.power_law
    ref = pl.extra.get("sigma_ref")
    at_first = (float(sigmas[0]) / ref) ** pl["kappa"] if "kappa" in pl.names and ref else 1.0
    ax.loglog(
        sf,
        at_first * pl["u_ref"] * (sf / pl.extra["sssig_ref"]) ** (-pl["alpha"]),
        "-",
        label=f"eq. 17 fit, alpha = {pl['alpha']:.2f} (W in {model.fit_range[0]:g}.."
        f"{model.fit_range[1]:g} px)",
    )
    ax.set(xlabel="SSSIG ((GL/px)^2)", ylabel="u_e (px)", title="log u_e vs log SSSIG")
    ax.legend()
    fig.tight_layout()
    paths.append(out / "ue_vs_sssig.png")
    _save(fig, paths[-1])
    return tuple(paths)


def plan_figure(plan: Any, path: str | Path, *, other: Any = None) -> Path:
    """u_e against exposure of an exposure plan (:func:`dicblur.models.plan_exposure`),
    with the chosen exposure, the 0.02 px rule of thumb and the target; written to
    ``path`` (format from the extension). Returns the path.

    ``other``: a second plan (another matcher mode, :func:`dicblur.models.compare_plans`),
    drawn dashed with its own exposure."""
    fig, ax = subplots(figsize=(6, 4))
    t = np.asarray(plan.curve_exposure) * 1e3
    from ..models.domain import compensation_label

    mode = "" if other is None else f", {compensation_label(plan.compensation)}"
    ax.plot(t, plan.curve_u_e, label=f"predicted u_e ({plan.model}{mode})")
    if other is not None:
        ax.plot(
            np.asarray(other.curve_exposure) * 1e3,
            other.curve_u_e,
            color="C4",
            ls="--",
            label=f"predicted u_e ({other.model}, {compensation_label(other.compensation)})",
        )
        ax.axvline(other.exposure * 1e3, color="C4", ls=":", lw=1)
    ax.axvline(
        plan.exposure * 1e3,
        color="C1",
        ls="--",
        label="optimum" if plan.optimal else "longest under target",
    )
    ax.axvline(plan.rule_of_thumb_exposure * 1e3, color="C2", ls=":", label="0.02 px rule")
    if plan.target is not None:
        ax.axhline(plan.target, color="C3", ls="-.", label="target")
    if plan.optimal:
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel("exposure (ms)")
    ax.set_ylabel("u_e (px)")
    ax.legend(fontsize="small" if other is not None else None)
    fig.tight_layout()
    _save(fig, path)
    return Path(path)
