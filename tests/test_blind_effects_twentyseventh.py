"""bench/blind_effects_twentyseventh.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
pitched load wire (the pull along the axis, the weight's inertia and the guide's normal load), the voice coil (its
current with the back-EMF and its push), the cold cloud (two lags of a pulse, the modes it moves), the drive fan's
tachometer (the heat sink's path, the controller's hysteresis, the fan's lag), the size measure, the draws, the made
data, the seeds, the accepted regressors, the pass rule and the command line.
"""

import math

import numpy as np
import pandas as pd
import pytest

G = 9.81


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twentyseventh")


@pytest.fixture(scope="module")
def world(audit, load_bench):
    """``(plan, nominal, conds, factors)`` of seed 1's setting."""
    plan, nominal, conds, factors = load_bench("blind_effects").setting("clean", 1, audit.draw)[:4]
    return plan, nominal, conds, factors


def two_lags(t, p, dt=2e-3):
    """The cloud written out: the air's deficit (lag tau_a of dT_a from t_1 to t_1 + T_f) and the stator's (lag tau_s
    of the air's), both integrated here by the trapezoidal rule from 0 at the session's start."""
    grid = np.arange(0.0, max(t) + dt, dt)
    src = np.where((grid >= p["t_1_s"]) & (grid < p["t_1_s"] + p["T_f_s"]), p["dT_a_K"], 0.0)
    air, y = np.zeros_like(grid), np.zeros_like(grid)
    ka, ks = dt / p["tau_a_s"], dt / p["tau_s_s"]
    for i in range(1, len(grid)):
        air[i] = (air[i - 1] * (1 - ka / 2) + ka / 2 * (src[i - 1] + src[i])) / (1 + ka / 2)
        y[i] = (y[i - 1] * (1 - ks / 2) + ks / 2 * (air[i - 1] + air[i])) / (1 + ks / 2)
    return np.interp(t, grid, y)


def fan_written_out(t, spans, p, dt=1e-3):
    """The fan stepped here on a 1 ms grid of the session: the heat sink (exact first-order steps, toward dT_a (V0 /
    324 V)^2 while a run drives, else 0), the controller (every 0.1 s: off/low/high, up at x_1 and x_1 + dx, down h
    below each) and the fan (a first-order lag tau_f of the command)."""
    n = int(round(max(t) / dt)) + 2
    on = np.zeros(n, bool)
    q = np.zeros(n)
    for t_on, t_off, V0 in spans:
        i0, i1 = int(round(t_on / dt)), int(round(t_off / dt))
        on[i0:i1] = True
        q[i0:i1] = p["dT_a_K"] * (V0 / 324.0) ** 2
    x, level, w = 0.0, 0, 0.0
    cmd_of = {0: 0.0, 1: p["rpm_lo"], 2: p["rpm_hi"]}
    W = np.zeros(n)
    for i in range(n):
        if i % 100 == 0:                                     # the controller's reading every 0.1 s
            if level == 0 and x >= p["x_1_K"]:
                level = 1
            if level == 1 and x >= p["x_1_K"] + p["dx_K"]:
                level = 2
            if level == 2 and x <= p["x_1_K"] + p["dx_K"] - p["h_K"]:
                level = 1
            if level == 1 and x <= p["x_1_K"] - p["h_K"]:
                level = 0
            cmd = cmd_of[level]
        W[i] = w
        x = q[i] + (x - q[i]) * math.exp(-dt / p["tau_h_s"])
        w = cmd + (w - cmd) * math.exp(-dt / p["tau_f_s"])
    return W[np.round(np.asarray(t) / dt).astype(int)]


def positions(plan, r):
    return np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)


