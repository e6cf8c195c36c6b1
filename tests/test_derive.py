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
