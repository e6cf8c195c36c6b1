#!/usr/bin/env python
"""A fifteenth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the fourteen earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_fourteenth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``sense_electrode_shunt`` -- logged ``sense_shunt_ohm`` per sample, the setting of a decade resistor box (three
  significant digits, constant in a run, no noise: the DAQ program reads the operator's entry). The stator carries
  a small sensing electrode (a strip of capacitance ``C_s``, drawn in 0.2-0.4 nF) that the motor's identification
  left open (read by a 10 MOhm probe). In a shunt-damping study the operator loads it with the box, a design factor
  log-uniform in 1 kOhm - 1 MOhm per run. A resistive shunt on a piezoelectric electrode (Hagood and von Flotow)
  with ``rho = R omega C_s`` (``omega`` the drive's angular frequency) adds to each mode ``i`` (L1, B2) the loss
  factor ``k_i^2 rho / (1 + rho^2)`` and softens it from the open-circuit stiffness by ``k_i^2 / (1 + rho^2)``
  (``k_i^2`` the mode's coupling with the strip, drawn in 0.002-0.004 for each mode independently): the damping
  ratios are ``zeta_i + k_i^2 rho / (2 (1 + rho^2))`` (a bell in ``log R``, largest at ``rho = 1``, near 8-16 kOhm)
  and the free frequencies ``f_i (1 - k_i^2 / (2 (1 + rho^2)))`` (a step in ``log R``: the motor's own above some
  100 kOhm, up to 0.1-0.2 % lower near 1 kOhm, that is 50-100 Hz). A threshold-like law of the logged ohms (nothing
  over the upper two thirds of their range), non-monotone through the damping's bell, on both modes of the drive
  side at once (B2 softening slows the motor, L1 softening speeds it).
* ``handling_reseat_walk`` -- no column; a change between runs through the recording protocol. Each time the
  operator changes the hanging weight (a run whose logged load differs from the run before's: the first run of a
  condition with another load, from the other side, or none), they steady the slider by its carriage, and the
  stator holder's pivot takes the push: the tip re-seats on a neighbouring patch of the lining, whose transfer film
  differs a little. The slip friction coefficient follows a random walk stepped at each handling, ``mu_p (1 +
  w_k)``, ``w_k = w_(k-1) + s z_k`` at a handling, ``w_k = w_(k-1)`` otherwise (``w`` 0 at the first run, ``s`` drawn
  in 1.5-2.5 %, ``z_k`` standard normal): the steps' timing follows the plan's load order, their sizes nothing
  logged. The rig's own 2 % run-to-run scatter stays on top.
* ``purge_flow_proxy`` -- logged ``purge_flow_L_min`` per sample, a thermal mass-flow meter (0.02 L/min of noise,
  0.01 L/min resolution), an indirect and lagged proxy of the cause. A hood (volume ``V_h`` drawn in 0.3-0.6 L)
  over the contact is purged with dry nitrogen at a flow ``Q`` set per run in the pause before it (a design factor,
  uniform in 0-4 L/min); lab air leaks in at ``q_l`` (drawn in 0.5-1.0 L/min) with the lab's humidity, which
  drifts on the session clock, ``RH_lab = RH_0 + a sin(2 pi t / P + phi)`` (``RH_0`` drawn in 40-50 %, ``a`` in
  2-5 %, ``P`` in 150-250 s, ``phi`` uniform; not logged). The hood's humidity follows ``dRH/dt = (q_l (RH_lab -
  RH) - Q RH) / V_h``: a first-order lag toward ``RH_lab q_l / (q_l + Q)`` with the time constant ``V_h / (q_l +
  Q)`` (4-36 s: over several runs), from ``RH_lab`` when the first flow is set one pause before the first run.
  Adsorbed water (a Langmuir coverage ``theta(a) = K a / (1 + K a)`` of the activity ``a = RH / 100``, ``K`` drawn
  in 3-6) lubricates the tip's slip: ``mu_p (1 + D (theta(0.45) - theta(a)) / theta(0.45))`` (``D`` drawn in
  0.15-0.25; the motor's own ``mu_p`` at the lab's usual 45 %), taken at the run's start (a run, 0.2-0.4 s, is
  short against the lag). The logged flow is this run's setting; the cause is the hood's humidity, a nonlinear lag
  of the flows before and of a lab humidity nobody logged.
* ``purge_rh_cause`` -- the proxy's control, not a kind of its own: the same draw and the same motion as
  ``purge_flow_proxy`` at the seed, with the hood's humidity logged (``hood_rh_pct``, a fast sensor, 0.3 % of
  noise, 0.01 % resolution) instead of the flow. What the loop makes of the cause tells the proxy's loss.
* ``weight_tray_decoy`` -- a decoy, no effect on the motor: logged ``tray_mass_g`` per sample, a balance under the
  rack that holds the unused weights (30, 50, 70 and 90 g, 240 g in all; a run without a load takes none). It reads
  ``240 g - 1000 |m|`` through its filter, first order with ``tau_b`` (drawn in 0.4-1.2 s) from each weight change
  (at the start of the pause before the run whose load differs from the run before's; from 240 g at the first
  one), plus its zero drift ``c_d t`` on the session clock (``c_d`` drawn in -0.5..+0.5 g per 100 s), 0.02 g of
  noise and 0.01 g resolution. It follows the load's magnitude (even in the load), settles in the first runs after
  a change and drifts with the clock; the rack stands on the floor, so it acts on nothing and must not be traced.

Pass rule (fixed before any loop ran; the eighth to fourteenth audits'): a kind passes when a regressor of ``WANT``
is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before
and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``tray_mass_g`` is nowhere in ``traced_all`` and ``a <=
1.02 b``. ``WANT``: the box's column for the shunt (a name holding ``sense_shunt``); the flow's column for the
purge (a name holding ``purge_flow``: the flow itself or a lag or history the loop derives from it); for the walk,
a regressor of the session's clock or order (its name holds ``time``, ``order``, ``index``, ``count``, ``since``,
``session``, ``segment`` or ``break``, and not ``time_in_run``: the run's own clock carries no change between runs;
the load alone is not accepted: the walk's steps follow the load's changes, not its value). The cause's control is
reported with its own column (``hood_rh``) but not counted.

Usage: python bench/blind_effects_fifteenth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run nrmse before
and after, channels considered, CPU of the close loop by ``time.process_time``), plus ``traced_all`` (every traced
regressor), ``want`` (the regressors accepted as the effect's) and ``accepted_in_first_two``.
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("sense_electrode_shunt", "handling_reseat_walk", "purge_flow_proxy", "weight_tray_decoy", "purge_rh_cause")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"purge_rh_cause": "purge_flow_proxy"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"sense_electrode_shunt": "sense_shunt_ohm", "handling_reseat_walk": None,
           "purge_flow_proxy": "purge_flow_L_min", "weight_tray_decoy": "tray_mass_g", "purge_rh_cause": "hood_rh_pct"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"sense_electrode_shunt": ("sense_shunt",),
        "handling_reseat_walk": ("time", "order", "index", "count", "since", "session", "segment", "break"),
        "purge_flow_proxy": ("purge_flow",),
        "weight_tray_decoy": (),
        "purge_rh_cause": ("hood_rh",)}
#: names that hold a word of ``WANT`` but are not accepted (the run's own clock)
NOT_WANT = {"handling_reseat_walk": ("time_in_run",)}
RACK_G = 240.0              # the rack's weights: 30 + 50 + 70 + 90 g
RH_REF = 45.0               # the lab's usual humidity [%], at which the motor's own mu_p holds
RH_STEP_S = 0.05            # the hood's integration step [s]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the proxy's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 171, KINDS.index(src) if src in KINDS else 99])
    if kind == "sense_electrode_shunt":
        R = np.array([float(f"{x:.3g}") for x in 10.0 ** rng.uniform(3.0, 6.0, n_runs)])
        return {"C_s_F": float(rng.uniform(0.2e-9, 0.4e-9)), "k2_l": float(rng.uniform(0.003, 0.006)),
                "k2_b": float(rng.uniform(0.003, 0.006)), "R_ohm": R}
    if kind == "handling_reseat_walk":
        return {"s": float(rng.uniform(0.015, 0.025)), "z": rng.standard_normal(n_runs)}
    if src == "purge_flow_proxy":
        return {"V_h_L": float(rng.uniform(0.05, 0.15)), "q_l_L_min": float(rng.uniform(0.5, 1.0)),
                "RH_0": float(rng.uniform(40.0, 50.0)), "a_pct": float(rng.uniform(2.0, 5.0)),
                "P_s": float(rng.uniform(150.0, 250.0)), "phi": float(rng.uniform(0.0, 2 * math.pi)),
                "K": float(rng.uniform(3.0, 6.0)), "D": float(rng.uniform(0.15, 0.25)),
                "Q_L_min": rng.uniform(0.0, 4.0, n_runs)}
    if kind == "weight_tray_decoy":
        return {"tau_b_s": float(rng.uniform(0.4, 1.2)), "c_d_g_per_100s": float(rng.uniform(-0.5, 0.5))}
    return {}


def shunt_modes(R_ohm: float, f_Hz: float, C_s_F: float, k2_l: float, k2_b: float) -> dict:
    """The shunt's factors at the box's setting ``R_ohm``: ``rho = R 2 pi f C_s``; the added damping ratios
    ``k^2 rho / (2 (1 + rho^2))`` and the frequency factors ``1 - k^2 / (2 (1 + rho^2))`` of L1 and B2."""
    rho = R_ohm * 2.0 * math.pi * f_Hz * C_s_F
    return {"rho": rho, "dzeta_l": k2_l * rho / (2.0 * (1.0 + rho ** 2)),
            "dzeta_b": k2_b * rho / (2.0 * (1.0 + rho ** 2)),
            "f_l_factor": 1.0 - k2_l / (2.0 * (1.0 + rho ** 2)), "f_b_factor": 1.0 - k2_b / (2.0 * (1.0 + rho ** 2))}


def handlings(loads) -> np.ndarray:
    """Whether each run is a handling: its load differs from the run before's (the first run is not)."""
    L = np.asarray(loads, float)
    return np.concatenate([[False], L[1:] != L[:-1]])


