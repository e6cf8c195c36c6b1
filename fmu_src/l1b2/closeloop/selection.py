"""Scoring and choosing candidates: exact, cheap scores against a fixed baseline, and selection rules.

With the baseline fixed, an extra force changes the free-run speed
*linearly* (the speed recursion is affine in the force), so each candidate is
scored exactly and cheaply: its free-run response ``S`` is computed by the
baseline's linear recursion (:func:`linear_response`), the TRAIN residual is
regressed on ``S`` together with the baseline's own re-identification
directions (:func:`nuisance_forces`) with K-fold cross-validation over runs
(:class:`FoldSolver`), and information criteria (AIC and BIC with the
AR(1)-effective sample size) are computed on all of TRAIN
(:func:`score_candidates`).

Selection that does not fool itself (plain functions, :func:`choose` applies
them in turn): a candidate is significant (:func:`significant`) when its
held-out gain (share of the held-out residual sum of squares it removes) is
at least ``min_gain``, its run-level Wilcoxon p-value is below
:func:`significance_level` (``alpha`` / number of families tested) and its
AIC improves on the baseline (AIC, asymptotically leave-one-out
cross-validation, rather than BIC: with the strongly autocorrelated free-run
residual the effective sample size is small and BIC's log n penalty would
overrule a held-out gain seen in nearly every run; both are reported). Among
significant candidates the most parsimonious one within ``parsimony`` of the
best gain is chosen (:func:`most_parsimonious`: named families before generic
smooth terms, then fewer parameters).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..ident.coarse import decimation, every_qth
from ..predictor import model as pr
from . import residuals as res
from .acceptance import NAMED_SHARE, one_se_gap_per_run, pooled_gain, time_dependent
from .candidates import CandidateForce

DEFAULT_MIN_GAIN = 0.5
DEFAULT_ALPHA = 0.01
DEFAULT_PARSIMONY = 0.9
#: smallest linearised held-out gain for the shortlist of the cross-validated refit
SHORTLIST_MIN_GAIN = 0.05


# ---------------------------------------------------------------------------
# exact linear response of the baseline free run to extra forces
# ---------------------------------------------------------------------------

def linear_response(params: pr.PredictorParams, df: pd.DataFrame, m_s: float, F: np.ndarray,
                    v_pred=None, *, overwrite_F: bool = False) -> np.ndarray:
    """Drive-coordinate free-run speed response to drive-coordinate forces ``F`` (n x k) [m/s per unit].

    ``S(k+1) = (1 - h_k D_k) S(k) + h_k F_k`` with ``h = dt / m_eff`` and ``D``
    the baseline's damping at the measured position, ``S = 0`` at each
    run's first sample (the free run starts from the measured speed).
    Exact for a moving slider (constant sign of the guide friction). For the
    pure-slip family the damping is ``D - dX/dv'`` at the baseline's free-run
    speed ``v_pred`` (data convention; the drive force's own slope,
    :func:`l1b2.predictor.model.speed_slope`), to first order.

    ``overwrite_F``: ``F`` (a float64 array) is overwritten with ``S`` and returned (no n x k array is made);
    the values are those of the default form to the last bit.
    """
    d = df[dataio.DIRECTION].to_numpy(float)
    s = df[dataio.POSITION].to_numpy(float)
    V0 = df[dataio.VOLTAGE].to_numpy(float)
    load = df[dataio.LOAD].to_numpy(float)
    t = df[dataio.TIME].to_numpy(float)
    D, _, _ = pr.force_parts(params, s, V0, d * load, m_s)
    if v_pred is not None:
        D = D - pr.speed_slope(params, s, V0, d * np.asarray(v_pred, float))
    D = np.broadcast_to(D, s.shape)
    m_eff = pr.effective_mass(params, load, m_s)
    if overwrite_F and not (isinstance(F, np.ndarray) and F.dtype == np.float64):
        raise ValueError("overwrite_F needs a float64 array")
    S = (F if overwrite_F else np.array(F, float)).reshape(len(df), -1)
    if overwrite_F and not np.shares_memory(S, F):
        raise ValueError("overwrite_F needs an array whose n x k reshape is a view")
    slices = [sl for _, sl in dataio.run_slices(df[dataio.RUN])]
    starts = np.array([sl.start for sl in slices])
    lengths = np.array([sl.stop - sl.start for sl in slices])
    dt = np.zeros(len(df))
    dt[:-1] = np.diff(t)
    h = dt / m_eff
    a = 1.0 - h * D
    # S is written over F row by row: f holds each run's force at its current row, read before that row is written
    f = S[starts]
    S[starts] = 0.0
    for k in range(int(lengths.max()) - 1):
        act = lengths > k + 1
        cur = starts[act] + k
        f_cur = f[act]
        f[act] = S[cur + 1]
        S[cur + 1] = a[cur, None] * S[cur] + h[cur, None] * f_cur
    return S


#: the most float64 values of candidates' forces over all samples integrated at once (:func:`candidate_responses`;
#: 128 MB)
BLOCK_VALUES = 1 << 24


def screen_mask(df: pd.DataFrame, mask) -> np.ndarray:
    """The samples the linearised screen compares on: ``mask``'s samples that are every ``q``-th of their run
    (:func:`l1b2.ident.coarse.every_qth`), ``q`` = :func:`l1b2.ident.coarse.decimation` (one sample per
    :data:`l1b2.ident.coarse.COARSE_PERIOD_S` at most: ``mask`` itself at 1 kHz or slower), a boolean array. The
    responses are integrated over every sample; only the rows they are compared on (and the collinearity checks'
    rows) are thinned, which keeps the screen's arrays, and its cost, those of a 1 kHz log."""
    return np.asarray(mask, bool) & every_qth(df[dataio.RUN].to_numpy(), decimation(df))


