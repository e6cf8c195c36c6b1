"""bench/blind_effects_sixteenth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
Stribeck curve of the oil's viscosity and the drive, the frequency search's offsets per data file, the drive's
soft start, the pulley's tachometer, the draws, the accepted regressors and the pass rule.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_sixteenth")


def test_the_stribeck_factor(audit):
    p = {"eta_t": 80.0, "n": 1.1, "D": 0.15}
    assert audit.stribeck_mu_factor(100.0, 272.0, p) == pytest.approx(1.0, rel=1e-15)
    f = lambda x: x ** 1.1 / (1 + x ** 1.1)  # noqa: E731
    x_ref = 100.0 / 80.0 * 272.0 / 324.0
    for eta, V0 in ((10.0, 220.0), (500.0, 324.0), (1000.0, 255.0)):
        x = eta / 80.0 * V0 / 324.0
        assert audit.stribeck_mu_factor(eta, V0, p) == pytest.approx((1 - 0.15 * f(x)) / (1 - 0.15 * f(x_ref)),
                                                                      rel=1e-14)
    assert audit.film_share(1.0, 0.9) == pytest.approx(0.5, rel=1e-15)
    eta = np.logspace(1, 3, 40)
    assert np.all(np.diff(audit.stribeck_mu_factor(eta, 290.0, p)) < 0)       # thicker oil: less friction
    V0 = np.array([220.0, 255.0, 290.0, 324.0])
    assert np.all(np.diff(audit.stribeck_mu_factor(50.0, V0, p)) < 0)         # a harder drive: less friction
    # the product: doubling the viscosity is worth as much as doubling the drive
    assert audit.stribeck_mu_factor(40.0, 300.0, p) == pytest.approx(audit.stribeck_mu_factor(20.0, 600.0, p),
                                                                      rel=1e-14)


def test_the_files_offsets(audit):
    p = {"N": 4, "delta_Hz": [10.0, -30.0, 0.0]}
    assert audit.file_offsets(10, p).tolist() == [10.0] * 4 + [-30.0] * 4 + [0.0] * 2
    for seed in (1, 2, 3):
        d = audit.draw("autotune_file_blocks", seed, 72)
        assert 6 <= d["N"] <= 12 and 40 <= d["sigma_f_Hz"] <= 70
        assert len(d["delta_Hz"]) == math.ceil(72 / d["N"])
        assert np.all(np.abs(np.asarray(d["delta_Hz"]) / 10 - np.round(np.asarray(d["delta_Hz"]) / 10)) < 1e-12)
        c = audit.draw("autotune_freq_logged", seed, 72)
        assert c["N"] == d["N"] and list(c["delta_Hz"]) == list(d["delta_Hz"])


def test_the_soft_start(audit):
    t = np.array([0.0, 0.01, 0.02, 0.04, 0.05, 0.2])
    want = 60.0 * np.minimum(1.0, 0.2 + 0.8 * t / 0.04)
    assert audit.ramp(t, 60.0, 0.04) == pytest.approx(want, rel=1e-15)
    assert audit.ramp(t, 60.0, 0.0).tolist() == [60.0] * 6


def test_the_tachometer(audit):
    p = {"r_p_m": 0.01, "tau_t_s": 0.02}
    t = np.arange(0.0, 0.1, 1e-3)
    v = np.full(t.shape, -0.15)                           # the reading is of the speed's magnitude
    y = audit.tach_rpm(t, v, 0.05, p)
    full = 60 * 0.15 / (2 * math.pi * 0.01)
    assert y == pytest.approx(full * (1 - np.exp(-t / 0.02)), rel=1e-12, abs=1e-12)
    assert audit.tach_rpm(t, v, 0.0, p).tolist() == [0.0] * len(t)
    assert audit.tach_rpm(t, v, -0.05, p).tolist() == [0.0] * len(t)


def test_the_runs_motors(audit, load_bench):
    be = load_bench("blind_effects")
    plan, nominal, conds, factors, p, every = be.setting("stribeck_viscosity", 2, audit.draw)
    mp = audit.run_motor("stribeck_viscosity", nominal, plan, p, 7, 255.0)
    x = p["eta"][7] / p["eta_t"] * 255.0 / 324.0
    x_ref = 100.0 / p["eta_t"] * 272.0 / 324.0
    f = lambda x: x ** p["n"] / (1 + x ** p["n"])  # noqa: E731
    assert mp.interface.mu_p == pytest.approx(nominal.interface.mu_p * (1 - p["D"] * f(x)) / (1 - p["D"] * f(x_ref)),
                                              rel=1e-14)
    assert mp.stator.P0_N == nominal.stator.P0_N
    for kind in ("autotune_file_blocks", "softstart_ramp", "pulley_tach_decoy", "autotune_freq_logged"):
        assert audit.run_motor(kind, nominal, plan, p, 7, 255.0) is nominal


def test_the_draws_stay_in_their_ranges(audit):
    for seed in (1, 2, 3):
        s = audit.draw("stribeck_viscosity", seed, 72)
        assert 50 <= s["eta_t"] <= 200 and 0.8 <= s["n"] <= 1.2 and 0.12 <= s["D"] <= 0.20
        assert s["eta"].min() >= 10 and s["eta"].max() <= 1000 and len(s["eta"]) == 72
        r = audit.draw("softstart_ramp", seed, 72)["T_r_ms"]
        assert r.min() >= 0 and r.max() <= 80 and np.all(r == np.round(r))
        d = audit.draw("pulley_tach_decoy", seed, 72)
        assert 0.008 <= d["r_p_m"] <= 0.012 and 0.010 <= d["tau_t_s"] <= 0.030


def test_the_controls_column_logs_the_files_frequency(audit):
    df, truth, nominal, plan = audit.experiment("autotune_freq_logged", 3, first=8)
    p = truth["parameters"]
    for k in range(1, 9):
        run = df[df["run"] == k]
        f = 48500.0 + p["delta_Hz"][(k - 1) // p["N"]]
        assert run["frequency_Hz"].tolist() == [f] * len(run)
        assert truth["per_run"][k - 1]["f_drive_Hz"] == f


def test_the_decoys_column_and_the_ramps_made_data(audit, load_bench):
    df, truth, nominal, plan = audit.experiment("pulley_tach_decoy", 1, first=4)
    p = truth["parameters"]
    be = load_bench("blind_effects")
    factors = be.setting("pulley_tach_decoy", 1, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    for k in range(1, 5):
        run = df[df["run"] == k]
        L, V, d = float(run["load_kg"].iloc[0]), float(run["voltage_V"].iloc[0]), int(run["direction"].iloc[0])
        mp = scattered_motor(nominal, factors[k - 1])
        assert truth["per_run"][k - 1]["mu_p"] == mp.interface.mu_p       # the decoy's motor is the clean one
        r = be.traverse(mp, nominal, plan, V, L, d)
        t, s = r["time"], r["Slider.s"]
        u = 60 * np.abs(np.gradient(s, t)) / (2 * math.pi * p["r_p_m"]) if L > 0 else np.zeros(len(t))
        y = np.zeros(len(t))
        for i in range(1, len(t)):
            y[i] = u[i - 1] + (y[i - 1] - u[i - 1]) * math.exp(-(t[i] - t[i - 1]) / p["tau_t_s"])
        noise = np.random.default_rng([1, 192, k - 1]).standard_normal(len(run))
        assert run["pulley_tach_rpm"].to_numpy() == pytest.approx(np.round(np.maximum(0, y + 0.3 * noise), 1),
                                                                  abs=1e-9)
    r0 = audit.traverse_ramped(nominal, nominal, plan, 324.0, 0.05, 1, 0.0)
    r1 = audit.traverse_ramped(nominal, nominal, plan, 324.0, 0.05, 1, 0.08)
    assert r1["time"][-1] > r0["time"][-1] + 0.02                            # the ramp delays the traverse
    moved = lambda r: r["time"][np.argmax(r["Slider.s"] > nominal.slider.s_min_m + 1e-3)]  # noqa: E731
    assert moved(r1) > moved(r0) + 0.02


def test_the_ramps_made_data(audit, load_bench):
    df, truth, nominal, plan = audit.experiment("softstart_ramp", 2, first=2)
    p = truth["parameters"]
    factors = load_bench("blind_effects").setting("softstart_ramp", 2, audit.draw)[3]
    from l1b2.rig.experiment import scattered_motor
    for k in (1, 2):
        run = df[df["run"] == k]
        T_ms = p["T_r_ms"][k - 1]
        assert run["softstart_ms"].tolist() == [T_ms] * len(run)
        assert truth["per_run"][k - 1]["T_r_s"] == T_ms / 1000.0
        L, V, d = float(run["load_kg"].iloc[0]), float(run["voltage_V"].iloc[0]), int(run["direction"].iloc[0])
        r = audit.traverse_ramped(scattered_motor(nominal, factors[k - 1]), nominal, plan, V, L, d, T_ms / 1000.0)
        assert truth["per_run"][k - 1]["duration_s"] == float(r["time"][-1])


def test_the_accepted_regressors_and_the_pass_rule(audit):
    assert audit.accepted("stribeck_viscosity", "oil_viscosity_mPa_s")
    assert audit.accepted("stribeck_viscosity", "log10_oil_viscosity_mPa_s")
    assert not audit.accepted("stribeck_viscosity", "voltage") and not audit.accepted("stribeck_viscosity", "load")
    assert audit.accepted("softstart_ramp", "softstart_ms") and not audit.accepted("softstart_ramp", "time_in_run_s")
    for name in ("time_s", "run_order", "since_break_s", "segment", "session_block", "file_index"):
        assert audit.accepted("autotune_file_blocks", name)
    for name in ("time_in_run_s", "frequency_Hz", "voltage", "load_kg_lag1r"):
        assert not audit.accepted("autotune_file_blocks", name)
    assert audit.accepted("autotune_freq_logged", "frequency_Hz")
    assert not audit.accepted("pulley_tach_decoy", "pulley_tach_rpm")
    b0 = 3.037
    row = {"kind": "stribeck_viscosity", "seed": 1, "traced": ["voltage", "oil_viscosity_mPa_s"], "before": 4.0}
    bound = math.sqrt(b0 ** 2 + (4.0 ** 2 - b0 ** 2) / 4)
    assert audit.verdict(row | {"after": bound - 1e-9}) == {"bound": pytest.approx(bound, rel=1e-14),
                                                            "attributed": True, "passes": True}
    assert not audit.verdict(row | {"after": bound + 1e-6})["passes"]
    assert not audit.verdict(row | {"traced": ["voltage", "load", "oil_viscosity_mPa_s"], "after": 3.0})["passes"]
    row = {"kind": "pulley_tach_decoy", "seed": 2, "traced": ["voltage", "load"], "before": 2.815, "after": 2.87,
           "traced_all": ["voltage", "load", "pulley_tach_rpm"]}
    assert audit.verdict(row)["bound"] == pytest.approx(1.02 * 2.815, rel=1e-14)
    assert not audit.verdict(row)["passes"]
    assert audit.verdict(row | {"traced_all": ["voltage", "load"]})["passes"]
    assert not audit.verdict(row | {"traced_all": ["voltage"], "after": 2.9})["passes"]
