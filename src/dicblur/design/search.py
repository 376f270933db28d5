"""Search the pattern family: coarse campaign sweep, local refinement, confirmation.

1. Coarse sweep: every member of the family's grid gets a campaign and a blur-model fit
   (:func:`~dicblur.design.evaluate_candidate`); these give the maps of u_ref, MBRF and
   predicted u_e (the generalisation of the paper's Fig. 11). With ``screen=n`` the grid
   is first ranked by the static surrogate (no DIC) and only its ``n`` best members get
   campaigns (the maps then have holes).
2. Refinement: bounded Nelder-Mead (:func:`scipy.optimize.minimize`) on the logarithm of
   the predicted u_e, in unit coordinates of the family (log speckle size, density,
   softness), started at the best grid member with a simplex of half the grid spacing,
   at most ``max_refine`` new campaigns. Candidates already evaluated are not re-run.
3. Confirmation: the best candidate, the default pattern (speckle_pattern defaults) and
   the worst grid member are measured again on fresh pattern seeds and a fresh noise seed
   (``confirm_realisations`` each), directly at the design blurs (no model): the measured
   u_e with its standard error and the paired improvement.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from .evaluate import (
    Evaluation,
    campaign_spec,
    evaluate_candidate,
    measure_candidate,
    pattern_seeds,
    screen_candidate,
)
from .family import DEFAULT_CANDIDATE, Candidate, PatternFamily
from .problem import DesignProblem

__all__ = ["Confirmation", "DesignResult", "confirm", "design_pattern"]

logger = logging.getLogger("dicblur")

Progress = Callable[[str, int, Evaluation], None]


@dataclass(frozen=True)
class Confirmation:
    """Measured u_e (px) of a few candidates on fresh seeds, at the design blurs.

    Attributes
    ----------
    labels : tuple of str
        ``"best"``, ``"default"``, ``"worst"``.
    candidates : tuple of Candidate
    u_e : tuple of tuple of tuple of float
        ``u_e[k][r][j]``: candidate k, realisation r, design blur j (px).
    objective : tuple of tuple of float
        Per candidate and realisation, the weighted mean over the design blurs (px).
    seeds : tuple of int
        Fresh pattern seeds; ``base_seed`` the fresh noise base seed.
    base_seed : int
    n_points : int
        Campaign tasks used.
    """

    labels: tuple[str, ...]
    candidates: tuple[Candidate, ...]
    u_e: tuple[tuple[tuple[float, ...], ...], ...]
    objective: tuple[tuple[float, ...], ...]
    seeds: tuple[int, ...]
    base_seed: int
    n_points: int

    def _index(self, label: str) -> int:
        try:
            return self.labels.index(label)
        except ValueError:
            raise InputError(f"label={label!r}: not confirmed; one of {self.labels}") from None

    def mean(self, label: str) -> float:
        """Mean measured objective (px) over the fresh realisations."""
        return float(np.mean(self.objective[self._index(label)]))

    def stderr(self, label: str) -> float:
        """Standard error (px) of :meth:`mean`."""
        v = np.asarray(self.objective[self._index(label)])
        return float(np.std(v, ddof=1) / math.sqrt(v.size)) if v.size > 1 else float("nan")

    def difference(self, a: str, b: str) -> tuple[float, float]:
        """Paired difference ``b - a`` (px) over the shared realisations, and its standard
        error (same pattern seeds and noise seeds: a paired comparison)."""
        d = np.asarray(self.objective[self._index(b)]) - np.asarray(self.objective[self._index(a)])
        se = float(np.std(d, ddof=1) / math.sqrt(d.size)) if d.size > 1 else float("nan")
        return float(np.mean(d)), se

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict with per-label mean and standard error."""
        return {
            "labels": list(self.labels),
            "candidates": [c.to_dict() for c in self.candidates],
            "u_e": [[list(r) for r in k] for k in self.u_e],
            "objective": [list(k) for k in self.objective],
            "mean": {lab: self.mean(lab) for lab in self.labels},
            "stderr": {lab: self.stderr(lab) for lab in self.labels},
            "seeds": list(self.seeds),
            "base_seed": self.base_seed,
            "n_points": self.n_points,
        }


