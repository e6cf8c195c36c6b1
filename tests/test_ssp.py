"""SSP system structure and parameter values: l1b2.cosim.ssp, system_models/L1B2Motor.ssd, reference_motor/*.ssv."""

from __future__ import annotations

import dataclasses
import os
import zipfile

import fmpy
import pytest
from l1b2.cosim import ssp
from l1b2.errors import SystemStructureError
from l1b2.physics.params import describe, load_motor
from l1b2.units import UNITS
from lxml import etree

SCHEMA_DIR = os.path.join(os.path.dirname(fmpy.__file__), "ssp", "schema")
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "l1b2": "urn:l1b2-usm:ssp:1",
}
COMPONENTS = ("Driver", "Stator", "Interface", "Slider")


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
    # reference: the SSP 1.0 XSD shipped with fmpy (committed files and freshly generated text, both forms)
    for comp in COMPONENTS:
        assert ssv_schema.validate(etree.parse(str(ssp.SSV_DIR / f"{comp}.ssv"))), ssv_schema.error_log
        fresh = etree.fromstring(ssp.motor_to_ssv(load_motor(), component=comp).encode())
        assert ssv_schema.validate(fresh), ssv_schema.error_log
    fresh = etree.fromstring(ssp.motor_to_ssv(load_motor()).encode())
    assert ssv_schema.validate(fresh), ssv_schema.error_log


