"""Stator: L1 and B2 modal dynamics, axially loaded B2 mode shape (paper Sect. 3.2, Eq. 5-16).

Conventions (decisions where the paper is ambiguous; see docs/explanation/physics.md)
---------------------------------------------------------------------------------------
* Phasors: a harmonic signal is ``x(t) = Im[X exp(j w t)]`` (the paper writes
  ``sin(w t)``), so ``|X|`` is the amplitude and ``angle(X)`` the phase.
* Modal coordinates ``q_l`` (L1) and ``q_b`` (B2) obey Eq. 6-7::

      M_l q_l'' + C_l q_l' + K_l q_l = A_l V0 sin(wt) - eta_N F_N(t)
      M_b q_b'' + C_b q_b' + K_b q_b = d A_b V0 sin(wt) - eta_T F_f(t)

  ``F_N >= 0`` is the normal contact force pushing the tip away from the
  bar, ``F_f`` the friction force on the slider (positive toward +position);
  the tip feels ``-F_N`` and ``-F_f``, hence the minus signs (the paper's
  ``+eta F`` with unsigned coefficients hides this). ``d = +1`` for CH1 and
  ``-1`` for CH2 (the channel reverses the B2 excitation).
* Load coefficients are the mode shapes at the tip (Hamilton's principle):
  ``eta_N = |phi_u(L)| = 1`` and ``eta_T = |phi_b(L, P)|``. Tip normal
  displacement (toward the bar) is ``eta_N q_l``, tip tangential displacement
  (toward +position) ``eta_T q_b``. Eq. 12-13 then give ``U_l = eta_N |Q_l|``
  and ``U_w = eta_T |Q_b|``.
* Mode shapes: ``phi_u = cos(pi x / L)`` (Eq. 8), ``int_0^L phi_u^2 dx = L/2``,
  so ``M_l = rho S L / 2``. ``phi_b`` (Eq. 9) is normalised to
  ``int_0^L phi_b^2 dx = L`` (so ``M_b = rho S L``) with ``phi_b(L) > 0``; B2 is
  the second free-free bending mode, antisymmetric about the centre
  (``beta L = 7.853`` without axial force).
* Axial force: ``P >= 0`` is the magnitude of the compressive preload the
  stator carries (as the paper uses it in Eq. 16 and Table 1, ``p(0) = 6 N``).
  Eq. 10-11 are written for a tensile force (docs/explanation/physics.md), so the beam
  sees the tension ``N = -P``; the square brackets of Eq. 10-11 are a square
  root. Free-end conditions from the energy ``1/2 int EI w''^2 + N w'^2``:
  ``w'' = 0`` and ``EI w''' - N w' = 0``.
* Effective bending modulus: the Euler-Bernoulli shape of Eq. 9-11 overestimates
  the B2 frequency of this stubby bar (L/width = 4; shear and rotary inertia,
  which the Timoshenko theory keeps, lower it). We keep the paper's shape
  functions and choose the effective ``E I`` that puts the unloaded B2 mode at
  the specified ``f_b0_Hz``; the axial force then shifts it by Eq. 10-11.
* Position dependence enters through ``P(s) = P0 + k_pre * delta(s)``: the
  friction bar deviates by ``delta(s)`` (a Legendre series in ``s / half length``)
  from the guide line and the preload spring turns that into force; the mean
  normal force is ``F_p = alpha0 P(s)`` (Eq. 16).
* Envelope dynamics: with slowly varying phasors, Eq. 6-7 become
  ``(2 j w M + C) dQ/dt = F - (K - w^2 M + j w C) Q`` whose steady state is
  Eq. 12-13 and whose time constant is ``2 M / C``.
"""

from __future__ import annotations

import cmath
import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numpy.polynomial import legendre

from .jit import cached_kernel
from .params import StatorParams

#: beta*L of the second free-free bending mode without axial force (tan = tanh root)
BETA_L_B2 = 7.853204624095838
ETA_N = 1.0  # |phi_u(L)| = |cos(pi)|

_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)


def _scalars(*xs) -> bool:
    """True when every argument is a plain (or numpy) scalar: the per-step fast paths apply."""
    for x in xs:
        if not isinstance(x, (float, complex, int)):
            return False
    return True


# ---------------------------------------------------------------------------
# L1 mode (Eq. 8)
# ---------------------------------------------------------------------------

def phi_u(x_m, length_m):
    """L1 mode shape ``cos(pi x / L)`` (Eq. 8) [-]."""
    return np.cos(np.pi * np.asarray(x_m, float) / length_m)


def modal_mass_l_kg(sp: StatorParams) -> float:
    """L1 modal mass ``rho S int phi_u^2 = rho S L / 2`` [kg]."""
    return sp.density_kg_m3 * sp.area_m2 * sp.length_m / 2.0


def modal_mass_b_kg(sp: StatorParams) -> float:
    """B2 modal mass ``rho S int phi_b^2 = rho S L`` (normalisation of phi_b) [kg]."""
    return sp.density_kg_m3 * sp.area_m2 * sp.length_m


def l1_frequency_Hz(sp: StatorParams, T_degC=None):
    """L1 natural frequency without contact, with optional linear thermal drift [Hz]."""
    dT = 0.0 if T_degC is None else np.asarray(T_degC, float) - sp.T_ref_degC
    return sp.f_l0_Hz + sp.df_dT_l_Hz_per_K * dT


# ---------------------------------------------------------------------------
# B2 mode with axial force (Eq. 9-11)
# ---------------------------------------------------------------------------

