"""What a close-the-loop fit found: diagnosis, candidate scores, error before and after, report and figures.

:class:`CloseLoopResult` is returned by :func:`l1b2.closeloop.loop.close_loop`
(and kept as ``CloseLoop.result_``). It computes nothing new: it presents.
``to_dict()`` is the content of ``report.json`` (strict JSON under the
package's one rule, :mod:`l1b2.jsonio`: NaN -> ``null``, +-inf -> ``"inf"``/``"-inf"``), ``markdown()`` that of
``report.md``, ``plot()`` returns the figures, and ``save(dir)`` is the only method that writes files
(``report.json``, ``report.md`` and the PNGs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..data import plots
from ..data.gaps import gap_lines
from ..data.coverage import channel_outside_lines, speed_source_lines
from ..data.onset import onset_lines
from ..data.plausibility import uneven_step_lines
from ..jsonio import dumps, sig, strict_json
from ..predictor.effects import ExtendedPredictor
from . import residuals as res
from .crosscheck import describe
from .report import (SCHEMA_VERSION, Diagnosis, ReportFormatError, Round, chain_line, left_line, loop_check_lines,
                     pct, run_setting_lines, response_test_lines)
from .selection import Score

#: file names (without ``.png``) of the figures, in report order
FIGURES = ("residual_vs_regressors", "residual_spectrum_and_whiteness", "chosen_effect", "before_after_test")



@dataclass(eq=False)
class ResidualAnalysis:
    """The TRAIN residual and what :mod:`l1b2.closeloop.residuals` found in it."""

    residual: np.ndarray          #: drive-coordinate free-run residual per TRAIN sample [m/s]
    mask: np.ndarray              #: the evaluation mask of TRAIN
    whiteness: list               #: per-run whiteness (``residuals.whiteness``)
    frequency: np.ndarray         #: spatial frequencies of the position spectrum [1/m]
    power: np.ndarray             #: residual power per frequency
    peak: dict                    #: the spectrum's peak (``residuals.position_spectrum``)
    traced: list                  #: regressors traced by forward selection
    rounds: list                  #: per round, the ``residuals.Evidence`` of each regressor


@dataclass
class CloseLoopResult:
    """Outcome of one close-the-loop fit (TEST never used for fitting or choosing).

    The report's fields (what ``report.json`` holds, :meth:`to_dict`) are
    JSON-normal values (:mod:`l1b2.jsonio`: NaN as None, infinities as
    ``"inf"``) and typed records; :meth:`from_dict` rebuilds an equal result
    from ``report.json`` (equality compares the report's fields only).

    Attributes
    ----------
    baseline, extended : dict
        Error metrics ``{"train": {"one_step": ..., "free_run": ...}, "test": ...}``
        of the baseline and of the extended model (``extended`` is None when
        nothing was significant; ``"test"`` is None without TEST data).
    diagnosis : Diagnosis
        What was found, traced and added (:class:`l1b2.closeloop.report.Diagnosis`).
    rounds : list of Round
        Per round: what was added, its CV result, the metrics after.
    extended_parameters, baseline_parameters : dict
        The new parameters (value, stderr, ci95, unit) and the baseline's.
    data : dict
        Files, run and sample counts of TRAIN and TEST.
    checks : dict or None
        The data checks (unit findings, TEST runs outside TRAIN's range), set by the caller.
    wall_time_s : float or None
        Wall time of the job [s].
    stages : list of dict
        Time and evaluations per stage of the fit (:class:`l1b2.closeloop.stages.StageClock`): stage,
        wall_s, cpu_s (this process), identifications, nfev; not compared (timings differ between runs).
    calibrated_model : ExtendedPredictor or None
        The final model as :class:`l1b2.predictor.effects.ExtendedPredictor` (what ``Predictor.fmu``
        carries; the baseline alone when nothing was added; None when an effect has no serialisable
        spec), ``calibrated_note`` says which.
    scores, significant, chosen
        Every candidate scored in the first round (:class:`~l1b2.closeloop.selection.Score`), those that
        passed every rule, the one added first (not in the report; None after :meth:`from_dict`).
    """

    baseline: dict
    diagnosis: Diagnosis
    extended: dict | None
    extended_parameters: dict | None
    baseline_parameters: dict
    data: dict
    wall_time_s: float | None = None
    rounds: list = field(default_factory=list)
    checks: dict | None = None
    calibrated_model: Any = field(default=None, repr=False)
    calibrated_note: str = ""
    stages: list = field(default_factory=list, compare=False)
    # -- what the fit holds besides the report (not compared, not serialised) --
    scores: list = field(default_factory=list, repr=False, compare=False)
    significant: list = field(default_factory=list, repr=False, compare=False)
    chosen: Score | None = field(default=None, repr=False, compare=False)
    baseline_model: Any = field(default=None, repr=False, compare=False)
    extended_model: Any = field(default=None, repr=False, compare=False)
    analysis: ResidualAnalysis | None = field(default=None, repr=False, compare=False)
    train_df: pd.DataFrame | None = field(default=None, repr=False, compare=False)
    test_df: pd.DataFrame | None = field(default=None, repr=False, compare=False)
    test_free_run_before: np.ndarray | None = field(default=None, repr=False, compare=False)
    test_free_run_after: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        # the report's fields in JSON-normal form (NaN -> None, inf -> "inf", numpy -> Python), typed records
        for name in ("baseline", "extended", "extended_parameters", "baseline_parameters", "data", "checks"):
            setattr(self, name, strict_json(getattr(self, name)))
        if not isinstance(self.diagnosis, Diagnosis):
            self.diagnosis = Diagnosis.from_dict(strict_json(self.diagnosis))
        self.rounds = [r if isinstance(r, Round) else Round.from_dict(strict_json(r)) for r in self.rounds]
        if self.wall_time_s is not None:
            self.wall_time_s = strict_json(self.wall_time_s)

    # -- views ---------------------------------------------------------------
    @property
    def before(self) -> dict:
        """Error metrics of the baseline (``self.baseline``)."""
        return self.baseline

    @property
    def after(self) -> dict | None:
        """Error metrics of the extended model, None when the baseline was kept."""
        return self.extended

    def scores_to_pandas(self) -> pd.DataFrame:
        """One row per candidate scored, by decreasing held-out gain, with ``significant``/``chosen`` flags."""
        sig = {id(s) for s in self.significant}
        rows = []
        for s in self.scores:
            d = s.to_dict()
            d["family"] = d.pop("effect")
            d["significant"] = id(s) in sig
            d["chosen"] = s is self.chosen
            rows.append(d)
        cols = ["family", "label", "regressor", "generic", "n_params", "cv_gain", "p_value", "runs_improved",
                "delta_aic", "delta_bic", "significant", "chosen", "parameters"]
        df = pd.DataFrame(rows, columns=cols)
        return df.sort_values("cv_gain", ascending=False, kind="stable").reset_index(drop=True)

    def before_after_table(self) -> str:
        """Plain-text table of the error metrics before and after (TEST and TRAIN)."""
        return before_after_table({"baseline": self.baseline, "extended": self.extended})

    def rounds_table(self) -> str:
        """Plain-text table: per round, the effect added and the free-run nrmse (TRAIN, TEST) after it."""
        return rounds_table(self.to_dict())

    def to_dict(self) -> dict:
        """The report (``report.json`` without ``figures``), strict JSON (:func:`l1b2.jsonio.strict_json`)."""
        return strict_json({
            "schema_version": SCHEMA_VERSION,
            "baseline": self.baseline,
            "diagnosis": self.diagnosis.to_dict(),
            "extended": self.extended,
            "rounds": [r.to_dict() for r in self.rounds],
            "extended_parameters": self.extended_parameters,
            "baseline_parameters": self.baseline_parameters,
            "data": self.data,
            "checks": self.checks,
            "wall_time_s": self.wall_time_s,
            "calibrated_model": self.calibrated_model.to_dict() if self.calibrated_model is not None else None,
            "calibrated_note": self.calibrated_note,
            "stages": self.stages,
        })

    @classmethod
    def from_dict(cls, d: Mapping) -> CloseLoopResult:
        """The result of a report dict (``report.json``; ``figures`` ignored), equal to the one that wrote it.

        Raises :class:`l1b2.closeloop.report.ReportFormatError` naming the
        field when a field is missing or the schema version is not this one.
        """
        if not isinstance(d, Mapping):
            raise ReportFormatError(f"report: expected an object, got {type(d).__name__}")
        version = d.get("schema_version")
        if version != SCHEMA_VERSION:
            raise ReportFormatError(f"report: schema_version {version!r}, this version reads {SCHEMA_VERSION}")
        try:
            cal = d["calibrated_model"]
            return cls(baseline=d["baseline"], diagnosis=Diagnosis.from_dict(d["diagnosis"]), extended=d["extended"],
                       extended_parameters=d["extended_parameters"], baseline_parameters=d["baseline_parameters"],
                       data=d["data"], wall_time_s=d["wall_time_s"],
                       rounds=[Round.from_dict(r) for r in d["rounds"]], checks=d["checks"],
                       calibrated_model=None if cal is None else ExtendedPredictor.from_dict(cal),
                       calibrated_note=d["calibrated_note"], stages=list(d.get("stages", [])))
        except KeyError as exc:
            raise ReportFormatError(f"report: field {exc.args[0]!r} missing") from None

    def markdown(self) -> str:
        """The report as Markdown (``report.md`` without the figure links)."""
        return markdown_report(self.to_dict())

    # -- figures and files ---------------------------------------------------
    def plot(self) -> dict:
        """The report's figures as ``{name: matplotlib Figure}`` (names as in :data:`FIGURES`); writes nothing.

        ``chosen_effect`` only when a candidate was chosen, ``before_after_test``
        only with TEST data. The caller closes the figures.
        """
        a = self.analysis
        if a is None or self.train_df is None:
            raise ValueError("this result carries no residual analysis to plot")
        plt = plots.pyplot()
        figs = {"residual_vs_regressors": _fig_residual_vs_regressors(plt, self.train_df, a),
                "residual_spectrum_and_whiteness": _fig_spectrum_and_whiteness(plt, a)}
        if self.chosen is not None:
            figs["chosen_effect"] = _fig_chosen(plt, self.train_df, a.mask, self.chosen)
        if self.test_df is not None and self.test_free_run_before is not None:
            figs["before_after_test"] = _fig_before_after(plt, self.test_df, self.test_free_run_before,
                                                          self.test_free_run_after,
                                                          bool((self.data or {}).get("test_speed_derived")))
        return figs

    def save(self, directory, *, plots_on: bool = True) -> list[Path]:
        """Write ``report.json``, ``report.md`` and (``plots_on``) the PNGs into ``directory``; the paths written."""
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        report = self.to_dict()
        written = []
        if plots_on:
            for name, fig in self.plot().items():
                written.append(plots.save_figure(fig, out / f"{name}.png"))
            report["figures"] = [str(p) for p in written]
        (out / "report.json").write_text(dumps(report))
        (out / "report.md").write_text(markdown_report(report))
        return [out / "report.json", out / "report.md"] + written


# ---------------------------------------------------------------------------
# text
# ---------------------------------------------------------------------------

def _interval_kind(p: dict) -> str:
    """The report's name of the clustering behind a parameter's interval (``interval`` of its record)."""
    kind = p.get("interval")
    if kind == "level":
        return f"level (V0, load size; {p['clusters']} clusters of runs)"
    return {"run": "run", "model": "none (model-based)"}.get(kind, "-")


def before_after_table(report: dict) -> str:
    """Plain-text table of the error metrics before and after (TEST and TRAIN) of a report dict."""
    def f(x):
        return pct(x, ".2%")

    lines = [f"{'':8s}{'':10s}{'nrmse':>18s}{'mean |rel|':>22s}{'p95 |rel|':>22s}",
             f"{'data':8s}{'kind':10s}{'before':>9s}{'after':>9s}{'before':>11s}{'after':>11s}"
             f"{'before':>11s}{'after':>11s}"]
    for part in ("test", "train"):
        if report["baseline"].get(part) is None:
            continue
        for kind in ("free_run", "one_step"):
            b = report["baseline"][part][kind]
            a = report["extended"][part][kind] if report["extended"] else None
            lines.append(f"{part:8s}{kind:10s}{f(b['nrmse']):>9s}{f(a['nrmse'] if a else None):>9s}"
                         f"{f(b['mean_abs_rel_error']):>11s}{f(a['mean_abs_rel_error'] if a else None):>11s}"
                         f"{f(b['p95_abs_rel_error']):>11s}{f(a['p95_abs_rel_error'] if a else None):>11s}")
    return "\n".join(lines)


def rounds_table(report: dict) -> str:
    """Per round: the effect added, its cross-validated (refit) gain and the free-run nrmse before/after it."""
    def f(x):
        return pct(x, ".2%")

    rounds = report.get("rounds") or []
    lines = [f"{'round':6s}{'added':44s}{'CV gain':>9s}{'train before':>14s}{'train after':>13s}"
             f"{'test before':>13s}{'test after':>12s}"]
    for prev, rnd in zip(rounds[:-1], rounds[1:]):
        def nr(rec, part):
            m = rec["metrics"].get(part)
            return m["free_run"]["nrmse"] if m else None
        lines.append(f"{rnd['round']:<6d}{(rnd['added'] or '-')[:43]:44s}{f(rnd['cv'].get('cv_gain')):>9s}"
                     f"{f(nr(prev, 'train')):>14s}{f(nr(rnd, 'train')):>13s}{f(nr(prev, 'test')):>13s}"
                     f"{f(nr(rnd, 'test')):>12s}")
    if len(rounds) <= 1:
        lines.append("(no round added an effect: the baseline is kept)")
    return "\n".join(lines)


def stages_table(stages: list) -> str:
    """Markdown table of the stage records (:class:`l1b2.closeloop.stages.StageClock`) with their total."""
    rows = ["| stage | wall [s] | CPU [s] | identifications | evaluations |", "|---|---|---|---|---|"]
    for r in stages:
        rows.append(f"| {r['stage']} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['identifications']} | {r['nfev']} |")
    rows.append(f"| total | {sum(r['wall_s'] for r in stages):.1f} | {sum(r['cpu_s'] for r in stages):.1f} | "
                f"{sum(r['identifications'] for r in stages)} | {sum(r['nfev'] for r in stages)} |")
    return "\n".join(rows)


def run_level_line(r: dict) -> str:
    """``report.md``'s line on the first round's run-level deviations (``diagnosis.run_level``): their spread, the
    heterogeneity test and the significant signals, each that a correlated one explains marked as not traced."""
    dom = r.get("dominated_signals", {})
    signals = [f"{s} (explained by {dom[s]} given it, not traced)" if s in dom else s for s in r["significant_signals"]]
    return (f"Run-level deviations (first round, {r['runs']} runs, shrunk by REML): between-run sd of the "
            f"drive-force gain {r['between_run_sd_gain']:.2%}, of the offset {r['between_run_sd_offset_N']:.3g} N; "
            f"heterogeneity p {r['heterogeneity_p']:.2g}; signals explaining them (Bonferroni level "
            f"{r['significance_level']:.2g}): {', '.join(signals) or 'none'}.")


def data_check_sections(checks: dict) -> list[str]:
    """``report.md``'s sections on the data checks of ``checks`` (report.json's): the gaps filled on reading, the
    uneven time steps, the rest before each run's onset, a TEST speed of another kind than TRAIN's and the logged
    channels TEST takes outside TRAIN's values, each a titled list when it has lines."""
    out = []
    for title, lines in (("Gaps in optional input columns, filled on reading:", gap_lines(checks.get("gaps_filled"))),
                         ("Uneven time steps:", uneven_step_lines(checks.get("uneven_time_steps"))),
                         ("Rest before each run's onset, cut on reading:",
                          onset_lines(checks.get("rest_before_onset"))),
                         ("Speed source:", speed_source_lines(checks.get("speed_derived"))),
                         ("Logged channels outside TRAIN's values:",
                          channel_outside_lines(checks.get("channels_outside")))):
        if lines:
            out += [title, ""] + [f"* {g}" for g in lines] + [""]
    return out


def refit_trial_lines(rounds: list) -> list[str]:
    """report.md's table of each round's refit trials (``diagnosis.refit_trials``): why the round refit each
    (``offered_by``, "-" in a report written before the key) and its cross-validated evidence."""
    lines = []
    for i, trials in enumerate(rounds, 1):
        if trials:
            lines += ["", f"Round {i}: candidates refit and cross-validated:", "",
                      "| candidate | offered by | regressors | linearised gain | CV nrmse current | CV nrmse refit "
                      "| CV gain | SE over runs | folds improved | runs improved |",
                      "|---|---|---|---|---|---|---|---|---|---|"]
            for t in trials:
                runs = f"{t['runs_improved']}/{t['runs']}" if t.get("runs") else "-"
                lines.append(f"| {t['label']} | {t.get('offered_by', '-')} | {', '.join(t['regressors'])} | "
                             f"{pct(t['linearised_gain'], '.1%')} | "
                             f"{pct(t['cv_free_run_nrmse_current'], '.2%')} | "
                             f"{pct(t['cv_free_run_nrmse_refit'], '.2%')} | {pct(t['cv_gain'], '.1%')} | "
                             f"{pct(t.get('cv_gain_se_runs'), '.1%')} | {t['folds_improved']}/{t['folds']} | {runs} |")
    return lines


def markdown_report(rep: dict) -> str:
    """``report.md`` from a report dict (:meth:`CloseLoopResult.to_dict`, plus ``figures`` when saved)."""
    d = rep["diagnosis"]
    data = rep["data"]
    test = (f"TEST: `{data['test']}` ({data['test_runs']} runs; never used for fitting or choosing)."
            if data.get("test") is not None else "no TEST data.")
    lines = ["# Close the loop: residual -> missing effect -> extended model", "",
             f"TRAIN: `{data['train']}` ({data['train_runs']} runs), {test}", ""]
    lines += data_check_sections(rep.get("checks") or {})
    lines += ["## Diagnosis", "", f"**{d['message']}**", ""]
    if d["significant"]:
        lines += [f"* traced to: {', '.join(d['traced_to'])}",
                  f"* effect: `{d['effect']}` {d['effect_shape'] or ''} — {d['effect_description']}"]
    else:
        lines += ["* the baseline is kept (no shortlisted candidate's re-identified model lowered the "
                  f"cross-validated free-run error by >= {d['rules'].get('min_cv_gain', 0):.0%} in most run folds)"]
    for e in d.get("effects", [])[1:]:
        lines.append(f"* then (round {e['round']}): `{e['label']}` ({', '.join(e['regressors'])}) — "
                     f"{e['description']}")
    for e in d.get("structural_effects", []):
        lines.append(f"* `{e['label']}` relaxes the paper model's own approximation ({e['relaxes']}); traced after "
                     "the missing effects")
    for t in d.get("immaterial_evidence", []):
        lines.append(f"* evidence below the materiality threshold: `{t['label']}` ({', '.join(t['regressors'])}), "
                     f"CV nrmse {t['cv_free_run_nrmse_current']:.2%} -> {t['cv_free_run_nrmse_refit']:.2%} "
                     f"(< {d['rules'].get('min_cv_drop', 0):.2%} drop: not added)")
    lines += [f"* {describe(c)}" for c in d.get("named_checks", [])]
    lines += [f"* round {c['round']}: `{c['label']}` refused, the total viscous damping turns negative within "
              f"TRAIN's range of the channel (" + ", ".join(f"{k}: {v:.3g} N s/m" for k, v in
                                                            c["damping_floor_N_s_per_m"].items()) + ")"
              for c in d.get("physical_range", []) if c["outcome"] != "kept"]
    lines += [f"* round {c['round']}: `{c['pick']}` reads a channel that the model's inputs stand for: `{c['taken']}` "
              f"taken instead (its CV gain {abs(c['gap']):.3f} {'lower' if c['gap'] >= 0 else 'higher'}, within one "
              f"SE {c['se']:.3f}; it explains "
              f"{c['share']:.0%} of the channel's force)" for c in d.get("input_readings", [])]
    for label, u in (d.get("unseen_levels") or {}).items():
        values = ", ".join(format(v, "g") for v in u["values"])
        lines.append(f"* TEST has {u['runs']} run(s) at {u['channel']} = {values}, a value TRAIN never had: "
                     f"`{label}` gives them TRAIN's average over runs (its prediction there carries no effect of "
                     "that value)")
    lines += [f"* {line}" for line in loop_check_lines(d, rep.get("baseline_parameters"))]
    bc = d.get("baseline_choice") or {}
    if bc.get("families"):
        lines += ["", f"## Baseline family (chosen: `{bc['chosen']}`, by TRAIN's cross-validated free-run nrmse over "
                  f"{bc.get('folds')} run folds)", "", "| family | CV nrmse | TRAIN nrmse | failed folds |",
                  "|---|---|---|---|"]
        for fam, r in bc["families"].items():
            lines.append(f"| {fam} | {pct(r['cv_free_run_nrmse'], '.2%')} | {pct(r['train_free_run_nrmse'], '.2%')} "
                         f"| {r['folds_failed']} |")
    lines += ["", "## Rounds (free-run nrmse before/after each added effect; CV gain = held-out free-run "
              "sum of squares of the re-identified model over run folds)", "", "```", rounds_table(rep), "```"]
    lines += refit_trial_lines(d.get("refit_trials", []))
    lines += ["", "## Error before and after (all rounds)", "", "```", before_after_table(rep), "```", "",
              "## Candidates (best of each family, by held-out gain)", "",
              "| effect | regressor | params | held-out gain | p (runs) | runs improved | dAIC | dBIC |",
              "|---|---|---|---|---|---|---|---|"]
    for c in d["candidates"]:
        lines.append(f"| {c['label']} | {c['regressor']} | {c['n_params']} | {c['cv_gain']:.1%} | "
                     f"{c['p_value']:.2g} | {c['runs_improved']:.0%} | {c['delta_aic']:.1f} | "
                     f"{c['delta_bic']:.1f} |")
    if d.get("channels_considered"):
        lines += ["", "## Channels and protocol signals considered (first round, best form of each)", "",
                  "| channel | kind | traced as | best form | held-out gain | p (runs) | run-level evidence | "
                  "significant | added |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for c in d["channels_considered"]:
            p = "-" if c["p_value"] is None else format(c["p_value"], ".2g")
            runl = "; ".join(f"{e['signal']}: p {e['p_value']:.2g}, gain {e['cv_gain']:.1%}"
                             for e in c.get("run_level") or []) or (
                f"none ({c['per_sample_only']})" if c.get("per_sample_only") else "-")
            lines.append(f"| {c['channel']} | {c['kind']} | {c['regressor']} | {c['best'] or c['note']} | "
                         f"{pct(c['cv_gain'], '.1%')} | {p} | {runl} | "
                         f"{'yes' if c['significant'] else 'no'} | "
                         f"{'yes' if c['added'] else ('no: ' + c['not_added'] if c.get('not_added') else 'no')} |")
    lines += response_test_lines(d.get("response_test") or [])
    lines += run_setting_lines(d.get("run_settings") or [])
    if d.get("auxiliary_columns"):
        lines += ["", "Auxiliary columns not numeric and finite as logged (flags, text labels, gaps):", ""]
        lines += [f"- `{a['channel']}`: {a['action']}: {a['note']}" for a in d["auxiliary_columns"]]
    if d.get("run_level"):
        lines += ["", run_level_line(d["run_level"])]
    if line := left_line(d.get("run_level_rounds") or []):
        lines += ["", line]
    lines += ["", "## Residual evidence per regressor (first round, cross-validated over runs)", "",
              "| regressor | held-out gain | p (runs) |", "|---|---|---|"]
    for e in d["regressor_evidence"][0] if d["regressor_evidence"] else []:
        lines.append(f"| {e['regressor']} | {e['cv_gain']:.1%} | {e['p_value']:.2g} |")
    w = d["whiteness"]
    lines += ["", f"Whiteness: median lag-1 autocorrelation {w['median_rho1']:.2f}; Ljung-Box p < 0.05 in "
              f"{w['share_runs_ljung_box_p_below_0.05']:.0%} of {w['runs']} runs (free-run residuals are "
              "coloured by the slider's low-pass even without a missing effect; evidence is judged per run).", ""]
    if line := chain_line(d.get("measurement_chain") or {}):
        lines += [line, ""]
    if rep.get("extended_parameters"):
        lines += ["## Extended model's new parameters", "",
                  "| name | value | stderr | 95 % interval | clustered by | unit |", "|---|---|---|---|---|---|"]
        for n, p in rep["extended_parameters"].items():
            if p.get("unidentifiable"):
                lines.append(f"| {n} | unidentifiable (no standard error: the data do not determine it) | | | | "
                             f"{p['unit']} |")
                continue
            ci = p.get("ci95") or [None, None]
            lines.append(f"| {n} | {sig(p['value'])} | {sig(p['stderr'])} | [{sig(ci[0])}, {sig(ci[1])}] | "
                         f"{_interval_kind(p)} | {p['unit']} |")
    if rep.get("stages"):
        lines += ["", "## Time per stage (CPU of this process; refits on Dask workers count as identifications)",
                  "", stages_table(rep["stages"])]
    if rep.get("figures"):
        lines += ["", "## Figures", ""] + [f"![{Path(f).stem}]({Path(f).name})" for f in rep["figures"]]
    lines.append("")
    return "\n".join(lines)


# ---------------------------------------------------------------------------
# figures (each returns an open Figure)
# ---------------------------------------------------------------------------

#: regressor -> (factor to the unit shown, axis label): mm and mm/s as in every other figure
REGRESSOR_AXES = {"time": (1.0, "time [s]"), "position": (1e3, "position [mm]"), "direction": (1.0, "direction [-]"),
                  "load": (1.0, "load [kg]"), "voltage": (1.0, "V0 [V]"), "speed": (1e3, "|speed| [mm/s]"),
                  "acceleration": (1.0, "acceleration [m/s²]"), "temperature": (1.0, "temperature [°C]")}


def _regressor_axis(name: str) -> tuple[float, str]:
    return REGRESSOR_AXES.get(name, (1.0, name))


def _fig_residual_vs_regressors(plt, dtr: pd.DataFrame, a: ResidualAnalysis):
    vals = res.regressor_values(dtr)
    names = [n for n in res.REGRESSORS if n in vals]
    ncol = 4
    nrow = math.ceil(len(names) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.4 * ncol, 2.8 * nrow), squeeze=False)
    plots.fixed_margins(fig, top=0.45, wspace=0.35, hspace=0.45)
    rows = np.flatnonzero(a.mask)
    rows = rows[plots.display_rows(len(rows))]  # drawing only
    for ax, n in zip(axes.flat, names):
        k, label = _regressor_axis(n)
        ax.plot(vals[n][rows] * k, a.residual[rows] * 1e3, ".", ms=2, alpha=0.4)
        ax.set_xlabel(label)
        ax.set_ylabel("residual [mm/s]")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    fig.suptitle("TRAIN free-run residual (drive coordinates) against each regressor")
    return fig


def _fig_spectrum_and_whiteness(plt, a: ResidualAnalysis):
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6))
    plots.fixed_margins(fig, left=0.8, top=0.35, wspace=0.25)
    freq, power, whiteness = a.frequency, a.power, a.whiteness
    if len(freq):
        a1.semilogy(freq[1:] ** -1 * 1e3, power[1:])
        a1.set_xscale("log")
        a1.set_xlabel("period over position [mm]")
        a1.set_ylabel("residual power [relative]")
        a1.set_title("residual spectrum over position")
        a1.grid(alpha=0.3)
    if whiteness:
        acfs = np.array([w["acf"][:11] for w in whiteness if len(w["acf"]) >= 11])
        if len(acfs):
            a2.plot(np.arange(11), acfs.T, color="0.7", lw=0.5)
            a2.plot(np.arange(11), np.median(acfs, axis=0), "k-", lw=2, label="median over runs")
            band = np.median([w["band"] for w in whiteness])
            a2.axhspan(-band, band, color="b", alpha=0.15, label="95 % white-noise band")
            a2.set_xlabel("lag [samples]")
            a2.set_ylabel("autocorrelation")
            a2.legend(fontsize=7)
            a2.set_title("whiteness per run")
            a2.grid(alpha=0.3)
    return fig


