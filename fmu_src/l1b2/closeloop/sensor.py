"""The measurement chain's second stage: the speed sensor's gain along the stroke.

A speed recorded through a position transducer whose scale factor varies along the stroke is
``v_rec = g(s) v`` (:class:`l1b2.predictor.effects.sensor.SpeedSensorGain`): the motor's dynamics are unchanged and
the recorded column is still the recorded position's derivative, so the speed channel's own test
(:func:`l1b2.closeloop.chain.speed_channel`) cannot see it; only the physics model's residual can. The stage:

* **screen** (:func:`screen`): the baseline's TRAIN residual (drive coordinates) regressed on the gain's response
  columns ``P_j(x) v_pred`` (exact: the gain multiplies the output, no recursion), with the baseline's nuisance
  responses (:func:`l1b2.closeloop.selection.nuisance_forces`) in both models, cross-validated over the runs'
  folds (:class:`~l1b2.closeloop.selection.FoldSolver`); evidence: the held-out gain and the runs' one-sided
  Wilcoxon p-value;
* **fit** (:func:`fit_gain`): given a model's free run ``v``, the coefficients are the least squares of
  ``v_rec - v`` on ``P_j(x) v`` (linear in ``c``), with standard errors clustered by run (a run's residual is
  correlated along it);
* **decision** (:func:`gain_cv_errors`): the physics refitted behind the gain (on ``v_rec / g(s)``,
  :func:`gain_frame`) against the baseline refitted on the recorded speed, both per fold of the refit folds,
  the held-out recorded speed predicted in free run (the gain's coefficients re-estimated on each fold's
  training runs only).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..errors import IdentificationError
from ..predictor.effects.sensor import STROKE_GAIN_ORDER, SpeedSensorGain, stroke_basis
from . import residuals as res
from .acceptance import EffectSet, RefitSettings, fold_fit_data, refit, stage_cv_errors
from .folds import held_out_split
from .selection import FoldSolver, finite_columns, linear_response, nuisance_forces

#: the family's name in reports
STROKE_GAIN = "sensor_stroke_gain"
DESCRIPTION = ("the speed sensor's gain varies along the stroke (a measurement effect, not a force): the recorded "
               "speed is g(s) times the slider's, g(s) = 1 + sum_j c_j P_j(x) in the scaled position")


class GainChain:
    """The measurement chain of a sensor gain: the physics is fitted on :meth:`frame` and its prediction of the
    slider's speed is turned into the recorded one by :meth:`apply` (the interface of
    :class:`~l1b2.closeloop.chain.OutputFilter`)."""

    def __init__(self, gain: SpeedSensorGain):
        self.gain = gain

    def frame(self, df: pd.DataFrame) -> pd.DataFrame:
        """:func:`gain_frame`."""
        return gain_frame(df, self.gain)

    def apply(self, df: pd.DataFrame, u) -> np.ndarray:
        """The recorded speed ``g(s) u`` [m/s] at ``df``'s recorded positions."""
        return self.gain.apply(df[dataio.POSITION].to_numpy(float), u)


def gain_frame(df: pd.DataFrame, gain: SpeedSensorGain) -> pd.DataFrame:
    """A copy of ``df`` whose speed column is the slider's speed behind the sensor, ``v_rec / g(s)`` [m/s]."""
    out = df.copy()
    out[dataio.SPEED] = gain.remove(df[dataio.POSITION].to_numpy(float), df[dataio.SPEED].to_numpy(float))
    return out


def position_range(df: pd.DataFrame) -> tuple[float, float]:
    """``(min, max)`` of the recorded position [m]: the range the gain's basis is scaled to."""
    pos = df[dataio.POSITION].to_numpy(float)
    return float(pos.min()), float(pos.max())


def fit_gain(df: pd.DataFrame, mask, v_model, s_range, order: int = STROKE_GAIN_ORDER) -> SpeedSensorGain:
    """The gain whose ``g(s) v_model`` fits the recorded speed best on the masked samples (least squares of
    ``v_rec - v_model`` on ``P_j(x) v_model``), with run-clustered standard errors (sandwich)."""
    m = np.asarray(mask, bool)
    s = df[dataio.POSITION].to_numpy(float)[m]
    v = np.asarray(v_model, float)[m]
    r = df[dataio.SPEED].to_numpy(float)[m] - v
    X = stroke_basis(s, *s_range, order) * v[:, None]
    XtX_inv = np.linalg.pinv(X.T @ X)
    coef = XtX_inv @ (X.T @ r)
    e = r - X @ coef
    runs = df[dataio.RUN].to_numpy()[m]
    _, code = np.unique(runs, return_inverse=True)
    score = np.zeros((code.max() + 1, X.shape[1])) if len(code) else np.zeros((0, X.shape[1]))
    np.add.at(score, code, X * e[:, None])
    cov = XtX_inv @ (score.T @ score) @ XtX_inv
    return SpeedSensorGain(float(s_range[0]), float(s_range[1]), tuple(float(c) for c in coef),
                           tuple(float(np.sqrt(max(c, 0.0))) for c in np.diag(cov)))


