#!/usr/bin/env python
"""Benchmark: the native (C) FMUs beside the Python FMUs, in one run, and where a host's time goes per step.

Prints:
* export: time to build each FMU (the Python FMU with pythonfmu, the native
  FMI 2.0 and FMI 3.0 FMUs from it: sources written and compiled with the
  system's C compiler) and the size of each file;
* the real-time factor (time / simulated time) of ``L1B2Motor.fmu`` and
  ``Predictor.fmu`` at 324 V and a 0.2 ms communication step, Python FMU and
  native FMUs side by side, in four hosts:

  - ``simulate_fmu``: fmpy's ``simulate_fmu`` (constant inputs as start
    values, output interval = the 0.2 ms step: fmpy's co-simulation loop steps
    at the output interval and records every output each step). Its RTF is the
    slope between a short and a long run (instantiation, initialisation and the
    result's assembly cancel);
  - ``fmpy master``: the smallest master written with fmpy's low-level API (as
    in FMPy's ``examples/custom_input.py``): value references looked up once,
    ``FMU2Slave.doStep``/``FMU3Slave.doStep`` every 0.2 ms, the outputs read
    only at the output points (every ``OUTPUT_S``); the stepping loop is timed;
  - ``ctypes master``: the same loop calling the ctypes function fmpy loaded
    (no fmpy wrapper): what any Python master pays at least;
  - ``C host``: ``l1b2/fmi/chost/fmu_host.c`` (``-T 1`` times its loop, ``-e``
    the output points), started with an empty environment (``env -i``) for the
    native FMUs and with ``l1b2.fmi.runtime.host_environment()`` for the
    Python FMUs (FMI 2.0 only).

  Also the cost of one ctypes call of an FMI function that does nothing
  (``fmi2GetTypesPlatform``/``fmi3GetVersion``) in a Python loop: the floor of
  any Python master that calls the FMU once per step. Per-step figures in
  microseconds say where the time goes: the FMU's step (C host), the foreign
  call and loop (ctypes - C host), fmpy's wrapper (fmpy master - ctypes), and
  simulate_fmu's recording and input handling (simulate_fmu - fmpy master).
  (The split uses CPU time: on a shared machine the wall time of a short
  loop depends on the other processes.)
  Targets (issue "Drop-in without Python", through fmpy): native motor <= 0.01,
  native predictor <= 0.002.
* the largest relative difference of the final outputs, native against Python.

Usage: python bench/bench_native.py [--sim-time S] [--repeat N]
"""
import argparse
import ctypes
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.fmi.fmpy_slave import open_slave  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.params import load_motor  # noqa: E402

STEP_S = 2e-4
OUTPUT_S = 1e-2     #: output interval of the minimal masters and the C host [s]
V0_V = 324.0
TARGETS = {("L1B2Motor", "native"): 0.01, ("L1B2Motor", "native-fmi3"): 0.01, ("Predictor", "native"): 0.002,
           ("Predictor", "native-fmi3"): 0.002}
KINDS = ("python", "native", "native-fmi3")


def master(path, unz, params, inputs, outputs, sim_time, raw):
    """Wall and CPU RTF of the stepping loop of the minimal fmpy master (``raw``: the ctypes functions), and the
    final outputs."""
    with open_slave(path, unzipdir=unz, instance_name="b", params=params, inputs=inputs) as sl:
        fmu, fmi3 = sl.fmu, sl.fmi3
        out = sl.refs(outputs)
        n, every = int(round(sim_time / STEP_S)), int(round(OUTPUT_S / STEP_S))
        comp = fmu.component
        out_vr, out_val = (ctypes.c_uint * len(out))(*out), (ctypes.c_double * len(out))()
        t0, c0 = time.perf_counter(), time.process_time()
        if raw and fmi3:
            do_step, get = fmu._functions["fmi3DoStep"], fmu._functions["fmi3GetFloat64"]
            flags = [ctypes.c_bool() for _ in range(3)]
            last = ctypes.c_double()
            b0, b1, b2, bl = (ctypes.byref(f) for f in (*flags, last))
            for k in range(n):
                if do_step(comp, k * STEP_S, STEP_S, True, b0, b1, b2, bl) > 1:
                    raise RuntimeError(f"{path.name} failed at step {k}")
                if (k + 1) % every == 0 and get(comp, out_vr, len(out), out_val, len(out)) > 1:
                    raise RuntimeError(f"{path.name} failed at step {k}")
            values = list(out_val)
        elif raw:
            do_step, get = fmu._functions["fmi2DoStep"], fmu._functions["fmi2GetReal"]
            for k in range(n):
                if do_step(comp, k * STEP_S, STEP_S, 1) > 1:
                    raise RuntimeError(f"{path.name} failed at step {k}")
                if (k + 1) % every == 0 and get(comp, out_vr, len(out), out_val) > 1:
                    raise RuntimeError(f"{path.name} failed at step {k}")
            values = list(out_val)
        else:
            do_step, get_real = fmu.doStep, sl.get_real
            for k in range(n):
                do_step(k * STEP_S, STEP_S)
                if (k + 1) % every == 0:
                    values = get_real(out)
        wall, cpu = (time.perf_counter() - t0) / sim_time, (time.process_time() - c0) / sim_time
    return wall, cpu, list(values)


