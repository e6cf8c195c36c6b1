"""The calibrated ``Stator.asym_b``'s standard error (issue 28, item 6): the delta method ``sqrt(g' C g)`` with the
direction calibration's gradient over the effect's force parameters and their covariance, which the close loop
carries from the identification into the calibrated record.

Fast (seconds): the standard error against a central-difference gradient computed here and a covariance written out
(strongly correlated gain and offset: the diagonal alone gives another figure), the reported covariance's block
against the grouped sandwich summed by hand, and the record's round trip (an older record without ``cov`` loads).
"""

import numpy as np
import pytest
from l1b2.closeloop.intervals import reported_covariance, reported_uncertainty
from l1b2.physics.params import load_motor
from l1b2.predictor import effects as fx
from l1b2.predictor.derive import derive_predictor_setup
from l1b2.predictor.effects.direction import calibrate_asymmetry

MP = load_motor()
SETUP = derive_predictor_setup(MP)
MODEL = fx.ExtendedPredictor(SETUP, SETUP, (), None, {"operating_points": {
    "voltages_V": [220.0, 324.0], "loads_kg": [0.0, 0.05], "position_m": [-0.01, 0.01]}})
PHI = (0.2, 0.05)                       # N: asym_gain, asym_offset_N
SE = (0.02, 0.01)
RHO = -0.9                              # the gain's column d V0/V_ref and the offset's d are nearly collinear
COV = ((SE[0] ** 2, RHO * SE[0] * SE[1]), (RHO * SE[0] * SE[1], SE[1] ** 2))


def _effect(cov=COV, phi=PHI):
    h = fx.family("direction_asymmetry").grid(None)[0]
    return fx.IdentifiedEffect(h.family, h.family, dict(h.spec), tuple(h.names), tuple(h.units), tuple(phi), SE,
                               cov=cov)


def test_the_calibrated_asymmetrys_standard_error_is_the_delta_method_with_the_effects_covariance():
    _, rec = fx.family("direction_asymmetry").calibrate(_effect(), MODEL, MP)
    value, se = rec["parameters"]["Stator.asym_b"], rec["stderr"]["Stator.asym_b"]
    assert value == pytest.approx(calibrate_asymmetry(MODEL, _effect(), MP)["value"])
    # the gradient by central differences (steps 1 % of each parameter), independent of the code's forward ones
    g = []
    for j, step in enumerate((0.002, 0.0005)):
        up, down = list(PHI), list(PHI)
        up[j] += step
        down[j] -= step
        g.append((calibrate_asymmetry(MODEL, _effect(phi=up), MP)["value"]
                  - calibrate_asymmetry(MODEL, _effect(phi=down), MP)["value"]) / (2 * step))
    want = np.sqrt(g[0] ** 2 * SE[0] ** 2 + 2 * g[0] * g[1] * RHO * SE[0] * SE[1] + g[1] ** 2 * SE[1] ** 2)
    assert se == pytest.approx(want, rel=0.02)
    np.testing.assert_allclose(rec["calibration"]["gradient"], g, rtol=0.02)
    diagonal = np.sqrt(g[0] ** 2 * SE[0] ** 2 + g[1] ** 2 * SE[1] ** 2)
    assert abs(se - diagonal) > 0.2 * diagonal       # the correlation matters: the standard errors alone mislead


def test_without_a_covariance_the_record_says_so_and_carries_no_standard_error():
    _, rec = fx.family("direction_asymmetry").calibrate(_effect(cov=None), MODEL, MP)
    assert rec["stderr"] == {"Stator.asym_b": None} and "no covariance" in rec["reason"]
    assert "gradient" not in rec["calibration"]


def test_an_effect_record_carries_its_covariance_and_an_older_one_without_it_still_loads():
    e = _effect()
    assert fx.IdentifiedEffect.from_dict(e.to_dict()) == e
    old = e.to_dict()
    del old["cov"]
    assert fx.IdentifiedEffect.from_dict(old).cov is None
    with pytest.raises(fx.EffectSpecError, match="cov is not 2 x 2"):
        fx.IdentifiedEffect.from_dict({**e.to_dict(), "cov": [[1.0, 0.0]]})


