#!/usr/bin/env python
"""A twenty-second blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the twenty-one earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_twentyfirst.py``, ``bench/blind_effects_stamps.py``)
names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row, traverse
and ``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan
at a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). Every kind sets FMU parameters per run, the air
cushions also an FMU input per step as a function of the co-simulation's own state (the slider's position and speed
one step before, ``bench/blind_effects_fifth.py``'s ``StateInput``); the speed is always the DAQ's derivative of the
recorded position. Each kind draws from one random stream of its seed. The kinds:

* ``pulley_grease_thixotropy`` -- no column; a change between runs set by the history of which pulley turned when.
  A positive load hangs over the pulley at the stroke's -position end, a negative one over the pulley at its
  +position end (a run without a load hangs no cable and turns neither). Each pulley turns on a sealed ball bearing
  packed with a lithium-soap grease, which is thixotropic: at rest its soap fibres knit into a network whose yield
  stress drags on the seals' lips, and rotation shears the network apart. With the network's structure ``lam`` (1
  knit, 0 sheared; 1 for both pulleys at the session's start, after a night at rest) the bearing's drag, referred to
  the cable, is ``F_g lam`` against the motion (``F_g`` drawn in 0.20-0.32 N: a sealed bearing's breakaway torque of
  2.0-3.2 mN m on a 10 mm pulley; independent of the load, none for the other pulley). While a pulley turns its
  structure breaks down with the cable's travel ``x``, ``d lam / dx = -lam / x_b`` (``x_b`` drawn in 20-40 mm), so a
  traverse of the stroke ``X`` (42 mm) leaves ``q = exp(-X / x_b)`` of it; at rest it rebuilds on the session clock,
  ``lam(t) = 1 - (1 - lam_off) exp(-(t - t_off) / t_r)`` (``t_r`` drawn in 2-5 s; ``lam_off`` and ``t_off`` the
  structure and the session time when the pulley stopped: the end of the last run it turned in). The co-simulation
  holds the drag per run at the structure's mean over the run's travel, ``F_g lam0 (1 - q) x_b / X`` (``lam0`` at
  the run's start), set through the slider's load-path friction ``pulley_mu = drag / (g |m|)``. A run's drag
  follows how long the pulley of its load's side has rested since it last turned: the plan's order of the loads'
  signs and the runs' durations (a condition's backward run meets the structure its forward run left one pause
  before; a forward run after conditions on the other side or without a load, a rebuilt one), not the run's own
  factors and not the session clock as such.
* ``pulley_grease_logged`` -- the grease's control, not a kind of its own: the same draw and the same motion as
  ``pulley_grease_thixotropy`` at the seed, with the run's drag logged as ``pulley_drag_mN`` (1000 times the drag in
  N, 0 without a load; per sample, 0.01 mN resolution, no noise), as a torque sensor in the pulley's axle would read
  it. What the loop makes of the state logged tells the hidden grease's loss.
* ``electrode_brine_leak`` -- logged ``enclosure_rh_pct`` per sample, a capacitive humidity sensor in the rig's
  enclosure (0.5 %-point of noise, 0.1 % resolution). A humidity-qualification study: a humidity generator sets the
  enclosure to a new relative humidity ``RH`` per run (uniform 30-90 %). A thin salt residue (from handling: sodium
  and potassium chlorides) bridges the gap between the stator's split electrodes. Below its deliquescence humidity
  ``RH_d`` (drawn in 70-80 %, about sodium chloride's 75 %) the residue is a dry, insulating crust; above it the salt
  takes up water and dissolves into a brine film that conducts. The dissolved share is ``b(RH) = 1 / (1 + exp(-(RH
  - RH_d) / w))`` (``w`` drawn in 1-2 %-points: the mixture's smeared transition), and the film's leak across the
  electrodes, in parallel with the stator's own loss resistance ``R_m`` in the tank, is ``R_m / (rho_s b)``
  (``rho_s`` drawn in 0.06-0.09: a film of some 10^6 Ohm per square across a 1 mm gap along the 30 mm plate, 22-33
  kOhm). The tank sees ``R_m / (1 + rho_s b(RH))``: the motor's own below the knee, ``1 / (1 + rho_s)`` of it above
  it, a step of the logged humidity. Near its resonance the tank's gain follows its resistance (about ``R sqrt(C /
  L)``), so above the knee the stator's amplitude is 5.3-7.7 % lower (over the drawn ``rho_s``). The operator's
  supply table is for the dry stator and ``voltage_V`` logs the plan's V0. The modes, the contact and the guide do
  not see the humidity (a dry PTFE-composite lining): only the drive's tank does.
* ``stop_air_cushion`` -- no column; within a run, along the stroke, through the motion itself. Two air dashpots (a
  glass piston in a graphite cylinder, its orifice set by a needle valve) cushion the slider's arrival at the end
  stops: the plunger of the one at the +position stop reaches ``x_p`` into the stroke, the one at the -position stop
  ``x_n`` (each drawn in 4-8 mm). While the slider pushes a plunger in, the air forced through its orifice resists
  with a force in proportion to the speed (laminar orifice flow), ``-c_p v`` for ``s > s_max - x_p`` and ``v > 0``,
  ``-c_n v`` for ``s < s_min + x_n`` and ``v < 0`` (``c_p``, ``c_n`` drawn in 2.0-4.5 N s/m each); a check valve lets
  the plunger return freely behind a departing slider, so a dashpot acts only on the run that arrives at its stop,
  over the run's last few mm (2 mm of which the evaluation leaves out). Set through the slider's load input as the
  equivalent mass ``m_load - F / g`` computed each step from the slider's position and speed of the step before,
  with the load's inertia moved into the slider's mass and the guide's Coulomb levels and preload share rescaled
  (:func:`blind_effects.load_in_slider_motor`: the moving mass and the guide's friction are the motor's). The
  plungers' own mass and the dashpots' return springs are left out.
* ``lvdt_lag_decoy`` -- a decoy, no effect on the motor: logged ``lvdt_mm`` per sample, an LVDT beside the encoder
  for a cross-check of the slider's position (its core on a rod from the slider rides in the coil without contact;
  the rod is part of the slider's mass). Its conditioner's demodulator smooths the position ``s`` through a
  first-order low-pass of time constant ``tau`` (drawn in 15-40 ms), updated at each DAQ sample, ``y_k = y_(k-1) +
  (1 - exp(-(t_k - t_(k-1)) / tau)) (s_k - y_(k-1))``, ``y_0 = s_0`` (the slider at rest at its start stop), and
  the reading is ``o + 1000 y (1 + g) + e3 (1000 y / 25 mm)^3`` mm (offset ``o`` drawn in -0.3..+0.3 mm, gain
  error ``g`` in -1..+1 %, cubic linearity error ``|e3|`` in 0.05-0.15 mm with its sign at random), 2 um of noise
  and 1 um resolution. It follows the position, lagging it by about ``tau v`` (1-11 mm over the runs' speeds): a
  consequence of the motion that carries its speed; a coil reading a core acts on nothing and must not be traced.

Pass rule (fixed before any loop ran; the eighth to twenty-first audits'): a kind passes when a regressor of
``WANT`` is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse
before and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``:
3.037 / 2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``lvdt`` is nowhere in ``traced_all`` and ``a <=
1.02 b``. ``WANT``: the humidity sensor's column for the brine (a name holding ``enclosure_rh``); for the grease, a
regressor of the runs before or of the rest since them (a name holding ``_lag``, ``prev``, ``last_``, ``_last``,
``since``, ``history`` or ``memory``), none holding ``voltage`` or ``direction`` (the drag follows the loads'
history, not the voltages' nor the directions', which alternate in every condition), ``speed`` or ``position`` (lags
within a run), ``time_in_run``, ``start`` or ``onset`` (the run's own clock) or ``break`` (the session has no
breaks: every pause is the plan's); for the cushions, a regressor of the position or of the way to the stop (a name
holding ``position``, ``stop``, ``arriv``, ``distance``, ``travel`` or ``cushion``), none holding ``time_in_run``
(the dashpots act over the stroke's last mm, not at a time of the run). The control is reported with its own column
(``pulley_drag_mN``) but not counted.

Usage: python bench/blind_effects_twentysecond.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one
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

KINDS = ("pulley_grease_thixotropy", "electrode_brine_leak", "stop_air_cushion", "lvdt_lag_decoy",
         "pulley_grease_logged")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"pulley_grease_logged": "pulley_grease_thixotropy"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"pulley_grease_thixotropy": None, "electrode_brine_leak": "enclosure_rh_pct",
           "stop_air_cushion": None, "lvdt_lag_decoy": "lvdt_mm", "pulley_grease_logged": "pulley_drag_mN"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"pulley_grease_thixotropy": ("_lag", "prev", "last_", "_last", "since", "history", "memory"),
        "electrode_brine_leak": ("enclosure_rh",),
        "stop_air_cushion": ("position", "stop", "arriv", "distance", "travel", "cushion"),
        "lvdt_lag_decoy": (),
        "pulley_grease_logged": ("pulley_drag",)}
#: names that hold a word of ``WANT`` but are not accepted (the voltages' and directions' history, lags within a
#: run, the run's own clock, the clock's breaks)
NOT_WANT = {"pulley_grease_thixotropy": ("voltage", "direction", "speed", "position", "time_in_run", "start", "onset",
                                         "break"),
            "stop_air_cushion": ("time_in_run",)}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"lvdt_lag_decoy": "lvdt"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
RH_RANGE = (30.0, 90.0)      # the enclosure's relative humidity set per run [%]
LVDT_RANGE_MM = 25.0         # the LVDT's half range: the scale of its cubic linearity error [mm]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the grease's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 241, KINDS.index(src) if src in KINDS else 99])
    if src == "pulley_grease_thixotropy":
        return {"F_g_N": float(rng.uniform(0.20, 0.32)), "x_b_m": float(rng.uniform(0.020, 0.040)),
                "t_r_s": float(rng.uniform(2.0, 5.0))}
    if kind == "electrode_brine_leak":
        return {"rho_s": float(rng.uniform(0.06, 0.09)), "RH_d_pct": float(rng.uniform(70.0, 80.0)),
                "w_pct": float(rng.uniform(1.0, 2.0)), "RH_pct": rng.uniform(*RH_RANGE, n_runs)}
    if kind == "stop_air_cushion":
        return {"c_p_N_s_per_m": float(rng.uniform(2.0, 4.5)), "c_n_N_s_per_m": float(rng.uniform(2.0, 4.5)),
                "x_p_m": float(rng.uniform(0.004, 0.008)), "x_n_m": float(rng.uniform(0.004, 0.008))}
    if kind == "lvdt_lag_decoy":
        return {"tau_s": float(rng.uniform(0.015, 0.040)), "o_mm": float(rng.uniform(-0.3, 0.3)),
                "g": float(rng.uniform(-0.01, 0.01)),
                "e3_mm": float(rng.uniform(0.05, 0.15) * rng.choice((-1.0, 1.0)))}
    return {}


def pulley_of(load_kg: float) -> int:
    """The pulley a load hangs over: -1 the -position end's (a positive load), +1 the +position end's (a negative
    one), 0 none (no load, no cable)."""
    return -1 if load_kg > 0 else (1 if load_kg < 0 else 0)


def grease_recovery(lam_off: float, rest_s: float, t_r: float) -> float:
    """The grease's structure after ``rest_s`` at rest from ``lam_off``: ``1 - (1 - lam_off) exp(-rest / t_r)``
    (an infinite rest: 1)."""
    return 1.0 - (1.0 - lam_off) * math.exp(-rest_s / t_r)


def grease_breakdown(lam0: float, travel_m: float, x_b: float) -> float:
    """The structure left after the cable's travel ``travel_m`` from ``lam0``: ``lam0 exp(-x / x_b)``."""
    return lam0 * math.exp(-travel_m / x_b)


