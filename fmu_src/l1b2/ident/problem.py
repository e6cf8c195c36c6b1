"""The maximum-likelihood problem: samples, force terms, residuals, analytic Jacobian.

The identification fits theta of :mod:`l1b2.predictor.model` (Eq. 35 order,
``3 n + 8`` entries for polynomial order n) and optionally the parameters phi
of :class:`l1b2.ident.extra.ExtraForces` to measured traverses in the data
format (docs/reference/data-format.md; SI units: s, m, m/s, V, kg).

Criteria (:class:`LikelihoodProblem`)
-------------------------------------
* ``free_run``: residual ``v_pred_free(k) - v_meas(k)`` [m/s], where the
  predictor propagates its own speed along the measured positions from the
  measured first speed of each run (the stricter figure).
* ``one_step``: ``v_pred(k+1 | v_meas(k)) - v_meas(k+1)`` [m/s] within runs
  (the paper's use).

A boolean ``mask`` selects which samples' residuals enter the likelihood; the
free-run recursion always runs over all samples.

Conditioning
------------
Positions are scaled to x = (s - s_center) / s_half in [-1, 1] and A', B', P
are Legendre series (see :mod:`l1b2.predictor.model`); the optimiser works on
``z = theta[varied] / scale`` (:class:`ScaledObjective`) with ``scale`` the
typical magnitude of each parameter (:func:`param_scale`: group magnitude for
polynomial coefficients; :func:`extra_parameter_scale` for phi).

Analytic Jacobian
-----------------
Free run: forward sensitivities ``S[k+1] = S[k] (1 + h dF/dv) + h dF/dtheta``
(``h = dt / m_eff`` [s/kg]), vectorised over runs and parameters (loop over
the time index only; the rest and reversal steps of
:func:`l1b2.predictor.model.step_drive` have their own exact derivatives).
One step: the sensitivity is ``h dF/dtheta`` at the measured speed. Both are
tested against finite differences (``tests/test_identify.py``). Extra forces
enter as ``dF/dphi = features``.

Data
----
:class:`SampleData` takes a validated :class:`l1b2.data.measurements.Measurements`
as it is, or checks a DataFrame against the same contract
(:func:`l1b2.data.measurements.validate_frame`) and reports a breach as an
:class:`~l1b2.errors.IdentificationError` naming column, row and run.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from numpy.polynomial.legendre import legvander

from ..data.measurements import (
    DIRECTION,
    LOAD,
    POSITION,
    RUN,
    SPEED,
    TIME,
    VOLTAGE,
    Measurements,
    validate_frame_filled,
)
from ..errors import DataFormatError, IdentificationError
from ..predictor.model import (
    SCALAR_NAMES,
    G_of_k0,
    PredictorParams,
    ddrive_factor_dk0,
    dG_dk0,
    drive_factor,
    rest_sign,
    step_drive,
)
from ..predictor.frequency import contact_angle, effective_voltage, sample_frequency
from ..predictor.simulate import (
    STEP_REVERSAL,
    STEP_STUCK,
    RunLayout,
    packed_linear_recursion,
    packed_recursion,
)
from ..units import G_M_S2
from .kernels import drive_derivative
from .pins import RECOMMENDED_FIXED, pinned_parameters

__all__ = [
    "RECOMMENDED_FIXED", "pinned_parameters", "run_label", "SampleData", "ForceCore", "LikelihoodProblem",
    "clip_theta", "param_scale", "strictly_inside", "ParameterSpace", "extra_parameter_scale", "ScaledObjective",
]

# ---------------------------------------------------------------------------
# data
# ---------------------------------------------------------------------------


def run_label(x):
    """A run label for messages and JSON (numpy scalars -> Python)."""
    return x.item() if isinstance(x, np.generic) else x


def _format_error_text(exc: DataFormatError, df: pd.DataFrame) -> str:
    """One line naming column [unit], data row and run of a contract breach of a DataFrame."""
    where = "data"
    if exc.column is not None:
        where += f": column '{exc.column}'" + (f" [{exc.unit}]" if exc.unit else "")
    if exc.row is not None:
        where += f"{',' if exc.column is not None else ':'} row {exc.row}"
        if exc.column != RUN and RUN in df.columns:
            where += f" (run {run_label(df[RUN].iloc[exc.row - 1])})"
    return f"{where}: {exc.problem}"


def _checked_frame(data) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(the frame extra forces are evaluated on, the contract-checked frame) of a Measurements or a DataFrame: the
    caller's frame, or the checked one when gaps of an optional input column were filled in it."""
    if isinstance(data, Measurements):
        return data.df, data.df  # validated when it was read
    if not isinstance(data, pd.DataFrame):
        raise IdentificationError("data must be a Measurements or a pandas DataFrame in the data format")
    try:
        checked, filled = validate_frame_filled(data, "data")
    except DataFormatError as exc:
        raise IdentificationError(_format_error_text(exc, data)) from exc
    return (checked if filled else data), checked


