"""Tests of the maximum-likelihood identification (paper Eq. 32, 35; l1b2.ident)."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny dense problems: threads only cost

import json

import numpy as np
from objectives import central_difference
import pandas as pd
import pytest
from scipy.stats import chi2
from l1b2.errors import IdentificationError
from l1b2.ident.estimator import (
    RECOMMENDED_FIXED,
    PredictorIdentifier,
    evaluation_mask,
)
from l1b2.ident.problem import LikelihoodProblem, SampleData
from l1b2.ident.reduced import reduced_of_theta
from l1b2.predictor.model import PredictorParams, example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset

M_S = 0.1
#: a small design for the repeated fits: 2 voltages x 3 loads x 2 directions
SMALL = design_grid(voltages=(220.0, 324.0), loads=(-0.07, 0.0, 0.07))
#: pins that make the varied parameters of order 3 locally identifiable and
#: well conditioned (smallest relative singular value ~6e-4, see test below)
COVERAGE_FIXED = ("sigma", "k0", "mu", "mu_sd", "p_0")


def _truth(order):
    prm = example_params(order)
    return prm, prm.to_vector(), PredictorParams.names(order)


@pytest.fixture(scope="module")
def noisy_small():
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=1e-3, seed=11)
    return prm, th, names, df


# ---------------------------------------------------------------------------
# analytic Jacobian
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("criterion", ["free_run", "one_step"])
def test_jacobian_matches_finite_differences(noisy_small, criterion):
    prm, th, names, df = noisy_small
    df = df.copy()
    starts = np.flatnonzero(np.r_[True, np.diff(df["run"].to_numpy()) != 0])
    df.loc[starts[:2], "speed_m_s"] = 0.0  # runs starting exactly at rest
    data = SampleData(df, evaluation_mask(df))
    prob = LikelihoodProblem(data, 3, 0.5, True, criterion, 0.0, 0.02, M_S)
    theta = th * (1 + 0.05 * np.sin(np.arange(th.size)))  # away from the truth
    cols = np.arange(th.size)
    J = prob.jacobian(theta, cols)
    # the data exercise the rest rule and the reversal rule
    flags = prob.evaluate(theta)["flags"]
    if criterion == "free_run":
        assert np.any(flags == 1), "no reversal step in the test data"
    Jfd = np.empty_like(J)
    for j in cols:
        Jfd[:, j] = central_difference(prob.residual, theta, j, 1e-3)
    rel = np.abs(J - Jfd).max(axis=0) / np.abs(Jfd).max(axis=0)
    assert rel.max() < 1e-5, dict(zip(names, rel))
    # sensitivity of the free run to the measured start speed
    if criterion == "free_run":
        # (perturbed in the drive direction: at an exact rest start the map has a kink,
        # and the gain is the one of a motion starting in the drive direction)
        g = prob.start_gain(theta)
        lay = prob.lay
        d_run = prob.core.d[: lay.na[0]]
        d_res = prob.core.d[prob.sel]
        v0 = prob.v0.copy()
        prob.v0 = v0 + 1e-7 * d_run
        prob.reset_cache()
        rp = prob.residual(theta)
        prob.v0 = v0
        prob.reset_cache()
        r0 = prob.residual(theta)
        np.testing.assert_allclose((rp - r0) / (1e-7 * d_res), g, rtol=1e-4, atol=1e-6)
        assert lay.R == 12


def test_equation_error_jacobian():
    th = example_params(8).to_vector() * 1.1
    g, Jg = reduced_of_theta(th, 8, M_S, 0.5, jac=True)
    Jfd = np.empty_like(Jg)
    for j in range(th.size):
        Jfd[:, j] = central_difference(lambda t: reduced_of_theta(t, 8, M_S, 0.5), th, j, 1e-3)
    assert np.abs(Jg - Jfd).max() / np.abs(Jfd).max() < 1e-7


# ---------------------------------------------------------------------------
# identifiability
# ---------------------------------------------------------------------------


def test_all_parameters_varied_names_the_structural_groups():
    """Paper setting (all of Eq. 35 varied): three exact null directions.

    Noise-free data, runs starting at rest. Structurally the data determine
    D(s) = c_r + sigma (0.5 - A'), B'(s) and C(s) = mu P (g1 - pi/2 A' G)
    - mu_sd (9.81 m_s + kappa P); the invariances are (1) sigma-scaling of
    A' - alpha_0, (2) the split c_r / alpha_0, (3) the scale of P, each
    compensated by mu and k0. Only beta (B') and mu_sd are identifiable.
    """
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=0.0)
    idf = PredictorIdentifier(order=3, n_starts=2, seed=0).fit(df, M_S, mask=evaluation_mask(df))
    assert idf.residual_rms_ < 1e-9
    assert len(idf.unidentifiable_) == 3
    ident = {n for n, i in zip(names, idf.identifiable_) if i}
    assert ident == {"mu_sd", "beta_0", "beta_1", "beta_2", "beta_3"}
    involved = set().union(*(c["parameters"] for c in idf.unidentifiable_))
    assert {"c_r", "sigma", "mu", "k0", "alpha_0", "p_0"} <= involved
    assert not any(n.startswith("beta") for n in involved)
    for i, n in enumerate(names):
        if n in ident:
            assert np.isfinite(idf.stderr_[i])
        else:
            assert idf.stderr_[i] == np.inf and np.isnan(idf.corr_[i, 0])
    rel = idf.singular_values_ / idf.singular_values_[0]
    assert np.sum(rel < 1e-8) == 3 and rel[-4] > 1e-9
    # mu_sd is identifiable only through the constant 9.81 m_s mu_sd in C(s): weak
    assert any("mu_sd" in w["parameters"][:1] for w in idf.weak_directions_)
    assert idf.k_params_ == len(names) - 3
    rep = idf.fit_report()
    assert "not identifiable" in rep and "predictions unchanged along" in rep
    # predictions are exact although the parameters are not determined
    assert np.max(np.abs(idf.predict_free_run(df) - df["speed_m_s"])) < 1e-9


def test_recommended_pins_are_locally_identifiable():
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=5e-5, seed=2)
    idf = PredictorIdentifier(order=3, n_starts=2, fixed="recommended", seed=0).fit(
        df, M_S, mask=evaluation_mask(df)
    )
    assert tuple(idf.fixed_) == RECOMMENDED_FIXED
    assert idf.unidentifiable_ == []
    assert np.all(np.isfinite(idf.stderr_[idf.varied_]))
    assert np.all(np.isnan(idf.stderr_[~idf.varied_]))
    # pinned at data-driven conventional values: the structural pins cost no fit
    assert 0.9 < idf.residual_rms_ / 5e-5 < 1.1


def test_coverage_pinned_configuration_free_run():
    """Recovery and 95 % interval coverage over 20 seeded repetitions.

    Configuration: order 3, sigma, k0, mu, mu_sd and p_0 pinned at the truth
    (the three structural null directions, the practically unidentifiable
    mu_sd, and the weak split alpha_0 / P-scale; smallest relative singular
    value ~6e-4). White speed noise 5e-5 m/s (about 2.5x the quantisation
    noise of a 50 nm encoder differentiated at 1 kHz).
    """
    prm, th, names = _truth(3)
    fixed = {n: th[names.index(n)] for n in COVERAGE_FIXED}
    noise = 5e-5
    inside = []
    ratios = []
    estimates, stderrs, fisher_se, noise_var = [], [], [], []
    for seed in range(20):
        df = simulate_dataset(prm, SMALL, M_S, noise_std=noise, seed=100 + seed)
        idf = PredictorIdentifier(order=3, n_starts=4, fixed=fixed, seed=0).fit(df, M_S, mask=evaluation_mask(df))
        v = idf.varied_
        assert idf.unidentifiable_ == []
        lo, hi = idf.ci95_[v, 0], idf.ci95_[v, 1]
        inside.append((lo <= th[v]) & (th[v] <= hi))
        ratios.append(idf.residual_rms_ / noise)
        estimates.append(idf.theta_[v])
        stderrs.append(idf.stderr_[v])
        fisher_se.append(idf.stderr_fisher_[v])
        noise_var.append(idf.noise_var_)
    inside = np.array(inside)
    cover = inside.mean(axis=0)
    vn = [n for n in names if n not in fixed]
    assert np.all(cover >= 0.9), dict(zip(vn, cover))
    ratios = np.array(ratios)
    assert np.all(np.abs(ratios - 1) < 0.1), ratios
    # issue 14: the Eq. 32 noise variances are the simulated one (per run within 25 %, on average within
    # 5 %): a variance off by a factor (standard errors scaled with it) fails here. (In this configuration
    # the intervals are conservative for the higher Legendre coefficients - Fisher stderr up to ~1.9x the
    # spread of the estimates over the repetitions, pooled coverage 99 % - so the two-sided coverage test
    # is the next one, on a configuration where the Fisher matrix is calibrated.)
    noise_var = np.array(noise_var)
    # per run, n_r * R_r / sigma^2 is about chi-square with n_r degrees of freedom (the smallest run has ~100
    # evaluated samples: a spread of ~14 %); bounds at a family-wise level of 1e-3 over every run and seed
    ratio = noise_var / noise**2
    n_min = int(np.min(np.bincount(pd.factorize(df["run"])[0][evaluation_mask(df)])))
    level = 1e-3 / ratio.size
    lo, hi = chi2.ppf(level / 2, n_min) / n_min, chi2.ppf(1 - level / 2, n_min) / n_min
    assert np.all((lo < ratio) & (ratio < hi)), (lo, hi, ratio.min(), ratio.max())
    assert abs(np.mean(noise_var) / noise**2 - 1) < 0.05, np.mean(noise_var) / noise**2
    assert np.all(np.array(stderrs) >= np.array(fisher_se) * (1 - 1e-12))


#: the two-sided coverage configuration: the leading coefficients and c_r varied, the rest pinned at the truth
TWO_SIDED_VARIED = ("c_r", "alpha_0", "alpha_1", "beta_0", "beta_1", "p_1")


def test_coverage_is_two_sided():
    """95 % intervals cover 90-99 % of 30 repeated simulations (pooled), not more, not less.

    Six parameters varied (the rest pinned at the truth), order 3, white speed
    noise 5e-5 m/s. Too wide intervals fail as well as too narrow ones: the
    reported stderr must agree with the spread of the estimates over the
    repetitions (factor 0.7-1.4, the sampling error of 30 repetitions) and the
    Eq. 32 noise variance with the simulated one.
    """
    prm, th, names = _truth(3)
    fixed = {n: th[names.index(n)] for n in names if n not in TWO_SIDED_VARIED}
    noise = 5e-5
    inside, est, se, nv = [], [], [], []
    for seed in range(30):
        df = simulate_dataset(prm, SMALL, M_S, noise_std=noise, seed=300 + seed)
        idf = PredictorIdentifier(order=3, n_starts=1, fixed=fixed, seed=0).fit(df, M_S, mask=evaluation_mask(df))
        v = idf.varied_
        assert [names[i] for i in np.flatnonzero(v)] == list(TWO_SIDED_VARIED)
        lo, hi = idf.ci95_[v, 0], idf.ci95_[v, 1]
        inside.append((lo <= th[v]) & (th[v] <= hi))
        est.append(idf.theta_[v])
        se.append(idf.stderr_[v])
        nv.append(np.mean(idf.noise_var_))
    inside = np.array(inside)
    assert 0.90 <= inside.mean() <= 0.99, inside.mean(axis=0)
    ratio = np.mean(se, axis=0) / np.std(est, axis=0, ddof=1)
    assert np.all((ratio > 0.7) & (ratio < 1.4)), dict(zip(TWO_SIDED_VARIED, ratio))
    assert abs(np.mean(nv) / noise**2 - 1) < 0.05


def test_one_step_recovers_theta_on_low_noise_data():
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=1e-6, seed=3)
    fixed = {n: th[names.index(n)] for n in RECOMMENDED_FIXED}
    idf = PredictorIdentifier(order=3, criterion="one_step", n_starts=4, fixed=fixed, seed=0).fit(
        df, M_S, mask=evaluation_mask(df)
    )
    v = idf.varied_
    err = np.abs(idf.theta_[v] - th[v])
    # the scalars and the leading coefficients to 1 %, every coefficient well inside its interval
    for n in ("c_r", "alpha_0", "beta_0"):
        i = names.index(n)
        assert abs(idf.theta_[i] - th[i]) < 0.01 * abs(th[i]), n
    assert np.all(err < 3 * idf.stderr_[v])
    p1 = idf.predict_one_step(df)
    starts = np.flatnonzero(np.r_[True, np.diff(df["run"].to_numpy()) != 0])
    assert np.all(np.isnan(p1[starts]))
    ok = ~np.isnan(p1)
    assert np.sqrt(np.mean((p1[ok] - df["speed_m_s"].to_numpy()[ok]) ** 2)) < 5e-6


# ---------------------------------------------------------------------------
# estimator behaviour
# ---------------------------------------------------------------------------


def test_common_noise_loglik_is_the_closed_form_of_the_residual_sum_of_squares():
    """Eq. 32 with one unknown variance R (the default): at the fit, R = RSS / n and the log-likelihood is
    -n/2 (log(2 pi RSS / n) + 1), from the residuals of the reported prediction (start-speed term off)."""
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=1e-4, seed=5)
    mask = evaluation_mask(df)
    idf = PredictorIdentifier(order=3, n_starts=2, fixed="recommended", seed=1, start_noise=False).fit(
        df, M_S, mask=mask)
    assert idf.noise == "common" and idf.result_.settings["noise"] == "common"
    e = (df["speed_m_s"].to_numpy() - idf.predict_free_run(df))[mask]
    n, rss = e.size, float(np.sum(e ** 2))
    assert idf.n_obs_ == n
    assert np.allclose(idf.noise_var_, rss / n, rtol=1e-9)
    assert idf.loglik_ == pytest.approx(-0.5 * n * (np.log(2 * np.pi * rss / n) + 1.0), abs=1e-6)


def test_fixed_pins_reporting_and_serialisation(tmp_path):
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=1e-4, seed=5)
    fixed = {"sigma": 0.3, "k0": 0.4, "mu": 0.23, "mu_sd": 0.1}
    idf = PredictorIdentifier(order=3, n_starts=2, fixed=fixed, noise="common", seed=1).fit(df, M_S)
    for k, val in fixed.items():
        assert idf.theta_[names.index(k)] == val
        assert not idf.varied_[names.index(k)]
    assert isinstance(idf.params_, PredictorParams) and idf.params_.order == 3
    assert np.allclose(idf.noise_var_, idf.noise_var_[0])  # common variance
    for attr in ("theta_", "stderr_", "stderr_fisher_", "ci95_", "cov_", "corr_", "noise_var_", "loglik_",
                 "aic_", "bic_", "singular_values_", "unidentifiable_", "convergence_", "fit_time_s_"):
        assert hasattr(idf, attr), attr
    assert idf.aic_ == pytest.approx(2 * idf.k_params_ - 2 * idf.loglik_)
    assert idf.bic_ == pytest.approx(idf.k_params_ * np.log(idf.n_obs_) - 2 * idf.loglik_)
    c = idf.convergence_
    assert len(c["starts"]) == 2 and all("cost" in s and "nfev" in s and "status" in s for s in c["starts"])
    # the AR(1)-corrected error is never smaller than the plain Fisher error
    v = idf.varied_
    assert np.all(idf.stderr_[v] >= idf.stderr_fisher_[v] * (1 - 1e-12))
    rep = idf.fit_report()
    for piece in ("[[Variables]]", "c_r", "N s/m", "(fixed)", "AIC", "BIC", "[[Convergence]]", "95% CI"):
        assert piece in rep
    d = idf.to_dict()
    text = json.dumps(d, allow_nan=False)
    path = tmp_path / "fit.json"
    path.write_text(text)
    d2 = json.loads(path.read_text())
    assert d2["parameters"]["c_r"]["unit"] == "N s/m"
    assert len(d2["paper_monomials"]["p"]) == 4
    back = PredictorIdentifier.from_dict(d2)
    np.testing.assert_array_equal(back.theta_, idf.theta_)
    np.testing.assert_allclose(back.predict_free_run(df), idf.predict_free_run(df), rtol=0, atol=0)
    np.testing.assert_allclose(back.stderr_, idf.stderr_)
    vs = back.steady_state(0.0, 300.0, 0.0, 1)
    assert 0.2 < float(vs) < 0.35
    assert back.fit_report()


def test_speed_derived_from_positions_when_absent():
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=0.0).drop(columns=["speed_m_s"])
    fixed = {n: th[names.index(n)] for n in COVERAGE_FIXED}
    idf = PredictorIdentifier(order=3, n_starts=1, fixed=fixed).fit(df, M_S)
    assert idf.residual_rms_ < 5e-3


def _df_ok():
    prm, _, _ = _truth(3)
    return simulate_dataset(prm, SMALL, M_S, noise_std=1e-4, seed=1)


@pytest.mark.parametrize(
    "case",
    ["one_run", "few_samples", "no_motion", "mass_missing", "mass_negative", "nan_run", "bad_fixed",
     "missing_column", "bad_direction", "bad_mask"],
)
def test_errors_raise_identification_error(case):
    df = _df_ok()
    kwargs = {"slider_mass_kg": M_S}
    est = PredictorIdentifier(order=3, n_starts=1)
    if case == "one_run":
        df = df[df["run"] == 0]
        match = "too few runs"
    elif case == "few_samples":
        df = df.groupby("run").head(3)
        match = "too few"
    elif case == "no_motion":
        df = df.assign(speed_m_s=0.0)
        match = "no speed variation"
    elif case == "mass_missing":
        kwargs = {"slider_mass_kg": None}
        match = "slider_mass_kg"
    elif case == "mass_negative":
        kwargs = {"slider_mass_kg": -1.0}
        match = "slider_mass_kg"
    elif case == "nan_run":
        df = df.copy()
        df.loc[df.index[df["run"] == 3][10], "position_m"] = np.nan
        match = "run 3"
    elif case == "bad_fixed":
        est = PredictorIdentifier(order=3, n_starts=1, fixed={"gamma": 1.0})
        match = "unknown parameter"
    elif case == "missing_column":
        df = df.drop(columns=["load_kg"])
        match = "load_kg"
    elif case == "bad_direction":
        df = df.assign(direction=df["direction"] * 2)
        match = "direction"
    elif case == "bad_mask":
        kwargs["mask"] = np.ones(5, dtype=bool)
        match = "mask"
    with pytest.raises(IdentificationError, match=match):
        est.fit(df, **kwargs)


def test_constructor_and_usage_errors():
    # the constructor only stores the settings (scikit-learn convention); fit checks them
    df = _df_ok()
    with pytest.raises(IdentificationError):
        PredictorIdentifier(criterion="two_step").fit(df, M_S)
    with pytest.raises(IdentificationError):
        PredictorIdentifier(noise="white").fit(df, M_S)
    with pytest.raises(IdentificationError, match="not fitted"):
        PredictorIdentifier().predict_free_run(pd.DataFrame())


def test_evaluation_mask_is_the_metrics_one():
    from l1b2.data import metrics

    assert evaluation_mask is metrics.evaluation_mask


# ---------------------------------------------------------------------------
# noise fit: profile likelihood against the alternation; "auto" (default) chooses between them
# ---------------------------------------------------------------------------


def test_profile_noise_fit_reaches_the_ml_variances_and_beats_the_alternation():
    """On data the model does not fit exactly (order-5 truth, order-2 model, per-run noise variances), the
    profile search ends at a point where the noise variances are their ML values (re-estimating them
    changes nothing) and its log-likelihood is at least the alternation's."""
    prm = example_params(5)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=3e-4, seed=5)
    kw = dict(order=2, n_starts=3, fixed="recommended", seed=0, noise="per_run")
    alt = PredictorIdentifier(noise_fit="alternate", **kw).fit(df, M_S, mask=evaluation_mask(df))
    pro = PredictorIdentifier(noise_fit="profile", **kw).fit(df, M_S, mask=evaluation_mask(df))
    assert pro.result_.settings["noise_fit"] == "profile"  # the setting is in the report
    assert PredictorIdentifier().noise_fit == "auto"  # the defaults
    assert PredictorIdentifier().noise == "common"
    assert alt.result_.settings["noise_fit"] == "alternate"
    assert pro.loglik_ >= alt.loglik_ - 0.1
    conv = pro.convergence_
    assert conv["success"] and conv["noise_converged"]
    ll = [h["loglik"] for h in conv["outer"]]
    assert np.all(np.diff(ll) > 0)  # every accepted iteration gains likelihood
    # the final variances are the ML ones at the optimum: a profile step from there gains < stat_tol
    assert conv["outer"][-1]["loglik"] == pytest.approx(pro.loglik_, abs=1e-6)


def test_profile_search_statistical_stop_and_settings_errors():
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=1e-4, seed=7)
    est = PredictorIdentifier(order=3, n_starts=6, fixed="recommended", start_agree=2, seed=0, noise_fit="profile")
    est.fit(df, M_S, mask=evaluation_mask(df))
    starts = est.convergence_["starts"]
    run = [s for s in starts if s.get("status") is not None]
    skipped = [s for s in starts if s.get("status") is None]
    # well-posed data: the starts agree, so the search stops after the second agreeing start
    assert len(run) >= 2 and len(run) + len(skipped) == 6
    assert all("statistical stop" in s["message"] for s in skipped)
    best = max(s["loglik"] for s in run)
    assert sum(s["loglik"] >= best - 10 * est.stat_tol for s in run) >= 2
    for bad in (dict(noise_fit="newton"), dict(start_agree=-1), dict(stat_window_profile=0)):
        with pytest.raises(IdentificationError):
            PredictorIdentifier(order=3, **bad).fit(df, M_S)


#: the ways the profile search stops (its convergence message's start); which one ends a search short of an exact
#: optimum depends on the last bits of its steps, so on the BLAS kernels of the machine
PROFILE_STOPS = ("no step increases the log-likelihood", "iteration limit", "statistical convergence")


@pytest.mark.parametrize("noise", ["per_run", "common"])
def test_profile_search_stalled_on_exact_data_is_polished_to_the_optimum(noise):
    """Noise-free data, every parameter varied: the damped Gauss-Newton of the profile search ends about
    6e-8 m/s rms short of the exact fit -- it stalls (no step gains), creeps to its iteration limit or stops
    by its statistical rule, as the round-off of the machine's BLAS has it; least-squares refits continue from
    there to the exact optimum (residual at rounding level), and the report says why and how."""
    prm, th, names = _truth(3)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=0.0)
    idf = PredictorIdentifier(order=3, n_starts=2, seed=0, solver="joint", noise_fit="profile", noise=noise).fit(
        df, M_S, mask=evaluation_mask(df))
    assert idf.residual_rms_ < 1e-9
    conv = idf.convergence_
    stop = next((x for x in PROFILE_STOPS if conv["message"].startswith(x)), None)
    assert stop is not None, conv["message"]
    assert "least-squares refit(s) at the ML variances" in conv["message"]
    assert "polish" in conv["outer"][-1] and stop in conv["outer"][-1]["polish"]
    ll = [h["loglik"] for h in conv["outer"]]
    assert np.all(np.diff(ll) > 0)


