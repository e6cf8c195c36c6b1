"""Reduced speed predictor of the L1B2 motor (paper Eq. 25-31, 33-35).

The paper's Eq. 29 is the explicit-Euler step (Eq. 28) of the slider ODE

    m_eff dv'/dt = F(v'; s, V0, m_load')

with the period-averaged force (drive coordinates, see *Direction* below)

    F = -(c_r + sigma*(0.5 - A'(s))) v' + B'(s) V0
        + mu*P(s)*[2*sqrt(1 - k0^2) - 1 - (pi/2)*A'(s)*G(k0)]
        - 9.81*m_load' + sign(-v')*mu_sd*(9.81*m_s + kappa*P(s))

    G(k0) = 2 k0 sqrt(1 - k0^2) - 2 arcsin(k0) + pi/2          (Eq. 25, "2k" read as k0)

This module implements the continuous form so that the per-sample time step
``dt_k = t[k+1] - t[k]`` can be used::

    v'(k+1) = v'(k) + dt_k / m_eff * F(v'(k))

Decisions (and where they deviate from the paper)
-------------------------------------------------
* **A', B' instead of A, B.** By Eq. 30 the paper's ``A`` [s] and ``B`` [N s/V]
  are proportional to the sampling time T_s. With ``A = A' T_s`` and
  ``B = B' T_s`` the expansion of Eq. 28 is *exactly* Eq. 29 (tested), and the
  dimensionless A' and the gain B' [N/V] do not depend on the sampling rate.
  :meth:`PredictorParams.to_paper_monomials` converts back for a given T_s.
* **P is the preload.** The paper writes ``F_p = alpha_0 P`` (Eq. 16); the
  conversion factor cannot be separated from the polynomial P(s) by any data,
  so it is absorbed: P(s) [N] *is* the period-mean normal force F_p.
* **kappa** is the share of F_p that loads the linear guide: Eq. 29 uses 0.5,
  Eq. 22 uses 1. It is a fixed model constant (``PredictorParams.kappa``,
  default 0.5), never identified.
* **m_eff.** The paper writes ``m``. The hanging load on the pulley is
  accelerated together with the slider, so by default
  ``m_eff = m_s + |m_load|`` (``include_load_inertia=True``); set
  ``include_load_inertia=False`` for the paper's literal ``m = m_s``.
  This only matters in transients; steady states do not depend on it.
* **Coulomb friction at and through v' = 0.** Eq. 29's ``sign(-v')`` is
  undefined at rest. At ``v' = 0`` exactly the guide friction is static
  (Karnopp): it opposes the net drive force ``X`` (everything in F except the
  v'-terms) and is capped at its Coulomb level, i.e.
  ``F(0) = X - clip(X, -Fr, Fr)`` with ``Fr = mu_sd (9.81 m_s + kappa P)``;
  a slider whose drive does not exceed the friction stays at rest. A step
  that would reverse the sign of the speed stops at v' = 0 at the fraction
  ``phi = v'(k) / (v'(k) - v'_euler(k+1))`` of the step and continues from
  rest for the remaining ``(1 - phi) dt`` with the static rule (Coulomb
  friction cannot reverse a motion within a step). Both rules only act at or
  through v' = 0; for a moving slider (v' != 0, no reversal) the step is
  exactly Eq. 29. Why it matters: numpy's ``sign(0) = 0`` would omit the
  guide friction on the first step of every run that starts at rest (an
  artefact that makes the structurally non-identifiable combinations of
  theta look very weakly identifiable), a measured start speed of -0.5 mm/s
  (noise) in a +1 run would apply the friction the wrong way for a whole
  step, and stuck runs would chatter.
* **Direction.** Eq. 29 is written for CH1 (direction +1, toward +position).
  For direction ``d`` in {+1, -1} the mirrored form is used in drive
  coordinates ``v' = d v``, ``m_load' = d m_load`` (a positive ``load_kg``
  pulls toward -position: it opposes +1 runs and assists -1 runs). A', B' and
  P are evaluated at the *actual* position s (not mirrored): the stator sees
  the same friction-bar point whichever way it drives. Speeds are returned in
  the data's signed convention ``v = d v'``.

Extra forces
------------
:func:`derivative`, :func:`one_step`, :func:`free_run`,
:func:`free_run_coefficients`, :func:`steady_state` and
:func:`simulate_dataset` accept an optional ``extra_force`` (default
``None`` = the model above, unchanged): a force [N] in *drive coordinates*
(positive = in the drive direction) added to the drive force ``X`` of every
sample, ``X_total = X + extra_force``. It enters the static-friction rule
like any other part of X. This is how candidate physical effects the paper's
model lacks are carried (see :class:`l1b2.identify.ExtraForces`).

Position polynomials
--------------------
A'(s), B'(s), P(s) have order n (default 8 as in the paper) and are stored as
Legendre series in ``x = (s - s_center) / s_half`` (x in [-1, 1] over the
training stroke). Raw monomials in metres span ~20 orders of magnitude
(Table 1); the Legendre basis is well conditioned. Conversions to and from
the paper's layout (monomials in metres, highest power first) are provided.

Parameter vector (Eq. 35 order)::

    theta = [c_r, sigma, mu, k0, mu_sd, alpha_0..alpha_n, beta_0..beta_n, p_0..p_n]

with alpha, beta, p the Legendre coefficients of A' [-], B' [N/V], P [N];
c_r, sigma in N s/m; mu, k0, mu_sd dimensionless. Bounds: c_r, sigma, mu,
mu_sd >= 0 and 0 <= k0 < 1.

All functions are pure and vectorised (numpy broadcasting); nothing here
loops over samples except :func:`free_run` / :func:`simulate_dataset`, which
loop over the time index only, vectorised across runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
from numpy.polynomial import Legendre, Polynomial
from numpy.polynomial.legendre import legvander

__all__ = [
    "G_ACC",
    "SCALAR_NAMES",
    "PredictorParams",
    "G_of_k0",
    "drive_factor",
    "rest_sign",
    "step_drive",
    "derivative",
    "one_step",
    "free_run",
    "steady_state",
    "simulate_dataset",
    "design_grid",
    "example_params",
    "RunLayout",
]

#: gravitational acceleration used by the paper (Eq. 22, 29) [m/s^2]
G_ACC = 9.81

#: names of the five scalar parameters, in Eq. 35 order
SCALAR_NAMES = ("c_r", "sigma", "mu", "k0", "mu_sd")

_SCALAR_UNITS = {"c_r": "N s/m", "sigma": "N s/m", "mu": "-", "k0": "-", "mu_sd": "-"}
_GROUP_UNITS = {"alpha": "-", "beta": "N/V", "p": "N"}
_PAPER_UNITS = {"alpha": "s", "beta": "N s/V", "p": "N"}

#: upper bound used for k0 (k0 < 1 strictly; G'(k0) diverges at 1)
K0_MAX = 0.999


def G_of_k0(k0):
    """G(k0) = 2 k0 sqrt(1-k0^2) - 2 arcsin(k0) + pi/2 (Eq. 25, "2k" read as k0)."""
    k0 = np.asarray(k0, dtype=float)
    return 2.0 * k0 * np.sqrt(1.0 - k0 * k0) - 2.0 * np.arcsin(k0) + 0.5 * np.pi


def dG_dk0(k0):
    """dG/dk0 = -4 k0^2 / sqrt(1 - k0^2)."""
    k0 = np.asarray(k0, dtype=float)
    return -4.0 * k0 * k0 / np.sqrt(1.0 - k0 * k0)


def drive_factor(k0):
    """g1(k0) = 2 sqrt(1 - k0^2) - 1, the slip-friction drive factor of Eq. 29."""
    k0 = np.asarray(k0, dtype=float)
    return 2.0 * np.sqrt(1.0 - k0 * k0) - 1.0


def ddrive_factor_dk0(k0):
    k0 = np.asarray(k0, dtype=float)
    return -2.0 * k0 / np.sqrt(1.0 - k0 * k0)


# ---------------------------------------------------------------------------
# parameters
# ---------------------------------------------------------------------------


def _as_coef_tuple(values, name):
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    if arr.ndim != 1 or arr.size < 1:
        raise ValueError(f"{name} must be a 1-D sequence of polynomial coefficients")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values")
    return tuple(float(a) for a in arr)


@dataclass(frozen=True)
class PredictorParams:
    """Parameters of the reduced predictor (Eq. 29, 35) plus its fixed settings.

    ``alpha``, ``beta`` and ``p`` are Legendre coefficients (lowest degree
    first) of A'(s) [-], B'(s) [N/V] and P(s) [N] in the scaled position
    ``x = (s - s_center) / s_half``. ``kappa`` and ``include_load_inertia``
    are model settings, not identified (see module docstring).
    """

    c_r: float
    sigma: float
    mu: float
    k0: float
    mu_sd: float
    alpha: tuple
    beta: tuple
    p: tuple
    s_center: float = 0.0
    s_half: float = 0.02
    kappa: float = 0.5
    include_load_inertia: bool = True

    def __post_init__(self):
        for name in SCALAR_NAMES + ("s_center", "s_half", "kappa"):
            val = float(getattr(self, name))
            if not math.isfinite(val):
                raise ValueError(f"PredictorParams.{name} must be finite, got {val}")
            object.__setattr__(self, name, val)
        for name in ("alpha", "beta", "p"):
            object.__setattr__(self, name, _as_coef_tuple(getattr(self, name), name))
        if not (len(self.alpha) == len(self.beta) == len(self.p)):
            raise ValueError("alpha, beta and p must have the same length (order + 1)")
        if self.s_half <= 0:
            raise ValueError("s_half must be > 0 [m]")
        object.__setattr__(self, "include_load_inertia", bool(self.include_load_inertia))

    # -- structure ---------------------------------------------------------
    @property
    def order(self) -> int:
        """Polynomial order n of A', B', P."""
        return len(self.alpha) - 1

    @staticmethod
    def names(order: int = 8) -> list[str]:
        """Names of the entries of theta (Eq. 35 order) for polynomial order ``order``."""
        n1 = int(order) + 1
        return (
            list(SCALAR_NAMES)
            + [f"alpha_{j}" for j in range(n1)]
            + [f"beta_{j}" for j in range(n1)]
            + [f"p_{j}" for j in range(n1)]
        )

    @staticmethod
    def units(order: int = 8) -> dict[str, str]:
        """Units of every entry of theta (A' dimensionless, B' in N/V, P in N)."""
        out = {}
        for name in PredictorParams.names(order):
            if name in _SCALAR_UNITS:
                out[name] = _SCALAR_UNITS[name]
            else:
                out[name] = _GROUP_UNITS[name.rsplit("_", 1)[0]]
        return out

    @staticmethod
    def bounds(order: int = 8) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of theta (c_r, sigma, mu, mu_sd >= 0; 0 <= k0 < 1)."""
        n = len(PredictorParams.names(order))
        lo = np.full(n, -np.inf)
        hi = np.full(n, np.inf)
        lo[:5] = 0.0
        hi[3] = K0_MAX
        return lo, hi

    def to_vector(self) -> np.ndarray:
        """theta in Eq. 35 order."""
        return np.concatenate(
            [
                [self.c_r, self.sigma, self.mu, self.k0, self.mu_sd],
                self.alpha,
                self.beta,
                self.p,
            ]
        ).astype(float)

    @classmethod
    def from_vector(
        cls,
        theta,
        s_center: float = 0.0,
        s_half: float = 0.02,
        kappa: float = 0.5,
        include_load_inertia: bool = True,
    ) -> "PredictorParams":
        """Build from theta in Eq. 35 order; the order follows from its length."""
        theta = np.asarray(theta, dtype=float).ravel()
        if theta.size < 8 or (theta.size - 5) % 3:
            raise ValueError(f"theta has length {theta.size}; expected 5 + 3*(order+1)")
        n1 = (theta.size - 5) // 3
        return cls(
            *theta[:5],
            alpha=theta[5 : 5 + n1],
            beta=theta[5 + n1 : 5 + 2 * n1],
            p=theta[5 + 2 * n1 :],
            s_center=s_center,
            s_half=s_half,
            kappa=kappa,
            include_load_inertia=include_load_inertia,
        )

    def replace(self, **changes) -> "PredictorParams":
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d.update(changes)
        return PredictorParams(**d)

    # -- polynomials -------------------------------------------------------
    def scaled_position(self, s):
        return (np.asarray(s, dtype=float) - self.s_center) / self.s_half

    def A_prime(self, s):
        """A'(s) = A(s)/T_s [-]."""
        return np.polynomial.legendre.legval(self.scaled_position(s), np.asarray(self.alpha))

    def B_prime(self, s):
        """B'(s) = B(s)/T_s [N/V]."""
        return np.polynomial.legendre.legval(self.scaled_position(s), np.asarray(self.beta))

    def P(self, s):
        """Preload P(s) = F_p [N]."""
        return np.polynomial.legendre.legval(self.scaled_position(s), np.asarray(self.p))

    def _domain(self):
        return [self.s_center - self.s_half, self.s_center + self.s_half]

    def legendre_to_monomial(self, coef) -> np.ndarray:
        """Legendre coefficients (in x) -> monomials in s [m], highest power first."""
        poly = Legendre(np.asarray(coef, dtype=float), domain=self._domain()).convert(kind=Polynomial)
        c = np.zeros(len(coef))
        c[: poly.coef.size] = poly.coef
        return c[::-1].copy()

    @staticmethod
    def monomial_to_legendre(mono_high_first, s_center: float, s_half: float) -> np.ndarray:
        """Monomials in s [m] (highest power first) -> Legendre coefficients in x."""
        mono = np.asarray(mono_high_first, dtype=float)[::-1]
        leg = Polynomial(mono).convert(
            kind=Legendre, domain=[s_center - s_half, s_center + s_half]
        )
        c = np.zeros(mono.size)
        c[: leg.coef.size] = leg.coef
        return c

    def to_paper_monomials(self, T_s: float) -> dict[str, Any]:
        """Table-1 layout: monomials in metres, highest power first.

        ``alpha`` are the coefficients of A(s) = A'(s) T_s [s], ``beta`` of
        B(s) = B'(s) T_s [N s/V], ``p`` of P(s) [N]; scalars unchanged.
        """
        T_s = float(T_s)
        if not (T_s > 0):
            raise ValueError("T_s must be > 0 [s]")
        return {
            "c_r": self.c_r,
            "sigma": self.sigma,
            "mu": self.mu,
            "k0": self.k0,
            "mu_sd": self.mu_sd,
            "alpha": (self.legendre_to_monomial(self.alpha) * T_s).tolist(),
            "beta": (self.legendre_to_monomial(self.beta) * T_s).tolist(),
            "p": self.legendre_to_monomial(self.p).tolist(),
            "T_s": T_s,
            "position_unit": "m",
            "order": "highest power first",
            "units": {**_SCALAR_UNITS, **_PAPER_UNITS},
        }

    @classmethod
    def from_paper_monomials(
        cls,
        c_r,
        sigma,
        mu,
        k0,
        mu_sd,
        alpha,
        beta,
        p,
        T_s: float,
        s_center: float = 0.0,
        s_half: float = 0.02,
        kappa: float = 0.5,
        include_load_inertia: bool = True,
    ) -> "PredictorParams":
        """Load Table-1-like values (A [s], B [N s/V], P [N]; monomials in m, highest first)."""
        T_s = float(T_s)
        if not (T_s > 0):
            raise ValueError("T_s must be > 0 [s]")
        return cls(
            c_r,
            sigma,
            mu,
            k0,
            mu_sd,
            alpha=cls.monomial_to_legendre(np.asarray(alpha, float) / T_s, s_center, s_half),
            beta=cls.monomial_to_legendre(np.asarray(beta, float) / T_s, s_center, s_half),
            p=cls.monomial_to_legendre(p, s_center, s_half),
            s_center=s_center,
            s_half=s_half,
            kappa=kappa,
            include_load_inertia=include_load_inertia,
        )

    # -- serialisation -----------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict (plain floats, lists); inverse of :meth:`from_dict`."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        for k in ("alpha", "beta", "p"):
            d[k] = list(d[k])
        d["basis"] = "legendre in x = (s - s_center)/s_half"
        d["units"] = {**_SCALAR_UNITS, **_GROUP_UNITS, "s_center": "m", "s_half": "m", "kappa": "-"}
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "PredictorParams":
        keys = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in keys})


