"""Acceptance of a candidate by cross-validation of the *re-identified* model over whole runs.

The linearised score (:mod:`l1b2.closeloop.selection`) only shortlists: it
assumes the current model's parameters stay put, which is wrong when the
baseline itself is imperfect (its structural error is absorbed differently
once a term is added). Here each shortlisted candidate is judged by what a
user would see on new runs:

* TRAIN's runs are split into ``k`` folds (:mod:`l1b2.closeloop.folds`: seeded,
  stratified by direction and voltage; or whole conditions);
* for each fold, the current model (its accepted effects included) and the
  current model + the candidate are both re-identified on the other folds
  (warm start from the current fit, one local search with a bounded budget,
  the candidate's parameters started from its linearised fit on the same
  training folds only) and predict the held-out fold in free run;
* the candidate is accepted when the pooled held-out free-run error
  (sum of squares on the evaluation mask) falls by at least ``min_gain``
  (relative) and falls in most folds (:func:`accepts`).

An :class:`EffectSet` is the ordered list of accepted candidates with their
parameter values; it builds the :class:`~l1b2.ident.extra.ExtraForces` of
the joint identification.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from ..cluster import run_tasks
from ..data import measurements as dataio
from ..errors import IdentificationError
from ..ident.coarse import decimate, decimation
from ..ident.estimator import ExtraForces, PredictorIdentifier
from ..predictor import effects as fx
from . import chain
from .folds import held_out_split, held_out_times
from .candidates import CandidateForce
from .events import SUFFIX as EVENT_SUFFIX
from ..units import LAG_SUFFIX_RE

DEFAULT_REFIT_FOLDS = 4
#: splits of TRAIN's runs into the refit's folds (repeated cross-validation, :func:`repeated_folds`)
DEFAULT_REFIT_REPEATS = 1
#: splits of TRAIN's runs over which a round whose fold vote is tied is cross-validated again (:func:`tied`)
DEFAULT_TIE_REPEATS = 3
DEFAULT_REFIT_NFEV = 10
DEFAULT_MIN_CV_GAIN = 0.03
#: smallest fall of the cross-validated free-run nrmse (absolute, share of the speed's rms): a relative gain of a
#: residual already near the noise floor is not worth a new term
DEFAULT_MIN_CV_DROP = 0.005


@dataclass(frozen=True)
class EffectSet:
    """Accepted candidates, in order, with the start values of their parameters."""

    candidates: tuple = ()
    phi: tuple = ()          #: one array of parameter values per candidate

    def add(self, c: CandidateForce, phi) -> EffectSet:
        return EffectSet(self.candidates + (c,), self.phi + (np.asarray(phi, float).ravel(),))

    @property
    def families(self) -> set:
        return {c.family for c in self.candidates}

    @property
    def labels(self) -> list[str]:
        """The accepted candidates' labels, in order (round ``r`` added ``labels[r - 1]``)."""
        return [c.label for c in self.candidates]

    def start(self) -> np.ndarray:
        """The parameters' start values, each candidate's inside its physical range."""
        return np.concatenate([c.clip(p) for c, p in zip(self.candidates, self.phi)]) if self.phi else np.zeros(0)

    def bounds(self) -> tuple[tuple, tuple] | None:
        """``(lower, upper)`` of every parameter in order (None when no candidate is bounded)."""
        if not any(c.bounds for c in self.candidates):
            return None
        lo, hi = [], []
        for c in self.candidates:
            b = c.bounds or ((-np.inf, np.inf),) * c.n_params
            lo.extend(float(x[0]) for x in b)
            hi.extend(float(x[1]) for x in b)
        return tuple(lo), tuple(hi)

    def extra(self) -> ExtraForces | None:
        """The joint extra forces (None when empty)."""
        if not self.candidates:
            return None
        cands = self.candidates

        def features(df):
            return np.column_stack([np.asarray(c.features(df), float).reshape(len(df), -1) for c in cands])
        names = tuple(n for c in cands for n in c.names)
        units = tuple(u for c in cands for u in c.units)
        desc = "; ".join(c.description for c in cands)
        lo, hi = self.bounds() or (None, None)
        return ExtraForces(names=names, units=units, features=features, start=tuple(self.start()),
                           lower=lo, upper=hi, description=desc)

    def with_phi(self, phi_all) -> EffectSet:
        """The same candidates with the parameter values ``phi_all`` (flat, in order)."""
        out, i = [], 0
        for c in self.candidates:
            out.append(np.asarray(phi_all[i:i + c.n_params], float))
            i += c.n_params
        return EffectSet(self.candidates, tuple(out))


#: relative residual below which an added effect's force lies in a candidate's span (collinear, :func:`collinear`)
COLLINEAR_RTOL = 1e-3


