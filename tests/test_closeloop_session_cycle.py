"""A cycle of the session (issue 28, items 2, 3 and 7): the family ``session_cycle`` and the run-level analysis's
period search (l1b2.closeloop.cycle, l1b2.closeloop.runlevel).

Fast unit tests (seconds), each against a formula written out here: the cycle's waves and centred columns, the
family's force ``(a (cos - m_c) + b (sin - m_s)) V0/V_ref``, the periods' grid, the waves less their line in the
session clock, the search's pick and its correction of the p-value, the evidence of a cycle on the gain, the
candidate a significant cycle offers; and the search on made deviations: the period found where a cycle was made,
nothing significant for a drift or for no change at all.
"""

import numpy as np
import pytest
from l1b2.closeloop import cycle as cyc
from l1b2.closeloop import runlevel as rl
from l1b2.closeloop import runstats as rs
from l1b2.closeloop.acceptance import time_dependent
from l1b2.closeloop.candidates import CandidateForce
from l1b2.closeloop.reml import reml
from l1b2.predictor import effects as fx
from l1b2.predictor.effects import cycle as fc
from l1b2.predictor.effects.base import V_REF
from l1b2.predictor.effects.channels import export_problem


def test_the_waves_are_the_cosine_and_sine_of_the_session_clock_over_the_period():
    t = np.array([0.0, 10.0, 25.0, 40.0])
    P = 40.0
    want = np.column_stack([np.cos(2 * np.pi * t / P), np.sin(2 * np.pi * t / P)])
    np.testing.assert_allclose(fc.cycle_waves(t, P), want, atol=1e-15)
    np.testing.assert_allclose(fc.cycle_waves(t, P)[:3], [[1, 0], [0, 1], [-np.sqrt(0.5), -np.sqrt(0.5)]], atol=1e-12)
    np.testing.assert_allclose(fc.cycle_columns(t, P, (0.25, -0.5)), want - [0.25, -0.5], atol=1e-15)


def test_the_family_scales_the_drive_force_by_the_centred_waves_and_reads_the_session_clock():
    h = fx.family("session_cycle").hypotheses([{"period_s": 40.0, "means": (0.25, -0.5)}])[0]
    assert h.family == "session_cycle(40.0 s)" and h.regressor == "session_cycle" and h.generic
    assert h.names == ("cycle_cos_run_gain", "cycle_sin_run_gain") and h.units == ("N", "N")
    assert h.spec == {"kind": "session_cycle", "channel": "time_s", "period_s": 40.0, "cos_mean": 0.25,
                      "sin_mean": -0.5}
    V0 = np.array([220.0, 324.0, 290.0, 255.0])
    t = np.array([0.0, 10.0, 25.0, 40.0])
    x = {"V0": V0, "d": np.array([1.0, -1.0, 1.0, -1.0]), "run:time_s": t}
    F = fx.effect_features(h.spec, x)
    want = np.column_stack([np.cos(2 * np.pi * t / 40.0) - 0.25, np.sin(2 * np.pi * t / 40.0) + 0.5])
    np.testing.assert_allclose(F, want * (V0 / V_REF)[:, None], atol=1e-14)
    assert fx.family("session_cycle").width(h.spec) == 2
    assert "run:time_s" in fx.needs(h.spec)
    assert export_problem(h.spec) == "the family 'session_cycle' is not exportable"    # no session clock input
    assert fx.family("session_cycle").session_average                                 # the calibrated model: out
    c = CandidateForce(h.family + "[run]", h.regressor, "run", h.names, h.units, features=None, spec=h.spec)
    assert time_dependent(c)          # cross-validated over blocks of the session: the cycle must carry over
    assert rl.is_run_level(c) and not rl.is_last_resort(c)
    for bad in (0.0, -3.0, float("nan")):
        with pytest.raises(fx.EffectSpecError, match="period"):
            fc.cycle_spec(bad, 0.0, 0.0)


def test_the_periods_run_from_the_sessions_span_to_three_runs_in_steps_of_a_third_of_its_frequency():
    t = np.array([0.0, 1.0, 3.0, 4.0, 6.0, 8.0, 9.0, 12.0, 14.0, 15.0, 18.0, 21.0])   # median step 2 s, span 21 s
    S, dt = 21.0, 2.0
    f = [1 / S + j / (3 * S) for j in range(100) if 1 / S + j / (3 * S) <= 1 / (3 * dt) * (1 + 1e-12)]
    np.testing.assert_allclose(cyc.periods_s(t), 1 / np.array(f), rtol=1e-12)
    assert cyc.periods_s(t)[0] == pytest.approx(S) and cyc.periods_s(t)[-1] >= 3 * dt
    np.testing.assert_allclose(cyc.periods_s(t[::-1]), cyc.periods_s(t))               # any order of the runs
    assert len(cyc.periods_s(t[:7])) == 0                                              # too few runs
    assert len(cyc.periods_s(np.zeros(12))) == 0                                       # no span


