"""Build the project's FMUs with pythonfmu and complete their ``modelDescription.xml``.

What the build adds to a plain ``pythonfmu build``:

* **Unique names per version (and FMU).** The physics package is bundled as
  ``l1b2_<version>_<fmu>`` (e.g. ``l1b2_0_1_0_stator``) and the slave module
  as ``l1b2_<version>_<fmu>_slave``; pythonfmu's own runtime is vendored
  inside it as ``l1b2_<version>_<fmu>._pythonfmu``. The PythonFMU loader imports the module named
  in ``resources/slavemodule.txt`` through ``sys.modules``, so two FMUs
  bundling modules of the same name (PythonFMU issue #228), two versions of
  ours or another PythonFMU FMU built with another pythonfmu, would otherwise
  share code in one process.
* **Metadata pythonfmu cannot express**: ``UnitDefinitions`` and a unit on
  every Real, min/max/nominal, descriptions, a default experiment, a complete
  ``ModelStructure`` (outputs and initial unknowns), author, version,
  license, and a GUID that is stable for identical content (libcosim caches
  extracted FMUs by GUID, so different content must never share one).
* **Defaults**: the reference motor's values (or any other parameter set)
  are baked in as start values, in ``resources/_fmu_defaults.json`` of each
  FMU, read by every instance from its own resources folder.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import re
import shutil
import sys
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from .. import __version__
from ..cosim.blocks import motor_defaults
from ..cosim.composite import BLOCKS
from ..physics.params import MotorParams, load_motor
from ..units import UNITS, tidy_float
from .slaves import slave_script

PACKAGE_DIR = Path(__file__).resolve().parents[1]
#: what an FMU's runtime imports: bundled into every FMU (identification, close-loop, rig, CLI are not)
RUNTIME_PARTS = ("__init__.py", "errors.py", "units.py", "physics", "cosim", "predictor", "fmi")
#: modules of the runtime parts that an FMU never imports (host-side tools)
HOST_ONLY = ("fmi/build.py", "fmi/cache.py", "fmi/export.py", "cosim/master.py", "predictor/derive.py",
             "fmi/native/__init__.py", "fmi/native/build.py", "fmi/native/translate.py")
SUBSYSTEM_FMUS = ("Driver", "Stator", "Interface", "Slider")
GUID_NAMESPACE = uuid.UUID("6f1f5d4e-2b1a-5c3e-9a57-0b1b2c0ffee0")
AUTHOR = "L1B2 USM tool team"
LICENSE = "MIT"
DEFAULT_EXPERIMENT = {"startTime": 0.0, "stopTime": 0.1, "stepSize": 2e-4}
_ORDER = ["ModelExchange", "CoSimulation", "UnitDefinitions", "TypeDefinitions", "LogCategories",
          "DefaultExperiment", "VendorAnnotations", "ModelVariables", "ModelStructure"]


def bundle_name(version: str = __version__, fmu: str | None = None) -> str:
    """Name of the bundled physics package: unique per project, version and FMU.

    Per FMU as well as per version, so every FMU is self-contained: a host
    that unloads or deletes one FMU's folder cannot break another of ours
    (Python caches imported packages by name for the whole process).
    """
    name = "l1b2_" + re.sub(r"[^0-9A-Za-z]", "_", version)
    return name if fmu is None else f"{name}_{fmu.lower()}"


def rewrite_imports(text: str, package: str) -> str:
    """Point ``import l1b2`` / ``from l1b2...`` at the bundled package name."""
    text = re.sub(r"^(\s*)from\s+l1b2(?=[\s.])", rf"\1from {package}", text, flags=re.M)
    return re.sub(r"^(\s*)import\s+l1b2(?=\s|$)", rf"\1import {package} as l1b2", text, flags=re.M)


def _vendor_pythonfmu(text: str, package: str) -> str:
    return re.sub(r"^(\s*)from\s+pythonfmu(?=[\s.])", rf"\1from {package}._pythonfmu", text, flags=re.M)


def stable_guid(model_name: str, version: str, content: str) -> str:
    """``uuid5`` of name, version and content hash, in FMI's braces form."""
    return "{" + str(uuid.uuid5(GUID_NAMESPACE, f"{model_name}|{version}|{content}")) + "}"


