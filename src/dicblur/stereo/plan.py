"""Exposure planning for a 3-D target: the longest exposure whose predicted sigma of the
3-D displacement meets a target, and which stereo angle would do better (docs/stereo.md,
"Planning").

Per exposure ``t`` the point moves ``dX = v t`` (mm) during it; each camera's blur is that
motion projected through it (:func:`~dicblur.stereo.uncertainty.blur_vectors`, the blur of
the stereo track), ``W_cam = |p_cam(X + dX/2) - p_cam(X - dX/2)|``. Each camera's image
error is the 2-D model's (:meth:`dicblur.BlurUncertaintyModel.predict`, the model
``dicblur plan`` uses): ``u_e(W)`` along its blur, the noise term ``u_noise`` across it
(``u_e`` both ways when the model has no noise term, the power law), as a covariance in
``(row, col)``:

    C_cam = u_noise^2 I + (u_e^2 - u_noise^2) d d^T        (d: the blur direction)

propagated through the triangulation as the track does,
``Cov = G diag(C_L, C_R) G^T`` (:func:`~dicblur.stereo.triangulate.propagate`,
paper-brief s. 11), the two cameras' errors independent. The sigmas are given in the
target's frame: ``x`` along the baseline, ``z`` along the bisector of the two lines of
sight (away from the rig: out of plane for a target facing the rig), ``y = z x x``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..arrays import Float64Array
from ..errors import InputError
from ..models import BlurUncertaintyModel, parse_quantity
from .camera import StereoRig
from .synthetic import symmetric_rig
from .triangulate import propagate, triangulation_jacobian
from .uncertainty import blur_vectors

__all__ = [
    "AngleOption",
    "StereoPlan",
    "parse_vector",
    "plan_stereo_exposure",
    "stereo_sigma",
    "target_frame",
]

Component = Literal["worst", "x", "y", "z"]
#: Stereo angles (deg) a plan compares by default (symmetric rigs, the same distance).
ANGLES = (10.0, 15.0, 20.0, 30.0, 45.0, 60.0)


def parse_vector(value: str | Sequence[Any], kind: str, name: str) -> Float64Array:
    """Three components ``"0,0,100mm/s"`` (the unit of the last applies to bare numbers;
    each may carry its own) or a sequence of 3 numbers / strings, in the base unit of
    ``kind`` (:func:`dicblur.models.parse_quantity`)."""
    parts: list[Any] = value.split(",") if isinstance(value, str) else list(value)
    if len(parts) != 3:
        raise InputError(f"{name}={value!r}: expected three components x,y,z, e.g. '0,0,100mm/s'")
    unit = ""
    if isinstance(parts[-1], str):
        last = parts[-1].strip()
        i = len(last)
        while i > 0 and not (last[i - 1].isdigit() or last[i - 1] == "."):
            i -= 1
        unit = last[i:]
    out = []
    for p in parts:
        if isinstance(p, str):
            p = p.strip()
            if unit and p and (p[-1].isdigit() or p[-1] == "."):
                p = p + unit
        out.append(parse_quantity(p, kind, name=name))  # type: ignore[arg-type]
    return np.array(out, dtype=np.float64)


def target_frame(rig: StereoRig, point: Float64Array) -> Float64Array:
    """Rows ``x, y, z`` (3, 3) of the target frame at ``point`` (left frame, mm): ``z``
    the bisector of the two lines of sight (away from the rig), ``x`` the baseline made
    orthogonal to it, ``y = z x x`` (module docstring)."""
    p = np.asarray(point, dtype=np.float64)
    d_l = p / np.linalg.norm(p)
    d_r = (p - rig.right_centre) / np.linalg.norm(p - rig.right_centre)
    z = d_l + d_r
    z /= np.linalg.norm(z)
    b = rig.right_centre - z * (rig.right_centre @ z)
    x = b / np.linalg.norm(b)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def _camera_cov(
    model: BlurUncertaintyModel,
    vec: Float64Array,
    sigma: float | None,
    which: str | None,
) -> tuple[Float64Array, Float64Array, bool]:
    """(row, col) covariances (n, 2, 2) px^2 of blur vectors (n, 2), their W (n,), and
    whether every W lies inside the model's domain."""
    w = np.hypot(vec[:, 0], vec[:, 1])
    fin = np.isfinite(w)  # a motion that takes the point behind a camera: no prediction
    pred = model.predict(np.where(fin, w, 0.0), sigma, model=which)
    ue = np.where(fin, np.asarray(pred.u_e, dtype=np.float64), np.inf)
    un = ue if pred.u_noise is None else np.minimum(np.asarray(pred.u_noise, np.float64), ue)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(w[:, None] > 0, vec / w[:, None], 0.0)
    with np.errstate(invalid="ignore"):  # inf - inf where there is no prediction
        cov = un[:, None, None] ** 2 * np.eye(2)[None] + (ue**2 - un**2)[:, None, None] * (
            d[:, :, None] * d[:, None, :]
        )
    cov[~np.isfinite(cov)] = np.inf
    inside = pred.inside_domain is None or bool(np.all(pred.inside_domain))
    return cov, w, inside


