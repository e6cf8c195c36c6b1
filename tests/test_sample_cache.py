"""SampleData reads a Measurements' arrays once per instance and shares them read-only."""
import numpy as np
import pytest

from l1b2.data.measurements import Measurements
from l1b2.ident import problem
from l1b2.ident.problem import SampleData


def _frame(n_runs=3, n=40):
    import pandas as pd
    rows = []
    t0 = 0.0
    for r in range(n_runs):
        t = t0 + np.arange(n) * 1e-3
        s = -0.01 + 0.2 * (t - t0)
        rows.append(pd.DataFrame({"time_s": t, "run": r, "position_m": s, "voltage_V": 200.0 + 20 * r,
                                  "direction": 1, "load_kg": 0.0, "speed_m_s": 0.2}))
        t0 = t[-1] + 0.5
    return pd.concat(rows, ignore_index=True)


def test_measurements_arrays_are_read_once_and_read_only(monkeypatch, tmp_path):
    meas = Measurements(_frame(), {"slider_mass_kg": 0.1}, tmp_path / "x.csv")
    calls = []
    real = problem._read_arrays
    monkeypatch.setattr(problem, "_read_arrays", lambda *a: calls.append(1) or real(*a))
    a = SampleData(meas)
    b = SampleData(meas, mask=np.arange(len(meas.df)) % 2 == 0)
    assert len(calls) == 1                       # second build reuses the first's arrays
    assert a.v is b.v and a.layout is b.layout
    assert b.mask.sum() == len(meas.df) // 2 and a.mask.all()
    with pytest.raises(ValueError):
        a.v[0] = 1.0                             # shared arrays cannot be changed through one user
    np.testing.assert_array_equal(a.s, meas.df["position_m"].to_numpy())


def test_dataframes_are_read_each_time(monkeypatch):
    df = _frame()
    calls = []
    real = problem._read_arrays
    monkeypatch.setattr(problem, "_read_arrays", lambda *a: calls.append(1) or real(*a))
    SampleData(df)
    SampleData(df)
    assert len(calls) == 2                       # a DataFrame may change between calls: never cached
