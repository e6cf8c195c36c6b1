"""The likelihood problem of the pure-slip predictor family (``PredictorIdentifier(model="pure_slip")``).

Same parameter vector (Eq. 35 order), residuals, criteria, noise model and
uncertainty as :class:`l1b2.ident.problem.LikelihoodProblem`; only the drive
force differs (:mod:`l1b2.predictor.pureslip`): its slip ratio
``k = c_k v'``, ``c_k = sigma / (pi B'(s) V0)``, follows the state, so

* the free run is the non-linear recursion
  :func:`l1b2.predictor.pureslip.packed_slip_recursion` (loop over the time
  index, vectorised across runs);
* the forward sensitivities keep the linear recursion
  ``S[k+1] = a[k] S[k] + h d dF/dtheta`` with ``a = 1 - h (D - dX/dv')``
  (the slope of the slip force enters ``a``) and ``dF/dtheta`` of
  :meth:`SlipForceCore.dF`, which adds the chain through k
  (``dk/dsigma = k/sigma``, ``dk/dbeta_j = -k L_j / B'``);
* k0 has no effect (its column is 0: it is reported as unidentifiable unless
  pinned, which :data:`RECOMMENDED_FIXED_PURE_SLIP` does), while sigma, which
  sets the tip-speed scale of k, is determined by the data.

With the response's contact law (:func:`l1b2.predictor.frequency.contact_angle`,
``SampleData.contact_a``) each row has its half contact angle ``a``: ``D = c_r + sigma (a/pi - A')``,
the drive term ``B' V0 sin a`` and the Coulomb share ``h(k, a)`` in place of ``g1(k)``
(:mod:`l1b2.predictor.pureslip`); ``a`` depends on the response only, not on theta, so the Jacobian
in theta keeps its form with these factors.

Approximation (gradient only, never the likelihood): the derivative of the
start-speed gain keeps only D's parameters, as for Eq. 29, and a step that
reverses the motion uses the slip force at its start.
"""

from __future__ import annotations

import numpy as np

from ..predictor.model import rest_sign, step_drive
from ..predictor.pureslip import (contact_slip_factor, contact_slip_slope, inverse_tip_speed, packed_slip_recursion,
                                  slip_factors, slip_force)
from ..predictor.simulate import STEP_REVERSAL, STEP_STUCK
from ..units import G_M_S2
from .problem import ForceCore, LikelihoodProblem

__all__ = ["RECOMMENDED_FIXED_PURE_SLIP", "SlipForceCore", "PureSlipProblem", "make_problem"]

#: ``fixed="recommended"`` for the pure-slip family: k0 (no effect), mu (scale of P) and mu_sd (practically
#: unidentifiable); sigma is free (it sets the tip speed of the slip ratio)
RECOMMENDED_FIXED_PURE_SLIP = ("k0", "mu", "mu_sd")


