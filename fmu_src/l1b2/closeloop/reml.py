"""Restricted maximum likelihood of a multivariate random-effects model with known sampling covariances.

The runs' deviations ``theta_r`` (p components) are ``theta_r = X_r beta + u_r + e_r``, ``u_r ~ N(0, T)`` between
runs and ``e_r ~ N(0, S_r)`` the sampling error (``S_r`` known). With ``W_r = (T + S_r)^-1``,
``C = (sum_r X_r' W_r X_r)^-1``, ``beta_hat(T) = C sum_r X_r' W_r theta_r`` and ``r_r = theta_r - X_r beta_hat``
the restricted log-likelihood is (up to a constant)
``l_R(T) = -1/2 [sum_r log|T + S_r| + log|sum_r X_r' W_r X_r| + sum_r r_r' W_r r_r]`` and its gradient, for a
symmetric ``T``, ``dl_R/dT = 1/2 sum_r [W_r r_r r_r' W_r - W_r + W_r X_r C X_r' W_r]``.

:func:`reml` maximises ``l_R`` over ``T = A L L' A'``: ``L`` lower triangular (free), ``A`` the Cholesky factor
of the runs' mean sampling covariance (the solver works in units of the sampling error). ``T`` is positive
semidefinite by construction and reaches its boundary (a variance 0, or a rank-deficient ``T``: gain and offset
perfectly correlated between runs) at a finite ``L``, a zero of its diagonal, where ``l_R`` is smooth in ``L`` (a
log-parametrised diagonal would approach it only asymptotically). The boundary's faces of lower rank are searched
too and its first-order condition is checked (:func:`_maximise`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import optimize

#: largest number of quasi-Newton iterations of the REML fit, and its convergence criterion: the largest component
#: of the gradient of ``-l_R / n`` in the Cholesky parameters (the solver aims at a hundredth of it)
REML_ITER = 400
REML_TOL = 1e-6
#: the boundary's first-order condition: largest eigenvalue of the whitened ``dl_R/dT / n`` at the solution; and how
#: often the search starts again along a direction that violates it
KKT_TOL = 1e-6
KKT_RESTARTS = 3
#: L-BFGS iterations between two looks at the boundary, and the relative eigenvalue of the whitened ``T`` below which
#: its face of lower rank is searched too
FULL_CHUNK = 50
FACE_REL = 1e-3


@dataclass
class REMLFit:
    """A random-effects fit: ``T`` between-run covariance, ``beta`` the mean's coefficients with covariance
    ``beta_cov``, ``blup`` each run's shrunk deviation, ``iterations`` of the optimiser and whether it
    ``converged`` (the gradient and boundary criteria of :func:`_maximise` met before the iteration cap)."""

    T: np.ndarray
    beta: np.ndarray
    beta_cov: np.ndarray
    blup: np.ndarray
    iterations: int
    converged: bool = True


def design_rows(z: np.ndarray | None, n: int, p: int) -> np.ndarray:
    """The mean's design per run, ``(n, p, p * q)``: ``I_p (x) [1, z_r...]`` (``z`` (n, q) or None: intercepts)."""
    x = np.ones((n, 1)) if z is None else np.column_stack([np.ones(n), np.asarray(z, float).reshape(n, -1)])
    return np.einsum("ij,rk->rijk", np.eye(p), x).reshape(n, p, p * x.shape[1])


def _gls(theta, S, X, T):
    """``(W, C, beta, r, WX, A)`` at ``T``: the runs' weights, the mean's covariance, its estimate, the residuals,
    ``W_r X_r`` and ``sum_r X_r' W_r X_r``."""
    W = np.linalg.inv(T[None] + S)
    WX = W @ X
    A = np.einsum("rpk,rpj->kj", X, WX)
    C = np.linalg.inv(A)
    beta = C @ np.einsum("rpk,rp->k", WX, theta)
    return W, C, beta, theta - X @ beta, WX, A


def restricted_loglik(theta, S, X, T) -> tuple[float, np.ndarray]:
    """``(l_R, dl_R/dT)`` of the module's formulas at ``T`` (``theta`` (n, p), ``S`` (n, p, p), ``X`` (n, p, k));
    ``l_R`` is ``-inf`` when ``T + S_r`` or ``X' W X`` is not positive definite."""
    sv, ldv = np.linalg.slogdet(T[None] + S)
    W, C, _, r, WX, A = _gls(theta, S, X, T)
    sa, lda = np.linalg.slogdet(A)
    if np.any(sv <= 0) or sa <= 0:
        return -np.inf, np.zeros_like(T)
    Wr = (W @ r[:, :, None])[:, :, 0]
    ll = -0.5 * (float(np.sum(ldv)) + float(lda) + float(np.sum(r * Wr)))
    G = 0.5 * (Wr.T @ Wr - W.sum(axis=0) + np.einsum("rpk,rqk->pq", WX @ C, WX))
    return ll, 0.5 * (G + G.T)