def gain_columns(df: pd.DataFrame, v_pred, order: int = STROKE_GAIN_ORDER) -> np.ndarray:
    """``(n, order + 1)``: the recorded speed's response to the gain's coefficients in drive coordinates,
    ``d P_j(x) v_pred`` (:meth:`~l1b2.predictor.effects.sensor.SpeedSensorGain.response`; ``x`` scaled to
    ``df``'s position range, ``d`` the direction, ``v_pred`` [m/s] the model's free run, data convention)."""
    zero = SpeedSensorGain(*position_range(df), (0.0,) * (order + 1))
    return zero.response(df[dataio.POSITION].to_numpy(float),
                         df[dataio.DIRECTION].to_numpy(float) * np.asarray(v_pred, float))


def screen(df: pd.DataFrame, mask, v_pred, params, m_s: float, folds, order: int = STROKE_GAIN_ORDER) -> dict:
    """Cross-validated evidence of the gain against the baseline ``params`` (free run ``v_pred`` [m/s]).

    Returns ``{"cv_gain", "p_value", "runs_improved"}``: the pooled held-out share of the nuisance-only model's
    sum of squares the gain's response columns remove, the one-sided Wilcoxon p-value of the runs' reductions and
    the share of runs improved.
    """
    m = np.asarray(mask, bool)
    idx = np.flatnonzero(m)
    d = df[dataio.DIRECTION].to_numpy(float)
    v_pred = np.asarray(v_pred, float)
    y = (d * (df[dataio.SPEED].to_numpy(float) - v_pred))[idx]
    with np.errstate(over="ignore", invalid="ignore"):
        N = finite_columns(linear_response(params, df, m_s, nuisance_forces(params, df, v_pred), v_pred=v_pred)[idx])
    S = gain_columns(df, v_pred, order)[idx]
    runs = df[dataio.RUN].to_numpy()[idx]
    gain, per_run = FoldSolver(y, N, runs, folds).gain(S)
    return {"cv_gain": float(gain), "p_value": float(res.wilcoxon_greater(per_run)),
            "runs_improved": float(np.mean(per_run > 0)) if len(per_run) else 0.0}


def gain_fold_error(df: pd.DataFrame, mask: np.ndarray, m_s: float, held_runs, init, settings: RefitSettings,
                    v_base, s_range, order: int = STROKE_GAIN_ORDER) -> tuple:
    """One fold of the gain's model: on the training runs the gain from the baseline's free run ``v_base``
    (:func:`fit_gain`), the physics refitted behind it, the gain refitted on that model's free run; the held-out
    runs' recorded speed predicted as ``g(s)`` times the physics' free run. Returns what
    :func:`~l1b2.closeloop.acceptance.fold_error` returns: ``(sse, ss_meas, failed, nfev, run_sse)``."""
    split = held_out_split(df, mask, held_runs)
    train, test, m_tr = split.train, split.test, split.mask_train
    try:
        g0 = fit_gain(train, m_tr, np.asarray(v_base, float)[~split.held], s_range, order)
        est = refit(*fold_fit_data(gain_frame(train, g0), m_tr), m_s, init, EffectSet(), settings)
        g1 = fit_gain(train, m_tr, est.predict_free_run(gain_frame(train, g0)), s_range, order)
        pred = g1.apply(test[dataio.POSITION].to_numpy(float), est.predict_free_run(gain_frame(test, g1)))
    except (IdentificationError, np.linalg.LinAlgError):
        return split.failed()
    return split.score(pred, est.convergence_.get("nfev_total", 0))


def gain_cv_errors(df: pd.DataFrame, mask: np.ndarray, m_s: float, folds, init, settings: RefitSettings,
                   v_base, order: int = STROKE_GAIN_ORDER) -> dict:
    """Held-out free-run sums of squares of the baseline (refitted on the recorded speed) and of the gain's model
    (:func:`gain_fold_error`), both from ``init`` on the same ``folds``
    (:func:`~l1b2.closeloop.acceptance.stage_cv_errors`: ``{"sse_baseline", "sse_stage", "ss_meas", "failed",
    "nfev", "folds_improved"}``)."""
    return stage_cv_errors(df, mask, m_s, folds, init, settings, gain_fold_error,
                           (v_base, position_range(df), order), "l1b2-sensor-gain-cv")
