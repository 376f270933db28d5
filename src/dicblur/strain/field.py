"""``dicblur.strain``: strain fields and their covariance from a displacement field."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..dic.result import DICResult
from ..dic.status import PointStatus
from ..errors import InputError
from .covariance import Kind, gradient_covariance, strain_covariance, strains
from .fit import GridGradients, grid_gradients

__all__ = ["StrainField", "StrainStatus", "grid_of", "strain", "strain_on_grid", "vsg"]

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

    rows: NDArray[np.int64]
    cols: NDArray[np.int64]
    exx: NDArray[np.float64]
    eyy: NDArray[np.float64]
    exy: NDArray[np.float64]
    e1: NDArray[np.float64]
    e2: NDArray[np.float64]
    angle: NDArray[np.float64]
    sigma_exx: NDArray[np.float64] | None
    sigma_eyy: NDArray[np.float64] | None
    sigma_exy: NDArray[np.float64] | None
    sigma_e1: NDArray[np.float64] | None
    sigma_e2: NDArray[np.float64] | None
    sigma_angle: NDArray[np.float64] | None
    sigma_exx_noise: NDArray[np.float64] | None
    sigma_exx_blur: NDArray[np.float64] | None
    cov: NDArray[np.float64] | None
    status: NDArray[np.uint8]
    window: NDArray[np.int64]
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


def _principal(
    exx: NDArray[np.float64], eyy: NDArray[np.float64], exy: NDArray[np.float64]
) -> tuple[NDArray[np.float64], ...]:
    """``e1, e2, angle`` and the rows of their Jacobian with respect to (exx, eyy, exy)."""
    m = 0.5 * (exx + eyy)
    a = 0.5 * (exx - eyy)
    r = np.hypot(a, exy)
    rs = np.where(r > 0, r, np.finfo(np.float64).tiny)
    angle = 0.5 * np.arctan2(exy, a)
    # d r / d(exx, eyy, exy) = (a / 2r, -a / 2r, exy / r)
    dr = (0.5 * a / rs, -0.5 * a / rs, exy / rs)
    # angle = atan2(exy, a) / 2: d/d a = -exy / (2 r^2), d/d exy = a / (2 r^2)
    r2 = rs**2
    dth = (-0.25 * exy / r2, 0.25 * exy / r2, 0.5 * a / r2)
    return m + r, m - r, angle, *dr, *dth


def strain_on_grid(
    u: NDArray[np.floating[Any]],
    v: NDArray[np.floating[Any]],
    valid: NDArray[np.bool_],
    *,
    step: int,
    subset: int,
    window: int = 5,
    kind: Kind = "green-lagrange",
    sigma_u: NDArray[np.floating[Any]] | None = None,
    sigma_v: NDArray[np.floating[Any]] | None = None,
    shift_u: NDArray[np.floating[Any]] | None = None,
    shift_v: NDArray[np.floating[Any]] | None = None,
    gradients: tuple[NDArray[np.floating[Any]], ...] | None = None,
    rows: NDArray[Any] | None = None,
    cols: NDArray[Any] | None = None,
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
    if not (isinstance(window, int | np.integer) and window >= 3 and window % 2 == 1):
        raise InputError(f"window={window!r}: use an odd number of grid points >= 3 (e.g. 5)")
    if kind not in ("green-lagrange", "small"):
        raise InputError(f"kind={kind!r}: use 'green-lagrange' or 'small'")
    if not (step > 0 and subset > 0):
        raise InputError(f"step={step!r}, subset={subset!r}: both must be > 0 px")
    half = window // 2
    sigmas = sigma_u is not None and sigma_v is not None
    if gradients is None:
        method = "fit"
        grad = grid_gradients(u, v, valid, half=half, step=step)
        n_used = np.where(grad.half > 0, 2 * grad.half + 1, 0)
        full = grad.half == half
    else:
        method = "subset"
        gs = [np.where(valid, np.asarray(g, np.float64), np.nan) for g in gradients]
        grad = GridGradients(*gs, half=valid.astype(np.int64))
        n_used = valid.astype(np.int64)
        full = valid
    exx, eyy, exy = strains(grad, kind)
    status = np.where(full, StrainStatus.OK, StrainStatus.REDUCED_WINDOW).astype(np.uint8)
    status[grad.half == 0] = StrainStatus.NO_WINDOW
    status[~valid] = StrainStatus.POINT_FAILED
    e1, e2, ang, *jac = _principal(exx, eyy, exy)
    out_sig: dict[str, Any] = dict.fromkeys(
        (
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
    )
    if sigmas:
        var_u = np.asarray(sigma_u, np.float64) ** 2
        var_v = np.asarray(sigma_v, np.float64) ** 2
        if method == "fit":
            gc = gradient_covariance(
                grad, var_u, var_v, step=step, subset=subset, shift_u=shift_u, shift_v=shift_v
            )
        else:
            # eq. 9: the affine subset's gradient from its own pixels
            h = subset // 2
            mean_d2 = h * (h + 1) / 3.0
            z = np.zeros_like(var_u)
            gc = _subset_covariance(var_u / mean_d2, var_v / mean_d2, z, valid)
        sc = strain_covariance(grad, gc, kind)
        cov = np.empty((*u.shape, 3, 3))
        idx = {"xx": 0, "yy": 1, "xy": 2}
        noise_xx = sc["xx_xx"][0]
        blur_xx = sc["xx_xx"][1]
        for key, (nz, bl) in sc.items():
            a, b = (idx[p] for p in key.split("_"))
            val = nz if bl is None else nz + bl
            cov[..., a, b] = val
            cov[..., b, a] = val
        cov[~(n_used > 0)] = np.nan
        out_sig["cov"] = cov
        d = np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1), 0.0, None))
        out_sig["sigma_exx"], out_sig["sigma_eyy"], out_sig["sigma_exy"] = d[..., 0], d[..., 1], d[..., 2]
        out_sig["sigma_exx_noise"] = np.where(n_used > 0, np.sqrt(np.clip(noise_xx, 0, None)), np.nan)
        if blur_xx is not None:
            out_sig["sigma_exx_blur"] = np.where(n_used > 0, np.sqrt(blur_xx), np.nan)
        dr = np.stack(jac[:3], axis=-1)
        dth = np.stack(jac[3:], axis=-1)
        m = np.array([0.5, 0.5, 0.0])
        for name, row in (("sigma_e1", m + dr), ("sigma_e2", m - dr), ("sigma_angle", dth)):
            var = np.einsum("...a,...ab,...b->...", row, cov, row)
            out_sig[name] = np.sqrt(np.clip(var, 0.0, None))
    ny, nx = u.shape[-2:]
    lead = u.shape[:-2]

    def flat(a: Any) -> Any:
        if a is None:
            return None
        a = np.asarray(a)
        return a.reshape(*lead, ny * nx, *a.shape[u.ndim :])

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


def _subset_covariance(
    var_gu: NDArray[np.float64],
    var_gv: NDArray[np.float64],
    zero: NDArray[np.float64],
    valid: NDArray[np.bool_],
) -> Any:
    """Gradient covariance of the subset method: independent gradients (eq. 9)."""
    from .covariance import GradientCovariance

    vu = np.where(valid, var_gu, np.nan)
    vv = np.where(valid, var_gv, np.nan)
    return GradientCovariance(vu, vu, zero, vv, vv, zero)


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
