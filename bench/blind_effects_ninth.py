#!/usr/bin/env python
"""A ninth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the eight earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_eighth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``magnet_gap_preload`` -- logged ``magnet_gap_mm`` per sample, an eddy-current gap sensor (5 um of noise, 1 um
  resolution). Part of the preload is magnetic: a NdFeB magnet on the stator holder pulls on a steel plate under
  the friction bar across an air gap that a micrometer screw sets for each run (a design factor, uniform in
  0.7-1.8 mm). A permanent magnet's pull across a gap ``g`` falls as ``1 / (1 + g / g0)^2`` (``g0`` drawn in
  0.5-0.9 mm, the magnet's size scale), and the magnet gives a share ``s`` (drawn in 0.20-0.35) of the motor's
  preload at the reference gap of 1.0 mm, so ``P0(g) = P0 (1 - s + s ((1 + 1 mm / g0) / (1 + g / g0))^2)``: a
  convex, inverse-square law of the logged gap (about 0.8-1.2 P0 over the gaps), not a linear scaling.
* ``setpoint_overshoot`` -- no column; a state of the recording protocol. The operator sets each new V0 by turning
  the drive's amplitude knob while watching its RMS display, which lags (a meter's averaging): turning until the
  display reads the target leaves the output past it, by a fixed share ``rho`` (drawn in 10-16 %) of the step from
  the previous setting, ``V_k = V0_k + rho (V0_k - V_(k-1))`` (``V_(k-1)``: the actual amplitude of the run
  before, 0 before the first run), and the operator does not come back to it. When a run keeps the previous
  run's V0 (the backward run of a condition, or the next condition at the same V0), the knob is not touched:
  ``V_k = V_(k-1)``. The logged ``voltage_V`` is the plan's V0; the actual one differs by up to ~15 V, with a
  sign and size set by the run order (the previous condition's V0), constant along the stroke.
* ``supply_current_limit`` -- the drive side: the H-bridge's DC bus is fed by a bench supply whose current limit
  the operator set at ``I_lim`` (drawn in 0.26-0.30 A) through the bus capacitor ``C_b`` (drawn in 1.0-2.2 mF).
  The bridge and its tank take the real power ``V0^2 / (2 R_m)`` (R_m the stator's loss resistance), so with V0
  proportional to the bus, ``V0 = G V_b``, the bus sees a resistor ``R_eq = 2 R_m / G^2`` (about 170 Ohm). When the
  set supply voltage ``V_s`` would draw more than ``I_lim`` (``V_s > I_lim R_eq``: the runs at the higher V0), the
  supply holds its current and the capacitor discharges toward ``I_lim R_eq`` from the run's start, ``V_b(t) =
  I_lim R_eq + (V_s - I_lim R_eq) exp(-t / (R_eq C_b))``; otherwise ``V_b = V_s``. In the pause (1 s) the supply
  recharges the capacitor at ``I_lim`` (over 100 V/s, more than the bus lost), so every run starts at ``V_s``. The
  drive's amplitude sags along the higher-V0 runs (by 10-26 % at 324 V by a run's end, measured), while
  ``voltage_V`` logs the plan's.
* ``grid_frequency_decoy`` -- a decoy, no effect on the motor: logged ``grid_frequency_Hz`` per sample, the mains
  frequency that the drive's power analyser reads (its display refreshed every 0.2 s, 1 mHz resolution). The
  drive runs from a regulated DC supply, so the mains frequency reaches nothing. It wanders on the session clock
  as an Ornstein-Uhlenbeck process about 50 Hz (standard deviation ``sigma`` drawn in 15-30 mHz, correlation time
  ``tau`` in 60-300 s, longer than the session), so it follows the clock: it must not be traced.

Pass rule (fixed before any loop ran; the eighth audit's): a kind passes when a regressor of ``WANT`` is among the
first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before and after the
loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``). The decoy passes
when ``grid_frequency_Hz`` is nowhere in ``traced_all`` and ``a <= 1.02 b``. ``WANT``: the gap column for the
magnet; a regressor of the drive's amplitude or of the setting's history (its name holds ``voltage``, ``V0``,
``previous``, ``history`` or ``setpoint``) for the overshoot; a regressor of the drive's amplitude or its supply
(``voltage``, ``V0``, ``supply``, ``saturation``, ``bus``, ``amplitude`` or ``power``) for the current limit.

Usage: python bench/blind_effects_ninth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run nrmse before
and after, channels considered, CPU of the close loop by ``time.process_time``), plus ``traced_all`` (every traced
regressor) and ``want`` (the regressors accepted as the effect's).
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
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("magnet_gap_preload", "setpoint_overshoot", "supply_current_limit", "grid_frequency_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"magnet_gap_preload": "magnet_gap_mm", "setpoint_overshoot": None, "supply_current_limit": None,
           "grid_frequency_decoy": "grid_frequency_Hz"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"magnet_gap_preload": ("magnet_gap_mm",),
        "setpoint_overshoot": ("voltage", "V0", "previous", "history", "setpoint"),
        "supply_current_limit": ("voltage", "V0", "supply", "saturation", "bus", "amplitude", "power"),
        "grid_frequency_decoy": ()}
GAP_REF_M = 1.0e-3
GRID_HZ = 50.0
ANALYSER_S = 0.2
GRID_SPAN_S = 2000.0   # the decoy's process is drawn over this much of the session clock (a session: ~100 s)


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 113, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "magnet_gap_preload":
        return {"share": float(rng.uniform(0.20, 0.35)), "g0_m": float(rng.uniform(0.5e-3, 0.9e-3)),
                "gap_m": rng.uniform(0.7e-3, 1.8e-3, n_runs)}
    if kind == "setpoint_overshoot":
        return {"rho": float(rng.uniform(0.10, 0.16))}
    if kind == "supply_current_limit":
        return {"I_lim_A": float(rng.uniform(0.26, 0.30)), "C_b_F": float(rng.uniform(1.0e-3, 2.2e-3))}
    if kind == "grid_frequency_decoy":
        sigma, tau = float(rng.uniform(0.015, 0.030)), float(rng.uniform(60.0, 300.0))
        return {"sigma_Hz": sigma, "tau_s": tau,
                "x_Hz": ou_path(rng.standard_normal(int(GRID_SPAN_S / ANALYSER_S) + 1), sigma, tau, ANALYSER_S)}
    return {}


def magnet_preload_N(P0_N, gap_m, share: float, g0_m: float, gap_ref_m: float = GAP_REF_M):
    """The preload [N] with the magnet at the gap ``gap_m`` [m]: ``P0 (1 - s + s ((1 + g_ref/g0) / (1 +
    g/g0))^2)``."""
    ratio = ((1.0 + gap_ref_m / g0_m) / (1.0 + np.asarray(gap_m, float) / g0_m)) ** 2
    return np.asarray(P0_N, float) * (1.0 - share + share * ratio)


def set_amplitudes_V(V0_V, rho: float):
    """The actual amplitudes [V] of runs whose plan asks ``V0_V`` in turn: ``V_k = V0_k + rho (V0_k - V_(k-1))``
    when V0 changes (``V_(-1)`` = 0), ``V_k = V_(k-1)`` when it does not."""
    out, prev_cmd, prev = [], None, 0.0
    for v in np.asarray(V0_V, float):
        if prev_cmd is None or v != prev_cmd:
            prev = v + rho * (v - prev)
        out.append(prev)
        prev_cmd = v
    return np.array(out)


def bus_resistance_ohm(R_m_ohm: float, gain: float):
    """The resistor [Ohm] the bridge and tank present to the bus, ``2 R_m / G^2`` (``G = V0 / V_b``)."""
    return 2.0 * R_m_ohm / gain ** 2


def bus_voltage_V(t_s, V_s_V: float, I_lim_A: float, R_eq_ohm: float, C_b_F: float):
    """The bus [V] at the run's time ``t_s`` [s]: ``I_lim R_eq + (V_s - I_lim R_eq) exp(-t / (R_eq C_b))`` when
    ``V_s > I_lim R_eq`` (the supply in current limit), else ``V_s``."""
    t = np.asarray(t_s, float)
    v_inf = I_lim_A * R_eq_ohm
    if V_s_V <= v_inf:
        return np.full(t.shape, float(V_s_V))
    return v_inf + (V_s_V - v_inf) * np.exp(-t / (R_eq_ohm * C_b_F))


def ou_path(z, sigma: float, tau_s: float, step_s: float):
    """An Ornstein-Uhlenbeck path [same unit as ``sigma``] on a grid of ``step_s`` [s] from the standard normal
    draws ``z``: ``x_0 = sigma z_0``, ``x_(n+1) = x_n e^(-step/tau) + sigma sqrt(1 - e^(-2 step/tau)) z_(n+1)``."""
    z = np.asarray(z, float)
    a = math.exp(-step_s / tau_s)
    b = sigma * math.sqrt(1.0 - a * a)
    x = np.empty_like(z)
    x[0] = sigma * z[0]
    for n in range(1, z.size):
        x[n] = a * x[n - 1] + b * z[n]
    return x


def grid_reading_Hz(t_session_s, x_Hz, step_s: float = ANALYSER_S):
    """The analyser's reading [Hz] at the session times ``t_session_s`` [s]: 50 Hz plus the path ``x_Hz`` held over
    each refresh ``step_s`` [s] (``x[floor(t / step)]``)."""
    i = np.floor(np.asarray(t_session_s, float) / step_s + 1e-9).astype(int)
    return GRID_HZ + np.asarray(x_Hz, float)[i]


def traverse_bus(mp, nominal, plan, V0, load, d, p: dict):
    """One traverse with the bus of ``supply_current_limit`` (``p``: its draw) feeding the drive; returns the
    co-simulation's record and the bus's function of the run's time."""
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    R_eq = bus_resistance_ohm(nominal.driver.R_m_ohm, V0 / V_s)
    bus = lambda t: float(bus_voltage_V(t, V_s, p["I_lim_A"], R_eq, p["C_b_F"]))  # noqa: E731
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=bus, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=d, m_load=load, s0=s0)
    rec = ("Slider.s", "Stator.T_stator")
    return m.run(plan.max_run_s, record=rec, until=lambda mm: mm.value("Slider.at_stop") == d), bus


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next = [], [], 0.0
    actual = set_amplitudes_V([c[0] for c in conds], p["rho"]) if kind == "setpoint_overshoot" else None
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        V_run, bus_end = V if actual is None else float(actual[k]), None
        if kind == "magnet_gap_preload":
            mp = mp.replace(stator__P0_N=float(magnet_preload_N(mp.stator.P0_N, p["gap_m"][k], p["share"],
                                                                p["g0_m"])))
        if kind == "supply_current_limit":
            r, bus = traverse_bus(mp, nominal, plan, V, L, d, p)
            bus_end = bus(float(r["time"][-1]))
        else:
            r = be.traverse(mp, nominal, plan, V_run, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 114, k]).standard_normal(len(t))
        if kind == "magnet_gap_preload":
            extra["magnet_gap_mm"] = np.round(p["gap_m"][k] * 1e3 + 0.005 * noise, 3)
        elif kind == "grid_frequency_decoy":
            extra["grid_frequency_Hz"] = np.round(grid_reading_Hz(t_next + t, p["x_Hz"]), 3)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "V0_actual_V": V_run, "bus_end_V": bus_end})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    if kind == "grid_frequency_decoy":
        p = {k: v for k, v in p.items() if k != "x_Hz"}
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.want_fields(CHANNEL, WANT))


if __name__ == "__main__":
    main()
