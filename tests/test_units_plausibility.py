"""Unit mistakes in measured data are refused, naming the likely mistake (issue 14, item 1).

The data contract's third stage (l1b2.data.validate.unusual_values and
unusual_setting, applied by load_measurements): values a linear USM rig does
not produce in SI units and a speed column that disagrees with the
position's derivative. Real rig data (filtered, lagged, noisy speed) pass;
``allow_unusual_units`` accepts and records the findings; identify checks
TEST files the same way and writes nothing when refusing.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from l1b2.cli import main as cli_main
from l1b2.data.measurements import load_measurements
from l1b2.errors import DataFormatError, L1B2Error, ParameterError
from l1b2.predictor.model import example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset

M_S = 0.1
DESIGN = design_grid(voltages=(220.0, 324.0), loads=(-0.05, 0.0, 0.05))


def synthetic_frame(noise=1e-4, seed=0) -> pd.DataFrame:
    """Traverses of the Eq. 29 predictor in the data format (12 runs, consistent speed and position)."""
    df = simulate_dataset(example_params(3), DESIGN, M_S, noise_std=noise, seed=seed)
    return df.assign(frequency_Hz=48500.0, temperature_C=25.0)


def write(tmp_path, df, name="data", sidecar=None) -> "pathlib.Path":  # noqa: F821
    path = tmp_path / f"{name}.csv"
    df.to_csv(path, index=False)
    (tmp_path / f"{name}.json").write_text(json.dumps({"slider_mass_kg": M_S, **(sidecar or {})}))
    return path


@pytest.fixture(scope="module")
def rig_frame():
    from rigcache import rig_dir
    return pd.read_csv(rig_dir() / "all.csv")


# ---------------------------------------------------------------------------
# what must pass
# ---------------------------------------------------------------------------

def test_synthetic_and_rig_data_pass(tmp_path, rig_frame):
    meas = load_measurements(write(tmp_path, synthetic_frame()))
    assert meas.meta["unusual_units"] == []
    meas = load_measurements(write(tmp_path, rig_frame, "rig", {"slider_mass_kg": 0.12}))
    assert meas.meta["unusual_units"] == []


@pytest.mark.parametrize("speed", ["lag1", "lag2", "lag5", "butter25Hz", "butter100Hz", "noise10mm_s", "absent"])
def test_filtered_lagged_noisy_rig_speed_passes(tmp_path, rig_frame, speed):
    # reference: a real rig's speed column is filtered (here Butterworth, 2nd order, at 1 kHz), lags the
    # encoder by a sample or more, and is noisy; its per-run regression slope on d(position)/dt stays
    # within a few percent of 1 (the band is 0.5-2)
    from scipy.signal import butter, lfilter
    df = rig_frame.copy()
    v = df["speed_m_s"].to_numpy()
    if speed.startswith("lag"):
        k = int(speed[3:])
        df["speed_m_s"] = np.concatenate([np.full(k, v[0]), v[:-k]])
    elif speed.startswith("butter"):
        b, a = butter(2, (25.0 if speed == "butter25Hz" else 100.0) / 500.0)
        df["speed_m_s"] = lfilter(b, a, v)
    elif speed == "noise10mm_s":
        df["speed_m_s"] = v + np.random.default_rng(0).normal(0.0, 0.01, v.size)
    else:
        df = df.drop(columns=["speed_m_s"])
    meas = load_measurements(write(tmp_path, df, "rig", {"slider_mass_kg": 0.12}))
    assert meas.meta["unusual_units"] == []


# ---------------------------------------------------------------------------
# what must be refused (one case per unit mistake)
# ---------------------------------------------------------------------------

def _scale(col, factor):
    return lambda df: df.assign(**{col: df[col] * factor})


MISTAKES = {
    # id: (corruption, sidecar, column or field named, fragment of the message)
    "load_grams": (_scale("load_kg", 1000.0), None, "load_kg", "grams?"),
    "load_grams_up_to_50": (lambda df: df.assign(load_kg=np.sign(df["load_kg"]) * 30.0), None, "load_kg", "grams?"),
    "time_ms": (_scale("time_s", 1000.0), None, "time_s", "time in ms?"),
    "time_ms_no_speed": (lambda df: _scale("time_s", 1000.0)(df).drop(columns=["speed_m_s"]), None, "time_s",
                         "time in ms?"),
    "voltage_kV": (_scale("voltage_V", 1e-3), None, "voltage_V", "kV?"),
    "position_x10": (_scale("position_m", 10.0), None, "speed_m_s", "position_m scaled up"),
    "position_x10_no_speed": (lambda df: _scale("position_m", 10.0)(df).drop(columns=["speed_m_s"]), None,
                              "speed_m_s", "position_m not in metres"),
    "position_cm": (_scale("position_m", 100.0), None, "position_m", "centimetres"),  # a hard limit
    "speed_unsigned": (lambda df: df.assign(speed_m_s=df["speed_m_s"].abs()), None, "speed_m_s",
                       "opposite sign"),
    "speed_mm_s_small": (_scale("speed_m_s", 1e-3), None, "speed_m_s", "disagrees with d(position_m)/dt"),
    "frequency_tenth": (_scale("frequency_Hz", 0.1), None, "frequency_Hz", "not ultrasonic"),
    "temperature_kelvin": (lambda df: df.assign(temperature_C=df["temperature_C"] + 273.15), None,
                           "temperature_C", "kelvin"),
    "slider_mass_grams": (lambda df: df, {"slider_mass_kg": 120}, "slider_mass_kg", "grams?"),
    "encoder_micrometres": (lambda df: df, {"encoder_resolution_m": 0.05}, "encoder_resolution_m", "micrometres"),
}


@pytest.mark.parametrize("case", sorted(MISTAKES))
def test_unit_mistake_is_refused_naming_column_row_and_mistake(tmp_path, case):
    corrupt, sidecar, column, fragment = MISTAKES[case]
    path = write(tmp_path, corrupt(synthetic_frame()), sidecar=sidecar)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    exc = info.value
    msg = str(exc)
    assert exc.column == column, msg
    assert fragment in msg, msg
    assert ("data.json" if sidecar else "data.csv") in msg
    assert "\n" not in msg
    if not sidecar:
        assert exc.row is not None and f"row {exc.row} (line {exc.row + 1})" in msg
    if case == "position_cm":  # beyond the hard limit (|position| > 1 m): not overridable
        with pytest.raises(DataFormatError):
            load_measurements(path, allow_unusual_units=True)
        return
    assert "--allow-unusual-units" in msg, msg
    # the explicit override accepts the file and keeps the finding
    meas = load_measurements(path, allow_unusual_units=True)
    assert any(fragment in m for m in meas.meta["unusual_units"]), meas.meta["unusual_units"]


def test_slider_mass_option_in_grams_is_a_parameter_error(tmp_path):
    path = write(tmp_path, synthetic_frame())
    with pytest.raises(ParameterError, match=r"option slider_mass_kg \[kg\].*grams\?"):
        load_measurements(path, slider_mass_kg=120.0)
    assert load_measurements(path, slider_mass_kg=120.0, allow_unusual_units=True).meta["slider_mass_kg"] == 120.0


def test_separator_and_decimal_comma_are_named(tmp_path):
    df = synthetic_frame().head(20)
    path = tmp_path / "semicolon.csv"
    df.to_csv(path, sep=";", decimal=",", index=False)
    with pytest.raises(DataFormatError, match=r"semicolon.csv: .*';' as separator and ',' as decimal mark\?"):
        load_measurements(path)
    path = tmp_path / "tab.csv"
    df.to_csv(path, sep="\t", index=False)
    with pytest.raises(DataFormatError, match=r"tab.csv: .*tab as separator"):
        load_measurements(path)


# ---------------------------------------------------------------------------
# the CLI: TEST is checked too, nothing is written, the override is recorded
# ---------------------------------------------------------------------------

def _fit_must_not_run(monkeypatch):
    from l1b2.ident import estimator

    def refuse(self, *a, **k):
        raise AssertionError("the fit ran although the input should have been refused")
    monkeypatch.setattr(estimator.PredictorIdentifier, "fit", refuse)


def test_identify_refuses_test_file_in_grams_before_fitting(tmp_path, capsys, monkeypatch):
    _fit_must_not_run(monkeypatch)
    train = write(tmp_path, synthetic_frame(), "train")
    test = write(tmp_path, _scale("load_kg", 1000.0)(synthetic_frame(seed=1)), "test")
    out = tmp_path / "out"
    code = cli_main(["identify", "--train", str(train), "--test", str(test), "--out", str(out)])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and err.startswith("l1b2: error:")
    assert "test.csv" in err and "'load_kg' [kg]" in err and "grams?" in err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == \
        ["test.csv", "test.json", "train.csv", "train.json"]


def test_close_loop_refuses_unit_mistake_in_test_file(tmp_path, capsys, monkeypatch):
    _fit_must_not_run(monkeypatch)
    train = write(tmp_path, synthetic_frame(), "train")
    test = write(tmp_path, _scale("time_s", 1000.0)(synthetic_frame(seed=1)), "test")
    out = tmp_path / "report"
    code = cli_main(["close-loop", "--train", str(train), "--test", str(test), "--report-dir", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "test.csv" in err and "time in ms?" in err
    assert not out.exists()


def test_single_run_train_names_the_file_and_the_cause(tmp_path, capsys, monkeypatch):
    _fit_must_not_run(monkeypatch)
    df = synthetic_frame()
    train = write(tmp_path, df[df["run"] == 2], "one_run")  # 220 V, no load, +1
    code = cli_main(["identify", "--train", str(train), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1
    assert "one_run.csv" in err and "1 run" in err and "'run' column" in err


def test_allow_unusual_units_is_recorded_in_the_report(tmp_path, capsys):
    train = write(tmp_path, synthetic_frame(), "train", {"slider_mass_kg": 0.0005})  # 0.5 g: unusual, allowed
    out = tmp_path / "out"
    with pytest.raises(L1B2Error):  # refused without the flag
        load_measurements(train)
    code = cli_main(["identify", "--train", str(train), "--out", str(out), "--order", "3", "--starts", "1",
                     "--test-loads", "0.05", "--no-plots", "--allow-unusual-units", "--noise", "per_run"])
    printed = capsys.readouterr().out
    assert code == 0
    rep = json.loads((out / "identification.json").read_text())
    assert rep["settings"]["noise"] == "per_run"  # the CLI's noise model reaches the fit and its report
    checks = rep["checks"]
    assert checks["allow_unusual_units"] is True
    assert any("slider_mass_kg" in m for m in checks["unusual_units"]["train"])
    assert "--allow-unusual-units accepted" in printed


@pytest.mark.parametrize("column, value", [("voltage_V", 0.0), ("load_kg", 0.05), ("direction", -1)])
def test_a_drive_input_changing_within_a_run_is_refused(tmp_path, column, value):
    # reference: the rig data format (docs/reference/data-format.md) - "a run is one continuous traverse of the slider at constant drive
    # inputs"; one corrupted cell of a set value passed every range check before
    df = synthetic_frame()
    row = int(np.flatnonzero(df["run"].to_numpy() == 2)[10])   # run 2: 220 V, no load, +1
    df.loc[row, column] = value
    path = write(tmp_path, df)
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert info.value.column == column and info.value.row == row + 1
    assert "changes within the run" in str(info.value)
    # a measured, noisy V0 (1 % ripple) is fine
    ok = synthetic_frame()
    ok["voltage_V"] = ok["voltage_V"] * (1 + 0.01 * np.sin(np.arange(len(ok))))
    assert load_measurements(write(tmp_path, ok, "noisy_v")).meta["unusual_units"] == []


def test_a_single_speed_glitch_is_refused_noise_and_steps_are_not(tmp_path, rig_frame):
    # reference: the malformed-data campaign - one speed sample replaced by -1 m/s passed every check and
    # raised the held-out nrmse from 0.44 % to 6.1 %
    df = rig_frame.copy()
    runs = df["run"].to_numpy()
    row = int(np.flatnonzero(runs == runs[0])[60])
    df.loc[row, "speed_m_s"] = -1.0
    path = write(tmp_path, df, "glitch", {"slider_mass_kg": 0.12})
    with pytest.raises(DataFormatError) as info:
        load_measurements(path)
    assert info.value.column == "speed_m_s" and info.value.row == row + 1 and "glitch" in str(info.value)
    # a noisy speed (10 mm/s white noise on top) and the end-stop steps of the rig's data are not glitches
    noisy = rig_frame.assign(speed_m_s=rig_frame["speed_m_s"] + np.random.default_rng(1).normal(0, 0.01, len(df)))
    assert load_measurements(write(tmp_path, noisy, "noisy", {"slider_mass_kg": 0.12})).meta["unusual_units"] == []
