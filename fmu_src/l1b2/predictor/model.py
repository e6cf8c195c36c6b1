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

Families
--------
``PredictorParams.drive_law`` selects the model family: ``"eq29"`` (default,
everything above) or ``"pure_slip"``, the same force with the slip ratio of
the state ``k = sigma v' / (pi B'(s) V0)`` in place of k0
(:mod:`l1b2.predictor.pureslip`; :func:`drive_force`, :func:`speed_slope`).
:func:`derivative`, :func:`one_step`, :func:`steady_state` and the free run of
:mod:`l1b2.predictor.simulate` dispatch on it; :func:`force_parts` is always
Eq. 29's split.

Extra forces
------------
:func:`derivative`, :func:`one_step`, :func:`free_run`,
:func:`free_run_coefficients`, :func:`steady_state` and
:func:`simulate_dataset` accept an optional ``extra_force`` (default
``None`` = the model above, unchanged): a force [N] in *drive coordinates*
(positive = in the drive direction) added to the drive force ``X`` of every
sample, ``X_total = X + extra_force``. It enters the static-friction rule
like any other part of X. This is how candidate physical effects the paper's
model lacks are carried (see :class:`l1b2.ident.extra.ExtraForces`).

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
from typing import Any, Mapping

import numpy as np
from numpy.polynomial import Legendre, Polynomial
from numpy.polynomial.legendre import legvander

from ..units import G_M_S2
from .pureslip import inverse_tip_speed, slip_force, steady_drive_speed

__all__ = [
    "SCALAR_NAMES",
    "DRIVE_LAWS",
    "PredictorParams",
    "G_of_k0",
    "drive_factor",
    "rest_sign",
    "step_drive",
    "derivative",
    "one_step",
    "steady_state",
    "example_params",
    "viscous_damping",
]


#: names of the five scalar parameters, in Eq. 35 order
SCALAR_NAMES = ("c_r", "sigma", "mu", "k0", "mu_sd")

_SCALAR_UNITS = {"c_r": "N s/m", "sigma": "N s/m", "mu": "-", "k0": "-", "mu_sd": "-"}
_GROUP_UNITS = {"alpha": "-", "beta": "N/V", "p": "N"}
_PAPER_UNITS = {"alpha": "s", "beta": "N s/V", "p": "N"}

#: the predictor's model families: Eq. 29 as published (slip ratio frozen at k0) and the pure-slip drive
#: force whose slip ratio follows the state (:mod:`l1b2.predictor.pureslip`, same parameters; k0 unused)
DRIVE_LAWS = ("eq29", "pure_slip")

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
    are model settings, not identified (see module docstring). ``drive_law``
    is the model family (:data:`DRIVE_LAWS`): ``"eq29"`` (default, the
    paper's Eq. 29) or ``"pure_slip"`` (the drive force of
    :mod:`l1b2.predictor.pureslip`, slip ratio ``k = sigma v'/(pi B' V0)``
    instead of the constant k0, which it does not use).
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
    drive_law: str = "eq29"

    def __post_init__(self):
        if self.drive_law not in DRIVE_LAWS:
            raise ValueError(f"PredictorParams.drive_law must be one of {DRIVE_LAWS}, got {self.drive_law!r}")
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
        drive_law: str = "eq29",
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
            drive_law=drive_law,
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


def position_terms(params: PredictorParams, s):
    """A'(s), B'(s), P(s) evaluated at positions s (any shape)."""
    x = np.asarray(params.scaled_position(s), dtype=float)
    V = legvander(x.ravel(), params.order).reshape(x.shape + (params.order + 1,))
    return V @ np.asarray(params.alpha), V @ np.asarray(params.beta), V @ np.asarray(params.p)


def force_parts(params: PredictorParams, s, V0, m_load_p, m_s, contact=None):
    """Split F(v') = -D v' + X + sign(-v') * Fr (drive coordinates).

    D  = c_r + sigma*(0.5 - A')                     [N s/m]
    X  = B' V0 + mu P [g1 - (pi/2) A' G] - 9.81 m'  [N]
    Fr = mu_sd (9.81 m_s + kappa P)                 [N]

    ``contact`` (pure-slip family with the contact law: the half contact angle a per sample [rad],
    :func:`l1b2.predictor.frequency.contact_angle`): ``0.5 -> a/pi`` in D and ``B' V0 -> B' V0 sin a``
    in X (:mod:`l1b2.predictor.pureslip`); None is a = pi/2.
    """
    Ap, Bp, P = position_terms(params, s)
    g1 = drive_factor(params.k0)
    G = G_of_k0(params.k0)
    sin_a = 1.0 if contact is None else np.sin(contact)
    D = _damping(params, Ap, contact)
    X = Bp * np.asarray(V0, float) * sin_a + params.mu * P * (g1 - 0.5 * np.pi * Ap * G) - G_M_S2 * np.asarray(
        m_load_p, float
    )
    Fr = params.mu_sd * (G_M_S2 * np.asarray(m_s, float) + params.kappa * P)
    return D, X, Fr


