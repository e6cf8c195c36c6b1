"""The pure-slip drive force with a finite contact (half angle a): closed form against the interface's period mean."""

import math

import numpy as np
import pytest
from l1b2.physics import interface as itf
from l1b2.predictor.pureslip import contact_drive_force, contact_shape, contact_slip_factor, pure_slip_drive_force


def test_half_contact_of_half_a_period_is_the_pure_slip_closed_form():
    # reference: docs/explanation/physics.md's closed form (phi_c = pi): h(k, pi/2) = 2 sqrt(1 - k^2) - 1
    k = np.linspace(0.0, 1.0, 41)
    assert contact_shape(0.5 * math.pi) == pytest.approx(1.0, abs=1e-15)
    assert np.allclose(contact_slip_factor(k, 0.5 * math.pi), 2 * np.sqrt(1 - k * k) - 1, atol=1e-14)
    W, v = 0.5, np.linspace(0.0, 0.6, 13)
    assert np.allclose(contact_drive_force(W, v, 6.0, 8.0, 0.2, 0.5 * math.pi),
                       pure_slip_drive_force(W, v, 6.0, 8.0, 0.2), atol=1e-12)


def test_coulomb_share_is_full_while_the_whole_contact_outruns_the_slider():
    # stated behaviour: no braking edge for k <= cos a; all braking at k = 1; h falls with k beyond cos a
    a = np.array([0.6, 1.0, 1.3])
    for ai in a:
        k = np.linspace(0.0, math.cos(ai), 9)
        assert np.allclose(contact_slip_factor(k, ai), 1.0, atol=1e-14)
        kk = np.linspace(math.cos(ai), 1.0, 30)
        h = contact_slip_factor(kk, ai)
        assert h[-1] == pytest.approx(-1.0, abs=1e-12) and np.all(np.diff(h) < 0)


@pytest.mark.parametrize("rho", [0.1, 0.4, 1.0, 1.7])
def test_closed_form_equals_the_interface_period_mean(motor, rho):
    # independent solution: l1b2.physics.interface.period_integrals (Eq. 17-20 integrated piece by piece) with
    # an ideal ellipse (delta = -pi/2: the contact centred on the tangential speed's peak) and almost no stick
    # (u_m = 1e-15 m; the stick phase shrinks with u_m: below 1e-5 N here, while the half-period form differs
    # by 2-4 N at rho = 0.1 ... 0.4); the half contact angle a from Eq. 18 (contact_half_angle_rad) for the
    # normal amplitude U_l with pi F_p / (k_e U_l) = rho: rho = 1.7 is a contact longer than half a period
    ip = motor.interface
    F_p, omega, U_w = 6.0, 2 * math.pi * 48500.0, 1.7e-6
    W = omega * U_w
    U_l = math.pi * F_p / (ip.k_e_N_per_m * rho)
    a = float(itf.contact_half_angle_rad(U_l, F_p, ip.k_e_N_per_m))
    assert float(contact_shape(a)) == pytest.approx(rho, rel=1e-12)
    assert (a > 0.5 * math.pi + 1e-9) == (rho > 1.0) and a < math.pi
    for v in np.linspace(0.0, 0.95 * W, 12):
        ref = itf.period_integrals(U_l, U_w, -0.5 * math.pi, omega, float(v), F_p, ip.k_e_N_per_m, 1e-15,
                                   ip.mu_p, ip.sigma_N_s_per_m, 0.0)[0]
        got = contact_drive_force(W, v, F_p, ip.sigma_N_s_per_m, ip.mu_p, a)
        assert got == pytest.approx(ref, rel=1e-5, abs=1e-5)