def screen_rows(df: pd.DataFrame, mask) -> np.ndarray:
    """The rows of :func:`screen_mask`, increasing."""
    return np.flatnonzero(screen_mask(df, mask))


def candidate_responses(candidates, df: pd.DataFrame, idx: np.ndarray, params: pr.PredictorParams, m_s: float, *,
                        v_pred=None, block_values: int = BLOCK_VALUES) -> tuple[np.ndarray, list[int]]:
    """The candidates' free-run responses (:func:`linear_response`) at the rows ``idx`` of ``df``, side by side
    (``len(idx)`` x the sum of their widths), and each candidate's width (its features' columns, which must be
    its ``n_params``). The forces are evaluated and integrated over all of ``df``'s samples in blocks of
    consecutive candidates holding at most ``block_values`` values (a wider candidate alone), so no array over
    every sample holds more than a block; the recursion acts column by column, so the values are those of one
    integration of all the forces, to the last bit."""
    n = len(df)
    out = np.empty((len(idx), sum(c.n_params for c in candidates)))
    widths, pending, done = [], [], 0      # done: the columns of ``out`` written

    def flush(start: int) -> int:
        S = linear_response(params, df, m_s, np.column_stack(pending), v_pred=v_pred, overwrite_F=True)
        out[:, start:start + S.shape[1]] = S[idx]
        pending.clear()
        return start + S.shape[1]
    for c in candidates:
        f = np.asarray(c.features(df), float).reshape(n, -1)
        if f.shape[1] != c.n_params:
            raise ValueError(f"candidate {c.label}: its features have {f.shape[1]} columns for {c.n_params} "
                             "parameters")
        if pending and n * (sum(widths) - done + f.shape[1]) > block_values:
            done = flush(done)
        pending.append(f)
        widths.append(f.shape[1])
    if pending:
        flush(done)
    return out, widths


def _rows_in_place(X: np.ndarray, idx: np.ndarray, block: int = 256) -> np.ndarray:
    """``X[idx]`` for increasing ``idx``, written into ``X``'s first ``len(idx)`` rows (a view is returned)."""
    if len(idx) == len(X) or len(idx) == 0:
        return X[:len(idx)]
    cuts = np.flatnonzero(np.diff(idx) != 1) + 1
    dst = 0
    for lo, hi in zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [len(idx)]])):
        src, n = int(idx[lo]), int(hi - lo)
        for o in range(0, n if src != dst else 0, block):   # in blocks: an overlapping copy buffers only a block
            b = min(block, n - o)
            X[dst + o:dst + o + b] = X[src + o:src + o + b]
        dst += n
    return X[:len(idx)]


def position_basis(params: pr.PredictorParams, s_m) -> np.ndarray:
    """The baseline's position series per sample: ``L_j(x)``, ``j = 0..order``, the Legendre polynomials of the
    scaled position ``x`` (:meth:`~l1b2.predictor.model.PredictorParams.scaled_position` of ``s_m`` [m], clipped to
    ``[-1.2, 1.2]``), ``(n, order + 1)``."""
    from numpy.polynomial.legendre import legvander
    return legvander(np.clip(params.scaled_position(np.asarray(s_m, float)), -1.2, 1.2), params.order)


def nuisance_forces(params: pr.PredictorParams, df: pd.DataFrame, v_pred: np.ndarray) -> np.ndarray:
    """Forces spanning Eq. 29's own function space around the fit (drive coordinates).

    Perturbations of D(s), B'(s) and the offset E(s) as Legendre series in
    the scaled position (:func:`position_basis`): ``-v' L_j(x)``, ``V0 L_j(x)``, ``L_j(x)``. Their
    free-run responses are the re-identification directions of the baseline:
    a candidate gets credit only for what the baseline cannot absorb by
    re-fitting itself (a score test with nuisance parameters).
    """
    Lv = position_basis(params, df[dataio.POSITION].to_numpy(float))
    vp = df[dataio.DIRECTION].to_numpy(float) * np.asarray(v_pred, float)
    V0 = df[dataio.VOLTAGE].to_numpy(float)
    return np.column_stack([-vp[:, None] * Lv, V0[:, None] * Lv / 300.0, Lv])


