#!/usr/bin/env python
"""A fourth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the loop
and no kind of the three earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, traverse, cache and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). A kind sets FMU parameters per run; the speed is always the DAQ's
derivative of the recorded position. Each kind draws from one random stream of its seed. The kinds:

* ``runin_glaze`` -- no channel; non-monotone in the run order. A fresh composite lining first runs in under the
  ceramic tip (its asperities flatten and a transfer film forms, so the real contact area and the slip friction
  grow), then glazes (the film polishes to a resin-rich skin and the friction falls back). With ``S`` the tip's
  sliding distance over the runs before (tip speed ~ 0.2 m/s x V0/324 V times the run's duration), the slip friction
  coefficient is ``mu_p (1 + H x exp(1 - x))``, ``x = S / S1``: a hump of height H (drawn in 0.15-0.22) at the
  sliding distance S1 (drawn in 1.0-1.6 m; the 72-run session slides ~2.9 m), falling back over the rest of the session.
* ``eyelet_capstan`` -- the load's own column, in one direction only (a direction x load interaction). The load's
  cable runs from the slider through a fixed PTFE eyelet before the pulley; in forward runs (``direction`` +1) the
  slider drags the cable over the eyelet's lip (wrap angle theta drawn in 80-110 deg, cable-on-PTFE friction mu_c in
  0.15-0.20), a capstan whose tension ratio adds ``m g (exp(mu_c theta) - 1)`` against the motion; in backward runs
  the cable leaves the lip and runs freely over the pulley. Set through the slider's load-path friction
  ``pulley_mu = exp(mu_c theta) - 1`` in forward runs, 0 in backward runs.
* ``oil_viscosity_proxy`` -- logged ``air_temp_C`` per sample, a noisy proxy of the cause. The friction bar's
  lubricant film and the guide's grease thin with the bar's temperature (an Andrade/Walther viscosity law, near
  room temperature ``exp(-b (T_bar - 25 degC))``, b drawn in 3.5-5 %/K): the interface's viscous slip coefficient
  ``sigma`` and the guide's ``c_r`` both scale by it. The bar's temperature per run is ``25 + 5 z`` degC (z standard
  normal, clipped to 15-35 degC; the bar sits between a lamp and the chamber's vent); the rig logs only the air
  temperature beside it, ``25 + rho (T_bar - 25) + 5 sqrt(1 - rho^2) z'`` (rho drawn in 0.75-0.85, z' standard
  normal per run) plus 0.05 degC of sensor noise per sample: correlated with the cause at about rho, never equal.
  The drive sits in its own rack at 25 degC (its tank does not see the bar's temperature).
* ``oil_viscosity_cause`` -- the proxy's control, not a kind of its own: the same draw and the same motion as
  ``oil_viscosity_proxy`` at the seed, with the bar's own temperature logged (``bar_temp_C``, plus 0.05 degC of sensor
  noise per sample) instead of the air's. What the loop makes of the cause tells the proxy's loss from the loop's.
* ``dewpoint_film`` -- two logged columns whose combination acts, ``humidity_pct`` and ``air_temp_C`` (one value
  per run each, independent: RH ``45 + 12 z`` clipped to 20-75 %, air 20-30 degC uniform, plus 0.5 % and 0.05 degC
  of sensor noise per sample). The friction bar is clamped to a base plate held at 27 degC, so the water film on it
  is set by the water activity at the bar's temperature, ``a = (RH/100) p_sat(T_air) / p_sat(27 degC)`` (the air's
  vapour pressure over the saturation pressure at the bar; Magnus, ``p_sat(T) = 6.112 hPa exp(17.62 T / (243.12 degC
  + T))``): a product of the humidity and a function of the air temperature. The adsorbed film lubricates the tip's
  slip, ``mu_p (1 - A tanh((a - 0.45) / 0.15))``, A drawn in 0.10-0.14.

Usage: python bench/blind_effects_fourth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run nrmse before
and after, channels considered, CPU of the close loop by ``time.process_time``).
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("runin_glaze", "eyelet_capstan", "oil_viscosity_proxy", "dewpoint_film", "oil_viscosity_cause")
#: a kind that draws from another kind's stream (the same draw and motion, another logged column)
STREAM = {"oil_viscosity_cause": "oil_viscosity_proxy"}
#: the channel each kind acts through (a logged column; the session clock for the unlogged run-in)
CHANNEL = {"runin_glaze": "time", "eyelet_capstan": "load_kg x direction", "oil_viscosity_proxy": "air_temp_C",
           "oil_viscosity_cause": "bar_temp_C",
           "dewpoint_film": "humidity_pct x air_temp_C"}
BAR_PLATE_DEGC = 27.0   # the base plate's set point under the friction bar (dewpoint_film)


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    kind = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 83, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "runin_glaze":
        return {"H": float(rng.uniform(0.15, 0.22)), "S1_m": float(rng.uniform(1.0, 1.6))}
    if kind == "eyelet_capstan":
        mu_c, theta = float(rng.uniform(0.15, 0.20)), math.radians(float(rng.uniform(80, 110)))
        return {"mu_c": mu_c, "theta_rad": theta, "pulley_mu_fwd": math.expm1(mu_c * theta)}
    if kind == "oil_viscosity_proxy":
        rho = float(rng.uniform(0.75, 0.85))
        T_bar = np.clip(25 + 5 * rng.standard_normal(n_runs), 15, 35)
        T_air = 25 + rho * (T_bar - 25) + 5 * math.sqrt(1 - rho ** 2) * rng.standard_normal(n_runs)
        return {"b_per_K": float(rng.uniform(0.035, 0.05)), "rho": rho, "T_bar": T_bar, "T_air": T_air}
    if kind == "dewpoint_film":
        return {"A": float(rng.uniform(0.10, 0.14)), "RH": np.clip(45 + 12 * rng.standard_normal(n_runs), 20, 75),
                "T_air": rng.uniform(20, 30, n_runs)}
    return {}


def runin_factor(S_m: float, H: float, S1_m: float) -> float:
    """The run-in and glazing factor of the slip friction after the sliding distance ``S_m`` [m]."""
    x = S_m / S1_m
    return 1 + H * x * math.exp(1 - x)


def p_sat_hPa(T_degC):
    """The saturation vapour pressure of water over a flat surface [hPa] at ``T_degC`` (Magnus formula)."""
    return 6.112 * np.exp(17.62 * np.asarray(T_degC, float) / (243.12 + np.asarray(T_degC, float)))


def water_activity(RH_pct, T_air_degC, T_surface_degC: float = BAR_PLATE_DEGC):
    """The water activity (0-1, may exceed 1: condensation) at a surface held at ``T_surface_degC`` under air of
    relative humidity ``RH_pct`` [%] at ``T_air_degC``."""
    return np.asarray(RH_pct, float) / 100 * p_sat_hPa(T_air_degC) / p_sat_hPa(T_surface_degC)


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next, S = [], [], 0.0, 0.0
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        if kind == "runin_glaze":
            mp = mp.replace(interface__mu_p=mp.interface.mu_p * runin_factor(S, p["H"], p["S1_m"]))
        elif kind == "eyelet_capstan":
            mp = mp.replace(slider__pulley_mu=p["pulley_mu_fwd"] if d > 0 else 0.0)
        elif kind in ("oil_viscosity_proxy", "oil_viscosity_cause"):
            thin = math.exp(-p["b_per_K"] * (p["T_bar"][k] - 25))
            mp = mp.replace(interface__sigma_N_s_per_m=mp.interface.sigma_N_s_per_m * thin,
                            slider__c_r_N_s_per_m=mp.slider.c_r_N_s_per_m * thin)
        elif kind == "dewpoint_film":
            a = float(water_activity(p["RH"][k], p["T_air"][k]))
            mp = mp.replace(interface__mu_p=mp.interface.mu_p * (1 - p["A"] * math.tanh((a - 0.45) / 0.15)))
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t = r["time"][idx]
        noise = np.random.default_rng([seed, 84, k]).standard_normal(len(t))
        extra = {}
        if kind == "oil_viscosity_proxy":
            extra["air_temp_C"] = np.round(p["T_air"][k] + 0.05 * noise, 2)
        elif kind == "oil_viscosity_cause":
            extra["bar_temp_C"] = np.round(p["T_bar"][k] + 0.05 * noise, 2)
        elif kind == "dewpoint_film":
            extra["humidity_pct"] = np.round(p["RH"][k] + 0.5 * noise, 2)
            extra["air_temp_C"] = np.round(p["T_air"][k] + 0.05 * noise[::-1], 2)
        out = be.daq_frame(plan, t_next, k, t, r["Slider.s"][idx], V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "S_m": S, "mu_p": mp.interface.mu_p, "pulley_mu": mp.slider.pulley_mu,
                        "sigma": mp.interface.sigma_N_s_per_m, "c_r": mp.slider.c_r_N_s_per_m})
        S += be.TIP_SPEED_M_S * V / 324.0 * float(t[-1])
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.channel_field(CHANNEL))

if __name__ == "__main__":
    main()
