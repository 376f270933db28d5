"""Benchmark: coverage of the fitted-parameter intervals (issue 14, docs/models.md s. 5).

Over N synthetic data sets per model with known parameters, the fraction of 95 % intervals
that contain the truth, for every parameter of every model:

- power law (eq. 17 around SSSIG_0): ``u_ref``, ``alpha``; 13 points over W = 0..3 px,
  5 % log-normal scatter in u_e and 1 % in SSSIG;
- SSSIG decay (eq. 18): ``sssig0``, ``beta``; 17 points over W = 0..8 px, additive 2 %
  scatter;
- noise + blur-mismatch model without the cross term: ``a``, ``c`` (one noise level,
  13 points, 5 % log scatter);
- with floor and cross term: ``a``, ``floor``, ``cross``, ``c`` (noise 2 and 8 GL, 26
  points, 5 % log scatter);
- the static kind (:func:`dicblur.models.fit_static_scales`): ``k_noise``, ``k_blur`` on
  a tabulated static prediction (W = 0..8 px step 0.25, noise variance ~ 1/SSSIG, a
  noise-free variance ``(c W^2)^2`` plus a sub-pixel bias swinging with ``W/2 mod 1``);
  noise 2 and 8 GL, 26 points over W = 0..6 px, 5 % log scatter.

Target: 90-99 % for every parameter. Also records how often the degenerate-covariance
fallback (seeded bootstrap) was used. Writes ``benchmarks/results/coverage.json``.

Run: ``NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_coverage.py [--n 200] [--only static]``
(``--only``: those models, written to ``results/coverage_<models>.json``)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

import dicblur
from dicblur.models import (
    StaticTerms,
    fit_mismatch,
    fit_power_law,
    fit_sssig_decay,
    fit_static_scales,
    mismatch_model,
    sssig_decay,
)

OUT = Path(__file__).resolve().parent / "results" / "coverage.json"
OUT_ONLY = Path(__file__).resolve().parent / "results" / "coverage_{}.json"
S0, BETA = 2.4e6, 0.03


def static_table() -> StaticTerms:
    """A static-prediction table with the shapes of a real one (module docstring)."""
    w = np.round(np.arange(0.0, 8.001, 0.25), 10)
    s = sssig_decay(w, S0, BETA)
    off = (w / 2) % 1.0
    return StaticTerms(
        blur=tuple(w),
        noise=tuple(1.6 / s),
        noise2=tuple(2e-10 * (1 + 0.1 * w**2) * S0 / s**2),
        mismatch=tuple((9e-4 * w**2) ** 2 + (1e-3 * np.sin(np.pi * off)) ** 2),
        valid_fraction=tuple(np.ones(w.size)),
        breakdown_blur=None,
    )


def case(which: str, seed: int):
    rng = np.random.default_rng(20_000 + seed)
    if which == "static":
        terms = static_table()
        w1 = np.arange(0.0, 6.01, 0.5)
        w, sig = np.tile(w1, 2), np.repeat([2.0, 8.0], w1.size)
        x = np.array(terms.blur)
        n1, n2, b2 = (
            np.interp(w, x, np.array(v)) for v in (terms.noise, terms.noise2, terms.mismatch)
        )
        truth = {"k_noise": 0.95, "k_blur": 1.05}
        u = np.sqrt(0.95**2 * (sig**2 * n1 + sig**4 * n2) + 1.05**2 * b2)
        u = u * np.exp(rng.normal(0, 0.05, w.size))
        return truth, fit_static_scales(terms, w, sig, u)
    if which == "power_law":
        w = np.arange(0.0, 3.01, 0.25)
        s = sssig_decay(w, S0, BETA) * np.exp(rng.normal(0, 0.01, w.size))
        truth = {"u_ref": 2e-3, "alpha": 2.7}
        u = 2e-3 * (s / S0) ** -2.7 * np.exp(rng.normal(0, 0.05, w.size))
        return truth, fit_power_law(s, u, blur=w, sssig_ref=S0)
    if which == "decay":
        w = np.arange(0.0, 8.01, 0.5)
        s = sssig_decay(w, S0, BETA) + rng.normal(0, 0.02 * S0, w.size)
        return {"sssig0": S0, "beta": BETA}, fit_sssig_decay(w, s)
    if which == "mismatch":
        w = np.arange(0.0, 6.01, 0.5)
        s = sssig_decay(w, S0, BETA)
        truth = {"a": 2.0, "c": 3e-4}
        u = mismatch_model(w, s, 2.0, **truth) * np.exp(rng.normal(0, 0.05, w.size))
        return truth, fit_mismatch(
            w, s, u, noise_sigma=2.0, next_term=False, floor=False, noise_blur=False, cross=False
        )
    w1 = np.arange(0.0, 6.01, 0.5)
    w, sig = np.tile(w1, 2), np.repeat([2.0, 8.0], w1.size)
    s = sssig_decay(w, S0, BETA)
    truth = {"a": 1.4, "floor": 1e-3, "cross": 1e-3, "c": 3e-4}
    u = mismatch_model(w, s, sig, **truth) * np.exp(rng.normal(0, 0.05, w.size))
    return truth, fit_mismatch(
        w, s, u, noise_sigma=sig, next_term=False, floor=True, noise_blur=False, cross=True
    )


MODELS = ("power_law", "decay", "mismatch", "mismatch_cross", "static")


def run(n: int, models: tuple[str, ...] = MODELS) -> dict:
    out: dict = {}
    for which in models:
        t0 = time.perf_counter()
        hits: dict[str, int] = {}
        methods: dict[str, int] = {}
        for seed in range(n):
            truth, fit = case(which, seed)
            methods[fit.ci_method] = methods.get(fit.ci_method, 0) + 1
            for name, value in truth.items():
                p = fit.parameter(name)
                hits[name] = hits.get(name, 0) + int(p.low <= value <= p.high)
        cov = {k: v / n for k, v in hits.items()}
        # binomial standard error of a 95 % coverage estimate
        out[which] = {
            "coverage": cov,
            "ci_methods": methods,
            "n": n,
            "se_at_95": float(np.sqrt(0.95 * 0.05 / n)),
            "ok": all(0.90 <= c <= 0.99 for c in cov.values()),
            "time_s": time.perf_counter() - t0,
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="data sets per model (>= 50)")
    ap.add_argument("--only", nargs="+", choices=MODELS, default=list(MODELS))
    args = ap.parse_args()
    res = run(args.n, tuple(args.only))
    print(f"{'model':16s} {'parameter':9s} {'coverage':>9s}  ci methods")
    for which, r in res.items():
        for name, c in r["coverage"].items():
            print(f"{which:16s} {name:9s} {100 * c:8.1f}%  {r['ci_methods']}")
    print(f"(binomial se at 95 %: {100 * next(iter(res.values()))['se_at_95']:.1f} %)")
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            cwd=Path(__file__).parent,
            check=False,
        ).stdout.strip()
    except OSError:
        commit = None
    doc = {
        "results": res,
        "commit": commit,
        "version": dicblur.__version__,
        "machine": {
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "load": os.getloadavg(),
            "platform": platform.platform(),
        },
    }
    out = OUT if set(args.only) == set(MODELS) else Path(str(OUT_ONLY).format("_".join(args.only)))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
