"""The measurement chain's sensor stages in series: each considered behind the ones already kept.

A rig's logged speed can pass through more than one sensor stage: the position sensor's cyclic error
(:mod:`~l1b2.closeloop.encoder`, ``v (1 + e'(s))``) and then a derivative taken over uneven time stamps
(:mod:`~l1b2.closeloop.stamps`, ``r^gamma`` times it). Their effects on the logged speed multiply, and each has
its own signature (an uneven clock; a line in the residual's spectrum over the position), so one does not explain
the other. The stages are therefore decided in turn from the logged side inwards (:data:`ORDER`: the stamps, the
outermost operation of the DAQ, first), each by its own module's rule (screen, then the cross-validated free run
against the current model) on the frame behind the stages already kept, against the physics fitted there.

:class:`SensorChain` holds the kept stages: the physics is fitted on :meth:`SensorChain.frame` (each stage's frame
in turn) and its prediction is turned into the logged speed by :meth:`SensorChain.apply` (each stage's ``apply``
from the innermost outwards, each at the frame it was fitted on). With one stage it is that stage.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from . import encoder, stamps

__all__ = ["ORDER", "SensorChain", "decide_stages"]

#: the sensor stages in the order they are decided: ``(record key, module)`` (module docstring)
ORDER = (("time_stamps", stamps), ("position_cyclic_error", encoder))


class SensorChain:
    """Kept sensor stages in series (module docstring); ``stages`` from the logged side inwards."""

    def __init__(self, stages):
        self.stages = tuple(stages)

    def then(self, stage) -> SensorChain:
        """This chain with ``stage`` kept behind it."""
        return SensorChain(self.stages + (stage,))

    @property
    def regressors(self) -> tuple:
        """Each stage's regressor (what the loop's trace names), logged side first."""
        return tuple(s.regressor for s in self.stages)

    def frame(self, df: pd.DataFrame) -> pd.DataFrame:
        """The frame behind every stage: each stage's ``frame`` in turn."""
        for s in self.stages:
            df = s.frame(df)
        return df

    def apply(self, df: pd.DataFrame, u) -> np.ndarray:
        """The logged speed [m/s] of the slider's speed ``u`` [m/s] predicted on :meth:`frame` of ``df``."""
        frames = [df]
        for s in self.stages[:-1]:
            frames.append(s.frame(frames[-1]))
        for s, f in zip(reversed(self.stages), reversed(frames)):
            u = s.apply(f, u)
        return u

    def parameters(self) -> dict:
        """Every stage's ``extended_parameters`` entries."""
        return {k: v for s in self.stages for k, v in s.parameters().items()}

    def record(self, rec: dict) -> dict:
        """The report's effect record of the round ``rec`` (the stage it added; KeyError when no kept stage did)."""
        for s in self.stages:
            if s.name == rec["added"]:
                return s.record(rec)
        raise KeyError(f"no kept sensor stage added {rec['added']!r}")

    def reading(self) -> str:
        """The message's words on the kept stages."""
        return "; ".join(s.reading() for s in self.stages)

    def model_note(self) -> str:
        """The calibrated model's note: the physics behind every stage."""
        return "".join(s.model_note() for s in self.stages)


def decide_stages(df: pd.DataFrame, mask, m_s: float, folds, model, identify, settings, **rules):
    """Decide the stages of :data:`ORDER` in turn on TRAIN ``df``: ``(records, kept)``.

    Each module's ``decide`` (``rules``: its ``alpha``, ``min_gain``, ``min_cv_gain``) runs on the frame behind the
    stages kept so far, against the physics model fitted there (``model`` at first; ``identify(frame)`` fits the
    physics on a frame). ``records``: each stage's record by its key; ``kept``: ``[(physics model, stage,
    record)]`` in the order kept.
    """
    records, kept, frame = {}, [], df
    for key, module in ORDER:
        rec, out = module.decide(frame, mask, m_s, folds, model, identify, settings, **rules)
        records[key] = rec
        if out is not None:
            model, stage = out
            kept.append((model, stage, rec))
            frame = stage.frame(frame)
    return records, kept
