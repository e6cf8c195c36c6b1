"""Tests of l1b2.data.metrics: the error metrics of the rig data format (docs/reference/data-format.md)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from l1b2.data import metrics as M
from l1b2.data.measurements import Measurements
from l1b2.data.metrics import evaluation_mask, report_metrics, speed_metrics

MM = 1e-3
#: a 10 mm traverse sampled away from the 2 mm boundaries: samples 3..8 are evaluated
BASE_MM = np.array([0.0, 1.0, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5, 8.5, 10.0])


def test_constants():
    assert M.MIN_EVAL_SPEED_M_S == 5e-3
    assert M.END_EXCLUSION_M == 2e-3


# --------------------------------------------------------------------------
# speed_metrics
# --------------------------------------------------------------------------

def test_speed_metrics_hand_computed():
    v_meas = np.array([1.0, 2.0, 4.0, -1.0])
    v_pred = np.array([1.1, 1.8, 4.0, -1.5])
    out = speed_metrics(v_pred, v_meas, np.ones(4, dtype=bool))
    # errors 0.1, -0.2, 0, -0.5 -> mean square 0.075; mean v_meas^2 = 22 / 4 = 5.5
    assert out["nrmse"] == pytest.approx(math.sqrt(0.075) / math.sqrt(5.5), rel=1e-12)
    # relative errors 0.1, 0.1, 0, 0.5
    assert out["mean_abs_rel_error"] == pytest.approx(0.175, rel=1e-12)
    # sorted 0, .1, .1, .5: 95th percentile at position 0.95 * 3 = 2.85 -> .1 + .85 * .4
    assert out["p95_abs_rel_error"] == pytest.approx(0.44, rel=1e-12)
    assert out["n_samples"] == 4 and isinstance(out["n_samples"], int)
    assert set(out) == set(M.METRIC_KEYS)


def test_speed_metrics_uses_only_masked_samples_and_tolerates_nan_outside():
    v_meas = np.array([0.01, 2.0, 4.0, 3.0, 0.0])
    v_pred = np.array([np.nan, 3.0, 4.0, 1.0, 7.0])  # NaN / zero speed outside the mask
    mask = np.array([False, True, True, False, False])
    out = speed_metrics(v_pred, v_meas, mask)
    assert out["n_samples"] == 2
    assert out["nrmse"] == pytest.approx(math.sqrt(0.5) / math.sqrt(10.0), rel=1e-12)
    assert out["mean_abs_rel_error"] == pytest.approx(0.25, rel=1e-12)
    assert out["p95_abs_rel_error"] == pytest.approx(0.475, rel=1e-12)


def test_speed_metrics_nan_prediction_in_mask_raises_with_count():
    v_meas = np.ones(5)
    v_pred = np.array([1.0, np.nan, 1.0, np.inf, np.nan])
    mask = np.array([True, True, True, True, False])
    with pytest.raises(ValueError, match=r"2 of 4 evaluated predictions"):
        speed_metrics(v_pred, v_meas, mask)


def test_speed_metrics_empty_mask_gives_nan():
    out = speed_metrics(np.ones(3), np.ones(3), np.zeros(3, dtype=bool))
    assert out["n_samples"] == 0
    assert all(math.isnan(out[k]) for k in ("nrmse", "mean_abs_rel_error", "p95_abs_rel_error"))
    out = speed_metrics([], [], np.array([], dtype=bool))
    assert out["n_samples"] == 0


@pytest.mark.parametrize("pred, meas, mask", [
    (np.ones(3), np.ones(4), np.ones(3, dtype=bool)),      # shape mismatch
    (np.ones(3), np.ones(3), np.ones(3)),                   # mask not boolean
    (np.ones(2), np.array([1.0, 0.0]), np.ones(2, dtype=bool)),  # zero measured speed
])
def test_speed_metrics_rejects_bad_input(pred, meas, mask):
    with pytest.raises(ValueError):
        speed_metrics(pred, meas, mask)


# --------------------------------------------------------------------------
# evaluation_mask
# --------------------------------------------------------------------------

def test_mask_excludes_first_and_last_2mm_and_slow_samples():
    x = np.array([0.0, 0.5, 1.5, 1.9, 2.1, 3.0, 5.0, 7.9, 8.1, 9.0, 10.0]) * MM
    v = np.full(x.size, 0.01)
    v[6] = 0.004                                         # slow -> excluded
    mask = evaluation_mask(v, x)
    expected = np.array([0, 0, 0, 0, 1, 1, 0, 1, 0, 0, 0], dtype=bool)
    np.testing.assert_array_equal(mask, expected)


def test_mask_speed_threshold_is_inclusive_and_uses_magnitude():
    x = -BASE_MM * MM                                    # run toward -position
    v = np.full(x.size, -0.006)
    v[5] = -0.005                                        # exactly 5 mm/s: kept
    v[6] = -0.0049                                       # below: excluded
    mask = evaluation_mask(v, x)
    np.testing.assert_array_equal(np.flatnonzero(mask), [3, 4, 5, 7, 8])


def test_mask_is_per_run():
    x1 = BASE_MM * MM                                    # 0 .. 10 mm
    x2 = x1[::-1].copy()                                 # back 10 .. 0 mm, starts where a ends
    x = np.concatenate([x1, x2])
    v = np.concatenate([np.full(11, 0.01), np.full(11, -0.01)])
    run = ["a"] * 11 + ["b"] * 11
    mask = evaluation_mask(v, x, run)
    np.testing.assert_array_equal(np.flatnonzero(mask),
                                  [3, 4, 5, 6, 7, 8] + [11 + k for k in (2, 3, 4, 5, 6, 7)])
    # as one run the tail of run a / head of run b would be evaluated: the run matters
    assert evaluation_mask(v, x)[9:13].all()


def test_mask_travel_is_along_the_path():
    # 0 -> 10 mm then bounce back to 9 mm: sample at 8.5 mm has 1.5 + 1 = 2.5 mm of
    # travel left along the path (only 0.5 mm away from the final position)
    x = np.array([0.0, 2.5, 5.0, 8.5, 10.0, 9.5, 9.0]) * MM
    v = np.full(x.size, 0.01)
    np.testing.assert_array_equal(evaluation_mask(v, x),
                                  [False, True, True, True, False, False, False])


def test_mask_from_dataframe_and_measurements():
    x = BASE_MM * MM
    df = pd.DataFrame({"run": [3] * 11, "position_m": x, "speed_m_s": 0.01,
                       "time_s": np.arange(11.0)})
    expected = evaluation_mask(df["speed_m_s"].to_numpy(), x, df["run"].to_numpy())
    np.testing.assert_array_equal(evaluation_mask(df), expected)
    meas = Measurements(df=df, meta={}, path="x.csv")
    np.testing.assert_array_equal(evaluation_mask(meas), expected)
    assert np.flatnonzero(expected).tolist() == [3, 4, 5, 6, 7, 8]
    with pytest.raises(TypeError):
        evaluation_mask(df, x)


def test_report_metrics():
    x = BASE_MM * MM
    v = np.full(11, 0.01)
    df = pd.DataFrame({"run": 1, "position_m": x, "speed_m_s": v})
    one = v * 1.1
    one[0] = np.nan                                      # no one-step prediction at k = 0
    free = v * 0.8
    out = report_metrics(df, one, free)
    assert set(out) == {"one_step", "free_run"}
    assert out["one_step"]["n_samples"] == out["free_run"]["n_samples"] == 6
    assert out["one_step"]["nrmse"] == pytest.approx(0.1, rel=1e-9)
    assert out["free_run"]["mean_abs_rel_error"] == pytest.approx(0.2, rel=1e-9)
    assert out["free_run"]["p95_abs_rel_error"] == pytest.approx(0.2, rel=1e-9)
