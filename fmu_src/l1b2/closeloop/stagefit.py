"""The sensor stages of the measurement chain, decided by one skeleton: screen, physics behind, folds, verdict.

A sensor stage turns the physics' prediction of the slider's speed into the recorded one: the time stamps' chain
(:class:`l1b2.closeloop.stamps.StampChain`), the position sensor's cyclic error
(:class:`l1b2.closeloop.encoder.CyclicChain`), the speed sensor's gain along the stroke
(:class:`l1b2.closeloop.sensor.GainChain`). A stage has

* ``frame(df)``: a copy of ``df`` as the physics behind the stage sees it (the stage undone on the recorded
  columns);
* ``apply(df, u)``: the recorded speed [m/s] of the slider's speed ``u`` [m/s] at ``df``'s samples;
* ``refit(df, mask, v_model)``: the stage of the same shape (the cyclic error's pitch, the gain's position range
  and order) refitted on the masked samples of ``df`` to a model's free run ``v_model`` [m/s];

and its fit function ``fit(df, mask, v_model)`` gives the stage from the baseline's free run (the shape chosen
there: the cyclic error's pitch refined on the samples it is given). Every stage is decided by the same steps:

* **screen** (:func:`screen`): the baseline's TRAIN residual (drive coordinates) regressed on the stage's response
  columns, with the baseline's nuisance responses (:func:`l1b2.closeloop.selection.nuisance_forces`) in both
  models, cross-validated over the runs' folds (:class:`~l1b2.closeloop.selection.FoldSolver`); the held-out gain
  and the runs' one-sided Wilcoxon p-value;
* **the physics behind it** (:func:`physics_behind`): the stage fitted to the baseline's free run, the physics
  identified on the frame behind it, the stage refitted to that physics' free run;
* **decision** (:func:`stage_cv_errors`, :func:`stage_verdict`): the baseline refitted on the recorded speed
  against the physics refitted behind the stage (:func:`stage_fold_error`), per fold of the refit folds, the
  held-out recorded speed predicted in free run (the stage fitted on each fold's training runs only).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..cluster import run_tasks
from ..data import measurements as dataio
from ..errors import IdentificationError
from . import residuals as res
from .acceptance import EffectSet, RefitSettings, fold_error, fold_fit_data, refit
from .folds import held_out_split
from .selection import FoldSolver, finite_columns, linear_response, nuisance_forces, usable_response


def screen(df: pd.DataFrame, mask, v_pred, params, m_s: float, folds, columns, rivals: dict | None = None) -> dict:
    """Cross-validated evidence of a stage against the baseline ``params`` (free run ``v_pred`` [m/s]).

    ``columns``: the recorded speed's response to the stage's parameters in drive coordinates, one row per sample
    of ``df`` (one column or ``(n, k)``); ``rivals``: other responses (name -> columns) screened on the same folds
    and nuisance. Returns ``{"cv_gain", "p_value", "runs_improved"}``: the pooled held-out share of the
    nuisance-only model's sum of squares the stage's columns remove, the one-sided Wilcoxon p-value of the runs'
    reductions and the share of runs improved; and ``<name>_cv_gain``, the held-out share each rival removes. Columns
    that are not all finite on the masked samples (a linearised response that diverges) or all zero score as the
    candidates' screen scores them (:func:`l1b2.closeloop.selection.usable_response`): no gain, p-value 1, no run
    improved.
    """
    idx = np.flatnonzero(np.asarray(mask, bool))
    v_pred = np.asarray(v_pred, float)
    y = res.drive_residual(df, v_pred)[idx]
    with np.errstate(over="ignore", invalid="ignore"):
        N = finite_columns(linear_response(params, df, m_s, nuisance_forces(params, df, v_pred), v_pred=v_pred)[idx])
    solver = FoldSolver(y, N, df[dataio.RUN].to_numpy()[idx], folds)
    S = np.asarray(columns, float).reshape(len(df), -1)[idx]
    out = {"cv_gain": 0.0, "p_value": 1.0, "runs_improved": 0.0}
    if usable_response(S):
        gain, per_run = solver.gain(S)
        out = {"cv_gain": float(gain), "p_value": float(res.wilcoxon_greater(per_run)),
               "runs_improved": float(np.mean(per_run > 0)) if len(per_run) else 0.0}
    for name, cols in (rivals or {}).items():
        R = np.asarray(cols, float).reshape(len(df), -1)[idx]
        out[f"{name}_cv_gain"] = float(solver.gain(R)[0]) if usable_response(R) else 0.0
    return out


def physics_behind(df: pd.DataFrame, mask, v_base, fit, identify) -> tuple:
    """``(model, stage)`` on ``df``: the stage fitted to the baseline's free run ``v_base`` [m/s] (``fit(df, mask,
    v_base)``), the physics identified on the frame behind it (``identify(frame)``), the stage refitted to that
    model's free run on that frame (the stage's ``refit``)."""
    first = fit(df, mask, v_base)
    model = identify(first.frame(df))
    return model, first.refit(df, mask, model.predict_free_run(first.frame(df)))


def stage_fold_error(df: pd.DataFrame, mask: np.ndarray, m_s: float, held_runs, init, settings: RefitSettings,
                     v_base, fit) -> tuple:
    """One fold of a stage's model: on the training runs the physics behind the stage (:func:`physics_behind`
    from the baseline's free run ``v_base`` on those runs, the physics refitted from ``init`` as every fold is,
    :func:`~l1b2.closeloop.acceptance.refit`); the held-out runs' recorded speed predicted as the stage applied to
    the physics' free run on the frame behind it. Returns what :func:`~l1b2.closeloop.acceptance.fold_error`
    returns: ``(sse, ss_meas, failed, nfev, run_sse)``."""
    split = held_out_split(df, mask, held_runs)
    m_tr = split.mask_train
    try:
        est, stage = physics_behind(split.train, m_tr, np.asarray(v_base, float)[~split.held], fit,
                                    lambda frame: refit(*fold_fit_data(frame, m_tr), m_s, init, EffectSet(), settings))
        pred = stage.apply(split.test, est.predict_free_run(stage.frame(split.test)))
    except (IdentificationError, np.linalg.LinAlgError):
        return split.failed()
    return split.score(pred, est.convergence_.get("nfev_total", 0))


def stage_cv_errors(df: pd.DataFrame, mask: np.ndarray, m_s: float, folds, init, settings: RefitSettings, v_base,
                    fit, name: str) -> dict:
    """Held-out free-run sums of squares of the baseline (:func:`~l1b2.closeloop.acceptance.fold_error`, refitted
    on the recorded speed) and of a stage's model (:func:`stage_fold_error` with the stage's ``fit``), both from
    ``init`` on the same ``folds``, every fold of both one task of :func:`l1b2.cluster.run_tasks` named ``name``
    (``fit`` then travels with the task): ``{"sse_baseline", "sse_stage", "ss_meas", "failed", "nfev",
    "folds_improved"}`` (per-fold arrays, totals)."""
    task = settings.task()
    args = ([(fold_error, (df, mask, m_s, fold, init, EffectSet(), task, None)) for fold in folds]
            + [(stage_fold_error, (df, mask, m_s, fold, init, task, v_base, fit)) for fold in folds])
    out = [None] * len(args)
    for i, r in run_tasks(_apply, args, client=settings.client, name=name):
        out[i] = r
    k = len(folds)
    sse0 = np.array([r[0] for r in out[:k]])
    sse1 = np.array([r[0] for r in out[k:]])
    return {"sse_baseline": sse0, "sse_stage": sse1, "ss_meas": np.array([r[1] for r in out[:k]]),
            "failed": sum(bool(r[2]) for r in out), "nfev": sum(int(r[3]) for r in out),
            "folds_improved": int(np.sum(sse1 < sse0))}


def stage_verdict(cv: dict, n_folds: int, min_cv_gain: float, name: str = "chain") -> tuple[dict, bool]:
    """The decision on a measurement-chain stage from its :func:`stage_cv_errors` ``cv``: ``(fields, kept)``.

    ``fields``: ``cv_free_run_gain`` (``1 - SSE_stage / SSE_baseline`` pooled over the folds; 0 when a fold failed),
    the two held-out free-run nrmse (``cv_free_run_nrmse_baseline``, ``cv_free_run_nrmse_<name>``) and
    ``cv_folds_improved``; ``kept`` when the gain is at least ``min_cv_gain`` in more than half of the ``n_folds``
    folds."""
    ssm = max(float(cv["ss_meas"].sum()), 1e-300)
    sse0, sse1 = float(cv["sse_baseline"].sum()), float(cv["sse_stage"].sum())
    gain = 1 - sse1 / sse0 if cv["failed"] == 0 and sse0 > 0 else 0.0
    fields = {"cv_free_run_gain": gain, "cv_free_run_nrmse_baseline": float(np.sqrt(sse0 / ssm)),
              f"cv_free_run_nrmse_{name}": float(np.sqrt(sse1 / ssm)), "cv_folds_improved": cv["folds_improved"]}
    return fields, bool(gain >= min_cv_gain and cv["folds_improved"] > n_folds / 2)


def _apply(fn, args):
    return fn(*args)
