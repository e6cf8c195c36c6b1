"""bench/blind_effects_seventeenth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
bridge's dead time, the guide's cage creeping with the signed load, the friction bar's bow, the drive's energy
meter, the draws, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_seventeenth")


def test_the_dead_time(audit):
    from l1b2.physics import driver as drv
    assert audit.deadtime_duty(0.0, 48500.0) == 1.0
    assert audit.deadtime_duty(2e-6, 48500.0) == pytest.approx(1 - 2 * 48500 * 2e-6, rel=1e-15)   # 0.806
    for t_d in (0.0, 5e-7, 1.3e-6, 2.7e-6):
        want = math.cos(math.pi * 48500 * t_d)
        assert audit.deadtime_factor(t_d, 48500.0) == pytest.approx(want, rel=1e-14)
        # the drive's own three-level wave of that duty, against its full square wave
        duty = audit.deadtime_duty(t_d, 48500.0)
        assert drv.inverter_fundamental_V(1.0, duty) / drv.inverter_fundamental_V(1.0, 1.0) == pytest.approx(want,
                                                                                                          rel=1e-12)
    assert audit.deadtime_factor(2.7e-6, 48500.0) == pytest.approx(0.91657, abs=1e-5)


def test_the_cages_offsets(audit):
    loads = [0.09, 0.09, -0.03, 0.0, 0.05, 0.05, -0.09, -0.09, -0.09, -0.09, -0.09, 0.07]
    # u_0 = 0; each stroke adds m / 0.1 kg; clipped at +-1; the offset at a run's start is the strokes' before it
    want = [0.0, 0.9, 1.0, 0.7, 0.7, 1.0, 1.0, 0.1, -0.8, -1.0, -1.0, -1.0]
    assert audit.cage_offsets(loads, 0.1) == pytest.approx(want, abs=1e-12)
    assert audit.cage_offsets([0.0] * 5, 0.2).tolist() == [0.0] * 5
    assert audit.cage_factor([0.0, 0.5, -0.5, -1.0], 0.2) == pytest.approx([1.0, 1.05, 1.05, 1.2], rel=1e-15)


def test_the_bars_bow(audit, load_bench):
    from l1b2.physics.stator import axial_force_N
    be = load_bench("blind_effects")
    nominal = be.setting("bar_bow", 1, audit.draw)[1]
    st = nominal.stator
    L, k_p = st.bar_half_length_m, st.preload_stiffness_N_per_m
    for b in (8e-6, -6e-6):
        bent = audit.bow_motor(nominal, b).stator
        for s in (-0.021, -0.0125, 0.0, 0.004, 0.0125, 0.021, L, -L):
            want = axial_force_N(st, s) + k_p * b * (1 - (s / L) ** 2)
            assert axial_force_N(bent, s) == pytest.approx(want, rel=1e-12)
        assert axial_force_N(bent, L) == pytest.approx(axial_force_N(st, L), rel=1e-12)          # the ends: as made
        assert axial_force_N(bent, 0.0) == pytest.approx(axial_force_N(st, 0.0) + k_p * b, rel=1e-12)


def test_the_energy_meter(audit):
    p = {"P_i_W": 1.0, "P_a_W": 6.0}
    t = np.array([0.0, 0.1, 0.25])
    assert audit.energy_J(t, 324.0, p) == pytest.approx(7.0 * t, rel=1e-15)
    assert audit.energy_J(t, 220.0, p) == pytest.approx((1.0 + 6.0 * (220 / 324) ** 2) * t, rel=1e-15)


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    plan, nominal, conds, factors, p, every = be.setting("cage_creep", 2, audit.draw)
    loads = [c[1] for c in conds]
    u = 0.0
    for k in range(12):
        mp = audit.run_motor("cage_creep", nominal, plan, p, k, conds)
        assert mp.slider.mu_sd == pytest.approx(nominal.slider.mu_sd * (1 + p["J"] * u * u), rel=1e-14)
        assert mp.slider.mu_ss == pytest.approx(nominal.slider.mu_ss * (1 + p["J"] * u * u), rel=1e-14)
        assert mp.interface.mu_p == nominal.interface.mu_p and mp.stator.P0_N == nominal.stator.P0_N
        u = min(1.0, max(-1.0, u + loads[k] / p["m_c_kg"]))
    pb = be.setting("bar_bow", 2, audit.draw)[4]
    mp = audit.run_motor("bar_bow", nominal, plan, pb, 5, conds)
    b = pb["b_um"][5] * 1e-6
    assert mp.stator.P0_N == pytest.approx(nominal.stator.P0_N + nominal.stator.preload_stiffness_N_per_m * 2 * b / 3,
                                           rel=1e-14)
    assert mp.stator.bar_dev_2_m == pytest.approx(nominal.stator.bar_dev_2_m - 2 * b / 3, rel=1e-14)
    for kind in ("bridge_deadtime", "energy_meter_decoy"):
        assert audit.run_motor(kind, nominal, plan, p, 7, conds) is nominal


def test_the_draws_stay_in_their_ranges(audit):
    for seed in (1, 2, 3):
        t = audit.draw("bridge_deadtime", seed, 72)["t_d_ns"]
        assert t.min() >= 0 and t.max() <= 2700 and len(t) == 72 and np.all(np.abs(t / 10 - np.round(t / 10)) < 1e-9)
        c = audit.draw("cage_creep", seed, 72)
        assert 0.15 <= c["m_c_kg"] <= 0.30 and 0.14 <= c["J"] <= 0.28
        assert audit.draw("cage_creep_logged", seed, 72) == c                  # the control shares the draw
        b = audit.draw("bar_bow", seed, 72)["b_um"]
        assert b.min() >= -10 and b.max() <= 10 and len(b) == 72
        e = audit.draw("energy_meter_decoy", seed, 72)
        assert 0.5 <= e["P_i_W"] <= 1.5 and 4 <= e["P_a_W"] <= 8


def test_the_dead_times_made_data(audit, load_bench):
    df, truth, nominal, plan = audit.experiment("bridge_deadtime", 1, first=2)
    p = truth["parameters"]
    factors = load_bench("blind_effects").setting("bridge_deadtime", 1, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    for k in (1, 2):
        run = df[df["run"] == k]
        t_d = p["t_d_ns"][k - 1]
        assert run["deadtime_ns"].tolist() == [t_d] * len(run)
        assert truth["per_run"][k - 1]["duty"] == pytest.approx(1 - 2 * 48500 * t_d * 1e-9, rel=1e-14)
        L, V, d = float(run["load_kg"].iloc[0]), float(run["voltage_V"].iloc[0]), int(run["direction"].iloc[0])
        r = audit.traverse_duty(scattered_motor(nominal, factors[k - 1]), nominal, plan, V, L, d,
                                1 - 2 * 48500 * t_d * 1e-9)
        assert truth["per_run"][k - 1]["duration_s"] == float(r["time"][-1])
    r0 = audit.traverse_duty(nominal, nominal, plan, 290.0, 0.05, 1, 1.0)
    r1 = audit.traverse_duty(nominal, nominal, plan, 290.0, 0.05, 1, 0.8)
    assert r1["time"][-1] > 1.03 * r0["time"][-1]                             # a lower fundamental: a slower run


def test_the_decoys_column(audit, load_bench):
    df, truth, nominal, plan = audit.experiment("energy_meter_decoy", 2, first=3)
    p = truth["parameters"]
    factors = load_bench("blind_effects").setting("energy_meter_decoy", 2, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        mp = scattered_motor(nominal, factors[k - 1])
        assert truth["per_run"][k - 1]["mu_p"] == mp.interface.mu_p and truth["per_run"][k - 1]["duty"] == 1.0
        V = float(run["voltage_V"].iloc[0])
        t = run["time_s"].to_numpy() - truth["per_run"][k - 1]["t_start_s"]
        noise = np.random.default_rng([2, 198, k - 1]).standard_normal(len(run))
        want = np.round((p["P_i_W"] + p["P_a_W"] * (V / 324) ** 2) * t + 0.002 * noise, 3)
        assert run["drive_energy_J"].to_numpy() == pytest.approx(want, abs=1.5e-3)
        assert run["drive_energy_J"].iloc[0] == pytest.approx(0.0, abs=0.01)   # reset at each run's start


def test_the_controls_column_logs_the_cages_offset(audit):
    df, truth, nominal, plan = audit.experiment("cage_creep_logged", 3, first=8)
    p = truth["parameters"]
    u = 0.0
    for k in range(1, 9):
        run = df[df["run"] == k]
        assert run["cage_offset_pct"].tolist() == [round(100 * u, 1)] * len(run)
        assert truth["per_run"][k - 1]["cage_u"] == pytest.approx(u, abs=1e-12)
        u = min(1.0, max(-1.0, u + float(run["load_kg"].iloc[0]) / p["m_c_kg"]))


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("bridge_deadtime", "deadtime_ns") and audit.accepted("bridge_deadtime", "ln_deadtime_ns")
    assert not audit.accepted("bridge_deadtime", "voltage") and not audit.accepted("bridge_deadtime", "load")
    assert audit.accepted("bar_bow", "bar_bow_um") and not audit.accepted("bar_bow", "position")
    for name in ("time_s", "run_order", "load_kg_lag1r", "prev_load", "since_break_s", "session_block", "cum_load"):
        assert audit.accepted("cage_creep", name)
    for name in ("time_in_run_s", "load", "voltage", "position", "direction"):
        assert not audit.accepted("cage_creep", name)
    assert audit.accepted("cage_creep_logged", "cage_offset_pct")
    assert not audit.accepted("energy_meter_decoy", "drive_energy_J")
    b0 = 2.815
    row = {"kind": "bar_bow", "seed": 2, "traced": ["voltage", "bar_bow_um"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "bar_bow_um"], "after": 3.0})["passes"]
    row = {"kind": "energy_meter_decoy", "seed": 3, "traced": ["voltage", "load"], "before": 3.241, "after": 3.3,
           "traced_all": ["voltage", "load", "drive_energy_J"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.241, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.31})["passes"]


def test_the_probes_columns(load_bench):
    import pandas as pd
    probe = load_bench("blind_effects_seventeenth_probe")
    be = load_bench("blind_effects")
    loads = [c[1] for c in be.plan_runs(be.plan_of(2))]
    df = pd.DataFrame({"run": [1, 1, 2, 3], "load_kg": [loads[0], loads[0], loads[1], loads[2]],
                       "position_m": [0.0, 0.0125, -0.025, 0.02], "voltage_V": [220.0, 220.0, 324.0, 255.0]})
    truth = {"plan": {"seed": 2}, "parameters": {"b_um": [4.0, -2.0, 1.0], "P_i_W": 1.0, "P_a_W": 6.0}}
    cum = probe.changed(df, "cum_load", truth)["cum_load_kg"].tolist()
    assert cum == pytest.approx([0.0, 0.0, loads[0], loads[0] + loads[1]], abs=1e-9)
    bow = probe.changed(df, "bow_truth", truth)["bow_preload_N"].tolist()
    assert bow == pytest.approx([0.3, 0.225, 0.0, 0.027], abs=1e-9)           # 75 kN/m x b x (1 - (s / 25 mm)^2)
    power = probe.changed(df, "power_only", truth)["drive_energy_J"].tolist()
    assert power == pytest.approx([round(1 + 6 * (220 / 324) ** 2, 3)] * 2 + [7.0, round(1 + 6 * (255 / 324) ** 2, 3)],
                                  abs=1e-12)
