"""The pure-slip drive force without Eq. 29's linearisation: the slip ratio follows the state.

Contract
--------
Under the paper's Sect. 4 assumptions (contact angle phi_c = pi, pure slip,
tangential tip velocity ``W sin(omega t)`` with ``W = omega U_w``, a half-sine
normal force whose period mean is the preload F_p) the period-mean drive
force on a slider moving at ``v`` is (:func:`pure_slip_drive_force`)::

    F_d = sigma (W/pi - v/2) + mu F_p g1(k),   g1(k) = 2 sqrt(1 - k^2) - 1,   k = v / W

Eq. 29 freezes ``k`` at the constant ``k0``, so its drive force has one
speed slope at every voltage. Here ``k`` is the slip ratio of the state:
with the tip speed of the open-loop drive (Eq. 25/30 without the interface
feedback, ``sigma W / pi = B'(s) V0``)::

    k = c_k v',   c_k = sigma / (pi B'(s) V0)   [s/m]   (:func:`inverse_tip_speed`)

and the drive force of the predictor keeps Eq. 29's form with ``k0 -> k``::

    X(v') = X_lin + mu P [g1(k) - (pi/2) A' G(k)]          (:func:`slip_force`)

``W`` is the open-loop tip speed: Eq. 25's feedback of the interface on the
tip amplitude is not modelled. It is proportional to V0 (times the position
profile ``pi B'(s)/sigma``),
so the slope ``dX/dv' = mu P [g1'(k) - (pi/2) A' G'(k)] c_k`` shrinks as V0
grows: the V0-dependence of the load slope that Eq. 29 lacks.

Outside the pure-slip range the factors are continued by their physics: for
``k <= 0`` (slider at rest or pushed backwards) the tip is faster than the
slider over the whole contact, ``g1 = 1``, ``G = pi/2``; for ``k >= 1`` (slider
as fast as the tip) the friction always brakes, ``g1 = -1``, ``G = -pi/2``;
both are the values of the closed forms at k = 0 and k = 1, so X is continuous
in v'. The derivatives are 0 outside (0, 1) and the slope near k = 1 is capped
at :data:`K_SLOPE_MAX` (g1' diverges there).

Finite contact (:func:`contact_drive_force`): with a contact of half angle
``a`` centred on the tangential speed's peak (Eq. 17-18: ``F_N = K (sin theta
- cos a)`` inside, period mean ``F_p``, so ``K = pi F_p / rho(a)`` with
``rho(a) = sin a - a cos a``) the same period mean is::

    F_d = sigma (W sin a - a v) / pi + mu F_p h(k, a)
    h(k, a) = 1 - 2 I(k, a) / rho(a),   I = 0 for k <= cos a, else
    I = sin a - sqrt(1 - k^2) - cos a (arcsin k - pi/2 + a)

(the braking edges of the contact, where the tip is slower than the slider);
``a = pi/2`` gives the form above (``rho = 1``, ``h = g1``). A shorter
contact (larger normal amplitude U_l, Eq. 18) brakes only once ``k > cos a``.
This is the contact's dependence on the normal (L1) amplitude that the
predictor's drive force above holds at ``a = pi/2``. With a per-sample
half angle ``a`` (:func:`l1b2.predictor.frequency.contact_angle`, from the
drive frequency and V0) the predictor's force becomes::

    D = c_r + sigma (a/pi - A'),   X_lin = B' V0 sin a - 9.81 m' + extras
    X(v') = X_lin + mu P [h(k, a) - (pi/2) A' G(k)]   (:func:`slip_force` with ``a``)

(``a = pi/2``: the form above exactly; the interface's speed feedback A' G(k)
is kept as it is, the form measured in decision 0034).

All functions are pure and vectorised over arrays (SI units); nothing here
knows a parameter class (:mod:`l1b2.predictor.model` assembles the inputs).
"""

from __future__ import annotations

import numpy as np

from ..physics.jit import cached_kernel
from .kernels import FLAG_REVERSAL, FLAG_STUCK

__all__ = ["K_SLOPE_MAX", "inverse_tip_speed", "slip_ratio", "slip_factors", "slip_force",
           "pure_slip_drive_force", "contact_shape", "contact_slip_factor", "contact_slip_slope", "contact_drive_force",
           "steady_drive_speed", "packed_slip_recursion"]

#: slip ratio above which the slopes g1'(k), G'(k) are held at their value here (they diverge at k = 1)
K_SLOPE_MAX = 0.999


