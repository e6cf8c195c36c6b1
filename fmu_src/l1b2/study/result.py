"""The result of a multi-seed study: one row per seed, a summary against the issue's rules, a figure.

:class:`StudyResult` holds the rows (:meth:`~StudyResult.to_pandas`), the
settings and the engine's figures; :meth:`~StudyResult.summary` condenses
them:

* coverage: per injection and interval kind, the share of seeds whose 95 %
  interval holds the injected value with its exact (Clopper-Pearson) 95 %
  band, whether it lies in the issue's 90-99 %, the seeds with an estimate of
  the wrong sign, the estimate's mean error (bias) and its spread over seeds
  against the median standard error (an interval too narrow for the
  seed-to-seed scatter has ``spread / median se`` above 1);
* control: the largest ratio of the loop's held-out nrmse to the baseline's,
  the seeds above the 2 % rule, the held-out p95 before and after, the
  medians of the two reference p95 (:mod:`l1b2.study.control`) and how often
  each baseline family was chosen.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats

from .control import CONTROL_TOLERANCE
from .recovery import INTERVALS

#: the issue's band for the share of seeds covered by a 95 % interval
COVERAGE_BAND = (0.90, 0.99)


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial confidence interval of a share ``k/n``."""
    a = 1 - level
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def coverage_summary(df: pd.DataFrame) -> list[dict]:
    """One record per (injection, interval kind) of a coverage table (see the module)."""
    out = []
    for inj, g in df.groupby("injection", sort=True):
        err = g["estimate"] - g["injected"]
        for kind in (k for k in INTERVALS if f"covered_{k}" in g):   # rows of older studies lack "condition"
            has = g[f"covered_{kind}"].notna()   # an interval that the fit does not offer counts for nothing
            if not has.any():
                continue
            k, n = int(g.loc[has, f"covered_{kind}"].astype(bool).sum()), int(has.sum())
            share = k / n
            rec = {"injection": inj, "parameter": str(g["parameter"].iloc[0]), "interval": kind, "seeds": n,
                   "covered": k, "share": share, "share_ci95": clopper_pearson(k, n),
                   "in_band": bool(COVERAGE_BAND[0] <= share <= COVERAGE_BAND[1]),
                   "wrong_sign_seeds": [int(s) for s in g.loc[g["wrong_sign"], "seed"]],
                   "mean_error": float(err.mean()), "error_sd": float(err.std(ddof=1)) if len(g) > 1 else float("nan"),
                   "median_se": float(g.loc[has, f"se_{kind}"].median())}
            rec["error_sd_over_median_se"] = rec["error_sd"] / rec["median_se"]
            if "clean_estimate" in g:
                rec["mean_clean_estimate"] = float(g["clean_estimate"].mean())
            out.append(rec)
    return out


def control_summary(df: pd.DataFrame) -> dict:
    """The control rule over the seeds and the held-out p95 (see the module)."""
    worst = df.loc[df["ratio"].idxmax()]
    return {"seeds": int(len(df)), "max_ratio": float(worst["ratio"]), "worst_seed": int(worst["seed"]),
            "tolerance": CONTROL_TOLERANCE, "all_within": bool(df["within_tolerance"].all()),
            "seeds_above": [int(s) for s in df.loc[~df["within_tolerance"], "seed"]],
            "seeds_with_effects": [int(s) for s in df.loc[df["added"] != "", "seed"]],
            "nrmse_before_median": float(df["nrmse_before"].median()),
            "nrmse_after_median": float(df["nrmse_after"].median()),
            "p95_before_median": float(df["p95_before"].median()), "p95_after_median": float(df["p95_after"].median()),
            "p95_after_max": float(df["p95_after"].max()),
            **{f"{k}_median": float(df[k].median()) for k in ("p95_nominal", "p95_run_gain_after") if k in df},
            **({"baselines": {str(k): int(n) for k, n in df["baseline"].value_counts().items()}}
               if "baseline" in df else {})}


