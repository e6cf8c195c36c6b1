#!/usr/bin/env python
"""A third blind audit of the close loop: three more kinds that no injection of the rig, no candidate form of the loop
and no kind of ``bench/blind_effects.py`` or ``bench/blind_effects_more.py`` names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, traverse, cache and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). A kind sets FMU parameters per run; the speed is always the DAQ's
derivative of the recorded position. Each kind draws from one random stream of its seed. The kinds:

* ``fixture_station`` -- logged per-run column ``fixture_id`` (1-4): a numeric column that is really a category.
  The rig has four clamping fixtures and the plan assigns each run to one at random; each fixture has its own
  preload, ``P0 (1 + e_j)`` with ``e_j`` drawn for each fixture independently in -10..+10 %. The effect of the
  column is not monotone in its value (fixture 3 is not "more" than fixture 2).
* ``eddy_brake`` -- logged ``coil_current_A`` per sample (one value per run plus 0.01 A of sensor noise): a
  neighbouring axis's electromagnet holds its own schedule of currents (uniform 0-2 A per run) and its field
  reaches the slider's aluminium carriage. Eddy currents give a viscous force ``-c_e I^2 v`` (the induced current
  grows with B v, the force with B times it, B with I), c_e drawn in 0.6-1.0 N s/(m A^2): the channel scales the
  slider's viscous damping (``c_r + c_e I^2``), a channel x speed interaction, quadratic in the channel.
* ``heater_lag`` -- logged per-run column ``heater_W``: the design randomises a clamp heater's power per run (0, 2,
  4, 6 or 8 W, held until the next run starts). The clamp's temperature follows the power through its thermal mass,
  first order on the session clock, ``dT/dt = (R_th P - T) / tau`` (R_th 3-4 K/W, tau 3-6 s, the pauses included:
  the heater stays on between runs), and its expansion unloads the preload, ``P0 (1 + k T)`` with k drawn in
  -1.5..-1.0 %/K, T taken at the run's start (a run, 0.2-0.4 s, is short against tau). The logged channel is the
  cause; the effect is its low-pass, delayed by a few runs.

Usage: python bench/blind_effects_third.py KIND SEED [--cache DIR]     (KIND: one of the above or clean)
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

KINDS = ("fixture_station", "eddy_brake", "heater_lag")
#: the logged channel each kind acts through
CHANNEL = {"fixture_station": "fixture_id", "eddy_brake": "coil_current_A", "heater_lag": "heater_W"}


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 81, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "fixture_station":
        return {"e": rng.uniform(-0.10, 0.10, 4), "fixture": rng.integers(1, 5, n_runs)}
    if kind == "eddy_brake":
        return {"c_e": float(rng.uniform(0.6, 1.0)), "I": rng.uniform(0.0, 2.0, n_runs)}
    if kind == "heater_lag":
        return {"R_th": float(rng.uniform(3, 4)), "tau_s": float(rng.uniform(3, 6)),
                "k_per_K": float(rng.uniform(-0.015, -0.010)),
                "P": rng.choice([0.0, 2.0, 4.0, 6.0, 8.0], size=n_runs)}
    return {}


def heated(T: float, P: float, dt: float, R_th: float, tau: float) -> float:
    """The clamp's temperature rise after ``dt`` at power ``P`` from ``T`` (the first-order law solved exactly)."""
    return R_th * P + (T - R_th * P) * math.exp(-dt / tau)


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next, T_clamp, t_prev = [], [], 0.0, 0.0, 0.0
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        if kind == "fixture_station":
            mp = mp.replace(stator__P0_N=mp.stator.P0_N * (1 + p["e"][p["fixture"][k] - 1]))
        elif kind == "eddy_brake":
            mp = mp.replace(slider__c_r_N_s_per_m=mp.slider.c_r_N_s_per_m + p["c_e"] * p["I"][k] ** 2)
        elif kind == "heater_lag":
            if k > 0:   # the previous run's power from its start to this run's start
                T_clamp = heated(T_clamp, p["P"][k - 1], t_next - t_prev, p["R_th"], p["tau_s"])
            mp = mp.replace(stator__P0_N=mp.stator.P0_N * (1 + p["k_per_K"] * T_clamp))
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t = r["time"][idx]
        noise = np.random.default_rng([seed, 82, k]).standard_normal(len(t))
        extra = {}
        if kind == "fixture_station":
            extra["fixture_id"] = np.full(len(t), int(p["fixture"][k]))
        elif kind == "eddy_brake":
            extra["coil_current_A"] = np.round(p["I"][k] + 0.01 * noise, 3)
        elif kind == "heater_lag":
            extra["heater_W"] = np.full(len(t), p["P"][k])
        out = be.daq_frame(plan, t_next, k, t, r["Slider.s"][idx], V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "c_r": mp.slider.c_r_N_s_per_m,
                        "mu_p": mp.interface.mu_p, "T_clamp_K": T_clamp})
        t_prev = t_next
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.channel_field(CHANNEL))

if __name__ == "__main__":
    main()
