"""bench/blind_effects_twentysixth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
tilted axis (the slider's weight down the slope as an equivalent load), the drive's thermal foldback (the heat sink's
path over the runs and the pauses and the amplitude it leaves), the holder's grip off the modes' nodes (the unloaded
B2 shape, the pads' stiffness and loss in each mode), the CO2 sensor's reading, the size measure, the draws, the made
data, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pandas as pd
import pytest

G = 9.81
L_PLATE = 0.030
BETA = 7.853204624095838


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twentysixth")


@pytest.fixture(scope="module")
def world(audit, load_bench):
    """``(plan, nominal, conds, factors)`` of seed 1's setting."""
    plan, nominal, conds, factors = load_bench("blind_effects").setting("clean", 1, audit.draw)[:4]
    return plan, nominal, conds, factors


def b2(x):
    """The unloaded free-free B2 shape written out (centred form), normalised numerically to int phi^2 = L."""
    k, h = BETA / L_PLATE, L_PLATE / 2
    xi = np.linspace(-h, h, 200001)
    raw = np.sin(k * xi) + math.sin(k * h) / math.sinh(k * h) * np.sinh(k * xi)
    D = math.sqrt(L_PLATE / np.trapezoid(raw ** 2, xi))
    D = D if raw[-1] > 0 else -D
    x = np.asarray(x, float) - h
    return D * (np.sin(k * x) + math.sin(k * h) / math.sinh(k * h) * np.sinh(k * x))


def modes(sp, delta, k_s, eta):
    """The grip's modes written out: added modal stiffness k_s phi^2 and loss eta times it, in each mode."""
    rhoS = sp.density_kg_m3 * sp.width_m * sp.thickness_m
    out = {}
    phi_l = math.cos(math.pi * (0.5 + delta / L_PLATE))
    for name, M, f, z, phi in (("l", rhoS * L_PLATE / 2, sp.f_l0_Hz, sp.zeta_l, phi_l),
                               ("b", rhoS * L_PLATE, sp.f_b0_Hz, sp.zeta_b, float(b2(L_PLATE / 2 + delta)))):
        K = M * (2 * math.pi * f) ** 2
        K2 = K + k_s * phi ** 2
        C = 2 * z * M * 2 * math.pi * f + eta * k_s * phi ** 2 / (2 * math.pi * f)
        w2 = math.sqrt(K2 / M)
        out[f"f_{name}0_Hz"] = w2 / (2 * math.pi)
        out[f"zeta_{name}"] = C / (2 * M * w2)
    return out


def co2_written_out(t, hangs, C_0, r, tau_p, tau_s):
    """The sensor integrated here: a first-order lag (tau_s) of the air's CO2 from C_0, on a fine grid from -5 s."""
    dt = 1e-3
    grid = np.arange(-5.0, max(t) + dt, dt)
    air = C_0 + r * np.maximum(grid, 0.0)
    for t_h, A in hangs:
        air = air + np.where(grid >= t_h, A * np.exp(-np.maximum(grid - t_h, 0.0) / tau_p), 0.0)
    y = np.empty_like(grid)
    y[0] = C_0
    a = dt / tau_s
    for i in range(1, len(grid)):                      # trapezoidal step of tau_s dy/dt = air - y
        y[i] = (y[i - 1] * (1 - a / 2) + a / 2 * (air[i - 1] + air[i])) / (1 + a / 2)
    return np.interp(t, grid, y)


def test_the_inclines_equivalent_load(audit, world):
    from l1b2.physics.slider import guide_friction_level_N
    nominal = world[1]
    for th in (-45.0, -12.3, 0.0, 7.5, 45.0):
        assert float(audit.incline_load_kg(th, 0.12)) == pytest.approx(0.12 * math.sin(th / 1000), rel=1e-14, abs=1e-18)
    assert float(audit.incline_load_kg(45.0, 0.12)) * 1000 == pytest.approx(5.4, abs=0.01)   # the docstring's 5.4 g
    assert audit.INCLINE_RANGE_MRAD == 45.0 and math.degrees(0.045) == pytest.approx(2.58, abs=0.01)
    assert math.cos(0.045) > 0.9989                                                         # the normal load kept
    p = {"theta_mrad": np.array([30.0, -20.0]), "z_0_mrad": 0.1}
    for k, L in ((0, 0.05), (1, -0.07), (0, 0.0)):
        mp, load = audit.run_motor("axis_incline", nominal, p, k, L)
        m_s = nominal.slider.mass_kg
        assert load == pytest.approx(L + m_s * math.sin(p["theta_mrad"][k] / 1000), rel=1e-14)
        assert mp.slider.mass_kg == pytest.approx(m_s + abs(L), rel=1e-14) and mp.slider.load_inertia == 0.0
        for F_p in (5.0, 6.0, 6.8):                                   # the guide's friction is the motor's
            want = guide_friction_level_N(nominal.slider, F_p)
            assert guide_friction_level_N(mp.slider, F_p) == pytest.approx(want, rel=1e-13)
        assert mp.stator == nominal.stator and mp.interface == nominal.interface and mp.driver == nominal.driver


