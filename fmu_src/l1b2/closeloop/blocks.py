"""Contiguous blocks of the session that the runs' own deviations show: the segmentation search of the run-level
analysis (:mod:`l1b2.closeloop.runlevel`) for the family :class:`l1b2.predictor.effects.blocks.SessionBlocks`.

The runs' deviations ``theta_r`` (gain, offset; :class:`l1b2.closeloop.runlevel.RunDeviations`), in the order of
their mean session time, are cut into ``B`` contiguous blocks, for each ``B``, at the positions that give the least
weighted within-block scatter

    ``C = sum_blocks sum_(r in block) (theta_r - m_block)' W_r (theta_r - m_block)``,

``W_r = (T + S_r)^-1`` (``T`` the REML between-run covariance without blocks, ``S_r`` the run's sampling
covariance) and ``m_block`` the block's weighted mean (:func:`segment_cost`), every block keeping at least
:data:`MIN_BLOCK_RUNS` runs, ``B`` from 2 to :data:`MAX_BLOCKS` (:func:`optimal_segmentations`, dynamic
programming). Each ``B`` gives one segmentation; its edges lie midway between the last run of a block and the first
of the next (:func:`edges_of`).

The search looks at many segmentations, so its evidence is corrected for them: a segmentation's p-value is
multiplied by :func:`search_count`, the number of ways to cut the runs into ``B`` contiguous blocks of at least
:data:`MIN_BLOCK_RUNS` runs, times the number of ``B`` tried (a union bound over every segmentation the search could
have returned). The run-level analysis searches only when no other run-level signal is significant
(:func:`l1b2.closeloop.runlevel.analyse`): blocks are the evidence of last resort, since enough blocks follow any
misfit of the runs.
"""

from __future__ import annotations

from math import comb

import numpy as np

from ..predictor.effects.blocks import block_index

#: the fewest runs of a block: fewer leave its level to the runs' own random deviations
MIN_BLOCK_RUNS = 3
#: the share of the best cross-validated gain within which the fewest blocks are taken (the loop's own parsimony,
#: :func:`l1b2.closeloop.loop.prefer`): a block cut in two gains by chance what its own runs' scatter gives
PARSIMONY = 0.9
#: the most blocks searched (``B - 1`` parameters of the family at most: 11)
MAX_BLOCKS = 12


def load_size_folds(load) -> list[np.ndarray] | None:
    """Folds of the runs by the size of their load (``load``: each run's drive-coordinate load ``d m / max|m|``, or
    None): the indices of the runs at each distinct ``|load|`` (to 1e-9), smallest first; None with fewer than two
    sizes. A block's level is a fact of the session, so it must hold for the runs of a load size that the fit did
    not see, as for a TEST set of its own load (the paper's split)."""
    if load is None:
        return None
    size = np.round(np.abs(np.asarray(load, float)), 9)
    levels = np.unique(size)
    return [np.flatnonzero(size == v) for v in levels] if len(levels) >= 2 else None


