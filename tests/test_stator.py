"""Stator (paper Sect. 3.2, Eq. 5-16): l1b2.physics.stator."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from l1b2.physics import stator as st
from numpy.polynomial import legendre as npleg
from scipy.integrate import quad, solve_ivp
from scipy.linalg import eigh
from scipy.optimize import brentq


@pytest.fixture(scope="module")
def sp(motor):
    return motor.stator


# ---------------------------------------------------------------------------
# Eq. 12-13 and the envelope dynamics against the full second-order ODE (Eq. 6-7)
# ---------------------------------------------------------------------------

M_TEST = 0.05          # modal mass [kg]
F0_TEST = 48000.0      # natural frequency [Hz]
F_AMP = 10.0           # excitation amplitude [N]
ETA_TEST = 0.7         # mode shape at the tip


def _full_ode(zeta, r, t_end, rtol=1e-8):
    w0 = 2 * np.pi * F0_TEST
    K, C = M_TEST * w0 ** 2, 2 * zeta * M_TEST * w0
    w = r * w0

    def rhs(t, y):
        return [y[1], (F_AMP * np.sin(w * t) - C * y[1] - K * y[0]) / M_TEST]

    sol = solve_ivp(rhs, (0.0, t_end), [0.0, 0.0], method="DOP853", rtol=rtol, atol=1e-16, dense_output=True)
    assert sol.success
    return sol, w, w0, K, C


@pytest.mark.parametrize("r", [0.9, 0.98, 1.0, 1.01, 1.1])
def test_eq12_13_match_ode_steady_state(r):
    # reference: solve_ivp of M q'' + C q' + K q = F sin(w t) from rest, > 8 time constants 2M/C
    zeta = 0.05
    w0 = 2 * np.pi * F0_TEST
    tau = 1.0 / (zeta * w0)  # 2M/C
    T = 2 * np.pi / (r * w0)
    t_end = 10 * tau + 3 * T
    sol, w, w0, K, C = _full_ode(zeta, r, t_end)
    tt = np.linspace(t_end - 3 * T, t_end, 6001)
    q = sol.sol(tt)[0]
    U_ode = ETA_TEST * np.max(np.abs(q))
    U_eq = float(st.steady_amplitude(F_AMP, ETA_TEST, w, K, w0, zeta))
    assert U_eq == pytest.approx(U_ode, rel=1e-2)
    # tighter: the amplitude from a projection on sin/cos over the last period equals Eq. 12-13
    t1 = np.linspace(t_end - T, t_end, 4001)[:-1]
    q1 = sol.sol(t1)[0]
    amp = 2 * abs(np.mean(q1 * np.exp(-1j * w * t1)))
    assert ETA_TEST * amp == pytest.approx(U_eq, rel=1e-4)


def test_dynamic_stiffness_phasor_is_the_ode_steady_state():
    # reference: Q = F/Z with x(t) = Im[Q e^{jwt}] must satisfy the ODE exactly (substitution)
    w0 = 2 * np.pi * F0_TEST
    for zeta, r in [(0.01, 0.99), (0.05, 1.02)]:
        K, C, w = M_TEST * w0 ** 2, 2 * zeta * M_TEST * w0, r * w0
        Q = F_AMP / st.dynamic_stiffness(w, M_TEST, K, C)
        t = np.linspace(0, 3 * 2 * np.pi / w, 50)
        x = np.imag(Q * np.exp(1j * w * t))
        xd = np.imag(1j * w * Q * np.exp(1j * w * t))
        xdd = np.imag(-w * w * Q * np.exp(1j * w * t))
        resid = M_TEST * xdd + C * xd + K * x - F_AMP * np.sin(w * t)
        assert np.max(np.abs(resid)) < 1e-9 * F_AMP
        # and |Q| is Eq. 12-13 (eta = 1)
        assert abs(Q) == pytest.approx(float(st.steady_amplitude(F_AMP, 1.0, w, K, w0, zeta)), rel=1e-12)


@pytest.mark.parametrize("zeta, r", [(0.01, 1.0), (0.01, 1.0104), (0.02, 0.995)])
def test_envelope_follows_full_ode_during_transient(zeta, r):
    # reference: complex envelope of the solve_ivp solution, demodulated over one period,
    # against envelope_step from Q=0; the slowly varying approximation is accurate to O(zeta)
    w0 = 2 * np.pi * F0_TEST
    tau = 1.0 / (zeta * w0)
    t_end = 3 * tau
    sol, w, w0, K, C = _full_ode(zeta, r, t_end, rtol=1e-9)
    T = 2 * np.pi / w
    Qss = F_AMP / st.dynamic_stiffness(w, M_TEST, K, C)
    errs, ratios = [], []
    for tc in np.linspace(T, t_end - T, 25):
        tt = tc - T / 2 + (np.arange(400) + 0.5) * T / 400
        Q_full = 2j * np.mean(sol.sol(tt)[0] * np.exp(-1j * w * tt))
        Q_env = complex(st.envelope_step(0j, F_AMP, 0.0, w, M_TEST, K, C, tc))
        errs.append(abs(Q_full - Q_env) / abs(Qss))
        ratios.append(abs(Q_env) / abs(Qss))
    assert max(errs) < 3 * zeta
    assert ratios[0] < 0.2  # it is a genuine transient, not only the steady state
    # the ODE envelope rises with time constant 2M/C: after 1 tau the envelope is 1 - e^-1 of steady (on resonance)
    if r == 1.0:
        Q_tau = complex(st.envelope_step(0j, F_AMP, 0.0, w, M_TEST, K, C, tau))
        assert abs(Q_tau) / abs(Qss) == pytest.approx(1 - np.exp(-1), rel=0.02)


@pytest.mark.parametrize("Y", [0.0, 2.0e6 + 5.0e5j, -1.0e6j])
def test_envelope_step_is_exact_vs_many_small_steps(Y):
    # reference: (a) 20000 explicit Euler steps of envelope_derivative, (b) solve_ivp, (c) semigroup property
    w0 = 2 * np.pi * F0_TEST
    zeta = 0.01
    K, C, w = M_TEST * w0 ** 2, 2 * zeta * M_TEST * w0, 1.003 * w0
    F = 3.0 + 4.0j
    Q0 = 1e-7 - 2e-7j
    h = 2e-4
    exact = complex(st.envelope_step(Q0, F, Y, w, M_TEST, K, C, h))
    # the interface load -Y Q is a stiffness change: envelope_derivative with K + Y
    n = 20000
    Q = Q0
    for _ in range(n):
        Q = Q + (h / n) * complex(st.envelope_derivative(Q, F, w, M_TEST, K + Y, C))
    scale = max(abs(exact), abs(Q0))
    assert abs(Q - exact) < 2e-4 * scale  # Euler is first order: error ~ h/n |lambda|
    sol = solve_ivp(lambda t, y: [st.envelope_derivative(y[0], F, w, M_TEST, K + Y, C)], (0, h), [Q0],
                    method="DOP853", rtol=1e-12, atol=1e-20)
    assert abs(sol.y[0, -1] - exact) < 1e-9 * scale
    two_halves = st.envelope_step(st.envelope_step(Q0, F, Y, w, M_TEST, K, C, h / 2), F, Y, w, M_TEST, K, C, h / 2)
    assert abs(complex(two_halves) - exact) < 1e-12 * scale


@pytest.mark.parametrize("Y", [0.0, 2.0e6 + 5.0e5j, -1.0e6j, 3.0e7j, -2.0e8 - 3.0e8j])
def test_envelope_growth_rate_is_the_homogeneous_steps_modulus(Y):
    # reference: with no excitation the exact step multiplies Q by exp(lambda h), so |Q1/Q0| = exp(rate h)
    w0 = 2 * np.pi * F0_TEST
    K, C, w = M_TEST * w0 ** 2, 2 * 0.01 * M_TEST * w0, 1.003 * w0
    h, Q0 = 2e-5, 1e-7 - 2e-7j
    rate = st.envelope_growth_rate_scalar(complex(Y), w, M_TEST, K, C)
    ratio = abs(complex(st.envelope_step(Q0, 0.0, Y, w, M_TEST, K, C, h))) / abs(Q0)
    assert ratio == pytest.approx(np.exp(rate * h), rel=1e-10)
    # an interface load with a negative quadrature part (-Im Y > w C) feeds the mode, a positive one damps it
    assert (rate > 0) == (-complex(Y).imag > w * C * (1 + 1e-9))


def test_coupled_step_holds_a_force_that_would_feed_a_mode(motor):
    # the interface's generalised force -G on a mode is the describing function -Y Q (Y = G/Q) when that damps
    # the mode, and a held excitation F - G when Y would make the step grow (here a 0.5 N friction fundamental
    # on a bending mode of 1e-10 m, as at a start from zero under a pulling load): the step's growth is then
    # bounded by the forced response instead of exp(rate h)
    props = st.modal_properties(motor.stator, 70.0)
    w, h, eta = 2 * np.pi * 48500.0, 2e-4, props.eta_T
    Q_l, Q_b = 1e-8 + 0j, 1e-10 + 0j

    def step(F_T1):  # (F_T1_sin, F_T1_cos) in the normal frame; phase_l 0, no normal force, no drive
        out = st.coupled_envelope_step(Q_l.real, Q_l.imag, Q_b.real, Q_b.imag, 0.0, 0.0, 0.0, F_T1.real,
                                       F_T1.imag, 0.0, 0.0, eta, w, props.M_l, props.K_l, props.C_l, props.M_b,
                                       props.K_b, props.C_b, h, eta)
        return complex(out[2], out[3])

    args = (w, props.M_b, props.K_b, props.C_b, h)
    for F_T1, feeds in ((0.5j, False), (-0.5j, True), (0.3 - 0.4j, True)):
        G = eta * F_T1
        Y = G / Q_b
        assert (st.envelope_growth_rate_scalar(Y, *args[:4]) > 0) == feeds
        expected = st.envelope_step(Q_b, -G, 0.0, *args) if feeds else st.envelope_step(Q_b, 0.0, Y, *args)
        assert step(F_T1) == pytest.approx(complex(expected), rel=1e-12, abs=1e-25)
        if feeds:  # the describing function would have amplified Q by more than e^10; the held force does not
            assert abs(complex(st.envelope_step(Q_b, 0.0, Y, *args))) > np.exp(10) * abs(Q_b)
            assert abs(step(F_T1)) <= abs(Q_b) + abs(G) * h / (2 * w * props.M_b) * 1.01


def test_envelope_steady_state_is_eq12_13():
    # reference: after many time constants the envelope equals F/Z, whose modulus is Eq. 12-13
    w0 = 2 * np.pi * F0_TEST
    for zeta, r in [(0.01, 1.0), (0.01, 1.02), (0.03, 0.97)]:
        K, C, w = M_TEST * w0 ** 2, 2 * zeta * M_TEST * w0, r * w0
        Q = complex(st.envelope_step(0j, F_AMP, 0.0, w, M_TEST, K, C, 60.0 / (zeta * w0)))
        assert ETA_TEST * abs(Q) == pytest.approx(float(st.steady_amplitude(F_AMP, ETA_TEST, w, K, w0, zeta)),
                                                  rel=1e-10)


# ---------------------------------------------------------------------------
# B2 mode shape with axial force (Eq. 9-11)
# ---------------------------------------------------------------------------

def _beta_L_second_free_free():
    """Second non-zero root of cos(x) cosh(x) = 1 (second free-free bending mode)."""
    return brentq(lambda x: np.cos(x) * np.cosh(x) - 1.0, 7.0, 8.5, xtol=1e-14)


def test_beta_L_constant_is_the_second_free_free_root():
    # reference: brentq root of the free-free frequency equation cos x cosh x = 1
    assert st.BETA_L_B2 == pytest.approx(_beta_L_second_free_free(), rel=1e-12)


def test_effective_EI_places_unloaded_B2_at_f_b0(sp):
    # reference: Euler-Bernoulli w = (beta L)^2 / L^2 sqrt(EI / (rho S)) with beta L from brentq
    EI = float(st.effective_EI_N_m2(sp))
    bl = _beta_L_second_free_free()
    w = bl ** 2 / sp.length_m ** 2 * np.sqrt(EI / (sp.density_kg_m3 * sp.width_m * sp.thickness_m))
    assert w == pytest.approx(2 * np.pi * sp.f_b0_Hz, rel=1e-10)
    assert float(st.b2_frequency_rad_s(sp, 0.0)) == pytest.approx(2 * np.pi * sp.f_b0_Hz, rel=1e-9)


def _fourth_derivative(shape, x):
    b1, b2 = shape.beta1_per_m, shape.beta2_per_m
    return (b1 ** 4 * (shape.C * np.cos(b1 * x) + shape.D * np.sin(b1 * x))
            + b2 ** 4 * (shape.E * np.sinh(b2 * x) + shape.F * np.cosh(b2 * x)))


def _loads(motor):
    return [0.0, float(st.axial_force_N(motor.stator, 0.0)), 3.0e4, -3.0e4, 1.0e5, -1.0e5]


@pytest.mark.parametrize("k", range(6))
def test_b2_mode_shape_satisfies_ode_and_free_end_conditions(motor, sp, k):
    # reference: the axially loaded beam equation and its natural boundary conditions, written here
    P = _loads(motor)[k]
    N = -P  # tension
    shape = st.b2_mode_shape(sp, P)
    EI = float(st.effective_EI_N_m2(sp))
    rhoS = sp.density_kg_m3 * sp.width_m * sp.thickness_m
    w = float(shape.omega_rad_s)
    L = sp.length_m
    x = np.linspace(0, L, 401)
    phi = st.phi_b(shape, x)
    bmax = max(float(shape.beta1_per_m), float(shape.beta2_per_m))
    amp = np.max(np.abs(phi))
    # derivatives of phi_b agree with central finite differences of the lower derivative
    hx = 1e-7 * L
    xi = x[5:-5]
    for d in (1, 2, 3):
        fd = (st.phi_b(shape, xi + hx, d - 1) - st.phi_b(shape, xi - hx, d - 1)) / (2 * hx)
        np.testing.assert_allclose(st.phi_b(shape, xi, d), fd, atol=1e-6 * amp * bmax ** d)
    # EI phi'''' - N phi'' - rho S w^2 phi = 0
    resid = EI * _fourth_derivative(shape, x) - N * st.phi_b(shape, x, 2) - rhoS * w * w * phi
    assert np.max(np.abs(resid)) < 1e-9 * EI * bmax ** 4 * amp
    # free ends: w'' = 0 and EI w''' - N w' = 0 at x = 0 and x = L
    for xe in (0.0, L):
        assert abs(float(st.phi_b(shape, xe, 2))) < 1e-9 * bmax ** 2 * amp
        shear = EI * float(st.phi_b(shape, xe, 3)) - N * float(st.phi_b(shape, xe, 1))
        assert abs(shear) < 1e-9 * EI * bmax ** 3 * amp
    # normalisation int phi^2 = L, sign phi(L) > 0, antisymmetric about the centre (B2)
    norm, _ = quad(lambda s: float(st.phi_b(shape, s)) ** 2, 0, L, epsabs=0, epsrel=1e-12, limit=200)
    assert norm == pytest.approx(L, rel=1e-9)
    assert float(st.phi_b(shape, L)) > 0
    np.testing.assert_allclose(st.phi_b(shape, L - x), -phi, atol=1e-9 * amp)
    # second flexible mode: exactly 3 nodes (sign changes) along the bar
    xn = (np.arange(1000) + 0.5) / 1000 * L  # grid avoiding the central node x = L/2
    assert np.count_nonzero(np.diff(np.sign(st.phi_b(shape, xn))) != 0) == 3


def test_b2_mode_shape_without_axial_force_has_beta_L_7_853(sp):
    # reference: brentq root of cos x cosh x = 1; without axial force beta1 = beta2
    shape = st.b2_mode_shape(sp, 0.0)
    bl = _beta_L_second_free_free()
    assert float(shape.beta1_per_m) * sp.length_m == pytest.approx(bl, rel=1e-9)
    assert float(shape.beta2_per_m) * sp.length_m == pytest.approx(bl, rel=1e-9)
    assert bl == pytest.approx(7.853, abs=5e-4)


def _ritz_b2_frequency(sp, P, EI, n=20):
    """Rayleigh-Ritz of the axially loaded free-free beam with odd Legendre trial functions."""
    L = sp.length_m
    rhoS = sp.density_kg_m3 * sp.width_m * sp.thickness_m
    N = -P
    xg, wg = npleg.leggauss(120)
    B, B1, B2 = [], [], []
    for k in range(n):
        c = np.zeros(2 * k + 2)
        c[-1] = 1.0  # P_{2k+1}: antisymmetric about the centre
        B.append(npleg.legval(xg, c))
        B1.append(npleg.legval(xg, npleg.legder(c)) * (2 / L))
        B2.append(npleg.legval(xg, npleg.legder(c, 2)) * (2 / L) ** 2)
    B, B1, B2 = (np.array(a) for a in (B, B1, B2))
    J = L / 2
    K = EI * (B2 * wg) @ B2.T * J + N * (B1 * wg) @ B1.T * J
    M = rhoS * (B * wg) @ B.T * J
    lam = eigh(K, M, eigvals_only=True)
    # antisymmetric family: rigid rotation (first), then B2
    assert lam[1] > 0 and lam[1] > lam[0]
    return np.sqrt(lam[1])


@pytest.mark.parametrize("k", range(6))
def test_b2_frequency_matches_rayleigh_ritz(motor, sp, k):
    # reference: independent Rayleigh-Ritz eigen solution (odd Legendre polynomials, scipy eigh)
    P = _loads(motor)[k]
    EI = float(st.effective_EI_N_m2(sp))
    w_ritz = _ritz_b2_frequency(sp, P, EI)
    assert float(st.b2_frequency_rad_s(sp, P)) == pytest.approx(w_ritz, rel=1e-5)
    assert float(st.b2_mode_shape(sp, P).omega_rad_s) == pytest.approx(w_ritz, rel=1e-5)


def test_compression_lowers_b2_frequency(sp):
    # reference: physics - compression softens bending, tension stiffens (monotone in P)
    P = np.array([-1e5, -3e4, -1e3, 0.0, 6.0, 1e3, 3e4, 1e5])
    w = st.b2_frequency_rad_s(sp, P)
    assert np.all(np.diff(w) < 0)
    # vectorised call equals scalar calls
    np.testing.assert_allclose(w, [float(st.b2_frequency_rad_s(sp, p)) for p in P], rtol=1e-12)


def test_modal_properties_consistent_with_eq12_13_definitions(sp):
    # reference: paper definitions w0 = sqrt(K/M), zeta = C/(2 M w0); M_l = rho S L/2, M_b = rho S L
    P = float(st.axial_force_N(sp, 0.0))
    mp_ = st.modal_properties(sp, P)
    rhoS = sp.density_kg_m3 * sp.width_m * sp.thickness_m
    assert mp_.M_l == pytest.approx(rhoS * sp.length_m / 2, rel=1e-12)
    assert mp_.M_b == pytest.approx(rhoS * sp.length_m, rel=1e-12)
    assert np.sqrt(mp_.K_l / mp_.M_l) == pytest.approx(2 * np.pi * sp.f_l0_Hz, rel=1e-12)
    assert np.sqrt(mp_.K_b / mp_.M_b) == pytest.approx(float(st.b2_frequency_rad_s(sp, P)), rel=1e-12)
    assert mp_.C_l / (2 * mp_.M_l * mp_.omega_l0) == pytest.approx(sp.zeta_l, rel=1e-12)
    assert mp_.C_b / (2 * mp_.M_b * mp_.omega_b0) == pytest.approx(sp.zeta_b, rel=1e-12)
    shape = st.b2_mode_shape(sp, P)
    assert float(mp_.eta_T) == pytest.approx(abs(float(st.phi_b(shape, sp.length_m))), rel=1e-12)
    # the L1 mode shape: phi_u(L) = -1 and int phi_u^2 = L/2 (Eq. 8)
    assert float(st.phi_u(sp.length_m, sp.length_m)) == pytest.approx(-1.0, abs=1e-15)
    val, _ = quad(lambda x: float(st.phi_u(x, sp.length_m)) ** 2, 0, sp.length_m)
    assert val == pytest.approx(sp.length_m / 2, rel=1e-12)


# ---------------------------------------------------------------------------
# Preload profile (Eq. 16) and excitation
# ---------------------------------------------------------------------------

def test_preload_is_alpha0_times_axial_force(sp):
    # reference: Eq. 16 F_p = alpha0 P(s), and P(s) = P0 + k_pre * Legendre series written here
    s = np.linspace(-0.021, 0.021, 43)
    P = st.axial_force_N(sp, s)
    np.testing.assert_allclose(st.preload_N(sp, s), sp.alpha0 * P, rtol=1e-14)
    xi = s / sp.bar_half_length_m
    dev = sp.bar_dev_1_m * xi + sp.bar_dev_2_m * (3 * xi ** 2 - 1) / 2 + sp.bar_dev_3_m * (5 * xi ** 3 - 3 * xi) / 2
    extra = [f.name for f in dataclasses.fields(sp) if f.name.endswith("_amp_m") and getattr(sp, f.name)]
    if not extra:  # only the Legendre deviation is active in the reference motor
        np.testing.assert_allclose(P, np.maximum(sp.P0_N + sp.preload_stiffness_N_per_m * dev, 0), rtol=1e-12)


def test_axial_force_is_never_tensile(sp):
    # reference: the preload spring can only push: P(s) >= 0 even for a huge bar deviation
    sp2 = dataclasses.replace(sp, bar_dev_1_m=1e-3)
    s = np.linspace(-0.025, 0.025, 51)
    P = st.axial_force_N(sp2, s)
    assert np.all(P >= 0)
    assert np.any(P == 0)


def test_position_independent_preload_when_bar_is_straight(sp):
    # reference: no bar deviation -> P(s) = P0 everywhere
    zero = {f.name: 0.0 for f in dataclasses.fields(sp) if f.name.startswith("bar_dev") or f.name.endswith("_amp_m")}
    sp0 = dataclasses.replace(sp, **zero)
    s = np.linspace(-0.02, 0.02, 11)
    np.testing.assert_allclose(st.axial_force_N(sp0, s), sp.P0_N, rtol=1e-15)


def test_excitation_reverses_b2_with_direction(sp):
    # reference: stator docstring - the channel reverses the B2 excitation (d = +/-1), L1 unchanged
    sp0 = dataclasses.replace(sp, asym_b=0.0)
    Fl_p, Fb_p = st.excitation_phasors(sp0, 324.0, +1)
    Fl_m, Fb_m = st.excitation_phasors(sp0, 324.0, -1)
    assert complex(Fl_p) == pytest.approx(complex(Fl_m), rel=1e-15)
    assert complex(Fb_m) == pytest.approx(-complex(Fb_p), rel=1e-15)
    assert abs(complex(Fl_p)) == pytest.approx(sp.A_l_N_per_V * 324.0, rel=1e-15)
    assert abs(complex(Fb_p)) == pytest.approx(sp.A_b_N_per_V * 324.0, rel=1e-15)


def test_tip_motion_phase_convention():
    # reference: x(t) = Im[X e^{jwt}]; delta = phase(tangential) - phase(normal) wrapped to (-pi, pi]
    Q_l = 2e-6 * np.exp(1j * 0.3)
    Q_b = 1e-6 * np.exp(1j * (0.3 - np.pi / 2))
    out = st.tip_motion(Q_l, Q_b, 0.8)
    assert out.U_l_m == pytest.approx(2e-6 * st.ETA_N, rel=1e-14)
    assert out.U_w_m == pytest.approx(0.8e-6, rel=1e-14)
    assert out.delta_rad == pytest.approx(-np.pi / 2, abs=1e-14)
    out2 = st.tip_motion(Q_l, 1e-6 * np.exp(1j * (0.3 + 3.0)), 1.0)
    assert out2.delta_rad == pytest.approx(3.0, abs=1e-14)
    out3 = st.tip_motion(Q_l, 1e-6 * np.exp(1j * (0.3 + 3.5)), 1.0)
    assert out3.delta_rad == pytest.approx(3.5 - 2 * np.pi, abs=1e-14)


def test_b2_frequency_near_b2_buckling_load(sp):
    # reference: the same Rayleigh-Ritz solution as above, at a compression close to the B2 stability limit
    P = 1.4e5
    w_ritz = _ritz_b2_frequency(sp, P, float(st.effective_EI_N_m2(sp)))
    assert float(st.b2_frequency_rad_s(sp, P)) == pytest.approx(w_ritz, rel=1e-3)


# ---------------------------------------------------------------------------
# Scalar fast paths (the per-step calls of the stator block) equal the numpy paths
# ---------------------------------------------------------------------------

def _one(x):
    return np.array([x], dtype=complex if isinstance(x, complex) else float)


@pytest.mark.parametrize("drift", [False, True])
def test_scalar_fast_paths_equal_vector_paths(sp, drift):
    # reference: the same functions called with one-element arrays (numpy code paths)
    if drift:  # thermal drift, self-heating, bar waviness and bump switched on
        sp = dataclasses.replace(sp, df_dT_b_Hz_per_K=-4.0, df_dT_l_Hz_per_K=-3.0, thermal_tau_s=20.0,
                                 heating_K_per_V2=1e-4, bar_wave_amp_m=2e-6, bar_bump_amp_m=3e-6,
                                 bar_bump_center_m=0.004)
    for s in (-0.02, -0.003, 0.0, 0.0071, 0.019):
        assert st.axial_force_N(sp, s) == pytest.approx(st.axial_force_N(sp, _one(s))[0], rel=1e-14)
    for P in (-3e4, -10.0, 0.0, 5.6, 6.35, 40.0, 3e4):
        for T in (None, 10.0, 25.0, 70.0):
            fast = st.modal_properties(sp, P, T)
            vec = st.modal_properties(sp, _one(P), None if T is None else _one(T))
            assert all(isinstance(x, float) for x in fast)
            for f in fast._fields:  # eta_T: closed-form vs 64-point Gauss-Legendre normalisation
                assert getattr(fast, f) == pytest.approx(float(np.ravel(getattr(vec, f))[0]), rel=1e-12), (P, T, f)
    for V0, d in ((324.0, 1.0), (120.0, -1.0)):
        for a, b in zip(st.excitation_phasors(sp, V0, d, 0.3), st.excitation_phasors(sp, _one(V0), _one(d), 0.3)):
            assert a == pytest.approx(b[0], rel=1e-15)
    assert st.stator_temperature_step(30.0, 25.0, 324.0, sp, 1e-3) == pytest.approx(
        np.ravel(st.stator_temperature_step(_one(30.0), _one(25.0), 324.0, sp, 1e-3))[0], rel=1e-15)
    props = st.modal_properties(sp, 6.0, 25.0)
    for Q, F, Y in ((1e-6 + 2e-7j, 40.0 + 3j, 1e5 + 2e5j), (0j, 40.0 + 0j, 0.0), (3e-6 - 1e-6j, -5j, -2e4 + 1e3j)):
        args = (2 * np.pi * 48500.0, props.M_b, props.K_b, props.C_b, 2e-4)
        assert st.envelope_step(Q, F, Y, *args) == pytest.approx(st.envelope_step(_one(Q), F, Y, *args)[0],
                                                                 rel=1e-13, abs=1e-22)
        fast, vec = st.tip_motion(Q + 1e-7, F * 1e-8, props.eta_T), st.tip_motion(_one(Q + 1e-7), F * 1e-8, props.eta_T)
        for a, b in zip(fast, vec):
            assert a == pytest.approx(float(np.ravel(b)[0]), rel=1e-15, abs=1e-300)


# ---------------------------------------------------------------------------
# ModalTable: the stator block's per-step modal properties (interpolated in P) equal the exact ones
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("drift", [False, True])
def test_modal_table_equals_modal_properties(sp, drift):
    if drift:  # B2 drifts with the temperature: one table per temperature
        sp = dataclasses.replace(sp, df_dT_b_Hz_per_K=-4.0, df_dT_l_Hz_per_K=-3.0)
    rng = np.random.default_rng(1)
    T = 40.0
    table = st.ModalTable(sp, T if drift else None)
    # over the reference motor's forces and far beyond, across cell edges, and a node exactly
    forces = np.concatenate([rng.uniform(0.0, 60.0, 400), np.arange(0.0, 61.0, 1.0), [5.6, 6.35, 1e-9]])
    worst = 0.0
    for P in forces:
        got = table(float(P), T)
        exact = st.modal_properties(sp, float(P), T)
        for f in got._fields:
            a, b = getattr(got, f), getattr(exact, f)
            assert isinstance(a, float)
            worst = max(worst, abs(a / b - 1))
    assert worst < 2e-14  # round-off (TABLE_DEGREE over TABLE_CELL_N newtons)
    assert st.modal_table(sp, T) is st.modal_table(sp, T)  # shared per parameters (and B2 temperature)


def test_modal_table_falls_back_beyond_buckling(sp):
    table = st.ModalTable(sp)
    P = 3e5  # beyond the B2 stability limit: the cell is not tabulated, the exact path answers
    got, exact = table(P, 25.0), st.modal_properties(sp, P, 25.0)
    assert table.cells[int(P // st.TABLE_CELL_N)] is None
    for a, b in zip(got, exact):
        assert (np.isnan(a) and np.isnan(b)) or a == b


@pytest.mark.parametrize("thermal", [False, True])
def test_stator_block_step_equals_physics_functions(motor, thermal):
    # the block writes excitation, envelope step and temperature step out in plain floats
    from l1b2.cosim.blocks import StatorBlock
    sp = motor.stator
    if thermal:
        sp = dataclasses.replace(sp, thermal_tau_s=20.0, heating_K_per_V2=1e-4, df_dT_b_Hz_per_K=-4.0)
    b = StatorBlock(sp)
    b.V0, b.omega, b.direction, b.s, b.T = 300.0, 2 * np.pi * 48500.0, -1.0, 0.004, 25.0
    b.initialize()
    for k in range(40):
        # reference: the same step through the physics functions
        props = b._props
        Q_l, Q_b = complex(b.Q_l_re, b.Q_l_im), complex(b.Q_b_re, b.Q_b_im)
        b.F_N1_sin, b.F_N1_cos, b.F_T1_sin, b.F_T1_cos = (0.0, 0.0, 0.0, 0.0) if k == 0 else (5.8, 0.3, -0.4, 1.2)
        rot = np.exp(1j * b.phase_l)
        F1_N = complex(b.F_N1_sin, b.F_N1_cos) * rot
        F1_T = complex(b.F_T1_sin, b.F_T1_cos) * rot
        F_l, F_b = st.excitation_phasors(sp, b.V0, b.direction)
        big_l, big_b = abs(Q_l) > 1e-15, abs(Q_b) > 1e-15
        Y_l = st.ETA_N * F1_N / Q_l if big_l else 0.0
        Y_b = props.eta_T * F1_T / Q_b if big_b else 0.0
        F_l = F_l if big_l else F_l - st.ETA_N * F1_N
        F_b = F_b if big_b else F_b - props.eta_T * F1_T
        w = b.omega
        Q_l = st.envelope_step(Q_l, F_l, Y_l, w, props.M_l, props.K_l, props.C_l, 2e-4)
        Q_b = st.envelope_step(Q_b, F_b, Y_b, w, props.M_b, props.K_b, props.C_b, 2e-4)
        T_st = st.stator_temperature_step(b.T_st, b.T, b.V0, sp, 2e-4)
        b.do_step(k * 2e-4, 2e-4)
        assert complex(b.Q_l_re, b.Q_l_im) == pytest.approx(Q_l, rel=1e-13)
        assert complex(b.Q_b_re, b.Q_b_im) == pytest.approx(Q_b, rel=1e-13)
        assert b.T_st == pytest.approx(T_st, rel=1e-15)
        tip = st.tip_motion(Q_l, Q_b, b._props.eta_T)
        assert (b.U_l, b.U_w) == pytest.approx((tip.U_l_m, tip.U_w_m), rel=1e-13)
        assert b.delta == pytest.approx(tip.delta_rad, rel=1e-12)
        exact = st.modal_properties(sp, st.axial_force_N(sp, b.s), b.T_st)
        assert b.eta_T == pytest.approx(exact.eta_T, rel=1e-13)


def test_compiled_envelope_step_equals_the_python_one(motor):
    # the stator's per-step update compiled by numba against the same function in Python, for modes at rest
    # (force moved into the excitation), ringing up and loaded by the interface; 1e-13 relative
    from l1b2.physics.jit import jit_status
    kern = st.compiled_envelope_step()
    if kern is None:
        pytest.skip(f"numba kernel not available: {jit_status()}")
    props = st.modal_properties(motor.stator, 70.0)
    rng = np.random.default_rng(5)
    for i in range(2000):
        Q = [0.0] * 4 if i % 10 == 0 else list(rng.normal(0.0, 1e-6, 4))
        args = (*Q, rng.uniform(-np.pi, np.pi), *rng.normal(0.0, 20.0, 4), rng.uniform(0.0, 30.0),
                rng.uniform(-30.0, 30.0), props.eta_T, 2 * np.pi * rng.uniform(45e3, 52e3), props.M_l, props.K_l,
                props.C_l, props.M_b, props.K_b, props.C_b, float(rng.choice([2e-5, 2e-4, 1e-3])),
                props.eta_T * rng.uniform(0.9, 1.1))
        py, jt = st.coupled_envelope_step(*args), kern(*args)
        scale = max(abs(x) for x in py[:6]) + 1e-300
        for k, (a, b) in enumerate(zip(py, jt)):
            tol = 1e-13 * scale if k < 6 else 1e-12  # phasors and amplitudes [m]; phases [rad]
            assert abs(a - b) <= tol or (k >= 6 and abs(abs(a - b) - 2 * np.pi) <= 1e-12), (k, args, a, b)
