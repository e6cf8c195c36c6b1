"""The close loop's selection rules and every effect's features, each against a formula written out here.

Fast unit tests (seconds): a wrong fold split, a CV gain taken as 1 - sqrt(SSE1/SSE0), a dropped Bonferroni
correction or a wrong sign in an effect's features fails one of them.
"""

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import acceptance as acc
from l1b2.closeloop import folds as fo
from l1b2.closeloop import residuals as res
from l1b2.closeloop import selection as sel
from l1b2.closeloop.candidates import CandidateForce
from l1b2.predictor import effects as fx

G = 9.81


def _runs_frame(n_runs=23, seed=3):
    rng = np.random.default_rng(seed)
    rows = []
    for r in range(n_runs):
        rows.append(pd.DataFrame({"run": r, "direction": rng.choice([-1, 1]),
                                  "voltage_V": rng.choice([220.0, 255.0, 290.0]), "time_s": r + np.arange(3) * 0.1}))
    return pd.concat(rows, ignore_index=True)


@pytest.mark.parametrize("k", [2, 4, 5])
def test_stratified_folds_hold_out_every_run_exactly_once_and_balance_each_stratum(k):
    df = _runs_frame()
    folds = fo.stratified_folds(df, k, seed=7)
    assert len(folds) == k
    held = np.concatenate(folds)
    assert sorted(held.tolist()) == sorted(pd.unique(df["run"]).tolist())   # each run once, none missing
    first = df.groupby("run")[["direction", "voltage_V"]].first()
    for _, stratum in first.groupby(["direction", "voltage_V"]):
        counts = [int(np.isin(stratum.index, f).sum()) for f in folds]
        assert max(counts) - min(counts) <= 1, counts
    assert [f.tolist() for f in fo.stratified_folds(df, k, seed=7)] == [f.tolist() for f in folds]  # seeded


def test_a_held_out_split_scores_only_the_held_runs_masked_samples_per_run():
    # reference: sse = sum over held-out rows on the mask of (v - p)^2, per run the same sum; ss_meas = sum v^2 there
    df = pd.DataFrame({"run": [1, 1, 2, 2, 2, 3, 3], "speed_m_s": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]})
    mask = np.array([True, True, True, False, True, True, False])
    split = fo.held_out_split(df, mask, [2, 3])
    assert split.held.tolist() == [False, False, True, True, True, True, True]
    assert split.train["run"].tolist() == [1, 1] and split.mask_train.tolist() == [True, True]
    assert split.test.index.tolist() == [0, 1, 2, 3, 4] and split.mask_test.tolist() == [True, False, True, True, False]
    pred = np.array([2.5, 0.0, 4.0, 5.5, 100.0])            # rows with mask False never count
    sse, ssm, failed, nfev, per_run = split.score(pred, 7)
    assert per_run == {2: pytest.approx(0.5 ** 2 + 1.0 ** 2), 3: pytest.approx(0.5 ** 2)}
    assert sse == pytest.approx(0.25 + 1.0 + 0.25) and ssm == pytest.approx(9.0 + 25.0 + 36.0)
    assert (failed, nfev) == (False, 7)
    diverged = split.score(np.array([2.5, 0.0, np.nan, 5.5, 0.0]), 3)
    assert diverged[0] == np.inf and diverged[4] == {2: np.inf, 3: np.inf} and diverged[2] is False
    assert split.failed() == (np.inf, ssm, True, 0, {2: np.inf, 3: np.inf})


@pytest.mark.parametrize("k", [3, 5])
def test_run_folds_hold_out_every_run_exactly_once(k):
    runs = np.repeat(np.arange(17), 4)
    folds = res.run_folds(runs, k, seed=2)
    assert len(folds) == k and sorted(np.concatenate(folds).tolist()) == list(range(17))
    assert max(map(len, folds)) - min(map(len, folds)) <= 1


def test_refit_cv_gain_is_one_minus_the_ratio_of_sums_of_squares():
    c = CandidateForce("x", "time", "", ("a",), ("N",), features=None)
    cur = acc.FoldErrors(np.array([4.0, 4.0, 2.0]), np.array([100.0, 100.0, 100.0]))
    ext = acc.FoldErrors(np.array([1.0, 3.0, 1.0]), np.array([100.0, 100.0, 100.0]))
    r = acc.RefitCV(c, cur, ext)
    assert r.gain == pytest.approx(1 - 5.0 / 10.0)             # not 1 - sqrt(0.5)
    assert r.folds_improved == 3
    assert cur.nrmse == pytest.approx(np.sqrt(10.0 / 300.0))
    assert acc.accepts(r, min_gain=0.5, min_drop=0.0) and not acc.accepts(r, min_gain=0.51, min_drop=0.0)
    # most folds must improve: 1 of 3 is not enough, whatever the pooled gain
    worse = acc.RefitCV(c, cur, acc.FoldErrors(np.array([0.1, 5.0, 3.0]), cur.ss_meas))
    assert worse.gain == pytest.approx(1 - 8.1 / 10.0) and not acc.accepts(worse, min_gain=0.01, min_drop=0.0)
    failed = acc.RefitCV(c, cur, acc.FoldErrors(ext.sse, ext.ss_meas, failed=1))
    assert not acc.accepts(failed, min_gain=0.0, min_drop=0.0)


def _held_out_sse(y, X, runs, folds):
    """Per-run held-out SSE of least squares on X, fitted on the other folds (written out)."""
    out = {}
    for fold in folds:
        te = np.isin(runs, fold)
        beta = np.linalg.lstsq(X[~te], y[~te], rcond=None)[0]
        e = y[te] - X[te] @ beta
        for r in fold:
            out[r] = float(np.sum(e[runs[te] == r] ** 2))
    return out


def test_linearised_cv_gain_is_one_minus_held_out_sse_ratio():
    rng = np.random.default_rng(0)
    runs = np.repeat(np.arange(12), 30)
    n = len(runs)
    N = rng.normal(size=(n, 2))
    S = rng.normal(size=(n, 1))
    y = 0.5 * N[:, 0] + 0.8 * S[:, 0] + rng.normal(0, 0.5, n)
    folds = res.run_folds(runs, 4, 0)
    solver = sel.FoldSolver(y, N, runs, folds)
    gain, per_run = solver.gain(S)
    A = np.column_stack([np.ones(n), N])
    s0 = _held_out_sse(y, A, runs, folds)
    s1 = _held_out_sse(y, np.column_stack([A, S]), runs, folds)
    keys = sorted(s0)
    sse0, sse1 = sum(s0[k] for k in keys), sum(s1[k] for k in keys)
    assert gain == pytest.approx(1 - sse1 / sse0, rel=1e-6)
    assert 0.2 < gain < 0.9 and abs(gain - (1 - np.sqrt(sse1 / sse0))) > 0.05   # the sqrt form is far off
    np.testing.assert_allclose(sorted(per_run), sorted((np.array([s0[k] - s1[k] for k in keys]))
                                                        / np.mean([s0[k] for k in keys])), rtol=1e-6)
    # the residual analysis' gain follows the same formula (its ridge is negligible at lam=1e-12)
    g2, _, _ = res.cv_gain(y, S, runs, folds, base=N, lam=1e-12)
    assert g2 == pytest.approx(1 - sse1 / sse0, rel=1e-6)


