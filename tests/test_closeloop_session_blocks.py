"""Contiguous blocks of the session (issue 28, items 3 and 7): the family ``session_blocks`` and the run-level
analysis's segmentation search (l1b2.closeloop.blocks, l1b2.closeloop.runlevel.block_signal).

Fast unit tests (seconds), each against a formula or an enumeration written out here: the block of a session time
at and around the edges, the centred indicators, the family's force ``x_j V0/V_ref``, a block's weighted scatter
about its generalised least-squares mean, every cost of the dynamic programme, the optimal cuts against every cut
enumerated, the search count against counted cuts, the edges midway, the search correction of the p-value, and the
search on made deviations: blocks found where they were made, nothing significant where none were.
"""

import itertools
from math import comb

import numpy as np
import pytest
from l1b2.closeloop import blocks as blk
from l1b2.closeloop import runlevel as rl
from l1b2.closeloop import runstats as rs
from l1b2.closeloop.acceptance import time_dependent
from l1b2.closeloop.candidates import CandidateForce
from l1b2.predictor import effects as fx
from l1b2.predictor.effects import blocks as fb
from l1b2.predictor.effects.base import V_REF
from l1b2.predictor.effects.channels import export_problem
from l1b2.closeloop.reml import reml


def test_a_run_is_in_the_block_of_the_edges_at_or_below_its_session_time():
    edges = (10.0, 20.0, 35.0)
    t = np.array([0.0, 9.99, 10.0, 19.0, 20.0, 34.0, 35.0, 99.0])
    np.testing.assert_array_equal(fb.block_index(t, edges), [0, 0, 1, 1, 2, 2, 3, 3])


def test_the_block_columns_are_centred_indicators_without_the_last_block():
    shares = (0.25, 0.5)
    idx = np.array([0, 1, 2, 1])
    want = np.array([[1 - 0.25, -0.5], [-0.25, 1 - 0.5], [-0.25, -0.5], [-0.25, 1 - 0.5]])
    np.testing.assert_allclose(fb.index_columns(idx, shares), want)
    np.testing.assert_allclose(fb.block_columns([1.0, 15.0, 50.0, 12.0], (10.0, 20.0), shares), want)


def test_the_family_scales_the_drive_force_per_block_and_reads_the_session_clock():
    h = fx.family("session_blocks").hypotheses([{"edges": (10.0, 20.0), "shares": (0.25, 0.5)}])[0]
    assert h.family == "session_blocks(3)" and h.regressor == "session_block" and h.generic
    assert h.names == ("block_0_run_gain", "block_1_run_gain") and h.units == ("N", "N")
    V0 = np.array([220.0, 324.0, 290.0, 255.0])
    x = {"V0": V0, "d": np.array([1.0, -1.0, 1.0, -1.0]), "run:time_s": np.array([1.0, 15.0, 50.0, 12.0])}
    F = fx.effect_features(h.spec, x)
    ind = np.array([[0.75, -0.5], [-0.25, 0.5], [-0.25, -0.5], [-0.25, 0.5]])
    np.testing.assert_allclose(F, ind * (V0 / V_REF)[:, None])
    assert fx.family("session_blocks").width(h.spec) == 2
    assert export_problem(h.spec) == "the family 'session_blocks' is not exportable"   # no session clock input
    c = CandidateForce("session_blocks(3)[run]", "session_block", "run", h.names, h.units, features=None,
                       spec=h.spec)
    assert not time_dependent(c)     # cross-validated over runs: a block's level from the runs within it
    with pytest.raises(fx.EffectSpecError, match="increasing edges"):
        fb.blocks_spec((20.0, 10.0), (0.5, 0.25))


def _made(n, seed=0):
    rng = np.random.default_rng(seed)
    theta = rng.normal(size=(n, 2))
    A = rng.normal(size=(n, 2, 2))
    return theta, np.einsum("rij,rkj->rik", A, A) + 0.5 * np.eye(2)


