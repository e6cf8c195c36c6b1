"""Eq. 29 in its identifiable coordinates: the two exact null directions of (sigma, mu, k0) removed.

The force of Eq. 29 on the slider (drive coordinates) is ``F = -D v + X + sg Fr`` with

    D(s)  = c_r + sigma (0.5 - A'(s)),
    X(s)  = B'(s) V0 + mu P(s) (g1(k0) - (pi/2) G(k0) A'(s)) - g m_p (+ E phi),
    Fr(s) = mu_sd (g m_s + kappa P(s)).

With ``beta_s = b / sigma`` (b = mu (pi/2) G(k0)) and A'(s) = (c_r + sigma/2 - D(s)) / sigma,

    mu (g1 - (pi/2) G A'(s)) = K + beta_s D(s),        K = mu g1(k0) - beta_s (c_r + sigma / 2),

so the model sees (c_r, sigma, mu, k0, alpha) only through D(s) (Legendre coefficients ``d``), ``beta_s`` and
``K``: every step of the recursion (moving, at rest, reversing) and the start-speed gain are functions of
(d, beta_s, K, mu_sd, B'(s), P(s), phi). Of the n + 5 parameters c_r, sigma, mu, k0, alpha, two directions are
exact nulls of the likelihood: (sigma, k0) can take any values with mu, c_r, alpha following from

    mu = beta_s sigma / ((pi/2) G(k0)),   c_r = sigma h(k0) - K / beta_s,   h(k0) = g1(k0) / ((pi/2) G(k0)) - 1/2,
    alpha_0 = (c_r + sigma/2 - d_0) / sigma,   alpha_j = -d_j / sigma  (j >= 1).

The paper's bounds (c_r >= 0, k0 >= 0) are bounds of the gauge, not of the model: a search in (c_r, sigma, mu,
k0, alpha) stops where its path meets them (decisions 0020, 0023), while in (d, beta_s, K) the only constraints
are beta_s >= 0 and, for a paper vector to exist, K < 0 (h(k0) <= h(0) = 4 / pi^2 - 1/2 < 0 on 0 <= k0 < 1,
so c_r >= 0 needs K / beta_s <= sigma h(k0) < 0; then sigma <= (K / beta_s) / h(k0) gives one).

:class:`IdentifiableProblem` wraps a :class:`~l1b2.ident.problem.LikelihoodProblem` so that it takes vectors
``y`` laid out like theta with slot 0 = K, slot 2 = beta_s, slots 5 .. 5 + n = d and slots 1, 3 = the gauge's
sigma and k0 (never varied: changing them is the exact null move). A
:class:`~l1b2.ident.problem.ScaledObjective` on it with slots 1 and 3 pinned is the likelihood without its
null directions; :func:`l1b2.ident.varpro.local_fit` runs on it unchanged (the linear parameters B'(s), P(s),
phi keep their slots).
"""

from __future__ import annotations

import numpy as np

from ..predictor.model import G_of_k0, drive_factor

__all__ = ["h_of_k0", "y_of_theta", "admissible", "theta_of_y", "offset_form", "k_form", "feasible_gauge",
           "IdentifiableProblem"]


def h_of_k0(k0: float) -> float:
    """h(k0) = g1(k0) / ((pi/2) G(k0)) - 1/2 (negative on 0 <= k0 < 1; 4 / pi^2 - 1/2 at k0 = 0)."""
    return float(drive_factor(k0)) / (0.5 * np.pi * float(G_of_k0(k0))) - 0.5


def y_of_theta(theta, n1: int) -> np.ndarray:
    """The identifiable vector y of theta (Eq. 35 order; slots 1, 3 keep theta's sigma and k0 as the gauge)."""
    th = np.asarray(theta, dtype=float)
    y = th.copy()
    c_r, sigma, mu, k0 = th[:4]
    beta_s = mu * 0.5 * np.pi * float(G_of_k0(k0)) / sigma
    y[0] = mu * float(drive_factor(k0)) - beta_s * (c_r + 0.5 * sigma)
    y[2] = beta_s
    d = -sigma * th[5:5 + n1]
    d[0] += c_r + 0.5 * sigma
    y[5:5 + n1] = d
    return y


