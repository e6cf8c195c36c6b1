"""A logged channel's inertia form with the mass inside the free run's recursion (issue 28, item 2).

The channel changes the slider's mass, ``m_s (1 + shape(z) . a + a_0)``; the free run integrates
``(m_s (1 + g) + |m|) dv/dt = F(v)`` with that mass (its inertia and its weight on the guide), and the parameters'
sensitivities are the same recursion's. The form's physical range is a positive slider mass over TRAIN's range.
"""

import dataclasses

import numpy as np
import pytest
from l1b2.predictor import simulate as sim
from l1b2.predictor.effects import channels as ch
from l1b2.predictor.model import example_params, force_parts

M_S = 0.12


def _runs(conds, n=250, dt=1e-3, v_start=0.1):
    """Flat per-sample inputs of runs ``(V0, load, direction)``: the stroke -20..20 mm in ``n`` samples, each run
    starting at ``v_start`` [m/s] in its drive direction."""
    k = np.arange(n)
    s = np.concatenate([np.where(dd > 0, -0.02 + 0.04 * k / n, 0.02 - 0.04 * k / n) for _, _, dd in conds])
    V0, load, d = (np.repeat([c[i] for c in conds], n).astype(float) for i in range(3))
    t = np.concatenate([r * 1.0 + dt * k for r in range(len(conds))])
    run = np.repeat(np.arange(len(conds)), n)
    return s, V0, load, d, t, d * v_start, run


def _spec(c, shape="linear"):
    spec = {"kind": "channel", "channel": "payload_g", "form": "inertia", "level": "run", "mean": float(np.mean(c)),
            "sd": float(np.std(c)), "m_s": M_S}
    if shape != "linear":
        spec.update(shape=shape, lo=float(np.min(c)), hi=float(np.max(c)))
    return spec


def test_the_mass_forms_slider_mass_is_m_s_times_one_plus_the_shaped_channel_and_its_linearisation_the_force():
    # reference: m = m_s (1 + a z + a_0) (linear), m_s (1 + a zc + b (zc^2 - 1) + a_0) (quadratic),
    # m_s (1 + a zc + c (zc^3 - 3 zc) + a_0) (odd), zc clipped to TRAIN's range; the force features are the same
    # columns times -m_s d a_base
    from l1b2.predictor import effects as fx
    c = np.array([1.0, 3.0, 2.5, 9.0, 0.0])
    z, zc = (c - 2.0) / 0.5, np.array([-2.0, 2.0, 1.0, 8.0, -2.0])
    d, a_base = np.array([1.0, -1.0, 1.0, -1.0, 1.0]), np.array([2.0, -0.5, 0.0, 1.5, -3.0])
    x = {"run:payload_g": c, "d": d, "a_base": a_base, "V0": np.full(5, 200.0)}
    base = {"kind": "channel", "channel": "payload_g", "form": "inertia", "level": "run", "mean": 2.0, "sd": 0.5,
            "m_s": M_S, "lo": 1.0, "hi": 6.0}
    phi = np.array([0.3, -0.05, 0.4])
    want = {"linear": M_S * (1 + 0.3 * z + (-0.05)),
            "quadratic": M_S * (1 + 0.3 * zc - 0.05 * (zc ** 2 - 1) + 0.4),
            "odd": M_S * (1 + 0.3 * zc - 0.05 * (zc ** 3 - 3 * zc) + 0.4)}
    for shape, m in want.items():
        spec = {**base, "shape": shape}
        p = phi[[0, 1]] if shape == "linear" else phi
        np.testing.assert_allclose(ch.slider_mass(spec, x, p), m, rtol=1e-14)
        np.testing.assert_allclose(fx.effect_features(spec, x),
                                   (-M_S * d * a_base)[:, None] * ch.mass_columns(spec, x), rtol=0, atol=1e-15)
    with pytest.raises(fx.EffectSpecError, match="inertia"):
        ch.mass_columns({**base, "form": "damping"}, x)
    with pytest.raises(fx.EffectSpecError, match="m_s"):
        ch.slider_mass({**base, "m_s": 0.0}, x, phi[:2])