def stereo_sigma(
    rig: StereoRig,
    model: BlurUncertaintyModel,
    *,
    point: Float64Array,
    motion: Float64Array,
    sigma: float | None = None,
    which: str | None = None,
) -> tuple[Float64Array, Float64Array, Float64Array, bool]:
    """Predicted sigma (n, 3) mm in the target frame of ``point`` for the motions during
    the exposure ``motion`` (n, 3) mm (left frame), with each camera's W (n,) px (left,
    right) and whether all W are inside the model's domain (module docstring)."""
    m = np.atleast_2d(np.asarray(motion, dtype=np.float64))
    pts = np.broadcast_to(np.asarray(point, dtype=np.float64), m.shape)
    vl, vr = blur_vectors(rig, pts, m)
    c_l, w_l, in_l = _camera_cov(model, vl, sigma, which)
    c_r, w_r, in_r = _camera_cov(model, vr, sigma, which)
    g = triangulation_jacobian(rig, np.ascontiguousarray(pts))
    with np.errstate(invalid="ignore"):  # no prediction (inf): NaN sigma, never planned
        cov = propagate(g, c_l, c_r)
    f = target_frame(rig, np.asarray(point, dtype=np.float64))
    cov_t = np.einsum("ij,njk,lk->nil", f, cov, f)
    sig = np.sqrt(np.maximum(np.diagonal(cov_t, axis1=1, axis2=2), 0.0))
    return sig, w_l, w_r, in_l and in_r


@dataclass(frozen=True)
class AngleOption:
    """One stereo angle of a plan's comparison (a symmetric rig, the same distance).

    Attributes
    ----------
    stereo_angle : float
        deg.
    exposure : float
        Longest exposure meeting the target, s (0 when not even a still target does).
    sigma : tuple of 3 float
        sigma x, y, z (mm, target frame) at that exposure.
    sigma_at_plan : tuple of 3 float
        sigma x, y, z (mm) at the exposure planned for the given rig.
    blur_left, blur_right : float
        W of each camera at ``exposure``, px.
    """

    stereo_angle: float
    exposure: float
    sigma: tuple[float, float, float]
    sigma_at_plan: tuple[float, float, float]
    blur_left: float
    blur_right: float


@dataclass(frozen=True)
class StereoPlan:
    """The exposure for a 3-D target (:func:`plan_stereo_exposure`).

    Attributes
    ----------
    exposure : float
        Longest exposure whose sigma meets ``target``, s (0: the noise alone misses it).
    target : float
        mm.
    component : str
        ``"worst"`` (the largest of x, y, z) or the component planned for.
    sigma : tuple of 3 float
        sigma x, y, z (mm, target frame) at ``exposure``.
    sigma_static : tuple of 3 float
        sigma x, y, z (mm) of a still target (the noise floor).
    blur_left, blur_right : float
        Each camera's W at ``exposure``, px.
    velocity : tuple of 3 float
        mm/s, target frame (as given).
    point : tuple of 3 float
        The planned point, mm (left frame).
    stereo_angle, distance : float
        deg; mm from the left camera to the point.
    limited_by_breakdown : bool
        The exposure stops where a camera's W reaches the model's breakdown blur.
    inside_domain : bool
        Both cameras' W inside the 2-D model's validity domain at ``exposure``.
    angles : tuple of AngleOption
        The comparison of stereo angles; ``best_angle`` the one with the longest exposure.
    curve_exposure : ndarray (n,)
        s; ``curve_sigma`` (n, 3) mm: sigma over exposures up to twice the plan's.
    notes : tuple of str
    """

    exposure: float
    target: float
    component: str
    sigma: tuple[float, float, float]
    sigma_static: tuple[float, float, float]
    blur_left: float
    blur_right: float
    velocity: tuple[float, float, float]
    point: tuple[float, float, float]
    stereo_angle: float
    distance: float
    limited_by_breakdown: bool
    inside_domain: bool
    angles: tuple[AngleOption, ...]
    best_angle: float
    curve_exposure: Float64Array
    curve_sigma: Float64Array
    notes: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            if isinstance(v, np.ndarray):
                out[k] = v.tolist()
            elif k == "angles":
                out[k] = [a.__dict__ for a in v]
            else:
                out[k] = v
        return out


