"""The subsystem FMUs (l1b2.fmi.build, fmu_src/slaves) and the fmpy co-simulation master (l1b2.cosim.master).

The FMUs are built once per session (conftest ``fmus``).  Everything that
instantiates an FMU runs in a fresh Python process through the ``isolated``
fixture: the ``worker_*`` functions below are executed there and return JSON;
the physics references are computed here, in the test process.
"""

from __future__ import annotations

import dataclasses
import math
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from l1b2 import __version__
from l1b2.physics import driver as drv
from l1b2.physics import interface as itf
from l1b2.physics import slider as sld
from l1b2.physics import stator as st

pytestmark = pytest.mark.fmu

NAMES = ("Driver", "Stator", "Interface", "Slider")
H_STEP = 2e-4
SYSTEM_INPUTS = dict(duty=1.0, f_s=48500.0, T=25.0, direction=1.0, m_load=0.0)

# SI base-unit exponents (kg, m, s, A, K, rad) of the units used by the FMUs, written here independently
SI = {
    "1": {}, "s": {"s": 1}, "m": {"m": 1}, "kg": {"kg": 1}, "rad": {"rad": 1},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1}, "Hz": {"s": -1}, "rad/s": {"rad": 1, "s": -1},
    "N": {"kg": 1, "m": 1, "s": -2}, "m/s": {"m": 1, "s": -1}, "m/s2": {"m": 1, "s": -2},
    "H": {"kg": 1, "m": 2, "s": -2, "A": -2}, "F": {"kg": -1, "m": -2, "s": 4, "A": 2},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2}, "1/K": {"K": -1}, "1/Hz": {"s": 1}, "Hz/K": {"s": -1, "K": -1},
    "kg/m3": {"kg": 1, "m": -3}, "N/V": {"m": -1, "s": 1, "A": 1}, "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1}, "degC": {"K": 1},
}


# ---------------------------------------------------------------------------
# Workers (run in a fresh process by the `isolated` fixture)
# ---------------------------------------------------------------------------

class _Slave:
    """Minimal FMU2Slave session: value references looked up once; always terminated and freed."""

    def __init__(self, path, name, logging=False):
        import shutil

        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave
        self._rmtree = shutil.rmtree
        self.md = read_model_description(str(path))
        self.unzipdir = extract(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(loggingOn=logging)
        self.initialized = False

    def set(self, **values):
        for k, x in values.items():
            v = self.vars[k]
            if v.type == "Real":
                self.fmu.setReal([v.valueReference], [float(x)])
            elif v.type == "Integer":
                self.fmu.setInteger([v.valueReference], [int(x)])
            elif v.type == "Boolean":
                self.fmu.setBoolean([v.valueReference], [bool(x)])

    def get(self, names):
        return dict(zip(names, self.fmu.getReal([self.vars[n].valueReference for n in names])))

    def init(self, **values):
        self.fmu.setupExperiment(startTime=0.0)
        self.set(**values)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.initialized = True

    def close(self):
        try:
            try:
                self.fmu.terminate()
            except Exception:  # noqa: BLE001 - may be in an error state; free anyway
                pass
            self.fmu.freeInstance()
        finally:
            self._rmtree(self.unzipdir, ignore_errors=True)


def _outputs(md):
    return [v.name for v in md.modelVariables if v.causality == "output"]


def worker_driver(path, params, cases):
    s = _Slave(path, "Driver")
    try:
        s.init(**params)
        out = []
        t = 0.0
        for case in cases:
            s.set(**case)
            s.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=H_STEP)
            t += H_STEP
            out.append(s.get(_outputs(s.md)))
        return out
    finally:
        s.close()


STATOR_STATES = ("Q_l_re", "Q_l_im", "Q_b_re", "Q_b_im")


def worker_stator(path, start, steps, h):
    s = _Slave(path, "Stator")
    try:
        s.init(**start)
        names = _outputs(s.md) + list(STATOR_STATES)
        out = [s.get(names)]
        t = 0.0
        for inp in steps:
            s.set(**inp)
            s.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            t += h
            out.append(s.get(names))
        return out
    finally:
        s.close()


def worker_interface(path, params, cases):
    s = _Slave(path, "Interface")
    try:
        s.init(**params, **cases[0])
        out = [s.get(_outputs(s.md))]
        t = 0.0
        for case in cases:
            s.set(**case)
            s.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=H_STEP)
            t += H_STEP
            out.append(s.get(_outputs(s.md)))
        return out
    finally:
        s.close()