def test_the_heat_sinks_path_and_the_foldback(audit):
    dT_a, tau, x_k, k_d = 40.0, 100.0, 1.0, 0.02
    for x0, V, on, off in ((0.0, 324.0, 0.3, 1.0), (2.5, 220.0, 0.5, 1.0), (1.2, 290.0, 0.0, 3.0),
                           (3.0, 0.0, 1.0, 0.0)):
        q = dT_a * (V / 324) ** 2
        want = (q + (x0 - q) * math.exp(-on / tau)) * math.exp(-off / tau)
        assert audit.heat_after(x0, V, on, off, dT_a, tau) == pytest.approx(want, rel=1e-14, abs=1e-15)
    # a long drive at 324 V settles at dT_a, a long pause at the idle level
    assert audit.heat_after(0.0, 324.0, 1e5, 0.0, dT_a, tau) == pytest.approx(dT_a, rel=1e-12)
    assert audit.heat_after(5.0, 324.0, 0.0, 1e5, dT_a, tau) == pytest.approx(0.0, abs=1e-12)
    assert audit.V0_HEAT_REF_V == 324.0
    for x, want in ((0.0, 1.0), (0.99, 1.0), (1.0, 1.0), (1.5, 0.99), (3.0, 0.96), (6.0, 0.90)):
        assert float(audit.foldback_factor(x, x_k, k_d)) == pytest.approx(want, rel=1e-14)
    # the docstring's numbers: 5 % at 3.9 K past a 1.3 K knee at 2 %/K
    assert float(audit.foldback_factor(3.9, 1.3, 0.02)) == pytest.approx(0.948, abs=1e-3)


def test_the_b2_shape_and_the_grips_modes(audit, world):
    from l1b2.physics import stator as st
    sp = world[1].stator
    x = np.linspace(0.0, L_PLATE, 31)
    assert audit.b2_shape(x, sp) == pytest.approx(b2(x), rel=1e-7, abs=1e-9)
    assert audit.b2_shape(x, sp) == pytest.approx(st.phi_b(st.b2_mode_shape(sp, 0.0), x), rel=1e-9, abs=1e-12)
    assert float(audit.b2_shape(L_PLATE, sp)) == pytest.approx(2.0, rel=1e-9)             # the tip
    assert float(audit.b2_shape(L_PLATE / 2, sp)) == pytest.approx(0.0, abs=1e-12)         # the centre's node
    slope = (float(audit.b2_shape(0.0151, sp)) - float(audit.b2_shape(0.0149, sp))) / 2e-4
    assert slope == pytest.approx(-360.0, abs=0.5)                                            # -360 delta / m
    for delta, k_s, eta in ((1e-3, 1e7, 0.08), (-0.6e-3, 0.7e7, 0.05), (1.35e-3, 1.2e7, 0.10), (0.0, 1e7, 0.1)):
        got = audit.grip_modes(sp, delta, k_s, eta)
        want = modes(sp, delta, k_s, eta)
        assert set(got) == set(want)
        for key in want:
            assert got[key] == pytest.approx(want[key], rel=1e-9), (delta, key)
        mirror = audit.grip_modes(sp, -delta, k_s, eta)                                      # even in delta
        assert all(mirror[key] == pytest.approx(got[key], rel=1e-12) for key in got)
    centred = audit.grip_modes(sp, 0.0, 1e7, 0.1)                                             # the motor's own
    assert centred["f_l0_Hz"] == sp.f_l0_Hz and centred["f_b0_Hz"] == sp.f_b0_Hz
    assert centred["zeta_l"] == pytest.approx(sp.zeta_l, rel=1e-15) and centred["zeta_b"] == sp.zeta_b
    # the docstring's numbers at 1 mm over the drawn k_s: B2 46-78 Hz up, L1 8-13 Hz, the damping within ~1.5 %
    lo, hi = audit.grip_modes(sp, 1e-3, 0.7e7, 0.1), audit.grip_modes(sp, 1e-3, 1.2e7, 0.1)
    assert 45.5 < lo["f_b0_Hz"] - sp.f_b0_Hz < 46.5 and 78 < hi["f_b0_Hz"] - sp.f_b0_Hz < 79
    assert 7.5 < lo["f_l0_Hz"] - sp.f_l0_Hz < 8 and 13 < hi["f_l0_Hz"] - sp.f_l0_Hz < 13.5
    hi = audit.grip_modes(sp, 1e-3, 1.2e7, 0.1)
    assert 1.0 < hi["zeta_b"] / sp.zeta_b < 1.013 and 1.0 < hi["zeta_l"] / sp.zeta_l < 1.002
    assert audit.SLIDE_RANGE_MM == 1.2


