"""Driving circuit: H-bridge inverter and LC resonance tank (paper Sect. 3.1, Eq. 1-4).

All functions are pure and vectorised (numpy broadcasting); SI units are in
the argument names.

The tank (paper Fig. 4) is a series inductor ``L`` feeding the stator, which
is modelled as its resistance ``R_m`` in parallel with ``C = C1 + C_m``
(matching capacitor plus clamped capacitance). The output ``V0`` is the
voltage across the stator.

Relation to the paper's Eq. 2
-----------------------------
Eq. 3 is the frequency at which the tank's input impedance is purely
resistive. The exact phasor gain of the circuit is::

    H(w) = V0 / V_invb = 1 / (1 - w^2 L C + j w L / R_m)

and at Eq. 3's ``w0`` its magnitude is exactly ``R_m sqrt(C / L)``. The
paper's Eq. 2 gain ``sqrt(R_m^2 + w0^2 L^2) / R_m`` equals it only when
``L = R_m^2 C`` (then both are 1). We implement the exact phasor solution at
the switching frequency, which stays valid off resonance, where the drift of
Eq. 4 puts the drive; :func:`paper_eq2_amplitude_V` is kept for comparison.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .params import DriverParams


def inverter_fundamental_V(V_s_V, duty):
    """Amplitude of the fundamental of the inverter voltage, Eq. 1.

    ``V_invb = 4/pi * sin(pi*duty/2) * V_s`` for the three-level H-bridge
    wave of :func:`inverter_waveform_V` (duty 1 gives a full square wave).

    Parameters
    ----------
    V_s_V : array_like
        Supply voltage [V].
    duty : array_like
        Duty ratio delta in [0, 1] [-].
    """
    return 4.0 / np.pi * np.sin(0.5 * np.pi * np.asarray(duty, float)) * np.asarray(V_s_V, float)


def inverter_waveform_V(t_s, V_s_V, duty, f_s_Hz):
    """H-bridge output voltage [V] at times ``t_s`` [s].

    +V_s during a pulse of width ``duty*T/2`` centred on the positive
    half-period, -V_s on the negative one, 0 otherwise (phase-shift PWM).
    Its Fourier fundamental is Eq. 1 with phase ``sin(w_s t)``.
    """
    phase = np.mod(np.asarray(t_s, float) * f_s_Hz, 1.0)  # fraction of a period
    half_width = 0.25 * duty  # in periods, each pulse is duty/2 of a period wide
    pos = np.abs(phase - 0.25) < half_width
    neg = np.abs(phase - 0.75) < half_width
    return V_s_V * (pos.astype(float) - neg.astype(float))


def tank_inductance_H(params: DriverParams, T_degC, f_Hz):
    """L(T, w_s) of Eq. 4: first-order drift around the reference values [H]."""
    return params.L_H * (1.0 + params.L_temp_coeff_per_K * (np.asarray(T_degC, float) - params.T_ref_degC)
                         + params.L_freq_coeff_per_Hz * (np.asarray(f_Hz, float) - params.f_ref_Hz))


def tank_C1_F(params: DriverParams, f_Hz):
    """C1(w_s) of Eq. 4: first-order drift around the reference value [F]."""
    return params.C1_F * (1.0 + params.C1_freq_coeff_per_Hz * (np.asarray(f_Hz, float) - params.f_ref_Hz))


def tank_gain(omega_rad_s, L_H, C_F, R_m_ohm):
    """Complex voltage gain ``V0/V_invb`` of the tank at angular frequency ``omega``."""
    w = np.asarray(omega_rad_s, float)
    return 1.0 / (1.0 - w * w * L_H * C_F + 1j * w * L_H / R_m_ohm)


def tank_input_impedance_ohm(omega_rad_s, L_H, C_F, R_m_ohm):
    """Complex input impedance of the tank seen by the inverter [Ohm]."""
    w = np.asarray(omega_rad_s, float)
    return 1j * w * L_H + R_m_ohm / (1.0 + 1j * w * R_m_ohm * C_F)


def tank_resonance_rad_s(L_H, C_F, R_m_ohm):
    """Eq. 3: ``w0 = sqrt(1/(L C) - 1/(R_m^2 C^2))`` [rad/s] (NaN if overdamped)."""
    arg = 1.0 / (L_H * C_F) - 1.0 / (R_m_ohm ** 2 * C_F ** 2)
    scale = 1.0 / (L_H * C_F)
    # round-off at the boundary L = R_m^2 C (w0 = 0) must not turn into NaN
    arg = np.where(np.abs(arg) <= 1e-12 * scale, 0.0, arg)
    return np.sqrt(np.where(arg >= 0, arg, np.nan))


def paper_eq2_amplitude_V(V_s_V, duty, L_H, C_F, R_m_ohm):
    """Eq. 2 as printed: ``V0 = 4/pi sin(pi delta/2) V_s sqrt(R_m^2 + w0^2 L^2) / R_m``.

    Agrees with the exact gain at ``w0`` only when ``L = R_m^2 C`` (module docstring).
    """
    w0 = tank_resonance_rad_s(L_H, C_F, R_m_ohm)
    return inverter_fundamental_V(V_s_V, duty) * np.sqrt(R_m_ohm ** 2 + (w0 * L_H) ** 2) / R_m_ohm


class DriverOutput(NamedTuple):
    V0_V: np.ndarray          #: amplitude of the sinusoidal stator voltage [V]
    omega_rad_s: np.ndarray   #: drive angular frequency [rad/s]
    phase_rad: np.ndarray     #: phase of V0 relative to the inverter fundamental [rad]
    V_inv1_V: np.ndarray      #: fundamental of the inverter voltage (Eq. 1) [V]
    omega0_rad_s: np.ndarray  #: zero-phase (resonance) frequency of the tank, Eq. 3 [rad/s]
    L_H: np.ndarray           #: drifted inductance [H]
    C1_F: np.ndarray          #: drifted matching capacitance [F]


def driver_output(params: DriverParams, V_s_V, duty, f_s_Hz, T_degC) -> DriverOutput:
    """Stator voltage amplitude and frequency produced by the driver.

    The switching frequency is the drive frequency (``w_s = w``, paper
    Sect. 3.1); the exact phasor gain of the drifted tank is applied to the
    fundamental of Eq. 1.

    Parameters
    ----------
    V_s_V : supply voltage [V]; duty : PWM duty ratio [-];
    f_s_Hz : switching frequency [Hz]; T_degC : tank temperature [degC].
    """
    f = np.asarray(f_s_Hz, float)
    omega = 2.0 * np.pi * f
    L = tank_inductance_H(params, T_degC, f)
    C1 = tank_C1_F(params, f)
    C = C1 + params.C_m_F
    H = tank_gain(omega, L, C, params.R_m_ohm)
    V1 = inverter_fundamental_V(V_s_V, duty)
    return DriverOutput(
        V0_V=saturate_V(np.abs(H) * V1, params.V0_sat_V),
        omega_rad_s=omega,
        phase_rad=np.angle(H),
        V_inv1_V=V1,
        omega0_rad_s=tank_resonance_rad_s(L, C, params.R_m_ohm),
        L_H=L,
        C1_F=C1,
    )


def saturate_V(V0_lin_V, V_sat_V):
    """Soft output limit of the drive: ``V_sat tanh(V0 / V_sat)``; ``V_sat = 0`` means no limit [V]."""
    V = np.asarray(V0_lin_V, float)
    if V_sat_V <= 0:
        return V
    return V_sat_V * np.tanh(V / V_sat_V)


def supply_for_voltage_V(params: DriverParams, V0_V, duty, f_s_Hz, T_degC):
    """Supply voltage [V] giving the amplitude ``V0_V`` through the small-signal (linear) tank gain.

    This is the setting an operator derives from the nominal gain; with the
    output saturation enabled (``V0_sat_V > 0``) the actual V0 is lower.
    """
    H = tank_gain(2 * np.pi * np.asarray(f_s_Hz, float), tank_inductance_H(params, T_degC, f_s_Hz),
                  tank_C1_F(params, f_s_Hz) + params.C_m_F, params.R_m_ohm)
    return np.asarray(V0_V, float) / (np.abs(H) * inverter_fundamental_V(1.0, duty))
