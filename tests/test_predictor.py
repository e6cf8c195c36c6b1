"""Tests of the reduced speed predictor (paper Eq. 25-31, l1b2.predictor.model)."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json
import math

import numpy as np
import pytest
from l1b2.predictor.model import (
    G_of_k0,
    PredictorParams,
    derivative,
    example_params,
    one_step,
    steady_state,
)
from l1b2.predictor.simulate import design_grid, free_run, simulate_dataset

M_S = 0.1


def _table1():
    """alpha, beta, p of the paper's Table 1 as printed (monomials in m, highest power first).

    The paper reports them to four or five significant digits; docs/explanation/physics.md explains the
    layout (position in metres, highest power first; p(0) = 6.06 N reads as a preload).
    """
    alpha = [-2.2549e-6, -0.8633, -63.5158, 31.9521, 81.9674, -132.9991, -1.3819, 0.0078, 5.9610e-4]
    beta = [8.3913e7, -8.7852e6, -1.5375e5, 7.2194e3, 76.8995, -1.7187, -0.0104, 6.7924e-5, 1.0573e-6]
    p = [-1.0573e14, -3.1504e12, 1.4224e11, 2.9068e9, -2.5863e7, -7.8668e5, -1.9848e4, 59.4874, 6.0554]
    return np.array(alpha), np.array(beta), np.array(p)


def _eq29_literal(paper, T_s, m, v, s, V0, m_load, m_s):
    """Literal transcription of the paper's Eq. 29 (CH1), Table-1 layout polynomials."""
    A = np.polyval(paper["alpha"], s)
    B = np.polyval(paper["beta"], s)
    F_p = np.polyval(paper["p"], s)
    c_r, sigma, mu, k0, mu_sd = (paper[k] for k in ("c_r", "sigma", "mu", "k0", "mu_sd"))
    return (
        (1 - c_r * T_s / m + sigma / m * (A - 0.5 * T_s)) * v
        + B / m * V0
        + mu * F_p / m
        * (
            -0.5 * math.pi * A * (2 * k0 * math.sqrt(1 - k0**2) - 2 * math.asin(k0) + 0.5 * math.pi)
            + T_s * (2 * math.sqrt(1 - k0**2) - 1)
        )
        - T_s / m * (9.81 * m_load - np.sign(-v) * mu_sd * (9.81 * m_s + 0.5 * F_p))
    )


@pytest.mark.parametrize("include_load_inertia", [False, True])
def test_step_equals_literal_eq29(include_load_inertia):
    prm = example_params(8).replace(include_load_inertia=include_load_inertia)
    T_s = 1e-3
    paper = prm.to_paper_monomials(T_s)
    rng = np.random.default_rng(1)
    n = 200
    s = rng.uniform(-0.02, 0.02, n)
    V0 = rng.choice([220.0, 260.0, 300.0, 324.0], n)
    load = rng.choice([-0.09, -0.05, 0.0, 0.05, 0.09], n)
    v = rng.uniform(0.05, 0.4, n)  # moving, far from a reversal
    m = M_S + (np.abs(load) if include_load_inertia else 0.0)
    # direction +1 is the paper's CH1 form
    lit = _eq29_literal(paper, T_s, m, v, s, V0, load, M_S)
    ours = one_step(prm, v, s, V0, load, 1, T_s, M_S)
    np.testing.assert_allclose(ours, lit, rtol=1e-11, atol=1e-14)
    # direction -1: the mirrored form in drive coordinates v' = -v, m' = -m_load
    ours_m = one_step(prm, -v, s, V0, -load, -1, T_s, M_S)
    np.testing.assert_allclose(-ours_m, lit, rtol=1e-11, atol=1e-14)
    # the continuous form: (v1 - v)/T_s equals the acceleration
    acc = derivative(prm, v, s, V0, load, 1, M_S)
    np.testing.assert_allclose(v + T_s * acc, lit, rtol=1e-11, atol=1e-14)


def test_G_and_paper_constants():
    assert G_of_k0(0.0) == pytest.approx(math.pi / 2)
    assert G_of_k0(1.0) == pytest.approx(-math.pi / 2)
    # G(k0) = 2 k0 sqrt(1-k0^2) - 2 asin(k0) + pi/2 ("2k" of Eq. 25 read as k0)
    assert G_of_k0(0.5) == pytest.approx(2 * 0.5 * math.sqrt(0.75) - 2 * math.asin(0.5) + math.pi / 2)
    # G decreases monotonically on [0, 1]
    k = np.linspace(0, 0.99, 50)
    assert np.all(np.diff(G_of_k0(k)) < 0)