def _score(family, p, gain=0.3, aic=-5.0, generic=False, n=1):
    c = CandidateForce(family, "time", "", tuple(f"p{i}" for i in range(n)), ("N",) * n, features=None,
                       generic=generic)
    return sel.Score(c, gain, p, 1.0, 0.0, np.zeros(n), aic)


def _shaped(family, shape, p, gain, aic=-5.0, n=2):
    c = CandidateForce(family, "aux", "", tuple(f"{family}_{shape}_{i}_{gain}" for i in range(n)), ("N",) * n,
                       features=None, generic=True, spec={"kind": "channel", "shape": shape})
    return sel.Score(c, gain, p, 1.0, 0.0, np.zeros(n), aic)


def test_every_shape_of_a_shortlisted_family_that_passes_the_screen_is_cross_validated():
    # reference: the screen keeps a family's best hypothesis by its linearised gain (here the odd shape); the
    # family's best of each other shape that passes the same screen (gain >= min_gain, p < level, AIC improves)
    # goes to the cross-validated refit too, once per shape; a shape failing any screen rule, another family's
    # shapes and the shortlisted hypothesis itself do not
    odd = _shaped("channel_h", "odd", 1e-4, 0.40)
    quad = _shaped("channel_h", "quadratic", 1e-4, 0.35)
    quad2 = _shaped("channel_h", "quadratic", 1e-5, 0.30)            # the same shape, a smaller gain
    lin = _shaped("channel_h", "linear", 1e-3, 0.20, n=1)
    lin_p = _shaped("channel_h", "linear", 0.2, 0.25, n=1)           # a larger gain, but p above the level
    odd2 = _shaped("channel_h", "odd", 1e-4, 0.39)                   # the shortlisted shape's runner-up
    other = _shaped("channel_k", "quadratic", 1e-6, 0.5)             # not shortlisted
    weak = _shaped("channel_w", "odd", 1e-6, 0.30, aic=1.0)
    weak_alt = _shaped("channel_w", "linear", 1e-6, 0.04, n=1)       # below min_gain
    scores = [odd, quad, quad2, lin, lin_p, odd2, other, weak, weak_alt]
    level = 0.01
    alt = sel.shape_alternatives([odd], scores, level=level, min_gain=0.05)
    assert [a.candidate is b.candidate for a, b in zip(alt, [quad, lin])] == [True, True] and len(alt) == 2
    assert [a.origin for a in alt] == ["shape", "shape"] and [a.p_value for a in alt] == [quad.p_value, lin.p_value]
    assert sel.shape_of(odd.candidate) == "odd" and sel.shape_of(CandidateForce(
        "x", "time", "", ("a",), ("N",), features=None)) == "linear"
    # with the level at 0.5 the linear shape's best passing hypothesis is lin_p (larger gain)
    assert [s.candidate is lin_p.candidate
            for s in sel.shape_alternatives([odd], scores, level=0.5, min_gain=0.05)] == [False, True]
    assert sel.shape_alternatives([weak], scores, level=level, min_gain=0.05) == []
    assert sel.shape_alternatives([], scores, level=level, min_gain=0.05) == []
    # the refit then chooses: the quadratic shape's cross-validated gain beats the odd one's
    from l1b2.closeloop.loop import prefer

    def trial(s, gain):
        cur = acc.FoldErrors(np.ones(4), np.full(4, 100.0))
        return acc.RefitCV(s.candidate, cur, acc.FoldErrors(np.full(4, 1.0 - gain), np.full(4, 100.0)))
    assert prefer([trial(odd, 0.20), trial(quad, 0.35), trial(lin, 0.10)], 0.9).candidate is quad.candidate
    assert prefer([trial(odd, 0.36), trial(quad, 0.35), trial(lin, 0.34)], 0.9).candidate is lin.candidate


#: eight held-out runs in four folds of two (every run in exactly one fold)
RUN_FOLDS = [[0, 4], [1, 5], [2, 6], [3, 7]]


def _errors(run_sse):
    """:class:`FoldErrors` of per-run held-out SSEs ``run_sse`` (run i at index i): the folds' SSEs are their sums."""
    run_sse = np.asarray(list(run_sse), float)
    return acc.FoldErrors(np.array([run_sse[f].sum() for f in RUN_FOLDS]), np.full(len(RUN_FOLDS), 100.0),
                          run_sse={i: float(x) for i, x in enumerate(run_sse)})


def _run_trial(score, run_sse, cur):
    """A refit trial of ``score``'s candidate with per-run held-out SSEs ``run_sse`` against the current model's."""
    return acc.RefitCV(score.candidate, cur, _errors(run_sse))


def test_per_run_gap_and_standard_error_written_out():
    # reference, by hand: current per-run SSE [10, 12, 8, 10, 9, 11, 10, 10] (mean 10), the best's
    # [5, 6, 4, 5, 4.5, 5.5, 5, 5], the trial's [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5]; per run
    # delta = (trial - best) / 10 = [0.25, -0.05, 0.15, -0.1, -0.15, 0.1, -0.1, 0.15]: mean 0.25 / 8 = 0.03125
    # (the pooled gains' difference: (42.5 - 40) / 80), sum of squared deviations 0.1625 - 8 * 0.03125**2 = 0.1546875,
    # sd = sqrt(0.1461875 / 7), se = sd / sqrt(8)
    cur = _errors([10, 12, 8, 10, 9, 11, 10, 10])
    best = _run_trial(_shaped("channel_h", "odd", 1e-4, 0.4), [5, 6, 4, 5, 4.5, 5.5, 5, 5], cur)
    lin = _run_trial(_shaped("channel_h", "linear", 1e-4, 0.3, n=1), [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5], cur)
    gap, se = acc.one_se_gap_per_run(lin, best)
    assert gap == pytest.approx(0.03125, rel=1e-12) and gap == pytest.approx(best.gain - lin.gain, rel=1e-12)
    assert se == pytest.approx(np.sqrt(0.1546875 / 7) / np.sqrt(8), rel=1e-12)      # 0.05256
    # the folds' gap is the same number; its standard error over the four folds is another one: per fold
    # (trial - best) / 20 = [1, 0.5, 0.5, 0.5] / 20, sd 0.0125 over sqrt(4) = 0.00625
    fgap, fse = acc.one_se_gap(lin, best)
    assert fgap == pytest.approx(gap, rel=1e-12) and fse == pytest.approx(0.00625, rel=1e-12)
    # not the same current model's runs, or a run missing: no paired gap
    assert acc.one_se_gap_per_run(lin, _run_trial(best, best.extended.run_sse.values(),
                                                  _errors([10, 12, 8, 10, 9, 11, 10, 10.5]))) is None
    assert acc.one_se_gap_per_run(acc.RefitCV(lin.candidate, cur, acc.FoldErrors(lin.extended.sse,
                                                                                  lin.extended.ss_meas)), best) is None
    assert acc.paired_gap([1.0, np.inf], [1.0, 1.0], [2.0, 2.0]) is None


