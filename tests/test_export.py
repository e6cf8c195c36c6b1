"""``l1b2.fmi.export.export_all``: the deliverables, their validation, the manifest, and the coupled-motor FMU.

The export is built once per session (conftest ``exported``); everything that
instantiates an FMU runs in a fresh process (conftest ``isolated``).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import read_model_description
from l1b2 import __version__
from l1b2.cosim import ssp
from l1b2.fmi.export import ExportError, export_all
from lxml import etree

pytestmark = pytest.mark.fmu

SUBSYSTEMS = ("Driver", "Stator", "Interface", "Slider")
SCHEMA_DIR = Path(fmpy.__file__).parent / "ssp" / "schema"
H = 2e-4


def _fmu_files(out: Path, manifest: dict) -> dict[str, Path]:
    """The Python FMUs by model name (the native ones, ``*-native*.fmu``, are tested in test_native_fmu.py)."""
    return {rec["modelName"]: out / rec["path"] for rec in manifest["files"]
            if rec["kind"] == "fmu" and "-native" not in rec["path"]}


# ---------------------------------------------------------------------------
# Workers (fresh process each)
# ---------------------------------------------------------------------------

def worker_motor_fmu_vs_cosim(motor_fmu, ssp_path, t_end, inputs, s0):
    """L1B2Motor.fmu through fmpy.simulate_fmu, and the four FMUs of the .ssp through l1b2.cosim.master."""
    from fmpy import simulate_fmu
    from l1b2.cosim.hosting import install_exit_fix
    from l1b2.cosim.master import CoSimulation
    install_exit_fix()
    r = simulate_fmu(motor_fmu, stop_time=t_end, step_size=H, output_interval=H,
                     start_values={**inputs, "Slider.s0": s0}, output=["v", "s", "F_d", "at_stop"])
    with CoSimulation(ssp_path, step_s=H) as cs:
        c = cs.run(t_end, inputs, record=["Slider.v", "Slider.s", "Interface.F_d"],
                   start_values={"Slider.s0": s0, "Stator.s": s0})
    return {"fmu_time": r["time"].tolist(), "fmu_v": r["v"].tolist(), "fmu_s": r["s"].tolist(),
            "cs_time": c.df["time"].tolist(), "cs_v": c.df["Slider.v"].tolist(), "cs_s": c.df["Slider.s"].tolist()}


def worker_master_reads_ssd_and_ssp(ssp_path, fmu_dir, inputs):
    """Our master on the source tree's SSD (FMUs from fmu_dir) and on the packed .ssp."""
    from l1b2.cosim.master import CoSimulation
    out = {}
    for key, system in (("ssd", str(ssp.SSD_FILE)), ("ssp", ssp_path)):
        with CoSimulation(system, fmu_dir=fmu_dir) as cs:
            r = cs.run(0.01, inputs, record=["Slider.v", "Stator.U_w"])
            out[key] = {"v": r["Slider.v"].tolist(), "U_w": r["Stator.U_w"].tolist(),
                        "parameters": cs.parameters}
    return out


# ---------------------------------------------------------------------------
# Files, validation, manifest
# ---------------------------------------------------------------------------

def test_export_writes_every_deliverable(exported):
    # reference: the layout of the issue (four subsystem FMUs + predictor, L1B2Motor.ssp, L1B2Motor.fmu, manifest)
    out, manifest = exported
    for name in SUBSYSTEMS:
        assert (out / "fmus" / f"{name}.fmu").is_file()
    assert (out / "L1B2Motor.ssp").is_file() and (out / "L1B2Motor.fmu").is_file()
    assert json.loads((out / "manifest.json").read_text()) == manifest
    assert manifest["predictor"] == {"included": True, "path": "fmus/Predictor.fmu"}
    assert (out / "fmus" / "Predictor.fmu").is_file()
    paths = sorted(rec["path"] for rec in manifest["files"])
    natives = [f"{stem}.fmu" for name, info in manifest["native"].items() for stem in info.get("fmus", [])]
    assert "Predictor-native" in manifest["native"]["Predictor"]["fmus"]
    assert paths == sorted([f"fmus/{n}.fmu" for n in SUBSYSTEMS + ("Predictor",)]
                           + ["L1B2Motor.fmu", "L1B2Motor.ssp", "L1B2Motor_libcosim.ssp"]
                           + [f"fmus/{n}" if n.startswith("Predictor") else n for n in natives])
    for rec in manifest["files"]:
        f = out / rec["path"]
        assert rec["bytes"] == f.stat().st_size
        assert oct(f.stat().st_mode & 0o777) == "0o644"
    assert manifest["version"] == __version__
    assert manifest["runtime"]["python"] == "3.11"


