"""The one JSON writer of every report the package writes (strict JSON, one rule for non-finite numbers).

Rule (``docs/decisions/0001-one-json-rule-for-non-finite-numbers.md``):

* ``NaN`` is written as ``null`` (a value that does not exist: a pinned
  parameter's standard error, a metric without data);
* ``+inf`` / ``-inf`` are written as the strings ``"inf"`` / ``"-inf"`` (a
  value that exists and is unbounded: the standard error of a parameter the
  data cannot determine, a diverged fold's error);
* numpy scalars and arrays become Python numbers and lists, tuples become
  lists, keys become strings, any other object its ``str``;
* the text is written with ``allow_nan=False``, so a value that escaped the
  rule fails loudly instead of writing ``NaN``/``Infinity``, which strict
  JSON parsers refuse.

:func:`from_json_float` is the inverse for one number (``null`` -> NaN,
``"inf"`` -> inf). :func:`sig` formats a number for the human-readable
reports with a fixed number of significant digits.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

__all__ = ["strict_json", "json_float", "from_json_float", "dumps", "sig"]


def json_float(x, digits: int | None = None) -> float | str | None:
    """One float under the rule: finite as is (or to ``digits`` significant digits), NaN -> None, +-inf -> ``"inf"``/``"-inf"``."""
    v = float(x)
    if math.isnan(v):
        return None
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return v if digits is None else float(f"{v:.{digits}g}")


def from_json_float(x) -> float:
    """The inverse of :func:`json_float`: None -> NaN, ``"inf"``/``"-inf"`` -> +-inf, a number -> float."""
    if x is None:
        return float("nan")
    return float(x)


def strict_json(x: Any, digits: int | None = None) -> Any:
    """``x`` with every float finite or replaced by the rule, numpy -> Python, tuples -> lists.

    ``digits``: finite floats rounded to that many significant digits
    (as :func:`l1b2.units.tidy_float`), for reports people read; ``None`` keeps
    them exact (results that are read back, e.g. ``report.json``).
    """
    if isinstance(x, dict):
        return {str(k): strict_json(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [strict_json(v, digits) for v in x]
    if isinstance(x, np.ndarray):
        return [strict_json(v, digits) for v in x.tolist()]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return json_float(x, digits)
    if x is None or isinstance(x, str):
        return x
    return str(x)


def dumps(x: Any, indent: int | None = 1, digits: int | None = None) -> str:
    """Strict JSON text of ``x`` (:func:`strict_json` with ``digits``, then ``json.dumps(..., allow_nan=False)``)."""
    return json.dumps(strict_json(x, digits), indent=indent, allow_nan=False)


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