def test_the_co2_sensors_reading(audit):
    p = {"C_0_ppm": 500.0, "r_ppm_s": 0.25, "tau_p_s": 6.0, "tau_s_s": 20.0}
    hangs = [(-1.0, 40.0), (10.3, 25.0), (31.0, 55.0)]
    t = np.array([0.0, 0.5, 9.0, 10.3, 12.0, 30.0, 31.5, 47.2, 90.0])
    air = 500 + 0.25 * t + sum(np.where(t >= th, A * np.exp(-(t - th) / 6.0), 0.0) for th, A in hangs)
    assert audit.co2_air_ppm(t, hangs, p) == pytest.approx(air, rel=1e-14)
    closed = 500 + 0.25 * (t - 20 * (1 - np.exp(-t / 20))) + sum(
        np.where(t >= th, A * 6 / (6 - 20) * (np.exp(-(t - th) / 6) - np.exp(-(t - th) / 20)), 0.0) for th, A in hangs)
    assert audit.co2_sensor_ppm(t, hangs, p) == pytest.approx(closed, rel=1e-14)
    assert audit.co2_sensor_ppm(t, hangs, p) == pytest.approx(co2_written_out(t, hangs, 500, 0.25, 6, 20), abs=5e-3)
    assert audit.co2_sensor_ppm(t, [], p)[0] == 500.0                                        # at C_0 at the start
    # the DAQ holds the reading taken every 2 s, with 3 ppm of noise per reading, to 1 ppm
    noise = np.linspace(-1, 1, 64)
    ts = np.array([0.0, 1.999, 2.0, 2.001, 5.9, 47.25])
    j = np.array([0, 0, 1, 1, 2, 23])
    want = np.round(closed_at(2.0 * j, hangs) + 3.0 * noise[j])
    assert audit.co2_logged_ppm(ts, hangs, p, noise) == pytest.approx(want, abs=0)
    assert audit.CO2_INTERVAL_S == 2.0 and audit.CO2_NOISE_PPM == 3.0
    conds = [(220.0, 0.0, 1), (220.0, 0.0, -1), (255.0, 0.05, 1), (255.0, 0.05, -1), (324.0, 0.05, 1),
             (324.0, 0.05, -1), (290.0, 0.0, 1), (290.0, 0.0, -1), (220.0, -0.03, 1)]
    assert audit.weight_changes(conds) == [2, 6, 8]
    assert audit.weight_changes([(220.0, 0.07, 1), (220.0, 0.07, -1), (255.0, -0.07, 1)]) == [0, 2]


def closed_at(t, hangs):
    t = np.asarray(t, float)
    return 500 + 0.25 * (t - 20 * (1 - np.exp(-t / 20))) + sum(
        np.where(t >= th, A * 6 / (6 - 20) * (np.exp(-(t - th) / 6) - np.exp(-(t - th) / 20)), 0.0) for th, A in hangs)


