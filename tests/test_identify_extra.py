"""Extra exogenous forces identified jointly with theta (l1b2.ident.extra.ExtraForces).

The model with extras: in drive coordinates ``X_total = X + features(df) @ phi``.
Synthetic data come from :func:`l1b2.predictor.simulate.simulate_dataset` with its
``extra_force`` hook (the same step function the predictor uses), so the
extended model is exact for them.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny dense problems: threads only cost

import json

import numpy as np
from objectives import central_difference
import pytest
from l1b2.errors import IdentificationError
from l1b2.ident.estimator import PredictorIdentifier, evaluation_mask
from l1b2.ident.extra import ExtraForces
from l1b2.ident.problem import LikelihoodProblem, SampleData
from l1b2.ident.reduced import init_theta
from l1b2.predictor.model import (
    PredictorParams,
    derivative,
    example_params,
    one_step,
    steady_state,
)
from l1b2.predictor.simulate import design_grid, free_run, simulate_dataset
from numpy.polynomial.legendre import legval

M_S = 0.1
SMALL = design_grid(voltages=(220.0, 324.0), loads=(-0.07, 0.0, 0.07))
NOISE = 1e-4
PRM = example_params(3)
TH = PRM.to_vector()
NAMES = PredictorParams.names(3)
#: the well-conditioned configuration of tests/test_identify.py (structural
#: null directions, the practically unidentifiable mu_sd and the weak P-scale pinned)
FIX = {n: TH[NAMES.index(n)] for n in ("sigma", "k0", "mu", "mu_sd", "p_0")}


def asym(df):
    """Direction-dependent force: +1 N per unit in drive coordinates for both directions."""
    return np.asarray(df["direction"], dtype=float)[:, None]


def bump(df):
    """A smooth position bump (e.g. a dent in the friction bar) at s = 5 mm, width 4 mm."""
    s = np.asarray(df["position_m"], dtype=float)
    return np.exp(-((s - 0.005) ** 2) / (2 * 0.004**2))[:, None]


def ones(df):
    return np.ones((len(df), 1))


def legendre2(df):
    """A smooth function of position that the Eq. 35 polynomials nearly reproduce."""
    x = np.asarray(df["position_m"], dtype=float) / 0.02
    return legval(x, [0.0, 0.0, 1.0])[:, None]


FEATURES = {"asym": (asym, 0.03), "bump": (bump, 0.08)}


def _simulate(feature=None, phi=0.0, seed=7, noise=NOISE):
    ef = None if feature is None else (lambda cols: feature(cols)[:, 0] * phi)
    return simulate_dataset(PRM, SMALL, M_S, noise_std=noise, seed=seed, extra_force=ef)


@pytest.fixture(scope="module")
def data_asym():
    return _simulate(asym, FEATURES["asym"][1])


@pytest.fixture(scope="module")
def fits_asym(data_asym):
    df = data_asym
    m = evaluation_mask(df)
    base = PredictorIdentifier(order=3, n_starts=2, fixed=FIX, seed=0).fit(df, M_S, mask=m)
    ex = ExtraForces(("dir_asym_force_N",), ("N",), asym, description="direction asymmetry")
    ext = PredictorIdentifier(order=3, n_starts=2, fixed=FIX, seed=0, extra=ex).fit(df, M_S, mask=m)
    return df, base, ext, ex


@pytest.fixture(scope="module")
def data_clean():
    return _simulate(None, seed=8)


@pytest.fixture(scope="module")
def base_clean(data_clean):
    df = data_clean
    return PredictorIdentifier(order=3, n_starts=2, fixed=FIX, seed=0).fit(df, M_S, mask=evaluation_mask(df))


# ---------------------------------------------------------------------------
# predictor: the extra_force argument
# ---------------------------------------------------------------------------


def test_predictor_extra_force_argument():
    rng = np.random.default_rng(0)
    n = 50
    s = rng.uniform(-0.02, 0.02, n)
    V0 = rng.choice([220.0, 324.0], n)
    load = rng.choice([-0.05, 0.0, 0.05], n)
    d = rng.choice([-1.0, 1.0], n)
    v = d * rng.uniform(0.05, 0.3, n)  # moving in the drive direction
    f = rng.uniform(-0.05, 0.05, n)
    m_eff = M_S + np.abs(load)
    # None = unchanged, bit for bit
    np.testing.assert_array_equal(derivative(PRM, v, s, V0, load, d, M_S, extra_force=None),
                                  derivative(PRM, v, s, V0, load, d, M_S))
    np.testing.assert_array_equal(one_step(PRM, v, s, V0, load, d, 1e-3, M_S, extra_force=None),
                                  one_step(PRM, v, s, V0, load, d, 1e-3, M_S))
    # a drive-coordinate force adds d * f / m_eff to the acceleration
    np.testing.assert_allclose(derivative(PRM, v, s, V0, load, d, M_S, extra_force=f),
                               derivative(PRM, v, s, V0, load, d, M_S) + d * f / m_eff, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(one_step(PRM, v, s, V0, load, d, 1e-3, M_S, extra_force=f),
                               one_step(PRM, v, s, V0, load, d, 1e-3, M_S) + 1e-3 * d * f / m_eff,
                               rtol=1e-12, atol=1e-15)
    # steady state of the forward branch: v'* = (X + f - Fr)/D
    v0 = steady_state(PRM, s, 300.0, 0.0, 1, M_S)
    v1 = steady_state(PRM, s, 300.0, 0.0, 1, M_S, extra_force=0.01)
    D = PRM.c_r + PRM.sigma * (0.5 - PRM.A_prime(s))
    np.testing.assert_allclose(v1 - v0, 0.01 / D, rtol=1e-10)
    # free_run with the force reproduces the simulation that used it
    df = simulate_dataset(PRM, SMALL, M_S, noise_std=0.0, extra_force=lambda c: 0.03 * asym(c)[:, 0])
    vf = free_run(PRM, df["position_m"], df["voltage_V"], df["load_kg"], df["direction"], df["time_s"], 0.0, M_S,
                  run_index=df["run"], extra_force=0.03 * asym(df)[:, 0])
    np.testing.assert_allclose(vf, df["speed_m_s"], rtol=0, atol=1e-12)
    v_plain = free_run(PRM, df["position_m"], df["voltage_V"], df["load_kg"], df["direction"], df["time_s"], 0.0,
                       M_S, run_index=df["run"])
    assert np.max(np.abs(v_plain - df["speed_m_s"])) > 1e-3  # the force matters


# ---------------------------------------------------------------------------
# analytic Jacobian w.r.t. phi
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("criterion", ["free_run", "one_step"])
def test_jacobian_wrt_phi_matches_finite_differences(criterion):
    df = _simulate(asym, 0.03, seed=11, noise=1e-3).copy()
    starts = np.flatnonzero(np.r_[True, np.diff(df["run"].to_numpy()) != 0])
    df.loc[starts[:2], "speed_m_s"] = 0.0  # runs starting exactly at rest
    E = np.column_stack([asym(df)[:, 0], bump(df)[:, 0]])
    data = SampleData(df, evaluation_mask(df))
    prob = LikelihoodProblem(data, 3, 0.5, True, criterion, 0.0, 0.02, M_S, E=E)
    theta = np.concatenate([TH * (1 + 0.05 * np.sin(np.arange(TH.size))), [0.02, -0.03]])
    cols = np.arange(theta.size)
    J = prob.jacobian(theta, cols)
    flags = prob.evaluate(theta)["flags"]
    if criterion == "free_run":
        assert np.any(flags == 1), "no reversal step in the test data"
    Jfd = np.empty_like(J)
    for j in cols:
        Jfd[:, j] = central_difference(prob.residual, theta, j, 1e-3)
    rel = np.abs(J - Jfd).max(axis=0) / np.abs(Jfd).max(axis=0)
    assert rel.max() < 1e-5, dict(zip(NAMES + ["asym", "bump"], rel))
    assert np.abs(Jfd[:, -2:]).max() > 0  # the extras do act on the residuals
    # zero features: residuals and theta columns are those of the model without extras
    prob0 = LikelihoodProblem(data, 3, 0.5, True, criterion, 0.0, 0.02, M_S)
    probz = LikelihoodProblem(data, 3, 0.5, True, criterion, 0.0, 0.02, M_S, E=np.zeros_like(E))
    np.testing.assert_array_equal(probz.residual(theta), prob0.residual(theta[: TH.size]))
    np.testing.assert_array_equal(probz.jacobian(theta, np.arange(TH.size)),
                                  prob0.jacobian(theta[: TH.size], np.arange(TH.size)))


# ---------------------------------------------------------------------------
# recovery
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["asym", "bump"])
def test_recovery_of_an_extra_force(kind):
    feature, phi_true = FEATURES[kind]
    df = _simulate(feature, phi_true)
    m = evaluation_mask(df)
    ex = ExtraForces((f"{kind}_N",), ("N",), feature)
    ext = PredictorIdentifier(order=3, n_starts=2, fixed=FIX, seed=0, extra=ex).fit(df, M_S, mask=m)
    base = PredictorIdentifier(order=3, n_starts=2, fixed=FIX, seed=0).fit(df, M_S, mask=m)
    phi = ext.extra_params_[f"{kind}_N"]
    lo, hi = ext.extra_ci95_[f"{kind}_N"]
    assert lo <= phi_true <= hi, (phi, lo, hi)
    assert abs(phi - phi_true) < 0.02 * phi_true
    assert lo > 0  # significant
    np.testing.assert_array_equal(ext.phi_, [phi])
    assert ext.extra_identifiable_.all() and ext.extra_varied_.all()
    # the free-run residual drops to the noise level; without the extra it is clearly larger
    assert 0.9 < ext.residual_rms_ / NOISE < 1.1
    assert base.residual_rms_ > 3 * NOISE
    assert ext.loglik_ > base.loglik_ + 100
    assert ext.aic_ < base.aic_ and ext.bic_ < base.bic_
    assert ext.k_params_ == base.k_params_ + 1
    # the theta-shaped attributes keep their shape; the joint ones are one longer
    p = len(NAMES)
    assert ext.theta_.shape == (p,) and ext.stderr_.shape == (p,) and ext.ci95_.shape == (p, 2)
    assert ext.cov_.shape == (p, p) and ext.corr_.shape == (p, p)
    assert ext.stderr_all_.shape == (p + 1,) and ext.corr_all_.shape == (p + 1, p + 1)
    assert ext.param_names_all_ == NAMES + [f"{kind}_N"]
    assert ext.stderr_all_[-1] == ext.extra_stderr_[f"{kind}_N"]
    # predictions computed with the features of the given data frame
    v = ext.predict_free_run(df)
    r = (v - df["speed_m_s"].to_numpy())[m]
    assert np.sqrt(np.mean(r**2)) == pytest.approx(ext.residual_rms_, rel=1e-9)
    np.testing.assert_allclose(ext.extra_force(df), feature(df)[:, 0] * phi)


def test_useless_features_are_not_significant(data_clean, base_clean):
    df, base = data_clean, base_clean
    m = evaluation_mask(df)
    col = np.random.default_rng(0).normal(size=len(df))
    cases = {"noise_N": lambda d: col[np.asarray(d.index)][:, None], "const_N": ones, "leg2_N": legendre2}
    for name, feat in cases.items():
        ext = PredictorIdentifier(order=3, n_starts=2, fixed=FIX, seed=0,
                                  extra=ExtraForces((name,), ("N",), feat)).fit(df, M_S, mask=m)
        lo, hi = ext.extra_ci95_[name]
        assert lo < 0 < hi, (name, lo, hi)
        # predictions as good as without it (the fit of 13 instead of 12 parameters)
        assert abs(ext.residual_rms_ / base.residual_rms_ - 1) < 2e-3, name
        v_e = ext.predict_free_run(df)[m]
        v_b = base.predict_free_run(df)[m]
        assert np.sqrt(np.mean((v_e - v_b) ** 2)) < 0.2 * NOISE, name
        conf = ext.extra_confounding_[name]
        rep = ext.fit_report()
        assert "not significant: CI contains 0" in rep
        if name == "noise_N":
            assert conf["variance_inflation"] < 2  # white noise is nothing like theta's sensitivities
        else:
            # a constant or smooth position force is (nearly) reproduced by the position polynomials
            assert conf["variance_inflation"] > 1e3 and conf["explained_by_theta"] > 0.999, (name, conf)
            assert f"extra parameter {name} is confounded with theta" in rep


# ---------------------------------------------------------------------------
# warm start
# ---------------------------------------------------------------------------


def test_warm_start_from_the_baseline(fits_asym, data_clean, base_clean):
    df, base, ext_cold, ex = fits_asym
    m = evaluation_mask(df)
    warm = PredictorIdentifier(order=3, n_starts=1, fixed=FIX, seed=0, extra=ex, init=base.params_).fit(
        df, M_S, mask=m
    )
    c = warm.convergence_
    assert c["n_starts"] == 1 and len(c["starts"]) == 1 and c["success"]
    assert warm.reduced_["equation_error_minima"] == []  # no equation-error search: one local refinement
    assert warm.warm_prestep_["accepted"]  # phi given theta moved phi off its start value 0
    np.testing.assert_array_equal(c["starts"][0]["x0"][-1], warm.warm_prestep_["phi"][0])
    assert warm.loglik_ >= base.loglik_
    assert warm.residual_rms_ < 1.1 * NOISE
    phi = warm.extra_params_["dir_asym_force_N"]
    assert abs(phi - FEATURES["asym"][1]) < 0.01 * FEATURES["asym"][1]
    # the pins come from init (FIX values); init's theta is the centre
    for k, v in FIX.items():
        assert warm.fixed_[k] == v
    np.testing.assert_array_equal(warm.theta_init_, base.theta_)
    # with n_starts=2: two tracks, the warm start and the data-driven search; the better one is kept
    warm2 = PredictorIdentifier(order=3, n_starts=2, fixed=FIX, seed=0, extra=ex, init=base.params_,
                                init_extra=[0.01]).fit(df, M_S, mask=m)
    tr = warm2.convergence_["tracks"]
    assert [t["track"] for t in tr] == ["warm start (init)", "data-driven"]
    assert warm2.loglik_ == max(t["loglik"] for t in tr)
    assert sum(t["chosen"] for t in tr) == 1
    assert warm2.loglik_ >= max(warm.loglik_, ext_cold.loglik_) - 1.0
    assert warm2.extra_params_ and warm2.fit_time_s_ >= max(t["fit_time_s"] for t in tr)
    # on data without the effect a useless feature cannot lower the likelihood
    dfc = data_clean
    ex_c = ExtraForces(("const_N",), ("N",), ones)
    w_c = PredictorIdentifier(order=3, n_starts=1, fixed=FIX, seed=0, extra=ex_c, init=base_clean.params_).fit(
        dfc, M_S, mask=evaluation_mask(dfc)
    )
    assert w_c.loglik_ >= base_clean.loglik_ - 1e-6


def test_init_in_another_position_scaling_is_re_expanded():
    th = init_theta(PRM, 3, 0.001, 0.018)
    p2 = PredictorParams.from_vector(th, s_center=0.001, s_half=0.018)
    s = np.linspace(-0.017, 0.019, 37)
    np.testing.assert_allclose(p2.A_prime(s), PRM.A_prime(s), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(p2.B_prime(s), PRM.B_prime(s), rtol=1e-12, atol=1e-16)
    np.testing.assert_allclose(p2.P(s), PRM.P(s), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(th[:5], TH[:5])
    np.testing.assert_array_equal(init_theta(PRM, 3, 0.0, 0.02), TH)


# ---------------------------------------------------------------------------
# serialisation, reporting, API
# ---------------------------------------------------------------------------


def test_to_dict_from_dict_round_trip(fits_asym):
    df, _, ext, ex = fits_asym
    d = json.loads(json.dumps(ext.to_dict(), allow_nan=False))
    sec = d["extra"]["dir_asym_force_N"]
    assert sec["unit"] == "N" and sec["value"] == ext.extra_params_["dir_asym_force_N"]
    assert sec["ci95"] == list(ext.extra_ci95_["dir_asym_force_N"]) and sec["stderr"] > 0
    assert d["extra_description"] == "direction asymmetry"
    assert "dir_asym_force_N" not in d["parameters"]  # the Eq. 35 section is unchanged
    back = PredictorIdentifier.from_dict(d, extra=ex)
    np.testing.assert_array_equal(back.theta_, ext.theta_)
    assert back.extra_params_ == ext.extra_params_
    assert back.extra_ci95_ == ext.extra_ci95_
    assert back.extra_stderr_ == ext.extra_stderr_
    np.testing.assert_array_equal(back.predict_free_run(df), ext.predict_free_run(df))
    np.testing.assert_array_equal(back.predict_one_step(df), ext.predict_one_step(df))
    assert "dir_asym_force_N" in back.fit_report()
    # without the feature function: values restored, predictions refused clearly
    bare = PredictorIdentifier.from_dict(d)
    assert bare.extra_params_ == ext.extra_params_
    with pytest.raises(IdentificationError, match="from_dict"):
        bare.predict_free_run(df)
    with pytest.raises(IdentificationError, match="extra"):
        bare.predict_one_step(df)
    with pytest.raises(IdentificationError, match="differ"):
        PredictorIdentifier.from_dict(d, extra=ExtraForces(("other",), ("N",), asym))
    # steady state with the identified extra force of a +1 run
    vs0 = back.steady_state(0.0, 300.0, 0.0, 1)
    vs1 = back.steady_state(0.0, 300.0, 0.0, 1, extra_force_N=ext.extra_params_["dir_asym_force_N"])
    assert vs1 > vs0


def test_report_and_fixed_extras(fits_asym):
    df, base, ext, ex = fits_asym
    rep = ext.fit_report()
    for piece in ("-- extra forces --", "dir_asym_force_N", "significant: CI excludes 0", "direction asymmetry",
                  "[[Variables]]"):
        assert piece in rep
    assert "extra" not in base.fit_report()
    assert base.extra_params_ == {} and base.extra_names_ == [] and base.phi_.shape == (0,)
    np.testing.assert_array_equal(base.stderr_all_, base.stderr_)
    assert base.to_dict()["extra"] == {}
    # an extra parameter can be pinned like any other
    m = evaluation_mask(df)
    pinned = PredictorIdentifier(order=3, n_starts=1, fixed={**FIX, "dir_asym_force_N": 0.02}, seed=0,
                                 extra=ex).fit(df, M_S, mask=m)
    assert pinned.extra_params_["dir_asym_force_N"] == 0.02
    assert not pinned.extra_varied_[0] and np.isnan(pinned.extra_stderr_["dir_asym_force_N"])
    assert pinned.k_params_ == base.k_params_
    # a zero feature pinned at 0 is the model without extras
    zero = ExtraForces(("zero_N",), ("N",), lambda d: np.zeros(len(d)))
    z = PredictorIdentifier(order=3, n_starts=2, fixed={**FIX, "zero_N": 0.0}, seed=0, extra=zero).fit(
        df, M_S, mask=m
    )
    np.testing.assert_allclose(z.theta_, base.theta_, rtol=1e-7, atol=1e-12)
    assert z.loglik_ == pytest.approx(base.loglik_, rel=1e-9)  # same optimum up to rounding


def test_extra_forces_validation(data_clean):
    df = data_clean
    with pytest.raises(IdentificationError, match="units"):
        ExtraForces(("a", "b"), ("N",), lambda d: np.zeros((len(d), 2)))
    with pytest.raises(IdentificationError, match="callable"):
        ExtraForces(("a",), ("N",), None)
    with pytest.raises(IdentificationError, match="lower < upper"):
        ExtraForces(("a",), ("N",), ones, lower=(1.0,), upper=(0.0,))
    # settings are checked by fit (the constructor only stores them)
    with pytest.raises(IdentificationError, match="clash"):
        PredictorIdentifier(order=3, extra=ExtraForces(("c_r",), ("N",), ones)).fit(df, M_S)
    with pytest.raises(IdentificationError, match="init_extra"):
        PredictorIdentifier(order=3, extra=ExtraForces(("a",), ("N",), ones), init_extra=[1.0, 2.0]).fit(df, M_S)
    with pytest.raises(IdentificationError, match="order"):
        PredictorIdentifier(order=3, init=example_params(4)).fit(df, M_S)
    bad_shape = ExtraForces(("a", "b"), ("N", "N"), ones)
    with pytest.raises(IdentificationError, match="shape"):
        PredictorIdentifier(order=3, n_starts=1, extra=bad_shape).fit(df, M_S)
    nan_feat = ExtraForces(("a",), ("N",), lambda d: np.full(len(d), np.nan))
    with pytest.raises(IdentificationError, match="not finite"):
        PredictorIdentifier(order=3, n_starts=1, extra=nan_feat).fit(df, M_S)
    with pytest.raises(IdentificationError, match="unknown parameter"):
        PredictorIdentifier(order=3, n_starts=1, fixed={"zz": 1.0}, extra=ExtraForces(("a",), ("N",), ones)).fit(
            df, M_S
        )
    # 1-D features for one parameter, bounds respected
    ex = ExtraForces("a", "N", lambda d: np.asarray(d["direction"], float), lower=(0.0,), upper=(0.01,))
    assert ex.names == ("a",) and ex.units == ("N",)
    fit = PredictorIdentifier(order=3, n_starts=1, fixed=FIX, extra=ex).fit(
        _simulate(asym, 0.03), M_S)
    assert 0.0 <= fit.extra_params_["a"] <= 0.01


def test_confounding_survives_serialisation(data_clean):
    df = data_clean
    ex = ExtraForces(("const_N",), ("N",), ones)
    ext = PredictorIdentifier(order=3, n_starts=1, fixed=FIX, seed=0, extra=ex).fit(df, M_S, mask=evaluation_mask(df))
    back = PredictorIdentifier.from_dict(json.loads(json.dumps(ext.to_dict(), allow_nan=False)), extra=ex)
    a, b = ext.extra_confounding_["const_N"], back.extra_confounding_["const_N"]
    assert b["variance_inflation"] == pytest.approx(a["variance_inflation"])
    assert b["most_correlated"] == a["most_correlated"]
    assert "confounded with theta" in back.fit_report()
