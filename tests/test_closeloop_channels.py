"""An open set of regressors (issue 28, item 2): every logged channel and the protocol's clock is a candidate.

Realistic world (Eq. 29 not exact), seed 21's clean rig data, post-processed with two extra logged columns:
``aux_relay`` (0 or 1 per run, a switch the rig logs and no document names) whose runs at 1 move 5 % faster
(speed and position scaled together about the run's start, so the position stays the integral of the speed),
and ``ambient_noise`` (pure noise: a random level per run plus white noise per sample, acting on nothing).
"""

import functools
import json

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop.loop import close_loop
from l1b2.data.measurements import load_measurements, write_measurements
from l1b2.data.metrics import report_metrics
from l1b2.ident.estimator import PredictorIdentifier
from rigcache import assert_round_trips, case_row, held_out_nrmse, rig_dir, world_plan

SEED = 21
GAIN = 0.05


def _with_channels(m, rng, effect=True):
    """The measurements with the two logged columns; runs with ``aux_relay`` 1 scaled by 1 + GAIN (if ``effect``)."""
    df = m.df.copy()
    runs = pd.unique(df["run"])
    relay = dict(zip(runs, rng.integers(0, 2, len(runs)).astype(float)))
    level = dict(zip(runs, rng.normal(0, 1, len(runs))))
    df["aux_relay"] = df["run"].map(relay).to_numpy(float)
    df["ambient_noise"] = df["run"].map(level).to_numpy(float) + rng.normal(0, 0.5, len(df))
    if effect:
        f = 1.0 + GAIN * df["aux_relay"].to_numpy()
        s0 = df.groupby("run", sort=False)["position_m"].transform("first").to_numpy()
        df["position_m"] = s0 + f * (df["position_m"].to_numpy() - s0)
        df["speed_m_s"] = f * df["speed_m_s"].to_numpy()
    return df


@functools.cache
def _data(tmp):
    d = rig_dir(f"realistic_clean_{SEED}", injection_seed=SEED, plan=world_plan("realistic", SEED), world="realistic")
    rng = np.random.default_rng(SEED)
    out = {}
    for part in ("train", "test"):
        m = load_measurements(d / f"{part}.csv")
        path = write_measurements(_with_channels(m, rng), f"{tmp}/{part}.csv", {"slider_mass_kg": m.slider_mass_kg})
        out[part] = load_measurements(path)
    tr, te = load_measurements(d / "train.csv"), load_measurements(d / "test.csv")
    return out["train"], out["test"], tr, te


def test_channel_features_are_the_generic_forms_of_the_standardised_channel():
    # reference: the forms written out: friction -z, force factor V0/300 z, force d z; z = (c - mean)/sd, c the
    # sample value or the run's mean
    from l1b2.predictor import effects as fx
    c = np.array([1.0, 3.0, 2.0, 6.0])
    run_mean = np.array([2.0, 2.0, 4.0, 4.0])
    V0, d = np.array([300.0, 150.0, 240.0, 330.0]), np.array([1.0, -1.0, 1.0, -1.0])
    x = {"V0": V0, "d": d, "col:aux": c, "run:aux": run_mean}
    spec = {"kind": "channel", "channel": "aux", "mean": 2.0, "sd": 0.5}
    z, zr = (c - 2.0) / 0.5, (run_mean - 2.0) / 0.5
    F = {(f, lv): fx.effect_features({**spec, "form": f, "level": lv}, x)[:, 0]
         for f in ("friction", "force_factor", "force") for lv in ("run", "sample")}
    np.testing.assert_allclose(F["friction", "sample"], -z)
    np.testing.assert_allclose(F["friction", "run"], -zr)
    np.testing.assert_allclose(F["force_factor", "sample"], V0 / 300.0 * z)
    np.testing.assert_allclose(F["force", "run"], d * zr)
    assert fx.needs({**spec, "form": "force", "level": "run"}) == {"V0", "d", "run:aux"}


