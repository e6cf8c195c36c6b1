"""Eq. 29 in its identifiable coordinates (:mod:`l1b2.ident.identifiable`): the null directions of (sigma, mu, k0)."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pytest
from l1b2.ident.identifiable import (
    IdentifiableProblem,
    admissible,
    feasible_gauge,
    h_of_k0,
    identifiable_objective,
    identifiable_search,
    k_form,
    offset_form,
    theta_of_y,
    y_of_theta,
)
from l1b2.ident.varpro import profile_loglik
from l1b2.predictor.model import K0_MAX, G_of_k0, drive_factor, example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset
from objectives import central_difference, scaled_objective

M_S = 0.1
SMALL = design_grid(voltages=(220.0, 324.0), loads=(-0.07, 0.0, 0.07))
X = np.linspace(-1.0, 1.0, 201)
ORDER, N1 = 3, 4


def _theta(seed):
    """A random admissible theta (c_r, sigma, mu > 0, 0 < k0 < 1)."""
    rng = np.random.default_rng(seed)
    th = example_params(ORDER).to_vector()
    th[:5] = [rng.uniform(2, 20), rng.uniform(1, 15), rng.uniform(0.1, 2), rng.uniform(0.05, 0.9),
              rng.uniform(0, 0.3)]
    th[5:5 + N1] = rng.normal(0, 0.3, N1)
    return th


@pytest.fixture(scope="module")
def world():
    """The small synthetic world (noise 1 mm/s, reversals and stops included) and its objective at the truth."""
    prm = example_params(ORDER)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=1e-3, seed=11)
    theta = prm.to_vector()
    return df, theta, scaled_objective(df, theta, M_S, ORDER)


def test_h_is_negative_on_the_k0_range_with_its_closed_form_at_zero():
    assert h_of_k0(0.0) == pytest.approx(4.0 / np.pi ** 2 - 0.5, rel=1e-14)
    k = np.linspace(0.0, K0_MAX, 2001)
    h = np.array([h_of_k0(x) for x in k])
    g = np.array([float(drive_factor(x)) / (0.5 * np.pi * float(G_of_k0(x))) - 0.5 for x in k])
    np.testing.assert_allclose(h, g, rtol=1e-14)
    assert np.all(h[G_of_k0(k) > 0] <= h_of_k0(0.0) + 1e-15)


@pytest.mark.parametrize("seed", range(4))
def test_theta_and_y_round_trip_and_y_holds_what_the_model_sees(seed):
    th = _theta(seed)
    y = y_of_theta(th, N1)
    np.testing.assert_allclose(theta_of_y(y, N1), th, rtol=1e-12, atol=1e-12)
    c_r, sigma, mu, k0, mu_sd = th[:5]
    A = np.polynomial.legendre.legval(X, th[5:5 + N1])
    # D(s) = c_r + sigma (0.5 - A'(s)) and mu (g1 - (pi/2) G A'(s)) = K + beta_s D(s), written out
    np.testing.assert_allclose(np.polynomial.legendre.legval(X, y[5:5 + N1]), c_r + sigma * (0.5 - A), rtol=1e-12)
    lhs = mu * (drive_factor(k0) - 0.5 * np.pi * G_of_k0(k0) * A)
    np.testing.assert_allclose(y[0] + y[2] * (c_r + sigma * (0.5 - A)), lhs, rtol=1e-10, atol=1e-12)
    # a paper vector exists only for K < 0 (c_r >= 0 and h < 0)
    assert y[0] < 0


@pytest.mark.parametrize("gauge", [(3.0, 0.02), (40.0, 0.6), (0.5, 0.95)])
def test_a_null_move_of_the_gauge_leaves_the_likelihood_unchanged_to_rounding(world, gauge):
    df, theta, obj = world
    prob = IdentifiableProblem(obj.problem)
    y = y_of_theta(theta, N1)
    r0 = prob.residual(y)
    g0 = prob.start_gain(y)
    y2 = y.copy()
    y2[1], y2[3] = gauge
    th2 = theta_of_y(y2, N1)
    assert not np.allclose(th2[:4], theta[:4])  # a different paper vector
    r2 = obj.problem.residual(th2)
    scale = float(np.max(np.abs(r0)))
    np.testing.assert_allclose(r2, r0, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(prob.start_gain(y2), g0, rtol=0, atol=1e-10)
    ll0 = obj.noise.loglik(r0)
    assert obj.noise.loglik(r2) == pytest.approx(ll0, abs=1e-6)


def test_feasible_gauge_gives_a_paper_vector_with_the_same_residuals(world):
    df, theta, obj = world
    y = y_of_theta(theta, N1)
    for sigma_max, k0 in ((1e3, 0.02), (theta[1], theta[3]), (1e-3, 0.5)):
        yg = feasible_gauge(y, sigma_max, k0)
        th = theta_of_y(yg, N1)
        assert th[0] >= 0 and th[1] > 0 and th[2] >= 0 and th[3] == k0
        assert yg[1] <= sigma_max
        r = obj.problem.residual(th)
        np.testing.assert_allclose(r, obj.problem.residual(theta), rtol=0, atol=1e-10 * np.max(np.abs(r)))
    bad = y.copy()
    bad[0] = 0.1
    with pytest.raises(ValueError, match="K < 0"):
        feasible_gauge(bad, 1.0, 0.02)


def test_the_chain_rule_jacobian_and_start_gain_sensitivity_match_finite_differences(world):
    df, theta, obj = world
    prob = IdentifiableProblem(obj.problem)
    y = y_of_theta(theta, N1)
    cols = np.array([0, 2, 4, 5, 6, 8, 9, 13, 16])
    J = prob.jacobian(y, cols)
    g, G = prob.start_gain_sensitivity(y, cols)
    p = obj.problem
    flags = p.evaluate(theta)["flags"]
    plain = ~np.isin(p.run_sel, p.lay.to_packed(p.lay.run_of_sample)[flags != 0])
    assert 0 < plain.sum() < plain.size  # both kinds of run in the world
    for j, c in enumerate(cols):
        fd = central_difference(prob.residual, y, c, 1e-2)
        np.testing.assert_allclose(J[:, j], fd, rtol=0, atol=1e-5 * max(np.max(np.abs(fd)), 1e-12))
        # the start gain's sensitivity holds the factor of reversing and stuck steps fixed (its contract):
        # compared on the runs without such steps
        fdg = central_difference(prob.start_gain, y, c, 1e-2)[plain]
        np.testing.assert_allclose(G[plain, j], fdg, rtol=0, atol=1e-5 * max(np.max(np.abs(fdg)), 1e-5))
    # D(s) does not depend on K or beta_s: their start-gain columns vanish
    np.testing.assert_allclose(G[:, :2], 0.0, atol=1e-9 * max(np.max(np.abs(G)), 1.0))
    with pytest.raises(ValueError, match="null"):
        prob.jacobian(y, [1])


def test_the_search_ends_above_its_start_with_a_paper_vector_of_that_likelihood(world):
    df, theta, obj = world
    # start away from the truth: c_r and mu_sd off, the gauge as the truth's
    th0 = theta.copy()
    th0[0] *= 0.5
    th0[4] *= 2.0
    oy, y0 = identifiable_objective(obj, th0, N1)
    ll0 = profile_loglik(oy, oy.z_of(y0))
    search, outer, stages = identifiable_search(obj, th0, N1, obj.problem.core.p_theta, 100, 1e-10, 0.01, 5)
    th = obj.theta_of(outer.z)
    lo = np.array([0.0, 0.0, 0.0, 0.0, 0.0])
    assert np.all(th[:5] >= lo) and th[3] < 1
    ll = profile_loglik(obj, outer.z)
    assert ll == pytest.approx(-search.results[search.best].cost, abs=1e-6)
    assert ll > ll0


def test_admissible_points_have_k_below_zero_and_positive_sigma_and_b():
    for seed in range(4):
        assert admissible(_theta(seed), N1)
    for i in (1, 2):  # sigma = 0 or mu = 0 (their bound): no beta_s = b / sigma
        th = _theta(0)
        th[i] = 0.0
        assert not admissible(th, N1)
    y = y_of_theta(_theta(1), N1)
    y[0] = 0.5  # K > 0: c_r = sigma h(k0) - K / beta_s < 0 for every gauge
    assert not admissible(theta_of_y(y, N1), N1)


# ---- the offset form: the drive offset kappa0 in slot 0 instead of K (decision 0079) ---------------------------

KAPPA = 0.5


@pytest.mark.parametrize("seed", range(4))
def test_the_offset_form_holds_the_drive_offset_and_round_trips(seed):
    from l1b2.ident.offset import drive_offset

    th = _theta(seed)
    y = y_of_theta(th, N1)
    yo = offset_form(y, KAPPA)
    # kappa0 = sigma a / b - c_r - sigma / 2, a = mu g1(k0) - mu_sd kappa, b = mu (pi/2) G(k0), written out
    c_r, sigma, mu, k0, mu_sd = th[:5]
    a = mu * drive_factor(k0) - mu_sd * KAPPA
    b = mu * 0.5 * np.pi * G_of_k0(k0)
    assert yo[0] == pytest.approx(sigma * a / b - c_r - 0.5 * sigma, rel=1e-12)
    assert yo[0] == pytest.approx(drive_offset(th, N1, KAPPA), rel=1e-12)
    np.testing.assert_array_equal(yo[1:], y[1:])
    np.testing.assert_allclose(k_form(yo, KAPPA), y, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(theta_of_y(k_form(yo, KAPPA), N1), th, rtol=1e-11, atol=1e-11)


def test_the_offset_forms_chain_rule_matches_finite_differences_and_rejects_k_above_zero(world):
    df, theta, obj = world
    prob = IdentifiableProblem(obj.problem, KAPPA)
    yo = offset_form(y_of_theta(theta, N1), KAPPA)
    np.testing.assert_allclose(prob.residual(yo), obj.problem.residual(theta), rtol=0,
                               atol=1e-10 * np.max(np.abs(obj.problem.residual(theta))))
    cols = np.array([0, 2, 4, 5, 6, 9, 16])
    J = prob.jacobian(yo, cols)
    g, G = prob.start_gain_sensitivity(yo, cols)
    for j, c in enumerate(cols):
        fd = central_difference(prob.residual, yo, c, 1e-2)
        np.testing.assert_allclose(J[:, j], fd, rtol=0, atol=1e-5 * max(np.max(np.abs(fd)), 1e-12))
    # D(s) depends on d only: the start gain's columns of kappa0, beta_s and mu_sd vanish
    np.testing.assert_allclose(G[:, :3], 0.0, atol=1e-9 * max(np.max(np.abs(G)), 1.0))
    # K = beta_s kappa0 + kappa mu_sd >= 0 has no paper vector: the problem gives no finite residual there
    bad = yo.copy()
    bad[0] = -KAPPA * yo[4] / yo[2] + 0.1
    assert k_form(bad, KAPPA)[0] > 0
    assert not np.all(np.isfinite(prob.residual(bad)))


def test_the_search_in_the_offset_form_ends_not_below_the_k_forms_with_a_vanishing_gradient(world):
    # mu_sd pinned; from c_r halved both forms search the same likelihood: the offset form must end where the
    # criterion's gradient vanishes and not below the K form
    from l1b2.ident.varpro import Projection, linear_positions

    df, theta, _ = world
    varied = np.ones(theta.size, bool)
    varied[4] = False
    obj = scaled_objective(df, theta, M_S, ORDER, varied=varied)
    th0 = theta.copy()
    th0[0] *= 0.5
    p_theta = obj.problem.core.p_theta
    res = {}
    for kappa in (None, KAPPA):
        search, outer, _ = identifiable_search(obj, th0, N1, p_theta, 200, 1e-12, 1e-6, 10, kappa=kappa)
        res[kappa] = (profile_loglik(obj, outer.z), obj.theta_of(outer.z))
        assert res[kappa][0] == pytest.approx(-search.results[search.best].cost, abs=1e-6)
    assert res[KAPPA][0] > profile_loglik(obj, obj.z_of(th0)) + 1.0
    assert res[KAPPA][0] >= res[None][0] - 0.01
    assert res[KAPPA][1][4] == theta[4]  # mu_sd stayed pinned
    # the gradient of the criterion (the projection's, in the offset form, at the returned vector) against the
    # start's
    grads = []
    for th in (th0, res[KAPPA][1]):
        oy, y0 = identifiable_objective(obj, th, N1, KAPPA)
        z = oy.z_of(y0)
        profile_loglik(oy, z)
        proj = Projection(oy, linear_positions(oy, p_theta, N1))
        r, cost = proj.residual(z)
        z, r, cost = proj.project(z, r, cost)
        grads.append(np.max(np.abs(proj.normal(z, r)[1])))
    assert grads[1] < 1e-3 * grads[0], grads
