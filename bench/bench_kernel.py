#!/usr/bin/env python
"""Benchmark: the interface kernels, and the real-time factors of the three engines with the old and new kernel.

Prints, side by side in one run:
* time per interface call over tip motions taken from steady states of the
  reference motor: the numerical kernel (``interface_forces_reference``,
  n_theta = 256), the closed form in plain Python (the kernel of the previous
  releases) and the same closed form compiled by numba (``l1b2.physics.jit``),
  with the largest output differences;
* the real-time factor (wall time / simulated time) of the in-process engine
  (``l1b2.cosim.engine.InProcessMotor``, 324 V, 0.2 ms step) with the old kernels
  (``L1B2_JIT=0``: interface, stator and slider steps in plain Python, block
  by block, as in the releases before the compiled kernels) and the new ones
  (the fused coupled step compiled by numba; target: <= 0.1), and the final
  slider speeds of both; then the compiled kernels called block by block
  (``fused=False``, the release before the fused step) against the fused step;
* the same for the four-FMU co-simulation (``l1b2.cosim.CoSimulation``,
  target <= 0.5) and for ``L1B2Motor.fmu`` alone, stepped through fmpy
  (``doStep`` and ``getReal`` of its outputs every step, target <= 0.15), once
  through fmpy's Python API and once ("ctypes host") through the ctypes
  functions fmpy loaded, as a host written in C calls them; unless ``--no-fmu``.
  Each run's time includes instantiating and initialising the FMU.

Old and new runs alternate and the best of ``--repeat`` runs is reported.
The real-time factor is also given in CPU time of this process
(``time.process_time``), which a loaded, shared machine distorts less than
the wall time.

Usage: python bench/bench_kernel.py [--sim-time S] [--repeat N] [--no-fmu]
"""
import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.cosim import engine  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics import interface as itf  # noqa: E402
from l1b2.physics import steady  # noqa: E402
from l1b2.physics.params import load_motor  # noqa: E402

STEP_S = 2e-4
V0_V = 324.0


def _tip_motions(mp):
    """Interface inputs (U_l, U_w, delta, omega, v, F_p) at steady states over voltage, load and direction."""
    rows = []
    for V0 in (150.0, 250.0, 324.0):
        for m_load, d in ((0.0, 1), (0.1, 1), (0.0, -1), (0.05, -1)):
            ss = steady.steady_state(mp, 0.0, V0, m_load, d)
            for frac in (0.0, 1.0):  # at rest (start-up) and at the steady speed
                rows.append((ss.U_l_m, ss.U_w_m, ss.delta_rad, 2 * 3.141592653589793 * mp.operating.f_drive_Hz,
                             frac * ss.v_m_s, ss.F_p_N))
    return rows


def _per_call(fn, rows, ip, repeat):
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for r in rows:
            fn(*r, ip)
        best = min(best, (time.perf_counter() - t0) / len(rows))
    return best


def bench_calls(mp, repeat):
    from l1b2.physics.jit import jit_status
    rows = _tip_motions(mp)
    ip = mp.interface
    itf.compiled_kernel()  # compile (or load from the cache) outside the timing

    def python(*r):
        return itf.interface_forces_scalar(*r, "stick_slip", jit=False)

    def compiled(*r):
        return itf.interface_forces_scalar(*r, "stick_slip", jit=True)

    t_quad = t_py = t_jit = float("inf")
    for _ in range(repeat):  # alternate
        t_jit = min(t_jit, _per_call(compiled, rows, ip, 3))
        t_py = min(t_py, _per_call(python, rows, ip, 3))
        t_quad = min(t_quad, _per_call(itf.interface_forces_reference, rows, ip, 1))
    d256 = dfine = djit = 0.0
    for r in rows:
        new, py = compiled(*r, ip), python(*r, ip)
        old = itf.interface_forces_reference(*r, ip)
        fine = itf.interface_forces_reference(*r, ip, n_theta=3 * 2 ** 15)
        djit = max(djit, max(abs(a - b) for a, b in zip(new, py)))
        d256 = max(d256, max(abs(a - b) for a, b in zip(new[:6], old[:6])))
        dfine = max(dfine, max(abs(a - b) for a, b in zip(new[:6], fine[:6])))
    print(f"interface kernel per call over {len(rows)} operating points of the reference motor "
          f"(numba: {jit_status()})")
    print(f"{'quadrature, 256 [us]':>21} {'closed form, Python [us]':>25} {'closed form, compiled [us]':>27} "
          f"{'speed-up Python / compiled':>27}")
    print(f"{t_quad * 1e6:21.1f} {t_py * 1e6:25.1f} {t_jit * 1e6:27.2f} {t_py / t_jit:27.1f}")
    print(f"largest difference compiled - Python: {djit:.2e} (any output); largest force difference "
          f"compiled - quadrature: {d256:.2e} N at n_theta = 256, {dfine:.2e} N at n_theta = {3 * 2 ** 15}")


