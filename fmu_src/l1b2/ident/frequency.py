"""The drive-frequency response in the identification: estimated when TRAIN's frequency varies, held fixed otherwise.

The response (:class:`~l1b2.predictor.frequency.FrequencyResponse`: B2
resonance ``f_b0_Hz`` and damping ``zeta_b``, gain 1 at the reference
frequency ``f_ref_Hz``) scales the force factor B'; with the response fixed
the model is the Eq. 29 model at the effective amplitude ``V0 g(f)``, so
every search, Jacobian and uncertainty of :mod:`l1b2.ident` applies unchanged
(:class:`~l1b2.ident.problem.SampleData` takes the response).

Estimation (:func:`fit_frequency_response`) maximises the *profile*
likelihood over the two response parameters: every trial ``(f_b0, zeta_b)``
is one warm local identification of theta at that response (the identifier's
own search, started from the best theta so far). A coarse grid over
resonances on both sides of the drive (0.4-3 % of ``f_ref`` away) and three
dampings finds the basin, a Nelder-Mead search in ``(f_b0 [Hz], ln zeta_b)``
refines it, and the final model is identified at the optimum with the
identifier's full search. Standard errors of ``f_b0`` and ``zeta_b`` come
from the curvature of the profile log-likelihood (central differences; the
profile's Hessian is the inverse of the parameters' covariance block).

Settings (``PredictorIdentifier(frequency=...)``): ``"auto"`` (default)
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
from scipy import optimize

from ..data.coverage import FREQUENCY_REL_SPREAD, frequency_varies, run_frequencies
from ..data.measurements import Measurements
from ..errors import IdentificationError
from ..predictor.frequency import FrequencyResponse

__all__ = ["FREQUENCY_SETTINGS", "response_setting", "reference_frequency", "frequency_record",
           "frequency_report_lines", "fit_frequency_response", "GRID_OFFSETS", "GRID_ZETAS"]

FREQUENCY_SETTINGS = ("auto", "off")
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
    return [f"    drive frequency: response {rec['status'].upper()} ({rec.get('reason', '')}): "
            f"B' x g(f), B2 f_b0 = {pm('f_b0_Hz', '.1f')} Hz, zeta_b = {pm('zeta_b', '.5f')}, "
            f"g(f_ref = {r['f_ref_Hz']:.1f} Hz) = 1"]


def _clone(est, **changes):
    return type(est)(**{**est.get_params(), **changes})


def _profile(est, data, m_s, mask, f_ref, log):
    """The profile log-likelihood l(f_b0, ln zeta) with warm inner fits (the best theta so far as start)."""
    best: dict[str, Any] = {"loglik": -np.inf, "params": None, "x": None}
    seen: dict = {}

    def loglik(x):
        key = (round(float(x[0]), 3), round(float(x[1]), 6))
        if key in seen:
            return seen[key]
        try:
            resp = FrequencyResponse(f_ref, float(x[0]), math.exp(float(x[1])))
            fit = _clone(est, frequency=resp, init=best["params"], n_starts=1 if best["params"] is not None
                         else est.n_starts, verbose=False).fit(data, slider_mass_kg=m_s, mask=mask)
            ll = float(fit.loglik_)
        except (IdentificationError, ValueError):
            ll = -np.inf
        if not np.isfinite(ll):
            ll = -np.inf
        seen[key] = ll
        if ll > best["loglik"]:
            best.update(loglik=ll, params=fit.params_, x=np.array(x, float))
        log(f"frequency response: f_b0 {x[0]:.1f} Hz, zeta {math.exp(x[1]):.5f}: loglik {ll:.2f}")
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


def fit_frequency_response(est, data, slider_mass_kg=None, mask=None):
    """Identify the model with its frequency response (``est.frequency == "auto"``, TRAIN's frequency varies).

    Returns the fitted identifier (``est`` itself) whose result carries the
    estimated response and the record ``status="estimated"``.
    """
    log = est._log
    m_s = slider_mass_kg if slider_mass_kg is not None else getattr(data, "slider_mass_kg", None)
    if mask is None and isinstance(data, Measurements):
        mask = data.mask
    f_ref = reference_frequency(data)
    loglik, best = _profile(est, data, m_s, mask, f_ref, log)
    # the basin: a coarse grid of resonances on both sides of the drive and three dampings
    grid = [np.array([f_ref * (1 + o), math.log(z)]) for o in GRID_OFFSETS for z in GRID_ZETAS]
    vals = [loglik(x) for x in grid]
    if not np.isfinite(max(vals)):
        raise IdentificationError("frequency response: no trial response gave a finite fit")
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
    return None, frequency_record(
        "fixed", f"TRAIN's runs at one drive frequency (spread within {FREQUENCY_REL_SPREAD:.1%}): not identifiable, "
        "gain 1", None, data), False
