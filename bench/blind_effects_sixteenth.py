#!/usr/bin/env python
"""A sixteenth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the fifteen earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_fifteenth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``stribeck_viscosity`` -- logged ``oil_viscosity_mPa_s`` per sample, an inline viscometer on the bar's lubricant
  line (0.5 % of noise per sample, three significant digits). A lubricant study: before each run a felt wiper
  strips the friction bar's track and a dispenser lays a fixed dose of a blend of two silicone oils mixed at a
  ratio set per run, so the blend's viscosity ``eta`` is a design factor, log-uniform in 10-1000 mPa s. The tip's
  slip runs in mixed lubrication: the share of the contact the film carries follows the Hersey number, the
  viscosity times the sliding speed, and the tip's sliding speed (about ``omega U_w``) scales with the drive's
  amplitude, so ``x = (eta / eta_t) (V0 / 324 V)`` (``eta_t`` drawn log-uniform in 50-200 mPa s: the transition).
  The film's share is ``f(x) = x^n / (1 + x^n)`` (``n`` drawn in 0.8-1.2: how sharp the Stribeck curve's mixed
  regime is) and the film carries a friction a share ``D`` (drawn in 0.12-0.20) lower than the asperities, so the
  Coulomb slip friction is ``mu_p (1 - D f(x)) / (1 - D f(x_ref))``, the motor's own ``mu_p`` at the lab's usual
  oil (100 mPa s) and the plan's middle V0 (272 V). A Stribeck curve of a product of the logged channel and the
  plan's V0: thicker oil and a harder drive lower the friction, which drives the slider.
* ``autotune_file_blocks`` -- no column; a change between runs through the recording protocol. The DAQ program
  writes the session into files of ``N`` runs each (``N`` drawn among 6-12; files start at run 1), and on opening
  each file it reruns the drive's frequency search: a sweep in 10 Hz steps that locks where the drive current's
  phase crosses zero. The lock's tolerance and the contact's seat at that moment put the found frequency at the
  plan's plus ``delta_j = 10 Hz round(sigma_f z_j / 10 Hz)`` (``z_j`` standard normal per file, ``sigma_f`` drawn in
  40-70 Hz), and the drive holds it for the file's runs. The operator's supply table is for the plan's frequency
  and ``frequency_Hz`` logs the plan's (the run sheet's): the drive's actual frequency, and with it the tank's
  gain, is a constant per file, drawn anew at each file's start, whose boundaries follow nothing logged but the
  run count.
* ``autotune_freq_logged`` -- the blocks' control, not a kind of its own: the same draw and the same motion as
  ``autotune_file_blocks`` at the seed, with ``frequency_Hz`` logging the drive's actual frequency (0.1 Hz
  resolution) instead of the plan's. What the loop makes of the cause logged in the model's own column tells the
  hidden blocks' loss.
* ``softstart_ramp`` -- logged ``softstart_ms`` per sample, the drive's soft-start setting (an integer number of ms
  read from its register, constant in a run, no noise). A start-transient study sets it per run, uniform in
  0-80 ms: at each start the drive ramps its bus linearly over ``T_r`` from a pedestal of 20 % (where its gate
  drivers switch cleanly) to the operator's supply ``V_s``, ``V_s min(1, 0.2 + 0.8 t / T_r)`` (``t`` from the run's
  start; ``T_r = 0``: a step), so the stator's amplitude follows the ramp. The slider starts only once the thrust beats the guide's and the load's resistance, late in the ramp, and
  reaches its speed after it: a per-sample dynamic in the time within the run whose length is the logged setting
  (a channel x time-in-run interaction), worth nothing once the ramp is over.
* ``pulley_tach_decoy`` -- a decoy, no effect on the motor: logged ``pulley_tach_rpm`` per sample, an optical
  tachometer on the pulley that carries the positive loads (a 60-slot disc on the pulley of radius ``r_p``, drawn
  in 8-12 mm; its frequency-to-voltage converter a first-order filter with ``tau_t`` drawn in 10-30 ms, from 0 at
  each run's start). The cable runs over that pulley only for a positive load (a negative load hangs over the other
  end's pulley; a run without a load hangs no cable), so it reads ``60 |v| / (2 pi r_p)`` through its filter for a
  positive load and 0 otherwise, plus 0.3 rpm of noise (read as ``max(0, .)``: a converter reads no negative
  speed) and 0.1 rpm resolution. It echoes the slider's speed (each run's scatter with it) in half of the loaded
  runs; a slotted disc read by light acts on nothing, and it must not be traced.

Pass rule (fixed before any loop ran; the eighth to fifteenth audits'): a kind passes when a regressor of ``WANT``
is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before
and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``pulley_tach_rpm`` is nowhere in ``traced_all`` and ``a
<= 1.02 b``. ``WANT``: the viscometer's column for the Stribeck kind (a name holding ``oil_viscosity``); the
soft-start's column for the ramp (a name holding ``softstart``: the time in the run alone is not accepted, the
ramp's length is the channel's); for the file blocks, a regressor of the session's clock or order (its name holds
``time``, ``order``, ``index``, ``count``, ``since``, ``session``, ``segment``, ``break``, ``block`` or ``file``, and
not ``time_in_run``: the run's own clock carries no change between runs). The control is reported with its own
column (``frequency``) but not counted.

Usage: python bench/blind_effects_sixteenth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one of
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

KINDS = ("stribeck_viscosity", "autotune_file_blocks", "softstart_ramp", "pulley_tach_decoy", "autotune_freq_logged")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"autotune_freq_logged": "autotune_file_blocks"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"stribeck_viscosity": "oil_viscosity_mPa_s", "autotune_file_blocks": None, "softstart_ramp": "softstart_ms",
           "pulley_tach_decoy": "pulley_tach_rpm", "autotune_freq_logged": "frequency_Hz"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"stribeck_viscosity": ("oil_viscosity",),
        "autotune_file_blocks": ("time", "order", "index", "count", "since", "session", "segment", "break", "block",
                                 "file"),
        "softstart_ramp": ("softstart",),
        "pulley_tach_decoy": (),
        "autotune_freq_logged": ("frequency",)}
#: names that hold a word of ``WANT`` but are not accepted (the run's own clock)
NOT_WANT = {"autotune_file_blocks": ("time_in_run",)}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"pulley_tach_decoy": "pulley_tach_rpm"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
ETA_REF = 100.0           # the lab's usual oil [mPa s], at which (and V0_REF) the motor's own mu_p holds
V0_REF = 272.0            # the plan's middle V0 [V]
V0_HERSEY = 324.0         # the V0 [V] at which x = eta / eta_t
SEARCH_STEP_HZ = 10.0     # the frequency search's step [Hz]
SLOTS = 60                # the tachometer disc's slots (its resolution is the converter's, 0.1 rpm)
PEDESTAL = 0.2            # the soft start's pedestal: the share of the bus the ramp starts from


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the blocks')."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 191, KINDS.index(src) if src in KINDS else 99])
    if kind == "stribeck_viscosity":
        return {"eta_t": float(10.0 ** rng.uniform(math.log10(50.0), math.log10(200.0))),
                "n": float(rng.uniform(0.8, 1.2)), "D": float(rng.uniform(0.12, 0.20)),
                "eta": 10.0 ** rng.uniform(1.0, 3.0, n_runs)}
    if src == "autotune_file_blocks":
        N = int(rng.integers(6, 13))
        sigma = float(rng.uniform(40.0, 70.0))
        z = rng.standard_normal(-(-n_runs // N))
        return {"N": N, "sigma_f_Hz": sigma, "delta_Hz": SEARCH_STEP_HZ * np.round(sigma * z / SEARCH_STEP_HZ)}
    if kind == "softstart_ramp":
        return {"T_r_ms": np.round(rng.uniform(0.0, 80.0, n_runs))}
    if kind == "pulley_tach_decoy":
        return {"r_p_m": float(rng.uniform(0.008, 0.012)), "tau_t_s": float(rng.uniform(0.010, 0.030))}
    return {}


def film_share(x, n: float):
    """The share of the contact the film carries at the Hersey-type number ``x``: ``x^n / (1 + x^n)``."""
    xn = np.asarray(x, float) ** n
    return xn / (1.0 + xn)


def stribeck_mu_factor(eta, V0, p: dict):
    """The slip friction's factor at the viscosity ``eta`` [mPa s] and the drive's ``V0`` [V]: ``(1 - D f(x)) / (1 -
    D f(x_ref))``, ``x = (eta / eta_t) (V0 / 324 V)``, ``x_ref`` at 100 mPa s and 272 V."""
    x = np.asarray(eta, float) / p["eta_t"] * np.asarray(V0, float) / V0_HERSEY
    x_ref = ETA_REF / p["eta_t"] * V0_REF / V0_HERSEY
    return (1.0 - p["D"] * film_share(x, p["n"])) / (1.0 - p["D"] * film_share(x_ref, p["n"]))


def file_offsets(n_runs: int, p: dict) -> np.ndarray:
    """Each run's frequency offset [Hz]: its file's ``delta_j`` (files of ``N`` runs from run 1)."""
    return np.asarray(p["delta_Hz"], float)[np.arange(n_runs) // int(p["N"])]


def ramp(t_s, V_s: float, T_r_s: float):
    """The soft-started bus [V] at the run's times ``t_s``: ``V_s min(1, r0 + (1 - r0) t / T_r)`` with the pedestal
    ``r0`` (``V_s`` when ``T_r = 0``)."""
    t = np.asarray(t_s, float)
    if T_r_s <= 0:
        return np.full(t.shape, V_s)
    return V_s * np.minimum(1.0, PEDESTAL + (1.0 - PEDESTAL) * t / T_r_s)


def tach_rpm(t_s, v_m_s, load_kg: float, p: dict) -> np.ndarray:
    """The tachometer's filtered reading [rpm] (no noise, no rounding) on the co-simulation's grid ``t_s`` with the
    slider's speeds ``v_m_s``: ``60 |v| / (2 pi r_p)`` through the first-order converter (``tau_t``, from 0 at the
    run's start, exact for a speed held over each step) for a positive load, 0 otherwise."""
    t = np.asarray(t_s, float)
    if load_kg <= 0:
        return np.zeros(t.shape)
    u = 60.0 * np.abs(np.asarray(v_m_s, float)) / (2.0 * math.pi * p["r_p_m"])
    y = np.zeros(t.shape)
    for i in range(1, len(t)):
        a = math.exp(-(t[i] - t[i - 1]) / p["tau_t_s"])
        y[i] = u[i - 1] + (y[i - 1] - u[i - 1]) * a
    return y


