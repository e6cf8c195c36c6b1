#!/usr/bin/env python
"""An eighteenth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the seventeen earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_seventeenth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``lining_durometer`` -- logged ``lining_shore_A`` per sample, a durometer's reading of the lining strip under the
  tip (0.3 Shore A of noise per sample, 0.1 resolution). A lining-formulation study: the friction bar carries its
  lining as a cast polyurethane strip clipped into a slot, and the operator clips in another strip before each run
  (strips cast with different hardener ratios, so of different hardness; the filler that sets the friction is the
  same in all). The hardness per run is uniform in 78-95 Shore A. The contact layer's stiffness ``k_e`` scales with
  the strip's Young's modulus, which Gent's relation gives from the Shore A hardness ``S``, ``E(S) = 0.0981 (56 +
  7.62336 S) / (0.137505 (254 - 2.54 S))`` MPa (a rational law with a pole at S = 100): ``k_e(S) = k_e E(S) / E(88)``,
  the motor's own ``k_e`` at the lab's usual strip (88 Shore A), 0.49-2.58 times it over the range. The contact
  layer's stiffness sets how long and how hard the tip presses in each cycle; the speed's answer to it depends on
  V0, the load and the direction, and is not monotone.
* ``tap_relay`` -- no column; a change between runs through a hysteresis driven by the plan's own sequence. The
  drive's linear amplifier feeds the tank through an output transformer with two taps and picks its tap on each
  new V0 setting with a hysteresis (a Schmitt trigger on the commanded V0): the high tap at a V0 of 300 V or more,
  the low tap at 240 V or less, and between them it keeps the tap it has (it powers up on the low tap before the
  first run). The operator's supply table was measured in one upward sweep (220, 255, 290, 324 V), so its 220-290 V
  rows hold on the low tap and its 324 V row on the high tap. The high tap's ratio is off the low tap's by ``e``
  (drawn in -7..-4 %), so a run at 255 or 290 V gets ``(1 + e)`` of its V0 when the amplifier still sits on the high
  tap: after a 324 V run and no 220 V run since. ``voltage_V`` logs the plan's V0. The state is a function of the
  order of the plan's V0s, not of time and not of the run's own setting.
* ``tap_relay_logged`` -- the relay's control, not a kind of its own: the same draw and the same motion as
  ``tap_relay`` at the seed, with the amplifier's tap logged as ``amp_tap`` (1 low, 2 high, per sample, no noise), as a
  drive that reports its range would. What the loop makes of the state logged tells the hidden relay's loss.
* ``air_knife`` -- logged ``air_speed_m_s`` per sample, a hot-wire anemometer in an air knife's jet (0.1 m/s of
  noise, 0.01 m/s resolution), varying within a run. An air knife at the stroke's +position end blows dry air along
  the axis toward -position to keep wear debris off the friction bar. Its solenoid valve is cycled by its own timer
  on the session clock (period ``P`` drawn in 0.5-1.0 s, open for a share ``D`` drawn in 0.4-0.6 of it, at a phase
  drawn uniform), and the jet's speed follows the valve first order (time constant ``tau`` drawn in 20-50 ms) toward
  ``u_on`` (drawn in 8-11 m/s) when open and 0 when shut. The jet presses on the carriage's face (30 x 40 mm, a flat
  plate, drag coefficient 1.2) with ``F = rho C_d A u^2 / 2`` toward -position (air at 1.2 kg/m^3; the slider's own
  speed, under 0.3 m/s, is left out of the relative wind): 0.055-0.105 N with the valve open, acting at each sample as
  a force on the slider (through the slider's load input as the equivalent mass ``m_load + F / g``; the load's
  inertia moved into the slider's mass and the guide's Coulomb levels and preload share rescaled so that the guide's
  friction, the moving mass and the load's force are the motor's: see :func:`knife_motor`).
* ``phase_meter_decoy`` -- a decoy, no effect on the motor: logged ``drive_phase_deg`` per sample, the phase of the
  drive's CH2 against its CH1 as the drive's power analyser reads it. The drive holds its channels in quadrature and
  swaps them for backward runs (+90 deg forward, -90 deg backward); the analyser's phase error grows with the
  amplitude it reads, so it shows ``d (90 deg + eps (V0 / 324 V)^2)`` (``eps`` drawn in 1.5-3.0 deg; the relay
  swaps the channels in the pause and the analyser has settled when the run's record starts), 0.1 deg of noise and
  0.01 deg resolution. It follows the direction (its sign) and V0 (its size), not the run's duration or speed; a
  meter's reading acts on nothing, and it must not be traced.

Pass rule (fixed before any loop ran; the eighth to seventeenth audits'): a kind passes when a regressor of ``WANT``
is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before
and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``drive_phase_deg`` is nowhere in ``traced_all`` and ``a
<= 1.02 b``. ``WANT``: the durometer's column for the lining (a name holding ``shore``); the anemometer's column for
the air knife (a name holding ``air_speed``); for the tap relay, a regressor of the V0's history (its name holds
``lag``, ``prev``, ``last``, ``hist``, ``mean``, ``avg``, ``ewm``, ``tap`` or ``range``) and none of the load's, the
direction's, the speed's, the position's or the run's own clock (``load``, ``direction``, ``speed``, ``position``,
``time_in_run``): the session clock is not accepted either, the state follows the plan's order of V0s, not time.
The control is reported with its own column (``amp_tap``) but not counted.

Usage: python bench/blind_effects_eighteenth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one of
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

KINDS = ("lining_durometer", "tap_relay", "air_knife", "phase_meter_decoy", "tap_relay_logged")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"tap_relay_logged": "tap_relay"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"lining_durometer": "lining_shore_A", "tap_relay": None, "air_knife": "air_speed_m_s",
           "phase_meter_decoy": "drive_phase_deg", "tap_relay_logged": "amp_tap"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"lining_durometer": ("shore",),
        "tap_relay": ("lag", "prev", "last", "hist", "mean", "avg", "ewm", "tap", "range"),
        "air_knife": ("air_speed",),
        "phase_meter_decoy": (),
        "tap_relay_logged": ("amp_tap",)}
#: names that hold a word of ``WANT`` but are not accepted (another input's history, the run's own clock)
NOT_WANT = {"tap_relay": ("load", "direction", "speed", "position", "time_in_run")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"phase_meter_decoy": "drive_phase_deg"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
SHORE_RANGE = (78.0, 95.0)   # the strips' Shore A hardness per run
SHORE_REF = 88.0             # the lab's usual strip: the motor's own k_e
TAP_UP_V = 300.0             # the amplifier takes its high tap at this V0 or more
TAP_DOWN_V = 240.0           # and its low tap at this V0 or less
AIR_RHO = 1.2                # air's density [kg/m^3]
PLATE_CD = 1.2               # a flat plate's drag coefficient
PLATE_AREA_M2 = 0.030 * 0.040
G = 9.81
PHASE_V0_REF = 324.0         # the V0 at which the analyser's phase error is eps


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the relay's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 199, KINDS.index(src) if src in KINDS else 99])
    if kind == "lining_durometer":
        return {"shore": rng.uniform(*SHORE_RANGE, n_runs)}
    if src == "tap_relay":
        return {"e": float(rng.uniform(-0.07, -0.04))}
    if kind == "air_knife":
        return {"u_on": float(rng.uniform(8.0, 11.0)), "P_s": float(rng.uniform(0.5, 1.0)),
                "D": float(rng.uniform(0.4, 0.6)), "phase": float(rng.uniform(0.0, 1.0)),
                "tau_s": float(rng.uniform(0.02, 0.05))}
    if kind == "phase_meter_decoy":
        return {"eps_deg": float(rng.uniform(1.5, 3.0))}
    return {}


def gent_modulus_MPa(shore_a):
    """Gent's relation: Young's modulus [MPa] of a rubber of Shore A hardness ``S``, ``0.0981 (56 + 7.62336 S) /
    (0.137505 (254 - 2.54 S))``."""
    S = np.asarray(shore_a, float)
    return 0.0981 * (56.0 + 7.62336 * S) / (0.137505 * (254.0 - 2.54 * S))


def lining_k_e(k_e_ref: float, shore_a):
    """The contact layer's stiffness [N/m] of a strip of hardness ``S``: ``k_e E(S) / E(88)``."""
    return float(k_e_ref) * gent_modulus_MPa(shore_a) / gent_modulus_MPa(SHORE_REF)