def test_the_pitched_wires_motor(audit, world):
    from l1b2.physics.slider import guide_friction_level_N, load_force_N, moving_mass_kg
    nominal = world[1]
    sl = nominal.slider
    for h, D in ((160.0, 0.28), (-160.0, 0.28), (37.5, 0.33), (0.0, 0.3), (-0.1, 0.36)):
        assert float(audit.pitch_rad(h, D)) == pytest.approx(math.atan2(h / 1000.0, D), rel=1e-14, abs=1e-18)
    for L, h, D in ((0.05, 120.0, 0.30), (-0.09, -160.0, 0.28), (0.03, -45.2, 0.36), (-0.07, 150.0, 0.29),
                    (0.09, 160.0, 0.28)):
        beta = math.atan(h / 1000.0 / D)
        mp, load = audit.pitch_motor(nominal, L, beta)
        assert load == pytest.approx(L * math.cos(beta), rel=1e-14)
        assert float(load_force_N(load)) == pytest.approx(G * L * math.cos(beta), rel=1e-13)   # the pull along
        assert float(moving_mass_kg(mp.slider, load)) == pytest.approx(sl.mass_kg + abs(L) * math.cos(beta) ** 2,
                                                                       rel=1e-13)
        for F_p in (5.0, 6.0, 6.8):                           # the guide carries the wire's pull across the axis
            for static, mu in ((False, sl.mu_sd), (True, sl.mu_ss)):
                want = mu * (sl.kappa * F_p + G * sl.mass_kg - G * abs(L) * math.sin(beta))
                assert float(guide_friction_level_N(mp.slider, F_p, static)) == pytest.approx(want, rel=1e-13)
        assert mp.slider.mass_kg == sl.mass_kg and mp.slider.pulley_mu == 0.0
        assert mp.slider.c_r_N_s_per_m == sl.c_r_N_s_per_m and mp.slider.s_max_m == sl.s_max_m
        assert mp.stator == nominal.stator and mp.interface == nominal.interface and mp.driver == nominal.driver
    assert audit.pitch_motor(nominal, 0.0, 0.4) == (nominal, 0.0)             # no load: no wire
    # the pull's shortfall is even in the pitch, the guide's change odd
    b = math.atan(0.12 / 0.3)
    up, down = audit.pitch_motor(nominal, 0.05, b), audit.pitch_motor(nominal, 0.05, -b)
    assert up[1] == down[1] and up[0].slider.load_inertia == down[0].slider.load_inertia
    assert up[0].slider.mu_sd < sl.mu_sd < down[0].slider.mu_sd
    assert up[0].slider.mu_sd + down[0].slider.mu_sd == pytest.approx(2 * sl.mu_sd, rel=1e-14)
    # the docstring's numbers: up to +-24-30 deg, a shortfall up to 13 %, 4.9 mN of guide friction per 10 g
    assert audit.PULLEY_RISE_MM == 160.0
    assert math.degrees(math.atan(0.16 / 0.36)) == pytest.approx(24.0, abs=0.05)
    assert math.degrees(math.atan(0.16 / 0.28)) == pytest.approx(29.7, abs=0.05)
    assert 1 - math.cos(math.atan(0.16 / 0.28)) == pytest.approx(0.13, abs=0.002)
    assert 0.1 * G * 0.01 * math.sin(math.atan(0.16 / 0.28)) == pytest.approx(4.9e-3, abs=0.05e-3)


def test_the_voice_coils_current_and_push(audit):
    for u, v, K, R in ((0.3, 0.2, 0.5, 4.0), (-0.45, -0.15, 0.55, 3.5), (0.0, 0.28, 0.45, 4.5), (0.12, 0.0, 0.5, 4.1)):
        i = (u - K * v) / R
        assert float(audit.vcm_current_A(u, v, K, R)) == pytest.approx(i, rel=1e-14, abs=1e-17)
        assert float(audit.vcm_force_N(u, v, K, R)) == pytest.approx(K * i, rel=1e-14, abs=1e-17)
    v = np.linspace(-0.3, 0.3, 7)
    i = audit.vcm_current_A(0.2, v, 0.5, 4.0)
    assert np.all(np.diff(i) < 0)                                   # the back-EMF opposes the motion
    assert i == pytest.approx((0.2 - 0.5 * v) / 4.0, rel=1e-14)
    assert audit.VCM_U_V == 0.45 and audit.VCM_NOISE_MA == 0.3
    # the docstring's numbers: a push up to 71 mN, a drag of 0.045-0.086 N s/m, 44 mA of back-EMF at 0.28 m/s
    assert 0.55 * 0.45 / 3.5 == pytest.approx(0.071, abs=5e-4)
    assert 0.45 ** 2 / 4.5 == pytest.approx(0.045, abs=5e-4) and 0.55 ** 2 / 3.5 == pytest.approx(0.086, abs=5e-4)
    assert 0.55 * 0.28 / 3.5 == pytest.approx(0.044, abs=5e-4)


