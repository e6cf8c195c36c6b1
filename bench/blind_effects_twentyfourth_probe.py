#!/usr/bin/env python
"""Probes of the twenty-fourth blind audit's misses (``bench/blind_effects_twentyfourth.py``): the audit's own command
on its cached case, with one rule of the close loop replaced for the run:

* ``blocks`` -- the session's blocks are searched in every run-level analysis
  (:func:`l1b2.closeloop.runlevel.searches_blocks` always true), not only when no signal has Wald evidence: a
  segmentation of the session's clock is then tested beside the significant signals, at its own level, and offered
  and preferred by the loop's unchanged rules.
* ``notravel`` -- the run's travel is never derived (:func:`l1b2.closeloop.derived.with_run_travel` returns the
  frames as they are, with an empty record): the loop as it was before the travel was a channel.

Usage: python bench/blind_effects_twentyfourth_probe.py MODE KIND SEED [--cache DIR] [--report FILE] (the audit's
arguments after MODE). Other audits' kinds run through ``--audit MODULE`` before MODE (a ``bench`` module with a
``main(argv)``, such as ``blind_effects`` for the clean case).
"""
import importlib
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects_twentyfourth  # noqa: E402  (adds fmu_src to the path)

from l1b2.closeloop import derived, runlevel  # noqa: E402

MODES = ("blocks", "notravel")


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
