#!/usr/bin/env python
"""Probes of the thirteenth blind audit's misses (``bench/blind_effects_thirteenth.py``): the close loop on a changed
copy of a case's files, one change per mode:

* ``deficit`` -- a run-level column ``supply_deficit`` added: the bench supply's relative shortfall in the run,
  ``min(0, (U230 mains / 230 V - h) / V_set - 1)`` with the case's own ``U230``, ``h`` and per-run mains (the
  truth's) and ``V_set`` the operator's setting for the run's logged V0: the dropout's law as a logged column, 0 for
  the runs in regulation.
* ``mains_x_v0`` -- a column ``mains_x_voltage`` added per sample, ``(mains_V - 230 V) voltage_V / 324 V`` from the
  logged columns only: a plain product of the two channels, no threshold, no truth.
* ``left_after`` -- no change of the files: the close loop on the case as it is, then each TRAIN run's mean relative
  speed error of the final model's free run (measured minus predicted over the measured, in drive coordinates,
  ``|s| < 15 mm``) against the run's mean ``mains_V`` and the truth's supply deficit (the ``deficit`` mode's),
  over all runs and over the runs at 324 V; and the run-level evidence (``closeloop.runlevel.analyse``, alpha 0.01,
  5 folds) of ``mains_V``'s run mean and of the plan's inputs against that final model, the loop's own test of a
  run-level signal in a round after the last; printed as one JSON line after the row.

Usage: python bench/blind_effects_thirteenth_probe.py KIND SEED MODE [--cache DIR] [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_thirteenth as thirteenth  # noqa: E402

from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402

MODES = ("deficit", "mains_x_v0", "left_after")
COLUMN = {"deficit": "supply_deficit", "mains_x_v0": "mains_x_voltage", "left_after": "mains_V"}


def deficit_of_runs(truth: dict, voltages: dict) -> dict:
    """Each run's relative supply shortfall (``deficit`` mode); ``voltages``: run -> logged V0."""
    p = truth["parameters"]
    nominal = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    plan = be.plan_of(int(truth["plan"]["seed"]))
    out = {}
    for r, V0 in voltages.items():
        V_set = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
        got = float(thirteenth.supplied_V(V_set, p["mains_V"][r - 1], p["U230_V"], p["h_V"]))
        out[r] = min(0.0, got / V_set - 1.0)
    return out


def changed(df: pd.DataFrame, mode: str, truth: dict) -> pd.DataFrame:
    """The frame of one split as the probe ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    if mode == "deficit":
        volts = {int(r): float(v) for r, v in out.groupby("run")["voltage_V"].first().items()}
        dfc = deficit_of_runs(truth, volts)
        out["supply_deficit"] = np.round(out["run"].map(lambda r: dfc[int(r)]).to_numpy(float), 5)
    elif mode == "mains_x_v0":
        out["mains_x_voltage"] = np.round((out["mains_V"] - 230.0) * out["voltage_V"] / 324.0, 3)
    return out


def left_after(argv) -> None:
    """Mode ``left_after``: the loop's row, then what its final model leaves per TRAIN run against the mains."""
    args = be.probe_args(argv, __doc__, thirteenth.KINDS, MODES)
    src, dst = be.probe_copy(args, thirteenth.experiment)
    truth = json.loads((src / "rig_truth.json").read_text())
    _, res = be.probe_loop(args, dst, None)
    df = res.train_df
    model = res.extended_model if res.extended_model is not None else res.baseline_model
    v = df["speed_m_s"].to_numpy(float)
    d = df["direction"].to_numpy(float)
    frame = pd.DataFrame({"run": df["run"].to_numpy(), "err": d * (v - np.asarray(model.predict_free_run(df), float)),
                          "v": d * v, "mains": df["mains_V"].to_numpy(float), "V0": df["voltage_V"].to_numpy(float)})
    frame = frame[np.abs(df["position_m"].to_numpy(float)) < 0.015]
    g = frame.groupby("run")
    runs = pd.DataFrame({"rel": g["err"].mean() / g["v"].mean(), "mains": g["mains"].mean(), "V0": g["V0"].first()})
    dfc = deficit_of_runs(truth, {int(r): float(x) for r, x in runs["V0"].items()})
    runs["deficit"] = [dfc[int(r)] for r in runs.index]
    hi = runs[runs["V0"] == 324.0]

    def r(a, b):
        return round(float(np.corrcoef(a, b)[0, 1]), 3)
    print(json.dumps({"kind": args.kind, "seed": args.seed, "mode": "left_after", "runs": len(runs),
                      "runs_324": len(hi),
                      "sd_rel_all_pct": round(100 * float(runs["rel"].std()), 3),
                      "sd_rel_324_pct": round(100 * float(hi["rel"].std()), 3),
                      "r_mains_all": r(runs["rel"], runs["mains"]), "r_mains_324": r(hi["rel"], hi["mains"]),
                      "r_deficit_all": r(runs["rel"], runs["deficit"]),
                      "dropped_runs": int((runs["deficit"] < 0).sum()),
                      "run_level_after": run_level_after(res, dst, model)}))


def run_level_after(res, dst: Path, model) -> list:
    """The run-level evidence of ``mains_V`` and the plan's inputs against the final ``model`` (mode
    ``left_after``): per signal its label, p-value, cv gain, significance at this test's own level and dominance."""
    from l1b2.closeloop import runlevel
    from l1b2.data.measurements import load_measurements
    mask = np.array(load_measurements(dst / "train.csv").mask)
    assert len(mask) == len(res.train_df)
    rl = runlevel.analyse(res.train_df, model, mask, [{"name": "mains_V", "kind": "logged"}], alpha=0.01, k=5,
                          seed=0)
    return [{"signal": e.label, "p_value": float(e.p_value), "cv_gain": round(float(e.cv_gain), 4),
             "significant": bool(e.significant), "dominated_by": e.dominated_by, "level": rl.level}
            for e in rl.evidence]


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) >= 3 and argv[2] == "left_after":
        left_after(argv)
        return
    be.probe_truth_main(argv, __doc__, thirteenth, MODES, changed, COLUMN, {})


if __name__ == "__main__":
    main()
