"""In-process co-simulation engine: the four blocks wired by hand, no FMUs.

:class:`InProcessMotor` runs the same communication-step algorithm as the
FMU master (Gauss-Seidel in the causal order driver -> stator -> interface
-> slider, inputs held over a step) calling the physics through the blocks
directly: the reference against which the fmpy co-simulation is tested.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..physics.params import MotorParams
from .blocks import make_blocks, variable_unit
from .result import CoSimResult

# ---------------------------------------------------------------------------
# In-process time simulation (reference for the FMU master)
# ---------------------------------------------------------------------------

#: variables recorded by :class:`InProcessMotor`, named as in the FMU master ("Component.variable")
RECORDED = ("Driver.V0", "Stator.U_l", "Stator.U_w", "Stator.delta", "Stator.F_p", "Interface.F_d",
            "Interface.phi_c", "Interface.stick_fraction", "Slider.v", "Slider.s")


class InProcessMotor:
    """The four blocks wired by hand and stepped in Gauss-Seidel order, without FMUs.

    The wiring is written out here on purpose (not read from the SSD): it is
    the independent reference the SSD-driven fmpy master is tested against.
    Inputs are held over each communication step of length ``h_s``; any input
    may be a function of time.
    """

    INPUTS = ("V_s", "duty", "f_s", "T", "direction", "m_load")

    def __init__(self, mp: MotorParams, h_s: float = 2e-4, pure_slip: bool = False):
        self.mp = mp
        self.h = float(h_s)
        self.b = make_blocks(mp, pure_slip=pure_slip)
        self._inputs: dict = {}
        self._constant = None
        self._driven = None

    @property
    def inputs(self) -> dict:
        """The system inputs: constants or functions of time (assigning a new dict is allowed)."""
        return self._inputs

    @inputs.setter
    def inputs(self, values: dict):
        self._inputs = dict(values)
        self._driven = None  # the constant inputs the driver last stepped with (None: step it)
        # all constant: converted once, not at every step
        self._constant = (None if any(callable(v) for v in self._inputs.values())
                          else {k: float(v) for k, v in self._inputs.items()})

    def _inputs_at(self, t):
        if self._constant is not None:
            return self._constant
        return {k: float(v(t) if callable(v) else v) for k, v in self._inputs.items()}

    def initialize(self, *, V_s, duty=1.0, f_s=48500.0, T=25.0, direction=1.0, m_load=0.0,
                   s0: float = 0.0, v0: float = 0.0):
        """Set the system inputs (constants or functions of time) and initialise the blocks."""
        self.inputs = dict(V_s=V_s, duty=duty, f_s=f_s, T=T, direction=direction, m_load=m_load)
        u = self._inputs_at(0.0)
        d, stt, itf_, sl = (self.b[k] for k in ("Driver", "Stator", "Interface", "Slider"))
        d.V_s, d.duty, d.f_s, d.T = u["V_s"], u["duty"], u["f_s"], u["T"]
        d.initialize()
        stt.V0, stt.omega, stt.direction, stt.T, stt.s = d.V0, d.omega, u["direction"], u["T"], s0
        stt.initialize()
        itf_.U_l, itf_.U_w, itf_.delta, itf_.omega, itf_.v, itf_.F_p = (
            stt.U_l, stt.U_w, stt.delta, d.omega, v0, stt.F_p)
        itf_.initialize()
        sl.s0, sl.v0, sl.m_load, sl.F_d, sl.F_p = s0, v0, u["m_load"], itf_.F_d, stt.F_p
        sl.initialize()
        self.t = 0.0

    def step(self):
        b = self.b
        d, stt, itf_, sl = b["Driver"], b["Stator"], b["Interface"], b["Slider"]
        t, h = self.t, self.h
        u = self._inputs_at(t)
        if u is not self._driven:  # the driver is algebraic: with the same constant inputs its outputs stand
            d.V_s, d.duty, d.f_s, d.T = u["V_s"], u["duty"], u["f_s"], u["T"]
            d.do_step(t, h)
            self._driven = u if u is self._constant else None
        stt.V0, stt.omega, stt.s, stt.direction, stt.T = d.V0, d.omega, sl.s, u["direction"], u["T"]
        stt.F_N1_sin, stt.F_N1_cos, stt.F_T1_sin, stt.F_T1_cos = (
            itf_.F_N1_sin, itf_.F_N1_cos, itf_.F_T1_sin, itf_.F_T1_cos)
        stt.do_step(t, h)
        itf_.U_l, itf_.U_w, itf_.delta, itf_.omega, itf_.v, itf_.F_p = (
            stt.U_l, stt.U_w, stt.delta, d.omega, sl.v, stt.F_p)
        itf_.do_step(t, h)
        sl.F_d, sl.F_p, sl.m_load = itf_.F_d, stt.F_p, u["m_load"]
        sl.do_step(t, h)
        self.t = t + h

    def value(self, name: str) -> float:
        comp, var = name.split(".")
        return float(getattr(self.b[comp], var))

    def run(self, t_end: float, record: tuple[str, ...] = RECORDED, until=None):
        """Step to ``t_end`` (or until ``until(self)`` is true); the recorded series incl. ``time``.

        Returns the same :class:`~l1b2.cosim.result.CoSimResult` as the fmpy
        master (``res["Slider.v"]`` is a numpy array; units from the blocks).
        """
        n = int(round(t_end / self.h))
        out = {k: [self.value(k)] for k in record}
        times = [self.t]
        for _ in range(n):
            self.step()
            times.append(self.t)
            for k in record:
                out[k].append(self.value(k))
            if until is not None and until(self):
                break
        cols = {"time": np.array(times)}
        cols.update({k: np.array(v) for k, v in out.items()})
        units = {"time": "s"}
        units.update({k: variable_unit(*k.split(".")) for k in record})
        return CoSimResult(pd.DataFrame(cols), units)
