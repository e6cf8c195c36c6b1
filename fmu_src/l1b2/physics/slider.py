"""Slider on its linear guide (paper Sect. 3.4, Eq. 21-22).

``m dv/dt + c_r v = F_d + F_g - F_load`` (Eq. 21) with the guide friction
``F_g = -sign(v) mu_sd (kappa F_p + g m_s)`` (Eq. 22 has ``kappa = 1``, Eq. 29
``kappa = 0.5``: a parameter here) and the load force ``F_load = g m_load``.
An optional load-path (pulley) friction ``pulley_mu g |m_load|`` adds to the
Coulomb level; it is off in the reference motor.

Conventions and decisions
-------------------------
* Load sign as in the rig data format (docs/reference/data-format.md): a positive ``m_load`` hangs on the
  pulley pulling toward -position, so ``F_load > 0`` opposes +direction runs.
* Moving mass ``m_s + load_inertia * |m_load|``: the hanging weight moves
  with the slider (``load_inertia = 1`` for the pulley rig; the paper writes m).
* Stick: a bare ``sign(v)`` chatters at ``v = 0``. The slider sticks when its
  speed reaches zero and the applied force ``F_d - F_load`` does not exceed
  the static friction ``mu_ss (kappa F_p + g m_s)`` (Karnopp's idea, exact
  here because the stepper finds the zero crossing in time).
* End stops at ``s_min_m`` and ``s_max_m`` are inelastic: the slider stops
  there (``v = 0``) and stays until the force pulls it away.
* Stepping: inputs are held over a step (zero-order hold, as in
  co-simulation) and the piecewise-linear ODE is solved in closed form
  between events (zero speed, end stop), so the result does not depend on
  the step size except through the input hold.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .jit import cached_kernel
from .params import G_M_S2, SliderParams


def moving_mass_kg(sp: SliderParams, m_load_kg):
    """Mass accelerated with the slider [kg]."""
    if isinstance(m_load_kg, float):  # scalar fast path (per-step call)
        return sp.mass_kg + sp.load_inertia * abs(m_load_kg)
    return sp.mass_kg + sp.load_inertia * np.abs(np.asarray(m_load_kg, float))


def guide_friction_level_N(sp: SliderParams, F_p_N, static: bool = False):
    """Coulomb level of the guide friction ``mu (kappa F_p + g m_s)`` (Eq. 22) [N]."""
    mu = sp.mu_ss if static else sp.mu_sd
    if isinstance(F_p_N, float):
        return mu * (sp.kappa * F_p_N + G_M_S2 * sp.mass_kg)
    return mu * (sp.kappa * np.asarray(F_p_N, float) + G_M_S2 * sp.mass_kg)


def load_path_friction_N(sp: SliderParams, m_load_kg):
    """Coulomb friction of the load path (pulley bearing) ``pulley_mu g |m_load|`` [N] (0 in the reference)."""
    if isinstance(m_load_kg, float):
        return sp.pulley_mu * G_M_S2 * abs(m_load_kg)
    return sp.pulley_mu * G_M_S2 * np.abs(np.asarray(m_load_kg, float))


def load_force_N(m_load_kg):
    """Force of the hanging load, positive toward -position [N]."""
    if isinstance(m_load_kg, float):
        return G_M_S2 * m_load_kg
    return G_M_S2 * np.asarray(m_load_kg, float)


def acceleration_m_s2(sp: SliderParams, v_m_s, F_d_N, F_p_N, m_load_kg):
    """Right side of Eq. 21 divided by the moving mass, for a moving slider [m/s^2] (vectorised)."""
    v = np.asarray(v_m_s, float)
    F = (np.asarray(F_d_N, float) - load_force_N(m_load_kg) - sp.c_r_N_s_per_m * v
         - np.sign(v) * (guide_friction_level_N(sp, F_p_N) + load_path_friction_N(sp, m_load_kg)))
    return F / moving_mass_kg(sp, m_load_kg)


def first_order_response(v0_m_s, F_N, c_r_N_s_per_m, m_kg, t_s):
    """Speed and travelled distance of ``m dv/dt = F - c_r v`` from ``v0`` after ``t`` (closed form).

    Handles ``c_r = 0`` (uniform acceleration). Returns ``(v, ds)`` [m/s, m].
    """
    if isinstance(v0_m_s, float) and isinstance(F_N, float) and isinstance(t_s, float) and c_r_N_s_per_m != 0:
        return first_order_scalar(v0_m_s, F_N, c_r_N_s_per_m, m_kg, t_s)  # scalar fast path, same formulas
    v0 = np.asarray(v0_m_s, float)
    t = np.asarray(t_s, float)
    if c_r_N_s_per_m == 0:
        acc = np.asarray(F_N, float) / m_kg
        return v0 + acc * t, v0 * t + 0.5 * acc * t * t
    T = m_kg / c_r_N_s_per_m
    v_inf = np.asarray(F_N, float) / c_r_N_s_per_m
    decay = -np.expm1(-t / T)  # 1 - exp(-t/T), accurate for small t
    return v_inf + (v0 - v_inf) * (1 - decay), v_inf * t + (v0 - v_inf) * T * decay


class SliderState(NamedTuple):
    v_m_s: float
    s_m: float
    stuck: bool
    at_stop: int  #: -1 at the negative end stop, +1 at the positive one, 0 elsewhere


def step(sp: SliderParams, state: SliderState, F_d_N: float, F_p_N: float, m_load_kg: float,
         h_s: float, kernel=None) -> SliderState:
    """Advance the slider by ``h_s`` with the inputs held constant (event-exact).

    The force levels are computed here; the event loop is ``kernel``, by default
    :func:`step_floats` compiled by numba when available (:func:`compiled_step`).
    """
    m, F_ext, Fc, Fs = force_levels(float(F_d_N), float(F_p_N), float(m_load_kg), sp.mass_kg, sp.load_inertia,
                                    sp.pulley_mu, sp.mu_sd, sp.mu_ss, sp.kappa)
    kern = kernel or compiled_step() or step_floats
    v, s, stuck, at_stop = kern(float(state.v_m_s), float(state.s_m), 1.0 if state.stuck else 0.0,
                                float(state.at_stop), m, F_ext, Fc, Fs, sp.c_r_N_s_per_m, sp.s_min_m, sp.s_max_m,
                                float(h_s))
    return SliderState(v, s, stuck != 0.0, int(at_stop))


def force_levels(F_d, F_p, m_load, mass, load_inertia, pulley_mu, mu_sd, mu_ss, kappa):
    """The force levels of :func:`step` in plain floats (numba compiles it; the fused coupled step calls it too):
    ``(m, F_ext, Fc, Fs)``, the arguments of :func:`step_floats`.

    The formulas of :func:`moving_mass_kg`, :func:`load_force_N`,
    :func:`load_path_friction_N` and :func:`guide_friction_level_N` (which take
    the parameter dataclass; tests/test_slider.py checks :func:`step` against
    them) in one call: ``F_d`` drive force [N], ``F_p`` preload [N], ``m_load``
    signed load [kg], ``mass`` slider mass [kg], ``load_inertia`` 1 when the
    load mass is accelerated with the slider, 0 when not, ``pulley_mu``
    load-path friction per load weight, ``mu_sd`` / ``mu_ss`` dynamic / static
    guide friction, ``kappa`` share of the preload loading the guide.
    """
    F_path = pulley_mu * G_M_S2 * abs(m_load)
    return (mass + load_inertia * abs(m_load), F_d - G_M_S2 * m_load,
            mu_sd * (kappa * F_p + G_M_S2 * mass) + F_path, mu_ss * (kappa * F_p + G_M_S2 * mass) + F_path)


def step_floats(v, s, stuck, at_stop, m, F_ext, Fc, Fs, c, s_min, s_max, h_s):
    """The event loop of :func:`step` in plain floats: ``(v, s, stuck, at_stop)`` after ``h_s``.

    ``m`` moving mass [kg], ``F_ext = F_d - F_load`` [N], ``Fc`` / ``Fs`` dynamic /
    static Coulomb level of guide and load path [N], ``c`` viscous coefficient
    [N s/m], ``s_min`` / ``s_max`` end stops [m]; ``stuck`` 1.0 or 0.0,
    ``at_stop`` -1.0, 0.0 or 1.0. Written in the subset of Python numba compiles.
    """
    t = 0.0
    for _ in range(16):  # a step holds at most a few events
        remaining = h_s - t
        if remaining <= 0:
            break
        if stuck != 0.0 or v == 0.0:
            if abs(F_ext) <= Fs:
                return 0.0, s, 1.0, at_stop
            direction = 1.0 if F_ext > 0 else -1.0
            if at_stop == direction:  # pushed into the stop
                return 0.0, s, 1.0, at_stop
            stuck, v = 0.0, 0.0
        else:
            direction = 1.0 if v > 0 else -1.0
        at_stop = 0.0
        F = F_ext - direction * Fc
        # time at which the speed reaches zero (if the net force decelerates it)
        t_zero = math.inf
        if direction * F < 0:  # decelerating: v heads for v_inf of the opposite sign
            t_zero = -v * m / F if c == 0 else (m / c) * math.log((v - F / c) / (-F / c))
        tau = min(remaining, t_zero)
        v_new, ds = first_order_scalar(v, F, c, m, tau)
        s_new = s + ds
        limit = s_max if direction > 0 else s_min
        if direction * (s_new - limit) >= 0:  # reaches the end stop within tau
            t += time_to_reach(v, F, c, m, limit - s, tau)
            s, v, stuck, at_stop = limit, 0.0, 1.0, direction
            continue
        t += tau
        s = s_new
        if tau == t_zero:
            v = 0.0
            stuck = 1.0 if abs(F_ext) <= Fs else 0.0
        else:
            v = v_new
    return v, s, (1.0 if stuck != 0.0 and v == 0.0 else 0.0), at_stop


def first_order_scalar(v0, F, c, m, t):
    """:func:`first_order_response` for plain floats (any ``c >= 0``): ``(v, ds)`` [m/s, m]."""
    if c == 0:
        acc = F / m
        return v0 + acc * t, v0 * t + 0.5 * acc * t * t
    T = m / c
    v_inf = F / c
    decay = -math.expm1(-t / T)  # 1 - exp(-t/T), accurate for small t
    return v_inf + (v0 - v_inf) * (1 - decay), v_inf * t + (v0 - v_inf) * T * decay


_COMPILED: list = []  # [kernel or None], filled on the first call of compiled_step()


def kernel_family() -> dict:
    """:func:`step_floats` and the helpers it calls, by name (for :func:`l1b2.physics.jit.compile_family`)."""
    return {"first_order_scalar": first_order_scalar, "time_to_reach": time_to_reach, "step_floats": step_floats,
            "force_levels": force_levels}


def compiled_step():
    """:func:`step_floats` compiled by numba (once per process), or None (see :mod:`.jit`)."""
    return cached_kernel(_COMPILED, lambda: (
        kernel_family(), "step_floats", "UniTuple(float64, 4)(" + ", ".join(["float64"] * 12) + ")"))


def time_to_reach(v0, F, c, m, distance, t_max):
    """First time at which the travelled distance equals ``distance`` (monotone motion), by bisection [s]."""
    lo, hi = 0.0, t_max
    sgn = math.copysign(1.0, distance)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        _, ds = first_order_scalar(v0, F, c, m, mid)
        if (ds - distance) * sgn < 0:
            lo = mid
        else:
            hi = mid
    return hi