def _use_compiled(compiled: bool):
    """Select the kernels for the blocks initialised next, in this process and in the FMUs it hosts."""
    os.environ["L1B2_JIT"] = "1" if compiled else "0"


def _inprocess(mp, inputs, sim_time, compiled, fused=None):
    _use_compiled(compiled)
    m = engine.InProcessMotor(mp, h_s=STEP_S, fused=fused)
    t0, c0 = time.perf_counter(), time.process_time()
    m.initialize(**inputs)
    m.run(sim_time, record=("Slider.v",))
    return (time.perf_counter() - t0) / sim_time, (time.process_time() - c0) / sim_time, m.value("Slider.v")


def _fmu(cosims, inputs, sim_time, compiled):
    """One run of the kept four-FMU co-simulation (reset, initialisation and stepping are timed)."""
    cs = cosims[compiled]
    _use_compiled(compiled)
    t0, c0 = time.perf_counter(), time.process_time()
    res = cs.run(sim_time, inputs, record=["Slider.v"])
    return (time.perf_counter() - t0) / sim_time, (time.process_time() - c0) / sim_time, float(res["Slider.v"][-1])


def _cosims(fmu_dir):
    """One CoSimulation per kernel, keeping its FMU instances between the runs (SSD, SSV and model
    descriptions read once, as a host running many simulations would)."""
    from l1b2.cosim.master import CoSimulation
    return {c: CoSimulation(fmu_dir=fmu_dir, step_s=STEP_S, keep_instances=True,
                            parameters={"Slider.s_min_m": -1.0, "Slider.s_max_m": 1.0})
            for c in (False, True)}


