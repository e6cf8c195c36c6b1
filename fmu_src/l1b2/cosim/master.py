"""Co-simulation master on fmpy's ``FMU2Slave`` API, driven by the SSP system structure.

* The wiring and the parameter set come from the ``.ssd`` and its bound
  ``.ssv`` files (``system_models/`` or an ``.ssp`` archive); nothing is
  hard-coded. The system connectors are wired by the SSD's
  ``org.l1b2-usm.SystemConnections`` annotation (see :mod:`l1b2.cosim.ssp`).
* Gauss-Seidel: components are stepped in the order they appear in the SSD
  (driver -> stator -> interface -> slider), each one's inputs taken from
  the latest outputs, with a fixed communication step.
* Optional fixed-point iteration: the whole macro step is repeated (FMU
  states restored with ``fmi2SetFMUstate``) with inputs taken from the
  previous iterate's end-of-step outputs until the coupling values change by
  less than a tolerance.
* Value references are looked up once; instances are always terminated and
  freed (``finally``), like FMPy's ``custom_input`` example.
* Connection units are checked against the FMUs' model descriptions; a
  system whose units disagree is refused.
* Before the first FMU is loaded the PythonFMU exit fix of
  :mod:`l1b2.fmi.runtime` is installed.
* An ``.ssp`` is untrusted: it is unpacked under :class:`~l1b2.cosim.ssp.ArchiveLimits`
  into a temporary folder that is removed by :meth:`CoSimulation.close`
  (``with CoSimulation(...) as cs``), when the object is collected, at
  exit, and at once when the constructor fails; its FMUs and parameter sets
  must lie inside the archive (``allow_outside=True`` lifts that), and each
  FMU is checked against the same limits before it is read. Every problem
  is a :class:`~l1b2.errors.SystemStructureError` naming archive member and element.
"""

from __future__ import annotations

import atexit
import math
import operator
import os
import shutil
import signal
import tempfile
import threading
import warnings
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import numpy as np
import pandas as pd

from ..errors import SimulationError, SystemStructureError
from .result import CoSimResult
from .ssp import (
    DEFAULT_LIMITS,
    SSD_FILE,
    ArchiveLimits,
    SystemStructure,
    check_against_model_descriptions,
    check_zip_file,
    read_ssd,
    read_ssv,
    resolve_resource,
    unpack_ssp,
)

DEFAULT_STEP_S = 2e-4
#: fmi2Status values above this one (discard, error, fatal) end a simulation
FMI2_WARNING = 1
FMI2_STATUS = {2: "fmi2Discard", 3: "fmi2Error", 4: "fmi2Fatal", 5: "fmi2Pending"}
_EXTRACTED: dict[str, str] = {}


#: prefix of the temporary folders this module makes (FMU extractions, unpacked ``.ssp``), then ``<pid>-``
EXTRACT_PREFIX = "l1b2-fmu-"
_SSP_PREFIX = "l1b2_ssp_"
_LIVE_TMP: set[str] = set()   # unpacked .ssp folders of live CoSimulation objects (removed on SIGTERM too)
_swept = False


def pid_alive(pid: int) -> bool:
    """Whether the process ``pid`` of this host runs. True where no safe probe exists (not POSIX), so that a
    caller never takes over or removes what a live process may hold."""
    if os.name != "posix":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def remove_stale_extractions(tmp_root: str | None = None) -> list[str]:
    """Remove FMU extractions left in the temporary folder by l1b2 processes that no longer run.

    Only folders named ``l1b2-fmu-<pid>-*`` whose process is gone are
    removed (a killed run cannot clean up after itself). Returns them.
    """
    root = Path(tmp_root or tempfile.gettempdir())
    removed = []
    try:
        entries = list(root.glob(f"{EXTRACT_PREFIX}*"))
    except OSError:
        return removed
    for folder in entries:
        pid_text = folder.name[len(EXTRACT_PREFIX):].split("-", 1)[0]
        if pid_text.isdigit() and int(pid_text) != os.getpid() and not pid_alive(int(pid_text)):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(str(folder))
    return removed