def test_one_standard_error_rule_keeps_the_simplest_shape_of_a_family():
    # reference: among one family's accepted shapes, those whose pooled CV gain is below the best's by at most one
    # standard error of the gap paired per held-out run are equivalent; the simplest of them is kept (fewest
    # parameters, then the lowest polynomial degree of the shape: linear 1, quadratic 2, odd 3); another family is
    # left alone. Per run, delta = (trial - best) / mean(current) with mean(current) = 10 here.
    cur = _errors([10, 12, 8, 10, 9, 11, 10, 10])
    B = [5, 6, 4, 5, 4.5, 5.5, 5, 5]
    odd = _run_trial(_shaped("channel_h", "odd", 1e-4, 0.4), B, cur)                          # gain 0.5, best
    # gap 0.03125, se 0.0526 (test above): within one per-run SE. Over the four folds the SE is 0.00625 and the
    # gap beyond it: a rule on the folds' SE would keep the best
    lin = _run_trial(_shaped("channel_h", "linear", 1e-4, 0.3, n=1), [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5], cur)
    other = _run_trial(_shaped("channel_k", "odd", 1e-4, 0.3), [9.0] * 8, cur)
    other_lin = _run_trial(_shaped("channel_k", "linear", 1e-4, 0.3, n=1), B, cur)
    out = sel.simplest_within_one_se([other, odd, lin, other_lin])
    assert [t is u for t, u in zip(out, [lin, other_lin])] == [True, True] and len(out) == 2
    # delta = [0.09, 0, 0.05, 0, 0.07, 0.01, 0.03, 0.01]: gap 0.0325, sd 0.03412 (sum of squared deviations
    # 0.0165 - 8 * 0.0325**2 = 0.00815), se 0.01206: beyond one SE, within one SD: the best
    mid = _run_trial(_shaped("channel_h", "linear", 1e-4, 0.3, n=1), [5.9, 6, 4.5, 5, 5.2, 5.6, 5.3, 5.1], cur)
    gap, se = acc.one_se_gap_per_run(mid, odd)
    assert gap == pytest.approx(0.0325, rel=1e-12) and se == pytest.approx(np.sqrt(0.00815 / 7 / 8), rel=1e-12)
    assert se < gap <= se * np.sqrt(8)
    assert [t is odd for t in sel.simplest_within_one_se([mid, odd])] == [True]
    # delta = [0.03, 0.01, 0.03, 0, 0.02, 0.01, 0.02, 0.02]: gap 0.0175, paired se 0.00366 (sum of squared
    # deviations 0.0032 - 8 * 0.0175**2 = 0.00075): the best. Unpaired, the spread of each model's own per-run
    # SSEs (the best's sd 0.0598 / sqrt(8) alone is 0.0211) would hide the gap
    near = _run_trial(_shaped("channel_h", "linear", 1e-4, 0.3, n=1), [5.3, 6.1, 4.3, 5, 4.7, 5.6, 5.2, 5.2], cur)
    gap, se = acc.one_se_gap_per_run(near, odd)
    assert gap == pytest.approx(0.0175, rel=1e-12) and se == pytest.approx(np.sqrt(0.00075 / 7 / 8), rel=1e-12)
    assert np.std(np.array(B) / 10, ddof=1) / np.sqrt(8) > gap > se
    assert [t is odd for t in sel.simplest_within_one_se([near, odd])] == [True]
    # the quadratic shape within one SE (its two parameters as the odd one's, degree 2 < 3) and a linear one beyond:
    # the quadratic is kept; with only the far linear one, the best
    quad = _run_trial(_shaped("channel_h", "quadratic", 1e-4, 0.3), [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5], cur)
    assert [t is quad for t in sel.simplest_within_one_se([odd, mid, quad])] == [True]
    assert [t is odd for t in sel.simplest_within_one_se([odd, mid])] == [True]
    # the same parameters and degree (an interaction counts as its shape): the larger gain
    a = _run_trial(_shaped("channel_h", "linear", 1e-4, 0.3), B, cur)
    b = _run_trial(_shaped("channel_h", "linear", 1e-4, 0.31), [5.1] + B[1:], cur)
    assert [t is a for t in sel.simplest_within_one_se([b, a])] == [True]
    # trials on other folds (another current model's per-run errors): no gap can be computed, the best stays
    lin_else = _run_trial(lin, lin.extended.run_sse.values(), _errors([10, 12, 8, 10, 9, 11, 10, 10.5]))
    assert [t is odd for t in sel.simplest_within_one_se([lin_else, odd])] == [True]
    assert sel.simplest_within_one_se([]) == []
    assert [sel.shape_degree(t.candidate) for t in (lin, quad, odd)] == [1, 2, 3]


def test_pooled_gain_is_the_share_of_the_current_sum_of_squares_removed():
    # reference: 1 - (1 + 3 + 1) / (4 + 4 + 2) = 0.5, for the refit's trials and the linearised score alike
    assert acc.pooled_gain([4.0, 4.0, 2.0], [1.0, 3.0, 1.0]) == pytest.approx(0.5, rel=1e-15)
    assert acc.pooled_gain([0.0, 0.0], [1.0, 1.0]) == 0.0
    t = acc.RefitCV(None, acc.FoldErrors(np.array([4.0, 4.0, 2.0]), np.full(3, 100.0)),
                    acc.FoldErrors(np.array([1.0, 3.0, 1.0]), np.full(3, 100.0)))
    assert t.gain == pytest.approx(0.5, rel=1e-15)
    # the linearised score's gain on two folds of two runs each: the same formula over runs
    rng = np.random.default_rng(0)
    y, S = rng.normal(size=40), rng.normal(size=40)
    y += 0.8 * S
    runs = np.repeat([0, 1, 2, 3], 10)
    solver = sel.FoldSolver(y, np.zeros((40, 0)), runs, [np.array([0, 2]), np.array([1, 3])])
    gain, per_run = solver.gain(S)
    s0 = np.array([solver.sse0[r] for r in solver.keys])
    assert gain == pytest.approx(1 - (s0 - per_run * s0.mean()).sum() / s0.sum(), rel=1e-12)


