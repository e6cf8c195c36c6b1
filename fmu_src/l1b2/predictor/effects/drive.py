"""``drive_saturation`` (voltage): the drive's output limits or has a threshold.

The force factor is not proportional to V0: ``dF = a (V0/V_ref)^2 + b (V0/V_ref)^3``.
"""

from __future__ import annotations

import numpy as np

from .base import Effect, drive_gain, register


@register
class DriveSaturation(Effect):
    kind = "drive_saturation"
    regressor = "voltage"
    description = "drive output not proportional to the commanded V0 (saturation or threshold)"

    def features(self, spec, x):
        g = drive_gain(x)
        return np.column_stack([g ** 2, g ** 3])

    def grid(self, train):
        return [self.hypothesis(("sat_quad_N", "sat_cubic_N"), ("N", "N"), {})]