def collinear(candidate: CandidateForce, effects: EffectSet, df: pd.DataFrame, mask: np.ndarray,
              rtol: float = COLLINEAR_RTOL, added: AddedColumns | None = None) -> bool:
    """Whether ``candidate`` and the added effects share a direction: a column of one lies in the other's span.

    Both ways are checked on the masked samples. Each added column ``f`` is fitted
    by least squares on the candidate's columns, and each candidate column ``c``
    on the added columns together; collinear when a residual's norm is below
    ``rtol`` of ``|f|`` (or ``|c|``). Both in one model would trade their
    parameters against each other (a pulley coefficient of -22.9 cancelled by a
    generic load term of -20.4), or leave a parameter without a standard error,
    so such a candidate is not offered once the effect is in. ``added``:
    :func:`added_columns` of ``effects``, computed once for many candidates
    (default: computed here).
    """
    if not effects.candidates:
        return False
    a = added_columns(effects, df, mask) if added is None else added
    if a.rows != int(np.count_nonzero(mask)):
        raise ValueError(f"collinear: the added columns have {a.rows} rows for {int(np.count_nonzero(mask))} masked "
                         "samples (computed on another mask)")
    if not a.columns.shape[1]:
        return False
    C = np.asarray(candidate.features(df), float).reshape(len(df), -1)[np.asarray(mask, bool)]
    coef = np.linalg.lstsq(C, a.columns, rcond=None)[0]   # one factorisation of C for every added column
    if np.any(np.linalg.norm(a.columns - C @ coef, axis=0) < rtol * a.norms):
        return True
    nc = np.linalg.norm(C, axis=0)
    C, Q = C[:, nc > 0], a.basis                  # the other way: a candidate column in the added columns' span
    return bool(np.any(np.linalg.norm(C - Q @ (Q.T @ C), axis=0) < rtol * nc[nc > 0]))


@dataclass(frozen=True)
class AddedColumns:
    """The added effects' non-zero feature columns on the masked samples (:func:`added_columns`), with what
    :func:`collinear` reads of them for every candidate: their norms and an orthonormal basis of their span (each
    column scaled to unit norm first, so a small column keeps its direction)."""
    columns: np.ndarray
    norms: np.ndarray
    basis: np.ndarray

    @property
    def rows(self) -> int:
        """The masked samples the columns were computed on."""
        return self.columns.shape[0]


def added_columns(effects: EffectSet, df: pd.DataFrame, mask: np.ndarray) -> AddedColumns:
    """The added effects' feature columns side by side on the masked samples (:func:`collinear`'s ``added``)."""
    m = np.asarray(mask, bool)
    F = np.column_stack([np.asarray(c.features(df), float).reshape(len(df), -1)[m] for c in effects.candidates]
                        + [np.zeros((int(m.sum()), 0))])
    nf = np.linalg.norm(F, axis=0)
    F, nf = F[:, nf > 0], nf[nf > 0]
    return AddedColumns(F, nf, _orth(F / nf) if F.shape[1] else np.zeros((len(F), 0)))


#: squared canonical correlation at and above which a named effect and a generic term share a direction (after the
#: nuisance directions): a variance inflation factor ``1 / (1 - r2)`` of 10 or more, the usual limit beyond which
#: one coefficient is not identified apart from the other's (:func:`max_canonical_r2`)
SHARED_R2 = 0.9
#: share of a generic term's fitted force that a named family's span must explain for the named form to be read as
#: what the generic term models: more than half ("most of it", :func:`explained_share`)
NAMED_SHARE = 0.5


