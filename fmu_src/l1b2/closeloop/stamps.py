"""The measurement chain of the time stamps: a speed derived over stamps that are not the samples' times.

A DAQ samples on its own regular clock, but the logged ``time_s`` may be stamped by a host (on a packet's arrival,
after a latency; a PC clock), so some steps of ``time_s`` within a run are uneven although the sampling was
regular. A speed column the host derives from the position over its own stamps is then, at each sample, the
slider's speed times the sample's time step ratio ``r`` (:func:`l1b2.data.stamps.time_step_ratio`: the run's median
step over the effective step of the derivative over the stamps). When the stamps are the true times of unevenly
taken samples, the speed column is right and ``r`` says nothing about it. A file cannot say which holds; the
data can, and the stage lets them. The chain's form on the prediction's output (:class:`StampChain`) is

    ``v_logged = r^gamma v``, ``gamma`` estimated (1: a speed derived over arrival stamps, 0: true stamps),

and the physics behind it is fitted on the logged speed over ``r^gamma`` (:func:`stamp_frame`; the model runs on
the logged stamps, whose error, a fraction of a step, moves a slow motion's prediction little). The stage is
considered only when the steps of TRAIN's ``time_s`` are uneven (:func:`l1b2.data.plausibility.uneven_steps`): on an
even clock ``r`` is 1 and the loop runs as before. It is decided as every sensor stage is
(:mod:`l1b2.closeloop.stagefit`):

* **screen** (:func:`screen`): the baseline's TRAIN residual (drive coordinates) regressed on the form's response
  at ``gamma = 0``, ``d v_pred ln r`` (exact to first order: the form multiplies the output, no recursion), with
  the baseline's nuisance responses in both models, cross-validated over the runs' folds; the held-out gain and
  the runs' one-sided Wilcoxon p-value. Under true stamps the residual at an uneven step is not proportional to
  ``v_pred ln r``, and there is no gain;
* **fit** (:func:`fit_gamma`): given a model's free run ``v``, ``gamma`` is the least squares of
  ``v_logged - r^gamma v`` (Gauss-Newton from 0);
* **decision** (:func:`l1b2.closeloop.stagefit.stage_cv_errors` with :func:`fit_gamma`): the physics refitted
  behind the form against the baseline refitted on the logged speed, per fold of the refit folds, the held-out
  logged speed predicted in free run (``gamma`` re-estimated on each fold's training runs only).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..data.plausibility import uneven_steps
from ..data.stamps import time_step_ratio
from .acceptance import RefitSettings
from . import stagefit

#: the stage's name in reports
STAMP_CHAIN = "speed_over_time_stamps"
#: its regressor in ``diagnosis.traced_to``: the time stamps' step ratio per sample
REGRESSOR = "time_step_ratio"
DESCRIPTION = ("the speed column was derived over time stamps that are not the samples' times (a host's arrival "
               "stamps): the logged speed is r^gamma times the slider's, r the run's median time step over the "
               "sample's step of the derivative over the stamps")


def ratio(df: pd.DataFrame) -> np.ndarray:
    """The time step ratio per sample of ``df`` (:func:`l1b2.data.stamps.time_step_ratio`) [1]."""
    return time_step_ratio(df[dataio.TIME].to_numpy(float), df[dataio.RUN].to_numpy())


def uneven(df: pd.DataFrame) -> bool:
    """Whether ``df``'s time steps within runs are uneven (:func:`l1b2.data.plausibility.uneven_steps`)."""
    return uneven_steps(df) is not None


class StampChain:
    """The time stamps' chain ``v_logged = r^gamma v`` (the interface of
    :class:`~l1b2.closeloop.chain.OutputFilter`: the physics is fitted on :meth:`frame`, its prediction of the
    slider's speed is turned into the logged one by :meth:`apply`)."""

    name, regressor = STAMP_CHAIN, REGRESSOR

    def __init__(self, gamma: float, stderr: float | None = None):
        self.gamma, self.stderr = float(gamma), stderr

    def frame(self, df: pd.DataFrame) -> pd.DataFrame:
        """:func:`stamp_frame`."""
        return stamp_frame(df, self.gamma)

    def apply(self, df: pd.DataFrame, u) -> np.ndarray:
        """The logged speed ``r^gamma u`` [m/s] at ``df``'s stamps."""
        return ratio(df) ** self.gamma * np.asarray(u, float)

    def refit(self, df: pd.DataFrame, mask, v_model) -> StampChain:
        """:func:`fit_gamma` (``gamma`` estimated anew from 0)."""
        return fit_gamma(df, mask, v_model)

    def to_dict(self) -> dict:
        return {"gamma": self.gamma, "gamma_stderr": self.stderr}

    def parameters(self) -> dict:
        """The report's ``extended_parameters`` entry of ``gamma``."""
        ci = None if self.stderr is None else [self.gamma - 1.96 * self.stderr, self.gamma + 1.96 * self.stderr]
        return {"time_stamp_gamma": {"value": self.gamma, "stderr": self.stderr, "unit": "1", "ci95": ci}}

    def record(self, rec: dict) -> dict:
        """:func:`stage_record`."""
        return stage_record(rec, self)

    def reading(self) -> str:
        """:func:`reading`."""
        return reading(self)

    def model_note(self) -> str:
        """:func:`model_note`."""
        return model_note(self)