def test_the_detrended_waves_are_their_residual_on_the_session_clocks_line():
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(0, 90, 40))
    Z = fc.cycle_waves(t, 33.0)
    R = cyc.detrended(Z, t)
    for j in range(2):
        slope, icpt = np.polyfit(t, Z[:, j], 1)
        np.testing.assert_allclose(R[:, j], Z[:, j] - (icpt + slope * t), atol=1e-12)
    np.testing.assert_allclose(R.T @ np.column_stack([np.ones(40), t]), 0, atol=1e-9)
    np.testing.assert_allclose(cyc.detrended(3.0 + 0.2 * t, t), 0, atol=1e-12)       # a line has no cycle


def test_the_plans_columns_written_out_and_the_waves_free_of_them():
    V, d, m = np.array([150.0, 200, 250, 300, 150]), np.array([1.0, -1, 1, -1, 1]), np.array([0.0, 0.05, -0.05, 0, 0])
    cols = np.column_stack([V, V ** 2, d * m, np.abs(m), m ** 2, d, d * V])
    np.testing.assert_allclose(cyc.plan_columns(V, d, m), (cols - cols.mean(0)) / cols.std(0), atol=1e-12)
    np.testing.assert_allclose(cyc.plan_columns(V, np.ones(5), m)[:, 5], 0.0)        # a constant input: 0
    rng = np.random.default_rng(2)
    t, P = np.sort(rng.uniform(0, 90, 40)), rng.normal(size=(40, 7))
    Z = fc.cycle_waves(t, 21.0)
    R = cyc.detrended(Z, t, P)
    G = np.column_stack([np.ones(40), t, P])
    np.testing.assert_allclose(R, Z - G @ np.linalg.solve(G.T @ G, G.T @ Z), atol=1e-10)
    np.testing.assert_allclose(G.T @ R, 0.0, atol=1e-9)


def test_a_period_of_the_plans_own_pattern_is_no_cycle_once_the_waves_are_free_of_the_plan():
    # V0 repeats every four runs and the runs' gain follows it (an effect of V0 the model lacks): without the plan's
    # columns the search takes the plan's period for a cycle; with them it finds none, and a true cycle beside the
    # same pattern keeps its evidence
    t = _session(seed=3)
    n = len(t)
    V = np.array([150.0, 200.0, 250.0, 300.0])[np.arange(n) % 4]
    plan = cyc.plan_columns(V, np.ones(n), np.zeros(n))
    dev = _deviations(0.015 * (V - 225.0) / 56.0, seed=4)
    naive = cyc.cycle_signal(dev, t)
    p_naive = rl.signal_evidence(dev, [naive], alpha=0.01, k=4, seed=0, session_order=t)[0].p_value
    free = cyc.cycle_signal(dev, t, plan)
    p_free = rl.signal_evidence(dev, [free], alpha=0.01, k=4, seed=0, session_order=t)[0].p_value
    assert p_naive < 1e-4 and p_free > 0.05
    assert naive["period_s"] < 4 * np.median(np.diff(t)) * 1.5                  # the plan's few runs
    both = _deviations(0.015 * (V - 225.0) / 56.0 + 0.02 * np.cos(2 * np.pi * t / 37.0), seed=4)
    sg = cyc.cycle_signal(both, t, plan)
    assert abs(1 / sg["period_s"] - 1 / 37.0) <= 1 / (3 * np.ptp(t))
    assert rl.signal_evidence(both, [sg], alpha=0.01, k=4, seed=0, session_order=t)[0].p_value < 1e-4


def _deviations(gain_by_run, seed, sd_between=0.004, se=0.004):
    """Made run deviations: each run's gain ``gain_by_run`` plus a between-run scatter and sampling noise."""
    rng = np.random.default_rng(seed)
    n = len(gain_by_run)
    theta = np.column_stack([gain_by_run + rng.normal(0, sd_between, n) + rng.normal(0, se, n),
                             rng.normal(0, 0.05, n)])
    cov = np.broadcast_to(np.diag([se ** 2, 0.05 ** 2]), (n, 2, 2)).copy()
    return rl.RunDeviations(np.arange(n), theta, cov, np.full(n, 200), None)


