"""bench/blind_effects_nineteenth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
holder's creep and its reseat by a hard arrival at the stop, the glove box's oxygen on the guide, the lining's
WLF-shifted Grosch friction, the weight's laser, the draws, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_nineteenth")


def test_the_holders_creep_and_reseat(audit):
    assert audit.seat_factor(0, 0.25, 3.0) == 1.0
    for n, R, n0 in ((1, 0.25, 3.0), (3, 0.2, 2.0), (7, 0.3, 4.0)):
        assert audit.seat_factor(n, R, n0) == pytest.approx(1 - R * (1 - math.exp(-n / n0)), rel=1e-15)
    assert audit.seat_factor(200, 0.25, 3.0) == pytest.approx(0.75, rel=1e-12)
    # 0 after a hard arrival (at v_hard or more), else one more
    assert audit.next_n(4, 0.23, 0.23) == 0 and audit.next_n(4, 0.2299, 0.23) == 5 and audit.next_n(0, 0.1, 0.23) == 1
    # the gauge: P0 R (1 - exp(-n / n0)) / k_p in um
    assert audit.walk_um(2, 6.35, 7.5e4, 0.25, 2.0) == pytest.approx(1e6 * 6.35 * 0.25 * (1 - math.exp(-1)) / 7.5e4,
                                                                     rel=1e-14)
    assert audit.walk_um(0, 6.35, 7.5e4, 0.25, 2.0) == 0.0


def test_the_arrival_speed(audit):
    t = np.arange(0, 0.301, 0.001)
    s = -0.021 + 0.15 * t                     # 0.15 m/s up to the stop at +0.024 (a hand-made stop)
    assert audit.arrival_speed(t, s, 1, float(s[-1])) == pytest.approx(0.15, rel=1e-9)
    # backward at 0.2 m/s, then 0.1 m/s over the last 4 mm: the last 5 mm take 1 mm / 0.2 + 4 mm / 0.1 = 45 ms
    h = 1e-5
    t = np.arange(0, 0.145 + h / 2, h)
    s = np.where(t < 0.105, 0.021 - 0.2 * t, 0.021 - 0.2 * 0.105 - 0.1 * (t - 0.105))
    assert audit.arrival_speed(t, s, -1, float(s[-1])) == pytest.approx(0.005 / 0.045, rel=1e-3)


def test_the_oxygen_on_the_guide(audit):
    for x, x_h in ((0.1, 1.0), (2.0, 0.5), (20.9, 2.0)):
        assert audit.coverage(x, x_h) == pytest.approx(x / (x + x_h), rel=1e-15)
    A, x_h = 0.25, 1.2
    air = 20.9 / (20.9 + x_h)
    for x in (0.1, 1.2, 5.0, 20.9):
        assert audit.guide_factor(x, x_h, A) == pytest.approx((1 + A * (1 - x / (x + x_h))) / (1 + A * (1 - air)),
                                                              rel=1e-14)
    assert audit.guide_factor(20.9, x_h, A) == pytest.approx(1.0, rel=1e-15)
    assert audit.guide_factor(0.0, x_h, A) == pytest.approx((1 + A) / (1 + A * (1 - air)), rel=1e-14)


def wlf(T):
    return -8.86 * (T - 25) / (101.6 + T - 25)


def G(x, x_p, w):
    return 8 + math.exp(-(x - x_p) ** 2 / (2 * w * w))


def test_the_linings_grosch_friction(audit):
    assert audit.log_aT(25.0) == 0.0
    for T in (15.0, 35.0, 45.0):
        assert audit.log_aT(T) == pytest.approx(wlf(T), rel=1e-14)
    assert audit.log_aT(45.0) == pytest.approx(-8.86 * 20 / 121.6, rel=1e-14)
    for T, V in ((15.0, 220.0), (40.0, 324.0)):
        assert audit.grosch_x(T, V) == pytest.approx(math.log10(0.2 * V / 324 / 0.2) + wlf(T), rel=1e-13)
    assert audit.grosch_G(0.3, 0.3, 0.7) == pytest.approx(9.0, rel=1e-15)
    assert audit.grosch_G(-0.4, 0.3, 0.7) == pytest.approx(G(-0.4, 0.3, 0.7), rel=1e-15)
    T_pk, w = 35.0, 0.7
    x_p = wlf(T_pk)
    for V in (220.0, 290.0, 324.0):
        assert audit.lining_factor(25.0, V, T_pk, w) == pytest.approx(1.0, rel=1e-15)   # the motor's own at 25 degC
        for T in (15.0, 35.0, 45.0):
            x, x0 = math.log10(V / 324) + wlf(T), math.log10(V / 324)
            assert audit.lining_factor(T, V, T_pk, w) == pytest.approx(G(x, x_p, w) / G(x0, x_p, w), rel=1e-13)
    # the peak at T_pk at 324 V: the bell's top, 9 / G(x(25))
    assert audit.lining_factor(T_pk, 324.0, T_pk, w) == pytest.approx(9.0 / G(0.0, x_p, w), rel=1e-13)
    assert audit.lining_factor(T_pk, 324.0, T_pk, w) > audit.lining_factor(45.0, 324.0, T_pk, w)


def test_the_weights_laser(audit):
    p = {"z0_mm": 50.0, "h_m_mm_per_g": 0.3}
    s = np.array([-0.021, 0.0, 0.0205])
    assert audit.laser_reading_mm(s, 0.05, p) == pytest.approx(50 + 1000 * (s + 0.021) - 0.3 * 50, rel=1e-14)
    assert audit.laser_reading_mm(s, 0.09, p)[0] == pytest.approx(50 - 27.0, rel=1e-14)
    for L in (0.0, -0.05):
        assert audit.laser_reading_mm(s, L, p).tolist() == [200.0] * 3


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    plan, nominal, conds, factors, _, every = be.setting("glovebox_oxygen", 1, audit.draw)
    p = {"R": 0.25, "n0": 3.0, "v_hard": 0.23}
    for kind in ("hardstop_gib_reseat", "hardstop_gib_logged"):
        mp = audit.run_motor(kind, nominal, p, 5, 290.0, 2)
        assert mp.stator.P0_N == pytest.approx(nominal.stator.P0_N * (1 - 0.25 * (1 - math.exp(-2 / 3))), rel=1e-14)
        assert mp.interface.mu_p == nominal.interface.mu_p and mp.slider.mu_sd == nominal.slider.mu_sd
    p = {"o2": [20.9, 0.5], "x_h": 1.0, "A": 0.2}
    mp = audit.run_motor("glovebox_oxygen", nominal, p, 1, 290.0)
    g = (1 + 0.2 * (1 - 0.5 / 1.5)) / (1 + 0.2 * (1 - 20.9 / 21.9))
    assert mp.slider.mu_sd == pytest.approx(nominal.slider.mu_sd * g, rel=1e-14)
    assert mp.slider.mu_ss == pytest.approx(nominal.slider.mu_ss * g, rel=1e-14)
    assert mp.stator.P0_N == nominal.stator.P0_N and mp.interface.mu_p == nominal.interface.mu_p
    assert audit.run_motor("glovebox_oxygen", nominal, p, 0, 290.0).slider.mu_sd == pytest.approx(
        nominal.slider.mu_sd, rel=1e-15)
    p = {"T": [40.0], "T_pk": 35.0, "w": 0.7}
    mp = audit.run_motor("lining_wlf_grosch", nominal, p, 0, 255.0)
    x, x0 = math.log10(255 / 324) + wlf(40.0), math.log10(255 / 324)
    assert mp.interface.mu_p == pytest.approx(nominal.interface.mu_p * G(x, wlf(35.0), 0.7) / G(x0, wlf(35.0), 0.7),
                                              rel=1e-13)
    assert mp.slider.mu_sd == nominal.slider.mu_sd
    assert audit.run_motor("weight_laser_decoy", nominal, {}, 3, 290.0) is nominal


def test_the_draws_stay_in_their_ranges(audit):
    x = np.concatenate([audit.draw("glovebox_oxygen", seed, 72)["o2"] for seed in (1, 2, 3)])
    assert x.min() < 0.12 and x.max() > 19.0                              # they fill 0.1-20.9 %
    assert np.mean(x < 1.45) == pytest.approx(0.5, abs=0.1)                # log-uniform: half below sqrt(0.1 x 20.9)
    T = np.concatenate([audit.draw("lining_wlf_grosch", seed, 72)["T"] for seed in (1, 2, 3)])
    assert T.min() < 16 and T.max() > 44
    for seed in (1, 2, 3):
        r = audit.draw("hardstop_gib_reseat", seed, 72)
        assert 0.20 <= r["R"] <= 0.30 and 2 <= r["n0"] <= 4 and 0.21 <= r["v_hard"] <= 0.25
        assert audit.draw("hardstop_gib_logged", seed, 72) == r              # the control shares the draw
        o = audit.draw("glovebox_oxygen", seed, 72)
        assert 0.5 <= o["x_h"] <= 2 and 0.15 <= o["A"] <= 0.30 and 0.1 <= o["o2"].min() and o["o2"].max() <= 20.9
        g = audit.draw("lining_wlf_grosch", seed, 72)
        assert 30 <= g["T_pk"] <= 40 and 0.6 <= g["w"] <= 0.9 and 15 <= g["T"].min() and g["T"].max() <= 45
        d = audit.draw("weight_laser_decoy", seed, 72)
        assert 40 <= d["z0_mm"] <= 60 and 0.25 <= d["h_m_mm_per_g"] <= 0.35


def test_the_reseats_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 10
    df, truth, nominal, plan = audit.experiment("hardstop_gib_reseat", 2, first=first)
    p = truth["parameters"]
    factors = be.setting("hardstop_gib_reseat", 2, audit.draw)[3]
    pr = truth["per_run"]
    n = 0
    for k in range(first):
        assert pr[k]["n_since_seat"] == n
        mp = scattered_motor(nominal, factors[k])
        assert pr[k]["P0_N"] == pytest.approx(mp.stator.P0_N * (1 - p["R"] * (1 - math.exp(-n / p["n0"]))), rel=1e-14)
        n = 0 if pr[k]["v_arrival_m_s"] >= p["v_hard"] else n + 1
    assert {q["n_since_seat"] for q in pr} != {0}                          # the holder crept at least once
    # a run's arrival speed from its own traverse, and its duration
    k = 3
    V, L, d = (float(df[df["run"] == k + 1][c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
    mp = scattered_motor(nominal, factors[k]).replace(stator__P0_N=pr[k]["P0_N"])
    r = be.traverse(mp, nominal, plan, V, L, int(d))
    stop = mp.slider.s_max_m if d > 0 else mp.slider.s_min_m
    assert pr[k]["v_arrival_m_s"] == pytest.approx(audit.arrival_speed(r["time"], r["Slider.s"], int(d), stop),
                                                   rel=1e-12)
    assert pr[k]["duration_s"] == float(r["time"][-1])
    ctl = audit.experiment("hardstop_gib_logged", 2, first=first)[0]
    for k in range(first):
        n = pr[k]["n_since_seat"]
        want = round(1e6 * 6.35 * p["R"] * (1 - math.exp(-n / p["n0"])) / 7.5e4, 1)
        assert set(ctl[ctl["run"] == k + 1]["holder_walk_um"]) == {want}
    assert ctl["speed_m_s"].to_numpy() == pytest.approx(df["speed_m_s"].to_numpy(), abs=0)   # the same motion


def test_the_oxygens_and_the_linings_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("glovebox_oxygen", 1, first=2)
    p = truth["parameters"]
    factors = be.setting("glovebox_oxygen", 1, audit.draw)[3]
    for k in (1, 2):
        run = df[df["run"] == k]
        noise = np.random.default_rng([1, 212, k - 1]).standard_normal(len(run))
        assert run["o2_pct"].to_numpy() == pytest.approx(np.round(p["o2"][k - 1] * (1 + 0.01 * noise), 2), abs=1e-9)
        x, x_h, A = p["o2"][k - 1], p["x_h"], p["A"]
        g = (1 + A * (1 - x / (x + x_h))) / (1 + A * (1 - 20.9 / (20.9 + x_h)))
        mp = scattered_motor(nominal, factors[k - 1])
        assert truth["per_run"][k - 1]["mu_sd"] == pytest.approx(mp.slider.mu_sd * g, rel=1e-13)
    df, truth, nominal, plan = audit.experiment("lining_wlf_grosch", 3, first=2)
    p = truth["parameters"]
    factors = be.setting("lining_wlf_grosch", 3, audit.draw)[3]
    for k in (1, 2):
        run = df[df["run"] == k]
        noise = np.random.default_rng([3, 212, k - 1]).standard_normal(len(run))
        assert run["lining_temp_C"].to_numpy() == pytest.approx(np.round(p["T"][k - 1] + 0.05 * noise, 2), abs=1e-9)
        V = float(run["voltage_V"].iloc[0])
        x, x0 = math.log10(V / 324) + wlf(p["T"][k - 1]), math.log10(V / 324)
        f = G(x, wlf(p["T_pk"]), p["w"]) / G(x0, wlf(p["T_pk"]), p["w"])
        mp = scattered_motor(nominal, factors[k - 1])
        assert truth["per_run"][k - 1]["mu_p"] == pytest.approx(mp.interface.mu_p * f, rel=1e-13)


def test_the_decoys_column(audit, load_bench):
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("weight_laser_decoy", 1, first=4)
    p = truth["parameters"]
    factors = load_bench("blind_effects").setting("weight_laser_decoy", 1, audit.draw)[3]
    loads = set()
    for k in (1, 2, 3, 4):
        run = df[df["run"] == k]
        mp = scattered_motor(nominal, factors[k - 1])
        pr = truth["per_run"][k - 1]
        assert pr["mu_p"] == mp.interface.mu_p and pr["P0_N"] == mp.stator.P0_N and pr["mu_sd"] == mp.slider.mu_sd
        L = float(run["load_kg"].iloc[0])
        loads.add(L > 0)
        noise = np.random.default_rng([1, 212, k - 1]).standard_normal(len(run))
        s = run["position_m"].to_numpy()
        clean = p["z0_mm"] + 1000 * (s + 0.021) - p["h_m_mm_per_g"] * 1000 * L if L > 0 else 200.0 + 0 * s
        # the reading is of the slider's position before the encoder's rounding: within 0.05 um of the logged one
        assert run["weight_height_mm"].to_numpy() == pytest.approx(np.round(clean + 0.02 * noise, 2), abs=1.5e-2)
    assert loads == {True, False}                                          # both sides met in four runs


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("glovebox_oxygen", "o2_pct") and audit.accepted("glovebox_oxygen", "ln_o2_pct")
    assert not audit.accepted("glovebox_oxygen", "voltage")
    assert audit.accepted("lining_wlf_grosch", "lining_temp_C") and not audit.accepted("lining_wlf_grosch", "load")
    for name in ("prev_run_speed_m_s", "speed_lag3r", "duration_prev", "holder_walk_um"):
        assert audit.accepted("hardstop_gib_reseat", name)
    for name in ("speed", "prev_run_load_kg", "voltage_V_lag3r", "voltage_V_step", "time_s", "since_break_s",
                 "ln_pause_s", "load", "direction", "position", "prev_run_voltage_V_speed"):
        assert not audit.accepted("hardstop_gib_reseat", name)
    assert audit.accepted("hardstop_gib_logged", "holder_walk_um")
    assert not audit.accepted("weight_laser_decoy", "weight_height_mm")
    b0 = 3.037
    row = {"kind": "glovebox_oxygen", "seed": 1, "traced": ["voltage", "o2_pct"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "o2_pct"], "after": 3.0})["passes"]
    row = {"kind": "weight_laser_decoy", "seed": 2, "traced": ["voltage", "load"], "before": 2.815, "after": 2.85,
           "traced_all": ["voltage", "load", "weight_height_mm"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 2.815, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 2.88})["passes"]


def test_the_probes_columns(load_bench):
    import pandas as pd
    probe = load_bench("blind_effects_nineteenth_probe")
    truth = {"parameters": {"v_hard": 0.2},
             "per_run": [{"v_arrival_m_s": v} for v in (0.25, 0.1, 0.3, 0.15)]}
    df = pd.DataFrame({"run": [1, 1, 2, 3, 4, 4], "speed_m_s": [0.1] * 6})
    # run 1: the median of the others' previous arrivals, 0.25, 0.1 and 0.3
    assert probe.changed(df, "prev_arrival", truth)["prev_arrival_m_s"].tolist() == [0.25, 0.25, 0.25, 0.1, 0.3, 0.3]
    assert probe.changed(df, "prev_hard", truth)["prev_hard_arrival"].tolist() == [0, 0, 1, 0, 1, 1]
    assert "prev_hard_arrival" not in probe.changed(df, "prev_arrival", truth).columns
