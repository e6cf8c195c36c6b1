#!/usr/bin/env python
"""Probes of the seventh blind audit (decision 0101): the close loop on a changed copy of a case's data.

Modes, each on a copy of ``<cache>/<KIND>_<SEED>`` (``bench/blind_effects_seventh.py`` or ``bench/blind_effects.py``
makes it first):

* ``rest`` -- each run's rest before it (its first ``time_s`` minus the previous run's last in the whole session,
  ``all.csv``; the first run's own start) also logged as a per-run column ``rest_before_s``: would the loop trace
  the rests if a column held them?
* ``logrest`` -- as ``rest``, with the column's natural logarithm ``ln_rest_before_s`` (ln of the rest in s) instead:
  does the shape of the column's law stand between the loop and the rests?
* ``regular`` -- each run's ``time_s`` replaced by its least-squares line in the sample index (a regular clock, as
  the DAQ's own), and the speed column's derivative of the position moved onto that clock (its noise kept): the loop
  on the same motion with the packets' stamps undone.
* ``allow`` -- the files unchanged, read with the loader's plausibility findings allowed (``allow_unusual_units``,
  the documented way on with values that are right): the loop on a case the loader refuses.
* ``response`` -- the files unchanged, ``mic_level_dB`` declared a response of the motor (``response_columns``,
  the CLI's ``--response-column``): the loop as a user who knows the meter's column would run it.

Usage: python bench/blind_effects_seventh_probe.py KIND SEED MODE [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``), then the evidence of the probed column, one JSON line each.
"""
import functools
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_seventh as seventh  # noqa: E402

COLUMN = {"rest": "rest_before_s", "logrest": "ln_rest_before_s"}


def rest_before_s(df: pd.DataFrame, session: pd.DataFrame) -> pd.Series:
    """Each sample's run's rest [s] before it in the ``session`` (every run, in recording order): the run's first
    time minus the previous run's last (the first run: its first time, the clock's start being the session's)."""
    ends = session.groupby("run", sort=False)["time_s"].agg(["first", "last"])
    rest = (ends["first"] - ends["last"].shift(1).fillna(0.0)).to_dict()
    return df["run"].map(rest)


def regular_clock(df: pd.DataFrame) -> pd.DataFrame:
    """The frame with each run's time on its least-squares line in the sample index and the speed's derivative of
    the position moved onto it (the speed column minus ``gradient(position, time)`` plus ``gradient(position,
    regular time)``)."""
    out = df.copy()
    for _, idx in out.groupby("run", sort=False).groups.items():
        t = out.loc[idx, "time_s"].to_numpy(float)
        s = out.loc[idx, "position_m"].to_numpy(float)
        k = np.arange(t.size)
        t_reg = np.polyval(np.polyfit(k, t, 1), k)
        v = out.loc[idx, "speed_m_s"].to_numpy(float)
        out.loc[idx, "speed_m_s"] = np.round(v - np.gradient(s, t) + np.gradient(s, t_reg), 9)
        out.loc[idx, "time_s"] = np.round(t_reg, 9)
    return out


def changed(df: pd.DataFrame, mode: str, session: pd.DataFrame) -> pd.DataFrame:
    """The frame of one split as the probe ``mode`` changes it (``session``: the whole session's frame)."""
    if mode == "rest":
        out = df.copy()
        out["rest_before_s"] = np.round(rest_before_s(df, session), 6)
        return out
    if mode == "logrest":
        out = df.copy()
        out["ln_rest_before_s"] = np.round(np.log(rest_before_s(df, session)), 6)
        return out
    if mode == "regular":
        return regular_clock(df)
    return df


def main(argv=None):
    args = be.probe_args(argv, __doc__, seventh.KINDS, ("rest", "logrest", "regular", "allow", "response"))
    src, dst = be.probe_copy(args, seventh.experiment)
    session = pd.read_csv(src / "all.csv")
    for part in ("train", "test"):
        changed(pd.read_csv(src / f"{part}.csv"), args.mode, session).to_csv(dst / f"{part}.csv", index=False)
    if args.mode == "allow":
        be.load_measurements = functools.partial(be.load_measurements, allow_unusual_units=True)
    if args.mode == "response":
        be.close_loop = functools.partial(be.close_loop, response_columns=("mic_level_dB",))
    be.probe_loop(args, dst, COLUMN.get(args.mode))


if __name__ == "__main__":
    main()
