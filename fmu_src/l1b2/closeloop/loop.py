"""Close the loop with measured data: residual -> missing effect -> extended model -> error before and after.

Procedure (TEST is never used for fitting or choosing):

1. **Baseline**: the Eq. 29 predictor identified on TRAIN by maximum likelihood
   (free-run criterion; sigma, k0, mu, mu_sd pinned, which leaves the
   predictions unchanged and makes the fit well posed, see :mod:`l1b2.ident.estimator`).
2. **Residual analysis** on TRAIN (:mod:`l1b2.closeloop.residuals`): drive-coordinate
   free-run residual; whiteness per run; spectrum over position; evidence per
   regressor by cross-validation over runs, traced by forward selection.
3. **Candidates** (:mod:`l1b2.closeloop.candidates`): every named effect over its shape
   grid, and a generic smooth term per regressor. With the baseline fixed, an
   extra force changes the free-run speed *linearly* (the speed recursion is
   affine in the force), so each candidate is scored exactly and cheaply:
   its free-run response ``S`` is computed by the baseline's linear
   recursion, the residual is regressed on ``S`` with K-fold cross-validation
   over runs, and information criteria (AIC and BIC with the AR(1)-effective
   sample size) are computed on all of TRAIN.
4. **Selection that does not fool itself**: a candidate is significant when
   its held-out gain (share of the held-out residual sum of squares it
   removes) is at least ``min_gain``, its run-level Wilcoxon p-value is below
   ``alpha`` / number of effect families tested, and its AIC improves on the
   baseline (AIC, asymptotically leave-one-out cross-validation, rather than
   BIC: with the strongly autocorrelated free-run residual the effective
   sample size is small and BIC's log n penalty would overrule a held-out
   gain seen in nearly every run; both are reported). Among significant candidates the most parsimonious one within
   ``parsimony`` of the best gain is chosen (named effects before generic
   smooth terms, then fewer parameters). Otherwise: "no significant missing
   effect" and the baseline is kept.
5. **Extended model**: baseline + chosen effect, re-identified jointly by
   maximum likelihood (warm start from the baseline); both models are
   reported on TEST.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..data.coverage import input_checks
from ..data.jsonsafe import dumps, sig
from ..data.metrics import evaluation_mask, report_metrics
from ..predictor import model as pr
from ..workflows import load_train_test
from . import candidates as eff
from . import residuals as res

DEFAULT_MIN_GAIN = 0.5
DEFAULT_ALPHA = 0.01
DEFAULT_PARSIMONY = 0.9


# ---------------------------------------------------------------------------
# exact linear response of the baseline free run to extra forces
# ---------------------------------------------------------------------------

def linear_response(params: pr.PredictorParams, df: pd.DataFrame, m_s: float, F: np.ndarray) -> np.ndarray:
    """Drive-coordinate free-run speed response to drive-coordinate forces ``F`` (n x k) [m/s per unit].

    ``S(k+1) = (1 - h_k D_k) S(k) + h_k F_k`` with ``h = dt / m_eff`` and ``D``
    the baseline's damping at the measured position, ``S = 0`` at each
    run's first sample (the free run starts from the measured speed).
    Exact for a moving slider (constant sign of the guide friction).
    """
    d = df[dataio.DIRECTION].to_numpy(float)
    s = df[dataio.POSITION].to_numpy(float)
    V0 = df[dataio.VOLTAGE].to_numpy(float)
    load = df[dataio.LOAD].to_numpy(float)
    t = df[dataio.TIME].to_numpy(float)
    D, _, _ = pr.force_parts(params, s, V0, d * load, m_s)
    D = np.broadcast_to(D, s.shape)
    m_eff = pr.effective_mass(params, load, m_s)
    F = np.asarray(F, float).reshape(len(df), -1)
    S = np.zeros_like(F)
    slices = [sl for _, sl in dataio.run_slices(df[dataio.RUN])]
    starts = np.array([sl.start for sl in slices])
    lengths = np.array([sl.stop - sl.start for sl in slices])
    dt = np.zeros(len(df))
    dt[:-1] = np.diff(t)
    h = dt / m_eff
    a = 1.0 - h * D
    for k in range(int(lengths.max()) - 1):
        act = lengths > k + 1
        cur = starts[act] + k
        S[cur + 1] = a[cur, None] * S[cur] + h[cur, None] * F[cur]
    return S


# ---------------------------------------------------------------------------
# scoring
# ---------------------------------------------------------------------------

@dataclass
class Score:
    candidate: eff.CandidateForce
    cv_gain: float
    p_value: float
    runs_improved: float
    delta_bic: float
    phi: np.ndarray
    delta_aic: float = 0.0

    def to_dict(self) -> dict:
        c = self.candidate
        return {"effect": c.effect, "label": c.label, "regressor": c.regressor, "generic": c.generic,
                "n_params": c.n_params, "cv_gain": self.cv_gain, "p_value": self.p_value,
                "runs_improved": self.runs_improved, "delta_aic": self.delta_aic, "delta_bic": self.delta_bic,
                "parameters": dict(zip(c.names, (float(x) for x in self.phi)))}


def _effective_n(r: np.ndarray, runs: np.ndarray) -> float:
    """Sample count corrected for lag-1 autocorrelation within runs."""
    n_eff = 0.0
    for run in pd.unique(runs):
        x = r[runs == run]
        if len(x) < 3:
            n_eff += len(x)
            continue
        rho = float(np.clip(res.acf(x, 1)[1], 0.0, 0.99))
        n_eff += len(x) * (1 - rho) / (1 + rho)
    return max(n_eff, 1.0)


def nuisance_forces(params: pr.PredictorParams, df: pd.DataFrame, v_pred: np.ndarray) -> np.ndarray:
    """Forces spanning Eq. 29's own function space around the fit (drive coordinates).

    Perturbations of D(s), B'(s) and the offset E(s) as Legendre series in
    the scaled position: ``-v' L_j(x)``, ``V0 L_j(x)``, ``L_j(x)``. Their
    free-run responses are the re-identification directions of the baseline:
    a candidate gets credit only for what the baseline cannot absorb by
    re-fitting itself (a score test with nuisance parameters).
    """
    from numpy.polynomial.legendre import legvander
    x = np.clip(params.scaled_position(df[dataio.POSITION].to_numpy(float)), -1.2, 1.2)
    Lv = legvander(x, params.order)
    vp = df[dataio.DIRECTION].to_numpy(float) * np.asarray(v_pred, float)
    V0 = df[dataio.VOLTAGE].to_numpy(float)
    return np.column_stack([-vp[:, None] * Lv, V0[:, None] * Lv / 300.0, Lv])


class _FoldSolver:
    """Cross-validated least squares over runs with a fixed nuisance block (Gram matrices precomputed)."""

    def __init__(self, y, N, runs, folds, lam=1e-10):
        self.y, self.runs, self.folds, self.lam = y, runs, folds, lam
        self.A = np.column_stack([np.ones(len(y)), N])
        self.parts = []
        for fold in folds:
            test = np.isin(runs, fold)
            tr = ~test
            A_tr = self.A[tr]
            G = A_tr.T @ A_tr
            self.parts.append((test, tr, G, A_tr.T @ y[tr]))
        self.sse0 = self._held_out(None)

    def _solve(self, G, g):
        reg = self.lam * (np.trace(G) / len(G)) * np.eye(len(G))
        return np.linalg.solve(G + reg, g)

    def _held_out(self, S):
        sse = {}
        for test, tr, G, g in self.parts:
            if S is None:
                beta = self._solve(G, g)
                pred = self.A[test] @ beta
            else:
                S_tr = S[tr]
                AS = self.A[tr].T @ S_tr
                Gf = np.block([[G, AS], [AS.T, S_tr.T @ S_tr]])
                gf = np.concatenate([g, S_tr.T @ self.y[tr]])
                beta = self._solve(Gf, gf)
                pred = np.column_stack([self.A[test], S[test]]) @ beta
            e = self.y[test] - pred
            for run in pd.unique(self.runs[test]):
                sse[run] = float(np.sum(e[self.runs[test] == run] ** 2))
        return sse

    def gain(self, S):
        sse1 = self._held_out(S)
        keys = list(self.sse0)
        s0 = np.array([self.sse0[k] for k in keys])
        s1 = np.array([sse1[k] for k in keys])
        gain = 1 - s1.sum() / s0.sum() if s0.sum() > 0 else 0.0
        return float(gain), (s0 - s1) / max(s0.mean(), 1e-300)


def score_candidates(candidates, r_drive, df, mask, params, m_s, *, v_pred, k=5, seed=0):
    """Cross-validated gain, run-level p-value and BIC change of every candidate.

    The regression of the TRAIN residual on a candidate's free-run response
    includes the nuisance responses (:func:`nuisance_forces`) in both the
    null and the candidate model; folds are whole runs.
    """
    runs = df[dataio.RUN].to_numpy()
    idx = np.flatnonzero(mask)
    y, runs_m = r_drive[idx], runs[idx]
    folds = res.run_folds(runs_m, k, seed)
    n_eff = _effective_n(y, runs_m)
    feats = [np.asarray(c.features(df), float).reshape(len(df), -1) for c in candidates]
    widths = [f.shape[1] for f in feats]
    N = linear_response(params, df, m_s, nuisance_forces(params, df, v_pred))[idx]
    S_all = linear_response(params, df, m_s, np.column_stack(feats))[idx]
    solver = _FoldSolver(y, N, runs_m, folds)
    A = solver.A
    coef0 = np.linalg.lstsq(A, y, rcond=None)[0]
    sse0 = float(np.sum((y - A @ coef0) ** 2))
    out = []
    col = 0
    for c, w in zip(candidates, widths):
        S = S_all[:, col:col + w]
        col += w
        if not np.all(np.isfinite(S)) or np.allclose(S, 0):
            out.append(Score(c, 0.0, 1.0, 0.0, 0.0, np.zeros(w)))
            continue
        gain, per_run = solver.gain(S)
        Xf = np.column_stack([A, S])
        coef = np.linalg.lstsq(Xf, y, rcond=None)[0]
        sse1 = float(np.sum((y - Xf @ coef) ** 2))
        dll = n_eff * math.log(max(sse1, 1e-300) / max(sse0, 1e-300))
        out.append(Score(c, gain, res._wilcoxon_greater(per_run), float(np.mean(per_run > 0)),
                         dll + w * math.log(n_eff), coef[A.shape[1]:], dll + 2 * w))
    return out


def choose(scores: list[Score], *, alpha=DEFAULT_ALPHA, min_gain=DEFAULT_MIN_GAIN, parsimony=DEFAULT_PARSIMONY):
    """The significant candidates and the chosen one (None when nothing is significant)."""
    families = {s.candidate.effect for s in scores}
    level = alpha / max(len(families), 1)
    sig = [s for s in scores if s.cv_gain >= min_gain and s.p_value < level and s.delta_aic < 0]
    if not sig:
        return sig, None, level
    best = max(s.cv_gain for s in sig)
    close = [s for s in sig if s.cv_gain >= parsimony * best]
    close.sort(key=lambda s: (s.candidate.generic, s.candidate.n_params, -s.cv_gain))
    return sig, close[0], level


def _best_per_family(scores: list[Score]) -> list[Score]:
    best = {}
    for s in scores:
        key = s.candidate.effect
        if key not in best or s.cv_gain > best[key].cv_gain:
            best[key] = s
    return sorted(best.values(), key=lambda s: -s.cv_gain)


# ---------------------------------------------------------------------------
# the whole job
# ---------------------------------------------------------------------------

def close_loop(train_path, test_path, report_dir, *, order=8, k_folds=5, alpha=DEFAULT_ALPHA,
               min_gain=DEFAULT_MIN_GAIN, parsimony=DEFAULT_PARSIMONY, seed=0, n_starts=4,
               slider_mass_kg=None, plots_on=True, progress=None, allow_unusual_units=False) -> dict:
    """Identify, diagnose, extend, re-identify and report (see the module docstring)."""
    from ..ident.estimator import PredictorIdentifier
    from ..ident.extra import ExtraForces

    say = progress or (lambda msg: None)
    t_start = time.perf_counter()
    train, test, _ = load_train_test(train_path, test_path, slider_mass_kg=slider_mass_kg,
                                     allow_unusual_units=allow_unusual_units)
    m_s = train.slider_mass_kg
    dtr, dte = train.df, test.df
    mask_tr = evaluation_mask(dtr)

    say("baseline: identifying the Eq. 29 predictor on TRAIN")
    base = PredictorIdentifier(order=order, criterion="free_run", fixed="recommended", n_starts=n_starts,
                               seed=seed)
    base.fit(dtr, slider_mass_kg=m_s, mask=mask_tr)
    v_tr = base.predict_free_run(dtr)
    v_te = base.predict_free_run(dte)
    baseline = {"train": report_metrics(dtr, base.predict_one_step(dtr), v_tr),
                "test": report_metrics(dte, base.predict_one_step(dte), v_te)}

    say("residual analysis on TRAIN")
    r_tr = res.drive_residual(dtr, v_tr)
    whiteness = res.whiteness(r_tr, dtr, mask_tr)
    freq, power, peak = res.position_spectrum(r_tr, dtr, mask_tr)
    traced, rounds = res.trace(r_tr, dtr, mask_tr, alpha=alpha, k=k_folds, seed=seed)

    say("scoring candidate effects")
    pos = dtr[dataio.POSITION].to_numpy(float)[mask_tr]
    ctx = eff.Context(
        baseline_free_run=base.predict_free_run, m_s=float(m_s),
        time_range=(float(dtr[dataio.TIME].min()), float(dtr[dataio.TIME].max())),
        position_range=(float(pos.min()), float(pos.max())),
        temperature_ref=float(dtr[dataio.TEMPERATURE].median()) if dataio.TEMPERATURE in dtr.columns else None,
        spectral_period_m=peak.get("period_m") if peak.get("power_ratio_to_median", 0) > 4 else None)
    candidates = eff.named_candidates(ctx, dtr) + eff.generic_candidates(ctx, dtr)
    scores = score_candidates(candidates, r_tr, dtr, mask_tr, base.params_, m_s, v_pred=v_tr, k=k_folds,
                              seed=seed)
    significant, chosen, level = choose(scores, alpha=alpha, min_gain=min_gain, parsimony=parsimony)

    extended = None
    ext_params = None
    v_te_ext = None
    if chosen is not None:
        say(f"extended model: re-identifying with {chosen.candidate.label}")
        c = chosen.candidate
        extra = ExtraForces(names=c.names, units=c.units, features=c.features, start=tuple(chosen.phi),
                            description=c.description)
        ext = PredictorIdentifier(order=order, criterion="free_run", fixed="recommended", n_starts=1, seed=seed,
                                  extra=extra, init=base.params_, init_extra=np.asarray(chosen.phi))
        ext.fit(dtr, slider_mass_kg=m_s, mask=mask_tr)
        v_te_ext = ext.predict_free_run(dte)
        extended = {"train": report_metrics(dtr, ext.predict_one_step(dtr), ext.predict_free_run(dtr)),
                    "test": report_metrics(dte, ext.predict_one_step(dte), v_te_ext)}
        ext_params = {n: {"value": float(ext.extra_params_[n]), "stderr": _jf(ext.extra_stderr_[n]),
                          "ci95": [_jf(x) for x in ext.extra_ci95_[n]], "unit": u}
                      for n, u in zip(c.names, c.units)}

    if chosen is not None:
        traced_to = [chosen.candidate.regressor] + [r for r in traced if r != chosen.candidate.regressor]
    else:
        traced_to = []
    report = {
        "baseline": baseline,
        "diagnosis": {
            "significant": chosen is not None,
            "traced_to": traced_to,
            "effect": chosen.candidate.effect if chosen else None,
            "effect_shape": chosen.candidate.shape if chosen else None,
            "effect_description": chosen.candidate.description if chosen else None,
            "message": (f"missing effect: {chosen.candidate.label} ({chosen.candidate.regressor})" if chosen
                        else "no significant missing effect"),
            "residual_trace": traced,
            "candidates": [s.to_dict() for s in _best_per_family(scores)],
            "n_candidates_scored": len(scores),
            "significance_level": level,
            "rules": {"min_gain": min_gain, "alpha": alpha, "parsimony": parsimony, "k_folds": k_folds},
            "regressor_evidence": [[e.to_dict() for e in rnd] for rnd in rounds],
            "whiteness": {"runs": len(whiteness),
                          "share_runs_ljung_box_p_below_0.05": float(np.mean([w["ljung_box_p"] < 0.05
                                                                               for w in whiteness]))
                          if whiteness else None,
                          "median_rho1": float(np.median([w["rho1"] for w in whiteness])) if whiteness else None},
            "position_spectrum_peak": peak,
        },
        "extended": extended,
        "extended_parameters": ext_params,
        "baseline_parameters": base.to_dict()["parameters"],
        "data": {"train": str(train_path), "test": str(test_path), "train_runs": len(train.runs),
                 "test_runs": len(test.runs), "train_samples": train.n_samples, "test_samples": test.n_samples},
        "checks": input_checks(train, test),
        "wall_time_s": None,
    }
    out = Path(report_dir)
    out.mkdir(parents=True, exist_ok=True)
    if plots_on:
        say("plots")
        report["figures"] = _plots(out, dtr, dte, r_tr, mask_tr, whiteness, freq, power, chosen, v_te, v_te_ext,
                                   base, m_s)
    report["wall_time_s"] = round(time.perf_counter() - t_start, 2)
    (out / "report.json").write_text(dumps(report))
    (out / "report.md").write_text(markdown_report(report))
    return report


def _jf(x):
    x = float(x)
    return x if math.isfinite(x) else ("inf" if x > 0 else ("-inf" if x < 0 else None))


# ---------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------

def before_after_table(report: dict) -> str:
    """Plain-text table of the error metrics before and after (TEST and TRAIN)."""
    lines = [f"{'':8s}{'':10s}{'nrmse':>18s}{'mean |rel|':>22s}{'p95 |rel|':>22s}",
             f"{'data':8s}{'kind':10s}{'before':>9s}{'after':>9s}{'before':>11s}{'after':>11s}"
             f"{'before':>11s}{'after':>11s}"]
    for part in ("test", "train"):
        for kind in ("free_run", "one_step"):
            b = report["baseline"][part][kind]
            a = report["extended"][part][kind] if report["extended"] else None

            def f(x):
                return f"{x:.2%}" if x is not None else "-"
            lines.append(f"{part:8s}{kind:10s}{f(b['nrmse']):>9s}{f(a['nrmse'] if a else None):>9s}"
                         f"{f(b['mean_abs_rel_error']):>11s}{f(a['mean_abs_rel_error'] if a else None):>11s}"
                         f"{f(b['p95_abs_rel_error']):>11s}{f(a['p95_abs_rel_error'] if a else None):>11s}")
    return "\n".join(lines)


def markdown_report(rep: dict) -> str:
    d = rep["diagnosis"]
    lines = ["# Close the loop: residual -> missing effect -> extended model", "",
             f"TRAIN: `{rep['data']['train']}` ({rep['data']['train_runs']} runs), "
             f"TEST: `{rep['data']['test']}` ({rep['data']['test_runs']} runs; never used for fitting or choosing).",
             "", "## Diagnosis", "", f"**{d['message']}**", ""]
    if d["significant"]:
        lines += [f"* traced to: {', '.join(d['traced_to'])}",
                  f"* effect: `{d['effect']}` {d['effect_shape'] or ''} — {d['effect_description']}"]
    else:
        lines += ["* the baseline is kept (no candidate met all of: held-out gain >= "
                  f"{d['rules']['min_gain']:.0%}, run-level p < {d['significance_level']:.2g}, AIC improvement)"]
    lines += ["", "## Error before and after", "", "```", before_after_table(rep), "```", "",
              "## Candidates (best of each family, by held-out gain)", "",
              "| effect | regressor | params | held-out gain | p (runs) | runs improved | dAIC | dBIC |",
              "|---|---|---|---|---|---|---|---|"]
    for c in d["candidates"]:
        lines.append(f"| {c['label']} | {c['regressor']} | {c['n_params']} | {c['cv_gain']:.1%} | "
                     f"{c['p_value']:.2g} | {c['runs_improved']:.0%} | {c['delta_aic']:.1f} | "
                     f"{c['delta_bic']:.1f} |")
    lines += ["", "## Residual evidence per regressor (first round, cross-validated over runs)", "",
              "| regressor | held-out gain | p (runs) |", "|---|---|---|"]
    for e in d["regressor_evidence"][0] if d["regressor_evidence"] else []:
        lines.append(f"| {e['regressor']} | {e['cv_gain']:.1%} | {e['p_value']:.2g} |")
    w = d["whiteness"]
    lines += ["", f"Whiteness: median lag-1 autocorrelation {w['median_rho1']:.2f}; Ljung-Box p < 0.05 in "
              f"{w['share_runs_ljung_box_p_below_0.05']:.0%} of {w['runs']} runs (free-run residuals are "
              "coloured by the slider's low-pass even without a missing effect; evidence is judged per run).", ""]
    if rep.get("extended_parameters"):
        lines += ["## Extended model's new parameters", "", "| name | value | stderr | 95 % interval | unit |",
                  "|---|---|---|---|---|"]
        for n, p in rep["extended_parameters"].items():
            lines.append(f"| {n} | {sig(p['value'])} | {sig(p['stderr'])} | [{sig(p['ci95'][0])}, "
                         f"{sig(p['ci95'][1])}] | {p['unit']} |")
    if rep.get("figures"):
        lines += ["", "## Figures", ""] + [f"![{Path(f).stem}]({Path(f).name})" for f in rep["figures"]]
    lines.append("")
    return "\n".join(lines)


def _plots(out, dtr, dte, r_tr, mask, whiteness, freq, power, chosen, v_te, v_te_ext, base, m_s) -> list[str]:
    from ..data import plots
    plt = plots._plt()
    figs = []
    vals = res.regressor_values(dtr)
    names = [n for n in res.REGRESSORS if n in vals]
    ncol = 4
    nrow = math.ceil(len(names) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.4 * ncol, 2.8 * nrow), squeeze=False)
    for ax, n in zip(axes.flat, names):
        x = vals[n][mask]
        ax.plot(x, r_tr[mask] * 1e3, ".", ms=1, alpha=0.3)
        ax.set_xlabel(n)
        ax.set_ylabel("residual [mm/s]")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    fig.suptitle("TRAIN free-run residual (drive coordinates) against each regressor")
    figs.append(str(plots._save(fig, out / "residual_vs_regressors.png")))

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6))
    if len(freq):
        a1.semilogy(freq[1:] ** -1 * 1e3, power[1:])
        a1.set_xscale("log")
        a1.set_xlabel("period over position [mm]")
        a1.set_ylabel("residual power")
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
    figs.append(str(plots._save(fig, out / "residual_spectrum_and_whiteness.png")))

    if chosen is not None:
        c = chosen.candidate
        F = np.asarray(c.features(dtr), float).reshape(len(dtr), -1) @ chosen.phi
        x = vals.get(c.regressor, vals["position"])
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.plot(x[mask], F[mask], ".", ms=1)
        ax.set_xlabel(c.regressor)
        ax.set_ylabel("extra force [N]")
        ax.set_title(f"chosen effect: {c.label}")
        ax.grid(alpha=0.3)
        figs.append(str(plots._save(fig, out / "chosen_effect.png")))

    runs = [r for r, _ in dataio.run_slices(dte[dataio.RUN])]
    pick = runs[:: max(1, len(runs) // 4)][:4]
    fig, axes = plt.subplots(len(pick), 1, figsize=(7, 2.6 * len(pick)), squeeze=False)
    for ax, (run, sl) in zip(axes[:, 0], [(r, s) for r, s in dataio.run_slices(dte[dataio.RUN]) if r in pick]):
        g = dte.iloc[sl]
        ax.plot(g[dataio.POSITION] * 1e3, np.abs(g[dataio.SPEED]) * 1e3, "k.", ms=1.5, label="measured (TEST)")
        ax.plot(g[dataio.POSITION] * 1e3, np.abs(v_te[sl]) * 1e3, "b-", label="baseline")
        if v_te_ext is not None:
            ax.plot(g[dataio.POSITION] * 1e3, np.abs(v_te_ext[sl]) * 1e3, "r--", label="extended")
        ax.set_title(f"run {run}: V0 {g[dataio.VOLTAGE].iloc[0]:g} V, load {g[dataio.LOAD].iloc[0]:+g} kg, "
                     f"dir {int(g[dataio.DIRECTION].iloc[0]):+d}", fontsize=9)
        ax.set_ylabel("speed [mm/s]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("position [mm]")
    figs.append(str(plots._save(fig, out / "before_after_test.png")))
    return figs
