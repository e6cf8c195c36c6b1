"""bench/blind_effects_twentyfifth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
tank core's magnetostrictive ringing (its motional impedance, the lossy tank's gain, the amplitude's fixed point and
the tank's resistance that gives it, the tracking drive's frequencies), the lining's fibre angle (the anisotropic
friction), the stator's relanding (the plunger's friction held back from the preload), the hook's load cell, the
draws, the made data, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest

G = 9.81
F0 = 48500.0


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twentyfifth")


@pytest.fixture(scope="module")
def driver(audit, load_bench):
    return load_bench("blind_effects").setting("clean", 1, audit.draw)[1].driver


def tank_gain(d, f, Z=0.0):
    """The tank written out: the inverter drives the inductor (with ``Z`` in series) into C1 + C_m parallel to R_m."""
    w = 2 * math.pi * f
    L = d.L_H * (1 + 1e-7 * (f - 48500.0))
    C = d.C1_F * (1 - 2e-7 * (f - 48500.0)) + d.C_m_F
    Zp = 1 / (1 / d.R_m_ohm + 1j * w * C)
    return abs(Zp / (1j * w * L + Z + Zp))


def test_the_cores_motional_impedance(audit):
    f_c, Q, r = 97000.0, 450.0, 30.0
    assert complex(audit.core_impedance_ohm(48500.0, 324.0, f_c, Q, r)) == pytest.approx(30.0, rel=1e-14)
    for f, V in ((48510.0, 324.0), (48440.0, 290.0), (48620.0, 220.0), (48500.0, 255.0)):
        x = Q * (2 * f / f_c - f_c / (2 * f))
        want = r * (V / 324) ** 2 / (1 + 1j * x)
        got = complex(audit.core_impedance_ohm(f, V, f_c, Q, r))
        assert got == pytest.approx(want, rel=1e-12)
        assert got.real == pytest.approx(r * (V / 324) ** 2 / (1 + x * x), rel=1e-12)
        assert got.imag == pytest.approx(-r * (V / 324) ** 2 * x / (1 + x * x), rel=1e-12)
    assert complex(audit.core_impedance_ohm(48450.0, 220.0, f_c, Q, r)) == pytest.approx(
        (220 / 324) ** 2 * complex(audit.core_impedance_ohm(48450.0, 324.0, f_c, Q, r)), rel=1e-13)
    # inductive below the core's mode, capacitive above it; the loss halves f_c / (4 Q) from its peak
    assert complex(audit.core_impedance_ohm(48480.0, 324.0, f_c, Q, r)).imag > 0
    assert complex(audit.core_impedance_ohm(48520.0, 324.0, f_c, Q, r)).imag < 0
    hw = f_c / (4 * Q)
    for f in (f_c / 2 - hw, f_c / 2 + hw):
        assert complex(audit.core_impedance_ohm(f, 324.0, f_c, Q, r)).real == pytest.approx(15.0, rel=2e-3)
    # the docstring's numbers: 40-81 Hz wide, centred at 48.44-48.56 kHz
    assert 96880 / (4 * 600) == pytest.approx(40.4, abs=0.05) and 97120 / (4 * 300) == pytest.approx(80.9, abs=0.05)
    assert audit.V0_CORE_REF_V == 324.0


def test_the_lossy_tank_and_the_amplitudes_fixed_point(audit, driver):
    from l1b2.physics import driver as drv
    for f in (48400.0, 48500.0, 48561.3):
        w = 2 * math.pi * f
        H = abs(complex(drv.tank_gain(w, float(drv.tank_inductance_H(driver, 25.0, f)),
                                      float(drv.tank_C1_F(driver, f)) + driver.C_m_F, driver.R_m_ohm)))
        assert audit.lossy_gain(driver, f, 25.0, 0.0) == pytest.approx(H, rel=1e-13)
        assert audit.lossy_gain(driver, f, 25.0, 0.0) == pytest.approx(tank_gain(driver, f), rel=1e-12)
        for Z in (20.0, 12.0 + 9.0j, 8.0 - 14.0j):
            assert audit.lossy_gain(driver, f, 25.0, Z) == pytest.approx(tank_gain(driver, f, Z), rel=1e-12)
            assert audit.lossy_gain(driver, f, 25.0, Z) < audit.lossy_gain(driver, f, 25.0, 0.0)
    assert 2 * math.pi * 48500 * driver.L_H == pytest.approx(509, abs=0.5)          # the winding's reactance
    p = {"f_c_Hz": 97000.0, "Q_c": 450.0, "r_324_ohm": 30.0}
    V, V_free = audit.core_V0(driver, 324.0, 48500.0, 48500.0, 25.0, p)
    assert V_free == pytest.approx(324.0, rel=1e-13)
    V1 = 324.0 / tank_gain(driver, 48500.0)
    Z = 30.0 * (V / 324) ** 2                                                         # on the peak: real
    assert V == pytest.approx(V1 * tank_gain(driver, 48500.0, Z), rel=1e-12)         # the fixed point
    assert 0.80 < V / V_free < 0.90
    V, V_free = audit.core_V0(driver, 290.0, 48530.0, 48500.0, 25.0, p)
    assert V_free == pytest.approx(290.0 * tank_gain(driver, 48530.0) / tank_gain(driver, 48500.0), rel=1e-12)
    x = 450 * (97060 / 97000 - 97000 / 97060)
    assert V == pytest.approx(V_free / tank_gain(driver, 48530.0) * tank_gain(
        driver, 48530.0, 30.0 * (V / 324) ** 2 / (1 + 1j * x)), rel=1e-12)
    # the docstring's numbers: on the peak 10-15 % down at 324 V, 6-9 % at 220 V over the drawn r_324
    drops = {(r, V0): 1 - np.divide(*audit.core_V0(driver, V0, 48500.0, 48500.0, 25.0,
                                                    {"f_c_Hz": 97000.0, "Q_c": 450.0, "r_324_ohm": r}))
             for r in (20.0, 35.0) for V0 in (220.0, 324.0)}
    assert drops[20.0, 324.0] == pytest.approx(0.1035, abs=1e-3)
    assert drops[35.0, 324.0] == pytest.approx(0.153, abs=1e-3)
    assert drops[20.0, 220.0] == pytest.approx(0.056, abs=1e-3) and drops[35.0, 220.0] == pytest.approx(0.088, abs=1e-3)
    V, V_free = audit.core_V0(driver, 324.0, 48620.0, 48500.0, 25.0, p)          # 2.2 half widths off the peak
    assert 0.95 < V / V_free < 0.99


def test_the_tanks_resistance_gives_the_cores_amplitude(audit, driver, load_bench):
    from l1b2.physics import driver as drv
    nominal = load_bench("blind_effects").setting("clean", 1, audit.draw)[1]
    p = {"f_c_Hz": 97010.0, "Q_c": 400.0, "r_324_ohm": 28.0, "df_Hz": np.array([12.34, -40.0])}
    for k, V0 in ((0, 324.0), (1, 255.0)):
        f = audit.run_frequency_Hz(p, k, F0)
        assert f == round(F0 + p["df_Hz"][k], 1)
        mp = audit.run_motor("core_magnetostriction", nominal, p, k, V0, f)
        V_s = float(drv.supply_for_voltage_V(driver, V0, 1.0, F0, 25.0))                  # the operator's table
        got = float(drv.driver_output(mp.driver, V_s, 1.0, f, 25.0).V0_V)
        assert got == pytest.approx(audit.core_V0(driver, V0, f, F0, 25.0, p)[0], rel=1e-10)
        assert mp.driver.R_m_ohm < driver.R_m_ohm and mp.driver.L_H == driver.L_H
        assert mp.stator == nominal.stator and mp.interface == nominal.interface and mp.slider == nominal.slider


def test_the_fibres_friction(audit):
    rho = 1.12
    for th in (0.0, 12.5, -30.0, 45.0, 61.2, -90.0, 90.0):
        t = math.radians(th)
        want = 2 * (math.cos(t) ** 2 + rho * math.sin(t) ** 2) / (1 + rho)
        assert float(audit.fibre_factor(th, rho)) == pytest.approx(want, rel=1e-14)
    assert float(audit.fibre_factor(0.0, rho)) == pytest.approx(2 / 2.12, rel=1e-14)          # along the fibres
    assert float(audit.fibre_factor(90.0, rho)) == pytest.approx(2 * 1.12 / 2.12, rel=1e-14)  # across them
    assert float(audit.fibre_factor(45.0, rho)) == pytest.approx(1.0, rel=1e-14)              # the mat's own
    assert float(audit.fibre_factor(-45.0, rho)) == pytest.approx(1.0, rel=1e-14)
    th = np.linspace(-90, 90, 3601)
    f = audit.fibre_factor(th, rho)
    assert f == pytest.approx(f[::-1], rel=1e-14)                                             # even
    assert f.mean() == pytest.approx(1.0, abs=1e-3)                                           # the angle average
    assert np.all(np.diff(f[1800:]) >= 0)                                                     # rises with |theta|
    assert float(audit.fibre_factor(150.0, rho)) == pytest.approx(float(audit.fibre_factor(-30.0, rho)), rel=1e-13)
    # the docstring's numbers over the drawn rho: 0.93-0.97 along, 1.03-1.07 across
    assert 2 / 2.06 == pytest.approx(0.971, abs=1e-3) and 2 / 2.16 == pytest.approx(0.926, abs=1e-3)
    assert float(audit.fibre_factor(90.0, 1.16)) == pytest.approx(1.074, abs=1e-3)
    assert audit.FIBRE_RANGE_DEG == (-90.0, 90.0)


def test_the_plungers_friction_held_back(audit):
    F_b, q = 0.8, 0.8
    assert [audit.plunger_offset_N(k, 7, F_b, q) for k in range(7)] == [0.0] * 7             # before the first lift
    assert audit.plunger_offset_N(7, 7, F_b, q) == pytest.approx(0.64, rel=1e-14)             # run 8: one switch-on
    assert audit.plunger_offset_N(8, 7, F_b, q) == pytest.approx(0.512, rel=1e-14)
    assert audit.plunger_offset_N(13, 7, F_b, q) == pytest.approx(0.8 ** 8, rel=1e-13)
    assert audit.plunger_offset_N(14, 7, F_b, q) == pytest.approx(0.64, rel=1e-14)            # the second landing
    assert audit.plunger_offset_N(71, 10, 0.6, 0.75) == pytest.approx(0.6 * 0.75 ** 2, rel=1e-14)


def test_the_hook_cells_reading(audit):
    v = np.array([0.0, 0.01, 0.03, 0.05, 0.05, 0.0])           # a = 0, 10, 20, 20, 0, -50 m/s^2 at 1 ms
    T = audit.hook_tension_N(v, 1e-3, 0.05)
    assert T == pytest.approx([0.4905, 0.9905, 1.4905, 1.4905, 0.4905, 0.0], abs=1e-12)       # slack at the stop
    T = audit.hook_tension_N(v, 1e-3, -0.07)                    # a negative load: the weight sinks as v > 0
    assert T == pytest.approx([0.6867, 0.0, 0.0, 0.0, 0.6867, 0.6867 + 3.5], abs=1e-12)
    assert audit.hook_tension_N(-v, 1e-3, -0.07)[:4] == pytest.approx([0.6867, 1.3867, 2.0867, 2.0867], abs=1e-12)
    assert np.all(audit.hook_tension_N(v, 1e-3, 0.0) == 0.0)
    p = {"tau_c_s": 5e-3, "z_0_N": 0.003, "c_d_N_s": -5e-5}
    t = np.arange(6) * 1e-3
    y = audit.hook_cell_N(t, v, 1e-3, 0.05, 20.0, p)
    e = math.exp(-0.2)
    u = [0.4905, 0.9905, 1.4905, 1.4905, 0.4905, 0.0]
    want = [0.4905]
    for i in range(1, 6):
        want.append(u[i] + (want[-1] - u[i]) * e)
    assert y == pytest.approx(np.array(want) + 0.003 - 5e-5 * (20.0 + t), abs=1e-12)
    assert audit.hook_cell_N(t, v, 1e-3, 0.0, 0.0, p) == pytest.approx(0.003 - 5e-5 * t, abs=1e-15)


def test_the_runs_motors(audit, load_bench):
    nominal = load_bench("blind_effects").setting("clean", 1, audit.draw)[1]
    p = {"rho": 1.10, "theta_deg": np.array([0.0, 90.0, -45.0])}
    mp = audit.run_motor("lining_fibre_angle", nominal, p, 1, 290.0, F0)
    assert mp.interface.mu_p == pytest.approx(0.2 * 2.2 / 2.1, rel=1e-13)
    assert mp.stator == nominal.stator and mp.driver == nominal.driver and mp.slider == nominal.slider
    assert mp.interface.k_e_N_per_m == nominal.interface.k_e_N_per_m
    assert audit.run_motor("lining_fibre_angle", nominal, p, 2, 290.0, F0).interface.mu_p == pytest.approx(0.2)
    p = {"N": 6, "F_b_N": 0.7, "q": 0.75}
    mp = audit.run_motor("plunger_relanding", nominal, p, 13, 220.0, F0)
    assert mp.stator.P0_N == pytest.approx(6.35 - 0.7 * 0.75 ** 2, rel=1e-13)
    assert mp.driver == nominal.driver and mp.interface == nominal.interface and mp.slider == nominal.slider
    assert audit.run_motor("plunger_relanding", nominal, p, 5, 220.0, F0) == nominal
    assert audit.run_motor("hook_cell_decoy", nominal, {}, 3, 324.0, F0) == nominal
    assert audit.run_motor("clean", nominal, {}, 3, 324.0, F0) == nominal


def test_the_draws_stay_in_their_ranges(audit):
    draws = {kind: [audit.draw(kind, seed, 3) for seed in range(1, 301)] for kind in audit.KINDS}
    ranges = {"core_magnetostriction": {"sigma_f_Hz": (25.0, 45.0), "f_c_Hz": (96880.0, 97120.0),
                                        "Q_c": (300.0, 600.0), "r_324_ohm": (20.0, 35.0)},
              "lining_fibre_angle": {"rho": (1.06, 1.16)},
              "plunger_relanding": {"F_b_N": (0.6, 1.0), "q": (0.70, 0.90)},
              "hook_cell_decoy": {"tau_c_s": (3e-3, 10e-3), "z_0_N": (-5e-3, 5e-3), "c_d_N_s": (-1e-4, 1e-4)}}
    extra = {"core_magnetostriction": {"df_Hz"}, "lining_fibre_angle": {"theta_deg"}, "plunger_relanding": {"N"},
             "hook_cell_decoy": set()}
    for kind, rs in ranges.items():
        assert set(draws[kind][0]) == set(rs) | extra[kind], kind
        for key, (lo, hi) in rs.items():
            x = np.array([d[key] for d in draws[kind]])
            assert lo <= x.min() < lo + 0.02 * (hi - lo) and hi - 0.02 * (hi - lo) < x.max() <= hi, (kind, key)
    assert sorted({d["N"] for d in draws["plunger_relanding"]}) == [6, 7, 8, 9, 10]
    th = np.concatenate([audit.draw("lining_fibre_angle", seed, 72)["theta_deg"] for seed in range(1, 21)])
    assert -90 <= th.min() < -89 and 89 < th.max() <= 90 and th == pytest.approx(np.round(th, 1), abs=1e-9)
    assert th.mean() == pytest.approx(0.0, abs=4.0)
    rng = np.random.default_rng([2, 271, 0])                              # the core's own stream at seed 2
    d = audit.draw("core_magnetostriction", 2, 72)
    vals = rng.uniform([25.0, 96880.0, 300.0, 20.0], [45.0, 97120.0, 600.0, 35.0])
    assert [d[k] for k in ("sigma_f_Hz", "f_c_Hz", "Q_c", "r_324_ohm")] == pytest.approx(list(vals), rel=1e-14)
    assert d["df_Hz"] == pytest.approx(vals[0] * rng.standard_normal(72), rel=1e-12)
    rng = np.random.default_rng([1, 271, 1])
    d = audit.draw("lining_fibre_angle", 1, 72)
    assert d["rho"] == rng.uniform(1.06, 1.16)
    assert d["theta_deg"] == pytest.approx(np.round(rng.uniform(-90.0, 90.0, 72), 1), abs=1e-12)
    rng = np.random.default_rng([3, 271, 2])
    d = audit.draw("plunger_relanding", 3, 72)
    assert (d["N"], d["F_b_N"], d["q"]) == (int(rng.integers(6, 11)), rng.uniform(0.6, 1.0), rng.uniform(0.7, 0.9))
    rng = np.random.default_rng([1, 271, 3])
    assert audit.draw("hook_cell_decoy", 1, 72)["tau_c_s"] == rng.uniform(3e-3, 10e-3)
    assert audit.draw("clean", 1, 72) == {}


def test_the_cores_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("core_magnetostriction", 2, first=3)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["core_magnetostriction"] in df.columns and len(df.columns) == 8   # the drive's own column
    factors = be.setting("core_magnetostriction", 2, audit.draw)[3]
    clean = audit.experiment("clean", 2, first=3)[0]
    assert np.all(clean["frequency_Hz"] == F0)
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        f = round(F0 + p["df_Hz"][k - 1], 1)
        assert np.all(run["frequency_Hz"].to_numpy() == f) and pr[k - 1]["f_Hz"] == f
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        V0, V_free = audit.core_V0(nominal.driver, V, f, F0, 25.0, p)
        assert pr[k - 1]["V0_V"] == pytest.approx(V0, rel=1e-14) and V0 < V_free
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr[k - 1]["P0_N"] == mp.stator.P0_N and pr[k - 1]["mu_p"] == mp.interface.mu_p
        mp = mp.replace(driver__R_m_ohm=pr[k - 1]["R_m_ohm"])
        r = be.traverse(mp, nominal, plan, V, L, int(d), None, f)     # the supply set at f0, the drive at f
        pos = np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
        assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)


def test_the_fibres_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("lining_fibre_angle", 1, first=3)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["lining_fibre_angle"] in df.columns and len(df.columns) == 9
    factors = be.setting("lining_fibre_angle", 1, audit.draw)[3]
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        th = p["theta_deg"][k - 1]
        assert np.all(run["fibre_angle_deg"].to_numpy() == th) and np.all(run["frequency_Hz"] == F0)
        t = math.radians(th)
        mp = scattered_motor(nominal, factors[k - 1])
        mu = mp.interface.mu_p * 2 * (math.cos(t) ** 2 + p["rho"] * math.sin(t) ** 2) / (1 + p["rho"])
        assert pr[k - 1]["mu_p"] == pytest.approx(mu, rel=1e-13) and pr[k - 1]["P0_N"] == mp.stator.P0_N
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        r = be.traverse(mp.replace(interface__mu_p=mu), nominal, plan, V, L, int(d))
        pos = np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
        assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)


def test_the_relandings_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("plunger_relanding", 3, first=9)
    p, pr = truth["parameters"], truth["per_run"]
    assert p["N"] == 7 and audit.CHANNEL["plunger_relanding"] is None and len(df.columns) == 8
    factors = be.setting("plunger_relanding", 3, audit.draw)[3]
    clean = audit.experiment("clean", 3, first=9)[0]
    for k in range(1, 10):
        P0 = scattered_motor(nominal, factors[k - 1]).stator.P0_N
        held = 0.0 if k <= 7 else p["F_b_N"] * p["q"] ** (k - 7)                 # runs 8, 9 after the landing
        assert pr[k - 1]["P0_N"] == pytest.approx(P0 - held, rel=1e-14)
        if k <= 7:                                                                # before it: the clean runs
            assert df[df["run"] == k]["speed_m_s"].to_numpy() == pytest.approx(
                clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
    run = df[df["run"] == 8]
    V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
    mp = scattered_motor(nominal, factors[7])
    r = be.traverse(mp.replace(stator__P0_N=mp.stator.P0_N - p["F_b_N"] * p["q"]), nominal, plan, V, L, int(d))
    pos = np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
    assert len(run) > len(clean[clean["run"] == 8])                               # a lower preload: slower
    starts = df.groupby("run")["time_s"].first().to_numpy()
    ends = df.groupby("run")["time_s"].last().to_numpy()
    assert starts[1:] == pytest.approx(ends[:-1] + 1.0, abs=1e-9)                 # the plan's pauses, no more


def test_the_decoys_column(audit, load_bench):
    be = load_bench("blind_effects")
    b5 = load_bench("blind_effects_fifth")
    from l1b2.rig.experiment import scattered_motor
    first = 4
    df, truth, nominal, plan = audit.experiment("hook_cell_decoy", 2, first=first)
    p = truth["parameters"]
    column = audit.CHANNEL["hook_cell_decoy"]
    assert column in df.columns and audit.DECOY["hook_cell_decoy"] in column and len(df.columns) == 9
    factors = be.setting("hook_cell_decoy", 2, audit.draw)[3]
    clean = audit.experiment("clean", 2, first=first)[0]
    for k in range(1, first + 1):
        run = df[df["run"] == k]
        pr = truth["per_run"][k - 1]
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr["P0_N"] == mp.stator.P0_N and pr["mu_p"] == mp.interface.mu_p and pr["R_m_ohm"] == 2000.0
        assert run["speed_m_s"].to_numpy() == pytest.approx(clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        r = b5.traverse(mp, nominal, plan, V, L, int(d), record=b5.POSITION_AND_SPEED)[0]
        v = r["Slider.v"]
        a = np.concatenate([[0.0], np.diff(v) / 1e-3])
        u = np.maximum(0.0, abs(L) * G + L * a)
        y = np.empty_like(u)
        y[0] = abs(L) * G
        for i in range(1, len(u)):
            y[i] = u[i] + (y[i - 1] - u[i]) * math.exp(-1e-3 / p["tau_c_s"])
        t0 = float(run["time_s"].iloc[0])
        noise = np.random.default_rng([2, 272, k - 1]).standard_normal(len(run))
        want = np.round(y + p["z_0_N"] + p["c_d_N_s"] * (t0 + r["time"]) + 2e-3 * noise, 3)
        assert run["hook_cell_N"].to_numpy() == pytest.approx(want, abs=1e-9)
        j1, j2 = len(run) // 3, 2 * len(run) // 3          # mid-stroke: the weight's pull and its inertia, lagged
        pull = abs(L) * G + L * (v[j2] - v[j1]) / (r["time"][j2] - r["time"][j1])
        zero = p["z_0_N"] + p["c_d_N_s"] * (t0 + r["time"][(j1 + j2) // 2])
        assert run["hook_cell_N"].to_numpy()[j1:j2].mean() == pytest.approx(pull + zero, abs=0.03)
        last = run["hook_cell_N"].to_numpy()[-1] - zero
        if L * d < 0:                              # the weight sinks: the stop jerks the cable
            assert last > abs(L) * G + 0.5
        elif L * d > 0:                            # it rises: the stop slackens the cable
            assert last < abs(L) * G * (math.exp(-1e-3 / p["tau_c_s"]) + 0.05)
    Ld = df.groupby("run")[["load_kg", "direction"]].first().prod(axis=1).to_numpy()
    assert sorted(np.round(Ld, 9)) == [-0.07, -0.05, 0.05, 0.07]               # both ends of the stroke met


def test_the_accepted_regressors_and_the_pass_rule(audit):
    for name in ("frequency_Hz", "freq", "frequency_Hz_x_voltage", "d*frequency_Hz"):
        assert audit.accepted("core_magnetostriction", name), name
    for name in ("voltage", "load", "time", "voltage_V_lag1r", "fibre_angle_deg"):
        assert not audit.accepted("core_magnetostriction", name), name
    assert audit.accepted("lining_fibre_angle", "fibre_angle_deg")
    for name in ("voltage", "frequency_Hz", "time", "load"):
        assert not audit.accepted("lining_fibre_angle", name), name
    for name in ("time", "time_s", "session_clock", "elapsed_s", "run_index", "run_count", "run_order", "block_3",
                 "file", "segment", "period_8", "cycle", "phase", "sin_index", "cos_time", "sawtooth"):
        assert audit.accepted("plunger_relanding", name), name
    for name in ("time_in_run_s", "elapsed_in_run", "since_start", "onset_time", "time_since_break", "pause_time",
                 "voltage_V_lag1r", "prev_load_time", "time_last", "speed", "position", "load", "direction",
                 "voltage", "start_time", "speed_time", "position_x_time", "load_x_time", "direction_x_time",
                 "frequency_Hz", "hook_cell_N"):
        assert not audit.accepted("plunger_relanding", name), name
    assert not audit.accepted("hook_cell_decoy", "hook_cell_N")
    assert audit.B0 == {1: 3.037, 2: 2.815, 3: 3.241}
    b0 = 2.815
    row = {"kind": "core_magnetostriction", "seed": 2, "traced": ["voltage", "frequency_Hz"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "frequency_Hz"], "after": 3.0})["passes"]
    row = {"kind": "plunger_relanding", "seed": 3, "traced": ["load", "run_index"], "before": 4.5}
    assert audit.verdict(row | {"after": 3.5})["passes"]
    assert audit.verdict(row | {"after": 3.5})["bound"] == pytest.approx(math.sqrt(3.241 ** 2 + (4.5 ** 2
                                                                                                 - 3.241 ** 2) / 4))
    assert not audit.verdict(row | {"traced": ["load", "time_in_run_s"], "after": 3.4})["passes"]
    row = {"kind": "lining_fibre_angle", "seed": 1, "traced": ["fibre_angle_deg"], "before": 4.2, "after": 3.2}
    assert audit.verdict(row)["passes"] and not audit.verdict(row | {"traced": ["speed"]})["passes"]
    row = {"kind": "hook_cell_decoy", "seed": 1, "traced": ["voltage", "load"], "before": 3.037, "after": 3.05,
           "traced_all": ["voltage", "load", "hook_cell_N"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.037, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load", "dynamic_friction"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.11})["passes"]


def test_the_tables_name_every_kind(audit):
    kinds = set(audit.KINDS)
    assert audit.KINDS == ("core_magnetostriction", "lining_fibre_angle", "plunger_relanding", "hook_cell_decoy")
    assert set(audit.CHANNEL) == kinds and set(audit.WANT) == kinds
    assert set(audit.NOT_WANT) == {"plunger_relanding"}
    assert audit.DECOY == {"hook_cell_decoy": "hook_cell"} and audit.WANT["hook_cell_decoy"] == ()
    assert audit.CHANNEL == {"core_magnetostriction": "frequency_Hz", "lining_fibre_angle": "fibre_angle_deg",
                             "plunger_relanding": None, "hook_cell_decoy": "hook_cell_N"}
    assert audit.WANT["core_magnetostriction"] == ("frequency", "freq")
    for line in audit.__doc__.splitlines():
        assert len(line) <= 120
