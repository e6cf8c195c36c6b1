"""Adapter between a pythonfmu slave and a co-simulation block (:mod:`l1b2.cosim.blocks`).

A slave script only names its block class and its parameter section; the
adapter registers every declared variable (parameters, inputs, outputs and the
continuous states as ``local`` variables, so get/set FMU state captures
them) with getters and setters into the block.

Error handling (PythonFMU 0.7.0 behaviour, verified): a Python exception that
escapes an FMI callback becomes ``fmi2Fatal`` and leaves a dangling instance
that can crash the host later. So no callback here lets an exception out:
setters only store values; problems (non-finite or out-of-range inputs,
invalid parameters) are logged with status ``fmi2Error`` and ``do_step``
returns False, which the host sees as ``fmi2Discard`` with the message in its
log, and the instance stays usable until the host frees it.

Initialization Mode (FMI 2.0, 3.2.3): outputs are initial unknowns
(``initial="calculated"``), so ``fmi2GetReal`` between
``fmi2EnterInitializationMode`` and ``fmi2ExitInitializationMode`` returns
them computed from the current parameters and inputs. Masters that
propagate start values through the connections in that mode (libcosim runs
N get/set sweeps before it exits initialisation) depend on it; an input that
is still provisional there (e.g. 0 rad/s) is not an error until
``fmi2ExitInitializationMode``.

FMI state machine (FMI 2.0, 4.2.4): the adapter tracks the mode of the
instance (instantiated -> initialization mode -> stepping -> terminated). A
call in the wrong mode - ``fmi2DoStep`` before ``fmi2ExitInitializationMode``
or after ``fmi2Terminate``, ``fmi2ExitInitializationMode`` without
``fmi2EnterInitializationMode``, entering initialization mode twice - has
no effect and logs one line with status ``fmi2Error`` naming the call and
the mode. PythonFMU 0.7.0's ``fmi2DoStep`` can only return ``fmi2OK``,
``fmi2Discard`` (``do_step`` returned False) or ``fmi2Fatal`` (``do_step``
raised, which also frees the Python slave under the host's feet), so a
refused step is reported as ``fmi2Discard``, the same in every FMU; the
other calls return ``fmi2OK`` with the error in the log.

FMU state: ``fmi2GetFMUstate`` captures every variable and the error flag
(:meth:`BlockAdapter.fmu_state`), so ``fmi2SetFMUstate`` with a state taken
before a discarded step makes the instance usable again, and restoring a
state taken after an error brings the error back. The mode is not part of
the state (restoring never moves the instance back into initialization mode).
"""

from __future__ import annotations

import json
import math
import operator
from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real  # noqa: F401
from pythonfmu.enums import Fmi2Status

from ..cosim.blocks import motor_defaults
from ..physics.params import load_motor

#: file holding the start values, written by l1b2.fmi.build into each FMU's resources folder
DEFAULTS_FILE = "_fmu_defaults.json"


def load_defaults(resources: str | None = None) -> dict:
    """Start values of an FMU: its own ``resources/_fmu_defaults.json``, else the reference motor.

    Each FMU carries the values it was built with and every instance reads
    them from its own resources folder: the bundled package may be shared
    with another FMU of the same version in the process.
    """
    if resources:
        path = Path(resources) / DEFAULTS_FILE
        if path.exists():
            return json.loads(path.read_text())
    return motor_defaults(load_motor())


_CAUSALITY = {"input": Fmi2Causality.input, "output": Fmi2Causality.output,
              "parameter": Fmi2Causality.parameter, "local": Fmi2Causality.local}
_VARIABILITY = {"continuous": Fmi2Variability.continuous, "fixed": Fmi2Variability.fixed,
                "tunable": Fmi2Variability.tunable, "discrete": Fmi2Variability.discrete}
_TYPES = {"Real": (Real, float), "Integer": (Integer, int), "Boolean": (Boolean, bool)}


