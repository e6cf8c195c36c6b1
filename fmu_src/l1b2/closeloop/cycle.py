"""A cycle of the session that the runs' own deviations show: the period search of the run-level analysis
(:mod:`l1b2.closeloop.runlevel`) for the family :class:`l1b2.predictor.effects.cycle.SessionCycle`, when the loop's
``session_cycle`` option asks for it.

The runs' deviations ``theta_r`` (gain, offset; :class:`l1b2.closeloop.runlevel.RunDeviations`) are set against
their mean session times ``t_r``. For each period ``P`` of a grid (:func:`periods_s`) the cycle's cosine and sine of
``t_r`` (:func:`l1b2.predictor.effects.cycle.cycle_waves`), each less its least-squares line in ``t_r`` over the
runs (:func:`detrended`: a drift of the session is the session clock's own signal, and over a few cycles a
drift would otherwise pass for the longest ones), enter the runs' mean on the gain (``gain_only`` of
:func:`l1b2.closeloop.runstats.joint_test`: the family's form). The period of the smallest p-value of that joint Wald
test (2 degrees of freedom) is the cycle found (:func:`cycle_signal`); its p-value is multiplied by the number of
periods tried (a union bound over every period the search could have returned).

The waves are also taken free of the plan's inputs per run (:func:`plan_columns`: V0 and its square, the
drive-coordinate load ``d m``, the load's size and square, the direction and the direction times V0): a plan that
repeats its settings every few runs gives the runs' deviations a period of its own (an effect of V0 or the load the
model lacks follows the plan's pattern), which a cycle of the session clock must not take. A cycle that the plan's
sequence carries cannot be told from the plan, and is not searched.

The grid: frequencies from ``1/S`` (``S`` the span of the runs' mean times: one cycle over the session) to
``1/(MIN_RUNS_PER_CYCLE dt)`` (``dt`` the median step between consecutive runs' mean times), in steps of
``1/(OVERSAMPLING S)``: :data:`OVERSAMPLING` points per independent frequency of the runs' span.
"""

from __future__ import annotations

import numpy as np

from ..predictor.effects.channels import SESSION_TIME
from ..predictor.effects.cycle import CYCLE, cycle_waves
from .runstats import joint_test

#: the fewest runs per cycle searched (at two, a cycle alternates run by run: the plan's own pattern of conditions)
MIN_RUNS_PER_CYCLE = 3
#: grid points per independent frequency (``1/S``) of the runs' span
OVERSAMPLING = 3
#: the fewest runs the search needs
MIN_RUNS = 8


def periods_s(t_run_s) -> np.ndarray:
    """The periods [s] searched for runs at mean session times ``t_run_s`` (module docstring), longest first;
    empty for fewer than :data:`MIN_RUNS` runs or runs that span no time."""
    t = np.sort(np.asarray(t_run_s, float))
    if len(t) < MIN_RUNS or not np.all(np.isfinite(t)):
        return np.zeros(0)
    span, dt = float(t[-1] - t[0]), float(np.median(np.diff(t)))
    if not (span > 0 and dt > 0):
        return np.zeros(0)
    f_hi = 1.0 / (MIN_RUNS_PER_CYCLE * dt)
    f = np.arange(1.0 / span, f_hi * (1 + 1e-12), 1.0 / (OVERSAMPLING * span))
    return 1.0 / f


def plan_columns(voltage_V, direction, load_kg) -> np.ndarray:
    """The plan's inputs per run that the cycle's waves are taken free of (module docstring), ``(n, 7)``: ``V0``,
    ``V0^2``, ``d m``, ``|m|``, ``m^2``, ``d`` and ``d V0``, each standardised (centred, over its standard deviation;
    a constant one left at 0)."""
    V, d, m = (np.asarray(x, float) for x in (voltage_V, direction, load_kg))
    cols = np.column_stack([V, V * V, d * m, np.abs(m), m * m, d, d * V])
    sd = cols.std(axis=0)
    return (cols - cols.mean(axis=0)) / np.where(sd > 0, sd, 1.0)


def detrended(Z, t_s, plan=None) -> np.ndarray:
    """The columns of ``Z`` (n, q) less their least-squares fit on ``[1, t]`` (``t_s`` (n,): their line in the session
    times) and on the columns of ``plan`` (n, p) when given (:func:`plan_columns`): the residual."""
    Z = np.asarray(Z, float).reshape(len(t_s), -1)
    G = np.column_stack([np.ones(len(Z)), np.asarray(t_s, float) - float(np.mean(t_s))]
                        + ([] if plan is None else [np.asarray(plan, float).reshape(len(Z), -1)]))
    return Z - G @ np.linalg.lstsq(G, Z, rcond=None)[0]


def cycle_signal(dev, t_run_s, plan=None) -> dict | None:
    """The session's cycle as a run-level signal, or None when no period is searched (:func:`periods_s`).

    ``dev``: the runs' deviations; ``t_run_s``: each run's mean session time [s], in ``dev.runs``' order; ``plan``:
    the plan's inputs per run, in that order (:func:`plan_columns`; None: the waves are free of the line only). The
    signal
    ``{"channel": "time_s", "transform": "cycle", "values": t_run_s, "columns", "period_s", "shares",
    "search_count"}``: ``columns`` the detrended waves of the period found (what its evidence tests), ``shares`` the
    plain waves' means over the runs (the family's centring, :func:`l1b2.predictor.effects.cycle.cycle_spec`),
    ``search_count`` the number of periods tried."""
    t = np.asarray(t_run_s, float)
    periods = periods_s(t)
    if len(periods) == 0:
        return None
    best = None
    for P in periods:
        z = detrended(cycle_waves(t, P), t, plan)
        p = joint_test(dev, z, True)[1]
        if best is None or p < best[0]:
            best = (p, float(P), z)
    _, P, z = best
    return {"channel": SESSION_TIME, "transform": CYCLE, "values": t, "columns": z, "period_s": P,
            "shares": tuple(float(m) for m in cycle_waves(t, P).mean(axis=0)), "search_count": len(periods)}