def _python_free_run(prm, s, V0, load, d, t, v_meas, run, m_s):
    """Plain Python loop over samples (the reference for the vectorised free_run)."""
    out = np.empty(len(s))
    for i in range(len(s)):
        if i == 0 or run[i] != run[i - 1]:
            out[i] = v_meas[i]
        else:
            dt = t[i] - t[i - 1]
            out[i] = float(one_step(prm, out[i - 1], s[i - 1], V0[i - 1], load[i - 1], d[i - 1], dt, m_s))
    return out


def test_free_run_equals_python_loop():
    prm = example_params(5)
    design = design_grid(voltages=(220.0, 324.0), loads=(-0.09, 0.0, 0.05), directions=(1, -1))
    df = simulate_dataset(prm, design, M_S, noise_std=2e-3, seed=4, stroke=(-0.01, 0.01))
    # jitter the clock so dt varies per sample, and perturb positions
    rng = np.random.default_rng(0)
    t = df["time_s"].to_numpy() + rng.uniform(0, 2e-4, len(df))
    t = np.maximum.accumulate(t + np.arange(len(df)) * 1e-9)
    s = df["position_m"].to_numpy() + rng.normal(0, 1e-5, len(df))
    cols = dict(
        s=s,
        V0=df["voltage_V"].to_numpy(),
        load=df["load_kg"].to_numpy(),
        d=df["direction"].to_numpy(),
        t=t,
        v_meas=df["speed_m_s"].to_numpy().copy(),
        run=df["run"].to_numpy(),
    )
    # some runs start exactly at rest, some with a (noisy) reversed speed
    starts = np.flatnonzero(np.r_[True, np.diff(cols["run"]) != 0])
    cols["v_meas"][starts[::3]] = 0.0
    assert np.any(cols["v_meas"][starts] * cols["d"][starts] < 0)
    ref = _python_free_run(prm, cols["s"], cols["V0"], cols["load"], cols["d"], cols["t"], cols["v_meas"],
                           cols["run"], M_S)
    vec = free_run(prm, cols["s"], cols["V0"], cols["load"], cols["d"], cols["t"], cols["v_meas"], M_S,
                   run_index=cols["run"])
    np.testing.assert_allclose(vec, ref, rtol=1e-12, atol=1e-15)
    # per-run start speeds give the same result
    vec2 = free_run(prm, cols["s"], cols["V0"], cols["load"], cols["d"], cols["t"], cols["v_meas"][starts], M_S,
                    run_index=cols["run"])
    np.testing.assert_array_equal(vec, vec2)


def test_free_run_reproduces_noise_free_simulation():
    prm = example_params(8)
    df = simulate_dataset(prm, design_grid(), M_S)
    assert list(df.columns[:7]) == ["time_s", "run", "position_m", "voltage_V", "direction", "load_kg", "speed_m_s"]
    assert df["run"].nunique() == 72
    assert np.all(np.diff(df["time_s"].to_numpy()) > 0)
    v = free_run(prm, df["position_m"], df["voltage_V"], df["load_kg"], df["direction"], df["time_s"],
                 df["speed_m_s"], M_S, run_index=df["run"].to_numpy())
    np.testing.assert_allclose(v, df["speed_m_s"].to_numpy(), rtol=0, atol=1e-12)
    # runs start at rest at the stroke end opposite to their direction
    first = df.groupby("run").head(1)
    assert np.all(first["speed_m_s"] == 0.0)
    np.testing.assert_allclose(first["position_m"], np.where(first["direction"] > 0, -0.02, 0.02))
    # the design is physically sensible: every run moves, speeds 0.04-0.5 m/s
    vmax = df.groupby("run")["speed_m_s"].apply(lambda x: np.max(np.abs(x)))
    assert vmax.min() > 0.04 and vmax.max() < 0.5


