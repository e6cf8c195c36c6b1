#!/usr/bin/env python
"""Probes of the eighth blind audit (decision 0108): the close loop on a changed copy of a case's data.

Modes, each on a copy of ``<cache>/<KIND>_<SEED>`` (``bench/blind_effects_eighth.py`` makes it first):

* ``logp`` -- ``chamber_pressure_hPa`` replaced by its natural logarithm ``ln_chamber_pressure`` (ln of the
  pressure in hPa): does the column's scale (1-1000 hPa, log-uniform) stand between the loop and the pressure?
* ``law`` -- ``chamber_pressure_hPa`` replaced by the law's own variable, ``b2_damping_factor`` (each run's B2
  damping over the motor's, from ``rig_truth.json``): the best any shape of the channel could give; is the effect
  large enough to be found at all?
* ``onset`` -- each run's samples before its motion's onset dropped (the onset: the last sample whose position is
  within two encoder counts, 100 nm, of the run's first): the loop on runs that begin with the drive.
* ``undo`` -- the encoder's cyclic error taken out of the position with the drawn parameters
  (``position - e(position)``) and the speed column's derivative of the position moved onto the corrected one
  (its noise kept): the loop on the same motion with a perfect encoder.
* ``fit`` -- as ``undo``, with the cyclic error estimated from TRAIN alone (:func:`fit_cyclic_error`: the pitch
  scanned over 0.5-5 mm, the two harmonics' four coefficients by least squares on the speed's ripple), then taken
  out of TRAIN and TEST: a measurement-chain stage of the position sensor, as the loop could fit it.

Usage: python bench/blind_effects_eighth_probe.py KIND SEED MODE [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``), then the evidence of the probed column, one JSON line each.
"""
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.signal import savgol_filter

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_eighth as eighth  # noqa: E402

COLUMN = {"logp": "ln_chamber_pressure", "law": "b2_damping_factor"}
ENCODER_COUNT_M = 5e-8


def onset_trimmed(df: pd.DataFrame) -> pd.DataFrame:
    """The frame without each run's samples before its onset (the last sample within two encoder counts of the
    run's first position; the run keeps that sample and the rest)."""
    keep = []
    for _, idx in df.groupby("run", sort=False).groups.items():
        s = df.loc[idx, "position_m"].to_numpy(float)
        moved = np.flatnonzero(np.abs(s - s[0]) > 2 * ENCODER_COUNT_M)
        first = max(int(moved[0]) - 1, 0) if moved.size else 0
        keep.append(np.asarray(idx)[first:])
    return df.loc[np.concatenate(keep)].reset_index(drop=True)


def encoder_undone(df: pd.DataFrame, p: dict) -> pd.DataFrame:
    """The frame with the cyclic error ``e`` of the drawn parameters ``p`` taken out of the position, and the speed's
    derivative of the position moved onto the corrected one (the speed minus ``gradient(position, time)`` plus
    ``gradient(position - e(position), time)``, run by run)."""
    out = df.copy()
    for _, idx in out.groupby("run", sort=False).groups.items():
        t = out.loc[idx, "time_s"].to_numpy(float)
        s = out.loc[idx, "position_m"].to_numpy(float)
        s_c = s - eighth.cyclic_error_m(s, p["P_m"], p["A1_m"], p["A2_m"], p["phi1"], p["phi2"])
        v = out.loc[idx, "speed_m_s"].to_numpy(float)
        out.loc[idx, "speed_m_s"] = np.round(v - np.gradient(s, t) + np.gradient(s_c, t), 9)
        out.loc[idx, "position_m"] = np.round(s_c, 12)
    return out


