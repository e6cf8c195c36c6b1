"""Residual analysis a system-identification engineer can trust.

The residual is taken in *drive coordinates*, ``r = d (v_meas - v_pred)``
(``d`` the run's direction), so a missing thrust has the same sign in both
directions. Samples are those of the data-format evaluation mask.

Residuals of one run are autocorrelated (the slider low-passes any missing
force over tens of ms), so no test here treats samples as independent:

* **Whiteness, per run** — autocorrelation with its white-noise 95 % band
  ``+/- 1.96/sqrt(n)`` and the Ljung-Box portmanteau test; reported, not used
  to decide (model mismatch alone makes free-run residuals coloured).
* **Evidence per regressor** — can a smooth function of the regressor
  predict the residual of runs it has *not* seen? K-fold cross-validation
  over runs: fit on the other runs, predict a held-out run, and record each
  run's reduction of its residual sum of squares. The runs are the
  statistical units: a one-sided Wilcoxon signed-rank test over the per-run
  reductions gives the p-value, and the pooled held-out reduction (share of
  residual SS explained, ``cv_gain``) gives the size.
* **Tracing** — forward selection: the regressor with the largest
  significant ``cv_gain`` first, then the others tested *conditionally* on
  those already chosen (their incremental held-out gain), so a regressor that
  only echoes a confounded one (speed echoing voltage, time echoing
  temperature) does not enter.

Regressors (names as in the report): ``time`` (experiment clock),
``position``, ``direction``, ``load`` (signed in drive coordinates and its
magnitude), ``voltage``, ``speed`` (measured |v|), ``acceleration`` (measured,
drive coordinates), ``temperature`` (when the data has it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats

from ..data import measurements as dataio
from ..predictor.effects import bspline_basis  # noqa: F401  (re-exported)

REGRESSORS = ("time", "position", "direction", "load", "voltage", "speed", "acceleration", "temperature")
#: regressors constant within a run (their evidence is carried by run-to-run differences only)
RUN_LEVEL = ("direction", "load", "voltage")
#: a line of :func:`position_spectrum`: its power over the spectrum's median above this (the period is then offered
#: to the position-periodic forms: the bar's waviness and the position sensor's cyclic error)
LINE_POWER_RATIO = 4.0


# ---------------------------------------------------------------------------
# Regressors and their smooth bases
# ---------------------------------------------------------------------------

def drive_residual(df: pd.DataFrame, v_pred) -> np.ndarray:
    """``d (v_meas - v_pred)`` [m/s]: positive when the motor is faster than predicted."""
    return df[dataio.DIRECTION].to_numpy(float) * (df[dataio.SPEED].to_numpy(float) - np.asarray(v_pred, float))


def measured_acceleration(df: pd.DataFrame) -> np.ndarray:
    """Drive-coordinate acceleration from the measured speed, per run (central differences) [m/s^2]."""
    out = np.zeros(len(df))
    v = df[dataio.SPEED].to_numpy(float) * df[dataio.DIRECTION].to_numpy(float)
    t = df[dataio.TIME].to_numpy(float)
    for _, sl in dataio.run_slices(df[dataio.RUN]):
        if sl.stop - sl.start > 1:
            out[sl] = np.gradient(v[sl], t[sl])
    return out


def regressor_values(df: pd.DataFrame) -> dict[str, np.ndarray]:
    """Per-sample values of every regressor available in the data."""
    d = df[dataio.DIRECTION].to_numpy(float)
    vals = {
        "time": df[dataio.TIME].to_numpy(float),
        "position": df[dataio.POSITION].to_numpy(float),
        "direction": d,
        "load": df[dataio.LOAD].to_numpy(float),
        "voltage": df[dataio.VOLTAGE].to_numpy(float),
        "speed": np.abs(df[dataio.SPEED].to_numpy(float)),
        "acceleration": measured_acceleration(df),
    }
    if dataio.TEMPERATURE in df.columns:
        vals["temperature"] = df[dataio.TEMPERATURE].to_numpy(float)
    return vals


def _scaled(x, lo, hi):
    return (x - lo) / (hi - lo) if hi > lo else np.zeros_like(x)


def basis(name: str, values: dict[str, np.ndarray], ranges: dict[str, tuple[float, float]]) -> np.ndarray:
    """Design matrix of a smooth function of one regressor (no intercept column for splines' sum).

    * time, speed, acceleration, temperature: cubic B-splines (6 inner knots);
    * position: cubic B-splines with inner knots every ~1.5 mm of the range
      (smooth profiles are already in the predictor's order-n polynomials; what
      is left is local or periodic);
    * direction: the direction itself (+/-1);
    * load: drive-coordinate load ``d m_load`` (opposing > 0), its magnitude, their product;
    * voltage: V0 and V0^2 (scaled).
    """
    x = values[name]
    lo, hi = ranges[name]
    if name == "direction":
        return x[:, None].astype(float)
    if name == "load":
        opp = values["direction"] * x
        s = max(hi - lo, 1e-12) / 2
        return np.column_stack([opp / s, np.abs(x) / s, opp * np.abs(x) / s ** 2])
    if name == "voltage":
        u = 2 * _scaled(x, lo, hi) - 1
        return np.column_stack([u, u ** 2])
    if name == "position":
        n_inner = int(np.clip(round((hi - lo) / 1.5e-3), 4, 60))
        return bspline_basis(_scaled(x, lo, hi), n_inner)[:, 1:]
    return bspline_basis(_scaled(x, lo, hi), 6)[:, 1:]


# ---------------------------------------------------------------------------
# Whiteness and spectrum
# ---------------------------------------------------------------------------

def acf(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocorrelation for lags 0..max_lag."""
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    denom = np.dot(x, x)
    if denom == 0 or n < 2:
        return np.zeros(max_lag + 1)
    return np.array([np.dot(x[:n - k], x[k:]) / denom if k < n else 0.0 for k in range(max_lag + 1)])


def ljung_box(x: np.ndarray, lags: int) -> tuple[float, float]:
    """Ljung-Box statistic ``Q = n(n+2) sum rho_k^2/(n-k)`` and its chi-square p-value."""
    n = len(x)
    lags = int(min(lags, n - 2))
    if lags < 1:
        return float("nan"), float("nan")
    rho = acf(x, lags)[1:]
    q = n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, lags + 1)))
    return float(q), float(stats.chi2.sf(q, lags))


