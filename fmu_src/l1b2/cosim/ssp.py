"""SSP 1.0 system structure: read the ``.ssd``, read/write the ``.ssv``, check units, pack ``.ssp``.

The wiring of the motor lives in ``system_models/L1B2Motor.ssd`` (written by
hand, validated against the SSP schema in the tests); the parameter values in
``system_models/reference_motor/<Component>.ssv``, one parameter set per
component with the FMU's bare variable names, generated from
``reference_motor.toml`` by :func:`motor_to_ssv` (a test keeps them in sync).

Layout rules, so that the same ``SystemStructure.ssd`` runs in our master
(:mod:`l1b2.cosim.master`) and in libcosim (verified with libcosimpy 0.0.6):

* parameter values are bound per component (``ssd:Component/ssd:ParameterBindings``)
  with bare names; libcosim ignores system-level bindings and applies only
  the first binding of a component. System-level bindings with hierarchical
  names (``Component.variable``) are still read here and, as in SSP, take
  precedence over component-level ones.
* ``ssd:Connections`` holds only component-to-component connections: libcosim
  refuses (does not ignore) a connection without ``startElement`` or
  ``endElement``. The wiring of the system connectors is the vendor
  annotation :data:`SYSTEM_CONNECTIONS_ANNOTATION` of the system (elements
  with the attributes of ``ssd:Connection``); standard system-level
  connections in ``ssd:Connections`` are read too, for SSDs written for other
  engines.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import SystemStructureError
from ..physics.params import SYSTEM_MODELS_DIR, MotorParams, describe
from ..units import UNITS, same_dimension

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "l1b2": "urn:l1b2-usm:ssp:1",
}
SSD_FILE = SYSTEM_MODELS_DIR / "L1B2Motor.ssd"
#: folder of the reference parameter set, one ``<Component>.ssv`` per component
SSV_DIR = SYSTEM_MODELS_DIR / "reference_motor"
#: ``ssc:Annotation`` type of the system whose content wires the system connectors
SYSTEM_CONNECTIONS_ANNOTATION = "org.l1b2-usm.SystemConnections"
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
    #: ``source`` of each ``ssd:ParameterBinding`` of the component (bare variable names), in order
    parameter_sources: tuple[str, ...] = ()
    #: values of inline ``ssd:ParameterValues`` bindings ``{variable: (value, unit)}``
    inline_parameters: dict = field(default_factory=dict)


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
    parameter_sources: list[str]     # system-level bindings (hierarchical names)
    default_stop_time: float | None = None
    default_step_size: float | None = None  # OSP fixed-step annotation, if any

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


def _bindings(node, path) -> tuple[list[str], dict]:
    """Sources and inline values of the ``ssd:ParameterBindings`` of an element."""
    sources, inline = [], {}
    pb = node.find("ssd:ParameterBindings", NS)
    for b in (pb.findall("ssd:ParameterBinding", NS) if pb is not None else []):
        if b.get("source"):
            sources.append(b.get("source"))
            continue
        values = b.find("ssd:ParameterValues", NS)
        ps = values.find("ssv:ParameterSet", NS) if values is not None else None
        if ps is None:
            raise SystemStructureError(f"{path}: ParameterBinding of {node.get('name')} has neither a source "
                                       "nor an inline ssv:ParameterSet")
        inline.update(_parameter_values(ps))
    return sources, inline


def _connection(c) -> Connection:
    return Connection(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))


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
        sources, inline = _bindings(c, path)
        comps[c.get("name")] = Component(c.get("name"), c.get("source"), _connectors(c, path),
                                         tuple(sources), inline)
    conns = []
    cn = system.find("ssd:Connections", NS)
    for c in (cn.findall("ssd:Connection", NS) if cn is not None else []):
        conns.append(_connection(c))
    ann = system.find("ssd:Annotations", NS)
    for a in (ann.findall("ssc:Annotation", NS) if ann is not None else []):
        if a.get("type") == SYSTEM_CONNECTIONS_ANNOTATION:
            for c in a.iter(f"{{{NS['l1b2']}}}Connection"):
                if c.get("startElement") and c.get("endElement"):
                    raise SystemStructureError(
                        f"{path}: {SYSTEM_CONNECTIONS_ANNOTATION} holds only connections to or from system "
                        f"connectors, not {c.get('startElement')}.{c.get('startConnector')} -> "
                        f"{c.get('endElement')}.{c.get('endConnector')}")
                conns.append(_connection(c))
    sources, inline = _bindings(system, path)
    if inline:
        raise SystemStructureError(f"{path}: inline parameter values at system level are not supported")
    de = root.find("ssd:DefaultExperiment", NS)
    stop = float(de.get("stopTime")) if de is not None and de.get("stopTime") else None
    step = None
    if de is not None:
        for fs in de.iter("{http://opensimulationplatform.com/SSP/OSPAnnotations}FixedStepAlgorithm"):
            step = float(fs.get("baseStepSize"))
    sysst = SystemStructure(root.get("name"), path, _connectors(system, path), comps, conns, sources, stop, step)
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

def motor_to_ssv(mp: MotorParams, name: str | None = None, component: str | None = None) -> str:
    """SSV XML text of a motor's subsystem parameters.

    ``component`` given (e.g. ``"Driver"``): that component's parameters with
    the FMU's bare variable names, for a component-level ParameterBinding (the
    form libcosim reads). ``component=None``: every subsystem parameter as
    ``Component.parameter``, for a system-level binding.
    """
    ET.register_namespace("ssv", NS["ssv"])
    ET.register_namespace("ssc", NS["ssc"])
    if component is not None and component not in COMPONENT_PARAMS:
        raise SystemStructureError(f"no component '{component}' (expected one of {list(COMPONENT_PARAMS)})")
    root = ET.Element(f"{{{NS['ssv']}}}ParameterSet", {"version": "1.0", "name": name or mp.name})
    params = ET.SubElement(root, f"{{{NS['ssv']}}}Parameters")
    used = set()
    for comp, attr in COMPONENT_PARAMS.items():
        if component is not None and comp != component:
            continue
        values = getattr(mp, attr)
        for d in describe(type(values)):
            pname = d["name"] if component is not None else f"{comp}.{d['name']}"
            p = ET.SubElement(params, f"{{{NS['ssv']}}}Parameter", {"name": pname})
            ET.SubElement(p, f"{{{NS['ssv']}}}Real", {"value": repr(float(getattr(values, d["name"]))),
                                                      "unit": d["unit"]})
            used.add(d["unit"])
    units = ET.SubElement(root, f"{{{NS['ssv']}}}Units")
    for u in sorted(used):
        ue = ET.SubElement(units, f"{{{NS['ssc']}}}Unit", {"name": u})
        ET.SubElement(ue, f"{{{NS['ssc']}}}BaseUnit", UNITS[u].base_unit_attributes())
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def motor_to_ssvs(mp: MotorParams, name: str | None = None) -> dict[str, str]:
    """``{component: SSV text}`` of the per-component parameter sets (bare names)."""
    return {comp: motor_to_ssv(mp, name, component=comp) for comp in COMPONENT_PARAMS}


def write_reference_ssvs(mp: MotorParams, folder: str | Path = SSV_DIR, name: str | None = None) -> list[Path]:
    """Write ``<folder>/<Component>.ssv`` for every component (regenerates ``system_models/reference_motor``)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for comp, text in motor_to_ssvs(mp, name).items():
        path = folder / f"{comp}.ssv"
        path.write_text(text)
        out.append(path)
    return out


