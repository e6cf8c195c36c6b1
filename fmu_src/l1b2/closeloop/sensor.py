"""The measurement chain's second stage: the speed sensor's gain along the stroke.

A speed recorded through a position transducer whose scale factor varies along the stroke is
``v_rec = g(s) v`` (:class:`l1b2.predictor.effects.sensor.SpeedSensorGain`): the motor's dynamics are unchanged and
the recorded column is still the recorded position's derivative, so the speed channel's own test
(:func:`l1b2.closeloop.chain.speed_channel`) cannot see it; only the physics model's residual can. The stage:

It is decided as every sensor stage is (:mod:`l1b2.closeloop.stagefit`):

* **screen** (:func:`screen`): the baseline's TRAIN residual (drive coordinates) regressed on the gain's response
  columns ``P_j(x) v_pred`` (exact: the gain multiplies the output, no recursion), with the baseline's nuisance
  responses (:func:`l1b2.closeloop.selection.nuisance_forces`) in both models, cross-validated over the runs'
  folds (:class:`~l1b2.closeloop.selection.FoldSolver`); evidence: the held-out gain and the runs' one-sided
  Wilcoxon p-value;
* **fit** (:func:`fit_gain`, as a stage :func:`fit_chain`): given a model's free run ``v``, the coefficients are
  the least squares of ``v_rec - v`` on ``P_j(x) v`` (linear in ``c``), with standard errors clustered by run (a
  run's residual is correlated along it);
* **decision** (:func:`l1b2.closeloop.stagefit.stage_cv_errors` with :func:`fit_chain`): the physics refitted
  behind the gain (on ``v_rec / g(s)``, :func:`gain_frame`) against the baseline refitted on the recorded speed,
  both per fold of the refit folds, the held-out recorded speed predicted in free run (the gain's coefficients
  re-estimated on each fold's training runs only).
"""

from __future__ import annotations

from functools import partial

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..predictor.effects.sensor import STROKE_GAIN_ORDER, SpeedSensorGain, stroke_basis
from . import stagefit

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

    def refit(self, df: pd.DataFrame, mask, v_model) -> GainChain:
        """:func:`fit_chain` on this gain's position range and order."""
        return fit_chain(df, mask, v_model, (self.gain.s_lo, self.gain.s_hi), self.gain.order)


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


def fit_chain(df: pd.DataFrame, mask, v_model, s_range, order: int = STROKE_GAIN_ORDER) -> GainChain:
    """:func:`fit_gain` as a stage of the measurement chain (:class:`GainChain`)."""
    return GainChain(fit_gain(df, mask, v_model, s_range, order))


def stage_fit(df: pd.DataFrame, order: int = STROKE_GAIN_ORDER):
    """The gain's fit function on TRAIN ``df`` (:func:`fit_chain`, its basis scaled to ``df``'s position range,
    :func:`position_range`): what :func:`l1b2.closeloop.stagefit.stage_cv_errors` and
    :func:`~l1b2.closeloop.stagefit.physics_behind` take."""
    return partial(fit_chain, s_range=position_range(df), order=order)


def gain_columns(df: pd.DataFrame, v_pred, order: int = STROKE_GAIN_ORDER) -> np.ndarray:
    """``(n, order + 1)``: the recorded speed's response to the gain's coefficients in drive coordinates,
    ``d P_j(x) v_pred`` (:meth:`~l1b2.predictor.effects.sensor.SpeedSensorGain.response`; ``x`` scaled to
    ``df``'s position range, ``d`` the direction, ``v_pred`` [m/s] the model's free run, data convention)."""
    zero = SpeedSensorGain(*position_range(df), (0.0,) * (order + 1))
    return zero.response(df[dataio.POSITION].to_numpy(float),
                         df[dataio.DIRECTION].to_numpy(float) * np.asarray(v_pred, float))


def screen(df: pd.DataFrame, mask, v_pred, params, m_s: float, folds, order: int = STROKE_GAIN_ORDER) -> dict:
    """Cross-validated evidence of the gain against the baseline ``params`` (free run ``v_pred`` [m/s]):
    :func:`l1b2.closeloop.stagefit.screen` of the gain's response columns (:func:`gain_columns`), ``{"cv_gain",
    "p_value", "runs_improved"}``."""
    return stagefit.screen(df, mask, v_pred, params, m_s, folds, gain_columns(df, v_pred, order))
