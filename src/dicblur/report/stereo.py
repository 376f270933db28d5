"""The HTML report of a stereo track (``dicblur stereo track``, docs/stereo.md): the
shape in 3-D coloured by the displacement, sigma over time, blur of each camera."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..arrays import Float64Array
from ._figure import figure, figure_axes
from .html import HtmlReport

__all__ = [
    "fig_predicted_measured",
    "fig_shape_3d",
    "fig_sigma_time",
    "write_stereo_report",
    "write_validation_report",
]


def _largest_frame(ds: Any) -> int:
    """Frame position of the largest median |displacement| of the valid points."""
    mag = np.sqrt(ds["U"].values ** 2 + ds["V"].values ** 2 + ds["W3"].values ** 2)
    mag = np.where(ds["valid"].values.astype(bool), mag, np.nan)
    with np.errstate(all="ignore"):
        med = np.nanmedian(np.where(np.isfinite(mag), mag, np.nan), axis=1)
    med = np.where(np.isfinite(med), med, -1.0)
    return int(np.argmax(med))


def fig_shape_3d(ds: Any, index: int | None = None) -> Any:
    """The reference shape (X, Y, Z, mm) as a 3-D scatter coloured by |U, V, W3| at frame
    position ``index`` (default: the largest displacement)."""
    k = _largest_frame(ds) if index is None else index
    fig, ax = figure_axes(6.8, 5.4, projection="3d")
    x, y, z = ds["X"].values, ds["Y"].values, ds["Z"].values
    mag = np.sqrt(ds["U"].values[k] ** 2 + ds["V"].values[k] ** 2 + ds["W3"].values[k] ** 2)
    ok = ds["valid"].values[k].astype(bool) & np.isfinite(mag)
    sc = ax.scatter(x[ok], z[ok], -y[ok], c=mag[ok], s=6, cmap="viridis")
    bad = ~ok & np.isfinite(x)
    if bad.any():
        ax.scatter(x[bad], z[bad], -y[bad], s=6, marker="x", color="#d1495b", label="not valid")
        ax.legend(fontsize=7)
    cb = fig.colorbar(sc, ax=ax, fraction=0.04, pad=0.1)
    cb.set_label("|displacement| (mm)")
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Z (mm)")
    ax.set_zlabel("-Y (mm)")
    ax.set_title(f"shape and displacement at frame {int(ds['frame'].values[k])}", fontsize=10)
    return fig


def fig_sigma_time(ds: Any) -> Any:
    """Median predicted sigma_U, sigma_V, sigma_W3 of the valid points, and the median blur
    of each camera, per frame."""
    fig = figure(7.0, 5.0)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    t = ds["time"].values * 1e3
    valid = ds["valid"].values.astype(bool)
    for name in ("sigma_U", "sigma_V", "sigma_W3"):
        v = np.where(valid, ds[name].values, np.nan)
        with np.errstate(all="ignore"):
            med = np.nanmedian(np.where(np.isfinite(v), v, np.nan), axis=1)
        ax1.plot(t, med * 1e3, label=name)
    ax1.set_ylabel("median sigma (um)")
    ax1.legend(fontsize=7)
    for name in ("W_left", "W_right"):
        v = np.where(valid, ds[name].values, np.nan)
        with np.errstate(all="ignore"):
            ax2.plot(t, np.nanmedian(v, axis=1), label=name)
    ax2.set_ylabel("median blur W (px)")
    ax2.set_xlabel("time (ms)")
    ax2.legend(fontsize=7)
    return fig


def fig_predicted_measured(rows: list[dict[str, Any]]) -> Any:
    """Predicted against measured sigma (mm) of the benchmark's bins, one marker per
    component; rows hold ``component``, ``predicted``, ``measured``."""
    fig, ax = figure_axes(5.0, 4.6)
    lim = [np.inf, 0.0]
    for comp, marker in (("U", "o"), ("V", "s"), ("W3", "^")):
        p = np.array([r["predicted"] for r in rows if r["component"] == comp], float)
        m = np.array([r["measured"] for r in rows if r["component"] == comp], float)
        if p.size:
            ax.loglog(m, p, marker, label=f"sigma_{comp}", alpha=0.8)
            lim = [min(lim[0], p.min(), m.min()), max(lim[1], p.max(), m.max())]
    if np.isfinite(lim[0]):
        a = np.array([lim[0] / 1.3, lim[1] * 1.3])
        ax.plot(a, a, "k-", lw=0.8)
        ax.fill_between(a, a * 0.8, a * 1.2, color="0.85", label="+-20 %")
    ax.set_xlabel("measured scatter (mm)")
    ax.set_ylabel("predicted sigma (mm)")
    ax.legend(fontsize=7)
    return fig


def write_stereo_report(
    ds: Any,
    folder: Path,
    *,
    image: Float64Array | None = None,
    title: str = "dicblur stereo track",
) -> Path:
    """Write ``folder/report.html`` (figures also as PNG/SVG in ``folder/figures``)."""
    rep = HtmlReport(title=title, folder=Path(folder))
    a = ds.attrs
    valid = ds["valid"].values.astype(bool)

    def med(name: str) -> float:
        v = ds[name].values[valid]
        return float(np.median(v)) if v.size else float("nan")

    rep.section("Summary")
    rows: list[dict[str, Any]] = [
        {"quantity": "left recording", "value": str(a.get("source_left", ""))},
        {"quantity": "right recording", "value": str(a.get("source_right", ""))},
        {"quantity": "frame pairs", "value": int(ds.sizes["frame"])},
        {"quantity": "points", "value": int(ds.sizes["point"])},
        {"quantity": "stereo angle (deg)", "value": float(a.get("stereo_angle_deg", np.nan))},
        {"quantity": "baseline (mm)", "value": float(a.get("baseline_mm", np.nan))},
        {"quantity": "exposure (ms)", "value": float(a.get("exposure", np.nan)) * 1e3},
        {"quantity": "frame rate (Hz)", "value": float(a.get("fps", np.nan))},
        {
            "quantity": "stereo-matched points (%)",
            "value": 100 * float((ds["status_stereo"].values == 0).mean()),
        },
        {"quantity": "valid point-frames (%)", "value": 100 * float(valid.mean())},
        {"quantity": "median sigma_U (um)", "value": 1e3 * med("sigma_U")},
        {"quantity": "median sigma_V (um)", "value": 1e3 * med("sigma_V")},
        {"quantity": "median sigma_W3 (um)", "value": 1e3 * med("sigma_W3")},
    ]
    rep.table(rows, left=("quantity", "value"))
    rep.paragraph(f"Frame of reference: {a.get('frame_of_reference', 'left camera')}.")
    rep.section("Shape and displacement")
    rep.figure(
        fig_shape_3d(ds),
        "shape_3d",
        "the triangulated shape of the reference pair, coloured by the 3-D displacement at the "
        "frame of the largest one; crosses: not valid",
    )
    rep.section("Uncertainty and blur")
    rep.figure(
        fig_sigma_time(ds),
        "sigma_time",
        "median predicted sigma of the 3-D displacement (noise and both cameras' blur "
        "propagated through the triangulation) and each camera's median blur",
    )
    if image is not None:
        rep.paragraph("Left reference image size: " + "x".join(str(s) for s in image.shape))
    return rep.write()


def write_validation_report(
    doc: dict[str, Any], folder: Path, *, title: str = "dicblur stereo validation"
) -> Path:
    """``folder/report.html`` of a ``benchmarks/bench_stereo.py`` result (its JSON as a
    dict: ``cases`` with their ``bins``): predicted against measured sigma of every W bin
    (:func:`fig_predicted_measured`, also as PNG/SVG in ``folder/figures``) and the table
    of the bins."""
    rep = HtmlReport(title=title, folder=Path(folder))
    cases = list(doc.get("cases", []))
    rows = [
        {**b, "stereo_angle": c["stereo_angle"], "motion": c["motion"]}
        for c in cases
        for b in c.get("bins", [])
    ]
    ratios = [r["ratio"] for r in rows]
    rep.section("Predicted against measured 3-D sigma")
    if ratios:
        inside = sum(0.8 <= x <= 1.2 for x in ratios)
        rep.paragraph(
            f"{len(ratios)} (angle, motion, W bin, component) cells: predicted / measured "
            f"{min(ratios):.2f}-{max(ratios):.2f}, {inside} within 20 %."
        )
    rep.figure(
        fig_predicted_measured(rows),
        "predicted_measured",
        "predicted sigma_U, sigma_V, sigma_W3 (RMS over a W bin's points) against the measured "
        "scatter about each frame's mean, one marker per bin; the band is +-20 %",
    )
    table = [
        {
            "angle (deg)": r["stereo_angle"],
            "motion": r["motion"],
            "W bin (px)": f"{r['W_lo']:g}-{r['W_hi']:g}",
            "component": r["component"],
            "predicted (um)": 1e3 * r["predicted"],
            "measured (um)": 1e3 * r["measured"],
            "ratio": r["ratio"],
        }
        for r in rows
    ]
    if table:
        rep.table(table, left=("motion", "W bin (px)", "component"))
    return rep.write()
