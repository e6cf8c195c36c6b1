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

import numpy as np
from scipy.optimize import least_squares

from ..errors import IdentificationError
from .problem import strictly_inside

__all__ = [
    "HAS_CALLBACK", "StatStop", "sobol_box", "LocalSolver", "start_points", "SearchOutcome", "multi_start",
    "warm_prestep", "NoiseRefinement", "alternate_noise",
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
    """

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
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            res = least_squares(
                obj.fun,
                z_init,
                jac=obj.jac,
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
