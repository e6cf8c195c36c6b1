"""Tests of the data layer (l1b2.data.measurements and the columns / validate / io modules behind it).

The measured-data contract of the rig data format (docs/reference/data-format.md), exercised through the
public API :mod:`l1b2.data.measurements`.
"""

from __future__ import annotations

import json
import pickle

import numpy as np
import pandas as pd
import pytest
from l1b2.data import measurements as D
from l1b2.data.measurements import (
    Measurements,
    load_measurements,
    split_by_load,
    write_measurements,
)
from l1b2.errors import DataFormatError, IdentificationError, L1B2Error, ParameterError
from l1b2.units import COLUMN_UNITS, SIDECAR_FIELD_UNITS

COLUMNS = ["time_s", "run", "position_m", "voltage_V", "direction", "load_kg",
           "speed_m_s", "frequency_Hz", "temperature_C"]


def good_rows() -> list[dict]:
    """Six valid samples, two runs (run 1 forward unloaded, run 2 backward loaded)."""
    rows = []
    for k in range(6):
        first = k < 3
        rows.append({
            "time_s": repr(0.001 * k),
            "run": "1" if first else "2",
            "position_m": repr(1e-4 * (k if first else -(k - 3))),
            "voltage_V": "100",
            "direction": "1" if first else "-1",
            "load_kg": "0" if first else "0.05",
            "speed_m_s": "0.1" if first else "-0.1",
            "frequency_Hz": "48500",
            "temperature_C": "25",
        })
    return rows


def to_csv_text(rows: list[dict], columns: list[str] | None = None) -> str:
    columns = columns or list(rows[0])
    lines = [",".join(columns)]
    lines += [",".join(r[c] for c in columns) for r in rows]
    return "\n".join(lines) + "\n"


def write_csv(tmp_path, rows, columns=None, name="data.csv"):
    path = tmp_path / name
    path.write_text(to_csv_text(rows, columns))
    return path


def assert_names(exc: DataFormatError, path, column: str | None, unit: str | None,
                 row: int | None) -> None:
    """The message names file, column with unit and row/line."""
    msg = str(exc)
    assert path.name in msg
    if column is not None:
        assert f"'{column}' [{unit}]" in msg, msg
        assert exc.column == column
    if row is None:
        assert exc.row is None
        assert " row " not in msg, msg
    else:
        assert exc.row == row
        assert f"row {row} (line {row + 1})" in msg, msg


# --------------------------------------------------------------------------
# Refusal rules: one parametrised case per rule, for reading AND writing
# --------------------------------------------------------------------------

# (id, column, 1-based row, bad text, unit, expected fragment of the message)
BAD_VALUES = [
    ("non_numeric", "position_m", 3, "abc", "m", "non-numeric value 'abc'"),
    ("decimal_comma", "voltage_V", 2, '"1,5"', "V", "decimal comma"),
    ("empty_required", "voltage_V", 2, "", "V", "empty value"),
    ("nan_required", "load_kg", 4, "nan", "kg", "NaN value"),
    ("inf_required", "position_m", 5, "inf", "m", "infinite value"),
    ("nan_optional_speed", "speed_m_s", 5, "NaN", "m/s", "NaN value"),
    ("text_optional_freq", "frequency_Hz", 2, "off", "Hz", "non-numeric value 'off'"),
    ("text_optional_temp", "temperature_C", 6, "open", "degC", "non-numeric value 'open'"),
    ("empty_run", "run", 3, "", "-", "empty run id"),
    ("time_decreasing", "time_s", 3, "0.0005", "s",
     "time not increasing (0.0005 after 0.001)"),
    ("time_equal", "time_s", 2, "0.0", "s", "time not increasing (0 after 0)"),
    ("direction_zero", "direction", 2, "0", "-", "direction must be exactly +1 or -1"),
    ("direction_fraction", "direction", 5, "-0.5", "-", "direction must be exactly +1 or -1"),
    ("direction_two", "direction", 1, "2", "-", "direction must be exactly +1 or -1"),
    ("position_mm", "position_m", 4, "12.5", "m", "suggests millimetres"),
    ("speed_mm_s", "speed_m_s", 2, "100", "m/s", "suggests mm/s"),
    ("voltage_negative", "voltage_V", 3, "-1", "V", "negative"),
    ("voltage_too_high", "voltage_V", 6, "2500", "V", "implausible"),
    ("load_too_heavy", "load_kg", 5, "-60", "kg", "implausible"),
    ("frequency_khz", "frequency_Hz", 2, "48.5", "Hz", "suggests kHz"),
    ("frequency_too_high", "frequency_Hz", 3, "2e6", "Hz", "implausible"),
    ("temperature_too_low", "temperature_C", 2, "-150", "degC", "implausible"),
    ("temperature_too_high", "temperature_C", 4, "350", "degC", "implausible"),
]


