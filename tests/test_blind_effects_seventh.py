"""bench/blind_effects_seventh.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
holder's force on L1, the guide's rest ageing, the USB packets' time stamps and the sound level meter's reading.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_seventh")


def test_l1_rises_with_the_cube_root_of_the_holding_force(audit):
    # f_l0 + K ((F / 50 N)^(1/3) - 1): 50 N leaves it, 400 N = 8 x 50 N adds K, 6.25 N = 50 N / 8 takes K/2
    got = audit.l1_frequency_Hz(49200.0, np.array([50.0, 400.0, 6.25]), 1500.0)
    assert got == pytest.approx([49200.0, 50700.0, 48450.0], rel=1e-12)


def test_guide_friction_after_a_rest_is_one_at_the_plans_pause(audit):
    B, theta = 0.06, 0.2
    assert audit.rest_factor(1.0, B, theta) == pytest.approx(1.0, rel=1e-12)
    want = (1 + B * math.log(1 + 10.0 / theta)) / (1 + B * math.log(1 + 1.0 / theta))   # 10 s at rest
    assert audit.rest_factor(np.array([10.0]), B, theta) == pytest.approx([want], rel=1e-12)
    # a longer rest, a larger friction
    f = audit.rest_factor(np.array([0.5, 1.0, 5.0, 30.0]), B, theta)
    assert np.all(np.diff(f) > 0)


def test_packet_stamps_add_each_packets_latency(audit):
    t = np.arange(7) * 1e-3
    got = audit.packet_stamps(t, 3, [0.2e-3, 0.5e-3, 0.1e-3])
    want = t + np.array([0.2, 0.2, 0.2, 0.5, 0.5, 0.5, 0.1]) * 1e-3
    assert got == pytest.approx(want, abs=1e-15)
    # steps: 1 ms within a packet, 1 ms + L_(p+1) - L_p across: always positive for latencies under 1 ms
    assert np.diff(got) == pytest.approx(np.array([1, 1, 1.3, 1, 1, 0.6]) * 1e-3, abs=1e-15)


def test_meter_reads_the_background_then_the_averaged_power(audit):
    tau, L1, Lbg = 0.125, 60.0, 40.0
    t = np.arange(0.0, 1.0 + 5e-4, 1e-3)
    v = np.full(t.size, 0.1)                        # half the reference speed: a quarter of L1's power
    got = audit.meter_level_dB(t, v, L1, Lbg, tau)
    P1, Pbg = 10 ** (L1 / 10) * 0.25, 10 ** (Lbg / 10)
    assert got[0] == pytest.approx(Lbg, abs=1e-12)
    k = 125                                         # t = tau: the average at (1 - 1/e) of the held power
    assert got[k] == pytest.approx(10 * math.log10(Pbg + P1 * (1 - math.exp(-1))), abs=1e-9)
    assert got[-1] == pytest.approx(10 * math.log10(Pbg + P1 * (1 - math.exp(-8))), abs=1e-9)


def test_draws_lie_in_their_ranges(audit):
    for seed in (1, 2, 3):
        p = audit.draw("holder_clamp_force", seed, 72)
        assert 1400 <= p["K_Hz"] <= 1800 and np.all((p["F_N"] >= 15) & (p["F_N"] <= 90))
        p = audit.draw("guide_rest_aging", seed, 72)
        assert 0.05 <= p["B"] <= 0.08 and 0.1 <= p["theta_s"] <= 0.3
        assert np.all((p["pause_s"] >= 0.5) & (p["pause_s"] <= 30.0))
        p = audit.draw("usb_timestamps", seed, 72)
        assert 10 <= p["N"] <= 25 and 0.3e-3 <= p["L_max_s"] <= 0.6e-3
        p = audit.draw("acoustic_echo_decoy", seed, 72)
        assert 55 <= p["L1_dB"] <= 62 and 38 <= p["Lbg_dB"] <= 42


def test_the_idle_control_has_the_rests_pauses_and_a_guide_that_does_not_age(audit):
    for seed in (1, 2, 3):
        aging, idle = audit.draw("guide_rest_aging", seed, 72), audit.draw("guide_rest_idle", seed, 72)
        np.testing.assert_array_equal(idle["pause_s"], aging["pause_s"])
        assert idle["B"] == 0.0 and idle["theta_s"] == aging["theta_s"]
        assert audit.rest_factor(idle["pause_s"], idle["B"], idle["theta_s"]) == pytest.approx(np.ones(72), abs=0)
