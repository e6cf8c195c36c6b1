"""Compiled loops of the Eq. 29 free run and of its forward sensitivities (numba, see :mod:`l1b2.physics.jit`).

The free run of Eq. 29 is, for given parameters, the recursion

    v[k+1] = a[k] v[k] + e[k] + f[k] sg[k]

along each run (``a = 1 - h D``, ``e = d h X``, ``f = d h Fr``, ``sg`` the
sign of -v' with the static-friction value ``z0`` at rest, and the rest /
reversal rules of :func:`l1b2.predictor.model.step_drive`), and the
derivative of the speed with respect to any parameter obeys the *same* linear
recursion with an extra forcing term::

    S[k+1] = a'[k] S[k] + U[k]          (a' = d v[k+1] / d v[k], U = d v[k+1] / d theta at fixed v[k])

:func:`free_run_loop` and :func:`linear_recursion_loop` are these two loops
over the packed time-major layout of :class:`l1b2.predictor.simulate.RunLayout`
(``offs``, ``na``), written in plain Python on arrays so that numba compiles
the same source. :func:`compiled_free_run` and :func:`compiled_linear_recursion`
return the compiled loops (once per process, cached on disk like the physics
kernels) or ``None`` when numba is missing or ``L1B2_JIT=0``; the callers in
:mod:`l1b2.predictor.simulate` then use their numpy-vectorised forms, which
compute the same numbers (tests/test_sensitivities.py).
"""

from __future__ import annotations

from ..physics.jit import cached_kernel

__all__ = ["free_run_loop", "linear_recursion_loop", "compiled_free_run", "compiled_linear_recursion",
           "FLAG_REVERSAL", "FLAG_STUCK"]

#: step codes written to ``flags`` (the values of :data:`l1b2.predictor.simulate.STEP_REVERSAL` / ``STEP_STUCK``)
FLAG_REVERSAL, FLAG_STUCK = 1, 2


def _sign(x):
    """sign(x) as numpy's: -1, 0, +1, NaN for NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    if x == 0.0:
        return 0.0
    return x


def free_run_loop(offs, na, a, e, f, nd, z0, v0_sorted, v, flags):
    """The free-run recursion in the packed layout, written into ``v`` (and the step codes into ``flags``).

    Same rules and the same floating-point operations, in the same order, as
    :func:`l1b2.predictor.simulate.packed_recursion`.
    """
    for i in range(na[0]):
        v[i] = v0_sorted[i]
    for k in range(na.size - 1):
        m = na[k + 1]
        i0 = offs[k]
        i1 = offs[k + 1]
        for i in range(m):
            j = i0 + i
            cur = v[j]
            sg = _sign(nd[j] * cur)
            rest = sg == 0.0
            if rest:
                sg = z0[j]
            out = a[j] * cur
            out += e[j]
            out += f[j] * sg
            if rest and abs(sg) < 1.0:
                out = 0.0
                flags[j] = FLAG_STUCK
            if out * cur < 0.0:
                zc = z0[j]
                frac = cur / (cur - out)
                inc = e[j] + f[j] * zc
                if abs(zc) < 1.0:
                    inc = 0.0
                    flags[j] = FLAG_STUCK
                else:
                    flags[j] = FLAG_REVERSAL
                out = (1.0 - frac) * inc
            v[i1 + i] = out


def linear_recursion_loop(offs, na, a, U, S):
    """``S[k+1] = a[k] S[k] + U[k]`` (rows, all columns) in the packed layout; ``S``'s first block is the start."""
    p = U.shape[1]
    for k in range(na.size - 1):
        m = na[k + 1]
        i0 = offs[k]
        i1 = offs[k + 1]
        for i in range(m):
            ai = a[i0 + i]
            for c in range(p):
                S[i1 + i, c] = ai * S[i0 + i, c] + U[i0 + i, c]


_FREE_RUN: list = []
_LINEAR: list = []


def compiled_free_run():
    """:func:`free_run_loop` compiled by numba (once per process), or None (see :mod:`l1b2.physics.jit`)."""
    return cached_kernel(_FREE_RUN, lambda: (
        {"_sign": _sign, "free_run_loop": free_run_loop}, "free_run_loop",
        "void(int64[::1], int64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], "
        "float64[::1], float64[::1], int8[::1])"))


def compiled_linear_recursion():
    """:func:`linear_recursion_loop` compiled by numba (once per process), or None."""
    return cached_kernel(_LINEAR, lambda: (
        {"linear_recursion_loop": linear_recursion_loop}, "linear_recursion_loop",
        "void(int64[::1], int64[::1], float64[::1], float64[:, ::1], float64[:, ::1])"))
