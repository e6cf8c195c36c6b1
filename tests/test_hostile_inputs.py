"""Wrong data that looked right, and inputs that crashed instead of being refused (issue 30).

Whole-file physics (l1b2.data.plausibility): the load's effect has the sign
gravity gives it, runs whose inputs contradict their own speed, clock jumps,
temperature in degF, loads heavier than the slider; strict sidecars
(duplicate keys, deep nesting) and TEST's sidecar against TRAIN's; both
sides of every hard limit; the internal errors the campaign found (run ids
beyond int64, a full disk, deeply nested study tables, oversized studies,
absurd operating points) as one-line refusals.
"""

from __future__ import annotations

import errno
import json

import numpy as np
import pandas as pd
import pytest
from l1b2.cli import main as cli_main
from l1b2.data import plausibility as pl
from l1b2.data.measurements import load_measurements
from l1b2.errors import DataFormatError, SpecError
from test_units_plausibility import M_S, synthetic_frame, write


@pytest.fixture(scope="module")
def rig_frame():
    from rigcache import rig_dir
    return pd.read_csv(rig_dir() / "all.csv")


def _refused(path, column, fragment, **kw):
    with pytest.raises(DataFormatError) as info:
        load_measurements(path, **kw)
    msg = str(info.value)
    assert "\n" not in msg and info.value.column == column, msg
    assert fragment in msg, msg
    assert "--allow-unusual-units" in msg or kw, msg
    return info.value


# ---------------------------------------------------------------------------
# whole-file physics
# ---------------------------------------------------------------------------

def test_clean_rig_and_synthetic_files_have_no_physics_finding(rig_frame):
    assert pl.physics_findings(rig_frame, slider_mass_kg=0.12) == []
    assert pl.physics_findings(synthetic_frame(), slider_mass_kg=M_S) == []


def test_a_reversed_load_sign_contradicts_gravity(tmp_path, rig_frame):
    # reference: issue 30 - the load's sign flipped was accepted; gravity slows a slider that lifts its load
    path = write(tmp_path, rig_frame.assign(load_kg=-rig_frame["load_kg"]), sidecar={"slider_mass_kg": 0.12})
    _refused(path, "load_kg", "wrong sign")
    load_measurements(path, allow_unusual_units=True)  # the override still works


def test_load_sign_finding_follows_the_sign_of_the_slope():
    # closed form: runs at one voltage and direction, u = u0 - k * load * direction exactly
    loads = np.array([-0.05, 0.0, 0.05, 0.07])
    for k, expect in ((+2.0, None), (-2.0, "load_kg")):
        rows = [("r%d%d" % (i, d), i * 10, float(d), m, 300.0, 0.2 - k * m * d, 100)
                for i, m in enumerate(loads) for d in (1, -1)]
        runs = pd.DataFrame(rows, columns=["run", "row", "direction", "load", "voltage", "u", "n"])
        runs["u"] += np.tile([1e-4, -1e-4], len(loads))  # a little noise: a finite t statistic
        found = pl.load_sign_finding(runs)
        assert (found.column if found else None) == expect


@pytest.mark.parametrize("case", ["voltage zeroed", "direction flipped"])
def test_a_run_whose_inputs_contradict_its_speed_is_named(tmp_path, rig_frame, case):
    df = rig_frame.copy()
    runs = df["run"].unique()
    victim = next(r for r in runs if (df.loc[df.run == r, "load_kg"].iloc[0] == 0.0))
    m = df["run"] == victim
    if case == "voltage zeroed":
        df.loc[m, "voltage_V"] = 0.0
        column = "voltage_V"
    else:
        df.loc[m, "direction"] = -df.loc[m, "direction"]
        column = "direction"
    err = _refused(write(tmp_path, df, sidecar={"slider_mass_kg": 0.12}), column, f"run {victim}")
    assert err.row == int(np.flatnonzero(m)[0]) + 1


