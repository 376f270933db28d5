"""Evaluate one candidate pattern: a small campaign, the blur-model fit, the static surrogate.

Measured evaluation. A candidate's campaign is a :class:`dicblur.campaign.CampaignSpec`
with one generated pattern per realisation (names ``r0, r1, ...``, pattern seeds from the
problem's base seed), the problem's noise (per exposure), subset, step and shape function,
and the blur grid ``problem.fit_blurs``. Its batches are run in this process by the
campaign's own task function :func:`dicblur.campaign.simulate_batch`, so every number is
the one ``dicblur campaign run`` would store for that spec. Pattern names and seeds are
shared by all candidates (common random numbers): two candidates differ by their settings
only, not by a noise draw, which makes the search objective smooth and the ranking stable.

The blur model (:func:`dicblur.models.fit_blur_model`) is fitted to u_e(W) pooled over the
realisations (root mean square per W); its noise + blur-mismatch prediction at the design
blurs is the candidate's objective. eta and alpha (eq. 17), beta (eq. 18) and
MBRF = 2 alpha beta (eq. 22) are fitted over the whole W grid so that the maps compare like
with like.

Static surrogate (no DIC). ``u_s(W)**2 = 2 sigma**2 / SSSIG(W) + (c W**2)**2`` with SSSIG(W)
the mean subset SSSIG of the noise-free blurred image and ``c`` the static blur
sensitivity (:func:`dicblur.models.blur_sensitivity`); docs/models.md s. 4.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arrays import Float64Array
from ..errors import FitError, InputError
from .family import Candidate
from .problem import DesignProblem

__all__ = [
    "Evaluation",
    "campaign_spec",
    "evaluate_candidate",
    "measure_candidate",
    "pattern_seeds",
    "screen_candidate",
    "surrogate",
]


@dataclass(frozen=True)
class Evaluation:
    """One candidate evaluated by a campaign and a blur-model fit.

    Attributes
    ----------
    candidate : Candidate
    stage : str
        ``"grid"``, ``"refine"`` or ``"reference"`` (the default pattern).
    objective : float
        Predicted u_e (px) at the design blur (weighted mean over the design blurs).
    predicted : tuple of float
        Predicted u_e (px) at each design blur.
    fit_blurs : tuple of float
        W (px) of the campaign.
    u_e : tuple of float
        Measured u_e (px) per W, root mean square over the realisations.
    sssig : tuple of float
        Mean subset SSSIG (GL/px)**2 of the noise-free blurred images per W.
    u_ref, alpha, beta, mbrf : float
        Power law (eq. 17) as ``u_e = u_ref (SSSIG / SSSIG_0)**-alpha`` (``u_ref`` px: its
        u_e(0)), SSSIG decay (eq. 18), MBRF = 2 alpha beta (eq. 22), 1/px**2.
    c_fit : float
        Fitted blur-mismatch coefficient (px/px**2), NaN if the fit failed.
    c_static : float
        Static blur sensitivity (px/px**2), mean over the realisations.
    mig0 : float
        MIG of the sharp pattern (GL/px).
    surrogate : float
        Static surrogate objective (px).
    fit_ok : bool
        False if the mismatch model could not be fitted; the objective is then the measured
        u_e interpolated at the design blurs.
    n_points : int
        Campaign tasks (DIC runs) used.
    time_s : float
    """

    candidate: Candidate
    stage: str
    objective: float
    predicted: tuple[float, ...]
    fit_blurs: tuple[float, ...]
    u_e: tuple[float, ...]
    sssig: tuple[float, ...]
    u_ref: float
    alpha: float
    beta: float
    mbrf: float
    c_fit: float
    c_static: float
    mig0: float
    surrogate: float
    fit_ok: bool
    n_points: int
    time_s: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (NaN kept as float NaN)."""
        d: dict[str, Any] = {**self.candidate.to_dict(), "stage": self.stage}
        for k in (
            "objective",
            "u_ref",
            "alpha",
            "beta",
            "mbrf",
            "c_fit",
            "c_static",
            "mig0",
            "surrogate",
            "fit_ok",
            "n_points",
            "time_s",
        ):
            d[k] = getattr(self, k)
        for k in ("predicted", "fit_blurs", "u_e", "sssig"):
            d[k] = list(getattr(self, k))
        return d


