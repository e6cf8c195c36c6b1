"""Run-level evidence, folds that respect the session, the response-column option and the run-level rig
injections (issue 28, items 3 and 7), each against a formula written out here.

Fast unit tests (seconds): a fold split that is not contiguous in the session, a block never held out, a REML
estimate without its restricted correction, a dropped Bonferroni correction over the run-level signals or a
wrong run-level feature fails one of them. The realistic-world cases of the two rig injections are in
``tests/test_closeloop_runlevel_slow.py``.
"""

import types

import numpy as np
import pandas as pd
import pytest
from l1b2.cli import build_parser
from l1b2.closeloop import acceptance as acc
from l1b2.closeloop import folds as fo
from l1b2.closeloop import runlevel as rl
from l1b2.closeloop import runstats as rs
from l1b2.closeloop.auxiliary import DERIVED_ATTR
from l1b2.closeloop.candidates import CandidateForce, candidate, channels_of
from l1b2.closeloop.loop import CloseLoop, prefer
from l1b2.predictor import effects as fx
from l1b2.rig import experiment as rig


# ---------------------------------------------------------------------------
# folds that are blocks of the session
# ---------------------------------------------------------------------------

def _session(n_runs=23, seed=4):
    """Runs whose ids are NOT in session order (a shuffled numbering), 3 samples each, 1 s apart."""
    rng = np.random.default_rng(seed)
    ids = rng.permutation(np.arange(100, 100 + n_runs))
    rows = [pd.DataFrame({"run": r, "time_s": 10.0 * k + np.arange(3) * 0.1}) for k, r in enumerate(ids)]
    return pd.concat(rows, ignore_index=True), ids            # ids[k]: the k-th run of the session


@pytest.mark.parametrize("k", [2, 4, 5])
def test_session_blocks_are_contiguous_stretches_of_the_session_each_held_out_once(k):
    df, order = _session()
    blocks = fo.session_blocks(df, k)
    assert len(blocks) == k
    assert sorted(np.concatenate(blocks).tolist()) == sorted(order.tolist())          # every run exactly once
    sizes = [len(b) for b in blocks]
    assert max(sizes) - min(sizes) <= 1                                              # balanced
    # written out: block j is the session's runs from sum(sizes[:j]) to sum(sizes[:j+1]), in session order
    edges = np.cumsum([0] + sizes)
    for j, b in enumerate(blocks):
        assert b.tolist() == order[edges[j]:edges[j + 1]].tolist()
    # the same split whatever the frame's row order (runs are ordered by their first time, not by id or row)
    shuffled = df.sample(frac=1.0, random_state=1).sort_values(["run", "time_s"])
    assert [b.tolist() for b in fo.session_blocks(shuffled, k)] == [b.tolist() for b in blocks]


def _conditions_session(seed=7):
    """A session of conditions (V0, load) in a row: mostly two runs each (forward, backward), one of three runs,
    two of one run, and two neighbouring conditions at the same V0 (different loads); run ids shuffled.
    Returns the frame and the session's units written out (lists of run ids, in session order)."""
    sizes = [2, 2, 3, 2, 1, 2, 2, 1, 2, 2, 2]
    conds = [(324.0, 0.03), (255.0, 0.0), (220.0, -0.07), (220.0, 0.09), (324.0, -0.03), (255.0, 0.07),
             (290.0, 0.0), (255.0, 0.0), (324.0, 0.09), (220.0, -0.03), (290.0, 0.07)]
    n = sum(sizes)
    ids = np.random.default_rng(seed).permutation(np.arange(500, 500 + n))
    rows, units, k = [], [], 0
    for (V, L), m in zip(conds, sizes):
        units.append(ids[k:k + m].tolist())
        for j in range(m):
            rows.append(pd.DataFrame({"run": ids[k], "time_s": 2.0 * k + np.arange(3) * 0.1, "voltage_V": V,
                                      "load_kg": L, "direction": 1 - 2 * (j % 2)}))
            k += 1
    return pd.concat(rows, ignore_index=True).sample(frac=1.0, random_state=3), units


def test_session_units_are_the_conditions_in_a_row():
    df, units = _conditions_session()
    assert [u.tolist() for u in fo.session_units(df)] == units
    # without the condition columns: one unit per run, in session order
    assert [u.tolist() for u in fo.session_units(df.drop(columns=["voltage_V", "load_kg"]))] == [
        [r] for u in units for r in u]


@pytest.mark.parametrize("k", [2, 3, 4, 5])
def test_session_rotation_deals_whole_conditions_to_the_folds_in_turn(k):
    df, units = _conditions_session()
    folds = fo.session_rotation(df, k)
    assert len(folds) == k
    order = [r for u in units for r in u]
    # written out: fold i holds units i, i + k, i + 2k, ... of the session, their runs in session order
    for i, f in enumerate(folds):
        assert f.tolist() == [r for j, u in enumerate(units) if j % k == i for r in u]
    assert sorted(np.concatenate(folds).tolist()) == sorted(order)                   # every run held out once
    assert [len(f) for f in folds] == [sum(len(u) for u in units[i::k]) for i in range(k)]          # sizes
    fold_of = {r: i for i, f in enumerate(folds) for r in f.tolist()}
    for j, u in enumerate(units):
        assert len({fold_of[r] for r in u}) == 1                   # a condition in a row is never split
        pos = [order.index(r) for r in u]
        assert pos == list(range(pos[0], pos[0] + len(u)))         # a held-out unit is contiguous in time
        # its neighbouring units, on both sides (one at the session's ends), are in the fitted part
        for nb in (units[j - 1] if j > 0 else [], units[j + 1] if j + 1 < len(units) else []):
            assert all(fold_of[r] != fold_of[u[0]] for r in nb)
    # more folds than units: one unit per fold
    assert [f.tolist() for f in fo.session_rotation(df, 50)] == units


def test_clock_folds_picks_the_scheme_and_refuses_an_unknown_one():
    df, units = _conditions_session()
    for k in (2, 4):
        assert [f.tolist() for f in fo.clock_folds(df, k, "blocks")] == [
            f.tolist() for f in fo.session_blocks(df, k)]
        assert [f.tolist() for f in fo.clock_folds(df, k, "rotation")] == [
            f.tolist() for f in fo.session_rotation(df, k)]
    with pytest.raises(ValueError, match="clock_folds"):
        fo.clock_folds(df, 4, "interleaved")


