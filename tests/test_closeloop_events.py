"""Event clocks of logged step channels (``l1b2.closeloop.events``), each against a rule written out here.

Fast unit tests: an event clock that restarts one sample late or early (``searchsorted`` on the wrong side), events
taken at the wrong run, a step rule off by one block, TEST's events not merged with TRAIN's, or two sessions on
one clock merged, fails one of them; one shows on run-level deviations that relax after each event that the
event clock explains them where the channel itself and the session clock do not; the last one that of two
correlated run-level signals the one that only follows the cause ranks after it (``runlevel.dominated_signals``).
"""

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import events as ev
from l1b2.closeloop import runlevel as rl
from l1b2.closeloop.candidates import channels_of


def _frame(values, *, t0=0.0, run0=1, n=4, dt=0.1, gap=1.0, extra=None):
    """Runs of ``n`` samples ``dt`` apart and ``gap`` s between runs, the step column ``count`` = ``values[k]``
    in run k; ``extra``: more per-run columns (one value per run) or per-sample ones (callables of the sample)."""
    rows, t = [], t0
    for k, v in enumerate(values):
        tt = t + dt * np.arange(n)
        row = {"time_s": tt, "run": run0 + k, "position_m": 0.001 * np.arange(n), "voltage_V": 220.0,
               "direction": 1, "load_kg": 0.0, "speed_m_s": 0.01, "count": float(v)}
        for name, vals in (extra or {}).items():
            row[name] = vals(k, tt) if callable(vals) else float(vals[k])
        rows.append(pd.DataFrame(row))
        t = tt[-1] + gap
    return pd.concat(rows, ignore_index=True)


def test_the_event_clock_restarts_at_each_event_and_counts_from_the_session_start_before_the_first():
    t = np.array([0.0, 4.0, 10.0, 10.5, 19.9, 20.0, 27.0])
    assert ev.since_event(t, [10.0, 20.0], 0.0) == pytest.approx([0.0, 4.0, 0.0, 0.5, 9.9, 0.0, 7.0])
    assert ev.since_event(t, [], -3.0) == pytest.approx(t + 3.0)


def test_events_are_the_starts_of_the_runs_whose_value_differs_from_the_run_before():
    tab = pd.DataFrame({"start": [0.0, 2.0, 4.0, 6.0, 8.0, 10.0], "stop": [1.0, 3.0, 5.0, 7.0, 9.0, 11.0],
                        "value": [0, 0, 1, 1, 1, 0]})
    assert ev.event_times(tab) == pytest.approx([4.0, 10.0])
    assert ev.one_session(tab)
    assert not ev.one_session(tab.assign(start=[0.0, 2.0, 4.0, 6.0, 8.5, 8.9]))   # run 6 starts before 5 stops


def test_a_step_channel_changes_at_least_once_and_at_most_once_per_block_of_runs():
    n = 16
    steps = np.repeat([0, 1, 2, 3, 4], [4, 3, 3, 3, 3])    # 4 changes in 16 runs: one per MIN_BLOCK_RUNS runs
    more = np.repeat([0, 1, 2, 3, 4, 5], [3, 3, 3, 3, 2, 2])  # 5 changes: blocks too short
    df = _frame(steps, extra={"more": more, "per_run": np.arange(n) % 2, "const": np.zeros(n),
                              "drifting": lambda k, tt: tt})
    assert ev.MIN_BLOCK_RUNS == 4
    assert ev.step_channels(df) == ["count"]
    assert ev.step_channels(df, response_columns=("count",)) == []     # a response is never a cause


def test_train_and_test_of_one_session_place_the_events_together():
    values = [0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 2]
    whole = _frame(values)
    test_runs = {4, 8, 9}                                # run 4 is the first after the first event
    train = whole[~whole["run"].isin(test_runs)].reset_index(drop=True)
    test = whole[whole["run"].isin(test_runs)].reset_index(drop=True)
    tr, te, rec = ev.with_event_clocks(train, test)
    starts = whole.groupby("run")["time_s"].min()
    assert rec[0]["channel"] == "count" and rec[0]["clock"] == "count_since_s" and rec[0]["one_session"]
    assert rec[0]["events_s"] == pytest.approx([starts[4], starts[8]])     # run 4 is TEST's, run 8 TEST's too
    expect = ev.since_event(whole["time_s"].to_numpy(), [starts[4], starts[8]], 0.0)
    got = pd.concat([tr, te]).sort_values("time_s")["count_since_s"].to_numpy()
    assert got == pytest.approx(expect)
    assert te.loc[te["run"] == 4, "count_since_s"].iloc[0] == 0.0
    assert "count_since_s" not in train.columns                          # the caller's frames are not changed


