"""Build the native (C) co-simulation FMUs, FMI 2.0 and FMI 3.0, from the Python FMU of the same name.

:func:`build_native_fmu` takes the ``modelDescription.xml`` of the Python FMU
(:func:`l1b2.fmi.build.build_fmu`) as the declaration of the variables, so the
native FMU has the same names, value references, units, ranges, start values
and descriptions; it writes

* ``sources/``: the C sources (``fmu_core.c``, the FMI 2 or FMI 3 glue, the
  model, the generated ``model_data.h``) and the FMI headers; FMI 3.0 with
  ``sources/buildDescription.xml``, FMI 2.0 listing them in the
  ``<SourceFiles>`` of ``modelDescription.xml`` (a source FMU);
* ``binaries/linux64/<id>.so`` (FMI 2) or ``binaries/x86_64-linux/<id>.so``
  (FMI 3), compiled here with the system's C compiler (``$CC``, else ``cc`` or
  ``gcc``): no Python at run time.

The model identifier is ``<name>_native``; the FMU file is named apart from the
Python one (``Predictor-native.fmu``, ``Predictor-native-fmi3.fmu``).
FMI 3.0 adds the independent variable ``time`` (FMI 3.0 requires one) with the
first value reference after the Python FMU's.
"""

from __future__ import annotations

import ast
import hashlib
import inspect
import json
import math
import os
import shutil
import subprocess
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from ... import __version__
from ...errors import L1B2Error
from ..build import AUTHOR, LICENSE, stable_guid

C_DIR = Path(__file__).resolve().parent / "c"
#: the models with a native implementation: FMU name -> folder of its C model under c/
MODELS = {"Predictor": "predictor", "L1B2Motor": "motor"}
#: the motor's modal table is baked for axial forces up to at least this [N] (ModalTable's tested range)
TABLE_P_MAX_N = 60.0
#: the stator parameters the modal table's values depend on (B2 frequency and tip coefficient against P)
TABLE_PARAMETERS = ("f_b0_Hz", "density_kg_m3", "width_m", "thickness_m", "length_m")
FMI_PLATFORM = {2: "linux64", 3: "x86_64-linux"}
#: compiler flags: IEEE arithmetic as written (no contraction into fused multiply-adds, no fast math)
CFLAGS = ("-O2", "-std=c99", "-fPIC", "-shared", "-fvisibility=hidden", "-ffp-contract=off", "-fno-fast-math")
GENERATION_TOOL = "l1b2 native FMU builder"
_CAUSALITY = {"parameter": "VC_PARAMETER", "input": "VC_INPUT", "output": "VC_OUTPUT", "local": "VC_LOCAL",
              "calculatedParameter": "VC_PARAMETER"}


class NativeBuildError(L1B2Error):
    """The native FMU cannot be built (no C compiler, a compiler error, an unsupported model)."""


class NoCompilerError(NativeBuildError):
    """No C compiler was found to build the native FMUs."""


def native_fmu_name(name: str, fmi_version: int) -> str:
    """File stem of the native FMU: ``<name>-native`` (FMI 2.0) or ``<name>-native-fmi3``."""
    return f"{name}-native" if fmi_version == 2 else f"{name}-native-fmi3"


def model_identifier(name: str) -> str:
    """Model identifier (and library name) of the native FMU of ``name``."""
    return f"{name}_native"


def fmi_headers() -> Path:
    """Folder of the FMI 2.0 and 3.0 headers fmpy ships (copied into every source FMU)."""
    import fmpy
    return Path(fmpy.__file__).resolve().parent / "c-code"


def find_cc(cc: str | None = None) -> str:
    """The C compiler: ``cc``, else ``$CC``, else ``cc`` or ``gcc`` on PATH (:class:`NativeBuildError` if none)."""
    found = cc or os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not found:
        raise NoCompilerError("no C compiler found (set CC, or install cc/gcc) to build the native FMUs")
    return found


# ---------------------------------------------------------------------------
# variables
# ---------------------------------------------------------------------------