def test_run_evidence_pairs_the_gain_per_held_out_run():
    # reference, by hand: current per-run SSE [10, 12, 8, 10, 9, 11, 10, 10] (mean 10), the refit's
    # [6, 13, 5, 10.5, 7, 12, 8, 9]; per run delta = (current - refit) / 10 = [0.4, -0.1, 0.3, -0.05, 0.2, -0.1, 0.2,
    # 0.1]: mean 0.95 / 8 = 0.11875, which is the pooled gain 1 - 70.5 / 80; sum of squared deviations
    # 0.3625 - 8 * 0.11875**2 = 0.2496875, se = sqrt(0.2496875 / 7) / sqrt(8); 5 of the 8 runs fell (13 > 12,
    # 10.5 > 10 and 12 > 11 rose). Over the four folds of two runs: current [19, 23, 18, 20], refit [13, 25, 13, 19.5]
    cur = _errors([10, 12, 8, 10, 9, 11, 10, 10])
    c = CandidateForce("x", "time", "", ("a",), ("N",), features=None)
    t = acc.RefitCV(c, cur, _errors([6, 13, 5, 10.5, 7, 12, 8, 9]))
    gain, se, improved, n = acc.run_evidence(t)
    assert gain == pytest.approx(0.11875, rel=1e-12) and gain == pytest.approx(t.gain, rel=1e-12)
    assert se == pytest.approx(np.sqrt(0.2496875 / 7) / np.sqrt(8), rel=1e-12)     # 0.0667
    assert (improved, n) == (5, 8) and t.folds_improved == 3
    rec = t.to_dict()
    assert rec["cv_gain_se_runs"] == pytest.approx(se, rel=1e-12) and (rec["runs_improved"], rec["runs"]) == (5, 8)
    # no per-run record, a run missing from the refit, or a run's refit diverged: no evidence (and None in the record)
    assert acc.run_evidence(acc.RefitCV(c, acc.FoldErrors(cur.sse, cur.ss_meas), t.extended)) is None
    part = acc.FoldErrors(t.extended.sse, t.extended.ss_meas, run_sse={k: v for k, v in t.extended.run_sse.items()
                                                                       if k != 3})
    assert acc.run_evidence(acc.RefitCV(c, cur, part)) is None
    assert acc.run_evidence(acc.RefitCV(c, cur, _errors([6, 13, 5, np.inf, 7, 12, 8, 9]))) is None
    assert acc.RefitCV(c, cur, part).to_dict()["runs"] is None


def test_acceptance_of_a_refit_that_improved_two_of_four_folds():
    # reference: a run-level category's refit, measured per fold (held-out free-run SSE of the current model and of
    # the refit, four stratified folds of 14 runs): pooled gain 1 - 0.28679 / 0.32479 = 0.117, but folds 1 and 4
    # rose (0.043046 -> 0.043278, 0.104179 -> 0.121022), so not more than half of the folds fell: refused
    c = CandidateForce("run_level_category(fixture_id)", "fixture_id", "", ("a",), ("N",), features=None)
    ss = np.full(4, 1.0)
    cur = acc.FoldErrors(np.array([0.04304604769860089, 0.07505304486288528, 0.10251306639137184,
                                   0.10417896486205147]), ss)
    ext = acc.FoldErrors(np.array([0.043278106249645114, 0.04531599560021911, 0.07717494875618396,
                                   0.12102173112379866]), ss)
    t = acc.RefitCV(c, cur, ext)
    assert t.gain == pytest.approx(1 - 0.2867907 / 0.3247911, abs=1e-6) and t.folds_improved == 2
    assert not acc.accepts(t, min_gain=acc.DEFAULT_MIN_CV_GAIN, min_drop=0.0)
    # the same refit with its first fold's tie resolved the other way (3 of 4 folds fell): accepted
    tied = acc.RefitCV(c, cur, acc.FoldErrors(np.array([0.043] + ext.sse[1:].tolist()), ss))
    assert tied.folds_improved == 3 and acc.accepts(tied, min_gain=acc.DEFAULT_MIN_CV_GAIN, min_drop=0.0)


def test_the_uncorrected_fallback_judges_a_family_by_its_best_hypothesis_that_passes():
    # reference: at the corrected level a family stands or falls with its best-gain hypothesis (the level is
    # Bonferroni over families); only when no family passes, the fallback at the uncorrected level takes the one
    # best family, judged by its best-gain hypothesis among those that pass
    scores = [_score("ch", 0.019, gain=0.228), _score("ch", 0.007, gain=0.222), _score("b", 0.03, gain=0.21),
              _score("c", 0.004, gain=0.1)]
    assert sel.shortlist(scores, level=0.01, min_gain=0.05, size=2) == [scores[3]]   # ch's best fails: out
    assert sel.shortlist(scores, level=0.01, min_gain=0.05, size=2, within_family=True) == [scores[1], scores[3]]
    assert sel.screened(scores, level=0.001, min_gain=0.05, size=2) == ([], 0.001)   # no fallback set
    assert sel.screened(scores, level=0.001, min_gain=0.05, size=2, fallback_level=0.01) == ([scores[1]], 0.01)
    assert sel.screened(scores, level=0.005, min_gain=0.05, size=2, fallback_level=0.01) == ([scores[3]], 0.005)
    assert sel.screened(scores[:1], level=0.001, min_gain=0.05, size=2, fallback_level=0.01) == ([], 0.01)


def test_a_failing_searched_hypothesis_does_not_judge_its_family():
    # reference: a family stands or falls with its best-gain hypothesis, but a grid point of a searched shape (a
    # channel's peak, p-value times the grid's size) represents its family only when it passes: failing, the family
    # is judged by its best-gain unsearched hypothesis; passing with the best gain, it is the family's pick. An
    # unsearched best-gain hypothesis that fails still sinks its family
    def peak(family, p, gain):
        c = CandidateForce(family, "aux", "", (f"{family}_peak_{gain}",), ("N",), features=None, generic=True,
                           spec={"kind": "channel", "shape": "peak", "grid_points": 27})
        return sel.Score(c, gain, p, 1.0, 0.0, np.zeros(1), -5.0)
    quad = _shaped("channel_h", "quadratic", 1e-4, 0.30)
    failing, passing = peak("channel_h", 0.2, 0.45), peak("channel_h", 1e-5, 0.45)
    other = _shaped("channel_k", "linear", 1e-4, 0.20)
    assert sel.shortlist([failing, quad, other], level=1e-3, min_gain=0.05, size=3) == [quad, other]
    assert sel.shortlist([passing, quad, other], level=1e-3, min_gain=0.05, size=3) == [passing, other]
    assert sel.shortlist([failing, other], level=1e-3, min_gain=0.05, size=3) == [other]
    weak = _shaped("channel_h", "odd", 0.01, 0.40)                 # unsearched, best gain, fails: the family is out
    assert sel.shortlist([weak, quad, failing, other], level=1e-3, min_gain=0.05, size=3) == [other]
    assert sel.shortlist([weak, quad, passing, other], level=1e-3, min_gain=0.05, size=3) == [passing, other]
    # the public rule `choose` counts a grid's choices too: the peak's 1 + 2 parameters against the linear's 1
    lin = _shaped("channel_h", "linear", 1e-5, 0.44, n=1)
    assert sel.most_parsimonious([passing, lin], parsimony=0.9) is lin
    assert sel.most_parsimonious([passing, _shaped("channel_h", "odd", 1e-5, 0.44, n=4)], parsimony=0.9) is passing


