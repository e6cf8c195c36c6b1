#!/usr/bin/env python
"""Benchmark: a Monte-Carlo design study on the Dask engine, 1 vs 2 workers.

The shipped study (``system_models/studies/tolerances_220V.toml``: 5 toleranced
parameters, V0 = 220 V, 0.05 kg, the full 42 mm stroke at a 1 ms step) with
200 draws at one operating point, in-process engine, run on a LocalCluster
of 1 and of 2 worker processes. Prints side by side:

* wall time with and without the cluster's start-up, and the parallel
  efficiency T1 / (2 T2) of the study itself (target >= 80 %);
* the cost of one traverse (worker-seconds per traverse) for the in-process
  engine and, on a few draws run serially, for the FMU engine.

The Parquet of both runs must be identical (same seed, any number of workers).

Usage: python bench/bench_sweep.py [--draws 200] [--fmu-draws 10]
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

import pandas as pd  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR  # noqa: E402
from l1b2.workflows import run_sweep  # noqa: E402

SPEC = SYSTEM_MODELS_DIR / "studies" / "tolerances_220V.toml"


def _spec(tmp: Path, draws: int, engine: str = "inprocess") -> Path:
    text = SPEC.read_text().replace("draws = 50", f"draws = {draws}").replace("chunk_size = 5", "chunk_size = 10")
    text = text.replace('engine = "inprocess"', f'engine = "{engine}"')
    p = tmp / f"study_{engine}_{draws}.toml"
    p.write_text(text)
    return p


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--draws", type=int, default=200)
    ap.add_argument("--fmu-draws", type=int, default=10, help="draws for the FMU engine's cost (0: skip)")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="l1b2_bench_sweep_"))
    spec = _spec(tmp, args.draws)
    runs = {}
    for n in (1, 2):
        t0 = time.perf_counter()
        res = run_sweep(spec, tmp / f"w{n}", workers=n, progress=False, plots_on=False)
        runs[n] = (time.perf_counter() - t0, res.info, pd.read_parquet(tmp / f"w{n}" / "samples.parquet"))
    same = runs[1][2].equals(runs[2][2])
    t1 = runs[1][1]["wall_time_s"] - runs[1][1]["startup_s"]
    t2 = runs[2][1]["wall_time_s"] - runs[2][1]["startup_s"]
    eff = t1 / (2 * t2)
    print(f"Monte-Carlo study: {args.draws} draws at one operating point (220 V, 0.05 kg, 42 mm stroke, 1 ms step), "
          f"in-process engine, LocalCluster of single-thread worker processes")
    print(f"{'workers':>8} {'total [s]':>10} {'start-up [s]':>13} {'study [s]':>10} {'worker-s / traverse':>20}")
    for n in (1, 2):
        total, info, _ = runs[n]
        study = info["wall_time_s"] - info["startup_s"]
        print(f"{n:>8} {total:10.1f} {info['startup_s']:13.1f} {study:10.1f} {study * n / args.draws:20.3f}")
    print(f"parallel efficiency of the study T1 / (2 T2): {eff:.0%}  target >= 80 % {'ok' if eff >= 0.8 else 'MISSED'}")
    print(f"with the cluster start-up included: {runs[1][0] / (2 * runs[2][0]):.0%}")
    print(f"Parquet identical for 1 and 2 workers: {same}")
    print(f"cost of one traverse, in-process engine: {t1 / args.draws:.3f} s")
    if args.fmu_draws:
        fspec = _spec(tmp, args.fmu_draws, "fmu")
        res = run_sweep(fspec, tmp / "fmu", workers=0, progress=False, plots_on=False)  # FMUs built/cached first
        t_fmu = res.info["wall_time_s"] / args.fmu_draws
        print(f"cost of one traverse, FMU engine (serial, {args.fmu_draws} draws): {t_fmu:.3f} s "
              f"({t_fmu / (t1 / args.draws):.2f} x in-process)")


if __name__ == "__main__":
    main()