def read_variables(model_description: bytes) -> list[dict]:
    """The variables of an FMI 2.0 ``modelDescription.xml``: dicts with name, vr, type, causality,
    variability, start (float; 0 when none), has_start, min, max, unit, description, nominal."""
    root = ET.fromstring(model_description)
    out = []
    for sv in root.find("ModelVariables"):
        el = sv[0]
        kind = el.tag
        if kind not in ("Real", "Boolean"):
            raise NativeBuildError(f"variable {sv.get('name')}: type {kind} is not supported by the native FMUs")
        start = el.get("start")
        if kind == "Boolean":
            value = 1.0 if start == "true" else 0.0
        else:
            value = float(start) if start is not None else 0.0
        out.append({
            "name": sv.get("name"), "vr": int(sv.get("valueReference")), "type": kind,
            "causality": sv.get("causality", "local"), "variability": sv.get("variability", "continuous"),
            "start": value, "has_start": start is not None, "start_text": start,
            "min": el.get("min"), "max": el.get("max"), "unit": el.get("unit"), "nominal": el.get("nominal"),
            "description": sv.get("description", ""),
        })
    vrs = [v["vr"] for v in out]
    if vrs != list(range(len(vrs))):
        raise NativeBuildError("the value references are not 0..n-1 in order")
    return out


def c_name(name: str) -> str:
    """A variable name as part of a C identifier (``Stator.f_b0_Hz`` -> ``Stator_f_b0_Hz``)."""
    return "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in name)


def _c_double(x: float) -> str:
    if x != x:
        return "NAN"
    if x in (float("inf"), float("-inf")):
        return "INFINITY" if x > 0 else "-INFINITY"
    return x.hex()  # exact


def _c_string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def model_data_header(name: str, variables: list[dict], guid: str, block: str, fmi_version: int,
                      defaults: dict | None = None) -> str:
    """``model_data.h``: the variable table, the inputs' ranges, the identity, and model-specific tables."""
    from ...cosim.composite import BLOCKS
    max_step = float(getattr(BLOCKS[name], "MAX_STEP_S", math.inf))
    max_sub = int(getattr(BLOCKS[name], "MAX_SUBSTEPS", 0))
    n = len(variables)
    lines = [f"/* model_data.h - generated by l1b2.fmi.native.build for {name} (FMI {fmi_version}.0); do not edit */",
             "#ifndef L1B2_MODEL_DATA_H", "#define L1B2_MODEL_DATA_H", "#include <math.h>", "",
             f"#define MODEL_IDENTIFIER {_c_string(model_identifier(name))}",
             f"#define BLOCK_NAME {_c_string(block)}", f"#define INSTANTIATION_TOKEN {_c_string(guid)}",
             f"#define NV {n}", f"#define STATE_TAG 0x{hashlib.sha256(guid.encode()).hexdigest()[:16]}ULL",
             "enum { VT_REAL = 0, VT_BOOLEAN = 1 };",
             "enum { VC_PARAMETER = 0, VC_INPUT = 1, VC_OUTPUT = 2, VC_LOCAL = 3 };", ""]
    if fmi_version == 3:
        lines.append(f"#define VR_TIME {n} /* the independent variable of FMI 3.0 */")
    for v in variables:
        lines.append(f"#define VR_{c_name(v['name'])} {v['vr']}")
    lines += ["", "static const int VAR_TYPE[NV] = {" + ", ".join(
        "VT_BOOLEAN" if v["type"] == "Boolean" else "VT_REAL" for v in variables) + "};",
        "static const int VAR_CAUS[NV] = {" + ", ".join(_CAUSALITY[v["causality"]] for v in variables) + "};",
        "static const double VAR_START[NV] = {" + ", ".join(_c_double(v["start"]) for v in variables) + "};",
        "static const char* const VAR_NAME[NV] = {" + ", ".join(_c_string(v["name"]) for v in variables) + "};",
        "static const char* const VAR_UNIT[NV] = {" + ", ".join(_c_string(v["unit"] or "") for v in variables) + "};"]
    inputs = [v for v in variables if v["causality"] == "input"]
    big = "DBL_MAX"
    lines += ["#include <float.h>",
              "static const double VAR_MIN[NV] = {" + ", ".join(
                  "-" + big if v["min"] is None else _c_double(float(v["min"])) for v in variables) + "};",
              "static const double VAR_MAX[NV] = {" + ", ".join(
                  big if v["max"] is None else _c_double(float(v["max"])) for v in variables) + "};",
              "static const int VAR_FIXED[NV] = {" + ", ".join(
                  "1" if v["variability"] in ("fixed", "constant") else "0" for v in variables) + "};",
              f"#define MAX_STEP_S {_c_double(max_step)} /* the block's MAX_STEP_S (none: INFINITY) */",
              f"#define MAX_SUBSTEPS {max_sub} /* the block's MAX_SUBSTEPS (none: 0) */",
              f"#define N_INPUTS {len(inputs)}",
              "static const int INPUT_VR[] = {" + ", ".join(str(v["vr"]) for v in inputs) + "};",
              "static const double INPUT_MIN[] = {" + ", ".join(
                  "-" + big if v["min"] is None else _c_double(float(v["min"])) for v in inputs) + "};",
              "static const double INPUT_MAX[] = {" + ", ".join(
                  big if v["max"] is None else _c_double(float(v["max"])) for v in inputs) + "};"]
    lines += _model_tables(name, variables, defaults)
    lines += ["", "#endif", ""]
    return "\n".join(lines)