def test_significance_is_bonferroni_over_the_families_tested():
    scores = [_score("a", 0.001), _score("a", 0.2), _score("b", 0.004), _score("c", 0.5), _score("d", 0.02)]
    level = sel.significance_level(scores, alpha=0.02)
    assert level == pytest.approx(0.02 / 4)                    # four families, not five candidates, not one
    short = sel.shortlist(scores, level=level, min_gain=0.05, size=5)
    assert [s.candidate.family for s in short] == ["a", "b"]   # p 0.02 < alpha but > alpha/4: out
    assert [s.candidate.family for s in sel.shortlist(scores, level=0.02, min_gain=0.05, size=5)] == ["a", "b"]
    assert not sel.shortlist([_score("a", 0.001, aic=1.0)], level=level, min_gain=0.05, size=5)  # AIC must improve
    assert not sel.shortlist([_score("a", 0.001, gain=0.04)], level=level, min_gain=0.05, size=5)
    choice = sel.choose(scores, alpha=0.02, min_gain=0.2)
    assert choice.level == pytest.approx(0.005) and {s.candidate.family for s in choice.significant} == {"a", "b"}


def test_trace_corrects_for_the_regressors_tested(monkeypatch):
    # residuals.trace: a regressor enters only below alpha / number of regressors tested
    ev = [res.Evidence("time", 0.5, 0.004, 1.0, 20), res.Evidence("load", 0.4, 0.0005, 1.0, 20)]
    ev += [res.Evidence(f"r{i}", 0.0, 1.0, 0.0, 20) for i in range(6)]
    calls = []

    def fake(r, df, mask, *, k, seed, given=(), regressors=None):
        calls.append(given)
        return [e for e in ev if e.regressor not in given]
    monkeypatch.setattr(res, "regressor_evidence", fake)
    chosen, _ = res.trace(None, None, None, alpha=0.01)
    assert chosen == ["load"]            # time's p 0.004 < 0.01 but > 0.01/8 (then 0.01/7): not traced


# ---------------------------------------------------------------------------
# every effect's features, written out
# ---------------------------------------------------------------------------

def _x(n=40, seed=1):
    rng = np.random.default_rng(seed)
    return {"t": np.linspace(0, 300, n), "s": rng.uniform(-0.012, 0.012, n), "V0": rng.uniform(220, 324, n),
            "load": rng.uniform(-0.09, 0.09, n), "d": rng.choice([-1.0, 1.0], n), "T": rng.uniform(25, 40, n),
            "v_base": rng.uniform(-0.3, 0.3, n), "a_base": rng.normal(0, 1, n)}


def test_speed_dependent_friction_opposes_the_motion():
    x = _x()
    x["v_base"] = x["d"] * np.abs(x["v_base"])            # moving the way it is driven (data sign = d)
    F = fx.effect_features({"kind": "speed_dependent_friction"}, x)
    vp = np.abs(x["v_base"])
    np.testing.assert_allclose(F, np.column_stack([-vp / 0.2, -vp ** 2 / 0.04]))
    assert np.all(F <= 0)                                  # positive coefficients: a drag, whatever the direction
    x["v_base"] = -x["v_base"]                             # moving against the drive: the drag changes sign
    np.testing.assert_allclose(fx.effect_features({"kind": "speed_dependent_friction"}, x),
                               np.column_stack([vp / 0.2, vp ** 2 / 0.04]))


def test_named_effects_features_against_their_formulas():
    x = _x()
    d, V0, m, s, v, a = x["d"], x["V0"], x["load"], x["s"], x["v_base"], x["a_base"]
    g = V0 / 300.0

    def F(spec):
        return fx.effect_features(spec, x)
    np.testing.assert_allclose(F({"kind": "load_path_friction"}), (-G * np.abs(m))[:, None])
    np.testing.assert_allclose(F({"kind": "direction_asymmetry"}), np.column_stack([d * g, d]))
    np.testing.assert_allclose(F({"kind": "drive_saturation"}), np.column_stack([g ** 2, g ** 3]))
    np.testing.assert_allclose(F({"kind": "inertia_mismatch", "m_s": 0.12}), (-0.12 * d * a)[:, None])
    np.testing.assert_allclose(F({"kind": "thermal_drift_T", "T_ref": 30.0}),
                               np.column_stack([g * (x["T"] - 30), g * (x["T"] - 30) ** 2 / 10]))
    np.testing.assert_allclose(F({"kind": "load_slope_voltage", "V_ref": 270.0}),
                               (-d * m * G * (V0 - 270.0) / 300.0)[:, None])
    np.testing.assert_allclose(F({"kind": "damping_voltage", "V_ref": 270.0}),
                               (-d * v / 0.2 * (V0 - 270.0) / 300.0)[:, None])
    xp = 2 * np.clip((s + 0.012) / 0.024, 0, 1) - 1
    np.testing.assert_allclose(F({"kind": "position_load", "s_lo": -0.012, "s_hi": 0.012}),
                               np.column_stack([-d * m * G * xp, -d * m * G * xp ** 2]))
    np.testing.assert_allclose(F({"kind": "local_defect", "center_m": 0.002, "width_m": 0.001}),
                               np.exp(-0.5 * ((s - 0.002) / 0.001) ** 2)[:, None])
    ph = 2 * np.pi * s / 0.004
    u = d * v / 0.2
    np.testing.assert_allclose(F({"kind": "bar_waviness", "period_m": 0.004}), np.column_stack(
        [np.cos(ph), np.sin(ph), g * np.cos(ph), g * np.sin(ph), u * np.cos(ph), u * np.sin(ph),
         np.cos(2 * ph), np.sin(2 * ph)]))
    # spline families: a partition of unity times their factor (B-splines sum to 1 on the range)
    th = F({"kind": "thermal_drift", "t_lo": 0.0, "t_hi": 300.0, "n_inner": 2})
    assert th.shape[1] == 6
    np.testing.assert_allclose(th.sum(axis=1), g)


