"""A fit that fails says so: the close-the-loop identifications are checked before anything is drawn from them.

A fitted model is *broken* (:func:`broken`) when its free run on the data it
was fitted to is non-finite, or when its free-run nrmse there (on the
evaluation mask) is at least :data:`MAX_FIT_NRMSE`: a model that misses half
the measured speed's rms on its own training data has not fitted (an
overflowing recursion, a search that left the basin: the diverged baselines
seen so far had 97 % held-out error), whatever its likelihood said.
:func:`checked_fit` fits, checks, retries once from the identifier's
multistart (and, when given, once more by a rescue: the seed-free search of
the identifier without pins, continued with the pins) and raises
:class:`~l1b2.errors.FitDivergedError` when every attempt is broken (or
fails outright).

A usable fit can still sit in a wrong basin of the multi-modal likelihood. A
fit is *below the level law* (:func:`level_law_nrmse`) when its free-run nrmse
on its training data is above that of an affine law of the runs' speed levels
in V0 and the load: a motor model that predicts the runs worse than the
simplest form of its own steady state has missed what Eq. 29 is about. Then
:func:`checked_fit` searches again by the rescue (when given) and keeps the fit
of the higher log-likelihood (:func:`better`); ``record`` says what was
compared.
"""

from __future__ import annotations

import warnings
from typing import Callable

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..data.metrics import level_law_nrmse
from ..errors import FitDivergedError, IdentificationError


#: free-run nrmse on its own training data (share of the measured speed's rms) from which a fit is broken
MAX_FIT_NRMSE = 0.5


def free_run_nrmse(model, df: pd.DataFrame, mask: np.ndarray) -> tuple[float, str | None]:
    """``(nrmse, why)``: the free-run nrmse of ``model`` on ``df`` over ``mask`` (share of the measured speed's rms),
    or ``(nan, why)`` when its free run raises a numerical error or is non-finite on the mask."""
    m = np.asarray(mask, bool)
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            pred = np.asarray(model.predict_free_run(df), float)
    except (FloatingPointError, OverflowError, ValueError, np.linalg.LinAlgError) as exc:
        return float("nan"), f"its free run fails ({type(exc).__name__}: {' '.join(str(exc).split())})"
    e = df[dataio.SPEED].to_numpy(float)[m] - pred[m]
    bad = ~np.isfinite(e)
    if bad.any():
        return float("nan"), f"its free run is non-finite on {int(bad.sum())} of {len(e)} evaluated samples"
    ss = float(np.sum(df[dataio.SPEED].to_numpy(float)[m] ** 2))
    return float(np.sqrt(np.sum(e ** 2) / max(ss, 1e-300))), None


def broken(model, df: pd.DataFrame, mask: np.ndarray) -> str | None:
    """Why ``model`` (fitted on ``df``) is broken, or None when it is usable.

    Broken: its free run on ``df`` raises a numerical error or is non-finite
    on the mask, or its free-run nrmse on the mask is at least :data:`MAX_FIT_NRMSE`.
    """
    return _why_broken(*free_run_nrmse(model, df, mask))


def _why_broken(nrmse: float, why: str | None) -> str | None:
    """:func:`broken`'s answer from :func:`free_run_nrmse`'s ``(nrmse, why)``."""
    if why is not None:
        return why
    if not nrmse < MAX_FIT_NRMSE:
        return (f"its free-run nrmse on its own training data is {100 * nrmse:.1f} % "
                f"(broken from {100 * MAX_FIT_NRMSE:.0f} %)")
    return None


def _loglik(model) -> float:
    result = getattr(model, "result_", None)
    return float(getattr(result, "loglik", float("nan")))


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def better(first, second, df: pd.DataFrame, mask: np.ndarray) -> bool:
    """Whether ``second`` is the better fit of the same data than ``first``: the higher log-likelihood when
    both are fitted identifiers (``result_.loglik``), else the lower free-run nrmse on ``mask``; an unusable
    ``second`` (:func:`broken`) never is."""
    return _prefers_second(first, second, free_run_nrmse(first, df, mask)[0], free_run_nrmse(second, df, mask)[0])


