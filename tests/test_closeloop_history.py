"""The previous run's load as a channel. Fast tests against the definition written out."""

import numpy as np
import pandas as pd
import pytest

DT = 0.1   # the clock's sample interval [s]


def _session(starts, loads, n=5, run0=1):
    """Runs of ``n`` samples DT apart starting at ``starts`` [s], each at its load [kg], alternating in direction."""
    rows = []
    for k, (t0, m) in enumerate(zip(starts, loads)):
        d = 1 if k % 2 == 0 else -1
        for i in range(n):
            rows.append({"time_s": t0 + DT * i, "run": run0 + k, "position_m": 0.01 * k + d * 0.01 * i,
                         "voltage_V": 250.0, "direction": d, "load_kg": m, "speed_m_s": d * 0.1})
    return pd.DataFrame(rows)


def _per_run(df, column):
    return df.groupby("run", sort=False)[column].agg(["min", "max"])


def test_each_run_reads_the_load_of_the_run_before_it_and_test_continues_the_session():
    from l1b2.closeloop.history import LOAD_COLUMN, with_previous_pass
    loads = [0.0, 0.0, 0.1, 0.1, -0.05, -0.05]       # conditions as the rig's plan: forward then backward
    whole = _session([0.0, 1.0, 2.0, 3.0, 4.0, 5.0], loads)
    train = whole[whole["run"].isin([1, 2, 4, 6])].reset_index(drop=True)
    test = whole[whole["run"].isin([3, 5])].reset_index(drop=True)
    tr, te, rec = with_previous_pass(train, test)
    assert rec["one_session"] and rec["derived"] and rec["imputed_runs"] == 1
    known_train = [loads[0], loads[2], loads[4]]       # the runs before runs 2, 4 and 6 (3 and 5 are TEST's)
    want = {1: float(np.median(known_train)), 2: loads[0], 3: loads[1], 4: loads[2], 5: loads[3], 6: loads[4]}
    for df in (tr, te):
        got = _per_run(df, LOAD_COLUMN)
        assert (got["min"] == got["max"]).all()
        for run, v in got["min"].items():
            assert v == pytest.approx(want[run], abs=1e-12)
    assert LOAD_COLUMN not in train.columns and LOAD_COLUMN not in test.columns
    assert rec["range"]["min"] == pytest.approx(-0.05) and rec["range"]["max"] == pytest.approx(0.1)


def test_frames_of_their_own_sessions_are_ordered_each_on_its_own():
    from l1b2.closeloop.history import LOAD_COLUMN, with_previous_pass
    train = _session([0.0, 1.0, 2.0, 3.0], [0.0, 0.05, 0.1, 0.02])
    test = _session([0.2, 1.2], [0.3, 0.4], run0=11)   # overlaps TRAIN's clock: its own session
    tr, te, rec = with_previous_pass(train, test)
    assert not rec["one_session"] and rec["imputed_runs"] == 2
    fill = 0.05                                        # TRAIN's median of 0.0, 0.05, 0.1
    assert _per_run(tr, LOAD_COLUMN)["min"].tolist() == pytest.approx([fill, 0.0, 0.05, 0.1])
    assert _per_run(te, LOAD_COLUMN)["min"].tolist() == pytest.approx([fill, 0.3])


def test_not_derived_with_too_few_or_constant_loads_or_a_logged_column_of_its_name():
    from l1b2.closeloop.history import LOAD_COLUMN, MIN_KNOWN_RUNS, with_previous_pass
    few = _session([0.0, 1.0, 2.0][:MIN_KNOWN_RUNS], [0.0, 0.05, 0.1][:MIN_KNOWN_RUNS])
    tr, _, rec = with_previous_pass(few)               # MIN_KNOWN_RUNS runs: one fewer known previous load
    assert not rec["derived"] and tr is few
    same = _session([0.0, 1.0, 2.0, 3.0, 4.0], [0.05] * 5)
    tr, _, rec = with_previous_pass(same)
    assert not rec["derived"] and LOAD_COLUMN not in tr.columns
    logged = _session([0.0, 1.0, 2.0, 3.0, 4.0], [0.0, 0.05, 0.1, 0.02, 0.07]).assign(**{LOAD_COLUMN: 1.0})
    tr, _, rec = with_previous_pass(logged)
    assert not rec["derived"] and (tr[LOAD_COLUMN] == 1.0).all()


def test_a_logged_column_of_its_name_is_set_aside_and_the_channel_derived_beside_it():
    from l1b2.closeloop.derived import prepare_channels, with_protocol_channels
    from l1b2.closeloop.events import session
    from l1b2.closeloop.history import LOAD_COLUMN
    df = _session([0.0, 1.0, 2.0, 3.0, 4.0], [0.0, 0.05, 0.1, 0.02, 0.07]).assign(**{LOAD_COLUMN: 1.0})
    sess = session(df)
    tr, _, aux, _ = prepare_channels(df, None, ())
    assert LOAD_COLUMN + "_logged" in tr.columns and any(r.get("from") == LOAD_COLUMN for r in aux)
    tr, _, recs = with_protocol_channels(tr, None, (), sess)
    assert recs["previous_pass"]["derived"]
    assert _per_run(tr, LOAD_COLUMN)["min"].tolist()[1:] == pytest.approx([0.0, 0.05, 0.1, 0.02])
    assert set(recs) == {"event_clocks", "lagged_channels", "pause_channel", "break_clock", "previous_pass",
                         "run_clock", "run_travel", "log_channels", "run_settings"}
