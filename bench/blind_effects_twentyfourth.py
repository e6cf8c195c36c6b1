#!/usr/bin/env python
"""A twenty-fourth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the twenty-three earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_twentythird.py``, ``bench/blind_effects_stamps.py``)
names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row and
``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan
at a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). Every kind sets FMU parameters per run, the
latch also an FMU input per step as a function of the co-simulation's own state (the slider's position one step
before, ``bench/blind_effects_fifth.py``'s ``StateInput``); the speed is always the DAQ's derivative of the recorded
position. Each kind draws from one random stream of its seed. The kinds:

* ``bias_domain_clamp`` -- logged ``bias_V`` per sample, the high-voltage monitor of a DC bias supply coupled into
  the stator's electrodes through a choke (0.5 V of noise, 0.1 V resolution). A bias study: the operator sets a new
  DC bias ``V_b`` per run (uniform in 0-900 V) on top of the drive's ac amplitude, a field ``E = V_b / t`` along the
  poling direction of the 3 mm plate (0-0.30 kV/mm, far below a hard PZT's coercive field). The bias pins the
  domain walls whose motion gives the extrinsic share ``x`` of the piezoelectric coefficient (drawn in 0.05-0.10),
  a saturating clamp: ``d(E) / d(0) = 1 - x (E / E_s)^2 / (1 + (E / E_s)^2)`` (``E_s`` drawn in 0.12-0.22 kV/mm),
  and both modes' force factors ``A_l``, ``A_b`` scale with it. Monotone (the coefficient falls with the bias and
  levels off at the intrinsic ``1 - x``) and non-linear (flat at no bias). The bias's change of the clamped
  capacitance, of the modes' frequencies and of the drive's tank is left out.
* ``enclosure_cycle_grease`` -- no column; a change between runs on the session clock, periodic. The rig stands in a
  small enclosure whose cooling unit runs a limit cycle: the enclosure's air swings about 25 degC as ``25 + A sin(2
  pi t / P + phi)`` (``A`` drawn in 1.5-2.5 K, ``P`` in 40-70 s, ``phi`` uniform in 0-2 pi; ``t`` the session's
  clock, a session lasts some 95 s), and the guide's rail follows it through its own first-order lag ``tau_r``
  (drawn in 4-10 s; the cycle long established, so the rail swings ``A / sqrt(1 + (omega tau_r)^2)`` behind it by
  ``atan(omega tau_r)``). The crossed rollers run in a grease whose base oil's viscosity follows Arrhenius's law,
  and the guide's viscous damping with it: ``c_r(T) = c_r exp(E_a / R (1 / T - 1 / 298.15 K))`` (``E_a`` drawn in
  25-40 kJ/mol, ``R`` = 8.314 J/(mol K)). The co-simulation holds ``c_r`` per run at the rail's temperature at the
  run's start on the session's clock (the pauses included); the guide's Coulomb levels are the dry rollers'. Only the
  protocol's own clock carries it.
* ``stop_magnet_latch`` -- no column; within a run, along the stroke. A magnetic catch on the negative end stop
  keeps the parked slider from drifting: a pot magnet behind a 1 mm brass cap faces a steel striker on the slider.
  It pulls the slider toward the stop with ``F = F_0 / (1 + x / x_0)^2`` (``x = s - s_min`` the striker's distance
  from its seat; ``F_0`` drawn in 0.30-0.50 N, ``x_0`` in 1.5-3.0 mm), whatever the direction and the speed. The
  forward runs start in it and break out against it, the backward runs are drawn into it at their end. Set through
  the slider's load input as the equivalent mass ``m_load + F / g`` computed each step from the slider's position of
  the step before, with the load's inertia moved into the slider's mass and the guide's Coulomb levels and preload
  share rescaled (:func:`blind_effects.load_in_slider_motor`). The magnet's eddy-current drag is left out.
* ``table_tilt_decoy`` -- a decoy, no effect on the motor: logged ``table_tilt_urad`` per sample, a precision
  inclinometer on the rig's breadboard (0.2 urad of noise, 0.1 urad resolution). The breadboard rests on rubber
  feet: the weight hanging from the pulley at its edge tilts it by ``a_L`` per kg of the signed load (drawn in 8-15
  urad/kg), the slider's own mass moving along the stroke by ``a_s`` per metre of its position (drawn in 100-200
  urad/m), and the feet settle over the session in a random walk (a step per run normal with the sd ``sigma_w``,
  drawn in 0.1-0.3 urad) from an offset ``theta_0`` (drawn in -20..20 urad). A tilt of tens of urad gives the
  slider a force of its weight times the tilt, some 1e-5 N: nothing. It carries the load, the position and the
  session's clock: a consequence of the conditions and the motion that must not be traced.

Pass rule (fixed before any loop ran; the eighth to twenty-third audits'): a kind passes when a regressor of
``WANT`` is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse
before and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``:
3.037 / 2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``tilt`` is nowhere in ``traced_all`` and
``a <= 1.02 b``. ``WANT``: the monitor's column for the bias (a name holding ``bias``); for the enclosure's cycle, a
regressor of the session's own clock or of a periodic function of it (a name holding ``time``, ``session``,
``clock``, ``elapsed``, ``index``, ``count``, ``sin``, ``cos``, ``period``, ``cycl``, ``phase`` or ``harmon``), none
holding ``time_in_run`` or ``in_run`` (the run's own clock), ``onset`` or ``start`` (the run's start), ``break`` or
``pause`` (the plan's pauses are all alike), ``_lag``, ``prev`` or ``last`` (the runs' conditions before),
``voltage``, ``load``, ``direction``, ``speed`` or ``position``; for the latch, a regressor of the position or of a
stop (a name holding ``position``, ``stop``, ``near``, ``proxim``, ``distance``, ``latch`` or ``magnet``), none
holding ``time_in_run`` or ``in_run`` (the force follows the place, not the run's clock), ``speed``, ``veloc``,
``lag``, ``prev``, ``last``, ``history`` or ``memory`` (the force is the step's own), ``voltage``, ``load`` or
``session``.

Usage: python bench/blind_effects_twentyfourth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one
of the above or clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST
free-run nrmse before and after, channels considered, CPU of the close loop by ``time.process_time``), plus
``traced_all`` (every traced regressor), ``want`` (the regressors accepted as the effect's) and
``accepted_in_first_two``.
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)
import blind_effects_fifth as b5  # noqa: E402

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics.slider import G_M_S2  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("bias_domain_clamp", "enclosure_cycle_grease", "stop_magnet_latch", "table_tilt_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"bias_domain_clamp": "bias_V", "enclosure_cycle_grease": None, "stop_magnet_latch": None,
           "table_tilt_decoy": "table_tilt_urad"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"bias_domain_clamp": ("bias",),
        "enclosure_cycle_grease": ("time", "session", "clock", "elapsed", "index", "count", "sin", "cos", "period",
                                   "cycl", "phase", "harmon"),
        "stop_magnet_latch": ("position", "stop", "near", "proxim", "distance", "latch", "magnet"),
        "table_tilt_decoy": ()}
#: names that hold a word of ``WANT`` but are not accepted (for the cycle the run's own clock, the run's start, the
#: pauses, the runs before and the plan's factors; for the latch the run's clock, the speed, lags and the runs
#: before, the plan's factors and the session)
NOT_WANT = {"enclosure_cycle_grease": ("time_in_run", "in_run", "onset", "start", "break", "pause", "_lag", "prev",
                                       "last", "voltage", "load", "direction", "speed", "position"),
            "stop_magnet_latch": ("time_in_run", "in_run", "speed", "veloc", "lag", "prev", "last", "history",
                                  "memory", "voltage", "load", "session")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"table_tilt_decoy": "tilt"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
BIAS_RANGE_V = (0.0, 900.0)         # the DC bias set per run [V]
GAS_J_PER_MOL_K = 8.314             # the gas constant [J/(mol K)]
T_REF_K = 298.15                    # the guide's c_r is the motor's at 25 degC [K]
ENCLOSURE_MEAN_DEGC = 25.0          # the enclosure's mean air temperature [degC]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 261, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "bias_domain_clamp":
        return {"x": float(rng.uniform(0.05, 0.10)), "E_s_kV_mm": float(rng.uniform(0.12, 0.22)),
                "V_b": rng.uniform(*BIAS_RANGE_V, n_runs)}
    if kind == "enclosure_cycle_grease":
        return {"A_K": float(rng.uniform(1.5, 2.5)), "P_s": float(rng.uniform(40.0, 70.0)),
                "phi": float(rng.uniform(0.0, 2.0 * math.pi)), "tau_r_s": float(rng.uniform(4.0, 10.0)),
                "E_a_J_mol": float(rng.uniform(25e3, 40e3))}
    if kind == "stop_magnet_latch":
        return {"F_0_N": float(rng.uniform(0.30, 0.50)), "x_0_m": float(rng.uniform(1.5e-3, 3.0e-3))}
    if kind == "table_tilt_decoy":
        out = {"a_L_urad_kg": float(rng.uniform(8.0, 15.0)), "a_s_urad_m": float(rng.uniform(100.0, 200.0)),
               "sigma_w_urad": float(rng.uniform(0.1, 0.3)), "theta_0_urad": float(rng.uniform(-20.0, 20.0))}
        out["walk_urad"] = np.cumsum(out["sigma_w_urad"] * rng.standard_normal(n_runs))
        return out
    return {}


def coupling_factor(V_b, thickness_m: float, x: float, E_s_kV_mm: float):
    """The piezoelectric coefficient under the DC bias ``V_b`` [V] over its unbiased value: ``1 - x u / (1 + u)``
    with ``u = (E / E_s)^2``, ``E = V_b / t`` in kV/mm."""
    E = np.asarray(V_b, float) / thickness_m * 1e-6
    u = (E / E_s_kV_mm) ** 2
    return 1.0 - x * u / (1.0 + u)


def rail_temperature_degC(t_s, A_K: float, P_s: float, phi: float, tau_r_s: float):
    """The guide rail's temperature [degC] at the session's times ``t_s``: the enclosure's sinusoid through the
    rail's first-order lag (steady state): ``25 + A sin(omega t + phi - atan(omega tau)) / sqrt(1 + (omega tau)^2)``."""
    w = 2.0 * math.pi / P_s
    wt = w * tau_r_s
    return ENCLOSURE_MEAN_DEGC + A_K / math.sqrt(1.0 + wt * wt) * np.sin(w * np.asarray(t_s, float) + phi
                                                                          - math.atan(wt))


