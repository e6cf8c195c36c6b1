#!/usr/bin/env python
"""Probes of the sixth blind audit (decision 0089): the close loop on a changed copy of a case's data.

Modes, each on a copy of ``<cache>/<KIND>_<SEED>`` (``bench/blind_effects_sixth.py`` or ``bench/blind_effects.py``
makes it first):

* ``fill`` -- the ``holder_temp_C`` column's NaN gaps filled by linear interpolation within each run (held at the
  run's ends): is the gap the only reason the channel is not traced?
* ``derived`` -- the ``speed_m_s`` column removed, so the loader derives the speed from the position: the loop on the
  same motion without the clipped speed channel.
* ``vcopy`` -- the voltage also logged as an auxiliary column ``drive_setting_V``, a run setting the loop lags
  (``l1b2.closeloop.lags``): would a lag of the voltage be traced?

Usage: python bench/blind_effects_sixth_probe.py KIND SEED MODE [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``), then the evidence of the probed column (and of its lags), one JSON
line each.
"""
import json
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_sixth as sixth  # noqa: E402

COLUMN = {"fill": "holder_temp_C", "vcopy": "drive_setting_V"}


def changed(df: pd.DataFrame, mode: str) -> pd.DataFrame:
    """The frame of one split as the probe ``mode`` changes it."""
    out = df.copy()
    if mode == "fill":
        out["holder_temp_C"] = out.groupby("run")["holder_temp_C"].transform(
            lambda s: s.interpolate(limit_direction="both"))
    elif mode == "derived":
        out = out.drop(columns=["speed_m_s"])
    elif mode == "vcopy":
        out["drive_setting_V"] = out["voltage_V"]
    return out


def main(argv=None):
    args = be.probe_args(argv, __doc__, sixth.KINDS, ("fill", "derived", "vcopy"))
    src, dst = be.probe_copy(args, sixth.experiment)
    for part in ("train", "test"):
        changed(pd.read_csv(src / f"{part}.csv"), args.mode).to_csv(dst / f"{part}.csv", index=False)
    row, res = be.loop_row(f"{args.kind}({args.mode})", args.seed, dst)
    print(json.dumps(row))
    be.print_channel_evidence(res, COLUMN.get(args.mode), ("channel", "significant", "p_value", "cv_gain",
                                                           "dominated_by"),
                              ("signal", "significant", "p_value", "cv_gain", "dominated_by"))


if __name__ == "__main__":
    main()
