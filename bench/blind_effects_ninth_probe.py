#!/usr/bin/env python
"""Probes of the ninth blind audit (decision 0113): the close loop on a changed copy of a case's data, or with
other acceptance settings.

Modes, each on a copy of ``<cache>/<KIND>_<SEED>`` (``bench/blind_effects_ninth.py`` makes it first):

* ``repeats3`` -- the files unchanged, the loop with ``refit_repeats=3`` (its acceptance's folds from three
  splits of TRAIN's runs instead of one): is a refusal the vote of one split's four folds?
* ``folds8`` -- the files unchanged, the loop with ``refit_folds=8``.
* ``truevolt`` -- ``voltage_V`` replaced by the drive's actual amplitude: each run's set amplitude for
  ``setpoint_overshoot`` (``rig_truth.json``'s ``V0_actual_V``), the plan's V0 times ``V_b(t) / V_s`` per sample for
  ``supply_current_limit`` (:func:`blind_effects_ninth.bus_voltage_V` from the drawn parameters, t from the run's
  first sample): the loop with a perfect log of the drive; is the effect anything but the drive's amplitude?
* ``step`` -- a run-level column ``voltage_step_V`` added: each run's V0 minus the V0 of the previous different
  setting (0 for the session's first setting), held while V0 is unchanged: the setting's history as a signal.
* ``step0`` -- as ``step``, with the drive off (0 V) before the session: the first setting's step is its V0.
* ``runtime`` -- a column ``time_in_run_s`` added (each sample's time since its run's first sample): the time
  since the drive started, as a signal apart from the position and the direction.

Usage: python bench/blind_effects_ninth_probe.py KIND SEED MODE [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``), one JSON line.
"""
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_ninth as ninth  # noqa: E402

from l1b2.closeloop.loop import close_loop  # noqa: E402
from l1b2.data.measurements import load_measurements  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402

MODES = ("repeats3", "folds8", "truevolt", "step", "step0", "runtime")
SETTINGS = {"repeats3": {"refit_repeats": 3}, "folds8": {"refit_folds": 8}}


def setting_steps(V0_V, from_off: bool = False) -> np.ndarray:
    """Per run (in the order given): its V0 minus the previous different setting's, held while V0 is unchanged;
    the session's first setting's step is 0, or its V0 when ``from_off`` (the drive at 0 V before)."""
    out, prev, cur, step = [], None, None, 0.0
    for v in np.asarray(V0_V, float):
        if cur is None:
            cur, step = v, (v if from_off else 0.0)
        elif v != cur:
            prev, cur = cur, v
            step = cur - prev
        out.append(step)
    return np.array(out)


def changed(df: pd.DataFrame, mode: str, kind: str, truth: dict) -> pd.DataFrame:
    """The frame of one split as the probe ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    first = out.groupby("run")["time_s"].transform("min")
    if mode == "truevolt" and kind == "setpoint_overshoot":
        actual = {r["run"]: r["V0_actual_V"] for r in truth["per_run"]}
        out["voltage_V"] = out["run"].map(actual).round(6)
    elif mode == "truevolt" and kind == "supply_current_limit":
        p, nominal, f = truth["parameters"], load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml"), 48500.0
        for run, g in out.groupby("run"):
            V0 = float(g["voltage_V"].iloc[0])
            V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, f, 25.0))
            R_eq = ninth.bus_resistance_ohm(nominal.driver.R_m_ohm, V0 / V_s)
            t = (g["time_s"] - g["time_s"].min()).to_numpy(float)
            out.loc[g.index, "voltage_V"] = np.round(V0 * ninth.bus_voltage_V(t, V_s, p["I_lim_A"], R_eq,
                                                                              p["C_b_F"]) / V_s, 4)
    elif mode == "runtime":
        out["time_in_run_s"] = np.round(out["time_s"] - first, 6)
    return out


def main(argv=None):
    args = be.probe_args(argv, __doc__, ninth.KINDS, MODES)
    src, dst = be.probe_copy(args, ninth.experiment)
    truth = json.loads((src / "rig_truth.json").read_text())
    if args.mode in ("step", "step0"):   # the session's order: the runs of both parts on one clock
        both = pd.concat([pd.read_csv(src / "train.csv"), pd.read_csv(src / "test.csv")]).sort_values("time_s")
        runs = both.groupby("run", sort=False)["voltage_V"].first()
        step = dict(zip(runs.index, setting_steps(runs.to_numpy(), args.mode == "step0")))
    for part in ("train", "test"):
        mode = "" if args.mode.startswith("step") else args.mode
        df = changed(pd.read_csv(src / f"{part}.csv"), mode, args.kind, truth)
        if args.mode.startswith("step"):
            df["voltage_step_V"] = df["run"].map(step)
        df.to_csv(dst / f"{part}.csv", index=False)
    c0 = time.process_time()
    res = close_loop(load_measurements(dst / "train.csv"), load_measurements(dst / "test.csv"),
                     **SETTINGS.get(args.mode, {}))
    cpu = time.process_time() - c0
    d = res.diagnosis
    b = res.before["test"]["free_run"]["nrmse"]
    a = res.after["test"]["free_run"]["nrmse"] if res.after is not None else b
    print(json.dumps({"kind": f"{args.kind}({args.mode})", "seed": args.seed, "traced": d["traced_to"][:2],
                      "added": [e["label"] for e in d["effects"]], "before": round(100 * b, 3),
                      "after": round(100 * a, 3), "traced_all": list(d["traced_to"]), "message": d["message"],
                      "refit_trials": [[{k: t.get(k) for k in ("label", "cv_gain", "folds_improved", "folds",
                                                                 "cv_gain_se_runs", "runs_improved", "runs")}
                                        for t in rnd] for rnd in d.get("refit_trials") or []],
                      "cpu_s": round(cpu, 1)}, default=str))


if __name__ == "__main__":
    main()
