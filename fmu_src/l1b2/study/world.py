"""The rig worlds of the studies, generated in memory (nothing is written).

A world is a motor (the realistic variant by default) and the rig's noise; a
seed sets the run order, the noise, the run-to-run scatter of the contact and
the draws of the injected effects (``injection_seed``), exactly as the
close-the-loop tests make their data. TRAIN/TEST is the paper's split
(TEST = the runs at |load| 0.05 kg).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path

from ..data.measurements import Measurements, split_by_load
from ..physics.params import SYSTEM_MODELS_DIR, load_motor
from ..rig.experiment import PAPER_LOADS_KG, RigPlan, apply_overrides, run_experiment, sidecar_meta

#: the motor file of each world (None: the embedded reference motor)
WORLD_MOTORS = {"reference": None, "realistic": "realistic_motor.toml"}


@dataclass(frozen=True)
class World:
    """A rig world: motor, rig noise and the experiment plan's grid (the paper's 72 runs by default).

    ``speed_noise_m_s`` and ``run_scatter`` are :class:`l1b2.rig.experiment.RigPlan`'s;
    the realistic world's defaults are the close-the-loop tests' (1 mm/s, 2 %).
    """

    motor: str = "realistic"
    speed_noise_m_s: float = 1e-3
    run_scatter: float = 0.02
    voltages_V: tuple = (220.0, 255.0, 290.0, 324.0)
    loads_kg: tuple = PAPER_LOADS_KG
    step_s: float = 1e-3
    #: the rig's drive frequencies and per-run jitter [Hz] (:class:`l1b2.rig.experiment.RigPlan`; empty: one)
    frequencies_Hz: tuple = ()
    frequency_jitter_Hz: float = 0.0

    def plan(self, seed: int) -> RigPlan:
        return RigPlan(voltages_V=tuple(self.voltages_V), loads_kg=tuple(self.loads_kg), step_s=self.step_s,
                       seed=int(seed), speed_noise_m_s=self.speed_noise_m_s, run_scatter=self.run_scatter,
                       frequencies_Hz=tuple(self.frequencies_Hz), frequency_jitter_Hz=self.frequency_jitter_Hz)

    def motor_params(self):
        name = WORLD_MOTORS[self.motor]
        return load_motor(SYSTEM_MODELS_DIR / name) if name else load_motor()

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> World:
        return replace(cls(), **{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})


def world_data(world: World, seed: int, injections=(), motor_overrides=None
               ) -> tuple[Measurements, Measurements, dict]:
    """``(train, test, truth)`` of one seed: the rig run in this process, split as in the paper.

    ``injections``: names or ``(name, overrides)`` pairs (:func:`l1b2.rig.experiment.run_experiment`),
    the ranged parameters drawn from ``seed``; ``motor_overrides``: ``{"Component.parameter": value}``
    applied to the world's motor (a motor parameter the study varies itself, e.g. the B2 resonance).
    """
    mp = world.motor_params()
    if motor_overrides:
        mp = apply_overrides(mp, motor_overrides)
    plan = world.plan(seed)
    df, truth = run_experiment(plan, mp, injections=list(injections), engine="inprocess", injection_seed=seed)
    meas = Measurements(df, {**sidecar_meta(mp, plan, f"{world.motor} world, seed {seed}"), "source": None,
                             "sidecar": None}, Path(f"<{world.motor} world seed {seed}>"))
    train, test = split_by_load(meas)
    return train, test, truth
