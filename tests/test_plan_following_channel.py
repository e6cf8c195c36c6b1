"""bench/plan_following_channel.py: the supply's error and the monitor's reading, against the formulas written out.

The script's rows are measurements (decision 0150); these checks hold its two kinds to its docstring: the motor
driven at the setting times ``1 + e`` when the supply errs and at the setting when only the monitor does, the
monitor's reading, and one draw shared by both kinds.
"""

import numpy as np
import pytest


@pytest.fixture(scope="module")
def pf(load_bench):
    return load_bench("plan_following_channel")


def test_the_supply_errs_in_one_kind_and_only_the_monitor_in_the_other(pf):
    assert pf.driven_voltage("supply_monitor_error", 250.0, 0.02) == pytest.approx(255.0, rel=1e-15)
    assert pf.driven_voltage("supply_monitor_error", 250.0, -0.01) == pytest.approx(247.5, rel=1e-15)
    assert pf.driven_voltage("supply_monitor_decoy", 250.0, 0.02) == 250.0
    noise = np.array([0.0, 1.0, -2.0, 0.26])
    # 250 * 1.02 = 255; + 0.05 * noise; rounded to 0.01 V
    assert pf.monitor_reading(250.0, 0.02, noise).tolist() == [255.0, 255.05, 254.9, 255.01]


def test_both_kinds_draw_the_same_errors_from_one_stream_of_the_seed(pf):
    a, b = pf.draw("supply_monitor_error", 3, 72), pf.draw("supply_monitor_decoy", 3, 72)
    assert a["sigma"] == b["sigma"] and np.array_equal(a["e"], b["e"])
    assert 0.015 <= a["sigma"] <= 0.025 and a["e"].shape == (72,)
    rng = np.random.default_rng([3, 150, 0])
    sigma = rng.uniform(0.015, 0.025)
    assert a["sigma"] == sigma and np.array_equal(a["e"], sigma * rng.standard_normal(72))
    assert not np.array_equal(pf.draw("supply_monitor_error", 4, 72)["e"], a["e"])
