"""The interval the close loop reports: cluster-robust with TRAIN's runs grouped by level (V0, |load|), decision 0031.

Decision 0025 measured that the runs are not independent clusters (the rig's condition pairs correlate
+0.32, the mirror pairs -0.85) and that clusters of the four runs at one V0 and load size cover the injected
direction asymmetry in 19 of 20 seeds.
"""

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from l1b2.closeloop.acceptance import EffectSet
from l1b2.closeloop.candidates import candidate
from l1b2.closeloop.intervals import added_parameters, reported_uncertainty, train_levels
from l1b2.closeloop.result import markdown_report
from l1b2.ident.clusters import grouped_interval, run_groups
from l1b2.ident.uncertainty import run_influence
from l1b2.predictor import effects as fx

V0 = (220.0, 255.0, 324.0)
LOADS = (-0.07, -0.03, 0.0, 0.03, 0.07)


def _plan(seed=0, n=3):
    """Runs at every V0, signed load and direction, in a shuffled order, ``n`` samples each."""
    rng = np.random.default_rng(seed)
    conds = [(v, m, d) for v in V0 for m in LOADS for d in (1, -1)]
    order = rng.permutation(len(conds))
    rows = []
    for run, k in zip(100 + 3 * np.arange(len(conds)), order):   # run ids neither 0.. nor in plan order
        v, m, d = conds[k]
        rows += [{"run": int(run), "voltage_V": v, "load_kg": -0.0 if m == 0 and d < 0 else m, "direction": d}] * n
    return pd.DataFrame(rows)


def test_runs_are_grouped_by_voltage_and_load_size():
    df = _plan()
    first = df.groupby("run").first()
    runs = list(np.random.default_rng(1).permutation(first.index))           # the fit's own order
    want = {"level": lambda v, m, d: (v, abs(m)), "condition": lambda v, m, d: (v, m),
            "mirror": lambda v, m, d: (v, d * m)}
    for grouping, f in want.items():
        got = run_groups(df, runs, grouping)
        assert got == [f(*first.loc[r, ["voltage_V", "load_kg", "direction"]]) for r in runs]
    levels = run_groups(df, runs, "level")
    # 3 voltages x 3 load sizes (0, 0.03, 0.07): the zero-load level holds the two runs of each direction,
    # the others both signs in both directions
    sizes = pd.Series(levels).value_counts()
    assert len(sizes) == 9 and sorted(sizes.to_list()) == [2, 2, 2, 4, 4, 4, 4, 4, 4]
    with pytest.raises(ValueError, match="grouping"):
        run_groups(df, runs, "voltage")


