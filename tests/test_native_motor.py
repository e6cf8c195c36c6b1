"""Native (C) L1B2Motor FMU, FMI 2.0 and 3.0: the Python L1B2Motor.fmu's variables and numbers, no Python.

The Python FMU (numba-compiled fused step) is the reference; the native one runs
the C generated from the same kernels (tests/test_native_translate.py) and is
compared over runs with input changes, sub-stepped communication steps, loads,
both directions, an end stop, self-heating, bar waviness and bump, pulley
friction and the pure-slip interface: every output and every sub-block variable,
1e-9 relative.
"""

from __future__ import annotations

import subprocess
import zipfile

import numpy as np
import pytest

pytestmark = pytest.mark.fmu

#: per scenario: (Real parameters, Boolean parameters, [(inputs V_s, duty, f_s, T, direction, m_load, h)] )
_BASE = (67.1, 1.0, 48500.0, 25.0, 1.0, 0.0)
SCENARIOS = {
    "inputs change, sub-steps": (
        {"Slider.s0": -0.015}, {},
        [(*_BASE, 2e-4)] * 60 + [(67.1, 1.0, 48500.0, 25.0, 1.0, 0.2, 1e-3)] * 20
        + [(60.0, 0.9, 48300.0, 30.0, -1.0, -0.1, 5e-4)] * 30 + [(40.0, 1.0, 48500.0, 25.0, -1.0, 0.3, 2e-4)] * 30),
    "end stop": (
        {"Slider.s0": 0.017, "Slider.v0": 0.05}, {},
        [(*_BASE, 1e-3)] * 40 + [(67.1, 1.0, 48500.0, 25.0, -1.0, 0.0, 1e-3)] * 20),
    "effects": (
        {"Slider.s0": -0.005, "Stator.thermal_tau_s": 0.02, "Stator.heating_K_per_V2": 1e-4,
         "Stator.df_dT_l_Hz_per_K": -10.0, "Stator.bar_wave_amp_m": 2e-6, "Stator.bar_bump_amp_m": 3e-6,
         "Stator.bar_bump_center_m": 0.0, "Slider.pulley_mu": 0.05, "Stator.T_st0": 30.0}, {},
        [(67.1, 1.0, 48500.0, 25.0, 1.0, 0.1, 1e-3)] * 60),
    "stator changed, forces beyond the baked cells": (
        {"Slider.s0": 0.004, "Stator.f_b0_Hz": 47900.0, "Stator.P0_N": 75.0, "Stator.density_kg_m3": 7900.0}, {},
        [(120.0, 1.0, 48500.0, 25.0, 1.0, 0.0, 1e-3)] * 30 + [(120.0, 1.0, 48500.0, 25.0, -1.0, 0.0, 1e-3)] * 20),
    "temperature-dependent B2, self-heating then a constant temperature": (
        {"Slider.s0": -0.006, "Stator.df_dT_b_Hz_per_K": -8.0, "Stator.thermal_tau_s": 0.02,
         "Stator.heating_K_per_V2": 1e-4, "Stator.df_dT_l_Hz_per_K": -10.0, "Stator.T_st0": 28.0}, {},
        [(67.1, 1.0, 48500.0, 25.0, 1.0, 0.05, 1e-3)] * 40 + [(67.1, 1.0, 48500.0, 31.0, -1.0, 0.0, 5e-4)] * 20),
    "temperature-dependent B2, constant temperature": (
        {"Slider.s0": 0.003, "Stator.df_dT_b_Hz_per_K": -8.0}, {},
        [(67.1, 1.0, 48500.0, 35.0, 1.0, 0.0, 1e-3)] * 30),
    "a supply ramped from zero under a load pulling the slider its way (an interface force held over a step)": (
        {"Slider.s0": -0.021}, {},
        [(67.1 * min(1.0, (k + 1) * 2e-4 / 0.07), 1.0, 48500.0, 25.0, 1.0, -0.09, 2e-4) for k in range(60)]),
    "pure slip": (
        {"Slider.s0": 0.0, "internal_step_s": 1e-4}, {"Interface.pure_slip": True},
        [(*_BASE, 1e-3)] * 40 + [(67.1, 1.0, 48500.0, 25.0, -1.0, 0.05, 2e-4)] * 30),
}