def test_a_blocks_scatter_is_about_its_generalised_least_squares_mean():
    theta, W = _made(5)
    m = np.linalg.solve(W.sum(axis=0), sum(W[r] @ theta[r] for r in range(5)))
    want = sum((theta[r] - m) @ W[r] @ (theta[r] - m) for r in range(5))
    assert blk.segment_cost(theta, W) == pytest.approx(want, rel=1e-12)
    # the mean is the minimiser: any other centre scatters more
    assert blk.segment_cost(theta, W) < sum((theta[r] - m - 0.01) @ W[r] @ (theta[r] - m - 0.01) for r in range(5))


def test_every_cost_of_the_programme_is_the_blocks_scatter_and_short_blocks_are_barred():
    theta, W = _made(9, seed=1)
    C = blk.cost_matrix(theta, W, min_runs=3)
    for a in range(10):
        for b in range(10):
            if b - a >= 3:
                assert C[a, b] == pytest.approx(blk.segment_cost(theta[a:b], W[a:b]), rel=1e-9, abs=1e-12)
            else:
                assert np.isinf(C[a, b])


def _total(theta, W, starts, n):
    return sum(blk.segment_cost(theta[a:b], W[a:b]) for a, b in zip((0,) + starts, starts + (n,)))


def test_the_cuts_are_the_least_scatter_of_every_cut_enumerated():
    n, m = 15, 3
    theta, W = _made(n, seed=2)
    segs = blk.optimal_segmentations(theta, W, max_blocks=5, min_runs=m)
    assert [len(s) + 1 for s in segs] == [2, 3, 4, 5]
    for starts in segs:
        cuts = [c for c in itertools.combinations(range(1, n), len(starts))
                if all(b - a >= m for a, b in zip((0,) + c, c + (n,)))]
        best = min(_total(theta, W, c, n) for c in cuts)
        assert _total(theta, W, starts, n) == pytest.approx(best, rel=1e-10)
        assert all(b - a >= m for a, b in zip((0,) + starts, starts + (n,)))


def test_the_search_count_is_the_number_of_cuts_into_blocks_of_the_fewest_runs():
    for n, B, m in ((12, 3, 3), (15, 4, 2), (10, 2, 1), (9, 3, 3), (8, 3, 3)):
        counted = sum(1 for c in itertools.combinations(range(1, n), B - 1)
                      if all(b - a >= m for a, b in zip((0,) + c, c + (n,))))
        assert blk.search_count(n, B, m) == counted
    assert blk.search_count(56, 4, 1) == comb(55, 3)


def test_the_edges_lie_midway_between_the_last_run_of_a_block_and_the_first_of_the_next():
    assert blk.edges_of([1.0, 3.0, 7.0, 8.0, 20.0], (2, 4)) == (5.0, 14.0)


def _deviations(levels_by_run, seed, sd_between=0.01, se=0.004):
    """Made run deviations: each run's gain its block's level plus a between-run scatter and sampling noise."""
    rng = np.random.default_rng(seed)
    n = len(levels_by_run)
    theta = np.column_stack([levels_by_run + rng.normal(0, sd_between, n) + rng.normal(0, se, n),
                             rng.normal(0, 0.05, n)])
    cov = np.broadcast_to(np.diag([se ** 2, 0.05 ** 2]), (n, 2, 2)).copy()
    return rl.RunDeviations(np.arange(n), theta, cov, np.full(n, 200), None)