def worker_slider(path, params, steps):
    s = _Slave(path, "Slider")
    try:
        s.init(**params)
        out = [s.get(_outputs(s.md))]
        t = 0.0
        for F_d, F_p, m_load, h in steps:
            s.set(F_d=F_d, F_p=F_p, m_load=m_load)
            s.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            t += h
            out.append(s.get(_outputs(s.md)))
        return out
    finally:
        s.close()


def worker_nonfinite(paths):
    from fmpy.fmi1 import FMICallException
    result = {}
    for name, var, bad in (("Slider", "F_d", float("nan")), ("Interface", "U_l", float("inf")),
                           ("Stator", "V0", float("nan"))):
        s = _Slave(paths[name], name, logging=True)
        try:
            s.init()
            s.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=H_STEP)  # a good step first
            s.set(**{var: bad})
            try:
                s.fmu.doStep(currentCommunicationPoint=H_STEP, communicationStepSize=H_STEP)
                result[name] = {"raised": False}
            except FMICallException as exc:
                result[name] = {"raised": True, "status": exc.status, "function": exc.function}
        finally:
            s.close()  # must not crash after the discarded step
        result[name]["freed"] = True
    return result


def worker_state_rollback(paths):
    res = {}
    # Stator: continuous modal phasors
    s = _Slave(paths["Stator"], "Stator")
    try:
        s.init(V0=324.0, s=0.005)
        names = _outputs(s.md) + list(STATOR_STATES)
        s.fmu.doStep(0.0, H_STEP)
        saved = s.fmu.getFMUstate()
        at_save = s.get(names)
        s.set(V0=324.0)
        s.fmu.doStep(H_STEP, H_STEP)
        first = s.get(names)
        s.fmu.setFMUstate(saved)
        restored = s.get(names)
        s.set(V0=100.0, F_N1_sin=3.0)
        s.fmu.doStep(H_STEP, H_STEP)
        other = s.get(names)
        s.fmu.setFMUstate(saved)
        s.set(V0=324.0, F_N1_sin=0.0)
        s.fmu.doStep(H_STEP, H_STEP)
        again = s.get(names)
        blob = s.fmu.serializeFMUstate(saved)
        s.fmu.freeFMUstate(saved)
        state2 = s.fmu.deSerializeFMUstate(blob)
        s.fmu.setFMUstate(state2)
        s.fmu.doStep(H_STEP, H_STEP)
        deser = s.get(names)
        s.fmu.freeFMUstate(state2)
        res["Stator"] = dict(at_save=at_save, first=first, restored=restored, other=other, again=again, deser=deser)
    finally:
        s.close()
    # Slider: speed, position and the stick / end-stop flags
    s = _Slave(paths["Slider"], "Slider")
    try:
        s.init(s0=0.0, v0=0.0)
        names = _outputs(s.md)
        s.set(F_d=1.0, F_p=5.6, m_load=0.0)
        s.fmu.doStep(0.0, 0.01)
        saved = s.fmu.getFMUstate()
        at_save = s.get(names)
        s.fmu.doStep(0.01, 0.01)
        first = s.get(names)
        s.fmu.setFMUstate(saved)
        restored = s.get(names)
        s.set(F_d=-2.0, m_load=0.05)
        s.fmu.doStep(0.01, 0.01)
        other = s.get(names)
        s.fmu.setFMUstate(saved)
        s.set(F_d=1.0, m_load=0.0)
        s.fmu.doStep(0.01, 0.01)
        again = s.get(names)
        s.fmu.freeFMUstate(saved)
        res["Slider"] = dict(at_save=at_save, first=first, restored=restored, other=other, again=again)
    finally:
        s.close()
    return res


def worker_defaults(paths):
    out = []
    for p in paths:
        s = _Slave(p, "Driver")
        try:
            s.init()
            start = float(s.vars["R_m_ohm"].start)
            s.fmu.doStep(0.0, H_STEP)
            out.append({"start": start, **s.get(["R_m_ohm", "V0"])})
        finally:
            s.close()
    return out


def worker_repeated_instantiation(paths, n):
    import gc
    out = {}
    for name in NAMES:
        vals = []
        for _ in range(n):
            s = _Slave(paths[name], name)
            try:
                s.init()
                s.fmu.doStep(0.0, H_STEP)
                vals.append(s.get(_outputs(s.md)[:1]))
            finally:
                s.close()
            gc.collect()
        out[name] = vals
    return out


RECORD = ["Driver.V0", "Stator.U_l", "Stator.U_w", "Stator.delta", "Stator.F_p", "Interface.F_d",
          "Interface.phi_c", "Interface.stick_fraction", "Slider.v", "Slider.s"]


