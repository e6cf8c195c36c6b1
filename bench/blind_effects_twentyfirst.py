#!/usr/bin/env python
"""A twenty-first blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the twenty earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_twentieth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row, traverse
and ``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan
at a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). Every kind sets FMU parameters per run; the speed
is always the DAQ's derivative of the recorded position. Each kind draws from one random stream of its seed. The
kinds:

* ``holder_thermostat_cycle`` -- no column; a change between runs on the session clock, periodic. The stator holder
  sits on a small heated plate that a bimetal snap-disc thermostat holds above the lab's 25 degC: it switches the
  heater off when the plate reaches ``T_set + h`` and on again when it has cooled to ``T_set - h`` (``T_set`` =
  30 degC; ``h``, half the disc's differential, drawn in 2.0-3.0 K). The plate follows Newton's law of heating and
  cooling with one time constant ``tau`` (drawn in 12-25 s), toward the heater's equilibrium ``T_hi`` (drawn in
  38-44 degC) while on and toward the lab's 25 degC while off, so its temperature is a relaxation oscillation: heating
  ``T_hi - (T_hi - T_set + h) exp(-u / tau)`` for ``0 <= u < t_on``, cooling ``25 + (T_set + h - 25) exp(-(u - t_on)
  / tau)`` for ``t_on <= u < P``, with ``t_on = tau ln((T_hi - T_set + h) / (T_hi - T_set - h))``, ``t_off = tau
  ln((T_set + h - 25) / (T_set - h - 25))``, ``P = t_on + t_off`` (14-54 s: 1.7-6.5 cycles in a session of some
  90 s) and ``u = (t + phi P) mod P`` (``t`` the session clock, ``phi`` the cycle's phase at the session's start,
  drawn uniform: the thermostat has cycled for hours). The clamped stator is at the plate's temperature, and its
  modes drift with it from the motor's own (identified at ``T_set``): ``f_b0 + c_b (T - T_set)``, ``f_l0 + c_l (T -
  T_set)`` (``c_b`` drawn in -30..-20 Hz/K, ``c_l`` in -20..-10 Hz/K), held at the temperature of each run's start
  (a run, 0.15-0.8 s, and the stator's own lag behind the plate are short against the cycle: left out). No column
  logs the plate; its cycle follows the clock alone, neither the plan nor the runs.
* ``holder_thermostat_logged`` -- the thermostat's control, not a kind of its own: the same draw and the same motion
  as ``holder_thermostat_cycle`` at the seed, with the plate's temperature at each run's start logged as
  ``holder_plate_C`` (per sample, 0.01 degC resolution, no noise), as a thermocouple read at the run's trigger would.
  What the loop makes of the state logged tells the hidden cycle's loss.
* ``drive_field_ferrite`` -- logged ``drive_field_mT`` per sample, a Hall gaussmeter on the drive's board (0.05 mT of
  noise, 0.01 mT resolution). A magnetic-immunity study: the drive's board sits between a pair of Helmholtz coils
  that apply a DC field ``B`` set per run (uniform 0-25 mT, one polarity). The tank's inductor is an unshielded
  drum-core ferrite: the external field biases its open core, whose incremental permeability follows the slope of
  the anhysteretic magnetisation, Langevin's ``M = M_s L(H / a)``, ``L(x) = coth x - 1 / x``, so it is ``3 L'(x)``
  of its unbiased value with ``L'(x) = 1 / x^2 - 1 / sinh^2 x`` (``L'(0) = 1 / 3``) and ``x = B / B_a`` (``B_a``
  drawn in 17-22 mT: the open core's demagnetisation makes the field inside it a multiple of the applied one). The
  core carries a share ``s`` of the inductance (drawn in 0.50-0.65; the rest is the winding's air path), so ``L_H(B)
  = L_H (1 - s + s 3 L'(B / B_a))``: flat at small fields (``1 - s x^2 / 5``), falling to 0.79-0.89 of it at 25 mT.
  The operator's supply table is for the unbiased tank and ``voltage_V`` logs the plan's V0: the tank's gain, whose
  peak in ``L_H`` the drive sits on, falls with the field (about quadratically in the inductance's drop).
* ``stator_gradient_asym`` -- logged ``stator_dT_K`` per sample, a differential thermocouple across the stator's
  width (0.05 K of noise, 0.01 K resolution). A thermal-gradient study (a motor mounted beside a heat source): the
  holder's two side pads are Peltier elements that set a temperature difference ``dT`` across the plate per run
  (uniform in -25..+25 K), its mean held at 25 degC, so the split electrodes' two halves sit at ``25 +- dT / 2``.
  The ceramic's piezoelectric coupling rises with its temperature, by ``c`` per kelvin (drawn in 0.30-0.50 %/K), so
  the halves' couplings differ by ``c dT`` and the B2 coupling's asymmetry between CH1 and CH2 is ``asym_b = c dT /
  2`` (the motor's own is 0): a forward run's B2 forcing ``A_b (1 + asym_b)``, a backward run's ``A_b (1 - asym_b)``.
  The mean temperature does not move, so neither do the modes. A law of the logged channel times the direction: the
  same ``dT`` speeds one direction up and slows the other down (the slow runs the most).
* ``encoder_signal_decoy`` -- a decoy, no effect on the motor: logged ``encoder_signal_pct`` per sample, the optical
  encoder's signal strength as its readhead reports it (the amplitude of its quadrature signals in % of their
  nominal, 0.2 % of noise, 0.1 % resolution). The scale's tape lies at a slight angle to the guide, so the readhead's
  ride height is off its nominal by ``e(s) = e0 + e1 s / 21 mm`` (``e0`` drawn in -40..+40 um, ``|e1|`` in 40-80 um,
  its sign at random) and the signal follows the readhead's ride-height tolerance curve ``exp(-(e / w)^2)`` (``w``
  drawn in 100-150 um). The stator's vibration reaches the slider and its scale vibrates along the axis at the drive
  frequency with the amplitude ``a = a_324 V0 / 324 V`` (``a_324`` drawn in 0.3-0.5 um); the readhead averages over
  many cycles, so the fringes' contrast is the time average of ``cos(2 pi (x + a sin wt) / p)``, Bessel's ``J0(2 pi a /
  p)`` (``p`` = 4 um, the scale's signal period). The reading is ``100 exp(-(e(s) / w)^2) J0(2 pi a / p)``: it follows
  the slider's position within a run and the plan's V0 between runs; the encoder interpolates correctly at any
  strength above its 30 % alarm, so it acts on nothing and must not be traced.

Pass rule (fixed before any loop ran; the eighth to twentieth audits'): a kind passes when a regressor of ``WANT`` is
among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before and
after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``encoder_signal`` is nowhere in ``traced_all`` and ``a <=
1.02 b``. ``WANT``: the gaussmeter's column for the ferrite (a name holding ``drive_field``); the differential
thermocouple's for the gradient (a name holding ``stator_dT``); for the thermostat, a regressor of the session clock
or of the session's stretches (a name holding ``time``, ``session``, ``block``, ``cycle``, ``period``, ``oscill`` or
``thermostat``), none holding ``time_in_run`` or ``time_step`` (the run's own clock and the stamps' steps carry no
state between runs) nor ``load``, ``voltage``, ``direction``, ``position`` or ``speed`` (the plan's factors and the
motion, which the cycle does not follow). The control is reported with its own column (``holder_plate_C``) but not
counted.

Usage: python bench/blind_effects_twentyfirst.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one of
the above or clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run
nrmse before and after, channels considered, CPU of the close loop by ``time.process_time``), plus ``traced_all``
(every traced regressor), ``want`` (the regressors accepted as the effect's) and ``accepted_in_first_two``.
"""
import math
import sys
from pathlib import Path

