"""BENCHMARKS.md, generated from ``benchmarks/results/*.json`` so that it cannot drift from them.

Usage::

    python -m benchmarks.report            # rewrite BENCHMARKS.md
    python -m benchmarks.report --check    # exit 1 if BENCHMARKS.md differs from the JSON

Each capability (DIC, blur, track, ...) is one section; each result file one table with its
provenance line (commit, date, machine, load, command). A known file has a small renderer of
its own (``RENDERERS``); a file no renderer knows is drawn by :func:`render_generic` (its
first list of flat records under "cases", "results", "rows", "runs", ...), in the section its
name starts with, or under "Other results": a new benchmark appears without a code change.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
OUT = ROOT / "BENCHMARKS.md"
MAX_LINES = 300
GENERIC_ROWS = 2  # rows of a generic table (the JSON holds the rest)
GENERIC_COLUMNS = 8

Doc = dict[str, Any]
Lines = list[str]

# Sections in order: (title, result-file name prefixes that belong to it). A section shows
# only when a file of it exists; a file of no section goes under "Other results".
SECTIONS: tuple[tuple[str, tuple[str, ...]], ...] = (
    # the default path's screening (issue 26) with the engine: the page stays <= 300 lines
    ("DIC", ("dic", "cold_compile", "subpixel", "trust", "screening")),
    ("Blur", ("blur",)),
    ("Track", ("track",)),
    ("Models", ("models", "noise_term", "large_blur", "coverage", "planning")),
    ("Uncertainty budgets", ("budget",)),
    ("Blur compensation", ("compensat",)),
    ("Strain", ("strain",)),
    ("Stereo", ("stereo",)),
    ("Campaign", ("campaign",)),
    ("Study", ("reproduce", "pulse", "design")),
    ("Start-up and tests", ("startup", "test_suite")),
)


# -- formatting -------------------------------------------------------------------------------


def fmt(x: Any) -> str:
    """A number in 3-4 significant digits, anything else as short text."""
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return f"{x:,}" if abs(x) >= 10_000 else str(x)
    if isinstance(x, float):
        if x != x:
            return "nan"
        a = abs(x)
        if a == 0:
            return "0"
        if a >= 10_000:
            return f"{x:,.0f}"
        if a >= 100:
            return f"{x:.1f}"
        if a >= 0.01:
            return f"{x:.3g}"
        return f"{x:.2e}"
    if x is None:
        return "-"
    if isinstance(x, list | tuple) and len(x) <= 3 and all(isinstance(v, int | float) for v in x):
        return " / ".join(fmt(v) for v in x)
    text = str(x).replace("|", "/").replace("\n", " ")
    return text if len(text) <= 60 else text[:57] + "..."


def table(head: list[str], rows: list[list[Any]]) -> Lines:
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return out


def ratio(a: float | None, b: float | None) -> str:
    if not a or not b:
        return "-"
    return f"{a / b:.2g}x" if a / b < 10 else f"{a / b:.0f}x"


def _load(x: Any) -> str:
    if isinstance(x, list) and x:
        return f"{x[0]:.1f}"
    if isinstance(x, int | float):
        return f"{x:.1f}"
    return "?"


def provenance_line(doc: Doc) -> str:
    """Commit, date, machine (CPU, cores, load) and command of one result file."""
    p = doc.get("provenance") or {}
    m = p.get("machine") or {}
    commit = (p.get("commit") or "?")[:7] + (" (uncommitted changes)" if p.get("dirty") else "")
    date = str(p.get("date_utc") or "?")[:10]
    cpu = m.get("cpu") or m.get("processor") or m.get("platform") or "?"
    load = f"load {_load(p.get('load_start'))} -> {_load(p.get('load_end'))}"
    if p.get("load_end") is None:
        load = f"load {_load(p.get('load_start'))}"
    if p.get("load_start") is None and p.get("load_end") is None:
        load = "load not recorded"
    argv = p.get("argv")
    if isinstance(argv, list):
        argv = " ".join(str(a) for a in argv)
    command = f"`python {argv}`" if argv else "command not recorded"
    return f"{command} · commit {commit} · {date} · {cpu}, {m.get('cpus', '?')} cores, {load}"


# -- renderers of the known files -----------------------------------------------------------


def render_dic(doc: Doc) -> Lines:
    r = doc["results"]
    methods = [("dicblur IC-GN translation", "dicblur_translation")]
    methods += [("dicblur IC-GN affine", "dicblur_affine"), ("OpenCV LK (8-bit)", "opencv_lk")]
    peer = (r.get("opencv_lk") or {}).get("poi_per_s")
    rows = []
    for label, key in methods:
        m = r.get(key)
        if not isinstance(m, dict):
            continue
        rows.append(
            [
                label,
                m.get("poi_per_s"),
                m.get("poi_per_cpu_s_1thread"),
                ratio(m.get("poi_per_s"), peer),
                f"{fmt(m.get('bias_u'))} / {fmt(m.get('bias_v'))}",
                f"{fmt(m.get('std_u'))} / {fmt(m.get('std_v'))}",
                f"{fmt(m.get('norm_std_u'))} / {fmt(m.get('norm_std_v'))}",
            ]
        )
    head = ["method", "POI/s (best, 2 thr)", "POI/CPU-s (1 thr)", "vs OpenCV"]
    head += ["bias u / v (px)", "std u / v (px)", "std / predicted"]
    note = (
        "512^2 speckle, shift (0.3, -0.2) px, noise 2 GL, subset 21, step 10 (2,401 POIs); "
        f"pyvale: {r.get('pyvale')}."
        if isinstance(r.get("pyvale"), str)
        else "512^2 speckle, shift (0.3, -0.2) px, noise 2 GL, subset 21, step 10."
    )
    return [note, "", *table(head, rows)]


def render_dic_peers(doc: Doc) -> Lines:
    head = ["method", "POI/s", "bias u (px)", "std u (px)", "std / predicted", "vs pyvale"]
    rows = [
        [
            c["method"],
            c["poi_per_s"],
            c["bias_u_px"],
            c["std_u_px"],
            c["std_over_predicted_u"],
            f"{c['vs_pyvale_same_shape']:.0f}x",
        ]
        for c in doc["cases"]
    ]
    return [
        "Peers on the same arrays in one run (pyvale `calculate_2d`, OpenCV LK).",
        "",
        *table(head, rows),
    ]


def render_compensation(doc: Doc) -> Lines:
    rows = []
    for r in doc["accuracy"]:
        if r.get("angle") == 0.0 and r.get("blur") == 8.0:
            given = r["u_e_given"]
            rows.append(
                [
                    f"{r['pattern']}, {r['shape']}",
                    r["u_e_plain"],
                    r["u_e_deblur"],
                    given,
                    r["u_e_estimate"],
                    ratio(r["u_e_plain"], given),
                    ratio(r["u_e_deblur"], given),
                ]
            )
    head = ["pattern, shape", "u_e plain", "u_e deblur", "u_e given", "u_e estimate"]
    head += ["plain / given", "deblur / given"]
    return [
        "u_e (px) at W = 8 px, noise 2 GL: the plain matcher, deblur-then-correlate, and the "
        "compensated matcher (`given`, `estimate`), side by side.",
        "",
        *table(head, rows),
    ]


def render_dic_robust(doc: Doc) -> Lines:
    base: dict[str, Any] = {}
    path = RESULTS / "dic_robust_main.json"
    if path.exists():
        base = json.loads(path.read_text())["results"]
    rows = []
    for case, r in doc["results"].items():
        if not isinstance(r, dict):
            continue
        b = (base.get(case) or {}).get("poi_per_cpu_s_1thread")
        rows.append(
            [
                case,
                r["poi_per_cpu_s_1thread"],
                b,
                ratio(r["poi_per_cpu_s_1thread"], b),
                r["wrong_unflagged_fraction"],
                r["flagged_fraction"],
                r["mean_iterations"],
            ]
        )
    head = ["case", "POI/CPU-s (1 thr)", "baseline", "ratio", "wrong, unflagged", "flagged"]
    return [
        "Clean, blob-damaged and fading images; baseline: the previous main "
        "(`dic_robust_main.json`, same run).",
        "",
        *table([*head, "iterations"], rows),
    ]


def render_screening(doc: Doc) -> Lines:
    """One line: the default path's rates on the hostile images, speeds against clean."""
    cases = [c for c in doc["cases"] if c["image"] != "clean"]
    gross = max(c["unflagged_gross_pct"] for c in cases)
    flagged = max(c["flagged_correct_pct"] for c in cases)
    speed = {
        shape: [c["cpu_ratio_to_clean"] for c in cases if c["shape"] == shape]
        for shape in ("affine", "translation")
    }
    # a header-only table (two lines): the page stays within MAX_LINES
    cells = [
        f"blobs, dots, thresholded, {doc['size']}^2, {fmt(doc['noise'])} GL, defaults",
        f"unflagged gross <= {fmt(gross)} %",
        f"correct flagged <= {fmt(flagged)} %",
        *(f"{k} POI/CPU-s vs clean {fmt(min(v))}-{fmt(max(v))}" for k, v in speed.items()),
        # issue 26's absolute targets, on the blob image
        *(
            f"{t['shape']} on blobs {t['poi_per_s'] / 1e3:.0f}k POI/s, "
            f"{t['poi_per_cpu_s'] / 1e3:.0f}k per CPU-s (target {t['target'] / 1e3:.0f}k)"
            for t in doc.get("targets", [])
        ),
    ]
    return ["| " + " | ".join(cells) + " |", "|" + "---|" * len(cells)]