def worker_motor_runs(path, scenarios):
    """Per scenario: every Real variable after initialisation and after every step (fmpy, FMI 2 or 3)."""
    from fmpy import extract, read_model_description
    from l1b2.fmi.fmpy_slave import open_slave
    md = read_model_description(path)
    reals = [v.name for v in md.modelVariables
             if v.type in ("Real", "Float64") and v.causality in ("output", "local")]
    unz = extract(path)
    out = {"names": reals, "units": [next(v.unit for v in md.modelVariables if v.name == n) for n in reals]}
    ins = ("V_s", "duty", "f_s", "T", "direction", "m_load")
    for name, (params, booleans, run) in scenarios.items():
        with open_slave(path, unzipdir=unz, instance_name="m", params=params, booleans=booleans,
                        inputs=dict(zip(ins, run[0][:6]))) as sl:
            rows = [sl.get(reals)]
            t = 0.0
            for *u, h in run:
                sl.set(dict(zip(ins, u)))
                sl.step(t, h)
                t += h
                rows.append(sl.get(reals))
        out[name] = rows
    return out


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    from l1b2.fmi.native.build import NoCompilerError, python_and_native_fmus
    try:
        return python_and_native_fmus("L1B2Motor", tmp_path_factory.mktemp("native_motor"))
    except NoCompilerError as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def python_runs(fmus, isolated):
    return isolated(__file__, "worker_motor_runs", str(fmus["python"]), SCENARIOS).value


def test_native_motor_validates_and_declares_the_python_variables(fmus):
    # reference: fmpy validation; the Python FMU's modelDescription.xml read by fmpy
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    ref = {v.name: v for v in read_model_description(str(fmus["python"])).modelVariables}
    for ver in (2, 3):
        assert validate_fmu(str(fmus[ver])) == []
        got = {v.name: v for v in read_model_description(str(fmus[ver])).modelVariables
               if v.causality != "independent"}
        assert list(got) == list(ref)
        for name, r in ref.items():
            g = got[name]
            assert (g.valueReference, g.causality, g.variability, g.unit, g.min, g.max) == (
                r.valueReference, r.causality, r.variability, r.unit, r.min, r.max), name
            assert (g.start is None) == (r.start is None), name
            if r.start is not None:
                assert str(g.start).lower() == str(r.start).lower() or float(g.start) == float(r.start), name
        with zipfile.ZipFile(fmus[ver]) as z:
            names = z.namelist()
        assert {"sources/motor_model.c", "sources/motor_kernels.h", "sources/model_data.h"} <= set(names)


@pytest.mark.parametrize("ver", [2, 3])
def test_native_motor_equals_the_python_fmu(fmus, python_runs, ver, isolated):
    # reference: the Python L1B2Motor.fmu in fmpy (fresh process), same call sequences: every output and
    # sub-block variable after every step, 1e-9 relative; a quantity that is zero up to round-off (e.g. the cos
    # component of the normal force, +-1e-14 N) within 1e-12 of the largest value of its unit in the run
    got = worker_motor_runs(str(fmus[ver]), SCENARIOS)
    assert got["names"] == python_runs["names"]
    names, units = got["names"], got["units"]
    worst = 0.0
    for scenario in SCENARIOS:
        a, b = np.array(got[scenario]), np.array(python_runs[scenario])
        assert a.shape == b.shape
        for j, name in enumerate(names):
            same_unit = [i for i, u in enumerate(units) if u == units[j]]
            atol = 1e-12 * float(np.max(np.abs(b[:, same_unit])))
            np.testing.assert_allclose(a[:, j], b[:, j], rtol=1e-9, atol=atol, err_msg=f"{scenario}: {name}")
        for j, name in enumerate(names):  # relative difference where a value is not near a zero crossing
            scale = float(np.max(np.abs(b[:, [i for i, u in enumerate(units) if u == units[j]]])))
            big = np.abs(b[:, j]) > 1e-3 * scale
            if big.any():
                rel = float(np.max(np.abs(a[big, j] - b[big, j]) / np.abs(b[big, j])))
                worst = max(worst, rel)
                assert rel < 1e-9, (scenario, name, rel)
        v = b[:, names.index("v")]
        assert np.ptp(v) > 0.01, scenario  # the slider moves
        if scenario.startswith("stator changed"):
            assert np.min(b[:, names.index("Stator.P")]) > 70.0
        if scenario == "end stop":
            assert np.any(b[:, names.index("at_stop")] == 1.0)
        if scenario == "effects":
            assert b[-1, names.index("T_stator")] > 31.0
        if scenario.startswith("temperature-dependent B2, constant"):   # B2 at 35 degC: -8 Hz/K * 10 K
            ref = np.array(python_runs["end stop"])[0, names.index("Stator.f_b")]
            assert b[-1, names.index("Stator.f_b")] - ref == pytest.approx(-80.0, abs=5.0)
        if scenario.startswith("temperature-dependent B2, self-heating"):
            assert np.ptp(b[:, names.index("T_stator")]) > 1.0
    assert worst < 1e-9