def example_params(order: int = 8, s_half: float = 0.02, kappa: float = 0.5) -> PredictorParams:
    """A synthetic, physically plausible parameter set (NOT the paper's Table 1).

    Used by tests and benchmarks: c_r = 6 N s/m, sigma = 0.2 N s/m,
    mu = 0.23, k0 = 0.4, mu_sd = 0.1 (the paper's 0.0994), preload P(s)
    ~5.1-6.4 N, A'(s) ~0.25-0.32, B'(s) ~5.6-6.6 mN/V. With m_s = 0.1 kg:
    stuck at 0 V, no-load speeds ~0.20 m/s at 220 V and ~0.31 m/s at 324 V,
    0.04-0.46 m/s over the paper's loads (+-0.09 kg all move), 3-23 % speed
    variation over a +-20 mm stroke, time constant m_eff/D ~17-32 ms.
    Coefficients beyond degree 3 are small (decaying), so lower orders are a
    fair truncation (``example_params(3)`` is the truncation).
    """
    n1 = int(order) + 1
    alpha = np.zeros(n1)
    beta = np.zeros(n1)
    p = np.zeros(n1)
    a_src = [0.30, 0.03, -0.02, 0.01, 0.004, -0.002, 0.001, 0.0005, -0.0003]
    b_src = [6.4e-3, 3.5e-4, -4.0e-4, 1.6e-4, 5.0e-5, -2.5e-5, 1.2e-5, -6e-6, 3e-6]
    p_src = [6.0, 0.5, -0.4, 0.2, 0.08, -0.04, 0.02, -0.01, 0.005]
    m = min(n1, len(a_src))
    alpha[:m] = a_src[:m]
    beta[:m] = b_src[:m]
    p[:m] = p_src[:m]
    return PredictorParams(
        c_r=6.0,
        sigma=0.2,
        mu=0.23,
        k0=0.40,
        mu_sd=0.10,
        alpha=alpha,
        beta=beta,
        p=p,
        s_center=0.0,
        s_half=s_half,
        kappa=kappa,
        include_load_inertia=True,
    )


