#!/usr/bin/env python
"""A twenty-seventh blind audit of the close loop: four more kinds that no injection of the rig and no kind of the
twenty-six earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``, ``bench/blind_effects_third.py``
... ``bench/blind_effects_twentysixth.py``, ``bench/blind_effects_stamps.py``) names, written without the close
loop's code, its effect families and its decision records.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row and
``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan
at a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). Every kind but the decoy sets FMU parameters
per run, the pitch also the slider's load input per run and the voice coil the load input per step, as a law of the
slider's speed of the step before (``bench/blind_effects_fifth.py``'s ``traverse`` and ``StateInput``); the speed
is always the DAQ's derivative of the recorded position. Each kind draws from one random stream of its seed. The
kinds:

* ``pulley_pitch`` -- logged ``pulley_rise_mm`` per sample, the height of the pulley's top above the hook's eye on the
  carriage, read from a digital height gauge on the pulley's post (0.1 mm, no noise: its display read by the DAQ
  program). A load-line study: each pulley (the -position end's carries the positive loads, the +position end's the
  negative ones) rides on a vertical post, and the operator sets both to a height ``h`` before each run, uniform in
  -160..+160 mm (a run without a load logs it too). The wire runs from the hook to the pulley's top ``D`` away along
  the axis (drawn in 0.28-0.36 m, at mid-stroke), pitched by ``beta = atan(h / D)`` (up to +-24-30 deg; positive:
  rising toward the pulley), and the weight hangs below the pulley and moves ``cos beta`` as fast as the slider: the
  carriage feels ``|m| g cos beta`` along the axis, with the weight's inertia ``|m| cos^2 beta``, and ``|m| g sin
  beta`` across it, upward for ``beta > 0``, which the guide's rollers take: the guide's normal load is ``kappa F_p +
  g m_s - g |m| sin beta``. Set through the slider's load input ``m cos beta`` with ``load_inertia`` times ``cos
  beta``, and the guide's Coulomb levels (``mu_sd``, ``mu_ss``) times ``r = 1 - |m| sin beta / m_s`` and its preload
  share ``kappa`` times ``1 / r`` (the guide's friction exact at every preload). A product with the load (nothing
  without one), saturating and asymmetric in the logged height: an even shortfall of the pull, ``1 - cos beta`` (up to
  13 %), and an odd change of the guide's friction, ``mu_sd g |m| sin beta`` (up to +-4.9 mN per 10 g of load). Left
  out: the pitch's change along the stroke (``D`` +- 21 mm: +-6-8 % of ``tan beta``), the wire's inertial pull across
  the axis (``|m| a cos beta sin beta``) and the wire's moment about the guide.
* ``voice_coil_load`` -- logged ``vcm_current_mA`` per sample, the current of a voice-coil actuator as its
  amplifier's current monitor reads it (0.3 mA of noise, 0.1 mA resolution). A load-emulation study: a moving-coil
  linear actuator (its coil on the carriage, its magnet on the frame, along the axis; force constant ``K`` equal to
  its back-EMF constant, drawn in 0.45-0.55 N/A; coil resistance ``R``, drawn in 3.5-4.5 Ohm) pushes on the carriage
  beside the hanging weights. Its linear amplifier is a voltage source whose output ``u`` the operator sets before
  each run (uniform in -0.45..+0.45 V, 1 mV steps; its knob is not logged). The coil carries ``i = (u - K v) / R``
  (``v`` the slider's speed; the coil's electrical time constant, some 0.1 ms, lies under the co-simulation's step
  and is left out) and pushes with ``K i`` toward +position: a constant push of up to +-71 mN (``K u / R``) and a
  viscous drag ``K^2 v / R`` (0.045-0.086 N s/m, 1-2 % of the guide's ``c_r``). The logged current carries the run's
  setting and, within the run, the speed's echo through the back-EMF (up to 44 mA at 0.28 m/s): a cause that is in
  part a consequence of the motion. Set through the slider's load input as the equivalent mass ``m_load - K i / g``
  computed each step from the slider's speed of the step before, with the load's inertia moved into the slider's
  mass and the guide's Coulomb levels and preload share rescaled (:func:`blind_effects.load_in_slider_motor`). The
  coil's few grams of moving mass and its lead's drag are left out.
* ``cold_gas_cloud`` -- no column; a single excursion over the session by a cause nobody logs. At the next bench a
  colleague fills a dewar from a liquid-nitrogen line from ``t_1`` (drawn in 10-40 s of the session's clock) for
  ``T_f`` (drawn in 20-40 s). The cold boil-off sinks and spreads over the bench top: the air around the stator falls
  below the lab's 25 degC toward ``dT_a`` (drawn in 7.5-11.5 K) first order with ``tau_a`` (drawn in 4-10 s) while
  the fill lasts and recovers with it after, and the stator (a 5 g plate held by polymer pads) follows the air first
  order with ``tau_s`` (drawn in 40-80 s). Its deficit is ``y(t) = dT_a (c(t - t_1) - c(t - t_1 - T_f))`` with the
  two lags' step response ``c(u) = 1 - (tau_a exp(-u / tau_a) - tau_s exp(-u / tau_s)) / (tau_a - tau_s)`` for ``u >
  0`` (0 before): a tenth of its peak some 5 s after ``t_1``, the peak (3.0-3.5 K) 4-11 s after the fill ends, then
  a slow recovery (still 1.5-2.4 K at the session's end; seeds 1-3). The modes rise as the stator cools, ``f_b0 -
  c_b y`` and ``f_l0 - c_l y`` (``c_b`` drawn in -30..-20 Hz/K, ``c_l`` in -20..-10 Hz/K; the motor's own at the
  lab's temperature), held at their values at each run's start (a run, 0.15-0.9 s, is short against ``tau_s``). One
  smooth rise and fall on the session's clock, neither monotone nor periodic nor a block of runs, which neither the
  plan's factors nor its pauses carry. The drive in its rack, the bar, the carriage and the guide (massive, or out
  of the cloud) stay at the lab's temperature.
* ``drive_fan_decoy`` -- a decoy, no effect on the motor: logged ``drive_fan_rpm`` per sample, the tachometer of the
  fan on the drive's heat sink (pulses counted over a gate: 0.5 % jitter, 10 rpm resolution; a stopped fan reads
  0). The heat sink warms with the drive's losses: ``x`` above its idle temperature (0 at the session's start)
  follows ``q = dT_a (V0 / 324 V)^2`` while a run drives and 0 in the pauses, first order with ``tau_h`` (``dT_a``
  drawn in 25-40 K, ``tau_h`` in 60-120 s). The fan's controller reads ``x`` every 0.1 s of the session's clock and
  switches the fan between off, low and high with a hysteresis: up a level at ``x_1`` (drawn in 0.8-1.6 K) and at
  ``x_1 + dx`` (``dx`` drawn in 1.0-1.6 K), down a level ``h`` (drawn in 0.2-0.4 K) below each; the fan follows the
  command (0, ``rpm_lo`` drawn in 1800-2400 rpm, ``rpm_hi`` in 3600-4400 rpm) first order with ``tau_f`` (drawn in
  1.5-3 s; at rest at the start). A staircase of the drive's heat, so of the session's clock and the plan's V0
  history (off until run 14-26, low until run 30-59, then high at seeds 1-3); the fan's air leaves the drive's rack
  at its back, away from the rig, so it acts on nothing and must not be traced.

Sizes (measured on the made data: each TEST run's mean speed over its evaluation samples against the clean case's
same run, :func:`speed_change` (``bench/blind_effects_twentysixth.py``'s); its sd over the 16 TEST runs, and its
root mean square, at seeds 1 / 2 / 3, from the ``--data-only`` cases): ``pulley_pitch`` 2.54 / 1.77 / 2.61 % (2.64
/ 1.77 / 2.98 %), ``voice_coil_load`` 1.89 / 1.87 / 2.10 % (2.20 / 1.88 / 2.31 %), ``cold_gas_cloud`` 1.49 / 2.61 /
3.00 % (2.37 / 3.58 / 4.18 %); the decoy's runs are the clean case's.

Pass rule (fixed before any loop ran; the eighth to twenty-sixth audits'): a kind passes when a regressor of
``WANT`` is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse
before and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``:
3.037 / 2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``drive_fan`` is nowhere in ``traced_all`` and
``a <= 1.02 b``. ``WANT``: for the pitch, the height gauge's column (a name holding ``pulley_rise``: the height
itself or a product or shape of it the loop derives); for the voice coil, the current's column (a name holding
``vcm_current``); for the cloud, a regressor of the session's clock or the run count, or of a block, segment, regime,
drift or trend of them (a name holding ``time``, ``session``, ``clock``, ``elapsed``, ``index``, ``count``,
``order``, ``block``, ``segment``, ``regime``, ``drift`` or ``trend``), none holding ``time_in_run`` or ``in_run``
(the run's own clock), ``onset`` or ``start`` (the run's start), ``break`` or ``pause`` (the plan's pauses are all
alike), ``_lag``, ``prev`` or ``last`` (the runs' conditions before), ``voltage``, ``load``, ``direction``,
``speed``, ``position`` or ``frequency`` (the cloud follows none of the plan's factors, nor the motion).

Usage: python bench/blind_effects_twentyseventh.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND:
one of the above or clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST
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
import blind_effects_twentysixth as b26  # noqa: E402

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics.params import G_M_S2  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("pulley_pitch", "voice_coil_load", "cold_gas_cloud", "drive_fan_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"pulley_pitch": "pulley_rise_mm", "voice_coil_load": "vcm_current_mA", "cold_gas_cloud": None,
           "drive_fan_decoy": "drive_fan_rpm"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"pulley_pitch": ("pulley_rise",),
        "voice_coil_load": ("vcm_current",),
        "cold_gas_cloud": ("time", "session", "clock", "elapsed", "index", "count", "order", "block", "segment",
                           "regime", "drift", "trend"),
        "drive_fan_decoy": ()}
#: names that hold a word of ``WANT`` but are not accepted (for the cloud the run's own clock, the run's start, the
#: plan's pauses, the runs' conditions before, the plan's factors, the motion and the frequency)
NOT_WANT = {"cold_gas_cloud": ("time_in_run", "in_run", "onset", "start", "break", "pause", "_lag", "prev", "last",
                               "voltage", "load", "direction", "speed", "position", "frequency")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"drive_fan_decoy": "drive_fan"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
PULLEY_RISE_MM = 160.0           # the pulley's height above the hook per run, uniform in +-this [mm]
VCM_U_V = 0.45                   # the voice coil amplifier's output per run, uniform in +-this [V]
VCM_NOISE_MA = 0.3               # the current monitor's noise [mA]
FAN_TICK_S = 0.1                 # the fan controller's sampling interval [s]
FAN_HEAT_REF_V = 324.0           # the amplitude at which the heat sink's steady rise is dT_a
FAN_JITTER = 0.005               # the tachometer's relative jitter


speed_change = b26.speed_change


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 291, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "pulley_pitch":
        return {"D_m": float(rng.uniform(0.28, 0.36)),
                "h_mm": np.round(rng.uniform(-PULLEY_RISE_MM, PULLEY_RISE_MM, n_runs), 1)}
    if kind == "voice_coil_load":
        return {"K_N_A": float(rng.uniform(0.45, 0.55)), "R_ohm": float(rng.uniform(3.5, 4.5)),
                "u_V": np.round(rng.uniform(-VCM_U_V, VCM_U_V, n_runs), 3)}
    if kind == "cold_gas_cloud":
        return {"t_1_s": float(rng.uniform(10.0, 40.0)), "T_f_s": float(rng.uniform(20.0, 40.0)),
                "dT_a_K": float(rng.uniform(7.5, 11.5)), "tau_a_s": float(rng.uniform(4.0, 10.0)),
                "tau_s_s": float(rng.uniform(40.0, 80.0)), "c_b_Hz_K": float(rng.uniform(-30.0, -20.0)),
                "c_l_Hz_K": float(rng.uniform(-20.0, -10.0))}
    if kind == "drive_fan_decoy":
        return {"dT_a_K": float(rng.uniform(25.0, 40.0)), "tau_h_s": float(rng.uniform(60.0, 120.0)),
                "x_1_K": float(rng.uniform(0.8, 1.6)), "dx_K": float(rng.uniform(1.0, 1.6)),
                "h_K": float(rng.uniform(0.2, 0.4)), "rpm_lo": float(rng.uniform(1800.0, 2400.0)),
                "rpm_hi": float(rng.uniform(3600.0, 4400.0)), "tau_f_s": float(rng.uniform(1.5, 3.0))}
    return {}


def pitch_rad(h_mm, D_m: float):
    """The wire's pitch from the hook to the pulley [rad] (positive: rising toward the pulley): ``atan(h / D)``."""
    return np.arctan(np.asarray(h_mm, float) * 1e-3 / D_m)


