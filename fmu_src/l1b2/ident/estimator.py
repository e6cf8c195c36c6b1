"""Maximum-likelihood identification of the reduced predictor (paper Eq. 32, 35).

:class:`PredictorIdentifier` fits theta of :mod:`l1b2.predictor.model` (Eq. 35
order) to measured traverses in the data format of ``shared/data-format.md``.

Method
------
* **Criterion.** ``free_run``: residual ``v_pred_free(k) - v_meas(k)`` where
  the predictor propagates its own speed along the measured positions from
  the measured first speed of each run (the stricter figure). ``one_step``:
  ``v_pred(k+1 | v_meas(k)) - v_meas(k+1)`` within runs (the paper's use).
  An optional boolean ``mask`` selects which samples' residuals enter the
  likelihood; the free-run recursion always runs over all samples.
* **Likelihood (Eq. 32).** Gaussian; the residual covariance is block
  diagonal by run, ``R_r (I + g g^T)``: ``R_r`` is one variance per run
  (``noise="per_run"``, floored at 10 % of the median run variance) or one
  common variance, and the rank-one term is the noise of the *measured*
  start speed, which the free run propagates through the recursion
  (``g = d v_pred / d v_start``, same variance as any other sample;
  ``start_noise=True``). Ignoring it made the stderr of the B' coefficients
  up to ~25 % too small in simulation. Iterated as Eq. 32 asks for unknown R: fit
  theta with R fixed (a weighted least-squares problem, solved by
  :func:`scipy.optimize.least_squares`, ``trf`` with bounds), re-estimate R
  (and g) from the residuals, repeat until R changes by < 1 % (at most
  ``max_outer`` times).
* **Conditioning.** Positions are scaled to [-1, 1] and A', B', P are Legendre
  series (see :mod:`l1b2.predictor.model`); the optimiser works on ``z = theta /
  scale`` with ``scale`` the typical magnitude of each parameter (group
  magnitude for polynomial coefficients) taken from the data-driven centre.
* **Analytic Jacobian.** Free run: forward sensitivities
  ``S[k+1] = S[k] (1 + h dF/dv) + h dF/dtheta`` (``h = dt/m_eff``), vectorised
  over runs and parameters (loop over the time index only; the rest and
  reversal steps of :func:`l1b2.predictor.model.step_drive` have their own exact
  derivatives). One step: the sensitivity is ``h dF/dtheta`` at the measured
  speed. Both are tested against finite differences.
* **Data-driven initial guess.** For v' > 0 the force is
  ``F = -D(s) v' + B'(s) V0 + C(s) - 9.81 m_load'`` with ``D = c_r +
  sigma (0.5 - A')`` and ``C = mu P (g1 - pi/2 A' G) - mu_sd (9.81 m_s +
  kappa P)``. Its one-step equation error is *linear* in the Legendre
  coefficients of D, B', C (C has order 2n). Summed over short windows
  (``m_eff dv' + 9.81 m' dt = sum dt (-D v' + B' V0 + C)``, ~10 ms, which
  averages speed noise), one linear least-squares gives D(s), B'(s), C(s).
  They are mapped to Eq. 35 parameters with conventional values for the
  directions the data cannot determine (sigma from the spread of D, k0 = 0.5,
  mu = 0.2, mu_sd = 0.05, or the user's ``fixed`` values), then the Eq. 35
  structure is fitted to the same window equation error by variable
  projection (c_r, beta, p are linear) from many scrambled Sobol starts.
  The distinct minima of this cheap problem seed the global search.
* **Global search.** Like MATLAB's GlobalSearch: stage 1 scatters many trial
  points and scores them cheaply (the equation error above); then local
  ``least_squares`` runs of the true criterion start from the distinct
  equation-error minima (best first) and from Sobol points in the box
  ``z0 +- start_spread * max(|z0|, 0.05)`` around the best, ``n_starts`` in
  all. Each gets ``explore_nfev`` evaluations, the ``n_refine`` best are run
  to convergence. Every start's cost, nfev, status and message are recorded
  in ``convergence_``. A local run also stops when the cost (= -log
  likelihood + const) decreased by < ``stat_tol`` over ``stat_window``
  iterations: along practically non-identifiable directions trf otherwise
  creeps for hundreds of iterations without a statistically relevant gain.

Identifiability (findings)
--------------------------
*Structural* (exact for any data with v' > 0 and known m_s). The data
determine the functions D(s), B'(s) and C(s) above (B' via the voltage
dependence; the absolute force scale via the known load weights and mass).
Writing ``a = mu g1(k0) - mu_sd kappa`` and ``b = mu (pi/2) G(k0)``::

    D(s) = c_r + sigma/2 - sigma A'(s)
    C(s) = P(s) (a - b A'(s)) - 9.81 m_s mu_sd

is invariant under three one-parameter groups:

1. ``sigma -> r sigma, A' - alpha_0 -> (A' - alpha_0)/r`` with c_r, alpha_0,
   mu, k0 adjusted (keeps sigma A'(s) up to a constant, b/sigma and
   a - b alpha_0);
2. ``alpha_0 -> alpha_0 + delta/sigma, c_r -> c_r + delta`` with mu, k0
   adjusted so that ``a - b alpha_0`` is unchanged;
3. ``P -> lambda P`` with mu, k0 (and thus a, b) scaled by 1/lambda.

With all 3n+8 parameters varied (the paper's setting) the Fisher matrix has
exactly three zero singular values (tested on noise-free data: relative
singular values ~1e-16); only beta (B') and mu_sd are identifiable, c_r,
sigma, mu, k0, every alpha and every p only in combinations.
:attr:`PredictorIdentifier.unidentifiable_` reports the null directions
numerically and the affected parameters get ``stderr = inf``.

*Practical*. (a) mu_sd enters only through the constant ``9.81 m_s mu_sd``
in C(s) (its P-proportional part is absorbed by a); it is separable only
through the polynomial structure of C and has a relative singular value of
~7e-7 (order 3, 12 runs) to ~5e-8 (order 8, 72 runs): practically not identifiable, and
its value barely changes the fit. (b) The split of the order-2n polynomial
C(s) into the factors P(s) and (a - b A'(s)) is informed only by the small
position variation of D(s) = c_r + sigma (0.5 - A'); with sigma, k0, mu and
mu_sd pinned the Fisher matrix has full rank (smallest relative singular
value ~7e-5 at order 3, ~7e-6 at order 8 in the synthetic rig) but the
likelihood can be *bimodal* in the preload scale / alpha_0 / c_r (two
factorisations fitting within ~1 log-likelihood unit, e.g. p_0 = 0.7 N vs
6 N): locally identifiable, not globally. ``alternative_optima_`` reports
such a second optimum when the global search finds one.

*Recommendation.* ``fixed="recommended"`` pins sigma, k0, mu (one per
structural direction; any values give the same predictions) and mu_sd
(practically unidentifiable; use the guide's datasheet value). The fitted
c_r, alpha, p are then conditional on those pins. Pinning in addition the
mean preload p_0 (only meaningful when sigma, k0, mu are physical values)
removes the bimodality; that configuration is well conditioned (relative
singular value ~3e-4 at order 3) and its 95 % intervals have the nominal
coverage in simulation (tests/test_identify.py).

Extra forces ("closing the loop")
---------------------------------
``PredictorIdentifier(extra=ExtraForces(...))`` adds candidate physical
effects the paper's model lacks as extra forces with their own parameters
phi: in drive coordinates ``X_total = X + features(df) @ phi`` for every
sample (nothing else changes: Fr, D, the sign, rest and reversal rules, the
mass). Features are computed once per data frame and never depend on theta.
phi is identified jointly with theta: it enters the window equation error
(linear in phi, extra columns of the linear fit), the analytic Jacobian
(dF/dphi = features), bounds, scaling (phi's scale makes the force ~1 % of
the typical drive force), ``fixed``, the SVD/Fisher uncertainty and the
AIC/BIC count. ``init=`` (e.g. a baseline's ``params_``) warm-starts the
search; with ``n_starts=1`` it is one local refinement: first phi given theta
(the baseline can sit on a kink of the free run where the joint step cannot
move), then jointly; the warm runs also stop when the projected gain over the
remaining budget is below 50 * ``stat_tol`` log-likelihood units. It is a
*local* refinement: the baseline's theta was bent to absorb the missing
effect and may lie in another basin of the (multi-modal, see above)
likelihood (and on a kink, and under noise variances fitted to the missing
effect); ``n_starts >= 2`` fits two tracks, the warm start and the
data-driven search with ``n_starts - 1`` starts, and keeps the higher final
log-likelihood (``convergence_["tracks"]``).

*Confounding.* A feature that is (nearly) a function of position alone is
largely reproducible by the position polynomials of Eq. 35 (C(s) has order
2n): its parameter is then weakly determined or not at all. The fit reports
it: ``stderr = inf`` and a null direction in ``unidentifiable_`` when exactly
confounded, otherwise a large ``extra_confounding_[name]["variance_inflation"]``
(joint variance over the variance if theta were known; ``explained_by_theta``
= 1 - 1/inflation; ``most_correlated`` theta parameters), entries in
``weak_directions_`` and a [[Warnings]] line in :meth:`fit_report`.
Direction-dependent or voltage-dependent features are not confounded this way.

Uncertainty
-----------
Covariance from the Fisher information ``(J^T R^-1 J)^-1`` at the optimum
via the SVD of the weighted (whitened), scaled Jacobian. Singular values
below ``svd_rtol * s_max`` (default 1e-8) mark directions the data cannot
separate; every parameter with a component > 1e-6 in that null space gets
``stderr = inf`` (not determined) -- never a pseudo-inverse value. For the
other parameters the pseudo-inverse restricted to the identified subspace is
exact (they are estimable functions). Directions with relative singular
values below ``weak_rtol`` (1e-5) are listed in ``weak_directions_``.

Free-run residuals are autocorrelated when the model is not exact, which
makes the white-noise Fisher covariance too optimistic. ``stderr_`` inflates
the noise variance of each run by the AR(1) long-run variance factor
``(1 + rho)/(1 - rho)``, rho = lag-1 autocorrelation of that run's
(whitened) residuals, clipped to [0, 0.99] so the correction never shrinks
an interval. Chosen over a run-block sandwich estimator because the sandwich
needs many more runs than parameters to be stable (72 runs vs 32 parameters
at order 8, far fewer runs in small experiments), whereas the AR(1) factor
uses every sample and is exact for slowly varying sensitivities under AR(1)
errors. ``stderr_fisher_`` keeps the plain white-noise value. Intervals use
the t distribution with ``n_eff - k`` degrees of freedom, ``n_eff = sum_r
n_r / f_r`` (AR(1)-effective sample count) and k = number of varied
identifiable parameters. (One-step residuals are MA(1)-like, negatively
correlated; with rho clipped at 0 their intervals are conservative.)

Information criteria: ``loglik_`` is the Gaussian log-likelihood at the final
(theta, R) (including the start-speed term); ``aic_ = 2k - 2 loglik``, ``bic_ = k ln(n) - 2 loglik`` with n
the number of residuals and k counting only varied, identifiable theta
parameters (the noise variances are not counted; they are the same for all
models compared on the same data with the same ``noise`` option).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np
import numpy.polynomial.legendre as npleg
from numpy.polynomial.legendre import legvander
from scipy import stats
from scipy.linalg import qr as _qr
from scipy.optimize import least_squares

from ..data.metrics import (
    evaluation_mask,  # re-exported: the data-format evaluation mask
)
from ..errors import IdentificationError
from ..predictor.model import (
    SCALAR_NAMES,
    G_of_k0,
    PredictorParams,
    ddrive_factor_dk0,
    dG_dk0,
    drive_factor,
    rest_sign,
    step_drive,
)
from ..predictor.model import steady_state as _steady_state
from ..predictor.simulate import (
    STEP_REVERSAL,
    STEP_STUCK,
    RunLayout,
    packed_linear_recursion,
    packed_recursion,
)
from ..units import G_M_S2

__all__ = ["PredictorIdentifier", "ExtraForces", "evaluation_mask", "RECOMMENDED_FIXED"]

REQUIRED_COLUMNS = ("time_s", "run", "position_m", "voltage_V", "direction", "load_kg")

#: parameters pinned by ``fixed="recommended"``: one per structural null
#: direction (sigma, k0, mu) plus the practically unidentifiable mu_sd
RECOMMENDED_FIXED = ("sigma", "k0", "mu", "mu_sd")

#: conventional values for the directions the data cannot determine (the pin
#: when such a parameter is fixed without a value, and the centre of the
#: global search when it is varied)
CONVENTIONAL = {"k0": 0.5, "mu": 0.2, "mu_sd": 0.05}

_NULL_TOL = 1e-6


# ---------------------------------------------------------------------------
# data
# ---------------------------------------------------------------------------


def _label(x):
    """A run label for messages and JSON (numpy scalars -> Python)."""
    return x.item() if isinstance(x, np.generic) else x


def _opt_tuple(x, n, name, default):
    if x is None:
        return tuple(float(default) for _ in range(n))
    arr = np.atleast_1d(np.asarray(x, dtype=float)).ravel()
    if arr.size != n:
        raise IdentificationError(f"ExtraForces.{name} has {arr.size} entries, expected {n} (one per name)")
    return tuple(float(a) for a in arr)


@dataclass(frozen=True)
class ExtraForces:
    """Extra exogenous forces with their own parameters (identified jointly with theta).

    The model's drive force becomes ``X_total = X + features(df) @ phi`` in
    drive coordinates (positive = in the drive direction): ``features`` maps a
    data-format DataFrame to an ``(n_samples, n_extra)`` array of forces [N]
    per unit of each parameter (a 1-D array is accepted for one parameter).
    Features may use any column of the data frame but never theta. Nothing
    else of the model changes (Fr, D, the sign, rest and reversal rules,
    the mass).

    ``names`` / ``units``: one per parameter (names must differ from the Eq. 35
    names). ``start``: start values of phi for a warm start (``init``) when
    ``init_extra`` is not given (default zeros); the data-driven start takes
    phi from the joint linear equation-error fit. ``lower`` / ``upper``:
    bounds (default -inf / +inf). ``features`` cannot be serialised:
    :meth:`PredictorIdentifier.from_dict` takes it again (``extra=``).
    """

    names: tuple
    units: tuple
    features: Callable
    start: tuple | None = None
    lower: tuple | None = None
    upper: tuple | None = None
    description: str = ""

    def __post_init__(self):
        names = (self.names,) if isinstance(self.names, str) else tuple(self.names)
        names = tuple(str(n) for n in names)
        if not names:
            raise IdentificationError("ExtraForces.names is empty")
        if len(set(names)) != len(names):
            raise IdentificationError(f"ExtraForces.names are not unique: {names}")
        units = (self.units,) if isinstance(self.units, str) else tuple(self.units)
        units = tuple(str(u) for u in units)
        if len(units) != len(names):
            raise IdentificationError(f"ExtraForces: {len(units)} units for {len(names)} names")
        if not callable(self.features):
            raise IdentificationError("ExtraForces.features must be callable: df -> (n_samples, n_extra) array")
        n = len(names)
        lower = _opt_tuple(self.lower, n, "lower", -np.inf)
        upper = _opt_tuple(self.upper, n, "upper", np.inf)
        if any(not (lo < hi) for lo, hi in zip(lower, upper)) or any(math.isnan(x) for x in lower + upper):
            raise IdentificationError(f"ExtraForces: need lower < upper, got {lower} / {upper}")
        start = None if self.start is None else _opt_tuple(self.start, n, "start", 0.0)
        if start is not None and not all(math.isfinite(x) for x in start):
            raise IdentificationError(f"ExtraForces.start must be finite, got {start}")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "units", units)
        object.__setattr__(self, "lower", None if self.lower is None else lower)
        object.__setattr__(self, "upper", None if self.upper is None else upper)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "description", str(self.description or ""))

    @property
    def n(self) -> int:
        """Number of extra parameters."""
        return len(self.names)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        lo = np.full(n, -np.inf) if self.lower is None else np.asarray(self.lower, float)
        hi = np.full(n, np.inf) if self.upper is None else np.asarray(self.upper, float)
        return lo, hi

    def start_vector(self) -> np.ndarray:
        return np.zeros(self.n) if self.start is None else np.asarray(self.start, float)

    def evaluate(self, df) -> np.ndarray:
        """``features(df)`` validated: float array of shape (len(df), n), all finite."""
        n_rows = len(df)
        try:
            E = np.asarray(self.features(df), dtype=float)
        except IdentificationError:
            raise
        except Exception as exc:  # the user's callable: report what failed
            raise IdentificationError(f"extra forces {list(self.names)}: features(df) failed: {exc}") from exc
        if E.ndim == 1 and self.n == 1:
            E = E[:, None]
        if E.ndim == 0 and self.n == 1:
            E = np.full((n_rows, 1), float(E))
        if E.shape != (n_rows, self.n):
            raise IdentificationError(
                f"extra forces: features(df) returned shape {E.shape}, expected ({n_rows}, {self.n}) "
                f"(one column per parameter {list(self.names)})"
            )
        bad = ~np.isfinite(E)
        if bad.any():
            i, j = (int(a[0]) for a in np.nonzero(bad))
            raise IdentificationError(
                f"extra forces: feature of '{self.names[j]}' is not finite (first at row {i + 1})"
            )
        return np.ascontiguousarray(E)


class _Data:
    """Validated flat arrays of a data-format DataFrame."""

    def __init__(self, df, mask=None):
        try:
            cols = list(df.columns)
        except AttributeError as exc:
            raise IdentificationError("data must be a pandas DataFrame in the data format") from exc
        missing = [c for c in REQUIRED_COLUMNS if c not in cols]
        if missing:
            raise IdentificationError(f"data: missing column(s) {missing}")
        n = len(df)
        if n == 0:
            raise IdentificationError("data: no samples")
        self.run = df["run"].to_numpy()
        self.layout = RunLayout(self.run)
        lay = self.layout
        if len(np.unique(self.run)) != lay.R:
            raise IdentificationError("data: column 'run': rows of one run must be contiguous")
        arrays = {}
        for c in ("time_s", "position_m", "voltage_V", "direction", "load_kg"):
            try:
                arrays[c] = df[c].to_numpy(dtype=float)
            except (TypeError, ValueError) as exc:
                raise IdentificationError(f"data: column '{c}' is not numeric") from exc
        if "speed_m_s" in cols:
            try:
                arrays["speed_m_s"] = df["speed_m_s"].to_numpy(dtype=float)
            except (TypeError, ValueError) as exc:
                raise IdentificationError("data: column 'speed_m_s' is not numeric") from exc
            self.speed_derived = False
        else:
            arrays["speed_m_s"] = None
            self.speed_derived = True
        for c, a in arrays.items():
            if a is None:
                continue
            bad = ~np.isfinite(a)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise IdentificationError(
                    f"data: run {_label(self.run[i])} has NaN/inf in column '{c}' "
                    f"(first at row {i + 1}); remove or repair that run"
                )
        self.t = arrays["time_s"]
        self.s = arrays["position_m"]
        self.V0 = arrays["voltage_V"]
        self.d = arrays["direction"]
        self.load = arrays["load_kg"]
        if not np.all(np.isin(self.d, (-1.0, 1.0))):
            i = int(np.flatnonzero(~np.isin(self.d, (-1.0, 1.0)))[0])
            raise IdentificationError(f"data: column 'direction' must be +1 or -1 (row {i + 1})")
        dtt = np.diff(self.t)
        within = ~lay.is_last[:-1]
        if np.any(dtt[within] <= 0):
            i = int(np.flatnonzero((dtt <= 0) & within)[0])
            raise IdentificationError(f"data: column 'time_s' not increasing within run {_label(self.run[i])}")
        if arrays["speed_m_s"] is None:
            v = np.empty(n)
            for r in range(lay.R):
                sl = slice(lay.starts[r], lay.starts[r] + lay.lengths[r])
                if lay.lengths[r] >= 2:
                    v[sl] = np.gradient(self.s[sl], self.t[sl])
                else:
                    v[sl] = 0.0
            self.v = v
        else:
            self.v = arrays["speed_m_s"]
        if mask is None:
            self.mask = np.ones(n, dtype=bool)
        else:
            m = np.asarray(mask)
            if m.shape != (n,):
                raise IdentificationError(f"mask has shape {m.shape}, expected ({n},)")
            self.mask = m.astype(bool)
        self.n = n


# ---------------------------------------------------------------------------
# model core on arbitrary sample sets
# ---------------------------------------------------------------------------


class _Core:
    """Force terms and their theta-derivatives on one set of samples."""

    def __init__(self, L, V0, mp, h, d, m_s, kappa, E=None):
        self.L = np.ascontiguousarray(L)
        self.V0 = V0
        self.mp = mp
        self.h = h
        self.d = d
        self.hd = h * d
        self.m_s = float(m_s)
        self.kappa = float(kappa)
        self.n1 = L.shape[1]
        #: length of the Eq. 35 part; entries beyond it are the extra-force parameters phi
        self.p_theta = 5 + 3 * self.n1
        #: extra-force features (drive coordinates, N per unit phi), or None
        self.E = None if E is None else np.ascontiguousarray(E, dtype=float)

    def terms(self, theta):
        n1 = self.n1
        c_r, sig, mu, k0, musd = theta[:5]
        Ap = self.L @ theta[5 : 5 + n1]
        Bp = self.L @ theta[5 + n1 : 5 + 2 * n1]
        P = self.L @ theta[5 + 2 * n1 : 5 + 3 * n1]
        g1 = float(drive_factor(k0))
        G = float(G_of_k0(k0))
        D = c_r + sig * (0.5 - Ap)
        X = Bp * self.V0 + mu * P * (g1 - 0.5 * np.pi * Ap * G) - G_M_S2 * self.mp
        if self.E is not None:
            X = X + self.E @ theta[self.p_theta :]
        Fr = musd * (G_M_S2 * self.m_s + self.kappa * P)
        return Ap, P, D, X, Fr

    def dF(self, theta, vp, sg, Ap, P, cols, rows=None):
        """dF/dtheta[cols] (drive coordinates) at drive speed vp (on ``rows`` if given).

        ``sg`` is the effective sign(-v') (static-friction value at rest).
        """
        n1 = self.n1
        L = self.L if rows is None else self.L[rows]
        V0 = self.V0 if rows is None else self.V0[rows]
        c_r, sig, mu, k0, musd = theta[:5]
        g1 = float(drive_factor(k0))
        G = float(G_of_k0(k0))
        dg1 = float(ddrive_factor_dk0(k0))
        dG = float(dG_dk0(k0))
        cols = np.asarray(cols)
        out = np.empty((vp.size, cols.size))
        group_a = group_p = None
        for j, c in enumerate(cols):
            if c == 0:
                out[:, j] = -vp
            elif c == 1:
                out[:, j] = -(0.5 - Ap) * vp
            elif c == 2:
                out[:, j] = P * (g1 - 0.5 * np.pi * Ap * G)
            elif c == 3:
                out[:, j] = mu * P * (dg1 - 0.5 * np.pi * Ap * dG)
            elif c == 4:
                out[:, j] = sg * (G_M_S2 * self.m_s + self.kappa * P)
            elif c < 5 + n1:
                if group_a is None:
                    group_a = sig * vp - mu * P * 0.5 * np.pi * G
                out[:, j] = L[:, c - 5] * group_a
            elif c < 5 + 2 * n1:
                out[:, j] = L[:, c - 5 - n1] * V0
            elif c >= self.p_theta:
                # extra force: X += E phi, dF/dphi = E (whatever the speed)
                out[:, j] = self.E[:, c - self.p_theta] if rows is None else self.E[rows, c - self.p_theta]
            else:
                if group_p is None:
                    group_p = mu * (g1 - 0.5 * np.pi * Ap * G) + sg * musd * self.kappa
                out[:, j] = L[:, c - 5 - 2 * n1] * group_p
        return out


class _Problem:
    """Residuals and analytic Jacobian of one criterion on one data set."""

    def __init__(self, data: _Data, order, kappa, include_load_inertia, criterion, s_center, s_half, m_s,
                 E=None):
        self.data = data
        self.criterion = criterion
        lay = data.layout
        self.lay = lay
        x = (data.s - s_center) / s_half
        L = legvander(x, order)
        m_eff = m_s + (np.abs(data.load) if include_load_inertia else 0.0)
        dt = lay.step_dt(data.t)
        h = dt / m_eff
        mp = data.d * data.load
        self.m_s = m_s
        if criterion == "free_run":
            pk = lay.to_packed
            self.core = _Core(pk(L), pk(data.V0), pk(mp), pk(h), pk(data.d), m_s, kappa,
                              None if E is None else pk(E))
            self.nd = -self.core.d
            self.v0 = data.v[lay.starts][lay.run_order]
            mask_p = pk(data.mask)
            self.sel = np.flatnonzero(mask_p)
            self.z = pk(data.v)[self.sel]
            self.run_sel = pk(lay.run_of_sample)[self.sel]
            self.sample_sel = lay.perm[self.sel]  # flat sample index of each residual
        elif criterion == "one_step":
            idx = np.flatnonzero(~lay.is_last)
            self.idx = idx
            self.core = _Core(L[idx], data.V0[idx], mp[idx], h[idx], data.d[idx], m_s, kappa,
                              None if E is None else E[idx])
            self.vprev = data.v[idx]
            keep = data.mask[idx + 1]
            self.sel = np.flatnonzero(keep)
            self.z = data.v[idx + 1][self.sel]
            self.run_sel = lay.run_of_sample[idx + 1][self.sel]
            self.sample_sel = (idx + 1)[self.sel]
        else:
            raise IdentificationError(f"criterion must be 'free_run' or 'one_step', got {criterion!r}")
        self._cache_theta = None
        self._cache = None

    # prediction on the evaluation set (packed for free_run, pairs for one_step)
    def _evaluate(self, theta):
        if self._cache_theta is not None and np.array_equal(theta, self._cache_theta):
            return self._cache
        core = self.core
        Ap, P, D, X, Fr = core.terms(theta)
        z0 = rest_sign(X, Fr)
        if self.criterion == "free_run":
            a = 1.0 - core.h * D
            flags = np.zeros(self.lay.n, dtype=np.int8)
            with np.errstate(over="ignore", invalid="ignore"):
                v = packed_recursion(self.lay, a, core.hd * X, core.hd * Fr, self.nd, z0, self.v0, flags)
            vsrc = v
        else:
            vp0 = core.d * self.vprev
            with np.errstate(over="ignore", invalid="ignore"):
                vnew = step_drive(vp0, D, X, Fr, core.h)
            v = core.d * vnew
            a = None
            vsrc = self.vprev
            # classify the steps like packed_recursion does
            flags = np.zeros(v.size, dtype=np.int8)
            stuck = np.abs(z0) < 1.0
            rest = vp0 == 0
            with np.errstate(over="ignore", invalid="ignore"):
                eul = vp0 + core.h * (-D * vp0 + X + np.sign(-vp0) * Fr)
            cross = (~rest) & (vp0 * eul < 0)
            flags[cross] = STEP_REVERSAL
            flags[(cross | rest) & stuck] = STEP_STUCK
        vp = core.d * vsrc
        sg = np.sign(-vp)
        rest = vp == 0
        if rest.any():
            sg[rest] = z0[rest]
        res = {"v": v, "a": a, "Ap": Ap, "P": P, "sg": sg, "flags": flags, "D": D, "X": X, "Fr": Fr,
               "z0": z0, "vp": vp}
        self._cache_theta = np.array(theta, copy=True)
        self._cache = res
        return res

    def residual(self, theta):
        v = self._evaluate(theta)["v"]
        return v[self.sel] - self.z

    def _sensitivity_rows(self, theta, c, rows, cols):
        """Step sensitivities on ``rows``: returns (a_rows, U_rows) in the data convention.

        Normal step: dv[k+1] = a dv[k] + h d dF/dtheta. Reversal within the
        step (see predictor.step_drive): v'[k+1] = h F_rest + v' F_rest/F with
        F the moving force at v' and F_rest = X + z0 Fr. Stuck: 0.
        """
        core = self.core
        vp = c["vp"][rows]
        h = core.h[rows]
        d = core.d[rows]
        D, X, Fr, z0 = c["D"][rows], c["X"][rows], c["Fr"][rows], c["z0"][rows]
        Ap, P = c["Ap"][rows], c["P"][rows]
        sgm = np.sign(-vp)
        Fk = -D * vp + X + sgm * Fr
        Frest = X + z0 * Fr
        dFk = core.dF(theta, vp, sgm, Ap, P, cols, rows=rows)
        dFr = core.dF(theta, np.zeros_like(vp), z0, Ap, P, cols, rows=rows)
        with np.errstate(divide="ignore", invalid="ignore"):
            a_r = (Frest / Fk) * (1.0 + vp * D / Fk)
            U = (h + vp / Fk)[:, None] * dFr - (vp * Frest / Fk**2)[:, None] * dFk
        U *= d[:, None]
        return a_r, U

    def jacobian(self, theta, cols):
        """d residual / d theta[cols] (unweighted): forward sensitivities for the free run."""
        c = self._evaluate(theta)
        core = self.core
        flags = c["flags"]
        if self.criterion == "free_run":
            U = core.dF(theta, c["vp"], c["sg"], c["Ap"], c["P"], cols)
            U *= core.hd[:, None]
            a = c["a"]
            if flags.any():
                a = a.copy()
                rev = np.flatnonzero(flags == STEP_REVERSAL)
                if rev.size:
                    a[rev], U[rev] = self._sensitivity_rows(theta, c, rev, cols)
                st = flags == STEP_STUCK
                U[st] = 0.0
                a[st] = 0.0
            with np.errstate(over="ignore", invalid="ignore"):
                S = packed_linear_recursion(self.lay, a, U)
            return S[self.sel]
        sub = self.sel
        U = core.dF(theta, c["vp"][sub], c["sg"][sub], c["Ap"][sub], c["P"][sub], cols, rows=sub)
        U *= core.hd[sub, None]
        fl = flags[sub]
        if fl.any():
            rev = np.flatnonzero(fl == STEP_REVERSAL)
            if rev.size:
                U[rev] = self._sensitivity_rows(theta, c, sub[rev], cols)[1]
            U[fl == STEP_STUCK] = 0.0
        return U

    def start_gain(self, theta):
        """g = d v_pred / d v_start on the residual rows (free run; zeros for one_step).

        The free run starts from the *measured* first speed, whose noise
        propagates as ``g * delta0`` into every residual of the run.
        """
        if self.criterion != "free_run":
            return np.zeros(self.sel.size)
        c = self._evaluate(theta)
        a = c["a"]
        flags = c["flags"]
        if flags.any():
            a = a.copy()
            rev = np.flatnonzero(flags == STEP_REVERSAL)
            if rev.size:
                a[rev] = self._sensitivity_rows(theta, c, rev, [0])[0]
            a[flags == STEP_STUCK] = 0.0
        with np.errstate(over="ignore", invalid="ignore"):
            g = packed_linear_recursion(self.lay, a, np.zeros((self.lay.n, 1)), S0=1.0)
        g = g[self.sel, 0]
        return np.where(np.isfinite(g), g, 0.0)

    def predict_all(self, theta):
        """Predictions for every sample (flat order); one_step: NaN at run starts."""
        v = self._evaluate(theta)["v"]
        if self.criterion == "free_run":
            return self.lay.from_packed(v)
        out = np.full(self.data.n, np.nan)
        out[self.idx + 1] = v
        return out


# ---------------------------------------------------------------------------
# data-driven initial guess
# ---------------------------------------------------------------------------


def _reduced_linear_fit(data: _Data, order, m_s, include_load_inertia, s_center, s_half, use_mask=True, E=None):
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


def _reduced_of_theta(theta, order, m_s, kappa, jac=False):
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
    dCp = -mu * hG * np.einsum("j,ijk->ki", al, T)
    dCp[:n1, :] += (mu * g1 - musd * kappa) * np.eye(n1)
    Jg[iC, 5 + 2 * n1 : p_theta] = dCp
    return g, Jg


def _grid(order):
    ng = 4 * order + 4
    return np.cos(np.pi * (np.arange(ng) + 0.5) / ng)


def _map_reduced_to_theta(dco, bco, cco, fixed, order, m_s, kappa):
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


def _equation_error_fit(theta_start, varied, red, order, m_s, kappa, n_starts, seed, spread=1.0, floor=0.25,
                        max_nfev=100):
    """Fit the Eq. 35 structure to the window-integrated equation error.

    Minimises ``|M g(theta) - y|^2`` (``g`` = reduced coefficients of D, B',
    C implied by theta, see :func:`_reduced_of_theta`), evaluated cheaply
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
            return th, Rc @ _reduced_of_theta(th, order, m_s, kappa) - qy
        th[lin] = 0.0
        g0, Jg = _reduced_of_theta(th, order, m_s, kappa, jac=True)
        A = Rc @ Jg[:, lin]
        b = qy - Rc @ g0
        x, *_ = np.linalg.lstsq(A, b, rcond=1e-13)
        th[lin] = x
        return th, A @ x - b

    if idx.size == 0:
        return [(float("nan"), theta_start)]
    if non.size == 0:
        th, r = project(theta_start)
        return [(0.5 * float(r @ r), _clip_theta(th, order))]
    lo, hi = PredictorParams.bounds(order)
    scale = _param_scale(theta_start, order)[non]
    lb, ub = lo[non] / scale, hi[non] / scale

    def fun(zv):
        th = theta_start.copy()
        th[non] = zv * scale
        return project(th)[1]

    z0 = _strictly_inside(theta_start[non] / scale, lb, ub)
    starts = [z0] + [_strictly_inside(z, lb, ub) for z in _sobol_box(z0, n_starts - 1, seed, spread, floor)]
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
        out.append((cost, _clip_theta(th, order)))
    return out


def _clip_theta(theta, order):
    """Clip the Eq. 35 part of theta into its bounds (extra entries, if any, unchanged)."""
    lo, hi = PredictorParams.bounds(order)
    out = np.array(theta, dtype=float, copy=True)
    out[: lo.size] = np.clip(out[: lo.size], lo, hi)
    return out


def _param_scale(theta, order):
    """Typical magnitudes: |value| (with floors) for scalars, group max for polynomials."""
    n1 = order + 1
    scale = np.ones(theta.size)  # entries beyond Eq. 35 (extra forces) are scaled by the caller
    floors = {"c_r": 1e-3, "sigma": 1e-4, "mu": 1e-2, "k0": 0.05, "mu_sd": 1e-2}
    for i, nm in enumerate(SCALAR_NAMES):
        scale[i] = max(abs(theta[i]), floors[nm])
    for g in range(3):
        sl = slice(5 + g * n1, 5 + (g + 1) * n1)
        scale[sl] = max(float(np.max(np.abs(theta[sl]))), 1e-12)
    return scale


def _strictly_inside(z, lb, ub):
    z = np.clip(z, lb, ub)
    fin = np.isfinite(ub)
    top = np.where(fin, ub - 1e-9 * np.maximum(np.abs(np.where(fin, ub, 0.0)), 1.0), np.inf)
    return np.minimum(z, top)


def _sobol_box(z0, n, seed, spread, floor=0.05):
    """n scrambled-Sobol points in z0 +- spread*max(|z0|, floor)."""
    if n <= 0:
        return []
    from scipy.stats import qmc

    m = int(math.ceil(math.log2(n))) if n > 1 else 0
    sob = qmc.Sobol(d=z0.size, scramble=True, seed=seed)
    u = sob.random_base2(m)[:n]
    hw = spread * np.maximum(np.abs(z0), floor)
    return [z0 + (2.0 * row - 1.0) * hw for row in u]


try:  # least_squares(callback=...) exists from scipy 1.16
    import inspect as _inspect

    _HAS_CALLBACK = "callback" in _inspect.signature(least_squares).parameters
except (TypeError, ValueError):  # pragma: no cover
    _HAS_CALLBACK = False


class _StatStop:
    """least_squares callback: stop when the cost stalls statistically.

    The cost is 0.5 * sum(whitened residuals^2) = -log-likelihood + const. In
    flat, curved valleys along practically non-identifiable directions trf
    creeps with tiny steps for hundreds of iterations; once the cost
    decreased by less than ``tol`` (log-likelihood units, default 0.01, far
    below the 1.92 of a 95 % likelihood-ratio interval) over ``window``
    iterations, further progress cannot matter statistically.

    With ``budget`` (the iteration budget of the run; used for warm starts
    only) the run also stops when the *projected* gain -- the decrease rate
    over the last ``window`` iterations times the iterations left -- is below
    ``budget_tol`` (default 0.5 log-likelihood units): even if the creep
    went on to the end of the budget, it could not matter statistically.
    """

    def __init__(self, tol, window, budget=None, budget_tol=0.5):
        self.tol = float(tol)
        self.window = int(window)
        self.budget = None if budget is None else int(budget)
        self.budget_tol = float(budget_tol)
        self.costs = []
        self.reason = None

    def __call__(self, intermediate_result):
        self.costs.append(float(intermediate_result.cost))
        if len(self.costs) > self.window:
            dec = self.costs[-self.window - 1] - self.costs[-1]
            if dec < self.tol:
                self.reason = "window"
                raise StopIteration
            if self.budget is not None:
                left = max(self.budget - len(self.costs), 0)
                if dec / self.window * left < self.budget_tol:
                    self.reason = "projected"
                    raise StopIteration


class _NoiseModel:
    """Gaussian residual covariance: per run ``R_r (I + g g^T)``.

    ``R_r`` is the run's measurement-noise variance (``"per_run"``, floored
    at 10 % of the median, or ``"common"``). ``g = d v_pred / d v_start`` is
    the propagation of the noise of the measured start speed into the free
    run (rank-one, same variance as every other sample); ``g = 0`` for the
    one-step criterion or ``start_noise=False``. Whitening uses
    ``(I + g g^T)^(-1/2) = I - c g g^T``, ``c = (1 - (1 + g.g)^(-1/2)) / g.g``.
    """

    def __init__(self, run_sel, n_runs, mode):
        self.run_sel = run_sel
        self.n_runs = n_runs
        self.mode = mode
        self.n = run_sel.size
        self.counts = np.bincount(run_sel, minlength=n_runs)
        self.R = np.ones(n_runs)
        self.g = None
        self.gg = np.zeros(n_runs)
        self._sqrtR = np.ones(self.n)

    def set_start_gain(self, g):
        from scipy.sparse import csr_matrix

        g = np.asarray(g, float)
        self.g = g
        gg = np.bincount(self.run_sel, weights=g * g, minlength=self.n_runs)
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.where(gg > 0, (1.0 - 1.0 / np.sqrt(1.0 + gg)) / gg, 0.0)
        self.gg = gg
        self.cg = c[self.run_sel] * g
        self.G = csr_matrix((g, (self.run_sel, np.arange(self.n))), shape=(self.n_runs, self.n))

    def W(self, x):
        """(I + g g^T)^(-1/2) x, run by run (x: vector or matrix with residual rows)."""
        if self.g is None:
            return x
        proj = self.G @ x
        if x.ndim == 1:
            return x - self.cg * proj[self.run_sel]
        return x - self.cg[:, None] * proj[self.run_sel]

    def weighted(self, x):
        y = self.W(x)
        if y.ndim == 1:
            return y / self._sqrtR
        return y / self._sqrtR[:, None]

    def update_R(self, r):
        """ML variances from the whitened residuals; returns the max relative change."""
        w = self.W(r)
        ss = np.bincount(self.run_sel, weights=w * w, minlength=self.n_runs)
        cnt = self.counts
        if self.mode == "common":
            new = np.full(self.n_runs, max(float(np.sum(ss)) / max(self.n, 1), 1e-300))
        else:
            var = np.where(cnt > 0, ss / np.maximum(cnt, 1), np.nan)
            med = float(np.nanmedian(var)) if np.any(cnt > 0) else 1.0
            if not np.isfinite(med) or med <= 0:
                med = 1e-300
            new = np.where(np.isfinite(var), np.maximum(var, 0.1 * med), med)
        with np.errstate(divide="ignore", invalid="ignore"):
            change = float(np.nanmax(np.abs(new / self.R - 1.0)))
        self.R = new
        self._sqrtR = np.sqrt(new[self.run_sel])
        return change

    def loglik(self, r):
        w = self.W(r)
        quad = np.bincount(self.run_sel, weights=w * w, minlength=self.n_runs)
        has = self.counts > 0
        R = self.R[has]
        return float(
            -0.5 * np.sum(self.counts[has] * np.log(2 * np.pi * R) + np.log1p(self.gg[has]) + quad[has] / R)
        )


# ---------------------------------------------------------------------------
# the estimator
# ---------------------------------------------------------------------------


def _json_float(x):
    x = float(x)
    if math.isnan(x):
        return None
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return x


def _from_json_float(x):
    if x is None:
        return float("nan")
    if isinstance(x, str):
        return float(x)
    return float(x)


def _describe_direction(vec_z, pivot, vidx, sv_scale, names):
    """A direction in scaled coordinates as physical parameter changes per unit change of ``pivot``."""
    dtheta = vec_z * sv_scale
    dtheta = dtheta / dtheta[pivot]
    zmag = np.abs(vec_z)
    members = np.flatnonzero(zmag > 1e-3 * zmag.max())
    members = members[np.argsort(-zmag[members])]
    terms = [(names[vidx[i]], float(dtheta[i])) for i in members]
    return {
        "pivot": names[vidx[pivot]],
        "direction": terms,
        "parameters": [nm for nm, _ in terms],
        "text": " ".join(f"{c:+.4g}*d({nm})" for nm, c in terms),
    }


class PredictorIdentifier:
    """Maximum-likelihood identification of the Eq. 29 predictor (see module docstring).

    Parameters
    ----------
    order : polynomial order n of A', B', P (paper: 8).
    criterion : ``"free_run"`` (default) or ``"one_step"``.
    n_starts : number of local optimisations of the global search (centre + Sobol points).
    seed : seed of the Sobol sequence.
    fixed : parameters pinned at a value (``vary=False``): dict name -> value
        (value ``None`` = pin at the data-driven/conventional centre value),
        a sequence of names, or ``"recommended"`` (= :data:`RECOMMENDED_FIXED`).
        ``None`` varies all Eq. 35 parameters (the paper's setting).
    noise : ``"per_run"`` (one variance per run, floored at 10 % of the median)
        or ``"common"``.
    kappa : share of the preload loading the guide (fixed, not identified).
    include_load_inertia : m_eff = m_s + |m_load| (True) or m_s.
    max_nfev : function evaluations per local optimisation.
    start_spread : relative half-width of the global-search box.
    max_outer : maximum number of (theta, R) alternations.
    svd_rtol : relative singular-value threshold for non-identifiable directions.
    weak_rtol : directions with svd_rtol < relative singular value < weak_rtol are
        reported in ``weak_directions_`` (identifiable, but barely).
    tol : ftol = xtol = gtol of every local least_squares.
    stat_tol, stat_window : statistical convergence: a local run also stops when
        its cost (= -log-likelihood + const) decreased by less than ``stat_tol``
        over ``stat_window`` iterations (scipy >= 1.16; 0 disables).
    alt_tol : a refined optimum of the global search whose log-likelihood is within
        ``alt_tol`` of the best but which differs by > 3 stderr is reported in
        ``alternative_optima_`` (a discrete ambiguity the local stderr cannot show).
    explore_nfev, n_refine : global search in two stages (when n_starts > n_refine):
        every start gets a short local run of ``explore_nfev`` evaluations, then
        the ``n_refine`` best continue to convergence (``max_nfev`` in total).
    start_noise : free run: model the noise of the measured start speed of each
        run, which propagates through the recursion (residual covariance
        ``R_r (I + g g^T)``, ``g = d v_pred/d v_start``); see :class:`_NoiseModel`.
    extra : :class:`ExtraForces` or None. Extra exogenous forces with their own
        parameters phi, identified jointly with theta: in drive coordinates
        ``X_total = X + features(df) @ phi``. ``None`` (default) is the
        paper's model, unchanged. See *Extra forces* below.
    init : PredictorParams (or theta in Eq. 35 order) to warm-start from,
        e.g. a baseline fit. With ``n_starts=1`` only this start is run: one
        local refinement (phi given theta, then jointly, with the noise
        re-estimation), no equation-error search. With ``n_starts >= 2`` two
        tracks are fitted and the higher final log-likelihood wins: this
        warm start, and the data-driven search with ``n_starts - 1`` starts
        (as without init); ``convergence_["tracks"]`` records both. (One
        global search with init among the starts would compare the starts
        under init's noise variances, which are wrong for the others when
        init lacks an effect.) Parameters pinned by ``fixed`` without a value
        take init's values in the warm track.
        Its polynomials are re-expanded exactly if its position scaling
        (s_center, s_half) differs from the data's; kappa and
        include_load_inertia are the identifier's.
    init_extra : start values of phi for the warm start (default
        ``extra.start``, else zeros). Only used with ``init``.

    Extra forces
    ------------
    With ``extra`` the parameter vector is ``[theta, phi]`` internally: phi is
    in the data-driven start (the window equation error is linear in phi),
    the analytic Jacobian (dF/dphi = features), the bounds, the scaling, the
    SVD/Fisher uncertainty with AR(1) inflation (null and weak directions may
    involve phi), the AIC/BIC parameter count and ``fixed`` (extra names
    accepted). Attributes keep their theta-only shape and meaning
    (``theta_``, ``params_``, ``varied_``, ``identifiable_``, ``stderr_``,
    ``stderr_fisher_``, ``ci95_`` (p, 2), ``cov_``, ``cov_fisher_``,
    ``corr_`` (p, p) with p = 3n+8: the theta block of the joint covariance);
    the extras are in ``phi_`` (n_extra,), ``extra_names_``,
    ``extra_params_``, ``extra_stderr_``, ``extra_stderr_fisher_`` (dict name
    -> float), ``extra_ci95_`` (dict name -> (lo, hi)), ``extra_varied_``,
    ``extra_identifiable_`` (bool arrays), and the joint quantities in
    ``param_names_all_`` (theta names + extra names), ``stderr_all_``,
    ``ci95_all_``, ``cov_all_``, ``corr_all_`` (cross-correlations theta-phi).
    ``extra_confounding_`` (dict name -> dict) compares each extra
    parameter's stderr with the one it would have if theta were known
    (``variance_inflation``, ``explained_by_theta`` = 1 - 1/inflation,
    ``most_correlated``): a feature that is a smooth function of position is
    largely reproducible by the position polynomials of Eq. 35, which shows
    here, in ``weak_directions_`` / ``unidentifiable_`` and in the
    [[Warnings]] of :meth:`fit_report`. Without extras these attributes exist
    and are empty (or equal the theta versions). Also: ``extra_init_`` (phi
    at the centre start), ``warm_prestep_`` (the phi-given-theta step of a
    warm start, or None), ``fixed_`` may hold extra names, the ``"theta"`` of
    ``alternative_optima_`` and the ``x0`` of ``convergence_["starts"]`` are
    the joint vectors (theta then phi), :meth:`extra_force` gives
    ``features(df) @ phi`` per sample, ``to_dict()`` has ``"extra"`` (name ->
    value, stderr, stderr_fisher, ci95, unit, vary, identifiable,
    confounding) and ``"extra_description"``; ``from_dict(d, extra=...)``.
    """

    def __init__(
        self,
        order: int = 8,
        criterion: str = "free_run",
        n_starts: int = 8,
        seed: int | None = 0,
        fixed=None,
        noise: str = "per_run",
        kappa: float = 0.5,
        include_load_inertia: bool = True,
        max_nfev: int = 200,
        start_spread: float = 0.5,
        max_outer: int = 5,
        svd_rtol: float = 1e-8,
        weak_rtol: float = 1e-5,
        tol: float = 1e-10,
        start_noise: bool = True,
        explore_nfev: int = 30,
        n_refine: int = 3,
        stat_tol: float = 0.01,
        stat_window: int = 10,
        alt_tol: float = 2.0,
        verbose: bool = False,
        extra: "ExtraForces | None" = None,
        init: PredictorParams | None = None,
        init_extra=None,
    ):
        self.order = int(order)
        self.criterion = criterion
        self.n_starts = int(n_starts)
        self.seed = seed
        self.fixed = fixed
        self.noise = noise
        self.kappa = float(kappa)
        self.include_load_inertia = bool(include_load_inertia)
        self.max_nfev = int(max_nfev)
        self.start_spread = float(start_spread)
        self.max_outer = int(max_outer)
        self.svd_rtol = float(svd_rtol)
        self.weak_rtol = float(weak_rtol)
        self.tol = float(tol)
        self.start_noise = bool(start_noise)
        self.explore_nfev = int(explore_nfev)
        self.n_refine = max(1, int(n_refine))
        self.stat_tol = float(stat_tol)
        self.stat_window = int(stat_window)
        self.alt_tol = float(alt_tol)
        self.verbose = bool(verbose)
        if criterion not in ("free_run", "one_step"):
            raise IdentificationError(f"criterion must be 'free_run' or 'one_step', got {criterion!r}")
        if noise not in ("per_run", "common"):
            raise IdentificationError(f"noise must be 'per_run' or 'common', got {noise!r}")
        if self.order < 0:
            raise IdentificationError("order must be >= 0")
        if self.n_starts < 1:
            raise IdentificationError("n_starts must be >= 1")
        if extra is not None and not isinstance(extra, ExtraForces):
            raise IdentificationError(f"extra must be an ExtraForces or None, got {type(extra).__name__}")
        if extra is not None:
            clash = set(extra.names) & set(PredictorParams.names(self.order))
            if clash:
                raise IdentificationError(f"extra: names {sorted(clash)} clash with Eq. 35 parameter names")
        self.extra = extra
        self.init = init
        self.init_extra = None if init_extra is None else np.atleast_1d(np.asarray(init_extra, float)).ravel()
        if self.init_extra is not None:
            if extra is None:
                raise IdentificationError("init_extra given without extra")
            if self.init_extra.size != extra.n:
                raise IdentificationError(
                    f"init_extra has {self.init_extra.size} values, expected {extra.n} ({list(extra.names)})"
                )
        if init is not None and not isinstance(init, PredictorParams):
            th = np.asarray(init, dtype=float).ravel()
            if th.size != len(PredictorParams.names(self.order)):
                raise IdentificationError(
                    f"init: expected PredictorParams or theta of length {len(PredictorParams.names(self.order))}"
                )
        elif init is not None and init.order != self.order:
            raise IdentificationError(f"init has polynomial order {init.order}, the identifier {self.order}")

    # -- helpers -------------------------------------------------------------
    @property
    def param_names(self) -> list[str]:
        """Names of theta (Eq. 35 order); extra parameters are in :attr:`extra_names`."""
        return PredictorParams.names(self.order)

    @property
    def extra_names(self) -> list[str]:
        """Names of the extra-force parameters (empty without extras)."""
        if self.extra is not None:
            return list(self.extra.names)
        return list(getattr(self, "extra_names_", []))

    def _parse_fixed(self) -> dict:
        names = self.param_names + ([] if self.extra is None else list(self.extra.names))
        fx = self.fixed
        if fx is None:
            return {}
        if isinstance(fx, str):
            if fx != "recommended":
                raise IdentificationError(f"fixed: unknown preset {fx!r} (use 'recommended' or a dict)")
            fx = {k: None for k in RECOMMENDED_FIXED}
        elif not isinstance(fx, Mapping):
            fx = {k: None for k in fx}
        out = {}
        for k, v in fx.items():
            if k not in names:
                raise IdentificationError(f"fixed: unknown parameter {k!r}; known: {names}")
            out[k] = None if v is None else float(v)
        return out

    def _log(self, msg):
        if self.verbose:
            print(msg, flush=True)

    # -- fitting -------------------------------------------------------------
    def _settings(self) -> dict:
        """The constructor arguments (for the two tracks of a warm start)."""
        keys = ("order", "criterion", "n_starts", "seed", "fixed", "noise", "kappa", "include_load_inertia",
                "max_nfev", "start_spread", "max_outer", "svd_rtol", "weak_rtol", "tol", "start_noise",
                "explore_nfev", "n_refine", "stat_tol", "stat_window", "alt_tol", "verbose", "extra", "init",
                "init_extra")
        return {k: getattr(self, k) for k in keys}

    def _fit_two_tracks(self, df, slider_mass_kg, mask):
        """Warm start with n_starts >= 2: the warm track and the data-driven track; keep the better."""
        t_start = time.perf_counter()
        st = self._settings()
        warm = type(self)(**{**st, "n_starts": 1}).fit(df, slider_mass_kg, mask)
        tracks = [("warm start (init)", warm)]
        try:
            cold = type(self)(**{**st, "n_starts": self.n_starts - 1, "init": None, "init_extra": None}).fit(
                df, slider_mass_kg, mask
            )
            tracks.append(("data-driven", cold))
        except IdentificationError as exc:  # e.g. too few forward windows for the linear fit
            self._log(f"data-driven track failed: {exc}")
            tracks.append(("data-driven", exc))
        fitted = [(nm, t) for nm, t in tracks if not isinstance(t, Exception)]
        name, best = max(fitted, key=lambda nt: nt[1].loglik_)
        for k, v in vars(best).items():
            if k.endswith("_") and not k.startswith("_"):
                setattr(self, k, v)
        rec = []
        for nm, t in tracks:
            if isinstance(t, Exception):
                rec.append({"track": nm, "error": str(t)})
                continue
            rec.append({
                "track": nm, "chosen": t is best, "loglik": t.loglik_, "residual_rms": t.residual_rms_,
                "n_starts": t.convergence_["n_starts"], "nfev_total": t.convergence_["nfev_total"],
                "fit_time_s": t.fit_time_s_, "theta": t.theta_.tolist(), "phi": t.phi_.tolist(),
                "fixed": dict(t.fixed_),
            })
        self.convergence_ = dict(best.convergence_)
        self.convergence_["tracks"] = rec
        self.convergence_["chosen_track"] = name
        self.convergence_["nfev_total"] = int(sum(r.get("nfev_total", 0) for r in rec))
        self.fit_time_s_ = time.perf_counter() - t_start
        self._log(f"warm start: tracks {[(r['track'], r.get('loglik')) for r in rec]}; chosen: {name}")
        return self

    def fit(self, df, slider_mass_kg=None, mask=None):
        """Identify theta (and the extra-force parameters) from a data-format DataFrame; returns self."""
        if self.init is not None and self.n_starts >= 2:
            return self._fit_two_tracks(df, slider_mass_kg, mask)
        t_start = time.perf_counter()
        if slider_mass_kg is None:
            raise IdentificationError(
                "slider_mass_kg is missing: give the slider mass [kg] (sidecar 'slider_mass_kg')"
            )
        try:
            m_s = float(slider_mass_kg)
        except (TypeError, ValueError) as exc:
            raise IdentificationError(f"slider_mass_kg must be a number [kg], got {slider_mass_kg!r}") from exc
        if not (math.isfinite(m_s) and m_s > 0):
            raise IdentificationError(f"slider_mass_kg must be a positive mass [kg], got {slider_mass_kg!r}")
        data = _Data(df, mask)
        lay = data.layout
        names = self.param_names
        extra = self.extra
        xnames = [] if extra is None else list(extra.names)
        names_all = names + xnames
        p_theta = len(names)
        nx = len(xnames)
        p_all = p_theta + nx
        E = None if extra is None else extra.evaluate(df)  # features, once, flat order
        fixed_in = self._parse_fixed()
        n_var = p_all - len(fixed_in)
        if lay.R < 2:
            raise IdentificationError(f"too few runs: {lay.R}; need at least 2 (different voltages/loads)")
        if np.any(lay.lengths < 2):
            r = int(np.flatnonzero(lay.lengths < 2)[0])
            raise IdentificationError(f"run {_label(lay.labels[r])} has fewer than 2 samples")
        n_min = max(n_var + 2, 3 * (self.order + 1))
        if int(data.mask.sum()) < n_min:
            raise IdentificationError(
                f"too few samples: {int(data.mask.sum())} selected, need at least {n_min} "
                f"for {n_var} varied parameters"
            )
        vsel = data.v[data.mask]
        if not np.ptp(data.v) > 1e-9 or np.max(np.abs(vsel)) < 1e-6:
            raise IdentificationError("no speed variation in the data: the slider does not move")
        s_lo, s_hi = float(np.min(data.s)), float(np.max(data.s))
        if not s_hi - s_lo > 1e-6:
            raise IdentificationError("no position variation in the data (position_m constant)")
        s_center = 0.5 * (s_lo + s_hi)
        s_half = 0.5 * (s_hi - s_lo)
        lo_t, hi_t = PredictorParams.bounds(self.order)
        xlo, xhi = extra.bounds() if extra is not None else (np.zeros(0), np.zeros(0))
        lo = np.concatenate([lo_t, xlo])
        hi = np.concatenate([hi_t, xhi])
        varied = np.ones(p_all, dtype=bool)
        for k in fixed_in:
            varied[names_all.index(k)] = False
        fixed_vals = {k: v for k, v in fixed_in.items() if v is not None}

        def clip_all(th):
            th = _clip_theta(th, self.order)
            th[p_theta:] = np.clip(th[p_theta:], xlo, xhi)
            return th

        def with_fixed(th):
            th = th.copy()
            for k, v in fixed_vals.items():
                th[names_all.index(k)] = v
            return th

        # ---- data-driven centre ------------------------------------------
        warm = self.init is not None  # (then n_starts == 1, see _fit_two_tracks)
        need_dd = not warm
        try:
            red = _reduced_linear_fit(data, self.order, m_s, self.include_load_inertia, s_center, s_half, E=E)
        except IdentificationError:
            if not warm:
                raise
            red = None  # a warm start does without the data-driven starts
        ee = []
        if need_dd and red is not None:
            dco, bco, cco = red["D"], red["B"], red["C"]
            theta_conv = _map_reduced_to_theta(
                dco, bco, cco, {k: v for k, v in fixed_vals.items() if k in names}, self.order, m_s, self.kappa
            )
            theta_conv = clip_all(with_fixed(np.concatenate([theta_conv, red["E"]])))
            ee = _equation_error_fit(
                theta_conv, varied, red, self.order, m_s, self.kappa,
                max(16, 4 * self.n_starts), self.seed, 1.0,
            )
            ee = [(c, clip_all(with_fixed(th))) for c, th in ee]
        if warm:
            phi_init = (
                self.init_extra if self.init_extra is not None
                else (extra.start_vector() if extra is not None else np.zeros(0))
            )
            theta0 = clip_all(with_fixed(np.concatenate([self._init_vector(s_center, s_half), phi_init])))
        else:
            theta0 = ee[0][1].copy()
        # pin fixed-without-value at the centre
        fixed_final = {k: (theta0[names_all.index(k)] if v is None else v) for k, v in fixed_in.items()}
        for k, v in fixed_final.items():
            theta0[names_all.index(k)] = v
        if red is not None:
            self.reduced_ = {
                "D": red["D"].tolist(), "B_prime": red["B"].tolist(), "C": red["C"].tolist(),
                "n_windows": red["n_windows"], "window_samples": red["window"],
                "equation_error_minima": [c for c, _ in ee],
            }
            if nx:
                self.reduced_["extra"] = dict(zip(xnames, (float(x) for x in red["E"])))
        else:
            self.reduced_ = None
        self.theta_init_ = theta0[:p_theta].copy()
        self.extra_init_ = theta0[p_theta:].copy()

        problem = _Problem(
            data, self.order, self.kappa, self.include_load_inertia, self.criterion, s_center, s_half, m_s, E=E
        )

        # ---- scaling -------------------------------------------------------
        scale = _param_scale(theta0, self.order)
        if nx:
            # phi: the magnitude that makes the extra force ~1 % of the typical drive force
            with np.errstate(over="ignore", invalid="ignore"):
                X0 = problem.core.terms(theta0)[3]
            X0 = np.abs(X0[np.isfinite(X0)])
            x_typ = float(np.median(X0)) if X0.size else 1.0
            x_typ = max(x_typ, 0.1 * G_M_S2 * m_s)
            e_rms = np.sqrt(np.mean(E[data.mask] ** 2, axis=0)) if data.mask.any() else np.ones(nx)
            e_rms = np.where(e_rms > 0, e_rms, 1.0)
            scale[p_theta:] = np.maximum(np.abs(theta0[p_theta:]), 0.01 * x_typ / e_rms)
        vidx = np.flatnonzero(varied)
        sv_scale = scale[vidx]
        zlo = lo[vidx] / sv_scale
        zhi = hi[vidx] / sv_scale
        z_centre = _strictly_inside(theta0[vidx] / sv_scale, zlo, zhi)

        run_sel = problem.run_sel
        n_res = run_sel.size

        def theta_of(z):
            th = theta0.copy()
            th[vidx] = z * sv_scale
            return th

        noise = _NoiseModel(run_sel, lay.R, self.noise)

        def fun(z):
            r = problem.residual(theta_of(z))
            out = noise.weighted(r)
            if not np.all(np.isfinite(out)):
                out = np.where(np.isfinite(out), out, 1e10)
            return out

        def jac(z):
            J = problem.jacobian(theta_of(z), vidx)
            J = noise.weighted(J)
            J *= sv_scale[None, :]
            if not np.all(np.isfinite(J)):
                J = np.where(np.isfinite(J), J, 0.0)
            return J

        def update_noise(theta):
            """Re-estimate g (start-speed propagation) and R at theta; returns max rel. R change."""
            if self.start_noise:
                noise.set_start_gain(problem.start_gain(theta))
            return noise.update_R(problem.residual(theta))

        r0 = problem.residual(theta_of(z_centre))
        if not np.all(np.isfinite(r0)):
            raise IdentificationError(
                ("the warm start (init) gives" if warm else "the data-driven initial guess gives")
                + " a non-finite prediction; check units (m, m/s, V, kg) and slider_mass_kg"
            )
        update_noise(theta_of(z_centre))
        R_cur = noise.R

        def local(z_init, max_nfev):
            t0 = time.perf_counter()
            kw = {}
            stop = None
            if _HAS_CALLBACK and self.stat_tol > 0:
                # warm start: also stop a creep whose projected gain is irrelevant
                stop = _StatStop(self.stat_tol, self.stat_window, budget=max_nfev if warm else None,
                                 budget_tol=50 * self.stat_tol)
                kw["callback"] = stop
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                res = least_squares(
                    fun,
                    z_init,
                    jac=jac,
                    bounds=(zlo, zhi),
                    method="trf",
                    x_scale=1.0,
                    ftol=self.tol,
                    xtol=self.tol,
                    gtol=self.tol,
                    max_nfev=max_nfev,
                    **kw,
                )
            if res.status == -2 and stop is not None and stop.reason == "projected":
                res.message = (
                    f"statistical convergence (warm start): at the rate of the last {self.stat_window} "
                    f"iterations the remaining budget would gain < {50 * self.stat_tol:g} log-likelihood units"
                )
            elif res.status == -2:
                res.message = (
                    f"statistical convergence: cost decreased by < {self.stat_tol:g} (log-likelihood units) "
                    f"over the last {self.stat_window} iterations"
                )
            return res, time.perf_counter() - t0

        # ---- warm start with extras: phi given theta first ---------------------
        # A baseline fitted without the extras can sit on a kink of the free run
        # (a run at the edge of sticking / reversing); the joint Jacobian there is
        # one-sided in theta and trf may not move at all. The extras' conditional
        # fit (theta fixed at init: a small, nearly linear problem) moves off it.
        self.warm_prestep_ = None
        xv = np.flatnonzero(vidx >= p_theta)
        if warm and xv.size:
            t0 = time.perf_counter()
            zc = z_centre.copy()

            def fun_x(zx):
                z = zc.copy()
                z[xv] = zx
                return fun(z)

            def jac_x(zx):
                z = zc.copy()
                z[xv] = zx
                J = noise.weighted(problem.jacobian(theta_of(z), vidx[xv]))
                J *= sv_scale[xv][None, :]
                return np.where(np.isfinite(J), J, 0.0)

            c_before = 0.5 * float(np.sum(fun(zc) ** 2))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                pre = least_squares(
                    fun_x, zc[xv], jac=jac_x, bounds=(zlo[xv], zhi[xv]), method="trf", x_scale=1.0,
                    ftol=self.tol, xtol=self.tol, gtol=self.tol, max_nfev=self.max_nfev,
                )
            if np.isfinite(pre.cost) and pre.cost < c_before:
                z_centre = z_centre.copy()
                z_centre[xv] = pre.x
                z_centre = _strictly_inside(z_centre, zlo, zhi)
                update_noise(theta_of(z_centre))
                R_cur = noise.R
            self.warm_prestep_ = {
                "cost_before": c_before, "cost_after": float(pre.cost), "nfev": int(pre.nfev),
                "accepted": bool(np.isfinite(pre.cost) and pre.cost < c_before),
                "phi": (theta_of(z_centre)[p_theta:]).tolist(), "time_s": time.perf_counter() - t0,
            }
            self._log(f"warm start: phi given theta: cost {c_before:.6g} -> {pre.cost:.6g}, nfev {pre.nfev}")

        # ---- global search (first outer iteration) ---------------------------
        # starts: the distinct equation-error minima (best first), then Sobol
        # points around the best one (warm start: init only)
        starts = [z_centre]
        for _, th_ee in ee[1:]:
            if len(starts) >= self.n_starts:
                break
            starts.append(_strictly_inside(th_ee[vidx] / sv_scale, zlo, zhi))
        starts += [
            _strictly_inside(z, zlo, zhi)
            for z in _sobol_box(z_centre, self.n_starts - len(starts), self.seed, self.start_spread)
        ]
        # stage 1: a short local run from every start; stage 2: the n_refine
        # best continue to convergence (budget max_nfev in total per start)
        explore = self.max_nfev if len(starts) <= self.n_refine else min(self.explore_nfev, self.max_nfev)
        records = []
        results = {}
        for i, z_init in enumerate(starts):
            r_init = fun(z_init)
            if not np.all(np.abs(r_init) < 1e9):
                records.append(
                    {"start": i, "status": None, "message": "skipped: non-finite prediction at start",
                     "cost": float("inf"), "nfev": 0, "njev": 0, "time_s": 0.0,
                     "x0": (z_init * sv_scale).tolist(), "refined": False}
                )
                continue
            res, dtime = local(z_init, explore)
            results[i] = res
            records.append(
                {
                    "start": i,
                    "x0": (z_init * sv_scale).tolist(),
                    "cost": float(res.cost),
                    "nfev": int(res.nfev),
                    "njev": int(res.njev) if res.njev is not None else None,
                    "status": int(res.status),
                    "message": str(res.message),
                    "optimality": float(res.optimality),
                    "time_s": dtime,
                    "refined": False,
                }
            )
            self._log(f"start {i}: cost {res.cost:.6g} nfev {res.nfev} status {res.status} ({dtime:.2f}s)")
        if not results:
            raise IdentificationError("global search failed: every start gave a non-finite prediction")
        ranked = sorted(results, key=lambda i: results[i].cost)
        for i in ranked[: self.n_refine]:
            res0 = results[i]
            if res0.status != 0 or explore >= self.max_nfev:
                continue  # converged already (or had the full budget)
            res, dtime = local(res0.x, self.max_nfev - explore)
            results[i] = res
            rec = records[[r["start"] for r in records].index(i)]
            rec.update(
                cost=float(res.cost), nfev=rec["nfev"] + int(res.nfev),
                njev=(rec["njev"] or 0) + int(res.njev or 0), status=int(res.status),
                message=str(res.message), optimality=float(res.optimality),
                time_s=rec["time_s"] + dtime, refined=True,
            )
            self._log(f"refine {i}: cost {res.cost:.6g} nfev {res.nfev} status {res.status} ({dtime:.2f}s)")
        best_i = min(results, key=lambda i: results[i].cost)
        best = results[best_i]
        z_best = best.x
        outer_hist = [{"iteration": 0, "cost": float(best.cost), "noise_var_median": float(np.median(R_cur))}]
        final_res = best
        converged_R = False
        for it in range(1, self.max_outer + 1):
            change = update_noise(theta_of(z_best))
            R_cur = noise.R
            outer_hist[-1]["R_change"] = change
            if change < 0.01:
                converged_R = True
                break
            res, dtime = local(z_best, self.max_nfev)
            z_best = res.x
            final_res = res
            outer_hist.append(
                {"iteration": it, "cost": float(res.cost), "nfev": int(res.nfev), "status": int(res.status),
                 "noise_var_median": float(np.median(R_cur)), "time_s": dtime}
            )
            self._log(f"outer {it}: R change {change:.3g}, cost {res.cost:.6g}, nfev {res.nfev}")
        theta_hat = theta_of(z_best)

        # ---- uncertainty --------------------------------------------------------
        r = problem.residual(theta_hat)
        Jz = jac(z_best)  # whitened with the final noise model, scaled
        self._uncertainty(Jz, r, problem, noise, vidx, sv_scale, theta_hat, varied, names_all)
        self._split_uncertainty(p_theta, Jz, vidx, sv_scale)
        # other converged optima of the global search that fit almost as well
        # but lie far away in parameter space (discrete non-identifiability)
        alts = []
        for i in ranked[: self.n_refine]:
            if i == best_i or results[i].status == 0:
                continue
            dll = float(results[i].cost - results[best_i].cost)
            th_i = theta_of(results[i].x)
            with np.errstate(divide="ignore", invalid="ignore"):
                zd = np.abs(th_i - theta_hat) / self.stderr_all_
            zd = np.where(self.identifiable_all_ & np.isfinite(zd), zd, 0.0)
            dup = any(np.allclose(th_i, np.asarray(a["theta"]), rtol=1e-3, atol=1e-12) for a in alts)
            if dll < self.alt_tol and zd.max() > 3.0 and not dup:
                top = np.argsort(-zd)[:6]
                alts.append(
                    {
                        "start": int(i),
                        "delta_loglik": dll,
                        "theta": th_i.tolist(),
                        "max_z": float(zd.max()),
                        "differs_most": [(names_all[j], float(th_i[j]), float(zd[j])) for j in top
                                         if zd[j] > 3.0],
                    }
                )
        self.alternative_optima_ = alts

        # ---- store ----------------------------------------------------------------
        self.m_s_ = m_s
        self.s_center_ = s_center
        self.s_half_ = s_half
        self.varied_ = varied[:p_theta]
        self.fixed_ = {k: float(v) for k, v in fixed_final.items()}
        self.theta_ = theta_hat[:p_theta].copy()
        self.params_ = PredictorParams.from_vector(
            self.theta_, s_center, s_half, self.kappa, self.include_load_inertia
        )
        self.extra_names_ = list(xnames)
        self.extra_units_ = [] if extra is None else list(extra.units)
        self.extra_description_ = "" if extra is None else extra.description
        self.phi_ = theta_hat[p_theta:].copy()
        self.extra_varied_ = varied[p_theta:].copy()
        self.varied_all_ = varied.copy()
        self._set_extra_dicts()
        dts = np.diff(data.t)[~lay.is_last[:-1]]
        self.T_s_ = float(np.median(dts)) if dts.size else float("nan")
        self.runs_ = [_label(x) for x in lay.labels]
        self.noise_var_ = R_cur.copy()
        self.n_obs_ = int(n_res)
        self.residual_rms_ = float(np.sqrt(np.mean(r * r)))
        self.convergence_ = {
            "criterion": self.criterion,
            "n_starts": len(starts),
            "best_start": int(best_i),
            "starts": records,
            "outer": outer_hist,
            "noise_converged": bool(converged_R),
            "status": int(final_res.status),
            "message": str(final_res.message),
            "success": bool(final_res.status > 0 or final_res.status == -2),
            "optimality": float(final_res.optimality),
            "cost": float(0.5 * np.sum(noise.weighted(r) ** 2)),
            "nfev_total": int(sum(rec.get("nfev", 0) for rec in records)
                              + sum(h.get("nfev", 0) for h in outer_hist[1:])),
        }
        self.fit_time_s_ = time.perf_counter() - t_start
        return self

    def _uncertainty(self, Jz, r_raw, problem, noise, vidx, sv_scale, theta_hat, varied, names=None):
        """Joint (theta and phi) uncertainty; sets the ``*_all_`` attributes (see :meth:`_split_uncertainty`)."""
        names = self.param_names if names is None else list(names)
        p_all = len(names)
        run_sel = problem.run_sel
        lay = problem.lay
        n_res = r_raw.size
        r = noise.W(r_raw)  # residuals decorrelated from the start-speed noise
        # AR(1) factor per run from the lag-1 autocorrelation of consecutive residuals
        order_ = np.lexsort((problem.sample_sel, run_sel))
        rs = r[order_]
        runs_o = run_sel[order_]
        samp_o = problem.sample_sel[order_]
        adj = (runs_o[1:] == runs_o[:-1]) & (samp_o[1:] == samp_o[:-1] + 1)
        num = np.bincount(runs_o[1:][adj], weights=(rs[1:] * rs[:-1])[adj], minlength=lay.R)
        den = np.bincount(run_sel, weights=r * r, minlength=lay.R)
        with np.errstate(invalid="ignore", divide="ignore"):
            rho = np.where(den > 0, num / den, 0.0)
        rho = np.clip(np.nan_to_num(rho), 0.0, 0.99)
        f_ar = (1.0 + rho) / (1.0 - rho)
        self.ar1_rho_ = rho
        self.ar1_factor_ = f_ar

        U, sv, Vt = np.linalg.svd(Jz, full_matrices=False)
        self.singular_values_ = sv.copy()
        thr = self.svd_rtol * (sv[0] if sv.size else 0.0)
        ident = sv > thr
        Vn = Vt[~ident].T  # (p_var, q) null directions in z
        null_norm = np.sqrt(np.sum(Vn * Vn, axis=1)) if Vn.size else np.zeros(vidx.size)
        affected_v = null_norm > _NULL_TOL
        k_ident = int(np.sum(ident))

        def cov_from(J):
            _, s_, Vt_ = np.linalg.svd(J, full_matrices=False)
            keep = s_ > self.svd_rtol * s_[0]
            Vr = Vt_[keep].T
            cz = (Vr / s_[keep] ** 2) @ Vr.T
            return cz * np.outer(sv_scale, sv_scale)

        cov_plain_v = cov_from(Jz)
        Jc = Jz / np.sqrt(f_ar[run_sel])[:, None]
        cov_corr_v = cov_from(Jc)

        def full(cv):
            c = np.full((p_all, p_all), np.nan)
            c[np.ix_(vidx, vidx)] = cv
            aff = vidx[affected_v]
            c[aff, :] = np.nan
            c[:, aff] = np.nan
            c[aff, aff] = np.inf
            return c

        cov_plain = full(cov_plain_v)
        cov_corr = full(cov_corr_v)
        se_plain = np.sqrt(np.diag(cov_plain))
        se_corr = np.sqrt(np.diag(cov_corr))
        self.cov_all_ = cov_corr
        self.cov_fisher_all_ = cov_plain
        self.stderr_all_ = se_corr
        self.stderr_fisher_all_ = se_plain
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov_corr / np.outer(se_corr, se_corr)
        ok = np.isfinite(se_corr)
        corr[~ok, :] = np.nan
        corr[:, ~ok] = np.nan
        self.corr_all_ = corr
        self._Jc_ar = Jc  # AR(1)-corrected whitened scaled Jacobian (for the confounding diagnostic)
        nr = np.bincount(run_sel, minlength=lay.R)
        n_eff = float(np.sum(nr / f_ar))
        dof = max(n_eff - k_ident, 1.0)
        tq = float(stats.t.ppf(0.975, dof))
        self.n_eff_ = n_eff
        self.dof_ = dof
        self.t_quantile_ = tq
        ci = np.column_stack([theta_hat - tq * se_corr, theta_hat + tq * se_corr])
        ci[~varied] = np.nan
        self.ci95_all_ = ci
        self.identifiable_all_ = np.zeros(p_all, dtype=bool)
        self.identifiable_all_[vidx[~affected_v]] = True
        self.param_names_all_ = list(names)
        self.k_params_ = k_ident
        # log-likelihood, information criteria
        self.loglik_ = noise.loglik(r_raw)
        self.aic_ = 2 * k_ident - 2 * self.loglik_
        self.bic_ = k_ident * math.log(max(n_res, 1)) - 2 * self.loglik_
        # describe the null directions
        combos = []
        if Vn.size:
            q = Vn.shape[1]
            # pivoted QR picks q parameters that span the null space best; express
            # each direction with a unit change of its pivot and zero change of the others
            _, _, piv = _qr(Vn.T, pivoting=True, mode="economic")
            pv = piv[:q]
            B = Vn @ np.linalg.inv(Vn[pv, :])
            for j in range(q):
                d = _describe_direction(B[:, j], pv[j], vidx, sv_scale, names)
                d["text"] = "predictions unchanged along: " + d["text"]
                combos.append(d)
        self.unidentifiable_ = combos
        self.null_space_ = Vn
        # weakly determined directions (identifiable, but barely)
        weak = []
        rel = sv / sv[0] if sv.size else sv
        for j in np.flatnonzero(ident & (rel < self.weak_rtol)):
            vec = Vt[j]
            d = _describe_direction(vec, int(np.argmax(np.abs(vec))), vidx, sv_scale, names)
            d["relative_singular_value"] = float(rel[j])
            d["text"] = f"weakly determined (relative singular value {rel[j]:.2g}): " + d["text"]
            weak.append(d)
        self.weak_directions_ = weak

    def _split_uncertainty(self, p_theta, Jz, vidx, sv_scale):
        """theta-shaped public attributes from the joint ones, and the extra-force diagnostics."""
        p = p_theta
        self.cov_ = self.cov_all_[:p, :p].copy()
        self.cov_fisher_ = self.cov_fisher_all_[:p, :p].copy()
        self.stderr_ = self.stderr_all_[:p].copy()
        self.stderr_fisher_ = self.stderr_fisher_all_[:p].copy()
        self.corr_ = self.corr_all_[:p, :p].copy()
        self.ci95_ = self.ci95_all_[:p].copy()
        self.identifiable_ = self.identifiable_all_[:p].copy()
        self.extra_identifiable_ = self.identifiable_all_[p:].copy()
        # confounding of each varied extra parameter with theta: its stderr if
        # theta were known (the other extras still varied) vs. the joint one
        names_all = self.param_names_all_
        conf = {}
        Jc = self._Jc_ar
        xcols = np.flatnonzero(vidx >= p)
        if xcols.size:
            Je = Jc[:, xcols]
            _, s_, Vt_ = np.linalg.svd(Je, full_matrices=False)
            keep = s_ > self.svd_rtol * (s_[0] if s_.size and s_[0] > 0 else 1.0)
            keep &= s_ > 0
            Vr = Vt_[keep].T
            cz = (Vr / s_[keep] ** 2) @ Vr.T
            null_e = np.sqrt(np.sum(Vt_[~keep].T ** 2, axis=1)) if (~keep).any() else np.zeros(xcols.size)
            se_cond = np.sqrt(np.diag(cz)) * sv_scale[xcols]
            se_cond = np.where(null_e > _NULL_TOL, np.inf, se_cond)
            for jj, c in enumerate(xcols):
                i = int(vidx[c])
                nm = names_all[i]
                se_j = float(self.stderr_all_[i])
                sc = float(se_cond[jj])
                with np.errstate(divide="ignore", invalid="ignore"):
                    vif = se_j**2 / sc**2 if (np.isfinite(sc) and sc > 0) else float("nan")
                if not np.isfinite(se_j) and np.isfinite(sc):
                    vif = float("inf")
                cr = self.corr_all_[i, :p]
                ok = np.flatnonzero(np.isfinite(cr))
                top = ok[np.argsort(-np.abs(cr[ok]))][:3]
                conf[nm] = {
                    "stderr": se_j,
                    "stderr_if_theta_known": sc,
                    "variance_inflation": float(vif),
                    "explained_by_theta": float(1.0 - 1.0 / vif) if np.isfinite(vif) and vif > 0 else (
                        1.0 if vif == np.inf else float("nan")),
                    "most_correlated": [(names_all[j], float(cr[j])) for j in top],
                }
        self.extra_confounding_ = conf
        del self._Jc_ar

    def _set_extra_dicts(self):
        """extra_params_, extra_stderr_, extra_stderr_fisher_, extra_ci95_ (dicts by name) from the arrays."""
        p = len(self.param_names)
        names = list(self.extra_names_)
        se = np.asarray(self.stderr_all_, float)[p:]
        sef = np.asarray(self.stderr_fisher_all_, float)[p:]
        ci = np.asarray(self.ci95_all_, float).reshape(-1, 2)[p:]
        self.extra_params_ = {n: float(v) for n, v in zip(names, self.phi_)}
        self.extra_stderr_ = {n: float(v) for n, v in zip(names, se)}
        self.extra_stderr_fisher_ = {n: float(v) for n, v in zip(names, sef)}
        self.extra_ci95_ = {n: (float(a), float(b)) for n, (a, b) in zip(names, ci)}

    def _init_vector(self, s_center, s_half) -> np.ndarray:
        """theta of ``init`` in the data's position scaling (exact re-expansion of the polynomials)."""
        init = self.init
        if not isinstance(init, PredictorParams):
            return np.asarray(init, dtype=float).ravel().copy()
        th = init.to_vector()
        if math.isclose(init.s_center, s_center, rel_tol=1e-12, abs_tol=1e-15) and math.isclose(
            init.s_half, s_half, rel_tol=1e-12
        ):
            return th
        n1 = self.order + 1
        new_dom = [s_center - s_half, s_center + s_half]

        def conv(c):
            out = np.zeros(n1)
            cc = npleg.Legendre(np.asarray(c, float), domain=init._domain()).convert(
                domain=new_dom, kind=npleg.Legendre
            ).coef
            out[: cc.size] = cc[:n1]
            return out

        return np.concatenate([th[:5], conv(init.alpha), conv(init.beta), conv(init.p)])

    # -- predictions ------------------------------------------------------------
    def _check_fitted(self):
        if not hasattr(self, "params_"):
            raise IdentificationError("PredictorIdentifier is not fitted yet: call fit() first")

    def _theta_all(self) -> np.ndarray:
        return np.concatenate([self.theta_, np.asarray(getattr(self, "phi_", np.zeros(0)), float)])

    def _extra_matrix(self, df):
        """Features of the extra forces on ``df`` (None without extras)."""
        names = list(getattr(self, "extra_names_", []))
        if not names:
            return None
        if self.extra is None:
            raise IdentificationError(
                f"this identifier has extra-force parameters {names} but no feature function: "
                "reattach it with PredictorIdentifier.from_dict(d, extra=ExtraForces(...))"
            )
        if list(self.extra.names) != names:
            raise IdentificationError(f"extra: names {list(self.extra.names)} differ from the fitted {names}")
        return self.extra.evaluate(df)

    def extra_force(self, df) -> np.ndarray:
        """The identified extra force ``features(df) @ phi`` per sample [N, drive coordinates] (0 without extras)."""
        self._check_fitted()
        E = self._extra_matrix(df)
        if E is None:
            return np.zeros(len(df))
        return E @ self.phi_

    def predict_free_run(self, df) -> np.ndarray:
        """Free-run speed per sample [m/s] (from each run's first measured speed).

        With extra forces their features are computed on ``df``.
        """
        self._check_fitted()
        data = _Data(df)
        E = self._extra_matrix(df)
        prob = _Problem(
            data, self.order, self.kappa, self.include_load_inertia, "free_run",
            self.s_center_, self.s_half_, self.m_s_, E=E,
        )
        return prob.predict_all(self._theta_all())

    def predict_one_step(self, df) -> np.ndarray:
        """v(k+1 | measured v(k)) per sample [m/s]; NaN at the first sample of each run.

        With extra forces their features are computed on ``df``.
        """
        self._check_fitted()
        data = _Data(df)
        E = self._extra_matrix(df)
        prob = _Problem(
            data, self.order, self.kappa, self.include_load_inertia, "one_step",
            self.s_center_, self.s_half_, self.m_s_, E=E,
        )
        return prob.predict_all(self._theta_all())

    def steady_state(self, s, V0, load, direction, extra_force_N=0.0) -> np.ndarray:
        """Closed-form steady speed [m/s] (see :func:`l1b2.predictor.model.steady_state`).

        ``extra_force_N`` [N, drive coordinates, broadcasts] is added to X
        (default 0). With extra forces, pass ``features @ phi`` for the
        conditions of interest (e.g. ``self.extra_force(df)``); it is not
        computed here because the features need a data frame.
        """
        self._check_fitted()
        return _steady_state(self.params_, s, V0, load, direction, self.m_s_, extra_force=extra_force_N)

    # -- reporting ----------------------------------------------------------------
    def _all_view(self) -> dict:
        """Joint (theta then phi) names, values and uncertainty, for reporting."""
        xn = list(getattr(self, "extra_names_", []))
        names = self.param_names + xn
        if hasattr(self, "stderr_all_"):
            return {
                "names": names, "value": self._theta_all(), "varied": np.asarray(self.varied_all_, bool),
                "stderr": self.stderr_all_, "stderr_fisher": self.stderr_fisher_all_, "ci95": self.ci95_all_,
                "corr": self.corr_all_,
            }
        return {
            "names": names, "value": self._theta_all(), "varied": np.asarray(self.varied_, bool),
            "stderr": self.stderr_, "stderr_fisher": self.stderr_fisher_, "ci95": self.ci95_, "corr": self.corr_,
        }

    def fit_report(self, min_correl: float = 0.9) -> str:
        """Readable summary in the spirit of lmfit's fit_report."""
        self._check_fitted()
        names = self.param_names
        units = PredictorParams.units(self.order)
        lines = []
        lines.append("[[Model]]")
        lines.append(
            f"    L1B2 reduced predictor (paper Eq. 29), order {self.order}, criterion {self.criterion}, "
            f"noise {self.noise}, kappa {self.kappa}, m_eff = m_s{' + |m_load|' if self.include_load_inertia else ''}"
        )
        xnames = list(getattr(self, "extra_names_", []))
        if xnames:
            desc = getattr(self, "extra_description_", "") or ""
            lines.append(
                f"    + extra forces (drive coordinates, X += features @ phi): {', '.join(xnames)}"
                + (f" -- {desc}" if desc else "")
            )
        lines.append("[[Fit Statistics]]")
        nvar = int(np.sum(self.varied_)) + int(np.sum(getattr(self, "extra_varied_", np.zeros(0, bool))))
        lines.append(f"    # residuals (n)          = {self.n_obs_}")
        lines.append(f"    # runs                   = {len(self.runs_)}")
        lines.append(f"    # varied parameters      = {nvar} (identifiable: {self.k_params_})")
        lines.append(f"    residual RMS             = {self.residual_rms_:.6g} m/s")
        lines.append(f"    log-likelihood           = {self.loglik_:.6g}")
        lines.append(f"    AIC                      = {self.aic_:.6g}")
        lines.append(f"    BIC                      = {self.bic_:.6g}")
        lines.append(
            "    (k counts varied identifiable theta "
            + ("and extra-force " if xnames else "")
            + "parameters; noise variances not counted)"
        )
        lines.append(f"    effective n (AR(1))      = {self.n_eff_:.6g}; t(0.975, {self.dof_:.0f}) = {self.t_quantile_:.4f}")
        lines.append(f"    slider mass              = {self.m_s_} kg; fit time = {self.fit_time_s_:.2f} s")
        c = self.convergence_
        lines.append("[[Convergence]]")
        lines.append(
            f"    best start {c['best_start']} of {c['n_starts']}; status {c['status']} ({c['message']}); "
            f"optimality {c['optimality']:.3g}; noise R converged: {c['noise_converged']}; "
            f"total nfev {c['nfev_total']}"
        )
        costs = [s["cost"] for s in c["starts"]]
        lines.append("    start costs: " + ", ".join(f"{x:.6g}" for x in costs))
        lines.append("[[Variables]]  value +/- stderr (AR(1)-corrected; plain Fisher in brackets)  95% CI")
        av = self._all_view()
        names_all = av["names"]
        units = {**units, **dict(zip(xnames, getattr(self, "extra_units_", [""] * len(xnames))))}
        w = max(len(nm) for nm in names_all)
        for i, nm in enumerate(names_all):
            if i == len(names) and xnames:
                lines.append("    -- extra forces --")
            val = av["value"][i]
            u = units.get(nm, "")
            if not av["varied"][i]:
                lines.append(f"    {nm:<{w}} = {val: .6g} [{u}] (fixed)")
                continue
            se = av["stderr"][i]
            if not np.isfinite(se):
                lines.append(f"    {nm:<{w}} = {val: .6g} [{u}] +/- inf  (not identifiable from these data)")
                continue
            rel = f" ({100 * se / abs(val):.2f}%)" if val != 0 else ""
            lo, hi = av["ci95"][i]
            sig = ""
            if i >= len(names):
                sig = "  (significant: CI excludes 0)" if (lo > 0 or hi < 0) else "  (not significant: CI contains 0)"
            lines.append(
                f"    {nm:<{w}} = {val: .6g} +/- {se:.3g}{rel} [{u}]  [{av['stderr_fisher'][i]:.3g}]"
                f"  CI [{lo:.6g}, {hi:.6g}]{sig}"
            )
        pairs = []
        corr = av["corr"]
        for i in range(len(names_all)):
            for j in range(i + 1, len(names_all)):
                cij = corr[i, j]
                if np.isfinite(cij) and abs(cij) > min_correl:
                    pairs.append((abs(cij), names_all[i], names_all[j], cij))
        lines.append(f"[[Correlations]] (|C| > {min_correl})")
        if pairs:
            for _, a, b, cij in sorted(pairs, reverse=True)[:40]:
                lines.append(f"    C({a}, {b}) = {cij:+.4f}")
            if len(pairs) > 40:
                lines.append(f"    ... {len(pairs) - 40} more")
        else:
            lines.append("    none")
        warn = []
        if self.unidentifiable_:
            warn.append(
                f"    {len(self.unidentifiable_)} direction(s) in parameter space the data cannot determine "
                f"(singular values < {self.svd_rtol:g} x largest); affected parameters have stderr = inf."
            )
            for cmb in self.unidentifiable_:
                warn.append("    - " + cmb["text"])
            warn.append(
                "    Structurally the data fix only D(s) = c_r + sigma (0.5 - A'(s)), B'(s) and "
                "C(s) = mu P (2 sqrt(1-k0^2) - 1 - pi/2 A' G(k0)) - mu_sd (9.81 m_s + kappa P); "
                f"pin one parameter per direction, e.g. fixed='recommended' = {list(RECOMMENDED_FIXED)}."
            )
        for w in getattr(self, "weak_directions_", []):
            warn.append("    - " + w["text"])
        for nm, cf in getattr(self, "extra_confounding_", {}).items():
            vif = cf.get("variance_inflation", float("nan"))
            if vif is None or not (isinstance(vif, (int, float)) and (vif > 10 or vif == float("inf"))):
                continue
            mc = ", ".join(f"{a} ({b:+.3f})" for a, b in cf.get("most_correlated", []))
            if vif == float("inf"):
                warn.append(
                    f"    - extra parameter {nm} is confounded with theta: its effect on the predictions can be "
                    "reproduced by the Eq. 35 parameters (not identifiable jointly)"
                )
            else:
                warn.append(
                    f"    - extra parameter {nm} is confounded with theta: {100 * cf['explained_by_theta']:.2f} % of "
                    f"its effect on the predictions can be reproduced by the Eq. 35 parameters (variance inflation "
                    f"{vif:.3g}: stderr {cf['stderr']:.3g} jointly vs {cf['stderr_if_theta_known']:.3g} if theta "
                    f"were known); most correlated: {mc}"
                )
        for alt in getattr(self, "alternative_optima_", []):
            diff = ", ".join(f"{n} = {v:.4g} ({z:.0f} stderr away)" for n, v, z in alt["differs_most"])
            warn.append(
                f"    - another optimum (start {alt['start']}) fits almost as well "
                f"(log-likelihood lower by {alt['delta_loglik']:.2f}) with {diff}: "
                "the local intervals do not cover it (discrete ambiguity, e.g. the split of C(s) into P and A')."
            )
        if not c["success"]:
            warn.append(f"    - the final local optimisation did not converge: {c['message']}")
        if warn:
            lines.append("[[Warnings]]")
            lines.extend(warn)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe summary (inf -> "inf", NaN -> None) that :meth:`from_dict` restores."""
        self._check_fitted()
        names = self.param_names
        units = PredictorParams.units(self.order)
        params = {}
        for i, nm in enumerate(names):
            params[nm] = {
                "value": float(self.theta_[i]),
                "stderr": _json_float(self.stderr_[i]),
                "stderr_fisher": _json_float(self.stderr_fisher_[i]),
                "ci95": [_json_float(self.ci95_[i, 0]), _json_float(self.ci95_[i, 1])],
                "unit": units[nm],
                "vary": bool(self.varied_[i]),
                "identifiable": bool(self.identifiable_[i]),
            }
        conv = _jsonify(self.convergence_)
        xnames = list(getattr(self, "extra_names_", []))
        p = len(names)
        extra_sec = {}
        for j, nm in enumerate(xnames):
            i = p + j
            cf = getattr(self, "extra_confounding_", {}).get(nm, {})
            extra_sec[nm] = {
                "value": float(self.phi_[j]),
                "stderr": _json_float(self.stderr_all_[i]),
                "stderr_fisher": _json_float(self.stderr_fisher_all_[i]),
                "ci95": [_json_float(self.ci95_all_[i, 0]), _json_float(self.ci95_all_[i, 1])],
                "unit": self.extra_units_[j],
                "vary": bool(self.varied_all_[i]),
                "identifiable": bool(self.identifiable_all_[i]),
                "confounding": _jsonify(cf),
            }
        return {
            "model": "l1b2 reduced predictor (Eq. 29)",
            "settings": {
                "order": self.order,
                "criterion": self.criterion,
                "n_starts": self.n_starts,
                "seed": self.seed,
                "fixed": self.fixed_,
                "noise": self.noise,
                "kappa": self.kappa,
                "include_load_inertia": self.include_load_inertia,
                "max_nfev": self.max_nfev,
                "start_spread": self.start_spread,
                "max_outer": self.max_outer,
                "svd_rtol": self.svd_rtol,
                "weak_rtol": self.weak_rtol,
                "tol": self.tol,
                "start_noise": self.start_noise,
                "explore_nfev": self.explore_nfev,
                "n_refine": self.n_refine,
                "stat_tol": self.stat_tol,
                "stat_window": self.stat_window,
                "alt_tol": self.alt_tol,
            },
            "slider_mass_kg": self.m_s_,
            "predictor_params": self.params_.to_dict(),
            "parameters": params,
            "extra": extra_sec,
            "extra_description": getattr(self, "extra_description_", "") or "",
            "paper_monomials": self.params_.to_paper_monomials(self.T_s_),
            "T_s": self.T_s_,
            "runs": [r if isinstance(r, (int, str)) else _jsonify(r) for r in self.runs_],
            "noise_var": [float(x) for x in self.noise_var_],
            "ar1_rho": [float(x) for x in self.ar1_rho_],
            "n_obs": self.n_obs_,
            "n_eff": self.n_eff_,
            "k_params": self.k_params_,
            "loglik": self.loglik_,
            "aic": self.aic_,
            "bic": self.bic_,
            "residual_rms": self.residual_rms_,
            "singular_values": [float(x) for x in self.singular_values_],
            "unidentifiable": _jsonify(self.unidentifiable_),
            "weak_directions": _jsonify(self.weak_directions_),
            "alternative_optima": _jsonify(self.alternative_optima_),
            "convergence": conv,
            "fit_time_s": self.fit_time_s_,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], extra: ExtraForces | None = None) -> "PredictorIdentifier":
        """Rebuild a fitted identifier (for prediction and reporting) from :meth:`to_dict`.

        The values of extra-force parameters (section ``"extra"``) are
        restored; their feature function cannot be serialised: pass the same
        ``extra=ExtraForces(...)`` to reattach it (its names must match).
        Without it, predictions of a model with extra forces raise
        :class:`IdentificationError`.
        """
        st = dict(d["settings"])
        fixed = st.pop("fixed", None)
        xsec = dict(d.get("extra") or {})
        xnames = list(xsec)
        if extra is not None:
            if not xnames:
                raise IdentificationError("from_dict: extra given, but the fit has no extra-force parameters")
            if sorted(extra.names) != sorted(xnames):
                raise IdentificationError(
                    f"from_dict: extra names {list(extra.names)} differ from the fitted {xnames}"
                )
            xnames = list(extra.names)
        obj = cls(fixed=fixed or None, extra=extra, **st)
        names = obj.param_names
        prm = d["parameters"]
        obj.params_ = PredictorParams.from_dict(d["predictor_params"])
        obj.theta_ = obj.params_.to_vector()
        obj.fixed_ = dict(fixed or {})
        obj.m_s_ = float(d["slider_mass_kg"])
        obj.s_center_ = obj.params_.s_center
        obj.s_half_ = obj.params_.s_half
        obj.varied_ = np.array([prm[n]["vary"] for n in names])
        obj.identifiable_ = np.array([prm[n]["identifiable"] for n in names])
        obj.stderr_ = np.array([_from_json_float(prm[n]["stderr"]) for n in names])
        obj.stderr_fisher_ = np.array([_from_json_float(prm[n]["stderr_fisher"]) for n in names])
        obj.ci95_ = np.array([[_from_json_float(x) for x in prm[n]["ci95"]] for n in names])
        obj.T_s_ = float(d["T_s"])
        obj.runs_ = list(d["runs"])
        obj.noise_var_ = np.asarray(d["noise_var"], float)
        obj.ar1_rho_ = np.asarray(d["ar1_rho"], float)
        obj.ar1_factor_ = (1 + obj.ar1_rho_) / (1 - obj.ar1_rho_)
        obj.n_obs_ = int(d["n_obs"])
        obj.n_eff_ = float(d["n_eff"])
        obj.k_params_ = int(d["k_params"])
        obj.dof_ = max(obj.n_eff_ - obj.k_params_, 1.0)
        obj.t_quantile_ = float(stats.t.ppf(0.975, obj.dof_))
        obj.loglik_ = float(d["loglik"])
        obj.aic_ = float(d["aic"])
        obj.bic_ = float(d["bic"])
        obj.residual_rms_ = float(d["residual_rms"])
        obj.singular_values_ = np.asarray(d["singular_values"], float)
        obj.unidentifiable_ = list(d["unidentifiable"])
        obj.weak_directions_ = list(d.get("weak_directions", []))
        obj.alternative_optima_ = list(d.get("alternative_optima", []))
        obj.convergence_ = dict(d["convergence"])
        obj.fit_time_s_ = float(d["fit_time_s"])
        # covariance is not serialised in full; keep the diagonal
        p = len(names)
        obj.cov_ = np.full((p, p), np.nan)
        np.fill_diagonal(obj.cov_, obj.stderr_ ** 2)
        obj.cov_fisher_ = np.full((p, p), np.nan)
        np.fill_diagonal(obj.cov_fisher_, obj.stderr_fisher_ ** 2)
        obj.corr_ = np.full((p, p), np.nan)
        np.fill_diagonal(obj.corr_, np.where(np.isfinite(obj.stderr_), 1.0, np.nan))
        # extra forces
        obj.extra_names_ = xnames
        obj.extra_units_ = [str(xsec[n].get("unit", "")) for n in xnames]
        obj.extra_description_ = str(d.get("extra_description", "") or "")
        obj.phi_ = np.array([float(xsec[n]["value"]) for n in xnames])
        obj.extra_varied_ = np.array([bool(xsec[n].get("vary", True)) for n in xnames], dtype=bool)
        obj.extra_identifiable_ = np.array([bool(xsec[n].get("identifiable", True)) for n in xnames], dtype=bool)
        obj.extra_confounding_ = {}
        for n in xnames:
            cf = dict(xsec[n].get("confounding") or {})
            for k in ("stderr", "stderr_if_theta_known", "variance_inflation", "explained_by_theta"):
                if k in cf:
                    cf[k] = _from_json_float(cf[k])
            cf["most_correlated"] = [(str(a), float(b)) for a, b in cf.get("most_correlated", [])]
            obj.extra_confounding_[n] = cf
        xse = np.array([_from_json_float(xsec[n].get("stderr")) for n in xnames])
        xsef = np.array([_from_json_float(xsec[n].get("stderr_fisher", xsec[n].get("stderr"))) for n in xnames])
        xci = np.array([[_from_json_float(x) for x in xsec[n]["ci95"]] for n in xnames]).reshape(-1, 2)
        obj.param_names_all_ = names + xnames
        obj.varied_all_ = np.concatenate([obj.varied_, obj.extra_varied_])
        obj.identifiable_all_ = np.concatenate([obj.identifiable_, obj.extra_identifiable_])
        obj.stderr_all_ = np.concatenate([obj.stderr_, xse])
        obj.stderr_fisher_all_ = np.concatenate([obj.stderr_fisher_, xsef])
        obj.ci95_all_ = np.vstack([obj.ci95_, xci])
        pa = p + len(xnames)
        obj.cov_all_ = np.full((pa, pa), np.nan)
        np.fill_diagonal(obj.cov_all_, obj.stderr_all_ ** 2)
        obj.cov_fisher_all_ = np.full((pa, pa), np.nan)
        np.fill_diagonal(obj.cov_fisher_all_, obj.stderr_fisher_all_ ** 2)
        obj.corr_all_ = np.full((pa, pa), np.nan)
        np.fill_diagonal(obj.corr_all_, np.where(np.isfinite(obj.stderr_all_), 1.0, np.nan))
        obj._set_extra_dicts()
        return obj


def _jsonify(x):
    if isinstance(x, dict):
        return {str(k): _jsonify(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonify(v) for v in x]
    if isinstance(x, np.ndarray):
        return [_jsonify(v) for v in x.tolist()]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return _json_float(x)
    if x is None or isinstance(x, str):
        return x
    return str(x)
