"""The diagnosis's evidence tables: the order of what was traced, and every channel and signal considered."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from ..data import measurements as dataio
from ..data import onset
from ..predictor.effects import channels as fx_channels
from ..units import tidy_float
from . import runlevel
from .selection import Score, best_per_family, position_basis

__all__ = ["with_onset", "onset_explanation", "ONSET_MIN_RUNS", "order_traced", "channels_considered",
           "position_share", "with_position_share", "with_auxiliary", "not_added_reason"]


def order_traced(effects, speed_filter: bool, residual_trace, evidence=(), speed_evidence: bool = False,
                 measured=()) -> list[str]:
    """``diagnosis.traced_to``: the regressors with significant evidence, strongest first.

    ``speed`` first if the speed channel's filter was kept (the measurement
    chain is settled before any physical effect), then ``measured``, the regressors of the measurement chain's
    other kept stage (``position`` for the speed sensor's gain along the stroke); the added effects in the
    order they were chosen (each round takes the candidate with the largest
    cross-validated gain against the current model, so earlier is stronger);
    then the evidence not acted on: ``speed`` if ``speed_evidence`` (the
    channel's own cross-validated test found the filter, but re-identifying
    behind it did not lower the cross-validated free-run error, so it was not applied),
    and ``evidence``, the candidates that improve the final model
    in cross-validation but by less than the materiality threshold (largest
    gain first). *Structural* terms (``CandidateForce.structural``: they
    relax an approximation of Eq. 29 itself) come after all of these: they
    are the paper model's own error, present on clean data too, and the first
    regressors should point at what the data hold beyond it. Then the rest of
    the baseline residual's regressor trace. Empty when nothing was added.
    """
    if not effects and not speed_filter and not measured:
        return []
    traced: list[str] = ["speed"] if speed_filter else []
    traced.extend(r for r in measured if r not in traced)

    def take(cands):
        for c in cands:
            traced.extend(r for r in c.regressors if r not in traced)
    take(e for e in effects if not e.structural)
    if speed_evidence and "speed" not in traced:
        traced.append("speed")
    take(e for e in evidence if not e.structural)
    take(e for e in effects if e.structural)
    take(e for e in evidence if e.structural)
    return traced + [r for r in residual_trace if r not in traced]


#: the fewest TRAIN runs cut at rest before their onset for their delays to be explained by a run-level signal
ONSET_MIN_RUNS = 3


def onset_explanation(df: pd.DataFrame, record: dict | None, channels, alpha: float) -> dict | None:
    """What explains the rests cut before TRAIN's onsets beyond the plan's inputs, or None.

    Each TRAIN run's delay (``record``'s ``per_run``; 0 for a run not cut) is fitted by least squares on a constant
    and the inputs' run signals (V0, the drive-coordinate load, its size, the direction:
    :data:`l1b2.predictor.effects.channels.INPUT_SIGNALS`; a heavier load delays any late start), and every other
    run-level signal of :func:`l1b2.closeloop.runlevel.run_signals` (a channel's run mean, not a label's codes) is
    tested by Spearman's rank correlation with the residual, Bonferroni over those signals. The strongest one below
    ``alpha`` explains the rests: ``{"signal", "regressor", "rho", "p_value"`` (multiplied by ``signals_tested``),
    ``"signals_tested", "runs"}``. None with fewer than :data:`ONSET_MIN_RUNS` runs cut, or none below ``alpha``."""
    if not (record and record.get("cut") and record.get("runs", 0) >= ONSET_MIN_RUNS):
        return None
    delays = {r: d for r, _, d, _ in record["per_run"]}
    y = np.array([delays.get(r, 0.0) for r in pd.unique(df[dataio.RUN])], float)
    inputs = set(fx_channels.INPUT_SIGNALS)
    sigs = runlevel.run_signals(df, channels)
    X = np.column_stack([np.ones(len(y))] + [s["values"] for s in sigs if (s["channel"], s["transform"]) in inputs])
    resid = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    others = [s for s in sigs if (s["channel"], s["transform"]) not in inputs and s["transform"] == "none"]
    if not others or not np.std(resid) > 0:
        return None
    # ranks of the run values to 12 digits (a run mean carries round-off in its last bits, which would part ties);
    # a tie of p (a monotone transform the loop derives has its column's ranks): the signal listed first
    tests = [(stats.spearmanr([tidy_float(v) for v in s["values"]], resid), s["channel"]) for s in others]
    k = len(tests)
    p, _, name, rho = min(((float(t.pvalue) * k, i, c, float(t.statistic)) for i, (t, c) in enumerate(tests)
                           if np.isfinite(t.pvalue)), default=(np.inf, 0, None, np.nan))
    if not p < alpha:
        return None
    return {"signal": name, "regressor": fx_channels.regressor_of(name), "rho": rho, "p_value": min(p, 1.0),
            "signals_tested": k, "runs": int(record["runs"])}


def with_onset(diagnosis: dict, record: dict | None, df: pd.DataFrame | None = None, channels=(),
               alpha: float = 0.05) -> dict:
    """``diagnosis`` with the rest cut before TRAIN's onsets (``record``: ``meta["rest_before_onset"]`` of
    :func:`l1b2.data.onset.from_onset`) as the stage it is: removed on reading, before any round, its regressor
    :data:`l1b2.data.onset.REGRESSOR` first in ``traced_to`` and its reading in the message, as a kept stage of the
    measurement chain is reported. With TRAIN's frame ``df`` (and its candidate ``channels``), the signal that
    explains the rests beyond the plan's inputs (:func:`onset_explanation` at ``alpha``) is traced second and named
    in the message (the record's ``explained_by``). Unchanged when no run was cut."""
    if not (record and record.get("runs") and record.get("cut")):
        return diagnosis
    explained = None if df is None else onset_explanation(df, record, channels, alpha)
    first = [onset.REGRESSOR] + ([explained["regressor"]] if explained else [])
    traced = first + [r for r in diagnosis.get("traced_to") or [] if r not in first]
    note = (f"; {record['runs']} of {record['of_runs']} TRAIN runs rest at their start before the drive (onset "
            f"after {record['median_delay_s'] * 1e3:.3g} ms median, {record['max_delay_s'] * 1e3:.3g} ms at most: a "
            "fact of the recording, cut on reading; every run's free run starts at its onset")
    if explained:
        note += (f"; the rests follow {explained['signal']} beyond the plan's inputs (Spearman rho "
                 f"{explained['rho']:+.2f}, p {explained['p_value']:.2g} over {explained['signals_tested']} signals)")
    return {**diagnosis, "traced_to": traced, "message": diagnosis.get("message", "") + note + ")",
            "rest_before_onset": {**record, "explained_by": explained} if explained else record}


def position_share(values, basis) -> float:
    """The share of a channel's variance over the samples that a series ``basis`` (n, k; its columns span the
    constants) holds: ``1 - |c - B b|^2 / |c - mean(c)|^2``, ``b`` the least-squares coefficients of the values
    ``c`` (n,) on ``B``. In [0, 1]; NaN for a constant channel (no variance to share)."""
    c = np.asarray(values, float).ravel()
    B = np.asarray(basis, float).reshape(len(c), -1)
    sst = float(np.sum((c - np.mean(c)) ** 2))
    if not sst > 0:
        return float("nan")
    coef = np.linalg.lstsq(B, c, rcond=None)[0]
    return float(min(max(1.0 - float(np.sum((c - B @ coef) ** 2)) / sst, 0.0), 1.0))


def with_position_share(channels, df, mask, params) -> tuple:
    """The channel records ``channels`` (:func:`l1b2.closeloop.candidates.channels_of`) with ``position_share``:
    the share of each channel's variance over the masked samples of ``df`` that is a function of the position in
    the baseline's own position series (:func:`position_share` on
    :func:`l1b2.closeloop.selection.position_basis` of ``params``, the series whose forces are the screen's
    re-identification directions); None for a channel constant on the masked samples or a measured response (no
    hypothesis)."""
    m = np.asarray(mask, bool)
    basis = position_basis(params, df[dataio.POSITION].to_numpy(float)[m])
    out = []
    for ch in channels:
        ok = ch.get("sd", 0) > 0 and ch.get("kind") not in fx_channels.NOT_CAUSE_KINDS and ch["name"] in df.columns
        share = position_share(df[ch["name"]].to_numpy(float)[m], basis) if ok else float("nan")
        out.append({**ch, "position_share": share if np.isfinite(share) else None})
    return tuple(out)


def channels_considered(channels, scores: list[Score], level: float, min_gain: float, added,
                        run_level: runlevel.RunLevelAnalysis | None = None, trials=(), picked=()) -> list[dict]:
    """``diagnosis.channels_considered``: every candidate channel and run-level signal with its first-round evidence.

    Per channel (:func:`l1b2.closeloop.candidates.channels_of`): its kind,
    the regressor it is traced to, whether it varies within runs, the best
    form of its family ``channel_<name>`` by linearised held-out gain with
    that gain and its run-level p-value, ``significant`` (it passes the
    Bonferroni screen: gain >= ``min_gain``, p < ``level``, AIC improved)
    and ``added`` (the loop added it or its run-level form); ``forms``: the best hypothesis of each generic
    physical form of the family (friction, force factor, force, inertia) with its gain and p-value, so that a
    form that is not the family's best is still reported. A constant channel has no evidence (``note``).
    ``run_level``: the evidence of its run mean as an explanation of the runs' own deviations from the model
    (:class:`l1b2.closeloop.runlevel.SignalEvidence` as dicts; empty when not tested). The model's inputs
    that are run-level signals (V0, the drive-coordinate load and its size, the direction) follow as rows of
    kind ``"input"`` with their run-level evidence only (their within-run forms are the named and generic
    families of the candidate table). ``position_share``: the channel record's (:func:`with_position_share`; None
    when it has none): how much of the channel is a function of the position in the baseline's own series. What is,
    the baseline's re-identification absorbs, so a within-run form is credited only for the rest, and a channel
    near 1 cannot be told from the position along the stroke. ``not_added``: for a significant row that was not
    added, why (:func:`not_added_reason` over ``trials``, the rounds' refit trials as dicts, and ``picked``, the
    label each round added), else None. ``peak``: :func:`peak_profile` of the family (None: no peak listed).
    """
    from ..predictor.effects.channels import INPUT_SIGNALS, regressor_of
    best = {s.candidate.family: s for s in best_per_family(scores)}
    forms: dict = {}
    for s in scores:
        form = s.candidate.spec.get("form") if s.candidate.spec.get("kind") == "channel" else None
        key = (s.candidate.family, form)
        if form and (key not in forms or s.cv_gain > forms[key].cv_gain):
            forms[key] = s
    ev: dict = {}
    for e in (run_level.evidence if run_level is not None else []):
        ev.setdefault(e.channel, []).append(e)
    out = []
    for ch in channels:
        fam = f"channel_{ch['name']}"
        s = best.get(fam)
        rec = {"channel": ch["name"], "kind": ch["kind"], "regressor": regressor_of(ch["name"]),
               "varies_within_runs": bool(ch["within_run"]), "best": None, "cv_gain": None, "p_value": None,
               "significant": False, "added": fam in added, "note": "", "position_share": ch.get("position_share"),
               "per_sample_only": fx_channels.sample_only_reason(ch),
               "forms": {f: {"best": b.candidate.label, "cv_gain": float(b.cv_gain), "p_value": float(b.p_value)}
                         for (g, f), b in forms.items() if g == fam}}
        if ch["kind"] == "response":
            rec["note"] = "a measured response of the motor, not a cause: not a candidate"
        elif ch["kind"] == "relabel":
            rec["follows"] = list(ch["follows"])
            rec["note"] = (f"run by run a function of the plan's {' and '.join(ch['follows'])} on TRAIN, constant "
                           "within runs up to noise: read as those inputs, not a candidate")
        elif not ch["sd"] > 0:
            rec["note"] = "constant on TRAIN: no evidence possible"
        elif ch["kind"] == "label":
            rec["note"] = "a text label's unordered codes: categorical run-level evidence only"
        elif s is None:
            rec["note"] = "not scored (not in the candidate library)"
        else:
            rec.update(best=s.candidate.label, cv_gain=float(s.cv_gain), p_value=float(s.p_value),
                       significant=bool(s.cv_gain >= min_gain and s.p_value < level and s.delta_aic < 0))
        rec["peak"] = peak_profile(scores, fam)
        rec["run_level"] = [e.to_dict() for e in ev.get(ch["name"], [])]
        rec["added"] = rec["added"] or any(f"run_level_{e.label}" in added for e in ev.get(ch["name"], []))
        out.append(rec)
    for col in dict.fromkeys(c for c, _ in INPUT_SIGNALS):
        rows = ev.get(col, [])
        out.append({"channel": col, "kind": "input", "regressor": regressor_of(col), "varies_within_runs": False,
                    "best": None, "cv_gain": None, "p_value": None, "position_share": None, "peak": None,
                    "significant": any(e.significant for e in rows),
                    "added": any(f"run_level_{e.label}" in added for e in rows),
                    "note": "an input of the model: run-level evidence only" if rows
                    else "constant on TRAIN or not tested: no run-level evidence",
                    "run_level": [e.to_dict() for e in rows]})
    for rec in out:
        fams = {f"channel_{rec['channel']}"} | {f"run_level_{e['signal']}" for e in rec["run_level"]}
        rec["not_added"] = (not_added_reason(fams, trials, picked) if rec["significant"] and not rec["added"]
                            else None)
    return out


#: the 95 % point of the chi-square law with two degrees of freedom (the peak's centre and width jointly)
CHI2_2_95 = 5.991


def peak_profile(scores: list[Score], family: str) -> dict | None:
    """The peak of a channel's family on its grid, with the profile likelihood's 95 % region (None: no peak scored).

    The best-gain peak hypothesis of ``family`` (:data:`l1b2.predictor.effects.channels.PEAK`) names the centre and
    half width the screen chose (``z0_sd``, ``w_sd`` in standard deviations of the channel; ``centre``,
    ``half_width`` in its units), its form, gain and p-value (already multiplied by the grid's size,
    ``grid_points``). ``profile_95``: the ranges of centre and half width over the grid points of that form whose
    in-sample log-likelihood, counting each TRAIN run once (``n_runs log SSE``, :attr:`Score.dll_runs`: a run-level
    shape is informed by the runs, not by their correlated samples), is within :data:`CHI2_2_95` / 2 of the best
    point's: the values the data do not tell from the chosen one, given the grid, each widened to its grid cell (a
    centre by half its width's centre spacing, within TRAIN's range; a half width by a factor sqrt(2), half the
    grid's factor 2), since the best value between grid points is as likely as the point (an interval on the grid,
    not a fitted value's standard error)."""
    peaks = [s for s in scores if s.candidate.family == family and s.candidate.spec.get("shape") == "peak"]
    if not peaks:
        return None
    best = max(peaks, key=lambda s: s.cv_gain)
    spec = best.candidate.spec
    form = [s for s in peaks if s.candidate.spec.get("form") == spec.get("form")]
    top = min(s.dll_runs for s in form)
    near = [s.candidate.spec for s in form if s.dll_runs - top <= CHI2_2_95]
    mean, sd = float(spec["mean"]), float(spec["sd"])
    z_lo, z_hi = (float(spec["lo"]) - mean) / sd, (float(spec["hi"]) - mean) / sd
    half = {w: 0.5 * (z_hi - z_lo) / max(np.ceil((z_hi - z_lo) / w - 1e-9), 1.0) for w in {n["w"] for n in near}}
    c_lo = max(z_lo, min(n["z0"] - half[n["w"]] for n in near))
    c_hi = min(z_hi, max(n["z0"] + half[n["w"]] for n in near))
    return {"best": best.candidate.label, "form": spec.get("form"), "z0_sd": float(spec["z0"]),
            "w_sd": float(spec["w"]), "centre": mean + float(spec["z0"]) * sd, "half_width": float(spec["w"]) * sd,
            "grid_points": int(spec.get("grid_points", 1)), "cv_gain": float(best.cv_gain),
            "p_value": float(best.p_value),
            "profile_95": {"centre": [mean + c_lo * sd, mean + c_hi * sd],
                           "half_width": [min(n["w"] for n in near) * sd / np.sqrt(2.0),
                                          max(n["w"] for n in near) * sd * np.sqrt(2.0)],
                           "grid_points": len(near)}}


def not_added_reason(families, trials, picked=()) -> str:
    """Why significant evidence of ``families`` (a channel's family and its run-level forms) added nothing.

    ``trials``: the loop's refit trials per round (:meth:`l1b2.closeloop.acceptance.RefitCV.to_dict`, with
    ``accepted``: whether it passed the acceptance rules); ``picked``: the label each round added, in order. When a
    family was refit, its last trial's figures and either that the rules refused it or, when it passed them, what
    its round added instead (another passing candidate, chosen by the round's rule); otherwise it was never
    shortlisted: each round refits its strongest candidates first, and the first round's are named.
    """
    hits = [(r, t) for r, rnd in enumerate(trials, 1) for t in rnd if t["effect"] in families]
    if hits:
        r, t = hits[-1]
        figures = (f"refit in round {r}: CV gain {t['cv_gain']:.1%}, {t['folds_improved']}/{t['folds']} folds "
                   f"improved, CV nrmse {t['cv_free_run_nrmse_current']:.2%} -> {t['cv_free_run_nrmse_refit']:.2%}")
        if not t.get("accepted"):
            return figures + ": refused by the acceptance rules"
        pick = picked[r - 1] if r - 1 < len(picked) else None
        return figures + (f": passed the acceptance rules, but round {r} added {pick} instead" if pick
                          else f": passed the acceptance rules, but a later check of round {r} added nothing")
    if not trials or not trials[0]:
        return "not refit: the loop refit no candidate"
    first = ", ".join(dict.fromkeys(t["label"] for t in trials[0]))
    return (f"not refit: stronger candidates were refit first (round 1: {first}); the loop ended after "
            f"round {len(trials)}")


def with_response_test(rows: list[dict], tests) -> list[dict]:
    """``channels_considered``'s rows with the consequence test of their column
    (:func:`l1b2.closeloop.responses.response_tests`, with ``applied``/``decided_by``): the record as
    ``response_test`` (None: not tested), and for a column the test made a response, the test's figures in the note."""
    by = {r["channel"]: r for r in tests}
    out = []
    for row in rows:
        t = by.get(row["channel"])
        row = {**row, "response_test": t}
        if t is not None and t["response"] and t["applied"] and t["decided_by"] == "test":
            row["note"] = (f"classed a response of the motion: a smooth function of the speed explains "
                           f"{t['share']:.0%} of its within-run variation (more than half in {t['runs_above']} of "
                           f"{t['n_runs']} runs, sign test p {t['p_value']:.2g}): not a candidate; "
                           "set response_columns to override")
        out.append(row)
    return out


def with_auxiliary(rows: list[dict], auxiliary) -> list[dict]:
    """``channels_considered``'s rows with what :func:`l1b2.closeloop.auxiliary.with_usable_channels` did to the
    auxiliary columns: the note of a flag, a label or a filled column joined to its row (``prepared``: the action),
    and one row of kind ``"unusable"`` per column left out, with the reason, so that every column of the file is
    listed."""
    by = {r["channel"]: r for r in auxiliary}
    out = []
    for row in rows:
        aux = by.get(row["channel"])
        if aux is not None and aux["action"] != "unusable":
            row = {**row, "prepared": aux["action"],
                   "note": "; ".join(x for x in (aux["note"], row.get("note", "")) if x)}
        out.append(row)
    for aux in auxiliary:
        if aux["action"] == "unusable":
            out.append({"channel": aux["channel"], "kind": "unusable", "regressor": None, "varies_within_runs": None,
                        "best": None, "cv_gain": None, "p_value": None, "significant": False, "added": False,
                        "prepared": "unusable", "note": aux["note"], "forms": {}, "run_level": [],
                        "position_share": None, "peak": None})
    return out
