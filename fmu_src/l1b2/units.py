"""Units: SI unit definitions for the FMUs and SSP files, and the units of the measured data.

* :data:`UNITS`: each unit by its exponents of the SI base units (FMI 2.0 and
  SSP 1.0 both use this ``BaseUnit`` form), plus ``factor`` and ``offset``
  for non-coherent units (degC); used by the FMUs (``UnitDefinitions``) and
  the SSP files (``ssd:Units``).
* :data:`COLUMN_UNITS` and :data:`SIDECAR_FIELD_UNITS`: the unit of every
  column of the measured-data CSV and of every sidecar field
  (the rig data format (docs/reference/data-format.md)), defined here once so that both the data layer
  (:mod:`l1b2.data.columns`) and :class:`l1b2.errors.DataFormatError` (which
  names the unit in its messages) read the same table.

This is the bottom layer: it imports nothing of the package.
"""

from __future__ import annotations

import math
import re

from dataclasses import dataclass

#: gravitational acceleration used throughout, as in the paper (Eq. 22, 29) [m/s^2]
G_M_S2 = 9.81


@dataclass(frozen=True)
class UnitDef:
    kg: int = 0
    m: int = 0
    s: int = 0
    A: int = 0
    K: int = 0
    mol: int = 0
    cd: int = 0
    rad: int = 0
    factor: float = 1.0
    offset: float = 0.0

    def base_unit_attributes(self) -> dict[str, str]:
        """Non-default attributes of the ``BaseUnit`` element."""
        out = {k: str(getattr(self, k)) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad") if getattr(self, k)}
        if self.factor != 1.0:
            out["factor"] = repr(self.factor)
        if self.offset != 0.0:
            out["offset"] = repr(self.offset)
        return out


UNITS: dict[str, UnitDef] = {
    "1": UnitDef(),
    "s": UnitDef(s=1),
    "m": UnitDef(m=1),
    "kg": UnitDef(kg=1),
    "rad": UnitDef(rad=1),
    "V": UnitDef(kg=1, m=2, s=-3, A=-1),
    "Hz": UnitDef(s=-1),
    "rad/s": UnitDef(rad=1, s=-1),
    "degC": UnitDef(K=1, offset=273.15),
    "N": UnitDef(kg=1, m=1, s=-2),
    "m/s": UnitDef(m=1, s=-1),
    "m/s2": UnitDef(m=1, s=-2),
    "H": UnitDef(kg=1, m=2, s=-2, A=-2),
    "F": UnitDef(kg=-1, m=-2, s=4, A=2),
    "Ohm": UnitDef(kg=1, m=2, s=-3, A=-2),
    "1/K": UnitDef(K=-1),
    "1/Hz": UnitDef(s=1),
    "Hz/K": UnitDef(s=-1, K=-1),
    "kg/m3": UnitDef(kg=1, m=-3),
    "K/V2": UnitDef(kg=-2, m=-4, s=6, A=2, K=1),
    "N/V": UnitDef(m=-1, s=1, A=1),
    "N/K": UnitDef(kg=1, m=1, s=-2, K=-1),
    "N/K2": UnitDef(kg=1, m=1, s=-2, K=-2),
    "N/m": UnitDef(kg=1, s=-2),
    "N.s/m": UnitDef(kg=1, s=-1),
    "K": UnitDef(K=1),
    # units a rig's logged auxiliary channel may name in its column's suffix (:func:`column_unit`)
    "A": UnitDef(A=1),
    "W": UnitDef(kg=1, m=2, s=-3),
    "Pa": UnitDef(kg=1, m=-1, s=-2),
    "bar": UnitDef(kg=1, m=-1, s=-2, factor=1e5),
    "g": UnitDef(kg=1, factor=1e-3),
    "Pa.s": UnitDef(kg=1, m=-1, s=-1),
    "mPa.s": UnitDef(kg=1, m=-1, s=-1, factor=1e-3),
}


def unit_def(name: str) -> UnitDef:
    """The definition of unit ``name``; ``KeyError`` names the unknown unit."""
    try:
        return UNITS[name]
    except KeyError:
        raise KeyError(f"unit '{name}' has no definition in l1b2.units.UNITS") from None


def same_dimension(a: str, b: str) -> bool:
    """True if units ``a`` and ``b`` are identical in base units, factor and offset."""
    return unit_def(a) == unit_def(b)


# --------------------------------------------------------------------------
# Units of the measured data (the rig data format (docs/reference/data-format.md))
# --------------------------------------------------------------------------

#: Unit of each known column of the measured-data CSV, in the order of the
#: contract table (``"-"`` = dimensionless or identifier).
COLUMN_UNITS: dict[str, str] = {
    "time_s": "s",
    "run": "-",
    "position_m": "m",
    "voltage_V": "V",
    "direction": "-",
    "load_kg": "kg",
    "speed_m_s": "m/s",
    "frequency_Hz": "Hz",
    "temperature_C": "degC",
}

#: Unit of each known field of a measured-data sidecar ``NAME.json``.
SIDECAR_FIELD_UNITS: dict[str, str] = {
    "slider_mass_kg": "kg",
    "encoder_resolution_m": "m",
    "drive_frequency_Hz": "Hz",
    "description": "-",
}


def data_unit(name: str | None) -> str | None:
    """Unit of a known measured-data column or sidecar field.

    Parameters
    ----------
    name : str or None
        Column or sidecar field name.

    Returns
    -------
    str or None
        The unit (``"-"`` for dimensionless), ``None`` when unknown.
    """
    if name in COLUMN_UNITS:
        return COLUMN_UNITS[name]
    return SIDECAR_FIELD_UNITS.get(name)  # type: ignore[arg-type]


#: a column name's suffix that names a unit other than by its symbol in :data:`UNITS` (the data format's
#: ``temperature_C``)
SUFFIX_UNITS: dict[str, str] = {"C": "degC"}

#: the name of a channel derived as the low-pass of column ``X`` over ``n`` run periods is ``X + lag_suffix(n)``
#: (:func:`lag_suffix`); this pattern matches that suffix for any ``n``
LAG_SUFFIX_RE = re.compile(r"_lag[0-9]+r$")
#: the name of a channel derived as a setting's step from its previous different setting: ``X + STEP_SUFFIX``
STEP_SUFFIX = "_step"
#: the name of a channel derived as the run's setting that column ``X`` carries beside what the motion makes of it
#: (:mod:`l1b2.closeloop.runsetting`): ``X + SETTING_SUFFIX``, in ``X``'s unit
SETTING_SUFFIX = "_setting"
#: the name of a channel that is the natural logarithm of a quantity in a unit: ``LOG_PREFIX + Q`` where ``Q``
#: names the quantity with its unit by the naming rule (``ln_pause_s``: ``ln(pause / 1 s)``)
LOG_PREFIX = "ln_"
#: the unit of a difference of two values of an offset unit (a step of a temperature in degC is in K)
DIFFERENCE_UNITS: dict[str, str] = {"degC": "K"}


def lag_suffix(n) -> str:
    """The suffix of the channel derived as a column's low-pass over ``n`` run periods (``_lag3r``)."""
    return f"_lag{n}r"


def _derived_base(name: str) -> tuple[str, str] | None:
    """``(kind, base)`` of a name built as ``base + suffix`` (kind ``"lag"``, ``"step"`` or ``"setting"``), or
    ``LOG_PREFIX + base`` (kind ``"log"``); None for any other name."""
    m = LAG_SUFFIX_RE.search(name)
    if m and m.start() > 0:
        return "lag", name[:m.start()]
    if name.endswith(STEP_SUFFIX) and len(name) > len(STEP_SUFFIX):
        return "step", name[:-len(STEP_SUFFIX)]
    if name.endswith(SETTING_SUFFIX) and len(name) > len(SETTING_SUFFIX):
        return "setting", name[:-len(SETTING_SUFFIX)]
    if name.startswith(LOG_PREFIX) and len(name) > len(LOG_PREFIX):
        return "log", name[len(LOG_PREFIX):]
    return None


def is_setting_history(name: str) -> bool:
    """Whether a channel's name is that of a setting's history the loop derives: a low-pass of a column over run
    periods (``X_lag<n>r``) or a setting's step from its previous different setting (``X_step``)."""
    return history_source(name) is not None


def history_source(name: str) -> str | None:
    """The column whose setting history a derived channel is (``X`` of ``X_lag<n>r`` or ``X_step``), else None."""
    derived = _derived_base(name)
    return derived[1] if derived is not None and derived[0] in ("lag", "step") else None


def column_unit(name: str) -> str | None:
    """The unit of a measured-data column as a key of :data:`UNITS`, None when neither the data format nor the
    name says it.

    A column of the data format has its unit (:func:`data_unit`, ``"-"`` as ``"1"``). A name built from another by
    the naming rule of derived channels has the unit its construction gives, when the other name has one:

    * ``X_lag<n>r`` (:data:`LAG_SUFFIX_RE`, a low-pass of ``X``): ``X``'s unit;
    * ``X_step`` (:data:`STEP_SUFFIX`, a difference of two values of ``X``): ``X``'s unit, an offset unit's
      coherent one (:data:`DIFFERENCE_UNITS`: degC -> K);
    * ``X_setting`` (:data:`SETTING_SUFFIX`, a run's level of ``X``): ``X``'s unit;
    * ``ln_Q`` (:data:`LOG_PREFIX`, ``ln(Q / 1 unit)`` of a quantity ``Q`` in a unit): ``1`` (:func:`unit_note` says
      of what, in which unit).

    Any other column's name gives it by its suffix, the rig's naming rule (``line_pressure_bar``, ``supply_V``,
    ``belt_speed_m_s``, ``oil_viscosity_mPa_s``, the event clock ``X_since_s``): the last two ``_``-separated parts
    read as a product (``mPa_s`` -> ``mPa.s``), else as a quotient (``m_s`` -> ``m/s``), else the last part, the
    first of these that is a unit of :data:`UNITS` other than ``1`` or of :data:`SUFFIX_UNITS` (``C`` -> ``degC``).
    """
    known = data_unit(name)
    if known is not None:
        return "1" if known == "-" else known
    derived = _derived_base(str(name))
    if derived is not None:
        kind, base = derived
        unit = column_unit(base)
        if unit is not None:
            return "1" if kind == "log" else DIFFERENCE_UNITS.get(unit, unit) if kind == "step" else unit
    parts = str(name).split("_")[1:]
    for suffix in ([".".join(parts[-2:]), "/".join(parts[-2:])] if len(parts) >= 2 else []) + parts[-1:]:
        unit = SUFFIX_UNITS.get(suffix, suffix)
        if unit in UNITS and unit != "1":   # a trailing number is an index, not the unit 1
            return unit
    return None


def unit_note(name: str) -> str:
    """What the unit of column ``name`` (:func:`column_unit`) does not say, for a description: for a logarithm
    ``ln_Q`` whose ``Q`` has a unit ``u``, ``"ln(Q / 1 u): the natural logarithm of Q in u, dimensionless"``, whose
    ``Q``'s name gives no unit, ``"ln(Q): the natural logarithm of Q in its column's own unit"``; for a lag or a step
    of such a logarithm the same; else ``""``."""
    derived = _derived_base(str(name))
    while derived is not None and derived[0] != "log":
        derived = _derived_base(derived[1])
    if derived is None:
        return ""
    q, u = derived[1], column_unit(derived[1])
    if u is None:
        return f"ln({q}): the natural logarithm of {q} in its column's own unit"
    return f"ln({q} / 1 {u}): the natural logarithm of {q} in {u}, dimensionless"


def tidy_float(x: float, digits: int = 12) -> float:
    """``x`` rounded to ``digits`` significant digits, for files people read.

    Values derived by arithmetic carry round-off in their last bits
    (``-0.021`` computed as ``-0.020999999999999998``, ``67.1`` as
    ``67.09999999999999``); written with ``repr`` they show 17 digits that
    mean nothing. Twelve significant digits change a value by less than
    5e-12 relative, far below any measured or identified uncertainty here.
    Non-finite values are returned unchanged.
    """
    v = float(x)
    return float(f"{v:.{digits}g}") if math.isfinite(v) else v
