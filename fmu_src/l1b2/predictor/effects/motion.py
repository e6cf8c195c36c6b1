"""Effects of the slider's motion, at the baseline's predicted speed and acceleration.

* ``speed_dependent_friction`` (speed): non-Newtonian film or air drag,
  ``dF = -(a v + b v |v|)`` (``v`` in drive coordinates, scaled by ``SPEED_REF``);
  ``b >= 0`` (:data:`DRAG_RANGES`), ``a`` of either sign.
* ``inertia_mismatch`` (acceleration): moving mass other than assumed (load
  inertia, coupling), ``dF = -a m_s dv/dt``, ``a > -1`` (:data:`MASS_ERROR_RANGE`).
"""

from __future__ import annotations

import numpy as np

from .base import SPEED_REF, Effect, num, register, signal


#: physical ranges of the drag parameters: the linear part corrects the baseline's damping (either sign); the
#: quadratic part is a drag (film, air) and opposes the motion (>= 0)
DRAG_RANGES = ((-np.inf, np.inf), (0.0, np.inf))
#: physical range of the relative mass error: the moving mass m_eff + a m_s stays positive (a > -1, m_eff >= m_s)
MASS_ERROR_RANGE = (-1.0, np.inf)


@register
class SpeedDependentFriction(Effect):
    kind = "speed_dependent_friction"
    regressor = "speed"
    signals = ("v_base",)
    description = "friction growing non-linearly with speed (film, air)"

    def features(self, spec, x):
        vp = signal(x, "d") * signal(x, "v_base")
        return np.column_stack([-vp / SPEED_REF, -vp * np.abs(vp) / SPEED_REF ** 2])

    def grid(self, train):
        return [self.hypothesis(("drag_lin_N", "drag_quad_N"), ("N", "N"), {}, bounds=DRAG_RANGES)]


@register
class InertiaMismatch(Effect):
    kind = "inertia_mismatch"
    regressor = "acceleration"
    signals = ("a_base",)
    description = "moving mass other than assumed"

    def features(self, spec, x):
        return (-num(spec, "m_s") * signal(x, "d") * signal(x, "a_base"))[:, None]

    def grid(self, train):
        return [self.hypothesis(("mass_error",), ("1",), {"m_s": float(train.m_s)}, bounds=(MASS_ERROR_RANGE,))]
