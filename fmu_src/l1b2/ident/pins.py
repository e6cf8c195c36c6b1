"""The pins of an identification: the parameters held at a value instead of estimated (the ``fixed`` setting of
:class:`l1b2.ident.estimator.PredictorIdentifier`), read in one place for the parameter space and the choice of
the search."""

from __future__ import annotations

from collections.abc import Mapping

from ..errors import IdentificationError

__all__ = ["RECOMMENDED_FIXED", "pinned_parameters"]

#: parameters pinned by ``fixed="recommended"``: one per structural null
#: direction (sigma, k0, mu) plus the practically unidentifiable mu_sd
RECOMMENDED_FIXED = ("sigma", "k0", "mu", "mu_sd")


def pinned_parameters(fixed, names=None) -> dict:
    """The pins of an identification's ``fixed`` setting: name -> value (float) or None, in the order given.

    ``fixed``: None (no pin), ``"recommended"`` (:data:`RECOMMENDED_FIXED`), a sequence of names (each pinned at
    its start value, None) or a mapping name -> value (None: at the start value). ``names``: the known parameter
    names, or None to leave the names unchecked. Raises IdentificationError for another string, for a value
    that is neither a sequence nor a mapping, for a value that is not a number, and (with ``names``) for an
    unknown name.
    """
    if fixed is None:
        return {}
    if isinstance(fixed, str):
        if fixed != "recommended":
            raise IdentificationError(f"fixed: unknown preset {fixed!r} (use 'recommended' or a dict)")
        fixed = {k: None for k in RECOMMENDED_FIXED}
    elif not isinstance(fixed, Mapping):
        try:
            fixed = {k: None for k in fixed}
        except TypeError:
            raise IdentificationError(f"fixed: expected None, 'recommended', a sequence of names or a mapping, "
                                      f"got {fixed!r}") from None
    out = {}
    for k, v in fixed.items():
        if names is not None and k not in names:
            raise IdentificationError(f"fixed: unknown parameter {k!r}; known: {list(names)}")
        try:
            out[k] = None if v is None else float(v)
        except (TypeError, ValueError):
            raise IdentificationError(f"fixed: the value of {k!r} is not a number: {v!r}") from None
    return out
