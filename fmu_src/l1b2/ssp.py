"""SSP 1.0 system structure: read the ``.ssd``, read/write the ``.ssv``, check units, pack ``.ssp``.

The wiring of the motor lives in ``system_models/L1B2Motor.ssd`` (written by
hand, validated against the SSP schema in the tests); the parameter values in
``system_models/reference_motor.ssv``, generated from
``reference_motor.toml`` by :func:`motor_to_ssv` (a test keeps them in sync).
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from .errors import SystemStructureError
from .params import SYSTEM_MODELS_DIR, MotorParams, describe
from .units import UNITS, same_dimension

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
}
SSD_FILE = SYSTEM_MODELS_DIR / "L1B2Motor.ssd"
SSV_FILE = SYSTEM_MODELS_DIR / "reference_motor.ssv"
#: which parameter dataclass of MotorParams each component carries
COMPONENT_PARAMS = {"Driver": "driver", "Stator": "stator", "Interface": "interface", "Slider": "slider"}


@dataclass(frozen=True)
class Connector:
    name: str
    kind: str
    unit: str | None
    type: str = "Real"


@dataclass(frozen=True)
class Component:
    name: str
    source: str
    connectors: dict[str, Connector]


@dataclass(frozen=True)
class Connection:
    start_element: str | None  # None = the system itself
    start_connector: str
    end_element: str | None
    end_connector: str


@dataclass(frozen=True)
class SystemStructure:
    name: str
    path: Path
    connectors: dict[str, Connector]
    components: dict[str, Component]  # in document order = Gauss-Seidel order
    connections: list[Connection]
    parameter_sources: list[str]
    default_stop_time: float | None = None

    def component_inputs(self, comp: str) -> list[Connection]:
        return [c for c in self.connections if c.end_element == comp]

    def unit_of(self, element: str | None, connector: str) -> str | None:
        conns = self.connectors if element is None else self.components[element].connectors
        if connector not in conns:
            where = "the system" if element is None else f"component {element}"
            raise SystemStructureError(f"{self.path}: {where} has no connector '{connector}'")
        return conns[connector].unit


def _connectors(node, path) -> dict[str, Connector]:
    out = {}
    cs = node.find("ssd:Connectors", NS)
    if cs is None:
        return out
    for c in cs.findall("ssd:Connector", NS):
        typ, unit = "Real", None
        for t in ("Real", "Integer", "Boolean", "String"):
            e = c.find(f"ssc:{t}", NS)
            if e is not None:
                typ, unit = t, e.get("unit")
        out[c.get("name")] = Connector(c.get("name"), c.get("kind"), unit, typ)
    return out


def read_ssd(path: str | Path = SSD_FILE) -> SystemStructure:
    """Parse an SSD file (or the ``SystemStructure.ssd`` inside a directory)."""
    path = Path(path)
    if path.is_dir():
        path = path / "SystemStructure.ssd"
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise SystemStructureError(f"{path}: cannot read system structure ({exc})") from None
    system = root.find("ssd:System", NS)
    if system is None:
        raise SystemStructureError(f"{path}: no ssd:System element")
    comps = {}
    elements = system.find("ssd:Elements", NS)
    for c in (elements.findall("ssd:Component", NS) if elements is not None else []):
        comps[c.get("name")] = Component(c.get("name"), c.get("source"), _connectors(c, path))
    conns = []
    cn = system.find("ssd:Connections", NS)
    for c in (cn.findall("ssd:Connection", NS) if cn is not None else []):
        conns.append(Connection(c.get("startElement"), c.get("startConnector"),
                                c.get("endElement"), c.get("endConnector")))
    sources = []
    pb = system.find("ssd:ParameterBindings", NS)
    for b in (pb.findall("ssd:ParameterBinding", NS) if pb is not None else []):
        sources.append(b.get("source"))
    de = root.find("ssd:DefaultExperiment", NS)
    stop = float(de.get("stopTime")) if de is not None and de.get("stopTime") else None
    sysst = SystemStructure(root.get("name"), path, _connectors(system, path), comps, conns, sources, stop)
    for c in conns:  # every endpoint must exist and connected units must agree
        u1 = sysst.unit_of(c.start_element, c.start_connector)
        u2 = sysst.unit_of(c.end_element, c.end_connector)
        if u1 is not None and u2 is not None and not same_dimension(u1, u2):
            raise SystemStructureError(
                f"{path}: connection {c.start_element or '(system)'}.{c.start_connector} [{u1}] -> "
                f"{c.end_element or '(system)'}.{c.end_connector} [{u2}]: units disagree")
    return sysst


def check_against_model_descriptions(system: SystemStructure, model_descriptions: dict) -> None:
    """Refuse a system whose connectors disagree with the FMUs' variables (name, causality, unit).

    ``model_descriptions`` maps component name to an ``fmpy`` ModelDescription.
    """
    for name, comp in system.components.items():
        md = model_descriptions[name]
        variables = {v.name: v for v in md.modelVariables}
        for conn in comp.connectors.values():
            v = variables.get(conn.name)
            if v is None:
                raise SystemStructureError(f"{system.path}: {name}.{conn.name} is not a variable of {comp.source}")
            if conn.kind in ("input", "output") and v.causality != conn.kind:
                raise SystemStructureError(
                    f"{system.path}: {name}.{conn.name} is '{conn.kind}' in the SSD but '{v.causality}' in the FMU")
            fmu_unit = v.unit if v.unit is not None else (v.declaredType.unit if v.declaredType else None)
            if conn.unit is not None and fmu_unit is not None and not same_dimension(conn.unit, fmu_unit):
                raise SystemStructureError(
                    f"{system.path}: {name}.{conn.name} has unit [{conn.unit}] in the SSD but [{fmu_unit}] in the FMU")


# ---------------------------------------------------------------------------
# SSV parameter sets
# ---------------------------------------------------------------------------

def motor_to_ssv(mp: MotorParams, name: str | None = None) -> str:
    """SSV XML text holding every subsystem parameter as ``Component.parameter``."""
    ET.register_namespace("ssv", NS["ssv"])
    ET.register_namespace("ssc", NS["ssc"])
    root = ET.Element(f"{{{NS['ssv']}}}ParameterSet", {"version": "1.0", "name": name or mp.name})
    params = ET.SubElement(root, f"{{{NS['ssv']}}}Parameters")
    used = set()
    for comp, attr in COMPONENT_PARAMS.items():
        values = getattr(mp, attr)
        for d in describe(type(values)):
            p = ET.SubElement(params, f"{{{NS['ssv']}}}Parameter", {"name": f"{comp}.{d['name']}"})
            ET.SubElement(p, f"{{{NS['ssv']}}}Real", {"value": repr(float(getattr(values, d["name"]))),
                                                      "unit": d["unit"]})
            used.add(d["unit"])
    units = ET.SubElement(root, f"{{{NS['ssv']}}}Units")
    for u in sorted(used):
        ue = ET.SubElement(units, f"{{{NS['ssc']}}}Unit", {"name": u})
        ET.SubElement(ue, f"{{{NS['ssc']}}}BaseUnit", UNITS[u].base_unit_attributes())
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def read_ssv(path: str | Path) -> dict[str, tuple[float, str | None]]:
    """Parameter values of an SSV file: ``{"Component.name": (value, unit)}``."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise SystemStructureError(f"{path}: cannot read parameter set ({exc})") from None
    out = {}
    for p in root.iter(f"{{{NS['ssv']}}}Parameter"):
        for t in ("Real", "Integer", "Boolean"):
            e = p.find(f"ssv:{t}", NS)
            if e is not None:
                raw = e.get("value")
                value = float(raw) if t != "Boolean" else float(raw.lower() == "true")
                out[p.get("name")] = (value, e.get("unit"))
    return out