def test_the_clouds_dip_and_the_modes(audit, world):
    sp = world[1].stator
    for tau_a, tau_s in ((5.0, 50.0), (9.0, 41.0), (4.0, 80.0)):
        t = np.array([-1.0, 0.0, 0.5, 3.0, 20.0, 100.0, 1000.0])
        c = audit.cascade_step(t, tau_a, tau_s)
        u = np.maximum(t, 0.0)
        want = np.where(t > 0, 1 - (tau_a * np.exp(-u / tau_a) - tau_s * np.exp(-u / tau_s)) / (tau_a - tau_s), 0.0)
        assert c == pytest.approx(want, rel=1e-13, abs=1e-15)
        assert c[-1] == pytest.approx(1.0, abs=1e-3) and c[2] == pytest.approx(0.25 / (2 * tau_a * tau_s), rel=0.2)
    p = {"t_1_s": 16.0, "T_f_s": 25.0, "dT_a_K": 9.0, "tau_a_s": 6.0, "tau_s_s": 55.0}
    t = np.array([0.0, 10.0, 16.0, 18.5, 30.0, 41.0, 47.3, 60.0, 90.0])
    y = audit.stator_dip_K(t, p)
    assert y == pytest.approx(two_lags(t, p), abs=2e-3)
    assert np.all(y[:3] == 0.0) and np.all(y[3:] > 0)
    tt = np.linspace(0, 200, 20001)
    yy = audit.stator_dip_K(tt, p)
    assert 41.0 < tt[yy.argmax()] < 60.0 and yy.max() < p["dT_a_K"] * (1 - math.exp(-25.0 / 55.0))
    for y_K in (0.0, 1.7, 3.5):
        mp = audit.cloud_motor(world[1], y_K, {"c_b_Hz_K": -25.0, "c_l_Hz_K": -12.0})
        assert mp.stator.f_b0_Hz == pytest.approx(sp.f_b0_Hz + 25.0 * y_K, rel=1e-15)
        assert mp.stator.f_l0_Hz == pytest.approx(sp.f_l0_Hz + 12.0 * y_K, rel=1e-15)
        assert mp.stator.P0_N == sp.P0_N and mp.stator.zeta_b == sp.zeta_b and mp.slider == world[1].slider
    # the docstring's numbers at seeds 1-3: a tenth some 5 s after t_1, the peak 3.0-3.5 K 4-11 s after the fill,
    # 1.5-2.4 K at the session's end (90 s)
    for seed in (1, 2, 3):
        p = audit.draw("cold_gas_cloud", seed, 72)
        yy = audit.stator_dip_K(tt, p)
        assert 2.95 < yy.max() < 3.55 and 4 < tt[yy.argmax()] - p["t_1_s"] - p["T_f_s"] < 11.5
        assert 5 < tt[np.argmax(yy > 0.1 * yy.max())] - p["t_1_s"] < 6.5
        assert 1.45 < float(audit.stator_dip_K(90.0, p)) < 2.45


