"""The run's setting that a reading carries beside what the motion makes of it.

A logged column that the consequence test classes a response of the motion (:mod:`l1b2.closeloop.responses`) is never
a candidate: it follows the speed within runs, and read as a cause it would stand in for the model with TEST's own
speeds. A column read along the stroke (:func:`l1b2.closeloop.candidates.is_along_stroke`: a function of where the
slider is) gets no run-level signal: its run mean weighs each position by the time the slider spent there, so it
follows how the run moved. A reading can be part motion, part setting: the current of a voice coil driven by a
voltage set per run, ``i = (u - K v) / R``, carries the speed's back-EMF ``K v / R`` within the run and the
amplifier's setting ``u / R`` in its level; a load cell under a preload spring reads the spring's deflection along
the stroke and the preload set before the run. A law says what the motion makes of the column; what it leaves in
each run's level is the run's own.

**The law** is fitted by least squares on TRAIN over every run::

    c = X(v) beta + P(s) gamma + a_r + b_r (t - tbar_r) + e

``X`` the speed's history of the consequence test's best fit for a response (its ``history`` and ``tau_s``,
:func:`l1b2.closeloop.responses.history_basis` on TRAIN's scale; none for a column read along the stroke), ``P`` the
position's polynomials over TRAIN's stroke (:func:`l1b2.closeloop.responses.position_basis`), ``a_r`` and ``b_r``
each run's level and trend (``tbar_r`` the run's mean time): ``beta`` and ``gamma`` come from the fit of the within-run
residuals (each run's mean and line in time removed from the column and from ``X`` and ``P``), the same fit by the
Frisch-Waugh theorem. A response's law has the trend, as the consequence test has (a drift within the run is no
echo of the speed); a column read along the stroke has none (``b_r = 0``): within a run the way gone grows nearly in
proportion to the time, so a trend per run would take the position's own slope.

**The run's setting** is ``a_r``, the run's mean of ``c - X beta - P gamma`` (the trend is centred on ``tbar_r``), in
the column's unit: the derived channel ``<column>_setting`` (:data:`l1b2.units.SETTING_SUFFIX`), constant within each
run, a logged channel like any setting (offered with the generic forms and as a run-level signal). TEST's runs get
theirs from TRAIN's law (``beta``, ``gamma``, the history's scale and the stroke's span) applied to TEST's column and
measured speed and position: the run's setting as the reading carries it. When the law is exact it holds nothing of
the motion; what it holds of it is the law's misfit, which the loop's acceptance weighs like any candidate's.

**What the plan fixes is no setting.** A reading whose level follows the drive amplitude (a sound level, a sensor's
gain drift with the supply) leaves run levels that the plan's inputs fix, up to the law's misfit of the speed's
echo, which is itself a function of the run's speed: read as a cause, it would carry TEST's own speed into the
prediction. So the settings are kept only when the plan's inputs explain less than :data:`PLAN_SHARE_MAX` of their
variance over TRAIN's runs (:func:`plan_share`: a least-squares fit on the standardised drive amplitude, load and
drive frequency, each with its square, the direction and the direction times the load), as a logged setting that
only relabels the plan is offered nothing (:mod:`l1b2.closeloop.relabels`).

**Nor is noise.** A reading that is a function of the motion alone (a homing probe's field along the stroke) leaves
run levels that scatter by its noise only. The settings are kept only when their scatter over TRAIN's runs exceeds
what each run's mean holds of the column's noise (:func:`scatter_p`: a chi-square test of the precision-weighted
scatter, each run mean's variance from its within-run residual, inflated for lag-1 autocorrelation, below
:data:`SCATTER_P`).

It is derived for every column the test classed a response (``response`` true and among the loop's responses; not
for the named responses of the default list or of the user's setting, which no law was fitted to) and every logged
column read along the stroke (not a model input: the drive frequency and the temperature are read per sample), that
varies in every run of TRAIN (a response constant in some runs was tested on the others only), that TEST logs when a
TEST is given and whose settings neither the plan fixes nor noise makes. Each is recorded
(:func:`with_run_settings`), derived or not and why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from ..data import measurements as dataio
from ..units import SETTING_SUFFIX
from .responses import history_basis, position_basis, position_span, within_runs

__all__ = ["PLAN_SHARE_MAX", "SCATTER_P", "MotionLaw", "fit_motion_law", "plan_share", "scatter_p",
           "with_run_settings"]

#: the largest share of the settings' variance over TRAIN's runs that the plan's inputs may explain for the settings
#: to be derived (more than half of it is the runs' own)
PLAN_SHARE_MAX = 0.5
#: the largest p-value of the settings' scatter against their noise (:func:`scatter_p`) for them to be derived
SCATTER_P = 1e-3


@dataclass(frozen=True)
class MotionLaw:
    """The law of a column fitted on TRAIN (module docstring): the column's ``channel``, the speed's ``history`` and
    its ``tau_s`` [s] (None for the rate's bank; ``history`` None: no speed part, a column read along the stroke), the
    history's ``scale`` (the divisors of its columns, TRAIN's largest magnitudes), the position's ``span``
    (``(lowest, range)`` [m] of TRAIN's stroke), and the coefficients ``beta`` (of the history's columns) and
    ``gamma`` (of the position's polynomials), in the column's unit; ``trend``: each run's trend in time was part of
    the fit (module docstring)."""

    channel: str
    history: str | None
    tau_s: float | None
    scale: tuple
    span: tuple
    beta: tuple
    gamma: tuple
    trend: bool = True

    def echo(self, df: pd.DataFrame) -> np.ndarray:
        """``X beta + P gamma`` on the samples of ``df`` [the column's unit]: what the motion makes of the column by
        the law, with TRAIN's scale and span."""
        X = _history(df, self.history, self.tau_s, self.scale)[0]
        P = position_basis(df[dataio.POSITION].to_numpy(float), self.span)
        return X @ np.asarray(self.beta, float) + P @ np.asarray(self.gamma, float)

    def run_settings(self, df: pd.DataFrame) -> np.ndarray:
        """Each sample's run mean of ``c - echo`` [the column's unit]: the run's setting, constant within each run."""
        rest = df[self.channel].to_numpy(float) - self.echo(df)
        return pd.Series(rest).groupby(df[dataio.RUN].to_numpy(), sort=False).transform("mean").to_numpy(float)


def _history(df: pd.DataFrame, history: str | None, tau_s, scale=None):
    """``(columns, scale)`` of the speed's ``history`` on ``df``'s samples (:func:`history_basis`); no column for
    ``history`` None."""
    if history is None:
        return np.zeros((len(df), 0)), ()
    return history_basis(df[dataio.SPEED].to_numpy(float), df[dataio.TIME].to_numpy(float),
                         df[dataio.RUN].to_numpy(), history, tau_s, scale)


def fit_motion_law(df: pd.DataFrame, channel: str, history: str | None = None,
                     tau_s: float | None = None) -> MotionLaw:
    """The law of column ``channel`` of ``df`` (TRAIN, runs in consecutive blocks) with the speed's ``history`` at
    ``tau_s`` [s] (None: the position's polynomials only, and no trend per run), fitted by least squares on the
    within-run residuals (module docstring)."""
    run, t = df[dataio.RUN].to_numpy(), df[dataio.TIME].to_numpy(float)
    X, scale = _history(df, history, tau_s)
    s = df[dataio.POSITION].to_numpy(float)
    span = position_span(s)
    trend = history is not None
    A = within_runs(np.column_stack([X, position_basis(s, span)]), run, t, trend)
    c = within_runs(df[channel].to_numpy(float)[:, None], run, t, trend)[:, 0]
    coef = np.linalg.lstsq(A, c, rcond=None)[0]
    k = X.shape[1]
    return MotionLaw(channel=str(channel), history=history, tau_s=tau_s, scale=tuple(scale), span=span,
                       beta=tuple(float(b) for b in coef[:k]), gamma=tuple(float(g) for g in coef[k:]), trend=trend)


def plan_share(df: pd.DataFrame, values) -> float:
    """The share of the variance over ``df``'s runs of the per-sample column ``values``' run means that the plan's
    inputs explain (the R^2 of a least-squares fit with an intercept on the runs' standardised drive amplitude,
    load and drive frequency, each with its square, the direction and the direction times the standardised load;
    the inputs constant over the runs left out); 1 for run means that do not vary."""
    runs = df.assign(_v=np.asarray(values, float)).groupby(dataio.RUN, sort=False)
    y = runs["_v"].mean().to_numpy(float)
    first = runs.first()
    z = {c: first[c].to_numpy(float) for c in (dataio.VOLTAGE, dataio.LOAD, dataio.FREQUENCY) if c in first}
    z = {c: (x - x.mean()) / x.std() for c, x in z.items() if np.ptp(x) > 0}
    d = first[dataio.DIRECTION].to_numpy(float)
    cols = [np.ones_like(y), d] + [x for c in z for x in (z[c], z[c] ** 2)]
    cols += [d * z[dataio.LOAD]] if dataio.LOAD in z else []
    ss = float(np.sum((y - y.mean()) ** 2))
    if not ss > 0:
        return 1.0
    X = np.column_stack(cols)
    e = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    return float(1.0 - (e @ e) / ss)


def scatter_p(df: pd.DataFrame, law: MotionLaw) -> float:
    """The p-value of the scatter of the settings of ``df``'s runs (:meth:`MotionLaw.run_settings`) against their
    noise: ``Q = sum w_r (a_r - abar)^2`` with ``w_r = 1 / se_r^2`` and ``abar`` the ``w``-weighted mean, against
    chi-square with ``n_runs - 1`` degrees of freedom. ``se_r^2 = s_r^2 / n_r (1 + rho) / (1 - rho)``: ``s_r^2`` the
    variance of the run's residual (``c - echo`` less the run's mean and, for a law with the trend, its line in time;
    ``n_r - 2`` or ``n_r - 1`` degrees of freedom), ``rho`` (at least 0) the residuals' lag-1 autocorrelation
    pooled over the runs. 1 for fewer than two runs or residuals without variance."""
    run, t = df[dataio.RUN].to_numpy(), df[dataio.TIME].to_numpy(float)
    rest = df[law.channel].to_numpy(float) - law.echo(df)
    e = within_runs(rest[:, None], run, t, law.trend)[:, 0]
    blocks = [sl for _, sl in dataio.run_slices(run)]
    blocks = [sl for sl in blocks if sl.stop - sl.start > 2]
    if len(blocks) < 2:
        return 1.0
    num = sum(float(e[sl][1:] @ e[sl][:-1]) for sl in blocks)
    den = sum(float(e[sl] @ e[sl]) for sl in blocks)
    if not den > 0:
        return 1.0
    rho = min(max(num / den, 0.0), 0.99)
    n = np.array([sl.stop - sl.start for sl in blocks], float)
    s2 = np.array([float(e[sl] @ e[sl]) for sl in blocks]) / (n - (2 if law.trend else 1))
    a = np.array([float(rest[sl].mean()) for sl in blocks])
    se2 = s2 / n * (1.0 + rho) / (1.0 - rho)
    if not np.all(se2 > 0):
        return 1.0
    w = 1.0 / se2
    q = float(np.sum(w * (a - np.sum(w * a) / np.sum(w)) ** 2))
    return float(stats.chi2.sf(q, len(blocks) - 1))


def _spread(values: np.ndarray, run) -> float:
    """The standard deviation over runs of a per-sample column's run means."""
    means = pd.Series(values).groupby(np.asarray(run), sort=False).mean().to_numpy(float)
    return float(np.std(means)) if len(means) > 1 else 0.0


def _sources(tests, response_columns, along_stroke) -> list[tuple[str, str, dict]]:
    """``(column, source, test record)`` of every column a setting is sought for: the responses the consequence test
    classed (source ``"response"``), then the columns read along the stroke (``"along_stroke"``)."""
    responses = set(response_columns)
    out = [(r["channel"], "response", r) for r in tests if r.get("response") and r["channel"] in responses]
    taken = {c for c, _, _ in out}
    return out + [(c, "along_stroke", {}) for c in along_stroke if c not in taken]


def _refusal(row: dict, rec: dict, test: pd.DataFrame | None) -> str | None:
    """Why no law is fitted to the column of ``row`` (None: one is): constant in some runs, or not logged by TEST."""
    if rec.get("runs_constant"):
        return (f"constant within {rec['runs_constant']} of TRAIN's runs: its law is the other runs' only, no "
                "setting derived")
    if test is not None and row["from"] not in test.columns:
        return "TEST does not log it: no setting derived"
    return None


def with_run_settings(train: pd.DataFrame, test: pd.DataFrame | None, tests, response_columns, along_stroke=()):
    """``(train, test, record)``: the frames with ``<column>_setting`` appended for every column that qualifies
    (module docstring): those the consequence test classed a response (``tests``:
    :func:`l1b2.closeloop.responses.response_tests`' records, ``response`` true, the column among
    ``response_columns``), then the logged columns read along the stroke (``along_stroke``). ``record`` one dict per
    such column: ``{"channel" (the derived name), "from", "source" ("response" or "along_stroke"), "derived",
    "note"}`` and, when the law was fitted, its ``history`` and ``tau_s``, ``run_spread`` (the standard deviation
    over TRAIN's runs of the settings) and ``echo_spread`` (of the runs' mean of what the motion makes of the
    column), in the column's unit, ``plan_share`` (:func:`plan_share`) and ``scatter_p`` (:func:`scatter_p`). The
    frames are returned unchanged when nothing is derived."""
    record, new_tr, new_te = [], {}, {}
    for column, source, rec in _sources(tests, response_columns, along_stroke):
        name = column + SETTING_SUFFIX
        row = {"channel": name, "from": column, "source": source, "derived": False}
        why = _refusal(row, rec, test)
        if why is not None:
            record.append({**row, "note": why})
            continue
        law = fit_motion_law(train, column, rec.get("history"), rec.get("tau_s"))
        values = law.run_settings(train)
        row.update(history=law.history, tau_s=law.tau_s, run_spread=_spread(values, train[dataio.RUN]),
                   echo_spread=_spread(law.echo(train), train[dataio.RUN]), plan_share=plan_share(train, values),
                   scatter_p=scatter_p(train, law))
        if not row["plan_share"] < PLAN_SHARE_MAX:
            record.append({**row, "note": f"the plan's inputs explain {row['plan_share']:.0%} of its run levels: "
                                          "they fix them, no setting derived"})
            continue
        if not row["scatter_p"] < SCATTER_P:
            record.append({**row, "note": f"its run levels scatter by its noise only (p {row['scatter_p']:.2g}): "
                                          "no setting derived"})
            continue
        new_tr[name] = values
        if test is not None:
            new_te[name] = law.run_settings(test)
        record.append({**row, "derived": True, "note": "the run's level less what the motion makes of it by the "
                                                       "law, TRAIN's law on TEST"})
    if not new_tr:
        return train, test, record
    train = train.assign(**new_tr)
    test = test.assign(**new_te) if test is not None else None
    return train, test, record