def test_the_free_run_with_the_mass_form_equals_an_independent_integration_with_the_heavier_slider():
    # reference: per run, explicit Euler on the predictor's step of (m + |m_load|) dv'/dt = F(v'),
    # F = -D v' + X + sign(-v') Fr with Eq. 29's forces at the heavier slider's mass m = m_s (1 + a z + a_0)
    # (the payload's weight on the guide included), written out here; the payload per run 0/60/120/180 g
    p = example_params()
    conds = [(324.0, 0.0, 1.0), (300.0, -0.05, -1.0), (260.0, 0.05, 1.0), (324.0, 0.03, -1.0)]
    s, V0, load, d, t, v_start, run = _runs(conds)
    payload = np.array([0.0, 60.0, 120.0, 180.0])[run]
    spec, phi = _spec(payload), np.array([0.55, 0.9])
    m = ch.slider_mass(spec, {"run:payload_g": payload}, phi)
    np.testing.assert_allclose(np.unique(m), M_S * (1 + 0.9 + 0.55 * (np.array([0, 60, 120, 180]) - 90)
                                                    / np.std(payload)), rtol=1e-12)
    v = sim.free_run(p, s, V0, load, d, t, v_start, m, run_index=run)
    v_ms = sim.free_run(p, s, V0, load, d, t, v_start, M_S, run_index=run)
    for r in range(len(conds)):
        i = np.flatnonzero(run == r)
        D, X, Fr = force_parts(p, s[i], V0[i], d[i] * load[i], m[i])
        w = np.empty(i.size)
        w[0] = d[i[0]] * v_start[i[0]]
        for k in range(i.size - 1):
            assert w[k] != 0
            w[k + 1] = w[k] + 1e-3 / (m[i[k]] + abs(load[i[k]])) * (-D[k] * w[k] + X[k] + np.sign(-w[k]) * Fr[k])
        np.testing.assert_allclose(v[i], d[i] * w, rtol=1e-11, atol=1e-14)
        if payload[i[0]] > 0:   # the heavier slider starts slower: below the stated mass's speed early on
            early = i[1:40]
            assert np.all(np.abs(v[early]) < np.abs(v_ms[early]))


@pytest.mark.parametrize("shape", ["linear", "quadratic", "odd"])
def test_the_mass_forms_sensitivity_is_the_free_runs_derivative_in_its_parameters(shape):
    # reference: central finite differences of the free run with the slider's mass m_s (1 + cols @ phi), on runs
    # that move freely, stop (a stuck step) and reverse (a heavy load at 20 V)
    p = example_params()
    conds = [(324.0, 0.0, 1.0), (260.0, 0.05, -1.0), (100.0, 0.09, 1.0), (20.0, 0.5, 1.0)]
    s, V0, load, d, t, v_start, run = _runs(conds)
    flags = np.zeros(run.size, np.int8)
    lay = sim.RunLayout(run)
    a, e, f, z0 = sim.free_run_coefficients(p, s, V0, load, d, lay.step_dt(t), M_S)
    pk = lay.to_packed
    sim.packed_recursion(lay, pk(a), pk(e), pk(f), pk(-d), pk(z0), (d * 0.1)[lay.starts][lay.run_order], flags)
    assert (flags == sim.STEP_REVERSAL).any() and (flags == sim.STEP_STUCK).any()
    payload = np.array([0.0, 60.0, 120.0, 180.0])[run]
    x = {"run:payload_g": payload}
    spec = _spec(payload, shape)
    phi = np.array([0.4, 0.6]) if shape == "linear" else np.array([0.4, 0.1, 0.6])
    v, S = sim.mass_sensitivity(p, s, V0, load, d, t, v_start, ch.slider_mass(spec, x, phi),
                                M_S * ch.mass_columns(spec, x), run_index=run)
    np.testing.assert_array_equal(v, sim.free_run(p, s, V0, load, d, t, v_start, ch.slider_mass(spec, x, phi),
                                                  run_index=run))
    eps = 1e-6
    for j in range(phi.size):
        dp = np.zeros(phi.size)
        dp[j] = eps
        vp, vm = (sim.free_run(p, s, V0, load, d, t, v_start, ch.slider_mass(spec, x, phi + sgn * dp),
                               run_index=run) for sgn in (1, -1))
        fd = (vp - vm) / (2 * eps)
        assert np.max(np.abs(S[:, j])) > 1e-3
        np.testing.assert_allclose(S[:, j], fd, rtol=0, atol=1e-7 * np.max(np.abs(fd)))
    with pytest.raises(ValueError, match="pure-slip"):
        sim.mass_sensitivity(dataclasses.replace(p, drive_law="pure_slip"), s, V0, load, d, t, v_start, M_S,
                             np.ones((run.size, 1)), run_index=run)


