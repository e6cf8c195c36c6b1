#!/usr/bin/env python
"""The time stamps' twin of the seventh audit's ``usb_timestamps`` (decision 0109): uneven stamps that are true.

Same world and machinery as ``bench/blind_effects.py`` (imported) and the same draws as
``bench/blind_effects_seventh.py usb_timestamps SEED`` (its packets of N samples and each packet's latency uniform in
0-L_max), with one difference: here the latencies are in the sampling itself, not in the stamps. The DAQ takes the
p-th packet's samples ``L_p`` late (a trigger that waits for the bus), so sample ``k`` is taken at ``k dt + L_p`` and
stamped at that true time; the position is the slider's at that time (the co-simulation's 1 ms course through a
monotone cubic, PCHIP, with no overshoot at the end stops, held within the stroke, then the encoder's resolution),
and the speed is derived over those true stamps. The logged ``time_s`` has exactly the steps of ``usb_timestamps``
at the same seed, but the speed column is right. Nothing is injected: the loop must run as on ``clean`` and must not
keep a form of the speed over the stamps.

Kinds: ``true_uneven_stamps``. Usage: python bench/blind_effects_stamps.py KIND SEED [--cache DIR] [--report
FILE]. Prints the row of ``bench/blind_effects.py`` plus ``traced_all`` and the stamps' stage record
(``time_stamps``: considered, screened, kept, gamma).
"""
import sys
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)
import blind_effects_seventh as seventh  # noqa: E402

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("true_uneven_stamps",)


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The seventh audit's ``usb_timestamps`` draws at ``seed`` (its own random stream)."""
    return seventh.draw("usb_timestamps", seed, n_runs)


def experiment(kind: str, seed: int):
    """The 72-run experiment with the packets' latencies in the sampling instants, and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next, u_at = [], [], 0.0, 0
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t = r["time"][idx]
        n_packets = -(-len(t) // p["N"])
        lat = p["u"][u_at:u_at + n_packets] * p["L_max_s"]
        u_at += n_packets
        t_true = seventh.packet_stamps(t, p["N"], lat)      # the instants the samples are taken (and stamped)
        s_true = np.clip(PchipInterpolator(r["time"], r["Slider.s"])(t_true), mp.slider.s_min_m, mp.slider.s_max_m)
        frames.append(be.daq_frame(plan, t_next, k, t_true, s_true, V, L, d))
        per_run.append({"run": k + 1})
        t_next = float(frames[-1][dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, {k: v for k, v in p.items() if k != "u"}, nominal, plan)


def row_extra(kind: str) -> dict:
    return {"traced_all": lambda names, diag: list(diag["traced_to"]),
            "time_stamps": lambda names, diag: {k: v for k, v in (diag["measurement_chain"].get("time_stamps")
                                                                  or {}).items() if k != "description"}}


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, row_extra)

if __name__ == "__main__":
    main()