def effective_EI_N_m2(sp: StatorParams, T_degC=None):
    """Bending stiffness that places the unloaded Euler-Bernoulli B2 mode at ``f_b0_Hz`` [N m^2].

    With thermal drift enabled, the unloaded B2 frequency moves by
    ``df_dT_b_Hz_per_K`` per kelvin, i.e. the effective modulus softens.
    """
    f0 = sp.f_b0_Hz
    if T_degC is not None:
        f0 = f0 + sp.df_dT_b_Hz_per_K * (np.asarray(T_degC, float) - sp.T_ref_degC)
    w = 2 * np.pi * np.asarray(f0, float)
    return (w * sp.length_m ** 2 / BETA_L_B2 ** 2) ** 2 * sp.density_kg_m3 * sp.area_m2


def wavenumbers(N_tension_N, omega_rad_s, EI_N_m2, rhoS_kg_m):
    """Eq. 10-11: ``beta1, beta2`` [1/m] for tension ``N`` at angular frequency ``omega``.

    ``beta^2 = sqrt((N/2EI)^2 + rho S w^2 / EI) -/+ N/(2EI)``.
    """
    N = np.asarray(N_tension_N, float)
    h = N / (2.0 * EI_N_m2)
    root = np.sqrt(h * h + rhoS_kg_m * np.asarray(omega_rad_s, float) ** 2 / EI_N_m2)
    return np.sqrt(root - h), np.sqrt(root + h)


def _b2_characteristic(omega, N, EI, rhoS, half):
    """Frequency function of the antisymmetric free-free mode, scaled to O(1)."""
    b1, b2 = wavenumbers(N, omega, EI, rhoS)
    return (-b1 * np.sin(b1 * half) * (EI * b2 ** 2 - N)
            + b2 * np.tanh(b2 * half) * np.cos(b1 * half) * (EI * b1 ** 2 + N)) / (EI * b1 ** 3)


@lru_cache(maxsize=1)
def _phi_slope_ratio() -> float:
    """``L^2 int phi'^2 / int phi^2`` of the unloaded free-free B2 mode (dimensionless)."""
    bh = BETA_L_B2 / 2.0
    xi = _GL_X  # xi in [-1, 1] = x / half
    E = np.sin(bh) / np.sinh(bh)
    phi = np.sin(bh * xi) + E * np.sinh(bh * xi)
    dphi = bh * (np.cos(bh * xi) + E * np.cosh(bh * xi))  # d/dxi
    # d/dx = d/dxi / half, L = 2 half  => L^2 (dphi/dx)^2 = 4 (dphi/dxi)^2
    return float(4 * np.sum(_GL_W * dphi ** 2) / np.sum(_GL_W * phi ** 2))


def b2_frequency_rad_s(sp: StatorParams, P_N, T_degC=None):
    """Natural angular frequency of B2 under the compressive axial force ``P_N`` [rad/s].

    Exact root of the free-free frequency equation of the antisymmetric mode
    with the tension ``N = -P``, by secant iteration from the Rayleigh
    estimate ``w^2 = w0^2 + N int phi'^2 / (rho S int phi^2)``.
    """
    N = -np.asarray(P_N, float)
    EI = effective_EI_N_m2(sp, T_degC)
    rhoS = sp.density_kg_m3 * sp.area_m2
    half = sp.length_m / 2.0
    w0 = BETA_L_B2 ** 2 / sp.length_m ** 2 * np.sqrt(EI / rhoS)
    wa = np.sqrt(np.maximum(w0 ** 2 + N * _phi_slope_ratio() / sp.length_m ** 2 / rhoS, 1e-6 * w0 ** 2))
    w_rayleigh = wa
    wb = wa * (1 + 1e-7)
    fa = _b2_characteristic(wa, N, EI, rhoS, half)
    fb = _b2_characteristic(wb, N, EI, rhoS, half)
    with np.errstate(all="ignore"):
        for _ in range(8):
            moved = fb != fa
            wc = np.where(moved, wb - fb * (wb - wa) / np.where(moved, fb - fa, 1.0), wb)
            wa, fa = wb, fb
            wb, fb = wc, _b2_characteristic(wc, N, EI, rhoS, half)
    ok = np.isfinite(wb) & (wb > 0) & (np.abs(fb) < 1e-9) & (np.abs(wb / w_rayleigh - 1) < 0.5)
    if np.all(ok):
        return wb
    # Safeguarded fallback (large axial forces): bracket the root nearest the Rayleigh estimate
    wb = np.array(wb, dtype=float, copy=True)
    shape = wb.shape
    wb, w_r = wb.reshape(-1), np.broadcast_to(w_rayleigh, shape).reshape(-1)
    Nf, EIf = np.broadcast_to(N, shape).reshape(-1), np.broadcast_to(EI, shape).reshape(-1)
    w0f = np.broadcast_to(w0, shape).reshape(-1)
    for i in np.flatnonzero(~np.broadcast_to(ok, shape).reshape(-1)):
        wb[i] = _b2_root_bracketed(w_r[i], w0f[i], Nf[i], EIf[i], rhoS, half)
    return wb.reshape(shape)


