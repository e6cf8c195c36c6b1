"""bench/blind_effects_sixth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
ADC's rails on the speed, the holder's damping and its thermocouple's gaps, the heat sink's first-order path and the
de-ageing memory of the previous runs.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_sixth")


def test_speed_reads_flat_at_the_rails_and_unchanged_between_them(audit):
    v = np.array([-0.31, -0.25, -0.1, 0.0, 0.2, 0.2599, 0.26, 0.34])
    got = audit.clip_speed(v, 0.26)
    assert got == pytest.approx([-0.26, -0.25, -0.1, 0.0, 0.2, 0.2599, 0.26, 0.26], abs=0.0)


def test_holder_damping_rises_linearly_with_its_temperature(audit):
    # zeta (1 + beta (T - 25)): 0.015 at 25 degC; at 31 degC with beta 0.03 /K: 0.015 * 1.18 = 0.0177;
    # at 20 degC: 0.015 * 0.85 = 0.01275
    got = audit.holder_damping(0.015, np.array([25.0, 31.0, 20.0]), 0.03)
    assert got == pytest.approx([0.015, 0.0177, 0.01275], rel=1e-12)


def test_thermocouple_gap_is_a_burst_of_nan_of_its_length(audit):
    x = np.arange(100.0)
    got = audit.with_gap(x, True, 12, 0.305)        # starts at int(0.305 * 100) = 30
    assert np.flatnonzero(np.isnan(got)).tolist() == list(range(30, 42))
    assert got[~np.isnan(got)] == pytest.approx(np.r_[x[:30], x[42:]], abs=0.0)
    # a burst that would run past the end is moved back to end with the run
    assert np.flatnonzero(np.isnan(audit.with_gap(x, True, 12, 0.95))).tolist() == list(range(88, 100))
    assert not np.isnan(audit.with_gap(x, False, 12, 0.3)).any()


def test_heat_sink_heats_and_cools_first_order(audit):
    tau, V = 4.0, 290.0
    T_inf = 25.0 + 12.0 * (290.0 / 324.0) ** 2       # 34.61 degC
    t = np.array([0.0, tau, 50 * tau])
    got = audit.heatsink_path(t, V, 27.0, tau)
    assert got == pytest.approx([27.0, T_inf + (27.0 - T_inf) / math.e, T_inf], rel=1e-9)
    # the pause: from 30 degC toward the idle 27 degC, 1 s at tau 4 s: 27 + 3 exp(-1/4)
    assert audit.heatsink_pause(30.0, 1.0, tau) == pytest.approx(27.0 + 3.0 * math.exp(-0.25), rel=1e-12)


def test_deaging_share_is_an_average_of_the_previous_runs_only(audit):
    r = 0.7
    got = audit.deaging_share([324.0, 220.0, 324.0, 255.0], r)
    h1 = (1 - r) * 1.0
    h2 = r * h1 + (1 - r) * (220.0 / 324.0) ** 2
    h3 = r * h2 + (1 - r) * 1.0
    assert got == pytest.approx([0.0, h1, h2, h3], rel=1e-12)
    # the first run's share does not depend on its own voltage
    assert audit.deaging_share([220.0], r)[0] == audit.deaging_share([324.0], r)[0] == 0.0


def test_draws_lie_in_their_ranges(audit):
    for seed in (1, 2, 3):
        p = audit.draw("velocity_clip", seed, 72)
        assert 0.19 <= p["v_rail_m_s"] <= 0.22
        p = audit.draw("holder_damping_nan", seed, 72)
        assert 0.06 <= p["beta_per_K"] <= 0.08 and np.all((p["T_C"] >= 20) & (p["T_C"] <= 32))
        assert np.all((p["gap_len"] >= 5) & (p["gap_len"] <= 40)) and 0 < p["gap"].sum() < 72
        p = audit.draw("heatsink_decoy", seed, 72)
        assert 3.0 <= p["tau_s"] <= 6.0
        p = audit.draw("piezo_deaging", seed, 72)
        assert 0.6 <= p["r"] <= 0.85 and 0.10 <= p["delta"] <= 0.16
