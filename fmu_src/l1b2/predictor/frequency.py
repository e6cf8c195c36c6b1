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

The contact's L1 dependence (optional, ``f_l0_Hz`` and ``contact_V`` of the response; decisions 0034,
0038): the normal (L1) tip amplitude is driven by the same V0 through the L1 mode,
``U_l = u_l V0 g_l(f)``, ``g_l(f) = |H_l(f)| / |H_l(f_ref)|`` (a single mode's magnitude, resonance
``f_l0_Hz``, damping :data:`ZETA_L`; the contact's stiffening absorbed in the effective ``f_l0_Hz``), and
the interface's contact condition (Eq. 18, :func:`l1b2.physics.interface.contact_half_angle_rad`: the
normal force ``k_e (U_l sin theta - ...)`` is positive over the half angle ``a`` whose period mean is the
preload) gives

    rho(a) = sin a - a cos a = pi F_p / (k_e U_l) = contact_V / (V0 g_l(f)),   contact_V = pi F_p / (k_e u_l)

so ``contact_V`` [V] is the drive amplitude whose contact is half a period (``a = pi/2``) at ``f_ref``;
the preload F_p is the rig's nominal one (its position profile is not carried: one angle per operating
point). :func:`contact_angle` solves it once per distinct (V0, f) pair. Without these two fields the
contact is ``a = pi/2`` everywhere: the model without a contact law.

Units: frequencies in Hz, ``zeta_b`` dimensionless; all functions are pure and vectorised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..physics.interface import contact_half_angle_rad

__all__ = ["FrequencyResponse", "b2_magnitude", "frequency_gain", "effective_voltage", "sample_frequency", "ZETA_L",
           "contact_angle"]

#: damping ratio of the L1 response in the contact law: held, not estimated (decision 0034: with the L1
#: resonance 1-3 kHz above the drive the data do not determine it; the order of a mounted stator's mode)
ZETA_L = 0.01


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
    #: the contact law (module docstring): L1 resonance [Hz] and the amplitude of a half-period contact [V]
    f_l0_Hz: float | None = None
    contact_V: float | None = None

    def __post_init__(self):
        if (self.f_l0_Hz is None) != (self.contact_V is None):
            raise ValueError("FrequencyResponse: f_l0_Hz and contact_V are given together or not at all")
        for name in ("f_ref_Hz", "f_b0_Hz", "zeta_b") + (("f_l0_Hz", "contact_V") if self.has_contact else ()):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"FrequencyResponse.{name} = {v!r}: must be finite and > 0")
            object.__setattr__(self, name, v)

    @property
    def has_contact(self) -> bool:
        """Whether the response carries the contact law (``f_l0_Hz``, ``contact_V``)."""
        return self.f_l0_Hz is not None

    def gain(self, f_Hz) -> np.ndarray:
        """g(f) per sample [-] (1 at ``f_ref_Hz``)."""
        return frequency_gain(f_Hz, self.f_ref_Hz, self.f_b0_Hz, self.zeta_b)

    def to_dict(self) -> dict[str, Any]:
        d = {"f_ref_Hz": self.f_ref_Hz, "f_b0_Hz": self.f_b0_Hz, "zeta_b": self.zeta_b,
             "units": {"f_ref_Hz": "Hz", "f_b0_Hz": "Hz", "zeta_b": "1"}}
        if self.has_contact:
            d.update(f_l0_Hz=self.f_l0_Hz, zeta_l=ZETA_L, contact_V=self.contact_V)
            d["units"].update(f_l0_Hz="Hz", zeta_l="1", contact_V="V")
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> "FrequencyResponse | None":
        if d is None:
            return None
        more = ({"f_l0_Hz": float(d["f_l0_Hz"]), "contact_V": float(d["contact_V"])}
                if d.get("f_l0_Hz") is not None else {})
        return cls(float(d["f_ref_Hz"]), float(d["f_b0_Hz"]), float(d["zeta_b"]), **more)

    def l1_gain(self, f_Hz) -> np.ndarray:
        """``g_l(f) = |H_l(f)| / |H_l(f_ref)|`` [-] (resonance ``f_l0_Hz``, damping :data:`ZETA_L`); needs the contact law."""
        return b2_magnitude(f_Hz, self.f_l0_Hz, ZETA_L) / b2_magnitude(self.f_ref_Hz, self.f_l0_Hz, ZETA_L)


def effective_voltage(V0, f_Hz, response: FrequencyResponse | None) -> np.ndarray:
    """``V0 g(f)`` [V]: the drive amplitude the frequency-free Eq. 29 needs (``V0`` itself without a response)."""
    V0 = np.asarray(V0, float)
    if response is None:
        return V0
    return V0 * response.gain(f_Hz)


def contact_angle(V0, f_Hz, response: FrequencyResponse | None) -> np.ndarray:
    """Half contact angle ``a`` per sample [rad] from the commanded ``V0`` [V] and the drive frequency [Hz].

    ``rho(a) = contact_V / (V0 g_l(f))`` (module docstring), solved by the interface's own root finder
    (:func:`l1b2.physics.interface.contact_half_angle_rad` with ``F_p = contact_V``, ``k_e = pi``,
    ``U_l = V0 g_l``) once per distinct (V0, f) pair; ``pi`` (permanent contact) where the right side
    exceeds pi, ``pi/2`` everywhere without the contact law (or ``f_Hz`` None).
    """
    V0 = np.asarray(V0, float)
    if response is None or not response.has_contact or f_Hz is None:
        return np.full(V0.shape, 0.5 * np.pi)
    pairs, inv = np.unique(np.column_stack(np.broadcast_arrays(V0.ravel(), np.asarray(f_Hz, float).ravel())),
                           axis=0, return_inverse=True)
    a = contact_half_angle_rad(pairs[:, 0] * response.l1_gain(pairs[:, 1]), response.contact_V, np.pi)
    return np.asarray(a, float)[np.ravel(inv)].reshape(V0.shape)


def sample_frequency(frame, f_default: float | None) -> np.ndarray | None:
    """Each sample's drive frequency [Hz]: the ``frequency_Hz`` column, else ``f_default`` everywhere (or None)."""
    if frame is not None and "frequency_Hz" in getattr(frame, "columns", ()):
        return np.asarray(frame["frequency_Hz"], float)
    if f_default is None:
        return None
    return np.full(len(frame), float(f_default))
