"""libcosim (libcosimpy) runs the native FMUs through an SSP: the native motor drives the native predictor.

The SSP (written here) holds ``L1B2Motor-native.fmu`` and ``Predictor-native.fmu``
with the motor's stator voltage and slider position connected to the
predictor's inputs. References: the native motor alone in fmpy (libcosim must
give the same numbers: the motor has no input from the system), and the native
predictor in fmpy fed with the motor's outputs one communication step late
(libcosim's fixed-step Jacobi algorithm transfers outputs after every FMU stepped).
"""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

pytest.importorskip("libcosimpy")

pytestmark = pytest.mark.fmu

H = 2e-4
N = 150
MOTOR_INPUTS = {"V_s": 67.1, "duty": 1.0, "f_s": 48500.0, "T": 25.0, "direction": 1.0, "m_load": 0.05}

SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0" name="NativeMotorAndPredictor">
  <ssd:System name="NativeMotorAndPredictor">
    <ssd:Elements>
      <ssd:Component name="Motor" type="application/x-fmu-sharedlibrary" source="resources/L1B2Motor-native.fmu">
        <ssd:Connectors>
          <ssd:Connector name="V0" kind="output"><ssc:Real unit="V"/></ssd:Connector>
          <ssd:Connector name="s" kind="output"><ssc:Real unit="m"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="Predictor" type="application/x-fmu-sharedlibrary" source="resources/Predictor-native.fmu">
        <ssd:Connectors>
          <ssd:Connector name="V0" kind="input"><ssc:Real unit="V"/></ssd:Connector>
          <ssd:Connector name="s" kind="input"><ssc:Real unit="m"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="Motor" startConnector="V0" endElement="Predictor" endConnector="V0"/>
      <ssd:Connection startElement="Motor" startConnector="s" endElement="Predictor" endConnector="s"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.0" stopTime="0.1"/>
</ssd:SystemStructureDescription>
"""


def worker_libcosim(ssp_path, motor_inputs, n, h):
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_ssp_file(ssp_path, step_size=int(round(h * 1e9)))
    slaves = {info.name.decode(): (info.index, {v.name.decode(): v.reference for v in ex.slave_variables(info.index)})
              for info in ex.slave_infos()}

    def ref(comp, var):
        return slaves[comp][0], slaves[comp][1][var]
    for k, x in motor_inputs.items():
        assert ex.real_initial_value(*ref("Motor", k), float(x)), k
    ts = CosimObserver.create_time_series(buffer_size=n + 10)
    ex.add_observer(ts)
    record = [("Motor", "v"), ("Motor", "s"), ("Motor", "V0"), ("Predictor", "v"), ("Predictor", "v_steady")]
    for r in record:
        assert ts.start_time_series(*ref(*r), CosimVariableType.REAL)
    assert ex.simulate_until(int(round(n * h * 1e9)))
    out = {}
    for r in record:
        _, _, values = ts.time_series_real_samples(*ref(*r), from_step=0, sample_count=n + 1)
        _, _, last = ts.time_series_real_samples(*ref(*r), from_step=n, sample_count=1)
        out[".".join(r)] = list(values) + list(last)
    return out


def _fmpy_rows(path, inputs_per_step, outputs, params=None):
    """Outputs after initialisation and after every step; ``inputs_per_step[k]`` set before initialisation (k=0)
    and before the k-th step."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="r")
    fmu.instantiate()
    rows = []
    try:
        fmu.setupExperiment(startTime=0.0)
        u = inputs_per_step[0]
        fmu.setReal([vr[k] for k in u], list(u.values()))
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        rows.append(fmu.getReal([vr[k] for k in outputs]))
        for k, u in enumerate(inputs_per_step[1:]):
            fmu.setReal([vr[k2] for k2 in u], list(u.values()))
            fmu.doStep(k * H, H)
            rows.append(fmu.getReal([vr[k2] for k2 in outputs]))
        fmu.terminate()
    finally:
        fmu.freeInstance()
    return np.array(rows)


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    from l1b2.fmi.build import build_fmu
    from l1b2.fmi.native.build import build_native_fmu, find_cc
    try:
        find_cc()
    except Exception as exc:  # noqa: BLE001
        pytest.skip(str(exc))
    out = tmp_path_factory.mktemp("native_ssp")
    motor = build_native_fmu("L1B2Motor", build_fmu("L1B2Motor", out), out, 2)
    pred = build_native_fmu("Predictor", build_fmu("Predictor", out), out, 2)
    ssp = out / "NativeMotorAndPredictor.ssp"
    with zipfile.ZipFile(ssp, "w") as z:
        z.writestr("SystemStructure.ssd", SSD)
        z.write(motor, "resources/L1B2Motor-native.fmu")
        z.write(pred, "resources/Predictor-native.fmu")
    return motor, pred, ssp


def test_libcosim_runs_the_native_fmus_through_an_ssp(native, isolated):
    # reference: the native motor alone in fmpy (1e-12), the native predictor in fmpy fed with the
    # motor's V0 and s of the previous communication point (libcosim's Jacobi step), bit-identical
    motor, pred, ssp = native
    got = isolated(__file__, "worker_libcosim", str(ssp), MOTOR_INPUTS, N, H).value
    m = _fmpy_rows(motor, [MOTOR_INPUTS] * (N + 1), ["v", "s", "V0"])
    assert len(got["Motor.v"]) == N + 1
    # libcosim's step sizes are differences of its time points (integer nanoseconds converted to seconds): equal
    # to 0.2 ms up to round-off, hence 1e-12 and not bit for bit
    np.testing.assert_allclose(got["Motor.v"], m[:, 0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got["Motor.s"], m[:, 1], rtol=1e-12, atol=1e-15)
    assert m[-1, 0] > 0.05
    # predictor inputs: at initialisation the motor's initial outputs; before step k the outputs after step k-1
    # of the motor, i.e. what the motor published at the start of the step (Jacobi)
    feed = [{"V0": m[0, 2], "s": m[0, 1]}] + [{"V0": m[k, 2], "s": m[k, 1]} for k in range(N)]
    p = _fmpy_rows(pred, feed, ["v", "v_steady"])
    np.testing.assert_allclose(got["Predictor.v"], p[:, 0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got["Predictor.v_steady"], p[:, 1], rtol=1e-12, atol=1e-15)
    assert p[-1, 0] > 0.05
