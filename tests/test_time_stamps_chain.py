"""The time stamps' chain: the step ratio per sample, the output form ``r^gamma v``, its fit and screen, and the
loader's glitch rule beside uneven stamps (``l1b2.data.stamps``, ``l1b2.closeloop.stamps``,
``l1b2.data.plausibility.speed_glitch``)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from l1b2.closeloop import stamps
from l1b2.closeloop.evidence import order_traced
from l1b2.closeloop.loop import ChainModel
from l1b2.data import measurements as dataio
from l1b2.data.plausibility import speed_glitch
from l1b2.data.stamps import effective_steps_s, regular_clock_derivative, time_step_ratio
from l1b2.predictor.model import example_params

#: two runs: the first with one sample stamped 0.4 ms early (steps 1, 1, 0.6, 1, 1 ms), the second even
T_S = np.array([0.0, 1.0, 2.0, 2.6, 3.6, 4.6, 10.0, 11.0, 12.0]) * 1e-3
RUNS = np.array([1, 1, 1, 1, 1, 1, 2, 2, 2])
#: the effective step beside the 0.6 ms step: h1 h2 (h1 + h2) / (h1^2 + h2^2) = 1 x 0.6 x 1.6 / 1.36 ms
H_SHORT_S = 1.0 * 0.6 * 1.6 / 1.36 * 1e-3


def test_the_effective_step_and_the_ratio_are_the_written_out_ones():
    np.testing.assert_allclose(effective_steps_s(T_S, RUNS),
                               np.array([1.0, 1.0, H_SHORT_S * 1e3, H_SHORT_S * 1e3, 1.0, 1.0, 1.0, 1.0, 1.0]) * 1e-3,
                               rtol=1e-12)
    # each run's median step (1 ms) over the effective step: 1.36 / 0.96 beside the short step, else 1
    np.testing.assert_allclose(time_step_ratio(T_S, RUNS), [1, 1, 1.36 / 0.96, 1.36 / 0.96, 1, 1, 1, 1, 1],
                               rtol=1e-12)
    np.testing.assert_array_equal(time_step_ratio([0.0, 5.0], [1, 2]), [1.0, 1.0])   # runs of one sample


def test_a_speed_derived_over_arrival_stamps_is_the_slider_speed_times_the_ratio():
    """Samples taken every 1 ms, stamped late by a packet's latency: ``gradient(position, stamps)`` is exactly
    ``v x ratio`` for a position linear in the true time, and the regular clock's derivative is ``v``."""
    rng = np.random.default_rng(3)
    n, N, dt, v = 60, 7, 1e-3, 0.137
    t_true = np.arange(n) * dt
    stamped = t_true + (rng.uniform(0, 0.5e-3, -(-n // N)))[np.arange(n) // N]
    s = v * t_true
    runs = np.ones(n, int)
    np.testing.assert_allclose(np.gradient(s, stamped), v * time_step_ratio(stamped, runs), rtol=1e-10)
    np.testing.assert_allclose(regular_clock_derivative(s, stamped), v, rtol=1e-10)


def frame(stamped: bool, n_runs=8, n=300, seed=0, gamma_true=1.0):
    """Runs at a smooth speed on uneven stamps (packets of 9 samples, latency up to 0.45 ms): the logged speed is
    ``r^gamma_true v`` when ``stamped`` (a speed derived over arrival stamps), else ``v`` (true stamps), plus
    0.2 mm/s noise. Returns the frame and ``v``."""
    rng = np.random.default_rng(seed)
    rows, vs = [], []
    for r in range(n_runs):
        d = 1.0 if r % 2 == 0 else -1.0
        k = np.arange(n)
        t = 2.0 * r + k * 1e-3 + rng.uniform(0, 0.45e-3, -(-n // 9))[k // 9]
        v = d * (0.08 + 0.01 * r) * (1 + 0.2 * np.sin(k / 40.0))
        ratio = time_step_ratio(t, np.zeros(n))
        logged = (ratio ** gamma_true if stamped else 1.0) * v + 2e-4 * rng.standard_normal(n)
        rows.append(pd.DataFrame({dataio.RUN: r, dataio.TIME: t, dataio.POSITION: np.cumsum(v) * 1e-3,
                                  dataio.SPEED: logged, dataio.VOLTAGE: 200.0 + 10 * r, dataio.LOAD: 0.0,
                                  dataio.DIRECTION: d}))
        vs.append(v)
    return pd.concat(rows, ignore_index=True), np.concatenate(vs)


def test_the_output_form_and_its_frame_are_r_to_the_gamma():
    df = pd.DataFrame({dataio.RUN: RUNS, dataio.TIME: T_S, dataio.SPEED: np.linspace(0.1, 0.2, 9)})
    u = np.linspace(-0.3, 0.3, 9)
    r = np.array([1, 1, 1.36 / 0.96, 1.36 / 0.96, 1, 1, 1, 1, 1])
    np.testing.assert_allclose(stamps.StampChain(0.5).apply(df, u), np.sqrt(r) * u, rtol=1e-12)
    np.testing.assert_allclose(stamps.stamp_frame(df, 0.5)[dataio.SPEED], np.linspace(0.1, 0.2, 9) / np.sqrt(r),
                               rtol=1e-12)
    np.testing.assert_allclose(stamps.StampChain(0.0).apply(df, u), u, rtol=0)

    class Physics:
        def predict_free_run(self, frame):
            return 2.0 * frame[dataio.SPEED].to_numpy()
    # the chain's model: r^gamma times the physics run on the frame behind the chain
    got = ChainModel(Physics(), stamps.StampChain(1.0)).predict_free_run(df)
    np.testing.assert_allclose(got, r * 2.0 * np.linspace(0.1, 0.2, 9) / r, rtol=1e-12)


@pytest.mark.parametrize("gamma_true", [1.0, 0.6])
def test_gamma_is_recovered_by_least_squares(gamma_true):
    df, v = frame(True, gamma_true=gamma_true)
    chain = stamps.fit_gamma(df, np.ones(len(df), bool), v)
    assert chain.gamma == pytest.approx(gamma_true, abs=0.02)
    assert stamps.StampChain(0.3).refit(df, np.ones(len(df), bool), v).gamma == chain.gamma   # anew from 0
    assert 0 < chain.stderr < 0.02
    df0, v0 = frame(False)
    assert abs(stamps.fit_gamma(df0, np.ones(len(df0), bool), v0).gamma) < 0.02


def test_the_screen_finds_arrival_stamps_and_not_true_ones():
    """The screen's response is ``d v_pred ln r``; the model's own speed ``v`` predicted: under arrival stamps the
    residual is that response (gain near 1, every run), under true stamps it is noise (no gain)."""
    folds = [[0, 1], [2, 3], [4, 5], [6, 7]]
    params = example_params(3)
    df, v = frame(True)
    d = df[dataio.DIRECTION].to_numpy()
    np.testing.assert_allclose(stamps.response(df, v), d * v * np.log(stamps.ratio(df)), rtol=1e-12)
    got = stamps.screen(df, np.ones(len(df), bool), v, params, 0.1, folds)
    assert got["cv_gain"] > 0.9 and got["p_value"] < 0.01 and got["runs_improved"] == 1.0
    df0, v0 = frame(False)
    got0 = stamps.screen(df0, np.ones(len(df0), bool), v0, params, 0.1, folds)
    assert got0["cv_gain"] < 0.05 and got0["p_value"] > 0.01


def test_the_stage_is_not_considered_on_an_even_clock():
    df, v = frame(True)
    even = df.assign(**{dataio.TIME: df[dataio.RUN] * 2.0 + df.groupby(dataio.RUN).cumcount() * 1e-3})
    rec, kept = stamps.decide(even, np.ones(len(df), bool), 0.1, [], None, None, None, alpha=0.01, min_gain=0.0,
                              min_cv_gain=0.0)
    assert rec["considered"] is False and kept is None and rec["accepted"] is False


def test_a_kept_stage_puts_the_time_step_ratio_first_in_the_trace():
    assert order_traced((), False, ["voltage"], measured=(stamps.REGRESSOR,)) == ["time_step_ratio", "voltage"]


def _run(stamp_late: float):
    """One run at 0.2 m/s sampled every 1 ms; sample 40 stamped ``stamp_late`` ms late and the speed derived over the
    stamps (the host's column): ``(speed, position, stamps)``."""
    k = np.arange(100)
    s = 0.2 * k * 1e-3
    t = k * 1e-3
    t[40] += stamp_late * 1e-3
    return np.gradient(s, t), s, t


def test_a_glitch_the_uneven_stamps_explain_is_not_refused_and_a_real_one_still_is():
    v, s, t = _run(-0.5)   # steps 1, 0.5, 1.5, 1 ms: the host's speed at samples 39-41 is far off 0.2 m/s
    assert np.max(np.abs(v - 0.2)) > 0.1 + 0.01   # beyond the rule's limit (half the peak + 10 mm/s): a glitch
    assert speed_glitch(v, s, t, 0.5) is None   # explained: the position moved smoothly on the DAQ's clock
    real = v.copy()
    real[70] = -0.5   # a real glitch on even steps elsewhere in the run
    assert speed_glitch(real, s, t, 0.5) == (70, pytest.approx(0.2, abs=1e-12))
    beside = v.copy()
    beside[40] += 0.3   # a glitch on the uneven sample itself: not the position's derivative over the stamps
    assert speed_glitch(beside, s, t, 0.5)[0] == 40
    jumped = s.copy()
    jumped[40] += 5e-4   # the position itself jumps there: its derivative on the regular clock is a glitch too
    v_j = np.gradient(jumped, t)
    assert speed_glitch(v_j, jumped, t, 0.5) is not None


def test_the_report_line_names_the_stage_when_the_steps_are_uneven():
    from l1b2.closeloop.report import stamps_sentence
    assert stamps_sentence({"considered": False, "accepted": False}) == ""
    kept = {"considered": True, "accepted": True, "cv_gain": 0.4846, "p_value": 1e-9, "gamma": 1.0013,
            "gamma_of_baseline": {"gamma": 0.9877}}
    assert stamps_sentence(kept) == (
        " The time steps are uneven: a speed derived over stamps that are not the samples' times (logged speed = "
        "r^gamma x the slider's, r the time step ratio) has held-out gain 48.5% (p 1e-09), gamma 1.001 (1: stamps "
        "given on arrival, 0: true stamps): kept: the prediction is multiplied by r^gamma.")
    refused = {"considered": True, "accepted": False, "cv_gain": -0.0001, "p_value": 0.996,
               "gamma_of_baseline": {"gamma": 0.0028}}
    assert stamps_sentence(refused).endswith("held-out gain -0.0% (p 1), gamma 0.003 (1: stamps given on arrival, "
                                             "0: true stamps): not kept.")


def test_the_loop_keeps_the_stage_as_round_1_and_fits_the_rounds_behind_it(sensor_stages):
    """``CloseLoop._sensor_stages``: a kept stage becomes the model's chain (round 1, ``time_step_ratio``) and the
    rounds' frame is the logged speed over ``r^gamma``; a refused one falls through to the cyclic error (no line in
    a zero residual) and the stroke gain (off: the frame)."""
    df, v = frame(True)
    chain = stamps.StampChain(1.0, 0.01)
    kept = {"considered": True, "accepted": True, "cv_gain": 0.5, "cv_free_run_gain": 0.3, "gamma": 1.0}
    it, rec, fit_tr = sensor_stages(df, stamps=(kept, chain))
    assert it.sensor_stage.stages == (chain,) and rec["time_stamps"] is kept
    assert [(r["round"], r["added"], r["regressors"]) for r in it.rounds[1:]] == [
        (1, "speed_over_time_stamps", ["time_step_ratio"])]
    np.testing.assert_allclose(fit_tr[dataio.SPEED], df[dataio.SPEED] / stamps.ratio(df), rtol=1e-12)
    it2, rec2, fit2 = sensor_stages(df, stamps=({"considered": True, "accepted": False}, None))
    assert fit2 is df and it2.sensor_stage is None and not rec2["position_cyclic_error"]["considered"]