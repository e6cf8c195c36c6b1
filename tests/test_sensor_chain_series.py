"""Sensor stages in series (:mod:`l1b2.closeloop.sensorchain`): the time stamps' chain and the position sensor's
cyclic error kept together. Fast tests against the forms written out."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from l1b2.closeloop import encoder, sensorchain, stamps
from l1b2.closeloop.sensorchain import SensorChain
from l1b2.data import measurements as dataio

P = 1.5e-3
COEF = np.array([7e-6, -3e-6, 2e-6, 1.5e-6])   # c1, d1, c2, d2 [m]
GAMMA = 0.8


def frame(n_runs=3, n=200, seed=0):
    """Slow runs (5 mm/s: neighbours 5-13 um apart, under 1 % of the pitch, so the ripple is ``e'(p)``) with
    jittered time stamps (steps 0.7-1.3 ms), a logged position and a speed column."""
    rng = np.random.default_rng(seed)
    rows = []
    for r in range(n_runs):
        t = 2.0 * r + np.cumsum(rng.uniform(0.7e-3, 1.3e-3, n))
        s = -20e-3 + 0.005 * (t - t[0])
        rows.append(pd.DataFrame({dataio.RUN: r + 1, dataio.TIME: t, dataio.POSITION: s,
                                  dataio.SPEED: 0.005 + 1e-4 * rng.standard_normal(n), dataio.VOLTAGE: 200.0,
                                  dataio.LOAD: 0.0, dataio.DIRECTION: 1.0}))
    return pd.concat(rows, ignore_index=True)


def written_out_slope(p):
    """``e'(p)`` of COEF at the pitch P, written out."""
    c1, d1, c2, d2 = COEF
    th = 2 * np.pi * np.asarray(p) / P
    return (2 * np.pi / P) * (c1 * np.cos(th) - d1 * np.sin(th) + 2 * c2 * np.cos(2 * th) - 2 * d2 * np.sin(2 * th))


def test_two_stages_in_series_multiply_the_slider_speed_and_their_frame_undoes_it():
    df = frame()
    chain = SensorChain([stamps.StampChain(GAMMA), encoder.CyclicChain(P, COEF)])
    r = stamps.ratio(df)
    p = df[dataio.POSITION].to_numpy()
    u = np.linspace(0.05, 0.2, len(df))
    # logged = r^gamma (1 + e'(p)) u, e' at the logged position
    np.testing.assert_allclose(chain.apply(df, u), r ** GAMMA * (1 + written_out_slope(p)) * u, rtol=1e-12)
    behind = chain.frame(df)
    c1, d1, c2, d2 = COEF
    th = 2 * np.pi * p / P
    e = c1 * np.sin(th) + d1 * np.cos(th) + c2 * np.sin(2 * th) + d2 * np.cos(2 * th)
    np.testing.assert_allclose(behind[dataio.POSITION], p - e, rtol=0, atol=1e-15)
    np.testing.assert_allclose(behind[dataio.SPEED],
                               df[dataio.SPEED] / (r ** GAMMA * (1 + written_out_slope(p))), rtol=1e-12)
    # the round trip: the logged speed from the speed behind the chain
    np.testing.assert_allclose(chain.apply(df, behind[dataio.SPEED].to_numpy()), df[dataio.SPEED], rtol=1e-12)
    one = SensorChain([stamps.StampChain(GAMMA)])
    np.testing.assert_allclose(one.apply(df, u), stamps.StampChain(GAMMA).apply(df, u), rtol=0)
    assert chain.regressors == (stamps.REGRESSOR, encoder.REGRESSOR)
    assert set(chain.parameters()) == {"time_stamp_gamma", "cyclic_error_sin1_m", "cyclic_error_cos1_m",
                                       "cyclic_error_sin2_m", "cyclic_error_cos2_m"}
    assert chain.reading().count(";") >= 1 and "gamma 0.800" in chain.reading() and "pitch 1.5000 mm" in chain.reading()


def test_each_stage_is_decided_behind_the_ones_kept_before_it(monkeypatch):
    df = frame()
    first, second = stamps.StampChain(GAMMA), encoder.CyclicChain(P, COEF)
    m0, m1, m2 = object(), object(), object()
    seen = {}

    def decide_stamps(frame_, mask, m_s, folds, model, identify, settings, **rules):
        seen["stamps"] = (frame_, model, rules)
        return {"considered": True, "accepted": True}, (m1, first)

    def decide_cyclic(frame_, mask, m_s, folds, model, identify, settings, **rules):
        seen["cyclic"] = (frame_, model)
        return {"considered": True, "accepted": True}, (m2, second)
    monkeypatch.setattr(stamps, "decide", decide_stamps)
    monkeypatch.setattr(encoder, "decide", decide_cyclic)
    rules = {"alpha": 0.01, "min_gain": 0.0, "min_cv_gain": 0.01}
    records, kept = sensorchain.decide_stages(df, None, 0.1, [], m0, None, None, **rules)
    assert seen["stamps"][0] is df and seen["stamps"][1] is m0 and seen["stamps"][2] == rules
    pd.testing.assert_frame_equal(seen["cyclic"][0], first.frame(df))   # behind the kept stamps' chain
    assert seen["cyclic"][1] is m1                                      # against the physics fitted there
    assert [(m, s) for m, s, _ in kept] == [(m1, first), (m2, second)]
    assert set(records) == {"time_stamps", "position_cyclic_error"}
    # the first refused: the second is decided on the logged frame against the baseline
    monkeypatch.setattr(stamps, "decide", lambda *a, **k: ({"considered": False}, None))
    records, kept = sensorchain.decide_stages(df, None, 0.1, [], m0, None, None, **rules)
    assert seen["cyclic"][0] is df and seen["cyclic"][1] is m0 and [s for _, s, _ in kept] == [second]


def test_the_loop_makes_each_kept_stage_a_round_and_fits_the_rounds_behind_both(monkeypatch):
    from l1b2.closeloop.acceptance import EffectSet
    from l1b2.closeloop.loop import CloseLoop, _Iteration

    class Physics:
        def predict_free_run(self, df):
            return df[dataio.SPEED].to_numpy()

        def predict_one_step(self, df):
            return df[dataio.SPEED].to_numpy()
    df = frame()
    first, second = stamps.StampChain(GAMMA), encoder.CyclicChain(P, COEF)
    kept = {"considered": True, "accepted": True, "cv_gain": 0.3, "cv_free_run_gain": 0.2}
    monkeypatch.setattr(stamps, "decide", lambda *a, **k: (kept, (Physics(), first)))
    monkeypatch.setattr(encoder, "decide", lambda *a, **k: (kept, (Physics(), second)))
    it, rec = _Iteration(model=Physics(), effects=EffectSet(), rounds=[{"round": 0}]), {}
    fit_tr = CloseLoop()._sensor_stages(it, rec, df, None, np.ones(len(df), bool), 0.1, [])
    assert it.sensor_stage.stages == (first, second)
    assert [(r["round"], r["added"], r["regressors"]) for r in it.rounds[1:]] == [
        (1, stamps.STAMP_CHAIN, [stamps.REGRESSOR]), (2, encoder.CYCLIC_CHAIN, [encoder.REGRESSOR])]
    pd.testing.assert_frame_equal(fit_tr, second.frame(first.frame(df)))
    records = [it.sensor_stage.record(r) for r in it.rounds[1:]]
    assert [x["effect"] for x in records] == [stamps.STAMP_CHAIN, encoder.CYCLIC_CHAIN]
    assert "time_stamp_gamma" in records[0]["parameters"] and "cyclic_error_sin1_m" in records[1]["parameters"]
    with pytest.raises(KeyError, match="bar_waviness"):
        it.sensor_stage.record({"added": "bar_waviness"})
