"""The previous run as channels: the mean speed of the last pass at another setting, and the previous run's load.
Fast tests against the definitions written out."""

import numpy as np
import pandas as pd
import pytest

DT = 0.1   # the clock's sample interval [s]


def _session(starts, speeds, n=5, run0=1, volts=None, loads=None):
    """Runs of ``n`` samples DT apart starting at ``starts`` [s], each moving at its speed [m/s] (signed by an
    alternating direction), from a position that differs per run; every run at its own setting unless ``volts`` /
    ``loads`` say otherwise."""
    rows = []
    for k, (t0, v) in enumerate(zip(starts, speeds)):
        d = 1 if k % 2 == 0 else -1
        V = 200.0 + 10.0 * (run0 + k) if volts is None else volts[k]
        m = 0.0 if loads is None else loads[k]
        for i in range(n):
            rows.append({"time_s": t0 + DT * i, "run": run0 + k, "position_m": 0.01 * k + d * v * DT * i,
                         "voltage_V": V, "direction": d, "load_kg": m, "speed_m_s": d * v})
    return pd.DataFrame(rows)


def _per_run(df, column):
    return df.groupby("run", sort=False)[column].agg(["min", "max"])


def test_run_speed_is_the_stroke_over_the_duration():
    from l1b2.closeloop.history import run_speeds_m_s
    df = _session([0.0, 2.0], [0.05, 0.12])
    df = df.sample(frac=1.0, random_state=3)           # any row order: each run in time order
    got = run_speeds_m_s(df)
    assert got.loc[1] == pytest.approx(0.05) and got.loc[2] == pytest.approx(0.12)
    one = _session([0.0], [0.05], n=1)
    assert np.isnan(run_speeds_m_s(one).loc[1])        # a run of zero duration has no speed


def test_each_run_reads_the_speed_of_the_run_before_it_and_test_continues_the_session():
    from l1b2.closeloop.history import COLUMN, with_previous_pass
    speeds = [0.05, 0.08, 0.11, 0.03, 0.07, 0.09]
    whole = _session([0.0, 1.0, 2.0, 3.0, 4.0, 5.0], speeds)
    train = whole[whole["run"].isin([1, 2, 4, 6])].reset_index(drop=True)
    test = whole[whole["run"].isin([3, 5])].reset_index(drop=True)
    tr, te, rec = with_previous_pass(train, test)
    rec = dict(rec["columns"][0], one_session=rec["one_session"])
    assert rec["derived"] and rec["one_session"] and rec["imputed_runs"] == 1
    known_train = [speeds[0], speeds[2], speeds[4]]    # the passes before runs 2, 4 and 6 (3 and 5 are TEST's)
    want = {1: float(np.median(known_train)), 2: speeds[0], 3: speeds[1], 4: speeds[2], 5: speeds[3],
            6: speeds[4]}
    for df in (tr, te):
        got = _per_run(df, COLUMN)
        assert (got["min"] == got["max"]).all()
        for run, v in got["min"].items():
            assert v == pytest.approx(want[run], abs=1e-12)
    assert COLUMN not in train.columns and COLUMN not in test.columns
    assert rec["range"]["min"] == pytest.approx(0.05) and rec["range"]["max"] == pytest.approx(0.11)


def test_frames_of_their_own_sessions_are_ordered_each_on_its_own():
    from l1b2.closeloop.history import COLUMN, with_previous_pass
    train = _session([0.0, 1.0, 2.0, 3.0], [0.05, 0.08, 0.11, 0.03])
    test = _session([0.2, 1.2], [0.2, 0.3], run0=11)   # overlaps TRAIN's clock: its own session
    tr, te, rec = with_previous_pass(train, test)
    rec = dict(rec["columns"][0], one_session=rec["one_session"])
    assert rec["derived"] and not rec["one_session"] and rec["imputed_runs"] == 2
    fill = 0.08                                        # TRAIN's median of 0.05, 0.08, 0.11
    assert _per_run(tr, COLUMN)["min"].tolist() == pytest.approx([fill, 0.05, 0.08, 0.11])
    assert _per_run(te, COLUMN)["min"].tolist() == pytest.approx([fill, 0.2])


