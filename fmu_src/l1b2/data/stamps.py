"""The time stamps' steps per sample: the step a speed derived over the logged ``time_s`` divides by.

A speed derived from the position over the time column by the data format's derivative (``numpy.gradient``:
three points over uneven steps inside a run, one-sided at its ends) divides the position's change at sample ``k``
by an effective step,

    ``h_eff = h1 h2 (h1 + h2) / (h1^2 + h2^2)`` inside a run (``h1 = t_k - t_(k-1)``, ``h2 = t_(k+1) - t_k``),
    ``h1`` at a run's first sample (its first step) and its last step at its last sample,

which is the step itself on a regular clock. When the samples were taken on a regular clock of step ``dt`` and the
stamps are not their times (a host's arrival stamps), the derivative over the stamps of a position that moves at
``v`` over ``dt`` is ``v dt / h_eff``, exactly for a position linear in the true time. The **time step ratio** of
a sample is ``dt / h_eff`` with ``dt`` its run's median step (the clock's own step when most steps are regular):
1 on a regular clock, the factor by which a speed derived over arrival stamps differs from the slider's speed.
"""

from __future__ import annotations

import numpy as np

from .columns import run_slices

__all__ = ["effective_steps_s", "time_step_ratio", "regular_clock_derivative"]


def effective_steps_s(t_s, runs) -> np.ndarray:
    """Per sample, the effective step [s] of the data format's derivative over the stamps ``t_s`` within its run
    (``runs``: the run id per sample, each run's samples consecutive; module docstring). NaN in a run of one
    sample."""
    t = np.asarray(t_s, float)
    out = np.full(t.size, np.nan)
    for _, sl in run_slices(runs):
        a, b = sl.start, sl.stop
        if b - a < 2:
            continue
        h = np.diff(t[a:b])
        out[a], out[b - 1] = h[0], h[-1]
        h1, h2 = h[:-1], h[1:]
        out[a + 1:b - 1] = h1 * h2 * (h1 + h2) / (h1 ** 2 + h2 ** 2)
    return out


def time_step_ratio(t_s, runs) -> np.ndarray:
    """Per sample, its run's median step over its effective step (:func:`effective_steps_s`) [1]; 1 in a run of one
    sample or with no positive step."""
    t = np.asarray(t_s, float)
    h = effective_steps_s(t, runs)
    out = np.ones(t.size)
    for _, sl in run_slices(runs):
        a, b = sl.start, sl.stop
        if b - a < 2:
            continue
        med = float(np.median(np.diff(t[a:b])))
        if med > 0 and np.all(h[a:b] > 0):
            out[a:b] = med / h[a:b]
    return out


def regular_clock_derivative(s_m, t_s) -> np.ndarray:
    """The derivative [m/s] of one run's positions ``s_m`` [m] over a regular clock of the run's median step (the
    sample index times it): the slider's speed when the samples were taken on that clock, whatever the stamps."""
    s = np.asarray(s_m, float)
    if s.size < 2:
        return np.zeros(s.size)
    dt = float(np.median(np.diff(np.asarray(t_s, float))))
    return np.gradient(s, dt) if dt > 0 else np.zeros(s.size)
