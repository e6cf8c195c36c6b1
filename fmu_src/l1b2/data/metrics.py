"""Speed-prediction error metrics used in every report.

Implements "Error metrics" of the rig data format (docs/reference/data-format.md). Samples are
evaluated when the measured speed is at least :data:`MIN_EVAL_SPEED_M_S` in
magnitude and the sample is not within the first or last
:data:`END_EXCLUSION_M` of travel of its run (end-stop collisions, as the
paper notes); see :func:`evaluation_mask`. On those samples:

* ``nrmse`` = sqrt(mean((v_pred - v_meas)^2)) / sqrt(mean(v_meas^2))
* ``mean_abs_rel_error``, ``p95_abs_rel_error`` = mean and 95th percentile
  of |v_pred - v_meas| / |v_meas|

The two kinds of prediction, ``one_step`` (v(k+1) from measured v(k), Eq.
28-29 of the paper) and ``free_run`` (the predictor propagates its own speed
along the measured position trajectory from the measured speed of the run's
first sample), are computed elsewhere and scored separately by
:func:`report_metrics`.

A prediction can diverge (the free run of a model used outside the range it
was identified on grows without bound): a run whose prediction is infinite,
or non-finite or faster than :data:`DIVERGED_FACTOR` times the run's fastest
measured speed on an evaluated sample, is a *diverged run*
(:func:`diverged_runs`). :func:`report_metrics` excludes diverged runs from
the metrics and reports them (``n_diverged_runs``, ``diverged_runs``), so a
report never shows ``inf`` or a mean error of 1e183 %.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from .measurements import (
    END_EXCLUSION_M,
    MIN_EVAL_SPEED_M_S,
    DIRECTION,
    LOAD,
    RUN,
    SPEED,
    VOLTAGE,
    Measurements,
    as_1d,
    evaluation_mask,
    run_slices,
)

__all__ = [
    "MIN_EVAL_SPEED_M_S", "END_EXCLUSION_M", "P95_PERCENTILE", "METRIC_KEYS", "DIVERGED_FACTOR",
    "evaluation_mask", "speed_metrics", "report_metrics", "diverged_runs", "level_law_nrmse", "level_law_check",
    "level_law_lines",
]

#: A prediction faster than this many times the run's fastest measured speed (at least 5 mm/s) has diverged.
DIVERGED_FACTOR: float = 10.0

#: Percentile reported as ``p95_abs_rel_error`` [%].
P95_PERCENTILE: float = 95.0
#: Keys of the dictionary returned by :func:`speed_metrics`.
METRIC_KEYS: tuple[str, ...] = ("nrmse", "mean_abs_rel_error", "p95_abs_rel_error", "n_samples")


def speed_metrics(v_pred: Any, v_meas: Any, mask: Any) -> dict[str, float | int]:
    """Error metrics of a speed prediction on the evaluated samples.

    Parameters
    ----------
    v_pred : array_like
        Predicted speed per sample [m/s]. May be NaN outside ``mask`` (e.g.
        no one-step prediction for a run's first sample).
    v_meas : array_like
        Measured speed per sample [m/s].
    mask : array_like of bool
        Samples to evaluate, usually :func:`evaluation_mask`.

    Returns
    -------
    dict
        ``nrmse`` = sqrt(mean((v_pred - v_meas)^2)) / sqrt(mean(v_meas^2)),
        ``mean_abs_rel_error`` and ``p95_abs_rel_error`` = mean and 95th
        percentile (numpy's default linear interpolation) of
        |v_pred - v_meas| / |v_meas| (dimensionless fractions, not %), and
        ``n_samples`` (int). With an empty mask the three values are NaN and
        ``n_samples`` is 0.

    Raises
    ------
    ValueError
        Shapes differ, ``mask`` is not boolean, a masked prediction or
        measurement is NaN / infinite (the message says how many), or a
        masked measured speed is zero (relative error undefined).
    """
    pred = as_1d("v_pred", v_pred)
    meas = as_1d("v_meas", v_meas)
    m = mask.to_numpy() if isinstance(mask, pd.Series) else np.asarray(mask)
    if m.dtype != bool:
        raise ValueError(f"mask must be boolean, got dtype {m.dtype}")
    if not (pred.shape == meas.shape == m.shape):
        raise ValueError(f"v_pred, v_meas and mask differ in shape "
                         f"({pred.shape}, {meas.shape}, {m.shape})")
    n = int(m.sum())
    if n == 0:
        return {"nrmse": float("nan"), "mean_abs_rel_error": float("nan"),
                "p95_abs_rel_error": float("nan"), "n_samples": 0}
    p, y = pred[m], meas[m]
    bad_p = ~np.isfinite(p)
    if bad_p.any():
        first = int(np.flatnonzero(m)[np.flatnonzero(bad_p)[0]])
        raise ValueError(f"{int(bad_p.sum())} of {n} evaluated predictions are NaN or "
                         f"infinite (first at sample index {first})")
    bad_y = ~np.isfinite(y)
    if bad_y.any():
        first = int(np.flatnonzero(m)[np.flatnonzero(bad_y)[0]])
        raise ValueError(f"{int(bad_y.sum())} of {n} evaluated measured speeds are NaN or "
                         f"infinite (first at sample index {first})")
    zero = y == 0.0
    if zero.any():
        raise ValueError(f"{int(zero.sum())} of {n} evaluated measured speeds are zero; "
                         "relative error undefined (use evaluation_mask)")
    err = p - y
    rel = np.abs(err) / np.abs(y)
    return {
        "nrmse": float(np.sqrt(np.mean(err ** 2)) / np.sqrt(np.mean(y ** 2))),
        "mean_abs_rel_error": float(np.mean(rel)),
        "p95_abs_rel_error": float(np.percentile(rel, P95_PERCENTILE)),
        "n_samples": n,
    }


def report_metrics(df: pd.DataFrame | Measurements, v_one_step: Any,
                   v_free_run: Any) -> dict[str, dict[str, float | int]]:
    """Score one-step and free-run predictions of one data set.

    Parameters
    ----------
    df : pandas.DataFrame or Measurements
        Measured data with ``speed_m_s`` [m/s], ``position_m`` [m], ``run``.
    v_one_step : array_like
        One-step prediction per sample [m/s] (v(k+1) from measured v(k)).
    v_free_run : array_like
        Free-run prediction per sample [m/s].

    Returns
    -------
    dict
        ``{'one_step': {...}, 'free_run': {...}}``: :func:`speed_metrics` on
        the :func:`evaluation_mask` of ``df`` without the diverged runs of
        that prediction (:func:`diverged_runs`), plus ``n_runs``,
        ``n_diverged_runs`` and ``diverged_runs`` (their ids). With every
        run diverged the metrics are NaN and ``n_samples`` is 0.
    """
    if isinstance(df, Measurements):
        df = df.df
    mask = evaluation_mask(df)
    v_meas = df[SPEED]
    blocks = run_slices(df[RUN])
    out = {}
    for kind, pred in (("one_step", v_one_step), ("free_run", v_free_run)):
        pred = as_1d("v_pred", pred)
        bad = diverged_runs(df, pred, mask)
        keep = mask.copy()
        for rid, sl in blocks:
            if rid in bad:
                keep[sl] = False
        out[kind] = {**speed_metrics(pred, v_meas, keep), "n_runs": len(blocks),
                     "n_diverged_runs": len(bad), "diverged_runs": bad}
    return out


def diverged_runs(df: pd.DataFrame, v_pred: Any, mask: Any = None) -> list:
    """Runs whose prediction diverged: non-finite where evaluated, or absurdly fast anywhere.

    Parameters
    ----------
    df : pandas.DataFrame
        Measured data with ``speed_m_s`` [m/s] and ``run``.
    v_pred : array_like
        Predicted speed per sample [m/s] (NaN outside the evaluated samples
        is allowed, e.g. the one-step prediction of a run's first sample).
    mask : array_like of bool, optional
        Evaluated samples (default :func:`evaluation_mask`).

    Returns
    -------
    list
        Run ids (file order) with a non-finite prediction on an evaluated
        sample or an infinite one anywhere, or an evaluated prediction faster
        than :data:`DIVERGED_FACTOR` x max(the run's fastest measured speed, 5 mm/s).
    """
    pred = as_1d("v_pred", v_pred)
    meas = as_1d(SPEED, df[SPEED])
    m = evaluation_mask(df) if mask is None else np.asarray(mask, dtype=bool)
    out = []
    for rid, sl in run_slices(df[RUN]):
        p = pred[sl]
        finite = np.isfinite(p)
        limit = DIVERGED_FACTOR * max(float(np.max(np.abs(meas[sl]))), MIN_EVAL_SPEED_M_S)
        judged = finite & m[sl]
        if np.isinf(p).any() or (~finite & m[sl]).any() or \
                (judged.any() and float(np.max(np.abs(p[judged]))) > limit):
            out.append(rid)
    return out


def level_law_nrmse(df: pd.DataFrame, mask: np.ndarray) -> float:
    """The nrmse over ``mask`` of the runs' speed levels' affine law: each run's level is its median measured speed
    on the mask, in drive coordinates (times its direction ``d``); the levels are fitted by least squares on
    ``(1, V0, d m)`` over the runs that have one, and each sample is predicted by its run's fitted level times
    ``d`` (a run with no sample on the mask predicts 0). That is the steady-state law Eq. 29 holds (the drive's
    speed affine in V0 and the load in drive coordinates), with no transient and nothing along the stroke."""
    m = np.asarray(mask, bool)
    v = df[SPEED].to_numpy(float)
    runs = pd.DataFrame({"v": np.where(m, v, np.nan), "run": df[RUN].to_numpy(),
                         "V": df[VOLTAGE].to_numpy(float), "d": df[DIRECTION].to_numpy(float),
                         "m": df[LOAD].to_numpy(float)}).groupby("run", sort=False).agg(
        v=("v", "median"), V=("V", "first"), d=("d", "first"), m=("m", "first"))
    X = np.column_stack([np.ones(len(runs)), runs["V"], runs["d"] * runs["m"]])
    has = np.isfinite(runs["v"].to_numpy(float))
    level = np.zeros(len(runs))
    if has.any():
        coef = np.linalg.lstsq(X[has], (runs["v"] * runs["d"]).to_numpy(float)[has], rcond=None)[0]
        level = np.where(has, X @ coef * runs["d"].to_numpy(float), 0.0)
    pred = df[RUN].map(dict(zip(runs.index, level))).to_numpy(float)
    e = v[m] - pred[m]
    return float(np.sqrt(np.sum(e ** 2) / max(float(np.sum(v[m] ** 2)), 1e-300)))

def level_law_check(df: pd.DataFrame, mask: Any, train_free_run_nrmse: float) -> dict:
    """``{"train_free_run_nrmse", "level_law_nrmse", "above"}``: a fit's free-run nrmse on TRAIN against
    :func:`level_law_nrmse` of TRAIN, and whether the fit is worse than that law (then it has missed the steady state
    its own model holds: a wrong basin of the search, or a model that does not fit these data)."""
    law = level_law_nrmse(df, mask)
    x = float(train_free_run_nrmse)
    return {"train_free_run_nrmse": x, "level_law_nrmse": law, "above": bool(np.isfinite(x) and x > law)}


def level_law_lines(rec: dict | None) -> list[str]:
    """A warning when :func:`level_law_check` found the fit above the level law (none otherwise)."""
    if not rec or not rec.get("above"):
        return []
    return [f"TRAIN's free run ({100 * rec['train_free_run_nrmse']:.2f} % nrmse) is worse than the runs' level law "
            f"({100 * rec['level_law_nrmse']:.2f} %: each run's median speed, affine in V0 and the load): the fit "
            "may have stopped in a wrong basin; try more starts (--starts) or another --seed, and compare the "
            "log-likelihoods"]
