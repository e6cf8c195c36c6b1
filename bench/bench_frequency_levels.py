"""The identification's clustered interval of f_b0 on a rig plan with few drive-frequency levels.

Usage: python bench/bench_frequency_levels.py LEVELS SEED   (LEVELS: 2, 3, 4 or 5)

The realistic world, the drive-frequency study's fit (``l1b2.study.recovery``: the B2 resonance drawn per seed,
no injection, +-50 Hz per-run jitter), but the rig's frequencies are ``PLANS[LEVELS]``. Prints one JSON line:
the injected and estimated f_b0, the model-based se, the record's clustered interval (``clustered``), the
linear interval ``f_b0 +- t se`` of the same se and t for comparison, which covers, and the CPU time. When the
record withholds the number (too few levels, dof, or "not identified"), ``withheld_ci95`` is the log interval it
would have given and ``covered_withheld`` whether that covers.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace

import numpy as np
from scipy import stats

from l1b2.ident.frequency import log_interval
from l1b2.study.recovery import TARGETS, FitSettings, fit_family
from l1b2.study.world import World, world_data

#: the rig's drive frequencies [Hz] by number of levels (the study's five, and two to four over the same span)
PLANS = {2: (48000.0, 49000.0), 3: (48000.0, 48500.0, 49000.0), 4: (48000.0, 48333.3, 48666.7, 49000.0),
         5: (48000.0, 48250.0, 48500.0, 48750.0, 49000.0)}


def main(levels: int, seed: int) -> dict:
    t0 = time.process_time()
    target = TARGETS["drive_frequency"]
    truth = target.draw(seed)
    world = replace(World(), frequencies_Hz=PLANS[levels], frequency_jitter_Hz=50.0)
    train, _, _ = world_data(world, seed, (), {target.rig_parameter: truth})
    est, _ = fit_family(train, "", FitSettings())
    rec = est.result_.frequency
    f, c = rec["response"]["f_b0_Hz"], rec.get("clustered") or {}
    se_ar1 = (rec.get("stderr") or {}).get("f_b0_Hz")
    row = {"plan_levels": levels, "seed": seed, "injected": truth, "estimate": f, "se_ar1": se_ar1,
           "covered_ar1": None if se_ar1 is None else bool(abs(f - truth) <= 1.959964 * se_ar1),
           "at_bound": rec.get("at_bound"), "clustered": c}
    if c.get("available"):
        lo, hi = c["ci95_Hz"]
        row["covered_log"] = bool(lo <= truth <= hi)
        row["linear_ci95"] = [f - c["t"] * c["stderr_Hz"], f + c["t"] * c["stderr_Hz"]]
        row["covered_linear"] = bool(row["linear_ci95"][0] <= truth <= row["linear_ci95"][1])
    elif c.get("stderr_Hz") and c.get("dof"):
        # the interval the record withholds (too few levels, or not identified), for the record's tables only
        t = float(stats.t.ppf(0.975, c["dof"]))
        with np.errstate(over="ignore"):
            row["withheld_ci95"] = [float(x) for x in log_interval(f, c["stderr_Hz"], t)]
        row["covered_withheld"] = bool(row["withheld_ci95"][0] <= truth <= row["withheld_ci95"][1])
    row["cpu_s"] = round(time.process_time() - t0, 1)
    return row


if __name__ == "__main__":
    row = main(int(sys.argv[1]), int(sys.argv[2]))
    print(json.dumps(row, default=lambda x: float(x) if np.isscalar(x) else str(x)))
