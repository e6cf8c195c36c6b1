#!/usr/bin/env python
"""Benchmark: how far a frequency law on the pure-slip drive force can follow the coupled physics over +-550 Hz.

The truth: the coupled periodic steady state (:func:`l1b2.physics.steady.steady_state`, stick-slip) of the
realistic motor at the bar's centre (s = 0, direction +1) on 12 drive frequencies 47.95-49.05 kHz x V0
220/255/290/324 V x load -0.09...0.09 kg (7), the TRAIN span of ``bench/bench_frequency.py``. The forms, each
fitted by least squares on the steady speeds (relative to their rms), print side by side in one run:

* ``B2``: the predictor's law (decision 0029): the pure-slip steady state at the effective amplitude
  V0 g_b(f), g_b the B2 response (f_b0, zeta_b);
* ``B2+L1``: the same plus the contact's dependence on the normal amplitude: U_l = U_l(f_ref) g_l(f),
  g_l = |H_l(f)| / |H_l(f_ref)| (L1 resonance f_l0 > f_ref, damping zeta_l), the half contact angle a from
  Eq. 18, rho(a) = rho(a_ref) / g_l(f), with a_ref = pi/2 (the family's contact at f_ref) and the drive force
  of :func:`l1b2.predictor.pureslip.contact_drive_force` (sigma (W sin a - a v)/pi + mu F_p h(k, a));
* ``B2+L1, a_ref free``: a_ref estimated as well (within 0.3 ... pi/2);
* floors: the ``B2`` form fitted at one frequency only, at that frequency.

Printed: the rms error (% of the rms speed) over all frequencies and per frequency, the fitted responses and
the CPU time of each fit (``time.process_time``). No rig, no identification: the structural error of each
form against the physics, before noise, transients and the position polynomials.

Usage: python bench/bench_frequency_forms.py
"""
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy import optimize

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.physics.interface import contact_half_angle_rad  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402
from l1b2.physics.steady import steady_state  # noqa: E402
from l1b2.predictor.frequency import b2_magnitude, frequency_gain  # noqa: E402
from l1b2.predictor.pureslip import contact_shape, contact_slip_factor, slip_factors  # noqa: E402

F_REF = 48500.0
FREQS = np.linspace(47950.0, 49050.0, 12)
VOLTS = (220.0, 255.0, 290.0, 324.0)
LOADS = (-0.09, -0.06, -0.03, 0.0, 0.03, 0.06, 0.09)


def physics_grid():
    mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    rows = [(f, V0, m, steady_state(mp, 0.0, V0, m, 1, f_Hz=float(f))) for f in FREQS for V0 in VOLTS for m in LOADS]
    rows = [r for r in rows if not r[3].stuck]
    return tuple(np.array([r[i] for r in rows]) for i in range(3)) + (np.array([r[3].v_m_s for r in rows]),)


def model_speed(p, f, V0, m, law):
    """Steady speed of the pure-slip force (s = 0, one position): bisection of F(v) = 0 on [0, 2 m/s]."""
    c_r, sig, B, muP, Ap, Fr, f_b0, zeta_b = p[:8]
    W = B * V0 * frequency_gain(f, F_REF, f_b0, zeta_b)          # sigma W_tip / pi of the module docstring
    if law == "B2":
        a = np.full_like(f, 0.5 * math.pi)
    else:
        a_ref = p[10] if law == "B2+L1, a_ref free" else 0.5 * math.pi
        g_l = b2_magnitude(f, p[8], p[9]) / b2_magnitude(F_REF, p[8], p[9])   # a single mode's |H|, here L1's
        a = contact_half_angle_rad(g_l / contact_shape(a_ref), 1.0 / math.pi, 1.0)   # rho(a) = rho(a_ref)/g_l

    def force(v):
        k = np.clip(sig * v / (math.pi * W), 0.0, 1.0)
        G = slip_factors(k)[1]
        return (-(c_r + sig * (a / math.pi - Ap)) * v + W * np.sin(a) + muP * (contact_slip_factor(k, a)
                - 0.5 * math.pi * Ap * G) - 9.81 * m - Fr)
    lo, hi = np.zeros_like(f), np.full_like(f, 2.0)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        pos = force(mid) > 0
        lo, hi = np.where(pos, mid, lo), np.where(pos, hi, mid)
    return 0.5 * (lo + hi)


