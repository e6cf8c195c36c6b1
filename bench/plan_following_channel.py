#!/usr/bin/env python
"""A channel that follows the plan's input, carrying a real effect or none: the two sides of decision 0150's rule.

Decision 0150 prefers the model's own inputs to an auxiliary channel that stands in for them when the channel's
cross-validated gain is within one standard error of the inputs' trial and the inputs explain most of its force.
Its risk is a channel that follows an input *and* carries a real effect beyond it. This script makes both sides in
the audits' world and machinery (``bench/blind_effects.py``: the realistic motor, the rig's 72-run plan at a 1 ms
step, 1 mm/s speed noise, 2 % run-to-run contact scatter; TEST the 16 runs at |load| 0.05 kg). Both kinds draw the
same per-run errors from one random stream of the seed:

* ``supply_monitor_error`` -- the bench supply's output differs from its setting by a relative error ``e_k`` per run
  (``e_k`` normal with a standard deviation ``sigma`` drawn in 1.5-2.5 %: an uncalibrated amplifier's load regulation
  and reference drift between settings). The motor is driven at ``V0 (1 + e_k)``; the DAQ logs the setting as
  ``voltage_V`` and a monitor's reading of the drive amplitude as ``supply_monitor_V`` (``V0 (1 + e_k)`` plus 0.05 V
  of noise, 0.01 V resolution). The monitor follows V0 (r above 0.99) and carries the real error beyond it: it must
  be traced.
* ``supply_monitor_decoy`` -- the same monitor column with the same ``e_k``, but the supply gives its setting
  exactly: the monitor's own per-run calibration error. It acts on nothing and must not be traced.

Pass rule (the audits'): ``supply_monitor_error`` passes when a name holding ``supply_monitor`` is among the first
two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4`` (b, a: TEST's free-run nrmse before and after the loop; b0 the
clean control's before at the same seed, ``bench/blind_effects.py clean SEED``). The decoy passes when
``supply_monitor_V`` is nowhere in ``traced_all`` and ``a <= 1.02 b``.

Usage: python bench/plan_following_channel.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
clean). Prints one JSON line as ``bench/blind_effects.py`` does, plus ``traced_all``, ``want`` and
``accepted_in_first_two``.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("supply_monitor_error", "supply_monitor_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced)
CHANNEL = {"supply_monitor_error": "supply_monitor_V", "supply_monitor_decoy": "supply_monitor_V"}
#: the regressors accepted as the effect's when traced among the first two
WANT = {"supply_monitor_error": ("supply_monitor",), "supply_monitor_decoy": ()}
NOISE_V = 0.05              # the monitor's noise [V]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The supply's (or the monitor's) relative error per run: one stream of the seed for both kinds."""
    rng = np.random.default_rng([seed, 150, 0])
    sigma = float(rng.uniform(0.015, 0.025))
    return {"sigma": sigma, "e": sigma * rng.standard_normal(n_runs)}


def driven_voltage(kind: str, V0: float, e: float) -> float:
    """The drive amplitude the motor gets at the setting ``V0``: ``V0 (1 + e)`` when the supply errs, else ``V0``."""
    return V0 * (1.0 + e) if kind == "supply_monitor_error" else V0


def monitor_reading(V0: float, e: float, noise) -> np.ndarray:
    """The monitor's samples: ``V0 (1 + e)`` plus ``NOISE_V`` times ``noise``, rounded to 0.01 V."""
    return np.round(V0 * (1.0 + e) + NOISE_V * np.asarray(noise, float), 2)


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds):
        e = float(p["e"][k])
        mp = scattered_motor(nominal, factors[k])
        r = be.traverse(mp, nominal, plan, driven_voltage(kind, V, e), L, d)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        noise = np.random.default_rng([seed, 151, k]).standard_normal(len(t))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, supply_monitor_V=monitor_reading(V, e, noise))
        frames.append(out)
        per_run.append({"run": k + 1, "e": e, "V_driven": driven_voltage(kind, V, e), "t_start_s": t_next})
        t_next = float(out["time_s"].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_audit(argv, __doc__, KINDS, experiment, CHANNEL, WANT, {})


if __name__ == "__main__":
    main()
