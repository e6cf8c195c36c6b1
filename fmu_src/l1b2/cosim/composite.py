"""Composite blocks: the whole coupled motor in one block, and the Eq. 29 predictor as a block.

:class:`MotorBlock` (``L1B2Motor.fmu``) runs the in-process engine inside one
block; :class:`PredictorBlock` (``Predictor.fmu``) wraps the reduced speed
predictor. :data:`BLOCKS` maps every FMU name to its block class.
"""

from __future__ import annotations

import math
import operator
from dataclasses import fields, replace

import numpy as np

from ..errors import SimulationError
from ..physics.params import (
    DriverParams,
    InterfaceParams,
    MotorParams,
    OperatingPoint,
    SliderParams,
    StatorParams,
)
from ..predictor import effects as fx
from ..predictor import model as pr
from ..predictor.effects import ExtendedPredictor
from ..predictor.frequency import FrequencyResponse, effective_voltage
from ..predictor.model import PredictorParams
from ..predictor.setup import PredictorSetup
from ..units import COLUMN_UNITS, column_unit, unit_note
from .blocks import SUBSYSTEM_BLOCKS, Block, Var, parameter_vars
from .engine import InProcessMotor, state_getter


class MotorBlock(Block):
    """The whole coupled motor in one block (for ``L1B2Motor.fmu``, hosts that cannot import SSP).

    Runs the four subsystem blocks with the same Gauss-Seidel sequence as
    :class:`l1b2.cosim.engine.InProcessMotor`, sub-stepping each communication step
    with ``internal_step_s``. Every subsystem parameter is exposed as
    ``Component.parameter`` (same names and values as the SSV of the SSP), and
    every sub-block input, output and state as a ``local`` variable
    ``Component.variable`` so that get/set FMU state captures the whole motor.

    With the compiled kernels (:mod:`l1b2.physics.jit`) the communication steps
    run through :class:`l1b2.cosim.engine.FusedSteps`: one compiled call per
    communication step, with the same operations as the blocks and the same
    numbers (tests/test_fused.py); the blocks catch up whenever a sub-block
    variable is read or written.
    """

    PARAMS_CLASS = MotorParams
    SECTION = "motor"
    COMPONENTS = ("Driver", "Stator", "Interface", "Slider")
    INPUTS = [
        Var("V_s", "input", "V", "supply voltage of the H bridge", start=67.1, min=0.0, max=2000.0),
        Var("duty", "input", "1", "PWM duty ratio", start=1.0, min=0.0, max=1.0),
        Var("f_s", "input", "Hz", "drive frequency", start=48500.0, min=1e3, max=1e6),
        Var("T", "input", "degC", "ambient temperature of driver and stator", start=25.0, min=-100.0, max=300.0),
        Var("direction", "input", "1", "+1 excites CH1 (toward +position), -1 CH2", start=1.0, min=-1.0, max=1.0),
        Var("m_load", "input", "kg", "signed load mass; > 0 pulls toward -position", min=-100.0, max=100.0),
    ]
    OUTPUTS = [
        Var("v", "output", "m/s", "slider speed"),
        Var("s", "output", "m", "slider position"),
        Var("V0", "output", "V", "stator voltage amplitude"),
        Var("U_l", "output", "m", "tip normal vibration amplitude", nominal=1e-6),
        Var("U_w", "output", "m", "tip tangential vibration amplitude", nominal=1e-6),
        Var("delta", "output", "rad", "phase of tangential minus normal tip displacement"),
        Var("F_p", "output", "N", "static axial force alpha0 P(s)"),
        Var("F_d", "output", "N", "driving force"),
        Var("phi_c", "output", "rad", "contact angle"),
        Var("stick_fraction", "output", "1", "share of the contact time in stick"),
        Var("T_stator", "output", "degC", "stator temperature"),
        Var("at_stop", "output", "1", "-1/+1 at the negative/positive end stop, 0 elsewhere"),
    ]
    EXTRA_PARAMETERS = [
        Var("internal_step_s", "parameter", "s", "internal Gauss-Seidel step between the subsystems",
            start=2e-4, min=1e-6, max=1e-2, variability="fixed"),
        Var("Interface.pure_slip", "parameter", "", "true: the paper's Sect. 4 assumptions (phi_c = pi, no stick)",
            start=False, variability="fixed", type="Boolean"),
        Var("Interface.quadrature", "parameter", "", "true: the numerical reference kernel of the interface "
            "(slow) instead of the exact closed form", start=False, variability="fixed", type="Boolean"),
        Var("Slider.s0", "parameter", "m", "initial slider position", start=0.0, min=-1.0, max=1.0,
            variability="fixed"),
        Var("Slider.v0", "parameter", "m/s", "initial slider speed", start=0.0, min=-10.0, max=10.0,
            variability="fixed"),
        Var("Stator.T_st0", "parameter", "degC", "initial stator temperature (when self-heating is on)",
            start=25.0, min=-100.0, max=300.0, variability="fixed"),
    ]
    _OUT_SOURCE = {"v": ("Slider", "v"), "s": ("Slider", "s"), "V0": ("Driver", "V0"), "U_l": ("Stator", "U_l"),
                   "U_w": ("Stator", "U_w"), "delta": ("Stator", "delta"), "F_p": ("Stator", "F_p"),
                   "F_d": ("Interface", "F_d"), "phi_c": ("Interface", "phi_c"),
                   "stick_fraction": ("Interface", "stick_fraction"), "T_stator": ("Stator", "T_stator"),
                   "at_stop": ("Slider", "at_stop")}
    #: where each output comes from, ``{output: (component, variable)}`` (the native FMU publishes the same)
    OUTPUT_SOURCES = _OUT_SOURCE
    #: the same outputs from the fused state vector
    _out_getter = staticmethod(state_getter([f"{comp}.{var}" for comp, var in _OUT_SOURCE.values()]))

    def __init__(self, params: MotorParams):
        self.params = params
        for var in self.INPUTS + self.OUTPUTS:
            setattr(self, var.name, 0.0 if var.start is None else var.start)
        self.internal_step_s = 2e-4
        self.motor = InProcessMotor(params, h_s=self.internal_step_s)
        self._held = None  # system inputs the engine holds (set at the first step after initialisation)
        self._pub_blocks = None  # the sub-blocks _publish planned its reads for
        self._extra = {v.name: v.start for v in self.EXTRA_PARAMETERS if "." in v.name}

    @classmethod
    def params_from_defaults(cls, defaults: dict) -> MotorParams:
        return MotorParams(driver=DriverParams(**defaults["driver"]), stator=StatorParams(**defaults["stator"]),
                           interface=InterfaceParams(**defaults["interface"]),
                           slider=SliderParams(**defaults["slider"]),
                           operating=OperatingPoint(**defaults["operating"]), name="reference")

    @classmethod
    def _sub_locals(cls) -> list[Var]:
        out = []
        for comp in cls.COMPONENTS:
            bcls = SUBSYSTEM_BLOCKS[comp]
            for v in bcls.INPUTS + bcls.OUTPUTS + bcls.STATES:
                out.append(Var(f"{comp}.{v.name}", "local", v.unit, f"{comp}: {v.description}", nominal=v.nominal))
        return out

    @classmethod
    def variables(cls, params=None) -> list[Var]:
        pars = []
        if params is not None:
            for comp in cls.COMPONENTS:
                sub = getattr(params, SUBSYSTEM_BLOCKS[comp].SECTION)
                for v in parameter_vars(type(sub), sub):
                    pars.append(Var(f"{comp}.{v.name}", v.causality, v.unit, v.description, start=v.start,
                                    min=v.min, max=v.max, variability=v.variability))
        return pars + list(cls.EXTRA_PARAMETERS) + cls.INPUTS + cls.OUTPUTS + cls._sub_locals()

    def get(self, name: str):
        if "." not in name:
            return getattr(self, name)
        if name in self._extra:
            return self._extra[name]
        comp, var = name.split(".", 1)
        section = SUBSYSTEM_BLOCKS[comp].SECTION
        if var in {f.name for f in fields(getattr(self.params, section))}:
            return getattr(getattr(self.params, section), var)  # parameters: the dataclass is the truth
        self.motor.sync()  # the blocks catch up with the fused steps
        return getattr(self.motor.b[comp], var)                  # sub-block inputs, outputs, states

    def set(self, name: str, value):
        if "." in name:
            comp, var = name.split(".", 1)
            if name in self._extra:
                self._extra[name] = value
                return
            section = SUBSYSTEM_BLOCKS[comp].SECTION
            if var in {f.name for f in fields(getattr(self.params, section))}:
                self.params = self.params.replace(**{f"{section}__{var}": value})
            self.motor.sync()  # the blocks are the authority again until the next step
            setattr(self.motor.b[comp], var, value)
            return
        setattr(self, name, value)

    def check_inputs(self):
        super().check_inputs()
        if abs(abs(self.direction) - 1.0) > 1e-9:
            raise SimulationError(f"MotorBlock: input direction [1] = {self.direction} must be +1 or -1")

    def initialize(self):
        self.check_inputs()
        self.motor = InProcessMotor(self.params, h_s=float(self.internal_step_s),
                                    pure_slip=bool(self._extra["Interface.pure_slip"]))
        self.motor.b["Stator"].T_st0 = float(self._extra["Stator.T_st0"])
        self.motor.b["Interface"].quadrature = bool(self._extra["Interface.quadrature"])
        self._held = None
        self.motor.initialize(V_s=self.V_s, duty=self.duty, f_s=self.f_s, T=self.T, direction=self.direction,
                              m_load=self.m_load, s0=float(self._extra["Slider.s0"]),
                              v0=float(self._extra["Slider.v0"]))
        self._publish()

    def initialize_outputs(self):
        self.motor.sync()
        for b in self.motor.b.values():
            b.refresh()
        self._publish()

    def _publish(self):
        """The outputs from the sub-blocks: one attrgetter per sub-block, one ``__dict__`` update."""
        b = self.motor.b
        if self._pub_blocks is not b:
            self._pub_blocks = b
            by_comp: dict[str, list] = {}
            for out, (comp, var) in self._OUT_SOURCE.items():
                by_comp.setdefault(comp, []).append((out, var))
            self._pub_plan = [(b[comp], operator.attrgetter(*(v for _, v in pairs)) if len(pairs) > 1
                               else (lambda blk, v=pairs[0][1]: (getattr(blk, v),)))
                              for comp, pairs in by_comp.items()]
            self._pub_names = [out for pairs in by_comp.values() for out, _ in pairs]
        (b1, g1), (b2, g2), (b3, g3), (b4, g4) = self._pub_plan  # the four sub-blocks (plain floats)
        self.__dict__.update(zip(self._pub_names, g1(b1) + g2(b2) + g3(b3) + g4(b4)))

    def do_step(self, t, h):
        u = (self.V_s, self.duty, self.f_s, self.T, self.direction, self.m_load)
        if u != self._held:  # new inputs (nan never equals itself): checked, and converted once by the engine
            self.check_inputs()
            self.motor.inputs = dict(zip(InProcessMotor.INPUTS, u))
            self._held = u
        n = max(1, int(round(h / float(self.internal_step_s))))
        if n > self.MAX_SUBSTEPS:
            raise SimulationError(f"MotorBlock: a step of {h} s takes {n} internal steps of internal_step_s = "
                                  f"{self.internal_step_s} s, more than {self.MAX_SUBSTEPS}")
        motor = self.motor
        motor.t = t
        motor.advance(n, h / n)
        fused = motor.fused_step
        if fused is not None and fused.ahead:  # outputs straight from the fused state vector
            self.__dict__.update(zip(self._OUT_SOURCE, self._out_getter(fused.x.tolist())))
        else:
            self._publish()


