"""bench/blind_effects_thirteenth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
slip friction's factor against the stator's tilt, the bench supply's output under the mains, the matching capacitor
and the rests around its swap, the accelerometer's reading, the draws and the accepted regressors.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_thirteenth")


def test_the_edge_factor_is_flat_up_to_the_threshold_and_an_inverse_law_past_it(audit):
    for theta in (0.0, 0.5, -0.5, 1.0, -1.0):
        assert audit.edge_factor(theta, 1.0, 0.3) == 1.0
    assert audit.edge_factor(2.0, 1.0, 0.3) == pytest.approx(1 - 0.3 + 0.3 / 2, rel=1e-15)
    assert audit.edge_factor(-2.5, 1.0, 0.3) == pytest.approx(0.7 + 0.3 * 0.4, rel=1e-15)
    assert audit.edge_factor(2.4, 1.2, 0.25) == pytest.approx(1 - 0.25 / 2, rel=1e-15)
    t = np.linspace(1.01, 2.5, 30)
    f = audit.edge_factor(t, 1.0, 0.3)
    assert np.all(np.diff(f) < 0) and np.all(np.diff(f, 2) > 0)  # falling, convex past the threshold
    assert np.array_equal(f, audit.edge_factor(-t, 1.0, 0.3))  # even


def test_the_supply_delivers_its_setting_or_its_raw_dc_less_the_headroom(audit):
    # raw DC 66 V at 230 V mains, 2 V headroom: 64 V
    assert audit.supplied_V(67.1, 230.0, 66.0, 2.0) == pytest.approx(64.0, rel=1e-15)
    assert audit.supplied_V(60.0, 230.0, 66.0, 2.0) == 60.0
    assert audit.supplied_V(60.0, 207.0, 66.0, 2.0) == pytest.approx(66.0 * 0.9 - 2.0, rel=1e-15)
    assert audit.supplied_V(45.6, 212.0, 64.0, 2.5) == 45.6


def test_the_capacitor_is_swapped_after_its_run_and_the_rest_comes_before_the_next(audit):
    p = {"k_swap": 30, "C1_new_nF": 2.5, "rest_s": 200.0}
    assert audit.c1_of_run(p, 29, 3e-9) == 3e-9          # run 30 (1-based): the cracked part's last run
    assert audit.c1_of_run(p, 30, 3e-9) == pytest.approx(2.5e-9, rel=1e-15)  # run 31: the spare
    assert audit.c1_of_run(p, 71, 3e-9) == pytest.approx(2.5e-9, rel=1e-15)
    assert audit.c1_of_run(dict(p, C1_new_nF=None), 50, 3e-9) == 3e-9
    assert audit.rest_before(p, 30, 1.0) == 200.0
    assert audit.rest_before(p, 29, 1.0) == 1.0 and audit.rest_before(p, 31, 1.0) == 1.0
    assert audit.rest_before({}, 30, 1.0) == 1.0


def test_the_accelerometer_reads_a_first_order_filtered_acceleration_in_g(audit):
    t = np.arange(0.0, 1.0, 1e-3)
    v = 2.0 * t  # 2 m/s^2
    out = audit.accelerometer_g(t, v, 50.0, 0.01)
    assert out[0] == pytest.approx(0.01, rel=1e-15)
    e = math.exp(-2 * math.pi * 50.0 * 1e-3)
    assert out[1] == pytest.approx(0.01 + (1 - e) * 2.0 / 9.81, rel=1e-12)
    assert out[2] == pytest.approx(0.01 + (1 - e * e) * 2.0 / 9.81, rel=1e-12)
    assert out[-1] == pytest.approx(0.01 + 2.0 / 9.81, rel=1e-9)
    # a ramp of the acceleration: the filter holds each sample's acceleration over the step after it
    q = audit.accelerometer_g(t, t * t, 50.0, 0.0)  # dv/dt: 1e-3 (one-sided) at t = 0, then 2 t
    assert q[1] == pytest.approx((1 - e) * 1e-3 / 9.81, rel=1e-9)
    assert q[2] == pytest.approx((e * (1 - e) * 1e-3 + (1 - e) * 2e-3) / 9.81, rel=1e-9)


def test_the_runs_setup_scales_the_slip_friction_and_caps_the_supply(audit, load_bench):
    be = load_bench("blind_effects")
    plan, nominal, conds, factors, p, every = be.setting("mains_dropout", 1, audit.draw)
    _, V_s = audit.run_setup("mains_dropout", nominal, nominal, plan, p, 5, 324.0)
    raw = p["U230_V"] * p["mains_V"][5] / 230.0 - p["h_V"]
    assert V_s == pytest.approx(min(67.12309264141288, raw), rel=1e-9)
    q = audit.draw("tip_edge_tilt", 1, 72)
    mp, V_s = audit.run_setup("tip_edge_tilt", nominal, nominal, plan, q, 7, 290.0)
    th = abs(q["theta_mrad"][7])
    fac = 1.0 if th <= q["theta_c_mrad"] else 1 - q["a"] + q["a"] * q["theta_c_mrad"] / th
    assert V_s is None and mp.interface.mu_p == pytest.approx(nominal.interface.mu_p * fac, rel=1e-14)


def test_the_draws_stay_in_their_ranges_and_the_control_shares_the_swaps_draw(audit):
    for seed in (1, 2, 3):
        t = audit.draw("tip_edge_tilt", seed, 72)
        assert 0.8 <= t["theta_c_mrad"] <= 1.3 and 0.25 <= t["a"] <= 0.35
        assert len(t["theta_mrad"]) == 72 and np.abs(t["theta_mrad"]).max() <= 2.5
        s = audit.draw("matching_cap_swap", seed, 72)
        c = audit.draw("repair_pause_control", seed, 72)
        assert 20 <= s["k_swap"] <= 52 and 120.0 <= s["rest_s"] <= 300.0
        assert 2.4 * 0.95 <= s["C1_new_nF"] <= 2.7 * 1.05
        assert c["C1_new_nF"] is None and (c["k_swap"], c["rest_s"]) == (s["k_swap"], s["rest_s"])
        m = audit.draw("mains_dropout", seed, 72)
        assert 64.0 <= m["U230_V"] <= 68.0 and 1.5 <= m["h_V"] <= 2.5
        assert m["mains_V"].min() >= 212.0 and m["mains_V"].max() <= 248.0
        a = audit.draw("slider_accel_decoy", seed, 72)
        assert 40.0 <= a["f_c_Hz"] <= 80.0 and abs(a["bias_g"]) <= 0.02


def test_the_accepted_regressors(audit):
    assert audit.accepted("matching_cap_swap", "time_s") and audit.accepted("matching_cap_swap", "run_order")
    assert not audit.accepted("matching_cap_swap", "time_in_run_s")
    assert not audit.accepted("matching_cap_swap", "voltage")
    assert audit.accepted("mains_dropout", "mains_V") and not audit.accepted("mains_dropout", "voltage")
    assert audit.accepted("tip_edge_tilt", "stator_tilt_mrad")
    assert not audit.accepted("slider_accel_decoy", "slider_accel_g")
    assert not audit.accepted("repair_pause_control", "time_s")
