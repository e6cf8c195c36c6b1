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

import numpy as np
import pandas as pd

from ..physics.params import MotorParams
from ..physics.steady import steady_state as physics_steady_state
from ..predictor.frequency import effective_voltage
from ..predictor.model import steady_state as predictor_steady_state
from ..predictor.setup import PredictorSetup

__all__ = ["frequency_map", "map_agreement", "plot_frequency_map"]


def frequency_map(setup: PredictorSetup, mp: MotorParams, frequencies_Hz, voltages_V, *, s_m: float = 0.0,
                  load_kg: float = 0.0, direction: int = 1) -> pd.DataFrame:
    """Steady speed [m/s] on the grid ``frequencies_Hz`` x ``voltages_V`` from the predictor and the physics.

    Columns: ``frequency_Hz``, ``voltage_V``, ``v_predictor_m_s``,
    ``v_physics_m_s`` (signed, data convention), ``stuck_physics``. A
    predictor without a frequency response predicts the same speed at every
    frequency.
    """
    F, V = np.meshgrid(np.asarray(frequencies_Hz, float), np.asarray(voltages_V, float), indexing="ij")
    f, v0 = F.ravel(), V.ravel()
    V_eff = effective_voltage(v0, f, setup.frequency)
    v_pred = predictor_steady_state(setup.params, s_m, V_eff, load_kg, direction, setup.slider_mass_kg)
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
