"""Slider on its guide (paper Sect. 3.4, Eq. 21-22): l1b2.physics.slider."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from l1b2.physics import slider as sld
from scipy.integrate import solve_ivp

G = 9.81


def _params(motor, **kw):
    """Reference slider with changes; wide end stops and no load-path friction unless asked."""
    base = dict(s_min_m=-1.0, s_max_m=1.0)
    if any(f.name == "pulley_mu" for f in dataclasses.fields(motor.slider)):
        base["pulley_mu"] = 0.0
    base.update(kw)
    return dataclasses.replace(motor.slider, **base)


def _run(sp, state, F_d, F_p, m_load, h, n):
    states = [state]
    for _ in range(n):
        state = sld.step(sp, state, F_d, F_p, m_load, h)
        states.append(state)
    return states


REST = sld.SliderState(0.0, 0.0, True, 0)


@pytest.mark.parametrize("h", [1e-4, 7e-4, 5e-3, 0.02])
@pytest.mark.parametrize("F_d", [0.8, -0.5])
def test_step_response_is_analytic_first_order_solution(motor, h, F_d):
    # reference: m v' + c_r v = F (no Coulomb friction): v = F/c_r (1 - e^{-c_r t/m}), s = its integral
    sp = _params(motor, mu_sd=0.0, mu_ss=0.0)
    m, c = sp.mass_kg, sp.c_r_N_s_per_m
    n = int(round(0.2 / h))
    states = _run(sp, REST, F_d, 5.6, 0.0, h, n)
    t = h * np.arange(n + 1)
    v = np.array([s.v_m_s for s in states])
    s = np.array([s.s_m for s in states])
    v_ref = F_d / c * (1 - np.exp(-c * t / m))
    s_ref = F_d / c * (t - m / c * (1 - np.exp(-c * t / m)))
    np.testing.assert_allclose(v, v_ref, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(s, s_ref, rtol=1e-9, atol=1e-15)


def test_first_order_response_without_damping(motor):
    # reference: uniform acceleration when c_r = 0
    v, ds = sld.first_order_response(0.1, 0.6, 0.0, 0.12, 0.05)
    assert float(v) == pytest.approx(0.1 + 0.6 / 0.12 * 0.05, rel=1e-14)
    assert float(ds) == pytest.approx(0.1 * 0.05 + 0.5 * 0.6 / 0.12 * 0.05 ** 2, rel=1e-14)


def _levels(sp, F_p):
    Fc = sp.mu_sd * (sp.kappa * F_p + G * sp.mass_kg)
    Fs = sp.mu_ss * (sp.kappa * F_p + G * sp.mass_kg)
    return Fc, Fs


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_coulomb_stays_stuck_below_static_friction(motor, sign):
    # reference: Eq. 22 static level mu_ss (kappa F_p + g m_s) computed here; stuck means v = 0, s fixed
    sp = _params(motor)
    F_p = 5.6
    _, Fs = _levels(sp, F_p)
    assert float(sld.guide_friction_level_N(sp, F_p, static=True)) == pytest.approx(Fs, rel=1e-14)
    for F in (0.5 * Fs, 0.999 * Fs, Fs):
        states = _run(sp, sld.SliderState(0.0, 0.003, True, 0), sign * F, F_p, 0.0, 1e-3, 50)
        assert all(s.v_m_s == 0.0 and s.s_m == 0.003 and s.stuck for s in states)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_coulomb_breaks_away_above_static_friction(motor, sign):
    # reference: once moving, m v' = F - Fc - c_r v (dynamic level): closed form written here
    sp = _params(motor)
    F_p = 5.6
    Fc, Fs = _levels(sp, F_p)
    F = sign * 1.001 * Fs
    m, c = sp.mass_kg, sp.c_r_N_s_per_m
    h, n = 2e-3, 40
    states = _run(sp, REST, F, F_p, 0.0, h, n)
    t = h * np.arange(n + 1)
    net = F - sign * Fc
    v_ref = net / c * (1 - np.exp(-c * t / m))
    np.testing.assert_allclose([s.v_m_s for s in states], v_ref, rtol=1e-9, atol=1e-15)
    assert all(not s.stuck for s in states[1:])
    assert all(math.copysign(1.0, s.v_m_s) == sign for s in states[1:])


@pytest.mark.parametrize("h", [1e-3, 0.05, 1.0])
def test_decelerating_slider_stops_exactly_without_chatter(motor, h):
    # reference: v(t) = -Fc/c + (v0 + Fc/c) e^{-c t/m}; stop time t* = m/c ln(1 + c v0/Fc),
    # stop position s* = m v0/c - Fc t*/c
    sp = _params(motor)
    F_p = 5.6
    Fc, _ = _levels(sp, F_p)
    m, c = sp.mass_kg, sp.c_r_N_s_per_m
    v0 = 0.2
    t_stop = m / c * math.log(1 + c * v0 / Fc)
    s_stop = m * v0 / c - Fc * t_stop / c
    n = int(math.ceil(2 * t_stop / h)) + 3
    states = _run(sp, sld.SliderState(v0, 0.0, False, 0), 0.0, F_p, 0.0, h, n)
    v = np.array([s.v_m_s for s in states])
    assert np.all(v >= 0.0)                      # no sign flip
    assert states[-1].v_m_s == 0.0 and states[-1].stuck
    assert states[-1].s_m == pytest.approx(s_stop, rel=1e-9)
    stopped = [k for k, s in enumerate(states) if s.v_m_s == 0.0]
    assert stopped == list(range(stopped[0], len(states)))  # once stopped, stays stopped
    t = h * np.arange(n + 1)
    moving = t < t_stop
    v_ref = -Fc / c + (v0 + Fc / c) * np.exp(-c * t[moving] / m)
    np.testing.assert_allclose(v[moving], v_ref, rtol=1e-9)


def test_reversing_force_reverses_without_chatter(motor):
    # reference: solve_ivp of Eq. 21 with sign(v) Coulomb friction, piecewise (events at v = 0)
    sp = _params(motor)
    F_p = 5.6
    Fc, Fs = _levels(sp, F_p)
    m, c = sp.mass_kg, sp.c_r_N_s_per_m
    F = -3.0 * Fs
    h, n = 1e-3, 150
    states = _run(sp, sld.SliderState(0.15, 0.0, False, 0), F, F_p, 0.0, h, n)
    v = np.array([s.v_m_s for s in states])
    # forward phase then backward phase: the speed changes sign exactly once
    signs = np.sign(v[v != 0.0])
    assert np.count_nonzero(np.diff(signs)) == 1
    # independent reference
    t_end = h * n

    def rhs(t, y, d):
        return [(F - d * Fc - c * y[0]) / m, y[0]]

    ev = lambda t, y, d: y[0]  # noqa: E731
    ev.terminal, ev.direction = True, -1
    s1 = solve_ivp(rhs, (0, t_end), [0.15, 0.0], args=(1.0,), events=ev, rtol=1e-12, atol=1e-15)
    t0 = s1.t_events[0][0]
    s2 = solve_ivp(rhs, (t0, t_end), [0.0, s1.y_events[0][0][1]], args=(-1.0,), rtol=1e-12, atol=1e-15)
    assert states[-1].v_m_s == pytest.approx(s2.y[0, -1], rel=1e-7)
    assert states[-1].s_m == pytest.approx(s2.y[1, -1], rel=1e-7)


def test_end_stop_stops_and_holds_while_pushed_leaves_when_pulled(motor):
    # reference: stroke limits - inelastic stop at s_max (v = 0, at_stop = +1), stays while pushed,
    # leaves (v < 0) as soon as the pull exceeds the static friction
    sp = _params(motor, s_min_m=-0.021, s_max_m=0.021)
    F_p = 5.6
    Fc, Fs = _levels(sp, F_p)
    states = _run(sp, sld.SliderState(0.2, 0.015, False, 0), 1.0, F_p, 0.0, 1e-3, 200)
    hit = next(k for k, s in enumerate(states) if s.at_stop == 1)
    for s in states[hit:]:
        assert s.s_m == sp.s_max_m and s.v_m_s == 0.0 and s.at_stop == 1
    assert all(s.s_m <= sp.s_max_m for s in states)
    # a pull below static friction keeps it there
    held = _run(sp, states[-1], -0.9 * Fs, F_p, 0.0, 1e-3, 20)
    assert all(s.s_m == sp.s_max_m and s.v_m_s == 0.0 for s in held)
    # a pull above static friction moves it away
    left = _run(sp, states[-1], -1.5 * Fs, F_p, 0.0, 1e-3, 20)
    assert left[-1].v_m_s < 0 and left[-1].s_m < sp.s_max_m and left[-1].at_stop == 0
    # the same at the negative end
    neg = _run(sp, sld.SliderState(-0.2, -0.015, False, 0), -1.0, F_p, 0.0, 1e-3, 200)
    assert neg[-1].s_m == sp.s_min_m and neg[-1].v_m_s == 0.0 and neg[-1].at_stop == -1
    away = _run(sp, neg[-1], +1.5 * Fs, F_p, 0.0, 1e-3, 5)
    assert away[-1].v_m_s > 0 and away[-1].s_m > sp.s_min_m


def test_end_stop_is_hit_at_the_analytic_time(motor):
    # reference: first-order motion s(t) from rest with constant force; the stop is reached when s = s_max
    sp = _params(motor, mu_sd=0.0, mu_ss=0.0, s_min_m=-0.01, s_max_m=0.01)
    m, c = sp.mass_kg, sp.c_r_N_s_per_m
    F = 1.0
    # one long step: position must be exactly s_max and v = 0
    end = sld.step(sp, sld.SliderState(0.0, 0.0, True, 0), F, 5.6, 0.0, 1.0)
    assert end.s_m == sp.s_max_m and end.v_m_s == 0.0 and end.at_stop == 1
    # a step that ends just before the analytic hitting time still moves freely
    from scipy.optimize import brentq
    s_of_t = lambda t: F / c * (t - m / c * (1 - math.exp(-c * t / m))) - sp.s_max_m  # noqa: E731
    t_hit = brentq(s_of_t, 1e-6, 1.0, xtol=1e-14)
    before = sld.step(sp, sld.SliderState(0.0, 0.0, True, 0), F, 5.6, 0.0, 0.999 * t_hit)
    assert before.at_stop == 0 and before.v_m_s > 0 and before.s_m < sp.s_max_m


@pytest.mark.parametrize("m_load", [0.03, 0.05, 0.09])
def test_load_sign_convention(motor, m_load):
    # reference: data-format.md - positive load pulls toward -position (opposes + runs), negative toward +
    sp = _params(motor, mu_sd=0.0, mu_ss=0.0)
    assert float(sld.load_force_N(m_load)) == pytest.approx(G * m_load, rel=1e-14)
    down = _run(sp, REST, 0.0, 5.6, m_load, 1e-3, 20)[-1]
    up = _run(sp, REST, 0.0, 5.6, -m_load, 1e-3, 20)[-1]
    assert down.v_m_s < 0 and down.s_m < 0
    assert up.v_m_s > 0 and up.s_m > 0
    assert up.v_m_s == pytest.approx(-down.v_m_s, rel=1e-12)
    # with a driving force the terminal speed is (F_d - g m_load)/c_r
    F_d = 1.2
    fin = _run(sp, REST, F_d, 5.6, m_load, 0.05, 40)[-1]  # 2 s = 35 time constants, 0.6 m < s_max
    assert fin.v_m_s == pytest.approx((F_d - G * m_load) / sp.c_r_N_s_per_m, rel=1e-9)


@pytest.mark.parametrize("m_load", [0.05, -0.07])
@pytest.mark.parametrize("load_inertia", [1.0, 0.0])
def test_load_inertia_adds_moving_mass(motor, m_load, load_inertia):
    # reference: analytic first-order response with m = m_s + load_inertia |m_load|
    sp = _params(motor, mu_sd=0.0, mu_ss=0.0, load_inertia=load_inertia)
    m = sp.mass_kg + load_inertia * abs(m_load)
    c = sp.c_r_N_s_per_m
    assert float(sld.moving_mass_kg(sp, m_load)) == pytest.approx(m, rel=1e-14)
    F_d = 1.5
    net = F_d - G * m_load
    h, n = 2e-3, 60
    states = _run(sp, REST, F_d, 5.6, m_load, h, n)
    t = h * np.arange(n + 1)
    np.testing.assert_allclose([s.v_m_s for s in states], net / c * (1 - np.exp(-c * t / m)), rtol=1e-9)


SCENARIOS = {
    "breakaway": (sld.SliderState(0.0, 0.0, True, 0), 0.9, 5.6, 0.03),
    "stopping": (sld.SliderState(0.25, 0.0, False, 0), 0.0, 5.6, 0.0),
    "reversing": (sld.SliderState(0.25, 0.0, False, 0), -1.6, 5.6, 0.05),
    "end_stop": (sld.SliderState(0.2, 0.01, False, 0), 1.5, 5.6, -0.05),
    "stuck": (sld.SliderState(0.0, 0.0, True, 0), 0.05, 5.6, 0.0),
}


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_result_independent_of_step_size(motor, name):
    # reference: the slider's own one-big-step result vs 1000 small steps with the same held inputs
    sp = _params(motor, s_min_m=-0.021, s_max_m=0.021)
    state, F_d, F_p, m_load = SCENARIOS[name]
    H = 0.3
    big = sld.step(sp, state, F_d, F_p, m_load, H)
    small = _run(sp, state, F_d, F_p, m_load, H / 1000, 1000)[-1]
    assert big.v_m_s == pytest.approx(small.v_m_s, rel=1e-9, abs=1e-12)
    assert big.s_m == pytest.approx(small.s_m, rel=1e-9, abs=1e-12)
    assert big.stuck == small.stuck and big.at_stop == small.at_stop


def test_acceleration_matches_eq21(motor):
    # reference: Eq. 21-22 right-hand side written here for a moving slider
    sp = _params(motor)
    v = np.array([-0.2, -0.01, 0.01, 0.2])
    F_d, F_p, m_load = 0.7, 5.6, 0.05
    Fc, _ = _levels(sp, F_p)
    expect = (F_d - G * m_load - sp.c_r_N_s_per_m * v - np.sign(v) * Fc) / (sp.mass_kg + sp.load_inertia * m_load)
    np.testing.assert_allclose(sld.acceleration_m_s2(sp, v, F_d, F_p, m_load), expect, rtol=1e-13)


def test_scalar_fast_paths_equal_vector_paths(motor):
    # reference: the same helpers called with one-element arrays (numpy code paths)
    sp = _params(motor, pulley_mu=0.05)
    one = lambda x: np.array([x])  # noqa: E731
    for m in (-0.07, 0.0, 0.05):
        assert sld.moving_mass_kg(sp, m) == pytest.approx(sld.moving_mass_kg(sp, one(m))[0], rel=1e-15)
        assert sld.load_path_friction_N(sp, m) == pytest.approx(sld.load_path_friction_N(sp, one(m))[0], rel=1e-15)
        assert sld.load_force_N(m) == pytest.approx(sld.load_force_N(one(m))[0], rel=1e-15)
    for static in (False, True):
        assert sld.guide_friction_level_N(sp, 5.6, static) == pytest.approx(
            sld.guide_friction_level_N(sp, one(5.6), static)[0], rel=1e-15)
    for v0, F, t in ((0.0, 1.2, 2e-4), (0.3, -2.0, 1e-3), (-0.1, 0.5, 0.05)):
        fast = sld.first_order_response(v0, F, sp.c_r_N_s_per_m, sp.mass_kg, t)
        vec = sld.first_order_response(one(v0), one(F), sp.c_r_N_s_per_m, sp.mass_kg, one(t))
        for a, b in zip(fast, vec):
            assert isinstance(a, float) and a == pytest.approx(b[0], rel=1e-14, abs=1e-18)


def test_compiled_event_loop_equals_the_python_one(motor):
    # the slider's event loop compiled by numba (l1b2.physics.jit) against the same function in Python, over
    # stuck, breaking away, decelerating to rest, reversing and end-stop cases; 1e-15 m/s and m absolute
    from l1b2.physics.jit import jit_status
    kern = sld.compiled_step()
    if kern is None:
        pytest.skip(f"numba kernel not available: {jit_status()}")
    sp = motor.slider
    rng = np.random.default_rng(3)
    events = set()
    for _ in range(3000):
        v = float(rng.choice([0.0, rng.uniform(-0.3, 0.3)]))
        s = float(rng.uniform(sp.s_min_m, sp.s_max_m)) if rng.random() < 0.8 else float(
            rng.choice([sp.s_min_m, sp.s_max_m]))
        args = (v, s, float(v == 0.0), float(np.sign(s) if s in (sp.s_min_m, sp.s_max_m) else 0.0),
                sp.mass_kg + rng.uniform(0.0, 0.2), rng.uniform(-4.0, 4.0), rng.uniform(0.0, 1.0),
                rng.uniform(0.0, 1.3), float(rng.choice([0.0, sp.c_r_N_s_per_m])), sp.s_min_m, sp.s_max_m,
                float(rng.choice([2e-4, 1e-3, 0.05])))
        py, jt = sld.step_floats(*args), kern(*args)
        assert np.allclose(py, jt, rtol=0.0, atol=1e-15), (args, py, jt)
        events.add((py[2], py[3]))
    assert {(1.0, 0.0), (0.0, 0.0), (1.0, 1.0), (1.0, -1.0)} <= events  # stuck, moving, at both stops


@pytest.mark.parametrize("m_load", [0.07, -0.05])
def test_step_force_levels_equal_the_helpers(motor, m_load):
    # step() writes the helpers' formulas inline (per-step cost); reference: the closed-form response with the
    # net force built from load_force_N, guide_friction_level_N, load_path_friction_N and moving_mass_kg
    sp = dataclasses.replace(motor.slider, pulley_mu=0.04)
    v0, F_d, F_p, h = 0.15, 3.0, 40.0, 2e-4
    new = sld.step(sp, sld.SliderState(v0, 0.0, False, 0), F_d, F_p, m_load, h)
    F = (F_d - float(sld.load_force_N(m_load)) - float(sld.guide_friction_level_N(sp, F_p))
         - float(sld.load_path_friction_N(sp, m_load)))
    v, ds = sld.first_order_response(v0, F, sp.c_r_N_s_per_m, float(sld.moving_mass_kg(sp, m_load)), h)
    assert new.v_m_s == pytest.approx(float(v), rel=1e-12) and new.s_m == pytest.approx(float(ds), rel=1e-12)
    assert not new.stuck and new.at_stop == 0
