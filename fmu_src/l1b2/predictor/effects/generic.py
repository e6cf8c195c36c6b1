"""Generic smooth terms, for residual structure that no named family explains.

* ``smooth`` (one regressor, :data:`REGRESSORS`): splines in time, position,
  temperature and |baseline speed|; the regressor's own low-order basis for
  direction, load, voltage and acceleration. Report family ``smooth_<regressor>``.
* ``smooth_pair`` (two regressors): the products of their linear and
  quadratic terms scaled to [-1, 1] (direction: itself). Report family
  ``smooth_<a>_x_<b>``; the pairs (load, voltage) and (voltage, speed) are
  structural (:data:`l1b2.predictor.effects.interactions.EQ29_LINEARISATION`).
"""

from __future__ import annotations

import numpy as np

from .base import Effect, EffectSpecError, bspline_basis, num, register, scaled, signal
from .interactions import EQ29_LINEARISATION

#: regressor -> the signals it reads (besides V0 and d), in the order the generic library lists them
REGRESSOR_SIGNALS = {"time": ("t",), "position": ("s",), "direction": ("d",), "load": ("load", "d"),
                     "voltage": ("V0",), "speed": ("v_base",), "acceleration": ("a_base", "d"),
                     "temperature": ("T",)}
REGRESSORS = tuple(REGRESSOR_SIGNALS)
#: the regressors of the pair terms, in the order their pairs are listed
PAIR_REGRESSORS = ("time", "position", "direction", "load", "voltage", "speed")
_LINEARISATION_PAIRS = ({"load", "voltage"}, {"voltage", "speed"})


def _regressor(spec, key):
    r = spec.get(key)
    if r not in REGRESSOR_SIGNALS:
        raise EffectSpecError(f"effect spec {spec.get('kind')!r}: {key} = {r!r} is not a regressor "
                              f"({', '.join(REGRESSOR_SIGNALS)})")
    return r


def _lin_quad(u):
    return np.column_stack([u, u ** 2])


def _factor(reg: str, spec, x) -> np.ndarray:
    """The linear and quadratic terms of one regressor scaled to [-1, 1] (direction: itself), for pair terms."""
    if reg == "time":
        return _lin_quad(2 * scaled(signal(x, "t"), num(spec, "t_lo"), num(spec, "t_hi")) - 1)
    if reg == "position":
        return _lin_quad(2 * scaled(signal(x, "s"), num(spec, "s_lo"), num(spec, "s_hi")) - 1)
    if reg == "direction":
        return signal(x, "d")[:, None]
    if reg == "load":
        return _lin_quad(signal(x, "d") * signal(x, "load") / num(spec, "load_abs"))
    if reg == "voltage":
        return _lin_quad(2 * scaled(signal(x, "V0"), num(spec, "V_lo"), num(spec, "V_hi")) - 1)
    if reg == "speed":
        return _lin_quad(2 * scaled(np.abs(signal(x, "v_base")), num(spec, "v_lo"), num(spec, "v_hi")) - 1)
    raise EffectSpecError(f"regressor {reg!r} has no pair factor (pairs of: {', '.join(PAIR_REGRESSORS)})")


def _single(reg: str, spec, x) -> np.ndarray:
    """The generic smooth term of one regressor."""
    if reg == "time":
        return bspline_basis(scaled(signal(x, "t"), num(spec, "t_lo"), num(spec, "t_hi")), 6)
    if reg == "position":
        return bspline_basis(scaled(signal(x, "s"), num(spec, "s_lo"), num(spec, "s_hi")), int(num(spec, "n_inner")))
    if reg == "direction":
        return signal(x, "d")[:, None]
    if reg == "load":
        m = signal(x, "load") / num(spec, "load_abs")
        dm = signal(x, "d") * m
        return np.column_stack([dm, np.abs(m), dm ** 2])
    if reg == "voltage":
        return _lin_quad(2 * scaled(signal(x, "V0"), num(spec, "V_lo"), num(spec, "V_hi")) - 1)
    if reg == "speed":
        return bspline_basis(scaled(np.abs(signal(x, "v_base")), num(spec, "v_lo"), num(spec, "v_hi")), 4)
    if reg == "acceleration":
        acc = signal(x, "d") * signal(x, "a_base") * num(spec, "m_s")
        return np.column_stack([acc, np.abs(acc)])
    if reg == "temperature":
        return bspline_basis(scaled(signal(x, "T"), num(spec, "T_lo"), num(spec, "T_hi")), 4)
    raise EffectSpecError(f"no generic term for regressor {reg!r}")


@register
class Smooth(Effect):
    kind = "smooth"
    group = "generic"

    def needs(self, spec):
        return super().needs(spec) | set(REGRESSOR_SIGNALS[_regressor(spec, "regressor")])

    def features(self, spec, x):
        return _single(_regressor(spec, "regressor"), spec, x)

    def grid(self, train):
        s0, s1 = train.position_range
        ranges = dict(train.ranges)
        ranges["n_inner"] = int(np.clip(round((s1 - s0) / 1.5e-3), 4, 40))
        ranges["m_s"] = float(train.m_s)
        available = ["time", "position", "direction", "load", "voltage", "speed", "acceleration"]
        if train.has_temperature:
            ranges.update(T_lo=float(train.temperature_range[0]), T_hi=float(train.temperature_range[1]))
            available.append("temperature")
        out = []
        for reg in REGRESSORS:
            if reg not in available:
                continue
            spec = {"regressor": reg, **ranges}
            k = self.width({"kind": self.kind, **spec})
            out.append(self.hypothesis([f"smooth_{reg}_{j}" for j in range(k)], ["N"] * k, spec,
                                       family=f"smooth_{reg}", regressor=reg, generic=True,
                                       description=f"generic smooth force in {reg} (no named effect)"))
        return out


@register
class SmoothPair(Effect):
    kind = "smooth_pair"
    group = "generic_interaction"

    def needs(self, spec):
        return (super().needs(spec) | set(REGRESSOR_SIGNALS[_regressor(spec, "a")])
                | set(REGRESSOR_SIGNALS[_regressor(spec, "b")]))

    def features(self, spec, x):
        A = _factor(_regressor(spec, "a"), spec, x)
        B = _factor(_regressor(spec, "b"), spec, x)
        return np.column_stack([A[:, j] * B[:, k] for j in range(A.shape[1]) for k in range(B.shape[1])])

    def grid(self, train):
        out = []
        for i, a in enumerate(PAIR_REGRESSORS):
            for b in PAIR_REGRESSORS[i + 1:]:
                spec = {"a": a, "b": b, **train.ranges}
                k = self.width({"kind": self.kind, **spec})
                out.append(self.hypothesis([f"smooth_{a}_x_{b}_{j}" for j in range(k)], ["N"] * k, spec,
                                           family=f"smooth_{a}_x_{b}", regressor=a, also=(b,), generic=True,
                                           description=f"generic smooth interaction of {a} and {b}",
                                           structural=EQ29_LINEARISATION if {a, b} in _LINEARISATION_PAIRS else ""))
        return out