def call_floor(path, unz, params, inputs, n=20000):
    """CPU seconds per ctypes call of an FMI function that does nothing, in a Python loop of ``n`` calls."""
    with open_slave(path, unzipdir=unz, instance_name="b", params=params, inputs=inputs) as sl:
        f = sl.fmu._functions["fmi3GetVersion" if sl.fmi3 else "fmi2GetTypesPlatform"]
        c0 = time.process_time()
        for _ in range(n):
            f()
        return (time.process_time() - c0) / n


def simulate(path, unz, params, inputs, outputs, sim_time):
    """fmpy.simulate_fmu's wall and CPU time of one run (extracted FMU; output interval = the step) and its last
    outputs."""
    from fmpy import simulate_fmu
    t0, c0 = time.perf_counter(), time.process_time()
    res = simulate_fmu(unz, start_time=0.0, stop_time=sim_time, output_interval=STEP_S,
                       start_values={**params, **inputs}, output=outputs, fmi_type="CoSimulation")
    return time.perf_counter() - t0, time.process_time() - c0, [float(res[k][-1]) for k in outputs]


def simulate_rtf(path, unz, params, inputs, outputs, sim_time, repeat):
    """simulate_fmu's RTF per simulated second: the slope between runs of sim_time/5 and sim_time (best of repeat)."""
    short = [simulate(path, unz, params, inputs, outputs, sim_time / 5) for _ in range(repeat)]
    long_ = [simulate(path, unz, params, inputs, outputs, sim_time) for _ in range(repeat)]
    dt = sim_time - sim_time / 5
    return ((min(r[0] for r in long_) - min(r[0] for r in short)) / dt,
            (min(r[1] for r in long_) - min(r[1] for r in short)) / dt, long_[-1][2])


