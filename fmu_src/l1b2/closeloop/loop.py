"""Close the loop with measured data: residual -> missing effect -> extended model -> error before and after.

:class:`CloseLoop` is the estimator (scikit-learn convention, shared with
:class:`~l1b2.ident.estimator.PredictorIdentifier` through
:class:`~l1b2.ident.convention.EstimatorSettings`: ``__init__`` stores the
settings, ``get_params``/``set_params`` read and change them), :meth:`CloseLoop.fit` takes validated
:class:`l1b2.data.measurements.Measurements` and sets ``result_``, a
:class:`~l1b2.closeloop.result.CloseLoopResult`); :func:`close_loop` is the
one-call form. No file is read or written and nothing is plotted here
(:func:`l1b2.workflows.run_close_loop` does the files).

Procedure (TEST is never used for fitting or choosing):

1. **Baseline**: the Eq. 29 predictor identified on TRAIN by maximum likelihood
   (free-run criterion; sigma, k0, mu, mu_sd pinned, which leaves the
   predictions unchanged and makes the fit well posed, see :mod:`l1b2.ident.estimator`).
2. **Measurement chain** (:meth:`CloseLoop._chain`): when the speed column is a
   filtered derivative of the position, the physics is re-identified on the
   derivative and the filter applied to its predictions (:class:`ChainModel`);
   everything below then works on the derivative.
3. **Residual analysis** on TRAIN (:mod:`l1b2.closeloop.residuals`): drive-coordinate
   free-run residual; whiteness per run; spectrum over position; evidence per
   regressor by cross-validation over runs, traced by forward selection.
4. **Rounds** (at most ``max_rounds``), each against the *current* model
   (the baseline plus the effects accepted so far):

   a. *shortlist*: every candidate of the library (default
      :func:`l1b2.closeloop.candidates.full_library`; families already added
      excluded, candidates that could reproduce an added force,
      :func:`~l1b2.closeloop.acceptance.collinear`, and a generic term sharing a direction with an added named
      effect or the reverse, :meth:`~l1b2.closeloop.acceptance.Directions.conflicts`) scored exactly against the
      fixed current model
      (:mod:`l1b2.closeloop.selection`: linearised held-out gain over runs,
      run-level Wilcoxon p-value, AIC); the best of each family passing
      ``min_gain``, ``alpha`` / number of families and an AIC improvement,
      the best ``shortlist`` of them (when none passes and ``screen_alpha``
      is set: the best family at that uncorrected level, judged by its best hypothesis that passes,
      :func:`~l1b2.closeloop.selection.screened`), and for a shortlisted generic term the named family that
      explains most of its force (:func:`~l1b2.closeloop.selection.named_alternatives`), and for a shortlisted
      family the best of each of its other shapes that passes the same screen
      (:func:`~l1b2.closeloop.selection.shape_alternatives`: the refit chooses a channel's shape); with nothing
      to refit, the last round's accepted candidate that points elsewhere and is still shown
      (:func:`~l1b2.closeloop.selection.carried`);
   b. *acceptance* (:mod:`l1b2.closeloop.acceptance`): current model and current model + candidate re-identified on
      ``refit_folds`` - 1 run folds (warm start, bounded budget) and predicting the held-out fold in free run;
      accepted when the pooled held-out sum of squares falls by ``min_cv_gain`` in most folds; of a family's accepted
      shapes the simplest within one standard error of its best
      (:func:`~l1b2.closeloop.selection.simplest_within_one_se`); the most parsimonious within ``parsimony`` of the
      best CV gain is added, a named family instead of a generic term it explains unless the generic one is better by
      more than one standard error (:func:`~l1b2.closeloop.acceptance.named_reading`), the inputs' trial instead of an
      auxiliary channel they explain on the same terms (:func:`~l1b2.closeloop.acceptance.input_reading`); from the
      Eq. 29 baseline a named pick must be accepted again from the pure-slip family, else its reading is withdrawn and
      the same force is added as a generic term of the reduced model
      (:func:`~l1b2.closeloop.crosscheck.confirmed_pick`, decision 0043); a pick read as physics is named only when
      its parameters are jointly different from zero under the reported covariance at ``alpha``, else the round's next
      trial is taken (:func:`~l1b2.closeloop.crosscheck.identified_pick`);
   c. *joint re-identification* of the model with every accepted effect
      (warm start).

   The rounds stop when no shortlisted candidate is accepted. Otherwise "no significant missing effect" and the
   baseline is kept.
5. Both the baseline and the final model are reported on TEST, with the metrics after every round.
   ``diagnosis.traced_to`` lists the regressors of the added effects strongest first, the terms that only relax
   Eq. 29's own linearisation after the missing effects (:func:`l1b2.closeloop.evidence.order_traced`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..ident.coarse import coarse_to_fine, nfev_of
from ..ident.convention import EstimatorSettings
from ..ident.estimator import PredictorIdentifier
from ..predictor.model import DRIVE_LAWS
from ..predictor.effects import channels as fx_channels
from . import chain
from . import residuals as res
from . import othersession, ranges, runlevel
from .othersession import metrics
from .candidates import Context, baseline_damping, channels_of, full_library, range_check, training_summary
from .settings import LoopSettings, keyword_signature
from .stages import StageClock
from .auxiliary import check_test_columns
from .calibrated import calibrated_model
from . import sensor
from .sensor import GainChain
from . import encoder, sensorchain, stamps
from .sensorchain import SensorChain
from .acceptance import (Directions, EffectSet, RefitCV, RefitSettings, Validated, accepts, added_columns,
                         block_checked, chain_cv_errors, collinear, cv_errors, fold_start_phi, immaterial,
                         input_reading, materiality, named_reading, refit, tied, time_dependent, validated)
from .stagefit import physics_behind, stage_cv_errors, stage_verdict
from .folds import refit_schemes, screen_folds, stratified_folds
from .baselines import choose_baseline, identify_families, retag_structural
from .crosscheck import PureSlipCheck, identified_pick, score_of, withdrawn_note
from .derived import prepare_channels, with_protocol_channels
from .events import session
from .responses import classed_responses, response_tests, with_applied
from .evidence import (channels_considered, order_traced, with_auxiliary, with_onset, with_position_share,
                       with_response_test)
from .guard import checked_fit, checked_identification
from .intervals import added_parameters, identification, train_levels
from .result import CloseLoopResult, ResidualAnalysis
from .selection import (Score, best_per_family, counted_params, design, nuisance_forces, refit_list,
                        score_candidates, screen_mask, screened, significance_level, simplest_within_one_se,
                        to_carry)


def _quiet(msg: str) -> None:
    pass


class CloseLoop(EstimatorSettings):
    """Find the missing effect in the free-run residual of the Eq. 29 predictor, add it, report before/after.

    Parameters
    ----------
    **settings
        The fields of :class:`~l1b2.closeloop.settings.LoopSettings`, by name (their defaults and meaning there);
        each is stored as an attribute of the same name, :attr:`settings` is them as one record.

    Attributes
    ----------
    result_ : CloseLoopResult
        Set by :meth:`fit`.
    """

    def __init__(self, **settings):
        for name, value in LoopSettings(**settings).as_dict().items():   # an unknown name: TypeError
            setattr(self, name, value)

    __init__.__signature__ = keyword_signature(LoopSettings)

    @property
    def settings(self) -> LoopSettings:
        """The current settings as one frozen record."""
        return LoopSettings(**self.get_params())

    # -- the job -------------------------------------------------------------
    def fit(self, train: dataio.Measurements, test: dataio.Measurements | None = None) -> CloseLoop:
        """Identify, diagnose, extend round by round and re-identify on ``train``; report on ``train`` and ``test``.

        ``train``/``test`` are :class:`l1b2.data.measurements.Measurements`
        (``load_measurements(path)``); the slider mass is ``train``'s.
        ``test`` is only predicted, never used to fit or choose.
        """
        _check_measurements(train, "train")
        responses = fx_channels.RESPONSE_COLUMNS if self.response_columns is None else self.response_columns
        if test is not None:
            _check_measurements(test, "test")
            check_test_columns(train, test, responses)
        say = StageClock(self.progress or _quiet)  # times every stage it announces (report.json "stages")
        t_start = time.perf_counter()
        m_s = train.slider_mass_kg
        dtr, dte = train.df, (test.df if test is not None else None)
        sess = session(dtr, dte)   # the runs on the clock, for both derivations of logged channels
        dtr, dte, aux_rec, responses = prepare_channels(dtr, dte, responses)   # derivable names, flags, labels, gaps
        response_rec = response_tests(dtr, responses)   # columns that follow the speed: responses unless set
        responses = self.response_columns_ = classed_responses(self.response_columns, responses, response_rec)
        dtr, dte, derived_rec = with_protocol_channels(dtr, dte, responses, sess, response_rec)   # clocks, lags, ...
        mask_tr = np.array(train.mask)
        folds = stratified_folds(dtr, self.refit_folds, self.seed)   # TRAIN's run folds, one split for the fit

        if self.baseline not in ("best",) + DRIVE_LAWS:
            raise ValueError(f"baseline must be 'best' or one of {DRIVE_LAWS}, got {self.baseline!r}")
        self.frequency_, searches = None, {}   # searches: per family, the baseline's check against the level law
        def fit_family(family, df=dtr, what="baseline"):
            say(f"{what}: identifying the {family} predictor on TRAIN")
            est = checked_identification(lambda **kw: self._identify(df, m_s, mask_tr, model=family, **kw), df, mask_tr,
                                         f"the {family} {what} identification on TRAIN",
                                         searches.setdefault(family + ("" if what == "baseline" else f" ({what})"), {}))
            say.count(1, nfev_of(est))
            return est
        fits, failed = identify_families(DRIVE_LAWS if self.baseline == "best" else (self.baseline,), fit_family)
        family, self.baseline_choice_ = next(iter(fits)), {"chosen": next(iter(fits)), "families": {}}
        if len(fits) > 1:
            say("baseline: cross-validating both families on TRAIN's run folds")
            family, self.baseline_choice_ = choose_baseline(fits, dtr, mask_tr, m_s, folds, self.refit_settings(),
                                                            min_drop=self.min_cv_drop)
            say.count(*(sum(r[k] for r in self.baseline_choice_["families"].values()) for k in ("refits", "nfev")))
        self.baseline_choice_["families"].update({f: {"fit_failed": why} for f, why in failed.items()})
        self.baseline_choice_["search"] = searches
        base = fits[family]
        #: the baseline's drive-frequency response (estimated when TRAIN's frequency varies): every refit holds it
        self.frequency_ = base.result_.frequency_response
        v_te = base.predict_free_run(dte) if dte is not None else None
        baseline = metrics(base, dtr, dte)
        it = _Iteration(model=base, effects=EffectSet(), rounds=[{"round": 0, "added": None, "metrics": baseline}])

        say("measurement chain: speed column against the position's derivative")
        chain_rec, fit_tr = self._chain(it, dtr, dte, mask_tr, m_s, folds)
        start = it.model     # the physics model the rounds extend (fitted on fit_tr)
        stage = next((s for s in (it.output_filter, it.speed_gain, it.sensor_stage) if s is not None), None)
        wrap = (lambda mdl: ChainModel(mdl, stage)) if stage is not None else (lambda mdl: mdl)

        say("residual analysis on TRAIN")
        analysis = analyse_residuals(fit_tr, start.predict_free_run(fit_tr), mask_tr, alpha=self.alpha,
                                     k=self.k_folds, seed=self.seed)
        ctx = candidate_context(start.predict_free_run, m_s, fit_tr, mask_tr, analysis.peak,
                                response_columns=responses,
                                damping=baseline_damping(start, fit_tr, mask_tr))
        library = self.library if self.library is not None else full_library()
        pool = retag_structural(library(ctx, fit_tr), start.params_.drive_law)
        it.channels = with_position_share(training_summary(ctx, fit_tr).channels, fit_tr, mask_tr, start.params_)
        # a named pick from Eq. 29 is confirmed from the pure-slip family (decision 0043): that family's fit
        other = (None if start.params_.drive_law != "eq29" else (lambda: fits["pure_slip"]) if (
            "pure_slip" in fits and fit_tr is dtr) else (lambda: fit_family("pure_slip", fit_tr, "named-effect check")))
        one = dte is None or sess.one    # TEST on TRAIN's clock: else a fact of TRAIN's session predicts its average
        tested = lambda mdl: wrap(othersession.for_test(mdl, it.effects, one))  # noqa: E731
        self._iterate(it, pool, fit_tr, mask_tr, m_s, lambda mdl: metrics(wrap(mdl), dtr, dte, test_model=tested(mdl)),
                      say, ctx, other, folds)
        ext_te = tested(it.model)
        it.model = wrap(it.model)

        ext = it.model if (it.effects.candidates or stage is not None) else None
        v_te_ext = ext_te.predict_free_run(dte) if (ext is not None and dte is not None) else None
        extended = it.rounds[-1]["metrics"] if ext is not None else None
        levels = train_levels(ext, fit_tr) if ext is not None else None    # the reported interval's clusters
        ext_params = added_parameters(ext, it.effects, levels) if ext is not None else None
        if it.output_filter is not None:
            ext_params.update({f"speed_filter_{k}": {"value": v, "stderr": None, "ci95": None, "unit": "1"}
                               for k, v in (("a", it.output_filter.a), ("b0", it.output_filter.b0),
                                            ("b1", it.output_filter.b1))})
            ext_params.update({f"speed_clip_{k}": {"value": v, "stderr": None, "ci95": None, "unit": "m/s"}
                               for k, v in it.output_filter.params().items() if k.endswith("_m_s")})
        if it.sensor_stage is not None:
            ext_params.update(it.sensor_stage.parameters())
        if it.speed_gain is not None:
            g = it.speed_gain.gain
            ses = g.stderr or (None,) * len(g.coef)
            ext_params.update({n: {"value": c, "stderr": se, "unit": "1",
                                   "ci95": None if se is None else [c - 1.96 * se, c + 1.96 * se]}
                               for n, c, se in zip(g.names(), g.coef, ses)})
        calibrated, why = calibrated_model(start, ext, it.effects, it.output_filter,
                                           {**_data_summary(train, test), "operating_points": _operating_points(dtr),
                                            **({"auxiliary_columns": aux_rec} if aux_rec else {})},
                                           levels, None if it.speed_gain is None else it.speed_gain.gain, dtr)
        why += it.sensor_stage.model_note() if calibrated is not None and it.sensor_stage is not None else ""
        first = it.first_scores or []
        chosen = it.chosen
        diagnosis = {**self._diagnosis(it, first, analysis, ext_params, chain_rec), "auxiliary_columns": aux_rec,
                     "response_test": with_applied(response_rec, self.response_columns, responses),
                     **derived_rec,
                     "unseen_levels": ranges.unseen_test_levels(it.effects.candidates, dte),
                     "test_session": othersession.record(one, it.effects),
                     "channel_ranges": ranges.channel_ranges(it.effects.candidates, dtr, dte)}
        diagnosis["channels_considered"] = with_response_test(
            with_auxiliary(diagnosis["channels_considered"], aux_rec), diagnosis["response_test"])
        diagnosis = with_onset(diagnosis, train.meta.get("rest_before_onset"), dtr, it.channels, self.alpha)
        self.result_ = CloseLoopResult(
            baseline=baseline, diagnosis=diagnosis, scores=first,
            significant=it.significant, chosen=chosen, extended=extended,
            extended_parameters=ext_params, baseline_parameters=base.to_dict()["parameters"],
            data=_data_summary(train, test), wall_time_s=round(time.perf_counter() - t_start, 2),
            baseline_model=base, extended_model=ext, analysis=analysis, train_df=dtr, test_df=dte,
            test_free_run_before=v_te, test_free_run_after=v_te_ext, rounds=it.rounds,
            calibrated_model=calibrated, calibrated_note=why, stages=say.close())
        return self

    def _identify(self, df: pd.DataFrame, m_s: float, mask: np.ndarray, retry: bool = False,
                  model: str = "eq29", rescue: bool = False) -> Validated:
        """The baseline Eq. 29 predictor identified on ``df`` (free-run maximum likelihood, multi-start; coarse
        to fine on data sampled faster than once per millisecond, :func:`l1b2.ident.coarse.coarse_to_fine`).

        ``retry``: the identifier's multistart again with twice the starts (at least 8) and the next seed.
        ``rescue``: the identifier's default search without pins (``solver="auto"``: the seed-free offset search
        for Eq. 29), then the pinned fit warm-started there (the pins held at that fit's values, one local search).
        """
        n_starts, seed = (max(2 * self.n_starts, 8), self.seed + 1) if retry else (self.n_starts, self.seed)
        freq = getattr(self, "frequency_", None) or "auto"   # once the baseline's is known, it is held

        def fit(**kw):
            return coarse_to_fine(PredictorIdentifier(order=self.order, criterion="free_run", noise=self.noise,
                                                      model=model, frequency=freq, **kw), validated(df), m_s, mask)
        init = fit().params_ if rescue else None
        return Validated(fit(fixed="recommended", n_starts=1 if rescue else n_starts, seed=seed,
                             noise_fit=self.noise_fit, init=init))

    def refit_settings(self) -> RefitSettings:
        """The settings of every refit of the loop (order, seed, budget of a fold's refit, noise, client)."""
        return RefitSettings(order=self.order, seed=self.seed, max_nfev=self.refit_nfev, noise=self.noise,
                             client=self.client, frequency=getattr(self, "frequency_", None) or "off")

    def _iterate(self, it: _Iteration, pool, dtr, mask, m_s, report, say, ctx=None, other=None,
                 folds=None) -> None:
        """Rounds of linearised shortlist -> cross-validated refit -> acceptance -> joint re-identification.

        Extends ``it`` in place; ``report(model)`` gives a round's metrics (on the measured speed); ``say`` is
        the job's :class:`~l1b2.closeloop.stages.StageClock` (refits and evaluations are counted on it).
        ``other``: None, or the pure-slip baseline's fit (a callable) from which every named pick is confirmed
        (:mod:`l1b2.closeloop.crosscheck`; the checks go to ``it.checks``). Candidates that depend on the session
        clock are scored and cross-validated on the session's folds (``clock_folds``), the others on the run folds;
        the current model on the same folds as each. ``folds``: ``stratified_folds(dtr, refit_folds, seed)`` if given.
        """
        schemes = refit_schemes(dtr, self.refit_folds, self.refit_repeats, self.seed, self.clock_folds, self.fold_unit,
                                folds if self.fold_unit == "run" else None)
        screen_runs, screen_blocks = screen_folds(dtr, mask, self.k_folds, self.seed, self.clock_folds, self.fold_unit)
        check = None if other is None else PureSlipCheck(
            other, dtr, mask, m_s, lambda c: schemes[time_dependent(c)], self.refit_settings(),
            min_gain=self.min_cv_gain, final_nfev=self.final_nfev, clock=say)
        cur_err: dict = {}
        def analyse(mdl):   # the run-level analysis against a model; rl_of: the model of the latest one
            return runlevel.analyse(dtr, mdl, mask, it.channels, alpha=self.alpha, k=self.k_folds, seed=self.seed,
                                    cycle=self.session_cycle)
        rl_of, sm, carry = None, screen_mask(dtr, mask), []   # sm: the screen's (thinned) rows, every round
        for rnd in range(1, self.max_rounds + 1):
            n_rnd, cur = len(it.rounds), it.model
            say(f"round {n_rnd}: the current model's residual; screening the candidates against the added effects")
            v_cur = cur.predict_free_run(dtr)
            r = res.drive_residual(dtr, v_cur)
            added = added_columns(it.effects, dtr, sm) if it.effects.candidates else None
            geo = Directions(dtr, sm, nuisance_forces(cur.params_, dtr, v_cur))   # named vs generic, issue 28
            cands = [c for c in pool if c.family not in it.effects.families
                     and not collinear(c, it.effects, dtr, sm, added=added) and not geo.conflicts(c, it.effects)]
            say(f"round {n_rnd}: scoring {len(cands)} candidate effects (linearised)")
            scores = score_candidates(cands, r, dtr, mask, cur.params_, m_s, v_pred=v_cur, folds=screen_runs,
                                      time_folds=screen_blocks)
            level = significance_level(scores, self.alpha)
            short, screen = screened(scores, level=level, min_gain=self.min_gain, size=self.shortlist,
                                     fallback_level=self.screen_alpha)
            rl, offered = None, []
            def allowed(c):   # not added, not collinear with what is, no named/generic conflict
                return (c.family not in it.effects.families and not collinear(c, it.effects, dtr, sm, added=added)
                        and not geo.conflicts(c, it.effects))
            def score(cands):   # further candidates' linearised scores against the current model
                return score_candidates(cands, r, dtr, mask, cur.params_, m_s, v_pred=v_cur, folds=screen_runs,
                                        time_folds=screen_blocks)
            if self.run_level and ctx is not None:
                say(f"round {n_rnd}: run-level deviations and the signals that explain them")
                rl, rl_of = analyse(cur), cur
                it.run_levels.append(rl.round_record(rnd))
                offered = runlevel.offer(runlevel.candidates(rl, ctx), short, allowed)
            short = refit_list(short, offered, carry, scores, allowed=allowed, score=score,
                               run_p=lambda c: rl and rl.signal_p(c),
                               share=lambda n, g: geo.share(n, g.candidate, g.phi),
                               level=self.screen_alpha or level, screen=screen, min_gain=self.min_gain)
            if rnd == 1:
                it.first_scores, it.level, it.run_level = scores, level, rl
            if not short:
                it.trials.append([])
                break
            trials = self._trials(it, short, cur, cur_err, schemes, (r, dtr, mask, m_s, v_cur), say, n_rnd)
            it.trials.append(trials)
            accepted = [t for t in trials if accepts(t, **self._rules(t))]
            ok = simplest_within_one_se(accepted)
            if not ok:
                break
            pick, model, checks = self._identified_pick(
                it, ok, lambda tr: input_reading(named_reading(prefer(tr, self.parsimony, rl), tr, geo.of_trials), tr,
                                                 geo.of_trials, log=it.readings, round_no=n_rnd),
                (lambda t: check(t, it.effects, n_rnd, True)) if check is not None else (lambda t: None),
                cur, dtr, mask, m_s, n_rnd, say)
            if pick is None:
                break
            if rnd == 1:
                it.chosen = score_of(pick, short)
                it.significant = [s for s in short if any(t.candidate is s.candidate for t in ok)]
            effects, carry = it.effects.add(pick.candidate, pick.phi), to_carry(accepted, pick)
            if self._refused_range(it, effects.with_phi(model.phi_), model, dtr, mask, n_rnd, pick, say):
                break
            it.model, it.effects = model, effects.with_phi(model.phi_)
            if check is not None:     # a confirmed reading's Eq. 29 estimates are this refit's (decision 0054)
                check.record_joint_refit(checks, model)
            cur_err = {}
            it.rounds.append({"round": n_rnd, "added": pick.candidate.label, "effect": pick.candidate.family,
                              "regressors": list(pick.candidate.regressors), "cv": pick.to_dict(),
                              "metrics": report(model)})
        if rl_of is not None and rl_of is not it.model:     # the last round added an effect: what it leaves
            say("the final model: run-level deviations and the signals left")
            it.run_levels.append(analyse(it.model).round_record(None))

    def _identified_pick(self, it, ok, choose, confirm, cur, dtr, mask, m_s, n_rnd, say) -> tuple:
        """``(pick, model, checks)``: :func:`~l1b2.closeloop.crosscheck.identified_pick` of the accepted trials
        ``ok`` with the joint re-identification of the current model ``cur`` and the test at the loop's ``alpha``
        (``it.checks`` gets every record; ``checks`` are the kept pick's)."""
        def fit(pick):
            say(f"round {n_rnd}: adding {pick.candidate.label}; re-identifying jointly")
            effects = it.effects.add(pick.candidate, pick.phi)
            settings = self.refit_settings().budget(self.final_nfev)
            model = checked_fit(
                lambda: refit(dtr, mask, m_s, cur.params_, effects, settings, max_outer=3),
                lambda: refit(dtr, mask, m_s, cur.params_, effects, settings, max_outer=3,
                              n_starts=max(self.n_starts, 2)),
                dtr, mask, f"the joint re-identification with {pick.candidate.label} (round {n_rnd})")
            say.count(1, model.convergence_.get("nfev_total", 0))
            return model
        pick, model, checks, records = identified_pick(ok, choose, confirm, fit, lambda m, c: identification(
            m, c.names, train_levels(m, dtr), self.alpha), n_rnd)
        it.checks += records
        return pick, model, checks

    @staticmethod
    def _refused_range(it, effects, model, dtr, mask, n_rnd, pick, say) -> bool:
        """Whether the joint refit with ``pick`` is refused by :func:`~l1b2.closeloop.candidates.range_check` (its
        record goes to ``it.ranges``; a refused pick is not added, the model stays the previous round's)."""
        rec = range_check(effects, model, dtr, mask, it.channels, n_rnd, pick.candidate.label)
        it.ranges += [rec] if rec else []
        refused = bool(rec) and rec["outcome"] != "kept"
        if refused:
            say(f"round {n_rnd}: {pick.candidate.label} {rec['outcome']} within TRAIN's range of the channel")
        return refused

    def _rules(self, t: RefitCV) -> dict:
        """The thresholds a refit trial ``t`` is judged by (:func:`accepts`, :func:`tied`): ``min_cv_gain``, and
        ``min_cv_drop`` when it is structural (:func:`materiality`)."""
        return {"min_gain": self.min_cv_gain, "min_drop": materiality(t.candidate, self.min_cv_drop)}

    def _trials(self, it, short, cur, cur_err: dict, schemes: dict, frame: tuple, say, n_rnd) -> list[RefitCV]:
        """The round's refit trials (:class:`RefitCV`, in the order of ``short``) on ``schemes``; when one over the
        run folds is :func:`tied`, those over the run folds again on ``tie_repeats`` splits (settings); an accepted
        one of a lag's form checked on the session's blocks too (:func:`block_checked`)."""
        def trials(sch: dict, err: dict, sub=None, key=time_dependent) -> list:
            sub = short if sub is None else [short[i] for i in sub]
            errs = self._cross_validate(it, sub, cur, err, sch, *frame, say, n_rnd, key)
            return [None if e is None else RefitCV(s.candidate, err[key(s.candidate)], e, s.cv_gain, s.phi, s.origin)
                    for s, e in zip(sub, errs)]
        out = trials(schemes, cur_err)
        if self.tie_repeats > self.refit_repeats and any(not time_dependent(t.candidate) and tied(t, **self._rules(t))
                                                         for t in out):
            say(f"round {n_rnd}: a tied fold vote; the refits over run folds again over {self.tie_repeats} splits")
            more = refit_schemes(frame[1], self.refit_folds, self.tie_repeats, self.seed, self.clock_folds,
                                 self.fold_unit)
            out = [t2 or t for t, t2 in zip(out, trials({False: more[False]}, {}))]
        return block_checked(out, self._rules, lambda w: trials({True: schemes[True]}, cur_err, w, lambda c: True))

    def _cross_validate(self, it, short, cur, cur_err: dict, schemes: dict, r, dtr, mask, m_s, v_cur, say,
                        n_rnd, key=time_dependent) -> list:
        """The shortlist's cross-validated refits (:class:`FoldErrors` per candidate, in order), each on its folds
        (``schemes[key(c)]``, by default whether it depends on the session clock); the current model's errors on a
        scheme's folds are computed once per round into ``cur_err``."""
        errs: list = [None] * len(short)
        for blocked, folds in schemes.items():
            which = [i for i, s in enumerate(short) if key(s.candidate) == blocked]
            if not which:
                continue
            jobs = [] if blocked in cur_err else [(it.effects, None)]
            for i in which:
                s = short[i]
                y, A, S, runs_m = design(s.candidate, r, dtr, mask, cur.params_, m_s, v_pred=v_cur)
                jobs.append((it.effects.add(s.candidate, s.phi), fold_start_phi(S, A, y, runs_m, folds)))
            labels = ", ".join(short[i].candidate.label for i in which)
            say(f"round {n_rnd}: cross-validating {'the current model and ' if blocked not in cur_err else ''}the "
                f"refit with {labels} over {len(folds)} {'session blocks' if blocked else 'run folds'}")
            out = cv_errors(dtr, mask, m_s, folds, cur.params_, jobs, self.refit_settings())
            say.count(len(jobs) * len(folds), sum(e.nfev for e in out))
            if blocked not in cur_err:
                cur_err[blocked], out = out[0], out[1:]
            for i, e in zip(which, out):
                errs[i] = e
        return errs

    def _chain(self, it: _Iteration, dtr, dte, mask, m_s, folds):
        """The speed channel first (:mod:`l1b2.closeloop.chain`): ``(record, the TRAIN frame the rounds fit)``;
        ``folds``: TRAIN's run folds (:func:`~l1b2.closeloop.folds.stratified_folds`).

        When the speed column is a filtered derivative of the position (found from
        position and speed alone, cross-validated over runs), the physics is
        re-identified on the position's derivative (the slider's speed) and the
        filter is applied to its prediction (:class:`ChainModel`). This model is
        kept when it lowers the *cross-validated* free-run sum of squares on the
        measured speed against the baseline (by any amount; the evidence for the
        filter is the channel's own test, this guards against harm), over the
        refit folds with both models refitted per fold
        (:func:`~l1b2.closeloop.acceptance.chain_cv_errors`), as every effect is
        decided. TRAIN's gain is still reported. The rounds then extend that model on the
        derivative data. Otherwise TRAIN is returned unchanged.
        """
        ch = chain.speed_channel(dtr, mask, k=self.k_folds, seed=self.seed)
        rec = {k: v for k, v in ch.items() if k != "filter"}
        rec["sensor_gain"] = chain.stroke_gain(   # run means: not of a response or of a sample-only kind
            dtr, [c["name"] for c in channels_of(dtr, self.response_columns_)
                  if c["kind"] not in ("response",) + fx_channels.SAMPLE_ONLY_KINDS], alpha=self.alpha)
        if "filter" in ch:
            rec["filter"] = ch["filter"].to_dict()
        if not ch["accepted"]:
            return rec, self._sensor_stages(it, rec, dtr, dte, mask, m_s, folds)
        ptr = chain.with_position_speed(dtr)
        filt = ChainModel(self._identify(ptr, m_s, mask), ch["filter"])
        v = dtr[dataio.SPEED].to_numpy(float)[mask]
        sse0 = float(np.sum((v - it.model.predict_free_run(dtr)[mask]) ** 2))
        fr1 = filt.predict_free_run(dtr)
        sse1 = float(np.sum((v - fr1[mask]) ** 2))
        rec["train_free_run_gain"] = 1 - sse1 / sse0 if sse0 > 0 else 0.0   # reported, not deciding
        base_cv, chain_cv = chain_cv_errors(dtr, mask, m_s, folds,
                                            it.model.params_, filt.model.params_, self.refit_settings(),
                                            k=self.k_folds)
        gain = (float(1 - chain_cv.sse.sum() / base_cv.sse.sum())
                if base_cv.failed == 0 and chain_cv.failed == 0 and base_cv.sse.sum() > 0 else 0.0)
        rec.update(cv_free_run_gain=gain, cv_free_run_nrmse_baseline=base_cv.nrmse,
                   cv_free_run_nrmse_chain=chain_cv.nrmse, cv_folds_improved=int(np.sum(chain_cv.sse < base_cv.sse)))
        if not gain > 0:
            rec["accepted"] = False
            rec["refused_by_harm_guard"] = True  # found by the channel's test, not applied
            return rec, self._sensor_stages(it, rec, dtr, dte, mask, m_s, folds)
        it.model, it.output_filter = filt.model, ch["filter"]
        it.rounds.append({"round": len(it.rounds), "added": "speed_channel_filter", "effect": "speed_channel_filter",
                          "regressors": ["speed"], "cv": {"cv_gain": ch["cv_gain"], "cv_free_run_gain": gain,
                                                          "train_free_run_gain": rec["train_free_run_gain"]},
                          "metrics": metrics(filt, dtr, dte, train_free_run=fr1)})
        return rec, ptr

    def _sensor_stages(self, it: _Iteration, rec: dict, dtr, dte, mask, m_s, folds):
        """The sensor stages when the speed channel kept no filter (:func:`l1b2.closeloop.sensorchain.decide_stages`:
        the time stamps' chain, ``rec["time_stamps"]``, then the position sensor's cyclic error behind it,
        ``rec["position_cyclic_error"]``), each kept one a round; none kept, the speed sensor's gain
        (:meth:`_stroke_gain`). Returns the TRAIN frame the rounds fit."""
        recs, kept = sensorchain.decide_stages(dtr, mask, m_s, folds, it.model,
                                               lambda df: self._identify(df, m_s, mask), self.refit_settings(),
                                               alpha=self.alpha, min_gain=self.min_gain, min_cv_gain=self.min_cv_gain)
        rec.update(recs)
        if not kept:
            return self._stroke_gain(it, rec, dtr, dte, mask, m_s, folds)
        for model, stage, out in kept:
            it.model, it.sensor_stage = model, (it.sensor_stage or SensorChain(())).then(stage)
            it.rounds.append({"round": len(it.rounds), "added": stage.name, "effect": stage.name,
                              "regressors": [stage.regressor],
                              "cv": {k: out[k] for k in ("cv_gain", "cv_free_run_gain")},
                              "metrics": metrics(ChainModel(it.model, it.sensor_stage), dtr, dte)})
        return it.sensor_stage.frame(dtr)

    def _stroke_gain(self, it: _Iteration, rec: dict, dtr, dte, mask, m_s, folds):
        """The speed sensor's gain along the stroke (:mod:`l1b2.closeloop.sensor`), when the speed channel kept no
        filter: the TRAIN frame the rounds fit (the recorded speed over the gain when it is kept, else ``dtr``).

        Screened at the loop's ``alpha`` against the baseline with its nuisance responses (one pre-declared
        hypothesis, shortlisted at the screen's smallest gain as every candidate is); kept when the physics
        refitted behind the gain lowers the cross-validated free-run sum of squares of the recorded speed by at
        least ``min_cv_gain``, in more than half of the folds (the rule of every added effect that is not
        structural, :func:`~l1b2.closeloop.acceptance.accepts`; the gain is a missing effect of the measurement,
        not an approximation of Eq. 29). ``rec["stroke_speed_gain"]``
        holds the evidence and the decision. Runs only when ``self.stroke_speed_gain`` is True (default off).
        """
        if not self.stroke_speed_gain:
            return dtr
        v_base = it.model.predict_free_run(dtr)
        out = rec["stroke_speed_gain"] = {"effect": sensor.STROKE_GAIN, "accepted": False,
                                    **sensor.screen(dtr, mask, v_base, it.model.params_, m_s, folds)}
        if not (out["p_value"] < self.alpha and out["cv_gain"] >= self.min_gain):
            return dtr
        fit = sensor.stage_fit(dtr)
        cv = stage_cv_errors(dtr, mask, m_s, folds, it.model.params_, self.refit_settings(), v_base, fit,
                             "l1b2-sensor-gain-cv")
        fields, kept = stage_verdict(cv, len(folds), self.min_cv_gain, "gain")
        out.update(fields)
        if not kept:
            return dtr
        it.model, it.speed_gain = physics_behind(dtr, mask, v_base, fit, lambda df: self._identify(df, m_s, mask))
        g1, wrapped = it.speed_gain.gain, ChainModel(it.model, it.speed_gain)
        out.update(accepted=True, gain=g1.to_dict(), names=list(g1.names()), description=sensor.DESCRIPTION)
        it.rounds.append({"round": len(it.rounds), "added": sensor.STROKE_GAIN, "effect": sensor.STROKE_GAIN,
                          "regressors": ["position"],
                          "cv": {"cv_gain": out["cv_gain"], "cv_free_run_gain": out["cv_free_run_gain"]},
                          "metrics": metrics(wrapped, dtr, dte)})
        return it.speed_gain.frame(dtr)

    def _diagnosis(self, it: _Iteration, scores: list[Score], a: ResidualAnalysis, ext_params,
                   chain_rec: dict) -> dict:
        """The report's ``diagnosis`` section (``chain_rec``: the measurement chain's record)."""
        effects = it.effects.candidates
        c = effects[0] if effects else None
        below = immaterial(it.trials, it.effects, self.min_cv_gain)
        chain_rounds = ("speed_channel_filter", sensor.STROKE_GAIN, stamps.STAMP_CHAIN, encoder.CYCLIC_CHAIN)
        records = ([_filter_record(rec, ext_params) for rec in it.rounds if rec["added"] == "speed_channel_filter"]
                   + [it.sensor_stage.record(r) for r in it.rounds if r["added"] in chain_rounds[2:]]
                   + [_gain_record(rec, ext_params) for rec in it.rounds if rec["added"] == sensor.STROKE_GAIN]
                   + [_effect_record(e, rec, ext_params) for e, rec in
                      zip(effects, [r for r in it.rounds[1:] if r["added"] not in chain_rounds])])
        # the channel's test found a filter that was not applied (it did not lower the CV free-run error)
        chain_found = bool(chain_rec.get("refused_by_harm_guard", False))
        traced_to = order_traced(effects, it.output_filter is not None, a.traced,
                                 evidence=[t.candidate for t in below], speed_evidence=chain_found,
                                 measured=(("position",) if it.speed_gain is not None else ())
                                 + (it.sensor_stage.regressors if it.sensor_stage is not None else ()))
        w = a.whiteness
        labels = "; ".join(f"{e.label} ({', '.join(e.regressors)})" + (", relaxes Eq. 29" if e.structural else "")
                           for e in effects)
        return {
            "significant": c is not None or any(s is not None for s in (it.output_filter, it.speed_gain,
                                                                          it.sensor_stage)),
            "traced_to": traced_to,
            "effect": records[0]["effect"] if records else None,
            "effect_shape": records[0]["shape"] if records else None,
            "effect_description": records[0]["description"] if records else None,
            "effects": records,
            "message": (f"missing effect{'s' if len(effects) > 1 else ''}: {labels}" if c
                        else "no significant missing effect")
                       + _chain_note(it.output_filter)
                       + (f"; {_gain_reading(it.speed_gain.gain)}" if it.speed_gain is not None else "")
                       + (f"; {it.sensor_stage.reading()}" if it.sensor_stage is not None else "")
                       + withdrawn_note(it.checks)
                       + (f"; the speed column looks filtered (measurement chain, cross-validated gain "
                          f"{chain_rec['cv_gain']:.3f}) but a model behind the filter did not lower the "
                          "cross-validated free-run error: not applied" if chain_found and (c is not None) else ""),
            "structural_effects": [{"label": e.label, "regressors": list(e.regressors), "relaxes": e.structural}
                                   for e in effects if e.structural],
            "immaterial_evidence": [t.to_dict() for t in below],
            "residual_trace": a.traced,
            "candidates": [s.to_dict() for s in best_per_family(scores)],
            "n_candidates_scored": len(scores), "significance_level": it.level,
            "refit_trials": [[t.to_dict() for t in rnd] for rnd in it.trials],
            "baseline_choice": getattr(self, "baseline_choice_", {}),
            "rules": self.settings.rules(),
            "regressor_evidence": [[e.to_dict() for e in rnd] for rnd in a.rounds],
            "whiteness": {"runs": len(w),
                          "share_runs_ljung_box_p_below_0.05": (float(np.mean([x["ljung_box_p"] < 0.05 for x in w]))
                                                                if w else None),
                          "median_rho1": float(np.median([x["rho1"] for x in w])) if w else None},
            "position_spectrum_peak": a.peak,
            "measurement_chain": chain_rec,
            "channels_considered": channels_considered(
                it.channels, scores, it.level, self.min_gain, it.effects.families, it.run_level,
                [[{**t.to_dict(), "accepted": accepts(t, **self._rules(t))} for t in rnd] for rnd in it.trials],
                it.effects.labels),
            "run_level": it.run_level.to_dict() if it.run_level is not None else None,
            "run_level_rounds": list(it.run_levels),
            "named_checks": list(it.checks), "physical_range": list(it.ranges), "input_readings": list(it.readings),
        }


@dataclass
class _Iteration:
    """State of the rounds: the current model, its effects, per-round records."""

    model: object
    effects: EffectSet
    rounds: list
    trials: list = field(default_factory=list)
    first_scores: list | None = None
    chosen: Score | None = None
    significant: list = field(default_factory=list)
    level: float = float("nan")
    output_filter: chain.OutputFilter | None = None
    speed_gain: GainChain | None = None   #: the speed sensor's gain along the stroke (measurement chain)
    sensor_stage: SensorChain | None = None   #: the kept sensor stages (speed over the time stamps, cyclic error)
    channels: tuple = ()
    run_level: runlevel.RunLevelAnalysis | None = None
    run_levels: list = field(default_factory=list)   #: each round's run-level record, then the final model's
    checks: list = field(default_factory=list)    #: the named picks' checks from the pure-slip family
    ranges: list = field(default_factory=list)    #: the damping forms' physical-range checks after each refit
    readings: list = field(default_factory=list)  #: the picks of an auxiliary channel read as the inputs instead


class ChainModel:
    """The measurement chain around a physics model fitted behind it.

    The model predicts the slider's speed along the chain's frame (``output_filter.frame``: the position's
    derivative behind the speed channel's filter, :func:`l1b2.closeloop.chain.with_position_speed`, or the recorded
    speed over the sensor's gain, :class:`l1b2.closeloop.sensor.GainChain`; run starts and one-step inputs from
    it); ``output_filter.apply`` turns that into the measured speed column.
    """

    def __init__(self, model, output_filter):
        self.model, self.output_filter = model, output_filter

    def predict_free_run(self, df) -> np.ndarray:
        return self.output_filter.apply(df, self.model.predict_free_run(self.output_filter.frame(df)))

    def predict_one_step(self, df) -> np.ndarray:
        return self.output_filter.apply(df, self.model.predict_one_step(self.output_filter.frame(df)))

    def __getattr__(self, name):
        if name == "model":
            raise AttributeError(name)
        return getattr(self.model, name)


def prefer(accepted: list[RefitCV], parsimony: float, run_level: runlevel.RunLevelAnalysis | None = None) -> RefitCV:
    """The candidate added among the accepted ones: within ``parsimony`` of the best CV gain, named before generic,
    the session's blocks (:func:`~l1b2.closeloop.runlevel.is_last_resort`) after every other, then a form constant
    along the stroke (:func:`~l1b2.closeloop.runlevel.is_run_level`) whose regressor the run-level evidence names,
    then the fewest parameters (:func:`~l1b2.closeloop.selection.counted_params`), then the largest gain."""
    best_gain = max(t.gain for t in accepted)
    named = {e.regressor for e in run_level.significant} if run_level is not None else set()

    def key(t):
        c = t.candidate
        return (c.generic, runlevel.is_last_resort(c), not (runlevel.is_run_level(c) and c.regressor in named),
                counted_params(c), -t.gain)
    return min((t for t in accepted if t.gain >= parsimony * best_gain), key=key)


def _chain_note(stage: chain.OutputFilter | None) -> str:
    """The message's words on a kept speed-channel stage: filtered, clipped at its range, or both."""
    if stage is None:
        return ""
    what = " and ".join(w for w, on in (("filtered", stage.filtered or not stage.clipped),
                                         ("clipped at its range", stage.clipped)) if on)
    return f"; speed channel {what} (measurement chain)"


def _filter_record(rec: dict, params: dict | None) -> dict:
    return {"round": rec["round"], "effect": "speed_channel_filter", "label": "speed_channel_filter", "shape": "",
            "regressors": ["speed"], "generic": False, "structural": None,
            "parameters": {n: (params or {}).get(n) for n in ("speed_filter_a", "speed_filter_b0", "speed_filter_b1")
                           + tuple(n for n in (params or {}) if n.startswith("speed_clip_"))},
            "description": "the speed column is a filtered/delayed/scaled derivative of the position "
                           "(measurement chain): output filter on the predicted speed"
                           + ("; the column saturates at its range (rails): the prediction is clipped after the filter"
                              if any(n.startswith("speed_clip_") for n in (params or {})) else ""),
            "cv_gain": rec["cv"]["cv_gain"], "cv_free_run_nrmse_before": None, "cv_free_run_nrmse_after": None,
            "folds_improved": None}


def _gain_record(rec: dict, params: dict | None) -> dict:
    names = [n for n in (params or {}) if n.startswith("sensor_gain_c")]
    return {"round": rec["round"], "effect": sensor.STROKE_GAIN, "label": sensor.STROKE_GAIN, "shape": "",
            "regressors": ["position"], "generic": False, "structural": None,
            "parameters": {n: (params or {}).get(n) for n in names}, "description": sensor.DESCRIPTION,
            "cv_gain": rec["cv"]["cv_gain"], "cv_free_run_nrmse_before": None, "cv_free_run_nrmse_after": None,
            "folds_improved": None}


def _gain_reading(g) -> str:
    """The report's line for a kept sensor gain: its coefficients with their standard errors and range."""
    se = g.stderr or (float("nan"),) * len(g.coef)
    coef = ", ".join(f"c{j} {c:+.4f} +- {e:.4f}" for j, (c, e) in enumerate(zip(g.coef, se)))
    gs = g.gain(np.linspace(g.s_lo, g.s_hi, 201))
    return (f"speed sensor's gain along the stroke (measurement, not a force): g(s) = 1 + sum c_j P_j, {coef}; "
            f"g from {gs.min():.3f} to {gs.max():.3f} over the stroke")


def _effect_record(c, rec: dict, params: dict | None) -> dict:
    cv = rec.get("cv", {})
    return {"round": rec["round"], "effect": c.family, "label": c.label, "shape": c.shape,
            "regressors": list(c.regressors), "description": c.description, "generic": c.generic,
            "structural": c.structural or None,
            "parameters": {n: (params or {}).get(n) for n in c.names},
            "cv_gain": cv.get("cv_gain"), "cv_free_run_nrmse_before": cv.get("cv_free_run_nrmse_current"),
            "cv_free_run_nrmse_after": cv.get("cv_free_run_nrmse_refit"),
            "folds_improved": cv.get("folds_improved")}


def close_loop(train: dataio.Measurements, test: dataio.Measurements | None = None, **settings) -> CloseLoopResult:
    """``CloseLoop(**settings).fit(train, test).result_`` (settings: the fields of
    :class:`~l1b2.closeloop.settings.LoopSettings`)."""
    return CloseLoop(**settings).fit(train, test).result_


# -- stages -----------------------------------------------------------------
def analyse_residuals(df: pd.DataFrame, v_pred: np.ndarray, mask: np.ndarray, *, alpha: float, k: int,
                      seed: int) -> ResidualAnalysis:
    """Drive-coordinate residual, whiteness, position spectrum and regressor trace (TRAIN)."""
    r = res.drive_residual(df, v_pred)
    whiteness = res.whiteness(r, df, mask)
    freq, power, peak = res.position_spectrum(r, df, mask)
    traced, rounds = res.trace(r, df, mask, alpha=alpha, k=k, seed=seed)
    return ResidualAnalysis(residual=r, mask=mask, whiteness=whiteness, frequency=freq, power=power, peak=peak,
                            traced=traced, rounds=rounds)


def candidate_context(baseline_free_run, m_s: float, df: pd.DataFrame, mask: np.ndarray, peak: dict,
                      response_columns=None, damping: float | None = None) -> Context:
    """What candidate features may use: the baseline's free run, the mass, TRAIN's ranges, the spectral peak
    (``response_columns``: the measured responses, never candidates; None: the default list; ``damping``: the
    baseline's smallest viscous damping over TRAIN [N s/m], :func:`~l1b2.closeloop.candidates.baseline_damping`)."""
    pos = df[dataio.POSITION].to_numpy(float)[mask]
    return Context(
        baseline_free_run=baseline_free_run, m_s=float(m_s),
        time_range=(float(df[dataio.TIME].min()), float(df[dataio.TIME].max())),
        position_range=(float(pos.min()), float(pos.max())),
        temperature_ref=float(df[dataio.TEMPERATURE].median()) if dataio.TEMPERATURE in df.columns else None,
        spectral_period_m=peak.get("period_m") if peak.get("power_ratio_to_median", 0) > res.LINE_POWER_RATIO else None,
        damping_N_s_per_m=damping,
        **({} if response_columns is None else {"response_columns": tuple(response_columns)}))


def _operating_points(df: pd.DataFrame) -> dict:
    """TRAIN's operating grid: its voltages [V], loads [kg] and position range [m] (for mapping effects)."""
    pos = df[dataio.POSITION].to_numpy(float)
    return {"voltages_V": sorted(float(v) for v in np.unique(df[dataio.VOLTAGE].round(6))),
            "loads_kg": sorted(float(v) for v in np.unique(df[dataio.LOAD].round(9))),
            "position_m": [float(pos.min()), float(pos.max())]}


def _check_measurements(m, name: str) -> None:
    if not isinstance(m, dataio.Measurements):
        raise TypeError(f"{name}: expected l1b2.data.measurements.Measurements (validated data, e.g. "
                        f"load_measurements(path)), got {type(m).__name__}")


def _data_summary(train: dataio.Measurements, test: dataio.Measurements | None) -> dict:
    def where(m):
        return str(m.path) if m is not None and m.path is not None else None
    return {"train": where(train), "test": where(test), "train_runs": len(train.runs),
            "test_runs": len(test.runs) if test is not None else 0, "train_samples": train.n_samples,
            "test_samples": test.n_samples if test is not None else 0,
            # no speed column: the speed is the position's derivative (figures say "derived", not "measured")
            "train_speed_derived": bool(train.meta.get("speed_derived")),
            "test_speed_derived": bool(test.meta.get("speed_derived")) if test is not None else False}
