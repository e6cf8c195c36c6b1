"""Files of measured data: reading and writing the CSV and its sidecar JSON.

The file side of the contract in the rig data format (docs/reference/data-format.md): one CSV file (one
row per sample, header line first) plus an optional sidecar ``NAME.json``
beside ``NAME.csv`` with the rig settings. :func:`read_table_and_sidecar`
reads both, applies :func:`~l1b2.data.validate.validate_frame_filled` (which
bridges the gaps of the optional input columns), merges the
settings (keyword > sidecar > default), derives ``speed_m_s`` / fills
``frequency_Hz`` when absent; :func:`write_table_and_sidecar` validates the
same way and writes both files atomically. Problems of the files themselves
(missing, not UTF-8, ragged lines, invalid JSON, and what exports write
instead of the format, named by :mod:`~l1b2.data.dialects`: a units row, a
preamble, a repeated header, an unnamed column, a binary file) are reported
as :class:`~l1b2.errors.DataFormatError` naming file and line.

The public entry points are :func:`l1b2.data.measurements.load_measurements`
and :func:`l1b2.data.measurements.write_measurements`, which wrap these two
functions in the :class:`~l1b2.data.measurements.Measurements` container.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
from collections.abc import Mapping
from io import StringIO
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import DataFormatError, ParameterError
from .columns import (
    COLUMN_SPECS,
    DEFAULT_DRIVE_FREQUENCY_HZ,
    DEFAULT_ENCODER_RESOLUTION_M,
    FREQUENCY,
    LOAD_TIME_META,
    NAN_TOKENS,
    NUMERIC_COLUMNS,
    POSITION,
    RUN,
    SIDECAR_FIELDS,
    SPEED,
    TIME,
    sidecar_path,
)
from .dialects import binary_kind, header_line_problem, repeated_header, units_row, unnamed_columns
from .plausibility import physics_findings
from .validate import (
    check_setting,
    format_value,
    is_blank_row,
    run_slices,
    unusual_setting,
    unusual_values,
    validate_frame,
    validate_frame_filled,
)

__all__ = ["read_table_and_sidecar", "write_table_and_sidecar", "read_sidecar", "unit_findings"]

_LINE_IN_PARSER_ERROR = re.compile(r"line (\d+)")
_FIELDS_IN_PARSER_ERROR = re.compile(r"Expected (\d+) fields in line (\d+), saw (\d+)")


# --------------------------------------------------------------------------
# Settings (sidecar, keywords, defaults)
# --------------------------------------------------------------------------

#: longest sidecar read [characters]
MAX_SIDECAR_CHARS = 1_000_000


class _DuplicateKey(ValueError):
    def __init__(self, key: str):
        super().__init__(key)
        self.key = key


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict:
    """``json.loads`` hook: an object with a key twice is refused (the last one would silently win)."""
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def read_sidecar(path: Path) -> dict:
    """Read and validate a sidecar JSON file (``{}`` when absent)."""
    if not path.exists():
        return {}
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(path, None, None, f"cannot read sidecar: {exc}") from None
    if len(text) > MAX_SIDECAR_CHARS:
        raise DataFormatError(path, None, None, f"sidecar of {len(text)} characters, more than "
                              f"{MAX_SIDECAR_CHARS}: a sidecar holds a few settings")
    try:
        data = json.loads(text, object_pairs_hook=_unique_keys)
    except json.JSONDecodeError as exc:
        raise DataFormatError(path, None, None,
                              f"invalid JSON at line {exc.lineno} column {exc.colno}: "
                              f"{exc.msg}") from None
    except _DuplicateKey as exc:
        raise DataFormatError(path, exc.key, None, f"the key '{exc.key}' appears twice in the sidecar: which "
                              "value is meant? (JSON readers disagree: some keep the first, some the last)") from None
    except RecursionError:
        raise DataFormatError(path, None, None, "JSON nested too deeply: a sidecar is one flat object "
                              "of settings") from None
    if not isinstance(data, dict):
        raise DataFormatError(path, None, None,
                              f"sidecar must be a JSON object, got {type(data).__name__}")
    out = {}
    for key, value in data.items():
        if key in SIDECAR_FIELDS:
            if value is None:  # JSON null = not given
                continue
            why = check_setting(key, value)
            if why is not None:
                raise DataFormatError(path, key, None, why)
            out[key] = value if key == "description" else float(value)
        elif key in LOAD_TIME_META:
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
        why = check_setting(name, value)
        if why is not None:
            raise ParameterError(f"option {name} [{SIDECAR_FIELDS[name]}]: {why}")
        meta[name] = float(value)
    return meta


# --------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------

#: rows parsed at a time by :func:`_read_fast` (bounds the parser's buffers)
FAST_CHUNK_ROWS = 50_000
_CANONICAL_RUN = r"-?(?:0|[1-9][0-9]{0,17})"  # an integer id that int64 holds and the text path would convert


def _count_lines(path: Path) -> int:
    n, last = 0, b"\n"
    with open(path, "rb") as fh:
        while block := fh.read(1 << 22):
            n += block.count(b"\n")
            last = block[-1:]
    return n + (last != b"\n")


def _read_fast(path: Path) -> pd.DataFrame | None:
    """A well-formed file read straight into typed columns, or ``None`` (then :func:`_read_table` reads text).

    Known numeric columns are parsed to float64 while reading, a ``run``
    column of plain integers to int64, other columns as text, a block of
    :data:`FAST_CHUNK_ROWS` rows at a time into arrays sized once, so a
    valid file gives the same table as the text path at a fraction of its
    memory (no copy of the file as one string, no Python string per numeric
    cell). Anything unusual - a header that is not plain comma-separated
    names, a cell that is not a finite number, a blank or ragged line, bytes
    that are not UTF-8 - gives ``None``, and the text path finds and names it.
    """
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            header = fh.readline().rstrip("\r\n")
        n_rows = _count_lines(path) - 1
    except (OSError, UnicodeDecodeError):
        return None
    names = [h.strip() for h in header.split(",")]
    if (not header or '"' in header or "\t" in header or ";" in header or not all(names)
            or len(set(names)) != len(names) or RUN not in names or n_rows < 1):
        return None
    numeric = [n for n in names if n in NUMERIC_COLUMNS]
    cols: dict[str, Any] = {n: np.empty(n_rows) for n in numeric}
    text: dict[str, list] = {n: [] for n in names if n not in numeric and n != RUN}
    run_text: list = []  # only once an id is not a plain integer (the ids before it are, as text)
    run_int = np.empty(n_rows, dtype=np.int64)
    run_is_int = True
    at = 0
    try:
        reader = pd.read_csv(path, encoding="utf-8-sig", dtype={n: ("float64" if n in numeric else str) for n in names},
                             header=0, names=names, na_filter=False, skip_blank_lines=False, engine="c",
                             chunksize=FAST_CHUNK_ROWS)
        with reader:
            for chunk in reader:
                k = len(chunk)
                if at + k > n_rows or len(chunk.columns) != len(names):
                    return None
                for n in numeric:
                    x = chunk[n].to_numpy(dtype=float)
                    if not np.isfinite(x).all():
                        return None
                    cols[n][at:at + k] = x
                run = chunk[RUN]
                if run_is_int and bool(run.str.fullmatch(_CANONICAL_RUN).all()):
                    run_int[at:at + k] = run.to_numpy(dtype=np.int64)
                else:
                    if run_is_int:
                        run_text.append(run_int[:at].astype(str).astype(object))
                        run_is_int = False
                    run_text.append(run.to_numpy(dtype=object))
                for n in text:
                    text[n].append(chunk[n].to_numpy(dtype=object))
                at += k
    except (ValueError, TypeError, pd.errors.ParserError, UnicodeDecodeError, OSError, OverflowError):
        return None
    if at != n_rows:
        return None
    out = {}
    for n in names:
        if n in numeric:
            out[n] = cols[n]
        elif n == RUN:
            out[n] = run_int if run_is_int else np.concatenate(run_text)
        else:
            out[n] = np.concatenate(text[n]) if text[n] else np.empty(0, dtype=object)
    return pd.DataFrame(out, copy=False)  # (columns= would copy every column)


def _read_table(path: Path) -> pd.DataFrame:
    """Read a CSV as strings, one DataFrame row per file line after the header."""
    if not path.exists():
        raise DataFormatError(path, None, None, "file not found")
    if path.is_dir():
        raise DataFormatError(path, None, None, "is a directory, not a CSV file")
    fast = _read_fast(path)
    if fast is not None:
        return fast
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataFormatError(path, None, None, f"cannot read file: {exc.strerror or exc}") from None
    kind = binary_kind(raw[:32])
    if kind is not None:
        raise DataFormatError(path, None, None, kind)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        row = line - 1 if line > 1 else None
        raise DataFormatError(path, None, row,
                              f"not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line})") from None
    if not text.strip():
        raise DataFormatError(path, None, None, "file is empty")
    why = header_line_problem(text)
    if why is not None:
        raise DataFormatError(path, None, None, why)
    _check_separator(path, text)
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
    body = table.iloc[1:].reset_index(drop=True)
    drop, why = unnamed_columns(header, body)
    if why is not None:
        raise DataFormatError(path, None, None, why)
    keep = [k for k in range(len(header)) if k not in drop]
    header = [header[k] for k in keep]
    body = body.iloc[:, keep]
    body.columns = header
    _check_body(path, body, header)
    # drop blank lines at the end of the file (blank lines inside are refused
    # later as empty values, so data rows keep mapping to line = row + 1)
    n = len(body)
    while n > 0 and is_blank_row(body.iloc[n - 1]):
        n -= 1
    return body.iloc[:n]


def _check_body(path: Path, body: pd.DataFrame, header: list[str]) -> None:
    """Refuse a units row under the header and a header line repeated inside the data, naming the row."""
    why = units_row(body)
    if why is not None:
        raise DataFormatError(path, None, 1, why)
    k = repeated_header(body, header)
    if k is not None:
        raise DataFormatError(path, None, k + 1, "the header line again inside the data (two files "
                              "concatenated?): one file has one header line, on line 1; delete this line")


def _check_separator(path: Path, text: str) -> None:
    """Refuse a header written with another separator (';' or tab), naming the likely export setting."""
    header = text.lstrip("\ufeff").split("\n", 1)[0]
    if "," in header:
        return
    for sep, name in ((";", "';'"), ("\t", "tab")):
        if sep in header:
            body = text.split("\n", 2)[1] if text.count("\n") >= 1 else ""
            decimal = (" and ',' as decimal mark" if re.search(r"\d,\d", body) else "")
            raise DataFormatError(path, None, None,
                                  f"the header line uses {name} as separator{decimal}? the format requires "
                                  "',' between fields and '.' as decimal point (export as plain CSV, "
                                  "e.g. with an English locale)")


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
    no_value = empty | stripped.str.lower().isin(NAN_TOKENS).to_numpy()
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
                                  f"run {format_value(rid)} has a single sample: speed_m_s is "
                                  "absent and cannot be derived from position")
        with np.errstate(all="ignore"):  # absurd positions overflow to inf, refused as implausible speed
            v[sl] = np.gradient(x[sl], t[sl], edge_order=2 if n >= 3 else 1)
    return v


def unit_findings(df: pd.DataFrame, meta: Mapping, path: Path, side: Path,
                  explicit: Mapping[str, float | None]) -> list[DataFormatError | ParameterError]:
    """Likely unit mistakes of a validated table and its settings, as the errors they raise when not allowed.

    Settings first (an option: :class:`~l1b2.errors.ParameterError`; a
    sidecar field: :class:`~l1b2.errors.DataFormatError` naming the field),
    then the columns in row order (:func:`~l1b2.data.validate.unusual_values`).
    """
    found: list[DataFormatError | ParameterError] = []
    for name in SIDECAR_FIELDS:
        why = unusual_setting(name, meta.get(name))
        if why is None:
            continue
        if explicit.get(name) is not None:
            found.append(ParameterError(f"option {name} [{SIDECAR_FIELDS[name]}]: {why}"))
        elif name in meta.get("sidecar_fields", ()):
            found.append(DataFormatError(side, name, None, why))
    for q in unusual_values(df, speed_derived=bool(meta.get("speed_derived"))):
        found.append(DataFormatError(path, q.column, q.row + 1, q.text))
    for f in physics_findings(df, slider_mass_kg=meta.get("slider_mass_kg")):
        found.append(DataFormatError(path, f.column, f.row + 1, f.text))
    return found


#: appended to a refused likely unit mistake
OVERRIDE_HINT = " (if the values are right, allow them with --allow-unusual-units)"


def _with_override_hint(exc: DataFormatError | ParameterError) -> DataFormatError | ParameterError:
    if isinstance(exc, DataFormatError):
        return DataFormatError(exc.path, exc.column, exc.row, exc.problem + OVERRIDE_HINT)
    return ParameterError(str(exc) + OVERRIDE_HINT)


def read_table_and_sidecar(path: str | os.PathLike, *, slider_mass_kg: float | None = None,
                           encoder_resolution_m: float | None = None,
                           drive_frequency_Hz: float | None = None,
                           allow_unusual_units: bool = False) -> tuple[pd.DataFrame, dict]:
    """Read and validate a measured-data CSV and its sidecar.

    The work of :func:`l1b2.data.measurements.load_measurements` (see there
    for the parameters, the columns and ``meta``), without the container.
    Likely unit mistakes (:func:`unit_findings`) raise the first of them
    unless ``allow_unusual_units``; either way their messages are in
    ``meta["unusual_units"]``.

    Returns
    -------
    df : pandas.DataFrame
        The validated samples (index 0..n-1).
    meta : dict
        The settings and the load-time flags (``gaps_filled``: per optional
        input column with gaps, what was filled).
    """
    path = Path(path)
    table = _read_table(path)
    side = sidecar_path(path)
    sidecar = read_sidecar(side) if side != path else {}
    meta = _merge_settings(sidecar, slider_mass_kg=slider_mass_kg,
                           encoder_resolution_m=encoder_resolution_m,
                           drive_frequency_Hz=drive_frequency_Hz)
    df, meta["gaps_filled"] = validate_frame_filled(table, path)
    del table  # the typed columns are shared with ``df``; the rest is released before the checks below
    for name in df.columns:
        if name not in COLUMN_SPECS:
            df[name] = _infer_extra(df[name])
    meta["speed_derived"] = SPEED not in df.columns
    if meta["speed_derived"]:
        df[SPEED] = _derive_speed(df, path)
    meta["frequency_filled"] = FREQUENCY not in df.columns
    if meta["frequency_filled"]:
        df[FREQUENCY] = np.full(len(df), float(meta["drive_frequency_Hz"]))
    meta["source"] = str(path)
    meta["sidecar"] = str(side) if side != path and side.exists() else None
    explicit = {"slider_mass_kg": slider_mass_kg, "encoder_resolution_m": encoder_resolution_m,
                "drive_frequency_Hz": drive_frequency_Hz}
    found = unit_findings(df, {**meta, "sidecar_fields": tuple(sidecar)}, path, side, explicit)
    if found and not allow_unusual_units:
        raise _with_override_hint(found[0])
    meta["unusual_units"] = [str(e) for e in found]
    meta["allow_unusual_units"] = bool(allow_unusual_units)
    return df.reset_index(drop=True), meta


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
        if key not in payload and key not in LOAD_TIME_META:
            payload[key] = value
    out = {}
    for key, value in payload.items():
        if key in SIDECAR_FIELDS:
            if value is None:
                continue
            why = check_setting(key, value)
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


def write_table_and_sidecar(df: pd.DataFrame, path: str | os.PathLike, meta: Mapping | None = None) -> Path:
    """Validate and write measured data as CSV plus sidecar JSON.

    The work of :func:`l1b2.data.measurements.write_measurements` (see there
    for the parameters and the rules), for a plain DataFrame.
    """
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
