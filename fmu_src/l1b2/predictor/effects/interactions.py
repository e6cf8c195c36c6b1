"""Effects of two regressors: named physical forms (``d`` the direction, ``m`` the signed load, ``g`` gravity).

* ``load_slope_voltage`` (load, voltage): slip friction whose speed slope
  changes with V0, ``dF = -a d m g (V0 - V_ref)/V_ref``;
* ``damping_voltage`` (speed, voltage): damping that changes with the drive
  amplitude, ``dF = -a (v/v_ref) (V0 - V_ref)/V_ref``;
* ``position_load`` (position, load): the load's effect varies along the bar
  (preload profile, pulley geometry), ``dF = -d m g (a x + b x^2)``, x the scaled position.

The first two are *structural* (:data:`EQ29_LINEARISATION`): Eq. 29 holds
the slope of the drive force over speed constant, while the pure-slip closed
form behind it (Eq. 25, ``F_d = sigma (omega U_w/pi - v/2) + mu F_p (2 sqrt(1
- k0^2) - 1)``, ``k0 = v/(omega U_w)``) has a slope that changes with
``omega U_w``, i.e. with V0. They relax that approximation of the paper's
model and are traced after the effects the model lacks.
"""

from __future__ import annotations

import numpy as np

from ...units import G_M_S2
from .base import SPEED_REF, V_REF, Effect, num, register, scaled, signal

#: the approximation of Eq. 29 that the structural interaction candidates relax
EQ29_LINEARISATION = ("Eq. 29 holds the drive force's slope over speed constant; by Eq. 25 it changes with "
                      "omega U_w, i.e. with V0 (load slope and damping depend on the voltage)")


def _voltage_offset(spec, x) -> np.ndarray:
    return (signal(x, "V0") - num(spec, "V_ref")) / V_REF


#: the drive-coordinate term ``d r`` of each regressor a structural voltage interaction scales: the load's
#: weight ``d m g`` [N] and the speed ``d v / SPEED_REF`` [1]
_SLOPE_TERMS = {"load": lambda x: signal(x, "d") * signal(x, "load") * G_M_S2,
                "speed": lambda x: signal(x, "d") * signal(x, "v_base") / SPEED_REF}


def voltage_slope_feature(regressor: str, spec, x) -> np.ndarray:
    """``-(d r) (V0 - V_ref)/V_REF`` as one feature column: the structural interaction of ``regressor``'s
    drive-coordinate term (:data:`_SLOPE_TERMS`) with the voltage."""
    return (-_SLOPE_TERMS[regressor](x) * _voltage_offset(spec, x))[:, None]


@register
class LoadSlopeVoltage(Effect):
    kind = "load_slope_voltage"
    regressor = "load"
    also = ("voltage",)
    signals = ("load",)
    group = "interaction"
    description = "the load's effect on the speed depends on the drive voltage"
    structural = EQ29_LINEARISATION

    def features(self, spec, x):
        return voltage_slope_feature(self.regressor, spec, x)

    def grid(self, train):
        return [self.hypothesis(("load_V_gain",), ("1",), {"V_ref": train.voltage_median})]


@register
class DampingVoltage(Effect):
    kind = "damping_voltage"
    regressor = "speed"
    also = ("voltage",)
    signals = ("v_base",)
    group = "interaction"
    description = "damping of the slider that changes with the drive voltage"
    structural = EQ29_LINEARISATION

    def features(self, spec, x):
        return voltage_slope_feature(self.regressor, spec, x)

    def grid(self, train):
        return [self.hypothesis(("damping_V_N",), ("N",), {"V_ref": train.voltage_median})]


@register
class PositionLoad(Effect):
    kind = "position_load"
    regressor = "position"
    also = ("load",)
    signals = ("s", "load")
    group = "interaction"
    description = "the load's effect varies along the bar"

    def features(self, spec, x):
        w = signal(x, "d") * signal(x, "load") * G_M_S2
        xp = 2 * scaled(signal(x, "s"), num(spec, "s_lo"), num(spec, "s_hi")) - 1
        return np.column_stack([-w * xp, -w * xp ** 2])

    def grid(self, train):
        s0, s1 = train.position_range
        return [self.hypothesis(("load_pos_1", "load_pos_2"), ("1", "1"), {"s_lo": float(s0), "s_hi": float(s1)})]
