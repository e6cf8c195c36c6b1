"""``load_path_friction`` (load): Coulomb friction in the pulley, proportional to the hanging weight.

``dF = -a g |m_load|``, opposing the motion. Home: ``Slider.pulley_mu``,
the same law in both models (``pulley_mu g |m_load|``): the identified
coefficient is copied. It is identified inside its physical range
(:data:`MU_RANGE`).
"""

from __future__ import annotations

import numpy as np

from ...units import G_M_S2
from .base import Effect, register, signal


#: the physical range of a Coulomb coefficient: friction opposes the motion (>= 0) and is below sliding on dry
#: metal (1); the identification keeps ``pulley_mu`` inside it
MU_RANGE = (0.0, 1.0)


@register
class LoadPathFriction(Effect):
    kind = "load_path_friction"
    regressor = "load"
    signals = ("load",)
    description = "Coulomb friction in the load path, proportional to the hanging weight, opposing motion"
    home = ("Slider.pulley_mu",)

    def features(self, spec, x):
        return (-G_M_S2 * np.abs(signal(x, "load")))[:, None]

    def grid(self, train):
        return [self.hypothesis(("pulley_mu",), ("1",), {}, bounds=(MU_RANGE,))]

    def calibrate(self, effect, model, mp):
        from dataclasses import replace
        mu = max(0.0, float(effect.phi[0]))
        return replace(mp, slider=replace(mp.slider, pulley_mu=mu)), {
            "parameters": {"Slider.pulley_mu": mu},
            "reason": "same law in both models: the identified coefficient, copied"
                      + ("" if effect.phi[0] >= 0 else " (negative estimate clipped at 0)")}
