"""Friction interface (paper Sect. 3.3, Eq. 17-20, 23): l1b2.physics.interface."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from l1b2.physics import interface as itf
from l1b2.physics.params import InterfaceParams
from scipy.optimize import brentq

W = 2 * np.pi * 48500.0  # drive angular frequency [rad/s]
FIELDS = ("F_d_N", "F_N_mean_N", "F_N1_sin_N", "F_N1_cos_N", "F_T1_sin_N", "F_T1_cos_N", "phi_c_rad",
          "stick_fraction")


@pytest.fixture(scope="module")
def ip():
    # fixed interface parameters for these unit tests (independent of the reference-motor tuning):
    # a compliant contact layer (long contact, reversals inside it) and Coulomb-dominated slip
    return InterfaceParams(k_e_N_per_m=3.0e7, mu_p=0.25, sigma_N_s_per_m=3.0, u_m_m=20e-9)


# ---------------------------------------------------------------------------
# Eq. 17-18: normal force and contact angle
# ---------------------------------------------------------------------------

def _period_mean(f, n=2 ** 16):
    th = (np.arange(n) + 0.5) * (2 * np.pi / n)
    return np.mean(f(th))


@pytest.mark.parametrize("U_l", [0.05e-6, 0.15e-6, 0.2e-6, 0.25e-6, 0.5e-6, 1.22e-6, 3e-6, 20e-6])
@pytest.mark.parametrize("F_p", [2.0, 5.6])
def test_eq18_makes_period_mean_of_eq17_equal_Fp(ip, U_l, F_p):
    # reference: numerical period mean (midpoint rule, 65536 points) of normal_force_N
    k_e = ip.k_e_N_per_m
    mean = _period_mean(lambda th: itf.normal_force_N(th, U_l, F_p, k_e))
    assert mean == pytest.approx(F_p, rel=1e-6)
    F = itf.normal_force_N(np.linspace(0, 2 * np.pi, 5001), U_l, F_p, k_e)
    assert np.all(F >= -1e-12 * F_p)  # the bar only pushes
    a = float(itf.contact_half_angle_rad(U_l, F_p, k_e))
    if k_e * U_l <= F_p:  # permanent contact: F_N = F_p + k_e U_l sin(theta), phi_c = 2 pi
        assert a == pytest.approx(np.pi, abs=1e-15)
        th = np.linspace(0, 2 * np.pi, 101)
        np.testing.assert_allclose(itf.normal_force_N(th, U_l, F_p, k_e), F_p + k_e * U_l * np.sin(th),
                                   rtol=1e-12, atol=1e-12 * F_p)
    else:  # intermittent: zero outside the window centred on pi/2, continuous (zero) at its edges
        assert 0 < a < np.pi
        outside = np.pi / 2 + a + np.linspace(1e-9, 2 * np.pi - 2 * a - 1e-9, 200)
        assert np.all(itf.normal_force_N(outside, U_l, F_p, k_e) == 0.0)
        for edge in (np.pi / 2 - a, np.pi / 2 + a):
            assert abs(float(itf.normal_force_N(edge, U_l, F_p, k_e))) < 1e-9 * k_e * U_l
        assert float(itf.normal_force_N(np.pi / 2, U_l, F_p, k_e)) == pytest.approx(k_e * U_l * (1 - np.cos(a)),
                                                                                   rel=1e-12)
        # mean_normal_force_N is the closed form of the same mean
        assert float(itf.mean_normal_force_N(U_l, a, k_e)) == pytest.approx(F_p, rel=1e-12)


@pytest.mark.parametrize("F_p", [1.0, 5.6])
def test_normal_force_is_continuous_at_permanent_contact_boundary(ip, F_p):
    # reference: both branches of Eq. 17 must agree at k_e U_l = F_p (a -> pi)
    k_e = ip.k_e_N_per_m
    U0 = F_p / k_e
    th = np.linspace(0, 2 * np.pi, 721)
    below = itf.normal_force_N(th, U0 * (1 - 1e-9), F_p, k_e)  # permanent contact
    above = itf.normal_force_N(th, U0 * (1 + 1e-9), F_p, k_e)  # intermittent, a just below pi
    at = itf.normal_force_N(th, U0, F_p, k_e)
    np.testing.assert_allclose(above, below, atol=1e-6 * F_p)
    np.testing.assert_allclose(at, below, atol=1e-6 * F_p)


def _r_grid():
    tiny = np.logspace(-12, 0, 150)
    return np.unique(np.concatenate([np.pi * tiny, np.pi * (1 - tiny), np.linspace(0.01, np.pi - 0.01, 300)]))


def test_contact_half_angle_solves_eq18_over_whole_range(ip):
    # reference: residual of Eq. 18, g(a) = sin a - a cos a = pi F_p / (k_e U_l), for r in (0, pi)
    k_e, F_p = ip.k_e_N_per_m, 5.0
    r = _r_grid()
    r = r[(r > 0) & (r < np.pi)]
    U = np.pi * F_p / (k_e * r)
    a_vec = itf.contact_half_angle_rad(U, F_p, k_e)
    a_sca = np.array([float(itf.contact_half_angle_rad(float(u), F_p, k_e)) for u in U])
    for a in (a_vec, a_sca):
        assert np.all((a > 0) & (a <= np.pi))
        resid = np.sin(a) - a * np.cos(a) - r
        assert np.max(np.abs(resid)) < 1e-12
    order = np.argsort(r)  # g is increasing, so a(r) is monotone
    assert np.all(np.diff(a_vec[order]) >= -1e-15)
    assert np.all(np.diff(a_sca[order]) >= -1e-15)
    # (near a -> 0 the absolute stopping test |g| <= 4e-16 pi leaves a relative error ~1e-6 in a)
    np.testing.assert_allclose(a_vec, a_sca, rtol=1e-5, atol=1e-12)
    # against an independent brentq solve on a few points
    for ri in (1e-6, 0.3, 1.5, 3.0, np.pi - 1e-6):
        ref = brentq(lambda x: np.sin(x) - x * np.cos(x) - ri, 0, np.pi, xtol=1e-15)
        assert float(itf.contact_half_angle_rad(np.pi * F_p / (k_e * ri), F_p, k_e)) == pytest.approx(ref, abs=1e-9)


def test_contact_half_angle_limits(ip):
    # reference: Eq. 18 regimes - permanent contact (k_e U_l <= F_p) gives pi, no preload gives 0
    k_e = ip.k_e_N_per_m
    assert float(itf.contact_half_angle_rad(1e-7, 5.0, k_e)) == pytest.approx(np.pi)      # k_e U = 3 N < 5 N
    assert float(itf.contact_half_angle_rad(5.0 / k_e, 5.0, k_e)) == pytest.approx(np.pi)  # boundary
    assert float(itf.contact_half_angle_rad(1e-6, 0.0, k_e)) == 0.0
    np.testing.assert_allclose(itf.contact_half_angle_rad(np.array([1e-7, 1e-6, 1e-5]), np.array([5.0, 0.0, 5.0]), k_e)[:2],
                               [np.pi, 0.0])
    # increasing amplitude at fixed preload shortens the contact: a decreasing in U_l
    U = np.logspace(np.log10(5.0 / k_e), -4, 50)
    assert np.all(np.diff(itf.contact_half_angle_rad(U, 5.0, k_e)) < 0)


# ---------------------------------------------------------------------------
# Pure slip: closed form at phi_c = pi (docs/explanation/physics.md) and Eq. 23
# ---------------------------------------------------------------------------

def _pure_slip_reference(U_w, v, F_p, sigma, mu):
    """Independent closed form of the pure-slip period means for every v (derived here).

    F_f = sigma (u sin th - v) + mu pi F_p sin th sign(u sin th - v) on [0, pi], 0 elsewhere.
    Mean: sigma (u/pi - v/2) + mu F_p C(k), C = 2 sqrt(1-k^2) - 1 for 0 <= k < 1, +1 for k < 0, -1 for k >= 1.
    Fundamental: sigma (u/2 - 2v/pi) + mu F_p S(k), S = pi/2 - 2 th1 + sin 2 th1 (0 <= k < 1),
    pi/2 for k < 0, -pi/2 for k >= 1, th1 = arcsin k.
    """
    u = W * U_w
    k = v / u
    if k < 0:
        C, S = 1.0, np.pi / 2
    elif k >= 1:
        C, S = -1.0, -np.pi / 2
    else:
        th1 = np.arcsin(k)
        C, S = 2 * np.sqrt(1 - k * k) - 1, np.pi / 2 - 2 * th1 + np.sin(2 * th1)
    return sigma * (u / np.pi - v / 2) + mu * F_p * C, sigma * (u / 2 - 2 * v / np.pi) + mu * F_p * S


V_ALL = [-0.6, -0.3, -0.1, -0.01, 0.0, 0.05, 0.2, 0.3, 0.4, 0.45, 0.6, 1.0]  # w U_w = 0.427 m/s
V_NONNEG = [v for v in V_ALL if v >= 0]
V_NEG = [-0.3, -0.1]  # where the two closed forms below go wrong by more than the tolerance


@pytest.mark.parametrize("v", V_ALL)
def test_pure_slip_numerics_equal_independent_closed_form(ip, v):
    # reference: piecewise closed form derived in this test (including v < 0 and v > w U_w)
    U_w, F_p = 1.4e-6, 5.6
    out = itf.interface_forces(1.2e-6, U_w, -np.pi / 2, W, v, F_p, ip, mode="pure_slip")
    Fd, F1 = _pure_slip_reference(U_w, v, F_p, ip.sigma_N_s_per_m, ip.mu_p)
    scale = ip.mu_p * F_p + ip.sigma_N_s_per_m * W * U_w
    assert out.F_d_N == pytest.approx(Fd, rel=5e-3, abs=1e-4 * scale)
    assert out.F_T1_sin_N == pytest.approx(F1, rel=5e-3, abs=1e-4 * scale)
    assert out.F_T1_cos_N == pytest.approx(0.0, abs=1e-4 * scale)  # symmetric about pi/2
    assert out.F_N_mean_N == pytest.approx(F_p, rel=1e-4)  # midpoint rule: O(h^2) = 6e-6 at n_theta = 256
    assert out.phi_c_rad == pytest.approx(np.pi)
    assert out.stick_fraction == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("v", V_NONNEG)
def test_pure_slip_numerics_equal_physics_notes_closed_form(ip, v):
    # reference: closed form of docs/explanation/physics.md (pure_slip_drive_force_N) at phi_c = pi, within 0.5 %
    U_w, F_p = 1.4e-6, 5.6
    out = itf.interface_forces(1.2e-6, U_w, -np.pi / 2, W, v, F_p, ip, mode="pure_slip")
    closed = float(itf.pure_slip_drive_force_N(U_w, W, v, F_p, ip.sigma_N_s_per_m, ip.mu_p))
    scale = ip.mu_p * F_p + ip.sigma_N_s_per_m * W * U_w
    assert out.F_d_N == pytest.approx(closed, rel=5e-3, abs=1e-4 * scale)


@pytest.mark.parametrize("v", V_NEG)
def test_pure_slip_closed_form_for_negative_speed(ip, v):
    # reference: numerical period average (and the independent piecewise closed form) for v < 0
    U_w, F_p = 1.4e-6, 5.6
    out = itf.interface_forces(1.2e-6, U_w, -np.pi / 2, W, v, F_p, ip, mode="pure_slip")
    closed = float(itf.pure_slip_drive_force_N(U_w, W, v, F_p, ip.sigma_N_s_per_m, ip.mu_p))
    assert closed == pytest.approx(out.F_d_N, rel=5e-3)


@pytest.mark.parametrize("v", [v for v in V_NONNEG if v < W * 1.4e-6] + [0.6, 1.0])
def test_eq23_is_the_fundamental_of_the_pure_slip_force(ip, v):
    # reference: numerical sin(theta) component of the period force (F_T1_sin) vs Eq. 23
    U_w, F_p = 1.4e-6, 5.6
    out = itf.interface_forces(1.2e-6, U_w, -np.pi / 2, W, v, F_p, ip, mode="pure_slip", n_theta=1024)
    eq23 = float(itf.pure_slip_fundamental_N(U_w, W, v, F_p, ip.sigma_N_s_per_m, ip.mu_p))
    assert out.F_T1_sin_N == pytest.approx(eq23, rel=1e-3, abs=1e-6)


@pytest.mark.parametrize("v", [-0.6] + V_NEG)
def test_eq23_for_negative_speed(ip, v):
    # reference: numerical fundamental of the pure-slip force for v < 0
    U_w, F_p = 1.4e-6, 5.6
    out = itf.interface_forces(1.2e-6, U_w, -np.pi / 2, W, v, F_p, ip, mode="pure_slip", n_theta=1024)
    eq23 = float(itf.pure_slip_fundamental_N(U_w, W, v, F_p, ip.sigma_N_s_per_m, ip.mu_p))
    assert out.F_T1_sin_N == pytest.approx(eq23, rel=1e-3)


def test_stick_slip_tends_to_slip_as_u_m_tends_to_zero(ip):
    # reference: (i) monotone convergence of F_d and the stick fraction as u_m -> 0, at the rate
    # u_m^(1/2) expected from the stick after a reversal (u_r grows quadratically there), (ii) the
    # limit equals the brute-force period average with no stick and the same (Eq. 18) contact angle
    args = (1.22e-6, 1.41e-6, -1.69, W, 0.2, 5.6)
    n = 16384
    limit = itf.interface_forces(*args, dataclasses.replace(ip, u_m_m=0.0), n_theta=n)
    u_ms = np.array([1e-8, 1e-9, 1e-10, 1e-11, 1e-12])
    diffs, sticks = [], []
    for u_m in u_ms:
        out = itf.interface_forces(*args, dataclasses.replace(ip, u_m_m=u_m), n_theta=n)
        diffs.append(abs(out.F_d_N - limit.F_d_N))
        sticks.append(out.stick_fraction)
    diffs, sticks = np.array(diffs), np.array(sticks)
    assert np.all(np.diff(diffs) < 0)
    assert np.all(np.diff(sticks) < 0)
    assert diffs[-1] < 1e-3 * abs(limit.F_d_N)
    assert sticks[-1] < 1e-3
    slope = np.polyfit(np.log(u_ms), np.log(diffs), 1)[0]
    assert 0.35 < slope < 0.75
    assert limit.stick_fraction == 0.0
    bf = _brute_force(*args, dataclasses.replace(ip, u_m_m=0.0))
    assert limit.F_d_N == pytest.approx(bf["F_d_N"], rel=1e-3)
    assert limit.F_T1_sin_N == pytest.approx(bf["F_T1_sin_N"], rel=1e-3)


# ---------------------------------------------------------------------------
# Independent brute-force time stepping of Eq. 17-20 with the u_r rule
# ---------------------------------------------------------------------------

def _brute_force(U_l, U_w, delta, omega, v, F_p, ip, n=2 ** 15, periods=3):
    """Explicit time stepping over several periods; averages over the last one.

    u_r accumulates (w' - v) dt and is reset at the start of every contact interval and
    whenever the relative velocity changes sign while in contact (module docstring rule).
    """
    k_e, mu, sig, um = ip.k_e_N_per_m, ip.mu_p, ip.sigma_N_s_per_m, ip.u_m_m
    permanent = k_e * U_l <= F_p
    if not permanent:
        a = brentq(lambda x: math.sin(x) - x * math.cos(x) - math.pi * F_p / (k_e * U_l), 0.0, math.pi, xtol=1e-15)
        ca = math.cos(a)
    dth = 2 * math.pi / n
    dt = dth / omega
    acc = np.zeros(6)
    n_contact = n_stick = 0
    u_r, prev_contact, prev_sign = 0.0, False, 0
    for k in range(n * periods):
        th = (k + 0.5) * dth
        if permanent:
            FN = F_p + k_e * U_l * math.sin(th)
        else:
            d = abs((th - math.pi / 2 + math.pi) % (2 * math.pi) - math.pi)
            FN = k_e * U_l * (math.sin(th) - ca) if d <= a else 0.0
        rv = omega * U_w * math.cos(th + delta) - v
        sg = (rv > 0) - (rv < 0)
        contact = FN > 0
        if contact and (not prev_contact or sg != prev_sign):
            u_r = 0.0
        u_r += rv * dt
        stick = False
        if not contact:
            Ff = 0.0
        elif um > 0 and abs(u_r) <= um:
            Ff, stick = sg * mu * abs(u_r) / um * FN, True
        else:
            Ff = sig * rv + sg * mu * FN
        prev_contact, prev_sign = contact, sg
        if k >= n * (periods - 1):
            s, c = math.sin(th), math.cos(th)
            acc += np.array([Ff, FN, FN * s, FN * c, Ff * s, Ff * c]) * dth
            n_contact += contact
            n_stick += stick
    out = acc / np.array([2 * math.pi, 2 * math.pi, math.pi, math.pi, math.pi, math.pi])
    return dict(zip(FIELDS[:6], out), stick_fraction=n_stick / max(n_contact, 1))


CASES = {
    "reference": (1.22e-6, 1.41e-6, -1.69, W, 0.264, 5.6, None),
    "slider_at_rest": (1.22e-6, 1.41e-6, -1.69, W, 0.0, 5.6, None),
    "slider_backward": (1.22e-6, 1.41e-6, -1.69, W, -0.1, 5.6, None),
    "skewed_ellipse": (1.0e-6, 1.2e-6, -np.pi / 2 + 0.5, W, 0.1, 5.0, None),
    "reverse_drive": (1.0e-6, 1.2e-6, 1.2, W, -0.2, 5.0, None),
    "permanent_contact": (0.1e-6, 1.4e-6, -np.pi / 2, W, 0.2, 5.6, None),
    "permanent_no_reversal": (0.1e-6, 1.4e-6, -np.pi / 2, W, 0.5, 5.6, None),
    "no_reversal_in_contact": (1.22e-6, 1.41e-6, -1.69, W, 0.5, 5.6, None),
    "long_stick": (1.22e-6, 1.41e-6, -1.69, W, 0.2, 5.6, 200e-9),
}


def _case(ip, name):
    *args, u_m = CASES[name]
    return args, (ip if u_m is None else dataclasses.replace(ip, u_m_m=u_m))


@pytest.mark.parametrize("name", list(CASES))
def test_interface_forces_match_brute_force_time_stepping(ip, name):
    # reference: independent explicit time stepping of Eq. 17-20 with the documented u_r rule
    args, p = _case(ip, name)
    bf = _brute_force(*args, p)
    out = itf.interface_forces(*args, p, n_theta=1024)  # discretisation: see the n_theta tests below
    scale = p.mu_p * args[5] + p.sigma_N_s_per_m * args[3] * args[1]
    for f in FIELDS[:6]:
        assert getattr(out, f) == pytest.approx(bf[f], rel=1e-3, abs=1e-3 * scale), f
    assert out.stick_fraction == pytest.approx(bf["stick_fraction"], abs=2e-3)
    assert out.F_N_mean_N == pytest.approx(args[5], rel=1e-4)
    a_expected = np.pi if CASES[name][0] * p.k_e_N_per_m <= args[5] else float(
        itf.contact_half_angle_rad(args[0], args[5], p.k_e_N_per_m))
    assert out.phi_c_rad == pytest.approx(2 * a_expected, rel=1e-12)


def test_friction_drives_the_slider_in_the_tip_direction(ip):
    # reference: physics - with the ideal ellipse (delta = -pi/2) a resting slider is pushed toward +,
    # with delta = +pi/2 toward -; the two are mirror images
    fwd = itf.interface_forces(1.22e-6, 1.41e-6, -np.pi / 2, W, 0.0, 5.6, ip)
    bwd = itf.interface_forces(1.22e-6, 1.41e-6, +np.pi / 2, W, 0.0, 5.6, ip)
    assert fwd.F_d_N > 0
    assert bwd.F_d_N == pytest.approx(-fwd.F_d_N, rel=1e-6)
    # and the driving force decreases as the slider speeds up
    v = np.linspace(0.0, 0.6, 13)
    Fd = itf.interface_forces(1.22e-6, 1.41e-6, -np.pi / 2, W, v, 5.6, ip).F_d_N
    assert np.all(np.diff(Fd) < 0)


# ---------------------------------------------------------------------------
# Numerics: convergence in n_theta, vectorisation
# ---------------------------------------------------------------------------

NS = [32, 64, 128, 256, 512, 1024, 2048, 4096]


@pytest.mark.parametrize("name", ["reference", "skewed_ellipse", "permanent_contact"])
def test_stick_slip_converges_in_n_theta(ip, name):
    # reference: a fine solution (n_theta = 65536); error bound of first order, O(h): at most a
    # fraction of one cell's Coulomb force per event (reset at a reversal / stick end).
    # (n_theta is the resolution of the numerical reference kernel; interface_forces is exact.)
    args, p = _case(ip, name)
    ref = itf.interface_forces_reference(*args, p, n_theta=2 ** 16)
    scale = p.mu_p * args[5] + p.sigma_N_s_per_m * args[3] * args[1]
    errs = []
    for n in NS:
        out = itf.interface_forces_reference(*args, p, n_theta=n)
        errs.append(max(abs(getattr(out, f) - getattr(ref, f)) for f in FIELDS[:6]) / scale)
    errs = np.array(errs)
    assert np.all(errs * np.array(NS) < 1.0), errs
    assert errs[-1] < 3e-4
    assert errs[-1] < errs[0] / 10


@pytest.mark.parametrize("delta", [-np.pi / 2, -1.9])
def test_pure_slip_converges_in_n_theta_at_second_order(ip, delta):
    # reference: fine solution; second order in the cell size (cells aligned with the sign reversals)
    args = (1.22e-6, 1.41e-6, delta, W, 0.2, 5.6)
    ref = itf.interface_forces_reference(*args, ip, mode="pure_slip", n_theta=2 ** 16)
    scale = ip.mu_p * args[5] + ip.sigma_N_s_per_m * W * args[1]
    errs = np.array([max(abs(getattr(itf.interface_forces_reference(*args, ip, mode="pure_slip", n_theta=n), f)
                             - getattr(ref, f)) for f in FIELDS[:6]) / scale for n in NS])
    order = np.log2(errs[:-1] / errs[1:])
    assert np.all(order > 1.8), (errs, order)
    assert errs[-1] < 1e-6


def test_vectorised_call_equals_loop_of_scalar_calls(ip):
    # reference: scalar calls (scalar fast path) one by one
    rows = [c[:6] for c in CASES.values()]
    cols = [np.array(c) for c in zip(*rows)]
    vec = itf.interface_forces(*cols, ip)
    for i, r in enumerate(rows):
        sca = itf.interface_forces(*r, ip)
        for f in FIELDS:
            assert getattr(vec, f)[i] == pytest.approx(getattr(sca, f), rel=1e-9, abs=1e-12), f
    # 2-D broadcasting keeps the shape
    U_l = np.array([[0.8e-6], [1.2e-6]])
    v = np.array([0.0, 0.1, 0.2])
    out = itf.interface_forces(U_l, 1.4e-6, -1.69, W, v, 5.6, ip)
    assert out.F_d_N.shape == (2, 3)
    assert out.F_d_N[1, 2] == pytest.approx(itf.interface_forces(1.2e-6, 1.4e-6, -1.69, W, 0.2, 5.6, ip).F_d_N,
                                            rel=1e-9)


def test_unknown_mode_is_refused(ip):
    # reference: documented modes only
    with pytest.raises(ValueError, match="mode"):
        itf.interface_forces(1e-6, 1e-6, -np.pi / 2, W, 0.0, 5.0, ip, mode="coulomb")


# ---------------------------------------------------------------------------
# Closed-form kernel: exact period averages against the numerical kernel and an
# independent adaptive quadrature; continuity; steady speeds unchanged
# ---------------------------------------------------------------------------

def _piecewise_quad_reference(U_l, U_w, delta, omega, v, F_p, ip, mode="stick_slip"):
    """Independent period averages of Eq. 17-20: breakpoints by root finding, pieces by adaptive quadrature.

    The contact window comes from Eq. 18 (brentq), the relative-velocity reversals from sign
    changes of w' - v on a grid refined by brentq, the stick end from brentq on |u_r| - u_m with
    u_r the integral of (w' - v) dt since the latest reset; every smooth piece is integrated by
    scipy's adaptive Gauss-Kronrod rule.
    """
    from scipy.integrate import quad
    k_e, mu, sig = ip.k_e_N_per_m, ip.mu_p, ip.sigma_N_s_per_m
    um = 0.0 if mode == "pure_slip" else ip.u_m_m
    rv = lambda th: omega * U_w * math.cos(th + delta) - v  # noqa: E731
    permanent = mode != "pure_slip" and k_e * U_l <= F_p
    if mode == "pure_slip":
        FN, start, width, a = (lambda th: math.pi * F_p * math.sin(th)), 0.0, math.pi, math.pi / 2
    elif permanent:
        FN, width, a = (lambda th: F_p + k_e * U_l * math.sin(th)), 2 * math.pi, math.pi
    else:
        a = brentq(lambda x: math.sin(x) - x * math.cos(x) - math.pi * F_p / (k_e * U_l), 0.0, math.pi, xtol=1e-15)
        FN, start, width = (lambda th: k_e * U_l * (math.sin(th) - math.cos(a))), math.pi / 2 - a, 2 * a
    grid = 0.1234567 + np.linspace(0.0, 2 * math.pi, 4001)  # offset: no reversal on a grid point
    vals = np.array([rv(t) for t in grid])
    revs = [brentq(rv, grid[i], grid[i + 1], xtol=1e-15) for i in np.flatnonzero(vals[:-1] * vals[1:] < 0)]
    if permanent:  # the window starts at a reset (a reversal, or anywhere when the contact slides)
        start = revs[0] if revs else 0.0
    cuts = sorted({start} | {start + (r - start) % (2 * math.pi) for r in revs} | {start + width})
    cuts = [c for c in cuts if c <= start + width]
    acc, stick_len = np.zeros(6), 0.0
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        sg = math.copysign(1.0, rv(0.5 * (lo + hi)))
        u_r = lambda th, lo=lo: (U_w * (math.sin(th + delta) - math.sin(lo + delta))  # noqa: E731
                                 - v * (th - lo) / omega)
        sw = lo
        if um > 0 and (revs or not permanent):
            sw = hi if abs(u_r(hi)) <= um else brentq(lambda th: abs(u_r(th)) - um, lo, hi, xtol=1e-15)
        stick_len += sw - lo
        for p, q, Ff in ((lo, sw, lambda th: mu * u_r(th) / um * FN(th)),
                         (sw, hi, lambda th: sig * rv(th) + sg * mu * FN(th))):
            if q > p:
                for j, f in enumerate((Ff, FN)):
                    for w, wf in enumerate((lambda th: 1.0, math.sin, math.cos)):
                        acc[3 * j + w] += quad(lambda th: f(th) * wf(th), p, q, epsabs=1e-12, epsrel=1e-12,
                                               limit=200)[0]
    return dict(F_d_N=acc[0] / (2 * math.pi), F_N_mean_N=acc[3] / (2 * math.pi), F_N1_sin_N=acc[4] / math.pi,
                F_N1_cos_N=acc[5] / math.pi, F_T1_sin_N=acc[1] / math.pi, F_T1_cos_N=acc[2] / math.pi,
                phi_c_rad=2 * a, stick_fraction=stick_len / width)


#: regimes of the closed-form tests: contact geometry x u_m; speeds are scaled by the tip speed w U_w
REGIMES = {
    "partial_contact": (1.22e-6, 1.41e-6, -1.69, 5.6),
    "partial_skewed": (1.0e-6, 1.2e-6, -np.pi / 2 + 0.5, 5.0),
    "partial_reverse_drive": (1.0e-6, 1.2e-6, 1.2, 5.0),
    "permanent_contact": (0.1e-6, 1.4e-6, -np.pi / 2, 5.6),
    "permanent_skewed": (0.15e-6, 1.0e-6, -1.2, 5.6),
}
V_OVER_TIP = [-1.3, -0.4, 0.0, 0.3, 0.62, 0.95, 1.2]  # v / (w U_w): backward, forward, beyond the tip speed
U_M = {"slip_dominated": 0.5e-9, "reference_u_m": 20e-9, "stick_dominated": 400e-9, "huge_u_m": 20e-6}


def _regime_cases():
    for name, (U_l, U_w, delta, F_p) in REGIMES.items():
        for k in V_OVER_TIP:
            yield f"{name}-v{k}", (U_l, U_w, delta, W, k * W * U_w, F_p)


@pytest.mark.parametrize("mode, u_m_name", [("stick_slip", k) for k in U_M] + [("pure_slip", "reference_u_m")])
def test_closed_form_equals_fine_quadrature_over_regimes(ip, u_m_name, mode):
    # reference: the numerical kernel at n_theta = 3 * 2^15 (error ~1e-8 N, second order toward the
    # closed form); tolerance 1e-5 N on every force, 1e-5 on the stick fraction, phi_c exact
    p = dataclasses.replace(ip, u_m_m=U_M[u_m_name])
    for label, args in _regime_cases():
        new = itf.interface_forces(*args, p, mode=mode)
        ref = itf.interface_forces_reference(*args, p, mode=mode, n_theta=3 * 2 ** 15)
        for f in FIELDS[:6]:
            assert getattr(new, f) == pytest.approx(getattr(ref, f), abs=1e-5), (label, f)
        assert new.stick_fraction == pytest.approx(ref.stick_fraction, abs=1e-5), label
        assert new.phi_c_rad == ref.phi_c_rad, label
        assert new.F_N_mean_N == pytest.approx(args[5], rel=1e-12), label  # Eq. 18, exact now


@pytest.mark.parametrize("u_m_name", ["slip_dominated", "reference_u_m", "stick_dominated"])
def test_closed_form_equals_independent_adaptive_quadrature(ip, u_m_name):
    # reference: _piecewise_quad_reference (brentq breakpoints + adaptive quadrature, ~1e-12 N);
    # the closed form is exact, so the tolerance is 1e-8 N (far below the 1e-5 N requirement)
    p = dataclasses.replace(ip, u_m_m=U_M[u_m_name])
    for label, args in _regime_cases():
        new = itf.interface_forces(*args, p)
        ref = _piecewise_quad_reference(*args, p)
        for f in FIELDS:
            assert getattr(new, f) == pytest.approx(ref[f], abs=1e-8), (label, f)
    for v in (-0.3, 0.1, 0.2, 0.5):  # pure slip against the same reference
        new = itf.interface_forces(1.22e-6, 1.41e-6, -1.9, W, v, 5.6, p, mode="pure_slip")
        ref = _piecewise_quad_reference(1.22e-6, 1.41e-6, -1.9, W, v, 5.6, p, mode="pure_slip")
        for f in FIELDS:
            assert getattr(new, f) == pytest.approx(ref[f], abs=1e-8), (v, f)


def test_closed_form_pure_slip_equals_eq23_and_physics_notes_exactly(ip):
    # reference: the closed forms pure_slip_drive_force_N and Eq. 23 (ideal phase), now to round-off
    U_w, F_p = 1.4e-6, 5.6
    for v in V_ALL:
        out = itf.interface_forces(1.2e-6, U_w, -np.pi / 2, W, v, F_p, ip, mode="pure_slip")
        Fd, F1 = _pure_slip_reference(U_w, v, F_p, ip.sigma_N_s_per_m, ip.mu_p)
        assert out.F_d_N == pytest.approx(Fd, abs=1e-12)
        assert out.F_T1_sin_N == pytest.approx(F1, abs=1e-12)
        assert out.F_T1_cos_N == pytest.approx(0.0, abs=1e-12)
        assert out.F_N_mean_N == pytest.approx(F_p, rel=1e-14)
        assert out.F_N1_sin_N == pytest.approx(np.pi * F_p / 2, rel=1e-14)


def _jump(ip, args, index, x0, eps, mode="stick_slip", kernel=itf.interface_forces, **kw):
    lo, hi = list(args), list(args)
    lo[index], hi[index] = x0 - eps, x0 + eps
    a, b = kernel(*lo, ip, mode=mode, **kw), kernel(*hi, ip, mode=mode, **kw)
    return max(abs(getattr(a, f) - getattr(b, f)) for f in FIELDS[:6]), a, b


def test_closed_form_is_continuous_across_regime_boundaries(ip):
    # reference: physics - where the structure of the period changes but the model does not jump,
    # the period averages change by O(eps) (Lipschitz, here < 1e-6 N for a step of 2e-9)
    U_l, U_w, F_p = 1.22e-6, 1.41e-6, 5.6
    a = float(itf.contact_half_angle_rad(U_l, F_p, ip.k_e_N_per_m))
    k0 = 0.3
    ac = math.acos(k0)
    eps = 1e-9
    base = [U_l, U_w, 0.0, W, k0 * W * U_w, F_p]
    # a velocity reversal crossing the contact start, then the contact end (delta sweeps)
    for delta0 in (ac - (np.pi / 2 - a), ac - (np.pi / 2 + a), -ac - (np.pi / 2 - a) + 2 * np.pi):
        d, lo, hi = _jump(ip, base, 2, delta0, eps)
        assert d < 1e-6, delta0
    # the stick reaching the end of its segment (u_m at the full relative travel, no reversal in contact)
    args = (U_l, U_w, -1.69, W, 0.5, F_p)
    lo_th, hi_th = np.pi / 2 - a, np.pi / 2 + a
    travel = abs(U_w * (math.sin(hi_th - 1.69) - math.sin(lo_th - 1.69)) - 0.5 * (hi_th - lo_th) / W)
    below = itf.interface_forces(*args, dataclasses.replace(ip, u_m_m=travel * (1 - 1e-9)))
    above = itf.interface_forces(*args, dataclasses.replace(ip, u_m_m=travel * (1 + 1e-9)))
    assert above.stick_fraction == 1.0 and below.stick_fraction < 1.0
    assert max(abs(getattr(above, f) - getattr(below, f)) for f in FIELDS[:6]) < 1e-6
    # pure slip at v = 0 (nothing special) and where the two reversals merge (v = w U_w, inside the
    # contact): there the sign flips over an interval ~ sqrt(w U_w - v), so the modulus is a square root
    d, _, _ = _jump(ip, [U_l, U_w, -1.9, W, 0.0, F_p], 4, 0.0, eps, mode="pure_slip")
    assert d < 1e-6
    d = [_jump(ip, [U_l, U_w, -1.9, W, W * U_w, F_p], 4, W * U_w, e, mode="pure_slip")[0] for e in (1e-8, 1e-12)]
    assert d[1] < 2e-5 and 50 < d[0] / d[1] < 200


def test_closed_form_reproduces_the_model_jumps_of_the_reference(ip):
    # reference: the numerical kernel (n_theta = 3 * 2^15) on both sides of the two places where the
    # u_r rule itself is discontinuous: permanent contact k_e U_l = F_p (the contact-start reset
    # disappears) and, in permanent contact, the tangency v = w U_w (no reversal: the contact slides)
    U_w, F_p = 1.0e-6, 5.6
    for idx, x0, args in ((0, F_p / ip.k_e_N_per_m, [0.0, U_w, -1.6, W, 0.1, F_p]),
                          (4, W * U_w, [0.1e-6, U_w, -1.6, W, 0.0, F_p])):
        eps = 1e-9 * x0
        d_new, lo_n, hi_n = _jump(ip, args, idx, x0, eps)
        d_ref, lo_r, hi_r = _jump(ip, args, idx, x0, eps, kernel=itf.interface_forces_reference, n_theta=3 * 2 ** 15)
        assert d_new > 1e-3  # a real jump
        for f in FIELDS[:6]:
            assert getattr(lo_n, f) == pytest.approx(getattr(lo_r, f), abs=1e-5), (idx, f)
            assert getattr(hi_n, f) == pytest.approx(getattr(hi_r, f), abs=1e-5), (idx, f)


def test_closed_form_scalar_and_array_paths_agree_bitwise(ip):
    # reference: the scalar fast path (what the blocks call) element by element; numpy scalars and
    # 0-d arrays take it too
    rows = [c[:6] for c in CASES.values()]
    cols = [np.array(c) for c in zip(*rows)]
    vec = itf.interface_forces(*cols, ip)
    for i, r in enumerate(rows):
        sca = itf.interface_forces(*r, ip)
        assert all(isinstance(x, float) for x in sca)
        for f in FIELDS:
            assert getattr(vec, f)[i] == getattr(sca, f), f
    zero_d = itf.interface_forces(*(np.float64(x) for x in rows[0][:5]), np.array(rows[0][5]), ip)
    assert tuple(zero_d) == tuple(itf.interface_forces(*rows[0], ip))


STEADY_GRID = [  # (position [m], V0 [V], load [kg], direction)
    (0.0, 324.0, 0.0, 1), (0.0, 200.0, 0.0, 1), (0.005, 324.0, 0.1, 1), (-0.01, 280.0, 0.0, -1),
    (0.0, 324.0, 0.2, -1), (0.0, 150.0, 0.05, 1), (0.01, 324.0, -0.1, 1),
]


@pytest.mark.parametrize("mode", ["stick_slip", "pure_slip"])
def test_steady_speeds_unchanged_by_the_closed_form(motor, monkeypatch, mode):
    # reference: coupled.steady_state with the numerical kernel (default n_theta = 256, and 4096 on part
    # of the grid) patched in; within 1e-4 relative of the former, 1e-6 of the finer one
    from l1b2.physics import steady as coupled
    new = [coupled.steady_state(motor, s, V0, m, d, mode=mode) for s, V0, m, d in STEADY_GRID]
    with monkeypatch.context() as mp:
        mp.setattr(itf, "interface_forces", itf.interface_forces_reference)
        old = [coupled.steady_state(motor, s, V0, m, d, mode=mode) for s, V0, m, d in STEADY_GRID]
        mp.setattr(itf, "interface_forces", lambda *a, **k: itf.interface_forces_reference(*a, **k, n_theta=4096))
        fine = [coupled.steady_state(motor, s, V0, m, d, mode=mode) for s, V0, m, d in STEADY_GRID[:3]]
    for g, n, o in zip(STEADY_GRID, new, old):
        assert n.converged and o.converged and n.stuck == o.stuck, g
        assert abs(n.v_m_s) > 0.05, g
        assert n.v_m_s == pytest.approx(o.v_m_s, rel=1e-4), g
        assert n.F_d_N == pytest.approx(o.F_d_N, rel=1e-3, abs=1e-4), g
    for g, n, f in zip(STEADY_GRID, new, fine):
        assert n.v_m_s == pytest.approx(f.v_m_s, rel=1e-6), g


def test_steady_state_stuck_slider_unchanged(motor, monkeypatch):
    # reference: the numerical kernel patched in; at low voltage with a load the guide holds the slider
    from l1b2.physics import steady as coupled
    new = coupled.steady_state(motor, 0.0, 60.0, 0.15, 1)
    with monkeypatch.context() as mp:
        mp.setattr(itf, "interface_forces", itf.interface_forces_reference)
        old = coupled.steady_state(motor, 0.0, 60.0, 0.15, 1)
    assert new.stuck and old.stuck and new.v_m_s == old.v_m_s == 0.0
    assert new.F_d_N == pytest.approx(old.F_d_N, rel=1e-3)


# ---------------------------------------------------------------------------
# The compiled kernel (l1b2.physics.jit): same source, same numbers
# ---------------------------------------------------------------------------

def _random_tip_motions(n, seed):
    """Inputs over every regime: partial and permanent contact, any phase, speeds beyond the tip speed."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        U_w = rng.uniform(0.0, 1.5e-6) if i % 17 else 0.0
        v = rng.uniform(-1.5, 1.5) * W * max(U_w, 1e-7) if i % 11 else 0.0
        yield (rng.uniform(0.0, 4e-6) if i % 13 else 0.0, U_w, rng.uniform(-3.5, 3.5),
               W * rng.uniform(0.6, 1.4), v, rng.uniform(0.0, 80.0) if i % 19 else 0.0)


@pytest.mark.parametrize("mode", ["stick_slip", "pure_slip"])
def test_compiled_kernel_equals_the_python_kernel(ip, mode):
    # the compiled function is the Python function translated by numba: the same operations in the same
    # order, so the outputs agree to a few ulps (1e-12 relative to the force scale k_e U_l + F_p)
    from l1b2.physics.jit import jit_status
    if itf.compiled_kernel() is None:
        pytest.skip(f"numba kernel not available: {jit_status()}")
    for u_m in (0.0, 0.5e-9, 20e-9, 400e-9):
        p = dataclasses.replace(ip, u_m_m=u_m)
        for args in _random_tip_motions(400, seed=int(u_m * 1e12)):
            py = itf.interface_forces_scalar(*args, p, mode, jit=False)
            jt = itf.interface_forces_scalar(*args, p, mode, jit=True)
            scale = p.k_e_N_per_m * args[0] + args[5] + p.sigma_N_s_per_m * (args[3] * args[1] + abs(args[4])) + 1.0
            for f, a, b in zip(FIELDS, py, jt):
                assert abs(a - b) <= 1e-12 * scale, (f, args, a, b)


def test_kernel_without_numba_is_the_python_kernel(tmp_path):
    # L1B2_JIT=0: nothing is compiled, the Python function runs, the block gives the same forces
    import subprocess
    import sys
    code = ("from l1b2.physics import interface as itf, jit; from l1b2.physics.params import load_motor; "
            "ip = load_motor().interface; "
            "out = itf.interface_forces_scalar(1.2e-7, 7e-7, -1.6, 3.05e5, 0.05, 40.0, ip, 'stick_slip'); "
            "print(itf.compiled_kernel() is None, jit.jit_status(), repr(out.F_d_N))")
    env = dict(__import__("os").environ, L1B2_JIT="0", L1B2_CACHE_DIR=str(tmp_path))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    none, *status, f_d = res.stdout.split()
    assert none == "True" and " ".join(status) == "disabled by L1B2_JIT=0"
    from l1b2.physics.params import load_motor
    expected = itf.interface_forces_scalar(1.2e-7, 7e-7, -1.6, 3.05e5, 0.05, 40.0, load_motor().interface,
                                           "stick_slip", jit=False)
    assert float(f_d) == expected.F_d_N
    assert not (tmp_path / "numba").exists()


def test_compiled_kernel_cache_is_shared_by_copies_of_the_module(tmp_path):
    # copies of the physics package in different folders, as every extraction of one FMU holds its bundle:
    # the first compiles into the content-keyed cache, a copy under the same package name elsewhere loads
    # from it; a copy under another package name (another FMU's bundle) compiles its own
    import os
    import shutil
    import subprocess
    import sys
    src = Path(itf.__file__).resolve().parent
    env = dict(os.environ, L1B2_CACHE_DIR=str(tmp_path / "cache"), L1B2_JIT="1")
    stats = []
    for folder, pkg in (("x1", "pkg_same"), ("x2", "pkg_same"), ("x3", "pkg_other")):
        shutil.copytree(src, tmp_path / folder / pkg / "physics", ignore=shutil.ignore_patterns("__pycache__"))
        (tmp_path / folder / pkg / "__init__.py").write_text("")
        for f in ("errors.py", "units.py"):
            shutil.copy(src.parent / f, tmp_path / folder / pkg)
        code = (f"import {pkg}.physics.interface as itf, {pkg}.physics.jit as jit; "
                "k = itf.compiled_kernel(); s = k.stats; "
                "print(jit.jit_status(), sum(s.cache_hits.values()), sum(s.cache_misses.values()))")
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                             cwd=tmp_path / folder)
        assert res.returncode == 0, res.stderr
        stats.append(res.stdout.split())
    assert stats[0] == ["compiled", "0", "1"], stats   # compiled and stored
    assert stats[1] == ["compiled", "1", "0"], stats   # another extraction: loaded, not compiled
    assert stats[2] == ["compiled", "0", "1"], stats   # another bundle name: its own entry
    assert sorted(p.name.split("-")[0] for p in (tmp_path / "cache" / "numba").iterdir()) == [
        "pkg_other.physics.interface", "pkg_same.physics.interface"]
