#!/usr/bin/env python
"""Peak memory and time of loading a large valid measured-data CSV (issue 30: 200 MB took 2.9 GB and 127 s).

Writes a valid file of about ``--mb`` megabytes (default 200: ~2 M rows) by
repeating simulated traverses of the Eq. 29 predictor (new run ids, the
clock running on), then loads it with ``l1b2.data.measurements.load_measurements``
in a fresh process and prints, side by side: the file size, the process's
peak resident memory (``ru_maxrss``), the same before loading (Python,
numpy, pandas and l1b2 imported), the growth caused by loading and its ratio
to the file size (target: at most 3), and the wall time.

Usage::

    python bench/bench_load_memory.py [--mb 200] [--file PATH] [--keep]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHILD = r"""
import json, resource, sys, time
import numpy, pandas
from l1b2.data.measurements import load_measurements
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
t0 = time.perf_counter()
m = load_measurements(sys.argv[1], slider_mass_kg=0.1)
dt = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps({"rows": len(m.df), "runs": len(m.runs), "base": base, "peak": peak, "seconds": dt}))
"""


def write_file(path: Path, megabytes: float) -> None:
    import numpy as np

    from l1b2.predictor.model import example_params
    from l1b2.predictor.simulate import design_grid, simulate_dataset
    block = simulate_dataset(example_params(3), design_grid(voltages=(220.0, 324.0), loads=(-0.05, 0.0, 0.05)), 0.1,
                             noise_std=1e-4, seed=0)
    block = block.assign(frequency_Hz=48500.0, temperature_C=25.0)
    n_runs = int(block["run"].nunique())
    span = float(block["time_s"].iloc[-1] - block["time_s"].iloc[0]) + 1.0
    text0 = block.to_csv(index=False, lineterminator="\n", float_format="%.9g")
    per_block = len(text0) - text0.index("\n") - 1
    reps = max(1, int(megabytes * 1e6 / per_block))
    with open(path, "w") as fh:
        fh.write(text0[: text0.index("\n") + 1])
        for k in range(reps):
            b = block.assign(time_s=block["time_s"] + k * span, run=block["run"].astype(int) + k * n_runs)
            fh.write(b.to_csv(index=False, header=False, lineterminator="\n", float_format="%.9g"))
    path.with_suffix(".json").write_text(json.dumps({"slider_mass_kg": 0.1}))
    del np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, default=200.0, help="size of the generated file [MB]")
    ap.add_argument("--file", type=Path, help="load this file instead of generating one")
    ap.add_argument("--keep", action="store_true", help="keep the generated file")
    args = ap.parse_args(argv)
    tmp = None
    path = args.file
    if path is None:
        tmp = tempfile.mkdtemp(prefix="l1b2_bench_mem_")
        path = Path(tmp) / "big.csv"
        t0 = time.perf_counter()
        write_file(path, args.mb)
        print(f"wrote {path} in {time.perf_counter() - t0:.0f} s")
    size = path.stat().st_size
    proc = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True)
    if proc.returncode != 0:
        print(proc.stderr[-3000:], file=sys.stderr)
        return 1
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    grow = r["peak"] - r["base"]
    print(f"{'file':>10s} {'rows':>9s} {'peak RSS':>9s} {'before':>8s} {'growth':>8s} {'growth/file':>11s} "
          f"{'peak/file':>9s} {'time':>7s}")
    print(f"{size / 1e6:8.0f}MB {r['rows']:9d} {r['peak'] / 1e6:7.0f}MB {r['base'] / 1e6:6.0f}MB {grow / 1e6:6.0f}MB "
          f"{grow / size:11.2f} {r['peak'] / size:9.2f} {r['seconds']:6.1f}s")
    if tmp and not args.keep:
        import shutil
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
