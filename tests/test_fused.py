"""The fused coupled step (l1b2.physics.coupled, l1b2.cosim.engine.FusedSteps) against the blocks it replaces.

``L1B2Motor.fmu`` steps the whole motor through one compiled function. The
blocks (``InProcessMotor.step``) are the reference: run side by side from the
same start, every output and every sub-block variable must agree exactly
(same operations on the same floats), in worlds that exercise every branch:
loads both ways, end stops, waviness and a bump on the bar, self-heating,
a temperature-dependent B2 mode (steps handed back to the blocks), pure
slip, communication steps of several internal steps and inputs changed
mid-run.
"""

from __future__ import annotations

import numpy as np
import pytest
from l1b2.cosim.composite import MotorBlock
from l1b2.cosim.engine import FusedSteps, InProcessMotor
from l1b2.errors import SimulationError
from l1b2.physics import coupled as cp
from l1b2.physics import driver as drv
from l1b2.physics import stator as st
from l1b2.physics.jit import jit_status

STEP_S = 2e-4


@pytest.fixture(scope="module", autouse=True)
def _compiled():
    if cp.compiled_substeps() is None:
        pytest.skip(f"numba kernel not available: {jit_status()}")


def _block(mp, fused: bool, V0=324.0, internal_step_s=STEP_S, **inputs):
    b = MotorBlock(mp)
    b.V_s = float(drv.supply_for_voltage_V(mp.driver, V0, 1.0, 48500.0, 25.0))
    for k, v in inputs.items():
        setattr(b, k, v)
    b.internal_step_s = internal_step_s
    b.initialize()
    if fused:
        assert b.motor.fused_step is not None
    else:
        b.motor.fused_step = None  # the blocks, step by step (the reference)
    return b


def _variables(b):
    names = [v.name for v in MotorBlock.OUTPUTS] + [v.name for v in MotorBlock._sub_locals()]
    return {n: b.get(n) for n in names}


def _run_both(mp, n_steps, h=STEP_S, change=None, **kw):
    fused, ref = _block(mp, True, **kw), _block(mp, False, **kw)
    fused.peak_speed = 0.0
    t = 0.0
    for k in range(n_steps):
        if change is not None and k == n_steps // 2:
            for b in (fused, ref):
                change(b)
        fused.do_step(t, h)
        ref.do_step(t, h)
        fused.peak_speed = max(fused.peak_speed, abs(fused.v))
        t += h
    return fused, ref


def _assert_same(fused, ref):
    a, b = _variables(fused), _variables(ref)
    diff = {n: (a[n], b[n]) for n in a if a[n] != b[n]}
    assert not diff, f"{len(diff)} variables differ, e.g. {list(diff.items())[:3]}"


WORLDS = {
    "reference, no load": (lambda m: m, {}),
    "load against -direction, end stop": (lambda m: m, dict(m_load=0.05, direction=-1.0)),
    "aiding load": (lambda m: m, dict(m_load=-0.1)),
    "wavy bar with a bump": (lambda m: m.replace(stator__bar_wave_amp_m=3e-6, stator__bar_wave_period_m=4e-3,
                                                 stator__bar_bump_amp_m=5e-6, stator__bar_bump_center_m=5e-3,
                                                 stator__bar_bump_width_m=1e-3), dict(m_load=0.03)),
    "self-heating, L1 drift": (lambda m: m.replace(stator__thermal_tau_s=0.05, stator__heating_K_per_V2=1e-4,
                                                   stator__df_dT_l_Hz_per_K=-8.0), {}),
    "asymmetric B2, pulley friction": (lambda m: m.replace(stator__asym_b=0.05, slider__pulley_mu=0.05),
                                       dict(m_load=0.07, direction=-1.0)),
}


@pytest.mark.parametrize("world", list(WORLDS))
def test_fused_step_equals_the_blocks_exactly(motor, world):
    change_motor, inputs = WORLDS[world]
    fused, ref = _run_both(change_motor(motor), 1500, **inputs)
    _assert_same(fused, ref)
    assert fused.motor.fused_step.steps_fused >= 1500 and fused.motor.fused_step.steps_blocks == 0
    assert fused.peak_speed > 0.02  # it moved: the comparison covers the motion, not only a rest state


