"""Benchmark: identification wall time and free-run predictor throughput.

Run from the repository root::

    .venv/bin/python bench/bench_identify.py            # full run
    .venv/bin/python bench/bench_identify.py --quick    # smaller, for a smoke test

Prints, side by side in one run:

* the wall time of :class:`l1b2.ident.estimator.PredictorIdentifier` (order 8,
  criterion ``free_run``, default ``n_starts``) on a rig-sized synthetic data
  set (72 runs: 4 voltages x 9 loads x 2 directions, 1 kHz, ~21k samples),
  once in the paper's setting (all of Eq. 35 varied) and once with the
  recommended pins (``fixed="recommended"``); target < 60 s each on 2 cores;
* the throughput (samples/s) of the vectorised :func:`l1b2.predictor.simulate.free_run`
  against a plain Python loop over samples (scalar ``math`` arithmetic, the
  same force law and step rules), and their ratio.

OpenBLAS threads are limited to 1 (as the Makefile does): the optimiser's
dense problems are small and thread start-up costs more than it saves.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import math
import platform
import sys
import time

import numpy as np
from l1b2.data.metrics import evaluation_mask
from l1b2.ident.estimator import PredictorIdentifier
from l1b2.predictor.model import example_params
from l1b2.predictor.simulate import design_grid, free_run, simulate_dataset
from l1b2.units import G_M_S2

M_S = 0.1


def python_free_run(prm, s, V0, load, d, t, v_meas, run, m_s):
    """Plain Python loop over samples, scalar arithmetic only (the baseline)."""
    alpha, beta, p = list(prm.alpha), list(prm.beta), list(prm.p)
    n1 = len(alpha)
    k0 = prm.k0
    g1 = 2.0 * math.sqrt(1.0 - k0 * k0) - 1.0
    G = 2.0 * k0 * math.sqrt(1.0 - k0 * k0) - 2.0 * math.asin(k0) + 0.5 * math.pi
    out = [0.0] * len(s)
    for i in range(len(s)):
        if i == 0 or run[i] != run[i - 1]:
            out[i] = float(v_meas[i])
            continue
        j = i - 1
        # Legendre polynomials by recurrence
        x = (s[j] - prm.s_center) / prm.s_half
        P0, P1 = 1.0, x
        Ap = alpha[0] * P0 + (alpha[1] * P1 if n1 > 1 else 0.0)
        Bp = beta[0] * P0 + (beta[1] * P1 if n1 > 1 else 0.0)
        Pp = p[0] * P0 + (p[1] * P1 if n1 > 1 else 0.0)
        for k in range(2, n1):
            P0, P1 = P1, ((2 * k - 1) * x * P1 - (k - 1) * P0) / k
            Ap += alpha[k] * P1
            Bp += beta[k] * P1
            Pp += p[k] * P1
        dj = d[j]
        vp = dj * out[j]
        mp = dj * load[j]
        D = prm.c_r + prm.sigma * (0.5 - Ap)
        X = Bp * V0[j] + prm.mu * Pp * (g1 - 0.5 * math.pi * Ap * G) - G_M_S2 * mp
        Fr = prm.mu_sd * (G_M_S2 * m_s + prm.kappa * Pp)
        m_eff = m_s + (abs(load[j]) if prm.include_load_inertia else 0.0)
        h = (t[i] - t[j]) / m_eff
        z0 = -max(-1.0, min(1.0, X / Fr)) if Fr > 0 else -math.copysign(1.0, X)
        if vp == 0.0:
            new = 0.0 if abs(z0) < 1.0 else h * (X + z0 * Fr)
        else:
            sg = -1.0 if vp > 0 else 1.0
            new = vp + h * (-D * vp + X + sg * Fr)
            if vp * new < 0:
                frac = vp / (vp - new)
                new = 0.0 if abs(z0) < 1.0 else (1.0 - frac) * h * (X + z0 * Fr)
        out[i] = dj * new
    return np.array(out)


def bench_throughput(df, prm, repeat):
    cols = [df[c].to_numpy() for c in ("position_m", "voltage_V", "load_kg", "direction", "time_s")]
    v_meas = df["speed_m_s"].to_numpy()
    run = df["run"].to_numpy()
    n = len(df)
    t0 = time.perf_counter()
    for _ in range(repeat):
        vv = free_run(prm, *cols, v_meas, M_S, run_index=run)
    t_vec = (time.perf_counter() - t0) / repeat
    lists = [c.tolist() for c in cols]
    t0 = time.perf_counter()
    vp = python_free_run(prm, *lists, v_meas.tolist(), run.tolist(), M_S)
    t_py = time.perf_counter() - t0
    return n / t_vec, n / t_py, float(np.max(np.abs(vv - vp)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="order 3, 12 runs (smoke test)")
    ap.add_argument("--noise", type=float, default=5e-5, help="white speed noise [m/s]")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)

    order = 3 if args.quick else 8
    design = (
        design_grid(voltages=(220.0, 324.0), loads=(-0.07, 0.0, 0.07)) if args.quick else design_grid()
    )
    prm = example_params(order)
    df = simulate_dataset(prm, design, M_S, dt=1e-3, stroke=(-0.025, 0.025), noise_std=args.noise, seed=args.seed)
    mask = evaluation_mask(df)
    print(f"python {platform.python_version()}, numpy {np.__version__}, {os.cpu_count()} cpu(s), "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}")
    print(f"data: {df['run'].nunique()} runs, {len(df)} samples, {int(mask.sum())} in the evaluation mask, "
          f"noise {args.noise:g} m/s, order {order}")

    rows = []
    for label, fixed in (("paper: all Eq.35 varied", None), ("fixed='recommended'", "recommended")):
        est = PredictorIdentifier(order=order, criterion="free_run", fixed=fixed)
        t0 = time.perf_counter()
        est.fit(df, M_S, mask=mask)
        wall = time.perf_counter() - t0
        c = est.convergence_
        rows.append((label, wall, est.n_starts, c["nfev_total"], est.residual_rms_ / args.noise,
                     len(est.unidentifiable_), len(est.weak_directions_), c["message"]))

    thr_vec, thr_py, diff = bench_throughput(df, prm, repeat=5)

    print()
    print(f"{'identification (free_run, order %d)' % order:<40} {'wall [s]':>9} {'starts':>7} {'nfev':>6} "
          f"{'rms/noise':>10} {'null':>5} {'weak':>5}  termination")
    for label, wall, ns, nfev, ratio, nnull, nweak, msg in rows:
        flag = "" if wall < 60 else "  (over the 60 s target)"
        print(f"{label:<40} {wall:9.2f} {ns:7d} {nfev:6d} {ratio:10.4f} {nnull:5d} {nweak:5d}  {msg[:60]}{flag}")
    print()
    print(f"{'free-run predictor':<40} {'samples/s':>12}")
    print(f"{'vectorised free_run (numpy)':<40} {thr_vec:12.4g}")
    print(f"{'plain Python loop over samples':<40} {thr_py:12.4g}")
    print(f"{'ratio vectorised / loop':<40} {thr_vec / thr_py:12.1f}   (max |difference| {diff:.2g} m/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