def _model_tables(name: str, variables: list[dict], defaults: dict | None = None) -> list[str]:
    if name == "L1B2Motor":
        return _motor_tables(variables, defaults)
    if name != "Predictor":
        return []
    names = {v["name"]: v["vr"] for v in variables}
    np_ = sum(1 for k in names if k.startswith("alpha_"))
    out = ["", f"#define PRED_NP {np_}"]
    ext = (defaults or {}).get("extended_predictor")
    for prefix in ("", "baseline_") if ext else ("",):
        tag = "BASE_" if prefix else ""
        if prefix and sum(1 for k in names if k.startswith(prefix + "alpha_")) != np_:
            raise NativeBuildError("the baseline and the re-identified predictor have different polynomial orders")
        for group in ("alpha", "beta", "p"):
            out.append(f"static const int PRED_VR_{tag}{group.upper()}[PRED_NP] = {{" + ", ".join(
                str(names[f"{prefix}{group}_{j}"]) for j in range(np_)) + "};")
        out.append(f"static const int PRED_VR_{tag}SCALARS[{len(PREDICTOR_SCALARS)}] = {{" + ", ".join(
            str(names[prefix + n]) for n in PREDICTOR_SCALARS) + "};")
    if ext:
        out += _extended_tables(ext, names)
    return out


#: the scalar parameters of one Eq. 29 setup in the order predictor_model.c reads them
PREDICTOR_SCALARS = ("c_r", "sigma", "mu", "k0", "mu_sd", "s_center", "s_half", "kappa", "load_inertia",
                     "slider_mass_kg", "T_s")


def _keyed(tree, key: str) -> list:
    """Every non-null value stored under ``key`` anywhere in an FMU's defaults (the predictor's setup and an
    extended model's setups alike)."""
    if isinstance(tree, dict):
        return [v for k, v in tree.items() if k == key and v is not None] + [
            found for v in tree.values() for found in _keyed(v, key)]
    if isinstance(tree, list):
        return [found for v in tree for found in _keyed(v, key)]
    return []


def _drive_laws(tree) -> list[str]:
    """Every ``drive_law`` named anywhere in an FMU's defaults."""
    return [str(v) for v in _keyed(tree, "drive_law")]


def _extended_tables(ext: dict, vr: dict) -> list[str]:
    """The calibrated extended predictor's effects (kind codes, spec scalars, parameter value references) and
    output filter with its rails for ``predictor_model.c`` (the kernels: :mod:`l1b2.predictor.effects.kernels`)."""
    from ...predictor.effects import EffectSpecError
    from ...predictor.effects.kernels import spec_scalars
    kinds, qs, phis = [], [], []
    for e in ext.get("effects", []):
        try:
            kind, q = spec_scalars(e["spec"])
        except EffectSpecError as exc:
            raise NativeBuildError(f"effect {e.get('label', e.get('family'))}: {exc}; its Predictor.fmu stays a "
                                   "Python FMU") from None
        kinds.append(kind)
        qs.append(q)
        phis.append([vr[n] for n in e["names"]])

    def offsets(groups):
        o = [0]
        for g in groups:
            o.append(o[-1] + len(g))
        return o

    def arr(ctype, name, values, fmt=str):
        return f"static const {ctype} {name}[{max(1, len(values))}] = {{" + ", ".join(
            fmt(v) for v in values or [0.0 if fmt is _c_double else 0]) + "};"

    return ["#define PRED_EXTENDED 1", f"#define PRED_HAS_T {int('T' in vr)}",
            f"#define PRED_HAS_FILTER {int(ext.get('output_filter') is not None)}",
            f"#define PRED_HAS_RAIL_LO {int('lo_m_s' in (ext.get('output_filter') or {}))}",
            f"#define PRED_HAS_RAIL_HI {int('hi_m_s' in (ext.get('output_filter') or {}))}",
            f"#define EFF_N {len(kinds)}", f"#define EFF_NPHI {max(1, sum(map(len, phis)))}",
            arr("int", "EFF_KIND", kinds), arr("int", "EFF_Q_OFF", offsets(qs)),
            arr("double", "EFF_Q", [v for q in qs for v in q], _c_double), arr("int", "EFF_PHI_OFF", offsets(phis)),
            arr("int", "EFF_PHI_VR", [v for p in phis for v in p])]


