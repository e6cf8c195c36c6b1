"""bench/blind_effects_twentyfourth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
DC bias's clamp of the piezoelectric coefficient (and the modes' force factors with it), the enclosure's cycle (the
rail's lagged temperature on the session's clock and the grease's Arrhenius damping), the end stop's magnetic catch
(its pull along the stroke and the motion it gives), the inclinometer's reading, the draws, the made data, the
accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest

G = 9.81


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twentyfourth")


def clamp(V_b, x, E_s):
    """The biased coefficient over the unbiased one, the intrinsic share plus the extrinsic share's Lorentzian."""
    E = V_b / 3.0e-3 / 1e6                                                # kV/mm in the 3 mm plate
    return (1 - x) + x / (1 + (E / E_s) ** 2)


def test_the_bias_clamps_the_coefficient(audit):
    x, E_s = 0.08, 0.17
    assert float(audit.coupling_factor(0.0, 3e-3, x, E_s)) == 1.0
    for V_b in (1.0, 150.0, 510.0, 700.0, 900.0):
        assert float(audit.coupling_factor(V_b, 3e-3, x, E_s)) == pytest.approx(clamp(V_b, x, E_s), rel=1e-14)
    # at E = E_s (510 V over 3 mm at 0.17 kV/mm) half the extrinsic share is clamped
    assert float(audit.coupling_factor(510.0, 3e-3, x, E_s)) == pytest.approx(1 - x / 2, rel=1e-14)
    h = audit.coupling_factor(np.linspace(0, 900, 901), 3e-3, x, E_s)
    assert np.all(np.diff(h) < 0)                                          # monotone: falls with the bias
    assert 1 - h[1] < 1e-4 * x and h[-1] > 1 - x                           # flat at no bias, above the intrinsic
    assert float(audit.coupling_factor(1e6, 3e-3, x, E_s)) == pytest.approx(1 - x, rel=1e-6)   # levels off
    # the docstring's numbers: 900 V over 3 mm is 0.30 kV/mm; the strongest clamp over the draws
    assert 900 / 3e-3 / 1e6 == pytest.approx(0.30)
    assert float(audit.coupling_factor(900.0, 3e-3, 0.10, 0.12)) == pytest.approx(1 - 0.10 * 6.25 / 7.25, rel=1e-13)
    assert audit.BIAS_RANGE_V == (0.0, 900.0)
    # another plate's thickness: the field, not the voltage, sets it
    assert float(audit.coupling_factor(300.0, 1e-3, x, E_s)) == pytest.approx(clamp(900.0, x, E_s), rel=1e-13)


def test_the_rails_temperature_and_the_greases_damping(audit):
    A, P, phi, tau = 2.0, 55.0, 1.1, 7.0
    # the rail's first-order lag integrated here from a long-established cycle
    dt = 1e-3
    t = np.arange(-30 * P, 100.0, dt)
    air = 25 + A * np.sin(2 * math.pi * t / P + phi)
    T = np.empty_like(t)
    T[0] = 25.0
    a = 1 - math.exp(-dt / tau)
    for i in range(1, len(t)):
        T[i] = T[i - 1] + a * (air[i - 1] - T[i - 1])
    for ts in (0.0, 13.7, 40.0, 91.3):
        i = int(round((ts - t[0]) / dt))
        assert float(audit.rail_temperature_degC(ts, A, P, phi, tau)) == pytest.approx(T[i], abs=3e-3)
    w = 2 * math.pi / P
    ts = np.linspace(0, 100, 2001)
    Tr = audit.rail_temperature_degC(ts, A, P, phi, tau)
    assert Tr.max() - 25 == pytest.approx(A / math.sqrt(1 + (w * tau) ** 2), rel=1e-3)
    assert Tr.mean() == pytest.approx(25.0, abs=0.05)
    assert float(audit.rail_temperature_degC(0.0, A, P, phi, 0.0)) == pytest.approx(25 + A * math.sin(phi), rel=1e-14)
    # Arrhenius: exp(E_a / R (1/T - 1/T_ref)), the motor's c_r at 25 degC
    for T_c in (20.0, 23.4, 25.0, 27.9, 30.0):
        want = math.exp(30e3 / 8.314 * (1 / (T_c + 273.15) - 1 / 298.15))
        assert float(audit.grease_factor(T_c, 30e3)) == pytest.approx(want, rel=1e-13)
    assert float(audit.grease_factor(25.0, 40e3)) == 1.0
    assert float(audit.grease_factor(24.0, 30e3)) == pytest.approx(1.0414, abs=5e-4)   # some 4 %/K
    assert float(audit.grease_factor(26.0, 30e3)) < 1 < float(audit.grease_factor(24.0, 25e3))


