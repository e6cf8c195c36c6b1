"""A toy effect family defined outside the package, in this one file (used by ``test_effect_plugin.py``).

``toy_pulley`` restates the pulley's Coulomb friction (the rig's ``pulley_friction``
injection) as a user would write a new family: a force ``dF = -a g |m_load|``
opposing the motion, traced to the load, one parameter (the friction
coefficient per load weight), one shape, and a physical home,
``Slider.pulley_mu``, to which the identified coefficient is copied. It imports
only numpy and the family contract, so an export can ship this file inside
``Predictor.fmu``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from l1b2.predictor.effects import Effect, signal
from l1b2.units import G_M_S2


class ToyPulley(Effect):
    kind = "toy_pulley"
    regressor = "load"
    signals = ("load",)
    description = "toy: Coulomb friction of the load path per load weight"
    home = ("Slider.pulley_mu",)

    def features(self, spec, x):
        return (-G_M_S2 * np.abs(signal(x, "load")))[:, None]

    def grid(self, train):
        return [self.hypothesis(("toy_mu",), ("1",), {})]

    def calibrate(self, effect, model, mp):
        mu = max(0.0, float(effect.phi[0]))
        return replace(mp, slider=replace(mp.slider, pulley_mu=mu)), {
            "parameters": {"Slider.pulley_mu": mu}, "reason": "toy: the coefficient, copied"}