def pitch_motor(mp, L: float, beta: float):
    """The motor and the load input [kg] of a run with the load ``L`` hung on a wire pitched ``beta`` [rad]: the
    load input ``L cos beta`` with ``load_inertia`` times ``cos beta`` (the weight's pull along the axis, its inertia
    ``|L| cos^2 beta``), and the guide's Coulomb levels times ``r = 1 - |L| sin beta / m_s`` and its preload share
    times ``1 / r`` (the guide's normal load ``kappa F_p + g m_s - g |L| sin beta``). A run without a load hangs no
    wire: the motor's own."""
    if L == 0:
        return mp, L
    sl = mp.slider
    r = 1.0 - abs(L) * math.sin(beta) / sl.mass_kg
    return (mp.replace(slider__load_inertia=sl.load_inertia * math.cos(beta), slider__mu_sd=sl.mu_sd * r,
                       slider__mu_ss=sl.mu_ss * r, slider__kappa=sl.kappa / r), L * math.cos(beta))


def vcm_current_A(u_V, v_m_s, K_N_A: float, R_ohm: float):
    """The voice coil's current [A] at the amplifier's output ``u_V`` and the slider's speed ``v_m_s``: ``(u - K v) /
    R`` (the back-EMF ``K v``)."""
    return (np.asarray(u_V, float) - K_N_A * np.asarray(v_m_s, float)) / R_ohm