def _session(n=56, seed=0):
    """Runs' mean session times: about 1.6 s apart with a scatter, as the rig's plan records them."""
    return np.cumsum(np.random.default_rng(seed).uniform(1.0, 2.2, n))


def test_the_search_finds_a_made_cycle_beside_a_drift_and_corrects_its_p_value():
    t = _session()
    P0 = 37.0
    dev = _deviations(0.02 * np.cos(2 * np.pi * t / P0 + 0.7) + 0.0004 * t, seed=1)
    sg = cyc.cycle_signal(dev, t)
    periods = cyc.periods_s(t)
    p = [rs.joint_test(dev, cyc.detrended(fc.cycle_waves(t, P), t), True)[1] for P in periods]
    best = int(np.argmin(p))
    assert sg["period_s"] == pytest.approx(periods[best]) and sg["search_count"] == len(periods)
    assert abs(1 / sg["period_s"] - 1 / P0) <= 1 / (3 * np.ptp(t))      # within a step of the grid
    np.testing.assert_allclose(sg["columns"], cyc.detrended(fc.cycle_waves(t, sg["period_s"]), t))
    np.testing.assert_allclose(sg["shares"], fc.cycle_waves(t, sg["period_s"]).mean(axis=0))
    assert sg["channel"] == "time_s" and sg["transform"] == "cycle"
    ev = rl.signal_evidence(dev, [sg], alpha=0.01, k=4, seed=0, session_order=t)[0]
    assert ev.p_value == pytest.approx(min(1.0, p[best] * len(periods)), rel=1e-9)
    assert ev.significant and ev.cv_gain > 0.1 and ev.dof == 2        # two gains: the cosine's and the sine's
    stretches = [np.sort(b) for b in np.array_split(np.argsort(t), 4)]     # held out: stretches of the session
    assert ev.cv_gain == pytest.approx(rs.cv_signal_gain(dev.theta, dev.cov, sg["columns"], stretches, None,
                                                         gain_only=True)[0], rel=1e-12)
    assert ev.label == f"session_cycle({sg['period_s']:.1f} s)" and ev.regressor == "session_cycle"
    assert ev.period_s == sg["period_s"] and ev.shares == sg["shares"] and ev.blocked_folds
    d = ev.to_dict()
    assert d["period_s"] == sg["period_s"] and d["gain_per_sd"] is None and d["folds"] == "session blocks"
    assert (d["cos_gain"], d["sin_gain"]) == ev.coef[:2]


def test_the_search_reads_the_cycle_on_the_gain_alone_the_familys_form():
    # a stronger cycle of another period in the runs' offsets: the family scales the drive force, so the search
    # reads the gain's cycle
    t = _session(seed=5)
    dev = _deviations(0.02 * np.cos(2 * np.pi * t / 37.0), seed=6)
    dev.theta[:, 1] += 0.3 * np.sin(2 * np.pi * t / 17.0)
    P = cyc.cycle_signal(dev, t)["period_s"]
    assert abs(1 / P - 1 / 37.0) <= 1 / (3 * np.ptp(t))


def test_a_drift_of_the_session_or_no_change_gives_no_cycle():
    # the waves less their line: a drift, however strong, is the session clock's own signal, not a long cycle
    t = _session(seed=2)
    for seed in range(4):
        for gain in (0.0005 * t, np.zeros(len(t))):
            dev = _deviations(gain, seed=20 + seed)
            ev = rl.signal_evidence(dev, [cyc.cycle_signal(dev, t)], alpha=0.01, k=4, seed=0, session_order=t)[0]
            assert not ev.significant, (seed, ev.p_value)
            assert ev.p_value > 0.01


def test_a_significant_cycle_offers_its_family_with_its_period_and_centring():
    from types import SimpleNamespace
    t = _session(seed=3)
    dev = _deviations(0.02 * np.sin(2 * np.pi * t / 29.0), seed=4)
    ev = rl.signal_evidence(dev, [cyc.cycle_signal(dev, t)], alpha=0.01, k=4, seed=0, session_order=t)
    fit = reml(dev.theta, dev.cov)
    analysis = rl.RunLevelAnalysis(dev, fit, 0.0, 1.0, ev, 0.01)
    ctx = SimpleNamespace()
    import l1b2.closeloop.candidates as cands
    made = []
    orig = cands.candidate
    try:
        cands.candidate = lambda c, h: made.append(h) or h
        got = rl.candidates(analysis, ctx)
    finally:
        cands.candidate = orig
    assert len(got) == 1 and got[0].family == ev[0].label
    assert got[0].spec == {"kind": "session_cycle", **fc.cycle_spec(ev[0].period_s, *ev[0].shares)}
    assert analysis.round_record(1)["signals"][0]["signal"] == ev[0].label


