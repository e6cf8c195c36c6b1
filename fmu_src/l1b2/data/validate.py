"""The rules of the measured-data contract: checking a table and the rig settings.

:func:`validate_frame` checks a table (as read from a CSV, or about to be
written) in two stages: first every value must parse (non-numeric, empty,
NaN and infinite values; the earliest offending row over all columns is
reported), then the contents rules (direction, SI plausibility, time order,
run contiguity; again the earliest offending row is reported). In the
optional input columns :data:`~l1b2.data.gaps.GAP_COLUMNS` an empty, NaN or
infinite cell is a gap, not a breach: it is filled within its run
(:func:`~l1b2.data.gaps.fill_gaps`), and only a run with no reading at all
there is refused; :func:`validate_frame_filled` also returns what was
filled. Each breach
found is a :class:`DataProblem`; the earliest one is raised as a
:class:`~l1b2.errors.DataFormatError` naming the file, the column with its
unit and the row.

A third stage, applied when reading (:mod:`~l1b2.data.io`), looks for unit
mistakes that the hard limits let through: :func:`unusual_values` finds
values outside the range a linear USM rig produces
(:data:`~l1b2.data.columns.PLAUSIBLE`: grams as kg, kV as V, ms as s, ...)
and a speed column that disagrees with the position's time derivative
(:func:`speed_slopes`, per run, robust to noise, filtering and a lag of a
few samples); :func:`unusual_setting` does the same for a rig setting. These
are overridable (``allow_unusual_units``), the hard limits are not.

:func:`check_setting` is the rule for one rig setting (sidecar field or
keyword argument). :func:`run_slices` gives the contiguous blocks of a run
that the contiguity rule checks, and :func:`format_value` the shortest text
of a value, as used in every message of the data layer.

Used by :mod:`~l1b2.data.io` (reading and writing apply the same checks) and
:mod:`~l1b2.data.measurements` (which re-exports :func:`validate_frame` and
:func:`run_slices`).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from ..errors import DataFormatError
from .columns import (
    COLUMN_SPECS,
    run_slices,
    DIRECTION,
    FREQUENCY,
    KNOWN_COLUMNS,
    LOAD,
    MAX_ABS_LOAD_KG,
    MAX_ABS_POSITION_M,
    MAX_ABS_SPEED_M_S,
    MAX_FREQUENCY_HZ,
    MAX_TEMPERATURE_C,
    MAX_VOLTAGE_V,
    MIN_FREQUENCY_HZ,
    MIN_TEMPERATURE_C,
    MAX_SAMPLE_INTERVAL_S,
    MIN_PEAK_SPEED_M_S,
    MIN_VOLTAGE_V,
    NAN_TOKENS,
    NUMERIC_COLUMNS,
    PLAUSIBLE,
    POSITION,
    REQUIRED_COLUMNS,
    RUN,
    SIDECAR_FIELDS,
    SPEED,
    SPEED_SLOPE_BAND,
    TEMPERATURE,
    TIME,
    VOLTAGE,
    PlausibleRange,
)
from .dialects import time_order_hint, value_hint
from .gaps import GAP_COLUMNS, fill_gaps, gap_record
from .plausibility import speed_glitch, step_hint

__all__ = [
    "DataProblem", "validate_frame", "validate_frame_filled", "check_setting", "run_slices", "format_value",
    "is_blank_row", "unusual_setting", "unusual_values", "speed_slopes",
]

_CANONICAL_INT = re.compile(r"^-?(0|[1-9][0-9]*)$")

#: column -> its place in the contract table (tie-break between columns)
_ORDER = {c.name: k for k, c in enumerate(KNOWN_COLUMNS)}


# --------------------------------------------------------------------------
# Shared helpers: run blocks, message text
# --------------------------------------------------------------------------

def _py(value: Any) -> Any:
    """Numpy scalar -> Python scalar (for run ids in lists and messages)."""
    return value.item() if isinstance(value, np.generic) else value


def format_value(x: Any) -> str:
    """Shortest round-trip text of a value for messages (``1.0`` -> ``1``, strings quoted)."""
    if isinstance(x, (float, np.floating)):
        text = repr(float(x))
        return text[:-2] if text.endswith(".0") else text
    return repr(_py(x)) if isinstance(x, str) else str(_py(x))


def is_blank_row(row: pd.Series) -> bool:
    """True for a row read from a blank line (every field an empty string)."""
    return all(isinstance(v, str) and not v.strip() for v in row.tolist())


# --------------------------------------------------------------------------
# Parsing values (stage 1)
# --------------------------------------------------------------------------

class DataProblem(NamedTuple):
    """One breach of the data contract found in a table.

    Attributes
    ----------
    row : int
        0-based position of the offending row.
    order : int
        Place of the column in the contract table (tie-break among columns
        of the same row).
    column : str
        The offending column.
    text : str
        What is wrong, in plain words.
    """

    row: int
    order: int
    column: str
    text: str


def _first(mask: np.ndarray) -> int | None:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def _earliest(problems: list[DataProblem]) -> DataProblem:
    """The problem of the earliest row (ties: the column first in the contract table)."""
    return min(problems, key=lambda q: (q.row, q.order))


def _raise_first(path, problems: list[DataProblem]):
    p = _earliest(problems)
    raise DataFormatError(path, p.column, p.row + 1, p.text)


def _add_first(problems: list[DataProblem], name: str, bad: np.ndarray,
               text: Callable[[int], str]) -> None:
    """Record the first row where ``bad`` holds, with ``text(row)``, as a problem of column ``name``."""
    i = _first(bad)
    if i is not None:
        problems.append(DataProblem(i, _ORDER[name], name, text(i)))


def _strip_text(col: pd.Series) -> tuple[pd.Series, np.ndarray, bool]:
    """Strip whitespace from string values.

    Returns
    -------
    text : pandas.Series
        Object series: stripped strings, other values unchanged, missing
        values replaced by ``""``.
    missing : numpy.ndarray of bool
        Where the input was missing (None / NaN).
    all_str : bool
        Whether every non-missing value is a string.
    """
    missing = col.isna().to_numpy()
    if pd.api.types.infer_dtype(col, skipna=True) == "string":
        text = col.str.strip().astype(object).where(~missing, "")
        return text, missing, True
    obj = col.astype(object).where(~missing, "")
    return obj.map(lambda v: v.strip() if isinstance(v, str) else v), missing, False


def _parse_numeric(col: pd.Series) -> tuple[np.ndarray, int | None, str]:
    """Parse one column to float64.

    Returns
    -------
    values : numpy.ndarray
        Parsed values (NaN where not parseable).
    bad : int or None
        0-based position of the first value that is empty, NaN, infinite or
        non-numeric; ``None`` when all are finite numbers.
    why : str
        Description of the first bad value.
    """
    if pd.api.types.is_numeric_dtype(col.dtype):
        # float64 as it is (no copy: a large file is held once); other numbers converted, missing -> NaN
        values = col.to_numpy() if col.dtype == np.float64 else col.to_numpy(dtype=float, na_value=np.nan)
        i = _first(~np.isfinite(values))
        if i is None:
            return values, None, ""
        v = values[i]
        what = "NaN value" if np.isnan(v) else f"infinite value ({format_value(v)})"
        return values, i, what
    if pd.api.types.infer_dtype(col, skipna=False) == "string":
        # fast path (pd.to_numeric ignores surrounding whitespace)
        values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=float, na_value=np.nan)
        if np.isfinite(values).all():
            return values, None, ""
    obj = col.astype(object)
    text, missing, _ = _strip_text(col)
    values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float, na_value=np.nan)
    i = _first(~np.isfinite(values) | missing)
    if i is None:
        return values, None, ""
    raw = text.iloc[i]
    if missing[i]:
        orig = obj.iloc[i]
        what = "NaN value" if isinstance(orig, (float, np.floating)) else "empty value"
    elif isinstance(raw, str) and raw == "":
        what = "empty value"
    elif isinstance(raw, str) and raw.lower() in NAN_TOKENS:
        what = f"NaN value ({raw!r})"
    elif np.isinf(values[i]):
        what = f"infinite value ({raw!r})"
    elif isinstance(raw, float) and np.isnan(raw):
        what = "NaN value"
    else:
        what = f"non-numeric value {raw!r}{value_hint(raw) if isinstance(raw, str) else ''}"
    return values, i, what


def _normalise_run(col: pd.Series) -> tuple[pd.Series, int | None]:
    """Strip string run ids; integers when every id is a canonical integer.

    Returns the normalised column and the 0-based position of the first
    empty id (or ``None``).
    """
    if pd.api.types.is_integer_dtype(col.dtype) or pd.api.types.is_bool_dtype(col.dtype):
        return col, None
    if pd.api.types.is_float_dtype(col.dtype):
        return col, _first(col.isna().to_numpy())
    stripped, missing, all_str = _strip_text(col)
    bad = _first(missing | (stripped == "").to_numpy(dtype=bool))
    if bad is not None:
        return col, bad
    if all_str:
        if bool(stripped.str.fullmatch(_CANONICAL_INT.pattern).all()):
            try:
                return stripped.astype("int64"), None
            except OverflowError:  # beyond int64: identifiers all the same, kept as text
                return stripped.astype(str), None
        return stripped.astype(str), None
    return stripped, None


def _gap_cells(col: pd.Series, values: np.ndarray) -> np.ndarray:
    """Where a parsed column holds no reading: an empty cell, a NaN token (:data:`NAN_TOKENS`) or an infinity."""
    if pd.api.types.is_numeric_dtype(col.dtype):
        return ~np.isfinite(values)
    text, missing, _ = _strip_text(col)
    token = text.astype(str).str.lower().isin(NAN_TOKENS).to_numpy()
    return missing | (text == "").to_numpy(dtype=bool) | token | np.isinf(values)


#: appended to a gap in the measured speed: why it is not filled, and the remedy
SPEED_GAP_HINT = ("; speed_m_s is the measured output the model is fitted and scored on, so a gap in it is not "
                  "filled: leave the column out (the speed is then derived from position_m in every run) or leave "
                  "out the runs with gaps")


def _parse_values(table: pd.DataFrame, path) -> tuple[dict[str, np.ndarray], pd.Series, dict[str, np.ndarray]]:
    """Stage 1: every value must parse.

    Returns the known numeric columns present, parsed to float64, the
    normalised ``run`` column and, per column of :data:`GAP_COLUMNS` with a
    gap, where its gaps are (NaN there); raises for the earliest value that
    does not parse (over all columns; a gap in a column of
    :data:`GAP_COLUMNS` is not one), or for a blank line inside the data.
    """
    problems: list[DataProblem] = []
    values: dict[str, np.ndarray] = {}
    gaps: dict[str, np.ndarray] = {}
    for name in NUMERIC_COLUMNS:
        if name not in table.columns:
            continue
        vals, bad, why = _parse_numeric(table[name])
        if bad is not None and name in GAP_COLUMNS:
            gap = _gap_cells(table[name], vals)
            bad = _first(~np.isfinite(vals) & ~gap)
            if bad is not None:
                why = _parse_numeric(table[name].iloc[bad:bad + 1])[2]
            vals = np.where(gap, np.nan, vals)
            gaps[name] = gap
        elif bad is not None and name == SPEED and not why.startswith("non-numeric"):
            why += SPEED_GAP_HINT
        values[name] = vals
        if bad is not None:
            problems.append(DataProblem(bad, _ORDER[name], name, why))
    run_col, bad_run = _normalise_run(table[RUN])
    if bad_run is not None:
        problems.append(DataProblem(bad_run, _ORDER[RUN], RUN, "empty run id"))
    if problems:
        first = _earliest(problems)
        if is_blank_row(table.iloc[first.row]):
            raise DataFormatError(path, None, first.row + 1, "blank line inside the data")
        _raise_first(path, problems)
    return values, run_col, gaps


# --------------------------------------------------------------------------
# Contents rules (stage 2)
# --------------------------------------------------------------------------

def _order_problems(t: np.ndarray, run_col: pd.Series) -> list[DataProblem]:
    """Time strictly increasing over the whole file; rows of one run contiguous."""
    problems: list[DataProblem] = []
    if len(t) > 1:
        bad = np.zeros(len(t), dtype=bool)
        bad[1:] = ~(t[1:] > t[:-1])
        ids = run_col.to_numpy()
        _add_first(problems, TIME, bad,
                   lambda i: f"time not increasing ({format_value(t[i])} after {format_value(t[i - 1])})"
                   + time_order_hint(t, i, format_value(ids[i]) if ids[i] != ids[i - 1] else None))
    first_seen: dict[Any, int] = {}
    for rid, sl in run_slices(run_col):
        if rid in first_seen:
            prev = _py(run_col.iloc[sl.start - 1])
            problems.append(DataProblem(
                sl.start, _ORDER[RUN], RUN,
                f"run {format_value(rid)} reappears after run {format_value(prev)} (first seen at row "
                f"{first_seen[rid] + 1}); rows of one run must be contiguous"))
            break
        first_seen[rid] = sl.start
    return problems


def _range_problems(values: dict[str, np.ndarray]) -> list[DataProblem]:
    """Direction exactly +-1; every physical value plausible in SI units."""
    problems: list[DataProblem] = []
    fmt = format_value
    d = values[DIRECTION]
    _add_first(problems, DIRECTION, (d != 1.0) & (d != -1.0),
               lambda i: f"direction must be exactly +1 or -1, got {fmt(d[i])}")
    x = values[POSITION]
    _add_first(problems, POSITION, np.abs(x) > MAX_ABS_POSITION_M,
               lambda i: f"|position| = {fmt(abs(x[i]))} m > {fmt(MAX_ABS_POSITION_M)} m "
                         "is implausible in SI units (suggests millimetres or centimetres)")
    u = values[VOLTAGE]
    _add_first(problems, VOLTAGE, u < MIN_VOLTAGE_V,
               lambda i: f"voltage amplitude {fmt(u[i])} V is negative")
    _add_first(problems, VOLTAGE, u > MAX_VOLTAGE_V,
               lambda i: f"voltage amplitude {fmt(u[i])} V > {fmt(MAX_VOLTAGE_V)} V "
                         "is implausible (suggests millivolts)")
    m = values[LOAD]
    _add_first(problems, LOAD, np.abs(m) > MAX_ABS_LOAD_KG,
               lambda i: f"|load| = {fmt(abs(m[i]))} kg > {fmt(MAX_ABS_LOAD_KG)} kg "
                         "is implausible (suggests grams)")
    if SPEED in values:
        v = values[SPEED]
        _add_first(problems, SPEED, np.abs(v) > MAX_ABS_SPEED_M_S,
                   lambda i: f"|speed| = {fmt(abs(v[i]))} m/s > {fmt(MAX_ABS_SPEED_M_S)} m/s "
                             "is implausible in SI units (suggests mm/s)")
    if FREQUENCY in values:
        f = values[FREQUENCY]
        _add_first(problems, FREQUENCY, f < MIN_FREQUENCY_HZ,
                   lambda i: f"frequency {fmt(f[i])} Hz < {fmt(MIN_FREQUENCY_HZ)} Hz "
                             "is implausible (suggests kHz)")
        _add_first(problems, FREQUENCY, f > MAX_FREQUENCY_HZ,
                   lambda i: f"frequency {fmt(f[i])} Hz > {fmt(MAX_FREQUENCY_HZ)} Hz "
                             "is implausible")
    if TEMPERATURE in values:
        th = values[TEMPERATURE]
        _add_first(problems, TEMPERATURE, th < MIN_TEMPERATURE_C,
                   lambda i: f"temperature {fmt(th[i])} degC < {fmt(MIN_TEMPERATURE_C)} degC "
                             "is implausible")
        _add_first(problems, TEMPERATURE, th > MAX_TEMPERATURE_C,
                   lambda i: f"temperature {fmt(th[i])} degC > {fmt(MAX_TEMPERATURE_C)} degC "
                             "is implausible (kelvin?)")
    return problems


# --------------------------------------------------------------------------
# The table as a whole
# --------------------------------------------------------------------------

def _checked_header(df: pd.DataFrame, path) -> list[str]:
    """Column names as strings; refuses duplicate names, missing required columns and no rows."""
    columns = [str(c) for c in df.columns]
    seen: set[str] = set()
    for c in columns:
        if c in seen:
            raise DataFormatError(path, c, None, "duplicate column name")
        seen.add(c)
    missing = [c for c in REQUIRED_COLUMNS if c not in seen]
    if missing:
        raise DataFormatError(path, missing[0], None,
                              "missing required column" + _missing_hint(missing, columns))
    if len(df) == 0:
        raise DataFormatError(path, None, None, "no data rows")
    return columns


def _missing_hint(missing: list[str], columns: list[str]) -> str:
    """Hint for a missing column: lists all missing ones and near names."""
    hint = ""
    if len(missing) > 1:
        hint += " (also missing: " + ", ".join(repr(c) for c in missing[1:]) + ")"
    if len(columns) == 1 and (";" in columns[0] or "\t" in columns[0]):
        return hint + "; the header looks like it uses ';' or tab as separator, " \
                      "the format requires ','"
    stem = missing[0].split("_")[0].lower()
    near = [c for c in columns if c.lower() == missing[0].lower()
            or (re.split(r"[_\s\[(]", c.lower())[0] == stem and c not in COLUMN_SPECS)]
    if near:
        hint += "; found " + ", ".join(repr(c) for c in near) + \
                f": names are case-sensitive and the unit must be SI " \
                f"[{COLUMN_SPECS[missing[0]].unit}]"
    return hint


def _readingless_runs(gaps: dict[str, np.ndarray], run_col: pd.Series) -> list[DataProblem]:
    """Per column of :data:`GAP_COLUMNS`, the first run in which every sample is a gap (no reading to bridge from)."""
    problems: list[DataProblem] = []
    for name, gap in gaps.items():
        for rid, sl in run_slices(run_col):
            if gap[sl].all():
                problems.append(DataProblem(
                    sl.start, _ORDER[name], name,
                    f"run {format_value(rid)} has no reading in {name} (all of its {sl.stop - sl.start} cells "
                    "empty, NaN or infinite): a gap is bridged from its run's own readings, and a run without "
                    f"any is not a gap; log {name} in every run, or leave the column out"))
                break
    return problems


def validate_frame_filled(df: pd.DataFrame, path: str | os.PathLike) -> tuple[pd.DataFrame, dict[str, dict]]:
    """Check a measurement table against the contract, type its columns and bridge the gaps it allows.

    Gaps (empty cells, NaN tokens, infinities) are allowed in the optional
    input columns :data:`~l1b2.data.gaps.GAP_COLUMNS` when each run holds a
    reading there, and filled within their run
    (:func:`~l1b2.data.gaps.fill_gaps`); in any other column they are refused.

    Parameters
    ----------
    df : pandas.DataFrame
        Table with (at least) the required columns; values may be strings
        (as read from a CSV) or numbers.
    path : str or os.PathLike
        File named in error messages (the file read or to be written).

    Returns
    -------
    frame : pandas.DataFrame
        A copy with known numeric columns as ``float64`` (``direction`` as
        ``int64``), gaps filled, ``run`` normalised (see
        :class:`~l1b2.data.measurements.Measurements`), all other columns
        untouched, column order unchanged.
    filled : dict
        Per column with a gap, its :func:`~l1b2.data.gaps.gap_record`.

    Raises
    ------
    DataFormatError
        On the first breach of the contract; row numbers are 1-based data
        rows (positional, header excluded).
    """
    columns = _checked_header(df, path)
    out = df.copy(deep=False)  # copy-on-write: the columns replaced below never touch ``df``
    out.columns = columns
    values, run_col, gaps = _parse_values(out, path)
    problems = (_order_problems(values[TIME], run_col) + _range_problems(values)
                + _readingless_runs(gaps, run_col))
    if problems:
        _raise_first(path, problems)
    filled: dict[str, dict] = {}
    for name, gap in gaps.items():
        values[name] = fill_gaps(values[name], values[TIME], run_col)[0]
        filled[name] = gap_record(gap, run_col)
    for name, vals in values.items():
        out[name] = vals.astype(np.int64) if name == DIRECTION else vals
    out[RUN] = run_col
    return out, filled


def validate_frame(df: pd.DataFrame, path: str | os.PathLike) -> pd.DataFrame:
    """Check a measurement table against the contract and type its columns.

    The frame of :func:`validate_frame_filled` (parameters, result and
    errors there), without the record of the gaps filled.
    """
    return validate_frame_filled(df, path)[0]


# --------------------------------------------------------------------------
# Rig settings (sidecar fields, keyword arguments)
# --------------------------------------------------------------------------

def check_setting(name: str, value: Any) -> str | None:
    """Problem text for a bad value of a rig setting, or ``None`` when acceptable.

    Parameters
    ----------
    name : str
        A sidecar field (:data:`~l1b2.data.columns.SIDECAR_FIELDS`).
    value : object
        Its value: ``description`` must be a string, every other setting a
        positive finite number (plausible in SI units for the drive
        frequency and the encoder resolution).
    """
    if name == "description":
        return None if isinstance(value, str) else \
            f"must be a string, got {type(value).__name__}"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        return f"must be a number, got {value!r}"
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        return f"must be a positive finite number, got {format_value(v)}"
    if name == "drive_frequency_Hz":
        if v < MIN_FREQUENCY_HZ:
            return f"{format_value(v)} Hz < {format_value(MIN_FREQUENCY_HZ)} Hz is implausible (suggests kHz)"
        if v > MAX_FREQUENCY_HZ:
            return f"{format_value(v)} Hz > {format_value(MAX_FREQUENCY_HZ)} Hz is implausible"
    if name == "encoder_resolution_m" and v > MAX_ABS_POSITION_M:
        return f"{format_value(v)} m is implausible in SI units"
    return None


# --------------------------------------------------------------------------
# Physical plausibility (stage 3, on reading; overridable)
# --------------------------------------------------------------------------

def _unusual_text(value: float, rng: PlausibleRange, label: str, unit: str) -> str | None:
    """Problem text for one value outside its plausible range, or ``None``."""
    x = value if rng.signed else abs(value)
    shown = f"{label} = {x:.4g} {unit}"
    if x > rng.high:
        return f"{shown} > {rng.high:g} {unit} is unusual for a linear USM rig: {rng.above}"
    if rng.low and (rng.signed or x > 0) and x < rng.low:
        return f"{shown} < {rng.low:g} {unit} is unusual for a linear USM rig: {rng.below}"
    return None


def unusual_setting(name: str, value: Any) -> str | None:
    """Problem text for a rig setting outside the range a linear USM rig has, or ``None``.

    Parameters
    ----------
    name : str
        A sidecar field (:data:`~l1b2.data.columns.SIDECAR_FIELDS`).
    value : object
        Its value (already accepted by :func:`check_setting`; ``None`` = not given).
    """
    rng = PLAUSIBLE.get(name)
    if rng is None or value is None or isinstance(value, str):
        return None
    return _unusual_text(float(value), rng, name, SIDECAR_FIELDS[name])


def speed_slopes(df: pd.DataFrame, *, min_travel_m: float = 2e-4,
                 min_rms_speed_m_s: float = 5e-3) -> list[tuple[Any, int, float]]:
    """Per run, the regression slope of ``speed_m_s`` on d(``position_m``)/dt.

    The slope through the origin, ``sum(v * x') / sum(x'^2)`` with ``x'`` the
    per-run ``numpy.gradient`` of position over time, is 1 for a consistent
    file and stays within a few percent of it under measurement noise, a
    low-pass filtered speed and a lag of a few samples (the tests use a
    25 Hz filter at 1 kHz: 0.93-0.97), while a unit mistake moves it by a
    factor of 10 or more (time in ms: 1000, position x 100: 0.01) and a sign
    mistake makes it negative.

    Parameters
    ----------
    df : pandas.DataFrame
        Validated samples with ``time_s``, ``run``, ``position_m`` and ``speed_m_s``.
    min_travel_m, min_rms_speed_m_s : float
        A run is judged only when it travels at least this far [m] and its
        position derivative has at least this RMS [m/s] (a stalled run has
        nothing to compare).

    Returns
    -------
    list of (run_id, first_row, slope)
        One entry per judged run; ``first_row`` is the 0-based position of
        the run's first sample.
    """
    x = df[POSITION].to_numpy(dtype=float)
    t = df[TIME].to_numpy(dtype=float)
    v = df[SPEED].to_numpy(dtype=float)
    out = []
    for rid, sl in run_slices(df[RUN]):
        if sl.stop - sl.start < 3 or np.ptp(x[sl]) < min_travel_m:
            continue
        with np.errstate(all="ignore"):  # absurd positions (1e308) give inf here and are not judged
            xd = np.gradient(x[sl], t[sl])
            ss = float(np.sum(xd * xd))
            vv = float(np.sum(v[sl] * v[sl]))
        # judged when either speed is a traverse's: a slow derivative with a fast measured speed (time x 100)
        # is exactly what the slope must catch
        if not (np.isfinite(ss) and ss > 0) or max(math.sqrt(ss / xd.size),
                                                   math.sqrt(vv / xd.size)) < min_rms_speed_m_s:
            continue
        out.append((rid, sl.start, float(np.sum(v[sl] * xd)) / ss))
    return out


#: a measured speed sample further than this share of the run's peak speed (+ 10 mm/s + 6 x the robust noise
#: level) from the median of its 5 neighbours is a glitch (a step, e.g. at an end stop, and a filtered or
#: lagged speed are not)
MAX_SPEED_DEVIATION: float = 0.5


def _speed_spike_problem(df: pd.DataFrame, judged: list[tuple[Any, int, float]]) -> DataProblem | None:
    """An isolated speed sample far from its neighbours (a glitch, :func:`~l1b2.data.plausibility.speed_glitch`:
    not one that the uneven time stamps beside it explain), in a run whose slope is consistent."""
    v, s, t = (df[c].to_numpy(dtype=float) for c in (SPEED, POSITION, TIME))
    starts = {row for _, row, _ in judged}
    for rid, sl in run_slices(df[RUN]):
        hit = speed_glitch(v[sl], s[sl], t[sl], MAX_SPEED_DEVIATION) if sl.start in starts else None
        if hit is not None:
            i, med = hit
            return DataProblem(sl.start + i, _ORDER[SPEED], SPEED,
                               f"run {format_value(rid)}: speed_m_s = {v[sl][i]:.4g} m/s where its neighbours have "
                               f"{med:.4g} m/s (more than {MAX_SPEED_DEVIATION:.0%} of the run's peak speed "
                               f"off): a glitch in the speed column?{step_hint(t[sl], i)}")
    return None



def _slope_hint(b: float) -> str:
    if b < 0:
        return "the speed has the opposite sign of the position's change (sign convention of speed_m_s?)"
    if b > SPEED_SLOPE_BAND[1]:
        return (f"the speed is {b:.3g} x the position's derivative: time_s in ms, speed_m_s in mm/s, "
                "or position_m scaled down?")
    return (f"the speed is {b:.3g} x the position's derivative: position_m scaled up (mm, cm, x100) "
            "or time_s not in seconds?")


def _interval_problem(df: pd.DataFrame) -> DataProblem | None:
    """Median sample interval within runs implausibly long for a rig (time in ms?)."""
    t = df[TIME].to_numpy(dtype=float)
    if t.size < 2:
        return None
    same_run = np.zeros(t.size - 1, dtype=bool)
    for _, sl in run_slices(df[RUN]):
        same_run[sl.start:sl.stop - 1] = True
    dts = np.diff(t)[same_run]
    if not dts.size:
        return None
    med = float(np.median(dts))
    if med < MAX_SAMPLE_INTERVAL_S:
        return None
    i = int(np.flatnonzero(same_run & (np.diff(t) >= MAX_SAMPLE_INTERVAL_S))[0]) + 1
    return DataProblem(i, _ORDER[TIME], TIME,
                       f"median sample interval within runs {med:.4g} s >= "
                       f"{format_value(MAX_SAMPLE_INTERVAL_S)} s is unusual for a test rig: time in ms?")


def _peak_speed_problem(df: pd.DataFrame, speed_derived: bool) -> DataProblem | None:
    """No sample of the file as fast as a traverse (speed or time scaled?)."""
    v = np.abs(df[SPEED].to_numpy(dtype=float))
    if not v.size or float(np.max(v)) >= MIN_PEAK_SPEED_M_S:
        return None
    i = int(np.argmax(v))
    cause = "time_s in ms or position_m not in metres?" if speed_derived else \
        "speed_m_s not in m/s (km/s?) or time_s in ms?"
    return DataProblem(i, _ORDER[SPEED], SPEED,
                       f"the fastest sample of the file moves at {float(v[i]):.4g} m/s < "
                       f"{format_value(MIN_PEAK_SPEED_M_S)} m/s: no traverse of a linear USM is that slow; {cause}")


#: relative spread of voltage_V within a run above which it is not a run at constant drive inputs
MAX_RUN_VOLTAGE_SPREAD: float = 0.1


def _drive_input_problems(df: pd.DataFrame) -> list[DataProblem]:
    """A run is a traverse at constant drive inputs: direction and load constant, V0 within 10 % (measured V0 is noisy)."""
    problems: list[DataProblem] = []
    cols = {c: df[c].to_numpy(dtype=float) for c in (DIRECTION, LOAD, VOLTAGE)}
    for rid, sl in run_slices(df[RUN]):
        for name, x in cols.items():
            seg = x[sl]
            if name == VOLTAGE:
                ref = float(np.median(seg))
                bad = np.abs(seg - ref) > MAX_RUN_VOLTAGE_SPREAD * max(abs(ref), 1.0)
            else:
                ref = float(seg[0])
                bad = seg != ref
            i = _first(bad)
            if i is not None:
                problems.append(DataProblem(
                    sl.start + i, _ORDER[name], name,
                    f"run {format_value(rid)}: {name} changes within the run ({format_value(float(seg[i]))} where "
                    f"the run has {format_value(ref)}): a run is one traverse at constant drive inputs "
                    "(a corrupted cell, or two runs with one id?)"))
                break
    return problems[:1]


def unusual_values(df: pd.DataFrame, *, speed_derived: bool = False) -> list[DataProblem]:
    """Likely unit mistakes in a validated table (at most one per column, its first row).

    Values outside :data:`~l1b2.data.columns.PLAUSIBLE` (``load_kg`` above
    2 kg: grams?, ``voltage_V`` below 5 V: kV?, ...), a median sample
    interval above :data:`~l1b2.data.columns.MAX_SAMPLE_INTERVAL_S` (time in
    ms?) and, when the speed was measured, a run whose speed disagrees with
    the position's derivative (:func:`speed_slopes` outside
    :data:`~l1b2.data.columns.SPEED_SLOPE_BAND`) or an isolated speed
    sample (a glitch: further than half the run's peak speed from the median
    of its 5 neighbours), and a run whose direction, load or voltage (beyond
    10 %) changes within it.

    Parameters
    ----------
    df : pandas.DataFrame
        Validated samples (:func:`validate_frame`, speed derived if absent).
    speed_derived : bool
        ``speed_m_s`` was derived from position (then it is not compared
        with the derivative, and an implausible value blames position/time).

    Returns
    -------
    list of DataProblem
        Empty when everything is plausible.
    """
    problems: list[DataProblem] = []
    for name, rng in PLAUSIBLE.items():
        if name not in df.columns or name not in _ORDER:
            continue
        vals = df[name].to_numpy(dtype=float)
        mags = vals if rng.signed else np.abs(vals)
        bad = (mags > rng.high) | ((mags < rng.low) & (rng.signed | (mags > 0)))
        i = _first(bad)
        if i is None:
            continue
        label = name if (rng.signed or name in (VOLTAGE, FREQUENCY)) else f"|{name}|"
        text = _unusual_text(float(vals[i]), rng, label, COLUMN_SPECS[name].unit)
        if name == SPEED and speed_derived:
            text += " (speed derived from position_m and time_s: check both units)"
        span = f"{float(np.min(mags)):.4g} to {float(np.max(mags)):.4g}"
        problems.append(DataProblem(i, _ORDER[name], name, f"{text} ({label} in this file: {span})"))
    problems += _drive_input_problems(df)
    interval = _interval_problem(df)
    for extra in (interval, _peak_speed_problem(df, speed_derived) if SPEED in df.columns else None):
        if extra is not None:
            problems.append(extra)
    if not speed_derived and SPEED in df.columns and interval is None:  # time in ms: named by time_s already
        lo, hi = SPEED_SLOPE_BAND
        slopes = speed_slopes(df)
        for rid, row, b in slopes:
            if not lo <= b <= hi:
                problems.append(DataProblem(
                    row, _ORDER[SPEED], SPEED,
                    f"run {format_value(rid)}: speed_m_s disagrees with d(position_m)/dt (regression slope "
                    f"{b:.3g}, expected 1 within [{format_value(lo)}, {format_value(hi)}]): {_slope_hint(b)}"))
                break
        else:
            spike = _speed_spike_problem(df, slopes)
            if spike is not None:
                problems.append(spike)
    return sorted(problems, key=lambda q: (q.row, q.order))