def _derived_speed(s, t, layout) -> np.ndarray:
    """Per-run ``numpy.gradient`` of position over time [m/s] (0 for one-sample runs)."""
    v = np.empty(layout.n)
    for r in range(layout.R):
        sl = slice(layout.starts[r], layout.starts[r] + layout.lengths[r])
        if layout.lengths[r] >= 2:
            v[sl] = np.gradient(s[sl], t[sl])
        else:
            v[sl] = 0.0
    return v


class SampleData:
    """Flat per-sample arrays of measured data in the data format.

    Parameters
    ----------
    data : Measurements or pandas.DataFrame
        A :class:`~l1b2.data.measurements.Measurements` is used as validated
        when read; a DataFrame (e.g. synthetic data) is checked against the
        same contract (:func:`~l1b2.data.measurements.validate_frame`), a
        breach raises :class:`~l1b2.errors.IdentificationError`.
    mask : array_like of bool, shape (n_samples,), optional
        Samples whose residuals enter the likelihood; default all.
    frequency : FrequencyResponse, optional
        The predictor's drive-frequency response (:mod:`l1b2.predictor.frequency`):
        ``V0`` is then the effective amplitude ``V0 g(frequency_Hz)`` (the
        commanded one is ``V0_commanded``); default None: ``V0`` as logged (``contact_a``: contact angles).

    Attributes
    ----------
    frame : pandas.DataFrame
        The caller's table (extra-force features are evaluated on it).
    t, s, V0, d, load, v : ndarray
        time [s], position [m], voltage amplitude [V], direction (+1/-1),
        signed load [kg] and speed [m/s] per sample. Without a
        ``speed_m_s`` column the speed is ``numpy.gradient`` of position
        per run (``speed_derived``).
    run, layout, mask, n
        Run id per sample, its :class:`~l1b2.predictor.simulate.RunLayout`,
        the boolean mask and the number of samples.
    """

    def __init__(self, data, mask=None, frequency=None):
        frame, checked = _checked_frame(data)
        self.frame = frame
        self.run = checked[RUN].to_numpy()
        self.layout = RunLayout(self.run)
        self.t = checked[TIME].to_numpy(dtype=float)
        self.s = checked[POSITION].to_numpy(dtype=float)
        self.V0_commanded = checked[VOLTAGE].to_numpy(dtype=float)
        self.frequency = frequency
        f_s = sample_frequency(checked, None if frequency is None else frequency.f_ref_Hz)
        self.V0 = effective_voltage(self.V0_commanded, f_s, frequency)
        self.contact_a = (contact_angle(self.V0_commanded, f_s, frequency)
                          if frequency is not None and frequency.has_contact else None)
        self.d = checked[DIRECTION].to_numpy(dtype=float)
        self.load = checked[LOAD].to_numpy(dtype=float)
        self.speed_derived = SPEED not in checked.columns
        if self.speed_derived:
            self.v = _derived_speed(self.s, self.t, self.layout)
        else:
            self.v = checked[SPEED].to_numpy(dtype=float)
        n = len(checked)
        if mask is None:
            self.mask = np.ones(n, dtype=bool)
        else:
            m = np.asarray(mask)
            if m.shape != (n,):
                raise IdentificationError(f"mask has shape {m.shape}, expected ({n},)")
            self.mask = m.astype(bool)
        self.n = n

    def check_sufficient(self, n_var: int, order: int) -> None:
        """Refuse data that cannot identify ``n_var`` parameters of polynomial order ``order``."""
        lay = self.layout
        if lay.R < 2:
            raise IdentificationError(f"too few runs: {lay.R}; need at least 2 (different voltages/loads)")
        if np.any(lay.lengths < 2):
            r = int(np.flatnonzero(lay.lengths < 2)[0])
            raise IdentificationError(f"run {run_label(lay.labels[r])} has fewer than 2 samples")
        n_min = max(n_var + 2, 3 * (order + 1))
        if int(self.mask.sum()) < n_min:
            raise IdentificationError(
                f"too few samples: {int(self.mask.sum())} selected, need at least {n_min} "
                f"for {n_var} varied parameters"
            )
        vsel = self.v[self.mask]
        if not np.ptp(self.v) > 1e-9 or np.max(np.abs(vsel)) < 1e-6:
            raise IdentificationError("no speed variation in the data: the slider does not move")

    def position_scaling(self) -> tuple[float, float]:
        """``(s_center, s_half)`` [m] mapping the travelled positions onto x in [-1, 1]."""
        s_lo, s_hi = float(np.min(self.s)), float(np.max(self.s))
        if not s_hi - s_lo > 1e-6:
            raise IdentificationError("no position variation in the data (position_m constant)")
        return 0.5 * (s_lo + s_hi), 0.5 * (s_hi - s_lo)

    def sample_period(self) -> float:
        """Median time step within runs [s] (NaN without one)."""
        dts = np.diff(self.t)[~self.layout.is_last[:-1]]
        return float(np.median(dts)) if dts.size else float("nan")


