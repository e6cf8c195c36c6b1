"""Replay measured runs through a co-simulated system (an ``.ssp``): the FMUs' free-run speed at the data's samples.

Each run of a data-format frame is simulated from rest at its first measured
position with its voltage, load and direction (supply set from the motor's
small-signal drive gain, as the rig's operator does), until its last sample
or the end stop; the slider speed is read at the run's sample times
(relative to its first). What the close-the-loop export is checked with: the
calibrated SSP's held-out free-run error beside the extended predictor's and
the uncalibrated SSP's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..cosim.master import CoSimulation
from ..data import measurements as dataio
from ..physics import driver as drv
from ..physics.params import MotorParams


def replay_runs(system: str | Path, df: pd.DataFrame, mp: MotorParams, *, step_s: float = 1e-3,
                ambient_degC: float = 25.0) -> np.ndarray:
    """Free-run speed [m/s] of ``system`` per sample of ``df``, run by run (see module docstring).

    ``mp``: the motor whose driver sets the supply for each run's V0 (the
    system's own parameters come from its parameter sets). After the end
    stop the speed is the last simulated one (0 at a stop).
    """
    out = np.zeros(len(df))
    t_all = df[dataio.TIME].to_numpy(float)
    with CoSimulation(system, step_s=step_s, keep_instances=True) as cs:
        for _, sl in dataio.run_slices(df[dataio.RUN]):
            run = df.iloc[sl]
            first = run.iloc[0]
            d = float(first[dataio.DIRECTION])
            f = float(first[dataio.FREQUENCY]) if dataio.FREQUENCY in run else mp.operating.f_drive_Hz
            V0 = float(first[dataio.VOLTAGE])
            V_s = float(drv.supply_for_voltage_V(mp.driver, V0, 1.0, f, ambient_degC))
            s0 = float(first[dataio.POSITION])
            t_rel = t_all[sl] - t_all[sl][0]
            res = cs.run(float(t_rel[-1]) + step_s,
                         inputs=dict(V_s=V_s, duty=1.0, f_s=f, T=ambient_degC, direction=d,
                                     m_load=float(first[dataio.LOAD])),
                         record=["Slider.v", "Slider.at_stop"], start_values={"Slider.s0": s0, "Stator.s": s0},
                         stop_when=lambda v: v["Slider.at_stop"] == d)
            v = np.asarray(res["Slider.v"], float)
            out[sl] = np.interp(t_rel, np.asarray(res["time"], float), v, right=v[-1])
    return out