def worker_cosim(fmu_dir, t_end, inputs, parameters, iterate, start_values, csv_path, repeat):
    from l1b2.cosim.master import CoSimulation
    runs = []
    for _ in range(repeat):
        cs = CoSimulation(fmu_dir=fmu_dir, parameters=parameters or None, iterate=iterate)
        r = cs.run(t_end, inputs, record=RECORD, start_values=start_values or None)
        res = {k: r.df[k].tolist() for k in ["time"] + RECORD}
        res["iterations"] = list(cs.iterations_)
        res["max_iter"] = cs.max_iter
        res["units"] = r.units
        if csv_path:
            r.to_csv(csv_path)
            res["csv_header"] = Path(csv_path).read_text().splitlines()[0]
        runs.append(res)
    return runs


# ---------------------------------------------------------------------------
# Model descriptions, validation, packaging
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_fmu_passes_fmpy_validation(fmus, name):
    # reference: fmpy.validation (schema and consistency checks of modelDescription.xml)
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fmus[name])) == []


@pytest.mark.parametrize("name", NAMES)
def test_every_real_has_a_defined_unit(fmus, name):
    # reference: FMI 2.0 UnitDefinitions; SI exponents of the definitions against the table written here
    md = read_model_description(str(fmus[name]))
    defs = {u.name: u for u in md.unitDefinitions}
    reals = [v for v in md.modelVariables if v.type == "Real"]
    assert reals
    for v in reals:
        assert v.unit, f"{name}.{v.name} has no unit"
        assert v.unit in defs, f"{name}.{v.name}: unit {v.unit} not in UnitDefinitions"
    for u in defs.values():
        if u.name in SI:
            bu = u.baseUnit
            got = {k: getattr(bu, k) for k in ("kg", "m", "s", "A", "K", "rad") if getattr(bu, k)}
            assert got == SI[u.name], u.name
    assert "degC" not in defs or defs["degC"].baseUnit.offset == pytest.approx(273.15)
    # parameters carry the units declared in l1b2.physics.params
    from l1b2.physics.params import describe, load_motor
    section = getattr(load_motor(), name.lower())
    declared = {d["name"]: d["unit"] for d in describe(type(section))}
    units = {v.name: v.unit for v in md.modelVariables}
    for pname, unit in declared.items():
        assert units[pname] == unit, pname


@pytest.mark.parametrize("name", NAMES)
def test_fmpy_dump_lists_units(fmus, name, capsys):
    # reference: the unit of every input/output (from the model description) appears on its dump line
    import fmpy
    fmpy.dump(str(fmus[name]))
    text = capsys.readouterr().out
    md = read_model_description(str(fmus[name]))
    lines = text.splitlines()
    for v in md.modelVariables:
        if v.causality in ("input", "output"):
            line = next(ln for ln in lines if re.match(rf"^\s+{re.escape(v.name)}\s", ln))
            assert re.search(rf"\s{re.escape(v.unit)}\s", line + " "), (v.name, v.unit, line)


@pytest.mark.parametrize("name", NAMES)
def test_bundle_is_version_unique(fmus, name):
    # reference: fmu_build docstring - resources/l1b2_<version>_<fmu>/, slave module l1b2_<version>_<fmu>_slave,
    # no shared top-level resources/pythonfmu/, no C host source inside
    pkg = "l1b2_" + re.sub(r"[^0-9A-Za-z]", "_", __version__) + "_" + name.lower()
    with zipfile.ZipFile(fmus[name]) as z:
        names = z.namelist()
        assert any(n.startswith(f"resources/{pkg}/") for n in names)
        assert f"resources/{pkg}/__init__.py" in names
        assert z.read("resources/slavemodule.txt").decode().strip() == f"{pkg}_slave"
        assert f"resources/{pkg}_slave.py" in names
        assert not any(n.startswith("resources/pythonfmu/") for n in names)
        assert not any(n.startswith("resources/l1b2/") for n in names)
        assert not any("/chost/" in n for n in names)
        # the bundled code imports only the bundled package
        src = z.read(f"resources/{pkg}_slave.py").decode()
        assert not re.search(r"^\s*(from|import)\s+l1b2(\s|\.)", src, flags=re.M)
        assert not re.search(r"^\s*(from|import)\s+pythonfmu(\s|\.)", src, flags=re.M)


