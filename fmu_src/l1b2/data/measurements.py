"""Measured data of an L1B2 test rig: reading, validating, writing, splitting.

Implements the contract of ``shared/data-format.md``: one CSV file with one
row per sample (SI units, unit in the column name), optionally accompanied by
a sidecar ``NAME.json`` beside ``NAME.csv`` holding rig settings.

Reading (:func:`load_measurements`) and writing (:func:`write_measurements`)
apply the same validation. Input that breaks the contract is refused with one
:class:`~l1b2.errors.DataFormatError` naming the file, the column with its
unit and the first offending row (1-based data row and file line), e.g.::

    data.csv: column 'time_s' [s], row 17 (line 18): time not increasing (0.016 after 0.017)

Checks are made in two stages: first every value must parse (non-numeric,
empty, NaN and infinite values; the earliest offending row over all columns
is reported), then the contents rules (direction, SI plausibility, time
order, run contiguity; again the earliest offending row is reported).

Settings precedence: explicit keyword argument (the command line) > sidecar
> defaults (:data:`DEFAULT_DRIVE_FREQUENCY_HZ`,
:data:`DEFAULT_ENCODER_RESOLUTION_M`; the slider mass has no default and is
``None`` = unknown unless given).
"""

from __future__ import annotations

import functools
import json
import math
import os
import re
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from io import StringIO
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from ..errors import DataFormatError, IdentificationError, ParameterError
from ..units import COLUMN_UNITS, SIDECAR_FIELD_UNITS, data_unit

__all__ = [
    "TIME", "RUN", "POSITION", "VOLTAGE", "DIRECTION", "LOAD", "SPEED",
    "FREQUENCY", "TEMPERATURE",
    "ColumnSpec", "KNOWN_COLUMNS", "REQUIRED_COLUMNS", "NUMERIC_COLUMNS",
    "SIDECAR_FIELDS",
    "DEFAULT_DRIVE_FREQUENCY_HZ", "DEFAULT_ENCODER_RESOLUTION_M",
    "MAX_ABS_POSITION_M", "MAX_ABS_SPEED_M_S", "MIN_VOLTAGE_V", "MAX_VOLTAGE_V",
    "MAX_ABS_LOAD_KG", "MIN_FREQUENCY_HZ", "MAX_FREQUENCY_HZ",
    "MIN_TEMPERATURE_C", "MAX_TEMPERATURE_C",
    "Measurements", "load_measurements", "write_measurements",
    "validate_frame", "split_by_load", "run_slices", "sidecar_path", "unit_of",
]

# --------------------------------------------------------------------------
# Columns
# --------------------------------------------------------------------------

TIME = "time_s"
RUN = "run"
POSITION = "position_m"
VOLTAGE = "voltage_V"
DIRECTION = "direction"
LOAD = "load_kg"
SPEED = "speed_m_s"
FREQUENCY = "frequency_Hz"
TEMPERATURE = "temperature_C"


class ColumnSpec(NamedTuple):
    """One known column of the measured-data CSV.

    Attributes
    ----------
    name : str
        Column name as written in the CSV header (case-sensitive).
    required : bool
        Whether every file must contain it.
    unit : str
        SI unit (``"-"`` for dimensionless / identifiers), from
        :data:`l1b2.units.COLUMN_UNITS`.
    meaning : str
        Short description, from ``shared/data-format.md``.
    """

    name: str
    required: bool
    unit: str
    meaning: str


#: The known columns, in the order of the contract table.
KNOWN_COLUMNS: tuple[ColumnSpec, ...] = (
    ColumnSpec(TIME, True, COLUMN_UNITS[TIME],
               "experiment clock; strictly increasing over the whole file in "
               "recording order, not reset between runs"),
    ColumnSpec(RUN, True, COLUMN_UNITS[RUN],
               "run identifier (integer or string); rows of one run are contiguous"),
    ColumnSpec(POSITION, True, COLUMN_UNITS[POSITION],
               "slider position from the encoder (0 = centre of the friction bar)"),
    ColumnSpec(VOLTAGE, True, COLUMN_UNITS[VOLTAGE], "drive voltage amplitude V0 at the stator"),
    ColumnSpec(DIRECTION, True, COLUMN_UNITS[DIRECTION],
               "+1 when channel CH1 is excited (drives toward +position), -1 for CH2"),
    ColumnSpec(LOAD, True, COLUMN_UNITS[LOAD],
               "signed load mass on the pulley: positive pulls toward -position, "
               "negative toward +position, 0 = no load"),
    ColumnSpec(SPEED, False, COLUMN_UNITS[SPEED],
               "measured slider speed; derived from position_m when absent"),
    ColumnSpec(FREQUENCY, False, COLUMN_UNITS[FREQUENCY],
               "drive frequency; filled from the sidecar / default when absent"),
    ColumnSpec(TEMPERATURE, False, COLUMN_UNITS[TEMPERATURE], "stator temperature, when measured"),
)