#: key of the adapter's own entries in an FMU state (beside the variables; see BlockAdapter.fmu_state)
STATE_KEY = "__l1b2_adapter__"
#: modes of an instance (FMI 2.0 co-simulation state machine, reduced to what the FMUs distinguish)
INSTANTIATED, INITIALIZATION, STEPPING, TERMINATED = "instantiated", "initialization mode", "stepping", "terminated"
_WHEN = {INSTANTIATED: "before initialisation", INITIALIZATION: "in initialization mode",
         STEPPING: "after initialisation", TERMINATED: "after fmi2Terminate"}
_HINT = {
    INSTANTIATED: "call fmi2EnterInitializationMode and fmi2ExitInitializationMode first",
    INITIALIZATION: "call fmi2ExitInitializationMode first",
    STEPPING: "the instance is already initialised",
    TERMINATED: "call fmi2Reset or instantiate the FMU again",
}


def safe_text(message: str) -> str:
    """``message`` as text PythonFMU 0.7.0 can pass to the host (it crashes on text that is not valid UTF-8)."""
    return str(message).encode("utf-8", "replace").decode("utf-8")


class BlockAdapter:
    """Exposes a :class:`l1b2.cosim.blocks.Block` through the ``Fmi2Slave`` that owns it.

    The slave scripts keep the literal form ``class Name(Fmi2Slave):`` that
    PythonFMU's loader looks for (its 0.7.0 binary crashes on the second
    instantiation in a process when the slave class inherits through an
    imported intermediate class), and delegate here.
    """

    def __init__(self, slave: Fmi2Slave, block_cls):
        self.slave = slave
        params = block_cls.params_from_defaults(load_defaults(slave.resources))
        self.block = block_cls(params)
        self.failed = None
        self.mode = INSTANTIATED
        self.in_initialization_mode = False
        self._outputs_stale = True
        self._plain: dict[int, str] = {}   # value reference -> attribute, for the fast get_real/set_real
        self._plans: dict[tuple, object] = {}
        self._decl: dict[int, object] = {}  # value reference -> the block's Var declaration
        self._set_checks: dict[tuple, tuple] = {}
        for var in block_cls.variables(params):
            vtype, conv = _TYPES[var.type]
            self._decl[len(slave.vars)] = var  # PythonFMU numbers the variables in this order
            if var.type == "Real" and var.causality != "parameter" and "." not in var.name:
                self._plain[len(slave.vars)] = var.name
            getter = self._output_getter(var.name, conv) if var.causality == "output" else self._getter(var.name, conv)
            kw = dict(causality=_CAUSALITY[var.causality], description=var.description,
                      getter=getter, setter=self._setter(var.name, conv))
            if var.causality in ("parameter", "input", "local"):
                kw["variability"] = _VARIABILITY[var.variability]
            slave.register_variable(vtype(var.name, **kw))
        # the slave scripts leave enter_initialization_mode and terminate to Fmi2Slave (no-ops): take them over
        slave.enter_initialization_mode = self.enter_initialization_mode
        slave.setup_experiment = self.setup_experiment
        slave.terminate = self.terminate
        # PythonFMU 0.7.0 exit-time use-after-free: make exit() empty this library's PyState pointer first
        from ..cosim.hosting import register_exit_fix_in_fmu
        register_exit_fix_in_fmu(slave.resources, slave.modelName)

    def _getter(self, name, conv):
        return lambda: conv(self.block.get(name))

    def _output_getter(self, name, conv):
        def get_value():
            if self.in_initialization_mode and self._outputs_stale:
                self._outputs_stale = False
                try:
                    self.block.initialize()
                except Exception:  # noqa: BLE001 - inputs may be provisional; checked at exit
                    pass
            return conv(self.block.get(name))
        return get_value

    def _setter(self, name, conv):
        def set_value(value):
            self._outputs_stale = True
            try:
                self.block.set(name, conv(value))
            except Exception as exc:  # noqa: BLE001 - never raise out of a callback
                self.fail(f"cannot set {name} to {value!r}: {exc}")
        return set_value

    # -- fmi2GetReal / fmi2SetReal -----------------------------------------------------
    # PythonFMU 0.7.0's get_real/set_real look every variable up, check its type and call
    # its getter/setter closure. Inputs, outputs and states of a block are plain float
    # attributes (blocks.py), so a list of them is read with one attrgetter, planned once
    # per list of value references; anything else takes PythonFMU's general path.
    def _plan(self, vrs: tuple):
        if len(self._plans) >= 64:
            self._plans.clear()
        names = [self._plain.get(vr) for vr in vrs]
        plan = None
        if names and None not in names:
            plan = (operator.attrgetter(*names) if len(names) > 1
                    else (lambda block, n=names[0]: (getattr(block, n),)), names)
        self._plans[vrs] = plan
        return plan

    def get_real(self, vrs) -> list:
        """``fmi2GetReal`` (same values as ``Fmi2Slave.get_real``, which serves initialization mode).

        An unknown value reference or one of another type is logged with
        status ``fmi2Error`` and gives NaN for every value (never an exception:
        see the module docstring).
        """
        try:
            if not self.in_initialization_mode:
                key = tuple(vrs)
                plan = self._plans[key] if key in self._plans else self._plan(key)
                if plan is not None:
                    return list(plan[0](self.block))
            problem = self._access_problem(vrs, "Real", "fmi2GetReal")
            if problem:
                self.log_error(problem)
                return [math.nan] * len(vrs)
            return Fmi2Slave.get_real(self.slave, vrs)
        except Exception as exc:  # noqa: BLE001 - never raise out of a callback
            self.log_error(f"{self.slave.modelName}: fmi2GetReal failed: {exc}")
            return [math.nan] * len(vrs)

    def get_other(self, kind: str, vrs) -> list:
        """``fmi2GetInteger`` / ``fmi2GetBoolean`` / ``fmi2GetString`` (``kind``), checked like :meth:`get_real`."""
        blank = {"Integer": 0, "Boolean": False, "String": ""}[kind]
        try:
            problem = self._access_problem(vrs, kind, f"fmi2Get{kind}")
            if problem:
                self.log_error(problem)
                return [blank] * len(vrs)
            return getattr(Fmi2Slave, f"get_{kind.lower()}")(self.slave, vrs)
        except Exception as exc:  # noqa: BLE001 - never raise out of a callback
            self.log_error(f"{self.slave.modelName}: fmi2Get{kind} failed: {exc}")
            return [blank] * len(vrs)

    def set_real(self, vrs, values):
        """``fmi2SetReal`` (same effect as ``Fmi2Slave.set_real`` through the setters), refused as a whole
        (one ``fmi2Error`` line, nothing set) for :meth:`_set_problem`'s reasons."""
        try:
            problem = self._set_problem(vrs, values, "Real")
            if problem:
                self.log_error(problem)
                return
            key = tuple(vrs)
            plan = self._plans[key] if key in self._plans else self._plan(key)
            if plan is None:
                Fmi2Slave.set_real(self.slave, vrs, values)
                return
            self._outputs_stale = True
            block = self.block
            for name, value in zip(plan[1], values):
                setattr(block, name, float(value))
        except Exception as exc:  # noqa: BLE001 - never raise out of a callback
            self.log_error(f"{self.slave.modelName}: fmi2SetReal failed: {exc}")

    def set_other(self, kind: str, vrs, values):
        """``fmi2SetInteger`` / ``fmi2SetBoolean`` / ``fmi2SetString`` (``kind``), checked like :meth:`set_real`."""
        try:
            problem = self._set_problem(vrs, values, kind)
            if problem:
                self.log_error(problem)
                return
            self._outputs_stale = True
            getattr(Fmi2Slave, f"set_{kind.lower()}")(self.slave, vrs, values)
        except Exception as exc:  # noqa: BLE001 - never raise out of a callback
            self.log_error(f"{self.slave.modelName}: fmi2Set{kind} failed: {exc}")

    def _access_problem(self, vrs, kind: str, call: str) -> str | None:
        """Why ``call`` cannot read or write ``vrs`` as ``kind`` (unknown reference, other type), or None."""
        for vr in vrs:
            var = self._decl.get(vr)
            if var is None:
                return (f"{self.slave.modelName}: {call}: unknown value reference {vr} (this FMU has 0 to "
                        f"{len(self._decl) - 1}); nothing done")
            if var.type != kind:
                return (f"{self.slave.modelName}: {call}: value reference {vr} ({var.name}) is a {var.type}, "
                        f"not a {kind}; nothing done")
        return None

    def _set_problem(self, vrs, values, kind: str) -> str | None:
        """Why an ``fmi2Set<kind>`` of ``values`` at ``vrs`` must be refused (FMI 2.0, 3.2.3), or None.

        Refused: an unknown reference or one of another type; an output (the
        FMU computes it); a ``fixed`` parameter after
        ``fmi2ExitInitializationMode``; a parameter value that is not finite or
        outside the parameter's declared min/max. Inputs may be non-finite
        here: the step that would use them is refused (``fmi2Discard``) with
        the input named.
        """
        key = (tuple(vrs), kind, self.mode)
        checked = self._set_checks.get(key)
        if checked is None:
            call = f"fmi2Set{kind}"
            problem = self._access_problem(vrs, kind, call)
            params = []
            for i, vr in enumerate(vrs):
                if problem:
                    break
                var = self._decl[vr]
                if var.causality == "output":
                    problem = (f"{self.slave.modelName}: {call}: {var.name} is an output, computed by the FMU: it "
                               "cannot be set; nothing done")
                elif var.causality == "parameter":
                    if var.variability == "fixed" and self.mode in (STEPPING, TERMINATED):
                        problem = (f"{self.slave.modelName}: {call}: {var.name} is a fixed parameter: it can only "
                                   "be set before fmi2ExitInitializationMode (fmi2Reset to change it); nothing done")
                    params.append((i, var))
            checked = (problem, tuple(params))
            if len(self._set_checks) >= 256:
                self._set_checks.clear()
            self._set_checks[key] = checked
        problem, params = checked
        if problem:
            return problem
        if len(values) < len(vrs):
            return f"{self.slave.modelName}: fmi2Set{kind}: {len(vrs)} references but {len(values)} values"
        for i, var in params:
            value = values[i]
            if kind != "Real" or not isinstance(value, (int, float)):
                continue
            where = f"{self.slave.modelName}: fmi2SetReal: parameter {var.name} [{var.unit or '1'}] = {value!r}"
            if not math.isfinite(value):
                return f"{where} is not finite; the value is unchanged"
            if (var.min is not None and value < var.min) or (var.max is not None and value > var.max):
                return f"{where} is outside its declared range [{var.min}, {var.max}]; the value is unchanged"
        return None

    def log_error(self, message: str):
        """One line with status ``fmi2Error`` in the FMU log."""
        self.slave.log(safe_text(message), Fmi2Status.error)

    def fail(self, message: str):
        self.failed = safe_text(message)
        self.log_error(message)

    def refused(self, call: str, allowed: tuple[str, ...]) -> bool:
        """True (and one ``fmi2Error`` log line) when ``call`` is not allowed in the current mode."""
        if self.mode in allowed:
            return False
        self.log_error(f"{self.slave.modelName}: {call} called {_WHEN[self.mode]} (mode '{self.mode}', FMI 2.0 "
                       f"allows it only in {' or '.join(repr(m) for m in allowed)}): {_HINT[self.mode]}; "
                       "the call has no effect")
        return True

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        """``fmi2SetupExperiment``: blocks that use the FMU's own time (``set_start_time``) learn its start."""
        if self.refused("fmi2SetupExperiment", (INSTANTIATED,)):
            return
        if hasattr(self.block, "set_start_time"):
            try:
                self.block.set_start_time(float(start_time))
            except (TypeError, ValueError) as exc:  # never raise out of a callback
                self.fail(f"invalid start time {start_time!r}: {exc}")

    def enter_initialization_mode(self):
        if self.refused("fmi2EnterInitializationMode", (INSTANTIATED,)):
            return
        self.mode = INITIALIZATION
        self.in_initialization_mode = True
        self._outputs_stale = True

    def exit_initialization_mode(self):
        if self.refused("fmi2ExitInitializationMode", (INITIALIZATION,)):
            return
        self.mode = STEPPING
        self.in_initialization_mode = False
        try:
            self.block.initialize()
        except Exception as exc:  # noqa: BLE001 - reported through the FMI logger
            self.fail(f"{self.slave.modelName}: initialisation failed: {exc}")

    def terminate(self):
        self.mode = TERMINATED
        self.in_initialization_mode = False

    def do_step(self, current_time, step_size) -> bool:
        """``True``: step done (``fmi2OK``); ``False``: step refused (``fmi2Discard``, reason in the log)."""
        name = self.slave.modelName
        if self.refused("fmi2DoStep", (STEPPING,)):
            return False
        if self.failed is not None:
            self.log_error(f"{name}: refusing to step after an error: {self.failed} (restore an FMU state taken "
                           "before the error with fmi2SetFMUstate, or fmi2Reset)")
            return False
        if not (math.isfinite(step_size) and step_size > 0):
            self.fail(f"{name}: invalid communication step {step_size!r} s at t={current_time}")
            return False
        limit = float(getattr(self.block, "MAX_STEP_S", math.inf))
        if step_size > limit:  # not an error of the instance: a smaller step is accepted
            self.log_error(f"{name}: communication step {step_size!r} s at t={current_time} s is above this FMU's "
                           f"maximum {limit!r} s (maxCommunicationStepSize in modelDescription.xml); step refused, "
                           "take smaller steps")
            return False
        try:
            self.block.do_step(current_time, step_size)
            return True
        except Exception as exc:  # noqa: BLE001
            self.fail(f"{name}: step at t={current_time} s failed: {exc}")
            return False

    # -- FMU state (fmi2GetFMUstate / fmi2SetFMUstate / (de)serialisation) ----------
    def fmu_state(self, variables: dict) -> dict:
        """The FMU state: ``variables`` (name -> value, from ``Fmi2Slave``) plus the error flag and the model name.

        JSON-serialisable, as PythonFMU's ``fmi2SerializeFMUstate`` needs.
        """
        return {**variables, STATE_KEY: {"failed": self.failed, "model": self.slave.modelName}}

    def get_state(self, get_variables) -> dict:
        """``fmi2GetFMUstate``: :meth:`fmu_state` of ``get_variables()``; never raises (an empty state on failure)."""
        try:
            return self.fmu_state(get_variables())
        except Exception as exc:  # noqa: BLE001 - never raise out of a callback
            self.log_error(f"{self.slave.modelName}: fmi2GetFMUstate failed: {exc}")
            return {}

    def set_state(self, state, set_variables):
        """``fmi2SetFMUstate``: a state of this model is restored; anything else is refused with ``fmi2Error``."""
        own = state.get(STATE_KEY) if isinstance(state, dict) else None
        if not isinstance(own, dict) or own.get("model") != self.slave.modelName:
            owner = own.get("model") if isinstance(own, dict) else None
            self.log_error(f"{self.slave.modelName}: fmi2SetFMUstate: the state is not one of this FMU"
                           + (f" (it is a state of {owner})" if owner else "") + "; the instance is unchanged")
            return
        try:
            set_variables(self.before_state_restore(state))
            self.after_state_restore()
        except Exception as exc:  # noqa: BLE001 - never raise out of a callback
            self.fail(f"{self.slave.modelName}: fmi2SetFMUstate failed: {exc}")

    def before_state_restore(self, state: dict) -> dict:
        """Take the error flag from ``state``; return the variables (a copy: the host may restore it again)."""
        state = dict(state)
        own = state.pop(STATE_KEY, None)
        if isinstance(own, dict) and "failed" in own:
            failed = own["failed"]
            self.failed = None if failed is None else safe_text(failed)
        return state

    def after_state_restore(self):
        self._outputs_stale = True
        if self.mode != STEPPING:
            return  # nothing computed yet: fmi2ExitInitializationMode initialises from the restored values
        try:
            self.block.refresh()
        except Exception as exc:  # noqa: BLE001
            # the state was restored as asked (e.g. one taken after a non-finite input): the next step is
            # refused with this message; the restore itself is only a warning
            self.failed = safe_text(f"{self.slave.modelName}: the restored FMU state cannot be stepped: {exc}")
            self.slave.log(self.failed, Fmi2Status.warning)
