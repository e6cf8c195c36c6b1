"""Gaps in the optional input columns of the measured-data CSV (``temperature_C``, ``frequency_Hz``): filled within
their run on reading, recorded and reported; a run without a reading, a gap in a required column and a gap in the
measured speed are refused.

Values checked against the interpolation written out in each test.
"""

from __future__ import annotations

import numpy as np
import pytest
from l1b2.data import gaps as G
from l1b2.data.coverage import input_checks
from l1b2.data.measurements import load_measurements, validate_frame, validate_frame_filled, write_measurements
from l1b2.errors import DataFormatError

HEADER = ["time_s", "run", "position_m", "voltage_V", "direction", "load_kg", "speed_m_s", "frequency_Hz",
          "temperature_C"]

#: (time_s, run, direction, load_kg, frequency_Hz cell, temperature_C cell) per sample; positions and speeds
#: follow at 0.1 m/s in the run's direction
SAMPLES = [
    # run 1: uneven clock; gaps at its start, inside and at its end (next to run 2)
    (0.000, 1, 1, 0.0, "48500", ""),
    (0.001, 1, 1, 0.0, "48500", "nan"),
    (0.002, 1, 1, 0.0, "48500", "20.0"),
    (0.004, 1, 1, 0.0, "48500", ""),
    (0.005, 1, 1, 0.0, "48500", "23.0"),
    (0.006, 1, 1, 0.0, "48500", "NaN"),
    # run 2: a gap at its start (next to run 1) and an infinity inside
    (1.000, 2, -1, 0.05, "48500", ""),
    (1.001, 2, -1, 0.05, "48500", "30.0"),
    (1.002, 2, -1, 0.05, "48500", "inf"),
    (1.003, 2, -1, 0.05, "48500", "34.0"),
    # run 3: the frequency counter misses two readings
    (2.000, 3, 1, -0.05, "48500", "25.0"),
    (2.001, 3, 1, -0.05, "-inf", "25.0"),
    (2.002, 3, 1, -0.05, "", "25.0"),
    (2.003, 3, 1, -0.05, "48600", "25.0"),
]


def rows(samples=SAMPLES) -> list[list[str]]:
    out = []
    start = {}
    for t, run, d, load, f, temp in samples:
        t0 = start.setdefault(run, t)
        x = -0.02 * d + 0.1 * d * (t - t0)
        out.append([repr(t), str(run), repr(x), "300", str(d), repr(load), repr(0.1 * d), f, temp])
    return out


def write(tmp_path, table, header=HEADER, name="gappy.csv"):
    path = tmp_path / name
    path.write_text("\n".join([",".join(header)] + [",".join(r) for r in table]) + "\n")
    return path