def test_the_fans_heat_staircase_and_tachometer(audit):
    spans = [(0.0, 0.4, 324.0), (1.4, 1.9, 220.0), (2.9, 3.2, 290.0), (4.2, 4.9, 255.0)]
    p = {"dT_a_K": 35.0, "tau_h_s": 3.0, "x_1_K": 1.0, "dx_K": 1.2, "h_K": 0.3, "rpm_lo": 2000.0,
         "rpm_hi": 4000.0, "tau_f_s": 0.5}
    t = np.round(np.arange(0.0, 20.0, 0.001), 9)
    x = audit.heat_path(t, spans, p["dT_a_K"], p["tau_h_s"])
    xs, t_prev, want = 0.0, 0.0, []
    for t_on, t_off, V0 in spans:                     # the heat at each run's end, by the closed form
        xs *= math.exp(-(t_on - t_prev) / 3.0)
        q = 35.0 * (V0 / 324.0) ** 2
        xs = q + (xs - q) * math.exp(-(t_off - t_on) / 3.0)
        want.append(xs)
        t_prev = t_off
    ends = [int(round(t_off / 0.001)) for _, t_off, _ in spans]
    assert x[ends] == pytest.approx(want, rel=1e-9)
    assert x[0] == 0.0 and x[-1] == pytest.approx(want[-1] * math.exp(-(t[-1] - 4.9) / 3.0), rel=1e-9)
    assert audit.FAN_HEAT_REF_V == 324.0 and audit.FAN_TICK_S == 0.1 and audit.FAN_JITTER == 0.005
    # the controller: up at x_1 and x_1 + dx, down h below each, one reading at a time
    lev = audit.fan_levels([0.0, 0.99, 1.0, 1.5, 2.19, 2.2, 2.0, 1.91, 1.9, 1.0, 0.71, 0.7, 3.0, 0.1], 1.0, 1.2, 0.3)
    assert list(lev) == [0, 0, 1, 1, 1, 2, 2, 2, 1, 1, 1, 0, 2, 0]
    rpm = audit.fan_rpm(t, spans, p)
    assert rpm == pytest.approx(fan_written_out(t, spans, p), rel=1e-9, abs=1e-6)
    assert rpm[0] == 0.0 and rpm.max() > 3000.0 and rpm[-1] < rpm.max()
    noise = np.sin(np.arange(len(t)))
    logged = audit.fan_logged_rpm(t, spans, p, noise)
    assert logged == pytest.approx(np.round(rpm * (1 + 0.005 * noise) / 10) * 10, abs=0)
    assert np.all(logged[rpm == 0.0] == 0.0) and np.all(logged % 10 == 0)


def test_the_size_measure(audit, load_bench):
    assert audit.speed_change is audit.b26.speed_change and audit.b26.__file__.endswith("blind_effects_twentysixth.py")

    def frame(run, v):
        n = 60
        return pd.DataFrame({"run": run, "speed_m_s": np.full(n, v), "position_m": np.cumsum(np.full(n, v * 1e-3))})
    clean = pd.concat([frame(1, 0.2), frame(2, -0.15)], ignore_index=True)
    df = pd.concat([frame(1, 0.206), frame(2, -0.147)], ignore_index=True)
    assert audit.speed_change(df, clean) == pytest.approx([0.03, -0.02], rel=1e-12)


