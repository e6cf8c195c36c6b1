"""Report values that strict readers accept: JSON without NaN/Infinity, numbers with sensible digits.

Every JSON report of the package goes through :func:`dumps`: non-finite
floats become ``None`` (NaN) or the strings ``"inf"`` / ``"-inf"``, numpy
scalars and arrays become Python numbers and lists, and the text is written
with ``allow_nan=False`` so a forgotten case fails loudly instead of writing
``Infinity``, which strict JSON parsers refuse. :func:`sig` formats a number
for human-readable reports with a fixed number of significant digits.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from ..units import tidy_float

__all__ = ["strict_json", "dumps", "sig"]


def strict_json(x: Any) -> Any:
    """``x`` with every float finite or replaced (NaN -> None, +-inf -> "inf"/"-inf"), numpy -> Python.

    Finite floats are written with 12 significant digits (:func:`l1b2.units.tidy_float`).
    """
    if isinstance(x, dict):
        return {str(k): strict_json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [strict_json(v) for v in x]
    if isinstance(x, np.ndarray):
        return [strict_json(v) for v in x.tolist()]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        v = float(x)
        if math.isnan(v):
            return None
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return tidy_float(v)
    if x is None or isinstance(x, str):
        return x
    return str(x)


def dumps(x: Any, indent: int | None = 1) -> str:
    """Strict JSON text of ``x`` (:func:`strict_json`, then ``json.dumps(..., allow_nan=False)``)."""
    return json.dumps(strict_json(x), indent=indent, allow_nan=False)


def sig(x: Any, digits: int = 4) -> str:
    """``x`` with ``digits`` significant digits (``"-"`` for None/NaN, ``"inf"`` for infinity)."""
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    v = float(x)
    if math.isnan(v):
        return "-"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{digits}g}"
