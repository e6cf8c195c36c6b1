"""Friction interface between stator tip and friction bar (paper Sect. 3.3, Eq. 17-20, 23).

The interface is evaluated over one vibration period for given tip motion
(a steady periodic state, so it has no memory between periods). With
``theta = w t + phase_l`` the phase of the tip's normal displacement::

    normal displacement      n(theta) = U_l sin(theta)
    tangential displacement  w(theta) = U_w sin(theta + delta)
    tangential tip velocity  w'(theta) = w U_w cos(theta + delta)

For the ideal ellipse ``delta = -pi/2`` so ``w' = w U_w sin(theta)``: the tip
moves toward +position while it presses on the bar (paper Fig. 6).

Normal force (Eq. 17-18)
------------------------
Contact is centred on ``theta = pi/2`` with half angle ``a = phi_c/2`` and
``F_N = k_e U_l (sin theta - cos a)`` inside. Eq. 18,
``(sin a - a cos a) U_l = pi F_p / k_e``, is exactly the condition that the
period mean of ``F_N`` equals ``F_p``. When ``k_e U_l <= F_p`` the tip never
separates (permanent contact, ``phi_c = 2 pi``) and ``F_N = F_p + k_e U_l sin theta``;
both forms agree at the boundary.

Friction (Eq. 19-20) and the rule for ``u_r``
--------------------------------------------
``u_r`` is the relative tip-to-slider displacement accumulated since the
latest *reset*: the start of the current contact interval, or the last
reversal of the relative velocity ``w' - v``. Between resets ``|u_r|`` grows
monotonically. While ``|u_r| <= u_m`` (stick, asperity links deform)
``F_f = sign(w' - v) mu_p (|u_r| / u_m) F_N`` (Eq. 19 with ``c = mu_p / u_m``);
beyond (slip) ``F_f = sigma (w' - v) + sign(w' - v) mu_p F_N`` (Eq. 20).
Friction acts only in contact. In permanent contact with no velocity
reversal the relative motion never resets and the contact slides.

``mode="pure_slip"`` reproduces the paper's Sect. 4 assumptions for Eq. 23:
contact angle fixed at ``phi_c = pi`` (``F_N = pi F_p sin theta`` on
``[0, pi]``, keeping the period mean ``F_p``) and no stick (``u_m -> 0``).

Numerics (closed form): the contact window is split at the relative-velocity
reversals into up to three segments. Inside a segment the friction sign is
constant and ``u_r(theta) = U(theta) - U(theta_reset)``, with
``U = U_w sin(theta + delta) - (v / w) theta``, grows monotonically in
magnitude, so the stick-to-slip switch ``|u_r| = u_m`` is a unique root,
found by safeguarded Newton iteration. On every piece the integrands are
elementary (``F_N = A sin theta + B``; stick: ``(mu_p / u_m) u_r F_N``; slip:
``sigma (w' - v) + sign mu_p F_N``; times 1, ``sin theta``, ``cos theta``) and
are integrated exactly from their antiderivatives. The period averages are
exact to round-off and continuous in the inputs (needed by the steady-state
solver), except where the model itself jumps: at ``k_e U_l = F_p`` the
contact-start reset of ``u_r`` disappears.

The closed form is :func:`period_integrals` (plain floats, the subset of
Python numba compiles); the co-simulation runs it compiled
(:mod:`l1b2.physics.jit`), with the same results as the Python function.

:func:`interface_forces_reference` keeps the original numerical kernel
(midpoint rule, ``n_theta // 3`` cells per segment, switch located by linear
interpolation inside a cell), which converges to the closed form as
``n_theta`` grows; it serves as a check and for benchmarks.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..errors import SimulationError
from .jit import cached_kernel, jit_status
from .params import InterfaceParams

MODES = ("stick_slip", "pure_slip")


def contact_half_angle_rad(U_l_m, F_p_N, k_e_N_per_m):
    """Half contact angle ``a = phi_c / 2`` from Eq. 18, in ``[0, pi]`` [rad].

    Solves ``g(a) = sin a - a cos a = pi F_p / (k_e U_l)``; ``g`` rises
    monotonically from 0 to pi (``g' = a sin a``). Newton's method from the
    better of the two asymptotic starts (``a^3/3`` near 0, ``pi - pi e^2/2``
    near pi), kept inside a shrinking bracket. Returns ``pi`` (permanent
    contact) when ``k_e U_l <= F_p`` and 0 when ``F_p <= 0``.
    """
    U = np.asarray(U_l_m, float)
    Fp = np.asarray(F_p_N, float)
    if U.ndim == 0 and Fp.ndim == 0:
        return _half_angle_scalar(float(U), float(Fp), float(k_e_N_per_m))
    with np.errstate(divide="ignore", invalid="ignore"):
        rhs = np.where(U > 0, np.pi * Fp / (k_e_N_per_m * U), np.inf)
    r = np.clip(rhs, 0.0, np.pi)
    a = np.clip(np.where(r < 1.2, np.cbrt(3.0 * r), np.pi - np.sqrt(2.0 * (np.pi - r) / np.pi)),
                1e-12, np.pi - 1e-12)
    lo, hi = np.zeros_like(a), np.full_like(a, np.pi)
    for _ in range(30):
        g = np.sin(a) - a * np.cos(a) - r
        if np.all(np.abs(g) <= 4e-16 * np.pi):
            break
        lo = np.where(g < 0, a, lo)
        hi = np.where(g < 0, hi, a)
        a_new = a - g / np.maximum(a * np.sin(a), 1e-300)
        a = np.where((a_new >= lo) & (a_new <= hi), a_new, 0.5 * (lo + hi))
    a = np.where(rhs >= np.pi, np.pi, a)
    return np.where((Fp <= 0) | (r <= 0), 0.0, a)


def _half_angle_scalar(U: float, Fp: float, k_e: float) -> float:
    """Scalar fast path of :func:`contact_half_angle_rad` (same algorithm)."""
    if Fp <= 0:
        return 0.0
    if U <= 0 or k_e * U <= Fp:
        return math.pi
    r = math.pi * Fp / (k_e * U)
    a = (3.0 * r) ** (1.0 / 3.0) if r < 1.2 else math.pi - math.sqrt(2.0 * (math.pi - r) / math.pi)
    a = min(max(a, 1e-12), math.pi - 1e-12)
    lo, hi = 0.0, math.pi
    for _ in range(60):
        sin_a = math.sin(a)
        g = sin_a - a * math.cos(a) - r
        if abs(g) <= 4e-16 * math.pi:
            break
        if g < 0:
            lo = a
        else:
            hi = a
        a_new = a - g / max(a * sin_a, 1e-300)
        a = a_new if lo <= a_new <= hi else 0.5 * (lo + hi)
    return a


def normal_force_N(theta_rad, U_l_m, F_p_N, k_e_N_per_m):
    """Eq. 17 normal force at phase ``theta`` of the normal displacement [N] (permanent contact included)."""
    th = np.asarray(theta_rad, float)
    a = contact_half_angle_rad(U_l_m, F_p_N, k_e_N_per_m)
    U = np.asarray(U_l_m, float)
    # distance from the contact centre pi/2, wrapped to [-pi, pi]
    dist = np.abs(np.mod(th - np.pi / 2 + np.pi, 2 * np.pi) - np.pi)
    inside = dist <= a
    pulse = k_e_N_per_m * U * (np.sin(th) - np.cos(a))
    permanent = a >= np.pi
    return np.where(permanent, np.asarray(F_p_N, float) + k_e_N_per_m * U * np.sin(th),
                    np.where(inside, pulse, 0.0))


def mean_normal_force_N(U_l_m, a_rad, k_e_N_per_m):
    """Period mean of Eq. 17 for half contact angle ``a`` (the left side of Eq. 18 over pi) [N]."""
    a = np.asarray(a_rad, float)
    return k_e_N_per_m * np.asarray(U_l_m, float) * (np.sin(a) - a * np.cos(a)) / np.pi


def pure_slip_drive_force_N(U_w_m, omega_rad_s, v_m_s, F_p_N, sigma_N_s_per_m, mu_p):
    """Closed-form period-mean driving force for pure slip, phi_c = pi, ideal phase (docs/explanation/physics.md).

    ``F_d = sigma (w U_w / pi - v / 2) + mu F_p (2 sqrt(1 - k0^2) - 1)``, ``k0 = v / (w U_w)``
    for ``0 <= k0 < 1``. Outside, the relative velocity keeps one sign over the
    contact half period: the Coulomb part is ``+mu F_p`` for ``k0 <= 0`` and
    ``-mu F_p`` for ``k0 >= 1``. Eq. 23 is the fundamental of the same force.
    """
    u = np.asarray(omega_rad_s, float) * np.asarray(U_w_m, float)
    v = np.asarray(v_m_s, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(u > 0, v / u, np.sign(v) * np.inf)
    # k0 <= 0: the relative velocity never reverses within contact (+1); k0 >= 1: never positive (-1)
    coul = np.where(k >= 1, -1.0, np.where(k <= 0, 1.0, 2 * np.sqrt(np.clip(1 - k * k, 0, None)) - 1))
    return sigma_N_s_per_m * (u / np.pi - v / 2) + mu_p * np.asarray(F_p_N, float) * coul


def pure_slip_fundamental_N(U_w_m, omega_rad_s, v_m_s, F_p_N, sigma_N_s_per_m, mu_p):
    """Eq. 23: amplitude of the ``sin(w t)`` component of the pure-slip friction force [N].

    ``0.5 sigma w U_w - 2 sigma v / pi + mu F_p (sin 2 w t1 + pi/2 - 2 w t1)``
    with ``w t1 = arcsin(v / (w U_w))`` for ``0 <= v <= w U_w``; ``w t1`` is
    clipped to ``[0, pi/2]`` (no reversal within contact outside that range).
    """
    u = np.asarray(omega_rad_s, float) * np.asarray(U_w_m, float)
    v = np.asarray(v_m_s, float)
    wt1 = np.arcsin(np.clip(v / u, 0, 1))
    return sigma_N_s_per_m * (0.5 * u - 2 * v / np.pi) + mu_p * np.asarray(F_p_N, float) * (
        np.sin(2 * wt1) + 0.5 * np.pi - 2 * wt1)


class InterfaceOutput(NamedTuple):
    F_d_N: np.ndarray          #: period-mean friction force on the slider (driving force) [N]
    F_N_mean_N: np.ndarray     #: period-mean normal force (equals F_p) [N]
    F_N1_sin_N: np.ndarray     #: sin(theta) component of the normal force fundamental [N]
    F_N1_cos_N: np.ndarray     #: cos(theta) component of the normal force fundamental [N]
    F_T1_sin_N: np.ndarray     #: sin(theta) component of the friction force fundamental [N]
    F_T1_cos_N: np.ndarray     #: cos(theta) component of the friction force fundamental [N]
    phi_c_rad: np.ndarray      #: contact angle phi_c (2 pi = permanent contact) [rad]
    stick_fraction: np.ndarray  #: fraction of the contact time spent in stick [-]


def interface_forces(U_l_m, U_w_m, delta_rad, omega_rad_s, v_m_s, F_p_N,
                     params: InterfaceParams, mode: str = "stick_slip", n_theta: int = 256) -> InterfaceOutput:
    """Period-averaged interface forces for the given tip motion and slider speed (closed form).

    Parameters
    ----------
    U_l_m, U_w_m : tip normal / tangential vibration amplitude [m]
    delta_rad : phase of the tangential relative to the normal displacement [rad]
    omega_rad_s : vibration angular frequency [rad/s]
    v_m_s : slider speed [m/s]
    F_p_N : static axial force, the period mean of the normal force [N]
    params : contact stiffness, friction coefficients, stick threshold
    mode : ``"stick_slip"`` (Eq. 17-20) or ``"pure_slip"`` (Eq. 23 assumptions)
    n_theta : not used: the period averages are exact integrals (module
        docstring). Kept for compatibility; it is the resolution of
        :func:`interface_forces_reference`, the numerical kernel.

    Scalar arguments (the co-simulation's hot path) give floats; arrays are
    broadcast and evaluated element by element.

    Returns
    -------
    InterfaceOutput
        Fundamental components are in the frame of the normal displacement:
        ``F(theta) ~ F1_sin sin(theta) + F1_cos cos(theta)``.
    """
    if mode not in MODES:
        raise ValueError(f"interface mode must be one of {MODES}, got {mode!r}")
    args = (U_l_m, U_w_m, delta_rad, omega_rad_s, v_m_s, F_p_N)
    for x in args:
        if not isinstance(x, (float, int)):
            break
    else:  # plain (or numpy) scalars: the co-simulation's hot path
        return interface_forces_scalar(float(U_l_m), float(U_w_m), float(delta_rad), float(omega_rad_s),
                                       float(v_m_s), float(F_p_N), params, mode)
    arrays = np.broadcast_arrays(*(np.asarray(x, float) for x in args))
    shape = arrays[0].shape
    if not shape:
        return interface_forces_scalar(*(float(x) for x in arrays), params, mode)
    kernel, kargs = compiled_kernel() or period_integrals, kernel_arguments(params, mode)  # once per call
    rows = [kernel(*row, *kargs) for row in zip(*(x.ravel().tolist() for x in arrays))]
    cols = np.array(rows, dtype=float).reshape(shape + (len(InterfaceOutput._fields),))
    return InterfaceOutput(*np.moveaxis(cols, -1, 0))


def interface_forces_scalar(U_l, U_w, delta, omega, v, F_p, params: InterfaceParams, mode: str,
                            jit: bool | None = None) -> InterfaceOutput:
    """Exact period averages for scalar inputs (floats): the contact window cut into elementary pieces.

    The scalar kernel behind :func:`interface_forces`, for callers that already hold
    plain floats and a valid ``mode`` (the co-simulation's per-step call). The
    work is done by :func:`period_integrals`, compiled with numba when it is
    available (``jit=None``, the default; :mod:`l1b2.physics.jit`); ``jit=False``
    runs the same function as plain Python (the results agree to round-off).
    """
    kernel = compiled_kernel() if jit is None or jit else None
    if kernel is None:
        if jit:
            raise SimulationError(f"the compiled interface kernel is not available: {jit_status()}")
        kernel = period_integrals
    return InterfaceOutput(*kernel(U_l, U_w, delta, omega, v, F_p, *kernel_arguments(params, mode)))


def kernel_arguments(params: InterfaceParams, mode: str) -> tuple:
    """The parameter arguments of :func:`period_integrals`, after its six tip-motion inputs."""
    return params.k_e_N_per_m, params.u_m_m, params.mu_p, params.sigma_N_s_per_m, 1.0 if mode == "pure_slip" else 0.0


_COMPILED: list = []  # [kernel or None], filled on the first call of compiled_kernel()


def kernel_family() -> dict:
    """:func:`period_integrals` and the helpers it calls, by name (for :func:`l1b2.physics.jit.compile_family`)."""
    return {"_half_angle_scalar": _half_angle_scalar, "_primitives": _primitives, "_switch_phase": _switch_phase,
            "period_integrals": period_integrals}


def compiled_kernel():
    """:func:`period_integrals` compiled by numba (once per process), or None (see :mod:`.jit`)."""
    return cached_kernel(_COMPILED, lambda: (
        kernel_family(), "period_integrals", "UniTuple(float64, 8)(" + ", ".join(["float64"] * 11) + ")"))


def period_integrals(U_l, U_w, delta, omega, v, F_p, k_e, u_m, mu, sigma, pure_slip):
    """The period averages of :class:`InterfaceOutput`, in its order, as a tuple of floats.

    Plain floats in, plain floats out (``pure_slip`` 1.0 or 0.0), written in
    the subset of Python that numba compiles (:func:`compiled_kernel`).

    ``F_N = A sin(theta) + B`` on the window. The cuts are the relative-velocity
    reversals (friction sign and ``u_r`` reset) and, inside each segment, the
    stick-to-slip switch ``|u_r| = u_m`` (:func:`_switch_phase`). Each piece
    is integrated with the antiderivatives of :func:`_primitives`.
    """
    if pure_slip != 0.0:  # phi_c = pi, F_N = pi F_p sin(theta), no stick
        a, A, B, u_m, permanent = 0.5 * math.pi, math.pi * F_p, 0.0, 0.0, False
    else:
        a = _half_angle_scalar(U_l, F_p, k_e)
        A = k_e * U_l
        permanent = a >= math.pi
        B = F_p if permanent else -A * math.cos(a)
    two_pi = 2.0 * math.pi
    u_tip = omega * U_w
    has_rev = u_tip > 0 and abs(v) < u_tip
    if permanent:  # the window starts at a reset: the first reversal if there is one
        start, width = (math.acos(v / u_tip) - delta if has_rev else 0.0), two_pi
    else:
        start, width = 0.5 * math.pi - a, 2.0 * a
    # the window [start, start + width] cut at the reversals inside it: up to three segments
    cut1 = cut2 = math.inf  # "no cut"
    if has_rev:
        ac = math.acos(v / u_tip)
        x1, x2 = (ac - delta - start) % two_pi, (-ac - delta - start) % two_pi
        if x2 < x1:
            x1, x2 = x2, x1
        if x1 < width:
            cut1 = start + (0.0 if permanent and x1 < 1e-12 else x1)
            if x2 < width:
                cut2 = start + x2
    end = start + width
    q = v / omega  # u_r(th) = U(th) - U(lo), U(th) = U_w sin(th + delta) - q th
    cd, sd = math.cos(delta), math.sin(delta)
    stick_on = u_m > 0 and not (permanent and not has_rev)  # permanent contact without reversal slides
    P0 = P_lo = _primitives(start, A, B, U_w, q, u_tip, v, cd, sd)
    I0 = I1 = I2 = 0.0  # integrals of F_f, F_f sin, F_f cos over the window
    stick_len = 0.0
    for i in range(3):
        hi = cut1 if i == 0 else (cut2 if i == 1 else end)
        if hi > end:  # no such cut
            continue
        lo = P_lo[0]
        P_hi = _primitives(hi, A, B, U_w, q, u_tip, v, cd, sd)
        if hi > lo:
            rv_mid = u_tip * math.cos(0.5 * (lo + hi) + delta) - v
            sgn = 1 if rv_mid > 0 else (-1 if rv_mid < 0 else 0)
            P_sw = P_lo
            slips = True
            if stick_on:  # stick on [lo, sw]: F_f = (mu / u_m) (U - U(lo)) F_N
                sw = _switch_phase(lo, hi, sgn, U_w, delta, q, u_m)
                slips = sw != hi
                P_sw = _primitives(sw, A, B, U_w, q, u_tip, v, cd, sd) if slips else P_hi
                c, U_lo = mu / u_m, P_lo[10]
                I0 += c * (P_sw[4] - P_lo[4] - U_lo * (P_sw[1] - P_lo[1]))
                I1 += c * (P_sw[5] - P_lo[5] - U_lo * (P_sw[2] - P_lo[2]))
                I2 += c * (P_sw[6] - P_lo[6] - U_lo * (P_sw[3] - P_lo[3]))
                stick_len += sw - lo
            if slips:  # slip on [sw, hi]: F_f = sigma (w' - v) + sgn mu F_N
                c = sgn * mu
                I0 += sigma * (P_hi[7] - P_sw[7]) + c * (P_hi[1] - P_sw[1])
                I1 += sigma * (P_hi[8] - P_sw[8]) + c * (P_hi[2] - P_sw[2])
                I2 += sigma * (P_hi[9] - P_sw[9]) + c * (P_hi[3] - P_sw[3])
        P_lo = P_hi
    return (I0 / two_pi, (P_lo[1] - P0[1]) / two_pi, (P_lo[2] - P0[2]) / math.pi, (P_lo[3] - P0[3]) / math.pi,
            I1 / math.pi, I2 / math.pi, 2.0 * a, stick_len / width if width > 0 else 0.0)


def _primitives(th, A, B, U_w, q, u_tip, v, cd, sd) -> tuple:
    """Antiderivatives at ``th`` of the integrands of the period averages, and ``U(th)``.

    Returns ``(th, F_N w ..., U F_N w ..., (w' - v) w ..., U)`` for the weights
    ``w = 1, sin th, cos th``, with ``F_N = A sin th + B``, the relative velocity
    ``w' - v = u_tip cos(th + delta) - v`` and ``U = U_w sin(th + delta) - q th``
    (so that ``u_r = U(th) - U(reset)``).
    """
    S, C = math.sin(th), math.cos(th)
    SC, SS, CC = S * C, S * S, C * C
    s2, c2 = 2.0 * SC * cd + (CC - SS) * sd, (CC - SS) * cd - 2.0 * SC * sd  # sin, cos of 2 th + delta
    E, G = S * cd + C * sd, C * cd - S * sd  # sin, cos of th + delta
    tS, tC, tt = th * S, th * C, th * th
    iS, iC = S - tC, C + tS  # int th S, int th C
    return (
        th,
        B * th - A * C,                                  # int F_N
        0.5 * A * (th - SC) - B * C,                     # int F_N S
        0.5 * A * SS + B * S,                            # int F_N C
        U_w * (A * (0.5 * th * cd - 0.25 * s2) - B * G) - q * (A * iS + 0.5 * B * tt),
        U_w * (A * (cd * C * (CC / 3.0 - 1.0) + sd * S * SS / 3.0) + B * (0.5 * th * cd - 0.25 * s2))
        - q * (A * (0.25 * tt - 0.5 * th * SC - 0.125 * (CC - SS)) + B * iS),
        U_w * (A * (cd * S * SS - sd * C * CC) / 3.0 + B * (0.5 * th * sd - 0.25 * c2))
        - q * (A * (0.25 * SC - 0.25 * th * (CC - SS)) + B * iC),
        u_tip * E - v * th,                              # int (w' - v)
        u_tip * (-0.25 * c2 - 0.5 * th * sd) + v * C,   # int (w' - v) S
        u_tip * (0.25 * s2 + 0.5 * th * cd) - v * S,    # int (w' - v) C
        U_w * E - q * th,                                # U
    )


def _switch_phase(lo: float, hi: float, sgn: int, U_w: float, delta: float, q: float, u_m: float) -> float:
    """Phase in ``[lo, hi]`` where the stick ends, ``sgn u_r(th) = u_m``; ``hi`` if it never does.

    ``u_r(th) = U_w (sin(th + delta) - sin(lo + delta)) - q (th - lo)``, ``q = v / w``, is
    reset at ``lo`` and ``sgn u_r`` rises monotonically over the segment (its slope
    ``sgn (w' - v) / w >= 0``), so the root is unique. Newton's method from the
    second-order Taylor estimate, kept inside a shrinking bracket (bisection otherwise).
    """
    e0, g0 = math.sin(lo + delta), math.cos(lo + delta)
    if sgn == 0 or sgn * (U_w * (math.sin(hi + delta) - e0) - q * (hi - lo)) <= u_m:
        return hi
    d1, d2 = sgn * (U_w * g0 - q), -sgn * U_w * e0  # first two derivatives of sgn u_r at lo
    disc = d1 * d1 + 2 * d2 * u_m
    den = d1 + math.sqrt(disc) if disc > 0 else 0.0
    x = lo + 2 * u_m / den if den > 0 else 0.5 * (lo + hi)
    a, b = lo, hi  # g(a) < 0 < g(b)
    for _ in range(100):
        if not a < x < b:
            x = 0.5 * (a + b)
        gx = sgn * (U_w * (math.sin(x + delta) - e0) - q * (x - lo)) - u_m
        if gx < 0:
            a = x
        elif gx > 0:
            b = x
        else:
            return x
        slope = sgn * (U_w * math.cos(x + delta) - q)
        x_new = x - gx / slope if slope > 0 else 0.5 * (a + b)
        if abs(x_new - x) <= 1e-10 or b - a <= 1e-13:  # quadratic convergence: x_new is then exact
            return min(max(x_new, a), b)
        x = x_new
    return x


def interface_forces_reference(U_l_m, U_w_m, delta_rad, omega_rad_s, v_m_s, F_p_N, params: InterfaceParams,
                               mode: str = "stick_slip", n_theta: int = 256) -> InterfaceOutput:
    """Numerical reference kernel of :func:`interface_forces` (same arguments and outputs).

    Midpoint rule with ``n_theta // 3`` cells per segment between the window
    start, the relative-velocity reversals and the window end; the stick-to-slip
    switch inside a cell by linear interpolation (module docstring). First
    order in the cell size for stick-slip, second order for pure slip. Kept to
    check and benchmark the closed form against; vectorised with numpy.
    """
    if mode not in MODES:
        raise ValueError(f"interface mode must be one of {MODES}, got {mode!r}")
    U_l, U_w, delta, omega, v, F_p = np.broadcast_arrays(
        *(np.asarray(x, float) for x in (U_l_m, U_w_m, delta_rad, omega_rad_s, v_m_s, F_p_N)))
    shape = U_l.shape
    U_l, U_w, delta, omega, v, F_p = (x.reshape(-1, 1) for x in (U_l, U_w, delta, omega, v, F_p))

    if mode == "pure_slip":
        a = np.full_like(U_l, np.pi / 2)
        amp_N = np.pi * F_p  # k_e U_l replaced so that the mean stays F_p
        u_m = 0.0
    else:
        if U_l.size == 1:  # scalar fast path (the co-simulation's hot loop)
            a = np.full_like(U_l, _half_angle_scalar(float(U_l[0, 0]), float(F_p[0, 0]), params.k_e_N_per_m))
        else:
            a = contact_half_angle_rad(U_l, F_p, params.k_e_N_per_m)
        amp_N = params.k_e_N_per_m * U_l
        u_m = params.u_m_m
    permanent = a >= np.pi
    u_tip = omega * U_w  # tangential velocity amplitude

    # Reversal phases of the relative velocity: w U_w cos(theta + delta) = v
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(u_tip > 0, v / u_tip, np.sign(v) * np.inf)
    has_rev = np.abs(ratio) < 1
    acos = np.arccos(np.clip(ratio, -1, 1))
    rev = np.concatenate([acos - delta, -acos - delta], axis=1)  # (n, 2)

    # Window start: contact start, or (permanent contact) the first reversal.
    start = np.where(permanent, np.where(has_rev, rev[:, :1], 0.0), np.pi / 2 - a)
    width = np.where(permanent, 2 * np.pi, 2 * a)  # (n, 1)
    rev_rel = np.mod(rev - start, 2 * np.pi)  # reversal positions inside the window
    rev_rel = np.where(has_rev & (rev_rel < width), rev_rel, np.inf)
    # in permanent contact the first reversal is the window start itself
    rev_rel = np.where(permanent & has_rev, np.where(rev_rel < 1e-12, 0.0, rev_rel), rev_rel)

    # Cells aligned with the breakpoints (window start, up to two reversals, window end): inside a
    # segment the relative velocity keeps its sign and u_r accumulates from the segment start, so the
    # midpoint rule is second order everywhere. Each segment gets n_theta // 3 cells.
    r_sorted = np.sort(rev_rel, axis=1)
    bounds = (np.zeros_like(width), np.minimum(r_sorted[:, :1], width), np.minimum(r_sorted[:, 1:2], width), width)
    m = max(n_theta // 3, 1)
    frac_m = (np.arange(m) + 0.5) / m
    frac_e = np.arange(m + 1) / m
    mids, hcell, seg_lo, e0, e1 = [], [], [], [], []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        span = hi - lo
        mids.append(lo + span * frac_m)
        edges = lo + span * frac_e
        e0.append(edges[:, :-1])
        e1.append(edges[:, 1:])
        hcell.append(np.broadcast_to(span / m, (len(width), m)))
        seg_lo.append(np.broadcast_to(lo, (len(width), m)))
    mids, hcell, seg_lo, e0, e1 = (np.concatenate(x, axis=1) for x in (mids, hcell, seg_lo, e0, e1))
    th_m = start + mids

    # Normal force at midpoints
    if mode == "pure_slip":
        F_N = amp_N * np.sin(th_m)
    else:
        F_N = np.where(permanent, F_p + amp_N * np.sin(th_m), amp_N * (np.sin(th_m) - np.cos(a)))
    F_N = np.maximum(F_N, 0.0)

    # Relative velocity (constant sign within a segment) and accumulated relative displacement
    rv_m = u_tip * np.cos(th_m + delta) - v
    sgn = np.sign(rv_m)
    th_r = start + seg_lo

    def rel_disp(th):
        return U_w * (np.sin(th + delta) - np.sin(th_r + delta)) - v * (th - th_r) / omega

    u_r = rel_disp(th_m)
    slides_forever = permanent & ~has_rev  # no reset ever: the contact slides
    if u_m > 0:
        # slip share of each cell from |u_r| - u_m at its edges (|u_r| is monotone in a segment)
        g0 = np.abs(rel_disp(start + e0)) - u_m
        g1 = np.abs(rel_disp(start + e1)) - u_m
        with np.errstate(divide="ignore", invalid="ignore"):
            slip = np.where(g0 * g1 < 0, np.where(g1 > 0, g1 / (g1 - g0), g0 / (g0 - g1)),
                            (g0 + g1 > 0).astype(float))
        slip = np.where(slides_forever, 1.0, slip)
        mu_eff = params.mu_p * np.where(slides_forever, 1.0, np.minimum(np.abs(u_r) / u_m, 1.0))
    else:
        slip = np.ones_like(u_r)
        mu_eff = np.full_like(u_r, params.mu_p)
    F_f = slip * params.sigma_N_s_per_m * rv_m + sgn * mu_eff * F_N
    stick = 1.0 - slip

    two_pi = 2 * np.pi
    s_m, c_m = np.sin(th_m), np.cos(th_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        stick_share = np.where(width[:, 0] > 0, np.sum(stick * hcell, axis=1) / width[:, 0], 0.0)
    out = InterfaceOutput(
        F_d_N=np.sum(F_f * hcell, axis=1) / two_pi,
        F_N_mean_N=np.sum(F_N * hcell, axis=1) / two_pi,
        F_N1_sin_N=np.sum(F_N * s_m * hcell, axis=1) / np.pi,
        F_N1_cos_N=np.sum(F_N * c_m * hcell, axis=1) / np.pi,
        F_T1_sin_N=np.sum(F_f * s_m * hcell, axis=1) / np.pi,
        F_T1_cos_N=np.sum(F_f * c_m * hcell, axis=1) / np.pi,
        phi_c_rad=(2 * a)[:, 0],
        stick_fraction=stick_share,
    )
    return InterfaceOutput(*(np.reshape(x, shape) if shape else float(x[0]) for x in out))
