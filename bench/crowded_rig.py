#!/usr/bin/env python
"""A crowded rig: an audit case's files with ``N`` bystander channels added, and the close loop on them.

A real rig logs what its engineers chose, many channels that act on nothing. Each bystander is a logged column
``bystander<j>_mV`` (j = 1 ... N), one value per run, log-uniform over two decades (1-100 mV) from the stream
``[seed, 231, j]`` and constant within the run: a run setting that spans decades, so the loop derives its logarithm
and its lags as for any such channel. It acts on nothing. The case's own files (TRAIN, TEST, truth) are otherwise
unchanged: the row answers whether the case's cause is still traced when the rig logs more.

Usage: python bench/crowded_rig.py AUDIT KIND SEED N [--cache DIR] [--out DIR] [--report FILE]   (AUDIT: a
``bench`` module with an ``experiment(kind, seed)``, e.g. ``blind_effects_twentieth``). Prints the row of
``bench/blind_effects.py`` (its ``loop_row``, with ``traced_all`` and ``bystanders_traced``: the bystanders among
every traced regressor); ``--report``: the loop's whole result, as the audits' ``--report`` writes it.
"""
import argparse
import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

PREFIX = "bystander"
UNIT = "_mV"
RANGE_MV = (1.0, 100.0)


def bystander_values(seed: int, j: int, n_runs: int) -> np.ndarray:
    """Bystander ``j``'s value per run 1 ... ``n_runs`` [mV]: log-uniform over :data:`RANGE_MV`, stream
    ``[seed, 231, j]``."""
    rng = np.random.default_rng([seed, 231, j])
    lo, hi = np.log(RANGE_MV[0]), np.log(RANGE_MV[1])
    return np.round(np.exp(rng.uniform(lo, hi, size=n_runs)), 3)


def crowded(df: pd.DataFrame, seed: int, n: int, n_runs: int) -> pd.DataFrame:
    """The part ``df`` with bystanders 1 ... ``n`` appended (each run's value from :func:`bystander_values`)."""
    out = df.copy()
    runs = out["run"].astype(int).to_numpy()
    for j in range(1, n + 1):
        out[f"{PREFIX}{j}{UNIT}"] = bystander_values(seed, j, n_runs)[runs - 1]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("audit")
    ap.add_argument("kind")
    ap.add_argument("seed", type=int)
    ap.add_argument("n", type=int)
    ap.add_argument("--cache", default=be.default_cache())
    ap.add_argument("--out", default="")
    be.report_option(ap)
    args = ap.parse_args(argv)
    audit = importlib.import_module(args.audit)
    src, dst = be.probe_copy(args, audit.experiment)
    parts = {p: pd.read_csv(src / f"{p}.csv") for p in ("train", "test")}
    n_runs = int(max(df["run"].max() for df in parts.values()))
    for p, df in parts.items():
        crowded(df, args.seed, args.n, n_runs).to_csv(dst / f"{p}.csv", index=False)
    row, res = be.loop_row(f"{args.kind}(+{args.n})", args.seed, dst,
                         traced_all=lambda names, diag: list(diag["traced_to"]),
                         bystanders_traced=lambda names, diag: [t for t in diag["traced_to"] if PREFIX in str(t)])
    print(json.dumps(row))
    be.write_report(args.report, res)


if __name__ == "__main__":
    main()