# ---------------------------------------------------------------------------
# scoring
# ---------------------------------------------------------------------------

#: why a round refits a candidate (:attr:`Score.origin`, a trial's ``offered_by`` in ``report.json``): it passed the
#: linearised screen, the run-level evidence offered it (:func:`l1b2.closeloop.runlevel.offer`), the round before
#: accepted it and added another (:func:`carried`), it is a named family beside a generic term
#: (:func:`named_alternatives`) or another shape of a shortlisted family (:func:`shape_alternatives`)
ORIGINS = ("screen", "run_level", "carried", "named", "shape")


@dataclass
class Score:
    """A candidate's evidence: held-out gain, run-level p-value, runs improved, AIC/BIC change, fitted phi."""

    candidate: CandidateForce
    cv_gain: float
    p_value: float
    runs_improved: float
    delta_bic: float
    phi: np.ndarray
    delta_aic: float = 0.0
    #: the in-sample log-likelihood change counting each TRAIN run once, ``n_runs log(SSE_1 / SSE_0)``: the scale of
    #: a run-level shape's profile over its grid (:func:`l1b2.closeloop.evidence.peak_profile`), where the samples
    #: of one run do not inform the shape independently
    dll_runs: float = 0.0
    #: why a round refits it (:data:`ORIGINS`)
    origin: str = "screen"

    def to_dict(self) -> dict:
        """The report's row of this candidate (``effect`` is the candidate's family)."""
        c = self.candidate
        return {"effect": c.family, "label": c.label, "regressor": c.regressor, "generic": c.generic,
                "n_params": c.n_params, "cv_gain": self.cv_gain, "p_value": self.p_value,
                "runs_improved": self.runs_improved, "delta_aic": self.delta_aic, "delta_bic": self.delta_bic,
                "parameters": dict(zip(c.names, (float(x) for x in self.phi)))}


def _effective_n(r: np.ndarray, runs: np.ndarray) -> float:
    """Sample count corrected for lag-1 autocorrelation within runs."""
    n_eff = 0.0
    for run in pd.unique(runs):
        x = r[runs == run]
        if len(x) < 3:
            n_eff += len(x)
            continue
        rho = float(np.clip(res.acf(x, 1)[1], 0.0, 0.99))
        n_eff += len(x) * (1 - rho) / (1 + rho)
    return max(n_eff, 1.0)


def _basis(A, rcond=1e-12):
    """Thin SVD of ``A`` restricted to the directions above ``rcond`` (relative): ``(U, V / s)``."""
    U, sv, Vt = np.linalg.svd(A, full_matrices=False)
    keep = sv > rcond * max(float(sv[0]) if sv.size else 0.0, 1e-300)
    return U[:, keep], Vt[keep].T / sv[keep]


def _solve_small(M, b, scale):
    """Least-squares solution of the small symmetric system ``M x = b`` (directions below 1e-10 ``scale`` cut)."""
    w, V = np.linalg.eigh(M)
    keep = w > 1e-10 * max(scale, 1e-300)
    return V[:, keep] @ ((V[:, keep].T @ b) / w[keep])


