"""The drive-frequency response in the identification: estimated when TRAIN's frequency varies, held fixed otherwise.

The response (:class:`~l1b2.predictor.frequency.FrequencyResponse`: B2
resonance ``f_b0_Hz`` and damping ``zeta_b``, gain 1 at the reference
frequency ``f_ref_Hz``) scales the force factor B'; with the response fixed
the model is the Eq. 29 model at the effective amplitude ``V0 g(f)``, so
every search, Jacobian and uncertainty of :mod:`l1b2.ident` applies unchanged
(:class:`~l1b2.ident.problem.SampleData` takes the response).

Estimation (:func:`fit_frequency_response`): the response's coordinates
``q = (f_b0 / f_ref, ln zeta_b)`` are parameters of the joint least squares
with theta. A coarse grid over resonances on both sides of the drive (0.4-3 %
of ``f_ref`` away) and three dampings, one warm identification of theta at
each point, finds the basin; Gauss-Newton steps of the joint problem in q
(:class:`ResponseLinearisation`: the sensitivities of the weighted residuals
in q by central differences, theta's analytic Jacobian projected out, so the
step is the joint step with theta re-optimised to first order; each step is
followed by a warm refit of theta and a line search) refine it, and the final
model is identified at the optimum with the identifier's full search.
Standard errors of ``f_b0`` and ``zeta_b``: q's block of the joint Fisher
covariance, ``(J_q^T P J_q)^-1`` (the Schur complement), inflated by the
fit's median AR(1) factor like theta's. Beside them, ``f_b0``'s interval
clustered by drive-frequency level (:func:`clustered_interval`: CR2 with
Bell-McCaffrey degrees of freedom, on log f_b0; not available with fewer than
:data:`CLUSTERED_MIN_LEVELS` levels or :data:`CLUSTERED_MIN_DOF`, and "not identified" when it contains
the whole range the fit searches). The former estimation (a Nelder-Mead
search of the profile likelihood, standard errors from its curvature) is
kept as :func:`fit_frequency_response_profile`, the benchmark's reference
(``bench/bench_frequency.py``; measured figures in
docs/decisions/0024-frequency-response-form-and-joint-estimation.md).

Settings (``PredictorIdentifier(frequency=...)``): ``"auto"`` (default; ``"contact"`` the same plus the
contact law for the pure-slip family, :func:`fit_frequency_response`)
estimates the response when TRAIN's runs spread over more than
:data:`~l1b2.data.coverage.FREQUENCY_REL_SPREAD` of their median frequency
and holds it fixed at gain 1 otherwise; ``"off"`` never uses it; a
:class:`FrequencyResponse` (or its dict) holds it fixed at those values.
The record (:func:`frequency_record`) names which happened, in the fit
report and ``identification.json``.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Mapping

import numpy as np
from scipy import optimize, stats

from ..data.coverage import FREQUENCY_REL_SPREAD, frequency_varies, run_frequencies
from ..data.measurements import Measurements
from ..errors import IdentificationError
from ..predictor.frequency import FrequencyResponse
from .clusters import frequency_levels
from .problem import SampleData
from .slipproblem import make_problem
from .uncertainty import bell_mccaffrey_dof, profiled_influence

__all__ = ["FREQUENCY_SETTINGS", "response_setting", "reference_frequency", "frequency_record",
           "frequency_report_lines", "fit_frequency_response", "GRID_OFFSETS", "GRID_ZETAS", "ZETA_B_RANGE",
           "bounds_hit", "clustered_interval", "clustered_record", "log_interval", "CLUSTERED_MIN_LEVELS",
           "CLUSTERED_MIN_DOF"]

#: "contact": as "auto", and the pure-slip family estimates the contact law as well (decision 0038)
FREQUENCY_SETTINGS = ("auto", "off", "contact")
#: resonance offsets of the coarse grid, as shares of f_ref (both sides of the drive)
GRID_OFFSETS = (-0.03, -0.02, -0.014, -0.008, -0.004, 0.004, 0.008, 0.014, 0.02, 0.03)
#: dampings of the coarse grid
GRID_ZETAS = (0.006, 0.012, 0.024)


def response_setting(value) -> str | FrequencyResponse:
    """The ``frequency`` setting normalised: ``"auto"``, ``"off"`` or a FrequencyResponse (IdentificationError else)."""
    if value is None:
        return "off"
    if isinstance(value, FrequencyResponse):
        return value
    if isinstance(value, Mapping):
        try:
            return FrequencyResponse.from_dict(value)
        except (KeyError, TypeError, ValueError) as exc:
            raise IdentificationError(f"frequency: a response needs f_ref_Hz, f_b0_Hz, zeta_b > 0 ({exc})") from None
    if isinstance(value, str) and value in FREQUENCY_SETTINGS:
        return value
    raise IdentificationError(f"frequency must be 'auto', 'off' or a FrequencyResponse, got {value!r}")


def reference_frequency(data) -> float:
    """The data's nominal drive frequency [Hz]: the sidecar's ``drive_frequency_Hz``, else the median run frequency."""
    if isinstance(data, Measurements) and data.meta.get("drive_frequency_Hz") is not None:
        return float(data.meta["drive_frequency_Hz"])
    f = run_frequencies(data.df if isinstance(data, Measurements) else data)
    if f.size == 0:
        raise IdentificationError("frequency: the data have no frequency_Hz column and no drive_frequency_Hz")
    return float(np.median(f))


def frequency_record(status: str, reason: str, response: FrequencyResponse | None, data=None, **more) -> dict:
    """The JSON-safe record of the treatment: ``status`` ("estimated"/"fixed"), ``reason``, ``response``, TRAIN range."""
    rec: dict[str, Any] = {"status": status, "reason": reason,
                           "response": None if response is None else response.to_dict()}
    if data is not None:
        f = run_frequencies(data.df if isinstance(data, Measurements) else data)
        if f.size:
            rec["train_range_Hz"] = [float(f.min()), float(f.max())]
            rec["train_levels"] = int(np.unique(np.round(f, 0)).size)
    rec.update(more)
    return rec


def frequency_report_lines(rec: Mapping | None) -> list[str]:
    """The fit report's lines on the frequency response (none without a record)."""
    if not rec:
        return []
    r = rec.get("response")
    if r is None:
        return [f"    drive frequency: response FIXED at gain 1 ({rec.get('reason', '')})"]
    se = rec.get("stderr") or {}

    def pm(name, fmt):
        s = se.get(name)
        return f"{r[name]:{fmt}}" + (f" +/- {s:{fmt}}" if s is not None else "")
    lines = [f"    drive frequency: response {rec['status'].upper()} ({rec.get('reason', '')}): "
             f"B' x g(f), B2 f_b0 = {pm('f_b0_Hz', '.1f')} Hz, zeta_b = {pm('zeta_b', '.5f')}, "
             f"g(f_ref = {r['f_ref_Hz']:.1f} Hz) = 1"]
    if r.get("f_l0_Hz") is not None:
        lines.append(f"    drive frequency: contact law (decision 0038): L1 f_l0 = {pm('f_l0_Hz', '.1f')} Hz "
                     f"(zeta_l {r['zeta_l']:g} held), contact_V = {pm('contact_V', '.2f')} V")
    elif rec.get("contact"):
        lines.append("    drive frequency: contact law tried, NOT kept (no higher log-likelihood than the B2 response)")
    if rec.get("at_bound"):
        lines.append(f"    drive frequency: AT A BOUND, not an estimate: {'; '.join(rec['at_bound'])}")
    if rec.get("clustered"):
        lines.append(_clustered_line(rec["clustered"]))
    return lines


