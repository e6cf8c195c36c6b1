"""A run setting's history: its low-pass on the session clock (a store), and the drive's step from its last setting.

A rig may log a setting that the design changes from run to run (a heater's power, a coolant's flow, a bias
current) while the motor feels it through a store: a thermal mass, a charge, a soaked film. The effect then follows
the setting's low-pass in session time, delayed by a few runs, and the setting's current value explains little of
it. For each *run setting* the loop therefore derives the logged columns ``<column>_lag<n>r`` (:data:`TAU_RUNS`):

    ``y' = (c - y) / tau`` on the session clock, ``c`` held at its last logged value between samples (a setting
    holds through the pause until the next run's), ``y`` starting at the session's first value,
    ``tau = n`` times the session's median run period (start to start),

solved exactly sample to sample (``y_i = c_(i-1) + (y_(i-1) - c_(i-1)) exp(-(t_i - t_(i-1)) / tau)``), and considers
each as one more logged channel (every form, shape and level of :mod:`l1b2.predictor.effects.channels` and the
run-level evidence). A lag is a smooth curve of the session, so a form of it accepted over run folds must pass over
contiguous blocks of the session too (:func:`l1b2.closeloop.acceptance.block_checked`). The derivation reads only
the logged channel and the clock, never a response; TRAIN and TEST are merged in time order when they are one session
(:func:`l1b2.closeloop.events.one_session`), so TEST's first run carries the store TRAIN's runs filled; otherwise
each frame from its own runs.

A column is a run setting (:func:`run_settings`) when it is a logged candidate channel, constant within every run and
changes between consecutive runs more often than a step channel may (more than once per
:data:`l1b2.closeloop.events.MIN_BLOCK_RUNS` runs on average; a step channel gets its event clock instead). A
channel that varies within runs is not lagged: its sensor already samples the path along the stroke.

The plan's own drive amplitude is such a setting too (:data:`STORED_INPUTS`): the motor stores what its drive did in
the previous runs (the stator's heat, a piezoceramic's de-ageing under a strong field, a film worked by fast runs), so
its effect follows the voltage's low-pass while the current run's voltage is already a model input. When the
plan's ``voltage_V`` is a run setting by the rule above, its lags ``voltage_V_lag<n>r`` are derived like a logged
column's; the voltage itself stays an input, never a channel.

**The setting's step.** A stored input's state before the session is known (:data:`BEFORE_SESSION`: the drive
off, 0 V), and how a setting was *reached* leaves a state of its own that a low-pass starting at the session's first
value cannot see: an operator who overshoots a knob by a share of the step, a range relay or a hysteresis side
chosen by the direction of the last change. For each stored input that is a run setting the loop therefore also
derives ``<column>_step`` (:data:`STEP_SUFFIX`, :func:`setting_steps`), per run in session order:

    the run's setting minus the previous *different* setting, held while the setting is unchanged (a state set by a
    change lasts until the next change); the previous setting of the session's first run is the state before the
    session,

constant within each run, one more logged channel like the lags (the same merge of one session; two sessions each
from their own first run and the drive off before each). A logged run setting gets no step: its state before the
session is not known, and a step of 0 for its first setting would state one (decision 0120).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
# the suffixes of the lags and of the step (``_lag<n>r``, ``_step``): the naming rule that gives each its column's unit
from ..units import STEP_SUFFIX, lag_suffix
from .auxiliary import varies_within_runs
from .candidates import channels_of
from .events import MIN_BLOCK_RUNS, Session, event_times, run_table, session

#: the stores' time constants, in the session's median run period
TAU_RUNS = (3, 10)
#: the model inputs whose lags are derived when they are run settings (the drive's history: module docstring)
STORED_INPUTS = (dataio.VOLTAGE,)
#: the state of each stored input before the session (the drive off): the previous setting of the first run
BEFORE_SESSION = {dataio.VOLTAGE: 0.0}


def lowpass(t, c, tau: float) -> np.ndarray:
    """The first-order low-pass of the samples ``c`` at times ``t`` (sorted) with time constant ``tau`` [s]: ``c``
    held between samples, the start at ``c[0]`` (module docstring)."""
    t, c = np.asarray(t, float), np.asarray(c, float)
    if not tau > 0:
        raise ValueError(f"lag time constant {tau} s is not positive")
    y = np.empty_like(c)
    if len(c) == 0:
        return y
    decay = np.exp(-np.diff(t) / tau)
    y[0] = c[0]
    for i in range(1, len(c)):
        y[i] = c[i - 1] + (y[i - 1] - c[i - 1]) * decay[i - 1]
    return y


def setting_steps(values, before: float) -> np.ndarray:
    """Per run (``values``: each run's setting in session order), its setting minus the previous different setting,
    held while the setting is unchanged; the first run's previous setting is ``before`` (a first run at ``before``
    has step 0 until the first change)."""
    v = np.asarray(values, float)
    d = v - np.concatenate([[float(before)], v[:-1]])
    last = np.maximum.accumulate(np.where(d != 0, np.arange(len(v)), -1))   # the latest change at or before each
    return np.where(last >= 0, d[np.maximum(last, 0)], 0.0)


def is_run_setting(tab: pd.DataFrame, within_run: bool) -> bool:
    """The run-setting rule on one channel's run table (session order): constant within runs and more than one
    change per :data:`~l1b2.closeloop.events.MIN_BLOCK_RUNS` runs."""
    return (not within_run) and len(event_times(tab)) > len(tab) / MIN_BLOCK_RUNS


def run_settings(df: pd.DataFrame, response_columns=None) -> list[str]:
    """The run settings of a TRAIN frame (module docstring): the inputs of :data:`STORED_INPUTS` that are run
    settings, then the logged channels in column order."""
    inputs = [c for c in STORED_INPUTS if c in df.columns
              and is_run_setting(run_table([df], c), varies_within_runs(df, c))]
    return [c for c in inputs if not any(c + lag_suffix(n) in df.columns for n in TAU_RUNS)] + [
        ch["name"] for ch in channels_of(df, response_columns)
        if ch["kind"] == "logged" and not any(ch["name"] + lag_suffix(n) in df.columns for n in TAU_RUNS)
        and is_run_setting(run_table([df], ch["name"]), ch["within_run"])]


def run_period(tab: pd.DataFrame) -> float:
    """The median start-to-start time of consecutive runs [s] (``tab``: :func:`~l1b2.closeloop.events.run_table`)."""
    starts = tab["start"].to_numpy(float)
    return float(np.median(np.diff(starts))) if len(starts) > 1 else 0.0


def with_lagged_channels(train: pd.DataFrame, test: pd.DataFrame | None = None, response_columns=None,
                         sess: Session | None = None):
    """``(train, test, record)``: copies of the frames with the lags of every run setting of ``train`` appended, and
    the step of each that is a stored input (``test`` None stays None), and ``record`` ``[{"channel", "lags",
    "tau_s", "one_session", "start", "step", "step_from"}]`` (``start`` the lags' value at the first sample of each
    session, TRAIN's first: the session's first setting, which a host computing the lags starts from; ``step``
    the step's column or None, ``step_from`` the state before the session it starts from or None).

    ``sess``: the frames' :func:`~l1b2.closeloop.events.session` when the caller has it (default: computed here).
    The frames are returned unchanged (not copied) when TRAIN has no run setting.
    """
    names = run_settings(train, response_columns)
    sess = session(train, test) if sess is None else sess
    period = run_period(sess.runs)
    if not names or not period > 0:
        return train, test, []
    train, test = train.copy(), (test.copy() if test is not None else None)
    merged = sess.one
    taus = [n * period for n in TAU_RUNS]
    record = []
    for name in names:
        frames, starts = [df for df in (train, test) if df is not None and name in df.columns], []
        for group in [frames] if merged else [[df] for df in frames]:
            t = np.concatenate([df[dataio.TIME].to_numpy(float) for df in group])
            c = np.concatenate([df[name].to_numpy(float) for df in group])
            order = np.argsort(t, kind="stable")
            t_o, c_o = t[order], c[order]
            starts.append(float(c_o[0]))
            for n, tau in zip(TAU_RUNS, taus):
                y = np.empty_like(c)
                y[order] = lowpass(t_o, c_o, tau)
                k = 0
                for df in group:
                    df[name + lag_suffix(n)] = y[k:k + len(df)]
                    k += len(df)
            if name in BEFORE_SESSION:
                _add_steps(group, name)
        record.append({"channel": name, "lags": [name + lag_suffix(n) for n in TAU_RUNS],
                       "tau_s": [float(x) for x in taus], "one_session": merged, "start": starts,
                       "step": name + STEP_SUFFIX if name in BEFORE_SESSION else None,
                       "step_from": BEFORE_SESSION.get(name)})
    return train, test, record


def _add_steps(group, name: str) -> None:
    """Write ``<name>_step`` (:func:`setting_steps` from :data:`BEFORE_SESSION`) into the frames of one session."""
    tab = run_table(group, name)
    tab["step"] = setting_steps(tab["value"], BEFORE_SESSION[name])
    for i, df in enumerate(group):
        per_run = tab[tab["frame"] == i].set_index("run")["step"]
        df[name + STEP_SUFFIX] = df[dataio.RUN].map(per_run).to_numpy(float)