def render_cold_compile(doc: Doc) -> Lines:
    before = {}
    path = RESULTS / "cold_compile_before.json"
    if path.exists():
        before = {c["shape"]: c for c in json.loads(path.read_text())["cold_compile"]}
    rows = [
        [
            c["shape"],
            c["wall_s"],
            c["cpu_s"],
            (before.get(c["shape"]) or {}).get("wall_s"),
            ratio((before.get(c["shape"]) or {}).get("wall_s"), c["wall_s"]),
        ]
        for c in doc["cold_compile"]
    ]
    head = ["shape", "wall s", "CPU s", "before: wall s", "speed-up"]
    return [
        "First `dicblur correlate` of a 512^2 pair with an empty numba cache "
        "(before: `cold_compile_before.json`).",
        "",
        *table(head, rows),
    ]


def render_blur(doc: Doc) -> Lines:
    rows = [
        [
            f"{s['size']}^2",
            s["loop_s"],
            s["fft_s"],
            f"{s['speedup']:.0f}x",
            f"{s['speedup_cpu']:.0f}x",
            s["max_abs_diff_over_range"],
        ]
        for s in doc["speed"]
    ]
    head = ["size", "Algorithm 1 loop s", "motion_blur s", "wall ratio", "CPU ratio"]
    head += ["max diff / grey range"]
    return [
        "Literal Algorithm 1 (K = 100, 101 inverse FFTs) against `motion_blur` (one FFT pair), "
        "side by side; target >= 100x at 1024^2.",
        "",
        *table(head, rows),
    ]


