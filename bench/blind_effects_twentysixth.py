#!/usr/bin/env python
"""A twenty-sixth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the twenty-five earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_twentyfifth.py``, ``bench/blind_effects_stamps.py``)
names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row and
``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan
at a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). Every kind sets FMU parameters per run, the
incline also the slider's load input per run (an equivalent mass) and the foldback the drive's supply per run
(``bench/blind_effects_fifth.py``'s ``traverse``); the speed is always the DAQ's derivative of the recorded position.
Each kind draws from one random stream of its seed. The kinds:

* ``axis_incline`` -- logged ``base_level_mrad`` per sample, an electronic level on the axis's base plate (0.02 mrad
  of noise, 0.01 mrad resolution) whose zero, set on the lab's bench, is off by ``z_0`` (drawn in -0.3..+0.3 mrad).
  A mounting-orientation study: the whole axis (base plate, guide, stator holder and both pulleys) stands on a
  tilting table whose pitch about the lateral axis the operator sets before each run, ``theta`` uniform in -45..+45
  mrad (+-2.6 deg; positive: the +position end raised). Gravity pulls the slider (the carriage with the friction
  bar and the scale, the motor's ``m_s`` = 0.12 kg) down the slope with ``m_s g sin theta``, toward -position for
  ``theta > 0``, as a positive load pulls. The hanging weight pulls its cable over its pulley with ``|m| g`` as before
  (the cable leaves the pulley vertically whatever the base's pitch) and moves with the slider as before. Set through
  the slider's load input as the equivalent mass ``m_load + m_s sin theta``, with the load's inertia moved into the
  slider's mass and the guide's Coulomb levels and preload share rescaled (:func:`blind_effects.load_in_slider_motor`:
  the moving mass and the guide's friction are the motor's). Up to 5.4 g of equivalent load either way, linear in
  ``sin theta`` and odd in it: it slows the runs up the slope and speeds those down it (a channel x direction
  interaction). The guide's normal load ``g m_s cos theta`` (0.999 of the motor's or more) and the stator holder's
  own weight across the preload are left out.
* ``amp_thermal_foldback`` -- no column; a change over the session through the drive's own protection. The drive's
  bridge and the tank's inductor sit on one small heat sink, and the drive's controller folds its bus back linearly
  above a knee of the heat sink's temperature (as a power supply's thermal foldback does), so the stator's amplitude
  is ``g V0`` with ``g = 1 - k_d max(0, x - x_k)`` (``k_d`` drawn in 1.5-3 % per K). ``x`` is the heat sink's
  temperature above its idle level (0 at the session's start: the drive has idled since it was switched on); it
  follows the drive's losses first order with ``tau_h`` (drawn in 80-160 s), toward ``q = dT_a (g V0 / 324 V)^2``
  while a run drives the stator (``dT_a``, the rise a steady drive at 324 V would give, drawn in 30-45 K: 3-4 W of
  the bridge's and the inductor's losses over some 10 K/W) and toward 0 in the pauses. The knee lies ``x_k`` above
  the idle level (drawn in 0.5-1.5 K: a drive that idles in a warm rack with its foldback set for a cool one). The
  controller sets the bus at each run's enable from the heat sink's temperature then and holds it through the run (a
  run, 0.15-0.9 s, is short against ``tau_h``: it moves ``x`` by under 0.2 K at seed 1). Over the session (some 92
  s) ``x`` climbs to 3.3-3.9 K (measured at seeds 1-3): the first 17-20 runs are untouched, then the amplitude falls
  along the session to about 5 % below the setting, faster after stretches of high-V0 runs. The operator's supply
  table and ``voltage_V`` are the plan's; the clock shows nothing but the plan's pauses.
* ``grip_node_offset`` -- logged ``holder_slide_mm`` per sample, a digital micrometer on the stator holder's slide (1
  um resolution, no noise: its display read by the DAQ program). A mounting study: the holder grips the plate between
  two stiff polymer pads on its thickness faces, nominally at the plate's centre, where both L1 (axial displacement
  ``cos(pi x / L)``) and B2 (antisymmetric) have a node of their displacement; the holder slides along the plate on a
  dovetail, and the operator sets it before each run to a reading ``u`` uniform in -1.2..+1.2 mm. The micrometer was
  zeroed by eye on the plate's centre mark, off by ``x_0`` (drawn in -0.15..+0.15 mm), so the pads sit ``delta = u -
  x_0`` off the nodes. Off a node the plate moves under the pads, which shear with the stiffness ``k_s`` (both pads,
  drawn in 0.7-1.2 x 10^7 N/m) and the loss factor ``eta`` (drawn in 0.05-0.10): each mode ``i`` gains the modal
  stiffness ``k_s phi_i(x_p)^2`` and a hysteretic loss ``eta`` times it (``x_p = L / 2 + delta``; ``phi_l = cos(pi x /
  L)``; ``phi_b`` the unloaded B2 shape ``D (sin(k xi) + c sinh(k xi))``, ``xi = x - L / 2``, ``k = 7.8532 / L``, ``c
  = sin(k L / 2) / sinh(k L / 2)``, normalised to ``int_0^L phi_b^2 dx = L``: about ``-360 delta / m`` near the
  centre). With ``e_i = k_s phi_i(x_p)^2 / K_i`` (``K_i = M_i (2 pi f_i0)^2``, ``M_l = rho S L / 2``, ``M_b = rho S
  L``) the modes are ``f_i0 sqrt(1 + e_i)`` and ``(zeta_i + eta e_i / 2) / sqrt(1 + e_i)``: at 1 mm off, B2 rises by
  46-78 Hz toward the drive and L1 by 8-13 Hz away from it, their damping by about 1 % or less. An even law of the
  logged reading about ``x_0``, near-quadratic (the motor's own at ``u = x_0``, as it was identified). The preload's
  change of B2's shape is left out.
* ``breath_co2_decoy`` -- a decoy, no effect on the motor: logged ``co2_ppm`` per sample, the NDIR CO2 sensor of an
  environment logger on the rig's bench. The air at it carries the room's CO2, climbing with the operator's
  breathing, ``C_0 + r t`` (``C_0`` drawn in 450-650 ppm, ``r`` in 0.1-0.4 ppm/s; ``t`` the session's clock), plus a
  plume each time the operator leans over the rig to change the weight (hangs, swaps or removes one: the first run
  with a load and each run whose load differs from the run before's, at the start of the pause before it), ``A_h
  exp(-(t - t_h) / tau_p)`` from its time ``t_h`` on (``A_h`` drawn per change in 20-60 ppm, ``tau_p`` in 4-8 s). The
  gas diffuses into the sensor's cell, first order with ``tau_s`` (drawn in 15-30 s; at ``C_0`` before the session),
  so it reads ``C_0 + r (t - tau_s (1 - exp(-t / tau_s)))`` plus ``A_h tau_p / (tau_p - tau_s) (exp(-(t - t_h) /
  tau_p) - exp(-(t - t_h) / tau_s))`` from each ``t_h`` on; it measures every 2 s of the session's clock (3 ppm of
  noise per reading, 1 ppm resolution) and the DAQ holds its last reading. It follows the session's clock and the
  plan's weight changes (up by 95-125 ppm over the session at seeds 1-3); a few hundred ppm of CO2 acts on nothing,
  and it must not be traced.

Sizes (measured on the made data: each TEST run's mean speed over its evaluation samples against the clean case's
same run, :func:`speed_change`; its sd over the 16 TEST runs, and its root mean square, at seeds 1 / 2 / 3, from the
``--data-only`` cases): ``axis_incline`` 2.33 / 2.67 / 2.30 % (2.35 / 2.70 / 2.31 %), ``amp_thermal_foldback`` 1.70 /
1.43 / 2.16 % (2.24 / 1.89 / 3.07 %), ``grip_node_offset`` 2.27 / 1.34 / 2.42 % (3.98 / 1.79 / 3.79 %); the decoy's
runs are the clean case's.

Pass rule (fixed before any loop ran; the eighth to twenty-fifth audits'): a kind passes when a regressor of
``WANT`` is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse
before and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``:
3.037 / 2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``co2`` is nowhere in ``traced_all`` and ``a <=
1.02 b``. ``WANT``: for the incline, the level's column (a name holding ``base_level``); for the grip, the
micrometer's column (a name holding ``holder_slide``); for the foldback, a regressor of the session's clock or the run
count, of a block, segment or regime of them, of the drive's history or of a heat state (a name holding ``time``,
``session``, ``clock``, ``elapsed``, ``index``, ``count``, ``order``, ``block``, ``segment``, ``regime``, ``cumul``,
``history``, ``memory``, ``heat``, ``therm``, ``drift`` or ``trend``), none holding ``time_in_run`` or ``in_run`` (the
run's own clock), ``onset`` or ``start`` (the run's start), ``break`` or ``pause`` (the plan's pauses are all alike),
``_lag``, ``prev`` or ``last`` (the runs' conditions before), ``load``, ``direction``, ``speed``, ``position`` or
``frequency``.

Usage: python bench/blind_effects_twentysixth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one
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
from l1b2.physics.stator import b2_mode_shape, modal_mass_b_kg, modal_mass_l_kg, phi_b  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("axis_incline", "amp_thermal_foldback", "grip_node_offset", "breath_co2_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"axis_incline": "base_level_mrad", "amp_thermal_foldback": None, "grip_node_offset": "holder_slide_mm",
           "breath_co2_decoy": "co2_ppm"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"axis_incline": ("base_level",),
        "amp_thermal_foldback": ("time", "session", "clock", "elapsed", "index", "count", "order", "block",
                                 "segment", "regime", "cumul", "history", "memory", "heat", "therm", "drift",
                                 "trend"),
        "grip_node_offset": ("holder_slide",),
        "breath_co2_decoy": ()}
#: names that hold a word of ``WANT`` but are not accepted (for the foldback the run's own clock, the run's start,
#: the plan's pauses, the runs' conditions before, the plan's load and direction, the motion and the frequency)
NOT_WANT = {"amp_thermal_foldback": ("time_in_run", "in_run", "onset", "start", "break", "pause", "_lag", "prev",
                                     "last", "load", "direction", "speed", "position", "frequency")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"breath_co2_decoy": "co2"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
INCLINE_RANGE_MRAD = 45.0        # the tilting table's pitch per run, uniform in +-this [mrad]
SLIDE_RANGE_MM = 1.2             # the holder's slide setting per run, uniform in +-this [mm]
V0_HEAT_REF_V = 324.0            # the amplitude at which the heat sink's steady rise is dT_a
CO2_INTERVAL_S = 2.0             # the CO2 sensor's measurement interval [s]
CO2_NOISE_PPM = 3.0              # its noise per reading [ppm]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 281, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "axis_incline":
        return {"z_0_mrad": float(rng.uniform(-0.3, 0.3)),
                "theta_mrad": rng.uniform(-INCLINE_RANGE_MRAD, INCLINE_RANGE_MRAD, n_runs)}
    if kind == "amp_thermal_foldback":
        return {"dT_a_K": float(rng.uniform(30.0, 45.0)), "tau_h_s": float(rng.uniform(80.0, 160.0)),
                "x_k_K": float(rng.uniform(0.5, 1.5)), "k_d_per_K": float(rng.uniform(0.015, 0.03))}
    if kind == "grip_node_offset":
        return {"x_0_mm": float(rng.uniform(-0.15, 0.15)), "k_s_N_m": float(rng.uniform(0.7e7, 1.2e7)),
                "eta": float(rng.uniform(0.05, 0.10)),
                "u_mm": np.round(rng.uniform(-SLIDE_RANGE_MM, SLIDE_RANGE_MM, n_runs), 3)}
    if kind == "breath_co2_decoy":
        return {"C_0_ppm": float(rng.uniform(450.0, 650.0)), "r_ppm_s": float(rng.uniform(0.1, 0.4)),
                "tau_p_s": float(rng.uniform(4.0, 8.0)), "tau_s_s": float(rng.uniform(15.0, 30.0)),
                "A_ppm": rng.uniform(20.0, 60.0, n_runs)}
    return {}


def incline_load_kg(theta_mrad, m_s_kg: float):
    """The slider's weight along the tilted stroke as an equivalent load [kg] (positive toward -position, as a
    positive load pulls): ``m_s sin theta``."""
    return m_s_kg * np.sin(np.asarray(theta_mrad, float) * 1e-3)


def heat_after(x_K: float, V0_V: float, on_s: float, off_s: float, dT_a_K: float, tau_h_s: float) -> float:
    """The heat sink's excess over its idle temperature [K] after a run of ``on_s`` at the amplitude ``V0_V`` and
    the pause ``off_s`` that follows, from ``x_K``: toward ``q = dT_a (V0 / 324 V)^2`` while the drive is on, toward 0
    while it idles, first order with ``tau_h``."""
    q = dT_a_K * (V0_V / V0_HEAT_REF_V) ** 2
    x = q + (x_K - q) * math.exp(-on_s / tau_h_s)
    return x * math.exp(-off_s / tau_h_s)


def foldback_factor(x_K, x_k_K: float, k_d_per_K: float):
    """The drive's amplitude over its setting at the heat sink's excess ``x_K``: ``1 - k_d max(0, x - x_k)``."""
    return 1.0 - k_d_per_K * np.maximum(0.0, np.asarray(x_K, float) - x_k_K)


def b2_shape(x_m, sp):
    """The stator's unloaded B2 mode shape at ``x_m`` (from the plate's end): the model's own
    (:func:`l1b2.physics.stator.b2_mode_shape` at no axial force), ``int_0^L phi^2 dx = L``, ``phi(L) > 0``."""
    return phi_b(b2_mode_shape(sp, 0.0), x_m)


def grip_modes(sp, delta_m: float, k_s_N_m: float, eta: float) -> dict:
    """The stator's modes with the holder's pads ``delta_m`` off the plate's centre: each mode ``i`` gains the
    stiffness ``k_s phi_i(x_p)^2`` and the loss ``eta`` times it, so ``f_i0 sqrt(1 + e_i)`` and ``(zeta_i + eta e_i /
    2) / sqrt(1 + e_i)`` with ``e_i = k_s phi_i(x_p)^2 / K_i``, ``K_i = M_i (2 pi f_i0)^2``, ``x_p = L / 2 + delta``
    (``phi_l = cos(pi x / L)``, ``phi_b``: :func:`b2_shape`)."""
    x_p = sp.length_m / 2.0 + delta_m
    e_l = k_s_N_m * math.cos(math.pi * x_p / sp.length_m) ** 2 / (modal_mass_l_kg(sp) * (2 * math.pi * sp.f_l0_Hz) ** 2)
    e_b = k_s_N_m * float(b2_shape(x_p, sp)) ** 2 / (modal_mass_b_kg(sp) * (2 * math.pi * sp.f_b0_Hz) ** 2)
    return {"f_l0_Hz": sp.f_l0_Hz * math.sqrt(1.0 + e_l), "f_b0_Hz": sp.f_b0_Hz * math.sqrt(1.0 + e_b),
            "zeta_l": (sp.zeta_l + eta * e_l / 2.0) / math.sqrt(1.0 + e_l),
            "zeta_b": (sp.zeta_b + eta * e_b / 2.0) / math.sqrt(1.0 + e_b)}


def co2_air_ppm(t_s, hangs, p: dict):
    """The CO2 at the sensor [ppm] at the session's times ``t_s``: ``C_0 + r t`` plus, for each weight change ``(t_h,
    A_h)`` of ``hangs``, ``A_h exp(-(t - t_h) / tau_p)`` from ``t_h`` on."""
    t = np.asarray(t_s, float)
    c = p["C_0_ppm"] + p["r_ppm_s"] * t
    for t_h, A in hangs:
        c = c + np.where(t >= t_h, A * np.exp(-np.maximum(t - t_h, 0.0) / p["tau_p_s"]), 0.0)
    return c


def co2_sensor_ppm(t_s, hangs, p: dict):
    """The sensor's first-order response (``tau_s``, at ``C_0`` before the session) to :func:`co2_air_ppm` [ppm] at the
    session's times ``t_s >= 0``: ``C_0 + r (t - tau_s (1 - exp(-t / tau_s)))`` plus ``A_h tau_p / (tau_p - tau_s)
    (exp(-(t - t_h) / tau_p) - exp(-(t - t_h) / tau_s))`` from each ``t_h`` on."""
    t = np.asarray(t_s, float)
    tp, ts = p["tau_p_s"], p["tau_s_s"]
    y = p["C_0_ppm"] + p["r_ppm_s"] * (t - ts * (1.0 - np.exp(-t / ts)))
    for t_h, A in hangs:
        u = np.maximum(t - t_h, 0.0)
        y = y + np.where(t >= t_h, A * tp / (tp - ts) * (np.exp(-u / tp) - np.exp(-u / ts)), 0.0)
    return y


def co2_logged_ppm(t_s, hangs, p: dict, noise) -> np.ndarray:
    """The logged CO2 [ppm] at the DAQ's times ``t_s``: the sensor's last reading, taken every 2 s of the session's
    clock (reading ``j`` at ``2 j`` s with the noise ``3 ppm noise[j]``), to 1 ppm."""
    j = np.floor(np.asarray(t_s, float) / CO2_INTERVAL_S + 1e-9).astype(int)
    return np.round(co2_sensor_ppm(CO2_INTERVAL_S * j, hangs, p) + CO2_NOISE_PPM * np.asarray(noise)[j])


def weight_changes(conds) -> list:
    """The runs (from 0) at whose start the operator changes the weight: the first run with a load, and each run
    whose load differs from the run before's."""
    out = []
    for k, (_, L, _) in enumerate(conds):
        prev = 0.0 if k == 0 else conds[k - 1][1]
        if L != prev:
            out.append(k)
    return out


