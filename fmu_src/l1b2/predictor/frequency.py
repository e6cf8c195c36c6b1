"""The drive frequency as an input of the reduced predictor: the B2 response of Eq. 26 in the force factor.

By Eq. 30 the force factor is ``B = 2 T^-1 sigma A_b T_s / (Theta^-1 + 0.5 sigma omega eta_T)`` with
Theta (Eq. 26) proportional to the B2 mode's magnitude response

    |H(f)| = ((1 - (f/f_b0)^2)^2 + (2 zeta_b f/f_b0)^2)^(-1/2)

and ``T^-1 = f``. The interface term ``0.5 sigma omega eta_T`` only adds damping to the resonance; it is
absorbed in an *effective* ``zeta_b`` (and ``f_b0``) identified from the rig's data. The predictor's
force factor at drive frequency ``f`` is therefore

    B'(s, f) = B'(s) g(f),   g(f) = (f |H(f)|) / (f_ref |H(f_ref)|)

normalised at the reference (nominal) drive frequency ``f_ref``: ``g(f_ref) = 1`` exactly, so a model
identified at one frequency is the model without a frequency response. Only B' carries the response
(the drive's force), A' (the interface's speed feedback, also proportional to Theta in Eq. 30) is held
at its value at ``f_ref``: see docs/decisions/0017-drive-frequency-input.md. Since V0 enters Eq. 29
only through ``B' V0``, the model with a response is the model without one evaluated at the effective
drive amplitude ``V0 g(f)`` (:func:`effective_voltage`), which is how the identification, the free run
and ``Predictor.fmu`` apply it. ``k0 = v/(omega U_w)`` stays one constant: the paper observes ``v``
proportional to ``omega U_w``, and the data determine only its combination with mu.

Units: frequencies in Hz, ``zeta_b`` dimensionless; all functions are pure and vectorised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

__all__ = ["FrequencyResponse", "b2_magnitude", "frequency_gain", "effective_voltage", "sample_frequency"]


def b2_magnitude(f, f_b0, zeta_b):
    """|H(f)| = ((1 - r^2)^2 + (2 zeta_b r)^2)^(-1/2), r = f/f_b0 (Eq. 13/26 without K_b and phi_b) [-]."""
    r = np.asarray(f, float) / np.asarray(f_b0, float)
    return 1.0 / np.sqrt((1.0 - r * r) ** 2 + (2.0 * np.asarray(zeta_b, float) * r) ** 2)


def frequency_gain(f, f_ref, f_b0, zeta_b):
    """g(f) = f |H(f)| / (f_ref |H(f_ref)|): the force factor at ``f`` relative to ``f_ref`` (Eq. 26, 30) [-]."""
    f = np.asarray(f, float)
    return f * b2_magnitude(f, f_b0, zeta_b) / (float(f_ref) * b2_magnitude(float(f_ref), f_b0, zeta_b))


@dataclass(frozen=True)
class FrequencyResponse:
    """The predictor's drive-frequency response: B2 resonance ``f_b0_Hz``, damping ``zeta_b``, reference ``f_ref_Hz``.

    ``f_ref_Hz`` is the nominal drive frequency at which the gain is 1 (the
    rig's ``drive_frequency_Hz``); ``f_b0_Hz`` and ``zeta_b`` are effective
    values identified from data (see the module docstring).
    """

    f_ref_Hz: float
    f_b0_Hz: float
    zeta_b: float

    def __post_init__(self):
        for name in ("f_ref_Hz", "f_b0_Hz", "zeta_b"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"FrequencyResponse.{name} = {v!r}: must be finite and > 0")
            object.__setattr__(self, name, v)

    def gain(self, f_Hz) -> np.ndarray:
        """g(f) per sample [-] (1 at ``f_ref_Hz``)."""
        return frequency_gain(f_Hz, self.f_ref_Hz, self.f_b0_Hz, self.zeta_b)

    def to_dict(self) -> dict[str, Any]:
        return {"f_ref_Hz": self.f_ref_Hz, "f_b0_Hz": self.f_b0_Hz, "zeta_b": self.zeta_b,
                "units": {"f_ref_Hz": "Hz", "f_b0_Hz": "Hz", "zeta_b": "1"}}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> "FrequencyResponse | None":
        if d is None:
            return None
        return cls(float(d["f_ref_Hz"]), float(d["f_b0_Hz"]), float(d["zeta_b"]))


def effective_voltage(V0, f_Hz, response: FrequencyResponse | None) -> np.ndarray:
    """``V0 g(f)`` [V]: the drive amplitude the frequency-free Eq. 29 needs (``V0`` itself without a response)."""
    V0 = np.asarray(V0, float)
    if response is None:
        return V0
    return V0 * response.gain(f_Hz)


def sample_frequency(frame, f_default: float | None) -> np.ndarray | None:
    """Each sample's drive frequency [Hz]: the ``frequency_Hz`` column, else ``f_default`` everywhere (or None)."""
    if frame is not None and "frequency_Hz" in getattr(frame, "columns", ()):
        return np.asarray(frame["frequency_Hz"], float)
    if f_default is None:
        return None
    return np.full(len(frame), float(f_default))
