#!/usr/bin/env python
"""Benchmark: the effective B2 resonance the predictor's response finds in the coupled physics, per stator f_b0.

The truth: the coupled periodic steady state (:func:`l1b2.physics.steady.steady_state`, stick-slip) of the
realistic motor at the bar's centre (s = 0, direction +1) with the stator's ``f_b0_Hz`` set to each value asked
for. Its *equivalent-voltage gain* at drive frequency f is ``g_w(f) = V_e / V0``, where ``V_e`` is the amplitude
whose steady speed at the reference frequency (48.5 kHz) equals the steady speed at (V0, f): exactly the
predictor's assumption that the model with a response is the model without one at ``V0 g(f)``
(:mod:`l1b2.predictor.frequency`). ``g_w`` is taken on the coverage study's band (nine frequencies 48.0-49.0
kHz) at three operating points (324 V no load, 270 V 0.05 kg, 220 V 0.03 kg), and the predictor's
``frequency_gain(f; f_b0, zeta_b)`` is fitted to it by least squares (12 starts) within the identification's
bounds (:data:`l1b2.ident.frequency.F_B0_REL_RANGE`, :data:`~l1b2.ident.frequency.ZETA_B_RANGE`). Printed per
stator f_b0 and operating point: the effective f_b0 and its offset, the effective zeta_b, the fit's rms (of g),
and g_w at 48.0 / 48.5 / 49.0 kHz.

No rig, no noise, no identification: the structural map from the stator's resonance to the effective one,
before the data's weights. Usage: python bench/bench_frequency_effective.py [F_B0_HZ ...]
"""
import sys
import time

import numpy as np
from scipy import optimize

from l1b2.physics.params import load_motor, motor_file
from l1b2.physics.steady import steady_state
from l1b2.ident.frequency import F_B0_REL_RANGE, ZETA_B_RANGE
from l1b2.predictor.frequency import frequency_gain

BAND_HZ = np.linspace(48000.0, 49000.0, 9)
F_REF_HZ = 48500.0
POINTS = ((324.0, 0.0), (270.0, 0.05), (220.0, 0.03))   # (V0 [V], load [kg])


def world_gain(mp, V0, load_kg, s_m=0.0, direction=1):
    """``g_w(f)`` on :data:`BAND_HZ`: the equivalent-voltage gain of the coupled steady state (module docstring)."""
    def v_ref(V):
        return steady_state(mp, s_m, V, load_kg, direction, f_Hz=F_REF_HZ).v_m_s
    out = []
    for f in BAND_HZ:
        v = steady_state(mp, s_m, V0, load_kg, direction, f_Hz=float(f)).v_m_s
        out.append(optimize.brentq(lambda V: v_ref(V) - v, 0.3 * V0, 3.0 * V0, xtol=1e-6) / V0)
    return np.array(out)


def fit_response(g):
    """``((f_b0, zeta_b), rms)``: the predictor's gain fitted to ``g`` on :data:`BAND_HZ`."""
    def resid(p):
        return frequency_gain(BAND_HZ, F_REF_HZ, p[0], p[1]) - g
    best = None
    LO = [F_B0_REL_RANGE[0] * F_REF_HZ, ZETA_B_RANGE[0]]
    HI = [F_B0_REL_RANGE[1] * F_REF_HZ, ZETA_B_RANGE[1]]
    for f0 in (46000.0, 47000.0, 47800.0, 48300.0):
        for z in (0.005, 0.0125, 0.03):
            sol = optimize.least_squares(resid, [f0, z], bounds=(LO, HI))
            if best is None or sol.cost < best.cost:
                best = sol
    return best.x, float(np.sqrt(2.0 * best.cost / len(BAND_HZ)))


def main(argv):
    values = [float(a) for a in argv] or [47500.0, 47650.0, 47800.0, 47950.0, 48100.0]
    base = load_motor(motor_file("realistic_motor"))
    t0 = time.process_time()
    for fb in values:
        mp = base.replace(stator__f_b0_Hz=fb)
        for V0, load in POINTS:
            g = world_gain(mp, V0, load)
            (f0, z), rms = fit_response(g)
            print(f"stator f_b0 {fb:8.1f} Hz  V0 {V0:5.1f} V  load {load:4.2f} kg -> effective f_b0 {f0:8.1f} Hz "
                  f"({f0 - fb:+7.1f}), zeta_b {z:.4f}, rms {rms:.1e}; g_w(48.0/48.5/49.0 kHz) "
                  f"{g[0]:.4f} / {g[4]:.4f} / {g[8]:.4f}", flush=True)
    print(f"CPU {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
