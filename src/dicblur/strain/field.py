"""``dicblur.strain``: strain fields and their covariance from a displacement field."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..arrays import BoolArray, Float64Array, FloatArray, Int64Array, UInt8Array
from ..dic.result import DICResult
from ..dic.status import PointStatus
from ..errors import InputError
from .covariance import Kind
from .fit import choose_half
from .kernels import N_GRAD, N_OUT, WindowFields, measure_pass, stacked_kernels, window_pass

__all__ = [
    "StrainField",
    "StrainStatus",
    "grid_of",
    "strain",
    "strain_on_grid",
    "vsg",
    "window_from_vsg",
]

Method = Literal["fit", "subset"]


class StrainStatus(IntEnum):
    """Outcome of the strain at one point (uint8)."""

    #: The full N x N window of trusted points was fitted.
    OK = 0
    #: A point of the full window is missing: the largest complete smaller symmetric
    #: window (at least 3 x 3) was fitted; its VSG is smaller.
    REDUCED_WINDOW = 1
    #: No complete 3 x 3 window around the point: no strain (NaN).
    NO_WINDOW = 2
    #: The point itself is not trusted (its DIC status is not ``CONVERGED``): NaN.
    POINT_FAILED = 3


def vsg(window: int, step: float, subset: int) -> float:
    """Virtual strain gauge size, px: ``(window - 1) step + subset`` (iDICs Good Practices
    Guide, 2018)."""
    return float((window - 1) * step + subset)


def window_from_vsg(
    value: int | float | str, *, step: int, subset: int, name: str = "--vsg"
) -> int:
    """The window N (grid points) of a VSG given as grid points (``5``) or px (``"41px"``:
    ``N = (VSG - subset) / step + 1``, which must be an odd whole number >= 3)."""
    text = str(value).strip()
    if text.lower().endswith("px"):
        from ..models.units import parse_quantity

        px = parse_quantity(text, "displacement", name=name)
        n = (px - subset) / step + 1
        if not (abs(n - round(n)) < 1e-9 and round(n) >= 3 and round(n) % 2 == 1):
            ok = [vsg(k, step, subset) for k in (3, 5, 7, 9)]
            raise InputError(
                f"{name}={text!r}: a VSG of (N - 1) x step {step} px + subset {subset} px "
                f"with N odd >= 3, e.g. {', '.join(f'{v:g}px' for v in ok)}"
            )
        return round(n)
    try:
        n = int(text)
    except ValueError:
        raise InputError(
            f"{name}={text!r}: give the window in grid points (an odd number >= 3, e.g. 5) "
            "or the VSG in px (e.g. 41px)"
        ) from None
    if n < 3 or n % 2 == 0:
        raise InputError(f"{name}={text!r}: the window must be an odd number >= 3, e.g. 5")
    return n


def check_window_fits(
    window: int, grid_shape: tuple[int, int], *, step: int, subset: int, name: str = "window"
) -> None:
    """Raise :class:`~dicblur.errors.InputError` when no point of a ``grid_shape`` (rows,
    cols) POI grid can have a complete ``window`` x ``window`` plane fit: every point would
    otherwise fall back to a smaller window or to ``NO_WINDOW``, not the VSG asked for.
    ``name``: the parameter as the caller typed it; an option such as ``"--vsg"`` is
    answered in VSG px, as the command line gives it."""
    ny, nx = grid_shape
    small = min(ny, nx)
    if window <= small:
        return
    px = f"{vsg(window, step, subset):g}px"
    if small < 3:
        fix = "a grid of at least 3 x 3 points (a larger roi or a smaller step)"
    elif name == "window":
        fit = small if small % 2 else small - 1
        fix = f"window <= {fit} (VSG {vsg(fit, step, subset):g} px) or a larger grid"
    else:  # an option in VSG px (the CLI's --vsg)
        fit = small if small % 2 else small - 1
        fix = f"{name} <= {vsg(fit, step, subset):g}px or a larger grid"
    asked, full = (
        (f"window={window}", f" (VSG {px[:-2]} px)") if name == "window" else (f"{name}={px}", "")
    )
    raise InputError(
        f"{asked}: larger than the POI grid ({ny} x {nx} points), so no point has a full "
        f"window{full}; use {fix}"
    )


@dataclass(frozen=True)
class StrainField:
    """Strains of a POI grid, their covariance and status.

    Arrays have shape (..., n) over the points of the input (row-major grid order),
    dimensionless (strain) or rad (``angle``). Shear ``exy`` is the tensor component
    (engineering shear ``gamma_xy = 2 exy``).

    Attributes
    ----------
    rows, cols : ndarray of int, shape (n,)
        POI centres, px.
    exx, eyy, exy : ndarray
        Strain components of ``kind``.
    e1, e2, angle : ndarray
        Principal strains (``e1 >= e2``) and the angle of ``e1`` from +x towards +y, rad.
    sigma_exx, sigma_eyy, sigma_exy, sigma_e1, sigma_e2, sigma_angle : ndarray or None
        Predicted standard uncertainties (noise and blur), None without displacement
        sigmas. The principal ones are linearised: meaningless where ``e1 - e2`` is not
        large against them.
    sigma_exx_noise, sigma_exx_blur : ndarray or None
        The noise and the blur part of ``sigma_exx`` (blur: None without blur shifts).
    cov : ndarray, shape (..., n, 3, 3), or None
        Covariance of ``(exx, eyy, exy)`` (noise + blur).
    status : ndarray of uint8
        :class:`StrainStatus` codes.
    window : ndarray of int
        Window size N actually fitted (0: none).
    vsg : float
        Virtual strain gauge of the full window, px: ``(window - 1) step + subset``.
    kind, method : str
    step, subset : int
        Grid step and subset size, px.
    """

    rows: Int64Array
    cols: Int64Array
    exx: Float64Array
    eyy: Float64Array
    exy: Float64Array
    e1: Float64Array
    e2: Float64Array
    angle: Float64Array
    sigma_exx: Float64Array | None
    sigma_eyy: Float64Array | None
    sigma_exy: Float64Array | None
    sigma_e1: Float64Array | None
    sigma_e2: Float64Array | None
    sigma_angle: Float64Array | None
    sigma_exx_noise: Float64Array | None
    sigma_exx_blur: Float64Array | None
    cov: Float64Array | None
    status: UInt8Array
    window: Int64Array
    vsg: float
    kind: str
    method: str
    step: int
    subset: int

    def variables(self) -> dict[str, NDArray[Any]]:
        """The per-point arrays by name (``exx`` ... ``strain_status``), for a Dataset
        or a CSV beside ``u``, ``v``."""
        out: dict[str, NDArray[Any]] = {
            "exx": self.exx,
            "eyy": self.eyy,
            "exy": self.exy,
            "e1": self.e1,
            "e2": self.e2,
            "principal_angle": self.angle,
        }
        for name in (
            "sigma_exx",
            "sigma_eyy",
            "sigma_exy",
            "sigma_e1",
            "sigma_e2",
            "sigma_exx_noise",
            "sigma_exx_blur",
        ):
            val = getattr(self, name)
            if val is not None:
                out[name] = val
        if self.cov is not None:
            out["cov_exx_eyy"] = self.cov[..., 0, 1]
            out["cov_exx_exy"] = self.cov[..., 0, 2]
            out["cov_eyy_exy"] = self.cov[..., 1, 2]
        out["strain_status"] = self.status
        out["strain_window"] = self.window
        return out


def grid_of(rows: NDArray[Any], cols: NDArray[Any]) -> tuple[tuple[int, int], int, int]:
    """``((n_rows, n_cols), step_row, step_col)`` of POIs that fill a regular grid in
    row-major order; :class:`InputError` otherwise (strain needs the grid)."""
    r = np.asarray(rows)
    c = np.asarray(cols)
    ur, uc = np.unique(r), np.unique(c)
    ny, nx = ur.size, uc.size
    ok = ny * nx == r.size and r.size > 0
    if ok:
        ok = bool(np.all(r.reshape(ny, nx) == ur[:, None]) and np.all(c.reshape(ny, nx) == uc))
    sr = np.diff(ur)
    sc = np.diff(uc)
    if ok and ((sr.size and np.any(sr != sr[0])) or (sc.size and np.any(sc != sc[0]))):
        ok = False
    if not ok:
        raise InputError(
            "result: the points do not fill a regular grid in row-major order; strain "
            "needs the Correlator's POI grid (no explicit points)"
        )
    return (ny, nx), int(sr[0]) if sr.size else 0, int(sc[0]) if sc.size else 0


def _principal(exx: Float64Array, eyy: Float64Array, exy: Float64Array) -> tuple[Float64Array, ...]:
    """``e1, e2, angle`` and the rows of the Jacobian of ``r = (e1 - e2) / 2`` and of the
    angle with respect to (exx, eyy, exy) (eq. 10)."""
    m = 0.5 * (exx + eyy)
    a = 0.5 * (exx - eyy)
    r = np.hypot(a, exy)
    rs = np.where(r > 0, r, np.sqrt(np.finfo(np.float64).tiny))  # r**2 stays > 0
    angle = 0.5 * np.arctan2(exy, a)
    dr = (0.5 * a / rs, -0.5 * a / rs, exy / rs)
    r2 = rs**2
    dth = (-0.25 * exy / r2, 0.25 * exy / r2, 0.5 * a / r2)
    return m + r, m - r, angle, *dr, *dth


def strain_on_grid(
    u: FloatArray,
    v: FloatArray,
    valid: BoolArray,
    *,
    step: int,
    subset: int,
    window: int = 5,
    kind: Kind = "green-lagrange",
    sigma_u: FloatArray | None = None,
    sigma_v: FloatArray | None = None,
    shift_u: FloatArray | None = None,
    shift_v: FloatArray | None = None,
    gradients: tuple[FloatArray, ...] | None = None,
    rows: NDArray[Any] | None = None,
    cols: NDArray[Any] | None = None,
    with_principal_sigma: bool = True,
    with_covariance: bool = True,
) -> StrainField:
    """Strains and their covariance of fields on a grid (the engine of :func:`strain`).

    Parameters
    ----------
    u, v : ndarray, shape (..., n_rows, n_cols)
        Displacements, px (leading axes: e.g. frames).
    valid : ndarray of bool, same shape
        Trusted points.
    step, subset : int
        Grid step and subset size, px.
    window : int
        Odd window size N (grid points) of the plane fit, >= 3.
    kind : {"green-lagrange", "small"}
    sigma_u, sigma_v : ndarray, same shape, optional
        Noise part of each point's displacement sigma, px (the noise errors of
        overlapping subsets correlate, eq. 4).
    shift_u, shift_v : ndarray, same shape, optional
        Signed blur-mismatch shift of each point, px (a deterministic error, eq. 6).
    gradients : (ux, uy, vx, vy), optional
        The subsets' own gradients (affine shape function) instead of the plane fit:
        ``method="subset"``; the noise sigma of a gradient is then taken as
        ``sigma_u / sqrt(mean(dx**2))`` over the subset (eq. 9).
    rows, cols : ndarray, optional
        POI centres (px) to record.
    with_principal_sigma : bool
        Also the (linearised) sigmas of ``e1``, ``e2`` and the angle (needs
        ``with_covariance``).
    with_covariance : bool
        Also the (..., n, 3, 3) covariance (False: the sigmas alone, less memory).

    Returns
    -------
    StrainField
        Arrays flattened over the grid to (..., n).
    """
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    valid = np.asarray(valid, bool) & np.isfinite(u) & np.isfinite(v)
    if u.shape != v.shape or u.shape != valid.shape or u.ndim < 2:
        raise InputError(
            f"u, v, valid: expected arrays of one (..., rows, cols) shape, got {u.shape}, "
            f"{v.shape}, {valid.shape}"
        )
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 3:
        raise InputError(f"window={window!r}: use an odd number of grid points >= 3 (e.g. 5)")
    if window % 2 == 0:
        raise InputError(f"window={window!r}: the window must be odd (use {window + 1})")
    if kind not in ("green-lagrange", "small"):
        raise InputError(f"kind={kind!r}: use 'green-lagrange' or 'small'")
    if not (step > 0 and subset > 0):
        raise InputError(f"step={step!r}, subset={subset!r}: both must be > 0 px")
    half = int(window) // 2
    sigmas = sigma_u is not None and sigma_v is not None
    blur = sigmas and shift_u is not None and shift_v is not None
    shape3 = (-1, *u.shape[-2:])
    s2u = np.zeros(u.shape) if not sigmas else np.nan_to_num(np.asarray(sigma_u, np.float64) ** 2)
    s2v = np.zeros(u.shape) if not sigmas else np.nan_to_num(np.asarray(sigma_v, np.float64) ** 2)
    grad = np.empty((*u.shape, N_GRAD))
    if gradients is None:
        method = "fit"
        use = choose_half(valid, half)
        xu = np.nan_to_num(np.asarray(shift_u, np.float64)) if blur else np.zeros((1, 1, 1))
        xv = np.nan_to_num(np.asarray(shift_v, np.float64)) if blur else np.zeros((1, 1, 1))
        kern = stacked_kernels(half, float(step), int(subset))
        fields = WindowFields(
            np.where(valid, u, 0.0).reshape(shape3),
            np.where(valid, v, 0.0).reshape(shape3),
            use.reshape(shape3),
            s2u.reshape(shape3),
            s2v.reshape(shape3),
            xu.reshape(shape3) if blur else xu,
            xv.reshape(shape3) if blur else xv,
        )
        window_pass(fields, blur, kern, grad.reshape(*shape3, N_GRAD))
        n_used = np.where(use > 0, 2 * use + 1, 0)
        full = use == half
    else:
        # eq. 9: the affine subset's gradients from its own pixels, independent points
        method = "subset"
        use = valid.astype(np.int64)
        hs = subset // 2
        mean_d2 = hs * (hs + 1) / 3.0
        for i, g in enumerate(gradients):
            grad[..., i] = np.asarray(g, np.float64)
        grad[..., 4] = grad[..., 5] = s2u / mean_d2
        grad[..., 7] = grad[..., 8] = s2v / mean_d2
        grad[..., 6] = grad[..., 9] = 0.0
        grad[..., 10:] = 0.0
        grad[~valid] = np.nan
        n_used = use
        full = valid
    res = np.empty((*u.shape, N_OUT))
    measure_pass(grad.reshape(-1, N_GRAD), kind == "green-lagrange", res.reshape(-1, N_OUT))
    exx, eyy, exy = res[..., 0], res[..., 1], res[..., 2]
    status = np.where(full, StrainStatus.OK, StrainStatus.REDUCED_WINDOW).astype(np.uint8)
    status[use == 0] = StrainStatus.NO_WINDOW
    status[~valid] = StrainStatus.POINT_FAILED
    e1, e2, ang, *jac = _principal(exx, eyy, exy)
    names = (
        "sigma_exx",
        "sigma_eyy",
        "sigma_exy",
        "sigma_e1",
        "sigma_e2",
        "sigma_angle",
        "sigma_exx_noise",
        "sigma_exx_blur",
        "cov",
    )
    out_sig: dict[str, Any] = dict.fromkeys(names)
    if sigmas and not with_covariance:
        for i, name in enumerate(("sigma_exx", "sigma_eyy", "sigma_exy")):
            var = res[..., 3 + i] + (res[..., 9 + i] ** 2 if blur else 0.0)
            out_sig[name] = np.sqrt(np.clip(var, 0.0, None))
        out_sig["sigma_exx_noise"] = np.sqrt(np.clip(res[..., 3], 0.0, None))
        if blur:
            out_sig["sigma_exx_blur"] = np.abs(res[..., 9])
    if sigmas and with_covariance:
        # eq. 8: the noise covariance plus the outer product of the signed blur errors
        cov = np.empty((*u.shape, 3, 3))
        for m, (a, b) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
            val = res[..., 3 + m] + (res[..., 9 + a] * res[..., 9 + b] if blur else 0.0)
            cov[..., a, b] = val
            cov[..., b, a] = val
        out_sig["cov"] = cov
        d = np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1), 0.0, None))
        out_sig["sigma_exx"], out_sig["sigma_eyy"], out_sig["sigma_exy"] = (
            d[..., 0],
            d[..., 1],
            d[..., 2],
        )
        out_sig["sigma_exx_noise"] = np.sqrt(np.clip(res[..., 3], 0.0, None))
        if blur:
            out_sig["sigma_exx_blur"] = np.abs(res[..., 9])
    if sigmas and with_covariance and with_principal_sigma:
        dr = np.stack(jac[:3], axis=-1)
        dth = np.stack(jac[3:], axis=-1)
        mid = np.array([0.5, 0.5, 0.0])
        for name, row in (("sigma_e1", mid + dr), ("sigma_e2", mid - dr), ("sigma_angle", dth)):
            var = np.einsum("...a,...ab,...b->...", row, out_sig["cov"], row)
            out_sig[name] = np.sqrt(np.clip(var, 0.0, None))
    ny, nx = u.shape[-2:]
    front = u.shape[:-2]

    def flat(a: Any) -> Any:
        if a is None:
            return None
        a = np.asarray(a)
        return a.reshape(*front, ny * nx, *a.shape[u.ndim :])

    if rows is None or cols is None:
        rr, cc = np.meshgrid(np.arange(ny) * step, np.arange(nx) * step, indexing="ij")
        rows, cols = rr.ravel(), cc.ravel()
    return StrainField(
        rows=np.asarray(rows, np.int64),
        cols=np.asarray(cols, np.int64),
        exx=flat(exx),
        eyy=flat(eyy),
        exy=flat(exy),
        e1=flat(e1),
        e2=flat(e2),
        angle=flat(ang),
        **{k: flat(val) for k, val in out_sig.items()},
        status=flat(status),
        window=flat(n_used),
        vsg=vsg(window if method == "fit" else 1, step, subset),
        kind=kind,
        method=method,
        step=int(step),
        subset=int(subset),
    )


def strain(
    result: DICResult,
    *,
    window: int = 5,
    kind: Kind = "green-lagrange",
    method: Method = "fit",
) -> StrainField:
    """Strain field of a DIC result, with its predicted uncertainty.

    Parameters
    ----------
    result : DICResult
        A field on the Correlator's POI grid. Only ``CONVERGED`` points are used.
    window : int
        Odd number N of grid points on a side of the plane fit (the VSG is
        ``(N - 1) step + subset`` px). Points whose window holds a failed point use the
        largest complete smaller window (status ``REDUCED_WINDOW``) or get NaN
        (``NO_WINDOW``, ``POINT_FAILED``); a window never spans a failed point.
    kind : {"green-lagrange", "small"}
        Green-Lagrange (large rotations) or small (linearised) strain.
    method : {"fit", "subset"}
        ``"fit"``: local least-squares plane of ``u``, ``v`` over the window (docs/strain.md
        eq. 1). ``"subset"``: the affine subsets' own gradients (VSG = subset; needs
        ``shape="affine"``).

    Returns
    -------
    StrainField
        With sigmas and covariance when the result carries predicted sigmas (a
        Correlator with ``noise_sigma``): noise only, the errors of neighbouring subsets
        correlated through their shared pixels (docs/strain.md eq. 4-5).

    Examples
    --------
    >>> import numpy as np, dicblur
    >>> from dicblur.dic import DICResult
    >>> r, c = np.meshgrid(np.arange(7) * 10, np.arange(7) * 10, indexing="ij")
    >>> res = DICResult(rows=r.ravel(), cols=c.ravel(), u=1e-3 * c.ravel().astype(float),
    ...     v=np.zeros(49), params=np.zeros((49, 2)), zncc=np.ones(49),
    ...     iterations=np.ones(49, int), status=np.zeros(49, np.uint8), info={"subset": 21})
    >>> round(float(dicblur.strain(res, kind="small").exx[24]), 6)
    0.001
    """
    if not isinstance(result, DICResult):
        raise InputError("result: expected a dicblur.DICResult (Correlator.correlate)")
    if method not in ("fit", "subset"):
        raise InputError(f"method={method!r}: use 'fit' or 'subset'")
    (ny, nx), sr, sc = grid_of(result.rows, result.cols)
    step = int(result.info.get("step", max(sr, sc)) or max(sr, sc))
    if sr and sc and sr != sc:
        raise InputError(f"result: rows {sr} px and columns {sc} px apart; strain needs one step")
    subset = int(result.info.get("subset", 0) or 0)
    if subset <= 0:
        raise InputError("result: info has no 'subset' (px); use a Correlator's result")
    shape = (ny, nx)
    if method == "fit" and isinstance(window, int | np.integer) and not isinstance(window, bool):
        check_window_fits(int(window), shape, step=step, subset=subset)
    valid = (result.status == PointStatus.CONVERGED).reshape(shape)
    grads = None
    if method == "subset":
        if result.params.shape[1] != 6:
            raise InputError(
                "method='subset': needs the affine shape function's gradients (shape='affine')"
            )
        p = result.params
        grads = tuple(p[:, i].reshape(shape) for i in (1, 2, 4, 5))
    su = sv = None
    if result.predicted_sigma_u is not None and result.predicted_sigma_v is not None:
        su = result.predicted_sigma_u.reshape(shape)
        sv = result.predicted_sigma_v.reshape(shape)
    return strain_on_grid(
        result.u.reshape(shape),
        result.v.reshape(shape),
        valid,
        step=step,
        subset=subset,
        window=window,
        kind=kind,
        sigma_u=su,
        sigma_v=sv,
        gradients=grads,
        rows=result.rows,
        cols=result.cols,
    )