_SPEC = {c.name: c for c in KNOWN_COLUMNS}

#: Names of the required columns, in contract order.
REQUIRED_COLUMNS: tuple[str, ...] = tuple(c.name for c in KNOWN_COLUMNS if c.required)

#: Known columns holding real numbers (everything but ``run``).
NUMERIC_COLUMNS: tuple[str, ...] = tuple(c.name for c in KNOWN_COLUMNS if c.name != RUN)

#: Sidecar fields and their units (:data:`l1b2.units.SIDECAR_FIELD_UNITS`).
SIDECAR_FIELDS: dict[str, str] = SIDECAR_FIELD_UNITS

# --------------------------------------------------------------------------
# Defaults and plausibility thresholds (SI)
# --------------------------------------------------------------------------

#: Drive frequency used when neither column, sidecar nor caller gives one [Hz].
DEFAULT_DRIVE_FREQUENCY_HZ: float = 48_500.0
#: Encoder resolution used when neither sidecar nor caller gives one [m].
DEFAULT_ENCODER_RESOLUTION_M: float = 5e-8

#: |position_m| above this suggests the file is in millimetres [m].
MAX_ABS_POSITION_M: float = 1.0
#: |speed_m_s| above this suggests the file is in mm/s [m/s].
MAX_ABS_SPEED_M_S: float = 10.0
#: Lowest plausible drive voltage amplitude [V] (an amplitude is never negative).
MIN_VOLTAGE_V: float = 0.0
#: Highest plausible drive voltage amplitude [V] (above suggests mV).
MAX_VOLTAGE_V: float = 2000.0
#: |load_kg| above this suggests grams [kg].
MAX_ABS_LOAD_KG: float = 50.0
#: Lowest plausible drive frequency [Hz] (below suggests kHz).
MIN_FREQUENCY_HZ: float = 1e3
#: Highest plausible drive frequency [Hz].
MAX_FREQUENCY_HZ: float = 1e6
#: Lowest plausible stator temperature [degC].
MIN_TEMPERATURE_C: float = -100.0
#: Highest plausible stator temperature [degC] (above suggests kelvin).
MAX_TEMPERATURE_C: float = 300.0

# meta keys computed at load time; never written to a sidecar
_LOAD_TIME_META = ("source", "sidecar", "speed_derived", "frequency_filled")

_NAN_TOKENS = frozenset({
    "nan", "-nan", "+nan", "na", "n/a", "#n/a", "null", "none", "<na>",
    "nat", "#nan", "-1.#ind", "1.#qnan",
})
_CANONICAL_INT = re.compile(r"^-?(0|[1-9][0-9]*)$")
_LINE_IN_PARSER_ERROR = re.compile(r"line (\d+)")
_FIELDS_IN_PARSER_ERROR = re.compile(r"Expected (\d+) fields in line (\d+), saw (\d+)")


def unit_of(name: str | None) -> str | None:
    """Unit of a known column or sidecar field.

    Parameters
    ----------
    name : str or None
        Column or sidecar field name.

    Returns
    -------
    str or None
        The unit (``"-"`` for dimensionless), ``None`` when unknown.
    """
    return data_unit(name)


def sidecar_path(path: str | os.PathLike) -> Path:
    """Path of the sidecar ``NAME.json`` belonging to ``NAME.csv``.

    Parameters
    ----------
    path : str or os.PathLike
        The measured-data CSV file.

    Returns
    -------
    pathlib.Path
        ``path`` with its suffix replaced by ``.json``.
    """
    return Path(path).with_suffix(".json")


# --------------------------------------------------------------------------
# Evaluation mask (data-format.md, "Error metrics")
# --------------------------------------------------------------------------

#: Samples with |measured speed| below this are not evaluated [m/s] (5 mm/s).
MIN_EVAL_SPEED_M_S: float = 5e-3
#: Travel excluded at the start and at the end of each run [m] (2 mm).
END_EXCLUSION_M: float = 2e-3


def as_1d(name: str, values: Any) -> np.ndarray:
    arr = values.to_numpy(dtype=float) if isinstance(values, pd.Series) \
        else np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    return arr