def test_guid_is_stable_and_follows_the_defaults(tmp_path, motor):
    # reference: two builds of identical content share the GUID; changed defaults change it
    from l1b2.fmi.build import build_fmu
    g1 = read_model_description(str(build_fmu("Driver", tmp_path / "a", mp=motor))).guid
    g2 = read_model_description(str(build_fmu("Driver", tmp_path / "b", mp=motor))).guid
    g3 = read_model_description(str(build_fmu("Driver", tmp_path / "c",
                                              mp=motor.replace(driver__R_m_ohm=2100.0)))).guid
    assert re.fullmatch(r"\{[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}\}", g1)
    assert g1 == g2
    assert g3 != g1
    md3 = read_model_description(str(tmp_path / "c" / "Driver.fmu"))
    start = {v.name: v.start for v in md3.modelVariables}
    assert float(start["R_m_ohm"]) == 2100.0


def test_guids_differ_between_fmus(fmus):
    # reference: different content never shares a GUID (libcosim caches by GUID)
    guids = {read_model_description(str(p)).guid for p in fmus.values()}
    assert len(guids) == len(fmus)


def test_fmu_parameter_start_values_are_the_reference_motor(fmus, motor):
    # reference: the TOML values loaded by load_motor()
    for name in NAMES:
        md = read_model_description(str(fmus[name]))
        section = getattr(motor, name.lower())
        start = {v.name: v.start for v in md.modelVariables if v.causality == "parameter"}
        for f in dataclasses.fields(section):
            assert float(start[f.name]) == pytest.approx(getattr(section, f.name), rel=1e-15, abs=0), f.name


# ---------------------------------------------------------------------------
# Each FMU returns the outputs of its physics function
# ---------------------------------------------------------------------------

def test_driver_fmu_equals_driver_output(fmus, motor, isolated):
    # reference: l1b2.physics.driver.driver_output with the same (modified) parameters
    params = dict(R_m_ohm=2500.0, L_temp_coeff_per_K=5e-4)
    cases = [dict(V_s=67.1, duty=1.0, f_s=48500.0, T=25.0), dict(V_s=40.0, duty=0.6, f_s=47000.0, T=60.0),
             dict(V_s=90.0, duty=0.9, f_s=50000.0, T=10.0)]
    out = isolated(__file__, "worker_driver", str(fmus["Driver"]), params, cases).value
    dp = dataclasses.replace(motor.driver, **params)
    for case, got in zip(cases, out):
        ref = drv.driver_output(dp, case["V_s"], case["duty"], case["f_s"], case["T"])
        assert got["V0"] == pytest.approx(float(ref.V0_V), rel=1e-12)
        assert got["omega"] == pytest.approx(float(ref.omega_rad_s), rel=1e-14)
        assert got["V0_phase"] == pytest.approx(float(ref.phase_rad), abs=1e-12)
        assert got["V_inv1"] == pytest.approx(float(ref.V_inv1_V), rel=1e-12)
        assert got["omega0"] == pytest.approx(float(ref.omega0_rad_s), rel=1e-12)


def _stator_reference(sp, start, steps, h):
    """Envelope_step + tip_motion with the describing-function coupling of l1b2.cosim.blocks (written here)."""
    s = start["s"]
    P = float(st.axial_force_N(sp, s))
    props = st.modal_properties(sp, P, 25.0)
    eta_T = float(props.eta_T)
    Q_l = Q_b = 0j
    inp = dict(start)
    out = []

    def publish():
        tip = st.tip_motion(Q_l, Q_b, eta_T)
        return dict(U_l=float(tip.U_l_m), U_w=float(tip.U_w_m), delta=float(tip.delta_rad),
                    phase_l=float(tip.phase_l_rad), phase_w=float(tip.phase_w_rad), F_p=sp.alpha0 * P, P=P,
                    f_b=float(props.omega_b0) / (2 * math.pi), eta_T=eta_T, v_tip=inp["omega"] * float(tip.U_w_m),
                    Q_l_re=Q_l.real, Q_l_im=Q_l.imag, Q_b_re=Q_b.real, Q_b_im=Q_b.imag)

    out.append(publish())
    for step in steps:
        inp.update(step)
        rot = np.exp(1j * np.angle(st.ETA_N * Q_l))
        F1_N = complex(inp["F_N1_sin"], inp["F_N1_cos"]) * rot
        F1_T = complex(inp["F_T1_sin"], inp["F_T1_cos"]) * rot
        F_l, F_b = st.excitation_phasors(sp, inp["V0"], inp["direction"])
        if abs(Q_l) > 1e-15:
            Y_l, Fl_eff = st.ETA_N * F1_N / Q_l, F_l
        else:
            Y_l, Fl_eff = 0.0, F_l - st.ETA_N * F1_N
        if abs(Q_b) > 1e-15:
            Y_b, Fb_eff = eta_T * F1_T / Q_b, F_b
        else:
            Y_b, Fb_eff = 0.0, F_b - eta_T * F1_T
        w = inp["omega"]
        Q_l = complex(st.envelope_step(Q_l, Fl_eff, Y_l, w, props.M_l, props.K_l, props.C_l, h))
        Q_b = complex(st.envelope_step(Q_b, Fb_eff, Y_b, w, props.M_b, props.K_b, props.C_b, h))
        out.append(publish())
    return out