def render_track_speed(doc: Doc) -> Lines:
    rows = [
        [
            s["shape"],
            s["mode"],
            s["workers"],
            s["end_to_end_frames_per_s"],
            s["end_to_end_poi_per_s"],
            s["frames_per_s"],
        ]
        for s in doc["speed"]
    ]
    head = ["shape", "mode", "threads", "frames/s end to end", "POI/s end to end"]
    head += ["frames/s tracking loop"]
    return [
        "1,000 frames of 512^2, subset 21, step 10 (2,401 points), advice included.",
        "",
        *table(head, rows),
    ]


def render_track_vs_main(doc: Doc) -> Lines:
    main = {r["shape"]: r for r in doc["main"]}
    rows = []
    for b in doc["branch"]:
        m = main.get(b["shape"], {})
        fps, base = b["end_to_end_frames_per_s"], m.get("end_to_end_frames_per_s")
        rows.append([b["shape"], fps, base, ratio(fps, base)])
    head = ["shape", "frames/s", f"baseline {doc.get('main_commit', '?')} frames/s", "ratio"]
    return [fmt(doc.get("what", "")) + " (1 thread)", "", *table(head, rows)]


def render_campaign(doc: Doc) -> Lines:
    rows = [
        [
            name,
            r["wall_s"],
            r["setup_s"],
            r["compute_s"],
            r["mean_task_ms"],
            f"{100 * r['overhead_fraction']:.1f}",
        ]
        for name, r in doc["runs"].items()
    ]
    case = doc.get("case", {})
    eff = doc.get("parallel_efficiency")
    head = ["run", "wall s", "setup s", "compute s", "task ms", "overhead %"]
    return [
        f"{case.get('tasks')} tasks, {case.get('size')}^2, subset {case.get('subset')}, "
        f"W {case.get('blur')}; parallel efficiency 1 -> 2 workers "
        f"{fmt(100 * eff) if isinstance(eff, float) else fmt(eff)} %.",
        "",
        *table(head, rows),
    ]