def _prefers_second(first, second, first_nrmse: float, second_nrmse: float) -> bool:
    """:func:`better` given both fits' free-run nrmse on the mask (NaN: the free run failed)."""
    if not second_nrmse < MAX_FIT_NRMSE:
        return False
    a, b = _loglik(first), _loglik(second)
    if np.isfinite(a) and np.isfinite(b):
        return b > a
    return second_nrmse < first_nrmse


def checked_fit(fit: Callable[[], object], retry: Callable[[], object], df: pd.DataFrame, mask: np.ndarray,
                what: str, rescue: Callable[[], object] | None = None, record: dict | None = None) -> object:
    """``fit()``, or ``retry()`` when that fails or is :func:`broken`, or ``rescue()`` (when given) when both do;
    :class:`FitDivergedError` naming every attempt's reason when all are.

    A usable ``fit()`` or ``retry()`` whose free-run nrmse on ``mask`` is above :func:`level_law_nrmse` is compared
    with ``rescue()`` (when given) and the better (:func:`better`) is returned; a rescue that fails outright
    leaves the first. ``record`` (a dict, filled when given): ``train_free_run_nrmse`` (of the first usable
    fit), ``level_law_nrmse``, ``searched_again`` and, when it did, ``loglik`` of both and ``kept``
    (``"first"`` or ``"rescue"``).

    ``fit``/``retry``/``rescue``: callables returning a fitted model (an
    :class:`~l1b2.errors.IdentificationError` counts as a failure); ``what``
    names the fit in the message (e.g. ``"the baseline identification on TRAIN"``).
    """
    why = []
    record = {} if record is None else record
    for i, attempt in enumerate((fit, retry) + ((rescue,) if rescue is not None else ())):
        try:
            model = attempt()
        except IdentificationError as exc:
            why.append(f"failed ({' '.join(str(exc).split())})")
            continue
        nrmse, failed = free_run_nrmse(model, df, mask)
        reason = _why_broken(nrmse, failed)
        if reason is None:
            return model if i == 2 else _against_level_law(model, nrmse, rescue, df, mask, record)
        why.append(reason)
    rescued = f"; from the seed-free search without pins, then with them: {why[2]}" if rescue is not None else ""
    raise FitDivergedError(f"{what} diverged: {why[0]}; retried from the identifier's multistart: {why[1]}{rescued}; "
                           "no diagnosis is drawn from a broken fit (check the data's units and runs)")


def checked_identification(identify: Callable[..., object], df: pd.DataFrame, mask: np.ndarray, what: str,
                           record: dict | None = None) -> object:
    """:func:`checked_fit` of one identification by its three searches: ``identify()`` (the multistart),
    ``identify(retry=True)`` (more starts, another seed) and ``identify(rescue=True)`` (the seed-free search
    without pins, continued with the pins)."""
    return checked_fit(identify, lambda: identify(retry=True), df, mask, what, lambda: identify(rescue=True), record)


def _against_level_law(model, nrmse: float, rescue, df, mask, record: dict):
    """``model`` (its free-run nrmse on ``mask``: ``nrmse``), or ``rescue()`` when ``model`` is below the level law
    and the rescue is :func:`better`."""
    law = level_law_nrmse(df, mask)
    again = rescue is not None and nrmse > law
    record.update(train_free_run_nrmse=_finite(nrmse), level_law_nrmse=law, searched_again=bool(again))
    if not again:
        return model
    try:
        other = rescue()
    except IdentificationError as exc:
        record.update(kept="first", rescue_failed=" ".join(str(exc).split()))
        return model
    other_nrmse = free_run_nrmse(other, df, mask)[0]
    keep = _prefers_second(model, other, nrmse, other_nrmse)
    record.update(loglik={"first": _finite(_loglik(model)), "rescue": _finite(_loglik(other))},
                  rescue_train_free_run_nrmse=_finite(other_nrmse), kept="rescue" if keep else "first")
    return other if keep else model
