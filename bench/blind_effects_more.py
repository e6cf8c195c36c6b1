#!/usr/bin/env python
"""A second blind audit of the close loop: four more kinds that no injection of the rig, no candidate of the loop and
no kind of ``bench/blind_effects.py`` names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, traverse and cache): the realistic
world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s speed
noise, 2 % run-to-run contact scatter). A kind sets FMU parameters per run, or (the sensor kind only) the recorded
position through the sensor's gain; the speed is always the DAQ's derivative of the recorded position. The kinds:

* ``payload_swap`` -- logged per-run column ``payload_g``. The operator bolts a payload onto the slider between
  blocks of runs (0, 60, 120 or 180 g, a new one every 8-16 runs): the moving mass is ``m_s + payload``. It acts
  only through inertia (the slider's time constant m/c_r is tens of ms, comparable with a run's length).
* ``sensor_gain_thermal`` -- logged ``readhead_temp_C`` per sample. A measurement effect, not a force: the linear
  sensor's gain depends on its read head's temperature, ``1 + g (T - 25 degC)`` (g drawn in -0.5..-0.3 %/K), so the
  recorded position about the bar centre and the speed derived from it are scaled. The read head warms over the
  session (22 -> 28 degC, first order) plus the lab's air-conditioning cycle (+-2 degC, period 150-250 s).
* ``clamp_decoy`` -- two logged per-sample columns, ``clamp_temp_C`` and ``case_temp_C``, correlated (r ~ 0.85 over
  runs). Only the clamp's acts: its thermal expansion unloads the preload spring, ``P0 (1 + k (Tc - 25))`` with k
  drawn in -1.6..-1.0 %/K, Tc per run 25 +- 4 degC; the case's temperature follows it with its own scatter and acts
  on nothing. Does the loop trace the right one?
* ``reclamp_relax`` -- logged per-run column ``clamp_count`` (the logbook's count of re-tightenings). The preload
  relaxes run by run after each re-tightening, ``P0 (1 - R (1 - exp(-n/n0)))``, n the runs since the last one (R
  0.10-0.15, n0 4-8 runs), and the operator re-tightens every 12-24 runs: a sawtooth in session time, a step
  function of the logged count.

Usage: python bench/blind_effects_more.py KIND SEED [--cache DIR]     (KIND: one of the above or clean)
Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run nrmse before and
after, channels considered, CPU of the close loop by ``time.process_time``).
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("payload_swap", "sensor_gain_thermal", "clamp_decoy", "reclamp_relax")
#: the logged channel each kind acts through
CHANNEL = {"payload_swap": "payload_g", "sensor_gain_thermal": "readhead_temp_C", "clamp_decoy": "clamp_temp_C",
           "reclamp_relax": "clamp_count"}
#: a logged channel that acts on nothing (the decoy)
DECOY = {"clamp_decoy": "case_temp_C"}


def blocks(rng, n_runs: int, lo: int, hi: int) -> np.ndarray:
    """A block index per run: blocks of ``lo``..``hi`` runs (uniform integers)."""
    out, k, b = np.zeros(n_runs, int), 0, 0
    while k < n_runs:
        n = int(rng.integers(lo, hi + 1))
        out[k:k + n] = b
        k, b = k + n, b + 1
    return out


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 79, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "payload_swap":
        b = blocks(rng, n_runs, 8, 16)
        per_block = rng.choice([0.0, 60.0, 120.0, 180.0], size=b.max() + 1)
        return {"payload_g": per_block[b]}
    if kind == "sensor_gain_thermal":
        return {"g_per_K": float(rng.uniform(-0.005, -0.003)), "tau_s": float(rng.uniform(150, 300)),
                "period_s": float(rng.uniform(150, 250)), "phase": float(rng.uniform(0, 2 * math.pi))}
    if kind == "clamp_decoy":
        Tc = 25 + 4 * rng.standard_normal(n_runs)
        return {"k_per_K": float(rng.uniform(-0.016, -0.010)), "Tc": Tc,
                "Tcase": 25 + 0.85 * (Tc - 25) + 4 * 0.53 * rng.standard_normal(n_runs)}
    if kind == "reclamp_relax":
        b = blocks(rng, n_runs, 12, 24)
        n = np.array([k - np.flatnonzero(b == b[k])[0] for k in range(n_runs)], float)
        return {"R": float(rng.uniform(0.10, 0.15)), "n0": float(rng.uniform(4, 8)), "count": b, "n": n}
    return {}


def readhead_temperature(p: dict, t: np.ndarray) -> np.ndarray:
    """The read head's temperature on the session clock: self-heating 22 -> 28 degC plus the lab's cycle."""
    return 22 + 6 * (1 - np.exp(-t / p["tau_s"])) + 2 * np.sin(2 * math.pi * t / p["period_s"] + p["phase"])


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        if kind == "payload_swap":
            mp = mp.replace(slider__mass_kg=mp.slider.mass_kg + p["payload_g"][k] / 1000)
        elif kind == "clamp_decoy":
            mp = mp.replace(stator__P0_N=mp.stator.P0_N * (1 + p["k_per_K"] * (p["Tc"][k] - 25)))
        elif kind == "reclamp_relax":
            mp = mp.replace(stator__P0_N=mp.stator.P0_N * (1 - p["R"] * (1 - math.exp(-p["n"][k] / p["n0"]))))
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t = r["time"][idx]
        s = r["Slider.s"][idx]
        noise = np.random.default_rng([seed, 80, k]).standard_normal(len(t))
        extra = {}
        if kind == "sensor_gain_thermal":
            T = readhead_temperature(p, t_next + t)
            s = s * (1 + p["g_per_K"] * (T - 25))
            extra["readhead_temp_C"] = np.round(T + 0.05 * noise, 2)
        elif kind == "payload_swap":
            extra["payload_g"] = np.full(len(t), p["payload_g"][k])
        elif kind == "clamp_decoy":
            extra["clamp_temp_C"] = np.round(p["Tc"][k] + 0.05 * noise, 2)
            extra["case_temp_C"] = np.round(p["Tcase"][k] + 0.05 * noise[::-1], 2)
        elif kind == "reclamp_relax":
            extra["clamp_count"] = np.full(len(t), int(p["count"][k]))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "mass_kg": mp.slider.mass_kg, "P0_N": mp.stator.P0_N,
                        "mu_p": mp.interface.mu_p})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    run_cli_extra = lambda kind: {"channel": lambda names, diag: CHANNEL.get(kind),  # noqa: E731
                                  "decoy": lambda names, diag: DECOY.get(kind),
                                  "event_clocks": lambda names, diag: diag.get("event_clocks")}
    be.run_cli(argv, __doc__, KINDS, experiment, run_cli_extra)

if __name__ == "__main__":
    main()