class PredictorBlock(Block):
    """The paper's Eq. 29 speed predictor as a co-simulation block (for ``Predictor.fmu``).

    Inputs V0, s, load, direction; outputs the predicted speed ``v`` (the
    Eq. 29 map iterated with the identified sampling time ``T_s`` inside each
    communication step, i.e. the identified discrete-time model) and the
    closed-form steady speed ``v_steady`` at the current inputs (for
    feedforward). Every identified parameter is an FMI parameter with its unit.
    """

    SECTION = "predictor"
    INPUTS = [
        Var("V0", "input", "V", "stator voltage amplitude", start=324.0, min=0.0, max=2000.0),
        Var("s", "input", "m", "slider position", min=-1.0, max=1.0),
        Var("load", "input", "kg", "signed load mass; > 0 pulls toward -position", min=-100.0, max=100.0),
        Var("direction", "input", "1", "+1 CH1 (toward +position), -1 CH2", start=1.0, min=-1.0, max=1.0),
        Var("frequency_Hz", "input", "Hz", "drive frequency; scales the force factor by the identified frequency "
            "response (none identified: no effect)", start=48500.0, min=1.0, max=1e7),
    ]
    OUTPUTS = [
        Var("v", "output", "m/s", "predicted slider speed (Eq. 29 iterated at T_s)"),
        Var("v_steady", "output", "m/s", "closed-form steady speed v* = b/(1-a) at the current inputs"),
    ]
    STATES = [Var("v_state", "local", "m/s", "predicted speed (state)")]
    EXTRA_PARAMETERS = [
        Var("v0", "parameter", "m/s", "initial speed", start=0.0, min=-10.0, max=10.0, variability="fixed"),
    ]

    def __new__(cls, setup=None):
        if cls is PredictorBlock and isinstance(setup, ExtendedPredictor):
            cls = ExtendedPredictorBlock
        return super().__new__(cls)

    def __init__(self, setup: PredictorSetup):
        self.setup = setup
        self.params = setup
        for var in self.EXTRA_PARAMETERS:
            setattr(self, var.name, var.start)
        for var in self.INPUTS + self.OUTPUTS + self.STATES:
            setattr(self, var.name, 0.0 if var.start is None else var.start)
        self.frequency_Hz = setup.f_nominal_Hz if isinstance(setup, PredictorSetup) else 48500.0
        self._values = self._param_values(setup)

    @staticmethod
    def _param_values(setup: PredictorSetup) -> dict:
        p = setup.params
        vals = dict(zip(p.names(p.order), p.to_vector().tolist()))
        vals.update(s_center=p.s_center, s_half=p.s_half, kappa=p.kappa, load_inertia=float(p.include_load_inertia),
                    slider_mass_kg=setup.slider_mass_kg, T_s=setup.T_s)
        if setup.frequency is not None:
            vals.update(f_ref_Hz=setup.frequency.f_ref_Hz, f_b0_Hz=setup.frequency.f_b0_Hz,
                        zeta_b=setup.frequency.zeta_b)
        return vals

    @classmethod
    def inputs(cls, params) -> list[Var]:
        """The inputs, ``frequency_Hz`` starting at the nominal drive frequency of ``params``'s response."""
        setup = getattr(params, "model", params)
        f0 = getattr(setup, "f_nominal_Hz", 48500.0) if setup is not None else 48500.0
        return [replace(v, start=f0) if v.name == "frequency_Hz" else v for v in cls.INPUTS]

    @classmethod
    def params_from_defaults(cls, defaults: dict) -> PredictorSetup | ExtendedPredictor:
        if "extended_predictor" in defaults:
            return ExtendedPredictor.from_dict(defaults["extended_predictor"])
        if "predictor" in defaults:
            return PredictorSetup.from_dict(defaults["predictor"])
        from ..predictor.derive import derive_predictor_setup
        return derive_predictor_setup(cls._motor_from(defaults))

    @staticmethod
    def _motor_from(defaults: dict) -> MotorParams:
        return MotorBlock.params_from_defaults(defaults)

    @classmethod
    def baked_defaults(cls, mp: MotorParams) -> dict:
        """Without an identification, the FMU carries the physical model's linearization (derived once)."""
        from ..predictor.derive import derive_predictor_setup
        return {"predictor": derive_predictor_setup(mp).to_dict()}

    @classmethod
    def variables(cls, params: PredictorSetup | ExtendedPredictor | None = None) -> list[Var]:
        if cls is PredictorBlock and isinstance(params, ExtendedPredictor):
            return ExtendedPredictorBlock.variables(params)
        return cls._setup_vars(params) + list(cls.EXTRA_PARAMETERS) + cls.inputs(params) + cls.OUTPUTS + cls.STATES

    @staticmethod
    def _setup_vars(params: PredictorSetup | None, prefix: str = "", what: str = "Eq. 35 parameter") -> list[Var]:
        """The parameters of one Eq. 29 setup (names prefixed with ``prefix``)."""
        pars = []
        if params is not None:
            p = params.params
            units = p.units(p.order)
            for name, value in zip(p.names(p.order), p.to_vector()):
                pars.append(Var(name, "parameter", units[name].replace("N s/m", "N.s/m").replace("-", "1"),
                                f"{what} {name}", start=float(value), variability="fixed"))
            pars += [
                Var("s_center", "parameter", "m", "centre of the position scaling of the polynomials",
                    start=p.s_center, variability="fixed"),
                Var("s_half", "parameter", "m", "half range of the position scaling", start=p.s_half, min=1e-6,
                    variability="fixed"),
                Var("kappa", "parameter", "1", "share of F_p loading the guide", start=p.kappa, min=0.0, max=1.0,
                    variability="fixed"),
                Var("load_inertia", "parameter", "1", "1: the load mass is accelerated with the slider",
                    start=float(p.include_load_inertia), min=0.0, max=1.0, variability="fixed"),
                Var("slider_mass_kg", "parameter", "kg", "slider mass m_s", start=params.slider_mass_kg, min=1e-6,
                    variability="fixed"),
                Var("T_s", "parameter", "s", "sampling time the predictor was identified with", start=params.T_s,
                    min=1e-7, variability="fixed"),
            ]
            fr = params.frequency
            if fr is not None:
                pars += [
                    Var("f_ref_Hz", "parameter", "Hz", "drive frequency at which the force factor's gain is 1",
                        start=fr.f_ref_Hz, min=1.0, variability="fixed"),
                    Var("f_b0_Hz", "parameter", "Hz", "B2 resonance of the identified frequency response (Eq. 26)",
                        start=fr.f_b0_Hz, min=1.0, variability="fixed"),
                    Var("zeta_b", "parameter", "1", "B2 damping of the identified frequency response (Eq. 26)",
                        start=fr.zeta_b, min=1e-9, variability="fixed"),
                ]
        return [replace(v, name=prefix + v.name) for v in pars]

    def get(self, name: str):
        if name in self._values:
            return self._values[name]
        return getattr(self, name)

    def set(self, name: str, value):
        if name in self._values:
            self._values[name] = float(value)
        else:
            setattr(self, name, value)

    def rebuild_params(self):
        self.setup = _setup_from_values(self._values, self.setup)

    def check_inputs(self):
        super().check_inputs()
        if abs(abs(self.direction) - 1.0) > 1e-9:
            raise SimulationError(f"PredictorBlock: input direction [1] = {self.direction} must be +1 or -1")

    def initialize(self):
        self.rebuild_params()
        self.check_inputs()
        self.v_state = float(self.v0)
        self.initialize_outputs()

    def initialize_outputs(self):
        su = self.setup
        self.v = float(self.v_state)
        self.v_steady = float(pr.steady_state(su.params, self.s, self._drive(su), self.load, self.direction,
                                              su.slider_mass_kg))

    def _drive(self, su: PredictorSetup) -> float:
        """The effective drive amplitude ``V0 g(frequency_Hz)`` [V] of a setup (V0 without a frequency response)."""
        if su.frequency is None:
            return float(self.V0)
        return float(effective_voltage(self.V0, self.frequency_Hz, su.frequency))

    def _advance(self, su: PredictorSetup, v: float, h: float, F=None) -> float:
        """Speed after the communication step ``h`` [s]: Eq. 29 iterated at sub-steps of at most ``su.T_s``."""
        n = max(1, int(math.ceil(h / su.T_s - 1e-9)))
        if n > self.MAX_SUBSTEPS:
            raise SimulationError(f"PredictorBlock: a step of {h} s takes {n} sub-steps of T_s = {su.T_s} s, "
                                  f"more than {self.MAX_SUBSTEPS}")
        for _ in range(n):
            v = float(pr.one_step(su.params, v, self.s, self._drive(su), self.load, self.direction, h / n,
                                  su.slider_mass_kg, extra_force=F))
        return v

    def do_step(self, t, h):
        self.check_inputs()
        self.v_state = self._advance(self.setup, float(self.v_state), h)
        self.initialize_outputs()