def _orth(X: np.ndarray, rtol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis of the column span of ``X`` (directions below ``rtol`` of the largest singular value cut)."""
    X = np.asarray(X, float)
    if not X.size:
        return np.zeros((X.shape[0], 0))
    U, sv, _ = np.linalg.svd(X, full_matrices=False)
    return U[:, sv > rtol * max(float(sv[0]), 1e-300)]


def off_nuisance(X: np.ndarray, N: np.ndarray | None) -> np.ndarray:
    """``X`` with its least-squares projection on ``[1, N]`` removed (the part no re-fit of the nuisance absorbs).

    A column whose remainder is below 1e-9 of its own norm lies in the nuisance's span: its remainder is
    round-off and is returned as zeros.
    """
    X = np.asarray(X, float).reshape(len(X), -1)
    A = np.ones((len(X), 1)) if N is None else np.column_stack([np.ones(len(X)), np.asarray(N, float)])
    return _project_off(X, _orth(A))


def _project_off(X: np.ndarray, U: np.ndarray) -> np.ndarray:
    """``X - U U' X`` (``U`` orthonormal), columns left with less than 1e-9 of their norm set to zero."""
    R = X - U @ (U.T @ X)
    R[:, np.linalg.norm(R, axis=0) <= 1e-9 * np.linalg.norm(X, axis=0)] = 0.0
    return R


def max_canonical_r2(X: np.ndarray, Y: np.ndarray, N: np.ndarray | None = None) -> float:
    """The largest squared canonical correlation of the columns of ``X`` and ``Y`` after ``[1, N]`` (0 to 1).

    The squared cosine of the smallest principal angle between the two spans once the nuisance is projected off:
    1 when some combination of ``X`` is a combination of ``Y`` (plus nuisance), so that a model with both trades
    their coefficients along that direction; 0 when the spans are orthogonal. A term with no direction left
    after the nuisance has 0.
    """
    Qx, Qy = _orth(off_nuisance(X, N)), _orth(off_nuisance(Y, N))
    if not (Qx.shape[1] and Qy.shape[1]):
        return 0.0
    return float(min(np.linalg.norm(Qx.T @ Qy, 2) ** 2, 1.0))


def explained_share(x: np.ndarray, Y: np.ndarray, N: np.ndarray | None = None) -> float:
    """The share of the force ``x`` (one column) that the span of ``Y`` explains after ``[1, N]``: the R^2 of the
    least-squares fit of ``x`` on ``[1, N, Y]`` beyond ``[1, N]`` (0 to 1; 0 when nothing of ``x`` is left)."""
    xp = off_nuisance(np.asarray(x, float).reshape(-1, 1), N)[:, 0]
    nx = float(xp @ xp)
    Q = _orth(off_nuisance(Y, N))
    if not nx > 0 or not Q.shape[1]:
        return 0.0
    c = Q.T @ xp
    return float(min(c @ c / nx, 1.0))


#: the signals of the session clock (:data:`l1b2.predictor.effects.SIGNALS` and the channel family's)
SESSION_SIGNALS = frozenset({"t", "col:time_s", "run:time_s"})


def time_dependent(candidate: CandidateForce) -> bool:
    """Whether a candidate's force depends on the session clock (its spec reads ``t``, the ``time_s`` channel or
    an event clock ``<column>_since_s``, the session's time since a logged step; a candidate without a spec:
    ``time`` among its regressors). A family that reads the clock only to place each run in a block whose level the
    runs within it carry (``run_folds``: :class:`l1b2.predictor.effects.blocks.SessionBlocks`) does not: it is
    cross-validated over runs."""
    if candidate.spec:
        try:
            if fx.family(candidate.spec.get("kind")).run_folds:
                return False
            signals = fx.needs(candidate.spec)
            return bool(signals & SESSION_SIGNALS) or any(c.endswith(EVENT_SUFFIX) for c in columns_read(signals))
        except fx.EffectSpecError:
            pass
    return "time" in candidate.regressors


def columns_read(signals) -> list:
    """The logged columns among a spec's signals (:func:`l1b2.predictor.effects.needs`): ``X`` of every ``col:X``
    (along the stroke) and ``run:X`` (its run value)."""
    return [s.partition(":")[2] for s in signals if s.startswith(("col:", "run:"))]


def session_curve(candidate: CandidateForce) -> bool:
    """Whether a candidate that does not depend on the session clock (:func:`time_dependent`) reads a setting's
    low-pass over the last runs, ``<column>_lag<n>r`` (:mod:`l1b2.closeloop.lags`): a smooth curve of the session,
    whose refit accepted over run folds must pass over the session's blocks too (:func:`block_checked`)."""
    if not candidate.spec or time_dependent(candidate):
        return False
    try:
        return any(LAG_SUFFIX_RE.search(c) for c in columns_read(fx.needs(candidate.spec)))
    except fx.EffectSpecError:
        return False


def block_checked(trials: list, rules, refit_on_blocks) -> list:
    """The round's refit trials with each one that reads a lag (:func:`session_curve`) and is accepted over run
    folds checked over the session's blocks: when its refit there fails :func:`accepts`, that trial replaces it
    (so it is refused and recorded as refused on the blocks); otherwise it stays as it was.

    ``rules(t)``: the keywords of :func:`accepts` for a trial; ``refit_on_blocks(indices)``: the trials
    (:class:`RefitCV`) of those shortlist entries refitted on the session's blocks, against the current model on
    the same blocks. A lag's form can follow a slow drift of the session between a held-out run's fitted
    neighbours, which shuffled run folds reward and a held-out stretch of the session does not."""
    which = [i for i, t in enumerate(trials)
             if t is not None and session_curve(t.candidate) and accepts(t, **rules(t))]
    out = list(trials)
    for i, t in zip(which, refit_on_blocks(which) if which else []):
        if t is not None and not accepts(t, **rules(t)):
            out[i] = t
    return out


@dataclass(frozen=True)
class RefitSettings:
    """How every refit of the loop is identified, in one object.

    ``order``: polynomial order of A, B, P; ``seed``; ``max_nfev``: function
    evaluations of one warm refit; ``noise``: the identifier's noise
    variances (``"common"`` or ``"per_run"``); ``client``: where the folds
    run (a Dask client, None: in this process; not part of a task);
    ``frequency``: the drive-frequency response every refit holds fixed (the
    baseline's, :mod:`l1b2.ident.frequency`; ``"off"``: none).
    """

    order: int = 8
    seed: int = 0
    max_nfev: int = DEFAULT_REFIT_NFEV
    noise: str = "common"
    frequency: Any = "off"
    client: Any = field(default=None, compare=False, repr=False)

    def budget(self, max_nfev: int) -> RefitSettings:
        """The same settings with another evaluation budget."""
        return replace(self, max_nfev=int(max_nfev))

    def task(self) -> RefitSettings:
        """The settings a task carries (without the client)."""
        return replace(self, client=None)


def validated(df) -> dataio.Measurements:
    """A frame of the loop's data as :class:`~l1b2.data.measurements.Measurements`: not validated again.

    Every frame the loop hands to the identification is TRAIN or TEST as
    loaded (validated once, by ``load_measurements``), a subset of their runs,
    or their speed replaced by the position's derivative
    (:func:`l1b2.closeloop.chain.with_position_speed`); the identification
    validates a plain DataFrame on every call, a Measurements never.
    """
    return df if isinstance(df, dataio.Measurements) else dataio.Measurements(df, {}, None)


class Validated:
    """A fitted identifier whose predictions take the loop's frames as validated data (:func:`validated`)."""

    def __init__(self, est: PredictorIdentifier):
        self.est = est

    def predict_free_run(self, df) -> np.ndarray:
        return self.est.predict_free_run(validated(df))

    def predict_one_step(self, df) -> np.ndarray:
        return self.est.predict_one_step(validated(df))

    def __getattr__(self, name):
        if name == "est":
            raise AttributeError(name)
        return getattr(self.est, name)


def refit(df: pd.DataFrame, mask: np.ndarray, m_s: float, init, effects: EffectSet, settings: RefitSettings, *,
          max_outer: int = 2, n_starts: int = 1) -> Validated:
    """The model with ``effects``, re-identified on ``df`` by one warm local search (bounded budget).

    The search is the least-squares alternation (``noise_fit="alternate"``) whatever the baseline's;
    ``n_starts >= 2`` adds the identifier's data-driven multistart track to the warm one (the better is kept).
    """
    extra = effects.extra()
    est = PredictorIdentifier(order=settings.order, criterion="free_run", fixed="recommended", n_starts=n_starts,
                              model=getattr(init, "drive_law", "eq29"),   # the refit keeps the baseline's family
                              seed=settings.seed, extra=extra, init=init,
                              init_extra=effects.start() if extra is not None else None, max_nfev=settings.max_nfev,
                              max_outer=max_outer, noise=settings.noise, noise_fit="alternate",
                              frequency=settings.frequency)
    return Validated(est.fit(validated(df), slider_mass_kg=m_s, mask=mask))


@dataclass
class FoldErrors:
    """Held-out free-run sums of squares per fold (on the evaluation mask) and the measured speed's.

    The folds may come from ``repeats`` splits of the runs (:func:`repeated_folds`: every run held out exactly
    ``repeats`` times; ``sse`` has one entry per fold of every split). ``run_sse``: each held-out run's sum of
    squares, averaged over the ``repeats`` times it was held out (run id -> SSE; every run with at least one
    sample on the evaluation mask; with one split each run is in exactly one fold, so they add up to ``sse``'s
    folds, and with ``repeats`` splits they add up to ``sum(sse) / repeats``; empty when not kept). A fold that
    failed gives its runs ``inf``.
    """

    sse: np.ndarray
    ss_meas: np.ndarray
    failed: int = 0
    nfev: int = 0        #: function evaluations of the folds' refits (all folds)
    run_sse: dict = field(default_factory=dict)
    repeats: int = 1     #: splits the folds come from (each run held out this many times)

    @property
    def nrmse(self) -> float:
        return float(np.sqrt(self.sse.sum() / max(self.ss_meas.sum(), 1e-300)))


def pooled_gain(sse_current, sse_new) -> float:
    """The cross-validated gain: the share of the current model's pooled held-out sum of squares that the new model
    removes, ``1 - sum(sse_new) / sum(sse_current)`` (sums over folds or runs; 0 when the current sum is not
    positive). The one formula of the refit's gain (:attr:`RefitCV.gain`) and the linearised score's
    (:class:`l1b2.closeloop.selection.FoldSolver`)."""
    s0 = float(np.sum(sse_current))
    return float(1.0 - float(np.sum(sse_new)) / s0) if s0 > 0 else 0.0


@dataclass
class RefitCV:
    """Outcome of one candidate's cross-validated refit against the current model on the same folds."""

    candidate: CandidateForce
    current: FoldErrors
    extended: FoldErrors
    linear_gain: float = 0.0
    phi: np.ndarray = field(default=None, repr=False)
    #: why the round refit it (:data:`l1b2.closeloop.selection.ORIGINS`), the report's ``offered_by``
    origin: str = "screen"

    @property
    def gain(self) -> float:
        """Relative fall of the pooled held-out free-run sum of squares (:func:`pooled_gain`)."""
        return pooled_gain(self.current.sse, self.extended.sse)

    @property
    def folds_improved(self) -> int:
        return int(np.sum(self.extended.sse < self.current.sse))

    def to_dict(self) -> dict:
        c = self.candidate
        ev = run_evidence(self)
        return {"effect": c.family, "label": c.label, "regressors": list(c.regressors),
                "cv_free_run_nrmse_current": self.current.nrmse, "cv_free_run_nrmse_refit": self.extended.nrmse,
                "cv_gain": self.gain, "folds_improved": self.folds_improved, "folds": len(self.current.sse),
                "repeats": self.current.repeats,
                "cv_gain_se_runs": None if ev is None else ev[1],
                "runs_improved": None if ev is None else ev[2], "runs": None if ev is None else ev[3],
                "linearised_gain": self.linear_gain, "offered_by": self.origin}


def run_evidence(r: RefitCV) -> tuple[float, float, int, int] | None:
    """``(gain, se, improved, n)``: the trial's pooled CV gain paired per held-out run against the current model.

    Every TRAIN run is held out in one fold of each split, its SSE averaged over the splits
    (:attr:`FoldErrors.run_sse`). Per run ``r`` of ``n``,
    ``delta_r = (SSE_current_r - SSE_refit_r) / mean_r SSE_current_r``: ``gain = mean(delta)`` is
    :attr:`RefitCV.gain` exactly and ``se = sd(delta) / sqrt(n)`` its standard error over the runs
    (:func:`paired_gap`); ``improved`` counts the runs whose held-out SSE fell. None when the two models' runs
    differ, a run is missing, or a run's SSE is not finite. A record: :func:`accepts` does not read it.
    """
    cur, ext = r.current.run_sse, r.extended.run_sse
    if not cur or set(cur) != set(ext):
        return None
    runs = list(cur)
    c, e = np.array([cur[k] for k in runs], float), np.array([ext[k] for k in runs], float)
    pg = paired_gap(c, e, c)
    if pg is None:
        return None
    return pg[0], pg[1], int(np.sum(e < c)), len(runs)


def accepts(r: RefitCV, *, min_gain: float = DEFAULT_MIN_CV_GAIN, min_drop: float = DEFAULT_MIN_CV_DROP) -> bool:
    """At least ``min_gain`` relative fall of the held-out free-run SS, in more than half of the folds, and a
    fall of the pooled held-out free-run nrmse by at least ``min_drop`` (absolute).

    With folds from ``R`` splits (:func:`repeated_folds`) the gain and the nrmse are pooled over all ``R * k``
    held-out folds (each run counted ``R`` times) and the majority is over the ``R * k`` folds."""
    return 2 * r.folds_improved > len(r.current.sse) and _other_rules(r, min_gain, min_drop)


def tied(r: RefitCV, *, min_gain: float = DEFAULT_MIN_CV_GAIN, min_drop: float = DEFAULT_MIN_CV_DROP) -> bool:
    """Whether ``r`` meets every rule of :func:`accepts` but the fold majority, with exactly half of its folds
    improved: a vote that does not decide (two of four folds), which more splits of the same runs can."""
    return 2 * r.folds_improved == len(r.current.sse) and _other_rules(r, min_gain, min_drop)


def _other_rules(r: RefitCV, min_gain: float, min_drop: float) -> bool:
    """The acceptance rules beside the fold vote (:func:`accepts`, :func:`tied`): no fold failed, the pooled gain at
    least ``min_gain`` and the pooled held-out nrmse lower by at least ``min_drop``."""
    return r.extended.failed == 0 and r.gain >= min_gain and r.current.nrmse - r.extended.nrmse >= min_drop


def immaterial(trials: list, effects: EffectSet, min_gain: float = DEFAULT_MIN_CV_GAIN) -> list:
    """Trials of the last round (``trials``: the rounds' :class:`RefitCV` lists) that pass every acceptance rule
    but the materiality threshold, largest CV gain first; none when the last round added its pick (its other
    trials were against an earlier model; ``effects``: the added ones).

    They were cross-validated against the final model (its residual) and improve it in most folds by at least
    ``min_gain``: significant evidence of a regressor, too small to add (``min_cv_drop``, which only structural
    terms must meet, so these are structural).
    """
    if not trials or not trials[-1] or len(trials) <= len(effects.candidates):
        return []
    added = effects.families
    last = [t for t in trials[-1]
            if t.candidate.family not in added and accepts(t, min_gain=min_gain, min_drop=-np.inf)]
    return sorted(last, key=lambda t: -t.gain)


def materiality(candidate: CandidateForce, min_drop: float) -> float:
    """The smallest fall of the CV free-run nrmse that ``candidate`` must bring: ``min_drop`` if it is structural.

    Structural terms relax Eq. 29's own linearisation; clean data carry them too, so only a material fall
    adds one. Any other candidate needs only the relative rule of :func:`accepts` (returns 0).
    """
    return min_drop if candidate.structural else 0.0


def paired_gap(sse_a, sse_b, sse_current, repeats: int = 1) -> tuple[float, float] | None:
    """``(gap, se)`` of two models' held-out sums of squares paired by unit (fold or run), against the current
    model's on the same units: per unit ``i``, ``delta_i = (a_i - b_i) / mean(current)``; ``gap = mean(delta)``,
    which is exactly ``pooled_gain(current, b) - pooled_gain(current, a)``, and ``se = sd(delta) / sqrt(n /
    repeats)`` (sample standard deviation, ``n`` units; 0 with one unit). ``repeats``: the units are the folds
    of that many splits of the same runs (:func:`repeated_folds`), which hold no more independent units than one
    split's ``n / repeats`` folds. None when a ``delta`` is not finite or there is no unit."""
    a, b, c = (np.asarray(x, float) for x in (sse_a, sse_b, sse_current))
    n = len(c)
    if not n:
        return None
    delta = (a - b) / max(float(np.mean(c)), 1e-300)
    if not np.all(np.isfinite(delta)):
        return None
    return float(np.mean(delta)), (float(np.std(delta, ddof=1) / np.sqrt(n / repeats)) if n > 1 else 0.0)


def one_se_gap(named: RefitCV, generic: RefitCV) -> tuple[float, float] | None:
    """``(gap, se)``: how far the generic trial's pooled CV gain is above the named one's, and the standard error of
    that gap over the folds; None when the two were not cross-validated against the same current model's errors
    on the same folds.

    Per fold ``f``, ``delta_f = (SSE_named_f - SSE_generic_f) / mean_f SSE_current_f``: their mean is the gap of
    the pooled gains exactly, and ``se = sd(delta) / sqrt(k)`` (0 with one fold; :func:`paired_gap`); with the
    folds of ``R`` splits, ``sd`` over all ``R * k`` folds and ``k`` the folds of one split.
    """
    cur, other = named.current, generic.current
    if cur is not other and not (np.array_equal(cur.sse, other.sse) and np.array_equal(cur.ss_meas, other.ss_meas)):
        return None
    return paired_gap(named.extended.sse, generic.extended.sse, cur.sse, repeats=cur.repeats)


def one_se_gap_per_run(trial: RefitCV, best: RefitCV) -> tuple[float, float] | None:
    """``(gap, se)``: how far ``best``'s pooled CV gain is above ``trial``'s, with the standard error of that gap
    over the held-out *runs* (paired per run); None when the two were not cross-validated against the same
    current model's per-run errors (the same folds) or a per-run error is missing or not finite.

    Every run is held out in exactly one fold of each of the ``R`` splits, and its SSE is the mean over them
    (:attr:`FoldErrors.run_sse`). Per run ``r`` (``n`` runs),
    ``delta_r = (SSE_trial_r - SSE_best_r) / mean_r SSE_current_r``: their mean is
    ``(sum SSE_trial - sum SSE_best) / sum SSE_current``, the gap of the pooled gains exactly (the same gap as
    :func:`one_se_gap`'s over folds), and ``se = sd(delta) / sqrt(n)`` (:func:`paired_gap`): with ``n`` runs
    instead of ``k`` folds the standard error has ``n - 1`` degrees of freedom instead of ``k - 1``.
    """
    cur = trial.current.run_sse
    if not cur or (trial.current is not best.current and best.current.run_sse != cur):
        return None
    runs = list(cur)
    a, b = trial.extended.run_sse, best.extended.run_sse
    if any(r not in a or r not in b for r in runs):
        return None
    return paired_gap([a[r] for r in runs], [b[r] for r in runs], [cur[r] for r in runs])


def named_reading(pick: RefitCV, accepted: list, share, min_share: float = NAMED_SHARE) -> RefitCV:
    """The named physical form instead of a generic pick when the evidence does not clearly favour the generic one.

    When ``pick`` is generic, an accepted named trial replaces it if (a) the named family's span explains at least
    ``min_share`` of the generic term's fitted force (``share(named, generic)``, :func:`explained_share` after the
    nuisance: they model the same thing) and (b) the generic term's CV gain exceeds the named one's by no more
    than one standard error of that gap over the folds (:func:`one_se_gap`; the one-standard-error rule of
    cross-validated model choice: the simpler model unless the richer one is better beyond the selection's own
    noise). Among several such named trials, the largest CV gain, then the fewest parameters. Otherwise ``pick``.
    """
    if not pick.candidate.generic:
        return pick
    found = within_one_se(pick, [t for t in accepted if not t.candidate.generic], one_se_gap, share, min_share)
    return pick if found is None else found[0]


def within_one_se(pick: RefitCV, trials: list, gap_of, share, min_share: float) -> tuple | None:
    """``(trial, (gap, se), share)`` of the trial that replaces ``pick`` under the one-standard-error rule of
    :func:`named_reading` and :func:`input_reading`, None when none does: of ``trials``, those whose gap to the pick
    (``gap_of(trial, pick)``, :func:`one_se_gap` or :func:`one_se_gap_per_run`) is within its standard error and
    whose span explains at least ``min_share`` of the pick's force (``share(trial, pick)``); of several, the largest
    CV gain, then the fewest parameters."""
    best = None
    for t in trials:
        gap = gap_of(t, pick)
        if gap is None or gap[0] > gap[1]:
            continue
        s = share(t, pick)
        if s < min_share:
            continue
        if best is None or (t.gain, -t.candidate.n_params) > (best[0].gain, -best[0].candidate.n_params):
            best = (t, gap, float(s))
    return best


#: the regressors the predictor reads from its own inputs (``Predictor.fmu``: V0, load, direction, temperature,
#: drive frequency) and from its own motion (position, speed, acceleration): what a host always gives it. Every
#: other regressor (a logged auxiliary channel, a history the loop derives, the session clock) is not an input.
INPUT_REGRESSORS = ("position", "direction", "load", "voltage", "speed", "acceleration", "temperature", "frequency")


def reads_auxiliary(candidate) -> bool:
    """Whether a candidate reads a logged channel or a derived history beyond the predictor's inputs: one of its
    regressors is neither in :data:`INPUT_REGRESSORS` nor the session clock ``time``."""
    return any(r not in INPUT_REGRESSORS and r != "time" for r in candidate.regressors)


def input_reading(pick: RefitCV, accepted: list, share, min_share: float = NAMED_SHARE,
                  log: list | None = None, round_no: int | None = None) -> RefitCV:
    """The model's own inputs instead of an auxiliary channel that stands in for them.

    When ``pick`` reads an auxiliary channel (:func:`reads_auxiliary`), an accepted trial that reads only the
    predictor's inputs (:data:`INPUT_REGRESSORS`) replaces it if (a) its span explains at least ``min_share`` of the
    pick's fitted force (``share(trial, pick)``, :func:`explained_share` after the nuisance) and (b) the pick's CV
    gain exceeds the trial's by no more than one standard error of that gap, paired per held-out run
    (:func:`one_se_gap_per_run`; None, when the two were not cross-validated on the same folds, keeps the pick).
    The one-standard-error rule of :func:`named_reading`, with the inputs as the simpler model: a channel is read as
    a cause only when it explains the runs beyond what the inputs it follows explain, and a predictor that needs it
    needs a channel its host may not have. Among several such trials, the largest CV gain, then the fewest
    parameters. ``log`` (a list) gets ``{"round", "pick", "taken", "gap", "se", "share"}`` when the pick is
    replaced (``round``: ``round_no``).
    """
    if not reads_auxiliary(pick.candidate):
        return pick
    inputs = [t for t in accepted if all(r in INPUT_REGRESSORS for r in t.candidate.regressors)]
    found = within_one_se(pick, inputs, one_se_gap_per_run, share, min_share)
    if found is None:
        return pick
    best, (gap, se), s = found
    if log is not None:
        log.append({"round": round_no, "pick": pick.candidate.label, "taken": best.candidate.label, "gap": gap,
                    "se": se, "share": s})
    return best


class Directions:
    """The candidates' forces on the masked samples with the current model's nuisance directions projected off.

    ``nuisance``: forces spanning the current model's own re-identification (n x q on every row of ``df``,
    :func:`l1b2.closeloop.selection.nuisance_forces`); an intercept is added. One object per round; each
    candidate's columns are computed once.
    """

    def __init__(self, df: pd.DataFrame, mask: np.ndarray, nuisance: np.ndarray):
        self.df, self.m = df, np.asarray(mask, bool)
        self.U = _orth(np.column_stack([np.ones(int(self.m.sum())), np.asarray(nuisance, float)[self.m]]))
        self._cols: dict = {}

    def columns(self, c: CandidateForce) -> np.ndarray:
        """``c``'s feature columns on the masked samples, off the nuisance (zeros when a feature is not finite)."""
        key = (c.family, c.label)
        if key not in self._cols:
            X = np.asarray(c.features(self.df), float).reshape(len(self.df), -1)[self.m]
            self._cols[key] = _project_off(X, self.U) if np.all(np.isfinite(X)) else np.zeros_like(X)
        return self._cols[key]

    def shared_r2(self, a: CandidateForce, b: CandidateForce) -> float:
        """:func:`max_canonical_r2` of two candidates after the nuisance."""
        return max_canonical_r2(self.columns(a), self.columns(b))

    def share(self, named: CandidateForce, generic: CandidateForce, phi) -> float:
        """:func:`explained_share` of the generic candidate's force with parameters ``phi`` by the named one's span."""
        return explained_share(self.columns(generic) @ np.asarray(phi, float).ravel(), self.columns(named))

    def of_trials(self, explaining: RefitCV, explained: RefitCV) -> float:
        """:meth:`share` of two refit trials: ``explained``'s force (its fitted ``phi``) by ``explaining``'s span."""
        return self.share(explaining.candidate, explained.candidate, explained.phi)

    def conflicts(self, c: CandidateForce, effects: EffectSet, r2: float = SHARED_R2) -> bool:
        """Whether ``c`` shares a direction (:data:`SHARED_R2`) with an added effect of the other kind (a named effect
        with a generic term or the reverse): such a pair is never in one model, whichever came first."""
        return any(e.generic != c.generic and self.shared_r2(c, e) >= r2 for e in effects.candidates)


def fold_error(df: pd.DataFrame, mask: np.ndarray, m_s: float, held_runs, init, effects: EffectSet,
               settings: RefitSettings, chain_k: int | None = None) -> tuple[float, float, bool]:
    """One fold: refit on the runs not in ``held_runs``, predict those in free run.

    With ``chain_k`` the model is the measurement chain's
    (:class:`l1b2.closeloop.loop.ChainModel`): on the training runs the speed
    channel's output stage (:func:`l1b2.closeloop.chain.speed_channel`, with
    ``chain_k`` folds: its filter or clip when its test accepts it there, else
    the identity, as the chain's rule keeps no stage that its test rejects) and
    the physics refitted on the position's derivative; the held-out runs'
    measured speed is predicted by that stage applied to the physics' free run.

    The refit sees the training runs at one sample per millisecond at most (:func:`fold_fit_data`); the
    held-out runs are predicted at their own rate.

    Returns ``(sse, ss_meas, failed, nfev, run_sse)`` on the held-out evaluation mask (a
    failed fit or a diverged prediction: ``sse = inf``; ``nfev``: the refit's evaluations; ``run_sse``: the same
    sum of squares per held-out run with a sample on the mask, ``inf`` for each when ``sse`` is). A pure function
    of its arguments: the unit of work of :func:`cv_errors` and :func:`chain_cv_errors`.
    """
    split = held_out_split(df, mask, held_runs)
    train, test = split.train, split.test
    filt = None
    if chain_k is not None:
        ch = chain.speed_channel(train, split.mask_train, k=chain_k, seed=settings.seed)
        if ch.get("filter") is None:
            return split.failed()
        filt = ch["filter"] if ch["accepted"] else chain.OutputFilter()
        train, test_in = chain.with_position_speed(train), chain.with_position_speed(test)
    else:
        test_in = test
    try:
        est = refit(*fold_fit_data(train, split.mask_train), m_s, init, effects, settings)
        pred = est.predict_free_run(test_in)
    except IdentificationError:
        return split.failed()
    return split.score(pred if filt is None else filt.apply(test, pred), est.convergence_.get("nfev_total", 0))


def fold_fit_data(train: pd.DataFrame, mask: np.ndarray) -> tuple[pd.DataFrame, np.ndarray]:
    """The samples a fold's refit is fitted on: the training runs decimated to one sample per millisecond at most
    (:func:`l1b2.ident.coarse.decimate`; unchanged at 1 kHz or slower) and their mask.

    The fold refits only compare the current model with a candidate on held-out runs, both refitted the same
    way; on a fast DAQ the extra samples of each millisecond cost evaluations without moving that comparison.
    """
    return decimate(train, mask, decimation(train))


def chain_cv_errors(df: pd.DataFrame, mask: np.ndarray, m_s: float, folds, init_base, init_chain,
                    settings: RefitSettings, *, k: int = 5) -> tuple[FoldErrors, FoldErrors]:
    """:class:`FoldErrors` of the baseline (refitted on the measured speed from ``init_base``) and of the
    measurement-chain model (:func:`fold_error` with ``chain_k=k``, from ``init_chain``) on the same
    ``folds``; every fold of both is one task of :func:`l1b2.cluster.run_tasks`."""
    args = [(df, mask, m_s, fold, init, EffectSet(), settings.task(), chain_k)
            for init, chain_k in ((init_base, None), (init_chain, k)) for fold in folds]
    return tuple(_fold_errors(args, 2, len(folds), settings.client, "l1b2-chain-cv"))


def _fold_errors(args: list, n_groups: int, n_folds: int, client, name: str, repeats: int = 1) -> list[FoldErrors]:
    """Run :func:`fold_error` on every argument tuple (tasks of :func:`l1b2.cluster.run_tasks`); one
    :class:`FoldErrors` per group of ``n_folds`` consecutive tuples, ``n_groups`` of them (their folds from
    ``repeats`` splits)."""
    out = [None] * len(args)
    for i, r in run_tasks(fold_error, args, client=client, name=name):
        out[i] = r
    groups = [out[j * n_folds:(j + 1) * n_folds] for j in range(n_groups)]
    return [FoldErrors(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]), sum(bool(r[2]) for r in rows),
                       sum(int(r[3]) for r in rows), mean_per_run([r[4] for r in rows]), repeats)
            for rows in groups]