class FoldSolver:
    """Cross-validated least squares over runs with a fixed nuisance block (its factorisations precomputed).

    ``y`` the residual, ``N`` the nuisance responses (an intercept is added),
    ``runs`` the run id per sample and ``folds`` the held-out run ids per
    fold. :meth:`gain` scores one candidate response ``S`` against the
    nuisance-only model, :meth:`gains` many at once.

    The nuisance block's SVD on each fold's training rows is computed once;
    a candidate's columns are projected off it (one matrix product for all
    candidates), so each candidate costs only its own small normal
    equations: the least-squares fit of ``[A, S]`` exactly, by the
    Frisch-Waugh-Lovell theorem.
    """

    def __init__(self, y, N, runs, folds):
        self.y, self.runs, self.folds = y, runs, folds
        self.A = np.column_stack([np.ones(len(y)), N])
        self.keys = []
        self.parts = []
        for fold in folds:
            test = np.isin(runs, fold)
            tr = ~test
            U, W = _basis(self.A[tr])
            beta0 = W @ (U.T @ y[tr])
            yp = y[tr] - U @ (U.T @ y[tr])
            e0 = y[test] - self.A[test] @ beta0
            labels, code = np.unique(runs[test], return_inverse=True)
            order = pd.unique(runs[test])
            self.keys += list(order)
            self.parts.append((test, tr, U, W, yp, e0, code, [int(np.searchsorted(labels, r)) for r in order]))
        self.sse0 = self._run_sse([(np.bincount(p[6], weights=p[5] ** 2), p) for p in self.parts])

    def _run_sse(self, per_fold) -> dict:
        out = {}
        for sums, part in per_fold:
            labels = pd.unique(self.runs[part[0]])
            out.update({run: float(sums[k]) for run, k in zip(labels, part[7])})
        return out

    def gains(self, S_all, widths, work=None) -> list:
        """:meth:`gain` of every candidate: ``S_all`` holds their columns side by side, ``widths`` their counts.

        ``work``: two C-contiguous float64 arrays of at least ``S_all``'s shape, not sharing memory with it,
        used as scratch (overwritten); made here when not given.
        """
        bounds = np.cumsum([0] + list(widths))
        sums = [[] for _ in widths]
        # each fold's training rows, their projection and its held-out rows go into two arrays (a fresh n x k array
        # costs the kernel its pages each time): the training rows fill the first rows, the held-out rows the rest;
        # the same products as S_tr - U @ (U.T @ S_tr) and S_te - A_te @ (W @ C)
        rows_buf, proj_buf = _scratch(work, S_all.shape)
        for part in self.parts:
            test, tr, U, W, yp, e0, code, _ = part
            n_tr, n_te = U.shape[0], len(e0)
            S_tr = np.compress(tr, S_all, axis=0, out=rows_buf[:n_tr])
            C = U.T @ S_tr
            Sp = np.subtract(S_tr, np.matmul(U, C, out=proj_buf[:n_tr]), out=proj_buf[:n_tr])
            Spy = Sp.T @ yp
            S_te = np.compress(test, S_all, axis=0, out=rows_buf[n_tr:n_tr + n_te])
            T_te = np.subtract(S_te, np.matmul(self.A[test], W @ C, out=proj_buf[n_tr:n_tr + n_te]), out=S_te)
            norms = np.einsum("ij,ij->j", S_tr, S_tr)
            for j, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
                Spj = Sp[:, a:b]
                coef = _solve_small(Spj.T @ Spj, Spy[a:b], float(np.max(norms[a:b])))
                e = e0 - T_te[:, a:b] @ coef
                sums[j].append((np.bincount(code, weights=e * e, minlength=len(part[7])), part))
        keys = self.keys
        s0 = np.array([self.sse0[k] for k in keys])
        out = []
        for per_fold in sums:
            sse1 = self._run_sse(per_fold)
            s1 = np.array([sse1[k] for k in keys])
            out.append((pooled_gain(s0, s1), (s0 - s1) / max(s0.mean(), 1e-300)))
        return out

    def gain(self, S):
        """Pooled held-out gain of ``S`` and the per-run reductions (scaled by the mean null SSE)."""
        S = np.asarray(S, float).reshape(len(self.y), -1)
        return self.gains(S, [S.shape[1]])[0]


def _scratch(work, shape):
    """Two float64 arrays of ``shape`` (rows x columns): the first ones of ``work``'s, or new ones."""
    if work is None:
        return np.empty(shape), np.empty(shape)
    if any(w.dtype != np.float64 or not w.flags.c_contiguous or w.shape[0] < shape[0] or w.shape[1] != shape[1]
           for w in work):
        raise ValueError("work: two C-contiguous float64 arrays with at least the rows and the columns of S_all")
    return tuple(w[:shape[0]] for w in work)


def insample_fits(A, y, S_all, widths, work=None):
    """Least squares of ``y`` on ``[A, S_j]`` for every candidate j on all rows: ``(sse0, [(sse1, coef_S)])``.

    ``work``: as in :meth:`FoldSolver.gains` (its first array holds the projection).
    """
    U, _ = _basis(A)
    yp = y - U @ (U.T @ y)
    out_buf = None if work is None else _scratch(work, S_all.shape)[0]
    Sp = np.matmul(U, U.T @ S_all, out=out_buf)
    Sp = np.subtract(S_all, Sp, out=Sp)
    Spy = Sp.T @ yp
    norms = np.einsum("ij,ij->j", S_all, S_all)
    sse0 = float(yp @ yp)
    out = []
    bounds = np.cumsum([0] + list(widths))
    for a, b in zip(bounds[:-1], bounds[1:]):
        Spj = Sp[:, a:b]
        coef = _solve_small(Spj.T @ Spj, Spy[a:b], float(np.max(norms[a:b])))
        r = yp - Spj @ coef
        out.append((float(r @ r), coef))
    return sse0, out


def finite_columns(X: np.ndarray) -> np.ndarray:
    """``X`` without its columns that hold a value that is not finite (a free-run response whose linearised
    recursion diverges where the local damping is negative, :func:`linear_response`); ``X`` itself when all are."""
    ok = np.isfinite(X).all(axis=0)
    return X if ok.all() else X[:, ok]


def usable_response(S) -> bool:
    """Whether a candidate's response columns ``S`` can be scored: every value finite (its linearised recursion
    does not diverge, :func:`linear_response`) and not all zero."""
    S = np.asarray(S, float)
    return bool(np.all(np.isfinite(S)) and not np.allclose(S, 0))


