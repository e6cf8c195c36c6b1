"""Rig files as DAQs and spreadsheets write them (decision 0115): read alike when unambiguous, else one line.

Each case is a small file in ``tmp_path``: the variants the format reads as
the plain file (line ends, quotes, column order, a trailing separator) give
the same samples, and the ones it refuses name the cause in the message
(a units row, a preamble, a repeated header, pandas' index column, a binary
or JSON file, a clock reset at each run, a run of one sample, a TEST run that
is a TRAIN run).
"""

from __future__ import annotations

import numpy as np
import pytest
from l1b2.data.measurements import load_measurements
from l1b2.errors import DataFormatError
from l1b2.workflows import load_train_test

HEADER = "time_s,run,position_m,voltage_V,direction,load_kg,speed_m_s"
UNITS = "s,-,m,V,-,kg,m/s"


def rows(t0: float = 0.0, runs=(1, 2), n: int = 4) -> list[str]:
    """n samples per run at 1 kHz, 0.1 m/s forward in odd runs, backward in even ones; the clock runs on."""
    out, t = [], t0
    for r in runs:
        d = 1 if r % 2 else -1
        for k in range(n):
            out.append(f"{t:.3f},{r},{d * 1e-4 * k:.6f},100,{d},0.0,{d * 0.1}")
            t += 0.001
        t += 0.5
    return out


def write(tmp_path, lines: list[str], name: str = "data.csv", end: str = "\n") -> object:
    path = tmp_path / name
    path.write_bytes((end.join(lines) + end).encode("utf-8"))
    return path


def refused(path, fragment: str, *, row=None, column=None) -> DataFormatError:
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    exc = info.value
    msg = str(exc)
    assert "\n" not in msg and path.name in msg and fragment in msg, msg
    assert exc.row == row and exc.column == column, msg
    return exc


def same_samples(a, b, *, order: bool = True) -> None:
    assert a.runs == b.runs
    for c in ("time_s", "position_m", "voltage_V", "direction", "load_kg", "speed_m_s"):
        np.testing.assert_array_equal(a.df[c].to_numpy(dtype=float), b.df[c].to_numpy(dtype=float))
    assert (list(a.df.columns) if order else sorted(a.df.columns)) == \
        (list(b.df.columns) if order else sorted(b.df.columns))


# ---------------------------------------------------------------------------
# variants read as the plain file
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("variant", ["crlf", "cr", "quoted", "reversed", "trailing_separator"])
def test_variants_with_one_meaning_give_the_plain_files_samples(tmp_path, variant):
    plain = load_measurements(write(tmp_path, [HEADER] + rows(), "plain.csv"))
    lines, end = [HEADER] + rows(), "\n"
    if variant in ("crlf", "cr"):
        end = "\r\n" if variant == "crlf" else "\r"
    elif variant == "quoted":
        lines = [",".join(f'"{c}"' for c in ln.split(",")) for ln in lines]
    elif variant == "reversed":
        lines = [",".join(reversed(ln.split(","))) for ln in lines]
    else:  # a separator at the end of every line: a last column with no name and no value, dropped
        lines = [ln + "," for ln in lines]
    same_samples(load_measurements(write(tmp_path, lines, end=end)), plain, order=variant != "reversed")


def test_an_unnamed_column_with_values_is_refused_not_taken_as_a_channel(tmp_path):
    lines = ["," + HEADER] + [f"{k},{ln}" for k, ln in enumerate(rows())]
    msg = str(refused(write(tmp_path, lines), "no name but holds values"))
    assert "column 1" in msg and "index=False" in msg
    # a named column with the same values is an ordinary extra column
    lines[0] = "sample" + lines[0]
    assert list(load_measurements(write(tmp_path, lines, "named.csv")).df["sample"]) == list(range(8))


# ---------------------------------------------------------------------------
# variants refused with their cause named
# ---------------------------------------------------------------------------

def test_a_units_row_under_the_header_is_named_with_the_units_that_contradict_the_names(tmp_path):
    msg = str(refused(write(tmp_path, [HEADER, UNITS] + rows()), "a units row under the header?", row=1))
    assert "contradict" not in msg and "convert" not in msg
    msg = str(refused(write(tmp_path, [HEADER, "s,-,mm,V,-,g,mm/s"] + rows(), "mm.csv"), "units row", row=1))
    assert "'mm' for position_m [m]" in msg and "'g' for load_kg [kg]" in msg and "'V'" not in msg.split("gives")[1]
    # the row below may hold a gap in an optional column
    gap = [HEADER + ",temperature_C", UNITS + ",degC"] + [ln + ("," if k == 0 else ",25") for k, ln in enumerate(rows())]
    assert "contradict" not in str(refused(write(tmp_path, gap, "gap.csv"), "a units row under the header?", row=1))
    # a first row of junk with digits is no units row: the value check names it
    msg = str(refused(write(tmp_path, [HEADER, "x1,1,y2,100,1,0.0,z3"] + rows(), "junk.csv"), "non-numeric",
                      row=1, column="time_s"))
    assert "units row" not in msg


