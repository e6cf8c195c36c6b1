"""What DAQ and spreadsheet exports write that the rig data format does not, named in one line.

The format (docs/reference/data-format.md) is one plain CSV: the header on
line 1, ``,`` between fields, numbers on every data line. Exports of real
rigs break it in a few recurring ways that the general checks would name
only by their symptom (``non-numeric value 's'``, ``line has 8 fields, the
header has 1``). Each function here recognises one of them in the text or
the table as read and returns the message that names the cause and the
remedy, or ``None``:

* :func:`binary_kind`: a Parquet, Excel, HDF5, MATLAB, TDMS or gzip file
  given as the CSV (by its leading bytes);
* :func:`header_line_problem`: lines before the header (a DAQ preamble,
  ``#`` comments) or fields separated by spaces;
* :func:`units_row`: a row of units under the header;
* :func:`repeated_header`: the header line again inside the data (two
  files concatenated);
* :func:`unnamed_columns`: a column without a name (a trailing separator
  on every line, harmless and dropped; or pandas' row index, refused);
* :func:`value_hint`: the likely cause of a cell that is no number (a
  decimal comma, a Fortran ``D`` exponent, a unit in the cell, a clock time);
* :func:`time_order_hint`: the likely cause of time stamps that do not
  increase (a clock reset at each run, stamps rounded coarser than the
  sampling interval).

Pure functions of text and tables; :mod:`~l1b2.data.io` raises their
messages as :class:`~l1b2.errors.DataFormatError`.
"""

from __future__ import annotations

import re


import numpy as np
import pandas as pd

from .columns import COLUMN_SPECS, NAN_TOKENS, NUMERIC_COLUMNS, REQUIRED_COLUMNS, RUN, TIME

__all__ = ["binary_kind", "header_line_problem", "units_row", "repeated_header", "unnamed_columns",
           "value_hint", "time_order_hint", "MAX_PREAMBLE_LINES"]

