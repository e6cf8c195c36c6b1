"""Co-simulation blocks: the four subsystems as stateful step objects.

Each block holds its parameters (a frozen dataclass), its inputs, outputs and
states as plain float attributes, and implements ``initialize()`` and
``do_step(t, h)`` on top of the pure physics functions. The FMU slaves in
``fmu_src/slaves`` are thin wrappers that expose these attributes as FMI
variables, and :mod:`l1b2.cosim.master` runs the very same blocks in-process as the
reference for the fmpy master.

Every variable is declared once, in ``VARIABLES`` of each block, with its
causality, variability, SI unit, description and range; the FMU build uses
that table for ``modelDescription.xml``.

Communication between blocks (periodic steady state over a vibration period)
---------------------------------------------------------------------------
The blocks exchange amplitudes, phases and period-averaged forces, not 48 kHz
signals (docs/explanation/physics.md). The stator receives the interface force
fundamentals computed from its own outputs at the start of the step and
treats them over the step as a describing function (an equivalent complex
stiffness ``Y = eta F1 / Q``); its envelope ODE stays linear over the step and
is integrated exactly, which keeps the explicit coupling stable for
communication steps up to 1 ms. In a steady state ``Y Q`` is exactly the
interface force, so steady results do not depend on this choice.
"""

from __future__ import annotations

import math
import operator
import sys
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from ..errors import SimulationError
from ..physics import driver as drv
from ..physics import interface as itf
from ..physics import slider as sld
from ..physics import stator as st
from ..physics.params import (
    DriverParams,
    InterfaceParams,
    MotorParams,
    SliderParams,
    StatorParams,
    describe,
)


@dataclass(frozen=True)
class Var:
    """Declaration of one block variable (becomes one FMI ScalarVariable)."""

    name: str
    causality: str          # "input", "output", "parameter", "local"
    unit: str
    description: str
    start: float | None = None
    min: float | None = None
    max: float | None = None
    variability: str = "continuous"  # parameters: "fixed"
    type: str = "Real"                 # "Real", "Integer" or "Boolean"
    nominal: float | None = None


def parameter_vars(cls, values) -> list[Var]:
    return [Var(d["name"], "parameter", d["unit"], d["description"], start=getattr(values, d["name"]),
                min=d["min"], max=d["max"], variability="fixed") for d in describe(cls)]


#: per block class: (name, min, max) of its inputs, for the fast pass of Block.check_inputs
_INPUT_BOUNDS: dict[type, tuple] = {}


def motor_defaults(mp: MotorParams) -> dict:
    """JSON-safe start values of every section of a motor parameter set."""
    from dataclasses import asdict
    return {sec: asdict(getattr(mp, sec)) for sec in ("driver", "stator", "interface", "slider", "operating")}


