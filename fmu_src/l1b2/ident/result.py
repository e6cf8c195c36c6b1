"""The result of an identification, in the style of lmfit's ``ModelResult``.

:class:`IdentificationResult` holds everything a fit of
:class:`l1b2.ident.estimator.PredictorIdentifier` determined: the parameters
(theta of Eq. 35, then the extra-force parameters phi) with their standard
errors, 95 % intervals and units (:class:`Parameter`), the covariance and
correlation matrices, the log-likelihood with AIC/BIC, the identifiability
findings, the noise variances, the convergence record and the settings.

* :meth:`IdentificationResult.fit_report` -- readable text report;
* :meth:`IdentificationResult.to_dict` / :meth:`IdentificationResult.from_dict`
  -- strict JSON form (the package's one rule, :mod:`l1b2.jsonio`: NaN -> ``None``,
  +-inf -> ``"inf"`` / ``"-inf"``; never a NaN or Infinity token);
* :meth:`IdentificationResult.predict` and :meth:`IdentificationResult.plot_runs`
  -- predicted speed [m/s] and a figure of measured vs predicted speed per run;
* :meth:`IdentificationResult.save` -- ``identification.json`` and
  ``fit_report.txt`` in a folder (the only file output of this package layer).

Units: speeds m/s, positions m, voltages V, masses kg, forces N; parameter
units as :meth:`l1b2.predictor.model.PredictorParams.units` (extra forces:
:attr:`l1b2.ident.extra.ExtraForces.units`). Standard errors are
AR(1)-corrected (plain Fisher values in ``stderr_fisher``), see
:mod:`l1b2.ident.uncertainty`; ``stderr`` is ``inf`` for a parameter the data
cannot determine and NaN for a pinned one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from scipy import stats

from ..data.measurements import Measurements
from ..errors import IdentificationError
from ..jsonio import dumps, from_json_float, json_float, strict_json
from ..predictor.frequency import FrequencyResponse
from ..predictor.model import PredictorParams
from .frequency import frequency_report_lines
from .problem import RECOMMENDED_FIXED, SampleData
from .slipproblem import make_problem

#: how the report names each predictor family (``PredictorParams.drive_law``)
_FAMILY_TEXT = {"eq29": "Eq. 29", "pure_slip": "pure slip, slip ratio of the state"}

__all__ = ["Parameter", "IdentificationResult"]


def _diagonal(se):
    """Covariance and correlation matrices known only on the diagonal (restored from JSON)."""
    p = se.size
    cov = np.full((p, p), np.nan)
    np.fill_diagonal(cov, se**2)
    corr = np.full((p, p), np.nan)
    np.fill_diagonal(corr, np.where(np.isfinite(se), 1.0, np.nan))
    return cov, corr


# ---------------------------------------------------------------------------
# the result
# ---------------------------------------------------------------------------


#: sections of identification.json that define the model: written exactly (repr), everything else tidied
MODEL_SECTIONS = ("predictor_params", "parameters", "paper_monomials", "predictor", "extra")


@dataclass(frozen=True)
class Parameter:
    """One identified parameter.

    Attributes
    ----------
    name : str
    value : float
    stderr : float
        AR(1)-corrected standard error (inf: not identifiable; NaN: fixed).
    ci95 : tuple of float
        95 % interval (t distribution; NaN for fixed parameters).
    unit : str
    vary : bool
        False when pinned by ``fixed``.
    identifiable : bool
    stderr_fisher : float
        Plain (white-noise) Fisher standard error.
    stderr_robust : float
        Cluster-robust (sandwich, by run) standard error: valid when the
        model misses an effect (see :mod:`l1b2.ident.uncertainty`).
    ci95_robust : tuple of float
        95 % interval from ``stderr_robust`` (t with runs - 1 degrees of freedom).
    """

    name: str
    value: float
    stderr: float
    ci95: tuple
    unit: str
    vary: bool = True
    identifiable: bool = True
    stderr_fisher: float = float("nan")
    stderr_robust: float = float("nan")
    ci95_robust: tuple = (float("nan"), float("nan"))


@dataclass(eq=False)
class IdentificationResult:
    """Outcome of one maximum-likelihood identification (theta then phi, "joint" order).

    Arrays are in joint order (theta in Eq. 35 order, then the extra-force
    parameters): ``values``, ``varied``, ``identifiable``, ``stderr``,
    ``stderr_fisher`` (p,), ``ci95`` (p, 2), ``cov``, ``cov_fisher``,
    ``corr`` (p, p); restored from JSON the matrices are known only on the
    diagonal. ``settings`` are the estimator's (``"fixed"``: the pins as
    applied, name -> value). ``slider_mass_kg`` [kg], ``T_s`` median sample
    period [s], ``runs`` run ids, ``noise_var`` per run [(m/s)^2],
    ``ar1_rho`` per run, ``n_obs`` residuals in the likelihood, ``n_eff``
    their AR(1)-effective number, ``k_params`` varied identifiable
    parameters, ``dof`` / ``t_quantile`` of the intervals, ``loglik``,
    ``aic``, ``bic``, ``residual_rms`` [m/s], ``singular_values`` of the
    whitened scaled Jacobian, ``unidentifiable`` / ``weak_directions`` /
    ``alternative_optima`` / ``extra_confounding`` (see
    :mod:`l1b2.ident.uncertainty`), ``convergence`` (search record),
    ``fit_time_s`` [s]. ``extra`` is the :class:`~l1b2.ident.extra.ExtraForces`
    whose features predictions need (not serialised).
    """

    settings: dict
    params: PredictorParams
    values: np.ndarray
    extra_names: list
    extra_units: list
    extra_description: str
    varied: np.ndarray
    identifiable: np.ndarray
    stderr: np.ndarray
    stderr_fisher: np.ndarray
    ci95: np.ndarray
    cov: np.ndarray
    cov_fisher: np.ndarray
    corr: np.ndarray
    slider_mass_kg: float
    T_s: float
    runs: list
    noise_var: np.ndarray
    ar1_rho: np.ndarray
    n_obs: int
    n_eff: float
    k_params: int
    dof: float
    t_quantile: float
    loglik: float
    aic: float
    bic: float
    residual_rms: float
    singular_values: np.ndarray
    unidentifiable: list
    weak_directions: list
    alternative_optima: list
    extra_confounding: dict
    convergence: dict
    fit_time_s: float
    extra: Any = None
    stderr_robust: np.ndarray | None = None
    ci95_robust: np.ndarray | None = None
    cov_robust: np.ndarray | None = None
    #: each run's influence on the joint estimate, ``(runs, p)`` in the order of ``runs``
    #: (:func:`l1b2.ident.uncertainty.run_influence`): regrouping its rows gives the cluster-robust covariance
    #: by coarser clusters (:func:`l1b2.ident.uncertainty.grouped_sandwich`); None when not computed
    run_influence: np.ndarray | None = None
    #: the drive-frequency response and how it was treated (:func:`l1b2.ident.frequency.frequency_record`):
    #: ``{"status": "estimated" | "fixed", "reason", "response": FrequencyResponse dict or None, ...}``
    frequency: dict | None = None

    @property
    def frequency_response(self):
        """The :class:`~l1b2.predictor.frequency.FrequencyResponse` of the model (None: gain 1 at every frequency)."""
        return FrequencyResponse.from_dict((self.frequency or {}).get("response"))

    def __post_init__(self):
        p = len(self.values)
        if self.stderr_robust is None:
            self.stderr_robust = np.full(p, np.nan)
        if self.ci95_robust is None:
            self.ci95_robust = np.full((p, 2), np.nan)
        if self.cov_robust is None:
            self.cov_robust, _ = _diagonal(np.asarray(self.stderr_robust, float))

    # -- views ------------------------------------------------------------------
    @property
    def order(self) -> int:
        """Polynomial order n of A', B', P."""
        return self.params.order

    @property
    def theta_names(self) -> list[str]:
        return PredictorParams.names(self.order)

    @property
    def names(self) -> list[str]:
        """Joint names: theta (Eq. 35 order), then the extra-force parameters."""
        return self.theta_names + list(self.extra_names)

    @property
    def p_theta(self) -> int:
        return len(self.theta_names)

    @property
    def theta(self) -> np.ndarray:
        return self.values[: self.p_theta]

    @property
    def phi(self) -> np.ndarray:
        return self.values[self.p_theta:]

    @property
    def fixed(self) -> dict:
        """The pins as applied (name -> value)."""
        return dict(self.settings.get("fixed") or {})

    @property
    def ar1_factor(self) -> np.ndarray:
        """AR(1) variance inflation ``(1 + rho)/(1 - rho)`` per run."""
        return (1 + self.ar1_rho) / (1 - self.ar1_rho)

    @property
    def n_samples(self) -> int:
        """Number of residuals in the likelihood."""
        return self.n_obs

    @property
    def units(self) -> dict[str, str]:
        """Unit of every joint parameter."""
        xu = list(self.extra_units) or [""] * len(self.extra_names)
        return {**PredictorParams.units(self.order), **dict(zip(self.extra_names, xu))}

    @property
    def parameters(self) -> dict[str, Parameter]:
        """name -> :class:`Parameter`, joint order."""
        units = self.units
        out = {}
        for i, nm in enumerate(self.names):
            out[nm] = Parameter(
                name=nm, value=float(self.values[i]), stderr=float(self.stderr[i]),
                ci95=(float(self.ci95[i, 0]), float(self.ci95[i, 1])), unit=units.get(nm, ""),
                vary=bool(self.varied[i]), identifiable=bool(self.identifiable[i]),
                stderr_fisher=float(self.stderr_fisher[i]), stderr_robust=float(self.stderr_robust[i]),
                ci95_robust=(float(self.ci95_robust[i, 0]), float(self.ci95_robust[i, 1])),
            )
        return out

    def correlations(self, min_correl: float = 0.0) -> list[tuple[str, str, float]]:
        """Pairs ``(a, b, C_ab)`` with finite |C_ab| > ``min_correl``, strongest first."""
        names = self.names
        pairs = []
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                cij = self.corr[i, j]
                if np.isfinite(cij) and abs(cij) > min_correl:
                    pairs.append((abs(cij), names[i], names[j], cij))
        return [(a, b, float(c)) for _, a, b, c in sorted(pairs, reverse=True)]

    # -- predictions ---------------------------------------------------------------
    def _extra_matrix(self, frame):
        """Features of the extra forces on ``frame`` (None without extras)."""
        names = list(self.extra_names)
        if not names:
            return None
        if self.extra is None:
            raise IdentificationError(
                f"this identifier has extra-force parameters {names} but no feature function: "
                "reattach it with PredictorIdentifier.from_dict(d, extra=ExtraForces(...))"
            )
        if list(self.extra.names) != names:
            raise IdentificationError(f"extra: names {list(self.extra.names)} differ from the fitted {names}")
        return self.extra.evaluate(frame)

    def extra_force(self, data) -> np.ndarray:
        """``features(df) @ phi`` per sample [N, drive coordinates] (zeros without extras)."""
        frame = data.df if isinstance(data, Measurements) else data
        E = self._extra_matrix(frame)
        if E is None:
            return np.zeros(len(frame))
        return E @ self.phi

    def predict(self, data, criterion: str = "free_run") -> np.ndarray:
        """Predicted speed per sample [m/s] on a Measurements or data-format DataFrame.

        ``"free_run"``: from each run's first measured speed; ``"one_step"``:
        v(k+1 | measured v(k)), NaN at the first sample of each run. Extra
        forces are computed on ``data``.
        """
        sample = SampleData(data, frequency=self.frequency_response)
        E = self._extra_matrix(sample.frame)
        prm = self.params
        prob = make_problem(prm.drive_law, sample, self.order, prm.kappa, prm.include_load_inertia, criterion,
                            prm.s_center, prm.s_half, self.slider_mass_kg, E=E)
        return prob.predict_all(self.values)

    def plot_runs(self, data, runs=None, criterion: str = "free_run", predicted=None, ncols: int = 4):
        """Figure of measured and predicted speed [mm/s] over position [mm], one panel per run.

        Parameters
        ----------
        data : Measurements or pandas.DataFrame
            Data in the data format.
        runs : sequence, optional
            Run ids to show (default all, in data order).
        criterion : {"free_run", "one_step"}
            Which prediction to draw (ignored when ``predicted`` is given).
        predicted : array_like, optional
            Predicted speed per sample [m/s] to draw instead.
        ncols : int
            Panels per row.

        Returns
        -------
        matplotlib.figure.Figure
            Not attached to pyplot; save it with ``fig.savefig(path)``.
        """
        from matplotlib.figure import Figure

        sample = SampleData(data)
        v_pred = self.predict(data, criterion) if predicted is None else np.asarray(predicted, float)
        lay = sample.layout
        label = "predicted" if predicted is not None else criterion.replace("_", " ")
        chosen = [r for r in range(lay.R) if runs is None or lay.labels[r] in set(runs)]
        if not chosen:
            raise IdentificationError(f"plot_runs: none of the runs {list(runs)} is in the data")
        ncols = max(1, min(int(ncols), len(chosen)))
        nrows = math.ceil(len(chosen) / ncols)
        fig = Figure(figsize=(3.2 * ncols, 2.5 * nrows + 0.6), layout="constrained")
        axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True)
        for ax, r in zip(axes.flat, chosen):
            sl = slice(lay.starts[r], lay.starts[r] + lay.lengths[r])
            ax.plot(sample.s[sl] * 1e3, sample.v[sl] * 1e3, "k.", ms=2,
                    label="derived from position" if sample.speed_derived else "measured")
            ax.plot(sample.s[sl] * 1e3, v_pred[sl] * 1e3, "b-", lw=1, label=label)
            ax.set_title(f"run {lay.labels[r]}: {sample.V0[sl.start]:g} V, {sample.load[sl.start]:+g} kg, "
                         f"dir {int(sample.d[sl.start]):+d}", fontsize=8)
            ax.grid(alpha=0.3)
        for ax in list(axes.flat)[len(chosen):]:
            ax.set_visible(False)
        axes.flat[0].legend(fontsize=7)
        fig.supxlabel("position [mm]")
        fig.supylabel("speed [mm/s]")
        return fig

    # -- report ----------------------------------------------------------------------
    def fit_report(self, min_correl: float = 0.9) -> str:
        """Readable summary in the spirit of lmfit's fit_report."""
        lines = self._report_model() + self._report_statistics() + self._report_convergence()
        lines += self._report_variables() + self._report_correlations(min_correl)
        warn = self._report_warnings()
        if warn:
            lines.append("[[Warnings]]")
            lines.extend(warn)
        return "\n".join(lines)

    def _report_model(self) -> list[str]:
        st = self.settings
        lines = [
            "[[Model]]",
            f"    L1B2 reduced predictor ({'paper ' if self.params.drive_law == 'eq29' else ''}"
            f"{_FAMILY_TEXT[self.params.drive_law]}), order {st['order']}, "
            f"criterion {st['criterion']}, "
            f"noise {st['noise']}, kappa {st['kappa']}, "
            f"m_eff = m_s{' + |m_load|' if st['include_load_inertia'] else ''}",
        ]
        lines += frequency_report_lines(self.frequency)
        if self.extra_names:
            desc = self.extra_description or ""
            lines.append(
                f"    + extra forces (drive coordinates, X += features @ phi): {', '.join(self.extra_names)}"
                + (f" -- {desc}" if desc else "")
            )
        return lines

    def _report_statistics(self) -> list[str]:
        nvar = int(np.sum(self.varied))
        return [
            "[[Fit Statistics]]",
            f"    # residuals (n)          = {self.n_obs}",
            f"    # runs                   = {len(self.runs)}",
            f"    # varied parameters      = {nvar} (identifiable: {self.k_params})",
            f"    residual RMS             = {self.residual_rms:.6g} m/s",
            f"    log-likelihood           = {self.loglik:.6g}",
            f"    AIC                      = {self.aic:.6g}",
            f"    BIC                      = {self.bic:.6g}",
            "    (k counts varied identifiable theta "
            + ("and extra-force " if self.extra_names else "")
            + "parameters; noise variances not counted)",
            f"    effective n (AR(1))      = {self.n_eff:.6g}; t(0.975, {self.dof:.0f}) = {self.t_quantile:.4f}",
            f"    slider mass              = {self.slider_mass_kg} kg; fit time = {self.fit_time_s:.2f} s",
        ]

    def _report_convergence(self) -> list[str]:
        c = self.convergence
        costs = [s["cost"] for s in c["starts"]]
        return [
            "[[Convergence]]",
            f"    best start {c['best_start']} of {c['n_starts']}; status {c['status']} ({c['message']}); "
            f"optimality {c['optimality']:.3g}; noise R converged: {c['noise_converged']}; "
            f"total nfev {c['nfev_total']}",
            "    start costs: " + ", ".join(f"{x:.6g}" if np.isfinite(x) else "-" for x in costs)
            + ("  (-: start not continued)" if not all(np.isfinite(costs)) else ""),
        ]

    def _report_variables(self) -> list[str]:
        lines = ["[[Variables]]  value +/- stderr (AR(1)-corrected; plain Fisher in brackets)  95% CI"
                 "  | robust (sandwich by run) stderr and 95% CI"]
        names_all = self.names
        p = self.p_theta
        w = max(len(nm) for nm in names_all)
        free = []  # not identifiable: named once below the table, not as rows of infinite errors
        for i, prm in enumerate(self.parameters.values()):
            nm, val, u = prm.name, prm.value, prm.unit
            if i == p and self.extra_names:
                lines.append("    -- extra forces --")
            if not prm.vary:
                lines.append(f"    {nm:<{w}} = {val: .6g} [{u}] (fixed)")
                continue
            se = prm.stderr
            if not np.isfinite(se):
                free.append(f"{nm} = {val:.6g} [{u}]")
                continue
            rel = f" ({100 * se / abs(val):.2f}%)" if val != 0 else ""
            lo, hi = prm.ci95
            sig = ""
            if i >= p:
                sig = "  (significant: CI excludes 0)" if (lo > 0 or hi < 0) else "  (not significant: CI contains 0)"
            rlo, rhi = prm.ci95_robust
            robust = (f"  | robust +/- {prm.stderr_robust:.3g} CI [{rlo:.6g}, {rhi:.6g}]"
                      if np.isfinite(prm.stderr_robust) else "")
            lines.append(
                f"    {nm:<{w}} = {val: .6g} +/- {se:.3g}{rel} [{u}]  [{prm.stderr_fisher:.3g}]"
                f"  CI [{lo:.6g}, {hi:.6g}]{sig}{robust}"
            )
        if free:
            lines.append(f"    not identifiable from these data ({len(free)} parameters on the "
                         f"{len(self.unidentifiable)} direction(s) under [[Warnings]]; values only):")
            lines += ["      " + ", ".join(free[k:k + 4]) for k in range(0, len(free), 4)]
        return lines

    def _report_correlations(self, min_correl) -> list[str]:
        pairs = self.correlations(min_correl)
        lines = [f"[[Correlations]] (|C| > {min_correl})"]
        if not pairs:
            return lines + ["    none"]
        for a, b, cij in pairs[:40]:
            lines.append(f"    C({a}, {b}) = {cij:+.4f}")
        if len(pairs) > 40:
            lines.append(f"    ... {len(pairs) - 40} more")
        return lines

    def _report_warnings(self) -> list[str]:
        warn = []
        if self.unidentifiable:
            warn.append(
                f"    {len(self.unidentifiable)} direction(s) in parameter space the data cannot determine "
                f"(singular values < {self.settings['svd_rtol']:g} x largest); affected parameters have stderr = inf."
            )
            for cmb in self.unidentifiable:
                warn.append("    - " + cmb["text"])
            warn.append(
                "    Structurally the data fix only D(s) = c_r + sigma (0.5 - A'(s)), B'(s) and "
                "C(s) = mu P (2 sqrt(1-k0^2) - 1 - pi/2 A' G(k0)) - mu_sd (9.81 m_s + kappa P); "
                f"pin one parameter per direction, e.g. fixed='recommended' = {list(RECOMMENDED_FIXED)}."
            )
        for w in self.weak_directions:
            warn.append("    - " + w["text"])
        for nm, cf in self.extra_confounding.items():
            warn.extend(_confounding_warning(nm, cf))
        for alt in self.alternative_optima:
            diff = ", ".join(f"{n} = {v:.4g} ({z:.0f} stderr away)" for n, v, z in alt["differs_most"])
            warn.append(
                f"    - another optimum (start {alt['start']}) fits almost as well "
                f"(log-likelihood lower by {alt['delta_loglik']:.2f}) with {diff}: "
                "the local intervals do not cover it (discrete ambiguity, e.g. the split of C(s) into P and A')."
            )
        if not self.convergence["success"]:
            warn.append(f"    - the final local optimisation did not converge: {self.convergence['message']}")
        return warn

    # -- serialisation -------------------------------------------------------------------
    def _parameter_entry(self, prm: Parameter) -> dict:
        return {
            "value": prm.value,
            "stderr": json_float(prm.stderr),
            "stderr_fisher": json_float(prm.stderr_fisher),
            "ci95": [json_float(prm.ci95[0]), json_float(prm.ci95[1])],
            "stderr_robust": json_float(prm.stderr_robust),
            "ci95_robust": [json_float(prm.ci95_robust[0]), json_float(prm.ci95_robust[1])],
            "unit": prm.unit,
            "vary": prm.vary,
            "identifiable": prm.identifiable,
        }

    def to_dict(self) -> dict[str, Any]:
        """Strict-JSON summary (NaN -> None, inf -> "inf") that :meth:`from_dict` restores."""
        prms = self.parameters
        params = {nm: self._parameter_entry(prms[nm]) for nm in self.theta_names}
        extra_sec = {}
        for nm in self.extra_names:
            extra_sec[nm] = {**self._parameter_entry(prms[nm]),
                             "confounding": strict_json(self.extra_confounding.get(nm, {}))}
        d = {
            "model": f"l1b2 reduced predictor ({_FAMILY_TEXT[self.params.drive_law]})",
            "settings": dict(self.settings),
            "slider_mass_kg": self.slider_mass_kg,
            "predictor_params": self.params.to_dict(),
            "parameters": params,
            "extra": extra_sec,
            "extra_description": self.extra_description or "",
            "paper_monomials": self.params.to_paper_monomials(self.T_s),
            "T_s": self.T_s,
            "runs": [r if isinstance(r, (int, str)) else strict_json(r) for r in self.runs],
            "noise_var": [float(x) for x in self.noise_var],
            "ar1_rho": [float(x) for x in self.ar1_rho],
            "n_obs": self.n_obs,
            "n_eff": self.n_eff,
            "k_params": self.k_params,
            "loglik": self.loglik,
            "aic": self.aic,
            "bic": self.bic,
            "residual_rms": self.residual_rms,
            "singular_values": [float(x) for x in self.singular_values],
            "unidentifiable": self.unidentifiable,
            "weak_directions": self.weak_directions,
            "alternative_optima": self.alternative_optima,
            "convergence": self.convergence,
            "fit_time_s": self.fit_time_s,
            "frequency": self.frequency,
        }
        return strict_json(d)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], extra=None) -> "IdentificationResult":
        """Rebuild from :meth:`to_dict` (covariance and correlation only on the diagonal).

        The values of extra-force parameters (section ``"extra"``) are
        restored; their feature function cannot be serialised: pass the same
        ``extra=ExtraForces(...)`` to reattach it (its names must match).
        Without it, predictions of a model with extra forces raise
        :class:`~l1b2.errors.IdentificationError`.
        """
        xsec = dict(d.get("extra") or {})
        xnames = list(xsec)
        if extra is not None:
            if not xnames:
                raise IdentificationError("from_dict: extra given, but the fit has no extra-force parameters")
            if sorted(extra.names) != sorted(xnames):
                raise IdentificationError(
                    f"from_dict: extra names {list(extra.names)} differ from the fitted {xnames}"
                )
            xnames = list(extra.names)
        params = PredictorParams.from_dict(d["predictor_params"])
        prm = d["parameters"]
        names = PredictorParams.names(params.order)
        sec = [prm[n] for n in names] + [xsec[n] for n in xnames]
        stderr = np.array([from_json_float(s.get("stderr")) for s in sec])
        stderr_fisher = np.array([from_json_float(s.get("stderr_fisher", s.get("stderr"))) for s in sec])
        cov, corr = _diagonal(stderr)
        cov_fisher, _ = _diagonal(stderr_fisher)
        n_eff, k_params = float(d["n_eff"]), int(d["k_params"])
        dof = max(n_eff - k_params, 1.0)
        return cls(
            settings=dict(d["settings"]), params=params,
            values=np.concatenate([params.to_vector(), [float(xsec[n]["value"]) for n in xnames]]),
            extra_names=xnames, extra_units=[str(xsec[n].get("unit", "")) for n in xnames],
            extra_description=str(d.get("extra_description", "") or ""),
            varied=np.array([bool(s.get("vary", True)) for s in sec], dtype=bool),
            identifiable=np.array([bool(s.get("identifiable", True)) for s in sec], dtype=bool),
            stderr=stderr, stderr_fisher=stderr_fisher,
            ci95=np.array([[from_json_float(x) for x in s["ci95"]] for s in sec]).reshape(-1, 2),
            cov=cov, cov_fisher=cov_fisher, corr=corr,
            slider_mass_kg=float(d["slider_mass_kg"]), T_s=from_json_float(d["T_s"]), runs=list(d["runs"]),
            noise_var=np.asarray(d["noise_var"], float), ar1_rho=np.asarray(d["ar1_rho"], float),
            n_obs=int(d["n_obs"]), n_eff=n_eff, k_params=k_params, dof=dof,
            t_quantile=float(stats.t.ppf(0.975, dof)), loglik=from_json_float(d["loglik"]),
            aic=from_json_float(d["aic"]), bic=from_json_float(d["bic"]),
            residual_rms=from_json_float(d["residual_rms"]),
            singular_values=np.asarray(d["singular_values"], float),
            unidentifiable=list(d["unidentifiable"]), weak_directions=list(d.get("weak_directions", [])),
            alternative_optima=list(d.get("alternative_optima", [])),
            extra_confounding={n: _confounding_from_json(xsec[n].get("confounding")) for n in xnames},
            convergence=dict(d["convergence"]), fit_time_s=float(d["fit_time_s"]), extra=extra,
            stderr_robust=np.array([from_json_float(s.get("stderr_robust")) for s in sec]),
            ci95_robust=np.array([[from_json_float(x) for x in s.get("ci95_robust", [None, None])]
                                  for s in sec]).reshape(-1, 2),
            frequency=d.get("frequency"),
        )

    def save(self, directory, **sections) -> Path:
        """Write ``identification.json`` (:meth:`to_dict` plus ``sections``) and ``fit_report.txt``.

        ``sections``: further top-level entries of the JSON (e.g. data,
        metrics, figures), made strict JSON the same way. Creates
        ``directory`` if needed; returns it.
        """
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        payload = {**self.to_dict(), **strict_json(sections)}
        # the model's own numbers round-trip exactly (export --identification rebuilds it); the rest of the
        # report is written with the digits it has (12 significant: 0.001, not 0.0009999999999998899)
        payload = {k: (v if k in MODEL_SECTIONS else strict_json(v, digits=12)) for k, v in payload.items()}
        (out / "identification.json").write_text(dumps(payload))
        (out / "fit_report.txt").write_text(self.fit_report())
        return out