def test_steady_state_is_limit_of_free_run():
    prm = example_params(8)
    cases = [
        (220.0, 0.09, 1), (324.0, -0.09, 1), (260.0, 0.05, -1), (300.0, 0.0, -1),
        (220.0, 0.6, 1),  # backward branch: the load drags the slider back
        (220.0, -0.6, -1),
        (0.0, 0.0, 1),  # stuck: drive below the guide friction
    ]
    n = 6000
    t = np.arange(n) * 1e-3
    for V0, load, d in cases:
        for s in (-0.015, 0.0, 0.012):
            vf = free_run(prm, np.full(n, s), V0, load, d, t, 0.0, M_S)
            vs = steady_state(prm, s, V0, load, d, M_S)
            assert vf[-1] == pytest.approx(float(vs), abs=1e-9), (V0, load, d, s)
    assert steady_state(prm, 0.0, 220.0, 0.6, 1, M_S) < 0  # backward branch used
    assert steady_state(prm, 0.0, 0.0, 0.0, 1, M_S) == 0.0


def test_stuck_case_gives_zero():
    prm = example_params(3)
    # at 0 V (or with a load balancing the drive) |X| <= Fr: neither branch is consistent
    assert steady_state(prm, 0.01, 0.0, 0.0, 1, M_S) == 0.0
    assert steady_state(prm, 0.01, 0.0, 0.0, -1, M_S) == 0.0
    vs = steady_state(prm, np.linspace(-0.02, 0.02, 7), 220.0, 0.125, 1, M_S)
    np.testing.assert_array_equal(vs, 0.0)
    assert steady_state(prm, 0.0, 220.0, 0.10, 1, M_S) > 0  # a lighter load still moves
    # from rest the predictor stays at rest (static friction), no chatter
    t = np.arange(500) * 1e-3
    np.testing.assert_array_equal(free_run(prm, np.zeros(500), 220.0, 0.125, 1, t, 0.0, M_S), 0.0)
    np.testing.assert_array_equal(derivative(prm, 0.0, 0.0, 220.0, 0.125, 1, M_S), 0.0)
    # a stuck design run records zeros for max_duration
    df = simulate_dataset(prm, [(0.0, 0.0, 1)], M_S, max_duration=0.2)
    assert len(df) == 201 and np.all(df["speed_m_s"] == 0.0)


def test_rest_and_reversal_rules():
    prm = example_params(3)
    s, V0, load, dt = 0.0, 300.0, 0.0, 1e-3
    # from rest: the static friction opposes the drive, capped at Coulomb level
    a0 = float(derivative(prm, 0.0, s, V0, load, 1, M_S))
    a_plus = float(derivative(prm, 1e-12, s, V0, load, 1, M_S))
    assert a0 == pytest.approx(a_plus, rel=1e-9)
    # a step that would reverse the speed continues from rest for the rest of the step
    v_neg = -1e-4
    v1 = float(one_step(prm, v_neg, s, V0, load, 1, dt, M_S))
    a_back = float(derivative(prm, v_neg, s, V0, load, 1, M_S))
    frac = v_neg / (v_neg - (v_neg + dt * a_back))
    assert v1 == pytest.approx((1 - frac) * dt * a0, rel=1e-12)
    assert 0 < v1 < dt * a0


def _mirror(prm):
    sgn = lambda c: tuple(np.asarray(c) * (-1.0) ** np.arange(len(c)))  # noqa: E731
    return prm.replace(alpha=sgn(prm.alpha), beta=sgn(prm.beta), p=sgn(prm.p), s_center=-prm.s_center)


def test_mirror_symmetry():
    prm = example_params(6).replace(s_center=0.003)
    mir = _mirror(prm)
    rng = np.random.default_rng(3)
    s = rng.uniform(-0.02, 0.02, 50)
    v = rng.uniform(-0.3, 0.3, 50)
    V0 = rng.uniform(200, 330, 50)
    m = rng.uniform(-0.09, 0.09, 50)
    # direction -1 with load -m is direction +1 with load m, mirrored
    a_plus = derivative(prm, v, s, V0, m, 1, M_S)
    a_minus = derivative(mir, -v, -s, V0, -m, -1, M_S)
    np.testing.assert_allclose(a_minus, -a_plus, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        steady_state(mir, -s, V0, -m, -1, M_S), -steady_state(prm, s, V0, m, 1, M_S), rtol=1e-12
    )
    df = simulate_dataset(prm, [(300.0, 0.05, 1)], M_S)
    dfm = simulate_dataset(mir, [(300.0, -0.05, -1)], M_S)
    np.testing.assert_allclose(dfm["position_m"], -df["position_m"], atol=1e-15)
    np.testing.assert_allclose(dfm["speed_m_s"], -df["speed_m_s"], atol=1e-15)
    vf = free_run(mir, dfm["position_m"], 300.0, -0.05, -1, dfm["time_s"], 0.0, M_S)
    np.testing.assert_allclose(vf, -df["speed_m_s"].to_numpy(), atol=1e-15)
    # with mirror-symmetric polynomials the same parameters serve both directions
    sym = prm.replace(s_center=0.0, alpha=(0.2, 0.0, 0.01), beta=(4e-3, 0.0, 1e-4), p=(6.0, 0.0, 0.3))
    np.testing.assert_allclose(
        derivative(sym, -v, -s, V0, -m, -1, M_S), -derivative(sym, v, s, V0, m, 1, M_S), rtol=1e-12, atol=1e-12
    )


