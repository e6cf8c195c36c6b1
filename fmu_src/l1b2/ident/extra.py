"""Extra exogenous forces with their own parameters phi, identified jointly with theta.

:class:`ExtraForces` describes candidate physical effects the paper's Eq. 29
model lacks ("closing the loop"): in drive coordinates (positive = in the
drive direction) the model's drive force becomes

    X_total = X + features(df) @ phi        [N]

for every sample. ``features`` maps a data-format DataFrame to an
``(n_samples, n_extra)`` array of forces [N] per unit of each parameter, so
each entry of phi carries the unit given in :attr:`ExtraForces.units`
(``"N"`` for a force amplitude, ``"N s/m"`` for a speed coefficient, ...).
Features are computed once per data frame and never depend on theta; nothing
else of the model changes (Fr, D, the sign, rest and reversal rules, the
mass). The identification itself treats phi like theta (see
:mod:`l1b2.ident.problem`, :mod:`l1b2.ident.uncertainty`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import IdentificationError

__all__ = ["ExtraForces"]


def _opt_tuple(x, n, name, default):
    """``x`` as a tuple of ``n`` floats (``default`` everywhere when ``x`` is None)."""
    if x is None:
        return tuple(float(default) for _ in range(n))
    arr = np.atleast_1d(np.asarray(x, dtype=float)).ravel()
    if arr.size != n:
        raise IdentificationError(f"ExtraForces.{name} has {arr.size} entries, expected {n} (one per name)")
    return tuple(float(a) for a in arr)


@dataclass(frozen=True)
class ExtraForces:
    """Extra exogenous forces with their own parameters (identified jointly with theta).

    The model's drive force becomes ``X_total = X + features(df) @ phi`` in
    drive coordinates (positive = in the drive direction): ``features`` maps a
    data-format DataFrame to an ``(n_samples, n_extra)`` array of forces [N]
    per unit of each parameter (a 1-D array is accepted for one parameter).
    Features may use any column of the data frame but never theta. Nothing
    else of the model changes (Fr, D, the sign, rest and reversal rules,
    the mass).

    ``names`` / ``units``: one per parameter (names must differ from the Eq. 35
    names). ``start``: start values of phi for a warm start (``init``) when
    ``init_extra`` is not given (default zeros); the data-driven start takes
    phi from the joint linear equation-error fit. ``lower`` / ``upper``:
    bounds (default -inf / +inf). ``features`` cannot be serialised:
    :meth:`l1b2.ident.estimator.PredictorIdentifier.from_dict` takes it again (``extra=``).
    """

    names: tuple
    units: tuple
    features: Callable
    start: tuple | None = None
    lower: tuple | None = None
    upper: tuple | None = None
    description: str = ""

    def __post_init__(self):
        names = (self.names,) if isinstance(self.names, str) else tuple(self.names)
        names = tuple(str(n) for n in names)
        if not names:
            raise IdentificationError("ExtraForces.names is empty")
        if len(set(names)) != len(names):
            raise IdentificationError(f"ExtraForces.names are not unique: {names}")
        units = (self.units,) if isinstance(self.units, str) else tuple(self.units)
        units = tuple(str(u) for u in units)
        if len(units) != len(names):
            raise IdentificationError(f"ExtraForces: {len(units)} units for {len(names)} names")
        if not callable(self.features):
            raise IdentificationError("ExtraForces.features must be callable: df -> (n_samples, n_extra) array")
        n = len(names)
        lower = _opt_tuple(self.lower, n, "lower", -np.inf)
        upper = _opt_tuple(self.upper, n, "upper", np.inf)
        if any(not (lo < hi) for lo, hi in zip(lower, upper)) or any(math.isnan(x) for x in lower + upper):
            raise IdentificationError(f"ExtraForces: need lower < upper, got {lower} / {upper}")
        start = None if self.start is None else _opt_tuple(self.start, n, "start", 0.0)
        if start is not None and not all(math.isfinite(x) for x in start):
            raise IdentificationError(f"ExtraForces.start must be finite, got {start}")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "units", units)
        object.__setattr__(self, "lower", None if self.lower is None else lower)
        object.__setattr__(self, "upper", None if self.upper is None else upper)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "description", str(self.description or ""))

    @property
    def n(self) -> int:
        """Number of extra parameters."""
        return len(self.names)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        lo = np.full(n, -np.inf) if self.lower is None else np.asarray(self.lower, float)
        hi = np.full(n, np.inf) if self.upper is None else np.asarray(self.upper, float)
        return lo, hi

    def start_vector(self) -> np.ndarray:
        return np.zeros(self.n) if self.start is None else np.asarray(self.start, float)

    def evaluate(self, df) -> np.ndarray:
        """``features(df)`` validated: float array of shape (len(df), n), all finite."""
        n_rows = len(df)
        try:
            E = np.asarray(self.features(df), dtype=float)
        except IdentificationError:
            raise
        except Exception as exc:  # the user's callable: report what failed
            raise IdentificationError(f"extra forces {list(self.names)}: features(df) failed: {exc}") from exc
        if E.ndim == 1 and self.n == 1:
            E = E[:, None]
        if E.ndim == 0 and self.n == 1:
            E = np.full((n_rows, 1), float(E))
        if E.shape != (n_rows, self.n):
            raise IdentificationError(
                f"extra forces: features(df) returned shape {E.shape}, expected ({n_rows}, {self.n}) "
                f"(one column per parameter {list(self.names)})"
            )
        bad = ~np.isfinite(E)
        if bad.any():
            i, j = (int(a[0]) for a in np.nonzero(bad))
            raise IdentificationError(
                f"extra forces: feature of '{self.names[j]}' is not finite (first at row {i + 1})"
            )
        return np.ascontiguousarray(E)