def test_the_size_measure(audit):
    def frame(run, v):
        n = 60
        pos = np.cumsum(np.full(n, v * 1e-3)) - 0.021
        return pd.DataFrame({"run": run, "speed_m_s": np.full(n, v), "position_m": pos})
    clean = pd.concat([frame(1, 0.2), frame(2, -0.15), frame(3, 0.1)], ignore_index=True)
    df = pd.concat([frame(1, 0.21), frame(2, -0.147), frame(4, 0.3)], ignore_index=True)
    assert audit.speed_change(df, clean) == pytest.approx([0.05, -0.02], rel=1e-12)
    s = clean["speed_m_s"].to_numpy().copy()
    s[[0, 1, 2]] = 9.0                                                   # the run's first 2 mm are not evaluated
    assert audit.speed_change(clean.assign(speed_m_s=s), clean) == pytest.approx([0.0, 0.0, 0.0], abs=1e-15)


def test_the_runs_motors(audit, world):
    nominal = world[1]
    p = {"u_mm": np.array([0.8, -1.1]), "x_0_mm": 0.1, "k_s_N_m": 1e7, "eta": 0.07}
    mp, load = audit.run_motor("grip_node_offset", nominal, p, 1, 0.05)
    want = modes(nominal.stator, -1.2e-3, 1e7, 0.07)
    assert load == 0.05 and mp.slider == nominal.slider and mp.driver == nominal.driver
    assert mp.interface == nominal.interface and mp.stator.P0_N == nominal.stator.P0_N
    for key in want:
        assert getattr(mp.stator, key) == pytest.approx(want[key], rel=1e-9)
    assert mp.stator.f_b0_Hz > nominal.stator.f_b0_Hz + 60
    for kind in ("amp_thermal_foldback", "breath_co2_decoy", "clean"):
        assert audit.run_motor(kind, nominal, {}, 3, -0.09) == (nominal, -0.09)


def test_the_draws_stay_in_their_ranges(audit):
    draws = {kind: [audit.draw(kind, seed, 3) for seed in range(1, 301)] for kind in audit.KINDS}
    ranges = {"axis_incline": {"z_0_mrad": (-0.3, 0.3)},
              "amp_thermal_foldback": {"dT_a_K": (30.0, 45.0), "tau_h_s": (80.0, 160.0), "x_k_K": (0.5, 1.5),
                                       "k_d_per_K": (0.015, 0.03)},
              "grip_node_offset": {"x_0_mm": (-0.15, 0.15), "k_s_N_m": (0.7e7, 1.2e7), "eta": (0.05, 0.10)},
              "breath_co2_decoy": {"C_0_ppm": (450.0, 650.0), "r_ppm_s": (0.1, 0.4), "tau_p_s": (4.0, 8.0),
                                   "tau_s_s": (15.0, 30.0)}}
    extra = {"axis_incline": {"theta_mrad"}, "amp_thermal_foldback": set(), "grip_node_offset": {"u_mm"},
             "breath_co2_decoy": {"A_ppm"}}
    for kind, rs in ranges.items():
        assert set(draws[kind][0]) == set(rs) | extra[kind], kind
        for key, (lo, hi) in rs.items():
            x = np.array([d[key] for d in draws[kind]])
            assert lo <= x.min() < lo + 0.02 * (hi - lo) and hi - 0.02 * (hi - lo) < x.max() <= hi, (kind, key)
    th = np.concatenate([audit.draw("axis_incline", seed, 72)["theta_mrad"] for seed in range(1, 21)])
    assert -45 <= th.min() < -44.5 and 44.5 < th.max() <= 45 and th.mean() == pytest.approx(0.0, abs=2.0)
    u = np.concatenate([audit.draw("grip_node_offset", seed, 72)["u_mm"] for seed in range(1, 21)])
    assert -1.2 <= u.min() < -1.19 and 1.19 < u.max() <= 1.2 and u == pytest.approx(np.round(u, 3), abs=1e-12)
    A = np.concatenate([audit.draw("breath_co2_decoy", seed, 72)["A_ppm"] for seed in range(1, 21)])
    assert 20 <= A.min() < 20.5 and 59.5 < A.max() <= 60
    rng = np.random.default_rng([2, 281, 0])                               # the incline's own stream at seed 2
    d = audit.draw("axis_incline", 2, 72)
    assert d["z_0_mrad"] == rng.uniform(-0.3, 0.3) and list(d["theta_mrad"]) == list(rng.uniform(-45.0, 45.0, 72))
    rng = np.random.default_rng([1, 281, 1])
    d = audit.draw("amp_thermal_foldback", 1, 72)
    assert [d[k] for k in ("dT_a_K", "tau_h_s", "x_k_K", "k_d_per_K")] == list(
        rng.uniform([30.0, 80.0, 0.5, 0.015], [45.0, 160.0, 1.5, 0.03]))
    rng = np.random.default_rng([3, 281, 2])
    d = audit.draw("grip_node_offset", 3, 72)
    assert [d[k] for k in ("x_0_mm", "k_s_N_m", "eta")] == list(rng.uniform([-0.15, 0.7e7, 0.05], [0.15, 1.2e7, 0.10]))
    assert list(d["u_mm"]) == list(np.round(rng.uniform(-1.2, 1.2, 72), 3))
    rng = np.random.default_rng([1, 281, 3])
    d = audit.draw("breath_co2_decoy", 1, 72)
    assert [d[k] for k in ("C_0_ppm", "r_ppm_s", "tau_p_s", "tau_s_s")] == list(
        rng.uniform([450.0, 0.1, 4.0, 15.0], [650.0, 0.4, 8.0, 30.0]))
    assert list(d["A_ppm"]) == list(rng.uniform(20.0, 60.0, 72))
    assert audit.draw("clean", 1, 72) == {}