def _b2_root_bracketed(w_guess, w0, N, EI, rhoS, half) -> float:
    """Root of the B2 frequency equation in ``(0, 2 w0]`` nearest ``w_guess`` (scan + Brent).

    Below ``2 w0`` the antisymmetric family has only the B2 root (the next,
    B4, lies at 3.2 w0) besides, under tension, the stiffened rigid rotation;
    the root nearest the Rayleigh estimate is B2. NaN when there is none
    (beyond the buckling load).
    """
    from scipy.optimize import brentq
    f = lambda w: float(_b2_characteristic(w, N, EI, rhoS, half))  # noqa: E731
    grid = w0 * np.geomspace(1e-3, 2.0, 400)
    with np.errstate(all="ignore"):
        vals = np.array([f(w) for w in grid])
    sign_change = np.flatnonzero(np.isfinite(vals[:-1]) & np.isfinite(vals[1:]) & (vals[:-1] * vals[1:] < 0))
    if sign_change.size == 0:
        return float("nan")
    j = sign_change[np.argmin(np.abs(np.log(grid[sign_change] / w_guess)))]
    return float(brentq(f, grid[j], grid[j + 1], xtol=1e-12 * grid[j], rtol=1e-14))


class B2Shape(NamedTuple):
    """Coefficients of Eq. 9, ``phi_b = C cos b1 x + D sin b1 x + E sinh b2 x + F cosh b2 x`` (x from 0)."""

    C: np.ndarray
    D: np.ndarray
    E: np.ndarray
    F: np.ndarray
    beta1_per_m: np.ndarray
    beta2_per_m: np.ndarray
    omega_rad_s: np.ndarray


def b2_mode_shape(sp: StatorParams, P_N, T_degC=None) -> B2Shape:
    """Normalised B2 mode shape under the compressive axial force ``P_N`` (Eq. 9-11).

    Normalisation ``int_0^L phi_b^2 dx = L`` (64-point Gauss-Legendre), sign
    ``phi_b(L) > 0``. Vectorised over ``P_N`` (and ``T_degC``).
    """
    omega = b2_frequency_rad_s(sp, P_N, T_degC)
    N = -np.asarray(P_N, float)
    EI = effective_EI_N_m2(sp, T_degC)
    rhoS = sp.density_kg_m3 * sp.area_m2
    half = sp.length_m / 2.0
    b1, b2 = wavenumbers(N, omega, EI, rhoS)
    # centred form phi = sin(b1 xi) + Ec sinh(b2 xi), xi = x - L/2, from w''(L/2) = 0
    Ec = b1 ** 2 * np.sin(b1 * half) / (b2 ** 2 * np.sinh(b2 * half))
    xi = np.multiply.outer(_GL_X * half, np.ones_like(b1))  # (64, *shape)
    phi = np.sin(b1 * xi) + Ec * np.sinh(b2 * xi)
    norm2 = np.tensordot(_GL_W, phi ** 2, axes=1) * half
    tip = np.sin(b1 * half) + Ec * np.sinh(b2 * half)
    Dc = np.sign(tip) * np.sqrt(sp.length_m / norm2)
    Ec = Ec * Dc
    # shift to x from 0: sin(b1 (x - h)) = sin b1x cos b1h - cos b1x sin b1h, likewise sinh
    return B2Shape(
        C=-Dc * np.sin(b1 * half), D=Dc * np.cos(b1 * half),
        E=Ec * np.cosh(b2 * half), F=-Ec * np.sinh(b2 * half),
        beta1_per_m=b1, beta2_per_m=b2, omega_rad_s=omega,
    )


def phi_b(shape: B2Shape, x_m, deriv: int = 0):
    """Evaluate the B2 mode shape (or its ``deriv``-th derivative, 0-3) at ``x_m``."""
    x = np.asarray(x_m, float)
    b1, b2 = shape.beta1_per_m, shape.beta2_per_m
    c, s = np.cos(b1 * x), np.sin(b1 * x)
    sh, ch = np.sinh(b2 * x), np.cosh(b2 * x)
    # derivatives cycle: cos -> -sin -> -cos -> sin ; sin -> cos -> -sin -> -cos
    trig_c = [c, -s, -c, s][deriv] * b1 ** deriv
    trig_s = [s, c, -s, -c][deriv] * b1 ** deriv
    hyp_s = [sh, ch, sh, ch][deriv] * b2 ** deriv
    hyp_c = [ch, sh, ch, sh][deriv] * b2 ** deriv
    return shape.C * trig_c + shape.D * trig_s + shape.E * hyp_s + shape.F * hyp_c


# ---------------------------------------------------------------------------
# Position-dependent axial force (Eq. 16, 31)
# ---------------------------------------------------------------------------

def bar_deviation_m(sp: StatorParams, s_m):
    """Deviation of the friction bar from the guide line at slider position ``s_m`` [m].

    A smooth Legendre series in ``s / half length`` (tilt, bow, waviness of
    third order), plus two non-uniformities that are off in the reference
    motor: a periodic waviness ``A sin(2 pi s / lambda)`` (grinding marks) and a
    local Gaussian bump (a defect or debris).
    """
    if isinstance(s_m, float):  # scalar fast path: the same series in plain floats
        return bar_deviation_scalar(s_m, *bar_arguments(sp))
    s = np.asarray(s_m, float)
    xi = s / sp.bar_half_length_m
    dev = legendre.legval(xi, [0.0, sp.bar_dev_1_m, sp.bar_dev_2_m, sp.bar_dev_3_m])
    if sp.bar_wave_amp_m:
        dev = dev + sp.bar_wave_amp_m * np.sin(2 * np.pi * s / sp.bar_wave_period_m)
    if sp.bar_bump_amp_m:
        dev = dev + sp.bar_bump_amp_m * np.exp(-0.5 * ((s - sp.bar_bump_center_m) / sp.bar_bump_width_m) ** 2)
    return dev