def test_stator_fmu_equals_envelope_steps(fmus, motor, isolated):
    # reference: envelope_step + tip_motion called here (module docstrings' conventions), several steps
    w = 2 * math.pi * 48500.0
    start = dict(V0=324.0, omega=w, direction=1.0, s=0.01, T=25.0,
                 F_N1_sin=0.0, F_N1_cos=0.0, F_T1_sin=0.0, F_T1_cos=0.0)
    steps = [dict(F_N1_sin=4.0, F_T1_sin=1.0), dict(F_N1_sin=9.7, F_N1_cos=0.0, F_T1_sin=2.6, F_T1_cos=-0.14),
             dict(V0=250.0), dict(V0=250.0, direction=-1.0, F_T1_sin=-2.0, F_T1_cos=0.3),
             dict(omega=2 * math.pi * 48300.0)]
    h = 3e-4
    got = isolated(__file__, "worker_stator", str(fmus["Stator"]), start, steps, h).value
    ref = _stator_reference(motor.stator, start, steps, h)
    assert len(got) == len(ref)
    for k, (g, r) in enumerate(zip(got, ref)):
        for key, val in r.items():
            if key in ("delta", "phase_l", "phase_w") and k == 0:
                continue  # undefined phase of a zero phasor
            scale = 1e-6 if key.startswith(("Q_", "U_")) else 1.0
            assert g[key] == pytest.approx(val, rel=1e-9, abs=1e-12 * scale), (k, key)
    # the tip really vibrates after a few steps
    assert got[-1]["U_l"] > 1e-8 and got[-1]["U_w"] > 1e-8


@pytest.mark.parametrize("mode, n_theta", [("stick_slip", 256), ("pure_slip", 512)])
def test_interface_fmu_equals_interface_forces(fmus, motor, isolated, mode, n_theta):
    # reference: l1b2.physics.interface.interface_forces with the same mode and resolution
    params = dict(pure_slip=(mode == "pure_slip"), n_theta=n_theta, mu_p=0.22)
    w = 2 * math.pi * 48500.0
    cases = [dict(U_l=1.22e-6, U_w=1.41e-6, delta=-1.69, omega=w, v=0.264, F_p=5.6),
             dict(U_l=0.1e-6, U_w=1.4e-6, delta=-math.pi / 2, omega=w, v=0.2, F_p=5.6),
             dict(U_l=1.0e-6, U_w=1.2e-6, delta=1.2, omega=w, v=-0.2, F_p=5.0)]
    got = isolated(__file__, "worker_interface", str(fmus["Interface"]), params, cases).value
    ip = dataclasses.replace(motor.interface, mu_p=0.22)
    for case, g in zip(cases, got[1:]):
        ref = itf.interface_forces(case["U_l"], case["U_w"], case["delta"], case["omega"], case["v"], case["F_p"],
                                   ip, mode=mode, n_theta=n_theta)
        for var, fld in [("F_d", "F_d_N"), ("F_N_mean", "F_N_mean_N"), ("F_N1_sin", "F_N1_sin_N"),
                         ("F_N1_cos", "F_N1_cos_N"), ("F_T1_sin", "F_T1_sin_N"), ("F_T1_cos", "F_T1_cos_N"),
                         ("phi_c", "phi_c_rad"), ("stick_fraction", "stick_fraction")]:
            assert g[var] == pytest.approx(float(getattr(ref, fld)), rel=1e-10, abs=1e-13), var
    # initialisation already computes the outputs of the first case
    assert got[0]["F_d"] == pytest.approx(got[1]["F_d"], rel=1e-12)


