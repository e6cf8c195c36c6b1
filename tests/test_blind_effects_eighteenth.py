"""bench/blind_effects_eighteenth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
lining strip's hardness and its contact stiffness, the amplifier's tap relay, the air knife's jet and push, the
drive's phase meter, the draws, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_eighteenth")


def gent(S):
    return 0.0981 * (56 + 7.62336 * S) / (0.137505 * (254 - 2.54 * S))


def test_the_linings_hardness(audit):
    for S in (78.0, 80.0, 88.0, 95.0):
        assert audit.gent_modulus_MPa(S) == pytest.approx(gent(S), rel=1e-14)
    assert audit.gent_modulus_MPa(88.0) == pytest.approx(0.0981 * 726.85568 / (0.137505 * 30.48), rel=1e-12)
    assert audit.lining_k_e(6e7, 88.0) == pytest.approx(6e7, rel=1e-14)
    for S in (78.0, 84.5, 95.0):
        assert audit.lining_k_e(6e7, S) == pytest.approx(6e7 * gent(S) / gent(88.0), rel=1e-13)
    assert audit.lining_k_e(1.0, 78.0) == pytest.approx(0.488, abs=1e-3)
    assert audit.lining_k_e(1.0, 95.0) == pytest.approx(2.576, abs=1e-3)


def test_the_tap_relay(audit):
    V = [255, 290, 324, 255, 290, 220, 290, 255, 324, 324, 220, 255]
    # high from 300 V up, low from 240 V down, else the tap of the run before (low at power-up)
    want = [0, 0, 1, 1, 1, 0, 0, 0, 1, 1, 0, 0]
    assert audit.tap_states(V).tolist() == want
    assert audit.tap_states([290.0] * 4).tolist() == [0] * 4
    assert audit.tap_gain(255.0, 1, -0.05) == pytest.approx(0.95, rel=1e-15)
    assert audit.tap_gain(290.0, 1, -0.05) == pytest.approx(0.95, rel=1e-15)
    assert audit.tap_gain(324.0, 1, -0.05) == 1.0 and audit.tap_gain(255.0, 0, -0.05) == 1.0
    assert audit.tap_gain(220.0, 0, -0.05) == 1.0


def test_the_air_knifes_jet(audit):
    p = {"u_on": 10.0, "P_s": 1.0, "D": 0.5, "phase": 0.25, "tau_s": 0.1}
    ev, st = audit.valve_events(p, 3.0)
    # open at (n - 0.25) s, shut at (n + 0.25) s
    assert ev[:4] == pytest.approx([-5.25, -4.75, -4.25, -3.75], abs=1e-12) and st[:4].tolist() == [1, 0, 1, 0]
    assert ev[-1] > 3.0
    # the periodic state: at each opening u = u_on (1 - a) b / (1 - a b), a = exp(-D P / tau), b = exp(-(1 - D) P / tau)
    a, b = math.exp(-5.0), math.exp(-5.0)
    u_open = 10.0 * (1 - a) * b / (1 - a * b)
    u_shut = 10.0 + (u_open - 10.0) * a
    assert audit.air_speed([0.75, 1.25], p) == pytest.approx([u_open, u_shut], abs=1e-6)
    for t in (0.8, 1.0, 1.2):           # open since 0.75 s
        assert audit.air_speed([t], p)[0] == pytest.approx(10.0 + (u_open - 10.0) * math.exp(-(t - 0.75) / 0.1),
                                                           abs=1e-6)
    for t in (1.3, 1.6):                # shut since 1.25 s
        assert audit.air_speed([t], p)[0] == pytest.approx(u_shut * math.exp(-(t - 1.25) / 0.1), abs=1e-6)
    # against a fine-step integration of du/dt = (u_on open(t) - u) / tau from rest five periods before 0
    h, u, t = 1e-4, 0.0, -5.25
    fine = {}
    while t < 2.0 - 1e-12:
        mid = t + h / 2
        target = 10.0 if ((mid + 0.25) % 1.0) < 0.5 else 0.0
        u = target + (u - target) * math.exp(-h / 0.1)
        t += h
        for q in (0.1, 0.5, 1.9):
            if abs(t - q) < h / 2:
                fine[q] = u
    table = audit.valve_table(p, 2.0)
    assert audit.air_speed(list(fine), p, table) == pytest.approx(list(fine.values()), abs=1e-6)
    assert audit.air_force_N(10.0) == pytest.approx(0.5 * 1.2 * 1.2 * 0.03 * 0.04 * 100, rel=1e-14)   # 0.0864 N


def test_the_knifes_motor_keeps_the_guide_and_the_mass(audit, load_bench):
    from l1b2.physics.slider import force_levels
    be = load_bench("blind_effects")
    nominal = be.setting("air_knife", 1, audit.draw)[1]
    s = nominal.slider
    for L in (0.09, -0.05, 0.0):
        k = audit.knife_motor(nominal, L).slider
        F = 0.08
        for F_p in (5.5, 6.0, 7.2):
            m0, Fx0, Fc0, Fs0 = force_levels(1.0, F_p, L, s.mass_kg, s.load_inertia, s.pulley_mu, s.mu_sd, s.mu_ss,
                                             s.kappa)
            m1, Fx1, Fc1, Fs1 = force_levels(1.0, F_p, L + F / 9.81, k.mass_kg, k.load_inertia, k.pulley_mu, k.mu_sd,
                                             k.mu_ss, k.kappa)
            assert (m1, Fc1, Fs1) == pytest.approx((m0, Fc0, Fs0), rel=1e-13)
            assert Fx1 == pytest.approx(Fx0 - F, rel=1e-12)          # the push toward -position, and nothing else
        assert k.kappa <= 1.0 and k.load_inertia == 0.0
    with pytest.raises(ValueError):
        audit.knife_motor(nominal.replace(slider__pulley_mu=0.1), 0.05)


def test_the_phase_meter(audit):
    p = {"eps_deg": 2.0}
    t = np.array([0.0, 0.02, 0.3])
    want = (90 + 2.0 * (290 / 324) ** 2) * np.ones(3)
    assert audit.phase_reading_deg(t, 290.0, 1, p) == pytest.approx(want, rel=1e-14)
    assert audit.phase_reading_deg(t, 290.0, -1, p) == pytest.approx(-want, rel=1e-14)
    assert audit.phase_reading_deg([10.0], 324.0, 1, p)[0] == pytest.approx(92.0, rel=1e-12)


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    plan, nominal, conds, factors, p, every = be.setting("lining_durometer", 2, audit.draw)
    for k in (0, 5, 40):
        mp = audit.run_motor("lining_durometer", nominal, p, k, conds[k][1])
        assert mp.interface.k_e_N_per_m == pytest.approx(
            nominal.interface.k_e_N_per_m * gent(p["shore"][k]) / gent(88.0), rel=1e-13)
        assert mp.interface.mu_p == nominal.interface.mu_p and mp.stator.P0_N == nominal.stator.P0_N
    k = audit.run_motor("air_knife", nominal, {}, 3, 0.07).slider
    assert k.mass_kg == pytest.approx(nominal.slider.mass_kg + 0.07, rel=1e-15)
    for kind in ("tap_relay", "phase_meter_decoy", "tap_relay_logged"):
        assert audit.run_motor(kind, nominal, p, 7, 0.05) is nominal


def test_the_draws_stay_in_their_ranges(audit):
    S = np.concatenate([audit.draw("lining_durometer", seed, 72)["shore"] for seed in (1, 2, 3)])
    assert S.min() < 79 and S.max() > 94                                    # they fill 78-95
    for seed in (1, 2, 3):
        S = audit.draw("lining_durometer", seed, 72)["shore"]
        assert S.min() >= 78 and S.max() <= 95 and len(S) == 72
        r = audit.draw("tap_relay", seed, 72)
        assert -0.07 <= r["e"] <= -0.04
        assert audit.draw("tap_relay_logged", seed, 72) == r                  # the control shares the draw
        a = audit.draw("air_knife", seed, 72)
        assert 8 <= a["u_on"] <= 11 and 0.5 <= a["P_s"] <= 1.0 and 0.4 <= a["D"] <= 0.6 and 0 <= a["phase"] <= 1
        assert 0.02 <= a["tau_s"] <= 0.05
        d = audit.draw("phase_meter_decoy", seed, 72)
        assert 1.5 <= d["eps_deg"] <= 3.0


def test_the_linings_made_data(audit, load_bench):
    df, truth, nominal, plan = audit.experiment("lining_durometer", 1, first=2)
    p = truth["parameters"]
    factors = load_bench("blind_effects").setting("lining_durometer", 1, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    for k in (1, 2):
        run = df[df["run"] == k]
        noise = np.random.default_rng([1, 200, k - 1]).standard_normal(len(run))
        assert run["lining_shore_A"].to_numpy() == pytest.approx(np.round(p["shore"][k - 1] + 0.3 * noise, 1),
                                                                 abs=1e-9)
        mp = scattered_motor(nominal, factors[k - 1])
        assert truth["per_run"][k - 1]["k_e_N_per_m"] == pytest.approx(
            mp.interface.k_e_N_per_m * gent(p["shore"][k - 1]) / gent(88.0), rel=1e-13)


def test_the_relays_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    conds = be.setting("tap_relay", 2, audit.draw)[2]
    V = [c[0] for c in conds]
    taps = audit.tap_states(V)
    k_hi = next(k for k in range(72) if taps[k] == 1 and V[k] < 300)       # the first run off the table
    df, truth, nominal, plan = audit.experiment("tap_relay", 2, first=k_hi + 1)
    e = truth["parameters"]["e"]
    for k in range(k_hi + 1):
        assert truth["per_run"][k]["tap"] == taps[k]
        assert truth["per_run"][k]["gain"] == pytest.approx(1 + e if (taps[k] and V[k] < 300) else 1.0, rel=1e-15)
    factors = be.setting("tap_relay", 2, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    L, d = conds[k_hi][1], conds[k_hi][2]
    mp = scattered_motor(nominal, factors[k_hi])
    r = audit.traverse_in(mp, nominal, plan, V[k_hi], L, d, 1 + e)
    assert truth["per_run"][k_hi]["duration_s"] == float(r["time"][-1])
    r1 = audit.traverse_in(mp, nominal, plan, V[k_hi], L, d, 1.0)
    assert float(r["time"][-1]) > 1.02 * float(r1["time"][-1])             # the high tap's lower V0: a slower run
    ctl = audit.experiment("tap_relay_logged", 2, first=k_hi + 1)[0]
    for k in range(k_hi + 1):
        assert set(ctl[ctl["run"] == k + 1]["amp_tap"]) == {1 + int(taps[k])}
    assert ctl["speed_m_s"].to_numpy() == pytest.approx(df["speed_m_s"].to_numpy(), abs=0)   # the same motion


def test_the_knifes_made_data(audit, load_bench):
    df, truth, nominal, plan = audit.experiment("air_knife", 2, first=2)
    p = truth["parameters"]
    be = load_bench("blind_effects")
    factors = be.setting("air_knife", 2, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    for k in (1, 2):
        run = df[df["run"] == k]
        t0 = truth["per_run"][k - 1]["t_start_s"]
        noise = np.random.default_rng([2, 200, k - 1]).standard_normal(len(run))
        want = np.round(audit.air_speed(run["time_s"].to_numpy(), p) + 0.1 * noise, 2)
        assert run["air_speed_m_s"].to_numpy() == pytest.approx(want, abs=1.5e-2)
        L, V, d = float(run["load_kg"].iloc[0]), float(run["voltage_V"].iloc[0]), int(run["direction"].iloc[0])
        mp = audit.knife_motor(scattered_motor(nominal, factors[k - 1]), L)

        def law(t, L=L, t0=t0):
            u = audit.air_speed([t0 + t], p)[0]
            return L + 0.5 * 1.2 * 1.2 * 0.0012 * u * u / 9.81
        r = audit.traverse_in(mp, nominal, plan, V, L, d, 1.0, law)
        assert truth["per_run"][k - 1]["duration_s"] == pytest.approx(float(r["time"][-1]), abs=1e-9)
    # with no push, the knife's motor runs as the motor itself
    mp0 = scattered_motor(nominal, factors[0])
    L, V, d = 0.05, 290.0, 1
    r0 = audit.traverse_in(mp0, nominal, plan, V, L, d)
    r1 = audit.traverse_in(audit.knife_motor(mp0, L), nominal, plan, V, L, d, 1.0, lambda t: L)
    assert float(r1["time"][-1]) == pytest.approx(float(r0["time"][-1]), abs=1e-9)
    assert r1["Slider.s"] == pytest.approx(r0["Slider.s"], abs=1e-9)
    r2 = audit.traverse_in(audit.knife_motor(mp0, L), nominal, plan, V, L, d, 1.0, lambda t: L + 0.1 / 9.81)
    assert float(r2["time"][-1]) > 1.05 * float(r0["time"][-1])              # a push against the run: slower


def test_the_decoys_column(audit, load_bench):
    df, truth, nominal, plan = audit.experiment("phase_meter_decoy", 3, first=3)
    p = truth["parameters"]
    factors = load_bench("blind_effects").setting("phase_meter_decoy", 3, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        mp = scattered_motor(nominal, factors[k - 1])
        pr = truth["per_run"][k - 1]
        assert pr["mu_p"] == mp.interface.mu_p and pr["gain"] == 1.0 and pr["k_e_N_per_m"] == mp.interface.k_e_N_per_m
        V, d = float(run["voltage_V"].iloc[0]), int(run["direction"].iloc[0])
        noise = np.random.default_rng([3, 200, k - 1]).standard_normal(len(run))
        want = np.round(d * (90 + p["eps_deg"] * (V / 324) ** 2) + 0.1 * noise, 2)
        assert run["drive_phase_deg"].to_numpy() == pytest.approx(want, abs=1.5e-2)


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("lining_durometer", "lining_shore_A") and not audit.accepted("lining_durometer", "voltage")
    assert audit.accepted("air_knife", "air_speed_m_s") and not audit.accepted("air_knife", "position")
    for name in ("voltage_V_lag3r", "voltage_V_lag10r", "prev_run_voltage_V", "amp_tap", "voltage_history"):
        assert audit.accepted("tap_relay", name)
    for name in ("prev_run_load_kg", "prev_run_speed_m_s", "time_s", "time_in_run_s", "voltage", "load", "direction",
                 "session_block"):
        assert not audit.accepted("tap_relay", name)
    assert audit.accepted("tap_relay_logged", "amp_tap")
    assert not audit.accepted("phase_meter_decoy", "drive_phase_deg")
    b0 = 2.815
    row = {"kind": "air_knife", "seed": 2, "traced": ["voltage", "air_speed_m_s"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "air_speed_m_s"], "after": 3.0})["passes"]
    row = {"kind": "phase_meter_decoy", "seed": 3, "traced": ["voltage", "load"], "before": 3.241, "after": 3.3,
           "traced_all": ["voltage", "load", "drive_phase_deg"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.241, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.31})["passes"]


def test_the_probes_columns(load_bench):
    import pandas as pd
    probe = load_bench("blind_effects_eighteenth_probe")
    df = pd.DataFrame({"run": [1, 1, 2], "direction": [1, 1, -1], "voltage_V": [220.0, 220.0, 324.0],
                       "drive_phase_deg": [91.1, 90.9, -92.0]})
    truth = {"parameters": {"eps_deg": 2.0}}
    assert probe.changed(df, "sign_only", truth)["drive_phase_deg"].tolist() == [90.0, 90.0, -90.0]
    size = probe.changed(df, "size_only", truth)["drive_phase_deg"].tolist()
    assert size == pytest.approx([round(90 + 2 * (220 / 324) ** 2, 2)] * 2 + [92.0], abs=1e-12)
