"""Noise model of the identification: per-run variances and the start-speed term (paper Eq. 32).

Gaussian residuals, block diagonal by run with covariance ``R_r (I + g g^T)``:

* ``R_r`` [(m/s)^2] is one variance per run (``noise="per_run"``, floored at
  10 % of the median run variance) or one common variance (``"common"``);
* the rank-one term is the noise of the *measured* start speed, which the
  free run propagates through the recursion (``g = d v_pred / d v_start``
  [-], same variance as any other sample; ``start_noise=True``). Ignoring it
  made the stderr of the B' coefficients up to ~25 % too small in simulation.

Eq. 32 asks for unknown R: the estimator fits theta with R fixed (a weighted
least-squares problem), re-estimates R (and g) from the residuals with
:meth:`NoiseModel.update_R` and repeats until R changes by < 1 %
(:func:`l1b2.ident.search.alternate_noise`). Residual autocorrelation is
handled in the uncertainty (AR(1) inflation, :mod:`l1b2.ident.uncertainty`),
not here.
"""

from __future__ import annotations

import numpy as np

from .kernels import scaled_whitened, whitened

__all__ = ["NoiseModel"]


def _finite_stat(fn, x) -> float:
    """``fn`` (``np.max``, ``np.median``) of the entries of ``x`` that are not NaN, NaN when none is: the value of
    ``np.nanmax`` / ``np.nanmedian`` without their warning on an all-NaN array (a trial step whose free run blew
    up, rejected by the caller)."""
    x = np.asarray(x, float)
    x = x[~np.isnan(x)]
    return float(fn(x)) if x.size else float("nan")


class NoiseModel:
    """Gaussian residual covariance: per run ``R_r (I + g g^T)``.

    ``R_r`` is the run's measurement-noise variance (``"per_run"``, floored
    at 10 % of the median, or ``"common"``). ``g = d v_pred / d v_start`` is
    the propagation of the noise of the measured start speed into the free
    run (rank-one, same variance as every other sample); ``g = 0`` for the
    one-step criterion or ``start_noise=False``. Whitening uses
    ``(I + g g^T)^(-1/2) = I - c g g^T``, ``c = (1 - (1 + g.g)^(-1/2)) / g.g``.

    Parameters
    ----------
    run_sel : ndarray of int
        Run index (0 .. n_runs - 1) of every residual.
    n_runs : int
        Number of runs.
    mode : {"per_run", "common"}
        One variance per run or one for all.

    Attributes
    ----------
    R : ndarray, shape (n_runs,)
        Noise variance per run [(m/s)^2].
    g : ndarray or None
        Start-speed gain per residual [-] (None until :meth:`set_start_gain`).
    gg : ndarray
        ``g.g`` per run.
    """

    #: whether :meth:`weighted` whitens a matrix by the compiled loop (:func:`l1b2.ident.kernels.whitened`)
    compiled = True

    def __init__(self, run_sel, n_runs, mode):
        self.run_sel = run_sel
        self.n_runs = n_runs
        self.mode = mode
        self.n = run_sel.size
        self.counts = np.bincount(run_sel, minlength=n_runs)
        self.R = np.ones(n_runs)
        self.g = None
        self._G = None
        self.gg = np.zeros(n_runs)
        self._sqrtR = np.ones(self.n)

    def set_start_gain(self, g):
        """Set ``g = d v_pred / d v_start`` per residual (rank-one part of the covariance)."""
        g = np.asarray(g, float)
        self.g = g
        gg = np.bincount(self.run_sel, weights=g * g, minlength=self.n_runs)
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.where(gg > 0, (1.0 - 1.0 / np.sqrt(1.0 + gg)) / gg, 0.0)
        self.gg = gg
        self.cg = c[self.run_sel] * g
        self._G = None  # the sparse run-by-residual matrix of g, made when a matrix is whitened without numba

    @property
    def G(self):
        """The runs x residuals matrix with g in each residual's run row (scipy CSR, made on first use)."""
        if self._G is None:
            from scipy.sparse import csr_matrix

            self._G = csr_matrix((self.g, (self.run_sel, np.arange(self.n))), shape=(self.n_runs, self.n))
        return self._G

    def W(self, x):
        """(I + g g^T)^(-1/2) x, run by run (x: vector or matrix with residual rows).

        A vector's run sums ``G x`` come from one ``bincount`` (the same additions in the same order as the
        sparse product: equal to the last bit); a matrix's from :attr:`G`."""
        if self.g is None:
            return x
        if x.ndim == 1:
            proj = np.bincount(self.run_sel, weights=self.g * x, minlength=self.n_runs)
            return x - self.cg * proj[self.run_sel]
        proj = self.G @ x
        return x - self.cg[:, None] * proj[self.run_sel]

    def weighted(self, x):
        """Whitened and scaled: ``R^(-1/2) (I + g g^T)^(-1/2) x`` (residual rows)."""
        if x.ndim == 2 and self.g is not None and self.compiled:   # a matrix: the compiled loop if there is one
            y = whitened(x, self.run_sel, self.g, self.cg, self._sqrtR, self.n_runs)
            if y is not None:
                return y
        y = self.W(x)
        if y.ndim == 1:
            return y / self._sqrtR
        return y / self._sqrtR[:, None]

    def weighted_jacobian(self, S, rows, scale, order="C"):
        """``where(isfinite(J), J, 0)`` of ``J = weighted(S[rows]) * scale[None, :]`` in memory order ``order``.

        ``S``: a C-contiguous float64 matrix of which ``rows`` are the residual rows. With start gains and the
        compiled loops one fused pass (:func:`l1b2.ident.kernels.scaled_whitened`, the same values to the last
        bit), else these numpy steps.
        """
        if self.g is not None and self.compiled:
            out = scaled_whitened(S, rows, self.run_sel, self.g, self.cg, self._sqrtR, self.n_runs, scale, order)
            if out is not None:
                return out
        J = self.weighted(S[rows])
        J *= scale[None, :]
        if not np.all(np.isfinite(J)):
            J = np.where(np.isfinite(J), J, 0.0)
        return np.asarray(J, order=order)

    def update_R(self, r):
        """ML variances from the whitened residuals; returns the max relative change."""
        w = self.W(r)
        ss = np.bincount(self.run_sel, weights=w * w, minlength=self.n_runs)
        cnt = self.counts
        if self.mode == "common":
            new = np.full(self.n_runs, max(float(np.sum(ss)) / max(self.n, 1), 1e-300))
        else:
            var = np.where(cnt > 0, ss / np.maximum(cnt, 1), np.nan)
            med = _finite_stat(np.median, var) if np.any(cnt > 0) else 1.0
            if not np.isfinite(med) or med <= 0:
                med = 1e-300
            new = np.where(np.isfinite(var), np.maximum(var, 0.1 * med), med)
        with np.errstate(divide="ignore", invalid="ignore"):
            change = _finite_stat(np.max, np.abs(new / self.R - 1.0))
        self.R = new
        self._sqrtR = np.sqrt(new[self.run_sel])
        return change

    def loglik(self, r):
        """Gaussian log-likelihood of the residuals ``r`` [m/s] under (R, g)."""
        w = self.W(r)
        quad = np.bincount(self.run_sel, weights=w * w, minlength=self.n_runs)
        has = self.counts > 0
        R = self.R[has]
        return float(
            -0.5 * np.sum(self.counts[has] * np.log(2 * np.pi * R) + np.log1p(self.gg[has]) + quad[has] / R)
        )
