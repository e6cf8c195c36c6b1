"""The position sensor's cyclic error as a measurement-chain stage (:mod:`l1b2.closeloop.encoder`)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from l1b2.closeloop import encoder
from l1b2.closeloop.evidence import order_traced
from l1b2.closeloop.loop import ChainModel
from l1b2.closeloop.selection import linear_response
from l1b2.data import measurements as dataio
from l1b2.predictor.effects import effect_features
from l1b2.predictor.model import example_params

P = 1.5e-3
COEF = np.array([7e-6, -3e-6, 2e-6, 1.5e-6])   # c1, d1, c2, d2 [m]


def test_the_error_and_its_slope_are_the_written_out_ones():
    c1, d1, c2, d2 = COEF
    for s in (0.0, P / 4, P / 2, 0.7e-3):
        th = 2 * np.pi * s / P
        e = c1 * np.sin(th) + d1 * np.cos(th) + c2 * np.sin(2 * th) + d2 * np.cos(2 * th)
        de = (2 * np.pi / P) * (c1 * np.cos(th) - d1 * np.sin(th) + 2 * c2 * np.cos(2 * th) - 2 * d2 * np.sin(2 * th))
        assert encoder.error_m(np.array([s]), P, COEF)[0] == pytest.approx(e, abs=1e-18)
        assert (encoder.slope_basis(np.array([s]), P) @ COEF)[0] == pytest.approx(de, abs=1e-15)
    s = np.linspace(-3e-3, 3e-3, 2001)
    # the slope is the error's derivative, and the error is periodic with the pitch
    np.testing.assert_allclose(encoder.slope_basis(s, P) @ COEF, np.gradient(encoder.error_m(s, P, COEF), s),
                               atol=2e-4)
    np.testing.assert_allclose(encoder.error_m(s + P, P, COEF), encoder.error_m(s, P, COEF), atol=1e-15)


def frame(n_runs=12, n=500, seed=0, chain=True, force=None, params=None, noise=2e-4, speeds=(0.03, 0.25)):
    """Runs at steady speeds spread over ``speeds`` [m/s] over the stroke from -20 mm (directions alternate): the logged position
    ``s + e(s)`` when ``chain``, and the logged speed its derivative as a DAQ takes it (``numpy.gradient``); ``force``: forces' coefficients of the bar's waviness
    at the pitch added to the speed through the slider's linearised dynamics instead. Returns ``(frame, v)``."""
    rng = np.random.default_rng(seed)
    rows, vs = [], []
    for r in range(n_runs):
        d = 1.0 if r % 2 == 0 else -1.0
        speed = speeds[0] + (speeds[1] - speeds[0]) * r / (n_runs - 1)
        t = 2.0 * r + np.arange(n) * 1e-3
        s = d * (-20e-3 + speed * (t - t[0]))
        e = encoder.error_m(s, P, COEF) if chain else 0.0
        v = np.full(n, d * speed)
        rows.append(pd.DataFrame({dataio.RUN: r, dataio.TIME: t, dataio.POSITION: s + e,
                                  dataio.SPEED: np.gradient(s + e, t) + noise * rng.standard_normal(n),
                                  dataio.VOLTAGE: 200.0 + 5 * r, dataio.LOAD: 0.0, dataio.DIRECTION: d}))
        vs.append(v)
    df, v = pd.concat(rows, ignore_index=True), np.concatenate(vs)
    if force is not None:
        x = {"s": df[dataio.POSITION].to_numpy(), "V0": df[dataio.VOLTAGE].to_numpy(),
             "d": df[dataio.DIRECTION].to_numpy(), "v_base": v}
        F = effect_features({"kind": "bar_waviness", "period_m": P}, x) @ np.asarray(force, float)
        S = linear_response(params, df, 0.1, F[:, None], v_pred=v)[:, 0]
        df[dataio.SPEED] += df[dataio.DIRECTION].to_numpy() * S
    return df, v


def test_the_ripple_is_the_derivative_stencils_and_the_slope_where_neighbours_are_close():
    # steady runs without the error (logged positions linear in time, step dt): the central difference of
    # sin(h k p) is cos(h k p) sin(h k D) / D with D = v dt, i.e. e'(p) with each harmonic attenuated by
    # sin(h k D) / (h k D); the runs' first and last samples are one-sided differences
    k = 2 * np.pi / P
    for speed, slow in ((0.2, False), (0.005, True)):
        df, v = frame(n_runs=2, n=40, chain=False, noise=0.0, speeds=(speed, speed))
        got = encoder.slope_rows(df, P)
        p = df[dataio.POSITION].to_numpy()
        D = speed * 1e-3
        inner = np.ones(len(df), bool)
        inner[[0, 39, 40, 79]] = False
        for j, (h, trig) in enumerate([(1, "s"), (1, "c"), (2, "s"), (2, "c")]):
            att = 1.0 if slow else np.sin(h * k * D) / (h * k * D)
            want = (h * k * (np.cos(h * k * p) if trig == "s" else -np.sin(h * k * p))) * att
            np.testing.assert_allclose(got[inner, j], want[inner], rtol=0, atol=1e-9 * h * k)
        if not slow:
            assert np.sin(2 * k * D) / (2 * k * D) < 0.9     # the second harmonic visibly attenuated at 0.2 m/s
        else:
            np.testing.assert_array_equal(got, encoder.slope_basis(p, P))   # under 1 % of a pitch: the slope


