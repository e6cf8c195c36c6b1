#!/usr/bin/env python
"""The eleventh audit's ``elastic_load_line 3`` baseline: the loop's Eq. 29 identification on its TRAIN against a
warm start from a neighbouring case's fit.

Fits, with the close loop's baseline settings (order 8, free-run criterion, common noise, ``fixed="recommended"``,
``noise_fit="alternate"``, coarse to fine): the case's TRAIN from the identifier's multistart (``n_starts=4``, seed
0: the loop's baseline), ``elastic_load_line 2``'s TRAIN the same way, and the case's TRAIN again warm-started from
that second fit (``n_starts=1``). Prints one JSON line per fit: its log-likelihood, its free-run nrmse on its own
TRAIN and the first two preload coefficients; and the CPU of the three (``time.process_time``).

Usage: python bench/blind_effects_eleventh_basin.py [--cache DIR] [--seed N --from-seed M]   (the cases are made
by ``bench/blind_effects_eleventh.py`` when absent from the cache).
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402
import blind_effects_eleventh as eleventh  # noqa: E402

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.data.measurements import load_measurements  # noqa: E402
from l1b2.ident.coarse import coarse_to_fine  # noqa: E402
from l1b2.ident.estimator import PredictorIdentifier  # noqa: E402


def identify(m, **kw):
    """Eq. 29 identified on ``m`` with the close loop's baseline settings (``kw``: starts, seed, init)."""
    est = PredictorIdentifier(order=8, criterion="free_run", noise="common", model="eq29", frequency="auto",
                              fixed="recommended", noise_fit="alternate", **kw)
    return coarse_to_fine(est, m, m.slider_mass_kg, np.array(m.mask))


def train_nrmse(est, m) -> float:
    """The free-run nrmse of ``est`` on ``m`` (its evaluation mask)."""
    mask = np.array(m.mask)
    v = m.df[dataio.SPEED].to_numpy(float)[mask]
    p = np.asarray(est.predict_free_run(m.df), float)[mask]
    return float(np.sqrt(np.sum((v - p) ** 2) / np.sum(v ** 2)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", default=be.default_cache())
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--from-seed", type=int, default=2)
    args = ap.parse_args(argv)
    kind = "elastic_load_line"
    data = {s: load_measurements(be.data_dir(kind, s, Path(args.cache), eleventh.experiment) / "train.csv")
            for s in (args.seed, args.from_seed)}
    c0 = time.process_time()
    fits = [(f"{kind} {args.seed}: multistart", args.seed, identify(data[args.seed], n_starts=4, seed=0))]
    other = identify(data[args.from_seed], n_starts=4, seed=0)
    fits.append((f"{kind} {args.from_seed}: multistart", args.from_seed, other))
    fits.append((f"{kind} {args.seed}: warm from {args.from_seed}'s fit", args.seed,
                 identify(data[args.seed], n_starts=1, seed=0, init=other.params_)))
    cpu = time.process_time() - c0
    for name, s, est in fits:
        print(json.dumps({"fit": name, "loglik": round(float(est.result_.loglik), 2),
                          "train_nrmse_pct": round(100 * train_nrmse(est, data[s]), 3),
                          "p_0_1": [float(x) for x in est.params_.p[:2]]}))
    print(json.dumps({"cpu_s": round(cpu, 1)}))


if __name__ == "__main__":
    main()
