"""The measurement chain: is the speed column the position's derivative, or filtered, delayed or scaled?

A rig's ``speed_m_s`` need not be a clean central difference of
``position_m``: the DAQ may low-pass it, delay it or scale it. The physics
model cannot absorb that (it predicts the slider's speed), so the effect is
found and modelled apart from the physics, from position and speed alone:

* per run, ``u = d position / d t`` (central differences, as the data format
  derives the speed when it is absent);
* the output filter ``y(k) = a y(k-1) + b0 u(k) + b1 u(k-1)`` (a first-order
  lag with a fractional delay and a scale; identity: a = b1 = 0, b0 = 1) is
  fitted by least squares on the measured speed, K-fold over runs;
* it is accepted when it lowers the held-out sum of squares of
  ``speed - filter(u)`` against the identity by at least ``min_gain`` in most
  runs *and* the speed column's mismatch with the derivative is above the
  quantisation level (``min_rel_rms`` of the speed's rms).

When the filter is accepted, the close-the-loop estimator identifies the
physics on the position's derivative (:func:`with_position_speed`) and
applies the filter to its predictions (:meth:`OutputFilter.apply`), before
it looks for missing physical effects (:class:`l1b2.closeloop.loop.ChainModel`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from ..data import measurements as dataio
from ..predictor.effects import apply_output_filter
from .residuals import run_folds, wilcoxon_greater


@dataclass(frozen=True)
class OutputFilter:
    """``y(k) = a y(k-1) + b0 u(k) + b1 u(k-1)`` per run, ``y(0) = (b0 + b1) u(0) / (1 - a)`` (steady start)."""

    a: float = 0.0
    b0: float = 1.0
    b1: float = 0.0

    def apply(self, df: pd.DataFrame, u) -> np.ndarray:
        """The filtered signal of ``u`` (per sample), run by run (:func:`l1b2.predictor.effects.apply_output_filter`)."""
        starts = sorted(sl.start for _, sl in dataio.run_slices(df[dataio.RUN]))
        return apply_output_filter({"a": self.a, "b0": self.b0, "b1": self.b1}, u, starts)

    def frame(self, df: pd.DataFrame) -> pd.DataFrame:
        """The frame the physics behind the filter is fitted on and predicts along (:func:`with_position_speed`)."""
        return with_position_speed(df)

    def to_dict(self) -> dict:
        dc = (self.b0 + self.b1) / (1.0 - self.a) if abs(1.0 - self.a) > 1e-9 else float("nan")
        return {"a": self.a, "b0": self.b0, "b1": self.b1, "dc_gain": dc,
                "time_constant_samples": (-1.0 / np.log(self.a)) if 0 < self.a < 1 else 0.0}


def position_derivative(df: pd.DataFrame) -> np.ndarray:
    """``d position / d t`` per run (central differences) [m/s]."""
    pos = df[dataio.POSITION].to_numpy(float)
    t = df[dataio.TIME].to_numpy(float)
    out = np.zeros(len(df))
    for _, sl in dataio.run_slices(df[dataio.RUN]):
        if sl.stop - sl.start > 1:
            out[sl] = np.gradient(pos[sl], t[sl])
    return out


def with_position_speed(df: pd.DataFrame) -> pd.DataFrame:
    """A copy of ``df`` whose speed column is the position's derivative (:func:`position_derivative`) [m/s].

    The slider's speed as the data format derives it when the column is
    absent: what the physics predicts when the recorded column went through a
    filter of the measurement chain.
    """
    out = df.copy()
    out[dataio.SPEED] = position_derivative(df)
    return out


def _design(df: pd.DataFrame, u: np.ndarray, v: np.ndarray):
    """Rows k >= 1 of each run: ``[v(k-1), u(k), u(k-1)]`` and target ``v(k)``; their run ids."""
    keep = np.ones(len(df), bool)
    for _, sl in dataio.run_slices(df[dataio.RUN]):
        keep[sl.start] = False
    prev_v = np.roll(v, 1)
    prev_u = np.roll(u, 1)
    X = np.column_stack([prev_v, u, prev_u])[keep]
    return X, v[keep], df[dataio.RUN].to_numpy()[keep], keep


def speed_channel(df: pd.DataFrame, mask: np.ndarray, *, k: int = 5, seed: int = 0, min_gain: float = 0.5,
                  min_rel_rms: float = 0.01) -> dict:
    """Compare the speed column with the position's derivative; the accepted output filter (or None).

    Returns a dict: ``rel_rms_mismatch`` (rms of speed - derivative over the
    speed's rms), ``cv_gain`` (held-out share of the identity's mismatch the
    filter removes, one-step on the measured speed), ``p_value`` (runs),
    ``filter`` (:class:`OutputFilter` parameters fitted on all runs) and
    ``accepted``.
    """
    if dataio.SPEED not in df.columns:
        return {"accepted": False, "reason": "no speed column"}
    u = position_derivative(df)
    v = df[dataio.SPEED].to_numpy(float)
    X, y, runs, keep = _design(df, u, v)
    m = np.asarray(mask, bool)[keep]
    X, y, runs = X[m], y[m], runs[m]
    if len(y) < 10:
        return {"accepted": False, "reason": "too few samples"}
    ident = X[:, 1]
    rel = float(np.sqrt(np.mean((v[mask] - u[mask]) ** 2)) / max(np.sqrt(np.mean(v[mask] ** 2)), 1e-300))
    folds = run_folds(runs, k, seed)
    ss0, ss1 = {}, {}
    for fold in folds:
        te = np.isin(runs, fold)
        coef = np.linalg.lstsq(X[~te], y[~te], rcond=None)[0]
        e1 = y[te] - X[te] @ coef
        e0 = y[te] - ident[te]
        for run in fold:
            sel = runs[te] == run
            ss0[run] = float(np.sum(e0[sel] ** 2))
            ss1[run] = float(np.sum(e1[sel] ** 2))
    s0 = np.array(list(ss0.values()))
    s1 = np.array([ss1[r] for r in ss0])
    gain = float(1 - s1.sum() / s0.sum()) if s0.sum() > 0 else 0.0
    p = wilcoxon_greater((s0 - s1) / max(s0.mean(), 1e-300)) if s0.sum() > 0 else 1.0
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    filt = OutputFilter(float(coef[0]), float(coef[1]), float(coef[2]))
    ok = bool(rel >= min_rel_rms and gain >= min_gain and p < 0.01 and abs(filt.a) < 0.999)
    return {"accepted": ok, "rel_rms_mismatch": rel, "cv_gain": gain, "p_value": p,
            "runs_improved": float(np.mean(s1 < s0)) if len(s0) else 0.0, "filter": filt}


#: a run whose recorded travel is within this share of the median travel is a full traverse (stop to stop)
FULL_TRAVERSE_TOL = 0.05


def stroke_gain(df: pd.DataFrame, channels=(), *, alpha: float = 0.01) -> dict:
    """The position sensor's gain from run to run, read from each run's recorded travel between the end stops.

    Every run of the protocol traverses the stroke from one end stop to the other, and the stops do not move: a
    full traverse records the same travel in every run, up to the encoder's quantisation, unless the sensor's gain
    (its scale) changes. A run whose travel (``max - min`` of the position) is within :data:`FULL_TRAVERSE_TOL` of
    the median travel is a full traverse (a run that stalled short of the far stop is not), and its relative gain
    is ``g_r = travel_r / median - 1``. Each channel of ``channels`` (column names; its run means) is tested as the
    gain's cause by the least-squares slope of ``g_r`` on it (t-test, two-sided), significant below ``alpha`` /
    number of channels tested (Bonferroni). Such a gain scales the recorded position and every speed derived from
    it: a measurement effect, not a force. Reported; no model of the loop carries it.

    Returns ``{"full_runs", "gain_sd_rel", "gain_range_rel", "channel", "slope_per_unit", "r", "p_value",
    "significant"}`` (the strongest channel: smallest p-value; ``channel`` None when none was testable).
    """
    g = df.groupby(dataio.RUN, sort=False)
    travel = (g[dataio.POSITION].max() - g[dataio.POSITION].min()).to_numpy(float)
    full = np.abs(travel / np.median(travel) - 1.0) <= FULL_TRAVERSE_TOL if len(travel) else np.zeros(0, bool)
    gain = travel[full] / np.median(travel[full]) - 1.0 if full.any() else np.zeros(0)
    out = {"full_runs": int(full.sum()), "gain_sd_rel": float(np.std(gain)) if len(gain) else 0.0,
           "gain_range_rel": float(np.ptp(gain)) if len(gain) else 0.0, "channel": None, "slope_per_unit": None,
           "r": None, "p_value": 1.0, "significant": False}
    tested = []
    for name in channels:
        if name not in df.columns:
            continue
        c = g[name].mean().to_numpy(float)[full]
        if len(gain) < 4 or not (np.all(np.isfinite(c)) and np.std(c) > 0 and np.std(gain) > 0):
            continue
        fit = stats.linregress(c, gain)
        tested.append((float(fit.pvalue), name, float(fit.slope), float(fit.rvalue)))
    if tested:
        p, name, slope, r = min(tested)
        out.update(channel=name, slope_per_unit=slope, r=r, p_value=p, significant=bool(p < alpha / len(tested)))
    return out
