"""Event clocks: the session time since a logged step channel last changed.

A rig's log may carry a channel that is constant within every run and changes only now and then along the session:
a logbook's counter or setting (re-tightenings of a clamp, a payload bolted on, a tool or lubricant changed). An
effect that restarts at such an event (a preload that relaxes after each re-tightening, a run-in after each swap) is
a function of the time elapsed since the event, neither of the channel's value nor of the session clock: in session
time it is a sawtooth, which no form of either can express. For each *step channel* the loop therefore derives its
**event clock**, the logged column ``<column>_since_s`` [s]:

    ``t - t_e(t)``, ``t_e(t)`` the start of the latest run at or before ``t`` whose value differs from the run
    before it (before the first change: the session's first time),

and considers it as one more logged channel (every form, shape and level of
:mod:`l1b2.predictor.effects.channels` and the run-level evidence), beside the channel itself. The derivation reads
only the logged channel and the clock (inputs of the log, never a response), so TRAIN and TEST, when they are one
session (their runs do not overlap in time), are merged to place the events: a change that falls between a TRAIN
run and a TEST run is found in either frame. Frames whose runs overlap in time (two sessions on one clock) are each
derived from their own runs.

A column is a step channel (:func:`step_channels`) when it is a logged candidate channel
(:func:`l1b2.closeloop.candidates.channels_of`, not a response; a coded text label counts), constant within every
run, and its value changes between consecutive runs of the session at least once and at most once per
:data:`MIN_BLOCK_RUNS` runs on average: a channel that changes from almost every run to the next is a run-level
channel, not a log of events, and a block of fewer runs would not show what happens along it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from .candidates import channels_of

#: the fewest runs per block on average (runs / changes) for a step channel
MIN_BLOCK_RUNS = 4
#: the event clock's column suffix
SUFFIX = "_since_s"


def run_table(frames, column: str) -> pd.DataFrame:
    """One row per run of the frames (``start``, ``stop`` [s], ``value`` of ``column``, the run's id ``run`` and
    ``frame``, the position of its frame in ``frames``), in session order."""
    rows = []
    for i, df in enumerate(frames):
        if df is None or column not in df.columns:
            continue
        g = df.groupby(dataio.RUN, sort=False)
        lo = g[dataio.TIME].min()
        rows.append(pd.DataFrame({"start": lo.to_numpy(float), "stop": g[dataio.TIME].max().to_numpy(float),
                                  "value": g[column].first().to_numpy(float), "run": lo.index.to_numpy(),
                                  "frame": i}))
    tab = (pd.concat(rows, ignore_index=True) if rows
           else pd.DataFrame(columns=["start", "stop", "value", "run", "frame"]))
    return tab.sort_values("start", kind="stable").reset_index(drop=True)


def one_session(tab: pd.DataFrame) -> bool:
    """Whether the runs of ``tab`` (:func:`run_table`) follow one another on one clock (no two overlap in time)."""
    return bool(np.all(tab["start"].to_numpy()[1:] > tab["stop"].to_numpy()[:-1]))


class Session(NamedTuple):
    """The runs of TRAIN and TEST on the clock (:func:`run_table` of the time column) and whether they are one
    session (:func:`one_session`): what the event clocks and the lagged channels both read (:func:`session`)."""

    runs: pd.DataFrame
    one: bool


def session(train: pd.DataFrame, test: pd.DataFrame | None = None) -> Session:
    """The :class:`Session` of every run of both frames (``test`` may be None), logged channel or not."""
    clock = run_table([train, test], dataio.TIME)
    return Session(clock, one_session(clock))


def frame_run_values(sess: Session, n_frames: int, of) -> list:
    """Per frame ``i < n_frames``, the value ``of(runs)`` gives each of its runs (``runs``: :func:`run_table` rows,
    ``of`` returning one value per row in their order), in the order of the frame's rows of ``sess.runs``: read over
    the merged session's runs when the frames are one session (a run's neighbour may be the other frame's), else over
    each frame's own runs."""
    if sess.one:
        v = np.asarray(of(sess.runs))
        return [v[(sess.runs["frame"] == i).to_numpy()] for i in range(n_frames)]
    return [np.asarray(of(sess.runs[sess.runs["frame"] == i])) for i in range(n_frames)]


def with_run_column(df: pd.DataFrame, clock: pd.DataFrame, values, column: str) -> pd.DataFrame:
    """A copy of ``df`` with ``column``: each sample its run's value (``values`` per row of ``clock``, the frame's
    :func:`run_table` rows)."""
    out = df.copy()
    out[column] = out[dataio.RUN].map(dict(zip(clock["run"], values))).to_numpy(float)
    return out


def event_times(tab: pd.DataFrame) -> np.ndarray:
    """The start times [s] of the runs whose value differs from the run before (``tab`` in session order)."""
    v = tab["value"].to_numpy(float)
    return tab["start"].to_numpy(float)[1:][v[1:] != v[:-1]]


def since_event(t, events, t0: float) -> np.ndarray:
    """``t - t_e`` per sample: ``t_e`` the latest event at or before ``t`` (``events`` sorted), else ``t0`` [s]."""
    t = np.asarray(t, float)
    ev = np.concatenate([[t0], np.asarray(events, float)])
    return t - ev[np.searchsorted(ev, t, side="right") - 1]


def is_step(tab: pd.DataFrame, within_run: bool) -> bool:
    """The step-channel rule on one channel's run table (session order): constant within runs, changes at least
    once and at most once per :data:`MIN_BLOCK_RUNS` runs."""
    n_changes = len(event_times(tab))
    return (not within_run) and 1 <= n_changes <= len(tab) / MIN_BLOCK_RUNS


def step_channels(df: pd.DataFrame, response_columns=None) -> list[str]:
    """The step channels of a TRAIN frame (module docstring), in column order."""
    out = []
    for ch in channels_of(df, response_columns):
        if ch["kind"] not in ("logged", "label") or ch["name"] + SUFFIX in df.columns:
            continue
        if is_step(run_table([df], ch["name"]), ch["within_run"]):
            out.append(ch["name"])
    return out


def with_event_clocks(train: pd.DataFrame, test: pd.DataFrame | None = None, response_columns=None,
                      sess: Session | None = None):
    """``(train, test, record)``: copies of the frames with the event clock of every step channel of ``train``
    appended (``test`` None stays None), and ``record`` ``[{"channel", "clock", "events_s"}]``.

    ``sess``: the frames' :func:`session` when the caller has it (default: computed here). The frames are returned
    unchanged (not copied) when TRAIN has no step channel.
    """
    names = step_channels(train, response_columns)
    if not names:
        return train, test, []
    train, test = train.copy(), (test.copy() if test is not None else None)
    record = []
    merged = (session(train, test) if sess is None else sess).one   # every run of both frames, logged or not
    for name in names:
        tab = run_table([train, test], name)
        for df in (train, test):
            if df is None or (not merged and name not in df.columns):
                continue   # a frame of its own session without the channel has no events to place
            own = tab if merged else run_table([df], name)
            t = df[dataio.TIME].to_numpy(float)
            df[name + SUFFIX] = since_event(t, event_times(own), float(own["start"].min()))
        record.append({"channel": name, "clock": name + SUFFIX, "one_session": merged,
                       "events_s": [float(x) for x in event_times(tab if merged else run_table([train], name))]})
    return train, test, record
