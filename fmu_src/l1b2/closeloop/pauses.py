"""The pause before each run: the recording protocol's idle time, read from the session clock, as a channel.

Contacts that rest under load age: a static contact's friction grows with the logarithm of its contact time (the
ageing of rate-and-state friction, ``mu_s(t) = mu_0 + b ln(1 + t / theta)``), a lubricant film drains from a
loaded line contact, a piezo stack relaxes. A motor's stroke after a long pause then differs from one after a
short pause, by an amount that follows the pause's logarithm, a state that changes between runs only and that
only the gaps of ``time_s`` carry. For a session whose pauses vary the loop therefore derives the logged column
:data:`COLUMN` (constant within each run):

    ``ln(max(p, dt) / t_ref)``, ``p`` the pause before the run [s] (its first ``time_s`` minus the previous run's
    last, in session order), ``dt`` the clock's sample interval (TRAIN's median step within runs: a pause the clock
    cannot tell from none), ``t_ref`` = :data:`REFERENCE_S`,

and considers it as one more logged channel (every form, shape and level of
:mod:`l1b2.predictor.effects.channels` and the run-level evidence: one family). The channel is the pause's
logarithm, the ageing law's own variable; the generic shapes act on it (the linear shape is the log law, the
quadratic and odd shapes its curvature, e.g. the cut-off ``theta`` of ``ln(1 + t / theta)``). The standardisation of
:mod:`~l1b2.predictor.effects.channels` removes ``t_ref``, which only names the unit.

The first run of a session has no previous run, so its pause is unknown (the time at rest before the session is
not in the log). It gets TRAIN's median of the known values of the column: the rig's typical pause, which puts
the run at the channel's centre, so it gives no leverage to any form. The derivation reads only the clock and the
run order (never a response). TRAIN and TEST are merged in time order when they are one session
(:func:`l1b2.closeloop.events.one_session`), so TEST's first run has the pause after the run before it, whichever
frame holds that run; otherwise each frame's runs are ordered on their own and each frame's first run is imputed.

The column is derived only when TRAIN's known pauses vary (:func:`pauses_vary`): the longest at least
:data:`MIN_SPAN` times the shortest. A rig that pauses regularly (a plan's fixed pause, a timer's jitter) gives
a column with no information, and it would add one family to the significance correction for nothing.

``Predictor.fmu`` reads the column like any logged channel's (an input named after it): the host computes it
from its own clock as defined above.

**Breaks.** A session may stop for a while (a meal, a night, a re-mount of the weight): the motor cools, a film
drains, and the state the runs had built up starts again. An effect that builds up over the runs after each break
(a warm-up) is a function of the time since the latest break, a sawtooth in session time that no form of the
session clock can express. A pause is a *break* when it lasts at least :data:`BREAK_FACTOR` times the session's
median run period (start to start). For a session with breaks (at least one, at most one per
:data:`l1b2.closeloop.events.MIN_BLOCK_RUNS` runs on average, some TRAIN run after one) the loop derives the logged
column :data:`BREAK_COLUMN` per sample:

    ``t - t_b(t)`` [s], ``t_b(t)`` the start of the latest run at or before ``t`` that follows a break (before the
    first break: the session's first time),

one more logged channel (every form, shape and level), and the logged column :data:`BREAK_COUNT_COLUMN` per sample:

    the number of breaks at or before ``t`` (of the runs that follow a break, those starting at or before ``t``),

a step at every break, constant within each run (so read at the run level). A change of the rig or its use at a
break (a repair, a re-mount, another operator's weights or tools) is a step of the session that a smooth form of
the clock cannot take and the time since the break does not carry; the count carries it, and its run-level
evidence is read as any logged channel's. TRAIN and TEST are merged as for the pause; frames of their own sessions
are each read on their own. The host computes both from its own clock and run log.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..units import LOG_PREFIX
from .events import MIN_BLOCK_RUNS, Session, frame_run_values, session, since_event, with_run_column

#: the derived column: the logarithm of the pause before each run over :data:`REFERENCE_S`, named by the naming rule
#: of a logarithm (:data:`l1b2.units.LOG_PREFIX`): ``ln(pause_s / 1 s)``, dimensionless (:func:`l1b2.units.column_unit`)
COLUMN = LOG_PREFIX + "pause_s"
#: the reference time [s] of the logarithm: 1 s, the unit the column's name states (the standardised channel does
#: not depend on it)
REFERENCE_S = 1.0
#: the smallest ratio of TRAIN's longest to its shortest known pause for the column to be derived: a doubling of
#: the rest, a third of a decade of the log law (a span below it carries the log law's effect over less than that)
MIN_SPAN = 2.0
#: the break clock's column: the time since the latest run that follows a break [s]
BREAK_COLUMN = "since_break_s"
#: a pause is a break when it lasts at least this many median run periods (start to start)
BREAK_FACTOR = 10.0
#: the break count's column: the number of breaks at or before each sample (a step at every break)
BREAK_COUNT_COLUMN = "breaks_before"


def pauses_s(clock: pd.DataFrame) -> np.ndarray:
    """The pause before each run of ``clock`` (:func:`~l1b2.closeloop.events.run_table` rows, any order) [s], in the
    rows' order: its start minus the stop of the run that starts last before it; NaN for the first run."""
    start, stop = clock["start"].to_numpy(float), clock["stop"].to_numpy(float)
    order = np.argsort(start, kind="stable")
    p = np.full(len(start), np.nan)
    p[order[1:]] = start[order[1:]] - stop[order[:-1]]
    return p


def sample_interval_s(df: pd.DataFrame) -> float:
    """The clock's sample interval [s]: the median positive step of ``time_s`` within runs (0 when none)."""
    dt = df.groupby(dataio.RUN, sort=False)[dataio.TIME].diff().to_numpy(float)
    dt = dt[np.isfinite(dt) & (dt > 0)]
    return float(np.median(dt)) if dt.size else 0.0


