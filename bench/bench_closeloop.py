#!/usr/bin/env python
"""Benchmark: `l1b2 close-loop` (iterative, cross-validated refits) on a TRAIN file.

Default (issue 11): the paper's 72-run protocol on the realistic motor (~25 000
TRAIN samples), target under 3 minutes on 2 cores. ``--large``: the former
enlarged experiment (9 voltage levels x 9 loads x 2 directions, encoder
sampled at 2 kHz, ~50 000 samples) on the reference motor. One injected effect; the
close-the-loop job (:func:`l1b2.workflows.run_close_loop`, what `l1b2
close-loop` runs: load, fit, plots, report files) is then timed end to end,
printing each stage's share side by side with the whole.

``--train-samples N``: keep only the first TRAIN runs in rig order (the
order of (voltage, load) conditions is shuffled, so these are a random subset
of the conditions) until TRAIN has at least N samples; TEST is kept whole.
The issue's figure is ``--train-samples 20000``.

The cross-validated refits run on a local Dask cluster of ``--workers``
processes (default 2, the machine's cores; what `l1b2 close-loop` does by
default); ``--workers 0`` runs everything in this process.

Usage: python bench/bench_closeloop.py [--effect pulley_friction] [--train-samples 20000] [--workers N]
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402
from l1b2.rig.experiment import RigPlan, run_experiment, write_experiment  # noqa: E402
from l1b2.workflows import run_close_loop  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--effect", default="pulley_friction")
    ap.add_argument("--large", action="store_true")
    ap.add_argument("--train-samples", type=int, default=None, help="cut TRAIN to whole runs totalling >= N samples")
    ap.add_argument("--noise-fit", choices=("alternate", "profile"), default="alternate",
                    help="the baseline identification's search (CloseLoop(noise_fit=...))")
    ap.add_argument("--workers", type=int, default=2,
                    help="local Dask worker processes for the cross-validated refits (0 or 1: in this process)")
    args = ap.parse_args(argv)
    if args.large:
        mp = load_motor()
        plan = RigPlan(voltages_V=tuple(float(v) for v in np.linspace(220.0, 324.0, 9)), sample_rate_Hz=2000.0,
                       step_s=5e-4)
    else:
        mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
        plan = RigPlan(step_s=1e-3)
    target = 120.0 if args.large else 180.0
    t0 = time.perf_counter()
    df, truth = run_experiment(plan, mp, injections=[args.effect], engine="inprocess", jobs=2, injection_seed=0)
    t_rig = time.perf_counter() - t0
    if args.train_samples:
        df = _cut_train(df, args.train_samples)
    with tempfile.TemporaryDirectory() as td:
        write_experiment(df, td, mp, plan, truth)
        n_train = dataio.load_measurements(Path(td) / "train.csv").n_samples
        stages = {}
        last = [time.perf_counter()]

        def progress(msg):
            now = time.perf_counter()
            stages[msg] = now
            last[0] = now
        t0 = time.perf_counter()
        result = run_close_loop(Path(td) / "train.csv", Path(td) / "test.csv", Path(td) / "report",
                                progress=progress, noise_fit=args.noise_fit, workers=args.workers)
        t_total = time.perf_counter() - t0
    print(f"rig data: {len(df)} samples ({n_train} in TRAIN), generated in {t_rig:.1f} s (not part of the target)")
    print(f"diagnosis: {result.diagnosis['message']}")
    print(result.rounds_table())
    print(result.before_after_table())
    marks = sorted(stages.items(), key=lambda kv: kv[1]) + [("end", t0 + t_total)]
    print(f"\n{'stage':55s} {'wall [s]':>9s} {'share':>7s}")
    for (name, start), (_, end) in zip(marks[:-1], marks[1:]):
        print(f"{name:55s} {end - start:9.1f} {100 * (end - start) / t_total:6.0f}%")
    print(f"{'close-loop total':55s} {t_total:9.1f}   target < {target:.0f} s {'ok' if t_total < target else 'MISSED'}")


def _cut_train(df, n_samples: int, test_abs_load: float = 0.05):
    """``df`` with only the first TRAIN runs (rig order) that reach ``n_samples`` samples; TEST runs all kept."""
    is_test = np.isclose(np.abs(df[dataio.LOAD].to_numpy(float)), test_abs_load, atol=1e-9)
    keep, total = set(), 0
    for run, size in df[~is_test].groupby(dataio.RUN, sort=False).size().items():
        if total >= n_samples:
            break
        keep.add(run)
        total += int(size)
    return df[is_test | df[dataio.RUN].isin(keep).to_numpy()].reset_index(drop=True)


if __name__ == "__main__":
    main()
