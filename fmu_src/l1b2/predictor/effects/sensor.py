"""The speed sensor's gain along the stroke: an effect of the measurement, not of the motor.

A rig measures the slider's position through a transducer (an encoder's scale, an LVDT, a draw-wire, a laser)
whose scale factor is not exactly constant along the stroke (non-linearity, cosine error, a misaligned scale).
Such an error leaves the motor's dynamics alone: the slider's true speed obeys the model, and the recorded one is

    ``v_rec = g(s) v_true``,  ``g(s) = 1 + sum_j c_j P_j(x)``,  ``x = 2 (s - s_lo)/(s_hi - s_lo) - 1``

with ``P_j`` the Legendre polynomials of degree ``j = 0..order`` in the scaled recorded position ``x`` (clipped to
[-1, 1]) and ``c_j`` [1] dimensionless coefficients (``c = 0``: a perfect sensor). The recorded position is the
integral of the recorded speed, a smooth warp of the true one; the model reads its position-dependent terms at the
recorded position, whose smooth bases absorb that warp.

So the gain multiplies the model's predicted speed, not its state derivative: the free run with the gain is the
plain free run times ``g(s)`` at the recorded positions (:meth:`SpeedSensorGain.apply`), and its response to
``c_j`` is ``P_j(x) v`` directly, with no recursion through the dynamics (:meth:`SpeedSensorGain.response`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from numpy.polynomial.legendre import legvander

#: degree of the gain's Legendre series in the scaled position (cubic: the smooth curvature of a transducer's
#: non-linearity over one stroke)
STROKE_GAIN_ORDER = 3


def stroke_basis(s, s_lo: float, s_hi: float, order: int = STROKE_GAIN_ORDER) -> np.ndarray:
    """``(n, order + 1)``: ``P_j(x)``, ``x = 2 (s - s_lo)/(s_hi - s_lo) - 1`` clipped to [-1, 1] (``s`` [m])."""
    s = np.asarray(s, float).ravel()
    x = np.clip(2.0 * (s - s_lo) / (s_hi - s_lo) - 1.0, -1.0, 1.0) if s_hi > s_lo else np.zeros(len(s))
    return legvander(x, int(order))


@dataclass(frozen=True)
class SpeedSensorGain:
    """The recorded speed's gain along the stroke, ``g(s) = 1 + stroke_basis(s) @ coef`` [1].

    ``s_lo``/``s_hi`` [m]: the position range the basis is scaled to (TRAIN's); ``coef``: ``c_0..c_order`` [1];
    ``stderr``: their standard errors (None: not known).
    """

    s_lo: float
    s_hi: float
    coef: tuple
    stderr: tuple | None = None

    @property
    def order(self) -> int:
        return len(self.coef) - 1

    def names(self) -> tuple:
        """Parameter names ``sensor_gain_c0..`` (one per coefficient)."""
        return tuple(f"sensor_gain_c{j}" for j in range(len(self.coef)))

    def basis(self, s) -> np.ndarray:
        """:func:`stroke_basis` at the recorded positions ``s`` [m]."""
        return stroke_basis(s, self.s_lo, self.s_hi, self.order)

    def gain(self, s) -> np.ndarray:
        """``g(s)`` per sample [1]."""
        return 1.0 + self.basis(s) @ np.asarray(self.coef, float)

    def apply(self, s, v) -> np.ndarray:
        """The recorded speed ``g(s) v`` [m/s] of the slider's speed ``v`` [m/s] at recorded positions ``s`` [m]."""
        return self.gain(s) * np.asarray(v, float)

    def remove(self, s, v_rec) -> np.ndarray:
        """The slider's speed ``v_rec / g(s)`` [m/s] behind a recorded speed ``v_rec`` [m/s] (the inverse of
        :meth:`apply`; ``g`` must be positive, as a sensor's gain is)."""
        return np.asarray(v_rec, float) / self.gain(s)

    def response(self, s, v) -> np.ndarray:
        """``(n, order + 1)``: ``d (g v)/d c_j = P_j(x) v`` [m/s per unit of c_j], exact (linear in ``c``)."""
        return self.basis(s) * np.asarray(v, float).ravel()[:, None]

    def to_dict(self) -> dict:
        return {"s_lo": float(self.s_lo), "s_hi": float(self.s_hi), "coef": [float(c) for c in self.coef],
                "stderr": None if self.stderr is None else [None if e is None else float(e) for e in self.stderr]}

    @classmethod
    def from_dict(cls, d: Mapping) -> SpeedSensorGain:
        se = d.get("stderr")
        return cls(float(d["s_lo"]), float(d["s_hi"]), tuple(float(c) for c in d["coef"]),
                   None if se is None else tuple(None if e is None else float(e) for e in se))