def test_quadratic_channel_shape_is_the_clipped_z_and_its_square_minus_one():
    # reference: the quadratic shape written out: zc = z clipped to TRAIN's range [(lo - mean)/sd, (hi - mean)/sd],
    # columns (zc, zc^2 - 1) times the form's factor; the per-sample kernel of Predictor.fmu gives the same force,
    # also for a value beyond TRAIN's range (flat there)
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import kernels as ek
    c = np.array([1.0, 3.0, 2.0, 9.0])                  # 9 lies beyond TRAIN's hi = 6
    V0, d, T = np.array([300.0, 150.0, 240.0, 330.0]), np.array([1.0, -1.0, 1.0, -1.0]), c
    spec = {"kind": "channel", "channel": "temperature_C", "mean": 2.0, "sd": 0.5, "lo": 1.0, "hi": 6.0,
            "shape": "quadratic", "level": "sample"}
    zc = np.clip((c - 2.0) / 0.5, -2.0, 8.0)
    np.testing.assert_allclose(zc, [-2.0, 2.0, 0.0, 8.0])
    x = {"V0": V0, "d": d, "T": T, "col:temperature_C": c, "s": np.zeros(4), "load": np.zeros(4),
         "t": np.zeros(4), "v_base": np.zeros(4), "a_base": np.zeros(4)}
    want = {"friction": -np.column_stack([zc, zc ** 2 - 1]),
            "force_factor": (V0 / 300.0)[:, None] * np.column_stack([zc, zc ** 2 - 1]),
            "force": d[:, None] * np.column_stack([zc, zc ** 2 - 1])}
    phi = np.array([0.7, -0.3])
    rows = np.column_stack([x[sg] if sg in x else np.zeros(4) for sg in fx.SIGNALS])
    for form, F in want.items():
        s = {**spec, "form": form}
        np.testing.assert_allclose(fx.effect_features(s, x), F)
        kind, q = ek.spec_scalars(s)
        got = [ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows]
        np.testing.assert_allclose(got, F @ phi, rtol=0, atol=1e-12)
    # the linear shape keeps its one column and its four kernel scalars
    lin = {k: v for k, v in spec.items() if k != "shape"} | {"form": "friction"}
    np.testing.assert_allclose(fx.effect_features(lin, x)[:, 0], -(c - 2.0) / 0.5)
    assert len(ek.spec_scalars(lin)[1]) == 4


def test_odd_channel_shape_is_the_clipped_z_and_its_third_hermite_polynomial():
    # reference: the odd shape written out: zc = z clipped to TRAIN's range [(lo - mean)/sd, (hi - mean)/sd],
    # columns (zc, zc^3 - 3 zc) times the form's factor; the kernel of Predictor.fmu gives the same force,
    # also beyond TRAIN's range (9 -> flat at hi = 6)
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import kernels as ek
    c = np.array([1.0, 3.0, 2.5, 9.0, 0.0])
    V0, d = np.array([300.0, 150.0, 240.0, 330.0, 210.0]), np.array([1.0, -1.0, 1.0, -1.0, 1.0])
    spec = {"kind": "channel", "channel": "temperature_C", "mean": 2.0, "sd": 0.5, "lo": 1.0, "hi": 6.0,
            "shape": "odd", "level": "sample"}
    zc = np.array([-2.0, 2.0, 1.0, 8.0, -2.0])          # (c - 2)/0.5 clipped to [-2, 8]
    H = np.column_stack([zc, zc * zc * zc - 3.0 * zc])
    np.testing.assert_allclose(H[:, 1], [-2.0, 2.0, -2.0, 488.0, -2.0])
    x = {"V0": V0, "d": d, "T": c, "col:temperature_C": c}
    rows = np.column_stack([x[sg] if sg in x else np.zeros(5) for sg in fx.SIGNALS])
    phi = np.array([0.7, 0.05])
    for form, factor in (("friction", -np.ones(5)), ("force_factor", V0 / 300.0), ("force", d)):
        s = {**spec, "form": form}
        F = factor[:, None] * H
        np.testing.assert_allclose(fx.effect_features(s, x), F)
        kind, q = ek.spec_scalars(s)
        got = [ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows]
        np.testing.assert_allclose(got, F @ phi, rtol=0, atol=1e-12)
    assert fx.family("channel").width(spec) == 2


def test_a_channel_effect_growing_with_the_load_is_the_form_times_one_and_the_load_size():
    # reference: the interaction written out: the form's columns F = factor * shape(z), then F * |m| / load_abs
    # (the load's size, either sign of m; not V0, not the signed load); the kernel gives the same force
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import kernels as ek
    c = np.array([1.0, 3.0, 2.5, 9.0, 0.0, 2.0])
    m = np.array([0.1, -0.2, 0.0, 0.3, -0.05, 0.2])
    V0, d = np.array([300.0, 150.0, 240.0, 330.0, 210.0, 280.0]), np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    x = {"V0": V0, "d": d, "T": c, "load": m, "col:temperature_C": c, "run:temperature_C": c}
    rows = np.column_stack([x[sg] if sg in x else np.zeros(6) for sg in fx.SIGNALS])
    u = np.abs(m) / 0.4
    z = (c - 2.0) / 0.5
    zc = np.clip(z, -2.0, 8.0)
    shapes = {"linear": z[:, None], "quadratic": np.column_stack([zc, zc * zc - 1.0])}
    for shape, B in shapes.items():
        for form, factor in (("friction", -np.ones(6)), ("force_factor", V0 / 300.0), ("force", d)):
            s = {"kind": "channel", "channel": "temperature_C", "mean": 2.0, "sd": 0.5, "lo": 1.0, "hi": 6.0,
                 "shape": shape, "level": "sample", "form": form, "by": "load", "load_abs": 0.4, "run_spread": 0.0}
            F = factor[:, None] * B
            want = np.hstack([F, F * u[:, None]])
            np.testing.assert_allclose(fx.effect_features(s, x), want)
            phi = np.linspace(-0.8, 0.9, want.shape[1])
            kind, q = ek.spec_scalars(s)
            got = [ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows]
            np.testing.assert_allclose(got, want @ phi, rtol=0, atol=1e-12)
            assert "load" in fx.needs(s) and fx.family("channel").width(s) == want.shape[1]


