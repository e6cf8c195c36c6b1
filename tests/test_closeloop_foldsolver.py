"""The linearised scoring's cross-validated gains: the same numbers whatever arrays hold the folds' rows."""

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import residuals as res
from l1b2.closeloop import selection as sel


def _gains_written_out(solver, S_all, widths):
    """Each fold: training rows and their projection off the nuisance basis as fresh arrays (Frisch-Waugh-Lovell)."""
    bounds = np.cumsum([0] + list(widths))
    sums = [[] for _ in widths]
    for part in solver.parts:
        test, tr, U, W, yp, e0, code, _ = part
        S_tr = S_all[tr]
        C = U.T @ S_tr
        Sp = S_tr - U @ C
        Spy = Sp.T @ yp
        T_te = S_all[test] - solver.A[test] @ (W @ C)
        norms = np.einsum("ij,ij->j", S_tr, S_tr)
        for j, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
            Spj = Sp[:, a:b]
            coef = sel._solve_small(Spj.T @ Spj, Spy[a:b], float(np.max(norms[a:b])))
            e = e0 - T_te[:, a:b] @ coef
            sums[j].append((np.bincount(code, weights=e * e, minlength=len(part[7])), part))
    s0 = np.array([solver.sse0[k] for k in solver.keys])
    out = []
    for per_fold in sums:
        sse1 = solver._run_sse(per_fold)
        s1 = np.array([sse1[k] for k in solver.keys])
        out.append((sel.pooled_gain(s0, s1), (s0 - s1) / max(s0.mean(), 1e-300)))
    return out


def test_fold_gains_equal_the_fresh_array_form_to_the_last_bit():
    # runs of unequal length, so the folds' training sets differ in size (the shared arrays are cut per fold)
    rng = np.random.default_rng(3)
    runs = np.repeat(np.arange(13), rng.integers(20, 60, 13))
    n = len(runs)
    N = rng.normal(size=(n, 3))
    widths = [1, 2, 3, 1, 4]
    S_all = rng.normal(size=(n, sum(widths)))
    y = 0.4 * N[:, 0] + 0.7 * S_all[:, 1] - 0.3 * S_all[:, 5] + rng.normal(0, 0.5, n)
    solver = sel.FoldSolver(y, N, runs, res.run_folds(runs, 5, 0))
    assert len({p[2].shape[0] for p in solver.parts}) > 1
    got, ref = solver.gains(S_all, widths), _gains_written_out(solver, S_all, widths)
    assert len(got) == len(widths)
    for (g, per_run), (g_ref, per_run_ref) in zip(got, ref):
        assert g == g_ref and np.array_equal(per_run, per_run_ref)
    # one candidate at a time, from a column slice (not contiguous), gives the same numbers as among all
    g3, per_run3 = solver.gain(S_all[:, 3:6])
    g3_ref, per_run3_ref = _gains_written_out(solver, np.ascontiguousarray(S_all[:, 3:6]), [3])[0]
    assert g3 == g3_ref and np.array_equal(per_run3, per_run3_ref)


# --- the scoring's arrays written over and reused: the former fresh-array forms written out as references ---

def _linear_response_written_out(params, df, m_s, F, v_pred=None):
    """S(k+1) = (1 - h_k D_k) S(k) + h_k F_k into a fresh zero array, S = 0 at each run's first sample."""
    from l1b2.data import measurements as dataio
    from l1b2.predictor import model as pr
    d, s, V0, load, t = (df[c].to_numpy(float) for c in (dataio.DIRECTION, dataio.POSITION, dataio.VOLTAGE,
                                                         dataio.LOAD, dataio.TIME))
    D, _, _ = pr.force_parts(params, s, V0, d * load, m_s)
    if v_pred is not None:
        D = D - pr.speed_slope(params, s, V0, d * np.asarray(v_pred, float))
    D = np.broadcast_to(D, s.shape)
    m_eff = pr.effective_mass(params, load, m_s)
    F = np.asarray(F, float).reshape(len(df), -1)
    S = np.zeros_like(F)
    slices = [sl for _, sl in dataio.run_slices(df[dataio.RUN])]
    starts, lengths = np.array([sl.start for sl in slices]), np.array([sl.stop - sl.start for sl in slices])
    dt = np.zeros(len(df))
    dt[:-1] = np.diff(t)
    h = dt / m_eff
    a = 1.0 - h * D
    for k in range(int(lengths.max()) - 1):
        cur = starts[lengths > k + 1] + k
        S[cur + 1] = a[cur, None] * S[cur] + h[cur, None] * F[cur]
    return S