def test_generic_terms_against_their_formulas():
    x = _x()
    d, m, V0 = x["d"], x["load"], x["V0"]
    rng = {"t_lo": 0.0, "t_hi": 300.0, "s_lo": -0.012, "s_hi": 0.012, "V_lo": 220.0, "V_hi": 324.0,
           "load_abs": 0.09, "v_lo": 0.0, "v_hi": 0.3, "m_s": 0.12, "n_inner": 8}
    load = fx.effect_features({"kind": "smooth", "regressor": "load", **rng}, x)
    np.testing.assert_allclose(load, np.column_stack([d * m / 0.09, np.abs(m) / 0.09, (d * m / 0.09) ** 2]))
    u = 2 * (V0 - 220.0) / 104.0 - 1
    np.testing.assert_allclose(fx.effect_features({"kind": "smooth", "regressor": "voltage", **rng}, x),
                               np.column_stack([u, u ** 2]))
    acc_ = fx.effect_features({"kind": "smooth", "regressor": "acceleration", **rng}, x)
    np.testing.assert_allclose(acc_, np.column_stack([0.12 * d * x["a_base"], np.abs(0.12 * d * x["a_base"])]))
    pair = fx.effect_features({"kind": "smooth_pair", "a": "direction", "b": "voltage", **rng}, x)
    np.testing.assert_allclose(pair, np.column_stack([d * u, d * u ** 2]))
    np.testing.assert_allclose(fx.effect_features({"kind": "smooth", "regressor": "time", **rng}, x).sum(axis=1), 1.0)


# ---------------------------------------------------------------------------
# repeated cross-validation of the refit's acceptance
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("k,repeats", [(2, 1), (4, 1), (4, 2), (5, 3)])
def test_repeated_folds_hold_out_every_run_exactly_repeats_times(k, repeats):
    # reference: split j (of R) is stratified_folds(df, k, seed) for j = 0 and stratified_folds(df, k, [seed, j])
    # after it; each split is a partition of the runs, so every run is held out exactly R times; R = 1 is
    # stratified_folds itself; the list is a function of the seed
    df = _runs_frame()
    runs = sorted(pd.unique(df["run"]).tolist())
    folds = fo.repeated_folds(df, k, repeats, seed=7)
    assert len(folds) == k * repeats
    for j in range(repeats):
        split = folds[j * k:(j + 1) * k]
        assert sorted(np.concatenate(split).tolist()) == runs                       # one partition per split
        ref = fo.stratified_folds(df, k, seed=7 if j == 0 else [7, j])
        assert [f.tolist() for f in split] == [f.tolist() for f in ref]
    held, counts = np.unique(np.concatenate(folds), return_counts=True)
    assert held.tolist() == runs and set(counts.tolist()) == {repeats}
    assert fo.held_out_times(folds) == repeats
    assert [f.tolist() for f in fo.repeated_folds(df, k, repeats, seed=7)] == [f.tolist() for f in folds]
    if repeats > 1:
        assert [f.tolist() for f in folds[:k]] != [f.tolist() for f in folds[k:2 * k]]   # another shuffle
    with pytest.raises(ValueError):
        fo.held_out_times(folds + [folds[0]])         # the first fold's runs held out once more than the others


#: four runs in two splits of two folds; per split, each model's held-out SSE of every run (written out)
SPLITS = {"A": [[0, 1], [2, 3]], "B": [[0, 2], [1, 3]]}
RUN_SSE = {"current": {"A": {0: 10, 1: 12, 2: 8, 3: 10}, "B": {0: 12, 1: 10, 2: 8, 3: 14}},
           "refit": {"A": {0: 6, 1: 13, 2: 5, 3: 11}, "B": {0: 8, 1: 9, 2: 7, 3: 14}},
           "other": {"A": {0: 5, 1: 12, 2: 5, 3: 10}, "B": {0: 7, 1: 10, 2: 6, 3: 13}},
           "split_a_only": {"A": {0: 6, 1: 12, 2: 5, 3: 10}, "B": {0: 13, 1: 10, 2: 8, 3: 14}}}


def _repeated_errors(monkeypatch, splits):
    """``cv_errors`` of the four models of :data:`RUN_SSE` on the folds of ``splits`` (a fold's refit replaced by
    the written-out per-run SSEs; 100 for the measured speed's sum of squares of every fold)."""
    def fake(df, mask, m_s, held, init, effects, settings):
        name = next(s for s in splits if any(sorted(held) == f for f in SPLITS[s]))
        per_run = {r: float(RUN_SSE[effects][name][r]) for r in held}
        return sum(per_run.values()), 100.0, False, 1, per_run
    monkeypatch.setattr(acc, "fold_error", fake)
    folds = [np.array(f) for s in splits for f in SPLITS[s]]
    return dict(zip(RUN_SSE, acc.cv_errors(None, None, 1.0, folds, None, [(m, None) for m in RUN_SSE],
                                           acc.RefitSettings())))


def test_repeated_cv_pools_the_gain_the_majority_and_each_runs_error_over_the_splits(monkeypatch):
    # reference, by hand: folds A[0,1], A[2,3], B[0,2], B[1,3]. Current fold SSEs [22, 18, 20, 24] (sum 84), the
    # refit's [19, 16, 15, 23] (sum 73): pooled gain 1 - 73 / 84, 4 of 4 folds fell. Per run, the mean over its two
    # held-out predictions: current [11, 11, 8, 12] (sum 42 = 84 / 2, mean 10.5), refit [7, 11, 6, 12.5];
    # delta = (current - refit) / 10.5 = [4, 0, 2, -0.5] / 10.5: mean 5.5 / 42 = 0.130952 (= 1 - 36.5 / 42, the
    # pooled gain again); [4, 0, 2, -0.5] has mean 1.375 and sum of squared deviations 20.25 - 4 * 1.375**2 =
    # 12.6875, so se = sqrt(12.6875 / 3) / 10.5 / sqrt(4); 2 of the 4 runs fell (0 and 2)
    e = _repeated_errors(monkeypatch, "AB")
    cur, ext = e["current"], e["refit"]
    assert cur.repeats == 2 and cur.sse.tolist() == [22, 18, 20, 24] and ext.sse.tolist() == [19, 16, 15, 23]
    assert cur.run_sse == {0: 11, 1: 11, 2: 8, 3: 12} and ext.run_sse == {0: 7, 1: 11, 2: 6, 3: 12.5}
    t = acc.RefitCV(None, cur, ext)
    assert t.gain == pytest.approx(1 - 73 / 84, rel=1e-12) and t.folds_improved == 4
    assert cur.nrmse == pytest.approx(np.sqrt(84 / 400), rel=1e-12)
    gain, se, improved, n = acc.run_evidence(t)
    assert gain == pytest.approx(5.5 / 42, rel=1e-12) and gain == pytest.approx(t.gain, rel=1e-12)
    assert se == pytest.approx(np.sqrt(12.6875 / 3) / 10.5 / 2, rel=1e-12) and (improved, n) == (2, 4)
    # the one-standard-error rule paired per run, on the runs' means: other's per-run means [6, 11, 5.5, 11.5];
    # delta = (refit - other) / 10.5 = [1, 0, 0.5, 1] / 10.5: gap 2.5 / 42, sum of squared deviations
    # 2.25 - 4 * 0.625**2 = 0.6875, se = sqrt(0.6875 / 3) / 10.5 / 2
    o = acc.RefitCV(None, cur, e["other"])
    gap, se_r = acc.one_se_gap_per_run(t, o)
    assert gap == pytest.approx(2.5 / 42, rel=1e-12) and gap == pytest.approx(o.gain - t.gain, rel=1e-12)
    assert se_r == pytest.approx(np.sqrt(0.6875 / 3) / 10.5 / 2, rel=1e-12)
    # per fold: the other's fold SSEs [17, 15, 13, 23]; delta = [2, 1, 2, 0] / 21 (mean of current 21): gap 5 / 84,
    # sd of [2, 1, 2, 0] = sqrt(2.75 / 3), over the sqrt of 4 folds / 2 splits = sqrt(2), not sqrt(4)
    fgap, fse = acc.one_se_gap(t, o)
    assert fgap == pytest.approx(5 / 84, rel=1e-12)
    assert fse == pytest.approx(np.sqrt(2.75 / 3) / 21 / np.sqrt(2), rel=1e-12)