class Block:
    """Base class: parameters, inputs, outputs and states as attributes."""

    PARAMS_CLASS: type = object
    SECTION: str = ""     # key of the block's parameters in the baked-in defaults document
    INPUTS: list[Var] = []
    OUTPUTS: list[Var] = []
    STATES: list[Var] = []
    EXTRA_PARAMETERS: list[Var] = []
    #: the largest communication step [s] an FMU of this block accepts (declared in its modelDescription.xml
    #: as maxCommunicationStepSize; a larger fmi2DoStep is refused with fmi2Discard, so that a step returns
    #: in bounded time)
    MAX_STEP_S: float = 1.0
    #: the most internal sub-steps one communication step may take (blocks that sub-step refuse beyond)
    MAX_SUBSTEPS: int = 1_000_000

    def __init__(self, params):
        self.params = params
        for var in self.EXTRA_PARAMETERS:
            setattr(self, var.name, var.start)
        for f in fields(params):
            setattr(self, f.name, getattr(params, f.name))
        for var in self.INPUTS + self.OUTPUTS + self.STATES:
            setattr(self, var.name, 0.0 if var.start is None else var.start)

    @classmethod
    def variables(cls, params=None) -> list[Var]:
        """All variables of the block (parameters with the start values of ``params``)."""
        pars = parameter_vars(cls.PARAMS_CLASS, params) if params is not None else []
        return pars + list(cls.EXTRA_PARAMETERS) + cls.INPUTS + cls.OUTPUTS + cls.STATES

    @classmethod
    def params_from_defaults(cls, defaults: dict):
        """The block's parameter object from a defaults document (see :func:`motor_defaults`)."""
        return cls.PARAMS_CLASS(**defaults[cls.SECTION])

    @classmethod
    def baked_defaults(cls, mp: MotorParams) -> dict:
        """Extra entries the FMU build writes into the defaults document (computed once, at build time)."""
        return {}

    def get(self, name: str):
        return getattr(self, name)

    def set(self, name: str, value):
        setattr(self, name, value)

    def rebuild_params(self):
        """Re-create the frozen parameter dataclass from the (possibly changed) attributes."""
        kw = {f.name: float(getattr(self, f.name)) for f in fields(self.params)}
        self.params = replace(self.params, **kw)

    def check_inputs(self):
        """Raise :class:`SimulationError` on a non-finite or out-of-range input (the class's ``INPUTS``, or the
        instance's own when it has them)."""
        own = "INPUTS" in self.__dict__
        bounds = self.__dict__.get("_input_bounds") if own else _INPUT_BOUNDS.get(type(self))
        if bounds is None:  # unbounded inputs: the largest finite floats, so that inf and nan fail
            big = sys.float_info.max
            names = tuple(v.name for v in self.INPUTS)
            bounds = (operator.attrgetter(*names) if len(names) > 1
                      else (lambda obj, names=names: tuple(getattr(obj, n) for n in names)),
                      tuple(-big if v.min is None else v.min for v in self.INPUTS),
                      tuple(big if v.max is None else v.max for v in self.INPUTS))
            if own:
                self.__dict__["_input_bounds"] = bounds
            else:
                _INPUT_BOUNDS[type(self)] = bounds
        getter, lows, highs = bounds
        try:  # fast pass: every value inside its (finite) range; nan fails every comparison
            for value, lo, hi in zip(getter(self), lows, highs):
                if not lo <= value <= hi:
                    break
            else:
                return
        except TypeError:  # not a number: the checks below say which
            pass
        for var in self.INPUTS:
            value = getattr(self, var.name)
            if not isinstance(value, (int, float, np.floating)) or not math.isfinite(value):
                raise SimulationError(f"{type(self).__name__}: input {var.name} [{var.unit}] = {value!r} is not finite")
            if var.min is not None and value < var.min:
                raise SimulationError(f"{type(self).__name__}: input {var.name} [{var.unit}] = {value} is below {var.min}")
            if var.max is not None and value > var.max:
                raise SimulationError(f"{type(self).__name__}: input {var.name} [{var.unit}] = {value} is above {var.max}")

    def state_vector(self) -> dict[str, float]:
        return {v.name: float(getattr(self, v.name)) for v in self.STATES}

    def initialize(self):  # pragma: no cover - overridden
        raise NotImplementedError

    def refresh(self):
        """Recompute outputs and caches after the states were set from outside (FMU state restore)."""
        self.initialize_outputs()

    def initialize_outputs(self):  # pragma: no cover - overridden
        raise NotImplementedError

    def do_step(self, t: float, h: float):  # pragma: no cover - overridden
        raise NotImplementedError


# ---------------------------------------------------------------------------
# Driver
# ---------------------------------------------------------------------------

class DriverBlock(Block):
    """H-bridge + LC tank (Eq. 1-4): algebraic, outputs follow the inputs of the step."""

    PARAMS_CLASS = DriverParams
    SECTION = "driver"
    INPUTS = [
        Var("V_s", "input", "V", "supply voltage of the H bridge", start=67.1, min=0.0, max=2000.0),
        Var("duty", "input", "1", "duty ratio delta of the PWM signal", start=1.0, min=0.0, max=1.0),
        Var("f_s", "input", "Hz", "switching (= drive) frequency", start=48500.0, min=1e3, max=1e6),
        Var("T", "input", "degC", "temperature of the tank components", start=25.0, min=-100.0, max=300.0),
    ]
    OUTPUTS = [
        Var("V0", "output", "V", "amplitude of the sinusoidal stator voltage"),
        Var("omega", "output", "rad/s", "drive angular frequency"),
        Var("V0_phase", "output", "rad", "phase of V0 relative to the inverter fundamental"),
        Var("V_inv1", "output", "V", "fundamental of the inverter voltage (Eq. 1)"),
        Var("omega0", "output", "rad/s", "zero-phase frequency of the drifted tank (Eq. 3)"),
    ]

    def initialize(self):
        self.rebuild_params()
        self._memo = None
        self._compute()

    initialize_outputs = initialize

    def _compute(self):
        self.check_inputs()
        memo = (self.params, self.V_s, self.duty, self.f_s, self.T)
        if self._memo is not None and memo[0] is self._memo[0] and memo[1:] == self._memo[1:]:
            return  # algebraic: same parameters and inputs as the last call, the outputs stand
        self._memo = memo
        out = drv.driver_output(self.params, self.V_s, self.duty, self.f_s, self.T)
        self.V0 = float(out.V0_V)
        self.omega = float(out.omega_rad_s)
        self.V0_phase = float(out.phase_rad)
        self.V_inv1 = float(out.V_inv1_V)
        self.omega0 = float(out.omega0_rad_s) if np.isfinite(out.omega0_rad_s) else 0.0

    def do_step(self, t, h):
        self._compute()


