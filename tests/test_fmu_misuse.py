"""FMI misuse as a host would commit it: every call refused with the right status, no crash, no hang.

The cases of one FMU run in one fresh Python process (``isolated``), each
on its own instance, through fmpy's low-level FMI 2.0 API, so a
segmentation fault or an abort is seen as the worker's exit code and a hang
as its timeout. The worker records the status
of every call (0 OK, 2 Discard, 3 Error, "null" for an instantiation that
returned NULL) and the FMU's log lines; the tests check the status FMI 2.0
requires, that the log names the problem, and that the instance is still
usable afterwards (a good call returns fmi2OK and right values) and can be
freed. Reference: FMI 2.0.4, sections 2.1.3 (status), 2.1.5 (instantiation,
GUID), 2.1.7 (fmi2SetReal rules, Table 2.2), 2.1.8 (FMU state), 4.2.2
(fmi2DoStep).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.fmu

H = 2e-4
TIMEOUT_S = 120


# ---------------------------------------------------------------------------
# Worker side (fresh process)
# ---------------------------------------------------------------------------

class _Host:
    """One FMU instance driven through fmpy's low-level calls; records statuses instead of raising."""

    def __init__(self, path, guid=None, drop=None, name="misuse"):
        from ctypes import byref
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

        self.md = read_model_description(path)
        self.dir = extract(path)
        if drop:
            shutil.rmtree(Path(self.dir) / drop)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.var = {v.name: v for v in self.md.modelVariables}
        self.log = []

        def logger(env, instance, status, category, message):
            self.log.append((int(status), message.decode("utf-8", "replace")))

        self._cb_logger = fmi2CallbackLoggerTYPE(logger)
        from fmpy.fmi2 import defaultCallbacks
        cb = fmi2CallbackFunctions()
        cb.logger = self._cb_logger
        cb.allocateMemory = defaultCallbacks.allocateMemory
        cb.freeMemory = defaultCallbacks.freeMemory
        self.callbacks = cb
        self.fmu = FMU2Slave(guid=guid or self.md.guid, unzipDirectory=self.dir, instanceName=name,
                             modelIdentifier=self.md.coSimulation.modelIdentifier)
        self.byref = byref

    def call(self, method, *args):
        """Status of ``fmu.method(*args)`` (fmpy raises FMICallException above fmi2Warning)."""
        from fmpy.fmi1 import FMICallException
        try:
            value = getattr(self.fmu, method)(*args)
            return 0, value
        except FMICallException as exc:
            return int(exc.status), None

    def instantiate(self, logging=False):
        try:
            self.fmu.instantiate(callbacks=self.callbacks, loggingOn=logging)
            return 0
        except Exception:  # noqa: BLE001 - fmpy raises a plain Exception for NULL
            return "null"

    def init(self, **params):
        assert self.instantiate() == 0, self.log
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for k, v in params.items():
            self.fmu.setReal([self.vr[k]], [v])
        self.fmu.exitInitializationMode()

    def get(self, name):
        return self.fmu.getReal([self.vr[name]])[0]

    def errors(self):
        return [m for s, m in self.log if s >= 3]

    def close(self):
        try:
            self.fmu.terminate()
        except Exception:  # noqa: BLE001 - terminating after a refused call may itself be refused
            pass
        self.fmu.freeInstance()
        shutil.rmtree(self.dir, ignore_errors=True)


