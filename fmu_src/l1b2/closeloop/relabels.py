"""A logged channel that only relabels the plan's inputs: a run-level reading fixed by one or two of them.

A rig logs readings that follow what the operator set: a supply monitor reads V0, a meter's phase flips with the
direction, a balance reads the hung weight. When such a reading is, run by run, a function of the plan's inputs
(V0, the signed load, the direction, the drive frequency) taken one or two at a time, and constant within each run
up to its noise, the data hold nothing it could explain that those inputs cannot: any form built on it is a form of
the inputs, and tracing it as a cause would name a sensor for what the plan set. Such a channel is listed with the
inputs it follows and offered no hypothesis (kind ``"relabel"`` in :func:`l1b2.closeloop.candidates.channels_of`).

The test, :func:`follows_plan`, on TRAIN's frame:

1. **Run-level only.** The pooled variance of the samples about their run means is at most :data:`FLAT_RATIO`
   times the noise variance from first differences within runs (``sum(diff^2) / (2 n_diff)``): no structure
   within runs beyond white noise; and that within-run variance is at most :data:`WITHIN_SHARE` of the samples'
   total variance, so the reading is carried by its run means (a sensor whose sample-to-sample variation might
   itself act is never relabelled).
2. **Fixed by the cells.** For each set of one or two inputs (those that are constant within every run and take
   more than one value), the runs fall into cells of equal input values. The run means ``m_k`` deviate from their
   cell's precision-weighted mean by ``r_k``; with ``se_k^2`` the noise variance over the run's sample count,
   ``Q = sum(r_k^2 / se_k^2)`` is chi-square with ``n_runs - n_cells`` degrees of freedom when the channel is a
   function of the cells. The channel follows the first set (fewest cells, then the inputs' order) whose
   ``Q`` has an upper tail probability above :data:`RELABEL_P`, among the sets whose cells hold on average at
   least :data:`MIN_CELL_RUNS` runs and leave at least :data:`MIN_DOF` degrees of freedom. Cells of one or two runs
   fix anything that runs alike in neighbouring runs (a plan that drives each setting forward and then backward
   makes the cells of V0 and the load such pairs).

A reading that drifts, settles, accumulates or scatters between runs of the same cell fails the test and stays a
candidate; the rule that prefers the inputs to a channel that only partly follows them is
:func:`l1b2.closeloop.acceptance.input_reading`.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats

from ..data import measurements as dataio

__all__ = ["PLAN_INPUTS", "FLAT_RATIO", "WITHIN_SHARE", "RELABEL_P", "MIN_CELL_RUNS", "MIN_DOF", "follows_plan"]

#: the plan's inputs a channel may relabel, in the order the sets of cells are tried
PLAN_INPUTS = (dataio.VOLTAGE, dataio.DIRECTION, dataio.LOAD, dataio.FREQUENCY)
#: the largest ratio of the within-run variance to the first differences' noise variance of a run-level reading
FLAT_RATIO = 1.5
#: the largest share of the samples' total variance that may lie within runs
WITHIN_SHARE = 0.2
#: the chi-square upper tail probability of the within-cell scatter of the run means above which the cells fix them
RELABEL_P = 1e-3
#: the fewest runs a set's cells must hold on average
MIN_CELL_RUNS = 4
#: the fewest degrees of freedom (runs minus cells) a set of cells must leave
MIN_DOF = 8


def _run_inputs(df: pd.DataFrame, runs, exclude: str) -> dict:
    """The plan's inputs that are constant within every run of ``df`` and take more than one value: ``{name: one
    value per run}`` in :data:`PLAN_INPUTS`' order (``exclude`` left out)."""
    out = {}
    for col in PLAN_INPUTS:
        if col == exclude or col not in df.columns:
            continue
        g = runs[col]
        if bool((g.max() - g.min()).to_numpy(float).max() > 0):
            continue
        values = g.first().to_numpy(float)
        if len(np.unique(values)) > 1:
            out[col] = values
    return out


def follows_plan(df: pd.DataFrame, name: str) -> tuple[str, ...]:
    """The plan's inputs (one or two of :data:`PLAN_INPUTS`) whose cells fix the numeric column ``name`` of ``df``
    run by run (module docstring); ``()`` when none does, when the column varies within runs beyond white noise or
    has no variance, and for the model's own inputs (a plan input or the temperature: their physics is the
    predictor's)."""
    if name in PLAN_INPUTS or name == dataio.TEMPERATURE:
        return ()
    x = df[name].to_numpy(float)
    run_ids = df[dataio.RUN].to_numpy()
    runs = df.groupby(dataio.RUN, sort=False)
    means = runs[name].transform("mean").to_numpy(float)
    total = float(np.var(x))
    if not total > 0:
        return ()
    within = float(np.mean((x - means) ** 2))
    same = run_ids[1:] == run_ids[:-1]
    dx = np.diff(x)[same]
    noise = float(np.sum(dx ** 2) / (2 * dx.size)) if dx.size else 0.0
    if within > FLAT_RATIO * noise + 1e-24 * total or within > WITHIN_SHARE * total:
        return ()
    m = runs[name].mean().to_numpy(float)
    n = runs[name].size().to_numpy(float)
    se2 = np.maximum(noise / n, (1e-9 * np.sqrt(total)) ** 2)
    inputs = _run_inputs(df, runs, name)
    sets = [(c,) for c in inputs] + list(combinations(inputs, 2))
    cells_of = {s: pd.DataFrame({c: inputs[c] for c in s}).groupby(list(s), sort=False).ngroup().to_numpy()
                for s in sets}
    for s in sorted(sets, key=lambda s: int(cells_of[s].max()) + 1):
        cell = cells_of[s]
        k = int(cell.max()) + 1
        dof = len(m) - k
        if dof < MIN_DOF or k * MIN_CELL_RUNS > len(m):
            continue
        w = 1.0 / se2
        centre = np.bincount(cell, w * m, k) / np.bincount(cell, w, k)
        q = float(np.sum((m - centre[cell]) ** 2 * w))
        if stats.chi2.sf(q, dof) > RELABEL_P:
            return tuple(s)
    return ()
