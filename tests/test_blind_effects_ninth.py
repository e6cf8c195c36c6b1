"""bench/blind_effects_ninth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
magnet's share of the preload across its gap, the operator's overshoot of a new V0 setting, the bus of a supply in
current limit and the mains frequency's wander read by the analyser.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_ninth")


def test_magnet_preload_falls_with_the_inverse_square_of_the_gap(audit):
    P0, s, g0 = 6.35, 0.3, 0.6e-3
    # at the reference gap of 1 mm: the motor's preload
    assert audit.magnet_preload_N(P0, 1.0e-3, s, g0) == pytest.approx(P0, rel=1e-12)
    # at g = 1.6 mm: (1 + 1/0.6)^2 / (1 + 1.6/0.6)^2 = (8/3)^2 / (11/3)^2 = 64/121
    want = P0 * (0.7 + 0.3 * 64 / 121)
    assert audit.magnet_preload_N(P0, np.array([1.6e-3]), s, g0) == pytest.approx([want], rel=1e-12)
    # a far magnet leaves the spring's share; closer, more preload
    assert audit.magnet_preload_N(P0, 1.0, s, g0) == pytest.approx(0.7 * P0, rel=1e-5)
    got = audit.magnet_preload_N(P0, np.array([0.7e-3, 1.0e-3, 1.4e-3, 1.8e-3]), s, g0)
    assert np.all(np.diff(got) < 0) and np.all(np.diff(got, 2) > 0)   # falling and convex


def test_setpoint_overshoots_by_a_share_of_the_step_and_holds(audit):
    rho = 0.1
    got = audit.set_amplitudes_V([220.0, 220.0, 324.0, 324.0, 324.0, 255.0, 255.0], rho)
    v1 = 220.0 + 0.1 * (220.0 - 0.0)        # from 0 before the first run: 242 V
    v3 = 324.0 + 0.1 * (324.0 - v1)         # 332.2 V
    v6 = 255.0 + 0.1 * (255.0 - v3)         # 247.28 V
    assert got == pytest.approx([v1, v1, v3, v3, v3, v6, v6], abs=1e-12)


def test_bus_in_current_limit_discharges_toward_I_lim_R_eq(audit):
    R_eq = audit.bus_resistance_ohm(2000.0, 4.0)
    assert R_eq == pytest.approx(2 * 2000.0 / 16.0, rel=1e-15)          # 250 Ohm
    t = np.array([0.0, 0.1, 1.0])
    # V_s = 80 V > 0.28 A x 250 Ohm = 70 V: toward 70 V with tau = 250 Ohm x 2 mF = 0.5 s
    want = 70.0 + 10.0 * np.exp(-t / 0.5)
    assert audit.bus_voltage_V(t, 80.0, 0.28, R_eq, 2e-3) == pytest.approx(want, rel=1e-12)
    # below the limit: the set voltage, all along
    assert audit.bus_voltage_V(t, 60.0, 0.28, R_eq, 2e-3) == pytest.approx([60.0] * 3, abs=0)


def test_ou_path_follows_its_recursion(audit):
    z = np.array([0.5, -1.0, 2.0])
    sigma, tau, h = 0.02, 100.0, 0.2
    a = math.exp(-h / tau)
    b = sigma * math.sqrt(1 - a * a)
    x0 = sigma * 0.5
    x1 = a * x0 + b * -1.0
    x2 = a * x1 + b * 2.0
    assert audit.ou_path(z, sigma, tau, h) == pytest.approx([x0, x1, x2], abs=1e-15)
    # its stationary spread is sigma (a long path)
    x = audit.ou_path(np.random.default_rng(0).standard_normal(200000), sigma, 5.0, h)
    assert np.std(x) == pytest.approx(sigma, rel=0.05)


def test_grid_reading_holds_each_refresh(audit):
    x = np.array([0.01, -0.02, 0.03])
    got = audit.grid_reading_Hz(np.array([0.0, 0.199, 0.2, 0.45]), x, 0.2)
    assert got == pytest.approx([50.01, 50.01, 49.98, 50.03], abs=1e-12)


def test_draws_lie_in_their_ranges(audit):
    for seed in (1, 2, 3):
        p = audit.draw("magnet_gap_preload", seed, 72)
        assert 0.20 <= p["share"] <= 0.35 and 0.5e-3 <= p["g0_m"] <= 0.9e-3
        assert np.all((p["gap_m"] >= 0.7e-3) & (p["gap_m"] <= 1.8e-3))
        assert 0.10 <= audit.draw("setpoint_overshoot", seed, 72)["rho"] <= 0.16
        p = audit.draw("supply_current_limit", seed, 72)
        assert 0.26 <= p["I_lim_A"] <= 0.30 and 1.0e-3 <= p["C_b_F"] <= 2.2e-3
        p = audit.draw("grid_frequency_decoy", seed, 72)
        assert 0.015 <= p["sigma_Hz"] <= 0.030 and 60 <= p["tau_s"] <= 300
        assert p["x_Hz"].size * audit.ANALYSER_S >= 1000.0


@pytest.fixture(scope="module")
def probe(load_bench):
    return load_bench("blind_effects_ninth_probe")


def test_setting_steps_hold_the_step_from_the_previous_setting(probe):
    V = [220.0, 220.0, 324.0, 324.0, 255.0, 255.0, 255.0]
    # the step from the previous different setting, held while V0 is unchanged
    assert probe.setting_steps(V) == pytest.approx([0.0, 0.0, 104.0, 104.0, -69.0, -69.0, -69.0], abs=0)
    # with the drive off before the session, the first setting's step is its V0
    assert probe.setting_steps(V, from_off=True) == pytest.approx([220.0, 220.0, 104.0, 104.0, -69.0, -69.0, -69.0],
                                                                  abs=0)