def bar_arguments(sp: StatorParams) -> tuple:
    """The parameter arguments of :func:`bar_deviation_scalar`, after the position."""
    return (sp.bar_half_length_m, sp.bar_dev_1_m, sp.bar_dev_2_m, sp.bar_dev_3_m, sp.bar_wave_amp_m,
            sp.bar_wave_period_m, sp.bar_bump_amp_m, sp.bar_bump_center_m, sp.bar_bump_width_m)


def bar_deviation_scalar(s, half, dev_1, dev_2, dev_3, wave_amp, wave_period, bump_amp, bump_center, bump_width):
    """:func:`bar_deviation_m` at one position ``s`` [m], plain floats (numba compiles it) [m].

    ``half``: half length of the bar [m]; ``dev_1..3``: Legendre coefficients [m];
    the periodic waviness (amplitude, period) and the Gaussian bump (amplitude,
    centre, width) [m], each skipped when its amplitude is zero.
    """
    xi = s / half
    dev = xi * (dev_1 + dev_3 * (2.5 * xi * xi - 1.5)) + dev_2 * (1.5 * xi * xi - 0.5)
    if wave_amp != 0.0:
        dev += wave_amp * math.sin(2 * math.pi * s / wave_period)
    if bump_amp != 0.0:
        z = (s - bump_center) / bump_width
        dev += bump_amp * math.exp(-0.5 * (z * z))
    return dev


def stator_temperature_step(T_st_degC, T_amb_degC, V0_V, sp: StatorParams, h_s):
    """Exact step of the stator's thermal state [degC] (off when ``thermal_tau_s = 0``).

    ``tau dT/dt = T_amb + k V0^2 - T``: self-heating by dielectric and
    mechanical losses, both proportional to the vibration power ~ V0^2,
    relaxed toward the ambient temperature with time constant ``tau``.
    """
    if _scalars(T_st_degC, T_amb_degC, V0_V, h_s):
        return temperature_step_scalar(float(T_st_degC), float(T_amb_degC), float(V0_V), sp.thermal_tau_s,
                                       sp.heating_K_per_V2, float(h_s))
    target = np.asarray(T_amb_degC, float) + sp.heating_K_per_V2 * np.asarray(V0_V, float) ** 2
    if sp.thermal_tau_s <= 0:
        return target if sp.heating_K_per_V2 else np.asarray(T_amb_degC, float)
    return target + (np.asarray(T_st_degC, float) - target) * np.exp(-h_s / sp.thermal_tau_s)


def temperature_step_scalar(T_st, T_amb, V0, tau, heating, h):
    """:func:`stator_temperature_step` in plain floats (numba compiles it) [degC].

    ``tau`` thermal time constant [s] (``<= 0``: no thermal lag), ``heating``
    self-heating coefficient [K/V^2], ``h`` step [s].
    """
    target = T_amb + heating * (V0 * V0)  # products, not ** 2: numba's x ** 2 is x * x, Python's is pow()
    if tau <= 0:
        return target if heating != 0.0 else T_amb
    return target + (T_st - target) * math.exp(-h / tau)


def axial_force_N(sp: StatorParams, s_m):
    """Nominal compressive axial force ``P(s) = P0 + k_pre delta(s)`` (>= 0) [N]."""
    if isinstance(s_m, float):
        return max(sp.P0_N + sp.preload_stiffness_N_per_m * bar_deviation_m(sp, s_m), 0.0)
    return np.maximum(sp.P0_N + sp.preload_stiffness_N_per_m * bar_deviation_m(sp, s_m), 0.0)


def preload_N(sp: StatorParams, s_m):
    """Static axial (mean normal) force ``F_p = alpha0 P(s)``, Eq. 16 [N]."""
    return sp.alpha0 * axial_force_N(sp, s_m)


# ---------------------------------------------------------------------------
# Modal responses (Eq. 12-14)
# ---------------------------------------------------------------------------

class ModalProperties(NamedTuple):
    M_l: float
    K_l: np.ndarray
    C_l: np.ndarray
    M_b: float
    K_b: np.ndarray
    C_b: np.ndarray
    eta_T: np.ndarray
    omega_l0: np.ndarray
    omega_b0: np.ndarray


def modal_properties(sp: StatorParams, P_N, T_degC=None) -> ModalProperties:
    """Mass, stiffness, damping of both modes and the tip coefficient, at axial force ``P_N``.

    Damping ``C = 2 zeta M omega0`` (paper's ``zeta = C / (2 M omega0)``).
    Scalar ``P_N`` and ``T_degC`` take a plain-float fast path (floats out).
    """
    if isinstance(P_N, (float, int)) and (T_degC is None or isinstance(T_degC, (float, int))):
        fast = _modal_properties_scalar(sp, float(P_N), T_degC)
        if fast is not None:
            return fast
    M_l, M_b = modal_mass_l_kg(sp), modal_mass_b_kg(sp)
    w_l0 = 2 * np.pi * np.asarray(l1_frequency_Hz(sp, T_degC), float)
    shape = b2_mode_shape(sp, P_N, T_degC)
    w_b0 = shape.omega_rad_s
    eta_T = np.abs(phi_b(shape, sp.length_m))
    return ModalProperties(
        M_l=M_l, K_l=M_l * w_l0 ** 2, C_l=2 * sp.zeta_l * M_l * w_l0,
        M_b=M_b, K_b=M_b * w_b0 ** 2, C_b=2 * sp.zeta_b * M_b * w_b0,
        eta_T=eta_T, omega_l0=w_l0, omega_b0=w_b0,
    )


