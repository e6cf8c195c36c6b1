#!/usr/bin/env python
"""Probes of the eighteenth blind audit's decoy (``bench/blind_effects_eighteenth.py``): the close loop on a changed
copy of a case's files, one change per mode:

* ``sign_only`` -- the decoy's ``drive_phase_deg`` replaced by its sign part, ``90 d`` [deg] (the direction
  relabelled, constant in a run, no noise): what the loop makes of the direction's copy alone.
* ``size_only`` -- the decoy's ``drive_phase_deg`` replaced by its size, ``90 + eps (V0 / 324 V)^2`` [deg] (the
  truth's ``eps``, 0.01 deg resolution, constant in a run, no noise): V0 relabelled through the meter's error alone.

Usage: python bench/blind_effects_eighteenth_probe.py KIND SEED MODE [--cache DIR] [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_eighteenth as eighteenth  # noqa: E402

MODES = ("sign_only", "size_only")
COLUMN = {"sign_only": "drive_phase", "size_only": "drive_phase"}


def changed(df, mode: str, truth: dict):
    """The part ``df`` as ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    d = out["direction"].astype(float)
    if mode == "sign_only":
        out["drive_phase_deg"] = 90.0 * d
    elif mode == "size_only":
        V = out["voltage_V"].astype(float)
        out["drive_phase_deg"] = np.round(90.0 + truth["parameters"]["eps_deg"] * (V / eighteenth.PHASE_V0_REF) ** 2,
                                          2)
    return out


def main(argv=None):
    be.probe_truth_main(argv, __doc__, eighteenth, MODES, changed, COLUMN, {})


if __name__ == "__main__":
    main()
