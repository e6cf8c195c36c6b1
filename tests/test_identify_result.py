"""The identification API: scikit-learn settings protocol, Measurements input, the IdentificationResult object."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny dense problems: threads only cost

import json
import math

import numpy as np
import pytest
from l1b2.data.measurements import load_measurements, write_measurements
from l1b2.errors import IdentificationError
from l1b2.ident import IdentificationResult, Parameter, PredictorIdentifier, clone
from l1b2.ident.estimator import evaluation_mask
from l1b2.predictor.model import PredictorParams, example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset

M_S = 0.1
SMALL = design_grid(voltages=(220.0, 324.0), loads=(-0.07, 0.0, 0.07))
PRM = example_params(3)
TH = PRM.to_vector()
NAMES = PredictorParams.names(3)
FIX = {n: TH[NAMES.index(n)] for n in ("sigma", "k0", "mu", "mu_sd", "p_0")}


def _strict_json(text):
    """Parse JSON refusing NaN / Infinity tokens."""
    def refuse(token):
        raise ValueError(f"non-strict JSON token {token}")
    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def data():
    return simulate_dataset(PRM, SMALL, M_S, noise_std=1e-4, seed=5)


@pytest.fixture(scope="module")
def fitted(data):
    # mu_sd pinned without a value (NaN stderr), everything else varied: null directions (inf stderr)
    return PredictorIdentifier(order=3, n_starts=1, fixed=("mu_sd",), seed=0).fit(data, M_S,
                                                                                  mask=evaluation_mask(data))


def test_settings_protocol():
    est = PredictorIdentifier(order=3, n_starts="4", fixed="recommended")
    params = est.get_params()
    assert list(params)[:4] == ["order", "criterion", "n_starts", "seed"] and "init_extra" in params
    assert params["n_starts"] == "4"  # stored as given; fit normalises and checks
    twin = clone(est)
    assert twin is not est and twin.get_params() == params and not hasattr(twin, "result_")
    assert clone(est, n_starts=2).n_starts == 2 and est.n_starts == "4"
    assert est.set_params(seed=3, noise="common") is est and est.seed == 3 and est.noise == "common"
    with pytest.raises(IdentificationError, match="unknown setting"):
        est.set_params(gamma=1.0)
    assert "order=3" in repr(est) and "criterion" not in repr(est)


def test_fit_accepts_measurements(tmp_path, data):
    path = tmp_path / "train.csv"
    write_measurements(data, path, meta={"slider_mass_kg": M_S})
    meas = load_measurements(path)
    a = PredictorIdentifier(order=3, n_starts=1, fixed=FIX, seed=0).fit(meas)  # mass and mask from meas
    b = PredictorIdentifier(order=3, n_starts=1, fixed=FIX, seed=0).fit(data, M_S, mask=evaluation_mask(data))
    assert a.m_s_ == M_S
    assert a.n_obs_ == int(meas.mask.sum()) == b.n_obs_
    np.testing.assert_allclose(a.theta_, b.theta_, rtol=1e-12, atol=0)
    assert a.loglik_ == pytest.approx(b.loglik_, rel=1e-12)
    np.testing.assert_allclose(a.predict_free_run(meas), b.predict_free_run(data), rtol=1e-12, atol=1e-15)
    # an explicit mask and mass win over the Measurements' own
    c = PredictorIdentifier(order=3, n_starts=1, fixed=FIX, seed=0).fit(meas, slider_mass_kg=M_S,
                                                                        mask=np.ones(len(data), bool))
    assert c.n_obs_ == len(data)
    with pytest.raises(IdentificationError, match="slider_mass_kg"):
        PredictorIdentifier(order=3, n_starts=1).fit(data)


def test_result_object(fitted, data):
    res = fitted.result_
    assert isinstance(res, IdentificationResult)
    prms = res.parameters
    assert list(prms) == NAMES == res.names
    c_r = prms["c_r"]
    assert isinstance(c_r, Parameter) and c_r.unit == "N s/m" and c_r.name == "c_r"
    with pytest.raises(AttributeError):
        c_r.value = 1.0  # frozen
    mu_sd = prms["mu_sd"]
    assert not mu_sd.vary and math.isnan(mu_sd.stderr) and mu_sd.value == fitted.fixed_["mu_sd"]
    assert any(p.stderr == math.inf and not p.identifiable for p in prms.values())
    for i, n in enumerate(NAMES):
        assert prms[n].value == fitted.theta_[i]
        if fitted.varied_[i] and fitted.identifiable_[i]:
            lo, hi = prms[n].ci95
            assert lo < prms[n].value < hi and prms[n].stderr == fitted.stderr_[i]
    assert res.n_samples == fitted.n_obs_ and res.loglik == fitted.loglik_
    assert res.aic == fitted.aic_ and res.bic == fitted.bic_ and res.settings["order"] == 3
    assert all(abs(c) > 0.9 for _, _, c in res.correlations(0.9))
    assert res.fit_report() == fitted.fit_report()


def test_result_json_is_strict_and_round_trips(fitted, data):
    d = fitted.result_.to_dict()
    assert d == fitted.to_dict()
    text = json.dumps(d, allow_nan=False)
    back = IdentificationResult.from_dict(_strict_json(text))
    assert math.isnan(back.parameters["mu_sd"].stderr)  # NaN restored from None
    assert [p.stderr == math.inf for p in back.parameters.values()] == [
        p.stderr == math.inf for p in fitted.result_.parameters.values()]
    for n, p in fitted.result_.parameters.items():
        q = back.parameters[n]
        assert (q.value, q.unit, q.vary, q.identifiable) == (p.value, p.unit, p.vary, p.identifiable)
    np.testing.assert_array_equal(back.predict(data), fitted.predict_free_run(data))
    assert back.to_dict() == d


def test_result_plot_and_save(tmp_path, fitted, data):
    from matplotlib.figure import Figure

    fig = fitted.result_.plot_runs(data, ncols=4)
    assert isinstance(fig, Figure)
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert len(shown) == data["run"].nunique()
    assert len(shown[0].lines) == 2  # measured and predicted
    one = fitted.result_.plot_runs(data, runs=[3], criterion="one_step")
    assert len([ax for ax in one.axes if ax.get_visible()]) == 1
    with pytest.raises(IdentificationError, match="none of the runs"):
        fitted.result_.plot_runs(data, runs=["nope"])
    out = fitted.result_.save(tmp_path / "ident", metrics={"nrmse": float("nan")})
    doc = _strict_json((out / "identification.json").read_text())
    assert doc["metrics"] == {"nrmse": None}
    assert doc["parameters"] == fitted.to_dict()["parameters"]
    assert (out / "fit_report.txt").read_text() == fitted.fit_report()