@pytest.mark.parametrize("scheme", ["blocks", "rotation"])
def test_the_loop_folds_clock_candidates_by_its_setting(scheme, monkeypatch):
    df, _ = _conditions_session()
    seen = []

    class Stop(Exception):
        pass

    real = fo.clock_folds

    def spy(d, k, sch):
        seen.append((k, sch))
        if len(seen) == 2:
            raise Stop
        return real(d, k, sch)

    monkeypatch.setattr(fo, "clock_folds", spy)      # the refit's (refit_schemes) and the screen's (screen_folds)
    assert CloseLoop().clock_folds == "blocks"                       # the default: contiguous blocks
    est = CloseLoop(clock_folds=scheme, k_folds=5, refit_folds=3)
    assert est.get_params()["clock_folds"] == scheme
    with pytest.raises(Stop):
        est._iterate(None, [], df, None, 0.1, None, None)
    assert seen == [(3, scheme), (5, scheme)]                        # the refit's folds, then the screen's


def test_time_dependent_candidates_are_those_reading_the_session_clock():
    train = fx.TrainingSummary(m_s=0.12, time_range=(0.0, 300.0), position_range=(-0.012, 0.012),
                               voltage_median=270.0, ranges={"t_lo": 0.0, "t_hi": 300.0, "s_lo": -0.012,
                                                             "s_hi": 0.012, "V_lo": 220.0, "V_hi": 324.0,
                                                             "load_abs": 0.09, "v_lo": 0.0, "v_hi": 0.3},
                               channels=({"name": "aux", "kind": "logged", "mean": 1.0, "sd": 0.5,
                                          "within_run": False},
                                         {"name": "aux_since_s", "kind": "logged", "mean": 8.0, "sd": 4.0,
                                          "within_run": True},
                                         {"name": "since_s_aux", "kind": "logged", "mean": 8.0, "sd": 4.0,
                                          "within_run": False}))

    def cands(kind):
        return [CandidateForce(h.family, h.regressor, h.shape, h.names, h.units, None, also=h.also, spec=h.spec)
                for h in fx.family(kind).grid(train)]
    smooth = {c.family: acc.time_dependent(c) for c in cands("smooth")}
    assert smooth["smooth_time"] and not smooth["smooth_load"] and not smooth["smooth_position"]
    chan = {(c.spec["channel"], c.spec["level"]): acc.time_dependent(c) for c in cands("channel")}
    assert chan["time_s", "run"] and chan["time_s", "sample"] and not chan["aux", "run"]
    # an event clock (the session's time since a logged step, <column>_since_s) is a clock of the session too
    assert chan["aux_since_s", "run"] and chan["aux_since_s", "sample"] and not chan["since_s_aux", "run"]
    runl = {c.spec["channel"]: acc.time_dependent(c) for c in cands("run_level")}
    assert runl == {"aux": False, "time_s": True, "aux_since_s": True, "since_s_aux": False}
    assert not any(acc.time_dependent(c) for c in cands("load_path_friction"))
    assert all(acc.time_dependent(c) for c in cands("thermal_drift"))


# ---------------------------------------------------------------------------
# REML shrinkage and the run-level evidence
# ---------------------------------------------------------------------------

def test_reml_of_equal_variances_is_the_sample_variance_less_the_sampling_variance():
    # written out: theta_r = mu + u_r + e_r, var(e) = s2 for every run: REML tau2 = var(theta, ddof=1) - s2
    # (ML would use ddof=0); BLUP = mu + tau2/(tau2 + s2) (theta - mu)
    rng = np.random.default_rng(0)
    n, s2 = 30, 0.25
    theta = rng.normal(2.0, 1.0, n)
    fit = rl.reml(theta[:, None], np.full((n, 1, 1), s2))
    tau2 = np.var(theta, ddof=1) - s2
    assert fit.T[0, 0] == pytest.approx(tau2, rel=1e-6)
    assert fit.beta[0] == pytest.approx(theta.mean(), rel=1e-9)
    assert fit.beta_cov[0, 0] == pytest.approx((tau2 + s2) / n, rel=1e-6)
    np.testing.assert_allclose(fit.blup[:, 0], theta.mean() + tau2 / (tau2 + s2) * (theta - theta.mean()), rtol=1e-6)


def test_reml_with_a_covariate_uses_the_residual_degrees_of_freedom():
    # written out: equal variances, mean a + b z: tau2 = RSS/(n - 2) - s2, (a, b) the least-squares line
    rng = np.random.default_rng(1)
    n, s2 = 40, 0.1
    z = rng.normal(size=n)
    theta = 1.0 + 0.7 * z + rng.normal(0, 0.8, n)
    X = np.column_stack([np.ones(n), z])
    coef, rss = np.linalg.lstsq(X, theta, rcond=None)[:2]
    fit = rl.reml(theta[:, None], np.full((n, 1, 1), s2), rs.design_rows(z, n, 1))
    assert fit.T[0, 0] == pytest.approx(float(rss[0]) / (n - 2) - s2, rel=1e-6)
    np.testing.assert_allclose(fit.beta, coef, rtol=1e-8)


def test_design_rows_put_each_component_on_its_own_intercept_and_slope():
    z = np.array([0.5, -1.0])
    D = rs.design_rows(z, 2, 2)
    np.testing.assert_array_equal(D[0], [[1, 0.5, 0, 0], [0, 0, 1, 0.5]])
    np.testing.assert_array_equal(D[1], [[1, -1.0, 0, 0], [0, 0, 1, -1.0]])
    w = np.array([0.2, -0.4])          # the signal's design: the offset also scales with the run's load
    S = rs.signal_design(z, w)
    np.testing.assert_array_equal(S[0], [[1, 0.5, 0, 0, 0], [0, 0, 1, 0.5, 0.1]])
    np.testing.assert_array_equal(S[1], [[1, -1.0, 0, 0, 0], [0, 0, 1, -1.0, 0.4]])
    np.testing.assert_array_equal(rs.signal_design(z), D)


def test_heterogeneity_is_cochrans_q():
    theta = np.array([[1.0], [2.0], [4.0], [3.0]])
    cov = np.full((4, 1, 1), 0.5)
    q, p = rl.heterogeneity(theta, cov)
    assert q == pytest.approx(np.sum((theta - 2.5) ** 2) / 0.5)
    from scipy import stats
    assert p == pytest.approx(stats.chi2.sf(q, 3))


