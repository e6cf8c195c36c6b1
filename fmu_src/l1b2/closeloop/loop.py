"""Close the loop with measured data: residual -> missing effect -> extended model -> error before and after.

:class:`CloseLoop` is the estimator (scikit-learn convention: ``__init__``
stores the settings, :meth:`CloseLoop.fit` takes validated
:class:`l1b2.data.measurements.Measurements` and sets ``result_``, a
:class:`~l1b2.closeloop.result.CloseLoopResult`); :func:`close_loop` is the
one-call form. No file is read or written and nothing is plotted here
(:func:`l1b2.workflows.run_close_loop` does the files).

Procedure (TEST is never used for fitting or choosing):

1. **Baseline**: the Eq. 29 predictor identified on TRAIN by maximum likelihood
   (free-run criterion; sigma, k0, mu, mu_sd pinned, which leaves the
   predictions unchanged and makes the fit well posed, see :mod:`l1b2.ident.estimator`).
2. **Residual analysis** on TRAIN (:mod:`l1b2.closeloop.residuals`): drive-coordinate
   free-run residual; whiteness per run; spectrum over position; evidence per
   regressor by cross-validation over runs, traced by forward selection.
3. **Candidates** from the library (:mod:`l1b2.closeloop.candidates`; default:
   every named family over its shape grid and a generic smooth term per
   regressor), each scored exactly against the fixed baseline
   (:mod:`l1b2.closeloop.selection`: held-out gain over runs, run-level
   Wilcoxon p-value, AIC/BIC).
4. **Selection** (:func:`l1b2.closeloop.selection.choose`): significant when
   the held-out gain is at least ``min_gain``, the run-level p-value below
   ``alpha`` / number of families and the AIC improves; the most parsimonious
   significant candidate within ``parsimony`` of the best gain is chosen.
   Otherwise: "no significant missing effect" and the baseline is kept.
5. **Extended model**: baseline + chosen candidate, re-identified jointly by
   maximum likelihood (warm start from the baseline); both models are
   reported on TEST.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..data.metrics import report_metrics
from ..ident.estimator import ExtraForces, PredictorIdentifier
from . import residuals as res
from .candidates import CandidateSource, Context, default_library
from .result import CloseLoopResult, ResidualAnalysis
from .selection import (DEFAULT_ALPHA, DEFAULT_MIN_GAIN, DEFAULT_PARSIMONY, Choice, Score, best_per_family,
                        choose, score_candidates)


def _quiet(msg: str) -> None:
    pass


class CloseLoop:
    """Find the missing effect in the free-run residual of the Eq. 29 predictor, add it, report before/after.

    Parameters
    ----------
    order : int
        Polynomial order of the predictor's A, B, P (paper: 8).
    k_folds : int
        Cross-validation folds over runs.
    alpha : float
        Significance level, Bonferroni-corrected over the candidate families.
    min_gain : float
        Smallest held-out share of the residual a candidate must explain.
    parsimony : float
        Candidates within this share of the best gain count as equally good.
    seed : int
        Seed of the folds and of the baseline's multi-start.
    n_starts : int
        Multi-start local searches of the baseline identification.
    library : CandidateSource, optional
        Candidate library ``(ctx, df_train) -> list[CandidateForce]``;
        default :func:`l1b2.closeloop.candidates.default_library`.
    progress : callable, optional
        Called with a short message at the start of each stage.

    Attributes
    ----------
    result_ : CloseLoopResult
        Set by :meth:`fit`.
    """

    def __init__(self, *, order: int = 8, k_folds: int = 5, alpha: float = DEFAULT_ALPHA,
                 min_gain: float = DEFAULT_MIN_GAIN, parsimony: float = DEFAULT_PARSIMONY, seed: int = 0,
                 n_starts: int = 4, library: CandidateSource | None = None, progress=None):
        self.order = order
        self.k_folds = k_folds
        self.alpha = alpha
        self.min_gain = min_gain
        self.parsimony = parsimony
        self.seed = seed
        self.n_starts = n_starts
        self.library = library
        self.progress = progress

    def get_params(self) -> dict:
        """The settings given to ``__init__``."""
        return {k: getattr(self, k) for k in ("order", "k_folds", "alpha", "min_gain", "parsimony", "seed",
                                              "n_starts", "library", "progress")}

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items() if k != "progress")
        return f"CloseLoop({args})"

    # -- the job -------------------------------------------------------------
    def fit(self, train: dataio.Measurements, test: dataio.Measurements | None = None) -> CloseLoop:
        """Identify, diagnose, extend and re-identify on ``train``; report on ``train`` and ``test``.

        ``train``/``test`` are :class:`l1b2.data.measurements.Measurements`
        (``load_measurements(path)``); the slider mass is ``train``'s.
        ``test`` is only predicted, never used to fit or choose.
        """
        _check_measurements(train, "train")
        if test is not None:
            _check_measurements(test, "test")
        say = self.progress or _quiet
        t_start = time.perf_counter()
        m_s = train.slider_mass_kg
        dtr = train.df
        dte = test.df if test is not None else None
        mask_tr = np.array(train.mask)

        say("baseline: identifying the Eq. 29 predictor on TRAIN")
        base = PredictorIdentifier(order=self.order, criterion="free_run", fixed="recommended",
                                   n_starts=self.n_starts, seed=self.seed)
        base.fit(dtr, slider_mass_kg=m_s, mask=mask_tr)
        v_tr = base.predict_free_run(dtr)
        v_te = base.predict_free_run(dte) if dte is not None else None
        baseline = {"train": report_metrics(dtr, base.predict_one_step(dtr), v_tr),
                    "test": report_metrics(dte, base.predict_one_step(dte), v_te) if dte is not None else None}

        say("residual analysis on TRAIN")
        analysis = analyse_residuals(dtr, v_tr, mask_tr, alpha=self.alpha, k=self.k_folds, seed=self.seed)

        say("scoring candidate effects")
        ctx = candidate_context(base.predict_free_run, m_s, dtr, mask_tr, analysis.peak)
        library = self.library if self.library is not None else default_library()
        scores = score_candidates(library(ctx, dtr), analysis.residual, dtr, mask_tr, base.params_, m_s,
                                  v_pred=v_tr, k=self.k_folds, seed=self.seed)
        choice = choose(scores, alpha=self.alpha, min_gain=self.min_gain, parsimony=self.parsimony)

        ext = extended = ext_params = v_te_ext = None
        if choice.chosen is not None:
            say(f"extended model: re-identifying with {choice.chosen.candidate.label}")
            ext = self._extend(base, choice.chosen, dtr, m_s, mask_tr)
            v_te_ext = ext.predict_free_run(dte) if dte is not None else None
            extended = {"train": report_metrics(dtr, ext.predict_one_step(dtr), ext.predict_free_run(dtr)),
                        "test": (report_metrics(dte, ext.predict_one_step(dte), v_te_ext)
                                 if dte is not None else None)}
            c = choice.chosen.candidate
            ext_params = {n: {"value": float(ext.extra_params_[n]), "stderr": float(ext.extra_stderr_[n]),
                              "ci95": [float(x) for x in ext.extra_ci95_[n]], "unit": u}
                          for n, u in zip(c.names, c.units)}

        self.result_ = CloseLoopResult(
            baseline=baseline, diagnosis=self._diagnosis(choice, scores, analysis), scores=scores,
            significant=choice.significant, chosen=choice.chosen, extended=extended,
            extended_parameters=ext_params, baseline_parameters=base.to_dict()["parameters"],
            data=_data_summary(train, test), wall_time_s=round(time.perf_counter() - t_start, 2),
            baseline_model=base, extended_model=ext, analysis=analysis, train_df=dtr, test_df=dte,
            test_free_run_before=v_te, test_free_run_after=v_te_ext)
        return self

    def _extend(self, base, chosen: Score, dtr: pd.DataFrame, m_s: float, mask: np.ndarray):
        """Baseline + the chosen candidate, re-identified jointly (warm start from the baseline and phi)."""
        c = chosen.candidate
        extra = ExtraForces(names=c.names, units=c.units, features=c.features, start=tuple(chosen.phi),
                            description=c.description)
        ext = PredictorIdentifier(order=self.order, criterion="free_run", fixed="recommended", n_starts=1,
                                  seed=self.seed, extra=extra, init=base.params_, init_extra=np.asarray(chosen.phi))
        ext.fit(dtr, slider_mass_kg=m_s, mask=mask)
        return ext

    def _diagnosis(self, choice: Choice, scores: list[Score], a: ResidualAnalysis) -> dict:
        """The report's ``diagnosis`` section."""
        chosen = choice.chosen
        c = chosen.candidate if chosen is not None else None
        traced_to = [c.regressor] + [r for r in a.traced if r != c.regressor] if c is not None else []
        w = a.whiteness
        return {
            "significant": c is not None,
            "traced_to": traced_to,
            "effect": c.family if c else None,
            "effect_shape": c.shape if c else None,
            "effect_description": c.description if c else None,
            "message": f"missing effect: {c.label} ({c.regressor})" if c else "no significant missing effect",
            "residual_trace": a.traced,
            "candidates": [s.to_dict() for s in best_per_family(scores)],
            "n_candidates_scored": len(scores),
            "significance_level": choice.level,
            "rules": {"min_gain": self.min_gain, "alpha": self.alpha, "parsimony": self.parsimony,
                      "k_folds": self.k_folds},
            "regressor_evidence": [[e.to_dict() for e in rnd] for rnd in a.rounds],
            "whiteness": {"runs": len(w),
                          "share_runs_ljung_box_p_below_0.05": (float(np.mean([x["ljung_box_p"] < 0.05 for x in w]))
                                                                if w else None),
                          "median_rho1": float(np.median([x["rho1"] for x in w])) if w else None},
            "position_spectrum_peak": a.peak,
        }