import numpy as np
from scipy.special import j0

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("holder_thermostat_cycle", "drive_field_ferrite", "stator_gradient_asym", "encoder_signal_decoy",
         "holder_thermostat_logged")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"holder_thermostat_logged": "holder_thermostat_cycle"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"holder_thermostat_cycle": None, "drive_field_ferrite": "drive_field_mT",
           "stator_gradient_asym": "stator_dT_K", "encoder_signal_decoy": "encoder_signal_pct",
           "holder_thermostat_logged": "holder_plate_C"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"holder_thermostat_cycle": ("time", "session", "block", "cycle", "period", "oscill", "thermostat"),
        "drive_field_ferrite": ("drive_field",),
        "stator_gradient_asym": ("stator_dT",),
        "encoder_signal_decoy": (),
        "holder_thermostat_logged": ("holder_plate",)}
#: names that hold a word of ``WANT`` but are not accepted (the run's own clock, the stamps, the plan, the motion)
NOT_WANT = {"holder_thermostat_cycle": ("time_in_run", "time_step", "load", "voltage", "direction", "position",
                                        "speed")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"encoder_signal_decoy": "encoder_signal"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
T_LAB = 25.0                 # the lab's temperature [degC]
T_SET = 30.0                 # the holder's thermostat set point [degC]: the motor's modes are identified there
B_MAX_MT = 25.0              # the largest field the coils apply [mT]
DT_MAX_K = 25.0              # the largest temperature difference across the stator [K]
STROKE_HALF_M = 0.021        # the stroke's half length: the ride height's lever [m]
SIGNAL_PERIOD_UM = 4.0       # the encoder's signal period [um]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the thermostat's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 231, KINDS.index(src) if src in KINDS else 99])
    if src == "holder_thermostat_cycle":
        return {"h_K": float(rng.uniform(2.0, 3.0)), "tau_s": float(rng.uniform(12.0, 25.0)),
                "T_hi_C": float(rng.uniform(38.0, 44.0)), "phi": float(rng.uniform(0.0, 1.0)),
                "c_b_Hz_per_K": float(rng.uniform(-30.0, -20.0)), "c_l_Hz_per_K": float(rng.uniform(-20.0, -10.0))}
    if kind == "drive_field_ferrite":
        return {"s_core": float(rng.uniform(0.5, 0.65)), "B_a_mT": float(rng.uniform(17.0, 22.0)),
                "B_mT": rng.uniform(0.0, B_MAX_MT, n_runs)}
    if kind == "stator_gradient_asym":
        return {"c_per_K": float(rng.uniform(0.0030, 0.0050)), "dT_K": rng.uniform(-DT_MAX_K, DT_MAX_K, n_runs)}
    if kind == "encoder_signal_decoy":
        return {"e0_um": float(rng.uniform(-40.0, 40.0)),
                "e1_um": float(rng.uniform(40.0, 80.0) * rng.choice((-1.0, 1.0))),
                "w_um": float(rng.uniform(100.0, 150.0)), "a324_um": float(rng.uniform(0.3, 0.5))}
    return {}


def thermostat_times(h: float, tau: float, T_hi: float) -> tuple[float, float]:
    """``(t_on, t_off)`` [s]: the heater's on time from ``T_set - h`` up to ``T_set + h`` toward ``T_hi``, ``tau
    ln((T_hi - T_set + h) / (T_hi - T_set - h))``, and its off time back down toward the lab's 25 degC, ``tau
    ln((T_set + h - 25) / (T_set - h - 25))``."""
    t_on = tau * math.log((T_hi - T_SET + h) / (T_hi - T_SET - h))
    t_off = tau * math.log((T_SET + h - T_LAB) / (T_SET - h - T_LAB))
    return t_on, t_off


def plate_temp_C(t, h: float, tau: float, T_hi: float, phi: float):
    """The plate's temperature [degC] at the session times ``t``: with ``u = (t + phi P) mod P``, heating ``T_hi -
    (T_hi - T_set + h) exp(-u / tau)`` for ``u < t_on``, cooling ``25 + (T_set + h - 25) exp(-(u - t_on) / tau)``
    after it (:func:`thermostat_times`)."""
    t_on, t_off = thermostat_times(h, tau, T_hi)
    P = t_on + t_off
    u = np.mod(np.asarray(t, float) + phi * P, P)
    heat = T_hi - (T_hi - T_SET + h) * np.exp(-u / tau)
    cool = T_LAB + (T_SET + h - T_LAB) * np.exp(-(u - t_on) / tau)
    return np.where(u < t_on, heat, cool)


def langevin_slope(x):
    """The slope of Langevin's function ``L(x) = coth x - 1 / x``: ``L'(x) = 1 / x^2 - 1 / sinh^2 x``, even in x,
    1/3 at 0 (its series ``1/3 - x^2 / 15 + 2 x^4 / 189`` below |x| = 0.05, where the difference cancels)."""
    x = np.abs(np.asarray(x, float))
    small = x < 0.05
    xs = np.where(small, 1.0, x)
    exact = 1.0 / xs ** 2 - 1.0 / np.sinh(xs) ** 2
    return np.where(small, 1.0 / 3.0 - x ** 2 / 15.0 + 2.0 * x ** 4 / 189.0, exact)


def inductance_factor(B, s: float, B_a: float):
    """The tank inductor's share of its unbiased value in the field ``B``: ``1 - s + s 3 L'(B / B_a)``."""
    return 1.0 - s + s * 3.0 * langevin_slope(np.asarray(B, float) / B_a)


def coupling_asymmetry(dT, c: float):
    """The B2 coupling's asymmetry between CH1 and CH2 when the halves sit at ``25 +- dT / 2``: ``c dT / 2``."""
    return 0.5 * c * np.asarray(dT, float)


def ride_gain(s, e0: float, e1: float, w: float):
    """The readhead's share of its signal at the slider's positions ``s`` [m]: ``exp(-(e(s) / w)^2)``, ``e(s) = e0 +
    e1 s / 21 mm`` (``e0``, ``e1``, ``w`` in um)."""
    e = e0 + e1 * np.asarray(s, float) / STROKE_HALF_M
    return np.exp(-(e / w) ** 2)


def vibration_contrast(V0: float, a324: float) -> float:
    """The fringes' contrast under the scale's vibration at V0: ``J0(2 pi a / p)``, ``a = a_324 V0 / 324 V``."""
    return float(j0(2.0 * math.pi * a324 * float(V0) / 324.0 / SIGNAL_PERIOD_UM))


def encoder_signal_pct(s, V0: float, p: dict):
    """The readhead's signal strength [%] (no noise, no rounding): ``100 ride_gain(s) vibration_contrast(V0)``."""
    return 100.0 * ride_gain(s, p["e0_um"], p["e1_um"], p["w_um"]) * vibration_contrast(V0, p["a324_um"])


def run_motor(kind: str, mp, p: dict, k: int, t_start: float):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``t_start``: the run's start on the session
    clock)."""
    if STREAM.get(kind, kind) == "holder_thermostat_cycle":
        dT = float(plate_temp_C(t_start, p["h_K"], p["tau_s"], p["T_hi_C"], p["phi"])) - T_SET
        return mp.replace(stator__f_b0_Hz=mp.stator.f_b0_Hz + p["c_b_Hz_per_K"] * dT,
                          stator__f_l0_Hz=mp.stator.f_l0_Hz + p["c_l_Hz_per_K"] * dT)
    if kind == "drive_field_ferrite":
        return mp.replace(driver__L_H=mp.driver.L_H * float(inductance_factor(p["B_mT"][k], p["s_core"],
                                                                               p["B_a_mT"])))
    if kind == "stator_gradient_asym":
        return mp.replace(stator__asym_b=mp.stator.asym_b + float(coupling_asymmetry(p["dT_K"][k], p["c_per_K"])))
    return mp


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    thermo = STREAM.get(kind, kind) == "holder_thermostat_cycle"
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds_run):
        mp = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, t_next)
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        T_plate = float(plate_temp_C(t_next, p["h_K"], p["tau_s"], p["T_hi_C"], p["phi"])) if thermo else None
        extra = {}
        noise = np.random.default_rng([seed, 232, k]).standard_normal(len(t))
        if kind == "drive_field_ferrite":
            extra["drive_field_mT"] = np.round(p["B_mT"][k] + 0.05 * noise, 2)
        elif kind == "stator_gradient_asym":
            extra["stator_dT_K"] = np.round(p["dT_K"][k] + 0.05 * noise, 2)
        elif kind == "encoder_signal_decoy":
            extra["encoder_signal_pct"] = np.round(encoder_signal_pct(s, V, p) + 0.2 * noise, 1)
        elif kind == "holder_thermostat_logged":
            extra["holder_plate_C"] = np.full(len(t), round(T_plate, 2))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "f_b0_Hz": mp.stator.f_b0_Hz, "f_l0_Hz": mp.stator.f_l0_Hz, "L_H": mp.driver.L_H,
                        "asym_b": mp.stator.asym_b, "T_plate_C": T_plate, "t_start_s": t_next,
                        "duration_s": float(r["time"][-1])})
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