def _clustered_line(c: Mapping) -> str:
    """The fit report's line on :func:`clustered_record` (beside the model-based ``f_b0 +/- se``)."""
    head = f"    drive frequency: f_b0 clustered by drive-frequency level ({c['levels']} levels, CR2): "
    if not c.get("available"):
        return head + f"NOT AVAILABLE ({c['reason']})"
    return head + (f"Bell-McCaffrey dof {c['dof']:.2f}, t {c['t']:.2f}, se {c['stderr_Hz']:.1f} Hz, "
                   f"95 % [{c['ci95_Hz'][0]:.1f}, {c['ci95_Hz'][1]:.1f}] Hz (on log f_b0)")


def _clone(est, **changes):
    return type(est)(**{**est.get_params(), **changes})


#: finite-difference steps of the response coordinates q = (f_b0 / f_ref, ln zeta_b[, f_l0 / f_ref, ln contact_V])
Q_STEPS = (1e-4, 0.02, 1e-4, 0.02)
#: the physical range of the effective B2 damping ratio: Q from 100 down to 5. The interface only adds damping
#: to the mode (Eq. 24/30: the term 0.5 eta_T sigma omega U_w), so the effective zeta_b is at least the mode's
#: own, which for a mounted, preloaded stator is of order 0.01 (the project's motors: Q 30 and 40 for B2,
#: zeta_b 0.0165 and 0.0125); the lower end leaves a factor 2.5 below the lighter of the two for other
#: stators. Below it the fit can put a nearly undamped resonance just outside TRAIN's frequencies (decision
#: 0029); above 0.1 the B2 response is flat within +-1 kHz of the drive.
ZETA_B_RANGE = (0.005, 0.1)
#: the resonance within +-20 % of f_ref
F_B0_REL_RANGE = (0.8, 1.2)
#: bounds of q = (f_b0 / f_ref, ln zeta_b)
Q_LO = np.array([F_B0_REL_RANGE[0], math.log(ZETA_B_RANGE[0])])
Q_HI = np.array([F_B0_REL_RANGE[1], math.log(ZETA_B_RANGE[1])])
#: the contact law's L1 resonance: above the drive (the motor is driven between B2 and L1) within +20 %
F_L0_REL_RANGE = (1.0, 1.2)
#: the contact law's half-period amplitude contact_V [V]
CONTACT_V_RANGE = (10.0, 1e4)
#: bounds of the contact law's coordinates (f_l0 / f_ref, ln contact_V), appended to Q_LO / Q_HI
QC_LO = np.array([F_L0_REL_RANGE[0], math.log(CONTACT_V_RANGE[0])])
QC_HI = np.array([F_L0_REL_RANGE[1], math.log(CONTACT_V_RANGE[1])])
#: the contact stage's start grid: f_l0 / f_ref and contact_V / (TRAIN's median V0)
CONTACT_GRID = tuple((fl, c) for fl in (1.03, 1.06) for c in (0.9, 1.4, 2.2))
#: a coordinate of q this close to its bound (relative to the bound's width) is reported as at the bound
Q_AT_BOUND = 1e-3


