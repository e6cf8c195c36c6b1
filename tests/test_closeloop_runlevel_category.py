"""The categorical run-level signal (issue 28, items 2 and 3): a logged run setting with a few values is also a
category, its runs' deviations explained by its centred level indicators, tested jointly.

Fast unit tests (seconds), each against a formula written out here: the category rule, the indicator columns and
the run-level family's categorical features, the mean's design and the joint test's statistic and degrees of
freedom against ordinary least squares (REML's between-run variance about zero), a non-monotone effect of four
levels found by the category and not by the channel's linear value, and the dominance of nested signals. Uncentred
indicators, the last level kept or the wrong degrees of freedom fail one of them.
"""

import types

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import ranges, runlevel as rl
from l1b2.closeloop import runstats as rs
from l1b2.predictor import effects as fx
from l1b2.predictor.effects import category as ch
from l1b2.predictor.effects import channels
from scipy import stats


def test_a_run_setting_is_a_category_with_three_to_six_values_each_of_two_runs_or_more():
    v = np.array([4.0, 1.0, 2.0, 4.0, 1.0, 2.0, 2.0, 4.0])
    levels, shares = ch.category_levels(v)
    assert levels == (1.0, 2.0, 4.0)
    assert shares == pytest.approx((2 / 8, 3 / 8))               # every level but the last (dropped)
    assert ch.category_levels([1.0, 2.0, 1.0, 2.0]) is None      # two values: a line, the linear signal's
    assert ch.category_levels([1.0, 2.0, 3.0, 1.0, 2.0]) is None  # the value 3 in one run only
    assert ch.category_levels(np.repeat(np.arange(7.0), 2)) is None   # seven values: a quantity
    assert ch.category_levels(np.repeat(np.arange(6.0), 2)) is not None


def test_indicator_columns_are_centred_without_the_last_level_and_zero_for_an_unseen_value():
    levels, shares = (1.0, 2.0, 3.0, 4.0), (0.25, 0.5, 0.125)
    c = np.array([1.0, 2.0, 3.0, 4.0, 2.0 + 1e-13, 9.0])
    want = np.array([[1 - 0.25, -0.5, -0.125],
                     [-0.25, 1 - 0.5, -0.125],
                     [-0.25, -0.5, 1 - 0.125],
                     [-0.25, -0.5, -0.125],        # the last level: every column minus its share
                     [-0.25, 1 - 0.5, -0.125],     # a run mean of a constant, to rounding
                     [0.0, 0.0, 0.0]])              # a value TRAIN never had: the runs' average
    np.testing.assert_allclose(ch.category_columns(c, levels, shares), want)
    spec = {"kind": "run_level_category", "channel": "fixture_id", **ch.category_spec(levels, shares)}
    assert ch.unseen_levels(spec, c) == [9.0]


def test_the_categorical_family_gives_each_level_a_drive_gain_an_offset_and_a_load_term():
    levels, shares = (1.0, 2.0, 3.0), (0.5, 0.25)
    V0, d = np.array([300.0, 150.0, 240.0, 330.0]), np.array([1.0, -1.0, 1.0, -1.0])
    load = np.array([0.05, 0.05, -0.02, -0.02])
    c = np.array([1.0, 3.0, 2.0, 5.0])
    x = {"V0": V0, "d": d, "load": load, "run:fixture_id": c}
    h = fx.family("run_level_category").hypotheses([{"channel": "fixture_id", "levels": levels, "shares": shares,
                                                     "run_spread": 0.0}])[0]
    assert h.spec["kind"] == "run_level_category"
    assert h.family == "run_level_category(fixture_id)" and h.regressor == "fixture_id" and h.generic
    assert h.units == ("N", "N", "1") * 2
    assert h.names == ("cat_fixture_id_is_1_run_gain", "cat_fixture_id_is_1_run_offset", "cat_fixture_id_is_1_run_load",
                       "cat_fixture_id_is_2_run_gain", "cat_fixture_id_is_2_run_offset", "cat_fixture_id_is_2_run_load")
    x1 = np.array([0.5, -0.5, -0.5, 0.0])          # 1[c = 1] - 0.5 (c = 5: unseen)
    x2 = np.array([-0.25, -0.25, 0.75, 0.0])       # 1[c = 2] - 0.25
    g = 9.81 * d * load
    want = np.column_stack([V0 / 300 * x1, x1, g * x1, V0 / 300 * x2, x2, g * x2])
    np.testing.assert_allclose(fx.effect_features(h.spec, x), want)
    assert fx.family("run_level_category").width(h.spec) == 6
    assert fx.needs(h.spec) == {"V0", "d", "load", "run:fixture_id"}
    # a logged channel: Predictor.fmu reads it through an input of its own (its current value as the run's
    # level, exact as the setting is constant within runs: run_spread 0), the family has no kernel
    assert channels.fmu_signal("run:fixture_id") == "col:fixture_id"
    assert channels.export_problem(h.spec) is None
    assert channels.export_problem({**h.spec, "run_spread": 1e-9}) is not None   # no sd: only 0 is constant
    assert fx.family("run_level_category").exportable
    from l1b2.predictor.effects import kernels as ek
    with pytest.raises(fx.EffectSpecError, match="'run_level_category' has no per-sample kernel"):
        ek.spec_scalars(h.spec)


