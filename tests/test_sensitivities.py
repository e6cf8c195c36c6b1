"""Exact sensitivities of the Eq. 29 free run (compiled recursions) and the variable-projection search."""

import json
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pandas as pd
import pytest
from l1b2.ident.estimator import PredictorIdentifier
from l1b2.ident.problem import LikelihoodProblem, SampleData
from l1b2.ident.reduced import reduced_linear_fit, reduced_of_theta
from l1b2.ident.varpro import Projection, linear_positions
from l1b2.predictor import kernels
from l1b2.predictor.model import G_of_k0, drive_factor, example_params
from l1b2.predictor.simulate import RunLayout, design_grid, packed_linear_recursion, packed_recursion, \
    simulate_dataset
from l1b2.units import G_M_S2
from objectives import central_difference, scaled_objective

M_S = 0.1
SMALL = design_grid(voltages=(220.0, 324.0), loads=(-0.07, 0.0, 0.07))


def _random_recursion(seed):
    """Packed coefficients of runs that start at rest, reverse, stick and move (a random world)."""
    rng = np.random.default_rng(seed)
    runs = np.repeat(np.arange(7), rng.integers(5, 60, 7))
    lay = RunLayout(runs)
    n = lay.n
    a = rng.uniform(0.7, 1.0, n)
    e = rng.normal(0.0, 0.02, n)
    f = rng.uniform(0.0, 0.03, n)
    nd = -np.sign(rng.normal(size=n))
    z0 = np.clip(rng.normal(0.0, 1.5, n), -1.0, 1.0)
    v0 = np.where(rng.random(lay.R) < 0.4, 0.0, rng.normal(0.0, 0.05, lay.R))
    return lay, a, e, f, nd, z0, v0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_free_run_and_sensitivity_loops_compute_the_numpy_numbers(seed, monkeypatch):
    pytest.importorskip("numba")
    monkeypatch.delenv("L1B2_JIT", raising=False)
    assert kernels.compiled_free_run() is not None and kernels.compiled_linear_recursion() is not None
    lay, a, e, f, nd, z0, v0 = _random_recursion(seed)
    U = np.random.default_rng(seed + 10).normal(size=(lay.n, 4))
    fl_c = np.zeros(lay.n, dtype=np.int8)
    v_c = packed_recursion(lay, a, e, f, nd, z0, v0, fl_c)
    S_c = packed_linear_recursion(lay, a, U, S0=0.5)
    monkeypatch.setenv("L1B2_JIT", "0")
    assert kernels.compiled_free_run() is None
    fl_p = np.zeros(lay.n, dtype=np.int8)
    v_p = packed_recursion(lay, a, e, f, nd, z0, v0, fl_p)
    S_p = packed_linear_recursion(lay, a, U, S0=0.5)
    # the random world holds every kind of step
    assert np.any(fl_p == 1) and np.any(fl_p == 2) and np.any(fl_p == 0)
    np.testing.assert_array_equal(fl_c, fl_p)
    np.testing.assert_array_equal(v_c, v_p)  # same operations in the same order: bit-identical
    np.testing.assert_allclose(S_c, S_p, rtol=1e-14, atol=1e-15)


def _one_run_frame(n=80, dt=1e-3, v_start=0.01, V0=250.0, load=0.03):
    t = dt * np.arange(n)
    return pd.DataFrame({"time_s": t, "run": 0, "position_m": np.linspace(-0.01, 0.01, n), "voltage_V": V0,
                         "direction": 1, "load_kg": load, "speed_m_s": np.full(n, v_start)})


