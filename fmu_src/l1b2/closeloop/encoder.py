"""The measurement chain of the position sensor: an incremental scale's cyclic (sub-divisional) error.

An incremental position sensor (an optical or magnetic scale read by an interpolating head) reports ``p = s +
e(s)``, with ``e`` periodic in the slider's position ``s`` with the scale's pitch ``P`` and its harmonics. The form
kept here is two harmonics,

    ``e(s) = sum_h c_h sin(2 pi h s / P) + d_h cos(2 pi h s / P)``, h = 1, 2 (``c_h, d_h`` [m]),

and a speed column derived from that position (its time derivative) is ``v_logged = v (1 + e'(s))``: a
multiplicative ripple periodic in the position whose amplitude grows with the speed. A force periodic in the
position (a bar's waviness, :class:`l1b2.predictor.effects.bar.BarWaviness`) also ripples the speed at ``v / P``,
but through the slider's inertia, so that its ripple falls as the speed (the ripple's frequency) rises. The
chain's form on the prediction's output (:class:`CyclicChain`) is ``v_logged = v (1 + e'(p))`` (``e'`` at the
logged position: the difference is of second order in ``e``), and the physics behind it is fitted on the frame
``p - e(p)``, ``v_logged / (1 + e'(p))`` (:meth:`CyclicChain.frame`). ``e'`` is read as the speed column sees
it (:func:`slope_rows`): the column is the position's discrete derivative over the logged stamps (the speed
channel's test found no other), so its ripple is that derivative of ``e`` over the position's, which attenuates a
harmonic whose wavelength is not long against a sample's travel (``sin(x) / x``, ``x = 2 pi h v dt / P``).

It is decided as every sensor stage is (:mod:`l1b2.closeloop.stagefit`):

* **considered** (:func:`candidate_pitch`) when the baseline's TRAIN residual has a line in its spectrum over the
  position (:func:`l1b2.closeloop.residuals.position_spectrum`) whose power is more than
  :data:`l1b2.closeloop.residuals.LINE_POWER_RATIO` times the spectrum's median, the rule by which the same period
  is offered to the force family, and whose period the TRAIN stroke holds at least :data:`MIN_REPEATS` times (a
  cyclic error is told from a smooth function of the position by its repeats: over fewer, the form's two harmonics
  fit any slow misfit along the stroke, which is where a red residual spectrum's largest usable bin lies); the pitch
  is that line's period refined within one bin of the spectrum (:func:`refine_pitch`: the smallest TRAIN sum of
  squares of the chain's linear fit);
* **screen** (:func:`screen`): the baseline's TRAIN residual (drive coordinates) regressed on the form's response,
  ``d v_pred de'/dtheta_h`` (exact to first order), with the baseline's nuisance responses, cross-validated over the
  runs' folds; and, on the same folds and nuisance, on the force family's response at the same pitch (its forces
  through the slider's linearised dynamics, :func:`l1b2.closeloop.selection.linear_response`). It passes when
  significant and when its held-out gain exceeds the force family's;
* **fit** (:func:`fit_chain`): given a model's free run ``v``, ``c_h, d_h`` are the least squares of
  ``v_logged - v (1 + e'(p))`` (linear), with run-clustered standard errors;
* **decision** (:func:`l1b2.closeloop.stagefit.stage_cv_errors` with :func:`fit_refined`): the physics refitted
  behind the form against the baseline, per fold of the refit folds, the held-out logged speed predicted in free
  run (the pitch refined and the chain re-estimated on each fold's training runs only).
"""

from __future__ import annotations

from functools import partial

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..data.columns import run_slices
from ..predictor import effects as fx
from . import residuals as res
from . import stagefit
from .acceptance import RefitSettings
from .selection import linear_response

#: the stage's name in reports
CYCLIC_CHAIN = "position_sensor_cyclic_error"
#: its regressor in ``diagnosis.traced_to``
REGRESSOR = "position_cyclic_error"
#: the fewest times the TRAIN stroke must hold a spectral line's period for the line to be a pitch (module docstring)
MIN_REPEATS = 4.0
#: the harmonics of the pitch the form holds
HARMONICS = (1, 2)
#: the force family the stage competes with at the same pitch
FORCE_FAMILY = "bar_waviness"
DESCRIPTION = ("the position column carries the incremental scale's cyclic error e(s), periodic with the scale's "
               "pitch P (two harmonics), and the speed column is its derivative: the logged speed is v (1 + e'(s))")


