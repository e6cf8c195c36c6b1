"""Physical signs and ranges of the named effect families (issue 28, item 6), and what the calibrated motor carries.

The table below is the physics, written out here: a family whose parameters have a physical sign or range
declares it as bounds of its hypotheses (kept by the identification); every other named family is listed
as sign-free with the reason. A family that is in neither list fails the first test.
"""

import math

import numpy as np
import pytest
from l1b2.closeloop.acceptance import EffectSet
from l1b2.closeloop.candidates import candidate
from l1b2.physics.params import load_motor
from l1b2.predictor import effects as fx
from l1b2.predictor.effects.homes import map_effects
from l1b2.predictor.effects.model import ExtendedPredictor, IdentifiedEffect
from l1b2.predictor.model import example_params
from l1b2.predictor.setup import PredictorSetup
from test_effects_registry import TRAIN

INF = math.inf
#: parameter -> (lower, upper) of the families whose parameters have a physical range
PHYSICAL_RANGES = {
    "load_path_friction": {"pulley_mu": (0.0, 1.0)},                       # a Coulomb coefficient
    "speed_dependent_friction": {"drag_lin_N": (-INF, INF),               # corrects the baseline's damping
                                 "drag_quad_N": (0.0, INF)},              # a drag opposes the motion
    "inertia_mismatch": {"mass_error": (-1.0, INF)},                      # the moving mass stays positive
}
#: named families whose parameters take either sign, and why
SIGN_FREE = {
    "thermal_drift": "the force factor rises or falls with temperature (side of the resonance)",
    "thermal_drift_T": "same, driven by the logged temperature",
    "direction_asymmetry": "either channel may excite the B2 mode more strongly",
    "bar_waviness": "a waviness amplitude and phase",
    "local_defect": "a bump or a dip of the bar's friction",
    "drive_saturation": "saturation (< 0) or threshold (> 0)",
    "load_slope_voltage": "the load slope may grow or shrink with V0",
    "damping_voltage": "the damping may grow or shrink with V0",
    "position_load": "the load's effect may grow either way along the bar",
}


def _named():
    return [f for f in fx.families() if f.group in ("named", "interaction")]


def test_every_named_family_is_classified_and_declares_its_physical_ranges():
    for fam in _named():
        assert (fam.kind in PHYSICAL_RANGES) != (fam.kind in SIGN_FREE), fam.kind
        for h in fam.grid(TRAIN):
            if fam.kind in SIGN_FREE:
                assert h.bounds == (), (fam.kind, h.bounds)
            else:
                assert dict(zip(h.names, h.bounds)) == PHYSICAL_RANGES[fam.kind], fam.kind


@pytest.mark.parametrize("kind", sorted(PHYSICAL_RANGES))
def test_the_identification_is_bounded_by_the_physical_range(kind):
    c = candidate(None, fx.family(kind).grid(TRAIN)[0])
    outside = [lo - 1.0 if np.isfinite(lo) else -1.0 for lo, hi in c.bounds]
    extra = EffectSet().add(c, outside).extra()
    want = PHYSICAL_RANGES[kind]
    assert extra.lower == tuple(want[n][0] for n in c.names) and extra.upper == tuple(want[n][1] for n in c.names)
    start = EffectSet().add(c, outside).start()
    assert all(want[n][0] <= v <= want[n][1] for n, v in zip(c.names, start))


def _signals(n=200, seed=1):
    rng = np.random.default_rng(seed)
    d = rng.choice([-1.0, 1.0], n)
    return {"t": np.linspace(0, 10, n), "s": rng.uniform(-0.01, 0.01, n), "V0": rng.uniform(200, 320, n),
            "load": rng.choice([-0.07, -0.03, 0.03, 0.07], n), "d": d, "T": np.full(n, 25.0),
            "v_base": d * rng.uniform(0.02, 0.3, n) * rng.choice([1.0, 1.0, 1.0, -1.0], n),
            "a_base": rng.normal(0.0, 2.0, n)}


def _force(kind, phi, x):
    spec = fx.family(kind).grid(TRAIN)[0].spec
    return fx.effect_features(spec, x) @ np.asarray(phi, float)


def test_forces_inside_the_range_oppose_the_motion_as_the_physics_says():
    x = _signals()
    vp = x["d"] * x["v_base"]                     # speed in drive coordinates
    # pulley friction with mu in [0, 1]: a force against the drive direction, proportional to the hanging weight
    F = _force("load_path_friction", [0.15], x)
    np.testing.assert_allclose(F, -0.15 * 9.81 * np.abs(x["load"]), rtol=1e-12)
    # quadratic drag >= 0: opposes the motion whichever way the slider moves
    F = _force("speed_dependent_friction", [0.0, 0.4], x)
    assert np.all(F * vp < 0)
    # more moving mass (mass_error > 0): a force against the acceleration (drive coordinates)
    F = _force("inertia_mismatch", [0.5], x)
    acc = x["d"] * x["a_base"]
    assert np.all(F * acc <= 0) and np.any(F * acc < 0)


def _extended(stderr):
    setup = PredictorSetup(example_params(3), 0.1, 1e-3)
    spec = fx.family("load_path_friction").grid(TRAIN)[0].spec
    e = IdentifiedEffect("load_path_friction", "load_path_friction", dict(spec), ("pulley_mu",), ("1",),
                         (0.12,), (stderr,))
    return ExtendedPredictor(setup, setup, (e,), None, {"operating_points": {"voltages_V": [272.0],
                                                                            "loads_kg": [0.05],
                                                                            "position_m": [-0.01, 0.01]}})


@pytest.mark.parametrize("stderr", [None, float("inf"), float("nan")])
def test_the_calibrated_motor_carries_only_identified_values(stderr):
    mp = load_motor()
    out, recs = map_effects(_extended(stderr), mp)
    assert out == mp and not recs[0]["mapped"] and "not identified" in recs[0]["reason"]
    out, recs = map_effects(_extended(0.01), mp)
    assert recs[0]["mapped"] and out.slider.pulley_mu == pytest.approx(0.12)


def test_the_pulley_is_not_offered_once_a_generic_load_term_is_in():
    # the other order of test_closeloop_physical's collinearity check: the generic load term's |m| column
    # reproduces the pulley's force, so the named effect is not added on top of it
    import pandas as pd
    from l1b2.closeloop.acceptance import collinear
    x = _signals(400)
    run = np.repeat(np.arange(8), 50)
    df = pd.DataFrame({"time_s": x["t"], "run": run, "position_m": x["s"], "voltage_V": x["V0"],
                       "direction": np.repeat(np.where(np.arange(8) % 2, -1.0, 1.0), 50),
                       "load_kg": np.repeat([-0.07, -0.03, 0.0, 0.03, 0.07, 0.05, -0.05, 0.09], 50),
                       "speed_m_s": 0.1 * np.ones(400)})
    smooth = candidate(None, [h for h in fx.family("smooth").grid(TRAIN) if h.family == "smooth_load"][0])
    pulley = candidate(None, fx.family("load_path_friction").grid(TRAIN)[0])
    mask = np.ones(len(df), bool)
    assert collinear(pulley, EffectSet().add(smooth, np.zeros(smooth.n_params)), df, mask)
    assert not collinear(candidate(None, fx.family("drive_saturation").grid(TRAIN)[0]),
                         EffectSet().add(smooth, np.zeros(smooth.n_params)), df, mask)