def test_a_clock_jump_within_a_run_is_refused_but_a_pause_between_runs_is_not(tmp_path, rig_frame):
    df = rig_frame.copy()
    first = df.index[df["run"] == df["run"].iloc[0]]
    second = df.index[df["run"] != df["run"].iloc[0]][0]
    paused = df.copy()
    paused.loc[second:, "time_s"] += 1e6            # between runs: the clock may run on for any time
    load_measurements(write(tmp_path, paused, "paused", {"slider_mass_kg": 0.12}))
    jumped = df.copy()
    jumped.loc[first[10]:, "time_s"] += 1e6         # inside a run: a traverse is continuous
    err = _refused(write(tmp_path, jumped, "jumped", {"slider_mass_kg": 0.12}), "time_s", "clock jump")
    assert err.row == first[10] + 1


def test_clock_jump_limit_both_sides():
    t = np.arange(100) * 1e-3
    run = np.zeros(100, int)
    for jump, found in ((pl.MIN_CLOCK_JUMP_S * 1.1, True), (pl.MIN_CLOCK_JUMP_S * 0.9, False)):
        tt = t.copy()
        tt[50:] += jump
        df = pd.DataFrame({"time_s": tt, "run": run})
        assert (pl.clock_jump_finding(df) is not None) is found, jump


def test_uneven_time_steps_within_runs_are_counted_beside_the_5_percent_limit():
    # reference: two runs of 1 ms steps; a sample stamped late by d moves the step before it to 1 ms + d and the
    # one after it to 1 ms - d: uneven when d > 5 % of 1 ms (0.06 ms: two steps, 0.94 and 1.06 ms), even at 0.04 ms;
    # the pause between the runs is no step within a run
    t = np.r_[np.arange(50), 1000 + np.arange(50)] * 1e-3
    run = np.repeat([1, 2], 50)
    assert pl.uneven_steps(pd.DataFrame({"time_s": t, "run": run})) is None
    for d, found in ((0.06e-3, True), (0.04e-3, False)):
        tt = t.copy()
        tt[60] += d                                        # run 2's 11th sample (data row 61)
        rec = pl.uneven_steps(pd.DataFrame({"time_s": tt, "run": run}))
        assert (rec is not None) is found, d
    assert rec is None
    tt = t.copy()
    tt[60] += 0.06e-3
    rec = pl.uneven_steps(pd.DataFrame({"time_s": tt, "run": run}))
    assert rec == pytest.approx({"steps": 98, "uneven": 2, "runs": 1, "first_row": 61, "smallest_s": 0.94e-3,
                                 "largest_s": 1.06e-3, "median_s": 1e-3})
    assert pl.uneven_step_lines({"train": rec, "test": None}) == [
        "TRAIN time_s: 2 of 98 steps within runs (1 run(s), first at row 61) differ from their run's median step by "
        "more than 5% (steps 0.94 to 1.06 ms, median 1 ms): stamps given on arrival rather than by the DAQ's clock? "
        "A speed derived over them is off by as much"]


def test_a_speed_glitch_beside_uneven_time_steps_names_the_stamps(tmp_path, rig_frame):
    # reference: the glitch of test_a_single_speed_glitch_is_refused (one speed sample far off) with the sample
    # stamped 0.5 ms early: the refusal adds the steps beside it and the uneven stamps as the likely cause; the same
    # glitch on the rig's even clock does not
    df = rig_frame.copy()
    runs = df["run"].to_numpy()
    row = int(np.flatnonzero(runs == runs[0])[60])
    df.loc[row, "speed_m_s"] = -1.0
    step = float(np.median(np.diff(df["time_s"].to_numpy()[runs == runs[0]])))
    even = _refused(write(tmp_path, df, "even", {"slider_mass_kg": 0.12}), "speed_m_s", "a glitch in the speed")
    assert "uneven" not in str(even)
    df.loc[row, "time_s"] -= 0.5 * step
    err = _refused(write(tmp_path, df, "stamped", {"slider_mass_kg": 0.12}), "speed_m_s", "a glitch in the speed")
    assert err.row == row + 1
    assert (f"The time steps beside it are {step * 1e3:.3g}, {0.5 * step * 1e3:.3g}, {1.5 * step * 1e3:.3g}, "
            f"{step * 1e3:.3g} ms where the run's median step is {step * 1e3:.3g} ms: a speed derived over uneven "
            "time stamps") in str(err)


