#!/usr/bin/env python
"""Probes of the twelfth blind audit's misses (``bench/blind_effects_twelfth.py``): the close loop on a changed copy
of a case's files, one change per mode:

* ``prev_load`` -- a run-level column ``prev_run_load_kg`` added: the logged load of the run before in session order
  (0 before the first run: the empty hook), the one-run lag of the load that the late swap's forward runs carry.
* ``absorber`` -- a run-level column ``holder_absorption`` added: the holder mode's absorption at the run's drive
  frequency, ``1 / (1 + ((f - f_s) / gamma)^2)`` with the case's own ``f_s`` and ``gamma`` (the truth's): the
  notch's law as a logged column, linear in B2's damping factor.
* ``hall_runmean`` -- no loop: per run (TRAIN and TEST), the mean of the decoy's ``homing_hall_mT`` with its drift
  removed (the truth's), the run-level signal the loop reads, and its correlation with the run's mean speed, its
  duration, ``load_kg``, ``direction``, ``voltage_V`` and ``direction x load_kg``; printed as one JSON line.

Usage: python bench/blind_effects_twelfth_probe.py KIND SEED MODE [--cache DIR] [--out DIR]. A loop's mode prints the
row of ``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_twelfth as twelfth  # noqa: E402

from l1b2.rig.experiment import plan_runs  # noqa: E402

MODES = ("prev_load", "absorber")
#: the modes that print an analysis of the files and run no loop
ANALYSES = ("hall_runmean",)
COLUMN = {"prev_load": "prev_run_load_kg", "absorber": "holder_absorption"}


def changed(df: pd.DataFrame, mode: str, truth: dict) -> pd.DataFrame:
    """The frame of one split as the probe ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    if mode == "prev_load":
        conds = plan_runs(be.plan_of(int(truth["plan"]["seed"])))
        prev = {k + 1: (conds[k - 1][1] if k > 0 else 0.0) for k in range(len(conds))}
        out["prev_run_load_kg"] = out["run"].map(lambda r: prev[int(r)]).to_numpy(float)
    elif mode == "absorber":
        p = truth["parameters"]
        f = {int(r["run"]): float(r["f_Hz"]) for r in truth["per_run"]}
        a = {r: float(twelfth.notch_factor(x, p["f_s_Hz"], p["gamma_Hz"], 1.0)) - 1.0 for r, x in f.items()}
        out["holder_absorption"] = np.round(out["run"].map(lambda r: a[int(r)]).to_numpy(float), 4)
    return out


def hall_runmean(kind: str, seed: int, cache: str) -> dict:
    """The decoy's run means against the runs' own motion and settings (mode ``hall_runmean``)."""
    d = be.data_dir(kind, seed, Path(cache), twelfth.experiment)
    p = json.loads((d / "rig_truth.json").read_text())["parameters"]
    df = pd.concat([pd.read_csv(d / "train.csv"), pd.read_csv(d / "test.csv")])
    df["bell"] = df["homing_hall_mT"] - p["b_d_mT"] * (1 - np.exp(-df["time_s"] / twelfth.HALL_DRIFT_TAU_S))
    g = df.groupby("run")
    r = pd.DataFrame({"bell": g["bell"].mean(), "speed": g["speed_m_s"].agg(lambda x: np.abs(x).mean()),
                      "duration": g["time_s"].agg(lambda x: x.max() - x.min()), "load": g["load_kg"].first(),
                      "direction": g["direction"].first(), "voltage": g["voltage_V"].first()})
    r["d*load"] = r["load"] * r["direction"]
    return {"kind": kind, "seed": seed, "mode": "hall_runmean", "sd_run_mean_mT": round(float(r["bell"].std()), 4),
            "r": {c: round(float(np.corrcoef(r["bell"], r[c])[0, 1]), 3) for c in r.columns if c != "bell"}}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) >= 3 and argv[2] in ANALYSES:
        cache = argv[argv.index("--cache") + 1] if "--cache" in argv else be.default_cache()
        print(json.dumps(hall_runmean(argv[0], int(argv[1]), cache)))
        return
    be.probe_truth_main(argv, __doc__, twelfth, MODES, changed, COLUMN, {})


if __name__ == "__main__":
    main()
