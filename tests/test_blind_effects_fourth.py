"""bench/blind_effects_fourth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
run-in hump, the one-way capstan, the proxy's correlation with the cause and the water activity at the bar.
"""

import math

import numpy as np
import pytest

@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_fourth")


def test_runin_hump_peaks_at_s1_and_falls_back(audit):
    H, S1 = 0.2, 1.3
    assert audit.runin_factor(0.0, H, S1) == 1.0
    assert audit.runin_factor(S1, H, S1) == pytest.approx(1 + H, rel=1e-12)
    S = np.linspace(0, 4.0, 401)
    f = np.array([audit.runin_factor(s, H, S1) for s in S])
    assert S[np.argmax(f)] == pytest.approx(S1, abs=0.01)
    assert f[-1] < f.max() and f[-1] == pytest.approx(1 + H * (4.0 / S1) * math.exp(1 - 4.0 / S1), rel=1e-12)


def test_capstan_ratio_and_draws(audit):
    for seed in (1, 2, 3):
        p = audit.draw("eyelet_capstan", seed, 72)
        assert 0.15 <= p["mu_c"] <= 0.20 and math.radians(80) <= p["theta_rad"] <= math.radians(110)
        assert p["pulley_mu_fwd"] == pytest.approx(math.exp(p["mu_c"] * p["theta_rad"]) - 1, rel=1e-12)


def test_air_temperature_is_a_proxy_of_the_bar(audit):
    p = audit.draw("oil_viscosity_proxy", 1, 2000)
    r = np.corrcoef(p["T_bar"], p["T_air"])[0, 1]
    assert 0.6 < r < 0.9 and r < 0.999
    assert p["T_bar"].min() >= 15 and p["T_bar"].max() <= 35


def test_water_activity_against_magnus_written_out(audit):
    # at the plate's own temperature the activity is the relative humidity
    assert float(audit.water_activity(40.0, audit.BAR_PLATE_DEGC)) == pytest.approx(0.40, rel=1e-12)
    # colder air holds less vapour: at 20 degC and 50 % RH, e(20)/e(27) from the Magnus formula
    e = lambda T: 6.112 * math.exp(17.62 * T / (243.12 + T))  # noqa: E731
    assert float(audit.water_activity(50.0, 20.0)) == pytest.approx(0.5 * e(20.0) / e(27.0), rel=1e-12)
    assert 0.5 * e(20.0) / e(27.0) == pytest.approx(0.33, abs=0.01)   # 2.34 kPa / 3.57 kPa at 50 %


def test_the_cause_control_draws_the_proxy_s_world(audit):
    for seed in (1, 2):
        proxy, cause = audit.draw("oil_viscosity_proxy", seed, 72), audit.draw("oil_viscosity_cause", seed, 72)
        assert np.array_equal(proxy["T_bar"], cause["T_bar"]) and proxy["b_per_K"] == cause["b_per_K"]