def weights(T: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``W_r = (T + S_r)^-1``, ``(n, 2, 2)``."""
    return np.linalg.inv(np.asarray(T, float)[None] + np.asarray(cov, float))


def segment_cost(theta: np.ndarray, W: np.ndarray) -> float:
    """The weighted scatter of one block's deviations about their weighted mean: ``sum (theta_r - m)' W_r (theta_r
    - m)``, ``m = (sum W_r)^-1 sum W_r theta_r``."""
    theta, W = np.asarray(theta, float), np.asarray(W, float)
    m = np.linalg.solve(W.sum(axis=0), np.einsum("rpq,rq->p", W, theta))
    r = theta - m
    return float(np.einsum("rp,rpq,rq->", r, W, r))


def cost_matrix(theta, W, min_runs: int = MIN_BLOCK_RUNS) -> np.ndarray:
    """``C[a, b]``: :func:`segment_cost` of the runs ``a ... b - 1`` (in session order) for every block of at least
    ``min_runs`` runs (``inf`` elsewhere), ``(n + 1, n + 1)``, from prefix sums of ``W_r``, ``W_r theta_r`` and
    ``theta_r' W_r theta_r``: ``C = sum theta' W theta - v' M^-1 v``, ``v = sum W theta``, ``M = sum W``."""
    theta, W = np.asarray(theta, float), np.asarray(W, float)
    n = len(theta)
    Wt = np.einsum("rpq,rq->rp", W, theta)
    tWt = np.einsum("rp,rp->r", theta, Wt)
    SW = np.concatenate([np.zeros((1, 2, 2)), np.cumsum(W, axis=0)])
    SWt = np.concatenate([np.zeros((1, 2)), np.cumsum(Wt, axis=0)])
    St = np.concatenate([[0.0], np.cumsum(tWt)])
    a, b = np.triu_indices(n + 1, k=min_runs)
    M, v = SW[b] - SW[a], SWt[b] - SWt[a]
    C = np.full((n + 1, n + 1), np.inf)
    C[a, b] = St[b] - St[a] - np.einsum("kp,kp->k", v, np.linalg.solve(M, v[:, :, None])[:, :, 0])
    return C


def optimal_segmentations(theta, W, max_blocks: int = MAX_BLOCKS, min_runs: int = MIN_BLOCK_RUNS) -> list[tuple]:
    """For ``B = 2 ... max_blocks`` blocks (as many as ``min_runs`` allows), the cut of deviations in session order
    into ``B`` contiguous blocks of at least ``min_runs`` runs with the least total :func:`segment_cost`, as the
    positions where blocks ``2 ... B`` start (increasing); by dynamic programming over :func:`cost_matrix`."""
    n = len(theta)
    C = cost_matrix(theta, W, min_runs)
    best = C[0].copy()          # best[b]: the least cost of runs 0 ... b - 1 in k blocks (k = 1 here)
    back: list = []
    out = []
    for k in range(2, min(max_blocks, n // min_runs) + 1):
        tot = best[:, None] + C   # tot[a, b]: k - 1 blocks up to a, then one block a ... b - 1
        arg = np.argmin(tot, axis=0)
        best = tot[arg, np.arange(n + 1)]
        back.append(arg)
        if not np.isfinite(best[n]):
            break
        starts, b = [], n
        for arg_k in reversed(back):
            b = int(arg_k[b])
            starts.append(b)
        out.append(tuple(sorted(starts)))
    return out


def search_count(n: int, n_blocks: int, min_runs: int = MIN_BLOCK_RUNS) -> int:
    """The number of ways to cut ``n`` ordered runs into ``n_blocks`` contiguous blocks of at least ``min_runs``
    runs each: ``C(n - B (min_runs - 1) - 1, B - 1)`` (0 when they cannot be cut so)."""
    free = n - n_blocks * (min_runs - 1) - 1
    return comb(free, n_blocks - 1) if free >= n_blocks - 1 >= 0 else 0


def edges_of(t_sorted_s, starts) -> tuple:
    """The session times [s] between blocks: midway between the last run of a block and the first of the next
    (``t_sorted_s``: the runs' mean session times, increasing; ``starts``: where blocks ``2 ... B`` start)."""
    t = np.asarray(t_sorted_s, float)
    return tuple(float(0.5 * (t[k - 1] + t[k])) for k in starts)


def segmentations(theta, cov, T, t_run_s, max_blocks: int = MAX_BLOCKS, min_runs: int = MIN_BLOCK_RUNS) -> list[dict]:
    """Every segmentation the search finds for runs with deviations ``theta`` (n, 2), covariances ``cov`` and mean
    session times ``t_run_s`` (any order), between-run covariance ``T``: ``{"edges" [s], "shares" (every block's
    share of the runs but the last), "values" (each run's block, in the runs' order), "search_count"}``, two
    blocks first. ``search_count`` is :func:`search_count` times the number of block counts tried
    (``max_blocks - 1``)."""
    t = np.asarray(t_run_s, float)
    n = len(t)
    if n < 2 * min_runs:
        return []
    order = np.argsort(t, kind="stable")
    W = weights(T, np.asarray(cov, float)[order])
    out = []
    for starts in optimal_segmentations(np.asarray(theta, float)[order], W, max_blocks, min_runs):
        edges = edges_of(t[order], starts)
        idx = block_index(t, edges)
        shares = tuple(float(np.mean(idx == j)) for j in range(len(edges)))
        out.append({"edges": edges, "shares": shares, "values": idx.astype(float),
                    "search_count": search_count(n, len(edges) + 1, min_runs) * (max_blocks - 1)})
    return out
