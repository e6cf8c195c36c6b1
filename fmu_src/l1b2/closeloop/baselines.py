"""Which predictor family the loop starts from: Eq. 29 or the pure-slip family, by TRAIN's cross-validation.

Contract: :func:`choose_baseline` takes the baselines already identified on
TRAIN (one per family), cross-validates each by the loop's own refit folds
(:func:`l1b2.closeloop.acceptance.cv_errors`: warm refits on the training
folds, free-run error on the held-out runs; the refits keep each baseline's
family and its own drive-frequency response, :func:`family_settings`) and
returns Eq. 29 unless another family's CV free-run nrmse is lower by at
least ``min_drop`` (absolute; the loop's materiality threshold
``min_cv_drop``), then the lowest such family; a family whose CV failed is
never chosen over Eq. 29. Record: family, CV nrmse, folds, TRAIN nrmse, the
fold refits and their evaluations, the threshold. TEST is never used.

Why a threshold: leaving Eq. 29 relaxes its frozen slip ratio, which is what
the loop's *structural* candidates do (:func:`l1b2.closeloop.acceptance.materiality`);
clean data favour the relaxation a little even where Eq. 29 fits the motor
(decision 0026), and the small structural difference
of the other family is then traced as missing effects. The family switch
therefore needs the same material fall as a structural term.

:func:`retag_structural`: with the pure-slip baseline the voltage-dependent
slope is part of the model, so the candidates that Eq. 29 would call
structural (they relax its frozen slip ratio) are ordinary missing effects.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import FitDivergedError
from .acceptance import EffectSet, cv_errors

__all__ = ["identify_families", "choose_baseline", "family_settings", "retag_structural"]


#: the family kept unless another is materially better in cross-validation
DEFAULT_FAMILY = "eq29"


def identify_families(families, fit) -> tuple[dict, dict]:
    """``(fits, failed)``: ``fit(family)`` for each family; with more than one family, a family other than
    Eq. 29 whose fit raises :class:`l1b2.errors.FitDivergedError` is left out and its message kept in
    ``failed`` (the loop then starts from Eq. 29); Eq. 29's failure, or the only family's, is raised."""
    fits, failed = {}, {}
    for family in families:
        try:
            fits[family] = fit(family)
        except FitDivergedError as e:
            if len(families) == 1 or family == DEFAULT_FAMILY:
                raise
            failed[family] = str(e)
    return fits, failed


def choose_baseline(fits: dict, df, mask, m_s, folds, settings, min_drop: float = 0.0) -> tuple[str, dict]:
    """``(family, record)``: Eq. 29 unless a family of ``fits`` (family -> fitted model) has a CV free-run
    nrmse lower by at least ``min_drop`` (then the lowest); see the module."""
    rec = {"folds": len(folds), "min_drop": float(min_drop), "families": {}}
    cv = {}
    for family, est in fits.items():
        err = cv_errors(df, mask, m_s, folds, est.params_, [(EffectSet(), None)], family_settings(settings, est))[0]
        nrmse = float(err.nrmse)
        cv[family] = nrmse if np.isfinite(nrmse) else np.inf
        rec["families"][family] = {"cv_free_run_nrmse": nrmse if np.isfinite(nrmse) else None,
                                   "folds_failed": int(np.sum(~np.isfinite(err.sse))),
                                   "refits": len(folds), "nfev": int(err.nfev),
                                   "train_free_run_nrmse": _train_nrmse(est, df, mask)}
    best = DEFAULT_FAMILY if DEFAULT_FAMILY in cv else next(iter(cv))
    lowest = min(cv, key=cv.get)
    if np.isfinite(cv[lowest]) and cv[lowest] < cv[best] and cv[best] - cv[lowest] >= min_drop:
        best = lowest
    rec["chosen"] = best
    return best, rec


def family_settings(settings, est):
    """``settings`` with ``est``'s own drive-frequency response held by every refit (``settings`` unchanged when
    ``est`` has none, or when ``settings`` is None): each family is cross-validated as the loop would extend it,
    its response estimated on TRAIN when TRAIN's frequency varies (decision 0040)."""
    resp = getattr(getattr(est, "result_", None), "frequency_response", None)
    if settings is None or resp is None:
        return settings
    return dataclasses.replace(settings, frequency=resp)


def _train_nrmse(est, df, mask) -> float:
    v = df["speed_m_s"].to_numpy(float)
    e = (est.predict_free_run(df) - v)[mask]
    return float(np.sqrt(np.mean(e ** 2)) / np.sqrt(np.mean(v[mask] ** 2)))


def retag_structural(pool, drive_law: str):
    """The candidate pool for a baseline of ``drive_law``: with ``"pure_slip"`` no candidate is structural."""
    if drive_law != "pure_slip":
        return pool
    return [dataclasses.replace(c, structural="") if c.structural else c for c in pool]
