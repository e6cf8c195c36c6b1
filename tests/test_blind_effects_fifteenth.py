"""bench/blind_effects_fifteenth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
sensing electrode's shunt on both modes, the re-seat walk at the weight changes, the purged hood's humidity and the
friction it sets, the weight tray's balance, the draws and the accepted regressors.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_fifteenth")


def test_the_shunts_bell_of_damping_and_step_of_stiffness(audit):
    f, C = 48500.0, 0.3e-9
    R1 = 1.0 / (2 * math.pi * f * C)                       # rho = 1: 10.94 kOhm
    m = audit.shunt_modes(R1, f, C, 0.004, 0.005)
    assert m["rho"] == pytest.approx(1.0, rel=1e-14)
    assert m["dzeta_l"] == pytest.approx(0.004 / 4, rel=1e-14) and m["dzeta_b"] == pytest.approx(0.005 / 4, rel=1e-14)
    assert m["f_l_factor"] == pytest.approx(1 - 0.004 / 4, rel=1e-14)
    assert m["f_b_factor"] == pytest.approx(1 - 0.005 / 4, rel=1e-14)
    m = audit.shunt_modes(3 * R1, f, C, 0.004, 0.005)      # rho = 3
    assert m["dzeta_b"] == pytest.approx(0.005 * 3 / 20, rel=1e-12)
    assert m["f_l_factor"] == pytest.approx(1 - 0.004 / 20, rel=1e-12)
    R = np.logspace(3, 6, 61)
    dz = np.array([audit.shunt_modes(r, f, C, 0.004, 0.005)["dzeta_b"] for r in R])
    ff = np.array([audit.shunt_modes(r, f, C, 0.004, 0.005)["f_b_factor"] for r in R])
    i = int(np.argmax(dz))
    assert abs(R[i] / R1 - 1) < 0.13 and 0 < i < len(R) - 1       # a bell, largest at rho = 1
    assert np.all(np.diff(ff) > 0) and ff[-1] == pytest.approx(1.0, abs=1e-6)   # open: the motor's own
    assert ff[0] == pytest.approx(1 - 0.005 / (2 * (1 + (1e3 / R1) ** 2)), rel=1e-12)


def test_the_walk_steps_at_the_weight_changes_only(audit):
    loads = [0.05, 0.05, 0.05, 0.05, -0.05, -0.05, 0.0, 0.0, 0.0, 0.0, 0.09]
    assert audit.handlings(loads).tolist() == [False, False, False, False, True, False, True, False, False, False,
                                               True]
    z = np.array([5.0, 1.0, -2.0, 3.0, 0.5, 9.0, -1.5, 2.0, 2.0, 2.0, 0.25])
    w = audit.walk(loads, z, 0.02)
    want = [0.0, 0.0, 0.0, 0.0, 0.01, 0.01, -0.02, -0.02, -0.02, -0.02, -0.015]
    assert w == pytest.approx(want, abs=1e-15)


def test_the_hoods_humidity_against_its_closed_form(audit):
    p = {"V_h_L": 0.1, "q_l_L_min": 0.8, "RH_0": 44.0, "a_pct": 3.0, "P_s": 200.0, "phi": 0.7}
    assert audit.rh_lab(50.0, p) == pytest.approx(44.0 + 3.0 * math.sin(2 * math.pi * 0.25 + 0.7), rel=1e-14)
    for Q, t0, t1, rh0 in ((0.0, 0.0, 3.0, 44.0), (2.5, 10.0, 11.3, 30.0), (4.0, -1.0, 40.0, 5.0)):
        tau = 60 * 0.1 / (0.8 + Q)
        s = 0.8 / (0.8 + Q)
        w = 2 * math.pi / 200.0
        part = lambda t: s * (44.0 + 3.0 * (math.sin(w * t + 0.7) - w * tau * math.cos(w * t + 0.7))  # noqa: E731
                              / (1 + (w * tau) ** 2))
        want = part(t1) + (rh0 - part(t0)) * math.exp(-(t1 - t0) / tau)
        assert audit.hood_rh_step(rh0, t0, t1, Q, p) == pytest.approx(want, abs=2e-4)


def test_the_purges_friction_factor(audit):
    th = lambda a, K: K * a / (1 + K * a)  # noqa: E731
    assert audit.purge_mu_factor(45.0, 4.0, 0.2) == pytest.approx(1.0, rel=1e-15)
    assert audit.purge_mu_factor(10.0, 4.0, 0.2) == pytest.approx(1 + 0.2 * (th(0.45, 4) - th(0.1, 4)) / th(0.45, 4),
                                                                  rel=1e-14)
    assert audit.purge_mu_factor(0.0, 5.0, 0.25) == pytest.approx(1.25, rel=1e-14)
    f = audit.purge_mu_factor(np.linspace(5, 60, 30), 3.5, 0.2)
    assert np.all(np.diff(f) < 0) and np.all(np.diff(f, 2) > 0)      # drier: more friction, saturating


def test_the_trays_balance(audit):
    p = {"tau_b_s": 0.8, "c_d_g_per_100s": 0.3}
    assert audit.tray_filter(5.0, 190.0, 240.0, 5.0, p) == pytest.approx(240.0, rel=1e-15)
    assert audit.tray_filter(5.8, 190.0, 240.0, 5.0, p) == pytest.approx(190.0 + 50.0 / math.e, rel=1e-14)
    assert audit.tray_reading(50.0, 170.0, 150.0, 10.0, p) == pytest.approx(
        170.0 - 20.0 * math.exp(-40.0 / 0.8) + 0.15, rel=1e-14)


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    plan, nominal, conds, factors, p, every = be.setting("sense_electrode_shunt", 2, audit.draw)
    st = nominal.stator
    mp = audit.run_motor("sense_electrode_shunt", nominal, plan, p, 5, {"w": 0.0, "rh": None})
    rho = p["R_ohm"][5] * 2 * math.pi * 48500.0 * p["C_s_F"]
    assert mp.stator.zeta_b == pytest.approx(st.zeta_b + p["k2_b"] * rho / (2 * (1 + rho ** 2)), rel=1e-14)
    assert mp.stator.zeta_l == pytest.approx(st.zeta_l + p["k2_l"] * rho / (2 * (1 + rho ** 2)), rel=1e-14)
    assert mp.stator.f_b0_Hz == pytest.approx(st.f_b0_Hz * (1 - p["k2_b"] / (2 * (1 + rho ** 2))), rel=1e-14)
    assert mp.stator.f_l0_Hz == pytest.approx(st.f_l0_Hz * (1 - p["k2_l"] / (2 * (1 + rho ** 2))), rel=1e-14)
    assert mp.interface.mu_p == nominal.interface.mu_p
    mp = audit.run_motor("handling_reseat_walk", nominal, plan, {}, 0, {"w": -0.03, "rh": None})
    assert mp.interface.mu_p == pytest.approx(0.97 * nominal.interface.mu_p, rel=1e-14)
    q = {"K": 4.0, "D": 0.2}
    for kind in ("purge_flow_proxy", "purge_rh_cause"):
        mp = audit.run_motor(kind, nominal, plan, q, 0, {"w": 0.0, "rh": 20.0})
        assert mp.interface.mu_p == pytest.approx(
            nominal.interface.mu_p * (1 + 0.2 * (1 - (0.8 / 1.8) / (1.8 / 2.8))), rel=1e-14)
    assert audit.run_motor("weight_tray_decoy", nominal, plan, {}, 0, {"w": 0.0, "rh": 20.0}) is nominal


def test_the_draws_stay_in_their_ranges_and_the_control_shares_the_proxys_draw(audit):
    for seed in (1, 2, 3):
        s = audit.draw("sense_electrode_shunt", seed, 72)
        assert 0.2e-9 <= s["C_s_F"] <= 0.4e-9 and 0.003 <= s["k2_l"] <= 0.006 and 0.003 <= s["k2_b"] <= 0.006
        assert s["R_ohm"].min() >= 995.0 and s["R_ohm"].max() <= 1e6 and len(s["R_ohm"]) == 72
        assert all(float(f"{r:.3g}") == r for r in s["R_ohm"])
        w = audit.draw("handling_reseat_walk", seed, 72)
        assert 0.015 <= w["s"] <= 0.025 and len(w["z"]) == 72
        p = audit.draw("purge_flow_proxy", seed, 72)
        c = audit.draw("purge_rh_cause", seed, 72)
        assert 0.05 <= p["V_h_L"] <= 0.15 and 0.5 <= p["q_l_L_min"] <= 1.0 and 40 <= p["RH_0"] <= 50
        assert 2 <= p["a_pct"] <= 5 and 150 <= p["P_s"] <= 250 and 3 <= p["K"] <= 6 and 0.15 <= p["D"] <= 0.25
        assert p["Q_L_min"].min() >= 0.0 and p["Q_L_min"].max() <= 4.0
        assert c["Q_L_min"].tolist() == p["Q_L_min"].tolist() and c["D"] == p["D"] and c["phi"] == p["phi"]
        d = audit.draw("weight_tray_decoy", seed, 72)
        assert 0.4 <= d["tau_b_s"] <= 1.2 and -0.5 <= d["c_d_g_per_100s"] <= 0.5


@pytest.fixture(scope="module")
def cause_case(audit):
    return audit.experiment("purge_rh_cause", 1)


@pytest.fixture(scope="module")
def tray_case(audit):
    return audit.experiment("weight_tray_decoy", 2)


def test_the_causes_column_and_friction_follow_the_hood_across_runs(audit, cause_case, load_bench):
    df, truth, nominal, plan = cause_case
    p = truth["parameters"]
    factors = load_bench("blind_effects").setting("purge_rh_cause", 1, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    th = lambda rh: p["K"] * rh / 100 / (1 + p["K"] * rh / 100)  # noqa: E731
    rh, t_prev = p["RH_0"] + p["a_pct"] * math.sin(2 * math.pi * -1.0 / p["P_s"] + p["phi"]), -1.0
    for k in (1, 2, 3, 4):
        run = df[df["run"] == k]
        t = run["time_s"].to_numpy()
        Q = p["Q_L_min"][k - 1]
        rh = audit.hood_rh_step(rh, t_prev, t[0], Q, p)       # the flow set one pause before the run
        pr = truth["per_run"][k - 1]
        assert pr["rh_pct"] == pytest.approx(rh, rel=1e-12)
        mu = scattered_motor(nominal, factors[k - 1]).interface.mu_p
        assert pr["mu_p"] == pytest.approx(mu * (1 + p["D"] * (th(45.0) - th(rh)) / th(45.0)), rel=1e-13)
        got = np.array([audit.hood_rh_step(rh, t[0], x, Q, p) if x > t[0] else rh for x in t])
        noise = np.random.default_rng([1, 172, k - 1]).standard_normal(len(t))
        assert run["hood_rh_pct"].to_numpy() == pytest.approx(np.round(got + 0.3 * noise, 2), abs=0.0101)
        rh, t_prev = audit.hood_rh_step(rh, t[0], t[-1], Q, p), t[-1]


def test_the_decoys_column_follows_the_rack_and_its_filter(audit, tray_case):
    df, truth, nominal, plan = tray_case
    p = truth["parameters"]
    y, t_sw, target, prev = 240.0, -1.0, 240.0, None
    for k in range(1, 9):
        run = df[df["run"] == k]
        t, L = run["time_s"].to_numpy(), float(run["load_kg"].iloc[0])
        if prev is None or L != prev:
            swap = t[0] - 1.0
            y = target + (y - target) * math.exp(-(swap - t_sw) / p["tau_b_s"])
            target, t_sw = 240.0 - 1000 * abs(L), swap
        clean = target + (y - target) * np.exp(-(t - t_sw) / p["tau_b_s"]) + p["c_d_g_per_100s"] * t / 100
        noise = np.random.default_rng([2, 172, k - 1]).standard_normal(len(t))
        assert run["tray_mass_g"].to_numpy() == pytest.approx(np.round(clean + 0.02 * noise, 2), abs=1e-9)
        prev = L
    assert all(r["w"] == 0.0 for r in truth["per_run"])


def test_the_accepted_regressors(audit):
    assert audit.accepted("sense_electrode_shunt", "sense_shunt_ohm")
    assert audit.accepted("sense_electrode_shunt", "run_level_sense_shunt_ohm")
    assert not audit.accepted("sense_electrode_shunt", "voltage")
    assert audit.accepted("purge_flow_proxy", "purge_flow_L_min_lag10r")
    assert not audit.accepted("purge_flow_proxy", "load") and not audit.accepted("purge_flow_proxy", "time_s")
    for name in ("time_s", "run_order", "since_break_s", "smooth_time_x_load", "segment", "breaks_before"):
        assert audit.accepted("handling_reseat_walk", name)
    for name in ("time_in_run_s", "load", "voltage", "load_kg_lag1r"):
        assert not audit.accepted("handling_reseat_walk", name)
    assert not audit.accepted("weight_tray_decoy", "tray_mass_g")
    assert audit.accepted("purge_rh_cause", "hood_rh_pct") and not audit.accepted("purge_rh_cause", "purge_flow")