def test_the_draws_stay_in_their_ranges(audit):
    draws = {kind: [audit.draw(kind, seed, 3) for seed in range(1, 301)] for kind in audit.KINDS}
    ranges = {"pulley_pitch": {"D_m": (0.28, 0.36)},
              "voice_coil_load": {"K_N_A": (0.45, 0.55), "R_ohm": (3.5, 4.5)},
              "cold_gas_cloud": {"t_1_s": (10.0, 40.0), "T_f_s": (20.0, 40.0), "dT_a_K": (7.5, 11.5),
                                 "tau_a_s": (4.0, 10.0), "tau_s_s": (40.0, 80.0), "c_b_Hz_K": (-30.0, -20.0),
                                 "c_l_Hz_K": (-20.0, -10.0)},
              "drive_fan_decoy": {"dT_a_K": (25.0, 40.0), "tau_h_s": (60.0, 120.0), "x_1_K": (0.8, 1.6),
                                  "dx_K": (1.0, 1.6), "h_K": (0.2, 0.4), "rpm_lo": (1800.0, 2400.0),
                                  "rpm_hi": (3600.0, 4400.0), "tau_f_s": (1.5, 3.0)}}
    extra = {"pulley_pitch": {"h_mm"}, "voice_coil_load": {"u_V"}, "cold_gas_cloud": set(), "drive_fan_decoy": set()}
    for kind, rs in ranges.items():
        assert set(draws[kind][0]) == set(rs) | extra[kind], kind
        for key, (lo, hi) in rs.items():
            x = np.array([d[key] for d in draws[kind]])
            assert lo <= x.min() < lo + 0.02 * (hi - lo) and hi - 0.02 * (hi - lo) < x.max() <= hi, (kind, key)
    h = np.concatenate([audit.draw("pulley_pitch", seed, 72)["h_mm"] for seed in range(1, 21)])
    assert -160 <= h.min() < -159 and 159 < h.max() <= 160 and h == pytest.approx(np.round(h, 1), abs=1e-12)
    u = np.concatenate([audit.draw("voice_coil_load", seed, 72)["u_V"] for seed in range(1, 21)])
    assert -0.45 <= u.min() < -0.447 and 0.447 < u.max() <= 0.45 and u == pytest.approx(np.round(u, 3), abs=1e-12)
    rng = np.random.default_rng([2, 291, 0])                               # the pitch's own stream at seed 2
    d = audit.draw("pulley_pitch", 2, 72)
    assert d["D_m"] == rng.uniform(0.28, 0.36) and list(d["h_mm"]) == list(np.round(rng.uniform(-160, 160, 72), 1))
    rng = np.random.default_rng([1, 291, 1])
    d = audit.draw("voice_coil_load", 1, 72)
    assert [d["K_N_A"], d["R_ohm"]] == list(rng.uniform([0.45, 3.5], [0.55, 4.5]))
    assert list(d["u_V"]) == list(np.round(rng.uniform(-0.45, 0.45, 72), 3))
    rng = np.random.default_rng([3, 291, 2])
    d = audit.draw("cold_gas_cloud", 3, 72)
    keys = ("t_1_s", "T_f_s", "dT_a_K", "tau_a_s", "tau_s_s", "c_b_Hz_K", "c_l_Hz_K")
    assert [d[k] for k in keys] == list(rng.uniform([10.0, 20.0, 7.5, 4.0, 40.0, -30.0, -20.0],
                                                    [40.0, 40.0, 11.5, 10.0, 80.0, -20.0, -10.0]))
    rng = np.random.default_rng([1, 291, 3])
    d = audit.draw("drive_fan_decoy", 1, 72)
    keys = ("dT_a_K", "tau_h_s", "x_1_K", "dx_K", "h_K", "rpm_lo", "rpm_hi", "tau_f_s")
    assert [d[k] for k in keys] == list(rng.uniform([25.0, 60.0, 0.8, 1.0, 0.2, 1800.0, 3600.0, 1.5],
                                                    [40.0, 120.0, 1.6, 1.6, 0.4, 2400.0, 4400.0, 3.0]))
    assert audit.draw("clean", 1, 72) == {}


def test_the_pitchs_made_data(audit, load_bench):
    be, b5 = load_bench("blind_effects"), load_bench("blind_effects_fifth")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("pulley_pitch", 2, first=4)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["pulley_pitch"] in df.columns and len(df.columns) == 9
    factors = be.setting("pulley_pitch", 2, audit.draw)[3]
    loaded = 0
    for k in (1, 2, 3, 4):
        run = df[df["run"] == k]
        h = p["h_mm"][k - 1]
        assert np.all(run["pulley_rise_mm"].to_numpy() == h) and h == round(h, 1)
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        beta = math.atan(h / 1000.0 / p["D_m"])
        mp = scattered_motor(nominal, factors[k - 1])
        if L:
            loaded += 1
            sl = mp.slider
            r = 1 - abs(L) * math.sin(beta) / sl.mass_kg
            mp = mp.replace(slider__load_inertia=math.cos(beta), slider__mu_sd=sl.mu_sd * r,
                            slider__mu_ss=sl.mu_ss * r, slider__kappa=sl.kappa / r)
        assert pr[k - 1]["load_in_kg"] == pytest.approx(L * math.cos(beta), rel=1e-13, abs=0)
        assert pr[k - 1]["kappa"] == pytest.approx(mp.slider.kappa, rel=1e-13)
        assert pr[k - 1]["load_inertia"] == pytest.approx(mp.slider.load_inertia, rel=1e-13)
        r = b5.traverse(mp, nominal, plan, V, L * math.cos(beta), int(d))[0]
        assert run["position_m"].to_numpy() == pytest.approx(positions(plan, r), abs=1e-12)
    assert loaded >= 3


