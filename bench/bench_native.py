#!/usr/bin/env python
"""Benchmark: the native (C) FMUs beside the Python FMUs, in one run.

Prints:
* export: time to build each FMU (the Python FMU with pythonfmu, the native
  FMI 2.0 and FMI 3.0 FMUs from it: sources written and compiled with the
  system's C compiler) and the size of each file;
* the real-time factor (wall time / simulated time) of ``L1B2Motor.fmu`` and
  ``Predictor.fmu`` at 324 V and a 0.2 ms communication step, Python FMU and
  native FMUs side by side, stepped through fmpy: ``doStep`` and ``getReal``
  of two outputs every step, once through fmpy's Python API
  (``FMU2Slave``/``FMU3Slave``) and once ("ctypes host") through the ctypes
  functions fmpy loaded with preallocated arrays, as a host written in C calls
  them; for the native FMI 2.0 FMUs also in a C host (``bench/rtf_host.c``,
  started with an empty environment, ``env -i``), which times its loop of
  ``fmi2DoStep`` and ``fmi2GetReal`` itself (instantiation excluded): the
  cost of the FMU without a Python host loop. Targets (issue "Drop-in without Python"):
  native motor <= 0.01, native predictor <= 0.002. Each run includes instantiation and initialisation; the
  best of ``--repeat`` runs is reported, also in CPU time of this process.
* the largest relative difference of the final outputs, native against Python.

Usage: python bench/bench_native.py [--sim-time S] [--repeat N]
"""
import argparse
import ctypes
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.params import load_motor  # noqa: E402

STEP_S = 2e-4
V0_V = 324.0
TARGETS = {("L1B2Motor", "native"): 0.01, ("L1B2Motor", "native-fmi3"): 0.01, ("Predictor", "native"): 0.002,
           ("Predictor", "native-fmi3"): 0.002}


def _run(path, params, inputs, outputs, sim_time, raw):
    """Wall and CPU real-time factor of one run, and the final outputs."""
    from fmpy import extract, read_model_description
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unz = _run.extracted.setdefault(str(path), extract(str(path)))
    fmi3 = md.fmiVersion.startswith("3")
    t0, c0 = time.perf_counter(), time.process_time()
    if fmi3:
        from fmpy.fmi3 import FMU3Slave
        fmu = FMU3Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="b")
        fmu.instantiate()
        set_real, get_real = fmu.setFloat64, fmu.getFloat64
    else:
        from fmpy.fmi2 import FMU2Slave
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="b")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        set_real, get_real = fmu.setReal, fmu.getReal
    try:
        set_real([vr[k] for k in params], list(params.values()))
        set_real([vr[k] for k in inputs], list(inputs.values()))
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        out = [vr[k] for k in outputs]
        n = int(round(sim_time / STEP_S))
        if raw:
            comp = fmu.component
            out_vr, out_val = (ctypes.c_uint * len(out))(*out), (ctypes.c_double * len(out))()
            if fmi3:
                do_step, get = fmu._functions["fmi3DoStep"], fmu._functions["fmi3GetFloat64"]
                flags = [ctypes.c_bool() for _ in range(3)]
                last = ctypes.c_double()
                for k in range(n):
                    if (do_step(comp, k * STEP_S, STEP_S, True, ctypes.byref(flags[0]), ctypes.byref(flags[1]),
                                ctypes.byref(flags[2]), ctypes.byref(last)) > 1
                            or get(comp, out_vr, len(out), out_val, len(out)) > 1):
                        raise RuntimeError(f"{path.name} failed at step {k}")
            else:
                do_step, get = fmu._functions["fmi2DoStep"], fmu._functions["fmi2GetReal"]
                for k in range(n):
                    if do_step(comp, k * STEP_S, STEP_S, 1) > 1 or get(comp, out_vr, len(out), out_val) > 1:
                        raise RuntimeError(f"{path.name} failed at step {k}")
            values = list(out_val)
        else:
            for k in range(n):
                fmu.doStep(k * STEP_S, STEP_S)
                values = get_real(out)
        fmu.terminate()
    finally:
        fmu.freeInstance()
    return (time.perf_counter() - t0) / sim_time, (time.process_time() - c0) / sim_time, list(values)


