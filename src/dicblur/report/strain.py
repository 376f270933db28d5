"""Figures of strains (docs/strain.md): the strain plan's VSG / uncertainty trade-off and,
for a track with strains, a strain map and ``sigma_exx`` over time (matplotlib ``Figure``,
no pyplot)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._figure import subplots

__all__ = [
    "add_strain_section",
    "fig_sigma_exx_time",
    "fig_strain_map",
    "strain_plan_figure",
]


def _save(fig: Any, path: str | Path) -> Path:
    from ..io import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    return Path(path)


def strain_plan_figure(plan: Any, path: str | Path) -> Path:
    """Two panels of a :class:`~dicblur.strain.plan.StrainPlan`: ``sigma_exx`` against the
    exposure at the chosen VSG (with the target and the planned exposure), and the longest
    exposure meeting the target against the VSG (the trade-off). Returns ``path``."""
    fig, (a, b) = subplots(1, 2, figsize=(10, 4))
    a.plot(np.asarray(plan.curve_exposure) * 1e3, np.asarray(plan.curve_sigma_exx) * 1e6)
    a.axhline(plan.target * 1e6, color="C3", ls="-.", label="target")
    a.axvline(plan.exposure * 1e3, color="C1", ls="--", label="longest under target")
    a.set_xlabel("exposure (ms)")
    a.set_ylabel("predicted sigma_exx (microstrain)")
    a.set_title(f"VSG {plan.vsg:g} px")
    a.legend()
    vs = np.asarray(plan.tradeoff_vsg)
    b.plot(vs, np.asarray(plan.tradeoff_exposure) * 1e3, "o-", label="longest exposure")
    b.axvline(plan.vsg, color="C1", ls="--", label="chosen VSG")
    b.set_xlabel("VSG (px)")
    b.set_ylabel("longest exposure meeting the target (ms)")
    c = b.twinx()
    c.plot(vs, np.asarray(plan.tradeoff_sigma) * 1e6, "s:", color="C2")
    c.set_ylabel("sigma_exx at the planned exposure (microstrain)", color="C2")
    b.legend(loc="upper left")
    fig.tight_layout()
    return _save(fig, path)


def _strain_medians(ds: Any) -> tuple[Any, dict[str, Any]]:
    """Median ``sigma_exx`` over the OK points per frame, and of its parts."""
    import warnings

    ok = ds["strain_status"].values == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # frames without OK points: NaN
        med = np.nanmedian(np.where(ok, ds["sigma_exx"].values, np.nan), axis=1)
        parts = {
            k: np.nanmedian(np.where(ok, ds[k].values, np.nan), axis=1)
            for k in ("sigma_exx_noise", "sigma_exx_blur")
            if k in ds
        }
    return med, parts


def fig_sigma_exx_time(ds: Any) -> Any:
    """Median ``sigma_exx`` of the points per frame, with its noise and blur parts."""
    med, parts = _strain_medians(ds)
    t = ds["time"].values
    fig, ax = subplots(figsize=(6, 4))
    ax.plot(t * 1e3, med * 1e6, label="sigma_exx")
    for k, v in parts.items():
        ax.plot(t * 1e3, v * 1e6, ls="--", label=k.replace("sigma_exx_", "") + " part")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("median sigma_exx (microstrain)")
    ax.set_title(f"VSG {ds.attrs.get('strain_vsg', '?')} px")
    ax.legend()
    fig.tight_layout()
    return fig


def fig_strain_map(ds: Any) -> Any:
    """``exx`` on the POI grid at the frame with the largest median ``sigma_exx`` (blank:
    no strain there, see ``strain_status``)."""
    med, _ = _strain_medians(ds)
    ok = ds["strain_status"].values == 0
    rows, cols = ds["row"].values, ds["col"].values
    ur, uc = np.unique(rows), np.unique(cols)
    f = int(np.nanargmax(med)) if np.isfinite(med).any() else 0
    exx = np.where(ok[f], ds["exx"].values[f], np.nan).reshape(ur.size, uc.size)
    fig, ax = subplots(figsize=(6, 5))
    im = ax.imshow(
        exx * 1e6,
        extent=(uc[0], uc[-1], ur[-1], ur[0]),
        cmap="coolwarm",
        interpolation="nearest",
    )
    fig.colorbar(im, ax=ax, label="exx (microstrain)")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    ax.set_title(f"exx, frame {int(ds['frame'].values[f])} (largest median sigma_exx)")
    fig.tight_layout()
    return fig


def add_strain_section(rep: Any, ds: Any) -> None:
    """The "Strain" section of the track report (a track with strains)."""
    rep.section("Strain")
    rep.figure(
        fig_strain_map(ds),
        "strain_map",
        "exx of the points with a full plane-fit window (docs/strain.md) at the frame "
        "with the largest median sigma_exx",
    )
    rep.figure(
        fig_sigma_exx_time(ds),
        "sigma_exx_time",
        "median predicted sigma_exx over the points per frame, with its noise part "
        "(correlated through overlapping subsets) and its blur-mismatch part",
    )