def bounds_hit(q) -> list[str]:
    """The response's parameters that end at a bound of :data:`Q_LO`/:data:`Q_HI` ("zeta_b lower bound 0.005", ...)."""
    q = np.asarray(q, float)
    out = []
    names = (("f_b0_Hz", Q_LO[0], Q_HI[0], lambda x: f"{x:g} f_ref"),
             ("zeta_b", Q_LO[1], Q_HI[1], lambda x: f"{math.exp(x):g}"),
             ("f_l0_Hz", QC_LO[0], QC_HI[0], lambda x: f"{x:g} f_ref"),
             ("contact_V", QC_LO[1], QC_HI[1], lambda x: f"{math.exp(x):g}"))
    for i, (name, lo, hi, show) in enumerate(names[: q.size]):
        tol = Q_AT_BOUND * (hi - lo)
        if q[i] <= lo + tol:
            out.append(f"{name} lower bound {show(lo)}")
        elif q[i] >= hi - tol:
            out.append(f"{name} upper bound {show(hi)}")
    return out


def response_of(f_ref: float, q) -> FrequencyResponse:
    """The response at coordinates ``q = (f_b0 / f_ref, ln zeta_b)`` or, with the contact law,
    ``q = (f_b0 / f_ref, ln zeta_b, f_l0 / f_ref, ln contact_V)`` (:mod:`l1b2.predictor.frequency`)."""
    more = {} if len(q) == 2 else {"f_l0_Hz": float(q[2]) * f_ref, "contact_V": math.exp(float(q[3]))}
    return FrequencyResponse(f_ref, float(q[0]) * f_ref, math.exp(float(q[1])), **more)


def coordinates(resp: FrequencyResponse) -> np.ndarray:
    """``q`` of :func:`response_of` for ``resp`` (four coordinates with the contact law)."""
    q = [resp.f_b0_Hz / resp.f_ref_Hz, math.log(resp.zeta_b)]
    if resp.has_contact:
        q += [resp.f_l0_Hz / resp.f_ref_Hz, math.log(resp.contact_V)]
    return np.array(q)


class ResponseLinearisation:
    """A fitted model's weighted residuals as a function of the response q, theta held at the fit.

    ``r(q) = (v_pred(theta_hat, q) - v_meas) / sqrt(R_run)`` on the likelihood's
    samples (R_run the fit's noise variance of each run); ``J_theta`` its
    analytic Jacobian in the varied theta (and phi) at ``q_fit``, ``J_q`` the
    central differences in q (steps :data:`Q_STEPS`). With ``P`` the projector
    onto the orthogonal complement of ``J_theta``'s columns, the joint
    least squares' Gauss-Newton step in q (theta re-optimised to first order)
    is ``-(J_q^T P J_q)^-1 J_q^T P r`` and ``(J_q^T P J_q)^-1`` is q's block of
    the joint Fisher covariance (the Schur complement).
    """

    def __init__(self, result, data, mask, f_ref: float, q_fit):
        self.result, self.data, self.mask, self.f_ref = result, data, mask, float(f_ref)
        self.q_fit = np.asarray(q_fit, float)
        prob = self.problem(self.q_fit)
        self.w = 1.0 / np.sqrt(np.asarray(result.noise_var, float)[prob.run_sel])
        cols = np.flatnonzero(result.varied)
        J = prob.jacobian(result.values, cols) * self.w[:, None]
        J = J[:, np.all(np.isfinite(J), axis=0) & np.any(J != 0, axis=0)]
        self.Q = np.linalg.qr(J)[0]
        self.run_sel = np.asarray(prob.run_sel, int)
        self.n_runs = len(result.runs)
        self.r_fit = self.residual(self.q_fit, prob)
        self._jq = None

    def problem(self, q):
        res, prm = self.result, self.result.params
        sample = SampleData(self.data, self.mask, frequency=response_of(self.f_ref, q))
        E = None if res.extra is None else res.extra.evaluate(sample.frame)
        return make_problem(prm.drive_law, sample, res.order, prm.kappa, prm.include_load_inertia,
                            res.settings.get("criterion", "free_run"), prm.s_center, prm.s_half,
                            res.slider_mass_kg, E=E)

    def residual(self, q, prob=None) -> np.ndarray:
        """Weighted residuals at response q, theta held (non-finite values as a large residual)."""
        prob = self.problem(q) if prob is None else prob
        with np.errstate(all="ignore"):
            r = prob.residual(self.result.values) * (self.w if hasattr(self, "w") else 1.0)
        return np.where(np.isfinite(r), r, 1e3)

    def project(self, x: np.ndarray) -> np.ndarray:
        """``P x``: x without its part in the span of J_theta."""
        return x - self.Q @ (self.Q.T @ x)

    def projected_sse(self, q) -> float:
        """``|P r(q)|^2``: the sum of squares after theta's first-order refit at q."""
        return float(np.sum(self.project(self.residual(q)) ** 2))

    def jacobian_q(self) -> np.ndarray:
        """``J_q``: the weighted residuals' central differences in q at q_fit (steps :data:`Q_STEPS`), theta held."""
        cols = []
        for i, h in enumerate(Q_STEPS[: self.q_fit.size]):
            e = np.zeros(self.q_fit.size)
            e[i] = h
            cols.append((self.residual(self.q_fit + e) - self.residual(self.q_fit - e)) / (2 * h))
        return np.column_stack(cols)

    def cluster_influence(self, run_codes=None, cr2: bool = False) -> np.ndarray:
        """Each cluster's influence on the response's parameters in their units (``f_b0_Hz``, ``zeta_b``[, ``f_l0_Hz``,
        ``contact_V``]), theta profiled out: :func:`l1b2.ident.uncertainty.profiled_influence` of the weighted
        residuals, with ``J_q`` and ``Q`` of this linearisation, shape (G, len(q)).

        ``run_codes``: one integer cluster code per run of the fit (``result.runs``' order); None: each run its
        own cluster. ``cr2``: the Bell-McCaffrey adjusted rows (else the plain rows, CR1 through
        :func:`l1b2.ident.uncertainty.grouped_sandwich`).
        """
        codes = np.arange(self.n_runs) if run_codes is None else np.asarray(run_codes, int)
        return profiled_influence(self.Q, self._jacobian_q(), self.r_fit, codes[self.run_sel], cr2=cr2) * self.scale()

    def bell_mccaffrey_dof(self, run_codes, index: int) -> float:
        """:func:`l1b2.ident.uncertainty.bell_mccaffrey_dof` of the response's parameter ``index`` with the runs'
        clusters ``run_codes`` (as :meth:`cluster_influence`)."""
        c = np.zeros(self.q_fit.size)
        c[index] = 1.0
        return bell_mccaffrey_dof(self.Q, self._jacobian_q(), np.asarray(run_codes, int)[self.run_sel], c)

    def scale(self) -> np.ndarray:
        """d(parameter)/dq at q_fit: f_ref for the resonances (shares of f_ref), the value for the logs."""
        return np.array([self.f_ref if i % 2 == 0 else math.exp(v) for i, v in enumerate(self.q_fit)])

    def _jacobian_q(self) -> np.ndarray:
        if self._jq is None:
            self._jq = self.jacobian_q()
        return self._jq

    def step_and_information(self):
        """``(Gauss-Newton step in q, J_q^T P J_q)`` at q_fit."""
        PJ = self.project(self._jacobian_q())
        S = PJ.T @ PJ
        g = PJ.T @ self.project(self.r_fit)
        try:
            step = -np.linalg.solve(S + 1e-9 * np.trace(S) * np.eye(S.shape[0]), g)
        except np.linalg.LinAlgError:
            step = np.zeros(S.shape[0])
        return step, S