def test_slider_fmu_equals_slider_step(fmus, motor, isolated):
    # reference: l1b2.physics.slider.step called here with the same parameters, inputs and step sizes
    params = dict(s0=0.012, v0=0.1, mass_kg=0.15, c_r_N_s_per_m=3.0)  # light damping: reaches the stop
    steps = [(1.0, 5.6, 0.0, 1e-3)] * 30 + [(1.0, 5.6, 0.0, 0.02)] * 3 + [(-1.5, 5.6, 0.03, 5e-3)] * 20 \
        + [(0.0, 6.0, -0.02, 0.01)] * 10 + [(0.05, 6.0, 0.0, 0.01)] * 3
    got = isolated(__file__, "worker_slider", str(fmus["Slider"]), params, steps).value
    sp = dataclasses.replace(motor.slider, mass_kg=0.15, c_r_N_s_per_m=3.0)
    state = sld.SliderState(0.1, 0.012, False, 0)
    assert got[0]["s"] == 0.012 and got[0]["v"] == 0.1
    saw_stop = saw_stuck = False
    for (F_d, F_p, m_load, h), g in zip(steps, got[1:]):
        state = sld.step(sp, state, F_d, F_p, m_load, h)
        assert g["v"] == pytest.approx(state.v_m_s, rel=1e-12, abs=1e-15)
        assert g["s"] == pytest.approx(state.s_m, rel=1e-12, abs=1e-15)
        assert g["stuck"] == float(state.stuck)
        assert g["at_stop"] == float(state.at_stop)
        saw_stop |= state.at_stop != 0
        saw_stuck |= state.stuck
    assert saw_stop and saw_stuck  # the scenario covered the end stop and the stick state


# ---------------------------------------------------------------------------
# Robustness: bad inputs, FMU state, repeated instantiation
# ---------------------------------------------------------------------------

def test_non_finite_input_is_discarded_without_crash(fmus, isolated):
    # reference: FMI 2.0 - a refused step returns fmi2Discard (status 2), the instance can still be freed
    paths = {n: str(p) for n, p in fmus.items()}
    res = isolated(__file__, "worker_nonfinite", paths)
    for name, var in (("Slider", "F_d"), ("Interface", "U_l"), ("Stator", "V0")):
        r = res.value[name]
        assert r["raised"], name
        assert r["status"] == 2 and r["function"] == "fmi2DoStep", r
        assert r["freed"]
    # the FMU log names the offending input and its unit
    log = res.stdout
    assert re.search(r"F_d \[N\].*not finite", log), log[-2000:]
    assert re.search(r"U_l \[m\].*not finite", log), log[-2000:]


def test_fmu_state_rolls_back_continuous_states(fmus, isolated):
    # reference: the first path (step, step) must be reproduced exactly after save/other step/restore
    paths = {n: str(p) for n, p in fmus.items()}
    res = isolated(__file__, "worker_state_rollback", paths).value
    for name in ("Stator", "Slider"):
        r = res[name]
        assert r["again"] == r["first"], name
        assert r["restored"] == r["at_save"], name       # outputs follow the restored state at once
        assert r["other"] != r["first"], name            # the other input really changed the path
    assert res["Stator"]["deser"] == res["Stator"]["first"]  # serialised state works too
    assert res["Stator"]["first"]["U_l"] > 0


def test_fmus_can_be_instantiated_repeatedly_in_one_process(fmus, isolated):
    # reference: a host may instantiate/free the same FMU many times (PythonFMU 0.7.0 drops a reference to
    # the slave module's globals on every instantiation; this must not crash)
    paths = {n: str(p) for n, p in fmus.items()}
    res = isolated(__file__, "worker_repeated_instantiation", paths, 6).value
    for name in NAMES:
        vals = res[name]
        assert len(vals) == 6
        assert all(v == vals[0] for v in vals), name


# ---------------------------------------------------------------------------
# The fmpy co-simulation master against the in-process reference
# ---------------------------------------------------------------------------

def _in_process(mp, t_end, s0=0.0, h=H_STEP, **inputs):
    from l1b2.cosim.engine import InProcessMotor
    m = InProcessMotor(mp, h_s=h)
    kw = dict(SYSTEM_INPUTS, V_s=mp.operating.V_s_V)
    kw.update(inputs)
    m.initialize(**kw, s0=s0)
    return m.run(t_end, record=tuple(RECORD))


@pytest.fixture(scope="module")
def cosim_base(fmu_dir, motor, isolated, tmp_path_factory):
    csv = tmp_path_factory.mktemp("cosim") / "run.csv"
    inputs = dict(SYSTEM_INPUTS, V_s=motor.operating.V_s_V)
    return isolated(__file__, "worker_cosim", str(fmu_dir), 0.1, inputs, {}, False, {}, str(csv), 1).value[0]