def tap_states(V0s) -> np.ndarray:
    """The amplifier's tap at each run (0 low, 1 high): high at ``V0 >= 300 V``, low at ``V0 <= 240 V``, else the
    tap of the run before (low before the first run)."""
    h, out = 0, []
    for V in V0s:
        if V >= TAP_UP_V:
            h = 1
        elif V <= TAP_DOWN_V:
            h = 0
        out.append(h)
    return np.array(out, int)


def tap_gain(V0: float, tap: int, e: float) -> float:
    """The share of its V0 a run gets: ``1 + e`` on the high tap below 300 V (the table's rows of the low tap), else
    1."""
    return 1.0 + e if (tap == 1 and V0 < TAP_UP_V) else 1.0


def valve_events(p: dict, t_end: float) -> tuple[np.ndarray, np.ndarray]:
    """The valve's switching times [s] on the session clock from five periods before 0 to past ``t_end``, and its
    state after each (1 open, 0 shut): open at ``(n - phase) P``, shut at ``(n - phase + D) P``."""
    P, D, ph = p["P_s"], p["D"], p["phase"]
    n = np.arange(-5, int(math.ceil(t_end / P)) + 3)
    t = np.concatenate([(n - ph) * P, (n - ph + D) * P])
    state = np.concatenate([np.ones(n.size, int), np.zeros(n.size, int)])
    order = np.argsort(t, kind="stable")
    return t[order], state[order]


