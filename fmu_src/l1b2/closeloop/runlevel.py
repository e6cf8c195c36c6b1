"""Run-level evidence: each run's own deviation from the current model, shrunk as random effects, and the
run-level signals that explain it.

Many rig effects change between runs, not along the stroke (a supply that differs from run to run, a contact
that re-seats, a clamp that settles). They show in each run's *own* deviation from the model, which this module
estimates and explains:

1. **Per-run deviations** (:func:`run_deviations`): the model's one-step residual in drive coordinates, as a
   force, ``f_k = d (v_k - v^_k) m_eff / dt`` [N] (``v^_k`` predicted from the measured sample before), is fitted
   per run by least squares on ``[B'(s) V0 / <B' V0>, 1]``: a gain of the model's drive force (a share of it)
   and an offset [N]. Their sampling covariance is the least-squares one with the residual variance inflated
   for lag-1 autocorrelation (``(1 + rho) / (1 - rho)``).
2. **Shrinkage** (:func:`~l1b2.closeloop.reml.reml`): the runs' ``theta_r`` (gain, offset) are a random-effects model
   ``theta_r = X_r beta + u_r + e_r``, ``u_r ~ N(0, T)`` between runs, ``e_r ~ N(0, S_r)`` the sampling error;
   ``T`` (2 x 2) is estimated by restricted maximum likelihood (:mod:`l1b2.closeloop.reml`: the restricted
   log-likelihood maximised over a Cholesky factor of ``T``) and each run's deviation is its
   best linear unbiased prediction ``X_r beta + T W_r (theta_r - X_r beta)``, ``W_r = (T + S_r)^-1``.
3. **Explanation** (:func:`signal_evidence`): each run-level signal ``z`` (standardised) enters the mean
   (:func:`l1b2.closeloop.runstats.signal_design`): the gain as ``g0 + g1 z_r``, the offset as ``o0 + o1 z_r +
   o2 z_r w_r`` with ``w_r = d m / max|m|`` the run's drive-coordinate load (a signal that changes the contact
   changes the load's slope as well as the drive); its evidence is the Wald test of ``(g1, o1, o2)``
   (chi-square, 3 degrees of freedom; 2 without load variation) and the cross-validated share of the runs'
   weighted held-out deviation it removes (folds over runs: contiguous blocks of the session for the session clock,
   :func:`l1b2.closeloop.folds.session_blocks`).
   A signal is significant when its p-value is below ``alpha`` / the effective number of signals tested
   (Bonferroni over :func:`effective_signal_count`: value signals that follow each other count as fewer tests) and
   its cross-validated gain is positive. Of two significant signals whose run values correlate, the one with the
   weaker evidence given the other is *dominated* and ranks after every undominated one
   (:func:`dominated_signals`: a logged channel that only follows the cause). The loop offers the strongest
   significant one (:func:`offer`) as a
   :class:`~l1b2.predictor.effects.channels.RunLevel` candidate to the same cross-validated refit acceptance as
   every other candidate.

Signals (:func:`run_signals`): each candidate channel's run mean (the logged columns, the session clock
``time_s``, which also orders the runs), V0, the drive-coordinate load ``d m``, its size and the direction, and each
logged column's run mean, centred on its mean over the runs ``c0``, times the run's direction, ``d (c - c0)``
(``d*<column>``): a condition that speeds one direction and slows the other (a coupling asymmetry set by a
gradient, a tilt, a field) leaves the run's gain following ``d (c - c0)``, which neither ``c`` nor ``d`` alone
carries, as ``d m`` is the load's (centred, the product holds no copy of the direction's own signal); and that
centred run mean's square less its line over the runs (``<column>^2``): a condition whose effect has an extremum
inside the runs' range (an optimum, a resonance, a least friction at one setting) leaves the runs' gain following
that curvature, which the channel's linear value misses. When none of them has Wald evidence (no p-value below the
Bonferroni level, whatever its cross-validated gain), a cut of
the session into contiguous blocks (:func:`block_signal`, :mod:`l1b2.closeloop.blocks`: its p-value corrected for
the search) is tested as one more signal and offered as a :class:`~l1b2.predictor.effects.blocks.SessionBlocks`
candidate. With ``cycle`` (the loop's ``session_cycle`` option) a cycle of the session clock
(:mod:`l1b2.closeloop.cycle`, its p-value corrected for the periods searched) is tested in every analysis, beside
the signals, at the blocks' level, and offered as a :class:`~l1b2.predictor.effects.cycle.SessionCycle`
candidate. A signal with evidence that its folds do not confirm (the session clock's trend over held-out blocks of
the session) is not replaced by blocks, whose level is cross-validated over interleaved runs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats

from ..data import measurements as dataio
from ..predictor import effects as fx
from ..predictor import model as pr
from ..units import history_source
from . import blocks as blk, cycle as cyc, residuals as res
from .auxiliary import derived_columns
from .reml import REMLFit, reml
from .runstats import cv_signal_gain, joint_test, signal_design, signal_index

#: the columns a reduced run-level form leaves out, in the order :func:`offer` tries them: the drive gain and the
#: load term (whose products with a signal of V0 or of the load are what two run-level forms share), then the offset
REDUCED = ("gain", "load", "offset")
#: run-value correlation above which two significant signals are compared by their evidence given each other
DOMINANCE_CORR = 0.5


@dataclass
class RunDeviations:
    """Each run's least-squares deviation from the model: ``theta`` (n_runs, 2) = (gain [1], offset [N]),
    ``cov`` (n_runs, 2, 2) its sampling covariance, ``runs`` the run ids, ``n`` the samples used per run,
    ``load`` each run's drive-coordinate load ``d m / max|m|`` (None: no load varies)."""

    runs: np.ndarray
    theta: np.ndarray
    cov: np.ndarray
    n: np.ndarray
    load: np.ndarray | None = None


