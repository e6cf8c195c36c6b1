"""bench/blind_effects_twentythird.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
glow in the electrodes' gap (Paschen's law, the clamp of the amplitude and the tank's resistance that gives it), the
guide's dry film (its wear-through with the slider's travel and the guide's friction), the bellows' intake drag (its
coefficient, its force and its depression), the microphone's reading, the draws, the made data, the accepted
regressors and the pass rule.
"""

import math

import numpy as np
import pytest

G = 9.81
TORR_PA = 101325.0 / 760.0


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_twentythird")


def breakdown_V(pd_Pa_m):
    """Paschen's law for air in the textbook's units: A = 15 /(cm Torr), B = 365 V/(cm Torr), gamma = 0.01."""
    pd_cm_torr = pd_Pa_m * 100.0 / TORR_PA
    den = math.log(15.0 * pd_cm_torr) - math.log(math.log(1.0 + 1.0 / 0.01))
    return 365.0 * pd_cm_torr / den if den > 0 else math.inf


def test_paschens_law_and_the_glows_clamp(audit):
    for pd in (0.5, 0.9, 1.1143, 1.6, 3.0, 20.0, 81.0):
        assert float(audit.paschen_V(pd)) == pytest.approx(breakdown_V(pd), rel=2e-3)
    assert float(audit.paschen_V(0.2)) == math.inf and float(audit.paschen_V(0.3)) == math.inf   # no breakdown
    assert math.isfinite(float(audit.paschen_V(0.5)))
    pd = np.logspace(-0.3, 1.0, 20001)
    v = audit.paschen_V(pd)
    # the minimum: 305 V at p d = e ln(1 + 1/gamma) / A = 1.11 Pa m (the docstring's numbers)
    assert v.min() == pytest.approx(305.3, abs=0.2)
    assert pd[v.argmin()] == pytest.approx(math.e * math.log(101.0) / 11.25, rel=1e-3)
    assert pd[v.argmin()] == pytest.approx(1.115, abs=2e-3)
    assert 1.115 / 0.75e-3 / 100 == pytest.approx(14.9, abs=0.05)
    assert 1.115 / 0.55e-3 / 100 == pytest.approx(20.3, abs=0.05)
    # the glow holds the amplitude at V_b(p d) / beta where the drive exceeds it
    d, beta = 0.65e-3, 1.05
    for V0, p in ((324.0, 17.0), (290.0, 17.0), (324.0, 12.0), (220.0, 17.0), (324.0, 25.0)):
        Vc = breakdown_V(100 * p * d) / beta
        assert float(audit.glow_V0(V0, p, d, beta)) == pytest.approx(min(V0, Vc), rel=2e-3)
    assert float(audit.glow_V0(324.0, 17.0, d, beta)) < 300
    assert float(audit.glow_V0(324.0, 12.0, 0.55e-3, beta)) == 324.0
    assert float(audit.glow_V0(255.0, 17.15, 0.65e-3, 1.09)) == 255.0
    # over the drawn gaps and edge factors: 324 V clamped by up to 44 V, 290 V by up to 10 V, 255 V never
    assert 324 - 305.32 / 1.09 == pytest.approx(44, abs=0.2) and 290 - 305.32 / 1.09 == pytest.approx(10, abs=0.2)
    lowest = min(float(audit.glow_V0(400.0, p, dd, 1.09)) for p in np.linspace(12, 25, 131)
                 for dd in np.linspace(0.55e-3, 0.75e-3, 21))
    assert lowest == pytest.approx(280.1, abs=0.2) and lowest > 255
    assert float(audit.glow_V0(324.0, 12.0, 0.55e-3, 1.03)) == 324.0         # far on Paschen's left branch


