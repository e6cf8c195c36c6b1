#!/usr/bin/env python
"""Probes of the tenth blind audit's misses (``bench/blind_effects_tenth.py``): the close loop on a changed copy of a
case's files, one change per mode:

* ``law`` -- ``track_offset_mm`` replaced by the crown's own variable, ``track_drop_um``: each sample's drop of the
  bar's surface ``(y - y0)^2 / (2 R)`` [um] from its logged offset ``y`` and the drawn apex ``y0`` and radius ``R``
  (a column linear in the preload's change).
* ``since`` -- a run-level column ``traverses_since_wipe`` added: each run's traverses since the last wipe (the
  procedure's logbook), the count the friction's recovery follows.
* ``pulley`` -- a column ``pulley_distance_mm`` added: each sample's distance [mm] from the stroke's end nearest
  the load's pulley (``s - s_min`` for a positive load, ``s_max - s`` for a negative one; 0 without a load), the
  weight's height above its lowest point.
* ``repeats3`` -- the files unchanged, the loop with ``refit_repeats=3`` (its acceptance's folds from three
  splits of the runs, 12 folds, instead of one split's 4).

Usage: python bench/blind_effects_tenth_probe.py KIND SEED MODE [--out DIR]. Prints one JSON line: the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_tenth as tenth  # noqa: E402

MODES = ("law", "since", "pulley", "repeats3")
COLUMN = {"law": "track_drop_um", "since": "traverses_since_wipe", "pulley": "pulley_distance_mm",
          "repeats3": None}
SETTINGS = {"repeats3": {"refit_repeats": 3}}
S_MIN_MM, S_MAX_MM = -21.0, 21.0


def pulley_distance_mm(position_m, load_kg, s_min_mm: float = S_MIN_MM, s_max_mm: float = S_MAX_MM):
    """The distance [mm] from the stroke's end nearest the load's pulley: ``s - s_min`` for a positive load (it
    pulls toward -position), ``s_max - s`` for a negative one, 0 without a load."""
    s = 1e3 * np.asarray(position_m, float)
    m = np.asarray(load_kg, float)
    return np.where(m > 0, s - s_min_mm, np.where(m < 0, s_max_mm - s, 0.0))


def changed(df: pd.DataFrame, mode: str, truth: dict) -> pd.DataFrame:
    """The frame of one split as the probe ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    p = truth["parameters"]
    if mode == "law":
        y = out.pop("track_offset_mm").to_numpy(float) * 1e-3
        out["track_drop_um"] = np.round((y - p["y0_m"]) ** 2 / (2.0 * p["R_m"]) * 1e6, 4)
    elif mode == "since":
        counts = tenth.wipe_counts(len(truth["per_run"]))
        out["traverses_since_wipe"] = out["run"].map(lambda r: int(counts[int(r) - 1]))
    elif mode == "pulley":
        out["pulley_distance_mm"] = np.round(pulley_distance_mm(out["position_m"], out["load_kg"]), 4)
    return out


def main(argv=None):
    be.probe_truth_main(argv, __doc__, tenth, MODES, changed, COLUMN, SETTINGS)


if __name__ == "__main__":
    main()