def one_step_force(df: pd.DataFrame, model, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(f, gain_regressor, used)``: the one-step residual as a force [N] (drive coordinates), the model's drive
    force relative to its TRAIN mean, and the samples used (masked, not a run's first)."""
    p = model.params_
    d = df[dataio.DIRECTION].to_numpy(float)
    v = df[dataio.SPEED].to_numpy(float)
    t = df[dataio.TIME].to_numpy(float)
    load = df[dataio.LOAD].to_numpy(float)
    e = d * (v - np.asarray(model.predict_one_step(df), float))
    dt = np.zeros(len(df))
    dt[1:] = np.diff(t)
    first = np.zeros(len(df), bool)
    for _, sl in dataio.run_slices(df[dataio.RUN]):
        first[sl.start] = True
    used = np.asarray(mask, bool) & ~first & (dt > 0)
    m_eff = np.broadcast_to(pr.effective_mass(p, load, model.m_s_), (len(df),))
    f = np.zeros(len(df))
    f[used] = e[used] * m_eff[used] / dt[used]
    s_prev = np.roll(df[dataio.POSITION].to_numpy(float), 1)
    _, Bp, _ = pr.position_terms(p, s_prev)
    drive = np.asarray(Bp, float) * df[dataio.VOLTAGE].to_numpy(float)
    scale = float(np.mean(np.abs(drive[used]))) if used.any() else 1.0
    return f, drive / (scale if scale > 0 else 1.0), used


def run_deviations(df: pd.DataFrame, model, mask: np.ndarray) -> RunDeviations:
    """Per-run least squares of the one-step force on (relative drive force, 1): see the module's step 1."""
    f, g, used = one_step_force(df, model, mask)
    runs, th, cv, ns, w = [], [], [], [], []
    dm = df[dataio.DIRECTION].to_numpy(float) * df[dataio.LOAD].to_numpy(float)
    for run, sl in dataio.run_slices(df[dataio.RUN]):
        u = used[sl]
        if u.sum() < 8:
            continue
        X = np.column_stack([g[sl][u], np.ones(int(u.sum()))])
        y = f[sl][u]
        XtX = X.T @ X
        if np.linalg.cond(XtX) > 1e12:
            continue
        beta = np.linalg.solve(XtX, X.T @ y)
        r = y - X @ beta
        rho = float(np.clip(res.acf(r, 1)[1], 0.0, 0.98)) if len(r) > 2 else 0.0
        s2 = float(r @ r) / max(len(r) - 2, 1) * (1 + rho) / (1 - rho)
        runs.append(run)
        th.append(beta)
        cv.append(s2 * np.linalg.inv(XtX))
        ns.append(int(u.sum()))
        w.append(float(np.mean(dm[sl])))
    w = np.array(w, float)
    scale = float(np.max(np.abs(w))) if len(w) else 0.0
    return RunDeviations(np.array(runs), np.array(th, float).reshape(-1, 2), np.array(cv, float).reshape(-1, 2, 2),
                         np.array(ns), w / scale if scale > 0 else None)


def heterogeneity(theta: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    """Cochran's Q of the runs' deviations about their precision-weighted mean and its chi-square p-value
    (``p (n - 1)`` degrees of freedom): small p, the runs differ by more than their sampling error."""
    W = np.linalg.inv(cov)
    mu = np.linalg.solve(W.sum(axis=0), np.einsum("rpq,rq->p", W, theta))
    r = theta - mu
    q = float(np.einsum("rp,rpq,rq->", r, W, r))
    dof = theta.shape[1] * (len(theta) - 1)
    return q, float(stats.chi2.sf(q, dof)) if dof > 0 else 1.0


@dataclass
class SignalEvidence:
    """One run-level signal's evidence: Wald p-value of its coefficients, cross-validated gain, the coefficients
    (gain [1 per sd], offset [N per sd], offset per unit drive-coordinate load [N per sd]) and whether it passed
    (Bonferroni level and a positive gain)."""

    channel: str
    transform: str
    label: str
    regressor: str
    mean: float
    sd: float
    p_value: float = 1.0
    cv_gain: float = 0.0
    coef: tuple = (0.0, 0.0, 0.0)
    significant: bool = False
    blocked_folds: bool = False
    per_run: np.ndarray = field(default=None, repr=False)
    #: TRAIN's largest deviation of a sample's value from its run's (0: constant within every run; None: unknown)
    run_spread: float | None = None
    #: the label of a correlated significant signal whose evidence given this one is stronger than this one's
    #: given it (:func:`dominated_signals`); None: not dominated
    dominated_by: str | None = None
    #: a categorical signal's TRAIN levels and the runs' shares of all but the last (None: a value signal); its
    #: ``coef`` is then ``(gain, offset, load)`` per level but the last, against the runs' average, flat; a cycle's
    #: ``shares`` are its waves' means over the runs
    levels: tuple | None = None
    shares: tuple | None = None
    #: the joint test's degrees of freedom
    dof: int = 0
    #: a segmentation's edges [s] between its blocks of the session (:mod:`l1b2.closeloop.blocks`; ``shares`` its
    #: blocks' shares of the runs but the last, ``coef`` as a category's, ``p_value`` times its search count);
    #: None: no segmentation
    edges: tuple | None = None
    #: a cycle's period [s] (:mod:`l1b2.closeloop.cycle`: ``coef`` its cosine's and sine's gains, ``p_value`` times
    #: its search count); None: no cycle
    period_s: float | None = None
    #: the value a logged channel's ``drive`` or ``square`` signal is centred on, a ``square`` one's line taken off
    centre: float = 0.0
    slope: float = 0.0

    def to_dict(self) -> dict:
        out = {"signal": self.label, "regressor": self.regressor, "p_value": self.p_value, "cv_gain": self.cv_gain,
               "gain_per_sd": self.coef[0], "offset_per_sd_N": self.coef[1],
               "load_offset_per_sd_N": self.coef[2], "significant": self.significant,
               "folds": "session blocks" if self.blocked_folds else "runs", "dominated_by": self.dominated_by,
               "dof": self.dof}
        if self.edges is not None:
            out.update(gain_per_sd=None, offset_per_sd_N=None, load_offset_per_sd_N=None,
                       edges_s=list(self.edges), blocks=len(self.edges) + 1)
        if self.period_s is not None:
            out.update(gain_per_sd=None, offset_per_sd_N=None, load_offset_per_sd_N=None, period_s=self.period_s,
                       cos_gain=self.coef[0], sin_gain=self.coef[1])
        if self.levels is not None:
            q = len(self.levels) - 1
            c = list(self.coef) + [0.0] * (3 * q - len(self.coef))
            out.update(gain_per_sd=None, offset_per_sd_N=None, load_offset_per_sd_N=None,
                       levels=list(self.levels),
                       per_level={str(v): {"gain": c[j], "offset_N": c[q + j], "load_offset_N": c[2 * q + j]}
                                  for j, v in enumerate(self.levels[:-1])})
        return out


def run_signals(df: pd.DataFrame, channels) -> list[dict]:
    """The run-level signals of a frame: each candidate channel's run mean (not a kind of
    :data:`~l1b2.predictor.effects.channels.NO_RUN_LEVEL_KINDS`, not one read along the stroke or following the
    runs' lengths, not constant ones); for a logged channel that the loop did not derive
    (:func:`l1b2.closeloop.auxiliary.derived_columns`), or the run setting a reading carries
    (:mod:`l1b2.closeloop.runsetting`: a setting read through a response or a column read along the stroke), its
    run mean less its mean over the runs (``centre``) times the run's direction too (transform ``drive``,
    ``d*<column>``), when the runs go both ways, and its curvature (transform ``square``, ``<column>^2``:
    :func:`_squared`); the categorical signals; and the inputs of
    :data:`~l1b2.predictor.effects.channels.INPUT_SIGNALS`; ``{"channel", "transform", "values",
    "run_spread"}`` with one value per run (in run order) and the largest deviation of a sample's value from its run's
    (:func:`l1b2.predictor.effects.channels.run_spread`: what the export checks)."""
    out = []
    first = df.groupby(dataio.RUN, sort=False)
    for ch in channels:
        if (ch.get("kind") in fx.channels.NO_RUN_LEVEL_KINDS or "run" not in fx.channels.levels_of(ch)
                or ch["name"] not in df.columns):
            continue   # a label's codes have no order: its categorical signal below only; the run clock's run mean
            # is half the run's duration, a response of the speed, and so is an accumulating reading's
        out.append({"channel": ch["name"], "transform": "none", "values": first[ch["name"]].mean().to_numpy(float),
                    "run_spread": fx.channels.run_spread(df[ch["name"]], df[dataio.RUN])})
    d = first[dataio.DIRECTION].first().to_numpy(float)
    derived, kinds = set(derived_columns(df, settings=False)), {ch["name"]: ch.get("kind") for ch in channels}
    logged = [sg for sg in out if sg["channel"] not in derived and kinds.get(sg["channel"]) == "logged"]
    if np.ptp(d) > 0:    # runs both ways (else d*c only copies c)
        out += [_times_direction(sg, d) for sg in logged]
    out += [_squared(sg) for sg in logged]
    out += category_signals(df, channels)
    for col, tr in fx.channels.INPUT_SIGNALS:
        values = fx.channels.transformed(first[col].mean().to_numpy(float), d, tr)
        samples = fx.channels.transformed(df[col].to_numpy(float), df[dataio.DIRECTION].to_numpy(float), tr)
        out.append({"channel": col, "transform": tr, "values": values,
                    "run_spread": fx.channels.run_spread(samples, df[dataio.RUN])})
    return [s for s in out if np.all(np.isfinite(s["values"])) and np.std(s["values"]) > 0]


def _times_direction(sg: dict, d: np.ndarray) -> dict:
    """A value signal's ``drive`` copy: its run values less their mean (``centre``), times the runs' direction."""
    c0 = float(np.mean(sg["values"]))
    return {**sg, "transform": "drive", "centre": c0, "values": (sg["values"] - c0) * d}


def _squared(sg: dict) -> dict:
    """A value signal's ``square`` copy: ``u^2 - slope u``, ``u`` its run values less their mean (``centre``), less
    the square's least-squares line in ``u`` (``slope = mean(u^3)/mean(u^2)``): the curvature alone."""
    u = sg["values"] - float(np.mean(sg["values"]))
    slope = float(np.mean(u ** 3) / np.mean(u * u)) if np.ptp(u) > 0 else 0.0
    return {**sg, "transform": "square", "centre": float(np.mean(sg["values"])), "slope": slope,
            "values": u * u - slope * u}


def _category() -> fx.Effect:
    """The categorical run-level family (:class:`l1b2.predictor.effects.category.RunLevelCategory`)."""
    return fx.family("run_level_category")


def _is_category(sg) -> bool:
    return sg.get("transform") == fx.category.CATEGORY


def _blocks() -> fx.Effect:
    """The session's blocks (:class:`l1b2.predictor.effects.blocks.SessionBlocks`)."""
    return fx.family("session_blocks")


def _is_blocks(sg) -> bool:
    return sg.get("transform") == fx.blocks.BLOCKS


def _cycle() -> fx.Effect:
    """The session's cycle (:class:`l1b2.predictor.effects.cycle.SessionCycle`)."""
    return fx.family("session_cycle")


def _is_cycle(sg) -> bool:
    return sg.get("transform") == fx.cycle.CYCLE


@dataclass(frozen=True)
class _Searched:
    """How the evidence reads a run-level signal that is no channel's value (a category's levels, a segmentation of
    the session, a cycle of its clock): its ``columns`` in the mean (mean 0, sd 1), its ``label`` and ``regressor``,
    and ``gain_only`` (its family acts on the drive force's gain alone: the Wald test and the held-out gain read the
    gain's row only)."""

    columns: Callable[[dict], np.ndarray]
    label: Callable[[dict], str]
    regressor: Callable[[dict], str]
    gain_only: bool = False


#: the signals that are no channel's value, by their ``transform``; a value signal is read by
#: :func:`signal_columns`'s standardisation and :func:`l1b2.predictor.effects.channels.signal_label`
SEARCHED = {
    fx.category.CATEGORY: _Searched(lambda sg: _category().columns(sg), lambda sg: _category().label(sg["channel"]),
                                    lambda sg: fx.channels.regressor_of(sg["channel"])),
    fx.blocks.BLOCKS: _Searched(lambda sg: fx.blocks.index_columns(sg["values"], sg["shares"]),
                                lambda sg: _blocks().label(len(sg["edges"]) + 1), lambda sg: _blocks().regressor,
                                gain_only=True),
    fx.cycle.CYCLE: _Searched(lambda sg: np.asarray(sg["columns"], float), lambda sg: _cycle().label(sg["period_s"]),
                              lambda sg: _cycle().regressor, gain_only=True),
}


def block_signal(dev: RunDeviations, t_run_s: np.ndarray, T: np.ndarray, *, level: float, k: int,
                 seed: int) -> dict | None:
    """The segmentation of the session into contiguous blocks (:func:`l1b2.closeloop.blocks.segmentations`) as a
    signal (``{"channel": "time_s", "transform": "blocks", "values", "edges", "shares", "search_count"}``), or None
    when the search finds none. ``t_run_s``: each run's mean session time, in ``dev.runs``' order; ``T``: the
    runs' REML between-run covariance without blocks.

    The number of blocks is chosen by the folds: of the segmentations whose p-value times their search count is
    below ``level``, the fewest blocks whose cross-validated gain (:func:`cv_signal_gain` over the runs' load sizes,
    :func:`l1b2.closeloop.blocks.load_size_folds`, else the ``k`` run folds of ``seed``) is at least
    :data:`~l1b2.closeloop.blocks.PARSIMONY` of the largest; when none is below ``level``, the smallest corrected
    p-value (the record of what was searched; ties: the fewer blocks). The signal carries its folds (``folds``):
    :func:`signal_evidence` scores it on them; ``p_value`` is its corrected p-value. A segmentation's Wald test and
    gain read one level per block on the gain (``gain_only`` of :func:`joint_test`, :func:`cv_signal_gain`), the
    family's own form."""
    segs = blk.segmentations(dev.theta, dev.cov, T, t_run_s)
    if not segs:
        return None
    cols = [fx.blocks.index_columns(sg["values"], sg["shares"]) for sg in segs]
    p = [min(1.0, joint_test(dev, z, True)[1] * sg["search_count"]) for z, sg in zip(cols, segs)]
    passed = [i for i in range(len(segs)) if p[i] < level]
    folds = blk.load_size_folds(dev.load) or [np.flatnonzero(np.isin(dev.runs, f))
                                              for f in res.run_folds(dev.runs, k, seed)]
    if passed:
        memo: dict = {}
        gain = {i: cv_signal_gain(dev.theta, dev.cov, cols[i], folds, dev.load, memo, True)[0] for i in passed}
        best = max(gain.values())
        pick = min(i for i in passed if gain[i] >= (blk.PARSIMONY * best if best > 0 else best))
    else:
        pick = min(range(len(segs)), key=lambda i: (p[i], i))
    return {"channel": fx.channels.SESSION_TIME, "transform": fx.blocks.BLOCKS, **segs[pick], "folds": folds,
            "p_value": p[pick]}


def category_signals(df: pd.DataFrame, channels) -> list[dict]:
    """The categorical signals of a frame: each channel the categorical family takes
    (:meth:`~l1b2.predictor.effects.category.RunLevelCategory.takes`) whose values per run are a category
    (:meth:`~l1b2.predictor.effects.category.RunLevelCategory.signal`), with its ``run_spread``. None in most
    data: nothing then costs anything."""
    out = []
    fam = _category()
    runs = df.groupby(dataio.RUN, sort=False)
    for ch in channels:
        col = ch["name"]
        if col not in df.columns or not fam.takes(ch):
            continue
        sg = fam.signal(col, runs[col].first().to_numpy(float))
        if sg is not None:
            out.append({**sg, "run_spread": fx.channels.run_spread(df[col], df[dataio.RUN])})
    return out


def signal_columns(sg: dict) -> tuple[np.ndarray, float, float]:
    """A signal's columns in the run-level mean and its mean and sd: ``z = (v - mean) / sd`` (n,) of a value
    signal, the categorical family's columns (n, L - 1) of a categorical one (mean 0, sd 1)."""
    searched = SEARCHED.get(sg.get("transform"))
    if searched is not None:
        return searched.columns(sg), 0.0, 1.0
    v = np.asarray(sg["values"], float)
    mean, sd = float(np.mean(v)), float(np.std(v))
    return (v - mean) / sd, mean, sd


def effective_tests(Z: np.ndarray) -> float:
    """Galwey's effective number of tests among the columns of ``Z`` (n, m): ``(sum_i sqrt(l_i))^2 / sum_i l_i``
    over the eigenvalues ``l_i`` of the columns' correlation matrix (negative ones, round-off, as 0). ``m`` for
    uncorrelated columns, 1 for columns that are one column scaled; 0 for no column. A constant column counts as
    one test of its own."""
    Z = np.asarray(Z, float).reshape(len(Z), -1)
    m = Z.shape[1]
    if m <= 1:
        return float(m)
    sd = Z.std(axis=0)
    flat = ~(sd > 0)
    Zs = (Z[:, ~flat] - Z[:, ~flat].mean(axis=0)) / sd[~flat]
    lam = np.clip(np.linalg.eigvalsh(Zs.T @ Zs / len(Zs)), 0.0, None) if Zs.shape[1] else np.zeros(0)
    return float(flat.sum()) + (float(np.sqrt(lam).sum() ** 2 / lam.sum()) if lam.sum() > 0 else 0.0)


def effective_signal_count(signals_) -> float:
    """How many tests the run-level signals ``signals_`` (:func:`run_signals`' dicts) count as, at least 1: the
    value signals' :func:`effective_tests` over their run values (a channel's lags, its logarithm and the inputs it
    follows are not as many independent tests as signals), plus one per categorical signal or segmentation."""
    values = [np.asarray(sg["values"], float) for sg in signals_ if sg.get("transform") not in SEARCHED]
    other = len(signals_) - len(values)
    return max(1.0, other + (effective_tests(np.column_stack(values)) if values else 0.0))


def signal_evidence(dev: RunDeviations, signals_, *, alpha: float, k: int, seed: int,
                    session_order: np.ndarray | None = None, tests: float | None = None) -> list[SignalEvidence]:
    """Every signal's evidence (:class:`SignalEvidence`), strongest first: undominated before dominated
    (:func:`dominated_signals`), then the smallest p-value.

    ``signals_`` as :func:`run_signals` (values in ``dev.runs``' order); ``session_order``: each run's start
    time (its rank orders the contiguous session blocks of the session clock's folds); ``tests``: the number of
    tests ``alpha`` is divided by (None: :func:`effective_signal_count` of ``signals_``).
    """
    n = len(dev.runs)
    out = []
    if n < 6:
        return out
    level = alpha / (effective_signal_count(signals_) if tests is None else tests)
    rand = [np.flatnonzero(np.isin(dev.runs, f)) for f in res.run_folds(dev.runs, k, seed)]
    order = np.argsort(session_order) if session_order is not None else np.arange(n)
    blocks = [np.sort(b) for b in np.array_split(order, min(k, n))]
    zs = []
    null_fits: dict = {}     # the null model's fold fits, shared by every signal (same deviations, same folds)
    for sg in signals_:
        z, mean, sd = signal_columns(sg)
        searched = SEARCHED.get(sg.get("transform"))
        gain_only = searched is not None and searched.gain_only   # a segmentation or a cycle: on the gain
        cat, seg, cy = _is_category(sg), _is_blocks(sg), _is_cycle(sg)
        b, p, dof = joint_test(dev, z, gain_only)
        p = min(1.0, p * sg.get("search_count", 1))   # a segmentation's or a cycle's search (modules blocks, cycle)
        blocked = sg["channel"] == fx.channels.SESSION_TIME and not seg   # a block's level: from runs within it
        folds = sg.get("folds") or (blocks if blocked else rand)   # a segmentation's own (block_signal)
        gain, per_run = cv_signal_gain(dev.theta, dev.cov, z, folds, dev.load, null_fits, gain_only)
        label = (searched.label(sg) if searched is not None
                 else fx.channels.signal_label(sg["channel"], sg["transform"]))
        reg = searched.regressor(sg) if searched is not None else fx.channels.regressor_of(sg["channel"])
        out.append(SignalEvidence(sg["channel"], sg["transform"], label, reg,
                                  mean, sd, p, gain, tuple(float(x) for x in b) + (0.0,) * (3 - len(b)),
                                  bool(p < level and gain > 0),
                                  blocked, per_run, sg.get("run_spread"),
                                  levels=tuple(sg["levels"]) if cat else None,
                                  shares=tuple(sg["shares"]) if cat or seg or cy else None, dof=dof,
                                  period_s=float(sg["period_s"]) if cy else None,
                                  edges=tuple(sg["edges"]) if seg else None, centre=float(sg.get("centre", 0.0)),
                                  slope=float(sg.get("slope", 0.0))))
        zs.append(z)
    plan = {col for col, _ in fx.channels.INPUT_SIGNALS}
    dominated = dominated_signals(dev, [e.significant for e in out], zs, level,
                                  plan=[sg["channel"] in plan for sg in signals_],
                                  sources=history_sources([sg["channel"] for sg in signals_]))
    for e, dom in zip(out, dominated):
        e.dominated_by = out[dom].label if dom is not None else None
    return sorted(out, key=rank)


def rank(e: SignalEvidence) -> tuple:
    """The order of signals' evidence: undominated before dominated, then the smallest p-value, the larger gain."""
    return e.dominated_by is not None, e.p_value, -e.cv_gain


def _beyond(z: np.ndarray, given: np.ndarray) -> np.ndarray:
    """The part of ``z``'s columns that ``given``'s (and a constant) do not span: ``z`` itself when together they
    have full rank, else an orthonormal basis of its residual on them (no column: ``z`` is nested in ``given``)."""
    Z = np.asarray(z, float).reshape(len(z), -1)
    G = np.column_stack([np.ones(len(Z)), np.asarray(given, float).reshape(len(Z), -1)])
    if np.linalg.matrix_rank(np.column_stack([G, Z])) == G.shape[1] + Z.shape[1]:
        return z
    R = Z - G @ np.linalg.lstsq(G, Z, rcond=None)[0]
    u, sv, _ = np.linalg.svd(R, full_matrices=False)
    return u[:, sv > 1e-9 * max(float(np.linalg.norm(Z)), 1e-300)] * np.sqrt(len(Z))


def conditional_p(dev: RunDeviations, z: np.ndarray, given: np.ndarray, rest: np.ndarray | None = None) -> float:
    """Wald p-value of the signal ``z``'s coefficients (``g1, o1[, o2]`` of :func:`signal_design`, per column) in
    the mean that also holds the signal ``given``'s: its evidence beyond what ``given`` explains. Of a ``z`` whose
    columns ``given``'s span in part, only the rest is tested (:func:`_beyond`); nested in ``given``: 1.
    ``rest``: ``_beyond(z, given)`` when the caller has it (None: computed here)."""
    z = _beyond(z, given) if rest is None else rest
    Z = np.asarray(z, float).reshape(len(z), -1)
    G = np.asarray(given, float).reshape(len(Z), -1)
    if Z.shape[1] == 0:
        return 1.0
    load = dev.load is not None
    idx, gidx = signal_index(Z.shape[1], load), signal_index(G.shape[1], load)
    X = np.concatenate([signal_design(z, dev.load), signal_design(given, dev.load)[:, :, gidx]], axis=2)
    try:
        fit = reml(dev.theta, dev.cov, X)
        b, C = fit.beta[idx], fit.beta_cov[np.ix_(idx, idx)]
        return float(stats.chi2.sf(float(b @ np.linalg.solve(C, b)), len(idx)))
    except np.linalg.LinAlgError:
        return 1.0


def run_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """How closely two signals' run values follow each other: ``|r|`` of two value signals, the largest canonical
    correlation when one has several columns (a category: 1 for the linear value of the same channel)."""
    A, B = (np.asarray(x, float).reshape(len(x), -1) for x in (a, b))
    if A.shape[1] == 1 and B.shape[1] == 1:
        return abs(float(np.corrcoef(A[:, 0], B[:, 0])[0, 1]))
    qa, qb = (np.linalg.qr(M - M.mean(axis=0))[0] for M in (A, B))
    return float(np.linalg.svd(qa.T @ qb, compute_uv=False).max())


def history_sources(channels) -> list:
    """Per signal's channel, the index of the first signal of the column it is a setting history of
    (:func:`l1b2.units.history_source`: ``X`` of ``X_lag<n>r`` or ``X_step``), None when it is none or ``X`` has no
    signal."""
    first: dict = {}
    for i, ch in enumerate(channels):
        first.setdefault(ch, i)
    return [first.get(history_source(str(ch))) for ch in channels]


def dominated_signals(dev: RunDeviations, significant, zs, level: float = 0.0, plan=None, sources=None) -> list:
    """Per signal, the index of a significant signal that dominates it, else None.

    Two significant signals whose run values correlate (:func:`run_correlation` ``>=`` :data:`DOMINANCE_CORR`: a
    logged channel and another that follows it, such as two temperatures of one rig) both explain the runs'
    deviations on their own; the one whose evidence given the other (:func:`conditional_p`) is the weaker is
    dominated and is offered after every undominated one. When one is nested in the other (a channel's value in
    its category's indicators), the larger dominates only if its evidence beyond the smaller is below ``level``;
    else the smaller does. Two that are nested in each other carry the same run values (a logged read-back of the
    drive amplitude, a load logged in newtons): a signal of the plan's own inputs (``plan[i]`` true: the columns
    of :data:`~l1b2.predictor.effects.channels.INPUT_SIGNALS`, which the operator set and ``Predictor.fmu`` takes
    as inputs) dominates one that is not; otherwise the first listed does. The rest keep the order of their own
    evidence.

    ``sources[i]``: the index of the signal whose setting history signal ``i`` is (:func:`history_sources`), or
    None. A history's own evidence is its memory, what it adds beyond its source's present value: when one of the
    two is a history of a significant third signal, both conditional p-values also hold that source's signal.
    """
    out = [None] * len(zs)
    sig = [i for i, s in enumerate(significant) if s]
    held = _held_sources(sources, significant, len(zs))
    for a in sig:
        for b in sig:
            if b <= a or run_correlation(zs[a], zs[b]) < DOMINANCE_CORR:
                continue
            rest = {(i, j): _beyond(zs[i], zs[j]) for i, j in ((a, b), (b, a))}
            also = [zs[c] for c in sorted((held[a] | held[b]) - {a, b})]
            if also:
                ga, gb = (np.column_stack([np.asarray(z, float).reshape(len(z), -1) for z in (zs[j], *also)])
                          for j in (b, a))
                pa, pb = conditional_p(dev, zs[a], ga), conditional_p(dev, zs[b], gb)
            else:
                pa, pb = conditional_p(dev, zs[a], zs[b], rest[a, b]), conditional_p(dev, zs[b], zs[a], rest[b, a])
            nested = [i for i, j in ((a, b), (b, a)) if rest[i, j].reshape(len(zs[i]), -1).shape[1] == 0]
            if len(nested) == 2 and plan is not None and plan[a] != plan[b]:
                (loser, winner) = (b, a) if plan[a] else (a, b)
            elif nested:
                small = nested[0]
                big = b if small == a else a
                (loser, winner) = (small, big) if min(pa, pb) < level else (big, small)
            else:
                loser, winner = (a, b) if pa > pb else (b, a)
            if out[loser] is None:
                out[loser] = winner
    return out


def _held_sources(sources, significant, n: int) -> list[set]:
    """Per signal, the set of significant signals it is a setting history of (empty without ``sources``)."""
    if sources is None:
        return [set() for _ in range(n)]
    return [{c} if c is not None and c != i and significant[c] else set() for i, c in enumerate(sources)]


@dataclass
class RunLevelAnalysis:
    """The run-level analysis against one model: the deviations, their REML fit, heterogeneity, signal evidence."""

    deviations: RunDeviations
    fit: REMLFit | None
    q: float
    q_p: float
    evidence: list
    level: float

    @property
    def significant(self) -> list:
        return [e for e in self.evidence if e.significant]

    def to_dict(self) -> dict:
        """The report's ``diagnosis.run_level`` summary (the per-signal evidence is in ``channels_considered``)."""
        T = self.fit.T if self.fit is not None else np.full((2, 2), np.nan)
        return {"runs": int(len(self.deviations.runs)),
                "between_run_sd_gain": float(np.sqrt(max(T[0, 0], 0.0))),
                "between_run_sd_offset_N": float(np.sqrt(max(T[1, 1], 0.0))),
                "mean_gain": float(self.fit.beta[0]) if self.fit is not None else None,
                "mean_offset_N": float(self.fit.beta[1]) if self.fit is not None else None,
                "heterogeneity_Q": self.q if np.isfinite(self.q) else None, "heterogeneity_p": self.q_p,
                "significance_level": self.level,
                "significant_signals": [e.label for e in self.significant],
                "dominated_signals": {e.label: e.dominated_by for e in self.significant if e.dominated_by}}

    def signal_p(self, c) -> float | None:
        """The uncorrected p-value of the signal a run-level candidate ``c`` reads (the ``run_level`` or categorical
        family: its spec's channel and transform); 1.0 when that signal was not tested; None when ``c`` is not such a
        candidate (its evidence is then the screen's)."""
        spec = c.spec or {}
        if spec.get("kind") not in ("run_level", _category().kind):
            return None
        key = (spec.get("channel"), spec.get("transform", "none"))
        return next((e.p_value for e in self.evidence if e.edges is None and (e.channel, e.transform) == key), 1.0)

    def round_record(self, round_: int | None) -> dict:
        """One entry of ``diagnosis.run_level_rounds``: this analysis against the model entering round ``round_``
        (None: the final model, after a last round that added an effect), the summary of :meth:`to_dict` and every
        signal's evidence (``signal``, ``p_value``, ``cv_gain``, ``significant``, ``dominated_by``), the smallest
        p-value first."""
        rows = sorted(self.evidence, key=lambda e: e.p_value)
        return {"round": round_, **self.to_dict(),
                "signals": [{"signal": e.label, "p_value": float(e.p_value), "cv_gain": float(e.cv_gain),
                             "significant": bool(e.significant), "dominated_by": e.dominated_by} for e in rows]}


def analyse(df: pd.DataFrame, model, mask: np.ndarray, channels, *, alpha: float, k: int,
            seed: int, cycle: bool = False) -> RunLevelAnalysis:
    """Deviations of every run from ``model``, their REML shrinkage and every run-level signal's evidence
    (``cycle``: a cycle of the session clock searched too, :mod:`l1b2.closeloop.cycle`)."""
    dev = run_deviations(df, model, mask)
    sigs = run_signals(df, channels)
    keep = pd.Index(pd.unique(df[dataio.RUN])).get_indexer(dev.runs)
    sigs = [_kept(s, keep) for s in sigs]
    sigs = [s for s in sigs if s is not None]
    times = df.groupby(dataio.RUN, sort=False)[dataio.TIME]
    start, middle = times.min().to_numpy(float)[keep], times.mean().to_numpy(float)[keep]
    if len(dev.runs) < 6:
        return RunLevelAnalysis(dev, None, float("nan"), 1.0, [], alpha / effective_signal_count(sigs))
    q, qp = heterogeneity(dev.theta, dev.cov)
    fit = reml(dev.theta, dev.cov)
    m = effective_signal_count(sigs)
    evidence = signal_evidence(dev, sigs, alpha=alpha, k=k, seed=seed, session_order=start, tests=m)
    signals_level, level = alpha / m, alpha / (m + 1)
    if searches_blocks(evidence, signals_level):   # blocks of the session: the evidence of last resort
        seg = block_signal(dev, middle, fit.T, level=level, k=k, seed=seed)
        if seg is not None:
            evidence += signal_evidence(dev, [seg], alpha=level, k=k, seed=seed, session_order=start)
    found = cyc.cycle_signal(dev, middle, cyc.plan_columns(*_run_plan(df)[keep].T)) if cycle else None   # beside
    if found is not None:
        evidence = sorted(evidence + signal_evidence(dev, [found], alpha=level, k=k, seed=seed, session_order=start),
                          key=rank)
    return RunLevelAnalysis(dev, fit, q, qp, evidence, signals_level)


def _run_plan(df: pd.DataFrame) -> np.ndarray:
    """Each run's V0, direction and load (columns), in the runs' order of appearance."""
    return df.groupby(dataio.RUN, sort=False)[[dataio.VOLTAGE, dataio.DIRECTION, dataio.LOAD]].first().to_numpy(float)


def searches_blocks(evidence, level: float) -> bool:
    """Whether the session's blocks are searched (module docstring): no signal of ``evidence`` has a p-value below
    ``level``, the signals' Bonferroni level, whether or not its folds confirm it."""
    return not any(e.p_value < level for e in evidence)


def _kept(sg: dict, keep: np.ndarray) -> dict | None:
    """A signal on the runs the deviations kept; a category's levels and shares taken again on them (None: no
    longer a category)."""
    return _category().on_runs(sg, keep) if _is_category(sg) else {**sg, "values": sg["values"][keep]}


def candidates(analysis: RunLevelAnalysis, ctx) -> list:
    """The :class:`~l1b2.closeloop.candidates.CandidateForce` of every significant signal, strongest first, then
    the reduced forms of its value signals (each without one column: :data:`REDUCED`), strongest first: a reduced
    form is offered (:func:`offer`) only when no full form of its regressor is allowed, as when the full form
    shares a column with an added effect."""
    from .candidates import candidate
    full, reduced = [], []
    for e in analysis.significant:
        if e.edges is not None:
            full += [candidate(ctx, h) for h in _blocks().hypotheses([{"edges": e.edges, "shares": e.shares}])]
            continue
        if e.period_s is not None:
            full += [candidate(ctx, h) for h in _cycle().hypotheses([{"period_s": e.period_s, "means": e.shares}])]
            continue
        fam = fx.family("run_level") if e.levels is None else _category()
        sg = offered_signal(e)
        full += [candidate(ctx, h) for h in fam.hypotheses([sg])]
        if e.levels is None:
            reduced += [candidate(ctx, h) for h in fam.hypotheses([{**sg, "drop": d} for d in REDUCED])]
    return full + reduced


def offered_signal(e: SignalEvidence) -> dict:
    """The signal a value or categorical signal's evidence ``e`` offers to its family's ``hypotheses``: its channel,
    transform, mean and sd, with its ``run_spread``, ``centre``, ``slope`` and a category's ``levels`` and ``shares``
    when it has them."""
    return {"channel": e.channel, "transform": e.transform, "mean": e.mean, "sd": e.sd,
            **({} if e.run_spread is None else {"run_spread": float(e.run_spread)}),
            **({"centre": e.centre} if e.centre else {}), **({"slope": e.slope} if e.slope else {}),
            **({} if e.levels is None else {"levels": e.levels, "shares": e.shares})}


def is_run_level(c) -> bool:
    """Whether a candidate is constant along the stroke by construction (a run-level family or a channel's run mean)."""
    spec = c.spec or {}
    return (spec.get("kind") in ("run_level", _category().kind, _blocks().kind, _cycle().kind)
            or (spec.get("kind") == "channel" and spec.get("level") == "run"))


def is_last_resort(c) -> bool:
    """Whether a candidate is the session's blocks (:class:`~l1b2.predictor.effects.blocks.SessionBlocks`): enough
    blocks follow any misfit of the runs, so among the accepted candidates within the parsimony band it is added only
    when no other is (:func:`l1b2.closeloop.loop.prefer`)."""
    return (c.spec or {}).get("kind") == _blocks().kind


def offer(found: list, short: list, allowed) -> list:
    """The run-level candidates offered to a round's cross-validated refit (at most two, strongest first).

    ``found``: :func:`candidates` (strongest first); ``short``: the round's shortlisted scores; ``allowed(c)``:
    not added yet and not collinear with what is. The strongest allowed one whose family is not shortlisted, and
    the strongest allowed one of another regressor that no shortlisted candidate reads (``found`` lists the
    reduced forms after every full form: a reduced one is taken only when no full form of its regressor is
    allowed, as when the full form's span holds a column of an added effect, such as the V0 x load product that
    run-level forms of V0 and of the load share): when the runs' deviations
    follow signals of two regressors, the refit over the run folds, not the ranking of their p-values, decides
    which of them explains the runs (a signal that follows the other's cause by chance can have the smaller
    p-value).
    """
    fams = {s.candidate.family for s in short}
    regs = {r for s in short for r in s.candidate.regressors}
    first = next((c for c in found if c.family not in fams and allowed(c)), None)   # allowed last: a fit per call
    if first is None:
        return []
    second = next((c for c in found if c.family not in fams and c.regressor not in regs | {first.regressor}
                   and allowed(c)), None)
    return [first] + ([second] if second is not None else [])