def test_lines_before_the_header_are_named_as_a_preamble(tmp_path):
    msg = str(refused(write(tmp_path, ["# DAQ export", "rate: 1000 Hz", HEADER] + rows()), "line 3 is the header"))
    assert "2 lines above it" in msg and "preamble" in msg
    refused(write(tmp_path, ["# only a comment", "1,2,3"], "c.csv"), "line 1 is a comment")


def test_a_space_separated_file_is_named(tmp_path):
    lines = [ln.replace(",", " ") for ln in [HEADER] + rows()]
    refused(write(tmp_path, lines), "uses spaces as separator")


def test_the_header_repeated_inside_the_data_names_its_row(tmp_path):
    lines = [HEADER] + rows(runs=(1,)) + [HEADER] + rows(t0=1.0, runs=(2,))
    refused(write(tmp_path, lines), "the header line again inside the data", row=5)


@pytest.mark.parametrize("magic, kind", [(b"PAR1", "Parquet"), (b"PK\x03\x04", "xlsx"),
                                         (b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1", "xls"), (b"\x89HDF\r\n\x1a\n", "HDF5")])
def test_a_binary_file_is_named_by_its_kind(tmp_path, magic, kind):
    path = tmp_path / "data.csv"
    path.write_bytes(magic + bytes(range(256)))
    refused(path, kind)


def test_a_json_file_given_as_the_csv_is_named(tmp_path):
    path = tmp_path / "data.csv"
    path.write_text('{"slider_mass_kg": 0.12}\n')
    refused(path, "is JSON (the sidecar NAME.json?)")


@pytest.mark.parametrize("cell, fragment", [("1.0D-03", "Fortran 'D' exponent"), ("0.001 s", "unit written into"),
                                            ("00:00:00.001", "clock time"), ("0,001", "decimal comma"),
                                            ("abc", "non-numeric value 'abc'")])
def test_a_cell_that_is_no_number_names_its_likely_cause(tmp_path, cell, fragment):
    lines = [HEADER] + rows()
    c = lines[2].split(",")
    c[0] = f'"{cell}"'
    lines[2] = ",".join(c)
    msg = refused(write(tmp_path, lines), fragment, row=2, column="time_s").problem
    assert msg == "non-numeric value 'abc'" if cell == "abc" else "?" in msg


def test_a_clock_reset_at_each_run_and_equal_stamps_are_named(tmp_path):
    lines = [HEADER] + rows(runs=(1,)) + rows(t0=0.0, runs=(2,))
    refused(write(tmp_path, lines), "at the first row of run 2: is the clock reset at each run?", row=5,
            column="time_s")
    lines = [HEADER] + rows()
    lines[3] = lines[2].split(",")[0] + "," + ",".join(lines[3].split(",")[1:])
    msg = refused(write(tmp_path, lines, "eq.csv"), "equal stamps", row=3, column="time_s").problem
    assert "reset" not in msg
    lines = [HEADER] + rows()
    lines[3] = "0.0005," + ",".join(lines[3].split(",")[1:])  # backwards inside a run: neither cause
    msg = refused(write(tmp_path, lines, "back.csv"), "time not increasing", row=3, column="time_s").problem
    assert "reset" not in msg and "equal" not in msg


def test_a_missing_column_names_a_near_name_with_its_unit_in_brackets(tmp_path):
    lines = [HEADER.replace("time_s", "time [s]")] + rows()
    refused(write(tmp_path, lines), "found 'time [s]'", column="time_s")


# ---------------------------------------------------------------------------
# TRAIN and TEST as identify and close-loop load them
# ---------------------------------------------------------------------------

def test_a_run_of_one_sample_is_refused_naming_file_run_and_row(tmp_path):
    lines = [HEADER] + rows() + rows(t0=2.0, runs=(3,), n=1)
    path = write(tmp_path, lines)
    assert load_measurements(path).runs == [1, 2, 3]  # the data layer reads it (a speed column is given)
    with pytest.raises(DataFormatError) as info:
        load_train_test(path)
    msg = str(info.value)
    assert "data.csv" in msg and info.value.column == "run" and info.value.row == 9 and "single sample" in msg


def test_a_run_of_one_sample_is_named_by_its_file_row_after_rows_were_cut_on_reading(tmp_path):
    # property: the row is the file's (the frame's index + 1), not the frame's position, when reading cut rows
    from l1b2.data.coverage import runs_of_two
    from l1b2.data.measurements import Measurements
    m = load_measurements(write(tmp_path, [HEADER] + rows() + rows(t0=2.0, runs=(3,), n=1)))
    cut = Measurements(m.df.iloc[2:], m.meta, m.path)      # two rows of run 1 cut, the index kept
    with pytest.raises(DataFormatError) as info:
        runs_of_two(cut, "data.csv")
    assert info.value.row == 9


def test_a_test_run_that_is_a_train_run_is_refused(tmp_path):
    train = write(tmp_path, [HEADER] + rows(runs=(1, 2, 3, 4)), "train.csv")
    with pytest.raises(DataFormatError, match="TEST run 1 is TRAIN run 1"):
        load_train_test(train, train)
    cut = write(tmp_path, [HEADER] + rows(runs=(1, 2, 3, 4))[8:], "cut.csv")  # TEST cut from TRAIN: runs 3 and 4
    with pytest.raises(DataFormatError) as info:
        load_train_test(train, cut)
    assert "TEST run 3 is TRAIN run 3" in str(info.value) and info.value.row == 1 and "cut.csv" in str(info.value)
    other = write(tmp_path, [HEADER] + rows(t0=10.0, runs=(5, 6)), "other.csv")  # same shape, another recording
    assert load_train_test(train, other)[1].runs == [5, 6]
    # the same plan simulated twice: equal stamps and positions, another measured speed (its own noise): accepted
    resim = [ln.rsplit(",", 1)[0] + f",{float(ln.rsplit(',', 1)[1]) * 1.01}" for ln in rows(runs=(1, 2, 3, 4))]
    assert load_train_test(train, write(tmp_path, [HEADER] + resim, "resim.csv"))[1].runs == [1, 2, 3, 4]
    # without TEST's speed column (derived from position) the stamps and positions decide: refused
    no_speed = [ln.rsplit(",", 1)[0] for ln in [HEADER] + rows(runs=(1, 2, 3, 4))[8:]]
    with pytest.raises(DataFormatError, match="TEST run 3 is TRAIN run 3"):
        load_train_test(train, write(tmp_path, no_speed, "derived.csv"))


def test_a_test_speed_derived_while_trains_is_measured_is_named_in_the_checks(tmp_path):
    from l1b2.data.coverage import data_check_lines, input_checks
    train = write(tmp_path, [HEADER] + rows(runs=(1, 2)), "train.csv")
    no_speed = [",".join(ln.split(",")[:-1]) for ln in [HEADER] + rows(t0=10.0, runs=(3, 4))]
    checks = input_checks(*load_train_test(train, write(tmp_path, no_speed, "test.csv"))[:2])
    assert checks["speed_derived"] == {"train": False, "test": True}
    lines = [ln for ln in data_check_lines(checks) if "speed" in ln]
    assert len(lines) == 1 and "TRAIN's speed is measured (speed_m_s) and TEST's derived from position_m" in lines[0]
    alike = input_checks(*load_train_test(train, write(tmp_path, [HEADER] + rows(t0=10.0, runs=(3, 4)), "t2.csv"))[:2])
    assert alike["speed_derived"] == {"train": False, "test": False}
    assert not [ln for ln in data_check_lines(alike) if "speed" in ln]
    assert input_checks(load_train_test(train)[0], None)["speed_derived"]["test"] is None


def test_the_close_loops_report_names_a_test_speed_derived_while_trains_is_measured():
    from l1b2.closeloop.result import markdown_report
    from test_report_values import minimal_report
    rep = minimal_report()
    rep["checks"] = {**(rep.get("checks") or {}), "speed_derived": {"train": False, "test": True}}
    lines = markdown_report(rep).splitlines()
    assert "Speed source:" in lines
    assert lines[lines.index("Speed source:") + 2].startswith(
        "* TRAIN's speed is measured (speed_m_s) and TEST's derived from position_m")
    rep["checks"]["speed_derived"] = {"train": True, "test": True}
    assert "Speed source:" not in markdown_report(rep).splitlines()