def _search_coordinates(best, f_ref):
    """``(q, scale, lo, hi)`` of the best fit so far: ``q = x / scale`` (x: Hz and logs; q: shares of f_ref and
    logs) and q's bounds (two coordinates, or four with the contact law)."""
    x = np.asarray(best["x"], float)
    scale = np.where(np.arange(x.size) % 2 == 0, f_ref, 1.0)
    lo, hi = (Q_LO, Q_HI) if x.size == 2 else (np.r_[Q_LO, QC_LO], np.r_[Q_HI, QC_HI])
    return x / scale, scale, lo, hi


def _below_stop(step) -> bool:
    """Whether a step in q is below the stopping size: 2e-5 in the shares of f_ref and 0.01 in the logs."""
    return bool(np.all(np.abs(step[0::2]) < 2e-5) and np.all(np.abs(step[1::2]) < 0.01))


def _gauss_newton(data, mask, f_ref, loglik, best, max_outer=8, damping=(0.0,)):
    """Gauss-Newton steps of the joint least squares in q from the best fit so far, each with a line search.

    ``loglik(x)`` is the warm refit's log-likelihood at ``x = (f_b0 [Hz], ln zeta_b)`` (it updates ``best``).
    A step is tried at full length, then 0.3 and 0.1 of it; the search stops when no trial raises the
    log-likelihood by more than 0.01 or the step is below 2e-5 f_ref and 0.01 in ln zeta_b. ``damping``:
    Levenberg-Marquardt factors ``lam`` tried in turn when no trial of the plain step helps (the step of
    ``J^T P J + lam diag(J^T P J)``; the contact stage's four coordinates; ``(0,)``: plain Gauss-Newton).
    """
    for _ in range(max_outer):
        if len(damping) > 1:
            if not _damped_step(data, mask, f_ref, loglik, best, damping):
                return
            continue
        q, scale, lo, hi = _search_coordinates(best, f_ref)
        step = ResponseLinearisation(best["result"], data, mask, f_ref, q).step_and_information()[0]
        if _below_stop(step):
            return
        l0 = best["loglik"]
        for frac in (1.0, 0.3, 0.1):
            qn = np.clip(q + frac * step, lo, hi)
            if loglik(qn * scale) > l0 + 0.01:
                break
        else:
            return


def _damped_step(data, mask, f_ref, loglik, best, damping) -> bool:
    """One Levenberg-Marquardt step of :func:`_gauss_newton` in x's coordinates: True when a trial raised the
    log-likelihood by more than 0.01 (``best`` moved), False when none did or the step is below the stopping size."""
    q, scale, lo, hi = _search_coordinates(best, f_ref)
    lin = ResponseLinearisation(best["result"], data, mask, f_ref, q)
    PJ = lin.project(lin.jacobian_q())
    S, g = PJ.T @ PJ, PJ.T @ lin.project(lin.r_fit)
    l0 = best["loglik"]
    for lam in damping:
        try:
            step = -np.linalg.solve(S + (lam + 1e-9) * np.diag(np.diag(S)), g)
        except np.linalg.LinAlgError:
            continue
        if _below_stop(step):
            return False
        for frac in (1.0, 0.3):
            if loglik(np.clip(q + frac * step, lo, hi) * scale) > l0 + 0.01:
                return True
    return False


