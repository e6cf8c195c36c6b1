"""The run-level REML fit (:mod:`l1b2.closeloop.reml`) reaches the restricted likelihood's optimum.

Each test writes its reference out here: the closed form of a scalar model with equal sampling variances, the
restricted log-likelihood of the stacked model (full block-diagonal covariance, ``numpy`` only) maximised by
Nelder-Mead, finite differences of the likelihood for the analytic gradient, the boundary (runs that do not differ
beyond their sampling error: ``T`` 0) and the cross-validation fold fits of a realistic size, which must all converge
before the iteration cap. A REML without its ``log|X' W X|`` term (maximum likelihood), a sign error in the gradient,
a wrong whitening or a missing check of the boundary's first-order condition fails one of them.
"""

import numpy as np
import pytest
from l1b2.closeloop import reml as rm
from l1b2.closeloop import runlevel as rl
from l1b2.closeloop import runstats as rs
from scipy import optimize


def restricted_loglik_stacked(theta, S, X, T):
    """``l_R`` written out on the stacked model: ``y`` (n p), ``V = blockdiag(T + S_r)``, ``X`` (n p, k)."""
    n, p = theta.shape
    y = theta.ravel()
    Xs = X.reshape(n * p, -1)
    V = np.zeros((n * p, n * p))
    for r in range(n):
        V[r * p:(r + 1) * p, r * p:(r + 1) * p] = T + S[r]
    Vi = np.linalg.inv(V)
    XtVX = Xs.T @ Vi @ Xs
    beta = np.linalg.solve(XtVX, Xs.T @ Vi @ y)
    e = y - Xs @ beta
    return -0.5 * (np.linalg.slogdet(V)[1] + np.linalg.slogdet(XtVX)[1] + e @ Vi @ e), beta


def _world(n=40, seed=0, T_true=((4e-4, -3e-4), (-3e-4, 9e-4)), spread=1.0):
    """Runs' (gain, offset) with unequal, correlated sampling covariances, a covariate ``z`` in the mean and the
    runs' loads ``w`` (the signal's design of :func:`runstats.signal_design`)."""
    rng = np.random.default_rng(seed)
    z = rng.normal(size=n)
    w = rng.choice([-1.0, -0.5, 0.5, 1.0], n)
    S = np.empty((n, 2, 2))
    for r in range(n):
        a, b, rho = 0.02 * rng.uniform(0.5, 2.0), 0.03 * rng.uniform(0.5, 2.0), rng.uniform(-0.8, 0.8)
        S[r] = [[a * a, rho * a * b], [rho * a * b, b * b]]
    X = rs.signal_design(z, w)
    beta = np.array([1.0, 0.02, 0.0, 0.05, 0.01])
    u = rng.multivariate_normal([0, 0], np.asarray(T_true), n) if np.any(T_true) else np.zeros((n, 2))
    e = np.array([rng.multivariate_normal([0, 0], s) for s in S])
    return np.einsum("rpk,k->rp", X, beta) + u + spread * e, S, X


def _T_of(x):
    """``T`` of (log sd gain, log sd offset, atanh correlation)."""
    sa, sb, c = np.exp(x[0]), np.exp(x[1]), np.tanh(x[2])
    return np.array([[sa * sa, c * sa * sb], [c * sa * sb, sb * sb]])


def test_equal_scalar_variances_give_the_closed_form_and_zero_below_the_sampling_variance():
    # written out: theta_r = mu + u_r + e_r, var(e_r) = s2: T = max(0, var(theta, ddof=1) - s2)
    rng = np.random.default_rng(7)
    n, s2 = 25, 0.25
    for sd in (1.0, 0.3):                          # a spread above the sampling error, then one below it
        theta = rng.normal(2.0, sd, n)
        fit = rm.reml(theta[:, None], np.full((n, 1, 1), s2))
        want = max(0.0, np.var(theta, ddof=1) - s2)
        assert fit.converged and fit.iterations < rm.REML_ITER
        assert fit.T[0, 0] == pytest.approx(want, rel=1e-6, abs=1e-9 * s2)
        assert fit.beta[0] == pytest.approx(theta.mean(), rel=1e-9)
    assert want == 0.0                             # the second case is on the boundary


