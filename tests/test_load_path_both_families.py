"""The named pulley form (``load_path_friction``) in both predictor families against the slider's physics.

The rig's pulley friction is a Coulomb level added to the guide's (``physics.slider.force_levels``: ``Fc``
grows by ``pulley_mu g |m|``). For a slider moving in its drive direction that is the same as the named
effect's force ``-pulley_mu g |m|`` added to the drive force, in Eq. 29 and in the pure-slip family alike
(the pure-slip family replaces only Eq. 29's frozen slip term; an extra force stays in the balance).
"""

import dataclasses

import numpy as np
import pytest

from l1b2.physics.slider import force_levels
from l1b2.predictor import model as pr
from l1b2.predictor.effects import effect_features
from l1b2.predictor.pureslip import slip_force, steady_drive_speed

M_S = 0.1
PULLEY_MU = 0.4
LOADS = np.array([-0.07, -0.03, 0.0, 0.03, 0.07])


def _grid():
    s, V0, load, d = np.meshgrid(np.linspace(-0.015, 0.015, 5), (220.0, 324.0), LOADS, (1.0, -1.0), indexing="ij")
    return s.ravel(), V0.ravel(), load.ravel(), d.ravel()


def _pulley_level(load):
    """The slider's Coulomb level with the pulley minus without it [N] (force_levels' ``Fc``)."""
    def fc(mu):
        return np.array([force_levels(0.0, 5.0, float(m), M_S, 1.0, mu, 0.1, 0.12, 0.5)[2] for m in load])
    return fc(PULLEY_MU) - fc(0.0)


def _named_force(load):
    return effect_features({"kind": "load_path_friction"}, {"load": load}) @ np.array([PULLEY_MU])


@pytest.mark.parametrize("law", ["eq29", "pure_slip"])
def test_named_pulley_steady_speed_is_the_slider_coulomb_level(law):
    p = dataclasses.replace(pr.example_params(3), drive_law=law)
    s, V0, load, d = _grid()
    v = pr.steady_state(p, s, V0, load, d, M_S, extra_force=_named_force(load))
    # independent: the family's own balance with the guide's Coulomb level raised by the slider's pulley level
    D, X, Fr = pr.force_parts(p, s, V0, d * load, M_S)
    Fr = Fr + _pulley_level(load)
    if law == "pure_slip":
        muP, Ap, c_k, frozen = pr.slip_terms(p, s, V0)
        ref = steady_drive_speed(D, X - frozen, muP, Ap, c_k, Fr)
    else:
        ref = (X - Fr) / D          # Eq. 29's closed form, forward branch
    assert np.all(ref > 0.01)       # every case moves in its drive direction (where the two laws agree)
    np.testing.assert_allclose(d * v, ref, rtol=1e-9, atol=1e-12)
    # and the pulley slows every loaded run: the effect is in the balance, not lost in the family's own term
    v0 = pr.steady_state(p, s, V0, load, d, M_S)
    assert np.all((d * v0 - d * v)[load != 0] > 1e-4) and np.allclose(v0[load == 0], v[load == 0])


@pytest.mark.parametrize("law", ["eq29", "pure_slip"])
def test_named_pulley_one_step_is_the_slider_coulomb_level(law):
    p = dataclasses.replace(pr.example_params(3), drive_law=law)
    s, V0, load, d = _grid()
    vp = np.full(s.shape, 0.08)           # moving in the drive direction
    dt = 1e-3
    v1 = pr.one_step(p, d * vp, s, V0, load, d, dt, M_S, extra_force=_named_force(load))
    D, X, Fr = pr.force_parts(p, s, V0, d * load, M_S)
    if law == "pure_slip":      # the drive force with the slip ratio of the state, written out
        muP, Ap, c_k, frozen = pr.slip_terms(p, s, V0)
        X = X - frozen + slip_force(vp, muP, Ap, c_k)[0]
    F = -D * vp + X - (Fr + _pulley_level(load))
    ref = vp + dt / (M_S + np.abs(load)) * F
    np.testing.assert_allclose(d * v1, ref, rtol=1e-12, atol=1e-15)
