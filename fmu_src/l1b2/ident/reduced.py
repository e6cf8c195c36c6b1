"""Data-driven starts: reduced linear and equation-error fits, and the theta <-> reduced mapping.

For v' > 0 (drive coordinates) the force of Eq. 29 is

    F = -D(s) v' + B'(s) V0 + C(s) - 9.81 m_load'        [N]

with ``D = c_r + sigma (0.5 - A')`` [N s/m] and ``C = mu P (g1 - pi/2 A' G)
- mu_sd (9.81 m_s + kappa P)`` [N]. Its one-step equation error is *linear*
in the Legendre coefficients of D, B' [N/V], C (C has order 2n). Summed over
short windows (``m_eff dv' + 9.81 m' dt = sum dt (-D v' + B' V0 + C)``,
~10 ms, which averages speed noise), one linear least-squares gives D(s),
B'(s), C(s) (:func:`reduced_linear_fit`; extra-force parameters phi enter
linearly too). :func:`reduced_of_theta` maps theta to these reduced
coefficients (with its Jacobian).

They are mapped to Eq. 35 parameters with conventional values for the
directions the data cannot determine (:func:`map_reduced_to_theta`: sigma
from the spread of D, k0 = 0.5, mu = 0.2, mu_sd = 0.05 (:data:`CONVENTIONAL`),
or the user's ``fixed`` values), then the Eq. 35 structure is fitted to the
same window equation error by variable projection (c_r, beta, p are linear)
from many scrambled Sobol starts (:func:`equation_error_fit`). The distinct
minima of this cheap problem seed the global search (:mod:`l1b2.ident.search`).
:func:`data_driven_start` runs the chain; :func:`init_theta` takes a user's
warm start instead.
"""

from __future__ import annotations

import math
import warnings
from itertools import zip_longest

import numpy as np
import numpy.polynomial.legendre as npleg
from numpy.polynomial.legendre import legvander
from scipy.optimize import least_squares

from ..errors import IdentificationError
from ..predictor.model import (
    G_of_k0,
    PredictorParams,
    ddrive_factor_dk0,
    dG_dk0,
    drive_factor,
)
from ..units import G_M_S2
from .problem import SampleData, clip_theta, param_scale, strictly_inside
from .search import sobol_box

__all__ = [
    "CONVENTIONAL", "reduced_linear_fit", "reduced_of_theta", "reduced_linear_columns", "map_reduced_to_theta",
    "equation_error_fit",
    "data_driven_start", "slip_sigma_start", "reduced_summary", "init_theta",
]

#: conventional values for the directions the data cannot determine (the pin
#: when such a parameter is fixed without a value, and the centre of the
#: global search when it is varied)
CONVENTIONAL = {"k0": 0.5, "mu": 0.2, "mu_sd": 0.05}