def test_the_search_finds_made_blocks_and_corrects_its_p_value():
    n = 48
    level = np.repeat([0.0, 0.06, -0.04, 0.03], 12)
    dev = _deviations(level, seed=3)
    t = np.arange(n) * 5.0 + 1.0
    sg = rl.block_signal(dev, t, reml(dev.theta, dev.cov).T, level=0.001, k=4, seed=0)
    # the made edges, midway between runs 11 and 12, 23 and 24, 35 and 36, are all found (the runs' own scatter
    # may cut a block once more)
    assert {58.5, 118.5, 178.5} <= set(sg["edges"]) and len(sg["edges"]) <= 4
    p_raw = rs.joint_test(dev, fb.index_columns(sg["values"], sg["shares"]), gain_only=True)[1]
    assert sg["search_count"] == blk.search_count(n, len(sg["edges"]) + 1) * (blk.MAX_BLOCKS - 1)
    ev = rl.signal_evidence(dev, [sg], alpha=0.01, k=4, seed=0)[0]
    assert ev.p_value == pytest.approx(min(1.0, p_raw * sg["search_count"]), rel=1e-9, abs=0)
    assert sg["p_value"] == pytest.approx(ev.p_value, rel=1e-9, abs=0)   # the search's p is the evidence's
    cols = fb.index_columns(sg["values"], sg["shares"])
    assert ev.cv_gain == pytest.approx(rs.cv_signal_gain(dev.theta, dev.cov, cols, sg["folds"], dev.load,
                                                         gain_only=True)[0], rel=1e-9)
    assert ev.significant and ev.edges == sg["edges"] and ev.label == f"session_blocks({len(sg['edges']) + 1})"
    assert ev.regressor == "session_block" and not ev.blocked_folds


def test_a_segmentations_evidence_is_one_level_per_block_on_the_gain():
    # the family fits one drive-force level per block (no offset, no load term), so the search's Wald test and
    # cross-validated gain read the gain row only: written out here with the REML mean's design and the folds
    from scipy import stats
    n = 36
    dev = _deviations(np.repeat([0.0, 0.05, -0.03], 12), seed=4)
    Z = fb.index_columns(np.repeat([0.0, 1.0, 2.0], 12), (1 / 3, 1 / 3))          # (n, 2) centred indicators
    one, zero = np.ones((n, 1)), np.zeros((n, 1))
    X = np.stack([np.hstack([one, Z, zero]), np.hstack([zero, 0 * Z, one])], axis=1)   # gain [1 Z 0], offset [0 0 1]
    assert rs.signal_design(Z, None, gain_only=True) == pytest.approx(X, abs=0)
    assert rs.signal_index(2, True, gain_only=True) == [1, 2]
    fit = reml(dev.theta, dev.cov, X)
    b, C = fit.beta[1:3], fit.beta_cov[1:3, 1:3]
    want_p = stats.chi2.sf(float(b @ np.linalg.solve(C, b)), 2)
    got_b, got_p, dof = rs.joint_test(dev, Z, gain_only=True)
    assert dof == 2 and got_b == pytest.approx(b, rel=1e-9) and got_p == pytest.approx(want_p, rel=1e-9, abs=0)
    # the held-out share: for each fold, the null's and the signal's REML fits on the other runs, the held-out
    # runs' squared deviations weighted by the null fit's (T0 + S_r)^-1
    folds = [np.arange(j, n, 4) for j in range(4)]
    s0 = s1 = 0.0
    for te in folds:
        tr = np.setdiff1d(np.arange(n), te)
        f0 = reml(dev.theta[tr], dev.cov[tr])
        f1 = reml(dev.theta[tr], dev.cov[tr], X[tr])
        W = np.linalg.inv(f0.T[None] + dev.cov[te])
        r0 = dev.theta[te] - f0.beta[None, :]
        r1 = dev.theta[te] - np.einsum("rpk,k->rp", X[te], f1.beta)
        s0 += np.einsum("rp,rpq,rq->", r0, W, r0)
        s1 += np.einsum("rp,rpq,rq->", r1, W, r1)
    gain = rs.cv_signal_gain(dev.theta, dev.cov, Z, folds, None, gain_only=True)[0]
    assert gain == pytest.approx(1 - s1 / s0, rel=1e-9) and gain > 0.2
    # the run-level family's design (gain, offset and load slopes per column) gives another gain and test
    assert rs.cv_signal_gain(dev.theta, dev.cov, Z, folds, None)[0] != pytest.approx(gain, rel=1e-3)
    assert rs.joint_test(dev, Z)[2] == 4