def test_the_chain_and_its_frame_are_one_plus_the_ripple():
    df, v = frame(n_runs=2, n=50)
    c = encoder.CyclicChain(P, COEF)
    p = df[dataio.POSITION].to_numpy()
    de = encoder.slope_rows(df, P) @ COEF
    u = np.linspace(-0.3, 0.3, len(df))
    np.testing.assert_allclose(c.apply(df, u), u * (1 + de), rtol=1e-12)
    fr = c.frame(df)
    np.testing.assert_allclose(fr[dataio.SPEED], df[dataio.SPEED] / (1 + de), rtol=1e-12)
    np.testing.assert_allclose(fr[dataio.POSITION], p - encoder.error_m(p, P, COEF), rtol=1e-12)

    class Physics:
        def predict_free_run(self, f):
            return 2.0 * f[dataio.SPEED].to_numpy()
    # the chain's model: (1 + e') times the physics run on the frame behind the chain
    np.testing.assert_allclose(ChainModel(Physics(), c).predict_free_run(df), 2.0 * df[dataio.SPEED], rtol=1e-12)


def test_the_coefficients_and_the_pitch_are_recovered_by_least_squares():
    df, v = frame()
    mask = np.ones(len(df), bool)
    c = encoder.fit_chain(df, mask, v, P)
    # e' is taken at the logged position s + e(s): a difference of the order of 2 pi e / P (3 %) of e'
    np.testing.assert_allclose(c.coef, COEF, atol=0.3e-6)
    assert all(0 < se < 0.1e-6 for se in c.stderr)
    assert c.amplitudes_m() == pytest.approx([np.hypot(7e-6, 3e-6), np.hypot(2e-6, 1.5e-6)], rel=0.03)
    # from a pitch half a spectral bin (1 / 40 mm) off, the refined pitch is the true one
    got = encoder.refine_pitch(df, mask, v, 1 / (1 / P + 12.5), 25.0)
    assert got == pytest.approx(P, rel=2e-3)
    # the stage's fit refines the pitch and fits there; its refit keeps the pitch it was given
    c_ref = encoder.fit_refined(df, mask, v, 1 / (1 / P + 12.5), 25.0)
    assert c_ref.pitch_m == got
    np.testing.assert_allclose(c_ref.coef, COEF, atol=0.3e-6)
    off = encoder.CyclicChain(1.1 * P, np.zeros(4)).refit(df, mask, v)
    assert off.pitch_m == 1.1 * P and np.max(np.abs(off.coef)) < 1e-6
    clean, v0 = frame(chain=False)
    assert np.max(np.abs(encoder.fit_chain(clean, mask, v0, P).coef)) < 0.1e-6


def test_the_screen_takes_a_ripple_growing_with_speed_and_not_a_force_at_the_same_pitch():
    """The logged speed's ripple ``v e'(s)`` is the stage's (its gain beats the bar's waviness at the pitch); a
    force periodic in the position at that pitch, through the slider's dynamics, is the force family's."""
    params = example_params(3)
    folds = [[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11]]
    df, v = frame()
    mask = np.ones(len(df), bool)
    got = encoder.screen(df, mask, v, params, 0.1, folds, P)
    assert got["cv_gain"] > 0.5 and got["p_value"] < 0.01 and got["cv_gain"] > got["force_cv_gain"]
    assert encoder.screen_passes(got, 0.01, 0.05)
    wavy, vw = frame(chain=False, force=[0.05, -0.03, 0, 0, 0, 0, 0.01, 0], params=params)
    got_f = encoder.screen(wavy, mask, vw, params, 0.1, folds, P)
    assert got_f["force_cv_gain"] > got_f["cv_gain"]
    assert not encoder.screen_passes(got_f, 0.01, 0.05)


def test_the_stage_is_not_considered_without_a_line_in_the_residual_spectrum():
    df, v = frame(chain=False)

    class Baseline:
        def predict_free_run(self, f):
            return v
    rec, kept = encoder.decide(df, np.ones(len(df), bool), 0.1, [], Baseline(), None, None, alpha=0.01,
                               min_gain=0.0, min_cv_gain=0.0)
    assert rec["considered"] is False and kept is None and rec["accepted"] is False
    assert rec["spectrum_peak"]["power_ratio_to_median"] < 4
    wavy, vw = frame()
    peak, pitch, bin_per_m = encoder.candidate_pitch(wavy, np.ones(len(wavy), bool), vw)
    assert pitch == pytest.approx(P, rel=0.05) and bin_per_m > 0