def evaluation_mask(data: pd.DataFrame | Measurements | Any, position_m: Any = None,
                    run: Any = None, *, min_speed_m_s: float = MIN_EVAL_SPEED_M_S,
                    end_exclusion_m: float = END_EXCLUSION_M) -> np.ndarray:
    """Boolean mask of the samples on which errors are evaluated.

    Parameters
    ----------
    data : pandas.DataFrame, Measurements or array_like
        Either a table with columns ``speed_m_s`` [m/s] (measured speed),
        ``position_m`` [m] and ``run`` (then ``position_m`` and ``run`` must
        not be given), or the measured speed [m/s] per sample.
    position_m : array_like, optional
        Slider position per sample [m]; required when ``data`` is an array.
    run : array_like, optional
        Run id per sample (rows of one run contiguous); ``None`` = one run.
    min_speed_m_s : float
        Smallest evaluated |measured speed| [m/s]; default 5 mm/s.
    end_exclusion_m : float
        Travel excluded at each end of each run [m]; default 2 mm.

    Returns
    -------
    numpy.ndarray of bool
        True where |v_meas| >= ``min_speed_m_s`` and the distance travelled
        from the run's first sample and the distance remaining to the run's
        last sample are both >= ``end_exclusion_m``.

    Notes
    -----
    Travel is measured along the run's own path: the cumulative sum of
    |position(k) - position(k-1)| within the run (never across runs). For a
    monotonic traverse this equals |position - first position| and
    |last position - position|; if the slider reverses (e.g. bounces at an
    end stop) the back-and-forth motion counts as travel. Samples with
    non-finite speed or position are not evaluated.
    """
    if isinstance(data, Measurements):
        data = data.df
    if isinstance(data, pd.DataFrame):
        if position_m is not None or run is not None:
            raise TypeError("give either a DataFrame or arrays, not both")
        missing = [c for c in (SPEED, POSITION, RUN) if c not in data.columns]
        if missing:
            raise ValueError(f"evaluation_mask: DataFrame lacks column(s) {missing}")
        speed = as_1d(SPEED, data[SPEED])
        pos = as_1d(POSITION, data[POSITION])
        run = data[RUN]
    else:
        if position_m is None:
            raise TypeError("evaluation_mask: position_m is required with array input")
        speed = as_1d("speed", data)
        pos = as_1d("position_m", position_m)
    if pos.shape != speed.shape:
        raise ValueError(f"speed and position_m differ in length ({speed.size} vs {pos.size})")
    if run is None:
        blocks = [(None, slice(0, speed.size))] if speed.size else []
    else:
        run_values = run.to_numpy() if isinstance(run, pd.Series) else np.asarray(run)
        if run_values.shape != speed.shape:
            raise ValueError(f"run and speed differ in length ({run_values.size} vs {speed.size})")
        blocks = run_slices(run_values)

    with np.errstate(invalid="ignore"):
        mask = np.abs(speed) >= min_speed_m_s
    for _, sl in blocks:
        x = pos[sl]
        travelled = np.concatenate(([0.0], np.cumsum(np.abs(np.diff(x)))))
        remaining = travelled[-1] - travelled
        with np.errstate(invalid="ignore"):
            mask[sl] &= (travelled >= end_exclusion_m) & (remaining >= end_exclusion_m)
    return mask


# --------------------------------------------------------------------------
# Container
# --------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Measurements:
    """Validated measured data of one file.

    Attributes
    ----------
    df : pandas.DataFrame
        One row per sample, every column of the file in file order
        (including unknown extra columns, passed through). Known numeric
        columns are ``float64`` (``direction`` is ``int64``); ``run`` is
        ``int64`` when every id is a canonical integer, else strings exactly
        as given. When ``speed_m_s`` was absent it is appended, derived from
        position (``meta['speed_derived']``); when ``frequency_Hz`` was absent
        it is appended, filled with ``meta['drive_frequency_Hz']``
        (``meta['frequency_filled']``).
    meta : dict
        ``slider_mass_kg`` [kg] or ``None`` (unknown), ``encoder_resolution_m``
        [m], ``drive_frequency_Hz`` [Hz], ``description`` (str), ``source``
        (path of the CSV), ``sidecar`` (path of the sidecar read, or
        ``None``), ``speed_derived`` and ``frequency_filled`` (bool), plus any
        extra sidecar fields.
    path : pathlib.Path
        The CSV file the data came from.

    Notes
    -----
    ``eq=False``: comparing two instances with ``==`` compares identity
    (element-wise DataFrame comparison has no single truth value).
    """

    df: pd.DataFrame
    meta: dict
    path: Path

    @property
    def slider_mass_kg(self) -> float:
        """Slider mass [kg] from the sidecar or the caller; a :class:`DataFormatError` naming the file if unknown."""
        m_s = self.meta.get("slider_mass_kg")
        if m_s is None:
            raise DataFormatError(sidecar_path(self.path), "slider_mass_kg", None,
                                  f"slider mass unknown for {self.path}: give it on the command line "
                                  f"(--slider-mass) or in this sidecar")
        return float(m_s)

    @functools.cached_property
    def mask(self) -> np.ndarray:
        """The data format's evaluation mask (:func:`evaluation_mask`) of these samples, computed once."""
        out = evaluation_mask(self.df)
        out.setflags(write=False)
        return out

    @property
    def runs(self) -> list:
        """Run ids in file order (each once)."""
        return [rid for rid, _ in run_slices(self.df[RUN])]

    @property
    def n_samples(self) -> int:
        """Number of samples (rows)."""
        return int(len(self.df))

    def iter_runs(self) -> Iterator[tuple[Any, pd.DataFrame]]:
        """Iterate over the runs in file order.

        Yields
        ------
        run_id : int or str
            The run identifier.
        run_df : pandas.DataFrame
            The rows of that run (a slice of :attr:`df`, original index kept).
        """
        for rid, sl in run_slices(self.df[RUN]):
            yield rid, self.df.iloc[sl]


