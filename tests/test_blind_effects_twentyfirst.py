"""bench/blind_effects_twentyfirst.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
holder's thermostat cycle (Newton's heating and cooling between the disc's switch points) and the modes' drift with
it, the ferrite's Langevin slope under the coils' field, the coupling's asymmetry across the stator's gradient, the
encoder's signal strength, the draws, the made data, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twentyfirst")


def plate(t, h, tau, T_hi, phi):
    """The plate's temperature written out: Newton's heating toward T_hi from 30 - h, cooling toward 25 from 30 + h."""
    t_on = tau * math.log((T_hi - 30 + h) / (T_hi - 30 - h))
    t_off = tau * math.log((30 + h - 25) / (30 - h - 25))
    P = t_on + t_off
    u = (t + phi * P) % P
    if u < t_on:
        return T_hi - (T_hi - 30 + h) * math.exp(-u / tau)
    return 25 + (30 + h - 25) * math.exp(-(u - t_on) / tau)


def langevin_slope(x):
    return 1 / x ** 2 - 1 / math.sinh(x) ** 2


def bessel_j0(x):
    """J0 as Bessel's integral (1 / pi) int_0^pi cos(x sin th) dth (the trapezoid rule, exact to rounding here)."""
    th = np.linspace(0.0, math.pi, 4001)
    f = np.cos(x * np.sin(th))
    return float(np.sum((f[1:] + f[:-1]) / 2) * (th[1] - th[0]) / math.pi)


def test_the_thermostats_cycle(audit):
    h, tau, T_hi = 2.4, 18.0, 41.0
    t_on, t_off = audit.thermostat_times(h, tau, T_hi)
    assert t_on == pytest.approx(18.0 * math.log(13.4 / 8.6), rel=1e-14)
    assert t_off == pytest.approx(18.0 * math.log(7.4 / 2.6), rel=1e-14)
    P = t_on + t_off
    # the switch points: heating starts at 30 - h, reaches 30 + h at t_on; cooling reaches 30 - h at P
    assert float(audit.plate_temp_C(0.0, h, tau, T_hi, 0.0)) == pytest.approx(30 - h, rel=1e-14)
    assert float(audit.plate_temp_C(t_on - 1e-9, h, tau, T_hi, 0.0)) == pytest.approx(30 + h, abs=1e-8)
    assert float(audit.plate_temp_C(t_on, h, tau, T_hi, 0.0)) == pytest.approx(30 + h, rel=1e-14)
    assert float(audit.plate_temp_C(P - 1e-9, h, tau, T_hi, 0.0)) == pytest.approx(30 - h, abs=1e-8)
    for t, phi in ((0.0, 0.3), (3.7, 0.0), (11.0, 0.55), (40.2, 0.9), (87.5, 0.12)):
        assert float(audit.plate_temp_C(t, h, tau, T_hi, phi)) == pytest.approx(plate(t, h, tau, T_hi, phi),
                                                                                rel=1e-13)
        assert float(audit.plate_temp_C(t + P, h, tau, T_hi, phi)) == pytest.approx(plate(t, h, tau, T_hi, phi),
                                                                                    rel=1e-11)
    t = np.linspace(0, 90, 9001)
    T = audit.plate_temp_C(t, h, tau, T_hi, 0.37)
    assert T.min() >= 30 - h - 1e-9 and T.max() <= 30 + h + 1e-9
    assert T.min() < 30 - h + 0.01 and T.max() > 30 + h - 0.01     # both switch points reached