def _insample_written_out(A, y, S_all, widths):
    U, _ = sel._basis(A)
    yp = y - U @ (U.T @ y)
    Sp = S_all - U @ (U.T @ S_all)
    Spy = Sp.T @ yp
    norms = np.einsum("ij,ij->j", S_all, S_all)
    out = []
    bounds = np.cumsum([0] + list(widths))
    for a, b in zip(bounds[:-1], bounds[1:]):
        Spj = Sp[:, a:b]
        coef = sel._solve_small(Spj.T @ Spj, Spy[a:b], float(np.max(norms[a:b])))
        r = yp - Spj @ coef
        out.append((float(r @ r), coef))
    return float(yp @ yp), out


def _scores_written_out(candidates, r_drive, df, mask, params, m_s, v_pred, k=5, seed=0, folds=None):
    """The scoring with a fresh array at every step (responses, masked rows, usable columns, folds' rows)."""
    import math
    runs = df["run"].to_numpy()
    idx = np.flatnonzero(mask)
    y, runs_m = r_drive[idx], runs[idx]
    folds = res.run_folds(runs_m, k, seed) if folds is None else folds
    n_eff = sel._effective_n(y, runs_m)
    feats = [np.asarray(c.features(df), float).reshape(len(df), -1) for c in candidates]
    widths = [f.shape[1] for f in feats]
    N = _linear_response_written_out(params, df, m_s, sel.nuisance_forces(params, df, v_pred), v_pred)[idx]
    S_all = _linear_response_written_out(params, df, m_s, np.column_stack(feats), v_pred)[idx]
    solver = sel.FoldSolver(y, N, runs_m, folds)
    starts = np.cumsum([0] + widths[:-1])
    usable = [bool(np.all(np.isfinite(S_all[:, a:a + w])) and not np.allclose(S_all[:, a:a + w], 0))
              for a, w in zip(starts, widths)]
    cols = np.concatenate([np.arange(a, a + w) for a, w, u in zip(starts, widths, usable) if u]).astype(int)
    w_ok = [w for w, u in zip(widths, usable) if u]
    S_ok = np.ascontiguousarray(S_all[:, cols])
    cv = iter(_gains_written_out(solver, S_ok, w_ok))
    sse0, fits = _insample_written_out(solver.A, y, S_ok, w_ok)
    fits = iter(fits)
    out = []
    for w, u in zip(widths, usable):
        if not u:
            out.append((0.0, 1.0, 0.0, 0.0, np.zeros(w), 0.0))
            continue
        gain, per_run = next(cv)
        sse1, coef = next(fits)
        dll = n_eff * math.log(max(sse1, 1e-300) / max(sse0, 1e-300))
        out.append((gain, res.wilcoxon_greater(per_run), float(np.mean(per_run > 0)), dll + w * math.log(n_eff),
                    coef, dll + 2 * w))
    return out


def _simulated_case():
    from l1b2.predictor.model import example_params
    from l1b2.predictor.simulate import design_grid, free_run, simulate_dataset
    p = example_params(2).replace(sigma=8.0, c_r=5.0, alpha=(0.05, 0.005, 0.0))
    df = simulate_dataset(p, design_grid(voltages=(200.0, 260.0, 300.0), loads=(0.0, 0.03)), 0.1)
    cols = [df[c].to_numpy(float) for c in ("position_m", "voltage_V", "load_kg", "direction", "time_s")]
    v = df["speed_m_s"].to_numpy(float)
    base = free_run(p, *cols[:4], cols[4], v, 0.1, df["run"].to_numpy())
    rng = np.random.default_rng(5)
    r = cols[3] * (v - base) + rng.normal(0.0, 1e-3, len(df))
    return p, df, base, r, rng


def test_linear_response_written_over_its_forces_equals_the_fresh_array_form_to_the_last_bit():
    p, df, base, _, rng = _simulated_case()
    F = rng.normal(size=(len(df), 7))
    ref = _linear_response_written_out(p, df, 0.1, F, base)
    assert np.array_equal(sel.linear_response(p, df, 0.1, F, v_pred=base), ref)
    F_keep = F.copy()
    got = sel.linear_response(p, df, 0.1, F, v_pred=base, overwrite_F=True)
    assert np.shares_memory(got, F) and np.array_equal(got, ref) and not np.array_equal(F, F_keep)
    # one column given as a vector, no v_pred
    assert np.array_equal(sel.linear_response(p, df, 0.1, F_keep[:, 2].copy(), overwrite_F=True)[:, 0],
                          _linear_response_written_out(p, df, 0.1, F_keep[:, 2])[:, 0])