def _parameter_values(parameter_set) -> dict[str, tuple[float, str | None]]:
    out = {}
    for p in parameter_set.iter(f"{{{NS['ssv']}}}Parameter"):
        for t in ("Real", "Integer", "Boolean"):
            e = p.find(f"ssv:{t}", NS)
            if e is not None:
                raw = e.get("value")
                value = float(raw) if t != "Boolean" else float(raw.lower() == "true")
                out[p.get("name")] = (value, e.get("unit"))
    return out


def read_ssv(path: str | Path) -> dict[str, tuple[float, str | None]]:
    """Parameter values of an SSV file: ``{name: (value, unit)}``, names as written in the file."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise SystemStructureError(f"{path}: cannot read parameter set ({exc})") from None
    return _parameter_values(root)


def ssv_to_motor(path: str | Path, base: MotorParams, component: str | None = None) -> MotorParams:
    """A MotorParams whose subsystem values come from an SSV (others from ``base``).

    ``component=None``: names are ``Component.parameter``; else bare names of that component.
    """
    values = read_ssv(path)
    changes = {}
    for key, (value, unit) in values.items():
        if component is None:
            comp, _, pname = key.partition(".")
        else:
            comp, pname = component, key
        attr = COMPONENT_PARAMS.get(comp)
        if attr is None:
            if component is not None:
                raise SystemStructureError(f"{path}: no component '{component}'")
            continue
        declared = {d["name"]: d["unit"] for d in describe(type(getattr(base, attr)))}
        if pname not in declared:
            raise SystemStructureError(f"{path}: unknown parameter '{key}'")
        if unit is not None and unit != declared[pname]:
            raise SystemStructureError(f"{path}: parameter '{key}' has unit [{unit}], expected [{declared[pname]}]")
        changes[f"{attr}__{pname}"] = value
    return base.replace(**changes)


def resolve_resource(root: Path, source: str) -> Path | None:
    """The file an SSD ``source`` names, relative to the SSD's folder ``root``.

    In an ``.ssp`` archive the path is taken as written; in the source tree
    the resources live beside the SSD, so a leading ``resources/`` is dropped
    (``resources/reference_motor/Driver.ssv`` -> ``system_models/reference_motor/Driver.ssv``).
    """
    rel = Path(source)
    cands = [root / rel]
    if rel.parts and rel.parts[0] == "resources":
        cands.append(root / Path(*rel.parts[1:]))
    cands.append(root / rel.name)
    for c in cands:
        if c.exists():
            return c
    return None


def build_ssp(out_path: str | Path, fmu_paths: dict[str, Path], ssd_path: str | Path = SSD_FILE,
              mp: MotorParams | None = None) -> Path:
    """Zip the SSD (as ``SystemStructure.ssd``), its parameter sets and the FMUs into an ``.ssp`` archive.

    ``mp`` given: the component parameter sets are generated from it
    (:func:`motor_to_ssv`); otherwise the files the SSD binds are copied from
    beside the SSD (``system_models/reference_motor/*.ssv`` for the reference motor).
    """
    out_path = Path(out_path)
    ssd_path = Path(ssd_path)
    system = read_ssd(ssd_path)
    missing = [c.source for c in system.components.values() if Path(c.source).stem not in fmu_paths]
    if missing:
        raise SystemStructureError(f"{ssd_path}: no FMU given for {missing}")
    members: dict[str, bytes] = {"SystemStructure.ssd": ssd_path.read_bytes()}
    bindings = [(comp.name, src) for comp in system.components.values() for src in comp.parameter_sources]
    bindings += [(None, src) for src in system.parameter_sources]
    for comp, src in bindings:
        if mp is not None and (comp is None or comp in COMPONENT_PARAMS):
            members[src] = motor_to_ssv(mp, component=comp).encode()
        else:
            found = resolve_resource(system.path.parent, src)
            if found is None:
                raise SystemStructureError(f"{ssd_path}: cannot find parameter set {src}")
            members[src] = found.read_bytes()
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_suffix(".ssp.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
        for comp in system.components.values():
            z.write(fmu_paths[Path(comp.source).stem], comp.source)
    tmp.replace(out_path)
    return out_path
