"""Design study: the motor's steady speed over drive frequency and V0, predictor against the coupled physics.

Engineers control a USM by its drive frequency: above the B2 resonance the
speed falls as the frequency rises, so a frequency setpoint is a speed
setpoint. :func:`frequency_map` computes that curve family at one
operating point (position, load, direction) twice: the identified
predictor's closed-form steady speed (Eq. 29 with the force factor scaled by
its frequency response, :mod:`l1b2.predictor.frequency`) and the coupled
periodic steady state of the physics (stator phasors with the interface fed
back and the slider force balance, :func:`l1b2.physics.steady.steady_state`,
the yardstick the co-simulation converges to). :func:`map_agreement` is the
figure of agreement, :func:`plot_frequency_map` the PNG figure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..errors import IdentificationError
from ..physics.params import MotorParams
from ..physics.steady import steady_state as physics_steady_state
from ..predictor.frequency import contact_angle, effective_voltage
from ..predictor.model import steady_state as predictor_steady_state
from ..predictor.setup import PredictorSetup

__all__ = ["frequency_map", "map_agreement", "plot_frequency_map", "FrequencyMap", "frequency_map_study"]


def frequency_map(setup: PredictorSetup, mp: MotorParams, frequencies_Hz, voltages_V, *, s_m: float = 0.0,
                  load_kg: float = 0.0, direction: int = 1) -> pd.DataFrame:
    """Steady speed [m/s] on the grid ``frequencies_Hz`` x ``voltages_V`` from the predictor and the physics.

    Columns: ``frequency_Hz``, ``voltage_V``, ``v_predictor_m_s``,
    ``v_physics_m_s`` (signed, data convention), ``stuck_physics``. A
    predictor without a frequency response predicts the same speed at every
    frequency; a pure-slip predictor whose response carries the contact law
    (:func:`l1b2.predictor.frequency.contact_angle`) uses its contact angles.
    """
    F, V = np.meshgrid(np.asarray(frequencies_Hz, float), np.asarray(voltages_V, float), indexing="ij")
    f, v0 = F.ravel(), V.ravel()
    V_eff = effective_voltage(v0, f, setup.frequency)
    fr = setup.frequency
    a = contact_angle(v0, f, fr) if fr is not None and fr.has_contact and setup.params.drive_law == "pure_slip" else None
    v_pred = predictor_steady_state(setup.params, s_m, V_eff, load_kg, direction, setup.slider_mass_kg, contact=a)
    phys = [physics_steady_state(mp, s_m, float(V0), load_kg, direction, f_Hz=float(fr)) for fr, V0 in zip(f, v0)]
    return pd.DataFrame({"frequency_Hz": f, "voltage_V": v0, "v_predictor_m_s": np.asarray(v_pred, float),
                         "v_physics_m_s": [direction * p.v_m_s for p in phys],
                         "stuck_physics": [p.stuck for p in phys]})


def map_agreement(df: pd.DataFrame) -> dict:
    """Figure of agreement of a :func:`frequency_map`: rms and max of predictor - physics, relative to the physics.

    ``rms_rel`` = rms(v_pred - v_phys) / rms(v_phys) over the grid points
    where the physics moves; ``max_abs_m_s``; and ``shape_rms_rel``: the
    same after scaling each voltage's predicted curve by its mean ratio to the
    physics (the curve's *shape* over frequency, free of an offset in level).
    """
    m = ~df["stuck_physics"].to_numpy(bool)
    vp, vh = df["v_predictor_m_s"].to_numpy(float)[m], df["v_physics_m_s"].to_numpy(float)[m]
    V = df["voltage_V"].to_numpy(float)[m]
    err = vp - vh
    shaped = vp.copy()
    for v0 in np.unique(V):
        k = V == v0
        shaped[k] = vp[k] * (np.sum(vh[k] * vp[k]) / np.sum(vp[k] * vp[k]))
    ref = float(np.sqrt(np.mean(vh * vh)))
    return {"points": int(m.sum()), "rms_rel": float(np.sqrt(np.mean(err * err)) / ref),
            "max_abs_m_s": float(np.max(np.abs(err))),
            "shape_rms_rel": float(np.sqrt(np.mean((shaped - vh) ** 2)) / ref)}


def plot_frequency_map(df: pd.DataFrame, title: str = ""):
    """Figure: steady speed [mm/s] over drive frequency [kHz], one colour per V0 (predictor lines, physics dots)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.2), layout="constrained")
    ax = fig.subplots()
    for i, (v0, g) in enumerate(df.groupby("voltage_V")):
        c = f"C{i}"
        ax.plot(g["frequency_Hz"] / 1e3, g["v_predictor_m_s"] * 1e3, "-", color=c, label=f"predictor {v0:g} V")
        ax.plot(g["frequency_Hz"] / 1e3, g["v_physics_m_s"] * 1e3, "o", color=c, ms=4, label=f"physics {v0:g} V")
    ax.set_xlabel("drive frequency [kHz]")
    ax.set_ylabel("steady speed [mm/s]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    if title:
        ax.set_title(title, fontsize=9)
    return fig


@dataclass(frozen=True)
class FrequencyMap:
    """A speed-over-frequency design study: the grid (:func:`frequency_map`), its agreement and operating point."""

    table: pd.DataFrame
    setup: PredictorSetup
    s_m: float
    load_kg: float
    direction: int

    @property
    def agreement(self) -> dict:
        """:func:`map_agreement` of the grid."""
        return map_agreement(self.table)

    def to_pandas(self) -> pd.DataFrame:
        """The grid: frequency [Hz], V0 [V], predicted and physical steady speed [m/s], stuck flag."""
        return self.table.copy()

    def figure(self):
        """:func:`plot_frequency_map` titled with the operating point and the rms difference."""
        return plot_frequency_map(self.table, f"position {self.s_m * 1e3:g} mm, load {self.load_kg:+g} kg, direction "
                                              f"{self.direction:+d}: rms difference {self.agreement['rms_rel']:.1%}")

    def to_dict(self) -> dict:
        """The JSON report: agreement, operating point, the predictor's frequency response and what is compared."""
        fr = self.setup.frequency
        return {"agreement": self.agreement,
                "operating_point": {"position_m": self.s_m, "load_kg": self.load_kg, "direction": self.direction},
                "frequency_response": None if fr is None else fr.to_dict(),
                "note": "physics: the coupled periodic steady state (l1b2.physics.steady.steady_state), the fixed "
                        "point of the co-simulation; predictor: the closed-form steady speed of Eq. 29 with the "
                        "force factor scaled by its frequency response"}


def frequency_map_study(identification: dict, mp: MotorParams, *, frequencies_Hz=None,
                        voltages_V=(220.0, 324.0), s_m: float = 0.0, load_kg: float = 0.0,
                        direction: int = 1) -> FrequencyMap:
    """The design study of an identification report (``l1b2 identify``'s ``identification.json`` as a dict).

    ``frequencies_Hz`` default: 41 points over TRAIN's frequency range
    (``checks.training_range``) or +-500 Hz around the nominal frequency.
    Raises :class:`~l1b2.errors.IdentificationError` when the report has no
    readable ``predictor`` section.
    """
    try:
        setup = PredictorSetup.from_dict(identification["predictor"])
    except (KeyError, TypeError, ValueError) as exc:
        raise IdentificationError(f"--identification: not an identification.json of `l1b2 identify` "
                                  f"({type(exc).__name__}: {exc})") from None
    if frequencies_Hz is None:
        rng = ((identification.get("checks") or {}).get("training_range") or {}).get("frequency_Hz")
        lo, hi = rng if rng and rng[1] > rng[0] else (setup.f_nominal_Hz - 500.0, setup.f_nominal_Hz + 500.0)
        frequencies_Hz = np.linspace(lo, hi, 41)
    table = frequency_map(setup, mp, frequencies_Hz, voltages_V, s_m=s_m, load_kg=load_kg, direction=direction)
    return FrequencyMap(table, setup, s_m, load_kg, direction)