def test_rows_cut_in_place_equal_fancy_indexing():
    rng = np.random.default_rng(2)
    for n, p_keep in ((1000, 0.97), (1000, 0.5), (37, 1.0), (600, 0.0)):
        X = rng.normal(size=(n, 5))
        mask = rng.random(n) < p_keep
        mask[100:400] = p_keep > 0         # a block longer than the copy's block, shifted over itself
        idx = np.flatnonzero(mask)
        ref = X[idx]
        got = sel._rows_in_place(X, idx, block=64)
        assert (got.base is X or got is X) and got.shape == ref.shape and np.array_equal(got, ref)


def test_gains_and_insample_fits_with_shared_work_arrays_equal_the_fresh_array_forms():
    rng = np.random.default_rng(4)
    runs = np.repeat(np.arange(11), rng.integers(30, 70, 11))
    n = len(runs)
    N = rng.normal(size=(n, 3))
    widths = [3, 1, 2, 1]                  # an odd total: the held-out rows start off a 16-byte boundary
    S_all = rng.normal(size=(n, sum(widths)))
    y = 0.4 * N[:, 0] + 0.7 * S_all[:, 1] - 0.3 * S_all[:, 5] + rng.normal(0, 0.5, n)
    solver = sel.FoldSolver(y, N, runs, res.run_folds(runs, 5, 0))
    work = (np.full((n + 9, S_all.shape[1]), np.nan), np.full((n + 9, S_all.shape[1]), np.nan))
    for (g, pr_), (g_ref, pr_ref) in zip(solver.gains(S_all, widths, work),
                                         _gains_written_out(solver, S_all, widths)):
        assert g == g_ref and np.array_equal(pr_, pr_ref)
    sse0, fits = sel.insample_fits(solver.A, y, S_all, widths, work)
    sse0_ref, fits_ref = _insample_written_out(solver.A, y, S_all, widths)
    assert sse0 == sse0_ref
    for (s1, c), (s1_ref, c_ref) in zip(fits, fits_ref):
        assert s1 == s1_ref and np.array_equal(c, c_ref)
    assert np.array_equal(sel.insample_fits(solver.A, y, S_all, widths)[1][2][1], fits_ref[2][1])


def test_scores_equal_the_fresh_array_scoring_to_round_off():
    from l1b2.closeloop.candidates import CandidateForce
    p, df, base, r, rng = _simulated_case()
    mask = np.abs(base) > 0.01
    assert 0 < mask.sum() < len(mask)
    s, V0 = df["position_m"].to_numpy(float), df["voltage_V"].to_numpy(float)

    def cand(name, f):
        k = f(df).reshape(len(df), -1).shape[1]
        return CandidateForce(name, "x", "", tuple(f"c{i}" for i in range(k)), ("N",) * k, f)
    cands = [cand("a", lambda d: np.column_stack([np.sign(base), s])),
             cand("b", lambda d: V0 / 300.0),
             cand("c", lambda d: np.column_stack([s ** 2, np.sin(40 * s), np.ones(len(d))]))]
    zero = cand("z", lambda d: np.zeros(len(d)))
    for cs in (cands, cands[:1] + [zero] + cands[1:]):     # every candidate usable; one left out (a column copy)
        got = sel.score_candidates(cs, r, df, mask, p, 0.1, v_pred=base)
        ref = _scores_written_out(cs, r, df, mask, p, 0.1, base)
        assert len(got) == len(ref) == len(cs)
        for g, (gain, pv, imp, dbic, phi, daic) in zip(got, ref):
            # to round-off: the BLAS kernels' last bits may depend on the arrays' alignment (OpenBLAS builds)
            np.testing.assert_allclose((g.cv_gain, g.p_value, g.delta_bic, g.delta_aic), (gain, pv, dbic, daic),
                                       rtol=1e-10, atol=1e-14)
            assert g.runs_improved == imp
            # phi to round-off of its scale: a column inside the nuisance span (s, of the position series) has a
            # coefficient of pure round-off (order 1e-24), whose last bits depend on the LAPACK build
            np.testing.assert_allclose(g.phi, phi, rtol=1e-9, atol=1e-12 * float(np.max(np.abs(phi))))
    assert got[1].cv_gain == 0.0 and got[0].cv_gain != 0.0
    # folds given (whole conditions): the gains are those of the same scoring on those folds
    from l1b2.closeloop.folds import condition_folds
    folds = condition_folds(df[mask], 3, 0)
    got = sel.score_candidates(cands, r, df, mask, p, 0.1, v_pred=base, folds=folds)
    ref = _scores_written_out(cands, r, df, mask, p, 0.1, base, folds=folds)
    assert [g.cv_gain for g in got] == [x[0] for x in ref] and [g.p_value for g in got] == [x[1] for x in ref]
    assert [g.cv_gain for g in got] != [g.cv_gain for g in sel.score_candidates(cands, r, df, mask, p, 0.1,
                                                                                 v_pred=base)]


