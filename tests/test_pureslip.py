"""The pure-slip predictor family (l1b2.predictor.pureslip): closed forms, the step, the steady state, the physics."""

import math

import numpy as np
import pytest
from l1b2.physics import interface as itf
from l1b2.physics import steady
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor
from l1b2.predictor import model as pr
from l1b2.predictor import pureslip as ps
from l1b2.predictor.derive import derive_predictor
from l1b2.predictor.simulate import free_run


def _numeric_period_mean(W, v, F_p, sigma, mu, n=200_001):
    """Period mean of the pure-slip friction, integrated numerically over one period.

    Contact on the half period 0 <= theta <= pi, normal force pi F_p sin(theta) there (period mean F_p),
    tip velocity W sin(theta), friction sigma (w - v) + mu F_N sign(w - v) during contact, 0 outside.
    """
    th = np.linspace(0.0, 2 * np.pi, n)
    contact = th <= np.pi
    w = W * np.sin(th)
    FN = np.where(contact, np.pi * F_p * np.sin(th), 0.0)
    F = np.where(contact, sigma * (w - v) + mu * FN * np.sign(w - v), 0.0)
    return np.trapezoid(F, th) / (2 * np.pi)


@pytest.mark.parametrize("v", [-0.05, 0.0, 0.05, 0.2, 0.33, 0.45])
def test_closed_form_is_the_numeric_period_mean_and_the_physics_function(v):
    W, F_p, sigma, mu = 0.4, 6.0, 8.0, 0.2
    closed = float(ps.pure_slip_drive_force(W, v, F_p, sigma, mu))
    assert closed == pytest.approx(_numeric_period_mean(W, v, F_p, sigma, mu), abs=2e-4)
    omega = 2 * math.pi * 48.5e3
    assert closed == pytest.approx(float(itf.pure_slip_drive_force_N(W / omega, omega, v, F_p, sigma, mu)), rel=1e-12)


def test_slip_force_at_the_frozen_ratio_is_eq29s_term_and_its_slope_is_the_derivative():
    muP, Ap, c_k = 1.3, 0.3, 2.5     # tip speed W = 0.4 m/s
    for k0 in (0.1, 0.4, 0.8):
        Xs, dX, k = ps.slip_force(k0 / c_k, muP, Ap, c_k)
        assert k == pytest.approx(k0)
        eq29 = muP * (float(pr.drive_factor(k0)) - 0.5 * np.pi * Ap * float(pr.G_of_k0(k0)))
        assert Xs == pytest.approx(eq29, rel=1e-12)
        h = 1e-7
        fd = (ps.slip_force(k0 / c_k + h, muP, Ap, c_k)[0] - ps.slip_force(k0 / c_k - h, muP, Ap, c_k)[0]) / (2 * h)
        assert dX == pytest.approx(fd, rel=1e-6)
        # a negative slope (the drive force falls as the slider catches up with the tip) for physical A'
        assert dX < 0


def test_continuation_outside_pure_slip_is_continuous_and_constant():
    muP, Ap, c_k = 1.3, 0.3, 2.5
    v = np.array([-0.3, -1e-12, 0.0, 1e-12, 1 / c_k - 1e-12, 1 / c_k, 1 / c_k + 1e-12, 1.0])
    Xs, dX, k = ps.slip_force(v, muP, Ap, c_k)
    assert Xs[0] == Xs[1] == Xs[2] == pytest.approx(muP * (1 - 0.25 * np.pi ** 2 * Ap))
    assert Xs[3] == pytest.approx(Xs[2], abs=1e-9)
    assert Xs[4] == pytest.approx(Xs[5], abs=1e-5) and Xs[5] == pytest.approx(muP * (-1 + 0.25 * np.pi ** 2 * Ap))
    assert Xs[6] == Xs[7] == Xs[5]
    assert dX[0] == dX[7] == 0.0


def test_inverse_tip_speed_and_zero_voltage():
    assert float(ps.inverse_tip_speed(8.0, 6e-3, 300.0)) == pytest.approx(8.0 / (np.pi * 6e-3 * 300.0))
    # no drive: the slider outruns the (still) tip whenever it moves forward: k = 1, friction brakes
    c = ps.inverse_tip_speed(8.0, 6e-3, 0.0)
    assert np.isinf(c) and float(ps.slip_ratio(0.01, c)) == 1.0 and float(ps.slip_ratio(0.0, c)) == 0.0


def _slip_params():
    # a physically consistent set: sigma 8 N s/m and B' ~ 6 mN/V give a tip speed ~0.5 m/s at 272 V (k ~ 0.3-0.5)
    p = pr.example_params(3)
    return p.replace(sigma=8.0, c_r=5.0, alpha=(0.05, 0.005, 0.0, 0.0), drive_law="pure_slip")


def test_one_step_and_derivative_use_the_slip_ratio_of_the_state():
    q = _slip_params()
    s, V0, load, m_s, dt = 0.004, 272.0, 0.02, 0.1, 1e-3
    for v in (0.05, 0.15, -0.03):
        Ap, Bp, P = pr.position_terms(q, s)
        W = np.pi * Bp * V0 / q.sigma
        k = float(np.clip(v / W, 0, 1))
        g1 = 2 * math.sqrt(1 - k * k) - 1
        G = 2 * k * math.sqrt(1 - k * k) - 2 * math.asin(k) + np.pi / 2
        F = (-(q.c_r + q.sigma * (0.5 - Ap)) * v + Bp * V0 + q.mu * P * (g1 - 0.5 * np.pi * Ap * G)
             - 9.81 * load - np.sign(v) * q.mu_sd * (9.81 * m_s + q.kappa * P))
        m_eff = m_s + load
        assert float(pr.derivative(q, v, s, V0, load, 1, m_s)) == pytest.approx(F / m_eff, rel=1e-12)
        assert float(pr.one_step(q, v, s, V0, load, 1, dt, m_s)) == pytest.approx(v + dt * F / m_eff, rel=1e-12)
    # mirrored for direction -1 (drive coordinates)
    assert float(pr.one_step(q, -0.1, s, V0, -load, -1, dt, m_s)) == pytest.approx(
        -float(pr.one_step(q, 0.1, s, V0, load, 1, dt, m_s)), rel=1e-12)


