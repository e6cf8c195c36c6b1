#!/usr/bin/env python
"""Probes of the twenty-third blind audit's Paschen glow (``bench/blind_effects_twentythird.py``): the audit's own
command on its cached case, with one rule of the close loop replaced for the run:

* ``grid1`` -- every candidate's search count is 1 (:func:`l1b2.closeloop.selection.search_count`): a channel's peak
  form keeps its screen p-value without the grid's Bonferroni factor.
* ``vx`` -- every logged channel's ``d*<column>`` run-level signal is replaced by ``(c - c0) w`` with ``w = (V -
  mean V) / mean V`` over the runs (``c`` the run's mean of the channel, ``c0`` its mean over the runs): the channel
  times the drive level.
* ``q`` -- the same place holds ``z^2 - mean(z^2)``, ``z = (c - c0) / sd(c)``: a minimum or a maximum of the
  channel's effect inside its range.
* ``qv`` -- ``(z^2 - mean(z^2)) w``: that shape times the drive level.

The signals keep the name ``d*<column>`` and its transform; only their run values change, so a probe's p-values and
held-out gains of those signals (``diagnosis.channels_considered[...].run_level``) are the replaced ones'. A signal
that the loop then offers is realised as ``d*<column>``, so the rows after such an offer are not the probe's
reading; the evidence is. Usage: python bench/blind_effects_twentythird_probe.py MODE KIND SEED [--cache DIR]
[--report FILE] (the audit's arguments after MODE).
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects_twentythird as audit  # noqa: E402  (adds fmu_src to the path)

from l1b2.closeloop import runlevel, selection  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402

MODES = ("grid1", "vx", "q", "qv")


def drive_weight(voltage_v: np.ndarray) -> np.ndarray:
    """``(V - mean V) / mean V`` of the runs' amplitudes [V] (one value per run)."""
    v = np.asarray(voltage_v, float)
    return (v - v.mean()) / v.mean()


def replaced_values(mode: str, values: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The run values a probe puts in a ``d*<column>`` signal's place (module docstring): ``values`` the channel's
    run means, ``weight`` :func:`drive_weight` of the same runs."""
    c = np.asarray(values, float)
    if mode == "vx":
        return (c - c.mean()) * weight
    sd = np.std(c)
    z = (c - c.mean()) / (sd if sd > 0 else 1.0)
    shape = z * z - np.mean(z * z)
    if mode == "q":
        return shape
    if mode == "qv":
        return shape * weight
    raise ValueError(f"mode {mode!r}: not one of vx, q, qv")


def patch(mode: str) -> None:
    """Replace the loop's rule for ``mode`` in this process (module docstring)."""
    if mode == "grid1":
        selection.search_count = lambda candidate: 1
        return
    signals, state = runlevel.run_signals, {}

    def run_signals(df, channels):
        state["w"] = drive_weight(df.groupby(dataio.RUN, sort=False)[dataio.VOLTAGE].mean().to_numpy(float))
        return signals(df, channels)

    def times_direction(sg, d):
        return {**sg, "transform": "drive", "centre": float(np.mean(sg["values"])),
                "values": replaced_values(mode, sg["values"], state["w"])}

    runlevel.run_signals = run_signals
    runlevel._times_direction = times_direction


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] not in MODES:
        sys.exit(f"usage: blind_effects_twentythird_probe.py MODE KIND SEED [...] (MODE: one of {', '.join(MODES)})")
    patch(argv[0])
    audit.main(argv[1:])


if __name__ == "__main__":
    main()
