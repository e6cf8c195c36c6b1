#!/usr/bin/env python
"""A probe of the break clock: a session with two long breaks and a warm-up that starts again after each.

The realistic world's 72-run experiment (``bench/blind_effects.py``'s plan and motor) with two breaks of
:data:`BREAK_S` seconds, after runs 24 and 48 (an operator's meal, a re-mount). Kinds:

* ``break_warmup`` -- the stator warms while the drive is on (its dielectric and mechanical losses) and cools always
  (first order, time constant ``tau_s`` drawn in 20-40 s, a 30 x 7.5 x 3 mm plate in its holder):
  ``theta' = (Theta (V0 / 324 V)^2 on - theta) / tau``, ``Theta`` (the rise under continuous drive at 324 V) drawn
  in 50-70 K. The runs last a fraction of a second and pause 1 s, so a segment's stator ends some 5 K above the
  ambient. The friction lining's slip friction falls as it warms (a polymer lining near its softening range):
  ``mu_p (1 - c theta)``, ``c`` drawn in 0.015-0.025 per K, at each run's start. A break cools the stator back,
  so the warm-up starts again: the friction follows the time since the latest break, a sawtooth in session time.
  No column carries it (no temperature is logged).
* ``breaks_only`` -- the same session with its breaks and no effect: a control (nothing should be traced that the
  clean case does not trace).

The pass rule is the audits' (0053/0089/0101), with ``since_break`` as the effect's regressor. This is a probe of a
rule the package already has (the break clock), not a blind audit: it was written after the rule.

Usage: python bench/break_warmup.py KIND SEED [--cache DIR] [--report FILE]. Prints one JSON line as
``bench/blind_effects.py`` does.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("break_warmup", "breaks_only")
CHANNEL = {"break_warmup": None, "breaks_only": None}
WANT = {"break_warmup": ("since_break",), "breaks_only": ()}
BREAK_S = 1800.0            # each break's length [s]
BREAK_AFTER = (24, 48)      # the runs after which the session stops
V_REF = 324.0               # the drive amplitude whose square sets the stator's full rise [V]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 137, KINDS.index(kind)])
    return {"tau_s": float(rng.uniform(20.0, 40.0)), "Theta_K": float(rng.uniform(50.0, 70.0)),
            "c_per_K": float(rng.uniform(0.015, 0.025)) if kind == "break_warmup" else 0.0}


def experiment(kind: str, seed: int):
    """The 72-run experiment with its breaks, and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next, theta, t_prev_end = [], [], 0.0, 0.0, 0.0
    for k, (V, L, d) in enumerate(conds):
        theta *= np.exp(-(t_next - t_prev_end) / p["tau_s"])          # cooling over the pause before the run
        mp = scattered_motor(nominal, factors[k])
        mp = mp.replace(interface__mu_p=mp.interface.mu_p * (1.0 - p["c_per_K"] * theta))
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        out = be.daq_frame(plan, t_next, k, r["time"][idx], r["Slider.s"][idx], V, L, d)
        frames.append(out)
        dur = float(r["time"][-1])
        per_run.append({"run": k + 1, "theta_K": theta, "start_s": t_next})
        rise = p["Theta_K"] * (V / V_REF) ** 2                          # heating while the drive is on
        theta = rise + (theta - rise) * np.exp(-dur / p["tau_s"])
        t_prev_end = t_next + dur
        t_next = float(out["time_s"].iloc[-1]) + plan.pause_s + (BREAK_S if k + 1 in BREAK_AFTER else 0.0)
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.want_fields(CHANNEL, WANT))


if __name__ == "__main__":
    main()
