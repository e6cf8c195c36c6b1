"""bench/blind_effects_twentysecond.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
pulleys' thixotropic grease (its breakdown with the cable's travel, its rebuilding at rest, the drag of a run), the
brine's leak across the electrodes and the tank's gain, the air cushions' force at the stops, the LVDT's lagged
reading, the draws, the made data, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest

G = 9.81


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twentysecond")


def run_mean(lam0, X, x_b):
    """The structure's mean over the travel X, by the trapezoid rule on lam0 exp(-x / x_b)."""
    x = np.linspace(0.0, X, 200001)
    f = lam0 * np.exp(-x / x_b)
    return float(np.sum((f[1:] + f[:-1]) / 2) * (x[1] - x[0]) / X)


def test_the_greases_laws(audit):
    assert audit.pulley_of(0.05) == -1 and audit.pulley_of(0.09) == -1
    assert audit.pulley_of(-0.03) == 1 and audit.pulley_of(0.0) == 0
    # rebuilding at rest: first order toward 1 from the structure the pulley stopped with
    assert audit.grease_recovery(0.2, 3.0, 4.0) == pytest.approx(1 - 0.8 * math.exp(-0.75), rel=1e-15)
    assert audit.grease_recovery(0.35, 0.0, 2.5) == pytest.approx(0.35, rel=1e-15)
    assert audit.grease_recovery(1.0, 7.0, 3.0) == 1.0
    assert audit.grease_recovery(0.1, math.inf, 3.0) == 1.0                # never turned: a night's rest
    # breakdown with the cable's travel, and the mean over a run's travel
    assert audit.grease_breakdown(0.9, 0.042, 0.03) == pytest.approx(0.9 * math.exp(-1.4), rel=1e-15)
    for lam0, x_b in ((1.0, 0.02), (0.6, 0.031), (0.25, 0.04)):
        assert audit.grease_run_mean(lam0, 0.042, x_b) == pytest.approx(run_mean(lam0, 0.042, x_b), rel=1e-9)
        assert audit.grease_run_mean(lam0, 0.042, x_b) == pytest.approx(
            lam0 * (1 - math.exp(-0.042 / x_b)) * x_b / 0.042, rel=1e-15)
    assert audit.grease_breakdown(0.6, 0.042, 0.02) < audit.grease_run_mean(0.6, 0.042, 0.02) < 0.6


