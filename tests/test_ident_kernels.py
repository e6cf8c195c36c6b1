"""The identification's compiled Jacobian loops, the blocked R factor and the close loop's signal cache.

Each is a faster form of a computation that stays in the package (the numpy forms, one Householder QR, the
uncached signals): the reference of every test here.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pytest
from l1b2.closeloop.candidates import Context, signals
from l1b2.ident import kernels
from l1b2.ident.estimator import evaluation_mask
from l1b2.ident.noise import NoiseModel
from l1b2.ident.problem import LikelihoodProblem, SampleData, ScaledObjective, param_scale
from l1b2.ident.tallqr import r_factor
from l1b2.physics.jit import jit_enabled
from l1b2.predictor.model import PredictorParams, example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset

M_S = 0.1
compiled = pytest.mark.skipif(not jit_enabled() or kernels.compiled_drive_derivative() is None,
                              reason="numba kernels not available")


@pytest.fixture(scope="module")
def problem():
    prm = example_params(3)
    df = simulate_dataset(prm, design_grid(voltages=(220.0, 324.0), loads=(-0.07, 0.0, 0.07)), M_S,
                          noise_std=1e-3, seed=5)
    data = SampleData(df, evaluation_mask(df))
    rng = np.random.default_rng(0)
    E = rng.standard_normal((data.layout.n, 2))      # two extra-force features (packed rows)
    prob = LikelihoodProblem(data, 3, 0.5, True, "free_run", 0.0, 0.02, M_S, E=E)
    theta = np.concatenate([prm.to_vector() * (1 + 0.03 * np.cos(np.arange(prm.to_vector().size))), [0.1, -0.2]])
    return prob, theta, df


@compiled
@pytest.mark.parametrize("cols", ["all", "subset"])
def test_compiled_drive_derivative_is_the_numpy_form_to_the_last_bit(problem, cols):
    # reference: ForceCore.dF (numpy, block by block) times the row weight, the form the loop replaces
    prob, theta, _ = problem
    core = prob.core
    c = prob.evaluate(theta)
    p = theta.size
    idx = np.arange(p) if cols == "all" else np.array([0, 2, 4, 5, 7, 9 + 1, p - 2, p - 1])
    fast = kernels.drive_derivative(core, theta, c["vp"], c["sg"], c["Ap"], c["P"], idx, core.hd)
    slow = core.dF(theta, c["vp"], c["sg"], c["Ap"], c["P"], idx) * core.hd[:, None]
    assert fast.flags.c_contiguous and fast.shape == slow.shape
    assert np.array_equal(fast, slow)
    assert np.array_equal(core.weighted_dF(theta, c["vp"], c["sg"], c["Ap"], c["P"], idx, core.hd), slow)


@compiled
def test_compiled_whitening_is_the_sparse_numpy_form_to_the_last_bit(problem):
    # reference: NoiseModel.W (a sparse product per run) divided by sqrt(R), with per-run variances and start gains
    prob, theta, _ = problem
    noise = NoiseModel(prob.run_sel, prob.data.layout.R, "per_run")
    noise.set_start_gain(prob.start_gain(theta))
    noise.update_R(prob.residual(theta))
    J = prob.jacobian(theta, np.arange(theta.size))
    assert np.ptp(noise.R) > 0 and np.any(noise.g != 0)
    slow = noise.W(J) / noise._sqrtR[:, None]
    assert np.array_equal(noise.weighted(J), slow)
    try:
        NoiseModel.compiled = False
        assert np.array_equal(noise.weighted(J), slow)
    finally:
        NoiseModel.compiled = True


def test_objective_jacobian_matches_finite_differences_with_the_compiled_loops(problem):
    # reference: central differences of the whitened residual (the Jacobian the search uses)
    prob, theta, _ = problem
    prm_lo, prm_hi = PredictorParams.bounds(3)
    lo = np.concatenate([prm_lo, [-np.inf, -np.inf]])
    hi = np.concatenate([prm_hi, [np.inf, np.inf]])
    varied = np.ones(theta.size, bool)
    varied[[1, 3, 4]] = False
    scale = np.concatenate([param_scale(theta[:-2], 3), [1.0, 1.0]])
    obj = ScaledObjective(prob, NoiseModel(prob.run_sel, prob.data.layout.R, "common"), theta, varied, scale, lo,
                          hi, True)
    obj.update_noise(theta)
    z = obj.z_of(theta)
    J = obj.jac(z)
    eps = 1e-6
    for j in (0, 3, z.size - 1):
        dz = np.zeros_like(z)
        dz[j] = eps
        fd = (obj.fun(z + dz) - obj.fun(z - dz)) / (2 * eps)
        np.testing.assert_allclose(J[:, j], fd, rtol=1e-4, atol=1e-6 * np.max(np.abs(fd)))


@pytest.mark.parametrize("n,p,block", [(5000, 12, 256), (3001, 30, 1024), (700, 9, 256), (100, 5, 0)])
def test_blocked_r_factor_is_an_r_of_the_same_matrix(n, p, block):
    # reference: one Householder QR (numpy); R is unique up to the signs of its rows; R^T R = A^T A
    rng = np.random.default_rng(n)
    A = rng.standard_normal((n, p)) * np.logspace(0, 5, p)
    R = r_factor(A, block)
    R0 = np.linalg.qr(A, mode="r")
    assert R.shape == (p, p) and np.allclose(np.tril(R, -1), 0.0)
    np.testing.assert_allclose(np.abs(R), np.abs(R0), rtol=1e-10, atol=1e-12 * np.abs(R0).max())
    np.testing.assert_allclose(R.T @ R, A.T @ A, rtol=1e-10, atol=1e-12 * np.abs(A.T @ A).max())


def test_signals_are_computed_once_per_frame_and_equal_the_uncached_ones(problem):
    # reference: the same signals computed on a fresh context (nothing cached) and a counter of free runs
    _, _, df = problem
    calls = []

    def free_run(frame):
        calls.append(1)
        return np.linspace(0.0, 1.0, len(frame)) * frame["direction"].to_numpy(float)

    def ctx():
        return Context(baseline_free_run=free_run, m_s=M_S, time_range=(0.0, 1.0), position_range=(-0.02, 0.02))
    c = ctx()
    first = signals(df, c, {"v_base", "a_base", "s"})
    again = signals(df, c, {"a_base", "V0"})
    assert len(calls) == 1                                   # one free run for both calls on the same frame
    fresh = signals(df, ctx(), {"v_base", "a_base"})
    for k in ("v_base", "a_base", "t", "s", "V0", "load", "d"):
        assert np.array_equal(first[k], fresh[k])
    assert again["a_base"] is first["a_base"] and not again["a_base"].flags.writeable
    other = df.copy()
    signals(other, c, {"v_base"})
    assert len(calls) == 3                                   # a new frame (another object) is computed anew
    import pickle
    assert pickle.loads(pickle.dumps(Context(baseline_free_run=np.sin, m_s=M_S, time_range=(0.0, 1.0),
                                             position_range=(0.0, 1.0)))).signal_cache == {}


@pytest.mark.parametrize("sorted_runs", [True, False])
def test_whitening_a_vector_by_run_sums_is_the_sparse_product_to_the_last_bit(sorted_runs):
    # W(x) = x - c g (G x)[run]: G x by bincount adds the same products in the same order as the CSR product
    from scipy.sparse import csr_matrix

    rng = np.random.default_rng(3 if sorted_runs else 4)
    for _ in range(10):
        n, R = int(rng.integers(50, 20000)), int(rng.integers(1, 30))
        run = rng.integers(0, R, n)
        run = np.sort(run) if sorted_runs else run
        nm = NoiseModel(run, R, "per_run")
        g = rng.normal(size=n) * rng.uniform(0.0, 3.0)
        nm.set_start_gain(g)
        x = rng.normal(size=n) * 10.0 ** rng.uniform(-5, 5)
        G = csr_matrix((g, (run, np.arange(n))), shape=(R, n))
        np.testing.assert_array_equal(nm.W(x), x - nm.cg * (G @ x)[run])
        X = rng.normal(size=(n, 3))
        np.testing.assert_array_equal(nm.W(X), X - nm.cg[:, None] * (G @ X)[run])


@compiled
@pytest.mark.parametrize("order", ["C", "F"])
def test_fused_gather_whitening_and_scaling_is_the_numpy_form_to_the_last_bit(order):
    # reference: S[rows] whitened by NoiseModel.W / sqrt(R), scaled by columns, non-finite entries set to 0 (the
    # steps of ScaledObjective.jac before the fused loop), on unsorted runs with start gains and a few NaN / inf
    rng = np.random.default_rng(11)
    n_all, p, R = 3000, 7, 9
    rows = np.sort(rng.choice(n_all, 2200, replace=False))
    run = rng.integers(0, R, rows.size)
    nm = NoiseModel(run, R, "per_run")
    nm.set_start_gain(rng.normal(size=rows.size))
    nm.update_R(rng.normal(size=rows.size) * rng.uniform(0.5, 2.0, R)[run])
    S = rng.normal(size=(n_all, p)) * 10.0 ** rng.uniform(-4, 4, p)
    S[rows[5], 2], S[rows[17], 0] = np.nan, np.inf
    scale = 10.0 ** rng.uniform(-3, 3, p)
    with np.errstate(invalid="ignore"):                   # inf - inf in the run of the inf entry
        ref = nm.W(S[rows]) / nm._sqrtR[:, None]
    ref *= scale[None, :]
    ref = np.where(np.isfinite(ref), ref, 0.0)
    fast = kernels.scaled_whitened(S, rows, run, nm.g, nm.cg, nm._sqrtR, R, scale, order)
    assert fast.flags.c_contiguous if order == "C" else fast.flags.f_contiguous
    assert np.array_equal(fast, ref) and np.all(fast[run == run[5], 2] == 0.0)
    assert np.array_equal(nm.weighted_jacobian(S, rows, scale, order), ref)
    try:
        NoiseModel.compiled = False
        with np.errstate(invalid="ignore"):
            assert np.array_equal(nm.weighted_jacobian(S, rows, scale, order), ref)
    finally:
        NoiseModel.compiled = True


def test_objective_jacobian_is_the_whitened_scaled_problem_jacobian_in_either_memory_order(problem):
    # reference: the unfused steps (problem Jacobian on the residual rows, NoiseModel.weighted, column scaling)
    prob, theta, _ = problem
    varied = np.ones(theta.size, bool)
    varied[[1, 3]] = False
    scale = np.concatenate([param_scale(theta[:-2], 3), [1.0, 1.0]])
    lo, hi = np.full(theta.size, -np.inf), np.full(theta.size, np.inf)
    obj = ScaledObjective(prob, NoiseModel(prob.run_sel, prob.data.layout.R, "per_run"), theta, varied, scale, lo,
                          hi, True)
    obj.update_noise(theta)
    z = obj.z_of(theta)
    ref = obj.noise.weighted(prob.jacobian(obj.theta_of(z), obj.vidx)) * obj.sv_scale[None, :]
    assert np.array_equal(obj.jac(z), ref) and np.array_equal(obj.jac(z, order="F"), ref)
    assert obj.jac(z, order="F").flags.f_contiguous
    cols = np.array([0, 4, z.size - 1])
    assert np.array_equal(obj.jac_columns(z, cols, order="F"), ref[:, cols])


def test_run_sums_by_bincount_are_numpy_add_at_to_the_last_bit():
    # reference: numpy.add.at (the rows added in their order), unsorted runs, magnitudes over ten decades
    from l1b2.ident.search import _run_sums

    rng = np.random.default_rng(2)
    run = rng.integers(0, 13, 5000)
    X = rng.normal(size=(5000, 6)) * 10.0 ** rng.uniform(-5, 5, (5000, 1))
    ref = np.zeros((13, 6))
    np.add.at(ref, run, X)
    assert np.array_equal(_run_sums(run, 13, X), ref)


@pytest.mark.parametrize("n_extra", [0, 2])
def test_reduced_linear_columns_are_those_of_the_full_reduced_jacobian_to_the_last_bit(n_extra):
    # reference: reduced_of_theta(..., jac=True)'s columns of c_r, beta, p (and phi), at the projection's point
    # (the linear parameters zeroed, as the equation-error fit sets them)
    from l1b2.ident.reduced import reduced_linear_columns, reduced_of_theta

    order = 4
    n1 = order + 1
    th = np.concatenate([example_params(order).to_vector(), 0.3 * np.arange(1, n_extra + 1)])
    th[5:5 + n1] += 0.01 * np.cos(np.arange(n1))          # a curved A'(s): the P * A' products matter
    lin = np.array([0] + list(range(5 + n1, th.size)))
    th[lin] = 0.0
    full = reduced_of_theta(th, order, M_S, 0.5, jac=True)[1]
    assert np.array_equal(reduced_linear_columns(th, lin, order, M_S, 0.5), full[:, lin])
    sub = lin[[0, 2, -1]]
    assert np.array_equal(reduced_linear_columns(th, sub, order, M_S, 0.5), full[:, sub])
    with pytest.raises(ValueError):
        reduced_linear_columns(th, np.array([5]), order, M_S, 0.5)       # alpha_0 is not linear