def test_the_number_of_blocks_is_the_fewest_within_the_parsimony_of_the_best_gain():
    # written out: every segmentation's corrected p (one level per block on the gain), the gains of those below
    # the level over the run folds, and the fewest blocks whose gain is at least PARSIMONY of the best
    from l1b2.closeloop import residuals as res
    n = 48
    dev = _deviations(np.repeat([0.0, 0.02, -0.015, 0.01, -0.02, 0.015], 8), seed=7, sd_between=0.006)
    t, T = np.arange(n) * 5.0 + 1.0, reml(dev.theta, dev.cov).T
    segs = blk.segmentations(dev.theta, dev.cov, T, t)
    folds = [np.flatnonzero(np.isin(dev.runs, f)) for f in res.run_folds(dev.runs, 4, 0)]
    cols = [fb.index_columns(g["values"], g["shares"]) for g in segs]
    p = [min(1.0, rs.joint_test(dev, z, gain_only=True)[1] * g["search_count"]) for z, g in zip(cols, segs)]
    passed = [i for i in range(len(segs)) if p[i] < 0.001]
    gain = {i: rs.cv_signal_gain(dev.theta, dev.cov, cols[i], folds, None, gain_only=True)[0] for i in passed}
    best = max(gain.values())
    pick = min(i for i in passed if gain[i] >= blk.PARSIMONY * best)
    sg = rl.block_signal(dev, t, T, level=0.001, k=4, seed=0)
    assert len(passed) >= 2 and sg["edges"] == segs[pick]["edges"] and sg["p_value"] == pytest.approx(p[pick])


def test_without_blocks_in_the_session_no_segmentation_is_significant():
    n = 48
    for seed in range(5):
        dev = _deviations(np.zeros(n), seed=10 + seed)
        sg = rl.block_signal(dev, np.arange(n) * 5.0, reml(dev.theta, dev.cov).T, level=0.001, k=4, seed=0)
        ev = rl.signal_evidence(dev, [sg], alpha=0.01, k=4, seed=0)[0]
        assert not ev.significant, (seed, ev.p_value)


def test_a_session_recorded_in_files_with_their_own_drive_tuning_gets_its_blocks_and_exports_their_average(
        load_bench, tmp_path):
    # reference: the sixteenth audit's file blocks (bench/blind_effects_sixteenth.py, seed 2): the realistic world,
    # the drive's frequency re-tuned at each file of 6-12 runs, nothing logged; the loop traces the session's blocks
    # first, lowers TEST's error, and the calibrated model leaves the blocks out and says so
    from l1b2.closeloop.loop import close_loop
    from l1b2.data.measurements import load_measurements
    audit, be = load_bench("blind_effects_sixteenth"), load_bench("blind_effects")
    d = be.data_dir("autotune_file_blocks", 2, tmp_path, make=audit.experiment)
    res = close_loop(load_measurements(d / "train.csv"), load_measurements(d / "test.csv"))
    diag = res.diagnosis
    blocks = [e for e in diag["effects"] if e["effect"].startswith("session_blocks(")]
    assert len(blocks) == 1 and "session_block" in diag["traced_to"][:2], diag["message"]
    assert res.after["test"]["free_run"]["nrmse"] < res.before["test"]["free_run"]["nrmse"]
    ep = res.calibrated_model
    assert [e.label for e in ep.effects] == [e["label"] for e in diag["effects"] if e is not blocks[0]]
    assert res.calibrated_note.endswith(f"left out: {blocks[0]['label']} (a fact of the recorded session, centred "
                                        "on TRAIN's runs: the model predicts the session's average)")
    # one drive-force level per block but the last, each with a standard error
    n = int(blocks[0]["effect"][len("session_blocks("):-1])
    pars = blocks[0]["parameters"]
    assert list(pars) == [f"block_{j}_run_gain" for j in range(n - 1)]
    assert all(p["unit"] == "N" and p["stderr"] is not None and p["stderr"] > 0 for p in pars.values())
    assert diag["test_session"] == {"one_session": True, "session_average": [], "own_clock": []}
    # the same TEST on a clock of its own (each run re-timed one after the other from 0, as a file recorded
    # apart): its runs overlap TRAIN's, so its times say nothing of TRAIN's blocks. The loop scores TEST at TRAIN's
    # session average: the free run of the calibrated model, which leaves the blocks out, a path of its own
    # (Predictor.fmu's form); the report says so
    import dataclasses
    import pandas as pd
    from l1b2.closeloop.calibrated import frame_free_run
    te = load_measurements(d / "test.csv")
    df = te.df.copy()
    first = df.groupby("run", sort=False)["time_s"].transform("min")
    df["time_s"] = df["time_s"] - first + 1.5 * df["run"].map({r: i for i, r in enumerate(pd.unique(df["run"]))})
    apart = close_loop(load_measurements(d / "train.csv"), dataclasses.replace(te, df=df))
    labels = [e["label"] for e in apart.diagnosis["effects"] if e["effect"].startswith("session_blocks(")]
    rec = apart.diagnosis["test_session"]
    assert labels and rec["one_session"] is False and rec["session_average"] == labels
    v_avg = frame_free_run(apart.calibrated_model, apart.test_df)
    np.testing.assert_allclose(apart.test_free_run_after, v_avg, rtol=0, atol=1e-6)
    v_blocks = apart.extended_model.predict_free_run(apart.test_df)     # the blocks read at TEST's own times
    assert np.max(np.abs(v_blocks - v_avg)) > 1e-3
    assert (f"TEST is predicted at TRAIN's session average of `{labels[0]}`, not at the level of the block its times "
            "fall in" in apart.markdown())


