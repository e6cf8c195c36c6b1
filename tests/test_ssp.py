"""SSP system structure and parameter values: l1b2.ssp, system_models/L1B2Motor.ssd, reference_motor.ssv."""

from __future__ import annotations

import dataclasses
import os
import zipfile

import fmpy
import pytest
from lxml import etree

from l1b2 import ssp
from l1b2.errors import SystemStructureError
from l1b2.params import describe, load_motor
from l1b2.units import UNITS

SCHEMA_DIR = os.path.join(os.path.dirname(fmpy.__file__), "ssp", "schema")
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
}


def _schema(name):
    return etree.XMLSchema(etree.parse(os.path.join(SCHEMA_DIR, name)))


@pytest.fixture(scope="module")
def ssd_schema():
    return _schema("SystemStructureDescription.xsd")


@pytest.fixture(scope="module")
def ssv_schema():
    return _schema("SystemStructureParameterValues.xsd")


def test_ssd_validates_against_ssp_schema(ssd_schema):
    # reference: the SSP 1.0 XSD shipped with fmpy
    doc = etree.parse(str(ssp.SSD_FILE))
    assert ssd_schema.validate(doc), ssd_schema.error_log


def test_ssv_validates_against_ssp_schema(ssv_schema):
    # reference: the SSP 1.0 XSD shipped with fmpy (committed file and freshly generated text)
    assert ssv_schema.validate(etree.parse(str(ssp.SSV_FILE))), ssv_schema.error_log
    fresh = etree.fromstring(ssp.motor_to_ssv(load_motor()).encode())
    assert ssv_schema.validate(fresh), ssv_schema.error_log