def phase(p, pitch_m: float) -> np.ndarray:
    """``2 pi p / P`` [rad] of positions ``p`` [m]."""
    return 2.0 * np.pi * np.asarray(p, float) / float(pitch_m)


def error_m(p, pitch_m: float, coef) -> np.ndarray:
    """``e(p) = sum_h c_h sin(h theta) + d_h cos(h theta)`` [m], ``coef = (c_1, d_1, c_2, d_2)`` [m]."""
    th = phase(p, pitch_m)
    return sum(c * np.sin(h * th) + d * np.cos(h * th) for h, c, d in zip(HARMONICS, coef[0::2], coef[1::2]))


def slope_basis(p, pitch_m: float) -> np.ndarray:
    """``de'/dcoef`` per sample (n x 4) [1/m]: ``(2 pi h / P) (cos(h theta), -sin(h theta))``, h = 1, 2, so that
    ``e'(p) = slope_basis(p, P) @ coef``."""
    th = phase(p, pitch_m)
    k = 2.0 * np.pi / float(pitch_m)
    return np.column_stack([col for h in HARMONICS for col in (h * k * np.cos(h * th), -h * k * np.sin(h * th))])


def error_basis(p, pitch_m: float) -> np.ndarray:
    """``de/dcoef`` per sample (n x 4) [1]: ``(sin(h theta), cos(h theta))``, h = 1, 2, so that ``e(p) =
    error_basis(p, P) @ coef``."""
    th = phase(p, pitch_m)
    return np.column_stack([col for h in HARMONICS for col in (np.sin(h * th), np.cos(h * th))])


#: the shortest span of two neighbouring samples' positions, in pitches, over which the speed column's ripple is
#: read as a divided difference (under it the divided difference equals ``e'`` to about ``(pi h span / P)^2 / 6``,
#: 4e-4 at h = 2: the slope itself is used)
MIN_SPAN_PITCHES = 0.01


def slope_rows(df: pd.DataFrame, pitch_m: float) -> np.ndarray:
    """``de'/dcoef`` per sample (n x 4) [1] as a speed column derived from the logged position sees it.

    The speed column passed the speed channel's test (it is the position's derivative over the logged stamps,
    ``numpy.gradient`` within each run, or the sensor stages would not be considered), so its ripple is that
    derivative of ``e`` over that of the position: ``G[e(p)] / G[p]``, a divided difference of ``e`` across the
    neighbouring samples. It is ``e'(p)`` when the samples are close on the scale's pitch and smaller when a
    sample's travel is a sizeable part of it (the difference's own attenuation of a fast ripple). Where the
    neighbours span less than :data:`MIN_SPAN_PITCHES` of the pitch (slow motion, rest) the analytic slope
    :func:`slope_basis` is used.
    """
    p = df[dataio.POSITION].to_numpy(float)
    t = df[dataio.TIME].to_numpy(float)
    out = slope_basis(p, pitch_m)
    E = error_basis(p, pitch_m)
    for _, sl in run_slices(df[dataio.RUN]):
        if sl.stop - sl.start < 2:
            continue
        gp = np.gradient(p[sl], t[sl])
        span = np.abs(np.gradient(p[sl])) * 2.0
        ok = span > MIN_SPAN_PITCHES * pitch_m
        if ok.any():
            gE = np.gradient(E[sl], t[sl], axis=0)
            block = out[sl]
            block[ok] = gE[ok] / gp[ok, None]
            out[sl] = block
    return out


