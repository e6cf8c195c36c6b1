"""Eq. 29 predictor parameters derived from the physical model, and its comparison with the co-simulation.

Two derivations (no measured data involved):

``method="paper"``
    The paper's own reduction, Eq. 25-30, literally: Theta(s) from the B2
    receptance at the tip (Eq. 26, with eta_T and omega_b0 under the axial force
    P(s)), ``den = 1/Theta + 0.5 sigma omega eta_T``, ``A' = 4 sigma eta_T / (pi T den)``,
    ``B' = 2 sigma A_b / (T den)`` (Eq. 30 divided by T_s), ``P(s) = F_p(s)``,
    and the physical c_r, sigma, mu, mu_sd, kappa. ``k0`` is the physical
    model's ``v / (omega U_w)`` at the reference operating point (Fig. 9c's
    proportional coefficient). Eq. 24 adds the friction fundamental to the
    drive as if both were in phase with ``sin(omega t)``; near a resonance the
    tip responds ~90 deg out of phase with the force, so this scalar
    reduction is only as good as that approximation (the comparison reports it).

``method="linearized"``
    The physical model's own steady-state sensitivities, written in Eq. 35's
    parameters. At each position of a grid the coupled steady state is solved
    at the reference (V0, no load) and perturbed in V0 and load; Eq. 29's
    steady state ``v* = (B' V0 + E - 9.81 m') / D`` then gives
    ``D = -9.81 / (dv/dm')``, ``B' = D dv/dV0``, ``E = D v* - B' V0``. With the
    physical c_r, sigma, mu, mu_sd, kappa, ``A' = 0.5 + (c_r - D)/sigma`` and
    ``P = (E + 9.81 mu_sd m_s) / (mu [g1(k0) - pi/2 A' G(k0)] - mu_sd kappa)``;
    k0 (structurally free, see :mod:`l1b2.ident.estimator`) is chosen so that this P(s)
    is closest to the model's preload F_p(s). A', B', P are then fitted by
    Legendre series of the requested order. This reproduces the physical
    model exactly at the reference point and to its affinity error elsewhere.

Both use ``mode="pure_slip"`` (the paper's Sect. 4 assumptions, phi_c = pi and
no stick) or ``"stick_slip"`` for the co-simulation they are derived from.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from numpy.polynomial import legendre
from scipy.optimize import minimize_scalar

from ..physics import stator as st
from ..physics import steady
from ..physics.params import G_M_S2, MotorParams
from . import model as pr
from .setup import PredictorSetup

DEFAULT_V_REF = 272.0          # middle of the paper's high-voltage range [V]
DEFAULT_T_S = 1e-3             # the rig's sampling time [s]


def _grid(mp: MotorParams, n: int = 25, margin_m: float = 1e-3):
    return np.linspace(mp.slider.s_min_m + margin_m, mp.slider.s_max_m - margin_m, n)


def _scaling(mp: MotorParams, margin_m: float = 1e-3):
    lo, hi = mp.slider.s_min_m + margin_m, mp.slider.s_max_m - margin_m
    return 0.5 * (lo + hi), 0.5 * (hi - lo)


def _legfit(s, y, center, half, order):
    return tuple(legendre.legfit((np.asarray(s) - center) / half, y, order))


def derive_predictor(mp: MotorParams, *, method: str = "linearized", mode: str = "pure_slip", order: int = 8,
                     V_ref: float = DEFAULT_V_REF, n_grid: int = 25) -> pr.PredictorParams:
    """Eq. 35 parameters of the predictor from the physical model (see the module docstring)."""
    if method not in ("linearized", "paper"):
        raise ValueError(f"method must be 'linearized' or 'paper', got {method!r}")
    s = _grid(mp, n_grid)
    center, half = _scaling(mp)
    sl, ifc = mp.slider, mp.interface
    m_s = sl.mass_kg
    F_p = st.preload_N(mp.stator, s)
    common = dict(c_r=sl.c_r_N_s_per_m, sigma=ifc.sigma_N_s_per_m, mu=ifc.mu_p, mu_sd=sl.mu_sd,
                  s_center=center, s_half=half, kappa=sl.kappa, include_load_inertia=sl.load_inertia >= 0.5)
    if method == "paper":
        omega = 2 * math.pi * mp.operating.f_drive_Hz
        T = 2 * math.pi / omega
        props = st.modal_properties(mp.stator, st.axial_force_N(mp.stator, s))
        Z = np.abs(st.dynamic_stiffness(omega, props.M_b, props.K_b, props.C_b))
        theta_inv = Z / props.eta_T                       # Eq. 26: Theta = |phi_b(L)| / |Z_b|
        den = theta_inv + 0.5 * ifc.sigma_N_s_per_m * omega * props.eta_T
        Ap = 4 * ifc.sigma_N_s_per_m * props.eta_T / (math.pi * T * den)
        Bp = 2 * ifc.sigma_N_s_per_m * mp.stator.A_b_N_per_V / (T * den)
        ref = steady.steady_state(mp, center, V_ref, 0.0, 1, mode=mode)
        k0 = min(max(ref.v_m_s / (omega * ref.U_w_m), 0.0), pr.K0_MAX)
        return pr.PredictorParams(k0=k0, alpha=_legfit(s, Ap, center, half, order),
                                  beta=_legfit(s, Bp, center, half, order),
                                  p=_legfit(s, F_p, center, half, order), **common)

    dV, dL = 10.0, 0.01
    D = np.empty_like(s)
    Bp = np.empty_like(s)
    E = np.empty_like(s)
    for i, si in enumerate(s):
        v0 = steady.steady_state(mp, si, V_ref, 0.0, 1, mode=mode).v_m_s
        vV = [steady.steady_state(mp, si, V_ref + k * dV, 0.0, 1, mode=mode).v_m_s for k in (-1, 1)]
        vL = [steady.steady_state(mp, si, V_ref, k * dL, 1, mode=mode).v_m_s for k in (-1, 1)]
        dv_dV = (vV[1] - vV[0]) / (2 * dV)
        dv_dL = (vL[1] - vL[0]) / (2 * dL)
        D[i] = -G_M_S2 / dv_dL
        Bp[i] = D[i] * dv_dV
        E[i] = D[i] * v0 - Bp[i] * V_ref
    Ap = 0.5 + (sl.c_r_N_s_per_m - D) / ifc.sigma_N_s_per_m

    def preload_for(k0):
        bracket = ifc.mu_p * (pr.drive_factor(k0) - 0.5 * math.pi * Ap * pr.G_of_k0(k0)) - sl.mu_sd * sl.kappa
        return (E + G_M_S2 * sl.mu_sd * m_s) / bracket

    def misfit(k0):
        P = preload_for(k0)
        return float(np.mean((P - F_p) ** 2)) if np.all(np.isfinite(P)) else np.inf

    k0 = float(minimize_scalar(misfit, bounds=(0.0, 0.95), method="bounded",
                               options={"xatol": 1e-6}).x)
    return pr.PredictorParams(k0=k0, alpha=_legfit(s, Ap, center, half, order),
                              beta=_legfit(s, Bp, center, half, order),
                              p=_legfit(s, preload_for(k0), center, half, order), **common)


def derive_predictor_setup(mp: MotorParams, *, method: str = "linearized", mode: str = "stick_slip",
                           order: int = 8, T_s: float = DEFAULT_T_S) -> PredictorSetup:
    """What the predictor FMU carries when no identification is given: the physical model's linearization."""
    return PredictorSetup(derive_predictor(mp, method=method, mode=mode, order=order), mp.slider.mass_kg, T_s)