def _slave(path):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    log = []
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, cat, msg: log.append((status, msg.decode())))
    cb.allocateMemory, cb.freeMemory = defaultCallbacks.allocateMemory, defaultCallbacks.freeMemory
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="m")
    fmu.instantiate(callbacks=cb)
    fmu.cb = cb  # keep the callbacks alive
    fmu.setupExperiment(startTime=0.0)
    return md, vr, fmu, log


def test_native_motor_status_rules_and_state(fmus):
    # reference: the Python FMUs' rules (l1b2.fmi.adapter): an input out of range -> Discard, refused until an
    # earlier FMU state is restored; the restored run repeats the first one exactly
    from fmpy.fmi1 import FMICallException
    md, vr, fmu, log = _slave(fmus[2])
    try:
        fmu.setReal([vr["V_s"], vr["Slider.s0"]], [67.1, -0.01])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(20):
            fmu.doStep(k * 2e-4, 2e-4)
        state = fmu.getFMUstate()
        blob = fmu.serializeFMUstate(state)
        first = []
        for k in range(20, 60):
            fmu.doStep(k * 2e-4, 2e-4)
            first.append(fmu.getReal([vr["v"], vr["s"], vr["F_d"], vr["Stator.Q_b_im"]]))
        fmu.setReal([vr["V_s"]], [5000.0])
        with pytest.raises(FMICallException) as exc:
            fmu.doStep(60 * 2e-4, 2e-4)
        assert exc.value.status == 2 and "V_s" in log[-1][1] and "above" in log[-1][1]
        fmu.setReal([vr["V_s"]], [67.1])
        with pytest.raises(FMICallException):
            fmu.doStep(60 * 2e-4, 2e-4)
        assert "refusing to step" in log[-1][1]
        fmu.setFMUstate(fmu.deSerializeFMUstate(blob))
        again = []
        for k in range(20, 60):
            fmu.doStep(k * 2e-4, 2e-4)
            again.append(fmu.getReal([vr["v"], vr["s"], vr["F_d"], vr["Stator.Q_b_im"]]))
        assert again == first
        with pytest.raises(FMICallException):
            fmu.getReal([100000])
        assert log[-1][0] == 3 and "100000" in log[-1][1]
        fmu.freeFMUstate(state)
    finally:
        fmu.terminate()
        fmu.freeInstance()