class SlipForceCore(ForceCore):
    """Force terms of the pure-slip family: :meth:`terms` gives X without the slip force, :meth:`slip` the rest."""

    compiled_dF = False     # the compiled loop is Eq. 29's force
    #: half contact angle per row [rad] (the contact law), or None: pi/2
    contact = None

    def _contact(self, rows):
        """``(a/pi, sin a)`` on ``rows`` (``(0.5, 1.0)`` without the contact law)."""
        if self.contact is None:
            return 0.5, 1.0
        a = self.contact if rows is None else self.contact[rows]
        return a / np.pi, np.sin(a)

    def slip(self, theta, rows=None):
        """``mu P`` [N], ``A'`` [-], ``B'`` [N/V], ``c_k`` [s/m] and ``P`` [N] at ``theta`` (on ``rows``)."""
        n1 = self.n1
        L = self.L if rows is None else self.L[rows]
        V0 = self.V0 if rows is None else self.V0[rows]
        Ap = L @ theta[5 : 5 + n1]
        Bp = L @ theta[5 + n1 : 5 + 2 * n1]
        P = L @ theta[5 + 2 * n1 : 5 + 3 * n1]
        return theta[2] * P, Ap, Bp, inverse_tip_speed(theta[1], Bp, V0), P

    def terms(self, theta):
        """A', P, D, ``X_lin`` (drive force without the slip part: B' V0 - 9.81 m' + extras) and Fr."""
        n1 = self.n1
        c_r, sig, _, _, musd = theta[:5]
        Ap = self.L @ theta[5 : 5 + n1]
        P = self.L @ theta[5 + 2 * n1 : 5 + 3 * n1]
        a_pi, sin_a = self._contact(None)
        X = (self.L @ theta[5 + n1 : 5 + 2 * n1]) * self.V0 * sin_a - G_M_S2 * self.mp
        if self.E is not None:
            X = X + self.E @ theta[self.p_theta :]
        return Ap, P, c_r + sig * (a_pi - Ap), X, musd * (G_M_S2 * self.m_s + self.kappa * P)

    def dF(self, theta, vp, sg, Ap, P, cols, rows=None):
        """dF/dtheta[cols] at drive speed ``vp`` with the slip ratio of that speed (chain through k included)."""
        n1 = self.n1
        L = self.L if rows is None else self.L[rows]
        V0 = self.V0 if rows is None else self.V0[rows]
        c_r, sig, mu, k0, musd = theta[:5]
        Bp = L @ theta[5 + n1 : 5 + 2 * n1]
        c_k = inverse_tip_speed(sig, Bp, V0)
        with np.errstate(invalid="ignore", over="ignore"):   # inf * 0 (no tip speed, at rest): k = 0 below
            k = np.clip(np.where(vp > 0, np.nan_to_num(c_k * vp, posinf=1.0), 0.0), 0.0, 1.0)
        g1, G, dg1, dG = slip_factors(k)
        a_pi, sin_a = self._contact(rows)
        if self.contact is not None:
            a = self.contact if rows is None else self.contact[rows]
            g1, dg1 = contact_slip_factor(k, a), contact_slip_slope(k, a)
        inside = (k > 0) & (k < 1)
        dXs_dk = np.where(inside, mu * P * (dg1 - 0.5 * np.pi * Ap * dG), 0.0)
        p_all = self.p_theta + (0 if self.E is None else self.E.shape[1])
        out = np.empty((vp.size, p_all))
        out[:, 0] = -vp
        with np.errstate(divide="ignore", invalid="ignore"):
            out[:, 1] = -(a_pi - Ap) * vp + np.where(inside, dXs_dk * k / sig, 0.0)
            kb = np.where(inside, -dXs_dk * k / np.where(Bp != 0, Bp, 1.0), 0.0)
        out[:, 2] = P * (g1 - 0.5 * np.pi * Ap * G)
        out[:, 3] = 0.0
        out[:, 4] = sg * (G_M_S2 * self.m_s + self.kappa * P)
        out[:, 5 : 5 + n1] = L * (sig * vp - mu * P * 0.5 * np.pi * G)[:, None]
        out[:, 5 + n1 : 5 + 2 * n1] = L * (V0 * sin_a + kb)[:, None]
        out[:, 5 + 2 * n1 : self.p_theta] = L * (mu * (g1 - 0.5 * np.pi * Ap * G) + sg * musd * self.kappa)[:, None]
        if self.E is not None:
            out[:, self.p_theta :] = self.E if rows is None else self.E[rows]
        cols = np.asarray(cols, dtype=int)
        return out if (cols.size == p_all and np.array_equal(cols, np.arange(p_all))) else out[:, cols]


class PureSlipProblem(LikelihoodProblem):
    """:class:`~l1b2.ident.problem.LikelihoodProblem` with the pure-slip drive force (module docstring)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        c = self.core
        self.core = SlipForceCore(c.L, c.V0, c.mp, c.h, c.d, c.m_s, c.kappa, c.E)
        a = getattr(self.data, "contact_a", None)
        if a is not None:
            self.core.contact = self.lay.to_packed(a) if self.criterion == "free_run" else a[self.idx]

    def evaluate(self, theta):
        """As :meth:`LikelihoodProblem.evaluate`; ``X`` is the drive force at each row's speed, ``a`` its step slope."""
        if self._cache_theta is not None and np.array_equal(theta, self._cache_theta):
            return self._cache
        core = self.core
        Ap, P, D, X_lin, Fr = core.terms(theta)
        muP, _, _, c_k, _ = core.slip(theta)
        ca = core.contact
        X_rest = X_lin + slip_force(np.zeros_like(X_lin), muP, Ap, c_k, ca)[0]
        z0 = rest_sign(X_rest, Fr)
        if self.criterion == "free_run":
            flags = np.zeros(self.lay.n, dtype=np.int8)
            with np.errstate(over="ignore", invalid="ignore"):
                v, X, dX = packed_slip_recursion(self.lay.offs, self.lay.na, step_drive, D, X_lin, muP, Ap, c_k, Fr,
                                                 core.h, core.d, self.v0, flags, a=ca)
                a = 1.0 - core.h * (D - dX)
            vsrc = v
        else:
            vp0 = core.d * self.vprev
            Xs, dX, _ = slip_force(vp0, muP, Ap, c_k, ca)
            X = X_lin + Xs
            with np.errstate(over="ignore", invalid="ignore"):
                v = core.d * step_drive(vp0, D, X, Fr, core.h)
                eul = vp0 + core.h * (-D * vp0 + X + np.sign(-vp0) * Fr)
            a = None
            vsrc = self.vprev
            flags = np.zeros(v.size, dtype=np.int8)
            stuck = np.abs(X) < Fr
            cross = (vp0 != 0) & (vp0 * eul < 0)
            flags[cross] = STEP_REVERSAL
            flags[(cross | (vp0 == 0)) & stuck] = STEP_STUCK
        return self._store(theta, core, v, a, vsrc, flags, Ap, P, D, X, Fr, z0)


def make_problem(drive_law: str, *args, **kwargs) -> LikelihoodProblem:
    """The likelihood problem of a model family (``"eq29"`` or ``"pure_slip"``), same arguments as LikelihoodProblem."""
    return (PureSlipProblem if drive_law == "pure_slip" else LikelihoodProblem)(*args, **kwargs)
