"""Cross-check in an independent engine: libcosim (libcosimpy) runs ``L1B2Motor.ssp``.

libcosim and our master (:mod:`l1b2.cosim.master`) differ in their master algorithm:

* **libcosim: fixed-step Jacobi.** All FMUs step from t_k to t_k + h in
  parallel with the inputs transferred at t_k; outputs are transferred after
  all have stepped.
* **ours: Gauss-Seidel** in SSD order (Driver, Stator, Interface, Slider):
  each FMU steps with the newest outputs of the ones before it.

The forward path Stator -> Interface -> Slider therefore reaches the slider
two communication steps later in libcosim (2 h = 0.4 ms), and each feedback
loop (Interface -> Stator, Slider -> Interface/Stator) has one step more delay.
Delays do not change a fixed point, so both masters converge to the same
steady traverse speed (measured difference ~1e-6 relative); the transient is
shifted by the 2-step lag, which is 4 % of the slider time constant
m / c_r = 10.7 ms. Quantified below, for a full traverse at 324 V from the
end stop and a run against a 0.05 kg load (measured in brackets):

* speed as a function of position (the paper's quantity) agrees within 1 % of
  the peak speed over the whole stroke [0.13 %, 0.09 %];
* at equal times from 20 ms (two slider time constants) to the end-stop
  impact within 1 % of peak [0.20 %, 0.37 %];
* the whole run, once the 2-step lag is taken out, within 1.5 % of peak, the
  largest difference being the start-up in the first millisecond [1.02 %,
  0.80 %; 0.45 %, 0.34 % after 1 ms];
* the slider reaches the end stop at most 2 steps later in libcosim.

What libcosim needs from the SSP (verified with libcosimpy 0.0.6, see
``system_models/L1B2Motor.ssd``): component-level parameter bindings with
bare variable names, no connection to a system connector (it refuses the
SSD), a step size (``from_ssp_file(path, step_size=ns)``; the OSP
annotation in the SSD's default experiment also provides one), outputs
computed in initialization mode (it propagates values through the
connections before exiting initialisation). The system inputs are set as
initial values of the component inputs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("libcosimpy")

pytestmark = pytest.mark.fmu

H = 2e-4
LAG_STEPS = 2  # Jacobi delay of the forward path Stator -> Interface -> Slider
RECORD = ["Slider.v", "Slider.s", "Slider.at_stop", "Stator.s", "Stator.F_p", "Interface.F_d", "Interface.mu_p",
          "Slider.mass_kg"]
#: component inputs fed by each system input (the SSD's org.l1b2-usm.SystemConnections annotation)
SYSTEM_INPUTS = {"V_s": ["Driver.V_s"], "duty": ["Driver.duty"], "f_s": ["Driver.f_s"],
                 "T": ["Driver.T", "Stator.T"], "direction": ["Stator.direction"], "m_load": ["Slider.m_load"]}


# ---------------------------------------------------------------------------
# Workers (fresh process each, via the `isolated` fixture)
# ---------------------------------------------------------------------------

def worker_libcosim(ssp_path, stop_time, inputs, start_values, record, step_s=H):
    """Run an .ssp in libcosim; returns ``{name: samples}`` at every communication point incl. t = 0."""
    from l1b2.cosim.hosting import install_exit_fix
    install_exit_fix()
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_ssp_file(str(ssp_path), step_size=int(round(step_s * 1e9)))  # ns; always give it
    slaves = {}
    for info in ex.slave_infos():
        slaves[info.name.decode()] = (info.index, {v.name.decode(): v.reference
                                                   for v in ex.slave_variables(info.index)})

    def ref(name):
        comp, var = name.split(".", 1)
        return slaves[comp][0], slaves[comp][1][var]

    for sys_input, value in inputs.items():
        for target in SYSTEM_INPUTS[sys_input]:
            assert ex.real_initial_value(*ref(target), float(value)), target
    for name, value in start_values.items():
        assert ex.real_initial_value(*ref(name), float(value)), name
    n = int(round(stop_time / step_s))
    ts = CosimObserver.create_time_series(buffer_size=n + 10)
    ex.add_observer(ts)
    for name in record:
        assert ts.start_time_series(*ref(name), CosimVariableType.REAL)
    assert ex.simulate_until(int(round(n * step_s * 1e9)))
    out = {"steps": None}
    for name in record:
        # libcosimpy 0.0.6 drops the last sample of a read that starts at step 0: read the last one separately
        _, steps, values = ts.time_series_real_samples(*ref(name), from_step=0, sample_count=n + 1)
        _, steps2, values2 = ts.time_series_real_samples(*ref(name), from_step=n, sample_count=1)
        out[name] = list(values) + list(values2)
        out["steps"] = [int(s) for s in list(steps) + list(steps2)]
    out["slaves"] = sorted(slaves)
    return out


def worker_ours(system, stop_time, inputs, start_values, record, step_s=H):
    from l1b2.cosim.master import CoSimulation
    with CoSimulation(system, step_s=step_s) as cs:
        r = cs.run(stop_time, inputs, record=record, start_values=start_values)
    return {k: r.df[k].tolist() for k in ["time"] + record}


def worker_initialization_mode_outputs(fmu_dir):
    """Outputs read in Initialization Mode (before fmi2ExitInitializationMode), as libcosim reads them."""
    import shutil

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    res = {}
    for name, params, outputs in (("Slider", {"s0": -0.021}, ["s", "v"]), ("Driver", {"f_s": 47000.0}, ["omega"])):
        path = str(Path(fmu_dir) / f"{name}.fmu")
        md = read_model_description(path)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        unz = extract(path)
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName=name)
        try:
            fmu.instantiate()
            fmu.setupExperiment(startTime=0.0)
            fmu.setReal([vr[k] for k in params], list(params.values()))
            fmu.enterInitializationMode()
            res[name] = dict(zip(outputs, fmu.getReal([vr[k] for k in outputs])))
            fmu.exitInitializationMode()
            fmu.terminate()
        finally:
            fmu.freeInstance()
            shutil.rmtree(unz, ignore_errors=True)
    return res


# ---------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def ssp_path(exported):
    return exported[0] / "L1B2Motor_libcosim.ssp"


@pytest.fixture(scope="module")
def operating(motor):
    from l1b2.physics import driver as drv
    V_s = float(drv.supply_for_voltage_V(motor.driver, 324.0, 1.0, 48500.0, 25.0))
    return dict(V_s=V_s, duty=1.0, f_s=48500.0, T=25.0)


CASES = {  # name: (m_load [kg], direction, stop time [s]) - from the end stop the slider moves away from
    "traverse_324V": (0.0, 1.0, 0.25),
    "loaded_324V_0.05kg": (0.05, 1.0, 0.35),
}


@pytest.fixture(scope="module")
def runs(ssp_path, operating, motor, isolated):
    out = {}
    for case, (m_load, direction, t_end) in CASES.items():
        s0 = motor.slider.s_min_m if direction > 0 else motor.slider.s_max_m
        inputs = dict(operating, direction=direction, m_load=m_load)
        start = {"Slider.s0": s0, "Stator.s": s0}  # start position: both, consistently
        lc = isolated(__file__, "worker_libcosim", str(ssp_path), t_end, inputs, start, RECORD).value
        gs = isolated(__file__, "worker_ours", str(ssp_path), t_end, inputs, start, RECORD).value
        out[case] = (lc, gs, s0, direction)
    return out


def test_fmus_compute_outputs_in_initialization_mode(exported, isolated):
    # reference: FMI 2.0 (3.2.3) - outputs are initial unknowns, so fmi2GetReal in Initialization Mode returns
    # them computed from parameters and inputs (libcosim transfers them before exiting initialisation)
    res = isolated(__file__, "worker_initialization_mode_outputs", str(exported[0] / "fmus")).value
    assert res["Slider"]["s"] == -0.021 and res["Slider"]["v"] == 0.0
    assert res["Driver"]["omega"] == pytest.approx(2 * np.pi * 47000.0, rel=1e-12)


def test_libcosim_loads_ssp_and_applies_component_parameter_sets(exported, tmp_path, motor, operating, isolated):
    # reference: the parameter set written into a second .ssp (mu_p, mass differ from the values baked into the FMUs)
    from l1b2.cosim import ssp
    out, _ = exported
    fmus = {n: out / "fmus" / f"{n}.fmu" for n in ("Driver", "Stator", "Interface", "Slider")}
    other = ssp.build_ssp(tmp_path / "other.ssp", fmus, mp=motor.replace(interface__mu_p=0.2, slider__mass_kg=0.15),
                          standard=False)
    inputs = dict(operating, direction=1.0, m_load=0.0)
    res = isolated(__file__, "worker_libcosim", str(other), 0.002, inputs, {"Slider.s0": 0.0, "Stator.s": 0.0},
                   ["Interface.mu_p", "Slider.mass_kg", "Stator.s"]).value
    assert res["slaves"] == ["Driver", "Interface", "Slider", "Stator"]
    assert res["steps"] == list(range(11))
    assert set(res["Interface.mu_p"]) == {0.2}
    assert set(res["Slider.mass_kg"]) == {0.15}


def test_libcosim_starts_at_the_given_position(runs, motor):
    # reference: the start position s0 (end stop) in both components at t = 0 and the preload F_p(s0) of l1b2.physics.stator
    from l1b2.physics import stator as st
    for case, (lc, gs, s0, _) in runs.items():
        assert lc["Slider.s"][0] == s0 and lc["Stator.s"][0] == s0, case
        F_p = motor.stator.alpha0 * float(st.axial_force_N(motor.stator, s0))
        assert lc["Stator.F_p"][0] == pytest.approx(F_p, rel=1e-12), case
        assert gs["Stator.F_p"][0] == pytest.approx(F_p, rel=1e-12), case


@pytest.mark.parametrize("case", list(CASES))
def test_libcosim_agrees_with_our_master(runs, motor, case):
    """libcosim (Jacobi) against our fmpy master (Gauss-Seidel) on the paper's experiment; see the module docstring.

    Reference: our master on the same ``L1B2Motor.ssp``. Both runs start at the end
    stop and traverse the whole stroke to the other stop at V0 = 324 V.
    """
    lc, gs, s0, direction = runs[case]
    va, vb = np.array(lc["Slider.v"]), np.array(gs["Slider.v"])
    sa, sb = np.array(lc["Slider.s"]), np.array(gs["Slider.s"])
    n = len(gs["time"])
    assert len(va) == n and lc["steps"] == list(range(n))
    peak = np.max(np.abs(vb))
    assert peak > 0.1
    # the whole stroke was traversed in both
    end = motor.slider.s_max_m if direction > 0 else motor.slider.s_min_m
    assert sa[-1] == pytest.approx(end, abs=1e-12) and sb[-1] == pytest.approx(end, abs=1e-12)
    ka = int(np.argmax(np.array(lc["Slider.at_stop"]) == direction))
    kb = int(np.argmax(np.array(gs["Slider.at_stop"]) == direction))
    assert 0 < kb <= ka <= kb + LAG_STEPS
    # 1. same steady traverse speed (mean over the middle 20 mm of the stroke)
    mid = lambda v, s: np.mean(v[np.abs(s) < 0.01])  # noqa: E731
    assert mid(va, sa) == pytest.approx(mid(vb, sb), rel=1e-4)
    # 2. speed as a function of position over the whole stroke
    grid = np.linspace(min(s0, end) + 1e-4, max(s0, end) - 1e-4, 400)
    order = 1 if direction > 0 else -1
    pa = np.interp(grid[::order], sa[:ka][::order], va[:ka][::order])
    pb = np.interp(grid[::order], sb[:kb][::order], vb[:kb][::order])
    assert np.max(np.abs(pa - pb)) <= 0.01 * peak
    # 3. equal times, from two slider time constants to the end-stop impact
    t = np.array(gs["time"])
    window = (t >= 0.02) & (np.arange(n) < kb - 1)
    assert np.max(np.abs(va - vb)[window]) <= 0.01 * peak
    # 4. the whole run with the Jacobi lag of the forward path taken out
    shifted = np.abs(va[LAG_STEPS:] - vb[:n - LAG_STEPS])
    assert np.max(shifted) <= 0.015 * peak
    assert np.max(shifted[int(round(1e-3 / H)):]) <= 0.005 * peak


def worker_libcosim_loads(ssp_path):
    """Whether libcosim creates an execution from the archive (and its slaves' names)."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    log_output_level(CosimLogLevel.ERROR)
    try:
        ex = CosimExecution.from_ssp_file(str(ssp_path), step_size=200_000)
    except Exception as exc:  # libcosimpy raises a bare AssertionError with a generic message
        return {"loaded": False, "error": str(exc)}
    return {"loaded": True, "slaves": sorted(i.name.decode() for i in ex.slave_infos())}


def test_libcosim_needs_its_own_archive(exported, isolated):
    # reference: measured with libcosimpy 0.0.6 - it refuses an SSD with standard connections to system connectors
    # (no startElement/endElement), which L1B2Motor.ssp has so that standard SSP tools drive the system inputs;
    # the export therefore also writes L1B2Motor_libcosim.ssp (the SSD as written, wiring in the annotation)
    out, _ = exported
    std = isolated(__file__, "worker_libcosim_loads", str(out / "L1B2Motor.ssp")).value
    lc = isolated(__file__, "worker_libcosim_loads", str(out / "L1B2Motor_libcosim.ssp")).value
    assert std["loaded"] is False, std
    assert lc == {"loaded": True, "slaves": ["Driver", "Interface", "Slider", "Stator"]}


def test_ssd_is_loadable_by_libcosim_as_written():
    # reference: libcosim's SSP parser (ssp_parser.cpp) - every ssd:Connection needs startElement and endElement,
    # parameter bindings are read per component only, prefixes are matched literally (ssd:, ssc:, ssv:)
    from l1b2.cosim import ssp
    from lxml import etree
    doc = etree.parse(str(ssp.SSD_FILE))
    ns = {k: v for k, v in ssp.NS.items()}
    assert doc.getroot().prefix == "ssd"
    for c in doc.iterfind(".//ssd:System/ssd:Connections/ssd:Connection", ns):
        assert c.get("startElement") and c.get("endElement"), etree.tostring(c)
    assert doc.find(".//ssd:System/ssd:ParameterBindings", ns) is None
    for comp in doc.iterfind(".//ssd:Elements/ssd:Component", ns):
        bindings = comp.findall("ssd:ParameterBindings/ssd:ParameterBinding", ns)
        assert len(bindings) == 1, comp.get("name")  # libcosim applies only the first one