def test_the_tanks_resistance_gives_the_clamped_amplitude(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.physics import driver as drv
    d = be.setting("clean", 1, audit.draw)[1].driver
    for V0, Vc in ((324.0, 290.0), (324.0, 315.5), (290.0, 283.0)):
        R = audit.tank_R_for_V0(d, V0, Vc, 48500.0, 25.0)
        V_s = float(drv.supply_for_voltage_V(d, V0, 1.0, 48500.0, 25.0))
        d2 = d.__class__(**{**d.__dict__, "R_m_ohm": R})
        assert float(drv.driver_output(d2, V_s, 1.0, 48500.0, 25.0).V0_V) == pytest.approx(Vc, rel=1e-10)
        R_d = 1 / (1 / R - 1 / d.R_m_ohm)                                # the discharge's shunt
        assert 0 < R < d.R_m_ohm and R_d > 0
    assert audit.tank_R_for_V0(d, 324.0, 324.0, 48500.0, 25.0) == d.R_m_ohm
    assert audit.tank_R_for_V0(d, 290.0, 300.0, 48500.0, 25.0) == d.R_m_ohm
    # written out: |H| = 1 / sqrt((1 - w^2 L C)^2 + (w L / R)^2) at the drive, C = C1 + C_m
    w = 2 * math.pi * 48500.0
    gain = lambda R: 1 / math.sqrt((1 - w * w * d.L_H * (d.C1_F + d.C_m_F)) ** 2 + (w * d.L_H / R) ** 2)  # noqa: E731
    R = audit.tank_R_for_V0(d, 324.0, 300.0, 48500.0, 25.0)
    assert gain(R) / gain(d.R_m_ohm) == pytest.approx(300.0 / 324.0, rel=1e-10)


def test_the_dry_films_wearthrough(audit):
    f, x_w, k = 0.12, 1.5, 3.0
    assert float(audit.film_coverage(0.0, x_w, k)) == 1.0
    assert float(audit.film_coverage(x_w, x_w, k)) == pytest.approx(math.exp(-1), rel=1e-14)
    for x in (0.021, 0.6, 1.3, 2.2, 3.0):
        c = math.exp(-((x / x_w) ** k))
        assert float(audit.film_coverage(x, x_w, k)) == pytest.approx(c, rel=1e-13)
        assert float(audit.guide_factor(x, f, x_w, k)) == pytest.approx(1 - f * c, rel=1e-13)
    g = audit.guide_factor(np.linspace(0, 3.0, 301), f, x_w, k)
    assert np.all(np.diff(g) >= 0) and g[0] == pytest.approx(0.88, rel=1e-14) and g[-1] > 0.999
    slope = np.diff(g)
    assert slope[:20].max() < 0.1 * slope.max() and slope[-40:].max() < 0.1 * slope.max()   # a sigmoid
    # fresh, the guide's friction coefficient 0.10 falls to 0.082-0.091 over the drawn f (the docstring's numbers)
    assert 0.10 * (1 - 0.18) == pytest.approx(0.082) and 0.10 * (1 - 0.09) == pytest.approx(0.091)


def test_the_bellows_drag(audit):
    A = math.pi * 0.02 ** 2
    assert audit.bellows_area_m2() == pytest.approx(A, rel=1e-15)
    for d_v in (6.5e-3, 7.2e-3, 8.0e-3):
        a = math.pi * d_v ** 2 / 4
        v = -0.2
        dp = 1.2 / 2 * (A * abs(v) / (0.61 * a)) ** 2                     # the orifice's turbulent loss
        c_q = audit.bellows_coefficient(d_v)
        assert c_q * v * v == pytest.approx(A * dp, rel=1e-13)
        assert audit.bellows_force_N(v, c_q) == pytest.approx(A * dp, rel=1e-13)
        assert float(audit.bellows_dp_Pa(v, c_q)) == pytest.approx(dp, rel=1e-13)
    assert audit.bellows_coefficient(8.0e-3) == pytest.approx(1.27, abs=0.005)
    assert audit.bellows_coefficient(6.5e-3) == pytest.approx(2.91, abs=0.005)
    c_q = 2.0
    assert audit.bellows_force_N(-0.15, c_q) == pytest.approx(0.045, rel=1e-14)      # toward the end plate
    assert audit.bellows_force_N(0.15, c_q) == 0.0 and audit.bellows_force_N(0.0, c_q) == 0.0   # the flap valve
    assert audit.bellows_force_N(-0.3, c_q) == pytest.approx(4 * audit.bellows_force_N(-0.15, c_q), rel=1e-14)
    dp = audit.bellows_dp_Pa(np.array([-0.2, 0.0, 0.2, -0.1]), c_q)
    assert dp == pytest.approx([0.08 / A, 0.0, 0.0, 0.02 / A], rel=1e-14)


def test_the_microphones_reading(audit):
    p = {"L_bg_dBA": 33.0, "L_ref_dBA": 54.0, "n": 1.3}
    bg = 10 ** 3.3
    t = np.arange(0, 0.6, 1e-3)
    v = np.where(t > 0, -0.13, 0.0)                                       # a step of the speed
    m = 10 ** 5.4 * (290 / 324) ** 2 * (0.13 / 0.2) ** 2.6
    want = 10 * np.log10(bg + m - m * np.exp(-t / 0.125))                  # the fast weighting, from silence
    assert audit.mic_level_dBA(t, v, 290.0, p) == pytest.approx(want, rel=1e-12)
    assert audit.mic_level_dBA(t, v, 290.0, p)[0] == pytest.approx(33.0, rel=1e-14)
    L_m = 54 + 20 * math.log10(290 / 324) + 20 * 1.3 * math.log10(0.13 / 0.2)
    assert audit.mic_level_dBA(np.arange(0, 3, 1e-3), np.full(3000, 0.13), 290.0, p)[-1] == pytest.approx(
        10 * math.log10(10 ** 3.3 + 10 ** (L_m / 10)), rel=1e-9)
    assert audit.mic_level_dBA(t, np.zeros_like(t), 324.0, p) == pytest.approx(np.full(len(t), 33.0), rel=1e-14)
    # uneven sample times
    t2 = np.array([0.0, 0.001, 0.0035, 0.004, 0.05])
    y2 = audit.mic_level_dBA(t2, np.array([0.0, 0.2, 0.2, 0.2, 0.2]), 324.0, p)
    assert y2 == pytest.approx(10 * np.log10(bg + 10 ** 5.4 * (1 - np.exp(-t2 / 0.125))), rel=1e-12)
    # the meter starts from the silent rig whatever the first sample's speed
    assert audit.mic_level_dBA(t2, np.full(5, 0.2), 324.0, p)[0] == pytest.approx(33.0, rel=1e-14)


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.physics import driver as drv
    nominal = be.setting("clean", 1, audit.draw)[1]
    p = {"d_m": 0.55e-3, "beta": 1.05, "p_hPa": [12.0, 17.0]}
    mp, law = audit.run_motor("paschen_glow_clamp", nominal, p, 1, 0.05, 324.0)
    Vc = breakdown_V(100 * 17.0 * 0.55e-3) / 1.05
    V_s = float(drv.supply_for_voltage_V(nominal.driver, 324.0, 1.0, 48500.0, 25.0))
    assert law is None and Vc < 300
    assert float(drv.driver_output(mp.driver, V_s, 1.0, 48500.0, 25.0).V0_V) == pytest.approx(Vc, rel=2e-3)
    assert mp.driver.L_H == nominal.driver.L_H and mp.stator == nominal.stator and mp.slider == nominal.slider
    assert mp.interface == nominal.interface
    assert audit.run_motor("paschen_glow_clamp", nominal, p, 0, 0.05, 324.0) == (nominal, None)   # 12 hPa: none
    assert audit.run_motor("paschen_glow_clamp", nominal, p, 1, 0.05, 220.0) == (nominal, None)
    p = {"f": 0.12, "x_w_m": 1.5, "k": 3.0}
    mp, law = audit.run_motor("guide_film_wearthrough", nominal, p, 20, -0.07, 290.0, 0.861)
    g = 1 - 0.12 * math.exp(-((0.861 / 1.5) ** 3))
    assert law is None and mp.slider.mu_sd == pytest.approx(0.10 * g, rel=1e-13)
    assert mp.slider.mu_ss == pytest.approx(0.12 * g, rel=1e-13)
    assert mp.slider.c_r_N_s_per_m == nominal.slider.c_r_N_s_per_m and mp.slider.kappa == nominal.slider.kappa
    assert mp.stator == nominal.stator and mp.driver == nominal.driver and mp.interface == nominal.interface
    for kind in ("bellows_intake_drag", "bellows_intake_logged"):
        mp, law = audit.run_motor(kind, nominal, {"d_v_m": 7.0e-3}, 2, 0.05)
        assert mp == be.load_in_slider_motor(nominal, 0.05, kind)
        c_q = 1.2 * (math.pi * 0.02 ** 2) ** 3 / (2 * 0.61 ** 2 * (math.pi * 3.5e-3 ** 2) ** 2)
        assert law(0.1, 0.0, -0.2) == pytest.approx(0.05 - c_q * 0.04 / G, rel=1e-13)
        assert law(0.1, 0.015, 0.2) == 0.05 and law(0.1, -0.02, 0.0) == 0.05
    assert audit.run_motor("mic_level_decoy", nominal, {}, 3, 0.05) == (nominal, None)


def test_the_draws_stay_in_their_ranges(audit):
    p_hPa = np.concatenate([audit.draw("paschen_glow_clamp", seed, 72)["p_hPa"] for seed in range(1, 21)])
    assert 12 <= p_hPa.min() < 12.1 and 24.9 < p_hPa.max() <= 25
    lg = np.log10(p_hPa)                                                  # log-uniform: flat in log p
    assert np.mean(lg) == pytest.approx((math.log10(12) + math.log10(25)) / 2, abs=0.005)
    assert np.mean(p_hPa < math.sqrt(12 * 25)) == pytest.approx(0.5, abs=0.03)
    for seed in (1, 2, 3):
        assert audit.draw("bellows_intake_logged", seed, 72) == audit.draw("bellows_intake_drag", seed, 72)
    draws = {kind: [audit.draw(kind, seed, 2) for seed in range(1, 301)]
             for kind in ("paschen_glow_clamp", "guide_film_wearthrough", "bellows_intake_drag", "mic_level_decoy")}
    ranges = {"paschen_glow_clamp": {"d_m": (0.55e-3, 0.75e-3), "beta": (1.03, 1.09)},
              "guide_film_wearthrough": {"f": (0.09, 0.18), "x_w_m": (1.0, 2.0), "k": (2.0, 4.0)},
              "bellows_intake_drag": {"d_v_m": (6.5e-3, 8.0e-3)},
              "mic_level_decoy": {"L_bg_dBA": (30.0, 36.0), "L_ref_dBA": (50.0, 58.0), "n": (1.0, 1.6)}}
    for kind, rs in ranges.items():
        assert set(draws[kind][0]) - {"p_hPa"} == set(rs), kind
        for key, (lo, hi) in rs.items():
            x = np.array([d[key] for d in draws[kind]])
            assert lo <= x.min() < lo + 0.02 * (hi - lo) and hi - 0.02 * (hi - lo) < x.max() <= hi, (kind, key)
    rng = np.random.default_rng([2, 251, 1])                              # the film's own stream at seed 2
    assert audit.draw("guide_film_wearthrough", 2, 72)["f"] == rng.uniform(0.09, 0.18)
    rng = np.random.default_rng([3, 251, 2])                              # the bellows', its control's too
    assert audit.draw("bellows_intake_logged", 3, 72)["d_v_m"] == rng.uniform(6.5e-3, 8.0e-3)
    rng = np.random.default_rng([1, 251, 0])
    d = audit.draw("paschen_glow_clamp", 1, 72)
    assert d["d_m"] == rng.uniform(0.55e-3, 0.75e-3) and d["beta"] == rng.uniform(1.03, 1.09)
    assert d["p_hPa"] == pytest.approx(10 ** rng.uniform(math.log10(12), math.log10(25), 72), rel=1e-14)
    rng = np.random.default_rng([1, 251, 3])
    assert audit.draw("mic_level_decoy", 1, 72)["L_bg_dBA"] == rng.uniform(30.0, 36.0)
    assert audit.draw("clean", 1, 72) == {}


def test_the_glows_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.physics import driver as drv
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("paschen_glow_clamp", 2, first=4)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["paschen_glow_clamp"] in df.columns
    factors = be.setting("paschen_glow_clamp", 2, audit.draw)[3]
    clamped = []
    for k in (1, 2, 3, 4):
        run = df[df["run"] == k]
        noise = np.random.default_rng([2, 252, k - 1]).standard_normal(len(run))
        P = p["p_hPa"][k - 1]
        assert run["chamber_pressure_hPa"].to_numpy() == pytest.approx(np.round(P * (1 + 0.002 * noise), 2), abs=1e-9)
        V = float(run["voltage_V"].iloc[0])
        Vc = min(V, breakdown_V(100 * P * p["d_m"]) / p["beta"])
        assert pr[k - 1]["V0_V"] == pytest.approx(Vc, rel=2e-3)
        d2 = nominal.driver.__class__(**{**nominal.driver.__dict__, "R_m_ohm": pr[k - 1]["R_m_ohm"]})
        V_s = float(drv.supply_for_voltage_V(nominal.driver, V, 1.0, 48500.0, 25.0))
        assert float(drv.driver_output(d2, V_s, 1.0, 48500.0, 25.0).V0_V) == pytest.approx(Vc, rel=2e-3)
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr[k - 1]["P0_N"] == mp.stator.P0_N and pr[k - 1]["mu_p"] == mp.interface.mu_p
        clamped.append(Vc < V)
    assert clamped == [True, True, False, True]                           # run 3 at 324 V, 10.9 hPa: no glow
    # run 1's motion, rebuilt here: the scattered motor with the tank's resistance of the glow
    run = df[df["run"] == 1]
    V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
    mp = scattered_motor(nominal, factors[0]).replace(driver__R_m_ohm=pr[0]["R_m_ohm"])
    r = be.traverse(mp, nominal, plan, V, L, int(d))
    pos = np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
    clean = be.experiment("clean", 2)[0]
    assert len(run) > len(clean[clean["run"] == 1])                       # slower than the clean run
    assert df[df["run"] == 3]["position_m"].to_numpy() == pytest.approx(      # no glow: the clean motion
        clean[clean["run"] == 3]["position_m"].to_numpy(), abs=1e-12)


def test_the_films_made_data(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.rig.experiment import scattered_motor
    first = 6
    df, truth, nominal, plan = audit.experiment("guide_film_wearthrough", 3, first=first)
    p, pr = truth["parameters"], truth["per_run"]
    assert audit.CHANNEL["guide_film_wearthrough"] is None and len(df.columns) == 8   # nothing logged but the motion
    factors = be.setting("guide_film_wearthrough", 3, audit.draw)[3]
    for k in range(1, first + 1):
        x = (k - 0.5) * 0.042
        g = 1 - p["f"] * math.exp(-((x / p["x_w_m"]) ** p["k"]))
        assert pr[k - 1]["travel_mid_m"] == pytest.approx(x, rel=1e-12)
        assert pr[k - 1]["mu_sd"] == pytest.approx(0.10 * g, rel=1e-12)
        assert pr[k - 1]["mu_ss"] == pytest.approx(0.12 * g, rel=1e-12)
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr[k - 1]["P0_N"] == mp.stator.P0_N and pr[k - 1]["R_m_ohm"] == 2000.0
    starts = df.groupby("run")["time_s"].first().to_numpy()
    ends = df.groupby("run")["time_s"].last().to_numpy()
    assert starts[1:] == pytest.approx(ends[:-1] + 1.0, abs=1e-9)       # the plan's pause between runs
    run = df[df["run"] == 2]
    V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
    mp = scattered_motor(nominal, factors[1])
    mp = mp.replace(slider__mu_sd=pr[1]["mu_sd"], slider__mu_ss=pr[1]["mu_ss"])
    r = be.traverse(mp, nominal, plan, V, L, int(d))
    pos = np.round(np.round(r["Slider.s"] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
    clean = be.experiment("clean", 3)[0]
    for k in range(1, first + 1):                                         # the fresh film: every run faster
        assert len(df[df["run"] == k]) < len(clean[clean["run"] == k])
    # late in the session the film is worn through: the guide's levels are the dry ones
    full = audit.run_motor("guide_film_wearthrough", nominal, p, 71, 0.05, 290.0, 71.5 * 0.042)[0]
    assert full.slider.mu_sd == pytest.approx(0.10, rel=2e-3)


def test_the_bellows_made_data_and_its_control(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.cosim.engine import InProcessMotor
    from l1b2.physics import driver as drv
    from l1b2.rig.experiment import scattered_motor
    df, truth, nominal, plan = audit.experiment("bellows_intake_drag", 1, first=4)
    p = truth["parameters"]
    assert audit.CHANNEL["bellows_intake_drag"] is None and len(df.columns) == 8
    ctl = audit.experiment("bellows_intake_logged", 1, first=4)[0]
    assert audit.CHANNEL["bellows_intake_logged"] in ctl.columns
    assert ctl["speed_m_s"].to_numpy() == pytest.approx(df["speed_m_s"].to_numpy(), abs=0)   # the same motion
    clean = be.experiment("clean", 1)[0]
    factors = be.setting("bellows_intake_drag", 1, audit.draw)[3]
    A = math.pi * 0.02 ** 2
    c_q = 1.2 * A ** 3 / (2 * 0.61 ** 2 * (math.pi * p["d_v_m"] ** 2 / 4) ** 2)
    for k in (1, 2, 3, 4):
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
        state = {"v": 0.0}

        def bellows(t, L=L, state=state):
            v = state["v"]
            return L - (c_q * v * v if v < 0 else 0.0) / G
        m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=int(d), m_load=bellows, s0=s0)
        s_rec, v_rec = [s0], [0.0]
        for _ in range(int(round(plan.max_run_s / plan.step_s))):
            m.step()
            state["v"] = m.value("Slider.v")
            s_rec.append(m.value("Slider.s"))
            v_rec.append(state["v"])
            if m.value("Slider.at_stop") == d:
                break
        pos = np.round(np.round(np.array(s_rec) / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
        assert run["position_m"].to_numpy() == pytest.approx(pos, abs=1e-12)
        v = np.array(v_rec)
        dp = np.where(v < 0, c_q * v * v / A, 0.0)
        noise = np.random.default_rng([1, 252, k - 1]).standard_normal(len(run))
        assert ctl[ctl["run"] == k]["bellows_dp_Pa"].to_numpy() == pytest.approx(np.round(dp + 0.3 * noise, 1),
                                                                                 abs=1e-9)
        n_clean = len(clean[clean["run"] == k])
        if d > 0:   # folding it: the clean motion
            assert np.all(v >= 0) and len(run) == n_clean
            assert run["position_m"].to_numpy() == pytest.approx(clean[clean["run"] == k]["position_m"].to_numpy(),
                                                                 abs=1e-12)
        else:       # unfolding it: slower, by the drag at the speeds met
            assert len(run) > n_clean and truth["per_run"][k - 1]["bellows_max_N"] == pytest.approx(
                c_q * (v ** 2).max(), rel=1e-9)
            assert dp.max() > 3


def test_the_decoys_column(audit, load_bench):
    be = load_bench("blind_effects")
    from l1b2.cosim.engine import InProcessMotor
    from l1b2.physics import driver as drv
    from l1b2.rig.experiment import scattered_motor
    first = 6
    df, truth, nominal, plan = audit.experiment("mic_level_decoy", 2, first=first)
    p = truth["parameters"]
    column = audit.CHANNEL["mic_level_decoy"]
    assert column in df.columns and audit.DECOY["mic_level_decoy"] in column
    factors = be.setting("mic_level_decoy", 2, audit.draw)[3]
    clean = be.experiment("clean", 2)[0]
    for k in range(1, first + 1):
        run = df[df["run"] == k]
        pr = truth["per_run"][k - 1]
        mp = scattered_motor(nominal, factors[k - 1])
        assert pr["P0_N"] == mp.stator.P0_N and pr["mu_p"] == mp.interface.mu_p and pr["R_m_ohm"] == 2000.0
        assert pr["mu_sd"] == 0.10 and pr["mass_kg"] == mp.slider.mass_kg and pr["V0_V"] == run["voltage_V"].iloc[0]
        assert run["speed_m_s"].to_numpy() == pytest.approx(clean[clean["run"] == k]["speed_m_s"].to_numpy(), abs=0)
        # the slider's own speeds, from the clean co-simulation
        V, L, d = (float(run[c].iloc[0]) for c in ("voltage_V", "load_kg", "direction"))
        V_s = float(drv.supply_for_voltage_V(nominal.driver, V, 1.0, plan.f_drive_Hz, plan.ambient_degC))
        m = InProcessMotor(mp, h_s=plan.step_s)
        m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=int(d), m_load=L,
                     s0=mp.slider.s_min_m if d > 0 else mp.slider.s_max_m)
        r = m.run(plan.max_run_s, record=("Slider.v",), until=lambda mm: mm.value("Slider.at_stop") == d)
        t, v = r["time"], r["Slider.v"]
        bg = 10 ** (p["L_bg_dBA"] / 10)
        q = bg + 10 ** (p["L_ref_dBA"] / 10) * (V / 324) ** 2 * (np.abs(v) / 0.2) ** (2 * p["n"])
        y = np.empty_like(q)
        y[0] = bg
        for i in range(1, len(q)):
            y[i] = y[i - 1] + (1 - math.exp(-(t[i] - t[i - 1]) / 0.125)) * (q[i] - y[i - 1])
        noise = np.random.default_rng([2, 252, k - 1]).standard_normal(len(run))
        assert run["mic_dBA"].to_numpy() == pytest.approx(np.round(10 * np.log10(y) + 0.5 * noise, 1), abs=1e-9)
    assert np.corrcoef(df["mic_dBA"], df["speed_m_s"].abs())[0, 1] > 0.6      # it carries the speed


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("paschen_glow_clamp", "chamber_pressure_hPa")
    for name in ("voltage", "load", "pressure", "time", "voltage_V_lag1r"):
        assert not audit.accepted("paschen_glow_clamp", name), name
    for name in ("time", "time_s", "session_clock", "elapsed_s", "run_index", "run_count", "cumulative_travel",
                 "cumulative_run_travel", "block_3"):
        assert audit.accepted("guide_film_wearthrough", name), name
    for name in ("time_in_run_s", "run_travel", "elapsed_in_run", "since_start", "onset_time", "time_since_break",
                 "pause_time", "voltage_V_lag1r", "prev_load_time", "time_last", "speed", "position", "load",
                 "direction", "voltage", "start_time", "speed_time", "position_x_time", "load_x_time",
                 "direction_x_time", "time_in_run"):
        assert not audit.accepted("guide_film_wearthrough", name), name
    for name in ("speed", "speed_sq", "speed_x_direction", "velocity", "velocity_squared", "drag", "bellows",
                 "quadratic_speed", "v_squared"):
        assert audit.accepted("bellows_intake_drag", name), name
    for name in ("speed_lag2", "prev_speed", "last_speed", "speed_history", "speed_memory", "time_in_run_speed",
                 "position_speed", "speed_near_stop", "speed_travel", "speed_x_voltage", "speed_x_load",
                 "direction", "time", "position", "voltage"):
        assert not audit.accepted("bellows_intake_drag", name), name
    assert audit.accepted("bellows_intake_logged", "bellows_dp_Pa")
    assert not audit.accepted("bellows_intake_logged", "speed")
    assert not audit.accepted("mic_level_decoy", "mic_dBA")
    assert audit.B0 == {1: 3.037, 2: 2.815, 3: 3.241}
    b0 = 3.241
    row = {"kind": "paschen_glow_clamp", "seed": 3, "traced": ["voltage", "chamber_pressure_hPa"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "chamber_pressure_hPa"], "after": 3.0})["passes"]
    row = {"kind": "guide_film_wearthrough", "seed": 1, "traced": ["load", "time_s"], "before": 4.5}
    assert audit.verdict(row | {"after": 3.4})["passes"]
    assert not audit.verdict(row | {"traced": ["load", "time_in_run_s"], "after": 3.4})["passes"]
    row = {"kind": "bellows_intake_drag", "seed": 2, "traced": ["speed_x_direction"], "before": 4.2, "after": 3.2}
    assert audit.verdict(row)["passes"] and not audit.verdict(row | {"traced": ["direction"]})["passes"]
    row = {"kind": "mic_level_decoy", "seed": 1, "traced": ["voltage", "load"], "before": 3.037, "after": 3.05,
           "traced_all": ["voltage", "load", "mic_dBA"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 3.037, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load", "dynamic_friction"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 3.11})["passes"]


def test_the_tables_name_every_kind(audit):
    kinds = set(audit.KINDS)
    assert set(audit.CHANNEL) == kinds and set(audit.WANT) == kinds
    assert set(audit.NOT_WANT) == {"guide_film_wearthrough", "bellows_intake_drag"}
    assert audit.DECOY == {"mic_level_decoy": "mic_dB"} and audit.WANT["mic_level_decoy"] == ()
    assert audit.STREAM == {"bellows_intake_logged": "bellows_intake_drag"}
    assert audit.CHANNEL == {"paschen_glow_clamp": "chamber_pressure_hPa", "guide_film_wearthrough": None,
                             "bellows_intake_drag": None, "mic_level_decoy": "mic_dBA",
                             "bellows_intake_logged": "bellows_dp_Pa"}
    for line in audit.__doc__.splitlines():
        assert len(line) <= 120