def vcm_force_N(u_V, v_m_s, K_N_A: float, R_ohm: float):
    """The voice coil's force on the slider [N], positive toward +position: ``K i``."""
    return K_N_A * vcm_current_A(u_V, v_m_s, K_N_A, R_ohm)


def cascade_step(t_s, tau_a: float, tau_s: float):
    """The unit step response of two first-order lags in series (``tau_a``, then ``tau_s``) at ``t_s`` after the
    step (0 before it): ``1 - (tau_a exp(-t / tau_a) - tau_s exp(-t / tau_s)) / (tau_a - tau_s)``."""
    t = np.asarray(t_s, float)
    u = np.maximum(t, 0.0)
    y = 1.0 - (tau_a * np.exp(-u / tau_a) - tau_s * np.exp(-u / tau_s)) / (tau_a - tau_s)
    return np.where(t > 0, y, 0.0)


def stator_dip_K(t_s, p: dict):
    """The stator's temperature below the lab's [K] at the session's times ``t_s``: ``dT_a`` times the cascade's
    response to the cloud from ``t_1`` to ``t_1 + T_f``, ``cascade_step(t - t_1) - cascade_step(t - t_1 - T_f)``."""
    t = np.asarray(t_s, float)
    a, s = p["tau_a_s"], p["tau_s_s"]
    return p["dT_a_K"] * (cascade_step(t - p["t_1_s"], a, s) - cascade_step(t - p["t_1_s"] - p["T_f_s"], a, s))