def test_the_optimum_of_a_covariate_design_with_unequal_sampling_covariances_is_the_brute_force_one():
    theta, S, X = _world()
    fit = rm.reml(theta, S, X)
    assert fit.converged

    def neg(x):
        return -restricted_loglik_stacked(theta, S, X, _T_of(x))[0]

    best = None
    for x0 in ([-4.0, -4.0, 0.0], [-3.0, -3.5, -1.0], [-5.0, -3.0, 1.0]):
        o = optimize.minimize(neg, x0, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-13,
                                                                     "maxiter": 20000, "maxfev": 40000})
        best = o if best is None or o.fun < best.fun else best
    T_bf = _T_of(best.x)
    ll_fit, beta_bf = restricted_loglik_stacked(theta, S, X, fit.T)
    assert ll_fit >= -best.fun - 1e-8                       # at least as high as the brute force reaches
    np.testing.assert_allclose(fit.T, T_bf, rtol=1e-3, atol=1e-3 * np.max(np.abs(T_bf)))
    np.testing.assert_allclose(fit.beta, beta_bf, rtol=1e-9, atol=1e-12)   # GLS at the fit's T, stacked
    _, beta_at_bf = restricted_loglik_stacked(theta, S, X, T_bf)
    se = np.sqrt(np.diag(fit.beta_cov))
    assert np.max(np.abs(fit.beta - beta_at_bf) / se) < 1e-3
    # the BLUP and beta's covariance written out at the fit's T
    W = np.linalg.inv(fit.T[None] + S)
    C = np.linalg.inv(np.einsum("rpk,rpq,rqj->kj", X, W, X))
    np.testing.assert_allclose(fit.beta_cov, C, rtol=1e-9)
    mean = np.einsum("rpk,k->rp", X, fit.beta)
    np.testing.assert_allclose(fit.blup, mean + np.einsum("pq,rqs,rs->rp", fit.T, W, theta - mean), rtol=1e-9)
    # and the module's l_R is the stacked one up to nothing (both drop the same constant)
    assert rm.restricted_loglik(theta, S, X, fit.T)[0] == pytest.approx(ll_fit, rel=1e-10)


def test_the_analytic_gradient_is_the_finite_difference_one():
    theta, S, X = _world(n=20, seed=3)
    T = np.array([[3e-4, -1e-4], [-1e-4, 6e-4]])
    _, G = rm.restricted_loglik(theta, S, X, T)
    h = 1e-9
    for (i, j) in ((0, 0), (1, 1), (0, 1)):
        E = np.zeros((2, 2))
        E[i, j] = E[j, i] = h
        fd = (restricted_loglik_stacked(theta, S, X, T + E)[0] - restricted_loglik_stacked(theta, S, X, T - E)[0]) / (2 * h)
        want = G[i, j] * (1 if i == j else 2)               # a symmetric perturbation moves both T_ij and T_ji
        assert fd == pytest.approx(want, rel=1e-5, abs=1e-6 * np.max(np.abs(G)))
    # the solver's objective in the whitened Cholesky parameters, through the chain rule
    A = rm._whitener(S)
    x = np.array([0.7, -0.4, 1.3])
    f, g = rm._objective(x, theta, S, X, A)
    for j in range(3):
        d = np.zeros(3)
        d[j] = 1e-6
        fd = (rm._objective(x + d, theta, S, X, A)[0] - rm._objective(x - d, theta, S, X, A)[0]) / 2e-6
        assert fd == pytest.approx(g[j], rel=1e-5, abs=1e-8)
    L = np.array([[0.7, 0.0], [-0.4, 1.3]])
    assert -f * len(theta) == pytest.approx(restricted_loglik_stacked(theta, S, X, A @ L @ L.T @ A.T)[0], rel=1e-10)


def test_runs_that_do_not_differ_beyond_their_sampling_error_have_no_between_run_covariance():
    # each run's deviation is half its sampling error: every direction of T lowers l_R from T = 0
    theta, S, X = _world(n=40, seed=5, T_true=((0, 0), (0, 0)), spread=0.5)
    fit = rm.reml(theta, S, X)
    assert fit.converged
    assert np.max(np.abs(fit.T)) < 1e-10 * np.max(S[:, 0, 0])
    ll0 = restricted_loglik_stacked(theta, S, X, np.zeros((2, 2)))[0]
    for v in ([1, 0], [0, 1], [1, 1], [1, -2]):
        v = np.asarray(v, float) * 0.01
        assert restricted_loglik_stacked(theta, S, X, np.outer(v, v))[0] < ll0