def design(candidate: CandidateForce, r_drive, df, mask, params, m_s, *, v_pred):
    """``(y, A, S, runs)`` on the masked samples: residual, intercept + nuisance responses (those that are finite,
    :func:`finite_columns`), candidate response (not finite where its linearised recursion diverges)."""
    idx = np.flatnonzero(mask)
    with np.errstate(over="ignore", invalid="ignore"):
        N = finite_columns(linear_response(params, df, m_s, nuisance_forces(params, df, v_pred), v_pred=v_pred)[idx])
        F = np.asarray(candidate.features(df), float).reshape(len(df), -1)
        S = linear_response(params, df, m_s, F, v_pred=v_pred)[idx]
    A = np.column_stack([np.ones(len(idx)), N])
    return r_drive[idx], A, S, df[dataio.RUN].to_numpy()[idx]


def shortlist(scores: list[Score], *, level: float, min_gain: float, size: int,
              within_family: bool = False) -> list[Score]:
    """The best candidate of each family passing the linearised screen (gain, run-level p, AIC), best ``size``.

    By default a family is judged by its best-gain candidate (the screen's level is corrected over families), a
    searched one (a grid point of a shape, :func:`search_count` above 1) only when it passes: a failing searched
    hypothesis is no evidence against its family's others, so a family passes when its best-gain unsearched
    candidate does, or when a better searched one does (its p-value carries the grid's correction).
    ``within_family``: by the best-gain candidate of those that pass (for an uncorrected level)."""
    def passes(s):
        return s.cv_gain >= min_gain and s.p_value < level and s.delta_aic < 0
    ok = best_per_family([s for s in scores if passes(s)]) if within_family else [
        s for s in best_per_family([s for s in scores if search_count(s.candidate) <= 1 or passes(s)]) if passes(s)]
    return ok[:size]


def screened(scores: list[Score], *, level: float, min_gain: float, size: int,
             fallback_level: float | None = None) -> tuple[list[Score], float]:
    """``(shortlist, level used)``: the best ``size`` families passing the screen at the corrected ``level``
    (:func:`shortlist`); when none passes and ``fallback_level`` is set, the one best family at that uncorrected
    level, each family judged by its best-gain hypothesis among those that pass (``within_family``), since the
    uncorrected level is not a family-wise rule. The cross-validated refit, not this screen, decides what is added.
    """
    short = shortlist(scores, level=level, min_gain=min_gain, size=size)
    if short or not fallback_level:
        return short, level
    return shortlist(scores, level=fallback_level, min_gain=min_gain, size=1, within_family=True), fallback_level


def named_alternatives(short: list[Score], scores: list[Score], share, *, min_gain: float,
                       min_share: float | None = None) -> list[Score]:
    """Named families to cross-validate beside the shortlist's generic terms that they may be the physics of.

    For each generic candidate of ``short``, the best-gain named family of ``scores`` (best of its family, not in
    ``short``, linearised gain at least ``min_gain``) whose span explains at least ``min_share`` of the generic
    term's linearised force (``share(named_candidate, generic_score)``;
    default :data:`l1b2.closeloop.acceptance.NAMED_SHARE`); each at most once. The acceptance then compares
    them on the same folds (:func:`l1b2.closeloop.acceptance.named_reading`).
    """
    min_share = NAMED_SHARE if min_share is None else min_share
    taken = {s.candidate.family for s in short}
    named = [s for s in best_per_family(scores) if not s.candidate.generic and s.candidate.family not in taken
             and s.cv_gain >= min_gain]
    out = []
    for g in (s for s in short if s.candidate.generic):
        for s in named:     # by decreasing gain
            if s.candidate.family not in taken and share(s.candidate, g) >= min_share:
                out.append(replace(s, origin="named"))
                taken.add(s.candidate.family)
                break
    return out


def search_count(candidate: CandidateForce) -> int:
    """How many hypotheses a candidate's shape was chosen among (its spec's ``grid_points``, 1 without one): a
    channel's peak is one point of a grid of centres and widths (:func:`l1b2.predictor.effects.channels.peak_grid`)
    that the screen searches, so its run-level p-value is multiplied by the grid's size (Bonferroni over the grid,
    on top of the correction over families)."""
    return max(int(candidate.spec.get("grid_points", 1)), 1)


def searched_params(candidate: CandidateForce) -> int:
    """How many shape parameters of a candidate were chosen on a grid rather than fitted: 2 for a channel's peak
    (its centre and width), else 0 (the parsimony rule of :func:`simplest_within_one_se` counts them)."""
    return 2 if shape_of(candidate) == "peak" else 0


def counted_params(candidate: CandidateForce) -> int:
    """The parameters the parsimony rules count for a candidate: its fitted ones and those a grid chose
    (:func:`searched_params`)."""
    return candidate.n_params + searched_params(candidate)


def shape_of(candidate: CandidateForce) -> str:
    """The shape of a candidate within its family: its spec's ``shape`` (a channel's ``linear``, ``quadratic`` or
    ``odd``; ``linear`` for a spec without one)."""
    return str(candidate.spec.get("shape", "linear"))