def positions(plan, r):
    return np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)


def test_the_inclines_made_data(audit, load_bench):
    be, b5 = load_bench("blind_effects"), load_bench("blind_effects_fifth")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("axis_incline", 2, first=3)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["axis_incline"] in df.columns and len(df.columns) == 9
    factors = be.setting("axis_incline", 2, audit.draw)[3]
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        th = p["theta_mrad"][k - 1]
        noise = np.random.default_rng([2, 282, k - 1]).standard_normal(len(run))
        assert run["base_level_mrad"].to_numpy() == pytest.approx(np.round(th + p["z_0_mrad"] + 0.02 * noise, 2),
                                                                  abs=1e-12)
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        mp = scattered_motor(nominal, factors[k - 1])
        m_s = mp.slider.mass_kg
        assert pr[k - 1]["load_in_kg"] == pytest.approx(L + 0.12 * math.sin(th / 1000), rel=1e-13)
        assert pr[k - 1]["mass_kg"] == pytest.approx(0.12 + abs(L), rel=1e-14)
        sl = mp.slider
        moved = mp.replace(slider__mass_kg=m_s + abs(L), slider__load_inertia=0.0,
                           slider__mu_sd=sl.mu_sd * m_s / (m_s + abs(L)), slider__mu_ss=sl.mu_ss * m_s / (m_s + abs(L)),
                           slider__kappa=sl.kappa * (m_s + abs(L)) / m_s)
        r = b5.traverse(moved, nominal, plan, V, L + m_s * math.sin(th / 1000), int(d))[0]
        assert run["position_m"].to_numpy() == pytest.approx(positions(plan, r), abs=1e-12)
        r0 = b5.traverse(mp, nominal, plan, V, L, int(d))[0]                  # the level base: slower uphill
        uphill = (th > 0) == (d > 0)
        assert (len(r["time"]) > len(r0["time"])) == uphill or abs(th) < 3