@pytest.mark.parametrize("case", BAD_VALUES, ids=[c[0] for c in BAD_VALUES])
def test_load_refuses_bad_value(tmp_path, case):
    _, column, row, text, unit, fragment = case
    rows = good_rows()
    rows[row - 1][column] = text
    path = write_csv(tmp_path, rows)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, column, unit, row)
    assert fragment in str(info.value)


def _bad_frame(tmp_path, column, row, text) -> pd.DataFrame:
    """Typed DataFrame of the good data with one bad value."""
    df = load_measurements(write_csv(tmp_path, good_rows(), name="good.csv")).df
    df = df.astype({column: object})
    value = text.strip('"')
    try:
        value = float(value)
    except ValueError:
        pass
    df.iloc[row - 1, df.columns.get_loc(column)] = value
    return df


@pytest.mark.parametrize("case", BAD_VALUES, ids=[c[0] for c in BAD_VALUES])
def test_write_refuses_bad_value_and_writes_nothing(tmp_path, case):
    _, column, row, text, unit, fragment = case
    df = _bad_frame(tmp_path, column, row, text)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "out.csv"
    with pytest.raises(DataFormatError) as info:
        write_measurements(df, out, {"slider_mass_kg": 0.1})
    assert_names(info.value, out, column, unit, row)
    assert fragment.strip('"').split(" (")[0].split(" '")[0] in str(info.value)
    assert list(out_dir.iterdir()) == []


def test_run_not_contiguous(tmp_path):
    rows = good_rows()
    rows[4]["run"] = "1"  # runs 1,1,1,2,1,2
    path = write_csv(tmp_path, rows)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, "run", "-", 5)
    assert "run 1 reappears after run 2" in str(info.value)
    df = load_measurements(write_csv(tmp_path, good_rows(), name="ok.csv")).df
    df.loc[4, "run"] = 1
    with pytest.raises(DataFormatError) as info:
        write_measurements(df, tmp_path / "out.csv")
    assert_names(info.value, tmp_path / "out.csv", "run", "-", 5)
    assert not (tmp_path / "out.csv").exists() and not (tmp_path / "out.json").exists()


def test_time_reset_between_runs_is_refused(tmp_path):
    rows = good_rows()
    for k, row in enumerate(rows[3:]):
        row["time_s"] = repr(0.001 * k)  # clock restarted at run 2
    path = write_csv(tmp_path, rows)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, "time_s", "s", 4)


def test_earliest_offending_row_is_reported(tmp_path):
    rows = good_rows()
    rows[3]["position_m"] = "5"   # row 4
    rows[1]["direction"] = "0"    # row 2, other column
    path = write_csv(tmp_path, rows)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, "direction", "-", 2)