def cloud_motor(mp, y_K: float, p: dict):
    """The stator ``y_K`` below the lab's temperature: ``f_b0 - c_b y`` and ``f_l0 - c_l y`` (``c`` per kelvin)."""
    st = mp.stator
    return mp.replace(stator__f_b0_Hz=st.f_b0_Hz - p["c_b_Hz_K"] * y_K,
                      stator__f_l0_Hz=st.f_l0_Hz - p["c_l_Hz_K"] * y_K)


def run_motor(kind: str, mp, p: dict, k: int, L: float, t_start: float = 0.0):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp``, its load input [kg] and its load law (None: the
    load input) (``L`` the run's load, ``t_start`` its start on the session's clock [s])."""
    if kind == "pulley_pitch":
        mp, load_in = pitch_motor(mp, L, float(pitch_rad(p["h_mm"][k], p["D_m"])))
        return mp, load_in, None
    if kind == "voice_coil_load":
        u, K, R = float(p["u_V"][k]), p["K_N_A"], p["R_ohm"]
        return (be.load_in_slider_motor(mp, L, kind), L,
                lambda t, s, v: L - float(vcm_force_N(u, v, K, R)) / G_M_S2)
    if kind == "cold_gas_cloud":
        return cloud_motor(mp, float(stator_dip_K(t_start, p)), p), L, None
    return mp, L, None


def heat_path(t_s, spans, dT_a: float, tau_h: float) -> np.ndarray:
    """The drive's heat sink above its idle temperature [K] at the session's times ``t_s >= 0`` (0 at the session's
    start): toward ``q = dT_a (V0 / 324 V)^2`` while a run of ``spans`` (``(t_on, t_off, V0)``, in order) drives,
    toward 0 otherwise, first order with ``tau_h``."""
    pieces = [(0.0, 0.0, 0.0)]  # (start, heat at the start, target) of each stretch of the session
    x, t0 = 0.0, 0.0
    for t_on, t_off, V0 in spans:
        x *= math.exp(-(t_on - t0) / tau_h)
        q = dT_a * (V0 / FAN_HEAT_REF_V) ** 2
        pieces.append((t_on, x, q))
        x = q + (x - q) * math.exp(-(t_off - t_on) / tau_h)
        pieces.append((t_off, x, 0.0))
        t0 = t_off
    start, heat, target = (np.array(c) for c in zip(*pieces))
    t = np.asarray(t_s, float)
    j = np.searchsorted(start, t, side="right") - 1
    return target[j] + (heat[j] - target[j]) * np.exp(-(t - start[j]) / tau_h)


def fan_levels(x_K, x_1: float, dx: float, h: float) -> np.ndarray:
    """The fan controller's level (0 off, 1 low, 2 high) at each of its readings ``x_K`` of the heat sink, from off:
    up a level at ``x_1`` and at ``x_1 + dx``, down a level at ``h`` below each."""
    out, level = [], 0
    up, down = (x_1, x_1 + dx), (x_1 - h, x_1 + dx - h)
    for x in np.asarray(x_K, float):
        while level < 2 and x >= up[level]:
            level += 1
        while level > 0 and x <= down[level - 1]:
            level -= 1
        out.append(level)
    return np.array(out, int)


def fan_rpm(t_s, spans, p: dict) -> np.ndarray:
    """The fan's speed [rpm] at the session's times ``t_s``: the controller reads the heat sink (:func:`heat_path`)
    every 0.1 s from the session's start and commands 0, ``rpm_lo`` or ``rpm_hi`` (:func:`fan_levels`); the fan
    follows the command first order with ``tau_f`` (at rest at the start)."""
    t = np.asarray(t_s, float)
    n = int(np.floor(t.max() / FAN_TICK_S + 1e-9)) + 1 if t.size else 0
    ticks = FAN_TICK_S * np.arange(n)
    lev = fan_levels(heat_path(ticks, spans, p["dT_a_K"], p["tau_h_s"]), p["x_1_K"], p["dx_K"], p["h_K"])
    cmd = np.array([0.0, p["rpm_lo"], p["rpm_hi"]])[lev]
    a = math.exp(-FAN_TICK_S / p["tau_f_s"])
    w = np.zeros(n)
    for j in range(1, n):
        w[j] = cmd[j - 1] + (w[j - 1] - cmd[j - 1]) * a
    j = np.floor(t / FAN_TICK_S + 1e-9).astype(int)
    return cmd[j] + (w[j] - cmd[j]) * np.exp(-(t - ticks[j]) / p["tau_f_s"])


def fan_logged_rpm(t_s, spans, p: dict, noise) -> np.ndarray:
    """The logged tachometer [rpm]: :func:`fan_rpm` times ``1 + 0.005 noise`` (the gate's jitter), to 10 rpm."""
    return np.round(fan_rpm(t_s, spans, p) * (1.0 + FAN_JITTER * np.asarray(noise)) / 10.0) * 10.0


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    conds_run = conds[:first] if first else conds
    frames, per_run, spans, noises, t_next = [], [], [], [], 0.0
    for k, (V, L, d) in enumerate(conds_run):
        mp, load_in, load_law = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, L, t_next)
        r = b5.traverse(mp, nominal, plan, V, load_in, d, load_law=load_law, record=b5.POSITION_AND_SPEED)[0]
        idx = np.arange(0, len(r["time"]), every)
        t, s, v = r["time"][idx], r["Slider.s"][idx], r["Slider.v"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 292, k]).standard_normal(len(t))
        if kind == "pulley_pitch":
            extra["pulley_rise_mm"] = np.full(len(t), float(p["h_mm"][k]))
        elif kind == "voice_coil_load":
            i_mA = 1000.0 * vcm_current_A(p["u_V"][k], v, p["K_N_A"], p["R_ohm"])
            extra["vcm_current_mA"] = np.round(i_mA + VCM_NOISE_MA * noise, 1)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        noises.append(noise)
        duration = float(r["time"][-1])
        spans.append((t_next, t_next + duration, V))
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p, "f_l0_Hz": mp.stator.f_l0_Hz,
                        "f_b0_Hz": mp.stator.f_b0_Hz, "mass_kg": mp.slider.mass_kg, "mu_sd": mp.slider.mu_sd,
                        "mu_ss": mp.slider.mu_ss, "kappa": mp.slider.kappa, "load_inertia": mp.slider.load_inertia,
                        "load_in_kg": load_in, "t_start_s": t_next, "duration_s": duration})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    if kind == "drive_fan_decoy":  # the tachometer over the session (the fan acts on nothing)
        for out, noise in zip(frames, noises):
            out["drive_fan_rpm"] = fan_logged_rpm(out[dataio.TIME].to_numpy(), spans, p, noise)
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