def admissible(theta, n1: int) -> bool:
    """Whether theta has identifiable coordinates with a paper vector: sigma > 0, b > 0 and K < 0 (all finite)."""
    th = np.asarray(theta, dtype=float)
    if not (th[1] > 0 and th[2] > 0 and float(G_of_k0(th[3])) > 0):
        return False
    y = y_of_theta(th, n1)
    return bool(np.all(np.isfinite(y)) and y[0] < 0 < y[2])


def theta_of_y(y, n1: int) -> np.ndarray:
    """theta of the identifiable vector y at its gauge (sigma = y[1], k0 = y[3]): the inverse of
    :func:`y_of_theta`."""
    y = np.asarray(y, dtype=float)
    th = y.copy()
    K, sigma, beta_s, k0 = y[:4]
    th[2] = beta_s * sigma / (0.5 * np.pi * float(G_of_k0(k0)))
    with np.errstate(divide="ignore", invalid="ignore"):  # beta_s = 0 (its bound): non-finite, which searches reject
        th[0] = c_r = sigma * h_of_k0(k0) - K / beta_s
    alpha = -y[5:5 + n1] / sigma
    alpha[0] += (c_r + 0.5 * sigma) / sigma
    th[5:5 + n1] = alpha
    return th


def offset_form(y, kappa: float) -> np.ndarray:
    """y with slot 0 holding the drive offset kappa0 = (K - kappa mu_sd) / beta_s [N s/m] instead of K (the
    identifiable form of :func:`l1b2.ident.offset.drive_offset`: sigma a / b - c_r - sigma / 2 of theta_of_y(y))."""
    out = np.array(y, dtype=float)
    out[0] = (out[0] - kappa * out[4]) / out[2]
    return out


def k_form(y, kappa: float) -> np.ndarray:
    """The inverse of :func:`offset_form`: K = beta_s kappa0 + kappa mu_sd back in slot 0."""
    out = np.array(y, dtype=float)
    out[0] = out[2] * out[0] + kappa * out[4]
    return out


def feasible_gauge(y, sigma_max: float, k0: float, margin: float = 0.5) -> np.ndarray:
    """y with a gauge (sigma, k0) whose theta has c_r >= 0: sigma = ``sigma_max`` when that gives c_r >= 0,
    else ``margin`` times the largest sigma that does (c_r = (1 - margin) (-K / beta_s) > 0). Needs K < 0."""
    y = np.array(y, dtype=float)
    K, beta_s = y[0], y[2]
    if not (K < 0 and beta_s > 0):
        raise ValueError(f"no paper vector for K = {K:g}, beta_s = {beta_s:g} (needs K < 0 < beta_s)")
    top = (K / beta_s) / h_of_k0(k0)  # c_r = 0 at sigma = top
    y[1] = sigma_max if sigma_max <= top else margin * top
    y[3] = k0
    return y