def test_legendre_monomial_round_trip_table1():
    alpha, beta, p = _table1()
    assert alpha.size == beta.size == p.size == 9
    assert p[-1] == pytest.approx(6.0554)  # p(0): the preload in N
    T_s, s_half = 1e-3, 0.02
    prm = PredictorParams.from_paper_monomials(
        3.0871, 0.0014, 0.2297, 0.5844, 0.0994, alpha, beta, p, T_s=T_s, s_center=0.0, s_half=s_half
    )
    assert prm.order == 8
    back = prm.to_paper_monomials(T_s)
    powers = np.arange(8, -1, -1)
    for name, orig in (("alpha", alpha), ("beta", beta), ("p", p)):
        got = np.asarray(back[name])
        # coefficient-wise, relative to each term's size over the stroke
        term = np.abs(orig) * s_half**powers
        np.testing.assert_allclose(got * s_half**powers, orig * s_half**powers, rtol=0,
                                   atol=1e-12 * term.sum())
        # and the polynomials agree as functions of position
        s = np.linspace(-s_half, s_half, 41)
        np.testing.assert_allclose(np.polyval(got, s), np.polyval(orig, s), rtol=0,
                                   atol=1e-12 * term.sum())
    # A' = A/T_s, B' = B/T_s, P in N
    s = np.linspace(-0.02, 0.02, 9)
    np.testing.assert_allclose(prm.A_prime(s) * T_s, np.polyval(alpha, s), rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(prm.B_prime(s) * T_s, np.polyval(beta, s), rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(prm.P(s), np.polyval(p, s), rtol=1e-10)
    assert prm.P(0.0) == pytest.approx(6.0554)
    # a shifted window converts as well
    prm2 = PredictorParams.from_paper_monomials(
        3.0871, 0.0014, 0.2297, 0.5844, 0.0994, alpha, beta, p, T_s=T_s, s_center=0.004, s_half=0.018
    )
    np.testing.assert_allclose(prm2.P(s), prm.P(s), rtol=1e-9)


def test_params_vector_and_dict_round_trip():
    prm = example_params(4).replace(s_center=0.001, s_half=0.021, kappa=1.0, include_load_inertia=False)
    th = prm.to_vector()
    names = PredictorParams.names(4)
    assert len(th) == len(names) == 5 + 3 * 5
    assert names[:6] == ["c_r", "sigma", "mu", "k0", "mu_sd", "alpha_0"] and names[-1] == "p_4"
    back = PredictorParams.from_vector(th, 0.001, 0.021, 1.0, False)
    assert back == prm
    d = json.loads(json.dumps(prm.to_dict()))
    assert PredictorParams.from_dict(d) == prm
    units = PredictorParams.units(4)
    assert units["c_r"] == "N s/m" and units["beta_2"] == "N/V" and units["p_0"] == "N" and units["alpha_1"] == "-"
    lo, hi = PredictorParams.bounds(4)
    assert lo[3] == 0 and hi[3] < 1 and np.all(lo[:5] == 0)
    with pytest.raises(ValueError):
        PredictorParams.from_vector(th[:-1])


def test_kappa_is_the_guide_share():
    base = example_params(3)
    # kappa only changes the guide friction mu_sd * kappa * P
    a05 = derivative(base, 0.2, 0.0, 300.0, 0.0, 1, M_S)
    a10 = derivative(base.replace(kappa=1.0), 0.2, 0.0, 300.0, 0.0, 1, M_S)
    m_eff = M_S
    expected = -base.mu_sd * 0.5 * base.P(0.0) / m_eff
    assert float(a10 - a05) == pytest.approx(float(expected), rel=1e-10)
