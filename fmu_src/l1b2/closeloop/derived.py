"""The names of the channels the close loop derives from the log, kept free of logged columns.

The loop derives channels from what every log carries (:mod:`~l1b2.closeloop.events`: the event clock
``<column>_since_s`` of a step channel; :mod:`~l1b2.closeloop.lags`: the lags ``<column>_lag<n>r`` of a run
setting; :mod:`~l1b2.closeloop.pauses`: the pause before each run, ``ln_pause_s``, the time since the latest
break, ``since_break_s``, and the count of breaks before, ``breaks_before``; :mod:`~l1b2.closeloop.history`: the
previous run's load, ``prev_run_load_kg``;
:mod:`~l1b2.closeloop.runclock`: the time since each run's first sample, ``time_in_run_s``, and the way gone since,
``travel_in_run_m``;
:mod:`~l1b2.closeloop.logscale`: the logarithm ``ln_<column>`` of a logged channel that spans decades;
:mod:`~l1b2.closeloop.runsetting`: the run's setting ``<column>_setting`` that a response column or a column read
along the stroke carries;
:func:`with_protocol_channels` derives them all). A rig's own column may carry
one of those names by chance (a logger that writes its own ``ln_pause_s``, an export that already holds a
``voltage_V_lag3r``). Taken as the derived channel, such a column would replace the derivation (or be
overwritten by it): either way something is lost without a word. So, before anything reads the frames, a logged
column whose name a derivation could produce is **renamed** ``<name>_logged`` (``_logged2``, ... when that is
taken too) in both frames and kept as an auxiliary column of its own; the rename is recorded with the other
auxiliary columns' actions (:func:`l1b2.closeloop.auxiliary.with_usable_channels`), so the report lists it.

A name a derivation *could* produce: exactly :data:`l1b2.closeloop.pauses.COLUMN`,
:data:`l1b2.closeloop.pauses.BREAK_COLUMN`, :data:`l1b2.closeloop.pauses.BREAK_COUNT_COLUMN`,
:data:`l1b2.closeloop.runclock.COLUMN`, :data:`l1b2.closeloop.runclock.TRAVEL_COLUMN` or
:data:`l1b2.closeloop.history.LOAD_COLUMN`, or ``X + suffix`` for a column ``X`` of the frame and a suffix of the
event clock, of a lag of :data:`l1b2.closeloop.lags.TAU_RUNS` periods, of a setting's step (``_step``) or of a
run setting (``_setting``, :mod:`~l1b2.closeloop.runsetting`), or
``LOG_PREFIX + X`` (:data:`l1b2.units.LOG_PREFIX`) for a column ``X`` of the frame. The required columns and the
speed are never renamed.
"""

from __future__ import annotations

import pandas as pd

from .auxiliary import DERIVED_ATTR, NOT_CANDIDATES, derived_columns, with_usable_channels
from .candidates import channel_kinds, is_along_stroke
from .events import SUFFIX as EVENT_SUFFIX, Session, with_event_clocks
from ..units import LOG_PREFIX, SETTING_SUFFIX, STEP_SUFFIX, lag_suffix
from .history import LOAD_COLUMN as PREVIOUS_LOAD_COLUMN, with_previous_pass
from .lags import TAU_RUNS, with_lagged_channels
from .logscale import with_log_channels
from .pauses import BREAK_COLUMN, BREAK_COUNT_COLUMN, COLUMN as PAUSE_COLUMN, with_break_clock, with_pause_channel
from .runclock import COLUMN as RUN_CLOCK_COLUMN, TRAVEL_COLUMN, with_run_clock, with_run_travel
from .responses import MODEL_INPUTS
from .runsetting import with_run_settings

__all__ = ["RENAMED_SUFFIX", "derived_suffixes", "is_derivable_name", "set_aside_derivable_names",
           "prepare_channels", "with_protocol_channels"]

#: what a logged column whose name a derivation could produce is renamed with (module docstring)
RENAMED_SUFFIX = "_logged"


def derived_suffixes() -> tuple[str, ...]:
    """The suffixes the loop's derivations append to a column's name: the event clock's, each lag's, the step's, the
    run setting's."""
    return (EVENT_SUFFIX,) + tuple(lag_suffix(n) for n in TAU_RUNS) + (STEP_SUFFIX, SETTING_SUFFIX)


def is_derivable_name(name: str, columns) -> bool:
    """Whether a derivation of the loop could produce a channel called ``name`` from a frame with ``columns``
    (module docstring)."""
    if name in (PAUSE_COLUMN, BREAK_COLUMN, BREAK_COUNT_COLUMN, RUN_CLOCK_COLUMN, TRAVEL_COLUMN, PREVIOUS_LOAD_COLUMN):
        return True
    cols = set(columns)
    if name.startswith(LOG_PREFIX) and name[len(LOG_PREFIX):] in cols:
        return True
    return any(name.endswith(s) and name[:-len(s)] in cols for s in derived_suffixes())


