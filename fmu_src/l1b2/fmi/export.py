"""Export everything a simulation engine needs: the FMUs, the SSP archive and a manifest.

:func:`export_all` writes into one folder (``l1b2 export --out DIR``,
``make dist``)::

    DIR/fmus/Driver.fmu, Stator.fmu, Interface.fmu, Slider.fmu   the four subsystems
    DIR/fmus/Predictor.fmu                                       the Eq. 29 predictor (when given)
    DIR/L1B2Motor.ssp     SSP 1.0 archive: SystemStructure.ssd, the four FMUs and the
                          motor's parameter set (one .ssv per component); the system's
                          inputs and outputs as standard SSP system connections
    DIR/L1B2Motor_libcosim.ssp   the same for libcosim, which refuses those: system
                          connections in the vendor annotation (l1b2.cosim.ssp)
    DIR/L1B2Motor.fmu     the whole coupled motor in one co-simulation FMU
    DIR/manifest.json     files, sizes, SHA-256, GUIDs, versions, validation results

and the native (C, no Python at run time) FMUs of the predictor and the motor
where :mod:`l1b2.fmi.native` has their model, FMI 2.0 and 3.0, beside the
Python ones: ``Predictor-native.fmu``, ``Predictor-native-fmi3.fmu`` (in
``DIR/fmus``), ``L1B2Motor-native.fmu``, ``L1B2Motor-native-fmi3.fmu``.

Every FMU is validated with :func:`fmpy.validation.validate_fmu` and checked
for a unit on every Real; the SSD and the SSVs inside the archive are
validated against the SSP 1.0 schemas shipped with fmpy. Any problem raises
:class:`ExportError` (nothing is reported as exported that did not pass).
``DIR/fmus`` is the folder :class:`l1b2.cosim.master.CoSimulation` looks in by default
when ``DIR`` is the repository's ``dist``.

The manifest has no time stamps: exporting the same sources twice gives the
same manifest except for the SHA-256 of the zip files (zip members carry
their write time); the GUIDs are stable (content-derived, see
:mod:`l1b2.fmi.build`).
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import sys
import zipfile
from pathlib import Path
from typing import Any, Mapping

from .. import __version__
from ..errors import L1B2Error
from ..jsonio import dumps
from ..physics.params import MotorParams, load_motor
from ..predictor.effects.homes import map_effects
from .build import SUBSYSTEM_FMUS, build_fmu
from .native.build import build_native_set
from .slaves import SLAVES

MOTOR_FMU = "L1B2Motor"
PREDICTOR_FMU = "Predictor"
SSP_NAME = "L1B2Motor.ssp"
#: the same system for libcosim, which refuses standard system connections (measured with libcosimpy 0.0.6:
#: "Unable to create execution from path"): system connections in the vendor annotation, as the source SSD
LIBCOSIM_SSP_NAME = "L1B2Motor_libcosim.ssp"
MANIFEST = "manifest.json"


class ExportError(L1B2Error):
    """An exported file failed validation (the message lists every problem)."""


def predictor_available() -> bool:
    """True when the slave template knows the Predictor FMU (:data:`l1b2.fmi.slaves.SLAVES`)."""
    return PREDICTOR_FMU in SLAVES


def _predictor_dict(predictor: Any) -> dict:
    if hasattr(predictor, "to_dict"):
        predictor = predictor.to_dict()
    if not isinstance(predictor, Mapping):
        raise ExportError(f"predictor must be a dict from an identification result (or have .to_dict()), "
                          f"got {type(predictor).__name__}")
    d = json.loads(json.dumps(dict(predictor)))  # JSON-safe copy, as baked into the FMU
    if (d.get("frequency") or {}).get("f_l0_Hz") is not None:
        raise ExportError("Predictor.fmu does not carry the pure-slip family's contact law (frequency f_l0_Hz, "
                          "contact_V; identified with frequency='contact'): identify with frequency='auto' to export")
    return d


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _unit_problems(md) -> list[str]:
    defined = {u.name for u in md.unitDefinitions}
    out = []
    for v in md.modelVariables:
        if v.type == "Real":
            if not v.unit:
                out.append(f"Real variable '{v.name}' has no unit")
            elif v.unit not in defined:
                out.append(f"Real variable '{v.name}': unit '{v.unit}' is not in UnitDefinitions")
    return out


def fmu_record(path: Path, root: Path) -> dict:
    """Manifest entry of one FMU: identity, platforms and validation results (problems listed)."""
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    md = read_model_description(str(path))
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
    platforms = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
    return {
        "path": path.relative_to(root).as_posix(),
        "kind": "fmu",
        "bytes": path.stat().st_size,
        "sha256": _sha256(path),
        "modelName": md.modelName,
        "modelIdentifier": md.coSimulation.modelIdentifier if md.coSimulation else None,
        "guid": md.guid,
        "version": md.version,
        "fmiVersion": md.fmiVersion,
        "interfaces": ["CoSimulation"] if md.coSimulation else [],
        "platforms": platforms,
        "author": md.author,
        "license": md.license,
        "variables": len(md.modelVariables),
        "validation": {"fmpy": list(validate_fmu(str(path))), "units": _unit_problems(md)},
    }


def ssp_record(path: Path, root: Path, fmu_records: Mapping[str, dict]) -> dict:
    """Manifest entry of the ``.ssp``: members, components and schema validation of SSD and SSVs."""
    from lxml import etree

    from ..cosim import ssp

    schema_dir = Path(__import__("fmpy").__file__).resolve().parent / "ssp" / "schema"
    ssd_schema = etree.XMLSchema(etree.parse(str(schema_dir / "SystemStructureDescription.xsd")))
    ssv_schema = etree.XMLSchema(etree.parse(str(schema_dir / "SystemStructureParameterValues.xsd")))
    problems: dict[str, list[str]] = {}
    with zipfile.ZipFile(path) as z:
        members = sorted(z.namelist())
        ssd_bytes = z.read("SystemStructure.ssd")
        ssd_doc = etree.fromstring(ssd_bytes)
        if not ssd_schema.validate(ssd_doc):
            problems["SystemStructure.ssd"] = [str(e) for e in ssd_schema.error_log]
        for name in members:
            if name.endswith(".ssv"):
                if not ssv_schema.validate(etree.fromstring(z.read(name))):
                    problems[name] = [str(e) for e in ssv_schema.error_log]
        import tempfile
        with tempfile.TemporaryDirectory(prefix="l1b2_ssp_check_") as td:
            z.extract("SystemStructure.ssd", td)
            system = ssp.read_ssd(Path(td) / "SystemStructure.ssd")
        components = {}
        for name, comp in system.components.items():
            data = z.read(comp.source)
            stem = Path(comp.source).stem
            rec = fmu_records.get(stem)
            same = rec is not None and hashlib.sha256(data).hexdigest() == rec["sha256"]
            if not same:
                problems.setdefault(comp.source, []).append(f"{comp.source} is not the exported {stem}.fmu")
            components[name] = {"source": comp.source, "guid": rec["guid"] if rec else None,
                                "parameter_sets": list(comp.parameter_sources)}
    return {
        "path": path.relative_to(root).as_posix(),
        "kind": "ssp",
        "bytes": path.stat().st_size,
        "sha256": _sha256(path),
        "sspVersion": "1.0",
        "members": members,
        "components": components,
        "system_inputs": [c for c, k in system.connectors.items() if k.kind == "input"],
        "system_outputs": [c for c, k in system.connectors.items() if k.kind == "output"],
        "default_step_size_s": system.default_step_size,
        # where the system connectors are wired: standard ssd:Connections, or the annotation libcosim needs
        "system_connections": ("annotation" if f'type="{ssp.SYSTEM_CONNECTIONS_ANNOTATION}"'.encode() in ssd_bytes
                               else "standard"),
        "validation": {"schema": problems},
    }


def _all_problems(manifest: dict) -> list[str]:
    out = []
    for rec in manifest["files"]:
        for kind, probs in rec["validation"].items():
            if isinstance(probs, dict):
                out += [f"{rec['path']}: {member}: {p}" for member, ps in probs.items() for p in ps]
            else:
                out += [f"{rec['path']}: {kind}: {p}" for p in probs]
    return out


def export_all(out_dir: str | Path, mp: MotorParams | None = None, predictor: Mapping | Any | None = None) -> dict:
    """Build, validate and describe every deliverable of the motor in ``out_dir``.

    Parameters
    ----------
    out_dir : folder to write into (created; files of earlier exports are replaced)
    mp : the motor's parameters baked into every FMU and written as the SSP's
        parameter set (default: the reference motor, ``system_models/reference_motor.toml``)
    predictor : the identified Eq. 29 predictor, as the dict of an identification
        result (``PredictorSetup.to_dict()``; an object with ``.to_dict()`` is
        accepted). ``None``: no ``Predictor.fmu`` is exported and the manifest
        says why; likewise when this source tree has no Predictor slave.

    Returns
    -------
    The manifest (also written to ``out_dir/manifest.json``): ``files`` (one
    record per FMU and for the ``.ssp``: path relative to ``out_dir``, bytes,
    sha256, GUID, version, platforms, validation problems), ``predictor``
    (``included`` and ``reason``), versions of the tool and its runtime.

    Raises
    ------
    ExportError
        if any FMU has an fmpy validation problem or a Real without a unit, or
        the SSD/SSV do not validate against the SSP 1.0 schemas. The files stay
        in ``out_dir`` for inspection but no manifest is written.
    """
    from ..cosim import ssp

    mp = mp or load_motor()
    out = Path(out_dir)
    fmu_dir = out / "fmus"
    fmu_dir.mkdir(parents=True, exist_ok=True)
    (out / MANIFEST).unlink(missing_ok=True)

    paths: dict[str, Path] = {name: build_fmu(name, fmu_dir, mp=mp) for name in SUBSYSTEM_FMUS}
    pred_path = fmu_dir / f"{PREDICTOR_FMU}.fmu"
    if predictor is None:
        pred_info = {"included": False, "reason": "no identification result given (predictor=None)"}
    elif not predictor_available():
        pred_info = {"included": False, "reason": f"this package has no {PREDICTOR_FMU} slave"}
    else:
        pred_info = {"included": True, "path": pred_path.relative_to(out).as_posix()}
        paths[PREDICTOR_FMU] = build_fmu(PREDICTOR_FMU, fmu_dir, mp=mp,
                                         extra_defaults={"predictor": _predictor_dict(predictor)})
    if not pred_info["included"]:
        pred_path.unlink(missing_ok=True)  # never leave a stale predictor beside a manifest without it
        for stale in fmu_dir.glob(f"{PREDICTOR_FMU}-native*.fmu"):
            stale.unlink()
    paths[MOTOR_FMU] = build_fmu(MOTOR_FMU, out, mp=mp)
    ssp_path = ssp.build_ssp(out / SSP_NAME, {n: paths[n] for n in SUBSYSTEM_FMUS}, mp=mp)
    native_info = {}
    for name in (PREDICTOR_FMU, MOTOR_FMU):
        if name in paths:
            built, native_info[name] = build_native_set(name, paths[name], paths[name].parent)
            paths.update(built)
            if not native_info[name]["included"]:   # e.g. the pure-slip predictor: no stale native beside it
                for stale in paths[name].parent.glob(f"{name}-native*.fmu"):
                    stale.unlink()
    libcosim_path = ssp.build_ssp(out / LIBCOSIM_SSP_NAME, {n: paths[n] for n in SUBSYSTEM_FMUS}, mp=mp,
                                  standard=False)

    for p in list(paths.values()) + [ssp_path, libcosim_path]:
        os.chmod(p, 0o644)  # the build writes through mkstemp (0600); these files are for others to read
    records = {name: fmu_record(p, out) for name, p in paths.items()}
    files = [records[n] for n in paths]
    files.append(ssp_record(ssp_path, out, records))
    files.append(ssp_record(libcosim_path, out, records))
    import fmpy
    import numpy
    import pythonfmu
    import scipy
    manifest = {
        "tool": "l1b2-usm",
        "version": __version__,
        "motor": mp.name,
        "fmiVersion": "2.0",
        "files": files,
        "predictor": pred_info,
        "native": native_info,
        "build": {
            "python": platform.python_version(),
            "platform": f"{sys.platform}-{platform.machine()}",
            "pythonfmu": pythonfmu.__version__,
            "fmpy": fmpy.__version__,
        },
        "runtime": {
            "python": f"{sys.version_info.major}.{sys.version_info.minor}",
            "packages": {"numpy": numpy.__version__, "scipy": scipy.__version__, **_numba_version()},
            "notes": "PythonFMU FMUs: the host needs a shared libpython of this version loaded with global "
                     "symbols and numpy/scipy importable by it (PYTHONPATH); numba too for the compiled kernels "
                     "(without it the FMUs run the same kernels in plain Python, 1.5-3x slower); "
                     "see the README section 'Use the FMUs in your simulator'",
        },
    }
    problems = _all_problems(manifest)
    if problems:
        raise ExportError(f"{out}: {len(problems)} validation problem(s):\n  " + "\n  ".join(problems))
    write_manifest(out / MANIFEST, manifest)
    return manifest


def write_manifest(path: Path, manifest: dict) -> None:
    """``manifest`` as strict JSON at ``path``, replaced at once (through a temporary sibling)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(dumps(manifest) + "\n")
    os.replace(tmp, path)


