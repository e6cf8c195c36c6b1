"""The study's samples, all drawn up front from the seed: operating points x parameter design.

* ``montecarlo``: ``draws`` points of the unit hypercube from
  ``numpy.random.default_rng(seed)``, mapped through each parameter's
  truncated inverse CDF. The same draws are used at every operating point
  (common random numbers: operating points differ by the operating point,
  not by the luck of the draw).
* ``saltelli``: a scrambled Sobol' sequence (``scipy.stats.qmc.Sobol``,
  seeded) of dimension 2d gives the matrices A and B (N x d); the runs are A,
  B and, for each parameter i, A with column i taken from B (``AB:i``):
  N (d + 2) runs per operating point, what the Saltelli/Jansen estimators of
  first-order and total Sobol' indices need (:mod:`l1b2.sweep.analysis`).
* ``grid``: the nominal motor at every operating point.

Because every sample is fixed before any runs, a study gives the same table
whatever the number of workers or the order in which tasks finish.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy import stats

from .spec import OPERATING, ParameterDraw, StudySpec

#: columns of the sample table before the parameters
ID_COLUMNS = ("sample_id", "op_id", "draw", "block")
OP_COLUMNS = tuple(col for col, _ in OPERATING.values())


def ppf(d: ParameterDraw, u) -> np.ndarray:
    """Quantiles ``u`` in (0, 1) of ``d``'s distribution truncated to [low, high]."""
    u = np.clip(np.asarray(u, dtype=float), 1e-12, 1.0 - 1e-12)
    if d.kind == "uniform":
        x = d.a + u * (d.b - d.a)
    else:
        if d.kind == "normal":
            loc, lo, hi = d.a, d.low, d.high
        else:  # log-normal: ln x is normal around ln(median)
            loc = np.log(d.a)
            lo = np.log(d.low) if d.low > 0 else -np.inf
            hi = np.log(d.high) if np.isfinite(d.high) else np.inf
        f_lo, f_hi = stats.norm.cdf((lo - loc) / d.b), stats.norm.cdf((hi - loc) / d.b)
        z = stats.norm.ppf(f_lo + u * (f_hi - f_lo))
        x = loc + d.b * z
        if d.kind == "lognormal":
            x = np.exp(x)
    return np.clip(x, d.low, d.high)


def unit_design(spec: StudySpec) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``(U, draw, block)``: rows of the unit hypercube, their draw index and design block."""
    d, n = len(spec.parameters), spec.draws
    if spec.design == "grid" or d == 0:
        return np.zeros((1, 0)), np.zeros(1, dtype=int), ["nominal"]
    if spec.design == "montecarlo":
        u = np.random.default_rng(spec.seed).random((n, d))
        return u, np.arange(n), ["mc"] * n
    from scipy.stats import qmc
    with warnings.catch_warnings():  # Sobol' balance properties want N a power of 2; any N works
        warnings.simplefilter("ignore", UserWarning)
        m = qmc.Sobol(2 * d, scramble=True, seed=spec.seed).random(n)
    a, b = m[:, :d], m[:, d:]
    rows, blocks = [a, b], ["A"] * n + ["B"] * n
    for i, p in enumerate(spec.parameters):
        ab = a.copy()
        ab[:, i] = b[:, i]
        rows.append(ab)
        blocks += [f"AB:{p.name}"] * n
    return np.vstack(rows), np.tile(np.arange(n), d + 2), blocks


def draw_samples(spec: StudySpec) -> pd.DataFrame:
    """Every sample of the study, in sample-id order (operating point major, then design row)."""
    u, draw, block = unit_design(spec)
    values = {p.name: ppf(p, u[:, i]) for i, p in enumerate(spec.parameters)}
    frames = []
    for op_id, op in enumerate(spec.operating_points()):
        f = pd.DataFrame({"op_id": np.full(len(draw), op_id), "draw": draw, "block": block})
        for col in OP_COLUMNS:
            f[col] = op[col]
        for name, v in values.items():
            f[name] = v
        frames.append(f)
    out = pd.concat(frames, ignore_index=True)
    out.insert(0, "sample_id", np.arange(len(out)))
    out["direction"] = out["direction"].astype(int)
    return out


def parameter_columns(samples: pd.DataFrame) -> list[str]:
    """The drawn-parameter columns of a sample table (``Component.field``)."""
    skip = set(ID_COLUMNS) | set(OP_COLUMNS)
    return [c for c in samples.columns if c not in skip and "." in c]
