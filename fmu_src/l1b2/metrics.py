"""Speed-prediction error metrics used in every report.

Implements "Error metrics" of ``shared/data-format.md``. Samples are
evaluated when the measured speed is at least :data:`MIN_EVAL_SPEED_M_S` in
magnitude and the sample is not within the first or last
:data:`END_EXCLUSION_M` of travel of its run (end-stop collisions, as the
paper notes); see :func:`evaluation_mask`. On those samples:

* ``nrmse`` = sqrt(mean((v_pred - v_meas)^2)) / sqrt(mean(v_meas^2))
* ``mean_abs_rel_error``, ``p95_abs_rel_error`` = mean and 95th percentile
  of |v_pred - v_meas| / |v_meas|

The two kinds of prediction, ``one_step`` (v(k+1) from measured v(k), Eq.
28-29 of the paper) and ``free_run`` (the predictor propagates its own speed
along the measured position trajectory from the measured speed of the run's
first sample), are computed elsewhere and scored separately by
:func:`report_metrics`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from l1b2.data import POSITION, RUN, SPEED, Measurements, run_slices

__all__ = [
    "MIN_EVAL_SPEED_M_S", "END_EXCLUSION_M", "P95_PERCENTILE", "METRIC_KEYS",
    "evaluation_mask", "speed_metrics", "report_metrics",
]

#: Samples with |measured speed| below this are not evaluated [m/s] (5 mm/s).
MIN_EVAL_SPEED_M_S: float = 5e-3
#: Travel excluded at the start and at the end of each run [m] (2 mm).
END_EXCLUSION_M: float = 2e-3
#: Percentile reported as ``p95_abs_rel_error`` [%].
P95_PERCENTILE: float = 95.0
#: Keys of the dictionary returned by :func:`speed_metrics`.
METRIC_KEYS: tuple[str, ...] = ("nrmse", "mean_abs_rel_error", "p95_abs_rel_error", "n_samples")


def _as_1d(name: str, values: Any) -> np.ndarray:
    arr = values.to_numpy(dtype=float) if isinstance(values, pd.Series) \
        else np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    return arr


def evaluation_mask(data: pd.DataFrame | Measurements | Any, position_m: Any = None,
                    run: Any = None, *, min_speed_m_s: float = MIN_EVAL_SPEED_M_S,
                    end_exclusion_m: float = END_EXCLUSION_M) -> np.ndarray:
    """Boolean mask of the samples on which errors are evaluated.

    Parameters
    ----------
    data : pandas.DataFrame, Measurements or array_like
        Either a table with columns ``speed_m_s`` [m/s] (measured speed),
        ``position_m`` [m] and ``run`` (then ``position_m`` and ``run`` must
        not be given), or the measured speed [m/s] per sample.
    position_m : array_like, optional
        Slider position per sample [m]; required when ``data`` is an array.
    run : array_like, optional
        Run id per sample (rows of one run contiguous); ``None`` = one run.
    min_speed_m_s : float
        Smallest evaluated |measured speed| [m/s]; default 5 mm/s.
    end_exclusion_m : float
        Travel excluded at each end of each run [m]; default 2 mm.

    Returns
    -------
    numpy.ndarray of bool
        True where |v_meas| >= ``min_speed_m_s`` and the distance travelled
        from the run's first sample and the distance remaining to the run's
        last sample are both >= ``end_exclusion_m``.

    Notes
    -----
    Travel is measured along the run's own path: the cumulative sum of
    |position(k) - position(k-1)| within the run (never across runs). For a
    monotonic traverse this equals |position - first position| and
    |last position - position|; if the slider reverses (e.g. bounces at an
    end stop) the back-and-forth motion counts as travel. Samples with
    non-finite speed or position are not evaluated.
    """
    if isinstance(data, Measurements):
        data = data.df
    if isinstance(data, pd.DataFrame):
        if position_m is not None or run is not None:
            raise TypeError("give either a DataFrame or arrays, not both")
        missing = [c for c in (SPEED, POSITION, RUN) if c not in data.columns]
        if missing:
            raise ValueError(f"evaluation_mask: DataFrame lacks column(s) {missing}")
        speed = _as_1d(SPEED, data[SPEED])
        pos = _as_1d(POSITION, data[POSITION])
        run = data[RUN]
    else:
        if position_m is None:
            raise TypeError("evaluation_mask: position_m is required with array input")
        speed = _as_1d("speed", data)
        pos = _as_1d("position_m", position_m)
    if pos.shape != speed.shape:
        raise ValueError(f"speed and position_m differ in length ({speed.size} vs {pos.size})")
    if run is None:
        blocks = [(None, slice(0, speed.size))] if speed.size else []
    else:
        run_values = run.to_numpy() if isinstance(run, pd.Series) else np.asarray(run)
        if run_values.shape != speed.shape:
            raise ValueError(f"run and speed differ in length ({run_values.size} vs {speed.size})")
        blocks = run_slices(run_values)

    with np.errstate(invalid="ignore"):
        mask = np.abs(speed) >= min_speed_m_s
    for _, sl in blocks:
        x = pos[sl]
        travelled = np.concatenate(([0.0], np.cumsum(np.abs(np.diff(x)))))
        remaining = travelled[-1] - travelled
        with np.errstate(invalid="ignore"):
            mask[sl] &= (travelled >= end_exclusion_m) & (remaining >= end_exclusion_m)
    return mask


def speed_metrics(v_pred: Any, v_meas: Any, mask: Any) -> dict[str, float | int]:
    """Error metrics of a speed prediction on the evaluated samples.

    Parameters
    ----------
    v_pred : array_like
        Predicted speed per sample [m/s]. May be NaN outside ``mask`` (e.g.
        no one-step prediction for a run's first sample).
    v_meas : array_like
        Measured speed per sample [m/s].
    mask : array_like of bool
        Samples to evaluate, usually :func:`evaluation_mask`.

    Returns
    -------
    dict
        ``nrmse`` = sqrt(mean((v_pred - v_meas)^2)) / sqrt(mean(v_meas^2)),
        ``mean_abs_rel_error`` and ``p95_abs_rel_error`` = mean and 95th
        percentile (numpy's default linear interpolation) of
        |v_pred - v_meas| / |v_meas| (dimensionless fractions, not %), and
        ``n_samples`` (int). With an empty mask the three values are NaN and
        ``n_samples`` is 0.

    Raises
    ------
    ValueError
        Shapes differ, ``mask`` is not boolean, a masked prediction or
        measurement is NaN / infinite (the message says how many), or a
        masked measured speed is zero (relative error undefined).
    """
    pred = _as_1d("v_pred", v_pred)
    meas = _as_1d("v_meas", v_meas)
    m = mask.to_numpy() if isinstance(mask, pd.Series) else np.asarray(mask)
    if m.dtype != bool:
        raise ValueError(f"mask must be boolean, got dtype {m.dtype}")
    if not (pred.shape == meas.shape == m.shape):
        raise ValueError(f"v_pred, v_meas and mask differ in shape "
                         f"({pred.shape}, {meas.shape}, {m.shape})")
    n = int(m.sum())
    if n == 0:
        return {"nrmse": float("nan"), "mean_abs_rel_error": float("nan"),
                "p95_abs_rel_error": float("nan"), "n_samples": 0}
    p, y = pred[m], meas[m]
    bad_p = ~np.isfinite(p)
    if bad_p.any():
        first = int(np.flatnonzero(m)[np.flatnonzero(bad_p)[0]])
        raise ValueError(f"{int(bad_p.sum())} of {n} evaluated predictions are NaN or "
                         f"infinite (first at sample index {first})")
    bad_y = ~np.isfinite(y)
    if bad_y.any():
        first = int(np.flatnonzero(m)[np.flatnonzero(bad_y)[0]])
        raise ValueError(f"{int(bad_y.sum())} of {n} evaluated measured speeds are NaN or "
                         f"infinite (first at sample index {first})")
    zero = y == 0.0
    if zero.any():
        raise ValueError(f"{int(zero.sum())} of {n} evaluated measured speeds are zero; "
                         "relative error undefined (use evaluation_mask)")
    err = p - y
    rel = np.abs(err) / np.abs(y)
    return {
        "nrmse": float(np.sqrt(np.mean(err ** 2)) / np.sqrt(np.mean(y ** 2))),
        "mean_abs_rel_error": float(np.mean(rel)),
        "p95_abs_rel_error": float(np.percentile(rel, P95_PERCENTILE)),
        "n_samples": n,
    }


def report_metrics(df: pd.DataFrame | Measurements, v_one_step: Any,
                   v_free_run: Any) -> dict[str, dict[str, float | int]]:
    """Score one-step and free-run predictions of one data set.

    Parameters
    ----------
    df : pandas.DataFrame or Measurements
        Measured data with ``speed_m_s`` [m/s], ``position_m`` [m], ``run``.
    v_one_step : array_like
        One-step prediction per sample [m/s] (v(k+1) from measured v(k)).
    v_free_run : array_like
        Free-run prediction per sample [m/s].

    Returns
    -------
    dict
        ``{'one_step': speed_metrics(...), 'free_run': speed_metrics(...)}``
        on the common :func:`evaluation_mask` of ``df``.
    """
    if isinstance(df, Measurements):
        df = df.df
    mask = evaluation_mask(df)
    v_meas = df[SPEED]
    return {"one_step": speed_metrics(v_one_step, v_meas, mask),
            "free_run": speed_metrics(v_free_run, v_meas, mask)}