def _modal_properties_scalar(sp: StatorParams, P: float, T_degC) -> ModalProperties | None:
    """Scalar fast path of :func:`modal_properties` (the co-simulation's per-step call), plain floats.

    Same secant iteration for the B2 frequency as :func:`b2_frequency_rad_s`; the
    normalisation integral of the centred mode shape in closed form instead of
    Gauss-Legendre (both exact to round-off). ``None`` when the secant
    iteration fails its checks: the caller then takes the safeguarded vector path.
    """
    dT = 0.0 if T_degC is None else float(T_degC) - sp.T_ref_degC
    rhoS = sp.density_kg_m3 * sp.area_m2
    L, half = sp.length_m, sp.length_m / 2.0
    EI = (2 * math.pi * (sp.f_b0_Hz + sp.df_dT_b_Hz_per_K * dT) * L ** 2 / BETA_L_B2 ** 2) ** 2 * rhoS
    N = -P

    def wavenumbers_(w):
        h = N / (2.0 * EI)
        root = math.sqrt(h * h + rhoS * w * w / EI)
        return math.sqrt(root - h), math.sqrt(root + h)

    def characteristic(w):
        b1, b2 = wavenumbers_(w)
        return (-b1 * math.sin(b1 * half) * (EI * b2 ** 2 - N)
                + b2 * math.tanh(b2 * half) * math.cos(b1 * half) * (EI * b1 ** 2 + N)) / (EI * b1 ** 3)

    try:
        w0 = BETA_L_B2 ** 2 / L ** 2 * math.sqrt(EI / rhoS)
        wa = math.sqrt(max(w0 ** 2 + N * _phi_slope_ratio() / L ** 2 / rhoS, 1e-6 * w0 ** 2))
        w_rayleigh, wb = wa, wa * (1 + 1e-7)
        fa, fb = characteristic(wa), characteristic(wb)
        for _ in range(8):
            wc = wb - fb * (wb - wa) / (fb - fa) if fb != fa else wb
            if wc == wb:  # converged: the remaining iterations would not move it
                break
            wa, fa = wb, fb
            wb, fb = wc, characteristic(wc)
        if not (math.isfinite(wb) and wb > 0 and abs(fb) < 1e-9 and abs(wb / w_rayleigh - 1) < 0.5):
            return None
        b1, b2 = wavenumbers_(wb)
        # phi = sin(b1 xi) + Ec sinh(b2 xi) on [-half, half]; int phi^2 in closed form
        s1, sh2 = math.sin(b1 * half), math.sinh(b2 * half)
        Ec = b1 ** 2 * s1 / (b2 ** 2 * sh2)
        i_ss = half - math.sin(2 * b1 * half) / (2 * b1)
        i_hh = math.sinh(2 * b2 * half) / (2 * b2) - half
        i_sh = 2 * (b2 * s1 * math.cosh(b2 * half) - b1 * math.cos(b1 * half) * sh2) / (b1 * b1 + b2 * b2)
        norm2 = i_ss + 2 * Ec * i_sh + Ec * Ec * i_hh
        eta_T = abs(s1 + Ec * sh2) * math.sqrt(L / norm2)
    except (ValueError, ZeroDivisionError, OverflowError):
        return None
    M_l, M_b = modal_mass_l_kg(sp), modal_mass_b_kg(sp)
    w_l0 = l1_omega_scalar(sp.f_l0_Hz, sp.df_dT_l_Hz_per_K, dT)
    return ModalProperties(
        M_l=M_l, K_l=M_l * w_l0 ** 2, C_l=2 * sp.zeta_l * M_l * w_l0,
        M_b=M_b, K_b=M_b * wb ** 2, C_b=2 * sp.zeta_b * M_b * wb,
        eta_T=eta_T, omega_l0=w_l0, omega_b0=wb,
    )


#: width [N] and polynomial degree of the cells of :class:`ModalTable` (interpolation error at
#: round-off, ~1e-15 relative, over 0-60 N of the reference motor: tests/test_stator.py)
TABLE_CELL_N = 1.0
TABLE_DEGREE = 9