def test_steady_state_is_a_root_and_the_free_run_converges_to_it():
    q = _slip_params()
    m_s = 0.1
    for V0, load, d in [(180.0, 0.03, 1), (324.0, -0.05, -1), (272.0, 0.0, 1)]:
        vs = float(pr.steady_state(q, 0.0, V0, load, d, m_s))
        assert vs * d > 0
        assert float(pr.derivative(q, vs, 0.0, V0, load, d, m_s)) == pytest.approx(0.0, abs=1e-9)
        t = np.arange(1500) * 1e-3
        v = free_run(q, np.zeros(t.size), V0, load, d, t, 0.0, m_s)
        assert v[-1] == pytest.approx(vs, rel=1e-6)
    # no drive voltage: the tip does not move, so any forward motion is braked by the full friction (k = 1)
    assert abs(float(pr.steady_state(q, 0.0, 0.0, 0.001, 1, m_s))) < 1e-12


def test_pure_slip_and_eq29_agree_where_the_slip_ratio_equals_k0():
    q = _slip_params()
    s, V0, load, m_s = 0.0, 272.0, 0.0, 0.1
    vs = float(pr.steady_state(q, s, V0, load, 1, m_s))
    Ap, Bp, P = pr.position_terms(q, s)
    k = vs * q.sigma / (np.pi * Bp * V0)
    e = q.replace(drive_law="eq29", k0=float(k))
    assert float(pr.steady_state(e, s, V0, load, 1, m_s)) == pytest.approx(vs, rel=1e-9)


def test_drive_law_is_checked_and_serialised():
    q = _slip_params()
    assert pr.PredictorParams.from_dict(q.to_dict()) == q
    with pytest.raises(ValueError, match="drive_law"):
        q.replace(drive_law="linear")


def _slope_ratio(fn, voltages=(180.0, 324.0), dm=0.03):
    """Ratio of the steady speed's load slope dv/dm at the highest and the lowest voltage."""
    slopes = [(fn(V, dm) - fn(V, -dm)) / (2 * dm) for V in voltages]
    return slopes[1] / slopes[0]


@pytest.mark.parametrize("motor", ["realistic_motor.toml", None])
def test_pure_slip_follows_the_coupled_models_voltage_dependence_of_the_load_slope(motor):
    # both families with the same physical parameters (the paper's own reduction, Eq. 25-30); the coupled
    # model (stick-slip contact, the rig's) is the reference; Eq. 29's slope is the same at every voltage
    mp = load_motor(SYSTEM_MODELS_DIR / motor) if motor else load_motor()
    p = derive_predictor(mp, method="paper", mode="stick_slip", order=4)
    q = p.replace(drive_law="pure_slip")
    m_s = mp.slider.mass_kg
    for s in (0.5 * (mp.slider.s_min_m + mp.slider.s_max_m), mp.slider.s_min_m + 0.25 * (mp.slider.s_max_m - mp.slider.s_min_m)):
        ref = _slope_ratio(lambda V, m: steady.steady_state(mp, s, V, m, 1, mode="stick_slip").v_m_s)
        eq29 = _slope_ratio(lambda V, m: float(pr.steady_state(p, s, V, m, 1, m_s)))
        pure = _slope_ratio(lambda V, m: float(pr.steady_state(q, s, V, m, 1, m_s)))
        assert eq29 == pytest.approx(1.0, abs=1e-9)
        assert ref > 1.03                        # the coupled model's slope does grow with V0
        assert pure > 1.03 and abs(pure - ref) < 0.7 * abs(eq29 - ref), (ref, eq29, pure)


def test_compiled_slip_run_equals_the_numpy_loop():
    # reference: the numpy loop over model.step_drive; runs of different lengths, rest starts, reversals, stuck steps
    from l1b2.predictor.pureslip import compiled_slip_run, packed_slip_recursion
    from l1b2.predictor.simulate import RunLayout
    if compiled_slip_run() is None:
        pytest.skip("numba not available")
    rng = np.random.default_rng(4)
    lay = RunLayout(np.repeat(np.arange(6), [50, 80, 80, 30, 65, 5]))
    n = lay.n
    D = rng.uniform(3, 8, n)
    X_lin = rng.uniform(-2.0, 2.0, n)
    muP = rng.uniform(0.5, 1.5, n)
    Ap = rng.uniform(0.0, 0.3, n)
    c_k = np.where(rng.random(n) < 0.1, np.inf, rng.uniform(1, 5, n))
    Fr = rng.uniform(0.0, 1.2, n)
    h = np.full(n, 1e-3 / 0.12)
    d = np.repeat(rng.choice([-1.0, 1.0], lay.R), lay.lengths)[lay.perm]
    v0 = np.array([0.0, 0.1, -0.05, 0.0, 0.2, 0.0])
    args = (lay.offs, lay.na, pr.step_drive, D, X_lin, muP, Ap, c_k, Fr, h, d, v0)
    f1, f2 = np.zeros(n, np.int8), np.zeros(n, np.int8)
    a = packed_slip_recursion(*args, flags=f1, compiled=False)
    b = packed_slip_recursion(*args, flags=f2, compiled=True)
    assert (f1 == 1).any() and (f1 == 2).any()
    for x, y in zip(a, b):
        np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(f1, f2)
