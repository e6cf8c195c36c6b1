#!/usr/bin/env python
"""Probes of the fourteenth blind audit's misses (``bench/blind_effects_fourteenth.py``): the close loop on a changed
copy of a case's files, or with one setting changed, one change per mode:

* ``segment`` -- a column ``segment_after_break`` added per sample: 1 in the runs after the session's longest rest
  between two runs (read from the logged clock, TRAIN and TEST merged in time order; no truth), 0 before. The break's
  segment as a logged column.
* ``rotation`` -- no change of the files: the close loop with ``clock_folds="rotation"`` (the session clock's
  candidates scored on conditions dealt in turn, interpolating the clock) instead of contiguous blocks.
* ``no_voltage_lags`` -- no change of the files: the close loop with the plan voltage's derived history columns
  (``voltage_V_lag3r``, ``voltage_V_lag10r``, ``voltage_V_step``) switched off in this process
  (``closeloop.lags.STORED_INPUTS`` emptied; the package's files are not changed).
* ``segment_no_lags`` -- both: the ``segment`` column added and the voltage's history columns switched off.
* ``lag_truth`` -- no loop: each run's ``voltage_V_lag10r`` and ``voltage_V_lag3r`` (the loop's derivation,
  ``closeloop.lags.with_lagged_channels`` on TRAIN and TEST) and the truth's extra load (the second operator's hook
  in the run, in drive coordinates ``d (m_true - m_logged)``), with the correlations of each lag's TRAIN run values
  with the runs after the handover (an indicator) and with the session clock, the first conditions' V0 and the slow
  lag's first runs; printed as one JSON line.

Usage: python bench/blind_effects_fourteenth_probe.py KIND SEED MODE [--cache DIR] [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import functools
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_fourteenth as fourteenth  # noqa: E402

MODES = ("segment", "rotation", "no_voltage_lags", "segment_no_lags", "lag_truth")
COLUMN = {"segment": "segment_after_break", "rotation": "time", "no_voltage_lags": "time",
          "segment_no_lags": "segment_after_break", "lag_truth": None}
SETTINGS = {"rotation": {"clock_folds": "rotation"}}


def break_start(frames) -> float:
    """The session time [s] of the first run after the longest rest between two runs of ``frames`` (merged)."""
    g = pd.concat(frames).groupby("run")["time_s"]
    tab = pd.DataFrame({"start": g.min(), "stop": g.max()}).sort_values("start")
    gaps = tab["start"].to_numpy()[1:] - tab["stop"].to_numpy()[:-1]
    return float(tab["start"].to_numpy()[1:][int(np.argmax(gaps))])


def changed_pair(src: Path, dst: Path, mode: str) -> None:
    """Write ``dst``'s TRAIN and TEST as ``mode`` changes ``src``'s."""
    parts = {p: pd.read_csv(src / f"{p}.csv") for p in ("train", "test")}
    t0 = break_start(parts.values())
    for p, df in parts.items():
        out = df.copy()
        if mode in ("segment", "segment_no_lags"):
            start = out.groupby("run")["time_s"].transform("min")
            out["segment_after_break"] = (start >= t0).astype(float)
        out.to_csv(dst / f"{p}.csv", index=False)


def lag_truth(args) -> None:
    """Mode ``lag_truth`` (module docstring)."""
    from l1b2.closeloop import lags
    src = be.data_dir(args.kind, args.seed, Path(args.cache), fourteenth.experiment)
    train, test = pd.read_csv(src / "train.csv"), pd.read_csv(src / "test.csv")
    tr, te, _ = lags.with_lagged_channels(train, test)
    df = pd.concat([tr, te])
    truth = json.loads((src / "rig_truth.json").read_text())
    extra = {r["run"]: r["load_kg"] for r in truth["per_run"]}
    g = df.groupby("run")
    runs = pd.DataFrame({"start": g["time_s"].min(), "V0": g["voltage_V"].first(), "m": g["load_kg"].first(),
                         "d": g["direction"].first(), "lag10": g["voltage_V_lag10r"].mean(),
                         "lag3": g["voltage_V_lag3r"].mean()}).sort_values("start")
    runs["extra_drive"] = runs["d"] * (np.array([extra[int(r)] for r in runs.index]) - runs["m"])
    k = int(truth["parameters"]["k_hand"])
    runs["after"] = (runs.index > k).astype(float)
    train_runs = set(train["run"].unique())
    tr_runs = runs[runs.index.isin(train_runs)]

    def r(a, b):
        return round(float(np.corrcoef(a, b)[0, 1]), 3)
    first = float(runs["V0"].iloc[0])
    print(json.dumps({"kind": args.kind, "seed": args.seed, "mode": "lag_truth", "k_hand": k, "first_V0": first,
                      "first_conditions_V0": runs["V0"].iloc[:12].tolist(),
                      "lag10_first_runs": [round(x, 1) for x in runs["lag10"].iloc[:24]],
                      "train": {lag: {"r_after": r(tr_runs[lag], tr_runs["after"]),
                                      "r_clock": r(tr_runs[lag], tr_runs["start"])}
                                for lag in ("lag10", "lag3")},
                      "lag10_after_rest": round(float(runs["lag10"].loc[k + 1]), 1),
                      "V0_before_rest": float(runs["V0"].loc[k]),
                      "extra_drive_after_kg": sorted({round(float(x), 4) for x in runs["extra_drive"][runs.index > k]}),
                      "r_clock_after": r(tr_runs["start"], tr_runs["after"])}))


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    args = be.probe_args(argv, __doc__, fourteenth.KINDS, MODES)
    if args.mode == "lag_truth":
        lag_truth(args)
        return
    src, dst = be.probe_copy(args, fourteenth.experiment)
    changed_pair(src, dst, args.mode)
    if args.mode in ("no_voltage_lags", "segment_no_lags"):
        from l1b2.closeloop import lags
        lags.STORED_INPUTS = ()
    if args.mode in SETTINGS:
        be.close_loop = functools.partial(be.close_loop, **SETTINGS[args.mode])
    be.probe_loop(args, dst, COLUMN[args.mode])


if __name__ == "__main__":
    main()