def ripple_design(df: pd.DataFrame, P_m: float, window: int = 61, skip_s: float = 0.06):
    """``(X, y)`` of the speed's ripple on TRAIN: per run, ``y`` the speed minus its Savitzky-Golay smooth
    (``window`` samples, order 2) and ``X`` the smooth speed times ``e'(s)``'s four basis functions ``(2 pi h / P)
    (cos, sin)(2 pi h s / P)``, h = 1, 2, on the samples after the run's first ``skip_s`` [s] (the start) and at
    least ``window`` samples from its ends."""
    xs, ys = [], []
    for _, g in df.groupby("run", sort=False):
        v = g["speed_m_s"].to_numpy(float)
        if v.size < 3 * window:
            continue
        s = g["position_m"].to_numpy(float)
        t = g["time_s"].to_numpy(float)
        vs = savgol_filter(v, window, 2)
        keep = (t - t[0] >= skip_s) & (np.arange(v.size) < v.size - window)
        ph = 2 * np.pi * s / P_m
        basis = [h * 2 * np.pi / P_m * f(h * ph) for h in (1, 2) for f in (np.cos, np.sin)]
        xs.append(np.column_stack([vs * b for b in basis])[keep])
        ys.append((v - vs)[keep])
    return np.vstack(xs), np.concatenate(ys)


def fit_cyclic_error(df: pd.DataFrame) -> dict:
    """The encoder's cyclic error estimated from ``df``: the pitch [m] on a grid of 0.5-5 mm (steps of 0.2 %) with
    the smallest residual sum of squares of :func:`ripple_design`'s least squares, and ``e(s) = sum_h a_h cos(2 pi h
    s / P) + b_h sin(2 pi h s / P)`` as ``cyclic_error_m``'s ``A1, A2, phi1, phi2`` (``e'`` of the fit integrated)."""
    best = None
    for P in np.geomspace(0.5e-3, 5e-3, 1153):
        X, y = ripple_design(df, P)
        c, *_ = np.linalg.lstsq(X, y, rcond=None)
        rss = float(np.sum((y - X @ c) ** 2))
        if best is None or rss < best[0]:
            best = (rss, P, c)
    _, P, (a1, b1, a2, b2) = best
    # e'(s) = sum (2 pi h / P) (a cos + b sin)(h ph): e(s) = sum a sin(h ph) - b cos(h ph) = A sin(h ph + phi)
    return {"P_m": float(P), "A1_m": float(np.hypot(a1, b1)), "phi1": float(np.arctan2(-b1, a1)),
            "A2_m": float(np.hypot(a2, b2)), "phi2": float(np.arctan2(-b2, a2))}


def changed(df: pd.DataFrame, mode: str, truth: dict) -> pd.DataFrame:
    """The frame of one split as the probe ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    if mode == "logp":
        out = df.drop(columns=["chamber_pressure_hPa"])
        out["ln_chamber_pressure"] = np.round(np.log(df["chamber_pressure_hPa"]), 6)
        return out
    if mode == "law":
        zeta = {r["run"]: r["zeta_b"] for r in truth["per_run"]}
        out = df.drop(columns=["chamber_pressure_hPa"])
        out["b2_damping_factor"] = np.round(df["run"].map(zeta) / 0.0125, 6)
        return out
    if mode == "onset":
        return onset_trimmed(df)
    if mode == "undo":
        return encoder_undone(df, truth["parameters"])
    if mode == "fit":
        return encoder_undone(df, truth["fitted"])
    return df


def main(argv=None):
    args = be.probe_args(argv, __doc__, eighth.KINDS, ("logp", "law", "onset", "undo", "fit"))
    src, dst = be.probe_copy(args, eighth.experiment)
    truth = json.loads((src / "rig_truth.json").read_text())
    if args.mode == "fit":
        truth["fitted"] = fit_cyclic_error(pd.read_csv(src / "train.csv"))
        print(json.dumps({"fitted": truth["fitted"], "drawn": truth["parameters"]}))
    for part in ("train", "test"):
        changed(pd.read_csv(src / f"{part}.csv"), args.mode, truth).to_csv(dst / f"{part}.csv", index=False)
    be.probe_loop(args, dst, COLUMN.get(args.mode))


if __name__ == "__main__":
    main()