def test_the_mean_design_of_several_columns_puts_each_on_the_gain_the_offset_and_the_load_offset():
    Z = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    w = np.array([0.5, -1.0, 2.0])
    X = rs.signal_design(Z, w)
    assert X.shape == (3, 2, 8)
    for r in range(3):
        z1, z2 = Z[r]
        np.testing.assert_allclose(X[r, 0], [1, z1, z2, 0, 0, 0, 0, 0])
        np.testing.assert_allclose(X[r, 1], [0, 0, 0, 1, z1, z2, z1 * w[r], z2 * w[r]])
    assert rs.signal_index(2, True) == [1, 2, 4, 5, 6, 7] and rs.signal_index(2, False) == [1, 2, 4, 5]
    assert rs.signal_index(1, True) == [1, 3, 4]                   # the value signal's (g1, o1, o2)
    np.testing.assert_allclose(rs.signal_design(Z[:, 0], w), rs.signal_design(Z[:, :1], w))


def _category_runs(n_per=12, effect=(0.5, -0.5, -0.5, 0.5), noise=0.01, seed=3):
    """Four levels 1..4 in shuffled runs; gain and offset both ``effect`` of the run's level plus ``noise``."""
    rng = np.random.default_rng(seed)
    c = rng.permutation(np.repeat([1.0, 2.0, 3.0, 4.0], n_per))
    eff = np.asarray(effect)[c.astype(int) - 1]
    theta = np.column_stack([eff, eff]) + rng.normal(0, noise, (len(c), 2))
    return c, theta


def test_the_joint_test_is_ordinary_least_squares_chi_square_with_two_per_level_but_one():
    # written out: sampling covariance s2 I much larger than the runs' spread about their level means, so REML's
    # between-run variance is about zero and the GLS mean is the OLS one; per component k the Wald statistic is
    # (RSS0_k - RSS1_k) / s2 (intercept only vs intercept and indicators), summed over gain and offset, chi-square
    # with 2 (L - 1) = 6 degrees of freedom (no load variation)
    c, theta = _category_runs()
    s2 = 1.0
    n = len(c)
    dev = rl.RunDeviations(np.arange(n), theta, np.repeat(np.eye(2)[None] * s2, n, axis=0), np.full(n, 400))
    levels, shares = ch.category_levels(c)
    Z = ch.category_columns(c, levels, shares)
    b, p, dof = rs.joint_test(dev, Z)
    A = np.column_stack([np.ones(n), np.eye(4)[c.astype(int) - 1][:, :3]])     # uncentred dummies: same span
    chi2 = 0.0
    for k in range(2):
        y = theta[:, k]
        rss1 = np.sum((y - A @ np.linalg.lstsq(A, y, rcond=None)[0]) ** 2)
        chi2 += (np.sum((y - y.mean()) ** 2) - rss1) / s2
    assert dof == 6
    assert p == pytest.approx(stats.chi2.sf(chi2, 6), rel=2e-3)
    assert 1e-4 < p < 0.05                                                  # a statistic the test can resolve
    # the indicator coefficients: level mean minus the last level's (the dropped one), per component
    means = np.array([theta[c == v].mean(axis=0) for v in levels])
    np.testing.assert_allclose(b[:3], means[:3, 0] - means[3, 0], atol=1e-3)
    np.testing.assert_allclose(b[3:6], means[:3, 1] - means[3, 1], atol=1e-3)
    # with load variation the offset's load slopes join (offset on [1, Z, Z w]): 3 (L - 1) degrees of freedom
    w = np.where(np.arange(n) % 2 == 0, 0.5, -1.0)
    dev.load = w
    _, p, dof = rs.joint_test(dev, Z)
    y = theta[:, 1]
    Aw = np.column_stack([A, A[:, 1:] * w[:, None]])
    chi2_w = chi2 - (np.sum((y - y.mean()) ** 2) - np.sum((y - A @ np.linalg.lstsq(A, y, rcond=None)[0]) ** 2))
    chi2_w += np.sum((y - y.mean()) ** 2) - np.sum((y - Aw @ np.linalg.lstsq(Aw, y, rcond=None)[0]) ** 2)
    assert dof == 9
    assert p == pytest.approx(stats.chi2.sf(chi2_w / s2, 9), rel=2e-3)


