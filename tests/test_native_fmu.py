"""Native (C) FMUs, FMI 2.0 and 3.0: same variables and outputs as the Python FMUs, no Python at run time.

The Python FMU of the same name is the reference: the native FMU is built from
its modelDescription.xml (l1b2.fmi.native.build) and run through the same call
sequences in fmpy; the C host (l1b2/fmi/chost/fmu_host.c) runs it with an empty
environment.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import zipfile

import numpy as np
import pytest

pytestmark = pytest.mark.fmu

H = 1e-3
#: (V0, s, load, direction, h): a run with input changes, stuck phases, reversals and sub-stepped steps
RUN = ([(324.0, -0.010, 0.05, 1.0, 1e-3)] * 40 + [(260.0, 0.004, -0.03, -1.0, 2.5e-3)] * 30
       + [(40.0, 0.0, 0.0, 1.0, 2e-4)] * 20 + [(324.0, 0.015, 0.35, 1.0, 1e-3)] * 25
       + [(500.0, -0.018, -0.2, -1.0, 3e-3)] * 20 + [(324.0, 0.019, 0.0, 1.0, 1e-3)] * 10)
#: parameter sets (name -> value) set before initialisation, each run over RUN
PARAMS = [{}, {"v0": -0.12, "load_inertia": 0.0, "kappa": 0.8}, {"v0": 0.3, "T_s": 2.5e-4, "s_half": 0.025}]


def worker_run(path, params, run):
    """Outputs ``v, v_steady`` after initialisation and after every step of ``run`` (fmpy, FMI 2 or 3)."""
    from l1b2.fmi.fmpy_slave import open_slave
    ins = ("V0", "s", "load", "direction")
    with open_slave(path, instance_name="p", params=params, inputs=dict(zip(ins, run[0][:4]))) as sl:
        rows = [sl.get(("v", "v_steady"))]
        t = 0.0
        for V0, s, load, d, h in run:
            sl.set(dict(zip(ins, (V0, s, load, d))))
            sl.step(t, h)
            t += h
            rows.append(sl.get(("v", "v_steady")))
    return rows


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """``{"python": path, 2: path, 3: path}`` of the Predictor FMUs (physical linearisation of the reference motor)."""
    from l1b2.fmi.native.build import NoCompilerError, python_and_native_fmus
    try:
        return python_and_native_fmus("Predictor", tmp_path_factory.mktemp("native"))
    except NoCompilerError as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def python_rows(fmus, isolated):
    return [isolated(__file__, "worker_run", str(fmus["python"]), p, RUN).value for p in PARAMS]


def test_native_fmus_validate_and_carry_sources_and_binary(fmus):
    # reference: fmpy validation (FMI 2.0 and 3.0 schemas and rules), the FMI 3.0 buildDescription.xml,
    # and the library's dynamic dependencies (readelf): no libpython
    from fmpy.validation import validate_fmu
    for v in (2, 3):
        assert validate_fmu(str(fmus[v])) == []
        with zipfile.ZipFile(fmus[v]) as z:
            names = z.namelist()
        assert "sources/predictor_model.c" in names and "sources/model_data.h" in names
        platform = "linux64" if v == 2 else "x86_64-linux"
        assert f"binaries/{platform}/Predictor_native.so" in names
        assert ("sources/buildDescription.xml" in names) == (v == 3)
        assert not any(n.endswith(".py") for n in names)


def test_native_library_needs_no_python(fmus, tmp_path):
    # reference: the NEEDED entries of the ELF dynamic section (readelf -d)
    if shutil.which("readelf") is None:
        pytest.skip("no readelf")
    with zipfile.ZipFile(fmus[2]) as z:
        z.extract("binaries/linux64/Predictor_native.so", tmp_path)
    out = subprocess.run(["readelf", "-d", str(tmp_path / "binaries/linux64/Predictor_native.so")],
                         capture_output=True, text=True, check=True).stdout
    needed = [line.split("[")[1].rstrip("]") for line in out.splitlines() if "(NEEDED)" in line]
    assert needed and all(n.startswith(("libm.so", "libc.so")) for n in needed), needed


def test_native_fmus_declare_the_python_fmus_variables(fmus):
    # reference: the Python FMU's modelDescription.xml read by fmpy
    from fmpy import read_model_description
    ref = {v.name: v for v in read_model_description(str(fmus["python"])).modelVariables}
    for ver in (2, 3):
        md = read_model_description(str(fmus[ver]))
        got = {v.name: v for v in md.modelVariables if v.causality != "independent"}
        assert list(got) == list(ref)
        for name, r in ref.items():
            g = got[name]
            assert (g.valueReference, g.causality, g.variability, g.unit, g.min, g.max, g.nominal,
                    g.description) == (r.valueReference, r.causality, r.variability, r.unit, r.min, r.max,
                                       r.nominal, r.description), name
            assert (g.start is None) == (r.start is None) and (
                g.start is None or float(g.start) == float(r.start)), name
        assert md.guid != read_model_description(str(fmus["python"])).guid


@pytest.mark.parametrize("ver", [2, 3])
def test_native_outputs_equal_the_python_fmus(fmus, python_rows, ver):
    # reference: the Python Predictor.fmu in fmpy, same call sequence (input changes, stuck phases,
    # reversals, sub-stepped steps, three parameter sets): 1e-9 relative
    worst = 0.0
    for params, want in zip(PARAMS, python_rows):
        got = np.array(worker_run(str(fmus[ver]), params, RUN))
        want = np.array(want)
        assert got.shape == want.shape == (len(RUN) + 1, 2)
        assert np.array_equal(np.isnan(got), np.isnan(want))
        ok = ~np.isnan(want)
        np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-15)
        scale = np.maximum(np.abs(want[ok]), 1e-300)
        worst = max(worst, float(np.max(np.abs(got[ok] - want[ok]) / scale)))
        assert np.ptp(want[:, 0]) > 0.1  # the runs move
    assert worst < 1e-9


def _native_slave(path, instance="n"):
    """``(md, vr, fmu, log)``: an FMI 2.0 slave of the native FMU instantiated with a logger that keeps
    ``(status, message)``."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    log = []
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=instance)
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, cat, msg: log.append((status, msg.decode())))
    cb.allocateMemory = fmpy_calloc()
    cb.freeMemory = fmpy_free()
    fmu.cb = cb
    return md, vr, fmu, log