def reduced_linear_fit(data: SampleData, order, m_s, include_load_inertia, s_center, s_half, use_mask=True, E=None):
    """Linear LS for the Legendre coefficients of D (n+1), B' (n+1), C (2n+1) (and phi).

    Window-integrated equation error (v' > 0 throughout the window):
    m_eff (v'[k+w] - v'[k]) + 9.81 sum dt m' = sum dt (-D v' + B' V0 + C + E phi)
    (``E``: extra-force features, drive coordinates; linear in phi too).
    """
    lay = data.layout
    vp = data.d * data.v
    mp = data.d * data.load
    m_eff = m_s + (np.abs(data.load) if include_load_inertia else 0.0)
    dt = lay.step_dt(data.t)
    x = (data.s - s_center) / s_half
    L = legvander(x, order)
    L2 = legvander(x, 2 * order)
    med_dt = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 1e-3
    w = int(max(4, min(50, round(0.01 / med_dt))))
    stride = max(1, w // 2)
    vthr = max(5e-3, 0.05 * float(np.median(np.abs(vp))))
    blocks = [-L * vp[:, None], L * data.V0[:, None], L2]
    if E is not None:
        blocks.append(E)
    A = np.hstack(blocks) * dt[:, None]
    cumA = np.vstack([np.zeros(A.shape[1]), np.cumsum(A, axis=0)])
    cumT = np.concatenate([[0.0], np.cumsum(G_M_S2 * mp * dt)])

    def windows(good):
        cg = np.concatenate([[0], np.cumsum(good.astype(int))])
        idx = []
        for r in range(lay.R):
            st, ln = lay.starts[r], lay.lengths[r]
            if ln <= w:
                continue
            ks = st + np.arange(0, ln - w, stride)
            ok = (cg[ks + w + 1] - cg[ks]) == (w + 1)
            idx.append(ks[ok])
        return np.concatenate(idx) if idx else np.zeros(0, dtype=int)

    good = vp > vthr
    ks = windows(good & data.mask) if use_mask else np.zeros(0, dtype=int)
    ncoef = A.shape[1]
    if ks.size < 2 * ncoef:
        ks = windows(good)
    if ks.size < ncoef + 1:
        raise IdentificationError(
            f"too few usable samples for identification: {ks.size} windows of {w} samples "
            f"moving forward, need more than {ncoef}"
        )
    M = cumA[ks + w] - cumA[ks]
    y = m_eff[ks] * (vp[ks + w] - vp[ks]) + (cumT[ks + w] - cumT[ks])
    cn = np.sqrt(np.sum(M * M, axis=0))
    cn[cn == 0] = 1.0
    Q, Rm = np.linalg.qr(M / cn)
    qy = Q.T @ y
    sol, *_ = np.linalg.lstsq(Rm, qy, rcond=1e-12)
    sol = sol / cn
    n1 = order + 1
    nC = 2 * order + 1
    return {
        "D": sol[:n1],
        "B": sol[n1 : 2 * n1],
        "C": sol[2 * n1 : 2 * n1 + nC],
        "E": sol[2 * n1 + nC :],
        "R": Rm,
        "qy": qy,
        "cn": cn,
        "v_typ": float(np.median(np.abs(vp))),
        "V_typ": float(np.median(data.V0)),
        "n_windows": int(ks.size),
        "window": w,
    }


_LEGMUL_CACHE: dict = {}


def _legmul_tensor(order):
    """T[i, j, k]: coefficient k of P_i * P_j (Legendre), shape (n+1, n+1, 2n+1)."""
    T = _LEGMUL_CACHE.get(order)
    if T is None:
        n1 = order + 1
        T = np.zeros((n1, n1, 2 * order + 1))
        for i in range(n1):
            for j in range(n1):
                prod = npleg.legmul(np.eye(n1)[i], np.eye(n1)[j])
                T[i, j, : prod.size] = prod
        _LEGMUL_CACHE[order] = T
    return T


def reduced_of_theta(theta, order, m_s, kappa, jac=False):
    """Legendre coefficients of D (n+1), B' (n+1) and C (2n+1) implied by theta.

    With ``jac=True`` also returns d(coefficients)/d(theta), shape (4n+3, 3n+8).
    Entries of ``theta`` beyond the Eq. 35 part (extra-force parameters phi)
    are appended to the coefficients unchanged (identity Jacobian block).
    """
    n1 = order + 1
    T = _legmul_tensor(order)
    p_theta = 5 + 3 * n1
    phi = np.asarray(theta[p_theta:], dtype=float)
    nx = phi.size
    c_r, sig, mu, k0, musd = theta[:5]
    al = theta[5 : 5 + n1]
    be = theta[5 + n1 : 5 + 2 * n1]
    pp = theta[5 + 2 * n1 : p_theta]
    g1 = float(drive_factor(k0))
    G = float(G_of_k0(k0))
    hG = 0.5 * np.pi * G
    Dc = -sig * al
    Dc[0] += c_r + 0.5 * sig
    prod = np.einsum("i,j,ijk->k", pp, al, T)
    Cc = -mu * hG * prod
    Cc[:n1] += (mu * g1 - musd * kappa) * pp
    Cc[0] -= musd * G_M_S2 * m_s
    g = np.concatenate([Dc, be, Cc, phi])
    if not jac:
        return g
    nC = 2 * order + 1
    Jg = np.zeros((2 * n1 + nC + nx, p_theta + nx))
    if nx:
        Jg[2 * n1 + nC :, p_theta:] = np.eye(nx)
    iD, iB, iC = slice(0, n1), slice(n1, 2 * n1), slice(2 * n1, 2 * n1 + nC)
    # D
    Jg[0, 0] = 1.0
    Jg[iD, 1] = -al
    Jg[0, 1] += 0.5
    Jg[iD, 5 : 5 + n1] = -sig * np.eye(n1)
    # B'
    Jg[iB, 5 + n1 : 5 + 2 * n1] = np.eye(n1)
    # C
    ppad = np.zeros(nC)
    ppad[:n1] = pp
    Jg[iC, 2] = g1 * ppad - hG * prod
    Jg[iC, 3] = mu * float(ddrive_factor_dk0(k0)) * ppad - mu * 0.5 * np.pi * float(dG_dk0(k0)) * prod
    Jg[iC, 4] = -kappa * ppad
    Jg[2 * n1, 4] -= G_M_S2 * m_s
    Jg[iC, 5 : 5 + n1] = -mu * hG * np.einsum("i,ijk->kj", pp, T)
    Jg[iC, 5 + 2 * n1 : p_theta] = _dC_dp(al, T, mu, musd, kappa, g1, hG)
    return g, Jg


def _dC_dp(al, T, mu, musd, kappa, g1, hG):
    """d(C's Legendre coefficients)/d(p), (2n+1, n+1): ``g1 = drive_factor(k0)``, ``hG = pi/2 G(k0)``."""
    n1 = al.size
    dCp = -mu * hG * np.einsum("j,ijk->ki", al, T)
    dCp[:n1, :] += (mu * g1 - musd * kappa) * np.eye(n1)
    return dCp


def reduced_linear_columns(theta, lin, order, m_s, kappa):
    """``reduced_of_theta(theta, ..., jac=True)[1][:, lin]`` for columns ``lin`` among c_r (0), beta, p and
    phi (the parameters the reduced coefficients are affine in), without the other columns.

    The same entries to the last bit (the same expressions): the equation-error fit's projection needs only
    these, at every one of its many cheap evaluations.
    """
    n1 = order + 1
    T = _legmul_tensor(order)
    p_theta = 5 + 3 * n1
    nx = theta.size - p_theta
    nC = 2 * order + 1
    _, _, mu, k0, musd = theta[:5]
    al = theta[5 : 5 + n1]
    out = np.zeros((2 * n1 + nC + nx, len(lin)))
    ps = [j for j, c in enumerate(lin) if 5 + 2 * n1 <= c < p_theta]
    if ps:
        dCp = _dC_dp(al, T, mu, musd, kappa, float(drive_factor(k0)), 0.5 * np.pi * float(G_of_k0(k0)))
    for j, c in enumerate(lin):
        if c == 0:
            out[0, j] = 1.0
        elif 5 + n1 <= c < 5 + 2 * n1:
            out[n1 + c - 5 - n1, j] = 1.0
        elif 5 + 2 * n1 <= c < p_theta:
            out[2 * n1 : 2 * n1 + nC, j] = dCp[:, c - 5 - 2 * n1]
        elif c >= p_theta:
            out[2 * n1 + nC + c - p_theta, j] = 1.0
        else:
            raise ValueError(f"parameter {c} does not enter the reduced coefficients linearly")
    return out


def _grid(order):
    ng = 4 * order + 4
    return np.cos(np.pi * (np.arange(ng) + 0.5) / ng)


def map_reduced_to_theta(dco, bco, cco, fixed, order, m_s, kappa):
    """Eq. 35 parameters reproducing D, B', C, with conventions for the null directions."""
    n1 = order + 1
    xg = _grid(order)
    Lg = legvander(xg, order)
    L2g = legvander(xg, 2 * order)
    Dg = Lg @ dco
    Cg = L2g @ cco
    d0 = float(dco[0])
    # sigma: makes A' - alpha_0 = -(D - d0)/sigma span at most +-0.25
    if "sigma" in fixed:
        sig = fixed["sigma"]
    else:
        sig = max(4.0 * float(np.max(np.abs(Dg - d0))), 0.01 * abs(d0), 1e-6)
    k0 = fixed.get("k0", CONVENTIONAL["k0"])
    mu = fixed.get("mu", CONVENTIONAL["mu"])
    musd = fixed.get("mu_sd", CONVENTIONAL["mu_sd"])
    alpha = np.zeros(n1)
    if sig > 0:
        alpha[1:] = -dco[1:] / sig
    g1 = float(drive_factor(k0))
    G = float(G_of_k0(k0))
    a = mu * g1 - musd * kappa
    b = mu * 0.5 * np.pi * G
    e = G_M_S2 * m_s * musd
    q = Lg[:, 1:] @ alpha[1:]
    ce = Cg + e
    sgn = 1.0 if np.mean(ce) >= 0 else -1.0
    if "alpha_0" in fixed:
        alpha0 = fixed["alpha_0"]
    elif "c_r" in fixed and sig > 0:
        alpha0 = (fixed["c_r"] + 0.5 * sig - d0) / sig
    else:
        # convention: the factor (a - b alpha_0) takes the sign of C + e and
        # half the magnitude of |a| (or of b if a vanishes)
        phi = 0.5 * (abs(a) if abs(a) > 1e-9 else max(b, 1e-9))
        alpha0 = (a - sgn * phi) / b if b > 0 else 0.0
    alpha[0] = alpha0
    c_r = fixed.get("c_r", d0 - 0.5 * sig + sig * alpha0)
    if c_r < 0:
        c_r = 0.0
    denom = a - b * alpha0 - b * q
    if np.any(np.abs(denom) < 1e-9) or np.any(np.sign(denom) != np.sign(denom[0])):
        denom = np.full_like(denom, np.mean(denom) if abs(np.mean(denom)) > 1e-9 else 1.0)
    Pg = ce / denom
    pco, *_ = np.linalg.lstsq(Lg, Pg, rcond=None)
    theta = np.concatenate([[c_r, sig, mu, k0, musd], alpha, bco, pco])
    for name, val in fixed.items():
        theta[PredictorParams.names(order).index(name)] = val
    lo, hi = PredictorParams.bounds(order)
    return np.clip(theta, lo, np.minimum(hi, np.where(np.isfinite(hi), hi, np.inf)))


def equation_error_fit(theta_start, varied, red, order, m_s, kappa, n_starts, seed, spread=1.0, floor=0.25,
                        max_nfev=100):
    """Fit the Eq. 35 structure to the window-integrated equation error.

    Minimises ``|M g(theta) - y|^2`` (``g`` = reduced coefficients of D, B',
    C implied by theta, see :func:`reduced_of_theta`), evaluated cheaply
    through the QR factor of the linear problem; this weights the reduced
    functions by how well the data determine them (e.g. the small position
    variation of D is weakly determined).

    ``g`` is affine in c_r, beta and p for fixed (sigma, mu, k0, mu_sd,
    alpha), so the problem is solved by variable projection: the outer
    optimisation runs over the varied "nonlinear" parameters only, the
    linear ones are the exact least-squares solution for each trial. The
    bilinear P*A' term makes the outer problem multi-modal (the order-2n
    polynomial C(s) can be split into P(s) and (a - b A'(s)) in several
    ways), so it is multi-started from ``theta_start`` and scrambled Sobol
    points in the box ``z0 +- spread * max(|z0|, floor)`` (scaled
    coordinates). Returns the distinct local minima as ``(cost, theta)``,
    best first.
    """
    idx = np.flatnonzero(varied)
    n1 = order + 1
    Rc = red["R"] * red["cn"][None, :]
    qy = red["qy"]
    lin = np.array([i for i in idx if i == 0 or i >= 5 + n1], dtype=int)
    non = np.array([i for i in idx if i not in set(lin.tolist())], dtype=int)

    def project(th):
        """theta with the optimal linear parameters, and the residual."""
        th = th.copy()
        if lin.size == 0:
            return th, Rc @ reduced_of_theta(th, order, m_s, kappa) - qy
        th[lin] = 0.0
        g0 = reduced_of_theta(th, order, m_s, kappa)
        A = Rc @ reduced_linear_columns(th, lin, order, m_s, kappa)
        b = qy - Rc @ g0
        x, *_ = np.linalg.lstsq(A, b, rcond=1e-13)
        th[lin] = x
        return th, A @ x - b

    if idx.size == 0:
        return [(float("nan"), theta_start)]
    if non.size == 0:
        th, r = project(theta_start)
        return [(0.5 * float(r @ r), clip_theta(th, order))]
    lo, hi = PredictorParams.bounds(order)
    scale = param_scale(theta_start, order)[non]
    lb, ub = lo[non] / scale, hi[non] / scale

    def fun(zv):
        th = theta_start.copy()
        th[non] = zv * scale
        return project(th)[1]

    z0 = strictly_inside(theta_start[non] / scale, lb, ub)
    starts = [z0] + [strictly_inside(z, lb, ub) for z in sobol_box(z0, n_starts - 1, seed, spread, floor)]
    sols = []
    for zs in starts:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                res = least_squares(fun, zs, bounds=(lb, ub), method="trf", x_scale=1.0, max_nfev=max_nfev)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if np.isfinite(res.cost):
            sols.append((float(res.cost), res.x))
    if not sols:
        return [(float("nan"), theta_start)]
    sols.sort(key=lambda s: s[0])
    distinct = []
    for cost, x in sols:
        if all(np.max(np.abs(x - y)) > 0.05 for _, y in distinct):
            distinct.append((cost, x))
    out = []
    for cost, x in distinct:
        th = theta_start.copy()
        th[non] = x * scale
        th = project(th)[0]
        out.append((cost, clip_theta(th, order)))
    return out


def slip_sigma_start(data: SampleData, bco, s_center, s_half, k_ref: float = CONVENTIONAL["k0"]) -> float | None:
    """The pure-slip family's start for sigma [N s/m]: the slip ratio ``k = sigma v' / (pi B'(s) V0)`` equals
    ``k_ref`` (Eq. 29's conventional k0) at the median moving sample.

    In Eq. 29's reduced form sigma is a direction the data cannot determine (only D carries it), so the
    equation-error fit leaves it where its convention puts it (spread of D); in the pure-slip family sigma
    sets the tip speed of the slip ratio, and a start where ``k`` saturates at 1 on most samples is not
    in the basin of the likelihood. ``bco``: B'(s)'s Legendre coefficients [N/V] in the scaled position;
    moving samples: inside the mask, ``v' = d v > 0`` and ``B' V0 > 0``. None without such samples.
    """
    x = (np.asarray(data.s, float) - s_center) / s_half
    w = np.pi * npleg.legval(x, np.asarray(bco, float)) * np.asarray(data.V0, float)
    vp = np.asarray(data.d, float) * np.asarray(data.v, float)
    use = np.asarray(data.mask, bool) & (vp > 0) & (w > 0) & np.isfinite(vp)
    if not np.any(use):
        return None
    return float(k_ref / np.median(vp[use] / w[use]))


def data_driven_start(data, space, m_s, kappa, include_load_inertia, s_center, s_half, E, n_starts, seed,
                      warm=False, n_ee_starts=None, drive_law="eq29"):
    """The reduced linear fit and the equation-error minima that seed the global search.

    Parameters
    ----------
    data : SampleData
    space : ParameterSpace
        Names, bounds and pins of the joint vector.
    m_s, kappa, include_load_inertia, s_center, s_half
        Slider mass [kg], preload share [-], inertia convention, position scaling [m].
    E : ndarray or None
        Extra-force features [N per unit phi].
    n_starts, seed : int
        ``max(16, 4 n_starts)`` equation-error starts from the Sobol sequence of ``seed``
        (``n_ee_starts`` if given; 0: no equation-error fit, the only "minimum" is the reduced fit mapped by
        :func:`map_reduced_to_theta` (pins applied, clipped) with cost NaN, and ``seed`` is not used).
    warm : bool
        Warm start: no equation-error search; a failing linear fit gives ``red = None``.
    drive_law : ``"pure_slip"`` with sigma varied: the minima of a second equation-error fit with sigma held
        at :func:`slip_sigma_start` (Eq. 29's reduced form cannot move it meaningfully) come first, then
        alternate with those of the convention (the likelihood search tries both); ``"eq29"``: the convention.

    Returns
    -------
    red : dict or None
        :func:`reduced_linear_fit` output.
    minima : list of (cost, theta)
        Distinct equation-error minima (joint vectors, clipped, pins applied), best first.
    """
    order = space.order
    try:
        red = reduced_linear_fit(data, order, m_s, include_load_inertia, s_center, s_half, E=E)
    except IdentificationError:
        if not warm:
            raise
        return None, []  # a warm start does without the data-driven starts
    if warm:
        return red, []
    theta_names = set(space.theta_names)
    pins = {k: v for k, v in space.fixed_values.items() if k in theta_names}
    n_ee = max(16, 4 * n_starts) if n_ee_starts is None else int(n_ee_starts)

    def minima(pins, varied):
        theta_conv = map_reduced_to_theta(red["D"], red["B"], red["C"], pins, order, m_s, kappa)
        theta_conv = space.clip(space.with_fixed(np.concatenate([theta_conv, red["E"]])))
        if n_ee == 0:  # the mapped reduced fit itself (no equation-error fit, no seed)
            return [(float("nan"), theta_conv)]
        return equation_error_fit(theta_conv, varied, red, order, m_s, kappa, n_ee, seed, 1.0)
    ee = minima(pins, space.varied)
    sig = slip_sigma_start(data, red["B"], s_center, s_half) if drive_law == "pure_slip" else None
    if sig is not None and "sigma" not in pins:
        varied = space.varied.copy()
        varied[space.theta_names.index("sigma")] = False
        slip = minima({**pins, "sigma": sig}, varied)
        ee = [slip[0], ee[0]] + [m for pair in zip_longest(slip[1:], ee[1:]) for m in pair if m is not None]
    return red, [(c, space.clip(space.with_fixed(th))) for c, th in ee]


def reduced_summary(red, minima, extra_names) -> dict | None:
    """JSON-ready summary of the reduced fit (the estimator's ``reduced_``)."""
    if red is None:
        return None
    out = {
        "D": red["D"].tolist(), "B_prime": red["B"].tolist(), "C": red["C"].tolist(),
        "n_windows": red["n_windows"], "window_samples": red["window"],
        "equation_error_minima": [c for c, _ in minima],
    }
    if extra_names:
        out["extra"] = dict(zip(extra_names, (float(x) for x in red["E"])))
    return out


def init_theta(init, order, s_center, s_half) -> np.ndarray:
    """theta of a warm start ``init`` in the data's position scaling.

    ``init``: :class:`~l1b2.predictor.model.PredictorParams` (its polynomials
    are re-expanded exactly when its scaling (s_center, s_half) [m] differs)
    or a theta vector in Eq. 35 order (taken as is).
    """
    if not isinstance(init, PredictorParams):
        return np.asarray(init, dtype=float).ravel().copy()
    th = init.to_vector()
    if math.isclose(init.s_center, s_center, rel_tol=1e-12, abs_tol=1e-15) and math.isclose(
        init.s_half, s_half, rel_tol=1e-12
    ):
        return th
    n1 = order + 1
    old_dom = [init.s_center - init.s_half, init.s_center + init.s_half]
    new_dom = [s_center - s_half, s_center + s_half]

    def conv(c):
        out = np.zeros(n1)
        cc = npleg.Legendre(np.asarray(c, float), domain=old_dom).convert(domain=new_dom, kind=npleg.Legendre).coef
        out[: cc.size] = cc[:n1]
        return out

    return np.concatenate([th[:5], conv(init.alpha), conv(init.beta), conv(init.p)])