def _deviations(n=48, seed=2, slope=(0.04, 0.3)):
    """Runs' (gain, offset) with a between-run spread, a part explained by ``z`` and sampling noise."""
    rng = np.random.default_rng(seed)
    z = rng.normal(size=n)
    S = np.array([[4e-4, 0.0], [0.0, 0.01]])
    theta = (np.array([1.0, 0.0]) + np.outer(z, slope) + rng.multivariate_normal([0, 0], np.diag([1e-4, 4e-3]), n)
             + rng.multivariate_normal([0, 0], S, n))
    return rl.RunDeviations(np.arange(n), theta, np.repeat(S[None], n, axis=0), np.full(n, 500)), z, rng


def test_a_signal_explaining_the_runs_deviations_is_significant_and_noise_is_not_bonferroni_over_signals():
    dev, z, rng = _deviations()
    sigs = [{"channel": "aux", "transform": "none", "values": 3.0 + 2.0 * z},
            {"channel": "noise", "transform": "none", "values": rng.normal(size=len(z))},
            {"channel": "time_s", "transform": "none", "values": np.arange(len(z), dtype=float)}]
    ev = {e.channel: e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0,
                                                   session_order=np.arange(len(z), dtype=float))}
    assert ev["aux"].significant and ev["aux"].p_value < 1e-6 and ev["aux"].cv_gain > 0.3
    # the coefficients are per standard deviation of the signal: (gain, offset) slope x sd(z) / sd(values) x sd
    assert ev["aux"].coef[0] == pytest.approx(0.04 * np.std(z), rel=0.3)
    assert ev["aux"].coef[1] == pytest.approx(0.3 * np.std(z), rel=0.3)
    assert not ev["noise"].significant
    lam = np.clip(np.linalg.eigvalsh(np.corrcoef(np.column_stack([s["values"] for s in sigs]).T)), 0, None)
    m_eff = np.sqrt(lam).sum() ** 2 / lam.sum()          # Galwey's count of the three signals' tests
    assert 2.5 < m_eff < 3.0
    for e in ev.values():                      # Bonferroni over the signals' tests, and a positive held-out gain
        assert e.significant == (e.p_value < 0.01 / m_eff and e.cv_gain > 0)
    assert ev["time_s"].blocked_folds and not ev["aux"].blocked_folds
    # with the runs' loads the Wald test has three degrees of freedom (gain, offset, offset x load)
    dev.load = np.where(np.arange(len(z)) % 2 == 0, 0.5, -1.0)
    e = rl.signal_evidence(dev, sigs[:1], alpha=0.01, k=4, seed=0)[0]
    assert e.significant and e.coef[2] == pytest.approx(0.0, abs=0.1)


def test_effective_tests_count_orthogonal_columns_fully_and_copies_once():
    n = 64
    H = np.array([[1.0]])
    while len(H) < n:
        H = np.block([[H, H], [H, -H]])                    # Sylvester's Hadamard matrix: orthogonal +-1 columns
    assert rl.effective_tests(H[:, 1:6]) == pytest.approx(5.0, abs=1e-12)
    x = H[:, 1] + 0.5 * H[:, 2]
    assert rl.effective_tests(np.column_stack([x, 3 * x - 2, -x])) == pytest.approx(1.0, abs=1e-9)
    for r in (0.0, 0.3, 0.8, 0.99):                        # two columns with correlation r: 1 + sqrt(1 - r^2)
        y = r * H[:, 1] + np.sqrt(1 - r * r) * H[:, 2]
        assert rl.effective_tests(np.column_stack([H[:, 1], y])) == pytest.approx(1 + np.sqrt(1 - r * r), abs=1e-9)
    rng = np.random.default_rng(5)
    Z = rng.normal(size=(40, 6)) @ rng.normal(size=(6, 6))
    lam = np.linalg.eigvalsh(np.corrcoef(Z.T))
    assert rl.effective_tests(Z) == pytest.approx(np.sqrt(lam).sum() ** 2 / 6, rel=1e-9)
    assert rl.effective_tests(np.column_stack([Z[:, :2], np.ones(40)])) == pytest.approx(
        1 + rl.effective_tests(Z[:, :2]), rel=1e-12)        # a constant column: a test of its own
    assert rl.effective_tests(np.zeros((40, 0))) == 0.0 and rl.effective_tests(Z[:, :1]) == 1.0


def test_the_signal_count_takes_value_signals_by_their_tests_and_each_category_as_one():
    rng = np.random.default_rng(2)
    v = rng.normal(size=30)
    value = {"channel": "a", "transform": "none", "values": v}
    lagged = {"channel": "a_lag3r", "transform": "none", "values": 2 * v + 1}
    other = {"channel": "b", "transform": "none", "values": rng.normal(size=30)}
    cat = {"channel": "c", "transform": rl.fx.category.CATEGORY, "values": np.repeat([0.0, 1.0, 2.0], 10)}
    assert rl.effective_signal_count([value, lagged]) == pytest.approx(1.0)
    r = np.corrcoef(v, other["values"])[0, 1]
    # the correlations [[1, 1, r], [1, 1, r], [r, r, 1]]: eigenvalues 0 and (3 +- sqrt(1 + 8 r^2)) / 2
    lam = (3 + np.array([1, -1]) * np.sqrt(1 + 8 * r * r)) / 2
    assert rl.effective_signal_count([value, lagged, other, cat]) == pytest.approx(1 + np.sqrt(lam).sum() ** 2 / 3)
    assert rl.effective_signal_count([cat]) == 1.0 and rl.effective_signal_count([]) == 1.0


def test_a_channels_copies_do_not_dilute_another_signals_evidence_by_their_number():
    dev, z, rng = _deviations(slope=(0.04 * 0.24, 0.3 * 0.24))      # a weak signal
    u = rng.normal(size=len(z))
    sigs = [{"channel": "aux", "transform": "none", "values": 3.0 + 2.0 * z}] + [
        {"channel": f"u{j}", "transform": "none", "values": u + 0.05 * rng.normal(size=len(z))} for j in range(5)]
    lam = np.clip(np.linalg.eigvalsh(np.corrcoef(np.column_stack([s["values"] for s in sigs]).T)), 0, None)
    m_eff = np.sqrt(lam).sum() ** 2 / lam.sum()
    assert 1.8 < m_eff < 2.2                                  # aux and one channel read five times
    e = {x.channel: x for x in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)}["aux"]
    assert 0.01 / 6 < e.p_value < 0.01 / m_eff and e.cv_gain > 0   # between the two levels: the count decides
    assert e.significant