# ---------------------------------------------------------------------------
# model core on arbitrary sample sets
# ---------------------------------------------------------------------------


class ForceCore:
    """Force terms of Eq. 29 and their theta-derivatives on one set of samples.

    Parameters
    ----------
    L : ndarray, shape (n, order + 1)
        Legendre basis at the scaled positions x = (s - s_center) / s_half.
    V0 : ndarray
        Drive voltage amplitude per sample [V].
    mp : ndarray
        Load mass in drive coordinates, ``direction * load_kg`` [kg].
    h : ndarray
        ``dt / m_eff`` per step [s/kg].
    d : ndarray
        Drive direction (+1 / -1) per sample.
    m_s : float
        Slider mass [kg].
    kappa : float
        Share of the preload loading the guide [-].
    E : ndarray, shape (n, n_extra), optional
        Extra-force features [N per unit phi] (drive coordinates).
    """

    def __init__(self, L, V0, mp, h, d, m_s, kappa, E=None):
        self.L = np.ascontiguousarray(L)
        self.V0 = V0
        self.mp = mp
        self.h = h
        self.d = d
        self.hd = h * d
        self.m_s = float(m_s)
        self.kappa = float(kappa)
        self.n1 = L.shape[1]
        #: length of the Eq. 35 part; entries beyond it are the extra-force parameters phi
        self.p_theta = 5 + 3 * self.n1
        #: extra-force features (drive coordinates, N per unit phi), or None
        self.E = None if E is None else np.ascontiguousarray(E, dtype=float)

    def terms(self, theta):
        """A'(s) [-], P(s) [N], D [N s/m], drive force X [N] and guide friction Fr [N] at ``theta``."""
        n1 = self.n1
        c_r, sig, mu, k0, musd = theta[:5]
        Ap = self.L @ theta[5 : 5 + n1]
        Bp = self.L @ theta[5 + n1 : 5 + 2 * n1]
        P = self.L @ theta[5 + 2 * n1 : 5 + 3 * n1]
        g1 = float(drive_factor(k0))
        G = float(G_of_k0(k0))
        D = c_r + sig * (0.5 - Ap)
        X = Bp * self.V0 + mu * P * (g1 - 0.5 * np.pi * Ap * G) - G_M_S2 * self.mp
        if self.E is not None:
            X = X + self.E @ theta[self.p_theta :]
        Fr = musd * (G_M_S2 * self.m_s + self.kappa * P)
        return Ap, P, D, X, Fr

    def dF(self, theta, vp, sg, Ap, P, cols, rows=None):
        """dF/dtheta[cols] (drive coordinates) at drive speed vp (on ``rows`` if given).

        ``sg`` is the effective sign(-v') (static-friction value at rest).
        """
        n1 = self.n1
        L = self.L if rows is None else self.L[rows]
        V0 = self.V0 if rows is None else self.V0[rows]
        c_r, sig, mu, k0, musd = theta[:5]
        g1 = float(drive_factor(k0))
        G = float(G_of_k0(k0))
        dg1 = float(ddrive_factor_dk0(k0))
        dG = float(dG_dk0(k0))
        cols = np.asarray(cols, dtype=int)
        p_all = self.p_theta + (0 if self.E is None else self.E.shape[1])
        full = cols.size == p_all and np.array_equal(cols, np.arange(p_all))
        # all columns, block by block (the cheap way on long data); a subset is taken from them
        out = np.empty((vp.size, p_all))
        out[:, 0] = -vp
        out[:, 1] = -(0.5 - Ap) * vp
        out[:, 2] = P * (g1 - 0.5 * np.pi * Ap * G)
        out[:, 3] = mu * P * (dg1 - 0.5 * np.pi * Ap * dG)
        out[:, 4] = sg * (G_M_S2 * self.m_s + self.kappa * P)
        np.multiply(L, (sig * vp - mu * P * 0.5 * np.pi * G)[:, None], out=out[:, 5 : 5 + n1])
        np.multiply(L, V0[:, None], out=out[:, 5 + n1 : 5 + 2 * n1])
        np.multiply(L, (mu * (g1 - 0.5 * np.pi * Ap * G) + sg * musd * self.kappa)[:, None],
                    out=out[:, 5 + 2 * n1 : self.p_theta])
        if self.E is not None:  # extra force: X += E phi, dF/dphi = E (whatever the speed)
            out[:, self.p_theta :] = self.E if rows is None else self.E[rows]
        return out if full else out[:, cols]

    #: whether :meth:`weighted_dF` may use the compiled loop of this class's :meth:`dF` (Eq. 29's force)
    compiled_dF = True

    def weighted_dF(self, theta, vp, sg, Ap, P, cols, w):
        """``w[:, None] * dF(theta, vp, sg, Ap, P, cols)`` on all rows (:func:`l1b2.ident.kernels.drive_derivative`)."""
        U = drive_derivative(self, theta, vp, sg, Ap, P, cols, w) if self.compiled_dF else None
        if U is None:
            U = self.dF(theta, vp, sg, Ap, P, cols)
            U *= w[:, None]
        return U


