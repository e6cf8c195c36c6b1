"""The typed records of a close-the-loop report: :class:`Diagnosis`, :class:`Round`, :class:`EffectRecord`.

Each is a dataclass with ``to_dict()`` (the JSON form, under the package's
one rule :mod:`l1b2.jsonio`) and ``from_dict()`` (its inverse); the
loop builds them from JSON-normal values (NaN as None, infinities as
``"inf"``), so ``from_dict(to_dict(x)) == x``. They also read like the
dicts they replace (``diagnosis["traced_to"]``, ``record.get("cv_gain")``).
:data:`SCHEMA_VERSION` is written at the top of ``report.json``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, Mapping

from ..errors import L1B2Error

#: version of ``report.json``'s layout (1: typed records, issue 27)
SCHEMA_VERSION = 1


class ReportFormatError(L1B2Error):
    """A report dict does not have the fields of its record (names the record and the field)."""


class _Record:
    """Mapping-style read access to a record's fields (``r["name"]``, ``r.get``, ``"name" in r``)."""

    def __getitem__(self, key: str) -> Any:
        if key not in self._keys():
            raise KeyError(key)
        return getattr(self, key)

    def get(self, key: str, default=None) -> Any:
        return getattr(self, key) if key in self._keys() else default

    def __contains__(self, key) -> bool:
        return key in self._keys()

    def keys(self):
        return self.to_dict().keys()

    def _keys(self) -> set:
        return set(self.to_dict())

    def to_dict(self) -> dict:   # pragma: no cover - every record defines it
        raise NotImplementedError


def _take(cls, d: Mapping, name: str, optional=()):
    """``{field: d[field]}`` for the dataclass ``cls`` (fields in ``optional`` may be missing)."""
    if not isinstance(d, Mapping):
        raise ReportFormatError(f"{name}: expected an object, got {type(d).__name__}")
    out = {}
    for f in fields(cls):
        if f.name in d:
            out[f.name] = d[f.name]
        elif f.name not in optional:
            raise ReportFormatError(f"{name}: field {f.name!r} missing")
    return out


@dataclass(frozen=True)
class EffectRecord(_Record):
    """One effect added to the model (``diagnosis.effects[i]``): what, when, its parameters and its CV evidence."""

    round: int
    effect: str
    label: str
    shape: str
    regressors: list
    description: str
    generic: bool
    structural: str | None
    parameters: dict
    cv_gain: Any = None
    cv_free_run_nrmse_before: Any = None
    cv_free_run_nrmse_after: Any = None
    folds_improved: Any = None

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: Mapping) -> EffectRecord:
        return cls(**_take(cls, d, "diagnosis.effects[]"))


@dataclass(frozen=True)
class Round(_Record):
    """One round of the loop (``rounds[i]``): what was added (None in round 0), its CV record and the metrics after."""

    round: int
    added: str | None
    metrics: dict
    effect: str | None = None
    regressors: list | None = None
    cv: dict | None = None

    def to_dict(self) -> dict:
        out = {"round": self.round, "added": self.added}
        for k in ("effect", "regressors", "cv"):
            if getattr(self, k) is not None:
                out[k] = getattr(self, k)
        out["metrics"] = self.metrics
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> Round:
        return cls(**_take(cls, d, "rounds[]", optional=("effect", "regressors", "cv")))