def render_reproduce(doc: Doc) -> Lines:
    rows = []
    for r in doc["runs"]:
        st = {k: v for k, v in r["stages"].items() if k != "total"}
        top = sorted(st, key=st.get, reverse=True)[:3]  # type: ignore[arg-type]
        rows.append([r["mode"], r["wall_s"], r["target_s"], r.get("claims_agree")])
        rows[-1].append(", ".join(f"{k} {st[k]:.1f}" for k in top))
    head = ["mode", "wall s", "target s", "claims agree", "largest stages (s)"]
    return table(head, rows)


def render_pulse(doc: Doc) -> Lines:
    rows = [
        [r["variant"], f"{r['widths']} x {r['trials']}", r["seconds_min"], r["seconds_median"]]
        for r in doc["rows"]
    ]
    return [
        f"1-D Monte Carlo of the paper's Section V; target: {doc.get('target')}.",
        "",
        *table(["variant", "widths x trials", "min s", "median s"], rows),
    ]


def render_startup(doc: Doc) -> Lines:
    targets = {"import dicblur": 0.5, "dicblur --version": 0.4, "dicblur --help": 0.4}
    rows = [
        [
            f"`{c['case']}`",
            c["cpu_median_s"],
            c["wall_median_s"],
            targets.get(c["case"]),
            c.get("modules"),
        ]
        for c in doc["cases"]
    ]
    head = ["case", "CPU s (median)", "wall s (median)", "target s", "modules"]
    return [
        f"Each in a fresh interpreter, median of {doc.get('repeats')}.",
        "",
        *table(head, rows),
    ]


def render_test_suite(doc: Doc) -> Lines:
    rows = [
        [r["case"], f"{r['wall_s'] / 60:.1f}", fmt(r.get("of_which_s")), r["result"]]
        for r in doc["rows"]
    ]
    return [
        "Cold numba cache; the commands are the README's Quickstart, `python -m pytest` and "
        "`.ci/run`.",
        "",
        *table(["run", "wall min", "of which s", "result"], rows),
    ]


def render_track_subpixel_bias(doc: Doc) -> Lines:
    # rms error / sigma of a small vibrating target (u / v), taken apart, and the
    # frame-mean error at sub-pixel offsets against the models' interpolation bias
    case = doc["small_case"]["png folder"]
    cols = ("raw", "minus_bias", "minus_frame_mean", "still_frames")
    cells = [f"{case['u'][c]:.2f} / {case['v'][c]:.2f}" for c in cols]
    shifts = doc["subpixel_shifts"]
    peak = max(abs(r["mean_error_px"]) for r in shifts)
    gap = max(abs(r["mean_error_px"] - r["predicted_interpolation_bias_px"]) for r in shifts)
    head = [
        "error/sigma u / v: raw",
        "minus bias_u/v",
        "minus frame mean",
        "still frames",
        "frame-mean error px (max)",
        "its gap to the predicted bias px",
    ]
    return table(head, [[*cells, f"{peak:.4f}", f"{gap:.4f}"]])


def render_strain(doc: Doc) -> Lines:
    bins: dict[float, dict[str, Any]] = {}
    for b in doc["uniform_bins"]:
        bins.setdefault(b["W_px"], {})[b["field"]] = b["ratio_predicted_to_measured"]
    parts = {
        c["W_px"]: (c["predicted_noise_part"], c["predicted_blur_part"])
        for c in doc["cases"]
        if c["field"] == "uniform" and c["noise_gl"] == 2.0
    }
    rows = [
        [w, v.get("uniform"), v.get("sine"), *(1e6 * x for x in parts.get(w, (None, None)))]
        for w, v in bins.items()
    ]
    n_mean = sum(bool(c["mean_within"]) for c in doc["cases"])
    res = ", ".join(
        f"{r['vsg_px']} px {fmt(r['amplitude_ratio'])}" for r in doc.get("resolution", [])
    )
    sp, tr = doc.get("speed_2401", {}), doc.get("track", {})
    return [
        "Predicted sigma_exx over the measured scatter of the exx error (quadratic means over "
        "the noise levels 1-4 GL), VSG 61 px; the two parts at 2 GL in microstrain.",
        "",
        *table(["W px", "uniform 1e-3", "sinusoid", "noise part", "blur part"], rows),
        "",
        f"Mean error below sigma / sqrt(points) in {n_mean} of {len(doc['cases'])} cases. "
        f"Sinusoid amplitude recovered by VSG: {res}. Strain + covariance of "
        f"{sp.get('points', '-')} points {fmt(sp.get('median_ms'))} ms; track with strains "
        f"{fmt(tr.get('ratio'))}x the time without.",
    ]