@pytest.mark.parametrize("name, value, words", [
    ("Slider.s0", 0.5, "outside the stroke"),
])
def test_native_motor_refuses_an_initialisation_it_cannot_simulate(fmus, name, value, words):
    # reference: SliderBlock.initialize (s0 outside the stroke); the scope of the native motor (l1b2.fmi.native.build)
    from fmpy.fmi1 import FMICallException
    md, vr, fmu, log = _slave(fmus[2])
    try:
        fmu.setReal([vr[name]], [value])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        assert log[-1][0] == 3 and "initialisation failed" in log[-1][1] and words in log[-1][1]
        with pytest.raises(FMICallException) as exc:
            fmu.doStep(0.0, 2e-4)
        assert exc.value.status == 2
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_native_motor_runs_in_c_host_with_empty_environment(fmus, tmp_path):
    # reference: the same call sequence in fmpy (worker_motor_runs), bit-identical: the same library
    from fmpy import read_model_description
    from l1b2.fmi.runtime import compile_c_host
    host = compile_c_host(tmp_path / "fmu_host")
    unz = tmp_path / "native motor"
    with zipfile.ZipFile(fmus[2]) as z:
        z.extractall(unz)
    md = read_model_description(str(fmus[2]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = ["v", "s", "F_d", "U_w", "at_stop"]
    n = 50
    u = dict(zip(("V_s", "duty", "f_s", "T", "direction", "m_load"), _BASE))
    args = ["env", "-i", str(host), "-L", "-", "-x", "plain", "-h", "0.0002", "-n", str(n),
            "-p", f"{vr['Slider.s0']}=-0.01"]
    for k, x in u.items():
        args += ["-i", f"{vr[k]}={x!r}"]
    for k in outs:
        args += ["-o", str(vr[k])]
    proc = subprocess.run(args + [str(unz), md.coSimulation.modelIdentifier, md.guid], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    got = np.array([[float(x) for x in line.split()] for line in proc.stdout.splitlines() if line.strip()])
    ref = worker_motor_runs(str(fmus[2]), {"run": ({"Slider.s0": -0.01}, {}, [(*_BASE, 2e-4)] * n)})
    names = ref["names"]
    want = np.array(ref["run"])[:, [names.index(k) for k in outs]]
    assert got.shape == (n + 1, len(outs) + 1)
    assert np.array_equal(got[:, 1:], want)
    assert got[-1, 1] > 0.05


@pytest.mark.parametrize("ver", [2, 3])
def test_native_motor_source_fmu_rebuilds_from_its_sources(fmus, ver, tmp_path):
    # reference: the FMU's own build information (FMI 2.0: <SourceFiles> in modelDescription.xml; FMI 3.0:
    # sources/buildDescription.xml) and nothing else: the rebuilt library gives the shipped one's numbers exactly
    import shutil as sh
    from fmpy import read_model_description
    unz = tmp_path / "fmu"
    with zipfile.ZipFile(fmus[ver]) as z:
        z.extractall(unz)
    md = read_model_description(str(unz))
    bc = md.buildConfigurations[0]
    files = bc.sourceFileSets[0].sourceFiles
    assert files and bc.modelIdentifier == md.coSimulation.modelIdentifier
    platform = "linux64" if ver == 2 else "x86_64-linux"
    lib = unz / "binaries" / platform / f"{bc.modelIdentifier}.so"
    shipped = worker_motor_runs(str(fmus[ver]), {"run": ({"Slider.s0": -0.01}, {}, [(*_BASE, 2e-4)] * 30)})
    lib.unlink()
    cc = sh.which("cc") or sh.which("gcc")
    subprocess.run([cc, "-shared", "-fPIC", "-O2", "-std=c99", f"-I{unz / 'sources'}", "-o", str(lib),
                    *(str(unz / "sources" / f) for f in files), "-lm"], check=True)
    repacked = tmp_path / fmus[ver].name
    with zipfile.ZipFile(repacked, "w") as z:
        for p in unz.rglob("*"):
            if p.is_file():
                z.write(p, p.relative_to(unz).as_posix())
    rebuilt = worker_motor_runs(str(repacked), {"run": ({"Slider.s0": -0.01}, {}, [(*_BASE, 2e-4)] * 30)})
    assert rebuilt["run"] == shipped["run"]


def test_native_motor_fmi3_state_round_trip(fmus):
    # reference: the run continued without a restore (FMI 3.0 get/serialize/deserialize/set FMU state)
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave
    md = read_model_description(str(fmus[3]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmus[3])), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="m3")
    fmu.instantiate()
    try:
        fmu.setFloat64([vr["V_s"], vr["Slider.s0"], vr["m_load"]], [67.1, -0.01, 0.1])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(15):
            fmu.doStep(k * 2e-4, 2e-4)
        blob = fmu.serializeFMUState(fmu.getFMUState())
        outs = [vr[k] for k in ("v", "s", "U_w", "Slider.a", "time")]
        first = []
        for k in range(15, 40):
            fmu.doStep(k * 2e-4, 2e-4)
            first.append(fmu.getFloat64(outs))
        fmu.setFMUState(fmu.deserializeFMUState(blob))
        again = []
        for k in range(15, 40):
            fmu.doStep(k * 2e-4, 2e-4)
            again.append(fmu.getFloat64(outs))
        assert again == first and first[-1][0] > 0.01
        assert first[-1][-1] == pytest.approx(40 * 2e-4)  # the independent variable time
        fmu.terminate()
    finally:
        fmu.freeInstance()


def test_native_motor_bounds_the_internal_steps_like_the_python_fmu(fmus):
    # reference: MotorBlock.MAX_SUBSTEPS where the block declares one (a step needing more internal steps is an
    # error of the step: Discard, reason logged); without it, a step of 10 internal steps runs
    from fmpy.fmi1 import FMICallException
    from l1b2.cosim.composite import MotorBlock
    md, vr, fmu, log = _slave(fmus[2])
    limit = getattr(MotorBlock, "MAX_SUBSTEPS", None)
    try:
        fmu.setReal([vr["V_s"], vr["internal_step_s"]], [67.1, 1e-5])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 1e-4)
        assert fmu.getReal([vr["v"]])[0] > 0.0
        if limit is not None:
            h = min(1e-5 * (limit + 10), getattr(MotorBlock, "MAX_STEP_S", 1.0))
            if h / 1e-5 > limit:
                with pytest.raises(FMICallException) as exc:
                    fmu.doStep(1e-4, h)
                assert exc.value.status == 2 and f"more than {limit}" in log[-1][1]
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_cells_built_at_run_time_equal_the_modal_tables(fmus, tmp_path):
    # reference: l1b2.physics.stator.ModalTable.cell_array for the same stator parameters (the reference
    # stator and a changed one): the interpolants (B2 frequency, tip coefficient) over the cell within 1e-14
    # relative (the coefficients differ in the last bits: numpy sums the matrix product through BLAS)
    import ctypes
    import shutil as sh
    from fmpy import read_model_description
    from l1b2.physics import stator as st
    from l1b2.physics.params import load_motor
    unz = tmp_path / "fmu"
    with zipfile.ZipFile(fmus[2]) as z:
        z.extractall(unz)
    src = unz / "sources"
    lib = tmp_path / "cells.so"
    cc = sh.which("cc") or sh.which("gcc")
    subprocess.run([cc, "-shared", "-fPIC", "-O2", "-std=c99", "-ffp-contract=off", f"-I{src}", "-o", str(lib),
                    str(src / "modal_cell.c"), str(src / "fmu_core.c"), str(src / "motor_model.c"), "-lm"],
                   check=True)
    build = ctypes.CDLL(str(lib)).modal_cell_build
    dbl = ctypes.POINTER(ctypes.c_double)
    build.argtypes = [dbl, ctypes.c_double, dbl, ctypes.c_char_p]
    md = read_model_description(str(fmus[2]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    base = load_motor().stator
    for sp in (base, base.__class__(**{**base.__dict__, "f_b0_Hz": 47900.0, "density_kg_m3": 7900.0})):
        r = np.zeros(len(md.modelVariables))
        for name in ("width_m", "thickness_m", "density_kg_m3", "length_m", "f_b0_Hz", "df_dT_b_Hz_per_K"):
            r[vr[f"Stator.{name}"]] = getattr(sp, name)
        table = st.ModalTable(sp, None)
        for k in (0, 6, 7, 59, 60, 75, 300):
            want = table.cell_array(k)
            got = np.zeros_like(want)
            msg = ctypes.create_string_buffer(600)
            assert build(r.ctypes.data_as(dbl), float(k), got.ctypes.data_as(dbl), msg) == 0, msg.value
            u = np.linspace(-1.0, 1.0, 41)
            for j in (0, 1):
                np.testing.assert_allclose(np.polyval(got[:, j], u), np.polyval(want[:, j], u), rtol=1e-14, atol=0,
                                           err_msg=f"cell {k}, column {j}")
