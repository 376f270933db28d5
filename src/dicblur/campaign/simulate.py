"""The task of a campaign: blur, add noise, correlate, measure (the paper's Algorithm 1 + DIC).

:func:`simulate_batch` is a plain function of (pattern image, batch coordinates, spec):
it computes, for every blur length W of the batch, the blurred noisy image, correlates it
against the (noisy) reference with one :class:`dicblur.Correlator` prepared per batch,
and returns the per-task variables of :data:`dicblur.campaign.VARIABLES`. It knows
nothing of Dask or storage.

Conventions. The motion of angle ``a`` (degrees, from +x towards +y) and length W is
``(dy, dx) = W (sin a, cos a)``. The imposed displacement is the mean position of the
trajectory (``motion / 2`` for linear motion, Algorithm 1); "along" and "across" are the
components of the measured displacement ``(u, v)`` along ``(cos a, sin a)`` and
``(-sin a, cos a)``. SSSIG, MIG and contrast are measured on the noise-free images (they
describe the pattern and its blur, not a noise realisation).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ..arrays import Float64Array, IndexArray
from ..errors import ConfigError, InputError

# re-exported: the campaigns' SSSIG along the motion lives with the other metrics
from ..metrics import box_sssig, directional_sssig, match_score_sigma, pan_sigma
from .spec import CampaignSpec
from .tasks import Batch, task_seed

__all__ = ["directional_sssig", "simulate_batch", "task_points"]


def _trajectory(spec: CampaignSpec) -> Any:
    from ..blur import AcceleratedMotion, SineMotion

    params = dict(spec.trajectory_params)
    try:
        if spec.trajectory == "sine":
            return SineMotion(**params)
        if spec.trajectory == "acceleration":
            return AcceleratedMotion(**params)
    except (TypeError, InputError) as exc:
        raise ConfigError(f"blur.trajectory_params={params!r}: {exc}") from exc
    if params:
        raise ConfigError(f"blur.trajectory_params={params!r}: linear motion takes none")
    return "linear"


def _motion(length: float, angle: float) -> tuple[float, float]:
    a = math.radians(angle)
    return (length * math.sin(a), length * math.cos(a))


def task_points(
    shape: tuple[int, int], spec: CampaignSpec, *, subset: int, angle: float
) -> IndexArray:
    """POIs (row, col) of a task: the subset grid of ``spec.step``, restricted, when the
    blur boundary is not periodic, to subsets inside the region that only saw image
    content at the campaign's largest W (so every W of the campaign uses the same POIs).
    """
    from ..metrics import subset_centres

    pts = subset_centres(shape, subset=subset, step=spec.step)
    if spec.boundary == "periodic":
        return pts
    from ..blur import valid_region

    rows, cols = valid_region(
        shape, _motion(max(spec.blur), angle), substeps=spec.substeps, trajectory=_trajectory(spec)
    )
    h = subset // 2
    keep = (
        (pts[:, 0] - h >= rows.start)
        & (pts[:, 0] + h < rows.stop)
        & (pts[:, 1] - h >= cols.start)
        & (pts[:, 1] + h < cols.stop)
    )
    if not keep.any():
        raise ConfigError(
            f"blur.lengths: at W = {max(spec.blur)} px with boundary={spec.boundary!r} no "
            f"subset of {subset} px fits in the trustworthy region of a {shape[0]}x"
            f'{shape[1]} image; use a larger image, smaller W or boundary="periodic"'
        )
    return pts[keep]


def _noisy(
    image: Float64Array, spec: CampaignSpec, level: float, seed: np.random.SeedSequence
) -> Float64Array:
    from ..camera import Camera, add_gaussian_noise

    if spec.noise_model == "poisson-gaussian":
        assert spec.full_well is not None
        cam = Camera(
            read_noise=level, gain=255.0 / spec.full_well, full_well=spec.full_well, bit_depth=None
        )
        return cam.capture(image, seed=seed)
    k = 100 if spec.substeps is None else spec.substeps
    return add_gaussian_noise(
        image,
        level,
        model=spec.noise_model,  # type: ignore[arg-type]
        substeps=k,
        seed=seed,
    )


def _effective_noise(spec: CampaignSpec, level: float, image: Float64Array) -> float:
    if spec.noise_model == "per-subframe":
        k = 100 if spec.substeps is None else spec.substeps
        return level / math.sqrt(k + 1)
    if spec.noise_model == "poisson-gaussian":
        assert spec.full_well is not None
        return math.sqrt(level**2 + 255.0 / spec.full_well * float(np.mean(image)))
    return level


def simulate_batch(
    image: Float64Array, batch: Batch, spec: CampaignSpec
) -> dict[str, Float64Array]:
    """Run the tasks of one batch: one reference, one Correlator, every W of the batch.

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
        The pattern (noise-free grey levels); for ``method = "rendered"``, the pattern on
        the fine grid, shape ``(rows * supersample, cols * supersample)``.
    batch : Batch
        Coordinates of the tasks.
    spec : CampaignSpec
        Blur, noise and DIC settings, base seed.

    Returns
    -------
    dict of str to ndarray, shape (len(batch.blur),)
        One entry per name of :data:`dicblur.campaign.VARIABLES`.
    """
    from ..blur import motion_blur, render_blurred, trajectory_positions
    from ..dic import Correlator, PointStatus, deblur_wiener
    from ..metrics import image_gradients, michelson_contrast, mig, rms_contrast

    t_start = time.perf_counter()
    ss = spec.supersample
    if spec.method == "rendered":
        reference = image.reshape(image.shape[0] // ss, ss, image.shape[1] // ss, ss).mean(
            axis=(1, 3)
        )
    else:
        reference = image
    traj = _trajectory(spec)
    points = task_points(reference.shape, spec, subset=batch.subset, angle=batch.angle)
    if spec.boundary == "periodic":
        window: tuple[slice, slice] = (slice(None), slice(None))
    else:
        h = batch.subset // 2
        window = (
            slice(points[:, 0].min() - h, points[:, 0].max() + h + 1),
            slice(points[:, 1].min() - h, points[:, 1].max() + h + 1),
        )
    a = math.radians(batch.angle)
    ca, sa = math.cos(a), math.sin(a)

    ref_seed = task_seed(
        spec.seed, "reference", pattern=batch.pattern, noise=batch.noise, rep=batch.rep
    )
    # The compensated matcher's blurred reference (dicblur.dic.blur_reference) has an
    # even-mirror boundary, while a periodic pattern's current image wraps around: subsets
    # near the border then see a mismatch the forward model does not have (noise-free,
    # 192 px speckle, W = 10 px: 0.074 px error within 20 px of the border). A periodic
    # margin wider than half the blur plus the spline's reach keeps every POI off the seam.
    pad = 0
    if spec.compensation in ("given", "estimate") and spec.boundary == "periodic":
        pad = math.ceil(max(spec.blur) / 2) + 16

    def wrap(img: Float64Array) -> Float64Array:
        return img if pad == 0 else np.pad(img, pad, mode="wrap")

    def make_correlator(ref: Float64Array, pts: IndexArray, blur: str) -> Any:
        return Correlator(
            ref,
            settings=spec.matcher(batch.subset),
            points=pts,
            workers=1,
            blur=blur,  # type: ignore[arg-type]
            # u_e is the scatter of every converged point: no noise-based screening
            noise_sigma=None,
        )

    noisy_ref = _noisy(reference, spec, batch.noise, ref_seed)
    mode = "none" if spec.compensation in ("none", "deblur") else spec.compensation
    correlator = make_correlator(wrap(noisy_ref), points + pad, mode)
    # W = 0 with the blur given is the plain matcher: it needs no margin, and without one
    # its result is the plain campaign's bit for bit
    plain_at_zero: Any = None
    sssig_ref = float(
        np.mean(directional_sssig(reference, points, subset=batch.subset, angle=batch.angle))
    )
    mig_ref = mig(reference[window])
    contrast_ref = michelson_contrast(reference[window])
    rms_ref = rms_contrast(reference[window])

    n = len(batch.blur)
    out = {
        name: np.full(n, np.nan)
        for name in (
            "u_e",
            "u_e_across",
            "bias",
            "converged_fraction",
            "sssig_ref",
            "sssig",
            "sssig_std",
            "mig_ref",
            "mig",
            "contrast_ref",
            "contrast",
            "rms_contrast_ref",
            "rms_contrast",
            "u_match_score",
            "u_pan",
            "noise_effective",
            "n_points",
            "time_s",
        )
    }
    setup = time.perf_counter() - t_start
    for j, length in enumerate(batch.blur):
        t0 = time.perf_counter()
        motion = _motion(length, batch.angle)
        if spec.method == "rendered":
            blurred = render_blurred(
                image, motion, supersample=ss, substeps=spec.substeps, trajectory=traj
            )
            pos, w = trajectory_positions(motion, substeps=spec.substeps or 1024, trajectory=traj)
            pos = np.rint(pos * ss) / ss
        else:
            blurred = motion_blur(
                reference,
                motion,
                substeps=spec.substeps,
                trajectory=traj,
                boundary=spec.boundary,  # type: ignore[arg-type]
            )
            pos, w = trajectory_positions(motion, substeps=spec.substeps, trajectory=traj)
        true_dy, true_dx = w @ pos
        seed = task_seed(
            spec.seed,
            "current",
            pattern=batch.pattern,
            angle=batch.angle,
            noise=batch.noise,
            blur=length,
            rep=batch.rep,
        )
        noisy = _noisy(blurred, spec, batch.noise, seed)
        if spec.compensation == "given" and pad and length == 0:
            if plain_at_zero is None:
                plain_at_zero = make_correlator(noisy_ref, points, "none")
            result = plain_at_zero.correlate(noisy)
        elif spec.compensation == "given":  # the known motion of the exposure (issue 18)
            result = correlator.correlate(wrap(noisy), blur_vector=motion)
        elif spec.compensation == "estimate":  # the length estimated along the known angle
            result = correlator.correlate(wrap(noisy), blur_angle=batch.angle)
        elif spec.compensation == "deblur":  # the published baseline, known kernel
            result = correlator.correlate(
                deblur_wiener(noisy, motion, _effective_noise(spec, batch.noise, blurred))
            )
        else:
            result = correlator.correlate(noisy)
        ok = np.asarray(result.status) == int(PointStatus.CONVERGED)
        along = result.u * ca + result.v * sa
        across = -result.u * sa + result.v * ca
        n_ok = int(ok.sum())
        # one gradient pass for SSSIG and MIG (as dicblur.mig: interior pixels)
        gy, gx = image_gradients(blurred)
        s_b = box_sssig(gy, gx, points, subset=batch.subset, angle=batch.angle)
        gw = (gy[window][1:-1, 1:-1], gx[window][1:-1, 1:-1])
        sigma = _effective_noise(spec, batch.noise, blurred)
        out["u_e"][j] = float(np.std(along[ok], ddof=1)) if n_ok >= 2 else np.nan
        out["u_e_across"][j] = float(np.std(across[ok], ddof=1)) if n_ok >= 2 else np.nan
        out["bias"][j] = (
            float(np.mean(along[ok])) - (true_dx * ca + true_dy * sa) if n_ok else np.nan
        )
        out["converged_fraction"][j] = n_ok / ok.size
        out["sssig"][j] = float(np.mean(s_b))
        out["sssig_std"][j] = float(np.std(s_b))
        # interior of the window: equal to dicblur.mig(blurred[window])
        out["mig"][j] = m = float(np.hypot(gw[1], gw[0]).mean())
        out["contrast"][j] = michelson_contrast(blurred[window])
        out["rms_contrast"][j] = rms_contrast(blurred[window])
        out["u_match_score"][j] = float(match_score_sigma(out["sssig"][j], sigma))  # eq. 2
        out["u_pan"][j] = float(pan_sigma(m, sigma, batch.subset))  # eq. 5
        out["noise_effective"][j] = sigma
        out["n_points"][j] = ok.size
        out["time_s"][j] = time.perf_counter() - t0 + setup / n
    out["sssig_ref"][:] = sssig_ref
    out["mig_ref"][:] = mig_ref
    out["contrast_ref"][:] = contrast_ref
    out["rms_contrast_ref"][:] = rms_ref
    return out