def render_stereo(doc: Doc) -> Lines:
    """One header-only table (two lines): predicted/measured 3-D sigma over the W bins,
    the shape, and the speed (docs/stereo.md has the full tables)."""
    bins = [b for c in doc["cases"] for b in c["bins"]]
    r = [b["ratio"] for b in bins]
    hi_w = [b["ratio"] for b in bins if b["W_lo"] >= 4]
    angles = sorted({c["stereo_angle"] for c in doc["cases"]})
    sp = doc.get("speed") or {}
    cells = [
        f"plane, {'/'.join(fmt(a) for a in angles)} deg, in/out-of-plane, peak W ~6 px",
        f"sigma_U/V/W3 pred/meas {fmt(min(r))}-{fmt(max(r))}, "
        f"{sum(0.8 <= x <= 1.2 for x in r)}/{len(r)} bins within 20 %",
        f"W >= 4 px: {fmt(min(hi_w))}-{fmt(max(hi_w))}" if hi_w else "W >= 4 px: -",
        f"{sp.get('size', '-')}^2, {fmt(sp.get('points'))} POIs: "
        f"{fmt(sp.get('pairs_per_s_tracking'))} pairs/s "
        f"(end to end {fmt(sp.get('pairs_per_s_end_to_end'))})",
    ]
    return ["| " + " | ".join(cells) + " |", "|" + "---|" * len(cells)]


def render_stereo_speed(doc: Doc) -> Lines:
    """Two lines: the stereo track's speed (end to end, the loop, per CPU s) and, when a
    baseline ran alongside, the ratios to it and the largest difference of the fields."""
    doc = doc.get("speed") or doc
    cells = [
        f"{doc['size']}^2 x {doc['pairs']} pairs, {fmt(doc['points'])} POIs",
        f"{fmt(doc['pairs_per_s_end_to_end'])} pairs/s end to end, "
        f"{fmt(doc['pairs_per_s_tracking'])} in the loop, {fmt(doc['pairs_per_cpu_s'])} per CPU s",
    ]
    rat = doc.get("ratio_this_over_baseline")
    if rat:
        e2e = "/".join(fmt(x) for x in rat["pairs_per_s_end_to_end"])
        loop = "/".join(fmt(x) for x in rat["pairs_per_s_tracking"])
        diff = max(doc["max_abs_diff_mm"].values())
        cells.append(
            f"vs baseline (side by side): end to end x{e2e}, loop x{loop}; "
            f"fields within {fmt(diff)} mm"
        )
    return ["| " + " | ".join(cells) + " |", "|" + "---|" * len(cells)]


RENDERERS: dict[str, Callable[[Doc], Lines]] = {
    "dic": render_dic,
    "cold_compile": render_cold_compile,
    "dic_robust": render_dic_robust,
    "screening": render_screening,
    "dic_peers": render_dic_peers,
    "compensation": render_compensation,
    "blur": render_blur,
    "track_speed": render_track_speed,
    "track_speed_vs_main": render_track_vs_main,
    "track_subpixel_bias": render_track_subpixel_bias,
    "campaign": render_campaign,
    "reproduce": render_reproduce,
    "pulse": render_pulse,
    "startup": render_startup,
    "test_suite": render_test_suite,
    "strain": render_strain,
    "stereo": render_stereo,
    "stereo_speed": render_stereo_speed,
}
#: Files that are inputs of another file's table, not tables of their own.
PARTS = {"cold_compile_before", "dic_robust_main"}


# -- the generic renderer ------------------------------------------------------------------


def _flat(rec: dict[str, Any]) -> dict[str, Any]:
    """``rec`` with its nested dicts of scalars one level up (``coverage.alpha``)."""
    out: dict[str, Any] = {}
    for k, v in rec.items():
        if isinstance(v, dict):
            out.update({f"{k}.{s}": x for s, x in v.items() if _scalar(x)})
        else:
            out[k] = v
    return out


