"""Driving circuit (paper Sect. 3.1, Eq. 1-4): l1b2.physics.driver."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from l1b2.physics import driver as drv
from scipy.optimize import brentq

# (L [H], C [F], R_m [Ohm]) with a real zero-phase frequency (L < R^2 C), incl. the reference tank
TANKS = [
    (1.670e-3, 6.0e-9, 2000.0),
    (1.0e-3, 4.7e-9, 1500.0),
    (5.0e-4, 2.0e-8, 800.0),
    (2.2e-3, 3.3e-9, 5000.0),
]


def _pwm_fundamental(V_s, duty, f_s, n_per_period=2 ** 16, periods=3):
    """Amplitude and phase of the FFT fundamental of the sampled PWM wave (sampled at cell midpoints)."""
    n = n_per_period * periods
    t = (np.arange(n) + 0.5) / (n_per_period * f_s)
    x = drv.inverter_waveform_V(t, V_s, duty, f_s)
    X = np.fft.rfft(x)
    k = periods  # bin of the fundamental: `periods` whole periods in the record
    # undo the half-sample time shift of the midpoint grid
    c = X[k] * np.exp(1j * np.pi * k / n) * 2.0 / n
    return abs(c), np.angle(c), x


@pytest.mark.parametrize("duty", [0.1, 0.25, 0.5, 2.0 / 3.0, 0.8, 1.0])
@pytest.mark.parametrize("V_s", [1.0, 67.1])
def test_eq1_matches_fft_of_pwm_wave(V_s, duty):
    # reference: FFT fundamental of the finely sampled H-bridge wave over whole periods
    f_s = 48500.0
    amp, phase, x = _pwm_fundamental(V_s, duty, f_s)
    assert amp == pytest.approx(float(drv.inverter_fundamental_V(V_s, duty)), rel=1e-3)
    # the docstring says the fundamental has phase sin(w t): FFT coefficient of sin is -j
    assert phase == pytest.approx(-np.pi / 2, abs=1e-3)
    # three-level wave: only -V_s, 0, +V_s, and the time share of +V_s is duty/2
    assert set(np.unique(x)) <= {-V_s, 0.0, V_s}
    assert np.mean(x == V_s) == pytest.approx(duty / 2, abs=1e-4)


def test_eq1_zero_duty_gives_no_voltage():
    # reference: a zero-width pulse has no fundamental
    amp, _, x = _pwm_fundamental(10.0, 0.0, 48500.0, n_per_period=4096)
    assert np.all(x == 0.0)
    assert float(drv.inverter_fundamental_V(10.0, 0.0)) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("L, C, R", TANKS)
def test_eq3_is_the_zero_phase_frequency_of_the_tank(L, C, R):
    # reference: brentq root of angle(Z_in(w)) on a bracket around the LC frequency
    w_lc = 1.0 / np.sqrt(L * C)
    phase = lambda w: float(np.angle(drv.tank_input_impedance_ohm(w, L, C, R)))  # noqa: E731
    lo, hi = 1e-3 * w_lc, 10.0 * w_lc
    assert phase(lo) < 0 < phase(hi)  # capacitive below, inductive above
    w_num = brentq(phase, lo, hi, xtol=1e-12 * w_lc, rtol=1e-14)
    assert float(drv.tank_resonance_rad_s(L, C, R)) == pytest.approx(w_num, rel=1e-9)


def test_eq3_no_real_resonance_when_overdamped():
    # reference: for L > R^2 C, Im Z_in(w) = w (L - R^2 C / (1 + w^2 R^2 C^2)) > 0 for every w > 0
    L, C, R = 1e-2, 1e-9, 1000.0
    w = np.logspace(2, 8, 200)
    assert np.all(np.imag(drv.tank_input_impedance_ohm(w, L, C, R)) > 0)
    assert np.isnan(drv.tank_resonance_rad_s(L, C, R))


def _phasor_divider(w, L, C, R):
    """Independent phasor solve: series L, then R parallel C; output across R || C."""
    Z_L = 1j * w * L
    Z_RC = 1.0 / (1.0 / R + 1j * w * C)
    return Z_RC / (Z_L + Z_RC)


@pytest.mark.parametrize("L, C, R", TANKS)
def test_tank_gain_equals_direct_phasor_circuit_solve(L, C, R):
    # reference: voltage divider with complex impedances written here
    w = np.linspace(0.2, 3.0, 301) / np.sqrt(L * C)
    np.testing.assert_allclose(drv.tank_gain(w, L, C, R), _phasor_divider(w, L, C, R), rtol=1e-12, atol=0)
    # and the input impedance is Z_L + Z_RC
    np.testing.assert_allclose(drv.tank_input_impedance_ohm(w, L, C, R),
                               1j * w * L + 1.0 / (1.0 / R + 1j * w * C), rtol=1e-12)


@pytest.mark.parametrize("L, C, R", TANKS)
def test_exact_gain_at_w0_is_Rm_sqrt_C_over_L(L, C, R):
    # reference: closed form |H(w0)| = R sqrt(C/L) (docs/explanation/physics.md), with the independent divider
    w0 = float(drv.tank_resonance_rad_s(L, C, R))
    assert abs(_phasor_divider(w0, L, C, R)) == pytest.approx(R * np.sqrt(C / L), rel=1e-10)
    assert abs(drv.tank_gain(w0, L, C, R)) == pytest.approx(R * np.sqrt(C / L), rel=1e-10)


@pytest.mark.parametrize("x", [0.2, 0.5, 0.8, 0.95])
def test_paper_eq2_differs_from_exact_gain_unless_L_equals_Rm2C(x):
    # reference: with x = L/(R^2 C), Eq. 2 gain^2 = 1 + x - x^2 and exact gain^2 = 1/x;
    # they differ by (1-x)^2 (1+x) / x  (both written here from Eq. 2-3)
    R, C = 2000.0, 6e-9
    L = x * R * R * C
    V1 = float(drv.inverter_fundamental_V(100.0, 1.0))
    eq2 = float(drv.paper_eq2_amplitude_V(100.0, 1.0, L, C, R))
    exact = abs(_phasor_divider(float(drv.tank_resonance_rad_s(L, C, R)), L, C, R)) * V1
    assert eq2 == pytest.approx(V1 * np.sqrt(1 + x - x * x), rel=1e-12)
    assert (exact / V1) ** 2 - (eq2 / V1) ** 2 == pytest.approx((1 - x) ** 2 * (1 + x) / x, rel=1e-9)
    assert abs(eq2 - exact) > 1e-3 * exact  # they are not the same model off L = R^2 C


def test_paper_eq2_approaches_exact_gain_as_L_tends_to_Rm2C():
    # reference: the difference of the squared gains is (1-x)^2 (1+x)/x -> 0 quadratically as x -> 1
    R, C = 2000.0, 6e-9
    V1 = float(drv.inverter_fundamental_V(1.0, 1.0))
    diffs = []
    for eps in (1e-2, 1e-3, 1e-4):
        L = (1 - eps) * R * R * C
        eq2 = float(drv.paper_eq2_amplitude_V(1.0, 1.0, L, C, R)) / V1
        exact = abs(_phasor_divider(float(drv.tank_resonance_rad_s(L, C, R)), L, C, R))
        diffs.append(abs(exact - eq2))
    assert diffs[0] > 50 * diffs[1] > 50 * 50 * diffs[2]
    assert diffs[-1] < 1e-7


def test_paper_eq2_equals_exact_gain_at_L_equal_Rm2C():
    # reference: module docstring "Eq. 2 equals it only when L = R_m^2 C (then both are 1)";
    # at x = 1 the zero-phase frequency of Eq. 3 is w0 = 0 and both gains are exactly 1
    R, C = 1000.0, 1e-9
    L = R * R * C
    V1 = float(drv.inverter_fundamental_V(50.0, 0.7))
    w0 = float(drv.tank_resonance_rad_s(L, C, R))
    assert w0 == pytest.approx(0.0, abs=1e-6 / np.sqrt(L * C))
    assert float(drv.paper_eq2_amplitude_V(50.0, 0.7, L, C, R)) == pytest.approx(V1, rel=1e-9)
    assert abs(drv.tank_gain(w0, L, C, R)) * V1 == pytest.approx(V1, rel=1e-9)


@pytest.fixture()
def drifting(motor):
    """Reference driver with clearly non-zero drift coefficients."""
    return dataclasses.replace(motor.driver, L_temp_coeff_per_K=4e-4, L_freq_coeff_per_Hz=3e-7,
                               C1_freq_coeff_per_Hz=-5e-7)


def test_eq4_drift_is_linear_in_T_and_f(drifting):
    # reference: first-order drift L = L_ref (1 + a_T dT + a_f df), C1 = C1_ref (1 + b_f df)
    dp = drifting
    T = np.array([-10.0, 0.0, 25.0, 40.0, 85.0])
    f = np.array([40e3, 45e3, 48.5e3, 52e3, 60e3])
    TT, FF = np.meshgrid(T, f)
    L = drv.tank_inductance_H(dp, TT, FF)
    expect_L = dp.L_H * (1 + dp.L_temp_coeff_per_K * (TT - dp.T_ref_degC) + dp.L_freq_coeff_per_Hz * (FF - dp.f_ref_Hz))
    np.testing.assert_allclose(L, expect_L, rtol=1e-13)
    np.testing.assert_allclose(drv.tank_C1_F(dp, f), dp.C1_F * (1 + dp.C1_freq_coeff_per_Hz * (f - dp.f_ref_Hz)),
                               rtol=1e-13)
    # linearity: second differences vanish on an even grid, slopes are the coefficients
    Tg = np.linspace(0, 80, 9)
    LT = drv.tank_inductance_H(dp, Tg, dp.f_ref_Hz)
    np.testing.assert_allclose(np.diff(LT, 2), 0.0, atol=1e-12 * dp.L_H)
    assert np.diff(LT)[0] / np.diff(Tg)[0] == pytest.approx(dp.L_H * dp.L_temp_coeff_per_K, rel=1e-9)
    fg = np.linspace(40e3, 56e3, 9)
    Lf = drv.tank_inductance_H(dp, dp.T_ref_degC, fg)
    np.testing.assert_allclose(np.diff(Lf, 2), 0.0, atol=1e-12 * dp.L_H)
    assert np.diff(Lf)[0] / np.diff(fg)[0] == pytest.approx(dp.L_H * dp.L_freq_coeff_per_Hz, rel=1e-9)
    # at the reference point the values are the reference values
    assert float(drv.tank_inductance_H(dp, dp.T_ref_degC, dp.f_ref_Hz)) == pytest.approx(dp.L_H, rel=1e-15)
    assert float(drv.tank_C1_F(dp, dp.f_ref_Hz)) == pytest.approx(dp.C1_F, rel=1e-15)


@pytest.mark.parametrize("T, f", [(25.0, 48500.0), (60.0, 48500.0), (0.0, 47000.0), (40.0, 50500.0)])
@pytest.mark.parametrize("duty", [0.6, 1.0])
def test_driver_output_is_exact_phasor_gain_of_drifted_tank(drifting, T, f, duty):
    # reference: drifted L, C computed here from Eq. 4, then the independent divider and Eq. 1 closed form
    dp = drifting
    if getattr(dp, "V0_sat_V", 0.0):
        dp = dataclasses.replace(dp, V0_sat_V=0.0)
    L = dp.L_H * (1 + dp.L_temp_coeff_per_K * (T - dp.T_ref_degC) + dp.L_freq_coeff_per_Hz * (f - dp.f_ref_Hz))
    C = dp.C1_F * (1 + dp.C1_freq_coeff_per_Hz * (f - dp.f_ref_Hz)) + dp.C_m_F
    w = 2 * np.pi * f
    H = _phasor_divider(w, L, C, dp.R_m_ohm)
    V_s = 67.1
    V1 = 4 / np.pi * np.sin(np.pi * duty / 2) * V_s
    out = drv.driver_output(dp, V_s, duty, f, T)
    assert float(out.V0_V) == pytest.approx(abs(H) * V1, rel=1e-12)
    assert float(out.phase_rad) == pytest.approx(np.angle(H), abs=1e-12)
    assert float(out.omega_rad_s) == pytest.approx(w, rel=1e-15)
    assert float(out.V_inv1_V) == pytest.approx(V1, rel=1e-12)
    w0 = brentq(lambda x: float(np.angle(drv.tank_input_impedance_ohm(x, L, C, dp.R_m_ohm))),
                0.01 / np.sqrt(L * C), 10 / np.sqrt(L * C), xtol=1e-6, rtol=1e-14)
    assert float(out.omega0_rad_s) == pytest.approx(w0, rel=1e-9)


def test_temperature_drift_moves_the_output(drifting):
    # reference: physics - raising L moves the tank resonance down (Eq. 3 decreases with L)
    out_cold = drv.driver_output(drifting, 67.1, 1.0, 48500.0, 25.0)
    out_hot = drv.driver_output(drifting, 67.1, 1.0, 48500.0, 75.0)
    assert float(out_hot.L_H) > float(out_cold.L_H)
    assert float(out_hot.omega0_rad_s) < float(out_cold.omega0_rad_s)
    assert float(out_hot.V0_V) != pytest.approx(float(out_cold.V0_V), rel=1e-3)


@pytest.mark.parametrize("V0", [50.0, 200.0, 324.0, 400.0])
@pytest.mark.parametrize("duty, f, T", [(1.0, 48500.0, 25.0), (0.7, 47000.0, 40.0), (0.9, 50000.0, 10.0)])
def test_supply_for_voltage_inverts_driver_output(motor, drifting, V0, duty, f, T):
    # reference: round trip V0 -> V_s -> driver_output -> V0 (saturation off, as in the reference motor)
    for dp in (motor.driver, drifting):
        if getattr(dp, "V0_sat_V", 0.0):
            dp = dataclasses.replace(dp, V0_sat_V=0.0)
        V_s = float(drv.supply_for_voltage_V(dp, V0, duty, f, T))
        assert V_s > 0
        assert float(drv.driver_output(dp, V_s, duty, f, T).V0_V) == pytest.approx(V0, rel=1e-12)


def test_reference_supply_gives_the_papers_V0(motor):
    # reference: the TOML's operating point claims V0 = 324 V (paper) from V_s = 67.1 V at 48.5 kHz, duty 1
    op = motor.operating
    out = drv.driver_output(motor.driver, op.V_s_V, op.duty, op.f_drive_Hz, op.T_degC)
    assert float(out.V0_V) == pytest.approx(324.0, rel=0.01)
    # and the tank is tuned: its zero-phase frequency is the drive frequency (within 0.5 %)
    assert float(out.omega0_rad_s) / (2 * np.pi) == pytest.approx(op.f_drive_Hz, rel=5e-3)
