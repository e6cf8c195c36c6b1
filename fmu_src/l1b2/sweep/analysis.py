"""Reducing a study's table: percentiles per operating point, and which parameter matters most.

* :func:`summarize`: per operating point and output, the number of samples,
  failures, mean, standard deviation and the 5th, 50th and 95th percentiles
  (numpy's default linear interpolation) over the successful samples; for
  ``stalled``, the fraction of samples that stalled.
* :func:`src_ranking`: standardised regression coefficients (SRC): the
  least-squares fit of the standardised output on the standardised
  parameters. ``SRC_i^2`` is the share of the output's variance parameter i
  explains when the model is near linear, which the fit's R^2 says (SRC
  means little when R^2 is well below 1). Ranked by ``|SRC|``.
* :func:`sobol_indices`: for a Saltelli design, first-order indices by
  Saltelli et al. (2010) ``S_i = mean(f_B (f_ABi - f_A)) / V`` and total
  indices by Jansen (1999) ``ST_i = mean((f_A - f_ABi)^2) / (2 V)``, with
  95 % bootstrap half-widths (resampling the base draws); the outputs are
  centred on their mean first, which leaves the estimators' expectation and
  cuts their variance.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .sampling import OP_COLUMNS, parameter_columns

PERCENTILES = (5, 50, 95)


def numeric_outputs(df: pd.DataFrame, outputs) -> list[str]:
    return [c for c in outputs if c != "stalled" and c in df.columns]


def summarize(df: pd.DataFrame, outputs) -> pd.DataFrame:
    """One row per operating point and output: n, failed, mean, sd, p5, p50, p95 (see the module doc)."""
    rows = []
    for op_id, g in df.groupby("op_id", sort=True):
        ok = g[g["status"] == "ok"]
        base = {"op_id": int(op_id), **{c: g[c].iloc[0] for c in OP_COLUMNS}}
        n_failed = int((g["status"] != "ok").sum())
        for c in outputs:
            if c not in g.columns:
                continue
            x = ok[c].astype(float).to_numpy()
            x = x[np.isfinite(x)]
            row = {**base, "output": c, "n": int(len(x)), "failed": n_failed}
            if c == "stalled":
                row.update(mean=float(x.mean()) if len(x) else np.nan)
            elif len(x):
                p = np.percentile(x, PERCENTILES)
                row.update(mean=float(x.mean()), sd=float(x.std(ddof=1)) if len(x) > 1 else 0.0,
                           **{f"p{q}": float(v) for q, v in zip(PERCENTILES, p)})
            rows.append(row)
    cols = ["op_id", *OP_COLUMNS, "output", "n", "failed", "mean", "sd"] + [f"p{q}" for q in PERCENTILES]
    return pd.DataFrame(rows).reindex(columns=cols)


def src_ranking(df: pd.DataFrame, outputs) -> pd.DataFrame:
    """Standardised regression coefficients per operating point and output, ranked by |SRC|."""
    params = parameter_columns(df)
    rows = []
    if not params:
        return pd.DataFrame(columns=["op_id", "output", "parameter", "src", "rank", "r2", "n"])
    for op_id, g in df[df["status"] == "ok"].groupby("op_id", sort=True):
        for c in numeric_outputs(g, outputs):
            y = g[c].astype(float).to_numpy()
            keep = np.isfinite(y)
            x = g.loc[keep, params].to_numpy(float)
            y = y[keep]
            sx, sy = x.std(axis=0), y.std()
            use = sx > 0
            if len(y) < use.sum() + 2 or sy == 0 or not use.any():
                continue
            xs = (x[:, use] - x[:, use].mean(axis=0)) / sx[use]
            ys = (y - y.mean()) / sy
            coef, *_ = np.linalg.lstsq(np.column_stack([xs, np.ones(len(ys))]), ys, rcond=None)
            resid = ys - np.column_stack([xs, np.ones(len(ys))]) @ coef
            r2 = 1.0 - float(resid @ resid) / float(ys @ ys)
            src = dict(zip([p for p, u in zip(params, use) if u], coef[:-1]))
            order = sorted(src, key=lambda p: -abs(src[p]))
            for rank, p in enumerate(order, 1):
                rows.append({"op_id": int(op_id), "output": c, "parameter": p, "src": float(src[p]),
                             "rank": rank, "r2": r2, "n": int(len(y))})
    return pd.DataFrame(rows, columns=["op_id", "output", "parameter", "src", "rank", "r2", "n"])


def _sobol(fa, fb, fab):
    mean = np.mean(np.concatenate([fa, fb]))  # centred: the estimators' variance grows with the output's mean
    fa, fb, fab = fa - mean, fb - mean, fab - mean
    var = np.var(np.concatenate([fa, fb]), ddof=1)
    if not var > 0:
        return np.full(fab.shape[0], np.nan), np.full(fab.shape[0], np.nan)
    s1 = np.mean(fb * (fab - fa), axis=1) / var
    st = 0.5 * np.mean((fa - fab) ** 2, axis=1) / var
    return s1, st


def sobol_indices(df: pd.DataFrame, outputs, *, n_boot: int = 200, seed: int = 0) -> pd.DataFrame:
    """First-order and total Sobol' indices per operating point and output (Saltelli designs only)."""
    cols = ["op_id", "output", "parameter", "S1", "S1_conf", "ST", "ST_conf", "rank", "n"]
    if "block" not in df.columns or not (df["block"] == "A").any():
        return pd.DataFrame(columns=cols)
    params = [b[3:] for b in dict.fromkeys(df["block"]) if b.startswith("AB:")]
    rng = np.random.default_rng(seed)
    rows = []
    for op_id, g in df.groupby("op_id", sort=True):
        for c in numeric_outputs(g, outputs):
            y = g[c].astype(float).where(g["status"] == "ok")
            table = pd.DataFrame({"draw": g["draw"], "block": g["block"], "y": y}).pivot(
                index="draw", columns="block", values="y")
            table = table[["A", "B"] + [f"AB:{p}" for p in params]].dropna()
            if len(table) < 4:
                continue
            fa, fb = table["A"].to_numpy(), table["B"].to_numpy()
            fab = table[[f"AB:{p}" for p in params]].to_numpy().T
            s1, st = _sobol(fa, fb, fab)
            boots = [_sobol(fa[i], fb[i], fab[:, i]) for i in
                     (rng.integers(0, len(fa), len(fa)) for _ in range(n_boot))]
            s1_conf = 1.96 * np.nanstd([b[0] for b in boots], axis=0)
            st_conf = 1.96 * np.nanstd([b[1] for b in boots], axis=0)
            order = np.argsort(-np.nan_to_num(st, nan=-np.inf))
            rank = np.empty(len(params), dtype=int)
            rank[order] = np.arange(1, len(params) + 1)
            for i, p in enumerate(params):
                rows.append({"op_id": int(op_id), "output": c, "parameter": p, "S1": float(s1[i]),
                             "S1_conf": float(s1_conf[i]), "ST": float(st[i]), "ST_conf": float(st_conf[i]),
                             "rank": int(rank[i]), "n": int(len(fa))})
    return pd.DataFrame(rows, columns=cols)
