#!/usr/bin/env python
"""A twenty-fifth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the twenty-four earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_twentyfourth.py``, ``bench/blind_effects_stamps.py``)
names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row and
``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan
at a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). Every kind sets FMU parameters per run, the
tracking drive also its frequency input (``bench/blind_effects_fifth.py``'s ``traverse`` with a frequency law that
holds the run's lock); the speed is always the DAQ's derivative of the recorded position. Each kind draws from one
random stream of its seed. The kinds:

* ``core_magnetostriction`` -- logged ``frequency_Hz`` per sample, a drive that locks its frequency before each run.
  Its phase-locked loop sets the frequency, with the tip resting on the bar, to the zero phase of the tank's current;
  the lock scatters from run to run (the phase detector's offset, the contact's seat) by ``sigma_f`` (drawn in 25-45
  Hz): ``f_k = f0 + sigma_f z_k`` (``z_k`` standard normal per run), held through the run and logged at 0.1 Hz. The
  operator's supply table is for f0 = 48.5 kHz; the tank's gain and the modes at ``f_k`` are the motor's model. The
  tank's inductor is wound on a ferrite core whose lowest extensional mode lies at ``f_c`` (drawn in 96.88-97.12 kHz:
  a core some 17 mm across) with a mechanical quality factor ``Q_c`` (drawn in 300-600). An unbiased ferrite's
  magnetostriction is even in the flux, so the flux at ``f`` strains the core at ``2 f``, and where ``2 f`` meets
  ``f_c`` the core rings and dissipates. Seen from the winding the ringing core is a motional impedance in series with
  it, ``Z = r_324 (V0 / 324 V)^2 / (1 + j x)``, ``x = Q_c (2 f / f_c - f_c / (2 f))`` (the ringing's power goes as the
  flux to the fourth, the winding's current as the flux, and the flux follows the winding's voltage, about V0 near the
  tank's peak; ``r_324`` drawn in 20-35 Ohm against the winding's 509 Ohm of reactance): a loss peak of the drive
  frequency at ``f_c / 2`` (48.44-48.56 kHz), 40-81 Hz wide (half width at half height, ``f_c / (4 Q_c)``), with the
  reactance's dispersion about it, deeper at the higher V0. V0 is the fixed point of ``V0 = V_inv1 |H|`` with the
  tank's gain ``H = 1 / (1 - w^2 L C + j w L / R_m + Z (1 / R_m + j w C))`` (on the peak 10.4-15.3 % below the
  lossless V0 at 324 V, 5.6-8.8 % at 220 V); the co-simulation sets it through the tank's resistance (the ``R_m``
  whose gain gives that V0: ``bench/blind_effects_twentythird.py``'s ``tank_R_for_V0``). ``voltage_V`` logs the plan's
  V0. Not in the motor's model: the frequency's effect through a part the paper's B2 (and L1) modal response does not
  contain.
* ``lining_fibre_angle`` -- logged ``fibre_angle_deg`` per sample, the fibre angle marked on the lining strip (the
  DAQ program reads the operator's entry: constant in a run, no noise, 0.1 deg). A lining-orientation study: the
  friction bar carries its lining as a strip clipped into a slot, and before each run the operator clips in a strip
  cut from one unidirectional carbon-fibre/PEEK sheet with its fibres at ``theta`` to the track's axis (uniform in
  -90..+90 deg per run; the sign the side of the cut). A unidirectional composite's friction is anisotropic: sliding
  along the fibres (``mu_par``) and across them (``mu_perp = rho mu_par``, ``rho`` drawn in 1.06-1.16) differ, and
  at the angle ``theta`` the friction along the sliding is ``mu_par cos^2 theta + mu_perp sin^2 theta`` (the
  orthotropic friction tensor's axial component). The motor's own lining is the quasi-isotropic mat of the same
  fibres and matrix, the angle average ``(mu_par + mu_perp) / 2``, so the slip friction is ``mu_p 2 (cos^2 theta +
  rho sin^2 theta) / (1 + rho)``: even and periodic in the logged angle, the motor's own at +-45 deg, lowest along
  the fibres and highest across them (0.93-0.97 and 1.03-1.07 of ``mu_p`` over the drawn ``rho``). The fibres lie
  in the strip's plane, so its normal stiffness does not depend on the angle; the friction's lateral component,
  which the guide takes (a few mN), is left out.
* ``plunger_relanding`` -- no column; a change between runs through the recording protocol, a re-seat every ``N``
  runs. The lab's procedure asks for a look at the tip every ``N`` runs (``N`` drawn among 6-10): after runs ``N``,
  ``2 N``, ... the operator lifts the stator off the bar with its cam lever, inspects the tip with a loupe and lowers
  it again, all within the plan's pause (the session clock shows nothing). The preload spring pushes the holder
  through a plunger that slides in a bronze bushing; when the stator is lowered the spring extends and the bushing's
  friction holds back ``F_b`` (drawn in 0.6-1.0 N) of its force, so the preload is ``P0 - F_b`` after a landing.
  Each switch-on of the drive (each run's start, before the slider leaves its stop) shakes the holder and the
  plunger slips, giving up a share ``1 - q`` of the friction it holds (``q`` drawn in 0.70-0.90): the run ``n``
  after a landing (``n`` = 0, 1, ...) runs at ``P0 - F_b q^(n + 1)``, the runs before the first landing at ``P0``
  (the operator's warm-up seated the plunger). A sawtooth of the preload in the run count, held per run; neither the
  runs' conditions nor the clock's gaps mark it.
* ``hook_cell_decoy`` -- a decoy, no effect on the motor: logged ``hook_cell_N`` per sample, a miniature S-beam load
  cell between the load's cable and the weight's hook (its few grams counted in the plan's loads). A positive load
  hangs over the pulley at the stroke's -position end and rises as the slider moves toward +position, a negative one
  over the other end's pulley, so the cable's tension at the hook is ``|m| g + m a`` (``m`` the signed load, ``a`` the
  slider's acceleration; ``max(0, .)``: a cable does not push; at the arrival's stop a rising weight slackens it and a
  sinking one jerks it; a run without a load hangs no cable and reads its zero). The cell's conditioner filters it
  first order with ``tau_c`` (drawn in 3-10 ms, from ``|m| g`` at each run's start), its zero is ``z_0 + c_d t`` on
  the session's clock (``z_0`` drawn in -5..+5 mN, ``c_d`` in -0.1..+0.1 mN/s), 2 mN of noise and 1 mN resolution. It
  carries the load, the direction, the motion's starts and stops, and the clock; the cell is stiff and light, so it
  acts on nothing and must not be traced.

Pass rule (fixed before any loop ran; the eighth to twenty-fourth audits'): a kind passes when a regressor of
``WANT`` is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse
before and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``:
3.037 / 2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``hook_cell`` is nowhere in ``traced_all`` and
``a <= 1.02 b``. ``WANT``: for the ringing core, the drive frequency (a name holding ``frequency`` or ``freq``); for
the fibres, the strip's logged angle (a name holding ``fibre_angle``); for the relanding, a regressor of the run
count or the session's clock or of a block or periodic function of them (a name holding ``time``, ``session``,
``clock``, ``elapsed``, ``index``, ``count``, ``order``, ``block``, ``file``, ``segment``, ``period``, ``cycl``,
``phase``, ``sin``, ``cos`` or ``saw``), none holding ``time_in_run`` or ``in_run`` (the run's own clock), ``onset``
or ``start`` (the run's start), ``break`` or ``pause`` (the lift fits in the plan's pause, all alike), ``_lag``,
``prev`` or ``last`` (the runs' conditions before), ``voltage``, ``load``, ``direction``, ``speed`` or ``position``.

Usage: python bench/blind_effects_twentyfifth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one
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
import blind_effects_twentythird as b23  # noqa: E402

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.slider import G_M_S2  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("core_magnetostriction", "lining_fibre_angle", "plunger_relanding", "hook_cell_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"core_magnetostriction": "frequency_Hz", "lining_fibre_angle": "fibre_angle_deg",
           "plunger_relanding": None, "hook_cell_decoy": "hook_cell_N"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"core_magnetostriction": ("frequency", "freq"),
        "lining_fibre_angle": ("fibre_angle",),
        "plunger_relanding": ("time", "session", "clock", "elapsed", "index", "count", "order", "block", "file",
                              "segment", "period", "cycl", "phase", "sin", "cos", "saw"),
        "hook_cell_decoy": ()}
#: names that hold a word of ``WANT`` but are not accepted (for the relanding the run's own clock, the run's start,
#: the plan's pauses, the runs' conditions before and the plan's factors)
NOT_WANT = {"plunger_relanding": ("time_in_run", "in_run", "onset", "start", "break", "pause", "_lag", "prev",
                                  "last", "voltage", "load", "direction", "speed", "position")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"hook_cell_decoy": "hook_cell"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
V0_CORE_REF_V = 324.0        # the amplitude at which the core's loss peak is r_324
FIBRE_RANGE_DEG = (-90.0, 90.0)   # the strips' fibre angles, uniform per run [deg]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 271, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "core_magnetostriction":
        out = {"sigma_f_Hz": float(rng.uniform(25.0, 45.0)), "f_c_Hz": float(rng.uniform(96880.0, 97120.0)),
               "Q_c": float(rng.uniform(300.0, 600.0)), "r_324_ohm": float(rng.uniform(20.0, 35.0))}
        out["df_Hz"] = out["sigma_f_Hz"] * rng.standard_normal(n_runs)
        return out
    if kind == "lining_fibre_angle":
        return {"rho": float(rng.uniform(1.06, 1.16)),
                "theta_deg": np.round(rng.uniform(*FIBRE_RANGE_DEG, n_runs), 1)}
    if kind == "plunger_relanding":
        return {"N": int(rng.integers(6, 11)), "F_b_N": float(rng.uniform(0.6, 1.0)),
                "q": float(rng.uniform(0.70, 0.90))}
    if kind == "hook_cell_decoy":
        return {"tau_c_s": float(rng.uniform(3e-3, 10e-3)), "z_0_N": float(rng.uniform(-5e-3, 5e-3)),
                "c_d_N_s": float(rng.uniform(-1e-4, 1e-4))}
    return {}


def run_frequency_Hz(p: dict, k: int, f0: float) -> float:
    """Run ``k``'s drive frequency [Hz] for the tracking drive: ``f0 + df_k`` at the drive's 0.1 Hz."""
    return float(np.round(f0 + p["df_Hz"][k], 1))


def core_impedance_ohm(f_Hz, V0_V, f_c_Hz: float, Q_c: float, r_324_ohm: float):
    """The ringing core's motional impedance in series with the winding [Ohm, complex] at the drive frequency
    ``f_Hz`` and amplitude ``V0_V``: ``r_324 (V0 / 324 V)^2 / (1 + j x)``, ``x = Q_c (2 f / f_c - f_c / (2 f))``."""
    f2 = 2.0 * np.asarray(f_Hz, float)
    x = Q_c * (f2 / f_c_Hz - f_c_Hz / f2)
    return r_324_ohm * (np.asarray(V0_V, float) / V0_CORE_REF_V) ** 2 / (1.0 + 1j * x)


def lossy_gain(driver, f_Hz: float, T_degC: float, Z_ohm: complex) -> float:
    """The tank's gain ``|V0 / V_inv1|`` with the impedance ``Z_ohm`` in series with its inductor: ``1 / |1 - w^2 L C
    + j w L / R_m + Z (1 / R_m + j w C)|``."""
    w = 2.0 * math.pi * f_Hz
    L = float(drv.tank_inductance_H(driver, T_degC, f_Hz))
    C = float(drv.tank_C1_F(driver, f_Hz)) + driver.C_m_F
    R = driver.R_m_ohm
    return 1.0 / abs(1.0 - w * w * L * C + 1j * w * L / R + complex(Z_ohm) * (1.0 / R + 1j * w * C))


def core_V0(driver, V0_plan: float, f_Hz: float, f0_Hz: float, T_degC: float, p: dict) -> tuple[float, float]:
    """``(V0, V0_free)``: the stator's amplitude [V] at the drive frequency ``f_Hz`` from the supply the operator
    set for ``V0_plan`` at ``f0_Hz``, with the ringing core at that amplitude (the fixed point of ``V0 = V_inv1
    |H(f, Z(f, V0))|``, iterated from ``V0_free``), and without it."""
    V1 = V0_plan / lossy_gain(driver, f0_Hz, T_degC, 0.0)
    V_free = V1 * lossy_gain(driver, f_Hz, T_degC, 0.0)
    V = V_free
    for _ in range(200):
        Z = complex(core_impedance_ohm(f_Hz, V, p["f_c_Hz"], p["Q_c"], p["r_324_ohm"]))
        V_new = V1 * lossy_gain(driver, f_Hz, T_degC, Z)
        if abs(V_new - V) <= 1e-13 * V_free:
            return V_new, V_free
        V = V_new
    raise ValueError(f"the core's fixed point did not converge at {f_Hz} Hz, {V0_plan} V")


def fibre_factor(theta_deg, rho: float):
    """The slip friction over the motor's (a quasi-isotropic lining) at the fibre angle ``theta_deg`` to the
    track: ``2 (cos^2 theta + rho sin^2 theta) / (1 + rho)``."""
    t = np.radians(np.asarray(theta_deg, float))
    return 2.0 * (np.cos(t) ** 2 + rho * np.sin(t) ** 2) / (1.0 + rho)


def plunger_offset_N(k: int, N: int, F_b_N: float, q: float) -> float:
    """The friction the plunger holds back from the preload in run ``k`` (from 0) [N]: 0 before the first landing
    (after run ``N``), else ``F_b q^(n + 1)`` with ``n = k mod N`` the runs since the last landing."""
    if k < N:
        return 0.0
    return F_b_N * q ** (k % N + 1)


def hook_tension_N(v_m_s, h_s: float, L: float):
    """The cable's tension at the hook [N] on the co-simulation's grid (speeds ``v_m_s``, step ``h_s``) for the
    signed load ``L``: ``max(0, |L| g + L a)``, ``a`` the slider's acceleration (0 at the first step)."""
    a = np.concatenate([[0.0], np.diff(np.asarray(v_m_s, float)) / h_s])
    return np.maximum(0.0, abs(L) * G_M_S2 + L * a)