# ---------------------------------------------------------------------------
# the force law
# ---------------------------------------------------------------------------


def effective_mass(params: PredictorParams, load, m_s):
    """m_eff = m_s + |m_load| (include_load_inertia) or m_s (paper's literal m)."""
    m_s = np.asarray(m_s, dtype=float)
    if params.include_load_inertia:
        return m_s + np.abs(np.asarray(load, dtype=float))
    return m_s + 0.0 * np.asarray(load, dtype=float)


def _position_terms(params: PredictorParams, s):
    """A'(s), B'(s), P(s) evaluated at positions s (any shape)."""
    x = np.asarray(params.scaled_position(s), dtype=float)
    V = legvander(x.ravel(), params.order).reshape(x.shape + (params.order + 1,))
    return V @ np.asarray(params.alpha), V @ np.asarray(params.beta), V @ np.asarray(params.p)


def _force_parts(params: PredictorParams, s, V0, m_load_p, m_s):
    """Split F(v') = -D v' + X + sign(-v') * Fr (drive coordinates).

    D  = c_r + sigma*(0.5 - A')                     [N s/m]
    X  = B' V0 + mu P [g1 - (pi/2) A' G] - 9.81 m'  [N]
    Fr = mu_sd (9.81 m_s + kappa P)                 [N]
    """
    Ap, Bp, P = _position_terms(params, s)
    g1 = drive_factor(params.k0)
    G = G_of_k0(params.k0)
    D = params.c_r + params.sigma * (0.5 - Ap)
    X = Bp * np.asarray(V0, float) + params.mu * P * (g1 - 0.5 * np.pi * Ap * G) - G_ACC * np.asarray(
        m_load_p, float
    )
    Fr = params.mu_sd * (G_ACC * np.asarray(m_s, float) + params.kappa * P)
    return D, X, Fr