def walk(loads, z, s: float) -> np.ndarray:
    """The walk ``w_k`` of each run: ``w_(k-1) + s z_k`` at a handling, ``w_(k-1)`` otherwise, 0 at the first run."""
    steps = np.where(handlings(loads), s * np.asarray(z, float), 0.0)
    return np.cumsum(steps)


def rh_lab(t_s, p: dict):
    """The lab's humidity [%] at the session times ``t_s``: ``RH_0 + a sin(2 pi t / P + phi)``."""
    return p["RH_0"] + p["a_pct"] * np.sin(2 * math.pi * np.asarray(t_s, float) / p["P_s"] + p["phi"])


def hood_rh_step(rh: float, t0: float, t1: float, Q: float, p: dict) -> float:
    """The hood's humidity at ``t1`` from ``rh`` at ``t0`` under the flow ``Q`` [L/min]: the first-order lag toward
    ``RH_lab q_l / (q_l + Q)`` (time constant ``V_h / (q_l + Q)``), exact on steps of ``RH_STEP_S`` with the lab's
    humidity at each step's middle."""
    tau = 60.0 * p["V_h_L"] / (p["q_l_L_min"] + Q)
    share = p["q_l_L_min"] / (p["q_l_L_min"] + Q)
    n = max(1, int(math.ceil((t1 - t0) / RH_STEP_S)))
    h = (t1 - t0) / n
    for i in range(n):
        eq = float(rh_lab(t0 + (i + 0.5) * h, p)) * share
        rh = eq + (rh - eq) * math.exp(-h / tau)
    return rh


