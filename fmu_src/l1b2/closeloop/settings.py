"""The close loop's settings in one frozen record: the keyword arguments of :class:`l1b2.closeloop.loop.CloseLoop`
and :func:`l1b2.closeloop.loop.close_loop`, their defaults and meaning (:class:`LoopSettings`), and the rules
its report records (:meth:`LoopSettings.rules`)."""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field, fields
from typing import Any

from ..errors import L1B2Error
from .acceptance import (DEFAULT_MIN_CV_DROP, DEFAULT_MIN_CV_GAIN, DEFAULT_REFIT_FOLDS, DEFAULT_REFIT_NFEV,
                         DEFAULT_REFIT_REPEATS, DEFAULT_TIE_REPEATS)
from .selection import DEFAULT_ALPHA, DEFAULT_PARSIMONY, SHORTLIST_MIN_GAIN

__all__ = ["LoopSettings", "keyword_signature"]


@dataclass(frozen=True)
class LoopSettings:
    """The settings of one close loop, with their defaults.

    Parameters
    ----------
    order : int
        Polynomial order of the predictor's A, B, P (paper: 8).
    k_folds : int
        Cross-validation folds over runs.
    alpha : float
        Significance level, Bonferroni-corrected over the candidate families.
    min_gain : float
        Smallest linearised held-out share of the residual for a candidate to be shortlisted.
    parsimony : float
        Accepted candidates within this share of the best CV gain count as equally good
        (named before generic, then fewer parameters).
    seed : int
        Seed of the folds and of the baseline's multi-start.
    n_starts : int
        Multi-start local searches of the baseline identification.
    noise_fit : {"alternate", "auto", "profile"}
        The baseline identification's search (:class:`l1b2.ident.estimator.PredictorIdentifier`;
        default ``"alternate"``, with which the loop's results were measured); the refits are
        warm-started local searches either way.
    noise : {"common", "per_run"}
        The noise variances of every identification of the loop (baseline, refits): one common
        variance (default, the paper's single R) or one per run (see ``PredictorIdentifier``).
    library : CandidateSource, optional
        Candidate library ``(ctx, df_train) -> list[CandidateForce]``;
        default :func:`l1b2.closeloop.candidates.full_library` (one-regressor and two-regressor candidates).
    progress : callable, optional
        Called with a short message at the start of each stage.
    client : dask.distributed.Client, optional
        Where the cross-validated refits run (:func:`l1b2.cluster.dask_client`): each fold of each trial is
        one task, spread over the cluster's workers; ``None``: in this process, in order. The result does
        not depend on it.
    max_rounds : int
        Most effects added (one per round).
    shortlist : int
        Candidates (best of their family by linearised gain) refit and cross-validated per round.
    refit_folds : int
        Folds over runs of the cross-validated refit (stratified by direction and voltage).
    refit_repeats : int
        Splits of the runs into ``refit_folds`` folds for a round's acceptance
        (:func:`~l1b2.closeloop.folds.refit_schemes`, from ``seed``).
    tie_repeats : int
        When a round's refit over the run folds meets every acceptance rule but the fold majority with exactly
        half of its folds improved (:func:`~l1b2.closeloop.acceptance.tied`), the round's refits over the run
        folds (the current model's and every such trial's) are cross-validated again over this many splits
        (:func:`~l1b2.closeloop.folds.refit_schemes`; the first is the round's own) and decided there. Not
        above ``refit_repeats``: off. The session's folds are one split: a clock candidate's tie stays a refusal.
    min_cv_gain : float
        Smallest relative fall of the cross-validated free-run sum of squares (in most folds) to add an effect.
    min_cv_drop : float
        Smallest absolute fall of the cross-validated free-run nrmse to add a *structural* term (one that
        relaxes Eq. 29's own linearisation, ``CandidateForce.structural``): the materiality threshold.
        Other candidates need only ``min_cv_gain`` in most folds.
    refit_nfev, final_nfev : int
        Function evaluations of each fold's warm refit and of the joint re-identification after a round.
    screen_alpha : float or None
        When no candidate passes the Bonferroni-corrected screen, the best one whose run-level p-value is
        below this uncorrected level is still refit and cross-validated (one per round; ``None``: off).
        The screen only decides what is worth the refit: Bonferroni over ~30 families misses an effect
        whose per-run gains are uneven (a drift in time) although the re-identified model improves on
        held-out runs; what is added is decided by the acceptance rule. A screened round costs the
        cross-validated refits of the current model and of one candidate (and, if it is accepted, the
        next round).
    stroke_speed_gain : bool
        When the speed channel keeps no filter, test the speed sensor's gain along the stroke (a measurement
        effect, :mod:`l1b2.closeloop.sensor`) before the rounds, and keep it when the cross-validated rule says so.
        Off by default: the stage is decided against the baseline alone, before the force candidates compete.
    run_level : bool
        Each round, estimate every run's own deviation from the current model (a drive-force gain and an
        offset, shrunk as random effects) and offer the run-level signal that best explains them
        (:mod:`l1b2.closeloop.runlevel`, Bonferroni over the signals' effective number of tests) as one more
        candidate of the cross-validated refit; among accepted candidates within ``parsimony`` of the best, a form
        constant along the stroke is preferred over a within-run form when the run-level evidence names its regressor.
    session_cycle : bool
        With ``run_level``, also search each round's runs for a cycle of the session clock
        (:mod:`l1b2.closeloop.cycle`, its waves free of the plan's inputs per run) and offer a significant one as
        the family ``session_cycle``. Off by default: a cycle of a few runs followed the plan's own pattern before
        the waves were free of it (decision 0179), and the stored cases are not swept again yet (decision 0180).
    clock_folds : {"blocks", "rotation"}
        Folds of the candidates that depend on the session clock (screen and refit, whatever ``run_level``):
        ``"blocks"`` k contiguous blocks, ``"rotation"`` conditions dealt in turn (:mod:`~l1b2.closeloop.acceptance`).
    fold_unit : {"run", "condition"}
        Folds of the other candidates (screen and refit): ``"run"`` runs (the refit's stratified by direction and
        voltage), ``"condition"`` whole conditions, a drive amplitude and a load with all their runs
        (:func:`~l1b2.closeloop.folds.condition_folds`).
    response_columns : tuple of str or None
        Logged columns that are measured responses of the motor: listed in ``channels_considered``, never
        offered as a cause. None: :data:`l1b2.predictor.effects.channels.RESPONSE_COLUMNS` (the virtual rig's
        ``tip_velocity_amp_m_s``) and every column the consequence test classes a response of the motion
        (:mod:`l1b2.closeloop.responses`); a tuple replaces that list and the test (``()``: every logged column is
        a candidate).

    baseline : {"eq29", "best", "pure_slip"}
        The predictor family the loop starts from: ``"eq29"`` (default), ``"pure_slip"``, or ``"best"``,
        which identifies both on TRAIN and keeps Eq. 29 unless the pure-slip family's cross-validated
        free-run nrmse over the refit folds is lower by at least ``min_cv_drop``
        (:func:`l1b2.closeloop.baselines.choose_baseline`; both figures in ``diagnosis.baseline_choice``;
        a pure-slip fit that diverges is recorded there and the loop starts from Eq. 29). With the
        pure-slip family no candidate counts as relaxing Eq. 29 (a load x voltage term is a missing
        effect). Why ``"best"`` is not yet the default: ``docs/decisions/0026-best-baseline-by-default.md``,
        ``0032-run-level-effects-in-predictor-fmu.md``, ``0033-named-before-collinear-generic.md`` and
        ``0040-why-the-named-pulley-form-loses-from-pure-slip.md``.
    """

    order: int = 8
    k_folds: int = 5
    alpha: float = DEFAULT_ALPHA
    min_gain: float = SHORTLIST_MIN_GAIN
    parsimony: float = DEFAULT_PARSIMONY
    seed: int = 0
    n_starts: int = 4
    library: Any = None
    progress: Any = field(default=None, compare=False)
    max_rounds: int = 3
    shortlist: int = 2
    refit_folds: int = DEFAULT_REFIT_FOLDS
    refit_repeats: int = DEFAULT_REFIT_REPEATS
    tie_repeats: int = DEFAULT_TIE_REPEATS
    min_cv_gain: float = DEFAULT_MIN_CV_GAIN
    min_cv_drop: float = DEFAULT_MIN_CV_DROP
    refit_nfev: int = DEFAULT_REFIT_NFEV
    final_nfev: int = 60
    screen_alpha: float | None = 0.01
    noise_fit: str = "alternate"
    noise: str = "common"
    client: Any = field(default=None, compare=False)
    baseline: str = "eq29"
    run_level: bool = True
    session_cycle: bool = False
    stroke_speed_gain: bool = False
    response_columns: tuple | None = None
    clock_folds: str = "blocks"
    fold_unit: str = "run"

    def as_dict(self) -> dict:
        """name -> value of every setting, in the order of the fields (the values themselves, not copies)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def rules(self) -> dict:
        """The rules the report records (``diagnosis.rules`` of ``report.json``): the thresholds, folds and searches
        that decide what is added; ``response_columns`` as a list (None: the default list)."""
        return {"min_gain": self.min_gain, "alpha": self.alpha, "parsimony": self.parsimony,
                "k_folds": self.k_folds, "shortlist": self.shortlist, "refit_folds": self.refit_folds,
                "refit_repeats": self.refit_repeats, "tie_repeats": self.tie_repeats, "min_cv_gain": self.min_cv_gain,
                "min_cv_drop": self.min_cv_drop, "screen_alpha": self.screen_alpha,
                "noise_fit": self.noise_fit, "noise": self.noise, "fold_unit": self.fold_unit,
                "max_rounds": self.max_rounds, "run_level": self.run_level, "session_cycle": self.session_cycle,
                "stroke_speed_gain": self.stroke_speed_gain,
                "clock_folds": self.clock_folds,
                "response_columns": (list(self.response_columns) if self.response_columns is not None
                                     else None)}


def response_setting(names, none: bool = False) -> dict:
    """The loop's ``response_columns`` keyword from a command line: ``names`` (a list, None when not given), none
    (``none``: every logged column a candidate, no test), or nothing (the default list and the consequence test).
    Raises :class:`l1b2.errors.L1B2Error` when both are given."""
    if none and names:
        raise L1B2Error("--no-response-columns and --response-column contradict each other: give one")
    if none:
        return {"response_columns": ()}
    return {"response_columns": tuple(names)} if names else {}


def keyword_signature(record: type) -> inspect.Signature:
    """The signature ``(self, *, name=default, ...)`` of a constructor that takes the fields of the dataclass
    ``record`` as keyword arguments, in their order (what :class:`l1b2.ident.convention.EstimatorSettings` reads
    the settings from)."""
    params = [inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    params += [inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default) for f in fields(record)]
    return inspect.Signature(params)