def _on_sigterm(signum, frame):  # pragma: no cover - exercised in a subprocess (tests/test_output_dirs.py)
    """SIGTERM: remove this process's temporary FMU folders, then end as SIGTERM's default would (status 143)."""
    _remove_extracted()
    for folder in list(_LIVE_TMP):
        shutil.rmtree(folder, ignore_errors=True)
    os._exit(128 + signum)


def _install_cleanup() -> None:
    """Once per process: sweep stale extractions and remove ours on SIGTERM (only where SIGTERM is still default)."""
    global _swept
    if _swept:
        return
    _swept = True
    remove_stale_extractions()
    if os.name == "posix" and threading.current_thread() is threading.main_thread():
        if signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, None):
            signal.signal(signal.SIGTERM, _on_sigterm)


def extracted(path: Path) -> str:
    """Folder holding the extracted FMU, one per FMU content and process.

    PythonFMU puts each FMU's ``resources`` folder on ``sys.path`` for good and
    its bundled modules stay imported, so an extraction must outlive the run
    that made it: it is reused by later runs and removed at process exit, on
    SIGTERM, or (after a kill) by the next l1b2 process that extracts an FMU
    (:func:`remove_stale_extractions`). The key is the file's SHA-256, so the
    same FMU reached through another path (e.g. a fresh extraction of the
    same ``.ssp``) reuses the folder.
    """
    import hashlib

    from fmpy import extract
    _install_cleanup()
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    if digest not in _EXTRACTED or not Path(_EXTRACTED[digest]).exists():
        folder = tempfile.mkdtemp(prefix=f"{EXTRACT_PREFIX}{os.getpid()}-")
        _EXTRACTED[digest] = folder
        extract(str(path), unzipdir=folder)
    return _EXTRACTED[digest]


@atexit.register
def _remove_extracted():
    for folder in list(_EXTRACTED.values()):
        shutil.rmtree(folder, ignore_errors=True)


_ERRORS_LOGGED: list[str] = []   # the FMUs' error messages (status >= fmi2Error), newest last
_CALLBACKS = None


def _callbacks():
    """fmpy's callbacks with a logger that prints as fmpy's does and keeps the error messages."""
    global _CALLBACKS
    if _CALLBACKS is None:
        from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

        def logger(env, instance, status, category, message):
            text = message.decode("utf-8", "replace") if message else ""
            label = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"][status] if 0 <= status < 6 else "?"
            print(f"[{label}] {text}")
            if status >= 3:
                _ERRORS_LOGGED.append(" ".join(text.split()))
                del _ERRORS_LOGGED[:-20]
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(logger)
        cb.allocateMemory = defaultCallbacks.allocateMemory
        cb.freeMemory = defaultCallbacks.freeMemory
        _CALLBACKS = (cb, cb.logger)
    return _CALLBACKS[0]


def _load_slave(path, md, unz: str, name: str):
    """fmpy's FMU2Slave for an extracted FMU; an FMU without a binary for this platform is a SimulationError."""
    from fmpy.fmi2 import FMU2Slave
    try:
        return FMU2Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier=md.coSimulation.modelIdentifier,
                         instanceName=name)
    except Exception as exc:  # noqa: BLE001 - fmpy raises a plain Exception for a missing or unloadable library
        raise SimulationError(f"{path}: cannot load the FMU's binary for this platform ({' '.join(str(exc).split())}); "
                              "is the FMU complete (binaries/ folder)?") from None


def _instantiate(fmu, path) -> None:
    """``fmi2Instantiate``; NULL is a SimulationError with the reason the FMU logged."""
    mark = len(_ERRORS_LOGGED)
    try:
        fmu.instantiate(callbacks=_callbacks())
    except Exception:  # noqa: BLE001 - fmpy raises a plain Exception when fmi2Instantiate returns NULL
        why = "; ".join(_ERRORS_LOGGED[mark:]) if len(_ERRORS_LOGGED) > mark else "no reason logged"
        raise SimulationError(f"{path}: fmi2Instantiate failed: {why[:1500]}") from None


def _remove_tmp(folder: str) -> None:
    _LIVE_TMP.discard(folder)
    shutil.rmtree(folder, ignore_errors=True)


