"""Multi-start local search of the likelihood and the statistical stopping rule.

Global search (like MATLAB's GlobalSearch): stage 1 scatters many trial
points and scores them cheaply (the equation error of
:mod:`l1b2.ident.reduced`); then local :func:`scipy.optimize.least_squares`
runs (``trf`` with bounds) of the true criterion start from the distinct
equation-error minima (best first) and from scrambled Sobol points in the
box ``z0 +- start_spread * max(|z0|, 0.05)`` (scaled coordinates, see
:class:`l1b2.ident.problem.ScaledObjective`) around the best, ``n_starts`` in
all (:func:`start_points`). Each gets ``explore_nfev`` evaluations, the
``n_refine`` best are run to convergence (:func:`multi_start`). Every
start's cost, nfev, status and message are recorded.

Statistical stopping (:class:`StatStop`): a local run also stops when the
cost (= -log-likelihood + const, dimensionless) decreased by < ``stat_tol``
over ``stat_window`` iterations: along practically non-identifiable
directions trf otherwise creeps for hundreds of iterations without a
statistically relevant gain.

Then the noise variances are re-estimated and the best point refined until
they settle (:func:`alternate_noise`, paper Eq. 32). A warm start with extra
forces first fits phi given theta (:func:`warm_prestep`).
"""

from __future__ import annotations

import inspect
import math
import time
import warnings
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
from scipy.optimize import least_squares

from ..errors import IdentificationError
from .problem import strictly_inside
from .tallqr import BLOCK_ROWS, r_factor

__all__ = [
    "HAS_CALLBACK", "StatStop", "sobol_box", "CompressedObjective", "LocalSolver", "start_points", "SearchOutcome", "multi_start",
    "warm_prestep", "NoiseRefinement", "alternate_noise", "ProfileRefinement", "profile_refine", "profile_search",
    "STALL_MESSAGE", "polish_stalled", "bounded_step", "search_nfev",
]


try:  # least_squares(callback=...) exists from scipy 1.16
    #: whether :func:`scipy.optimize.least_squares` takes a ``callback`` (the statistical stop needs it)
    HAS_CALLBACK = "callback" in inspect.signature(least_squares).parameters
except (TypeError, ValueError):  # pragma: no cover
    HAS_CALLBACK = False


class StatStop:
    """least_squares callback: stop when the cost stalls statistically.

    The cost is 0.5 * sum(whitened residuals^2) = -log-likelihood + const. In
    flat, curved valleys along practically non-identifiable directions trf
    creeps with tiny steps for hundreds of iterations; once the cost
    decreased by less than ``tol`` (log-likelihood units, default 0.01, far
    below the 1.92 of a 95 % likelihood-ratio interval) over ``window``
    iterations, further progress cannot matter statistically.

    With ``budget`` (the iteration budget of the run; used for warm starts
    only) the run also stops when the *projected* gain -- the decrease rate
    over the last ``window`` iterations times the iterations left -- is below
    ``budget_tol`` (default 0.5 log-likelihood units): even if the creep
    went on to the end of the budget, it could not matter statistically.
    """

    def __init__(self, tol, window, budget=None, budget_tol=0.5):
        self.tol = float(tol)
        self.window = int(window)
        self.budget = None if budget is None else int(budget)
        self.budget_tol = float(budget_tol)
        self.costs = []
        self.reason = None

    def __call__(self, intermediate_result):
        self.costs.append(float(intermediate_result.cost))
        if len(self.costs) > self.window:
            dec = self.costs[-self.window - 1] - self.costs[-1]
            if dec < self.tol:
                self.reason = "window"
                raise StopIteration
            if self.budget is not None:
                left = max(self.budget - len(self.costs), 0)
                if dec / self.window * left < self.budget_tol:
                    self.reason = "projected"
                    raise StopIteration


def sobol_box(z0, n, seed, spread, floor=0.05):
    """n scrambled-Sobol points in z0 +- spread*max(|z0|, floor)."""
    if n <= 0:
        return []
    from scipy.stats import qmc

    m = int(math.ceil(math.log2(n))) if n > 1 else 0
    sob = qmc.Sobol(d=z0.size, scramble=True, seed=seed)
    u = sob.random_base2(m)[:n]
    hw = spread * np.maximum(np.abs(z0), floor)
    return [z0 + (2.0 * row - 1.0) * hw for row in u]