def _score(sig: Float64Array, component: str) -> Float64Array:
    if component == "worst":
        return np.asarray(np.max(sig, axis=-1))
    return np.asarray(sig[..., "xyz".index(component)])


def _longest(
    rig: StereoRig,
    model: BlurUncertaintyModel,
    point: Float64Array,
    v_left: Float64Array,
    target: float,
    component: str,
    sigma: float | None,
    which: str | None,
) -> tuple[float, bool]:
    """The longest exposure (s) meeting ``target``, and whether the breakdown blur capped
    it: a geometric scan for the first exposure that misses, then bisection (sigma grows
    with the exposure: the models' u_e grows with W)."""
    dom = model.domain
    w_break = None if dom is None else dom.breakdown_blur
    # blur per second of exposure, the larger of the two cameras
    vl, vr = blur_vectors(rig, point[None], v_left[None])
    rate = max(float(np.hypot(*vl[0])), float(np.hypot(*vr[0])))

    def scores(t: Float64Array) -> Float64Array:
        sg = stereo_sigma(
            rig, model, point=point, motion=t[:, None] * v_left[None], sigma=sigma, which=which
        )[0]
        val = _score(sg, component)
        return np.where(np.isfinite(val), val, np.inf)

    if not scores(np.zeros(1))[0] <= target:
        return 0.0, False
    if rate <= 0:
        return math.inf, False
    t_cap = math.inf if w_break is None else w_break / rate
    # vectorised: a geometric scan of W from 1e-3 px (to the breakdown, or 1,000 px), then
    # two linear refinements of the bracket (sigma grows with W: the models' u_e does)
    t = np.geomspace(1e-3, 1e3, 241) / rate
    if math.isfinite(t_cap):
        t = np.append(t[t < t_cap], t_cap)
    ok = scores(t) <= target
    if ok.all():
        return (t_cap, True) if math.isfinite(t_cap) else (math.inf, False)
    i = int(np.argmin(ok))  # the first exposure that misses
    lo, hi = (0.0 if i == 0 else float(t[i - 1])), float(t[i])
    for _ in range(2):
        tt = np.linspace(lo, hi, 101)
        ok = scores(tt) <= target
        j = int(np.argmin(ok))
        lo, hi = float(tt[j - 1]), float(tt[j])
    return lo, False


