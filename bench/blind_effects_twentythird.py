#!/usr/bin/env python
"""A twenty-third blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the twenty-two earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_twentysecond.py``, ``bench/blind_effects_stamps.py``)
names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row and
``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan
at a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). Every kind sets FMU parameters per run, the
bellows also an FMU input per step as a function of the co-simulation's own state (the slider's position and speed
one step before, ``bench/blind_effects_fifth.py``'s ``StateInput``); the speed is always the DAQ's derivative of the
recorded position. Each kind draws from one random stream of its seed. The kinds:

* ``paschen_glow_clamp`` -- logged ``chamber_pressure_hPa`` per sample, a capacitance manometer on the rig's vacuum
  chamber (0.2 % of the reading of noise, 0.01 hPa resolution). A low-pressure qualification: the chamber's
  controller holds a new pressure ``p`` per run (log-uniform 12-25 hPa, the critical range of an ascent). The
  stator's split electrodes face each other across a gap ``d`` (drawn in 0.55-0.75 mm) that sees the drive's
  amplitude ``V0``. The gas in the gap breaks down by Paschen's law, ``V_b(p d) = B p d / (ln(A p d) - ln(ln(1 +
  1 / gamma)))`` (air: ``A`` = 11.25 /(Pa m), ``B`` = 273.8 V/(Pa m), i.e. 15 /(cm Torr) and 365 V/(cm Torr),
  ``gamma`` = 0.01; no breakdown where the denominator is not positive), whose minimum, 305 V at ``p d`` = 1.11 Pa
  m, falls at 14.9-20.3 hPa over the drawn gaps; the electrodes' edges enhance the field by ``beta`` (drawn in
  1.03-1.09). Where ``V0`` exceeds ``V_c = V_b(p d) / beta`` a glow burns in the gap and, as a glow does, holds it at
  that voltage: the drive's amplitude is ``min(V0, V_c)``, the excess of the tank's current going through the
  discharge. The co-simulation sets it through the tank's resistance: the discharge is a shunt in parallel with the
  stator's ``R_m`` such that the tank's gain at the operator's supply (set for ``V0`` by the nominal tank) gives
  ``V_c``. A threshold that joins the logged pressure and the amplitude, which only the plan's two highest amplitudes
  reach (324 V: by up to 44 V; 290 V: by up to 10 V), non-monotone in ``p`` (deepest at Paschen's minimum).
  ``voltage_V`` logs the plan's V0. The contact, the guide and the modes do not see the pressure over this range (a
  dry PTFE-composite lining; the stator's damping is its mount's and the contact's).
* ``guide_film_wearthrough`` -- no column; a change between runs set by the slider's travel since the session's
  start. Before the session the guide's crossed-roller tracks were sprayed with a bonded PTFE dry film; the rollers'
  micro-slip wears it through. Its coverage after the slider's travel ``x`` is ``c(x) = exp(-(x / x_w)^k)`` (a
  Weibull wear-through: ``x_w`` drawn in 1.0-2.0 m, ``k`` in 2-4; a session travels 72 x 42 mm = 3.0 m), and the
  guide's Coulomb levels are the dry ones times ``1 - f c(x)`` (``f`` drawn in 0.09-0.18: the film lowers the
  guide's friction coefficient from 0.10 to 0.082-0.091 when fresh). Every run travels the stroke ``X`` (42 mm); the
  co-simulation holds the levels per run at the film's coverage at the run's mid-travel, ``x = (k + 1/2) X`` for
  the run ``k`` (from 0). The friction rises along the session in a sigmoid (flat while the film holds, steep when
  it breaks through, flat again), whatever the runs' conditions: only the protocol's own clock carries it.
* ``bellows_intake_drag`` -- no column; within a run, through the motion itself. A pleated bellows cover (effective
  diameter 40 mm) keeps the lining's wear dust off the guide between the slider and the frame's end plate at the
  +position end. Moving toward +position the slider folds it and the air leaves through a flap valve in the end
  plate without resistance; moving toward -position it unfolds it and draws the air in through the end plate's
  filter vent, a sharp-edged orifice of diameter ``d_v`` (drawn in 6.5-8.0 mm, discharge coefficient 0.61): a
  turbulent orifice flow, so the depression is ``dp = (rho / 2) (A_b v / (C_d a_v))^2`` (air 1.20 kg/m^3) and it
  pulls the slider toward the end plate, ``F = A_b dp = c_q v^2`` for ``v < 0`` (``c_q = rho A_b^3 / (2 C_d^2
  a_v^2)``, 1.27-2.91 N s^2/m^2 over the drawn vents; 0 for ``v >= 0``). A drag in the square of the speed, on the
  backward runs only, over the whole stroke. Set through the slider's load input as the equivalent mass ``m_load -
  F / g`` computed each step from the slider's speed of the step before, with the load's inertia moved into the
  slider's mass and the guide's Coulomb levels and preload share rescaled (:func:`blind_effects.load_in_slider_motor`).
  The air's inertia and the bellows' own stiffness and mass are left out.
* ``bellows_intake_logged`` -- the bellows' control, not a kind of its own: the same draw and the same motion as
  ``bellows_intake_drag`` at the seed, with the bellows' depression logged as ``bellows_dp_Pa`` per sample (``dp``
  at the sample's slider speed, 0 while the bellows folds or rests; 0.3 Pa of noise, 0.1 Pa resolution), as a
  differential pressure sensor on the bellows would read it. What the loop makes of the state logged tells the
  hidden bellows' loss.
* ``mic_level_decoy`` -- a decoy, no effect on the motor: logged ``mic_dBA`` per sample, a sound level meter 0.3 m
  from the motor (A-weighted, IEC 61672 ``fast`` time weighting, 125 ms). The rig is heard over the lab's background
  ``L_bg`` (drawn in 30-36 dBA): the drive's magnetics and the stator's audible subharmonics follow the amplitude,
  the guide's rollers the speed, ``L_m = L_ref + 20 log10(V0 / 324 V) + 20 n log10(|v| / 0.2 m/s)`` (``L_ref``
  drawn in 50-58 dBA, ``n`` in 1.0-1.6; ``v`` the slider's speed at the sample). The meter squares and averages,
  ``y_k = y_(k-1) + (1 - exp(-(t_k - t_(k-1)) / 0.125 s)) (q_k - y_(k-1))`` with ``q = 10^(L_bg / 10) + 10^(L_m /
  10)`` and ``y_0 = 10^(L_bg / 10)`` (the rig silent at rest), and reads ``10 log10(y)`` dBA, 0.5 dB of noise, 0.1
  dB resolution. It carries the voltage and the speed with a lag: a consequence of the conditions and the motion; a
  microphone acts on nothing and must not be traced.

Pass rule (fixed before any loop ran; the eighth to twenty-second audits'): a kind passes when a regressor of
``WANT`` is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse
before and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``:
3.037 / 2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``mic_dB`` is nowhere in ``traced_all`` and
``a <= 1.02 b``. ``WANT``: the manometer's column for the glow (a name holding ``chamber_pressure``); for the dry
film, a regressor of the session's own clock or count (a name holding ``time``, ``session``, ``clock``, ``elapsed``,
``index``, ``count``, ``cumul`` or ``block``: the slider's travel since the session's start is the plan's count of
runs times the stroke), none holding ``time_in_run`` or ``in_run`` (the run's own clock), ``onset`` or ``start``
(the run's start), ``break`` or ``pause`` (the session has no breaks and the plan's pauses are all alike), ``_lag``,
``prev`` or ``last`` (the film follows the travel, not the runs' conditions before), ``voltage``, ``load``,
``direction``, ``speed`` or ``position``; for the bellows, a regressor of the speed or of a drag (a name holding
``speed``, ``veloc``, ``drag``, ``quadr``, ``square`` or ``bellows``), none holding ``lag``, ``prev``, ``last``,
``history`` or ``memory`` (the drag is the step's own, not a lag or the runs before), ``time_in_run``, ``position``,
``stop`` or ``travel`` (it acts over the whole stroke), ``voltage`` or ``load``. The control is reported with its
own column (``bellows_dp_Pa``) but not counted.

Usage: python bench/blind_effects_twentythird.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one
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
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.slider import G_M_S2  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("paschen_glow_clamp", "guide_film_wearthrough", "bellows_intake_drag", "mic_level_decoy",
         "bellows_intake_logged")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"bellows_intake_logged": "bellows_intake_drag"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"paschen_glow_clamp": "chamber_pressure_hPa", "guide_film_wearthrough": None,
           "bellows_intake_drag": None, "mic_level_decoy": "mic_dBA", "bellows_intake_logged": "bellows_dp_Pa"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"paschen_glow_clamp": ("chamber_pressure",),
        "guide_film_wearthrough": ("time", "session", "clock", "elapsed", "index", "count", "cumul", "block"),
        "bellows_intake_drag": ("speed", "veloc", "drag", "quadr", "square", "bellows"),
        "mic_level_decoy": (),
        "bellows_intake_logged": ("bellows_dp",)}
#: names that hold a word of ``WANT`` but are not accepted (the run's own clock, the run's start, the
#: session's breaks and pauses, the runs before, the plan's factors; for the bellows lags, the runs before, places
#: along the stroke and the plan's factors)
NOT_WANT = {"guide_film_wearthrough": ("time_in_run", "in_run", "onset", "start", "break", "pause", "_lag", "prev",
                                       "last", "voltage", "load", "direction", "speed", "position"),
            "bellows_intake_drag": ("lag", "prev", "last", "history", "memory", "time_in_run", "position", "stop",
                                    "travel", "voltage", "load")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"mic_level_decoy": "mic_dB"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
PRESSURE_RANGE_HPA = (12.0, 25.0)   # the chamber's pressure set per run, log-uniform [hPa]
PASCHEN_A_PER_PA_M = 11.25          # air: 15 /(cm Torr)
PASCHEN_B_V_PER_PA_M = 273.8        # air: 365 V/(cm Torr)
PASCHEN_GAMMA = 0.01                # secondary-emission coefficient of the electrodes
BELLOWS_DIAMETER_M = 0.040          # the bellows' effective diameter [m]
VENT_CD = 0.61                      # a sharp-edged orifice's discharge coefficient
AIR_KG_M3 = 1.20                    # the air's density [kg/m^3]
MIC_TAU_S = 0.125                   # the sound level meter's ``fast`` time weighting [s]
MIC_V0_REF_V, MIC_V_REF_M_S = 324.0, 0.2   # the reference amplitude and speed of ``L_ref``


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the bellows')."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 251, KINDS.index(src) if src in KINDS else 99])
    if kind == "paschen_glow_clamp":
        lo, hi = np.log10(PRESSURE_RANGE_HPA)
        return {"d_m": float(rng.uniform(0.55e-3, 0.75e-3)), "beta": float(rng.uniform(1.03, 1.09)),
                "p_hPa": 10.0 ** rng.uniform(lo, hi, n_runs)}
    if kind == "guide_film_wearthrough":
        return {"f": float(rng.uniform(0.09, 0.18)), "x_w_m": float(rng.uniform(1.0, 2.0)),
                "k": float(rng.uniform(2.0, 4.0))}
    if src == "bellows_intake_drag":
        return {"d_v_m": float(rng.uniform(6.5e-3, 8.0e-3))}
    if kind == "mic_level_decoy":
        return {"L_bg_dBA": float(rng.uniform(30.0, 36.0)), "L_ref_dBA": float(rng.uniform(50.0, 58.0)),
                "n": float(rng.uniform(1.0, 1.6))}
    return {}


def paschen_V(pd_Pa_m):
    """The gap's breakdown voltage [V] at the product ``p d`` [Pa m]: ``B pd / (ln(A pd) - ln(ln(1 + 1 /
    gamma)))``, infinite where the denominator is not positive."""
    pd = np.asarray(pd_Pa_m, float)
    den = np.log(PASCHEN_A_PER_PA_M * pd) - math.log(math.log(1.0 + 1.0 / PASCHEN_GAMMA))
    return np.where(den > 0, PASCHEN_B_V_PER_PA_M * pd / np.where(den > 0, den, 1.0), np.inf)


def glow_V0(V0, p_hPa, d_m: float, beta: float):
    """The drive's amplitude [V] with the glow: ``min(V0, V_b(p d) / beta)`` (``p`` in hPa)."""
    return np.minimum(np.asarray(V0, float), paschen_V(100.0 * np.asarray(p_hPa, float) * d_m) / beta)


