"""Virtual test rig: the paper's experiments (Sect. 5.1, Fig. 9) on the co-simulated motor.

A run is one traverse of the stroke from rest at one end stop to the other
at constant drive inputs (V0, frequency, direction, load). The rig records
what a real rig records, in the rig data format
(docs/reference/data-format.md): a 50 nm encoder sampled at 1 kHz, the speed the
DAQ derives from it, the commanded voltage, load and direction, on one
continuous experiment clock with pauses between runs. It also records the
vibrometer's tangential tip velocity amplitude ``omega*U_w`` (paper Fig. 9c)
as an extra column.

Run order: the (V0, load) conditions are visited in a seeded random order,
each as a forward (CH1) then backward (CH2) traverse, so that slow drifts on
the experiment clock are not confounded with the factors.

Noise and repeatability (off by default, seeded by ``RigPlan.seed``): white
noise on the speed channel (``speed_noise_m_s``) and a run-to-run scatter of
the contact's preload and friction coefficient (``run_scatter``, independent
factors per run, as a contact that re-seats between traverses gives). With
both off, runs of the same conditions are identical and a different seed
only reorders the runs.

Injections: named physical effects that the reduced predictor does not
contain (:data:`INJECTIONS`), each naming the effect family of
:mod:`l1b2.predictor.effects` with the same physics. Each switches on declared parameters of the FMU
system that are off in the reference motor; with none injected the rig is
the plain coupled model. What was injected is written to ``rig_truth.json``,
never to the data or its sidecar.

Engines: ``"fmu"`` runs the four FMUs through the SSD-driven fmpy master
(:class:`l1b2.cosim.master.CoSimulation`); ``"inprocess"`` runs the same blocks
without FMUs (:class:`l1b2.cosim.engine.InProcessMotor`), identical results,
faster.

Parallel runs: independent runs go to the Dask engine of :mod:`l1b2.cluster`
(``workers`` local processes or an existing cluster) and are put back in rig
order on one clock, identical to a serial run; runs that carry state
(self-heating) run serially in rig order.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..errors import SimulationError
from ..jsonio import dumps
from ..fmi.cache import ensure_fmus
from ..physics import driver as drv
from ..physics.params import MotorParams, load_motor
from ..predictor import effects as fx

# ---------------------------------------------------------------------------
# Injections (the rig's undeclared physical effects)
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Injection:
    """An extra physical effect the rig can switch on (parameters of the FMU system).

    ``effect`` is the family of :mod:`l1b2.predictor.effects` that models the
    same physics (its kind); the data regressor the injection shows up in is
    that family's (:attr:`regressor`). An effect of the measurement chain,
    which no family models, gives ``effect=None`` and its ``chain_regressor``.
    ``params`` maps ``"Component.parameter"`` to a default value; ``ranges``
    gives, for the parameters that vary between seeded draws, ``(low, high)``.
    """

    name: str
    description: str
    effect: str | None
    params: dict
    ranges: dict = field(default_factory=dict)
    stateful: bool = False  # carries state from run to run (cannot run runs in parallel)
    chain_regressor: str = ""
    #: the regressor when the family's is a placeholder (the ``channel`` and ``run_level`` families act through
    #: a signal they are given): the logged column or the protocol signal the effect shows up in
    signal: str = ""

    @property
    def regressor(self) -> str:
        """The data regressor the effect shows up in (the family's, or :attr:`signal`; the chain's own without one)."""
        if self.signal:
            return fx.channels.regressor_of(self.signal)
        return fx.family(self.effect).regressor if self.effect else self.chain_regressor

    def draw(self, rng: np.random.Generator | None) -> dict:
        """Parameter values: defaults, with the ranged ones drawn uniformly when ``rng`` is given."""
        values = dict(self.params)
        if rng is not None:
            for k, (lo, hi) in self.ranges.items():
                values[k] = float(rng.uniform(lo, hi))
        return values


INJECTIONS: dict[str, Injection] = {e.name: e for e in [
    Injection("thermal_drift",
           "self-heating of the stator (loss ~ V0^2, time constant tens of s) shifts both resonances by "
           "about -10 Hz/K; the speed drifts along the experiment clock",
           "thermal_drift",
           {"Stator.thermal_tau_s": 30.0, "Stator.heating_K_per_V2": 6e-4,
            "Stator.df_dT_l_Hz_per_K": -10.0, "Stator.df_dT_b_Hz_per_K": -10.0},
           {"Stator.thermal_tau_s": (20.0, 40.0), "Stator.heating_K_per_V2": (4.5e-4, 8e-4)},
           stateful=True),
    Injection("direction_asymmetry",
           "CH1 and CH2 electrodes excite the B2 mode with different strength (polarisation, electrode "
           "area): forward and backward speeds differ",
           "direction_asymmetry",
           {"Stator.asym_b": 0.06}, {"Stator.asym_b": (0.04, 0.09)}),
    Injection("bar_waviness",
           "periodic waviness of the friction bar (grinding marks) modulates the preload with position",
           "bar_waviness",
           {"Stator.bar_wave_amp_m": 40e-6, "Stator.bar_wave_period_m": 6e-3},
           {"Stator.bar_wave_amp_m": (30e-6, 50e-6), "Stator.bar_wave_period_m": (4e-3, 8e-3)}),
    Injection("bar_bump",
           "a local bump (defect, debris) on the friction bar raises the preload over a few mm",
           "local_defect",
           {"Stator.bar_bump_amp_m": 80e-6, "Stator.bar_bump_center_m": 0.004, "Stator.bar_bump_width_m": 1.0e-3},
           {"Stator.bar_bump_amp_m": (60e-6, 100e-6), "Stator.bar_bump_center_m": (-0.012, 0.012),
            "Stator.bar_bump_width_m": (0.7e-3, 1.4e-3)}),
    Injection("pulley_friction",
           "Coulomb friction in the load path (pulley bearing), proportional to the load weight and "
           "always opposing the motion",
           "load_path_friction",
           {"Slider.pulley_mu": 0.4}, {"Slider.pulley_mu": (0.3, 0.5)}),
    Injection("drive_saturation",
           "the drive's output amplitude saturates (transformer / amplifier limit): the actual V0 falls "
           "below the commanded one at high voltage",
           "drive_saturation",
           {"Driver.V0_sat_V": 320.0}, {"Driver.V0_sat_V": (280.0, 360.0)}),
]}

#: effects of the measurement chain, applied to the recorded data (not to the FMU system; "DAQ." parameters)
DATA_INJECTIONS: dict[str, Injection] = {e.name: e for e in [
    Injection("speed_lowpass",
           "the DAQ's speed channel is low-pass filtered (first order, a few ms): the speed column lags "
           "the position's derivative (a measurement-chain effect, applied to the recorded data)",
           None,
           {"DAQ.speed_tau_s": 0.004}, {"DAQ.speed_tau_s": (0.003, 0.008)}, chain_regressor="speed"),
]}

DAQ_PREFIX = "DAQ."

#: effects that differ from run to run, applied by the rig per run ("Rig." parameters; not FMU parameters)
RUN_INJECTIONS: dict[str, Injection] = {e.name: e for e in [
    Injection("supply_sag",
           "the drive's DC bus differs from run to run (a shared supply, the mains); the amplifier's output "
           "amplitude follows the bus, which the rig logs as supply_V (a column no model of the loop names)",
           "channel",
           {"Rig.supply_nominal_V": 48.0, "Rig.supply_sd_rel": 0.04}, {"Rig.supply_sd_rel": (0.03, 0.05)},
           signal="supply_V"),
    Injection("preload_settling",
           "the clamp's preload settles traverse by traverse (creep of the clamp and the contact bedding in): "
           "each run's preload is lower than the last, constant along the stroke, not logged",
           "run_level",
           {"Rig.settling_depth_rel": 0.12, "Rig.settling_runs": 40.0},
           {"Rig.settling_depth_rel": (0.09, 0.15), "Rig.settling_runs": (25.0, 60.0)},
           signal="time_s"),
]}
RIG_PREFIX = "Rig."
#: the logged column of ``supply_sag`` and its sensor's noise [V] (one standard deviation per sample)
SUPPLY_COLUMN = "supply_V"
SUPPLY_SENSOR_SD_V = 0.05


def lowpass_speed(df: pd.DataFrame, tau_s: float) -> pd.DataFrame:
    """The speed column passed through a first-order low-pass (time constant ``tau_s``), run by run."""
    out = df.copy()
    v = out[dataio.SPEED].to_numpy(float).copy()
    t = out[dataio.TIME].to_numpy(float)
    for _, sl in dataio.run_slices(out[dataio.RUN]):
        for k in range(sl.start + 1, sl.stop):
            a = math.exp(-(t[k] - t[k - 1]) / tau_s)
            v[k] = a * v[k - 1] + (1 - a) * v[k]
    out[dataio.SPEED] = v
    return out


def apply_overrides(mp: MotorParams, overrides: dict) -> MotorParams:
    """MotorParams with ``{"Component.parameter": value}`` applied."""
    sections = {"Driver": "driver", "Stator": "stator", "Interface": "interface", "Slider": "slider"}
    changes = {}
    for key, value in overrides.items():
        comp, _, name = key.partition(".")
        if comp not in sections:
            raise SimulationError(f"override '{key}': unknown component '{comp}'")
        changes[f"{sections[comp]}__{name}"] = value
    return mp.replace(**changes)


def parse_injection(spec: str) -> tuple[str, dict]:
    """``"name"`` or ``"name:Component.param=value,..."`` -> (name, overrides)."""
    name, _, rest = spec.partition(":")
    known = {**INJECTIONS, **DATA_INJECTIONS, **RUN_INJECTIONS}
    if name not in known:
        raise SimulationError(f"unknown injection '{name}'; known: {', '.join(known)}")
    values = {}
    for item in filter(None, rest.split(",")):
        k, _, v = item.partition("=")
        if k not in known[name].params:
            raise SimulationError(f"injection '{name}' has no parameter '{k}' (has {', '.join(known[name].params)})")
        values[k] = float(v)
    return name, values


# ---------------------------------------------------------------------------
# Experiment plan and single runs
# ---------------------------------------------------------------------------

PAPER_LOADS_KG = (-0.09, -0.07, -0.05, -0.03, 0.0, 0.03, 0.05, 0.07, 0.09)


@dataclass(frozen=True)
class RigPlan:
    """What the rig runs: the paper's grid by default (4 V0 x 9 loads x 2 directions = 72 runs)."""

    voltages_V: tuple = (220.0, 255.0, 290.0, 324.0)
    loads_kg: tuple = PAPER_LOADS_KG
    directions: tuple = (1, -1)
    f_drive_Hz: float = 48500.0
    ambient_degC: float = 25.0
    sample_rate_Hz: float = 1000.0
    encoder_resolution_m: float = 5e-8
    pause_s: float = 1.0
    max_run_s: float = 4.0
    step_s: float = 2e-4
    record_temperature: bool = False
    shuffle: bool = True
    seed: int = 0
    #: standard deviation [m/s] of white noise on the DAQ's speed channel (pick-up, vibration of the
    #: sensor mount); drawn from ``seed``. 0: the speed is the clean derivative of the encoder position
    speed_noise_m_s: float = 0.0
    #: relative standard deviation of the contact's preload and friction coefficient from run to run (the
    #: contact re-seats, debris, wear, humidity: a real rig's run-to-run repeatability); two independent
    #: factors per run drawn from ``seed``. 0: every run alike
    run_scatter: float = 0.0
    #: drive frequencies [Hz] the rig records at (empty: every run at ``f_drive_Hz``): the (V0, load)
    #: conditions, in rig order, take them in turn, both directions of a condition at the same frequency
    frequencies_Hz: tuple = ()
    #: half-width [Hz] of a per-run frequency offset, uniform, drawn from ``seed`` (a drive that tracks the
    #: resonance settles at a slightly different frequency each run); 0: none
    frequency_jitter_Hz: float = 0.0

    def __post_init__(self):
        for name in ("speed_noise_m_s", "run_scatter", "frequency_jitter_Hz"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise SimulationError(f"RigPlan.{name} = {value!r}: must be a finite number >= 0")
        for f in self.frequencies_Hz:
            if not (math.isfinite(f) and f > 0):
                raise SimulationError(f"RigPlan.frequencies_Hz contains {f!r}: every frequency must be > 0 [Hz]")
        if self.run_scatter >= 0.25:
            raise SimulationError(f"RigPlan.run_scatter = {self.run_scatter!r} (relative contact std): "
                                  "must be below 0.25 (a contact factor must stay positive)")
        if not (math.isfinite(self.sample_rate_Hz) and self.sample_rate_Hz > 0):
            raise SimulationError(f"RigPlan.sample_rate_Hz = {self.sample_rate_Hz!r}: must be a finite number > 0 [Hz]")


@dataclass(frozen=True)
class RunSpec:
    run: int
    V0_V: float
    load_kg: float
    direction: int
    t_start_s: float = 0.0
    T_stator0_degC: float | None = None
    #: the run's drive frequency [Hz] (None: the plan's ``f_drive_Hz``)
    f_Hz: float | None = None
    #: the drive's supply relative to the operator's setting (``supply_sag``); 1: as set
    supply_factor: float = 1.0


def _simulate_inprocess(mp: MotorParams, spec: RunSpec, plan: RigPlan, V_s: float, s0: float):
    from ..cosim.engine import InProcessMotor
    m = InProcessMotor(mp, h_s=plan.step_s)
    if spec.T_stator0_degC is not None:
        m.b["Stator"].T_st0 = spec.T_stator0_degC
    m.initialize(V_s=V_s, f_s=run_frequency(spec, plan), T=plan.ambient_degC, direction=spec.direction,
                 m_load=spec.load_kg, s0=s0)
    rec = ("Slider.s", "Slider.v", "Stator.v_tip", "Stator.T_stator", "Slider.at_stop")
    res = m.run(plan.max_run_s, record=rec, until=lambda mm: mm.value("Slider.at_stop") == spec.direction)
    return {k: res[k] for k in ("time",) + rec}


def _simulate_fmu(mp: MotorParams, spec: RunSpec, plan: RigPlan, V_s: float, s0: float, fmu_dir):
    from ..cosim.master import CoSimulation
    from ..cosim.ssp import COMPONENT_PARAMS
    overrides = {f"{comp}.{k}": v for comp, attr in COMPONENT_PARAMS.items()
                 for k, v in asdict(getattr(mp, attr)).items()}
    start = {"Slider.s0": s0, "Stator.s": s0}
    if spec.T_stator0_degC is not None:
        start["Stator.T_st0"] = spec.T_stator0_degC
    rec = ["Slider.s", "Slider.v", "Stator.v_tip", "Stator.T_stator", "Slider.at_stop"]
    with CoSimulation(fmu_dir=fmu_dir, step_s=plan.step_s, parameters=overrides) as cs:
        res = cs.run(plan.max_run_s, inputs=dict(V_s=V_s, duty=1.0, f_s=run_frequency(spec, plan),
                                                 T=plan.ambient_degC, direction=float(spec.direction),
                                                 m_load=spec.load_kg),
                     record=rec, start_values=start,
                     stop_when=lambda v: v["Slider.at_stop"] == spec.direction)
    return {k: res[k] for k in ["time"] + rec}


def worker_fmu_dir(fmu_dir=None) -> Path:
    """The FMU folder to use in this process: ``fmu_dir`` if it exists here, else the per-user cache.

    The coordinating process passes the folder it built (or was given); a
    worker on another machine may not see it and builds the FMUs once into
    its own cache (:func:`l1b2.fmi.cache.ensure_fmus`), reused by later tasks.
    """
    global _WORKER_FMUS
    if fmu_dir is not None and Path(fmu_dir).is_dir():
        return Path(fmu_dir)
    if _WORKER_FMUS is None or not _WORKER_FMUS.is_dir():
        _WORKER_FMUS = ensure_fmus(log=None)
    return _WORKER_FMUS


_WORKER_FMUS: Path | None = None  # this process's fallback FMU folder (found or built once)


def simulate_traverse(mp: MotorParams, spec: RunSpec, plan: RigPlan = RigPlan(), engine: str = "inprocess",
                      fmu_dir=None, nominal: MotorParams | None = None) -> dict:
    """One traverse from rest at the end stop behind to the far one; the raw co-simulated series.

    Returns ``{"time", "Slider.s", "Slider.v", "Stator.v_tip", "Stator.T_stator", "Slider.at_stop"}``
    (numpy arrays at every communication step). The supply is set from the
    *nominal* motor's small-signal drive gain (what the operator calibrated),
    so an injected drive effect or a drawn driver tolerance is not compensated.
    """
    nominal = nominal or mp
    V_s = float(drv.supply_for_voltage_V(nominal.driver, spec.V0_V, 1.0, run_frequency(spec, plan),
                                         plan.ambient_degC))
    V_s *= float(spec.supply_factor)
    s0 = mp.slider.s_min_m if spec.direction > 0 else mp.slider.s_max_m
    if engine == "inprocess":
        return _simulate_inprocess(mp, spec, plan, V_s, s0)
    if engine == "fmu":
        return _simulate_fmu(mp, spec, plan, V_s, s0, worker_fmu_dir(fmu_dir))
    raise SimulationError(f"unknown engine '{engine}' (use 'inprocess' or 'fmu')")


def sampling_every(plan: RigPlan) -> int:
    """Simulation steps per DAQ sample (``1 / (sample_rate_Hz * step_s)``, an integer >= 1).

    Raises :class:`~l1b2.errors.SimulationError` when the step does not divide the sampling period.
    """
    every = round(1.0 / (plan.sample_rate_Hz * plan.step_s)) if plan.step_s > 0 else 0
    if every < 1 or abs(every * plan.sample_rate_Hz * plan.step_s - 1.0) > 1e-9:
        raise SimulationError(f"RigPlan.step_s = {plan.step_s!r} s does not divide the sampling period "
                              f"1/{plan.sample_rate_Hz:g} Hz: choose a step of 1/(k * sample rate), k = 1, 2, ...")
    return int(every)


def simulate_run(mp: MotorParams, spec: RunSpec, plan: RigPlan = RigPlan(), engine: str = "inprocess",
                 fmu_dir=None, nominal: MotorParams | None = None) -> pd.DataFrame:
    """One traverse; returns the rig's samples of this run (data-format columns plus extras).

    The supply is set from the *nominal* motor's small-signal drive gain (what
    the operator calibrated), so an injected drive effect is not compensated.
    """
    every = sampling_every(plan)
    r = simulate_traverse(mp, spec, plan, engine, fmu_dir, nominal)
    idx = np.arange(0, len(r["time"]), every)
    t = r["time"][idx]
    # encoder counts times the resolution, written with the digits they have (1 pm, 1 nm/s, 1 ns)
    pos = np.round(np.round(r["Slider.s"][idx] / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    speed = np.round(np.gradient(pos, t), 9) if len(t) > 1 else np.zeros_like(t)
    out = pd.DataFrame({
        dataio.TIME: np.round(spec.t_start_s + t, 9),
        dataio.RUN: spec.run,
        dataio.POSITION: pos,
        dataio.VOLTAGE: spec.V0_V,
        dataio.DIRECTION: spec.direction,
        dataio.LOAD: spec.load_kg,
        dataio.SPEED: speed,
        dataio.FREQUENCY: run_frequency(spec, plan),
    })
    if plan.record_temperature:
        out[dataio.TEMPERATURE] = np.round(r["Stator.T_stator"][idx], 2)
    out["tip_velocity_amp_m_s"] = np.round(r["Stator.v_tip"][idx], 9)
    out.attrs["T_stator_end"] = float(r["Stator.T_stator"][-1])
    return out


def plan_runs(plan: RigPlan) -> list[tuple[float, float, int]]:
    """Run conditions in rig order: shuffled (V0, load) pairs, each forward then backward."""
    conds = [(V, L) for V in plan.voltages_V for L in plan.loads_kg]
    if plan.shuffle:
        rng = np.random.default_rng(plan.seed)
        conds = [conds[i] for i in rng.permutation(len(conds))]
    return [(V, L, d) for V, L in conds for d in plan.directions]


def run_frequency(spec: RunSpec, plan: RigPlan) -> float:
    """The drive frequency of a run [Hz]: its own, else the plan's ``f_drive_Hz``."""
    return float(plan.f_drive_Hz if spec.f_Hz is None else spec.f_Hz)


def run_frequencies(plan: RigPlan, n_runs: int) -> np.ndarray:
    """Each run's drive frequency [Hz] in rig order (runs as :func:`plan_runs` gives them).

    The (V0, load) conditions take ``plan.frequencies_Hz`` in turn (both
    directions of a condition share it; the plan's ``f_drive_Hz`` without a
    list), plus a per-run offset uniform in +-``frequency_jitter_Hz`` from its
    own stream of ``plan.seed``. Rounded to 0.1 Hz (what the drive logs).
    """
    per_cond = max(1, len(plan.directions))
    cond = np.arange(n_runs) // per_cond
    freqs = np.asarray(plan.frequencies_Hz, float) if plan.frequencies_Hz else np.array([plan.f_drive_Hz])
    f = freqs[cond % freqs.size]
    if plan.frequency_jitter_Hz > 0:
        f = f + np.random.default_rng([plan.seed, 3]).uniform(-1.0, 1.0, n_runs) * plan.frequency_jitter_Hz
    return np.round(f, 1)


def run_contact_factors(plan: RigPlan, n_runs: int) -> np.ndarray:
    """Each run's contact factors, shape ``(n_runs, 2)``: preload ``P0`` and friction coefficient ``mu_p``.

    Each factor is 1 + ``run_scatter`` x an independent standard normal draw,
    from its own stream of ``plan.seed`` (not the run order's), so changing
    ``run_scatter`` scales the same draws.
    """
    z = np.random.default_rng([plan.seed, 1]).standard_normal((n_runs, 2))
    return 1.0 + plan.run_scatter * z


def scattered_motor(motor: MotorParams, factors) -> MotorParams:
    """``motor`` with one run's contact factors (preload, friction coefficient) applied."""
    return motor.replace(stator__P0_N=motor.stator.P0_N * float(factors[0]),
                         interface__mu_p=motor.interface.mu_p * float(factors[1]))


def add_speed_noise(df: pd.DataFrame, plan: RigPlan) -> pd.DataFrame:
    """The speed column plus white noise of standard deviation ``plan.speed_noise_m_s`` (from ``plan.seed``)."""
    if plan.speed_noise_m_s == 0:
        return df
    out = df.copy()
    z = np.random.default_rng([plan.seed, 2]).standard_normal(len(out))
    out[dataio.SPEED] = out[dataio.SPEED].to_numpy(float) + plan.speed_noise_m_s * z
    return out


def run_effects(plan: RigPlan, n_runs: int, values: dict) -> dict:
    """Per-run factors of the run injections (:data:`RUN_INJECTIONS`), from their ``"Rig."`` parameter values.

    Returns ``{"supply": (n_runs,) supply factors, "preload": (n_runs,) preload factors}`` (ones when off):
    the supply factor of run ``k`` is ``1 + supply_sd_rel z_k`` (``z`` standard normal from its own stream of
    ``plan.seed``); the preload factor of the ``k``-th traverse (0-based, rig order) is
    ``1 - depth (1 - exp(-k / settling_runs))``.
    """
    k = np.arange(n_runs, dtype=float)
    supply = np.ones(n_runs)
    if "Rig.supply_sd_rel" in values:
        z = np.random.default_rng([plan.seed, 3]).standard_normal(n_runs)
        supply = 1.0 + float(values["Rig.supply_sd_rel"]) * z
    preload = np.ones(n_runs)
    if "Rig.settling_depth_rel" in values:
        depth, runs = float(values["Rig.settling_depth_rel"]), float(values["Rig.settling_runs"])
        preload = 1.0 - depth * (1.0 - np.exp(-k / runs))
    return {"supply": supply, "preload": preload}


def log_supply(df: pd.DataFrame, plan: RigPlan, supply: np.ndarray, nominal_V: float) -> pd.DataFrame:
    """The frame with the logged bus voltage ``supply_V``: each run's ``nominal_V x factor`` plus sensor noise."""
    out = df.copy()
    runs = out[dataio.RUN].to_numpy()
    factor = supply[np.searchsorted(np.unique(runs), runs)]
    z = np.random.default_rng([plan.seed, 4]).standard_normal(len(out))
    out[SUPPLY_COLUMN] = np.round(nominal_V * factor + SUPPLY_SENSOR_SD_V * z, 3)
    return out


def is_stateful(motor: MotorParams, injected=()) -> bool:
    """Whether runs carry state from one to the next (then they run serially, in rig order).

    A stateful injection does; so does a motor whose stator heats up
    (``thermal_tau_s > 0``): each run starts at the temperature the previous
    one left after the pause.
    """
    return any(i["name"] in INJECTIONS and INJECTIONS[i["name"]].stateful for i in injected) \
        or motor.stator.thermal_tau_s > 0


def run_experiment(plan: RigPlan = RigPlan(), mp: MotorParams | None = None, injections=(), engine="inprocess",
                   jobs: int | None = None, fmu_dir=None, injection_seed: int | None = None, progress: bool = False,
                   *, workers: int = 1, scheduler: str | None = None):
    """Run the whole experiment; returns ``(DataFrame, truth)``.

    ``injections`` is a list of injection names or ``(name, overrides)`` pairs; with
    ``injection_seed`` the ranged effect parameters are drawn at random.
    With ``engine="fmu"`` and no ``fmu_dir``, the FMUs come from the per-user
    cache (:func:`l1b2.fmi.cache.ensure_fmus`, built once on demand).

    Runs are independent unless an injection (or the motor) carries state
    from run to run (:func:`is_stateful`): then they run serially in rig
    order. Otherwise, with ``workers >= 2`` or a ``scheduler`` address, they
    run on the Dask engine of :mod:`l1b2.cluster` (a local cluster of
    ``workers`` single-thread processes, or the cluster at ``scheduler``);
    the data are identical to a serial run. ``jobs`` is the deprecated name
    of ``workers``.
    """
    if jobs is not None:
        workers = jobs
    sampling_every(plan)  # refuse a step that does not divide the sampling period before any run
    nominal = mp or load_motor()
    if engine == "fmu" and fmu_dir is None:
        fmu_dir = ensure_fmus()
    rng = np.random.default_rng(injection_seed) if injection_seed is not None else None
    overrides, injected = {}, []
    known = {**INJECTIONS, **DATA_INJECTIONS, **RUN_INJECTIONS}
    for e in injections:
        name, user = (e, {}) if isinstance(e, str) else e
        if name not in known:
            raise SimulationError(f"unknown injection '{name}'; known: {', '.join(known)}")
        values = {**known[name].draw(rng), **user}
        overrides.update(values)
        injected.append({"name": name, "regressor": known[name].regressor, "parameters": values})
    daq = {k[len(DAQ_PREFIX):]: v for k, v in overrides.items() if k.startswith(DAQ_PREFIX)}
    motor = apply_overrides(nominal, {k: v for k, v in overrides.items()
                                      if not k.startswith((DAQ_PREFIX, RIG_PREFIX))})
    conditions = plan_runs(plan)
    factors = run_contact_factors(plan, len(conditions))
    freqs = run_frequencies(plan, len(conditions))
    per_run = run_effects(plan, len(conditions), overrides)
    motors = [motor if plan.run_scatter == 0 else scattered_motor(motor, f) for f in factors]
    motors = [m if p == 1.0 else m.replace(stator__P0_N=m.stator.P0_N * float(p))
              for m, p in zip(motors, per_run["preload"])]
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(conditions), desc=f"rig ({engine})", unit="run")
    try:
        if is_stateful(motor, injected) or (workers <= 1 and not scheduler):
            frames = _run_serially(motors, nominal, conditions, plan, engine, fmu_dir, bar, per_run["supply"],
                                   freqs)
        else:
            frames = _run_on_cluster(motors, nominal, conditions, plan, engine, fmu_dir, bar, workers, scheduler,
                                     per_run["supply"], freqs)
    finally:
        if bar:
            bar.close()
    df = pd.concat(frames, ignore_index=True)
    if "Rig.supply_sd_rel" in overrides:
        df = log_supply(df, plan, per_run["supply"], float(overrides["Rig.supply_nominal_V"]))
    df = add_speed_noise(df, plan)  # the sensor's noise, then the DAQ's filter (if injected) acts on it
    if "speed_tau_s" in daq:
        df = lowpass_speed(df, daq["speed_tau_s"])
    truth = {"injections": injected, "plan": asdict(plan), "engine": engine, "motor": nominal.name}
    if plan.run_scatter > 0:
        truth["run_contact_factors"] = {"P0": factors[:, 0].tolist(), "mu_p": factors[:, 1].tolist()}
    if any(k.startswith(RIG_PREFIX) for k in overrides):
        truth["run_factors"] = {"supply": per_run["supply"].tolist(), "preload": per_run["preload"].tolist()}
    return df, truth


def _run_serially(motors, nominal, conditions, plan, engine, fmu_dir, bar, supply, freqs=None) -> list:
    """The runs one after the other on one experiment clock; the stator temperature carried over."""
    frames, t_next, T_st = [], 0.0, plan.ambient_degC
    for k, (V, L, d) in enumerate(conditions):
        motor = motors[k]
        spec = RunSpec(k + 1, V, L, d, t_next, T_st if motor.stator.thermal_tau_s > 0 else None,
                       None if freqs is None else float(freqs[k]), float(supply[k]))
        f = simulate_run(motor, spec, plan, engine, fmu_dir, nominal)
        frames.append(f)
        t_next = float(f[dataio.TIME].iloc[-1]) + plan.pause_s
        if motor.stator.thermal_tau_s > 0:  # cools toward ambient during the pause
            T_st = plan.ambient_degC + (f.attrs["T_stator_end"] - plan.ambient_degC) * math.exp(
                -plan.pause_s / motor.stator.thermal_tau_s)
        if bar:
            bar.update()
    return frames


def _run_on_cluster(motors, nominal, conditions, plan, engine, fmu_dir, bar, workers, scheduler, supply,
                    freqs=None) -> list:
    """Independent runs on the Dask engine, then laid on one experiment clock in rig order."""
    from ..cluster import dask_client, run_tasks
    specs = [RunSpec(k + 1, V, L, d, f_Hz=None if freqs is None else float(freqs[k]),
                     supply_factor=float(supply[k])) for k, (V, L, d) in enumerate(conditions)]
    frames = [None] * len(specs)
    with dask_client(workers, scheduler) as client:
        where = None if fmu_dir is None else str(fmu_dir)
        args = [(m, s, plan, engine, where, nominal) for m, s in zip(motors, specs)]
        for i, f in run_tasks(simulate_run, args, client=client, name="l1b2-rig"):
            frames[i] = f
            if bar:
                bar.update()
    t_next = 0.0
    for f in frames:  # lay the runs on one experiment clock with pauses, as the serial rig does
        f[dataio.TIME] = np.round(f[dataio.TIME] + t_next, 9)
        t_next = float(f[dataio.TIME].iloc[-1]) + plan.pause_s
    return frames


# ---------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------

def sidecar_meta(mp: MotorParams, plan: RigPlan, description: str) -> dict:
    return {"slider_mass_kg": mp.slider.mass_kg, "encoder_resolution_m": plan.encoder_resolution_m,
            "drive_frequency_Hz": plan.f_drive_Hz, "description": description}


def write_experiment(df: pd.DataFrame, out_dir, mp: MotorParams, plan: RigPlan, truth: dict,
                     test_abs_loads=(0.05,)) -> dict:
    """Write ``all.csv``, the paper's ``train.csv``/``test.csv`` split and sidecars, and ``rig_truth.json``.

    A split with no runs (the plan has no load of ``test_abs_loads``, or only
    those) is not written; the returned dict names the files written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    meta = sidecar_meta(mp, plan, "virtual L1B2 rig (l1b2 rig): co-simulated reference motor")
    is_test = np.isclose(np.abs(df[dataio.LOAD].to_numpy()), np.array(test_abs_loads)[:, None], atol=1e-9).any(axis=0)
    paths = {}
    for name, part in (("all", df), ("train", df[~is_test]), ("test", df[is_test])):
        if len(part):  # a plan without the test loads has no test split
            paths[name] = dataio.write_measurements(part.reset_index(drop=True), out / f"{name}.csv", meta)
    (out / "rig_truth.json").write_text(dumps(truth))
    return paths
