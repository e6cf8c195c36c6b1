"""Named effects keep physical values (issue 28, item 6): ranges carried into the identification, no named effect
together with a generic term that can reproduce it, and no value reported without a standard error."""

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop.acceptance import EffectSet, collinear
from l1b2.closeloop.candidates import candidate
from l1b2.closeloop.intervals import added_parameters
from l1b2.predictor import effects as fx
from test_effects_registry import TRAIN


def _df(n=400, seed=0):
    rng = np.random.default_rng(seed)
    run = np.repeat(np.arange(8), n // 8)
    d = np.where(run % 2 == 0, 1, -1)
    load = np.repeat(rng.choice([-0.09, -0.05, 0.0, 0.03, 0.07], 8), n // 8)
    return pd.DataFrame({"time_s": np.arange(n) * 1e-3, "run": run, "position_m": rng.uniform(-0.01, 0.01, n),
                         "voltage_V": np.repeat(rng.choice([220.0, 290.0], 8), n // 8), "direction": d,
                         "load_kg": load, "speed_m_s": 0.1 * d})


def _cand(kind, family=None):
    hs = [h for h in fx.family(kind).grid(TRAIN) if family is None or h.family == family]
    return candidate(None, hs[0])


def test_pulley_coefficient_is_identified_inside_its_physical_range():
    pulley, asym = _cand("load_path_friction"), _cand("direction_asymmetry")
    assert pulley.bounds == ((0.0, 1.0),) and asym.bounds == ()
    eff = EffectSet().add(asym, [0.5, -0.2]).add(pulley, [-22.9])
    extra = eff.extra()
    assert extra.lower == (-np.inf, -np.inf, 0.0) and extra.upper == (np.inf, np.inf, 1.0)
    np.testing.assert_array_equal(eff.start(), [0.5, -0.2, 0.0])     # a start outside the range is moved in
    assert EffectSet().add(asym, [0.1, 0.2]).extra().lower is None


def test_a_generic_term_that_can_reproduce_an_added_effect_is_not_offered():
    df = _df()
    mask = np.ones(len(df), bool)
    eff = EffectSet().add(_cand("load_path_friction"), [0.1])
    smooth_load = _cand("smooth", "smooth_load")          # its |m| column is the pulley's -g|m| up to a factor
    assert collinear(smooth_load, eff, df, mask)
    assert not collinear(_cand("direction_asymmetry"), eff, df, mask)
    assert not collinear(_cand("smooth", "smooth_voltage"), eff, df, mask)
    assert not collinear(smooth_load, EffectSet(), df, mask)


class _Fitted:
    extra_params_ = {"a": 0.2, "b": -22.9}
    extra_stderr_ = {"a": 0.01, "b": float("inf")}
    extra_ci95_ = {"a": (0.18, 0.22), "b": (-np.inf, np.inf)}


def test_a_parameter_without_standard_error_is_named_unidentifiable_not_reported_as_a_value():
    c = candidate(None, fx.Hypothesis("x", "load", "", ("a", "b"), ("1", "N"), {"kind": "drive_saturation"}))
    p = added_parameters(_Fitted(), EffectSet().add(c, [0.2, -22.9]))
    assert p["a"] == {"value": 0.2, "stderr": 0.01, "ci95": [0.18, 0.22], "unit": "1", "unidentifiable": False,
                      "interval": "model"}
    assert p["b"] == {"value": None, "stderr": None, "ci95": None, "unit": "N", "unidentifiable": True}
    with pytest.raises(KeyError):
        added_parameters(type("M", (), {"extra_params_": {}, "extra_stderr_": {}, "extra_ci95_": {}})(),
                    EffectSet().add(c, [0.0, 0.0]))