def _setup_from_values(vals: dict, template: PredictorSetup, prefix: str = "") -> PredictorSetup:
    """The Eq. 29 setup from the FMU's current parameter values (names prefixed with ``prefix``)."""
    p0 = template.params
    theta = np.array([vals[prefix + n] for n in p0.names(p0.order)])
    pp = PredictorParams.from_vector(theta, s_center=vals[prefix + "s_center"], s_half=vals[prefix + "s_half"],
                                     kappa=vals[prefix + "kappa"],
                                     include_load_inertia=vals[prefix + "load_inertia"] >= 0.5,
                                     drive_law=p0.drive_law)   # the model family is structural, not a variable
    m_s, T_s = vals[prefix + "slider_mass_kg"], vals[prefix + "T_s"]
    if not (m_s > 0 and T_s > 0):
        raise SimulationError(f"PredictorBlock: {prefix}slider_mass_kg [kg] and {prefix}T_s [s] must be positive")
    fr = None
    if prefix + "f_b0_Hz" in vals:
        try:
            fr = FrequencyResponse(vals[prefix + "f_ref_Hz"], vals[prefix + "f_b0_Hz"], vals[prefix + "zeta_b"])
        except ValueError as exc:
            raise SimulationError(f"PredictorBlock: {prefix}frequency response: {exc}") from None
    return PredictorSetup(pp, m_s, T_s, fr)


