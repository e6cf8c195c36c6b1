"""How far TEST reaches beyond TRAIN in the signals the added effects read.

An added effect that reads a logged channel (or a protocol signal) is fitted on TRAIN's range of it; on TEST it
extrapolates (a form linear in the signal) or is held flat (the quadratic, odd and peak shapes), and a categorical
run-level setting has no effect of its own for a value TRAIN never had. The report states both
(``diagnosis.channel_ranges``, ``diagnosis.unseen_levels``) so that a TEST error can be read against them.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..data.coverage import values_outside
from ..predictor import effects as fx


def unseen_test_levels(added, df: pd.DataFrame | None) -> dict:
    """``{label: {"channel", "values", "runs"}}`` of every added categorical run-level effect whose channel takes
    a value in ``df`` (TEST) that TRAIN never had: those runs get TRAIN's average over runs (0 in the level
    columns), so their prediction cannot carry that value's own effect (``diagnosis.unseen_levels``)."""
    out: dict = {}
    fam = fx.family("run_level_category")
    for c in added if df is not None else ():
        spec = c.spec or {}
        col = spec.get("channel")
        if spec.get("kind") != fam.kind or col not in df.columns:
            continue
        unseen = fam.unseen(spec, df.groupby(dataio.RUN, sort=False)[col].first().to_numpy(float))
        if unseen:
            out[c.label] = {"channel": col, **unseen}
    return out


def _signal_values(df: pd.DataFrame, col: str, level: str, transform: str, centre: float = 0.0,
                   slope: float = 0.0) -> np.ndarray:
    """An effect's signal per sample of ``df``: the channel's value (``sample``), or the run-level signal the effect
    reads (``run``: :func:`l1b2.predictor.effects.channels.run_signal` of the run's mean, ``transform``,
    ``centre`` and ``slope``)."""
    if level == "sample":
        return df[col].to_numpy(float)
    x = {fx.channels.signal_key(col, "run"): df.groupby(dataio.RUN, sort=False)[col].transform("mean"),
         "d": df[dataio.DIRECTION]}
    return fx.channels.run_signal(x, col, transform, centre, slope)


def channel_ranges(added, dtr: pd.DataFrame, dte: pd.DataFrame | None) -> list:
    """For every logged channel (or protocol signal) an added effect reads, how much of TEST lies outside TRAIN's
    range of it (``diagnosis.channel_ranges``).

    ``added``: the added candidates (their specs); the ``channel`` family's (its level, ``sample`` or ``run``) and
    the ``run_level`` family's (a categorical setting's TEST values are :func:`unseen_test_levels`' check). One record
    per signal, in the order first read: ``channel``, ``level``, ``transform``, ``signal`` (the report's name),
    ``effects`` (label -> ``extrapolates`` for a form linear in the signal, ``clipped`` for the quadratic, odd and
    peak shapes, flat beyond TRAIN's range) and :func:`l1b2.data.coverage.values_outside` of the signal (TRAIN's and
    TEST's signal per sample). Empty without TEST.
    """
    out: dict = {}
    for c in added if dte is not None else ():
        spec = c.spec or {}
        kind, col, tr = spec.get("kind"), spec.get("channel"), spec.get("transform", "none")
        if kind not in ("channel", "run_level"):
            continue
        if col not in dtr.columns or col not in dte.columns:
            continue
        level, at = str(spec.get("level", "run")), (float(spec.get("centre", 0.0)), float(spec.get("slope", 0.0)))
        key = (col, level, tr)
        if key not in out:
            vals = values_outside(_signal_values(dtr, col, level, tr, *at),
                                  _signal_values(dte, col, level, tr, *at), dte[dataio.RUN].to_numpy())
            name = fx.channels.signal_label(col, tr) + (" (run mean)" if level == "run" else "")
            out[key] = {"channel": col, "level": level, "transform": tr, "signal": name, "effects": {}, **vals}
        clipped = kind == "channel" and spec.get("shape", "linear") != "linear"
        out[key]["effects"][c.label] = "clipped" if clipped else "extrapolates"
    return list(out.values())
