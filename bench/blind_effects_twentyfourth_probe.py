#!/usr/bin/env python
"""Probes of the twenty-fourth and twenty-fifth blind audits' misses (``bench/blind_effects_twentyfourth.py``,
``bench/blind_effects_twentyfifth.py``): an audit's own command on its cached case, with one rule of the close loop
replaced for the run:

* ``blocks`` -- the session's blocks are searched in every run-level analysis
  (:func:`l1b2.closeloop.runlevel.searches_blocks` always true), not only when no signal has Wald evidence: a
  segmentation of the session's clock is then tested beside the significant signals, at its own level, and offered
  and preferred by the loop's unchanged rules.
* ``notravel`` -- the run's travel is never derived (:func:`l1b2.closeloop.derived.with_run_travel` returns the
  frames as they are, with an empty record): the loop as it was before the travel was a channel.
* ``square`` -- every logged channel's ``d*<column>`` run-level signal is replaced by ``(c - c0)^2`` (``c`` the
  run's mean of the channel, ``c0`` its mean over the runs): an extremum of the channel's effect inside its range.
  Unlike the twenty-third audit's ``q`` probe, the run-level form the loop then offers is realised with the same
  values (:func:`l1b2.predictor.effects.channels.run_signal` of a logged channel's ``drive`` transform squared), so
  the rows are the probe's; a calibrated model's native kernels are not patched.

Usage: python bench/blind_effects_twentyfourth_probe.py MODE KIND SEED [--cache DIR] [--report FILE] (the audit's
arguments after MODE). Other audits' kinds run through ``--audit MODULE`` before MODE (a ``bench`` module with a
``main(argv)``, such as ``blind_effects`` for the clean case).
"""
import importlib
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects_twentyfourth  # noqa: E402  (adds fmu_src to the path)

import numpy as np  # noqa: E402
from l1b2.closeloop import derived, runlevel  # noqa: E402
from l1b2.predictor.effects import channels  # noqa: E402

MODES = ("blocks", "notravel", "square")


def no_travel(train, test):
    """:func:`l1b2.closeloop.derived.with_run_travel`'s place in the ``notravel`` probe: the frames unchanged, and a
    record that nothing was derived."""
    return train, test, {"column": None, "derived": False}


def patch(mode: str) -> None:
    """Replace the loop's rule for ``mode`` in this process (module docstring)."""
    if mode == "blocks":
        runlevel.searches_blocks = lambda evidence, level: True
    elif mode == "notravel":
        derived.with_run_travel = no_travel
    elif mode == "square":
        inputs, realised = {col for col, _ in channels.INPUT_SIGNALS}, channels.run_signal

        def squared(sg, d):
            c0 = float(np.mean(sg["values"]))
            return {**sg, "transform": "drive", "centre": c0, "values": (sg["values"] - c0) ** 2}

        def run_signal(x, column, transform, centre=0.0, slope=0.0):
            if transform == "drive" and column not in inputs:
                return (channels.signal(x, channels.signal_key(column, "run")) - centre) ** 2
            return realised(x, column, transform, centre, slope)
        runlevel._times_direction, channels.run_signal = squared, run_signal
    else:
        raise ValueError(f"mode {mode!r}: not one of {', '.join(MODES)}")


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else list(argv)
    audit = blind_effects_twentyfourth.__name__
    if argv[:1] == ["--audit"] and len(argv) > 1:
        audit, argv = argv[1], argv[2:]
    if not argv or argv[0] not in MODES:
        sys.exit(f"usage: blind_effects_twentyfourth_probe.py [--audit MODULE] MODE KIND SEED [...] "
                 f"(MODE: one of {', '.join(MODES)})")
    patch(argv[0])
    importlib.import_module(audit).main(argv[1:])


if __name__ == "__main__":
    main()
