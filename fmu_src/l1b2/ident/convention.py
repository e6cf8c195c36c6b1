"""The estimator convention of the package (scikit-learn's ``get_params``/``set_params`` contract).

:class:`EstimatorSettings` is what :class:`l1b2.ident.estimator.PredictorIdentifier`
and :class:`l1b2.closeloop.loop.CloseLoop` share: ``__init__`` stores each
keyword argument under its own name and does nothing else; the settings are
the constructor's arguments, read by :meth:`~EstimatorSettings.get_params`
(from the signature, in its order) and changed by
:meth:`~EstimatorSettings.set_params`; ``repr`` shows the settings that differ
from the defaults. Fitted attributes end in ``_``.
"""

from __future__ import annotations

import inspect
from typing import Any


class EstimatorSettings:
    """Mixin: settings are the constructor's arguments (scikit-learn's ``get_params``/``set_params``)."""

    #: the exception :meth:`set_params` raises for an unknown setting
    settings_error: type = ValueError

    @classmethod
    def _param_names(cls) -> list[str]:
        """The constructor's arguments, in signature order."""
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values()
                if p.name != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]

    def get_params(self, deep: bool = False) -> dict[str, Any]:
        """The settings, name -> value, as given to the constructor (``deep`` is accepted and ignored)."""
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self, **params):
        """Change settings (names of the constructor's arguments); returns self."""
        known = self._param_names()
        for name, value in params.items():
            if name not in known:
                raise self.settings_error(f"set_params: unknown setting {name!r}; known: {known}")
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        defaults = {p.name: p.default for p in inspect.signature(type(self).__init__).parameters.values()}
        changed = []
        for k, v in self.get_params().items():
            d = defaults.get(k)
            if not (v is d or (type(v) is type(d) and isinstance(v, (int, float, str)) and v == d)):
                changed.append(f"{k}={v!r}")
        return f"{type(self).__name__}({', '.join(changed)})"