def test_a_channel_gets_every_shape_and_the_load_interaction_with_its_training_range():
    from l1b2.closeloop.candidates import channels_of
    from l1b2.predictor import effects as fx
    df = pd.DataFrame({"time_s": [0.0, 0.1, 5.0, 5.1], "run": [1, 1, 2, 2], "position_m": 0.0, "voltage_V": 200.0,
                       "direction": 1, "load_kg": [0.1, 0.1, -0.2, -0.2], "speed_m_s": 0.1,
                       "aux": [1.0, 1.0, 3.0, 3.0]})
    ch = {c["name"]: c for c in channels_of(df)}
    assert (ch["aux"]["lo"], ch["aux"]["hi"]) == (1.0, 3.0)
    train = fx.TrainingSummary(0.1, (0.0, 5.1), (-0.02, 0.02), 200.0, {"load_abs": 0.2},
                               channels=tuple(ch.values()))
    hyps = [h for h in fx.family("channel").grid(train) if h.spec["channel"] == "aux"]
    # constant within runs: the run level only, 3 forms x (3 shapes + the linear and quadratic x load), the
    # inertia form in the 3 shapes (no load interaction), with TRAIN's slider mass, and the damping form in the
    # linear and quadratic shapes (no load interaction)
    assert sorted((h.spec["form"], h.spec.get("shape", "linear"), h.spec.get("by", "")) for h in hyps) == sorted(
        [(f, s, b) for f in ("friction", "force_factor", "force")
         for s, b in (("linear", ""), ("quadratic", ""), ("odd", ""), ("linear", "load"), ("quadratic", "load"))]
        + [("inertia", s, "") for s in ("linear", "quadratic", "odd")]
        + [("damping", s, "") for s in ("linear", "quadratic")])
    for h in hyps:
        assert (h.spec.get("m_s") == 0.1) == (h.spec["form"] == "inertia")
        assert set(h.units) == {"1" if h.spec["form"] == "inertia" else "N"}
        assert ("v_base" in fx.needs(h.spec)) == (h.spec["form"] == "damping")
        n = {"linear": 1, "quadratic": 2, "odd": 2}[h.spec.get("shape", "linear")]
        # the inertia form has its constant too: the mass change at the channel's mean
        assert len(h.names) == n * (2 if h.spec.get("by") else 1) + (h.spec["form"] == "inertia")
        if h.spec.get("shape", "linear") != "linear":
            assert (h.spec["lo"], h.spec["hi"]) == (1.0, 3.0)
        if h.spec.get("by"):
            assert h.spec["load_abs"] == 0.2 and h.regressor == "aux" and tuple(h.also) == ("load",)
    assert {h.family for h in hyps} == {"channel_aux"}   # one family for the significance correction
    # every parameter of the family has a name of its own (Predictor.fmu declares them as variables)
    names = [n for h in hyps for n in h.names]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)
    # the session clock: the linear shape only (its curvature is the generic time spline's), both levels,
    # no interaction (the generic time x load terms are its)
    clock = [h for h in fx.family("channel").grid(train) if h.spec["channel"] == "time_s"]
    assert ch["time_s"]["lo"] == 0.0 and len(clock) == 6
    assert all(h.spec.get("shape", "linear") == "linear" and len(h.names) == 1 and not h.spec.get("by")
               for h in clock)


def test_inertia_channel_form_is_the_channel_times_the_baseline_acceleration():
    # reference: the inertia form written out: the moving mass scaled by the channel, dF = -m_s d a_base times the
    # shape's columns (z, or zc and its Hermite polynomial; zc clipped to TRAIN's range) and a constant column (the
    # mass change at the channel's mean), a_base the baseline's predicted acceleration; the kernel of Predictor.fmu
    # gives the same force
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import kernels as ek
    c = np.array([1.0, 3.0, 2.5, 9.0, 0.0])                 # 9 and 0 lie beyond TRAIN's range 1-6
    V0, d = np.array([300.0, 150.0, 240.0, 330.0, 210.0]), np.array([1.0, -1.0, 1.0, -1.0, 1.0])
    a_base = np.array([2.0, -0.5, 0.0, 1.5, -3.0])
    m_s = 0.12
    x = {"V0": V0, "d": d, "T": c, "a_base": a_base, "col:temperature_C": c, "run:temperature_C": c}
    rows = np.column_stack([x[sg] if sg in x else np.zeros(5) for sg in fx.SIGNALS])
    z = (c - 2.0) / 0.5
    zc = np.array([-2.0, 2.0, 1.0, 8.0, -2.0])
    shapes = {"linear": z[:, None], "quadratic": np.column_stack([zc, zc * zc - 1.0]),
              "odd": np.column_stack([zc, zc * zc * zc - 3.0 * zc])}
    for shape, B in shapes.items():
        for level in ("sample", "run"):
            s = {"kind": "channel", "channel": "temperature_C", "mean": 2.0, "sd": 0.5, "lo": 1.0, "hi": 6.0,
                 "shape": shape, "level": level, "form": "inertia", "m_s": m_s, "run_spread": 0.0}
            want = (-m_s * d * a_base)[:, None] * np.column_stack([B, np.ones(5)])
            np.testing.assert_allclose(fx.effect_features(s, x), want)
            phi = np.linspace(0.4, -0.3, B.shape[1] + 1)
            kind, q = ek.spec_scalars(s)
            got = [ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows]
            np.testing.assert_allclose(got, want @ phi, rtol=0, atol=1e-12)
            assert "a_base" in fx.needs(s) and fx.family("channel").width(s) == B.shape[1] + 1
    # the linear shape is inertia_mismatch's constant mass error times z (a relative mass change per sd), then
    # inertia_mismatch's own column (the mass change at the channel's mean)
    lin = {"kind": "channel", "channel": "temperature_C", "mean": 2.0, "sd": 0.5, "level": "sample",
           "form": "inertia", "m_s": m_s}
    mis = fx.effect_features({"kind": "inertia_mismatch", "m_s": m_s}, x)[:, 0]
    np.testing.assert_allclose(fx.effect_features(lin, x), np.column_stack([mis * z, mis]))
    with pytest.raises(fx.EffectSpecError, match="m_s"):
        fx.effect_features({**lin, "m_s": 0.0}, x)


