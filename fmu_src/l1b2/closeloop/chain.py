"""The measurement chain: is the speed column the position's derivative, or filtered, delayed or scaled?

A rig's ``speed_m_s`` need not be a clean central difference of
``position_m``: the DAQ may low-pass it, delay it or scale it. The physics
model cannot absorb that (it predicts the slider's speed), so the effect is
found and modelled apart from the physics, from position and speed alone:

* per run, ``u = d position / d t`` (central differences, as the data format
  derives the speed when it is absent);
* the output filter ``y(k) = a y(k-1) + b0 u(k) + b1 u(k-1)`` (a first-order
  lag with a fractional delay and a scale; identity: a = b1 = 0, b0 = 1) is
  fitted by least squares on the measured speed, K-fold over runs;
* it is accepted when it lowers the held-out sum of squares of
  ``speed - filter(u)`` against the identity by at least ``min_gain`` in most
  runs *and* the speed column's mismatch with the derivative is above the
  quantisation level (``min_rel_rms`` of the speed's rms);
* the sensor's range: every analog speed output (tachometer, vibrometer,
  encoder interpolator read by an ADC) saturates, so the chain may end in
  ``y = clip(filter(u), lo, hi)`` with rails ``lo < 0 < hi`` [m/s], each sign
  on its own (:func:`speed_rails`: a saturated channel reads one value
  while the quantity exceeds it). Above the same ``min_rel_rms``, the clipped
  chain (its filter fitted on the samples inside the rails) competes with
  the chain without a clip under the same held-out rule over runs
  (``min_gain``, p < 0.01), and replaces it when it wins (:func:`clip_test`).

When the filter is accepted, the close-the-loop estimator identifies the
physics on the position's derivative (:func:`with_position_speed`) and
applies the filter (and the clip, when kept) to its predictions
(:meth:`OutputFilter.apply`), before it looks for missing physical effects
(:class:`l1b2.closeloop.loop.ChainModel`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from ..data import measurements as dataio
from ..predictor.effects import FILTER_RAILS, apply_output_filter
from .residuals import run_folds, wilcoxon_greater


@dataclass(frozen=True)
class OutputFilter:
    """``y(k) = a y(k-1) + b0 u(k) + b1 u(k-1)`` per run, ``y(0) = (b0 + b1) u(0) / (1 - a)`` (steady start), then
    ``clip(y, lo_m_s, hi_m_s)`` [m/s] (the speed channel's range; infinite: no limit on that side)."""

    a: float = 0.0
    b0: float = 1.0
    b1: float = 0.0
    lo_m_s: float = -np.inf
    hi_m_s: float = np.inf

    @property
    def clipped(self) -> bool:
        """Whether the stage holds a finite rail."""
        return bool(np.isfinite(self.lo_m_s) or np.isfinite(self.hi_m_s))

    @property
    def filtered(self) -> bool:
        """Whether the stage's filter is other than the identity (``a, b0, b1 != 0, 1, 0``)."""
        return (self.a, self.b0, self.b1) != (0.0, 1.0, 0.0)

    def params(self) -> dict:
        """``{"a", "b0", "b1"}`` and each finite rail (``lo_m_s``, ``hi_m_s``): the mapping
        :func:`l1b2.predictor.effects.apply_output_filter` and the exported model read."""
        out = {"a": self.a, "b0": self.b0, "b1": self.b1}
        out.update({k: getattr(self, k) for k in FILTER_RAILS if np.isfinite(getattr(self, k))})
        return out

    def apply(self, df: pd.DataFrame, u) -> np.ndarray:
        """The filtered (and clipped) signal of ``u`` (per sample), run by run
        (:func:`l1b2.predictor.effects.apply_output_filter`)."""
        starts = sorted(sl.start for _, sl in dataio.run_slices(df[dataio.RUN]))
        return apply_output_filter(self.params(), u, starts)

    def frame(self, df: pd.DataFrame) -> pd.DataFrame:
        """The frame the physics behind the filter is fitted on and predicts along (:func:`with_position_speed`)."""
        return with_position_speed(df)

    def to_dict(self) -> dict:
        dc = (self.b0 + self.b1) / (1.0 - self.a) if abs(1.0 - self.a) > 1e-9 else float("nan")
        return {"a": self.a, "b0": self.b0, "b1": self.b1, "dc_gain": dc,
                "time_constant_samples": (-1.0 / np.log(self.a)) if 0 < self.a < 1 else 0.0,
                **({"clip_lo_m_s": _finite(self.lo_m_s), "clip_hi_m_s": _finite(self.hi_m_s)} if self.clipped else {})}


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def position_derivative(df: pd.DataFrame) -> np.ndarray:
    """``d position / d t`` per run (central differences) [m/s]."""
    pos = df[dataio.POSITION].to_numpy(float)
    t = df[dataio.TIME].to_numpy(float)
    out = np.zeros(len(df))
    for _, sl in dataio.run_slices(df[dataio.RUN]):
        if sl.stop - sl.start > 1:
            out[sl] = np.gradient(pos[sl], t[sl])
    return out


def with_position_speed(df: pd.DataFrame) -> pd.DataFrame:
    """A copy of ``df`` whose speed column is the position's derivative (:func:`position_derivative`) [m/s].

    The slider's speed as the data format derives it when the column is
    absent: what the physics predicts when the recorded column went through a
    filter of the measurement chain.
    """
    out = df.copy()
    out[dataio.SPEED] = position_derivative(df)
    return out


def _design(df: pd.DataFrame, u: np.ndarray, v: np.ndarray):
    """Rows k >= 1 of each run: ``[v(k-1), u(k), u(k-1)]`` and target ``v(k)``; their run ids."""
    keep = np.ones(len(df), bool)
    for _, sl in dataio.run_slices(df[dataio.RUN]):
        keep[sl.start] = False
    prev_v = np.roll(v, 1)
    prev_u = np.roll(u, 1)
    X = np.column_stack([prev_v, u, prev_u])[keep]
    return X, v[keep], df[dataio.RUN].to_numpy()[keep], keep


def speed_channel(df: pd.DataFrame, mask: np.ndarray, *, k: int = 5, seed: int = 0, min_gain: float = 0.5,
                  min_rel_rms: float = 0.01) -> dict:
    """Compare the speed column with the position's derivative; the accepted output filter (or None).

    Returns a dict: ``rel_rms_mismatch`` (rms of speed - derivative over the
    speed's rms), ``cv_gain`` (held-out share of the identity's mismatch the
    filter removes, one-step on the measured speed), ``p_value`` (runs),
    ``filter`` (:class:`OutputFilter` parameters fitted on all runs; the clipped stage when the clip is
    accepted), ``accepted`` (the filter or the clip) and, when the mismatch reaches ``min_rel_rms``, ``clip``
    (:func:`clip_test`'s record without its stage).
    """
    if dataio.SPEED not in df.columns:
        return {"accepted": False, "reason": "no speed column"}
    u = position_derivative(df)
    v = df[dataio.SPEED].to_numpy(float)
    X, y, runs, keep = _design(df, u, v)
    m = np.asarray(mask, bool)[keep]
    X, y, runs = X[m], y[m], runs[m]
    if len(y) < 10:
        return {"accepted": False, "reason": "too few samples"}
    ident = X[:, 1]
    rel = float(np.sqrt(np.mean((v[mask] - u[mask]) ** 2)) / max(np.sqrt(np.mean(v[mask] ** 2)), 1e-300))
    folds = run_folds(runs, k, seed)
    ss0, ss1 = {}, {}
    for fold in folds:
        te = np.isin(runs, fold)
        coef = np.linalg.lstsq(X[~te], y[~te], rcond=None)[0]
        e1 = y[te] - X[te] @ coef
        e0 = y[te] - ident[te]
        for run in fold:
            sel = runs[te] == run
            ss0[run] = float(np.sum(e0[sel] ** 2))
            ss1[run] = float(np.sum(e1[sel] ** 2))
    s0 = np.array(list(ss0.values()))
    s1 = np.array([ss1[r] for r in ss0])
    gain = float(1 - s1.sum() / s0.sum()) if s0.sum() > 0 else 0.0
    p = wilcoxon_greater((s0 - s1) / max(s0.mean(), 1e-300)) if s0.sum() > 0 else 1.0
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    filt = OutputFilter(float(coef[0]), float(coef[1]), float(coef[2]))
    ok = bool(rel >= min_rel_rms and gain >= min_gain and p < 0.01 and abs(filt.a) < 0.999)
    out = {"accepted": ok, "rel_rms_mismatch": rel, "cv_gain": gain, "p_value": p,
           "runs_improved": float(np.mean(s1 < s0)) if len(s0) else 0.0, "filter": filt}
    if rel >= min_rel_rms:
        sim = (u, np.flatnonzero(keep)[m], sorted(sl.start for _, sl in dataio.run_slices(df[dataio.RUN])))
        clip = clip_test(X, y, runs, folds, sim, filter_kept=ok, min_gain=min_gain)
        out["clip"] = {k: v for k, v in clip.items() if k != "stage"}
        if clip["accepted"]:
            out.update(accepted=True, filter=clip["stage"])
    return out


#: a sample reads a rail when it lies within this share of the rail's value from it (a saturated ADC writes one
#: code; the share only absorbs the decimal round trip of a data file)
RAIL_REL_TOL = 1e-9


def column_noise(v: np.ndarray, runs: np.ndarray) -> float:
    """The white noise's standard deviation [m/s] in the column ``v``, from its second differences within runs.

    ``v(k+1) - 2 v(k) + v(k-1)`` of a speed that is smooth at the sample rate plus white noise of sd ``sigma`` has
    sd ``sqrt(6) sigma`` (a quantisation finer than the noise adds its ``q^2 / 12`` to ``sigma^2``); robust,
    ``1.4826 median|d2| / sqrt(6)``, so a short fast transient or a flat stretch at a rail moves it little. Only
    consecutive samples of one run enter (0.0 with fewer than three samples in every run).
    """
    v, runs = np.asarray(v, float), np.asarray(runs)
    same = (runs[2:] == runs[1:-1]) & (runs[1:-1] == runs[:-2])
    d2 = (v[2:] - 2.0 * v[1:-1] + v[:-2])[same]
    return float(1.4826 * np.median(np.abs(d2)) / np.sqrt(6.0)) if len(d2) else 0.0


def noise_band_width(sigma_m_s: float, n: int) -> float:
    """The width [m/s] below a column's extreme that holds its noisy rail: ``2 z sigma``, ``z`` the standard normal
    quantile exceeded with probability ``1 / n``.

    Of ``n`` samples reading ``rail + noise``, the largest lies about ``z sigma`` above the rail (``n`` bounds the
    samples at the rail), so the band ``[extreme - 2 z sigma, extreme]`` holds the rail's samples down to about
    ``z sigma`` below it.
    """
    return 2.0 * float(stats.norm.isf(1.0 / max(n, 2))) * sigma_m_s if sigma_m_s > 0 else 0.0


def rail_pile(sv: np.ndarray, band_m_s: float) -> tuple[float, np.ndarray, float, float]:
    """The candidate rail of the sign-turned column ``sv`` [m/s] (its extreme ``ext = max sv > 0``):
    ``(ext, at, rail, edge)``.

    ``band_m_s`` 0: an exact rail, ``at`` the samples within :data:`RAIL_REL_TOL` of ``ext`` and the rail ``ext``;
    else a noisy rail, ``at`` the samples within ``band_m_s`` below ``ext`` and the rail their median (a robust
    centre: the samples on their way to the rail are a minority of the band). ``edge``: the band's inner end, below
    which a sample is inside the range.
    """
    ext = float(np.max(sv))
    if band_m_s > 0:
        edge = ext - band_m_s
        at = sv >= edge
        return ext, at, float(np.median(sv[at])), edge
    edge = ext * (1.0 - RAIL_REL_TOL)
    at = sv >= edge
    return ext, at, ext, edge


def speed_rails(v: np.ndarray, u: np.ndarray, runs: np.ndarray, *, alpha: float = 0.01) -> dict:
    """The speed channel's range limits, each sign on its own, from the column ``v`` and the derivative ``u`` [m/s].

    A saturated channel stops following the quantity while the quantity exceeds the rail. Its samples there read
    the rail exactly when the saturation is the chain's last stage (a full-scale code), or the rail plus the noise
    and quantisation of the stages after it (an analogue stage that saturates before the ADC). Per sign (``max v >
    0``, ``min v < 0``) two candidates are tested, the exact one first (:func:`rail_pile`): the samples that read
    the column's extreme, then, when that fails, the samples within :func:`noise_band_width` of it (the column's
    noise :func:`column_noise` over its ``len(v)`` samples), the rail their median. A candidate is a rail when the
    derivative exceeds the column's extreme where the column reads the candidate: per run holding such samples,
    the mean of ``u - extreme`` (sign turned for the lower rail) is positive, one-sided Wilcoxon over those runs
    below ``alpha`` (seven runs at least for 0.01). A column that follows the quantity reads its extreme where the
    quantity plus the noise peaks, so there the derivative lies below the extreme: a clean or quantised column's
    top samples, a low-passed column's (which reads its extreme at one sample, the noise filtered) and the plateaus
    of its fastest runs alike. The extreme is the pile's upper end, so the test holds for the exact rail as for the
    noisy one; a noisy rail needs the quantity beyond it by more than the noise's largest excursion.

    Returns ``{"lo_m_s", "hi_m_s"}`` (the rails; -inf / inf when none), ``noise_m_s`` (the column's noise), and per
    side (``lo``, ``hi``) the candidate ``candidate_<side>_m_s`` (the column's extreme; None when the column has no
    sample of that sign), ``band_<side>_m_s`` (the last candidate's band below the extreme: 0.0 for the exact one),
    ``edge_<side>_m_s`` (its inner end: a sample beyond it reads the rail; the extreme's when the side has no
    sample), ``n_<side>`` (samples in it), ``runs_<side>`` (runs holding them) and ``p_<side>``.
    """
    v, u = np.asarray(v, float), np.asarray(u, float)
    sigma = column_noise(v, runs)
    bands = (0.0,) + ((noise_band_width(sigma, len(v)),) if sigma > 0 else ())
    out = {"noise_m_s": sigma}
    for side, sgn in (("lo", -1.0), ("hi", 1.0)):
        sv = sgn * v
        ext = float(np.max(sv)) if len(v) else 0.0
        rail, n, n_runs, p, band, edge = sgn * np.inf, 0, 0, 1.0, 0.0, ext
        for band in bands if ext > 0 else ():
            ext, at, value, edge = rail_pile(sv, band)
            ids, code = np.unique(runs[at], return_inverse=True)
            excess = np.bincount(code, weights=sgn * u[at] - ext) / np.bincount(code)
            n, n_runs, p = int(at.sum()), len(ids), wilcoxon_greater(excess)
            if p < alpha and value > 0:
                rail = sgn * value
                break
        out.update({f"{side}_m_s": rail, f"candidate_{side}_m_s": sgn * ext if ext > 0 else None,
                    f"band_{side}_m_s": band, f"edge_{side}_m_s": sgn * edge,
                    f"n_{side}": n, f"runs_{side}": n_runs, f"p_{side}": p})
    return out


def inside_rails(x: np.ndarray, lo_edge: float, hi_edge: float) -> np.ndarray:
    """Samples strictly inside the range, between the rails' inner edges ``(lo_edge, hi_edge)`` [m/s]
    (:func:`speed_rails`' ``edge_lo_m_s``/``edge_hi_m_s``; -inf / inf on a side without a rail)."""
    return (x < hi_edge) & (x > lo_edge)


def _rails_of(y: np.ndarray, rails: dict) -> tuple[float, float, float, float]:
    """``(lo, hi, lo_edge, hi_edge)`` [m/s] of the rows ``y``: the rails :func:`speed_rails` found (their sides and
    bands) with their values and inner edges refitted on ``y`` (:func:`rail_pile`); infinite on a side without."""
    out = {}
    for side, sgn in (("lo", -1.0), ("hi", 1.0)):
        if np.isfinite(rails[f"{side}_m_s"]) and np.max(sgn * y) > 0:
            _, _, value, edge = rail_pile(sgn * y, rails[f"band_{side}_m_s"])
            out[side] = (sgn * value, sgn * edge)
        else:
            out[side] = (sgn * np.inf, sgn * np.inf)
    return out["lo"][0], out["hi"][0], out["lo"][1], out["hi"][1]


def _heldout_ss(y: np.ndarray, runs: np.ndarray, folds, predict) -> np.ndarray:
    """Held-out sums of squares per run (rows) and model (columns): ``predict(train_rows, test_rows)`` gives each
    model's prediction of ``y[test_rows]`` fitted on ``train_rows`` (boolean masks)."""
    ss = {}
    for fold in folds:
        te = np.isin(runs, fold)
        preds = predict(~te, te)
        for run in fold:
            sel = runs[te] == run
            ss[run] = [float(np.sum((y[te][sel] - pr[sel]) ** 2)) for pr in preds]
    return np.array(list(ss.values()), float).reshape(-1, 2)


def _gain_p(ss: np.ndarray) -> tuple[float, float]:
    """Held-out gain ``1 - SS1/SS0`` and the runs' one-sided Wilcoxon p-value of model 1 over model 0."""
    s0, s1 = ss[:, 0], ss[:, 1]
    if not s0.sum() > 0:
        return 0.0, 1.0
    return float(1 - s1.sum() / s0.sum()), wilcoxon_greater((s0 - s1) / max(s0.mean(), 1e-300))


def _fit(X: np.ndarray, y: np.ndarray, rows, filtered: bool) -> np.ndarray:
    """``[a, b0, b1]``: the least-squares filter on ``rows`` of the design, or the identity."""
    return np.linalg.lstsq(X[rows], y[rows], rcond=None)[0] if filtered else np.array([0.0, 1.0, 0.0])


def clip_test(X: np.ndarray, y: np.ndarray, runs: np.ndarray, folds, sim, *, filter_kept: bool,
              min_gain: float = 0.5, alpha: float = 0.01) -> dict:
    """The chain ending in the speed channel's range against the chain without it, held out over runs.

    ``X``, ``y``, ``runs``: the rows of :func:`speed_channel`'s design (``[v(k-1), u(k), u(k-1)]``, target
    ``v(k)`` [m/s]); ``folds``: run ids per fold; ``sim = (u, rows, starts)``: the derivative at every sample
    [m/s], the design rows' sample indices and the runs' first samples. The rails are :func:`speed_rails` of all
    rows. The filter inside them is fitted on the rows whose ``v(k)`` and ``v(k-1)`` both lie inside
    (:func:`inside_rails`): the least-squares filter when it beats the identity there by the filter's own rule
    (one step ahead, held-out gain ``min_gain``, p < ``alpha``, ``|a| < 0.999``), else the identity. The chain
    without a clip is the least-squares filter on all rows when ``filter_kept``, else the identity. Both chains are
    compared as the loop uses them, run from the derivative alone (the filter's free run,
    :func:`l1b2.predictor.effects.apply_output_filter`, never fed the recorded speed), on held-out runs with the
    filters and the rails' values refitted on the training runs (the sides found on all rows keep their rail:
    the training runs' extreme), and the clipped chain predicts ``clip(filter(u), lo, hi)``. The
    clip is accepted when a rail exists and its held-out gain is at least ``min_gain`` with p < ``alpha``
    (one-sided Wilcoxon over runs).

    Returns the rails' record (:func:`speed_rails`, rails None when absent), ``share_at_rails`` (of the rows),
    ``inner_filter`` (bool), ``inner_cv_gain``, ``inner_p_value``, ``filter_kept``, ``cv_gain``, ``p_value``,
    ``accepted`` and
    ``stage`` (the :class:`OutputFilter` with its rails fitted on all rows; None without a rail).
    """
    u_all, idx, starts = sim
    u = X[:, 1]
    rails = speed_rails(y, u, runs, alpha=alpha)
    lo, hi = rails["lo_m_s"], rails["hi_m_s"]
    rec = {**rails, "lo_m_s": _finite(lo), "hi_m_s": _finite(hi), "accepted": False,
           "share_at_rails": (rails["n_lo"] * np.isfinite(lo) + rails["n_hi"] * np.isfinite(hi)) / max(len(y), 1)}
    if not (np.isfinite(lo) or np.isfinite(hi)):
        return {**rec, "stage": None}
    edges = tuple(rails[f"edge_{s}_m_s"] if np.isfinite(r) else sgn * np.inf
                  for s, r, sgn in (("lo", lo, -1.0), ("hi", hi, 1.0)))
    ins = inside_rails(y, *edges) & inside_rails(X[:, 0], *edges)
    Xi, yi, ri = X[ins], y[ins], runs[ins]
    g_in, p_in = _gain_p(_heldout_ss(yi, ri, folds,
                                     lambda tr, te: [Xi[te, 1], Xi[te] @ _fit(Xi, yi, tr, True)]))
    coef = _fit(Xi, yi, np.ones(len(yi), bool), True) if len(yi) > 3 else np.zeros(3)
    inner = bool(g_in >= min_gain and p_in < alpha and abs(coef[0]) < 0.999)
    if not inner:
        coef = _fit(X, y, None, False)

    def run(c):
        return apply_output_filter(dict(zip(("a", "b0", "b1"), c)), u_all, starts)[idx]

    def predict(tr, te):
        r_lo, r_hi, e_lo, e_hi = _rails_of(y[tr], rails)   # the rails found, refitted as coefficients are
        fit = tr & inside_rails(y, e_lo, e_hi) & inside_rails(X[:, 0], e_lo, e_hi)
        return [run(_fit(X, y, tr, filter_kept))[te] if filter_kept else u[te],
                np.clip(run(_fit(X, y, fit, True))[te] if inner else u[te], r_lo, r_hi)]
    gain, p = _gain_p(_heldout_ss(y, runs, folds, predict))
    rec.update(accepted=bool(gain >= min_gain and p < alpha), cv_gain=gain, p_value=p, inner_filter=inner,
               inner_cv_gain=g_in, inner_p_value=p_in, filter_kept=filter_kept)
    return {**rec, "stage": OutputFilter(*(float(c) for c in coef), lo_m_s=lo, hi_m_s=hi)}


#: a run whose recorded travel is within this share of the median travel is a full traverse (stop to stop)
FULL_TRAVERSE_TOL = 0.05


def stroke_gain(df: pd.DataFrame, channels=(), *, alpha: float = 0.01) -> dict:
    """The position sensor's gain from run to run, read from each run's recorded travel between the end stops.

    Every run of the protocol traverses the stroke from one end stop to the other, and the stops do not move: a
    full traverse records the same travel in every run, up to the encoder's quantisation, unless the sensor's gain
    (its scale) changes. A run whose travel (``max - min`` of the position) is within :data:`FULL_TRAVERSE_TOL` of
    the median travel is a full traverse (a run that stalled short of the far stop is not), and its relative gain
    is ``g_r = travel_r / median - 1``. Each channel of ``channels`` (column names; its run means) is tested as the
    gain's cause by the least-squares slope of ``g_r`` on it (t-test, two-sided), significant below ``alpha`` /
    number of channels tested (Bonferroni). Such a gain scales the recorded position and every speed derived from
    it: a measurement effect, not a force. Reported; no model of the loop carries it.

    Returns ``{"full_runs", "gain_sd_rel", "gain_range_rel", "channel", "slope_per_unit", "r", "p_value",
    "significant"}`` (the strongest channel: smallest p-value; ``channel`` None when none was testable).
    """
    g = df.groupby(dataio.RUN, sort=False)
    travel = (g[dataio.POSITION].max() - g[dataio.POSITION].min()).to_numpy(float)
    full = np.abs(travel / np.median(travel) - 1.0) <= FULL_TRAVERSE_TOL if len(travel) else np.zeros(0, bool)
    gain = travel[full] / np.median(travel[full]) - 1.0 if full.any() else np.zeros(0)
    out = {"full_runs": int(full.sum()), "gain_sd_rel": float(np.std(gain)) if len(gain) else 0.0,
           "gain_range_rel": float(np.ptp(gain)) if len(gain) else 0.0, "channel": None, "slope_per_unit": None,
           "r": None, "p_value": 1.0, "significant": False}
    tested = []
    for name in channels:
        if name not in df.columns:
            continue
        c = g[name].mean().to_numpy(float)[full]
        if len(gain) < 4 or not (np.all(np.isfinite(c)) and np.std(c) > 0 and np.std(gain) > 0):
            continue
        fit = stats.linregress(c, gain)
        tested.append((float(fit.pvalue), name, float(fit.slope), float(fit.rvalue)))
    if tested:
        p, name, slope, r = min(tested)
        out.update(channel=name, slope_per_unit=slope, r=r, p_value=p, significant=bool(p < alpha / len(tested)))
    return out