#: the contact stage's Levenberg-Marquardt factors (:func:`_gauss_newton`'s ``damping``)
CONTACT_DAMPING = (0.0, 0.3, 3.0, 30.0)


def _contact_stage(data, mask, f_ref, loglik, best) -> dict:
    """The contact law's estimation after the B2 response's (``fit_frequency_response(contact=True)``).

    From the B2 optimum: warm identifications at :data:`CONTACT_GRID` (f_l0 / f_ref x contact_V / TRAIN's
    median V0), then Levenberg-Marquardt steps of the joint problem in all four coordinates
    (:func:`_gauss_newton` with :data:`CONTACT_DAMPING`) from the best of them. The contact law is kept only if it ends above the B2 optimum's log-likelihood;
    otherwise ``best`` returns to the B2 response. Returns the stage's record (both log-likelihoods, kept).
    """
    v_med = float(np.median(np.asarray((data.df if isinstance(data, Measurements) else data)["voltage_V"], float)))
    b2 = {k: best[k] for k in ("loglik", "params", "x", "result")}
    trials = [np.r_[b2["x"], fl * f_ref, math.log(c * v_med)] for fl, c in CONTACT_GRID]
    lls = [loglik(x) for x in trials]
    if not np.isfinite(max(lls)):
        return {"kept": False, "b2_loglik": float(b2["loglik"]), "contact_loglik": None}
    if len(best["x"]) == 2:     # no contact start beat the B2 optimum: refit the best one as the current best
        x = trials[int(np.argmax(lls))]
        best["seen"].pop(_key(x), None)
        best["loglik"] = -np.inf
        loglik(x)
    _gauss_newton(data, mask, f_ref, loglik, best, max_outer=12, damping=CONTACT_DAMPING)
    rec = {"b2_loglik": float(b2["loglik"]), "contact_loglik": float(best["loglik"]),
           "kept": bool(best["loglik"] > b2["loglik"])}
    if not rec["kept"]:
        best.update(b2)
    return rec


def fit_frequency_response(est, data, slider_mass_kg=None, mask=None, contact=False, b2=None):
    """Identify the model with its frequency response (``est.frequency == "auto"``, TRAIN's frequency varies).

    The response's coordinates ``q = (f_b0 / f_ref, ln zeta_b)`` are parameters of the joint least squares
    with theta. The basin: the grid :data:`GRID_OFFSETS` x :data:`GRID_ZETAS`, one warm identification of
    theta at each point (started from the best theta so far). Then Gauss-Newton steps of the joint least
    squares in q (:class:`ResponseLinearisation`: theta re-optimised to first order by the projection, then
    exactly by a warm refit at the new q, with a line search; :func:`_gauss_newton`), and a final
    identification at the optimum with the identifier's full search. Standard errors of ``f_b0`` and
    ``zeta_b``: q's block of the joint Fisher covariance (the Schur complement), inflated by the fit's
    median AR(1) factor like theta's. q stays within :data:`Q_LO`/:data:`Q_HI` (zeta_b in
    :data:`ZETA_B_RANGE`); a parameter that ends at its bound is named in the record's ``at_bound`` (and the
    fit report) and has no standard error. The record's ``clustered``: :func:`clustered_interval` of ``f_b0``
    beside the model-based standard error. Returns the fitted identifier (``est`` itself) whose result
    carries the estimated response and the record ``status="estimated"``.

    ``contact=True`` (the setting ``frequency="contact"``, pure-slip family only) adds the contact law of
    :mod:`l1b2.predictor.frequency` (``f_l0_Hz``, ``contact_V``) after the B2 optimum
    (:func:`_contact_stage`, q of four coordinates, bounds :data:`QC_LO`/:data:`QC_HI`); the record's
    ``contact`` says whether it was kept (it must raise the log-likelihood over the B2 optimum). ``b2``: a
    fitted identifier whose response (held fixed, ``result_.frequency["response"]``) is taken as the B2
    optimum instead of estimating it here (the contact stage alone, e.g. after an ``"auto"`` identification).
    """
    if b2 is None:
        m_s, mask, f_ref, loglik, best, _, _ = _grid_basin(est, data, slider_mass_kg, mask)
        _gauss_newton(data, mask, f_ref, loglik, best)
    else:                           # the contact stage from a given B2 identification
        m_s, mask, f_ref = _prepared(data, slider_mass_kg, mask)
        loglik, best = _profile(est, data, m_s, mask, f_ref, est._log)
        x = np.array([b2.result_.frequency["response"]["f_b0_Hz"], math.log(b2.result_.frequency["response"]["zeta_b"])])
        best.update(loglik=float(b2.loglik_), params=b2.params_, x=x, result=b2.result_)
        best["seen"][_key(x)] = float(b2.loglik_)
    n_grid = len(best["seen"])
    contact_rec = _contact_stage(data, mask, f_ref, loglik, best) if contact else None
    resp = response_of(f_ref, np.asarray(best["x"], float) / np.where(np.arange(len(best["x"])) % 2 == 0, f_ref, 1.0))
    final = _clone(est, frequency=resp, init=best["params"]).fit(data, slider_mass_kg=m_s, mask=mask)
    q_hat = coordinates(resp)
    lin = ResponseLinearisation(final.result_, data, mask, f_ref, q_hat)
    stderr = response_stderr(lin, resp)
    at_bound = bounds_hit(q_hat)
    if at_bound and stderr is not None:   # a value held by its bound has no standard error
        stderr = {k: v for k, v in stderr.items() if not any(h.startswith(k) for h in at_bound)} or None
    rec = frequency_record(
        "estimated", f"TRAIN's runs spread over more than {FREQUENCY_REL_SPREAD:.1%} of their frequency: joint "
        "maximum likelihood", resp, data, stderr=stderr, at_bound=at_bound,
        clustered=clustered_interval(lin, data, at_bound),
        joint={"grid_fits": n_grid, "gauss_newton_fits": len(best["seen"]) - n_grid,
               "loglik": float(final.loglik_),
               "stderr_from": "Schur complement of the joint Fisher information" if stderr else "singular"},
        **({} if contact_rec is None else {"contact": contact_rec}))
    est._publish(replace(final.result_, frequency=rec, settings={**final.result_.settings,
                                                                 "frequency": "contact" if contact else "auto"}))
    return est


