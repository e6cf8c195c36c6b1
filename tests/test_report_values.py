"""Numbers in reports: diverged runs excluded and counted, strict JSON, sensible digits (issue 14, items 2 and 7)."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from l1b2.jsonio import dumps, sig, strict_json
from l1b2.data.metrics import DIVERGED_FACTOR, diverged_runs, report_metrics


def _two_runs() -> pd.DataFrame:
    x = np.linspace(-0.02, 0.02, 41)
    return pd.DataFrame({"run": np.repeat([1, 2], 41), "position_m": np.tile(x, 2),
                         "speed_m_s": np.full(82, 0.1)})


@pytest.mark.parametrize("bad", [np.inf, np.nan, 1e183, -50.0])
def test_a_diverged_run_is_excluded_from_the_metrics_and_counted(bad):
    df = _two_runs()
    pred = np.full(82, 0.11)
    pred[41 + 20] = bad                       # run 2 diverges in the middle (an evaluated sample)
    assert diverged_runs(df, pred) == [2]
    out = report_metrics(df, pred, pred)
    for kind in ("one_step", "free_run"):
        m = out[kind]
        assert m["n_runs"] == 2 and m["n_diverged_runs"] == 1 and m["diverged_runs"] == [2]
        assert m["nrmse"] == pytest.approx(0.1) and m["n_samples"] > 0  # run 1 alone


def test_fast_but_plausible_predictions_are_not_diverged():
    df = _two_runs()
    pred = np.full(82, 0.1 * DIVERGED_FACTOR * 0.9)
    assert diverged_runs(df, pred) == []


def test_every_run_diverged_gives_no_number_not_inf():
    df = _two_runs()
    out = report_metrics(df, np.full(82, np.inf), np.full(82, 1e300))
    for m in out.values():
        assert m["n_diverged_runs"] == 2 and m["n_samples"] == 0 and math.isnan(m["nrmse"])
    text = dumps(out)
    assert "Infinity" not in text and "NaN" not in text and json.loads(text)["free_run"]["nrmse"] is None


def test_strict_json_and_significant_digits():
    doc = {"a": float("inf"), "b": [float("-inf"), float("nan"), np.float32(1.5)], "c": np.arange(2),
           "d": {1: np.bool_(True)}}
    assert strict_json(doc) == {"a": "inf", "b": ["-inf", None, 1.5], "c": [0, 1], "d": {"1": True}}
    json.loads(dumps(doc), parse_constant=lambda c: pytest.fail(c))
    assert sig(0.012345678901234567) == "0.01235" and sig(None) == "-" and sig("inf") == "inf"
    assert sig(float("nan")) == "-" and sig(123456.789) == "1.235e+05"


def minimal_report() -> dict:
    """A minimal close-loop report dict (what :func:`l1b2.closeloop.result.markdown_report` reads)."""
    metrics = {"nrmse": 0.1, "mean_abs_rel_error": 0.1, "p95_abs_rel_error": 0.2, "n_samples": 10}
    part = {"one_step": metrics, "free_run": metrics}
    return {
        "data": {"train": "train.csv", "test": "test.csv", "train_runs": 4, "test_runs": 2},
        "diagnosis": {"message": "missing effect: pulley", "significant": True, "traced_to": ["load"],
                      "effect": "pulley_friction", "effect_shape": "", "effect_description": "load path",
                      "rules": {"min_gain": 0.5}, "significance_level": 0.01, "candidates": [],
                      "regressor_evidence": [], "whiteness": {"median_rho1": 0.9,
                                                              "share_runs_ljung_box_p_below_0.05": 0.5,
                                                              "runs": 4}},
        "baseline": {"train": part, "test": part},
        "extended": {"train": part, "test": part},
    }


def test_close_loop_report_md_prints_parameters_with_4_significant_digits():
    # reference: issue 14 item 7 - report.md printed a stderr with 17 digits
    from l1b2.closeloop.result import markdown_report
    rep = {**minimal_report(),
           "extended_parameters": {"pulley_mu": {"value": 0.38651234567890123, "stderr": 0.0012345678901234567,
                                                 "ci95": [0.38409876543210987, 0.38898765432101234], "unit": "-"}}}
    text = markdown_report(rep)
    row = next(line for line in text.splitlines() if line.startswith("| pulley_mu"))
    assert row == "| pulley_mu | 0.3865 | 0.001235 | [0.3841, 0.389] | - | - |"   # no interval kind recorded


def test_close_loop_report_md_flags_test_runs_at_a_category_value_train_never_had():
    from l1b2.closeloop.result import markdown_report
    rep = minimal_report()
    rep["diagnosis"] = {**rep["diagnosis"], "unseen_levels": {
        "run_level_category(fixture_id)[run]": {"channel": "fixture_id", "values": [5.0, 7.5], "runs": 3}}}
    lines = [line for line in markdown_report(rep).splitlines() if "never had" in line]
    assert lines == ["* TEST has 3 run(s) at fixture_id = 5, 7.5, a value TRAIN never had: "
                     "`run_level_category(fixture_id)[run]` gives them TRAIN's average over runs (its prediction "
                     "there carries no effect of that value)"]
    assert "never had" not in markdown_report(minimal_report())


def test_close_loop_report_md_prints_each_refit_trials_evidence_over_runs():
    from l1b2.closeloop.result import markdown_report
    rep = minimal_report()
    trial = {"effect": "run_level", "label": "run_level_category(fixture_id)[run]", "regressors": ["fixture_id"],
             "cv_free_run_nrmse_current": 0.028534, "cv_free_run_nrmse_refit": 0.026813, "cv_gain": 0.117,
             "folds_improved": 2, "folds": 4, "cv_gain_se_runs": 0.1956, "runs_improved": 29, "runs": 56,
             "linearised_gain": 0.25, "offered_by": "run_level"}
    old = {k: v for k, v in trial.items() if k != "offered_by"}    # a report written before the key
    rep["diagnosis"] = {**rep["diagnosis"], "refit_trials": [[trial, {**old, "label": "x", "cv_gain_se_runs": None,
                                                                      "runs_improved": None, "runs": None}]]}
    rows = [line for line in markdown_report(rep).splitlines() if line.startswith("| run_level_category")
            or line.startswith("| x |")]
    assert rows == ["| run_level_category(fixture_id)[run] | run_level | fixture_id | 25.0% | 2.85% | 2.68% | 11.7% "
                    "| 19.6% | 2/4 | 29/56 |",
                    "| x | - | fixture_id | 25.0% | 2.85% | 2.68% | 11.7% | - | 2/4 | - |"]


def test_close_loop_report_md_says_which_significant_run_level_signal_another_explains():
    from l1b2.closeloop.result import markdown_report
    rep = minimal_report()
    rep["diagnosis"] = {**rep["diagnosis"], "run_level": {
        "runs": 72, "between_run_sd_gain": 0.012, "between_run_sd_offset_N": 0.003, "heterogeneity_p": 1e-6,
        "significance_level": 0.005, "significant_signals": ["voltage_V", "heatsink_C"],
        "dominated_signals": {"heatsink_C": "voltage_V"}}}
    [line] = [line for line in markdown_report(rep).splitlines() if line.startswith("Run-level deviations")]
    assert line.endswith("signals explaining them (Bonferroni level 0.005): voltage_V, heatsink_C (explained by "
                         "voltage_V given it, not traced).")
    rep["diagnosis"]["run_level"].pop("dominated_signals")      # a report written before the key: names only
    [line] = [line for line in markdown_report(rep).splitlines() if line.startswith("Run-level deviations")]
    assert line.endswith("(Bonferroni level 0.005): voltage_V, heatsink_C.")
