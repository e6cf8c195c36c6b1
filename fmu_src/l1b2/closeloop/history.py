"""The previous pass: the speed of the run before each run, read from the log, as a channel.

A run can meet a state that the run before it left on the motor: the bar's oil film that the last pass entrained
(its thickness follows the speed of that pass), the wear debris or transfer layer it smeared, the heat its friction
dissipated in the contact. Such a state is set by what the previous run *did*, not by the plan's settings alone
(two passes at the same voltage and load run at different speeds when the motor's state differs), so neither the
current run's inputs nor a low-pass of the drive amplitude (:mod:`~l1b2.closeloop.lags`) carries it. For every
session the loop therefore derives the logged column :data:`COLUMN`, constant within each run:

    the mean speed of the run that ended last before the run started [m/s], ``|s_last - s_first| / (t_last -
    t_first)`` of that run's ``position_m`` and ``time_s`` (its stroke over its duration),

and considers it as one more logged channel (every form and shape of :mod:`l1b2.predictor.effects.channels` at the
run level, and the run-level evidence: one family). The value is a measurement of a run that is over when the run
starts: a host that predicts a run knows it (``Predictor.fmu`` reads it like any logged channel's, an input named
after it), and it is never the current run's own response.

The first run of a session has no previous run (the pass before the session is not in the log); it gets TRAIN's
median of the known values, the rig's typical pass, which puts the run at the channel's centre and gives it no
leverage. A run of one sample or of zero duration has no speed; a run after it gets the same median. TRAIN and TEST
are merged in time order when they are one session (:func:`l1b2.closeloop.events.one_session`), so a TEST run whose
previous run is a TRAIN run reads that run's speed; otherwise each frame's runs are ordered on their own.

The column is derived when TRAIN has at least :data:`MIN_KNOWN_RUNS` known values and they vary (their range above
:data:`VARY_RTOL` times the largest).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from .events import Session, session

#: the derived column: the previous run's mean speed [m/s] (the rig's naming rule gives the unit)
COLUMN = "prev_run_speed_m_s"
#: the fewest TRAIN runs with a known previous pass for the column to be derived
MIN_KNOWN_RUNS = 3
#: the relative spread below which TRAIN's known values count as one (the clock's and the encoder's rounding)
VARY_RTOL = 1e-9


def run_speeds_m_s(df: pd.DataFrame) -> pd.Series:
    """Each run's mean speed [m/s]: ``|s_last - s_first| / (t_last - t_first)`` in time order, indexed by run id;
    NaN for a run of zero duration."""
    d = df[[dataio.RUN, dataio.TIME, dataio.POSITION]].sort_values([dataio.RUN, dataio.TIME], kind="stable")
    g = d.groupby(dataio.RUN, sort=False)
    ds = g[dataio.POSITION].last() - g[dataio.POSITION].first()
    dt = g[dataio.TIME].last() - g[dataio.TIME].first()
    with np.errstate(invalid="ignore", divide="ignore"):
        return (ds.abs() / dt).where(dt > 0)


def previous_values(runs: pd.DataFrame, speed: dict) -> np.ndarray:
    """Per row of ``runs`` (:func:`~l1b2.closeloop.events.run_table` rows: ``start``, ``frame``, ``run``; any
    order), the speed (``speed[(frame, run)]``) of the row that starts last before it; NaN for the first row."""
    start = runs["start"].to_numpy(float)
    keys = list(zip(runs["frame"].to_numpy(), runs["run"].to_numpy()))
    order = np.argsort(start, kind="stable")
    out = np.full(len(start), np.nan)
    for a, b in zip(order[:-1], order[1:]):
        out[b] = speed.get(keys[a], np.nan)
    return out


def with_previous_pass(train: pd.DataFrame, test: pd.DataFrame | None = None, sess: Session | None = None):
    """``(train, test, record)``: copies of the frames with :data:`COLUMN` appended when TRAIN has at least
    :data:`MIN_KNOWN_RUNS` known values that vary (``test`` None stays None), and ``record`` ``{"column",
    "derived", "one_session", "speed_m_s": {"min", "median", "max"}, "imputed_runs"}`` (module docstring).

    ``sess``: the frames' :func:`~l1b2.closeloop.events.session` when the caller has it (default: computed here).
    The frames are returned unchanged (not copied) when the column is not derived or TRAIN already has it.
    """
    sess = session(train, test) if sess is None else sess
    frames = [df for df in (train, test) if df is not None]
    speed = {}
    for i, df in enumerate(frames):
        speed.update({(i, r): float(v) for r, v in run_speeds_m_s(df).items()})
    runs = sess.runs
    if sess.one:
        prev = previous_values(runs, speed)
        per_frame = [prev[(runs["frame"] == i).to_numpy()] for i in range(len(frames))]
    else:
        per_frame = [previous_values(runs[runs["frame"] == i], speed) for i in range(len(frames))]
    clocks = [runs[runs["frame"] == i] for i in range(len(frames))]
    known = per_frame[0][np.isfinite(per_frame[0])]
    record = {"column": COLUMN, "derived": False, "one_session": bool(sess.one),
              "speed_m_s": ({"min": float(known.min()), "median": float(np.median(known)),
                             "max": float(known.max())} if known.size else {}),
              "imputed_runs": 0}
    if COLUMN in train.columns or known.size < MIN_KNOWN_RUNS or not np.ptp(known) > VARY_RTOL * np.abs(known).max():
        return train, test, record
    fill = float(np.median(known))
    out = []
    for df, clock, p in zip(frames, clocks, per_frame):
        record["imputed_runs"] += int(np.isnan(p).sum())
        value = np.where(np.isnan(p), fill, p)
        df = df.copy()
        df[COLUMN] = df[dataio.RUN].map(dict(zip(clock["run"], value))).to_numpy(float)
        out.append(df)
    record["derived"] = True
    return out[0], (out[1] if test is not None else None), record