def response_stderr(lin: "ResponseLinearisation", resp: FrequencyResponse) -> dict | None:
    """Standard errors of ``f_b0_Hz`` and ``zeta_b``: ``(J_q^T P J_q)^-1`` x the median AR(1) factor (None if singular)."""
    S = lin.step_and_information()[1]
    try:
        cov = np.linalg.inv(S) * float(np.median(lin.result.ar1_factor))
    except np.linalg.LinAlgError:
        return None
    if not (np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0)):
        return None
    out = {"f_b0_Hz": float(resp.f_ref_Hz * math.sqrt(cov[0, 0])), "zeta_b": float(resp.zeta_b * math.sqrt(cov[1, 1]))}
    if cov.shape[0] == 4:
        out.update(f_l0_Hz=float(resp.f_ref_Hz * math.sqrt(cov[2, 2])),
                   contact_V=float(resp.contact_V * math.sqrt(cov[3, 3])))
    return out


#: the fewest drive-frequency levels, and the fewest Bell-McCaffrey degrees of freedom, for which
#: :func:`clustered_record` states the clustered interval of ``f_b0`` as a number. The gain's shape over the
#: levels has three parameters (B''s scale, ``f_b0``, ``zeta_b``) that pass through three levels' gains exactly,
#: so a level's shared error is measured only from a fourth level on.
CLUSTERED_MIN_LEVELS = 4
CLUSTERED_MIN_DOF = 1.0
#: what :func:`clustered_record`'s interval is
CLUSTERED_KIND = ("CR2 clustered by drive-frequency level, t on Bell-McCaffrey dof, delta method on log f_b0: "
                  "exp(log f_b0 +- t se / f_b0)")


def log_interval(value, se, t):
    """The interval ``exp(log value +- t se / value)``: the delta method's ``value +- t se`` on ``log value``
    (``se / value`` the standard error of ``log value``), positive for a positive ``value``; vectorised."""
    value, se, t = np.asarray(value, float), np.asarray(se, float), np.asarray(t, float)
    half = t * se / value
    return value * np.exp(-half), value * np.exp(half)