def pattern_seeds(base_seed: int, n: int, *, fresh: bool = False) -> list[int]:
    """Pattern seeds of the ``n`` realisations (``fresh=True``: the confirmation's, disjoint
    from the search's)."""
    ss = np.random.SeedSequence(int(base_seed), spawn_key=(1 if fresh else 0,))
    return [int(v) for v in ss.generate_state(n, dtype=np.uint32)]


def campaign_spec(
    candidate: Candidate,
    problem: DesignProblem,
    *,
    blurs: Any = None,
    seeds: list[int] | None = None,
    base_seed: int | None = None,
) -> Any:
    """The :class:`dicblur.campaign.CampaignSpec` of a candidate (one pattern per seed)."""
    from ..campaign import parse_spec

    seeds = pattern_seeds(problem.seed, problem.realisations) if seeds is None else seeds
    w = list(problem.fit_blurs if blurs is None else blurs)
    shape = (problem.image_size, problem.image_size)
    patterns = [
        {"name": f"r{i}", "generator": "speckle", **candidate.settings(shape, s)}
        for i, s in enumerate(seeds)
    ]
    data = {
        "campaign": {
            "name": "design",
            "seed": problem.seed if base_seed is None else int(base_seed),
        },
        "pattern": patterns,
        "blur": {"lengths": w, "substeps": problem.substeps, "boundary": "periodic"},
        "noise": {"model": "per-exposure", "levels": [problem.noise]},
        "dic": {"subsets": [problem.subset], "step": problem.step, "shape": problem.dic_shape},
        "run": {"blur_chunk": len(w)},
    }
    return parse_spec(data)


def measure_candidate(spec: Any) -> dict[str, Float64Array]:
    """Run a candidate's campaign (its :func:`campaign_spec`) in this process; variables
    of shape (realisation, W).

    Returns the campaign variables (``u_e``, ``sssig``, ``mig_ref``, ``contrast_ref``,
    ``contrast``, ``converged_fraction``, ...) plus ``images`` (realisation, rows, cols).
    """
    from ..campaign import iter_batches, make_pattern, simulate_batch

    images = {p.name: make_pattern(spec, p) for p in spec.patterns}
    rows: dict[str, list[Float64Array]] = {}
    for batch in iter_batches(spec):
        out = simulate_batch(images[batch.pattern], batch, spec)
        for k, v in out.items():
            rows.setdefault(k, []).append(np.asarray(v, dtype=np.float64))
    result = {k: np.stack(v) for k, v in rows.items()}
    result["images"] = np.stack([images[p.name] for p in spec.patterns])
    return result


