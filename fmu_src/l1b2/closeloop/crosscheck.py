"""A named effect found from the Eq. 29 baseline is read as physics only when the pure-slip family confirms it.

Eq. 29 holds the drive force's slope over speed constant; the pure-slip drive force (Eq. 25 with
``k0 = v/(omega U_w)``) has a slope that changes with V0. On data of a motor that is not Eq. 29, that
structural error is in every residual of the Eq. 29 baseline, and a named family can lower it (on a clean realistic
world the pulley's ``-g|m|`` does: a pulley coefficient for a pulley that is not there, decision 0043). Whether a
named effect's evidence hinges on that linearisation is a question the data can answer: the same candidate,
cross-validated by the same machinery from the family that does not make the linearisation, must be accepted too.

Contract:

* :func:`confirmed_pick` applies the rule to a round's accepted trials: the pick (``choose``, the loop's
  ``prefer`` then ``named_reading``) is kept when it is generic or when ``confirm`` accepts it (``confirm``
  returns None when no check applies, e.g. the baseline is already pure slip). A named pick that is not confirmed
  is withdrawn: its :func:`as_form` trial takes its place (the same force and the same cross-validated
  figures, whose acceptance stands, read as a generic structural term of the reduced model), so the round adds
  the force its acceptance and choice selected; every check is recorded with its outcome.
* :func:`identified_pick` then re-identifies the model with the pick; a pick read as physics (named, not
  structural) is named only when its parameters are jointly different from zero under the interval the report
  gives them (:func:`l1b2.closeloop.intervals.identification`); when they are not, it is recorded as not identified
  and the round's choice is made again without it.
* :class:`PureSlipCheck` is the ``confirm`` of the loop: the pure-slip baseline identified on TRAIN once
  (lazily, at the first named pick), the effects accepted so far re-identified jointly in that family, then the
  current model and the current model + the named candidate cross-validated on the trial's own folds
  (:func:`l1b2.closeloop.acceptance.cv_errors`, warm refits, the candidate started per fold from its linearised
  fit on the training folds only); confirmed when :func:`l1b2.closeloop.acceptance.accepts` accepts that trial
  with the loop's ``min_cv_gain`` (a named effect is not structural: no materiality threshold). A confirmed
  reading's parameters are then estimated in both families (each family's current model with the named candidate
  re-identified jointly on TRAIN, the report's standard errors, and the difference of the two estimates in units
  of their combined standard error): the pure-slip side by the check (:meth:`PureSlipCheck.parameters`), the
  Eq. 29 side from the loop's own joint re-identification after the pick, which is that same refit (same frame,
  start, effects and budget; :meth:`PureSlipCheck.record_joint_refit`). They are a record, not a rule:
  on the realistic world neither their agreement nor the pure-slip interval's distance from zero separates the
  false pulley readings that pass from the true ones (decision 0048). Its refits and evaluations are counted on
  the stage clock.

Nothing here is tuned: the rule is the loop's own acceptance rule, applied from the other family.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import FitDivergedError, IdentificationError
from . import residuals as res
from .acceptance import EffectSet, RefitCV, accepts, cv_errors, fold_start_phi, refit
from .candidates import EQ29_LINEARISATION, CandidateForce
from .intervals import reported_uncertainty, train_levels
from .selection import design

__all__ = ["FORM_SUFFIX", "as_form", "both_families", "confirmed_pick", "score_of", "PureSlipCheck", "describe",
           "identified_pick", "identified_text", "withdrawn_note"]

#: appended to a withdrawn named family's name: the same force read as a generic term of the reduced model
FORM_SUFFIX = "_form"
#: what a withdrawn named form relaxes (its ``structural`` tag)
WITHDRAWN = ("the named form's evidence was not confirmed from the pure-slip family: it takes up the error of "
             "Eq. 29's linearisation (" + EQ29_LINEARISATION + ")")


def as_form(c: CandidateForce) -> CandidateForce:
    """The named candidate ``c`` read as a generic structural term: the same features, spec and bounds; family
    ``c.family + FORM_SUFFIX`` (so no subsystem parameter is its home), parameters ``<family>_<j>``, generic,
    structural (:data:`WITHDRAWN`)."""
    fam = c.family + FORM_SUFFIX
    return replace(c, family=fam, names=tuple(f"{fam}_{j}" for j in range(c.n_params)), generic=True,
                   structural=WITHDRAWN,
                   description=f"the force of {c.label} ({c.description}), not read as that physics: " + WITHDRAWN)


def score_of(pick: RefitCV, scores: list):
    """The score of ``scores`` whose candidate ``pick`` cross-validated; for an :func:`as_form` trial, its named
    candidate's score carrying the form (the same force and linearised figures)."""
    for sc in scores:
        if sc.candidate is pick.candidate:
            return sc
    for sc in scores:
        if as_form(sc.candidate) == pick.candidate:
            return replace(sc, candidate=pick.candidate)
    raise ValueError(f"{pick.candidate.label}: not among the round's scores")


