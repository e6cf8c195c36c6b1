"""The speed sensor's gain along the stroke: a measurement effect that multiplies the recorded speed.

Checked against formulas written out here: the Legendre gain, the free run with the gain (the plain free run times
g(s) at the recorded points), the screen's response columns (``d P_j(x) v``, no recursion), the least-squares fit,
the frame behind the gain and the measurement chain's model around a physics model.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from l1b2.closeloop import sensor
from l1b2.closeloop.evidence import order_traced
from l1b2.closeloop.loop import ChainModel
from l1b2.data import measurements as dataio
from l1b2.fmi.export import ExportError, export_calibrated
from l1b2.predictor.effects import SpeedSensorGain, stroke_basis
from l1b2.predictor.effects.model import ExtendedPredictor
from l1b2.predictor.model import example_params
from l1b2.predictor.setup import PredictorSetup

S_LO, S_HI = -0.02, 0.025
COEF = (0.01, 0.05, -0.03, 0.02)


def legendre_gain(s, coef=COEF, lo=S_LO, hi=S_HI):
    """``1 + c0 + c1 x + c2 (3x^2 - 1)/2 + c3 (5x^3 - 3x)/2``, ``x = 2 (s - lo)/(hi - lo) - 1`` clipped."""
    x = np.clip(2 * (np.asarray(s, float) - lo) / (hi - lo) - 1, -1, 1)
    c0, c1, c2, c3 = coef
    return 1 + c0 + c1 * x + c2 * (3 * x ** 2 - 1) / 2 + c3 * (5 * x ** 3 - 3 * x) / 2


def frame(n_runs=6, n=400, seed=0):
    """Runs stop to stop at constant speeds, alternating direction (data convention: signed speed)."""
    rng = np.random.default_rng(seed)
    rows = []
    for r in range(n_runs):
        d = 1.0 if r % 2 == 0 else -1.0
        s = np.linspace(S_LO, S_HI, n)[::int(d)]
        v = d * (0.12 + 0.02 * r) * (1 + 0.1 * np.sin(40 * s)) + 1e-4 * rng.standard_normal(n)
        rows.append(pd.DataFrame({dataio.RUN: r, dataio.TIME: np.arange(n) * 1e-3, dataio.POSITION: s,
                                  dataio.SPEED: v, dataio.VOLTAGE: 220.0 + 20 * r, dataio.LOAD: 0.0,
                                  dataio.DIRECTION: d}))
    return pd.concat(rows, ignore_index=True)


def test_gain_is_the_written_out_legendre_series_and_its_inverse():
    g = SpeedSensorGain(S_LO, S_HI, COEF)
    s = np.linspace(S_LO - 0.005, S_HI + 0.005, 57)
    np.testing.assert_allclose(g.gain(s), legendre_gain(s), rtol=0, atol=1e-14)
    v = np.linspace(-0.2, 0.2, 57)
    np.testing.assert_allclose(g.apply(s, v), legendre_gain(s) * v, rtol=1e-14)
    np.testing.assert_allclose(g.remove(s, g.apply(s, v)), v, rtol=1e-12, atol=1e-15)
    assert SpeedSensorGain.from_dict(g.to_dict()) == g


def test_the_response_is_exact_and_has_no_recursion():
    """``g v - v = response @ c`` for any c (linear in the coefficients), and column j is ``P_j(x) v``."""
    g = SpeedSensorGain(S_LO, S_HI, COEF)
    s = np.linspace(S_LO, S_HI, 31)
    v = 0.1 + 0.05 * np.cos(s * 300)
    R = g.response(s, v)
    np.testing.assert_allclose(g.apply(s, v) - v, R @ np.array(COEF), rtol=1e-13, atol=1e-16)
    x = 2 * (s - S_LO) / (S_HI - S_LO) - 1
    np.testing.assert_allclose(R[:, 2], (3 * x ** 2 - 1) / 2 * v, rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(R[:, 3], (5 * x ** 3 - 3 * x) / 2 * v, rtol=1e-13, atol=1e-16)


def test_the_screens_columns_are_the_direction_times_the_response():
    df = frame()
    v = df[dataio.SPEED].to_numpy()
    S = sensor.gain_columns(df, v)
    s, d = df[dataio.POSITION].to_numpy(), df[dataio.DIRECTION].to_numpy()
    x = 2 * (s - s.min()) / (s.max() - s.min()) - 1
    want = np.column_stack([d * v, d * x * v, d * (3 * x ** 2 - 1) / 2 * v, d * (5 * x ** 3 - 3 * x) / 2 * v])
    np.testing.assert_allclose(S, want, rtol=1e-13, atol=1e-16)


def test_free_run_with_the_gain_is_the_plain_free_run_times_the_gain():
    setup = PredictorSetup(example_params(3), 0.1, 1e-3)
    df = frame(n_runs=2, n=300)
    args = (df[dataio.TIME].to_numpy() + 0.5 * df[dataio.RUN].to_numpy(), df[dataio.POSITION].to_numpy(),
            df[dataio.VOLTAGE].to_numpy(), df[dataio.LOAD].to_numpy(), df[dataio.DIRECTION].to_numpy(),
            np.array([0.1, -0.1]))
    plain = ExtendedPredictor(setup, setup).free_run(*args, run_index=df[dataio.RUN].to_numpy())
    g = SpeedSensorGain(S_LO, S_HI, COEF)
    model = ExtendedPredictor(setup, setup, speed_gain=g.to_dict())
    got = model.free_run(*args, run_index=df[dataio.RUN].to_numpy())
    np.testing.assert_allclose(got, plain * legendre_gain(df[dataio.POSITION].to_numpy()), rtol=1e-13, atol=1e-16)
    again = ExtendedPredictor.from_dict(model.to_dict())
    assert again.speed_gain == model.speed_gain
    assert "speed_gain" not in ExtendedPredictor(setup, setup).to_dict()   # a model without it is written as before


def test_export_refuses_a_model_with_a_sensor_gain(tmp_path):
    setup = PredictorSetup(example_params(3), 0.1, 1e-3)
    model = ExtendedPredictor(setup, setup, speed_gain=SpeedSensorGain(S_LO, S_HI, COEF).to_dict())
    with pytest.raises(ExportError, match="speed_gain"):
        export_calibrated(model, tmp_path)


def test_fit_recovers_a_gain_and_the_frame_removes_it():
    """Noise-free recorded speed ``g(s) v``: the least squares returns ``c`` and the frame returns ``v``."""
    df = frame()
    v_model = df[dataio.SPEED].to_numpy()
    s = df[dataio.POSITION].to_numpy()
    rec = df.copy()
    rec[dataio.SPEED] = legendre_gain(s) * v_model
    mask = np.ones(len(df), bool)
    g = sensor.fit_gain(rec, mask, v_model, (S_LO, S_HI))
    np.testing.assert_allclose(g.coef, COEF, rtol=0, atol=1e-10)
    assert all(e < 1e-8 for e in g.stderr)
    np.testing.assert_allclose(sensor.gain_frame(rec, g)[dataio.SPEED].to_numpy(), v_model, rtol=1e-9, atol=1e-14)
    # the stage's fit on TRAIN's position range and its refit on a gain's range and order are the same least squares
    staged = sensor.stage_fit(rec)(rec, mask, v_model)
    assert (staged.gain.s_lo, staged.gain.s_hi) == (s.min(), s.max())
    np.testing.assert_allclose(staged.gain.coef, COEF, rtol=0, atol=1e-10)
    again = sensor.GainChain(SpeedSensorGain(S_LO, S_HI, (0.0,) * 3)).refit(rec, mask, v_model)
    assert again.gain.order == 2 and (again.gain.s_lo, again.gain.s_hi) == (S_LO, S_HI)


def test_fit_standard_errors_are_clustered_by_run():
    """With one residual per run shared by its samples, the clustered variance is the written-out sandwich."""
    df = frame(n_runs=5, n=50)
    v = df[dataio.SPEED].to_numpy()
    runs = df[dataio.RUN].to_numpy()
    rec = df.copy()
    rec[dataio.SPEED] = v * (1 + 0.01 * (runs - 2))   # a constant gain error per run
    g = sensor.fit_gain(rec, np.ones(len(df), bool), v, (S_LO, S_HI), order=0)
    X = v[:, None]
    c = (X[:, 0] @ (rec[dataio.SPEED].to_numpy() - v)) / (X[:, 0] @ X[:, 0])
    e = rec[dataio.SPEED].to_numpy() - v - c * v
    meat = sum((X[runs == r, 0] @ e[runs == r]) ** 2 for r in range(5))
    assert g.coef[0] == pytest.approx(c, rel=1e-12)
    assert g.stderr[0] == pytest.approx(np.sqrt(meat) / (X[:, 0] @ X[:, 0]), rel=1e-9)


class _Physics:
    def predict_free_run(self, df):
        return 2.0 * df[dataio.SPEED].to_numpy()

    def predict_one_step(self, df):
        return df[dataio.SPEED].to_numpy() + 1.0


def test_the_chain_model_predicts_the_gain_times_the_physics_behind_it():
    df = frame(n_runs=2, n=20)
    g = SpeedSensorGain(S_LO, S_HI, COEF)
    m = ChainModel(_Physics(), sensor.GainChain(g))
    gs = legendre_gain(df[dataio.POSITION].to_numpy())
    v = df[dataio.SPEED].to_numpy()
    np.testing.assert_allclose(m.predict_free_run(df), gs * 2.0 * v / gs, rtol=1e-13)
    np.testing.assert_allclose(m.predict_one_step(df), gs * (v / gs + 1.0), rtol=1e-13)


def test_a_kept_gain_puts_position_first_in_the_trace():
    assert order_traced((), False, ["voltage"], measured=("position",)) == ["position", "voltage"]
    assert order_traced((), False, ["voltage"]) == []


def test_the_stage_is_off_by_default():
    from l1b2.closeloop.loop import CloseLoop
    df, rec = frame(n_runs=2, n=10), {}
    assert CloseLoop()._stroke_gain(None, rec, df, None, np.ones(len(df), bool), 0.1, []) is df
    assert rec == {}


def test_stroke_basis_is_constant_on_an_empty_range():
    B = stroke_basis(np.array([0.0, 0.01]), 0.01, 0.01, 2)
    np.testing.assert_allclose(B, [[1.0, 0.0, -0.5], [1.0, 0.0, -0.5]])
