"""Generic pythonfmu slave around a co-simulation block (:mod:`l1b2.blocks`).

A slave script only names its block class and its parameter section; this
base registers every declared variable (parameters, inputs, outputs and the
continuous states as ``local`` variables, so get/set FMU state captures
them) with getters and setters into the block.

Error handling (PythonFMU 0.7.0 behaviour, verified): a Python exception that
escapes an FMI callback becomes ``fmi2Fatal`` and leaves a dangling instance
that can crash the host later. So no callback here lets an exception out:
setters only store values; problems (non-finite or out-of-range inputs,
invalid parameters) are logged with status ``fmi2Error`` and ``do_step``
returns False, which the host sees as ``fmi2Discard`` with the message in its
log, and the instance stays usable until the host frees it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

from .params import DriverParams, InterfaceParams, SliderParams, StatorParams, load_motor

#: written next to this module into the bundled package by build_fmu.py
DEFAULTS_FILE = Path(__file__).with_name("_fmu_defaults.json")
_SECTION_CLASSES = {"driver": DriverParams, "stator": StatorParams, "interface": InterfaceParams,
                    "slider": SliderParams}


def default_parameters(section: str):
    """Start values of a subsystem's parameters: the reference motor baked in at build time."""
    cls = _SECTION_CLASSES[section]
    if DEFAULTS_FILE.exists():
        values = json.loads(DEFAULTS_FILE.read_text())[section]
        return cls(**values)
    return getattr(load_motor(), section)


_CAUSALITY = {"input": Fmi2Causality.input, "output": Fmi2Causality.output,
              "parameter": Fmi2Causality.parameter, "local": Fmi2Causality.local}
_VARIABILITY = {"continuous": Fmi2Variability.continuous, "fixed": Fmi2Variability.fixed,
                "tunable": Fmi2Variability.tunable, "discrete": Fmi2Variability.discrete}
_TYPES = {"Real": (Real, float), "Integer": (Integer, int), "Boolean": (Boolean, bool)}


class BlockSlave(Fmi2Slave):
    """Fmi2Slave exposing a :class:`l1b2.blocks.Block`."""

    BLOCK = None       # the Block subclass
    SECTION = ""       # parameter section of MotorParams
    author = "L1B2 USM tool team"
    license = "MIT"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        params = default_parameters(self.SECTION)
        self.block = self.BLOCK(params)
        self._failed = None
        for var in self.BLOCK.variables(params):
            vtype, conv = _TYPES[var.type]
            kw = dict(causality=_CAUSALITY[var.causality], description=var.description,
                      getter=self._getter(var.name, conv), setter=self._setter(var.name, conv))
            if var.causality in ("parameter", "input", "local"):
                kw["variability"] = _VARIABILITY[var.variability]
            self.register_variable(vtype(var.name, **kw))

    def _getter(self, name, conv):
        return lambda: conv(getattr(self.block, name))

    def _setter(self, name, conv):
        def set_value(value):
            try:
                setattr(self.block, name, conv(value))
            except (TypeError, ValueError) as exc:  # never raise out of a callback
                self._fail(f"cannot set {name} to {value!r}: {exc}")
        return set_value

    def _fail(self, message: str):
        self._failed = message
        self.log(message, Fmi2Status.error)

    def exit_initialization_mode(self):
        try:
            self.block.initialize()
        except Exception as exc:  # noqa: BLE001 - reported through the FMI logger
            self._fail(f"{type(self).__name__}: initialisation failed: {exc}")

    def do_step(self, current_time, step_size):
        if self._failed is not None:
            self.log(f"{type(self).__name__}: refusing to step after an error: {self._failed}", Fmi2Status.error)
            return False
        if not (math.isfinite(step_size) and step_size > 0):
            self._fail(f"{type(self).__name__}: invalid communication step {step_size!r} s at t={current_time}")
            return False
        try:
            self.block.do_step(current_time, step_size)
            return True
        except Exception as exc:  # noqa: BLE001
            self._fail(f"{type(self).__name__}: step at t={current_time} s failed: {exc}")
            return False

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        try:
            self.block.refresh()
        except Exception as exc:  # noqa: BLE001
            self._fail(f"{type(self).__name__}: restoring the FMU state failed: {exc}")
