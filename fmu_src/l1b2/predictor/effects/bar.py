"""The friction bar's non-uniformity: periodic waviness (grinding marks) and a local defect.

* ``bar_waviness`` (position): the modulated preload acts on the friction
  thrust, on the force factor (V0) and on the interface's damping (speed); a
  strong modulation acts non-linearly (second harmonic):
  ``dF = (a + c V0/V_ref + e v/v_ref) cos(2 pi s/L) + (same) sin(2 pi s/L)``
  plus the second harmonic, L on a grid (and around the residual's spectral peak).
* ``local_defect`` (position): a local bump or contamination,
  ``dF = a exp(-(s-c)^2 / (2 w^2))``, c and w on a grid.
"""

from __future__ import annotations

import numpy as np

from .base import SPEED_REF, Effect, drive_gain, num, register, signal


@register
class BarWaviness(Effect):
    kind = "bar_waviness"
    regressor = "position"
    signals = ("s", "v_base")
    description = "periodic non-uniformity of the friction bar"
    home = ("Stator.bar_wave_amp_m", "Stator.bar_wave_period_m")

    def features(self, spec, x):
        g = drive_gain(x)
        ph = 2 * np.pi * signal(x, "s") / num(spec, "period_m")
        u = signal(x, "d") * signal(x, "v_base") / SPEED_REF
        c, s = np.cos(ph), np.sin(ph)
        return np.column_stack([c, s, g * c, g * s, u * c, u * s, np.cos(2 * ph), np.sin(2 * ph)])

    def grid(self, train):
        periods = set(np.round(np.geomspace(2e-3, 12e-3, 13), 6))
        if train.spectral_period_m:
            periods |= {round(train.spectral_period_m * f, 6) for f in np.linspace(0.85, 1.15, 13)}
        names = ("wave_cos_N", "wave_sin_N", "wave_cos_gain_N", "wave_sin_gain_N", "wave_cos_damp_N",
                 "wave_sin_damp_N", "wave_cos2_N", "wave_sin2_N")
        return [self.hypothesis(names, ("N",) * 8, {"period_m": float(L)}, f"period {L * 1e3:.2f} mm")
                for L in sorted(periods)]


@register
class LocalDefect(Effect):
    kind = "local_defect"
    regressor = "position"
    signals = ("s",)
    description = "local bump or contamination of the friction bar"
    home = ("Stator.bar_bump_amp_m", "Stator.bar_bump_center_m", "Stator.bar_bump_width_m")

    def features(self, spec, x):
        return np.exp(-0.5 * ((signal(x, "s") - num(spec, "center_m")) / num(spec, "width_m")) ** 2)[:, None]

    def grid(self, train):
        s0, s1 = train.position_range
        return [self.hypothesis(("defect_N",), ("N",), {"center_m": float(c), "width_m": float(w)},
                                f"at {c * 1e3:+.0f} mm, width {w * 1e3:.1f} mm")
                for w in (0.6e-3, 1.2e-3, 2.4e-3) for c in np.arange(s0 + 2e-3, s1 - 2e-3 + 1e-9, 1.0e-3)]