def test_a_payload_whose_mean_is_not_zero_is_recovered_by_the_inertia_form_with_its_constant():
    # reference: a payload m_p bolted on between runs (0.06, 0.12 or 0.18 kg, never 0 in TRAIN) adds the force
    # -m_p d a (drive coordinates) to a model whose mass is the slider's m_s; least squares of that force on the
    # form's columns recovers a = sd(m_p)/m_s per standard deviation and a_0 = mean(m_p)/m_s at the mean, exactly
    # (the force is in the columns' span); without the constant column (the channel centred on its TRAIN mean, as
    # the other forms) the mean's mass change is left over: more than half of the force's sum of squares here
    from l1b2.predictor import effects as fx
    rng = np.random.default_rng(3)
    m_s, n_runs, n = 0.12, 12, 40
    m_p = np.repeat(rng.choice([0.06, 0.12, 0.18], n_runs), n)
    d = np.repeat(np.where(np.arange(n_runs) % 2 == 0, 1.0, -1.0), n)
    tk = np.tile(np.arange(n) * 1e-3, n_runs)
    a_base = d * 4.0 * np.exp(-tk / 0.024)                   # a start transient of time constant 24 ms
    c = 1000.0 * m_p                                         # the logged payload [g]
    mean, sd = float(np.mean(c)), float(np.std(c))
    x = {"V0": np.full(len(c), 250.0), "d": d, "a_base": a_base, "run:payload_g": c}
    spec = {"kind": "channel", "channel": "payload_g", "mean": mean, "sd": sd, "level": "run", "form": "inertia",
            "m_s": m_s, "run_spread": 0.0}
    X = fx.effect_features(spec, x)
    force = -m_p * d * a_base
    coef, *_ = np.linalg.lstsq(X, force, rcond=None)
    np.testing.assert_allclose(coef, [sd / 1000.0 / m_s, mean / 1000.0 / m_s], rtol=1e-9)
    centred = X[:, :1]
    left = force - centred @ np.linalg.lstsq(centred, force, rcond=None)[0]
    assert float(left @ left) > 0.5 * float(force @ force)


def test_damping_channel_form_is_the_channel_times_the_baseline_speed():
    # reference: the damping form written out: the viscous damping scaled by the channel, dF = -d v_base / 0.2 m/s
    # times the shape's columns (z, or zc and zc^2 - 1; zc clipped to TRAIN's range), v_base the baseline's predicted
    # speed (signed: the force opposes the motion in either direction); the kernel of Predictor.fmu gives the same
    # force; the linear shape is speed_dependent_friction's linear column times z
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import kernels as ek
    c = np.array([1.0, 3.0, 2.5, 9.0, 0.0, 4.0])           # 9 and 0 lie beyond TRAIN's range 1-6
    V0, d = np.array([300.0, 150.0, 240.0, 330.0, 210.0, 280.0]), np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    v_base = np.array([0.12, -0.05, 0.0, 0.3, -0.02, 0.08])   # the last moves against its drive direction
    x = {"V0": V0, "d": d, "T": c, "v_base": v_base, "a_base": np.full(6, 3.0), "col:temperature_C": c,
         "run:temperature_C": c}
    rows = np.column_stack([x[sg] if sg in x else np.zeros(6) for sg in fx.SIGNALS])
    z = (c - 2.0) / 0.5
    zc = np.array([-2.0, 2.0, 1.0, 8.0, -2.0, 4.0])
    speed = np.array([0.6, 0.25, 0.0, -1.5, -0.1, -0.4])    # d v_base / 0.2
    shapes = {"linear": z[:, None], "quadratic": np.column_stack([zc, zc * zc - 1.0])}
    for shape, B in shapes.items():
        for level in ("sample", "run"):
            s = {"kind": "channel", "channel": "temperature_C", "mean": 2.0, "sd": 0.5, "lo": 1.0, "hi": 6.0,
                 "shape": shape, "level": level, "form": "damping", "run_spread": 0.0}
            want = -speed[:, None] * B
            np.testing.assert_allclose(fx.effect_features(s, x), want)
            phi = np.linspace(0.6, -0.2, B.shape[1])
            kind, q = ek.spec_scalars(s)
            got = [ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows]
            np.testing.assert_allclose(got, want @ phi, rtol=0, atol=1e-12)
            assert "v_base" in fx.needs(s) and "a_base" not in fx.needs(s)
            assert fx.family("channel").width(s) == B.shape[1]
    lin = {"kind": "channel", "channel": "temperature_C", "mean": 2.0, "sd": 0.5, "level": "sample",
           "form": "damping"}
    drag = fx.effect_features({"kind": "speed_dependent_friction"}, x)[:, 0]
    np.testing.assert_allclose(fx.effect_features(lin, x)[:, 0], drag * z)
    # a positive parameter brakes: the force opposes the motion (drive coordinates) wherever z > 0
    F = fx.effect_features(lin, x)[:, 0] * 1.0
    assert np.all(F[z > 0] * (d * v_base)[z > 0] <= 0)