def test_the_voice_coils_made_data(audit, load_bench):
    be, b5 = load_bench("blind_effects"), load_bench("blind_effects_fifth")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("voice_coil_load", 1, first=3)
    p = truth["parameters"]
    assert audit.CHANNEL["voice_coil_load"] in df.columns and len(df.columns) == 9
    factors = be.setting("voice_coil_load", 1, audit.draw)[3]
    K, R = p["K_N_A"], p["R_ohm"]
    spans = []
    for k in (1, 2, 3):
        run = df[df["run"] == k]
        u = p["u_V"][k - 1]
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        mp = scattered_motor(nominal, factors[k - 1])
        sl = mp.slider
        m2 = sl.mass_kg + abs(L)
        moved = mp.replace(slider__mass_kg=m2, slider__load_inertia=0.0, slider__mu_sd=sl.mu_sd * sl.mass_kg / m2,
                           slider__mu_ss=sl.mu_ss * sl.mass_kg / m2, slider__kappa=sl.kappa * m2 / sl.mass_kg)
        r = b5.traverse(moved, nominal, plan, V, L, int(d), load_law=lambda t, s, v: L - K * (u - K * v) / R / G,
                        record=("Slider.s", "Slider.v"))[0]
        assert run["position_m"].to_numpy() == pytest.approx(positions(plan, r), abs=1e-12)
        noise = np.random.default_rng([1, 292, k - 1]).standard_normal(len(run))
        i_mA = 1000.0 * (u - K * r["Slider.v"]) / R
        assert run["vcm_current_mA"].to_numpy() == pytest.approx(np.round(i_mA + 0.3 * noise, 1), abs=1e-9)
        spans.append(np.ptp(i_mA))
        r0 = b5.traverse(mp, nominal, plan, V, L, int(d))[0]               # no coil: pushed runs go faster
        if abs(u) > 0.1:
            assert (len(r["time"]) < len(r0["time"])) == (u * d > 0)
    assert max(spans) > 10.0                                                # the speed's echo within a run


