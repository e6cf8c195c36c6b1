"""The previous run: the speed of the last pass at another setting, and the previous run's load, as channels.

A run can meet a state that the runs before it left on the motor: the bar's oil film that the last pass entrained
(its thickness follows the speed of that pass), the wear debris or transfer layer it smeared, the heat its friction
dissipated in the contact, a weight still hanging from the run before. Such a state is set by what the previous runs
*did*, not by the current run's settings, so neither the current run's inputs nor a low-pass of the drive
amplitude (:mod:`~l1b2.closeloop.lags`) carries it. For every session the loop therefore derives two logged columns,
constant within each run:

* :data:`COLUMN`, the **previous pass**: the mean speed [m/s] (``|s_last - s_first| / (t_last - t_first)`` of
  ``position_m`` and ``time_s``, its stroke over its duration) of the run that ended last before the run started
  *among the runs at another setting* (V0 or load differs from the run's). A run at the run's own setting (a
  backward run's forward twin) is skipped: its speed is largely the run's own condition's response, so it would
  stand in for the run's own speed and explain whatever the model misses at that condition;
* :data:`LOAD_COLUMN`, the **previous run's load** [kg]: the ``load_kg`` of the run that ended last before the run
  started (any setting: a setting of the plan carries no response).

Each is one more logged channel (every form and shape of :mod:`l1b2.predictor.effects.channels` at the run level,
and the run-level evidence: one family each). Both are known when the run starts: a host that predicts a run knows
them (``Predictor.fmu`` reads each like any logged channel's, an input named after it).

A run with no such earlier run (the session's first, or the runs of the session's first setting for the pass) gets
TRAIN's median of the known values, the rig's typical value, which puts the run at the channel's centre and gives
it no leverage; so does a run whose pass had zero duration. TRAIN and TEST are merged in time order when they are
one session (:func:`l1b2.closeloop.events.one_session`), so a TEST run reads a TRAIN run before it; otherwise each
frame's runs are ordered on their own.

A column is derived when TRAIN has at least :data:`MIN_KNOWN_RUNS` known values and they vary (their range above
:data:`VARY_RTOL` times the largest).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from .events import Session, session

#: the previous pass's column: the mean speed [m/s] of the last run at another setting (the name gives the unit)
COLUMN = "prev_run_speed_m_s"
#: the previous run's load column [kg]
LOAD_COLUMN = "prev_run_load_kg"
#: the fewest TRAIN runs with a known value for a column to be derived
MIN_KNOWN_RUNS = 3
#: two runs are at one setting when their V0 differ by at most this share (a logged amplitude's scatter) and their
#: loads by at most :data:`SAME_LOAD_KG`
SAME_VOLTAGE_REL = 0.01
SAME_LOAD_KG = 1e-6
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


def run_settings(df: pd.DataFrame) -> pd.DataFrame:
    """Each run's setting, indexed by run id: ``voltage_V`` (its median) and ``load_kg`` (its first value)."""
    g = df.groupby(dataio.RUN, sort=False)
    return pd.DataFrame({dataio.VOLTAGE: g[dataio.VOLTAGE].median(), dataio.LOAD: g[dataio.LOAD].first()})


def same_setting(a, b) -> bool:
    """Whether two runs' settings ``(V0 [V], load [kg])`` are one: V0 within :data:`SAME_VOLTAGE_REL` of the larger
    and the loads within :data:`SAME_LOAD_KG`."""
    return bool(abs(a[0] - b[0]) <= SAME_VOLTAGE_REL * max(abs(a[0]), abs(b[0])) and abs(a[1] - b[1]) <= SAME_LOAD_KG)


def previous_values(runs: pd.DataFrame, value: dict, setting: dict | None = None) -> np.ndarray:
    """Per row of ``runs`` (:func:`~l1b2.closeloop.events.run_table` rows: ``start``, ``frame``, ``run``; any
    order), ``value[(frame, run)]`` of the row that starts last before it; with ``setting`` (``(frame, run)`` ->
    ``(V0, load)``), of the last such row at another setting (:func:`same_setting`). NaN when there is none."""
    start = runs["start"].to_numpy(float)
    keys = list(zip(runs["frame"].to_numpy(), runs["run"].to_numpy()))
    out = np.full(len(start), np.nan)
    seen: list = []     # earlier rows in start order
    for b in np.argsort(start, kind="stable"):
        for a in reversed(seen):
            if setting is None or not same_setting(setting[keys[a]], setting[keys[b]]):
                out[b] = value.get(keys[a], np.nan)
                break
        seen.append(b)
    return out


def _append(frames, clocks, per_frame, column: str, record: dict):
    """The frames with ``column`` appended from each frame's run values ``per_frame`` (NaN: TRAIN's median of its
    known values); ``record`` gains ``imputed_runs`` and ``derived``. Unchanged frames when TRAIN has fewer than
    :data:`MIN_KNOWN_RUNS` known values or they do not vary."""
    known = per_frame[0][np.isfinite(per_frame[0])]
    record.update({"range": ({"min": float(known.min()), "median": float(np.median(known)),
                              "max": float(known.max())} if known.size else {}), "imputed_runs": 0})
    if (column in frames[0].columns or known.size < MIN_KNOWN_RUNS
            or not np.ptp(known) > VARY_RTOL * np.abs(known).max()):
        return frames
    fill = float(np.median(known))
    out = []
    for df, clock, p in zip(frames, clocks, per_frame):
        record["imputed_runs"] += int(np.isnan(p).sum())
        df = df.copy()
        df[column] = df[dataio.RUN].map(dict(zip(clock["run"], np.where(np.isnan(p), fill, p)))).to_numpy(float)
        out.append(df)
    record["derived"] = True
    return out


def with_previous_pass(train: pd.DataFrame, test: pd.DataFrame | None = None, sess: Session | None = None):
    """``(train, test, record)``: copies of the frames with :data:`COLUMN` and :data:`LOAD_COLUMN` appended, each
    when TRAIN has at least :data:`MIN_KNOWN_RUNS` known values that vary (``test`` None stays None), and
    ``record`` ``{"one_session", "columns": [{"column", "derived", "range": {"min", "median", "max"},
    "imputed_runs"}, ...]}`` (module docstring).

    ``sess``: the frames' :func:`~l1b2.closeloop.events.session` when the caller has it (default: computed here).
    The frames are returned unchanged (not copied) when no column is derived; a column TRAIN already has is not.
    """
    sess = session(train, test) if sess is None else sess
    frames = [df for df in (train, test) if df is not None]
    speed, load, setting = {}, {}, {}
    for i, df in enumerate(frames):
        speed.update({(i, r): float(v) for r, v in run_speeds_m_s(df).items()})
        st = run_settings(df)
        load.update({(i, r): float(v) for r, v in st[dataio.LOAD].items()})
        setting.update({(i, r): (float(v), float(m)) for r, v, m in zip(st.index, st[dataio.VOLTAGE], st[dataio.LOAD])})
    runs = sess.runs
    clocks = [runs[runs["frame"] == i] for i in range(len(frames))]
    record = {"one_session": bool(sess.one), "columns": []}
    for column, value, same in ((COLUMN, speed, setting), (LOAD_COLUMN, load, None)):
        if sess.one:
            prev = previous_values(runs, value, same)
            per_frame = [prev[(runs["frame"] == i).to_numpy()] for i in range(len(frames))]
        else:
            per_frame = [previous_values(c, value, same) for c in clocks]
        rec = {"column": column, "derived": False}
        frames = _append(frames, clocks, per_frame, column, rec)
        record["columns"].append(rec)
    return frames[0], (frames[1] if test is not None else None), record