def _confounding_warning(nm, cf) -> list[str]:
    """The [[Warnings]] line of a confounded extra parameter (variance inflation > 10), if any."""
    vif = cf.get("variance_inflation", float("nan"))
    if vif is None or not (isinstance(vif, (int, float)) and (vif > 10 or vif == float("inf"))):
        return []
    mc = ", ".join(f"{a} ({b:+.3f})" for a, b in cf.get("most_correlated", []))
    if vif == float("inf"):
        return [
            f"    - extra parameter {nm} is confounded with theta: its effect on the predictions can be "
            "reproduced by the Eq. 35 parameters (not identifiable jointly)"
        ]
    return [
        f"    - extra parameter {nm} is confounded with theta: {100 * cf['explained_by_theta']:.2f} % of "
        f"its effect on the predictions can be reproduced by the Eq. 35 parameters (variance inflation "
        f"{vif:.3g}: stderr {cf['stderr']:.3g} jointly vs {cf['stderr_if_theta_known']:.3g} if theta "
        f"were known); most correlated: {mc}"
    ]


def _confounding_from_json(cf) -> dict:
    cf = dict(cf or {})
    for k in ("stderr", "stderr_if_theta_known", "variance_inflation", "explained_by_theta"):
        if k in cf:
            cf[k] = from_json_float(cf[k])
    cf["most_correlated"] = [(str(a), float(b)) for a, b in cf.get("most_correlated", [])]
    return cf