@pytest.mark.parametrize("column", list(D.REQUIRED_COLUMNS))
def test_missing_required_column(tmp_path, column):
    rows = good_rows()
    columns = [c for c in COLUMNS if c != column]
    path = write_csv(tmp_path, rows, columns)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, column, D.unit_of(column), None)
    assert "missing required column" in str(info.value)
    df = load_measurements(write_csv(tmp_path, rows, name="ok.csv")).df.drop(columns=column)
    with pytest.raises(DataFormatError):
        write_measurements(df, tmp_path / "out.csv")
    assert not (tmp_path / "out.csv").exists() and not (tmp_path / "out.json").exists()


def test_missing_column_hints_at_non_si_name(tmp_path):
    columns = ["position_mm" if c == "position_m" else c for c in COLUMNS]
    rows = [{("position_mm" if k == "position_m" else k): v for k, v in r.items()}
            for r in good_rows()]
    path = write_csv(tmp_path, rows, columns)
    with pytest.raises(DataFormatError, match="position_mm"):
        load_measurements(path)


def test_missing_file(tmp_path):
    path = tmp_path / "nothere.csv"
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, None, None, None)
    assert "not found" in str(info.value)


@pytest.mark.parametrize("text, fragment", [("", "empty"), ("\n  \n", "empty"),
                                            (",".join(COLUMNS) + "\n", "no data rows")])
def test_empty_file(tmp_path, text, fragment):
    path = tmp_path / "data.csv"
    path.write_text(text)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert path.name in str(info.value) and fragment in str(info.value)


def test_unreadable_not_utf8(tmp_path):
    path = tmp_path / "data.csv"
    path.write_bytes(to_csv_text(good_rows()).encode() + b"\xff\xfe,\x00\n")
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, None, None, 7)
    assert "UTF-8" in str(info.value)


def test_ragged_row_names_its_line(tmp_path):
    text = to_csv_text(good_rows()).splitlines()
    text[3] += ",extra"
    path = tmp_path / "data.csv"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, None, None, 3)


def test_blank_line_inside_is_refused_trailing_blank_lines_ignored(tmp_path):
    text = to_csv_text(good_rows()).splitlines()
    path = tmp_path / "data.csv"
    path.write_text("\n".join(text[:3] + [""] + text[3:]) + "\n")
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, None, None, 3)
    assert "blank line" in str(info.value)
    path.write_text("\n".join(text) + "\n\n\n")
    assert load_measurements(path).n_samples == 6


def test_duplicate_column(tmp_path):
    path = tmp_path / "data.csv"
    path.write_text(to_csv_text(good_rows()).replace("temperature_C", "time_s", 1))
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, "time_s", "s", None)
    assert "duplicate" in str(info.value)


def test_error_is_project_error_and_picklable(tmp_path):
    exc = DataFormatError(tmp_path / "x.csv", "position_m", 3, "bad")
    assert isinstance(exc, L1B2Error)
    again = pickle.loads(pickle.dumps(exc))
    assert str(again) == str(exc) == f"{tmp_path / 'x.csv'}: column 'position_m' [m], row 3 (line 4): bad"


# --------------------------------------------------------------------------
# Sidecar and precedence
# --------------------------------------------------------------------------

@pytest.mark.parametrize("content, field, fragment", [
    ("{not json", None, "invalid JSON"),
    ("[1, 2]", None, "JSON object"),
    ('{"slider_mass_kg": "heavy"}', "slider_mass_kg", "must be a number"),
    ('{"slider_mass_kg": -0.1}', "slider_mass_kg", "positive"),
    ('{"slider_mass_kg": 0}', "slider_mass_kg", "positive"),
    ('{"slider_mass_kg": true}', "slider_mass_kg", "must be a number"),
    ('{"encoder_resolution_m": NaN}', "encoder_resolution_m", "finite"),
    ('{"drive_frequency_Hz": 48.5}', "drive_frequency_Hz", "suggests kHz"),
    ('{"description": 5}', "description", "string"),
])
def test_malformed_sidecar(tmp_path, content, field, fragment):
    path = write_csv(tmp_path, good_rows())
    side = tmp_path / "data.json"
    side.write_text(content)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    msg = str(info.value)
    assert "data.json" in msg and fragment in msg, msg
    if field is not None:
        assert f"field '{field}' [{D.SIDECAR_FIELDS[field]}]" in msg