def test_the_fold_majority_of_repeated_cv_is_over_every_split_s_folds(monkeypatch):
    # reference: split A alone: fold SSEs current [22, 18], refit [18, 15]: gain 1 - 33 / 40 = 0.175, 2 of 2 folds,
    # accepted. With split B too: current [22, 18, 20, 24], refit [18, 15, 21, 24]: gain 1 - 78 / 84 = 0.0714
    # (above min_gain 0.03) but 2 of the 4 folds fell, not more than half: refused
    one = _repeated_errors(monkeypatch, "A")
    t1 = acc.RefitCV(None, one["current"], one["split_a_only"])
    assert t1.gain == pytest.approx(0.175, rel=1e-12) and t1.folds_improved == 2
    assert acc.accepts(t1, min_gain=0.03, min_drop=0.0)
    two = _repeated_errors(monkeypatch, "AB")
    t2 = acc.RefitCV(None, two["current"], two["split_a_only"])
    assert t2.gain == pytest.approx(1 - 78 / 84, rel=1e-12) and t2.folds_improved == 2
    assert not acc.accepts(t2, min_gain=0.03, min_drop=0.0)


def test_one_split_is_todays_rule_exactly(monkeypatch):
    # reference: with one split every run is held out once: its SSE is the fold's own number (no mean taken), the
    # errors' repeats is 1 and the fold-level standard error is sd over the k folds / sqrt(k), as before repeats
    e = _repeated_errors(monkeypatch, "A")
    cur, ext, oth = e["current"], e["refit"], e["other"]
    assert cur.repeats == 1 and cur.run_sse == RUN_SSE["current"]["A"] and ext.run_sse == RUN_SSE["refit"]["A"]
    assert all(type(x) is float for x in ext.run_sse.values())
    t, o = acc.RefitCV(None, cur, ext), acc.RefitCV(None, cur, oth)
    # fold SSEs: current [22, 18], refit [19, 16], other [17, 15]; delta = [2, 1] / 20: gap 0.075, sd sqrt(0.5) / 20
    assert acc.one_se_gap(t, o) == pytest.approx((0.075, np.sqrt(0.5) / 20 / np.sqrt(2)), rel=1e-12)
    assert acc.paired_gap([19, 16], [17, 15], [22, 18]) == acc.paired_gap([19, 16], [17, 15], [22, 18], repeats=1)
    df = _runs_frame()
    assert [f.tolist() for f in fo.repeated_folds(df, 4, 1, seed=3)] == [
        f.tolist() for f in fo.stratified_folds(df, 4, seed=3)]
    assert acc.mean_per_run([{0: 0.1, 1: 0.7}, {2: 0.3}]) == {0: 0.1, 1: 0.7, 2: 0.3}


def test_the_loops_refit_folds_are_repeated_only_for_the_stratified_scheme():
    # reference: the loop's refit folds for refit_repeats = R are repeated_folds(df, k, R, seed) for a candidate
    # that does not read the session clock and the k session blocks (one split) for one that does; the setting is
    # a constructor argument of the loop (get_params / set_params)
    from l1b2.closeloop.loop import CloseLoop
    df = _runs_frame()
    s = fo.refit_schemes(df, 4, 3, seed=5)
    assert [f.tolist() for f in s[False]] == [f.tolist() for f in fo.repeated_folds(df, 4, 3, seed=5)]
    assert [f.tolist() for f in s[True]] == [f.tolist() for f in fo.session_blocks(df, 4)]
    assert fo.held_out_times(s[False]) == 3 and fo.held_out_times(s[True]) == 1
    loop = CloseLoop(refit_repeats=3)
    assert loop.get_params()["refit_repeats"] == 3 and CloseLoop().refit_repeats == acc.DEFAULT_REFIT_REPEATS == 1
    assert loop.set_params(refit_repeats=2).refit_repeats == 2


def _reader(family, regressor, run_sse, cur, n=1, also=()):
    """A refit trial of a candidate of ``family`` reading ``regressor`` (and ``also``), per-run SSEs ``run_sse``."""
    c = CandidateForce(family, regressor, "", tuple(f"{family}_{i}" for i in range(n)), ("N",) * n, None,
                       also=tuple(also))
    return acc.RefitCV(c, cur, _errors(run_sse))


def test_reads_auxiliary_names_every_regressor_beyond_the_inputs_and_the_clock():
    cur = _errors([10] * 8)
    for reg in ("position", "direction", "load", "voltage", "speed", "acceleration", "temperature", "frequency",
                "time"):
        assert not acc.reads_auxiliary(_reader("f", reg, [5] * 8, cur).candidate)
    for reg in ("tray_mass_g", "voltage_V_lag10r", "prev_run_load_kg", "ln_sense_shunt_ohm", "time_in_run_s"):
        assert acc.reads_auxiliary(_reader("f", reg, [5] * 8, cur).candidate)
    assert acc.reads_auxiliary(_reader("f", "load", [5] * 8, cur, also=("tray_mass_g",)).candidate)


