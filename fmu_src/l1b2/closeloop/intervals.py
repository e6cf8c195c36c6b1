"""The standard errors and 95 % intervals the close loop reports for its added effects' parameters (decision 0031).

The loop's premise is a model that misses something, so its residuals carry
errors shared within each run and between runs of one operating level; the
model-based (AR(1)-inflated Fisher) interval treats them as independent noise
and the run-robust one treats the runs as independent, while the paired
runs of one rig condition, and the mirror runs, share errors (decision
0025). The reported interval clusters the runs by level (V0 and load size,
the four runs of both pairs: :func:`l1b2.ident.clusters.run_groups`); the
run-robust and model-based ones are kept beside it.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ..ident.clusters import grouped_interval, run_groups
from ..ident.uncertainty import grouped_sandwich

__all__ = ["REPORTED_GROUPING", "added_parameters", "identification", "reported_covariance", "reported_uncertainty",
           "train_levels", "wald_test"]

#: the clustering of TRAIN's runs behind the reported interval (:data:`l1b2.ident.clusters.RUN_GROUPINGS`)
REPORTED_GROUPING = "level"


def train_levels(model, df) -> list | None:
    """Cluster labels of a fitted model's runs (its ``runs_``) by :data:`REPORTED_GROUPING`, read from ``df``.

    ``df``: the frame the model was fitted on. None when the model has no
    runs or no run influences (nothing to regroup).
    """
    runs = getattr(model, "runs_", None)
    if runs is None or getattr(model, "run_influence_", None) is None:
        return None
    return run_groups(df, runs, REPORTED_GROUPING)


def _extra_index(model, name: str) -> int:
    """The index of the added parameter ``name`` in the fit's full parameter vector (``param_names_all_``, the
    added parameters last)."""
    extras = list(model.extra_names_)
    return len(list(model.param_names_all_)) - len(extras) + extras.index(name)


def reported_uncertainty(model, name: str, groups=None) -> dict:
    """``{"stderr", "ci95", "interval", ...}`` the close loop reports for the added parameter ``name``.

    In order of preference (``interval`` names the one reported as
    ``stderr``/``ci95``):

    - ``"level"``: cluster-robust with the runs merged by ``groups`` (one
      label per run of ``model.runs_``, :func:`train_levels`), t with
      clusters - 1 degrees of freedom, ``clusters`` their number; needs the
      fit's ``run_influence_`` and a finite value. The run-robust interval is
      kept as ``stderr_run``/``ci95_run`` when finite.
    - ``"run"``: the cluster-by-run robust interval of the fit.
    - ``"model"``: the model-based one (a fit without finite robust values).

    Unless ``"model"`` is reported, the model-based one is kept as ``stderr_model``/``ci95_model``.
    """
    se = float(model.extra_stderr_[name])
    ci = [float(x) for x in model.extra_ci95_[name]]
    se_run = float(getattr(model, "extra_stderr_robust_", {}).get(name, float("nan")))
    run = ({"stderr": se_run, "ci95": [float(x) for x in model.extra_ci95_robust_[name]]}
           if np.isfinite(se_run) else None)
    level = None
    if groups is not None and getattr(model, "run_influence_", None) is not None:
        level = grouped_interval(float(model.extra_params_[name]), model.run_influence_, groups,
                                 _extra_index(model, name))
    model_based = {"stderr_model": se, "ci95_model": ci}
    if level is not None:
        out = {**level, "interval": "level"}
        if run is not None:
            out.update(stderr_run=run["stderr"], ci95_run=run["ci95"])
        return {**out, **model_based}
    if run is not None:
        return {**run, "interval": "run", **model_based}
    return {"stderr": se, "ci95": ci, "interval": "model"}


def reported_covariance(model, names, groups=None) -> tuple | None:
    """The covariance matrix of the added parameters ``names`` under the interval the report gives them.

    The kind is :func:`reported_uncertainty`'s (``level``: the grouped sandwich of the fit's ``run_influence_``
    with the runs merged by ``groups``; ``run``: the cluster-by-run robust ``cov_robust_all_``; ``model``:
    ``cov_all_``), so its diagonal is the reported standard errors squared. Nested tuples, one row per name;
    None when the names' kinds differ, the fit has no such matrix or a value is not finite.
    """
    kinds = {reported_uncertainty(model, n, groups)["interval"] for n in names}
    if len(kinds) != 1:
        return None
    kind = kinds.pop()
    idx = [_extra_index(model, n) for n in names]
    if kind == "level":
        cov = grouped_sandwich(model.run_influence_, groups)[0]
    else:
        cov = getattr(model, "cov_robust_all_" if kind == "run" else "cov_all_", None)
    if cov is None:
        return None
    block = np.asarray(cov, float)[np.ix_(idx, idx)]
    return tuple(tuple(float(v) for v in row) for row in block) if np.all(np.isfinite(block)) else None


def wald_test(phi, cov, clusters: int | None, alpha: float) -> dict:
    """Whether the parameters ``phi`` are jointly different from zero under their covariance ``cov``.

    The Wald statistic ``W = phi' C^-1 phi`` (k parameters). With ``clusters`` H (a cluster-robust ``cov``) the
    test is ``F = W / k`` on (k, H - 1) degrees of freedom, which for k = 1 is the square of the t with H - 1
    that :func:`reported_uncertainty` gives one parameter; without (``None``) it is chi-square with k. Returns
    ``{"wald", "k", "df_denominator", "p", "alpha", "identified"}``: identified when ``p < alpha``. A ``cov``
    that is missing (None), singular or not finite, or fewer than two clusters, identifies nothing (``wald`` and
    ``p`` None).
    """
    phi = np.asarray(phi, float).ravel()
    k = int(phi.size)
    out = {"wald": None, "k": k, "df_denominator": None if clusters is None else int(clusters) - 1, "p": None,
           "alpha": float(alpha), "identified": False}
    if cov is None:
        return out
    C = np.asarray(cov, float).reshape(phi.size, phi.size)
    if not (np.all(np.isfinite(C)) and np.all(np.isfinite(phi))) or (clusters is not None and clusters < 2):
        return out
    try:
        w = float(phi @ np.linalg.solve(C, phi))
    except np.linalg.LinAlgError:
        return out
    if not np.isfinite(w) or w < 0:
        return out
    p = float(stats.f.sf(w / k, k, clusters - 1) if clusters is not None else stats.chi2.sf(w, k))
    return {**out, "wald": w, "p": p, "identified": bool(p < alpha)}


def identification(model, names, groups, alpha: float) -> dict:
    """:func:`wald_test` of the added parameters ``names`` of ``model`` against zero, under the interval the
    report gives them (:func:`reported_covariance`; ``level``: H the level clusters, ``run``: H the runs,
    ``model``: chi-square). Adds ``"interval"`` and ``"values"``; no covariance: not identified."""
    names = list(names)
    phi = [float(model.extra_params_[n]) for n in names]
    cov = reported_covariance(model, names, groups)
    u = reported_uncertainty(model, names[0], groups)
    runs = getattr(model, "runs_", None)
    h = (u.get("clusters") if u["interval"] == "level"
         else (len(runs) if runs is not None else None) if u["interval"] == "run" else None)
    out = wald_test(phi, cov, None if cov is None else h, alpha)
    return {**out, "interval": u["interval"], "values": dict(zip(names, phi))}


def added_parameters(model, effects, groups=None) -> dict:
    """Every added parameter of the final model: value, stderr, 95 % interval, unit, and whether it is identified.

    A parameter without a finite standard error is named unidentifiable and
    reported without a value (``value``, ``stderr``, ``ci95`` None,
    ``unidentifiable`` True): the data do not determine it. The others carry
    :func:`reported_uncertainty` (``groups``: the runs' level labels,
    :func:`train_levels`). ``effects``: the loop's
    :class:`~l1b2.closeloop.acceptance.EffectSet`.
    """
    out = {}
    for c in effects.candidates:
        for n, u in zip(c.names, c.units):
            se = float(model.extra_stderr_[n])
            if np.isfinite(se):
                out[n] = {"value": float(model.extra_params_[n]), "unit": u, "unidentifiable": False,
                          **reported_uncertainty(model, n, groups)}
            else:
                out[n] = {"value": None, "stderr": None, "ci95": None, "unit": u, "unidentifiable": True}
    return out
