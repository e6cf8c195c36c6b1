#!/usr/bin/env python
"""Probes of the seventeenth blind audit's misses (``bench/blind_effects_seventeenth.py``): the close loop on a
changed copy of a case's files, one change per mode:

* ``bow_truth`` -- a column ``bow_preload_N`` added: the bow's added preload at each sample, ``k_p b (1 - (s /
  L)^2)`` (the truth's ``b`` of the run, ``s`` the logged position, the motor's ``k_p`` and half length ``L``; 0.1 mN
  resolution), the channel x position product that acts, beside the setting ``bar_bow_um``.
* ``cum_load`` -- a column ``cum_load_kg`` added: the sum of the signed loads of the runs before (0 at the first
  run; one value per run), the load's history that the cage's offset integrates, without its clip at the stop.
* ``power_only`` -- the decoy's ``drive_energy_J`` replaced by the analyser's power, ``P_i + P_a (V0 / 324 V)^2`` [W]
  (the truth's values, 0.001 W resolution, constant in a run): the same meter's reading without its integration
  over the run's time.

Usage: python bench/blind_effects_seventeenth_probe.py KIND SEED MODE [--cache DIR] [--out DIR]. Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all``) and the evidence on the probe's column.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_seventeenth as seventeenth  # noqa: E402

MODES = ("bow_truth", "cum_load", "power_only")
COLUMN = {"bow_truth": "bow_preload", "cum_load": "cum_load", "power_only": "drive_energy"}
K_P_N_PER_M = 7.5e4       # the realistic motor's preload spring rate
HALF_LENGTH_M = 0.025     # the realistic motor's bar half length


def changed(df, mode: str, truth: dict):
    """The part ``df`` as ``mode`` changes it (``truth``: the case's ``rig_truth.json``)."""
    out = df.copy()
    p = truth["parameters"]
    if mode == "bow_truth":
        b = out["run"].map(lambda k: p["b_um"][int(k) - 1] * 1e-6)
        s = out["position_m"]
        out["bow_preload_N"] = np.round(K_P_N_PER_M * b * (1.0 - (s / HALF_LENGTH_M) ** 2), 4)
    elif mode == "cum_load":
        # the plan's loads in run order (the seed's plan; the part's own runs are checked against it)
        plan_loads = [c[1] for c in be.plan_runs(be.plan_of(int(truth["plan"]["seed"])))]
        for k, v in df.groupby("run")["load_kg"].first().items():
            assert abs(float(v) - plan_loads[int(k) - 1]) < 1e-12, (k, v)
        cum = np.concatenate([[0.0], np.cumsum(plan_loads)[:-1]])
        out["cum_load_kg"] = out["run"].map(lambda k: round(float(cum[int(k) - 1]), 3))
    elif mode == "power_only":
        V = out["voltage_V"].astype(float)
        out["drive_energy_J"] = np.round(p["P_i_W"] + p["P_a_W"] * (V / seventeenth.V0_POWER) ** 2, 3)
    return out


def main(argv=None):
    be.probe_truth_main(argv, __doc__, seventeenth, MODES, changed, COLUMN, {})


if __name__ == "__main__":
    main()
