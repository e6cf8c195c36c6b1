"""bench/blind_effects_twentieth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
lining's grit (its Poisson shedding and its ploughing share ground away with the sliding), the guide's ultrasonic
dither (Littmann's law and the force that stands for it), the matching capacitor's Curie-Weiss share, the weight's
sway, the draws, the made data, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twentieth")


def poisson_cdf(k, mean):
    return sum(math.exp(-mean) * mean ** j / math.factorial(j) for j in range(k + 1))


def test_the_grits_shedding_and_ploughing(audit):
    assert audit.poisson_count(0.999, 0.0) == 0
    mean = 0.2
    assert audit.poisson_count(0.5, mean) == 0                       # below e^-0.2 = 0.8187
    assert audit.poisson_count(poisson_cdf(0, mean) + 1e-6, mean) == 1
    assert audit.poisson_count(poisson_cdf(1, mean) - 1e-6, mean) == 1
    assert audit.poisson_count(poisson_cdf(1, mean) + 1e-6, mean) == 2
    u = np.random.default_rng(5).uniform(0, 1, 20000)
    assert np.mean([audit.poisson_count(x, 0.7) for x in u]) == pytest.approx(0.7, abs=0.02)
    assert audit.sliding_m(290.0, 0.3) == pytest.approx(0.2 * 290 / 324 * 0.3, rel=1e-15)
    entries = [(0.10, 0.08), (0.25, 0.11)]
    assert audit.plough_share(0.30, entries, 0.04) == pytest.approx(
        0.08 * math.exp(-0.20 / 0.04) + 0.11 * math.exp(-0.05 / 0.04), rel=1e-14)
    assert audit.plough_share(0.25, [(0.25, 0.11)], 0.04) == pytest.approx(0.11, rel=1e-15)
    assert audit.plough_share(1.0, [], 0.04) == 0.0


def test_littmanns_law(audit):
    assert audit.dither_speed_m_s(1.2, 25e3) == pytest.approx(2 * math.pi * 25e3 * 1.2e-6, rel=1e-15)
    V_d = 0.15
    for v in (0.0, 0.03, 0.1, 0.1499):
        assert float(audit.littmann_share(v, V_d)) == pytest.approx(2 / math.pi * math.asin(v / V_d), rel=1e-13,
                                                                    abs=1e-15)
        assert float(audit.littmann_share(-v, V_d)) == pytest.approx(2 / math.pi * math.asin(v / V_d), rel=1e-13,
                                                                     abs=1e-15)
    for v in (0.15, 0.2, -0.3):
        assert float(audit.littmann_share(v, V_d)) == 1.0
    assert float(audit.littmann_share(0.05, 0.0)) == 1.0              # no dither: the guide's own friction


def preload_at(s, mp):
    sp = mp.stator
    xi = s / sp.bar_half_length_m
    dev = xi * (sp.bar_dev_1_m + sp.bar_dev_3_m * (2.5 * xi * xi - 1.5)) + sp.bar_dev_2_m * (1.5 * xi * xi - 0.5)
    return sp.alpha0 * (sp.P0_N + sp.preload_stiffness_N_per_m * dev)


def test_the_dithers_force(audit, load_bench):
    nominal = load_bench("blind_effects").setting("clean", 1, audit.draw)[1]
    sl = nominal.slider
    V_d, x = 0.2, 0.4
    for s, v in ((0.0, 0.1), (0.01, -0.05), (-0.015, 0.19)):
        N = sl.kappa * preload_at(s, nominal) + 9.81 * sl.mass_kg
        want = math.copysign(1, v) * x * sl.mu_sd * N * (1 - 2 / math.pi * math.asin(abs(v) / V_d))
        assert audit.dither_force_N(s, v, nominal, V_d, x) == pytest.approx(want, rel=1e-12)
    assert audit.dither_force_N(0.0, 0.0, nominal, V_d, x) == 0.0     # at rest: the static level is the motor's
    assert audit.dither_force_N(0.0, 0.25, nominal, V_d, x) == 0.0    # faster than the dither
    assert audit.dither_force_N(0.0, 0.1, nominal, 0.0, x) == 0.0     # no dither


def test_the_capacitors_curie_weiss_share(audit):
    y, theta = 0.2, 5.0
    assert float(audit.cap_factor(25.0, y, theta)) == pytest.approx(1.0, rel=1e-15)
    for T in (18.0, 30.0, 40.0):
        assert float(audit.cap_factor(T, y, theta)) == pytest.approx(1 - y + y * (25 - theta) / (T - theta),
                                                                     rel=1e-14)
    assert float(audit.cap_factor(18.0, y, theta)) > 1 > float(audit.cap_factor(40.0, y, theta))


def test_the_weights_sway(audit):
    t = np.array([3.0, 10.0, 40.0])
    assert audit.sway_mm(t, 2.0, 5.0, 60.0) == pytest.approx(5.0 * np.exp(-(t - 2.0) / 60.0), rel=1e-14)
    assert float(audit.sway_mm(2.0, 2.0, 5.0, 60.0)) == 5.0


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    nominal = be.setting("clean", 1, audit.draw)[1]
    for kind in ("lining_grit_ploughing", "lining_grit_logged"):
        mp, law = audit.run_motor(kind, nominal, {}, 3, 0.05, 0.07)
        assert mp.interface.mu_p == pytest.approx(nominal.interface.mu_p * 1.07, rel=1e-15) and law is None
        assert mp.stator.P0_N == nominal.stator.P0_N and mp.slider.mu_sd == nominal.slider.mu_sd
    p = {"f_u_Hz": 25e3, "x_share": 0.4, "a_um": [0.2, 1.2]}
    mp, law = audit.run_motor("guide_ultrasonic_dither", nominal, p, 1, -0.07)
    sl, m2 = nominal.slider, nominal.slider.mass_kg + 0.07
    assert mp.slider.mass_kg == pytest.approx(m2, rel=1e-15) and mp.slider.load_inertia == 0.0
    assert mp.slider.mu_sd * (mp.slider.kappa * 5.0 + 9.81 * m2) == pytest.approx(
        sl.mu_sd * (sl.kappa * 5.0 + 9.81 * sl.mass_kg), rel=1e-13)   # the guide's friction is the motor's
    V_d = 2 * math.pi * 25e3 * 1.2e-6
    N = sl.kappa * preload_at(0.004, nominal) + 9.81 * sl.mass_kg
    F = -0.4 * sl.mu_sd * N * (1 - 2 / math.pi * math.asin(0.08 / V_d))
    assert law(0.1, 0.004, -0.08) == pytest.approx(-0.07 - F / 9.81, rel=1e-12)
    p = {"T": [40.0], "y": 0.2, "theta_C": 5.0}
    mp, law = audit.run_motor("match_cap_curie_weiss", nominal, p, 0, 0.0)
    assert mp.driver.C1_F == pytest.approx(3.0e-9 * (0.8 + 0.2 * 20 / 35), rel=1e-14) and law is None
    assert mp.interface.mu_p == nominal.interface.mu_p and mp.driver.L_H == nominal.driver.L_H
    assert audit.run_motor("weight_sway_decoy", nominal, {}, 3, 0.05) == (nominal, None)


def test_the_draws_stay_in_their_ranges(audit):
    a = np.concatenate([audit.draw("guide_ultrasonic_dither", seed, 72)["a_um"] for seed in (1, 2, 3)])
    assert a.min() < 0.03 and a.max() > 1.45 and a.max() <= 1.5
    T = np.concatenate([audit.draw("match_cap_curie_weiss", seed, 72)["T"] for seed in (1, 2, 3)])
    assert T.min() < 19 and T.max() > 39 and 18 <= T.min() and T.max() <= 40
    for seed in (1, 2, 3):
        g = audit.draw("lining_grit_ploughing", seed, 72)
        assert 3.0 <= g["lam_per_m"] <= 5.0 and 0.03 <= g["S_g_m"] <= 0.06
        assert 0.06 <= g["c_pool"].min() and g["c_pool"].max() <= 0.12 and len(g["c_pool"]) == 288
        c = audit.draw("lining_grit_logged", seed, 72)
        assert c.keys() == g.keys() and all(np.array_equal(c[k], g[k]) for k in g)   # the control shares the draw
        d = audit.draw("guide_ultrasonic_dither", seed, 72)
        assert 20e3 <= d["f_u_Hz"] <= 28e3 and 0.3 <= d["x_share"] <= 0.5
        m = audit.draw("match_cap_curie_weiss", seed, 72)
        assert 0.15 <= m["y"] <= 0.25 and 0 <= m["theta_C"] <= 10
        w = audit.draw("weight_sway_decoy", seed, 72)
        assert 30 <= w["tau_s"] <= 90 and 2 <= w["A_h_mm"].min() and w["A_h_mm"].max() <= 8


def test_the_grits_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 24
    df, truth, nominal, plan = audit.experiment("lining_grit_ploughing", 1, first=first)
    p = truth["parameters"]
    factors = be.setting("lining_grit_ploughing", 1, audit.draw)[3]
    pr = truth["per_run"]
    S, entries, used = 0.0, [], 0
    for k in range(first):
        share = sum(c * math.exp(-(S - S_j) / p["S_g_m"]) for S_j, c in entries)
        assert pr[k]["plough_share"] == pytest.approx(share, rel=1e-12, abs=1e-15)
        mp = scattered_motor(nominal, factors[k])
        assert pr[k]["mu_p"] == pytest.approx(mp.interface.mu_p * (1 + share), rel=1e-14)
        V = float(df[df["run"] == k + 1]["voltage_V"].iloc[0])
        dS = 0.2 * V / 324 * pr[k]["duration_s"]
        assert pr[k]["S_m"] == pytest.approx(S, rel=1e-12, abs=1e-15)
        n = 0
        while p["u_count"][k] > poisson_cdf(n, p["lam_per_m"] * dS):
            n += 1
        assert pr[k]["shed"] == n
        for _ in range(n):
            entries.append((S + dS, p["c_pool"][used]))
            used += 1
        S += dS
    assert used > 0 and sum(q["plough_share"] > 0 for q in pr) > 0       # grit met at least once
    ctl = audit.experiment("lining_grit_logged", 1, first=first)[0]
    for k in range(first):
        assert set(ctl[ctl["run"] == k + 1]["grit_plough_pct"]) == {round(100 * pr[k]["plough_share"], 2)}
    assert ctl["speed_m_s"].to_numpy() == pytest.approx(df["speed_m_s"].to_numpy(), abs=0)   # the same motion


def test_the_dithers_and_the_capacitors_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    b5 = load_bench("blind_effects_fifth")
    from l1b2.rig.experiment import scattered_motor
    from l1b2.physics import driver as drv
    from l1b2.cosim.engine import InProcessMotor
    df, truth, nominal, plan = audit.experiment("guide_ultrasonic_dither", 2, first=3)
    p = truth["parameters"]
    factors = be.setting("guide_ultrasonic_dither", 2, audit.draw)[3]
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        noise = np.random.default_rng([2, 222, k - 1]).standard_normal(len(run))
        assert run["rail_dither_um"].to_numpy() == pytest.approx(np.round(p["a_um"][k - 1] + 0.005 * noise, 3),
                                                                 abs=1e-12)
    # run 2's motion, rebuilt here: the load law written out, through the fifth audit's state input
    k = 2
    run = df[df["run"] == k]
    V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
    mp0 = scattered_motor(nominal, factors[k - 1])
    sl = mp0.slider
    V_d, x = 2 * math.pi * p["f_u_Hz"] * p["a_um"][k - 1] * 1e-6, p["x_share"]

    def law(t, s, v):
        if v == 0:
            return L
        N = sl.kappa * preload_at(s, mp0) + 9.81 * sl.mass_kg
        share = 2 / math.pi * math.asin(min(1.0, abs(v) / V_d)) if abs(v) < V_d else 1.0
        return L - math.copysign(1, v) * x * sl.mu_sd * N * (1 - share) / 9.81
    m2 = sl.mass_kg + sl.load_inertia * abs(L)
    mp = mp0.replace(slider__mass_kg=m2, slider__load_inertia=0.0, slider__mu_sd=sl.mu_sd * sl.mass_kg / m2,
                     slider__mu_ss=sl.mu_ss * sl.mass_kg / m2, slider__kappa=sl.kappa * m2 / sl.mass_kg)
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    u = b5.StateInput(law, s0)
    m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=int(d), m_load=u, s0=s0)
    u.motor = m
    r = m.run(plan.max_run_s, record=("Slider.s",), until=lambda mm: mm.value("Slider.at_stop") == d)
    assert truth["per_run"][k - 1]["duration_s"] == float(r["time"][-1])
    idx = np.arange(0, len(r["time"]), be.sampling_every(plan))
    pos = np.round(np.round(r["Slider.s"][idx] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
    df, truth, nominal, plan = audit.experiment("match_cap_curie_weiss", 3, first=2)
    p = truth["parameters"]
    for k in (1, 2):
        run = df[df["run"] == k]
        noise = np.random.default_rng([3, 222, k - 1]).standard_normal(len(run))
        assert run["match_cap_temp_C"].to_numpy() == pytest.approx(np.round(p["T"][k - 1] + 0.05 * noise, 2),
                                                                   abs=1e-9)
        T, y, th = p["T"][k - 1], p["y"], p["theta_C"]
        assert truth["per_run"][k - 1]["C1_F"] == pytest.approx(3.0e-9 * (1 - y + y * (25 - th) / (T - th)),
                                                                rel=1e-14)


def test_the_decoys_column(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 24                                                         # runs 21-22 carry no load at seed 3
    df, truth, nominal, plan = audit.experiment("weight_sway_decoy", 3, first=first)
    p = truth["parameters"]
    factors = be.setting("weight_sway_decoy", 3, audit.draw)[3]
    clean = be.experiment("clean", 3)[0]
    loads, hung, t_h, A_h, prev = set(), 0, None, None, None
    for k in range(1, first + 1):
        run = df[df["run"] == k]
        pr = truth["per_run"][k - 1]
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr["mu_p"] == mp.interface.mu_p and pr["P0_N"] == mp.stator.P0_N and pr["mu_sd"] == mp.slider.mu_sd
        L = float(run["load_kg"].iloc[0])
        loads.add(L == 0)
        if prev is None or L != prev:
            t_h, A_h = pr["t_start_s"] - 1.0, p["A_h_mm"][k - 1]
            hung += 1
        assert pr["t_hung_s"] == pytest.approx(t_h, abs=1e-12)
        prev = L
        noise = np.random.default_rng([3, 222, k - 1]).standard_normal(len(run))
        t = run["time_s"].to_numpy()
        want = A_h * np.exp(-(t - t_h) / p["tau_s"]) if L != 0 else 0 * t
        # the reading is at the co-simulation's own times, within the session clock's rounding of the logged ones
        assert run["weight_sway_mm"].to_numpy() == pytest.approx(np.round(np.maximum(want + 0.02 * noise, 0), 2),
                                                                 abs=1.5e-2)
        assert run["speed_m_s"].to_numpy() == pytest.approx(clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
    assert loads == {True, False} and 1 < hung < first                 # runs without a load, and weights kept


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("guide_ultrasonic_dither", "rail_dither_um")
    assert audit.accepted("guide_ultrasonic_dither", "ln_rail_dither_um")
    assert not audit.accepted("guide_ultrasonic_dither", "speed")
    assert audit.accepted("match_cap_curie_weiss", "match_cap_temp_C")
    assert not audit.accepted("match_cap_curie_weiss", "voltage") and not audit.accepted("match_cap_curie_weiss",
                                                                                         "temperature")
    for name in ("session_block", "grit_plough_pct", "debris", "particle_count"):
        assert audit.accepted("lining_grit_ploughing", name)
    for name in ("time", "time_s", "speed", "prev_run_load_kg", "voltage_V_lag3r", "load_block", "voltage_block",
                 "since_break_s", "rest_before_onset", "direction", "position"):
        assert not audit.accepted("lining_grit_ploughing", name)
    assert audit.accepted("lining_grit_logged", "grit_plough_pct")
    assert not audit.accepted("weight_sway_decoy", "weight_sway_mm")
    b0 = 2.815
    row = {"kind": "match_cap_curie_weiss", "seed": 2, "traced": ["voltage", "match_cap_temp_C"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "match_cap_temp_C"], "after": 3.0})["passes"]
    row = {"kind": "weight_sway_decoy", "seed": 3, "traced": ["voltage", "load"], "before": 3.241, "after": 3.30,
           "traced_all": ["voltage", "load", "ln_weight_sway_mm"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.241, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.31})["passes"]


def test_the_probes_columns(load_bench):
    import pandas as pd
    probe = load_bench("blind_effects_twentieth_probe")
    truth = {"parameters": {"f_u_Hz": 25e3, "x_share": 0.4, "a_um": [0.0, 1.0, 0.5]}}
    df = pd.DataFrame({"run": [1, 2, 2, 3], "speed_m_s": [0.1] * 4})
    v = pd.Series([0.2, 0.1, 0.1], index=[1, 2, 3])
    V_d = 2 * math.pi * 25e3 * 1e-6                                   # 0.157 m/s at 1 um, 0.0785 at 0.5 um
    relief = probe.changed(df, "relief", truth, v)["dither_relief"].tolist()
    assert relief == [0.0, round(0.4 * (1 - 2 / math.pi * math.asin(0.1 / V_d)), 4),
                      round(0.4 * (1 - 2 / math.pi * math.asin(0.1 / V_d)), 4), 0.0]
    assert probe.changed(df, "ratio", truth, v)["dither_ratio"].tolist() == [0.0, round(V_d / 0.1, 4),
                                                                           round(V_d / 0.1, 4), round(V_d / 0.2, 4)]
    clean = pd.DataFrame({"run": [1, 1, 1, 2], "position_m": [-0.02, 0.0, 0.01, 0.0],
                          "speed_m_s": [0.5, 0.1, 0.3, -0.2]})
    assert probe.clean_speeds([clean]).tolist() == [pytest.approx(0.2), pytest.approx(0.2)]