@dataclass(frozen=True)
class Diagnosis(_Record):
    """``report.json``'s ``diagnosis``: what was found, traced and added, and the evidence behind it.

    ``effects`` are :class:`EffectRecord` in the order they were added;
    ``candidates`` the best score per family of the first round;
    ``refit_trials`` per round the cross-validated refits; ``rules`` the
    settings that decided; ``regressor_evidence``, ``whiteness`` and
    ``position_spectrum_peak`` the residual analysis; ``measurement_chain``
    the speed channel's test; ``channels_considered`` every logged channel
    and protocol signal with its first-round evidence, significant or not (its ``run_level`` entries: the
    evidence of its run mean for the runs' own deviations); ``run_level`` the first round's run-level
    deviations (:meth:`l1b2.closeloop.runlevel.RunLevelAnalysis.to_dict`; None when not estimated);
    ``run_level_rounds`` the run-level analysis of every round against the model entering it, then, when the last
    round added an effect, against the final model (:meth:`l1b2.closeloop.runlevel.RunLevelAnalysis.round_record`:
    its last entry is what the final model leaves);
    ``event_clocks`` the event clocks derived from logged step channels (:mod:`l1b2.closeloop.events`);
    ``lagged_channels`` the low-passes derived from logged run settings and the drive amplitude's step from its
    previous setting (:mod:`l1b2.closeloop.lags`);
    ``pause_channel`` the pause before each run and whether its logarithm was derived as a channel
    (:mod:`l1b2.closeloop.pauses`); ``break_clock`` whether the time since the latest break and the count of
    breaks were derived (:func:`l1b2.closeloop.pauses.with_break_clock`); ``previous_pass`` whether the previous
    run's load was derived as a channel and TRAIN's range of it (:mod:`l1b2.closeloop.history`); ``run_clock``
    whether the time since each run's start was derived as a channel and TRAIN's run durations
    (:mod:`l1b2.closeloop.runclock`); ``run_travel`` whether the way gone since each run's start was derived as a
    channel and TRAIN's runs' spans of the position (:func:`l1b2.closeloop.runclock.with_run_travel`);
    ``log_channels`` the logarithms derived from logged channels that span decades (:mod:`l1b2.closeloop.logscale`);
    ``run_settings`` the run settings sought in the columns classed responses and the columns read along the
    stroke, derived or not and why (:func:`l1b2.closeloop.runsetting.with_run_settings`);
    ``unseen_levels`` the TEST values of an added categorical setting that TRAIN never had
    (:func:`l1b2.closeloop.ranges.unseen_test_levels`); ``channel_ranges`` per logged channel an added effect
    reads, the share of TEST's samples and runs outside TRAIN's range of it
    (:func:`l1b2.closeloop.ranges.channel_ranges`, the report's line: :func:`channel_range_line`).
    ``test_session``: whether TRAIN and TEST are one session on the clock, the added effects that predict
    TRAIN's session average on a TEST of another session and those that read its own times as the session clock
    (:func:`l1b2.closeloop.othersession.record`).
    ``named_checks``: every named pick of a round from the Eq. 29 baseline, cross-validated again from the
    pure-slip family (:mod:`l1b2.closeloop.crosscheck`), with its figures and outcome; every named pick read as
    physics also carries ``identification``, the joint Wald test of its parameters against zero under the
    reported covariance (:func:`l1b2.closeloop.intervals.identification`), and is not added when it fails.
    ``physical_range``: after each joint refit with a channel's damping form, the total viscous damping's smallest
    value over TRAIN's range of the channel per such form (``damping_floor_N_s_per_m``) and the outcome (``kept``,
    or ``refused``: a negative floor, the pick not added).
    ``input_readings``: each pick of an auxiliary channel that the predictor's own inputs replaced within one
    standard error (:func:`l1b2.closeloop.acceptance.input_reading`: ``round``, ``pick``, ``taken``, ``gap``,
    ``se``, ``share``).
    ``auxiliary_columns``: what was done to each auxiliary column that was not numeric and finite as logged
    (flags, text labels, gaps; :func:`l1b2.closeloop.auxiliary.with_usable_channels`).
    ``response_test``: the consequence test of each logged column that varies within runs, whether the speed's
    history explains it as a response of the motion, with ``applied`` and ``decided_by``
    (:func:`l1b2.closeloop.responses.response_tests`, :func:`l1b2.closeloop.responses.with_applied`).
    ``rest_before_onset``: TRAIN's runs at rest before their onset, cut on reading
    (:func:`l1b2.data.onset.from_onset`'s record; None when none was cut; :func:`l1b2.closeloop.evidence.with_onset`).
    The nested evidence stays JSON-shaped.
    """

    significant: bool
    traced_to: list
    effect: str | None
    effect_shape: str | None
    effect_description: str | None
    effects: list
    message: str
    structural_effects: list = field(default_factory=list)
    immaterial_evidence: list = field(default_factory=list)
    residual_trace: list = field(default_factory=list)
    candidates: list = field(default_factory=list)
    n_candidates_scored: int = 0
    significance_level: Any = None
    refit_trials: list = field(default_factory=list)
    rules: dict = field(default_factory=dict)
    regressor_evidence: list = field(default_factory=list)
    whiteness: dict = field(default_factory=dict)
    position_spectrum_peak: dict = field(default_factory=dict)
    measurement_chain: dict = field(default_factory=dict)
    channels_considered: list = field(default_factory=list)
    baseline_choice: dict = field(default_factory=dict)
    run_level: Any = None
    named_checks: list = field(default_factory=list)
    event_clocks: list = field(default_factory=list)
    lagged_channels: list = field(default_factory=list)
    pause_channel: dict = field(default_factory=dict)
    break_clock: dict = field(default_factory=dict)
    previous_pass: dict = field(default_factory=dict)
    run_clock: dict = field(default_factory=dict)
    run_travel: dict = field(default_factory=dict)
    log_channels: list = field(default_factory=list)
    run_settings: list = field(default_factory=list)
    unseen_levels: dict = field(default_factory=dict)
    channel_ranges: list = field(default_factory=list)
    test_session: dict = field(default_factory=dict)
    physical_range: list = field(default_factory=list)
    input_readings: list = field(default_factory=list)
    auxiliary_columns: list = field(default_factory=list)
    response_test: list = field(default_factory=list)
    rest_before_onset: Any = None
    run_level_rounds: list = field(default_factory=list)

    def to_dict(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["effects"] = [e.to_dict() for e in self.effects]
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> Diagnosis:
        kw = _take(cls, d, "diagnosis", optional=tuple(f.name for f in fields(cls))[7:])
        kw["effects"] = [e if isinstance(e, EffectRecord) else EffectRecord.from_dict(e) for e in kw["effects"]]
        return cls(**kw)


def chain_line(rec: Mapping) -> str:
    """One line on the measurement chain's test (``diagnosis.measurement_chain``): how far the speed column is from
    the position's derivative (``rel_rms_mismatch``, a share of the speed's rms) and what the speed channel's
    filter test found; empty when the record is empty."""
    if not rec:
        return ""
    if "rel_rms_mismatch" not in rec:
        return f"Measurement chain: not tested ({rec.get('reason', 'no record')})."
    clip = rec.get("clip") or {}
    found = (f"the chain kept is the range below, with {'a' if clip.get('inner_filter') else 'no'} filter inside it"
             if rec.get("accepted") and clip.get("accepted") else "its filter was kept" if rec.get("accepted")
             else "a filter was found but not applied (it did not lower the cross-validated free-run error)"
             if rec.get("refused_by_harm_guard") else "no filter passed the test")
    return (f"Measurement chain: the speed column differs from the position's derivative by "
            f"{float(rec['rel_rms_mismatch']):.1%} of the speed's rms; the speed channel's test "
            f"(held-out gain {float(rec.get('cv_gain', 0.0)):.1%}, p {float(rec.get('p_value', 1.0)):.2g}): {found}."
            + clip_sentence(clip, applied=bool(rec.get("accepted"))) + stamps_sentence(rec.get("time_stamps") or {})
            + cyclic_sentence(rec.get("position_cyclic_error") or {}))


def stamps_sentence(rec: Mapping) -> str:
    """The sentence on the time stamps' chain (``measurement_chain.time_stamps``,
    :func:`l1b2.closeloop.stamps.decide`): the screen's held-out gain and p-value, ``gamma`` and whether it was
    kept; empty when the stage was not considered (even time steps)."""
    if not rec.get("considered"):
        return ""
    g = rec.get("gamma") if rec.get("accepted") else (rec.get("gamma_of_baseline") or {}).get("gamma")
    verdict = ("kept: the prediction is multiplied by r^gamma" if rec.get("accepted") else "not kept")
    return (f" The time steps are uneven: a speed derived over stamps that are not the samples' times (logged speed"
            f" = r^gamma x the slider's, r the time step ratio) has held-out gain {float(rec.get('cv_gain', 0.0)):.1%}"
            f" (p {float(rec.get('p_value', 1.0)):.2g}), gamma {float(g if g is not None else float('nan')):.3f}"
            f" (1: stamps given on arrival, 0: true stamps): {verdict}.")


def cyclic_sentence(rec: Mapping) -> str:
    """The sentence on the position sensor's cyclic error (``measurement_chain.position_cyclic_error``,
    :func:`l1b2.closeloop.encoder.decide`): the pitch, the screen's held-out gain against the force family's at the
    same pitch, and whether it was kept; empty when the stage was not considered (no line in the residual's
    spectrum over the position)."""
    if not rec.get("considered") or "cv_gain" not in rec:
        return ""
    verdict = "kept: the prediction is multiplied by 1 + e'(s)" if rec.get("accepted") else "not kept"
    return (f" The residual's spectrum over the position has a line: a position sensor's cyclic error of pitch "
            f"{float(rec['pitch_m']) * 1e3:.4f} mm (logged speed = (1 + e'(s)) x the slider's) has held-out gain "
            f"{float(rec['cv_gain']):.1%} (p {float(rec.get('p_value', 1.0)):.2g}), the bar's waviness at that pitch "
            f"{float(rec.get('force_cv_gain', 0.0)):.1%}: {verdict}.")


def clip_sentence(clip: Mapping, applied: bool = True) -> str:
    """The sentence on the speed channel's range test (``measurement_chain.clip``): the rails with their samples (and
    the band a noisy rail's samples lie in) and the clipped chain's held-out gain over the chain without a clip;
    empty when no rail was found. ``applied``: whether the chain was kept (the harm guard may refuse a chain whose
    test passed)."""
    rails = [f"{clip[f'{side}_m_s']:+.4g} m/s ({clip[f'n_{side}']} samples in {clip[f'runs_{side}']} runs"
             + (f", within {1e3 * clip[f'band_{side}_m_s']:.3g} mm/s of the column's extreme: a noisy rail"
                if clip.get(f"band_{side}_m_s") else "") + ")"
             for side in ("lo", "hi") if clip.get(f"{side}_m_s") is not None]
    if not rails:
        return ""
    verdict = ("not kept" if not clip.get("accepted") else "kept: the prediction is clipped after the filter"
               if applied else "passed, but the chain was not applied (it did not lower the cross-validated "
               "free-run error)")
    return (f" The column saturates at {' and '.join(rails)}, {float(clip.get('share_at_rails', 0.0)):.1%} of the "
            f"samples; the clip's held-out gain over the chain without it {float(clip.get('cv_gain', 0.0)):.1%} "
            f"(p {float(clip.get('p_value', 1.0)):.2g}): {verdict}.")


def _history_text(r: Mapping) -> str:
    """How report.md names a consequence test's best history of the speed (a record's ``history`` and ``tau_s``)."""
    if r.get("history") == "rate":
        return "the speed's rate through a bank of first-order filters"
    signed = r.get("history") == "signed" or (r.get("history") is None and r.get("signed"))
    return f"sensor lag {r['tau_s']} s{', of the signed speed' if signed else ''}"


def response_test_lines(tests) -> list:
    """report.md's lines on the consequence test (``diagnosis.response_test``): one per tested column with its share,
    its runs and the outcome; empty when no column was tested."""
    if not tests:
        return []
    lines = ["", "Consequence test of the logged columns that vary within runs (the share of a column's within-run "
             "variation, beyond each run's level and trend and a function of the position, that a smooth function "
             "of the speed or a filter of its rate explains; a response: at least half, in more runs than chance, "
             "and more than the drive's own course from the run's start explains):", ""]
    return lines + [f"- `{r['channel']}`: share {r['share']:.0%} ({_history_text(r)}), above half in "
                    f"{r['runs_above']} of {r['n_runs']} runs (p {r['p_value']:.2g})"
                    + (f", constant in {r['runs_constant']} other runs (not tested there)" if r.get("runs_constant")
                       else "")
                    + (f", the drive's course from the run's start {r['drive_share']:.0%}" if r.get("drive_share")
                       else "") + ": "
                    f"{'a response' if r['response'] else 'not a response'}"
                    f"{'' if r['decided_by'] == 'test' else ' (the response_columns setting decides)'}; "
                    f"{'not a candidate' if r['applied'] else 'a candidate'}" for r in tests]


def run_setting_lines(records) -> list:
    """report.md's lines on the run settings (``diagnosis.run_settings``): one per column a setting was sought in (a
    response, a column read along the stroke), derived or not and why; empty when there is none."""
    if not records:
        return []
    lines = ["", "Run settings of the readings the motion makes in part (each run's level less what the motion makes "
             "of it by a law fitted on TRAIN; derived when the plan's inputs explain less than half of the levels "
             "and they scatter beyond their noise):", ""]
    what = {"response": "a response", "along_stroke": "read along the stroke"}
    return lines + [f"- `{r['from']}` ({what.get(r.get('source'), r.get('source'))}) -> `{r['channel']}`: "
                    + (f"spread over TRAIN's runs {r['run_spread']:.4g}, the motion's {r['echo_spread']:.4g}, the "
                       f"plan explains {r['plan_share']:.0%}, scatter p {r['scatter_p']:.2g}; "
                       if "scatter_p" in r else "")
                    + ("derived, a candidate" if r["derived"] else r["note"]) for r in records]


def channel_range_line(rec: Mapping) -> str:
    """One line on a logged channel whose TEST values leave TRAIN's range (a record of
    ``diagnosis.channel_ranges``); empty when none does."""
    if not rec.get("runs_outside"):
        return ""
    how = {"extrapolates": "extrapolate linearly", "clipped": "are held at TRAIN's range's end (saturate)"}
    effects = "; ".join(f"`{label}` {how.get(v, v)}" for label, v in rec["effects"].items())
    lo, hi = rec["train"]
    return (f"TEST has {rec['samples_outside']:.1%} of its samples ({rec['runs_outside']} of {rec['test_runs']} "
            f"runs) with {rec['signal']} outside TRAIN's range [{lo:.4g}, {hi:.4g}] (TEST: "
            f"[{rec['test'][0]:.4g}, {rec['test'][1]:.4g}]): the effects of it there {effects}")


def other_session_line(rec: Mapping | None) -> str:
    """One line on a TEST of another session whose model left effects at TRAIN's session average or reads TEST's
    own clock (a ``diagnosis.test_session`` record, :func:`l1b2.closeloop.othersession.record`); empty
    otherwise."""
    if not rec or rec.get("one_session", True):
        return ""
    parts = []
    if rec.get("session_average"):
        parts.append("TEST is predicted at TRAIN's session average of "
                     + ", ".join(f"`{x}`" for x in rec["session_average"])
                     + ", not at the level of the block its times fall in")
    if rec.get("own_clock"):
        parts.append(", ".join(f"`{x}`" for x in rec["own_clock"]) + " read TEST's own times as TRAIN's session "
                     "clock (right for a course since the session's start, not for one over the rig's life)")
    return ("TEST's runs overlap TRAIN's in time (TEST was recorded on a clock of its own): " + "; ".join(parts)
            if parts else "")


def undetermined_line(parameters: Mapping) -> str:
    """One line naming the varied parameters of a model's ``parameters`` (the report's ``baseline_parameters``:
    name -> ``{"vary", "identifiable", ...}``) that TRAIN does not determine (no finite standard error: a
    direction of the parameters along which the predictions do not change to first order at the fitted values: TRAIN
    at one load or one drive amplitude, or a fit where a parameter's effect vanishes); empty when every varied one is
    determined. Their values are one point of that direction: TEST's
    figures then depend on where it lies."""
    names = [n for n, p in (parameters or {}).items()
             if isinstance(p, Mapping) and p.get("vary") and p.get("identifiable") is False]
    if not names:
        return ""
    return (f"TRAIN does not determine the baseline's {', '.join(names)} (no standard error: at the fitted values "
            "the predictions do not change, to first order, along a direction of them; the data may lack it, or the "
            "fit may sit where a parameter's effect vanishes): their values are one point of that direction, and "
            "predictions beyond TRAIN's plan (TEST) depend on where it lies")


def left_line(rounds: list, p_show: float = 0.05) -> str:
    """``report.md``'s line on the run-level evidence against the final model (the last entry of
    ``diagnosis.run_level_rounds``): the signals it leaves significant at the Bonferroni level and those below
    ``p_show`` that are not, each with its p-value; empty when no analysis was made."""
    if not rounds:
        return ""
    last = rounds[-1]
    sig = [f"{s['signal']} (p {s['p_value']:.2g})" for s in last["signals"] if s["significant"]]
    near = [f"{s['signal']} (p {s['p_value']:.2g})" for s in last["signals"]
            if not s["significant"] and s["p_value"] < p_show]
    return (f"Run-level evidence left against the final model (the runs' deviations from it, "
            f"{'after the last round' if last['round'] is None else 'in round ' + str(last['round'])}): "
            f"significant at the Bonferroni level {last['significance_level']:.2g}: {', '.join(sig) or 'none'}; "
            f"below p {p_show:g} but not significant: {', '.join(near) or 'none'}.")


def pct(x, spec: str = ".2%") -> str:
    """A report value as a percentage: ``"-"`` for None (NaN), the rule's ``"inf"``/``"-inf"`` as written."""
    if x is None:
        return "-"
    return x if isinstance(x, str) else format(x, spec)


def search_line(family: str, r: Mapping) -> str:
    """The line on a fit of a drive law searched again because it was below the level law
    (:func:`l1b2.closeloop.guard.checked_fit`'s record; ``family``: the drive law, with the fit's purpose when it
    is not the baseline); empty when it was not searched again."""
    if not r.get("searched_again"):
        return ""
    ll = r.get("loglik") or {}
    kept = "the seed-free search's fit" if r.get("kept") == "rescue" else "the multistart's fit"
    num = (lambda x: "-" if x is None else f"{x:.6g}")
    rescue = (f"failed ({r['rescue_failed']})" if r.get("rescue_failed") else
              f"log-likelihood {num(ll.get('rescue'))} against {num(ll.get('first'))}, TRAIN free-run nrmse "
              f"{pct(r.get('rescue_train_free_run_nrmse'))}")
    return (f"the {family} fit's TRAIN free-run nrmse {pct(r.get('train_free_run_nrmse'))} was above that of an "
            f"affine law of the runs' speed levels in V0 and the load ({pct(r.get('level_law_nrmse'))}): searched "
            f"again from the seed-free search without pins ({rescue}); kept {kept}")


def loop_check_lines(diagnosis: Mapping, baseline_parameters: Mapping) -> list:
    """The close loop's warnings beyond the data's checks, one line each: the logged channels whose TEST values
    leave TRAIN's range (:func:`channel_range_line`), the effects at TRAIN's session average on a TEST of another
    session (:func:`other_session_line`), the baseline's parameters TRAIN does not determine
    (:func:`undetermined_line`) and the fits searched again below the level law (:func:`search_line`); no empty
    line."""
    lines = [channel_range_line(r) for r in diagnosis.get("channel_ranges") or ()]
    lines += [other_session_line(diagnosis.get("test_session"))]
    lines += [undetermined_line(baseline_parameters)]
    lines += [search_line(f, r) for f, r in ((diagnosis.get("baseline_choice") or {}).get("search") or {}).items()]
    return [line for line in lines if line]