def run_slices(run: pd.Series | Sequence | np.ndarray) -> list[tuple[Any, slice]]:
    """Contiguous blocks of equal run id, in order.

    Parameters
    ----------
    run : array_like
        Run id per sample.

    Returns
    -------
    list of (run_id, slice)
        One entry per block of consecutive equal ids; ``slice`` indexes
        positions (not labels). With contiguous runs (as validated) there is
        exactly one block per run.
    """
    values = run.to_numpy() if isinstance(run, pd.Series) else np.asarray(run)
    n = len(values)
    if n == 0:
        return []
    change = np.ones(n, dtype=bool)
    if n > 1:
        change[1:] = values[1:] != values[:-1]
    starts = np.flatnonzero(change)
    stops = np.append(starts[1:], n)
    return [(_py(values[a]), slice(int(a), int(b))) for a, b in zip(starts, stops)]


def _py(value: Any) -> Any:
    """Numpy scalar -> Python scalar (for run ids in lists and messages)."""
    return value.item() if isinstance(value, np.generic) else value


# --------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------

def _fmt(x: Any) -> str:
    """Shortest round-trip text of a value for messages."""
    if isinstance(x, (float, np.floating)):
        text = repr(float(x))
        return text[:-2] if text.endswith(".0") else text
    return repr(_py(x)) if isinstance(x, str) else str(_py(x))


class _Problem(NamedTuple):
    row: int          # 0-based position
    order: int        # tie-break among columns
    column: str
    text: str


def _first(mask: np.ndarray) -> int | None:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


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
        values = col.to_numpy(dtype=float, na_value=np.nan)
        i = _first(~np.isfinite(values))
        if i is None:
            return values, None, ""
        v = values[i]
        what = "NaN value" if np.isnan(v) else f"infinite value ({_fmt(v)})"
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
    elif isinstance(raw, str) and raw.lower() in _NAN_TOKENS:
        what = f"NaN value ({raw!r})"
    elif np.isinf(values[i]):
        what = f"infinite value ({raw!r})"
    elif isinstance(raw, float) and np.isnan(raw):
        what = "NaN value"
    else:
        hint = ""
        if isinstance(raw, str) and re.fullmatch(r"[+-]?\d+,\d*([eE][+-]?\d+)?", raw):
            hint = " (decimal comma? the format requires a decimal point)"
        what = f"non-numeric value {raw!r}{hint}"
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
            return stripped.astype("int64"), None
        return stripped.astype(str), None
    return stripped, None


