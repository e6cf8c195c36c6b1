"""Gaps in a logged quantity: missing readings bridged within their run.

A logger writes an empty cell, a NaN token or an infinity where a sensor gave no reading (a thermocouple's
amplifier flagging an open circuit, a counter that lost its gate). For a continuous quantity that a run holds
constant or changes slowly, the best estimate at such a sample is the straight line in time between the run's
readings on either side; before the run's first reading and after its last the nearest reading holds. A run is
one traverse at constant drive inputs, so a bridge never crosses from one run into the next.

:func:`fill_gaps` is that rule, the one home of it: the data contract applies it to the optional input columns
:data:`GAP_COLUMNS` when reading (:mod:`~l1b2.data.validate`), and the close loop to the auxiliary columns it
takes as channels (:mod:`l1b2.closeloop.auxiliary`). :func:`gap_record` is what the loader records of it,
:func:`gap_lines` its lines in the reports and on the command line.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .columns import FREQUENCY, TEMPERATURE

__all__ = ["GAP_COLUMNS", "fill_gaps", "gap_record", "gap_lines"]

#: the known columns whose gaps are bridged on reading: optional inputs logged beside the experiment. The
#: required columns define the experiment and the measured speed is the output the model is scored on; a gap
#: in those is refused.
GAP_COLUMNS: tuple[str, ...] = (FREQUENCY, TEMPERATURE)


def fill_gaps(values, time_s, run) -> tuple[np.ndarray, list]:
    """Non-finite samples replaced by the linear interpolation in time between their run's finite samples.

    Parameters
    ----------
    values : array_like
        The quantity per sample (any unit); NaN and +-inf are gaps.
    time_s : array_like
        Time per sample [s], increasing within each run.
    run : array_like
        Run id per sample. Samples with one id form one run; a run is filled from its own samples only.

    Returns
    -------
    filled : numpy.ndarray
        A copy of ``values`` where each gap at time ``t`` between the run's readings ``(t0, x0)`` and
        ``(t1, x1)`` is ``x0 + (x1 - x0) (t - t0) / (t1 - t0)``; a gap before the run's first reading takes
        that reading, one after its last reading takes that one. Runs without any finite sample are left as
        they are.
    empty_runs : list
        The ids of the runs without any finite sample, in order of appearance.
    """
    v = np.asarray(values, float).copy()
    t = np.asarray(time_s, float)
    codes, uniq = pd.factorize(pd.Series(run), sort=False)
    empty = []
    for k in range(len(uniq)):
        idx = np.flatnonzero(codes == k)
        ok = np.isfinite(v[idx])
        if ok.all():
            continue
        if not ok.any():
            empty.append(uniq[k])
            continue
        v[idx[~ok]] = np.interp(t[idx[~ok]], t[idx[ok]], v[idx[ok]])
    return v, empty


def gap_record(gap: np.ndarray, run) -> dict:
    """What was filled in one column: ``cells`` (count), ``runs`` (runs with a gap) and ``first_row`` /
    ``first_line`` of the first gap (1-based data row, header excluded, and file line, as
    :class:`~l1b2.errors.DataFormatError` names them).

    Parameters
    ----------
    gap : numpy.ndarray of bool
        Where a sample was a gap.
    run : array_like
        Run id per sample.
    """
    idx = np.flatnonzero(gap)
    runs = pd.Series(np.asarray(run)[idx]).nunique() if idx.size else 0
    first = int(idx[0]) + 1 if idx.size else None
    return {"cells": int(idx.size), "runs": int(runs), "first_row": first,
            "first_line": None if first is None else first + 1}


def gap_lines(gaps_filled: dict) -> list[str]:
    """One line per file part and column of a report's ``checks["gaps_filled"]`` (``{"train": {column: record},
    "test": {...}}``, records of :func:`gap_record`): what the loader filled, where the first gap was."""
    out = []
    for part, columns in (gaps_filled or {}).items():
        for name, r in (columns or {}).items():
            out.append(f"{part.upper()} {name}: {r['cells']} empty, NaN or infinite cell(s) in {r['runs']} run(s) "
                       f"(first: row {r['first_row']}, line {r['first_line']}) filled by linear interpolation in "
                       "time within their run")
    return out
