#!/usr/bin/env python
"""One close-the-loop case of the realistic world, as the slow tests run it; prints what a closing note needs.

The data: the virtual rig (in-process engine, 1 ms step) on the realistic
motor (``system_models/realistic_motor.toml``) with the given injected
effects and seed (``RigPlan(step_s=1e-3, seed=SEED)``, ``injection_seed=SEED``:
the data of ``tests/test_closeloop_realistic.py``), made once and cached in
``--cache``. Then :func:`l1b2.closeloop.loop.close_loop` with the given
settings; printed: wall time, ``traced_to``, the free-run nrmse of TRAIN and
TEST after each round, and every cross-validated trial.

Usage: python bench/realistic_case.py EFFECTS SEED [--settings JSON] [--cache DIR] [--workers N]
       EFFECTS: clean, one effect, or effects joined by + (e.g. direction_asymmetry+thermal_drift)
Example: python bench/realistic_case.py thermal_drift 4 --settings '{"noise_fit": "profile"}'
"""
import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.closeloop.loop import close_loop  # noqa: E402
from l1b2.cluster import optional_client  # noqa: E402
from l1b2.data.measurements import load_measurements  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402
from l1b2.rig.experiment import RigPlan, run_experiment, write_experiment  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("effects")
    ap.add_argument("seed", type=int)
    ap.add_argument("--settings", default="{}", help="CloseLoop settings as JSON, e.g. '{\"screen_alpha\": 0.01}'")
    ap.add_argument("--cache", default=str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
                                           / "l1b2" / "realistic_cases"))
    ap.add_argument("--workers", type=int, default=0,
                    help="local Dask worker processes for the cross-validated refits (0: in this process, as the "
                         "tests run)")
    args = ap.parse_args(argv)
    effects = [e for e in args.effects.split("+") if e and e != "clean"]
    settings = json.loads(args.settings)
    out = Path(args.cache) / f"{args.effects}_{args.seed}"
    if not (out / "train.csv").exists():
        plan = RigPlan(step_s=1e-3, seed=args.seed)
        mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
        df, truth = run_experiment(plan, mp, injections=effects, engine="inprocess", workers=2,
                                   injection_seed=args.seed)
        tmp = out.with_name(out.name + ".partial")   # whole or nothing
        shutil.rmtree(tmp, ignore_errors=True)
        write_experiment(df, tmp, mp, plan, truth)
        os.replace(tmp, out)
    t = time.perf_counter()
    with optional_client(args.workers, serial_up_to=1) as client:
        res = close_loop(load_measurements(out / "train.csv"), load_measurements(out / "test.csv"), client=client,
                         **settings)
    d = res.diagnosis
    print(f"case {args.effects} seed {args.seed} settings {settings}: {time.perf_counter() - t:.0f} s")
    print(f"traced_to {d['traced_to']}: {d['message']}")
    for r in res.rounds:
        m = r["metrics"]
        print(f"  round {r['round']} {r.get('added') or 'baseline':45s} free-run nrmse TRAIN "
              f"{100 * m['train']['free_run']['nrmse']:.2f} %  TEST {100 * m['test']['free_run']['nrmse']:.2f} %")
    for i, rnd in enumerate(d["refit_trials"], start=1):
        for tr in rnd:
            print(f"  trial round {i}: {tr.get('label')}: CV nrmse {100 * tr['cv_free_run_nrmse_current']:.2f} -> "
                  f"{100 * tr['cv_free_run_nrmse_refit']:.2f} %, gain {tr['cv_gain']:.3f}, "
                  f"folds improved {tr['folds_improved']}")


if __name__ == "__main__":
    main()