def _free_name(name: str, taken: set) -> str:
    """``name + "_logged"``, or ``name + "_logged<k>"`` for the smallest k >= 2 that no column of ``taken`` has."""
    new, k = name + RENAMED_SUFFIX, 2
    while new in taken:
        new, k = f"{name}{RENAMED_SUFFIX}{k}", k + 1
    return new


def set_aside_derivable_names(train: pd.DataFrame, test: pd.DataFrame | None = None):
    """``(train, test, record)``: the frames with every logged column whose name a derivation could produce
    renamed (module docstring), and ``record`` one dict per rename ``{"channel" (the new name), "action":
    "renamed", "from", "note", "first_row": None}``. The frames are returned unchanged (not copied) when no
    column is renamed; a TEST column is renamed when TRAIN's is, or when TEST's own columns make it derivable."""
    frames = [df for df in (train, test) if df is not None]
    taken = set().union(*(df.columns for df in frames))
    names = []
    for df in frames:
        names += [c for c in df.columns if c not in NOT_CANDIDATES and c not in names
                  and is_derivable_name(c, df.columns)]
    if not names:
        return train, test, []
    mapping = {}
    for name in names:
        mapping[name] = _free_name(name, taken)
        taken.add(mapping[name])
    record = [{"channel": new, "action": "renamed", "from": old, "first_row": None,
               "note": (f"logged as `{old}`, a name the loop derives from the log; read as `{new}` so that both "
                        "are kept")} for old, new in mapping.items()]
    train = train.rename(columns=mapping)
    test = test.rename(columns=mapping) if test is not None else None
    return train, test, record


def prepare_channels(train: pd.DataFrame, test: pd.DataFrame | None = None, response_columns=()):
    """``(train, test, record, response_columns)``: :func:`set_aside_derivable_names`, then
    :func:`l1b2.closeloop.auxiliary.with_usable_channels` on its frames; ``record`` both records in that order, and
    the response columns under their names in the returned frames (a renamed one keeps its role)."""
    train, test, renamed = set_aside_derivable_names(train, test)
    mapping = {r["from"]: r["channel"] for r in renamed}
    responses = tuple(mapping.get(c, c) for c in response_columns)
    train, test, usable = with_usable_channels(train, test, responses)
    return train, test, renamed + usable, responses


def with_protocol_channels(train: pd.DataFrame, test: pd.DataFrame | None, response_columns, sess: Session,
                           response_tests=()):
    """``(train, test, records)``: the frames with every channel the loop derives from the log appended, in this
    order: the event clocks (:func:`l1b2.closeloop.events.with_event_clocks`), the lags and steps
    (:func:`l1b2.closeloop.lags.with_lagged_channels`), the pause (:func:`l1b2.closeloop.pauses.with_pause_channel`),
    the break clock (:func:`l1b2.closeloop.pauses.with_break_clock`), the previous run's load
    (:func:`l1b2.closeloop.history.with_previous_pass`), the run's clock and travel
    (:func:`l1b2.closeloop.runclock.with_run_clock`, :func:`~l1b2.closeloop.runclock.with_run_travel`) and the
    logarithms of the logged channels that span decades (:func:`l1b2.closeloop.logscale.with_log_channels`: of the
    channels logged, not of those derived here) and the run settings of the columns the consequence test classed
    responses and of the logged columns read along the stroke (:func:`l1b2.closeloop.runsetting.with_run_settings`,
    ``response_tests`` the test's records; the model's inputs are read per sample);
    ``records`` their records under ``"event_clocks"``, ``"lagged_channels"``, ``"pause_channel"``, ``"break_clock"``,
    ``"previous_pass"``, ``"run_clock"``, ``"run_travel"``, ``"log_channels"`` and ``"run_settings"``. Each
    returned frame names the columns derived here in its ``attrs`` (:func:`l1b2.closeloop.auxiliary.derived_columns`).
    ``sess``: the frames' :func:`~l1b2.closeloop.events.session` before any derivation."""
    rec = {}
    before = set(train.columns)
    logged = [name for name, kind in channel_kinds(train, response_columns) if kind == "logged"]
    along = [name for name in logged if name not in MODEL_INPUTS and is_along_stroke(train, name)]
    train, test, rec["event_clocks"] = with_event_clocks(train, test, response_columns, sess)
    train, test, rec["lagged_channels"] = with_lagged_channels(train, test, response_columns, sess)
    train, test, rec["pause_channel"] = with_pause_channel(train, test, sess)
    train, test, rec["break_clock"] = with_break_clock(train, test, sess)
    train, test, rec["previous_pass"] = with_previous_pass(train, test, sess)
    train, test, rec["run_clock"] = with_run_clock(train, test)   # along the stroke only
    train, test, rec["run_travel"] = with_run_travel(train, test)   # along the stroke only
    train, test, rec["log_channels"] = with_log_channels(train, test, logged)
    train, test, rec["run_settings"] = with_run_settings(train, test, response_tests, response_columns, along)
    for df in (train, test):
        if df is not None:
            df.attrs[DERIVED_ATTR] = derived_columns(df) + tuple(c for c in df.columns if c not in before)
    return train, test, rec