def _runs_frame(directions, seed=6):
    """Runs of 5 samples with a logged per-run channel ``aux``, a column the loop derived from it (``aux_lag3r``,
    named in the frame's derived columns) and the session clock; the runs' directions as given."""
    rng = np.random.default_rng(seed)
    rows = []
    for r, d in enumerate(directions):
        a = rng.uniform(-20.0, 20.0)
        rows.append(pd.DataFrame({"run": r, "time_s": 2.0 * r + 0.01 * np.arange(5),
                                  "position_m": d * np.linspace(-0.01, 0.01, 5), "voltage_V": 220.0 + 10.0 * (r % 3),
                                  "direction": float(d), "load_kg": 0.05 * ((r // 2) % 3 - 1), "speed_m_s": 0.1 * d,
                                  "aux": a + 0.01 * rng.normal(size=5), "aux_lag3r": 0.5 * a + r}))
    df = pd.concat(rows, ignore_index=True)
    df.attrs[DERIVED_ATTR] = ("aux_lag3r",)
    return df


def test_a_logged_channels_run_mean_times_the_direction_is_a_signal_of_its_own_a_derived_ones_is_not():
    d = np.array([1, -1, -1, 1, 1, -1, 1, -1, -1, 1, -1, 1], float)
    df = _runs_frame(d)
    chans = channels_of(df)
    assert {c["name"]: c["kind"] for c in chans if c["name"] in ("aux", "aux_lag3r")} == {"aux": "logged",
                                                                                       "aux_lag3r": "logged"}
    sigs = {(s["channel"], s["transform"]): s for s in rl.run_signals(df, chans)}
    mean = df.groupby("run")["aux"].mean().to_numpy()
    np.testing.assert_allclose(sigs[("aux", "none")]["values"], mean)
    assert sigs[("aux", "drive")]["centre"] == pytest.approx(mean.mean())
    np.testing.assert_allclose(sigs[("aux", "drive")]["values"], d * (mean - mean.mean()))   # d*aux, centred
    assert "centre" not in sigs[("load_kg", "drive")]
    assert sigs[("aux", "drive")]["run_spread"] == sigs[("aux", "none")]["run_spread"]
    assert ("aux_lag3r", "none") in sigs and ("aux_lag3r", "drive") not in sigs   # a history the loop derived
    assert ("time_s", "drive") not in sigs                                         # the protocol's clock
    assert ("load_kg", "drive") in sigs                                            # the plan's input, as before
    one_way = {(s["channel"], s["transform"]) for s in rl.run_signals(_runs_frame(np.ones(12)), chans)}
    assert ("aux", "none") in one_way and ("aux", "drive") not in one_way        # d*aux would copy aux
    h = fx.family("run_level").hypotheses([{**sigs[("aux", "drive")], "mean": 0.5, "sd": 2.0}])[0]
    assert h.family == "run_level_d*aux" and h.regressor == "aux" and h.spec["centre"] == pytest.approx(mean.mean())
    # the hypothesis's features: z = (d (run mean - centre) - 0.5) / 2 in the run-level form
    V0, dd, load = np.array([300.0, 220.0]), np.array([1.0, -1.0]), np.array([0.05, -0.05])
    x = {"V0": V0, "d": dd, "load": load, "run:aux": np.array([4.0, -3.0])}
    z = (dd * (x["run:aux"] - h.spec["centre"]) - 0.5) / 2.0
    np.testing.assert_allclose(fx.effect_features(h.spec, x),
                               np.column_stack([V0 / 300.0 * z, z, 9.81 * dd * load * z]))


def test_a_responses_run_setting_is_read_as_a_logged_setting_with_its_direction_and_curvature():
    # ``aux_setting`` (a run setting the loop derived from a response, :mod:`l1b2.closeloop.runsetting`) gets the
    # logged channel's direction and square copies; ``aux_lag3r`` (a history) still does not
    d = np.array([1, -1, -1, 1, 1, -1, 1, -1, -1, 1, -1, 1], float)
    df = _runs_frame(d).rename(columns={"aux": "aux_setting"})
    df.attrs[DERIVED_ATTR] = ("aux_lag3r", "aux_setting")
    sigs = {(s["channel"], s["transform"]): s for s in rl.run_signals(df, channels_of(df))}
    mean = df.groupby("run")["aux_setting"].mean().to_numpy()
    np.testing.assert_allclose(sigs[("aux_setting", "drive")]["values"], d * (mean - mean.mean()))
    u = mean - mean.mean()
    np.testing.assert_allclose(sigs[("aux_setting", "square")]["values"], u * u - np.mean(u ** 3) / np.mean(u * u) * u)
    assert ("aux_lag3r", "drive") not in sigs and ("aux_lag3r", "square") not in sigs


def test_a_gain_that_follows_the_channel_times_the_direction_shows_in_that_signal_alone():
    dev, z, rng = _deviations(slope=(0.04, 0.0))
    d = np.where(rng.uniform(size=len(z)) < 0.5, -1.0, 1.0)
    dev.theta[:, 0] = 1.0 + (dev.theta[:, 0] - 1.0 - 0.04 * z) + 0.04 * d * z   # the gain follows d z, not z
    c = 3.0 + 2.0 * z
    sigs = [{"channel": "aux", "transform": "none", "values": c},
            {"channel": "aux", "transform": "drive", "values": d * (c - c.mean()), "centre": c.mean()},
            {"channel": "direction", "transform": "none", "values": d}]
    ev = {(e.channel, e.transform): e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)}
    assert ev[("aux", "drive")].significant and ev[("aux", "drive")].p_value < 1e-6
    assert not ev[("aux", "none")].significant and not ev[("direction", "none")].significant
    offered = rl.offered_signal(ev[("aux", "drive")])          # what the loop offers to the run-level family
    assert offered["centre"] == pytest.approx(c.mean()) and offered["transform"] == "drive"
    assert "centre" not in rl.offered_signal(ev[("aux", "none")])


def test_a_logged_channels_curvature_over_the_runs_is_a_signal_of_its_own_a_derived_ones_is_not():
    d = np.array([1, -1, -1, 1, 1, -1, 1, -1, -1, 1, -1, 1], float)
    df = _runs_frame(d)
    chans = channels_of(df)
    sigs = {(s["channel"], s["transform"]): s for s in rl.run_signals(df, chans)}
    mean = df.groupby("run")["aux"].mean().to_numpy()
    u = mean - mean.mean()
    slope = np.polyfit(u, u ** 2, 1)[0]                                # the square's least-squares line in u
    assert abs(slope) > 0.05 * np.std(u)                               # the runs' spread is uneven
    sq = sigs[("aux", "square")]
    assert sq["centre"] == pytest.approx(mean.mean()) and sq["slope"] == pytest.approx(slope, rel=1e-9)
    np.testing.assert_allclose(sq["values"], u ** 2 - slope * u)
    assert abs(np.corrcoef(sq["values"], u)[0, 1]) < 1e-9              # the curvature alone
    assert sigs[("aux", "square")]["run_spread"] == sigs[("aux", "none")]["run_spread"]
    assert ("aux_lag3r", "square") not in sigs and ("time_s", "square") not in sigs   # derived; the clock
    assert not any(tr == "square" for ch, tr in sigs if ch in ("voltage_V", "load_kg", "direction"))   # inputs
    one_way = {(s["channel"], s["transform"]) for s in rl.run_signals(_runs_frame(np.ones(12)), chans)}
    assert ("aux", "square") in one_way                                           # no direction needed
    h = fx.family("run_level").hypotheses([{**sq, "mean": 90.0, "sd": 80.0}])[0]
    assert h.family == "run_level_aux^2" and h.regressor == "aux" and h.names[0] == "sq_aux_run_gain"
    assert h.spec["slope"] == sq["slope"] and h.spec["centre"] == sq["centre"]
    V0, dd, load = np.array([300.0, 220.0]), np.array([1.0, -1.0]), np.array([0.05, -0.05])
    x = {"V0": V0, "d": dd, "load": load, "run:aux": np.array([4.0, -13.0])}
    ux = x["run:aux"] - mean.mean()
    z = (ux ** 2 - slope * ux - 90.0) / 80.0
    np.testing.assert_allclose(fx.effect_features(h.spec, x),
                               np.column_stack([V0 / 300.0 * z, z, 9.81 * dd * load * z]))


def test_a_gain_linear_in_a_skewed_channel_shows_in_its_square_but_not_in_its_curvature():
    dev, z, rng = _deviations(slope=(0.0, 0.0))
    c = np.exp(z)                                                          # runs spread unevenly (log-normal)
    dev.theta[:, 0] += 0.04 * (c - c.mean()) / c.std()                     # monotone in the channel
    u = c - c.mean()
    slope = np.mean(u ** 3) / np.mean(u ** 2)
    sigs = [{"channel": "aux", "transform": "none", "values": c},
            {"channel": "sq", "transform": "none", "values": u ** 2},     # the plain square, for contrast
            {"channel": "aux", "transform": "square", "values": u ** 2 - slope * u, "centre": c.mean(),
             "slope": slope}]
    ev = {(e.channel, e.transform): e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)}
    assert ev[("aux", "none")].significant and ev[("aux", "none")].p_value < 1e-6
    assert ev[("sq", "none")].p_value < 1e-3                               # the square copies the channel in part
    assert not ev[("aux", "square")].significant and ev[("aux", "square")].p_value > 0.01


