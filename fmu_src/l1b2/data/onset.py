"""The rest at each run's start before its motion's onset: a fact of the recording, cut on reading.

A rig's DAQ often starts recording before the motor is driven (a relay that closes after the trigger, a driver's
soft start, a program that writes the previous run's file first). The stator's envelope builds up within a
fraction of a millisecond, and a slider with the drive on moves at once unless static friction holds it; then it
stays at rest for as long as the drive inputs stay as they are (the predictor's free run from rest is
time-invariant under constant inputs: it either moves from the first sample or never). A run that rests at its
start position and then moves, with the drive inputs of its motion logged during the rest, therefore holds samples
the motor did not produce: the drive was not on yet. The model cannot predict them, and a free run started at the
run's first sample drives a slider that is still at rest.

The rule (:func:`onset_index`, per run): a sample is **at rest** when its position is within ``band_s`` of the
run's first position and its speed within ``band_v`` of zero. The leading samples at rest end at the first sample
that is not; the **onset** is the last sample at rest before it (the run keeps that sample and the rest, so its
free run starts from rest at the drive's start). The bands are the columns' noise (:func:`rest_bands`):

    ``band_s = z sqrt(2) sigma_s + q`` (the difference of two readings, plus one encoder count ``q``),
    ``band_v = z sigma_v + q / dt`` (plus the speed of one count per step, which the position cannot resolve),

``sigma_s``, ``sigma_v`` the robust standard deviations of the file's within-run second differences of position
(at the samples whose speed is within ``band_v``) and of speed, over ``sqrt(6)`` (white noise; a smooth motion's
second differences over one step are far smaller), and
``z`` the two-sided normal quantile at ``alpha / (4 N)`` (``N`` samples, two comparisons each): a file's samples at
rest are all taken as at rest with probability at least ``1 - alpha``.

A run is **cut** (:func:`from_onset`) only when its onset lies past its first sample, it moves after the onset and
the drive inputs of the rest (:data:`DRIVE_INPUTS`: the median of each over the samples at rest) lie within their
range over the motion: a run that never leaves the bands (a stalled run) is kept whole, and a rest under other
logged inputs (a voltage logged at zero or ramping up) is the model's to predict and is kept too.
"""

from __future__ import annotations

from statistics import NormalDist

import numpy as np
import pandas as pd

from .columns import DIRECTION, FREQUENCY, LOAD, POSITION, RUN, SPEED, TIME, VOLTAGE

__all__ = ["ALPHA", "DRIVE_INPUTS", "REGRESSOR", "noise_sd", "rest_bands", "onset_index", "from_onset",
           "onset_lines"]

#: the family-wise chance that some sample of a file at rest is taken as moving
ALPHA = 0.01
#: the logged drive inputs that must be the same during the rest as during the motion for the rest to be cut
DRIVE_INPUTS: tuple[str, ...] = (VOLTAGE, DIRECTION, LOAD, FREQUENCY)
#: the name of the cut in the close loop's ``diagnosis.traced_to``
REGRESSOR = "rest_before_onset"


def _bounds(run) -> list[tuple[int, int]]:
    run = np.asarray(run)
    if not run.size:
        return []
    change = np.flatnonzero(run[1:] != run[:-1]) + 1
    return list(zip(np.r_[0, change].tolist(), np.r_[change, run.size].tolist()))


def noise_sd(x, run, where=None) -> float:
    """The robust standard deviation of white noise on ``x`` (any unit): 1.4826 x the median absolute deviation of
    the within-run second differences ``x[k+1] - 2 x[k] + x[k-1]``, over ``sqrt(6)``, at the samples ``k`` where
    ``where`` holds (default: all); 0 when there are none."""
    x = np.asarray(x, float)
    ok = np.ones(x.size, bool) if where is None else np.asarray(where, bool)
    d2 = np.concatenate([np.diff(x[a:b], 2)[ok[a + 1:b - 1]] for a, b in _bounds(run) if b - a >= 3]
                        or [np.zeros(0)])
    d2 = d2[np.isfinite(d2)]
    if not d2.size:
        return 0.0
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def rest_bands(df: pd.DataFrame, encoder_resolution_m: float, alpha: float = ALPHA) -> dict:
    """The bands of a sample at rest in ``df`` (module docstring): ``{"z", "sigma_position_m", "sigma_speed_m_s",
    "band_position_m", "band_speed_m_s"}``. The position's noise is taken at the samples whose speed is within
    the speed's band: at speed, a position's second differences also hold the motion's (a sensor's cyclic error
    along the stroke), which is not the reading's noise at rest."""
    run = df[RUN].to_numpy()
    n = max(len(df), 1)
    z = -NormalDist().inv_cdf(alpha / (4.0 * n))
    v = df[SPEED].to_numpy(float)
    v_sd = noise_sd(v, run)
    t = df[TIME].to_numpy(float)
    steps = np.concatenate([np.diff(t[a:b]) for a, b in _bounds(run) if b - a >= 2] or [np.zeros(0)])
    dt = float(np.median(steps)) if steps.size else 0.0
    q = float(encoder_resolution_m)
    band_v = z * v_sd + (q / dt if dt > 0 else 0.0)
    s_sd = noise_sd(df[POSITION].to_numpy(float), run)
    return {"z": z, "sigma_position_m": s_sd, "sigma_speed_m_s": v_sd,
            "band_position_m": float(z * np.sqrt(2.0) * s_sd + q), "band_speed_m_s": float(band_v)}


