#!/usr/bin/env python
"""A fifth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the loop
and no kind of the four earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py``, ``bench/blind_effects_fourth.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). A kind sets FMU parameters per run, or an FMU input per step as a
function of the co-simulation's own state (the slider's position and speed one step before: a rig's controller or
a cable sees the same); the speed is always the DAQ's derivative of the recorded position. Each kind draws from one
random stream of its seed. The kinds:

* ``pll_tracking`` -- logged ``frequency_Hz`` per sample, varying within a run along the stroke. The drive tracks
  the stator's resonance with a phase-locked loop instead of holding its set frequency: the loop's lock point moves
  with the contact's preload, which the bar's deviation changes along the stroke (the realistic bar: F_p 5.5-7.3 N
  over the stroke). The drive's target frequency is ``f0 + kappa (F_p(s) - F_p(0))``, kappa drawn in 600-800 Hz/N
  (the lock point of a mode of Q ~ 33 moves by about its half-bandwidth, 740 Hz, per 45 degrees of the current's
  phase, and the contact's stiffening and loss turn that phase by some 35-50 degrees per newton of preload), and the
  drive follows it through the loop's first-order lag ``df/dt = (f_target - f) / tau``, tau drawn in 3-8 ms (locked
  at the start position before the run). The drive frequency per sample is logged (0.1 Hz resolution); the
  operator's supply is set for f0.
* ``pneumatic_preload`` -- logged ``line_pressure_bar`` per sample (one value per run plus 0.01 bar of gauge noise;
  a column no code of the package names, in bar), changing between runs with a memory. The preload spring is
  replaced by a small pneumatic cylinder (bore 6 mm, area A = 28.3 mm^2) fed from the lab's line, whose pressure
  differs from run to run as the compressor cycles (``p_c + U(-0.55, 0.55) bar``, p_c such that ``p_c A`` is the
  motor's P0). The cylinder's seal holds the piston until the pressure force beats its friction F_s (drawn in
  0.25-0.45 N), so the preload is a play (backlash) operator of the logged pressure:
  ``P0_k = min(max(P0_{k-1}, p_k A - F_s), p_k A + F_s)``, ``P0_0 = p_0 A - F_s`` (pressurised from below).
* ``cable_loop`` -- no logged channel; along the stroke and with the direction. The readhead's and the drive's
  cables leave the slider in a loop clamped behind the stroke's negative end (at s_n drawn in -30..-24 mm); the
  loop's bending stiffness pulls the slider toward its clamp, ``-k_c (s - s_n)`` (k_c drawn in 3-5 N/m), and the
  strands' internal friction adds a hysteresis that grows with the bending and opposes the motion,
  ``-eta k_c |s - s_n| tanh(v / 5 mm/s)`` (eta drawn in 0.2-0.35). Set through the slider's load input as the
  equivalent mass ``m_load - F_c / g``, with the load's inertia moved into the slider's mass
  (``load_inertia`` 0, ``mass_kg + |m_load|``) and the guide's Coulomb levels and preload share rescaled
  (:func:`blind_effects.load_in_slider_motor`), so the moving mass and the guide's friction are the motor's.
* ``drawwire_sensor`` -- a measurement effect along the stroke, no channel. The position is measured by a
  draw-wire (string-pot) sensor mounted on the axis's negative side at a distance D (drawn 36-40 mm from s = 0)
  and a lateral offset h (drawn 17-20 mm: a compact rig's mount, the wire 42-53 deg off the axis at the near
  stop) from the line of motion: the wire's length is ``l(s) = sqrt((s + D)^2 + h^2)``; the operator calibrates
  the sensor at the two end stops, so the recorded position is ``s_min + (l(s) - l(s_min)) (s_max - s_min) /
  (l(s_max) - l(s_min))`` (exact at the stops, its slope ``(s + D) / l(s)`` rescaled: low near the sensor, high
  far from it). The wire's tension on the slider is left out.

Usage: python bench/blind_effects_fifth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run nrmse before
and after, channels considered, CPU of the close loop by ``time.process_time``).
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.cosim.engine import InProcessMotor  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.stator import preload_N  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("pll_tracking", "pneumatic_preload", "cable_loop", "drawwire_sensor")
#: the channel each kind acts through (a logged column, or the recorded signal the effect follows)
CHANNEL = {"pll_tracking": "frequency_Hz", "pneumatic_preload": "line_pressure_bar",
           "cable_loop": "position x direction", "drawwire_sensor": "position"}
G_M_S2 = 9.81
CYLINDER_AREA_M2 = math.pi * 0.003 ** 2   # 6 mm bore
PA_PER_BAR = 1e5
SIGN_SPEED_M_S = 5e-3   # speed scale of the cable's hysteresis sign (tanh)


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 89, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "pll_tracking":
        return {"kappa_Hz_per_N": float(rng.uniform(600, 800)), "tau_s": float(rng.uniform(3e-3, 8e-3))}
    if kind == "pneumatic_preload":
        return {"F_s_N": float(rng.uniform(0.25, 0.45)), "dp_bar": rng.uniform(-0.55, 0.55, n_runs)}
    if kind == "cable_loop":
        return {"k_c_N_per_m": float(rng.uniform(3, 5)), "s_n_m": float(rng.uniform(-0.030, -0.024)),
                "eta": float(rng.uniform(0.2, 0.35))}
    if kind == "drawwire_sensor":
        return {"D_m": float(rng.uniform(0.036, 0.040)), "h_m": float(rng.uniform(0.017, 0.020))}
    return {}


def play_preload(p_bar, F_s_N: float, area_m2: float = CYLINDER_AREA_M2):
    """The preload [N] per run of a cylinder at the pressures ``p_bar`` [bar] whose seal holds the piston against a
    force difference up to ``F_s_N`` (a play operator of ``p A`` of half-width F_s; the first run's piston
    pressurised from below, ``p_0 A - F_s``)."""
    force = np.asarray(p_bar, float) * PA_PER_BAR * area_m2
    out = np.empty_like(force)
    prev = force[0] - F_s_N
    for k, f in enumerate(force):
        prev = min(max(prev, f - F_s_N), f + F_s_N)
        out[k] = prev
    return out


def cable_force_N(s_m, v_m_s, k_c: float, s_n: float, eta: float):
    """The cable loop's force on the slider [N] at the position ``s_m`` and speed ``v_m_s``: its bending pull
    toward the clamp at ``s_n`` and a hysteresis ``eta`` times as large that opposes the motion."""
    x = np.asarray(s_m, float) - s_n
    return -k_c * x - eta * k_c * np.abs(x) * np.tanh(np.asarray(v_m_s, float) / SIGN_SPEED_M_S)


def drawwire_position(s_m, D_m: float, h_m: float, s_min: float, s_max: float):
    """The draw-wire sensor's recorded position [m] of the slider at ``s_m``: the wire's length from an exit at
    ``-D_m`` along the axis and ``h_m`` beside it, calibrated to read ``s_min`` and ``s_max`` at the end stops."""
    length = lambda s: np.hypot(np.asarray(s, float) + D_m, h_m)  # noqa: E731
    return s_min + (length(s_m) - length(s_min)) * (s_max - s_min) / (length(s_max) - length(s_min))


class StateInput:
    """An FMU input computed each step from the slider's position and speed (those of the step before): ``law(t,
    s, v)``; before the motor is initialised it sees the start position at rest. ``log`` holds ``(t, value)``."""

    def __init__(self, law, s0: float):
        self.law, self.s0, self.motor, self.log = law, s0, None, []

    def __call__(self, t: float) -> float:
        if self.log and self.log[-1][0] == t:
            return self.log[-1][1]
        m = self.motor
        s, v = (self.s0, 0.0) if m is None else (m.value("Slider.s"), m.value("Slider.v"))
        value = float(self.law(t, s, v))
        self.log.append((t, value))
        return value


def pll_law(mp, f0: float, kappa: float, tau: float, s0: float):
    """The tracking drive's frequency [Hz] as a law of ``(t, s, v)``: first-order lag ``tau`` toward
    ``f0 + kappa (F_p(s) - F_p(0))``, starting locked at ``s0``."""
    Fc = float(preload_N(mp.stator, 0.0))
    state = {"t": 0.0, "f": f0 + kappa * (float(preload_N(mp.stator, float(s0))) - Fc)}

    def law(t, s, v):
        target = f0 + kappa * (float(preload_N(mp.stator, float(s))) - Fc)
        state["f"] += (target - state["f"]) * (1.0 - math.exp(-(t - state["t"]) / tau))
        state["t"] = t
        return state["f"]
    return law


#: the recording of a traverse that needs the slider's speed as well as its position
POSITION_AND_SPEED = ("Slider.s", "Slider.v")


def traverse(mp, nominal, plan, V0, load, d, f_law=None, load_law=None, record=("Slider.s",)):
    """One traverse of the co-simulation with the drive frequency and the load input given as laws of the slider's
    state (None: the plan's frequency and the run's load), recording the outputs ``record``; the operator's supply
    is set at 25 degC and f0. Returns the recording and the frequency input."""
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    f_in = plan.f_drive_Hz if f_law is None else StateInput(f_law, s0)
    l_in = load if load_law is None else StateInput(load_law, s0)
    m.initialize(V_s=V_s, f_s=f_in, T=plan.ambient_degC, direction=d, m_load=l_in, s0=s0)
    for u in (f_in, l_in):
        if isinstance(u, StateInput):
            u.motor = m
    r = m.run(plan.max_run_s, record=record, until=lambda mm: mm.value("Slider.at_stop") == d)
    return r, f_in


def run_motor(kind: str, mp, L: float, p: dict, P0_k: float | None):
    """The run's motor of ``kind`` (and, for the cable, its load law)."""
    if kind == "pneumatic_preload":
        return mp.replace(stator__P0_N=P0_k), None
    if kind == "cable_loop":
        mp = be.load_in_slider_motor(mp, L, "cable_loop")
        k_c, s_n, eta = p["k_c_N_per_m"], p["s_n_m"], p["eta"]
        return mp, lambda t, s, v: L - float(cable_force_N(s, v, k_c, s_n, eta)) / G_M_S2
    return mp, None


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    P0 = None
    if kind == "pneumatic_preload":
        p_c = nominal.stator.P0_N / (CYLINDER_AREA_M2 * PA_PER_BAR)
        p["p_bar"] = p_c + p["dp_bar"]
        P0 = play_preload(p["p_bar"], p["F_s_N"])
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        if P0 is not None:  # the cylinder replaces the spring's set force, the run's scatter kept as a factor
            mp = mp.replace(stator__P0_N=mp.stator.P0_N * P0[k] / nominal.stator.P0_N)
        mp, load_law = run_motor(kind, mp, L, p, None if P0 is None else mp.stator.P0_N)
        f_law = None
        if kind == "pll_tracking":
            s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
            f_law = pll_law(mp, plan.f_drive_Hz, p["kappa_Hz_per_N"], p["tau_s"], s0)
        r, f_in = traverse(mp, nominal, plan, V, L, d, f_law, load_law)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        f = None
        if f_law is not None:
            tl, fl = np.array(f_in.log).T
            f = np.round(np.interp(t, tl, fl), 1)
        if kind == "drawwire_sensor":
            s = drawwire_position(s, p["D_m"], p["h_m"], nominal.slider.s_min_m, nominal.slider.s_max_m)
        extra = {}
        if kind == "pneumatic_preload":
            noise = np.random.default_rng([seed, 90, k]).standard_normal(len(t))
            extra["line_pressure_bar"] = np.round(p["p_bar"][k] + 0.01 * noise, 3)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, f, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mass_kg": mp.slider.mass_kg,
                        "f_range_Hz": None if f is None else [float(f.min()), float(f.max())]})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.channel_field(CHANNEL))

if __name__ == "__main__":
    main()
