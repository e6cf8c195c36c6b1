"""bench/blind_effects_eleventh.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: L1's
damping against the clamp's torque, the oil film a pass leaves for the next, the elastic thread's tension and the
relay coil's temperature.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_eleventh")


def test_clamp_damping_is_the_motors_at_the_reference_torque_and_falls_to_its_floor(audit):
    z, s, tau0 = 0.015, 0.3, 10.0
    assert audit.clamp_zeta(z, 30.0, s, tau0) == pytest.approx(z, rel=1e-15)
    # 10 cN m looser: 1 - 0.3 + 0.3 e^1
    assert audit.clamp_zeta(z, 20.0, s, tau0) == pytest.approx(z * (0.7 + 0.3 * math.e), rel=1e-14)
    # tight: toward the floor 0.7 z, monotone decreasing
    tau = np.linspace(20.0, 200.0, 50)
    got = audit.clamp_zeta(z, tau, s, tau0)
    assert np.all(np.diff(got) < 0) and got[-1] == pytest.approx(0.7 * z, rel=1e-6)


def test_a_faster_pass_leaves_a_thicker_film_and_less_friction(audit):
    assert audit.film_factor(0.2, 0.2) == pytest.approx(1.0, rel=1e-15)
    # (0.1 / 0.2)^(2/3) = 0.62996: 1 - 0.2 (0.62996 - 1)
    assert audit.film_factor(0.1, 0.2) == pytest.approx(1 + 0.2 * (1 - 0.5 ** (2 / 3)), rel=1e-14)
    assert audit.film_factor(-0.1, 0.2) == audit.film_factor(0.1, 0.2)  # a backward pass leaves the same film
    assert audit.film_factor(0.3, 0.2) < 1.0


def _thread_tension(audit, L, s0, k, eta, s_of_t, h=1e-3, n=400):
    law = audit.thread_law(L, s0, k, eta)
    out = [law(0.0, s0, 0.0)]
    for i in range(1, n):
        t = i * h
        v = (s_of_t(t) - s_of_t(t - h)) / h
        out.append(law(t, s_of_t(t), v))
    return np.array(out) * audit.G_M_S2 * np.sign(L)


def test_the_thread_holds_the_weight_at_rest_and_rings_at_its_frequency(audit):
    k, m = 400.0, 0.04
    # at rest: the weight's static tension, the load input is the load
    T = _thread_tension(audit, m, -0.021, k, 0.05, lambda t: -0.021)
    assert T == pytest.approx(np.full(T.size, m * audit.G_M_S2), rel=1e-12)
    # the slider jumps 1 mm away from the pulley (+position for a positive load) and stays: the tension steps by
    # k x 1 mm, then rings at omega_n = sqrt(k / m) = 100 rad/s (period 62.8 ms) about m g
    T = _thread_tension(audit, m, -0.021, k, 0.0, lambda t: -0.021 + (1e-3 if t > 0 else 0.0))
    assert T[1] - m * audit.G_M_S2 == pytest.approx(k * 1e-3, rel=0.05)
    dev = T[1:] - m * audit.G_M_S2
    crossings = np.flatnonzero(np.diff(np.sign(dev)) != 0)
    period = 2 * np.mean(np.diff(crossings)) * 1e-3
    assert period == pytest.approx(2 * math.pi / 100.0, rel=0.03)


def test_the_thread_goes_slack_and_a_negative_load_pulls_the_other_way(audit):
    k, m = 400.0, 0.04
    # a positive load's slider jumps 2 mm toward its pulley (-position): the thread's stretch m g / k = 0.98 mm is
    # lost, so it goes slack (no push)
    T = _thread_tension(audit, m, 0.0, k, 0.05, lambda t: -2e-3 if t > 0 else 0.0, n=5)
    assert T[1] == 0.0
    # a negative load hangs at the +position end: the same jump away from it (-position) stretches the thread
    T = _thread_tension(audit, -m, 0.0, k, 0.0, lambda t: -1e-3 if t > 0 else 0.0, n=3)
    assert T[1] - m * audit.G_M_S2 == pytest.approx(k * 1e-3, rel=0.05)


def test_the_relay_coil_heats_when_on_and_cools_when_off(audit):
    assert audit.relay_theta(0.0, 3.0, True, 30.0, 20.0) == pytest.approx(3.0, rel=1e-15)
    assert audit.relay_theta(20.0, 0.0, True, 30.0, 20.0) == pytest.approx(30.0 * (1 - math.exp(-1)), rel=1e-14)
    assert audit.relay_theta(20.0, 6.0, False, 30.0, 20.0) == pytest.approx(6.0 * math.exp(-1), rel=1e-14)


def test_the_draws_lie_in_their_ranges(audit):
    for seed in (1, 2, 3):
        p = audit.draw("clamp_torque_damping", seed, 72)
        assert 0.25 <= p["s"] <= 0.35 and 8 <= p["tau0_cNm"] <= 14
        assert p["torque_cNm"].min() >= 20 and p["torque_cNm"].max() <= 70
        assert 0.15 <= audit.draw("film_carryover", seed, 72)["B"] <= 0.25
        p = audit.draw("elastic_load_line", seed, 72)
        assert 200 <= p["k_N_per_m"] <= 500 and 0.04 <= p["eta"] <= 0.10
        p = audit.draw("relay_coil_decoy", seed, 72)
        assert 25 <= p["Theta_K"] <= 40 and 15 <= p["tau_s"] <= 30