_run.extracted = {}


def compile_rtf_host(dest: Path) -> Path:
    """``bench/rtf_host.c`` compiled with the system's C compiler (FMI 2.0 headers from fmpy)."""
    import subprocess
    from l1b2.fmi.native.build import find_cc, fmi_headers
    subprocess.run([find_cc(), "-O2", "-std=c99", f"-I{fmi_headers()}", "-o", str(dest),
                    str(Path(__file__).resolve().parent / "rtf_host.c"), "-ldl"], check=True)
    return dest


def _c_host(host, path, params, inputs, outputs, sim_time):
    """Wall and CPU real-time factor of the steps in the C host (started with ``env -i``), and its final outputs."""
    import subprocess
    import zipfile
    from fmpy import read_model_description
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unz = path.with_suffix("")
    if not unz.exists():
        with zipfile.ZipFile(path) as z:
            z.extractall(unz)
    args = ["env", "-i", str(host), str(unz), md.coSimulation.modelIdentifier, md.guid, repr(STEP_S),
            str(int(round(sim_time / STEP_S)))]
    args += [f"{vr[k]}={x!r}" for k, x in {**params, **inputs}.items()] + ["--"] + [str(vr[k]) for k in outputs]
    words = subprocess.run(args, capture_output=True, text=True, check=True).stdout.split()
    return float(words[0]) / sim_time, float(words[1]) / sim_time, [float(x) for x in words[2:]]


def _best(path, params, inputs, outputs, sim_time, raw, repeat):
    runs = [_run(path, params, inputs, outputs, sim_time, raw) for _ in range(repeat)]
    return min(r[0] for r in runs), min(r[1] for r in runs), runs[-1][2]


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--sim-time", type=float, default=0.5, help="simulated seconds per run")
    ap.add_argument("--repeat", type=int, default=3, help="runs per FMU and host loop (best is reported)")
    args = ap.parse_args(argv)
    from l1b2.cosim.hosting import install_exit_fix
    from l1b2.fmi.build import build_fmu
    from l1b2.fmi.native.build import build_native_fmu, native_fmu_name
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
        print(f"\nreal-time factor (wall / simulated time), {V0_V:.0f} V, {STEP_S * 1e3:.1f} ms communication step, "
              f"{args.sim_time} s simulated, best of {args.repeat}")
        print(f"{'FMU':>10} {'kind':>12} {'host loop':>12} {'RTF wall':>9} {'RTF CPU':>8} {'target':>7} {'':>6} "
              f"{'rel diff vs Python':>19}")
        host = compile_rtf_host(tmp / "rtf_host")
        for name, (params, inputs, outputs) in cases.items():
            ref = None
            for raw in (False, True, "c"):
                for kind in ("python", "native", "native-fmi3"):
                    if raw == "c":
                        if kind != "native":
                            continue
                        runs = [_c_host(host, paths[(name, kind)], params, inputs, outputs, args.sim_time)
                                for _ in range(args.repeat)]
                        wall, cpu, values = min(r[0] for r in runs), min(r[1] for r in runs), runs[-1][2]
                    else:
                        wall, cpu, values = _best(paths[(name, kind)], params, inputs, outputs, args.sim_time, raw,
                                                  args.repeat)
                    if kind == "python" and ref is None:
                        ref = values
                    diff = max(abs(a / b - 1) if b else abs(a) for a, b in zip(values, ref))
                    target = TARGETS.get((name, kind))
                    verdict = "" if target is None else ("ok" if wall <= target else "MISSED")
                    print(f"{name:>10} {kind:>12} {'C host' if raw == 'c' else ('ctypes' if raw else 'fmpy API'):>12} {wall:9.4f} {cpu:8.4f} "
                          f"{'' if target is None else f'{target:7.3f}':>7} {verdict:>6} {diff:19.1e}")


if __name__ == "__main__":
    main()