def _round(x) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


def confirmed_pick(ok: list, choose, confirm) -> tuple:
    """``(pick or None, records)``: the trial the round adds once its named pick has been checked.

    ``ok``: the round's accepted :class:`~l1b2.closeloop.acceptance.RefitCV` trials; ``choose(trials)`` the loop's
    choice among them; ``confirm(trial)`` a record ``{"confirmed": bool, ...}`` of the check, or None when no
    check applies. A generic pick, a structural one (a named term of the reduced model that relaxes Eq. 29's
    linearisation, no physical reading) or a named one confirmed (or not checked) is returned as chosen. A named
    pick that is not confirmed is withdrawn and its :func:`as_form` trial takes its place: the same force and
    cross-validated errors, so the round adds what its acceptance and choice selected and only the reading
    changes. Each record gets ``"outcome"``: ``"kept"`` or ``"withdrawn, kept as <label>"``.
    """
    if not ok:
        return None, []
    pick = choose(list(ok))
    if pick.candidate.generic or pick.candidate.structural:    # already read as Eq. 29's own linearisation
        return pick, []
    rec = confirm(pick)
    if rec is None:
        return pick, []
    if rec["confirmed"]:
        return pick, [{**rec, "outcome": "kept"}]
    form = replace(pick, candidate=as_form(pick.candidate))
    return form, [{**rec, "outcome": f"withdrawn, kept as {form.candidate.label}"}]


def identified_pick(ok: list, choose, confirm, fit, identify, round_no: int) -> tuple:
    """``(pick, model, checks, records)``: the round's pick once it is checked and, when read as physics, identified.

    The pick is :func:`confirmed_pick`'s of the trials left (``ok`` at first), ``model = fit(pick)`` its joint
    re-identification. A pick read as physics (named, not structural) is named only when identified:
    ``identify(model, candidate)`` (:func:`l1b2.closeloop.intervals.identification`, the joint test of its
    parameters against zero) goes into its records (``"identification"``; a record is made for a pick with no
    check), and when it says not identified the record's outcome says so, the trial leaves the round and the
    choice is made again among the rest. ``checks``: the kept pick's records; ``records``: all of them;
    ``(None, None, [], records)`` when no trial is left.
    """
    left, records = list(ok), []
    while left:
        pick, checks = confirmed_pick(left, choose, confirm)
        model = fit(pick)
        c = pick.candidate
        if c.generic or c.structural:
            return pick, model, checks, records + checks
        mine = [r for r in checks if r["label"] == c.label]
        if not mine:
            mine = [{"round": int(round_no), "label": c.label, "effect": c.family, "family": None,
                     "checked": False, "confirmed": True, "outcome": "kept"}]
            checks = checks + mine
        ident = identify(model, c)
        for r in mine:
            r["identification"] = ident
        records += checks
        if ident["identified"]:
            return pick, model, checks, records
        for r in mine:
            r["outcome"] = "not identified (its parameters are not jointly different from zero): not added"
        left = [t for t in left if t is not pick]
    return None, None, [], records