def test_the_clouds_made_data(audit, load_bench):
    be, b5 = load_bench("blind_effects"), load_bench("blind_effects_fifth")
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("cold_gas_cloud", 1, first=30)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["cold_gas_cloud"] is None and len(df.columns) == 8
    clean = audit.experiment("clean", 1, first=30)[0]
    factors = be.setting("cold_gas_cloud", 1, audit.draw)[3]
    starts = df.groupby("run")["time_s"].first().to_numpy()
    ends = df.groupby("run")["time_s"].last().to_numpy()
    assert starts[1:] == pytest.approx(ends[:-1] + 1.0, abs=1e-9)          # the plan's pauses, no more
    y = two_lags(starts, p)
    assert np.sum(y == 0.0) >= 10 and y.max() > 2.0
    for k in range(1, 31):
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr[k - 1]["t_start_s"] == pytest.approx(starts[k - 1], abs=1e-9)
        assert pr[k - 1]["f_b0_Hz"] == pytest.approx(mp.stator.f_b0_Hz - p["c_b_Hz_K"] * y[k - 1], abs=0.05)
        assert pr[k - 1]["f_l0_Hz"] == pytest.approx(mp.stator.f_l0_Hz - p["c_l_Hz_K"] * y[k - 1], abs=0.05)
        same = df[df["run"] == k]["speed_m_s"].to_numpy()
        if y[k - 1] == 0.0:
            assert same == pytest.approx(clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
    for k in (int(np.argmax(y)) + 1, 30):
        run = df[df["run"] == k]
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        mp = scattered_motor(nominal, factors[k - 1])
        st = mp.stator
        dip = float(audit.stator_dip_K(starts[k - 1], p))
        r = b5.traverse(mp.replace(stator__f_b0_Hz=st.f_b0_Hz - p["c_b_Hz_K"] * dip,
                                   stator__f_l0_Hz=st.f_l0_Hz - p["c_l_Hz_K"] * dip), nominal, plan, V, L, int(d))[0]
        assert run["position_m"].to_numpy() == pytest.approx(positions(plan, r), abs=1e-12)


def test_the_decoys_column(audit):
    df, truth, nominal, plan = audit.experiment("drive_fan_decoy", 2, first=40)
    p, pr = truth["parameters"], truth["per_run"]
    column = audit.CHANNEL["drive_fan_decoy"]
    assert column in df.columns and audit.DECOY["drive_fan_decoy"] in column and len(df.columns) == 9
    clean = audit.experiment("clean", 2, first=40)[0]
    assert df["speed_m_s"].to_numpy() == pytest.approx(clean["speed_m_s"].to_numpy(), abs=0)
    assert df["position_m"].to_numpy() == pytest.approx(clean["position_m"].to_numpy(), abs=0)
    volts = df.groupby("run")["voltage_V"].first().to_numpy()
    spans = [(r["t_start_s"], r["t_start_s"] + r["duration_s"], volts[i]) for i, r in enumerate(pr)]
    t = df["time_s"].to_numpy()
    w = fan_written_out(t, spans, p)
    noise = np.concatenate([np.random.default_rng([2, 292, k]).standard_normal(int((df["run"] == k + 1).sum()))
                            for k in range(40)])
    assert df[column].to_numpy() == pytest.approx(np.round(w * (1 + 0.005 * noise) / 10) * 10, abs=0)
    # the docstring's staircase at seed 2: off until run 15, low from run 15, high from run 30
    top = df.groupby("run")[column].max().to_numpy()
    assert np.all(top[:14] == 0) and top[14] > 0 and 0.5 * p["rpm_lo"] < top[20] < 1.1 * p["rpm_lo"]
    assert top[28] < 1.1 * p["rpm_lo"] < top[29] and top[-1] > 0.9 * p["rpm_hi"]


def test_seeds_are_reproducible(audit):
    for kind in audit.KINDS:
        a, ta = audit.experiment(kind, 3, first=2)[:2]
        b, tb = audit.experiment(kind, 3, first=2)[:2]
        pd.testing.assert_frame_equal(a, b)
        assert ta == tb
        c = audit.experiment(kind, 4, first=2)[1]
        assert c["parameters"] != ta["parameters"]
        d1, d2 = audit.draw(kind, 3, 72), audit.draw(kind, 3, 72)
        assert all(np.array_equal(d1[key], d2[key]) for key in d1)


def test_the_accepted_regressors_and_the_pass_rule(audit):
    for name in ("pulley_rise_mm", "pulley_rise_mm_sq", "load_kg_x_pulley_rise_mm"):
        assert audit.accepted("pulley_pitch", name), name
    for name in ("load", "voltage", "time", "direction", "vcm_current_mA", "pulley", "rise"):
        assert not audit.accepted("pulley_pitch", name), name
    for name in ("vcm_current_mA", "speed_x_vcm_current_mA"):
        assert audit.accepted("voice_coil_load", name), name
    for name in ("speed", "load", "time", "pulley_rise_mm", "current", "vcm"):
        assert not audit.accepted("voice_coil_load", name), name
    for name in ("time", "time_s", "session_clock", "elapsed_s", "run_index", "run_count", "run_order", "block_3",
                 "segment", "regime", "drift", "trend", "time_sq"):
        assert audit.accepted("cold_gas_cloud", name), name
    for name in ("time_in_run_s", "elapsed_in_run", "onset_time", "start_time", "time_since_break", "pause_time",
                 "voltage_V_lag1r", "prev_time", "time_last", "voltage_time", "load_x_time", "direction_time",
                 "speed_trend", "position_x_time", "frequency_drift", "thermal", "heat", "history", "cumulative",
                 "pulley_rise_mm", "vcm_current_mA", "drive_fan_rpm"):
        assert not audit.accepted("cold_gas_cloud", name), name
    assert not audit.accepted("drive_fan_decoy", "drive_fan_rpm")
    assert audit.B0 == {1: 3.037, 2: 2.815, 3: 3.241}
    b0 = 2.815
    row = {"kind": "pulley_pitch", "seed": 2, "traced": ["voltage", "pulley_rise_mm"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "pulley_rise_mm"], "after": 3.0})["passes"]
    row = {"kind": "cold_gas_cloud", "seed": 3, "traced": ["load", "run_index"], "before": 4.5}
    assert audit.verdict(row | {"after": 3.5})["passes"]
    assert audit.verdict(row | {"after": 3.5})["bound"] == pytest.approx(math.sqrt(3.241 ** 2 + (4.5 ** 2
                                                                                                 - 3.241 ** 2) / 4))
    assert not audit.verdict(row | {"traced": ["load", "time_in_run_s"], "after": 3.4})["passes"]
    row = {"kind": "voice_coil_load", "seed": 1, "traced": ["vcm_current_mA"], "before": 4.2, "after": 3.2}
    assert audit.verdict(row)["passes"] and not audit.verdict(row | {"traced": ["speed"]})["passes"]
    assert audit.verdict(row)["bound"] == pytest.approx(math.sqrt(3.037 ** 2 + (4.2 ** 2 - 3.037 ** 2) / 4))
    row = {"kind": "drive_fan_decoy", "seed": 1, "traced": ["voltage", "load"], "before": 3.037, "after": 3.05,
           "traced_all": ["voltage", "load", "drive_fan_rpm"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.037, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load", "fan_speed"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.11})["passes"]


def test_the_tables_name_every_kind(audit):
    kinds = set(audit.KINDS)
    assert audit.KINDS == ("pulley_pitch", "voice_coil_load", "cold_gas_cloud", "drive_fan_decoy")
    assert set(audit.CHANNEL) == kinds and set(audit.WANT) == kinds
    assert set(audit.NOT_WANT) == {"cold_gas_cloud"}
    assert audit.DECOY == {"drive_fan_decoy": "drive_fan"} and audit.WANT["drive_fan_decoy"] == ()
    assert audit.CHANNEL == {"pulley_pitch": "pulley_rise_mm", "voice_coil_load": "vcm_current_mA",
                             "cold_gas_cloud": None, "drive_fan_decoy": "drive_fan_rpm"}
    assert audit.WANT["pulley_pitch"] == ("pulley_rise",) and audit.WANT["voice_coil_load"] == ("vcm_current",)
    assert audit.WANT["cold_gas_cloud"] == ("time", "session", "clock", "elapsed", "index", "count", "order", "block",
                                            "segment", "regime", "drift", "trend")
    assert audit.NOT_WANT["cold_gas_cloud"] == (
        "time_in_run", "in_run", "onset", "start", "break", "pause", "_lag", "prev", "last", "voltage", "load",
        "direction", "speed", "position", "frequency")
    for kind in audit.KINDS:
        assert f"``{kind}``" in audit.__doc__ and (audit.CHANNEL[kind] or "no column") in audit.__doc__
    for line in audit.__doc__.splitlines():
        assert len(line) <= 120


def test_the_command_line(audit, tmp_path, capsys, monkeypatch):
    for argv in (["no_such_kind", "1"], ["pulley_pitch", "one"], [], ["pulley_pitch"], ["pulley_pitch", "1", "--x"]):
        with pytest.raises(SystemExit) as err:
            audit.main(argv)
        assert err.value.code == 2, argv
    capsys.readouterr()
    made = []
    real = audit.experiment
    monkeypatch.setattr(audit, "experiment", lambda kind, seed: made.append((kind, seed)) or real(kind, seed, 5))
    audit.main(["voice_coil_load", "2", "--data-only", "--cache", str(tmp_path)])
    out = tmp_path / "voice_coil_load_2"
    assert capsys.readouterr().out.strip() == str(out) and made == [("voice_coil_load", 2)]
    test = pd.read_csv(out / "test.csv")
    train = pd.read_csv(out / "train.csv")
    assert set(np.abs(test["load_kg"])) <= {0.05} and 0.05 not in set(np.abs(train["load_kg"]))
    assert "vcm_current_mA" in train.columns and len(set(train["run"]) | set(test["run"])) == 5
    audit.main(["voice_coil_load", "2", "--data-only", "--cache", str(tmp_path)])     # found in the cache: not remade
    assert capsys.readouterr().out.strip() == str(out) and made == [("voice_coil_load", 2)]
