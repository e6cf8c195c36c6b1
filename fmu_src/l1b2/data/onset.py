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

``sigma_s``, ``sigma_v`` the robust standard deviations of the noise of the position and speed columns from their
within-run fourth differences over even time steps (:func:`noise_sd`: a smooth motion adds nothing to them, white
noise ``sqrt(70)`` times its standard deviation), and
``z`` the two-sided normal quantile at ``alpha / (4 N)`` (``N`` samples, two comparisons each): a file's samples at
rest are all taken as at rest with probability at least ``1 - alpha``.

A run is **cut** (:func:`from_onset`) only when its onset lies :data:`MIN_REST_STEPS` or more samples and
:data:`MIN_REST_S` or more seconds past its first (a rest of one step is the sample clock's own uncertainty of the
start; a slow start stays within the bands for about a millisecond at any sample rate), it moves after the onset and
the drive inputs of the rest (:data:`DRIVE_INPUTS`: the median of each over the samples at rest) lie within their
range over the motion: a run that never leaves the bands (a stalled run) is kept whole, and a rest under other
logged inputs (a voltage logged at zero or ramping up) is the model's to predict and is kept too.
"""

from __future__ import annotations

from statistics import NormalDist

import numpy as np
import pandas as pd

from .columns import DIRECTION, FREQUENCY, LOAD, POSITION, RUN, SPEED, TIME, VOLTAGE, file_row, run_slices
from .plausibility import UNEVEN_STEP_SHARE

__all__ = ["ALPHA", "DRIVE_INPUTS", "MIN_REST_STEPS", "MIN_REST_S", "REGRESSOR", "noise_sd", "rest_bands",
           "onset_index", "from_onset", "subset_record", "onset_lines"]

#: the family-wise chance that some sample of a file at rest is taken as moving
ALPHA = 0.01
#: the logged drive inputs that must be the same during the rest as during the motion for the rest to be cut
DRIVE_INPUTS: tuple[str, ...] = (VOLTAGE, DIRECTION, LOAD, FREQUENCY)
#: the fewest steps a rest must last to be cut: a drive that starts within a run's first step, at a phase the
#: sample clock does not see, can leave the next sample within the bands
MIN_REST_STEPS = 2
#: the shortest time [s] a rest must last to be cut, whatever the sample rate: a driven slider that starts slowly
#: (low V0 against a heavy load, under 1 m/s^2) stays within the position band for up to about a millisecond, which
#: is several steps of a fast DAQ; at the 1 kHz the rule was first measured on, 2 ms are its 2 steps
MIN_REST_S = 2e-3
#: the name of the cut in the close loop's ``diagnosis.traced_to``
REGRESSOR = "rest_before_onset"


def noise_sd(x, t_s, run) -> float:
    """The robust standard deviation of white noise on ``x`` (any unit; ``t_s`` the times [s], ``run`` the run per
    sample): 1.4826 x the median absolute deviation of the within-run fourth differences, over ``sqrt(70)`` (the
    sum of the squares of the difference's weights 1, -4, 6, -4, 1), over the windows of five samples whose four
    time steps are even (each within :data:`~l1b2.data.plausibility.UNEVEN_STEP_SHARE` of its run's median step);
    0 when there are none. On an even clock a motion whose fourth derivative is small over four steps (a cubic in
    time: a start at constant jerk, a traverse at constant acceleration) adds nothing."""
    x, t = np.asarray(x, float), np.asarray(t_s, float)
    parts = []
    for _, sl in run_slices(run):
        a, b = sl.start, sl.stop
        if b - a < 5:
            continue
        h = np.diff(t[a:b])
        even = np.abs(h - np.median(h)) <= UNEVEN_STEP_SHARE * np.median(h)
        ok = np.all(np.lib.stride_tricks.sliding_window_view(even, 4), axis=1)
        parts.append(np.diff(x[a:b], 4)[ok])
    d4 = np.concatenate(parts) if parts else np.zeros(0)
    d4 = d4[np.isfinite(d4)]
    if not d4.size:
        return 0.0
    return float(1.4826 * np.median(np.abs(d4 - np.median(d4))) / np.sqrt(70.0))


def rest_bands(df: pd.DataFrame, encoder_resolution_m: float, alpha: float = ALPHA) -> dict:
    """The bands of a sample at rest in ``df`` (module docstring): ``{"z", "sigma_position_m", "sigma_speed_m_s",
    "band_position_m", "band_speed_m_s"}``."""
    run = df[RUN].to_numpy()
    n = max(len(df), 1)
    z = -NormalDist().inv_cdf(alpha / (4.0 * n))
    t = df[TIME].to_numpy(float)
    s_sd = noise_sd(df[POSITION].to_numpy(float), t, run)
    v_sd = noise_sd(df[SPEED].to_numpy(float), t, run)
    steps = np.concatenate([np.diff(t[sl]) for _, sl in run_slices(run) if sl.stop - sl.start >= 2]
                           or [np.zeros(0)])
    dt = float(np.median(steps)) if steps.size else 0.0
    q = float(encoder_resolution_m)
    return {"z": z, "sigma_position_m": s_sd, "sigma_speed_m_s": v_sd,
            "band_position_m": float(z * np.sqrt(2.0) * s_sd + q),
            "band_speed_m_s": float(z * v_sd + (q / dt if dt > 0 else 0.0))}


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
    first samples (None when none), ``first_row`` (1-based data row of the first cut run's first sample, from
    ``df``'s index), ``still_runs`` (runs that never leave the bands, kept whole), ``inputs_differ`` (runs at rest
    under other drive inputs, kept whole), ``cut`` (whether the samples were dropped; with ``cut=False`` only
    counted), the bands (:func:`rest_bands`) and ``per_run``: ``[run, samples dropped, delay [s], first row]`` of
    each cut run.
    """
    bands = rest_bands(df, encoder_resolution_m, alpha)
    s = df[POSITION].to_numpy(float)
    v = df[SPEED].to_numpy(float)
    t = df[TIME].to_numpy(float)
    keep = np.ones(len(df), bool)
    per_run, still, differ, n_runs = [], 0, 0, 0
    run = df[RUN].to_numpy()
    for rid, sl in run_slices(run):
        a, b = sl.start, sl.stop
        n_runs += 1
        k = onset_index(s[a:b], v[a:b], bands["band_position_m"], bands["band_speed_m_s"])
        if k is None:
            still += 1
            continue
        if k < MIN_REST_STEPS or t[a + k] - t[a] < MIN_REST_S * (1 - 1e-6):
            continue
        if not _inputs_hold(df, a, k, b):
            differ += 1
            continue
        keep[a:a + k] = False
        per_run.append([rid, int(k), float(t[a + k] - t[a]), file_row(df, a)])
    return (df.loc[keep] if cut and not keep.all() else df), _record(per_run, n_runs, still, differ, cut, bands)


def _record(per_run: list, n_runs: int, still: int, differ: int, cut: bool, bands: dict) -> dict:
    delays = [d for _, _, d, _ in per_run]
    return {"runs": len(per_run), "of_runs": n_runs, "samples": int(sum(k for _, k, _, _ in per_run)),
            "median_delay_s": float(np.median(delays)) if delays else None,
            "max_delay_s": float(np.max(delays)) if delays else None,
            "first_row": per_run[0][3] if per_run else None, "still_runs": still, "inputs_differ": differ,
            "cut": bool(cut), **bands, "per_run": per_run}


def subset_record(record: dict | None, runs) -> dict | None:
    """:func:`from_onset`'s ``record`` of a file restricted to the runs ``runs`` (a split of the file's runs); the
    kept-whole counts are the file's."""
    if record is None:
        return None
    keep = set(runs)
    per_run = [r for r in record["per_run"] if r[0] in keep]
    bands = {k: record[k] for k in ("z", "sigma_position_m", "sigma_speed_m_s", "band_position_m",
                                    "band_speed_m_s")}
    return _record(per_run, len(keep), record["still_runs"], record["inputs_differ"], record["cut"], bands)


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