def _output(md):
    return next(v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real")


def _input(md):
    return next(v.name for v in md.modelVariables if v.causality == "input" and v.type == "Real")


def _fixed_param(md):
    return next(v.name for v in md.modelVariables
                if v.causality == "parameter" and v.variability == "fixed" and v.type == "Real")


def worker_case(path, case, other=None):
    h = _Host(path)
    out = {"case": case}
    if case == "unknown_vr":
        h.init()
        bad = 10_000
        out["get1"], _ = h.call("getReal", [bad])
        out["get2"], _ = h.call("getReal", [bad, h.vr[_output(h.md)]])
        out["set"], _ = h.call("setReal", [bad], [1.0])
        out["get_int"], _ = h.call("getInteger", [bad])
        out["set_bool"], _ = h.call("setBoolean", [bad], [True])
        out["after_get"], value = h.call("getReal", [h.vr[_output(h.md)]])
        out["after_value"] = value[0] if value else None
        out["after_step"], _ = h.call("doStep", 0.0, H)
    elif case == "nan_parameter":
        assert h.instantiate() == 0
        h.fmu.setupExperiment(startTime=0.0)
        h.fmu.enterInitializationMode()
        name = _fixed_param(h.md)
        out["param"] = name
        out["before"] = h.get(name)
        out["set1"], _ = h.call("setReal", [h.vr[name]], [math.nan])
        out["set2"], _ = h.call("setReal", [h.vr[name]], [math.nan])
        out["after"] = h.get(name)
        out["exit"], _ = h.call("exitInitializationMode")
        out["step"], _ = h.call("doStep", 0.0, H)
    elif case == "huge_step":
        h.init()
        out["limit"] = float(_max_step(path))
        out["step"], _ = h.call("doStep", 0.0, 1e6)
        out["after_step"], _ = h.call("doStep", 0.0, H)
    elif case == "output_set":
        h.init()
        name = _output(h.md)
        before = h.get(name)
        out["set"], _ = h.call("setReal", [h.vr[name]], [before + 123.0])
        out["changed"] = h.get(name) != before
        out["after_step"], _ = h.call("doStep", 0.0, H)
    elif case == "fixed_after_init":
        h.init()
        name = _fixed_param(h.md)
        before = h.get(name)
        out["set"], _ = h.call("setReal", [h.vr[name]], [before * 1.01 if before else 1e-3])
        out["changed"] = h.get(name) != before
        out["after_step"], _ = h.call("doStep", 0.0, H)
    elif case == "time_backwards":
        h.init()
        out["step1"], _ = h.call("doStep", 0.0, H)
        out["step2"], _ = h.call("doStep", H, H)
        out["back"], _ = h.call("doStep", 0.0, H)
        out["after_step"], _ = h.call("doStep", 2 * H, H)
    elif case == "foreign_state":
        g = _Host(other, name="other")
        g.init()
        h.init()
        out["step"], _ = h.call("doStep", 0.0, H)
        name = _output(h.md)
        before = h.get(name)
        foreign = g.fmu.getFMUstate()
        out["set"], _ = h.call("setFMUstate", foreign)
        out["changed"] = h.get(name) != before
        g.fmu.freeFMUstate(foreign)
        garbage = b"not a state of this FMU" * 3
        out["deser"], _ = h.call("deSerializeFMUstate", garbage)
        out["after_step"], _ = h.call("doStep", H, H)
        g.close()
    elif case == "setup_after_init":
        h.init()
        out["setup"], _ = h.call("setupExperiment", None, 0.0)
        out["after_step"], _ = h.call("doStep", 0.0, H)
    elif case == "after_free":
        h.init()
        c = h.fmu.component
        h.fmu.fmi2FreeInstance(c)
        h.fmu.fmi2FreeInstance(c)                        # twice: nothing
        out["step_freed"], _ = h.call("fmi2DoStep", c, 0.0, H, 1)
        out["get_freed"], _ = h.call("getReal", [0])
        out["log"] = h.errors()
        h.fmu.freeLibrary()
        shutil.rmtree(h.dir, ignore_errors=True)
        out["freed"] = True
        return out
    elif case == "wrong_guid":
        h.close()
        h = _Host(path, guid="{00000000-0000-0000-0000-000000000000}")
        out["instantiate"] = h.instantiate()
        out["log"] = h.errors()
        shutil.rmtree(h.dir, ignore_errors=True)
        return out
    elif case == "no_resources":
        h.close()
        h = _Host(path, drop="resources")
        out["instantiate"] = h.instantiate()
        out["log"] = h.errors()
        shutil.rmtree(h.dir, ignore_errors=True)
        return out
    else:
        raise ValueError(case)
    out["log"] = h.errors()
    h.close()
    out["freed"] = True
    return out


#: every case, in the order one worker runs them on one FMU ("after_free" unloads the library: last)
CASES = ("unknown_vr", "nan_parameter", "huge_step", "output_set", "fixed_after_init", "time_backwards",
         "foreign_state", "setup_after_init", "wrong_guid", "no_resources", "after_free")


def worker_all(path, other):
    """Every case on one FMU in this process (each with its own instance); a Python error is recorded."""
    out = {}
    for case in CASES:
        try:
            out[case] = worker_case(path, case, other)
        except Exception as exc:  # noqa: BLE001 - recorded: the test of that case fails with it
            out[case] = {"error": repr(exc)}
    return out


def _max_step(path):
    import zipfile
    import xml.etree.ElementTree as ET
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    return root.find("VendorAnnotations/Tool[@name='l1b2']/Limits").get("maxCommunicationStepSize")


# ---------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def all_fmus(fmus, tmp_path_factory):
    from l1b2.fmi.build import build_fmu
    dest = tmp_path_factory.mktemp("misuse_fmus")
    return {**fmus, "Predictor": build_fmu("Predictor", dest), "L1B2Motor": build_fmu("L1B2Motor", dest)}


_RESULTS: dict[str, object] = {}
ALL = ("Driver", "Stator", "Interface", "Slider", "Predictor", "L1B2Motor")


def _run(isolated, all_fmus, name, case):
    """The result of ``case`` on FMU ``name``: all cases run once per FMU in one fresh process."""
    path = all_fmus[name]
    key = str(path)
    if key not in _RESULTS:
        other = all_fmus["Slider" if name == "Stator" else "Stator"]   # the foreign state's FMU
        _RESULTS[key] = isolated(__file__, "worker_all", key, str(other), timeout=TIMEOUT_S * len(CASES),
                                 check=False)
    res = _RESULTS[key]
    assert res.returncode == 0 and res.value is not None, (
        f"{Path(path).name}: worker exited with {res.returncode} (negative = signal, -11 = segfault, "
        f"None = hang)\n{res.stderr[-2000:]}")
    r = res.value[case]
    assert "error" not in r, r
    return r


@pytest.mark.parametrize("name", ALL)
def test_unknown_value_references_are_errors_and_the_instance_stays_usable(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "unknown_vr")
    assert (r["get1"], r["get2"], r["set"], r["get_int"], r["set_bool"]) == (3, 3, 3, 3, 3), r
    assert r["after_get"] == 0 and math.isfinite(r["after_value"]), r
    assert r["after_step"] == 0 and r["freed"], r
    assert any("unknown value reference 10000" in m for m in r["log"]), r["log"]


@pytest.mark.parametrize("name", ALL)
def test_nan_parameter_in_initialisation_is_an_error_and_leaves_the_value(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "nan_parameter")
    assert (r["set1"], r["set2"]) == (3, 3), r
    assert r["after"] == r["before"], r           # the refused value did not stick
    assert r["exit"] == 0 and r["step"] == 0 and r["freed"], r
    assert any(r["param"] in m and "not finite" in m for m in r["log"]), r["log"]


@pytest.mark.parametrize("name", ALL)
def test_a_step_beyond_the_declared_maximum_is_discarded_and_returns(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "huge_step")
    assert r["limit"] < 1e6
    assert r["step"] == 2, r                         # fmi2Discard, at once (the worker has TIMEOUT_S)
    assert r["after_step"] == 0 and r["freed"], r  # a step within the limit still works
    assert any("maximum" in m for m in r["log"]), r["log"]


@pytest.mark.parametrize("name", ALL)
def test_setting_an_output_is_an_error_and_does_not_stick(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "output_set")
    assert r["set"] == 3 and not r["changed"], r
    assert r["after_step"] == 0 and r["freed"], r
    assert any("is an output" in m for m in r["log"]), r["log"]


@pytest.mark.parametrize("name", ALL)
def test_fixed_parameter_after_initialisation_is_an_error(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "fixed_after_init")
    assert r["set"] == 3 and not r["changed"], r
    assert r["after_step"] == 0 and r["freed"], r
    assert any("fixed parameter" in m for m in r["log"]), r["log"]


@pytest.mark.parametrize("name", ALL)
def test_time_going_backwards_is_an_error(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "time_backwards")
    assert (r["step1"], r["step2"], r["back"], r["after_step"]) == (0, 0, 3, 0), r
    assert any("backwards" in m for m in r["log"]), r["log"]


@pytest.mark.parametrize("name", ALL)
def test_a_state_of_another_fmu_is_refused(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "foreign_state")
    assert r["set"] == 3 and not r["changed"], r
    assert r["deser"] == 3, r
    assert r["after_step"] == 0 and r["freed"], r
    assert any("not made by this FMU" in m for m in r["log"]), r["log"]


@pytest.mark.parametrize("name", ALL)
def test_setup_experiment_after_initialisation_is_an_error(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "setup_after_init")
    assert r["setup"] == 3 and r["after_step"] == 0 and r["freed"], r


@pytest.mark.parametrize("name", ALL)
def test_calls_on_a_freed_instance_are_refused_without_a_crash(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "after_free")
    assert r["step_freed"] == 3 and r["get_freed"] == 3 and r["freed"], r


@pytest.mark.parametrize("name", ALL)
def test_a_wrong_guid_is_refused_at_instantiation(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "wrong_guid")
    assert r["instantiate"] == "null", r
    assert any("GUID" in m and "does not match" in m for m in r["log"]), r["log"]


@pytest.mark.parametrize("name", ALL)
def test_instantiation_without_resources_is_refused_with_a_message(all_fmus, isolated, name):
    r = _run(isolated, all_fmus, name, "no_resources")
    assert r["instantiate"] == "null", r
    assert any("resources" in m for m in r["log"]), r["log"]


# ---------------------------------------------------------------------------
# Instantiation failures reach the host's logger at default settings
# ---------------------------------------------------------------------------

def worker_missing_module(path, module):
    """Instantiate with ``module`` made unimportable (as on a host that lacks it); return the error lines."""
    import builtins
    h = _Host(path)
    real_import = builtins.__import__

    def refuse(name, *args, **kw):
        if name == module or name.startswith(module + "."):
            raise ModuleNotFoundError(f"No module named '{module}'")
        return real_import(name, *args, **kw)
    builtins.__import__ = refuse
    for key in [k for k in sys.modules if k == module or k.startswith(module + ".")]:
        del sys.modules[key]
    status = h.instantiate(logging=False)
    builtins.__import__ = real_import
    shutil.rmtree(h.dir, ignore_errors=True)
    return {"instantiate": status, "log": h.errors()}


def test_a_missing_python_module_reaches_the_host_logger_as_an_error(all_fmus, isolated):
    # reference: issue 31 - a host lacking scipy saw only "Failed to instantiate model"
    res = isolated(__file__, "worker_missing_module", str(all_fmus["Slider"]), "numpy", timeout=TIMEOUT_S, check=False)
    assert res.returncode == 0, res.stderr[-2000:]
    r = res.value
    assert r["instantiate"] == "null", r
    assert any("No module named 'numpy'" in m for m in r["log"]), r["log"]


# ---------------------------------------------------------------------------
# The C host (fmi/chost/fmu_host.c): the same refusals, no crash
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def chost(tmp_path_factory):
    import fmpy
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("no gcc")
    src = Path(__file__).resolve().parents[1] / "fmu_src" / "l1b2" / "fmi" / "chost" / "fmu_host.c"
    exe = tmp_path_factory.mktemp("chost") / "fmu_host"
    subprocess.run([gcc, "-O2", "-std=c99", f"-I{Path(fmpy.__file__).parent / 'c-code'}", "-o", str(exe), str(src),
                    "-ldl"], check=True, capture_output=True)
    return exe


def _c_run(exe, fmu, tmp_path, *args, guid=None):
    import sysconfig
    import zipfile
    from fmpy import read_model_description
    md = read_model_description(str(fmu))
    d = tmp_path / Path(fmu).stem
    with zipfile.ZipFile(fmu) as z:
        z.extractall(d)
    libpython = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("LDLIBRARY")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONHOME"}
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p.endswith("site-packages"))
    proc = subprocess.run([str(exe), "-L", str(libpython), *args, str(d), md.coSimulation.modelIdentifier,
                           guid or md.guid], capture_output=True, text=True, timeout=TIMEOUT_S, env=env)
    return proc


def test_c_host_huge_step_and_wrong_guid(all_fmus, chost, tmp_path):
    big = _c_run(chost, all_fmus["Predictor"], tmp_path, "-h", "1e6", "-n", "1")
    assert big.returncode == 12, (big.returncode, big.stderr[-1500:])  # 10 + fmi2Discard, no hang, no crash
    assert "maximum" in big.stderr
    wrong = _c_run(chost, all_fmus["Slider"], tmp_path, guid="{00000000-0000-0000-0000-000000000000}")
    assert wrong.returncode == 4, (wrong.returncode, wrong.stderr[-1500:])  # instantiation refused
    assert "does not match" in wrong.stderr
    unknown = _c_run(chost, all_fmus["Slider"], tmp_path, "-o", "10000")
    assert unknown.returncode == 13, (unknown.returncode, unknown.stderr[-1500:])  # 10 + fmi2Error
    assert "unknown value reference" in unknown.stderr