def ssv_to_motor(path: str | Path, base: MotorParams) -> MotorParams:
    """A MotorParams whose subsystem values come from an SSV (others from ``base``)."""
    values = read_ssv(path)
    changes = {}
    for key, (value, unit) in values.items():
        comp, _, pname = key.partition(".")
        attr = COMPONENT_PARAMS.get(comp)
        if attr is None:
            continue
        declared = {d["name"]: d["unit"] for d in describe(type(getattr(base, attr)))}
        if pname not in declared:
            raise SystemStructureError(f"{path}: unknown parameter '{key}'")
        if unit is not None and unit != declared[pname]:
            raise SystemStructureError(f"{path}: parameter '{key}' has unit [{unit}], expected [{declared[pname]}]")
        changes[f"{attr}__{pname}"] = value
    return base.replace(**changes)


def build_ssp(out_path: str | Path, fmu_paths: dict[str, Path], ssd_path: str | Path = SSD_FILE,
              ssv_text: str | None = None) -> Path:
    """Zip the SSD (as ``SystemStructure.ssd``), the SSV and the FMUs into an ``.ssp`` archive."""
    out_path = Path(out_path)
    system = read_ssd(ssd_path)
    if ssv_text is None:
        ssv_text = Path(SSV_FILE).read_text()
    missing = [c.source for c in system.components.values() if Path(c.source).stem not in fmu_paths]
    if missing:
        raise SystemStructureError(f"{ssd_path}: no FMU given for {missing}")
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_suffix(".ssp.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", Path(ssd_path).read_text())
        for src in system.parameter_sources:
            z.writestr(src, ssv_text)
        for comp in system.components.values():
            z.write(fmu_paths[Path(comp.source).stem], comp.source)
    tmp.replace(out_path)
    return out_path