@functools.lru_cache(maxsize=None)
def _lower(p: int) -> tuple:
    """The lower triangle's indices of a ``p x p`` matrix, row by row."""
    return np.tril_indices(p)


def _factor(x: np.ndarray, p: int, q: int) -> np.ndarray:
    """The factor ``B`` of the parameters ``x``: lower triangular ``p x p`` (row by row) when ``q == p``, else a
    full ``p x q`` matrix (a face of rank ``q``)."""
    if q == p:
        B = np.zeros((p, p))
        B[_lower(p)] = x
        return B
    return np.asarray(x, float).reshape(p, q)


def _params(B: np.ndarray) -> np.ndarray:
    """The parameters of a factor (:func:`_factor`'s inverse)."""
    p, q = B.shape
    return B[_lower(p)] if q == p else B.ravel()


def _objective(x, theta, S, X, A, q: int | None = None):
    """``-l_R / n`` and its gradient in the factor's parameters ``x`` (``T = A B B' A'``, :func:`_factor`;
    ``q`` None: the full rank's lower-triangular ``B``)."""
    n, p = theta.shape
    B = _factor(x, p, p if q is None else q)
    AB = A @ B
    ll, G = restricted_loglik(theta, S, X, AB @ AB.T)
    if not np.isfinite(ll):
        return np.inf, np.zeros_like(x)
    return -ll / n, -_params(2.0 * A.T @ G @ AB) / n


def reml(theta: np.ndarray, cov: np.ndarray, X: np.ndarray | None = None, *, n_iter: int = REML_ITER,
         tol: float = REML_TOL) -> REMLFit:
    """Restricted maximum likelihood of ``theta_r = X_r beta + u_r + e_r`` (``theta`` (n, p), ``cov`` (n, p, p)
    the sampling covariances ``S_r``, ``X`` (n, p, k) the mean's design, default intercepts): ``T`` maximises the
    module's ``l_R`` (:func:`_maximise`), ``beta`` and ``beta_cov`` are the generalised least squares at ``T`` and
    each run's ``blup`` is ``X_r beta + T W_r (theta_r - X_r beta)``.

    Start from above: ``T`` diagonal, the mean squared residuals of the unweighted least-squares mean. Scalar,
    equal ``S_r = s2``, intercept only: ``T = max(0, var(theta, ddof=1) - s2)``.
    """
    theta = np.asarray(theta, float)
    n, p = theta.shape
    X = design_rows(None, n, p) if X is None else np.asarray(X, float)
    S = np.asarray(cov, float)
    r0 = theta - np.einsum("rpk,k->rp", X, np.linalg.lstsq(X.reshape(-1, X.shape[2]), theta.ravel(), rcond=None)[0])
    A = _whitener(S)
    Ai = np.linalg.inv(A)
    T, iterations, converged = _maximise(theta, S, X, A, Ai @ np.diag(np.mean(r0 ** 2, axis=0)) @ Ai.T, n_iter, tol)
    W, C, beta, r = _gls(theta, S, X, T)[:4]
    blup = theta - r + np.einsum("pq,rqs,rs->rp", T, W, r)
    return REMLFit(T, beta, C, blup, iterations, converged)


def _search(theta, S, X, A, B0: np.ndarray, maxiter: int, tol: float) -> tuple:
    """``(Tw, iterations, gradient_ok, l_R, dl_R/dT)``: L-BFGS on the factor ``B`` (``Tw = B B'``) from ``B0``."""
    p, q = B0.shape
    opt = optimize.minimize(_objective, _params(B0), args=(theta, S, X, A, q), jac=True, method="L-BFGS-B",
                            options={"maxiter": max(maxiter, 1), "maxfun": 5 * max(maxiter, 1) + 20,
                                     "gtol": 1e-2 * tol, "ftol": 1e-15})
    B = _factor(opt.x, p, q)
    ll, G = restricted_loglik(theta, S, X, A @ B @ B.T @ A.T)
    return B @ B.T, int(opt.nit), bool(np.max(np.abs(opt.jac), initial=0.0) <= tol), ll, G