def validate_frame(df: pd.DataFrame, path: str | os.PathLike) -> pd.DataFrame:
    """Check a measurement table against the contract and type its columns.

    Parameters
    ----------
    df : pandas.DataFrame
        Table with (at least) the required columns; values may be strings
        (as read from a CSV) or numbers.
    path : str or os.PathLike
        File named in error messages (the file read or to be written).

    Returns
    -------
    pandas.DataFrame
        A copy with known numeric columns as ``float64`` (``direction`` as
        ``int64``), ``run`` normalised (see :class:`Measurements`), all other
        columns untouched, column order unchanged.

    Raises
    ------
    DataFormatError
        On the first breach of the contract; row numbers are 1-based data
        rows (positional, header excluded).
    """
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

    out = df.copy()
    out.columns = columns
    order = {c.name: k for k, c in enumerate(KNOWN_COLUMNS)}

    # Stage 1: every value must parse
    parse_problems: list[_Problem] = []
    values: dict[str, np.ndarray] = {}
    for name in NUMERIC_COLUMNS:
        if name not in out.columns:
            continue
        vals, bad, why = _parse_numeric(out[name])
        values[name] = vals
        if bad is not None:
            parse_problems.append(_Problem(bad, order[name], name, why))
    run_col, bad_run = _normalise_run(out[RUN])
    if bad_run is not None:
        parse_problems.append(_Problem(bad_run, order[RUN], RUN, "empty run id"))
    if parse_problems:
        first = min(parse_problems, key=lambda q: (q.row, q.order))
        if _is_blank_row(out.iloc[first.row]):
            raise DataFormatError(path, None, first.row + 1, "blank line inside the data")
        _raise_first(path, parse_problems)

    # Stage 2: contents rules
    problems: list[_Problem] = []

    def rule(name: str, bad: np.ndarray, text) -> None:
        i = _first(bad)
        if i is not None:
            problems.append(_Problem(i, order[name], name, text(i)))

    t = values[TIME]
    if len(t) > 1:
        bad = np.zeros(len(t), dtype=bool)
        bad[1:] = ~(t[1:] > t[:-1])
        rule(TIME, bad, lambda i: f"time not increasing ({_fmt(t[i])} after {_fmt(t[i - 1])})")

    blocks = run_slices(run_col)
    first_seen: dict[Any, int] = {}
    for rid, sl in blocks:
        if rid in first_seen:
            prev = _py(run_col.iloc[sl.start - 1])
            problems.append(_Problem(
                sl.start, order[RUN], RUN,
                f"run {_fmt(rid)} reappears after run {_fmt(prev)} (first seen at row "
                f"{first_seen[rid] + 1}); rows of one run must be contiguous"))
            break
        first_seen[rid] = sl.start

    d = values[DIRECTION]
    rule(DIRECTION, (d != 1.0) & (d != -1.0),
         lambda i: f"direction must be exactly +1 or -1, got {_fmt(d[i])}")

    x = values[POSITION]
    rule(POSITION, np.abs(x) > MAX_ABS_POSITION_M,
         lambda i: f"|position| = {_fmt(abs(x[i]))} m > {_fmt(MAX_ABS_POSITION_M)} m "
                   "is implausible in SI units (suggests millimetres)")

    u = values[VOLTAGE]
    rule(VOLTAGE, u < MIN_VOLTAGE_V,
         lambda i: f"voltage amplitude {_fmt(u[i])} V is negative")
    rule(VOLTAGE, u > MAX_VOLTAGE_V,
         lambda i: f"voltage amplitude {_fmt(u[i])} V > {_fmt(MAX_VOLTAGE_V)} V "
                   "is implausible (suggests millivolts)")

    m = values[LOAD]
    rule(LOAD, np.abs(m) > MAX_ABS_LOAD_KG,
         lambda i: f"|load| = {_fmt(abs(m[i]))} kg > {_fmt(MAX_ABS_LOAD_KG)} kg "
                   "is implausible (suggests grams)")

    if SPEED in values:
        v = values[SPEED]
        rule(SPEED, np.abs(v) > MAX_ABS_SPEED_M_S,
             lambda i: f"|speed| = {_fmt(abs(v[i]))} m/s > {_fmt(MAX_ABS_SPEED_M_S)} m/s "
                       "is implausible in SI units (suggests mm/s)")
    if FREQUENCY in values:
        f = values[FREQUENCY]
        rule(FREQUENCY, f < MIN_FREQUENCY_HZ,
             lambda i: f"frequency {_fmt(f[i])} Hz < {_fmt(MIN_FREQUENCY_HZ)} Hz "
                       "is implausible (suggests kHz)")
        rule(FREQUENCY, f > MAX_FREQUENCY_HZ,
             lambda i: f"frequency {_fmt(f[i])} Hz > {_fmt(MAX_FREQUENCY_HZ)} Hz "
                       "is implausible")
    if TEMPERATURE in values:
        th = values[TEMPERATURE]
        rule(TEMPERATURE, th < MIN_TEMPERATURE_C,
             lambda i: f"temperature {_fmt(th[i])} degC < {_fmt(MIN_TEMPERATURE_C)} degC "
                       "is implausible")
        rule(TEMPERATURE, th > MAX_TEMPERATURE_C,
             lambda i: f"temperature {_fmt(th[i])} degC > {_fmt(MAX_TEMPERATURE_C)} degC "
                       "is implausible (kelvin?)")
    if problems:
        _raise_first(path, problems)

    for name, vals in values.items():
        if name == DIRECTION:
            out[name] = vals.astype(np.int64)
        else:
            out[name] = vals
    out[RUN] = run_col
    return out


def _is_blank_row(row: pd.Series) -> bool:
    """True for a row read from a blank line (every field an empty string)."""
    return all(isinstance(v, str) and not v.strip() for v in row.tolist())


def _raise_first(path, problems: list[_Problem]):
    p = min(problems, key=lambda q: (q.row, q.order))
    raise DataFormatError(path, p.column, p.row + 1, p.text)


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
            or (c.lower().split("_")[0] == stem and c not in _SPEC)]
    if near:
        hint += "; found " + ", ".join(repr(c) for c in near) + \
                f": names are case-sensitive and the unit must be SI " \
                f"[{_SPEC[missing[0]].unit}]"
    return hint


# --------------------------------------------------------------------------
# Settings (sidecar, keywords, defaults)
# --------------------------------------------------------------------------

def _check_setting(name: str, value: Any) -> str | None:
    """Problem text for a bad setting value, or ``None`` when acceptable."""
    if name == "description":
        return None if isinstance(value, str) else \
            f"must be a string, got {type(value).__name__}"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        return f"must be a number, got {value!r}"
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        return f"must be a positive finite number, got {_fmt(v)}"
    if name == "drive_frequency_Hz":
        if v < MIN_FREQUENCY_HZ:
            return f"{_fmt(v)} Hz < {_fmt(MIN_FREQUENCY_HZ)} Hz is implausible (suggests kHz)"
        if v > MAX_FREQUENCY_HZ:
            return f"{_fmt(v)} Hz > {_fmt(MAX_FREQUENCY_HZ)} Hz is implausible"
    if name == "encoder_resolution_m" and v > MAX_ABS_POSITION_M:
        return f"{_fmt(v)} m is implausible in SI units"
    return None


