"""bench/blind_effects_twelfth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
guide's Coulomb factor against the rails' interference, the loads the late swap hangs, B2's damping near the holder's
mode and the homing probe's field.
"""

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twelfth")


def test_the_guide_factor_is_flat_at_a_clearance_and_a_10_9_power_above(audit):
    assert audit.guide_factor(-4.0, 1.2, 4.0) == 1.0
    assert audit.guide_factor(0.0, 1.2, 4.0) == 1.0
    assert audit.guide_factor(8.0, 1.2, 4.0) == pytest.approx(1.3, rel=1e-14)
    assert audit.guide_factor(8.0, 1.2, 3.0) == pytest.approx(1.4, rel=1e-14)
    # 4 um: N8 0.5^(10/9)
    assert audit.guide_factor(4.0, 1.2, 4.0) == pytest.approx(1 + 1.2 * 0.5 ** (10 / 9) / 4.0, rel=1e-14)
    d = np.linspace(0.1, 8.0, 40)
    assert np.all(np.diff(audit.guide_factor(d, 1.2, 4.0), 2) > 0)  # convex above zero


def test_a_forward_run_carries_the_previous_conditions_weight(audit):
    conds = [(220.0, 0.05, 1), (220.0, 0.05, -1), (255.0, -0.09, 1), (255.0, -0.09, -1), (290.0, 0.0, 1),
             (290.0, 0.0, -1), (324.0, 0.0, 1), (324.0, 0.0, -1)]
    assert audit.carried_loads(conds) == [0.0, 0.05, 0.05, -0.09, -0.09, 0.0, 0.0, 0.0]


def test_b2_damping_doubles_at_the_holders_mode_with_d_one_and_halves_its_rise_at_gamma(audit):
    assert audit.notch_factor(48500.0, 48500.0, 100.0, 1.0) == pytest.approx(2.0, rel=1e-15)
    assert audit.notch_factor(48600.0, 48500.0, 100.0, 1.0) == pytest.approx(1.5, rel=1e-15)
    assert audit.notch_factor(48400.0, 48500.0, 100.0, 1.0) == pytest.approx(1.5, rel=1e-15)
    assert audit.notch_factor(49000.0, 48500.0, 100.0, 1.0) == pytest.approx(1 + 1 / 26, rel=1e-14)


def test_the_probes_field_is_a_dipoles_bell(audit):
    assert audit.hall_field_mT(0.002, 0.002, 30.0, 0.008) == pytest.approx(30.0, rel=1e-15)
    assert audit.hall_field_mT(0.010, 0.002, 30.0, 0.008) == pytest.approx(30.0 / 2 ** 1.5, rel=1e-14)
    assert audit.hall_field_mT(-0.006, 0.002, 30.0, 0.008) == pytest.approx(30.0 / 2 ** 1.5, rel=1e-14)


def test_the_draws_stay_in_their_ranges_and_the_control_shares_the_notchs_plan(audit):
    for seed in (1, 2, 3):
        g = audit.draw("guide_preload_hinge", seed, 72)
        assert 1.0 <= g["N8_N"] <= 1.6 and g["delta_um"].min() >= -4.0 and g["delta_um"].max() <= 8.0
        n = audit.draw("holder_mode_notch", seed, 72)
        c = audit.draw("frequency_plan_control", seed, 72)
        assert 48350.0 <= n["f_s_Hz"] <= 48650.0 and 60.0 <= n["gamma_Hz"] <= 120.0 and 0.8 <= n["D"] <= 1.2
        assert len(n["f_cond_Hz"]) == 36 and n["f_cond_Hz"].min() >= 48200.0 and n["f_cond_Hz"].max() <= 48800.0
        assert np.array_equal(c["f_cond_Hz"], n["f_cond_Hz"]) and c["D"] == 0.0
        h = audit.draw("hall_homing_decoy", seed, 72)
        assert -6e-3 <= h["s_h_m"] <= 6e-3 and 20.0 <= h["B_pk_mT"] <= 40.0 and 6e-3 <= h["w_m"] <= 10e-3