def grease_run_mean(lam0: float, travel_m: float, x_b: float) -> float:
    """The structure's mean over a run's travel ``X`` from ``lam0``: ``lam0 (1 - exp(-X / x_b)) x_b / X``."""
    return lam0 * (1.0 - math.exp(-travel_m / x_b)) * x_b / travel_m


def brine_share(RH, RH_d: float, w: float):
    """The residue's dissolved share at the humidity ``RH`` [%]: ``1 / (1 + exp(-(RH - RH_d) / w))``."""
    return 1.0 / (1.0 + np.exp(-(np.asarray(RH, float) - RH_d) / w))


def leak_factor(RH, rho_s: float, RH_d: float, w: float):
    """The tank's resistance over the stator's own ``R_m`` at the humidity ``RH`` [%]: ``1 / (1 + rho_s
    brine_share(RH))`` (``R_m`` in parallel with the brine's leak ``R_m / (rho_s brine_share(RH))``)."""
    return 1.0 / (1.0 + rho_s * brine_share(RH, RH_d, w))


def cushion_force_N(s: float, v: float, p: dict, s_min: float, s_max: float) -> float:
    """The air cushions' force on the slider [N] (positive toward +position) at the position ``s`` and speed ``v``:
    ``-c_p v`` within ``x_p`` of ``s_max`` moving toward it, ``-c_n v`` within ``x_n`` of ``s_min`` moving toward
    it, else 0."""
    if v > 0 and s > s_max - p["x_p_m"]:
        return -p["c_p_N_s_per_m"] * v
    if v < 0 and s < s_min + p["x_n_m"]:
        return -p["c_n_N_s_per_m"] * v
    return 0.0


