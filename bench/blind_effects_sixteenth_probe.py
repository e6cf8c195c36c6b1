#!/usr/bin/env python
"""Probes of the sixteenth blind audit's misses (``bench/blind_effects_sixteenth.py``): the close loop on a changed
copy of a case's files, one change per mode:

* ``offset_truth`` -- a column ``drive_offset_Hz`` added: the truth's frequency offset of each run's file (the
  cause of ``autotune_file_blocks``, exactly, one value per run), as an auxiliary channel beside the plan's
  ``frequency_Hz``.
* ``file_index`` -- a column ``file_index`` added: the number of each run's data file (1, 2, ...), the fact of the
  recording protocol that the blocks follow (what the DAQ could have logged; no truth of the offsets).
* ``ramp_truth`` -- a column ``bus_share`` added: the soft start's bus over its setting at each sample,
  ``min(1, 0.2 + 0.8 t / T_r)`` (1 when ``T_r = 0``; ``t`` the sample's time from its run's first sample), the
  ramp's cause per sample beside the setting ``softstart_ms``.
* ``tach_ungated`` -- the decoy's ``pulley_tach_rpm`` replaced by the reading of a tachometer that turns in every run:
  ``60 |v| / (2 pi r_p)`` through the converter's filter (the truth's ``r_p`` and ``tau_t``), ``v`` the derivative of
  the logged position (no noise, 0.1 rpm resolution): the decoy's echo of the speed without its gate by the load.
* ``softstart_on_clean`` / ``viscosity_on_clean`` -- the kind's control (the same draws, no effect): the clean case's
  files at the seed with the kind's column of each run added (``softstart_ms``, or ``oil_viscosity_mPa_s`` as the
  viscometer logged it; KIND ``softstart_ramp`` or ``stribeck_viscosity``; the clean case must be in the cache).

Usage: python bench/blind_effects_sixteenth_probe.py KIND SEED MODE [--cache DIR] [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_sixteenth as sixteenth  # noqa: E402

MODES = ("offset_truth", "file_index", "ramp_truth", "softstart_on_clean", "viscosity_on_clean", "tach_ungated")
CACHE = [be.default_cache()]   # the cache the command line names (the clean case's folder for ``*_on_clean``)
COLUMN = {"offset_truth": "drive_offset", "file_index": "file_index", "ramp_truth": "bus_share",
          "softstart_on_clean": "softstart", "viscosity_on_clean": "oil_viscosity", "tach_ungated": "pulley_tach"}
ON_CLEAN = {"softstart_on_clean": "softstart_ms", "viscosity_on_clean": "oil_viscosity_mPa_s"}


def on_clean(df, column: str, truth: dict):
    """The clean case's part at the seed holding the runs of ``df``, with ``df``'s ``column`` added (per sample: the
    column's value at the same run and sample index; the clean run's own length)."""
    src = Path(CACHE[0]) / f"clean_{int(truth['plan']['seed'])}"
    part = next(p for p in ("train", "test") if set(pd.read_csv(src / f"{p}.csv", usecols=["run"])["run"])
                == set(df["run"]))
    out = pd.read_csv(src / f"{part}.csv")
    i = out.groupby("run").cumcount()
    vals = df.assign(i=df.groupby("run").cumcount()).set_index(["run", "i"])[column]
    last = df.groupby("run")[column].last()
    out[column] = [vals.get((r, k), last[r]) for r, k in zip(out["run"], i)]
    return out


def changed(df, mode: str, truth: dict):
    """The part ``df`` as ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    per_run = {r["run"]: r for r in truth["per_run"]}
    p = truth["parameters"]
    if mode in ON_CLEAN:
        out = on_clean(out, ON_CLEAN[mode], truth)
    elif mode == "offset_truth":
        out["drive_offset_Hz"] = out["run"].map(lambda k: per_run[int(k)]["f_drive_Hz"] - 48500.0)
    elif mode == "file_index":
        out["file_index"] = (out["run"] - 1) // int(p["N"]) + 1
    elif mode == "ramp_truth":
        t = out["time_s"] - out.groupby("run")["time_s"].transform("first")
        Tr = out["run"].map(lambda k: per_run[int(k)]["T_r_s"])
        share = np.minimum(1.0, sixteenth.PEDESTAL + (1.0 - sixteenth.PEDESTAL) * t / Tr.where(Tr > 0, np.nan))
        out["bus_share"] = np.round(share.fillna(1.0), 4)
    elif mode == "tach_ungated":
        parts = []
        for _, g in out.groupby("run", sort=False):
            t, x = g["time_s"].to_numpy(float), g["position_m"].to_numpy(float)
            y = sixteenth.tach_rpm(t, np.gradient(x, t), 1.0, p)
            parts.append(pd.Series(np.round(y, 1), index=g.index))
        out["pulley_tach_rpm"] = pd.concat(parts)
    return out


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--cache" in argv:
        CACHE[0] = argv[argv.index("--cache") + 1]
    be.probe_truth_main(argv, __doc__, sixteenth, MODES, changed, COLUMN, {})


if __name__ == "__main__":
    main()
