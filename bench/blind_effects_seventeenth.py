#!/usr/bin/env python
"""A seventeenth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the sixteen earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_sixteenth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``bridge_deadtime`` -- logged ``deadtime_ns`` per sample, the gate driver's dead-time register (an integer number
  of 10 ns steps, constant in a run, no noise). A switching study sets it per run, uniform in 0-2700 ns (the
  bridge's MOSFETs are protected against shoot-through by it). The drive's resonant tank carries a current in phase
  with the bridge's fundamental, so at each switching edge the current is near zero and the bridge's node floats
  for the dead time ``t_d``: the square wave loses ``t_d`` at each of its two edges per half period, a three-level
  wave of duty ``1 - 2 f t_d`` (the drive's own ``duty`` input), whose fundamental is ``sin(pi duty / 2) =
  cos(pi f t_d)`` of the full square wave's. The operator's supply table is for a full square wave (duty 1) and
  ``voltage_V`` logs the plan's V0: the stator's amplitude falls by ``1 - cos(pi f t_d)``, quadratic in the
  channel, 8.3 % at 2700 ns.
* ``cage_creep`` -- no column; a change between runs through the session's handling of the load. The slider's
  crossed-roller guide keeps its rollers in a cage that should roll at half the slider's travel. The load's cable
  pulls the slider toward the pulley its weight hangs from, and the rollers slip a little under that traction, so
  each stroke the cage creeps toward the load's side by ``m / m_c`` of its free travel (``m`` the signed load [kg],
  ``m_c`` drawn in 0.15-0.30 kg per free travel), whichever way the slider goes; no stroke without a load moves it.
  The cage's offset ``u`` (a share of its free travel, 0 at the session's start, where the assembler centred it)
  is clipped at +-1, where the cage rests against its stop. An off-centre cage runs its leading rollers onto the
  raceway's unhardened ends and makes them skid near the stroke's end: the guide's Coulomb levels (``mu_sd``,
  ``mu_ss``) are ``(1 + J u^2)`` times the motor's (``J`` drawn in 0.14-0.28), ``u`` the offset at the run's start
  (after the strokes before it). A hidden state that integrates the signed load of the runs before, saturated,
  acting through an even law; the plan is shuffled, so it wanders over the session.
* ``cage_creep_logged`` -- the creep's control, not a kind of its own: the same draw and the same motion as
  ``cage_creep`` at the seed, with the cage's offset logged as ``cage_offset_pct`` (100 u, per sample, 0.1 %
  resolution, no noise), as a rig with a cage-position sensor would. What the loop makes of the state logged tells
  the hidden walk's loss.
* ``bar_bow`` -- logged ``bar_bow_um`` per sample, a dial indicator under the friction bar's centre (0.2 um noise,
  0.1 um resolution). A bar-shape study: the bar rests on its two end supports and a differential screw under its
  centre bends it toward the stator by ``b`` (set per run, uniform in -10..+10 um; negative: away) relative to its
  ends, a parabola along the stroke, ``b (1 - (s / L)^2)`` (``L`` the bar's half length). The preload spring (the
  motor's own rate ``k_p``) turns the added deviation into a preload along the stroke: ``P(s) = P_motor(s) + k_p b
  (1 - (s / L)^2)``, the motor's own at the bar's ends and ``k_p b`` more at its centre. A channel x position
  interaction: the same setting acts most mid-stroke and not at all at the ends.
* ``energy_meter_decoy`` -- a decoy, no effect on the motor: logged ``drive_energy_J`` per sample, the drive's power
  analyser integrating its input power from each run's start (the DAQ program resets its integrator at the trigger):
  ``E(t) = (P_i + P_a (V0 / 324 V)^2) t`` (``P_i`` the amplifier's idle power, drawn in 0.5-1.5 W; ``P_a`` the
  stator's loss at 324 V, drawn in 4-8 W), plus 0.002 J of noise per sample and 0.001 J resolution. It follows the
  time in the run times a function of V0 (and ends each run at a value that grows with the run's duration); an
  energy counted acts on nothing, and it must not be traced.

Pass rule (fixed before any loop ran; the eighth to sixteenth audits'): a kind passes when a regressor of ``WANT``
is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before
and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``drive_energy_J`` is nowhere in ``traced_all`` and ``a
<= 1.02 b``. ``WANT``: the register's column for the dead time (a name holding ``deadtime``); the indicator's column
for the bow (a name holding ``bar_bow``; the position alone is not accepted, the bow's size is the channel's); for
the cage's creep, a regressor of the load's history (its name holds ``lag``, ``prev``, ``last``, ``cum`` or
``hist``) or of the session's clock or order (``time``, ``order``, ``index``, ``count``, ``since``, ``session``,
``segment``, ``break``, ``block`` or ``file``), and not ``time_in_run`` (the run's own clock carries no change
between runs). The control is reported with its own column (``cage_offset``) but not counted.

Usage: python bench/blind_effects_seventeenth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one of
the above or clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run
nrmse before and after, channels considered, CPU of the close loop by ``time.process_time``), plus ``traced_all``
(every traced regressor), ``want`` (the regressors accepted as the effect's) and ``accepted_in_first_two``.
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

KINDS = ("bridge_deadtime", "cage_creep", "bar_bow", "energy_meter_decoy", "cage_creep_logged")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"cage_creep_logged": "cage_creep"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"bridge_deadtime": "deadtime_ns", "cage_creep": None, "bar_bow": "bar_bow_um",
           "energy_meter_decoy": "drive_energy_J", "cage_creep_logged": "cage_offset_pct"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"bridge_deadtime": ("deadtime",),
        "cage_creep": ("lag", "prev", "last", "cum", "hist", "time", "order", "index", "count", "since", "session",
                       "segment", "break", "block", "file"),
        "bar_bow": ("bar_bow",),
        "energy_meter_decoy": (),
        "cage_creep_logged": ("cage_offset",)}
#: names that hold a word of ``WANT`` but are not accepted (the run's own clock)
NOT_WANT = {"cage_creep": ("time_in_run",)}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"energy_meter_decoy": "drive_energy_J"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
DEADTIME_STEP_NS = 10.0   # the gate driver's dead-time register's step [ns]
V0_POWER = 324.0          # the V0 [V] at which the stator's loss is P_a


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the creep's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 197, KINDS.index(src) if src in KINDS else 99])
    if kind == "bridge_deadtime":
        return {"t_d_ns": DEADTIME_STEP_NS * np.round(rng.uniform(0.0, 2700.0, n_runs) / DEADTIME_STEP_NS)}
    if src == "cage_creep":
        return {"m_c_kg": float(rng.uniform(0.15, 0.30)), "J": float(rng.uniform(0.14, 0.28))}
    if kind == "bar_bow":
        return {"b_um": rng.uniform(-10.0, 10.0, n_runs)}
    if kind == "energy_meter_decoy":
        return {"P_i_W": float(rng.uniform(0.5, 1.5)), "P_a_W": float(rng.uniform(4.0, 8.0))}
    return {}


def deadtime_duty(t_d_s, f_Hz: float):
    """The bridge's duty with the dead time ``t_d_s`` [s] at each edge: ``1 - 2 f t_d``."""
    return 1.0 - 2.0 * float(f_Hz) * np.asarray(t_d_s, float)