def lvdt_lag(t, s, tau: float) -> np.ndarray:
    """The conditioner's first-order low-pass of the positions ``s`` at the sample times ``t``: ``y_k = y_(k-1) +
    (1 - exp(-(t_k - t_(k-1)) / tau)) (s_k - y_(k-1))``, ``y_0 = s_0``."""
    t, s = np.asarray(t, float), np.asarray(s, float)
    y = np.empty_like(s)
    y[0] = s[0]
    a = 1.0 - np.exp(-np.diff(t) / tau)
    for k in range(1, len(s)):
        y[k] = y[k - 1] + a[k - 1] * (s[k] - y[k - 1])
    return y


def lvdt_reading_mm(t, s, p: dict) -> np.ndarray:
    """The LVDT's reading [mm] (no noise, no rounding): ``o + 1000 y (1 + g) + e3 (1000 y / 25 mm)^3``, ``y`` the
    low-passed position (:func:`lvdt_lag`)."""
    y_mm = 1000.0 * lvdt_lag(t, s, p["tau_s"])
    return p["o_mm"] + y_mm * (1.0 + p["g"]) + p["e3_mm"] * (y_mm / LVDT_RANGE_MM) ** 3


def run_motor(kind: str, mp, p: dict, k: int, L: float, drag_N: float = 0.0):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``L`` the run's load, ``drag_N`` the grease's
    drag of the run) and its load law (None: the run's load)."""
    if STREAM.get(kind, kind) == "pulley_grease_thixotropy":
        if L == 0:
            return mp, None
        return mp.replace(slider__pulley_mu=mp.slider.pulley_mu + drag_N / (G_M_S2 * abs(L))), None
    if kind == "electrode_brine_leak":
        f = float(leak_factor(p["RH_pct"][k], p["rho_s"], p["RH_d_pct"], p["w_pct"]))
        return mp.replace(driver__R_m_ohm=mp.driver.R_m_ohm * f), None
    if kind == "stop_air_cushion":
        s_min, s_max = mp.slider.s_min_m, mp.slider.s_max_m
        return (be.load_in_slider_motor(mp, L, kind),
                lambda t, s, v: L - cushion_force_N(s, v, p, s_min, s_max) / G_M_S2)
    return mp, None


def traverse(mp, nominal, plan, V0, load, d, load_law=None):
    """One traverse (as :func:`blind_effects.traverse`) with the load input given as a law of the slider's state
    (None: the run's load); the operator's supply is set from the nominal drive at 25 degC and f0."""
    if load_law is None:
        return be.traverse(mp, nominal, plan, V0, load, d)
    return b5.traverse(mp, nominal, plan, V0, load, d, load_law=load_law, record=b5.POSITION_AND_SPEED)[0]


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    grease = STREAM.get(kind, kind) == "pulley_grease_thixotropy"
    stroke = nominal.slider.s_max_m - nominal.slider.s_min_m
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next = [], [], 0.0
    lam_off, t_off = {-1: 1.0, 1: 1.0}, {-1: -math.inf, 1: -math.inf}   # each pulley's structure when it stopped
    for k, (V, L, d) in enumerate(conds_run):
        j = pulley_of(L)
        lam0, drag = None, 0.0
        if grease and j:
            lam0 = grease_recovery(lam_off[j], t_next - t_off[j], p["t_r_s"])
            drag = p["F_g_N"] * grease_run_mean(lam0, stroke, p["x_b_m"])
        mp, load_law = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, L, drag)
        r = traverse(mp, nominal, plan, V, L, d, load_law)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 242, k]).standard_normal(len(t))
        if kind == "electrode_brine_leak":
            extra["enclosure_rh_pct"] = np.round(p["RH_pct"][k] + 0.5 * noise, 1)
        elif kind == "lvdt_lag_decoy":
            extra["lvdt_mm"] = np.round(lvdt_reading_mm(t, s, p) + 0.002 * noise, 3)
        elif kind == "pulley_grease_logged":
            extra["pulley_drag_mN"] = np.full(len(t), round(1000.0 * drag, 2))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        cushion = None
        if load_law is not None:  # the largest cushion force met, from the recorded steps
            s_min, s_max = nominal.slider.s_min_m, nominal.slider.s_max_m
            cushion = max(abs(cushion_force_N(a, b, p, s_min, s_max)) for a, b in zip(r["Slider.s"], r["Slider.v"]))
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "pulley_mu": mp.slider.pulley_mu, "R_m_ohm": mp.driver.R_m_ohm, "mass_kg": mp.slider.mass_kg,
                        "grease_lam0": lam0, "drag_N": drag, "cushion_max_N": cushion, "t_start_s": t_next,
                        "duration_s": float(r["time"][-1])})
        t_end = float(out[dataio.TIME].iloc[-1])
        if grease and j:  # the pulley stops with the run: its structure broken down by the stroke
            lam_off[j], t_off[j] = grease_breakdown(lam0, stroke, p["x_b_m"]), t_end
        t_next = t_end + plan.pause_s
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
