"""Logged columns that are consequences of the motion: a statistical test that classes a column a response.

A rig may log, beside the causes of the motion (a force, a temperature, a pressure), readings that the motion itself
makes: an acoustic level, a vibration, a tip-velocity amplitude, a back-EMF. Such a column follows the slider's
speed sample by sample; offered as a candidate cause it would stand in for the model, and a predictor that needs it
as an input could not predict a run before the run is made (TEST's own column carries TEST's speeds).

The test asks whether a column's variation *within runs* is a function of the measured speed's recent history. Per
run, the column's mean and its linear trend in time are removed (a run-level cause, a per-run clamp force or a
temperature, and a slow drift, a temperature that the drive heats, leave nothing else), and so is a smooth function
of the position shared by all runs (a cause that varies along the stroke, a preload or a field, is a function of the
position, which the integral of the speed also is). What is left of a cause is its own fluctuation; what is left of a
response is the course it takes while the slider accelerates from rest, runs and stops, which a smooth function of
the speed reproduces up to the column's own noise. The speed's history is ``u = h_tau * |v| / max|v|`` (a causal
first-order low-pass of time constant ``tau``, from rest at each run's start: a sensor's own averaging, a meter's
time weighting), with ``tau`` on the grid :data:`TAUS_S`, and the smooth function a cubic polynomial of ``u``
(:data:`DEGREE`) with one set of coefficients for every run (one law of the sensor). The same is done with the
signed speed ``h_tau * v / max|v|`` in place of its magnitude: a response that is even in the speed (a sound
level, an amplitude) follows the magnitude, one that is odd (a second velocity sensor, a back-EMF) changes sign with
the direction, which no function of the magnitude shared by the runs follows. A third history is the speed's rate,
``d/dt (h_tau * v) = (v - h_tau * v) / tau`` [m/s^2] (the signed speed's low-pass differentiated: the acceleration
through a first-order filter of time constant ``tau``), for a reading of the motion's changes (an accelerometer on
the slider, an inertial force), which is no function of the speed: it peaks while the slider rises from rest and is
nil at a steady speed. A sensor's filter is no single first-order lag and the measured speed's noise grows when
differentiated, so the rate enters as a bank: a linear combination of the rates at every ``tau`` of
:data:`RATE_TAUS_S`, one set of coefficients for every run (a filter of the acceleration with a fitted response;
as many parameters as the cubic's, plus one). Each history is normalised by its largest magnitude, and the best
of the three counts.

The statistic is the partial ``R^2`` of that polynomial, the share of the column's residual within-run variance it
explains (the best ``tau``). What tells a response from a column that follows the drive (a supply that sags while
the amplifier draws current, a stator's vibration, a heating) is the acceleration phase: the drive switches on at
the run's start and the slider reaches its speed only after its mechanical rise, so a consequence of the drive
moves ahead of the speed and a consequence of the motion with it or behind it. The drive's course is a fixed time
course from the run's start, ``e_tau(t) = 1 - exp(-(t - t_0 + dt) / tau)`` (``t_0`` the run's first sample, the
same grid of ``tau > 0``), either as a cubic of ``e_tau`` shared by the runs or as ``e_tau`` with an amplitude of
each run's own (the drive's settings differ between runs); its ``drive_share`` is the best of these.

The decision rule is an effect size, a comparison and a count of runs, none growing with the number of samples:

* ``share >= SHARE_MIN`` (1/2): more of the column's within-run variation is a function of the motion than not. A
  cause's within-run course is its own (its noise, its dynamics), and the speed's within-run course is dominated by
  the start transient and the stop, which the drive and the end of the stroke make and no logged cause does;
* the run's own share (the same fitted law) exceeds 1/2 in more runs than chance would give: a one-sided sign test
  over TRAIN's runs, ``P(X >= k)`` for ``X ~ Binomial(n_runs, 1/2)``, below :data:`P_MAX`;
* ``share > drive_share``: the speed explains the column better than any time course of the drive does (with the
  same three parameters, or with one per run), so the column follows the slider's own rise, not the switching on.
  A column whose own lag from the drive equals the slider's mechanical rise has the same course as the speed and
  cannot be told from a response by this test.

Columns that the model reads as inputs (the data format's drive frequency and temperature) are causes by the
model's physics and are not tested; nor are the required columns and the speed. A column constant within every run
has no within-run course and is not tested (a run-level reading is a setting or a state, not an echo of the speed).
A column constant within some runs only (a sensor switched off or gated by a setting in those runs) is tested on the
runs where it varies (:func:`active_runs`).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy.signal import lfilter

from ..data import measurements as dataio
from .auxiliary import NOT_CANDIDATES

__all__ = ["TAUS_S", "RATE_TAUS_S", "HISTORIES", "DEGREE", "SHARE_MIN", "P_MAX", "POSITION_DEGREE", "MODEL_INPUTS",
           "speed_history", "drive_course", "speed_rate", "history_basis", "history_columns", "within_runs",
           "position_basis", "position_span", "speed_histories", "response_statistic",
           "active_runs", "response_tests", "classed_responses"]

#: the sensor time constants [s] searched: none (the instantaneous speed), then 10 ms to 0.3 s (a meter's fast
#: time weighting is 125 ms; longer than the longest runs' acceleration, no transient is left to follow)
TAUS_S = (0.0, 0.01, 0.03, 0.1, 0.3)
#: the time constants [s] of the speed's rate bank (:func:`speed_rate`): the grid of :data:`TAUS_S` continued down
#: to 1 ms (a rate needs a filter: the bank's lags span 5 Hz to 160 Hz)
RATE_TAUS_S = (0.001, 0.003, 0.01, 0.03)
#: the speed's histories the test reads: its magnitude, the signed speed (each a cubic, on :data:`TAUS_S`) and the
#: signed speed's rate (the bank of :data:`RATE_TAUS_S`)
HISTORIES = ("magnitude", "signed", "rate")
#: the degree of the polynomial in the speed's history (a level in dB of a power ~ v^2, an amplitude ~ v: smooth)
DEGREE = 3
#: the degree of the Legendre polynomial in the position (over TRAIN's stroke) removed as a cause along the stroke
POSITION_DEGREE = 6
#: the smallest share of the residual within-run variance the speed must explain for a response
SHARE_MIN = 0.5
#: the largest one-sided sign-test p-value over runs for a response
P_MAX = 0.01
#: logged columns the model reads as inputs: causes by the model's physics, never tested
MODEL_INPUTS = frozenset({dataio.FREQUENCY, dataio.TEMPERATURE})


def speed_history(speed_m_s, time_s, run, tau_s: float, signed: bool = False) -> np.ndarray:
    """``h_tau * |v|`` per run [m/s]: the speed's magnitude (``signed``: the speed itself) through a causal
    first-order low-pass of time constant ``tau_s`` [s] (0: unchanged), its state 0 (at rest) at each run's start,
    stepped at the run's median sample interval (``y_i = y_(i-1) + (1 - exp(-dt/tau)) (|v_i| - y_(i-1))``)."""
    v = np.asarray(speed_m_s, float) if signed else np.abs(np.asarray(speed_m_s, float))
    if tau_s <= 0:
        return v
    t = np.asarray(time_s, float)
    blocks = [sl for _, sl in dataio.run_slices(run)]
    out = np.empty_like(v)
    for sl in blocks:
        dt = float(np.median(np.diff(t[sl]))) if sl.stop - sl.start > 1 else 0.0
        a = 1.0 - math.exp(-dt / tau_s) if dt > 0 else 1.0
        out[sl] = lfilter([a], [1.0, a - 1.0], v[sl])
    return out