def _unpacked_names(module, length_name: str) -> list[str]:
    """The names of ``(A, B, ...) = range(len(<length_name>))`` in ``module``'s source, in order."""
    for node in ast.walk(ast.parse(inspect.getsource(module))):
        if (isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Tuple)
                and ast.unparse(node.value) == f"range(len({length_name}))"):
            return [e.id for e in node.targets[0].elts]
    raise NativeBuildError(f"no index names for {length_name} in {module.__name__}")


def _motor_tables(variables: list[dict], defaults: dict) -> list[str]:
    """The motor's index names, parameter and variable maps, and the modal table baked for its stator."""
    from ...cosim.composite import MotorBlock
    from ...cosim.engine import fused_readers
    from ...physics import coupled as cp
    from ...physics import stator as st
    vr = {v["name"]: v["vr"] for v in variables}
    xs, ps = _unpacked_names(cp, "STATE"), _unpacked_names(cp, "PARAMS")
    out = ["", f"#define MOTOR_NX {len(cp.STATE)}", f"#define MOTOR_NP {len(cp.PARAMS)}"]
    out += [f"#define X_{n} {i}" for i, n in enumerate(xs)] + [f"#define P_{n} {i}" for i, n in enumerate(ps)]
    section = {name: "Stator" for name in cp.PARAMS[:cp.M_L]}
    section.update({name: "Interface" for name in cp.PARAMS[cp.K_E:cp.PURE_SLIP]})
    section.update({name: "Slider" for name in cp.PARAMS[cp.MASS:]})
    out.append("static const int MOTOR_PARAM_VR[MOTOR_NP] = {" + ", ".join(
        str(vr[f"{section[n]}.{n}"]) if n in section else "-1" for n in cp.PARAMS) + "};")
    readers = fused_readers()
    pairs = [(vr[out_name], readers[f"{comp}.{var}"]) for out_name, (comp, var) in MotorBlock.OUTPUT_SOURCES.items()]
    pairs += [(v["vr"], readers[v["name"]]) for v in variables
              if v["causality"] == "local" and type(readers.get(v["name"])) is int]
    out += [f"#define MOTOR_NMAP {len(pairs)}",
            "static const int MOTOR_MAP_VR[MOTOR_NMAP] = {" + ", ".join(str(a) for a, _ in pairs) + "};",
            "static const int MOTOR_MAP_X[MOTOR_NMAP] = {" + ", ".join(str(b) for _, b in pairs) + "};"]
    mp = MotorBlock.params_from_defaults(defaults)
    sp = mp.stator
    s = [mp.slider.s_min_m + (mp.slider.s_max_m - mp.slider.s_min_m) * i / 4000 for i in range(4001)]
    p_max = max(st.axial_force_N(sp, float(x)) for x in s)
    table = st.ModalTable(sp, None)
    cells = []
    for k in range(int(math.ceil(max(TABLE_P_MAX_N, 2.0 * p_max) / st.TABLE_CELL_N))):
        a = table.cell_array(k)
        if a is None:
            break
        cells.append(a.ravel().tolist())
    if not cells:
        raise NativeBuildError("the modal table of the motor's stator has no cell from 0 N")
    rows = st.TABLE_DEGREE + 1
    x_nodes, to_power = st.table_interpolation()
    out += [f"#define TABLE_ROWS {rows}", f"#define BETA_L_B2 {_c_double(st.BETA_L_B2)}",
            f"#define PHI_SLOPE_RATIO {_c_double(st.b2_slope_ratio())}",
            "static const double LOBATTO_X[TABLE_ROWS] = {" + ", ".join(_c_double(float(v)) for v in x_nodes) + "};",
            "static const double TO_POWER[TABLE_ROWS][TABLE_ROWS] = {" + ", ".join(
                "{" + ", ".join(_c_double(float(v)) for v in row) + "}" for row in to_power) + "};"]
    out += [f"#define TABLE_CELL_N {_c_double(float(st.TABLE_CELL_N))}", "#define TABLE_K0 0",
            f"#define TABLE_NCELL {len(cells)}",
            f"static const double MOTOR_TABLE[TABLE_NCELL][{2 * rows}] = {{"]
    out += ["    {" + ", ".join(_c_double(v) for v in cell) + "}," for cell in cells] + ["};"]
    out += [f"#define TABLE_NCHECK {len(TABLE_PARAMETERS)}",
            "static const int TABLE_CHECK_VR[TABLE_NCHECK] = {" + ", ".join(
                str(vr[f"Stator.{n}"]) for n in TABLE_PARAMETERS) + "};",
            "static const double TABLE_CHECK_VALUE[TABLE_NCHECK] = {" + ", ".join(
                _c_double(float(getattr(sp, n))) for n in TABLE_PARAMETERS) + "};"]
    return out


