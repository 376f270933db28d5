"""Helpers of the campaign tests: a small real task function and spec builders.

``shift_task`` is a genuine (cheap) computation with the same contract as
:func:`dicblur.campaign.simulate_batch`: it Fourier-shifts the pattern by the mean motion,
adds seeded noise, and measures the shift subset by subset with the linearised optical-flow
estimate ``sum(f_x d) / sum(f_x^2)``; it lets the engine tests run without the DIC stage.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np

from dicblur.campaign import VARIABLES, Batch, CampaignSpec, directional_sssig, task_seed
from dicblur.campaign.simulate import task_points
from dicblur.metrics import image_gradients, michelson_contrast, mig, rms_contrast


def _fourier_shift(img: np.ndarray, dy: float, dx: float) -> np.ndarray:
    fy = np.fft.fftfreq(img.shape[0])[:, None]
    fx = np.fft.rfftfreq(img.shape[1])[None, :]
    phase = np.exp(-2j * math.pi * (fy * dy + fx * dx))
    return np.fft.irfft2(np.fft.rfft2(img) * phase, s=img.shape)


def shift_task(image: np.ndarray, batch: Batch, spec: CampaignSpec) -> dict[str, np.ndarray]:
    n = len(batch.blur)
    out = {k: np.full(n, np.nan) for k in VARIABLES}
    pts = task_points(image.shape, spec, subset=batch.subset, angle=batch.angle)
    h = batch.subset // 2
    rng_ref = np.random.default_rng(
        task_seed(spec.seed, "reference", pattern=batch.pattern, noise=batch.noise, rep=batch.rep)
    )
    ref = image + rng_ref.normal(0.0, batch.noise, image.shape)
    _, gx = image_gradients(ref)
    a = math.radians(batch.angle)
    for j, w in enumerate(batch.blur):
        t0 = time.perf_counter()
        dy, dx = 0.5 * w * math.sin(a), 0.5 * w * math.cos(a)
        clean = _fourier_shift(image, dy, dx)
        rng = np.random.default_rng(
            task_seed(
                spec.seed,
                "current",
                pattern=batch.pattern,
                angle=batch.angle,
                noise=batch.noise,
                blur=w,
                rep=batch.rep,
            )
        )
        cur = clean + rng.normal(0.0, batch.noise, image.shape)
        diff = ref - cur
        est = np.empty(len(pts))
        for i, (r, c) in enumerate(pts):
            sl = (slice(r - h, r + h + 1), slice(c - h, c + h + 1))
            est[i] = np.sum(gx[sl] * diff[sl]) / np.sum(gx[sl] ** 2)
        s = directional_sssig(clean, pts, subset=batch.subset, angle=batch.angle)
        out["u_e"][j] = np.std(est, ddof=1)
        out["u_e_across"][j] = 0.0
        out["bias"][j] = np.mean(est) - dx
        out["converged_fraction"][j] = 1.0
        out["sssig"][j] = s.mean()
        out["sssig_std"][j] = s.std()
        out["mig"][j] = mig(clean)
        out["contrast"][j] = michelson_contrast(clean)
        out["rms_contrast"][j] = rms_contrast(clean)
        out["u_match_score"][j] = math.sqrt(2.0) * batch.noise / math.sqrt(s.mean())
        out["u_pan"][j] = math.sqrt(2.0) * batch.noise / (batch.subset * out["mig"][j])
        out["noise_effective"][j] = batch.noise
        out["n_points"][j] = len(pts)
        out["time_s"][j] = time.perf_counter() - t0
    out["sssig_ref"][:] = directional_sssig(
        image, pts, subset=batch.subset, angle=batch.angle
    ).mean()
    out["mig_ref"][:] = mig(image)
    out["contrast_ref"][:] = michelson_contrast(image)
    out["rms_contrast_ref"][:] = rms_contrast(image)
    return out


def small_spec_dict(**over: object) -> dict:
    d: dict = {
        "campaign": {"name": "t", "seed": 7, "repetitions": 2},
        "pattern": [
            {
                "name": "a",
                "generator": "speckle",
                "shape": [64, 64],
                "speckle_size": 4.0,
                "seed": 1,
            },
            {"name": "b", "generator": "paper4", "shape": [64, 64], "seed": 2},
        ],
        "blur": {"lengths": {"start": 0.0, "stop": 2.0, "step": 0.5}, "angles": [0.0]},
        "noise": {"model": "per-exposure", "levels": [1.0, 2.0]},
        "dic": {"subsets": [15], "step": 8},
        "run": {"blur_chunk": 2},
    }
    for k, v in over.items():
        sec, key = k.split("__")
        d[sec][key] = v
    return d


def spec_toml(d: dict) -> str:
    """The TOML text of a spec dict as ``small_spec_dict`` builds it: a table per section,
    an array of tables for a list of tables, inline tables, lists, strings and numbers."""

    def value(v: object) -> str:
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        if isinstance(v, list | tuple):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    lines: list[str] = []
    for section, body in d.items():
        for table in body if isinstance(body, list) else [body]:
            lines.append(f"[[{section}]]" if isinstance(body, list) else f"[{section}]")
            lines += [f"{k} = {value(v)}" for k, v in table.items()]
            lines.append("")
    return "\n".join(lines)


def kill_spec() -> CampaignSpec:
    """A campaign of about a second (2 patterns x 2 noise x 2 reps x 24 W, 80x80 px)."""
    from dicblur.campaign import parse_spec

    d = small_spec_dict(blur__lengths={"start": 0.0, "stop": 2.3, "step": 0.1})
    for p in d["pattern"]:
        p["shape"] = [80, 80]
    return parse_spec(d)


WARM_UP = """
from dicblur.campaign import iter_batches, make_pattern, parse_spec, simulate_batch
spec = parse_spec({"campaign": {"seed": 1},
                   "pattern": [{"name": "p", "generator": "speckle", "shape": [48, 48]}],
                   "blur": {"lengths": [0.0, 1.0]}, "noise": {"model": "per-exposure"},
                   "dic": {"subsets": [11], "step": 12}})
for b in iter_batches(spec):
    simulate_batch(make_pattern(spec, spec.patterns[0]), b, spec)
# the other kernel signatures the tests use: affine, quintic, the static predictions
import numpy as np
import dicblur
img = dicblur.speckle_pattern((48, 48), speckle_size=4.0, seed=1)
for shape in ("translation", "affine"):
    for interp in ("bspline3", "bspline5"):
        dicblur.correlate(img, img, subset=11, step=12, shape=shape, interpolation=interp,
                          noise_sigma=1.0)
dicblur.blur_mismatch_curve(img, [1.0], subset=11)
dicblur.motion_blur(img, (1.0, 2.0), substeps=None)
"""


_WARMED: list[bool] = []


def warm_numba_cache() -> None:
    """Compile the task's numba kernels in a separate process, writing the on-disk cache.

    A process that compiles the DIC kernels itself and one that loads them from the cache
    can differ in the last bits (measured: 9e-14 relative on u_e; fastmath kernels). Tests
    that compare a worker process with this process make both load the cached code: the
    warm-up must run before this process compiles anything (tests/conftest.py runs it
    after collection when a selected test is marked ``numba_cache``). Once per process;
    with a warm cache the subprocess only loads (a few seconds).
    """
    if _WARMED:
        return
    import subprocess
    import sys

    subprocess.run([sys.executable, "-c", WARM_UP], check=True, timeout=900)
    _WARMED.append(True)