def test_a_gain_with_an_extremum_inside_the_channels_range_shows_in_its_curvature_alone():
    dev, z, rng = _deviations(slope=(0.04, 0.0))
    dev.theta[:, 0] = 1.0 + (dev.theta[:, 0] - 1.0 - 0.04 * z) + 0.04 * (z * z - np.mean(z * z))   # least at z 0
    c = 3.0 + 2.0 * z
    u = c - c.mean()
    slope = np.mean(u ** 3) / np.mean(u ** 2)
    sigs = [{"channel": "aux", "transform": "none", "values": c},
            {"channel": "aux", "transform": "square", "values": u ** 2 - slope * u, "centre": c.mean(),
             "slope": slope}]
    ev = {(e.channel, e.transform): e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)}
    assert ev[("aux", "square")].significant and ev[("aux", "square")].p_value < 1e-6
    assert not ev[("aux", "none")].significant
    offered = rl.offered_signal(ev[("aux", "square")])
    assert offered["centre"] == pytest.approx(c.mean()) and offered["transform"] == "square"
    assert offered["slope"] == pytest.approx(slope)
    assert ev[("aux", "square")].label == "aux^2"


def _gain_by_hand(theta, cov, z, folds):
    """:func:`runstats.cv_signal_gain` written out: per fold both REML fits on the other runs, the held-out runs'
    weighted squared deviations with the null fit's between-run covariance."""
    n, p = theta.shape
    X0, X1 = rs.design_rows(None, n, p), rs.signal_design(z)
    s0, s1 = np.zeros(n), np.zeros(n)
    for te in folds:
        tr = np.setdiff1d(np.arange(n), te)
        f0 = rl.reml(theta[tr], cov[tr], X0[tr])
        f1 = rl.reml(theta[tr], cov[tr], X1[tr])
        for out, X, beta in ((s0, X0, f0.beta), (s1, X1, f1.beta)):
            r = theta[te] - np.einsum("rpk,k->rp", X[te], beta)
            out[te] = np.einsum("rp,rpq,rq->r", r, np.linalg.inv(f0.T[None] + cov[te]), r)
    return 1 - s1.sum() / s0.sum(), (s0 - s1) / s0.mean()


def test_the_null_fold_fits_are_shared_by_value_of_the_runs_and_the_folds():
    """The memo of the null model's fold fits gives every signal the fits of its own folds and runs' deviations:
    two fold schemes and two sets of deviations through one memo give, to the last bit, the gains computed
    without it (a memo keyed by the fold's position, or not by the deviations, hands over another fold's fit)."""
    dev, z, rng = _deviations(n=30)
    rand = [np.sort(f) for f in np.array_split(rng.permutation(30), 4)]
    blocks = [np.asarray(b) for b in np.array_split(np.arange(30), 4)]
    other = dev.theta + rng.normal(scale=0.05, size=dev.theta.shape)
    memo: dict = {}
    for theta, folds in ((dev.theta, rand), (dev.theta, blocks), (other, rand), (dev.theta, rand)):
        g, per_run = rs.cv_signal_gain(theta, dev.cov, z, folds, null_fits=memo)
        g_ref, per_run_ref = _gain_by_hand(theta, dev.cov, z, folds)
        assert g == g_ref and np.array_equal(per_run, per_run_ref)
    assert len(memo) == 12                       # one fit per distinct (deviations, fold): 4 + 4 + 4
    te = rand[1]
    tr = np.setdiff1d(np.arange(30), te)
    again = rs.null_fold_fit(dev.theta, dev.cov, te.copy(), memo)
    assert again is rs.null_fold_fit(dev.theta, dev.cov, te, memo)           # taken from the memo
    fresh = rl.reml(dev.theta[tr], dev.cov[tr], rs.design_rows(None, 30, 2)[tr])
    assert np.array_equal(again.T, fresh.T) and np.array_equal(again.beta, fresh.beta)