class ModalTable:
    """:func:`modal_properties` at a fixed B2 temperature, by piecewise polynomial interpolation in ``P``.

    The co-simulation needs the modal properties every step at a slowly moving
    axial force ``P(s)``. The B2 frequency and tip coefficient are smooth in
    ``P``: the table cuts the force axis into cells of :data:`TABLE_CELL_N`
    newtons, built when first visited from exact evaluations at the
    :data:`TABLE_DEGREE` + 1 Chebyshev-Lobatto nodes of the cell, and returns
    the interpolant (Horner in the cell's scaled coordinate), equal to the
    exact values to round-off. A cell with a failed node (beyond buckling) is
    not tabulated: :func:`modal_properties` is called instead. ``T_b_degC`` is
    the temperature the B2 properties are taken at (``None`` when the B2 mode
    has no thermal drift); the L1 properties follow the ``T`` of each call.
    """

    def __init__(self, sp: StatorParams, T_b_degC=None):
        self.sp, self.T_b = sp, T_b_degC
        self.cells: dict[int, tuple | None] = {}
        self._arrays: dict[int, np.ndarray | None] = {}  # cells as arrays, for compiled code
        self.M_l, self.M_b = modal_mass_l_kg(sp), modal_mass_b_kg(sp)
        self._l1_T: object = object()  # temperature of the cached L1 properties
        self._l1 = (0.0, 0.0, 0.0)

    def _build(self, k: int):
        deg, w = TABLE_DEGREE, TABLE_CELL_N
        x, to_power = _lobatto_interpolation()
        nodes = k * w + 0.5 * (x + 1.0) * w
        try:  # the scalar path: the values the per-step calls had before the table
            props = [modal_properties(self.sp, float(P), self.T_b) for P in nodes]
            wb = np.array([float(p.omega_b0) for p in props])
            eta = np.array([float(p.eta_T) for p in props])
        except (ValueError, FloatingPointError):
            wb = eta = np.full(deg + 1, np.nan)
        cell = None
        if np.all(np.isfinite(wb)) and np.all(np.isfinite(eta)) and k * w >= 0.0:
            cw, ce = _power_coefficients(to_power, wb), _power_coefficients(to_power, eta)
            cell = (cw[0], ce[0], tuple(zip(cw[1:], ce[1:])))  # leading coefficients, then pairs for Horner
        self.cells[k] = cell
        return cell

    def __call__(self, P: float, T_degC=None) -> ModalProperties:
        w = TABLE_CELL_N
        k = math.floor(P / w)
        cell = self.cells[k] if k in self.cells else self._build(k)
        sp = self.sp
        if cell is None:  # B2 at T_b: T_degC == T_b, or B2 does not depend on the temperature
            return modal_properties(sp, float(P), T_degC)
        u = 2.0 * (P - k * w) / w - 1.0
        wb, eta, pairs = cell
        for cw, ce in pairs:  # both interpolants by Horner's scheme
            wb = wb * u + cw
            eta = eta * u + ce
        K_l, C_l, w_l0 = self._l1 if T_degC == self._l1_T else self._l1_props(T_degC)
        M_b = self.M_b
        K_b, C_b = stiffness_damping(M_b, wb, sp.zeta_b)
        return ModalProperties(M_l=self.M_l, K_l=K_l, C_l=C_l, M_b=M_b, K_b=K_b, C_b=C_b, eta_T=abs(eta),
                               omega_l0=w_l0, omega_b0=wb)

    def cell_array(self, k: int):
        """Coefficients of cell ``k`` as a ``(TABLE_DEGREE + 1, 2)`` array (B2 frequency [rad/s], tip
        coefficient), highest power first, for compiled code (:func:`table_lookup`); None when the cell is
        not tabulated."""
        arrays = self._arrays
        if k not in arrays:
            cell = self.cells[k] if k in self.cells else self._build(k)
            arrays[k] = None if cell is None else np.array([(cell[0], cell[1])] + list(cell[2]), float)
        return arrays[k]

    def _l1_props(self, T_degC):
        if T_degC != self._l1_T:
            sp = self.sp
            dT = 0.0 if T_degC is None else float(T_degC) - sp.T_ref_degC
            w_l0 = l1_omega_scalar(sp.f_l0_Hz, sp.df_dT_l_Hz_per_K, dT)
            self._l1_T, self._l1 = T_degC, (*stiffness_damping(self.M_l, w_l0, sp.zeta_l), w_l0)
        return self._l1


def l1_omega_scalar(f_l0, df_dT, dT):
    """L1 natural angular frequency without contact [rad/s]: :func:`l1_frequency_Hz` in plain floats
    (``f_l0`` [Hz], ``df_dT`` [Hz/K], ``dT`` temperature above the reference [K]; numba compiles it: the
    modal properties, the modal table and the fused coupled step share it)."""
    return 2 * math.pi * (f_l0 + df_dT * dT)


def stiffness_damping(M, omega0, zeta):
    """Modal stiffness ``K = M omega0^2`` [N/m] and damping ``C = 2 zeta M omega0`` [N s/m] of mass ``M`` [kg]
    at natural frequency ``omega0`` [rad/s] (plain floats; numba compiles it: the modal table and the fused
    coupled step share it). Written with products, not ``** 2``: numba computes ``x ** 2`` as ``x * x``,
    CPython with ``pow()``, which differ by one ulp in about 1 of 1400 squares."""
    return M * (omega0 * omega0), 2 * zeta * M * omega0


def table_lookup(cell, P):
    """B2 frequency [rad/s] and tip coefficient (signed) at axial force ``P`` [N] from the coefficients of
    the table cell holding ``P`` (:meth:`ModalTable.cell_array`): the interpolants of
    :meth:`ModalTable.__call__`, same operations (numba compiles it)."""
    k = math.floor(P / TABLE_CELL_N)
    u = 2.0 * (P - k * TABLE_CELL_N) / TABLE_CELL_N - 1.0
    wb = cell[0, 0]
    eta = cell[0, 1]
    for i in range(1, cell.shape[0]):
        wb = wb * u + cell[i, 0]
        eta = eta * u + cell[i, 1]
    return wb, eta


@lru_cache(maxsize=1)
def _lobatto_interpolation():
    """Chebyshev-Lobatto nodes on [-1, 1] and the matrix from values there to the interpolant's
    power-series coefficients, highest power first (for Horner's scheme)."""
    deg = TABLE_DEGREE
    cheb = np.polynomial.chebyshev
    x = np.cos(np.pi * np.arange(deg + 1) / deg)
    to_cheb = cheb.chebfit(x, np.eye(deg + 1), deg)  # column j: coefficients of the j-th node's cardinal
    to_power = np.column_stack([cheb.cheb2poly(to_cheb[:, j]) for j in range(deg + 1)])
    return x, to_power[::-1].copy()


def table_interpolation() -> tuple:
    """The Chebyshev-Lobatto nodes on [-1, 1] of a :class:`ModalTable` cell and the matrix from node values to
    the interpolant's power coefficients, highest first (the native motor FMU builds cells with them)."""
    return _lobatto_interpolation()