def speed_rate(speed_m_s, time_s, run, tau_s: float) -> np.ndarray:
    """``(v - h_tau * v) / tau`` per run [m/s^2]: the rate of the signed speed's first-order low-pass of time
    constant ``tau_s`` [s] (> 0; :func:`speed_history` with ``signed``), the derivative ``dy/dt = (v - y) / tau`` of
    the filter's output: the acceleration read through that filter, from rest at each run's start."""
    if not tau_s > 0:
        raise ValueError(f"speed_rate: the time constant {tau_s} s is not positive")
    v = np.asarray(speed_m_s, float)
    return (v - speed_history(v, time_s, run, tau_s, signed=True)) / tau_s


def history_basis(speed_m_s, time_s, run, history: str, tau_s: float | None = None, scale=None):
    """``(columns, scale)``: the columns of a history of :data:`HISTORIES` [1] and the scale they were divided by.
    ``u``, ``u^2``, ``u^3`` of the speed's magnitude or the signed speed through the low-pass of ``tau_s``
    (:func:`speed_history`), ``u`` over ``scale`` (a 1-tuple); for ``rate``, the bank: :func:`speed_rate` at every
    ``tau`` of :data:`RATE_TAUS_S`, each over its entry of ``scale`` (``tau_s`` unused). ``scale`` None: each
    column's own largest magnitude (1 for a column of zeros), the scale another frame's columns are then put on."""
    if history == "rate":
        raw = np.column_stack([speed_rate(speed_m_s, time_s, run, tau) for tau in RATE_TAUS_S])
    elif history in HISTORIES:
        raw = speed_history(speed_m_s, time_s, run, tau_s, signed=history == "signed")[:, None]
    else:
        raise ValueError(f"history {history!r} is not one of {', '.join(HISTORIES)}")
    if scale is None:
        top = np.max(np.abs(raw), axis=0) if len(raw) else np.ones(raw.shape[1])
        scale = tuple(float(x) if x > 0 else 1.0 for x in top)
    a = raw / np.asarray(scale, float)
    return (a if history == "rate" else np.vander(a[:, 0], DEGREE + 1, increasing=True)[:, 1:]), tuple(scale)