# ---------------------------------------------------------------------------
# Stator
# ---------------------------------------------------------------------------

class StatorBlock(Block):
    """L1 and B2 modal envelopes (Eq. 5-16) with interface feedback (Eq. 14)."""

    PARAMS_CLASS = StatorParams
    SECTION = "stator"
    INPUTS = [
        Var("V0", "input", "V", "amplitude of the stator voltage", start=324.0, min=0.0, max=2000.0),
        Var("omega", "input", "rad/s", "drive angular frequency", start=2 * math.pi * 48500, min=1e3, max=1e7),
        Var("direction", "input", "1", "+1 excites CH1 (toward +position), -1 CH2", start=1.0, min=-1.0, max=1.0),
        Var("s", "input", "m", "slider position (sets the axial force P(s))", start=0.0, min=-1.0, max=1.0),
        Var("T", "input", "degC", "ambient temperature of the stator", start=25.0, min=-100.0, max=300.0),
        Var("F_N1_sin", "input", "N", "sin component of the normal-force fundamental (normal-displacement frame)"),
        Var("F_N1_cos", "input", "N", "cos component of the normal-force fundamental"),
        Var("F_T1_sin", "input", "N", "sin component of the friction-force fundamental"),
        Var("F_T1_cos", "input", "N", "cos component of the friction-force fundamental"),
    ]
    OUTPUTS = [
        Var("U_l", "output", "m", "tip normal vibration amplitude (Eq. 12)", nominal=1e-6),
        Var("U_w", "output", "m", "tip tangential vibration amplitude (Eq. 13)", nominal=1e-6),
        Var("delta", "output", "rad", "phase of tangential minus normal tip displacement"),
        Var("phase_l", "output", "rad", "phase of the tip normal displacement"),
        Var("phase_w", "output", "rad", "phase of the tip tangential displacement"),
        Var("F_p", "output", "N", "static axial force = mean normal force, alpha0 P(s) (Eq. 16)"),
        Var("P", "output", "N", "nominal compressive axial force P(s)"),
        Var("f_b", "output", "Hz", "B2 natural frequency under the axial force"),
        Var("eta_T", "output", "1", "tangential load coefficient |phi_b(L, P)|"),
        Var("v_tip", "output", "m/s", "tangential tip velocity amplitude omega*U_w"),
        Var("T_stator", "output", "degC", "stator temperature (equals T unless self-heating is on)"),
    ]
    STATES = [
        Var("Q_l_re", "local", "m", "L1 modal phasor, real part (state)", nominal=1e-6),
        Var("Q_l_im", "local", "m", "L1 modal phasor, imaginary part (state)", nominal=1e-6),
        Var("Q_b_re", "local", "m", "B2 modal phasor, real part (state)", nominal=1e-6),
        Var("Q_b_im", "local", "m", "B2 modal phasor, imaginary part (state)", nominal=1e-6),
        Var("T_st", "local", "degC", "stator temperature (thermal state)", start=25.0),
    ]
    EXTRA_PARAMETERS = [
        Var("T_st0", "parameter", "degC", "initial stator temperature (used when self-heating is on)",
            start=25.0, min=-100.0, max=300.0, variability="fixed"),
    ]
    _envelope_step = None  # the compiled (or Python) envelope step, looked up at the first step

    def initialize(self):
        self.rebuild_params()
        self._envelope_step = None
        self.T_st = float(self.T_st0 if self.params.thermal_tau_s > 0 else self.T)
        self.initialize_outputs()

    def initialize_outputs(self):
        self._props_T = None
        self._table = None
        self._update_props()
        self._publish()

    def _update_props(self):
        """Modal properties at the current ``P(s)`` and stator temperature.

        From the shared :class:`~l1b2.physics.stator.ModalTable` (exact to round-off)
        while the B2 properties do not change with the temperature or the
        temperature did not change since the last step; evaluated directly otherwise.
        """
        sp = self.params
        s = self.s
        P = st.axial_force_N(sp, s if type(s) is float else float(s))
        T = self.T_st
        T = T if type(T) is float else float(T)
        if sp.df_dT_b_Hz_per_K == 0.0 or T == self._props_T:
            table = self._table
            if table is None or (table.T_b is not None and table.T_b != T):
                table = self._table = st.modal_table(sp, T)
            self._props = table(P, T)
        else:
            self._props = st.modal_properties(sp, P, T)
        self._props_T = T
        self.P = P
        self.F_p = sp.alpha0 * P

    def modal_state(self) -> tuple:
        """The modal properties of the last step (:class:`~l1b2.physics.stator.ModalProperties`) and the
        stator temperature [degC] they were evaluated at: the state the next step starts from."""
        return self._props, self._props_T

    def set_modal_state(self, props, T_degC: float):
        """Set what :meth:`modal_state` returns (the fused coupled step hands its state back)."""
        self._props, self._props_T = props, T_degC

    def _publish(self):
        """Outputs from the modal phasors (:func:`l1b2.physics.stator.tip_motion_scalar`)."""
        props = self._props
        eta_T = props.eta_T
        self.U_l, self.U_w, self.phase_l, self.phase_w, self.delta = st.tip_motion_scalar(
            complex(self.Q_l_re, self.Q_l_im), complex(self.Q_b_re, self.Q_b_im), eta_T)
        self.f_b = props.omega_b0 / (2 * math.pi)
        self.eta_T = eta_T
        self.v_tip = self.omega * self.U_w
        self.T_stator = self.T_st

    def do_step(self, t, h):
        """One communication step: the envelopes integrated exactly with the interface's describing functions.

        The formulas of :func:`~l1b2.physics.stator.excitation_phasors` and
        :func:`~l1b2.physics.stator.envelope_step` in plain floats
        (:func:`~l1b2.physics.stator.coupled_envelope_step`, compiled by numba when
        available), then :func:`~l1b2.physics.stator.stator_temperature_step`
        (tests/test_stator.py checks the step against those functions).
        """
        self.check_inputs()
        d = self.direction
        if abs(abs(d) - 1.0) > 1e-9:
            raise SimulationError(f"StatorBlock: input direction [1] = {d} must be +1 or -1")
        sp, props = self.params, self._props  # the properties the interface forces were computed with
        V0 = self.V0
        if sp.thermal_tau_s <= 0.0 and not sp.heating_K_per_V2:
            self.T_st = float(self.T)
        else:
            self.T_st = float(st.stator_temperature_step(float(self.T_st), float(self.T), float(V0), sp, h))
        self._update_props()  # at the step's end: the input s, the new stator temperature
        new = self._props
        step = self._envelope_step
        if step is None:
            step = self._envelope_step = st.compiled_envelope_step() or st.coupled_envelope_step
        (self.Q_l_re, self.Q_l_im, self.Q_b_re, self.Q_b_im,
         self.U_l, self.U_w, self.phase_l, self.phase_w, self.delta) = step(
            self.Q_l_re, self.Q_l_im, self.Q_b_re, self.Q_b_im, self.phase_l,
            self.F_N1_sin, self.F_N1_cos, self.F_T1_sin, self.F_T1_cos,
            sp.A_l_N_per_V * V0, d * sp.A_b_N_per_V * (1.0 + d * sp.asym_b) * V0, props.eta_T, self.omega,
            props.M_l, props.K_l, props.C_l, props.M_b, props.K_b, props.C_b, h, new.eta_T)
        self.f_b = new.omega_b0 / (2 * math.pi)  # the rest of _publish
        self.eta_T = new.eta_T
        self.v_tip = self.omega * self.U_w
        self.T_stator = self.T_st


