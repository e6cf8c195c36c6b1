"""The previous run's load, read from the log, as a channel.

A run can meet a state that the run before it left on the motor: a weight still hanging from the run before (a
protocol that swaps the weight late), a cord or pulley that the previous load stretched or warmed, a film that the
previous pass entrained at the speed its load set. Such a state follows the previous run's setting, not the current
run's, so no input of the current run carries it. For every session the loop therefore derives the logged column
:data:`LOAD_COLUMN`, constant within each run: the ``load_kg`` of the run that ended last before the run started. It
is one more logged channel (every form and shape of :mod:`l1b2.predictor.effects.channels` at the run level, and the
run-level evidence: one family). It is known when the run starts (``Predictor.fmu`` reads it like any logged
channel's, an input named after it).

The column is a setting of the plan, never a measured response. A previous run's *measured* speed would carry, besides
what that run did, every slow drift of the session (the previous run's deviation from the model is the current
run's, one run earlier), and it would stand in for the session clock; a backward run's forward twin would carry the
run's own condition's response. The drive amplitude's history is the voltage's lags and step
(:mod:`~l1b2.closeloop.lags`).

The session's first run has no previous run; it gets TRAIN's median of the known values, the rig's typical value,
which puts the run at the channel's centre and gives it no leverage. TRAIN and TEST are merged in time order when
they are one session (:func:`l1b2.closeloop.events.one_session`), so a TEST run reads a TRAIN run before it;
otherwise each frame's runs are ordered on their own. The column is derived when TRAIN has at least
:data:`MIN_KNOWN_RUNS` known values and they vary (their range above :data:`VARY_RTOL` times the largest).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from .events import Session, frame_run_values, session, with_run_column

#: the previous run's load column [kg]
LOAD_COLUMN = "prev_run_load_kg"
#: the fewest TRAIN runs with a known value for a column to be derived
MIN_KNOWN_RUNS = 3
#: the relative spread below which TRAIN's known values count as one (the clock's and the encoder's rounding)
VARY_RTOL = 1e-9


def previous_values(runs: pd.DataFrame, value: dict) -> np.ndarray:
    """Per row of ``runs`` (:func:`~l1b2.closeloop.events.run_table` rows: ``start``, ``frame``, ``run``; any
    order), ``value[(frame, run)]`` of the row that starts last before it; NaN for the first row."""
    start = runs["start"].to_numpy(float)
    keys = list(zip(runs["frame"].to_numpy(), runs["run"].to_numpy()))
    order = np.argsort(start, kind="stable")
    out = np.full(len(start), np.nan)
    for a, b in zip(order[:-1], order[1:]):
        out[b] = value.get(keys[a], np.nan)
    return out


def with_previous_pass(train: pd.DataFrame, test: pd.DataFrame | None = None, sess: Session | None = None):
    """``(train, test, record)``: copies of the frames with :data:`LOAD_COLUMN` appended when TRAIN has at least
    :data:`MIN_KNOWN_RUNS` known values that vary (``test`` None stays None), and ``record`` ``{"column",
    "derived", "one_session", "range": {"min", "median", "max"}, "imputed_runs"}`` (module docstring).

    ``sess``: the frames' :func:`~l1b2.closeloop.events.session` when the caller has it (default: computed here).
    The frames are returned unchanged (not copied) when the column is not derived or TRAIN already has it.
    """
    sess = session(train, test) if sess is None else sess
    frames = [df for df in (train, test) if df is not None]
    load = {}
    for i, df in enumerate(frames):
        load.update({(i, r): float(v) for r, v in df.groupby(dataio.RUN, sort=False)[dataio.LOAD].first().items()})
    clocks = [sess.runs[sess.runs["frame"] == i] for i in range(len(frames))]
    per_frame = frame_run_values(sess, len(frames), lambda runs: previous_values(runs, load))
    known = per_frame[0][np.isfinite(per_frame[0])]
    record = {"column": LOAD_COLUMN, "derived": False, "one_session": bool(sess.one),
              "range": ({"min": float(known.min()), "median": float(np.median(known)),
                         "max": float(known.max())} if known.size else {}), "imputed_runs": 0}
    if (LOAD_COLUMN in train.columns or known.size < MIN_KNOWN_RUNS
            or not np.ptp(known) > VARY_RTOL * np.abs(known).max()):
        return train, test, record
    fill = float(np.median(known))
    out = []
    for df, clock, p in zip(frames, clocks, per_frame):
        record["imputed_runs"] += int(np.isnan(p).sum())
        out.append(with_run_column(df, clock, np.where(np.isnan(p), fill, p), LOAD_COLUMN))
    record["derived"] = True
    return out[0], (out[1] if test is not None else None), record