def test_the_foldbacks_made_data(audit, load_bench):
    be, b5 = load_bench("blind_effects"), load_bench("blind_effects_fifth")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("amp_thermal_foldback", 1)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["amp_thermal_foldback"] is None and len(df.columns) == 8
    clean = audit.experiment("clean", 1)[0]
    factors = be.setting("amp_thermal_foldback", 1, audit.draw)[3]
    x, gs, rises = 0.0, [], []
    for k in range(1, 73):
        run = df[df["run"] == k]
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        g = 1 - p["k_d_per_K"] * max(0.0, x - p["x_k_K"])
        assert pr[k - 1]["heat_K"] == pytest.approx(x, rel=1e-12, abs=1e-15)
        assert pr[k - 1]["V0_V"] == pytest.approx(g * V, rel=1e-13)
        dur = pr[k - 1]["duration_s"]
        assert run["time_s"].iloc[-1] - run["time_s"].iloc[0] == pytest.approx(dur, abs=1e-9)
        if g == 1.0:
            assert run["speed_m_s"].to_numpy() == pytest.approx(clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
        gs.append(g)
        q = p["dT_a_K"] * (g * V / 324.0) ** 2
        on = q + (x - q) * math.exp(-dur / p["tau_h_s"])
        rises.append(on - x)
        x = on * math.exp(-1.0 / p["tau_h_s"])
    gs = np.array(gs)
    # the docstring's numbers at seed 1: untouched up to run 17, about 5 % down at the end, x at 3.9 K
    assert np.all(gs[:17] == 1.0) and np.all(gs[17:] < 1.0)
    assert 0.94 < gs.min() < 0.96 and gs[-1] == gs.min() and 3.8 < x < 3.9 and max(rises) < 0.2
    assert 90 < pr[-1]["t_start_s"] < 92
    for k in (22, 60):
        run = df[df["run"] == k]
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        r = b5.traverse(scattered_motor(nominal, factors[k - 1]), nominal, plan, gs[k - 1] * V, L, int(d))[0]
        assert run["position_m"].to_numpy() == pytest.approx(positions(plan, r), abs=1e-12)
    starts = df.groupby("run")["time_s"].first().to_numpy()
    ends = df.groupby("run")["time_s"].last().to_numpy()
    assert starts[1:] == pytest.approx(ends[:-1] + 1.0, abs=1e-9)            # the plan's pauses, no more


def test_the_grips_made_data(audit, load_bench):
    be, b5 = load_bench("blind_effects"), load_bench("blind_effects_fifth")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("grip_node_offset", 3, first=3)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["grip_node_offset"] in df.columns and len(df.columns) == 9
    factors = be.setting("grip_node_offset", 3, audit.draw)[3]
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        u = p["u_mm"][k - 1]
        assert np.all(run["holder_slide_mm"].to_numpy() == u) and u == round(u, 3)
        mp = scattered_motor(nominal, factors[k - 1])
        want = modes(mp.stator, (u - p["x_0_mm"]) * 1e-3, p["k_s_N_m"], p["eta"])
        for key in want:
            assert pr[k - 1][key] == pytest.approx(want[key], rel=1e-9)
        assert pr[k - 1]["P0_N"] == mp.stator.P0_N and pr[k - 1]["mu_p"] == mp.interface.mu_p
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        r = b5.traverse(mp.replace(**{f"stator__{key}": v for key, v in want.items()}), nominal, plan, V, L, int(d))[0]
        assert run["position_m"].to_numpy() == pytest.approx(positions(plan, r), abs=1e-12)


def test_the_decoys_column(audit, load_bench):
    df, truth, nominal, plan = audit.experiment("breath_co2_decoy", 2, first=8)
    p = truth["parameters"]
    column = audit.CHANNEL["breath_co2_decoy"]
    assert column in df.columns and audit.DECOY["breath_co2_decoy"] in column and len(df.columns) == 9
    clean = audit.experiment("clean", 2, first=8)[0]
    assert df["speed_m_s"].to_numpy() == pytest.approx(clean["speed_m_s"].to_numpy(), abs=0)
    assert df["position_m"].to_numpy() == pytest.approx(clean["position_m"].to_numpy(), abs=0)
    loads = df.groupby("run")["load_kg"].first().to_numpy()
    starts = df.groupby("run")["time_s"].first().to_numpy()
    hangs = [(starts[k] - 1.0, p["A_ppm"][k]) for k in range(8) if loads[k] != (loads[k - 1] if k else 0.0)]
    assert len(hangs) >= 3
    t = df["time_s"].to_numpy()
    j = np.floor(t / 2.0 + 1e-9).astype(int)
    noise = np.random.default_rng([2, 283]).standard_normal(4096)
    tp, ts = p["tau_p_s"], p["tau_s_s"]
    tj = 2.0 * j
    y = p["C_0_ppm"] + p["r_ppm_s"] * (tj - ts * (1 - np.exp(-tj / ts)))
    for th, A in hangs:
        y = y + np.where(tj >= th, A * tp / (tp - ts) * (np.exp(-(tj - th) / tp) - np.exp(-(tj - th) / ts)), 0.0)
    assert df[column].to_numpy() == pytest.approx(np.round(y + 3.0 * noise[j]), abs=0)
    assert df[column].to_numpy() == pytest.approx(co2_written_out(tj, hangs, p["C_0_ppm"], p["r_ppm_s"], tp, ts)
                                                  + 3.0 * noise[j], abs=0.51)
    steps = np.flatnonzero(np.diff(j))                                          # it changes only at a new reading
    same = np.setdiff1d(np.arange(len(t) - 1), steps)
    assert np.all(np.diff(df[column].to_numpy())[same] == 0)


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("axis_incline", "base_level_mrad")
    for name in ("load", "voltage", "time", "direction", "load_kg_x_direction", "holder_slide_mm"):
        assert not audit.accepted("axis_incline", name), name
    assert audit.accepted("grip_node_offset", "holder_slide_mm")
    assert audit.accepted("grip_node_offset", "holder_slide_mm_sq")
    for name in ("voltage", "frequency_Hz", "time", "base_level_mrad", "load"):
        assert not audit.accepted("grip_node_offset", name), name
    for name in ("time", "time_s", "session_clock", "elapsed_s", "run_index", "run_count", "run_order", "block_3",
                 "segment", "regime", "cumulative_drive", "drive_history", "memory", "heat_state", "thermal_drift",
                 "drift", "trend", "voltage_V_x_time", "voltage_history"):
        assert audit.accepted("amp_thermal_foldback", name), name
    for name in ("time_in_run_s", "elapsed_in_run", "since_start", "onset_time", "time_since_break", "pause_time",
                 "voltage_V_lag1r", "prev_load_time", "time_last", "speed", "position", "load", "direction",
                 "voltage", "start_time", "speed_time", "position_x_time", "load_x_time", "direction_x_time",
                 "frequency_Hz", "frequency_time", "base_level_mrad", "holder_slide_mm", "co2_ppm", "hinge",
                 "voltage_step"):
        assert not audit.accepted("amp_thermal_foldback", name), name
    assert not audit.accepted("breath_co2_decoy", "co2_ppm")
    assert audit.B0 == {1: 3.037, 2: 2.815, 3: 3.241}
    b0 = 2.815
    row = {"kind": "axis_incline", "seed": 2, "traced": ["voltage", "base_level_mrad"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "base_level_mrad"], "after": 3.0})["passes"]
    row = {"kind": "amp_thermal_foldback", "seed": 3, "traced": ["load", "run_index"], "before": 4.5}
    assert audit.verdict(row | {"after": 3.5})["passes"]
    assert audit.verdict(row | {"after": 3.5})["bound"] == pytest.approx(math.sqrt(3.241 ** 2 + (4.5 ** 2
                                                                                                 - 3.241 ** 2) / 4))
    assert not audit.verdict(row | {"traced": ["load", "time_in_run_s"], "after": 3.4})["passes"]
    row = {"kind": "grip_node_offset", "seed": 1, "traced": ["holder_slide_mm"], "before": 4.2, "after": 3.2}
    assert audit.verdict(row)["passes"] and not audit.verdict(row | {"traced": ["speed"]})["passes"]
    assert audit.verdict(row)["bound"] == pytest.approx(math.sqrt(3.037 ** 2 + (4.2 ** 2 - 3.037 ** 2) / 4))
    row = {"kind": "breath_co2_decoy", "seed": 1, "traced": ["voltage", "load"], "before": 3.037, "after": 3.05,
           "traced_all": ["voltage", "load", "co2_ppm"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.037, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load", "dynamic_friction"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.11})["passes"]


def test_the_tables_name_every_kind(audit):
    kinds = set(audit.KINDS)
    assert audit.KINDS == ("axis_incline", "amp_thermal_foldback", "grip_node_offset", "breath_co2_decoy")
    assert set(audit.CHANNEL) == kinds and set(audit.WANT) == kinds
    assert set(audit.NOT_WANT) == {"amp_thermal_foldback"}
    assert audit.DECOY == {"breath_co2_decoy": "co2"} and audit.WANT["breath_co2_decoy"] == ()
    assert audit.CHANNEL == {"axis_incline": "base_level_mrad", "amp_thermal_foldback": None,
                             "grip_node_offset": "holder_slide_mm", "breath_co2_decoy": "co2_ppm"}
    assert audit.WANT["axis_incline"] == ("base_level",) and audit.WANT["grip_node_offset"] == ("holder_slide",)
    assert audit.WANT["amp_thermal_foldback"] == (
        "time", "session", "clock", "elapsed", "index", "count", "order", "block", "segment", "regime", "cumul",
        "history", "memory", "heat", "therm", "drift", "trend")
    assert audit.NOT_WANT["amp_thermal_foldback"] == (
        "time_in_run", "in_run", "onset", "start", "break", "pause", "_lag", "prev", "last", "load", "direction",
        "speed", "position", "frequency")
    for line in audit.__doc__.splitlines():
        assert len(line) <= 120