def test_an_analysis_asked_for_it_searches_the_cycle_beside_the_signals_and_ranks_it_by_its_p_value(monkeypatch):
    import pandas as pd
    t = _session(seed=7)
    n = len(t)
    dev = _deviations(0.02 * np.cos(2 * np.pi * t / 31.0), seed=8)
    dev.theta[:, 0] += 0.01 * np.where(np.arange(n) % 2, 1.0, -1.0)         # and a logged setting's effect
    df = pd.DataFrame({"run": np.repeat(np.arange(n), 5), "time_s": np.repeat(t, 5) + np.tile(np.arange(5) * 0.1, n),
                       "voltage_V": 220.0, "direction": 1.0, "load_kg": 0.0})
    setting = {"channel": "setting", "transform": "none", "values": np.where(np.arange(n) % 2, 1.0, -1.0)}
    monkeypatch.setattr(rl, "run_deviations", lambda *a: dev)
    monkeypatch.setattr(rl, "run_signals", lambda *a: [setting])
    assert len(rl.analyse(df, None, np.ones(len(df), bool), [], alpha=0.01, k=4, seed=0).evidence) == 1   # off
    a = rl.analyse(df, None, np.ones(len(df), bool), [], alpha=0.01, k=4, seed=0, cycle=True)
    labels = [e.label for e in a.evidence]
    assert len(labels) == 2 and labels[0].startswith("session_cycle(")        # the smaller corrected p-value first
    assert [e.significant for e in a.evidence] == [True, True]
    t_mean = df.groupby("run")["time_s"].mean().to_numpy()
    sg = cyc.cycle_signal(dev, t_mean)
    assert a.evidence[0].period_s == sg["period_s"]
    level = 0.01 / 2                                                           # one signal, and the cycle
    want = rl.signal_evidence(dev, [sg], alpha=level, k=4, seed=0,
                              session_order=df.groupby("run")["time_s"].min().to_numpy())[0]
    assert a.evidence[0].p_value == pytest.approx(want.p_value) and a.evidence[0].cv_gain == pytest.approx(
        want.cv_gain)
    assert rl.rank(a.evidence[0]) < rl.rank(a.evidence[1])
    # the cycle is tested at the blocks' level, alpha over the signals' count plus one (the signals' own: alpha / 1)
    calls, real = [], rl.signal_evidence
    monkeypatch.setattr(rl, "signal_evidence",
                        lambda d, sigs, **kw: calls.append(([s["transform"] for s in sigs], kw["alpha"])) or real(
                            d, sigs, **kw))
    rl.analyse(df, None, np.ones(len(df), bool), [], alpha=0.01, k=4, seed=0, cycle=True)
    assert calls == [(["none"], 0.01), ([cyc.CYCLE], pytest.approx(level))]


def test_an_analysis_reads_the_cycle_free_of_the_plans_inputs_per_run(monkeypatch):
    import pandas as pd
    t = _session(seed=3)
    n = len(t)
    V = np.array([150.0, 200.0, 250.0, 300.0])[np.arange(n) % 4]
    dev = _deviations(0.015 * (V - 225.0) / 56.0, seed=4)
    df = pd.DataFrame({"run": np.repeat(np.arange(n), 5), "time_s": np.repeat(t, 5) + np.tile(np.arange(5) * 0.1, n),
                       "voltage_V": np.repeat(V, 5), "direction": 1.0, "load_kg": 0.0})
    monkeypatch.setattr(rl, "run_deviations", lambda *a: dev)
    monkeypatch.setattr(rl, "run_signals", lambda *a: [])
    a = rl.analyse(df, None, np.ones(len(df), bool), [], alpha=0.01, k=4, seed=0, cycle=True)
    (ev,) = [e for e in a.evidence if e.period_s is not None]
    t_mean = df.groupby("run")["time_s"].mean().to_numpy()
    want = cyc.cycle_signal(dev, t_mean, cyc.plan_columns(V, np.ones(n), np.zeros(n)))
    assert ev.period_s == want["period_s"] and not ev.significant