def c_host(host, path, unz, params, inputs, outputs, sim_time, python_fmu):
    """Wall and CPU RTF of the C host's stepping loop (fmu_host.c -T 1) and its final outputs."""
    from fmpy import read_model_description
    from l1b2.fmi.runtime import host_environment
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    n = int(round(sim_time / STEP_S))
    args = [str(host), "-T", "1", "-h", repr(STEP_S), "-n", str(n), "-e", str(int(round(OUTPUT_S / STEP_S)))]
    args += [a for k, x in params.items() for a in ("-p", f"{vr[k]}={x!r}")]
    args += [a for k, x in inputs.items() for a in ("-i", f"{vr[k]}={x!r}")]
    args += [a for k in outputs for a in ("-o", str(vr[k]))] + [str(unz), md.coSimulation.modelIdentifier, md.guid]
    if python_fmu:
        proc = subprocess.run(args, capture_output=True, text=True, env=host_environment())
    else:
        proc = subprocess.run(["env", "-i", str(host), "-L", "-"] + args[1:], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"C host failed on {path.name}: {proc.stderr[-2000:]}")
    line = next(x for x in proc.stderr.splitlines() if x.startswith("fmu_host: timing"))
    _, _, steps, wall, cpu = line.split()
    last = [float(x) for x in proc.stdout.split("\n")[-2].split()[1:]]
    return float(wall) / sim_time, float(cpu) / sim_time, last


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--sim-time", type=float, default=0.5, help="simulated seconds per run")
    ap.add_argument("--repeat", type=int, default=3, help="runs per FMU and host (best is reported)")
    args = ap.parse_args(argv)
    from l1b2.cosim.hosting import install_exit_fix
    from l1b2.fmi.build import build_fmu
    from l1b2.fmi.native.build import build_native_fmu, native_fmu_name
    from l1b2.fmi.runtime import compile_c_host
    install_exit_fix()
    mp = load_motor()
    V_s = float(drv.supply_for_voltage_V(mp.driver, V0_V, 1.0, 48500.0, 25.0))
    cases = {
        "L1B2Motor": ({"Slider.s_min_m": -1.0, "Slider.s_max_m": 1.0},
                      dict(V_s=V_s, duty=1.0, f_s=48500.0, T=25.0, direction=1.0, m_load=0.0), ["v", "s"]),
        "Predictor": ({}, dict(V0=V0_V, s=0.0, load=0.0, direction=1.0), ["v", "v_steady"]),
    }
    with tempfile.TemporaryDirectory(prefix="l1b2_bench_native_") as tmp:
        tmp = Path(tmp)
        paths, build = {}, []
        for name in cases:
            t0 = time.perf_counter()
            py = build_fmu(name, tmp, mp=mp)
            build.append((f"{name}.fmu", "python (pythonfmu)", time.perf_counter() - t0, py.stat().st_size))
            paths[(name, "python")] = py
            for ver in (2, 3):
                t0 = time.perf_counter()
                p = build_native_fmu(name, py, tmp, ver)
                kind = "native" if ver == 2 else "native-fmi3"
                build.append((p.name, f"native FMI {ver}.0 (C, compiled)", time.perf_counter() - t0,
                              p.stat().st_size))
                paths[(name, kind)] = p
                assert p.name == native_fmu_name(name, ver) + ".fmu"
        print("export time and size")
        print(f"{'file':>28} {'kind':>28} {'build [s]':>10} {'size [kB]':>10}")
        for f, kind, dt, size in build:
            print(f"{f:>28} {kind:>28} {dt:10.2f} {size / 1024:10.1f}")
        unz = {}
        for key, p in paths.items():
            unz[key] = tmp / (p.stem + "_x")
            with zipfile.ZipFile(p) as z:
                z.extractall(unz[key])
        host = compile_c_host(tmp / "fmu_host")
        print(f"\nreal-time factor (time / simulated time), {V0_V:.0f} V, {STEP_S * 1e3:.1f} ms communication step, "
              f"outputs every {OUTPUT_S * 1e3:.0f} ms (simulate_fmu: every step), {args.sim_time} s simulated, "
              f"best of {args.repeat}")
        print(f"{'FMU':>10} {'kind':>12} {'host':>13} {'RTF wall':>9} {'RTF CPU':>8} {'us/step':>8} {'target':>7} "
              f"{'':>6} {'rel diff vs Python':>19}")
        for name, (params, inputs, outputs) in cases.items():
            ref, per_step = None, {}
            for host_kind in ("simulate_fmu", "fmpy master", "ctypes master", "C host"):
                for kind in KINDS:
                    key = (name, kind)
                    if host_kind == "C host":
                        if kind == "native-fmi3":
                            continue   # fmu_host.c is an FMI 2.0 host
                        runs = [c_host(host, paths[key], unz[key], params, inputs, outputs, args.sim_time,
                                       kind == "python") for _ in range(args.repeat)]
                    elif host_kind == "simulate_fmu":
                        runs = [simulate_rtf(paths[key], str(unz[key]), params, inputs, outputs, args.sim_time,
                                             args.repeat)]
                    else:
                        runs = [master(paths[key], str(unz[key]), params, inputs, outputs, args.sim_time,
                                       host_kind == "ctypes master") for _ in range(args.repeat)]
                    wall, cpu, values = min(r[0] for r in runs), min(r[1] for r in runs), runs[-1][2]
                    if ref is None:
                        ref = values
                    diff = max(abs(a / b - 1) if b else abs(a) for a, b in zip(values, ref))
                    target = TARGETS.get(key) if host_kind != "C host" else None
                    verdict = "" if target is None else ("ok" if wall <= target else "MISSED")
                    per_step[(host_kind, kind)] = cpu * STEP_S * 1e6
                    print(f"{name:>10} {kind:>12} {host_kind:>13} {wall:9.4f} {cpu:8.4f} {wall * STEP_S * 1e6:8.2f} "
                          f"{'' if target is None else f'{target:7.3f}':>7} {verdict:>6} {diff:19.1e}")
            floor = {kind: call_floor(paths[(name, kind)], str(unz[(name, kind)]), params, inputs)
                     for kind in ("native", "native-fmi3")}
            print(f"{name:>10} where the time goes per step [us of CPU], native FMI 2.0: FMU step (C host) "
                  f"{per_step[('C host', 'native')]:.2f}; Python loop and foreign call (ctypes - C host) "
                  f"{per_step[('ctypes master', 'native')] - per_step[('C host', 'native')]:.2f} "
                  f"(one empty ctypes call: {floor['native'] * 1e6:.2f}); fmpy's doStep wrapper (fmpy master - ctypes) "
                  f"{per_step[('fmpy master', 'native')] - per_step[('ctypes master', 'native')]:.2f}; simulate_fmu's "
                  f"recording and inputs (simulate_fmu - fmpy master) "
                  f"{per_step[('simulate_fmu', 'native')] - per_step[('fmpy master', 'native')]:.2f}")
            print(f"{name:>10} floor of a Python master with one FMI call per step: RTF "
                  f"{floor['native'] / STEP_S:.4f} (FMI 2.0), {floor['native-fmi3'] / STEP_S:.4f} (FMI 3.0)")


if __name__ == "__main__":
    main()