# ---------------------------------------------------------------------------
# the calibrated, extended model of a close-the-loop job
# ---------------------------------------------------------------------------

CALIBRATED_MANIFEST = "calibrated_manifest.json"
CALIBRATED_SSP = "L1B2Motor_calibrated.ssp"
CALIBRATED_LIBCOSIM_SSP = "L1B2Motor_calibrated_libcosim.ssp"   # see LIBCOSIM_SSP_NAME
CALIBRATED_SSV_DIR = "calibrated_ssv"


def _refuse_sensor_stages(model) -> None:
    """ExportError when the model's speed output goes through a sensor stage ``Predictor.fmu`` has no code for: the
    speed sensor's gain along the stroke (the output filter and its rails are stages of the FMU)."""
    if model.speed_gain is not None:
        raise ExportError("Predictor.fmu has no stage for the speed sensor's gain along the stroke (speed_gain): "
                          "the model predicts the recorded speed only through ExtendedPredictor.free_run")


def export_calibrated(model, out_dir: str | Path, mp: MotorParams | None = None) -> dict:
    """Write ``Predictor.fmu`` carrying a calibrated extended predictor, and a manifest of where each effect went.

    Parameters
    ----------
    model : l1b2.predictor.effects.ExtendedPredictor
        The close-the-loop job's final model (``CloseLoopResult.calibrated_model``).
    out_dir : folder to write into (created): ``fmus/Predictor.fmu`` and ``calibrated_manifest.json``
    mp : motor parameters baked into the FMU's defaults document (default: the reference motor)

    Returns
    -------
    The manifest: the FMU's record (validation results), those of the native
    FMI 2.0 and 3.0 ``Predictor-native[-fmi3].fmu`` written beside it (the
    effects' kernels in C; ``native`` says what was built or why not), and per effect its
    parameters and where it went (``Predictor.fmu``; the subsystem FMUs only
    where mapped, :func:`l1b2.predictor.effects.homes.map_effects`, else the reason).
    When at least one effect was mapped, also ``L1B2Motor_calibrated.ssp``
    (the four subsystem FMUs with the calibrated parameter set) and the
    parameter set itself, ``calibrated_ssv/<Component>.ssv``.

    Raises
    ------
    ExportError
        if the FMU fails fmpy validation or a Real has no unit (no manifest is written); before building
        anything, if an effect reads a signal that no input of ``Predictor.fmu`` gives (the session clock as a
        channel), or the run-level value of an input that TRAIN's runs did not hold constant
        (:func:`l1b2.predictor.effects.channels.export_problem`: the FMU reads a run-level signal of V0, the
        load, the direction, the temperature or a logged channel as the input's current value); if the model
        carries a speed sensor's gain along the stroke (``ExtendedPredictor.speed_gain``: Predictor.fmu has no such
        output stage). The output filter and the speed channel's range limits (``output_filter`` rails
        ``lo_m_s``/``hi_m_s``) are the FMU's last stages (parameters ``speed_filter_*``, ``speed_rail_lo/hi``).

    A logged channel an effect reads is an input of ``Predictor.fmu`` named after its column
    (:func:`l1b2.cosim.composite.channel_input`); the manifest lists it in ``inputs`` and ``channel_inputs``
    (:func:`channel_records`). No native FMU carries such an effect (its kernels read the fixed inputs only:
    ``native`` says so).
    """
    from ..predictor.effects import ExtendedPredictor, plugin_sources
    from ..predictor.effects.channels import export_problem

    if not isinstance(model, ExtendedPredictor):
        raise ExportError(f"export_calibrated needs an l1b2.predictor.effects.ExtendedPredictor, "
                          f"got {type(model).__name__}")
    _predictor_dict(model.model)     # refuses what the FMU cannot carry (the contact law)
    _refuse_sensor_stages(model)
    problems = [(e.label, export_problem(e.spec)) for e in model.effects]
    logged = [label for label, why in problems if why and why.startswith("no input")]
    if logged:
        raise ExportError(f"Predictor.fmu has no input for the signals these effects read: {', '.join(logged)}")
    varied = [f"{label}: {why}" for label, why in problems if why]
    if varied:
        raise ExportError("Predictor.fmu reads a run-level signal as its input's current value, exact only when "
                          f"TRAIN's runs held that input constant: {'; '.join(varied)}")
    mp = mp or load_motor()
    out = Path(out_dir)
    fmu_dir = out / "fmus"
    fmu_dir.mkdir(parents=True, exist_ok=True)
    (out / CALIBRATED_MANIFEST).unlink(missing_ok=True)
    defaults = {"predictor": model.model.to_dict()}
    if model.effects or model.output_filter is not None:   # else the plain Eq. 29 predictor is the model
        defaults["extended_predictor"] = model.to_dict()
    # families defined outside the package travel with the model (imported by the FMU's effects registry)
    plugins = {f"predictor/effects/plugins/{name}.py": src.encode() for name, src in plugin_sources(model).items()}
    path = build_fmu(PREDICTOR_FMU, fmu_dir, mp=mp, extra_defaults=defaults, extra_files=plugins or None)
    os.chmod(path, 0o644)
    records = {PREDICTOR_FMU: fmu_record(path, out)}
    for stale in fmu_dir.glob(f"{PREDICTOR_FMU}-native*.fmu"):
        stale.unlink()
    native, native_info = build_native_set(PREDICTOR_FMU, path, fmu_dir)   # the effects' kernels in C
    for name, p in native.items():
        os.chmod(p, 0o644)
        records[name] = fmu_record(p, out)
    mp_cal, mapping = map_effects(model, mp)
    files = list(records.values())
    ssp_info = {"included": False, "reason": "no effect was mapped into the subsystem FMUs"}
    if any(m["mapped"] for m in mapping):
        from ..cosim import ssp
        paths = {name: build_fmu(name, fmu_dir, mp=mp_cal) for name in SUBSYSTEM_FMUS}
        ssp_path = ssp.build_ssp(out / CALIBRATED_SSP, paths, mp=mp_cal)
        lc_path = ssp.build_ssp(out / CALIBRATED_LIBCOSIM_SSP, paths, mp=mp_cal, standard=False)
        for p in list(paths.values()) + [ssp_path, lc_path]:
            os.chmod(p, 0o644)
        records.update({name: fmu_record(p, out) for name, p in paths.items()})
        files = [records[n] for n in records] + [ssp_record(ssp_path, out, records),
                                                 ssp_record(lc_path, out, records)]
        ssv_dir = out / CALIBRATED_SSV_DIR
        ssv_dir.mkdir(exist_ok=True)
        for comp, text in ssp.motor_to_ssvs(mp_cal).items():
            (ssv_dir / f"{comp}.ssv").write_text(text)
        ssp_info = {"included": True, "path": CALIBRATED_SSP, "libcosim_path": CALIBRATED_LIBCOSIM_SSP,
                    "parameter_sets": CALIBRATED_SSV_DIR,
                    "motor": mp.name, "changed": {k: v for m in mapping for k, v in m["parameters"].items()}}
        if model.channel_inputs:   # the SSP's system has no input for them: their effects are Predictor.fmu's
            ssp_info["not_carried_channels"] = list(model.channel_inputs)
    problems = _all_problems({"files": files})
    if problems:
        raise ExportError(f"{out}: {len(problems)} validation problem(s):\n  " + "\n  ".join(problems))
    effects = [{"label": e.label, "family": e.family, "regressors": list(e.regressors),
                "parameters": {n: {"value": p, "stderr": s, "unit": u}
                               for n, p, s, u in zip(e.names, e.phi, e.stderr, e.units)},
                "predictor_fmu": records[PREDICTOR_FMU]["path"],
                "subsystems": {k: v for k, v in m.items() if k not in ("label", "family")}}
               for e, m in zip(model.effects, mapping)]
    manifest = {
        "tool": "l1b2-usm", "version": __version__, "kind": "calibrated extended predictor",
        "source": model.source, "files": files, "effects": effects, "calibrated_ssp": ssp_info,
        "native": {PREDICTOR_FMU: native_info},
        "output_filter": model.output_filter,
        "inputs": (["V0", "s", "load", "direction"] + (["T"] if model.needs_temperature else [])
                   + list(model.channel_inputs)),
        "channel_inputs": channel_records(model),
        "time": "the FMU's own time is the session clock the effects use (start the simulation at the run's "
                "session time)",
    }
    write_manifest(out / CALIBRATED_MANIFEST, manifest)
    return manifest


def channel_records(model) -> list:
    """One record per logged-channel input of a calibrated model's ``Predictor.fmu`` (``name``, ``unit``,
    ``start``: TRAIN's mean, ``description``, ``effects``: the labels of the effects reading it)."""
    from ..cosim.composite import ExtendedPredictorBlock
    from ..predictor.effects import needs
    from ..predictor.effects.channels import fmu_signal
    chans = model.channel_inputs
    out = []
    for v in ExtendedPredictorBlock.inputs(model):
        if v.name in chans:
            readers = [e.label for e in model.effects if "col:" + v.name in {fmu_signal(k) for k in needs(e.spec)}]
            out.append({"name": v.name, "unit": v.unit, "start": v.start, "description": v.description,
                        "effects": readers})
    return out


def _numba_version() -> dict:
    """``{"numba": version}`` when numba is importable (it compiles the FMUs' per-step kernels), else ``{}``."""
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency
        return {}
    return {"numba": numba.__version__}