@dataclass(frozen=True)
class DesignResult:
    """Outcome of :func:`design_pattern`.

    Attributes
    ----------
    problem : DesignProblem
    family : PatternFamily
    evaluations : tuple of Evaluation
        Every campaign of the search, in order (grid, then refinement).
    reference : Evaluation
        The default pattern (speckle_pattern defaults), evaluated like the others.
    best, worst : Evaluation
        Lowest predicted u_e over all evaluations; highest over the grid.
    confirmation : Confirmation or None
    n_campaigns : int
        Campaigns run (search + reference + confirmation, one per candidate and stage).
    n_points : int
        Campaign tasks (DIC runs) in total.
    wall_s : float
    """

    problem: DesignProblem
    family: PatternFamily
    evaluations: tuple[Evaluation, ...]
    reference: Evaluation
    best: Evaluation
    worst: Evaluation
    confirmation: Confirmation | None
    n_campaigns: int
    n_points: int
    wall_s: float
    settings: dict[str, Any] = field(default_factory=dict)
    screened: tuple[tuple[Candidate, float], ...] = ()

    @property
    def grid(self) -> tuple[Evaluation, ...]:
        return tuple(e for e in self.evaluations if e.stage == "grid")

    def ranking(self) -> list[Evaluation]:
        """All search evaluations, best (lowest predicted u_e) first."""
        return sorted(self.evaluations, key=lambda e: e.objective)

    def summary(self) -> dict[str, Any]:
        """Headline numbers (JSON-ready)."""
        d: dict[str, Any] = {
            "target": self.problem.describe_target(),
            "best": self.best.candidate.to_dict(),
            "best_predicted_u_e": self.best.objective,
            "default_predicted_u_e": self.reference.objective,
            "worst": self.worst.candidate.to_dict(),
            "worst_predicted_u_e": self.worst.objective,
            "n_campaigns": self.n_campaigns,
            "n_points": self.n_points,
            "n_grid": len(self.grid),
            "n_screened": len(self.screened),
            "n_refine": sum(e.stage == "refine" for e in self.evaluations),
            "wall_s": self.wall_s,
        }
        if self.confirmation is not None:
            c = self.confirmation
            d["best_measured_u_e"] = c.mean("best")
            d["best_measured_stderr"] = c.stderr("best")
            d["default_measured_u_e"] = c.mean("default")
            d["default_measured_stderr"] = c.stderr("default")
            d["worst_measured_u_e"] = c.mean("worst")
            d["worst_measured_stderr"] = c.stderr("worst")
            diff, se = c.difference("best", "default")
            d["gain_vs_default"] = diff / c.mean("default")
            d["gain_vs_default_px"] = diff
            d["gain_vs_default_stderr_px"] = se
            diff_w, se_w = c.difference("best", "worst")
            d["gain_vs_worst"] = diff_w / c.mean("worst")
            d["gain_vs_worst_px"] = diff_w
            d["gain_vs_worst_stderr_px"] = se_w
        return d

    def to_dict(self) -> dict[str, Any]:
        """Everything (JSON-ready)."""
        return {
            "problem": self.problem.to_dict(),
            "family": self.family.to_dict(),
            "summary": self.summary(),
            "settings": dict(self.settings),
            "reference": self.reference.to_dict(),
            "evaluations": [e.to_dict() for e in self.evaluations],
            "confirmation": None if self.confirmation is None else self.confirmation.to_dict(),
            "screened": [{**c.to_dict(), "surrogate": s} for c, s in self.screened],
        }


def confirm(
    candidates: dict[str, Candidate], problem: DesignProblem, *, realisations: int = 8
) -> Confirmation:
    """Measure candidates on fresh seeds at the design blurs (see module docs, step 3)."""
    if isinstance(realisations, bool) or not isinstance(realisations, int) or realisations < 2:
        raise InputError(
            f"confirm_realisations={realisations!r}: need an integer >= 2 "
            "(a standard error needs two realisations)"
        )
    seeds = pattern_seeds(problem.seed, realisations, fresh=True)
    base = int(np.random.SeedSequence(problem.seed, spawn_key=(2,)).generate_state(1)[0])
    # Distinct design blurs only (a campaign's W values must be distinct).
    w_unique, inverse = np.unique(problem.blur_array, return_inverse=True)
    weights = problem.weight_array
    u_all, obj_all = [], []
    n_points = 0
    for cand in candidates.values():
        spec = campaign_spec(
            cand, problem, blurs=[float(v) for v in w_unique], seeds=seeds, base_seed=base
        )
        m = measure_candidate(spec)
        u = m["u_e"][:, inverse]  # (realisation, design blur)
        n_points += int(m["u_e"].size)
        u_all.append(tuple(tuple(map(float, r)) for r in u))
        obj_all.append(tuple(float(np.dot(weights, r)) for r in u))
    return Confirmation(
        labels=tuple(candidates),
        candidates=tuple(candidates.values()),
        u_e=tuple(u_all),
        objective=tuple(obj_all),
        seeds=tuple(seeds),
        base_seed=base,
        n_points=n_points,
    )


