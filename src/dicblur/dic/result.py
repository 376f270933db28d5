"""The DIC result: a value object with summary, xarray and CSV export."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import BoolArray, Float64Array, Int64Array, UInt8Array
from ..errors import InputError, StoreError
from ..io import atomic_open
from .status import PointStatus

__all__ = ["PARAM_NAMES", "DICResult"]

#: Names of the shape parameters, by number of parameters.
PARAM_NAMES = {2: ("u", "v"), 6: ("u", "du_dx", "du_dy", "v", "dv_dx", "dv_dy")}


def _nanstat(fn: Any, x: Float64Array) -> float:
    return float(fn(x)) if x.size else float("nan")


@dataclass(frozen=True)
class DICResult:
    """Displacements of a set of points of interest (POIs).

    Attributes
    ----------
    rows, cols : ndarray of int, shape (n,)
        POI centres in the reference image, px (row, col).
    u, v : ndarray, shape (n,)
        Displacement along x (columns) and y (rows), px. NaN where the status is
        ``LOW_TEXTURE``, ``OUT_OF_BOUNDS`` or ``DIVERGED``.
    params : ndarray, shape (n, k)
        Shape parameters: ``(u, v)`` (translation) or ``(u, du/dx, du/dy, v, dv/dx, dv/dy)``
        (affine; gradients dimensionless).
    zncc : ndarray, shape (n,)
        Zero-normalised cross-correlation of the final match (-1..1).
    iterations : ndarray of int, shape (n,)
        IC-GN iterations used.
    status : ndarray of uint8, shape (n,)
        :class:`~dicblur.dic.PointStatus` codes; 0 is converged.
    predicted_sigma_u, predicted_sigma_v : ndarray, shape (n,), or None
        Predicted random error (std, px) per POI when a noise level was given: match score
        ``sqrt(2 sigma^2 / SSSIG)`` (translation) or the Fisher bound of the affine fit.
    info : mapping
        Settings and provenance (subset, step, shape, interpolation, noise_sigma, version).
    blur_length, blur_sigma : ndarray, shape (n,), or None
        ``blur="estimate"``: the blur length estimated per POI along the given direction
        and its standard error, px (NaN where the joint step did not converge).
    blur_identified : ndarray of bool, shape (n,), or None
        ``blur="estimate"``: the subset's texture tells its blur from the noise
        (``blur_sigma <= max_blur_sigma``); elsewhere the displacement is the one at the
        image's blur length.
    """

    rows: Int64Array
    cols: Int64Array
    u: Float64Array
    v: Float64Array
    params: Float64Array
    zncc: Float64Array
    iterations: Int64Array
    status: UInt8Array
    predicted_sigma_u: Float64Array | None = None
    predicted_sigma_v: Float64Array | None = None
    info: Mapping[str, Any] = field(default_factory=dict)
    blur_length: Float64Array | None = None
    blur_sigma: Float64Array | None = None
    blur_identified: BoolArray | None = None

    @property
    def converged(self) -> BoolArray:
        """Boolean mask of the POIs with status ``CONVERGED``."""
        return np.asarray(self.status == PointStatus.CONVERGED)

    def __len__(self) -> int:
        return int(self.rows.shape[0])

    def status_counts(self) -> dict[str, int]:
        """Number of POIs per status name."""
        return {s.name.lower(): int(np.count_nonzero(self.status == s)) for s in PointStatus}

    def summary(
        self, *, true_u: float | None = None, true_v: float | None = None
    ) -> dict[str, Any]:
        """Statistics over the converged POIs.

        Parameters
        ----------
        true_u, true_v : float, optional
            Known displacement (px); adds bias, RMS error and, with predicted sigmas, the
            std of ``error_i / predicted_sigma_i`` (1 at the predicted random error).

        Returns
        -------
        dict
            ``n_points``, ``n_converged``, ``converged_fraction``, ``mean_u``, ``std_u``,
            ``mean_v``, ``std_v`` (px), ``mean_zncc``, ``mean_iterations``, status counts;
            with a truth ``bias_u``, ``bias_v``, ``rms_error_u``, ``rms_error_v``; with
            predictions ``predicted_sigma_u``, ``predicted_sigma_v`` (means, px) and
            ``normalised_std_u``, ``normalised_std_v``.
        """
        ok = self.converged
        u = self.u[ok]
        v = self.v[ok]
        out: dict[str, Any] = {
            "n_points": len(self),
            "n_converged": int(ok.sum()),
            "converged_fraction": float(ok.mean()) if len(self) else float("nan"),
            "mean_u": _nanstat(np.mean, u),
            "std_u": _nanstat(lambda a: np.std(a, ddof=1) if a.size > 1 else np.nan, u),
            "mean_v": _nanstat(np.mean, v),
            "std_v": _nanstat(lambda a: np.std(a, ddof=1) if a.size > 1 else np.nan, v),
            "mean_zncc": _nanstat(np.mean, self.zncc[ok]),
            "mean_iterations": _nanstat(np.mean, self.iterations[ok].astype(float)),
        }
        if self.predicted_sigma_u is not None and self.predicted_sigma_v is not None:
            out["predicted_sigma_u"] = _nanstat(np.mean, self.predicted_sigma_u[ok])
            out["predicted_sigma_v"] = _nanstat(np.mean, self.predicted_sigma_v[ok])
        for name, truth, est, pred in (
            ("u", true_u, u, self.predicted_sigma_u),
            ("v", true_v, v, self.predicted_sigma_v),
        ):
            if truth is None:
                continue
            try:
                t = float(truth)
            except (TypeError, ValueError):
                raise InputError(
                    f"true_{name}={truth!r}: expected the true displacement, a number (px)"
                ) from None
            if not math.isfinite(t):
                raise InputError(f"true_{name}={truth!r}: must be a finite number (px)")
            err = est - t
            out[f"bias_{name}"] = _nanstat(np.mean, err)
            out[f"rms_error_{name}"] = _nanstat(lambda a: np.sqrt(np.mean(a**2)), err)
            if pred is not None and err.size > 1:
                out[f"normalised_std_{name}"] = float(np.std(err / pred[ok], ddof=1))
        out.update({f"n_{k}": c for k, c in self.status_counts().items() if k != "converged"})
        return out

    def _param_names(self) -> tuple[str, ...]:
        return PARAM_NAMES.get(
            self.params.shape[1], tuple(f"p{i}" for i in range(self.params.shape[1]))
        )

    def to_xarray(self, *, extra: Mapping[str, NDArray[Any]] | None = None) -> Any:
        """The result as an :class:`xarray.Dataset` over dimension ``point``.

        Variables ``u``, ``v``, ``params`` (point, param), ``zncc``, ``iterations``,
        ``status`` (+ ``predicted_sigma_u/v``, and the (n,) arrays of ``extra`` by name,
        e.g. strains); coordinates ``row``, ``col``; attributes hold ``info`` and the
        status legend. Write with ``.to_netcdf(path)``.
        """
        import xarray as xr

        data: dict[str, Any] = {
            "u": ("point", self.u, {"units": "px", "long_name": "displacement along x"}),
            "v": ("point", self.v, {"units": "px", "long_name": "displacement along y"}),
            "params": (("point", "param"), self.params),
            "zncc": ("point", self.zncc),
            "iterations": ("point", self.iterations.astype(np.int32)),
            "status": (
                "point",
                self.status,
                {"legend": ", ".join(f"{s.value}={s.name}" for s in PointStatus)},
            ),
        }
        if self.predicted_sigma_u is not None and self.predicted_sigma_v is not None:
            data["predicted_sigma_u"] = ("point", self.predicted_sigma_u, {"units": "px"})
            data["predicted_sigma_v"] = ("point", self.predicted_sigma_v, {"units": "px"})
        if self.blur_length is not None and self.blur_sigma is not None:
            data["blur_length"] = ("point", self.blur_length, {"units": "px"})
            data["blur_sigma"] = ("point", self.blur_sigma, {"units": "px"})
        if self.blur_identified is not None:
            data["blur_identified"] = ("point", self.blur_identified.astype(np.uint8))
        for name, values in (extra or {}).items():
            data[name] = ("point", np.asarray(values))
        attrs = {
            k: (v if isinstance(v, int | float | str) else str(v))
            for k, v in self.info.items()
            if v is not None
        }
        return xr.Dataset(
            data,
            coords={
                "row": ("point", self.rows.astype(np.int32)),
                "col": ("point", self.cols.astype(np.int32)),
                "param": list(self._param_names()),
            },
            attrs=attrs,
        )

    def to_csv(self, path: str | Path, *, extra: Mapping[str, NDArray[Any]] | None = None) -> None:
        """Write one row per POI (header: row, col, u, v, zncc, iterations, status,
        status_name, parameters, predicted sigmas, then the (n,) arrays of ``extra`` by
        name, e.g. strains) to ``path``."""
        path = Path(path)
        names = self._param_names()
        header = ["row", "col", "u", "v", "zncc", "iterations", "status", "status_name"]
        header += [f"param_{n}" for n in names]
        pred = self.predicted_sigma_u is not None and self.predicted_sigma_v is not None
        if pred:
            header += ["predicted_sigma_u", "predicted_sigma_v"]
        blur = self.blur_length is not None and self.blur_sigma is not None
        if blur:
            header += ["blur_length", "blur_sigma", "blur_identified"]
        more = {k: np.asarray(a) for k, a in (extra or {}).items()}
        header += list(more)
        try:
            with atomic_open(path, "w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(header)
                for i in range(len(self)):
                    row: list[Any] = [
                        int(self.rows[i]),
                        int(self.cols[i]),
                        repr(float(self.u[i])),
                        repr(float(self.v[i])),
                        repr(float(self.zncc[i])),
                        int(self.iterations[i]),
                        int(self.status[i]),
                        PointStatus(int(self.status[i])).name.lower(),
                    ]
                    row += [repr(float(x)) for x in self.params[i]]
                    if pred:
                        assert self.predicted_sigma_u is not None
                        assert self.predicted_sigma_v is not None
                        row += [
                            repr(float(self.predicted_sigma_u[i])),
                            repr(float(self.predicted_sigma_v[i])),
                        ]
                    if blur:
                        assert self.blur_length is not None and self.blur_sigma is not None
                        ident = self.blur_identified is not None and bool(self.blur_identified[i])
                        row += [
                            repr(float(self.blur_length[i])),
                            repr(float(self.blur_sigma[i])),
                            int(ident),
                        ]
                    row += [
                        int(a[i]) if a.dtype.kind in "iub" else repr(float(a[i]))
                        for a in more.values()
                    ]
                    w.writerow(row)
        except OSError as exc:
            raise StoreError(f"path={str(path)!r}: cannot write the CSV ({exc})") from exc
