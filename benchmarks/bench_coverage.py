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
import time
from pathlib import Path

import numpy as np
from _harness import Run, use_tests_dir

use_tests_dir()
from helpers.models import COVERAGE_MODELS as MODELS  # noqa: E402
from helpers.models import interval_coverage  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "coverage.json"
OUT_ONLY = Path(__file__).resolve().parent / "results" / "coverage_{}.json"


def run(n: int, models: tuple[str, ...] = MODELS) -> dict:
    out: dict = {}
    for which in models:
        t0 = time.perf_counter()
        # the data sets of tests/test_models_trust.py and test_models_static.py, other seeds
        res = interval_coverage(which, n, first_seed=20_000)
        cov = res["coverage"]
        # binomial standard error of a 95 % coverage estimate
        out[which] = {
            "coverage": cov,
            "ci_methods": res["ci_methods"],
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
    bench = Run("coverage")
    res = run(args.n, tuple(args.only))
    print(f"{'model':16s} {'parameter':9s} {'coverage':>9s}  ci methods")
    for which, r in res.items():
        for name, c in r["coverage"].items():
            print(f"{which:16s} {name:9s} {100 * c:8.1f}%  {r['ci_methods']}")
    print(f"(binomial se at 95 %: {100 * next(iter(res.values()))['se_at_95']:.1f} %)")
    out = OUT if set(args.only) == set(MODELS) else Path(str(OUT_ONLY).format("_".join(args.only)))
    print(f"wrote {bench.write({'results': res}, out)}")


if __name__ == "__main__":
    main()