def whiteness(r: np.ndarray, df: pd.DataFrame, mask: np.ndarray, max_lag: int = 20) -> list[dict]:
    """Per-run whiteness: lag-1 autocorrelation, share of lags outside the 95 % band, Ljung-Box."""
    out = []
    for run, sl in dataio.run_slices(df[dataio.RUN]):
        m = mask[sl]
        x = r[sl][m]
        if len(x) < 10:
            continue
        lags = min(max_lag, len(x) // 4)
        rho = acf(x, lags)
        band = 1.96 / np.sqrt(len(x))
        q, p = ljung_box(x, lags)
        out.append({"run": run, "n": int(len(x)), "rho1": float(rho[1]) if lags >= 1 else float("nan"),
                    "outside_band": float(np.mean(np.abs(rho[1:]) > band)) if lags >= 1 else float("nan"),
                    "ljung_box_Q": q, "ljung_box_p": p, "acf": rho.tolist(), "band": float(band)})
    return out


def position_spectrum(r: np.ndarray, df: pd.DataFrame, mask: np.ndarray, ds_m: float = 2.5e-4):
    """Residual power against spatial frequency, averaged over runs (periodic structure in position).

    Each run's masked residual is resampled on a uniform position grid of
    spacing ``ds_m``, detrended (linear), windowed (Hann) and transformed;
    the power spectra are averaged over runs. Returns ``(freq [1/m], power,
    peak dict)``; the peak is the largest bin above 1 / (half the stroke).
    """
    spectra, n_grid = [], None
    pos = df[dataio.POSITION].to_numpy(float)
    lo, hi = np.min(pos[mask]), np.max(pos[mask])
    grid = np.arange(lo, hi, ds_m)
    if len(grid) < 16:
        return np.array([]), np.array([]), {}
    for _, sl in dataio.run_slices(df[dataio.RUN]):
        m = mask[sl]
        s, x = pos[sl][m], r[sl][m]
        if len(s) < 16:
            continue
        order = np.argsort(s)
        s, x = s[order], x[order]
        inside = (grid >= s[0]) & (grid <= s[-1])
        if inside.sum() < 16:
            continue
        y = np.zeros_like(grid)
        y[inside] = np.interp(grid[inside], s, x)
        yi = y[inside]
        yi = yi - np.polyval(np.polyfit(grid[inside], yi, 1), grid[inside])
        y[inside] = yi * np.hanning(inside.sum())
        y[~inside] = 0.0
        spectra.append(np.abs(np.fft.rfft(y)) ** 2)
        n_grid = len(grid)
    if not spectra:
        return np.array([]), np.array([]), {}
    power = np.mean(spectra, axis=0)
    freq = np.fft.rfftfreq(n_grid, ds_m)
    usable = freq > 2.0 / (hi - lo)
    peak = {}
    if usable.any():
        k = np.flatnonzero(usable)[np.argmax(power[usable])]
        background = np.median(power[usable])
        peak = {"frequency_per_m": float(freq[k]), "period_m": float(1 / freq[k]),
                "power_ratio_to_median": float(power[k] / background) if background > 0 else float("inf")}
    return freq, power, peak


# ---------------------------------------------------------------------------
# Cross-validated evidence
# ---------------------------------------------------------------------------

@dataclass
class Evidence:
    regressor: str
    cv_gain: float          #: share of held-out residual SS removed (pooled over runs)
    p_value: float          #: one-sided Wilcoxon over per-run SS reductions
    runs_improved: float    #: share of runs whose held-out SS fell
    n_runs: int
    conditional_on: tuple = ()
    per_run_gain: np.ndarray = field(default=None, repr=False)

    def to_dict(self) -> dict:
        return {"regressor": self.regressor, "cv_gain": self.cv_gain, "p_value": self.p_value,
                "runs_improved": self.runs_improved, "n_runs": self.n_runs,
                "conditional_on": list(self.conditional_on)}


def run_folds(run_ids: np.ndarray, k: int, seed: int = 0) -> list[np.ndarray]:
    """Split the distinct runs into ``k`` folds (seeded shuffle); returns arrays of run ids."""
    runs = pd.unique(run_ids)
    rng = np.random.default_rng(seed)
    runs = runs[rng.permutation(len(runs))]
    return [runs[i::k] for i in range(min(k, len(runs)))]


def _ridge(X, y, lam):
    XtX = X.T @ X
    reg = lam * np.trace(XtX) / max(XtX.shape[0], 1) * np.eye(XtX.shape[0])
    return np.linalg.solve(XtX + reg, X.T @ y)


def cv_gain(r: np.ndarray, X: np.ndarray, runs: np.ndarray, folds, base: np.ndarray | None = None,
            lam: float = 1e-3) -> tuple[float, np.ndarray, dict]:
    """Held-out gain of predicting ``r`` with ``X`` (on top of ``base`` columns, if given).

    Returns the pooled share of held-out SS removed, the per-run SS reductions
    (relative to the base model's held-out SS), and the per-run held-out SS of
    the larger model.
    """
    Xb = np.ones((len(r), 1)) if base is None else np.column_stack([np.ones(len(r)), base])
    Xf = np.column_stack([Xb, X])
    ss0, ss1 = {}, {}
    for fold in folds:
        test = np.isin(runs, fold)
        train = ~test
        if train.sum() <= Xf.shape[1] or test.sum() == 0:
            continue
        c0 = _ridge(Xb[train], r[train], lam)
        c1 = _ridge(Xf[train], r[train], lam)
        e0 = r[test] - Xb[test] @ c0
        e1 = r[test] - Xf[test] @ c1
        for run in fold:
            sel = runs[test] == run
            ss0[run] = float(np.sum(e0[sel] ** 2))
            ss1[run] = float(np.sum(e1[sel] ** 2))
    keys = list(ss0)
    s0 = np.array([ss0[k] for k in keys])
    s1 = np.array([ss1[k] for k in keys])
    gain = 1 - s1.sum() / s0.sum() if s0.sum() > 0 else 0.0
    per_run = (s0 - s1) / max(s0.mean(), 1e-300)
    return float(gain), per_run, ss1


def wilcoxon_greater(x: np.ndarray) -> float:
    """One-sided Wilcoxon signed-rank p-value that the per-run values ``x`` are positive (1.0 below 6 runs)."""
    x = x[np.abs(x) > 0]
    if len(x) < 6:
        return 1.0
    return float(stats.wilcoxon(x, alternative="greater").pvalue)


def regressor_evidence(r: np.ndarray, df: pd.DataFrame, mask: np.ndarray, *, k: int = 5, seed: int = 0,
                       given: tuple[str, ...] = (), regressors=None) -> list[Evidence]:
    """Cross-validated evidence of each regressor (optionally conditional on ``given`` ones)."""
    vals = regressor_values(df)
    runs_all = df[dataio.RUN].to_numpy()
    idx = np.flatnonzero(mask)
    sub = {k_: v[idx] for k_, v in vals.items()}
    ranges = {k_: (float(np.min(v)), float(np.max(v))) for k_, v in sub.items()}
    rr, runs = r[idx], runs_all[idx]
    folds = run_folds(runs, k, seed)
    base = np.column_stack([basis(g, sub, ranges) for g in given]) if given else None
    out = []
    for name in (regressors or REGRESSORS):
        if name not in sub or name in given:
            continue
        if np.ptp(sub[name]) == 0:
            out.append(Evidence(name, 0.0, 1.0, 0.0, len(pd.unique(runs)), tuple(given)))
            continue
        X = basis(name, sub, ranges)
        g, per_run, _ = cv_gain(rr, X, runs, folds, base)
        out.append(Evidence(name, g, wilcoxon_greater(per_run), float(np.mean(per_run > 0)), len(per_run),
                            tuple(given), per_run))
    return sorted(out, key=lambda e: -e.cv_gain)


def trace(r: np.ndarray, df: pd.DataFrame, mask: np.ndarray, *, alpha: float = 0.01, min_gain: float = 0.05,
          k: int = 5, seed: int = 0, max_regressors: int = 3) -> tuple[list[str], list[list[Evidence]]]:
    """Forward selection of the regressors the residual depends on (strongest first).

    A regressor enters when its (conditional) held-out gain is at least
    ``min_gain`` and its run-level p-value is below ``alpha`` divided by the
    number of regressors tested (Bonferroni). Returns the chosen names and
    the evidence tables of every round.
    """
    chosen: list[str] = []
    rounds = []
    while len(chosen) < max_regressors:
        ev = regressor_evidence(r, df, mask, k=k, seed=seed, given=tuple(chosen))
        rounds.append(ev)
        n_tests = max(len(ev), 1)
        ok = [e for e in ev if e.cv_gain >= min_gain and e.p_value < alpha / n_tests]
        if not ok:
            break
        chosen.append(ok[0].regressor)
    return chosen, rounds
