"""bench/blind_effects_fourteenth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
film's shear against the oil's dose, the second operator's hook and the handover's rest, the stage's current and the
drive's bus behind the shared leads, the breadboard's creep, the draws and the accepted regressors.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_fourteenth")


def test_the_films_shear_falls_as_the_films_inverse(audit):
    nm = 1e-12 / (3e-3 * 50e-3) * 1e9          # 1 nL over a 3 mm x 50 mm track: 6.667 nm
    assert nm == pytest.approx(20.0 / 3.0, rel=1e-12)
    assert audit.film_sigma_factor(3.5, 50.0) == pytest.approx(1.0, rel=1e-15)
    assert audit.film_sigma_factor(1.0, 50.0) == pytest.approx((50 + 3.5 * nm) / (50 + nm), rel=1e-14)
    assert audit.film_sigma_factor(6.0, 40.0) == pytest.approx((40 + 3.5 * nm) / (40 + 6 * nm), rel=1e-14)
    assert audit.film_sigma_factor(0.0, 60.0) == pytest.approx(1 + 3.5 * nm / 60, rel=1e-14)
    d = np.linspace(1.0, 6.0, 40)
    f = audit.film_sigma_factor(d, 47.0)
    assert np.all(np.diff(f) < 0) and np.all(np.diff(f, 2) > 0)   # falling, convex
    assert 1 / f == pytest.approx((47 + d * nm) / (47 + 3.5 * nm), rel=1e-12)  # its inverse is linear in the dose


def test_the_second_operators_hook_and_the_handovers_rest(audit):
    p = {"k_hand": 30, "m_h_kg": 0.008, "rest_s": 150.0}
    assert audit.load_of_run(p, 29, 0.05) == 0.05            # run 30 (1-based): the first operator's last run
    assert audit.load_of_run(p, 30, 0.05) == pytest.approx(0.058, rel=1e-14)
    assert audit.load_of_run(p, 71, -0.09) == pytest.approx(-0.098, rel=1e-14)
    assert audit.load_of_run(p, 40, 0.0) == 0.0               # no load, no hook
    assert audit.load_of_run(dict(p, m_h_kg=0.0), 50, 0.07) == 0.07
    assert audit.load_of_run({}, 50, 0.07) == 0.07
    assert audit.rest_before(p, 30, 1.0) == 150.0
    assert audit.rest_before(p, 29, 1.0) == 1.0 and audit.rest_before(p, 31, 1.0) == 1.0
    assert audit.rest_before({}, 30, 1.0) == 1.0


def test_the_stages_current_steps_at_its_times(audit):
    steps, levels = np.array([2.0, 5.0, 6.5]), np.array([1.0, 7.5, 0.2, 4.0])
    got = audit.heater_A([0.0, 1.999, 2.0, 4.9, 5.0, 6.4, 6.5, 100.0], steps, levels)
    assert got.tolist() == [1.0, 1.0, 7.5, 7.5, 0.2, 0.2, 4.0, 4.0]


def test_the_bus_behind_the_shared_leads(audit, load_bench):
    assert audit.bus_V(60.0, 0.0, 0.5, 170.0) == pytest.approx(60.0 / (1 + 0.5 / 170.0), rel=1e-15)
    assert audit.bus_V(60.0, 8.0, 0.5, 170.0) == pytest.approx((60.0 - 4.0) / (1 + 0.5 / 170.0), rel=1e-15)
    assert audit.bus_V(45.6, 5.0, 0.7, 171.7) == pytest.approx((45.6 - 3.5) / (1 + 0.7 / 171.7), rel=1e-15)
    # the bus current V_b / R_eq is the tank's real power V0^2 / (2 R_m) over V_b at V0 = G V_b
    be = load_bench("blind_effects")
    plan, nominal, *_ = be.setting("clean", 1, audit.draw)
    G = audit.drive_gain(nominal, plan)
    V_set = 67.12309264141288                    # the operator's setting for 324 V (the thirteenth audit's test)
    assert G * V_set == pytest.approx(324.0, rel=1e-9)
    R_eq = 2 * nominal.driver.R_m_ohm / G ** 2
    V_b = audit.bus_V(V_set, 3.0, 0.6, R_eq)
    assert V_b == pytest.approx(V_set - 0.6 * (3.0 + (G * V_b) ** 2 / (2 * nominal.driver.R_m_ohm) / V_b), rel=1e-12)


def test_the_boards_creep_and_settling(audit):
    assert audit.creep_lag(3.0, 0.05, 0.01, 3.0, 20.0) == pytest.approx(0.01, rel=1e-15)
    assert audit.creep_lag(23.0, 0.05, 0.01, 3.0, 20.0) == pytest.approx(0.05 - 0.04 / math.e, rel=1e-14)
    assert audit.creep_lag(1e6, -0.09, 0.02, 0.0, 20.0) == pytest.approx(-0.09, rel=1e-12)
    p = {"c_um_per_N": 3.0, "s_i": 0.3, "tau_s": 20.0, "d_s_um": 2.0}
    assert audit.board_sink_um(0.0, 0.07, 0.0, p) == pytest.approx(3.0 * 9.81 * 0.3 * 0.07, rel=1e-14)
    assert audit.board_sink_um(300.0, -0.05, -0.02, p) == pytest.approx(
        3.0 * 9.81 * (0.3 * -0.05 + 0.7 * -0.02) - 2.0 * (1 - math.exp(-1.0)), rel=1e-14)


def test_the_runs_setup(audit, load_bench):
    be = load_bench("blind_effects")
    plan, nominal, conds, factors, p, every = be.setting("oil_dose_film", 1, audit.draw)
    mp, load, V_s = audit.run_setup("oil_dose_film", nominal, nominal, plan, p, 4, 255.0, 0.03, 10.0)
    nm = 20.0 / 3.0
    fac = (p["h_r_nm"] + 3.5 * nm) / (p["h_r_nm"] + p["dose_nL"][4] * nm)
    assert mp.interface.sigma_N_s_per_m == pytest.approx(nominal.interface.sigma_N_s_per_m * fac, rel=1e-14)
    assert mp.interface.mu_p == nominal.interface.mu_p and load == 0.03 and V_s is None
    q = audit.draw("shared_lead_droop", 2, 72)
    mp, load, V_s = audit.run_setup("shared_lead_droop", nominal, nominal, plan, q, 9, 324.0, -0.05, 12.0)
    G = audit.drive_gain(nominal, plan)
    R_eq = 2 * nominal.driver.R_m_ohm / G ** 2
    for t in (0.0, 0.1, 0.37):
        i = int(np.searchsorted(q["step_s"], 12.0 + t, side="right"))
        want = (67.12309264141288 - q["R_ohm"] * q["level_A"][i]) / (1 + q["R_ohm"] / R_eq)
        assert V_s(t) == pytest.approx(want, rel=1e-9)
    assert mp is nominal and load == -0.05
    h = audit.draw("operator_hook_handover", 3, 72)
    _, load, V_s = audit.run_setup("operator_hook_handover", nominal, nominal, plan, h, h["k_hand"], 220.0, -0.07,
                                   0.0)
    assert load == pytest.approx(-0.07 - h["m_h_kg"], rel=1e-14) and V_s is None
    c = audit.draw("handover_rest_control", 3, 72)
    assert audit.run_setup("handover_rest_control", nominal, nominal, plan, c, c["k_hand"], 220.0, -0.07, 0.0)[1] \
        == -0.07


def test_the_draws_stay_in_their_ranges_and_the_control_shares_the_handovers_draw(audit):
    for seed in (1, 2, 3):
        o = audit.draw("oil_dose_film", seed, 72)
        assert 40.0 <= o["h_r_nm"] <= 60.0 and len(o["dose_nL"]) == 72
        assert o["dose_nL"].min() >= 1.0 and o["dose_nL"].max() <= 6.0
        h = audit.draw("operator_hook_handover", seed, 72)
        c = audit.draw("handover_rest_control", seed, 72)
        assert 20 <= h["k_hand"] <= 52 and 0.006 <= h["m_h_kg"] <= 0.012 and 60.0 <= h["rest_s"] <= 240.0
        assert c["m_h_kg"] == 0.0 and (c["k_hand"], c["rest_s"]) == (h["k_hand"], h["rest_s"])
        s = audit.draw("shared_lead_droop", seed, 72)
        assert 0.4 <= s["R_ohm"] <= 0.7 and 2.0 <= s["T_i_s"] <= 5.0
        assert np.all(np.diff(s["step_s"]) > 0) and s["step_s"][-1] > 1000.0
        assert s["level_A"].size == s["step_s"].size + 1 and 0.0 <= s["level_A"].min() and s["level_A"].max() <= 8
        d = audit.draw("pad_creep_decoy", seed, 72)
        assert 2.0 <= d["c_um_per_N"] <= 4.0 and 0.2 <= d["s_i"] <= 0.4
        assert 10.0 <= d["tau_s"] <= 30.0 and 1.0 <= d["d_s_um"] <= 3.0


@pytest.fixture(scope="module")
def decoy_case(audit):
    return audit.experiment("pad_creep_decoy", 1)


def test_the_decoys_column_carries_the_lag_across_runs_and_pauses(audit, decoy_case):
    df, truth, nominal, plan = decoy_case
    p = truth["parameters"]
    y, t_y = 0.0, -1.0
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        t, L = run["time_s"].to_numpy(), float(run["load_kg"].iloc[0])
        ys = L + (y - L) * np.exp(-(t - t_y) / p["tau_s"])
        clean = (p["c_um_per_N"] * 9.81 * (p["s_i"] * L + (1 - p["s_i"]) * ys)
                 - p["d_s_um"] * (1 - np.exp(-t / 300.0)))
        noise = np.random.default_rng([1, 162, k - 1]).standard_normal(len(t))
        assert run["board_sink_um"].to_numpy() == pytest.approx(np.round(clean + 0.05 * noise, 2), abs=1e-9)
        y, t_y = float(ys[-1]), float(t[-1])
    assert df["speed_m_s"].notna().all()


def test_the_accepted_regressors(audit):
    assert audit.accepted("oil_dose_film", "oil_dose_nL") and not audit.accepted("oil_dose_film", "load")
    assert audit.accepted("shared_lead_droop", "run_level_stage_heater_A")
    assert not audit.accepted("shared_lead_droop", "voltage")
    for name in ("time_s", "run_order", "since_break_s", "smooth_time_x_load", "segment"):
        assert audit.accepted("operator_hook_handover", name)
    for name in ("time_in_run_s", "load", "voltage"):
        assert not audit.accepted("operator_hook_handover", name)
    assert not audit.accepted("pad_creep_decoy", "board_sink_um")
    assert not audit.accepted("handover_rest_control", "time_s")