def test_read_ssd_finds_components_and_all_connections():
    # reference: independent lxml parse of the same file
    sysst = ssp.read_ssd()
    doc = etree.parse(str(ssp.SSD_FILE))
    comps = [c.get("name") for c in doc.iterfind(".//ssd:Elements/ssd:Component", NS)]
    assert comps == ["Driver", "Stator", "Interface", "Slider"]
    assert list(sysst.components) == comps  # document order = Gauss-Seidel order
    xml_conns = [(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                 for c in doc.iterfind(".//ssd:Connections/ssd:Connection", NS)]
    got = [(c.start_element, c.start_connector, c.end_element, c.end_connector) for c in sysst.connections]
    assert got == xml_conns
    assert len(got) >= 20
    # every component input is fed by exactly one connection, every endpoint exists
    for name, comp in sysst.components.items():
        for conn in comp.connectors.values():
            if conn.kind == "input":
                assert sum(1 for c in sysst.connections
                           if c.end_element == name and c.end_connector == conn.name) == 1, (name, conn.name)
    for c in sysst.connections:
        sysst.unit_of(c.start_element, c.start_connector)
        sysst.unit_of(c.end_element, c.end_connector)
    # the physics loop of paper Fig. 3 is closed: stator <-> interface <-> slider
    pairs = {(c.start_element, c.end_element) for c in sysst.connections}
    for p in [("Driver", "Stator"), ("Stator", "Interface"), ("Interface", "Stator"), ("Interface", "Slider"),
              ("Slider", "Interface"), ("Slider", "Stator")]:
        assert p in pairs
    assert sysst.parameter_sources == ["resources/reference_motor.ssv"]


def test_ssd_unit_definitions_agree_with_l1b2_units():
    # reference: SI base-unit exponents of the SSD's ssd:Units against l1b2.units.UNITS
    doc = etree.parse(str(ssp.SSD_FILE))
    units = doc.findall(".//ssd:Units/ssc:Unit", NS)
    assert units
    for u in units:
        base = u.find("ssc:BaseUnit", NS)
        attrs = {k: v for k, v in base.attrib.items()}
        ref = UNITS[u.get("name")].base_unit_attributes()
        assert {k: float(v) for k, v in attrs.items()} == {k: float(v) for k, v in ref.items()}, u.get("name")


def test_committed_ssv_is_in_sync_with_the_toml():
    # reference: regenerate the SSV from reference_motor.toml; the committed file must be identical
    assert ssp.SSV_FILE.read_text() == ssp.motor_to_ssv(load_motor())


def test_ssv_values_equal_motor_values():
    # reference: every parameter of every component, with its declared unit
    mp = load_motor()
    values = ssp.read_ssv(ssp.SSV_FILE)
    n = 0
    for comp, attr in ssp.COMPONENT_PARAMS.items():
        params = getattr(mp, attr)
        for d in describe(type(params)):
            value, unit = values[f"{comp}.{d['name']}"]
            assert value == getattr(params, d["name"])
            assert unit == d["unit"]
            n += 1
    assert n == len(values)


def test_ssv_round_trip(tmp_path, motor):
    # reference: MotorParams -> SSV text -> MotorParams must be the identity (repr floats)
    changed = motor.replace(stator__zeta_b=0.0123456789, interface__mu_p=0.2345678901234567,
                            driver__L_H=1.23456789e-3, slider__mass_kg=0.1357913579)
    path = tmp_path / "changed.ssv"
    path.write_text(ssp.motor_to_ssv(changed, name="changed"))
    back = ssp.ssv_to_motor(path, base=motor)
    for sec in ("driver", "stator", "interface", "slider"):
        assert getattr(back, sec) == getattr(changed, sec), sec
    assert back.operating == motor.operating


def test_ssv_with_wrong_unit_is_refused(tmp_path):
    # reference: SSV units must equal the declared ones
    text = ssp.SSV_FILE.read_text().replace('unit="Hz"', 'unit="kHz"', 1)
    path = tmp_path / "bad.ssv"
    path.write_text(text)
    with pytest.raises(SystemStructureError, match="unit"):
        ssp.ssv_to_motor(path, base=load_motor())


def _mutated_ssd(tmp_path, old, new):
    text = ssp.SSD_FILE.read_text()
    assert text.count(old) >= 1
    path = tmp_path / "L1B2Motor_bad.ssd"
    path.write_text(text.replace(old, new, 1))
    return path


def test_ssd_with_mismatched_connector_unit_is_refused(tmp_path):
    # reference: a connection from Driver.V0 [V] to Stator.V0 declared in [m] has incompatible dimensions
    old = ('<ssd:Connector name="V0" kind="input"><ssc:Real unit="V"/></ssd:Connector>')
    path = _mutated_ssd(tmp_path, old, old.replace('unit="V"', 'unit="m"'))
    with pytest.raises(SystemStructureError) as exc:
        ssp.read_ssd(path)
    msg = str(exc.value)
    assert "V0" in msg and "[V]" in msg and "[m]" in msg and str(path) in msg


def test_ssd_with_unknown_endpoint_is_refused(tmp_path):
    # reference: every connection endpoint must be a declared connector
    old = 'startElement="Interface" startConnector="F_d" endElement="Slider" endConnector="F_d"'
    path = _mutated_ssd(tmp_path, old, old.replace('endConnector="F_d"', 'endConnector="F_drive"'))
    with pytest.raises(SystemStructureError, match="F_drive"):
        ssp.read_ssd(path)


def test_same_dimension_is_dimensional_not_textual():
    # reference: SI definitions - Hz and 1/s agree, Hz and rad/s do not (rad is kept as a base unit)
    from l1b2.units import same_dimension
    assert same_dimension("N", "N")
    assert not same_dimension("N", "N/m")
    assert not same_dimension("Hz", "rad/s")
    assert not same_dimension("degC", "1/K")


def test_build_ssp_archive(tmp_path, motor):
    # reference: SSP archive layout (SystemStructure.ssd at the root, resources/ as the SSD names them)
    fake = {}
    for name in ("Driver", "Stator", "Interface", "Slider"):
        p = tmp_path / f"{name}.fmu"
        p.write_bytes(b"not really an fmu")
        fake[name] = p
    out = ssp.build_ssp(tmp_path / "out" / "L1B2Motor.ssp", fake)
    with zipfile.ZipFile(out) as z:
        names = set(z.namelist())
        assert "SystemStructure.ssd" in names
        assert "resources/reference_motor.ssv" in names
        assert {f"resources/{n}.fmu" for n in fake} <= names
        assert z.read("resources/reference_motor.ssv").decode() == ssp.SSV_FILE.read_text()
    with pytest.raises(SystemStructureError):
        ssp.build_ssp(tmp_path / "x.ssp", {k: v for k, v in fake.items() if k != "Slider"})
    # an SSV generated for another motor is what gets bundled when given
    other = ssp.motor_to_ssv(dataclasses.replace(motor, name="other"))
    out2 = ssp.build_ssp(tmp_path / "o.ssp", fake, ssv_text=other)
    with zipfile.ZipFile(out2) as z:
        assert z.read("resources/reference_motor.ssv").decode() == other
