"""Which predictor family the loop starts from: Eq. 29 or the pure-slip family, by TRAIN's cross-validation.

Contract: :func:`choose_baseline` takes the baselines already identified on
TRAIN (one per family), cross-validates each by the loop's own refit folds
(:func:`l1b2.closeloop.acceptance.cv_errors`: warm refits on the training
folds, free-run error on the held-out runs; the refits keep each baseline's
family) and returns the one with the lower CV free-run nrmse (Eq. 29 on a
tie or when the other's CV failed), with a record of both: family, CV
nrmse, folds, TRAIN nrmse. TEST is never used.

:func:`retag_structural`: with the pure-slip baseline the voltage-dependent
slope is part of the model, so the candidates that Eq. 29 would call
structural (they relax its frozen slip ratio) are ordinary missing effects.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .acceptance import EffectSet, cv_errors

__all__ = ["choose_baseline", "retag_structural"]


def choose_baseline(fits: dict, df, mask, m_s, folds, settings) -> tuple[str, dict]:
    """``(family, record)``: the family with the lower CV free-run nrmse among ``fits`` (family -> fitted model)."""
    rec = {"folds": len(folds), "families": {}}
    best, best_err = None, np.inf
    for family, est in fits.items():
        err = cv_errors(df, mask, m_s, folds, est.params_, [(EffectSet(), None)], settings)[0]
        nrmse = float(err.nrmse)
        rec["families"][family] = {"cv_free_run_nrmse": nrmse if np.isfinite(nrmse) else None,
                                   "folds_failed": int(np.sum(~np.isfinite(err.sse))),
                                   "train_free_run_nrmse": _train_nrmse(est, df, mask)}
        if nrmse < best_err or best is None:
            best, best_err = family, nrmse
    rec["chosen"] = best
    return best, rec


def _train_nrmse(est, df, mask) -> float:
    v = df["speed_m_s"].to_numpy(float)
    e = (est.predict_free_run(df) - v)[mask]
    return float(np.sqrt(np.mean(e ** 2)) / np.sqrt(np.mean(v[mask] ** 2)))


def retag_structural(pool, drive_law: str):
    """The candidate pool for a baseline of ``drive_law``: with ``"pure_slip"`` no candidate is structural."""
    if drive_law != "pure_slip":
        return pool
    return [dataclasses.replace(c, structural="") if c.structural else c for c in pool]
