"""The effect registry's contract (l1b2.predictor.effects): every family is one class that states its regressor,
signals, parameters, grid and physical home consistently, and the rig's injections refer to those families."""

import numpy as np
import pytest
from l1b2.physics.params import load_motor
from l1b2.predictor import effects as fx
from l1b2.predictor.effects.homes import physical_homes
from l1b2.rig.experiment import DATA_INJECTIONS, INJECTIONS

TRAIN = fx.TrainingSummary(
    m_s=0.12, time_range=(0.0, 300.0), position_range=(-0.012, 0.012), voltage_median=270.0,
    ranges={"t_lo": 0.0, "t_hi": 300.0, "s_lo": -0.012, "s_hi": 0.012, "V_lo": 220.0, "V_hi": 324.0,
            "load_abs": 0.09, "v_lo": 0.02, "v_hi": 0.3},
    temperature_ref=30.0, temperature_range=(25.0, 40.0), spectral_period_m=0.006,
    # a logged run setting of three values whose summary records its category (the categorical family's grid)
    channels=({"name": "fixture_id", "kind": "logged", "mean": 2.0, "sd": 0.8, "lo": 1.0, "hi": 3.0,
               "within_run": False, "run_spread": 0.0, "levels": (1.0, 2.0, 3.0), "shares": (0.4, 0.4)},
              # the session clock, whose record holds a segmentation into blocks (the session blocks' grid) and a
              # cycle (the session cycle's grid)
              {"name": "time_s", "kind": "protocol", "mean": 150.0, "sd": 86.6, "within_run": True,
               "block_edges": (100.0, 200.0), "block_shares": (0.3, 0.35), "cycle_period_s": 40.0,
               "cycle_means": (0.1, -0.05)}))


def _signals(n=50, seed=0):
    rng = np.random.default_rng(seed)
    return {"t": np.linspace(0, 300, n), "s": rng.uniform(-0.012, 0.012, n), "V0": rng.uniform(220, 324, n),
            "load": rng.uniform(-0.09, 0.09, n), "d": rng.choice([-1.0, 1.0], n), "T": rng.uniform(25, 40, n),
            "v_base": rng.uniform(-0.3, 0.3, n), "a_base": rng.normal(0, 1, n),
            # the protocol clock as a logged channel (l1b2.predictor.effects.channels): samples and run means
            "col:time_s": np.linspace(0, 300, n), "run:time_s": np.repeat(np.linspace(0, 300, 5), n // 5),
            "col:fixture_id": np.repeat([1.0, 3.0, 2.0, 1.0, 3.0], n // 5),
            "run:fixture_id": np.repeat([1.0, 3.0, 2.0, 1.0, 3.0], n // 5)}


@pytest.mark.parametrize("kind", fx.kinds())
def test_every_hypothesis_has_one_named_parameter_with_a_unit_per_feature_column(kind):
    # reference: the contract dF = features @ phi: len(names) = len(units) = feature columns, for every grid point,
    # and the features read only the signals the family declares (the others absent)
    fam = fx.family(kind)
    hyps = fam.grid(TRAIN)
    assert hyps, kind
    x = _signals()
    for h in hyps:
        assert h.spec["kind"] == kind and len(h.names) == len(h.units) == fam.width(h.spec)
        only = {k: v for k, v in x.items() if k in fx.needs(h.spec)}
        F = fx.effect_features(h.spec, only)
        assert F.shape == (50, len(h.names)) and np.all(np.isfinite(F))


def test_the_physical_homes_are_declared_motor_parameters_and_unchanged():
    # reference: the subsystem FMUs' parameter declarations (MotorParams) and the homes before the registry
    # (fmi/calibrate.py's PHYSICAL_HOMES)
    mp = load_motor()
    for fam in fx.families():
        for key in fam.home:
            comp, _, name = key.partition(".")
            assert hasattr(getattr(mp, comp.lower()), name), (fam.kind, key)
    assert physical_homes() == {
        "load_path_friction": "Slider.pulley_mu",
        "direction_asymmetry": "Stator.asym_b",
        "thermal_drift": "Stator.df_dT_l_Hz_per_K, Stator.df_dT_b_Hz_per_K, Stator.thermal_tau_s",
        "thermal_drift_T": "Stator.df_dT_l_Hz_per_K, Stator.df_dT_b_Hz_per_K",
        "bar_waviness": "Stator.bar_wave_amp_m, Stator.bar_wave_period_m",
        "local_defect": "Stator.bar_bump_amp_m, Stator.bar_bump_center_m, Stator.bar_bump_width_m",
    }


@pytest.mark.parametrize("name", sorted(INJECTIONS))
def test_each_rig_injection_names_its_family_and_switches_on_its_home(name):
    # reference: the rig's injections before the registry carried their own regressor (time, direction, position,
    # position, load, voltage); a family with a physical home is injected through (some of) those parameters
    inj = INJECTIONS[name]
    fam = fx.family(inj.effect)
    assert inj.regressor == fam.regressor
    assert {"thermal_drift": "time", "direction_asymmetry": "direction", "bar_waviness": "position",
            "bar_bump": "position", "pulley_friction": "load", "drive_saturation": "voltage"}[name] == inj.regressor
    if fam.home:
        assert set(inj.params) & set(fam.home), (name, fam.home)


def test_the_measurement_chain_injection_has_no_family():
    assert DATA_INJECTIONS["speed_lowpass"].effect is None and DATA_INJECTIONS["speed_lowpass"].regressor == "speed"


def test_an_unknown_kind_is_refused_naming_the_known_ones():
    with pytest.raises(fx.EffectSpecError, match="unknown effect kind 'nope'; known: thermal_drift"):
        fx.effect_features({"kind": "nope"}, _signals())