def test_level_covariance_is_the_sandwich_of_a_least_squares_fit_with_runs_merged_by_level():
    # a linear least-squares fit y = X b + e over 12 runs; the cluster-robust covariance by level written out:
    # (X'X)^-1 [H/(H-1) sum_h X_h' e_h e_h' X_h] (X'X)^-1, t with H - 1 degrees of freedom
    rng = np.random.default_rng(3)
    runs = np.repeat(np.arange(12), 20)
    levels = [("a", "b", "c", "d")[r // 3] for r in range(12)]     # four levels of three runs
    X = np.column_stack([np.ones(runs.size), rng.normal(size=runs.size), rng.normal(size=runs.size)])
    y = X @ [1.0, 0.5, -0.2] + rng.normal(size=runs.size) + np.repeat(rng.normal(size=12), 20)
    b = np.linalg.lstsq(X, y, rcond=None)[0]
    e = y - X @ b
    a_inv = np.linalg.inv(X.T @ X)
    H = 4
    meat = sum(np.outer(X[m].T @ e[m], X[m].T @ e[m])
               for m in (np.isin(runs, [r for r in range(12) if levels[r] == lv]) for lv in "abcd"))
    cov = a_inv @ (H / (H - 1) * meat) @ a_inv
    infl = run_influence(X, e, runs, np.ones(3), 1e-12)
    for j in range(3):
        got = grouped_interval(b[j], infl, levels, j)
        se = np.sqrt(cov[j, j])
        q = stats.t.ppf(0.975, H - 1)
        assert got["clusters"] == H
        assert got["stderr"] == pytest.approx(se, rel=1e-10)
        np.testing.assert_allclose(got["ci95"], [b[j] - q * se, b[j] + q * se], rtol=1e-10)
    # one cluster: no interval
    assert grouped_interval(b[0], infl, ["a"] * 12, 0) is None


class _Fit:
    """A fitted model's views: 8 runs (two levels of four), theta (one parameter) then the extras a, b."""

    runs_ = [5, 6, 7, 8, 1, 2, 3, 4]
    param_names_all_ = ["alpha_0", "a", "b"]
    extra_names_ = ["a", "b"]
    extra_params_ = {"a": 0.2, "b": -1.5}
    extra_stderr_ = {"a": 0.01, "b": 0.3}
    extra_ci95_ = {"a": (0.18, 0.22), "b": (-2.1, -0.9)}
    extra_stderr_robust_ = {"a": 0.05, "b": 0.4}
    extra_ci95_robust_ = {"a": (0.1, 0.3), "b": (-2.3, -0.7)}
    run_influence_ = np.array([[0.1, 0.02, 0.1], [0.0, -0.03, 0.2], [0.2, 0.01, -0.1], [0.1, 0.04, 0.0],
                               [0.0, 0.02, 0.3], [0.3, -0.01, 0.1], [0.1, 0.03, -0.2], [0.2, 0.01, 0.1]])


def _train():
    # runs 1-4: 220 V, 0.05 kg (both signs, both directions); runs 5-8: 324 V, 0.09 kg
    rows = [{"run": r, "voltage_V": 220.0 if r <= 4 else 324.0, "load_kg": (0.05 if r <= 4 else 0.09) * s,
             "direction": d} for r, (s, d) in zip(range(1, 9), [(1, 1), (1, -1), (-1, 1), (-1, -1)] * 2)]
    return pd.DataFrame(rows)


def test_the_loop_reports_the_level_interval_and_keeps_the_run_and_model_based_ones():
    fit = _Fit()
    groups = train_levels(fit, _train())
    assert groups == [(324.0, 0.09)] * 4 + [(220.0, 0.05)] * 4
    # written out: level sums of the extras' influence rows, CR1 factor 2/1, t with 1 degree of freedom
    u = fit.run_influence_[:, 1:]
    v = np.array([u[:4].sum(axis=0), u[4:].sum(axis=0)])
    se = np.sqrt(np.diag(2.0 * v.T @ v))
    q = stats.t.ppf(0.975, 1)
    for j, n in enumerate(("a", "b")):
        got = reported_uncertainty(fit, n, groups)
        assert got["interval"] == "level" and got["clusters"] == 2
        assert got["stderr"] == pytest.approx(se[j], rel=1e-12)
        np.testing.assert_allclose(got["ci95"], fit.extra_params_[n] + np.array([-1, 1]) * q * se[j], rtol=1e-12)
        assert got["stderr_run"] == fit.extra_stderr_robust_[n] and got["ci95_run"] == list(fit.extra_ci95_robust_[n])
        assert got["stderr_model"] == fit.extra_stderr_[n] and got["ci95_model"] == list(fit.extra_ci95_[n])
    # without groups (or run influences): the run-robust one; without a finite robust one: the model-based one
    assert reported_uncertainty(fit, "a") == {"stderr": 0.05, "ci95": [0.1, 0.3], "interval": "run",
                                              "stderr_model": 0.01, "ci95_model": [0.18, 0.22]}
    bare = type("M", (), {k: getattr(_Fit, k) for k in ("extra_params_", "extra_stderr_", "extra_ci95_")})()
    assert train_levels(bare, _train()) is None
    assert reported_uncertainty(bare, "b", groups) == {"stderr": 0.3, "ci95": [-2.1, -0.9], "interval": "model"}


def test_the_report_shows_the_level_interval():
    from test_report_values import minimal_report
    fit = _Fit()
    c = candidate(None, fx.Hypothesis("x", "load", "", ("a", "b"), ("1", "N"), {"kind": "drive_saturation"}))
    params = added_parameters(fit, EffectSet().add(c, [0.2, -1.5]), train_levels(fit, _train()))
    text = markdown_report({**minimal_report(), "extended_parameters": params})
    row = next(line for line in text.splitlines() if line.startswith("| a |"))
    lo, hi = params["a"]["ci95"]
    assert row == (f"| a | 0.2 | {params['a']['stderr']:.4g} | [{lo:.4g}, {hi:.4g}] | "
                   "level (V0, load size; 2 clusters of runs) | 1 |")
    assert params["a"]["ci95"] != [0.1, 0.3]    # not the run-robust one
