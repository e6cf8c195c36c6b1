"""bench/blind_effects_fifth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
cylinder's play operator, the cable loop's force, the draw-wire sensor's geometry and the tracking drive's lag.
"""

import math

import numpy as np
import pytest

@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_fifth")


def test_cylinder_preload_is_a_play_of_the_pressure_force(audit):
    A, Fs = audit.CYLINDER_AREA_M2, 0.3
    assert A == pytest.approx(math.pi * 0.006 ** 2 / 4, rel=1e-12)
    p = np.array([2.0, 2.05, 2.5, 2.45, 2.0, 2.1])
    F = p * 1e5 * A          # 5.65, 5.79, 7.07, 6.93, 5.65, 5.94 N
    # pressurised from below: F0 - Fs, at the play's lower edge, so every rise drags the piston up (F1 - Fs,
    # F2 - Fs); the fall of 0.14 N < 2 Fs to 6.93 N stays within the play; the fall to 5.65 N drags it down to
    # 5.65 + Fs; the rise of 0.28 N < 2 Fs to 5.94 N stays within the play
    want = [F[0] - Fs, F[1] - Fs, F[2] - Fs, F[2] - Fs, F[4] + Fs, F[4] + Fs]
    assert audit.play_preload(p, Fs) == pytest.approx(want, rel=1e-12)
    # without seal friction the preload is the pressure force
    assert audit.play_preload(p, 0.0) == pytest.approx(F, rel=1e-12)


def test_cable_force_pulls_toward_the_clamp_with_a_hysteresis_against_the_motion(audit):
    k, sn, eta = 4.0, -0.027, 0.3
    s = np.array([-0.021, 0.0, 0.021])
    x = s - sn
    fwd = audit.cable_force_N(s, 1.0, k, sn, eta)     # well above the sign's speed scale: tanh = 1
    back = audit.cable_force_N(s, -1.0, k, sn, eta)
    assert fwd == pytest.approx(-k * x * (1 + eta), rel=1e-9)
    assert back == pytest.approx(-k * x * (1 - eta), rel=1e-9)
    assert audit.cable_force_N(sn, 1.0, k, sn, eta) == 0.0
    assert float(audit.cable_force_N(0.0, 0.0, k, sn, eta)) == pytest.approx(-k * (0.0 - sn), rel=1e-12)


def test_drawwire_reading_exact_at_the_stops_and_its_slope_the_wire_cosine(audit):
    D, h, lo, hi = 0.043, 0.016, -0.021, 0.021
    assert float(audit.drawwire_position(lo, D, h, lo, hi)) == pytest.approx(lo, abs=1e-15)
    assert float(audit.drawwire_position(hi, D, h, lo, hi)) == pytest.approx(hi, abs=1e-15)
    length = lambda s: math.sqrt((s + D) ** 2 + h ** 2)  # noqa: E731
    gain = (hi - lo) / (length(hi) - length(lo))
    for s in (-0.015, 0.0, 0.012):
        eps = 1e-7
        slope = (float(audit.drawwire_position(s + eps, D, h, lo, hi))
                 - float(audit.drawwire_position(s - eps, D, h, lo, hi))) / (2 * eps)
        assert slope == pytest.approx(gain * (s + D) / length(s), rel=1e-6)
    # the slope rises along the stroke: low near the sensor, high far from it
    s = np.linspace(lo, hi, 50)
    assert np.all(np.diff(np.gradient(audit.drawwire_position(s, D, h, lo, hi), s)) > 0)


def test_tracking_drive_lags_its_target_by_its_time_constant(audit):
    from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor
    from l1b2.physics.stator import preload_N
    mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    f0, kappa, tau, s0 = 48500.0, 200.0, 5e-3, -0.021
    law = audit.pll_law(mp, f0, kappa, tau, s0)
    Fc = preload_N(mp.stator, 0.0)
    target = lambda s: f0 + kappa * (preload_N(mp.stator, s) - Fc)  # noqa: E731
    # locked at the start: a first call at t = 0 and s0 returns the target there
    assert law(0.0, s0, 0.0) == pytest.approx(target(s0), rel=1e-12)
    # held at another position, the frequency approaches the new target as 1 - exp(-t/tau)
    s1, t = 0.015, 7e-3
    f = law(t, s1, 0.2)
    assert f == pytest.approx(target(s1) + (target(s0) - target(s1)) * math.exp(-t / tau), rel=1e-12)
    assert abs(target(s1) - target(s0)) > 50.0   # the bar's deviation moves the lock point by tens of Hz


def test_draws_lie_in_their_ranges(audit):
    for seed in (1, 2, 3):
        p = audit.draw("pll_tracking", seed, 72)
        assert 600 <= p["kappa_Hz_per_N"] <= 800 and 3e-3 <= p["tau_s"] <= 8e-3
        p = audit.draw("pneumatic_preload", seed, 72)
        assert 0.25 <= p["F_s_N"] <= 0.45 and np.all(np.abs(p["dp_bar"]) <= 0.55) and len(p["dp_bar"]) == 72
        p = audit.draw("cable_loop", seed, 72)
        assert 3 <= p["k_c_N_per_m"] <= 5 and -0.030 <= p["s_n_m"] <= -0.024 and 0.2 <= p["eta"] <= 0.35
        p = audit.draw("drawwire_sensor", seed, 72)
        assert 0.036 <= p["D_m"] <= 0.040 and 0.017 <= p["h_m"] <= 0.020


def test_the_cables_run_keeps_the_motors_guide_friction_and_moving_mass(audit, load_bench):
    from l1b2.physics.slider import force_levels
    be = load_bench("blind_effects")
    plan, nominal, conds, factors, p, every = be.setting("cable_loop", 1, audit.draw)
    s = nominal.slider
    for L in (0.09, -0.05, 0.0):
        mp, law = audit.run_motor("cable_loop", nominal, L, p, None)
        k = mp.slider
        assert k.load_inertia == 0.0 and k.mass_kg == pytest.approx(s.mass_kg + s.load_inertia * abs(L), rel=1e-15)
        for F_p in (5.5, 6.0, 7.2):
            m0, Fx0, Fc0, Fs0 = force_levels(1.0, F_p, L, s.mass_kg, s.load_inertia, s.pulley_mu, s.mu_sd, s.mu_ss,
                                             s.kappa)
            m1, Fx1, Fc1, Fs1 = force_levels(1.0, F_p, L, k.mass_kg, k.load_inertia, k.pulley_mu, k.mu_sd,
                                             k.mu_ss, k.kappa)
            # the guide's Coulomb levels mu (kappa F_p + g m_s) and the moving mass are the motor's
            assert (m1, Fx1, Fc1, Fs1) == pytest.approx((m0, Fx0, Fc0, Fs0), rel=1e-13)
        s_m, v = 0.01, 0.02
        F_c = -p["k_c_N_per_m"] * (s_m - p["s_n_m"]) * (1 + p["eta"] * math.tanh(v / 0.005))
        assert law(0.0, s_m, v) == pytest.approx(L - F_c / 9.81, rel=1e-12)
    with pytest.raises(ValueError, match="cable_loop"):
        audit.run_motor("cable_loop", nominal.replace(slider__pulley_mu=0.1), 0.05, p, None)