def test_the_catchs_pull(audit):
    s_min, F_0, x_0 = -0.021, 0.4, 2e-3
    for s in (-0.021, -0.0205, -0.019, -0.015, 0.0, 0.021):
        want = F_0 / (1 + (s - s_min) / x_0) ** 2
        assert float(audit.latch_force_N(s, s_min, F_0, x_0)) == pytest.approx(want, rel=1e-12)
    assert float(audit.latch_force_N(s_min + x_0, s_min, F_0, x_0)) == pytest.approx(F_0 / 4, rel=1e-13)
    assert float(audit.latch_force_N(-0.0212, s_min, F_0, x_0)) == F_0    # pressed into the stop: the seat's pull
    f = audit.latch_force_N(np.linspace(-0.021, 0.021, 421), s_min, F_0, x_0)
    assert np.all(np.diff(f) < 0) and f[-1] < 0.01 * F_0


def test_the_inclinometers_reading(audit):
    p = {"theta_0_urad": 4.0, "walk_urad": np.array([0.1, -0.3, 0.25]), "a_L_urad_kg": 12.0, "a_s_urad_m": 150.0}
    s = np.array([-0.021, 0.0, 0.02])
    assert audit.tilt_urad(s, -0.09, 1, p) == pytest.approx(4.0 - 0.3 - 1.08 + 150 * s, rel=1e-13)
    assert audit.tilt_urad(s, 0.05, 2, p) == pytest.approx(4.0 + 0.25 + 0.6 + 150 * s, rel=1e-13)


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    nominal = be.setting("clean", 1, audit.draw)[1]
    p = {"x": 0.08, "E_s_kV_mm": 0.17, "V_b": [0.0, 510.0]}
    mp, law = audit.run_motor("bias_domain_clamp", nominal, p, 1, 0.05)
    assert law is None and mp.stator.A_l_N_per_V == pytest.approx(0.068 * 0.96, rel=1e-13)
    assert mp.stator.A_b_N_per_V == pytest.approx(0.062 * 0.96, rel=1e-13)
    assert mp.stator.P0_N == nominal.stator.P0_N and mp.stator.f_l0_Hz == nominal.stator.f_l0_Hz
    assert mp.driver == nominal.driver and mp.slider == nominal.slider and mp.interface == nominal.interface
    assert audit.run_motor("bias_domain_clamp", nominal, p, 0, 0.05) == (nominal, None)   # no bias: none
    p = {"A_K": 2.0, "P_s": 55.0, "phi": 1.1, "tau_r_s": 7.0, "E_a_J_mol": 30e3}
    mp, law = audit.run_motor("enclosure_cycle_grease", nominal, p, 20, -0.07, 31.2)
    w = 2 * math.pi / 55
    T = 25 + 2 / math.sqrt(1 + (7 * w) ** 2) * math.sin(w * 31.2 + 1.1 - math.atan(7 * w))
    c = 5.0 * math.exp(30e3 / 8.314 * (1 / (T + 273.15) - 1 / 298.15))
    assert law is None and mp.slider.c_r_N_s_per_m == pytest.approx(c, rel=1e-12)
    assert mp.slider.mu_sd == 0.10 and mp.slider.mu_ss == 0.12 and mp.slider.mass_kg == nominal.slider.mass_kg
    assert mp.stator == nominal.stator and mp.driver == nominal.driver and mp.interface == nominal.interface
    mp, law = audit.run_motor("stop_magnet_latch", nominal, {"F_0_N": 0.4, "x_0_m": 2e-3}, 2, 0.05)
    assert mp == be.load_in_slider_motor(nominal, 0.05, "stop_magnet_latch")
    assert law(0.1, -0.021, 0.0) == pytest.approx(0.05 + 0.4 / G, rel=1e-13)   # toward the negative stop
    assert law(0.1, -0.019, 0.1) == pytest.approx(0.05 + 0.1 / G, rel=1e-13)
    assert law(0.1, -0.019, -0.1) == law(0.1, -0.019, 0.1)                   # whatever the speed
    assert audit.run_motor("table_tilt_decoy", nominal, {}, 3, 0.05) == (nominal, None)


