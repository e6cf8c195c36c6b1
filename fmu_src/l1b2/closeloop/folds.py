"""The folds of the close loop's cross-validation: which runs each refit holds out.

* over runs, stratified by direction and voltage (:func:`stratified_folds`), or over whole conditions
  (:func:`condition_folds`), chosen by unit (:data:`UNIT_FOLDS`, :func:`unit_folds`), repeated with fresh
  seeds (:func:`repeated_folds`);
* over the session clock, for candidates that depend on time: contiguous blocks of the session
  (:func:`session_blocks`) or whole conditions in rotation (:func:`session_rotation`), by scheme
  (:data:`CLOCK_FOLDS`, :func:`clock_folds`);
* both schemes at once for a round (:func:`refit_schemes`, :func:`screen_folds`);
* one fold's split of TRAIN and the score of its held-out prediction (:func:`held_out_split`, :class:`HeldOut`).

Pure functions of TRAIN's run table; the refits that use them live in :mod:`l1b2.closeloop.acceptance`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from . import residuals as res

def stratified_folds(df: pd.DataFrame, k: int, seed=0) -> list[np.ndarray]:
    """Run ids in ``k`` folds: seeded shuffle, then dealt in turn within each (direction, voltage) stratum.

    ``seed``: an int or a sequence of ints (the shuffle's :func:`numpy.random.default_rng` seed)."""
    first = df.groupby(dataio.RUN, sort=False)[[dataio.DIRECTION, dataio.VOLTAGE]].first()
    runs = first.index.to_numpy()
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(runs))
    keys = first.iloc[order]
    ranked = keys.assign(_o=np.arange(len(order))).sort_values([dataio.DIRECTION, dataio.VOLTAGE, "_o"],
                                                               kind="stable")
    ids = ranked.index.to_numpy()
    k = min(k, len(ids))
    return [ids[i::k] for i in range(k)]


def condition_units(df: pd.DataFrame) -> list[np.ndarray]:
    """Run ids grouped by condition: the runs that share a drive amplitude and a load (``voltage_V``, ``load_kg`` of
    a run's first sample; the rig's plan runs each such condition forward, then backward), wherever they lie in the
    session. Units in the order their first run appears in ``df``, runs in that order too; a frame without those
    columns has one unit per run. Every run is in exactly one unit."""
    cols = [c for c in (dataio.VOLTAGE, dataio.LOAD) if c in df.columns]
    first = df.groupby(dataio.RUN, sort=False)[cols].first()
    runs = first.index.to_numpy()
    code = (first.groupby(cols, sort=False, dropna=False).ngroup().to_numpy() if cols and len(runs)
            else np.arange(len(runs)))
    return [runs[code == u] for u in range(int(code.max()) + 1 if len(code) else 0)]


def condition_folds(df: pd.DataFrame, k: int, seed=0) -> list[np.ndarray]:
    """Run ids in ``k`` folds of whole conditions (:func:`condition_units`): the conditions shuffled (seeded), ordered
    stably by stratum (the mean ``direction`` of a condition's runs, then its ``voltage_V``) and dealt in turn,
    condition ``j`` of that order to fold ``j mod k``.

    A condition's runs share their inputs, so a held-out run's partner is never in the fitted part (grouped
    cross-validation; the TEST split holds out whole conditions too). Every run is held out exactly once; in
    every stratum the folds' numbers of conditions differ by at most one; a condition of a forward and a backward
    run has mean direction 0, so the strata are then the voltages and each fold holds both directions equally.
    With one run per condition this is :func:`stratified_folds`. ``seed``: an int or a sequence of ints.
    """
    units = condition_units(df)
    first = df.groupby(dataio.RUN, sort=False)[[dataio.DIRECTION, dataio.VOLTAGE]].first()
    keys = pd.DataFrame([[first.loc[u, dataio.DIRECTION].astype(float).mean(), first.loc[u[0], dataio.VOLTAGE]]
                         for u in units], columns=["d", "v"])
    order = np.random.default_rng(seed).permutation(len(units))
    ranked = order[keys.iloc[order].assign(_o=np.arange(len(order))).sort_values(["d", "v", "_o"],
                                                                                 kind="stable")["_o"].to_numpy()]
    k = min(k, len(units))
    return [np.concatenate([units[u] for u in ranked[i::k]]) for i in range(k)]


#: the fold schemes of a candidate that does not depend on the session clock (``CloseLoop(fold_unit=...)``)
UNIT_FOLDS = {"run": stratified_folds, "condition": condition_folds}