def _fig_chosen(plt, dtr: pd.DataFrame, mask: np.ndarray, chosen: Score):
    c = chosen.candidate
    vals = res.regressor_values(dtr)
    F = np.asarray(c.features(dtr), float).reshape(len(dtr), -1) @ chosen.phi
    name = c.regressor if c.regressor in vals else "position"
    k, label = _regressor_axis(name)
    x = vals[name] * k
    fig, ax = plt.subplots(figsize=(6, 4))
    plots.fixed_margins(fig, top=0.35)
    rows = np.flatnonzero(mask)
    rows = rows[plots.display_rows(len(rows))]  # drawing only
    ax.plot(x[rows], F[rows], "o", ms=3, alpha=0.5)
    ax.set_xlabel(label)
    ax.set_ylabel("extra force [N]")
    ax.set_title(f"chosen effect: {c.label}")
    ax.grid(alpha=0.3)
    return fig


def _fig_before_after(plt, dte: pd.DataFrame, v_te: np.ndarray, v_te_ext: np.ndarray | None,
                      speed_derived: bool = False):
    runs = [r for r, _ in dataio.run_slices(dte[dataio.RUN])]
    pick = runs[:: max(1, len(runs) // 4)][:4]
    fig, axes = plt.subplots(len(pick), 1, figsize=(7, 2.6 * len(pick)), squeeze=False)
    plots.fixed_margins(fig, top=0.3, hspace=0.45)
    what = "derived from position (TEST)" if speed_derived else "measured (TEST)"
    for ax, (run, sl) in zip(axes[:, 0], [(r, s) for r, s in dataio.run_slices(dte[dataio.RUN]) if r in pick]):
        g = dte.iloc[sl]
        ax.plot(g[dataio.POSITION] * 1e3, np.abs(g[dataio.SPEED]) * 1e3, "k.", ms=1.5, label=what)
        ax.plot(g[dataio.POSITION] * 1e3, np.abs(v_te[sl]) * 1e3, "b-", label="baseline")
        if v_te_ext is not None:
            ax.plot(g[dataio.POSITION] * 1e3, np.abs(v_te_ext[sl]) * 1e3, "r--", label="extended")
        ax.set_title(f"run {run}: V0 {g[dataio.VOLTAGE].iloc[0]:g} V, load {g[dataio.LOAD].iloc[0]:+g} kg, "
                     f"dir {int(g[dataio.DIRECTION].iloc[0]):+d}", fontsize=9)
        ax.set_ylabel("speed [mm/s]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("position [mm]")
    return fig