def fmpy_calloc():
    from fmpy.fmi2 import defaultCallbacks
    return defaultCallbacks.allocateMemory


def fmpy_free():
    from fmpy.fmi2 import defaultCallbacks
    return defaultCallbacks.freeMemory


def test_native_status_rules(fmus):
    # reference: the Python FMUs' rules (l1b2.fmi.adapter): bad value reference -> Error with a log line;
    # non-finite or out-of-range input -> Discard, then refused until an earlier state is restored
    from fmpy.fmi1 import FMICallException
    md, vr, fmu, log = _native_slave(fmus[2])
    fmu.instantiate(callbacks=fmu.cb)
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        with pytest.raises(FMICallException):
            fmu.getReal([9999])
        assert log[-1][0] == 3 and "9999" in log[-1][1]
        fmu.doStep(0.0, H)
        state = fmu.getFMUstate()
        v1 = fmu.getReal([vr["v"]])[0]
        fmu.setReal([vr["V0"]], [math.nan])
        with pytest.raises(FMICallException) as exc:
            fmu.doStep(H, H)
        assert exc.value.status == 2 and "V0" in log[-1][1] and "not finite" in log[-1][1]
        fmu.setReal([vr["V0"]], [324.0])
        with pytest.raises(FMICallException):
            fmu.doStep(H, H)                      # still refused: the error stands
        assert "refusing to step" in log[-1][1]
        fmu.setReal([vr["s"]], [1.5])             # out of range [-1, 1]
        fmu.setFMUstate(state)                    # the state before the error
        fmu.setReal([vr["V0"], vr["s"]], [324.0, 0.0])
        fmu.doStep(H, H)
        assert fmu.getReal([vr["v"]])[0] > v1
        fmu.setReal([vr["direction"]], [0.5])
        with pytest.raises(FMICallException):
            fmu.doStep(2 * H, H)
        assert "must be +1 or -1" in log[-1][1]
        fmu.freeFMUstate(state)
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_native_rejects_a_wrong_guid(fmus):
    # reference: FMI 2.0 fmi2Instantiate returns NULL for a GUID that is not the FMU's
    md, vr, fmu, log = _native_slave(fmus[2])
    fmu.guid = "{00000000-0000-0000-0000-000000000000}"
    with pytest.raises(Exception):
        fmu.instantiate(callbacks=fmu.cb)
    assert not fmu.component
    assert "does not match" in log[-1][1]
    fmu.freeLibrary()