class _Fit:
    """A fit's views: four runs at two levels (runs 10/11 and 12/13), theta ``alpha_0`` then two added parameters."""

    runs_ = [10, 11, 12, 13]
    param_names_all_ = ["alpha_0", "asym_gain", "asym_offset_N"]
    extra_names_ = ["asym_gain", "asym_offset_N"]
    extra_params_ = {"asym_gain": 0.2, "asym_offset_N": 0.05}
    run_influence_ = np.array([[9.0, 1.0, 0.5], [9.0, 2.0, -1.5], [9.0, -1.0, 0.5], [9.0, 0.5, 1.0]])
    cov_all_ = np.array([[1.0, 0.0, 0.0], [0.0, 4e-4, -1e-4], [0.0, -1e-4, 1e-4]])
    cov_robust_all_ = np.array([[1.0, 0.0, 0.0], [0.0, 9e-4, -2e-4], [0.0, -2e-4, 4e-4]])
    extra_stderr_ = {"asym_gain": 0.02, "asym_offset_N": 0.01}
    extra_ci95_ = {"asym_gain": (0.16, 0.24), "asym_offset_N": (0.03, 0.07)}
    extra_stderr_robust_ = {"asym_gain": 0.03, "asym_offset_N": 0.02}
    extra_ci95_robust_ = {"asym_gain": (0.14, 0.26), "asym_offset_N": (0.01, 0.09)}


def test_the_reported_covariance_is_the_block_of_the_reported_interval():
    names = ("asym_gain", "asym_offset_N")
    # level: the two levels' summed influence rows (3, -1) and (-0.5, 1.5), times H/(H-1) = 2
    v = np.array([[3.0, -1.0], [-0.5, 1.5]])
    want = 2.0 * v.T @ v
    got = np.array(reported_covariance(_Fit(), names, ["a", "a", "b", "b"]))
    np.testing.assert_allclose(got, want, rtol=1e-12)
    for j, n in enumerate(names):
        assert np.sqrt(got[j, j]) == pytest.approx(reported_uncertainty(_Fit(), n, ["a", "a", "b", "b"])["stderr"])
    # no levels: the run-robust block; no finite robust one: the model-based block
    np.testing.assert_allclose(reported_covariance(_Fit(), names), [[9e-4, -2e-4], [-2e-4, 4e-4]])
    fit = _Fit()
    fit.extra_stderr_robust_ = {"asym_gain": float("nan"), "asym_offset_N": float("nan")}
    np.testing.assert_allclose(reported_covariance(fit, names), [[4e-4, -1e-4], [-1e-4, 1e-4]])
    fit.extra_stderr_robust_ = {"asym_gain": 0.03, "asym_offset_N": float("nan")}    # kinds differ: none
    assert reported_covariance(fit, names) is None


def test_the_cli_prints_the_calibrated_parameter_with_its_standard_error(tmp_path, capsys):
    import json
    from l1b2.cli import _print_calibrated
    sub = {"mapped": True, "parameters": {"Stator.asym_b": 0.04436}, "stderr": {"Stator.asym_b": 0.002636}}
    old = {"mapped": True, "parameters": {"Slider.pulley_mu": 0.1}}          # a record without standard errors
    man = {"effects": [{"label": "direction_asymmetry", "subsystems": sub},
                       {"label": "load_path_friction", "subsystems": old}],
           "calibrated_ssp": {"included": False}}
    (tmp_path / "calibrated_manifest.json").write_text(json.dumps(man))
    _print_calibrated(tmp_path)
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "  direction_asymmetry: Predictor.fmu; Stator.asym_b = 0.04436 +- 0.0026 (se) in the calibrated SSP"
    assert out[1] == "  load_path_friction: Predictor.fmu; Slider.pulley_mu = 0.1 in the calibrated SSP"
