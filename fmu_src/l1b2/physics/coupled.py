"""The coupled motor's communication step in one function of plain floats (issue: faster than real time).

:func:`motor_substeps` runs ``n`` steps of the co-simulation's Gauss-Seidel
sequence (stator -> interface -> slider, driver outputs held) on a state
vector, calling the same per-subsystem kernels the blocks call:

* :func:`l1b2.physics.stator.temperature_step_scalar` and
  :func:`~l1b2.physics.stator.bar_deviation_scalar` (stator temperature,
  axial force ``P(s)``), the modal table's interpolant
  (:func:`~l1b2.physics.stator.table_lookup`) and stiffnesses
  (:func:`~l1b2.physics.stator.stiffness_damping`), and
  :func:`~l1b2.physics.stator.coupled_envelope_step`;
* :func:`l1b2.physics.interface.period_integrals`;
* :func:`l1b2.physics.slider.force_levels` and :func:`~l1b2.physics.slider.step_floats`.

Compiled by numba as one function (:func:`compiled_substeps`), it replaces
the per-step Python glue between the blocks: ``L1B2Motor.fmu`` runs it
(:class:`l1b2.cosim.engine.FusedSteps`). The blocks remain the reference; a
test runs both and compares every state.

The function stops early (returning the number of steps done) and says why
in ``x[REASON]``:

* ``REASON_CELL``: the axial force left the modal table's cell it was given;
  the caller builds cell ``x[NEED_CELL]`` and calls again;
* ``REASON_BLOCKS``: a step the blocks must take: an internal signal out of
  the range the blocks accept (the blocks then raise their error), or a
  temperature-dependent B2 mode whose temperature moved (the stator block
  evaluates the modal properties directly then).
"""

from __future__ import annotations

import math

import numpy as np

from . import interface, slider, stator
from .interface import period_integrals
from .jit import cached_kernel
from .params import MotorParams
from .slider import force_levels, step_floats
from .stator import (
    TABLE_CELL_N,
    bar_deviation_scalar,
    coupled_envelope_step,
    l1_omega_scalar,
    modal_mass_b_kg,
    modal_mass_l_kg,
    stiffness_damping,
    table_lookup,
    temperature_step_scalar,
)

#: names of the state vector's entries, in order (``x[i]`` is ``STATE[i]``); "Block.variable" where a
#: block holds the same value, "props.*" for the stator's modal properties of the previous step
STATE = (
    # inputs held over the call (driver outputs and system inputs)
    "Driver.V0", "Driver.omega", "direction", "T", "m_load",
    # stator states, the modal properties the interface forces were computed with, outputs
    "Stator.Q_l_re", "Stator.Q_l_im", "Stator.Q_b_re", "Stator.Q_b_im", "Stator.T_st",
    "props.K_l", "props.C_l", "props.K_b", "props.C_b", "props.eta_T", "props.omega_l0", "props.omega_b0",
    "props.T", "Stator.U_l", "Stator.U_w", "Stator.phase_l", "Stator.phase_w", "Stator.delta", "Stator.F_p",
    "Stator.P",
    # inputs of the stator and the interface at the last step (the blocks keep them as variables)
    "Stator.s", "Stator.F_N1_sin", "Stator.F_N1_cos", "Stator.F_T1_sin", "Stator.F_T1_cos", "Interface.v",
    # interface outputs
    "Interface.F_d", "Interface.F_N_mean", "Interface.F_N1_sin", "Interface.F_N1_cos", "Interface.F_T1_sin",
    "Interface.F_T1_cos", "Interface.phi_c", "Interface.stick_fraction",
    # slider states and acceleration
    "Slider.v_state", "Slider.s_state", "Slider.stuck_state", "Slider.stop_state", "Slider.a",
    # why the call stopped early, and the table cell it needs
    "reason", "need_cell",
)
(V0, OMEGA, DIR, T_AMB, M_LOAD, QLR, QLI, QBR, QBI, T_ST, K_L, C_L, K_B, C_B, ETA, W_L0, W_B0, PROPS_T,
 U_L, U_W, PH_L, PH_W, DELTA, F_P, P_AX, S_IN, FN1S_IN, FN1C_IN, FT1S_IN, FT1C_IN, V_IN,
 F_D, F_NM, FN1S, FN1C, FT1S, FT1C, PHI_C, STICK, V, S, STUCK, STOP, ACC, REASON, NEED_CELL) = range(len(STATE))