def design_pattern(
    problem: DesignProblem,
    family: PatternFamily | None = None,
    *,
    max_refine: int = 20,
    confirm_realisations: int = 8,
    screen: int | None = None,
    progress: Progress | None = None,
) -> DesignResult:
    """Find the member of ``family`` with the lowest predicted u_e at the design blur.

    Parameters
    ----------
    problem : DesignProblem
        From :func:`dicblur.design.design_problem`.
    family : PatternFamily, optional
        Default: :meth:`PatternFamily.for_subset` of the problem's subset.
    max_refine : int
        Most campaigns of the local refinement (0: grid only).
    confirm_realisations : int
        Fresh realisations of the confirmation run (0: no confirmation).
    screen : int, optional
        Run campaigns only for the ``screen`` grid members with the best static surrogate
        (plus the surrogate's worst member, for the comparison). Default: the whole grid.
    progress : callable, optional
        ``progress(stage, index, evaluation)`` after every campaign.

    Returns
    -------
    DesignResult
    """
    from scipy import optimize

    family = PatternFamily.for_subset(problem.subset) if family is None else family
    if isinstance(max_refine, bool) or not isinstance(max_refine, int) or max_refine < 0:
        raise InputError(f"max_refine={max_refine!r}: expected an integer >= 0")
    if confirm_realisations != 0 and (
        not isinstance(confirm_realisations, int) or confirm_realisations < 2
    ):
        raise InputError(
            f"confirm_realisations={confirm_realisations!r}: 0 (no confirmation) or an integer >= 2"
        )
    t0 = time.perf_counter()
    cache: dict[tuple[float, float, float], Evaluation] = {}
    evaluations: list[Evaluation] = []

    def run(c: Candidate, stage: str) -> Evaluation:
        key = c.key()
        if key not in cache:
            e = evaluate_candidate(c, problem, stage=stage)
            cache[key] = e
            evaluations.append(e)
            logger.info(
                "design %s %d: %s -> %.5f px", stage, len(evaluations), c.label(), e.objective
            )
            if progress is not None:
                progress(stage, len(evaluations), e)
        return cache[key]

    candidates = family.grid_candidates()
    screened: list[tuple[Candidate, float]] = []
    if screen is not None:
        if isinstance(screen, bool) or not isinstance(screen, int) or screen < 1:
            raise InputError(
                f"screen={screen!r}: expected an integer >= 1 (grid members "
                "to measure) or None (all)"
            )
        screened = [(c, screen_candidate(c, problem)) for c in candidates]
        order = sorted(range(len(candidates)), key=lambda i: screened[i][1])
        candidates = [candidates[i] for i in sorted(order[:screen])]
    for c in candidates:
        run(c, "grid")
    grid = list(evaluations)
    best_grid = min(grid, key=lambda e: e.objective)
    free = [i for i, f in enumerate(family.free) if f]
    if max_refine > 0 and free:
        z0 = family.to_unit(best_grid.candidate)
        spacing = np.array([0.5 / max(n - 1, 1) for n in family.grid])
        budget = {"left": max_refine}

        def f(zf: np.ndarray) -> float:
            z = z0.copy()
            z[free] = zf
            c = family.from_unit(z)
            if c.key() not in cache:
                if budget["left"] <= 0:
                    return math.inf
                budget["left"] -= 1
            e = run(c, "refine")
            return math.log(e.objective) if e.objective > 0 else math.inf

        x0 = z0[free]
        simplex = [x0]
        for j, i in enumerate(free):
            v = x0.copy()
            step = spacing[i]
            v[j] = x0[j] + step if x0[j] + step <= 1.0 else x0[j] - step
            simplex.append(v)
        optimize.minimize(
            f,
            x0,
            method="Nelder-Mead",
            bounds=[(0.0, 1.0)] * len(free),
            options={
                "initial_simplex": np.array(simplex),
                "maxfev": 3 * max_refine,
                "xatol": 0.02,
                "fatol": 0.005,
            },
        )
    extra_refs: list[Evaluation] = []
    reference = cache.get(DEFAULT_CANDIDATE.key())
    if reference is None:
        reference = evaluate_candidate(DEFAULT_CANDIDATE, problem, stage="reference")
        extra_refs.append(reference)
    best = min(evaluations, key=lambda e: e.objective)
    worst = max(grid, key=lambda e: e.objective)
    if screened:
        worst_sur = max(screened, key=lambda cs: cs[1])[0]
        if worst_sur.key() not in cache:
            worst_eval = evaluate_candidate(worst_sur, problem, stage="reference")
            extra_refs.append(worst_eval)
            worst = max(worst, worst_eval, key=lambda e: e.objective)
    confirmation = None
    if confirm_realisations:
        confirmation = confirm(
            {"best": best.candidate, "default": DEFAULT_CANDIDATE, "worst": worst.candidate},
            problem,
            realisations=confirm_realisations,
        )
    n_campaigns = len(evaluations) + len(extra_refs) + (3 if confirmation else 0)
    n_points = (
        sum(e.n_points for e in evaluations)
        + sum(e.n_points for e in extra_refs)
        + (confirmation.n_points if confirmation else 0)
    )
    return DesignResult(
        problem=problem,
        family=family,
        evaluations=tuple(evaluations),
        reference=reference,
        best=best,
        worst=worst,
        confirmation=confirmation,
        n_campaigns=n_campaigns,
        n_points=n_points,
        wall_s=time.perf_counter() - t0,
        settings={
            "max_refine": max_refine,
            "confirm_realisations": confirm_realisations,
            "screen": screen,
        },
        screened=tuple(screened),
    )
