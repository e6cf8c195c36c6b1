"""Clusters of runs for the cluster-robust interval: which runs share errors (decisions 0025, 0031).

The sandwich by run (:func:`l1b2.ident.uncertainty.cluster_sandwich`) treats
the runs as independent. On a rig they are not: the two runs of one rig
condition (V0 and signed load, one opposing and one aiding the motion) share
errors, and so, with the opposite sign, do the two mirror runs (V0 and the
load relative to the motion, in opposite directions). The grouping ``level``
(V0 and load size: the four runs of both kinds of pairs) is the smallest
clustering that holds every correlated pair.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ..data import measurements as dataio
from ..data.coverage import FREQUENCY_REL_SPREAD
from .uncertainty import grouped_sandwich

__all__ = ["RUN_GROUPINGS", "run_groups", "grouped_interval", "frequency_levels"]

#: each grouping's load coordinate of a run's label ``(V0, load form)`` from its signed load m [kg] and
#: direction d: the rig's condition (m), its mirror image (d m) and the level (|m|: both pairs together)
_LOAD_FORM = {"condition": lambda m, d: m, "mirror": lambda m, d: m * d, "level": lambda m, d: abs(m)}

#: the groupings of runs into clusters :func:`run_groups` offers
RUN_GROUPINGS = tuple(_LOAD_FORM)


def run_groups(df, runs, grouping: str = "level") -> list[tuple]:
    """Each run's cluster label under ``grouping`` (:data:`RUN_GROUPINGS`), in the order of ``runs``.

    ``df``: a frame with the run, voltage, load and direction columns (a run's
    first row gives its values); ``runs``: run ids, e.g. a fit's ``runs_``.
    A label is ``(V0 [V] rounded to 1e-6, load form [kg] rounded to 1e-9)``:
    ``condition`` the signed load, ``mirror`` direction x load, ``level`` its size.
    """
    if grouping not in _LOAD_FORM:
        raise ValueError(f"run grouping must be one of {RUN_GROUPINGS}, got {grouping!r}")
    load = _LOAD_FORM[grouping]
    first = df.groupby(dataio.RUN, sort=False)[[dataio.VOLTAGE, dataio.LOAD, dataio.DIRECTION]].first()
    label = {k: (round(float(v), 6), round(float(load(m, d)), 9) + 0.0)    # + 0.0: no -0.0 label
             for k, (v, m, d) in zip(first.index, first.to_numpy())}
    return [label[r] for r in runs]


def frequency_levels(df, runs) -> list[int]:
    """Each run's drive-frequency level (0, 1, ... from the lowest), in the order of ``runs``.

    A run's frequency is the median of its ``frequency_Hz``
    (as :func:`l1b2.data.coverage.run_frequencies`); sorted, a new level starts
    where the step to the next run's frequency exceeds
    :data:`l1b2.data.coverage.FREQUENCY_REL_SPREAD` of the runs' median
    frequency (the spread within which the package treats runs as at one
    frequency): runs closer than that to a neighbour share a level (single linkage).
    """
    if dataio.FREQUENCY not in df.columns:
        raise ValueError("frequency_levels: the data have no frequency_Hz column")
    freq = df[dataio.FREQUENCY].to_numpy(float)
    f = {rid: float(np.median(freq[sl])) for rid, sl in dataio.run_slices(df[dataio.RUN])}
    vals = np.array([f[r] for r in runs], float)
    srt = np.sort(np.unique(vals))
    level_of = np.concatenate([[0], np.cumsum(np.diff(srt) > FREQUENCY_REL_SPREAD * float(np.median(vals)))])
    return [int(level_of[np.searchsorted(srt, v)]) for v in vals]


def grouped_interval(value: float, influence, groups, index: int) -> dict | None:
    """Cluster-robust standard error and 95 % interval of parameter ``index`` with the runs merged by ``groups``.

    ``influence``: the fit's ``run_influence_`` (one row per run);
    ``groups``: one label per row (:func:`run_groups`). The covariance is
    :func:`~l1b2.ident.uncertainty.grouped_sandwich` (CR1 factor H/(H-1)),
    the interval ``value +- t_{0.975, H-1} se`` with H the clusters with a
    non-zero row. Returns ``{"stderr", "ci95", "clusters"}``, or None with
    fewer than two clusters or a non-finite standard error.
    """
    cov, h = grouped_sandwich(influence, groups)
    if h < 2:
        return None
    se = float(np.sqrt(cov[index, index]))
    if not np.isfinite(se):
        return None
    q = float(stats.t.ppf(0.975, h - 1))
    return {"stderr": se, "ci95": [float(value - q * se), float(value + q * se)], "clusters": int(h)}
