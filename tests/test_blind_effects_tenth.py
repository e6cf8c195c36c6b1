"""bench/blind_effects_tenth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
preload on a crowned bar's track, the wipes' friction and rests, where a hooked weight rests on the table, and the
scope's autoset scale.
"""

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_tenth")


def test_crowned_preload_falls_with_the_square_of_the_offset_from_the_apex(audit):
    P0, k_p, y0, R = 6.35, 7.5e4, 0.2e-3, 0.08
    # on the apex: the motor's preload
    assert audit.crowned_preload_N(P0, k_p, y0, y0, R) == pytest.approx(P0, rel=1e-15)
    # 1.2 mm off it: the surface lies (1.2 mm)^2 / (2 x 80 mm) = 9 um lower, the spring gives 7.5e4 x 9e-6 = 0.675 N
    got = audit.crowned_preload_N(P0, k_p, np.array([y0 + 1.2e-3, y0 - 1.2e-3]), y0, R)
    assert got == pytest.approx([P0 - 0.675, P0 - 0.675], rel=1e-12)
    # even about the apex, never above P0
    y = np.linspace(-1.5e-3, 1.5e-3, 31)
    assert np.all(audit.crowned_preload_N(P0, k_p, y, 0.0, R) <= P0)


def test_wipes_reset_the_count_and_the_friction_recovers_by_traverse(audit):
    assert list(audit.wipe_counts(10, 4)) == [0, 1, 2, 3, 0, 1, 2, 3, 0, 1]
    # 1 + W q^n at W 0.15, q 0.5: 1.15, 1.075, 1.0375
    assert audit.wipe_factor([0, 1, 2], 0.15, 0.5) == pytest.approx([1.15, 1.075, 1.0375], rel=1e-15)


def test_a_wipe_lengthens_the_rest_before_its_run_only(audit):
    wipe = np.arange(10, dtype=float) + 20.0          # 20, 21, ... s per run
    # runs 1..9 after the first (indices 1..9); wiped runs at indices 4 and 8 (every 4)
    got = audit.run_pauses_s(10, 1.0, wipe, 4)
    assert got == pytest.approx([1.0, 1.0, 1.0, 24.0, 1.0, 1.0, 1.0, 28.0, 1.0], abs=0)


def test_the_weight_rests_within_its_zone_of_its_pulleys_end(audit):
    # h_m 0.3 m/kg, c 6 mm: zones 3, 9, 15, 21 mm for 30, 50, 70, 90 g; none at 10 g or without a load
    assert audit.touchdown_zone_m([0.03, -0.05, 0.07, -0.09], 0.3, 6e-3) == pytest.approx(
        [3e-3, 9e-3, 15e-3, 21e-3], rel=1e-12)
    assert audit.touchdown_zone_m([0.01, 0.0], 0.3, 6e-3) == pytest.approx([0.0, 0.0], abs=0)
    s = np.array([-0.021, -0.013, -0.011, 0.0, 0.011, 0.013, 0.021])
    # a positive load pulls toward -position: it rests within 9 mm of -21 mm (s < -12 mm)
    assert list(audit.weight_rests(s, 0.05, 9e-3, -0.021, 0.021)) == [True, True, False, False, False, False, False]
    # a negative one within 9 mm of +21 mm (s > +12 mm)
    assert list(audit.weight_rests(s, -0.05, 9e-3, -0.021, 0.021)) == [False, False, False, False, False, True, True]
    assert not np.any(audit.weight_rests(s, 0.0, 9e-3, -0.021, 0.021))


def test_autoset_takes_the_smallest_scale_that_fits(audit):
    # 2 V0 / scale <= D: at D = 6, 2 x 290 / 100 = 5.8 fits, 2 x 324 / 100 = 6.48 does not
    got = audit.scope_scale_V_div(np.array([220.0, 255.0, 290.0, 324.0]), 6.0)
    assert got == pytest.approx([100.0, 100.0, 100.0, 200.0], abs=0)
    assert audit.scope_scale_V_div(290.0, 5.5) == 200.0
    assert audit.scope_scale_V_div(100.0, 5.5) == 50.0


def test_draws_lie_in_their_ranges(audit):
    for seed in (1, 2, 3):
        p = audit.draw("bar_crown_track", seed, 72)
        assert 0.06 <= p["R_m"] <= 0.10 and -0.3e-3 <= p["y0_m"] <= 0.3e-3
        assert np.all(np.abs(p["y_m"]) <= 1.5e-3) and p["y_m"].size == 72
        p = audit.draw("track_wipe_protocol", seed, 72)
        assert 0.12 <= p["W"] <= 0.20 and 0.40 <= p["q"] <= 0.60
        assert np.all((p["wipe_pause_s"] >= 20) & (p["wipe_pause_s"] <= 40))
        p = audit.draw("weight_touchdown", seed, 72)
        assert 0.25 <= p["h_m_per_kg"] <= 0.35 and 4e-3 <= p["c_m"] <= 8e-3
        assert 5.0 <= audit.draw("scope_scale_decoy", seed, 72)["D_div"] <= 6.4


def test_touchdown_traverse_steps_the_load_at_the_zones_edge(audit):
    import blind_effects as be
    from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor
    plan = be.plan_of(1)
    mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    zone, L = 10e-3, 0.09        # a positive load rests below s = -21 + 10 = -11 mm
    for d in (-1, 1):
        whole = audit.traverse_load(mp, mp, plan, 290.0, d, L if d < 0 else 0.0)
        r, t_c = audit.traverse_touchdown(mp, mp, plan, 290.0, L, d, zone)
        s_c = np.interp(t_c, r["time"], r["Slider.s"])
        assert s_c == pytest.approx(-11e-3, abs=0.5e-3)   # the step at the zone's edge (one 1 ms step of motion)
        before = r["time"] < t_c - 1e-9
        # the same motion as the run with the start's load until the crossing, another one after it
        assert r["Slider.s"][before] == pytest.approx(whole["Slider.s"][:before.sum()], abs=1e-12)
        n = min(len(r["time"]), len(whole["time"]))
        assert np.max(np.abs(r["Slider.s"][:n] - whole["Slider.s"][:n])) > 1e-4


def test_probe_pulley_distance_is_measured_from_the_loads_pulley_end(load_bench):
    probe = load_bench("blind_effects_tenth_probe")
    s = np.array([-0.021, 0.0, 0.021])
    assert probe.pulley_distance_mm(s, np.full(3, 0.05)) == pytest.approx([0.0, 21.0, 42.0], abs=1e-12)
    assert probe.pulley_distance_mm(s, np.full(3, -0.05)) == pytest.approx([42.0, 21.0, 0.0], abs=1e-12)
    assert probe.pulley_distance_mm(s, np.zeros(3)) == pytest.approx([0.0, 0.0, 0.0], abs=0)