def test_cosimulation_agrees_with_in_process_motor(cosim_base, motor):
    # reference: l1b2.cosim.engine.InProcessMotor (hand-wired blocks, same Gauss-Seidel algorithm)
    ref = _in_process(motor, 0.1)
    v, v_ref = np.array(cosim_base["Slider.v"]), ref["Slider.v"]
    assert len(v) == len(v_ref) == 501
    peak = np.max(np.abs(v_ref))
    assert peak > 0.1
    assert np.max(np.abs(v - v_ref)) <= 0.01 * peak
    # essentially exact: same arithmetic on both sides
    for k in RECORD:
        a, b = np.array(cosim_base[k]), ref[k]
        assert np.max(np.abs(a - b)) <= 1e-9 * max(np.max(np.abs(b)), 1e-30), k


def test_cosim_csv_has_units_in_header(cosim_base):
    # reference: CoSimResult.to_csv contract ("Slider.v [m/s]"), units from the FMUs' model descriptions
    header = cosim_base["csv_header"].split(",")
    assert header[0] == "time [s]"
    expected = {"Slider.v": "m/s", "Slider.s": "m", "Driver.V0": "V", "Stator.U_l": "m", "Interface.F_d": "N",
                "Interface.phi_c": "rad", "Interface.stick_fraction": "1"}
    for col, unit in expected.items():
        assert f"{col} [{unit}]" in header


def test_cosim_parameter_override(fmu_dir, motor, isolated, cosim_base):
    # reference: InProcessMotor with the same replacement in MotorParams
    inputs = dict(SYSTEM_INPUTS, V_s=motor.operating.V_s_V)
    res = isolated(__file__, "worker_cosim", str(fmu_dir), 0.1, inputs, {"Interface.mu_p": 0.2}, False, {}, "",
                   1).value[0]
    ref = _in_process(motor.replace(interface__mu_p=0.2), 0.1)
    v, v_ref = np.array(res["Slider.v"]), ref["Slider.v"]
    peak = np.max(np.abs(v_ref))
    assert np.max(np.abs(v - v_ref)) <= 0.01 * peak
    base = np.array(cosim_base["Slider.v"])
    assert np.max(np.abs(v - base)) > 0.03 * np.max(np.abs(base))  # the override really acted


@pytest.fixture(scope="module")
def cosim_iterated(fmu_dir, motor, isolated):
    inputs = dict(SYSTEM_INPUTS, V_s=motor.operating.V_s_V)
    return isolated(__file__, "worker_cosim", str(fmu_dir), 0.1, inputs, {}, True, {"Slider.s0": -0.02}, "",
                    1).value[0]


def test_iterated_cosim_gives_the_same_steady_speed(cosim_iterated, motor):
    # reference: the non-iterated in-process run from the same start (quasi-steady after 2.5 slider time constants)
    ref = _in_process(motor, 0.1, s0=-0.02)
    v_it = cosim_iterated["Slider.v"][-1]
    assert v_it == pytest.approx(ref["Slider.v"][-1], rel=1e-3)
    assert cosim_iterated["Slider.s"][-1] == pytest.approx(ref["Slider.s"][-1], abs=1e-4)


def test_iterated_cosim_converges(cosim_iterated):
    # reference: the fixed-point iteration must meet its tolerance before max_iter
    its = np.array(cosim_iterated["iterations"])
    assert len(its) == 500
    assert np.all(its < cosim_iterated["max_iter"])


def test_cosimulation_can_run_twice_in_one_process(fmu_dir, motor, isolated):
    # reference: two identical runs in one process must both succeed and agree exactly
    inputs = dict(SYSTEM_INPUTS, V_s=motor.operating.V_s_V)
    runs = isolated(__file__, "worker_cosim", str(fmu_dir), 0.01, inputs, {}, False, {}, "", 2).value
    assert runs[0]["Slider.v"] == runs[1]["Slider.v"]


def worker_cosim_kept(fmu_dir, t_end, inputs, plans):
    """Runs with different start values and inputs, once through one CoSimulation that keeps its
    FMU instances (fmi2Reset between runs) and once through a fresh CoSimulation each."""
    from l1b2.cosim.master import CoSimulation
    kept, fresh = [], []
    with CoSimulation(fmu_dir=fmu_dir, keep_instances=True) as cs:
        for start, extra in plans:
            r = cs.run(t_end, {**inputs, **extra}, record=RECORD + ["Slider.at_stop"], start_values=start,
                       stop_when=lambda v: v["Slider.at_stop"] != 0.0)
            kept.append({k: r.df[k].tolist() for k in ["time"] + RECORD})
        n_kept = len(cs._kept)
    for start, extra in plans:
        with CoSimulation(fmu_dir=fmu_dir) as cs:
            r = cs.run(t_end, {**inputs, **extra}, record=RECORD + ["Slider.at_stop"], start_values=start,
                       stop_when=lambda v: v["Slider.at_stop"] != 0.0)
            fresh.append({k: r.df[k].tolist() for k in ["time"] + RECORD})
    return {"kept": kept, "fresh": fresh, "n_kept": n_kept}


