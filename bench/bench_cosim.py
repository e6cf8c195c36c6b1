#!/usr/bin/env python
"""Benchmark: FMU co-simulation vs in-process reference, and a full rig experiment.

Prints, side by side in one run:
* wall time per simulated second for the four-FMU co-simulation (fmpy master,
  SSD wiring) and for the in-process reference (same blocks stepped one after
  the other, no FMI: ``InProcessMotor(fused=False)``), and their ratio
  (target: FMU overhead within 3x of in-process); beside them the in-process
  engine's default, the fused coupled step (one compiled call per step);
* the wall time of the full 72-run paper experiment on the virtual rig
  through the FMUs with 2 worker processes (target: under 5 minutes on 2 cores).

Usage: python bench/bench_cosim.py [--quick]   (--quick skips the 72-run experiment)
"""
import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.cosim.engine import InProcessMotor  # noqa: E402
from l1b2.cosim.master import CoSimulation  # noqa: E402
from l1b2.fmi.build import build_subsystem_fmus  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.params import load_motor  # noqa: E402
from l1b2.rig.experiment import RigPlan, run_experiment  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="skip the 72-run rig experiment")
    ap.add_argument("--sim-time", type=float, default=0.5, help="simulated seconds per engine")
    ap.add_argument("--fmu-dir", type=Path, default=Path("dist/fmus"))
    args = ap.parse_args(argv)
    mp = load_motor()
    build_subsystem_fmus(args.fmu_dir, mp)
    V_s = float(drv.supply_for_voltage_V(mp.driver, 324.0, 1.0, 48500.0, 25.0))
    inputs = dict(V_s=V_s, duty=1.0, f_s=48500.0, T=25.0, direction=1.0, m_load=0.0)
    # end stops far away so both engines simulate the full time
    wide = {"Slider.s_min_m": -1.0, "Slider.s_max_m": 1.0}
    mp_wide = mp.replace(slider__s_min_m=-1.0, slider__s_max_m=1.0)
    rows = []
    for step in (2e-4, 1e-3):
        t0 = time.perf_counter()
        with CoSimulation(fmu_dir=args.fmu_dir, step_s=step, parameters=wide) as cs:
            cs.run(args.sim_time, inputs, record=["Slider.v"])
        t_fmu = (time.perf_counter() - t0) / args.sim_time
        t_in = {}
        for fused in (False, None):
            m = InProcessMotor(mp_wide, h_s=step, fused=fused)
            t0 = time.perf_counter()
            m.initialize(**inputs)
            m.run(args.sim_time, record=("Slider.v",))
            t_in[fused] = (time.perf_counter() - t0) / args.sim_time
        rows.append((step, t_fmu, t_in[False], t_in[None]))
    print("co-simulation wall time per simulated second (reference motor, 324 V, no load)")
    print(f"{'step [ms]':>10} {'FMU [s/s]':>11} {'in-process [s/s]':>17} {'FMU / in-process':>17}  target <= 3"
          f"   {'fused [s/s]':>12}")
    for step, t_fmu, t_in, t_fused in rows:
        print(f"{step * 1e3:10.2f} {t_fmu:11.3f} {t_in:17.3f} {t_fmu / t_in:17.2f}  "
              f"{'ok' if t_fmu / t_in <= 3 else 'MISSED':>11}   {t_fused:12.3f}")
    if not args.quick:
        plan = RigPlan()
        t0 = time.perf_counter()
        df, _ = run_experiment(plan, mp, engine="fmu", jobs=2, fmu_dir=args.fmu_dir)
        t_rig = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_experiment(plan, mp, engine="inprocess", jobs=2)
        t_rig_in = time.perf_counter() - t0
        print(f"\nfull paper experiment: {df['run'].nunique()} runs, {len(df)} samples, 2 worker processes")
        print(f"{'engine':>12} {'wall [s]':>9}  target")
        print(f"{'FMU':>12} {t_rig:9.1f}  < 300 s {'ok' if t_rig < 300 else 'MISSED'}")
        print(f"{'in-process':>12} {t_rig_in:9.1f}  (ratio FMU / in-process {t_rig / t_rig_in:.2f})")


if __name__ == "__main__":
    main()