def shape_alternatives(short: list[Score], scores: list[Score], *, level: float, min_gain: float) -> list[Score]:
    """The other shapes of the shortlisted families, for the cross-validated refit to choose between.

    For each family of ``short`` whose hypotheses come in more than one shape (:func:`shape_of`), the best-gain
    hypothesis of ``scores`` of every other shape of that family that passes the same screen as the shortlist
    (held-out gain >= ``min_gain``, run-level p < ``level``, an AIC improvement), by decreasing gain; each
    family's shape at most once, nothing already in ``short``. The screen keeps the best of a family by its
    linearised gain; the refit's acceptance and its parsimony rule (fewest parameters within the parsimony of the
    best cross-validated gain) then choose the shape, as they choose between families.
    """
    listed = {id(s.candidate) for s in short}
    taken = {(s.candidate.family, shape_of(s.candidate)) for s in short}
    families = {s.candidate.family for s in short}
    pool = [s for s in significant(scores, level=level, min_gain=min_gain)
            if s.candidate.family in families and (s.candidate.family, shape_of(s.candidate)) not in taken
            and id(s.candidate) not in listed]
    return [replace(s, origin="shape") for s in best_per_family(pool, key=lambda c: (c.family, shape_of(c)))]


#: a shape's polynomial degree in the channel's standardised value (:func:`shape_degree`)
SHAPE_DEGREE = {"linear": 1, "quadratic": 2, "odd": 3}


def shape_degree(candidate: CandidateForce) -> int:
    """The degree of a candidate's shape as a polynomial in its channel's standardised value: 1 (``linear``, and
    every candidate without a shape), 2 (``quadratic``), 3 (``odd``)."""
    return SHAPE_DEGREE.get(shape_of(candidate), 1)


def simplest_within_one_se(accepted: list) -> list:
    """The accepted refits with each family's shapes reduced to one: the one-standard-error rule.

    Per family of ``accepted`` (:class:`~l1b2.closeloop.acceptance.RefitCV` trials; a family has several when
    :func:`shape_alternatives` sent its other shapes to the refit), the trial with the largest cross-validated gain
    (:func:`best_per_family`) and every trial whose gain is below it by at most one standard error of the gap are
    candidates; the simplest is kept: fewest parameters (:func:`counted_params`), then the lowest
    :func:`shape_degree`, then the largest gain. The gap and its standard error are paired per held-out run
    (:func:`~l1b2.closeloop.acceptance.one_se_gap_per_run`, on the same folds and current model): per run ``r``,
    ``delta_r = (SSE_trial_r - SSE_best_r) / mean_r SSE_current_r``, the gap ``mean(delta)`` (the pooled gains'
    difference exactly) and ``se = sd(delta) / sqrt(n_runs)``. A gap beyond its standard error, or one that cannot
    be computed, leaves the best. Families with one trial, and the order of the kept trials, are unchanged.
    """
    best = {t.candidate.family: t for t in best_per_family(accepted, gain=lambda t: t.gain)}

    def close(t) -> bool:
        b = best[t.candidate.family]
        if t is b:
            return True
        gap = one_se_gap_per_run(t, b)
        return gap is not None and gap[0] <= gap[1]

    keep = {}
    for t in accepted:
        if close(t):
            f = t.candidate.family
            key = (counted_params(t.candidate), shape_degree(t.candidate), -t.gain)
            if f not in keep or key < keep[f][0]:
                keep[f] = (key, t)
    kept = {id(t) for _, t in keep.values()}
    return [t for t in accepted if id(t) in kept]


def to_carry(accepted: list, pick) -> list:
    """What a round accepted and did not add that points elsewhere: the candidates of the round's ``accepted``
    refit trials (:class:`~l1b2.closeloop.acceptance.RefitCV`) not of ``pick``'s family and sharing no regressor
    with ``pick``, best held-out gain first.

    When the next round has nothing else to refit, it refits the first of them that is still allowed and still
    shown (:func:`carried`): a cause whose evidence passed this round's screen or run-level level and the
    cross-validated refit is refit against the model with ``pick`` added, rather than lost when the next round's
    level (corrected for every channel the rig logs) no longer reaches it."""
    regs = set(pick.candidate.regressors)
    ok = [t for t in accepted if t.candidate.family != pick.candidate.family and not regs & set(t.candidate.regressors)]
    return [t.candidate for t in sorted(ok, key=lambda t: -t.gain)]


