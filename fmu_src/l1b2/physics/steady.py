"""Coupled periodic steady state of the whole motor at a fixed slider position.

* :func:`steady_state` solves the coupled periodic steady state at a fixed
  slider position directly (stator phasors with interface feedback, Eq. 14,
  and the slider force balance, Eq. 21 with dv/dt = 0). It is what the paper's
  "steady-state speed" means and is the yardstick for the co-simulation.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy import optimize

from . import interface as itf
from . import slider as sld
from . import stator as st
from .params import G_M_S2, MotorParams


class SteadyState(NamedTuple):
    v_m_s: float          #: slider speed [m/s]
    U_l_m: float          #: tip normal amplitude [m]
    U_w_m: float          #: tip tangential amplitude [m]
    delta_rad: float      #: tangential-minus-normal phase [rad]
    F_p_N: float          #: static axial force [N]
    F_d_N: float          #: driving force [N]
    phi_c_rad: float      #: contact angle [rad]
    stick_fraction: float  #: share of contact time in stick [-]
    stuck: bool           #: the slider does not move
    converged: bool       #: the root finder met its tolerance


def _interface_loads(mp: MotorParams, Q_l, Q_b, eta_T, omega, v, F_p, mode):
    """Interface output and the generalised interface forces on both modes (phasors)."""
    tip = st.tip_motion(Q_l, Q_b, eta_T)
    out = itf.interface_forces(tip.U_l_m, tip.U_w_m, tip.delta_rad, omega, v, F_p, mp.interface, mode)
    rot = np.exp(1j * tip.phase_l_rad)
    gen_l = st.ETA_N * (out.F_N1_sin_N + 1j * out.F_N1_cos_N) * rot
    gen_b = eta_T * (out.F_T1_sin_N + 1j * out.F_T1_cos_N) * rot
    return out, gen_l, gen_b, tip


def steady_state(mp: MotorParams, s_m: float, V0_V: float, m_load_kg: float, direction: int,
                 mode: str = "stick_slip", f_Hz: float | None = None, T_degC: float | None = None
                 ) -> SteadyState:
    """Coupled steady state of the whole motor at a fixed slider position.

    For a trial speed ``v`` the stator phasors solve Eq. 6-7 in phasor form
    with the interface fundamentals fed back (Eq. 14); the speed is then the
    root of the slider force balance (Eq. 21 with dv/dt = 0), bracketed and
    found by Brent's method. If the applied force at rest stays within the
    static guide friction, the slider is stuck (speed 0).
    """
    sp = mp.stator
    f = mp.operating.f_drive_Hz if f_Hz is None else f_Hz
    omega = 2 * math.pi * f
    P = float(st.axial_force_N(sp, s_m))
    F_p = sp.alpha0 * P
    T_amb = mp.operating.T_degC if T_degC is None else T_degC
    T_st = T_amb + sp.heating_K_per_V2 * V0_V ** 2  # steady stator temperature
    props = st.modal_properties(sp, P, T_st)
    Z_l = st.dynamic_stiffness(omega, props.M_l, props.K_l, props.C_l)
    Z_b = st.dynamic_stiffness(omega, props.M_b, props.K_b, props.C_b)
    F_l, F_b = st.excitation_phasors(sp, V0_V, direction)
    eta_T = float(props.eta_T)
    F_path = float(sld.load_path_friction_N(mp.slider, m_load_kg))
    Fc = float(sld.guide_friction_level_N(mp.slider, F_p)) + F_path
    Fs = float(sld.guide_friction_level_N(mp.slider, F_p, static=True)) + F_path
    F_load = G_M_S2 * m_load_kg
    c_r = mp.slider.c_r_N_s_per_m
    q_scale = max(abs(F_l / Z_l), abs(F_b / Z_b), 1e-12)
    f_scale = max(abs(F_l), abs(F_b), 1e-9)
    warm = {"x": np.array([(F_l / Z_l).real, (F_l / Z_l).imag, (F_b / Z_b).real, (F_b / Z_b).imag]) / q_scale}
    ok = {"all": True}

    def stator_solve(v):
        def res(x):
            Q_l = (x[0] + 1j * x[1]) * q_scale
            Q_b = (x[2] + 1j * x[3]) * q_scale
            _, gen_l, gen_b, _ = _interface_loads(mp, Q_l, Q_b, eta_T, omega, v, F_p, mode)
            r_l = (Z_l * Q_l + gen_l - F_l) / f_scale
            r_b = (Z_b * Q_b + gen_b - F_b) / f_scale
            return np.array([r_l.real, r_l.imag, r_b.real, r_b.imag])
        sol = optimize.root(res, warm["x"], method="hybr", options={"xtol": 1e-12})
        if np.max(np.abs(res(sol.x))) > 1e-9:  # hybr may report "no progress" at machine precision
            ok["all"] = False
        else:
            warm["x"] = sol.x
        Q_l = (sol.x[0] + 1j * sol.x[1]) * q_scale
        Q_b = (sol.x[2] + 1j * sol.x[3]) * q_scale
        out, _, _, tip = _interface_loads(mp, Q_l, Q_b, eta_T, omega, v, F_p, mode)
        return out, tip

    def balance(v, sgn):
        out, _ = stator_solve(v)
        return out.F_d_N - F_load - c_r * v - sgn * Fc

    out0, tip0 = stator_solve(0.0)
    applied = out0.F_d_N - F_load
    stuck = abs(applied) <= Fs
    v = 0.0
    if not stuck:
        sgn = 1.0 if applied > 0 else -1.0
        hi = sgn * max(2.0 * omega * tip0.U_w_m, 0.05)
        for _ in range(40):
            if sgn * balance(hi, sgn) < 0:
                break
            hi *= 2.0
        else:
            raise RuntimeError(f"steady_state: no speed bracket found at s={s_m}, V0={V0_V}, load={m_load_kg}")
        warm["x"] = np.array([(F_l / Z_l).real, (F_l / Z_l).imag, (F_b / Z_b).real, (F_b / Z_b).imag]) / q_scale
        stator_solve(0.0)
        v = optimize.brentq(lambda x: balance(x, sgn), 0.0, hi, xtol=1e-9, rtol=1e-10)
    out, tip = stator_solve(v)
    return SteadyState(v_m_s=float(v), U_l_m=float(tip.U_l_m), U_w_m=float(tip.U_w_m),
                       delta_rad=float(tip.delta_rad), F_p_N=F_p, F_d_N=float(out.F_d_N),
                       phi_c_rad=float(out.phi_c_rad), stick_fraction=float(out.stick_fraction),
                       stuck=bool(stuck), converged=bool(ok["all"]))