#: parameters as fitted: log c_r, log sigma, log B', log muP, A', Fr, f_b0/f_ref, log zeta_b, f_l0/f_ref,
#: log zeta_l, a_ref
LO = [-5, -5, -12, -5, -1, -2, 0.8, math.log(0.002), 1.0005, math.log(0.002), 0.3]
HI = [5, 5, 0, 3, 1, 2, 0.9995, math.log(0.2), 1.2, math.log(0.2), 0.5 * math.pi]


def unpack(x):
    p = np.array(x, float).copy()
    p[[0, 1, 2, 3, 7]] = np.exp(p[[0, 1, 2, 3, 7]])
    p[6] *= F_REF
    if p.size > 8:
        p[8] *= F_REF
        p[9] = math.exp(p[9])
    return p


def fit(law, data, sel, starts):
    f, V0, m, v = data
    scale = math.sqrt(np.mean(v[sel] ** 2))
    n = len(starts[0])
    best, c0 = None, time.process_time()
    for x0 in starts:
        r = optimize.least_squares(lambda x: (model_speed(unpack(x), f[sel], V0[sel], m[sel], law) - v[sel]) / scale,
                                   np.clip(x0, np.array(LO[:n]) + 1e-9, np.array(HI[:n]) - 1e-9),
                                   bounds=(LO[:n], HI[:n]), max_nfev=300)
        if best is None or r.cost < best.cost:
            best = r
    return best.x, time.process_time() - c0


def rms_pct(x, law, data, sel):
    f, V0, m, v = data
    e = model_speed(unpack(x), f[sel], V0[sel], m[sel], law) - v[sel]
    return 100 * math.sqrt(np.mean(e ** 2) / np.mean(v[sel] ** 2))


def main() -> None:
    c0 = time.process_time()
    data = physics_grid()
    f = data[0]
    print(f"physics: {f.size} moving steady states, {time.process_time() - c0:.1f} s CPU")
    all_ = np.ones(f.size, bool)
    base = [math.log(5), math.log(8), math.log(0.01), math.log(1.2), 0.0, 0.3, 47300 / F_REF, math.log(0.0185)]
    starts = [np.array(base), np.array(base) + [0, 0.5, 0, 0, 0, 0, 0, 0],
              np.array(base) + [0, -0.7, 0, 0.2, 0.1, 0, 0.01, 0]]
    fits = {"B2": fit("B2", data, all_, starts)}
    x_b2 = fits["B2"][0]
    # starts: the B2 fit and the B2 resonance of the physics' B2-drive gains / the motor file's, each with L1 at
    # 0.7-3.5 kHz above the drive (the stator's L1 plus the contact's stiffening) and two dampings
    l1_starts = [(fl, z) for fl in (49200.0, 50000.0, 51000.0, 52000.0) for z in (0.01, 0.03)]
    b2_starts = [x_b2] + [np.r_[x_b2[:6], fb / F_REF, math.log(0.012)] for fb in (47300.0, 47800.0)]
    fits["B2+L1"] = fit("B2+L1", data, all_, [np.r_[xb, fl / F_REF, math.log(z)] for fl, z in l1_starts
                                              for xb in b2_starts])
    x_l1 = fits["B2+L1"][0]
    fits["B2+L1, a_ref free"] = fit("B2+L1, a_ref free", data, all_, [np.r_[x_l1, a] for a in (1.4, 1.0, 0.8)]
                                    + [np.r_[x_b2, fl / F_REF, math.log(z), 0.9] for fl, z in l1_starts[::3]])
    levels = np.unique(f)
    print(f"{'form':>20} | {'all %':>6} | " + " ".join(f"{fl / 1e3:6.2f}" for fl in levels) + " | cpu s | response")
    for law, (x, cpu) in fits.items():
        p = unpack(x)
        resp = (f"f_b0 {p[6]:.0f} Hz, zeta_b {p[7]:.4f}"
                + (f"; f_l0 {p[8]:.0f} Hz, zeta_l {p[9]:.4f}" if p.size > 8 else "")
                + (f"; a_ref {math.degrees(p[10]):.1f} deg" if p.size > 10 else ""))
        print(f"{law:>20} | {rms_pct(x, law, data, all_):6.2f} | "
              + " ".join(f"{rms_pct(x, law, data, f == fl):6.2f}" for fl in levels) + f" | {cpu:5.1f} | {resp}",
              flush=True)
    floors = []
    for fl in levels:
        x, _ = fit("B2", data, f == fl, [x_b2])
        floors.append(rms_pct(x, "B2", data, f == fl))
    print(f"{'floor: B2 at each f':>20} | {'':>6} | " + " ".join(f"{e:6.2f}" for e in floors)
          + " | (the form fitted at that frequency only)")


if __name__ == "__main__":
    main()