class PureSlipCheck:
    """The loop's ``confirm`` (see the module): a named trial cross-validated again from the pure-slip family.

    ``identify()`` returns the pure-slip baseline identified on the loop's TRAIN frame (called once, at the first
    check; a :class:`l1b2.errors.FitDivergedError` is recorded and every check then says it could not be made,
    and the named reading stands); ``df``, ``mask``, ``m_s``: the rounds' TRAIN frame; ``folds(candidate)``: the
    run ids per fold the loop cross-validated that candidate on; ``settings``: the loop's
    :class:`~l1b2.closeloop.acceptance.RefitSettings`; ``final_nfev``: the joint re-identification's budget;
    ``clock``: the job's :class:`~l1b2.closeloop.stages.StageClock`.
    """

    family = "pure_slip"

    def __init__(self, identify, df, mask, m_s: float, folds, settings, *, min_gain: float, final_nfev: int,
                 clock=None):
        self.identify, self.df, self.mask, self.m_s = identify, df, np.asarray(mask, bool), float(m_s)
        self.folds, self.settings, self.min_gain, self.final_nfev = folds, settings, min_gain, int(final_nfev)
        self.clock = clock if clock is not None else (lambda msg: None)
        self._base, self._failed = None, None
        self._current: dict = {}      # effects' labels -> the pure-slip model with them (re-identified once)
        self._pending: dict = {}      # (round, label) -> (candidate, its pure-slip estimates), for the joint refit

    def _count(self, refits: int, nfev: int) -> None:
        if hasattr(self.clock, "count"):
            self.clock.count(refits, nfev)

    def _baseline(self):
        """The pure-slip baseline (identified at the first call; None when that failed, ``_failed`` says why)."""
        if self._base is None and self._failed is None:
            try:
                self._base = self.identify()
            except (FitDivergedError, IdentificationError) as e:
                self._failed = str(e)
        return self._base

    def _model(self, effects: EffectSet):
        """The pure-slip baseline with ``effects`` re-identified jointly (the baseline itself when there are none)."""
        if self._baseline() is None:
            return None
        key = tuple(c.label for c in effects.candidates)
        if key not in self._current:
            if not effects.candidates:
                self._current[key] = self._base
            else:
                m = refit(self.df, self.mask, self.m_s, self._base.params_, effects,
                          self.settings.budget(self.final_nfev), max_outer=3)
                self._count(1, m.convergence_.get("nfev_total", 0))
                self._current[key] = m
        return self._current[key]

    def _estimates(self, model, effects: EffectSet, c: CandidateForce, phi) -> dict:
        """``{name: {"value", "stderr", "interval"}}`` of ``c``'s parameters: ``model``'s family with ``effects`` and
        ``c`` (started at ``phi``) re-identified jointly on TRAIN (the loop's final budget), the report's intervals."""
        m = refit(self.df, self.mask, self.m_s, model.params_, effects.add(c, c.clip(phi)),
                  self.settings.budget(self.final_nfev), max_outer=3)
        self._count(1, m.convergence_.get("nfev_total", 0))
        return self.estimates_of(m, c)

    def estimates_of(self, m, c: CandidateForce) -> dict:
        """``{name: {"value", "stderr", "interval"}}`` of ``c``'s parameters in the joint fit ``m`` (fitted on the
        check's TRAIN frame): the value and the report's interval
        (:func:`l1b2.closeloop.intervals.reported_uncertainty`)."""
        groups = train_levels(m, self.df)
        out = {}
        for n in c.names:
            u = reported_uncertainty(m, n, groups)
            out[n] = {"value": _round(m.extra_params_[n]), "stderr": _round(u["stderr"]), "interval": u["interval"]}
        return out

    def parameters(self, trial: RefitCV, effects: EffectSet, cur, y, A, S) -> dict:
        """The named candidate's pure-slip estimates (:meth:`estimates_of`): ``cur``, the pure-slip model with the
        current ``effects``, and the candidate re-identified jointly, started from the least-squares fit of the
        pure-slip design ``y, A, S``. The Eq. 29 side is the loop's joint refit (:meth:`record_joint_refit`)."""
        c = trial.candidate
        coef = np.linalg.lstsq(np.column_stack([A, S]), y, rcond=None)[0][A.shape[1]:]
        return self._estimates(cur, effects.with_phi(cur.phi_) if effects.candidates else effects, c, coef)

    def record_joint_refit(self, records: list, model) -> None:
        """Complete, in place, the ``"parameters"`` of the kept ``records`` (this round's checks) whose pure-slip
        estimates were made: the Eq. 29 side from ``model``, the loop's joint re-identification of its current
        model with the confirmed pick (the refit this check would otherwise repeat), by :func:`both_families`."""
        for rec in records:
            pending = self._pending.pop((rec["round"], rec["label"]), None)
            if pending is not None and rec.get("outcome") == "kept":
                c, ps = pending
                rec["parameters"] = both_families(c, self.estimates_of(model, c), ps, self.family)

    def __call__(self, trial: RefitCV, effects: EffectSet, round_no: int, estimate: bool = False) -> dict:
        """The check's record of ``trial`` (a named candidate) against the current ``effects``.

        ``estimate``: when the reading is confirmed, estimate its parameters from the pure-slip family
        (:meth:`parameters`); the record's ``"parameters"`` are completed by :meth:`record_joint_refit` once the
        loop has re-identified its model with the pick (a failed estimate: ``"parameters_note"``)."""
        c = trial.candidate
        self._baseline()    # its identification is a stage of its own
        self.clock(f"round {round_no}: checking the named {c.label} from the {self.family} family")
        rec = {"round": int(round_no), "label": c.label, "effect": c.family, "family": self.family,
               "eq29_cv_gain": _round(trial.gain), "eq29_cv_free_run_nrmse_current": _round(trial.current.nrmse),
               "eq29_cv_free_run_nrmse_refit": _round(trial.extended.nrmse)}
        try:
            cur = self._model(effects)
        except IdentificationError as e:
            cur, why = None, str(e)
        else:
            why = self._failed
        if cur is None:
            return {**rec, "confirmed": True, "checked": False,
                    "note": f"the {self.family} model could not be identified ({why}): not checked"}
        v = cur.predict_free_run(self.df)
        y, A, S, runs_m = design(c, res.drive_residual(self.df, v), self.df, self.mask, cur.params_, self.m_s,
                                 v_pred=v)
        folds = self.folds(c)
        phi = fold_start_phi(S, A, y, runs_m, folds)
        errs = cv_errors(self.df, self.mask, self.m_s, folds, cur.params_,
                         [(effects, None), (effects.add(c, trial.phi), phi)], self.settings)
        self._count(2 * len(folds), sum(e.nfev for e in errs))
        t = RefitCV(c, errs[0], errs[1])
        ok = accepts(t, min_gain=self.min_gain, min_drop=0.0)
        if ok and estimate:     # a reading that stands: its value from both families (decision 0048)
            try:
                self._pending[(int(round_no), c.label)] = (c, self.parameters(trial, effects, cur, y, A, S))
            except (FitDivergedError, IdentificationError) as e:
                rec["parameters_note"] = f"the named parameters could not be estimated in both families ({e})"
        return {**rec, "checked": True, "confirmed": ok,
                "cv_gain": _round(t.gain), "cv_free_run_nrmse_current": _round(t.current.nrmse),
                "cv_free_run_nrmse_refit": _round(t.extended.nrmse), "folds_improved": t.folds_improved,
                "folds": len(folds), "min_cv_gain": float(self.min_gain)}