def compare_steady(params: pr.PredictorParams, mp: MotorParams, *, mode: str = "stick_slip",
                   positions=None, voltages=(220.0, 255.0, 290.0, 324.0),
                   loads=(-0.09, -0.05, 0.0, 0.05, 0.09), directions=(1, -1)) -> pd.DataFrame:
    """Steady speed of the predictor against the coupled model's steady state on a grid.

    The coupled model's steady state (:func:`l1b2.physics.steady.steady_state`) is
    the co-simulation's fixed point (the tests check the time-domain
    co-simulation converges to it to 1e-6). Relative error is taken against
    the coupled model's speed.
    """
    positions = _grid(mp, 9, 2e-3) if positions is None else np.asarray(positions)
    rows = []
    for s in positions:
        for V0 in voltages:
            for L in loads:
                for d in directions:
                    ss = steady.steady_state(mp, s, V0, L, d, mode=mode)
                    vp = float(pr.steady_state(params, s, V0, L, d, mp.slider.mass_kg))
                    rows.append({"position_m": s, "voltage_V": V0, "load_kg": L, "direction": d,
                                 "v_cosim_m_s": 0.0 if ss.stuck else ss.v_m_s, "v_pred_m_s": vp})
    df = pd.DataFrame(rows)
    with np.errstate(divide="ignore", invalid="ignore"):
        df["rel_error"] = (df.v_pred_m_s - df.v_cosim_m_s) / df.v_cosim_m_s.abs()
    return df


def summarize(df: pd.DataFrame) -> dict:
    """Largest and rms relative steady-speed difference (moving points only)."""
    moving = df.v_cosim_m_s.abs() > 5e-3
    e = df.rel_error[moving].abs()
    return {"max_abs_rel_error": float(e.max()), "rms_rel_error": float(np.sqrt(np.mean(e ** 2))),
            "n_points": int(moving.sum())}