def test_precedence_keyword_over_sidecar_over_default(tmp_path):
    rows = good_rows()
    columns = [c for c in COLUMNS if c != "frequency_Hz"]
    path = write_csv(tmp_path, rows, columns)

    meta = load_measurements(path).meta  # defaults only
    assert meta["slider_mass_kg"] is None
    assert meta["encoder_resolution_m"] == D.DEFAULT_ENCODER_RESOLUTION_M == 5e-8
    assert meta["drive_frequency_Hz"] == D.DEFAULT_DRIVE_FREQUENCY_HZ == 48500
    assert meta["sidecar"] is None and meta["source"] == str(path)

    (tmp_path / "data.json").write_text(json.dumps(
        {"slider_mass_kg": 0.2, "drive_frequency_Hz": 40000, "description": "rig A",
         "operator": "kim"}))
    meas = load_measurements(path, slider_mass_kg=0.3)
    assert meas.meta["slider_mass_kg"] == 0.3          # keyword wins
    assert meas.meta["drive_frequency_Hz"] == 40000     # sidecar over default
    assert meas.meta["encoder_resolution_m"] == 5e-8    # default
    assert meas.meta["description"] == "rig A"
    assert meas.meta["operator"] == "kim"               # extra field kept
    assert meas.meta["frequency_filled"] is True
    assert (meas.df["frequency_Hz"] == 40000).all()

    meas = load_measurements(path, drive_frequency_Hz=50000, encoder_resolution_m=1e-7)
    assert meas.meta["slider_mass_kg"] == 0.2
    assert meas.meta["drive_frequency_Hz"] == 50000
    assert meas.meta["encoder_resolution_m"] == 1e-7
    assert (meas.df["frequency_Hz"] == 50000).all()


def test_measured_frequency_is_not_overridden(tmp_path):
    rows = good_rows()
    for r in rows:
        r["frequency_Hz"] = "47000"
    meas = load_measurements(write_csv(tmp_path, rows), drive_frequency_Hz=50000)
    assert meas.meta["frequency_filled"] is False
    assert (meas.df["frequency_Hz"] == 47000).all()


@pytest.mark.parametrize("kwargs", [{"slider_mass_kg": -1.0}, {"encoder_resolution_m": 0.0},
                                    {"drive_frequency_Hz": 48.5}])
def test_bad_keyword_is_parameter_error(tmp_path, kwargs):
    path = write_csv(tmp_path, good_rows())
    with pytest.raises(ParameterError, match=next(iter(kwargs))):
        load_measurements(path, **kwargs)


# --------------------------------------------------------------------------
# Round trip, container API
# --------------------------------------------------------------------------

def awkward_frame() -> pd.DataFrame:
    n = 8
    t = 1.0e5 + np.cumsum(np.full(n, 1e-4)) + np.array([0, 1e-12, 0, 0, 3e-13, 0, 0, 0])
    return pd.DataFrame({
        "comment": ["a", "b, with comma", "", "d", "e", "f", "g", "h"],
        "time_s": t,
        "run": ["up-1", "up-1", "up-1", "up-1", "down 2", "down 2", "down 2", "down 2"],
        "position_m": [0.0, 0.1 + 0.2, 1 / 3, 2 / 3, 1e-17, -1e-9, -2.5e-3, -0.123456789012345],
        "voltage_V": [120.0] * 4 + [87.654321] * 4,
        "direction": [1, 1, 1, 1, -1, -1, -1, -1],
        "load_kg": [0.0] * 4 + [-0.05] * 4,
        "speed_m_s": [0.01, 0.02 / 3, 0.03, 0.04, -0.01, -0.02, -np.pi / 100, -0.04],
        "current_A": [0.1, np.nan, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8],
        "cycle": [1, 2, 3, 4, 5, 6, 7, 8],
        "temperature_C": [25.5] * n,
    })