class CyclicChain:
    """The position sensor's chain ``v_logged = v (1 + e'(p))`` (the interface of
    :class:`~l1b2.closeloop.chain.OutputFilter`: the physics is fitted on :meth:`frame`, its prediction of the
    slider's speed is turned into the logged one by :meth:`apply`)."""

    name, regressor = CYCLIC_CHAIN, REGRESSOR

    def __init__(self, pitch_m: float, coef, stderr=None):
        self.pitch_m, self.coef = float(pitch_m), np.asarray(coef, float)
        self.stderr = None if stderr is None else np.asarray(stderr, float)

    def slope(self, df: pd.DataFrame) -> np.ndarray:
        """``e'(p)`` [1] at ``df``'s logged positions."""
        return slope_rows(df, self.pitch_m) @ self.coef

    def frame(self, df: pd.DataFrame) -> pd.DataFrame:
        """A copy of ``df`` with the slider's position ``p - e(p)`` and speed ``v_logged / (1 + e'(p))``."""
        out = df.copy()
        p = df[dataio.POSITION].to_numpy(float)
        out[dataio.POSITION] = p - error_m(p, self.pitch_m, self.coef)
        out[dataio.SPEED] = df[dataio.SPEED].to_numpy(float) / (1.0 + self.slope(df))
        return out

    def apply(self, df: pd.DataFrame, u) -> np.ndarray:
        """The logged speed ``u (1 + e'(p))`` [m/s] at ``df``'s logged positions."""
        return np.asarray(u, float) * (1.0 + self.slope(df))

    def refit(self, df: pd.DataFrame, mask, v_model) -> CyclicChain:
        """:func:`fit_chain` at this chain's pitch."""
        return fit_chain(df, mask, v_model, self.pitch_m)

    def amplitudes_m(self) -> list:
        """``A_h = hypot(c_h, d_h)`` [m] per harmonic."""
        return [float(np.hypot(c, d)) for c, d in zip(self.coef[0::2], self.coef[1::2])]

    def to_dict(self) -> dict:
        return {"pitch_m": self.pitch_m, "coef_m": self.coef.tolist(), "amplitude_m": self.amplitudes_m(),
                "coef_stderr_m": None if self.stderr is None else self.stderr.tolist()}

    def parameters(self) -> dict:
        """The report's ``extended_parameters`` entries: the four coefficients with their standard errors (the
        pitch is chosen from the residual's spectrum, not estimated with an error: it is the stage's shape, as a
        waviness's period is its label's)."""
        out = {}
        ses = self.stderr if self.stderr is not None else (None,) * len(self.coef)
        for (h, t), c, se in zip([(h, t) for h in HARMONICS for t in ("sin", "cos")], self.coef, ses):
            se = None if se is None else float(se)
            out[f"cyclic_error_{t}{h}_m"] = {"value": float(c), "stderr": se, "unit": "m",
                                             "ci95": None if se is None else [c - 1.96 * se, c + 1.96 * se]}
        return out

    def record(self, rec: dict) -> dict:
        """The report's effect record of the kept stage (``rec``: its round)."""
        return {"round": rec["round"], "effect": CYCLIC_CHAIN, "label": CYCLIC_CHAIN,
                "shape": f"pitch {self.pitch_m * 1e3:.4f} mm", "regressors": [REGRESSOR], "generic": False,
                "structural": None, "parameters": self.parameters(), "description": DESCRIPTION,
                "cv_gain": rec["cv"]["cv_gain"], "cv_free_run_nrmse_before": None, "cv_free_run_nrmse_after": None,
                "folds_improved": None}

    def reading(self) -> str:
        """The message's words on the kept stage."""
        a = ", ".join(f"{x * 1e6:.2f}" for x in self.amplitudes_m())
        return (f"position sensor's cyclic error (measurement chain, not a force): pitch {self.pitch_m * 1e3:.4f} mm, "
                f"harmonic amplitudes {a} um; logged speed = (1 + e'(s)) x the slider's")

    def model_note(self) -> str:
        """The calibrated model's note: the model is the physics behind the stage."""
        return ("; it is the physics behind the position sensor's cyclic error: it predicts the slider's speed at "
                f"its true position (the logged speed is (1 + e'(s)) times it, pitch {self.pitch_m * 1e3:.4f} mm: "
                "not carried)")


def _design(df: pd.DataFrame, mask, v_model, pitch_m: float):
    m = np.asarray(mask, bool)
    v = np.asarray(v_model, float)[m]
    X = v[:, None] * slope_rows(df, pitch_m)[m]
    return X, df[dataio.SPEED].to_numpy(float)[m] - v, m