def test_the_linear_damping_form_is_bounded_so_the_total_damping_stays_non_negative_over_trains_range():
    # reference, written out: TRAIN's channel has mean 2, sd 0.5, range 1..6, so z runs over [-2, 8]; the baseline's
    # smallest viscous damping D = 6 N s/m; the form's damping coefficient is a z / 0.2 m/s, and D + a z / 0.2 >= 0
    # over [-2, 8] is -6 * 0.2 / 8 = -0.15 <= a <= 6 * 0.2 / 2 = 0.6 N; at either bound the total damping is 0 at one
    # end of the range. The quadratic shape (two parameters) gets no box; a baseline without a positive damping none
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import channels as ch_mod
    ch = {"name": "coil_A", "kind": "logged", "mean": 2.0, "sd": 0.5, "lo": 1.0, "hi": 6.0, "within_run": False,
          "run_spread": 0.0}

    def grid(damping):
        train = fx.TrainingSummary(m_s=0.1, time_range=(0.0, 10.0), position_range=(-0.02, 0.02),
                                   voltage_median=250.0, ranges={"load_abs": 0.0}, channels=(ch,),
                                   damping_N_s_per_m=damping)
        return {h.shape: h for h in fx.family("channel").grid(train)
                if h.spec.get("channel") == "coil_A" and h.spec["form"] == "damping"}

    hs = grid(6.0)
    assert set(hs) == {"damping, run", "damping, run, quadratic"}
    (lo, hi), = hs["damping, run"].bounds
    np.testing.assert_allclose([lo, hi], [-0.15, 0.6], rtol=1e-12)
    for a, z_edge in ((lo, 8.0), (hi, -2.0)):
        np.testing.assert_allclose(6.0 + a * z_edge / 0.2, 0.0, atol=1e-12)
    assert hs["damping, run, quadratic"].bounds == ()
    assert grid(None)["damping, run"].bounds == () and grid(-1.0)["damping, run"].bounds == ()
    # the other forms stay unbounded, and no spec carries the damping
    hyps = fx.family("channel").grid(fx.TrainingSummary(
        m_s=0.1, time_range=(0.0, 10.0), position_range=(-0.02, 0.02), voltage_median=250.0,
        ranges={"load_abs": 0.0}, channels=(ch,), damping_N_s_per_m=6.0))
    assert all(h.bounds == () for h in hyps if h.spec["form"] != "damping")
    assert not any("damping_N_s_per_m" in h.spec or "damping" in h.spec for h in hyps)
    assert ch_mod.damping_bounds({"mean": 2.0, "sd": 0.5}, 1.0, 6.0, 6.0) == ((lo, hi),)


def test_the_damping_floor_is_the_smallest_total_damping_over_trains_range_of_the_channel():
    # reference, written out (mean 2, sd 0.5, range 1..6: z and zc in [-2, 8]; D the baseline's damping [N s/m]):
    # linear a = 0.3: 6 + min(0.3 * -2, 0.3 * 8) / 0.2 = 3; quadratic (a, b) = (0.2, 0.1): g = a zc + b (zc^2 - 1) is
    # -0.1 at -2, 7.9 at 8 and -0.2 at its vertex zc = -1, so 6 - 0.2 / 0.2 = 5 (and 0.5 - 1 = -0.5 with D = 0.5);
    # (0, -0.1): g(8) = -6.3, so 6 - 31.5 = -25.5; every value also against a dense grid of zc
    from l1b2.predictor.effects.channels import damping_floor
    base = {"kind": "channel", "channel": "coil_A", "form": "damping", "level": "run", "mean": 2.0, "sd": 0.5}
    quad = {**base, "shape": "quadratic", "lo": 1.0, "hi": 6.0}
    cases = [(base, [0.3], 6.0, 3.0), (base, [-0.3], 6.0, 6.0 - 2.4 / 0.2), (quad, [0.2, 0.1], 6.0, 5.0),
             (quad, [0.2, 0.1], 0.5, -0.5), (quad, [0.0, -0.1], 6.0, -25.5), (quad, [3.0, 0.1], 6.0, 6.0 - 5.7 / 0.2)]
    zz = np.linspace(-2.0, 8.0, 100001)
    for spec, phi, D, want in cases:
        got = damping_floor(spec, phi, 1.0, 6.0, D)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
        cols = zz[:, None] if len(phi) == 1 else np.column_stack([zz, zz * zz - 1.0])
        np.testing.assert_allclose(got, D + np.min(cols @ np.asarray(phi)) / 0.2, atol=1e-6)


