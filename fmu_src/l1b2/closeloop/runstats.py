"""The run-level statistics: a signal's place in the runs' random-effects mean, its Wald test and its
cross-validated gain.

The runs' deviations ``theta_r`` (gain, offset; :class:`l1b2.closeloop.runlevel.RunDeviations`) are a
random-effects model whose mean holds a signal ``z`` (:func:`signal_design`: on the gain and the offset, and on the
offset times the run's load; or on the gain alone, a signal of the session's own blocks or cycle). A signal's
evidence is the joint Wald test of its coefficients (:func:`joint_test`) and the held-out share of the runs'
weighted deviation that it removes over folds of the runs (:func:`cv_signal_gain`). Used by
:mod:`l1b2.closeloop.runlevel` (every signal) and by the searches over the session clock
(:mod:`l1b2.closeloop.cycle`).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from .reml import REMLFit, design_rows, reml

__all__ = ["signal_design", "identified_columns", "signal_index", "independent_columns", "null_fold_fit",
           "cv_signal_gain", "joint_test"]


def signal_design(z: np.ndarray, w: np.ndarray | None = None, gain_only: bool = False) -> np.ndarray:
    """The mean's design of a signal, ``(n, 2, 5)`` (``(n, 2, 4)`` without ``w``): gain row ``[1, z, 0, 0, 0]``,
    offset row ``[0, 0, 1, z, z w]``; coefficients ``(g0, g1, o0, o1, o2)``.

    ``z`` (n, q), q columns (a categorical signal's centred level indicators): ``(n, 2, 2 + 3 q)``, gain row
    ``[1, Z, 0, 0.., 0..]``, offset row ``[0, 0.., 1, Z, Z w]`` (:func:`signal_index`: where the signal's are).
    ``gain_only``: the signal acts on the gain alone (the session's blocks, one level each:
    :mod:`l1b2.predictor.effects.blocks`), ``(n, 2, 2 + q)``, gain row ``[1, Z, 0]``, offset row ``[0, 0.., 1]``."""
    z = np.asarray(z, float)
    n = len(z)
    Z = z.reshape(n, -1)
    one, zero = np.ones((n, 1)), np.zeros(Z.shape)
    if gain_only:
        return np.stack([np.hstack([one, Z, 0 * one]), np.hstack([0 * one, zero, one])], axis=1)
    gain = [one, Z, 0 * one, zero]
    off = [0 * one, zero, one, Z]
    if w is not None:
        gain.append(zero)
        off.append(Z * np.asarray(w, float)[:, None])
    return np.stack([np.hstack(gain), np.hstack(off)], axis=1)


def identified_columns(X: np.ndarray) -> list:
    """The columns of a mean's design ``X`` (n, p, k) that the runs identify, in order: each is kept when it is
    not in the span of the columns kept before it (numerical rank of the stacked ``(n p, k)`` design). All of them
    when the design has full rank; a categorical signal's load column of a value whose runs share one load, or whose
    runs carry no load, is not identified."""
    A = np.asarray(X, float).reshape(-1, np.shape(X)[2])
    keep: list = []
    for j in range(A.shape[1]):
        if np.linalg.matrix_rank(A[:, keep + [j]]) == len(keep) + 1:
            keep.append(j)
    return keep


def signal_index(q: int, load: bool, gain_only: bool = False) -> list:
    """The coefficients of a signal of ``q`` columns in :func:`signal_design` (gain, offset[, load] slopes):
    ``[1, 3, 4]`` for one column with the load, ``3 q`` (``2 q`` without) in all, the joint test's degrees of
    freedom; ``1 ... q`` for a signal on the gain alone (``gain_only``)."""
    gain = list(range(1, 1 + q))
    if gain_only:
        return gain
    off = list(range(2 + q, 2 + 2 * q))
    return gain + off + (list(range(2 + 2 * q, 2 + 3 * q)) if load else [])


def independent_columns(Z: np.ndarray) -> np.ndarray:
    """The columns of ``Z`` (n, q) that add to the rank of ``[1, the columns kept so far]``, in order (a fold
    whose training runs miss a level: its indicator is then constant, or the others sum to one)."""
    Z = np.asarray(Z, float).reshape(len(Z), -1)
    keep: list = []
    for j in range(Z.shape[1]):
        M = np.column_stack([np.ones(len(Z)), Z[:, keep + [j]]])
        if np.linalg.matrix_rank(M) == len(keep) + 2:
            keep.append(j)
    return np.array(keep, int)


def _weighted_sse(theta, cov, T, X, beta) -> np.ndarray:
    """Per run ``(theta_r - X_r beta)' (T + S_r)^-1 (theta_r - X_r beta)``."""
    r = theta - np.einsum("rpk,k->rp", X, beta)
    return np.einsum("rp,rpq,rq->r", r, np.linalg.inv(T[None] + cov), r)


def null_fold_fit(theta, cov, te, memo: dict | None = None) -> REMLFit:
    """The null model's (intercepts only) REML fit on the runs not in ``te`` (indices of held-out runs), as
    :func:`cv_signal_gain` fits it.

    ``memo``: a dict kept by the caller: the fit is stored under ``theta``, ``cov`` and the held-out indices
    (their values) and returned from there when they come again (every signal of one :func:`signal_evidence` is
    scored on the same folds against the same null fits)."""
    theta, cov, te = np.asarray(theta, float), np.asarray(cov, float), np.asarray(te)
    key = (theta.shape, theta.tobytes(), cov.tobytes(), te.dtype.str, te.tobytes())
    if memo is not None and key in memo:
        return memo[key]
    n, p = theta.shape
    tr = np.setdiff1d(np.arange(n), te)
    fit = reml(theta[tr], cov[tr], design_rows(None, n, p)[tr])
    if memo is not None:
        memo[key] = fit
    return fit


def cv_signal_gain(theta, cov, z, folds_idx, w=None, null_fits: dict | None = None,
                   gain_only: bool = False) -> tuple[float, np.ndarray]:
    """Held-out share of the runs' weighted deviation that the signal ``z`` removes, and the per-run reductions.

    For each fold (indices of held-out runs) the null (intercepts) and the signal's model are fitted by REML on
    the other runs; the held-out runs' weighted squared deviations (weights ``(T0 + S_r)^-1`` of the null fit,
    the same for both) are compared: gain ``1 - sum SSE1 / sum SSE0``. ``null_fits``: a memo of
    :func:`null_fold_fit` (None: every null fit computed here).
    """
    n, p = theta.shape
    Z = np.asarray(z, float).reshape(n, -1)
    X0 = design_rows(None, n, p)
    s0, s1 = np.zeros(n), np.zeros(n)
    for te in folds_idx:
        tr = np.setdiff1d(np.arange(n), te)
        X1 = signal_design(Z if Z.shape[1] == 1 else Z[:, independent_columns(Z[tr])], w, gain_only)
        X1 = X1[:, :, identified_columns(X1[tr])]
        f0 = null_fold_fit(theta, cov, te, null_fits)
        f1 = reml(theta[tr], cov[tr], X1[tr])
        s0[te] = _weighted_sse(theta[te], cov[te], f0.T, X0[te], f0.beta)
        s1[te] = _weighted_sse(theta[te], cov[te], f0.T, X1[te], f1.beta)
    gain = float(1 - s1.sum() / s0.sum()) if s0.sum() > 0 else 0.0
    return gain, (s0 - s1) / max(s0.mean(), 1e-300)


def joint_test(dev, z: np.ndarray, gain_only: bool = False) -> tuple[np.ndarray, float, int]:
    """``(b, p, dof)``: a signal's coefficients in the REML mean of :func:`signal_design` (:func:`signal_index`) of
    the runs' deviations ``dev`` (:class:`l1b2.closeloop.runlevel.RunDeviations`), the p-value of their joint
    Wald test ``b' C^-1 b`` (``C`` their block of REML's ``beta_cov``) against chi-square with ``dof = len(b)``
    degrees of freedom: 3 per column of ``z`` (2 without load variation).

    A coefficient the runs do not identify (:func:`identified_columns`) is left out of the mean and of the test: its
    ``b`` is 0 and ``dof`` counts the identified ones only (none: ``p`` 1)."""
    Z = np.asarray(z, float).reshape(len(z), -1)
    idx = signal_index(Z.shape[1], dev.load is not None, gain_only)
    X = signal_design(z, dev.load, gain_only)
    keep = identified_columns(X)
    fit = reml(dev.theta, dev.cov, X[:, :, keep])
    at = {j: i for i, j in enumerate(keep)}
    tested = [at[j] for j in idx if j in at]
    b = np.array([fit.beta[at[j]] if j in at else 0.0 for j in idx])
    if not tested:
        return b, 1.0, 0
    bt, C = fit.beta[tested], fit.beta_cov[np.ix_(tested, tested)]
    try:
        p = float(stats.chi2.sf(float(bt @ np.linalg.solve(C, bt)), len(tested)))
    except np.linalg.LinAlgError:
        p = 1.0
    return b, p, len(tested)
