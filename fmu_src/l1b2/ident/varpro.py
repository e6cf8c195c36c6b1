"""Variable projection of the parameters that enter the free run linearly (the ``solver="varpro"`` search).

For fixed "nonlinear" parameters (c_r, sigma, mu, k0, mu_sd and the
Legendre coefficients alpha of A'), the free run of Eq. 29 is a linear
recursion in the speed whose forcing term ``h d (X + sg Fr)`` is linear in the
coefficients beta of B'(s), p of P(s) and the extra-force parameters phi: the
predicted speed is *affine* in them as long as no step changes its kind (the
sign of -v', a stop at rest, a reversal; :mod:`l1b2.predictor.kernels`). So
for each trial of the nonlinear parameters the linear ones are the solution
of a weighted linear least-squares problem (Golub and Pereyra's variable
projection), found by Gauss-Newton steps with the exact sensitivities: one
step is exact when no step kind changes, further steps (at most
:data:`MAX_INNER`) follow the piecewise-affine map when one does.

The outer problem runs over the nonlinear parameters only, with bounds, by
Levenberg-Marquardt steps on Kaufman's approximation of the projected
problem (the Schur complement of the normal equations, :func:`local_fit`).
The linear parameters then cannot create local minima or slow valleys; they
are never started anywhere.

The criterion is the log-likelihood of Eq. 32 itself: its gradient includes
the dependence of the start-speed gain g (:class:`l1b2.ident.noise.NoiseModel`)
on the parameters of D(s) (:meth:`l1b2.ident.problem.LikelihoodProblem.start_gain_sensitivity`),
which the joint searches leave out of their steps; the variances R are set
to their ML values at every iteration. :func:`varpro_search` fits every
start, then refits the best until a refit gains less than ``stat_tol``.

The linear parameters are those that are varied and unbounded (beta, p; an
extra parameter only when its bounds are infinite); bounded extras stay in
the nonlinear set.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from ..errors import IdentificationError
from .problem import strictly_inside

__all__ = ["MAX_INNER", "linear_positions", "Projection", "LocalFit", "local_fit", "profile_loglik", "varpro_search"]

#: most Gauss-Newton steps of the linear parameters per projection (one is exact without a change of step kind)
MAX_INNER = 4


def linear_positions(obj, p_theta: int, n1: int) -> np.ndarray:
    """Positions in the scaled vector z (of ``obj``, a ScaledObjective) of the parameters that enter linearly.

    beta (B'(s)), p (P(s)) and unbounded extra-force parameters phi.
    """
    idx = obj.vidx
    lin = (idx >= 5 + n1) & (idx < p_theta)
    extra = idx >= p_theta
    unbounded = ~np.isfinite(obj.zlo) & ~np.isfinite(obj.zhi)
    return np.flatnonzero(lin | (extra & unbounded))


def _solve_spd(H, b, rcond=1e-13):
    """Least-squares solution of the symmetric positive semi-definite system ``H x = b`` (Jacobi-scaled,
    eigen-decomposition with a relative cut-off for the directions the data do not determine)."""
    d = np.sqrt(np.maximum(np.diag(H), 0.0))
    d = np.where(d > 0, d, 1.0)
    Hs = H / np.outer(d, d)
    w, V = np.linalg.eigh(Hs)
    keep = w > rcond * max(float(w[-1]), 1e-300)
    x = V[:, keep] @ ((V[:, keep].T @ (b / d)) / w[keep])
    return x / d


class Projection:
    """The variable-projection problem of a :class:`~l1b2.ident.problem.ScaledObjective` in normal equations.

    Parameters
    ----------
    obj : ScaledObjective
        Whitened residuals in scaled coordinates z (noise model as it is).
    lin : ndarray of int
        Positions in z of the linear parameters (:func:`linear_positions`).

    Attributes
    ----------
    non : ndarray of int
        Positions of the nonlinear parameters.
    nfev, njev : int
        Free-run evaluations and sensitivity passes used so far.
    """

    def __init__(self, obj, lin):
        self.obj = obj
        self.lin = np.asarray(lin, dtype=int)
        self.non = np.setdiff1d(np.arange(obj.vidx.size), self.lin)
        self.nfev = 0
        self.njev = 0
        from scipy.sparse import csr_matrix

        n = obj.noise.run_sel.size
        #: run-indicator matrix (runs x residual rows): per-run column sums as one sparse product
        self.by_run = csr_matrix((np.ones(n), (obj.noise.run_sel, np.arange(n))), shape=(obj.noise.n_runs, n))

    def _set_gain(self, theta):
        """The start-speed gain g of the noise model at theta (when the model has one); returns theta."""
        if self.obj.start_noise:
            self.obj.noise.set_start_gain(self.obj.problem.start_gain(theta))
        return theta

    def residual(self, z):
        """Whitened residual at z (start-speed gain g re-estimated there) and the criterion ``2 phi``.

        ``phi = 0.5 |r_w|^2 + 0.5 sum_r log(1 + g_r.g_r)`` is minus the
        log-likelihood at fixed variances R, up to a constant.
        """
        self.nfev += 1
        obj = self.obj
        self._set_gain(obj.theta_of(z))
        r = obj.fun(z)
        noise = obj.noise
        return r, float(r @ r) + float(np.sum(np.log1p(noise.gg[noise.counts > 0])))

    def normal(self, z, r):
        """``(J_w^T J_w, grad phi)`` at z: the Gauss-Newton matrix of the whitened residual and the exact
        gradient of the criterion, including the dependence of g on the parameters of D(s)."""
        self.njev += 1
        obj = self.obj
        theta = obj.theta_of(z)
        problem, noise = obj.problem, obj.noise
        vi = obj.vidx
        d_cols = np.flatnonzero((vi < 2) | ((vi >= 5) & (vi < 5 + problem.core.n1)))  # the parameters of D(s)
        if obj.start_noise and d_cols.size:
            g, G = problem.start_gain_sensitivity(theta, obj.vidx[d_cols])
            noise.set_start_gain(g)
        r = obj.fun(z)
        J = obj.jac(z, order="F")  # column-major: J^T J and J^T r several times faster
        grad = J.T @ r
        if obj.start_noise and d_cols.size:
            G = G * obj.sv_scale[d_cols][None, :]
            raw = problem.residual(theta)
            raw = np.where(np.isfinite(raw), raw, 0.0)
            R, gam = noise.R, noise.gg
            s_r = np.bincount(noise.run_sel, weights=g * raw, minlength=noise.n_runs)
            u = self.by_run @ (G * raw[:, None])
            w = self.by_run @ (G * g[:, None])
            q = 1.0 + gam
            extra = ((-s_r / q)[:, None] * u + (s_r * s_r / (q * q))[:, None] * w) / R[:, None] + w / q[:, None]
            grad[d_cols] += np.sum(extra[noise.counts > 0], axis=0)
            # Gauss-Newton curvature of 0.5 log(1 + g.g): sum_r G_r^T G_r / (1 + g_r.g_r) (its PSD part)
            Gq = np.asfortranarray(G / np.sqrt(q[noise.run_sel])[:, None])
            H = J.T @ J
            H[np.ix_(d_cols, d_cols)] += Gq.T @ Gq
            return H, grad
        return J.T @ J, grad

    def project(self, z, r, cost):
        """The linear parameters' least-squares optimum at z's nonlinear values: (z, r, cost).

        Gauss-Newton in the linear parameters with their exact sensitivities; one step is exact unless a step
        of the free run changes its kind, then at most :data:`MAX_INNER` steps (each kept only if it lowers
        the cost).
        """
        if self.lin.size == 0:
            return z, r, cost
        for _ in range(MAX_INNER):
            self.njev += 1
            JL = self.obj.jac_columns(z, self.lin, order="F")
            gL = JL.T @ r
            step = -_solve_spd(JL.T @ JL, gL)
            predicted = cost + float(gL @ step)  # the minimum of the quadratic model (affine residual)
            z_new = z.copy()
            z_new[self.lin] += step
            r_new, c_new = self.residual(z_new)
            if not c_new < cost:
                break  # a change of step kind the linear model did not see, and it does not pay
            # (2 phi units: 1e-3 is 5e-4 log-likelihood units, far below any statistical relevance)
            exact = abs(c_new - predicted) <= max(1e-9 * cost, 1e-3)
            z, r, cost = z_new, r_new, c_new
            if exact:
                break  # the affine map held: this is the projection
        return z, r, cost


def _nll(noise, cost):
    """-log-likelihood of the criterion value ``cost`` (= 2 phi) at the noise model's variances."""
    has = noise.counts > 0
    return 0.5 * cost + 0.5 * float(np.sum(noise.counts[has] * np.log(2 * np.pi * noise.R[has])))


@dataclass
class LocalFit:
    """One local variable-projection fit: final full z, an OptimizeResult-like record and counts."""

    z: np.ndarray
    result: object
    nfev: int
    njev: int
    time_s: float
    history: list = field(default_factory=list)


def local_fit(obj, lin, z_init, max_iter, tol, stat_tol=0.0, stat_window=3, update_R=True, min_gain=0.0):
    """Levenberg-Marquardt on the projected problem (Kaufman's step) from ``z_init``.

    The criterion is ``phi = 0.5 |r_w|^2 + 0.5 sum_r log(1 + g_r.g_r)``
    (minus the log-likelihood at the variances R, up to a constant), with the
    start-speed gain g re-evaluated at every point (:class:`Projection`).
    The linear parameters are projected at the start; each iteration solves
    the Gauss-Newton system of the nonlinear parameters with the linear ones
    eliminated (Schur complement of the normal equations, i.e. Kaufman's
    variable-projection step) and the exact gradient, damped on the
    nonlinear block only, with the bounds of the nonlinear parameters held
    (:func:`l1b2.ident.search.bounded_step`). The trial point carries the
    linear parameters the joint Gauss-Newton model predicts; if it does not
    lower the criterion they are projected exactly there before the trial is
    judged. With ``update_R`` the variances are set to their ML values at the
    start of every iteration (coordinate ascent of the likelihood in R), else
    they stay as they are. Stops when a step gains less than ``tol`` relative
    to the criterion, when the log-likelihood gained less than ``stat_tol``
    over ``stat_window`` accepted steps, when no damping finds a gain, or
    after ``max_iter`` iterations. ``history``: -log-likelihood per iteration.
    With ``min_gain > 0`` the damping also stops once the quadratic model of the step predicts a gain
    below ``min_gain`` log-likelihood units (a step that small cannot matter; without it a step that
    fails at every damping is tried until the damping reaches 1e10, each trial with a projection).
    """
    from .search import bounded_step

    t0 = time.perf_counter()
    proj = Projection(obj, lin)
    lin, non = proj.lin, proj.non
    z = strictly_inside(np.array(z_init, dtype=float), obj.zlo, obj.zhi)
    r, cost = proj.residual(z)
    z, r, cost = proj.project(z, r, cost)
    history = [_nll(obj.noise, cost)]  # -log-likelihood: comparable across updates of R
    lam, status, message = 1e-3, 0, "iteration limit"
    zlo, zhi = obj.zlo[non], obj.zhi[non]
    g_red = np.zeros(non.size)
    it = 0
    for it in range(1, max_iter + 1):
        if update_R:  # the variances at their ML values here (coordinate ascent of the likelihood in R)
            with np.errstate(over="ignore", invalid="ignore"):
                obj.noise.update_R(obj.problem.residual(obj.theta_of(z)))
            r, cost = proj.residual(z)
            history[-1] = _nll(obj.noise, cost)
        H, g = proj.normal(z, r)
        if lin.size:
            HLL, HLN, gL = H[np.ix_(lin, lin)], H[np.ix_(lin, non)], g[lin]
            K = np.column_stack([HLN, gL])
            X = np.column_stack([_solve_spd(HLL, K[:, j]) for j in range(K.shape[1])])
            S = H[np.ix_(non, non)] - HLN.T @ X[:, :-1]
            g_red = g[non] - HLN.T @ X[:, -1]
        else:
            S, g_red, X = H, g, None
        accepted = small = False
        while lam < 1e10:
            dn = bounded_step(S, np.diag(S).copy(), g_red, lam, z[non], zlo, zhi)
            if min_gain > 0 and -(g_red @ dn + 0.5 * dn @ S @ dn) < min_gain:  # (phi = -log-likelihood)
                small = True
                break
            z_try = z.copy()
            z_try[non] = strictly_inside(z[non] + dn, zlo, zhi)
            if X is not None:
                dn_taken = z_try[non] - z[non]
                z_try[lin] -= X[:, -1] + X[:, :-1] @ dn_taken
            r_try, c_try = proj.residual(z_try)
            if not c_try < cost:
                z_try, r_try, c_try = proj.project(z_try, r_try, c_try)
            if np.isfinite(c_try) and c_try < cost:
                accepted = True
                lam = max(lam / 3.0, 1e-9)
                break
            lam *= 4.0
        if not accepted:
            status, message = 2, ("no damped step predicted to gain min_gain lowers the cost" if small
                                  else "no damped step lowers the cost")
            break
        gain = cost - c_try
        z, r, cost = z_try, r_try, c_try
        history.append(_nll(obj.noise, cost))
        if gain <= tol * cost:
            status, message = 1, f"relative cost reduction < {tol:g}"
            break
        if stat_tol > 0 and len(history) > stat_window and history[-1 - stat_window] - history[-1] < stat_tol:
            status, message = -2, (f"statistical convergence: log-likelihood gained < {stat_tol:g} over the last "
                                   f"{stat_window} iterations")
            break
    z, r, cost = proj.project(z, r, cost)
    res = SimpleNamespace(x=z, cost=0.5 * cost, status=status, message=message, nit=it,
                          optimality=float(np.max(np.abs(g_red))) if g_red.size else 0.0, nfev=proj.nfev,
                          njev=proj.njev)
    return LocalFit(z, res, proj.nfev, proj.njev, time.perf_counter() - t0, history)


def profile_loglik(obj, z) -> float:
    """Log-likelihood at ``z`` of ``obj`` with the noise model re-estimated there (g and R at their ML values)."""
    theta = obj.theta_of(z)
    with np.errstate(over="ignore", invalid="ignore"):
        obj.update_noise(theta)
        return float(obj.noise.loglik(obj.problem.residual(theta)))


def varpro_search(obj, lin, starts, max_nfev, tol, stat_tol, max_outer, n_refine=2, log=None, min_gain=0.0):
    """Local variable-projection fits from every start, then the noise alternation on the best.

    Each start is fitted by :func:`local_fit` (from the noise model of the
    search's centre) and scored by its profile log-likelihood (noise
    re-estimated at its optimum). The
    ``n_refine`` best are then refitted with the noise model re-estimated
    after each fit until the log-likelihood gains less than ``stat_tol`` (at
    most ``max_outer`` refits); the higher final log-likelihood is kept.

    Returns ``(SearchOutcome, refinement, stages)`` shaped like
    :func:`l1b2.ident.search.profile_search`'s (``cost`` = -log-likelihood),
    ``stages`` a list of per-stage records (``stage``, ``time_s``, ``nfev``,
    ``njev``). ``min_gain``: that of every :func:`local_fit`.
    """
    from .search import ProfileRefinement, SearchOutcome

    noise = obj.noise
    saved = dict(vars(noise))
    sv_scale = obj.sv_scale
    records, results, fits = [], {}, {}
    t0, c0 = time.perf_counter(), time.process_time()
    nfev = njev = 0
    for i, z_init in enumerate(starts):
        vars(noise).update(saved)
        r_init = obj.fun(z_init)
        nfev += 1
        if not np.all(np.abs(r_init) < 1e9):
            records.append({"start": i, "status": None, "message": "skipped: non-finite prediction at start",
                            "cost": float("inf"), "nfev": 0, "njev": 0, "time_s": 0.0,
                            "x0": (z_init * sv_scale).tolist(), "refined": False})
            continue
        try:
            fit = local_fit(obj, lin, z_init, max_nfev, tol, stat_tol, min_gain=min_gain)
        except (np.linalg.LinAlgError, ValueError) as exc:
            records.append({"start": i, "status": None, "message": f"failed: {exc}", "cost": float("inf"),
                            "nfev": 0, "njev": 0, "time_s": 0.0, "x0": (z_init * sv_scale).tolist(),
                            "refined": False})
            continue
        ll = profile_loglik(obj, fit.z)
        nfev += fit.nfev + 1
        njev += fit.njev
        res = fit.result
        res.x = fit.z
        res.cost = -ll
        results[i], fits[i] = res, fit
        records.append({"start": i, "x0": (z_init * sv_scale).tolist(), "cost": -ll, "loglik": ll,
                        "nfev": fit.nfev, "njev": fit.njev, "status": int(res.status), "message": str(res.message),
                        "optimality": float(res.optimality), "time_s": fit.time_s, "refined": False})
        if log is not None:
            log(f"varpro start {i}: loglik {ll:.4f}, nfev {fit.nfev}, njev {fit.njev} ({fit.time_s:.2f}s); "
                f"{res.message}, cost history {[round(h, 3) for h in fit.history[-4:]]}")
    if not results:
        raise IdentificationError("global search failed: every start gave a non-finite prediction")
    stages = [{"stage": "starts", "time_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
               "nfev": nfev, "njev": njev, "n_starts": len(starts)}]
    t1, c1 = time.perf_counter(), time.process_time()
    nfev = njev = 0
    ranked = sorted(results, key=lambda i: results[i].cost)
    refinements = {}
    for i in ranked[:n_refine]:
        z = fits[i].z
        ll = -results[i].cost
        history = [{"iteration": 0, "loglik": ll}]
        converged = False
        final = results[i]
        for it in range(1, max_outer + 1):
            profile_loglik(obj, z)  # the noise model at z
            fit = local_fit(obj, lin, z, max_nfev, tol, stat_tol, min_gain=min_gain)
            ll_new = profile_loglik(obj, fit.z)
            if log is not None:
                log(f"  refit {it}: loglik {ll_new:.4f} ({fit.result.message}, {fit.result.nit} iterations, "
                    f"cost history {[round(h, 3) for h in fit.history[-4:]]})")
            nfev += fit.nfev + 2
            njev += fit.njev
            if ll_new > ll:
                gain = ll_new - ll
                z, ll, final = fit.z, ll_new, fit.result
                final.x = z
                history.append({"iteration": it, "loglik": ll, "nfev": fit.nfev, "njev": fit.njev,
                                "time_s": fit.time_s})
                if gain >= stat_tol:
                    continue
            converged = True
            break
        final.cost = -ll
        results[i] = final
        refinements[i] = ProfileRefinement(z, final, history, converged)
        rec = records[[r["start"] for r in records].index(i)]
        rec.update(cost=-ll, loglik=ll, refined=True, nfev=rec["nfev"] + sum(h.get("nfev", 0) for h in history))
        if log is not None:
            log(f"varpro refine {i}: loglik {ll:.4f} after {len(history) - 1} noise update(s)")
    ranked = sorted(results, key=lambda i: results[i].cost)
    best = min(refinements, key=lambda i: results[i].cost)
    ref = refinements[best]
    final = ref.final
    final.status = -2 if ref.converged else int(final.status)
    final.message = (f"variable projection: {final.message}; noise model re-estimated "
                     + ("until a refit gained < stat_tol log-likelihood units" if ref.converged
                        else f"{max_outer} times (max_outer)"))
    profile_loglik(obj, ref.z)  # the noise model at the chosen optimum
    stages.append({"stage": "noise refinement", "time_s": time.perf_counter() - t1,
                   "cpu_s": time.process_time() - c1, "nfev": nfev, "njev": njev, "n_refined": len(refinements)})
    return SearchOutcome(records, results, ranked, best, 0, list(refinements)), ref, stages