def clustered_record(value_Hz: float, levels: int, stderr_Hz: float | None = None, dof: float | None = None,
                     reason: str | None = None, search_Hz: tuple[float, float] | None = None) -> dict:
    """The record of ``f_b0``'s interval clustered by drive-frequency level (:data:`CLUSTERED_KIND`).

    ``value_Hz``: the estimate; ``levels``: the number of drive-frequency levels G; ``stderr_Hz``: the CR2
    standard error of ``f_b0_Hz``; ``dof``: its Bell-McCaffrey degrees of freedom nu; ``reason``: why no
    interval exists whatever G and nu are (e.g. f_b0 at its bound). The interval is a number only with
    G >= :data:`CLUSTERED_MIN_LEVELS`, nu >= :data:`CLUSTERED_MIN_DOF` and finite positive se and estimate:
    then ``{"available": True, "t", "stderr_log", "ci95_Hz"}`` with ``t = t_{0.975, nu}``,
    ``stderr_log = se / f_b0`` and ``ci95_Hz`` of :func:`log_interval`. Otherwise ``"available": False`` and
    ``"reason"`` says why (also when the ends overflow the floats). ``search_Hz``: the range ``(lo, hi)`` the
    fit searches ``f_b0`` in; an interval that reaches beyond both of its ends says no more than the search
    does, and is ``"available": False`` with the reason "not identified" and the ends in it. Every record has
    ``kind``, ``parameter``, ``levels``, ``dof`` and ``stderr_Hz`` (None when not computed); all values are
    JSON-safe.
    """
    fin = lambda x: None if x is None or not np.isfinite(x) else float(x)   # noqa: E731
    rec: dict[str, Any] = {"kind": CLUSTERED_KIND, "parameter": "f_b0_Hz", "levels": int(levels),
                           "dof": fin(dof), "stderr_Hz": fin(stderr_Hz)}
    if reason is None and levels < CLUSTERED_MIN_LEVELS:
        reason = (f"{levels} drive-frequency level{'s' if levels != 1 else ''}: at least {CLUSTERED_MIN_LEVELS} are "
                  "needed; the gain's scale, resonance and damping pass through three levels' gains exactly, so "
                  "no shared error of a level is left to measure")
    if reason is None and not (rec["dof"] is not None and rec["stderr_Hz"] is not None and rec["stderr_Hz"] > 0
                               and np.isfinite(value_Hz) and value_Hz > 0):
        reason = "no finite clustered standard error"
    if reason is None and rec["dof"] < CLUSTERED_MIN_DOF:
        reason = (f"Bell-McCaffrey dof {rec['dof']:.2f} below {CLUSTERED_MIN_DOF:g}: the levels do not "
                  "estimate the variance, the width would be the t quantile's, not the data's")
    if reason is not None:
        return {**rec, "available": False, "reason": reason}
    t = float(stats.t.ppf(0.975, rec["dof"]))
    with np.errstate(over="ignore"):
        lo, hi = log_interval(value_Hz, rec["stderr_Hz"], t)
    if not (np.isfinite(hi) and lo > 0):
        return {**rec, "available": False, "t": t, "reason": "the interval's ends overflow: t se / f_b0 = "
                f"{t * rec['stderr_Hz'] / value_Hz:.3g}, not identified"}
    if search_Hz is not None and lo <= search_Hz[0] and hi >= search_Hz[1]:
        return {**rec, "available": False, "t": t, "reason": f"not identified: the 95 % interval [{lo:.1f}, "
                f"{hi:.1f}] Hz contains the whole range [{search_Hz[0]:.1f}, {search_Hz[1]:.1f}] Hz the fit "
                "searches f_b0 in"}
    return {**rec, "available": True, "t": t, "stderr_log": rec["stderr_Hz"] / float(value_Hz),
            "ci95_Hz": [float(lo), float(hi)]}


def clustered_interval(lin: "ResponseLinearisation", data, at_bound=()) -> dict:
    """:func:`clustered_record` of the fit linearised in ``lin`` on ``data`` (its frame or Measurements).

    The clusters: each run's drive-frequency level (:func:`l1b2.ident.clusters.frequency_levels` of
    ``lin.result.runs``); the standard error ``sqrt(sum_g u_g^2)`` of the CR2 rows
    (:meth:`ResponseLinearisation.cluster_influence` with ``cr2=True``, column ``f_b0_Hz``) and its dof
    (:meth:`ResponseLinearisation.bell_mccaffrey_dof`), computed with two levels or more. ``at_bound``:
    :func:`bounds_hit`'s list; ``f_b0`` at a bound has no interval. The search range passed on is
    :data:`F_B0_REL_RANGE` times ``lin.f_ref``.
    """
    df = data.df if isinstance(data, Measurements) else data
    f_b0 = float(lin.q_fit[0] * lin.f_ref)
    codes = np.asarray(frequency_levels(df, lin.result.runs), int)
    G = int(np.unique(codes).size)
    if any(h.startswith("f_b0_Hz") for h in at_bound):
        return clustered_record(f_b0, G, reason="f_b0 at its bound: no interval")
    if G < 2:
        return clustered_record(f_b0, G)
    u = lin.cluster_influence(codes, cr2=True)[:, 0]
    search = (F_B0_REL_RANGE[0] * lin.f_ref, F_B0_REL_RANGE[1] * lin.f_ref)
    return clustered_record(f_b0, G, float(np.sqrt(u @ u)), lin.bell_mccaffrey_dof(codes, 0), search_Hz=search)


def _prepared(data, slider_mass_kg, mask) -> tuple:
    """``(slider mass, mask, f_ref)`` of an identification on ``data`` (the Measurements' own when not given)."""
    m_s = slider_mass_kg if slider_mass_kg is not None else getattr(data, "slider_mass_kg", None)
    if mask is None and isinstance(data, Measurements):
        mask = data.mask
    return m_s, mask, reference_frequency(data)


def _grid_basin(est, data, slider_mass_kg, mask):
    """``(m_s, mask, f_ref, loglik, best, grid, vals)``: the profile log-likelihood (:func:`_profile`) evaluated on
    the basin's grid, :data:`GRID_OFFSETS` resonances on both sides of the drive x :data:`GRID_ZETAS` dampings;
    :class:`IdentificationError` when no grid point gives a finite fit."""
    m_s, mask, f_ref = _prepared(data, slider_mass_kg, mask)
    loglik, best = _profile(est, data, m_s, mask, f_ref, est._log)
    grid = [np.array([f_ref * (1 + o), math.log(z)]) for o in GRID_OFFSETS for z in GRID_ZETAS]
    vals = [loglik(x) for x in grid]
    if not np.isfinite(max(vals)):
        raise IdentificationError("frequency response: no trial response gave a finite fit")
    return m_s, mask, f_ref, loglik, best, grid, vals


def _key(x) -> tuple:
    """The profile's cache key of a trial ``x`` (Hz to 1e-3, logs to 1e-6)."""
    return tuple(round(float(v), 3 if i % 2 == 0 else 6) for i, v in enumerate(x))