def unit_folds(df: pd.DataFrame, k: int, seed=0, unit: str = "run") -> list[np.ndarray]:
    """The ``k`` folds of a candidate that does not depend on the session clock by ``unit`` (a key of
    :data:`UNIT_FOLDS`): runs (:func:`stratified_folds`) or whole conditions (:func:`condition_folds`)."""
    if unit not in UNIT_FOLDS:
        raise ValueError(f"fold_unit must be one of {sorted(UNIT_FOLDS)}, got {unit!r}")
    return UNIT_FOLDS[unit](df, k, seed)


def repeated_folds(df: pd.DataFrame, k: int, repeats: int = 1, seed: int = 0, unit: str = "run",
                   first=None) -> list[np.ndarray]:
    """``repeats`` splits of the runs by :func:`unit_folds`, ``k`` folds each, in turn (``repeats * k`` folds).

    Split 0 is ``unit_folds(df, k, seed, unit)`` (``first``: that split, already computed; None: computed here);
    split ``j >= 1`` is shuffled by the stream ``[seed, j]``: the whole list is a function of ``seed``, and
    ``repeats=1`` gives :func:`unit_folds` itself. Every run is in exactly one fold of each split, so it is held out
    exactly ``repeats`` times (:func:`held_out_times`).
    """
    split0 = list(unit_folds(df, k, seed, unit) if first is None else first)
    return split0 + [f for j in range(1, max(int(repeats), 1)) for f in unit_folds(df, k, [seed, j], unit)]


def held_out_times(folds) -> int:
    """How many times every run is held out over ``folds`` (the number of splits they come from).

    Raises ValueError when there is no run or when the runs are not all held out the same number of times.
    """
    ids = np.concatenate([np.asarray(f).ravel() for f in folds]) if len(folds) else np.zeros(0)
    _, counts = np.unique(ids, return_counts=True)
    if not len(counts) or np.any(counts != counts[0]):
        raise ValueError("every run must be held out the same number of times over the folds")
    return int(counts[0])


def session_blocks(df: pd.DataFrame, k: int) -> list[np.ndarray]:
    """Run ids in ``k`` contiguous blocks of the session: runs ordered by their first time, split in order.

    The folds of a candidate that depends on the session clock (:func:`time_dependent`): a held-out block is a
    stretch of the session the fit has not seen, so a term that only interpolates a drift between neighbouring
    runs gains nothing. Block sizes differ by at most one run; every run is in exactly one block.
    """
    start = df.groupby(dataio.RUN, sort=False)[dataio.TIME].min()
    ids = start.index.to_numpy()[np.argsort(start.to_numpy(float), kind="stable")]
    return [b for b in np.array_split(ids, min(k, len(ids))) if len(b)]


def session_units(df: pd.DataFrame) -> list[np.ndarray]:
    """Run ids in session order (runs ordered by their first time), grouped into units: a maximal stretch of
    consecutive runs at the same drive amplitude and load (``voltage_V``, ``load_kg`` of a run's first sample),
    e.g. one condition of the rig's plan, its forward run and its backward run. A frame without those columns
    has one unit per run. Every run is in exactly one unit; a unit is contiguous in the session."""
    g = df.groupby(dataio.RUN, sort=False)
    first = g.first()
    order = np.argsort(g[dataio.TIME].min().reindex(first.index).to_numpy(float), kind="stable")
    ids = first.index.to_numpy()[order]
    cols = [c for c in (dataio.VOLTAGE, dataio.LOAD) if c in first.columns]
    if not cols or len(ids) < 2:
        return [ids[i:i + 1] for i in range(len(ids))]
    cond = first[cols].to_numpy(float)[order]
    new = np.r_[True, np.any(cond[1:] != cond[:-1], axis=1)]
    return np.split(ids, np.flatnonzero(new)[1:])


def session_rotation(df: pd.DataFrame, k: int) -> list[np.ndarray]:
    """Run ids in ``k`` folds of whole session units (:func:`session_units`) dealt in rotation: unit ``j`` of the
    session goes to fold ``j mod k``.

    The folds of a candidate that depends on the session clock when what must be predicted lies between
    measured runs of the session (held-out runs interleaved with the fitted ones in time): a held-out unit has
    fitted units on both sides (one side at the session's ends), so a term is scored on interpolating the clock,
    while the runs of one condition in a row are never split between the held-out and the fitted part. Each
    fold's runs are in session order; every run is in exactly one fold; ``min(k, units)`` folds.
    """
    units = session_units(df)
    k = min(k, len(units))
    return [np.concatenate(units[i::k]) for i in range(k)] if k else []


#: the fold schemes of a candidate that depends on the session clock (``CloseLoop(clock_folds=...)``)
CLOCK_FOLDS = {"blocks": session_blocks, "rotation": session_rotation}


