"""Predictor.fmu: the Eq. 29 predictor with identified parameters, for system simulators (issue 4)."""

import numpy as np
import pytest
from l1b2.fmi.build import build_fmu
from l1b2.physics.params import load_motor
from l1b2.predictor import model as pr
from l1b2.predictor.setup import PredictorSetup

INPUTS = [(324.0, -0.010, 0.05, 1.0)] * 40 + [(260.0, 0.004, -0.03, -1.0)] * 30


def worker_predictor(path, steps, h):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="p")
    out = []
    try:
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        V0, s, load, d = steps[0]
        fmu.setReal([vr["V0"], vr["s"], vr["load"], vr["direction"]], [V0, s, load, d])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        t = 0.0
        for V0, s, load, d in steps:
            fmu.setReal([vr["V0"], vr["s"], vr["load"], vr["direction"]], [V0, s, load, d])
            fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            t += h
            out.append(fmu.getReal([vr["v"], vr["v_steady"]]))
        fmu.terminate()
    finally:
        fmu.freeInstance()
    return out


@pytest.fixture(scope="module")
def setup():
    from l1b2.predictor.derive import derive_predictor
    mp = load_motor()
    return PredictorSetup(derive_predictor(mp, n_grid=9), mp.slider.mass_kg, 1e-3)


@pytest.fixture(scope="module")
def fmu(tmp_path_factory, setup):
    return build_fmu("Predictor", tmp_path_factory.mktemp("pred"), extra_defaults={"predictor": setup.to_dict()})


def test_predictor_fmu_validates_and_declares_units(fmu):
    # reference: fmpy validation (no problems) and a unit on every Real
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert all(v.unit for v in md.modelVariables if v.type == "Real")
    names = {v.name for v in md.modelVariables}
    assert {"V0", "s", "load", "direction", "v", "v_steady", "c_r", "beta_0", "p_8", "T_s"} <= names


@pytest.mark.parametrize("h", [1e-3, 2.5e-3])
def test_predictor_fmu_equals_the_predictor_functions(fmu, setup, isolated, h):
    # reference: l1b2.predictor.model.one_step iterated at T_s (sub-steps of h/n) and steady_state, called here
    got = isolated(__file__, "worker_predictor", str(fmu), INPUTS, h).value
    p, m_s = setup.params, setup.slider_mass_kg
    n = int(np.ceil(h / setup.T_s - 1e-9))
    v = 0.0
    for (V0, s, load, d), (v_fmu, v_ss) in zip(INPUTS, got):
        for _ in range(n):
            v = float(pr.one_step(p, v, s, V0, load, d, h / n, m_s))
        assert v_fmu == pytest.approx(v, rel=1e-12, abs=1e-15)
        assert v_ss == pytest.approx(float(pr.steady_state(p, s, V0, load, d, m_s)), rel=1e-12)
    assert got[39][0] == pytest.approx(got[39][1], rel=2e-2)   # settles toward its steady state (m/D ~ 8 ms)
    assert got[-1][0] < 0                                      # CH2 drives toward -position


@pytest.fixture(scope="module")
def slip_setup(setup):
    # the pure-slip family with physical parameters (the paper's reduction): slip ratio ~0.4 on these inputs
    from l1b2.predictor.derive import derive_predictor
    mp = load_motor()
    return PredictorSetup(derive_predictor(mp, method="paper", n_grid=9).replace(drive_law="pure_slip"),
                          mp.slider.mass_kg, 1e-3)


def test_pure_slip_predictor_fmu_equals_its_functions_and_has_no_native_twin(tmp_path, slip_setup, isolated):
    # reference: one_step / steady_state of the pure-slip family; the native build says why it is skipped
    from l1b2.fmi.native.build import build_native_set
    path = build_fmu("Predictor", tmp_path, extra_defaults={"predictor": slip_setup.to_dict()})
    got = isolated(__file__, "worker_predictor", str(path), INPUTS, 1e-3).value
    p, m_s = slip_setup.params, slip_setup.slider_mass_kg
    e = p.replace(drive_law="eq29")
    v = 0.0
    differs = False
    for (V0, s, load, d), (v_fmu, v_ss) in zip(INPUTS, got):
        v = float(pr.one_step(p, v, s, V0, load, d, 1e-3, m_s))
        assert v_fmu == pytest.approx(v, rel=1e-12, abs=1e-15)
        assert v_ss == pytest.approx(float(pr.steady_state(p, s, V0, load, d, m_s)), rel=1e-9)
        differs |= abs(v_ss - float(pr.steady_state(e, s, V0, load, d, m_s))) > 1e-3
    assert differs                                  # it is not Eq. 29 under another name
    built, info = build_native_set("Predictor", path, tmp_path)
    assert built == {} and not info["included"] and "pure-slip" in info["reason"]