class CompressedObjective:
    """The residuals and Jacobian of an objective in the ``(p+1)``-row form that ``least_squares`` needs.

    At a point z with residuals r (n) and Jacobian J (n x p), one Householder
    QR of ``[J r]`` (R factor only) gives ``[[R, c], [0, rho]]``: the compressed
    residual ``f = (c, rho)`` and Jacobian ``[R; 0]`` have the same norm
    ``|f| = |r|``, gradient ``J_c^T f = J^T r`` and Gauss-Newton matrix
    ``J_c^T J_c = J^T J``, and every trust-region step of ``trf`` (its SVD of
    the scaled Jacobian, the predicted and actual reductions) depends on
    (r, J) only through these: the steps are those of the full problem, while
    the SVD inside each step is of a (p+1) x p matrix instead of n x p.
    Each point costs one Jacobian (also at a rejected trial point); the last
    point's factors are kept for :meth:`jac`, which ``least_squares`` calls at
    the point it just evaluated. The R factor is computed by blocks of ``block_rows`` rows
    (:func:`l1b2.ident.tallqr.r_factor`: the same R up to the signs of its rows; 0: one Householder QR).
    """

    block_rows = BLOCK_ROWS

    def __init__(self, objective):
        self.objective = objective
        self._z = None
        self._R = None

    def _factor(self, z):
        if self._z is None or not np.array_equal(z, self._z):
            obj = self.objective
            A = np.column_stack([obj.jac(z), obj.fun(z)])
            self._R, self._z = r_factor(A, self.block_rows), np.array(z, copy=True)
        return self._R

    def fun(self, z):
        return self._factor(z)[:, -1].copy()

    def jac(self, z, *_):
        return self._factor(z)[:, :-1].copy()


class LocalSolver:
    """One local ``least_squares`` run (``trf``, bounds) of a :class:`~l1b2.ident.problem.ScaledObjective`.

    Parameters
    ----------
    objective : ScaledObjective
    tol : float
        ftol = xtol = gtol.
    stat_tol, stat_window : float, int
        Statistical stop (:class:`StatStop`; 0 disables, needs scipy >= 1.16).
    warm : bool
        Warm start: also stop a creep whose projected gain over the remaining
        budget is < 50 * ``stat_tol``.

    ``least_squares`` sees the objective through :class:`CompressedObjective` (the same steps, each step's
    SVD on p+1 rows instead of n) when the class attribute ``compressed`` is True (the default; False: the
    full residual vector, the former path).
    """

    compressed = True

    def __init__(self, objective, tol, stat_tol, stat_window, warm=False):
        self.objective = objective
        self.tol = tol
        self.stat_tol = stat_tol
        self.stat_window = stat_window
        self.warm = warm

    def __call__(self, z_init, max_nfev):
        """Run from ``z_init`` with ``max_nfev`` evaluations; returns ``(OptimizeResult, wall time [s])``."""
        obj = self.objective
        t0 = time.perf_counter()
        kw = {}
        stop = None
        if HAS_CALLBACK and self.stat_tol > 0:
            # warm start: also stop a creep whose projected gain is irrelevant
            stop = StatStop(self.stat_tol, self.stat_window, budget=max_nfev if self.warm else None,
                            budget_tol=50 * self.stat_tol)
            kw["callback"] = stop
        fun = CompressedObjective(obj) if self.compressed and obj.vidx.size else obj
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            res = least_squares(
                fun.fun,
                z_init,
                jac=fun.jac,
                bounds=(obj.zlo, obj.zhi),
                method="trf",
                x_scale=1.0,
                ftol=self.tol,
                xtol=self.tol,
                gtol=self.tol,
                max_nfev=max_nfev,
                **kw,
            )
        if res.status == -2 and stop is not None and stop.reason == "projected":
            res.message = (
                f"statistical convergence (warm start): at the rate of the last {self.stat_window} "
                f"iterations the remaining budget would gain < {50 * self.stat_tol:g} log-likelihood units"
            )
        elif res.status == -2:
            res.message = (
                f"statistical convergence: cost decreased by < {self.stat_tol:g} (log-likelihood units) "
                f"over the last {self.stat_window} iterations"
            )
        return res, time.perf_counter() - t0


