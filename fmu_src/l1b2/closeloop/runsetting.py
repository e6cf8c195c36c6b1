"""The run's setting that a response column carries beside the speed's echo.

A logged column the consequence test classes a response of the motion (:mod:`l1b2.closeloop.responses`) is never a
candidate: it follows the speed within runs, and read as a cause it would stand in for the model with TEST's own
speeds. A reading can be part echo, part setting: the current of a voice coil driven by a voltage set per run,
``i = (u - K v) / R``, carries the speed's back-EMF ``K v / R`` within the run and the amplifier's setting ``u / R``
in its level; a pressure behind a bellows carries the slider's pumping and the supply's setting. The test's law says
what the motion makes of the column; what it leaves in each run's level is the run's own.

**The law** is the test's, fitted by least squares on TRAIN over every run::

    c = X(v) beta + P(s) gamma + a_r + b_r (t - tbar_r) + e

``X`` the history of the test's best fit (its ``history`` and ``tau_s``, :func:`l1b2.closeloop.responses.history_basis`
on TRAIN's scale), ``P`` the position's polynomials over TRAIN's stroke
(:func:`l1b2.closeloop.responses.position_basis`), ``a_r`` and ``b_r`` each run's level and trend (``tbar_r`` the
run's mean time): ``beta`` and ``gamma`` come from the fit of the within-run residuals (each run's mean and line in
time removed from the column and from ``X`` and ``P``), the same fit by the Frisch-Waugh theorem.

**The run's setting** is ``a_r``, the run's mean of ``c - X beta - P gamma`` (the trend is centred on ``tbar_r``), in
the column's unit: the derived channel ``<column>_setting`` (:data:`l1b2.units.SETTING_SUFFIX`), constant within each
run, a logged channel like any setting (offered with the generic forms and as a run-level signal). TEST's runs get
theirs from TRAIN's law (``beta``, ``gamma``, the history's scale and the stroke's span) applied to TEST's column and
measured speed: the run's setting as the reading carries it. When the law is exact it holds nothing of the speed;
what it holds of the speed is the law's misfit, which the loop's acceptance weighs like any candidate's.

**What the plan fixes is no setting.** A reading whose level follows the drive amplitude (a sound level, a sensor's
gain drift with the supply) leaves run levels that the plan's inputs fix, up to the law's misfit of the speed's
echo, which is itself a function of the run's speed: read as a cause, it would carry TEST's own speed into the
prediction. So the settings are kept only when the plan's inputs explain less than :data:`PLAN_SHARE_MAX` of their
variance over TRAIN's runs (:func:`plan_share`: a least-squares fit on the standardised drive amplitude, load and
drive frequency, each with its square, the direction and the direction times the load), as a logged setting that
only relabels the plan is offered nothing (:mod:`l1b2.closeloop.relabels`).

It is derived for every column the test classed a response (``response`` true and among the loop's responses; not
for the named responses of the default list or of the user's setting, which no law was fitted to), that varies in
every run of TRAIN (a column constant in some runs was tested on the others only), that TEST logs when a TEST is
given and whose settings the plan does not fix. Each is recorded (:func:`with_response_settings`), derived or not
and why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..units import SETTING_SUFFIX
from .responses import history_basis, position_basis, position_span, within_runs

__all__ = ["PLAN_SHARE_MAX", "ResponseLaw", "fit_response_law", "plan_share", "with_response_settings"]

#: the largest share of the settings' variance over TRAIN's runs that the plan's inputs may explain for the settings
#: to be derived (more than half of it is the runs' own)
PLAN_SHARE_MAX = 0.5


@dataclass(frozen=True)
class ResponseLaw:
    """The law of a response column fitted on TRAIN (module docstring): the column's ``channel``, the speed's
    ``history`` and its ``tau_s`` [s] (None for the rate's bank), the history's ``scale`` (the divisors of its columns,
    TRAIN's largest magnitudes), the position's ``span`` (``(lowest, range)`` [m] of TRAIN's stroke), and the
    coefficients ``beta`` (of the history's columns) and ``gamma`` (of the position's polynomials), in the column's
    unit."""

    channel: str
    history: str
    tau_s: float | None
    scale: tuple
    span: tuple
    beta: tuple
    gamma: tuple

    def echo(self, df: pd.DataFrame) -> np.ndarray:
        """``X beta + P gamma`` on the samples of ``df`` [the column's unit]: what the motion makes of the column by
        the law, with TRAIN's scale and span."""
        X, _ = history_basis(df[dataio.SPEED].to_numpy(float), df[dataio.TIME].to_numpy(float),
                             df[dataio.RUN].to_numpy(), self.history, self.tau_s, self.scale)
        P = position_basis(df[dataio.POSITION].to_numpy(float), self.span)
        return X @ np.asarray(self.beta, float) + P @ np.asarray(self.gamma, float)

    def run_settings(self, df: pd.DataFrame) -> np.ndarray:
        """Each sample's run mean of ``c - echo`` [the column's unit]: the run's setting, constant within each run."""
        rest = df[self.channel].to_numpy(float) - self.echo(df)
        return pd.Series(rest).groupby(df[dataio.RUN].to_numpy(), sort=False).transform("mean").to_numpy(float)


def fit_response_law(df: pd.DataFrame, channel: str, history: str, tau_s: float | None) -> ResponseLaw:
    """The law of column ``channel`` of ``df`` (TRAIN, runs in consecutive blocks) with the speed's ``history`` at
    ``tau_s`` [s], fitted by least squares on the within-run residuals (module docstring)."""
    run, t = df[dataio.RUN].to_numpy(), df[dataio.TIME].to_numpy(float)
    X, scale = history_basis(df[dataio.SPEED].to_numpy(float), t, run, history, tau_s)
    s = df[dataio.POSITION].to_numpy(float)
    span = position_span(s)
    A = within_runs(np.column_stack([X, position_basis(s, span)]), run, t)
    c = within_runs(df[channel].to_numpy(float)[:, None], run, t)[:, 0]
    coef = np.linalg.lstsq(A, c, rcond=None)[0]
    k = X.shape[1]
    return ResponseLaw(channel=str(channel), history=history, tau_s=tau_s, scale=tuple(scale), span=span,
                       beta=tuple(float(b) for b in coef[:k]), gamma=tuple(float(g) for g in coef[k:]))


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


def _spread(values: np.ndarray, run) -> float:
    """The standard deviation over runs of a per-sample column's run means."""
    means = pd.Series(values).groupby(np.asarray(run), sort=False).mean().to_numpy(float)
    return float(np.std(means)) if len(means) > 1 else 0.0


def with_response_settings(train: pd.DataFrame, test: pd.DataFrame | None, tests, response_columns):
    """``(train, test, record)``: the frames with ``<column>_setting`` appended for every column that the consequence
    test classed a response (``tests``: :func:`l1b2.closeloop.responses.response_tests`' records, ``response`` true,
    the column among ``response_columns``) and that qualifies (module docstring); ``record`` one dict per such
    column: ``{"channel" (the derived name), "from", "derived", "note"}`` and, when the law was fitted, its
    ``history`` and ``tau_s``, ``run_spread`` (the standard deviation over TRAIN's runs of the settings) and
    ``echo_spread`` (of the runs' mean echo), in the column's unit, and ``plan_share`` (:func:`plan_share`). The frames are returned unchanged when nothing is derived."""
    record, new_tr, new_te = [], {}, {}
    responses = set(response_columns)
    for rec in tests:
        column = rec["channel"]
        if not rec.get("response") or column not in responses:
            continue
        name = column + SETTING_SUFFIX
        row = {"channel": name, "from": column, "derived": False}
        if rec.get("runs_constant"):
            record.append({**row, "note": f"constant within {rec['runs_constant']} of TRAIN's runs: its law is "
                                          "the other runs' only, no setting derived"})
            continue
        if test is not None and column not in test.columns:
            record.append({**row, "note": "TEST does not log it: no setting derived"})
            continue
        law = fit_response_law(train, column, rec["history"], rec["tau_s"])
        values = law.run_settings(train)
        row.update(history=law.history, tau_s=law.tau_s, run_spread=_spread(values, train[dataio.RUN]),
                   echo_spread=_spread(law.echo(train), train[dataio.RUN]), plan_share=plan_share(train, values))
        if not row["plan_share"] < PLAN_SHARE_MAX:
            record.append({**row, "note": f"the plan's inputs explain {row['plan_share']:.0%} of its run levels: "
                                          "they fix them, no setting derived"})
            continue
        new_tr[name] = values
        if test is not None:
            new_te[name] = law.run_settings(test)
        record.append({**row, "derived": True, "note": "the run's level less the speed's echo by the consequence "
                                                       "test's law, TRAIN's law on TEST"})
    if not new_tr:
        return train, test, record
    train = train.assign(**new_tr)
    test = test.assign(**new_te) if test is not None else None
    return train, test, record
