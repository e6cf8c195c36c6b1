"""Compiled loops of the identification's Jacobian (numba, see :mod:`l1b2.physics.jit`).

Each evaluation of a local search builds the free run's forcing ``U = h d dF/dtheta`` (n x p, one row per
sample, :meth:`l1b2.ident.problem.ForceCore.dF`) and whitens the Jacobian's rows with the noise model
(:meth:`l1b2.ident.noise.NoiseModel.weighted`). Written with numpy, both are a dozen passes over an
n x p array (column by column into a row-major array, a fancy-indexed copy, a sparse product, temporaries)
for a few floating-point operations per entry. The loops below make one pass (dF) and two passes (whitening)
with the *same* floating-point operations in the same order, so their results are those of the numpy forms
to the last bit (``tests/test_ident_kernels.py``).

:func:`compiled_drive_derivative` and :func:`compiled_whitening` return the compiled loops (once per
process, cached on disk like the physics kernels) or ``None`` when numba is missing or ``L1B2_JIT=0``;
the callers then use their numpy forms.
"""

from __future__ import annotations

import numpy as np

from ..physics.jit import cached_kernel
from ..predictor.model import G_of_k0, ddrive_factor_dk0, dG_dk0, drive_factor
from ..units import G_M_S2

__all__ = ["drive_derivative_loop", "whitening_loop", "scaled_whitening_loop", "compiled_drive_derivative",
           "compiled_whitening", "compiled_scaled_whitening", "drive_derivative", "whitened", "scaled_whitened"]


def drive_derivative_loop(L, V0, E, vp, sg, Ap, P, w, cols, c, out):
    """``out[i, j] = w[i] dF_i/dtheta[cols[j]]`` of Eq. 29's drive force (:meth:`ForceCore.dF`'s blocks).

    ``c`` holds the scalars ``(sigma, mu, musd, kappa, g1, G, dg1, dG, G_M_S2 m_s, pi/2, pi)``; ``E`` the
    extra-force features (n x 0 without extras). The expressions are :meth:`ForceCore.dF`'s, operand for
    operand.
    """
    sig, mu, musd, kappa, g1, G, dg1, dG, gms, hpi, pi = (c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8],
                                                         c[9], c[10])
    n1 = L.shape[1]
    pt = 5 + 3 * n1
    q = cols.size
    for i in range(vp.size):
        v = vp[i]
        ap = Ap[i]
        p = P[i]
        s = sg[i]
        wi = w[i]
        fa = sig * v - mu * p * 0.5 * pi * G
        fc = mu * (g1 - hpi * ap * G) + s * musd * kappa
        for j in range(q):
            k = cols[j]
            if k == 0:
                val = -v
            elif k == 1:
                val = -(0.5 - ap) * v
            elif k == 2:
                val = p * (g1 - hpi * ap * G)
            elif k == 3:
                val = mu * p * (dg1 - hpi * ap * dG)
            elif k == 4:
                val = s * (gms + kappa * p)
            elif k < 5 + n1:
                val = L[i, k - 5] * fa
            elif k < 5 + 2 * n1:
                val = L[i, k - 5 - n1] * V0[i]
            elif k < pt:
                val = L[i, k - 5 - 2 * n1] * fc
            else:
                val = E[i, k - pt]
            out[i, j] = val * wi


def whitening_loop(x, run, g, cg, sqrtR, acc, out):
    """``out = (x - cg * (G x)[run]) / sqrtR`` row by row (:meth:`NoiseModel.weighted` of a matrix).

    ``acc`` (runs x p, zeros) receives ``G x``: the sums of ``g[i] x[i]`` over each run's rows in row order,
    as the sparse product of the numpy form adds them.
    """
    p = x.shape[1]
    for i in range(x.shape[0]):
        r = run[i]
        gi = g[i]
        for k in range(p):
            acc[r, k] += gi * x[i, k]
    for i in range(x.shape[0]):
        r = run[i]
        ci = cg[i]
        si = sqrtR[i]
        for k in range(p):
            out[i, k] = (x[i, k] - ci * acc[r, k]) / si


def scaled_whitening_loop(S, rows, run, g, cg, sqrtR, scale, acc, out):
    """``out[i] = (S[rows[i]] - cg[i] (G x)[run[i]]) / sqrtR[i] * scale``, non-finite entries set to 0.

    The fused form of ``x = S[rows]``, :func:`whitening_loop` of ``x`` and the column scaling with the clean-up
    of :meth:`l1b2.ident.problem.ScaledObjective.jac` (``J *= scale``; ``where(isfinite(J), J, 0)``): the same
    floating-point operations in the same order, without the gathered copy and the passes of the scaling and
    the check. ``out`` may be row- or column-major (the second pass writes it column by column then).
    """
    p = S.shape[1]
    m = rows.size
    for i in range(m):
        r = run[i]
        gi = g[i]
        src = rows[i]
        for k in range(p):
            acc[r, k] += gi * S[src, k]
    if out.strides[0] < out.strides[1]:  # column-major: column by column (each entry on its own, as below)
        for k in range(p):
            sk = scale[k]
            for i in range(m):
                val = (S[rows[i], k] - cg[i] * acc[run[i], k]) / sqrtR[i]
                val = val * sk
                out[i, k] = val if np.isfinite(val) else 0.0
        return
    for i in range(m):
        r = run[i]
        ci = cg[i]
        si = sqrtR[i]
        src = rows[i]
        for k in range(p):
            val = (S[src, k] - ci * acc[r, k]) / si
            val = val * scale[k]
            out[i, k] = val if np.isfinite(val) else 0.0