@dataclass
class _Instance:
    name: str
    fmu: object
    md: object
    unzipdir: str
    vars: dict                       # name -> ModelVariable
    state: str = "created"           # created -> instantiated -> initialized
    in_names: list = field(default_factory=list)
    in_vrs: list = field(default_factory=list)
    out_names: list = field(default_factory=list)
    out_vrs: list = field(default_factory=list)


class CoSimulation:
    """A coupled system of FMUs described by an SSD.

    Parameters
    ----------
    system : path of an ``.ssd`` file, an ``.ssp`` archive, or a folder with ``SystemStructure.ssd``
    fmu_dir : where to find the FMUs named by the SSD (``resources/X.fmu``) when they are not
        beside it (``None``: only beside the SSD; :func:`l1b2.fmi.cache.ensure_fmus` builds
        the package's FMUs on demand and returns such a folder)
    step_s : communication step [s]
    parameters : overrides ``{"Component.variable": value}`` applied after the SSV
    iterate : repeat each macro step until the coupling values converge
    tol, max_iter : tolerance and iteration limit of the fixed-point iteration; a coupling value
        has converged when its change is below ``tol * (|value| + S)``, S the largest magnitude
        seen so far among the coupling variables of its unit
    allow_outside : load FMUs and parameter sets that the SSD names by an absolute path or a
        ``..`` leaving the archive (or the SSD's folder); refused by default
    limits : what an ``.ssp`` and each FMU may unpack to (default :data:`l1b2.cosim.ssp.DEFAULT_LIMITS`)
    keep_instances : keep the FMU instances between runs: the next :meth:`run` resets them
        (``fmi2Reset``) instead of instantiating the FMUs again, so many short runs (the rig's
        experiment) cost little more than their steps; :meth:`close` (or :meth:`reset`) frees them

    Use it as a context manager (or call :meth:`close`) to remove an unpacked ``.ssp`` at once.
    """

    #: class defaults, so that the parameter loading works on a bare instance too
    allow_outside = False
    archive: Path | None = None
    limits: ArchiveLimits = DEFAULT_LIMITS

    def __init__(self, system: str | Path = SSD_FILE, fmu_dir: str | Path | None = None,
                 step_s: float = DEFAULT_STEP_S, parameters: Mapping[str, float] | None = None,
                 iterate: bool = False, tol: float = 1e-6, max_iter: int = 30, *,
                 allow_outside: bool = False, limits: ArchiveLimits | None = None, keep_instances: bool = False):
        if not (step_s > 0 and math.isfinite(step_s)):
            raise SimulationError(f"communication step [s] must be positive, got {step_s}")
        self._tmp = None
        self._finalizer = None
        self._kept: dict[str, _Instance] = {}
        self.keep_instances = bool(keep_instances)
        self.allow_outside = bool(allow_outside)
        self.limits = limits or DEFAULT_LIMITS
        try:
            self._open(Path(system), fmu_dir, parameters)
        except BaseException:
            self.close()  # nothing unpacked may outlive a failed constructor
            raise
        self.step_s = float(step_s)
        self.iterate, self.tol, self.max_iter = iterate, tol, max_iter
        self.iterations_ = []

    def _open(self, system: Path, fmu_dir, parameters):
        label = None
        if system.suffix.lower() == ".ssp":
            _install_cleanup()
            self._tmp = unpack_ssp(system, self.limits)
            _LIVE_TMP.add(str(self._tmp))
            self._finalizer = weakref.finalize(self, _remove_tmp, str(self._tmp))
            self.archive = system
            label = f"{system}: SystemStructure.ssd"
            system = self._tmp
        self.system: SystemStructure = read_ssd(system, label=label)
        self.root = self.system.path.parent
        self.fmu_dir = Path(fmu_dir) if fmu_dir is not None else None
        self.parameters = self._load_parameters()
        for key, value in (parameters or {}).items():
            comp = key.split(".", 1)[0]
            if comp not in self.system.components:
                raise SystemStructureError(f"parameter override '{key}': no component '{comp}'")
            self.parameters[key] = value
        self.fmu_paths = {name: self._resolve(c.source, "fmu", f'<Component name="{name}">')
                          for name, c in self.system.components.items()}
        self.model_descriptions = {n: self._model_description(n, p) for n, p in self.fmu_paths.items()}
        check_against_model_descriptions(self.system, self.model_descriptions)
        self._check_parameter_units()

    # -- set-up ---------------------------------------------------------------
    def _member(self, path: Path) -> str:
        """How messages name a file: ``archive.ssp: resources/X.fmu`` inside an archive, else the path."""
        if self.archive is not None:
            try:
                return f"{self.archive}: {Path(path).relative_to(self.root).as_posix()}"
            except ValueError:
                pass
        return str(path)

    def _resolve(self, source: str, kind: str, element: str = "") -> Path:
        where = f"{self.system.where}: {element}" if element else self.system.where
        outside_of = "the archive" if self.archive is not None else f"the SSD's folder {self.root}"
        found = resolve_resource(self.root, source, allow_outside=self.allow_outside, where=where,
                                 outside_of=outside_of)
        if found is not None:
            return found
        cand = [self.root / source]
        if kind == "fmu" and self.fmu_dir is not None:
            c = self.fmu_dir / Path(source).name
            if c.exists():
                return c
            cand.append(c)
        hint = (" (pass fmu_dir=l1b2.fmi.cache.ensure_fmus(), or run `python build_fmu.py --out DIR`)"
                if kind == "fmu" else "")
        if self.archive is not None:
            also = f"; not in {cand[-1]} either" if len(cand) > 1 else ""
            raise SystemStructureError(f"{where} source '{source}': no such member in the archive{also}")
        raise SystemStructureError(f"{self.system.where}: cannot find {source}; looked in "
                                   f"{', '.join(str(c) for c in cand)} and beside the SSD{hint}")

    def _model_description(self, name: str, path: Path):
        """The FMU's model description, after checking the FMU archive against the limits."""
        from fmpy import read_model_description
        where = f'{self._member(path)} (<Component name="{name}">)'
        check_zip_file(path, where, self.limits)
        try:
            return read_model_description(str(path))
        except Exception as exc:  # noqa: BLE001 - fmpy raises many kinds on a broken FMU
            raise SystemStructureError(f"{where}: not a valid FMU ({type(exc).__name__}: {exc})") from None

    def _load_parameters(self) -> dict:
        """``{"Component.variable": value}`` from the SSD's parameter bindings.

        Component-level bindings name the FMU's variables bare; system-level
        ones use hierarchical names and, as in SSP, take precedence. Unit and
        file of each value are kept in ``self.parameter_sources_`` and checked
        against the FMUs (an unknown name or another unit is refused).
        """
        values, self.parameter_sources_ = {}, {}
        for name, comp in self.system.components.items():
            sets = [self._resolve(src, "ssv", f'<Component name="{name}"> ParameterBinding')
                    for src in comp.parameter_sources]
            for path in sets:
                for var, (value, unit) in read_ssv(path, label=self._member(path)).items():
                    values[f"{name}.{var}"] = value
                    self.parameter_sources_[f"{name}.{var}"] = (unit, path)
            for var, (value, unit) in comp.inline_parameters.items():
                values[f"{name}.{var}"] = value
                self.parameter_sources_[f"{name}.{var}"] = (unit, self.system.path)
        for src in self.system.parameter_sources:
            path = self._resolve(src, "ssv", f'<System name="{self.system.name}"> ParameterBinding')
            for key, (value, unit) in read_ssv(path, label=self._member(path)).items():
                if key.split(".", 1)[0] not in self.system.components:
                    continue  # SSP: names that match no element of the system are ignored
                values[key] = value
                self.parameter_sources_[key] = (unit, path)
        return values

    def _check_parameter_units(self):
        variables = {n: {v.name: v for v in md.modelVariables} for n, md in self.model_descriptions.items()}
        for key, (unit, path) in self.parameter_sources_.items():
            comp, _, var = key.partition(".")
            v = variables[comp].get(var)
            if v is None:
                raise SystemStructureError(f"{self._member(path)}: parameter '{key}': {comp} has no variable '{var}'")
            if unit is not None and v.type == "Real" and (v.unit or "1") != unit:
                raise SystemStructureError(f"{self._member(path)}: parameter '{key}' has unit [{unit}], "
                                           f"the FMU declares [{v.unit}]")

    def reset(self):
        """Free the FMU instances kept between runs (``keep_instances``); the next run instantiates anew."""
        kept, self._kept = self._kept, {}
        self._release(kept, free=True)

    @staticmethod
    def _release(inst: dict, free: bool):
        """Terminate the instances (and free them with ``free``); never raises."""
        for i in inst.values():  # calling FMI functions on a NULL component crashes the host
            if i.state == "initialized":
                try:
                    i.fmu.terminate()
                    i.state = "terminated"
                except Exception:  # noqa: BLE001 - instance may be in an error state
                    i.state = "failed"
            if free and i.state != "created":
                try:
                    i.fmu.freeInstance()
                except Exception:  # noqa: BLE001
                    pass
                i.state = "created"

    def close(self):
        """Free kept FMU instances and remove the unpacked ``.ssp`` (if any); idempotent."""
        self.reset()
        if getattr(self, "_finalizer", None) is not None:
            self._finalizer()  # runs shutil.rmtree once and detaches
            self._finalizer = None
        if getattr(self, "_tmp", None) is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- run ------------------------------------------------------------------
    def run(self, stop_time: float, inputs: Mapping[str, float | Callable[[float], float]],
            record: list[str] | None = None, stop_when: Callable[[dict], bool] | None = None,
            start_values: Mapping[str, float] | None = None, progress=None) -> CoSimResult:
        """Simulate from 0 to ``stop_time`` [s].

        ``inputs`` gives every system input connector a constant or a function
        of time. ``record`` lists ``"Component.variable"`` names (default: all
        component outputs). ``stop_when(values)`` may end the run early.
        ``start_values`` sets component variables before initialisation
        (e.g. ``{"Slider.s0": -0.02}``).
        """
        from .hosting import install_exit_fix
        install_exit_fix()  # PythonFMU 0.7.0 exit-time use-after-free (see l1b2.fmi.runtime)
        sysst = self.system
        missing = [c for c, k in sysst.connectors.items() if k.kind == "input" and c not in inputs]
        if missing:
            raise SimulationError(f"no value given for system input(s) {missing}")
        unknown = [c for c in inputs if c not in sysst.connectors]
        if unknown:
            raise SimulationError(f"{sysst.path}: no system input connector(s) {unknown}")
        inst, self._kept = self._kept, {}
        ok = False
        try:
            for i in inst.values():  # kept from the last run: back to the instantiated state
                i.fmu.reset()
                i.state = "instantiated"
            for name, path in self.fmu_paths.items():
                if name in inst:
                    continue
                md = self.model_descriptions[name]
                unz = extracted(path)
                fmu = _load_slave(path, md, unz, name)
                inst[name] = _Instance(name, fmu, md, unz, {v.name: v for v in md.modelVariables})
                _instantiate(fmu, path)
                inst[name].state = "instantiated"
            self._lookup(inst, record)
            self._initialize(inst, inputs, start_values or {})
            result = self._loop(inst, stop_time, inputs, stop_when, progress)
            ok = True
            return result
        finally:
            keep = ok and self.keep_instances
            self._release(inst, free=not keep)
            if keep:
                self._kept = inst

    def _lookup(self, inst, record):
        """Resolve value references once: per component, its connected inputs and needed outputs."""
        sysst = self.system
        needed_out = {n: set() for n in inst}
        for c in sysst.connections:
            if c.start_element is not None:
                needed_out[c.start_element].add(c.start_connector)
        self.record = list(record) if record is not None else [
            f"{n}.{v.name}" for n, i in inst.items() for v in i.md.modelVariables if v.causality == "output"]
        for r in self.record:
            comp, _, var = r.partition(".")
            if comp not in inst or var not in inst[comp].vars:
                raise SimulationError(f"cannot record '{r}': no such component variable")
            needed_out[comp].add(var)
        self._sources = {}  # (comp, input) -> ("sys", name) or (comp, output)
        for c in sysst.connections:
            if c.end_element is None:
                continue
            self._sources[(c.end_element, c.end_connector)] = (c.start_element, c.start_connector)
        for n, i in inst.items():
            i.in_names = sorted(var for (comp, var) in self._sources if comp == n)
            i.in_vrs = [self._real_vr(i, v) for v in i.in_names]
            i.out_names = sorted(needed_out[n])
            i.out_vrs = [self._real_vr(i, v) for v in i.out_names]
        self.units = {r: (inst[r.split('.')[0]].vars[r.split('.', 1)[1]].unit or "1") for r in self.record}

    @staticmethod
    def _real_vr(i: _Instance, name: str) -> int:
        v = i.vars[name]
        if v.type != "Real":
            raise SystemStructureError(f"{i.name}.{name} is {v.type}; connections must be Real")
        return v.valueReference

    def _set_any(self, i: _Instance, name: str, value):
        v = i.vars.get(name)
        if v is None:
            raise SimulationError(f"{i.name} has no variable '{name}'")
        if v.type == "Real":
            i.fmu.setReal([v.valueReference], [float(value)])
        elif v.type in ("Integer", "Enumeration"):
            i.fmu.setInteger([v.valueReference], [int(value)])
        elif v.type == "Boolean":
            i.fmu.setBoolean([v.valueReference], [bool(value)])
        else:
            raise SimulationError(f"{i.name}.{name}: unsupported type {v.type}")

    def _input_values(self, i: _Instance, t: float, inputs, values) -> list[float]:
        out = []
        for name in i.in_names:
            src_comp, src_var = self._sources[(i.name, name)]
            if src_comp is None:
                x = inputs[src_var]
                out.append(float(x(t) if callable(x) else x))
            else:
                out.append(values[(src_comp, src_var)])
        return out

    def _initialize(self, inst, inputs, start_values):
        for i in inst.values():
            i.fmu.setupExperiment(startTime=0.0)
        reals: dict[str, dict] = {n: {} for n in inst}  # Reals set in one fmi2SetReal per component
        for key, value in list(self.parameters.items()) + list(start_values.items()):
            comp, _, var = key.partition(".")
            if comp not in inst:
                raise SimulationError(f"start value '{key}': no component '{comp}'")
            v = inst[comp].vars.get(var)
            if v is not None and v.type == "Real":
                reals[comp].pop(v.valueReference, None)  # the later value wins, in its place
                reals[comp][v.valueReference] = float(value)
            else:
                self._set_any(inst[comp], var, value)
        for comp, vals in reals.items():
            if vals:
                inst[comp].fmu.setReal(list(vals), list(vals.values()))
        for i in inst.values():
            i.fmu.enterInitializationMode()
        # Initialise in Gauss-Seidel order so each sees its upstream outputs (others: start values)
        self.values = {}
        for n, i in inst.items():
            vals = []
            for name in i.in_names:
                src_comp, src_var = self._sources[(n, name)]
                if src_comp is None:
                    x = inputs[src_var]
                    vals.append(float(x(0.0) if callable(x) else x))
                elif (src_comp, src_var) in self.values:
                    vals.append(self.values[(src_comp, src_var)])
                else:
                    vals.append(float(i.fmu.getReal([i.vars[name].valueReference])[0]))
            i.fmu.setReal(i.in_vrs, vals)
            i.fmu.exitInitializationMode()
            i.state = "initialized"
            for name, val in zip(i.out_names, i.fmu.getReal(i.out_vrs)):
                self.values[(n, name)] = val

    def _pass(self, inst, t, h, inputs, source_values):
        """One Gauss-Seidel pass; inputs from ``source_values`` updated as components step."""
        values = dict(source_values)
        for n, i in inst.items():
            i.fmu.setReal(i.in_vrs, self._input_values(i, t, inputs, values))
            try:
                i.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            except Exception as exc:  # fmpy raises FMICallException on discard/error
                raise SimulationError(f"{n}.doStep at t={t:.6g} s failed ({exc}); see the FMU log above") from None
            for name, val in zip(i.out_names, i.fmu.getReal(i.out_vrs)):
                values[(n, name)] = val
        return values

    def _fast_pass(self, inst, inputs, h):
        """The Gauss-Seidel pass of :meth:`_pass` on buffers made once per run.

        Every value the pass moves (system inputs, then each component's needed
        outputs, in SSD order) has a fixed slot in one list; per component and
        step: one ``fmi2SetReal`` from preallocated ctypes arrays, ``fmi2DoStep``
        and one ``fmi2GetReal`` into a preallocated array copied into the
        component's slots (``fmi2SetReal`` only when a component's inputs changed: an
        FMU holds the values set). Returns ``(step(t), slots, slot of (component, variable))``;
        constant system inputs are converted once, functions of time at every step.
        """
        from fmpy.fmi2 import fmi2Real, fmi2True, fmi2ValueReference
        slot: dict[tuple, int] = {}
        flat: list[float] = []
        timed = []
        for src_comp, src_var in self._sources.values():
            if src_comp is None and (None, src_var) not in slot:
                x = inputs[src_var]
                slot[(None, src_var)] = len(flat)
                flat.append(0.0 if callable(x) else float(x))
                if callable(x):
                    timed.append((len(flat) - 1, x))
        spans = {}
        for n, i in inst.items():
            lo = len(flat)
            for name in i.out_names:
                slot[(n, name)] = len(flat)
                flat.append(float(self.values[(n, name)]))
            spans[n] = (lo, len(flat))
        plan = []
        for n, i in inst.items():
            src = [slot[self._sources[(n, name)]] for name in i.in_names]
            take = operator.itemgetter(*src) if len(src) > 1 else (lambda values, j=src[0] if src else 0: (values[j],))
            nin, nout = len(src), len(i.out_vrs)
            fmu = i.fmu
            # fmpy's wrappers add a Python layer per call (argument logging, status check); without a call
            # logger the ctypes functions they wrap are called directly and the status is checked here
            raw = getattr(fmu, "_functions", None) if getattr(fmu, "fmiCallLogger", None) is None else None
            calls = ((raw["fmi2SetReal"], raw["fmi2DoStep"], raw["fmi2GetReal"]) if raw
                     else (fmu.fmi2SetReal, fmu.fmi2DoStep, fmu.fmi2GetReal))
            plan.append((n, fmu.component, *calls, take if src else None,
                         (fmi2ValueReference * nin)(*i.in_vrs), (fmi2Real * nin)(), nin,
                         (fmi2ValueReference * nout)(*i.out_vrs), (fmi2Real * nout)(), nout, *spans[n]))
        held: dict[str, tuple] = {}

        def step(t):
            for j, x in timed:
                flat[j] = float(x(t))
            for n, comp, set_real, do_step, get_real, take, in_vr, in_val, nin, out_vr, out_val, nout, lo, hi in plan:
                if take is not None:
                    u = take(flat)
                    if u != held.get(n):  # inputs keep their values in the FMU: set them when they change
                        in_val[:] = u
                        if set_real(comp, in_vr, nin, in_val) > FMI2_WARNING:
                            raise SimulationError(f"{n}.setReal at t={t:.6g} s failed; see the FMU log above")
                        held[n] = u
                try:
                    status = do_step(comp, t, h, fmi2True)
                except Exception as exc:  # fmpy's wrapper raises FMICallException on discard/error
                    raise SimulationError(f"{n}.doStep at t={t:.6g} s failed ({exc}); see the FMU log above") from None
                if status > FMI2_WARNING:
                    raise SimulationError(f"{n}.doStep at t={t:.6g} s failed ({FMI2_STATUS.get(status, status)}); "
                                          "see the FMU log above")
                if nout:
                    if get_real(comp, out_vr, nout, out_val) > FMI2_WARNING:
                        raise SimulationError(f"{n}.getReal at t={t:.6g} s failed; see the FMU log above")
                    flat[lo:hi] = out_val

        return step, flat, slot

    def _loop(self, inst, stop_time, inputs, stop_when, progress):
        if not self.iterate:
            return self._loop_fast(inst, stop_time, inputs, stop_when, progress)
        h = self.step_s
        n_steps = int(round(stop_time / h))
        rows = np.empty((n_steps + 1, len(self.record)))
        keys = [tuple(r.split(".", 1)) for r in self.record]
        rows[0] = [self.values[k] for k in keys]
        times = np.arange(n_steps + 1) * h
        coupling = sorted({src for src in self._sources.values() if src[0] is not None})
        # scale of each coupling variable: the largest magnitude so far among the coupling variables of
        # the same unit (a force that is zero up to round-off is measured against the other forces)
        unit = {c: inst[c[0]].vars[c[1]].unit or "1" for c in coupling}
        scale = {c: abs(self.values[c]) for c in coupling}
        last = n_steps
        self.unconverged_steps_ = 0
        for k in range(n_steps):
            t = k * h
            if self.iterate:
                states = {n: i.fmu.getFMUstate() for n, i in inst.items()}
                guess = self.values
                for it in range(self.max_iter):
                    new = self._pass(inst, t, h, inputs, guess)
                    for c in coupling:
                        scale[c] = max(scale[c], abs(new[c]))
                    unit_scale = {}
                    for c in coupling:
                        unit_scale[unit[c]] = max(unit_scale.get(unit[c], 0.0), scale[c])
                    change = max(abs(new[c] - guess[c]) / (abs(new[c]) + unit_scale[unit[c]] + 1e-300)
                                 for c in coupling)
                    if change < self.tol:
                        break
                    if it == self.max_iter - 1:
                        self.unconverged_steps_ += 1
                        break
                    for n, i in inst.items():
                        i.fmu.setFMUstate(states[n])
                    guess = new
                for n, i in inst.items():
                    i.fmu.freeFMUstate(states[n])
                self.iterations_.append(it + 1)
                self.values = new
            else:
                self.values = self._pass(inst, t, h, inputs, self.values)
            rows[k + 1] = [self.values[kk] for kk in keys]
            if progress is not None:
                progress(k + 1, n_steps)
            if stop_when is not None and stop_when({f"{a}.{b}": v for (a, b), v in self.values.items()}):
                last = k + 1
                break
        return self._result(rows, times, last)

    def _loop_fast(self, inst, stop_time, inputs, stop_when, progress):
        """:meth:`_loop` without fixed-point iteration, on :meth:`_fast_pass` (same values, less work per step)."""
        h = self.step_s
        n_steps = int(round(stop_time / h))
        step, flat, slot = self._fast_pass(inst, inputs, h)
        rows = np.empty((n_steps + 1, len(self.record)))
        rec = [slot[tuple(r.split(".", 1))] for r in self.record]
        take = operator.itemgetter(*rec) if len(rec) > 1 else (lambda values, j=rec[0] if rec else 0: (values[j],))
        rows[0] = take(flat) if rec else ()
        times = np.arange(n_steps + 1) * h
        named = [(f"{a}.{b}", j) for (a, b), j in slot.items() if a is not None]
        last = n_steps
        self.unconverged_steps_ = 0
        try:
            for k in range(n_steps):
                step(k * h)
                if rec:
                    rows[k + 1] = take(flat)
                if progress is not None:
                    progress(k + 1, n_steps)
                if stop_when is not None and stop_when({name: flat[j] for name, j in named}):
                    last = k + 1
                    break
        finally:
            self.values = {(a, b): flat[j] for (a, b), j in slot.items() if a is not None}
        return self._result(rows, times, last)

    def _result(self, rows, times, last) -> CoSimResult:
        if self.unconverged_steps_:
            warnings.warn(f"fixed-point iteration did not reach tol={self.tol} within {self.max_iter} "
                          f"iterations in {self.unconverged_steps_} of {len(self.iterations_)} steps",
                          RuntimeWarning, stacklevel=4)
        df = pd.DataFrame(rows[:last + 1], columns=self.record)
        df.insert(0, "time", times[:last + 1])
        units = {"time": "s", **self.units}
        return CoSimResult(df, units)