def test_a_smooth_misfit_near_the_stops_is_no_pitch():
    # the logged speed loses up to a fifth of itself past 14 mm on the run's way (a drag in proportion to the speed
    # over part of the travel, as near a stop): a smooth misfit of the position, not a repeat of it. Its spectrum's
    # largest usable bin is a "line" by the power rule alone, at a period the stroke holds three times: no pitch.
    df, v = frame(chain=False, noise=2e-5)
    s = df[dataio.POSITION].to_numpy()
    d = df[dataio.DIRECTION].to_numpy()
    near = np.clip((d * s - 0.014) / 0.006, 0.0, 1.0)
    df[dataio.SPEED] -= 0.2 * near ** 2 * v
    peak, pitch, _ = encoder.candidate_pitch(df, np.ones(len(df), bool), v)
    assert peak["power_ratio_to_median"] > 4 and peak["repeats"] < encoder.MIN_REPEATS
    assert pitch is None
    # the true cyclic error on the same stroke repeats often enough
    wavy, vw = frame()
    peak_w, pitch_w, _ = encoder.candidate_pitch(wavy, np.ones(len(wavy), bool), vw)
    assert peak_w["repeats"] == pytest.approx(np.ptp(wavy[dataio.POSITION]) / peak_w["period_m"])
    assert pitch_w == pytest.approx(P, rel=0.05)


def test_a_kept_stage_puts_its_regressor_first_in_the_trace():
    assert order_traced((), False, ["voltage"], measured=(encoder.REGRESSOR,)) == ["position_cyclic_error", "voltage"]
    params = encoder.CyclicChain(P, COEF, np.full(4, 1e-7)).parameters()
    assert set(params) == {f"cyclic_error_{t}{h}_m" for h in (1, 2) for t in ("sin", "cos")}   # no pitch: no error
    assert all(p["stderr"] == 1e-7 and p["unit"] == "m" for p in params.values())
    assert params["cyclic_error_sin1_m"]["value"] == COEF[0] and params["cyclic_error_cos2_m"]["value"] == COEF[3]


def test_the_screen_rule_wants_significance_size_and_a_gain_above_the_force_family():
    rec = {"p_value": 0.001, "cv_gain": 0.3, "force_cv_gain": 0.2}
    assert encoder.screen_passes(rec, 0.01, 0.05)
    assert not encoder.screen_passes({**rec, "force_cv_gain": 0.31}, 0.01, 0.05)
    assert not encoder.screen_passes({**rec, "p_value": 0.02}, 0.01, 0.05)
    assert not encoder.screen_passes({**rec, "cv_gain": 0.04, "force_cv_gain": 0.0}, 0.01, 0.05)


def test_the_report_line_names_the_pitch_and_both_gains():
    from l1b2.closeloop.report import cyclic_sentence
    assert cyclic_sentence({"considered": False, "accepted": False}) == ""
    kept = {"considered": True, "accepted": True, "pitch_m": 1.5e-3, "cv_gain": 0.2, "p_value": 1e-4,
            "force_cv_gain": 0.05}
    assert cyclic_sentence(kept) == (
        " The residual's spectrum over the position has a line: a position sensor's cyclic error of pitch 1.5000 mm"
        " (logged speed = (1 + e'(s)) x the slider's) has held-out gain 20.0% (p 0.0001), the bar's waviness at that"
        " pitch 5.0%: kept: the prediction is multiplied by 1 + e'(s).")
    assert cyclic_sentence({**kept, "accepted": False}).endswith("pitch 5.0%: not kept.")


def test_the_loop_keeps_the_stage_after_the_time_stamps_and_fits_the_rounds_behind_it(sensor_stages):
    """``CloseLoop._sensor_stages``: when the time stamps' chain is not kept, a kept cyclic error becomes the
    model's chain (round 1, ``position_cyclic_error``) and the rounds' frame is the one behind it; refused, the
    stroke gain (off: TRAIN's frame)."""
    df, v = frame(n_runs=2, n=50)
    chain = encoder.CyclicChain(P, COEF)
    kept = {"considered": True, "accepted": True, "cv_gain": 0.2, "cv_free_run_gain": 0.1}
    it, rec, fit_tr = sensor_stages(df, stamps=({"considered": False}, None), encoder=(kept, chain))
    assert it.sensor_stage.stages == (chain,) and rec["position_cyclic_error"] is kept
    assert [(r["round"], r["added"], r["regressors"]) for r in it.rounds[1:]] == [
        (1, "position_sensor_cyclic_error", ["position_cyclic_error"])]
    np.testing.assert_allclose(fit_tr[dataio.SPEED], chain.frame(df)[dataio.SPEED], rtol=1e-12)
    it2, _, fit2 = sensor_stages(df, encoder=({"considered": True, "accepted": False}, None))
    assert fit2 is df and it2.sensor_stage is None