def test_every_exported_fmu_passes_fmpy_validation(exported):
    # reference: fmpy.validation.validate_fmu called here, independently of the manifest
    from fmpy.validation import validate_fmu
    out, manifest = exported
    fmus = _fmu_files(out, manifest)
    assert set(fmus) == set(SUBSYSTEMS) | {"Predictor", "L1B2Motor"}
    for name, path in fmus.items():
        assert validate_fmu(str(path)) == [], name
    for rec in manifest["files"]:
        if rec["kind"] == "fmu":
            assert rec["validation"] == {"fmpy": [], "units": []}


def test_every_real_of_every_exported_fmu_has_a_defined_unit(exported):
    # reference: FMI 2.0 UnitDefinitions; every unit used is defined with SI base-unit exponents
    out, manifest = exported
    for name, path in _fmu_files(out, manifest).items():
        md = read_model_description(str(path))
        defs = {u.name: u for u in md.unitDefinitions}
        reals = [v for v in md.modelVariables if v.type == "Real"]
        assert reals, name
        for v in reals:
            assert v.unit, f"{name}.{v.name} has no unit"
            assert v.unit in defs, f"{name}.{v.name}: unit {v.unit} not defined"
            assert defs[v.unit].baseUnit is not None, f"{name}: unit {v.unit} has no BaseUnit"


def test_fmu_metadata_a_host_expects(exported):
    # reference: FMI 2.0 attributes - author/version/license, default experiment, outputs in ModelStructure,
    # get/set FMU state capability, co-simulation only, binaries for linux64 and win64
    out, manifest = exported
    for name, path in _fmu_files(out, manifest).items():
        md = read_model_description(str(path))
        assert md.author and md.license == "MIT" and md.version == __version__, name
        assert md.defaultExperiment is not None and md.defaultExperiment.stepSize, name
        assert md.coSimulation is not None and md.modelExchange is None, name
        assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate, name
        outputs = [v for v in md.modelVariables if v.causality == "output"]
        assert len(md.outputs) == len(outputs) > 0, name
        rec = next(r for r in manifest["files"] if r.get("modelName") == name)
        assert rec["guid"] == md.guid and rec["platforms"] == ["linux64", "win64"]


def test_guids_are_unique_and_stable(exported, tmp_path, motor):
    # reference: a rebuild of identical content gives the same GUID; other content another one
    from l1b2.fmi.build import build_fmu
    out, manifest = exported
    guids = [r["guid"] for r in manifest["files"] if r["kind"] == "fmu"]
    assert len(set(guids)) == len(guids)
    again = read_model_description(str(build_fmu("L1B2Motor", tmp_path / "a", mp=motor))).guid
    assert again == read_model_description(str(out / "L1B2Motor.fmu")).guid
    other = read_model_description(str(build_fmu("L1B2Motor", tmp_path / "b",
                                                 mp=motor.replace(slider__mass_kg=0.13)))).guid
    assert other != again


