"""The linearised scoring's cross-validated gains: the same numbers whatever arrays hold the folds' rows."""

import numpy as np
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
