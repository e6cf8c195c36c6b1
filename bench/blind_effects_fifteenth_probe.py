#!/usr/bin/env python
"""Probes of the fifteenth blind audit's misses (``bench/blind_effects_fifteenth.py``): the close loop on a changed
copy of a case's files, or with one setting changed, one change per mode:

* ``log_shunt`` -- the box's column ``sense_shunt_ohm`` replaced by its decimal logarithm, ``sense_shunt_log10_ohm``
  (the same setting on the scale its law lives on; no truth).
* ``tray_exact`` -- the decoy's ``tray_mass_g`` replaced by ``240 g - 1000 |load_kg|`` exactly (no filter, drift or
  noise): the column as an affine function of the load's magnitude alone.
* ``tray_no_load`` -- the decoy's ``tray_mass_g`` less ``240 g - 1000 |load_kg|``: the balance's settling after each
  change, its drift and its noise alone.
* ``no_voltage_lags`` -- no change of the files: the close loop with the plan voltage's derived history columns
  switched off in this process (``closeloop.lags.STORED_INPUTS`` emptied; the package's files are not changed).
* ``rh_truth`` -- the purge's ``purge_flow_L_min`` (or the control's ``hood_rh_pct``) replaced by the truth's hood
  humidity at each run's start, ``hood_rh_truth_pct``, with no noise: the cause exactly, one value per run.
* ``rotation`` -- no change of the files: the close loop with ``clock_folds="rotation"`` (the session clock's
  candidates scored on conditions dealt in turn, interpolating the clock) instead of contiguous blocks.
* ``shunt_on_clean`` / ``log_shunt_on_clean`` -- the shunt's control (the same draws, no effect): the clean case's
  files at the seed with the box's setting of each run added, as ``sense_shunt_ohm`` or as its decimal logarithm
  ``sense_shunt_log10_ohm`` (KIND ``sense_electrode_shunt``; the clean case must be in the cache).
* ``walk_truth`` -- a column ``reseat_walk`` added: the truth's walk ``w`` of each run, with no noise (the ideal
  regressor of the walk).

Usage: python bench/blind_effects_fifteenth_probe.py KIND SEED MODE [--cache DIR] [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_fifteenth as fifteenth  # noqa: E402

MODES = ("log_shunt", "tray_exact", "tray_no_load", "no_voltage_lags", "rh_truth", "walk_truth", "rotation",
         "shunt_on_clean", "log_shunt_on_clean")
CACHE = [be.default_cache()]   # the cache the command line names (the clean case's folder for ``*_on_clean``)
COLUMN = {"log_shunt": "sense_shunt", "tray_exact": "tray", "tray_no_load": "tray", "no_voltage_lags": "time",
          "rh_truth": "hood_rh", "walk_truth": "reseat", "rotation": "time",
          "shunt_on_clean": "sense_shunt", "log_shunt_on_clean": "sense_shunt"}


def changed(df, mode: str, truth: dict):
    """The part ``df`` as ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    per_run = {r["run"]: r for r in truth["per_run"]}
    if mode in ("shunt_on_clean", "log_shunt_on_clean"):
        R = out.groupby("run")["sense_shunt_ohm"].first()
        src = Path(CACHE[0]) / f"clean_{int(truth['plan']['seed'])}"
        part = next(p for p in ("train", "test") if set(pd.read_csv(src / f"{p}.csv", usecols=["run"])["run"])
                    == set(R.index))
        out = pd.read_csv(src / f"{part}.csv")
        r = out["run"].map(R)
        if mode == "shunt_on_clean":
            out["sense_shunt_ohm"] = r
        else:
            out["sense_shunt_log10_ohm"] = np.log10(r)
    elif mode == "log_shunt":
        out["sense_shunt_log10_ohm"] = np.log10(out.pop("sense_shunt_ohm"))
    elif mode == "tray_exact":
        out["tray_mass_g"] = fifteenth.RACK_G - 1000.0 * out["load_kg"].abs()
    elif mode == "tray_no_load":
        out["tray_mass_g"] = out["tray_mass_g"] - (fifteenth.RACK_G - 1000.0 * out["load_kg"].abs())
    elif mode == "rh_truth":
        for c in ("purge_flow_L_min", "hood_rh_pct"):
            out.pop(c) if c in out else None
        out["hood_rh_truth_pct"] = out["run"].map(lambda k: per_run[int(k)]["rh_pct"])
    elif mode == "walk_truth":
        out["reseat_walk"] = out["run"].map(lambda k: per_run[int(k)]["w"])
    return out


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--cache" in argv:
        CACHE[0] = argv[argv.index("--cache") + 1]
    if len(argv) >= 3 and argv[2] == "no_voltage_lags":
        from l1b2.closeloop import lags
        lags.STORED_INPUTS = ()
    be.probe_truth_main(argv, __doc__, fifteenth, MODES, changed, COLUMN, {"rotation": {"clock_folds": "rotation"}})


if __name__ == "__main__":
    main()