def tank_R_for_V0(driver, V0_set: float, V0_target: float, f_Hz: float, T_degC: float) -> float:
    """The tank's resistance [Ohm] that gives ``V0_target`` at the supply the operator set for ``V0_set`` by the
    nominal tank ``driver``: ``omega L / sqrt(1 / |H'|^2 - (1 - omega^2 L C)^2)``, ``|H'| = |H| V0_target /
    V0_set``; the driver's own ``R_m`` when ``V0_target >= V0_set``."""
    if V0_target >= V0_set:
        return driver.R_m_ohm
    w = 2.0 * math.pi * f_Hz
    L = float(drv.tank_inductance_H(driver, T_degC, f_Hz))
    C = float(drv.tank_C1_F(driver, f_Hz)) + driver.C_m_F
    H = abs(complex(drv.tank_gain(w, L, C, driver.R_m_ohm))) * V0_target / V0_set
    return w * L / math.sqrt(1.0 / H ** 2 - (1.0 - w * w * L * C) ** 2)


def film_coverage(x_m, x_w: float, k: float):
    """The dry film's coverage after the slider's travel ``x_m`` [m]: ``exp(-(x / x_w)^k)``."""
    return np.exp(-(np.asarray(x_m, float) / x_w) ** k)


def guide_factor(x_m, f: float, x_w: float, k: float):
    """The guide's Coulomb levels over the dry ones after the travel ``x_m``: ``1 - f film_coverage(x)``."""
    return 1.0 - f * film_coverage(x_m, x_w, k)