def langmuir(a, K: float):
    """The water coverage ``K a / (1 + K a)`` at the activity ``a``."""
    a = np.asarray(a, float)
    return K * a / (1.0 + K * a)


def purge_mu_factor(rh_pct, K: float, D: float):
    """The slip friction's factor at the hood's humidity: ``1 + D (theta(0.45) - theta(a)) / theta(0.45)``."""
    th0 = langmuir(RH_REF / 100.0, K)
    return 1.0 + D * (th0 - langmuir(np.asarray(rh_pct, float) / 100.0, K)) / th0


def tray_filter(t_s, target_g: float, y0_g: float, t_swap_s: float, p: dict):
    """The balance's filter [g] at the session times ``t_s``: from ``y0_g`` at the swap ``t_swap_s`` toward
    ``target_g``, first order with ``tau_b``."""
    return target_g + (y0_g - target_g) * np.exp(-(np.asarray(t_s, float) - t_swap_s) / p["tau_b_s"])


def tray_reading(t_s, target_g: float, y0_g: float, t_swap_s: float, p: dict):
    """The balance's reading [g] (no noise, no rounding) at the session times ``t_s``: its filter
    (:func:`tray_filter`) plus the zero drift ``c_d t``."""
    return tray_filter(t_s, target_g, y0_g, t_swap_s, p) + p["c_d_g_per_100s"] * np.asarray(t_s, float) / 100.0