def _realistic_deviations(effect, seed=5):
    c, theta = _category_runs(effect=effect, noise=0.0, seed=seed)
    rng = np.random.default_rng(seed + 1)
    n = len(c)
    S = np.array([[0.01, 0.0], [0.0, 0.04]])
    theta = theta * np.array([0.1, 1.0]) + rng.multivariate_normal([0, 0], np.diag([1e-3, 0.02]), n)
    theta += rng.multivariate_normal([0, 0], S, n)
    dev = rl.RunDeviations(np.arange(n), theta, np.repeat(S[None], n, axis=0), np.full(n, 400))
    df = pd.DataFrame({"run": np.repeat(np.arange(n), 3), "fixture_id": np.repeat(c, 3)})
    chans = [{"name": "fixture_id", "kind": "logged", "within_run": False}]
    sigs = [{"channel": "fixture_id", "transform": "none", "values": c}] + rl.category_signals(df, chans)
    return dev, sigs


def test_a_non_monotone_four_level_effect_is_found_by_the_category_not_by_the_linear_value():
    # effect +1, -1, -1, +1 N of the levels 1..4: orthogonal to the value (its linear contrast sums to zero)
    dev, sigs = _realistic_deviations((1.0, -1.0, -1.0, 1.0))
    assert [s["transform"] for s in sigs] == ["none", "category"]
    ev = {e.transform: e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)}
    cat, lin = ev["category"], ev["none"]
    assert cat.significant and cat.p_value < 0.01 / 2 and cat.cv_gain > 0.2 and cat.dof == 6
    assert not lin.significant and lin.p_value > 0.05
    assert cat.label == "category(fixture_id)" and cat.levels == (1.0, 2.0, 3.0, 4.0)
    per = cat.to_dict()["per_level"]
    assert per["1.0"]["offset_N"] == pytest.approx(0.0, abs=0.3)            # level 1 against level 4: equal
    assert per["2.0"]["offset_N"] == pytest.approx(-2.0, abs=0.3)           # level 2 against level 4
    hyp = fx.family("run_level_category").hypotheses([{"channel": cat.channel, "levels": cat.levels,
                                                       "shares": cat.shares}])[0]
    assert len(hyp.names) == 9


def test_a_linear_effect_keeps_the_linear_value_first_and_the_category_dominated():
    # nested signals: the value is in the span of its indicators; with no evidence beyond the line the simpler wins
    dev, sigs = _realistic_deviations((-1.5, -0.5, 0.5, 1.5))
    ev = {e.transform: e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)}
    assert ev["none"].significant and ev["category"].significant
    assert ev["none"].dominated_by is None and ev["category"].dominated_by == "fixture_id"
    assert rl.run_correlation(sigs[0]["values"], ch.category_columns(sigs[0]["values"], *ch.category_levels(
        sigs[0]["values"]))) == pytest.approx(1.0)