def _profile(est, data, m_s, mask, f_ref, log):
    """The profile log-likelihood l(f_b0, ln zeta) with warm inner fits (the best theta so far as start)."""
    seen: dict = {}
    best: dict[str, Any] = {"loglik": -np.inf, "params": None, "x": None, "result": None, "seen": seen}

    def loglik(x):
        key = _key(x)
        if key in seen:
            return seen[key]
        try:
            resp = response_of(f_ref, np.asarray(x, float) / np.where(np.arange(len(x)) % 2 == 0, f_ref, 1.0))
            fit = _clone(est, frequency=resp, init=best["params"], n_starts=1 if best["params"] is not None
                         else est.n_starts, verbose=False).fit(data, slider_mass_kg=m_s, mask=mask)
            ll = float(fit.loglik_)
        except (IdentificationError, ValueError):
            ll = -np.inf
        if not np.isfinite(ll):
            ll = -np.inf
        seen[key] = ll
        if ll > best["loglik"]:
            best.update(loglik=ll, params=fit.params_, x=np.array(x, float), result=fit.result_)
        log(f"frequency response: f_b0 {x[0]:.1f} Hz, zeta {math.exp(x[1]):.5f}"
            + (f", f_l0 {x[2]:.1f} Hz, contact_V {math.exp(x[3]):.1f} V" if len(x) > 2 else "") + f": loglik {ll:.2f}")
        return ll
    return loglik, best


def _profile_stderr(loglik, x_hat, steps) -> tuple[np.ndarray | None, np.ndarray]:
    """Covariance of (f_b0, ln zeta) from the profile's Hessian (central differences), or None if not concave."""
    H = np.zeros((2, 2))
    l0 = loglik(x_hat)
    for i in range(2):
        e = np.zeros(2)
        e[i] = steps[i]
        H[i, i] = (loglik(x_hat + e) - 2 * l0 + loglik(x_hat - e)) / steps[i] ** 2
    e0, e1 = np.array([steps[0], 0.0]), np.array([0.0, steps[1]])
    H[0, 1] = H[1, 0] = (loglik(x_hat + e0 + e1) - loglik(x_hat + e0 - e1) - loglik(x_hat - e0 + e1)
                         + loglik(x_hat - e0 - e1)) / (4 * steps[0] * steps[1])
    if not np.all(np.isfinite(H)):
        return None, H
    try:
        cov = np.linalg.inv(-H)
    except np.linalg.LinAlgError:
        return None, H
    if not np.all(np.diag(cov) > 0):
        return None, H
    return cov, H


def fit_frequency_response_profile(est, data, slider_mass_kg=None, mask=None):
    """The former estimation (decision 0017), kept as the benchmark's reference: profile likelihood.

    Every trial response is one warm identification of theta; a grid (:data:`GRID_OFFSETS` x
    :data:`GRID_ZETAS`), then Nelder-Mead in ``(f_b0, ln zeta_b)``; standard errors from the profile's
    curvature. Same result record as :func:`fit_frequency_response` (``profile`` instead of ``joint``).
    """
    m_s, mask, f_ref, loglik, best, grid, vals = _grid_basin(est, data, slider_mass_kg, mask)
    x0 = grid[int(np.argmax(vals))]
    simplex = np.array([x0, x0 + [0.004 * f_ref, 0.0], x0 + [0.0, 0.4]])
    opt = optimize.minimize(lambda x: -loglik(x), x0, method="Nelder-Mead",
                            options={"initial_simplex": simplex, "xatol": 1e-4 * f_ref, "fatol": 0.05,
                                     "maxfev": 60})
    x_hat = best["x"]
    cov, _ = _profile_stderr(loglik, x_hat, np.array([1e-4 * f_ref, 0.05]))
    resp = FrequencyResponse(f_ref, float(x_hat[0]), math.exp(float(x_hat[1])))
    final = _clone(est, frequency=resp, init=best["params"]).fit(data, slider_mass_kg=m_s, mask=mask)
    stderr = None
    if cov is not None:
        stderr = {"f_b0_Hz": float(math.sqrt(cov[0, 0])), "zeta_b": float(resp.zeta_b * math.sqrt(cov[1, 1]))}
    rec = frequency_record(
        "estimated", f"TRAIN's runs spread over more than {FREQUENCY_REL_SPREAD:.1%} of their frequency: profile "
        "maximum likelihood", resp, data, stderr=stderr,
        profile={"evaluations": int(opt.nfev) + len(grid), "loglik": float(final.loglik_),
                 "stderr_from": "curvature of the profile log-likelihood" if stderr else "profile not concave"})
    est._publish(replace(final.result_, frequency=rec, settings={**final.result_.settings, "frequency": "auto"}))
    return est


def resolve(est, data) -> tuple[FrequencyResponse | None, dict | None, bool]:
    """``(response to hold fixed, its record, estimate?)`` for the identifier's ``frequency`` setting on ``data``."""
    setting = response_setting(est.frequency)
    if isinstance(setting, FrequencyResponse):
        return setting, frequency_record("fixed", "given", setting, data), False
    if setting == "off":
        return None, None, False
    if frequency_varies(data):
        return None, None, True
    if setting == "contact":
        setting = "auto"
    return None, frequency_record(
        "fixed", f"TRAIN's runs at one drive frequency (spread within {FREQUENCY_REL_SPREAD:.1%}): not identifiable, "
        "gain 1", None, data), False