def b2_slope_ratio() -> float:
    """``L^2 int phi'^2 / int phi^2`` of the unloaded B2 mode, the constant of the Rayleigh start of
    :func:`b2_frequency_rad_s` [1]."""
    return _phi_slope_ratio()


def _power_coefficients(to_power, values) -> tuple:
    """Interpolant's power coefficients from node values; the mean is taken out first, so that the
    matrix's large entries act only on the small variation over the cell (no cancellation)."""
    mean = float(np.mean(values))
    coef = to_power @ (values - mean)
    coef[-1] += mean
    return tuple(coef.tolist())


_TABLES: dict = {}


def modal_table(sp: StatorParams, T_degC=None) -> ModalTable:
    """The shared :class:`ModalTable` of ``sp`` for B2 at ``T_degC`` (any ``T`` when B2 has no thermal drift).

    Tables are shared by every stator with the same parameters in the process
    (runs of an experiment reuse the cells they visited); at most 32 are kept.
    """
    key = (sp, T_degC if sp.df_dT_b_Hz_per_K != 0.0 else None)
    table = _TABLES.get(key)
    if table is None:
        if len(_TABLES) >= 32:
            _TABLES.pop(next(iter(_TABLES)))
        table = _TABLES[key] = ModalTable(sp, key[1])
    return table


def dynamic_stiffness(omega_rad_s, M, K, C):
    """``Z = K - w^2 M + j w C`` so that the steady phasor is ``Q = F / Z`` [N/m]."""
    w = np.asarray(omega_rad_s, float)
    return K - w * w * M + 1j * w * C


def steady_amplitude(F_amp_N, eta, omega_rad_s, K, omega0_rad_s, zeta):
    """Eq. 12-13: ``U = F |phi(L)| / (K sqrt((1 - r^2)^2 + (2 zeta r)^2))``, ``r = w / w0`` [m]."""
    r = np.asarray(omega_rad_s, float) / omega0_rad_s
    return np.abs(F_amp_N) * eta / (K * np.sqrt((1 - r * r) ** 2 + (2 * zeta * r) ** 2))


def excitation_phasors(sp: StatorParams, V0_V, direction, voltage_phase_rad=0.0):
    """Electromechanical modal excitations ``(A_l V0, d A_b (1 + d asym) V0)`` as phasors [N]."""
    if _scalars(V0_V, direction, voltage_phase_rad):
        ph = cmath.exp(1j * voltage_phase_rad)
        return (sp.A_l_N_per_V * V0_V * ph,
                direction * sp.A_b_N_per_V * (1.0 + direction * sp.asym_b) * V0_V * ph)
    d = np.asarray(direction, float)
    ph = np.exp(1j * np.asarray(voltage_phase_rad, float))
    V0 = np.asarray(V0_V, float)
    return sp.A_l_N_per_V * V0 * ph, d * sp.A_b_N_per_V * (1.0 + d * sp.asym_b) * V0 * ph


def envelope_derivative(Q, F, omega_rad_s, M, K, C):
    """Slowly varying phasor dynamics: ``dQ/dt = (F - Z Q) / (2 j w M + C)`` [m/s]."""
    Z = dynamic_stiffness(omega_rad_s, M, K, C)
    return (F - Z * Q) / (2j * np.asarray(omega_rad_s, float) * M + C)


def envelope_step(Q, F, Y, omega_rad_s, M, K, C, h_s):
    """Exact step of length ``h_s`` of the envelope ODE with a linear interface load.

    Solves ``(2 j w M + C) dQ/dt = F - (Z + Y) Q`` for constant ``F`` (drive)
    and ``Y`` (interface describing function: generalised interface force
    ``= -Y Q``). Unconditionally stable; exact for constant coefficients.
    """
    if _scalars(Q, F, Y, omega_rad_s, M, K, C, h_s):
        return envelope_step_scalar(Q, F, Y, omega_rad_s, M, K, C, h_s)
    w = np.asarray(omega_rad_s, float)
    Zt = dynamic_stiffness(w, M, K, C) + Y
    lam = -Zt / (2j * w * M + C)
    Qs = F / Zt
    return Qs + (Q - Qs) * np.exp(lam * h_s)


def envelope_step_scalar(Q, F, Y, w, M, K, C, h):
    """:func:`envelope_step` for plain numbers (complex ``Q``, ``F``, ``Y``; numba compiles it)."""
    Zt = K - w * w * M + 1j * w * C + Y
    Qs = F / Zt
    return Qs + (Q - Qs) * cmath.exp(-Zt / (2j * w * M + C) * h)


def envelope_growth_rate_scalar(Y, w, M, K, C):
    """The real part of the envelope's exponent in :func:`envelope_step` with the interface load ``Y`` [1/s]:
    positive when ``Y`` feeds the mode (the step then amplifies ``Q - Q_s`` by ``exp(rate h)``)."""
    Zt = K - w * w * M + 1j * w * C + Y
    return (-Zt / (2j * w * M + C)).real


def tip_motion_scalar(Q_l, Q_b, eta_T):
    """:func:`tip_motion` for complex phasors: ``(U_l, U_w, phase_l, phase_w, delta)`` [m, m, rad, rad, rad]."""
    N, W = ETA_N * Q_l, eta_T * Q_b
    return abs(N), abs(W), cmath.phase(N), cmath.phase(W), cmath.phase(W * N.conjugate())