def test_round_trip_with_extra_columns_and_string_runs(tmp_path):
    df = awkward_frame()
    df.loc[2, "comment"] = np.nan  # empty text cell reads back as missing
    meta = {"slider_mass_kg": 0.123, "encoder_resolution_m": 1e-7,
            "drive_frequency_Hz": 45678.9, "description": "round trip", "rig": {"id": 3}}
    path = write_measurements(df, tmp_path / "rt.csv", meta)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rt.csv", "rt.json"]  # no temp files

    # the awkward frame is deliberately unphysical (0.3 m jumps in 0.1 ms): unit plausibility is
    # tested in test_units_plausibility.py; here only the round trip
    meas = load_measurements(path, allow_unusual_units=True)
    assert list(meas.df.columns)[:len(df.columns)] == list(df.columns)  # order kept
    pd.testing.assert_frame_equal(meas.df[list(df.columns)], df)     # bit-exact floats
    assert meas.runs == ["up-1", "down 2"]
    assert meas.meta["frequency_filled"] is True and meas.meta["speed_derived"] is False
    for key, value in meta.items():
        assert meas.meta[key] == value

    # second round trip through the Measurements object itself
    path2 = write_measurements(meas, tmp_path / "rt2.csv")
    assert "frequency_Hz" not in path2.read_text().splitlines()[0]  # filled, not measured
    again = load_measurements(path2, allow_unusual_units=True)
    pd.testing.assert_frame_equal(again.df, meas.df)


def test_round_trip_integer_runs_and_derived_speed(tmp_path):
    rows = good_rows()
    columns = [c for c in COLUMNS if c != "speed_m_s"]
    meas = load_measurements(write_csv(tmp_path, rows, columns))
    assert meas.df["run"].dtype == np.int64 and meas.runs == [1, 2]
    assert meas.meta["speed_derived"] is True
    out = write_measurements(meas, tmp_path / "out.csv")
    assert "speed_m_s" not in out.read_text().splitlines()[0]
    again = load_measurements(out)
    pd.testing.assert_frame_equal(again.df, meas.df)
    assert again.meta["speed_derived"] is True


def test_write_refuses_bad_meta_and_writes_nothing(tmp_path):
    with pytest.raises(DataFormatError) as info:
        write_measurements(awkward_frame(), tmp_path / "x.csv", {"slider_mass_kg": -1})
    assert "x.json" in str(info.value) and "'slider_mass_kg' [kg]" in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_write_replaces_existing_files(tmp_path):
    (tmp_path / "x.csv").write_text("old")
    (tmp_path / "x.json").write_text('{"slider_mass_kg": 9}')
    write_measurements(awkward_frame(), tmp_path / "x.csv")
    meas = load_measurements(tmp_path / "x.csv", allow_unusual_units=True)  # unphysical on purpose
    assert meas.meta["slider_mass_kg"] is None  # stale sidecar replaced
    assert meas.n_samples == 8
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.csv", "x.json"]


def test_measurements_api(tmp_path):
    rows = good_rows()
    for r in rows:
        r["run"] = "b" if r["run"] == "1" else "a"
    meas = load_measurements(write_csv(tmp_path, rows))
    assert isinstance(meas, Measurements)
    assert meas.n_samples == 6
    assert meas.runs == ["b", "a"]  # file order, not sorted
    parts = list(meas.iter_runs())
    assert [rid for rid, _ in parts] == ["b", "a"]
    assert [len(d) for _, d in parts] == [3, 3]
    assert (parts[1][1]["direction"] == -1).all()
    with pytest.raises(AttributeError):
        meas.df = None  # frozen


def test_known_columns_table():
    names = [c.name for c in D.KNOWN_COLUMNS]
    assert names == COLUMNS
    assert D.REQUIRED_COLUMNS == ("time_s", "run", "position_m", "voltage_V", "direction",
                                  "load_kg")
    assert {c.name: c.unit for c in D.KNOWN_COLUMNS}["speed_m_s"] == "m/s"