def run_motor(kind: str, mp, plan, p: dict, k: int, V0: float):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` at the plan's ``V0``."""
    if kind == "stribeck_viscosity":
        return mp.replace(interface__mu_p=mp.interface.mu_p * float(stribeck_mu_factor(p["eta"][k], V0, p)))
    return mp


def traverse_ramped(mp, nominal, plan, V0, load, d, T_r_s: float):
    """One traverse (as :func:`blind_effects.traverse`) with the bus soft-started over ``T_r_s`` (:func:`ramp`)."""
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    bus = V_s if T_r_s <= 0 else (lambda t: float(ramp(t, V_s, T_r_s)))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=bus, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=d, m_load=load, s0=s0)
    return m.run(plan.max_run_s, record=("Slider.s", "Stator.T_stator"),
                 until=lambda mm: mm.value("Slider.at_stop") == d)


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    conds = conds[:first] if first else conds
    blocks = STREAM.get(kind, kind) == "autotune_file_blocks"
    df_Hz = file_offsets(len(conds), p) if blocks else np.zeros(len(conds))
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds):
        mp = run_motor(kind, scattered_motor(nominal, factors[k]), plan, p, k, V)
        T_r = float(p["T_r_ms"][k]) / 1000.0 if kind == "softstart_ramp" else 0.0
        if kind == "softstart_ramp":
            r = traverse_ramped(mp, nominal, plan, V, L, d, T_r)
        else:
            r = be.traverse(mp, nominal, plan, V, L, d, None, plan.f_drive_Hz + float(df_Hz[k]) if blocks else None)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra, f_log = {}, None
        noise = np.random.default_rng([seed, 192, k]).standard_normal(len(t))
        if kind == "stribeck_viscosity":
            extra["oil_viscosity_mPa_s"] = np.array([float(f"{x:.3g}") for x in p["eta"][k] * (1 + 0.005 * noise)])
        elif kind == "softstart_ramp":
            extra["softstart_ms"] = np.full(len(t), float(p["T_r_ms"][k]))
        elif kind == "pulley_tach_decoy":
            v_full = np.gradient(r["Slider.s"], r["time"])
            y = tach_rpm(r["time"], v_full, L, p)[idx]
            extra["pulley_tach_rpm"] = np.round(np.maximum(0.0, y + 0.3 * noise), 1)
        elif kind == "autotune_freq_logged":
            f_log = np.full(len(t), round(plan.f_drive_Hz + float(df_Hz[k]), 1))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, f_log, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "f_drive_Hz": plan.f_drive_Hz + float(df_Hz[k]), "T_r_s": T_r, "t_start_s": t_next,
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
