"""The four subsystems coupled in-process (no FMUs).

Two uses:

* :func:`steady_state` solves the coupled periodic steady state at a fixed
  slider position directly (stator phasors with interface feedback, Eq. 14,
  and the slider force balance, Eq. 21 with dv/dt = 0). It is what the paper's
  "steady-state speed" means and is the yardstick for the co-simulation.
* :class:`InProcessMotor` runs the same communication-step algorithm as the
  FMU master (Gauss-Seidel in the causal order driver -> stator -> interface
  -> slider, inputs held over a step) calling the physics functions directly:
  the reference against which the fmpy co-simulation is tested.
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


# ---------------------------------------------------------------------------
# In-process time simulation (reference for the FMU master)
# ---------------------------------------------------------------------------

#: variables recorded by :class:`InProcessMotor`, named as in the FMU master ("Component.variable")
RECORDED = ("Driver.V0", "Stator.U_l", "Stator.U_w", "Stator.delta", "Stator.F_p", "Interface.F_d",
            "Interface.phi_c", "Interface.stick_fraction", "Slider.v", "Slider.s")


class InProcessMotor:
    """The four blocks wired by hand and stepped in Gauss-Seidel order, without FMUs.

    The wiring is written out here on purpose (not read from the SSD): it is
    the independent reference the SSD-driven fmpy master is tested against.
    Inputs are held over each communication step of length ``h_s``; any input
    may be a function of time.
    """

    INPUTS = ("V_s", "duty", "f_s", "T", "direction", "m_load")

    def __init__(self, mp: MotorParams, h_s: float = 2e-4, pure_slip: bool = False):
        from .blocks import make_blocks
        self.mp = mp
        self.h = float(h_s)
        self.b = make_blocks(mp, pure_slip=pure_slip)

    def _inputs_at(self, t):
        return {k: float(v(t) if callable(v) else v) for k, v in self.inputs.items()}

    def initialize(self, *, V_s, duty=1.0, f_s=48500.0, T=25.0, direction=1.0, m_load=0.0,
                   s0: float = 0.0, v0: float = 0.0):
        """Set the system inputs (constants or functions of time) and initialise the blocks."""
        self.inputs = dict(V_s=V_s, duty=duty, f_s=f_s, T=T, direction=direction, m_load=m_load)
        u = self._inputs_at(0.0)
        d, stt, itf_, sl = (self.b[k] for k in ("Driver", "Stator", "Interface", "Slider"))
        d.V_s, d.duty, d.f_s, d.T = u["V_s"], u["duty"], u["f_s"], u["T"]
        d.initialize()
        stt.V0, stt.omega, stt.direction, stt.T, stt.s = d.V0, d.omega, u["direction"], u["T"], s0
        stt.initialize()
        itf_.U_l, itf_.U_w, itf_.delta, itf_.omega, itf_.v, itf_.F_p = (
            stt.U_l, stt.U_w, stt.delta, d.omega, v0, stt.F_p)
        itf_.initialize()
        sl.s0, sl.v0, sl.m_load, sl.F_d, sl.F_p = s0, v0, u["m_load"], itf_.F_d, stt.F_p
        sl.initialize()
        self.t = 0.0

    def step(self):
        d, stt, itf_, sl = (self.b[k] for k in ("Driver", "Stator", "Interface", "Slider"))
        t, h = self.t, self.h
        u = self._inputs_at(t)
        d.V_s, d.duty, d.f_s, d.T = u["V_s"], u["duty"], u["f_s"], u["T"]
        d.do_step(t, h)
        stt.V0, stt.omega, stt.s, stt.direction, stt.T = d.V0, d.omega, sl.s, u["direction"], u["T"]
        stt.F_N1_sin, stt.F_N1_cos, stt.F_T1_sin, stt.F_T1_cos = (
            itf_.F_N1_sin, itf_.F_N1_cos, itf_.F_T1_sin, itf_.F_T1_cos)
        stt.do_step(t, h)
        itf_.U_l, itf_.U_w, itf_.delta, itf_.omega, itf_.v, itf_.F_p = (
            stt.U_l, stt.U_w, stt.delta, d.omega, sl.v, stt.F_p)
        itf_.do_step(t, h)
        sl.F_d, sl.F_p, sl.m_load = itf_.F_d, stt.F_p, u["m_load"]
        sl.do_step(t, h)
        self.t = t + h

    def value(self, name: str) -> float:
        comp, var = name.split(".")
        return float(getattr(self.b[comp], var))

    def run(self, t_end: float, record: tuple[str, ...] = RECORDED, until=None):
        """Step to ``t_end`` (or until ``until(self)`` is true); return ``{name: array}`` incl. ``time``."""
        n = int(round(t_end / self.h))
        out = {k: [self.value(k)] for k in record}
        times = [self.t]
        for _ in range(n):
            self.step()
            times.append(self.t)
            for k in record:
                out[k].append(self.value(k))
            if until is not None and until(self):
                break
        res = {"time": np.array(times)}
        res.update({k: np.array(v) for k, v in out.items()})
        return res
