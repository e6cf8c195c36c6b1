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
"""

from __future__ import annotations

import json
import math
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
        self.in_initialization_mode = False
        self._outputs_stale = True
        for var in block_cls.variables(params):
            vtype, conv = _TYPES[var.type]
            getter = self._output_getter(var.name, conv) if var.causality == "output" else self._getter(var.name, conv)
            kw = dict(causality=_CAUSALITY[var.causality], description=var.description,
                      getter=getter, setter=self._setter(var.name, conv))
            if var.causality in ("parameter", "input", "local"):
                kw["variability"] = _VARIABILITY[var.variability]
            slave.register_variable(vtype(var.name, **kw))
        # the slave scripts leave enter_initialization_mode to Fmi2Slave (a no-op): take it over here
        slave.enter_initialization_mode = self.enter_initialization_mode
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
            except (TypeError, ValueError) as exc:  # never raise out of a callback
                self.fail(f"cannot set {name} to {value!r}: {exc}")
        return set_value

    def fail(self, message: str):
        self.failed = message
        self.slave.log(message, Fmi2Status.error)

    def enter_initialization_mode(self):
        self.in_initialization_mode = True
        self._outputs_stale = True

    def exit_initialization_mode(self):
        self.in_initialization_mode = False
        try:
            self.block.initialize()
        except Exception as exc:  # noqa: BLE001 - reported through the FMI logger
            self.fail(f"{self.slave.modelName}: initialisation failed: {exc}")

    def do_step(self, current_time, step_size) -> bool:
        name = self.slave.modelName
        if self.failed is not None:
            self.slave.log(f"{name}: refusing to step after an error: {self.failed}", Fmi2Status.error)
            return False
        if not (math.isfinite(step_size) and step_size > 0):
            self.fail(f"{name}: invalid communication step {step_size!r} s at t={current_time}")
            return False
        try:
            self.block.do_step(current_time, step_size)
            return True
        except Exception as exc:  # noqa: BLE001
            self.fail(f"{name}: step at t={current_time} s failed: {exc}")
            return False

    def after_state_restore(self):
        try:
            self.block.refresh()
        except Exception as exc:  # noqa: BLE001
            self.fail(f"{self.slave.modelName}: restoring the FMU state failed: {exc}")
