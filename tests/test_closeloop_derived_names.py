"""A logged column named like a channel the loop derives is kept under a name of its own, and the derivation runs.
Fast tests on small frames, the names written out."""

import math

import numpy as np
import pandas as pd
import pytest

DT = 0.1   # the clock's sample interval [s]


def _session(starts, n=4, extra=None):
    """Runs of ``n`` samples DT apart starting at ``starts`` [s], with the columns ``extra`` (name -> per-run
    values)."""
    rows = []
    for k, t0 in enumerate(starts):
        for i in range(n):
            row = {"time_s": t0 + DT * i, "run": 1 + k, "position_m": 0.0, "voltage_V": 200.0 + 10.0 * (k % 3),
                   "direction": 1, "load_kg": 0.0, "speed_m_s": 0.1}
            row.update({name: float(v[k]) for name, v in (extra or {}).items()})
            rows.append(row)
    return pd.DataFrame(rows)


def test_the_names_a_derivation_could_produce():
    from l1b2.closeloop.derived import is_derivable_name
    cols = ["time_s", "run", "voltage_V", "heater", "heater_since_s", "ln_pause_s", "x_lag3r"]
    assert is_derivable_name("ln_pause_s", cols)
    assert is_derivable_name("since_break_s", cols) and is_derivable_name("breaks_before", cols)
    assert is_derivable_name("heater_since_s", cols)            # the event clock of a column the frame has
    assert is_derivable_name("voltage_V_lag3r", cols)           # a lag of 3 run periods
    assert is_derivable_name("voltage_V_lag10r", cols)          # and of 10
    assert not is_derivable_name("voltage_V_lag4r", cols)       # no lag of 4 periods is ever derived
    assert not is_derivable_name("x_lag3r", cols)               # no column x
    assert is_derivable_name("voltage_V_step", cols)            # a setting's step from the previous one
    assert not is_derivable_name("door_step", cols)             # no column door
    assert not is_derivable_name("door_since_s", cols)          # no column door
    assert not is_derivable_name("heater", cols)
    assert not is_derivable_name("ln_pause", cols)


def test_a_logged_column_with_a_derivable_name_is_renamed_in_both_frames():
    from l1b2.closeloop.derived import set_aside_derivable_names
    starts = [0.0, 1.0, 2.0, 3.0]
    extra = {"ln_pause_s": [1, 2, 3, 4], "heater": [0, 0, 1, 1], "heater_since_s": [5, 6, 7, 8],
             "ln_pause_s_logged": [9, 9, 9, 9], "ambient_since_s": [1, 1, 2, 2]}
    train = _session(starts, extra=extra)
    test = _session(starts, extra=extra)
    tr, te, rec = set_aside_derivable_names(train, test)
    # ln_pause_s_logged is taken: the next free name; ambient_since_s has no column ambient: kept as it is
    assert [(r["from"], r["channel"], r["action"]) for r in rec] == [
        ("ln_pause_s", "ln_pause_s_logged2", "renamed"), ("heater_since_s", "heater_since_s_logged", "renamed")]
    for df, src in ((tr, train), (te, test)):
        assert "ln_pause_s" not in df.columns and "heater_since_s" not in df.columns
        np.testing.assert_array_equal(df["ln_pause_s_logged2"], src["ln_pause_s"])   # nothing lost
        np.testing.assert_array_equal(df["heater_since_s_logged"], src["heater_since_s"])
        assert "ambient_since_s" in df.columns and "ln_pause_s_logged" in df.columns
    assert "ln_pause_s" in train.columns                         # the inputs untouched
    clean = _session(starts, extra={"heater": [0, 0, 1, 1]})
    same_tr, same_te, none = set_aside_derivable_names(clean, None)
    assert same_tr is clean and same_te is None and none == []


def test_the_pause_channel_is_derived_beside_a_logged_column_of_its_name():
    from l1b2.closeloop.derived import prepare_channels
    from l1b2.closeloop.pauses import COLUMN, with_pause_channel
    starts = [0.0, 1.3, 6.3, 6.65, 26.65, 28.05]      # a run lasts 0.3 s: pauses 1.0, 4.7, 0.05, 19.7, 1.1
    noise = [0.3, -1.2, 0.8, 0.1, -0.4, 2.0]
    train = _session(starts, extra={COLUMN: noise})
    tr, _, rec, responses = prepare_channels(train, None, ("tip_velocity_amp_m_s",))
    assert responses == ("tip_velocity_amp_m_s",)
    assert [r["channel"] for r in rec] == [COLUMN + "_logged"]
    tr, _, prec = with_pause_channel(tr)
    assert prec["derived"]
    per_run = tr.groupby("run", sort=False)[COLUMN].first()
    pauses = [1.0, 4.7, DT, 19.7, 1.1]                 # the 0.05 s pause floored at the sample interval
    for run, p in zip(range(2, 7), pauses):
        assert per_run[run] == pytest.approx(math.log(p), abs=1e-9)
    np.testing.assert_array_equal(tr.groupby("run", sort=False)[COLUMN + "_logged"].first(), noise)


def test_a_lag_is_no_longer_written_over_a_logged_column_of_its_name():
    from l1b2.closeloop.derived import prepare_channels
    from l1b2.closeloop.lags import with_lagged_channels
    from l1b2.units import lag_suffix as suffix
    volts = [200, 220, 180, 240, 200, 260, 180, 220, 240, 200, 260, 180]
    starts = [2.0 * k for k in range(len(volts))]
    own = np.arange(len(volts), dtype=float) * 7.0
    train = _session(starts, extra={"voltage_V_lag3r": own})
    train["voltage_V"] = np.repeat(volts, 4).astype(float)
    tr, _, rec, _ = prepare_channels(train, None, ())
    tr, _, lag_rec = with_lagged_channels(tr)
    assert "voltage_V" in [r["channel"] for r in lag_rec]          # (the user's column is a run setting too)
    assert "voltage_V" + suffix(3) in tr.columns
    np.testing.assert_array_equal(tr.groupby("run", sort=False)["voltage_V_lag3r_logged"].first(), own)
    assert not np.allclose(tr["voltage_V" + suffix(3)], np.repeat(own, 4))   # the derived lag, not the user's column