def test_a_start_on_a_saddle_of_the_cholesky_factor_is_left_for_the_optimum():
    # Tw = diag(0, 1): the Cholesky factor's first column is 0, where the gradient in it vanishes although l_R
    # grows with T's gain variance (the solver alone stays there); the boundary's first-order condition sends the
    # search on to the optimum
    theta, S, X = _world(n=40, seed=2)
    ref = rm.reml(theta, S, X)
    A = rm._whitener(S)
    stuck = rm._search(theta, S, X, A, rm._lower_factor(np.diag([0.0, 1.0])), rm.REML_ITER, rm.REML_TOL)
    assert stuck[0][0, 0] == 0.0 and stuck[2]                    # a zero gradient, and l_R grows from there:
    assert rm._kkt(A, stuck[4], len(theta))[0] > rm.KKT_TOL
    T, it, ok = rm._maximise(theta, S, X, A, np.diag([0.0, 1.0]), rm.REML_ITER, rm.REML_TOL)
    assert ok and ref.T[0, 0] > 1e-5
    np.testing.assert_allclose(T, ref.T, rtol=1e-4, atol=1e-6 * np.max(np.abs(ref.T)))


def test_the_fold_fits_of_a_realistic_session_converge_before_the_cap(monkeypatch):
    # 72 runs as the realistic world's plan; gain and offset sampling errors strongly correlated (as the one-step
    # force's least squares gives them), the between-run spread near rank one, a signal explaining part of it
    rng = np.random.default_rng(11)
    n = 72
    z = rng.normal(size=n)
    w = rng.choice([-1.0, 0.0, 1.0], n)
    S = np.empty((n, 2, 2))
    for r in range(n):
        a, b = 0.15 * rng.uniform(0.7, 1.5), 0.16 * rng.uniform(0.7, 1.5)
        S[r] = [[a * a, -0.99 * a * b], [-0.99 * a * b, b * b]]
    T_true = np.array([[3e-5, -3.4e-4], [-3.4e-4, 4.2e-3]])
    theta = (np.array([1.0, 0.0]) + np.outer(z, [0.01, 0.05])
             + rng.multivariate_normal([0, 0], T_true, n) + np.array([rng.multivariate_normal([0, 0], s) for s in S]))
    dev = rl.RunDeviations(np.arange(n), theta, S, np.full(n, 500), w)
    fits = []

    def recording(*a, **kw):
        f = rm.reml(*a, **kw)
        fits.append(f)
        return f

    monkeypatch.setattr(rs, "reml", recording)
    sigs = [{"channel": "aux", "transform": "none", "values": 3.0 + z},
            {"channel": "noise", "transform": "none", "values": rng.normal(size=n)}]
    rl.signal_evidence(dev, sigs, alpha=0.01, k=5, seed=0)
    assert len(fits) >= 2 * (1 + 5)
    assert all(f.converged and f.iterations < rm.REML_ITER for f in fits)
    # and fast: one fold fit's optimum is on the rank-one boundary with l_R flat across it, which the Cholesky
    # factor alone approaches in about 300 iterations; its face is searched instead
    assert max(f.iterations for f in fits) <= 2 * rm.FULL_CHUNK


def test_a_search_that_makes_no_progress_ends_at_the_cap_unconverged(monkeypatch):
    # a stretch of the solver that stops at once (a line search that cannot lower -l_R) still counts: the loop
    # over stretches ends at the iteration cap and says it did not converge
    theta, S, X = _world(n=20, seed=4)
    calls = []

    def stalled(theta, S, X, A, B0, maxiter, tol):
        calls.append(maxiter)
        assert len(calls) < 1000, "the loop over stretches does not end"
        ll, G = rm.restricted_loglik(theta, S, X, A @ B0 @ B0.T @ A.T)
        return B0 @ B0.T, 0, False, ll, G

    monkeypatch.setattr(rm, "_search", stalled)
    fit = rm.reml(theta, S, X, n_iter=30)
    assert not fit.converged and fit.iterations >= 30