def test_the_reports_and_the_command_line_name_uneven_time_steps(tmp_path, capsys, rig_frame):
    from l1b2.closeloop.result import markdown_report
    from l1b2.console import print_input_checks
    from l1b2.data.coverage import data_check_lines, input_checks
    from test_report_values import minimal_report
    df = rig_frame.copy()
    even = load_measurements(write(tmp_path, df, "even", {"slider_mass_kg": 0.12}))
    assert input_checks(even, even)["uneven_time_steps"] == {"train": None, "test": None}
    rows = np.flatnonzero(df["run"].to_numpy() == df["run"].iloc[0])
    df.loc[rows[100], "time_s"] += 0.2 * float(np.median(np.diff(df["time_s"].to_numpy()[rows])))
    m = load_measurements(write(tmp_path, df, "uneven", {"slider_mass_kg": 0.12}))
    checks = input_checks(m, even)
    assert checks["uneven_time_steps"] == {"train": pl.uneven_steps(m.df), "test": None}
    assert checks["uneven_time_steps"]["train"]["uneven"] == 2
    lines = pl.uneven_step_lines(checks["uneven_time_steps"])
    assert len(lines) == 1 and data_check_lines(checks) == lines
    text = markdown_report({**minimal_report(), "checks": checks}).splitlines()
    at = text.index("Uneven time steps:")
    assert text[at + 2] == f"* {lines[0]}"
    assert "Uneven time steps:" not in markdown_report(minimal_report())
    print_input_checks(checks, {}, data_check_lines(checks))
    assert capsys.readouterr().out.splitlines() == [f"  warning: {lines[0]}"]


@pytest.mark.parametrize("case, column, fragment", [
    ("temperature in degF", "temperature_C", "degF"),
    ("load in N", "load_kg", "load in N"),
    ("load in lb", "load_kg", "load in N"),
    ("load x10", "load_kg", "load in N"),
])
def test_unit_mistakes_within_the_plausible_ranges(tmp_path, rig_frame, case, column, fragment):
    # reference: issue 30 - load in N / lb / x10 and temperature in degF passed the per-column ranges
    df = rig_frame.assign(temperature_C=25.0)
    df = {"temperature in degF": lambda d: d.assign(temperature_C=d["temperature_C"] * 1.8 + 32),
          "load in N": lambda d: d.assign(load_kg=d["load_kg"] * 9.80665),
          "load in lb": lambda d: d.assign(load_kg=d["load_kg"] / 0.45359237),
          "load x10": lambda d: d.assign(load_kg=d["load_kg"] * 10)}[case](df)
    path = write(tmp_path, df, sidecar={"slider_mass_kg": 0.12})
    _refused(path, column, fragment)
    assert load_measurements(path, allow_unusual_units=True).meta["unusual_units"]


def test_coolest_temperature_limit_both_sides():
    for t, found in ((pl.MAX_COOLEST_TEMPERATURE_C + 1, True), (pl.MAX_COOLEST_TEMPERATURE_C - 1, False)):
        df = pd.DataFrame({"temperature_C": [t, t + 20.0]})
        assert (pl.temperature_finding(df) is not None) is found


def test_load_heavier_than_the_slider_both_signs():
    for load, found in ((0.13, True), (-0.13, True), (0.11, False), (-0.11, False)):
        df = pd.DataFrame({"load_kg": [0.0, load]})
        assert (pl.load_scale_finding(df, 0.12) is not None) is found, load


# ---------------------------------------------------------------------------
# sidecars
# ---------------------------------------------------------------------------

def test_duplicate_sidecar_key_is_refused(tmp_path):
    path = write(tmp_path, synthetic_frame())
    path.with_suffix(".json").write_text('{"slider_mass_kg": 0.1, "slider_mass_kg": 0.25}')
    with pytest.raises(DataFormatError, match="'slider_mass_kg' appears twice") as info:
        load_measurements(path)
    assert info.value.column == "slider_mass_kg"