def valve_table(p: dict, t_end: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(events, states, speeds)``: :func:`valve_events` up to ``t_end`` and the jet's speed [m/s] at each event,
    first order (``tau``) toward ``u_on`` while the valve is open and toward 0 while it is shut, from rest at the
    first event (five periods before 0)."""
    ev, st = valve_events(p, t_end)
    u_on, tau = p["u_on"], p["tau_s"]
    u_ev = np.zeros(ev.size)
    for i in range(1, ev.size):
        target = u_on * st[i - 1]
        u_ev[i] = target + (u_ev[i - 1] - target) * math.exp(-(ev[i] - ev[i - 1]) / tau)
    return ev, st, u_ev


def air_speed(t_s, p: dict, table=None) -> np.ndarray:
    """The jet's speed [m/s] at the session times ``t_s`` (no noise), from the last event before each time:
    ``target + (u_event - target) exp(-(t - t_event) / tau)`` (``table``: :func:`valve_table` reaching past the
    times; default made here)."""
    t_s = np.asarray(t_s, float)
    ev, st, u_ev = table if table is not None else valve_table(p, float(np.max(t_s)) if t_s.size else 0.0)
    i = np.searchsorted(ev, t_s, side="right") - 1
    target = p["u_on"] * st[i]
    return target + (u_ev[i] - target) * np.exp(-(t_s - ev[i]) / p["tau_s"])


def air_force_N(u):
    """The jet's push [N] on the carriage's face: ``rho C_d A u^2 / 2``."""
    return 0.5 * AIR_RHO * PLATE_CD * PLATE_AREA_M2 * np.asarray(u, float) ** 2


def knife_motor(mp, L: float):
    """The motor ``mp`` for a run with load ``L`` whose load input will carry the jet's push
    (:func:`blind_effects.load_in_slider_motor`: the guide's friction, the moving mass and the load's force are the
    motor's). Needs ``pulley_mu = 0``."""
    return be.load_in_slider_motor(mp, L, "air_knife")


def phase_reading_deg(t_s, V0: float, d: int, p: dict):
    """The analyser's phase [deg] at the run's times ``t_s`` (no noise, no rounding): ``d (90 + eps (V0 / 324
    V)^2)`` at every time."""
    t = np.asarray(t_s, float)
    return np.full(t.shape, d * (90.0 + p["eps_deg"] * (float(V0) / PHASE_V0_REF) ** 2))


def run_motor(kind: str, mp, p: dict, k: int, L: float):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``L`` the run's load)."""
    if kind == "lining_durometer":
        return mp.replace(interface__k_e_N_per_m=lining_k_e(mp.interface.k_e_N_per_m, p["shore"][k]))
    if kind == "air_knife":
        return knife_motor(mp, L)
    return mp


def traverse_in(mp, nominal, plan, V0, load, d, gain: float = 1.0, m_load=None):
    """One traverse (as :func:`blind_effects.traverse`) with the supply set for ``V0`` times ``gain`` (the tap's
    share) and the load input ``m_load`` (a function of the run's time; default the run's ``load``)."""
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC)) * gain
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=d,
                 m_load=load if m_load is None else m_load, s0=s0)
    return m.run(plan.max_run_s, record=("Slider.s", "Stator.T_stator"),
                 until=lambda mm: mm.value("Slider.at_stop") == d)


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    relay = STREAM.get(kind, kind) == "tap_relay"
    taps = tap_states([c[0] for c in conds]) if relay else np.zeros(len(conds), int)
    conds_run = conds[:first] if first else conds
    table = valve_table(p, len(conds) * (plan.max_run_s + plan.pause_s) + 1.0) if kind == "air_knife" else None
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds_run):
        mp = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, L)
        gain = tap_gain(V, int(taps[k]), p["e"]) if relay else 1.0
        law = None
        if kind == "air_knife":
            law = (lambda t, L=L, t0=t_next: L + float(air_force_N(air_speed([t0 + t], p, table))[0]) / G)
        r = traverse_in(mp, nominal, plan, V, L, d, gain, law)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 200, k]).standard_normal(len(t))
        if kind == "lining_durometer":
            extra["lining_shore_A"] = np.round(p["shore"][k] + 0.3 * noise, 1)
        elif kind == "air_knife":
            extra["air_speed_m_s"] = np.round(air_speed(t_next + t, p, table) + 0.1 * noise, 2)
        elif kind == "phase_meter_decoy":
            extra["drive_phase_deg"] = np.round(phase_reading_deg(t, V, d, p) + 0.1 * noise, 2)
        elif kind == "tap_relay_logged":
            extra["amp_tap"] = np.full(len(t), 1 + int(taps[k]))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "k_e_N_per_m": mp.interface.k_e_N_per_m, "mass_kg": mp.slider.mass_kg,
                        "mu_sd": mp.slider.mu_sd, "kappa": mp.slider.kappa, "tap": int(taps[k]), "gain": gain,
                        "t_start_s": t_next, "duration_s": float(r["time"][-1])})
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