def test_the_blocks_are_searched_only_when_no_signal_has_wald_evidence():
    # a signal whose p-value is below the level is evidence even when its folds do not confirm it (the session
    # clock's trend over held-out blocks of the session): blocks, cross-validated over interleaved runs, would fit
    # the same trend in steps, so they are not searched
    from types import SimpleNamespace as E
    level = 0.001
    assert rl.searches_blocks([], level)
    assert rl.searches_blocks([E(p_value=0.002, significant=False), E(p_value=0.5, significant=False)], level)
    assert not rl.searches_blocks([E(p_value=0.002, significant=False), E(p_value=0.0009, significant=False)], level)
    assert not rl.searches_blocks([E(p_value=0.0002, significant=True)], level)
    assert rl.searches_blocks([E(p_value=level, significant=False)], level)      # the level itself: no evidence


def test_the_folds_of_a_block_level_are_the_runs_load_sizes():
    load = np.array([0.0, 1.0, -1.0, 0.5, -0.5 + 1e-12, 0.0, 1.0])
    folds = blk.load_size_folds(load)
    assert [f.tolist() for f in folds] == [[0, 5], [3, 4], [1, 2, 6]]     # |load| 0, 0.5, 1: every run once
    assert blk.load_size_folds(np.array([0.5, -0.5, 0.5])) is None          # one size: no such fold
    assert blk.load_size_folds(None) is None


def _trial(family, gain, n, spec, regressor):
    from l1b2.closeloop import acceptance as acc
    c = CandidateForce(family, regressor, "", tuple(f"p{i}" for i in range(n)), ("N",) * n, None, generic=True,
                       spec=spec)
    return acc.RefitCV(c, acc.FoldErrors(np.ones(4), np.full(4, 100.0)),
                       acc.FoldErrors(np.full(4, 1.0 - gain), np.full(4, 100.0)))


def test_the_blocks_are_added_only_when_no_other_accepted_candidate_is_within_the_parsimony_band():
    from types import SimpleNamespace
    from l1b2.closeloop.loop import prefer
    spec = {"kind": "session_blocks", **fb.blocks_spec((10.0, 20.0), (0.3, 0.4))}
    blocks = _trial("session_blocks(3)", 0.42, 2, spec, "session_block")
    chan = _trial("channel_x", 0.40, 2, {"kind": "channel", "channel": "x", "level": "run"}, "x")
    ev = SimpleNamespace(significant=[SimpleNamespace(regressor="session_block")])
    assert rl.is_last_resort(blocks.candidate) and not rl.is_last_resort(chan.candidate)
    assert prefer([blocks, chan], 0.9, ev) is chan          # named by the run-level evidence, still after the channel
    far = _trial("channel_x", 0.30, 2, {"kind": "channel", "channel": "x", "level": "run"}, "x")
    assert prefer([blocks, far], 0.9, ev) is blocks         # the channel outside the band: the blocks