def test_public_api_reexports_the_modules_behind_it():
    from l1b2.data import columns, io, validate
    assert D.KNOWN_COLUMNS is columns.KNOWN_COLUMNS and D.SIDECAR_FIELDS is columns.SIDECAR_FIELDS
    assert D.validate_frame is validate.validate_frame and D.run_slices is validate.run_slices
    assert D.sidecar_path is columns.sidecar_path and D.unit_of is columns.unit_of
    assert all(hasattr(D, name) for name in D.__all__)
    assert all(hasattr(m, name) for m in (columns, validate, io) for name in m.__all__)

def test_units_are_defined_once_in_l1b2_units():
    assert [(c.name, c.unit) for c in D.KNOWN_COLUMNS] == list(COLUMN_UNITS.items())
    assert D.SIDECAR_FIELDS == SIDECAR_FIELD_UNITS
    assert all(D.unit_of(name) == unit for name, unit in {**COLUMN_UNITS, **SIDECAR_FIELD_UNITS}.items())
    assert D.unit_of("not_a_column") is None
    exc = DataFormatError("x.json", "drive_frequency_Hz", None, "bad")
    assert str(exc) == "x.json: field 'drive_frequency_Hz' [Hz]: bad"


# --------------------------------------------------------------------------
# Derived speed
# --------------------------------------------------------------------------

def test_derived_speed_matches_analytic_and_does_not_leak_across_runs(tmp_path):
    rng = np.random.default_rng(1)
    t1 = np.sort(rng.uniform(0.0, 0.1, 15))                     # uneven sampling
    t2 = 0.1 + np.sort(rng.uniform(0.001, 0.1, 12))             # back-to-back
    x1 = 0.1 * (t1 - t1[0]) ** 2                                # run 1: x = 0.1 t^2
    x2 = 0.003 - 0.1 * (t2 - t2[0]) ** 2                        # run 2 reversed, jumps
    t = np.concatenate([t1, t2])
    x = np.concatenate([x1, x2])
    df = pd.DataFrame({"time_s": t, "run": [7] * 15 + [8] * 12, "position_m": x,
                       "voltage_V": 100.0, "direction": [1] * 15 + [-1] * 12,
                       "load_kg": 0.0})
    path = write_measurements(df, tmp_path / "d.csv")
    meas = load_measurements(path)
    assert meas.meta["speed_derived"] is True
    v = meas.df["speed_m_s"].to_numpy()
    exact = np.concatenate([0.2 * (t1 - t1[0]), -0.2 * (t2 - t2[0])])
    np.testing.assert_allclose(v, exact, rtol=0, atol=1e-12)
    # sanity: differentiating the whole file at once would leak at the boundary
    leaky = np.gradient(x, t)
    assert abs(leaky[14] - exact[14]) > 1e-4 and abs(leaky[15] - exact[15]) > 1e-2


def test_derived_speed_two_sample_run_and_single_sample_refused(tmp_path):
    df = pd.DataFrame({"time_s": [0.0, 0.5, 1.0], "run": [1, 1, 2],
                       "position_m": [0.0, 0.01, 0.0], "voltage_V": 50.0,
                       "direction": [1, 1, -1], "load_kg": 0.0})
    path = write_measurements(df, tmp_path / "d.csv")
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert_names(info.value, path, "position_m", "m", 3)
    df = pd.DataFrame({"time_s": [0.0, 0.5, 1.0, 1.5, 2.0], "run": [1, 1, 2, 2, 2],
                       "position_m": [0.0, 0.01, 0.0, 0.0075, 0.03], "voltage_V": 50.0,
                       "direction": 1, "load_kg": 0.0})
    v = load_measurements(write_measurements(df, tmp_path / "e.csv")).df["speed_m_s"]
    # run 1: one-sided difference; run 2: x = 0.03 (t - 1)^2, exact at the ends too
    np.testing.assert_allclose(v, [0.02, 0.02, 0.0, 0.03, 0.06], rtol=0, atol=1e-15)