class LikelihoodProblem:
    """Residuals and analytic Jacobian of one criterion on one data set.

    Parameters
    ----------
    data : SampleData
        The samples; ``data.mask`` selects the residuals of the likelihood.
    order : int
        Polynomial order n of A', B', P.
    kappa : float
        Share of the preload loading the guide [-].
    include_load_inertia : bool
        m_eff = m_s + |m_load| (True) or m_s.
    criterion : {"free_run", "one_step"}
        Free-run or one-step-ahead residuals (see the module docstring).
    s_center, s_half : float
        Position scaling [m]: x = (s - s_center) / s_half.
    m_s : float
        Slider mass [kg].
    E : ndarray, shape (n_samples, n_extra), optional
        Extra-force features [N per unit phi]; ``theta`` then has the extra
        parameters appended.

    Notes
    -----
    Residuals ``v_pred - v_meas`` [m/s] on the selected samples, in the order
    of :attr:`sel` (packed order for the free run). Evaluations are cached
    for the last theta; :meth:`reset_cache` forgets it (after changing an
    input such as :attr:`v0`).
    """

    def __init__(self, data: SampleData, order, kappa, include_load_inertia, criterion, s_center, s_half, m_s,
                 E=None):
        self.data = data
        self.criterion = criterion
        lay = data.layout
        self.lay = lay
        self.s_center = s_center
        self.s_half = s_half
        x = (data.s - s_center) / s_half
        L = legvander(x, order)
        m_eff = m_s + (np.abs(data.load) if include_load_inertia else 0.0)
        dt = lay.step_dt(data.t)
        h = dt / m_eff
        mp = data.d * data.load
        self.m_s = m_s
        if criterion == "free_run":
            pk = lay.to_packed
            self.core = ForceCore(pk(L), pk(data.V0), pk(mp), pk(h), pk(data.d), m_s, kappa,
                              None if E is None else pk(E))
            self.nd = -self.core.d
            self.v0 = data.v[lay.starts][lay.run_order]
            mask_p = pk(data.mask)
            self.sel = np.flatnonzero(mask_p)
            self.z = pk(data.v)[self.sel]
            self.run_sel = pk(lay.run_of_sample)[self.sel]
            self.sample_sel = lay.perm[self.sel]  # flat sample index of each residual
        elif criterion == "one_step":
            idx = np.flatnonzero(~lay.is_last)
            self.idx = idx
            self.core = ForceCore(L[idx], data.V0[idx], mp[idx], h[idx], data.d[idx], m_s, kappa,
                              None if E is None else E[idx])
            self.vprev = data.v[idx]
            keep = data.mask[idx + 1]
            self.sel = np.flatnonzero(keep)
            self.z = data.v[idx + 1][self.sel]
            self.run_sel = lay.run_of_sample[idx + 1][self.sel]
            self.sample_sel = (idx + 1)[self.sel]
        else:
            raise IdentificationError(f"criterion must be 'free_run' or 'one_step', got {criterion!r}")
        self._cache_theta = None
        self._cache = None

    def reset_cache(self):
        """Forget the cached evaluation (call after changing an input such as :attr:`v0`)."""
        self._cache_theta = None
        self._cache = None

    def evaluate(self, theta):
        """Prediction and force terms at ``theta`` (packed order for free_run, step pairs for one_step).

        Returns a dict: ``v`` (predicted speed [m/s]), ``a`` (free run: the
        recursion factor), ``Ap``, ``P``, ``D``, ``X``, ``Fr``, ``z0`` (rest
        sign), ``vp`` (drive speed at the step start), ``sg`` (sign of -v',
        static value at rest) and ``flags`` (step kinds, see
        :mod:`l1b2.predictor.simulate`).
        """
        if self._cache_theta is not None and np.array_equal(theta, self._cache_theta):
            return self._cache
        core = self.core
        Ap, P, D, X, Fr = core.terms(theta)
        z0 = rest_sign(X, Fr)
        if self.criterion == "free_run":
            a = 1.0 - core.h * D
            flags = np.zeros(self.lay.n, dtype=np.int8)
            with np.errstate(over="ignore", invalid="ignore"):
                v = packed_recursion(self.lay, a, core.hd * X, core.hd * Fr, self.nd, z0, self.v0, flags)
            vsrc = v
        else:
            vp0 = core.d * self.vprev
            with np.errstate(over="ignore", invalid="ignore"):
                vnew = step_drive(vp0, D, X, Fr, core.h)
            v = core.d * vnew
            a = None
            vsrc = self.vprev
            # classify the steps like packed_recursion does
            flags = np.zeros(v.size, dtype=np.int8)
            stuck = np.abs(z0) < 1.0
            rest = vp0 == 0
            with np.errstate(over="ignore", invalid="ignore"):
                eul = vp0 + core.h * (-D * vp0 + X + np.sign(-vp0) * Fr)
            cross = (~rest) & (vp0 * eul < 0)
            flags[cross] = STEP_REVERSAL
            flags[(cross | rest) & stuck] = STEP_STUCK
        return self._store(theta, core, v, a, vsrc, flags, Ap, P, D, X, Fr, z0)

    def _store(self, theta, core, v, a, vsrc, flags, Ap, P, D, X, Fr, z0) -> dict:
        """Cache and return one evaluation: the Coulomb sign at each step's start state (the static rule's
        ``z0`` at rest), with the speeds, sensitivities and forces of the recursion."""
        vp = core.d * vsrc
        sg = np.sign(-vp)
        rest = vp == 0
        if rest.any():
            sg[rest] = z0[rest]
        res = {"v": v, "a": a, "Ap": Ap, "P": P, "sg": sg, "flags": flags, "D": D, "X": X, "Fr": Fr,
               "z0": z0, "vp": vp}
        self._cache_theta = np.array(theta, copy=True)
        self._cache = res
        return res

    def residual(self, theta):
        """Residuals ``v_pred - v_meas`` [m/s] on the selected samples."""
        v = self.evaluate(theta)["v"]
        return v[self.sel] - self.z

    def _sensitivity_rows(self, theta, c, rows, cols):
        """Step sensitivities on ``rows``: returns (a_rows, U_rows) in the data convention.

        Normal step: dv[k+1] = a dv[k] + h d dF/dtheta. Reversal within the
        step (see predictor.step_drive): v'[k+1] = h F_rest + v' F_rest/F with
        F the moving force at v' and F_rest = X + z0 Fr. Stuck: 0.
        """
        core = self.core
        vp = c["vp"][rows]
        h = core.h[rows]
        d = core.d[rows]
        D, X, Fr, z0 = c["D"][rows], c["X"][rows], c["Fr"][rows], c["z0"][rows]
        Ap, P = c["Ap"][rows], c["P"][rows]
        sgm = np.sign(-vp)
        Fk = -D * vp + X + sgm * Fr
        Frest = X + z0 * Fr
        dFk = core.dF(theta, vp, sgm, Ap, P, cols, rows=rows)
        dFr = core.dF(theta, np.zeros_like(vp), z0, Ap, P, cols, rows=rows)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            a_r = (Frest / Fk) * (1.0 + vp * D / Fk)
            U = (h + vp / Fk)[:, None] * dFr - (vp * Frest / Fk**2)[:, None] * dFk
        U *= d[:, None]
        return a_r, U

    def jacobian(self, theta, cols, packed=False):
        """d residual / d theta[cols] (unweighted): forward sensitivities for the free run (``packed``: of all
        packed rows, the residual rows being :attr:`sel`; one_step: the residual rows either way)."""
        c = self.evaluate(theta)
        core = self.core
        flags = c["flags"]
        if self.criterion == "free_run":
            U = core.weighted_dF(theta, c["vp"], c["sg"], c["Ap"], c["P"], cols, core.hd)
            a = c["a"]
            if flags.any():
                a = a.copy()
                rev = np.flatnonzero(flags == STEP_REVERSAL)
                if rev.size:
                    a[rev], U[rev] = self._sensitivity_rows(theta, c, rev, cols)
                st = flags == STEP_STUCK
                U[st] = 0.0
                a[st] = 0.0
            with np.errstate(over="ignore", invalid="ignore"):
                S = packed_linear_recursion(self.lay, a, U)
            return S if packed else S[self.sel]
        sub = self.sel
        U = core.dF(theta, c["vp"][sub], c["sg"][sub], c["Ap"][sub], c["P"][sub], cols, rows=sub)
        U *= core.hd[sub, None]
        fl = flags[sub]
        if fl.any():
            rev = np.flatnonzero(fl == STEP_REVERSAL)
            if rev.size:
                U[rev] = self._sensitivity_rows(theta, c, sub[rev], cols)[1]
            U[fl == STEP_STUCK] = 0.0
        return U

    def _start_factor(self, theta, c) -> np.ndarray:
        """The free run's recursion factor ``a`` per step for the start gain (:meth:`start_gain`): the evaluation's,
        with a reversing step's taken from its sensitivity row and a stuck step's set to 0 (``c``: ``evaluate(theta)``)."""
        a, flags = c["a"], c["flags"]
        if flags.any():
            a = a.copy()
            rev = np.flatnonzero(flags == STEP_REVERSAL)
            if rev.size:
                a[rev] = self._sensitivity_rows(theta, c, rev, [0])[0]
            a[flags == STEP_STUCK] = 0.0
        return a

    def start_gain(self, theta):
        """g = d v_pred / d v_start on the residual rows (free run; zeros for one_step).

        The free run starts from the *measured* first speed, whose noise
        propagates as ``g * delta0`` into every residual of the run.
        """
        if self.criterion != "free_run":
            return np.zeros(self.sel.size)
        c = self.evaluate(theta)
        a = self._start_factor(theta, c)
        with np.errstate(over="ignore", invalid="ignore"):
            g = packed_linear_recursion(self.lay, a, np.zeros((self.lay.n, 1)), S0=1.0)
        g = g[self.sel, 0]
        return np.where(np.isfinite(g), g, 0.0)

    def start_gain_sensitivity(self, theta, cols):
        """``(g, dg/dtheta[cols])`` on the residual rows (free run; zeros for one_step).

        ``g`` is :meth:`start_gain`; its derivative obeys the linear recursion
        ``G[k+1] = a[k] G[k] + g[k] da[k]/dtheta`` with ``a = 1 - h D``: only
        c_r, sigma and alpha (the parameters of D) have non-zero columns. The
        recursion factor of a step that reverses or sticks is held fixed (its
        derivative is left out: such steps are rare and isolated).
        """
        cols = np.asarray(cols, dtype=int)
        if self.criterion != "free_run":
            return np.zeros(self.sel.size), np.zeros((self.sel.size, cols.size))
        c = self.evaluate(theta)
        a = self._start_factor(theta, c)
        normal = c["flags"] == 0
        core = self.core
        n1 = core.n1
        with np.errstate(over="ignore", invalid="ignore"):
            g = packed_linear_recursion(self.lay, a, np.zeros((self.lay.n, 1)), S0=1.0)[:, 0]
            dD = np.zeros((self.lay.n, cols.size))
            for j, col in enumerate(cols):
                if col == 0:
                    dD[:, j] = 1.0
                elif col == 1:
                    dD[:, j] = 0.5 - c["Ap"]
                elif 5 <= col < 5 + n1:
                    dD[:, j] = -theta[1] * core.L[:, col - 5]
            U = dD * (-(core.h * g * normal))[:, None]
            G = packed_linear_recursion(self.lay, a, U)
        g, G = g[self.sel], G[self.sel]
        return np.where(np.isfinite(g), g, 0.0), np.where(np.isfinite(G), G, 0.0)

    def predict_all(self, theta):
        """Predictions for every sample (flat order); one_step: NaN at run starts."""
        v = self.evaluate(theta)["v"]
        if self.criterion == "free_run":
            return self.lay.from_packed(v)
        out = np.full(self.data.n, np.nan)
        out[self.idx + 1] = v
        return out