def _fmt(x) -> str:
    if isinstance(x, bool):
        return str(x).lower()
    return repr(tidy_float(x)) if isinstance(x, float) else str(x)


def variable_table(slave_name: str, defaults: dict) -> dict:
    """``{name: Var}`` of an FMU's variables, from its block's declaration."""
    cls = BLOCKS[slave_name]
    return {v.name: v for v in cls.variables(cls.params_from_defaults(defaults))}


def patch_model_description(xml_bytes: bytes, variables: dict, attributes: dict,
                            default_experiment: dict | None = None, limits: dict | None = None) -> bytes:
    """Add units, ranges, descriptions, model structure and metadata to a pythonfmu XML.

    ``limits`` (e.g. ``maxCommunicationStepSize``) go into
    ``VendorAnnotations/Tool[@name="l1b2"]/Limits``.
    """
    root = ET.fromstring(xml_bytes)
    for key, value in attributes.items():
        root.set(key, str(value))
    for old in root.findall("UnitDefinitions") + root.findall("DefaultExperiment") + root.findall("VendorAnnotations"):
        root.remove(old)
    if limits:
        tool = ET.SubElement(ET.SubElement(root, "VendorAnnotations"), "Tool", name="l1b2")
        ET.SubElement(tool, "Limits", {k: str(v) for k, v in limits.items()})
    mv = root.find("ModelVariables")
    svs = list(mv)
    index = {sv.get("name"): i + 1 for i, sv in enumerate(svs)}
    used_units = set()
    for sv in svs:
        name = sv.get("name")
        var = variables.get(name)
        if var is None:
            raise KeyError(f"FMU variable {name} has no declaration")
        sv.set("description", var.description)
        if var.type == "Real":
            real = sv.find("Real")
            unit = var.unit or "1"
            real.set("unit", unit)
            used_units.add(unit)
            for key in ("min", "max", "nominal"):
                value = getattr(var, key)
                if value is not None:
                    real.set(key, _fmt(float(value)))
        elif var.type == "Integer":
            el = sv.find("Integer")
            for key in ("min", "max"):
                value = getattr(var, key)
                if value is not None:
                    el.set(key, str(int(value)))
    ud = ET.SubElement(root, "UnitDefinitions")
    for u in sorted(used_units):
        ue = ET.SubElement(ud, "Unit", name=u)
        ET.SubElement(ue, "BaseUnit", UNITS[u].base_unit_attributes())
    if default_experiment:
        ET.SubElement(root, "DefaultExperiment", {k: _fmt(float(v)) for k, v in default_experiment.items()})
    ms = root.find("ModelStructure")
    for c in list(ms):
        ms.remove(c)
    outputs = [sv.get("name") for sv in svs if sv.get("causality") == "output"]
    if outputs:
        node = ET.SubElement(ms, "Outputs")
        for name in outputs:
            # co-simulation: outputs change only in fmi2DoStep, so no direct feedthrough from inputs
            ET.SubElement(node, "Unknown", {"index": str(index[name]), "dependencies": ""})
        init = ET.SubElement(ms, "InitialUnknowns")
        for name in outputs:  # computed at exitInitializationMode from parameters, inputs and states
            ET.SubElement(init, "Unknown", {"index": str(index[name])})
    children = list(root)
    for c in children:
        root.remove(c)
    children.sort(key=lambda e: _ORDER.index(e.tag) if e.tag in _ORDER else len(_ORDER))
    root.extend(children)
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def _rewrite_zip(fmu: Path, transform) -> None:
    """Rewrite an FMU zip atomically: ``transform(name, data) -> data or None`` (None drops it)."""
    fd, tmp = tempfile.mkstemp(suffix=".fmu", dir=fmu.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
            for info in zin.infolist():
                data = transform(info.filename, zin.read(info.filename))
                if data is not None:
                    zout.writestr(info.filename.replace("\\", "/"), data)
            for name, data in transform.extra.items():
                zout.writestr(name, data)
        shutil.move(tmp, fmu)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _content_hash(fmu: Path) -> str:
    h = hashlib.sha256()
    with zipfile.ZipFile(fmu) as z:
        for name in sorted(z.namelist()):
            if name != "modelDescription.xml":
                h.update(name.encode() + b"\0" + z.read(name))
    return h.hexdigest()[:32]


def _forget_modules(package: str, module: str) -> None:
    """Drop a bundle's modules from ``sys.modules`` (running instances keep their objects)."""
    for m in [m for m in sys.modules if m == package or m.startswith(package + ".") or m == module]:
        del sys.modules[m]
    importlib.invalidate_caches()


def defaults_document(mp: MotorParams, extra: dict | None = None) -> dict:
    """The start values baked into the FMUs (JSON-safe)."""
    doc = motor_defaults(mp)
    doc.update(extra or {})
    return doc


def copy_runtime(dest: Path) -> None:
    """Copy the package's runtime part (:data:`RUNTIME_PARTS` less :data:`HOST_ONLY`) into ``dest``."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "chost", "guard")
    dest.mkdir(parents=True)
    for part in RUNTIME_PARTS:
        src = PACKAGE_DIR / part
        if src.is_dir():
            shutil.copytree(src, dest / part, ignore=ignore)
        else:
            shutil.copy2(src, dest / part)
    for rel in HOST_ONLY:
        (dest / rel).unlink(missing_ok=True)
    shutil.rmtree(dest / "fmi" / "native", ignore_errors=True)  # the native FMUs' builder and C sources


def runtime_files() -> list[Path]:
    """The package files an FMU bundles (also what the FMU cache key hashes)."""
    files = []
    for part in RUNTIME_PARTS:
        src = PACKAGE_DIR / part
        files += sorted(src.rglob("*.py")) if src.is_dir() else [src]
    return [f for f in files if f.relative_to(PACKAGE_DIR).as_posix() not in HOST_ONLY]


def build_fmu(name: str, dest_dir: str | Path, *, mp: MotorParams | None = None, version: str = __version__,
              extra_defaults: dict | None = None, extra_files: dict[str, bytes] | None = None,
              vendor_pythonfmu: bool = True, guard_binary: bool = True) -> Path:
    """Build ``<dest_dir>/<name>.fmu`` from the slave template (:mod:`l1b2.fmi.slaves`)."""
    from pythonfmu.builder import FmuBuilder

    mp = mp or load_motor()
    dest_dir = Path(dest_dir)
    dest_dir.mkdir(parents=True, exist_ok=True)
    package = bundle_name(version, name)
    module = f"{package}_slave"
    if name not in BLOCKS:
        raise ValueError(f"unknown FMU '{name}'; known: {', '.join(BLOCKS)}")
    extra = dict(extra_defaults or {})
    if not all(k in extra for k in ("predictor",) if name == "Predictor"):
        for key, value in BLOCKS[name].baked_defaults(mp).items():
            extra.setdefault(key, value)
    defaults = defaults_document(mp, extra)
    with tempfile.TemporaryDirectory(prefix="l1b2_fmu_") as td:
        td = Path(td)
        pkg_dir = td / package
        copy_runtime(pkg_dir)
        for py in pkg_dir.rglob("*.py"):
            py.write_text(rewrite_imports(py.read_text(), package))
        defaults_file = td / "_fmu_defaults.json"  # lands in resources/, read by each instance
        defaults_file.write_text(json.dumps(defaults, indent=1))
        for rel, data in (extra_files or {}).items():   # a .py file's imports point at the bundle, as above
            (pkg_dir / rel).write_bytes(rewrite_imports(data.decode(), package).encode() if rel.endswith(".py")
                                        else data)
        script = td / f"{module}.py"
        script.write_text(rewrite_imports(slave_script(name, author=AUTHOR, license=LICENSE), package))
        dest = dest_dir / f"{name}.fmu"
        # An FMU of the same name run earlier in this process left its modules (built on the vendored
        # Fmi2Slave) in sys.modules; pythonfmu's builder would import those instead of the new script.
        _forget_modules(package, module)
        try:
            FmuBuilder.build_FMU(script, dest=dest, project_files=[pkg_dir, defaults_file],
                                 canGetAndSetFMUstate=True, canSerializeFMUstate=True)
        finally:
            while str(td) in sys.path:
                sys.path.remove(str(td))
            _forget_modules(package, module)

    import pythonfmu
    vendored = {f"resources/{package}/_pythonfmu/{f.name}": f.read_bytes()
                for f in sorted(Path(pythonfmu.__file__).parent.glob("*.py"))}

    def vendor(member: str, data: bytes):
        if member.startswith("resources/pythonfmu/"):
            return None  # the vendored copy replaces the shared top-level one
        if member.endswith(".py") and member.startswith(f"resources/{package}"):
            return _vendor_pythonfmu(data.decode(), package).encode()
        if member == f"resources/{module}.py":
            return _vendor_pythonfmu(data.decode(), package).encode()
        return data
    vendor.extra = vendored
    if vendor_pythonfmu:
        _rewrite_zip(dest, vendor)

    variables = variable_table(name, defaults)
    guid = stable_guid(name, version, _content_hash(dest))
    attrs = {"author": AUTHOR, "license": LICENSE, "version": version,
             "copyright": f"{AUTHOR}, {LICENSE} license", "guid": guid}
    annotations = {"maxCommunicationStepSize": _fmt(float(BLOCKS[name].MAX_STEP_S))}
    guard = compile_guard(guid, GUARD_INNER.format(name=name)) if guard_binary else None
    linux_binary = f"binaries/linux64/{name}.so"

    def patch(member: str, data: bytes):
        if member == "modelDescription.xml":
            return patch_model_description(data, variables, attrs, DEFAULT_EXPERIMENT, annotations)
        if member == linux_binary and guard is not None:
            return None  # moved under GUARD_INNER, the guard takes its name
        return data
    patch.extra = {}
    if guard is not None:
        with zipfile.ZipFile(dest) as z:
            patch.extra = {f"binaries/linux64/{GUARD_INNER.format(name=name)}": z.read(linux_binary),
                           linux_binary: guard}
    _rewrite_zip(dest, patch)
    return dest


#: PythonFMU's library in a guarded FMU (``binaries/linux64/``); the guard is ``<modelIdentifier>.so``
GUARD_INNER = "{name}_pythonfmu.so"
GUARD_SOURCE = Path(__file__).resolve().parent / "guard" / "fmi2_guard.c"


class GuardBuildError(RuntimeError):
    """The FMI guard library (``fmi/guard/fmi2_guard.c``) could not be compiled."""


def compile_guard(guid: str, inner: str) -> bytes:
    """The guard library (:file:`fmi/guard/fmi2_guard.c`) for one FMU, compiled with the system C compiler.

    It is what hosts load on Linux: it checks the GUID, the resources folder,
    statuses, time and FMU states before PythonFMU's library sees a call (see
    the source's header). Raises :class:`GuardBuildError` naming the compiler
    and its message when there is no C compiler or the build fails.
    """
    import subprocess

    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise GuardBuildError("building an FMU needs a C compiler (cc or gcc, or $CC) for its FMI guard library; "
                              "none was found on PATH")
    with tempfile.TemporaryDirectory(prefix="l1b2_guard_") as td:
        out = Path(td) / "guard.so"
        cmd = [cc, "-shared", "-fPIC", "-O2", "-Wl,-z,nodelete", f'-DGUARD_GUID="{guid}"', f'-DGUARD_INNER="{inner}"',
               "-o", str(out), str(GUARD_SOURCE), "-ldl", "-lm"]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise GuardBuildError(f"cannot run the C compiler {cc}: {exc}") from None
        if proc.returncode != 0 or not out.exists():
            first = (proc.stderr.strip().splitlines() or ["no message"])[0]
            raise GuardBuildError(f"the C compiler {cc} failed on {GUARD_SOURCE.name}: {first}")
        return out.read_bytes()


def build_subsystem_fmus(dest_dir: str | Path, mp: MotorParams | None = None,
                         names=SUBSYSTEM_FMUS) -> dict[str, Path]:
    """Build the four subsystem FMUs; returns ``{name: path}``."""
    return {name: build_fmu(name, dest_dir, mp=mp) for name in names}