def carried(carry: list, allowed, score, run_p, *, level: float, min_gain: float) -> list:
    """The one candidate of the previous round's :func:`to_carry` list that a round refits when it has nothing else
    to refit, as a :class:`Score` (none when no candidate qualifies): the first, in ``carry``'s order, that
    ``allowed(candidate)`` (not added, not collinear with what is, no named/generic conflict) and whose evidence
    against the current model still holds at the uncorrected ``level``, the kind of evidence that offered it:
    ``run_p(candidate)`` (:meth:`~l1b2.closeloop.runlevel.RunLevelAnalysis.signal_p`: a run-level candidate's
    signal's run-level p-value, None for any other candidate or without a run-level analysis) below ``level``;
    otherwise its linearised score (``score(candidates)``, e.g. :func:`score_candidates`) :func:`significant` at
    ``level`` with ``min_gain``. What the added effect explained is not offered again."""
    cands = [c for c in carry if allowed(c)]

    def shown(s) -> bool:
        p = run_p(s.candidate)
        return bool(significant([s], level=level, min_gain=min_gain)) if p is None else p < level
    return [replace(s, origin="carried") for s in score(cands) if shown(s)][:1] if cands else []


def refit_list(short: list[Score], offered: list, carry: list, scores: list[Score], *, allowed, score, run_p,
               share, level: float, screen: float, min_gain: float) -> list[Score]:
    """What a round cross-validates by refitting, each :class:`Score` tagged with why (``origin``), in this order:
    the screen's shortlist ``short``; the run-level candidates ``offered``
    (:func:`l1b2.closeloop.runlevel.offer`) as scored by ``score``; when both are empty, the :func:`carried`
    candidate of ``carry`` (``allowed``, ``score``, ``run_p`` at ``level``); then the list's
    :func:`named_alternatives` (``share``) and :func:`shape_alternatives` (at ``screen``) among the round's
    ``scores``, all with ``min_gain``."""
    out = short + [replace(s, origin="run_level") for s in score(offered)]
    out = out or carried(carry, allowed, score, run_p, level=level, min_gain=min_gain)
    out = out + named_alternatives(out, scores, share, min_gain=min_gain)
    return out + shape_alternatives(out, scores, level=screen, min_gain=min_gain)


def score_candidates(candidates, r_drive, df, mask, params, m_s, *, v_pred, k=5, seed=0,
                     time_folds=None, folds=None) -> list[Score]:
    """Cross-validated gain, run-level p-value (times :func:`search_count`) and AIC/BIC change of every candidate.

    A searched shape's grid (a channel's peak) is profiled first: of each group's points only the best in-sample
    fit is cross-validated (:func:`profile_choice`); the others get gain 0 and p-value 1 with their in-sample AIC
    and BIC change (the profile likelihood over the grid).

    The regression of the TRAIN residual on a candidate's free-run response
    includes the nuisance responses (:func:`nuisance_forces`) in both the
    null and the candidate model (a nuisance response that is not finite, where the linearised recursion of
    :func:`linear_response` diverges, is left out; a candidate whose response is not finite or zero scores gain 0
    and p-value 1); folds are whole runs (``time_folds``, run ids per fold, when given: the
    folds of the candidates that depend on the session clock,
    :func:`l1b2.closeloop.acceptance.time_dependent`, e.g. contiguous blocks of the session; ``folds``, when
    given: those of the other candidates, else ``k`` folds of the runs shuffled by ``seed``,
    :func:`l1b2.closeloop.residuals.run_folds`). The rows scored are :func:`screen_rows`: the masked samples,
    every ``q``-th of each run when the log is sampled faster than one sample per millisecond.
    """
    if not candidates:
        return []
    runs = df[dataio.RUN].to_numpy()
    idx = screen_rows(df, mask)
    y, runs_m = r_drive[idx], runs[idx]
    folds = res.run_folds(runs_m, k, seed) if folds is None else folds
    n_eff = _effective_n(y, runs_m)
    n_runs = len(pd.unique(runs_m))
    with np.errstate(over="ignore", invalid="ignore"):   # a diverging response is left out below, not warned of
        N = _rows_in_place(linear_response(params, df, m_s, nuisance_forces(params, df, v_pred), v_pred=v_pred,
                                           overwrite_F=True), idx)
        S_all, widths = candidate_responses(candidates, df, idx, params, m_s, v_pred=v_pred)
    N = finite_columns(N)
    solver = FoldSolver(y, N, runs_m, folds)
    time_solver = FoldSolver(y, N, runs_m, time_folds) if time_folds is not None else solver
    A = solver.A
    usable = [usable_response(S_all[:, a:a + w]) for a, w in zip(np.cumsum([0] + widths[:-1]), widths)]
    cols = np.concatenate([np.arange(a, a + w) for a, w, u in zip(np.cumsum([0] + widths[:-1]), widths, usable) if u]
                          + [np.zeros(0, int)]).astype(int)
    w_ok = [w for w, u in zip(widths, usable) if u]
    S_ok = S_all if all(usable) else S_all[:, cols]   # a copy only when a candidate is left out
    work = (np.empty(S_ok.shape), np.empty(S_ok.shape)) if w_ok else None
    sse0, fits = insample_fits(A, y, S_ok, w_ok, work) if w_ok else (0.0, [])
    kept = profile_choice([c for c, u in zip(candidates, usable) if u], [f[0] for f in fits])
    if not all(kept):   # the grid points no better in-sample than their group's best are not cross-validated
        starts = np.cumsum([0] + w_ok[:-1])
        S_ok = S_ok[:, np.concatenate([np.arange(a, a + w) for a, w, k in zip(starts, w_ok, kept) if k]
                                      + [np.zeros(0, int)]).astype(int)]
        work = (np.empty(S_ok.shape), np.empty(S_ok.shape))
    w_cv = [w for w, k in zip(w_ok, kept) if k]
    cv = iter(solver.gains(S_ok, w_cv, work)) if w_cv else iter(())
    fits, kept = iter(fits), iter(kept)
    out = []
    for c, w, u, start in zip(candidates, widths, usable, np.cumsum([0] + widths[:-1])):
        if not u:
            out.append(Score(c, 0.0, 1.0, 0.0, 0.0, np.zeros(w)))
            continue
        sse1, coef = next(fits)
        dll = n_eff * math.log(max(sse1, 1e-300) / max(sse0, 1e-300))
        if not next(kept):
            out.append(Score(c, 0.0, 1.0, 0.0, dll + w * math.log(n_eff), coef, dll + 2 * w, dll * n_runs / n_eff))
            continue
        gain, per_run = next(cv)
        if time_solver is not solver and time_dependent(c):   # scored on session blocks
            gain, per_run = time_solver.gain(np.ascontiguousarray(S_all[:, start:start + w]))
        p = min(1.0, res.wilcoxon_greater(per_run) * search_count(c))
        out.append(Score(c, gain, p, float(np.mean(per_run > 0)),
                         dll + w * math.log(n_eff), coef, dll + 2 * w, dll * n_runs / n_eff))
    return out