def test_test_runs_at_a_value_train_never_had_are_recorded():
    spec = {"kind": "run_level_category", "channel": "fixture_id", **ch.category_spec((1.0, 2.0, 3.0), (0.4, 0.3))}
    added = [types.SimpleNamespace(spec=spec, label="run_level_category(fixture_id)[run]"),
             types.SimpleNamespace(spec={"kind": "run_level", "channel": "fixture_id", "transform": "none"},
                                   label="run_level_fixture_id[run]")]
    test = pd.DataFrame({"run": np.repeat(np.arange(5), 2), "fixture_id": np.repeat([1.0, 5.0, 2.0, 5.0, 7.0], 2)})
    assert ranges.unseen_test_levels(added, test) == {
        "run_level_category(fixture_id)[run]": {"channel": "fixture_id", "values": [5.0, 7.0], "runs": 3}}
    assert ranges.unseen_test_levels(added, test[test.fixture_id < 3]) == {}
    assert ranges.unseen_test_levels(added, None) == {}


def _dominated_reference(dev, significant, zs, level):
    # the rule computed as written before one residual per ordered pair was shared: conditional_p computing its own
    # _beyond, and the nesting test computing both again
    out = [None] * len(zs)
    sig = [i for i, s in enumerate(significant) if s]
    for a in sig:
        for b in sig:
            if b <= a or rl.run_correlation(zs[a], zs[b]) < rl.DOMINANCE_CORR:
                continue
            pa, pb = rl.conditional_p(dev, zs[a], zs[b]), rl.conditional_p(dev, zs[b], zs[a])
            nested = [i for i, j in ((a, b), (b, a)) if rl._beyond(zs[i], zs[j]).reshape(len(zs[i]), -1).shape[1] == 0]
            if nested:
                small = nested[0]
                big = b if small == a else a
                loser, winner = (small, big) if min(pa, pb) < level else (big, small)
            else:
                loser, winner = (a, b) if pa > pb else (b, a)
            if out[loser] is None:
                out[loser] = winner
    return out


def test_dominated_signals_computes_each_pairs_residuals_once_with_the_same_result(monkeypatch):
    # property: the same dominance as the rule computed with every residual recomputed (nested value and category,
    # a correlated follower of the value, a signal below the correlation limit), for levels either side of the
    # nested pair's conditional p; and two _beyond calls per correlated pair instead of four
    import itertools
    calls = []
    beyond = rl._beyond
    for effect in ((-1.5, -0.5, 0.5, 1.5), (1.0, -1.0, -1.0, 1.0)):
        dev, sigs = _realistic_deviations(effect)
        zs = [rl.signal_columns(s)[0] for s in sigs]
        rng = np.random.default_rng(3)
        zs.append(zs[0] + 0.2 * rng.standard_normal(len(zs[0])))   # follows the value (|r| about 0.98)
        zs.append(rng.standard_normal(len(zs[0])))                 # uncorrelated
        pairs = sum(1 for a, b in itertools.combinations(range(4), 2)
                    if rl.run_correlation(zs[a], zs[b]) >= rl.DOMINANCE_CORR)
        assert pairs == 3
        p_nested = min(rl.conditional_p(dev, zs[0], zs[1]), rl.conditional_p(dev, zs[1], zs[0]))
        for level in (0.0, p_nested * 0.5, p_nested * 2.0, 1.0):
            want = _dominated_reference(dev, [True] * 4, zs, level)
            calls.clear()
            monkeypatch.setattr(rl, "_beyond", lambda z, g: calls.append(1) or beyond(z, g))
            got = rl.dominated_signals(dev, [True] * 4, zs, level)
            monkeypatch.setattr(rl, "_beyond", beyond)
            assert got == want
            assert len(calls) == 2 * pairs

def test_the_categorical_family_takes_a_logged_run_setting_and_relevels_it_on_the_kept_runs():
    fam = fx.family("run_level_category")
    logged = {"name": "fixture_id", "kind": "logged", "within_run": False}
    assert fam.takes(logged)
    assert not fam.takes({**logged, "within_run": True})              # varies inside a run: a quantity's signal
    assert not fam.takes({**logged, "name": "voltage_V"})             # an FMU input has its own signals
    assert not fam.takes({**logged, "kind": "protocol"})
    sg = fam.signal("fixture_id", [1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 3.0])
    assert sg["levels"] == (1.0, 2.0, 3.0) and sg["shares"] == pytest.approx((2 / 7, 2 / 7))
    kept = fam.on_runs(sg, np.array([0, 1, 2, 3, 4, 6]))              # one run of level 3 dropped: shares 2/6
    assert kept["shares"] == pytest.approx((1 / 3, 1 / 3)) and list(kept["values"]) == [1, 2, 3, 1, 2, 3]
    assert fam.on_runs(sg, np.array([0, 1, 3, 4, 6])) is None          # level 3 in one run: no longer a category
    assert fam.signal("fixture_id", [1.0, 2.0, 1.0, 2.0]) is None
    np.testing.assert_allclose(fam.columns(kept), ch.category_columns(kept["values"], (1.0, 2.0, 3.0),
                                                                       (1 / 3, 1 / 3)))