def mean_per_run(fold_run_sse: list) -> dict:
    """Each run's mean held-out SSE over the folds that held it out (``fold_run_sse``: one ``{run: SSE}`` per
    fold); a run held out once keeps its SSE exactly."""
    acc: dict = {}
    for d in fold_run_sse:
        for k, x in d.items():
            acc.setdefault(k, []).append(float(x))
    return {k: (v[0] if len(v) == 1 else sum(v) / len(v)) for k, v in acc.items()}


def cv_errors(df: pd.DataFrame, mask: np.ndarray, m_s: float, folds, init, jobs,
              settings: RefitSettings) -> list[FoldErrors]:
    """:class:`FoldErrors` of every job ``(effects, fold_phi)`` on the same ``folds``, all folds as tasks.

    ``folds`` may be the folds of several splits (:func:`repeated_folds`); every run must be held out the same
    number of times (:func:`held_out_times`, ValueError otherwise), which is the errors' ``repeats``.

    ``fold_phi`` (or None): per fold, the start of the last effect's parameters
    (:func:`fold_start_phi`). The ``len(jobs) * len(folds)`` refits are
    independent tasks of :func:`l1b2.cluster.run_tasks`: in this process in
    order with ``settings.client=None``, else spread over the Dask cluster's workers;
    the result does not depend on where they ran.
    """
    args = []
    for effects, fold_phi in jobs:
        for i, fold in enumerate(folds):
            eff = effects if fold_phi is None else effects.with_phi(
                np.concatenate([effects.start()[:-len(fold_phi[i])], fold_phi[i]]))
            args.append((df, mask, m_s, fold, init, eff, settings.task()))
    return _fold_errors(args, len(jobs), len(folds), settings.client, "l1b2-cv-refit", held_out_times(folds))


def fold_start_phi(S: np.ndarray, A: np.ndarray, y: np.ndarray, runs_m: np.ndarray, folds) -> list[np.ndarray] | None:
    """Per fold, the candidate's linearised parameters fitted on the training folds only (no held-out leak); None
    when a response is not finite (the refits then start from the effect's own start)."""
    X = np.column_stack([A, S])
    if not np.isfinite(X).all():
        return None
    return [np.linalg.lstsq(X[tr], y[tr], rcond=None)[0][A.shape[1]:] for tr in (~np.isin(runs_m, f) for f in folds)]