def test_the_mass_floor_is_the_smallest_slider_mass_over_trains_range_of_the_channel():
    # reference: mean 2, sd 0.5, range 1..6 (z over [-2, 8]), m_s = 0.12 kg; the smallest of m_s (1 + g(z)),
    # written out per case, and a dense grid of z
    base = {"kind": "channel", "channel": "payload_g", "form": "inertia", "level": "run", "mean": 2.0, "sd": 0.5,
            "m_s": M_S}
    cases = [("linear", (0.3, 0.2), M_S * (1 - 0.6 + 0.2)),            # at z = -2
             ("linear", (-0.2, 0.5), M_S * (1 - 1.6 + 0.5)),           # at z = 8: negative, out of range
             ("quadratic", (0.2, 0.1, 0.0), M_S * (1 - 0.2)),          # the vertex zc = -1
             ("quadratic", (0.2, -0.1, 0.0), M_S * (1 + 1.6 - 6.3)),   # concave: the end z = 8
             ("odd", (-0.3, 0.1, 0.0), M_S * (1 - 0.4 * np.sqrt(2))),  # the stationary point zc = sqrt(2)
             ("odd", (0.3, 0.1, 0.1), M_S * (1 - 0.6 - 0.2 + 0.1))]    # no interior minimum: the end z = -2
    grid = np.linspace(-2.0, 8.0, 200001)
    for shape, phi, want in cases:
        spec = {**base, **({} if shape == "linear" else {"shape": shape, "lo": 1.0, "hi": 6.0})}
        got = ch.mass_floor(spec, phi, 1.0, 6.0)
        assert got == pytest.approx(want, rel=1e-12, abs=1e-15)
        dense = M_S * (1 + ch._mass_basis({**spec, "lo": 1.0, "hi": 6.0}, grid) @ np.asarray(phi))
        assert got <= dense.min() + 1e-12 and got == pytest.approx(dense.min(), abs=1e-9)
    with pytest.raises(ch.EffectSpecError, match="inertia"):
        ch.mass_floor({**base, "form": "damping"}, (0.1, 0.0), 1.0, 6.0)


def test_the_mass_forms_free_run_takes_free_runs_inputs_in_every_form():
    # reference: each run integrated alone (one run, no layout to pack across runs) and its speeds put end to
    # end; the start speed as one scalar per run, one value per run or one per sample (its first sample), the
    # extra force and the mass per sample; a start speed of another size refused by both
    p = example_params()
    conds = [(324.0, 0.0, 1.0), (260.0, 0.05, -1.0), (20.0, 0.5, 1.0)]
    s, V0, load, d, t, v_start, run = _runs(conds)
    rng = np.random.default_rng(5)
    ef = rng.normal(0.0, 0.2, run.size)
    m = M_S * (1 + 0.3 * rng.uniform(size=run.size))
    M = np.stack([np.full(run.size, M_S), M_S * rng.normal(size=run.size)], 1)
    v_start = v_start * rng.uniform(0.5, 1.5, run.size)      # only each run's first sample is its start
    alone = np.concatenate([sim.free_run(p, s[run == r], V0[run == r], load[run == r], d[run == r], t[run == r],
                                         v_start[run == r][0], m[run == r], extra_force=ef[run == r])
                            for r in range(len(conds))])
    per_run = v_start[np.r_[0, np.flatnonzero(np.diff(run)) + 1]]
    for vs in (v_start, per_run):
        v, S = sim.mass_sensitivity(p, s, V0, load, d, t, vs, m, M, run_index=run, extra_force=ef)
        np.testing.assert_allclose(v, alone, rtol=1e-14, atol=1e-16)
        np.testing.assert_array_equal(v, sim.free_run(p, s, V0, load, d, t, vs, m, run_index=run, extra_force=ef))
        assert S.shape == (run.size, 2) and np.all(np.isfinite(S))
    v1, _ = sim.mass_sensitivity(p, s, V0, load, d, t, 0.1, m, M, run_index=run, extra_force=ef)
    np.testing.assert_array_equal(v1, sim.free_run(p, s, V0, load, d, t, 0.1, m, run_index=run, extra_force=ef))
    for call in (sim.free_run, lambda *a, **k: sim.mass_sensitivity(*a, M=M, **k)):
        with pytest.raises(ValueError, match="v_start must be a scalar, one value per run or one per sample"):
            call(p, s, V0, load, d, t, np.ones(2), m, run_index=run)