def test_the_draws_stay_in_their_ranges(audit):
    V_b = np.concatenate([audit.draw("bias_domain_clamp", seed, 72)["V_b"] for seed in range(1, 21)])
    assert 0 <= V_b.min() < 5 and 895 < V_b.max() <= 900 and V_b.mean() == pytest.approx(450, abs=10)
    draws = {kind: [audit.draw(kind, seed, 3) for seed in range(1, 301)] for kind in audit.KINDS}
    ranges = {"bias_domain_clamp": {"x": (0.05, 0.10), "E_s_kV_mm": (0.12, 0.22)},
              "enclosure_cycle_grease": {"A_K": (1.5, 2.5), "P_s": (40.0, 70.0), "phi": (0.0, 2 * math.pi),
                                         "tau_r_s": (4.0, 10.0), "E_a_J_mol": (25e3, 40e3)},
              "stop_magnet_latch": {"F_0_N": (0.30, 0.50), "x_0_m": (1.5e-3, 3.0e-3)},
              "table_tilt_decoy": {"a_L_urad_kg": (8.0, 15.0), "a_s_urad_m": (100.0, 200.0),
                                   "sigma_w_urad": (0.1, 0.3), "theta_0_urad": (-20.0, 20.0)}}
    for kind, rs in ranges.items():
        assert set(draws[kind][0]) - {"V_b", "walk_urad"} == set(rs), kind
        for key, (lo, hi) in rs.items():
            x = np.array([d[key] for d in draws[kind]])
            assert lo <= x.min() < lo + 0.02 * (hi - lo) and hi - 0.02 * (hi - lo) < x.max() <= hi, (kind, key)
    rng = np.random.default_rng([2, 261, 1])                              # the cycle's own stream at seed 2
    d = audit.draw("enclosure_cycle_grease", 2, 72)
    assert d["A_K"] == rng.uniform(1.5, 2.5) and d["P_s"] == rng.uniform(40.0, 70.0)
    rng = np.random.default_rng([1, 261, 0])
    d = audit.draw("bias_domain_clamp", 1, 72)
    assert d["x"] == rng.uniform(0.05, 0.10) and d["E_s_kV_mm"] == rng.uniform(0.12, 0.22)
    assert d["V_b"] == pytest.approx(rng.uniform(0.0, 900.0, 72), rel=1e-14)
    rng = np.random.default_rng([3, 261, 2])
    assert audit.draw("stop_magnet_latch", 3, 72)["F_0_N"] == rng.uniform(0.30, 0.50)
    rng = np.random.default_rng([1, 261, 3])
    d = audit.draw("table_tilt_decoy", 1, 72)
    vals = rng.uniform([8.0, 100.0, 0.1, -20.0], [15.0, 200.0, 0.3, 20.0])
    assert [d[k] for k in ("a_L_urad_kg", "a_s_urad_m", "sigma_w_urad", "theta_0_urad")] == pytest.approx(
        list(vals), rel=1e-14)
    assert d["walk_urad"] == pytest.approx(np.cumsum(vals[2] * rng.standard_normal(72)), rel=1e-12)
    assert audit.draw("clean", 1, 72) == {}


