#!/usr/bin/env python
"""Two effects at once, one of them a sensor stage: the eighth audit's position-sensor cyclic error
(``bench/blind_effects_eighth.py``'s law, drawn at SEED) added to an audit's experiment of another kind.

The base experiment is the cached (or newly made) audit file of ``BASE`` at ``SEED``: ``usb_timestamps`` (the seventh
audit's uneven arrival stamps, a second sensor stage), ``payload_swap`` (the second audit's logged payload, a force
effect), ``oil_viscosity_cause`` (the fourth audit's bar temperature), or ``clean``. In each run the logged position
gets ``e(s)`` (two harmonics of the scale's pitch), re-rounded to the encoder's resolution, and the speed column is
re-derived from it over the run's logged stamps (``numpy.gradient``, as the DAQ derives it), keeping the file's own
speed noise. The close loop then runs on TRAIN and TEST as every audit's does and one JSON row is printed
(``bench/blind_effects.py``'s fields, plus ``traced_all``).

Usage: python bench/sensor_stages_in_series.py BASE SEED [--cache DIR]
"""
import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)
import blind_effects_eighth as b8  # noqa: E402
import blind_effects_fourth as b4  # noqa: E402
import blind_effects_more as b2  # noqa: E402
import blind_effects_seventh as b7  # noqa: E402

BASES = {"usb_timestamps": b7.experiment, "payload_swap": b2.experiment, "oil_viscosity_cause": b4.experiment,
         "clean": None}
RESOLUTION_M = 5e-8   # the rig plan's encoder resolution (RigPlan.encoder_resolution_m)


def with_cyclic_error(df: pd.DataFrame, p: dict) -> pd.DataFrame:
    """A copy of ``df`` whose positions carry the cyclic error of the drawn ``p`` and whose speed is re-derived from
    them per run over the logged stamps, the original speed noise (speed minus the position's derivative) kept."""
    out = df.copy()
    for _, g in df.groupby("run", sort=False):
        t, s = g["time_s"].to_numpy(float), g["position_m"].to_numpy(float)
        noise = g["speed_m_s"].to_numpy(float) - np.gradient(s, t)
        s2 = s + b8.cyclic_error_m(s, p["P_m"], p["A1_m"], p["A2_m"], p["phi1"], p["phi2"])
        s2 = np.round(np.round(s2 / RESOLUTION_M) * RESOLUTION_M, 12)
        out.loc[g.index, "position_m"] = s2
        out.loc[g.index, "speed_m_s"] = np.round(np.gradient(s2, t) + noise, 9)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("base", choices=tuple(BASES))
    ap.add_argument("seed", type=int)
    ap.add_argument("--cache", default=be.default_cache())
    args = ap.parse_args(argv)
    cache = Path(args.cache)
    src = be.data_dir(args.base, args.seed, cache, BASES[args.base])
    dst = cache / f"{args.base}+encoder_cyclic_error_{args.seed}"
    if not (dst / "train.csv").exists():
        p = b8.draw("encoder_cyclic_error", args.seed, 72)
        tmp = dst.with_name(dst.name + ".partial")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(src, tmp)
        for part in ("train", "test"):
            with_cyclic_error(pd.read_csv(src / f"{part}.csv"), p).to_csv(tmp / f"{part}.csv", index=False)
        shutil.rmtree(dst, ignore_errors=True)
        tmp.rename(dst)
    row, res = be.loop_row(f"{args.base}+encoder_cyclic_error", args.seed, dst)
    row["traced_all"] = res.diagnosis["traced_to"]
    print(json.dumps(row))


if __name__ == "__main__":
    main()