def hook_cell_N(t_s, v_m_s, h_s: float, L: float, t0_s: float, p: dict):
    """The cell's reading [N] (no noise, no rounding) at the run's times ``t_s`` (the co-simulation's grid): the
    tension through the conditioner's first-order filter ``tau_c`` (from ``|L| g`` at rest, exact for a tension
    held over each step) plus the zero ``z_0 + c_d (t0 + t)`` on the session's clock."""
    u = hook_tension_N(v_m_s, h_s, L)
    y = np.empty_like(u)
    y[0] = abs(L) * G_M_S2
    a = math.exp(-h_s / p["tau_c_s"])
    for i in range(1, len(u)):
        y[i] = u[i] + (y[i - 1] - u[i]) * a
    return y + p["z_0_N"] + p["c_d_N_s"] * (t0_s + np.asarray(t_s, float))


def run_motor(kind: str, mp, p: dict, k: int, V0: float, f_Hz: float, f0_Hz: float = 48500.0, T_degC: float = 25.0):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` at the plan's ``V0`` and the drive frequency
    ``f_Hz`` (``f0_Hz`` and ``T_degC`` those of the operator's supply table)."""
    if kind == "core_magnetostriction":
        V, V_free = core_V0(mp.driver, V0, f_Hz, f0_Hz, T_degC, p)
        return mp.replace(driver__R_m_ohm=b23.tank_R_for_V0(mp.driver, V_free, V, f_Hz, T_degC))
    if kind == "lining_fibre_angle":
        return mp.replace(interface__mu_p=mp.interface.mu_p * float(fibre_factor(p["theta_deg"][k], p["rho"])))
    if kind == "plunger_relanding":
        return mp.replace(stator__P0_N=mp.stator.P0_N - plunger_offset_N(k, p["N"], p["F_b_N"], p["q"]))
    return mp


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds_run):
        f = run_frequency_Hz(p, k, plan.f_drive_Hz) if kind == "core_magnetostriction" else plan.f_drive_Hz
        mp = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, V, f, plan.f_drive_Hz, plan.ambient_degC)
        f_law = (lambda t, s, v, f=f: f) if kind == "core_magnetostriction" else None
        r = b5.traverse(mp, nominal, plan, V, L, d, f_law=f_law, record=b5.POSITION_AND_SPEED)[0]
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 272, k]).standard_normal(len(t))
        if kind == "lining_fibre_angle":
            extra["fibre_angle_deg"] = np.full(len(t), float(p["theta_deg"][k]))
        elif kind == "hook_cell_decoy":
            y = hook_cell_N(r["time"], r["Slider.v"], plan.step_s, L, t_next, p)[idx]
            extra["hook_cell_N"] = np.round(y + 2e-3 * noise, 3)
        f_col = np.full(len(t), f) if kind == "core_magnetostriction" else None
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, f_col, **extra)
        frames.append(out)
        V0_run = (core_V0(nominal.driver, V, f, plan.f_drive_Hz, plan.ambient_degC, p)[0]
                  if kind == "core_magnetostriction" else V)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p, "R_m_ohm": mp.driver.R_m_ohm,
                        "f_Hz": f, "V0_V": V0_run, "mu_sd": mp.slider.mu_sd, "mass_kg": mp.slider.mass_kg,
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