# ---------------------------------------------------------------------------
# parameter vector, scaling, bounds
# ---------------------------------------------------------------------------


def clip_theta(theta, order):
    """Clip the Eq. 35 part of theta into its bounds (extra entries, if any, unchanged)."""
    lo, hi = PredictorParams.bounds(order)
    out = np.array(theta, dtype=float, copy=True)
    out[: lo.size] = np.clip(out[: lo.size], lo, hi)
    return out


def param_scale(theta, order):
    """Typical magnitudes: |value| (with floors) for scalars, group max for polynomials."""
    n1 = order + 1
    scale = np.ones(theta.size)  # entries beyond Eq. 35 (extra forces) are scaled by the caller
    floors = {"c_r": 1e-3, "sigma": 1e-4, "mu": 1e-2, "k0": 0.05, "mu_sd": 1e-2}
    for i, nm in enumerate(SCALAR_NAMES):
        scale[i] = max(abs(theta[i]), floors[nm])
    for g in range(3):
        sl = slice(5 + g * n1, 5 + (g + 1) * n1)
        scale[sl] = max(float(np.max(np.abs(theta[sl]))), 1e-12)
    return scale


def strictly_inside(z, lb, ub):
    """``z`` clipped into [lb, ub] and moved strictly below finite upper bounds."""
    z = np.clip(z, lb, ub)
    fin = np.isfinite(ub)
    top = np.where(fin, ub - 1e-9 * np.maximum(np.abs(np.where(fin, ub, 0.0)), 1.0), np.inf)
    return np.minimum(z, top)