def test_free_run_sensitivities_equal_the_closed_form_of_a_constant_coefficient_run():
    # order 0: D, X, Fr constant along the run, so v_k = v_inf + (v_0 - v_inf) a^k with a = 1 - h D,
    # v_inf = (X - Fr) / D (forward motion) and every derivative has a closed form
    df = _one_run_frame()
    data = SampleData(df)
    prob = LikelihoodProblem(data, 0, 0.5, True, "free_run", 0.0, 0.02, M_S)
    c_r, sig, mu, k0, musd, al, be, p = 2.0, 1.0, 0.2, 0.5, 0.05, 0.1, 0.004, 2.0
    theta = np.array([c_r, sig, mu, k0, musd, al, be, p])
    h = 1e-3 / (M_S + 0.03)
    D = c_r + sig * (0.5 - al)
    X = be * 250.0 + mu * p * (float(drive_factor(k0)) - 0.5 * np.pi * al * float(G_of_k0(k0))) - G_M_S2 * 0.03
    Fr = musd * (G_M_S2 * M_S + 0.5 * p)
    v_inf = (X - Fr) / D
    assert v_inf > 0
    a = 1.0 - h * D
    k = np.arange(80)
    v = v_inf + (0.01 - v_inf) * a**k
    np.testing.assert_allclose(prob.residual(theta) + 0.01, v, rtol=1e-12)
    J = prob.jacobian(theta, np.arange(8))
    dv_dD = -(X - Fr) / D**2 * (1 - a**k) - (0.01 - v_inf) * k * a ** np.maximum(k - 1, 0) * h
    np.testing.assert_allclose(J[:, 0], dv_dD, rtol=1e-9, atol=1e-15)  # dD/dc_r = 1
    np.testing.assert_allclose(J[:, 6], (1 - a**k) / D * 250.0, rtol=1e-9, atol=1e-15)  # dX/dbeta_0 = V0
    g, G = prob.start_gain_sensitivity(theta, [0, 1, 5])
    np.testing.assert_allclose(g, a**k, rtol=1e-12)
    dg_dD = -h * k * a ** np.maximum(k - 1, 0)
    np.testing.assert_allclose(G[:, 0], dg_dD, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(G[:, 1], dg_dD * (0.5 - al), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(G[:, 2], dg_dD * (-sig), rtol=1e-9, atol=1e-15)


@pytest.fixture(scope="module")
def noisy_world():
    prm = example_params(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=1e-3, seed=11)
    return prm, df


@pytest.fixture(scope="module")
def moving_world():
    """Noisy speeds, but every run starts exactly at rest: the free run has no reversal or stuck step."""
    prm = example_params(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=1e-3, seed=12)
    starts = np.flatnonzero(np.r_[True, np.diff(df["run"].to_numpy()) != 0])
    df.loc[starts, "speed_m_s"] = 0.0
    return prm, df


def test_start_gain_sensitivity_matches_central_differences(noisy_world):
    prm, df = noisy_world
    theta = prm.to_vector() * (1 + 0.05 * np.sin(np.arange(prm.to_vector().size)))
    obj = scaled_objective(df, theta, M_S)
    prob = obj.problem
    cols = np.array([0, 1, 5, 6, 7, 8])  # c_r, sigma, alpha_0..3: the parameters of D(s)
    g, G = prob.start_gain_sensitivity(theta, cols)
    # runs without a reversal or stuck step are exact; the others hold those steps' factor (documented)
    flags = prob.evaluate(theta)["flags"]
    run_p = prob.lay.to_packed(prob.lay.run_of_sample)
    odd_runs = np.unique(run_p[flags != 0])
    assert odd_runs.size and odd_runs.size < prob.lay.R  # the data hold both kinds of run
    plain = ~np.isin(prob.run_sel, odd_runs)
    for j, c in enumerate(cols):
        fd = central_difference(prob.start_gain, theta, c, 1e-3)
        assert np.max(np.abs(G[plain, j] - fd[plain])) <= 1e-6 * np.max(np.abs(fd)), c


def test_criterion_gradient_is_exact_including_the_start_speed_term(moving_world):
    # grad phi of Projection.normal against central differences of phi = 0.5 |r_w|^2 + 0.5 sum log(1 + g.g)
    # with the start-speed gain g re-evaluated at every point (R fixed)
    prm, df = moving_world
    theta = prm.to_vector() * (1 + 0.03 * np.cos(np.arange(prm.to_vector().size)))
    obj = scaled_objective(df, theta, M_S)
    assert not np.any(obj.problem.evaluate(theta)["flags"])
    proj = Projection(obj, linear_positions(obj, obj.problem.core.p_theta, 4))
    z = obj.z_of(theta)
    r, _ = proj.residual(z)
    _, grad = proj.normal(z, r)
    fd = np.empty_like(grad)
    for j in range(z.size):
        step = 1e-6 * max(abs(z[j]), 1e-2)
        zp, zm = z.copy(), z.copy()
        zp[j] += step
        zm[j] -= step
        fd[j] = 0.25 * (proj.residual(zp)[1] - proj.residual(zm)[1]) / step
    np.testing.assert_allclose(grad, fd, rtol=2e-4, atol=2e-4 * np.max(np.abs(fd)))
    # and the start-speed term matters: without it the gradient is a different vector
    obj0 = scaled_objective(df, theta, M_S, start_noise=False)
    r0 = obj0.fun(obj0.z_of(theta))
    assert np.max(np.abs(obj0.jac(obj0.z_of(theta)).T @ r0 - grad)) > 1e-3 * np.max(np.abs(grad))


def test_one_step_linear_fit_recovers_the_linear_parameters_exactly_on_noise_free_data():
    # Eq. 29's one-step form is linear in the coefficients of D(s), B'(s) and C(s): on noise-free data of the
    # model (moving samples) the linear least-squares solution is the truth to rounding
    prm = example_params(4)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=0.0)
    data = SampleData(df)
    red = reduced_linear_fit(data, 4, M_S, True, prm.s_center, prm.s_half)
    truth = reduced_of_theta(prm.to_vector(), 4, M_S, prm.kappa)
    got = np.concatenate([red["D"], red["B"], red["C"]])
    np.testing.assert_allclose(got, truth, rtol=1e-7, atol=1e-9 * np.max(np.abs(truth)))


def test_varpro_reaches_the_joint_optimum_where_both_converge():
    # without the start-speed term both searches minimise the same weighted sum of squares; from the same
    # data-driven starts they must end at the same log-likelihood (and predictions)
    prm = example_params(2)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=3e-4, seed=6)
    common = dict(order=2, n_starts=2, start_noise=False, fixed="recommended", stat_tol=1e-6, max_nfev=400)
    joint = PredictorIdentifier(solver="joint", noise_fit="alternate", **common).fit(df, slider_mass_kg=M_S)
    vp = PredictorIdentifier(solver="varpro", **common).fit(df, slider_mass_kg=M_S)
    assert abs(vp.loglik_ - joint.loglik_) < 1e-3, (vp.loglik_, joint.loglik_)
    np.testing.assert_allclose(vp.predict_free_run(df), joint.predict_free_run(df), rtol=0, atol=1e-6)
    stages = [s["stage"] for s in vp.convergence_["stages"]]
    assert stages == ["start", "starts", "noise refinement", "uncertainty"]
    assert [s["stage"] for s in joint.convergence_["stages"]] == ["start", "search (alternate)", "uncertainty"]
    for est in (vp, joint):  # every stage's wall and CPU time; the search stages their evaluations
        assert all(s["time_s"] >= 0 and s["cpu_s"] >= 0 for s in est.convergence_["stages"])
        assert sum(s.get("nfev", 0) for s in est.convergence_["stages"]) >= est.convergence_["nfev_total"] > 0
        assert json.loads(json.dumps(est.to_dict()))["convergence"]["stages"] == est.convergence_["stages"]
    assert vp.convergence_["solver"] == "varpro" and vp.convergence_["nfev_total"] > 0


def test_an_unknown_solver_is_refused_with_the_known_ones():
    from l1b2.errors import IdentificationError

    df = simulate_dataset(example_params(2), SMALL, M_S, noise_std=1e-4, seed=1)
    with pytest.raises(IdentificationError, match="solver must be one of .*varpro"):
        PredictorIdentifier(order=2, solver="newton").fit(df, slider_mass_kg=M_S)
