"""The logarithm of a logged channel that spans decades, derived as a channel of its own.

A positive quantity that a rig sets or reads over more than a decade (a decade box's resistance, a chamber's
pressure, a flow, a dose) often acts through its logarithm: a law in ``ln Q`` (a relaxation peaking at one time
constant, an adsorption isotherm, a bell in ``log R``) is flat over most of the raw range and changes in its bottom
decade, where a line or a parabola of ``Q`` cannot follow it. For every such logged channel the loop derives
``ln_<channel>`` (:data:`l1b2.units.LOG_PREFIX`), the natural logarithm of the value in the column's own unit,
``ln(Q / 1 unit)``, dimensionless (:func:`l1b2.units.column_unit`, :func:`l1b2.units.unit_note`). It is one more
channel with every form, shape and level; the logged column keeps its own.

Which channels (:func:`log_candidates`): a logged channel of TRAIN (:func:`l1b2.closeloop.candidates.channel_kinds`,
kind ``"logged"``: not the required columns, a response, a text label or a channel the loop derives) whose values
are finite and positive in TRAIN and, when TEST has the column, in TEST, whose largest TRAIN value is at least
:data:`SPAN_RATIO` times its smallest, and whose unit is not an offset unit (:data:`l1b2.units.DIFFERENCE_UNITS`:
a logarithm of degrees Celsius means nothing). A name that a column of the frame already holds is not derived
(:mod:`l1b2.closeloop.derived` sets a logged ``ln_<channel>`` aside first).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..units import DIFFERENCE_UNITS, LOG_PREFIX, column_unit

__all__ = ["SPAN_RATIO", "log_candidates", "with_log_channels"]

#: a channel's largest TRAIN value over its smallest from which its logarithm is derived (one decade)
SPAN_RATIO = 10.0


def _positive(values) -> bool:
    v = np.asarray(values, float)
    return bool(v.size and np.all(np.isfinite(v)) and np.all(v > 0))


def log_candidates(train: pd.DataFrame, test: pd.DataFrame | None, logged) -> list[str]:
    """The names among ``logged`` (channels of ``train``) whose logarithm is derived (module docstring)."""
    out = []
    for name in logged:
        if name not in train.columns or LOG_PREFIX + name in train.columns:
            continue
        if test is not None and LOG_PREFIX + name in test.columns:
            continue
        unit = column_unit(name)
        v = train[name].to_numpy(float)
        if unit in DIFFERENCE_UNITS or not _positive(v) or v.max() < SPAN_RATIO * v.min():
            continue
        if test is not None and name in test.columns and not _positive(test[name].to_numpy(float)):
            continue
        out.append(name)
    return out


def with_log_channels(train: pd.DataFrame, test: pd.DataFrame | None, logged):
    """``(train, test, record)``: copies of the frames with ``ln_<name>`` appended for every name of
    :func:`log_candidates` (``test`` None stays None; a TEST frame without the column gets none), and ``record``
    one ``{"channel", "from", "unit", "train_range", "decades"}`` per derived channel (``unit`` the logged
    column's, None when its name gives none; ``decades`` ``log10`` of TRAIN's largest over its smallest value).
    The frames are returned unchanged (not copied) when no channel qualifies."""
    names = log_candidates(train, test, logged)
    if not names:
        return train, test, []
    train, test = train.copy(), (test.copy() if test is not None else None)
    record = []
    for name in names:
        for df in (train, test):
            if df is not None and name in df.columns:
                df[LOG_PREFIX + name] = np.log(df[name].to_numpy(float))
        v = train[name].to_numpy(float)
        record.append({"channel": LOG_PREFIX + name, "from": name, "unit": column_unit(name),
                       "train_range": [float(v.min()), float(v.max())],
                       "decades": float(np.log10(v.max() / v.min()))})
    return train, test, record