def plan_stereo_exposure(
    rig: StereoRig,
    model: BlurUncertaintyModel,
    *,
    velocity: str | Sequence[Any],
    target: float | str,
    component: Component = "worst",
    sigma: float | None = None,
    which: str | None = None,
    point: Sequence[float] | None = None,
    angles: Sequence[float] = ANGLES,
    n_curve: int = 100,
) -> StereoPlan:
    """The longest exposure whose predicted 3-D sigma meets ``target``, and the stereo
    angles compared.

    Parameters
    ----------
    rig : StereoRig
    model : BlurUncertaintyModel
        The 2-D model of the cameras' images (``dicblur fit``), both cameras alike.
    velocity : str or sequence of 3
        The target's velocity in its frame (module docstring: x along the baseline, z out
        of plane), mm/s: ``"0,0,100mm/s"`` or three numbers/strings.
    target : float or str
        Largest sigma, mm (``"0.01mm"``, ``"5um"``).
    component : {"worst", "x", "y", "z"}
        The component that must meet it (``"worst"``: all three).
    sigma : float, optional
        Noise std, GL (default the model's).
    which : {"mismatch", "power_law", "static"}, optional
        The 2-D model's kind (default its default).
    point : (3,) mm, optional
        The point planned for, left frame (default where the optical axes cross).
    angles : sequence of float
        Stereo angles (deg) of symmetric rigs at the same distance to compare.
    n_curve : int
        Points of the sigma(exposure) curve.

    Returns
    -------
    StereoPlan
    """
    if not isinstance(rig, StereoRig):
        raise InputError(f"rig={type(rig).__name__}: expected a dicblur.stereo.StereoRig")
    if not isinstance(model, BlurUncertaintyModel):
        raise InputError("model: expected a BlurUncertaintyModel (dicblur fit)")
    if component not in ("worst", "x", "y", "z"):
        raise InputError(f"component={component!r}: choose worst, x, y or z")
    tgt = parse_quantity(target, "length", name="target")
    if not tgt > 0:
        raise InputError(f"target={target!r}: must be > 0, e.g. '0.01mm'")
    v_t = parse_vector(velocity, "velocity", "velocity")
    if not np.any(v_t):
        raise InputError(
            f"velocity={velocity!r}: zero speed means no blur; any exposure works (give "
            "the target's velocity, e.g. '0,0,100mm/s')"
        )
    p = rig.converge_point() if point is None else np.asarray(point, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)) or not p[2] > 0:
        raise InputError(f"point={point!r}: expected (X, Y, Z) mm in front of the left camera")
    frame = target_frame(rig, p)
    v_l = frame.T @ v_t
    t_plan, limited = _longest(rig, model, p, v_l, tgt, component, sigma, which)
    notes: list[str] = []
    t_eval = t_plan if math.isfinite(t_plan) else 0.0
    sig, w_l, w_r, inside = stereo_sigma(
        rig, model, point=p, motion=t_eval * v_l[None], sigma=sigma, which=which
    )
    sig0 = stereo_sigma(rig, model, point=p, motion=np.zeros((1, 3)), sigma=sigma, which=which)[0]
    if t_plan == 0.0:
        notes.append(
            f"even a still target misses the target: sigma x, y, z = "
            f"{', '.join(f'{s * 1e3:.3g}' for s in sig0[0])} um (noise alone); lower the "
            "noise, a larger subset, or a wider stereo angle (the comparison below)"
        )
    if limited:
        notes.append(
            "the exposure stops where a camera's blur reaches the 2-D model's breakdown "
            f"blur (W = {model.domain.breakdown_blur:g} px)"  # type: ignore[union-attr]
        )
    if not inside:
        notes.append("a camera's W or the noise lies outside the 2-D model's domain (extrapolated)")
    distance = float(np.linalg.norm(p))
    opts = []
    for a in angles:
        r = symmetric_rig(stereo_angle=float(a), distance=distance, camera=rig.left)
        pa = r.converge_point()
        va = target_frame(r, pa).T @ v_t
        ta, _ = _longest(r, model, pa, va, tgt, component, sigma, which)
        te = ta if math.isfinite(ta) else 0.0
        sa, wla, wra, _ = stereo_sigma(
            r, model, point=pa, motion=te * va[None], sigma=sigma, which=which
        )
        sp = stereo_sigma(r, model, point=pa, motion=t_eval * va[None], sigma=sigma, which=which)[0]
        opts.append(
            AngleOption(
                stereo_angle=float(a),
                exposure=ta,
                sigma=tuple(float(x) for x in sa[0]),  # type: ignore[arg-type]
                sigma_at_plan=tuple(float(x) for x in sp[0]),  # type: ignore[arg-type]
                blur_left=float(wla[0]),
                blur_right=float(wra[0]),
            )
        )
    best = (
        max(opts, key=lambda o: (o.exposure, -float(_score(np.array(o.sigma_at_plan), component))))
        if opts
        else None
    )
    if best is not None:
        notes.append(
            f"of the symmetric rigs at {distance:.4g} mm, {best.stereo_angle:g} deg allows the "
            f"longest exposure ({best.exposure * 1e3:.4g} ms against {t_plan * 1e3:.4g} ms)"
        )
    t_c = np.linspace(0.0, 2.0 * (t_eval if t_eval > 0 else 1e-3), n_curve)
    curve = stereo_sigma(
        rig, model, point=p, motion=t_c[:, None] * v_l[None], sigma=sigma, which=which
    )[0]
    return StereoPlan(
        exposure=t_plan,
        target=tgt,
        component=component,
        sigma=tuple(float(x) for x in sig[0]),  # type: ignore[arg-type]
        sigma_static=tuple(float(x) for x in sig0[0]),  # type: ignore[arg-type]
        blur_left=float(w_l[0]),
        blur_right=float(w_r[0]),
        velocity=tuple(float(x) for x in v_t),  # type: ignore[arg-type]
        point=tuple(float(x) for x in p),  # type: ignore[arg-type]
        stereo_angle=rig.stereo_angle,
        distance=distance,
        limited_by_breakdown=limited,
        inside_domain=inside,
        angles=tuple(opts),
        best_angle=best.stereo_angle if best is not None else float("nan"),
        curve_exposure=t_c,
        curve_sigma=curve,
        notes=tuple(notes),
    )
