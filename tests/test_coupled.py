"""The four subsystems coupled in-process (no FMUs): l1b2.cosim.engine."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from l1b2.cosim import engine
from l1b2.physics import interface as itf
from l1b2.physics import slider as sld
from l1b2.physics import stator as st
from l1b2.physics import steady

G = 9.81
F_DRIVE = 48500.0
PAPER_LOADS = [0.03, 0.05, 0.07, 0.09]


def _flat(motor):
    """Position-independent preload (straight bar) and wide end stops."""
    zero = {f"stator__{f.name}": 0.0 for f in dataclasses.fields(motor.stator)
            if f.name.startswith("bar_dev") or f.name.endswith("_amp_m")}
    return motor.replace(**zero, slider__s_min_m=-0.5, slider__s_max_m=0.5)


@pytest.fixture(scope="module")
def flat(motor):
    return _flat(motor)


@pytest.fixture(scope="module")
def flat_run(flat):
    m = engine.InProcessMotor(flat, h_s=2e-4)
    m.initialize(V_s=flat.operating.V_s_V, s0=0.0)
    res = m.run(0.4)
    return m, res


def test_in_process_motor_converges_to_steady_state(flat, flat_run):
    # reference: steady.steady_state (root of the phasor balance + Eq. 21 with dv/dt = 0)
    m, res = flat_run
    V0 = m.value("Driver.V0")
    ss = steady.steady_state(flat, m.value("Slider.s"), V0, 0.0, 1)
    assert ss.converged and not ss.stuck
    assert m.value("Slider.v") == pytest.approx(ss.v_m_s, rel=1e-6)
    assert m.value("Stator.U_l") == pytest.approx(ss.U_l_m, rel=1e-6)
    assert m.value("Stator.U_w") == pytest.approx(ss.U_w_m, rel=1e-6)
    assert m.value("Stator.delta") == pytest.approx(ss.delta_rad, abs=1e-6)
    assert m.value("Interface.F_d") == pytest.approx(ss.F_d_N, rel=1e-6)
    # it really was a transient: the slider started at rest and took several slider time constants
    # m/D (D: guide damping c_r plus the interface's speed slope) to get half-way
    v = res["Slider.v"]
    assert v[0] == 0.0
    t_half = res["time"][np.argmax(v > 0.5 * ss.v_m_s)]
    tau_min = flat.slider.mass_kg / (flat.slider.c_r_N_s_per_m + flat.interface.sigma_N_s_per_m)
    assert 0.5 * tau_min < t_half < 0.1


def test_steady_state_satisfies_the_force_balances(flat, motor):
    # reference: Eq. 21 with dv/dt = 0 (F_d - F_load - c_r v - F_g = 0) and Eq. 6-7 / 14 in phasor form,
    # evaluated here from the returned amplitudes with the interface and stator functions
    for mp, s, V0, m_load, d in [(flat, 0.0, 324.0, 0.0, 1), (motor, 0.01, 324.0, 0.05, 1),
                                 (motor, -0.012, 250.0, -0.03, -1)]:
        ss = steady.steady_state(mp, s, V0, m_load, d)
        assert ss.converged and not ss.stuck
        w = 2 * math.pi * mp.operating.f_drive_Hz
        F_p = float(st.preload_N(mp.stator, s))
        assert ss.F_p_N == pytest.approx(F_p, rel=1e-12)
        out = itf.interface_forces(ss.U_l_m, ss.U_w_m, ss.delta_rad, w, ss.v_m_s, F_p, mp.interface)
        assert out.F_d_N == pytest.approx(ss.F_d_N, rel=1e-9)
        Fc = float(sld.guide_friction_level_N(mp.slider, F_p))
        if hasattr(sld, "load_path_friction_N"):
            Fc += float(sld.load_path_friction_N(mp.slider, m_load))
        balance = out.F_d_N - G * m_load - mp.slider.c_r_N_s_per_m * ss.v_m_s - math.copysign(Fc, ss.v_m_s)
        assert abs(balance) < 1e-6 * (abs(out.F_d_N) + Fc)
        assert math.copysign(1, ss.v_m_s) == d


def test_steady_state_phasors_solve_the_modal_equations(motor):
    # reference: Z Q + eta F1 = F for both modes (Eq. 6-7 with Eq. 14 feedback), rebuilt here
    mp, s, V0 = motor, 0.005, 324.0
    ss = steady.steady_state(mp, s, V0, 0.0, 1)
    w = 2 * math.pi * mp.operating.f_drive_Hz
    P = float(st.axial_force_N(mp.stator, s))
    props = st.modal_properties(mp.stator, P)
    F_l, F_b = st.excitation_phasors(mp.stator, V0, 1)
    out = itf.interface_forces(ss.U_l_m, ss.U_w_m, ss.delta_rad, w, ss.v_m_s, ss.F_p_N, mp.interface)
    eta_T = float(props.eta_T)
    # modal amplitudes and phases: choose the normal-displacement frame (phase_l) from the L1 equation
    Z_l = st.dynamic_stiffness(w, props.M_l, props.K_l, props.C_l)
    Z_b = st.dynamic_stiffness(w, props.M_b, props.K_b, props.C_b)
    # unknown absolute phase p of the normal displacement: Q_l = U_l e^{jp}, Q_b = U_w/eta_T e^{j(p+delta)}
    # L1: Z_l U_l e^{jp} + (F_N1_sin + j F_N1_cos) e^{jp} = F_l  ->  e^{jp} = F_l / (Z_l U_l + F_N1)
    F_N1 = out.F_N1_sin_N + 1j * out.F_N1_cos_N
    F_T1 = out.F_T1_sin_N + 1j * out.F_T1_cos_N
    e = F_l / (Z_l * ss.U_l_m + st.ETA_N * F_N1)
    assert abs(e) == pytest.approx(1.0, rel=1e-6)
    resid_b = Z_b * (ss.U_w_m / eta_T) * e * np.exp(1j * ss.delta_rad) + eta_T * F_T1 * e - F_b
    assert abs(resid_b) < 1e-6 * abs(F_b)


def test_halving_the_communication_step_changes_speed_little(motor):
    # reference: the same model at h and h/2 (reference motor, position dependent, quasi-steady at t = 0.15 s)
    speeds = []
    for h in (2e-4, 1e-4):
        m = engine.InProcessMotor(motor, h_s=h)
        m.initialize(V_s=motor.operating.V_s_V, s0=-0.02)
        m.run(0.15)
        speeds.append(m.value("Slider.v"))
        assert -0.02 < m.value("Slider.s") < motor.slider.s_max_m  # still travelling, no end stop
    assert speeds[1] == pytest.approx(speeds[0], rel=5e-3)


def test_in_process_motor_steady_speed_does_not_depend_on_step(flat):
    # reference: steady.steady_state; the describing-function coupling is exact in steady state
    ss = None
    for h in (1e-4, 5e-4, 1e-3):
        m = engine.InProcessMotor(flat, h_s=h)
        m.initialize(V_s=flat.operating.V_s_V)
        m.run(0.4)
        ss = ss or steady.steady_state(flat, 0.0, m.value("Driver.V0"), 0.0, 1)
        assert m.value("Slider.v") == pytest.approx(ss.v_m_s, rel=1e-5)


# ---------------------------------------------------------------------------
# The reference motor reproduces the paper's qualitative behaviour (docs/explanation/physics.md)
# ---------------------------------------------------------------------------

def test_no_load_speed_in_range_and_rises_with_voltage(motor):
    # reference: design targets (docs/explanation/physics.md) - 150-300 mm/s at 324 V, rising with V0
    V = [150.0, 200.0, 250.0, 300.0, 324.0, 360.0]
    v = [steady.steady_state(motor, 0.0, V0, 0.0, 1).v_m_s for V0 in V]
    assert np.all(np.diff(v) > 0)
    assert 0.150 <= v[V.index(324.0)] <= 0.300


@pytest.mark.parametrize("direction", [1, -1])
def test_speed_falls_with_opposing_load(motor, direction):
    # reference: paper Sect. 5 - heavier opposing loads slow the slider (load sign: data-format.md)
    loads = [0.0] + PAPER_LOADS
    speeds = [abs(steady.steady_state(motor, 0.0, 324.0, direction * m, direction).v_m_s) for m in loads]
    assert np.all(np.diff(speeds) < 0)
    # assisting loads speed it up
    assisted = [abs(steady.steady_state(motor, 0.0, 324.0, -direction * m, direction).v_m_s) for m in PAPER_LOADS]
    assert np.all(np.array(assisted) > speeds[0])


@pytest.mark.parametrize("direction", [1, -1])
@pytest.mark.parametrize("m_load", [m * s for m in PAPER_LOADS for s in (1, -1)])
def test_every_paper_load_moves_at_324V(motor, m_load, direction):
    # reference: design targets (docs/explanation/physics.md) - every paper load (0.03-0.09 kg, both signs) still moves at 324 V
    ss = steady.steady_state(motor, 0.0, 324.0, m_load, direction)
    assert not ss.stuck
    assert ss.converged
    assert math.copysign(1, ss.v_m_s) == direction
    assert abs(ss.v_m_s) > 0.02


def test_speed_varies_with_position_by_5_to_20_percent(motor):
    # reference: design targets (docs/explanation/physics.md) / paper Fig. 9a - 5-20 % variation over a ~40 mm stroke at 324 V, no load
    s = np.linspace(-0.02, 0.02, 21)
    v = np.array([steady.steady_state(motor, x, 324.0, 0.0, 1).v_m_s for x in s])
    variation = (v.max() - v.min()) / v.mean()
    assert 0.05 <= variation <= 0.20


def test_tip_motion_amplitudes_and_phase(motor):
    # reference: design targets (docs/explanation/physics.md) - tip amplitudes of order 1 um at 324 V, ~90 deg between the modes
    for s in (-0.02, 0.0, 0.02):
        for d in (1, -1):
            ss = steady.steady_state(motor, s, 324.0, 0.0, d)
            assert 0.3e-6 < ss.U_l_m < 3e-6
            assert 0.3e-6 < ss.U_w_m < 3e-6
            assert abs(abs(math.degrees(ss.delta_rad)) - 90.0) < 25.0
            # the tip moves toward the drive direction while pressing: delta ~ -90 deg for CH1, +90 for CH2
            assert math.copysign(1, ss.delta_rad) == -d
            assert 0 < ss.phi_c_rad < 2 * math.pi  # intermittent contact at high voltage


def test_speed_nearly_proportional_to_tip_velocity(motor):
    # reference: paper Fig. 9c / design targets (docs/explanation/physics.md) - v_s close to proportional to w U_w across positions and voltages
    w = 2 * math.pi * F_DRIVE
    ratio = []
    for V0 in (250.0, 324.0):
        for s in (-0.02, -0.01, 0.0, 0.01, 0.02):
            ss = steady.steady_state(motor, s, V0, 0.0, 1)
            ratio.append(ss.v_m_s / (w * ss.U_w_m))
    ratio = np.array(ratio)
    assert np.all((ratio > 0.2) & (ratio < 1.0))
    assert ratio.std() / ratio.mean() < 0.15


def test_low_voltage_leaves_slider_stuck(motor):
    # reference: Eq. 22 - with a tiny drive the interface force cannot beat the static guide friction
    ss = steady.steady_state(motor, 0.0, 5.0, 0.0, 1)
    assert ss.stuck and ss.v_m_s == 0.0


@pytest.mark.parametrize("margin, moves", [(-0.01, False), (+0.01, True)])
def test_breakaway_threshold_in_the_engine_is_the_static_friction_level(motor, margin, moves):
    # reference: Eq. 22 with the static coefficient - the slider held at its end stop by the drive
    # leaves it backwards only when the pulley load beats drive force + mu_ss (kappa F_p + g m_s);
    # 1 % of that level below it stays, 1 % above it moves (mu_sd, 20 % lower, would move both)
    sl = motor.slider
    t_switch = 0.1  # the stator has settled; until then no load, the drive presses the slider into the stop

    def run(m_after):
        m = engine.InProcessMotor(motor, h_s=2e-4)
        m.initialize(V_s=motor.operating.V_s_V, s0=sl.s_max_m, direction=1.0,
                     m_load=lambda t: 0.0 if t < t_switch else m_after)
        return m.run(0.2, record=("Interface.F_d", "Stator.F_p", "Slider.s", "Slider.v"))

    probe = run(0.0)
    k = int(np.searchsorted(probe["time"], t_switch)) - 1
    F_d, F_p = float(probe["Interface.F_d"][k]), float(probe["Stator.F_p"][k])
    assert probe["Slider.s"][-1] == sl.s_max_m and F_d > 1.0  # pressed into the stop
    assert abs(probe["Interface.F_d"][k - 50] - F_d) < 1e-6 * F_d  # settled before the switch
    assert sl.pulley_mu == 0.0  # no load-path friction in the reference motor
    static = sl.mu_ss * (sl.kappa * F_p + G * sl.mass_kg)
    threshold_kg = (F_d + static) / G
    r = run(threshold_kg + margin * static / G)
    left = sl.s_max_m - r["Slider.s"][-1]
    if moves:
        assert left > 1e-4 and r["Slider.v"].min() < -1e-3
    else:
        assert left == 0.0 and np.all(r["Slider.v"] == 0.0)


def test_in_process_motor_same_with_compiled_and_python_kernels(motor, monkeypatch):
    # one run two ways: every kernel compiled by numba, and every kernel in plain Python (L1B2_JIT=0, read by
    # the blocks at initialisation); start-up with stick-slip, a load step and the run to steady speed
    from l1b2.cosim.engine import InProcessMotor
    from l1b2.physics import driver as drv
    V_s = float(drv.supply_for_voltage_V(motor.driver, 300.0, 1.0, 48500.0, 25.0))
    runs = {}
    for flag in ("1", "0"):
        monkeypatch.setenv("L1B2_JIT", flag)
        m = InProcessMotor(motor, h_s=2e-4)
        m.initialize(V_s=V_s, m_load=lambda t: 0.0 if t < 0.03 else 0.05)
        runs[flag] = m.run(0.06, record=("Slider.v", "Slider.s", "Stator.U_w", "Interface.F_d"))
    for col in ("Slider.v", "Slider.s", "Stator.U_w", "Interface.F_d"):
        a, b = np.asarray(runs["1"][col]), np.asarray(runs["0"][col])
        assert np.allclose(a, b, rtol=1e-12, atol=1e-15 * np.max(np.abs(b))), col
    assert np.max(runs["1"]["Slider.v"]) > 0.1  # it moved


def _ramped_start(h_s: float) -> tuple[float, float]:
    """The realistic motor from rest at the stroke's start, its supply ramped from zero over 70 ms, under a 0.09 kg
    load that pulls the slider its way: the largest tip tangential amplitude [m] over the traverse, and the time [s]
    at which the slider crosses the stroke's middle."""
    from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor
    mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    V_s = mp.operating.V_s_V
    m = engine.InProcessMotor(mp, h_s=h_s)
    m.initialize(V_s=lambda t: V_s * min(1.0, t / 0.07), direction=1, m_load=-0.09, s0=mp.slider.s_min_m)
    res = m.run(0.4, record=("Stator.U_w", "Slider.s"), until=lambda mm: mm.value("Slider.at_stop") == 1)
    s_mid = 0.5 * (mp.slider.s_min_m + mp.slider.s_max_m)
    return float(np.max(res["Stator.U_w"])), float(np.interp(s_mid, res["Slider.s"], res["time"]))


def test_a_supply_ramped_from_zero_under_a_pulling_load_converges_in_the_step():
    # a start from zero amplitude: near U_w = 0 the friction's fundamental under the pulling load does not scale
    # with the amplitude, and is held as an excitation over the step (physics.stator.coupled_envelope_step);
    # reference: the same traverse at a 25 us step. The tip's amplitude stays at the steady drive's (a few um)
    # and the slider crosses mid-stroke within 1 ms of the reference's time at 0.2 ms and 1 ms
    U_ref, t_ref = _ramped_start(2.5e-5)
    assert 1e-6 < U_ref < 3e-6
    for h in (2e-4, 1e-3):
        U_w, t_mid = _ramped_start(h)
        assert U_w == pytest.approx(U_ref, rel=0.01), h
        assert abs(t_mid - t_ref) < 1e-3, h