class ParameterSpace:
    """The joint parameter vector ``[theta, phi]``: names, bounds and pins.

    Parameters
    ----------
    order : int
        Polynomial order n; theta has the 3 n + 8 entries of
        :meth:`l1b2.predictor.model.PredictorParams.names`.
    extra : ExtraForces or None
        Extra-force parameters phi appended to theta.
    fixed : None, "recommended", sequence of names or mapping name -> value
        Pinned parameters (value ``None`` = pinned at the start value).
        ``"recommended"`` pins :data:`RECOMMENDED_FIXED` (:func:`~l1b2.ident.pins.pinned_parameters`).

    Attributes
    ----------
    names, theta_names, extra_names : list of str
    p_theta, size : int
        Length of theta and of the joint vector.
    lo, hi : ndarray
        Bounds of the joint vector.
    fixed : dict
        name -> value (float) or None, in the order given.
    varied : ndarray of bool
        False for pinned entries.
    fixed_values : dict
        The pins that have a value.
    """

    def __init__(self, order: int, extra=None, fixed=None):
        self.order = int(order)
        self.theta_names = PredictorParams.names(self.order)
        self.extra_names = [] if extra is None else list(extra.names)
        self.names = self.theta_names + self.extra_names
        self.p_theta = len(self.theta_names)
        self.size = len(self.names)
        lo_t, hi_t = PredictorParams.bounds(self.order)
        self.xlo, self.xhi = extra.bounds() if extra is not None else (np.zeros(0), np.zeros(0))
        self.lo = np.concatenate([lo_t, self.xlo])
        self.hi = np.concatenate([hi_t, self.xhi])
        self.fixed = pinned_parameters(fixed, self.names)
        self.varied = np.ones(self.size, dtype=bool)
        for k in self.fixed:
            self.varied[self.names.index(k)] = False
        self.fixed_values = {k: v for k, v in self.fixed.items() if v is not None}

    def index(self, name: str) -> int:
        return self.names.index(name)

    def clip(self, theta):
        """Copy of the joint vector clipped into the bounds."""
        th = clip_theta(theta, self.order)
        th[self.p_theta:] = np.clip(th[self.p_theta:], self.xlo, self.xhi)
        return th

    def with_fixed(self, theta):
        """Copy of the joint vector with the valued pins applied."""
        th = theta.copy()
        for k, v in self.fixed_values.items():
            th[self.names.index(k)] = v
        return th