def history_columns(speed_m_s, time_s, run, history: str, tau_s: float | None = None) -> np.ndarray:
    """The columns of a history of :data:`HISTORIES` [1], each history over its own largest magnitude
    (:func:`history_basis`)."""
    return history_basis(speed_m_s, time_s, run, history, tau_s)[0]


def within_runs(A: np.ndarray, run, time_s, trend: bool = True) -> np.ndarray:
    """``A`` (columns) with each run's mean and least-squares line in ``time_s`` removed (runs in consecutive
    blocks; ``trend`` False: the mean only)."""
    t = np.asarray(time_s, float)
    out = np.array(A, float)
    for _, sl in dataio.run_slices(np.asarray(run)):
        tt = t[sl] - t[sl].mean()
        out[sl] -= out[sl].mean(axis=0)
        ss = tt @ tt
        if trend and ss > 0:
            out[sl] -= np.outer(tt, tt @ out[sl] / ss)
    return out


def _nuisance_residual(X: np.ndarray, run: np.ndarray, t: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``X`` (columns) with each run's mean and linear trend in ``t`` removed, then the shared position basis ``P``
    (itself so residualised) projected out: the residual of the least-squares fit on both."""
    R, Pr = within_runs(X, run, t), within_runs(P, run, t)
    Q, _ = np.linalg.qr(Pr)
    return R - Q @ (Q.T @ R)


def drive_course(time_s, run, tau_s: float) -> np.ndarray:
    """``1 - exp(-(t - t_0 + dt) / tau)`` per run [1]: the course of a first-order consequence of the drive switched
    on at the run's first sample ``t_0`` (``dt`` the run's median sample interval: the first sample one step in)."""
    t = np.asarray(time_s, float)
    blocks = [sl for _, sl in dataio.run_slices(run)]
    out = np.empty_like(t)
    for sl in blocks:
        dt = float(np.median(np.diff(t[sl]))) if sl.stop - sl.start > 1 else 0.0
        out[sl] = 1.0 - np.exp(-(t[sl] - t[sl.start] + dt) / tau_s)
    return out


def _share(X: np.ndarray, cr: np.ndarray, ss_tot: float) -> tuple[float, np.ndarray]:
    """The share of ``cr``'s sum of squares that the least-squares fit on ``X`` explains, and the fit's residual."""
    beta, *_ = np.linalg.lstsq(X, cr, rcond=None)
    e = cr - X @ beta
    return 1.0 - float(e @ e) / ss_tot, e


def _per_run_share(x: np.ndarray, cr: np.ndarray, Pr: np.ndarray, blocks: list[slice], ss_tot: float) -> float:
    """The share of ``cr``'s sum of squares explained by ``x`` with one coefficient per run and the shared columns
    ``Pr`` (all three already free of each run's mean and trend): the coefficients per run profiled out run by run
    (``M_r = I - x_r x_r^T / |x_r|^2``), the shared ones from ``sum P_r^T M_r P_r g = sum P_r^T M_r c_r``, in memory
    linear in the samples."""
    def m(run_x, a):
        xx = float(run_x @ run_x)
        return a - np.outer(run_x, run_x @ a) / xx if xx > 0 else a
    A = np.zeros((Pr.shape[1], Pr.shape[1]))
    y = np.zeros(Pr.shape[1])
    for sl in blocks:
        MP = m(x[sl], Pr[sl])
        A += MP.T @ MP
        y += MP.T @ cr[sl]
    g = np.linalg.lstsq(A, y, rcond=None)[0]
    ss = sum(float(np.sum(m(x[sl], (cr[sl] - Pr[sl] @ g)[:, None]) ** 2)) for sl in blocks)
    return 1.0 - ss / ss_tot


def _drive_share(cr, ss_tot, run, t, P) -> tuple[float, float | None]:
    """The best share of the drive's courses (:func:`drive_course`, a shared cubic or one amplitude per run) over
    the ``tau > 0`` of :data:`TAUS_S`, and its ``tau``."""
    blocks = [sl for _, sl in dataio.run_slices(run)]
    zero = np.zeros((len(t), 0))
    Pr = _nuisance_residual(P, run, t, zero)
    best = (0.0, None)
    for tau in TAUS_S[1:]:
        e = drive_course(t, run, tau)
        shared, _ = _share(_nuisance_residual(np.vander(e, DEGREE + 1, increasing=True)[:, 1:], run, t, P), cr,
                           ss_tot)
        per_run = _per_run_share(_nuisance_residual(e[:, None], run, t, zero)[:, 0], cr, Pr, blocks, ss_tot)
        for share in (shared, per_run):
            if share > best[0]:
                best = (share, tau)
    return best


def _sign_test_p(k: int, n: int) -> float:
    """``P(X >= k)`` for ``X ~ Binomial(n, 1/2)``."""
    return float(sum(math.comb(n, j) for j in range(k, n + 1)) / 2.0 ** n) if n else 1.0


def position_basis(position_m, span=None) -> np.ndarray:
    """The Legendre polynomials of degree 1 to :data:`POSITION_DEGREE` of the position over ``span`` (``(lowest,
    range)`` [m]; None: the position's own, :func:`position_span`) as columns."""
    s = np.asarray(position_m, float)
    lo, width = position_span(s) if span is None else span
    z = 2.0 * (s - lo) / width - 1.0
    return np.polynomial.legendre.legvander(z, POSITION_DEGREE)[:, 1:]


def position_span(position_m) -> tuple[float, float]:
    """``(lowest, range)`` [m] of the positions (a range of 0 read as 1 m)."""
    s = np.asarray(position_m, float)
    return float(s.min()), float(np.ptp(s)) or 1.0


def speed_histories(speed_m_s, time_s, position_m, run) -> list[tuple[str, float | None, np.ndarray]]:
    """Every history the test reads (:func:`history_columns` of each of :data:`HISTORIES`, at each of
    :data:`TAUS_S`, the rate's once), its columns free of each run's mean and linear trend in time and of the
    position's polynomials: ``(history, tau_s, columns)`` in the test's order. They depend on the motion only, so
    one computation serves every column of a frame (:func:`response_statistic`'s ``histories``)."""
    run = np.asarray(run)
    t = np.asarray(time_s, float)
    P = position_basis(position_m)
    return [(history, tau, _nuisance_residual(history_columns(speed_m_s, t, run, history, tau), run, t, P))
            for history in HISTORIES for tau in ((None,) if history == "rate" else TAUS_S)]


def response_statistic(column, speed_m_s, time_s, position_m, run, histories=None) -> dict:
    """The test of one column (arrays over the same samples, runs in consecutive blocks): ``{"share", "tau_s",
    "signed", "history", "runs_above", "n_runs", "p_value", "drive_share", "drive_tau_s", "response"}``; ``share``
    the partial R^2 of the module docstring at the best ``tau_s`` and history (``history``: one of
    :data:`HISTORIES`, the rate's ``tau_s`` None: its bank spans :data:`RATE_TAUS_S`; ``signed``: of the signed
    speed or its rate, else of its magnitude; both None when nothing is explained), ``runs_above`` the runs whose
    own share (same fitted law) exceeds :data:`SHARE_MIN`, ``p_value`` the sign test's, ``drive_share`` the
    drive's best share (computed only when the first two conditions hold; 0 otherwise), ``response`` the rule
    (``share >= SHARE_MIN``, ``p_value < P_MAX`` and ``share > drive_share``). ``histories``: the frame's
    :func:`speed_histories` when already computed (the same for every column), else computed here."""
    c = np.asarray(column, float)
    run = np.asarray(run)
    t = np.asarray(time_s, float)
    P = position_basis(position_m)
    cr = _nuisance_residual(c[:, None], run, t, P)[:, 0]
    blocks = [sl for _, sl in dataio.run_slices(run)]
    n_runs = len(blocks)
    ss_tot = float(cr @ cr)
    best = {"share": 0.0, "tau_s": None, "signed": None, "history": None, "runs_above": 0, "n_runs": n_runs,
            "p_value": 1.0, "drive_share": 0.0, "drive_tau_s": None, "response": False}
    if not ss_tot > 1e-12 * max(float(c @ c), 1e-300):
        return best
    for history, tau, Xr in speed_histories(speed_m_s, t, position_m, run) if histories is None else histories:
        share, e = _share(Xr, cr, ss_tot)
        if share > best["share"]:
            per = [1.0 - float(e[sl] @ e[sl]) / float(cr[sl] @ cr[sl])
                   for sl in blocks if float(cr[sl] @ cr[sl]) > 0]
            k = int(np.sum(np.array(per) > SHARE_MIN))
            best.update(share=share, tau_s=tau, signed=history != "magnitude", history=history, runs_above=k,
                        p_value=_sign_test_p(k, n_runs))
    if best["share"] >= SHARE_MIN and best["p_value"] < P_MAX:
        best["drive_share"], best["drive_tau_s"] = _drive_share(cr, ss_tot, run, t, P)
        best["response"] = bool(best["share"] > best["drive_share"])
    return best


def active_runs(df: pd.DataFrame, name: str) -> np.ndarray:
    """The run ids of ``df`` (in order of appearance) inside which the numeric column ``name`` takes more than one
    value: where it has a within-run course."""
    ptp = df.groupby(dataio.RUN, sort=False)[name].agg(np.ptp)
    return ptp.index[ptp.to_numpy(float) > 0].to_numpy()


def response_tests(df: pd.DataFrame, named=()) -> list[dict]:
    """The test of every numeric, finite column of ``df`` beyond the required ones, the speed, the named responses
    ``named`` and the model's inputs (:data:`MODEL_INPUTS`) that varies within some run: one ``{"channel", **``
    :func:`response_statistic` ``, "runs_constant"}`` each, in column order.

    A column is tested on the runs in which it varies (:func:`active_runs`): a sensor that is silent or held in
    some runs (switched off, gated by a setting) has no within-run course there, and a law shared by the runs
    cannot be asked to give a constant from a speed that moves. ``n_runs`` counts the runs tested and
    ``runs_constant`` the others; with every run active the test reads the whole frame."""
    skip = NOT_CANDIDATES | MODEL_INPUTS | set(named)
    out = []
    histories: dict = {}
    n_all = df[dataio.RUN].nunique()
    for name in df.columns:
        if name in skip or not pd.api.types.is_numeric_dtype(df[name]) or pd.api.types.is_bool_dtype(df[name]):
            continue
        if not np.all(np.isfinite(df[name].to_numpy(float))):
            continue
        runs = active_runs(df, name)
        if not len(runs):       # constant within every run: no within-run course
            continue
        key, sub = (None, df) if len(runs) == n_all else (tuple(runs), df[df[dataio.RUN].isin(runs)])
        if key not in histories:
            histories[key] = speed_histories(sub[dataio.SPEED], sub[dataio.TIME], sub[dataio.POSITION],
                                             sub[dataio.RUN])
        rec = response_statistic(sub[name].to_numpy(float), sub[dataio.SPEED], sub[dataio.TIME],
                                 sub[dataio.POSITION], sub[dataio.RUN], histories[key])
        out.append({"channel": str(name), **rec, "runs_constant": int(n_all - len(runs))})
    return out


def classed_responses(explicit, default, tests) -> tuple:
    """The responses the loop uses: ``explicit`` (the user's setting, a tuple) when given, which wins over the test;
    otherwise the ``default`` names and every column ``tests`` (:func:`response_tests`) classes a response."""
    if explicit is not None:
        return tuple(explicit)
    return tuple(default) + tuple(r["channel"] for r in tests if r["response"] and r["channel"] not in default)


def with_applied(tests, explicit, responses) -> list[dict]:
    """``diagnosis.response_test``: each record of :func:`response_tests` with ``applied`` (the column is among the
    loop's ``responses``, so never a candidate) and ``decided_by`` (``"setting"``: the user's explicit
    ``response_columns`` decided, the test is reported only; ``"test"``: the test's rule decided)."""
    by = "setting" if explicit is not None else "test"
    return [{**r, "applied": r["channel"] in set(responses), "decided_by": by} for r in tests]