def grease_factor(T_degC, E_a_J_mol: float):
    """The guide's viscous damping over the motor's at 25 degC: ``exp(E_a / R (1 / T - 1 / 298.15 K))``."""
    T = np.asarray(T_degC, float) + 273.15
    return np.exp(E_a_J_mol / GAS_J_PER_MOL_K * (1.0 / T - 1.0 / T_REF_K))


def latch_force_N(s_m, s_min_m: float, F_0_N: float, x_0_m: float):
    """The catch's pull toward the negative stop [N, positive toward -position] at the positions ``s_m``:
    ``F_0 / (1 + (s - s_min) / x_0)^2``."""
    x = np.maximum(np.asarray(s_m, float) - s_min_m, 0.0)
    return F_0_N / (1.0 + x / x_0_m) ** 2


def tilt_urad(s_m, L: float, k: int, p: dict):
    """The inclinometer's reading [urad] (no noise, no rounding) at the slider's positions ``s_m`` in run ``k`` with
    the signed load ``L``: ``theta_0 + walk_k + a_L L + a_s s``."""
    return (p["theta_0_urad"] + p["walk_urad"][k] + p["a_L_urad_kg"] * L
            + p["a_s_urad_m"] * np.asarray(s_m, float))


def run_motor(kind: str, mp, p: dict, k: int, L: float, t_s: float = 0.0):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``L`` the run's load, ``t_s`` the session's
    clock at the run's start) and its load law (None: the run's load)."""
    if kind == "bias_domain_clamp":
        h = float(coupling_factor(p["V_b"][k], mp.stator.thickness_m, p["x"], p["E_s_kV_mm"]))
        return mp.replace(stator__A_l_N_per_V=mp.stator.A_l_N_per_V * h,
                          stator__A_b_N_per_V=mp.stator.A_b_N_per_V * h), None
    if kind == "enclosure_cycle_grease":
        T = float(rail_temperature_degC(t_s, p["A_K"], p["P_s"], p["phi"], p["tau_r_s"]))
        return mp.replace(slider__c_r_N_s_per_m=mp.slider.c_r_N_s_per_m * float(grease_factor(T, p["E_a_J_mol"]))), None
    if kind == "stop_magnet_latch":
        s_min, F_0, x_0 = mp.slider.s_min_m, p["F_0_N"], p["x_0_m"]
        return (be.load_in_slider_motor(mp, L, kind),
                lambda t, s, v: L + float(latch_force_N(s, s_min, F_0, x_0)) / G_M_S2)
    return mp, None


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds_run):
        mp, load_law = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, L, t_next)
        r = b5.traverse(mp, nominal, plan, V, L, d, load_law=load_law, record=b5.POSITION_AND_SPEED)[0]
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 262, k]).standard_normal(len(t))
        if kind == "bias_domain_clamp":
            extra["bias_V"] = np.round(p["V_b"][k] + 0.5 * noise, 1)
        elif kind == "table_tilt_decoy":
            extra["table_tilt_urad"] = np.round(tilt_urad(s, L, k, p) + 0.2 * noise, 1)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        pull = None
        if load_law is not None:  # the largest pull of the catch met, from the recorded steps
            pull = float(latch_force_N(r["Slider.s"], mp.slider.s_min_m, p["F_0_N"], p["x_0_m"]).max())
        T_rail = (float(rail_temperature_degC(t_next, p["A_K"], p["P_s"], p["phi"], p["tau_r_s"]))
                  if kind == "enclosure_cycle_grease" else None)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "A_l_N_per_V": mp.stator.A_l_N_per_V, "A_b_N_per_V": mp.stator.A_b_N_per_V,
                        "c_r_N_s_per_m": mp.slider.c_r_N_s_per_m, "rail_T_degC": T_rail,
                        "mu_sd": mp.slider.mu_sd, "mass_kg": mp.slider.mass_kg, "latch_max_N": pull,
                        "t_start_s": t_next, "duration_s": float(r["time"][-1])})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def accepted(kind: str, name: str) -> bool:
    """Whether the traced regressor ``name`` is the kind's: a word of ``WANT`` and none of ``NOT_WANT``."""
    return be.accepted_by(WANT, NOT_WANT, kind, name)


def verdict(row: dict) -> dict:
    """The pass rule on a printed row (``kind``, ``seed``, ``traced``, ``traced_all``, ``before``, ``after`` in %):
    ``bound`` = sqrt(b0^2 + (b^2 - b0^2) / 4) (the decoy's: 1.02 b), ``attributed`` (a regressor of ``WANT`` among
    the first two; for the decoy, its column nowhere in ``traced_all``) and ``passes`` (both, ``a <= bound``)."""
    return be.audit_verdict(row, B0, DECOY, accepted)


def main(argv=None):
    be.run_audit(argv, __doc__, KINDS, experiment, CHANNEL, WANT, NOT_WANT, accepted)


if __name__ == "__main__":
    main()