def close_loop(train: dataio.Measurements, test: dataio.Measurements | None = None, **settings) -> CloseLoopResult:
    """``CloseLoop(**settings).fit(train, test).result_`` (settings: see :class:`CloseLoop`)."""
    return CloseLoop(**settings).fit(train, test).result_


# ---------------------------------------------------------------------------
# stages
# ---------------------------------------------------------------------------

def analyse_residuals(df: pd.DataFrame, v_pred: np.ndarray, mask: np.ndarray, *, alpha: float, k: int,
                      seed: int) -> ResidualAnalysis:
    """Drive-coordinate residual, whiteness, position spectrum and regressor trace (TRAIN)."""
    r = res.drive_residual(df, v_pred)
    whiteness = res.whiteness(r, df, mask)
    freq, power, peak = res.position_spectrum(r, df, mask)
    traced, rounds = res.trace(r, df, mask, alpha=alpha, k=k, seed=seed)
    return ResidualAnalysis(residual=r, mask=mask, whiteness=whiteness, frequency=freq, power=power, peak=peak,
                            traced=traced, rounds=rounds)


def candidate_context(baseline_free_run, m_s: float, df: pd.DataFrame, mask: np.ndarray, peak: dict) -> Context:
    """What candidate features may use: the baseline's free run, the mass, TRAIN's ranges, the spectral peak."""
    pos = df[dataio.POSITION].to_numpy(float)[mask]
    return Context(
        baseline_free_run=baseline_free_run, m_s=float(m_s),
        time_range=(float(df[dataio.TIME].min()), float(df[dataio.TIME].max())),
        position_range=(float(pos.min()), float(pos.max())),
        temperature_ref=float(df[dataio.TEMPERATURE].median()) if dataio.TEMPERATURE in df.columns else None,
        spectral_period_m=peak.get("period_m") if peak.get("power_ratio_to_median", 0) > 4 else None)


def _check_measurements(m, name: str) -> None:
    if not isinstance(m, dataio.Measurements):
        raise TypeError(f"{name}: expected l1b2.data.measurements.Measurements (validated data, e.g. "
                        f"load_measurements(path)), got {type(m).__name__}")


def _data_summary(train: dataio.Measurements, test: dataio.Measurements | None) -> dict:
    def where(m):
        return str(m.path) if m is not None and m.path is not None else None
    return {"train": where(train), "test": where(test), "train_runs": len(train.runs),
            "test_runs": len(test.runs) if test is not None else 0, "train_samples": train.n_samples,
            "test_samples": test.n_samples if test is not None else 0}