class IdentifiableProblem:
    """A likelihood problem taking identifiable vectors y (module docstring) instead of theta.

    ``residual``, ``jacobian``, ``start_gain``, ``start_gain_sensitivity``, ``predict_all`` and ``core`` as those of
    the wrapped problem, with the chain rule dtheta/dy for the Jacobian and the start-gain sensitivity. With
    ``kappa`` its vectors hold the drive offset kappa0 in slot 0 (:func:`offset_form`).
    """

    def __init__(self, problem, kappa=None):
        self.problem = problem
        self.core = problem.core
        self.n1 = problem.core.n1
        self.kappa = kappa

    def theta(self, y):
        """theta of y; with ``kappa`` (the offset form) NaN where K >= 0 (no paper vector: a search rejects it)."""
        if self.kappa is None:
            return theta_of_y(y, self.n1)
        y_k = k_form(y, self.kappa)
        th = theta_of_y(y_k, self.n1)
        if not y_k[0] < 0:
            th[:] = np.nan
        return th

    def residual(self, y):
        th = self.theta(y)
        with np.errstate(over="ignore", invalid="ignore"):
            return self.problem.residual(th)

    def start_gain(self, y):
        th = self.theta(y)
        with np.errstate(over="ignore", invalid="ignore"):
            return self.problem.start_gain(th)

    def predict_all(self, y):
        return self.problem.predict_all(self.theta(y))

    def chain(self, y, cols):
        """``(theta columns, M)``: d theta[tcols] / d y[cols] = M (a small dense matrix)."""
        if self.kappa is None:
            return self._chain_k(y, cols)
        cols = np.asarray(cols, dtype=int)
        y_k = k_form(y, self.kappa)
        kcols = np.union1d(cols, [0]) if np.isin([0, 2, 4], cols).any() else cols
        T = (kcols[:, None] == cols[None, :]).astype(float)  # d y_k[kcols] / d y[cols]
        for j, c in enumerate(cols):  # K = beta_s kappa0 + kappa mu_sd
            if c in (0, 2, 4):
                T[0, j] = {0: y[2], 2: y[0], 4: self.kappa}[int(c)]
        tcols, M = self._chain_k(y_k, kcols)
        return tcols, M @ T

    def _chain_k(self, y, cols):
        """:meth:`chain` for y with K in slot 0."""
        n1 = self.n1
        K, sigma, beta_s, k0 = (float(v) for v in y[:4])
        cols = np.asarray(cols, dtype=int)
        tcols = set()
        for c in cols:
            tcols.update({0: (0, 5), 2: (0, 2, 5)}.get(int(c), (int(c),)))
        tcols = np.array(sorted(tcols), dtype=int)
        pos = {int(t): i for i, t in enumerate(tcols)}
        M = np.zeros((tcols.size, cols.size))
        for j, c in enumerate(cols):
            c = int(c)
            if c == 0:  # K: c_r = sigma h - K / beta_s, alpha_0 = (c_r + sigma/2 - d_0) / sigma
                M[pos[0], j] = -1.0 / beta_s
                M[pos[5], j] = -1.0 / (beta_s * sigma)
            elif c == 2:  # beta_s: mu, c_r, alpha_0
                M[pos[2], j] = sigma / (0.5 * np.pi * float(G_of_k0(k0)))
                M[pos[0], j] = K / beta_s ** 2
                M[pos[5], j] = K / (beta_s ** 2 * sigma)
            elif c in (1, 3):
                raise ValueError("the gauge slots (sigma, k0) are null directions: they are never varied")
            elif 5 <= c < 5 + n1:  # d_j: alpha_j = -d_j / sigma (+ const for j = 0)
                M[pos[c], j] = -1.0 / sigma
            else:
                M[pos[c], j] = 1.0
        return tcols, M

    def jacobian(self, y, cols):
        tcols, M = self.chain(y, cols)
        return self.problem.jacobian(self.theta(y), tcols) @ M

    def start_gain_sensitivity(self, y, cols):
        tcols, M = self.chain(y, cols)
        g, G = self.problem.start_gain_sensitivity(self.theta(y), tcols)
        return g, G @ M


#: floors of the identifiable scalars' scales (K [N], beta_s [N s/m per (N s/m)], mu_sd [-])
_FLOORS = {0: 1e-2, 2: 1e-3, 4: 1e-2}