def test_run_level_offer_adds_the_strongest_signal_of_an_unread_second_regressor():
    def cand(fam, reg):
        return CandidateForce(fam, reg, "", ("a",), ("N",), None)
    short = [types.SimpleNamespace(candidate=CandidateForce("load_slope_voltage", "load", "", ("a",), ("N",), None,
                                                           also=("voltage",)))]
    found = [cand("run_level_voltage_V", "voltage"), cand("run_level_voltage_V_step", "voltage"),
             cand("run_level_d*load_kg", "load"), cand("run_level_time_s", "time"), cand("run_level_aux_C", "aux_C")]
    fams = lambda cs: [c.family for c in cs]   # noqa: E731
    # the shortlist reads voltage and load: the second is the first of another regressor it does not read
    assert fams(rl.offer(found, short, lambda c: True)) == ["run_level_voltage_V", "run_level_time_s"]
    # no shortlist: the first of another regressor than the strongest's, whichever regressors follow
    assert fams(rl.offer(found, [], lambda c: True)) == ["run_level_voltage_V", "run_level_d*load_kg"]
    # the strongest of a regressor the shortlist does not read is offered with the next such one
    assert fams(rl.offer(found[3:], short, lambda c: True)) == ["run_level_time_s", "run_level_aux_C"]
    # a shortlisted family is not offered again, and a candidate that is not allowed is skipped
    assert fams(rl.offer(found, [types.SimpleNamespace(candidate=found[0])], lambda c: True)) == \
        ["run_level_voltage_V_step", "run_level_d*load_kg"]
    assert fams(rl.offer(found, [], lambda c: c.regressor != "load")) == ["run_level_voltage_V", "run_level_time_s"]
    assert fams(rl.offer(found[:2], [], lambda c: True)) == ["run_level_voltage_V"]   # one regressor: one offer
    assert rl.offer(found, short, lambda c: False) == []


def _balanced_runs():
    """12 runs, 40 samples each: V0 in (220, 290, 324) V x load in (0.03, 0.07) kg x both directions, so that the
    runs' drive-coordinate loads d m average to exactly 0."""
    rows = []
    for k, (v, m, d) in enumerate((v, m, d) for v in (220.0, 290.0, 324.0) for m in (0.03, 0.07) for d in (1.0, -1.0)):
        rows.append(pd.DataFrame({"run": k, "time_s": 10.0 * k + 1e-3 * np.arange(40),
                                  "position_m": d * np.linspace(-0.01, 0.01, 40), "voltage_V": v, "direction": d,
                                  "load_kg": m, "speed_m_s": 0.1 * d}))
    return pd.concat(rows, ignore_index=True)


def _run_level_form(df, channel, transform, drop=None):
    """The loop's run-level form of an input signal (:func:`runlevel.run_signals`, standardised over the runs)."""
    [sg] = [s for s in rl.run_signals(df, []) if (s["channel"], s["transform"]) == (channel, transform)]
    [h] = fx.family("run_level").hypotheses([{**sg, "mean": float(np.mean(sg["values"])),
                                              "sd": float(np.std(sg["values"])), **({"drop": drop} if drop else {})}])
    return candidate(None, h)


def test_a_run_level_load_form_after_the_voltage_form_is_offered_without_their_shared_column():
    # written out: the V0 form's load column z_V g d m = g (V0 d m - mean_V d m) / sd_V; with mean(d m) = 0 the load
    # form's gain and offset columns z_w V0 / V_ref and z_w = d m / sd_w span both V0 d m and d m, so the full load
    # form can reproduce an added column; without its gain (or its offset) it cannot
    from l1b2.closeloop.acceptance import EffectSet, collinear
    df = _balanced_runs()
    mask = np.ones(len(df), bool)
    dm = df["direction"].to_numpy() * df["load_kg"].to_numpy()
    assert abs(np.mean(dm)) < 1e-12 and np.ptp(dm) > 0          # every run has 40 samples: the runs' mean too
    added = EffectSet().add(_run_level_form(df, "voltage_V", "none"), np.zeros(3))
    full = _run_level_form(df, "load_kg", "drive")
    reduced = [_run_level_form(df, "load_kg", "drive", d) for d in rl.REDUCED]
    assert [c.shape for c in reduced] == ["run, no gain", "run, no load", "run, no offset"]
    assert collinear(full, added, df, mask)
    assert [collinear(c, added, df, mask) for c in reduced] == [False, True, False]
    # candidates(): every significant signal's full form, strongest first, then their reduced forms
    def ev(channel, transform, p):
        return rl.SignalEvidence(channel, transform, channel, channel, 0.0, 1.0, p_value=p, significant=True)
    ana = rl.RunLevelAnalysis(None, None, float("nan"), 1.0, [ev("load_kg", "drive", 1e-6),
                                                              ev("load_kg", "abs", 1e-4)], 0.001)
    found = rl.candidates(ana, None)
    assert [c.label for c in found] == ["run_level_d*load_kg[run]", "run_level_|load_kg|[run]"] + [
        f"run_level_{s}[run, no {d}]" for s in ("d*load_kg", "|load_kg|") for d in rl.REDUCED]
    assert {c.regressor for c in found} == {"load"}

    # the offer takes a reduced form only when no full form of its regressor is allowed
    def allowed(c):
        return not collinear(c, added, df, mask)
    found = [full] + reduced
    assert [c.label for c in rl.offer(found, [], allowed)] == ["run_level_d*load_kg[run, no gain]"]
    assert [c.label for c in rl.offer(found, [], lambda c: True)] == ["run_level_d*load_kg[run]"]
    size = _run_level_form(df, "load_kg", "abs")
    assert not collinear(size, added, df, mask) and size.regressor == full.regressor
    assert [c.label for c in rl.offer([full, size] + reduced, [], allowed)] == ["run_level_|load_kg|[run]"]
    with pytest.raises(fx.EffectSpecError, match="drop 'slope' is not one of gain, offset, load"):
        _run_level_form(df, "load_kg", "drive", "slope").features(df)


