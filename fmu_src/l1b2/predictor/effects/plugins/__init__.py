"""Effect families shipped with an exported model rather than with the package.

``Predictor.fmu`` bundles the package; a model that uses a family defined
outside it (a user's own, registered at run time) gets that family's module
copied here by the export (:func:`l1b2.predictor.effects.plugin_sources`).
When :mod:`l1b2.predictor.effects` is imported, every module of this folder
is imported and every :class:`~l1b2.predictor.effects.base.Effect` subclass
it defines is registered. The package itself ships none.
"""

from __future__ import annotations

import importlib
import pkgutil


def load_all() -> list[str]:
    """Import every module of this folder and register the families it defines; the modules' names."""
    from ..base import Effect, register
    names = [m.name for m in pkgutil.iter_modules(__path__)]
    for name in names:
        mod = importlib.import_module(f"{__name__}.{name}")
        for obj in vars(mod).values():
            if isinstance(obj, type) and issubclass(obj, Effect) and obj.kind and obj.__module__ == mod.__name__:
                register(obj)
    return names
