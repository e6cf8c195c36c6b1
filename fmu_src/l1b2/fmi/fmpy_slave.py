"""One co-simulation instance of an FMU (FMI 2.0 or 3.0) through fmpy's low-level API, freed on every path.

The explicit master loop of FMPy's ``examples/custom_input.py``: value references looked up once,
parameters, Boolean parameters and the first inputs set before initialisation, and ``freeInstance``
always called (``terminate`` first when the block ends without an exception).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping


@dataclass(frozen=True)
class FmpySlave:
    """An initialised fmpy slave with its version's accessors.

    Attributes
    ----------
    fmu : fmpy.fmi2.FMU2Slave or fmpy.fmi3.FMU3Slave
        The instance (its ``doStep``, ``component`` and ctypes ``_functions`` are fmpy's).
    vr : dict
        Variable name -> value reference.
    fmi3 : bool
        True for an FMI 3.0 FMU.
    set_real, get_real, set_bool : callable
        ``setReal``/``getReal``/``setBoolean`` (FMI 2.0) or ``setFloat64``/``getFloat64``/``setBoolean`` (FMI 3.0),
        taking value references.
    """

    fmu: Any
    vr: dict
    fmi3: bool
    set_real: Callable
    get_real: Callable
    set_bool: Callable

    def refs(self, names) -> list[int]:
        """Value references of ``names`` (a KeyError names the first unknown variable)."""
        return [self.vr[n] for n in names]

    def set(self, values: Mapping[str, float]) -> None:
        """Set Real (Float64) variables by name."""
        if values:
            self.set_real(self.refs(values), [float(v) for v in values.values()])

    def get(self, names) -> list[float]:
        """Real (Float64) variables by name, in the order of ``names``."""
        return list(self.get_real(self.refs(names)))

    def step(self, t_s: float, h_s: float) -> None:
        """One communication step from ``t_s`` of length ``h_s`` [s] (fmpy raises on an error status)."""
        self.fmu.doStep(t_s, h_s)


@contextmanager
def open_slave(path: str | Path, *, unzipdir: str | None = None, instance_name: str = "l1b2",
               start_time_s: float = 0.0, params: Mapping[str, float] | None = None,
               booleans: Mapping[str, bool] | None = None,
               inputs: Mapping[str, float] | None = None) -> Iterator[FmpySlave]:
    """Instantiate the FMU at ``path``, set ``params``, ``booleans`` and ``inputs``, initialise it at
    ``start_time_s`` [s] and yield an :class:`FmpySlave`; terminate it when the block ends normally and free
    it on every path.

    ``unzipdir`` is an already extracted copy of the FMU (extracted here when None).
    """
    from fmpy import extract, read_model_description
    md = read_model_description(str(path))
    unz = unzipdir if unzipdir is not None else extract(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmi3 = md.fmiVersion.startswith("3")
    kw = dict(guid=md.guid, unzipDirectory=unz, modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName=instance_name)
    if fmi3:
        from fmpy.fmi3 import FMU3Slave
        fmu = FMU3Slave(**kw)
        fmu.instantiate()
        slave = FmpySlave(fmu, vr, True, fmu.setFloat64, fmu.getFloat64, fmu.setBoolean)
    else:
        from fmpy.fmi2 import FMU2Slave
        fmu = FMU2Slave(**kw)
        fmu.instantiate()
        slave = FmpySlave(fmu, vr, False, fmu.setReal, fmu.getReal, fmu.setBoolean)
    try:
        if not fmi3:
            fmu.setupExperiment(startTime=start_time_s)
        slave.set(params or {})
        if booleans:
            slave.set_bool(slave.refs(booleans), [bool(b) for b in booleans.values()])
        slave.set(inputs or {})
        if fmi3:
            fmu.enterInitializationMode(startTime=start_time_s)
        else:
            fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        yield slave
        fmu.terminate()
    finally:
        fmu.freeInstance()