def deadtime_factor(t_d_s, f_Hz: float):
    """The fundamental's share of the full square wave's with the dead time: ``cos(pi f t_d)``."""
    return np.cos(math.pi * float(f_Hz) * np.asarray(t_d_s, float))


def cage_offsets(loads_kg, m_c_kg: float) -> np.ndarray:
    """The cage's offset at each run's start (a share of its free travel): ``u_0 = 0``, ``u_k = clip(u_(k-1) +
    m_(k-1) / m_c, -1, 1)`` (each stroke creeps it toward its load's side)."""
    u, out = 0.0, []
    for m in loads_kg:
        out.append(u)
        u = min(1.0, max(-1.0, u + float(m) / m_c_kg))
    return np.array(out)


def cage_factor(u, J: float):
    """The guide's Coulomb levels' factor at the cage's offset ``u``: ``1 + J u^2``."""
    return 1.0 + J * np.asarray(u, float) ** 2


def bow_motor(mp, b_m: float):
    """The motor ``mp`` with the bar bent by ``b_m`` at its centre against its ends: the added deviation ``b (1 -
    xi^2) = (2 b / 3) (1 - P2(xi))``, i.e. ``P0 + k_p 2 b / 3`` and the Legendre-P2 coefficient ``- 2 b / 3``."""
    st = mp.stator
    return mp.replace(stator__P0_N=st.P0_N + st.preload_stiffness_N_per_m * 2.0 * b_m / 3.0,
                      stator__bar_dev_2_m=st.bar_dev_2_m - 2.0 * b_m / 3.0)


