#!/usr/bin/env python
"""Benchmark: closed-form interface kernel vs the numerical (quadrature) kernel.

Prints, side by side in one run:
* time per ``interface_forces`` call, old (``interface_forces_reference``,
  n_theta = 256) vs new (closed form), over tip motions taken from steady
  states of the reference motor, with the largest output differences;
* the real-time factor (wall time / simulated time) of the in-process engine
  (``l1b2.cosim.engine.InProcessMotor``, 324 V, 0.2 ms step) with the old kernel
  (``Interface.quadrature = true``) and the new one (target: <= 0.1), and the
  final slider speeds of both;
* the same for the four-FMU co-simulation (``l1b2.cosim.CoSimulation``),
  unless ``--no-fmu``.

Old and new runs alternate and the best of ``--repeat`` runs is reported.
The real-time factor is also given in CPU time of this process
(``time.process_time``), which a loaded, shared machine distorts less than
the wall time.

Usage: python bench/bench_kernel.py [--sim-time S] [--repeat N] [--no-fmu]
"""
import argparse
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
    rows = _tip_motions(mp)
    ip = mp.interface
    t_new, t_old = float("inf"), float("inf")
    for _ in range(repeat):  # alternate
        t_new = min(t_new, _per_call(itf.interface_forces, rows, ip, 3))
        t_old = min(t_old, _per_call(itf.interface_forces_reference, rows, ip, 1))
    d256 = dfine = 0.0
    for r in rows:
        new = itf.interface_forces(*r, ip)
        old = itf.interface_forces_reference(*r, ip)
        fine = itf.interface_forces_reference(*r, ip, n_theta=3 * 2 ** 15)
        d256 = max(d256, max(abs(a - b) for a, b in zip(new[:6], old[:6])))
        dfine = max(dfine, max(abs(a - b) for a, b in zip(new[:6], fine[:6])))
    print(f"interface_forces per call over {len(rows)} operating points of the reference motor")
    print(f"{'old (quadrature, 256) [us]':>27} {'new (closed form) [us]':>23} {'speed-up':>9}")
    print(f"{t_old * 1e6:27.1f} {t_new * 1e6:23.1f} {t_old / t_new:9.1f}")
    print(f"largest force difference new - old: {d256:.2e} N at n_theta = 256, "
          f"{dfine:.2e} N at n_theta = {3 * 2 ** 15}")


def _inprocess(mp, inputs, sim_time, quadrature):
    m = engine.InProcessMotor(mp, h_s=STEP_S)
    m.b["Interface"].quadrature = quadrature
    t0, c0 = time.perf_counter(), time.process_time()
    m.initialize(**inputs)
    m.run(sim_time, record=("Slider.v",))
    return (time.perf_counter() - t0) / sim_time, (time.process_time() - c0) / sim_time, m.value("Slider.v")


def _fmu(fmu_dir, inputs, sim_time, quadrature):
    from l1b2.cosim.master import CoSimulation
    params = {"Slider.s_min_m": -1.0, "Slider.s_max_m": 1.0, "Interface.quadrature": quadrature}
    t0, c0 = time.perf_counter(), time.process_time()
    with CoSimulation(fmu_dir=fmu_dir, step_s=STEP_S, parameters=params) as cs:
        res = cs.run(sim_time, inputs, record=["Slider.v"])
    return (time.perf_counter() - t0) / sim_time, (time.process_time() - c0) / sim_time, float(res["Slider.v"][-1])


def _engine_rows(run, repeat):
    """Best (wall RTF, CPU RTF, final speed) of ``repeat`` alternating runs: old kernel, new kernel."""
    best = {True: (float("inf"), float("inf"), None), False: (float("inf"), float("inf"), None)}
    for _ in range(repeat):
        for quadrature in (False, True):
            wall, cpu, v = run(quadrature)
            b = best[quadrature]
            best[quadrature] = (min(b[0], wall), min(b[1], cpu), v)
    return best[True], best[False]


def _print_engine(name, old, new):
    (wall_old, cpu_old, v_old), (wall_new, cpu_new, v_new) = old, new
    print(f"{name:>12} {'wall':>5} {wall_old:9.3f} {wall_new:9.3f} {wall_old / wall_new:9.1f}  "
          f"{'ok' if wall_new <= 0.1 else 'MISSED':>6}   {v_old:10.6f} {v_new:10.6f} {abs(v_new / v_old - 1):9.1e}")
    print(f"{'':>12} {'CPU':>5} {cpu_old:9.3f} {cpu_new:9.3f} {cpu_old / cpu_new:9.1f}  "
          f"{'ok' if cpu_new <= 0.1 else 'MISSED':>6}")


def main(argv=None):
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
    if not args.no_fmu:
        from l1b2.fmi.build import build_subsystem_fmus
        with tempfile.TemporaryDirectory(prefix="l1b2_bench_kernel_") as tmp:
            build_subsystem_fmus(tmp, mp)
            rows.append(("4 FMUs", _engine_rows(lambda q: _fmu(tmp, inputs, args.sim_time, q), args.repeat)))
    print(f"\nreal-time factor (wall / simulated time), reference motor, {V0_V:.0f} V, no load, "
          f"{STEP_S * 1e3:.1f} ms step, {args.sim_time} s simulated")
    print(f"{'engine':>12} {'time':>5} {'RTF old':>9} {'RTF new':>9} {'speed-up':>9}  {'<= 0.1':>6}   "
          f"{'v_end old':>10} {'v_end new':>10} {'rel diff':>9}")
    for name, (old, new) in rows:
        _print_engine(name, old, new)


if __name__ == "__main__":
    main()
