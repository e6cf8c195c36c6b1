#!/usr/bin/env python
"""Probes of the twentieth blind audit's ultrasonic dither (``bench/blind_effects_twentieth.py``): the close loop on a
changed copy of a case's files, one column added per mode, constant in each run:

* ``relief`` -- ``dither_relief``, the share of the guide's friction the dither takes away in the run, ``x (1 - (2 /
  pi) arcsin(min(1, v_c / V_d)))`` (Littmann's law at the run's speed), with ``v_c`` the run's mean speed over
  ``|s| < 15 mm`` in the clean case at the same seed (the run without the dither: the same plan and scatter) and
  ``V_d = 2 pi f_u a`` from the truth: the cause in the form in which the loop's ``friction`` form is linear.
* ``ratio`` -- ``dither_ratio``, ``V_d / v_c``: the dither's velocity over the run's, a monotone map of the relief
  without its threshold at 1.

The logged ``rail_dither_um`` stays in the files. Usage: python bench/blind_effects_twentieth_probe.py KIND SEED MODE
[--cache DIR] [--out DIR]. Prints the row of ``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and
the evidence on the probe's and the vibrometer's columns.
"""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_twentieth as twentieth  # noqa: E402

MODES = ("relief", "ratio")
COLUMN = {"relief": "dither_relief", "ratio": "dither_ratio"}
MID_M = 0.015        # the runs' speeds over |s| < 15 mm


def clean_speeds(frames) -> pd.Series:
    """Each run's mean |speed| over ``|s| < 15 mm`` in the clean case's ``frames`` (its parts), by run."""
    df = pd.concat(frames, ignore_index=True)
    df = df[df["position_m"].abs() < MID_M]
    return df.groupby("run")["speed_m_s"].mean().abs()


def changed(df, mode: str, truth: dict, v_clean: pd.Series):
    """The part ``df`` as ``mode`` changes it (``truth``: the case's ``rig_truth.json``, ``v_clean``: the clean
    case's run speeds by run)."""
    out = df.copy()
    p = truth["parameters"]
    runs = out["run"].astype(int).to_numpy()
    a = np.asarray(p["a_um"], float)[runs - 1]
    V_d = 2.0 * math.pi * p["f_u_Hz"] * a * 1e-6
    v = v_clean.reindex(runs).to_numpy(float)
    if mode == "relief":
        share = np.where(v < V_d, (2.0 / math.pi) * np.arcsin(np.minimum(v / np.maximum(V_d, 1e-12), 1.0)), 1.0)
        out[COLUMN[mode]] = np.round(p["x_share"] * (1.0 - share), 4)
    elif mode == "ratio":
        out[COLUMN[mode]] = np.round(V_d / v, 4)
    return out


def main(argv=None):
    args = be.probe_args(argv, __doc__, twentieth.KINDS, MODES)
    src, dst = be.probe_copy(args, twentieth.experiment)
    truth = json.loads((src / "rig_truth.json").read_text())
    clean = be.data_dir("clean", args.seed, Path(args.cache))
    v_clean = clean_speeds([pd.read_csv(clean / f"{part}.csv") for part in ("train", "test")])
    for part in ("train", "test"):
        changed(pd.read_csv(src / f"{part}.csv"), args.mode, truth, v_clean).to_csv(dst / f"{part}.csv", index=False)
    row, res = be.probe_loop(args, dst, "dither")
    be.print_channel_evidence(res, "rail_dither", ("channel", "significant", "p_value", "cv_gain", "best"),
                              ("signal", "significant", "p_value", "cv_gain", "dominated_by"))


if __name__ == "__main__":
    main()