def test_gaps_are_interpolated_in_time_within_their_run_and_never_across_runs(tmp_path):
    m = load_measurements(write(tmp_path, rows()))
    temp = m.df["temperature_C"].to_numpy()
    freq = m.df["frequency_Hz"].to_numpy()
    # run 1: held at its first reading (20) before it; at t = 4 ms, 20 + (23 - 20) (4 - 2)/(5 - 2) = 22; held at its
    # last reading (23) after it, not drawn toward run 2's first reading (30)
    np.testing.assert_allclose(temp[:6], [20.0, 20.0, 20.0, 22.0, 23.0, 23.0], rtol=0, atol=1e-12)
    # run 2: held at its own first reading (30), not drawn from run 1's 23; inf at 1.002 s: 30 + (34 - 30)/2 = 32
    np.testing.assert_allclose(temp[6:10], [30.0, 30.0, 32.0, 34.0], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(temp[10:], 25.0)
    # run 3's frequency: 48500 + (48600 - 48500) (t - 2.000 s)/(0.003 s)
    t = np.array([2.000, 2.001, 2.002, 2.003])
    np.testing.assert_allclose(freq[10:], 48500.0 + 100.0 * (t - 2.0) / 0.003, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(freq[:10], 48500.0)
    assert m.meta["frequency_filled"] is False            # a measured column with gaps, not the sidecar's value


def test_the_loader_records_per_column_the_cells_filled_and_the_first_row_and_line(tmp_path):
    m = load_measurements(write(tmp_path, rows()))
    assert m.meta["gaps_filled"] == {
        "temperature_C": {"cells": 6, "runs": 2, "first_row": 1, "first_line": 2},      # rows 1, 2, 4, 6, 7, 9
        "frequency_Hz": {"cells": 2, "runs": 1, "first_row": 12, "first_line": 13}}    # rows 12, 13
    clean = [r[:7] + ["48500", "25.0"] for r in rows()]
    assert load_measurements(write(tmp_path, clean, name="clean.csv")).meta["gaps_filled"] == {}


def test_a_run_without_any_reading_is_refused_naming_file_column_unit_and_its_first_row(tmp_path):
    table = rows()
    for r in table[6:10]:          # run 2 (rows 7-10): no temperature at all
        r[8] = "" if r[0] != "1.002" else "NaN"
    path = write(tmp_path, table)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    e = info.value
    assert (e.column, e.row, e.line) == ("temperature_C", 7, 8)
    assert str(e).startswith(f"{path}: column 'temperature_C' [degC], row 7 (line 8): run 2 has no reading")
    table = rows()
    for r in table[10:]:           # run 3 (rows 11-14): no frequency at all
        r[7] = "inf"
    with pytest.raises(DataFormatError, match=r"'frequency_Hz' \[Hz\], row 11 \(line 12\): run 3 has no reading"):
        load_measurements(write(tmp_path, table, name="nofreq.csv"))


@pytest.mark.parametrize("column,text", [("time_s", ""), ("run", ""), ("position_m", "nan"), ("voltage_V", ""),
                                         ("direction", "NaN"), ("load_kg", "inf")])
def test_a_gap_in_a_required_column_is_still_refused(tmp_path, column, text):
    table = [r[:7] + ["48500", "25.0"] for r in rows()]
    table[3][HEADER.index(column)] = text
    with pytest.raises(DataFormatError) as info:
        load_measurements(write(tmp_path, table))
    assert (info.value.column, info.value.row) == (column, 4)


def test_a_gap_in_the_measured_speed_is_refused_with_the_remedy_and_the_remedy_loads(tmp_path):
    table = [r[:7] + ["48500", "25.0"] for r in rows()]
    table[4][6] = ""
    with pytest.raises(DataFormatError) as info:
        load_measurements(write(tmp_path, table))
    assert (info.value.column, info.value.row) == ("speed_m_s", 5)
    assert "empty value; speed_m_s is the measured output" in str(info.value)
    assert "leave the column out (the speed is then derived from position_m" in str(info.value)
    no_speed = [r[:6] + r[7:] for r in table]
    m = load_measurements(write(tmp_path, no_speed, HEADER[:6] + HEADER[7:], name="derived.csv"))
    assert m.meta["speed_derived"] and np.isfinite(m.df["speed_m_s"]).all()


def test_a_frame_in_memory_follows_the_same_rule_and_a_written_gap_reads_back_filled(tmp_path):
    df = load_measurements(write(tmp_path, [r[:7] + ["48500", "25.0"] for r in rows()])).df
    df.loc[3, "temperature_C"] = np.nan              # run 1, between 25 at 2 ms and 25 at 5 ms
    df.loc[4, "temperature_C"] = 26.0
    checked, filled = validate_frame_filled(df, "frame")
    # t = 4 ms between (2 ms, 25) and (5 ms, 26): 25 + (26 - 25) (4 - 2)/(5 - 2)
    assert checked.loc[3, "temperature_C"] == pytest.approx(25.0 + 2.0 / 3.0, abs=1e-12)
    assert filled == {"temperature_C": {"cells": 1, "runs": 1, "first_row": 4, "first_line": 5}}
    assert np.isnan(df.loc[3, "temperature_C"])       # the caller's frame is not changed
    np.testing.assert_array_equal(validate_frame(df, "frame")["temperature_C"], checked["temperature_C"])
    back = load_measurements(write_measurements(df, tmp_path / "written.csv"))
    np.testing.assert_array_equal(back.df["temperature_C"], checked["temperature_C"])
    assert back.meta["gaps_filled"]["temperature_C"]["first_row"] == 4


def test_the_close_loop_bridges_its_auxiliary_channels_with_the_same_function():
    from l1b2.closeloop import auxiliary
    assert auxiliary.fill_gaps is G.fill_gaps


def test_the_reports_and_the_command_line_name_what_was_filled(tmp_path, capsys):
    from l1b2.closeloop.result import markdown_report
    from l1b2.console import print_input_checks
    from test_report_values import minimal_report
    m = load_measurements(write(tmp_path, rows()))
    clean = load_measurements(write(tmp_path, [r[:7] + ["48500", "25.0"] for r in rows()], name="clean.csv"))
    checks = input_checks(m, clean)
    assert checks["gaps_filled"] == {"train": m.meta["gaps_filled"], "test": {}}
    lines = G.gap_lines(checks["gaps_filled"])
    assert lines == [
        "TRAIN frequency_Hz: 2 empty, NaN or infinite cell(s) in 1 run(s) (first: row 12, line 13) filled by linear "
        "interpolation in time within their run",
        "TRAIN temperature_C: 6 empty, NaN or infinite cell(s) in 2 run(s) (first: row 1, line 2) filled by linear "
        "interpolation in time within their run"]
    text = markdown_report({**minimal_report(), "checks": checks}).splitlines()
    at = text.index("Gaps in optional input columns, filled on reading:")
    assert text[at + 2:at + 4] == [f"* {line}" for line in lines]
    assert "Gaps in optional" not in markdown_report(minimal_report())
    print_input_checks(checks, {}, lines)
    assert capsys.readouterr().out.splitlines() == [f"  warning: {line}" for line in lines]


def test_the_identification_reads_a_frame_with_gaps_filled_and_evaluates_extra_forces_on_the_filled_frame(tmp_path):
    from l1b2.ident.problem import SampleData
    df = load_measurements(write(tmp_path, [r[:7] + ["48500", "25.0"] for r in rows()])).df
    df.loc[11, "frequency_Hz"] = np.nan              # run 3, between 48500 at 2.000 s and ... at 2.002 s
    df.loc[12, "frequency_Hz"] = 48600.0
    sample = SampleData(df)
    # t = 2.001 s between (2.000 s, 48500) and (2.002 s, 48600): the midpoint
    assert sample.frame.loc[11, "frequency_Hz"] == pytest.approx(48550.0, abs=1e-9)
    clean = df.fillna(48500.0)
    assert SampleData(clean).frame is clean           # nothing filled: the caller's frame, as before