def rest_sign(X, Fr):
    """Effective sign(-v') at rest: -clip(X/Fr, -1, 1) (static friction opposes X, capped)."""
    X = np.asarray(X, dtype=float)
    Fr = np.asarray(Fr, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(Fr > 0, -np.clip(X / np.where(Fr > 0, Fr, 1.0), -1.0, 1.0), -np.sign(X))
    return z


def _force(D, X, Fr, vp):
    """F(v') with Coulomb friction and the static-friction rule at v' = 0."""
    sg = np.sign(-vp)
    rest = vp == 0
    if np.any(rest):
        z0 = rest_sign(X, Fr)
        sg = np.where(rest, z0, sg)
        F = -D * vp + X + sg * Fr
        return np.where(rest & (np.abs(z0) < 1.0), 0.0, F)
    return -D * vp + X + sg * Fr


def _add_extra(X, extra_force):
    """X + extra_force (drive coordinates, N); ``None`` leaves X untouched."""
    if extra_force is None:
        return X
    return X + np.asarray(extra_force, dtype=float)


def derivative(params: PredictorParams, v, s, V0, load, direction, m_s, extra_force=None):
    """Slider acceleration dv/dt = d * F(v')/m_eff [m/s^2], signed data convention.

    ``v`` [m/s] and ``load`` [kg] in the data convention, ``direction`` +1/-1,
    ``m_s`` slider mass [kg]. All inputs broadcast. At v = 0 the guide
    friction is static (see the module docstring). ``extra_force`` [N, drive
    coordinates] is added to X (default None: none).
    """
    d = np.asarray(direction, dtype=float)
    vp = d * np.asarray(v, dtype=float)
    D, X, Fr = _force_parts(params, s, V0, d * np.asarray(load, float), m_s)
    X = _add_extra(X, extra_force)
    F = _force(D, X, Fr, vp)
    return d * F / effective_mass(params, load, m_s)


def step_drive(vp, D, X, Fr, h):
    """One Euler step in drive coordinates with the rest and reversal rules.

    ``vp`` drive speed, ``D, X, Fr`` from :func:`_force_parts`, ``h = dt/m_eff``.
    """
    vp = np.asarray(vp, dtype=float)
    z0 = rest_sign(X, Fr)
    sg = np.sign(-vp)
    rest = vp == 0
    stuck = np.abs(z0) < 1.0
    sg = np.where(rest, z0, sg)
    new = vp + h * (-D * vp + X + sg * Fr)
    new = np.where(rest & stuck, 0.0, new)
    cross = vp * new < 0
    if np.any(cross):
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(cross, vp / (vp - new), 0.0)
        from_rest = np.where(stuck, 0.0, h * (X + z0 * Fr))
        new = np.where(cross, (1.0 - frac) * from_rest, new)
    return new


def one_step(params: PredictorParams, v, s, V0, load, direction, dt, m_s, extra_force=None):
    """Eq. 28/29: v(k+1) = v(k) + dt/m_eff F(v(k)) (the paper's one-step prediction).

    Signed data convention; the rest/reversal rules of the module docstring
    apply only at or through v = 0. ``extra_force`` [N, drive coordinates]
    is added to X (default None: none).
    """
    d = np.asarray(direction, dtype=float)
    vp = d * np.asarray(v, dtype=float)
    D, X, Fr = _force_parts(params, s, V0, d * np.asarray(load, float), m_s)
    X = _add_extra(X, extra_force)
    h = np.asarray(dt, float) / effective_mass(params, load, m_s)
    return d * step_drive(vp, D, X, Fr, h)


def steady_state(params: PredictorParams, s, V0, load, direction, m_s, extra_force=None):
    """Closed-form fixed point v* = b/(1-a) of the affine map (m_eff and T_s cancel).

    Forward branch (v' > 0): v'* = (X - Fr)/D, consistent if X - Fr > 0;
    else backward branch (v' < 0): v'* = (X + Fr)/D, consistent if X + Fr < 0;
    else the slider is stuck (|X| <= Fr): v* = 0. Returns NaN where D <= 0
    (no stable equilibrium). Signed data convention. ``extra_force`` [N,
    drive coordinates] is added to X (default None: none).
    """
    d = np.asarray(direction, dtype=float)
    D, X, Fr = _force_parts(params, s, V0, d * np.asarray(load, float), m_s)
    X = _add_extra(X, extra_force)
    D, X, Fr = np.broadcast_arrays(D, X, Fr)
    fwd = X - Fr
    bwd = X + Fr
    with np.errstate(divide="ignore", invalid="ignore"):
        vp = np.where(fwd > 0, fwd / D, np.where(bwd < 0, bwd / D, 0.0))
    vp = np.where(D > 0, vp, np.nan)
    return d * vp


# ---------------------------------------------------------------------------
# run layout: flat samples <-> padded (time, run) arrays
# ---------------------------------------------------------------------------


class RunLayout:
    """Map between flat per-sample arrays (runs contiguous) and a packed layout.

    The recursions need all runs at the same time index together. Runs are
    sorted by decreasing length and the samples are *packed time-major*:
    block ``k`` (rows ``offs[k]:offs[k] + na[k]``) holds sample ``k`` of the
    ``na[k]`` runs that are that long, in sorted-run order. Because ``na`` is
    non-increasing, the runs alive at ``k + 1`` are a prefix of those at
    ``k``. This is equivalent to padding the runs to a common length but
    without computing on the padding. ``perm[j]`` is the flat sample index of
    packed row ``j``; ``to_packed(x) = x[perm]``, ``from_packed(y)`` inverts.
    """

    def __init__(self, run_index=None, n: int | None = None):
        if run_index is None:
            if n is None:
                raise ValueError("need run_index or n")
            labels = np.zeros(int(n), dtype=int)
        else:
            labels = np.asarray(run_index)
            if labels.ndim != 1:
                raise ValueError("run_index must be 1-D")
        n = labels.size
        if n == 0:
            raise ValueError("no samples")
        change = np.ones(n, dtype=bool)
        change[1:] = labels[1:] != labels[:-1]
        self.starts = np.flatnonzero(change)
        self.n = n
        self.R = self.starts.size
        self.lengths = np.diff(np.append(self.starts, n))
        self.K = int(self.lengths.max())
        self.run_of_sample = np.repeat(np.arange(self.R), self.lengths)
        self.kk = np.arange(n) - self.starts[self.run_of_sample]
        self.labels = labels[self.starts]
        self.is_last = np.zeros(n, dtype=bool)
        self.is_last[self.starts + self.lengths - 1] = True
        # packed time-major layout
        self.run_order = np.argsort(-self.lengths, kind="stable")
        rank = np.empty(self.R, dtype=int)
        rank[self.run_order] = np.arange(self.R)
        sorted_len = self.lengths[self.run_order]
        # na[k] = number of runs longer than k
        self.na = self.R - np.searchsorted(sorted_len[::-1], np.arange(self.K), side="right")
        self.offs = np.concatenate([[0], np.cumsum(self.na)])
        packed_pos = self.offs[self.kk] + rank[self.run_of_sample]
        self.perm = np.empty(n, dtype=int)
        self.perm[packed_pos] = np.arange(n)
        self.packed_pos = packed_pos

    def to_packed(self, flat):
        return np.asarray(flat)[self.perm]

    def from_packed(self, packed):
        return np.asarray(packed)[self.packed_pos]

    def step_dt(self, t):
        """dt_k = t[k+1] - t[k] within runs, 0 at the last sample of each run."""
        t = np.asarray(t, dtype=float)
        dt = np.zeros(self.n)
        dt[:-1] = np.diff(t)
        dt[self.is_last] = 0.0
        return dt


def _broadcast_flat(x, n, name):
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    arr = arr.ravel()
    if arr.size != n:
        raise ValueError(f"{name} has {arr.size} entries, expected {n} (or a scalar)")
    return arr


#: codes of :func:`packed_recursion`'s ``flags``
STEP_NORMAL, STEP_REVERSAL, STEP_STUCK = 0, 1, 2


def packed_recursion(lay: RunLayout, a, e, f, nd, z0, v0_sorted, flags=None):
    """Free-run recursion in the packed layout (loops over the time index only).

    ``v[k+1] = a[k] v[k] + e[k] + f[k] sg[k]`` with ``sg = sign(nd v)``
    (``nd = -d``: sign(-v') in the data convention), replaced at rest (v = 0)
    by the static-friction value ``z0`` (see :func:`rest_sign`); a stuck step
    at rest gives 0, a step that reverses the sign of v continues from rest
    for the rest of the step (see :func:`step_drive`). ``flags`` (int8,
    packed) if given receives STEP_REVERSAL / STEP_STUCK at the source row
    of such steps. ``v0_sorted``: start speeds in sorted-run order.
    """
    v = np.empty(lay.n)
    offs, na = lay.offs, lay.na
    v[: na[0]] = v0_sorted
    for k in range(lay.K - 1):
        m = na[k + 1]
        i0 = offs[k]
        i1 = offs[k + 1]
        cur = v[i0 : i0 + m]
        sg = np.sign(nd[i0 : i0 + m] * cur)
        rest = sg == 0
        anyrest = rest.any()
        if anyrest:
            sg[rest] = z0[i0 : i0 + m][rest]
        out = a[i0 : i0 + m] * cur
        out += e[i0 : i0 + m]
        out += f[i0 : i0 + m] * sg
        if anyrest:
            st = rest & (np.abs(sg) < 1.0)
            if st.any():
                out[st] = 0.0
                if flags is not None:
                    flags[i0 : i0 + m][st] = STEP_STUCK
        cross = out * cur < 0
        if cross.any():
            zc = z0[i0 : i0 + m][cross]
            cc = cur[cross]
            frac = cc / (cc - out[cross])
            inc_rest = e[i0 : i0 + m][cross] + f[i0 : i0 + m][cross] * zc
            inc_rest[np.abs(zc) < 1.0] = 0.0
            out[cross] = (1.0 - frac) * inc_rest
            if flags is not None:
                flags[i0 : i0 + m][cross] = np.where(np.abs(zc) < 1.0, STEP_STUCK, STEP_REVERSAL)
        v[i1 : i1 + m] = out
    return v


def packed_linear_recursion(lay: RunLayout, a, U, S0=None):
    """S[k+1] = a[k] S[k] + U[k] (matrix rows) in the packed layout, S[0] = S0 (default 0)."""
    S = np.empty((lay.n,) + U.shape[1:])
    offs, na = lay.offs, lay.na
    S[: na[0]] = 0.0 if S0 is None else S0
    for k in range(lay.K - 1):
        m = na[k + 1]
        i0 = offs[k]
        i1 = offs[k + 1]
        out = S[i1 : i1 + m]
        np.multiply(a[i0 : i0 + m, None], S[i0 : i0 + m], out=out)
        out += U[i0 : i0 + m]
    return S


def free_run_coefficients(params: PredictorParams, s, V0, load, direction, dt, m_s, extra_force=None):
    """Per-sample coefficients of the free-run recursion in the data convention.

    v[k+1] = a_k v[k] + e_k + f_k sign(-d_k v[k]) with a = 1 - h D, e = d h X,
    f = d h Fr, h = dt/m_eff (see :func:`_force_parts`); z0 = rest_sign(X, Fr).
    ``extra_force`` [N, drive coordinates] is added to X (default None: none).
    """
    d = np.asarray(direction, float)
    D, X, Fr = _force_parts(params, s, V0, d * np.asarray(load, float), m_s)
    X = _add_extra(X, extra_force)
    h = np.asarray(dt, float) / effective_mass(params, load, m_s)
    return 1.0 - h * D, d * h * X, d * h * Fr, rest_sign(X, Fr)


def free_run(
    params: PredictorParams,
    s,
    V0,
    load,
    direction,
    t,
    v_start,
    m_s,
    run_index=None,
    extra_force=None,
):
    """Free-run prediction along a MEASURED position trajectory.

    Every run starts from ``v_start`` (the measured speed of its first
    sample) and the predictor propagates its own speed with the per-sample
    step ``dt_k = t[k+1] - t[k]``; positions, voltages and loads are taken
    from the data. Inputs are flat per-sample arrays (runs contiguous,
    labelled by ``run_index``; ``None`` = one run). ``v_start`` may be a
    scalar, one value per run, or a per-sample array (its first sample of
    each run is used). Runs are aligned on a common time index internally
    (packed time-major layout, see :class:`RunLayout`: padding without
    computing on the pads) and the recursion loops over the time index
    only, vectorised across runs. ``extra_force`` (scalar or one value per
    sample) [N, drive coordinates] is added to X (default None: none).
    Returns the predicted speed per sample [m/s], signed data convention.
    """
    s = np.asarray(s, dtype=float).ravel()
    n = s.size
    lay = RunLayout(run_index, n)
    V0 = _broadcast_flat(V0, n, "V0")
    load = _broadcast_flat(load, n, "load")
    d = _broadcast_flat(direction, n, "direction")
    t = _broadcast_flat(t, n, "t")
    m_s_arr = _broadcast_flat(m_s, n, "m_s")
    vs = np.asarray(v_start, dtype=float).ravel()
    if vs.size == 1:
        v0 = np.full(lay.R, float(vs[0]))
    elif vs.size == n:
        v0 = vs[lay.starts]
    elif vs.size == lay.R:
        v0 = vs.copy()
    else:
        raise ValueError("v_start must be a scalar, one value per run or one per sample")
    dt = lay.step_dt(t)
    if extra_force is not None:
        extra_force = _broadcast_flat(extra_force, n, "extra_force")
    a, e, f, z0 = free_run_coefficients(params, s, V0, load, d, dt, m_s_arr, extra_force)
    pk = lay.to_packed
    vpk = packed_recursion(lay, pk(a), pk(e), pk(f), pk(-d), pk(z0), v0[lay.run_order])
    return lay.from_packed(vpk)


# ---------------------------------------------------------------------------
# synthetic data
# ---------------------------------------------------------------------------


def design_grid(
    voltages: Iterable[float] = (220.0, 260.0, 300.0, 324.0),
    loads: Iterable[float] = (-0.09, -0.07, -0.05, -0.03, 0.0, 0.03, 0.05, 0.07, 0.09),
    directions: Iterable[int] = (1, -1),
):
    """Full-factorial design (pandas DataFrame: voltage_V, load_kg, direction).

    The default is the paper's rig design: 4 voltages x 9 loads x 2 directions = 72 runs.
    """
    import pandas as pd

    rows = [
        {"voltage_V": float(V), "load_kg": float(m), "direction": int(d)}
        for V in voltages
        for m in loads
        for d in directions
    ]
    return pd.DataFrame(rows)


def _design_arrays(design):
    import pandas as pd

    if isinstance(design, pd.DataFrame):
        df = design
    else:
        rows = []
        for row in design:
            if isinstance(row, Mapping):
                rows.append(dict(row))
            else:
                V, m, dd = row
                rows.append({"voltage_V": V, "load_kg": m, "direction": dd})
        df = pd.DataFrame(rows)
    for col in ("voltage_V", "load_kg", "direction"):
        if col not in df.columns:
            raise ValueError(f"design needs column '{col}'")
    d = df["direction"].to_numpy(dtype=float)
    if not np.all(np.isin(d, (-1.0, 1.0))):
        raise ValueError("design direction must be +1 or -1")
    return (
        df["voltage_V"].to_numpy(dtype=float),
        df["load_kg"].to_numpy(dtype=float),
        d,
    )


def simulate_dataset(
    params: PredictorParams,
    design,
    m_s: float,
    dt: float = 1e-3,
    stroke: Sequence[float] = (-0.02, 0.02),
    noise_std: float = 0.0,
    seed=None,
    max_duration: float = 5.0,
    pause: float = 0.5,
    extra_force=None,
):
    """Virtual traverses with the predictor itself (for tests and benchmarks).

    Each design row (voltage_V, load_kg, direction) is one run: the slider
    starts at rest at the stroke end opposite to its direction and v, s are
    integrated with the predictor step (``v[k+1] = one_step(v[k])``,
    ``s[k+1] = s[k] + dt (v[k] + v[k+1])/2``) until the position leaves the
    stroke or ``max_duration`` elapses; the last sample inside the stroke is
    the last sample of the run (a stuck run records zeros for
    ``max_duration``). :func:`free_run` along the recorded positions from
    v_start = 0 reproduces the noise-free speeds to rounding. ``time_s`` is continuous across runs
    with ``pause`` seconds between runs. ``noise_std`` [m/s] adds white
    Gaussian noise to ``speed_m_s`` only (positions stay exact).
    ``extra_force`` (optional callable) adds a drive-coordinate force [N] to
    X at every step: it is called with a mapping of per-run arrays under the
    data-format column names ``run``, ``position_m``, ``voltage_V``,
    ``direction``, ``load_kg``, ``speed_m_s`` (the noise-free state at the
    start of the step; no ``time_s``) and returns one force per run (or a
    scalar). A feature function written for data frames with
    ``np.asarray(df[col])`` works on it, e.g. ``lambda c: features(c) @ phi``.
    Returns a DataFrame with the data-format columns.
    """
    import pandas as pd

    V0, load, d = _design_arrays(design)
    R = V0.size
    lo, hi = float(stroke[0]), float(stroke[1])
    if not hi > lo:
        raise ValueError("stroke must be (low, high) with high > low [m]")
    nmax = int(round(max_duration / dt)) + 1
    s0 = np.where(d > 0, lo, hi)
    s = s0.copy()
    v = np.zeros(R)
    m_s_arr = np.full(R, float(m_s))
    S = [s.copy()]
    Vv = [v.copy()]
    active = np.ones(R, dtype=bool)
    length = np.ones(R, dtype=int)
    runs = np.arange(R)
    for k in range(1, nmax):
        ef = None
        if extra_force is not None:
            cols = {"run": runs, "position_m": s, "voltage_V": V0, "direction": d, "load_kg": load,
                    "speed_m_s": v}
            ef = np.broadcast_to(np.asarray(extra_force(cols), dtype=float).reshape(-1), (R,))
        v_new = one_step(params, v, s, V0, load, d, dt, m_s_arr, extra_force=ef)
        s_new = s + 0.5 * dt * (v + v_new)
        inside = (s_new >= lo) & (s_new <= hi)
        active &= inside
        if not active.any():
            break
        v = np.where(active, v_new, v)
        s = np.where(active, s_new, s)
        length = length + active
        S.append(s.copy())
        Vv.append(v.copy())
    S = np.array(S)
    Vv = np.array(Vv)
    rng = np.random.default_rng(seed)
    frames = []
    t0 = 0.0
    for r in range(R):
        L = int(length[r])
        t = t0 + dt * np.arange(L)
        speed = Vv[:L, r].copy()
        frames.append(
            pd.DataFrame(
                {
                    "time_s": t,
                    "run": r,
                    "position_m": S[:L, r],
                    "voltage_V": V0[r],
                    "direction": int(d[r]),
                    "load_kg": load[r],
                    "speed_m_s": speed,
                }
            )
        )
        t0 = t[-1] + pause
    df = pd.concat(frames, ignore_index=True)
    if noise_std > 0:
        df["speed_m_s"] = df["speed_m_s"].to_numpy() + rng.normal(0.0, noise_std, len(df))
    return df