def test_the_baselines_viscous_damping_is_c_r_plus_the_drive_forces_speed_slope():
    # reference, written out: Eq. 29's F = -(c_r + sigma (0.5 - A'(s))) v' + ...: D(s) = c_r + sigma (0.5 - A'(s)),
    # A' the Legendre series of alpha at (s - s_center) / s_half; with a contact half angle a, 0.5 -> a / pi;
    # baseline_damping is its smallest value over the masked samples
    from types import SimpleNamespace

    from l1b2.closeloop.candidates import baseline_damping
    from l1b2.predictor.model import example_params, force_parts, viscous_damping
    prm = example_params()
    s = np.linspace(-0.02, 0.02, 41)
    Ap = np.polynomial.legendre.legval(s / 0.02, prm.alpha)
    np.testing.assert_allclose(viscous_damping(prm, s), 6.0 + 0.2 * (0.5 - Ap), rtol=1e-14)
    a = np.full(41, 1.2)
    np.testing.assert_allclose(viscous_damping(prm, s, a), 6.0 + 0.2 * (1.2 / np.pi - Ap), rtol=1e-14)
    np.testing.assert_allclose(force_parts(prm, s, np.full(41, 250.0), 0.0, 0.1)[0], viscous_damping(prm, s))
    df = pd.DataFrame({"position_m": s, "voltage_V": 250.0})
    mask = s > 0.0
    model = SimpleNamespace(params_=prm, result_=SimpleNamespace(frequency_response=None))
    np.testing.assert_allclose(baseline_damping(model, df, mask), np.min((6.0 + 0.2 * (0.5 - Ap))[mask]))


def test_a_refit_whose_damping_form_turns_the_total_damping_negative_is_refused():
    # reference, written out: the model's own smallest damping D (baseline_damping, about 6 N s/m); a linear damping
    # form of a = 0.3 N over z in [-2, 8] takes at most 0.3 * 2 / 0.2 = 3 N s/m off (kept), a = 2 N takes 20 off
    # (refused: the pick is not added and the record says why); a candidate of another form has no floor
    from types import SimpleNamespace

    from l1b2.closeloop.acceptance import EffectSet
    from l1b2.closeloop.candidates import CandidateForce, baseline_damping, damping_floors
    from l1b2.closeloop.loop import CloseLoop
    from l1b2.predictor.model import example_params
    s = np.linspace(-0.02, 0.02, 41)
    df = pd.DataFrame({"position_m": s, "voltage_V": 250.0})
    mask = np.ones(41, bool)
    model = SimpleNamespace(params_=example_params(), result_=SimpleNamespace(frequency_response=None))
    D = baseline_damping(model, df, mask)
    spec = {"kind": "channel", "channel": "coil_A", "form": "damping", "level": "run", "mean": 2.0, "sd": 0.5}
    c = CandidateForce("channel_coil_A", "coil_A", "damping, run", ("coil_A_damping_run",), ("N",),
                       lambda d: np.zeros((len(d), 1)), spec=spec)
    chans = ({"name": "coil_A", "lo": 1.0, "hi": 6.0},)
    msgs = []
    # and either side of the edge: a floor of +0.05 N s/m is kept, one of -0.05 refused
    for a, refused in ((0.3, False), (2.0, True), ((D - 0.05) * 0.1, False), ((D + 0.05) * 0.1, True)):
        eff = EffectSet().add(c, [a])
        floors = damping_floors(eff, model, df, mask, chans)
        np.testing.assert_allclose(floors[c.label], D - 2.0 * a / 0.2, rtol=1e-12)
        it = SimpleNamespace(ranges=[], channels=chans)
        got = CloseLoop._refused_range(it, eff, model, df, mask, 3, SimpleNamespace(candidate=c), msgs.append)
        assert got is refused
        assert it.ranges[0]["outcome"].startswith("refused" if refused else "kept")
    assert len(msgs) == 2 and all("refused" in m for m in msgs)
    other = CandidateForce("smooth_time", "time", "", ("b",), ("N",), lambda d: np.zeros((len(d), 1)),
                           spec={"kind": "smooth_time"})
    assert damping_floors(EffectSet().add(other, [1.0]), model, df, mask, chans) == {}


