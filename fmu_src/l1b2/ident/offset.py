"""The drive offset as a search coordinate (the ``solver="offset"`` search, decisions 0020 and 0023).

With every Eq. 35 parameter varied the data determine D(s) = c_r + sigma (0.5 - A'(s)), B'(s) and the
drive term of a moving slider, C(s) = P(s) (a - b A'(s)) - 9.81 m_s mu_sd, with
a = mu g1(k0) - mu_sd kappa and b = mu (pi/2) G(k0). Since A' = (c_r + sigma/2 - D)/sigma,

    a - b A'(s) = (b / sigma) (kappa0 + D(s)),   kappa0 = sigma a / b - c_r - sigma / 2

(the *drive offset*, :func:`drive_offset`). For given D(s) the offset is the one nonlinear parameter of the
split of C(s) into P(s) and its multiplier. It is normalised as

    omega = (max D - min D) / (2 (kappa0 + mid D))        (mid D = (max D + min D) / 2, over the stroke)

so that |omega| < 1 exactly when kappa0 + D(s) keeps its sign over the stroke (P(s) needs no pole); omega
runs through 0 at kappa0 = +-inf, so (-1, 1) is one interval of offsets with the barrier at its ends.

The local searches of :mod:`l1b2.ident.varpro` reach the offset only through (c_r, sigma, mu, k0), whose
bounds (c_r >= 0; at k0 = 0 the derivatives of g1 and G vanish) end them at whichever optimum along the
offset their start allows. This search makes the offset a coordinate:

1. a *gauge* (:func:`gauge`): sigma, mu, k0 pinned (k0 = :data:`GAUGE_K0`, sigma and b = mu (pi/2) G(k0)
   of the start); then kappa0 is set by c_r alone and, for a given D(s), each omega maps to one c_r
   (:func:`c_r_of_omega`) with the same D(s) (alpha from D exactly, :func:`with_offset`, :func:`point`);
2. a *profile* over omega (:func:`profile`): at each grid point c_r and mu_sd are pinned as well (mu_sd
   free moves the offset through a = mu g1 - mu_sd kappa: on the realistic benchmark it went to 10.7), and
   alpha is fitted by :func:`l1b2.ident.varpro.local_fit` with B'(s), P(s) projected (short, loose fits;
   each point starts from its neighbour's optimum moved to its omega, a continuation along the offset);
3. the best grid point seeds :func:`l1b2.ident.varpro.varpro_search` with every parameter varied again
   (the paper's parameters, their bounds and the covariance machinery unchanged).

``solver="offset_bracket"`` (:func:`bracketed_offset_search`) replaces the grid of step 2 by a bracketed
search over omega on each side of omega = 0 (:func:`bracket_search`: a few coarse points from the barrier
inwards, then parabolic or golden-section points inside the bracket of the best one), each point warm-started
from the optimum of its nearest evaluated neighbour and fitted with a smaller budget; step 3 starts with the
noise model of the profile's best point, and when it ends below that point the point itself is the result.
``solver="offset_reduced"`` is the same search framed at the reduced linear fit mapped to Eq. 35
(:func:`l1b2.ident.reduced.map_reduced_to_theta`, no equation-error fits): its gauge (sigma, b) and the D(s),
B'(s) the profile starts from are fixed by the data alone, with no random starts. ``solver="offset_kappa0"`` is
``offset_reduced`` with its identifiable continuation run in the drive offset kappa0 instead of K
(:func:`l1b2.ident.identifiable.offset_form`): along the offset's valley kappa0 stays put while K, beta_s and
mu_sd move together. Each of the three bracketed searches has its own settings in :data:`BRACKETS`. Two of
them widen the last step: the final search from more than one profile point (``finals``: the points that a
likelihood-ratio test on omega does not tell from the best; two in ``offset_kappa0``, one in the other two) and
profile points between the coarse points and the barrier (``barrier``, none by default).

Why both are opt-in, with the measurements: decisions 0023 and 0036.

The mapping back to the paper's parameters is exact: every point of the search is an Eq. 35 vector.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from ..errors import IdentificationError
from ..predictor.model import G_of_k0, drive_factor
from .identifiable import admissible, identifiable_search
from .pins import pinned_parameters
from .problem import ScaledObjective
from .varpro import linear_positions, local_fit, profile_loglik, varpro_search

__all__ = ["OMEGA_GRID", "GAUGE_K0", "drive_offset", "offset_of_omega", "omega_of_offset", "d_coefficients",
           "gauge", "multiplier", "point", "c_r_of_omega", "with_offset", "profile",
           "offset_search", "offset_grid", "projected_search", "BRACKETS", "bracket_search", "bracketed_profile",
           "bracketed_offset_search", "OFFSET_COORDINATES", "auto_solver", "profile_candidates"]

#: the profile's grid of omega (both branches of the offset, the barrier |omega| -> 1 approached)
OMEGA_GRID = (-0.95, -0.85, -0.7, -0.5, -0.3, -0.1, 0.3, 0.6, 0.85, 0.95)
#: k0 of the gauge (k0 = 0 avoided: the derivatives of g1 and G vanish there)
GAUGE_K0 = 0.02
#: points of the stroke x in [-1, 1] on which max D and min D are taken
_X = np.linspace(-1.0, 1.0, 401)


def d_coefficients(theta, n1: int) -> np.ndarray:
    """Legendre coefficients of D(s) = c_r + sigma (0.5 - A'(s)) [N s/m] of theta (Eq. 35 order)."""
    c_r, sigma = float(theta[0]), float(theta[1])
    d = -sigma * np.asarray(theta[5:5 + n1], dtype=float)
    d[0] += c_r + 0.5 * sigma
    return d


def _d_range(dco) -> tuple[float, float]:
    D = np.polynomial.legendre.legval(_X, dco)
    return float(D.min()), float(D.max())


def drive_offset(theta, n1: int, kappa: float) -> float:
    """kappa0 = sigma a / b - c_r - sigma / 2 [N s/m] of theta (inf when b = 0)."""
    c_r, sigma, mu, k0, mu_sd = (float(x) for x in theta[:5])
    a = mu * float(drive_factor(k0)) - mu_sd * kappa
    b = mu * 0.5 * np.pi * float(G_of_k0(k0))
    return float("inf") if b == 0 else sigma * a / b - c_r - 0.5 * sigma


def omega_of_offset(kappa0: float, dco) -> float:
    """The normalised offset omega of kappa0 for D(s) with Legendre coefficients ``dco`` (0 at |kappa0| = inf)."""
    lo, hi = _d_range(dco)
    den = 2.0 * (kappa0 + 0.5 * (lo + hi))
    return 0.0 if not np.isfinite(den) else float((hi - lo) / den) if den != 0 else float("inf")


def offset_of_omega(omega: float, dco) -> float:
    """The drive offset kappa0 of omega (!= 0) for D(s): the inverse of :func:`omega_of_offset`."""
    lo, hi = _d_range(dco)
    return (hi - lo) / (2.0 * omega) - 0.5 * (lo + hi)


def gauge(theta, n1: int, kappa: float, k0: float = GAUGE_K0) -> np.ndarray:
    """theta with k0 = ``k0`` and mu such that b = mu (pi/2) G(k0) is unchanged; c_r, sigma, mu_sd, alpha
    (so D(s)), beta, p as they are (the drive multiplier changes: :func:`point` sets it)."""
    th = np.array(theta, dtype=float)
    b_old = th[2] * 0.5 * np.pi * float(G_of_k0(th[3]))
    if b_old > 0:
        th[2] = b_old / (0.5 * np.pi * float(G_of_k0(k0)))
    th[3] = k0
    return th


def multiplier(theta, n1: int, kappa: float) -> np.ndarray:
    """The drive multiplier a - b A'(s) = (b / sigma)(kappa0 + D(s)) of theta on the stroke grid."""
    c_r, sigma, mu, k0, mu_sd = (float(x) for x in theta[:5])
    a = mu * float(drive_factor(k0)) - mu_sd * kappa
    b = mu * 0.5 * np.pi * float(G_of_k0(k0))
    return a - b * np.polynomial.legendre.legval(_X, np.asarray(theta[5:5 + n1], dtype=float))


def point(theta, n1: int, kappa: float, omega: float, dco) -> np.ndarray:
    """theta at the offset of ``omega`` (through c_r, :func:`with_offset`) with D(s) = ``dco`` and P(s)
    rescaled so that the drive term P (a - b A') of a moving slider keeps its least-squares shape."""
    th = with_offset(theta, n1, kappa, offset_of_omega(omega, dco), dco)
    _rescale_p(th, n1, multiplier(theta, n1, kappa), multiplier(th, n1, kappa))
    return th


def _rescale_p(th, n1, mult_old, mult_new):
    """Rescale P(s)'s coefficients (in place) so that P * mult keeps its least-squares shape."""
    L = np.polynomial.legendre.legvander(_X, n1 - 1)
    P = L @ th[5 + 2 * n1:5 + 3 * n1]
    ok = np.abs(mult_new) > 1e-12 * max(float(np.max(np.abs(mult_new))), 1e-300)
    if not np.any(ok):
        return
    target = np.where(ok, P * mult_old / np.where(ok, mult_new, 1.0), 0.0)
    th[5 + 2 * n1:5 + 3 * n1] = np.linalg.lstsq(L[ok], target[ok], rcond=None)[0]


def c_r_of_omega(theta, n1: int, kappa: float, omega: float, dco=None) -> float:
    """c_r that gives the offset of ``omega`` at theta's sigma, mu, k0, mu_sd and D(s) (may be < 0)."""
    dco = d_coefficients(theta, n1) if dco is None else dco
    k_target = offset_of_omega(omega, dco)
    return drive_offset(np.r_[0.0, theta[1:5]], n1, kappa) - k_target


def with_offset(theta, n1: int, kappa: float, kappa0: float, dco) -> np.ndarray:
    """theta with the drive offset kappa0 (through c_r) and D(s) = ``dco`` (through alpha), sigma, mu, k0,
    mu_sd, beta, p as they are. Exact: :func:`drive_offset` and :func:`d_coefficients` of the result return
    ``kappa0`` and ``dco``."""
    th = np.array(theta, dtype=float)
    sigma = th[1]
    th[0] = drive_offset(np.r_[0.0, th[1:5]], n1, kappa) - kappa0
    alpha = -np.asarray(dco, dtype=float) / sigma
    alpha[0] = (th[0] + 0.5 * sigma - dco[0]) / sigma
    th[5:5 + n1] = alpha
    return th


#: the structural directions pinned during the profile (the gauge and the offset coordinate c_r)
_PROFILE_PINS = (0, 1, 2, 3, 4)


class HeldOffsetProblem:
    """A likelihood problem in which mu_sd moves at a held drive offset kappa0 and a held D(s).

    It takes vectors u in theta's layout (Eq. 35 order) and evaluates the wrapped problem at

        theta(u) = u + (u[4] - mu_sd_ref) v,   v = s (e_0 + e_5 / sigma),   s = -sigma kappa / b,

    b = mu (pi/2) G(k0) and sigma of ``theta_ref`` (their slots must stay pinned at those values). Along u[4]
    (mu_sd) c_r changes by s per unit and alpha_0 by s / sigma, so that d kappa0 / d mu_sd = -sigma kappa / b - s = 0
    (kappa0 = sigma a / b - c_r - sigma / 2, a = mu g1(k0) - mu_sd kappa) and dD(s) = s - sigma (s / sigma) = 0
    (D = c_r + sigma (0.5 - A')). At u[4] = mu_sd_ref, theta(u) = u. ``residual``, ``jacobian``, ``start_gain``,
    ``start_gain_sensitivity`` and ``predict_all`` are those of the wrapped problem with the chain rule d theta / d u.
    """

    def __init__(self, problem, theta_ref, kappa: float):
        self.problem = problem
        self.core = problem.core
        self.criterion = getattr(problem, "criterion", None)
        self.sel = getattr(problem, "sel", None)
        c_r, sigma, mu, k0, mu_sd = (float(x) for x in theta_ref[:5])
        b = mu * 0.5 * np.pi * float(G_of_k0(k0))
        self.mu_sd_ref, self.sigma = mu_sd, sigma
        self.slope = -sigma * kappa / b  #: d c_r / d mu_sd [N s/m per unit mu_sd]

    def theta(self, u):
        th = np.array(u, dtype=float)
        dm = th[4] - self.mu_sd_ref
        th[0] += self.slope * dm
        th[5] += self.slope * dm / self.sigma
        return th

    def u_of(self, theta):
        """The inverse of :meth:`theta` (at theta's own mu_sd)."""
        u = np.array(theta, dtype=float)
        dm = u[4] - self.mu_sd_ref
        u[0] -= self.slope * dm
        u[5] -= self.slope * dm / self.sigma
        return u

    def _chain(self, cols):
        """``(theta columns, M)``: d theta[tcols] / d u[cols] = M."""
        cols = np.asarray(cols, dtype=int)
        tcols = np.unique(np.concatenate([cols, [0, 5] if np.isin(4, cols) else []]).astype(int))
        pos = {int(t): i for i, t in enumerate(tcols)}
        M = np.zeros((tcols.size, cols.size))
        for j, c in enumerate(cols):
            M[pos[int(c)], j] = 1.0
            if c == 4:
                M[pos[0], j] += self.slope
                M[pos[5], j] += self.slope / self.sigma
        return tcols, M

    def residual(self, u):
        return self.problem.residual(self.theta(u))

    def start_gain(self, u):
        return self.problem.start_gain(self.theta(u))

    def predict_all(self, u):
        return self.problem.predict_all(self.theta(u))

    def jacobian(self, u, cols, packed=False):
        tcols, M = self._chain(cols)
        kw = {"packed": True} if packed else {}
        return self.problem.jacobian(self.theta(u), tcols, **kw) @ M

    def start_gain_sensitivity(self, u, cols):
        tcols, M = self._chain(cols)
        g, G = self.problem.start_gain_sensitivity(self.theta(u), tcols)
        return g, G @ M


def _held_objective(obj, theta, scale_full, kappa, c_hi):
    """``(objective, problem)``: :func:`_profile_objective` with mu_sd varied (when ``obj`` varies it) on a
    :class:`HeldOffsetProblem` at ``theta``: the offset, D(s)'s dependence on c_r and the gauge held, mu_sd
    bounded by ``obj``'s bounds and by c_r staying in [0, ``c_hi``]."""
    op = _profile_objective(obj, theta, scale_full)
    if 4 not in obj.vidx:
        return op, None
    held = HeldOffsetProblem(obj.problem, theta, kappa)
    varied = np.zeros(theta.size, dtype=bool)
    varied[op.vidx] = True
    varied[4] = True
    lo = np.full(theta.size, -np.inf)
    hi = np.full(theta.size, np.inf)
    lo[op.vidx], hi[op.vidx] = op.zlo * op.sv_scale, op.zhi * op.sv_scale
    k = int(np.flatnonzero(obj.vidx == 4)[0])
    lo[4], hi[4] = obj.zlo[k] * obj.sv_scale[k], obj.zhi[k] * obj.sv_scale[k]
    ends = sorted(theta[4] + (np.array([0.0, c_hi]) - theta[0]) / held.slope)  # c_r = 0 and c_r = c_hi
    lo[4], hi[4] = max(lo[4], ends[0]), min(hi[4], ends[1])
    return ScaledObjective(held, obj.noise, theta.copy(), varied, scale_full, lo, hi, obj.start_noise), held


def _profile_objective(obj, theta, scale_full):
    """A ScaledObjective on obj's problem and noise with c_r, sigma, mu, k0, mu_sd pinned at ``theta``'s values
    (the other bounds obj's)."""
    varied = np.zeros(theta.size, dtype=bool)
    varied[obj.vidx] = True
    varied[list(_PROFILE_PINS)] = False
    lo = np.full(theta.size, -np.inf)
    hi = np.full(theta.size, np.inf)
    lo[obj.vidx], hi[obj.vidx] = obj.zlo * obj.sv_scale, obj.zhi * obj.sv_scale
    return ScaledObjective(obj.problem, obj.noise, theta.copy(), varied, scale_full, lo, hi, obj.start_noise)


def _point_fit(obj, theta, omega, n1, kappa, p_theta, scale_full, c_hi, max_iter, stat_tol, saved, min_gain=0.0,
               mu_sd_free=False):
    """One point of the profile: theta moved to ``omega`` (its own D(s)), c_r, sigma, mu, k0, mu_sd pinned, the
    rest fitted by at most ``max_iter`` variable-projection iterations (0: B'(s), P(s) projected only;
    ``min_gain``: that of :func:`l1b2.ident.varpro.local_fit`). With ``mu_sd_free`` mu_sd is fitted too, at the
    point's drive offset kappa0 (:class:`HeldOffsetProblem`: c_r follows it); ``c_r`` of the record is that of the
    move, ``theta`` the fitted Eq. 35 vector."""
    th = point(theta, n1, kappa, omega, d_coefficients(theta, n1))
    rec = {"omega": float(omega), "c_r": float(th[0]), "loglik": -np.inf, "theta": th, "nfev": 0, "njev": 0}
    if not (0.0 <= th[0] < c_hi):
        return rec
    vars(obj.noise).update(saved)
    op, held = _held_objective(obj, th, scale_full, kappa, c_hi) if mu_sd_free else (
        _profile_objective(obj, th, scale_full), None)
    try:
        fit = local_fit(op, linear_positions(op, p_theta, n1), op.z_of(th), max_iter, 1e-8, stat_tol,
                        min_gain=min_gain)
    except (np.linalg.LinAlgError, ValueError) as exc:
        return {**rec, "message": str(exc)}
    th_fit = op.theta_of(fit.z) if held is None else held.theta(op.theta_of(fit.z))
    rec.update(loglik=profile_loglik(op, fit.z), theta=th_fit, nfev=fit.nfev + 1, njev=fit.njev)
    return rec


#: the profile's settings: iterations and statistical tolerance of each point's fit
PROFILE = {"max_iter": 12, "stat_tol": 0.05}


def _profile_frame(obj, theta_start, n1, kappa):
    """The gauged start, the full parameter scale and the upper bound of c_r shared by both profiles."""
    th_g = gauge(theta_start, n1, kappa)
    scale_full = np.ones(th_g.size)
    scale_full[obj.vidx] = obj.sv_scale
    c_hi = obj.zhi[0] * obj.sv_scale[0] if obj.vidx[0] == 0 else np.inf
    return th_g, scale_full, c_hi


def profile(obj, theta_start, n1, kappa, p_theta, grid=OMEGA_GRID, settings=None, log=None):
    """The profile log-likelihood over omega (module docstring, step 2): ``(records, best)``.

    The points of each branch (omega < 0, omega > 0) are visited from the barrier (|omega| -> 1) inwards,
    each starting from the previous point's optimum moved to its omega (a continuation along the offset;
    the first from the gauged start). Each record: ``omega``, ``c_r``, ``loglik``, ``theta`` (an Eq. 35
    vector), ``nfev``, ``njev``; points whose c_r would leave its bounds have ``loglik = -inf``.
    """
    cfg = {**PROFILE, **(settings or {})}
    th_g, scale_full, c_hi = _profile_frame(obj, theta_start, n1, kappa)
    saved = dict(vars(obj.noise))
    records = []
    for branch in (sorted(w for w in grid if w < 0), sorted((w for w in grid if w > 0), reverse=True)):
        prev = th_g
        for om in branch:
            rec = _point_fit(obj, prev, om, n1, kappa, p_theta, scale_full, c_hi, cfg["max_iter"], cfg["stat_tol"],
                             saved)
            records.append(rec)
            if np.isfinite(rec["loglik"]):
                prev = rec["theta"]
            if log is not None:
                log(f"offset profile: omega {om:+.2f} (c_r {rec['c_r']:.3f}): loglik {rec['loglik']:.3f}, "
                    f"{rec['nfev']} evaluations")
    vars(obj.noise).update(saved)
    return records, max(records, key=lambda r: r["loglik"])


#: the golden-section fraction (3 - sqrt 5) / 2
_GOLDEN = 0.5 * (3.0 - 5.0 ** 0.5)


def _bracket(pts, lo, hi):
    """``(a, b, c)`` with values: the best evaluated point b and its evaluated neighbours (lo / hi with
    value -inf where b has none on that side)."""
    xs = sorted(pts, key=lambda p: p[0])
    i = max(range(len(xs)), key=lambda k: xs[k][1])
    a = xs[i - 1][:2] if i > 0 else (lo, -np.inf)
    c = xs[i + 1][:2] if i + 1 < len(xs) else (hi, -np.inf)
    return a, xs[i][:2], c


def _probe(a, b, c, last_step, tol):
    """The next point inside the bracket (Brent's rule): the vertex of the parabola through a, b, c when their
    values are finite, the vertex is at least ``tol / 4`` from them and moves less than half ``last_step``;
    else the golden-section point of the larger side. ``None`` when no point is ``tol / 4`` from the others."""
    (xa, fa), (xb, fb), (xc, fc) = a, b, c
    if np.isfinite(fa) and np.isfinite(fc):
        den = (xb - xa) * (fb - fc) - (xb - xc) * (fb - fa)
        if den != 0:
            u = xb - 0.5 * ((xb - xa) ** 2 * (fb - fc) - (xb - xc) ** 2 * (fb - fa)) / den
            if xa < u < xc and min(abs(u - xa), abs(u - xb), abs(u - xc)) >= 0.25 * tol \
                    and abs(u - xb) < 0.5 * last_step:
                return u
    u = xb + _GOLDEN * (xc - xb) if xc - xb >= xb - xa else xb - _GOLDEN * (xb - xa)
    return u if min(abs(u - xa), abs(u - xb), abs(u - xc)) >= 0.25 * tol else None


def bracket_search(f, coarse, lo, hi, tol, max_points, seen=()):
    """Maximise a function of one variable on the open interval (lo, hi): coarse points, then a bracketed search.

    ``f(x, warm) -> (value, state)``: ``value`` may be -inf (x infeasible), ``warm`` is the ``state`` of the
    evaluated point nearest to x with a finite value (``None`` before there is one), so that each point can
    start from its neighbour's optimum. The ``coarse`` points are evaluated in their order; then, while fewer
    than ``max_points`` points (``seen`` included) were evaluated and the bracket (a, b, c) around the best
    point b (its evaluated neighbours, ``lo`` / ``hi`` counted as -inf) is at least ``tol`` wide, one point of
    :func:`_probe` (parabolic or golden section) is evaluated. Returns the evaluated points
    ``[(x, value, state), ...]`` (``seen`` first, then in the order visited).
    """
    pts = list(seen)

    def visit(x):
        near = [p for p in pts if np.isfinite(p[1])]
        warm = min(near, key=lambda p: (abs(p[0] - x), -p[1]))[2] if near else None
        value, state = f(x, warm)
        pts.append((float(x), float(value), state))

    for x in coarse:
        if len(pts) < max_points:
            visit(x)
    last_step = step = hi - lo
    while len(pts) < max_points and any(np.isfinite(p[1]) for p in pts):
        a, b, c = _bracket([p for p in pts if lo < p[0] < hi], lo, hi)
        if c[0] - a[0] < tol:
            break
        u = _probe(a, b, c, last_step, tol)
        if u is None:
            break
        last_step, step = step, abs(u - b[0])
        visit(u)
    return pts


#: the settings of a bracketed profile and its final search: the coarse |omega| of each branch (from the barrier
#: inwards), the bracket width that ends a branch's search, the most points of a branch (the branch with the
#: best coarse point is searched, the other as well when its best is within ``margin`` log-likelihood units), each
#: point's fit (iterations from a neighbour's optimum, ``cold_iter`` from the gauged start, statistical
#: tolerance, least gain a step must promise: ``local_fit``'s min_gain), the final free search's min_gain and its
#: coordinates ("identifiable": :func:`l1b2.ident.identifiable.identifiable_search`; "paper": the
#: variable-projection search in theta; "paper+identifiable": the paper's, then continued in the
#: identifiable coordinates from its optimum, the better kept); ``point_mu_sd``: each point fitted with mu_sd varied
#: at the point's drive offset (:func:`_point_fit`); ``finals``: the final search is run from at most this
#: many profile points, the bracket's best first, then the best of the points within ``final_margin`` of the best
#: profile log-likelihood (:func:`profile_candidates`), and the highest end is kept; ``barrier``: the |omega| of
#: points added on each branch after the bracketed search, between its coarse points and the barrier |omega| = 1
#: (each from its branch's nearest evaluated point; they are candidates of the other finals only).
_BRACKET_COMMON = {"coarse": (0.95, 0.7, 0.4), "tol": 0.08, "max_points": 4, "margin": 3.0, "max_iter": 4,
                   "cold_iter": 12, "stat_tol": 0.05, "min_gain": 0.01, "final_min_gain": 0.01,
                   "final": "paper+identifiable", "point_mu_sd": False, "finals": 1, "final_margin": 1.92,
                   "barrier": ()}
#: the settings of each bracketed search (``solver`` -> its own dict, read when a fit runs: changing one solver's
#: entry changes no other solver's fit); ``start_fits`` of ``offset_bracket``: the number of equation-error fits
#: of its start (:func:`l1b2.ident.reduced.data_driven_start`; ``offset_reduced`` and ``offset_kappa0`` have none).
#: ``offset_kappa0`` (the default cold search) runs its final search from the two best points of the profile's
#: 95 % confidence set of omega: its first final is the one-final search, so its result is never below that one's
BRACKETS = {"offset_bracket": {**_BRACKET_COMMON, "start_fits": 4},
            "offset_reduced": dict(_BRACKET_COMMON),
            "offset_kappa0": {**_BRACKET_COMMON, "finals": 2}}


def bracketed_profile(obj, theta_start, n1, kappa, p_theta, settings=None, log=None):
    """The profile over omega by a bracketed search on each side of omega = 0 (:func:`bracket_search`):
    ``(records, best)`` as :func:`profile`.

    ``settings``: a bracketed search's settings (:data:`BRACKETS`; default those of ``offset_bracket``, entries
    given override them). The coarse points on both branches (omega < 0 and omega > 0; the barrier |omega| = 1
    and omega = 0 are the ends of each interval), then the bracketed search on the branch with the best
    point, and on the other one when its best is within ``margin`` of it; then the ``barrier`` points of each branch.
    ``best`` is the best point of the bracketed searches (the barrier points left out). Each point is fitted as in
    :func:`profile`, starting from the optimum of the evaluated point nearest to it moved to its omega
    (the first of each branch from the gauged start).
    """
    cfg = {**BRACKETS["offset_bracket"], **(settings or {})}
    th_g, scale_full, c_hi = _profile_frame(obj, theta_start, n1, kappa)
    saved = dict(vars(obj.noise))
    records = []

    def f(om, warm):
        rec = _point_fit(obj, th_g if warm is None else warm, om, n1, kappa, p_theta, scale_full, c_hi,
                         cfg["cold_iter" if warm is None else "max_iter"], cfg["stat_tol"], saved, cfg["min_gain"],
                         cfg["point_mu_sd"])
        records.append(rec)
        if log is not None:
            log(f"offset profile: omega {om:+.3f} (c_r {rec['c_r']:.3f}): loglik {rec['loglik']:.3f}, "
                f"{rec['nfev']} evaluations")
        return rec["loglik"], (rec["theta"] if np.isfinite(rec["loglik"]) else None)

    ends = {-1: (-1.0, 0.0), 1: (0.0, 1.0)}
    pts = {sign: bracket_search(f, [sign * w for w in cfg["coarse"]], *ends[sign], cfg["tol"], len(cfg["coarse"]))
           for sign in (-1, 1)}
    top = {sign: max((p[1] for p in pts[sign]), default=-np.inf) for sign in pts}
    first = max(top, key=top.get)
    for sign in (first, -first):
        if sign == first or top[sign] >= top[first] - cfg["margin"]:
            bracket_search(f, (), *ends[sign], cfg["tol"], cfg["max_points"], seen=pts[sign])
    best = max(records, key=lambda r: r["loglik"])
    for sign in (-1, 1):  # the barrier side of each branch, outwards from its evaluated points
        for w in cfg["barrier"]:
            near = [r for r in records if np.sign(r["omega"]) == sign and np.isfinite(r["loglik"])]
            f(sign * w, min(near, key=lambda r: abs(r["omega"] - sign * w))["theta"] if near else None)
    vars(obj.noise).update(saved)
    return records, best


def profile_stage(records, t0: float, c0: float) -> dict:
    """The offset profile's stage record: its wall and CPU time since ``t0``/``c0`` [s] (``time.perf_counter``,
    ``time.process_time``), its evaluations and each profile point's omega, c_r, log-likelihood and evaluations."""
    return {"stage": "offset profile", "time_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
            "nfev": int(sum(r["nfev"] for r in records)), "njev": int(sum(r.get("njev", 0) for r in records)),
            "profile": [{"omega": r["omega"], "c_r": r["c_r"], "loglik": r["loglik"], "nfev": r["nfev"]}
                        for r in records]}


def offset_search(obj, theta_start, order, kappa, p_theta, max_nfev, tol, stat_tol, max_outer, grid=OMEGA_GRID,
                  log=None):
    """The drive-offset search (module docstring): the profile over omega, then the full search from its best.

    ``obj``: the :class:`~l1b2.ident.problem.ScaledObjective` of the fit (c_r, sigma, mu, k0 varied);
    ``theta_start``: the data-driven centre (its D(s) and B'(s) start the profile). Returns
    ``(SearchOutcome, refinement, stages)`` like :func:`l1b2.ident.varpro.varpro_search`, the profile's
    records in the first stage (``profile``: omega, c_r, log-likelihood, evaluations per point).
    """
    n1 = order + 1
    t0, c0 = time.perf_counter(), time.process_time()
    records, best = profile(obj, theta_start, n1, kappa, p_theta, grid, log=log)
    stage = profile_stage(records, t0, c0)
    theta0 = best["theta"] if np.isfinite(best["loglik"]) else theta_start
    lin = linear_positions(obj, p_theta, n1)
    search, outer, more = varpro_search(obj, lin, [obj.z_of(theta0)], max_nfev, tol, stat_tol, max_outer, 1, log)
    search.records[0]["nfev"] += stage["nfev"]  # the profile's evaluations count with the search's
    return search, outer, [stage] + more


def _keep_profile_point(obj, search, outer, best, log=None):
    """``(search, outer)`` of the free search, or of the profile's ``best`` point when the free search ended
    below it (the offset search never ends below its best profile point); the noise model at the kept point."""
    from .search import ProfileRefinement

    ll = -search.results[search.best].cost
    if not ll < best["loglik"]:
        return search, outer
    z = obj.z_of(best["theta"])
    ll_best = profile_loglik(obj, z)  # the noise model at the point kept
    final = SimpleNamespace(x=z, cost=-ll_best, status=-2, optimality=float("nan"), nfev=0, njev=0,
                            message=f"offset profile's best point kept (the free search ended {best['loglik'] - ll:.3g} "
                                    "log-likelihood units below it)")
    search.results[search.best] = final
    rec = search.records[[r["start"] for r in search.records].index(search.best)]
    rec.update(cost=-ll_best, loglik=ll_best)
    if log is not None:
        log(final.message)
    return search, ProfileRefinement(z, final, outer.history + [{"iteration": len(outer.history), "loglik": ll_best,
                                                                  "profile_point": True}], outer.converged)


def _continue_identifiable(obj, search, outer, more, n1, p_theta, max_nfev, tol, stat_tol, max_outer, log,
                           kappa=None, min_gain=0.01):
    """The search continued in the identifiable coordinates from its optimum (a bracketed search's ``final`` =
    "paper+identifiable", every local fit with ``min_gain``; with ``kappa`` in their offset form,
    :func:`l1b2.ident.identifiable.identifiable_search`): the continuation when it ends higher, else the search as
    it was (noise model there); its evaluations count either way and its stages are added as "identifiable ...".
    Not continued when the optimum has no identifiable coordinates (:func:`l1b2.ident.identifiable.admissible`)."""
    ll = -search.results[search.best].cost
    if not admissible(obj.theta_of(outer.z), n1):  # e.g. mu or sigma at its bound 0: no coordinates to continue in
        return search, outer, more
    try:
        s2, o2, m2 = identifiable_search(obj, obj.theta_of(outer.z), n1, p_theta, max_nfev, tol, stat_tol,
                                         max_outer, log, min_gain, kappa)
    except (IdentificationError, np.linalg.LinAlgError, ValueError) as exc:  # the search as it was
        if log is not None:
            log(f"identifiable continuation failed ({exc}); the paper-coordinate optimum kept")
        profile_loglik(obj, outer.z)
        return search, outer, more
    more = more + [{**m, "stage": "identifiable " + m["stage"]} for m in m2]
    extra = sum(m.get("nfev", 0) for m in m2)
    if -s2.results[s2.best].cost > ll:
        s2.records[0]["nfev"] += sum(r.get("nfev", 0) for r in search.records)
        return s2, o2, more
    profile_loglik(obj, outer.z)  # the noise model at the kept optimum
    search.records[0]["nfev"] += extra
    return search, outer, more


def bracketed_offset_search(obj, theta_start, order, kappa, p_theta, max_nfev, tol, stat_tol, max_outer, log=None,
                            offset_form=False, settings=None):
    """The drive-offset search with the bracketed profile (``solver="offset_bracket"``).

    ``settings``: the search's settings (:data:`BRACKETS`; default those of ``offset_bracket``, entries given
    override them). :func:`bracketed_profile`, then the free variable-projection search from its best point (the
    noise model set at that point, every local fit with ``final_min_gain``); the result is the profile's best
    point itself when the free search ends below it (:func:`_keep_profile_point`). With ``finals`` > 1
    the free search runs from the profile's best point and then from the other points of :func:`profile_candidates`
    (at most ``finals`` in all), and the highest end is the result (every search's evaluations counted, the other
    searches' stages named "other final ..."). With ``offset_form`` (``solver=
    "offset_kappa0"``) the identifiable stages of ``final`` run with the drive offset kappa0 in place of
    K (:func:`l1b2.ident.identifiable.offset_form`). Returns ``(SearchOutcome, refinement, stages)`` as
    :func:`offset_search`.
    """
    cfg = {**BRACKETS["offset_bracket"], **(settings or {})}
    n1 = order + 1
    t0, c0 = time.perf_counter(), time.process_time()
    records, best = bracketed_profile(obj, theta_start, n1, kappa, p_theta, cfg, log=log)
    stage = profile_stage(records, t0, c0)
    if not np.isfinite(best["loglik"]):
        search, outer, more = varpro_search(obj, linear_positions(obj, p_theta, n1), [obj.z_of(theta_start)],
                                            max_nfev, tol, stat_tol, max_outer, 1, log, cfg["final_min_gain"])
    else:
        args = (n1, p_theta, max_nfev, tol, stat_tol, max_outer, log, kappa if offset_form else None, cfg)
        others = [r for r in profile_candidates(records, cfg["finals"], cfg["final_margin"]) if r is not best]
        finals = [_final_search(obj, rec, *args) for rec in ([best] + others)[:cfg["finals"]]]
        search, outer, more = max(finals, key=lambda f: -f[0].results[f[0].best].cost)
        for other in finals:
            if other[0] is not search:
                search.records[0]["nfev"] += sum(r.get("nfev", 0) for r in other[0].records)
                more = more + [{**m, "stage": "other final " + m["stage"]} for m in other[2]]
        if len(finals) > 1:
            profile_loglik(obj, outer.z)  # the noise model at the kept optimum
    search.records[0]["nfev"] += stage["nfev"]  # the profile's evaluations count with the search's
    return search, outer, [stage] + more


def profile_candidates(records, k: int, margin: float) -> list:
    """The profile points the final search is run from: at most ``k`` of the points whose profile log-likelihood
    is within ``margin`` of the best (the profile-likelihood confidence set of omega: with ``margin`` =
    chi2_1(0.95) / 2 = 1.92 the offsets that a likelihood-ratio test at 5 % does not tell from the best), best
    first (``[]`` when no point is finite; with ``k = 1`` the profile's best point alone)."""
    pts = sorted((r for r in records if np.isfinite(r["loglik"])), key=lambda r: -r["loglik"])
    return [r for r in pts if r["loglik"] >= pts[0]["loglik"] - margin][:k] if pts else []


def _final_search(obj, best, n1, p_theta, max_nfev, tol, stat_tol, max_outer, log, kappa, cfg):
    """The free search from one profile point ``best`` (the coordinates of ``cfg["final"]``, the point itself kept
    when the search ends below it, the identifiable continuation of "paper+identifiable"; ``cfg``: the bracketed
    search's settings): ``(SearchOutcome, refinement, stages)``."""
    if cfg["final"] == "identifiable" and admissible(best["theta"], n1):  # null directions of (sigma, mu, k0) removed
        search, outer, more = identifiable_search(obj, best["theta"], n1, p_theta, max_nfev, tol, stat_tol,
                                                  max_outer, log, cfg["final_min_gain"], kappa)
    else:
        z0 = obj.z_of(best["theta"])
        profile_loglik(obj, z0)  # the free search starts with the noise model of its start
        search, outer, more = varpro_search(obj, linear_positions(obj, p_theta, n1), [z0], max_nfev, tol, stat_tol,
                                            max_outer, 1, log, cfg["final_min_gain"])
    search, outer = _keep_profile_point(obj, search, outer, best, log)
    if cfg["final"] == "paper+identifiable":  # continued without the null directions
        search, outer, more = _continue_identifiable(obj, search, outer, more, n1, p_theta, max_nfev, tol,
                                                     stat_tol, max_outer, log, kappa, cfg["final_min_gain"])
    return search, outer, more


def offset_grid(n_starts: int) -> tuple:
    """The omega grid of ``n_starts``: :data:`OMEGA_GRID` up to its size, else ``n_starts`` points evenly
    spaced in (-0.97, 0.97) without 0 (both branches)."""
    if n_starts <= len(OMEGA_GRID):
        return OMEGA_GRID
    w = np.linspace(-0.97, 0.97, n_starts + 1)
    return tuple(float(x) for x in w if abs(x) > 0.02)


def projected_search(cfg, obj, starts, theta_centre, p_theta, log=None):
    """The search of ``cfg.solver`` ("varpro", "offset", "offset_bracket", "offset_reduced" or "offset_kappa0": the
    bracketed search, framed at ``theta_centre`` either way) on ``obj``: ``(SearchOutcome, refinement, stages)``.

    The offset searches need c_r, sigma, mu, k0 varied (they carry the gauge and the offset); with any of them pinned
    it is the variable-projection search from ``starts[0]`` (the pins already fix the offset's range).
    """
    n1 = cfg.order + 1
    lin = linear_positions(obj, p_theta, n1)
    offset = cfg.solver in ("offset", "offset_bracket", "offset_reduced", "offset_kappa0")
    if offset and np.isin([0, 1, 2, 3, 5], obj.vidx).all():
        if cfg.solver != "offset":
            return bracketed_offset_search(obj, theta_centre, cfg.order, cfg.kappa, p_theta, cfg.max_nfev, cfg.tol,
                                           cfg.stat_tol, cfg.max_outer, log, cfg.solver == "offset_kappa0",
                                           BRACKETS[cfg.solver])
        return offset_search(obj, theta_centre, cfg.order, cfg.kappa, p_theta, cfg.max_nfev, cfg.tol,
                             cfg.stat_tol, cfg.max_outer, offset_grid(cfg.n_starts), log)
    if offset:
        starts = starts[:1]
    return varpro_search(obj, lin, starts, cfg.max_nfev, cfg.tol, cfg.stat_tol, cfg.max_outer, cfg.n_refine, log)


#: the parameters that carry the drive offset and its gauge: the offset searches need them varied
OFFSET_COORDINATES = ("c_r", "sigma", "mu", "k0", "alpha_0")


def auto_solver(cfg) -> str:
    """The search of ``solver="auto"`` for the settings ``cfg``: ``"offset_kappa0"`` for a cold fit (no
    ``init``) of the Eq. 29 model alone (no extra forces) with :data:`OFFSET_COORDINATES` varied, else ``"joint"``
    (a warm start is a local continuation; pins of the offset's coordinates fix its range; the pure-slip family and
    the extra forces are searched by the joint search)."""
    fixed = pinned_parameters(cfg.fixed)
    cold_eq29 = cfg.init is None and cfg.model == "eq29" and cfg.extra is None
    return "offset_kappa0" if cold_eq29 and not set(fixed) & set(OFFSET_COORDINATES) else "joint"