def energy_J(t_s, V0: float, p: dict):
    """The power analyser's integral [J] at the run's times ``t_s`` (no noise, no rounding): ``(P_i + P_a (V0 /
    324 V)^2) t``."""
    return (p["P_i_W"] + p["P_a_W"] * (float(V0) / V0_POWER) ** 2) * np.asarray(t_s, float)


def run_motor(kind: str, mp, plan, p: dict, k: int, conds):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``conds``: the plan's runs)."""
    if STREAM.get(kind, kind) == "cage_creep":
        u = float(cage_offsets([c[1] for c in conds], p["m_c_kg"])[k])
        f = float(cage_factor(u, p["J"]))
        return mp.replace(slider__mu_sd=mp.slider.mu_sd * f, slider__mu_ss=mp.slider.mu_ss * f)
    if kind == "bar_bow":
        return bow_motor(mp, float(p["b_um"][k]) * 1e-6)
    return mp


def traverse_duty(mp, nominal, plan, V0, load, d, duty: float):
    """One traverse (as :func:`blind_effects.traverse`) with the bridge's ``duty``; the supply set for duty 1."""
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=V_s, duty=float(duty), f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=d, m_load=load,
                 s0=s0)
    return m.run(plan.max_run_s, record=("Slider.s", "Stator.T_stator"),
                 until=lambda mm: mm.value("Slider.at_stop") == d)


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    creep = STREAM.get(kind, kind) == "cage_creep"
    u_all = cage_offsets([c[1] for c in conds], p["m_c_kg"]) if creep else np.zeros(len(conds))
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds_run):
        mp = run_motor(kind, scattered_motor(nominal, factors[k]), plan, p, k, conds)
        duty = float(deadtime_duty(p["t_d_ns"][k] * 1e-9, plan.f_drive_Hz)) if kind == "bridge_deadtime" else 1.0
        if kind == "bridge_deadtime":
            r = traverse_duty(mp, nominal, plan, V, L, d, duty)
        else:
            r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 198, k]).standard_normal(len(t))
        if kind == "bridge_deadtime":
            extra["deadtime_ns"] = np.full(len(t), float(p["t_d_ns"][k]))
        elif kind == "bar_bow":
            extra["bar_bow_um"] = np.round(p["b_um"][k] + 0.2 * noise, 1)
        elif kind == "energy_meter_decoy":
            extra["drive_energy_J"] = np.round(energy_J(t, V, p) + 0.002 * noise, 3)
        elif kind == "cage_creep_logged":
            extra["cage_offset_pct"] = np.full(len(t), round(100.0 * float(u_all[k]), 1))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "bar_dev_2_m": mp.stator.bar_dev_2_m, "mu_sd": mp.slider.mu_sd, "mu_ss": mp.slider.mu_ss,
                        "cage_u": float(u_all[k]), "duty": duty, "t_start_s": t_next,
                        "duration_s": float(r["time"][-1])})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def accepted(kind: str, name: str) -> bool:
    """Whether the traced regressor ``name`` is the kind's (a word of ``WANT`` and none of ``NOT_WANT``)."""
    return be.accepted_by(WANT, NOT_WANT, kind, name)


def verdict(row: dict) -> dict:
    """The pass rule on a printed row (``kind``, ``seed``, ``traced``, ``traced_all``, ``before``, ``after`` in %):
    ``bound`` = sqrt(b0^2 + (b^2 - b0^2) / 4) (the decoy's: 1.02 b), ``attributed`` (a regressor of ``WANT`` among
    the first two; for the decoy, its column nowhere in ``traced_all``) and ``passes`` (both, ``a <= bound``)."""
    return be.audit_verdict(row, B0, DECOY, accepted)


def main(argv=None):
    be.run_audit(argv, __doc__, KINDS, experiment, CHANNEL, WANT, NOT_WANT)


if __name__ == "__main__":
    main()