def test_a_channel_that_scales_the_damping_is_recovered_by_the_damping_form_not_the_friction_form():
    # reference: data made from the law written out, a damping coefficient c_0 (1 + k z) changed by a logged channel
    # (z its standardised run value), over runs whose speeds differ (V0 and load); the excess force on the baseline
    # (damping c_0) is -c_0 k z d v; least squares on the damping form recovers a = c_0 k 0.2 m/s [N per sd]; the
    # friction form (the same channel's level, no speed) explains far less of it
    from l1b2.predictor import effects as fx
    rng = np.random.default_rng(3)
    n_runs, n = 24, 50
    z_run = rng.normal(0.0, 1.0, n_runs)
    d_run = np.where(np.arange(n_runs) % 2 == 0, 1.0, -1.0)
    speed_run = rng.uniform(0.02, 0.25, n_runs)            # |v| per run [m/s]
    ramp = 1.0 - np.exp(-np.linspace(0.0, 5.0, n))          # each run's start transient
    z = np.repeat(z_run, n)
    d = np.repeat(d_run, n)
    v_base = d * np.repeat(speed_run, n) * np.tile(ramp, n_runs)
    c_0, k = 4.0, 0.15                                      # N s/m and its change per standard deviation
    dF = -c_0 * k * z * d * v_base + rng.normal(0.0, 0.002, len(z))
    c = 1.5 + 0.4 * z                                        # the logged channel: mean 1.5, sd 0.4
    x = {"V0": np.full(len(z), 300.0), "d": d, "v_base": v_base, "col:aux": c, "run:aux": c}
    spec = {"kind": "channel", "channel": "aux", "mean": 1.5, "sd": 0.4, "level": "run"}
    fits = {}
    for form in ("damping", "friction"):
        X = fx.effect_features({**spec, "form": form}, x)
        phi, *_ = np.linalg.lstsq(X, dF, rcond=None)
        fits[form] = (phi, float(np.sum((dF - X @ phi) ** 2)))
    np.testing.assert_allclose(fits["damping"][0], [c_0 * k * 0.2], rtol=0.01)
    sse0 = float(np.sum(dF ** 2))
    assert fits["damping"][1] < 0.01 * sse0, fits
    assert fits["friction"][1] > 0.1 * sse0, fits
    assert fits["friction"][1] > 30 * fits["damping"][1], fits