def test_deeply_nested_sidecar_is_one_line(tmp_path, capsys):
    path = write(tmp_path, synthetic_frame())
    path.with_suffix(".json").write_text('{"a":' * 100_000 + "1" + "}" * 100_000)  # < 1 MB, deeper than any parser recursion
    code = cli_main(["identify", "--train", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "too deeply" in err, err
    assert not (tmp_path / "out").exists()


def test_test_sidecar_must_describe_the_same_rig(tmp_path, capsys):
    # reference: issue 30 - TEST's sidecar slider mass was ignored
    df = synthetic_frame()
    train = write(tmp_path, df[df["load_kg"] != 0.05], "train")
    test = write(tmp_path, df[df["load_kg"] == 0.05], "test", {"slider_mass_kg": M_S / 0.45359237})
    code = cli_main(["identify", "--train", str(train), "--test", str(test), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "slider_mass_kg" in err and "(lb?)" in err, err
    assert not (tmp_path / "out").exists()


def test_a_test_direction_never_seen_in_train_is_flagged():
    from l1b2.data.coverage import data_range, outside_range
    df = synthetic_frame()
    train = df[df["direction"] == 1]
    flagged = outside_range(df[df["direction"] == -1], data_range(train))
    assert flagged and all("direction" in f["outside"] for f in flagged)
    assert not any("direction" in f["outside"] for f in outside_range(train, data_range(train)))


# ---------------------------------------------------------------------------
# both sides of every hard limit (with the plausibility ranges allowed, so the hard limit decides)
# ---------------------------------------------------------------------------

HARD = [("position_m", 1.0, True), ("speed_m_s", 10.0, True), ("load_kg", 50.0, True),
        ("voltage_V", 2000.0, False), ("frequency_Hz", 1e6, False), ("temperature_C", 300.0, False)]
LOW = [("voltage_V", 0.0), ("frequency_Hz", 1e3), ("temperature_C", -100.0)]


def _one_cell(tmp_path, column, value, name):
    df = synthetic_frame()
    df[column] = df[column].astype(float)
    df.loc[len(df) // 2, column] = value
    return write(tmp_path, df, name)


@pytest.mark.parametrize("column, limit, symmetric", HARD)
def test_hard_upper_limits_hold_on_both_signs(tmp_path, column, limit, symmetric):
    signs = (1, -1) if symmetric else (1,)
    for sign in signs:
        bad = _one_cell(tmp_path, column, sign * limit * 1.01, f"bad{sign}")
        with pytest.raises(DataFormatError) as info:
            load_measurements(bad, allow_unusual_units=True)
        assert info.value.column == column and info.value.row == len(synthetic_frame()) // 2 + 1, str(info.value)
    inside = _one_cell(tmp_path, column, -limit * 0.99 if symmetric else limit * 0.99, "inside")
    load_measurements(inside, allow_unusual_units=True)


@pytest.mark.parametrize("column, limit", LOW)
def test_hard_lower_limits(tmp_path, column, limit):
    bad = _one_cell(tmp_path, column, limit - max(1.0, abs(limit) * 0.01), "bad")
    with pytest.raises(DataFormatError) as info:
        load_measurements(bad, allow_unusual_units=True)
    assert info.value.column == column


@pytest.mark.parametrize("value", [0.0, 2.0, -2.0, 0.5])
def test_direction_is_exactly_plus_or_minus_one(tmp_path, value):
    with pytest.raises(DataFormatError) as info:
        load_measurements(_one_cell(tmp_path, "direction", value, "d"), allow_unusual_units=True)
    assert info.value.column == "direction"


# ---------------------------------------------------------------------------
# internal errors that are refusals now
# ---------------------------------------------------------------------------

def test_run_ids_beyond_int64_are_kept_as_identifiers(tmp_path):
    df = synthetic_frame()
    df["run"] = [str(int(r) + 2**63 + 5) for r in df["run"]]
    meas = load_measurements(write(tmp_path, df))
    assert len(meas.runs) == df["run"].nunique()
    assert str(2**63 + 5) in {str(r) for r in meas.runs}


def test_a_full_disk_is_one_line_and_leaves_the_earlier_result(tmp_path, capsys, monkeypatch):
    from l1b2 import workflows
    from l1b2.ident.result import IdentificationResult
    out = tmp_path / "out"
    with workflows.output_dir(out, command="identify") as tmp:
        (tmp / "identification.json").write_text('{"old": true}')

    def full(self, directory, **sections):  # the disk fills while the result is written
        (directory / "identification.json").write_text('{"half')
        raise OSError(errno.ENOSPC, "No space left on device", str(directory / "identification.json"))
    monkeypatch.setattr(IdentificationResult, "save", full)
    train = write(tmp_path, synthetic_frame(), "train")
    code = cli_main(["identify", "--train", str(train), "--out", str(out), "--order", "3", "--starts", "1",
                     "--no-plots"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "No space left on device" in err, err
    assert json.loads((out / "identification.json").read_text()) == {"old": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "train.csv", "train.json"]


SPEC = """
[study]
design = "montecarlo"
draws = {draws}
[simulation]
step_s = {{ value = 1e-3, unit = "s" }}
max_time_s = {{ value = {t_max}, unit = "s" }}
[operating_points]
V0 = {{ values = [{v0}], unit = "V" }}
load = {{ values = [{load}], unit = "kg" }}
[parameters]
"Interface.mu_p" = {{ distribution = "uniform", low = 0.13, high = 0.17, unit = "1" }}
"""


def _spec(**kw):
    return SPEC.format(**{"draws": 10, "t_max": 4.0, "v0": 220.0, "load": 0.05, **kw})


@pytest.mark.parametrize("kw, key", [
    (dict(v0=1e9), "operating_points.V0.values"),
    (dict(load=1e6), "operating_points.load.values"),
    (dict(load=-1e6), "operating_points.load.values"),
    (dict(t_max=1e9), "simulation.max_time_s"),
])
def test_absurd_sweep_values_are_refused_naming_the_key(kw, key):
    from l1b2.sweep.spec import parse_spec
    with pytest.raises(SpecError, match=key.replace(".", r"\.")):
        parse_spec(_spec(**kw))


def test_sweep_size_is_estimated_and_refused_beyond_the_limit_the_user_can_raise(tmp_path, capsys):
    from l1b2.sweep.spec import check_size, parse_spec
    spec = parse_spec(_spec(draws=10**9))
    with pytest.raises(SpecError, match="--max-runs"):
        check_size(spec)
    assert check_size(spec, max_runs=10**9)["runs"] == 10**9
    saltelli = parse_spec(_spec(draws=100).replace('"montecarlo"', '"saltelli"')
                          + '"Stator.P0_N" = { distribution = "uniform", low = 6.0, high = 6.5, unit = "N" }\n')
    assert check_size(saltelli)["runs"] == 100 * (2 + 2)   # N (d + 2)
    path = tmp_path / "big.toml"
    path.write_text(_spec(draws=10**9))
    code = cli_main(["sweep", "--spec", str(path), "--out", str(tmp_path / "out"), "--workers", "0", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "more than the limit" in err, err
    assert not (tmp_path / "out").exists()


def test_deeply_nested_study_tables_are_one_line(tmp_path, capsys):
    path = tmp_path / "deep.toml"
    path.write_text("x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    code = cli_main(["sweep", "--spec", str(path), "--out", str(tmp_path / "out"), "--workers", "0", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "nested too deeply" in err, err


# ---------------------------------------------------------------------------
# large files: the typed fast path reads the same table as the text path
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("ids", ["integers", "text", "mixed"])
def test_fast_reader_gives_the_text_readers_table(tmp_path, rig_frame, monkeypatch, ids):
    from l1b2.data import io as dio
    df = rig_frame.assign(note="x")
    if ids != "integers":
        df["run"] = df["run"].astype(object)
        pick = df.index if ids == "text" else df.index[df.index > len(df) // 2]
        df.loc[pick, "run"] = df.loc[pick, "run"].map(lambda r: f"run-{r}")
    path = write(tmp_path, df, sidecar={"slider_mass_kg": 0.12})
    monkeypatch.setattr(dio, "FAST_CHUNK_ROWS", 500)       # several blocks, ids changing kind between them
    assert dio._read_fast(path) is not None
    fast, _ = dio.read_table_and_sidecar(path)
    monkeypatch.setattr(dio, "_read_fast", lambda p: None)
    text, _ = dio.read_table_and_sidecar(path)
    pd.testing.assert_frame_equal(fast, text, check_exact=True)


def test_an_fmu_folder_without_binaries_is_one_line(tmp_path, fmus, capsys):
    # reference: issue 30 - an FMU folder without binaries was an internal error (exit 3, traceback)
    import zipfile
    folder = tmp_path / "fmus"
    folder.mkdir()
    for name, src in fmus.items():
        with zipfile.ZipFile(src) as zin, zipfile.ZipFile(folder / f"{name}.fmu", "w") as zout:
            for item in zin.infolist():
                if not item.filename.startswith("binaries/"):
                    zout.writestr(item, zin.read(item.filename))
    code = cli_main(["simulate", "--engine", "fmu", "--fmu-dir", str(folder), "--duration", "0.01",
                     "--out", str(tmp_path / "sim.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "binaries" in err and "Driver.fmu" in err, err
    assert not (tmp_path / "sim.csv").exists()


@pytest.mark.parametrize("factor, refused", [(1 / 0.45359237, True), (9.80665, True), (10.0, True), (1.0, False)])
def test_test_loads_in_another_unit_show_another_load_effect(tmp_path, capsys, factor, refused):
    # reference: campaign - TEST's load in lb stayed inside every range; a kilogram must act the same in both files
    from rigcache import rig_dir
    train = pd.read_csv(rig_dir() / "train.csv")
    test = pd.read_csv(rig_dir() / "test.csv")
    tr = write(tmp_path, train, "train", {"slider_mass_kg": 0.12})
    te = write(tmp_path, test.assign(load_kg=test["load_kg"] * factor), "test", {"slider_mass_kg": 0.12})
    from l1b2.workflows import load_train_test
    if refused:
        with pytest.raises(DataFormatError, match="as much as TRAIN's|heavier than the slider") as info:
            load_train_test(tr, te)    # (N and x10 are already heavier than the slider in TEST alone)
        assert info.value.column == "load_kg" and "\n" not in str(info.value)
        _, t, _ = load_train_test(tr, te, allow_unusual_units=True)
        assert any("as much as TRAIN's" in u for u in t.meta["unusual_units"])
    else:
        load_train_test(tr, te)


def test_the_load_effects_refusal_names_the_file_row_when_rows_were_cut_on_reading(tmp_path):
    # property: the row is TEST's file row (the frame's index + 1) of the heaviest run's first sample, unchanged
    # when rows before it were cut on reading (the onset's rest cut keeps the index)
    from l1b2.data.coverage import check_same_rig
    from l1b2.data.measurements import Measurements
    from rigcache import rig_dir
    side = {"slider_mass_kg": 0.3}
    tr = load_measurements(write(tmp_path, pd.read_csv(rig_dir() / "train.csv"), "train", side))
    test = pd.read_csv(rig_dir() / "test.csv")
    te = load_measurements(write(tmp_path, test.assign(load_kg=test["load_kg"] / 0.45359237), "test", side))
    cut = Measurements(te.df.iloc[2:], te.meta, te.path)     # two rows of the first run cut
    rows = []
    for m in (te, cut):
        with pytest.raises(DataFormatError, match="as much as TRAIN's") as info:
            check_same_rig(tr, m)
        rows.append(info.value.row)
    heavy = te.df.loc[rows[0] - 1, "run"]                    # the run named, its first sample in the file
    assert rows[0] - 1 == te.df.index[te.df["run"] == heavy][0]
    assert rows[1] - 1 == cut.df.index[cut.df["run"] == heavy][0], rows   # its first kept sample's file row
