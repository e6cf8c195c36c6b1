"""``session_cycle``: a cycle of the session's clock, one run-level effect that comes and goes with a period.

Much of what changes a rig's runs over a session comes and goes: a thermostat that switches the holder's or the
enclosure's heater, an air conditioner's cycle, a chiller, a neighbour's machine on a duty cycle. The runs then share
a deviation from the model that follows the session clock periodically. No logged channel follows it, a smooth
function of the clock (a drift) does not, and blocks of the session follow it only with many levels.

With ``P`` [s] the period the close loop's run-level analysis found (:mod:`l1b2.closeloop.cycle`) and ``t_r`` [s]
a run's mean session time, the family's columns are the cycle's cosine and sine, centred on their means over
TRAIN's runs (``m_c``, ``m_s``), each scaling the drive force:

    ``dF = (a (cos(2 pi t_r / P) - m_c) + b (sin(2 pi t_r / P) - m_s)) V0 / V_ref``

two parameters ``a``, ``b`` [N] (:func:`cycle_columns`): the cycle's amplitude and phase. A run-level form, constant
along each run: a cycle of tens of seconds barely moves within a run of under a second. Its refit is cross-validated
over blocks of the session (it depends on the session clock, so the held-out runs are stretches the cycle must
carry over, :func:`l1b2.closeloop.acceptance.time_dependent`). ``Predictor.fmu`` has no input for the session clock,
so the family is not exportable (:func:`l1b2.predictor.effects.channels.export_problem`), and its columns average to
zero over TRAIN's runs, so the calibrated model leaves it out and predicts the session's average
(:attr:`SessionCycle.session_average`, :func:`l1b2.closeloop.calibrated.calibrated_model`), as for the session's
blocks (:mod:`l1b2.predictor.effects.blocks`).
"""

from __future__ import annotations

import numpy as np

from .base import V_REF, Effect, EffectSpecError, num, register, signal
from .channels import SESSION_TIME, signal_key

#: the run-level transform name of a cycle's signal in the close loop's run-level analysis
CYCLE = "cycle"


def cycle_spec(period_s: float, cos_mean: float, sin_mean: float) -> dict:
    """A cycle's scalars in a spec: ``period_s`` [s] and the means ``cos_mean``, ``sin_mean`` of its columns over
    TRAIN's runs."""
    P = float(period_s)
    if not np.isfinite(P) or P <= 0:
        raise EffectSpecError(f"session cycle: a period in s above 0 needed, got {period_s!r}")
    return {"channel": SESSION_TIME, "period_s": P, "cos_mean": float(cos_mean), "sin_mean": float(sin_mean)}


def cycle_waves(t_s, period_s: float) -> np.ndarray:
    """``[cos(2 pi t / P), sin(2 pi t / P)]`` of session times ``t_s`` [s], ``(n, 2)``."""
    w = 2.0 * np.pi * np.asarray(t_s, float) / float(period_s)
    return np.column_stack([np.cos(w), np.sin(w)])


def cycle_columns(t_s, period_s: float, means) -> np.ndarray:
    """The cycle's centred columns ``(n, 2)``: :func:`cycle_waves` less ``means`` (``(m_c, m_s)``)."""
    return cycle_waves(t_s, period_s) - np.asarray(means, float)[None, :]


@register
class SessionCycle(Effect):
    """``session_cycle``: a cycle of the session's clock scaling the drive force of each run (module docstring).

    Not listed by any candidate library: the close loop's run-level analysis offers :meth:`hypotheses` of a
    significant cycle (report family ``session_cycle(<P> s)``).
    """

    kind = "session_cycle"
    regressor = "session_cycle"
    group = "run_level"
    description = ("a cycle of the session's clock (a thermostat, an air conditioner, a duty cycle) scaling the drive "
                   "force (constant along the stroke)")
    #: ``Predictor.fmu`` has no input for the session clock (module docstring)
    exportable = False
    #: a fact of the recorded session whose columns average to zero over TRAIN's runs (module docstring)
    session_average = True

    @staticmethod
    def label(period_s: float) -> str:
        """The report's name of a cycle's signal, ``session_cycle(<P> s)``."""
        return f"session_cycle({float(period_s):.1f} s)"

    def needs(self, spec):
        return super().needs(spec) | {signal_key(SESSION_TIME, "run")}

    def features(self, spec, x):
        """``(cos - m_c, sin - m_s) V0/V_ref`` of the run's mean session time (:func:`cycle_columns`)."""
        X = cycle_columns(signal(x, signal_key(SESSION_TIME, "run")), num(spec, "period_s"),
                          (num(spec, "cos_mean"), num(spec, "sin_mean")))
        return X * (signal(x, "V0") / V_REF)[:, None]

    def width(self, spec):
        return 2

    def channel_mean(self, spec):
        return None

    def hypotheses(self, cycles: list) -> list:
        """One hypothesis per cycle ``{"period_s", "means"}``: ``cycle_cos_run_gain``, ``cycle_sin_run_gain`` [N]."""
        out = []
        for cy in cycles:
            spec = cycle_spec(cy["period_s"], *cy["means"])
            label = self.label(spec["period_s"])
            out.append(self.hypothesis(
                ["cycle_cos_run_gain", "cycle_sin_run_gain"], ["N", "N"], spec, "run", family=label, generic=True,
                description=f"{label}: a cycle of the session's clock with a period of {spec['period_s']:.1f} s, "
                "scaling the drive force (against the runs' average)"))
        return out

    def grid(self, train):
        """The hypothesis of every cycle ``train``'s session clock record holds (``cycle_period_s`` and
        ``cycle_means``, what :mod:`l1b2.closeloop.cycle` finds). The loop does not list these: its run-level
        analysis offers :meth:`hypotheses` of a significant cycle."""
        return self.hypotheses([{"period_s": ch["cycle_period_s"], "means": ch["cycle_means"]} for ch in train.channels
                                if ch.get("name") == SESSION_TIME and "cycle_period_s" in ch and "cycle_means" in ch])