def test_langevins_slope_and_the_inductor(audit):
    for x in (0.05, 0.3, 1.0, 1.47, 2.5):
        assert float(audit.langevin_slope(x)) == pytest.approx(langevin_slope(x), rel=1e-9)
        assert float(audit.langevin_slope(-x)) == pytest.approx(langevin_slope(x), rel=1e-9)
        # the slope of L(x) = coth x - 1/x by a central difference
        L = lambda y: 1 / math.tanh(y) - 1 / y  # noqa: E731
        assert float(audit.langevin_slope(x)) == pytest.approx((L(x + 1e-5) - L(x - 1e-5)) / 2e-5, rel=1e-6)
    assert float(audit.langevin_slope(0.0)) == 1 / 3
    assert float(audit.langevin_slope(0.0499)) == pytest.approx(langevin_slope(0.0499), rel=1e-9)
    s, B_a = 0.6, 19.0
    assert float(audit.inductance_factor(0.0, s, B_a)) == pytest.approx(1.0, rel=1e-15)
    for B in (5.0, 12.0, 25.0):
        assert float(audit.inductance_factor(B, s, B_a)) == pytest.approx(
            1 - s + s * 3 * langevin_slope(B / B_a), rel=1e-12)
    f = audit.inductance_factor(np.linspace(0, 25, 51), s, B_a)
    assert np.all(np.diff(f) < 0) and f[-1] > 1 - s                   # falls with the field, never below the air path
    assert float(audit.inductance_factor(1.0, s, B_a)) == pytest.approx(1 - s * (1 / B_a) ** 2 / 5, rel=1e-6)


def test_the_couplings_asymmetry(audit):
    assert float(audit.coupling_asymmetry(20.0, 0.004)) == pytest.approx(0.04, rel=1e-15)
    assert float(audit.coupling_asymmetry(-12.5, 0.0035)) == pytest.approx(-0.0035 * 12.5 / 2, rel=1e-15)
    assert float(audit.coupling_asymmetry(0.0, 0.005)) == 0.0


def test_the_encoders_signal(audit):
    p = {"e0_um": 20.0, "e1_um": -60.0, "w_um": 120.0, "a324_um": 0.4}
    s = np.array([-0.02, 0.0, 0.013])
    e = 20.0 - 60.0 * s / 0.021
    assert audit.ride_gain(s, 20.0, -60.0, 120.0) == pytest.approx(np.exp(-(e / 120.0) ** 2), rel=1e-14)
    for V0 in (220.0, 290.0, 324.0):
        want = bessel_j0(2 * math.pi * 0.4 * V0 / 324 / 4.0)
        assert audit.vibration_contrast(V0, 0.4) == pytest.approx(want, rel=1e-9)
    assert audit.vibration_contrast(324.0, 0.4) < audit.vibration_contrast(220.0, 0.4) < 1
    assert audit.encoder_signal_pct(s, 255.0, p) == pytest.approx(
        100 * np.exp(-(e / 120.0) ** 2) * bessel_j0(2 * math.pi * 0.4 * 255 / 324 / 4.0), rel=1e-9)


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    nominal = be.setting("clean", 1, audit.draw)[1]
    st = nominal.stator
    p = {"h_K": 2.4, "tau_s": 18.0, "T_hi_C": 41.0, "phi": 0.3, "c_b_Hz_per_K": -25.0, "c_l_Hz_per_K": -15.0}
    for kind in ("holder_thermostat_cycle", "holder_thermostat_logged"):
        mp = audit.run_motor(kind, nominal, p, 4, 6.2)
        dT = plate(6.2, 2.4, 18.0, 41.0, 0.3) - 30
        assert mp.stator.f_b0_Hz == pytest.approx(st.f_b0_Hz - 25.0 * dT, rel=1e-14)
        assert mp.stator.f_l0_Hz == pytest.approx(st.f_l0_Hz - 15.0 * dT, rel=1e-14)
        assert mp.driver == nominal.driver and mp.interface == nominal.interface and mp.slider == nominal.slider
        assert mp.stator.P0_N == st.P0_N and mp.stator.asym_b == st.asym_b
    p = {"s_core": 0.6, "B_a_mT": 19.0, "B_mT": [3.0, 22.0]}
    mp = audit.run_motor("drive_field_ferrite", nominal, p, 1, 0.0)
    assert mp.driver.L_H == pytest.approx(1.670e-3 * (0.4 + 0.6 * 3 * langevin_slope(22 / 19)), rel=1e-12)
    assert mp.driver.C1_F == nominal.driver.C1_F and mp.stator == nominal.stator
    p = {"c_per_K": 0.004, "dT_K": [-18.0]}
    mp = audit.run_motor("stator_gradient_asym", nominal, p, 0, 0.0)
    assert mp.stator.asym_b == pytest.approx(-0.036, rel=1e-14)
    assert mp.stator.f_b0_Hz == st.f_b0_Hz and mp.stator.A_b_N_per_V == st.A_b_N_per_V and mp.driver == nominal.driver
    own = nominal.replace(stator__asym_b=0.01)                        # on top of a motor's own asymmetry
    assert audit.run_motor("stator_gradient_asym", own, p, 0, 0.0).stator.asym_b == pytest.approx(-0.026, rel=1e-14)
    assert audit.run_motor("encoder_signal_decoy", nominal, {}, 3, 5.0) == nominal