def inverse_tip_speed(sigma, Bp, V0):
    """``c_k = sigma / (pi B' V0)`` [s/m], 1/W of the open-loop tip speed; ``inf`` where B' V0 <= 0."""
    w = np.pi * np.asarray(Bp, float) * np.asarray(V0, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(w > 0, np.asarray(sigma, float) / np.where(w > 0, w, 1.0), np.inf)


def slip_ratio(vp, c_k):
    """``k = c_k v'`` clipped into [0, 1] (v' > 0 with c_k = inf gives 1, v' <= 0 gives 0)."""
    vp = np.asarray(vp, float)
    with np.errstate(invalid="ignore", over="ignore"):
        k = np.where(vp > 0, np.asarray(c_k, float) * vp, 0.0)
    return np.clip(np.nan_to_num(k, nan=0.0, posinf=1.0), 0.0, 1.0)


def slip_factors(k):
    """``g1(k), G(k), g1'(k), G'(k)`` with the continuation outside (0, 1) of the module docstring."""
    k = np.clip(np.asarray(k, float), 0.0, 1.0)
    r = np.sqrt(1.0 - k * k)
    g1 = 2.0 * r - 1.0
    G = 2.0 * k * r - 2.0 * np.arcsin(k) + 0.5 * np.pi
    ks = np.minimum(k, K_SLOPE_MAX)
    rs = np.sqrt(1.0 - ks * ks)
    inside = (k > 0.0) & (k < 1.0)
    dg1 = np.where(inside, -2.0 * ks / rs, 0.0)
    dG = np.where(inside, -4.0 * ks * ks / rs, 0.0)
    return g1, G, dg1, dG


def slip_force(vp, muP, Ap, c_k, a=None):
    """``(mu P [g1(k) - pi/2 A' G(k)], its derivative in v', k)`` at drive speed ``vp`` [N, N s/m, -].

    With ``a`` (half contact angle per row [rad]) ``g1(k)`` is the finite contact's ``h(k, a)``
    (:func:`contact_slip_factor`, slope :func:`contact_slip_slope`); ``a = None`` is ``a = pi/2``.
    """
    k = slip_ratio(vp, c_k)
    g1, G, dg1, dG = slip_factors(k)
    if a is not None:
        g1, dg1 = contact_slip_factor(k, a), contact_slip_slope(k, a)
    muP = np.asarray(muP, float)
    Ap = np.asarray(Ap, float)
    Xs = muP * (g1 - 0.5 * np.pi * Ap * G)
    with np.errstate(invalid="ignore"):
        dX = np.where((k > 0.0) & (k < 1.0), muP * (dg1 - 0.5 * np.pi * Ap * dG) * c_k, 0.0)
    return Xs, dX, k


def pure_slip_drive_force(W, v, F_p, sigma, mu):
    """The closed form of docs/explanation/physics.md, ``sigma (W/pi - v/2) + mu F_p (2 sqrt(1 - k^2) - 1)``, k = v/W in [0, 1]."""
    W = np.asarray(W, float)
    v = np.asarray(v, float)
    g1 = slip_factors(slip_ratio(v, 1.0 / W))[0]
    return sigma * (W / np.pi - 0.5 * v) + mu * np.asarray(F_p, float) * g1


def contact_shape(a):
    """``rho(a) = sin a - a cos a`` [-]: ``pi F_p / (k_e U_l)`` of Eq. 18 for half contact angle ``a`` in (0, pi]."""
    a = np.asarray(a, float)
    return np.sin(a) - a * np.cos(a)


def contact_slip_factor(k, a):
    """``h(k, a)``: the Coulomb share of the drive force (times mu F_p) for half contact angle ``a`` (module docstring).

    ``k`` is clipped into [0, 1] as in :func:`slip_ratio`; ``h(k, pi/2) = g1(k)``, ``h(1, a) = -1``, and
    ``h = 1`` while the whole contact is faster than the slider (``k <= cos a``).
    """
    k = np.clip(np.asarray(k, float), 0.0, 1.0)
    a = np.asarray(a, float)
    c = np.cos(a)
    with np.errstate(invalid="ignore"):
        edge = np.sin(a) - np.sqrt(1.0 - k * k) - c * (np.arcsin(k) - 0.5 * np.pi + a)
    return 1.0 - 2.0 * np.where(k > c, edge, 0.0) / contact_shape(a)


def contact_slip_slope(k, a):
    """``dh/dk = -2 (k - cos a) / (rho(a) sqrt(1 - k^2))`` for ``cos a < k < 1``, else 0 (k capped at :data:`K_SLOPE_MAX`)."""
    k = np.clip(np.asarray(k, float), 0.0, 1.0)
    a = np.asarray(a, float)
    c = np.cos(a)
    ks = np.minimum(k, K_SLOPE_MAX)
    return np.where((k > c) & (k > 0.0) & (k < 1.0), -2.0 * (ks - c) / (np.sqrt(1.0 - ks * ks) * contact_shape(a)), 0.0)


def contact_drive_force(W, v, F_p, sigma, mu, a):
    """``sigma (W sin a - a v)/pi + mu F_p h(v/W, a)`` [N]: pure slip with a contact of half angle ``a`` [rad]."""
    W = np.asarray(W, float)
    v = np.asarray(v, float)
    a = np.asarray(a, float)
    k = slip_ratio(v, 1.0 / W)
    return sigma * (W * np.sin(a) - a * v) / np.pi + mu * np.asarray(F_p, float) * contact_slip_factor(k, a)


def steady_drive_speed(D, X_lin, muP, Ap, c_k, Fr, n_iter: int = 80, contact=None):
    """Steady drive speed v'* of ``-D v' + X_lin + Xs(v') + sign(-v') Fr = 0`` (stuck: 0; D <= 0: NaN).

    Forward branch (v' > 0): the root of the force, bracketed in
    ``[0, v_hi]`` and found by bisection (the force decreases in v' where
    the pure-slip slope is negative, the case of every physical parameter
    set: ``pi A' k < 1``); backward branch (v' < 0): k = 0, the force is
    affine, ``v' = (X(0) + Fr)/D``; stuck when ``|X(0)| <= Fr``. ``contact``: the half contact angle
    (the Coulomb share h(k, a), :func:`slip_force`; D and X_lin carry the rest), None: pi/2.
    """
    D, X_lin, muP, Ap, c_k, Fr = np.broadcast_arrays(*(np.asarray(x, float) for x in (D, X_lin, muP, Ap, c_k, Fr)))
    X0 = X_lin + slip_force(0.0 * D, muP, Ap, c_k, contact)[0]

    def fwd(v):
        return -D * v + X_lin + slip_force(v, muP, Ap, c_k, contact)[0] - Fr

    with np.errstate(divide="ignore", invalid="ignore"):
        span = (np.abs(X_lin) + np.abs(muP) * (1.0 + 0.25 * np.pi ** 2 * np.abs(Ap)) + np.abs(Fr)) / D
        hi = np.where(D > 0, 2.0 * span + 1e-9, 0.0)
    lo = np.zeros_like(hi)
    for _ in range(n_iter):
        mid = 0.5 * (lo + hi)
        pos = fwd(mid) > 0
        lo = np.where(pos, mid, lo)
        hi = np.where(pos, hi, mid)
    with np.errstate(divide="ignore", invalid="ignore"):
        vp = np.where(X0 - Fr > 0, 0.5 * (lo + hi), np.where(X0 + Fr < 0, (X0 + Fr) / D, 0.0))
    return np.where(D > 0, vp, np.nan)


def packed_slip_recursion(offs, na, step, D, X_lin, muP, Ap, c_k, Fr, h, d, v0_sorted, flags=None, compiled=True,
                          a=None):
    """Free run of the pure-slip predictor in the packed time-major layout; returns (v, X, dX/dv').

    Same layout as :func:`l1b2.predictor.simulate.packed_recursion` (``offs``,
    ``na``; runs alive at k + 1 are a prefix of those at k). ``step`` is the
    drive-coordinate Euler step with the rest and reversal rules
    (:func:`l1b2.predictor.model.step_drive`), called with the drive force
    ``X = X_lin + Xs(v'[k])`` of the step's start. With ``compiled`` (default)
    the compiled :func:`slip_run_loop` (the same rules written out, numba)
    runs when numba is available; otherwise, or with ``compiled=False``, the
    numpy loop over ``step``. Returns the speed
    (data convention), the X used at each row and its slope dX/dv'; ``flags``
    (int8) if given receives the step codes of
    :mod:`l1b2.predictor.kernels`. ``a`` (per row, packed) is the half
    contact angle of the finite-contact force (module docstring; ``D`` and
    ``X_lin`` already carry its ``a/pi`` and ``sin a``); None is ``pi/2``.
    """
    n = int(offs[-1]) if len(offs) else 0
    v = np.empty(n)
    X = np.empty(n)
    dX = np.zeros(n)
    kernel = compiled_slip_run() if compiled else None
    if kernel is not None:
        fl = np.zeros(n, dtype=np.int8) if flags is None else flags
        kernel(np.ascontiguousarray(offs, dtype=np.int64), np.ascontiguousarray(na, dtype=np.int64),
               *(np.require(np.broadcast_to(x, (n,)), float, ["C", "W"])
                 for x in (D, X_lin, muP, Ap, c_k, Fr, h, d, 0.5 * np.pi if a is None else a)),
               np.require(v0_sorted, float, ["C", "W"]),
               v, X, dX, fl)
        return v, X, dX
    v[: na[0]] = v0_sorted
    K = len(na)
    for kk in range(K):
        i0 = offs[kk]
        m_all = na[kk]
        sl = slice(i0, i0 + m_all)
        vp = d[sl] * v[sl]
        xs, dxs, _ = slip_force(vp, muP[sl], Ap[sl], c_k[sl], None if a is None else a[sl])
        X[sl] = X_lin[sl] + xs
        dX[sl] = dxs
        if kk == K - 1:
            break
        m = na[kk + 1]
        s2 = slice(i0, i0 + m)
        vp = vp[:m]
        new = step(vp, D[s2], X[s2], Fr[s2], h[s2])
        if flags is not None:
            eul = vp + h[s2] * (-D[s2] * vp + X[s2] + np.sign(-vp) * Fr[s2])
            stuck = np.abs(X[s2]) < Fr[s2]     # the static rule of ``step`` at the X it was given
            cross = (vp != 0) & (vp * eul < 0)
            flags[s2] = np.where(cross & ~stuck, FLAG_REVERSAL, np.where((cross | (vp == 0)) & stuck, FLAG_STUCK, 0))
        v[offs[kk + 1] : offs[kk + 1] + m] = d[s2] * new
    return v, X, dX


def slip_run_loop(offs, na, D, X_lin, muP, Ap, c_k, Fr, h, d, a, v0_sorted, v, X, dX, flags):
    """:func:`packed_slip_recursion` as a scalar loop (the same rules; compiled by numba, see :func:`compiled_slip_run`).

    The step is :func:`l1b2.predictor.model.step_drive` written out for one
    row; the flags are those of :func:`packed_slip_recursion`. A row whose
    half contact angle ``a`` is exactly pi/2 takes g1(k) itself, any other
    h(k, a) of :func:`contact_slip_factor`.
    """
    half_pi = 0.5 * np.pi
    for i in range(na[0]):
        v[i] = v0_sorted[i]
    K = na.size
    for kk in range(K):
        i0 = offs[kk]
        m_next = na[kk + 1] if kk + 1 < K else 0
        for i in range(na[kk]):
            j = i0 + i
            vp = d[j] * v[j]
            k = 0.0
            if vp > 0.0:
                k = min(c_k[j] * vp, 1.0)
            r = np.sqrt(1.0 - k * k)
            aj = a[j]
            full = aj == half_pi
            ca = np.cos(aj)
            rho = np.sin(aj) - aj * ca
            hk = 2.0 * r - 1.0
            if not full:
                hk = 1.0
                if k > ca:
                    hk = 1.0 - 2.0 * (np.sin(aj) - r - ca * (np.arcsin(k) - half_pi + aj)) / rho
            xs = muP[j] * (hk - half_pi * Ap[j] * (2.0 * k * r - 2.0 * np.arcsin(k) + half_pi))
            x = X_lin[j] + xs
            X[j] = x
            slope = 0.0
            if 0.0 < k < 1.0:
                ks = min(k, K_SLOPE_MAX)
                rs = np.sqrt(1.0 - ks * ks)
                dh = -2.0 * ks / rs
                if not full:
                    dh = -2.0 * (ks - ca) / (rs * rho) if k > ca else 0.0
                slope = muP[j] * (dh + half_pi * Ap[j] * 4.0 * ks * ks / rs) * c_k[j]
            dX[j] = slope
            if i >= m_next:
                continue
            fr = Fr[j]
            if fr > 0.0:
                z0 = -min(max(x / fr, -1.0), 1.0)
            else:
                z0 = -1.0 if x > 0.0 else (1.0 if x < 0.0 else 0.0)
            stuck = abs(z0) < 1.0
            sg = -1.0 if vp > 0.0 else (1.0 if vp < 0.0 else z0)
            new = vp + h[j] * (-D[j] * vp + x + sg * fr)
            if vp == 0.0 and stuck:
                new = 0.0
            if vp * new < 0.0:
                frac = vp / (vp - new)
                from_rest = 0.0 if stuck else h[j] * (x + z0 * fr)
                new = (1.0 - frac) * from_rest
            sgm = -1.0 if vp > 0.0 else (1.0 if vp < 0.0 else 0.0)
            eul = vp + h[j] * (-D[j] * vp + x + sgm * fr)
            st2 = abs(x) < fr
            cross = vp != 0.0 and vp * eul < 0.0
            if cross and not st2:
                flags[j] = FLAG_REVERSAL
            elif (cross or vp == 0.0) and st2:
                flags[j] = FLAG_STUCK
            else:
                flags[j] = 0
            v[offs[kk + 1] + i] = d[j] * new


_SLIP_RUN: list = []


def compiled_slip_run():
    """:func:`slip_run_loop` compiled by numba (once per process, cached on disk), or None without numba."""
    return cached_kernel(_SLIP_RUN, lambda: (
        {"slip_run_loop": slip_run_loop}, "slip_run_loop",
        "void(int64[::1], int64[::1], " + ", ".join(["float64[::1]"] * 13) + ", int8[::1])"))