def clock_folds(df: pd.DataFrame, k: int, scheme: str = "blocks") -> list[np.ndarray]:
    """The ``k`` folds of a session-clock candidate by ``scheme`` (a key of :data:`CLOCK_FOLDS`)."""
    if scheme not in CLOCK_FOLDS:
        raise ValueError(f"clock_folds must be one of {sorted(CLOCK_FOLDS)}, got {scheme!r}")
    return CLOCK_FOLDS[scheme](df, k)


def refit_schemes(df: pd.DataFrame, k: int, repeats: int = 1, seed: int = 0, clock: str = "blocks",
                  unit: str = "run", first=None) -> dict:
    """The folds of a round's cross-validated refits: ``{False: repeated_folds(df, k, repeats, seed, unit, first),
    True: clock_folds(df, k, clock)}``, keyed by whether the candidate depends on the session clock
    (:func:`time_dependent`); the session's folds are one split whatever ``repeats`` (they are not shuffled).
    ``first``: ``unit_folds(df, k, seed, unit)`` when the caller has it already."""
    return {False: repeated_folds(df, k, repeats, seed, unit, first), True: clock_folds(df, k, clock)}


def screen_folds(df: pd.DataFrame, mask, k: int, seed: int = 0, clock: str = "blocks",
                 unit: str = "run") -> tuple[list, list]:
    """The folds of a round's linearised screen (:func:`l1b2.closeloop.selection.score_candidates`): ``(folds,
    time_folds)``, those of the candidates that do not depend on the session clock and of those that do
    (:func:`clock_folds`). ``folds`` are over the runs with a sample in ``mask`` (None: every sample): by
    ``unit`` ``"run"`` the runs shuffled (seeded) and dealt in turn (:func:`l1b2.closeloop.residuals.run_folds`),
    ``"condition"`` :func:`condition_folds`."""
    idx = np.flatnonzero(mask) if mask is not None else np.arange(len(df))
    folds = (res.run_folds(df[dataio.RUN].to_numpy()[idx], k, seed) if unit == "run"
             else unit_folds(df.iloc[idx], k, seed, unit))
    return folds, clock_folds(df, k, clock)


@dataclass(frozen=True)
class HeldOut:
    """One fold's split of TRAIN by whole runs, and how a prediction of its held-out runs is scored.

    ``held``: per row of TRAIN, whether its run is held out; ``train``/``test``: the kept and held-out rows (index
    reset); ``mask_train``/``mask_test``: the evaluation mask on each; ``speed_test`` [m/s]: the held-out runs'
    recorded speed (all rows); ``ss_meas`` [m^2/s^2]: its sum of squares on ``mask_test``; ``run_ids``/``code``:
    the held-out runs with a sample on the mask and each masked sample's index into them.
    """

    held: np.ndarray
    train: pd.DataFrame
    test: pd.DataFrame
    mask_train: np.ndarray
    mask_test: np.ndarray
    speed_test: np.ndarray
    ss_meas: float
    run_ids: np.ndarray
    code: np.ndarray

    def failed(self) -> tuple:
        """The score of a failed fit or a diverged prediction: ``(inf, ss_meas, True, 0, {run: inf})``."""
        return np.inf, self.ss_meas, True, 0, {r: np.inf for r in self.run_ids.tolist()}

    def score(self, prediction, nfev: int) -> tuple:
        """``(sse, ss_meas, False, nfev, run_sse)`` of ``speed_test - prediction`` [m/s] on ``mask_test``;
        ``sse`` and every run's sum ``inf`` when an error is not finite."""
        e = (self.speed_test - np.asarray(prediction, float))[self.mask_test]
        if not np.all(np.isfinite(e)):
            return np.inf, self.ss_meas, False, int(nfev), {r: np.inf for r in self.run_ids.tolist()}
        per_run = np.bincount(self.code, weights=e * e, minlength=len(self.run_ids))
        return float(np.sum(e ** 2)), self.ss_meas, False, int(nfev), dict(zip(self.run_ids.tolist(),
                                                                                per_run.tolist()))


def held_out_split(df: pd.DataFrame, mask: np.ndarray, held_runs) -> HeldOut:
    """:class:`HeldOut` of ``df`` (TRAIN, with the evaluation ``mask``) holding out the runs ``held_runs``."""
    runs = df[dataio.RUN].to_numpy()
    held = np.isin(runs, held_runs)
    m_te = np.asarray(mask, bool)[held]
    v = df[dataio.SPEED].to_numpy(float)[held]
    run_ids, code = np.unique(runs[held][m_te], return_inverse=True)
    return HeldOut(held, df.loc[~held].reset_index(drop=True), df.loc[held].reset_index(drop=True),
                   np.asarray(mask, bool)[~held], m_te, v, float(np.sum(v[m_te] ** 2)), run_ids, code)