def test_the_draws_stay_in_their_ranges(audit):
    B = np.concatenate([audit.draw("drive_field_ferrite", seed, 72)["B_mT"] for seed in (1, 2, 3)])
    assert B.min() < 0.5 and B.max() > 24.5 and 0 <= B.min() and B.max() <= 25
    dT = np.concatenate([audit.draw("stator_gradient_asym", seed, 72)["dT_K"] for seed in (1, 2, 3)])
    assert dT.min() < -24 and dT.max() > 24 and -25 <= dT.min() and dT.max() <= 25
    signs = set()
    for seed in (1, 2, 3):
        t = audit.draw("holder_thermostat_cycle", seed, 72)
        assert 2.0 <= t["h_K"] <= 3.0 and 12 <= t["tau_s"] <= 25 and 38 <= t["T_hi_C"] <= 44 and 0 <= t["phi"] < 1
        assert -30 <= t["c_b_Hz_per_K"] <= -20 and -20 <= t["c_l_Hz_per_K"] <= -10
        assert audit.draw("holder_thermostat_logged", seed, 72) == t              # the control shares the draw
        f = audit.draw("drive_field_ferrite", seed, 72)
        assert 0.50 <= f["s_core"] <= 0.65 and 17 <= f["B_a_mT"] <= 22
        g = audit.draw("stator_gradient_asym", seed, 72)
        assert 0.0030 <= g["c_per_K"] <= 0.0050
        d = audit.draw("encoder_signal_decoy", seed, 72)
        assert -40 <= d["e0_um"] <= 40 and 40 <= abs(d["e1_um"]) <= 80 and 100 <= d["w_um"] <= 150
        assert 0.3 <= d["a324_um"] <= 0.5
        signs.add(math.copysign(1, d["e1_um"]))
    assert signs == {-1.0, 1.0}
    # each session's parameters fill their ranges over many seeds
    draws = {kind: [audit.draw(kind, seed, 2) for seed in range(1, 301)]
             for kind in ("holder_thermostat_cycle", "drive_field_ferrite", "stator_gradient_asym",
                          "encoder_signal_decoy")}
    ranges = {"holder_thermostat_cycle": {"h_K": (2.0, 3.0), "tau_s": (12, 25), "T_hi_C": (38, 44), "phi": (0, 1),
                                          "c_b_Hz_per_K": (-30, -20), "c_l_Hz_per_K": (-20, -10)},
              "drive_field_ferrite": {"s_core": (0.50, 0.65), "B_a_mT": (17, 22)},
              "stator_gradient_asym": {"c_per_K": (0.0030, 0.0050)},
              "encoder_signal_decoy": {"e0_um": (-40, 40), "w_um": (100, 150), "a324_um": (0.3, 0.5)}}
    for kind, rs in ranges.items():
        for key, (lo, hi) in rs.items():
            x = np.array([d[key] for d in draws[kind]])
            assert lo <= x.min() < lo + 0.02 * (hi - lo) and hi - 0.02 * (hi - lo) < x.max() <= hi, (kind, key)
    e1 = np.abs([d["e1_um"] for d in draws["encoder_signal_decoy"]])
    assert 40 <= e1.min() < 40.8 and 79.2 < e1.max() <= 80
    rng = np.random.default_rng([2, 231, 2])                           # the gradient's own stream at seed 2
    assert audit.draw("stator_gradient_asym", 2, 72)["c_per_K"] == rng.uniform(0.0030, 0.0050)
    rng = np.random.default_rng([3, 231, 0])                           # the thermostat's, its control's too
    assert audit.draw("holder_thermostat_logged", 3, 72)["h_K"] == rng.uniform(2.0, 3.0)