def both_families(c: CandidateForce, e29: dict, other: dict, family: str) -> dict:
    """``{name: {"eq29", <family>, "z_difference", "z_<family>"}}``: ``c``'s estimates from Eq. 29 and from the
    other ``family`` (each ``{name: {"value", "stderr", "interval"}}``), the difference of the two in units of their
    combined standard error and the other family's value over its standard error (None where a figure is missing)."""
    out = {}
    for n in c.names:
        a, b = e29[n], other[n]
        d = (None if None in (a["value"], b["value"], a["stderr"], b["stderr"])
             else _round((b["value"] - a["value"]) / np.hypot(a["stderr"], b["stderr"])))
        z = None if None in (b["value"], b["stderr"]) else _round(b["value"] / b["stderr"])
        out[n] = {"eq29": a, family: b, "z_difference": d, f"z_{family}": z}
    return out


def describe(rec: dict) -> str:
    """One line of ``report.md`` for a check's record (:meth:`PureSlipCheck.__call__` and its outcome)."""
    ident = identified_text(rec.get("identification"))
    if rec.get("family") is None:
        return f"named reading of `{rec['label']}` (round {rec['round']}): {rec.get('outcome', '')}" + ident
    head = f"named reading of `{rec['label']}` (round {rec['round']}) checked from the {rec['family']} family: "
    if not rec.get("checked"):
        return head + rec.get("note", "not checked") + f"; {rec.get('outcome', '')}" + ident

    def pct(x, f):
        return "-" if x is None else format(x, f)
    return (head + f"CV free-run nrmse {pct(rec['cv_free_run_nrmse_current'], '.2%')} -> "
            f"{pct(rec['cv_free_run_nrmse_refit'], '.2%')} (gain {pct(rec['cv_gain'], '.1%')}, "
            f"{rec['folds_improved']}/{rec['folds']} folds; from Eq. 29: gain {pct(rec['eq29_cv_gain'], '.1%')}; "
            f"accepted needs >= {rec['min_cv_gain']:.0%} in most folds): "
            + ("confirmed" if rec["confirmed"] else "not confirmed") + f"; {rec.get('outcome', '')}"
            + "".join(f"; {n} " + values(p) for n, p in (rec.get("parameters") or {}).items()) + ident)