def test_a_run_level_voltage_form_after_the_full_load_form_is_refused_and_offered_without_its_load_column():
    # the other order, written out: the added load form's gain and offset columns z_w V0 / V_ref and z_w = d m / sd_w
    # span V0 d m and d m, so the V0 form's load column g (V0 d m - mean_V d m) / sd_V lies in the added span while no
    # added column lies in the V0 form's span: only the check of the candidate's columns finds it
    from l1b2.closeloop.acceptance import EffectSet, collinear
    df = _balanced_runs()
    mask = np.ones(len(df), bool)
    load = _run_level_form(df, "load_kg", "drive")
    added = EffectSet().add(load, np.zeros(3))
    full = _run_level_form(df, "voltage_V", "none")
    F, C = (np.asarray(c.features(df), float) for c in (load, full))
    own = np.linalg.lstsq(C, F, rcond=None)[0]                      # one way: every added column misses C's span
    assert np.all(np.linalg.norm(F - C @ own, axis=0) > 0.1 * np.linalg.norm(F, axis=0))
    col = np.linalg.lstsq(F, C[:, 2], rcond=None)[0]                # the other: C's load column is in F's span
    assert np.linalg.norm(F @ col - C[:, 2]) < 1e-9 * np.linalg.norm(C[:, 2])
    assert collinear(full, added, df, mask)
    reduced = [_run_level_form(df, "voltage_V", "none", d) for d in rl.REDUCED]
    assert [collinear(c, added, df, mask) for c in reduced] == [True, False, True]
    assert [c.label for c in rl.offer([full] + reduced, [], lambda c: not collinear(c, added, df, mask))] == \
        ["run_level_voltage_V[run, no load]"]


def test_one_step_force_deviations_are_recovered_per_run():
    # a stub model whose one-step prediction misses, in run r, the force g_r x (model drive force / its mean) + o_r
    n_runs, n = 5, 60
    rng = np.random.default_rng(3)
    rows = []
    for r in range(n_runs):
        d = 1.0 if r % 2 == 0 else -1.0
        rows.append(pd.DataFrame({"run": r, "time_s": 100.0 * r + 1e-3 * np.arange(n),
                                  "position_m": d * np.linspace(-0.01, 0.01, n), "voltage_V": 220.0 + 20 * r,
                                  "direction": d, "load_kg": 0.02 * r, "speed_m_s": d * 0.1}))
    df = pd.concat(rows, ignore_index=True)
    params = types.SimpleNamespace(order=1, alpha=[0.0, 0.0], beta=[1.0, 0.5], p=[0.0, 0.0],
                                   include_load_inertia=True, scaled_position=lambda s: np.asarray(s) / 0.012)
    g_true, o_true = rng.normal(0.0, 0.05, n_runs), rng.normal(0.0, 0.2, n_runs)
    runs = df["run"].to_numpy()
    s_prev = np.roll(df["position_m"].to_numpy(), 1)
    drive = (1.0 + 0.5 * s_prev / 0.012) * df["voltage_V"].to_numpy()
    first = np.r_[True, runs[1:] != runs[:-1]]
    drive_rel = drive / np.mean(np.abs(drive[~first]))
    m_eff = 0.12 + np.abs(df["load_kg"].to_numpy())
    force = g_true[runs] * drive_rel + o_true[runs]
    d = df["direction"].to_numpy()
    pred = df["speed_m_s"].to_numpy() - d * force * 1e-3 / m_eff      # v - v^ = d dF dt / m_eff
    model = types.SimpleNamespace(params_=params, m_s_=0.12, predict_one_step=lambda _df: pred)
    dev = rl.run_deviations(df, model, np.ones(len(df), bool))
    np.testing.assert_allclose(dev.theta[:, 0], g_true, atol=1e-6)
    np.testing.assert_allclose(dev.theta[:, 1], o_true, atol=1e-6)
    assert dev.n.tolist() == [n - 1] * n_runs                        # each run's first sample has no one-step


# ---------------------------------------------------------------------------
# the run-level family, the preference rule, the response columns
# ---------------------------------------------------------------------------

def test_run_level_features_are_the_standardised_run_signal_times_the_drive_gain_and_one():
    V0, d = np.array([300.0, 150.0, 240.0, 330.0]), np.array([1.0, -1.0, 1.0, -1.0])
    run_mean = np.array([2.0, 2.0, -4.0, -4.0])
    load = np.array([0.05, 0.05, -0.02, -0.02])
    x = {"V0": V0, "d": d, "load": load, "run:load_kg": run_mean}
    spec = {"kind": "run_level", "channel": "load_kg", "mean": 1.0, "sd": 2.0}
    for tr, c in (("none", run_mean), ("drive", d * run_mean), ("abs", np.abs(run_mean))):
        z = (c - 1.0) / 2.0
        np.testing.assert_allclose(fx.effect_features({**spec, "transform": tr}, x),
                                   np.column_stack([V0 / 300.0 * z, z, 9.81 * d * load * z]))
    assert fx.needs({**spec, "transform": "drive"}) == {"V0", "d", "load", "run:load_kg"}
    h = fx.family("run_level").hypotheses([{"channel": "load_kg", "transform": "drive", "mean": 0.0, "sd": 1.0}])[0]
    assert h.family == "run_level_d*load_kg" and h.regressor == "load" and h.generic


def _trial(family, gain, n=1, generic=True, spec=None, regressor="time"):
    c = CandidateForce(family, regressor, "", tuple(f"p{i}" for i in range(n)), ("N",) * n, None, generic=generic,
                       spec=spec or {})
    cur = acc.FoldErrors(np.ones(4), np.full(4, 100.0))
    return acc.RefitCV(c, cur, acc.FoldErrors(np.full(4, 1.0 - gain), np.full(4, 100.0)))


