#!/usr/bin/env python
"""The close loop on rig data recorded under protocols other than the paper's 72-run plan.

The world is the blind audits' realistic one (``bench/blind_effects.py``, ``tests/rigcache.world_plan``):
``system_models/realistic_motor.toml``, 1 mm/s white noise on the speed channel, a 2 % run-to-run scatter of the
contact's preload and friction coefficient, a 1 ms simulation step, the run order, the noise and the scatter from
``SEED``. The rig is the package's own (``l1b2.rig.experiment.run_experiment``, in-process engine, serial), and an
injection (``KIND``, one of ``l1b2.rig.experiment.INJECTIONS``) has its ranged parameters drawn from ``SEED``, as
``tests/realistic_cases.py`` makes its cases. ``KIND`` ``clean``: no injection.

Protocols (each a ``RigPlan`` of the world's noise; TEST: the runs at the held-out load magnitude, TRAIN the rest):

* ``paper`` -- the paper's plan for reference: V0 (220, 255, 290, 324) V x loads (-0.09 .. 0.09 kg, 9) x 2
  directions = 72 runs at 1 kHz; held out |load| 0.05 kg.
* ``five_volts`` -- V0 (200, 235, 270, 305, 340) V x the paper's loads x 2 = 90 runs; held out |load| 0.05 kg.
* ``few_loads`` -- the paper's V0 x loads (-0.08, -0.04, 0, 0.04, 0.08) kg x 2 = 40 runs; held out |load| 0.04 kg
  (the interior magnitude: the plan has no 0.05 kg load).
* ``repeats`` -- the paper's plan with every (V0, load) condition run twice in one session: the loads tuple given
  twice, so each condition appears twice among the shuffled conditions (each forward then backward), 144 runs
  on one clock, each with its own contact scatter and noise; held out |load| 0.05 kg (both repetitions).
* ``fast_daq`` -- the paper's plan sampled at 5 kHz. The rig samples every ``1 / (sample_rate x step)`` steps and
  refuses a step that does not divide the sampling period, so the step is 0.2 ms (the sampling period) instead of
  the world's 1 ms; held out |load| 0.05 kg.
* ``small`` -- V0 (220, 270, 324) V x loads (-0.09, -0.05, 0, 0.05, 0.09) kg x 2 = 30 runs; held out |load|
  0.05 kg (12 runs; TRAIN 18 runs at loads -0.09, 0, 0.09 kg).

The audit's injections (two, fixed before any run): ``pulley_friction`` (regressor ``load``) and
``drive_saturation`` (regressor ``voltage``); any injection of the rig is accepted on the command line.

Pass rules (``tests/realistic_cases.py``, decision 0113): ``clean`` -- TEST free-run nrmse after <= 1.02 x before
(what was added is reported); an injection -- its regressor (``Injection.regressor``) among the first two traced
and ``a^2 <= b0^2 + (b^2 - b0^2)/4`` with b, a the TEST free-run nrmse before and after the loop and b0 the clean
control's before at the same protocol and seed.

Usage: python bench/other_protocols.py PROTOCOL KIND SEED [--cache DIR] [--data-only] [--report FILE]
Prints one JSON line: protocol, kind, seed, the runs in TRAIN/TEST, the first two traced, every traced, the added
effects, TEST free-run nrmse before and after [%], the wanted regressor, the message, the CPU time of the close loop
(``time.process_time``) and of making the data (0 when cached).
"""
import argparse
import dataclasses
import json
import os
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from blind_effects import loop_row  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.data.measurements import load_measurements  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402
from l1b2.rig.experiment import INJECTIONS, PAPER_LOADS_KG, RigPlan, run_experiment, write_experiment  # noqa: E402

PAPER_V = (220.0, 255.0, 290.0, 324.0)
#: protocol -> (the plan's fields besides the world's, the held-out load magnitudes [kg])
PROTOCOLS = {
    "paper": ({}, (0.05,)),
    "five_volts": ({"voltages_V": (200.0, 235.0, 270.0, 305.0, 340.0)}, (0.05,)),
    "few_loads": ({"loads_kg": (-0.08, -0.04, 0.0, 0.04, 0.08)}, (0.04,)),
    "repeats": ({"loads_kg": PAPER_LOADS_KG + PAPER_LOADS_KG}, (0.05,)),
    "fast_daq": ({"sample_rate_Hz": 5000.0, "step_s": 2e-4}, (0.05,)),
    "small": ({"voltages_V": (220.0, 270.0, 324.0), "loads_kg": (-0.09, -0.05, 0.0, 0.05, 0.09)}, (0.05,)),
}
AUDITED = ("pulley_friction", "drive_saturation")


def plan_of(protocol: str, seed: int) -> RigPlan:
    """The protocol's plan in the realistic world (1 ms step unless the protocol sets one, noise and scatter)."""
    fields, _ = PROTOCOLS[protocol]
    base = RigPlan(step_s=1e-3, seed=seed, speed_noise_m_s=1e-3, run_scatter=0.02)
    return dataclasses.replace(base, **fields)


def data_dir(protocol: str, kind: str, seed: int, cache: Path) -> tuple[Path, float]:
    """``(folder, cpu_s)``: the cached experiment (made when absent; ``cpu_s`` 0 then) with its TRAIN/TEST split."""
    out = cache / f"{protocol}_{kind}_{seed}"
    if (out / "train.csv").exists():
        return out, 0.0
    c0 = time.process_time()
    plan = plan_of(protocol, seed)
    mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    injections = [] if kind == "clean" else [kind]
    df, truth = run_experiment(plan, mp, injections=injections, engine="inprocess", workers=1,
                               injection_seed=seed)
    truth["protocol"] = protocol
    tmp = out.with_name(out.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    write_experiment(df, tmp, mp, plan, truth, test_abs_loads=PROTOCOLS[protocol][1])
    os.replace(tmp, out)
    return out, time.process_time() - c0


def default_cache() -> str:
    return str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "l1b2" / "other_protocols")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("protocol", choices=tuple(PROTOCOLS))
    ap.add_argument("kind", choices=tuple(INJECTIONS) + ("clean",))
    ap.add_argument("seed", type=int)
    ap.add_argument("--cache", default=default_cache())
    ap.add_argument("--data-only", action="store_true", help="make (or find) the data and stop")
    ap.add_argument("--report", default="", help="write the close loop's whole result (report.json's content) here")
    args = ap.parse_args(argv)
    d, data_cpu = data_dir(args.protocol, args.kind, args.seed, Path(args.cache))
    if args.data_only:
        print(d)
        return
    want = None if args.kind == "clean" else INJECTIONS[args.kind].regressor
    row, res = loop_row(args.kind, args.seed, d, traced_all=lambda names, diag: list(diag["traced_to"]))
    runs = {part: int(load_measurements(d / f"{part}.csv").df[dataio.RUN].nunique()) for part in ("train", "test")}
    out = {"protocol": args.protocol, **row, "want": want, "runs": runs, "data_cpu_s": round(data_cpu, 1)}
    print(json.dumps(out))
    if args.report:
        Path(args.report).write_text(json.dumps(res.to_dict(), default=str))


if __name__ == "__main__":
    main()