def _unit(u: str) -> str:
    return {"-": "1", "N s/m": "N.s/m"}.get(u, u)


class ExtendedPredictorBlock(PredictorBlock):
    """The calibrated, extended predictor (``Predictor.fmu`` built from a close-the-loop result).

    Carries an :class:`l1b2.predictor.effects.ExtendedPredictor`: the
    re-identified Eq. 35 parameters (same names as the baseline FMU's), the
    baseline's (prefix ``baseline_``, they give the effects' signals
    ``v_base``/``a_base``), every effect's parameters with unit, value and
    standard error in the description, and the speed channel's output filter
    (``speed_filter_a/b0/b1``) when one was kept. Per communication step
    (inputs at the step's start, as in the identification's free run):

    1. the baseline speed is advanced one step (``v_base`` -> ``v_base_next``);
       its time derivative ``a_base`` is the one-sided or central difference of
       :func:`l1b2.predictor.effects.time_derivative`;
    2. the effects' force ``F_extra`` is evaluated from the inputs, the FMU's
       time (the session clock: start the simulation at the run's session
       time), ``v_base`` and ``a_base``;
    3. the model speed is advanced with ``F_extra`` added to its drive force,
       and passed through the output filter; the output ``v`` is the filtered
       speed held within the speed channel's range (``speed_rail_lo``/``speed_rail_hi``
       [m/s], declared only for the rails the model carries), the filter's state is not.

    Its inputs (:meth:`inputs`, one list per carried model, the block's own
    ``INPUTS``): the plain predictor's, the measured stator temperature ``T``
    when an effect reads it, and one input per logged channel the effects read
    (:attr:`~l1b2.predictor.effects.ExtendedPredictor.channel_inputs`), named
    after the column; a column of the data format that is already an input
    (``frequency_Hz``) is that input, and a column named like another variable
    of the predictor is refused (:meth:`variables`).
    """

    EXT_OUTPUTS = [
        Var("v_baseline", "output", "m/s", "baseline Eq. 29 speed (the effects' v_base signal)"),
        Var("F_extra", "output", "N", "sum of the identified effects' forces at the last step (drive coordinates)"),
    ]
    EXT_STATES = [
        Var("v_base", "local", "m/s", "baseline speed (state)"),
        Var("v_base_prev", "local", "m/s", "baseline speed one step back"),
        Var("h_prev", "local", "s", "previous communication step (0 before the first)"),
        Var("v_raw", "local", "m/s", "model speed before the output filter"),
        Var("t_now", "local", "s", "time of the current communication point"),
    ]
    TEMPERATURE = Var("T", "input", "degC", "measured stator temperature (used by a temperature effect)",
                      start=25.0, min=-100.0, max=300.0)

    def __init__(self, setup: ExtendedPredictor):
        self.extended = setup
        self.INPUTS = self.inputs(setup)
        self._channels = tuple(setup.channel_inputs)
        super().__init__(setup.model)
        for var in self.EXT_OUTPUTS + self.EXT_STATES:
            setattr(self, var.name, 0.0)
        self._values.update({"baseline_" + k: v for k, v in self._param_values(setup.baseline).items()})
        for e in setup.effects:
            self._values.update(zip(e.names, (float(p) for p in e.phi)))
        if setup.output_filter is not None:
            self._values.update({f"speed_filter_{k}": float(setup.output_filter[k]) for k in ("a", "b0", "b1")})
            self._values.update({RAIL_PARAMETERS[k]: float(setup.output_filter[k]) for k in RAIL_PARAMETERS
                                 if k in setup.output_filter})
        self.base_setup = setup.baseline

    @classmethod
    def variables(cls, params: ExtendedPredictor | None = None) -> list[Var]:
        if params is None:
            return PredictorBlock.variables(None)
        src = params.source.get("train") or "TRAIN data"
        out = cls._setup_vars(params.model, what="re-identified Eq. 35 parameter")
        out += cls._setup_vars(params.baseline, "baseline_", "baseline Eq. 35 parameter (gives v_base)")
        for e in params.effects:
            for name, unit, phi, se in zip(e.names, e.units, e.phi, e.stderr):
                told = (f"identified {phi:.6g} (standard error {float(se):.3g}) from {src}"
                        if se is not None and math.isfinite(float(se)) else
                        f"not identifiable on its own from {src} (no finite standard error): the data determine its "
                        f"combination with the effect's other parameters, of which {phi:.6g} is one value")
                out.append(Var(name, "parameter", _unit(unit), f"{e.label}: {e.description}; {told}",
                               start=float(phi), variability="fixed"))
        if params.output_filter is not None:
            for k in ("a", "b0", "b1"):
                out.append(Var(f"speed_filter_{k}", "parameter", "1",
                               f"speed channel output filter y(k) = a y(k-1) + b0 u(k) + b1 u(k-1): {k}",
                               start=float(params.output_filter[k]), variability="fixed"))
            for k, name in RAIL_PARAMETERS.items():
                if k in params.output_filter:
                    side = "lowest" if k == "lo_m_s" else "highest"
                    out.append(Var(name, "parameter", "m/s",
                                   f"the speed channel's {side} reading (its range limit, identified from {src}): "
                                   "the output v is the filtered speed held within the range",
                                   start=float(params.output_filter[k]), variability="fixed"))
        out = (out + list(cls.EXTRA_PARAMETERS) + cls.inputs(params) + cls.OUTPUTS + cls.EXT_OUTPUTS + cls.STATES
               + cls.EXT_STATES)
        names = [v.name for v in out]
        clash = sorted({n for n in names if names.count(n) > 1})
        if clash:   # a logged channel named like a variable of the predictor
            raise ValueError(f"Predictor.fmu: variable names declared twice: {', '.join(clash)} (a logged channel "
                             "an effect reads has the name of a predictor variable: rename the column)")
        return out

    @classmethod
    def inputs(cls, params) -> list[Var]:
        """The plain predictor's inputs (:meth:`PredictorBlock.inputs`), ``T`` when an effect of the extended
        model ``params`` reads the stator temperature, then one input per logged channel its effects read that is
        no input yet (:func:`channel_input`)."""
        out = PredictorBlock.inputs(params)
        if not isinstance(params, ExtendedPredictor):
            return out
        if params.needs_temperature:
            out.append(cls.TEMPERATURE)
        src = params.source.get("train") or "TRAIN data"
        chans = params.channel_inputs
        out = [replace(v, description=v.description + "; also the logged channel the identified effects read")
               if v.name in chans else v for v in out]
        shared = {v.name for v in out if v.name in COLUMN_UNITS}   # an input that is a data-format column
        return out + [channel_input(col, start, src) for col, start in chans.items() if col not in shared]

    def set_start_time(self, t0: float):
        self.t_now = float(t0)

    def rebuild_params(self):
        super().rebuild_params()
        self.base_setup = _setup_from_values(self._values, self.extended.baseline, "baseline_")
        ext = self.extended   # with the parameter values the host set
        self.current = replace(ext, effects=tuple(replace(e, phi=tuple(self._values[n] for n in e.names))
                                                  for e in ext.effects))
        self.filter = (None if ext.output_filter is None
                       else {k: self._values[f"speed_filter_{k}"] for k in ("a", "b0", "b1")})
        self.rails = tuple(self._values.get(RAIL_PARAMETERS[k], default) for k, default in
                           (("lo_m_s", -math.inf), ("hi_m_s", math.inf)))

    def initialize(self):
        self.rebuild_params()
        self.check_inputs()
        self.v_base = self.v_raw = self.v_base_prev = float(self.v0)
        self.h_prev = 0.0
        self.v_state = self.v_raw * (1.0 if self.filter is None else fx.filter_start_gain(self.filter))
        self.F_extra = self._force(self._signals(0.0))   # a_base is not known before the first step
        self.v_baseline = float(self.v_base)
        self.initialize_outputs()

    def _signals(self, a_base: float) -> dict:
        x = {"t": [self.t_now], "s": [self.s], "V0": [self.V0], "load": [self.load], "d": [self.direction],
             "v_base": [self.v_base], "a_base": [a_base]}
        if hasattr(self, "T"):
            x["T"] = [self.T]
        for col in self._channels:
            x["col:" + col] = [getattr(self, col)]
        return x

    def _force(self, x) -> float:
        return float(self.current.extra_force(x)[0])

    def initialize_outputs(self):
        su = self.setup
        self.v = min(max(float(self.v_state), self.rails[0]), self.rails[1])   # the channel's range, last stage
        self.v_steady = float(pr.steady_state(su.params, self.s, self.V0, self.load, self.direction,
                                              su.slider_mass_kg, extra_force=getattr(self, "F_extra", 0.0)))

    def do_step(self, t, h):
        self.check_inputs()
        self.t_now = float(t)
        vb, vb_next = self.v_base, self._advance(self.base_setup, self.v_base, h)
        a_base = ((vb_next - vb) / h if self.h_prev <= 0.0
                  else float(fx.derivative_step(self.v_base_prev, vb, vb_next, self.h_prev, h)))
        F = self._force(self._signals(a_base))
        self.F_extra = F
        u_prev = self.v_raw
        self.v_raw = self._advance(self.setup, self.v_raw, h, F if self.current.effects else None)
        self.v_state = (self.v_raw if self.filter is None
                        else fx.filter_step(self.filter, self.v_state, self.v_raw, u_prev))
        self.v_base_prev, self.v_base, self.h_prev = vb, vb_next, h
        self.t_now = float(t) + h
        self.v_baseline = float(self.v_base)
        self.initialize_outputs()