# --------------------------------------------------------------------------
# Split by load
# --------------------------------------------------------------------------

def _four_runs() -> Measurements:
    loads = [0.0, 0.05, -0.05, 0.1]
    n = 3
    df = pd.DataFrame({
        "time_s": np.arange(4 * n) * 0.01,
        "run": np.repeat(["r0", "r1", "r2", "r3"], n),
        "position_m": np.tile([0.0, 0.001, 0.002], 4),
        "voltage_V": 100.0,
        "direction": 1,
        "load_kg": np.repeat(loads, n),
        "speed_m_s": 0.1,
    })
    return Measurements(df=df, meta={"slider_mass_kg": 0.1, "source": "x.csv"}, path="x.csv")


def test_split_by_load():
    train, test = split_by_load(_four_runs())
    assert train.runs == ["r0", "r3"]
    assert test.runs == ["r1", "r2"]          # |load| = 0.05 both signs
    assert train.meta["slider_mass_kg"] == test.meta["slider_mass_kg"] == 0.1
    assert train.meta["subset"] == "train" and test.meta["subset"] == "test"
    assert train.n_samples + test.n_samples == 12
    train, test = split_by_load(_four_runs(), test_abs_loads=(0.0, 0.1))
    assert test.runs == ["r0", "r3"]


@pytest.mark.parametrize("loads", [(0.3,), (0.0, 0.05, 0.1)])
def test_split_by_load_empty_part_raises(loads):
    with pytest.raises(IdentificationError, match="empty"):
        split_by_load(_four_runs(), test_abs_loads=loads)


# --------------------------------------------------------------------------
# Runs at different drive frequencies: an input like voltage and load
# --------------------------------------------------------------------------

def test_test_runs_outside_trains_frequency_range_are_flagged(capsys):
    # reference: the drive frequency is a prediction input (the predictor's frequency response): a TEST run at a
    # frequency outside TRAIN's range is flagged like voltage and load; frequency_varies says whether TRAIN's
    # runs spread by more than FREQUENCY_REL_SPREAD of their median (then the response is identified)
    from l1b2.cli import print_input_checks
    from l1b2.data.coverage import FREQUENCY_REL_SPREAD, MIN_TOLERANCE, frequency_varies, input_checks
    train, test = split_by_load(_four_runs())
    assert "frequency_Hz" not in train.df
    def freq_flagged(checks):
        return [f["run"] for f in checks["test_runs_outside_training_range"] if "frequency_Hz" in f["outside"]]

    assert not frequency_varies(train, test) and freq_flagged(input_checks(train, test)) == []
    for m in (train, test):
        m.df["frequency_Hz"] = 48500.0
    below = 48500.0 * (1 + 0.9 * FREQUENCY_REL_SPREAD)
    test.df.loc[test.df["run"] == "r2", "frequency_Hz"] = below
    assert not frequency_varies(train, test)
    assert below - 48500.0 > MIN_TOLERANCE["frequency_Hz"]   # not a spread to identify, but outside TRAIN's point
    checks = input_checks(train, test)
    assert freq_flagged(checks) == ["r2"]
    test.df.loc[test.df["run"] == "r2", "frequency_Hz"] = 47000.0
    assert frequency_varies(train, test) and not frequency_varies(train)
    checks = input_checks(train, test)
    assert freq_flagged(checks) == ["r2"]
    flag = [f for f in checks["test_runs_outside_training_range"] if f["run"] == "r2"][0]["outside"]["frequency_Hz"]
    assert flag["min"] == 47000.0 and flag["train"] == [48500.0, 48500.0]
    assert "frequency_Hz 1" in checks["extrapolation"]
    print_input_checks(checks, {})
    assert "frequency_Hz" in capsys.readouterr().out