def identifiable_objective(obj, theta0, n1: int, kappa=None):
    """``(objective, y0)``: a :class:`~l1b2.ident.problem.ScaledObjective` on the identifiable coordinates of
    ``obj``'s problem and noise (slots 1, 3 pinned at theta0's sigma and k0; K <= 0, beta_s >= 0, mu_sd >= 0;
    d free; the other slots varied and bounded as in ``obj``), and y of ``theta0``. With ``kappa`` slot 0 holds
    the drive offset kappa0 instead (:func:`offset_form`, unbounded; K < 0 is held by the problem, which gives no
    finite value for K >= 0: :class:`IdentifiableProblem`).
    """
    from .problem import ScaledObjective

    y0 = y_of_theta(theta0, n1) if kappa is None else offset_form(y_of_theta(theta0, n1), kappa)
    varied = np.zeros(y0.size, dtype=bool)
    varied[obj.vidx] = True
    varied[[1, 3]] = False
    lo = np.full(y0.size, -np.inf)
    hi = np.full(y0.size, np.inf)
    lo[obj.vidx], hi[obj.vidx] = obj.zlo * obj.sv_scale, obj.zhi * obj.sv_scale
    lo[[0, 5]], hi[[0, 5]] = -np.inf, np.inf
    hi[0] = 0.0 if kappa is None else np.inf
    lo[2], hi[2] = 0.0, np.inf
    scale = np.ones(y0.size)
    scale[obj.vidx] = obj.sv_scale
    for i, fl in _FLOORS.items():
        scale[i] = max(abs(y0[i]), fl)
    scale[5:5 + n1] = max(float(np.max(np.abs(y0[5:5 + n1]))), 1e-12)
    return ScaledObjective(IdentifiableProblem(obj.problem, kappa), obj.noise, y0, varied, scale, lo, hi,
                           obj.start_noise), y0


def identifiable_search(obj, theta0, n1: int, p_theta: int, max_nfev, tol, stat_tol, max_outer, log=None,
                        min_gain=0.0, kappa=None):
    """The variable-projection search (:func:`l1b2.ident.varpro.varpro_search`, one start) in the identifiable
    coordinates, from ``theta0`` (the noise model set there first), mapped back to ``obj``'s coordinates.

    The optimum y is given the gauge of :func:`feasible_gauge` (theta0's sigma, or less when c_r would be
    negative; theta0's k0): the paper vector returned has the same likelihood. Returns ``(SearchOutcome,
    refinement, stages)`` as ``varpro_search`` on ``obj`` (``x`` / ``z`` in obj's scaled coordinates);
    ``min_gain``: that of its local fits (:func:`l1b2.ident.varpro.local_fit`); ``kappa``: the search
    runs with the drive offset in slot 0 (:func:`identifiable_objective`).
    """
    from .varpro import linear_positions, profile_loglik, varpro_search

    oy, y0 = identifiable_objective(obj, theta0, n1, kappa)
    zy0 = oy.z_of(y0)
    profile_loglik(oy, zy0)  # the noise model at the start
    search, outer, stages = varpro_search(oy, linear_positions(oy, p_theta, n1), [zy0], max_nfev, tol, stat_tol,
                                          max_outer, 1, log, min_gain)
    y_end = oy.theta_of(outer.z)
    y_hat = feasible_gauge(y_end if kappa is None else k_form(y_end, kappa), float(theta0[1]), float(theta0[3]))
    z = obj.z_of(theta_of_y(y_hat, n1))
    ll = profile_loglik(obj, z)  # the noise model at the paper vector (the same likelihood: a null move)
    final = search.results[search.best]
    final.x, final.cost = z, -ll
    outer.z = z
    outer.final = final
    for rec in search.records:
        rec["x0"] = (obj.z_of(theta0) * obj.sv_scale).tolist()
    if log is not None:
        log(f"identifiable coordinates: K {y_hat[0]:.6g}, beta_s {y_hat[2]:.6g}, gauge sigma {y_hat[1]:.6g}, "
            f"k0 {y_hat[3]:.3g}; loglik {ll:.4f}")
    return search, outer, stages