#: the speed channel's range limits (:data:`l1b2.predictor.effects.FILTER_RAILS`) as parameters of Predictor.fmu
RAIL_PARAMETERS = {"lo_m_s": "speed_rail_lo", "hi_m_s": "speed_rail_hi"}


def channel_input(column: str, start: float, source: str) -> Var:
    """The input of ``Predictor.fmu`` that gives a logged channel's signals to the effects reading it.

    Named after the column; its unit from the column's name (:func:`l1b2.units.column_unit`, a derived channel's
    by the naming rule of its derivation; ``1`` when the name does not say it, which the description states; a
    logarithm's description says of what in which unit, :func:`l1b2.units.unit_note`); its start value ``start``,
    TRAIN's mean of the channel; unbounded (a non-finite value is refused).
    """
    unit, note = column_unit(column), unit_note(column)
    return Var(column, "input", unit or "1",
               f"logged channel {column} of the calibration data ({source}), read by the identified effects (a "
               "run-level effect reads its current value as the run's); start: TRAIN's mean"
               + (f"; {note}" if note else "")
               + ("" if unit else "; its unit is not known from its name: the column's own"), start=float(start))


#: every FMU's block class by FMU name
BLOCKS = {**SUBSYSTEM_BLOCKS, "L1B2Motor": MotorBlock, "Predictor": PredictorBlock}