def test_the_bias_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("bias_domain_clamp", 2, first=3)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["bias_domain_clamp"] in df.columns and len(df.columns) == 9
    factors = be.setting("bias_domain_clamp", 2, audit.draw)[3]
    clean = audit.experiment("clean", 2, first=3)[0]
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        noise = np.random.default_rng([2, 262, k - 1]).standard_normal(len(run))
        assert run["bias_V"].to_numpy() == pytest.approx(np.round(p["V_b"][k - 1] + 0.5 * noise, 1), abs=1e-9)
        h = clamp(p["V_b"][k - 1], p["x"], p["E_s_kV_mm"])
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr[k - 1]["A_l_N_per_V"] == pytest.approx(0.068 * h, rel=1e-13)
        assert pr[k - 1]["A_b_N_per_V"] == pytest.approx(0.062 * h, rel=1e-13)
        assert pr[k - 1]["P0_N"] == mp.stator.P0_N and pr[k - 1]["mu_p"] == mp.interface.mu_p
        assert pr[k - 1]["c_r_N_s_per_m"] == 5.0 and pr[k - 1]["latch_max_N"] is None
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        mp = mp.replace(stator__A_l_N_per_V=0.068 * h, stator__A_b_N_per_V=0.062 * h)
        r = be.traverse(mp, nominal, plan, V, L, int(d))
        pos = np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
        assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
        assert len(run) > len(clean[clean["run"] == k])                  # weaker force factors: slower


def test_the_cycles_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 4
    df, truth, nominal, plan = audit.experiment("enclosure_cycle_grease", 3, first=first)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["enclosure_cycle_grease"] is None and len(df.columns) == 8   # nothing but the motion
    factors = be.setting("enclosure_cycle_grease", 3, audit.draw)[3]
    starts = df.groupby("run")["time_s"].first().to_numpy()
    ends = df.groupby("run")["time_s"].last().to_numpy()
    assert starts[1:] == pytest.approx(ends[:-1] + 1.0, abs=1e-9)       # the plan's pause between runs
    w = 2 * math.pi / p["P_s"]
    wt = w * p["tau_r_s"]
    for k in range(1, first + 1):
        t0 = starts[k - 1]
        T = 25 + p["A_K"] / math.sqrt(1 + wt ** 2) * math.sin(w * t0 + p["phi"] - math.atan(wt))
        assert pr[k - 1]["t_start_s"] == pytest.approx(t0, abs=1e-9)
        assert pr[k - 1]["rail_T_degC"] == pytest.approx(T, rel=1e-12)
        c = 5.0 * math.exp(p["E_a_J_mol"] / 8.314 * (1 / (T + 273.15) - 1 / 298.15))
        assert pr[k - 1]["c_r_N_s_per_m"] == pytest.approx(c, rel=1e-12)
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr[k - 1]["P0_N"] == mp.stator.P0_N and pr[k - 1]["A_l_N_per_V"] == 0.068
    run = df[df["run"] == 3]
    V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
    mp = scattered_motor(nominal, factors[2]).replace(slider__c_r_N_s_per_m=pr[2]["c_r_N_s_per_m"])
    r = be.traverse(mp, nominal, plan, V, L, int(d))
    pos = np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)