# ---------------------------------------------------------------------------
# model descriptions
# ---------------------------------------------------------------------------

def _source_files(name: str, fmi_version: int) -> list[str]:
    glue = ["fmi2_glue.c"] if fmi_version == 2 else ["fmi3_glue.c", "fmi3_stubs.c"]
    model = sorted(p.name for p in (C_DIR / MODELS[name]).glob("*.c"))
    return ["fmu_core.c", *glue, *model]


def fmi2_model_description(python_md: bytes, name: str, guid: str, sources: list[str]) -> bytes:
    """The Python FMU's ``modelDescription.xml`` (same variables) for the native library and its sources."""
    root = ET.fromstring(python_md)
    root.set("guid", guid)
    root.set("generationTool", GENERATION_TOOL)
    root.attrib.pop("generationDateAndTime", None)
    cs = root.find("CoSimulation")
    for key in list(cs.attrib):
        del cs.attrib[key]
    cs.attrib.update({"modelIdentifier": model_identifier(name), "needsExecutionTool": "false",
                      "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
                      "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "true",
                      "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true"})
    for old in cs.findall("SourceFiles"):
        cs.remove(old)
    sf = ET.SubElement(cs, "SourceFiles")
    for f in sources:
        ET.SubElement(sf, "File", name=f)
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def fmi3_model_description(python_md: bytes, name: str, guid: str) -> bytes:
    """The FMI 3.0 ``modelDescription.xml`` with the variables of the Python FMU's FMI 2.0 one."""
    src = ET.fromstring(python_md)
    variables = read_variables(python_md)
    attrs = {"fmiVersion": "3.0", "modelName": src.get("modelName"), "instantiationToken": guid,
             "description": src.get("description", ""), "author": src.get("author", AUTHOR),
             "version": src.get("version", __version__), "copyright": src.get("copyright", ""),
             "license": src.get("license", LICENSE), "generationTool": GENERATION_TOOL,
             "variableNamingConvention": src.get("variableNamingConvention", "structured")}
    root = ET.Element("fmiModelDescription", attrs)
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": model_identifier(name), "needsExecutionTool": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canGetAndSetFMUState": "true",
        "canSerializeFMUState": "true", "canHandleVariableCommunicationStepSize": "true",
        "providesIntermediateUpdate": "false", "canReturnEarlyAfterIntermediateUpdate": "false",
        "hasEventMode": "false"})
    ud = src.find("UnitDefinitions")
    units = ET.SubElement(root, "UnitDefinitions")
    for u in ud:
        ue = ET.SubElement(units, "Unit", name=u.get("name"))
        ET.SubElement(ue, "BaseUnit", dict(u.find("BaseUnit").attrib))
    if not any(u.get("name") == "s" for u in ud):
        ue = ET.SubElement(units, "Unit", name="s")
        ET.SubElement(ue, "BaseUnit", s="1")
    cats = ET.SubElement(root, "LogCategories")
    for c in src.find("LogCategories") if src.find("LogCategories") is not None else []:
        ET.SubElement(cats, "Category", dict(c.attrib))
    de = src.find("DefaultExperiment")
    if de is not None:
        ET.SubElement(root, "DefaultExperiment", dict(de.attrib))
    mv = ET.SubElement(root, "ModelVariables")
    for v in variables:
        a = {"name": v["name"], "valueReference": str(v["vr"]), "description": v["description"],
             "causality": v["causality"], "variability": v["variability"]}
        if v["type"] == "Boolean":
            if a["variability"] == "continuous":
                a["variability"] = "discrete"
            if v["has_start"]:
                a["start"] = v["start_text"]
            ET.SubElement(mv, "Boolean", a)
            continue
        if v["has_start"]:
            a["start"] = repr(v["start"])
        for key in ("unit", "min", "max", "nominal"):
            if v[key] is not None:
                a[key] = v[key]
        ET.SubElement(mv, "Float64", a)
    ET.SubElement(mv, "Float64", {"name": "time", "valueReference": str(len(variables)),
                                  "description": "simulation time", "causality": "independent",
                                  "variability": "continuous", "unit": "s"})
    ms = ET.SubElement(root, "ModelStructure")
    outputs = [v for v in variables if v["causality"] == "output"]
    for v in outputs:
        ET.SubElement(ms, "Output", valueReference=str(v["vr"]))
    for v in outputs:
        ET.SubElement(ms, "InitialUnknown", valueReference=str(v["vr"]))
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def build_description(name: str, sources: list[str]) -> bytes:
    """FMI 3.0 ``sources/buildDescription.xml``."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    bc = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model_identifier(name))
    fs = ET.SubElement(bc, "SourceFileSet", language="C99")
    for f in sources:
        ET.SubElement(fs, "SourceFile", name=f)
    ET.SubElement(fs, "IncludeDirectory", name=".")
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


# ---------------------------------------------------------------------------
# build
# ---------------------------------------------------------------------------

def _block_name(python_md: bytes, name: str) -> str:
    from ...cosim.composite import BLOCKS
    return BLOCKS[name].__name__


def source_tree(name: str, python_md: bytes, fmi_version: int, guid: str,
                defaults: dict | None = None) -> dict[str, bytes]:
    """``{file name: bytes}`` of the FMU's ``sources/`` folder."""
    if name not in MODELS:
        raise NativeBuildError(f"no native model for {name}; native FMUs exist for {', '.join(MODELS)}")
    files: dict[str, bytes] = {}
    for f in ("fmu_core.c", "fmu_core.h", "fmi2_glue.c" if fmi_version == 2 else "fmi3_glue.c"):
        files[f] = (C_DIR / f).read_bytes()
    if fmi_version == 3:
        files["fmi3_stubs.c"] = (C_DIR / "fmi3_stubs.c").read_bytes()
    for p in sorted((C_DIR / MODELS[name]).iterdir()):
        if p.suffix in (".c", ".h"):
            files[p.name] = p.read_bytes()
    headers = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h") if fmi_version == 2 else (
        "fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
    for h in headers:
        files[h] = (fmi_headers() / h).read_bytes()
    files["model_data.h"] = model_data_header(name, read_variables(python_md), guid, _block_name(python_md, name),
                                              fmi_version, defaults).encode()
    if name == "L1B2Motor":
        from .translate import translate_kernels
        files["motor_kernels.h"] = translate_kernels().encode()
    if name == "Predictor" and "extended_predictor" in (defaults or {}):
        from .translate import translate_effect_kernels
        files["effect_kernels.h"] = translate_effect_kernels().encode()
    return files