def log_pause(pause_s, floor_s: float) -> np.ndarray:
    """``ln(max(p, floor) / REFERENCE_S)`` per pause ``p`` [s] (NaN stays NaN): finite for a zero pause when
    ``floor_s`` > 0."""
    p = np.asarray(pause_s, float)
    with np.errstate(invalid="ignore"):
        return np.log(np.where(np.isnan(p), np.nan, np.maximum(p, floor_s)) / REFERENCE_S)


def pauses_vary(pause_s) -> bool:
    """Whether the known pauses (finite) vary: at least two, the longest at least :data:`MIN_SPAN` times the
    shortest (a shortest of zero: any longer one)."""
    p = np.asarray(pause_s, float)
    p = p[np.isfinite(p)]
    return bool(p.size >= 2 and p.max() > 0 and p.max() >= MIN_SPAN * max(p.min(), 0.0))


def with_pause_channel(train: pd.DataFrame, test: pd.DataFrame | None = None, sess: Session | None = None):
    """``(train, test, record)``: copies of the frames with :data:`COLUMN` appended when TRAIN's pauses vary
    (``test`` None stays None), and ``record`` ``{"column", "derived", "one_session", "floor_s", "reference_s",
    "pauses_s": {"min", "median", "max"}, "imputed_runs"}`` (module docstring).

    ``sess``: the frames' :func:`~l1b2.closeloop.events.session` when the caller has it (default: computed here).
    The frames are returned unchanged (not copied) when the column is not derived or TRAIN already has it.
    """
    sess = session(train, test) if sess is None else sess
    merged = sess.one
    frames = [df for df in (train, test) if df is not None]
    clocks = [sess.runs[sess.runs["frame"] == i] for i in range(len(frames))]   # each frame's runs on the clock
    per_frame = frame_run_values(sess, len(frames), pauses_s)
    known = per_frame[0][np.isfinite(per_frame[0])]
    record = {"column": COLUMN, "derived": False, "one_session": bool(merged), "floor_s": 0.0,
              "reference_s": REFERENCE_S, "pauses_s": ({"min": float(known.min()), "median": float(np.median(known)),
                                                        "max": float(known.max())} if known.size else {}),
              "imputed_runs": 0}
    if COLUMN in train.columns or not pauses_vary(per_frame[0]):
        return train, test, record
    floor = sample_interval_s(train)
    fill = float(np.median(log_pause(known, floor)))
    out = []
    for df, clock, p in zip(frames, clocks, per_frame):
        value = log_pause(p, floor)
        record["imputed_runs"] += int(np.isnan(value).sum())
        out.append(with_run_column(df, clock, np.where(np.isnan(value), fill, value), COLUMN))
    record.update(derived=True, floor_s=floor)
    return out[0], (out[1] if test is not None else None), record


def break_starts(clock: pd.DataFrame) -> np.ndarray:
    """The start times [s] of the runs of ``clock`` (:func:`~l1b2.closeloop.events.run_table` rows, any order) whose
    pause before (:func:`pauses_s`) is a break: at least :data:`BREAK_FACTOR` times the median run period (start to
    start), sorted. Empty for fewer than three runs."""
    start = np.sort(clock["start"].to_numpy(float))
    if len(start) < 3:
        return np.empty(0)
    period = float(np.median(np.diff(start)))
    p = pauses_s(clock)
    starts = clock["start"].to_numpy(float)[np.isfinite(p) & (p >= BREAK_FACTOR * period)]
    return np.sort(starts)


def with_break_clock(train: pd.DataFrame, test: pd.DataFrame | None = None, sess: Session | None = None):
    """``(train, test, record)``: copies of the frames with :data:`BREAK_COLUMN` and :data:`BREAK_COUNT_COLUMN`
    appended when the session has breaks (module docstring; ``test`` None stays None), and ``record``
    ``{"column", "count_column", "derived", "one_session", "breaks_s"}`` (the start times of the runs after a break:
    the merged session's, else TRAIN's).

    ``sess``: the frames' :func:`~l1b2.closeloop.events.session` when the caller has it (default: computed here).
    The frames are returned unchanged (not copied) when the column is not derived or TRAIN already has it.
    """
    sess = session(train, test) if sess is None else sess
    frames = [df for df in (train, test) if df is not None]
    clocks = [sess.runs[sess.runs["frame"] == i] for i in range(len(frames))]
    own = [sess.runs] * len(frames) if sess.one else clocks     # the runs each frame's breaks are read from
    breaks = [break_starts(c) for c in own]
    tr_start = clocks[0]["start"].to_numpy(float)
    n_runs = len(own[0])
    record = {"column": BREAK_COLUMN, "count_column": BREAK_COUNT_COLUMN, "derived": False,
              "one_session": bool(sess.one), "breaks_s": [float(x) for x in breaks[0]]}
    b0 = breaks[0]
    usable = 1 <= len(b0) <= n_runs / MIN_BLOCK_RUNS and bool(np.any(tr_start >= b0[0]))
    if BREAK_COLUMN in train.columns or BREAK_COUNT_COLUMN in train.columns or not usable:
        return train, test, record
    out = []
    for df, c, b in zip(frames, own, breaks):
        df = df.copy()
        t = df[dataio.TIME].to_numpy(float)
        df[BREAK_COLUMN] = since_event(t, b, float(c["start"].min()))
        df[BREAK_COUNT_COLUMN] = np.searchsorted(b, t, side="right").astype(float)
        out.append(df)
    record["derived"] = True
    return out[0], (out[1] if test is not None else None), record
