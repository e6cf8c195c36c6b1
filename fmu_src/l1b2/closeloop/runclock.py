"""The run's own clock and travel: the time since each run's first sample and the way the slider has gone since,
as channels offered along the stroke only.

A drive or supply state that evolves after the drive starts (a bench supply in current limit whose bus sags as
the bridge draws, a driver's soft start, a warm-up of the bridge) is a function of the time since the run began,
not of the session clock and not of the position: within one direction the distance from the start end is the
run's clock only at one speed, and runs at several speeds reach the same distance at different times. For every
session the loop therefore derives the logged column :data:`COLUMN`:

    ``t - t_0(run)`` [s], ``t_0(run)`` the run's earliest ``time_s`` (its first sample),

and considers it as one more candidate channel of kind ``"run_clock"``
(:data:`l1b2.predictor.effects.channels.SAMPLE_ONLY_KINDS`): every form and shape of
:mod:`l1b2.predictor.effects.channels` (its ``force_factor`` form is the effect that grows with V0), at the
``sample`` level only (:func:`l1b2.predictor.effects.channels.levels_of`), with no run-level signal
(:func:`l1b2.closeloop.runlevel.run_signals`) and no run-level hypothesis. The rule is general: a run's mean of its
own clock is half the run's duration, which the motor's speed over the stroke sets, so a run-level form of it would
read a response of the motor as a cause. The derivation reads only the clock and the run ids, each run on its own
(no session order, no imputation), and is the same for TRAIN and TEST.

The column is derived when some TRAIN run lasts longer than zero (a run of one sample has no clock). ``Predictor.fmu``
reads it like any logged channel's, an input named after it: the host computes it from its own clock as defined
above (the time since the run's drive started).

Its twin in space: a state that the slider meets at a place of its way (an end stop's cushion or damper, a cable
that pays out, a seal or a magnet it passes) acts at a distance from where the run began, which runs at several
speeds reach at different times. The loop derives :data:`TRAVEL_COLUMN` too:

    ``d (s - s_0(run))`` [m], ``d`` the run's direction and ``s_0(run)`` the position at its earliest ``time_s``,

the way the slider has gone in its own direction since the run's first sample, and considers it as a candidate
channel of kind ``"run_travel"`` (also of :data:`~l1b2.predictor.effects.channels.SAMPLE_ONLY_KINDS`: a run's mean
of it is half the run's travel, set by the stroke and by how far the motor got, not a cause between runs). The
loop's forms of the position are forces or stiffness-like profiles of ``s``; the channel's forms add what they lack,
such as a drag in proportion to the speed over part of the way (its ``damping`` form) or a share of the drive's
force (``force_factor``). It is derived when some TRAIN run's positions span more than zero; ``Predictor.fmu``
reads it as an input named after it, which the host computes from its own position reading and the run's start.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..predictor.effects.channels import RUN_CLOCK, RUN_TRAVEL

#: the derived column: the time since the run's first sample [s]
COLUMN = RUN_CLOCK
#: the derived column: the way gone in the run's direction since its first sample [m]
TRAVEL_COLUMN = RUN_TRAVEL


def time_in_run_s(df: pd.DataFrame) -> np.ndarray:
    """Each sample's time since its run's first sample [s]: ``time_s`` minus the run's smallest ``time_s``."""
    t = df[dataio.TIME].to_numpy(float)
    return t - df.groupby(dataio.RUN, sort=False)[dataio.TIME].transform("min").to_numpy(float)


def with_run_clock(train: pd.DataFrame, test: pd.DataFrame | None = None):
    """``(train, test, record)``: copies of the frames with :data:`COLUMN` appended when some TRAIN run lasts
    longer than zero (``test`` None stays None), and ``record`` ``{"column", "derived", "duration_s": {"min",
    "median", "max"}}`` (TRAIN's run durations; module docstring).

    The frames are returned unchanged (not copied) when the column is not derived or TRAIN already has it.
    """
    dur = train.groupby(dataio.RUN, sort=False)[dataio.TIME].agg(np.ptp).to_numpy(float)
    return _appended(train, test, COLUMN, time_in_run_s, dur, "duration_s")


def travel_in_run_m(df: pd.DataFrame) -> np.ndarray:
    """Each sample's way gone in its run's direction since the run's first sample [m]: ``d (s - s_0)``, ``s_0`` the
    position at the run's smallest ``time_s``."""
    first = df.loc[df.groupby(dataio.RUN, sort=False)[dataio.TIME].idxmin(), [dataio.RUN, dataio.POSITION]]
    s0 = df[dataio.RUN].map(dict(zip(first[dataio.RUN], first[dataio.POSITION]))).to_numpy(float)
    return df[dataio.DIRECTION].to_numpy(float) * (df[dataio.POSITION].to_numpy(float) - s0)


def with_run_travel(train: pd.DataFrame, test: pd.DataFrame | None = None):
    """``(train, test, record)``: copies of the frames with :data:`TRAVEL_COLUMN` appended when some TRAIN run's
    positions span more than zero (``test`` None stays None), and ``record`` ``{"column", "derived", "span_m":
    {"min", "median", "max"}}`` (TRAIN's runs' spans of the position; module docstring).

    The frames are returned unchanged (not copied) when the column is not derived or TRAIN already has it.
    """
    span = train.groupby(dataio.RUN, sort=False)[dataio.POSITION].agg(np.ptp).to_numpy(float)
    return _appended(train, test, TRAVEL_COLUMN, travel_in_run_m, span, "span_m")


def _appended(train: pd.DataFrame, test: pd.DataFrame | None, column: str, derive, extent: np.ndarray, key: str):
    """``(train, test, record)`` of :func:`with_run_clock` and :func:`with_run_travel`: ``column`` = ``derive(df)``
    appended to copies of the frames when some TRAIN run's ``extent`` (one value per run) is above zero and TRAIN
    lacks the column; ``record[key]`` the extents' min, median and max (``{}`` without runs)."""
    record = {"column": column, "derived": False,
              key: ({"min": float(extent.min()), "median": float(np.median(extent)), "max": float(extent.max())}
                    if extent.size else {})}
    if column in train.columns or not (extent.size and extent.max() > 0):
        return train, test, record
    out = []
    for df in (train, test):
        if df is not None:
            df = df.copy()
            df[column] = derive(df)
        out.append(df)
    record["derived"] = True
    return out[0], out[1], record
