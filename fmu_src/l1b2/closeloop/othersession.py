"""TEST recorded in another session than TRAIN: the effects that are facts of TRAIN's session predict its average.

An effect of a family whose ``session_average`` flag is set (:class:`l1b2.predictor.effects.blocks.SessionBlocks`:
contiguous blocks of the session's runs, found on TRAIN's deviations) says what TRAIN's session did at each of its
times. TEST runs recorded between TRAIN's on one clock (:func:`l1b2.closeloop.events.one_session`: no two runs
overlap in time) lie in those blocks and take their levels. When a TEST run overlaps a TRAIN run in time, TEST was
recorded on a clock of its own (another session, a file whose clock starts again); its times then place its runs
in TRAIN's blocks by accident. The effect's columns are centred on TRAIN's runs, so with its parameters at zero
the model predicts TRAIN's session average (:func:`averaged`), as the calibrated model does
(:func:`l1b2.closeloop.calibrated.calibrated_model`). The loop scores such a TEST with that model
(:func:`for_test`) and the report says so (:func:`record`,
:func:`l1b2.closeloop.report.other_session_line`).

TEST runs that do not overlap TRAIN's but lie before or after them are one session with TRAIN's: the first or the
last block holds them (the family's contract). Effects of the session clock that are not facts of the session (a
drift in ``time_s``) read TEST's own clock as logged; the report names them (:func:`clock_readers`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..data.metrics import report_metrics
from ..predictor import effects as fx
from ..predictor.effects import family
from .acceptance import SESSION_SIGNALS, validated

__all__ = ["session_facts", "clock_readers", "SessionAverage", "averaged", "for_test", "metrics", "record"]


def session_facts(effects) -> list[str]:
    """The labels of the effects in ``effects`` (an :class:`~l1b2.closeloop.acceptance.EffectSet`) whose family is
    a fact of the recorded session (``session_average``); a candidate without a spec (a user's, with a Python
    feature function only) is none."""
    return [c.label for c in effects.candidates if c.spec and family(c.spec.get("kind")).session_average]


def clock_readers(effects) -> list[str]:
    """The labels of the effects in ``effects`` that read the session clock ``time_s`` (along the stroke or as a
    run's value) and are not facts of the session: on a TEST of another session they read TEST's own times as if
    they were TRAIN's (a warm-up since the session's start repeats in a new session, a wear over the rig's life
    does not)."""
    facts = set(session_facts(effects))
    out = []
    for c in effects.candidates:
        try:
            reads = bool(c.spec) and bool(fx.needs(c.spec) & SESSION_SIGNALS)
        except fx.EffectSpecError:
            reads = False
        if reads and c.label not in facts:
            out.append(c.label)
    return out


class SessionAverage:
    """A fitted model (:class:`~l1b2.closeloop.acceptance.Validated` or
    :class:`~l1b2.ident.estimator.PredictorIdentifier` with the extra forces of ``effects``) predicting with the
    parameters of every :func:`session_facts` effect at zero: the same fit at TRAIN's session average. The model
    itself is not changed. ValueError when its extra parameters are not the effects' in order."""

    def __init__(self, model, effects):
        facts = set(session_facts(effects))
        names = [n for c in effects.candidates for n in c.names]
        if list(model.extra_names_) != names:
            raise ValueError(f"the model's extra parameters {list(model.extra_names_)} are not the effects' {names}")
        zero = np.concatenate([np.full(len(c.names), c.label in facts) for c in effects.candidates])
        values = np.array(model.result_.values, float)
        values[model.result_.p_theta:][zero] = 0.0
        self.model, self.result_ = model, replace(model.result_, values=values)

    def predict_free_run(self, df) -> np.ndarray:
        return self.result_.predict(validated(df), "free_run")

    def predict_one_step(self, df) -> np.ndarray:
        return self.result_.predict(validated(df), "one_step")

    def __getattr__(self, name):
        if name in ("model", "result_"):
            raise AttributeError(name)
        return getattr(self.model, name)


def averaged(model, effects):
    """:class:`SessionAverage` of ``model`` when ``effects`` hold a :func:`session_facts` effect, else ``model``."""
    return SessionAverage(model, effects) if session_facts(effects) else model


def for_test(model, effects, one_session: bool):
    """The model that predicts TEST: ``model`` when TRAIN and TEST are one session, else :func:`averaged`."""
    return model if one_session else averaged(model, effects)


def metrics(model, dtr, dte, train_free_run=None, test_model=None) -> dict:
    """TRAIN and TEST metrics of ``model`` (``train_free_run``: its free run on ``dtr``, when already computed;
    ``test_model``: the model that predicts TEST, default ``model``; ``dte`` None: no TEST metrics)."""
    fr = model.predict_free_run(dtr) if train_free_run is None else train_free_run
    te = model if test_model is None else test_model
    return {"train": report_metrics(dtr, model.predict_one_step(dtr), fr),
            "test": (report_metrics(dte, te.predict_one_step(dte), te.predict_free_run(dte))
                     if dte is not None else None)}


def record(one_session: bool, effects) -> dict:
    """The report's ``test_session``: ``{"one_session", "session_average", "own_clock"}``, the labels of the
    effects that predict TRAIN's session average on TEST (:func:`session_facts`) and of those that read TEST's own
    clock (:func:`clock_readers`); both empty when TRAIN and TEST are one session."""
    return {"one_session": bool(one_session), "session_average": [] if one_session else session_facts(effects),
            "own_clock": [] if one_session else clock_readers(effects)}