@dataclass
class StudyResult:
    """Rows of a study (one dict per seed and case), its settings and the engine's figures."""

    study: str
    rows: list
    settings: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def to_pandas(self) -> pd.DataFrame:
        """One row per seed (and injection), sorted."""
        df = pd.DataFrame(self.rows)
        keys = [k for k in ("injection", "seed") if k in df.columns]
        return df.sort_values(keys).reset_index(drop=True) if len(df) else df

    def summary(self) -> dict:
        """The study's figures against the issue's rules (see the module)."""
        df = self.to_pandas()
        if self.study == "coverage":
            return {"coverage": coverage_summary(df), "band": COVERAGE_BAND}
        return {"control": control_summary(df)}

    def to_dict(self) -> dict:
        return {"study": self.study, "settings": self.settings, "info": self.info, "summary": self.summary(),
                "rows": self.to_pandas().to_dict(orient="records")}

    @classmethod
    def from_dict(cls, d: dict) -> StudyResult:
        return cls(d["study"], list(d["rows"]), dict(d.get("settings", {})), dict(d.get("info", {})))

    def report_lines(self) -> list[str]:
        """The summary as printed lines."""
        s = self.summary()
        if self.study == "coverage":
            lines = []
            for r in s["coverage"]:
                lo, hi = r["share_ci95"]
                lines.append(f"{r['injection']} ({r['parameter']}), {r['interval']} interval: covered "
                             f"{r['covered']}/{r['seeds']} = {100 * r['share']:.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]"
                             f"{'' if r['in_band'] else ' (outside 90-99 %)'}; wrong sign: "
                             f"{r['wrong_sign_seeds'] or 'none'}; mean error {r['mean_error']:+.3g}, sd "
                             f"{r['error_sd']:.3g}, median se {r['median_se']:.3g}")
            return lines
        c = s["control"]
        return [f"control, {c['seeds']} seeds: max TEST nrmse ratio {c['max_ratio']:.4f} (seed {c['worst_seed']}); "
                f"above +{100 * c['tolerance']:.0f} %: {c['seeds_above'] or 'none'}; effects added on seeds "
                f"{c['seeds_with_effects'] or 'none'}",
                f"held-out free-run nrmse median {100 * c['nrmse_before_median']:.2f} -> "
                f"{100 * c['nrmse_after_median']:.2f} %; p95 median {100 * c['p95_before_median']:.2f} -> "
                f"{100 * c['p95_after_median']:.2f} % (max after {100 * c['p95_after_max']:.2f} %)"
                + (f"; the scatter-free rig's p95 median {100 * c['p95_nominal_median']:.2f} %, the final model's "
                   f"with the best gain per run {100 * c['p95_run_gain_after_median']:.2f} %"
                   if "p95_nominal_median" in c else "")
                + (f"; baselines {c['baselines']}" if "baselines" in c else "")]

    def figure(self):
        """A matplotlib figure: coverage -- estimate against injected value with the intervals, per injection;
        control -- the loop's TEST nrmse ratio and the p95 per seed."""
        import matplotlib
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        df = self.to_pandas()
        if self.study == "coverage":
            injections = sorted(df["injection"].unique())
            fig, axes = plt.subplots(1, len(injections), figsize=(5.5 * len(injections), 4.5), squeeze=False)
            for ax, inj in zip(axes[0], injections):
                g = df[df["injection"] == inj].sort_values("injected")
                x = g["injected"].to_numpy()
                for kind, colour, lw in (("robust", "tab:orange", 5.0), ("condition", "tab:green", 3.0),
                                         ("ar1", "tab:blue", 1.5)):
                    if f"lo_{kind}" not in g:
                        continue
                    ax.vlines(x, g[f"lo_{kind}"], g[f"hi_{kind}"], colors=colour, lw=lw, alpha=0.7,
                              label=f"95 % interval ({kind})")
                ax.plot(x, g["estimate"], "k.", label="estimate")
                lim = [min(x.min(), g["estimate"].min()), max(x.max(), g["estimate"].max())]
                ax.plot(lim, lim, "k:", lw=1, label="estimate = injected")
                share = {k: g[f"covered_{k}"].dropna().astype(bool).mean() for k in INTERVALS
                         if f"covered_{k}" in g and g[f"covered_{k}"].notna().any()}
                ax.set_title(f"{inj}, {len(g)} seeds, covered: "
                             + ", ".join(f"{k} {100 * v:.0f} %" for k, v in share.items()), fontsize=9)
                ax.set_xlabel(f"injected {g['parameter'].iloc[0]}")
                ax.set_ylabel("identified")
                ax.legend(fontsize=7)
        else:
            fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
            a1.bar(df["seed"].astype(str), 100 * (df["ratio"] - 1), color=np.where(df["within_tolerance"],
                                                                                     "tab:green", "tab:red"))
            a1.axhline(100 * CONTROL_TOLERANCE, color="k", ls="--", lw=1, label="+2 % rule")
            a1.set_xlabel("seed")
            a1.set_ylabel("TEST free-run nrmse: loop vs baseline [%]")
            a1.legend(fontsize=8)
            w = 0.4
            pos = np.arange(len(df))
            a2.bar(pos - w / 2, 100 * df["p95_before"], w, label="baseline")
            a2.bar(pos + w / 2, 100 * df["p95_after"], w, label="after the loop")
            if "p95_nominal" in df:
                a2.plot(pos, 100 * df["p95_nominal"], "kv", label="scatter-free rig (no model does better)")
            a2.axhline(3.0, color="k", ls="--", lw=1, label="3 % target")
            a2.set_xticks(pos, df["seed"].astype(str))
            a2.set_xlabel("seed")
            a2.set_ylabel("TEST p95 |relative error| [%]")
            a2.legend(fontsize=8)
        fig.tight_layout()
        return fig