def test_two_sessions_on_one_clock_are_derived_each_from_its_own_runs():
    train = _frame([0, 0, 0, 0, 1, 1, 1, 1])
    test = _frame([5, 5, 6, 6], t0=1.4, run0=100)                         # overlaps TRAIN's runs in time
    tr, te, rec = ev.with_event_clocks(train, test)
    assert not rec[0]["one_session"]
    t = test["time_s"].to_numpy()
    start = test.groupby("run")["time_s"].min()
    assert te["count_since_s"].to_numpy() == pytest.approx(ev.since_event(t, [start[102]], t[0]))
    _, te, _ = ev.with_event_clocks(train, test.drop(columns="count"))   # not logged there: no clock to derive
    assert "count_since_s" not in te.columns


def test_no_step_channel_leaves_the_frames_as_they_are_and_the_clock_is_a_logged_channel():
    df = _frame(np.arange(8))                              # changes every run: a run-level channel
    tr, te, rec = ev.with_event_clocks(df, None)
    assert tr is df and te is None and rec == []
    tr, _, _ = ev.with_event_clocks(_frame([0, 0, 0, 0, 1, 1, 1, 1]))
    ch = {c["name"]: c for c in channels_of(tr)}["count_since_s"]
    assert ch["kind"] == "logged" and ch["within_run"]


def test_deviations_that_relax_after_each_event_are_explained_by_the_event_clock_not_the_channel_or_the_clock():
    rng = np.random.default_rng(3)
    blocks = np.repeat(np.arange(4), [14, 18, 12, 16])
    n = len(blocks)
    since = np.array([k - np.flatnonzero(blocks == blocks[k])[0] for k in range(n)], float)
    relax = 1 - np.exp(-since / 5.0)                      # a relaxation restarting at each event (runs)
    S = np.array([[4e-4, 0.0], [0.0, 0.01]])
    theta = (np.array([1.0, 0.0]) + np.outer(relax, [0.0, 0.6])
             + rng.multivariate_normal([0, 0], np.diag([1e-4, 4e-3]), n) + rng.multivariate_normal([0, 0], S, n))
    dev = rl.RunDeviations(np.arange(n), theta, np.repeat(S[None], n, axis=0), np.full(n, 500))
    t = 1.3 * np.arange(n)
    sigs = [{"channel": "count", "transform": "none", "values": blocks.astype(float)},
            {"channel": "count_since_s", "transform": "none", "values": 1.3 * since},
            {"channel": "time_s", "transform": "none", "values": t}]
    got = {e.channel: e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=5, seed=0, session_order=t)}
    assert got["count_since_s"].significant and got["count_since_s"].cv_gain > 0.3
    assert not got["count"].significant and not got["time_s"].significant


def test_a_correlated_signal_that_only_follows_the_cause_is_dominated_and_ranks_after_it():
    rng = np.random.default_rng(11)
    n = 56
    cause, other = rng.normal(size=n), rng.normal(size=n)
    decoy = 0.85 * cause + 0.53 * rng.normal(size=n)          # r ~ 0.85 over runs, acts on nothing
    S = np.array([[4e-4, 0.0], [0.0, 0.01]])
    theta = (np.array([1.0, 0.0]) + np.outer(cause, [0.0, 0.3]) + np.outer(other, [0.015, 0.0])
             + rng.multivariate_normal([0, 0], np.diag([1e-4, 4e-3]), n) + rng.multivariate_normal([0, 0], S, n))
    dev = rl.RunDeviations(np.arange(n), theta, np.repeat(S[None], n, axis=0), np.full(n, 500))
    # the decoy's evidence given the cause is none, the cause's given the decoy remains (written-out Wald test)
    assert rl.conditional_p(dev, decoy, cause) > 0.01 and rl.conditional_p(dev, cause, decoy) < 1e-6
    # given an unrelated signal, a signal keeps its own evidence (the joint fit only adds independent columns)
    marginal = {e.channel: e for e in rl.signal_evidence(dev, [{"channel": "cause", "transform": "none",
                                                                 "values": cause}], alpha=0.01, k=4, seed=0)}
    assert np.log(rl.conditional_p(dev, (cause - cause.mean()) / cause.std(), other)) == pytest.approx(
        np.log(marginal["cause"].p_value), rel=0.2)
    sigs = [{"channel": "decoy", "transform": "none", "values": 25 + 4 * decoy},   # listed first on purpose
            {"channel": "cause", "transform": "none", "values": 25 + 4 * cause},
            {"channel": "other", "transform": "none", "values": other}]
    got = rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)
    by = {e.channel: e for e in got}
    assert all(e.significant for e in got)
    assert by["decoy"].dominated_by == "cause" and by["cause"].dominated_by is None
    assert by["other"].dominated_by is None                    # uncorrelated with both: never compared
    assert by["other"].p_value > by["decoy"].p_value           # weaker on its own, yet ranked before the decoy
    assert [e.channel for e in got] == ["cause", "other", "decoy"]
    assert by["decoy"].to_dict()["dominated_by"] == "cause"
    summary = rl.RunLevelAnalysis(dev, None, np.nan, np.nan, got, 0.01).to_dict()   # the report's run_level entry
    assert summary["significant_signals"] == ["cause", "other", "decoy"]
    assert summary["dominated_signals"] == {"decoy": "cause"}


