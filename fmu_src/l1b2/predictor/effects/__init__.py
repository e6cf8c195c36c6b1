"""The extended predictor's effect families, in one registry, and the calibrated model that carries them.

One family is one :class:`Effect` subclass in one module (its regressors,
parameters with units, shape grid, features, JSON spec and, where it has one,
its physical home with the calibration that maps it there); :func:`register`
adds it. The close-the-loop candidate library is the registry
(:mod:`l1b2.closeloop.candidates`), :func:`effect_features` evaluates a spec
by lookup, the rig's injections name the family they inject
(:mod:`l1b2.rig.experiment`) and :func:`map_effects` asks each family to carry
an identified effect into the subsystem FMUs.

Families (registration order = the library's candidate order):
:mod:`~.thermal` (``thermal_drift``, ``thermal_drift_T``),
:mod:`~.direction` (``direction_asymmetry``), :mod:`~.bar` (``bar_waviness``,
``local_defect``), :mod:`~.load_path` (``load_path_friction``),
:mod:`~.drive` (``drive_saturation``), :mod:`~.motion`
(``speed_dependent_friction``, ``inertia_mismatch``), :mod:`~.interactions`
(``load_slope_voltage``, ``damping_voltage``, ``position_load``) and
:mod:`~.generic` (``smooth``, ``smooth_pair``) and :mod:`~.channels` (``channel``: every
logged channel and the protocol's clock in generic forms; ``run_level``: a run-level signal explaining the runs'
own deviations, offered by the close loop's run-level analysis, not by a library) and :mod:`~.category`
(``run_level_category``: a logged run setting's values, each its own run-level effect, offered the same way) and
:mod:`~.blocks` (``session_blocks``: contiguous blocks of the session's runs, each its own run-level effect, offered
the same way) and :mod:`~.cycle` (``session_cycle``: a cycle of the session's clock, offered the same way).
"""

from __future__ import annotations

import importlib
import inspect
import sys

from .base import (ALWAYS_SIGNALS, SIGNALS, SPEED_REF, V_REF, Effect, EffectSpecError, Hypothesis,  # noqa: F401
                   TrainingSummary, bspline_basis, derivative_step, effect_features, families, family, kinds, needs,
                   num, register, scaled, signal, time_derivative, unregister)
from .model import (FILTER_RAILS, ExtendedPredictor, IdentifiedEffect, apply_output_filter,  # noqa: F401
                    filter_dict, filter_start_gain, filter_step)
from .sensor import STROKE_GAIN_ORDER, SpeedSensorGain, stroke_basis  # noqa: F401
from .plugins import load_all as _load_plugins

#: the package's family modules, imported (and so registered) in this order: the candidate library's order
FAMILY_MODULES = ("thermal", "direction", "bar", "load_path", "drive", "motion", "interactions", "generic", "channels",
                  "category", "blocks", "cycle")
for _m in FAMILY_MODULES:
    importlib.import_module(f"{__name__}.{_m}")
_load_plugins()


def __getattr__(name):
    if name == "KINDS":   # every registered kind, at the time of asking
        return kinds()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def plugin_sources(model: ExtendedPredictor) -> dict:
    """``{module_name: source}`` of the families ``model`` uses that live outside this package.

    What an export copies into :mod:`l1b2.predictor.effects.plugins` of the
    FMU's bundle, so the FMU knows those families too.
    """
    pkg = __name__.rsplit(".", 2)[0]   # the package's own name (l1b2, or an FMU's bundle name)
    out = {}
    for e in model.effects:
        cls = type(family(e.spec.get("kind")))
        mod = cls.__module__
        if mod == pkg or mod.startswith(pkg + "."):
            continue
        out[mod.rsplit(".", 1)[-1]] = inspect.getsource(sys.modules[mod])
    return out
