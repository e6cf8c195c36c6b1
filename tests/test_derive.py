"""Predictor parameters derived from the physical model vs the co-simulation (issue 4)."""

import numpy as np
import pytest
from l1b2.physics import steady
from l1b2.physics.params import load_motor
from l1b2.predictor import derive
from l1b2.predictor import model as pr

GRID = dict(positions=np.array([-0.015, 0.0, 0.015]), voltages=(220.0, 272.0, 324.0), loads=(-0.09, 0.0, 0.09))


@pytest.fixture(scope="module")
def motor():
    return load_motor()


@pytest.fixture(scope="module")
def linearized(motor):
    return derive.derive_predictor(motor, method="linearized", mode="pure_slip", n_grid=13)


def test_linearized_predictor_agrees_with_pure_slip_cosim_within_2_percent(motor, linearized):
    # reference: the coupled model's steady state in pure-slip mode (the co-simulation's fixed point),
    # across positions, voltages, loads and both directions
    df = derive.compare_steady(linearized, motor, mode="pure_slip", **GRID)
    s = derive.summarize(df)
    assert s["n_points"] == 3 * 3 * 3 * 2
    assert s["max_abs_rel_error"] < 0.02


def test_linearized_predictor_is_exact_at_the_reference_point(motor, linearized):
    # reference: the linearization reproduces the physical model exactly where it was taken

    c = linearized.s_center
    ss = steady.steady_state(motor, c, derive.DEFAULT_V_REF, 0.0, 1, mode="pure_slip")
    v = float(pr.steady_state(linearized, c, derive.DEFAULT_V_REF, 0.0, 1, motor.slider.mass_kg))
    assert v == pytest.approx(ss.v_m_s, rel=2e-3)  # up to the Legendre fit of A', B', P


def test_derived_preload_level_is_the_physical_preload(motor, linearized):
    # reference: k0 (structurally free) is chosen so that P(s) is closest to F_p(s) of the stator model
    # (Eq. 16): the mean level agrees; the shape need not (position acts through A' and B' too)
    from l1b2.physics import stator as st
    s = np.linspace(-0.015, 0.015, 7)
    assert np.mean(linearized.P(s)) == pytest.approx(np.mean(st.preload_N(motor.stator, s)), rel=0.1)
    assert linearized.c_r == motor.slider.c_r_N_s_per_m and linearized.mu == motor.interface.mu_p


def test_stick_slip_difference_is_reported_not_hidden(motor, linearized):
    # reference: the pure-slip derivation against the stick-slip co-simulation differs (stick, contact
    # angle from Eq. 18); the comparison reports a number for it
    s = derive.summarize(derive.compare_steady(linearized, motor, mode="stick_slip", **GRID))
    assert np.isfinite(s["max_abs_rel_error"]) and s["max_abs_rel_error"] > 0.005


def test_paper_reduction_is_computable_and_reported(motor):
    # reference: Eq. 30 literally; its scalar (in-phase) reduction is compared, not assumed good
    p = derive.derive_predictor(motor, method="paper", mode="pure_slip", n_grid=9)
    assert p.sigma == motor.interface.sigma_N_s_per_m
    s = derive.summarize(derive.compare_steady(p, motor, mode="pure_slip", **GRID))
    assert np.isfinite(s["max_abs_rel_error"])


# ---------------------------------------------------------------------------
# The paper's reduction (Eq. 25, 26, 30) against the formulas evaluated here, independently
# ---------------------------------------------------------------------------

def _paper_reduction_by_hand(motor, s):
    """A'(s), B'(s) [per second] and P(s) of Eq. 26 and Eq. 30 (divided by T_s), written out from the paper.

    Eq. 26: Theta = |phi_b(L)| / (K_b sqrt((1 - (w/w_b0)^2)^2 + (2 zeta_b w/w_b0)^2)),
    w_b0 = sqrt(K_b/M_b), zeta_b = C_b / (2 M_b w_b0); Eq. 25's denominator
    Theta^-1 + 0.5 eta_T sigma w; Eq. 30: A = 4 sigma eta_T T_s / (pi T den),
    B = 2 sigma A_b T_s / (T den). Only the B2 modal mass, stiffness, damping
    and tip mode-shape value come from the stator model (eta_T = |phi_b(L)|).
    """
    from l1b2.physics import stator as st
    w = 2 * np.pi * motor.operating.f_drive_Hz
    T = 2 * np.pi / w
    sigma = motor.interface.sigma_N_s_per_m
    props = st.modal_properties(motor.stator, st.axial_force_N(motor.stator, s))
    M, K, C, eta = (np.asarray(x, float) for x in (props.M_b, props.K_b, props.C_b, props.eta_T))
    w_b0 = np.sqrt(K / M)
    zeta = C / (2 * M * w_b0)
    theta = eta / (K * np.sqrt((1 - (w / w_b0) ** 2) ** 2 + (2 * zeta * w / w_b0) ** 2))
    den = 1 / theta + 0.5 * eta * sigma * w
    A = 4 * sigma * eta / (np.pi * T * den)
    B = 2 * sigma * motor.stator.A_b_N_per_V / (T * den)
    return A, B, st.preload_N(motor.stator, s)


def test_paper_reduction_matches_eq_26_and_30_evaluated_independently(motor):
    # reference: Deng et al. Eq. 25, 26 and 30 written out above; with order + 1 grid points the
    # Legendre series interpolates the derived functions exactly at the grid
    order = 8
    p = derive.derive_predictor(motor, method="paper", mode="pure_slip", order=order, n_grid=order + 1)
    s = np.linspace(motor.slider.s_min_m + 1e-3, motor.slider.s_max_m - 1e-3, order + 1)
    A, B, P = _paper_reduction_by_hand(motor, s)
    np.testing.assert_allclose(p.A_prime(s), A, rtol=1e-7)
    np.testing.assert_allclose(p.B_prime(s), B, rtol=1e-7)
    np.testing.assert_allclose(p.P(s), P, rtol=1e-7)
    # the check is sensitive: the friction term is about half of Eq. 25's denominator here and
    # eta_T = |phi_b(L)| is about 2, so a factor 2 on either or eta_T^2 on Theta moves A' by > 20 %
    from l1b2.physics import stator as st
    props = st.modal_properties(motor.stator, st.axial_force_N(motor.stator, s))
    w = 2 * np.pi * motor.operating.f_drive_Hz
    friction = 0.5 * props.eta_T * motor.interface.sigma_N_s_per_m * w
    den = 4 * motor.interface.sigma_N_s_per_m * props.eta_T * w / (2 * np.pi ** 2 * A)
    assert np.all(friction / den > 0.3) and np.all(np.abs(props.eta_T - 1) > 0.5)