def _cand(df, name, f):
    from l1b2.closeloop.candidates import CandidateForce
    k = f(df).reshape(len(df), -1).shape[1]
    return CandidateForce(name, "x", "", tuple(f"c{i}" for i in range(k)), ("N",) * k, f)


def test_candidate_responses_in_blocks_equal_one_integration_to_the_last_bit():
    # reference: the responses of all the forces side by side integrated at once (fresh arrays), cut to the rows
    p, df, base, _, rng = _simulated_case()
    n = len(df)
    s = df["position_m"].to_numpy(float)
    cands = [_cand(df, "a", lambda d: np.column_stack([np.sign(base), s])), _cand(df, "b", lambda d: s ** 2),
             _cand(df, "c", lambda d: np.column_stack([np.sin(40 * s), np.cos(40 * s), np.ones(len(d))]))]
    F = np.column_stack([np.asarray(c.features(df), float).reshape(n, -1) for c in cands])
    idx = np.flatnonzero(rng.random(n) < 0.3)
    ref = _linear_response_written_out(p, df, 0.1, F, base)[idx]
    for block in (1, 2 * n, 3 * n, 10 ** 9):    # each alone (c wider than a block), a+b then c, all together
        got, widths = sel.candidate_responses(cands, df, idx, p, 0.1, v_pred=base, block_values=block)
        assert widths == [2, 1, 3] and np.array_equal(got, ref)
    from dataclasses import replace
    liar = replace(_cand(df, "d", lambda d: s), names=("x", "y"), units=("N", "N"))
    with pytest.raises(ValueError, match="1 columns for 2 parameters"):
        sel.candidate_responses([liar], df, idx, p, 0.1)


def test_the_screen_scores_every_masked_sample_at_1_khz_and_every_qth_of_each_run_faster():
    from l1b2.ident.coarse import decimation
    rng = np.random.default_rng(8)
    lengths = [23, 7, 31, 12]
    run = np.repeat(np.arange(4), lengths)
    for dt, q in ((1e-3, 1), (2e-4, 5), (5e-4, 2), (3e-3, 1)):
        t = np.concatenate([r + dt * np.arange(k) for r, k in enumerate(lengths)])
        df = pd.DataFrame({"time_s": t, "run": run})
        mask = rng.random(len(df)) < 0.8
        assert decimation(df) == q
        # written out: a sample is kept when masked and its place in its run is a multiple of q
        place = np.concatenate([np.arange(k) for k in lengths])
        assert np.array_equal(sel.screen_mask(df, mask), mask & (place % q == 0))
        assert np.array_equal(sel.screen_rows(df, mask), np.flatnonzero(mask & (place % q == 0)))


def test_a_fast_log_is_scored_on_every_qth_sample_of_the_responses_over_all_samples():
    # reference: the fresh-array scoring written out, given the mask thinned to every 5th sample of each run: the
    # responses are still integrated over every sample (the recursion at the log's own step), only compared on those
    from l1b2.predictor.model import example_params
    from l1b2.predictor.simulate import design_grid, free_run, simulate_dataset
    p = example_params(2).replace(sigma=8.0, c_r=5.0, alpha=(0.05, 0.005, 0.0))
    df = simulate_dataset(p, design_grid(voltages=(200.0, 260.0, 300.0), loads=(0.0, 0.03)), 0.1, dt=2e-4)
    cols = [df[c].to_numpy(float) for c in ("position_m", "voltage_V", "load_kg", "direction", "time_s")]
    v = df["speed_m_s"].to_numpy(float)
    base = free_run(p, *cols[:4], cols[4], v, 0.1, df["run"].to_numpy())
    r = cols[3] * (v - base) + np.random.default_rng(6).normal(0.0, 1e-3, len(df))
    mask = np.abs(base) > 0.01
    s = cols[0]
    cands = [_cand(df, "a", lambda d: np.column_stack([np.sign(base), s])), _cand(df, "b", lambda d: s ** 2)]
    place = df.groupby("run").cumcount().to_numpy()
    thinned = mask & (place % 5 == 0)
    got = sel.score_candidates(cands, r, df, mask, p, 0.1, v_pred=base)
    ref = _scores_written_out(cands, r, df, thinned, p, 0.1, base)
    for g, (gain, pv, imp, dbic, phi, daic) in zip(got, ref):
        np.testing.assert_allclose((g.cv_gain, g.p_value, g.delta_bic, g.delta_aic), (gain, pv, dbic, daic),
                                   rtol=1e-10, atol=1e-14)
        assert g.runs_improved == imp
    assert got[0].cv_gain != _scores_written_out(cands, r, df, mask, p, 0.1, base)[0][0]