def fit_chain(df: pd.DataFrame, mask, v_model, pitch_m: float) -> CyclicChain:
    """The chain of pitch ``pitch_m`` whose ``v_model (1 + e'(p))`` fits the logged speed best on the masked
    samples (linear least squares in ``c_h, d_h``), with run-clustered standard errors (sandwich)."""
    X, y, m = _design(df, mask, v_model, pitch_m)
    XtX = X.T @ X
    try:
        coef = np.linalg.solve(XtX, X.T @ y)
        inv = np.linalg.inv(XtX)
    except np.linalg.LinAlgError:
        return CyclicChain(pitch_m, np.zeros(2 * len(HARMONICS)))
    _, code = np.unique(df[dataio.RUN].to_numpy()[m], return_inverse=True)
    e = y - X @ coef
    S = np.column_stack([np.bincount(code, weights=X[:, j] * e) for j in range(X.shape[1])])
    cov = inv @ (S.T @ S) @ inv
    return CyclicChain(pitch_m, coef, np.sqrt(np.clip(np.diag(cov), 0.0, None)))


def fit_refined(df: pd.DataFrame, mask, v_model, pitch_m: float, bin_per_m: float) -> CyclicChain:
    """:func:`fit_chain` at the pitch :func:`refine_pitch` finds within one bin of ``pitch_m`` on the same samples."""
    return fit_chain(df, mask, v_model, refine_pitch(df, mask, v_model, pitch_m, bin_per_m))


def refine_pitch(df: pd.DataFrame, mask, v_model, pitch_m: float, bin_per_m: float, points: int = 81) -> float:
    """The pitch [m] within one spectral bin (``bin_per_m`` [1/m]) of ``1 / pitch_m`` whose chain
    (:func:`fit_chain`'s least squares) leaves the smallest sum of squares on the masked samples."""
    f0 = 1.0 / float(pitch_m)
    best = (np.inf, float(pitch_m))
    for f in np.linspace(max(f0 - bin_per_m, 0.5 * f0), f0 + bin_per_m, points):
        X, y, _ = _design(df, mask, v_model, 1.0 / f)
        c, *_ = np.linalg.lstsq(X, y, rcond=None)
        sse = float(np.sum((y - X @ c) ** 2))
        if sse < best[0]:
            best = (sse, 1.0 / f)
    return best[1]


def candidate_pitch(df: pd.DataFrame, mask, v_model) -> tuple[dict, float | None, float]:
    """The line of the residual's spectrum over the position (:func:`l1b2.closeloop.residuals.position_spectrum`):
    ``(peak, pitch or None, bin [1/m])``; the pitch is the peak's period when its power exceeds
    :data:`~l1b2.closeloop.residuals.LINE_POWER_RATIO` times the median and the masked positions' span holds it at
    least :data:`MIN_REPEATS` times (the peak records ``repeats``, the span over the period)."""
    mask = np.asarray(mask, bool)
    freq, _, peak = res.position_spectrum(res.drive_residual(df, v_model), df, mask)
    ratio = peak.get("power_ratio_to_median", 0.0)
    if peak:
        peak["repeats"] = float(np.ptp(df[dataio.POSITION].to_numpy(float)[mask]) / peak["period_m"])
    line = bool(np.isfinite(ratio) and ratio > res.LINE_POWER_RATIO   # a zero median (no residual): no line
                and peak.get("repeats", 0.0) >= MIN_REPEATS)
    return peak, (peak["period_m"] if line else None), (float(freq[1] - freq[0]) if len(freq) > 1 else 0.0)


def response(df: pd.DataFrame, v_pred, pitch_m: float) -> np.ndarray:
    """The logged speed's response to ``(c_h, d_h)`` at 0 in drive coordinates, ``d v_pred de'/dcoef`` (n x 4)."""
    d = df[dataio.DIRECTION].to_numpy(float)
    return (d * np.asarray(v_pred, float))[:, None] * slope_rows(df, pitch_m)