def test_native_serialised_state_restarts_the_run(fmus):
    # reference: the run continued without a restore (same steps, same inputs): bit-identical
    md, vr, fmu, log = _native_slave(fmus[2])
    fmu.instantiate(callbacks=fmu.cb)
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(10):
            fmu.doStep(k * H, H)
        blob = fmu.serializeFMUstate(fmu.getFMUstate())
        first = []
        for k in range(10, 30):
            fmu.setReal([vr["load"]], [0.01 * (k % 3)])
            fmu.doStep(k * H, H)
            first.append(fmu.getReal([vr["v"], vr["v_steady"]]))
        fmu.setFMUstate(fmu.deSerializeFMUstate(blob))
        again = []
        for k in range(10, 30):
            fmu.setReal([vr["load"]], [0.01 * (k % 3)])
            fmu.doStep(k * H, H)
            again.append(fmu.getReal([vr["v"], vr["v_steady"]]))
        assert again == first
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_native_fmu_runs_in_c_host_with_empty_environment(fmus, tmp_path):
    # reference: the same call sequence in fmpy (worker_run), bit-identical: the same library
    from fmpy import read_model_description
    from l1b2.fmi.runtime import compile_c_host
    host = compile_c_host(tmp_path / "fmu_host")
    unz = tmp_path / "native fmu"
    with zipfile.ZipFile(fmus[2]) as z:
        z.extractall(unz)
    md = read_model_description(str(fmus[2]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    V0, s, load, d, h = RUN[0]
    n = 40
    args = ["env", "-i", str(host), "-L", "-", "-x", "plain", "-h", repr(h), "-n", str(n),
            "-i", f"{vr['V0']}={V0!r}", "-i", f"{vr['s']}={s!r}", "-i", f"{vr['load']}={load!r}",
            "-i", f"{vr['direction']}={d!r}", "-o", str(vr["v"]), "-o", str(vr["v_steady"]),
            str(unz), md.coSimulation.modelIdentifier, md.guid]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    got = np.array([[float(x) for x in line.split()] for line in proc.stdout.splitlines() if line.strip()])
    want = np.array(worker_run(str(fmus[2]), {}, RUN[:n]))
    assert got.shape == (n + 1, 3)
    assert np.array_equal(got[:, 1:], want)


def test_native_refuses_sets_the_python_fmus_refuse(fmus):
    # reference: the Python FMUs' set rules (FMI 2.0, 3.2.3): an output, a fixed parameter after initialisation,
    # a parameter value that is not finite or outside its declared range -> Error, the whole call refused
    from fmpy.fmi1 import FMICallException
    from l1b2.cosim.composite import PredictorBlock
    md, vr, fmu, log = _native_slave(fmus[2])
    fmu.instantiate(callbacks=fmu.cb)
    try:
        fmu.setupExperiment(startTime=0.0)
        for names, values, words in ((["v"], [1.0], "is an output"),
                                     (["V0", "s_half"], [300.0, math.nan], "not finite"),
                                     (["kappa"], [1.5], "outside its declared range")):
            with pytest.raises(FMICallException) as exc:
                fmu.setReal([vr[n] for n in names], values)
            assert exc.value.status == 3 and words in log[-1][1]
        assert fmu.getReal([vr["V0"], vr["s_half"], vr["kappa"]]) == [324.0, 0.02, 0.5]  # nothing was set
        fmu.setReal([vr["kappa"]], [0.6])                                                 # before initialisation
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        with pytest.raises(FMICallException):
            fmu.setReal([vr["kappa"]], [0.7])
        assert "fixed parameter" in log[-1][1]
        fmu.setReal([vr["V0"]], [250.0])                                                  # inputs may change
        fmu.doStep(0.0, H)
        limit = getattr(PredictorBlock, "MAX_STEP_S", None)
        if limit is not None:  # a step above the FMU's maximum is refused, the instance stays usable
            with pytest.raises(FMICallException) as exc:
                fmu.doStep(H, 2 * limit)
            assert exc.value.status == 2 and "above this FMU's maximum" in log[-1][1]
            fmu.doStep(H, H)
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_extended_predictor_of_a_family_without_kernel_stays_a_python_fmu(tmp_path):
    # reference: l1b2.predictor.effects.kernels.KERNEL_KINDS; a family registered outside the package (a toy one
    # here) has no per-sample kernel, so no native FMU is built and the export says which effect and why
    import numpy as np
    from l1b2.fmi.build import build_fmu
    from l1b2.fmi.native.build import NativeBuildError, build_native_fmu, build_native_set
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import ExtendedPredictor, IdentifiedEffect
    from l1b2.predictor.model import example_params
    from l1b2.predictor.setup import PredictorSetup

    toy_src = ("import numpy as np\nfrom ..base import Effect, drive_gain\n\n\nclass Toy(Effect):\n"
               "    kind = 'toy_native_test'\n    regressor = 'voltage'\n\n    def features(self, spec, x):\n"
               "        return drive_gain(x)[:, None] ** 4\n")
    scope = {}
    exec(toy_src.replace("from ..base import", "from l1b2.predictor.effects.base import"), scope)
    fx.register(scope["Toy"])
    try:
        base = PredictorSetup(example_params(), 0.1, 1e-3)
        eff = IdentifiedEffect("toy_native_test", "toy", {"kind": "toy_native_test"}, ("toy_N",), ("N",), (0.1,),
                               (0.01,))
        ext = ExtendedPredictor(base, base, (eff,), {"a": 0.5, "b0": 0.3, "b1": 0.2})
        py = build_fmu("Predictor", tmp_path, extra_defaults={"predictor": base.to_dict(),
                                                              "extended_predictor": ext.to_dict()},
                       extra_files={"predictor/effects/plugins/toy_native.py": toy_src.encode()})
        with pytest.raises(NativeBuildError, match="effect toy: .*no per-sample kernel"):
            build_native_fmu("Predictor", py, tmp_path, 2)
        built, info = build_native_set("Predictor", py, tmp_path)
        assert built == {} and info["included"] is False and "toy_native_test" in info["reason"]
        assert not list(tmp_path.glob("*-native*.fmu"))
        assert np.isfinite(fx.effect_features(eff.spec, {"V0": np.ones(2)})).all()
    finally:
        fx.unregister("toy_native_test")


def test_native_refuses_a_state_of_another_fmu(fmus, tmp_path):
    # reference: FMI 2.0 fmi2SetFMUstate takes a state of the same FMU; another FMU's state (here a Predictor with
    # other parameters, hence another GUID) is refused with Error, in memory and serialised, the instance unchanged
    from fmpy.fmi1 import FMICallException
    from l1b2.fmi.build import build_fmu
    from l1b2.fmi.native.build import build_native_fmu
    from l1b2.predictor.model import example_params
    from l1b2.predictor.setup import PredictorSetup
    other_py = build_fmu("Predictor", tmp_path, extra_defaults={
        "predictor": PredictorSetup(example_params(), 0.1, 1e-3).to_dict()})
    other = build_native_fmu("Predictor", other_py, tmp_path, 2)
    _, vr_o, fmu_o, _ = _native_slave(other, "other")
    md, vr, fmu, log = _native_slave(fmus[2])
    fmu_o.instantiate(callbacks=fmu_o.cb)
    fmu.instantiate(callbacks=fmu.cb)
    try:
        for f in (fmu, fmu_o):
            f.setupExperiment(startTime=0.0)
            f.enterInitializationMode()
            f.exitInitializationMode()
            f.doStep(0.0, H)
        foreign = fmu_o.getFMUstate()
        blob = fmu_o.serializeFMUstate(foreign)
        before = fmu.getReal([vr["v"], vr["v_steady"]])
        with pytest.raises(FMICallException):
            fmu.setFMUstate(foreign)
        assert "not one of this FMU" in log[-1][1]
        with pytest.raises(FMICallException):
            fmu.deSerializeFMUstate(blob)
        assert fmu.getReal([vr["v"], vr["v_steady"]]) == before
        fmu.doStep(H, H)
        fmu_o.freeFMUstate(foreign)
    finally:
        for f in (fmu, fmu_o):
            f.terminate()
            f.freeInstance()


def test_open_slave_terminates_on_success_and_frees_on_every_path(fmus, monkeypatch):
    from fmpy.fmi2 import FMU2Slave
    from l1b2.fmi.fmpy_slave import open_slave
    calls = []
    for name in ("terminate", "freeInstance"):
        orig = getattr(FMU2Slave, name)
        monkeypatch.setattr(FMU2Slave, name, lambda self, _o=orig, _n=name: (calls.append(_n), _o(self))[1])
    with open_slave(fmus[2], params={"v0": 0.05}, inputs={"V0": 324.0}) as sl:
        assert sl.get(["v"]) == [pytest.approx(0.05)]
        sl.step(0.0, 1e-3)
    assert calls == ["terminate", "freeInstance"]
    calls.clear()
    with pytest.raises(RuntimeError, match="master failed"):
        with open_slave(fmus[2]) as sl:
            sl.step(0.0, 1e-3)
            raise RuntimeError("master failed")
    assert calls == ["freeInstance"]                # not terminated after an error, but freed
    with pytest.raises(KeyError, match="no_such_input"):
        with open_slave(fmus[2], inputs={"no_such_input": 1.0}):
            pass
    assert calls == ["freeInstance"] * 2