def test_ssp_archive_layout_and_schemas(exported):
    # reference: SSP 1.0 archive layout and the XSDs shipped with fmpy (validated here with lxml);
    # the archive holds the source tree's SSD unchanged, the reference parameter sets and the exported FMUs
    out, manifest = exported
    ssd_schema = etree.XMLSchema(etree.parse(str(SCHEMA_DIR / "SystemStructureDescription.xsd")))
    ssv_schema = etree.XMLSchema(etree.parse(str(SCHEMA_DIR / "SystemStructureParameterValues.xsd")))
    with zipfile.ZipFile(out / "L1B2Motor.ssp") as z:
        names = set(z.namelist())
        assert names == ({"SystemStructure.ssd"} | {f"resources/{n}.fmu" for n in SUBSYSTEMS}
                         | {f"resources/reference_motor/{n}.ssv" for n in SUBSYSTEMS})
        ssd = z.read("SystemStructure.ssd")
        # system connections as standard SSP connections (what fmucontainer, pyssp, ecos read)
        assert ssd.decode() == ssp.standard_ssd_text(ssp.SSD_FILE.read_text())
        assert b"<ssd:Connection startConnector=\"V_s\" endElement=\"Driver\"" in ssd
        assert ssp.SYSTEM_CONNECTIONS_ANNOTATION.encode() not in ssd
        assert ssd_schema.validate(etree.fromstring(ssd)), ssd_schema.error_log
        for n in SUBSYSTEMS:
            ssv = z.read(f"resources/reference_motor/{n}.ssv")
            assert ssv_schema.validate(etree.fromstring(ssv)), ssv_schema.error_log
            assert ssv.decode() == (ssp.SSV_DIR / f"{n}.ssv").read_text()
            assert z.read(f"resources/{n}.fmu") == (out / "fmus" / f"{n}.fmu").read_bytes()
    with zipfile.ZipFile(out / "L1B2Motor_libcosim.ssp") as z:  # the layout libcosim loads: the SSD as written
        assert z.read("SystemStructure.ssd") == ssp.SSD_FILE.read_bytes()
        assert ssd_schema.validate(etree.fromstring(z.read("SystemStructure.ssd"))), ssd_schema.error_log
    recs = [r for r in manifest["files"] if r["kind"] == "ssp"]
    assert [(r["path"], r["system_connections"]) for r in recs] == [("L1B2Motor.ssp", "standard"),
                                                                    ("L1B2Motor_libcosim.ssp", "annotation")]
    rec = recs[0]
    assert recs[1]["validation"] == {"schema": {}} and recs[1]["system_inputs"] == rec["system_inputs"]
    assert rec["validation"] == {"schema": {}}
    assert rec["system_inputs"] == ["V_s", "duty", "f_s", "T", "direction", "m_load"]
    assert rec["default_step_size_s"] == H


@pytest.mark.parametrize("given, slave_exists, reason", [(False, True, "predictor=None"),
                                                          (True, False, "no Predictor slave")])
def test_export_without_predictor_says_so(tmp_path, exported, predictor_setup, monkeypatch, given, slave_exists,
                                          reason):
    # reference: the issue - no identification result (or no Predictor slave in this tree): no Predictor.fmu,
    # and the manifest tells why; a stale Predictor.fmu from an earlier export is removed
    import l1b2.fmi.export
    monkeypatch.setattr(l1b2.fmi.export, "predictor_available", lambda: slave_exists)
    (tmp_path / "fmus").mkdir()
    (tmp_path / "fmus" / "Predictor.fmu").write_bytes((exported[0] / "fmus" / "Predictor.fmu").read_bytes())
    manifest = export_all(tmp_path, predictor=predictor_setup if given else None)
    assert manifest["predictor"]["included"] is False
    assert reason in manifest["predictor"]["reason"]
    assert not (tmp_path / "fmus" / "Predictor.fmu").exists()
    assert all("Predictor" not in r["path"] for r in manifest["files"])
    # four subsystems, L1B2Motor.fmu, L1B2Motor.ssp, L1B2Motor_libcosim.ssp, and the motor's native FMUs where built
    assert len(manifest["files"]) == 7 + len(manifest["native"]["L1B2Motor"].get("fmus", []))


def test_export_refuses_an_fmu_with_validation_problems(tmp_path, monkeypatch):
    # reference: the contract "zero problems, raise otherwise"; no manifest is written
    import fmpy.validation
    monkeypatch.setattr(fmpy.validation, "validate_fmu",
                        lambda filename: ["variable 'x': made-up problem"] if filename.endswith("Slider.fmu") else [])
    with pytest.raises(ExportError, match=r"fmus/Slider.fmu: fmpy: variable 'x': made-up problem"):
        export_all(tmp_path)
    assert not (tmp_path / "manifest.json").exists()


