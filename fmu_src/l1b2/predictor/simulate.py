"""Run-level simulation of the Eq. 29 predictor: packed recursions, free runs, synthetic data sets.

The recursions of :mod:`l1b2.predictor.model` evaluated over many runs at
once: runs are packed time-major (:class:`RunLayout`) so the loop is over
the time index only, vectorised across runs.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Iterable, Mapping, Sequence

import numpy as np

from .kernels import compiled_free_run, compiled_linear_recursion
from .model import (
    PredictorParams,
    add_extra_force,
    effective_mass,
    force_parts,
    one_step,
    rest_sign,
    slip_terms,
    step_drive,
)
from .pureslip import packed_slip_recursion
from ..units import G_M_S2

# ---------------------------------------------------------------------------
# run layout: flat samples <-> padded (time, run) arrays
# ---------------------------------------------------------------------------


class RunLayout:
    """Map between flat per-sample arrays (runs contiguous) and a packed layout.

    The recursions need all runs at the same time index together. Runs are
    sorted by decreasing length and the samples are *packed time-major*:
    block ``k`` (rows ``offs[k]:offs[k] + na[k]``) holds sample ``k`` of the
    ``na[k]`` runs that are that long, in sorted-run order. Because ``na`` is
    non-increasing, the runs alive at ``k + 1`` are a prefix of those at
    ``k``. This is equivalent to padding the runs to a common length but
    without computing on the padding. ``perm[j]`` is the flat sample index of
    packed row ``j``; ``to_packed(x) = x[perm]``, ``from_packed(y)`` inverts.
    """

    def __init__(self, run_index=None, n: int | None = None):
        if run_index is None:
            if n is None:
                raise ValueError("need run_index or n")
            labels = np.zeros(int(n), dtype=int)
        else:
            labels = np.asarray(run_index)
            if labels.ndim != 1:
                raise ValueError("run_index must be 1-D")
        n = labels.size
        if n == 0:
            raise ValueError("no samples")
        change = np.ones(n, dtype=bool)
        change[1:] = labels[1:] != labels[:-1]
        self.starts = np.flatnonzero(change)
        self.n = n
        self.R = self.starts.size
        self.lengths = np.diff(np.append(self.starts, n))
        self.K = int(self.lengths.max())
        self.run_of_sample = np.repeat(np.arange(self.R), self.lengths)
        self.kk = np.arange(n) - self.starts[self.run_of_sample]
        self.labels = labels[self.starts]
        self.is_last = np.zeros(n, dtype=bool)
        self.is_last[self.starts + self.lengths - 1] = True
        # packed time-major layout
        self.run_order = np.argsort(-self.lengths, kind="stable")
        rank = np.empty(self.R, dtype=int)
        rank[self.run_order] = np.arange(self.R)
        sorted_len = self.lengths[self.run_order]
        # na[k] = number of runs longer than k
        self.na = self.R - np.searchsorted(sorted_len[::-1], np.arange(self.K), side="right")
        self.offs = np.concatenate([[0], np.cumsum(self.na)])
        #: offs and na as contiguous int64 (the compiled loops' argument types)
        self.offs_i64 = np.ascontiguousarray(self.offs, dtype=np.int64)
        self.na_i64 = np.ascontiguousarray(self.na, dtype=np.int64)
        packed_pos = self.offs[self.kk] + rank[self.run_of_sample]
        self.perm = np.empty(n, dtype=int)
        self.perm[packed_pos] = np.arange(n)
        self.packed_pos = packed_pos

    def to_packed(self, flat):
        return np.asarray(flat)[self.perm]

    def from_packed(self, packed):
        return np.asarray(packed)[self.packed_pos]

    def step_dt(self, t):
        """dt_k = t[k+1] - t[k] within runs, 0 at the last sample of each run."""
        t = np.asarray(t, dtype=float)
        dt = np.zeros(self.n)
        dt[:-1] = np.diff(t)
        dt[self.is_last] = 0.0
        return dt


def _broadcast_flat(x, n, name):
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    arr = arr.ravel()
    if arr.size != n:
        raise ValueError(f"{name} has {arr.size} entries, expected {n} (or a scalar)")
    return arr


#: codes of :func:`packed_recursion`'s ``flags``
STEP_NORMAL, STEP_REVERSAL, STEP_STUCK = 0, 1, 2


def packed_recursion(lay: RunLayout, a, e, f, nd, z0, v0_sorted, flags=None):
    """Free-run recursion in the packed layout (loops over the time index only).

    ``v[k+1] = a[k] v[k] + e[k] + f[k] sg[k]`` with ``sg = sign(nd v)``
    (``nd = -d``: sign(-v') in the data convention), replaced at rest (v = 0)
    by the static-friction value ``z0`` (see :func:`rest_sign`); a stuck step
    at rest gives 0, a step that reverses the sign of v continues from rest
    for the rest of the step (see :func:`step_drive`). ``flags`` (int8,
    packed) if given receives STEP_REVERSAL / STEP_STUCK at the source row
    of such steps. ``v0_sorted``: start speeds in sorted-run order.

    Runs the compiled loop of :mod:`l1b2.predictor.kernels` when numba is
    available (same operations), else the numpy form below.
    """
    kernel = compiled_free_run()
    if kernel is not None:
        v = np.empty(lay.n)
        fl = np.zeros(lay.n, dtype=np.int8) if flags is None else flags
        kernel(lay.offs_i64, lay.na_i64, *(np.ascontiguousarray(x, dtype=float) for x in (a, e, f, nd, z0, v0_sorted)),
               v, fl)
        return v
    v = np.empty(lay.n)
    offs, na = lay.offs, lay.na
    v[: na[0]] = v0_sorted
    for k in range(lay.K - 1):
        m = na[k + 1]
        i0 = offs[k]
        i1 = offs[k + 1]
        cur = v[i0 : i0 + m]
        sg = np.sign(nd[i0 : i0 + m] * cur)
        rest = sg == 0
        anyrest = rest.any()
        if anyrest:
            sg[rest] = z0[i0 : i0 + m][rest]
        out = a[i0 : i0 + m] * cur
        out += e[i0 : i0 + m]
        out += f[i0 : i0 + m] * sg
        if anyrest:
            st = rest & (np.abs(sg) < 1.0)
            if st.any():
                out[st] = 0.0
                if flags is not None:
                    flags[i0 : i0 + m][st] = STEP_STUCK
        cross = out * cur < 0
        if cross.any():
            zc = z0[i0 : i0 + m][cross]
            cc = cur[cross]
            frac = cc / (cc - out[cross])
            inc_rest = e[i0 : i0 + m][cross] + f[i0 : i0 + m][cross] * zc
            inc_rest[np.abs(zc) < 1.0] = 0.0
            out[cross] = (1.0 - frac) * inc_rest
            if flags is not None:
                flags[i0 : i0 + m][cross] = np.where(np.abs(zc) < 1.0, STEP_STUCK, STEP_REVERSAL)
        v[i1 : i1 + m] = out
    return v


def packed_linear_recursion(lay: RunLayout, a, U, S0=None):
    """S[k+1] = a[k] S[k] + U[k] (matrix rows) in the packed layout, S[0] = S0 (default 0).

    Runs the compiled loop of :mod:`l1b2.predictor.kernels` when numba is
    available and ``U`` is a matrix, else the numpy form below.
    """
    S = np.empty((lay.n,) + U.shape[1:])
    offs, na = lay.offs, lay.na
    S[: na[0]] = 0.0 if S0 is None else S0
    kernel = compiled_linear_recursion() if U.ndim == 2 else None
    if kernel is not None:
        kernel(lay.offs_i64, lay.na_i64, np.ascontiguousarray(a, dtype=float), np.ascontiguousarray(U, dtype=float), S)
        return S
    for k in range(lay.K - 1):
        m = na[k + 1]
        i0 = offs[k]
        i1 = offs[k + 1]
        out = S[i1 : i1 + m]
        np.multiply(a[i0 : i0 + m, None], S[i0 : i0 + m], out=out)
        out += U[i0 : i0 + m]
    return S


def free_run_coefficients(params: PredictorParams, s, V0, load, direction, dt, m_s, extra_force=None):
    """Per-sample coefficients of the free-run recursion in the data convention.

    v[k+1] = a_k v[k] + e_k + f_k sign(-d_k v[k]) with a = 1 - h D, e = d h X,
    f = d h Fr, h = dt/m_eff (see :func:`force_parts`); z0 = rest_sign(X, Fr).
    ``extra_force`` [N, drive coordinates] is added to X (default None: none).
    """
    d = np.asarray(direction, float)
    D, X, Fr = force_parts(params, s, V0, d * np.asarray(load, float), m_s)
    X = add_extra_force(X, extra_force)
    h = np.asarray(dt, float) / effective_mass(params, load, m_s)
    return 1.0 - h * D, d * h * X, d * h * Fr, rest_sign(X, Fr)


def _free_run_setup(params: PredictorParams, s, V0, load, direction, t, v_start, m_s, run_index, extra_force):
    """The inputs of a free run on its layout (the arguments of :func:`free_run`).

    Returns a namespace: ``n``, ``lay`` (:class:`RunLayout`), the flat per-sample arrays ``s``, ``V0``, ``load``,
    ``d`` (direction), ``m_s`` and ``extra_force`` (None when not given), ``dt`` (:meth:`RunLayout.step_dt`),
    ``v0`` (each run's start speed, in the packed run order) and ``coef``: the packed ``(a, e, f, z0)`` of
    :func:`free_run_coefficients` for Eq. 29's drive law, None for the pure-slip family. ValueError for a
    ``v_start`` that is neither a scalar nor one value per run nor one per sample.
    """
    s = np.asarray(s, dtype=float).ravel()
    n = s.size
    lay = RunLayout(run_index, n)
    V0 = _broadcast_flat(V0, n, "V0")
    load = _broadcast_flat(load, n, "load")
    d = _broadcast_flat(direction, n, "direction")
    t = _broadcast_flat(t, n, "t")
    m_s = _broadcast_flat(m_s, n, "m_s")
    vs = np.asarray(v_start, dtype=float).ravel()
    if vs.size == 1:
        v0 = np.full(lay.R, float(vs[0]))
    elif vs.size == n:
        v0 = vs[lay.starts]
    elif vs.size == lay.R:
        v0 = vs.copy()
    else:
        raise ValueError("v_start must be a scalar, one value per run or one per sample")
    dt = lay.step_dt(t)
    ef = None if extra_force is None else _broadcast_flat(extra_force, n, "extra_force")
    coef = (None if params.drive_law == "pure_slip" else
            tuple(lay.to_packed(x) for x in free_run_coefficients(params, s, V0, load, d, dt, m_s, ef)))
    return SimpleNamespace(n=n, lay=lay, s=s, V0=V0, load=load, d=d, m_s=m_s, extra_force=ef, dt=dt,
                           v0=v0[lay.run_order], coef=coef)


def free_run(
    params: PredictorParams,
    s,
    V0,
    load,
    direction,
    t,
    v_start,
    m_s,
    run_index=None,
    extra_force=None,
    contact=None,
):
    """Free-run prediction along a MEASURED position trajectory.

    Every run starts from ``v_start`` (the measured speed of its first
    sample) and the predictor propagates its own speed with the per-sample
    step ``dt_k = t[k+1] - t[k]``; positions, voltages and loads are taken
    from the data. Inputs are flat per-sample arrays (runs contiguous,
    labelled by ``run_index``; ``None`` = one run). ``v_start`` may be a
    scalar, one value per run, or a per-sample array (its first sample of
    each run is used). Runs are aligned on a common time index internally
    (packed time-major layout, see :class:`RunLayout`: padding without
    computing on the pads) and the recursion loops over the time index
    only, vectorised across runs (``params.drive_law="pure_slip"``: the
    non-linear step of :func:`l1b2.predictor.pureslip.packed_slip_recursion`). ``extra_force`` (scalar or one value per
    sample) [N, drive coordinates] is added to X (default None: none).
    ``contact`` (pure-slip family; scalar or per sample [rad]) is the half
    contact angle of the contact law (:func:`l1b2.predictor.frequency.contact_angle`;
    default None: pi/2).
    Returns the predicted speed per sample [m/s], signed data convention.
    """
    r = _free_run_setup(params, s, V0, load, direction, t, v_start, m_s, run_index, extra_force)
    lay, pk = r.lay, r.lay.to_packed
    if params.drive_law == "pure_slip":   # non-linear in the speed: stepped with the state's slip ratio
        ca = None if contact is None else _broadcast_flat(contact, r.n, "contact")
        D, X, Fr = force_parts(params, r.s, r.V0, r.d * r.load, r.m_s, ca)
        muP, Ap, c_k, frozen = slip_terms(params, r.s, r.V0)
        h = r.dt / effective_mass(params, r.load, r.m_s)
        vpk = packed_slip_recursion(lay.offs, lay.na, step_drive, *(pk(np.broadcast_to(x, (r.n,))) for x in (
            D, add_extra_force(X, r.extra_force) - frozen, muP, Ap, c_k, Fr, h, r.d)), r.v0,
            a=None if ca is None else pk(ca))[0]
        return lay.from_packed(vpk)
    a, e, f, z0 = r.coef
    vpk = packed_recursion(lay, a, e, f, pk(-r.d), z0, r.v0)
    return lay.from_packed(vpk)


def mass_sensitivity(params: PredictorParams, s, V0, load, direction, t, v_start, m_s, M, run_index=None,
                     extra_force=None):
    """The free run with a slider mass per sample and its exact derivative with respect to mass parameters.

    ``m_s`` [kg] (scalar or per sample) is the slider's mass inside the recursion, in its inertia
    (``m_eff = m_s + |m|``) and in its weight on the guide (``Fr = mu_sd (9.81 m_s + kappa P)``); ``M`` (n, p)
    [kg per unit parameter] is ``dm_s/dphi`` per sample (an inertia-form channel: ``m_s0`` times
    :func:`l1b2.predictor.effects.channels.mass_columns`). The other arguments are :func:`free_run`'s (Eq. 29's
    drive law only). Returns ``(v, S)``: :func:`free_run`'s speed [m/s] and ``S = dv/dphi`` (n, p) [m/s per unit],
    the forward sensitivity of the same recursion: with ``h = dt / m_eff`` and the step's drive-coordinate force
    ``F = -D v' + X + sg Fr``, a normal step gives ``dv[k+1]/dm_s[k] = d h (-F / m_eff + sg mu_sd 9.81)``; a step
    that reverses, ``v'[k+1] = h F_rest + v' F_rest / F`` (``F_rest = X + z0 Fr``), its derivative in ``m_s`` and
    ``v'``; a stuck step 0.
    """
    if params.drive_law == "pure_slip":
        raise ValueError("mass_sensitivity: Eq. 29's drive law only, not the pure-slip family's")
    r = _free_run_setup(params, s, V0, load, direction, t, v_start, m_s, run_index, extra_force)
    n, lay, pk, d, m, ef = r.n, r.lay, r.lay.to_packed, r.d, r.m_s, r.extra_force
    M = np.asarray(M, dtype=float).reshape(n, -1)
    a, e, f, z0 = r.coef
    D, X, Fr = force_parts(params, r.s, r.V0, d * r.load, m)
    D, X, Fr = (pk(np.broadcast_to(x, (n,))) for x in (D, add_extra_force(X, ef), Fr))
    m_eff, dp = pk(effective_mass(params, r.load, m)), pk(d)
    h = pk(r.dt) / m_eff
    flags = np.zeros(n, dtype=np.int8)
    vpk = packed_recursion(lay, a, e, f, -dp, z0, r.v0, flags)
    vp = dp * vpk
    sg = np.sign(-vp)
    sg[vp == 0] = z0[vp == 0]
    dFr = params.mu_sd * G_M_S2          # dFr/dm_s [N/kg]
    F = -D * vp + X + sg * Fr
    dv = dp * h * (-F / m_eff + sg * dFr)
    rev = flags == STEP_REVERSAL
    if rev.any():
        Frest = X[rev] + z0[rev] * Fr[rev]
        Fk, hr, vr, mr = F[rev], h[rev], vp[rev], m_eff[rev]
        dFrest, dFk = z0[rev] * dFr, sg[rev] * dFr
        dv[rev] = dp[rev] * (-hr / mr * Frest + hr * dFrest + vr * (dFrest * Fk - Frest * dFk) / Fk ** 2)
        a = a.copy()
        a[rev] = (Frest / Fk) * (1.0 + vr * D[rev] / Fk)
    st = flags == STEP_STUCK
    dv[st] = 0.0
    a = np.where(st, 0.0, a)
    S = packed_linear_recursion(lay, a, dv[:, None] * pk(M))
    return lay.from_packed(vpk), lay.from_packed(S)


# ---------------------------------------------------------------------------
# synthetic data
# ---------------------------------------------------------------------------


def design_grid(
    voltages: Iterable[float] = (220.0, 260.0, 300.0, 324.0),
    loads: Iterable[float] = (-0.09, -0.07, -0.05, -0.03, 0.0, 0.03, 0.05, 0.07, 0.09),
    directions: Iterable[int] = (1, -1),
):
    """Full-factorial design (pandas DataFrame: voltage_V, load_kg, direction).

    The default is the paper's rig design: 4 voltages x 9 loads x 2 directions = 72 runs.
    """
    import pandas as pd

    rows = [
        {"voltage_V": float(V), "load_kg": float(m), "direction": int(d)}
        for V in voltages
        for m in loads
        for d in directions
    ]
    return pd.DataFrame(rows)


def _design_arrays(design):
    import pandas as pd

    if isinstance(design, pd.DataFrame):
        df = design
    else:
        rows = []
        for row in design:
            if isinstance(row, Mapping):
                rows.append(dict(row))
            else:
                V, m, dd = row
                rows.append({"voltage_V": V, "load_kg": m, "direction": dd})
        df = pd.DataFrame(rows)
    for col in ("voltage_V", "load_kg", "direction"):
        if col not in df.columns:
            raise ValueError(f"design needs column '{col}'")
    d = df["direction"].to_numpy(dtype=float)
    if not np.all(np.isin(d, (-1.0, 1.0))):
        raise ValueError("design direction must be +1 or -1")
    return (
        df["voltage_V"].to_numpy(dtype=float),
        df["load_kg"].to_numpy(dtype=float),
        d,
    )


def simulate_dataset(
    params: PredictorParams,
    design,
    m_s: float,
    dt: float = 1e-3,
    stroke: Sequence[float] = (-0.02, 0.02),
    noise_std: float = 0.0,
    seed=None,
    max_duration: float = 5.0,
    pause: float = 0.5,
    extra_force=None,
):
    """Virtual traverses with the predictor itself (for tests and benchmarks).

    Each design row (voltage_V, load_kg, direction) is one run: the slider
    starts at rest at the stroke end opposite to its direction and v, s are
    integrated with the predictor step (``v[k+1] = one_step(v[k])``,
    ``s[k+1] = s[k] + dt (v[k] + v[k+1])/2``) until the position leaves the
    stroke or ``max_duration`` elapses; the last sample inside the stroke is
    the last sample of the run (a stuck run records zeros for
    ``max_duration``). :func:`free_run` along the recorded positions from
    v_start = 0 reproduces the noise-free speeds to rounding. ``time_s`` is continuous across runs
    with ``pause`` seconds between runs. ``noise_std`` [m/s] adds white
    Gaussian noise to ``speed_m_s`` only (positions stay exact).
    ``extra_force`` (optional callable) adds a drive-coordinate force [N] to
    X at every step: it is called with a mapping of per-run arrays under the
    data-format column names ``run``, ``position_m``, ``voltage_V``,
    ``direction``, ``load_kg``, ``speed_m_s`` (the noise-free state at the
    start of the step; no ``time_s``) and returns one force per run (or a
    scalar). A feature function written for data frames with
    ``np.asarray(df[col])`` works on it, e.g. ``lambda c: features(c) @ phi``.
    Returns a DataFrame with the data-format columns.
    """
    import pandas as pd

    V0, load, d = _design_arrays(design)
    R = V0.size
    lo, hi = float(stroke[0]), float(stroke[1])
    if not hi > lo:
        raise ValueError("stroke must be (low, high) with high > low [m]")
    nmax = int(round(max_duration / dt)) + 1
    s0 = np.where(d > 0, lo, hi)
    s = s0.copy()
    v = np.zeros(R)
    m_s_arr = np.full(R, float(m_s))
    S = [s.copy()]
    Vv = [v.copy()]
    active = np.ones(R, dtype=bool)
    length = np.ones(R, dtype=int)
    runs = np.arange(R)
    for k in range(1, nmax):
        ef = None
        if extra_force is not None:
            cols = {"run": runs, "position_m": s, "voltage_V": V0, "direction": d, "load_kg": load,
                    "speed_m_s": v}
            ef = np.broadcast_to(np.asarray(extra_force(cols), dtype=float).reshape(-1), (R,))
        v_new = one_step(params, v, s, V0, load, d, dt, m_s_arr, extra_force=ef)
        s_new = s + 0.5 * dt * (v + v_new)
        inside = (s_new >= lo) & (s_new <= hi)
        active &= inside
        if not active.any():
            break
        v = np.where(active, v_new, v)
        s = np.where(active, s_new, s)
        length = length + active
        S.append(s.copy())
        Vv.append(v.copy())
    S = np.array(S)
    Vv = np.array(Vv)
    rng = np.random.default_rng(seed)
    frames = []
    t0 = 0.0
    for r in range(R):
        L = int(length[r])
        t = t0 + dt * np.arange(L)
        speed = Vv[:L, r].copy()
        frames.append(
            pd.DataFrame(
                {
                    "time_s": t,
                    "run": r,
                    "position_m": S[:L, r],
                    "voltage_V": V0[r],
                    "direction": int(d[r]),
                    "load_kg": load[r],
                    "speed_m_s": speed,
                }
            )
        )
        t0 = t[-1] + pause
    df = pd.concat(frames, ignore_index=True)
    if noise_std > 0:
        df["speed_m_s"] = df["speed_m_s"].to_numpy() + rng.normal(0.0, noise_std, len(df))
    return df