def test_read_ssd_finds_components_and_all_connections():
    # reference: independent lxml parse of the same file
    sysst = ssp.read_ssd()
    doc = etree.parse(str(ssp.SSD_FILE))
    comps = [c.get("name") for c in doc.iterfind(".//ssd:Elements/ssd:Component", NS)]
    assert comps == ["Driver", "Stator", "Interface", "Slider"]
    assert list(sysst.components) == comps  # document order = Gauss-Seidel order
    # component-to-component connections in ssd:Connections, then the system connectors' wiring from the
    # org.l1b2-usm.SystemConnections annotation
    xml_conns = [(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                 for c in doc.iterfind(".//ssd:System/ssd:Connections/ssd:Connection", NS)]
    xml_conns += [(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                  for c in doc.iterfind(".//ssd:System/ssd:Annotations/ssc:Annotation"
                                        "[@type='org.l1b2-usm.SystemConnections']//l1b2:Connection", NS)]
    got = [(c.start_element, c.start_connector, c.end_element, c.end_connector) for c in sysst.connections]
    assert got == xml_conns
    assert len(got) >= 20
    # every system connector is wired: inputs to at least one component input, outputs from one component output
    for name, conn in sysst.connectors.items():
        if conn.kind == "input":
            assert any(c.start_element is None and c.start_connector == name for c in sysst.connections), name
        else:
            assert sum(1 for c in sysst.connections if c.end_element is None and c.end_connector == name) == 1
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
    assert sysst.parameter_sources == []
    for comp in COMPONENTS:  # one component-level binding each, bare names (the form libcosim reads)
        assert sysst.components[comp].parameter_sources == (f"resources/reference_motor/{comp}.ssv",)


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


def test_committed_ssvs_are_in_sync_with_the_toml():
    # reference: regenerate the SSVs from reference_motor.toml; the committed files must be identical
    # (regenerate with `python -c "from l1b2 import ssp, params; ssp.write_reference_ssvs(params.load_motor())"`)
    assert sorted(p.name for p in ssp.SSV_DIR.iterdir()) == sorted(f"{c}.ssv" for c in COMPONENTS)
    for comp, text in ssp.motor_to_ssvs(load_motor()).items():
        assert (ssp.SSV_DIR / f"{comp}.ssv").read_text() == text, comp
    assert not (ssp.SYSTEM_MODELS_DIR / "reference_motor.ssv").exists()  # replaced by the per-component files


def test_ssv_values_equal_motor_values():
    # reference: every parameter of every component, with its declared unit, bare names per component
    mp = load_motor()
    for comp, attr in ssp.COMPONENT_PARAMS.items():
        values = ssp.read_ssv(ssp.SSV_DIR / f"{comp}.ssv")
        params = getattr(mp, attr)
        n = 0
        for d in describe(type(params)):
            value, unit = values[d["name"]]
            assert value == getattr(params, d["name"])
            assert unit == d["unit"]
            n += 1
        assert n == len(values), comp
    # the system-level form carries the same values with hierarchical names
    path_values = {}
    for comp in COMPONENTS:
        path_values.update({f"{comp}.{k}": v for k, v in ssp.read_ssv(ssp.SSV_DIR / f"{comp}.ssv").items()})
    whole = etree.fromstring(ssp.motor_to_ssv(mp).encode())
    names = [p.get("name") for p in whole.iterfind(".//ssv:Parameter", NS)]
    assert names == list(path_values)


def test_ssv_round_trip(tmp_path, motor):
    # reference: MotorParams -> SSV text -> MotorParams must be the identity (repr floats), both forms
    changed = motor.replace(stator__zeta_b=0.0123456789, interface__mu_p=0.2345678901234567,
                            driver__L_H=1.23456789e-3, slider__mass_kg=0.1357913579)
    path = tmp_path / "changed.ssv"
    path.write_text(ssp.motor_to_ssv(changed, name="changed"))
    back = ssp.ssv_to_motor(path, base=motor)
    for sec in ("driver", "stator", "interface", "slider"):
        assert getattr(back, sec) == getattr(changed, sec), sec
    assert back.operating == motor.operating
    back = motor
    for comp, path in zip(COMPONENTS, ssp.write_reference_ssvs(changed, tmp_path / "per_component")):
        back = ssp.ssv_to_motor(path, base=back, component=comp)
    for sec in ("driver", "stator", "interface", "slider"):
        assert getattr(back, sec) == getattr(changed, sec), sec


def test_ssv_with_wrong_unit_is_refused(tmp_path):
    # reference: SSV units must equal the declared ones
    text = (ssp.SSV_DIR / "Driver.ssv").read_text().replace('unit="Hz"', 'unit="kHz"', 1)
    path = tmp_path / "bad.ssv"
    path.write_text(text)
    with pytest.raises(SystemStructureError, match="unit"):
        ssp.ssv_to_motor(path, base=load_motor(), component="Driver")


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
    for name in COMPONENTS:
        p = tmp_path / f"{name}.fmu"
        p.write_bytes(b"not really an fmu")
        fake[name] = p
    out = ssp.build_ssp(tmp_path / "out" / "L1B2Motor.ssp", fake)
    with zipfile.ZipFile(out) as z:
        names = set(z.namelist())
        assert "SystemStructure.ssd" in names
        assert z.read("SystemStructure.ssd").decode() == ssp.standard_ssd_text(ssp.SSD_FILE.read_text())
        assert {f"resources/{n}.fmu" for n in fake} <= names
        for comp in COMPONENTS:
            assert z.read(f"resources/reference_motor/{comp}.ssv").decode() == (ssp.SSV_DIR / f"{comp}.ssv").read_text()
    with pytest.raises(SystemStructureError):
        ssp.build_ssp(tmp_path / "x.ssp", {k: v for k, v in fake.items() if k != "Slider"})
    # the parameter sets generated for another motor are what gets bundled when given
    other = dataclasses.replace(motor.replace(slider__mass_kg=0.2), name="other")
    out2 = ssp.build_ssp(tmp_path / "o.ssp", fake, mp=other)
    with zipfile.ZipFile(out2) as z:
        for comp in COMPONENTS:
            assert z.read(f"resources/reference_motor/{comp}.ssv").decode() == ssp.motor_to_ssv(other, component=comp)


def test_system_level_bindings_take_precedence(tmp_path):
    # reference: SSP 1.0 (ParameterBinding) - bindings at the system level win over component-level ones;
    # system-level names are hierarchical. Read by our master (libcosim ignores system-level bindings).
    from l1b2.cosim.master import CoSimulation
    text = ssp.SSD_FILE.read_text().replace(
        "    <ssd:Elements>",
        '    <ssd:ParameterBindings><ssd:ParameterBinding source="resources/override.ssv"/></ssd:ParameterBindings>\n'
        "    <ssd:Elements>", 1)
    ssd = tmp_path / "L1B2Motor.ssd"
    ssd.write_text(text)
    (tmp_path / "reference_motor").mkdir()
    for comp in COMPONENTS:
        (tmp_path / "reference_motor" / f"{comp}.ssv").write_text((ssp.SSV_DIR / f"{comp}.ssv").read_text())
    (tmp_path / "override.ssv").write_text(ssp.motor_to_ssv(load_motor().replace(interface__mu_p=0.3)))
    sysst = ssp.read_ssd(ssd)
    assert sysst.parameter_sources == ["resources/override.ssv"]
    cs = CoSimulation.__new__(CoSimulation)  # parameter loading only: no FMUs needed
    cs.system, cs.root, cs.fmu_dir = sysst, ssd.parent, tmp_path
    values = cs._load_parameters()
    assert cs.parameter_sources_["Interface.mu_p"] == ("1", tmp_path / "override.ssv")
    assert values["Interface.mu_p"] == 0.3
    assert values["Slider.mass_kg"] == load_motor().slider.mass_kg


def test_annotation_may_not_hide_component_connections(tmp_path):
    # reference: the SystemConnections annotation wires only system connectors (the rest must be visible to
    # every engine in ssd:Connections)
    old = '<l1b2:Connection startConnector="V_s" endElement="Driver" endConnector="V_s"/>'
    path = _mutated_ssd(tmp_path, old, old.replace('startConnector="V_s"', 'startElement="Slider" startConnector="v"'))
    with pytest.raises(SystemStructureError, match="SystemConnections"):
        ssp.read_ssd(path)
