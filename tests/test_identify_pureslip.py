"""Identification of the pure-slip predictor family: Jacobian, recovery, Eq. 29 misfit on its data, serialisation."""

import numpy as np
from objectives import central_difference
import pytest
from l1b2.data.metrics import evaluation_mask
from l1b2.errors import IdentificationError
from l1b2.ident.estimator import PredictorIdentifier
from l1b2.ident.problem import SampleData
from l1b2.ident.result import IdentificationResult
from l1b2.ident.slipproblem import PureSlipProblem
from l1b2.predictor.model import PredictorParams, example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset

M_S = 0.1
DESIGN = design_grid(voltages=(180.0, 250.0, 324.0), loads=(-0.05, 0.0, 0.05))


def _truth():
    # sigma 8 N s/m with B' ~ 6 mN/V: tip speed ~0.4-0.8 m/s, slip ratio ~0.2-0.5 (pure slip matters)
    p = example_params(2)
    return p.replace(sigma=8.0, c_r=5.0, alpha=(0.05, 0.005, 0.0), drive_law="pure_slip")


@pytest.fixture(scope="module")
def data():
    prm = _truth()
    return prm, simulate_dataset(prm, DESIGN, M_S, noise_std=5e-4, seed=3)


@pytest.mark.parametrize("criterion", ["free_run", "one_step"])
def test_pure_slip_jacobian_matches_finite_differences(data, criterion):
    prm, df = data
    prob = PureSlipProblem(SampleData(df, evaluation_mask(df)), 2, 0.5, True, criterion, 0.0, 0.02, M_S)
    th = prm.to_vector()
    theta = th * (1 + 0.03 * np.sin(np.arange(th.size)))
    cols = np.arange(th.size)
    J = prob.jacobian(theta, cols)
    Jfd = np.empty_like(J)
    for j in cols:
        Jfd[:, j] = central_difference(prob.residual, theta, j, 1e-3)
    scale = np.abs(Jfd).max(axis=0)
    ok = scale > 0
    assert np.all(np.abs(J[:, ~ok]) == 0)              # k0: no effect in this family
    rel = np.abs(J - Jfd).max(axis=0)[ok] / scale[ok]
    assert rel.max() < 1e-4, dict(zip(np.array(PredictorParams.names(2))[ok], rel))
    # the free run reproduces the data it was simulated with (same step, same recursion)
    if criterion == "free_run":
        r = prob.residual(th)
        assert np.sqrt(np.mean(r ** 2)) < 2e-3


def test_pure_slip_fit_recovers_its_world_and_beats_eq29_there(data):
    prm, df = data
    kw = dict(order=2, n_starts=2, seed=0, fixed="recommended", max_nfev=60)
    ps = PredictorIdentifier(model="pure_slip", **kw).fit(df, slider_mass_kg=M_S)
    eq = PredictorIdentifier(**kw).fit(df, slider_mass_kg=M_S)
    assert ps.params_.drive_law == "pure_slip" and eq.params_.drive_law == "eq29"
    assert ps.result_.settings["model"] == "pure_slip"
    # sigma is free in this family and found: it sets the tip speed of the slip ratio
    i = ps.param_names.index("sigma")
    assert ps.varied_[i] and abs(ps.theta_[i] - prm.sigma) < 4 * ps.stderr_[i] + 0.1 * prm.sigma
    assert not ps.varied_[ps.param_names.index("k0")]
    assert ps.residual_rms_ < 1.2e-3 < eq.residual_rms_
    # the result round-trips with its family and predicts the same
    back = IdentificationResult.from_dict(ps.result_.to_dict())
    assert back.params.drive_law == "pure_slip"
    np.testing.assert_allclose(back.predict(df), ps.predict_free_run(df), rtol=1e-12, atol=1e-15)


def test_pure_slip_settings_are_checked():
    df = simulate_dataset(_truth(), DESIGN.iloc[:2], M_S, seed=1)
    with pytest.raises(IdentificationError, match="model must be one of"):
        PredictorIdentifier(model="linear", order=2).fit(df, slider_mass_kg=M_S)
    with pytest.raises(IdentificationError, match="varpro"):
        PredictorIdentifier(model="pure_slip", solver="varpro", order=2).fit(df, slider_mass_kg=M_S)
