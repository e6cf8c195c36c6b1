"""Lagged channels: a logged run setting's first-order low-pass on the session clock (a store between the setting and
the motor). Fast tests against the solution written out."""

import math

import numpy as np
import pandas as pd
import pytest


def test_the_lowpass_is_the_exact_first_order_response_to_the_held_samples():
    # reference: a unit step held from t = 2 s (the sample at 2 s is the first at 1): y = 1 - exp(-(t - 2)/tau) at
    # the later samples, whatever their spacing (a 3 s pause between 4 and 7 s); before the step the start value
    from l1b2.closeloop.lags import lowpass
    tau = 1.7
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 7.0, 7.5])
    c = np.array([0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    want = [0.0, 0.0, 0.0] + [1 - math.exp(-(x - 2.0) / tau) for x in t[3:]]
    np.testing.assert_allclose(lowpass(t, c, tau), want, rtol=0, atol=1e-15)
    # a setting held at 4 and then at 0: the charge of the first, the discharge of the second
    y = lowpass([0.0, 5.0, 6.0, 9.0], [4.0, 0.0, 0.0, 0.0], 2.0)
    q = 4.0 * (1 - math.exp(-5.0 / 2.0))
    np.testing.assert_allclose(y, [4.0, 4.0, 4.0 * math.exp(-1 / 2.0), 4.0 * math.exp(-4 / 2.0)], atol=1e-14)
    assert q < 4.0   # (the start is at the first value: no charge from zero)
    with pytest.raises(ValueError, match="not positive"):
        lowpass([0.0, 1.0], [1.0, 1.0], 0.0)


def _frame(values, t0=0.0, run0=1, n=3, period=2.0):
    rows = []
    for k, v in enumerate(values):
        for i in range(n):
            rows.append({"time_s": t0 + k * period + 0.1 * i, "run": run0 + k, "position_m": 0.0, "voltage_V": 200.0,
                         "direction": 1, "load_kg": 0.0, "speed_m_s": 0.1, "heater": v, "stepped": float(k // 4)})
    return pd.DataFrame(rows)


def test_a_test_on_a_clock_of_its_own_starts_its_lags_at_its_own_first_setting():
    from l1b2.closeloop.lags import TAU_RUNS, lowpass, with_lagged_channels
    train = _frame([1.0, 2.0, 4.0, 2.0, 0.0, 4.0, 2.0, 4.0, 0.0, 2.0, 0.0, 4.0])
    test = _frame([8.0, 0.0, 6.0, 6.0], t0=0.1, run0=100)          # overlaps TRAIN in time: two sessions
    tr, te, rec = with_lagged_channels(train, test)
    assert not rec[0]["one_session"] and rec[0]["start"] == [1.0, 8.0]
    for n, tau in zip(TAU_RUNS, rec[0]["tau_s"]):
        np.testing.assert_allclose(te[f"heater_lag{n}r"], lowpass(test["time_s"], test["heater"], tau))
        np.testing.assert_allclose(tr[f"heater_lag{n}r"], lowpass(train["time_s"], train["heater"], tau))
        assert te[f"heater_lag{n}r"].iloc[0] == 8.0 and tr[f"heater_lag{n}r"].iloc[0] == 1.0


def test_a_run_setting_changes_more_often_than_a_step_channel_may():
    from l1b2.closeloop.events import run_table
    from l1b2.closeloop.lags import is_run_setting
    tab = run_table([_frame([0, 1, 1, 1, 1, 1, 1, 2])], "heater")     # 2 changes in 8 runs: once per 4, a step
    assert not is_run_setting(tab, False)
    tab = run_table([_frame([0, 1, 1, 1, 2, 2, 2, 3])], "heater")     # 3 changes in 8 runs: one more
    assert is_run_setting(tab, False) and not is_run_setting(tab, True)


def test_lags_of_one_session_continue_from_train_into_test():
    from l1b2.closeloop.lags import TAU_RUNS, lowpass, with_lagged_channels
    v = [0.0, 2.0, 4.0, 2.0, 0.0, 4.0, 2.0, 4.0, 0.0, 2.0, 0.0, 4.0]
    whole = _frame(v)
    train, test = whole.iloc[:27].reset_index(drop=True), whole.iloc[27:].reset_index(drop=True)
    tr, te, rec = with_lagged_channels(train, test)
    assert [r["channel"] for r in rec] == ["heater"]      # the stepped column is a step channel, not lagged
    assert rec[0]["start"] == [0.0]                         # one session: the first run's setting
    for n, tau in zip(TAU_RUNS, rec[0]["tau_s"]):
        assert tau == pytest.approx(2.0 * n)               # n median run periods (start to start 2 s)
        want = lowpass(whole["time_s"], whole["heater"], tau)
        np.testing.assert_allclose(np.concatenate([tr[f"heater_lag{n}r"], te[f"heater_lag{n}r"]]), want)
    assert "heater_lag3r" not in train.columns             # copies, the inputs untouched
    # no run setting: the frames come back as they are
    plain = whole.drop(columns="heater")
    a, b, r = with_lagged_channels(plain, None)
    assert a is plain and b is None and r == []


@pytest.mark.parametrize("split", [27, None])
def test_the_session_computed_once_and_passed_gives_the_same_frames_and_records(split, monkeypatch):
    # reference: each derivation computing the session itself (as before the session was passed)
    from l1b2.closeloop import events as ev
    from l1b2.closeloop.lags import with_lagged_channels
    whole = _frame([0.0, 2.0, 4.0, 2.0, 0.0, 4.0, 2.0, 4.0, 0.0, 2.0, 0.0, 4.0])
    if split is None:      # two sessions on one clock: TEST overlaps TRAIN in time
        train, test = whole, _frame([4.0, 0.0, 2.0, 2.0], t0=0.1, run0=100)
    else:
        train, test = whole.iloc[:split].reset_index(drop=True), whole.iloc[split:].reset_index(drop=True)
    a_tr, a_te, a_ev = ev.with_event_clocks(train, test)
    a_tr, a_te, a_lag = with_lagged_channels(a_tr, a_te)
    sess = ev.session(train, test)
    assert sess.one == (split is not None)
    calls = []
    monkeypatch.setattr(ev, "one_session", lambda tab: calls.append(tab) or True)   # not called once passed
    b_tr, b_te, b_ev = ev.with_event_clocks(train, test, sess=sess)
    b_tr, b_te, b_lag = with_lagged_channels(b_tr, b_te, sess=sess)
    assert calls == [] and a_ev == b_ev and a_lag == b_lag and len(a_ev) == len(a_lag) == 1
    pd.testing.assert_frame_equal(a_tr, b_tr)
    pd.testing.assert_frame_equal(a_te, b_te)


def test_the_drive_amplitude_is_lagged_when_the_plan_changes_it_from_run_to_run_and_stays_an_input():
    from l1b2.closeloop.candidates import channels_of
    from l1b2.closeloop.lags import TAU_RUNS, lowpass, run_settings, with_lagged_channels
    v = [220.0, 324.0, 255.0, 324.0, 220.0, 290.0, 255.0, 220.0]        # 7 changes in 8 runs: a run setting
    df = _frame([0.0] * 8).drop(columns=["heater", "stepped"])
    df["voltage_V"] = np.repeat(v, 3)
    assert run_settings(df) == ["voltage_V"]
    tr, _, rec = with_lagged_channels(df, None)
    assert rec[0]["channel"] == "voltage_V"
    for n, tau in zip(TAU_RUNS, rec[0]["tau_s"]):
        np.testing.assert_allclose(tr[f"voltage_V_lag{n}r"], lowpass(df["time_s"], df["voltage_V"], tau))
    names = [c["name"] for c in channels_of(tr)]
    assert "voltage_V" not in names and {"voltage_V_lag3r", "voltage_V_lag10r"} <= set(names)
    blocks = df.copy()
    blocks["voltage_V"] = np.repeat([220.0] * 4 + [324.0] * 4, 3)       # one change in 8 runs: not a run setting
    assert run_settings(blocks) == []


def test_a_settings_step_is_from_the_previous_different_setting_held_and_from_the_state_before_the_session():
    # reference: the steps written out run by run for a plan 220, 220, 324, 255, 255, 255, 324, 220 V from the drive
    # off (0 V): +220 (from 0), held, +104, -69, held, held, +69, -104
    from l1b2.closeloop.lags import setting_steps
    v = [220.0, 220.0, 324.0, 255.0, 255.0, 255.0, 324.0, 220.0]
    np.testing.assert_array_equal(setting_steps(v, 0.0), [220.0, 220.0, 104.0, -69.0, -69.0, -69.0, 69.0, -104.0])
    # a first setting equal to the state before: no step until the first change
    np.testing.assert_array_equal(setting_steps([5.0, 5.0, 7.0, 7.0, 4.0], 5.0), [0.0, 0.0, 2.0, 2.0, -3.0])
    assert setting_steps([], 0.0).shape == (0,)


def test_the_drive_amplitudes_step_crosses_from_train_into_test_and_each_session_starts_from_the_drive_off():
    from l1b2.closeloop.lags import STEP_SUFFIX, with_lagged_channels
    v = [220.0, 324.0, 324.0, 255.0, 324.0, 220.0, 290.0, 290.0, 255.0, 220.0]
    whole = _frame([0.0] * len(v)).drop(columns=["heater", "stepped"])
    whole["voltage_V"] = np.repeat(v, 3)
    col = "voltage_V" + STEP_SUFFIX
    want = [220.0, 104.0, 104.0, -69.0, 69.0, -104.0, 70.0, 70.0, -35.0, -35.0]   # written out, from 0 V
    train, test = whole.iloc[:18].reset_index(drop=True), whole.iloc[18:].reset_index(drop=True)
    tr, te, rec = with_lagged_channels(train, test)
    assert rec[0]["step"] == col and rec[0]["step_from"] == 0.0 and rec[0]["one_session"]
    got = pd.concat([tr, te]).groupby("run", sort=False)[col]
    assert (got.nunique() == 1).all()                                  # constant within each run
    np.testing.assert_array_equal(got.first(), want)
    assert col not in train.columns
    # TEST on a clock of its own (overlapping TRAIN): its first run's step is from the drive off again
    other = test.copy()
    other["time_s"] -= 12.0
    _, te2, rec2 = with_lagged_channels(train, other)
    assert not rec2[0]["one_session"]
    np.testing.assert_array_equal(te2.groupby("run", sort=False)[col].first(), [290.0, 290.0, -35.0, -35.0])


def test_a_logged_run_setting_gets_lags_but_no_step():
    # its state before the session is not known (module docstring): no column, the record says so
    from l1b2.closeloop.lags import STEP_SUFFIX, with_lagged_channels
    tr, _, rec = with_lagged_channels(_frame([0.0, 2.0, 4.0, 2.0, 0.0, 4.0, 2.0, 4.0]), None)
    assert [(r["channel"], r["step"], r["step_from"]) for r in rec] == [("heater", None, None)]
    assert not [c for c in tr.columns if c.endswith(STEP_SUFFIX)]