_DERIVATIVE: list = []
_WHITENING: list = []
_SCALED_WHITENING: list = []


def compiled_drive_derivative():
    """:func:`drive_derivative_loop` compiled by numba (once per process), or None (see :mod:`l1b2.physics.jit`)."""
    return cached_kernel(_DERIVATIVE, lambda: (
        {"drive_derivative_loop": drive_derivative_loop}, "drive_derivative_loop",
        "void(float64[:, ::1], float64[::1], float64[:, ::1], float64[::1], float64[::1], float64[::1], "
        "float64[::1], float64[::1], int64[::1], float64[::1], float64[:, ::1])"))


def compiled_whitening():
    """:func:`whitening_loop` compiled by numba (once per process), or None."""
    return cached_kernel(_WHITENING, lambda: (
        {"whitening_loop": whitening_loop}, "whitening_loop",
        "void(float64[:, ::1], int64[::1], float64[::1], float64[::1], float64[::1], float64[:, ::1], "
        "float64[:, ::1])"))


def compiled_scaled_whitening():
    """:func:`scaled_whitening_loop` compiled by numba (once per process), or None."""
    return cached_kernel(_SCALED_WHITENING, lambda: (
        {"scaled_whitening_loop": scaled_whitening_loop}, "scaled_whitening_loop",
        "void(float64[:, ::1], int64[::1], int64[::1], float64[::1], float64[::1], float64[::1], float64[::1], "
        "float64[:, ::1], float64[:, :])"))


def drive_derivative(core, theta, vp, sg, Ap, P, cols, w):
    """``w[:, None] * core.dF(theta, vp, sg, Ap, P, cols)`` on all rows by :func:`drive_derivative_loop` (C order);
    None without the compiled loop. ``core``: an Eq. 29 :class:`~l1b2.ident.problem.ForceCore`."""
    kernel = compiled_drive_derivative()
    if kernel is None:
        return None
    _, sig, mu, k0, musd = theta[:5]
    c = np.array([sig, mu, musd, core.kappa, float(drive_factor(k0)), float(G_of_k0(k0)),
                  float(ddrive_factor_dk0(k0)), float(dG_dk0(k0)), G_M_S2 * core.m_s, 0.5 * np.pi, np.pi], float)
    cols = np.ascontiguousarray(cols, dtype=np.int64)
    E = core.E if core.E is not None else np.zeros((vp.size, 0))
    out = np.empty((vp.size, cols.size))
    kernel(core.L, np.ascontiguousarray(core.V0, dtype=float), E, np.ascontiguousarray(vp, dtype=float),
           np.ascontiguousarray(sg, dtype=float), np.ascontiguousarray(Ap, dtype=float),
           np.ascontiguousarray(P, dtype=float), np.ascontiguousarray(w, dtype=float), cols, c, out)
    return out


def whitened(x, run, g, cg, sqrtR, n_runs):
    """``(x - cg[:, None] * (G x)[run]) / sqrtR[:, None]`` of a matrix ``x`` by :func:`whitening_loop`; None
    without the compiled loop (:meth:`l1b2.ident.noise.NoiseModel.weighted`)."""
    kernel = compiled_whitening()
    if kernel is None:
        return None
    x = np.ascontiguousarray(x, dtype=float)
    out = np.empty_like(x)
    kernel(x, np.ascontiguousarray(run, dtype=np.int64), np.ascontiguousarray(g, dtype=float),
           np.ascontiguousarray(cg, dtype=float), np.ascontiguousarray(sqrtR, dtype=float),
           np.zeros((int(n_runs), x.shape[1])), out)
    return out


def scaled_whitened(S, rows, run, g, cg, sqrtR, n_runs, scale, order="C"):
    """``where(isfinite(J), J, 0)`` of ``J = whitened(S[rows], ...) * scale[None, :]`` by
    :func:`scaled_whitening_loop` (the same values to the last bit), in memory order ``order`` ("C" or "F");
    None without the compiled loop. ``S``: C-contiguous float64 (sensitivities of all packed rows)."""
    kernel = compiled_scaled_whitening()
    if kernel is None:
        return None
    S = np.ascontiguousarray(S, dtype=float)
    out = np.empty((rows.size, S.shape[1]), order=order)
    kernel(S, np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(run, dtype=np.int64),
           np.ascontiguousarray(g, dtype=float),
           np.ascontiguousarray(cg, dtype=float), np.ascontiguousarray(sqrtR, dtype=float),
           np.ascontiguousarray(scale, dtype=float), np.zeros((int(n_runs), S.shape[1])), out)
    return out
