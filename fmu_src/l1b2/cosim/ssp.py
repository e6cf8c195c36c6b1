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
  engines. :func:`build_ssp` packs that standard form by default
  (:func:`standard_ssd_text`, for every SSP tool but libcosim) and the SSD as
  written with ``standard=False`` (for libcosim).

An ``.ssp`` archive is untrusted input (its FMUs are native code):

* it is unpacked into a fresh temporary folder (:func:`unpack_ssp`,
  :func:`opened_ssp`) that is removed again whatever fails; the zip's member
  list is checked before anything is written (:class:`ArchiveLimits`: total
  unpacked size, member count, compression ratio of large members, no
  absolute or ``..`` member names, no encryption) and the bytes actually
  written are counted against the same limits;
* every ``source`` of the SSD (FMUs, parameter sets) must be a relative path
  that stays inside the archive (or the SSD's folder); an absolute path, a
  URI or a ``..`` escape is refused with :class:`l1b2.errors.SourceOutsideError`
  unless the caller passes ``allow_outside=True``;
* every problem is a :class:`l1b2.errors.SystemStructureError` (or subclass)
  whose message starts with the file - for an archive ``archive: member`` -
  and names the element, e.g. ``L1B2Motor.ssp: SystemStructure.ssd:
  <Component name="Driver"> source '../x.fmu' points outside the archive``.
"""

from __future__ import annotations

import math
import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
import zlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from urllib.parse import urlsplit

from ..errors import ArchiveError, SourceOutsideError, SystemStructureError
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
    #: how messages name the file (``archive.ssp: SystemStructure.ssd`` for an archive); default ``str(path)``
    label: str = ""

    @property
    def where(self) -> str:
        return self.label or str(self.path)

    def component_inputs(self, comp: str) -> list[Connection]:
        return [c for c in self.connections if c.end_element == comp]

    def unit_of(self, element: str | None, connector: str) -> str | None:
        if element is not None and element not in self.components:
            raise SystemStructureError(f"{self.where}: a connection names element '{element}', "
                                       "which is not a component of the system")
        conns = self.connectors if element is None else self.components[element].connectors
        if connector not in conns:
            where = "the system" if element is None else f"component {element}"
            raise SystemStructureError(f"{self.where}: {where} has no connector '{connector}'")
        return conns[connector].unit


def element_text(node) -> str:
    """How messages name an XML element: ``<Component name="Driver">`` (namespace dropped)."""
    tag = node.tag.rsplit("}", 1)[-1] if isinstance(node.tag, str) else "?"
    name = node.get("name")
    return f'<{tag} name="{name}">' if name is not None else f"<{tag}>"


def _required(node, attr: str, where: str) -> str:
    value = node.get(attr)
    if value is None or not value.strip():
        raise SystemStructureError(f"{where}: {element_text(node)} has no '{attr}' attribute")
    return value


def _number(node, attr: str, where: str, *, positive: bool = False) -> float | None:
    """Attribute ``attr`` of ``node`` as a finite float (``None`` when absent)."""
    raw = node.get(attr)
    if raw is None:
        return None
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or (positive and value <= 0) or value < 0:
        kind = "a positive" if positive else "a non-negative"
        raise SystemStructureError(f"{where}: {element_text(node)} {attr}='{raw}' is not {kind} finite number")
    return value


def _connectors(node, where) -> dict[str, Connector]:
    out = {}
    cs = node.find("ssd:Connectors", NS)
    if cs is None:
        return out
    for c in cs.findall("ssd:Connector", NS):
        name = _required(c, "name", f"{where}: {element_text(node)}")
        typ, unit = "Real", None
        for t in ("Real", "Integer", "Boolean", "String"):
            e = c.find(f"ssc:{t}", NS)
            if e is not None:
                typ, unit = t, e.get("unit")
        out[name] = Connector(name, c.get("kind"), unit, typ)
    return out


def _bindings(node, where) -> tuple[list[str], dict]:
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
            raise SystemStructureError(f"{where}: ParameterBinding of {node.get('name')} has neither a source "
                                       "nor an inline ssv:ParameterSet")
        inline.update(_parameter_values(ps, f"{where}: {element_text(node)} ParameterBinding"))
    return sources, inline


def _connection(c, where) -> Connection:
    for attr in ("startConnector", "endConnector"):
        _required(c, attr, where)
    return Connection(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))


def _components(system, where) -> dict[str, Component]:
    comps = {}
    elements = system.find("ssd:Elements", NS)
    for c in (elements.findall("ssd:Component", NS) if elements is not None else []):
        name = _required(c, "name", where)
        if name in comps:
            raise SystemStructureError(f"{where}: {element_text(c)} appears twice (component names must be unique)")
        source = _required(c, "source", where)
        sources, inline = _bindings(c, where)
        comps[name] = Component(name, source, _connectors(c, where), tuple(sources), inline)
    return comps


def _connections(system, where) -> list[Connection]:
    conns = []
    cn = system.find("ssd:Connections", NS)
    for c in (cn.findall("ssd:Connection", NS) if cn is not None else []):
        conns.append(_connection(c, where))
    ann = system.find("ssd:Annotations", NS)
    for a in (ann.findall("ssc:Annotation", NS) if ann is not None else []):
        if a.get("type") == SYSTEM_CONNECTIONS_ANNOTATION:
            for c in a.iter(f"{{{NS['l1b2']}}}Connection"):
                if c.get("startElement") and c.get("endElement"):
                    raise SystemStructureError(
                        f"{where}: {SYSTEM_CONNECTIONS_ANNOTATION} holds only connections to or from system "
                        f"connectors, not {c.get('startElement')}.{c.get('startConnector')} -> "
                        f"{c.get('endElement')}.{c.get('endConnector')}")
                conns.append(_connection(c, where))
    return conns


def _default_experiment(root, where) -> tuple[float | None, float | None]:
    de = root.find("ssd:DefaultExperiment", NS)
    if de is None:
        return None, None
    stop, step = _number(de, "stopTime", where), None
    for fs in de.iter("{http://opensimulationplatform.com/SSP/OSPAnnotations}FixedStepAlgorithm"):
        step = _number(fs, "baseStepSize", where, positive=True)
    return stop, step


def read_ssd(path: str | Path = SSD_FILE, label: str | None = None) -> SystemStructure:
    """Parse an SSD file (or the ``SystemStructure.ssd`` inside a directory).

    ``label`` names the file in messages (default: the path), e.g.
    ``L1B2Motor.ssp: SystemStructure.ssd`` for the SSD of an unpacked archive.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "SystemStructure.ssd"
    where = label or str(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise SystemStructureError(f"{where}: cannot read system structure ({exc})") from None
    system = root.find("ssd:System", NS)
    if system is None:
        raise SystemStructureError(f"{where}: no ssd:System element")
    comps = _components(system, where)
    conns = _connections(system, where)
    sources, inline = _bindings(system, where)
    if inline:
        raise SystemStructureError(f"{where}: inline parameter values at system level are not supported")
    stop, step = _default_experiment(root, where)
    sysst = SystemStructure(root.get("name"), path, _connectors(system, where), comps, conns, sources, stop, step,
                            label=where)
    for c in conns:  # every endpoint must exist and connected units must agree
        u1 = sysst.unit_of(c.start_element, c.start_connector)
        u2 = sysst.unit_of(c.end_element, c.end_connector)
        if u1 is not None and u2 is not None and not same_dimension(u1, u2):
            raise SystemStructureError(
                f"{where}: connection {c.start_element or '(system)'}.{c.start_connector} [{u1}] -> "
                f"{c.end_element or '(system)'}.{c.end_connector} [{u2}]: units disagree")
    return sysst


def check_against_model_descriptions(system: SystemStructure, model_descriptions: dict) -> None:
    """Refuse a system whose connectors disagree with the FMUs' variables (name, causality, unit).

    ``model_descriptions`` maps component name to an ``fmpy`` ModelDescription.
    """
    where = system.where
    for name, comp in system.components.items():
        md = model_descriptions[name]
        variables = {v.name: v for v in md.modelVariables}
        for conn in comp.connectors.values():
            v = variables.get(conn.name)
            if v is None:
                raise SystemStructureError(f"{where}: {name}.{conn.name} is not a variable of {comp.source}")
            if conn.kind in ("input", "output") and v.causality != conn.kind:
                raise SystemStructureError(
                    f"{where}: {name}.{conn.name} is '{conn.kind}' in the SSD but '{v.causality}' in the FMU")
            fmu_unit = v.unit if v.unit is not None else (v.declaredType.unit if v.declaredType else None)
            if conn.unit is not None and fmu_unit is not None and not same_dimension(conn.unit, fmu_unit):
                raise SystemStructureError(
                    f"{where}: {name}.{conn.name} has unit [{conn.unit}] in the SSD but [{fmu_unit}] in the FMU")


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


_BOOLEANS = {"true": 1.0, "1": 1.0, "false": 0.0, "0": 0.0}  # xs:boolean


def _parameter_value(kind: str, raw: str) -> float | None:
    """The value of an ``ssv:Real/Integer/Boolean`` as a float, ``None`` when it is not one."""
    try:
        if kind == "Real":
            value = float(raw)
            return value if math.isfinite(value) else None
        if kind == "Integer":
            return float(int(raw.strip(), 10))
    except ValueError:
        return None
    return _BOOLEANS.get(raw.strip())


def _parameter_values(parameter_set, where: str) -> dict[str, tuple[float, str | None]]:
    out = {}
    for p in parameter_set.iter(f"{{{NS['ssv']}}}Parameter"):
        name = _required(p, "name", where)
        for t in ("Real", "Integer", "Boolean"):
            e = p.find(f"ssv:{t}", NS)
            if e is None:
                continue
            raw = e.get("value")
            value = None if raw is None else _parameter_value(t, raw)
            if value is None:
                what = "no value" if raw is None else f"value '{raw}'"
                kind = {"Real": "a finite number", "Integer": "an integer", "Boolean": "true or false"}[t]
                raise SystemStructureError(f"{where}: {element_text(p)} ssv:{t} has {what}; expected {kind}")
            out[name] = (value, e.get("unit"))
    return out


def read_ssv(path: str | Path, label: str | None = None) -> dict[str, tuple[float, str | None]]:
    """Parameter values of an SSV file: ``{name: (value, unit)}``, names as written in the file.

    ``label`` names the file in messages (default: the path).
    """
    path = Path(path)
    where = label or str(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise SystemStructureError(f"{where}: cannot read parameter set ({exc})") from None
    return _parameter_values(root, where)


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


def check_source(source: str | None, where: str, *, allow_outside: bool = False,
                 outside_of: str = "the SSD's folder") -> str:
    """Refuse an SSD ``source`` that is not a relative path staying inside its folder (or archive).

    ``where`` names file and element for the message (``L1B2Motor.ssp: SystemStructure.ssd:
    <Component name="Driver">``). A URI (``file:``, ``http:``) is always refused; an absolute
    path or a ``..`` that climbs out is refused unless ``allow_outside``.
    """
    if source is None or not source.strip():
        raise SystemStructureError(f"{where} has an empty source")
    if "\x00" in source:
        raise SystemStructureError(f"{where} source {source!r} contains a NUL character")
    if len(urlsplit(source).scheme) > 1:
        raise SourceOutsideError(f"{where} source '{source}' is a URI; only relative paths are supported")
    if allow_outside:
        return source
    pure = PurePosixPath(source.replace("\\", "/"))
    if pure.is_absolute() or (pure.parts and pure.parts[0].endswith(":")):
        raise SourceOutsideError(f"{where} source '{source}' is an absolute path, outside {outside_of} "
                                 "(pass allow_outside=True to load it anyway)")
    depth = 0
    for part in pure.parts:
        depth += -1 if part == ".." else (0 if part == "." else 1)
        if depth < 0:
            raise SourceOutsideError(f"{where} source '{source}' points outside {outside_of} "
                                     "(pass allow_outside=True to load it anyway)")
    return source


def _inside(path: Path, root: Path) -> bool:
    try:
        path.resolve().relative_to(root.resolve())
        return True
    except ValueError:
        return False


def resolve_resource(root: Path, source: str, *, allow_outside: bool = False, where: str | None = None,
                     outside_of: str = "the SSD's folder") -> Path | None:
    """The file an SSD ``source`` names, relative to the SSD's folder ``root`` (``None``: not there).

    In an ``.ssp`` archive the path is taken as written; in the source tree
    the resources live beside the SSD, so a leading ``resources/`` is dropped
    (``resources/reference_motor/Driver.ssv`` -> ``system_models/reference_motor/Driver.ssv``).
    Unless ``allow_outside``, the source must stay inside ``root`` (:func:`check_source`;
    symbolic links are followed before the check) or :class:`l1b2.errors.SourceOutsideError` is raised.
    """
    where = where or "SSD"
    check_source(source, where, allow_outside=allow_outside, outside_of=outside_of)
    root = Path(root)
    rel = Path(source)
    cands = [root / rel]
    if rel.parts and rel.parts[0] == "resources":
        cands.append(root / Path(*rel.parts[1:]))
    cands.append(root / rel.name)
    for c in cands:
        if c.exists():
            if not allow_outside and not _inside(c, root):
                raise SourceOutsideError(f"{where} source '{source}' resolves to {c.resolve()}, outside "
                                         f"{outside_of} (pass allow_outside=True to load it anyway)")
            return c
    return None


# ---------------------------------------------------------------------------
# Untrusted archives (.ssp, .fmu): limits, checked unpacking
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class ArchiveLimits:
    """What an untrusted zip archive (``.ssp``, or an ``.fmu`` inside one) may unpack to.

    The defaults leave ample room for real archives (``L1B2Motor.ssp`` with its
    four FMUs unpacks to ~4 MB in ~200 members; our FMUs compress at most 7:1).
    """

    max_bytes: int = 256 * 2**20          #: total unpacked size [B]
    max_members: int = 10_000             #: number of members (files and folders)
    max_ratio: float = 100.0              #: unpacked / packed size of one member ...
    ratio_min_bytes: int = 2**20          #: ... checked for members larger than this [B]


DEFAULT_LIMITS = ArchiveLimits()
_COMPRESSIONS = {zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA}
#: what reading a broken zip can raise (zipfile, zlib, bz2, lzma, the file system)
_ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError, RuntimeError, ValueError)


def _member_parts(name: str, label: str) -> tuple[str, ...]:
    """The path parts of a member name; refuses names that would land outside the extraction folder."""
    pure = PurePosixPath(name.replace("\\", "/"))
    parts = tuple(p for p in pure.parts if p not in ("", "."))
    if pure.is_absolute() or ".." in parts or (parts and parts[0].endswith(":")) or "\x00" in name:
        raise ArchiveError(f"{label}: member {name!r} would be written outside the extraction folder")
    return parts


def check_archive(z: zipfile.ZipFile, label: str, limits: ArchiveLimits = DEFAULT_LIMITS) -> list[zipfile.ZipInfo]:
    """The members of an open zip after checking its directory against ``limits`` (nothing is unpacked).

    Refuses (:class:`l1b2.errors.ArchiveError`, naming ``label`` and the member) too many members, a total
    unpacked size above the limit, a large member compressed more than ``max_ratio`` : 1 (a compression
    bomb), encrypted members, unknown compression methods and member names that leave the folder.
    """
    infos = z.infolist()
    if len(infos) > limits.max_members:
        raise ArchiveError(f"{label}: {len(infos)} members, more than the limit of {limits.max_members}")
    total = 0
    for info in infos:
        _member_parts(info.filename, label)
        where = f"{label}: {info.filename}"
        if info.flag_bits & 0x1:
            raise ArchiveError(f"{where}: encrypted members are not supported")
        if info.compress_type not in _COMPRESSIONS:
            raise ArchiveError(f"{where}: unsupported compression method {info.compress_type}")
        if info.file_size > limits.ratio_min_bytes and info.file_size > limits.max_ratio * max(info.compress_size, 1):
            raise ArchiveError(f"{where}: unpacks {info.compress_size} bytes to {info.file_size} "
                               f"(more than {limits.max_ratio:g}:1, a compression bomb?)")
        total += info.file_size
        if total > limits.max_bytes:
            raise ArchiveError(f"{where}: the archive unpacks to more than the limit of {limits.max_bytes} bytes")
    return infos


def check_zip_file(path: str | Path, label: str, limits: ArchiveLimits = DEFAULT_LIMITS) -> None:
    """Check a zip file (e.g. an FMU) against ``limits`` without unpacking it (:func:`check_archive`)."""
    try:
        with zipfile.ZipFile(path) as z:
            check_archive(z, label, limits)
    except ArchiveError:
        raise
    except _ZIP_ERRORS as exc:
        raise ArchiveError(f"{label}: not a readable zip archive ({exc})") from None


def _copy_member(z: zipfile.ZipFile, info: zipfile.ZipInfo, target: Path, label: str, budget: int) -> int:
    """Unpack one member to ``target``; returns the bytes written (never more than declared or ``budget``)."""
    written = 0
    with z.open(info) as src, open(target, "xb") as dst:
        while chunk := src.read(1 << 16):
            written += len(chunk)
            if written > info.file_size or written > budget:
                raise ArchiveError(f"{label}: {info.filename}: unpacks to more bytes than its header declares "
                                   f"({info.file_size}) or the archive's limit allows")
            dst.write(chunk)
    return written


def extract_archive(archive: str | Path, dest: str | Path, label: str | None = None,
                    limits: ArchiveLimits = DEFAULT_LIMITS) -> Path:
    """Unpack a zip into the existing folder ``dest`` after :func:`check_archive`; returns ``dest``.

    The bytes actually written are counted against the limits too (a header
    may lie). Every failure is an :class:`l1b2.errors.ArchiveError` naming
    ``label`` (default: the archive's path) and the member; what was written
    stays in ``dest`` (the caller removes the folder, see :func:`unpack_ssp`).
    """
    label = label or str(archive)
    dest = Path(dest)
    try:
        with zipfile.ZipFile(archive) as z:
            infos = check_archive(z, label, limits)
            budget = limits.max_bytes
            for info in infos:
                target = dest.joinpath(*_member_parts(info.filename, label))
                if info.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                if target.exists():
                    raise ArchiveError(f"{label}: member {info.filename!r} appears twice")
                budget -= _copy_member(z, info, target, label, budget)
    except ArchiveError:
        raise
    except _ZIP_ERRORS as exc:
        raise ArchiveError(f"{label}: not a readable zip archive ({exc})") from None
    return dest


def unpack_ssp(archive: str | Path, limits: ArchiveLimits = DEFAULT_LIMITS) -> Path:
    """Unpack an ``.ssp`` into a new temporary folder (removed again if anything fails); returns the folder.

    The caller removes the folder when done (``shutil.rmtree``), or uses :func:`opened_ssp`.
    """
    archive = Path(archive)
    folder = Path(tempfile.mkdtemp(prefix="l1b2_ssp_"))
    try:
        if not archive.is_file():
            raise ArchiveError(f"{archive}: no such archive file")
        extract_archive(archive, folder, str(archive), limits)
        if not (folder / "SystemStructure.ssd").is_file():
            raise ArchiveError(f"{archive}: no SystemStructure.ssd at the root of the archive")
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return folder


@contextmanager
def opened_ssp(archive: str | Path, limits: ArchiveLimits = DEFAULT_LIMITS):
    """``with opened_ssp("x.ssp") as folder:`` the unpacked archive, removed on leaving the block."""
    folder = unpack_ssp(archive, limits)
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


_ANNOTATED = re.compile(r"\s*<ssd:Annotations>\s*<ssc:Annotation type=\"" + re.escape(SYSTEM_CONNECTIONS_ANNOTATION)
                        + r"\">\s*<l1b2:SystemConnections>(?P<body>.*?)</l1b2:SystemConnections>\s*</ssc:Annotation>"
                        r"\s*</ssd:Annotations>", re.S)


def standard_ssd_text(text: str) -> str:
    """The SSD with its system connections as standard SSP 1.0 ``ssd:Connection`` elements.

    The vendor annotation :data:`SYSTEM_CONNECTIONS_ANNOTATION` (the wiring of
    the system connectors, which libcosim needs out of ``ssd:Connections``) is
    moved into ``ssd:Connections``, where SSP puts a connection to or from a
    system connector (no ``startElement`` or ``endElement``), so that tools
    that only read the standard (``fmucontainer``, pyssp, ecos) drive the
    system inputs and read its outputs. Text is edited in place: prefixes,
    comments and layout stay as written.
    """
    m = _ANNOTATED.search(text)
    if m is None:
        return text
    rows = re.findall(r"<l1b2:Connection\b([^>]*)/>", m.group("body"))
    text = text[:m.start()] + text[m.end():]
    # the source's header comment explains the annotation; this file has none
    text = re.sub(r"<!--.*?-->", "<!-- The coupled L1B2 motor (l1b2-usm), made from its system_models/L1B2Motor.ssd: "
                  "the system connectors are wired by standard SSP 1.0 connections. -->", text, count=1, flags=re.S)
    close = text.index("</ssd:Connections>")
    indent = "  " * 3
    added = "".join(f"{indent}<ssd:Connection{attrs}/>\n" for attrs in rows)
    line_start = text.rindex("\n", 0, close) + 1
    return text[:line_start] + added + text[line_start:]


def build_ssp(out_path: str | Path, fmu_paths: dict[str, Path], ssd_path: str | Path = SSD_FILE,
              mp: MotorParams | None = None, *, standard: bool = True) -> Path:
    """Zip the SSD (as ``SystemStructure.ssd``), its parameter sets and the FMUs into an ``.ssp`` archive.

    ``standard`` (default): the system connections as standard SSP 1.0
    connections (:func:`standard_ssd_text`), for every SSP tool but libcosim;
    ``standard=False``: the SSD as written (system connections in the vendor
    annotation), the layout libcosim loads.

    ``mp`` given: the component parameter sets are generated from it
    (:func:`motor_to_ssv`); otherwise the files the SSD binds are copied from
    beside the SSD (``system_models/reference_motor/*.ssv`` for the reference motor).
    """
    out_path = Path(out_path)
    ssd_path = Path(ssd_path)
    system = read_ssd(ssd_path)
    for comp in system.components.values():
        check_source(comp.source, f'{ssd_path}: <Component name="{comp.name}">')
    missing = [c.source for c in system.components.values() if Path(c.source).stem not in fmu_paths]
    if missing:
        raise SystemStructureError(f"{ssd_path}: no FMU given for {missing}")
    ssd_text = ssd_path.read_text(encoding="utf-8")
    members: dict[str, bytes] = {"SystemStructure.ssd": (standard_ssd_text(ssd_text) if standard else ssd_text)
                                 .encode("utf-8")}
    bindings = [(comp.name, src) for comp in system.components.values() for src in comp.parameter_sources]
    bindings += [(None, src) for src in system.parameter_sources]
    for comp, src in bindings:
        check_source(src, f"{ssd_path}: <{'System' if comp is None else 'Component'} name=\"{comp or system.name}\">")
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