def test_cosimulation_keeps_instances_across_runs(fmu_dir, motor, isolated):
    # reference: the same runs, each through a fresh CoSimulation (new instances): results identical
    inputs = dict(SYSTEM_INPUTS, V_s=motor.operating.V_s_V)
    plans = [({"Slider.s0": -0.02, "Stator.s": -0.02}, {}),
             ({"Slider.s0": 0.01, "Stator.s": 0.01}, {"direction": -1.0, "m_load": 0.03}),
             ({"Slider.s0": -0.02, "Stator.s": -0.02}, {})]
    res = isolated(__file__, "worker_cosim_kept", str(fmu_dir), 0.03, inputs, plans).value
    assert res["n_kept"] == 4
    for kept, fresh in zip(res["kept"], res["fresh"]):
        assert kept == fresh
    assert res["kept"][0] == res["kept"][2]
    assert res["kept"][0]["Slider.v"] != res["kept"][1]["Slider.v"]


def test_fmus_with_other_defaults_use_their_own_defaults(tmp_path, motor, fmus, isolated):
    # reference: each FMU's own modelDescription start value of R_m_ohm and driver_output with it
    from l1b2.fmi.build import build_fmu
    other = build_fmu("Driver", tmp_path, mp=motor.replace(driver__R_m_ohm=2600.0))
    res = isolated(__file__, "worker_defaults", [str(fmus["Driver"]), str(other)]).value
    op = motor.operating
    for r, R in zip(res, (motor.driver.R_m_ohm, 2600.0)):
        assert r["start"] == R
        assert r["R_m_ohm"] == R
        dp = dataclasses.replace(motor.driver, R_m_ohm=R)
        assert r["V0"] == pytest.approx(float(drv.driver_output(dp, op.V_s_V, op.duty, op.f_drive_Hz, op.T_degC).V0_V),
                                        rel=1e-12)


def worker_build_after_run(dest):
    from fmpy import simulate_fmu
    from l1b2.fmi.build import build_fmu
    first = build_fmu("Driver", f"{dest}/a")
    simulate_fmu(str(first), stop_time=1e-3, step_size=1e-3)   # leaves the FMU's modules imported
    second = build_fmu("Driver", f"{dest}/b")                   # must build from the new script
    return float(simulate_fmu(str(second), stop_time=1e-3, step_size=1e-3)["V0"][-1])


def test_fmu_can_be_rebuilt_after_running_in_the_same_process(tmp_path, motor, isolated):
    # reference: driver_output of the reference motor; the demo runs FMUs, then exports (builds) again
    op = motor.operating
    V0 = isolated(__file__, "worker_build_after_run", str(tmp_path)).value
    assert V0 == pytest.approx(float(drv.driver_output(motor.driver, op.V_s_V, op.duty, op.f_drive_Hz,
                                                        op.T_degC).V0_V), rel=1e-12)


def worker_cosim_refused(fmu_dir, inputs):
    """A run whose input makes the Stator FMU refuse its step: the master's error, one line."""
    from l1b2.cosim.master import CoSimulation
    from l1b2.errors import SimulationError
    with CoSimulation(fmu_dir=fmu_dir) as cs:
        try:
            cs.run(0.002, inputs, record=["Slider.v"])
        except SimulationError as exc:
            return str(exc)
    return None


def test_master_turns_a_refused_step_into_a_simulation_error(fmu_dir, motor, isolated):
    # reference: FMI 2.0 - a step refused with fmi2Discard ends the run; the master calls the FMI functions
    # through ctypes directly and checks the status itself, naming the component, the time and the status
    inputs = dict(SYSTEM_INPUTS, V_s=motor.operating.V_s_V, direction=0.5)  # the stator needs +1 or -1
    msg = isolated(__file__, "worker_cosim_refused", str(fmu_dir), inputs).value
    assert msg is not None and "\n" not in msg
    assert re.match(r"Stator\.doStep at t=0 s failed \(fmi2Discard\); see the FMU log above", msg), msg