def force_response(df: pd.DataFrame, v_pred, params, m_s: float, pitch_m: float) -> np.ndarray:
    """The speed's response (drive coordinates) to the force family :data:`FORCE_FAMILY` at ``pitch_m``: its
    features (:func:`l1b2.predictor.effects.effect_features`) through the slider's linearised dynamics
    (:func:`~l1b2.closeloop.selection.linear_response`)."""
    sig = {"s": df[dataio.POSITION].to_numpy(float), "V0": df[dataio.VOLTAGE].to_numpy(float),
           "d": df[dataio.DIRECTION].to_numpy(float), "v_base": np.asarray(v_pred, float)}
    F = fx.effect_features({"kind": FORCE_FAMILY, "period_m": float(pitch_m)}, sig)
    return linear_response(params, df, m_s, np.asarray(F, float), v_pred=v_pred)


def screen(df: pd.DataFrame, mask, v_pred, params, m_s: float, folds, pitch_m: float) -> dict:
    """Cross-validated evidence of the form against the baseline ``params`` (free run ``v_pred`` [m/s]) and of the
    force family at the same pitch, on the same folds and nuisance (:func:`l1b2.closeloop.stagefit.screen`).

    Returns ``{"cv_gain", "p_value", "runs_improved", "force_cv_gain"}``: the pooled held-out share of the
    nuisance-only model's sum of squares the form's columns (:func:`response`) remove, the runs' one-sided Wilcoxon
    p-value, the share of runs improved, and the held-out share the force family's columns
    (:func:`force_response`) remove.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        force = force_response(df, v_pred, params, m_s, pitch_m)
    return stagefit.screen(df, mask, v_pred, params, m_s, folds, response(df, v_pred, pitch_m), {"force": force})


def screen_passes(rec: dict, alpha: float, min_gain: float) -> bool:
    """Whether the screen (:func:`screen`'s record) is significant at ``alpha``, gains at least ``min_gain`` and
    more than the force family at the same pitch."""
    return bool(rec["p_value"] < alpha and rec["cv_gain"] >= min_gain and rec["cv_gain"] > rec["force_cv_gain"])


def decide(df: pd.DataFrame, mask, m_s: float, folds, model, identify, settings: RefitSettings, *, alpha: float,
           min_gain: float, min_cv_gain: float) -> tuple[dict, tuple | None]:
    """The stage on TRAIN ``df`` against the current ``model`` (the baseline): ``(record, kept)``.

    Considered when the baseline residual's spectrum over the position has a line (:func:`candidate_pitch`).
    Screened (:func:`screen`) at ``alpha`` and the screen's smallest gain ``min_gain``, as every candidate is, and
    only when its held-out gain exceeds the force family's at the same pitch; kept when the physics refitted behind
    the form lowers the cross-validated free-run sum of squares of the logged speed by at least ``min_cv_gain``, in
    more than half of the folds (:func:`l1b2.closeloop.stagefit.stage_verdict`; the pitch refined anew on each
    fold's training runs, :func:`fit_refined`). ``kept``: None, or ``(physics model, CyclicChain)``: the chain from
    the baseline's free run at the pitch refined on TRAIN, the physics identified behind it (``identify(frame)``),
    the chain refitted on that model's free run.
    """
    v_base = model.predict_free_run(df)
    peak, pitch, bin_per_m = candidate_pitch(df, mask, v_base)
    rec = {"effect": CYCLIC_CHAIN, "regressor": REGRESSOR, "considered": pitch is not None, "accepted": False,
           "spectrum_peak": peak}
    if pitch is None:
        return rec, None
    pitch = refine_pitch(df, mask, v_base, pitch, bin_per_m)
    rec.update(screen(df, mask, v_base, model.params_, m_s, folds, pitch), pitch_m=pitch)
    if not screen_passes(rec, alpha, min_gain):
        return rec, None
    cv = stagefit.stage_cv_errors(df, mask, m_s, folds, model.params_, settings, v_base,
                                  partial(fit_refined, pitch_m=pitch, bin_per_m=bin_per_m), "l1b2-cyclic-chain-cv")
    fields, kept = stagefit.stage_verdict(cv, len(folds), min_cv_gain)
    rec.update(fields)
    if not kept:
        return rec, None
    est, c1 = stagefit.physics_behind(df, mask, v_base, partial(fit_chain, pitch_m=pitch), identify)
    rec.update(accepted=True, description=DESCRIPTION, **c1.to_dict())
    return rec, (est, c1)