# ---------------------------------------------------------------------------
# Interface
# ---------------------------------------------------------------------------

class InterfaceBlock(Block):
    """Tip/bar contact and friction over one vibration period (Eq. 17-20): algebraic."""

    PARAMS_CLASS = InterfaceParams
    SECTION = "interface"
    EXTRA_PARAMETERS = [
        Var("pure_slip", "parameter", "", "true: the paper's Sect. 4 assumptions (phi_c = pi, no stick)",
            start=False, variability="fixed", type="Boolean"),
        Var("quadrature", "parameter", "", "true: the numerical reference kernel (n_theta cells, slow) "
            "instead of the exact closed form", start=False, variability="fixed", type="Boolean"),
        Var("n_theta", "parameter", "", "cells over the contact window of the numerical reference kernel",
            start=256, min=16, max=65536, variability="fixed", type="Integer"),
    ]
    INPUTS = [
        Var("U_l", "input", "m", "tip normal vibration amplitude", min=0.0, max=1e-3, nominal=1e-6),
        Var("U_w", "input", "m", "tip tangential vibration amplitude", min=0.0, max=1e-3, nominal=1e-6),
        Var("delta", "input", "rad", "phase of tangential minus normal tip displacement",
            start=-math.pi / 2, min=-10.0, max=10.0),
        Var("omega", "input", "rad/s", "vibration angular frequency", start=2 * math.pi * 48500, min=1e3, max=1e7),
        Var("v", "input", "m/s", "slider speed", min=-10.0, max=10.0),
        Var("F_p", "input", "N", "static axial force, period mean of the normal force", start=6.0, min=0.0, max=1e4),
    ]
    OUTPUTS = [
        Var("F_d", "output", "N", "period-mean friction force on the slider (driving force, Eq. 27)"),
        Var("F_N_mean", "output", "N", "period mean of the normal force (equals F_p)"),
        Var("F_N1_sin", "output", "N", "sin component of the normal-force fundamental"),
        Var("F_N1_cos", "output", "N", "cos component of the normal-force fundamental"),
        Var("F_T1_sin", "output", "N", "sin component of the friction-force fundamental (fed back, Eq. 14)"),
        Var("F_T1_cos", "output", "N", "cos component of the friction-force fundamental"),
        Var("phi_c", "output", "rad", "contact angle (2 pi = permanent contact, Eq. 18)"),
        Var("stick_fraction", "output", "1", "share of the contact time in stick (Eq. 19)"),
    ]

    def __init__(self, params, pure_slip: bool = False, n_theta: int = 256):
        super().__init__(params)
        self.pure_slip = bool(pure_slip)
        self.n_theta = int(n_theta)

    def initialize(self):
        self.rebuild_params()
        # the closed form's kernel and its parameter arguments (itf.interface_forces_scalar, unwrapped)
        self._kernel = itf.compiled_kernel() or itf.period_integrals  # Python when L1B2_JIT=0
        self._kernel_args = itf.kernel_arguments(self.params, "pure_slip" if self.pure_slip else "stick_slip")
        self._compute()

    initialize_outputs = initialize

    def _compute(self):
        self.check_inputs()
        if not self.quadrature:  # inputs are real numbers here (check_inputs)
            (self.F_d, self.F_N_mean, self.F_N1_sin, self.F_N1_cos, self.F_T1_sin, self.F_T1_cos, self.phi_c,
             self.stick_fraction) = self._kernel(self.U_l, self.U_w, self.delta, self.omega, self.v, self.F_p,
                                                 *self._kernel_args)
            return
        out = itf.interface_forces_reference(self.U_l, self.U_w, self.delta, self.omega, self.v, self.F_p,
                                             self.params, mode="pure_slip" if self.pure_slip else "stick_slip",
                                             n_theta=int(self.n_theta))
        self.F_d, self.F_N_mean = out.F_d_N, out.F_N_mean_N
        self.F_N1_sin, self.F_N1_cos = out.F_N1_sin_N, out.F_N1_cos_N
        self.F_T1_sin, self.F_T1_cos = out.F_T1_sin_N, out.F_T1_cos_N
        self.phi_c, self.stick_fraction = out.phi_c_rad, out.stick_fraction

    def do_step(self, t, h):
        self._compute()