def coupled_envelope_step(Q_l_re, Q_l_im, Q_b_re, Q_b_im, phase_l, F_N1_sin, F_N1_cos, F_T1_sin, F_T1_cos,
                          F_l_re, F_b_re, eta_T, omega, M_l, K_l, C_l, M_b, K_b, C_b, h, eta_T_new):
    """One step of both modal envelopes with the interface's describing functions, in plain floats.

    The co-simulation's per-step stator update (``StatorBlock.do_step``), in the
    subset of Python that numba compiles (:func:`compiled_envelope_step`):

    * the interface force fundamentals ``F1 = (F1_sin + j F1_cos) e^{j phase_l}``
      rotated from the normal-displacement frame to the absolute phasor frame;
    * describing functions ``Y_l = ETA_N F1_N / Q_l`` and ``Y_b = eta_T F1_T / Q_b``
      (generalised interface force ``-Y Q``, implicit in the step); for a mode at rest
      (``|Q| <= 1e-15`` m), or one that ``Y`` would feed
      (:func:`envelope_growth_rate_scalar` ``> 0``), the force held as an excitation over the step
      instead: a force that does not scale with the amplitude (friction under a pulling load at a
      near-zero amplitude) would otherwise be amplified by ``exp(rate h)``, without bound as
      ``|Q| -> 0``;
    * :func:`envelope_step` for each mode with the real excitation amplitudes
      ``F_l_re``, ``F_b_re`` [N] (:func:`excitation_phasors` at zero voltage phase);
    * :func:`tip_motion` of the new phasors with the tip coefficient ``eta_T_new``
      of the step's end (the axial force may have changed).

    Returns the new ``(Q_l_re, Q_l_im, Q_b_re, Q_b_im)`` [m] and the tip motion
    ``(U_l, U_w, phase_l, phase_w, delta)`` [m, m, rad, rad, rad].
    """
    Q_l = complex(Q_l_re, Q_l_im)
    Q_b = complex(Q_b_re, Q_b_im)
    rot = cmath.exp(1j * phase_l)  # interface frame -> absolute phasor frame
    F1_N = complex(F_N1_sin, F_N1_cos) * rot
    F1_T = complex(F_T1_sin, F_T1_cos) * rot
    F_l = complex(F_l_re, 0.0)
    F_b = complex(F_b_re, 0.0)
    G_l = ETA_N * F1_N  # the generalised interface forces on the modes are -G
    G_b = eta_T * F1_T
    Y_l = complex(0.0, 0.0)
    Y_b = complex(0.0, 0.0)
    if abs(Q_l) > 1e-15:
        Y_l = G_l / Q_l
    if abs(Q_l) <= 1e-15 or envelope_growth_rate_scalar(Y_l, omega, M_l, K_l, C_l) > 0.0:
        Y_l = complex(0.0, 0.0)
        F_l = F_l - G_l
    if abs(Q_b) > 1e-15:
        Y_b = G_b / Q_b
    if abs(Q_b) <= 1e-15 or envelope_growth_rate_scalar(Y_b, omega, M_b, K_b, C_b) > 0.0:
        Y_b = complex(0.0, 0.0)
        F_b = F_b - G_b
    Q_l = envelope_step_scalar(Q_l, F_l, Y_l, omega, M_l, K_l, C_l, h)
    Q_b = envelope_step_scalar(Q_b, F_b, Y_b, omega, M_b, K_b, C_b, h)
    U_l, U_w, ph_l, ph_w, delta = tip_motion_scalar(Q_l, Q_b, eta_T_new)
    return Q_l.real, Q_l.imag, Q_b.real, Q_b.imag, U_l, U_w, ph_l, ph_w, delta


_COMPILED: list = []  # [kernel or None], filled on the first call of compiled_envelope_step()


def kernel_family() -> dict:
    """The stator's plain-float functions that compiled code calls, by name (for
    :func:`l1b2.physics.jit.compile_family`): the envelope step with its helpers, the temperature step,
    the bar deviation and the modal table's interpolant."""
    return {f.__name__: f for f in (envelope_step_scalar, envelope_growth_rate_scalar, tip_motion_scalar,
                                    coupled_envelope_step,
                                    temperature_step_scalar, bar_deviation_scalar, table_lookup, stiffness_damping,
                                    l1_omega_scalar)}


def compiled_envelope_step():
    """:func:`coupled_envelope_step` compiled by numba (once per process), or None (see :mod:`.jit`)."""
    return cached_kernel(_COMPILED, lambda: (  # helpers it does not call are never compiled (numba is lazy)
        kernel_family(), "coupled_envelope_step", "UniTuple(float64, 9)(" + ", ".join(["float64"] * 21) + ")"))


class StatorOutput(NamedTuple):
    U_l_m: np.ndarray        #: tip normal vibration amplitude [m]
    U_w_m: np.ndarray        #: tip tangential vibration amplitude [m]
    phase_l_rad: np.ndarray  #: phase of the tip normal displacement [rad]
    phase_w_rad: np.ndarray  #: phase of the tip tangential displacement [rad]
    delta_rad: np.ndarray    #: phase of tangential minus normal displacement, wrapped to (-pi, pi] [rad]


def tip_motion(Q_l, Q_b, eta_T) -> StatorOutput:
    """Tip amplitudes and phases from the modal phasors."""
    if _scalars(Q_l, Q_b, eta_T):
        return StatorOutput(*tip_motion_scalar(complex(Q_l), complex(Q_b), eta_T))
    N = ETA_N * np.asarray(Q_l)
    W = eta_T * np.asarray(Q_b)
    return StatorOutput(
        U_l_m=np.abs(N), U_w_m=np.abs(W), phase_l_rad=np.angle(N), phase_w_rad=np.angle(W),
        delta_rad=np.angle(W * np.conj(N)) if np.ndim(N) else float(np.angle(W * np.conj(N))),
    )