def extra_parameter_scale(problem: LikelihoodProblem, theta0, E, mask, m_s):
    """Scale of phi: the magnitude that makes each extra force ~1 % of the typical drive force.

    Returns ``max(|phi0|, 0.01 * X_typ / rms(feature))`` per extra parameter,
    X_typ [N] the median |drive force| at ``theta0`` (at least 10 % of the
    slider weight) and rms over the masked samples.
    """
    p_theta = problem.core.p_theta
    with np.errstate(over="ignore", invalid="ignore"):
        X0 = problem.core.terms(theta0)[3]
    X0 = np.abs(X0[np.isfinite(X0)])
    x_typ = float(np.median(X0)) if X0.size else 1.0
    x_typ = max(x_typ, 0.1 * G_M_S2 * m_s)
    nx = E.shape[1]
    e_rms = np.sqrt(np.mean(E[mask] ** 2, axis=0)) if mask.any() else np.ones(nx)
    e_rms = np.where(e_rms > 0, e_rms, 1.0)
    return np.maximum(np.abs(theta0[p_theta:]), 0.01 * x_typ / e_rms)


class ScaledObjective:
    """Whitened residuals of a :class:`LikelihoodProblem` in scaled coordinates.

    ``z = theta[varied] / scale``; the other entries stay at ``theta0``. The
    residual vector is ``noise.weighted(v_pred - v_meas)`` (dimensionless:
    0.5 * its squared norm is the negative log-likelihood up to a constant
    for fixed noise variances); non-finite entries are replaced by 1e10
    (Jacobian: 0) so that least_squares backs off.

    Parameters
    ----------
    problem : LikelihoodProblem
    noise : NoiseModel
        :class:`l1b2.ident.noise.NoiseModel` on ``problem.run_sel``.
    theta0 : ndarray
        Joint vector holding the pinned values.
    varied : ndarray of bool
    scale : ndarray
        Scale of every joint entry.
    lo, hi : ndarray
        Bounds of the joint vector.
    start_noise : bool
        Model the noise of the measured start speed (free run).
    """

    def __init__(self, problem, noise, theta0, varied, scale, lo, hi, start_noise):
        self.problem = problem
        self.noise = noise
        self.theta0 = theta0
        self.vidx = np.flatnonzero(varied)
        self.sv_scale = scale[self.vidx]
        self.zlo = lo[self.vidx] / self.sv_scale
        self.zhi = hi[self.vidx] / self.sv_scale
        self.start_noise = bool(start_noise)

    def z_of(self, theta):
        """Scaled coordinates of a joint vector (strictly inside the bounds)."""
        return strictly_inside(theta[self.vidx] / self.sv_scale, self.zlo, self.zhi)

    def theta_of(self, z):
        th = self.theta0.copy()
        th[self.vidx] = z * self.sv_scale
        return th

    def fun(self, z):
        r = self.problem.residual(self.theta_of(z))
        out = self.noise.weighted(r)
        if not np.all(np.isfinite(out)):
            out = np.where(np.isfinite(out), out, 1e10)
        return out

    def jac(self, z, order="C"):
        """Jacobian of :meth:`fun` (non-finite entries 0), in memory order ``order`` ("C" or "F")."""
        return self.jac_columns(z, slice(None), order)

    def jac_columns(self, z, cols, order="C"):
        """Columns ``cols`` (indices into z) of :meth:`jac` (``NoiseModel.weighted_jacobian`` of the sensitivities)."""
        prob, packed = self.problem, getattr(self.problem, "criterion", None) == "free_run"  # (Eq. 29 or pure slip)
        S = prob.jacobian(self.theta_of(z), self.vidx[cols], packed=True) if packed else prob.jacobian(
            self.theta_of(z), self.vidx[cols])
        rows = prob.sel if packed else np.arange(S.shape[0])
        return self.noise.weighted_jacobian(S, rows, self.sv_scale[cols], order)

    def update_noise(self, theta):
        """Re-estimate g (start-speed propagation) and R at theta; returns the max relative R change."""
        if self.start_noise:
            self.noise.set_start_gain(self.problem.start_gain(theta))
        return self.noise.update_R(self.problem.residual(theta))