def run_motor(kind: str, mp, plan, p: dict, k: int, state: dict):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``state``: the walk's ``w`` and the hood's
    humidity ``rh`` at the run's start)."""
    if kind == "sense_electrode_shunt":
        f = shunt_modes(float(p["R_ohm"][k]), plan.f_drive_Hz, p["C_s_F"], p["k2_l"], p["k2_b"])
        st = mp.stator
        return mp.replace(stator__zeta_l=st.zeta_l + f["dzeta_l"], stator__zeta_b=st.zeta_b + f["dzeta_b"],
                          stator__f_l0_Hz=st.f_l0_Hz * f["f_l_factor"], stator__f_b0_Hz=st.f_b0_Hz * f["f_b_factor"])
    if kind == "handling_reseat_walk":
        return mp.replace(interface__mu_p=mp.interface.mu_p * (1.0 + state["w"]))
    if kind == "purge_flow_proxy" or kind == "purge_rh_cause":
        fac = float(purge_mu_factor(state["rh"], p["K"], p["D"]))
        return mp.replace(interface__mu_p=mp.interface.mu_p * fac)
    return mp


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    loads = [L for _, L, _ in conds]
    w = walk(loads, p["z"], p["s"]) if kind == "handling_reseat_walk" else np.zeros(len(conds))
    swaps = handlings(loads)
    frames, per_run, t_next = [], [], 0.0
    purge = kind in ("purge_flow_proxy", "purge_rh_cause")
    rh, t_rh = (float(rh_lab(-plan.pause_s, p)), -plan.pause_s) if purge else (None, None)
    tray, t_swap, target = RACK_G, -plan.pause_s, RACK_G        # the balance's filter before the first weight
    for k, (V, L, d) in enumerate(conds):
        if purge:      # the flow Q_k set at the end of the run before (one pause before this run)
            rh = hood_rh_step(rh, t_rh, t_next, float(p["Q_L_min"][k]), p)
            t_rh = t_next
        mp = run_motor(kind, scattered_motor(nominal, factors[k]), plan, p, k, {"w": float(w[k]), "rh": rh})
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 172, k]).standard_normal(len(t))
        if kind == "sense_electrode_shunt":
            extra["sense_shunt_ohm"] = np.full(len(t), float(p["R_ohm"][k]))
        elif kind == "purge_flow_proxy":
            extra["purge_flow_L_min"] = np.round(p["Q_L_min"][k] + 0.02 * noise, 2)
        elif kind == "purge_rh_cause":
            Q = float(p["Q_L_min"][k])
            rh_t = np.array([hood_rh_step(rh, t_next, t_next + x, Q, p) if x > 0 else rh for x in t])
            extra["hood_rh_pct"] = np.round(rh_t + 0.3 * noise, 2)
        elif kind == "weight_tray_decoy":
            if swaps[k] or k == 0:      # the swap, at the start of the pause before this run
                t_sw = t_next - plan.pause_s
                tray = tray_filter(t_sw, target, tray, t_swap, p)
                target, t_swap = RACK_G - 1000.0 * abs(L), t_sw
            extra["tray_mass_g"] = np.round(tray_reading(t_next + t, target, tray, t_swap, p) + 0.02 * noise, 2)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "zeta_l": mp.stator.zeta_l, "zeta_b": mp.stator.zeta_b, "f_l0_Hz": mp.stator.f_l0_Hz,
                        "f_b0_Hz": mp.stator.f_b0_Hz, "w": float(w[k]), "rh_pct": rh, "t_start_s": t_next,
                        "duration_s": float(r["time"][-1])})
        t_end = float(out[dataio.TIME].iloc[-1])
        if purge:
            rh = hood_rh_step(rh, t_next, t_end, float(p["Q_L_min"][k]), p)
            t_rh = t_end
        t_next = t_end + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def accepted(kind: str, name: str) -> bool:
    """Whether the traced regressor ``name`` is the kind's (a word of ``WANT`` and none of ``NOT_WANT``)."""
    return be.accepted_by(WANT, NOT_WANT, kind, name)


def main(argv=None):
    be.run_audit(argv, __doc__, KINDS, experiment, CHANNEL, WANT, NOT_WANT)


if __name__ == "__main__":
    main()
