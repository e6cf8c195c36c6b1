"""All six FMUs: the error flag is part of the FMU state; calls in the wrong FMI mode are refused (issue 14).

* A discarded step leaves the instance refusing further steps until a state
  taken before the error is restored with ``fmi2SetFMUstate`` (also through
  ``fmi2SerializeFMUstate``/``fmi2DeSerializeFMUstate``); restoring a state
  taken after the error brings the error back.
* ``fmi2DoStep`` before initialisation, in initialization mode or after
  ``fmi2Terminate`` is refused with one ``fmi2Error`` log line naming the call
  and the mode, and has no effect: the instance then initialises and steps
  normally.

PythonFMU 0.7.0's ``fmi2DoStep`` returns ``fmi2OK`` when ``do_step`` returns
True, ``fmi2Discard`` when it returns False and ``fmi2Fatal`` when it raises
(and then frees the Python slave under the host); it has no path to
``fmi2Error`` from Python. A refused call therefore returns ``fmi2Discard``
(status 2) in every FMU, with the error in the FMU log.

Fast tests instantiate the generated slave classes in this process (as
PythonFMU's own tests do); the FMU tests load the built FMUs with fmpy in a
fresh process (``isolated``).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import types

import pytest
from l1b2.fmi.adapter import STATE_KEY
from l1b2.fmi.build import defaults_document
from l1b2.fmi.slaves import SLAVES, slave_script
from l1b2.physics.params import load_motor
from pythonfmu.enums import Fmi2Causality, Fmi2Status

SIX = ("Driver", "Stator", "Interface", "Slider", "L1B2Motor", "Predictor")
H = 2e-4
BEFORE_INIT = r"fmi2DoStep called before initialisation \(mode 'instantiated'.*fmi2EnterInitializationMode"


# ---------------------------------------------------------------------------
# Fast: the generated slave classes in this process
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def resources(tmp_path_factory, predictor_setup):
    """A resources folder with the defaults document (a cheap predictor: no derivation at instantiation)."""
    folder = tmp_path_factory.mktemp("resources")
    doc = defaults_document(load_motor(), {"predictor": predictor_setup})
    (folder / "_fmu_defaults.json").write_text(json.dumps(doc))
    return str(folder)


def _slave(name, resources):
    mod = types.ModuleType(f"l1b2_test_slave_{name}")
    exec(compile(slave_script(name, author="test", license="MIT"), f"<{name} slave>", "exec"), mod.__dict__)
    return getattr(mod, name)(instance_name=name, resources=resources)


def _first_input(s):
    return next(v for v in s.vars.values() if v.causality == Fmi2Causality.input and v.name != "direction")


def _outputs(s):
    return s.get_real([v.value_reference for v in s.vars.values() if v.causality == Fmi2Causality.output])


def _init(s):
    s.setup_experiment(0.0, None, None)
    s.enter_initialization_mode()
    s.exit_initialization_mode()


def test_slave_template_covers_the_six_fmus():
    assert set(SLAVES) == set(SIX)


@pytest.mark.parametrize("name", SIX)
def test_slave_refuses_do_step_before_initialisation(name, resources):
    # reference: FMI 2.0 state machine - fmi2DoStep only in stepComplete (after fmi2ExitInitializationMode)
    s = _slave(name, resources)
    before = _outputs(s)
    assert s.do_step(0.0, H) is False
    errors = [m for m in s.log_queue if m.status == Fmi2Status.error]
    assert len(errors) == 1 and errors[0].msg.startswith(f"{name}: ")
    assert pytest.approx(before, nan_ok=True) == _outputs(s)  # no effect
    assert s.adapter.failed is None                            # not an error of the instance: it still works
    s.setup_experiment(0.0, None, None)
    s.enter_initialization_mode()
    assert s.do_step(0.0, H) is False                          # in initialization mode
    s.exit_initialization_mode()
    s.exit_initialization_mode()                               # twice: refused, no effect
    assert s.do_step(0.0, H) is True
    s.terminate()
    assert s.do_step(H, H) is False                            # after fmi2Terminate
    msgs = [m.msg for m in s.log_queue if m.status == Fmi2Status.error]
    assert re.search(BEFORE_INIT, msgs[0]), msgs[0]
    assert "called in initialization mode" in msgs[1] and "fmi2ExitInitializationMode first" in msgs[1]
    assert "fmi2ExitInitializationMode called after initialisation" in msgs[2]
    assert "fmi2DoStep called after fmi2Terminate" in msgs[3]
    assert len(msgs) == 4


@pytest.mark.parametrize("name", SIX)
def test_slave_state_carries_the_error_flag(name, resources):
    # reference: FMI 2.0 (fmi2SetFMUstate restores the complete FMU state); the first path from the saved state
    s = _slave(name, resources)
    _init(s)
    bad_input = _first_input(s)
    assert s.do_step(0.0, H)
    good = s._get_fmu_state()
    assert good[STATE_KEY] == {"failed": None, "model": name}
    assert s.do_step(H, H)
    first = _outputs(s)
    s._set_fmu_state(good)
    s.set_real([bad_input.value_reference], [math.nan])
    assert s.do_step(H, H) is False                      # discarded
    assert s.do_step(H, H) is False                      # and stays refused
    bad = s._get_fmu_state()
    assert "not finite" in bad[STATE_KEY]["failed"]
    s._set_fmu_state(good)
    assert s.adapter.failed is None
    assert s.do_step(H, H) is True                       # the good state recovers the instance
    assert _outputs(s) == first
    s._set_fmu_state(bad)
    assert s.do_step(H, H) is False                      # the bad state brings the error back
    blob = s._fmu_state_to_bytes(good)                   # fmi2SerializeFMUstate / fmi2DeSerializeFMUstate
    s._set_fmu_state(s._fmu_state_from_bytes(blob))
    assert s.do_step(H, H) is True
    assert _outputs(s) == first
    s._set_fmu_state(good)                               # a state may be restored more than once
    assert good[STATE_KEY] == {"failed": None, "model": name} and s.do_step(H, H) is True


def test_restoring_a_state_before_initialisation_does_not_fail(resources):
    # reference: a state taken in instantiated mode holds start values; nothing is computed until initialisation
    s = _slave("L1B2Motor", resources)
    early = s._get_fmu_state()
    s._set_fmu_state(early)
    assert s.adapter.failed is None
    _init(s)
    assert s.do_step(0.0, H) is True


def test_log_text_is_valid_utf8(resources):
    # reference: PythonFMU 0.7.0 encodes log text as UTF-8 without error handling (a lone surrogate crashes it)
    s = _slave("Driver", resources)
    s.adapter.fail("bad \udcff value")
    s.log_queue[-1].msg.encode("utf-8")


# ---------------------------------------------------------------------------
# The built FMUs through fmpy (fresh process)
# ---------------------------------------------------------------------------

def _fmi_call(call, *args):
    """``(status, log lines)`` of one FMI call; fmpy raises on a status above fmi2Warning."""
    from fmpy.fmi1 import FMICallException
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):   # fmpy's default logger prints "[STATUS] message"
        try:
            call(*args)
            status = 0
        except FMICallException as exc:
            status = exc.status
    return status, buf.getvalue().splitlines()


def _open(path, name):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(path)
    unz = extract(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=name)
    fmu.instantiate(loggingOn=True)
    return md, unz, fmu


def _close(fmu, unz):
    import shutil
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            fmu.terminate()
        except Exception:  # noqa: BLE001 - may already be terminated
            pass
        fmu.freeInstance()
    shutil.rmtree(unz, ignore_errors=True)


def worker_wrong_mode(paths):
    out = {}
    for name, path in paths.items():
        md, unz, fmu = _open(path, name)
        r = {}
        try:
            outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
            r["before"] = _fmi_call(fmu.doStep, 0.0, H)
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            r["init_mode"] = _fmi_call(fmu.doStep, 0.0, H)
            fmu.exitInitializationMode()
            r["good"] = _fmi_call(fmu.doStep, 0.0, H)
            r["finite"] = all(math.isfinite(x) for x in fmu.getReal(outs))
            fmu.terminate()
            r["after_terminate"] = _fmi_call(fmu.doStep, H, H)
        finally:
            _close(fmu, unz)
        out[name] = r
    return out


def worker_discard_restore(paths):
    out = {}
    for name, path in paths.items():
        md, unz, fmu = _open(path, name)
        r = {}
        try:
            outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
            bad = next(v for v in md.modelVariables if v.causality == "input" and v.name != "direction")
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            fmu.doStep(0.0, H)
            good = fmu.getFMUstate()
            fmu.doStep(H, H)
            r["first"] = list(fmu.getReal(outs))
            fmu.setFMUstate(good)
            fmu.setReal([bad.valueReference], [float("nan")])
            r["discard"] = _fmi_call(fmu.doStep, H, H)
            r["still_refused"] = _fmi_call(fmu.doStep, H, H)
            broken = fmu.getFMUstate()
            r["restore"] = _fmi_call(fmu.setFMUstate, good)
            r["recovered"] = _fmi_call(fmu.doStep, H, H)
            r["recovered_out"] = list(fmu.getReal(outs))
            fmu.setFMUstate(broken)
            r["broken_again"] = _fmi_call(fmu.doStep, H, H)
            blob = fmu.serializeFMUstate(good)
            copy = fmu.deSerializeFMUstate(blob)
            fmu.setFMUstate(copy)
            r["deserialized"] = _fmi_call(fmu.doStep, H, H)
            r["deserialized_out"] = list(fmu.getReal(outs))
            for st in (good, broken, copy):
                fmu.freeFMUstate(st)
        finally:
            _close(fmu, unz)
        out[name] = r
    return out


@pytest.fixture(scope="module")
def six_fmus(fmus, tmp_path_factory, predictor_setup):
    from l1b2.fmi.build import build_fmu
    dest = tmp_path_factory.mktemp("six")
    paths = {n: str(p) for n, p in fmus.items()}
    paths["L1B2Motor"] = str(build_fmu("L1B2Motor", dest))
    paths["Predictor"] = str(build_fmu("Predictor", dest, extra_defaults={"predictor": predictor_setup}))
    return paths



@pytest.mark.fmu
def test_fmus_refuse_do_step_in_the_wrong_mode(six_fmus, isolated):
    # reference: FMI 2.0 state machine; PythonFMU 0.7.0 status mapping (refused = fmi2Discard, 2) - see docstring
    res = isolated(__file__, "worker_wrong_mode", six_fmus)
    assert set(res.value) == set(SIX)
    for name, r in res.value.items():
        for key in ("before", "init_mode", "after_terminate"):
            status, log = r[key]
            assert status == 2, (name, key, r)                    # never fmi2OK, never fmi2Fatal
            errors = [ln for ln in log if ln.startswith("[ERROR]")]
            assert len(errors) == 1, (name, key, log)
        assert re.search(BEFORE_INIT, r["before"][1][0]), r["before"]
        assert r["before"][1][0].startswith(f"[ERROR] {name}: ")
        assert "called in initialization mode" in r["init_mode"][1][0]
        assert "called after fmi2Terminate" in r["after_terminate"][1][0]
        assert r["good"] == [0, []], (name, r["good"])            # the refused calls had no effect
        assert r["finite"], name
    assert "Traceback" not in res.stdout + res.stderr


@pytest.mark.fmu
def test_fmus_recover_from_a_discard_by_restoring_a_good_state(six_fmus, isolated):
    # reference: FMI 2.0 - fmi2SetFMUstate restores the complete state; the first path from the saved state
    res = isolated(__file__, "worker_discard_restore", six_fmus)
    assert set(res.value) == set(SIX)
    for name, r in res.value.items():
        assert r["discard"][0] == 2 and any("not finite" in ln for ln in r["discard"][1]), (name, r)
        assert r["still_refused"][0] == 2, (name, r)
        assert r["restore"] == [0, []], (name, r)
        assert r["recovered"] == [0, []], (name, r)
        assert r["recovered_out"] == r["first"], name
        assert r["broken_again"][0] == 2, (name, r)
        assert r["deserialized"] == [0, []], (name, r)
        assert r["deserialized_out"] == r["first"], name
    assert "Traceback" not in res.stdout + res.stderr
