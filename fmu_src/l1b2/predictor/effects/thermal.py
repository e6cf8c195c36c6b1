"""Self-heating of the stator: its resonances move (about -10 Hz/K, docs/explanation/physics.md), the drive's force factor drifts.

* ``thermal_drift`` (time): ``dF = V0/V_ref * f(t)``, f a cubic spline in
  the session clock over TRAIN's time range (2 or 4 inner knots).
* ``thermal_drift_T`` (temperature): the same driven by a measured stator
  temperature, ``dF = V0/V_ref (a (T-T0) + b (T-T0)^2/10)``, T0 TRAIN's median.
"""

from __future__ import annotations

import numpy as np

from .base import Effect, bspline_basis, drive_gain, num, register, scaled, signal

#: the Stator parameters of self-heating and the resonances' temperature slopes
_HOME_T = ("Stator.df_dT_l_Hz_per_K", "Stator.df_dT_b_Hz_per_K")


@register
class ThermalDrift(Effect):
    kind = "thermal_drift"
    regressor = "time"
    signals = ("t",)
    description = "drive force factor drifting with the experiment clock (stator self-heating)"
    home = _HOME_T + ("Stator.thermal_tau_s",)

    def features(self, spec, x):
        u = scaled(signal(x, "t"), num(spec, "t_lo"), num(spec, "t_hi"))
        return drive_gain(x)[:, None] * bspline_basis(u, int(num(spec, "n_inner")))

    def grid(self, train):
        t0, t1 = train.time_range
        out = []
        for n_inner in (2, 4):
            k = n_inner + 4
            out.append(self.hypothesis([f"thermal_gain_{j}" for j in range(k)], ["N"] * k,
                                       {"t_lo": t0, "t_hi": t1, "n_inner": n_inner}, f"{k} splines in t"))
        return out


@register
class ThermalDriftT(Effect):
    kind = "thermal_drift_T"
    regressor = "temperature"
    signals = ("T",)
    description = "force factor drifting with the stator temperature"
    home = _HOME_T

    def features(self, spec, x):
        g = drive_gain(x)
        dT = signal(x, "T") - num(spec, "T_ref")
        return np.column_stack([g * dT, g * dT ** 2 / 10.0])

    def grid(self, train):
        if not train.has_temperature or train.temperature_ref is None:
            return []
        return [self.hypothesis(("thermal_gain_T", "thermal_gain_T2"), ("N/K", "N/K2"),
                                {"T_ref": float(train.temperature_ref)})]