def test_the_brines_leak_and_the_tanks_gain(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.physics import driver as drv
    RH_d, w, rho = 75.0, 1.5, 0.08
    assert float(audit.brine_share(75.0, RH_d, w)) == pytest.approx(0.5, rel=1e-15)
    for RH in (40.0, 72.0, 76.3, 90.0):
        share = 1 / (1 + math.exp(-(RH - RH_d) / w))
        assert float(audit.brine_share(RH, RH_d, w)) == pytest.approx(share, rel=1e-13)
        assert float(audit.leak_factor(RH, rho, RH_d, w)) == pytest.approx(1 / (1 + rho * share), rel=1e-13)
        # R_m in parallel with the brine's leak R_m / (rho share)
        R_leak = 1 / (rho * share)
        assert float(audit.leak_factor(RH, rho, RH_d, w)) == pytest.approx(R_leak / (1 + R_leak), rel=1e-12)
    f = audit.leak_factor(np.linspace(30, 90, 61), rho, RH_d, w)
    assert np.all(np.diff(f) < 0)
    assert f[0] == pytest.approx(1.0, abs=1e-10) and f[-1] == pytest.approx(1 / 1.08, rel=1e-4)   # a step
    # above the knee the stator's amplitude is 5.3-7.7 % lower over the drawn rho_s (the docstring's numbers)
    d = be.setting("clean", 1, audit.draw)[1].driver
    V0 = lambda R: float(drv.driver_output(d.__class__(**{**d.__dict__, "R_m_ohm": R}),  # noqa: E731
                                           50.0, 1.0, 48500.0, 25.0).V0_V)
    assert 1 - V0(d.R_m_ohm / 1.06) / V0(d.R_m_ohm) == pytest.approx(0.053, abs=5e-4)
    assert 1 - V0(d.R_m_ohm / 1.09) / V0(d.R_m_ohm) == pytest.approx(0.077, abs=5e-4)


def test_the_cushions_force(audit):
    p = {"c_p_N_s_per_m": 3.0, "c_n_N_s_per_m": 2.5, "x_p_m": 0.006, "x_n_m": 0.005}
    s_min, s_max = -0.021, 0.021
    assert audit.cushion_force_N(0.0155, 0.2, p, s_min, s_max) == pytest.approx(-0.6, rel=1e-15)
    assert audit.cushion_force_N(0.0149, 0.2, p, s_min, s_max) == 0.0      # before the plunger
    assert audit.cushion_force_N(0.0200, -0.2, p, s_min, s_max) == 0.0     # departing: the check valve
    assert audit.cushion_force_N(-0.0165, -0.1, p, s_min, s_max) == pytest.approx(0.25, rel=1e-15)
    assert audit.cushion_force_N(-0.0155, -0.1, p, s_min, s_max) == 0.0
    assert audit.cushion_force_N(-0.0200, 0.1, p, s_min, s_max) == 0.0
    assert audit.cushion_force_N(0.0, 0.25, p, s_min, s_max) == 0.0


def test_the_lvdts_reading(audit):
    # a step of the position: the low-pass decays toward it as exp(-t / tau), sample by sample
    t = np.arange(0, 0.2, 1e-3)
    s = np.where(t > 0, 0.004, -0.002)
    y = audit.lvdt_lag(t, s, 0.025)
    assert y[0] == -0.002
    assert y == pytest.approx(0.004 - 0.006 * np.exp(-t / 0.025), rel=1e-11)
    # uneven sample times
    t2 = np.array([0.0, 0.001, 0.0035, 0.004, 0.01])
    y2 = audit.lvdt_lag(t2, np.array([0.0, 0.01, 0.01, 0.01, 0.01]), 0.02)
    assert y2 == pytest.approx(0.01 * (1 - np.exp(-t2 / 0.02)), rel=1e-12)
    p = {"tau_s": 0.03, "o_mm": 0.12, "g": -0.004, "e3_mm": -0.09}
    x = np.full(5, 0.0185)                                               # at rest: the position itself
    want = 0.12 + 18.5 * 0.996 - 0.09 * (18.5 / 25.0) ** 3
    assert audit.lvdt_reading_mm(np.arange(5) * 1e-3, x, p) == pytest.approx(np.full(5, want), rel=1e-13)
    # a ramp: the reading lags the position by about tau v once the filter has settled
    tr = np.arange(0, 0.3, 1e-3)
    sr = -0.021 + 0.1 * tr
    lag = 1000 * sr - audit.lvdt_reading_mm(tr, sr, p | {"o_mm": 0.0, "g": 0.0, "e3_mm": 0.0})
    assert lag[-1] == pytest.approx(1000 * 0.1 * 0.03, rel=0.02)


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    nominal = be.setting("clean", 1, audit.draw)[1]
    for kind in ("pulley_grease_thixotropy", "pulley_grease_logged"):
        mp, law = audit.run_motor(kind, nominal, {}, 4, -0.07, 0.12)
        assert law is None and mp.slider.pulley_mu == pytest.approx(0.12 / (G * 0.07), rel=1e-14)
        assert mp.stator == nominal.stator and mp.driver == nominal.driver and mp.interface == nominal.interface
        assert mp.slider.mu_sd == nominal.slider.mu_sd and mp.slider.mass_kg == nominal.slider.mass_kg
        assert audit.run_motor(kind, nominal, {}, 4, 0.0, 0.12) == (nominal, None)   # no load: no pulley
    p = {"rho_s": 0.08, "RH_d_pct": 75.0, "w_pct": 1.5, "RH_pct": [50.0, 81.0]}
    mp, law = audit.run_motor("electrode_brine_leak", nominal, p, 1, 0.05)
    share = 1 / (1 + math.exp(-6.0 / 1.5))
    assert law is None and mp.driver.R_m_ohm == pytest.approx(2000.0 / (1 + 0.08 * share), rel=1e-13)
    assert mp.driver.L_H == nominal.driver.L_H and mp.stator == nominal.stator and mp.slider == nominal.slider
    p = {"c_p_N_s_per_m": 3.0, "c_n_N_s_per_m": 2.5, "x_p_m": 0.006, "x_n_m": 0.005}
    mp, law = audit.run_motor("stop_air_cushion", nominal, p, 2, 0.05)
    assert mp == be.load_in_slider_motor(nominal, 0.05, "stop_air_cushion")
    assert law(0.1, 0.017, 0.2) == pytest.approx(0.05 + 0.6 / G, rel=1e-14)
    assert law(0.1, -0.018, -0.1) == pytest.approx(0.05 - 0.25 / G, rel=1e-14)
    assert law(0.1, 0.0, 0.2) == 0.05
    assert audit.run_motor("lvdt_lag_decoy", nominal, {}, 3, 0.05) == (nominal, None)


def test_the_draws_stay_in_their_ranges(audit):
    RH = np.concatenate([audit.draw("electrode_brine_leak", seed, 72)["RH_pct"] for seed in (1, 2, 3)])
    assert RH.min() < 31 and RH.max() > 89 and 30 <= RH.min() and RH.max() <= 90
    for seed in (1, 2, 3):
        assert audit.draw("pulley_grease_logged", seed, 72) == audit.draw("pulley_grease_thixotropy", seed, 72)
    draws = {kind: [audit.draw(kind, seed, 2) for seed in range(1, 301)]
             for kind in ("pulley_grease_thixotropy", "electrode_brine_leak", "stop_air_cushion", "lvdt_lag_decoy")}
    ranges = {"pulley_grease_thixotropy": {"F_g_N": (0.20, 0.32), "x_b_m": (0.020, 0.040), "t_r_s": (2.0, 5.0)},
              "electrode_brine_leak": {"rho_s": (0.06, 0.09), "RH_d_pct": (70, 80), "w_pct": (1.0, 2.0)},
              "stop_air_cushion": {"c_p_N_s_per_m": (2.0, 4.5), "c_n_N_s_per_m": (2.0, 4.5), "x_p_m": (0.004, 0.008),
                                   "x_n_m": (0.004, 0.008)},
              "lvdt_lag_decoy": {"tau_s": (0.015, 0.040), "o_mm": (-0.3, 0.3), "g": (-0.01, 0.01)}}
    for kind, rs in ranges.items():
        for key, (lo, hi) in rs.items():
            x = np.array([d[key] for d in draws[kind]])
            assert lo <= x.min() < lo + 0.02 * (hi - lo) and hi - 0.02 * (hi - lo) < x.max() <= hi, (kind, key)
    e3 = np.array([d["e3_mm"] for d in draws["lvdt_lag_decoy"]])
    assert 0.05 <= np.abs(e3).min() < 0.052 and 0.148 < np.abs(e3).max() <= 0.15
    assert (e3 > 0).sum() > 100 and (e3 < 0).sum() > 100
    rng = np.random.default_rng([2, 241, 1])                            # the brine's own stream at seed 2
    assert audit.draw("electrode_brine_leak", 2, 72)["rho_s"] == rng.uniform(0.06, 0.09)
    rng = np.random.default_rng([3, 241, 0])                            # the grease's, its control's too
    assert audit.draw("pulley_grease_logged", 3, 72)["F_g_N"] == rng.uniform(0.20, 0.32)


def test_the_greases_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 20
    df, truth, nominal, plan = audit.experiment("pulley_grease_thixotropy", 2, first=first)
    p, pr = truth["parameters"], truth["per_run"]
    factors = be.setting("pulley_grease_thixotropy", 2, audit.draw)[3]
    lam_end, t_stop, drags = {}, {}, []
    for k in range(1, first + 1):
        run = df[df["run"] == k]
        L, t0, t1 = float(run["load_kg"].iloc[0]), float(run["time_s"].iloc[0]), float(run["time_s"].iloc[-1])
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr[k - 1]["t_start_s"] == pytest.approx(t0, abs=1e-9)
        if L == 0:
            assert pr[k - 1]["drag_N"] == 0 and pr[k - 1]["pulley_mu"] == 0 and pr[k - 1]["grease_lam0"] is None
            drags.append(0.0)
            continue
        side = L > 0                                                     # the -position end's pulley
        lam0 = 1.0 if side not in lam_end else 1 - (1 - lam_end[side]) * math.exp(-(t0 - t_stop[side]) / p["t_r_s"])
        drag = p["F_g_N"] * lam0 * (1 - math.exp(-0.042 / p["x_b_m"])) * p["x_b_m"] / 0.042
        drags.append(drag)
        assert pr[k - 1]["grease_lam0"] == pytest.approx(lam0, rel=1e-12)
        assert pr[k - 1]["drag_N"] == pytest.approx(drag, rel=1e-12)
        assert pr[k - 1]["pulley_mu"] == pytest.approx(drag / (G * abs(L)), rel=1e-12)
        assert pr[k - 1]["P0_N"] == mp.stator.P0_N and pr[k - 1]["mu_p"] == mp.interface.mu_p
        lam_end[side], t_stop[side] = lam0 * math.exp(-0.042 / p["x_b_m"]), t1
    starts = df.groupby("run")["time_s"].first().to_numpy()
    ends = df.groupby("run")["time_s"].last().to_numpy()
    assert starts[1:] == pytest.approx(ends[:-1] + 1.0, abs=1e-9)       # the plan's pause between runs
    assert max(drags) > 2.5 * min(d for d in drags if d > 0)            # the history spreads the drag
    # run 1's motion, rebuilt here: the scattered motor with the pulley's drag as its load-path friction
    run = df[df["run"] == 1]
    V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
    mp = scattered_motor(nominal, factors[0]).replace(slider__pulley_mu=drags[0] / (G * abs(L)))
    r = be.traverse(mp, nominal, plan, V, L, int(d))
    pos = np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
    assert "pulley_drag_mN" not in df.columns and audit.CHANNEL["pulley_grease_thixotropy"] is None
    ctl = audit.experiment("pulley_grease_logged", 2, first=first)[0]
    assert audit.CHANNEL["pulley_grease_logged"] in ctl.columns
    for k in range(1, first + 1):
        assert set(ctl[ctl["run"] == k]["pulley_drag_mN"]) == {round(1000 * drags[k - 1], 2)}
    assert ctl["speed_m_s"].to_numpy() == pytest.approx(df["speed_m_s"].to_numpy(), abs=0)   # the same motion


def test_the_brines_and_the_cushions_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.cosim.engine import InProcessMotor
    from l1b2.physics import driver as drv
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("electrode_brine_leak", 3, first=4)
    p = truth["parameters"]
    assert audit.CHANNEL["electrode_brine_leak"] in df.columns
    for k in (1, 2, 3, 4):
        run = df[df["run"] == k]
        noise = np.random.default_rng([3, 242, k - 1]).standard_normal(len(run))
        RH = p["RH_pct"][k - 1]
        assert run["enclosure_rh_pct"].to_numpy() == pytest.approx(np.round(RH + 0.5 * noise, 1), abs=1e-9)
        share = 1 / (1 + math.exp(-(RH - p["RH_d_pct"]) / p["w_pct"]))
        assert truth["per_run"][k - 1]["R_m_ohm"] == pytest.approx(2000.0 / (1 + p["rho_s"] * share), rel=1e-12)
    # the cushions: run 1's motion rebuilt step by step, the force from the slider's state before each step
    df, truth, nominal, plan = audit.experiment("stop_air_cushion", 1, first=2)
    p = truth["parameters"]
    assert audit.CHANNEL["stop_air_cushion"] is None and len(df.columns) == 8       # nothing logged but the motion
    clean = be.experiment("clean", 1)[0]
    factors = be.setting("stop_air_cushion", 1, audit.draw)[3]
    for k in (1, 2):
        run = df[df["run"] == k]
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        mp = scattered_motor(nominal, factors[k - 1])
        sl = mp.slider
        m2 = sl.mass_kg + abs(L)
        mp = mp.replace(slider__mass_kg=m2, slider__load_inertia=0.0, slider__mu_sd=sl.mu_sd * sl.mass_kg / m2,
                        slider__mu_ss=sl.mu_ss * sl.mass_kg / m2, slider__kappa=sl.kappa * m2 / sl.mass_kg)
        V_s = float(drv.supply_for_voltage_V(nominal.driver, V, 1.0, plan.f_drive_Hz, plan.ambient_degC))
        s0 = sl.s_min_m if d > 0 else sl.s_max_m
        m = InProcessMotor(mp, h_s=plan.step_s)
        state = {"s": s0, "v": 0.0}

        def cushion(t, L=L, state=state):
            s, v = state["s"], state["v"]
            F = 0.0
            if v > 0 and s > 0.021 - p["x_p_m"]:
                F = -p["c_p_N_s_per_m"] * v
            elif v < 0 and s < -0.021 + p["x_n_m"]:
                F = -p["c_n_N_s_per_m"] * v
            return L - F / G
        m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=int(d), m_load=cushion, s0=s0)
        s_rec = [s0]
        for _ in range(int(round(plan.max_run_s / plan.step_s))):
            m.step()
            state["s"], state["v"] = m.value("Slider.s"), m.value("Slider.v")
            s_rec.append(state["s"])
            if m.value("Slider.at_stop") == d:
                break
        pos = np.round(np.round(np.array(s_rec) / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
        assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
        # before the plunger the motion is the clean one (the same positions at the same times in the run); in
        # the last mm it is slower
        c = clean[clean["run"] == k]
        x, xc = run["position_m"].to_numpy(), c["position_m"].to_numpy()
        n = int((d * x < 0.021 - 0.008).sum())
        assert x[:n] == pytest.approx(xc[:n], abs=1e-12)
        assert len(x) > len(xc) and abs(x[-5] - x[-6]) < 0.9 * abs(xc[-5] - xc[-6])
        assert truth["per_run"][k - 1]["cushion_max_N"] > 0.1


def test_the_decoys_column(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 8
    df, truth, nominal, plan = audit.experiment("lvdt_lag_decoy", 2, first=first)
    p = truth["parameters"]
    column = audit.CHANNEL["lvdt_lag_decoy"]
    assert column in df.columns and audit.DECOY["lvdt_lag_decoy"] in column
    factors = be.setting("lvdt_lag_decoy", 2, audit.draw)[3]
    clean = be.experiment("clean", 2)[0]
    for k in range(1, first + 1):
        run = df[df["run"] == k]
        pr = truth["per_run"][k - 1]
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr["P0_N"] == mp.stator.P0_N and pr["mu_p"] == mp.interface.mu_p and pr["R_m_ohm"] == 2000.0
        assert pr["pulley_mu"] == 0.0 and pr["mass_kg"] == mp.slider.mass_kg
        noise = np.random.default_rng([2, 242, k - 1]).standard_normal(len(run))
        t, s = run["time_s"].to_numpy(), run["position_m"].to_numpy()
        y = np.empty_like(s)
        y[0] = s[0]
        for i in range(1, len(s)):
            y[i] = y[i - 1] + (1 - math.exp(-(t[i] - t[i - 1]) / p["tau_s"])) * (s[i] - y[i - 1])
        want = p["o_mm"] + 1000 * y * (1 + p["g"]) + p["e3_mm"] * (1000 * y / 25) ** 3
        # the reading is of the slider's own positions, within the encoder's rounding of the logged ones
        assert run["lvdt_mm"].to_numpy() == pytest.approx(np.round(want + 0.002 * noise, 3), abs=1.2e-3)
        assert run["speed_m_s"].to_numpy() == pytest.approx(clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
    lag = 1000 * df["position_m"] - df["lvdt_mm"] + p["o_mm"]
    assert np.corrcoef(lag, df["speed_m_s"])[0, 1] > 0.9                # it carries the speed


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("electrode_brine_leak", "enclosure_rh_pct")
    for name in ("voltage", "load", "enclosure_temp_C", "time"):
        assert not audit.accepted("electrode_brine_leak", name)
    for name in ("load_kg_lag1r", "prev_run_load_kg", "since_last_load_s", "load_history", "memory_ewma",
                 "last_load_sign"):
        assert audit.accepted("pulley_grease_thixotropy", name)
    for name in ("voltage_V_lag3r", "prev_direction", "speed_lag2", "position_lag", "time_in_run_s",
                 "since_break_s", "since_start", "onset_lag", "load", "direction", "time", "elastic_load"):
        assert not audit.accepted("pulley_grease_thixotropy", name), name
    for name in ("position", "position_x_direction", "distance_to_stop", "travel_m", "arrival_zone", "stop_zone"):
        assert audit.accepted("stop_air_cushion", name)
    for name in ("speed", "time_in_run_stop", "load", "voltage", "time"):
        assert not audit.accepted("stop_air_cushion", name)
    assert audit.accepted("pulley_grease_logged", "pulley_drag_mN")
    assert not audit.accepted("pulley_grease_logged", "load_kg_lag1r")
    assert not audit.accepted("lvdt_lag_decoy", "lvdt_mm")
    b0 = 2.815
    row = {"kind": "electrode_brine_leak", "seed": 2, "traced": ["load", "enclosure_rh_pct"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "enclosure_rh_pct"], "after": 3.0})["passes"]
    row = {"kind": "pulley_grease_thixotropy", "seed": 1, "traced": ["direction", "load_kg_lag1r"], "before": 4.5}
    assert audit.verdict(row | {"after": 3.4})["passes"]
    assert not audit.verdict(row | {"traced": ["direction", "voltage_V_lag1r"], "after": 3.4})["passes"]
    row = {"kind": "lvdt_lag_decoy", "seed": 3, "traced": ["voltage", "load"], "before": 3.241, "after": 3.26,
           "traced_all": ["voltage", "load", "lvdt_mm"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.241, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.32})["passes"]