def test_the_thermostats_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 16
    df, truth, nominal, plan = audit.experiment("holder_thermostat_cycle", 1, first=first)
    p = truth["parameters"]
    factors = be.setting("holder_thermostat_cycle", 1, audit.draw)[3]
    pr = truth["per_run"]
    t0, temps = 0.0, []
    for k in range(first):
        run = df[df["run"] == k + 1]
        assert pr[k]["t_start_s"] == pytest.approx(t0, abs=1e-9)
        assert float(run["time_s"].iloc[0]) == pytest.approx(t0, abs=1e-9)
        T = plate(t0, p["h_K"], p["tau_s"], p["T_hi_C"], p["phi"])
        temps.append(T)
        assert pr[k]["T_plate_C"] == pytest.approx(T, rel=1e-12)
        mp = scattered_motor(nominal, factors[k])
        assert pr[k]["f_b0_Hz"] == pytest.approx(mp.stator.f_b0_Hz + p["c_b_Hz_per_K"] * (T - 30), rel=1e-14)
        assert pr[k]["f_l0_Hz"] == pytest.approx(mp.stator.f_l0_Hz + p["c_l_Hz_per_K"] * (T - 30), rel=1e-14)
        assert pr[k]["P0_N"] == mp.stator.P0_N and pr[k]["mu_p"] == mp.interface.mu_p
        t0 = float(run["time_s"].iloc[-1]) + 1.0
    assert max(temps) - min(temps) > 2.0                                # the runs meet the cycle's swing
    assert "holder_plate_C" not in df.columns
    ctl = audit.experiment("holder_thermostat_logged", 1, first=first)[0]
    for k in range(first):
        assert set(ctl[ctl["run"] == k + 1]["holder_plate_C"]) == {round(temps[k], 2)}
    assert ctl["speed_m_s"].to_numpy() == pytest.approx(df["speed_m_s"].to_numpy(), abs=0)   # the same motion


