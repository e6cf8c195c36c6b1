"""Coarse-to-fine identification of data sampled faster than the model needs (a fast DAQ).

The predictor is a recursion over the logged samples with the logged time steps (Eq. 29 discretised
with each sample's own ``dt``), so the same parameters predict the same motor from every
``q``-th sample of each run. On a file sampled at 5 kHz the multistart search spends most of its
evaluations far from the optimum, where one sample per millisecond locates the basin as well as
five do. :func:`coarse_to_fine` runs the identifier's whole search on the decimated copy
(:func:`decimate`: every ``q``-th sample of each run, ``q`` from :func:`decimation`), then one
warm local search on all samples from its optimum (the identifier with ``init`` and
``n_starts=1``: the same likelihood and stopping rules, few evaluations). The number
of full-data evaluations then no longer grows with the sampling rate.

The warm search is the identifier's own (same solver, same likelihood); decision 0028 records
the measured search variants and why this one is used.

:data:`COARSE_PERIOD_S` is 1 ms: the virtual rig's default rate, at which every identification of
this package was developed and measured (``docs/decisions/0027-...``: the same diagnosis at 1 and
5 kHz). Data sampled at 2 ms or slower are fitted as given.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from .estimator import clone
from .frequency import resolve as resolve_frequency

__all__ = ["COARSE_PERIOD_S", "decimation", "every_qth", "decimate", "coarse_to_fine", "nfev_of"]

#: the sampling period of the coarse stage [s] (one sample per millisecond)
COARSE_PERIOD_S = 1e-3


def _frame(data) -> pd.DataFrame:
    return data.df if isinstance(data, dataio.Measurements) else data


def decimation(data, period_s: float = COARSE_PERIOD_S) -> int:
    """Samples per ``period_s`` in ``data`` (a frame or Measurements): ``floor(period_s / T_s)``, at least 1.

    ``T_s`` is the median time step within runs; 1 when it is not finite or not positive.
    """
    df = _frame(data)
    t = df[dataio.TIME].to_numpy(float)
    run = df[dataio.RUN].to_numpy()
    same = run[1:] == run[:-1]
    dts = np.diff(t)[same]
    ts = float(np.median(dts)) if dts.size else float("nan")
    if not (math.isfinite(ts) and ts > 0):
        return 1
    return max(1, int(math.floor(period_s / ts * (1 + 1e-9))))


def every_qth(run, q: int) -> np.ndarray:
    """Which samples are every ``q``-th of their run (its first always kept; runs in consecutive blocks): a
    boolean array over ``run``'s samples, all True for ``q <= 1``."""
    run = np.asarray(run)
    if q <= 1:
        return np.ones(len(run), bool)
    new_run = np.r_[True, run[1:] != run[:-1]]
    start = np.maximum.accumulate(np.where(new_run, np.arange(len(run)), 0))
    return (np.arange(len(run)) - start) % q == 0


def decimate(df: pd.DataFrame, mask, q: int) -> tuple[pd.DataFrame, np.ndarray]:
    """Every ``q``-th sample of each run (its first always kept, :func:`every_qth`), and the mask on those samples.

    The rows keep their order and values (time, position, speed as logged); the index is renumbered.
    ``q = 1`` returns the frame and mask unchanged.
    """
    mask = np.asarray(mask, bool)
    if q <= 1:
        return df, mask
    keep = every_qth(df[dataio.RUN].to_numpy(), q)
    return df.loc[keep].reset_index(drop=True), mask[keep]


def coarse_to_fine(est, data, slider_mass_kg=None, mask=None, period_s: float = COARSE_PERIOD_S):
    """Fit ``est`` (an unfitted :class:`~l1b2.ident.estimator.PredictorIdentifier`) coarse to fine; returns it.

    With ``q = decimation(data, period_s) >= 2``, no warm start (``init``) and no drive-frequency response
    to estimate: the identifier's search on :func:`decimate` ``(data, mask, q)``, then one warm local
    search on all samples from that optimum (``init``, ``init_extra``: the coarse fit's; ``n_starts=1``).
    Otherwise ``est.fit(data, slider_mass_kg, mask)``, unchanged. The fitted identifier is the fine
    stage's, with every setting of ``est`` but ``init``/``n_starts``; its ``coarse_`` attribute records
    ``{"decimation", "samples", "nfev", "cpu_s", "loglik"}`` of the coarse stage (log-likelihood on the
    decimated samples), or None when there was none. ``nfev_of(fitted)`` counts both stages.
    """
    if isinstance(data, dataio.Measurements):
        slider_mass_kg = data.slider_mass_kg if slider_mass_kg is None else slider_mass_kg
        mask = data.mask if mask is None else mask
    df = _frame(data)
    mask = np.ones(len(df), bool) if mask is None else np.asarray(mask, bool)
    q = decimation(df, period_s)
    if q < 2 or est.init is not None or resolve_frequency(est, data)[2]:
        est.fit(data, slider_mass_kg, mask)
        est.coarse_ = None
        return est
    c0 = time.process_time()
    sub, sub_mask = decimate(df, mask, q)
    coarse = clone(est).fit(dataio.Measurements(sub, {}, None), slider_mass_kg, sub_mask)
    rec = {"decimation": q, "samples": int(len(sub)), "nfev": int(coarse.convergence_.get("nfev_total", 0)),
           "cpu_s": time.process_time() - c0, "loglik": float(coarse.loglik_)}
    fine = clone(est, init=coarse.params_, n_starts=1,
                 init_extra=np.asarray(coarse.phi_) if est.extra is not None else None)
    fine.fit(data, slider_mass_kg, mask)
    fine.coarse_ = rec
    return fine


def nfev_of(fitted) -> int:
    """Function evaluations of a fit made by :func:`coarse_to_fine`, both stages (coarse ones on fewer samples)."""
    own = int(fitted.convergence_.get("nfev_total", 0))
    rec = getattr(fitted, "coarse_", None)
    return own + (int(rec["nfev"]) if rec else 0)