def bellows_area_m2() -> float:
    """The bellows' effective area [m^2]: ``pi D^2 / 4``."""
    return math.pi * BELLOWS_DIAMETER_M ** 2 / 4.0


def bellows_coefficient(d_v_m: float) -> float:
    """The bellows' drag coefficient [N s^2/m^2] for a vent of diameter ``d_v_m``: ``rho A_b^3 / (2 C_d^2 a_v^2)``."""
    a_v = math.pi * d_v_m ** 2 / 4.0
    return AIR_KG_M3 * bellows_area_m2() ** 3 / (2.0 * VENT_CD ** 2 * a_v ** 2)


def bellows_force_N(v: float, c_q: float) -> float:
    """The bellows' force on the slider [N] (positive toward +position) at the speed ``v``: ``c_q v^2`` while it
    unfolds (``v < 0``), else 0."""
    return c_q * v * v if v < 0 else 0.0


def bellows_dp_Pa(v, c_q: float):
    """The bellows' depression [Pa] at the speeds ``v``: ``c_q v^2 / A_b`` for ``v < 0``, else 0."""
    v = np.asarray(v, float)
    return np.where(v < 0, c_q * v * v / bellows_area_m2(), 0.0)


def mic_level_dBA(t, v, V0: float, p: dict) -> np.ndarray:
    """The sound level meter's reading [dBA] (no noise, no rounding) at the sample times ``t`` and slider speeds
    ``v`` of a run at the amplitude ``V0``: the ``fast``-weighted mean square of the background and the rig."""
    t, v = np.asarray(t, float), np.asarray(v, float)
    bg = 10.0 ** (p["L_bg_dBA"] / 10.0)
    q = bg + 10.0 ** (p["L_ref_dBA"] / 10.0) * (V0 / MIC_V0_REF_V) ** 2 * (np.abs(v) / MIC_V_REF_M_S) ** (2 * p["n"])
    y = np.empty_like(q)
    y[0] = bg
    a = 1.0 - np.exp(-np.diff(t) / MIC_TAU_S)
    for i in range(1, len(q)):
        y[i] = y[i - 1] + a[i - 1] * (q[i] - y[i - 1])
    return 10.0 * np.log10(y)