def surrogate(
    images: Float64Array, problem: DesignProblem, *, blurs: Any = None
) -> tuple[Float64Array, float]:
    """Static prediction of u_e (px) at ``blurs`` (default the design blurs), no DIC.

    Parameters
    ----------
    images : ndarray, shape (n, rows, cols)
        Sharp pattern realisations, grey levels.

    Returns
    -------
    u_s : ndarray, shape (len(blurs),)
        Root mean square over the realisations of
        ``sqrt(2 sigma**2 / SSSIG(W) + (c W**2)**2)``.
    c : float
        Mean static blur sensitivity (px/px**2).
    """
    from ..blur import motion_blur
    from ..campaign import directional_sssig
    from ..metrics import subset_centres
    from ..models import blur_sensitivity, mismatch_terms

    w = problem.blur_array if blurs is None else np.asarray(blurs, dtype=np.float64)
    u2 = np.zeros(w.size)
    cs = []
    for img in images:
        pts = subset_centres(img.shape, subset=problem.subset, step=problem.step)
        c = blur_sensitivity(
            img,
            subset=problem.subset,
            points=pts,
            shape=problem.dic_shape,  # type: ignore[arg-type]
            boundary="periodic",
        ).c
        cs.append(c)
        for j, wj in enumerate(w):
            b = img if wj == 0 else motion_blur(img, (0.0, float(wj)), substeps=problem.substeps)
            s = float(np.mean(directional_sssig(b, pts, subset=problem.subset, angle=0.0)))
            # the mismatch model with its theoretical constants (a = 2, gamma = 1, no floor)
            noise, blur2 = mismatch_terms([wj], [s], problem.noise, c=c)
            u2[j] += float(noise[0] + blur2[0])
    return np.sqrt(u2 / len(images)), float(np.mean(cs))


def screen_candidate(candidate: Candidate, problem: DesignProblem) -> float:
    """Static surrogate objective (px) of a candidate, no DIC: the same pattern
    realisations as its campaign, :func:`surrogate` at the design blurs."""
    from ..campaign import make_pattern

    spec = campaign_spec(candidate, problem)
    images = np.stack([make_pattern(spec, p) for p in spec.patterns])
    u, _ = surrogate(images, problem)
    return problem.objective(u)


def evaluate_candidate(
    candidate: Candidate, problem: DesignProblem, *, stage: str = "grid"
) -> Evaluation:
    """Measure a candidate (campaign), fit its blur model, compute its surrogate."""
    from ..models import fit_blur_model

    t0 = time.perf_counter()
    m = measure_candidate(campaign_spec(candidate, problem))
    w = np.asarray(problem.fit_blurs)
    u_e = np.sqrt(np.nanmean(m["u_e"] ** 2, axis=0))
    sssig = np.nanmean(m["sssig"], axis=0)
    u_sur, c_static = surrogate(m["images"], problem)
    nan = float("nan")
    u_ref = alpha = beta = mbrf = c_fit = nan
    fit_ok = False
    pred = np.interp(problem.blur_array, w, u_e)
    if np.all(np.isfinite(u_e)) and np.all(u_e > 0):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = fit_blur_model(
                    w,
                    sssig,
                    u_e,
                    noise_sigma=problem.noise,
                    # RMS contrast, as dicblur calibrate (Michelson barely moves under blur)
                    contrast_ref=np.nanmean(m["rms_contrast_ref"], axis=0),
                    contrast=np.nanmean(m["rms_contrast"], axis=0),
                    subset=problem.subset,
                    fit_range=(0.0, float(w[-1])),
                    c_static=c_static,
                    default="mismatch",
                    compare=False,
                    provenance={"candidate": candidate.to_dict()},
                )
            u_ref, alpha, beta, mbrf = model.u_ref, model.alpha, model.beta, model.mbrf
            if model.mismatch is not None:
                c_fit = float(model.mismatch["c"])
                pred = model.predict(problem.blur_array, problem.noise, model="mismatch").u_e
                fit_ok = True
        except (FitError, InputError):
            pass
    return Evaluation(
        candidate=candidate,
        stage=stage,
        objective=problem.objective(pred),
        predicted=tuple(map(float, pred)),
        fit_blurs=problem.fit_blurs,
        u_e=tuple(map(float, u_e)),
        sssig=tuple(map(float, sssig)),
        u_ref=float(u_ref),
        alpha=float(alpha),
        beta=float(beta),
        mbrf=float(mbrf),
        c_fit=c_fit,
        c_static=c_static,
        mig0=float(np.mean(m["mig_ref"][:, 0])),
        surrogate=problem.objective(u_sur),
        fit_ok=fit_ok,
        n_points=int(m["u_e"].size),
        time_s=time.perf_counter() - t0,
    )