def _read_sidecar(path: Path) -> dict:
    """Read and validate a sidecar JSON file (``{}`` when absent)."""
    if not path.exists():
        return {}
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(path, None, None, f"cannot read sidecar: {exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataFormatError(path, None, None,
                              f"invalid JSON at line {exc.lineno} column {exc.colno}: "
                              f"{exc.msg}") from None
    if not isinstance(data, dict):
        raise DataFormatError(path, None, None,
                              f"sidecar must be a JSON object, got {type(data).__name__}")
    out = {}
    for key, value in data.items():
        if key in SIDECAR_FIELDS:
            if value is None:  # JSON null = not given
                continue
            why = _check_setting(key, value)
            if why is not None:
                raise DataFormatError(path, key, None, why)
            out[key] = value if key == "description" else float(value)
        elif key in _LOAD_TIME_META:
            continue  # computed at load time, never taken from a file
        else:
            out[key] = value  # pass through unknown fields
    return out


def _merge_settings(sidecar: dict, **explicit: float | None) -> dict:
    meta: dict[str, Any] = {
        "slider_mass_kg": None,
        "encoder_resolution_m": DEFAULT_ENCODER_RESOLUTION_M,
        "drive_frequency_Hz": DEFAULT_DRIVE_FREQUENCY_HZ,
        "description": "",
    }
    meta.update(sidecar)
    for name, value in explicit.items():
        if value is None:
            continue
        why = _check_setting(name, value)
        if why is not None:
            raise ParameterError(f"option {name} [{SIDECAR_FIELDS[name]}]: {why}")
        meta[name] = float(value)
    return meta


# --------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------