def _records(doc: Any, depth: int = 0) -> tuple[str, list[dict[str, Any]]] | None:
    """The first list of records in ``doc`` (a list of dicts, or a dict of dicts keyed by
    name): preferred keys first, then any, two levels deep."""
    if not isinstance(doc, dict) or depth > 2:
        return None
    preferred = ("cases", "results", "rows", "runs", "speed", "patterns")
    keys = [k for k in preferred if k in doc] + [k for k in doc if k not in preferred]
    keys = [k for k in keys if k != "provenance"]
    for k in keys:
        v = doc[k]
        if isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            return k, [_flat(x) for x in v]
        if isinstance(v, dict) and v and all(isinstance(x, dict) for x in v.values()):
            if any(_scalar(y) for x in v.values() for y in x.values()):
                return k, [{"name": n, **_flat(x)} for n, x in v.items()]
    for k in keys:
        if (found := _records(doc[k], depth + 1)) is not None:
            return f"{k}.{found[0]}", found[1]
    return None


#: Fields that repeat the provenance line.
IDENTITY = {"commit", "version", "machine", "command", "dicblur", "dicblur_version", "python"}


def _scalar(v: Any) -> bool:
    return (
        v is None
        or isinstance(v, str | int | float | bool)
        or (isinstance(v, list) and len(v) <= 3 and all(isinstance(x, int | float) for x in v))
    )


def render_generic(doc: Doc) -> Lines:
    """A table of the file's first list of flat records, or its top-level numbers."""
    found = _records(doc)
    if found is None:
        flat = _flat({k: v for k, v in doc.items() if k != "provenance" and k not in IDENTITY})
        items = [(k, v) for k, v in flat.items() if _scalar(v)]
        return table(["field", "value"], [[k, v] for k, v in items[:GENERIC_ROWS]])
    recs = found[1]
    cols: list[str] = []
    for rec in recs:
        cols += [k for k, v in rec.items() if _scalar(v) and k not in cols]
    cols = cols[:GENERIC_COLUMNS]
    rows = [[rec.get(c) for c in cols] for rec in recs[:GENERIC_ROWS]]
    # the first rows only (the page stays <= 300 lines); the intro says the JSON has the rest
    return table(cols, rows)


# -- the document ---------------------------------------------------------------------------


def section_of(name: str) -> str:
    for title, prefixes in SECTIONS:
        if name.startswith(prefixes):
            return title
    return "Other results"


def render(results: Path = RESULTS) -> str:
    """The whole of BENCHMARKS.md from the result files in ``results``."""
    by_section: dict[str, list[str]] = {}
    for path in sorted(results.glob("*.json")):
        if path.stem not in PARTS:
            by_section.setdefault(section_of(path.stem), []).append(path.stem)
    out = [
        "# Benchmarks",
        "",
        "The current state, generated from `benchmarks/results/*.json` by `python -m",
        "benchmarks.report` (never edit by hand). Each table is one result file with its",
        "command, commit, date, machine and load; peers and baselines ran side by side, on shared",
        "2-core machines (ratios compare). A file without its own renderer shows its first rows.",
    ]
    titles = [t for t, _ in SECTIONS] + ["Other results"]
    for title in titles:
        if title not in by_section:
            continue
        out += ["", f"## {title}"]
        for stem in by_section[title]:
            doc = json.loads((results / f"{stem}.json").read_text())
            renderer = RENDERERS.get(stem, render_generic)
            try:
                body = renderer(doc)
            except (KeyError, TypeError, ValueError, AttributeError):  # a layout that changed
                body = render_generic(doc)
            # No blank line before a heading: it ends the table above (and keeps the file short).
            head = [f"### {stem}", provenance_line(doc)]
            if len(body) > 2 and not body[0].startswith("|") and body[1] == "":
                head[-1] += " \\"  # a note on the table: one paragraph with the provenance
                head.append(body[0])
                body = body[2:]
            out += [*head, "", *body]
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if BENCHMARKS.md is stale")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        if not OUT.exists() or OUT.read_text() != text:
            print("BENCHMARKS.md differs from benchmarks/results: run python -m benchmarks.report")
            return 1
        return 0
    OUT.write_text(text)
    n = text.count("\n")
    print(f"wrote {OUT.relative_to(ROOT)} ({n} lines)")
    if n > MAX_LINES:
        print(f"warning: {n} lines > {MAX_LINES}: trim a generic table or drop a stale file")
    return 0


if __name__ == "__main__":
    sys.exit(main())