# ---------------------------------------------------------------------------
# Slider
# ---------------------------------------------------------------------------

class SliderBlock(Block):
    """Slider with guide friction, stick and end stops (Eq. 21-22)."""

    PARAMS_CLASS = SliderParams
    SECTION = "slider"
    INPUTS = [
        Var("F_d", "input", "N", "driving force from the interface", min=-1e4, max=1e4),
        Var("F_p", "input", "N", "static axial force (loads the guide, Eq. 22)", start=6.0, min=0.0, max=1e4),
        Var("m_load", "input", "kg", "signed load mass; > 0 pulls toward -position", min=-100.0, max=100.0),
    ]
    OUTPUTS = [
        Var("v", "output", "m/s", "slider speed"),
        Var("s", "output", "m", "slider position"),
        Var("a", "output", "m/s2", "mean acceleration over the last step"),
        Var("stuck", "output", "1", "1 while the guide friction holds the slider"),
        Var("at_stop", "output", "1", "-1/+1 at the negative/positive end stop, 0 elsewhere"),
    ]
    STATES = [
        Var("v_state", "local", "m/s", "slider speed (state)"),
        Var("s_state", "local", "m", "slider position (state)", start=0.0),
        Var("stuck_state", "local", "1", "1 while stuck (state)", start=1.0),
        Var("stop_state", "local", "1", "end-stop flag (state)"),
    ]
    EXTRA_PARAMETERS = [
        Var("s0", "parameter", "m", "initial slider position", start=0.0, min=-1.0, max=1.0, variability="fixed"),
        Var("v0", "parameter", "m/s", "initial slider speed", start=0.0, min=-10.0, max=10.0, variability="fixed"),
    ]

    _kernel = None  # the slider's event loop (compiled or Python), looked up at initialisation

    def initialize(self):
        self.rebuild_params()
        sp = self.params
        if not sp.s_min_m <= self.s0 <= sp.s_max_m:
            raise SimulationError(f"SliderBlock: s0 [m] = {self.s0} outside the stroke [{sp.s_min_m}, {sp.s_max_m}]")
        self._kernel = sld.compiled_step() or sld.step_floats  # Python when L1B2_JIT=0
        self.s_state, self.v_state = float(self.s0), float(self.v0)
        self.stuck_state = 1.0 if self.v0 == 0.0 else 0.0
        self.stop_state = 0.0
        self._publish(0.0)

    def initialize_outputs(self):
        self._publish(self.a)

    def _publish(self, acc):
        """Outputs from the states, ``acc`` the mean acceleration over the last step [m/s^2]."""
        self.v, self.s, self.a = self.v_state, self.s_state, acc
        self.stuck, self.at_stop = self.stuck_state, self.stop_state

    def do_step(self, t, h):
        self.check_inputs()
        v_old = self.v_state
        new = sld.step(self.params, sld.SliderState(self.v_state, self.s_state, bool(self.stuck_state),
                                                    int(self.stop_state)),
                       self.F_d, self.F_p, self.m_load, h, self._kernel)
        self.v_state, self.s_state = new.v_m_s, new.s_m
        self.stuck_state, self.stop_state = float(new.stuck), float(new.at_stop)
        self._publish((new.v_m_s - v_old) / h if h > 0 else 0.0)