def test_a_fast_log_goes_through_the_loop_with_every_check_on_the_screens_rows(monkeypatch):
    # reference: a 5 kHz log of the Eq. 29 predictor with a load-path friction (0.4 g |m|) and a friction level set
    # per run by a logged channel; the loop adds the load's effect, then the channel's, and every check of a
    # candidate against the added effects (the run-level offer's included, called here on every candidate it is
    # given) reads the same thinned rows as the added effects' columns
    from l1b2.closeloop import runlevel
    from l1b2.closeloop.loop import close_loop
    from l1b2.data.measurements import Measurements
    from l1b2.predictor.model import example_params
    from l1b2.predictor.simulate import design_grid, simulate_dataset
    aux = np.random.default_rng(3).normal(0.0, 1.0, 18)

    def extra(c):
        return -0.02 * (aux[np.asarray(c["run"])] + 2.0) - 0.4 * 9.81 * np.abs(np.asarray(c["load_kg"]))
    df = simulate_dataset(example_params(3), design_grid(voltages=(220.0, 270.0, 324.0), loads=(-0.05, 0.0, 0.05)),
                          0.1, dt=2e-4, noise_std=1e-3, seed=1, extra_force=extra)
    df["aux_C"] = aux[df["run"].to_numpy()]
    calls, offer = [], runlevel.offer

    def spy(found, short, allowed):
        calls.append([allowed(c) for c in found] + [allowed(s.candidate) for s in short])
        return offer(found, short, allowed)
    monkeypatch.setattr(runlevel, "offer", spy)
    res = close_loop(Measurements(df=df, meta={"slider_mass_kg": 0.1}, path="train.csv"), order=3, n_starts=1,
                     max_rounds=2)
    assert [e.effect for e in res.diagnosis.effects] == ["load_path_friction", "channel_aux_C"]
    assert len(calls) == 2 and calls[1]     # round 2 checked candidates against the added effect


def test_a_diverging_nuisance_response_is_left_out_and_a_diverging_candidate_scores_nothing(monkeypatch):
    # reference: the same scoring with the diverging nuisance columns removed from nuisance_forces beforehand,
    # computed by the written-out scoring; a candidate whose response diverges gets gain 0, p-value 1
    from l1b2.closeloop.candidates import CandidateForce
    p, df, base, r, rng = _simulated_case()
    mask = np.abs(base) > 0.01
    s = df["position_m"].to_numpy(float)
    n_all = sel.nuisance_forces(p, df, base)
    bad = [1, 4]                               # two nuisance directions whose linearised response overflows
    keep = [j for j in range(n_all.shape[1]) if j not in bad]
    real = sel.linear_response

    def diverging(params, d, m_s, F, v_pred=None, overwrite_F=False):
        out = real(params, d, m_s, F, v_pred=v_pred, overwrite_F=overwrite_F)
        if out.shape[1] == n_all.shape[1]:
            out[len(out) // 2:, bad] = np.inf
        elif out.shape[1] == 3:                # the third candidate's response overflows too
            out[len(out) // 2:, 2] = np.nan
        return out

    def cand(name, f):
        k = f(df).reshape(len(df), -1).shape[1]
        return CandidateForce(name, "x", "", tuple(f"c{i}" for i in range(k)), ("N",) * k, f)
    cands = [cand("a", lambda d: np.sin(40 * s)), cand("b", lambda d: np.sign(base)), cand("c", lambda d: s ** 2)]
    monkeypatch.setattr(sel, "linear_response", diverging)
    got = sel.score_candidates(cands, r, df, mask, p, 0.1, v_pred=base)
    monkeypatch.setattr(sel, "linear_response", real)
    monkeypatch.setattr(sel, "nuisance_forces", lambda params, d, v: n_all[:, keep])
    ref = _scores_written_out(cands[:2], r, df, mask, p, 0.1, base)
    for g, (gain, pv, imp, dbic, phi, daic) in zip(got[:2], ref):
        assert (g.cv_gain, g.p_value) == (gain, pv) and np.array_equal(g.phi, phi)
    assert got[0].cv_gain != 0.0 or got[1].cv_gain != 0.0
    assert (got[2].cv_gain, got[2].p_value) == (0.0, 1.0)