def identified_text(t: dict | None) -> str:
    """The identification test's figures (:func:`l1b2.closeloop.intervals.identification`) as a clause of a
    check's line, e.g. ``; joint Wald 12.3 (k 2, F on 2 and 7 df, p 0.0041 < 0.01): identified``."""
    if not t:
        return ""
    if t["wald"] is None:
        return f"; joint Wald test not computable ({t['interval']} covariance): not identified"
    dist = (f"F on {t['k']} and {t['df_denominator']} df" if t["df_denominator"] is not None
            else f"chi-square with {t['k']} df")
    return (f"; joint Wald {t['wald']:.3g} (k {t['k']}, {dist}, {t['interval']} covariance, p {t['p']:.2g} "
            + ("<" if t["identified"] else ">=") + f" {t['alpha']:g}): "
            + ("identified" if t["identified"] else "not identified"))


def values(p: dict) -> str:
    """A named parameter's two estimates (``PureSlipCheck.parameters``), e.g. ``from eq29 0.061 ± 0.008, from
    pure_slip 0.045 ± 0.011 (difference -1.2 se)``."""
    def one(f):
        e = p[f]
        return f"from {f} " + ("-" if e["value"] is None else format(e["value"], ".4g")) + (
            "" if e["stderr"] is None else f" ± {e['stderr']:.2g}")
    fams = [f for f in p if isinstance(p[f], dict)]
    d = p.get("z_difference")
    return ", ".join(one(f) for f in fams) + ("" if d is None else f" (difference {d:+.1f} se)")


def withdrawn_note(records: list) -> str:
    """The diagnosis message's note on withdrawn and not identified named readings ('' when there is none)."""
    out = [r["label"] for r in records if str(r.get("outcome", "")).startswith("withdrawn")]
    nid = list(dict.fromkeys(r["label"] for r in records if str(r.get("outcome", "")).startswith("not identified")))
    return ((f"; named reading withdrawn (not confirmed from the pure-slip family, Eq. 29's linearisation): "
             f"{', '.join(out)}") if out else "") + (
        f"; named reading not identified (parameters not jointly different from zero), not added: "
        f"{', '.join(nid)}" if nid else "")