def test_the_latchs_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.cosim.engine import InProcessMotor
    from l1b2.physics import driver as drv
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("stop_magnet_latch", 1, first=2)
    p = truth["parameters"]
    assert audit.CHANNEL["stop_magnet_latch"] is None and len(df.columns) == 8
    clean = audit.experiment("clean", 1, first=2)[0]
    factors = be.setting("stop_magnet_latch", 1, audit.draw)[3]
    for k in (1, 2):
        run = df[df["run"] == k]
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        mp = scattered_motor(nominal, factors[k - 1])
        sl = mp.slider
        m2 = sl.mass_kg + abs(L)
        mp = mp.replace(slider__mass_kg=m2, slider__load_inertia=0.0, slider__mu_sd=sl.mu_sd * sl.mass_kg / m2,
                        slider__mu_ss=sl.mu_ss * sl.mass_kg / m2, slider__kappa=sl.kappa * m2 / sl.mass_kg)
        V_s = float(drv.supply_for_voltage_V(nominal.driver, V, 1.0, plan.f_drive_Hz, plan.ambient_degC))
        s0 = -0.021 if d > 0 else 0.021
        m = InProcessMotor(mp, h_s=plan.step_s)
        state = {"s": s0}

        def catch(t, L=L, state=state):
            x = max(state["s"] + 0.021, 0.0)
            return L + p["F_0_N"] / (1 + x / p["x_0_m"]) ** 2 / G
        m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=int(d), m_load=catch, s0=s0)
        s_rec = [s0]
        for _ in range(int(round(plan.max_run_s / plan.step_s))):
            m.step()
            state["s"] = m.value("Slider.s")
            s_rec.append(state["s"])
            if m.value("Slider.at_stop") == d:
                break
        pos = np.round(np.round(np.array(s_rec) / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
        assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
        assert truth["per_run"][k - 1]["latch_max_N"] == pytest.approx(
            p["F_0_N"] / (1 + (min(s_rec) + 0.021) / p["x_0_m"]) ** 2, rel=1e-12)
        n_clean = len(clean[clean["run"] == k])
        if d > 0:   # breaking out of the catch: slower
            assert len(run) > n_clean
        else:       # drawn into it at the end: not slower
            assert len(run) <= n_clean
            c = clean[clean["run"] == k]["speed_m_s"].to_numpy()
            assert run["speed_m_s"].to_numpy()[-15:-3].mean() < c[-15:-3].mean()   # faster toward the stop


def test_the_decoys_column(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 4
    df, truth, nominal, plan = audit.experiment("table_tilt_decoy", 2, first=first)
    p = truth["parameters"]
    column = audit.CHANNEL["table_tilt_decoy"]
    assert column in df.columns and audit.DECOY["table_tilt_decoy"] in column and len(df.columns) == 9
    factors = be.setting("table_tilt_decoy", 2, audit.draw)[3]
    clean = audit.experiment("clean", 2, first=first)[0]
    for k in range(1, first + 1):
        run = df[df["run"] == k]
        pr = truth["per_run"][k - 1]
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr["P0_N"] == mp.stator.P0_N and pr["mu_p"] == mp.interface.mu_p and pr["c_r_N_s_per_m"] == 5.0
        assert pr["A_l_N_per_V"] == 0.068 and pr["mu_sd"] == 0.10 and pr["mass_kg"] == mp.slider.mass_kg
        assert run["speed_m_s"].to_numpy() == pytest.approx(clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
        L = float(run["load_kg"].iloc[0])
        noise = np.random.default_rng([2, 262, k - 1]).standard_normal(len(run))
        s = run["position_m"].to_numpy()                                  # the encoder's, within 0.1 urad
        want = p["theta_0_urad"] + p["walk_urad"][k - 1] + p["a_L_urad_kg"] * L + p["a_s_urad_m"] * s
        assert run["table_tilt_urad"].to_numpy() == pytest.approx(np.round(want + 0.2 * noise, 1), abs=0.1001)
        assert run["table_tilt_urad"].to_numpy() == pytest.approx(np.round(
            audit.tilt_urad(s, L, k - 1, p) + 0.2 * noise, 1), abs=0.1001)
    y = df["table_tilt_urad"].to_numpy() - p["a_L_urad_kg"] * df["load_kg"].to_numpy() - p["theta_0_urad"]
    assert np.corrcoef(y, df["position_m"])[0, 1] > 0.9                   # it carries the position


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("bias_domain_clamp", "bias_V")
    for name in ("voltage", "load", "frequency_Hz", "time", "voltage_V_lag1r"):
        assert not audit.accepted("bias_domain_clamp", name), name
    for name in ("time", "time_s", "session_clock", "elapsed_s", "run_index", "run_count", "sin_time",
                 "cos_session", "period_55s", "cycle", "phase", "harmonic_2"):
        assert audit.accepted("enclosure_cycle_grease", name), name
    for name in ("time_in_run_s", "elapsed_in_run", "since_start", "onset_time", "time_since_break", "pause_time",
                 "voltage_V_lag1r", "prev_load_time", "time_last", "speed", "position", "load", "direction",
                 "voltage", "start_time", "speed_time", "position_x_time", "load_x_time", "direction_x_time",
                 "bias_V"):
        assert not audit.accepted("enclosure_cycle_grease", name), name
    for name in ("position", "position_sq", "near_stop", "stop_proximity", "distance_to_stop", "latch", "magnet",
                 "position_x_direction", "proximity", "stop_gap"):
        assert audit.accepted("stop_magnet_latch", name), name
    for name in ("time_in_run", "elapsed_in_run", "speed", "velocity", "position_lag1", "prev_position",
                 "last_position", "position_history", "position_memory", "position_x_voltage",
                 "position_x_load", "session_position", "speed_near_stop", "direction", "time", "voltage"):
        assert not audit.accepted("stop_magnet_latch", name), name
    assert not audit.accepted("table_tilt_decoy", "table_tilt_urad")
    assert audit.B0 == {1: 3.037, 2: 2.815, 3: 3.241}
    b0 = 3.241
    row = {"kind": "bias_domain_clamp", "seed": 3, "traced": ["voltage", "bias_V"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "bias_V"], "after": 3.0})["passes"]
    row = {"kind": "enclosure_cycle_grease", "seed": 1, "traced": ["load", "time_s"], "before": 4.5}
    b0 = 3.037
    assert audit.verdict(row | {"after": 3.4})["passes"]
    assert audit.verdict(row | {"after": 3.4})["bound"] == pytest.approx(math.sqrt(b0 ** 2 + (4.5 ** 2 - b0 ** 2) / 4))
    assert not audit.verdict(row | {"traced": ["load", "time_in_run_s"], "after": 3.4})["passes"]
    row = {"kind": "stop_magnet_latch", "seed": 2, "traced": ["position"], "before": 4.2, "after": 3.2}
    assert audit.verdict(row)["passes"] and not audit.verdict(row | {"traced": ["speed"]})["passes"]
    row = {"kind": "table_tilt_decoy", "seed": 1, "traced": ["voltage", "load"], "before": 3.037, "after": 3.05,
           "traced_all": ["voltage", "load", "table_tilt_urad"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.037, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load", "dynamic_friction"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.11})["passes"]


def test_the_tables_name_every_kind(audit):
    kinds = set(audit.KINDS)
    assert audit.KINDS == ("bias_domain_clamp", "enclosure_cycle_grease", "stop_magnet_latch", "table_tilt_decoy")
    assert set(audit.CHANNEL) == kinds and set(audit.WANT) == kinds
    assert set(audit.NOT_WANT) == {"enclosure_cycle_grease", "stop_magnet_latch"}
    assert audit.DECOY == {"table_tilt_decoy": "tilt"} and audit.WANT["table_tilt_decoy"] == ()
    assert audit.CHANNEL == {"bias_domain_clamp": "bias_V", "enclosure_cycle_grease": None,
                             "stop_magnet_latch": None, "table_tilt_decoy": "table_tilt_urad"}
    for line in audit.__doc__.splitlines():
        assert len(line) <= 120
