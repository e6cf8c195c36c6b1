#!/usr/bin/env python
"""Probes of the eleventh blind audit's misses (``bench/blind_effects_eleventh.py``): the close loop on a changed copy
of a case's files, one change per mode:

* ``prev_speed`` -- a run-level column ``prev_run_speed_mm_s`` added: each run's previous pass's mean speed [mm/s]
  (the stroke over the duration of the run before it in session order; the warm-up pass's 200 mm/s before the first
  run), the variable the oil film the run meets follows.
* ``starts8`` -- the files unchanged, the loop with ``n_starts=8`` (its identifications' multistart with eight
  starts instead of four).
* ``seed1`` -- the files unchanged, the loop with ``seed=1`` (its multistart's and its folds' random stream).

Usage: python bench/blind_effects_eleventh_probe.py KIND SEED MODE [--out DIR]. Prints one JSON line: the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_eleventh as eleventh  # noqa: E402

MODES = ("prev_speed", "starts8", "seed1")
COLUMN = {"prev_speed": "prev_run_speed_mm_s", "starts8": None, "seed1": None}
SETTINGS = {"starts8": {"n_starts": 8}, "seed1": {"seed": 1}}


def changed(df: pd.DataFrame, mode: str, truth: dict) -> pd.DataFrame:
    """The frame of one split as the probe ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    if mode == "prev_speed":
        v_prev = {int(r["run"]): 1e3 * float(r["v_prev_m_s"]) for r in truth["per_run"]}
        out["prev_run_speed_mm_s"] = np.round(out["run"].map(lambda r: v_prev[int(r)]).to_numpy(float), 3)
    return out


def main(argv=None):
    be.probe_truth_main(argv, __doc__, eleventh, MODES, changed, COLUMN, SETTINGS)


if __name__ == "__main__":
    main()