def warm_prestep(objective, z_centre, xv, tol, max_nfev, log=None):
    """Warm start with extras: fit phi given theta first.

    A baseline fitted without the extras can sit on a kink of the free run
    (a run at the edge of sticking / reversing); the joint Jacobian there is
    one-sided in theta and trf may not move at all. The extras' conditional
    fit (theta fixed at init: a small, nearly linear problem) moves off it.

    Parameters
    ----------
    objective : ScaledObjective
    z_centre : ndarray
        Scaled start point.
    xv : ndarray of int
        Positions of the varied extra parameters in z.
    tol, max_nfev : float, int
        least_squares tolerances and budget.

    Returns
    -------
    z_centre : ndarray
        The start point with the fitted phi (unchanged when the step did not
        lower the cost; the noise model is re-estimated when it did).
    record : dict
        ``cost_before``, ``cost_after``, ``nfev``, ``accepted``, ``phi``, ``time_s``.
    """
    obj = objective
    t0 = time.perf_counter()
    zc = z_centre.copy()

    def fun_x(zx):
        z = zc.copy()
        z[xv] = zx
        return obj.fun(z)

    def jac_x(zx):
        z = zc.copy()
        z[xv] = zx
        return obj.jac_columns(z, xv)

    c_before = 0.5 * float(np.sum(obj.fun(zc) ** 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        pre = least_squares(
            fun_x, zc[xv], jac=jac_x, bounds=(obj.zlo[xv], obj.zhi[xv]), method="trf", x_scale=1.0,
            ftol=tol, xtol=tol, gtol=tol, max_nfev=max_nfev,
        )
    accepted = bool(np.isfinite(pre.cost) and pre.cost < c_before)
    if accepted:
        z_centre = z_centre.copy()
        z_centre[xv] = pre.x
        z_centre = strictly_inside(z_centre, obj.zlo, obj.zhi)
        obj.update_noise(obj.theta_of(z_centre))
    p_theta = obj.problem.core.p_theta
    record = {
        "cost_before": c_before, "cost_after": float(pre.cost), "nfev": int(pre.nfev),
        "accepted": accepted,
        "phi": (obj.theta_of(z_centre)[p_theta:]).tolist(), "time_s": time.perf_counter() - t0,
    }
    if log is not None:
        log(f"warm start: phi given theta: cost {c_before:.6g} -> {pre.cost:.6g}, nfev {pre.nfev}")
    return z_centre, record


def start_points(z_centre, z_minima, n_starts, seed, spread, zlo, zhi):
    """Starts of the global search: the centre, further equation-error minima, then Sobol points.

    ``z_minima``: scaled equation-error minima after the best (best first).
    Sobol points fill up to ``n_starts`` in ``z_centre +- spread *
    max(|z_centre|, 0.05)``.
    """
    starts = [z_centre]
    for z in z_minima:
        if len(starts) >= n_starts:
            break
        starts.append(z)
    starts += [
        strictly_inside(z, zlo, zhi)
        for z in sobol_box(z_centre, n_starts - len(starts), seed, spread)
    ]
    return starts


@dataclass
class SearchOutcome:
    """Result of :func:`multi_start`.

    ``records``: one dict per start (x0, cost, nfev, njev, status, message,
    optimality, time_s, refined); ``results``: start index -> final
    ``OptimizeResult``; ``ranked``: start indices by cost after stage 1;
    ``best``: index of the lowest final cost; ``explore``: the stage-1 budget.
    """

    records: list
    results: dict
    ranked: list
    best: int
    explore: int
    refined: list = field(default_factory=list)


def multi_start(solver, starts, max_nfev, explore_nfev, n_refine, log=None):
    """Stage 1: a short local run from every start; stage 2: the ``n_refine`` best to convergence.

    The budget is ``max_nfev`` in total per start (the whole budget at once
    when there are at most ``n_refine`` starts). Starts with a non-finite
    prediction are skipped.
    """
    obj = solver.objective
    sv_scale = obj.sv_scale
    explore = max_nfev if len(starts) <= n_refine else min(explore_nfev, max_nfev)
    records = []
    results = {}
    for i, z_init in enumerate(starts):
        r_init = obj.fun(z_init)
        if not np.all(np.abs(r_init) < 1e9):
            records.append(
                {"start": i, "status": None, "message": "skipped: non-finite prediction at start",
                 "cost": float("inf"), "nfev": 0, "njev": 0, "time_s": 0.0,
                 "x0": (z_init * sv_scale).tolist(), "refined": False}
            )
            continue
        res, dtime = solver(z_init, explore)
        results[i] = res
        records.append(
            {
                "start": i,
                "x0": (z_init * sv_scale).tolist(),
                "cost": float(res.cost),
                "nfev": int(res.nfev),
                "njev": int(res.njev) if res.njev is not None else None,
                "status": int(res.status),
                "message": str(res.message),
                "optimality": float(res.optimality),
                "time_s": dtime,
                "refined": False,
            }
        )
        if log is not None:
            log(f"start {i}: cost {res.cost:.6g} nfev {res.nfev} status {res.status} ({dtime:.2f}s)")
    if not results:
        raise IdentificationError("global search failed: every start gave a non-finite prediction")
    ranked = sorted(results, key=lambda i: results[i].cost)
    for i in ranked[:n_refine]:
        res0 = results[i]
        if res0.status != 0 or explore >= max_nfev:
            continue  # converged already (or had the full budget)
        res, dtime = solver(res0.x, max_nfev - explore)
        results[i] = res
        rec = records[[r["start"] for r in records].index(i)]
        rec.update(
            cost=float(res.cost), nfev=rec["nfev"] + int(res.nfev),
            njev=(rec["njev"] or 0) + int(res.njev or 0), status=int(res.status),
            message=str(res.message), optimality=float(res.optimality),
            time_s=rec["time_s"] + dtime, refined=True,
        )
        if log is not None:
            log(f"refine {i}: cost {res.cost:.6g} nfev {res.nfev} status {res.status} ({dtime:.2f}s)")
    best = min(results, key=lambda i: results[i].cost)
    return SearchOutcome(records, results, ranked, best, explore, ranked[:n_refine])


@dataclass
class NoiseRefinement:
    """Result of :func:`alternate_noise`: final point and run, history, whether R converged."""

    z: np.ndarray
    final: object
    history: list
    converged: bool


def alternate_noise(solver, z_best, best_res, max_outer, max_nfev, log=None):
    """Eq. 32 for unknown R: re-estimate the noise at the optimum and refit until R changes by < 1 %.

    At most ``max_outer`` refits; ``history[0]`` is the search's optimum
    (with ``R_change`` of the first re-estimation).
    """
    obj = solver.objective
    outer_hist = [{"iteration": 0, "cost": float(best_res.cost),
                   "noise_var_median": float(np.median(obj.noise.R))}]
    final_res = best_res
    converged_R = False
    for it in range(1, max_outer + 1):
        change = obj.update_noise(obj.theta_of(z_best))
        R_cur = obj.noise.R
        outer_hist[-1]["R_change"] = change
        if change < 0.01:
            converged_R = True
            break
        res, dtime = solver(z_best, max_nfev)
        z_best = res.x
        final_res = res
        outer_hist.append(
            {"iteration": it, "cost": float(res.cost), "nfev": int(res.nfev), "status": int(res.status),
             "noise_var_median": float(np.median(R_cur)), "time_s": dtime}
        )
        if log is not None:
            log(f"outer {it}: R change {change:.3g}, cost {res.cost:.6g}, nfev {res.nfev}")
    return NoiseRefinement(z_best, final_res, outer_hist, converged_R)


@dataclass
class ProfileRefinement:
    """Result of :func:`profile_refine`: final point, a least_squares-like result, history, convergence."""

    z: np.ndarray
    final: object
    history: list
    converged: bool
    stalled: bool = False   #: stopped because no damped step gained (numerical, not statistical, stop)


def _run_sums(run_sel, n_runs, X):
    """Per-run column sums of the rows of ``X`` (n_runs, p): one ``bincount`` per column (the rows added in
    their order, as ``numpy.add.at`` adds them: the same sums to the last bit, without its per-element cost)."""
    out = np.empty((n_runs, X.shape[1]))
    for k in range(X.shape[1]):
        out[:, k] = np.bincount(run_sel, weights=X[:, k], minlength=n_runs)
    return out


def bounded_step(H, D, g, lam, z, zlo, zhi):
    """Damped Newton step ``(H + lam diag D) dz = -g``; coordinates at a bound that the step would
    push further out are held (solved again without them)."""
    d = np.maximum(D, 1e-12 * max(float(np.max(D)), 1e-300))
    A = H + lam * np.diag(d)
    free = np.ones(z.size, bool)
    for _ in range(3):
        dz = np.zeros_like(z)
        idx = np.flatnonzero(free)
        dz[idx] = np.linalg.solve(A[np.ix_(idx, idx)], -g[idx])
        tol = np.where(np.isfinite(zhi - zlo), 1e-9 * (zhi - zlo), 0.0)
        out = free & (((z <= zlo + tol) & (dz < 0)) | ((z >= zhi - tol) & (dz > 0)))
        if not out.any():
            break
        free &= ~out
    return dz


def history_nfev(history) -> int:
    """Evaluations counted in a refinement history so far."""
    return 1 + sum(h.get("nfev", 0) for h in history[1:])


def profile_refine(objective, z, max_iter=100, stat_tol=0.01, stat_window=3, log=None, coupling=2.0):
    """Eq. 32 with unknown R as one problem: maximise the profile likelihood over theta.

    The per-run variances are at their ML values at every point (``R_r = S_r / n_r``,
    S_r the run's whitened sum of squares; floored runs keep the floor), so the
    criterion is ``-sum_r n_r/2 log S_r`` + const. A damped Gauss-Newton
    iteration: gradient ``J_w^T r_w`` (the weighted least-squares gradient at those
    variances) and curvature ``sum_r J_w,r^T (I - c P_r) J_w,r`` with ``P_r`` the
    projector on the run's weighted residual and ``c = coupling`` (2: the
    Gauss-Newton curvature of ``n_r/2 log S_r``; the variance absorbs what
    only rescales the run's residuals), damped Levenberg-Marquardt style with
    the least-squares diagonal. This keeps the coupling between theta and R that the alternation
    of :func:`alternate_noise` (fit theta at fixed R, re-estimate R, repeat)
    resolves only over many refits on data the model does not fit exactly.
    The start-speed term ``g`` is re-estimated at every accepted point.

    Stops on statistical progress: when the log-likelihood gained less than
    ``stat_tol`` over the last ``stat_window`` iterations (or no step gains).
    The free run is only piecewise smooth (a run at the edge of sticking or
    reversing is a kink): a local search can end on one, which is why the
    global search (:func:`profile_search`) compares several starts.
    """
    obj = objective
    noise = obj.noise
    t0 = time.perf_counter()

    def loglik_at(zz, start_gain=True):
        theta = obj.theta_of(zz)
        r = obj.problem.residual(theta)
        with np.errstate(over="ignore", invalid="ignore"):  # a trial step may blow the free run up: rejected
            if start_gain:
                obj.update_noise(theta)
            else:  # the step's model: g as at the iteration's start
                noise.update_R(r)
            return noise.loglik(r)

    ll = loglik_at(z)
    history = [{"iteration": 0, "loglik": ll}]
    lam, nfev, njev, converged, reason, stalled = 1e-3, 1, 0, False, "iteration limit", False
    g = np.zeros_like(z)
    n_runs, run_sel = noise.n_runs, noise.run_sel
    for it in range(1, max_iter + 1):
        rw = obj.fun(z)
        J = obj.jac(z)
        njev += 1
        g = J.T @ rw
        H = J.T @ J
        D = np.diag(H).copy()
        s = np.bincount(run_sel, weights=rw * rw, minlength=n_runs)
        u = _run_sums(run_sel, n_runs, J * rw[:, None])
        w = noise.W(obj.problem.residual(obj.theta_of(z)))
        ss = np.bincount(run_sel, weights=w * w, minlength=n_runs)
        at_ml = (noise.counts > 0) & (s > 0) & np.isclose(noise.R * np.maximum(noise.counts, 1), ss, rtol=1e-9)
        saved = dict(vars(noise))
        ll_frozen = noise.loglik(obj.problem.residual(obj.theta_of(z)))
        accepted = False
        # the coupled step (profile likelihood); on a kink of the free run, where it finds no gain, the
        # least-squares step at the current variances (accepted by the likelihood at those variances,
        # the variances then re-estimated: a step of the alternation, which cannot lose likelihood)
        for c, lam_max, frozen in ((coupling, 1e4, False), (0.0, 1e10, True)):
            Hc = H if c == 0.0 or not at_ml.any() else H - c * (u[at_ml] / s[at_ml, None]).T @ u[at_ml]
            lam_c = lam
            while lam_c < lam_max:
                dz = bounded_step(Hc, D, g, lam_c, z, obj.zlo, obj.zhi)
                z_new = strictly_inside(np.clip(z + dz, obj.zlo, obj.zhi), obj.zlo, obj.zhi)
                if frozen:  # at the variances of the iteration's start
                    with np.errstate(over="ignore", invalid="ignore"):
                        ll_trial, ref = noise.loglik(obj.problem.residual(obj.theta_of(z_new))), ll_frozen
                else:  # at the variances' ML values there (g as at the start)
                    ll_trial, ref = loglik_at(z_new, start_gain=False), ll
                nfev += 1
                if np.isfinite(ll_trial) and ll_trial > ref:
                    accepted = True
                    lam = max(lam_c / 3.0, 1e-9)
                    ll_new = loglik_at(z_new)  # g and R at the new point
                    break
                vars(noise).update(saved)
                lam_c *= 4.0
            if accepted:
                break
        if not accepted or not ll_new > ll - 1e-9 * abs(ll):
            vars(noise).update(saved)
            converged, reason, stalled = True, STALL_MESSAGE, True
            break
        history.append({"iteration": it, "loglik": ll_new, "nfev": nfev - history_nfev(history), "lambda": lam})
        z, ll = z_new, ll_new
        if log is not None:
            log(f"profile {it}: loglik {ll:.4f} (lambda {lam:.1e})")
        if it >= stat_window and ll - history[-1 - stat_window]["loglik"] < stat_tol:
            converged = True
            reason = (f"statistical convergence: log-likelihood gained < {stat_tol:g} "
                      f"over the last {stat_window} iterations")
            break
    r = obj.fun(z)
    final = SimpleNamespace(x=z, cost=float(0.5 * np.sum(r * r)), nfev=nfev, njev=njev,
                            status=-2 if converged else 0, message=reason,
                            optimality=float(np.max(np.abs(g))) if g.size else 0.0,
                            time_s=time.perf_counter() - t0)
    return ProfileRefinement(z, final, history, converged, stalled=stalled)


#: :func:`profile_refine`'s stop when no damped step gains (a numerical, not a statistical, stop)
STALL_MESSAGE = "no step increases the log-likelihood"


def polish_stalled(solver, refinement, max_outer, max_nfev, min_gain=0.0, log=None):
    """Continue a profile refinement with least-squares refits (the estimator runs it after every profile search).

    :func:`profile_refine` can stop with :data:`STALL_MESSAGE` short of the
    optimum when its damped steps find no gain: near-exact data (residuals
    ~1e-7 of the speed with exact null directions) or a kink of the free run
    (measured: 1 log-likelihood unit short on an order-mismatched fit). Its
    statistical stop never fired there, so the fit is not done: trust-region
    least squares at the variances' ML values, the variances re-estimated
    after each refit, continue from the stalled point while a refit gains
    more than ``min_gain`` (the statistical tolerance) in log-likelihood, at
    most ``max_outer`` refits (converged: a further refit gains < ``min_gain``).
    A refit that does not gain is not kept; if none gains, the refinement
    (and its noise model) is returned unchanged.
    """
    obj = solver.objective
    ll0 = refinement.history[-1]["loglik"]
    z, ll, nfev, final, steps, converged = refinement.z, ll0, 0, None, 0, False
    for _ in range(max_outer):
        res, _dt = solver(z, max_nfev)
        nfev += int(res.nfev)
        obj.update_noise(obj.theta_of(res.x))
        ll_new = obj.noise.loglik(obj.problem.residual(obj.theta_of(res.x)))
        if not ll_new > ll:  # a further refit gains nothing
            converged = True
            break
        z, final, steps = res.x, res, steps + 1
        gain, ll = ll_new - ll, ll_new
        if gain <= min_gain:
            converged = True
            break
    obj.update_noise(obj.theta_of(z))
    if final is None:
        return refinement
    final.status = -2 if converged else final.status
    final.message = (f"{refinement.final.message}; continued by {steps} least-squares refit(s) at the ML variances: "
                     + ("a further refit gains < stat_tol log-likelihood units" if converged else str(final.message)))
    history = refinement.history + [{"iteration": len(refinement.history), "loglik": ll, "nfev": nfev,
                                     "polish": f"{steps} least-squares refit(s) after the damped Gauss-Newton "
                                               f"stopped ({refinement.final.message})"}]
    if log is not None:
        log(f"polish: loglik {ll0:.4f} -> {ll:.4f}, nfev {nfev}")
    return ProfileRefinement(z, final, history, refinement.converged)


def profile_search(objective, starts, max_iter, stat_tol, stat_window, agree, log=None):
    """Global search on the profile likelihood: :func:`profile_refine` from every start, in order.

    Each start is refined to statistical convergence with the noise variances at
    their ML values, so the starts are compared by the likelihood itself (not at
    variances estimated at another point). Statistical stop of the search: once
    ``agree`` starts (0: never) reached the best log-likelihood within
    ``10 * stat_tol``, the remaining starts are skipped (recorded as skipped):
    a further start finding the same optimum again would not change the fit.

    Returns ``(SearchOutcome, ProfileRefinement of the best start)``; the results'
    ``cost`` is the negative log-likelihood (differences are log-likelihood units).
    """
    obj = objective
    sv_scale = obj.sv_scale
    records, results, refinements = [], {}, {}
    for i, z_init in enumerate(starts):
        r_init = obj.fun(z_init)
        if not np.all(np.abs(r_init) < 1e9):
            records.append({"start": i, "status": None, "message": "skipped: non-finite prediction at start",
                            "cost": float("inf"), "nfev": 0, "njev": 0, "time_s": 0.0,
                            "x0": (z_init * sv_scale).tolist(), "refined": False})
            continue
        ref = profile_refine(obj, z_init, max_iter, stat_tol, stat_window)
        ll = ref.history[-1]["loglik"]
        res = ref.final
        res.cost = -ll
        results[i], refinements[i] = res, ref
        records.append({"start": i, "x0": (z_init * sv_scale).tolist(), "cost": -ll, "loglik": ll,
                        "nfev": int(res.nfev), "njev": int(res.njev), "status": int(res.status),
                        "message": str(res.message), "optimality": float(res.optimality),
                        "iterations": len(ref.history) - 1, "time_s": res.time_s, "refined": True})
        if log is not None:
            log(f"start {i}: loglik {ll:.4f} after {len(ref.history) - 1} iterations, nfev {res.nfev} "
                f"({res.time_s:.2f}s)")
        best_ll = max(-r.cost for r in results.values())
        if agree and sum(-r.cost >= best_ll - 10 * stat_tol for r in results.values()) >= agree:
            for j in range(i + 1, len(starts)):
                records.append({"start": j, "status": None, "cost": float("inf"), "nfev": 0, "njev": 0,
                                "time_s": 0.0, "x0": (starts[j] * sv_scale).tolist(), "refined": False,
                                "message": f"skipped: statistical stop ({agree} starts reached the best "
                                           f"log-likelihood within {10 * stat_tol:g})"})
            break
    if not results:
        raise IdentificationError("global search failed: every start gave a non-finite prediction")
    ranked = sorted(results, key=lambda i: results[i].cost)
    best = ranked[0]
    ref = refinements[best]
    obj.update_noise(obj.theta_of(ref.z))  # the noise model at the chosen optimum (not the last start's)
    return SearchOutcome(records, results, ranked, best, 0, list(ranked)), ref


def search_nfev(solver, noise_fit, search, outer) -> int:
    """Function evaluations of a global search (profile, varpro and offset: the records hold the refinement's)."""
    own = sum(rec.get("nfev", 0) for rec in search.records)
    if solver != "joint" or noise_fit == "profile":
        return int(own)
    return int(own + sum(h.get("nfev", 0) for h in outer.history[1:]))