#: leading bytes -> the kind of file they begin
_MAGIC: tuple[tuple[bytes, str], ...] = (
    (b"PAR1", "a Parquet file"),
    (b"PK\x03\x04", "a ZIP archive (an Excel .xlsx workbook?)"),
    (b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1", "an OLE2 file (an Excel .xls workbook?)"),
    (b"\x89HDF\r\n\x1a\n", "an HDF5 file"),
    (b"MATLAB 5.0 MAT-file", "a MATLAB .mat file"),
    (b"TDSm", "a LabVIEW TDMS file"),
    (b"\x1f\x8b", "a gzip-compressed file"),
)

#: lines searched for the header below a preamble
MAX_PREAMBLE_LINES = 100


def binary_kind(head: bytes) -> str | None:
    """The kind of binary file ``head`` (its first bytes) begins, or ``None`` for anything else."""
    for magic, kind in _MAGIC:
        if head.startswith(magic):
            return (f"is {kind}, not CSV text: the format is one plain CSV file (export it as CSV, e.g. "
                    "pandas DataFrame.to_csv(path, index=False))")
    return None


def value_hint(raw: str) -> str:
    """The likely cause of a cell that does not parse as a number, as a parenthesised hint ('' when none)."""
    num = r"[+-]?(?:\d+\.?\d*|\.\d+)"
    if re.fullmatch(r"[+-]?\d+,\d*([eE][+-]?\d+)?", raw):
        return " (decimal comma? the format requires a decimal point)"
    if re.fullmatch(num + r"[dD][+-]?\d+", raw):
        return " (a Fortran 'D' exponent? the format requires 'E', e.g. 1.5E-03)"
    if re.fullmatch(num + r"(?:[eE][+-]?\d+)?\s*[A-Za-z%°µ/]+", raw):
        return " (a unit written into the cell? the unit is part of the column name: write the number alone)"
    if re.fullmatch(r"\d+:\d+(:\d+)?([.,]\d+)?", raw):
        return " (a clock time? time_s is the experiment's clock in seconds, as a number)"
    return ""


def time_order_hint(t: np.ndarray, i: int, run_started: str | None) -> str:
    """The likely cause of ``t[i] <= t[i - 1]``: a clock reset where run ``run_started`` begins (``None``: ``i``
    is inside a run), or equal stamps (too few digits written, or a row twice); '' when neither."""
    if run_started is not None and t[i] < t[i - 1]:
        return (f" at the first row of run {run_started}: is the clock reset at each run? it must run on over the "
                "whole file (slow effects show only on it); if the runs' start times are lost, shift each run to "
                "start after the one before")
    if t[i] == t[i - 1]:
        return " (equal stamps: time_s written with too few digits for the sampling rate, or a row written twice?)"
    return ""


def _is_header(line: str) -> bool:
    names = {f.strip().strip('"') for f in line.split(",")}
    return TIME in names and RUN in names


def header_line_problem(text: str) -> str | None:
    """Lines before the header, or a header separated by spaces; ``None`` when line 1 can be the header.

    A header is a line holding both ``time_s`` and ``run`` as comma-separated
    fields. When line 1 is not one but one of the next
    :data:`MAX_PREAMBLE_LINES` lines is, the lines above it are a preamble;
    a line 1 holding the required names separated by spaces only is a
    space-separated file.
    """
    lines = text.lstrip("\ufeff").splitlines()
    if not lines or _is_header(lines[0]):
        return None
    if lines[0].lstrip().startswith(("{", "[")):
        return "is JSON (the sidecar NAME.json?), not the CSV of samples: give NAME.csv"
    for k, line in enumerate(lines[1:MAX_PREAMBLE_LINES], start=2):
        if _is_header(line):
            return (f"line {k} is the header ({line[:40]!r}...) and the {k - 1} line{'s' if k > 2 else ''} above "
                    f"it (from {lines[0][:40]!r}) are no part of the format, a DAQ preamble?: the header must be "
                    "line 1; delete the lines above it (keep the settings in the sidecar NAME.json)")
    first = lines[0]
    if "," not in first and ";" not in first and "\t" not in first:
        words = set(first.split())
        if len(words & set(REQUIRED_COLUMNS)) >= 2:
            return ("the header line uses spaces as separator? the format requires ',' between fields "
                    "(export as CSV)")
    if first.lstrip().startswith("#"):
        return (f"line 1 is a comment ({first[:40]!r}): the format has no comment lines and no header below "
                "it within the first lines; the header (time_s,run,...) must be line 1")
    return None


def _no_number(cells: pd.Series) -> np.ndarray:
    """Cells holding text that is neither a number nor a gap (empty, a NaN token)."""
    text = cells.astype(str).str.strip()
    gap = (text == "").to_numpy() | text.str.lower().isin(NAN_TOKENS).to_numpy()
    return pd.to_numeric(text, errors="coerce").isna().to_numpy() & ~gap


def units_row(body: pd.DataFrame) -> str | None:
    """A units row as the first data row: in the known numeric columns short texts without digits (unit
    symbols) and no number, numbers in the next row.

    The message lists the units written there and names any that contradict
    the column's own unit (``ms`` under ``time_s``).
    """
    known = [c for c in NUMERIC_COLUMNS if c in body.columns]
    if len(body) < 2 or len(known) < 2:
        return None
    first, second = body.iloc[0], body.iloc[1]
    filled = [c for c in known if str(first[c]).strip()]
    if len(filled) < 2 or not _no_number(first[filled]).all() or _no_number(second[known]).any():
        return None
    units = {c: str(first[c]).strip().strip("[]()") for c in filled}
    if not all(re.fullmatch(r"[^\d]{1,12}|[^\d]{1,10}\^?[23]", u) for u in units.values()):
        return None  # not unit symbols (junk in a data row is named by the value checks)
    other = [f"{units[c]!r} for {c} [{COLUMN_SPECS[c].unit}]" for c in filled
             if units[c].replace("deg", "°").replace("°", "") != COLUMN_SPECS[c].unit.replace("deg", "")]
    shown = ", ".join(f"{c}: {units[c]!r}" for c in filled[:4]) + (", ..." if len(filled) > 4 else "")
    text = (f"a units row under the header? ({shown}) the units are part of the column names in the format "
            "(time_s is in s): delete the row")
    if other:
        text += f"; it gives {', '.join(other)}: convert those values to the unit of the column name"
    return text


def repeated_header(body: pd.DataFrame, header: list[str]) -> int | None:
    """0-based row of the first data row that repeats the header line (files concatenated), or ``None``."""
    if not len(body) or not header:
        return None
    same = np.ones(len(body), dtype=bool)
    for k, name in enumerate(header[:3]):
        same &= (body.iloc[:, k].astype(str).str.strip().str.strip('"') == name).to_numpy()
    idx = np.flatnonzero(same)
    return int(idx[0]) if idx.size else None


def unnamed_columns(raw_header: list[str], body: pd.DataFrame) -> tuple[list[int], str | None]:
    """Columns without a name: the empty ones to drop, and the message for one that holds values.

    A column with an empty name and no value in any row is what a trailing
    separator on every line leaves (nothing is in it, so nothing is lost
    when it is dropped). An unnamed column with values (pandas' row index,
    written by ``to_csv`` without ``index=False``) is refused: the close loop
    would take it as a measured channel.

    Returns
    -------
    drop : list of int
        Positions of the empty unnamed columns.
    problem : str or None
        The message for the first unnamed column with values.
    """
    drop: list[int] = []
    for k, name in enumerate(raw_header):
        if str(name).strip():
            continue
        cells = body.iloc[:, k].astype(str).str.strip()
        if (cells == "").all():
            drop.append(k)
            continue
        return drop, (f"column {k + 1} of the header has no name but holds values (first {cells.iloc[0]!r}): "
                      "a row index written by pandas to_csv without index=False? every column needs a name; "
                      "leave it out or name it")
    return drop, None
