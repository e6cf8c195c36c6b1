"""In-process co-simulation engine: the four blocks wired by hand, no FMUs.

:class:`InProcessMotor` runs the same communication-step algorithm as the
FMU master (Gauss-Seidel in the causal order driver -> stator -> interface
-> slider, inputs held over a step) calling the physics through the blocks
directly: the reference against which the fmpy co-simulation is tested.

With the compiled kernels (:mod:`l1b2.physics.jit`) the steps run through
:class:`FusedSteps`: the state of the four blocks is copied into one vector
and advanced by :func:`l1b2.physics.coupled.motor_substeps` compiled by
numba, the blocks' operations in the blocks' order with the same numbers
(tests/test_fused.py), and copied back whenever a block variable is needed
that the vector does not hold. ``InProcessMotor(..., fused=False)`` steps
the blocks one after the other.
"""

from __future__ import annotations

import math
import operator

import numpy as np
import pandas as pd

from ..errors import SimulationError
from ..physics import coupled as cp
from ..physics import stator as st
from ..physics.jit import jit_status
from ..physics.params import MotorParams
from .blocks import SliderBlock, StatorBlock, make_blocks, variable_unit
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

    ``fused``: ``None`` (default) runs the steps through :class:`FusedSteps`
    where it applies (compiled kernels, the interface's closed form);
    ``False`` always steps the blocks; ``True`` requires the fused step
    (:class:`SimulationError` at initialisation when it is not available).
    ``fused_step`` is the :class:`FusedSteps` in use, or None.
    """

    INPUTS = ("V_s", "duty", "f_s", "T", "direction", "m_load")

    def __init__(self, mp: MotorParams, h_s: float = 2e-4, pure_slip: bool = False, fused: bool | None = None):
        self.mp = mp
        self.h = float(h_s)
        self.b = make_blocks(mp, pure_slip=pure_slip)
        self.fused = fused
        self.fused_step: FusedSteps | None = None
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
        self.fused_step = None if self.fused is False else FusedSteps.for_motor(self)
        if self.fused and self.fused_step is None:
            raise SimulationError("InProcessMotor(fused=True): the fused step is not available "
                                  f"(compiled kernels: {jit_status()}; interface quadrature: "
                                  f"{bool(itf_.quadrature)})")

    def step(self):
        """One communication step of length ``h`` (fused where it applies)."""
        if self.fused_step is not None:
            self.fused_step.advance(1, self.h)
        else:
            self.step_blocks()

    def advance(self, n: int, h: float):
        """``n`` communication steps of length ``h`` [s] (``h`` becomes the engine's step)."""
        self.h = h
        if self.fused_step is not None:
            self.fused_step.advance(n, h)
            return
        for _ in range(n):
            self.step_blocks()

    def sync(self):
        """Bring the blocks up to date with the fused steps (before reading or writing them directly)."""
        if self.fused_step is not None:
            self.fused_step.store()

    def step_blocks(self):
        """One communication step through the four blocks, one after the other."""
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
        """Current value of ``"Component.variable"`` (from the fused state where it holds it)."""
        f = self.fused_step
        if f is not None and f.ahead:
            read = _READERS.get(name)
            if read is not None:
                return float(f.x[read] if type(read) is int else read(f.x))
            f.store()
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


# ---------------------------------------------------------------------------
# The fused coupled step
# ---------------------------------------------------------------------------

#: the ranges the blocks accept for the inputs the fused step holds (the driver's outputs and the system
#: inputs), from the stator's and the slider's Var declarations
_HELD_BOUNDS = {v.name: (v.min, v.max) for v in StatorBlock.INPUTS + SliderBlock.INPUTS
                if v.name in ("V0", "omega", "T", "direction", "m_load")}

#: block variables copied between the blocks and the state vector: (index in x, component, attribute)
_BLOCK_VARS = tuple((i, *name.split(".", 1)) for i, name in enumerate(cp.STATE)
                    if name.split(".", 1)[0] in ("Driver", "Stator", "Interface", "Slider"))


class FusedSteps:
    """Steps an :class:`InProcessMotor` (initialised) through the compiled coupled step.

    ``motor.b`` stays the authority while the fused state is not loaded; after
    :meth:`advance` the vector ``x`` is ahead of the blocks until :meth:`store`.
    """

    def __init__(self, motor: InProcessMotor, kernel):
        self.motor = motor
        self.kernel = kernel
        b = motor.b
        self.p = cp.parameter_vector(motor.mp.replace(stator=b["Stator"].params, interface=b["Interface"].params,
                                                      slider=b["Slider"].params),
                                     pure_slip=b["Interface"].pure_slip)
        self.x = np.zeros(len(cp.STATE))
        self.cell, self.cell_k = np.zeros((st.TABLE_DEGREE + 1, 2)), -1  # no cell yet
        self.ahead = False  # True: x holds steps the blocks do not have yet
        self._inputs, self._inputs_ok = None, False  # the system inputs x holds, and whether they are in range
        self.steps_fused = 0
        self.steps_blocks = 0

    @staticmethod
    def applies(motor: InProcessMotor) -> bool:
        """True when the fused step reproduces ``motor.step`` (see the module docstring)."""
        return not motor.b["Interface"].quadrature

    @classmethod
    def for_motor(cls, motor: InProcessMotor):
        """A :class:`FusedSteps` for ``motor``, or None where it does not apply or nothing is compiled."""
        if not cls.applies(motor):
            return None
        kernel = cp.compiled_substeps()
        return None if kernel is None else cls(motor, kernel)

    def _table(self):
        stt = self.motor.b["Stator"]
        return st.modal_table(stt.params, stt.modal_state()[1])

    def load(self):
        """Copy the blocks' state into ``x`` (after initialisation, a restore, or steps through the blocks)."""
        b, x = self.motor.b, self.x
        for i, comp, var in _BLOCK_VARS:
            x[i] = getattr(b[comp], var)
        stt = b["Stator"]
        props, props_T = stt.modal_state()
        x[cp.K_L], x[cp.C_L], x[cp.K_B], x[cp.C_B] = props.K_l, props.C_l, props.K_b, props.C_b
        x[cp.ETA], x[cp.W_L0], x[cp.W_B0], x[cp.PROPS_T] = props.eta_T, props.omega_l0, props.omega_b0, props_T
        x[cp.DIR], x[cp.T_AMB], x[cp.M_LOAD] = stt.direction, stt.T, b["Slider"].m_load
        self.ahead = False

    def store(self):
        """Copy ``x`` back into the blocks (their states, inputs and outputs, as after ``motor.step``)."""
        if not self.ahead:
            return
        b = self.motor.b
        values = self.x.tolist()
        for comp, var, read in _STORE:  # every variable value() reads from the vector, written the same way
            setattr(b[comp], var, values[read] if type(read) is int else read(values))
        stt = b["Stator"]
        props = stt.modal_state()[0]
        stt.set_modal_state(st.ModalProperties(
            M_l=props.M_l, K_l=values[cp.K_L], C_l=values[cp.C_L], M_b=props.M_b, K_b=values[cp.K_B],
            C_b=values[cp.C_B], eta_T=values[cp.ETA], omega_l0=values[cp.W_L0], omega_b0=values[cp.W_B0]),
            values[cp.PROPS_T])
        self.ahead = False

    def set_inputs(self, t: float, h: float) -> bool:
        """Take the motor's system inputs (constant over the call): the driver's outputs by the driver block.

        False when the step must go through the blocks: an input out of the ranges the stator accepts
        (the blocks then raise their error).
        """
        m = self.motor
        u = m._inputs_at(t)
        if u is self._inputs and u is m._constant:
            return self._inputs_ok  # the same constant inputs as the last call
        d = m.b["Driver"]
        d.V_s, d.duty, d.f_s, d.T = u["V_s"], u["duty"], u["f_s"], u["T"]
        d.do_step(t, h)  # algebraic, memoised; raises on a bad input
        m._driven = u if u is m._constant else None
        x = self.x
        x[cp.V0], x[cp.OMEGA], x[cp.DIR], x[cp.T_AMB], x[cp.M_LOAD] = (
            d.V0, d.omega, u["direction"], u["T"], u["m_load"])
        self._inputs = u
        values = {"V0": d.V0, "omega": d.omega, "T": u["T"], "direction": u["direction"], "m_load": u["m_load"]}
        self._inputs_ok = (all(lo <= values[k] <= hi for k, (lo, hi) in _HELD_BOUNDS.items())
                           and abs(abs(u["direction"]) - 1.0) <= 1e-9)
        return self._inputs_ok

    def advance(self, n: int, h: float):
        """``n`` engine steps of ``h`` [s] from ``motor.t`` with the system inputs held (``motor.t`` advances)."""
        m = self.motor
        t_end = m.t + n * h
        if not self.ahead:
            self.load()
        if not self.set_inputs(m.t, h):
            self._through_blocks(n, h)
            m.t = t_end
            return
        done, x = 0, self.x
        while done < n:
            k = self.kernel(x, self.p, self.cell, self.cell_k, n - done, h)
            done += k
            self.steps_fused += k
            if k:
                self.ahead = True
            if done == n:
                break
            if x[cp.REASON] == cp.REASON_CELL:
                k_cell = int(x[cp.NEED_CELL])
                cell = self._table().cell_array(k_cell)
                if cell is not None:
                    self.cell, self.cell_k = cell, k_cell
                    continue
            self._through_blocks(1, h)  # the blocks take this step (and raise if they must)
            done += 1
            self.load()
            self.cell_k = -1  # the stator may have moved to another table (a temperature-dependent B2 mode)
        m.t = t_end

    def _through_blocks(self, n: int, h: float):
        self.store()
        m = self.motor
        m.h = h
        for _ in range(n):
            m.step_blocks()
        self.steps_blocks += n


def state_getter(names: list[str]):
    """A getter of the block variables ``names`` (``"Component.variable"``, each one the fused state vector
    holds: the entries :meth:`InProcessMotor.value` reads from it) from the vector as a list
    (``x.tolist()``): a tuple in that order."""
    index = [_READERS.get(n) for n in names]
    missing = [n for n, i in zip(names, index) if type(i) is not int]
    if missing:
        raise KeyError(f"not held by the fused state vector: {', '.join(missing)}")
    return operator.itemgetter(*index)


def _readers() -> dict:
    """``"Component.variable"`` -> index in the fused state vector, or a function of the vector, for
    every block variable the vector holds or gives: what :meth:`InProcessMotor.value` reads without
    bringing the blocks up to date, and what :meth:`FusedSteps.store` writes back into them (so the two
    cannot disagree on where a block variable sits)."""
    out: dict = {name: i for i, name in enumerate(cp.STATE) if name.split(".", 1)[0] in
                 ("Driver", "Stator", "Interface", "Slider")}
    out.update({"Slider.v": cp.V, "Slider.s": cp.S, "Slider.stuck": cp.STUCK, "Slider.at_stop": cp.STOP,
                "Stator.T_stator": cp.T_ST, "Stator.V0": cp.V0, "Stator.omega": cp.OMEGA,
                "Stator.direction": cp.DIR, "Stator.T": cp.T_AMB, "Slider.m_load": cp.M_LOAD,
                "Interface.U_l": cp.U_L, "Interface.U_w": cp.U_W, "Interface.delta": cp.DELTA,
                "Interface.omega": cp.OMEGA, "Interface.F_p": cp.F_P, "Slider.F_d": cp.F_D, "Slider.F_p": cp.F_P,
                "Stator.eta_T": cp.ETA,
                # the outputs StatorBlock derives, with its operations
                "Stator.v_tip": lambda x: x[cp.OMEGA] * x[cp.U_W],
                "Stator.f_b": lambda x: x[cp.W_B0] / (2 * math.pi)})
    return out


_READERS = _readers()


def fused_readers() -> dict:
    """A copy of the map ``"Component.variable"`` -> index in the fused state vector (or a function of the
    vector) that :meth:`InProcessMotor.value` reads (the native motor FMU publishes the same variables)."""
    return dict(_READERS)

#: what :meth:`FusedSteps.store` writes back into the blocks: (component, variable, reader) for every reader
_STORE = tuple((*name.split(".", 1), read) for name, read in _READERS.items())