#: names of the parameter vector's entries (:func:`parameter_vector` fills it from a motor's parameters)
PARAMS = (
    "A_l_N_per_V", "A_b_N_per_V", "asym_b", "alpha0", "P0_N", "preload_stiffness_N_per_m",
    "bar_half_length_m", "bar_dev_1_m", "bar_dev_2_m", "bar_dev_3_m", "bar_wave_amp_m", "bar_wave_period_m",
    "bar_bump_amp_m", "bar_bump_center_m", "bar_bump_width_m", "thermal_tau_s", "heating_K_per_V2",
    "f_l0_Hz", "df_dT_l_Hz_per_K", "T_ref_degC", "zeta_l", "zeta_b", "M_l", "M_b", "b2_thermal",
    "k_e_N_per_m", "u_m_m", "mu_p", "sigma_N_s_per_m", "pure_slip",
    "mass_kg", "load_inertia", "pulley_mu", "mu_sd", "mu_ss", "kappa", "c_r_N_s_per_m", "s_min_m", "s_max_m",
)
(A_L, A_B, ASYM_B, ALPHA0, P0, K_PRE, HALF, DEV1, DEV2, DEV3, WAVE_A, WAVE_P, BUMP_A, BUMP_C, BUMP_W, TAU,
 HEAT, F_L0, DF_L, T_REF, ZETA_L, ZETA_B, M_L, M_B, B2_THERMAL, K_E, U_M, MU_P, SIGMA, PURE_SLIP,
 MASS, INERTIA, PULLEY, MU_SD, MU_SS, KAPPA, C_R, S_MIN, S_MAX) = range(len(PARAMS))

#: values of ``x[REASON]``: all steps done, a new table cell needed, a step for the blocks
REASON_NONE, REASON_CELL, REASON_BLOCKS = 0.0, 1.0, 2.0
#: the ranges the blocks accept for the internal signals (their ``Var`` declarations in
#: :mod:`l1b2.cosim.blocks`; a test compares): stator position [m], interface amplitudes [m], phase [rad],
#: speed [m/s], static axial force [N], and the slider's driving force [N]
LIM_S = (-1.0, 1.0)
LIM_U = (0.0, 1e-3)
LIM_DELTA = (-10.0, 10.0)
LIM_V = (-10.0, 10.0)
LIM_FP = (0.0, 1e4)
LIM_FD = (-1e4, 1e4)
_BIG = 1.7976931348623157e308  # the bound of the blocks' unbounded inputs: inf and nan fail it


def parameter_vector(mp: MotorParams, pure_slip: bool = False) -> np.ndarray:
    """The parameter vector of :func:`motor_substeps` (:data:`PARAMS`) for motor ``mp``."""
    sp, ip, lp = mp.stator, mp.interface, mp.slider
    values = {name: getattr(sp, name) for name in PARAMS[:M_L]}
    values.update(M_l=modal_mass_l_kg(sp), M_b=modal_mass_b_kg(sp),
                  b2_thermal=1.0 if sp.df_dT_b_Hz_per_K != 0.0 else 0.0, pure_slip=1.0 if pure_slip else 0.0)
    values.update({name: getattr(ip, name) for name in PARAMS[K_E:PURE_SLIP]})
    values.update({name: getattr(lp, name) for name in PARAMS[MASS:]})
    return np.array([float(values[name]) for name in PARAMS], float)