def compile_library(sources_dir: Path, c_files: list[str], out: Path, cc: str | None = None) -> None:
    """Compile ``c_files`` of ``sources_dir`` into the shared library ``out``."""
    cmd = [find_cc(cc), *CFLAGS, f"-I{sources_dir}", "-o", str(out), *(str(sources_dir / f) for f in c_files), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise NativeBuildError(f"compiling {out.name} failed ({' '.join(cmd)}):\n{proc.stderr[-4000:]}")


def build_native_fmu(name: str, python_fmu: str | Path, dest_dir: str | Path, fmi_version: int = 2,
                     cc: str | None = None) -> Path:
    """Build ``<dest_dir>/<name>-native[-fmi3].fmu`` with the variables of the Python FMU ``python_fmu``.

    Returns the path. Raises :class:`NativeBuildError` when there is no native
    model for ``name``, no C compiler, or the compilation fails.
    """
    if fmi_version not in (2, 3):
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    with zipfile.ZipFile(python_fmu) as z:
        python_md = z.read("modelDescription.xml")
        defaults = json.loads(z.read("resources/_fmu_defaults.json"))
    if name == "Predictor" and set(_drive_laws(defaults)) - {"eq29"}:
        raise NativeBuildError("the native predictor implements Eq. 29 only; the pure-slip family's drive force "
                               "(slip ratio of the state) stays in the Python Predictor.fmu")
    if name == "Predictor" and _keyed(defaults, "frequency"):
        raise NativeBuildError("a predictor with a drive-frequency response has no native model (its C code has "
                               "no frequency response): its Predictor.fmu stays a Python FMU")
    sources = _source_files(name, fmi_version)
    # the GUID: stable for identical sources and variables (and different from the Python FMU's)
    provisional = source_tree(name, python_md, fmi_version, "{}", defaults)
    h = hashlib.sha256(python_md)
    for f in sorted(provisional):
        h.update(f.encode() + b"\0" + provisional[f])
    guid = stable_guid(f"{name}-native-fmi{fmi_version}", __version__, h.hexdigest()[:32])
    files = source_tree(name, python_md, fmi_version, guid, defaults)
    md = (fmi2_model_description(python_md, name, guid, sources) if fmi_version == 2
          else fmi3_model_description(python_md, name, guid))
    dest_dir = Path(dest_dir)
    dest_dir.mkdir(parents=True, exist_ok=True)
    dest = dest_dir / f"{native_fmu_name(name, fmi_version)}.fmu"
    with tempfile.TemporaryDirectory(prefix="l1b2_native_") as td:
        src_dir = Path(td) / "sources"
        src_dir.mkdir()
        for f, data in files.items():
            (src_dir / f).write_bytes(data)
        lib = Path(td) / f"{model_identifier(name)}.so"
        compile_library(src_dir, sources, lib, cc)
        tmp = dest.with_name(dest.name + ".tmp")
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", md)
            for f in sorted(files):
                z.writestr(f"sources/{f}", files[f])
            if fmi_version == 3:
                z.writestr("sources/buildDescription.xml", build_description(name, sources))
            z.write(lib, f"binaries/{FMI_PLATFORM[fmi_version]}/{lib.name}")
        os.replace(tmp, dest)
    os.chmod(dest, 0o644)
    return dest


def build_native_set(name: str, python_fmu: str | Path, dest_dir: str | Path,
                     cc: str | None = None) -> tuple[dict[str, Path], dict]:
    """The FMI 2.0 and FMI 3.0 native FMUs of ``name`` beside its Python FMU, for :func:`l1b2.fmi.export.export_all`.

    Returns ``({file stem: path}, info)``; ``info`` says what was built or why
    not (no native model for ``name``, no C compiler): the Python FMU is
    exported either way.
    """
    if name not in MODELS:
        return {}, {"included": False, "reason": f"no native model for {name} (native FMUs: {', '.join(MODELS)})"}
    try:
        paths = {native_fmu_name(name, v): build_native_fmu(name, python_fmu, dest_dir, v, cc) for v in (2, 3)}
    except NativeBuildError as exc:
        return {}, {"included": False, "reason": str(exc)}
    return paths, {"included": True, "fmus": sorted(paths), "compiler": find_cc(cc), "cflags": list(CFLAGS)}


def python_and_native_fmus(name: str, dest_dir: str | Path, **build_kw) -> dict:
    """``{"python": path, 2: path, 3: path}``: the Python FMU ``name`` (:func:`l1b2.fmi.build.build_fmu` with
    ``build_kw``) and its native FMI 2.0 and 3.0 FMUs, all in ``dest_dir``.

    Raises :class:`NoCompilerError` first when there is no C compiler (nothing is built then).
    """
    from ..build import build_fmu
    find_cc()
    py = build_fmu(name, dest_dir, **build_kw)
    return {"python": py, 2: build_native_fmu(name, py, dest_dir, 2), 3: build_native_fmu(name, py, dest_dir, 3)}