def _lower_factor(Tw: np.ndarray) -> np.ndarray:
    """A lower-triangular ``L`` with ``L L' = Tw`` for a positive semidefinite ``Tw`` (negative eigenvalues of
    rounding set to 0): ``R'`` of the QR decomposition of ``(U sqrt(lambda))'``; a zero direction of ``Tw`` stays
    an exact zero of ``L``."""
    lam, U = np.linalg.eigh(0.5 * (Tw + Tw.T))
    return np.linalg.qr((U * np.sqrt(np.maximum(lam, 0.0))).T, mode="r").T


def _kkt(A, G, n: int) -> tuple[float, np.ndarray]:
    """The largest eigenvalue of the whitened ``A' dl_R/dT A / n`` and its eigenvector."""
    lam, vec = np.linalg.eigh(A.T @ G @ A / n)
    return float(lam[-1]), vec[:, -1]


def _maximise(theta, S, X, A, Tw, n_iter: int, tol: float) -> tuple[np.ndarray, int, bool]:
    """``(T, iterations, converged)``: ``l_R``'s maximum over ``T = A Tw A'`` from the whitened ``Tw``.

    L-BFGS with the analytic gradient on the lower-triangular ``L`` of ``Tw = L L'`` (at most :data:`FULL_CHUNK`
    iterations at a time, ``n_iter`` in all), aiming at a gradient of ``-l_R / n`` below ``tol / 100``. Converged:
    fewer than ``n_iter`` iterations, the gradient's largest component at most ``tol`` and the boundary's
    first-order condition, no direction ``v`` in which ``l_R`` grows as ``T + s A v v' A'`` (``s >= 0``): the
    largest eigenvalue of ``A' dl_R/dT A / n`` at most :data:`KKT_TOL`.

    After each stretch, when ``Tw`` has eigenvalues below :data:`FACE_REL` times ``max(1, its largest)`` (the
    sampling error's unit), the face of the lower rank is searched as well (``Tw = B B'``, ``B`` ``p x q``; rank 0:
    ``T = 0``) and kept when its ``l_R`` is at least as high and it meets the criteria: an optimum on the boundary
    where ``l_R`` is flat across it is approached in ``L`` only slowly. A point that meets the gradient criterion
    but not the boundary's (at a zero column of ``L`` the gradient in it vanishes whichever way ``l_R`` goes, a
    saddle) is left along the violating direction, ``Tw + s v v'`` (``s`` the largest of 1, 0.1, 0.01 times
    ``Tw``'s scale that raises ``l_R``), at most :data:`KKT_RESTARTS` times.
    """
    n, p = theta.shape
    used, restarts = 0, 0
    while True:
        Tw, it, grad_ok, ll, G = _search(theta, S, X, A, _lower_factor(Tw), min(FULL_CHUNK, n_iter - used), tol)
        used += max(it, 1)             # every stretch counts: the cap bounds the loop
        lam, v = _kkt(A, G, n)
        if grad_ok and lam <= KKT_TOL and used < n_iter:
            return A @ Tw @ A.T, used, True
        ev, U = np.linalg.eigh(Tw)
        big = ev > FACE_REL * max(float(ev[-1]), 1.0)
        if not big.all():
            if big.any():
                Tf, it, f_ok, llf, Gf = _search(theta, S, X, A, U[:, big] * np.sqrt(ev[big]), n_iter - used, tol)
                used += max(it, 1)             # every stretch counts: the cap bounds the loop
            else:
                Tf, f_ok = np.zeros((p, p)), True
                llf, Gf = restricted_loglik(theta, S, X, np.zeros((p, p)))
            if llf >= ll and f_ok and _kkt(A, Gf, n)[0] <= KKT_TOL and used < n_iter:
                return A @ Tf @ A.T, used, True
        if used >= n_iter:
            return A @ Tw @ A.T, used, False
        if grad_ok:                        # a saddle: leave it along the direction that raises l_R
            restarts += 1
            scale = max(float(np.trace(Tw)) / p, 1.0)
            up = [Tw + st * scale * np.outer(v, v) for st in (1.0, 0.1, 0.01)]
            up = [t for t in up if restricted_loglik(theta, S, X, A @ t @ A.T)[0] > ll]
            if restarts > KKT_RESTARTS or not up:
                return A @ Tw @ A.T, used, False
            Tw = up[0]


def _whitener(S: np.ndarray) -> np.ndarray:
    """``A`` with ``A A'`` the runs' mean sampling covariance (its Cholesky factor; the diagonal's square root when
    that is not positive definite): the solver's ``T = A L L' A'`` is in units of the sampling error."""
    M = np.mean(S, axis=0)
    try:
        return np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        return np.diag(np.sqrt(np.maximum(np.diag(M), 1e-300)))