def motor_substeps(x, p, cell, cell_k, n, h):
    """Advance the state vector ``x`` (:data:`STATE`) by up to ``n`` steps of ``h`` [s], in place.

    ``p``: parameter vector (:data:`PARAMS`); ``cell``: coefficients of the
    modal table's cell ``cell_k`` (:meth:`l1b2.physics.stator.ModalTable.cell_array`).
    The operations of ``InProcessMotor.step`` with the driver's outputs held:
    ``StatorBlock.do_step``, ``InterfaceBlock.do_step``, ``SliderBlock.do_step``
    in that order, each with the inputs the engine wires to it. Returns the
    number of steps done; fewer than ``n`` when ``x[REASON]`` asks the caller
    for a table cell or a step through the blocks (the state is then that
    before the step not taken).
    """
    x[REASON] = REASON_NONE
    V0_, omega, d, T, m_load = x[V0], x[OMEGA], x[DIR], x[T_AMB], x[M_LOAD]
    for k in range(n):
        s_in, v_in = x[S], x[V]
        fn1s, fn1c, ft1s, ft1c = x[FN1S], x[FN1C], x[FT1S], x[FT1C]
        # the stator block's input checks (the driver's outputs were checked by the caller)
        if not (LIM_S[0] <= s_in <= LIM_S[1] and -_BIG <= fn1s <= _BIG and -_BIG <= fn1c <= _BIG
                and -_BIG <= ft1s <= _BIG and -_BIG <= ft1c <= _BIG):
            x[REASON] = REASON_BLOCKS
            return k
        # stator: temperature, axial force, modal properties at the step's end (StatorBlock._update_props)
        T_st = x[T_ST]
        if p[TAU] > 0.0 or p[HEAT] != 0.0:
            T_st = temperature_step_scalar(T_st, T, V0_, p[TAU], p[HEAT], h)
        else:
            T_st = T
        if p[B2_THERMAL] != 0.0 and T_st != x[PROPS_T]:
            x[REASON] = REASON_BLOCKS  # the stator block evaluates the modal properties directly
            return k
        P = max(p[P0] + p[K_PRE] * bar_deviation_scalar(s_in, p[HALF], p[DEV1], p[DEV2], p[DEV3], p[WAVE_A],
                                                        p[WAVE_P], p[BUMP_A], p[BUMP_C], p[BUMP_W]), 0.0)
        kc = math.floor(P / TABLE_CELL_N)
        if kc != cell_k:
            x[REASON] = REASON_CELL
            x[NEED_CELL] = kc
            return k
        wb, eta = table_lookup(cell, P)
        eta_new = abs(eta)
        w_l0 = l1_omega_scalar(p[F_L0], p[DF_L], T_st - p[T_REF])
        M_l, M_b = p[M_L], p[M_B]
        (qlr, qli, qbr, qbi, U_l, U_w, ph_l, ph_w, delta) = coupled_envelope_step(
            x[QLR], x[QLI], x[QBR], x[QBI], x[PH_L], fn1s, fn1c, ft1s, ft1c,
            p[A_L] * V0_, d * p[A_B] * (1.0 + d * p[ASYM_B]) * V0_, x[ETA], omega,
            M_l, x[K_L], x[C_L], M_b, x[K_B], x[C_B], h, eta_new)
        F_p = p[ALPHA0] * P
        # the interface block's input checks, then its kernel
        if not (LIM_U[0] <= U_l <= LIM_U[1] and LIM_U[0] <= U_w <= LIM_U[1] and LIM_DELTA[0] <= delta <= LIM_DELTA[1]
                and LIM_V[0] <= v_in <= LIM_V[1] and LIM_FP[0] <= F_p <= LIM_FP[1]):
            x[REASON] = REASON_BLOCKS
            return k
        (F_d, F_nm, o_fn1s, o_fn1c, o_ft1s, o_ft1c, phi_c, stick) = period_integrals(
            U_l, U_w, delta, omega, v_in, F_p, p[K_E], p[U_M], p[MU_P], p[SIGMA], p[PURE_SLIP])
        if not LIM_FD[0] <= F_d <= LIM_FD[1]:  # the slider block's input check
            x[REASON] = REASON_BLOCKS
            return k
        # slider (slider.step: the force levels, then the event loop)
        m_mov, F_ext, F_c, F_s = force_levels(F_d, F_p, m_load, p[MASS], p[INERTIA], p[PULLEY], p[MU_SD], p[MU_SS],
                                              p[KAPPA])
        v_new, s_new, stuck, stop = step_floats(v_in, s_in, x[STUCK], x[STOP], m_mov, F_ext, F_c, F_s, p[C_R],
                                                p[S_MIN], p[S_MAX], h)
        # the step is taken: write it back
        x[T_ST] = T_st
        x[K_L], x[C_L] = stiffness_damping(M_l, w_l0, p[ZETA_L])  # the ModalTable's operations
        x[K_B], x[C_B] = stiffness_damping(M_b, wb, p[ZETA_B])
        x[ETA], x[W_L0], x[W_B0], x[PROPS_T] = eta_new, w_l0, wb, T_st
        x[QLR], x[QLI], x[QBR], x[QBI] = qlr, qli, qbr, qbi
        x[U_L], x[U_W], x[PH_L], x[PH_W], x[DELTA], x[F_P], x[P_AX] = U_l, U_w, ph_l, ph_w, delta, F_p, P
        x[S_IN], x[FN1S_IN], x[FN1C_IN], x[FT1S_IN], x[FT1C_IN], x[V_IN] = s_in, fn1s, fn1c, ft1s, ft1c, v_in
        x[F_D], x[F_NM], x[FN1S], x[FN1C], x[FT1S], x[FT1C] = F_d, F_nm, o_fn1s, o_fn1c, o_ft1s, o_ft1c
        x[PHI_C], x[STICK] = phi_c, stick
        x[V], x[S], x[STUCK], x[STOP] = v_new, s_new, 1.0 if stuck != 0.0 else 0.0, stop
        x[ACC] = (v_new - v_in) / h if h > 0 else 0.0
    return n


_COMPILED: list = []  # [kernel or None], filled on the first call of compiled_substeps()


def compiled_substeps():
    """:func:`motor_substeps` compiled by numba with every kernel it calls (once per process), or None
    (``L1B2_JIT=0``, numba missing or failing: see :mod:`.jit`)."""
    return cached_kernel(_COMPILED, lambda: (
        {**stator.kernel_family(), **interface.kernel_family(), **slider.kernel_family(),
         "motor_substeps": motor_substeps},
        "motor_substeps", "int64(float64[::1], float64[::1], float64[:, ::1], int64, int64, float64)"))