def test_not_derived_with_too_few_or_constant_passes_or_a_logged_column_of_its_name():
    from l1b2.closeloop.history import COLUMN, MIN_KNOWN_RUNS, with_previous_pass
    few = _session([0.0, 1.0, 2.0][:MIN_KNOWN_RUNS], [0.05, 0.08, 0.11][:MIN_KNOWN_RUNS])
    tr, _, rec = with_previous_pass(few)               # MIN_KNOWN_RUNS runs: one fewer known previous pass
    assert not rec["columns"][0]["derived"] and tr is few
    same = _session([0.0, 1.0, 2.0, 3.0, 4.0], [0.05] * 5)
    tr, _, rec = with_previous_pass(same)
    assert not rec["columns"][0]["derived"] and COLUMN not in tr.columns
    logged = _session([0.0, 1.0, 2.0, 3.0, 4.0], [0.05, 0.08, 0.11, 0.03, 0.07]).assign(**{COLUMN: 1.0})
    tr, _, rec = with_previous_pass(logged)
    assert not rec["columns"][0]["derived"] and (tr[COLUMN] == 1.0).all()


def test_a_logged_column_of_its_name_is_set_aside_and_the_channel_derived_beside_it():
    from l1b2.closeloop.derived import prepare_channels, with_protocol_channels
    from l1b2.closeloop.events import session
    from l1b2.closeloop.history import COLUMN
    df = _session([0.0, 1.0, 2.0, 3.0, 4.0], [0.05, 0.08, 0.11, 0.03, 0.07]).assign(**{COLUMN: 1.0})
    sess = session(df)
    tr, _, aux, _ = prepare_channels(df, None, ())
    assert COLUMN + "_logged" in tr.columns and any(r.get("from") == COLUMN for r in aux)
    tr, _, recs = with_protocol_channels(tr, None, (), sess)
    assert recs["previous_pass"]["columns"][0]["derived"]
    assert _per_run(tr, COLUMN)["min"].tolist()[1:] == pytest.approx([0.05, 0.08, 0.11, 0.03])
    assert set(recs) == {"event_clocks", "lagged_channels", "pause_channel", "break_clock", "previous_pass", "run_clock"}


def test_the_pass_skips_runs_at_the_runs_own_setting_and_the_load_is_the_previous_runs():
    from l1b2.closeloop.history import COLUMN, LOAD_COLUMN, with_previous_pass
    # conditions as the rig's plan: each (V0, load) a forward then a backward run
    volts = [200.0, 200.0, 250.0, 250.0, 300.0, 300.0, 220.0, 220.0]
    loads = [0.0, 0.0, 0.1, 0.1, -0.1, -0.1, 0.05, 0.05]
    speeds = [0.10, 0.09, 0.15, 0.14, 0.20, 0.19, 0.12, 0.11]
    df = _session([2.0 * k for k in range(8)], speeds, volts=volts, loads=loads)
    tr, _, rec = with_previous_pass(df)
    assert [c["derived"] for c in rec["columns"]] == [True, True]
    got = _per_run(tr, COLUMN)["min"].tolist()
    # each run reads the backward run of the condition before (a backward run skips its forward twin)
    known = [0.09, 0.09, 0.14, 0.14, 0.19, 0.19]
    fill = float(np.median(known))
    assert got == pytest.approx([fill, fill] + known)
    assert rec["columns"][0]["imputed_runs"] == 2
    # the load: the run just before, twin or not
    assert _per_run(tr, LOAD_COLUMN)["min"].tolist() == pytest.approx([float(np.median(loads[:-1]))] + loads[:-1])


def test_one_setting_allows_a_logged_amplitudes_scatter():
    from l1b2.closeloop.history import SAME_LOAD_KG, SAME_VOLTAGE_REL, same_setting
    assert same_setting((300.0, 0.1), (300.0 * (1 + 0.9 * SAME_VOLTAGE_REL), 0.1))
    assert not same_setting((300.0, 0.1), (300.0 * (1 + 1.1 * SAME_VOLTAGE_REL), 0.1))
    assert same_setting((300.0, 0.1), (300.0, 0.1 + 0.9 * SAME_LOAD_KG))
    assert not same_setting((300.0, 0.1), (300.0, 0.1 + 1.1 * SAME_LOAD_KG))
    assert not same_setting((300.0, 0.1), (300.0, -0.1))                # the load's side is part of the setting