def _motor_fmu(fmu_path, inputs, sim_time, compiled, raw=False):
    """L1B2Motor.fmu alone through fmpy: a host loop of doStep and getReal (speed, position) per step.

    ``raw``: the loop calls the FMI functions through the ctypes function pointers fmpy loaded, with
    preallocated arrays (what a host written in C pays), instead of fmpy's Python API
    (``FMU2Slave.doStep``/``getReal``, which builds ctypes arrays and checks the status in Python).
    """
    from fmpy import read_model_description
    from fmpy.fmi2 import FMU2Slave
    from l1b2.cosim.hosting import install_exit_fix
    from l1b2.cosim.master import extracted
    install_exit_fix()
    md = read_model_description(str(fmu_path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extracted(fmu_path)
    _use_compiled(compiled)
    t0, c0 = time.perf_counter(), time.process_time()
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="motor")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.setReal([vr["Slider.s_min_m"], vr["Slider.s_max_m"]], [-1.0, 1.0])
        fmu.setReal([vr[k] for k in inputs], [float(x) for x in inputs.values()])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        out = [vr["v"], vr["s"]]
        v = fmu.getReal(out)
        n = int(round(sim_time / STEP_S))
        if raw:
            import ctypes
            do_step, get_real = fmu._functions["fmi2DoStep"], fmu._functions["fmi2GetReal"]
            comp, out_vr, out_val = fmu.component, (ctypes.c_uint * 2)(*out), (ctypes.c_double * 2)()
            for k in range(n):
                if do_step(comp, k * STEP_S, STEP_S, 1) > 1 or get_real(comp, out_vr, 2, out_val) > 1:
                    raise RuntimeError(f"L1B2Motor.fmu failed at step {k}")
            v = list(out_val)
        else:
            for k in range(n):
                fmu.doStep(k * STEP_S, STEP_S)
                v = fmu.getReal(out)
        fmu.terminate()
    finally:
        fmu.freeInstance()
    return (time.perf_counter() - t0) / sim_time, (time.process_time() - c0) / sim_time, float(v[0])


def _engine_rows(run, repeat):
    """Best (wall RTF, CPU RTF, final speed) of ``repeat`` alternating runs: old kernel, new kernel."""
    best = {True: (float("inf"), float("inf"), None), False: (float("inf"), float("inf"), None)}
    for _ in range(repeat):
        for compiled in (True, False):
            wall, cpu, v = run(compiled)
            b = best[compiled]
            best[compiled] = (min(b[0], wall), min(b[1], cpu), v)
    return best[False], best[True]


#: real-time factor targets (issue #12) per engine
TARGETS = {"in-process": 0.1, "4 FMUs": 0.5, "L1B2Motor.fmu": 0.15, "  ctypes host": 0.15}


def _print_engine(name, old, new):
    (wall_old, cpu_old, v_old), (wall_new, cpu_new, v_new) = old, new
    target = TARGETS[name]
    print(f"{name:>13} {'wall':>5} {wall_old:9.3f} {wall_new:9.3f} {wall_old / wall_new:9.1f} {target:7.2f} "
          f"{'ok' if wall_new <= target else 'MISSED':>6}   {v_old:10.6f} {v_new:10.6f} {abs(v_new / v_old - 1):9.1e}")
    print(f"{'':>13} {'CPU':>5} {cpu_old:9.3f} {cpu_new:9.3f} {cpu_old / cpu_new:9.1f} {target:7.2f} "
          f"{'ok' if cpu_new <= target else 'MISSED':>6}")


def main(argv=None):
    """Run the benchmark; the kernel switch ``L1B2_JIT`` is restored afterwards (run_all.py runs the
    benchmarks in one process)."""
    saved = os.environ.get("L1B2_JIT")
    try:
        _main(argv)
    finally:
        if saved is None:
            os.environ.pop("L1B2_JIT", None)
        else:
            os.environ["L1B2_JIT"] = saved


def _main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--sim-time", type=float, default=0.2, help="simulated seconds per engine run")
    ap.add_argument("--repeat", type=int, default=2, help="runs per kernel (best is reported)")
    ap.add_argument("--no-fmu", action="store_true", help="skip the FMU co-simulation")
    args = ap.parse_args(argv)
    mp = load_motor()
    bench_calls(mp, args.repeat)

    mp_wide = mp.replace(slider__s_min_m=-1.0, slider__s_max_m=1.0)  # end stops far away
    V_s = float(drv.supply_for_voltage_V(mp.driver, V0_V, 1.0, 48500.0, 25.0))
    inputs = dict(V_s=V_s, duty=1.0, f_s=48500.0, T=25.0, direction=1.0, m_load=0.0)
    rows = [("in-process", _engine_rows(lambda q: _inprocess(mp_wide, inputs, args.sim_time, q), args.repeat))]
    # the compiled kernels called block by block (the previous release) against the fused step
    blocks = _engine_rows(lambda q: _inprocess(mp_wide, inputs, args.sim_time, True, fused=None if q else False),
                          args.repeat)
    if not args.no_fmu:
        from l1b2.fmi.build import build_fmu, build_subsystem_fmus
        with tempfile.TemporaryDirectory(prefix="l1b2_bench_kernel_") as tmp:
            build_subsystem_fmus(tmp, mp)
            cosims = _cosims(tmp)
            try:
                rows.append(("4 FMUs", _engine_rows(lambda q: _fmu(cosims, inputs, args.sim_time, q), args.repeat)))
            finally:
                for cs in cosims.values():
                    cs.close()
            motor = build_fmu("L1B2Motor", Path(tmp) / "motor", mp=mp)
            rows.append(("L1B2Motor.fmu",
                         _engine_rows(lambda q: _motor_fmu(motor, inputs, args.sim_time, q), args.repeat)))
            rows.append(("  ctypes host",
                         _engine_rows(lambda q: _motor_fmu(motor, inputs, args.sim_time, q, raw=True),
                                      args.repeat)))
    print(f"\nreal-time factor (wall / simulated time), reference motor, {V0_V:.0f} V, no load, "
          f"{STEP_S * 1e3:.1f} ms step, {args.sim_time} s simulated; old = kernels in plain Python "
          "(L1B2_JIT=0), new = compiled by numba")
    print(f"{'engine':>13} {'time':>5} {'RTF old':>9} {'RTF new':>9} {'speed-up':>9} {'target':>7} {'':>6}   "
          f"{'v_end old':>10} {'v_end new':>10} {'rel diff':>9}")
    for name, (old, new) in rows:
        _print_engine(name, old, new)
    (w_blocks, _, v_blocks), (w_fused, _, v_fused) = blocks
    print(f"\nin-process, compiled kernels: blocks one after the other (fused=False) {w_blocks:.3f}, fused coupled "
          f"step {w_fused:.3f} (wall RTF), ratio {w_blocks / w_fused:.1f}; final speeds differ by "
          f"{abs(v_fused / v_blocks - 1):.1e} (relative)")


if __name__ == "__main__":
    main()
