#!/usr/bin/env python
"""Rig files as a DAQ or a spreadsheet really writes them, against ``l1b2 identify`` (decision 0115).

Takes a rig data set in the data format (a folder with ``train.csv``,
``test.csv`` and their sidecars, e.g. a realistic-world audit set of
``bench/blind_effects.py clean 1``), writes one variant per case (a units
row, CRLF line ends, a DAQ preamble, ...) and runs the console command on it
in a subprocess, exactly as a user would. Per case it prints one row:

    case | rc | the last line printed to stderr | result

where *result* compares what was read (``load_measurements`` in this
process) with the clean file: ``same data`` (every sample as in the clean
file), ``DIFFERENT: ...`` (accepted but read otherwise: a silent wrong
result), ``refused`` or ``traceback``.

Usage::

    python bench/hostile_rig_files.py --rig DIR [--work DIR] [--only 'CASE|...']
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from l1b2.data.measurements import load_measurements
from l1b2.errors import L1B2Error

FAST = ["--order", "3", "--starts", "1", "--no-plots", "--quiet"]
L1B2 = str(Path(sys.executable).with_name("l1b2"))


def _lines(text: str) -> list[str]:
    return text.rstrip("\n").split("\n")


def _join(lines: list[str], end: str = "\n") -> str:
    return end.join(lines) + end


def _units_row(t: str) -> str:
    ls = _lines(t)
    units = {"time_s": "s", "run": "-", "position_m": "m", "voltage_V": "V", "direction": "-", "load_kg": "kg",
             "speed_m_s": "m/s", "frequency_Hz": "Hz", "temperature_C": "degC"}
    return _join([ls[0], ",".join(units.get(h, "") for h in ls[0].split(","))] + ls[1:])


def _map_cells(t: str, f) -> str:
    ls = _lines(t)
    return _join([ls[0]] + [",".join(f(c) for c in ln.split(",")) for ln in ls[1:]])


def _rename(t: str, f) -> str:
    ls = _lines(t)
    return _join([",".join(f(h) for h in ls[0].split(","))] + ls[1:])


def _reorder(t: str) -> str:
    rows = [ln.split(",") for ln in _lines(t)]
    k = list(reversed(range(len(rows[0]))))
    return _join([",".join(r[i] for i in k) for r in rows])


def _col(t: str, name: str, f) -> str:
    ls = _lines(t)
    j = ls[0].split(",").index(name)
    out = [ls[0]]
    for ln in ls[1:]:
        c = ln.split(",")
        c[j] = f(c[j])
        out.append(",".join(c))
    return _join(out)


def _concat_with_header(t: str) -> str:
    ls = _lines(t)
    half = 1 + (len(ls) - 1) // 2
    while ls[half].split(",")[1] == ls[half - 1].split(",")[1]:
        half += 1
    return _join(ls[:half] + [ls[0]] + ls[half:])


def _preamble(t: str) -> str:
    return _join(["# DAQ export 2026-12-02 10:14:03", "# rate: 1000 Hz"]) + t


def _per_run_time(t: str) -> str:
    ls = _lines(t)
    out, t0, last = [ls[0]], None, None
    for ln in ls[1:]:
        c = ln.split(",")
        if c[1] != last:
            t0, last = float(c[0]), c[1]
        c[0] = repr(round(float(c[0]) - t0, 6))
        out.append(",".join(c))
    return _join(out)


def _pandas_index(t: str) -> str:
    ls = _lines(t)
    return _join(["," + ls[0]] + [f"{k},{ln}" for k, ln in enumerate(ls[1:])])


def _string_runs(t: str) -> str:
    return _col(t, "run", lambda r: f"run_{int(r):02d}")


def _float_runs(t: str) -> str:
    return _col(t, "run", lambda r: f"{int(r)}.0")


def _epoch(t: str) -> str:
    return _col(t, "time_s", lambda x: f"{1764669600 + float(x):.6f}")


def _space_separated(t: str) -> str:
    return t.replace(",", " ")


def _short_run(t: str, n: int) -> str:
    ls = _lines(t)
    run0 = ls[1].split(",")[1]
    body = [ln for ln in ls[1:] if ln.split(",")[1] == run0][:n]
    rest = [ln for ln in ls[1:] if ln.split(",")[1] != run0]
    return _join([ls[0]] + body + rest)


def _still_run(t: str) -> str:
    ls = _lines(t)
    h = ls[0].split(",")
    jr, jx = h.index("run"), h.index("position_m")
    js = h.index("speed_m_s") if "speed_m_s" in h else None
    run0, x0 = ls[1].split(",")[jr], ls[1].split(",")[jx]
    out = [ls[0]]
    for ln in ls[1:]:
        c = ln.split(",")
        if c[jr] == run0:
            c[jx] = x0
            if js is not None:
                c[js] = "0.0"
        out.append(",".join(c))
    return _join(out)


def _parquet(t: str) -> bytes:
    import io
    import pandas as pd
    buf = io.BytesIO()
    pd.read_csv(io.StringIO(t)).to_parquet(buf)
    return buf.getvalue()


def _footer(t: str) -> str:
    return t + "END OF DATA\n"


CASES = {
    "units row under the header": _units_row,
    "CRLF line ends": lambda t: t.replace("\n", "\r\n"),
    "CR line ends (old Mac)": lambda t: t.replace("\n", "\r"),
    "UTF-8 BOM + CRLF": lambda t: "\ufeff" + t.replace("\n", "\r\n"),
    "trailing empty column": lambda t: _join([ln + "," for ln in _lines(t)]),
    "quoted numbers": lambda t: _map_cells(t, lambda c: f'"{c}"'),
    "quoted header": lambda t: _rename(t, lambda h: f'"{h}"'),
    "spaces around names": lambda t: _rename(t, lambda h: f" {h} "),
    "spaces around cells": lambda t: _map_cells(t, lambda c: f" {c} "),
    "names in upper case": lambda t: _rename(t, str.upper),
    "names with bracketed units": lambda t: _rename(t, lambda h: h.replace("_s", " [s]", 1) if h == "time_s" else h),
    "columns in reverse order": _reorder,
    "Fortran D exponent": lambda t: _col(t, "time_s", lambda x: f"{float(x):.6E}".replace("E", "D")),
    "E exponent": lambda t: _col(t, "time_s", lambda x: f"{float(x):.9E}"),
    "Excel #DIV/0! in position": lambda t: t.replace(_lines(t)[5].split(",")[2], "#DIV/0!", 1),
    "run ids run_NN": _string_runs,
    "run ids 1.0 (float export)": _float_runs,
    "clock reset at each run": _per_run_time,
    "epoch time stamps": _epoch,
    "time in ms, column time_ms": lambda t: _rename(_col(t, "time_s", lambda x: repr(round(float(x) * 1e3, 6))),
                                                     lambda h: "time_ms" if h == "time_s" else h),
    "time in ms, column time_s": lambda t: _col(t, "time_s", lambda x: repr(round(float(x) * 1e3, 6))),
    "pandas index column": _pandas_index,
    "two files concatenated (header twice)": _concat_with_header,
    "DAQ preamble lines": _preamble,
    "footer line": _footer,
    "space separated": _space_separated,
    "semicolon + decimal comma": lambda t: t.replace(",", ";").replace(".", ","),
    "a run of 1 sample": lambda t: _short_run(t, 1),
    "a run of 2 samples": lambda t: _short_run(t, 2),
    "a run of 3 samples": lambda t: _short_run(t, 3),
    "a run that never moves": _still_run,
    "position 1e300 in one cell": lambda t: t.replace(_lines(t)[5].split(",")[2], "1e300", 1),
    "a JSON file given as the CSV": lambda t: '{"slider_mass_kg": 0.12}\n',
    "time rounded to 10 ms (1 kHz samples)": lambda t: _col(t, "time_s", lambda x: f"{float(x):.2f}"),
    "a unit in the cells (220.0 V)": lambda t: _col(t, "voltage_V", lambda x: x + " V"),
    "clock time hh:mm:ss.fff": lambda t: _col(t, "time_s", lambda x: f"00:{int(float(x) // 60):02d}:"
                                                                         f"{float(x) % 60:06.3f}"),
    "units row with mm, g, kHz": lambda t: _units_row(t).replace("s,-,m,V,-,kg,m/s,Hz", "s,-,mm,V,-,g,mm/s,kHz", 1),
    "Parquet file": _parquet,
    "empty file": lambda t: "",
    "header only": lambda t: _lines(t)[0] + "\n",
}


#: cases that change the data on purpose: accepted means read as written, not as the clean file
CHANGED = {"a run of 1 sample", "a run of 2 samples", "a run of 3 samples", "a run that never moves"}


def run(argv: list[str]) -> tuple[int, str]:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    p = subprocess.run([L1B2, *argv], capture_output=True, text=True, env=env)
    err = [ln for ln in p.stderr.splitlines() if ln.strip()]
    tb = "Traceback" in p.stderr or "internal error" in p.stderr
    line = err[-1] if err else (p.stdout.splitlines()[-1] if p.stdout.strip() else "")
    return p.returncode, ("TRACEBACK " if tb else "") + line


def compare(path: Path, clean) -> str:
    try:
        m = load_measurements(path)
    except L1B2Error:
        return "refused"
    except Exception as exc:  # noqa: BLE001 - a bug is what we look for
        return f"traceback ({type(exc).__name__})"
    a, b = m.df, clean.df
    if len(a) != len(b) or len(m.runs) != len(clean.runs):
        return f"DIFFERENT: {len(a)} samples in {len(m.runs)} runs (clean: {len(b)} in {len(clean.runs)})"
    for c in ("time_s", "position_m", "voltage_V", "direction", "load_kg", "speed_m_s"):
        x, y = a[c].to_numpy(dtype=float), b[c].to_numpy(dtype=float)
        if c == "time_s":
            x, y = np.diff(x), np.diff(y)
        if not np.allclose(x, y, rtol=1e-6, atol=1e-6 if c == "time_s" else 1e-9):
            return f"DIFFERENT: {c}"
    extra = sorted(set(a.columns) - set(b.columns))
    return "same data" + (f" (+ columns {extra})" if extra else "")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", type=Path, required=True, help="folder with train.csv/train.json")
    ap.add_argument("--work", type=Path, default=None)
    ap.add_argument("--only", default="")
    args = ap.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="hostile_"))
    text = (args.rig / "train.csv").read_text()
    side = (args.rig / "train.json").read_text()
    clean = load_measurements(args.rig / "train.csv")
    only = [c for c in args.only.split("|") if c]
    for k, (name, f) in enumerate(CASES.items()):
        if only and name not in only:
            continue
        d = work / f"case{k:02d}"
        shutil.rmtree(d, ignore_errors=True)
        d.mkdir(parents=True)
        path = d / "train.csv"
        data = f(text)
        path.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8"))
        (d / "train.json").write_text(side)
        rc, line = run(["identify", "--train", str(path), "--out", str(d / "out"), *FAST])
        line = line.replace(str(d) + os.sep, "")
        result = compare(path, clean)
        if name in CHANGED and result.startswith("DIFFERENT"):
            result = "read as written (changed on purpose)"
        print(json.dumps({"case": name, "rc": rc, "line": line, "result": result}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