def test_the_run_level_form_is_preferred_when_the_run_level_evidence_names_its_regressor():
    spline = _trial("smooth_time", 0.50, n=6, spec={"kind": "smooth", "regressor": "time"})
    runlev = _trial("run_level_time_s", 0.46, n=2, spec={"kind": "run_level", "channel": "time_s"})
    sample = _trial("channel_time_s", 0.47, n=1, spec={"kind": "channel", "channel": "time_s", "level": "sample"})
    named = _trial("thermal_drift", 0.46, n=6, generic=False, spec={"kind": "thermal_drift"})
    ev = types.SimpleNamespace(significant=[types.SimpleNamespace(regressor="time")])
    assert prefer([spline, runlev, sample], 0.9, ev) is runlev         # run-level evidence: the run-level form
    assert prefer([spline, runlev, sample], 0.9, None) is sample       # otherwise the fewest parameters
    assert prefer([spline, runlev, sample, named], 0.9, ev) is named   # a named family first
    far = _trial("run_level_time_s", 0.40, n=2, spec={"kind": "run_level", "channel": "time_s"})
    assert prefer([spline, far], 0.9, ev) is spline                    # outside the parsimony band: the best


def test_response_columns_are_a_setting_default_the_vibrometer():
    df = pd.DataFrame({"time_s": [0.0, 0.1, 5.0, 5.1], "run": [1, 1, 2, 2], "position_m": 0.0, "voltage_V": 200.0,
                       "direction": 1, "load_kg": 0.0, "speed_m_s": 0.1, "aux": [1.0, 1.0, 3.0, 3.0],
                       "tip_velocity_amp_m_s": [1.0, 1.1, 1.2, 1.3]})
    kinds = {c["name"]: c["kind"] for c in channels_of(df)}
    assert kinds["tip_velocity_amp_m_s"] == "response" and kinds["aux"] == "logged"
    kinds = {c["name"]: c["kind"] for c in channels_of(df, ("aux",))}
    assert kinds["tip_velocity_amp_m_s"] == "logged" and kinds["aux"] == "response"
    assert CloseLoop().get_params()["response_columns"] is None
    assert CloseLoop(response_columns=("aux",)).get_params()["response_columns"] == ("aux",)
    args = build_parser().parse_args(["close-loop", "--train", "a.csv", "--out", "o", "--response-column", "x",
                                      "--response-column", "y"])
    assert args.response_columns == ["x", "y"]
    assert build_parser().parse_args(["close-loop", "--train", "a.csv", "--out", "o"]).response_columns is None


# ---------------------------------------------------------------------------
# the rig's run-level injections
# ---------------------------------------------------------------------------

def test_run_injections_name_their_family_and_the_regressor_they_show_in():
    sup, pre = rig.RUN_INJECTIONS["supply_sag"], rig.RUN_INJECTIONS["preload_settling"]
    assert fx.family(sup.effect).kind == "channel" and sup.regressor == "supply_V"
    assert fx.family(pre.effect).kind == "run_level" and pre.regressor == "time"


def test_run_effects_follow_their_formulas():
    plan = rig.RigPlan(seed=5)
    vals = {"Rig.supply_sd_rel": 0.04, "Rig.settling_depth_rel": 0.1, "Rig.settling_runs": 20.0}
    f = rig.run_effects(plan, 30, vals)
    z = np.random.default_rng([5, 3]).standard_normal(30)
    np.testing.assert_allclose(f["supply"], 1 + 0.04 * z)
    np.testing.assert_allclose(f["preload"], 1 - 0.1 * (1 - np.exp(-np.arange(30) / 20.0)))
    off = rig.run_effects(plan, 3, {})
    assert off["supply"].tolist() == [1.0] * 3 and off["preload"].tolist() == [1.0] * 3


def test_a_sagging_supply_is_logged_and_slows_its_runs():
    plan = rig.RigPlan(voltages_V=(290.0,), loads_kg=(0.0,), directions=(1, -1), step_s=1e-3, seed=3)
    clean, _ = rig.run_experiment(plan, injections=[])
    sag, truth = rig.run_experiment(plan, injections=[("supply_sag", {"Rig.supply_sd_rel": 0.05})])
    factors = np.array(truth["run_factors"]["supply"])
    logged = sag.groupby("run")["supply_V"].mean().to_numpy()
    np.testing.assert_allclose(logged, 48.0 * factors, atol=0.02)
    assert "supply_V" not in clean.columns
    ratio = (sag.groupby("run")["speed_m_s"].apply(lambda v: np.abs(v).max()).to_numpy()
             / clean.groupby("run")["speed_m_s"].apply(lambda v: np.abs(v).max()).to_numpy())
    assert np.all(np.sign(ratio - 1) == np.sign(factors - 1)), (ratio, factors)


def test_each_rounds_run_level_record_lists_every_signal_by_p_and_the_report_says_what_is_left():
    from l1b2.closeloop.report import left_line
    dev, z, rng = _deviations()
    sigs = [{"channel": "noise", "transform": "none", "values": rng.normal(size=len(z))},
            {"channel": "weak", "transform": "none", "values": 0.3 * z + rng.normal(size=len(z))},
            {"channel": "aux", "transform": "none", "values": 3.0 + 2.0 * z}]
    ev = sorted(rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0), key=lambda e: -e.p_value)
    assert len({e.p_value for e in ev}) == 3       # the analysis lists them largest p first: the record sorts them
    analysis = rl.RunLevelAnalysis(dev, None, float("nan"), 1.0, ev, 0.01 / 3)
    rec = analysis.round_record(2)
    assert rec["round"] == 2 and rec["significant_signals"] == [e.label for e in ev if e.significant]
    ps = [s["p_value"] for s in rec["signals"]]
    assert ps == sorted(ps) and sorted(s["signal"] for s in rec["signals"]) == ["aux", "noise", "weak"]
    by = {s["signal"]: s for s in rec["signals"]}
    for e in ev:
        assert by[e.label]["p_value"] == e.p_value and by[e.label]["significant"] == e.significant
    line = left_line([{"round": 1, "significance_level": 1.0, "signals": []}, analysis.round_record(None)])
    assert "after the last round" in line and f"aux (p {by['aux']['p_value']:.2g})" in line.split("not significant")[0]
    assert "noise" not in line or by["noise"]["p_value"] < 0.05
    near = [s for s in rec["signals"] if not s["significant"] and s["p_value"] < 0.05]
    assert all(f"{s['signal']} (p" in line.split("not significant")[1] for s in near)
    assert left_line([]) == ""
    assert "in round 3" in left_line([analysis.round_record(3)])