def test_the_inputs_replace_an_auxiliary_pick_within_one_standard_error_that_they_mostly_explain():
    # reference written out: current per-run SSE mean 10; the channel's [5, 6, 4, 5, 4.5, 5.5, 5, 5] (gain 0.5),
    # the load's [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5]: delta = (load - channel) / 10 has mean 0.03125 and se 0.05256
    # (the per-run test above): within one SE
    cur = _errors([10, 12, 8, 10, 9, 11, 10, 10])
    chan = _reader("channel_tray", "tray_mass_g", [5, 6, 4, 5, 4.5, 5.5, 5, 5], cur)
    load = _reader("load_path_friction", "load", [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5], cur)
    explains = {"load_path_friction": 0.8, "run_level_load": 0.8, "channel_other": 0.9, "time_drift": 0.9}
    share = lambda n, g: explains[n.candidate.family]   # noqa: E731
    log = []
    assert acc.input_reading(chan, [chan, load], share, log=log, round_no=2) is load
    assert log == [{"round": 2, "pick": "channel_tray", "taken": "load_path_friction",
                    "gap": pytest.approx(0.03125, rel=1e-12), "se": pytest.approx(0.05256, rel=1e-3),
                    "share": 0.8}]
    # the inputs explain too little of the channel's force (below NAMED_SHARE = 0.5): the channel stays
    assert acc.input_reading(chan, [chan, load], lambda n, g: 0.49) is chan
    assert acc.input_reading(chan, [chan, load], lambda n, g: 0.5) is load
    # beyond one SE (the `mid` trial above: gap 0.0325, se 0.01206): the channel stays
    mid = _reader("run_level_load", "load", [5.9, 6, 4.5, 5, 5.2, 5.6, 5.3, 5.1], cur)
    assert acc.input_reading(chan, [chan, mid], share) is chan
    # a pick of the inputs, another auxiliary channel, or the clock is never an alternative; an input pick stays
    other = _reader("channel_other", "aux7", [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5], cur)
    clock = _reader("time_drift", "time", [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5], cur)
    assert acc.input_reading(chan, [chan, other, clock], share) is chan
    assert acc.input_reading(load, [chan, load], share) is load
    # an interaction of the channel with the load reads the channel: replaced as well
    inter = _reader("channel_tray", "tray_mass_g", [5, 6, 4, 5, 4.5, 5.5, 5, 5], cur, also=("load",))
    assert acc.input_reading(inter, [inter, load], share) is load
    # not cross-validated against the same current model's runs: no paired gap, the channel stays
    other_cur = _reader("load_path_friction", "load", [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5],
                        _errors([10, 12, 8, 10, 9, 11, 10, 10.5]))
    assert acc.input_reading(chan, [chan, other_cur], share) is chan
    # of two such input trials the larger gain, then the fewer parameters
    # gain 0.47625 against the load's 0.46875; delta from the channel's mean 0.02375, se 0.0290: within one SE
    near = _reader("run_level_load", "load", [6.5, 5.8, 5, 4.5, 3.8, 6, 4.5, 5.8], cur)
    assert acc.input_reading(chan, [chan, load, near], share) is near
    twin = _reader("run_level_load", "load", [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5], cur, n=3)
    assert acc.input_reading(chan, [chan, twin, load], share) is load


def test_the_loop_reads_an_auxiliary_pick_as_the_inputs_it_stands_for(monkeypatch):
    """``_iterate``'s choice of the round's pick applies :func:`input_reading` after ``prefer`` and
    ``named_reading``, with the round's geometry, and logs the replacement in ``it.readings``."""
    import types
    from l1b2.closeloop import loop as loop_mod
    from l1b2.closeloop.loop import CloseLoop
    cur = _errors([10, 12, 8, 10, 9, 11, 10, 10])
    chan = _reader("channel_tray", "tray_mass_g", [5, 6, 4, 5, 4.5, 5.5, 5, 5], cur)
    load = _reader("load_path_friction", "load", [7.5, 5.5, 5.5, 4, 3, 6.5, 4, 6.5], cur)
    chosen = {}

    class Stop(Exception):
        pass

    class Geo:
        def __init__(self, *a):
            pass

        def of_trials(self, named, generic):
            return 0.8 if (named.candidate.family, generic.candidate.family) == ("load_path_friction",
                                                                                 "channel_tray") else 0.0

    def identified_pick(it, ok, choose, *a):
        chosen["pick"] = choose(ok)
        raise Stop
    for name, fake in (("refit_schemes", lambda *a: {False: [], True: []}), ("screen_folds", lambda *a: ([], [])),
                       ("Directions", Geo), ("nuisance_forces", lambda *a: None),
                       ("score_candidates", lambda *a, **k: []), ("significance_level", lambda *a: 0.01),
                       ("screened", lambda *a, **k: ([object()], 0.01)),
                       ("refit_list", lambda short, *a, **k: list(short)),
                       ("accepts", lambda *a, **k: True), ("simplest_within_one_se", lambda t: list(t)),
                       ("screen_mask", lambda d, m: m)):
        monkeypatch.setattr(loop_mod, name, fake)
    monkeypatch.setattr(loop_mod.res, "drive_residual", lambda d, v: np.zeros(len(d)))
    est = CloseLoop(run_level=False)
    monkeypatch.setattr(est, "_trials", lambda *a: [chan, load])
    monkeypatch.setattr(est, "_identified_pick", identified_pick)
    model = types.SimpleNamespace(predict_free_run=lambda d: np.zeros(len(d)), params_=None)
    it = loop_mod._Iteration(model=model, effects=acc.EffectSet(), rounds=[{}])
    with pytest.raises(Stop):
        est._iterate(it, [], pd.DataFrame({"run": [0, 1]}), np.ones(2, bool), 0.1, None, lambda *a: None)
    assert chosen["pick"] is load                  # prefer's pick (the channel: the larger gain) read as the load's
    assert [(r["round"], r["pick"], r["taken"]) for r in it.readings] == [(1, "channel_tray", "load_path_friction")]


def test_the_report_names_each_channel_read_as_the_inputs_and_an_older_report_still_loads():
    from l1b2.closeloop.report import Diagnosis
    from l1b2.closeloop.result import markdown_report
    from test_report_values import minimal_report
    rec = {"round": 2, "pick": "channel_tray_mass_g[force_factor, run]", "taken": "load_path_friction",
           "gap": 0.04528, "se": 0.07304, "share": 0.8534}
    rep = minimal_report()
    rep["diagnosis"] = {**rep["diagnosis"], "input_readings": [rec]}
    want = ("* round 2: `channel_tray_mass_g[force_factor, run]` reads a channel that the model's inputs stand for: "
            "`load_path_friction` taken instead (its CV gain 0.045 lower, within one SE 0.073; it explains 85% of "
            "the channel's force)")
    assert want in markdown_report(rep).splitlines()
    assert "stand for" not in markdown_report(minimal_report())
    # the inputs' trial may have the larger gain (the pick came first by another rule of the choice)
    rep["diagnosis"]["input_readings"] = [{**rec, "gap": -0.0362}]
    assert any("(its CV gain 0.036 higher, within one SE 0.073;" in x for x in markdown_report(rep).splitlines())
    old = {"significant": False, "traced_to": [], "effect": None, "effect_shape": None,
           "effect_description": None, "effects": [], "message": "no significant missing effect"}
    assert Diagnosis.from_dict(old).input_readings == []
    d = Diagnosis.from_dict({**old, "input_readings": [rec]})
    assert Diagnosis.from_dict(d.to_dict()) == d