def test_fused_step_hands_temperature_dependent_b2_steps_to_the_blocks(motor):
    # with a B2 thermal drift and self-heating the stator block evaluates the modal properties directly
    # whenever its temperature moved: those steps go through the blocks, the rest stays fused
    mp = motor.replace(stator__df_dT_b_Hz_per_K=-10.0, stator__thermal_tau_s=0.01, stator__heating_K_per_V2=1e-4)
    fused, ref = _run_both(mp, 600)
    _assert_same(fused, ref)
    assert fused.motor.fused_step.steps_blocks > 0
    # the same drift at a constant temperature: one table, every step fused
    fused, ref = _run_both(motor.replace(stator__df_dT_b_Hz_per_K=-10.0), 600, T=40.0)
    _assert_same(fused, ref)
    assert fused.motor.fused_step.steps_blocks == 0


def test_fused_step_with_substeps_pure_slip_and_changed_inputs(motor):
    def change(b):  # the host changes voltage, direction and load mid-run
        b.V_s *= 0.8
        b.direction = -1.0
        b.m_load = 0.02

    fused, ref = _run_both(motor, 300, h=1e-3, change=change)  # 5 internal steps per communication step
    _assert_same(fused, ref)
    assert fused.motor.fused_step.steps_fused == 1500
    fused, ref = _block(motor, True), _block(motor, False)
    fused._extra["Interface.pure_slip"] = ref._extra["Interface.pure_slip"] = True
    fused.initialize()
    ref.initialize()
    ref.motor.fused_step = None
    for k in range(800):
        fused.do_step(k * STEP_S, STEP_S)
        ref.do_step(k * STEP_S, STEP_S)
    _assert_same(fused, ref)
    assert fused.motor.fused_step.p[cp.PURE_SLIP] == 1.0


def test_python_source_of_the_fused_step_gives_the_compiled_numbers(motor):
    # the compiled function is the module's source: run in plain Python it gives the same state, to the
    # round-off of complex arithmetic (numba's complex division and exp are not CPython's bit for bit)
    b = _block(motor, True, m_load=0.03)
    for k in range(40):
        b.do_step(k * STEP_S, STEP_S)
    f = b.motor.fused_step
    x_py, x_jit = f.x.copy(), f.x.copy()
    n_py = cp.motor_substeps(x_py, f.p, f.cell, f.cell_k, 200, STEP_S)
    n_jit = f.kernel(x_jit, f.p, f.cell, f.cell_k, 200, STEP_S)
    assert n_py == n_jit > 0
    forces = [cp.FN1S_IN, cp.FN1C_IN, cp.FT1S_IN, cp.FT1C_IN, cp.F_D, cp.F_NM, cp.FN1S, cp.FN1C, cp.FT1S, cp.FT1C]
    atol = np.full(len(cp.STATE), 1e-18)
    atol[forces] = 1e-12  # [N]: a force component that cancels to ~1e-15 N keeps only round-off
    assert np.all(np.abs(x_py - x_jit) <= atol + 1e-10 * np.abs(x_jit))
    assert x_py[cp.S] != f.x[cp.S]  # it advanced


def test_fused_step_asks_for_the_next_table_cell(motor):
    b = _block(motor, True)
    f = b.motor.fused_step
    f.load()
    f.set_inputs(0.0, STEP_S)
    x = f.x.copy()
    assert f.kernel(x, f.p, f.cell, -1, 5, STEP_S) == 0  # no cell given
    assert x[cp.REASON] == cp.REASON_CELL
    P = st.axial_force_N(motor.stator, float(x[cp.S]))
    assert x[cp.NEED_CELL] == np.floor(P / st.TABLE_CELL_N)
    # the cell's interpolant is the table's (same operations)
    table = st.modal_table(motor.stator)
    wb, eta = st.table_lookup(table.cell_array(int(x[cp.NEED_CELL])), P)
    props = table(P, 25.0)
    assert (wb, abs(eta)) == (props.omega_b0, props.eta_T)


def test_fused_step_reports_a_bad_input_as_the_blocks_do(motor):
    messages = []
    for fused in (True, False):
        b = _block(motor, fused)
        b.V_s = 1900.0  # drives the stator voltage above the 2000 V the stator accepts
        with pytest.raises(SimulationError) as err:
            for k in range(3):
                b.do_step(k * STEP_S, STEP_S)
        messages.append(str(err.value))
    assert messages[0] == messages[1] and "V0" in messages[0]


