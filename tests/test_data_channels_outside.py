"""Logged channels that TEST takes outside TRAIN's values: flagged per run against the rule written out."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest


def _frame(values, noise=0.0, run0=1, seed=0, n=20, col="aux_temp_C"):
    """Runs of ``n`` samples with ``col`` at each run's value plus Gaussian noise of sd ``noise``."""
    rng = np.random.default_rng(seed)
    rows = []
    for k, v in enumerate(values):
        for i in range(n):
            rows.append({"run": run0 + k, "time_s": 10.0 * k + 0.01 * i, "position_m": 0.0, "voltage_V": 200.0,
                         "direction": 1.0, "load_kg": 0.0, "speed_m_s": 0.1, "counter": 1000 * k + i,
                         col: v + noise * rng.standard_normal()})
    return pd.DataFrame(rows)


def test_a_channel_constant_in_train_is_flagged_in_the_test_runs_that_differ():
    from l1b2.data.coverage import channel_outside_lines, channels_outside
    train = _frame([25.0] * 6)
    test = _frame([25.0, 31.0, 35.0, 25.0], run0=11)
    got = channels_outside(train, test)
    assert [r["channel"] for r in got] == ["aux_temp_C"]
    r = got[0]
    assert r["constant_in_train"] and r["train"] == [25.0, 25.0] and r["test"] == [31.0, 35.0]
    assert (r["runs_outside"], r["test_runs"], r["first_run"]) == (2, 4, 12)
    line = channel_outside_lines(got)[0]
    assert "`aux_temp_C`" in line and "constant at 25" in line and "2 of 4 runs" in line and "first run 12" in line


def test_the_tolerance_is_the_largest_of_range_share_noise_and_rounding():
    from l1b2.data.coverage import DEFAULT_TOLERANCE, NOISE_SDS, channels_outside
    train = _frame([20.0, 30.0])                                 # width 10: range tolerance 0.2
    tol = DEFAULT_TOLERANCE * 10.0
    inside = _frame([30.0 + 0.9 * tol, 20.0 - 0.9 * tol], run0=11)
    outside = _frame([30.0 + 1.1 * tol], run0=11)
    assert channels_outside(train, inside) == []
    assert [r["runs_outside"] for r in channels_outside(train, outside)] == [1]
    noisy = _frame([25.0] * 8, noise=0.5, seed=1)              # constant, with a sensor's scatter
    sd = float(np.median(noisy.groupby("run")["aux_temp_C"].std(ddof=1)))
    med = noisy.groupby("run")["aux_temp_C"].median()
    lo, hi = med.min(), med.max()
    near = _frame([hi + 0.8 * NOISE_SDS * sd], run0=11)         # within the noise's band: no change
    far = _frame([hi + 1.2 * NOISE_SDS * sd], run0=11)
    assert channels_outside(noisy, near) == []
    got = channels_outside(noisy, far)
    assert len(got) == 1 and got[0]["test"][0] == pytest.approx(hi + 1.2 * NOISE_SDS * sd)
    assert got[0]["train"] == pytest.approx([lo, hi])


def test_model_inputs_and_non_numeric_or_missing_channels_are_not_read():
    from l1b2.data.coverage import channels_outside
    train = _frame([25.0] * 4)
    test = _frame([25.0] * 3, run0=11).assign(voltage_V=300.0, label="x", only_test=5.0)
    assert channels_outside(train, test) == []


def test_the_check_is_in_input_checks_and_its_lines():
    from l1b2.data.coverage import channels_outside, data_check_lines, input_checks
    from l1b2.data.measurements import Measurements
    train = Measurements(_frame([25.0] * 4), {}, Path("train.csv"))
    test = Measurements(_frame([40.0] * 2, run0=11), {}, Path("test.csv"))
    checks = input_checks(train, test)
    assert checks["channels_outside"] == channels_outside(train, test) != []
    assert any("`aux_temp_C`" in line for line in data_check_lines(checks))