def _read_table(path: Path) -> pd.DataFrame:
    """Read a CSV as strings, one DataFrame row per file line after the header."""
    if not path.exists():
        raise DataFormatError(path, None, None, "file not found")
    if path.is_dir():
        raise DataFormatError(path, None, None, "is a directory, not a CSV file")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataFormatError(path, None, None, f"cannot read file: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        row = line - 1 if line > 1 else None
        raise DataFormatError(path, None, row,
                              f"not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line})") from None
    if not text.strip():
        raise DataFormatError(path, None, None, "file is empty")
    try:
        table = pd.read_csv(StringIO(text), header=None, dtype=str, keep_default_na=False,
                            skip_blank_lines=False)
    except pd.errors.ParserError as exc:
        msg = str(exc).splitlines()[-1].strip()
        m = _FIELDS_IN_PARSER_ERROR.search(msg)
        if m:
            expected, line, saw = (int(g) for g in m.groups())
            raise DataFormatError(path, None, line - 1 if line > 1 else None,
                                  f"line has {saw} fields, the header has {expected}") from None
        m = _LINE_IN_PARSER_ERROR.search(msg)
        row = int(m.group(1)) - 1 if m else None
        raise DataFormatError(path, None, row if row else None,
                              f"cannot parse CSV: {msg}") from None
    header = [str(h).strip() for h in table.iloc[0].tolist()]
    if not any(header):
        raise DataFormatError(path, None, None, "header line (line 1) is blank")
    header = [h if h else f"Unnamed: {k}" for k, h in enumerate(header)]
    body = table.iloc[1:].reset_index(drop=True)
    body.columns = header
    # drop blank lines at the end of the file (blank lines inside are refused
    # later as empty values, so data rows keep mapping to line = row + 1)
    n = len(body)
    while n > 0 and _is_blank_row(body.iloc[n - 1]):
        n -= 1
    return body.iloc[:n]


def _infer_extra(col: pd.Series) -> pd.Series:
    """Type an unknown (pass-through) column read as text.

    Integers when every value is a canonical integer, floats when every
    non-empty value is a number (empty -> NaN), booleans for True/False,
    else strings (empty -> NaN), as pandas would infer.
    """
    stripped = col.str.strip()
    empty = (stripped == "").to_numpy()
    if not empty.any() and stripped.str.fullmatch(r"[+-]?\d+").all():
        try:
            return stripped.astype("int64")
        except (ValueError, OverflowError):
            pass
    no_value = empty | stripped.str.lower().isin(_NAN_TOKENS).to_numpy()
    nums = pd.to_numeric(stripped.where(~no_value, "nan"), errors="coerce")
    if not (nums.isna().to_numpy() & ~no_value).any():
        return nums.astype("float64")
    if not empty.any() and stripped.isin(["True", "False"]).all():
        return stripped == "True"
    return col.where(~empty, np.nan)


def _derive_speed(df: pd.DataFrame, path) -> np.ndarray:
    """Per-run finite-difference speed from position and time [m/s].

    Inside a run ``numpy.gradient`` (second-order central differences, valid
    for uneven sampling); at the two ends of a run second-order one-sided
    differences (first-order for a two-sample run). Never across runs.
    """
    x = df[POSITION].to_numpy(dtype=float)
    t = df[TIME].to_numpy(dtype=float)
    v = np.empty_like(x)
    for rid, sl in run_slices(df[RUN]):
        n = sl.stop - sl.start
        if n < 2:
            raise DataFormatError(path, POSITION, sl.start + 1,
                                  f"run {_fmt(rid)} has a single sample: speed_m_s is "
                                  "absent and cannot be derived from position")
        v[sl] = np.gradient(x[sl], t[sl], edge_order=2 if n >= 3 else 1)
    return v


def load_measurements(path: str | os.PathLike, *, slider_mass_kg: float | None = None,
                      encoder_resolution_m: float | None = None,
                      drive_frequency_Hz: float | None = None) -> Measurements:
    """Read and validate a measured-data CSV (and its sidecar).

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file. Its sidecar is ``NAME.json`` beside it (optional).
    slider_mass_kg : float, optional
        Slider mass [kg]; overrides the sidecar. Unknown (``None``) unless
        given here or in the sidecar.
    encoder_resolution_m : float, optional
        Encoder resolution [m]; overrides the sidecar; default
        :data:`DEFAULT_ENCODER_RESOLUTION_M`.
    drive_frequency_Hz : float, optional
        Drive frequency [Hz]; overrides the sidecar; default
        :data:`DEFAULT_DRIVE_FREQUENCY_HZ`. Used to fill ``frequency_Hz``
        only when that column is absent (a measured column always wins).

    Returns
    -------
    Measurements
        Validated data; see the class for columns and ``meta``.

    Raises
    ------
    DataFormatError
        The CSV or the sidecar breaks the contract (message names file,
        column or field with unit, and first offending row / line).
    ParameterError
        A keyword argument is not a plausible positive number.

    Notes
    -----
    * When ``speed_m_s`` is absent it is derived per run from position and
      time (see ``_derive_speed``) and ``meta['speed_derived']`` is True.
    * When ``frequency_Hz`` is absent it is filled with the constant
      ``meta['drive_frequency_Hz']`` (keyword > sidecar > 48 500 Hz) and
      ``meta['frequency_filled']`` is True: it was not measured.
    * Whitespace around header names and values is ignored; blank lines at
      the end of the file are ignored, blank lines inside are refused.
    """
    path = Path(path)
    table = _read_table(path)
    side = sidecar_path(path)
    sidecar = _read_sidecar(side) if side != path else {}
    meta = _merge_settings(sidecar, slider_mass_kg=slider_mass_kg,
                           encoder_resolution_m=encoder_resolution_m,
                           drive_frequency_Hz=drive_frequency_Hz)
    df = validate_frame(table, path)
    for name in df.columns:
        if name not in _SPEC:
            df[name] = _infer_extra(df[name])
    meta["speed_derived"] = SPEED not in df.columns
    if meta["speed_derived"]:
        df[SPEED] = _derive_speed(df, path)
    meta["frequency_filled"] = FREQUENCY not in df.columns
    if meta["frequency_filled"]:
        df[FREQUENCY] = np.full(len(df), float(meta["drive_frequency_Hz"]))
    meta["source"] = str(path)
    meta["sidecar"] = str(side) if side != path and side.exists() else None
    return Measurements(df=df.reset_index(drop=True), meta=meta, path=path)


# --------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------

def _sidecar_payload(meta: Mapping | None, side: Path) -> dict:
    """Settings to write into the sidecar, validated like a read sidecar."""
    meta = dict(meta or {})
    payload: dict[str, Any] = {
        "slider_mass_kg": meta.get("slider_mass_kg"),
        "encoder_resolution_m": meta.get("encoder_resolution_m", DEFAULT_ENCODER_RESOLUTION_M),
        "drive_frequency_Hz": meta.get("drive_frequency_Hz", DEFAULT_DRIVE_FREQUENCY_HZ),
        "description": meta.get("description", ""),
    }
    for key, value in meta.items():
        if key not in payload and key not in _LOAD_TIME_META:
            payload[key] = value
    out = {}
    for key, value in payload.items():
        if key in SIDECAR_FIELDS:
            if value is None:
                continue
            why = _check_setting(key, value)
            if why is not None:
                raise DataFormatError(side, key, None, why)
            value = value if key == "description" else float(value)
        try:
            json.dumps(value, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise DataFormatError(side, key, None, f"not JSON-serialisable: {exc}") from None
        out[key] = value
    return out


def _atomic_pair(files: list[tuple[Path, str]]) -> None:
    """Write texts to temp files beside their targets, then ``os.replace`` all."""
    temps: list[tuple[str, Path]] = []
    try:
        for target, text in files:
            fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp",
                                       dir=target.parent)
            temps.append((tmp, target))
            with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
            mode = target.stat().st_mode & 0o777 if target.exists() else 0o644
            os.chmod(tmp, mode)
        for tmp, target in temps:
            os.replace(tmp, target)
    finally:
        for tmp, _ in temps:
            if os.path.exists(tmp):
                os.unlink(tmp)


def write_measurements(df: pd.DataFrame | Measurements, path: str | os.PathLike,
                       meta: Mapping | None = None) -> Path:
    """Validate and write measured data as CSV plus sidecar JSON.

    Parameters
    ----------
    df : pandas.DataFrame or Measurements
        The samples (for a :class:`Measurements`, its ``meta`` is used when
        ``meta`` is not given).
    path : str or os.PathLike
        Target CSV file; the sidecar is written to ``NAME.json`` beside it.
    meta : mapping, optional
        Settings for the sidecar (``slider_mass_kg``, ``encoder_resolution_m``,
        ``drive_frequency_Hz``, ``description`` and any extra JSON fields);
        defaults when absent. Load-time keys (``source``, ``sidecar``,
        ``speed_derived``, ``frequency_filled``) are not written.

    Returns
    -------
    pathlib.Path
        The CSV path written.

    Raises
    ------
    DataFormatError
        The data or the settings break the contract; nothing is written.

    Notes
    -----
    * Columns marked in ``meta`` as not measured (``speed_derived`` ->
      ``speed_m_s``, ``frequency_filled`` -> ``frequency_Hz``) are not
      written, so the file does not claim they were measured; reading the
      file back derives / fills them again identically.
    * Floats are written with Python's shortest round-trip ``repr`` (the
      pandas default), so reading back gives bit-identical ``float64``.
    * Both files are written to temporary files in the target directory and
      then moved into place with ``os.replace``; a refused input writes
      nothing. The sidecar is always written (so a stale one cannot
      contradict the new CSV).
    """
    if isinstance(df, Measurements):
        meta = df.meta if meta is None else meta
        df = df.df
    path = Path(path)
    side = sidecar_path(path)
    if side == path:
        raise DataFormatError(path, None, None,
                              "a measured-data file must not have the suffix .json "
                              "(reserved for the sidecar)")
    meta = dict(meta or {})
    drop = [c for c, flag in ((SPEED, "speed_derived"), (FREQUENCY, "frequency_filled"))
            if meta.get(flag) and c in df.columns]
    table = df.drop(columns=drop)
    validate_frame(table, path)
    payload = _sidecar_payload(meta, side)
    csv_text = table.to_csv(index=False, lineterminator="\n")
    json_text = json.dumps(payload, indent=2, allow_nan=False) + "\n"
    _atomic_pair([(side, json_text), (path, csv_text)])
    return path


# --------------------------------------------------------------------------
# Train / test split
# --------------------------------------------------------------------------

def split_by_load(meas: Measurements, test_abs_loads: Sequence[float] = (0.05,),
                  atol: float = 1e-9) -> tuple[Measurements, Measurements]:
    """Split into training and test runs by load, as in the paper.

    Parameters
    ----------
    meas : Measurements
        Validated data.
    test_abs_loads : sequence of float
        |load_kg| values [kg] whose runs form the test set.
    atol : float
        Absolute tolerance [kg] when comparing |load_kg| with those values.

    Returns
    -------
    train, test : Measurements
        Disjoint subsets of whole runs, rows in file order, original index
        kept (file row = index + 1); ``meta`` copied with ``subset`` set to
        ``"train"`` / ``"test"`` and ``test_abs_loads`` recorded.

    Raises
    ------
    IdentificationError
        Either part would be empty, or a run mixes test and training loads.
    """
    loads = [float(v) for v in test_abs_loads]
    abs_load = np.abs(meas.df[LOAD].to_numpy(dtype=float))
    is_test = np.zeros(len(abs_load), dtype=bool)
    for value in loads:
        is_test |= np.isclose(abs_load, abs(value), rtol=0.0, atol=atol)
    for rid, sl in run_slices(meas.df[RUN]):
        part = is_test[sl]
        if part.any() and not part.all():
            raise IdentificationError(
                f"{meas.path}: run {_fmt(rid)} mixes loads selected for test "
                f"(|load_kg| in {loads} kg) with other loads; cannot split by run")
    for name, mask in (("test", is_test), ("training", ~is_test)):
        if not mask.any():
            present = sorted({float(v) for v in np.round(abs_load, 12)})
            raise IdentificationError(
                f"{meas.path}: split by load leaves the {name} set empty "
                f"(test |load_kg| = {loads} kg, atol {atol} kg; "
                f"|load_kg| present: {present} kg)")

    def subset(mask: np.ndarray, label: str) -> Measurements:
        meta = dict(meas.meta)
        meta["subset"] = label
        meta["test_abs_loads"] = loads
        return Measurements(df=meas.df.loc[mask], meta=meta, path=meas.path)

    return subset(~is_test, "train"), subset(is_test, "test")
