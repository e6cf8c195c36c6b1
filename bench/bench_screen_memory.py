#!/usr/bin/env python
"""Benchmark: the linearised screen's peak memory and CPU on a fast log with many logged channels, the state before
decision 0143 and the current code side by side.

The data: the rig files of ``bench/bench_closeloop_scale.py`` (realistic motor, pulley_friction, the paper's plan;
by default 1 kHz with 20,000 TRAIN samples and 5 kHz with 100,000), each with ``--channels`` logged columns appended
that act on nothing (per-run values, step logs and slow drifts with sample noise, a fixed random stream): a rig that
logs a dozen conditions multiplies the candidates, and so the screen's arrays, by the channels' hypotheses.

Variants, each in a process of its own (its peak resident memory is the process's, ``ru_maxrss``):

* ``d0143``: the screen as before decision 0143: every candidate's force over every sample held at once, and the
  responses compared on every masked sample (``selection.screen_rows`` and the block size patched);
* ``current``: the package's: the forces integrated in blocks of ``selection.BLOCK_VALUES`` values, the responses
  compared on every ``q``-th sample of each run above 1 kHz.

Each child fits the Eq. 29 predictor once (a short search), builds the library on the frame and scores every
candidate once (:func:`l1b2.closeloop.selection.score_candidates`): the CPU of that call, the process's peak memory,
the number of candidates and the three best (label, linearised CV gain).

Usage: python bench/bench_screen_memory.py [--sizes 1000:20000,5000:100000] [--channels 12]
       [--variants d0143,current] [--cache DIR]
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def with_channels(folder: Path, n_channels: int) -> Path:
    """A copy of ``folder``'s train/test files with ``n_channels`` logged columns that act on nothing (made once)."""
    out = folder.with_name(f"{folder.name}_ch{n_channels}")
    if (out / "train.csv").exists():
        return out
    tr, te = pd.read_csv(folder / "train.csv"), pd.read_csv(folder / "test.csv")
    both = pd.concat([tr.assign(_f=0), te.assign(_f=1)]).sort_values("time_s", kind="stable")
    rng = np.random.default_rng(7)
    runs = both["run"].drop_duplicates().to_numpy()
    t = both["time_s"].to_numpy()
    for k in range(n_channels):
        kind = k % 3
        if kind == 0:     # a value per run
            both[f"aux{k}"] = both["run"].map(dict(zip(runs, rng.normal(10.0 * k, 1.0, len(runs))))) \
                + rng.normal(0, 0.01, len(both))
        elif kind == 1:   # a step log: a value held for blocks of runs
            block = 6 + k
            vals = np.repeat(rng.integers(0, 5, len(runs) // block + 1), block)[:len(runs)]
            both[f"aux{k}"] = both["run"].map(dict(zip(runs, vals.astype(float))))
        else:             # a slow drift over the session with sample noise
            knots = np.cumsum(rng.normal(0, 1, 40))
            both[f"aux{k}"] = np.interp(t, np.linspace(t.min(), t.max(), 40), knots) + rng.normal(0, 0.05, len(both))
    tmp = out.with_name(out.name + ".partial")
    tmp.mkdir(parents=True, exist_ok=True)
    for f, name in ((0, "train"), (1, "test")):
        both[both._f == f].drop(columns="_f").to_csv(tmp / f"{name}.csv", index=False)
        (tmp / f"{name}.json").write_text((folder / f"{name}.json").read_text())
    os.replace(tmp, out)
    return out


def child(variant: str, folder: Path) -> dict:
    """One variant's scoring in this process: CPU [s] of the scoring call, peak memory [MB], candidates, best."""
    from bench_closeloop_scale import scoring_setup
    from l1b2.closeloop import selection as sel
    if variant == "d0143":
        sel.screen_rows = lambda df, mask: np.flatnonzero(mask)
        sel.BLOCK_VALUES = 1 << 62
        blocked = sel.candidate_responses
        sel.candidate_responses = lambda *a, **k: blocked(*a, **{**k, "block_values": 1 << 62})
    m, est, v, r, pool = scoring_setup(folder)
    df, mask = m.df, np.array(m.mask)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    c0 = time.process_time()
    scores = sel.score_candidates(pool, r, df, mask, est.params_, m.slider_mass_kg, v_pred=v)
    cpu = time.process_time() - c0
    best = sorted(scores, key=lambda s: -s.cv_gain)[:3]
    return {"variant": variant, "n": m.n_samples, "candidates": len(pool), "scoring_cpu_s": cpu,
            "peak_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "peak_before_scoring_MB": before,
            "best": [(s.candidate.label, round(s.cv_gain, 4)) for s in best]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000:20000,5000:100000", help="RATE_HZ:TRAIN_SAMPLES,...")
    ap.add_argument("--channels", type=int, default=12)
    ap.add_argument("--variants", default="d0143,current")
    ap.add_argument("--cache", default=str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
                                           / "l1b2" / "bench_closeloop_scale"))
    ap.add_argument("--child", nargs=2, metavar=("VARIANT", "FOLDER"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child[0], Path(args.child[1]))))
        return
    from bench_closeloop_scale import rig_files
    names = [v for v in args.variants.split(",") if v]
    rows = []
    for rate, n in ((float(a), int(b)) for a, b in (x.split(":") for x in args.sizes.split(","))):
        folder = with_channels(rig_files(rate, n, Path(args.cache)), args.channels)
        for name in names:
            out = subprocess.run([sys.executable, __file__, "--child", name, str(folder)], check=True,
                                 capture_output=True, text=True).stdout
            row = {"rate_Hz": rate, **json.loads(out.strip().splitlines()[-1])}
            rows.append(row)
            print(json.dumps(row), flush=True)
    print(f"\n{'rate':>6s} {'TRAIN':>7s} {'cands':>6s} " + " ".join(f"{n + ' CPU [s]':>16s} {n + ' peak [MB]':>17s}"
                                                             for n in names))
    for rate in dict.fromkeys(r["rate_Hz"] for r in rows):
        rs = {r["variant"]: r for r in rows if r["rate_Hz"] == rate}
        first = next(iter(rs.values()))
        print(f"{rate:6g} {first['n']:7d} {first['candidates']:6d} "
              + " ".join(f"{rs[n]['scoring_cpu_s']:16.1f} {rs[n]['peak_MB']:17.0f}" for n in names))
        if len(names) == 2:
            a, b = rs[names[0]], rs[names[1]]
            print(f"  {names[1]} / {names[0]}: CPU x {b['scoring_cpu_s'] / a['scoring_cpu_s']:.2f}, peak memory x "
                  f"{b['peak_MB'] / a['peak_MB']:.2f}; best three the same: {a['best'] == b['best']}")


if __name__ == "__main__":
    main()