def test_the_ferrites_and_the_gradients_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    from l1b2.physics import driver as drv
    from l1b2.cosim.engine import InProcessMotor
    df, truth, nominal, plan = audit.experiment("drive_field_ferrite", 2, first=3)
    p = truth["parameters"]
    factors = be.setting("drive_field_ferrite", 2, audit.draw)[3]
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        noise = np.random.default_rng([2, 232, k - 1]).standard_normal(len(run))
        assert run["drive_field_mT"].to_numpy() == pytest.approx(np.round(p["B_mT"][k - 1] + 0.05 * noise, 2),
                                                                 abs=1e-9)
        x = p["B_mT"][k - 1] / p["B_a_mT"]
        assert truth["per_run"][k - 1]["L_H"] == pytest.approx(
            1.670e-3 * (1 - p["s_core"] + p["s_core"] * 3 * langevin_slope(x)), rel=1e-12)
    # run 3's motion, rebuilt here: the biased inductor, the supply set for the unbiased tank
    k = 3
    run = df[df["run"] == k]
    V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
    mp = scattered_motor(nominal, factors[k - 1])
    x = p["B_mT"][k - 1] / p["B_a_mT"]
    mp = mp.replace(driver__L_H=1.670e-3 * (1 - p["s_core"] + p["s_core"] * 3 * langevin_slope(x)))
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=int(d), m_load=L, s0=s0)
    r = m.run(plan.max_run_s, record=("Slider.s",), until=lambda mm: mm.value("Slider.at_stop") == d)
    assert truth["per_run"][k - 1]["duration_s"] == float(r["time"][-1])
    idx = np.arange(0, len(r["time"]), be.sampling_every(plan))
    pos = np.round(np.round(r["Slider.s"][idx] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
    df, truth, nominal, plan = audit.experiment("stator_gradient_asym", 3, first=4)
    p = truth["parameters"]
    for k in (1, 2, 3, 4):
        run = df[df["run"] == k]
        noise = np.random.default_rng([3, 232, k - 1]).standard_normal(len(run))
        assert run["stator_dT_K"].to_numpy() == pytest.approx(np.round(p["dT_K"][k - 1] + 0.05 * noise, 2),
                                                              abs=1e-9)
        assert truth["per_run"][k - 1]["asym_b"] == pytest.approx(p["c_per_K"] * p["dT_K"][k - 1] / 2, rel=1e-14)


def test_the_decoys_column(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 8
    df, truth, nominal, plan = audit.experiment("encoder_signal_decoy", 2, first=first)
    p = truth["parameters"]
    factors = be.setting("encoder_signal_decoy", 2, audit.draw)[3]
    clean = be.experiment("clean", 2)[0]
    for k in range(1, first + 1):
        run = df[df["run"] == k]
        pr = truth["per_run"][k - 1]
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr["P0_N"] == mp.stator.P0_N and pr["mu_p"] == mp.interface.mu_p and pr["L_H"] == mp.driver.L_H
        assert pr["f_b0_Hz"] == mp.stator.f_b0_Hz and pr["asym_b"] == mp.stator.asym_b
        noise = np.random.default_rng([2, 232, k - 1]).standard_normal(len(run))
        s, V0 = run["position_m"].to_numpy(), float(run["voltage_V"].iloc[0])
        e = p["e0_um"] + p["e1_um"] * s / 0.021
        want = 100 * np.exp(-(e / p["w_um"]) ** 2) * bessel_j0(2 * math.pi * p["a324_um"] * V0 / 324 / 4.0)
        # the reading is at the slider's own positions, within the encoder's rounding of the logged ones
        assert run["encoder_signal_pct"].to_numpy() == pytest.approx(np.round(want + 0.2 * noise, 1), abs=0.1 + 1e-9)
        assert run["speed_m_s"].to_numpy() == pytest.approx(clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
    assert df["encoder_signal_pct"].min() < df["encoder_signal_pct"].max() - 10     # it moves along the stroke


def test_the_accepted_regressors_and_the_pass_rule(audit):
    for name in ("drive_field_mT", "ln_drive_field_mT", "drive_field_mT_lag3r"):
        assert audit.accepted("drive_field_ferrite", name)
    assert not audit.accepted("drive_field_ferrite", "voltage") and not audit.accepted("drive_field_ferrite", "load")
    assert audit.accepted("stator_gradient_asym", "stator_dT_K")
    assert not audit.accepted("stator_gradient_asym", "direction")
    for name in ("time", "session_block", "time_s_lag3r", "ln_time_s", "thermostat_cycle", "period_sin"):
        assert audit.accepted("holder_thermostat_cycle", name)
    for name in ("time_in_run_s", "time_step_ratio", "voltage_V_lag3r", "prev_run_load_kg", "load_block",
                 "rest_before_onset", "since_break_s", "ln_pause_s", "direction", "position", "speed",
                 "temperature", "voltage_time"):
        assert not audit.accepted("holder_thermostat_cycle", name)
    assert audit.accepted("holder_thermostat_logged", "holder_plate_C")
    assert not audit.accepted("holder_thermostat_logged", "time")
    assert not audit.accepted("encoder_signal_decoy", "encoder_signal_pct")
    b0 = 3.037
    row = {"kind": "drive_field_ferrite", "seed": 1, "traced": ["voltage", "drive_field_mT"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "drive_field_mT"], "after": 3.0})["passes"]
    row = {"kind": "holder_thermostat_cycle", "seed": 3, "traced": ["session_block", "load"], "before": 4.2}
    assert audit.verdict(row | {"after": 3.3})["passes"]
    assert not audit.verdict(row | {"traced": ["time_in_run_s", "load"], "after": 3.3})["passes"]
    row = {"kind": "encoder_signal_decoy", "seed": 2, "traced": ["voltage", "load"], "before": 2.815, "after": 2.85,
           "traced_all": ["voltage", "load", "ln_encoder_signal_pct"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 2.815, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 2.88})["passes"]
