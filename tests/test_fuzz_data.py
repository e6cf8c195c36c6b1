"""Property-based fuzzing of the data contract through ``l1b2 identify`` (issue 14).

Random corruptions of a valid measured-data file (and its sidecar): unit
mistakes, bad cells, broken lines and headers, other separators. For every
one, ``l1b2 identify`` must end with exactly one line ``l1b2: error: ...``
(never a traceback nor an "internal error"), write nothing, and refuse every
unit mistake before the fit. The fit itself is replaced by a sentinel that
fails, so an accepted file is recognised without running it.
"""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from l1b2.cli import main as cli_main
from l1b2.errors import IdentificationError
from l1b2.predictor.model import example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset

SENTINEL = "FIT-REACHED"


def _base():
    df = simulate_dataset(example_params(3), design_grid(voltages=(250.0, 324.0), loads=(0.03,)), 0.1,
                          noise_std=1e-4, seed=3)
    return df.assign(frequency_Hz=48500.0, temperature_C=25.0)


BASE = _base()
BASE_TEXT = BASE.to_csv(index=False, lineterminator="\n")
SIDECAR = {"slider_mass_kg": 0.1, "encoder_resolution_m": 5e-8}

#: unit mistakes the contract promises to catch: (column or sidecar field, transformation)
UNIT_MISTAKES = {
    "time in ms": ("time_s", lambda x: x * 1e3),
    "position in mm": ("position_m", lambda x: x * 1e3),
    "position in cm": ("position_m", lambda x: x * 1e2),
    "position x10": ("position_m", lambda x: x * 10.0),
    "load in g": ("load_kg", lambda x: x * 1e3),
    "voltage in kV": ("voltage_V", lambda x: x * 1e-3),
    "voltage in mV": ("voltage_V", lambda x: x * 1e3),
    "speed in mm/s": ("speed_m_s", lambda x: x * 1e3),
    "speed in m/ms": ("speed_m_s", lambda x: x * 1e-3),
    "speed unsigned": ("speed_m_s", np.abs),
    "frequency in kHz": ("frequency_Hz", lambda x: x * 1e-3),
    "temperature in K": ("temperature_C", lambda x: x + 273.15),
    "slider mass in g": ("slider_mass_kg", lambda x: x * 1e3),
}

CELL_TEXT = st.one_of(
    st.sampled_from(["", "nan", "NaN", "inf", "-inf", "1,5", "abc", "1e308", "-1e308", "0", "-1", "2", "1e-300",
                     " ", "\"", "'x'", "0x10", "1_000", "--1", "1e", "∞", "\u00a0", "TRUE"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(max_size=6),
)


@st.composite
def corruptions(draw):
    """(kind, text, sidecar, is_unit_mistake) of one corrupted file."""
    lines = BASE_TEXT.split("\n")
    header = lines[0].split(",")
    kind = draw(st.sampled_from(["unit", "cell", "delete_line", "duplicate_line", "swap_lines", "truncate_line",
                                 "blank_line", "drop_column", "rename_column", "separator", "bom", "empty",
                                 "header_only", "nul_byte"]))
    sidecar = dict(SIDECAR)
    if kind == "unit":
        name = draw(st.sampled_from(sorted(UNIT_MISTAKES)))
        col, f = UNIT_MISTAKES[name]
        if col in sidecar:
            sidecar[col] = float(f(sidecar[col]))
            return name, BASE_TEXT, sidecar, True
        df = BASE.copy()
        df[col] = f(df[col].to_numpy())
        return name, df.to_csv(index=False, lineterminator="\n"), sidecar, True
    body = lines[1:-1]
    k = draw(st.integers(0, len(body) - 1))
    if kind == "cell":
        j = draw(st.integers(0, len(header) - 1))
        cells = body[k].split(",")
        cells[j] = draw(CELL_TEXT).replace("\n", " ").replace(",", ";")
        body[k] = ",".join(cells)
    elif kind == "delete_line":
        del body[k]
    elif kind == "duplicate_line":
        body.insert(k, body[k])
    elif kind == "swap_lines":
        m = draw(st.integers(0, len(body) - 1))
        body[k], body[m] = body[m], body[k]
    elif kind == "truncate_line":
        body[k] = body[k][: draw(st.integers(0, max(len(body[k]) - 1, 0)))]
    elif kind == "blank_line":
        body.insert(k, "")
    elif kind in ("drop_column", "rename_column"):
        j = draw(st.integers(0, len(header) - 1))
        if kind == "drop_column":
            header = header[:j] + header[j + 1:]
            body = [",".join(c for i, c in enumerate(line.split(",")) if i != j) for line in body]
        else:
            header[j] = draw(st.sampled_from([header[j].upper(), header[j].split("_")[0] + "_mm", "", "x"]))
    elif kind == "separator":
        sep = draw(st.sampled_from([";", "\t", " "]))
        header = [sep.join(header)]
        body = [line.replace(",", sep) for line in body]
        if draw(st.booleans()):
            body = [line.replace(".", ",") for line in body]
    elif kind == "bom":
        return kind, "\ufeff" + BASE_TEXT, sidecar, False
    elif kind == "empty":
        return kind, "", sidecar, False
    elif kind == "header_only":
        return kind, lines[0] + "\n", sidecar, False
    elif kind == "nul_byte":
        body[k] = body[k][:3] + "\x00" + body[k][3:]
    return kind, "\n".join([",".join(header)] + body) + "\n", sidecar, False


def _sentinel_fit(self, *args, **kwargs):
    raise IdentificationError(SENTINEL)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(corruptions())
def test_corrupted_files_never_traceback_write_or_pass_a_unit_mistake(case):
    kind, text, sidecar, unit_mistake = case
    from l1b2.ident import estimator
    with tempfile.TemporaryDirectory() as d, pytest.MonkeyPatch.context() as mp:
        mp.setattr(estimator.PredictorIdentifier, "fit", _sentinel_fit)
        mp.delenv("L1B2_TRACEBACK", raising=False)
        folder = Path(d)
        data = folder / "data.csv"
        data.write_text(text, encoding="utf-8")
        (folder / "data.json").write_text(json.dumps(sidecar))
        out = folder / "out"
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli_main(["identify", "--train", str(data), "--out", str(out), "--no-plots"])
        msg = err.getvalue()
        assert code != 0, (kind, msg)
        assert msg.count("\n") == 1 and msg.startswith("l1b2: error:"), (kind, msg)
        assert "internal error" not in msg and "Traceback" not in msg, (kind, msg)
        assert sorted(p.name for p in folder.iterdir()) == ["data.csv", "data.json"], kind  # nothing written
        if unit_mistake:
            assert SENTINEL not in msg, f"unit mistake '{kind}' was accepted"


def test_the_uncorrupted_file_reaches_the_fit():
    # the fuzzing's baseline: the valid file passes every check and reaches the (sentinel) fit
    with tempfile.TemporaryDirectory() as d, pytest.MonkeyPatch.context() as mp:
        from l1b2.ident import estimator
        mp.setattr(estimator.PredictorIdentifier, "fit", _sentinel_fit)
        folder = Path(d)
        (folder / "data.csv").write_text(BASE_TEXT)
        (folder / "data.json").write_text(json.dumps(SIDECAR))
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli_main(["identify", "--train", str(folder / "data.csv"), "--out", str(folder / "out")])
        assert code != 0 and SENTINEL in err.getvalue()
        assert not (folder / "out").exists()