def profile_choice(candidates, sse) -> list[bool]:
    """Which candidates the screen cross-validates: every one but the grid points of a searched shape (a
    :func:`search_count` above 1) that are not their group's best in-sample fit (smallest ``sse``, the first of
    equals); a group is a family's shape at one form and level (a channel's peak of one form: its grid of centres
    and widths, profiled on TRAIN). The others are scored by their in-sample fit only (gain 0, p-value 1)."""
    best: dict = {}
    for i, c in enumerate(candidates):
        if search_count(c) > 1:
            key = (c.family, c.spec.get("form"), c.spec.get("level"), shape_of(c))
            if key not in best or sse[i] < sse[best[key]]:
                best[key] = i
    chosen = set(best.values())
    return [search_count(c) <= 1 or i in chosen for i, c in enumerate(candidates)]


# ---------------------------------------------------------------------------
# selection rules
# ---------------------------------------------------------------------------

def significance_level(scores: list[Score], alpha: float = DEFAULT_ALPHA) -> float:
    """Bonferroni level: ``alpha`` over the number of candidate families tested."""
    families = {s.candidate.family for s in scores}
    return alpha / max(len(families), 1)


def significant(scores: list[Score], *, level: float, min_gain: float = DEFAULT_MIN_GAIN) -> list[Score]:
    """Candidates with held-out gain >= ``min_gain``, run-level p < ``level`` and an AIC improvement."""
    return [s for s in scores if s.cv_gain >= min_gain and s.p_value < level and s.delta_aic < 0]


def most_parsimonious(scores: list[Score], *, parsimony: float = DEFAULT_PARSIMONY) -> Score | None:
    """Among ``scores``, those within ``parsimony`` of the best gain: named before generic, then fewest parameters
    (:func:`counted_params`: a grid's choices count), then the largest gain."""
    if not scores:
        return None
    best = max(s.cv_gain for s in scores)
    close = [s for s in scores if s.cv_gain >= parsimony * best]
    close.sort(key=lambda s: (s.candidate.generic, counted_params(s.candidate), -s.cv_gain))
    return close[0]


class Choice(NamedTuple):
    """What :func:`choose` decided: the significant candidates, the chosen one (or None), the level used."""

    significant: list
    chosen: Score | None
    level: float


def choose(scores: list[Score], *, alpha=DEFAULT_ALPHA, min_gain=DEFAULT_MIN_GAIN,
           parsimony=DEFAULT_PARSIMONY) -> Choice:
    """The significant candidates and the chosen one (None when nothing is significant)."""
    level = significance_level(scores, alpha)
    sig = significant(scores, level=level, min_gain=min_gain)
    return Choice(sig, most_parsimonious(sig, parsimony=parsimony), level)


def best_per_family(scores: list, key=lambda c: c.family, gain=lambda s: s.cv_gain) -> list:
    """The best-gain candidate of each family (or of each ``key(candidate)``: e.g. a family's shape), by decreasing
    held-out gain; of equal gains the first. ``scores``: anything with a ``candidate``; ``gain(s)`` its gain (default
    a :class:`Score`'s ``cv_gain``; a refit trial's ``gain``)."""
    best = {}
    for s in scores:
        k = key(s.candidate)
        if k not in best or gain(s) > gain(best[k]):
            best[k] = s
    return sorted(best.values(), key=lambda s: -gain(s))
