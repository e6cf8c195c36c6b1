#!/usr/bin/env python
"""Benchmark: the paper's 72-run experiment through the four FMUs, with the FMU instances reused.

Prints, side by side in one run:

* the whole experiment (72 traverses of the reference motor, the rig's plan
  and run order) through the four subsystem FMUs on ``--jobs`` worker
  processes, each worker keeping one :class:`l1b2.cosim.master.CoSimulation`
  with ``keep_instances=True`` (SSD, SSV and model descriptions read once,
  FMUs instantiated once, ``fmi2Reset`` between runs): wall time (target
  < 15 s on 2 cores), CPU time of all processes, simulated time and the
  resulting real-time factor;
* on the first ``--compare`` runs, the cost per run the way
  ``l1b2.rig.experiment.simulate_run`` runs them (a fresh ``CoSimulation``
  per run: SSD and model descriptions parsed, FMUs instantiated, every
  parameter set) against the kept instances, in one process, alternating,
  with the largest difference of the recorded speeds (must be 0: same
  arithmetic).

Usage: python bench/bench_rig.py [--jobs N] [--compare K]
"""
import argparse
import multiprocessing as mproc
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.cosim.master import CoSimulation  # noqa: E402
from l1b2.cosim.ssp import COMPONENT_PARAMS  # noqa: E402
from l1b2.fmi.cache import ensure_fmus  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.params import load_motor  # noqa: E402
from l1b2.rig.experiment import RigPlan, RunSpec, plan_runs, simulate_run  # noqa: E402

RECORD = ["Slider.s", "Slider.v", "Stator.v_tip", "Stator.T_stator", "Slider.at_stop"]
TARGET_S = 15.0

_WORKER = {}


def _specs(plan):
    return [RunSpec(k + 1, V, L, d) for k, (V, L, d) in enumerate(plan_runs(plan))]


def _kept_cosim(mp, plan, fmu_dir):
    """The rig's co-simulation set-up (every motor parameter as an override), instances kept."""
    overrides = {f"{comp}.{k}": v for comp, attr in COMPONENT_PARAMS.items()
                 for k, v in asdict(getattr(mp, attr)).items()}
    return CoSimulation(fmu_dir=fmu_dir, step_s=plan.step_s, parameters=overrides, keep_instances=True)


def _run_kept(cs, mp, spec, plan):
    """One traverse as ``l1b2.rig.experiment`` simulates it, through the kept instances."""
    V_s = float(drv.supply_for_voltage_V(mp.driver, spec.V0_V, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if spec.direction > 0 else mp.slider.s_max_m
    res = cs.run(plan.max_run_s, inputs=dict(V_s=V_s, duty=1.0, f_s=plan.f_drive_Hz, T=plan.ambient_degC,
                                             direction=float(spec.direction), m_load=spec.load_kg),
                 record=RECORD, start_values={"Slider.s0": s0, "Stator.s": s0},
                 stop_when=lambda v: v["Slider.at_stop"] == spec.direction)
    return res


def _init_worker(fmu_dir):
    mp, plan = load_motor(), RigPlan()
    _WORKER.update(mp=mp, plan=plan, cs=_kept_cosim(mp, plan, fmu_dir))


def _work(spec):
    c0 = time.process_time()
    res = _run_kept(_WORKER["cs"], _WORKER["mp"], spec, _WORKER["plan"])
    return spec.run, float(res["time"][-1]), time.process_time() - c0


def full_experiment(fmu_dir, jobs):
    """The 72 runs on ``jobs`` processes; (wall, CPU of all processes, simulated seconds, runs)."""
    specs = _specs(RigPlan())
    t0, c0 = time.perf_counter(), time.process_time()
    ctx = mproc.get_context("fork")  # workers load the FMUs themselves (nothing FMU-related in the parent yet)
    with ctx.Pool(jobs, initializer=_init_worker, initargs=(str(fmu_dir),)) as pool:
        out = pool.map(_work, specs, chunksize=1)
        # CPU of the workers' set-up (imports, instantiation) is counted through their children times
    wall = time.perf_counter() - t0
    t = os.times()
    cpu = (time.process_time() - c0) + t.children_user + t.children_system
    return wall, cpu, sum(o[1] for o in out), len(out)


def compare(fmu_dir, n_runs):
    """Per-run cost: fresh CoSimulation per run (the rig today) vs kept instances, alternating."""
    mp, plan = load_motor(), RigPlan()
    specs = _specs(plan)[:n_runs]
    cs = _kept_cosim(mp, plan, fmu_dir)
    fresh = {"wall": 0.0, "cpu": 0.0}
    kept = {"wall": 0.0, "cpu": 0.0}
    sim_s, diff = 0.0, 0.0
    try:
        for spec in specs:
            t0, c0 = time.perf_counter(), time.process_time()
            a = simulate_run(mp, spec, plan, "fmu", fmu_dir)
            fresh["wall"] += time.perf_counter() - t0
            fresh["cpu"] += time.process_time() - c0
            t0, c0 = time.perf_counter(), time.process_time()
            r = _run_kept(cs, mp, spec, plan)
            kept["wall"] += time.perf_counter() - t0
            kept["cpu"] += time.process_time() - c0
            sim_s += float(r["time"][-1])
            every = int(round(1.0 / (plan.sample_rate_Hz * plan.step_s)))
            tip = r["Stator.v_tip"][::every]
            diff = max(diff, float(abs(tip - a["tip_velocity_amp_m_s"].to_numpy()).max()))
    finally:
        cs.close()
    return fresh, kept, sim_s, diff


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--jobs", type=int, default=2, help="worker processes of the full experiment")
    ap.add_argument("--compare", type=int, default=6, help="runs of the fresh-vs-kept comparison (0: skip)")
    args = ap.parse_args(argv)
    fmu_dir = ensure_fmus(load_motor())
    wall, cpu, sim_s, n = full_experiment(fmu_dir, args.jobs)
    print(f"72-run experiment through the 4 FMUs, kept instances, {args.jobs} processes "
          f"({os.cpu_count()} cores): {n} runs, {sim_s:.2f} s simulated")
    print(f"{'wall [s]':>9} {'CPU [s]':>9} {'target':>7} {'':>6} {'CPU RTF':>8}")
    print(f"{wall:9.2f} {cpu:9.2f} {TARGET_S:7.1f} {'ok' if wall < TARGET_S else 'MISSED':>6} {cpu / sim_s:8.3f}")
    if args.compare > 0:
        fresh, kept, sim_c, diff = compare(fmu_dir, args.compare)
        print(f"\nper run, first {args.compare} runs ({sim_c:.2f} s simulated), one process: fresh CoSimulation "
              f"per run (as rig/experiment.py) vs kept instances")
        print(f"{'time':>5} {'fresh [s/run]':>14} {'kept [s/run]':>13} {'ratio':>6}")
        for key in ("wall", "cpu"):
            f, k = fresh[key] / args.compare, kept[key] / args.compare
            print(f"{key:>5} {f:14.3f} {k:13.3f} {f / k:6.2f}")
        print(f"largest difference of the sampled tip velocity, fresh vs kept: {diff:.1e} m/s")


if __name__ == "__main__":
    main()