def test_the_free_run_evaluates_the_damping_form_at_the_baselines_free_run_speed():
    # reference: an independent family that reads the same signal, speed_dependent_friction (-d v_base / 0.2 m/s
    # times its first parameter): with the channel (the stator temperature, an input of the free run and of
    # Predictor.fmu) held at z = 2, a damping-form effect of parameter a moves the free run exactly as the drag of
    # parameters (2 a, 0); both are evaluated at the baseline's free run of the same inputs, which the predictor runs
    from l1b2.physics.params import load_motor
    from l1b2.predictor import effects as fx
    from l1b2.predictor.derive import derive_predictor
    from l1b2.predictor.setup import PredictorSetup
    mp = load_motor()
    pp = derive_predictor(mp, n_grid=9)
    base = PredictorSetup(pp, mp.slider.mass_kg, 1e-3)
    model = PredictorSetup(type(pp).from_vector(pp.to_vector() * 1.03, s_center=pp.s_center, s_half=pp.s_half,
                                                kappa=pp.kappa, include_load_inertia=pp.include_load_inertia),
                           mp.slider.mass_kg, 1e-3)
    n = 400
    t = 5.0 + np.arange(2 * n) * 1e-3
    d = np.repeat([1.0, -1.0], n)
    s = np.concatenate([-0.01 + 0.2 * (t[:n] - 5.0), 0.01 - 0.2 * (t[n:] - t[n])])
    V0, load, run = np.repeat([324.0, 250.0], n), np.repeat([0.03, -0.02], n), np.repeat([0, 1], n)
    T = np.full(2 * n, 35.0)                                  # (35 - 31) / 2 = 2 standard deviations
    spec = {"kind": "channel", "channel": "temperature_C", "form": "damping", "level": "sample", "mean": 31.0,
            "sd": 2.0}
    a = 0.4

    def run_with(effects):
        ep = fx.ExtendedPredictor(base, model, effects)
        return ep.free_run(t, s, V0, load, d, [0.0, 0.0], run, temperature=T)
    damped = run_with((fx.IdentifiedEffect("channel_temperature_C", "damping", spec, ("a",), ("N",), (a,),
                                           (0.01,)),))
    drag = run_with((fx.IdentifiedEffect("speed_dependent_friction", "drag", {"kind": "speed_dependent_friction"},
                                         ("l", "q"), ("N", "N"), (2 * a, 0.0), (0.01, 0.01)),))
    np.testing.assert_allclose(damped, drag, rtol=0, atol=1e-12)
    plain = run_with(())
    assert np.max(np.abs(damped - plain)) > 1e-4              # not vacuous: the effect moves the speed
    # a positive parameter brakes (drive coordinates): the slider is slower in both runs
    tail = np.r_[n // 2:n, n + n // 2:2 * n]
    assert np.all(d[tail] * (damped[tail] - plain[tail]) < 0)


def test_every_numeric_column_beyond_the_required_ones_is_a_channel():
    from l1b2.closeloop.candidates import channels_of, signals
    df = pd.DataFrame({"time_s": [0.0, 0.1, 5.0, 5.1], "run": [1, 1, 2, 2], "position_m": 0.0, "voltage_V": 200.0,
                       "direction": 1, "load_kg": 0.0, "speed_m_s": 0.1, "frequency_Hz": 48500.0,
                       "aux": [1.0, 1.0, 3.0, 3.0], "note": ["a", "b", "c", "d"], "tip_velocity_amp_m_s": 1.0})
    ch = {c["name"]: c for c in channels_of(df)}
    assert list(ch) == ["frequency_Hz", "aux", "tip_velocity_amp_m_s", "time_s"]  # not text nor the required ones
    assert ch["tip_velocity_amp_m_s"]["kind"] == "response"
    assert ch["frequency_Hz"]["sd"] == 0 and ch["aux"]["sd"] == pytest.approx(1.0)
    assert not ch["aux"]["within_run"] and ch["time_s"]["within_run"] and ch["time_s"]["kind"] == "protocol"
    x = signals(df, None, {"run:time_s", "col:aux"})
    np.testing.assert_allclose(x["run:time_s"], [0.05, 0.05, 5.05, 5.05])
    np.testing.assert_allclose(x["col:aux"], [1, 1, 3, 3])


@pytest.mark.slow
@pytest.mark.ci_slow    # decision 0080
def test_an_effect_through_a_logged_channel_is_traced_and_a_noise_channel_is_not_added(tmp_path, record_property):
    train, test, clean_tr, clean_te = _data(str(tmp_path))
    res = close_loop(train, test)
    assert_round_trips(res)
    d = res.diagnosis
    est = PredictorIdentifier(order=8, criterion="free_run", fixed="recommended", n_starts=4, seed=0,
                              noise_fit="alternate").fit(clean_tr.df, slider_mass_kg=clean_tr.slider_mass_kg,
                                                         mask=np.array(clean_tr.mask))
    b0 = report_metrics(clean_te.df, est.predict_one_step(clean_te.df), est.predict_free_run(clean_te.df))
    b0 = b0["free_run"]["nrmse"]
    record_property("case", case_row("realistic", f"aux_relay x{1 + GAIN} {SEED}", res, b0))
    considered = {c["channel"]: c for c in d["channels_considered"]}
    assert {"aux_relay", "ambient_noise", "time_s", "frequency_Hz"} <= set(considered), considered
    assert considered["frequency_Hz"]["note"].startswith("constant")
    assert considered["tip_velocity_amp_m_s"]["kind"] == "response" and not considered["tip_velocity_amp_m_s"]["added"]
    assert considered["aux_relay"]["added"] and considered["aux_relay"]["cv_gain"] > 0, json.dumps(considered)
    assert "aux_relay" in d["traced_to"][:2], (d["traced_to"], d["message"])
    assert not considered["ambient_noise"]["added"] and "ambient_noise" not in d["traced_to"]
    assert considered["ambient_noise"]["cv_gain"] is not None     # considered: scored, with its evidence
    b, a = held_out_nrmse(res)
    assert a ** 2 <= b0 ** 2 + (b ** 2 - b0 ** 2) / 4, (b0, b, a, d["message"])


def test_the_loops_context_carries_the_baselines_damping_into_the_channels_grid():
    # property: candidate_context's damping reaches TrainingSummary.damping_N_s_per_m and bounds the linear damping
    # form of a logged channel by the formula of damping_bounds (z over the channel's TRAIN range)
    from l1b2.closeloop.candidates import channels_of, group_candidates, training_summary
    from l1b2.closeloop.loop import candidate_context
    n = 40
    df = pd.DataFrame({"run": np.repeat(np.arange(4), 10), "time_s": np.arange(n) * 0.01,
                       "position_m": np.tile(np.linspace(-0.01, 0.01, 10), 4), "voltage_V": 250.0,
                       "load_kg": 0.0, "direction": 1.0, "speed_m_s": 0.1,
                       "coil_A": np.repeat([0.0, 0.5, 1.5, 2.0], 10)})
    ctx = candidate_context(lambda d: np.full(len(d), 0.1), 0.1, df, np.ones(n, bool), {}, damping=6.0)
    assert training_summary(ctx, df).damping_N_s_per_m == 6.0
    ch = next(c for c in channels_of(df) if c["name"] == "coil_A")
    lin = [c for c in group_candidates(("generic",), ctx, df)
           if c.spec.get("channel") == "coil_A" and c.spec.get("form") == "damping" and c.n_params == 1]
    assert lin and all(c.bounds == ((-6.0 * 0.2 / ((ch["hi"] - ch["mean"]) / ch["sd"]),
                                     6.0 * 0.2 / ((ch["mean"] - ch["lo"]) / ch["sd"])),) for c in lin)
    assert training_summary(candidate_context(lambda d: np.full(len(d), 0.1), 0.1, df, np.ones(n, bool), {}),
                            df).damping_N_s_per_m is None