def stamp_frame(df: pd.DataFrame, gamma: float) -> pd.DataFrame:
    """A copy of ``df`` whose speed column is the slider's speed behind the stamps' chain, ``v_logged / r^gamma``
    [m/s]."""
    out = df.copy()
    out[dataio.SPEED] = df[dataio.SPEED].to_numpy(float) / ratio(df) ** gamma
    return out


def fit_gamma(df: pd.DataFrame, mask, v_model, iterations: int = 20) -> StampChain:
    """The chain whose ``r^gamma v_model`` fits the logged speed best on the masked samples (least squares,
    Gauss-Newton from ``gamma = 0``), with a run-clustered standard error (sandwich at the solution)."""
    m = np.asarray(mask, bool)
    lr = np.log(ratio(df))[m]
    v = np.asarray(v_model, float)[m]
    y = df[dataio.SPEED].to_numpy(float)[m]
    g = 0.0
    for _ in range(iterations):
        f = v * np.exp(g * lr)
        J = f * lr
        jj = float(J @ J)
        if not jj > 0:
            return StampChain(0.0, None)
        step = float(J @ (y - f)) / jj
        g += step
        if abs(step) < 1e-10:
            break
    f = v * np.exp(g * lr)
    J, e = f * lr, y - f
    _, code = np.unique(df[dataio.RUN].to_numpy()[m], return_inverse=True)
    score = np.bincount(code, weights=J * e)
    return StampChain(g, float(np.sqrt(score @ score) / float(J @ J)))


def response(df: pd.DataFrame, v_pred) -> np.ndarray:
    """The logged speed's response to ``gamma`` at 0 in drive coordinates, ``d v_pred ln r`` (``v_pred`` [m/s] the
    model's free run, data convention)."""
    return df[dataio.DIRECTION].to_numpy(float) * np.asarray(v_pred, float) * np.log(ratio(df))


def screen(df: pd.DataFrame, mask, v_pred, params, m_s: float, folds) -> dict:
    """Cross-validated evidence of the form against the baseline ``params`` (free run ``v_pred`` [m/s]):
    :func:`l1b2.closeloop.stagefit.screen` of the form's response column (:func:`response`), ``{"cv_gain",
    "p_value", "runs_improved"}``."""
    return stagefit.screen(df, mask, v_pred, params, m_s, folds, response(df, v_pred))


def decide(df: pd.DataFrame, mask, m_s: float, folds, model, identify, settings: RefitSettings, *, alpha: float,
           min_gain: float, min_cv_gain: float) -> tuple[dict, tuple | None]:
    """The stage on TRAIN ``df`` against the current ``model`` (the baseline): ``(record, kept)``.

    Considered only when ``df``'s time steps are uneven (:func:`uneven`). Screened (:func:`screen`) at ``alpha``
    and the screen's smallest gain ``min_gain``, as every candidate is; kept when the physics refitted behind the
    form lowers the cross-validated free-run sum of squares of the logged speed by at least ``min_cv_gain``, in
    more than half of the folds (:func:`l1b2.closeloop.stagefit.stage_verdict`). ``identify(frame)``
    fits the physics on a frame. ``kept``: None, or ``(physics model, StampChain)``: ``gamma`` from the baseline's
    free run, the physics identified behind it, ``gamma`` refitted on that model's free run.
    """
    rec = {"effect": STAMP_CHAIN, "regressor": REGRESSOR, "considered": uneven(df), "accepted": False}
    if not rec["considered"]:
        return rec, None
    v_base = model.predict_free_run(df)
    rec.update(screen(df, mask, v_base, model.params_, m_s, folds))
    rec["gamma_of_baseline"] = fit_gamma(df, mask, v_base).to_dict()
    if not (rec["p_value"] < alpha and rec["cv_gain"] >= min_gain):
        return rec, None
    cv = stagefit.stage_cv_errors(df, mask, m_s, folds, model.params_, settings, v_base, fit_gamma,
                                  "l1b2-stamp-chain-cv")
    fields, kept = stagefit.stage_verdict(cv, len(folds), min_cv_gain)
    rec.update(fields)
    if not kept:
        return rec, None
    est, c1 = stagefit.physics_behind(df, mask, v_base, fit_gamma, identify)
    rec.update(accepted=True, description=DESCRIPTION, **c1.to_dict())
    return rec, (est, c1)


def stage_record(rec: dict, chain: StampChain) -> dict:
    """The report's effect record of the kept stage (``rec``: its round)."""
    return {"round": rec["round"], "effect": STAMP_CHAIN, "label": STAMP_CHAIN, "shape": "",
            "regressors": [REGRESSOR], "generic": False, "structural": None,
            "parameters": chain.parameters(),
            "description": DESCRIPTION, "cv_gain": rec["cv"]["cv_gain"], "cv_free_run_nrmse_before": None,
            "cv_free_run_nrmse_after": None, "folds_improved": None}


def reading(chain: StampChain) -> str:
    """The message's words on a kept stage."""
    se = f" +- {chain.stderr:.3f}" if chain.stderr is not None else ""
    return (f"speed derived over uneven time stamps (measurement chain, not a force): logged speed = "
            f"r^gamma x the slider's, gamma {chain.gamma:.3f}{se} (1: stamps given on arrival, 0: true stamps)")


def model_note(chain: StampChain | None) -> str:
    """The calibrated model's note when the stage is kept ("" when not): the model is the physics behind it."""
    if chain is None:
        return ""
    return ("; it is the physics behind the time stamps' chain: it predicts the slider's speed on the samples' "
            f"clock (the logged speed over the stamps is r^gamma times it, gamma {chain.gamma:.3f}: not carried)")
