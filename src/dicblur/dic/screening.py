"""Screening of a Correlator's IC-GN results: the a-posteriori tests (``HIGH_RESIDUAL``,
``OUTLIER``) and the predicted-imprecise subsets (``IMPRECISE``); docs/dic.md, "Screening
for false convergence"."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .outliers import MEDIAN_EPS, MEDIAN_THRESHOLD, median_screen
from .passes import IcgnPasses
from .status import PointStatus

__all__ = ["MAX_PREDICTED_SIGMA", "PROBE_CHI2", "PROBE_DISTANCE", "Screening"]

#: ``OUTLIER`` when the neighbours' median displacement fits a subset better than its own
#: result by more than this chi-square gain (``Df^2 (zncc_nb - zncc) / sigma^2``; 0 or less
#: at a true optimum): IC-GN stopped at a false optimum.
PROBE_CHI2 = 10.0
#: Only POIs farther than this (px) from their neighbours' median are probed.
PROBE_DISTANCE = 0.05
#: Default ``max_predicted_sigma`` (px): a subset whose predicted random error (the
#: magnitude ``hypot(predicted_sigma_u, predicted_sigma_v)``) exceeds it is ``IMPRECISE``;
#: at 0.1/3 px an error beyond 0.1 px is a 3-sigma event.
MAX_PREDICTED_SIGMA = 0.1 / 3


class Screening(IcgnPasses):
    """The statuses of a Correlator's results after IC-GN."""

    def _flag(
        self,
        coef: NDArray[np.float32],
        p: NDArray[np.float64],
        z: NDArray[np.float64],
        st: NDArray[np.uint8],
    ) -> float | None:
        """The statuses after IC-GN, in place: :meth:`_screen`, then ``IMPRECISE``;
        returns the screen's noise variance (or None)."""
        noise_var = self._screen(coef, p, z, st)
        if self._imprecise is not None:
            # a predicted-imprecise subset stopped at its (reduced) limit: imprecision is the
            # cause, so it gets that status too
            done = (st == PointStatus.CONVERGED) | (st == PointStatus.MAX_ITERATIONS)
            st[done & self._imprecise] = PointStatus.IMPRECISE
        return noise_var

    def _screen(
        self,
        coef: NDArray[np.float32],
        p: NDArray[np.float64],
        z: NDArray[np.float64],
        st: NDArray[np.uint8],
    ) -> float | None:
        """Flag false convergence in place: ``HIGH_RESIDUAL``, then ``OUTLIER``.

        Returns the noise variance (GL^2) the tests used, or None when none ran.

        Residual: at the true match, with independent noise of std sigma in both images,
        ``1 - zncc ~ sigma^2 m / Df^2`` with ``m = npx - k - 2`` (ZNSSD ``C = 2 (1 - zncc)``,
        the residual being the difference of the two noises after removing mean, gain and
        the ``k`` fitted parameters). The noise variance used is the larger of
        ``noise_sigma^2`` and the field's median of ``(1 - zncc) Df^2 / m`` (so a blurred
        or otherwise mismatched pair, whose every subset exceeds the noise, is not flagged
        as a whole). The interpolation of the current image slightly smooths its noise,
        so the prediction is conservative (up to ~10 % high at half-pixel shifts).
        """
        ok = st == PointStatus.CONVERGED
        residual = self.max_residual is not None and self.noise_sigma is not None
        if not ok.any() or not (residual or self.median_test):
            return None
        k = p.shape[1]
        fnorm2 = self._prep.fnorm**2
        m = self.subset * self.subset - k - 2
        unit = np.maximum(1.0 - z, 0.0) * fnorm2 / m
        noise_var = float(np.median(unit[ok]))
        if self.noise_sigma is not None:
            noise_var = max(noise_var, self.noise_sigma**2)
        if self.max_residual is not None and self.noise_sigma is not None and noise_var > 0:
            high = ok & (unit > self.max_residual * noise_var)
            st[high] = PointStatus.HIGH_RESIDUAL
            ok &= ~high
        if not self.median_test or self._grid_shape is None or not ok.any():
            return noise_var
        assert self._grid_index is not None
        shape, cell = self._grid_shape, self._grid_index
        ucol, vcol = 0, 1 if k == 2 else 3
        # (k, ny, nx) with u, v first: the components the median test looks at
        order = [ucol, vcol] + [j for j in range(k) if j not in (ucol, vcol)]
        grid = np.full((k, shape[0] * shape[1]), np.nan)
        grid[:, cell] = np.where(ok, p[:, order].T, np.nan)
        valid = np.zeros(shape[0] * shape[1], bool)
        valid[cell] = ok
        # points within PROBE_DISTANCE of their neighbours' median skip the median (and the
        # probe): the shortcut of median_screen
        out2, med_g = median_screen(
            grid.reshape(k, *shape),
            valid.reshape(shape),
            eps=MEDIAN_EPS,
            threshold=MEDIAN_THRESHOLD,
            within=PROBE_DISTANCE / np.sqrt(2.0),
        )
        out = out2.ravel()[cell]
        st[out] = PointStatus.OUTLIER
        ok &= ~out
        # probe: a POI far from its neighbours' median is evaluated (one IC-GN iteration,
        # which reports the ZNCC at its start) at the neighbours' median parameters; a
        # clearly better fit there means IC-GN stopped at a false optimum
        med = np.empty((len(cell), k))
        med[:, order] = med_g.reshape(k, -1)[:, cell].T
        dist = np.hypot(p[:, ucol] - med[:, ucol], p[:, vcol] - med[:, vcol])
        with np.errstate(invalid="ignore"):
            probe = np.flatnonzero(ok & (dist > PROBE_DISTANCE))
        if probe.size and noise_var > 0:
            _, zp, _, _ = self._run_icgn(coef, med[probe], self._status0[probe], probe, 1)
            with np.errstate(invalid="ignore"):
                gain = fnorm2[probe] * (zp - z[probe]) / noise_var
            st[probe[gain > PROBE_CHI2]] = PointStatus.OUTLIER
        return noise_var