#: the four subsystem blocks by component name (the composite blocks are in :mod:`l1b2.cosim.composite`)
SUBSYSTEM_BLOCKS = {"Driver": DriverBlock, "Stator": StatorBlock, "Interface": InterfaceBlock, "Slider": SliderBlock}


def variable_unit(component: str, variable: str) -> str:
    """Unit of ``component.variable`` of a subsystem block (inputs, outputs, states and parameters)."""
    cls = SUBSYSTEM_BLOCKS[component]
    for v in cls.variables():
        if v.name == variable:
            return v.unit or "1"
    raise KeyError(f"{component} has no variable '{variable}'")


def make_blocks(mp: MotorParams, pure_slip: bool = False) -> dict[str, Block]:
    """The four blocks with the parameters of ``mp``."""
    return {
        "Driver": DriverBlock(mp.driver),
        "Stator": StatorBlock(mp.stator),
        "Interface": InterfaceBlock(mp.interface, pure_slip=pure_slip),
        "Slider": SliderBlock(mp.slider),
    }


def block_parameters(name: str, mp: MotorParams) -> Any:
    """The parameter dataclass of block ``name`` in ``mp``."""
    return {"Driver": mp.driver, "Stator": mp.stator, "Interface": mp.interface, "Slider": mp.slider}[name]