def _damping(params: PredictorParams, Ap, contact=None):
    """``c_r + sigma (a/pi - A')`` [N s/m] from A' at the samples (``a = pi/2`` without a contact angle)."""
    a_pi = 0.5 if contact is None else np.asarray(contact, float) / np.pi
    return params.c_r + params.sigma * (a_pi - Ap)


def viscous_damping(params: PredictorParams, s, contact=None):
    """The model's viscous damping ``D(s) = c_r + sigma (a/pi - A'(s))`` [N s/m] at positions ``s`` [m].

    ``F = -D v' + ...``: the slider's own damping ``c_r`` plus the speed slope of Eq. 29's drive force
    (:func:`force_parts`' ``D``); ``contact``: the half contact angle per sample [rad] of the pure-slip family's
    contact law (None: ``a = pi/2``, Eq. 29's 0.5). The pure-slip family's slip force adds its own slope in
    ``v'`` on top (:func:`l1b2.predictor.pureslip.slip_force`), which this does not include.
    """
    return _damping(params, position_terms(params, s)[0], contact)


def slip_terms(params: PredictorParams, s, V0):
    """Pure-slip inputs at s: ``mu P`` [N], ``A'`` [-], ``c_k`` [s/m] and Eq. 29's frozen term ``mu P [g1(k0) - pi/2 A' G(k0)]``."""
    Ap, Bp, P = position_terms(params, s)
    muP = params.mu * P
    frozen = muP * (drive_factor(params.k0) - 0.5 * np.pi * Ap * G_of_k0(params.k0))
    return muP, Ap, inverse_tip_speed(params.sigma, Bp, V0), frozen


def drive_force(params: PredictorParams, s, V0, X, vp):
    """The drive force at drive speed ``vp``: X itself for Eq. 29, the slip ratio of the state for pure slip.

    ``X`` is :func:`force_parts`' X (plus any extra force); for
    ``drive_law="pure_slip"`` its frozen-k0 term is replaced by
    :func:`l1b2.predictor.pureslip.slip_force` at ``k = c_k vp``.
    """
    if params.drive_law == "eq29":
        return X
    muP, Ap, c_k, frozen = slip_terms(params, s, V0)
    return X - frozen + slip_force(vp, muP, Ap, c_k)[0]


def speed_slope(params: PredictorParams, s, V0, vp):
    """``dX/dv'`` of the drive force at drive speed ``vp`` [N s/m]: 0 for Eq. 29, the slip force's slope for pure slip."""
    if params.drive_law == "eq29":
        return np.zeros(np.broadcast(np.asarray(s, float), np.asarray(V0, float), np.asarray(vp, float)).shape)
    muP, Ap, c_k, _ = slip_terms(params, s, V0)
    return slip_force(vp, muP, Ap, c_k)[1]


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


def add_extra_force(X, extra_force):
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
    D, X, Fr = force_parts(params, s, V0, d * np.asarray(load, float), m_s)
    X = drive_force(params, s, V0, add_extra_force(X, extra_force), vp)
    F = _force(D, X, Fr, vp)
    return d * F / effective_mass(params, load, m_s)


def step_drive(vp, D, X, Fr, h):
    """One Euler step in drive coordinates with the rest and reversal rules.

    ``vp`` drive speed, ``D, X, Fr`` from :func:`force_parts`, ``h = dt/m_eff``.
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
    D, X, Fr = force_parts(params, s, V0, d * np.asarray(load, float), m_s)
    X = drive_force(params, s, V0, add_extra_force(X, extra_force), vp)
    h = np.asarray(dt, float) / effective_mass(params, load, m_s)
    return d * step_drive(vp, D, X, Fr, h)


def steady_state(params: PredictorParams, s, V0, load, direction, m_s, extra_force=None, contact=None):
    """Closed-form fixed point v* = b/(1-a) of the affine map (m_eff and T_s cancel).

    Forward branch (v' > 0): v'* = (X - Fr)/D, consistent if X - Fr > 0;
    else backward branch (v' < 0): v'* = (X + Fr)/D, consistent if X + Fr < 0;
    else the slider is stuck (|X| <= Fr): v* = 0. Returns NaN where D <= 0
    (no stable equilibrium). Signed data convention. ``extra_force`` [N,
    drive coordinates] is added to X (default None: none). For
    ``drive_law="pure_slip"`` the forward branch is the root of the
    non-linear force (:func:`l1b2.predictor.pureslip.steady_drive_speed`); ``contact`` as in
    :func:`force_parts` (pure-slip family only).
    """
    d = np.asarray(direction, dtype=float)
    D, X, Fr = force_parts(params, s, V0, d * np.asarray(load, float), m_s, contact)
    X = add_extra_force(X, extra_force)
    if params.drive_law == "pure_slip":
        muP, Ap, c_k, frozen = slip_terms(params, s, V0)
        return d * steady_drive_speed(D, X - frozen, muP, Ap, c_k, Fr, contact=contact)
    D, X, Fr = np.broadcast_arrays(D, X, Fr)
    fwd = X - Fr
    bwd = X + Fr
    with np.errstate(divide="ignore", invalid="ignore"):
        vp = np.where(fwd > 0, fwd / D, np.where(bwd < 0, bwd / D, 0.0))
    vp = np.where(D > 0, vp, np.nan)
    return d * vp