def test_a_categorical_effect_recorded_as_the_run_level_transform_reads_as_its_own_family():
    # a record written when the category was the run_level family's transform: the same scalars and names, read as
    # the family's own spec, whose features are the per-level forms written out
    from l1b2.predictor.effects.model import IdentifiedEffect
    levels, shares = (1.0, 2.0, 3.0), (0.25, 0.5)
    old_spec = {"kind": "run_level", "transform": "category", "channel": "fixture_id",
                **ch.category_spec(levels, shares)}
    names = [f"cat_fixture_id_is_{v}_run_{p}" for v in (1, 2) for p in ("gain", "offset", "load")]
    rec = {"family": "run_level_category(fixture_id)", "label": "run_level_category(fixture_id)[run]",
           "spec": old_spec, "names": names, "units": ["N", "N", "1"] * 2, "phi": [0.0] * 6, "stderr": [None] * 6}
    e = IdentifiedEffect.from_dict(rec)
    assert e.spec["kind"] == "run_level_category" and "transform" not in e.spec
    assert {k: v for k, v in e.spec.items() if k != "kind"} == {k: v for k, v in old_spec.items()
                                                                if k not in ("kind", "transform")}
    assert IdentifiedEffect.from_dict(e.to_dict()) == e
    new = dict(rec, spec={k: v for k, v in old_spec.items() if k != "transform"} | {"kind": "run_level_category"})
    assert IdentifiedEffect.from_dict(new) == e


def test_identified_columns_drop_each_column_in_the_span_of_those_before():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(8, 2)), rng.normal(size=(8, 2))
    X = np.stack([a, b, np.zeros((8, 2)), 2 * a - b, rng.normal(size=(8, 2))], axis=2)   # (n, p, k)
    assert rs.identified_columns(X) == [0, 1, 4]
    assert rs.identified_columns(X[:, :, [0, 1, 4]]) == [0, 1, 2]


def test_a_category_whose_load_slopes_the_runs_do_not_identify_is_tested_on_the_rest():
    # two levels' runs carry no load (w = 0): their centred load columns Z_j w = -s_j w are both proportional to w,
    # so the mean's design [1, Z, Z w] lacks a rank (a small plan: a V0 step's values against three loads). The
    # identified columns give the offset [1, Z, w, ind_3 w]: written out as ordinary least squares, chi-square with
    # 3 + 3 + 2 = 8 degrees of freedom; the cross-validated gain is computed too (no singular fit)
    c, theta = _category_runs()
    s2 = 1.0
    n = len(c)
    w = np.where(c <= 2, 0.0, np.where(np.arange(n) % 2 == 0, 0.5, -1.0))
    dev = rl.RunDeviations(np.arange(n), theta, np.repeat(np.eye(2)[None] * s2, n, axis=0), np.full(n, 400), w)
    levels, shares = ch.category_levels(c)
    Z = ch.category_columns(c, levels, shares)
    assert len(rs.identified_columns(rs.signal_design(Z, w))) == 2 + 3 * 3 - 1
    b, p, dof = rs.joint_test(dev, Z)
    A = np.column_stack([np.ones(n), np.eye(4)[c.astype(int) - 1][:, :3]])
    chi2 = 0.0
    for k, Ak in ((0, A), (1, np.column_stack([A, w, (c == 3) * w]))):
        y = theta[:, k]
        chi2 += (np.sum((y - y.mean()) ** 2) - np.sum((y - Ak @ np.linalg.lstsq(Ak, y, rcond=None)[0]) ** 2)) / s2
    assert dof == 8 and len(b) == 9
    assert p == pytest.approx(stats.chi2.sf(chi2, 8), rel=2e-3)
    gain, per_run = rs.cv_signal_gain(dev.theta, dev.cov, Z, [np.arange(i, n, 4) for i in range(4)], w)
    assert np.isfinite(gain) and np.all(np.isfinite(per_run))