def _lowpass_runs(x, n_runs, reset):
    """A first-order low-pass over run periods (``y += (x - y) / n_runs``) from ``x[0]``, restarted at run
    ``reset`` (written out here as the derived ``X_lag<n>r`` channel of a session with one break)."""
    out, y = np.empty(len(x)), float(x[0])
    for k, v in enumerate(x):
        y = float(v) if k == reset else y
        y += (v - y) / n_runs
        out[k] = y
    return out


def test_a_setting_history_contests_another_signal_beyond_its_source():
    """Runs deviate with the drive amplitude and by a step after a break. The amplitude's 10-run low-pass restarts
    at the break, so it follows both. Against the break's count alone it is the stronger (it also carries the
    amplitude); beyond the amplitude, its only own evidence is its memory, and the count's step is the stronger:
    with the signals' sources known the count dominates the low-pass, not the reverse."""
    from l1b2.units import history_source
    assert history_source("voltage_V_lag10r") == history_source("voltage_V_step") == "voltage_V"
    assert history_source("breaks_before") is None and history_source("ln_pause_s") is None
    rng = np.random.default_rng(4)
    n, k = 56, 24
    V = np.repeat([255.0, 290.0, 220.0, 324.0, 220.0, 255.0, 324.0, 290.0], 7)
    B = (np.arange(n) >= k).astype(float)
    L = _lowpass_runs(V, 10, k)
    S = np.array([[4e-4, 0.0], [0.0, 0.01]])
    theta = (np.array([1.0, 0.0]) + np.outer((V - V.mean()) / V.std(), [0.0, 0.3]) + np.outer(B, [0.0, 0.25])
             + rng.multivariate_normal([0, 0], np.diag([1e-4, 4e-3]), n) + rng.multivariate_normal([0, 0], S, n))
    dev = rl.RunDeviations(np.arange(n), theta, np.repeat(S[None], n, axis=0), np.full(n, 500))
    sigs = [{"channel": "voltage_V", "transform": "none", "values": V},
            {"channel": "voltage_V_lag10r", "transform": "none", "values": L},
            {"channel": "breaks_before", "transform": "none", "values": B}]
    zs = [s["values"] for s in sigs]
    assert rl.history_sources([s["channel"] for s in sigs]) == [None, 0, None]
    assert rl.run_correlation(L, B) >= rl.DOMINANCE_CORR > rl.run_correlation(V, B)
    # the pair alone: the low-pass's evidence beyond the count is the stronger
    assert rl.dominated_signals(dev, [True] * 3, zs, 0.003) == [None, None, 1]
    # beyond the amplitude too (written out: both conditional tests hold the source's signal)
    pl = rl.conditional_p(dev, L, np.column_stack([B, V]))
    pb = rl.conditional_p(dev, B, np.column_stack([L, V]))
    assert pb < pl
    got = {e.channel: e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)}
    assert all(e.significant for e in got.values())
    assert got["voltage_V_lag10r"].dominated_by == "breaks_before" and got["breaks_before"].dominated_by is None
    # a source that is not significant is not held: the pair's own contest decides
    assert rl.dominated_signals(dev, [False, True, True], zs, 0.003, sources=[None, 0, None]) == [None, None, 1]
