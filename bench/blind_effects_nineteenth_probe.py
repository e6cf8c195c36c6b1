#!/usr/bin/env python
"""Probes of the nineteenth blind audit's hidden reseat (``bench/blind_effects_nineteenth.py``): the close loop on a
changed copy of a case's files, one column added per mode, constant in each run:

* ``prev_arrival`` -- ``prev_arrival_m_s``, the arrival speed of the run before (the truth's ``v_arrival_m_s`` of
  run ``k - 1`` for run ``k``; the session's first run gets the median of the others): the outcome the state
  follows, as a rig that logs each run's arrival at the stop would carry it into the next run's file.
* ``prev_hard`` -- ``prev_hard_arrival``, 1 when the run before arrived at ``v_hard`` or more and 0 otherwise (0 for
  the first run): the reseat's trigger itself, without the creep's count of runs.

Usage: python bench/blind_effects_nineteenth_probe.py KIND SEED MODE [--cache DIR] [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_nineteenth as nineteenth  # noqa: E402

MODES = ("prev_arrival", "prev_hard")
COLUMN = {"prev_arrival": "prev_arrival", "prev_hard": "prev_hard"}


def previous_arrivals(truth: dict) -> np.ndarray:
    """The arrival speed [m/s] of the run before each run (run 1: the median of the others)."""
    v = np.array([q["v_arrival_m_s"] for q in truth["per_run"]], float)
    out = np.empty_like(v)
    out[1:] = v[:-1]
    out[0] = float(np.median(v[:-1]))
    return out


def changed(df, mode: str, truth: dict):
    """The part ``df`` as ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    prev = previous_arrivals(truth)
    k = out["run"].astype(int).to_numpy() - 1
    if mode == "prev_arrival":
        out["prev_arrival_m_s"] = np.round(prev[k], 4)
    elif mode == "prev_hard":
        hard = (prev >= truth["parameters"]["v_hard"]).astype(float)
        hard[0] = 0.0
        out["prev_hard_arrival"] = hard[k]
    return out


def main(argv=None):
    be.probe_truth_main(argv, __doc__, nineteenth, MODES, changed, COLUMN, {})


if __name__ == "__main__":
    main()