def run_motor(kind: str, mp, p: dict, k: int, L: float):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` and its load input [kg] (``L`` the run's load)."""
    if kind == "axis_incline":
        m_s = mp.slider.mass_kg
        return be.load_in_slider_motor(mp, L, kind), L + float(incline_load_kg(p["theta_mrad"][k], m_s))
    if kind == "grip_node_offset":
        delta = (p["u_mm"][k] - p["x_0_mm"]) * 1e-3
        m = grip_modes(mp.stator, delta, p["k_s_N_m"], p["eta"])
        return mp.replace(**{f"stator__{key}": v for key, v in m.items()}), L
    return mp, L


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    conds_run = conds[:first] if first else conds
    changes = set(weight_changes(conds))
    hangs = []
    co2_noise = np.random.default_rng([seed, 283]).standard_normal(4096)
    frames, per_run, t_next, x = [], [], 0.0, 0.0
    for k, (V, L, d) in enumerate(conds_run):
        g = float(foldback_factor(x, p["x_k_K"], p["k_d_per_K"])) if kind == "amp_thermal_foldback" else 1.0
        mp, load_in = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, L)
        r = b5.traverse(mp, nominal, plan, g * V, load_in, d, record=b5.POSITION_AND_SPEED)[0]
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 282, k]).standard_normal(len(t))
        if kind == "axis_incline":
            extra["base_level_mrad"] = np.round(p["theta_mrad"][k] + p["z_0_mrad"] + 0.02 * noise, 2)
        elif kind == "grip_node_offset":
            extra["holder_slide_mm"] = np.full(len(t), float(p["u_mm"][k]))
        elif kind == "breath_co2_decoy":
            if k in changes:
                hangs.append((t_next - plan.pause_s, float(p["A_ppm"][k])))
            extra["co2_ppm"] = co2_logged_ppm(np.round(t_next + t, 9), hangs, p, co2_noise)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        duration = float(r["time"][-1])
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p, "V0_V": g * V,
                        "heat_K": x, "f_l0_Hz": mp.stator.f_l0_Hz, "f_b0_Hz": mp.stator.f_b0_Hz,
                        "zeta_l": mp.stator.zeta_l, "zeta_b": mp.stator.zeta_b, "mass_kg": mp.slider.mass_kg,
                        "load_in_kg": load_in, "t_start_s": t_next, "duration_s": duration})
        if kind == "amp_thermal_foldback":
            x = heat_after(x, g * V, duration, plan.pause_s, p["dT_a_K"], p["tau_h_s"])
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def speed_change(df, clean) -> np.ndarray:
    """Each run's change of its mean measured speed over its evaluation samples against the clean case's same run
    (``speed / clean - 1``), runs in order."""
    out = []
    for k in sorted(set(df[dataio.RUN]) & set(clean[dataio.RUN])):
        a = df[df[dataio.RUN] == k].reset_index(drop=True)
        c = clean[clean[dataio.RUN] == k].reset_index(drop=True)
        va = np.abs(a[dataio.SPEED].to_numpy())[dataio.evaluation_mask(a)].mean()
        vc = np.abs(c[dataio.SPEED].to_numpy())[dataio.evaluation_mask(c)].mean()
        out.append(va / vc - 1.0)
    return np.array(out)


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