def test_fmu_state_variables_read_and_written_through_the_fused_step(motor):
    # reading a sub-block variable brings the blocks up to date; writing one is taken at the next step
    fused, ref = _run_both(motor, 200, m_load=0.02)
    assert fused.motor.fused_step.ahead
    assert fused.get("Slider.s_state") == ref.get("Slider.s_state")
    assert not fused.motor.fused_step.ahead
    for b in (fused, ref):
        b.set("Slider.v_state", 0.0)
        b.set("Slider.stuck_state", 1.0)
        b.initialize_outputs()
    for k in range(200, 400):
        fused.do_step(k * STEP_S, STEP_S)
        ref.do_step(k * STEP_S, STEP_S)
    _assert_same(fused, ref)


def test_quadrature_interface_and_python_kernels_leave_the_fused_step_out(motor, monkeypatch):
    b = MotorBlock(motor)
    b._extra["Interface.quadrature"] = True
    b.initialize()
    assert b.motor.fused_step is None
    monkeypatch.setenv("L1B2_JIT", "0")
    b = MotorBlock(motor)
    b.initialize()
    assert b.motor.fused_step is None
    assert FusedSteps.for_motor(b.motor) is None


def test_engine_runs_fused_by_default_and_records_what_the_blocks_record(motor):
    # InProcessMotor.run with the fused step (default) against fused=False: every recorded series (the
    # engine's default record and the rig's, incl. the derived tip velocity), and the stop condition
    rec = ("Driver.V0", "Stator.U_l", "Stator.U_w", "Stator.delta", "Stator.F_p", "Interface.F_d",
           "Interface.phi_c", "Interface.stick_fraction", "Slider.v", "Slider.s", "Stator.v_tip",
           "Stator.T_stator", "Slider.at_stop", "Stator.f_b", "Slider.a")
    mp = motor.replace(stator__thermal_tau_s=0.02, stator__heating_K_per_V2=1e-4)
    runs = {}
    for fused in (None, False):
        m = InProcessMotor(mp, fused=fused)
        m.initialize(V_s=float(drv.supply_for_voltage_V(mp.driver, 280.0, 1.0, 48500.0, 25.0)), m_load=0.04,
                     direction=-1.0, s0=0.015)
        runs[fused] = (m.run(1.0, record=rec, until=lambda mm: mm.value("Slider.at_stop") == -1.0), m)
    (a, ma), (b, mb) = runs[None], runs[False]
    assert ma.fused_step is not None and mb.fused_step is None
    assert len(a["time"]) == len(b["time"]) < 5001  # stopped at the end stop, at the same step
    for k in rec:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    # a value the fused state does not hold brings the blocks up to date
    assert ma.value("Stator.phase_w") == mb.value("Stator.phase_w")
    m = InProcessMotor(motor, fused=True)
    m.b["Interface"].quadrature = True
    with pytest.raises(SimulationError, match="fused=True"):
        m.initialize(V_s=60.0)


def test_engine_with_inputs_that_are_functions_of_time_fused_equals_blocks(motor):
    # inputs may be functions of time (held over each step): the fused step takes them step by step
    V_s = float(drv.supply_for_voltage_V(motor.driver, 300.0, 1.0, 48500.0, 25.0))
    series = {}
    for fused in (None, False):
        m = InProcessMotor(motor, fused=fused)
        m.initialize(V_s=lambda t: V_s * (0.8 + 0.2 * min(t / 0.05, 1.0)), m_load=lambda t: 0.04 * (t > 0.03),
                     s0=-0.015)
        series[fused] = m.run(0.08, record=("Slider.v", "Slider.s", "Driver.V0", "Stator.U_w"))
        assert (m.fused_step is not None) == (fused is None)
    for k in ("Slider.v", "Slider.s", "Driver.V0", "Stator.U_w"):
        np.testing.assert_array_equal(series[None][k], series[False][k], err_msg=k)
    assert np.ptp(series[None]["Driver.V0"]) > 10.0  # the voltage did ramp
