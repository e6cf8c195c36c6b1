"""The logarithm of a logged channel that spans decades (``closeloop.logscale``): which channels, the values, the
record, its place among the derived channels. Fast tests on small frames, the rule written out."""

import math

import numpy as np
import pandas as pd
import pytest


def _frame(columns, n=3, period=2.0, t0=0.0):
    """Runs of ``n`` samples with the per-run values of ``columns`` (name -> list, one value per run)."""
    runs = len(next(iter(columns.values())))
    rows = []
    for k in range(runs):
        for i in range(n):
            row = {"time_s": t0 + k * period + 0.1 * i, "run": 1 + k, "position_m": 0.0,
                   "voltage_V": 200.0 + 20.0 * (k % 3), "direction": 1, "load_kg": 0.0, "speed_m_s": 0.1}
            row.update({name: float(v[k]) for name, v in columns.items()})
            rows.append(row)
    return pd.DataFrame(rows)


def test_a_positive_channel_over_a_decade_gets_its_logarithm_and_nothing_else_does():
    from l1b2.closeloop.logscale import SPAN_RATIO, log_candidates
    assert SPAN_RATIO == 10.0
    cols = {"shunt_Ohm": [1e3, 3e4, 1e6, 2e3, 5e5, 1e4],      # three decades
            "flow_L_min": [1.0, 10.0, 4.0, 2.0, 9.0, 5.0],    # exactly one decade: max = 10 min
            "dose_nL": [1.0, 6.0, 3.0, 2.0, 5.0, 4.0],        # positive, under a decade
            "current_A": [0.0, 8.0, 3.0, 1.0, 5.0, 2.0],      # a zero: no logarithm
            "offset_mm": [-2.0, 20.0, 3.0, 1.0, 5.0, 2.0],    # a negative value
            "case_C": [1.0, 30.0, 15.0, 2.0, 25.0, 9.0],      # an offset unit (degC), spans a decade
            "gap": [1.0, np.inf, 3.0, 2.0, 50.0, 4.0]}        # not finite
    df = _frame(cols)
    logged = list(cols)
    assert log_candidates(df, None, logged) == ["shunt_Ohm", "flow_L_min"]
    # TEST with a value that is not positive (or not finite) keeps the channel raw; TEST without the column is fine
    test = _frame({"shunt_Ohm": [1e3, 0.0], "flow_L_min": [2.0, 3.0]})
    assert log_candidates(df, test, logged) == ["flow_L_min"]
    assert log_candidates(df, _frame({"dose_nL": [1.0, 2.0]}), logged) == ["shunt_Ohm", "flow_L_min"]
    # a name the frame already has is not derived again
    assert log_candidates(df.assign(ln_flow_L_min=0.0), None, logged) == ["shunt_Ohm"]
    assert log_candidates(df, test.assign(ln_shunt_Ohm=0.0).drop(columns="shunt_Ohm"), logged) == ["flow_L_min"]


def test_the_derived_values_are_the_natural_logarithms_in_the_columns_unit():
    from l1b2.closeloop.logscale import with_log_channels
    from l1b2.units import column_unit, unit_note
    r = [1e3, 3e4, 1e6, 2e3, 5e5, 1e4]
    train, test = _frame({"shunt_Ohm": r}), _frame({"shunt_Ohm": [4e3, 2e5]}, t0=100.0)
    tr, te, rec = with_log_channels(train, test, ["shunt_Ohm"])
    np.testing.assert_allclose(tr["ln_shunt_Ohm"], [math.log(x) for x in np.repeat(r, 3)], rtol=1e-15)
    np.testing.assert_allclose(te["ln_shunt_Ohm"], [math.log(x) for x in np.repeat([4e3, 2e5], 3)], rtol=1e-15)
    assert "ln_shunt_Ohm" not in train.columns and "ln_shunt_Ohm" not in test.columns    # copies
    assert rec == [{"channel": "ln_shunt_Ohm", "from": "shunt_Ohm", "unit": "Ohm", "train_range": [1e3, 1e6],
                    "decades": pytest.approx(3.0)}]
    assert column_unit("ln_shunt_Ohm") == "1" and "shunt_Ohm in Ohm" in unit_note("ln_shunt_Ohm")
    # nothing qualifies: the same frames back, not copied
    plain = _frame({"dose_nL": [1.0, 6.0, 3.0]})
    got = with_log_channels(plain, None, ["dose_nL"])
    assert got[0] is plain and got[1] is None and got[2] == []


def test_the_logarithm_is_derived_from_logged_channels_only_and_a_logged_namesake_is_set_aside():
    from l1b2.closeloop.derived import is_derivable_name, prepare_channels, with_protocol_channels
    from l1b2.closeloop.events import session
    assert is_derivable_name("ln_shunt_Ohm", ["shunt_Ohm"]) and not is_derivable_name("ln_shunt_Ohm", ["x"])
    r = [1e3, 3e4, 1e6, 2e3, 5e5, 1e4, 3e3, 7e5, 2e4, 1e5, 6e3, 4e4]
    df = _frame({"shunt_Ohm": r})
    tr, te, rec = with_protocol_channels(df, None, (), session(df, None))
    assert [x["channel"] for x in rec["log_channels"]] == ["ln_shunt_Ohm"]
    assert "shunt_Ohm_lag3r" in tr.columns                      # the raw run setting is lagged ...
    assert not any(c.startswith("ln_") and c != "ln_shunt_Ohm" and "shunt" in c for c in tr.columns)   # ... not its log
    assert not any(c.startswith("ln_shunt_Ohm_lag") for c in tr.columns)
    # a rig's own ln_shunt_Ohm is kept under a name of its own, and the derivation runs
    own = df.assign(ln_shunt_Ohm=7.0)
    tr2, _, renamed, _ = prepare_channels(own, None)
    assert "ln_shunt_Ohm_logged" in tr2.columns and "ln_shunt_Ohm" not in tr2.columns
    assert any(x.get("from") == "ln_shunt_Ohm" for x in renamed)
    tr3, _, rec3 = with_protocol_channels(tr2, None, (), session(tr2, None))
    np.testing.assert_allclose(tr3["ln_shunt_Ohm"], np.log(tr3["shunt_Ohm"]))