def test_auto_noise_fit_is_profile_alone_and_alternate_with_extra_forces():
    # "auto" resolves to the search recorded in the report: the profile search for the Eq. 29 model alone,
    # the alternation when extra forces are fitted with it (PredictorIdentifier docstring: measured why)
    from l1b2.ident.extra import ExtraForces
    prm = example_params(2)
    df = simulate_dataset(prm, SMALL, M_S, noise_std=3e-4, seed=6)
    m = evaluation_mask(df)
    kw = dict(order=2, n_starts=2, fixed="recommended", seed=0)
    alone = PredictorIdentifier(**kw).fit(df, M_S, mask=m)
    extra = ExtraForces(("dir_N",), ("N",), lambda d: np.asarray(d["direction"], float)[:, None])
    withx = PredictorIdentifier(extra=extra, **kw).fit(df, M_S, mask=m)
    assert alone.get_params()["noise_fit"] == withx.get_params()["noise_fit"] == "auto"
    assert alone.result_.settings["noise_fit"] == "profile"
    assert withx.result_.settings["noise_fit"] == "alternate"
    prof = PredictorIdentifier(noise_fit="profile", **kw).fit(df, M_S, mask=m)
    assert alone.loglik_ == prof.loglik_  # the same search
    with pytest.raises(IdentificationError, match="noise_fit must be one of"):
        PredictorIdentifier(noise_fit="best", **kw).fit(df, M_S, mask=m)


def test_cli_offers_the_estimators_noise_fits():
    # the CLI keeps its own copy of the choices (it imports no numerical module to build its parser)
    from l1b2 import cli
    from l1b2.ident import estimator
    assert cli.NOISE_FITS == estimator.NOISE_FITS
