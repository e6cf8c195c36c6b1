"""The close loop's final model in the form ``Predictor.fmu`` carries, and how its run-level channel inputs are fed.

A run-level effect of a logged setting (a line pressure, a supply voltage set once per run) was identified on the
run means of its column, while ``Predictor.fmu`` reads its input's current value
(:mod:`l1b2.predictor.effects.channels`). The export's run-level contract (``run_spread`` within
:data:`~l1b2.predictor.effects.channels.RUN_CONSTANT_TOL` standard deviations) holds for the plan's own inputs, which
the rig sets exactly. A logged setting is recorded by a sensor, so its samples carry the sensor's noise around
the run's value, and the contract would refuse nearly every such effect. For a logged setting the consequence of
the difference is measured instead (:func:`run_feed`): the final model's free run on TRAIN with the column's
logged samples against the same free run with each run's mean, as a share of the speed's rms. When that is at most
:data:`~l1b2.predictor.effects.channels.RUN_FEED_TOL`, the spec records it (``run_feed``) and the export accepts
the effect; the input is then the run's value, which a host feeds as the run's set point or mean (or the logged
signal, at the recorded cost).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..predictor.effects import ExtendedPredictor, IdentifiedEffect
from ..predictor.effects import channels as fx_channels
from ..predictor.setup import PredictorSetup
from .intervals import reported_covariance, reported_uncertainty
from .othersession import session_facts

__all__ = ["calibrated_model", "frame_free_run", "run_feed", "with_run_feeds"]


def frame_free_run(model: ExtendedPredictor, df: pd.DataFrame, channels: dict | None = None) -> np.ndarray:
    """:meth:`ExtendedPredictor.free_run` over a data frame [m/s]: each run from its first measured speed, the
    temperature and the drive frequency when the frame has them, and ``channels`` (``{column: values per
    sample}``; default: the frame's own columns of :attr:`ExtendedPredictor.channel_inputs`)."""
    first = df.groupby(dataio.RUN, sort=False)[dataio.SPEED].first().to_numpy(float)
    chans = {c: df[c].to_numpy(float) for c in model.channel_inputs if c in df.columns}
    chans.update(channels or {})
    return model.free_run(df[dataio.TIME], df[dataio.POSITION], df[dataio.VOLTAGE], df[dataio.LOAD],
                          df[dataio.DIRECTION], first, df[dataio.RUN].to_numpy(),
                          temperature=df[dataio.TEMPERATURE] if dataio.TEMPERATURE in df.columns else None,
                          frequency=df[dataio.FREQUENCY] if dataio.FREQUENCY in df.columns else None,
                          channels=chans)


def run_feed(model: ExtendedPredictor, df: pd.DataFrame, column: str) -> float:
    """The largest change of ``model``'s free run on ``df`` when the logged channel ``column`` is fed as its samples
    instead of each run's mean, as a share of the free run's rms (the other channels as logged)."""
    v_logged = frame_free_run(model, df)
    means = df.groupby(dataio.RUN, sort=False)[column].transform("mean").to_numpy(float)
    v_means = frame_free_run(model, df, {column: means})
    rms = float(np.sqrt(np.mean(v_logged ** 2)))
    return float(np.max(np.abs(v_logged - v_means)) / rms) if rms > 0 else float("inf")


def _spread_columns(spec) -> list[str]:
    """The logged channels (no input of :data:`~l1b2.predictor.effects.channels.INPUT_COLUMNS`) whose run-level
    signal a spec reads beyond the run-level contract's tolerance
    (:func:`~l1b2.predictor.effects.channels.run_spread_excess`)."""
    return [col for col, spread, _ in fx_channels.run_spread_excess(spec)
            if np.isfinite(spread) and col not in fx_channels.INPUT_COLUMNS and col != fx_channels.SESSION_TIME]


def with_run_feeds(recs: list, build, df: pd.DataFrame | None) -> list:
    """``recs`` (:class:`IdentifiedEffect`) with ``run_feed`` in the spec of every run-level effect of a logged
    setting that TRAIN's runs did not hold constant (:func:`run_feed` of the model ``build(recs)`` on TRAIN ``df``,
    the largest over its columns). Unchanged without ``df`` or a column of those, and when another effect cannot be
    exported whatever its feed (an effect of the session clock): the model is then not exported, and its free run
    cannot be evaluated without the signals such an effect reads."""
    spread = {i: cols for i, r in enumerate(recs) if (cols := _spread_columns(r.spec))}
    if (not spread or df is None or not all(c in df.columns for cols in spread.values() for c in cols)
            or any(fx_channels.export_problem(r.spec) for i, r in enumerate(recs) if i not in spread)):
        return recs
    model = build(recs)
    share = {c: run_feed(model, df, c) for c in sorted({c for cols in spread.values() for c in cols})}
    return [replace(r, spec={**r.spec, "run_feed": max(share[c] for c in spread[i])}) if i in spread else r
            for i, r in enumerate(recs)]


def calibrated_model(base, ext, effects, output_filter, source: dict, groups=None, speed_gain=None, df=None):
    """``(ExtendedPredictor or None, note)``: the final model in the serialisable form ``Predictor.fmu`` carries.

    Each effect's standard errors are the report's (:func:`l1b2.closeloop.intervals.reported_uncertainty`,
    ``groups`` its runs' level labels), and so is its parameters' covariance
    (:func:`l1b2.closeloop.intervals.reported_covariance`). ``df``: TRAIN, on which a run-level effect of a logged
    setting that TRAIN's runs did not hold constant gets its ``run_feed`` (module docstring); without it such an
    effect is not exported.

    When nothing was added it is the baseline (no effects); None when an
    effect has no spec (a user's candidate with a Python feature function
    only) or ``Predictor.fmu`` cannot evaluate it as identified
    (:func:`l1b2.predictor.effects.channels.export_problem`), the note says which.
    An effect of a family that is a fact of the recorded session, centred on TRAIN's runs (``session_average``:
    :class:`l1b2.predictor.effects.blocks.SessionBlocks`), is left out, and the note names it: its columns average
    to zero over TRAIN's runs, so the model without it predicts the session's average.
    """
    base_setup = PredictorSetup(base.params_, base.m_s_, base.T_s_, base.result_.frequency_response)
    if ext is None:
        return (ExtendedPredictor(base_setup, base_setup, (), None, dict(source)),
                f"nothing was added: the baseline predictor ({base.params_.drive_law}) is the model")
    missing = [c.label for c in effects.candidates if not c.spec]
    if missing:
        return None, f"effects without a serialisable spec (custom candidates): {', '.join(missing)}"
    session = session_facts(effects)
    left = (f"; left out: {', '.join(session)} (a fact of the recorded session, centred on TRAIN's runs: the model "
            "predicts the session's average)") if session else ""
    recs = [IdentifiedEffect(c.family, c.label, dict(c.spec), tuple(c.names), tuple(c.units),
                             tuple(float(p) for p in phi),
                             tuple(reported_uncertainty(ext, n, groups)["stderr"] for n in c.names),
                             c.description, tuple(c.regressors), c.structural,
                             reported_covariance(ext, c.names, groups))
            for c, phi in zip(effects.candidates, effects.phi) if c.label not in session]
    filt = None if output_filter is None else output_filter.params()
    ext_setup = PredictorSetup(ext.params_, ext.m_s_, ext.T_s_, ext.result_.frequency_response)

    def build(effects_):
        return ExtendedPredictor(base_setup, ext_setup, tuple(effects_), filt, dict(source),
                                 None if speed_gain is None else speed_gain.to_dict())
    recs = with_run_feeds(recs, build, df)
    logged = [f"{r.label} ({why})" for r in recs if (why := fx_channels.export_problem(r.spec))]
    if logged:
        return None, f"effects Predictor.fmu cannot evaluate as identified: {', '.join(logged)}" + left
    return build(recs), "the final extended model" + left