def run_motor(kind: str, mp, p: dict, k: int, L: float, V0: float = 324.0, x_m: float = 0.0,
              f_Hz: float = 48500.0, T_degC: float = 25.0):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``L`` and ``V0`` the run's load and amplitude,
    ``x_m`` the slider's travel since the session's start at the run's mid-travel, ``f_Hz`` and ``T_degC`` the
    operator's frequency and temperature of the supply table) and its load law (None: the run's load)."""
    if kind == "paschen_glow_clamp":
        Vc = float(glow_V0(V0, p["p_hPa"][k], p["d_m"], p["beta"]))
        return mp.replace(driver__R_m_ohm=tank_R_for_V0(mp.driver, V0, Vc, f_Hz, T_degC)), None
    if kind == "guide_film_wearthrough":
        g = float(guide_factor(x_m, p["f"], p["x_w_m"], p["k"]))
        return mp.replace(slider__mu_sd=mp.slider.mu_sd * g, slider__mu_ss=mp.slider.mu_ss * g), None
    if STREAM.get(kind, kind) == "bellows_intake_drag":
        c_q = bellows_coefficient(p["d_v_m"])
        return be.load_in_slider_motor(mp, L, kind), lambda t, s, v: L - bellows_force_N(v, c_q) / G_M_S2
    return mp, None


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    stroke = nominal.slider.s_max_m - nominal.slider.s_min_m
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds_run):
        x_mid = (k + 0.5) * stroke
        mp, load_law = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, L, V, x_mid, plan.f_drive_Hz,
                                 plan.ambient_degC)
        r = b5.traverse(mp, nominal, plan, V, L, d, load_law=load_law, record=b5.POSITION_AND_SPEED)[0]
        idx = np.arange(0, len(r["time"]), every)
        t, s, v = r["time"][idx], r["Slider.s"][idx], r["Slider.v"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 252, k]).standard_normal(len(t))
        if kind == "paschen_glow_clamp":
            extra["chamber_pressure_hPa"] = np.round(p["p_hPa"][k] * (1.0 + 0.002 * noise), 2)
        elif kind == "mic_level_decoy":
            extra["mic_dBA"] = np.round(mic_level_dBA(t, v, V, p) + 0.5 * noise, 1)
        elif kind == "bellows_intake_logged":
            dp = bellows_dp_Pa(v, bellows_coefficient(p["d_v_m"]))
            extra["bellows_dp_Pa"] = np.round(dp + 0.3 * noise, 1)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        drag = None
        if load_law is not None:  # the largest bellows force met, from the recorded steps
            c_q = bellows_coefficient(p["d_v_m"])
            drag = max(bellows_force_N(float(u), c_q) for u in r["Slider.v"])
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p, "R_m_ohm": mp.driver.R_m_ohm,
                        "V0_V": float(glow_V0(V, p["p_hPa"][k], p["d_m"], p["beta"])) if "p_hPa" in p else V,
                        "mu_sd": mp.slider.mu_sd, "mu_ss": mp.slider.mu_ss, "mass_kg": mp.slider.mass_kg,
                        "travel_mid_m": x_mid, "bellows_max_N": drag, "t_start_s": t_next,
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