def onset_index(s_m, v_m_s, band_s_m: float, band_v_m_s: float) -> int | None:
    """The onset of one run (positions ``s_m`` [m], speeds ``v_m_s`` [m/s]): the last of its leading samples at
    rest (position within ``band_s_m`` of the first, speed within ``band_v_m_s`` of zero); 0 when the first sample
    is not at rest or the second is not; ``None`` when every sample is at rest (the slider never moves)."""
    s, v = np.asarray(s_m, float), np.asarray(v_m_s, float)
    if not s.size:
        return None
    rest = (np.abs(s - s[0]) <= band_s_m) & (np.abs(v) <= band_v_m_s)
    moving = np.flatnonzero(~rest)
    if not moving.size:
        return None
    return max(int(moving[0]) - 1, 0)


def _inputs_hold(df: pd.DataFrame, a: int, k: int, b: int) -> bool:
    """Whether each drive input's median over the rest ``a..a+k`` lies within its range over the motion
    ``a+k+1..b``."""
    for c in DRIVE_INPUTS:
        if c not in df.columns:
            continue
        x = df[c].to_numpy(float)
        rest, motion = x[a:a + k + 1], x[a + k + 1:b]
        if not motion.size or not (motion.min() <= np.median(rest) <= motion.max()):
            return False
    return True


def from_onset(df: pd.DataFrame, encoder_resolution_m: float, *, cut: bool = True,
               alpha: float = ALPHA) -> tuple[pd.DataFrame, dict]:
    """``df`` without each run's samples before its onset (module docstring), and the record of it.

    The kept rows keep their index (a file's row is its index + 1). The record: ``runs`` (runs cut), ``of_runs``,
    ``samples`` (samples dropped), ``median_delay_s`` and ``max_delay_s`` of the cut runs' onsets after their
    first samples (None when none), ``first_row`` (1-based data row of the first cut run's first sample),
    ``still_runs`` (runs that never leave the bands, kept whole), ``inputs_differ`` (runs at rest under other
    drive inputs, kept whole), ``cut`` (whether the samples were dropped; with ``cut=False`` only counted) and the
    bands (:func:`rest_bands`).
    """
    bands = rest_bands(df, encoder_resolution_m, alpha)
    s = df[POSITION].to_numpy(float)
    v = df[SPEED].to_numpy(float)
    t = df[TIME].to_numpy(float)
    keep = np.ones(len(df), bool)
    delays, first, still, differ, n_runs = [], None, 0, 0, 0
    for a, b in _bounds(df[RUN].to_numpy()):
        n_runs += 1
        k = onset_index(s[a:b], v[a:b], bands["band_position_m"], bands["band_speed_m_s"])
        if k is None:
            still += 1
            continue
        if k == 0:
            continue
        if not _inputs_hold(df, a, k, b):
            differ += 1
            continue
        keep[a:a + k] = False
        delays.append(float(t[a + k] - t[a]))
        first = a + 1 if first is None else first
    rec = {"runs": len(delays), "of_runs": n_runs, "samples": int((~keep).sum()),
           "median_delay_s": float(np.median(delays)) if delays else None,
           "max_delay_s": float(np.max(delays)) if delays else None, "first_row": first,
           "still_runs": still, "inputs_differ": differ, "cut": bool(cut), **bands}
    return (df.loc[keep] if cut and not keep.all() else df), rec


def onset_lines(records: dict) -> list[str]:
    """One line per file part of a report's ``checks["rest_before_onset"]`` (``{"train": record or None, "test":
    ...}``, records of :func:`from_onset`) with runs at rest before their onset."""
    out = []
    for part, r in (records or {}).items():
        if r and r.get("runs"):
            done = ("the free run and the identification start at each run's onset" if r["cut"]
                    else "kept (not cut)")
            out.append(f"{part.upper()}: {r['runs']} of {r['of_runs']} runs rest at their start position before "
                       f"they move (first at row {r['first_row']}; {r['samples']} samples, onset after "
                       f"{r['median_delay_s'] * 1e3:.3g} ms median, {r['max_delay_s'] * 1e3:.3g} ms at most; "
                       f"position within {r['band_position_m'] * 1e9:.3g} nm, speed within "
                       f"{r['band_speed_m_s'] * 1e3:.3g} mm/s) under the drive inputs of their motion: the "
                       f"recording began before the drive; {done}")
    return out
