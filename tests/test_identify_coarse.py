"""The identification's cheaper steps on many samples: the compressed trust-region problem and coarse to fine."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pandas as pd
import pytest
from l1b2.ident.coarse import coarse_to_fine, decimate, decimation, nfev_of
from l1b2.ident.estimator import PredictorIdentifier
from l1b2.ident.search import CompressedObjective, LocalSolver
from l1b2.predictor.model import example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset
from objectives import scaled_objective

M_S = 0.1
SMALL = design_grid(voltages=(220.0, 324.0), loads=(-0.07, 0.0, 0.07))


@pytest.fixture(scope="module")
def world():
    prm = example_params(3)
    return prm, simulate_dataset(prm, SMALL, M_S, noise_std=1e-3, seed=11)


def _objective(df, theta):
    varied = np.ones(theta.size, bool)
    varied[[1, 3, 4]] = False     # sigma, mu, k0 pinned (one per structural direction): J has full rank
    return scaled_objective(df, theta, M_S, varied=varied)


def test_compressed_problem_has_the_norm_gradient_and_gauss_newton_matrix_of_the_full_one(world):
    # reference: with [J r] = Q [[R, c], [0, rho]], |(c, rho)| = |r|, R^T c = J^T r, R^T R = J^T J (exact algebra)
    prm, df = world
    theta = prm.to_vector() * (1 + 0.03 * np.cos(np.arange(prm.to_vector().size)))
    obj = _objective(df, theta)
    z = obj.z_of(theta)
    r, J = obj.fun(z), obj.jac(z)
    comp = CompressedObjective(obj)
    f, Jc = comp.fun(z), comp.jac(z)
    assert f.size == J.shape[1] + 1 < r.size and Jc.shape == (f.size, J.shape[1])
    assert np.linalg.norm(f) == pytest.approx(np.linalg.norm(r), rel=1e-12)
    np.testing.assert_allclose(Jc.T @ f, J.T @ r, rtol=1e-9, atol=1e-9 * np.max(np.abs(J.T @ r)))
    np.testing.assert_allclose(Jc.T @ Jc, J.T @ J, rtol=1e-9, atol=1e-9 * np.max(np.abs(J.T @ J)))
    z2 = z * 1.001   # a second point is factorised anew, not served from the first one's factors
    assert np.linalg.norm(comp.fun(z2)) == pytest.approx(np.linalg.norm(obj.fun(z2)), rel=1e-12)


def test_local_search_on_the_compressed_problem_takes_the_full_problems_steps(world):
    # reference: the same trust-region search on the full residual vector (the steps depend on J^T J, J^T r, |r|)
    prm, df = world
    theta = prm.to_vector() * (1 + 0.05 * np.sin(np.arange(prm.to_vector().size)))
    out = {}
    for compressed in (False, True):
        obj = _objective(df, theta)
        solver = LocalSolver(obj, 1e-10, 0.0, 10)
        solver.compressed = compressed
        res, _ = solver(obj.z_of(theta), 15)
        out[compressed] = (res, 0.5 * float(np.sum(obj.fun(res.x) ** 2)))
    (full, c_full), (comp, c_comp) = out[False], out[True]
    assert comp.nfev == full.nfev
    assert c_comp == pytest.approx(c_full, rel=1e-9)
    np.testing.assert_allclose(comp.x, full.x, rtol=1e-6, atol=1e-9)
    assert comp.cost == pytest.approx(c_comp, rel=1e-12)    # the reported cost is the full problem's


def _frame(lengths, dt):
    runs = np.repeat(np.arange(len(lengths)), lengths)
    k = np.concatenate([np.arange(n) for n in lengths])
    return pd.DataFrame({"time_s": 10.0 * runs + dt * k, "run": runs, "position_m": 1e-4 * k, "speed_m_s": 0.01})


@pytest.mark.parametrize("dt,q", [(2e-4, 5), (1e-3, 1), (3e-4, 3), (5e-4, 2), (2e-3, 1)])
def test_decimation_is_the_samples_per_millisecond(dt, q):
    assert decimation(_frame([40, 7, 25], dt)) == q


def test_decimate_keeps_every_qth_sample_of_each_run_from_its_first():
    df = _frame([11, 3, 7], 2e-4)
    mask = np.arange(len(df)) % 4 != 0
    sub, m = decimate(df, mask, 5)
    # reference, by hand: run 0 keeps samples 0, 5, 10; run 1 keeps 0; run 2 keeps 0, 5
    k = np.concatenate([np.arange(n) for n in (11, 3, 7)])
    keep = np.array([0, 5, 10, 11, 14, 19])
    np.testing.assert_array_equal(keep, np.flatnonzero(k % 5 == 0))
    pd.testing.assert_frame_equal(sub, df.iloc[keep].reset_index(drop=True))
    np.testing.assert_array_equal(m, mask[keep])
    same, m1 = decimate(df, mask, 1)
    assert same is df and np.array_equal(m1, mask)


def _identifier():
    return PredictorIdentifier(order=3, fixed="recommended", n_starts=2, seed=0, noise_fit="alternate", max_nfev=60)


def test_coarse_to_fine_at_one_khz_is_the_plain_fit(world):
    _, df = world
    plain = _identifier().fit(df, slider_mass_kg=M_S)
    est = coarse_to_fine(_identifier(), df, M_S)
    assert est.coarse_ is None and nfev_of(est) == plain.convergence_["nfev_total"]
    assert est.loglik_ == plain.loglik_
    np.testing.assert_array_equal(est.theta_, plain.theta_)


def test_coarse_to_fine_on_a_fast_daq_ends_as_high_as_the_whole_search_on_all_samples():
    # stated behaviour: the coarse search locates the basin, the warm search on all samples reaches its optimum;
    # reference: the identifier's whole search on all samples (same settings)
    prm = example_params(3)
    df = simulate_dataset(prm, SMALL, M_S, dt=2.5e-4, noise_std=1e-3, seed=5)
    full = _identifier().fit(df, slider_mass_kg=M_S)
    est = coarse_to_fine(_identifier(), df, M_S)
    assert est.coarse_["decimation"] == 4 and est.coarse_["samples"] < len(df) / 3
    assert est.loglik_ >= full.loglik_ - 0.5
    assert nfev_of(est) == est.convergence_["nfev_total"] + est.coarse_["nfev"]
