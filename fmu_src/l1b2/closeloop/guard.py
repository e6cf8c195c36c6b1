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
"""

from __future__ import annotations

import warnings
from typing import Callable

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..errors import FitDivergedError, IdentificationError


#: free-run nrmse on its own training data (share of the measured speed's rms) from which a fit is broken
MAX_FIT_NRMSE = 0.5


def broken(model, df: pd.DataFrame, mask: np.ndarray) -> str | None:
    """Why ``model`` (fitted on ``df``) is broken, or None when it is usable.

    Broken: its free run on ``df`` raises a numerical error or is non-finite
    on the mask, or its free-run nrmse on the mask is at least :data:`MAX_FIT_NRMSE`.
    """
    m = np.asarray(mask, bool)
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            pred = np.asarray(model.predict_free_run(df), float)
    except (FloatingPointError, OverflowError, ValueError, np.linalg.LinAlgError) as exc:
        return f"its free run fails ({type(exc).__name__}: {' '.join(str(exc).split())})"
    e = df[dataio.SPEED].to_numpy(float)[m] - pred[m]
    bad = ~np.isfinite(e)
    if bad.any():
        return f"its free run is non-finite on {int(bad.sum())} of {len(e)} evaluated samples"
    ss = float(np.sum(df[dataio.SPEED].to_numpy(float)[m] ** 2))
    nrmse = float(np.sqrt(np.sum(e ** 2) / max(ss, 1e-300)))
    if not nrmse < MAX_FIT_NRMSE:
        return (f"its free-run nrmse on its own training data is {100 * nrmse:.1f} % "
                f"(broken from {100 * MAX_FIT_NRMSE:.0f} %)")
    return None


def checked_fit(fit: Callable[[], object], retry: Callable[[], object], df: pd.DataFrame, mask: np.ndarray,
                what: str, rescue: Callable[[], object] | None = None) -> object:
    """``fit()``, or ``retry()`` when that fails or is :func:`broken`, or ``rescue()`` (when given) when both do;
    :class:`FitDivergedError` naming every attempt's reason when all are.

    ``fit``/``retry``/``rescue``: callables returning a fitted model (an
    :class:`~l1b2.errors.IdentificationError` counts as a failure); ``what``
    names the fit in the message (e.g. ``"the baseline identification on TRAIN"``).
    """
    why = []
    for attempt in (fit, retry) + ((rescue,) if rescue is not None else ()):
        try:
            model = attempt()
        except IdentificationError as exc:
            why.append(f"failed ({' '.join(str(exc).split())})")
            continue
        reason = broken(model, df, mask)
        if reason is None:
            return model
        why.append(reason)
    rescued = f"; from the seed-free search without pins, then with them: {why[2]}" if rescue is not None else ""
    raise FitDivergedError(f"{what} diverged: {why[0]}; retried from the identifier's multistart: {why[1]}{rescued}; "
                           "no diagnosis is drawn from a broken fit (check the data's units and runs)")
