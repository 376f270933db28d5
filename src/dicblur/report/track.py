"""The ``dicblur track`` report: one self-contained HTML page of a tracked recording.

Figures (``matplotlib.figure.Figure``, no pyplot state): displacement time series at
chosen or automatic points with +-2 sigma bands, the sigma map at the worst frame over the
reference image, the histogram of W, the blur-dominated share over time, the statuses
over time; the exposure advice in one sentence.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..arrays import Float64Array
from ._figure import figure, figure_axes
from .html import HtmlReport

__all__ = [
    "auto_points",
    "fig_blur_share",
    "fig_sigma_map",
    "fig_status",
    "fig_time_series",
    "fig_w_histogram",
    "matcher_label",
    "write_track_report",
]


def matcher_label(attrs: Any) -> str:
    """The matcher of a track, for the report: plain or blur-compensated (with its passes)
    and, with chunks, how they ran."""
    m = str(attrs.get("matcher", "plain"))
    text = (
        "plain (sigma: noise + blur-mismatch terms)"
        if m == "plain"
        else f"blur-compensated, blur vector per point from the track, "
        f"{int(attrs.get('compensation_passes', 1))} pass(es) (sigma: noise term of the "
        "blurred reference, no mismatch term)"
    )
    if "chunks_n_chunks" in attrs:
        text += (
            f"; {int(attrs['chunks_n_chunks'])} chunks of {int(attrs['chunks_chunk_frames'])} "
            f"frames ({attrs.get('chunks_scheduler', 'serial')}, "
            f"{int(attrs.get('chunks_n_resumed', 0))} resumed)"
        )
    return text


def auto_points(ds: Any, n: int = 3) -> list[int]:
    """Points to plot: the one with the largest mean sigma, the median one, the smallest."""
    s = np.hypot(ds["sigma_u"].values, ds["sigma_v"].values)
    valid = ds["valid"].values.astype(bool)
    with np.errstate(invalid="ignore"):
        cnt = valid.sum(axis=0)
        mean = np.where(
            cnt > 0, np.nansum(np.where(valid, s, 0.0), axis=0) / np.maximum(cnt, 1), np.nan
        )
    ok = np.flatnonzero(np.isfinite(mean) & (cnt >= max(2, 0.5 * valid.shape[0])))
    if ok.size == 0:
        return [0]
    order = ok[np.argsort(mean[ok])]
    picks = [int(order[-1]), int(order[order.size // 2]), int(order[0])]
    return list(dict.fromkeys(picks))[:n]


def fig_time_series(ds: Any, points: Sequence[int]) -> Any:
    """u and v against time at ``points`` with +-2 sigma bands (invalid samples hidden)."""
    fig = figure(10, 2.6 * len(points))
    t = ds["time"].values * 1e3
    for i, p in enumerate(points):
        for j, (name, sname) in enumerate((("u", "sigma_u"), ("v", "sigma_v"))):
            ax = fig.add_subplot(len(points), 2, 2 * i + j + 1)
            valid = ds["valid"].values[:, p].astype(bool)
            y = np.where(valid, ds[name].values[:, p], np.nan)
            s = np.where(valid, ds[sname].values[:, p], np.nan)
            ax.fill_between(
                t, y - 2 * s, y + 2 * s, color="#00798c", alpha=0.35, linewidth=0, label="+-2 sigma"
            )
            ax.plot(t, y, color="#30638e", lw=0.9, label=name)
            ax.set_title(
                f"point {p} (row {int(ds['row'].values[p])}, col "
                f"{int(ds['col'].values[p])}): {name}",
                fontsize=9,
            )
            ax.set_xlabel("time (ms)", fontsize=8)
            ax.set_ylabel(f"{name} (px)", fontsize=8)
            ax.tick_params(labelsize=7)
            if i == 0 and j == 0:
                ax.legend(fontsize=7, loc="best")
    fig.subplots_adjust(hspace=0.8, wspace=0.25, left=0.07, right=0.98, top=0.93, bottom=0.08)
    return fig


def worst_frame(ds: Any) -> int:
    """Index (position along ``frame``) of the frame with the largest median sigma."""
    s = np.hypot(ds["sigma_u"].values, ds["sigma_v"].values)
    s = np.where(ds["valid"].values.astype(bool), s, np.nan)
    with np.errstate(invalid="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(s, axis=1)
    return int(np.nanargmax(med)) if np.isfinite(med).any() else 0


def fig_sigma_map(ds: Any, image: Float64Array | None, index: int) -> Any:
    """sigma = hypot(sigma_u, sigma_v) of every valid point at frame position ``index``
    over the reference image."""
    fig, ax = figure_axes(6.4, 5.2)
    if image is not None:
        ax.imshow(image, cmap="gray", interpolation="nearest")
    s = np.hypot(ds["sigma_u"].values[index], ds["sigma_v"].values[index])
    ok = ds["valid"].values[index].astype(bool)
    rows, cols = ds["row"].values, ds["col"].values
    sc = ax.scatter(cols[ok], rows[ok], c=s[ok], s=14, cmap="viridis", marker="s")
    ax.scatter(
        cols[~ok], rows[~ok], s=10, marker="x", color="#d1495b", linewidths=0.8, label="not valid"
    )
    cb = fig.colorbar(sc, ax=ax, fraction=0.046, pad=0.04)
    cb.set_label("sigma (px)")
    ax.set_title(f"predicted sigma at frame {int(ds['frame'].values[index])} (worst)", fontsize=10)
    if (~ok).any():
        ax.legend(fontsize=7, loc="upper right")
    ax.set_xlabel("col (px)")
    ax.set_ylabel("row (px)")
    return fig


def _labelled(fig: Any, ax: Any, xlabel: str, ylabel: str, **margins: float) -> Any:
    """``fig`` with its one axes labelled and the margins of the report's strip figures
    (``margins``: ``subplots_adjust`` keywords that differ from them)."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    fig.subplots_adjust(**{"bottom": 0.17, "left": 0.1, "right": 0.98, "top": 0.95, **margins})
    return fig