# ---------------------------------------------------------------------------
# Our master on the SSD and on the packed SSP; the coupled-motor FMU
# ---------------------------------------------------------------------------

def test_master_reads_source_tree_ssd_and_packed_ssp_alike(exported, motor, isolated):
    # reference: the same FMUs and parameter values through both routes give identical runs;
    # the parameters read from the per-component SSVs are the reference motor's
    out, _ = exported
    inputs = dict(V_s=67.1, duty=1.0, f_s=48500.0, T=25.0, direction=1.0, m_load=0.0)
    res = isolated(__file__, "worker_master_reads_ssd_and_ssp", str(out / "L1B2Motor.ssp"), str(out / "fmus"),
                   inputs).value
    assert res["ssd"]["v"] == res["ssp"]["v"] and res["ssd"]["U_w"] == res["ssp"]["U_w"]
    assert res["ssd"]["parameters"] == res["ssp"]["parameters"]
    params = res["ssp"]["parameters"]
    assert params["Slider.mass_kg"] == motor.slider.mass_kg
    assert params["Stator.f_b0_Hz"] == motor.stator.f_b0_Hz
    assert len(params) == sum(len(ssp.read_ssv(ssp.SSV_DIR / f"{n}.ssv")) for n in SUBSYSTEMS)


@pytest.mark.parametrize("m_load", [0.0, 0.05])
def test_motor_fmu_agrees_with_four_fmu_cosimulation(exported, motor, isolated, m_load):
    # reference: the four subsystem FMUs of L1B2Motor.ssp under our master (same communication step);
    # a full traverse at 324 V from the end stop, within 1 % of the peak speed
    from l1b2.physics import driver as drv
    out, _ = exported
    V_s = float(drv.supply_for_voltage_V(motor.driver, 324.0, 1.0, 48500.0, 25.0))
    inputs = dict(V_s=V_s, duty=1.0, f_s=48500.0, T=25.0, direction=1.0, m_load=m_load)
    s0 = motor.slider.s_min_m
    r = isolated(__file__, "worker_motor_fmu_vs_cosim", str(out / "L1B2Motor.fmu"), str(out / "L1B2Motor.ssp"),
                 0.3, inputs, s0).value
    v_fmu, v_cs = np.array(r["fmu_v"]), np.array(r["cs_v"])
    assert len(v_fmu) == len(v_cs) == 1501
    np.testing.assert_allclose(r["fmu_time"], r["cs_time"], atol=1e-12)
    peak = np.max(np.abs(v_cs))
    assert peak > 0.1
    assert np.max(np.abs(v_fmu - v_cs)) <= 0.01 * peak
    assert r["fmu_s"][-1] == pytest.approx(motor.slider.s_max_m)
    assert r["cs_s"][-1] == pytest.approx(motor.slider.s_max_m)


def test_master_refuses_parameter_set_with_unknown_name_or_other_unit(exported, tmp_path):
    # reference: the FMUs' model descriptions (variable names, units); the message names the .ssv file
    from l1b2.cosim.master import CoSimulation
    from l1b2.errors import SystemStructureError
    out, _ = exported
    (tmp_path / "reference_motor").mkdir()
    ssd = tmp_path / "L1B2Motor.ssd"
    ssd.write_text(ssp.SSD_FILE.read_text())
    for n in SUBSYSTEMS:
        (tmp_path / "reference_motor" / f"{n}.ssv").write_text((ssp.SSV_DIR / f"{n}.ssv").read_text())
    CoSimulation(ssd, fmu_dir=out / "fmus").close()  # as copied: accepted
    bad = tmp_path / "reference_motor" / "Driver.ssv"
    good = bad.read_text()
    for text, match in ((good.replace('unit="Hz"', 'unit="kHz"', 1), r"unit \[kHz\], the FMU declares \[Hz\]"),
                        (good.replace('name="L_H"', 'name="L_Henry"'), "Driver has no variable 'L_Henry'")):
        bad.write_text(text)
        with pytest.raises(SystemStructureError, match=match) as exc:
            CoSimulation(ssd, fmu_dir=out / "fmus")
        assert str(bad) in str(exc.value)