def fig_w_histogram(ds: Any) -> Any:
    """Histogram of the blur length W over valid points and frames."""
    fig, ax = figure_axes(6, 3.4)
    w = ds["W"].values[ds["valid"].values.astype(bool)]
    w = w[np.isfinite(w)]
    ax.hist(w, bins=min(60, max(10, int(np.sqrt(w.size)))), color="#edae49")
    return _labelled(
        fig, ax, "W, motion during the exposure (px)", "points x frames", left=0.14, right=0.97
    )


def fig_blur_share(ds: Any) -> Any:
    """Share of the valid points where the blur term exceeds the noise term, per frame."""
    fig, ax = figure_axes(8, 3)
    ax.plot(ds["time"].values * 1e3, 100 * ds["blur_dominated_share"].values, color="#d1495b", lw=1)
    ax.set_ylim(-3, 103)
    return _labelled(fig, ax, "time (ms)", "blur-dominated points (%)", bottom=0.18)


def fig_status(ds: Any) -> Any:
    """Points per status (and normalised-median-test outliers) over time."""
    from ..dic import PointStatus

    fig, ax = figure_axes(8, 3.2)
    t = ds["time"].values * 1e3
    st = ds["status"].values
    for s in PointStatus:
        c = (st == s).sum(axis=1)
        if c.any():
            ax.plot(t, c, lw=1, label=s.name.lower())
    ax.plot(t, ds["n_outliers"].values, lw=1, ls="--", color="k", label="outlier (median test)")
    ax.set_yscale("symlog", linthresh=1)
    ax.legend(fontsize=7, ncol=3, loc="best")
    return _labelled(fig, ax, "time (ms)", "points")


def write_track_report(
    ds: Any,
    folder: Path,
    *,
    image: Float64Array | None = None,
    points: Sequence[int] | None = None,
    title: str = "dicblur track",
) -> Path:
    """Write ``folder/report.html`` (figures also as PNG/SVG in ``folder/figures``).

    Parameters
    ----------
    ds : xarray.Dataset
        The result of :func:`dicblur.track`.
    folder : pathlib.Path
    image : ndarray, optional
        Reference frame, for the sigma map's background.
    points : sequence of int, optional
        Point indices for the time series (default :func:`auto_points`).
    """
    rep = HtmlReport(title=title, folder=Path(folder))
    a = ds.attrs
    valid = ds["valid"].values.astype(bool)
    s = np.hypot(ds["sigma_u"].values, ds["sigma_v"].values)
    rep.section("Summary")
    if not a.get("complete", 1):
        rep.paragraph(
            f"**Incomplete:** {a.get('stop_reason', 'stopped')}; "
            f"{a.get('n_frames_tracked')} frames tracked.",
            css_class="note",
        )
    if "advice_sentence" in a:
        rep.paragraph(str(a["advice_sentence"]), css_class="note")
    rows: list[dict[str, Any]] = [
        {"quantity": "recording", "value": str(a.get("source", ""))},
        {"quantity": "frames tracked", "value": int(ds.sizes["frame"])},
        {"quantity": "points", "value": int(ds.sizes["point"])},
        {"quantity": "exposure (ms)", "value": float(a.get("exposure", np.nan)) * 1e3},
        {"quantity": "frame rate (Hz)", "value": float(a.get("fps", np.nan))},
        {"quantity": "noise (GL)", "value": float(a.get("noise_sigma", np.nan))},
        {"quantity": "matcher", "value": matcher_label(a)},
        {"quantity": "valid point-frames (%)", "value": 100 * float(valid.mean())},
        {
            "quantity": "median sigma (px)",
            "value": float(np.median(s[valid])) if valid.any() else float("nan"),
        },
        {
            "quantity": "largest W (px)",
            "value": float(np.nanmax(ds["W"].values[valid])) if valid.any() else float("nan"),
        },
        {"quantity": "outliers (median test)", "value": int(ds["n_outliers"].values.sum())},
    ]
    rep.table(rows, left=("quantity", "value"))
    if "notes" in a:
        rep.paragraph("Notes: " + str(a["notes"]))
    pts = list(points) if points else auto_points(ds)
    rep.section("Displacement with +-2 sigma")
    rep.figure(
        fig_time_series(ds, pts),
        "time_series",
        "u and v at the plotted points; the band is +-2 predicted sigma (noise and blur terms)",
    )
    rep.section("Sigma map")
    wf = worst_frame(ds)
    rep.figure(
        fig_sigma_map(ds, image, wf),
        "sigma_map",
        "predicted sigma of every valid point at the frame with the largest median "
        "sigma; crosses: not valid (not converged, outlier or no prediction)",
    )
    rep.section("Blur")
    rep.figure(
        fig_w_histogram(ds),
        "w_histogram",
        "blur length W (motion during the exposure, from the local fit of each point's track)",
    )
    rep.figure(
        fig_blur_share(ds),
        "blur_share",
        "share of the valid points whose blur term exceeds their noise term",
    )
    rep.section("Statuses")
    rep.figure(fig_status(ds), "statuses", "points per DIC status and outliers per frame")
    if "sigma_exx" in ds:  # a track with strains (docs/strain.md)
        from .strain import add_strain_section

        add_strain_section(rep, ds)
    return rep.write()
