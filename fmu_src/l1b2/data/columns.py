"""The vocabulary of the measured-data contract (the rig data format (docs/reference/data-format.md)).

Declarations only, no file access: the column names of the CSV and their
specifications (:data:`KNOWN_COLUMNS`), the sidecar fields
(:data:`SIDECAR_FIELDS`) and how a sidecar is named (:func:`sidecar_path`),
the default rig settings and the plausibility thresholds that tell SI values
from millimetres, grams or kHz. The units themselves are defined once in
:mod:`l1b2.units` (:data:`~l1b2.units.COLUMN_UNITS`,
:data:`~l1b2.units.SIDECAR_FIELD_UNITS`), where :class:`~l1b2.errors.DataFormatError`
reads them too.

Used by :mod:`~l1b2.data.validate` (the rules), :mod:`~l1b2.data.io`
(reading and writing) and :mod:`~l1b2.data.measurements` (the public API,
which re-exports these names).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from ..units import COLUMN_UNITS, SIDECAR_FIELD_UNITS, data_unit

__all__ = [
    "TIME", "RUN", "POSITION", "VOLTAGE", "DIRECTION", "LOAD", "SPEED",
    "FREQUENCY", "TEMPERATURE", "run_slices", "file_row",
    "ColumnSpec", "KNOWN_COLUMNS", "COLUMN_SPECS", "REQUIRED_COLUMNS", "NUMERIC_COLUMNS",
    "SIDECAR_FIELDS", "LOAD_TIME_META", "NAN_TOKENS",
    "DEFAULT_DRIVE_FREQUENCY_HZ", "DEFAULT_ENCODER_RESOLUTION_M",
    "MAX_ABS_POSITION_M", "MAX_ABS_SPEED_M_S", "MIN_VOLTAGE_V", "MAX_VOLTAGE_V",
    "MAX_ABS_LOAD_KG", "MIN_FREQUENCY_HZ", "MAX_FREQUENCY_HZ",
    "MIN_TEMPERATURE_C", "MAX_TEMPERATURE_C",
    "PlausibleRange", "PLAUSIBLE", "SPEED_SLOPE_BAND", "MAX_SAMPLE_INTERVAL_S",
    "MIN_PEAK_SPEED_M_S",
    "sidecar_path", "unit_of",
]

# --------------------------------------------------------------------------
# Columns
# --------------------------------------------------------------------------

TIME = "time_s"
RUN = "run"
POSITION = "position_m"
VOLTAGE = "voltage_V"
DIRECTION = "direction"
LOAD = "load_kg"
SPEED = "speed_m_s"
FREQUENCY = "frequency_Hz"
TEMPERATURE = "temperature_C"


class ColumnSpec(NamedTuple):
    """One known column of the measured-data CSV.

    Attributes
    ----------
    name : str
        Column name as written in the CSV header (case-sensitive).
    required : bool
        Whether every file must contain it.
    unit : str
        SI unit (``"-"`` for dimensionless / identifiers), from
        :data:`l1b2.units.COLUMN_UNITS`.
    meaning : str
        Short description, from the rig data format (docs/reference/data-format.md).
    """

    name: str
    required: bool
    unit: str
    meaning: str


#: The known columns, in the order of the contract table.
KNOWN_COLUMNS: tuple[ColumnSpec, ...] = (
    ColumnSpec(TIME, True, COLUMN_UNITS[TIME],
               "experiment clock; strictly increasing over the whole file in "
               "recording order, not reset between runs"),
    ColumnSpec(RUN, True, COLUMN_UNITS[RUN],
               "run identifier (integer or string); rows of one run are contiguous"),
    ColumnSpec(POSITION, True, COLUMN_UNITS[POSITION],
               "slider position from the encoder (0 = centre of the friction bar)"),
    ColumnSpec(VOLTAGE, True, COLUMN_UNITS[VOLTAGE], "drive voltage amplitude V0 at the stator"),
    ColumnSpec(DIRECTION, True, COLUMN_UNITS[DIRECTION],
               "+1 when channel CH1 is excited (drives toward +position), -1 for CH2"),
    ColumnSpec(LOAD, True, COLUMN_UNITS[LOAD],
               "signed load mass on the pulley: positive pulls toward -position, "
               "negative toward +position, 0 = no load"),
    ColumnSpec(SPEED, False, COLUMN_UNITS[SPEED],
               "measured slider speed; derived from position_m when absent"),
    ColumnSpec(FREQUENCY, False, COLUMN_UNITS[FREQUENCY],
               "drive frequency; filled from the sidecar / default when absent"),
    ColumnSpec(TEMPERATURE, False, COLUMN_UNITS[TEMPERATURE], "stator temperature, when measured"),
)

#: The known columns by name.
COLUMN_SPECS: dict[str, ColumnSpec] = {c.name: c for c in KNOWN_COLUMNS}

#: Names of the required columns, in contract order.
REQUIRED_COLUMNS: tuple[str, ...] = tuple(c.name for c in KNOWN_COLUMNS if c.required)

#: Known columns holding real numbers (everything but ``run``).
NUMERIC_COLUMNS: tuple[str, ...] = tuple(c.name for c in KNOWN_COLUMNS if c.name != RUN)

#: Sidecar fields and their units (:data:`l1b2.units.SIDECAR_FIELD_UNITS`).
SIDECAR_FIELDS: dict[str, str] = SIDECAR_FIELD_UNITS

#: ``meta`` keys computed at load time; never written to nor read from a sidecar.
LOAD_TIME_META: tuple[str, ...] = ("source", "sidecar", "speed_derived", "frequency_filled", "unusual_units",
                                    "allow_unusual_units", "gaps_filled", "rest_before_onset")

#: Texts (lower case, stripped) that mean "no value" (NaN) in a CSV cell.
NAN_TOKENS: frozenset[str] = frozenset({
    "nan", "-nan", "+nan", "na", "n/a", "#n/a", "null", "none", "<na>",
    "nat", "#nan", "-1.#ind", "1.#qnan",
})

# --------------------------------------------------------------------------
# Defaults and plausibility thresholds (SI)
# --------------------------------------------------------------------------

#: Drive frequency used when neither column, sidecar nor caller gives one [Hz].
DEFAULT_DRIVE_FREQUENCY_HZ: float = 48_500.0
#: Encoder resolution used when neither sidecar nor caller gives one [m].
DEFAULT_ENCODER_RESOLUTION_M: float = 5e-8

#: |position_m| above this suggests the file is in millimetres [m].
MAX_ABS_POSITION_M: float = 1.0
#: |speed_m_s| above this suggests the file is in mm/s [m/s].
MAX_ABS_SPEED_M_S: float = 10.0
#: Lowest plausible drive voltage amplitude [V] (an amplitude is never negative).
MIN_VOLTAGE_V: float = 0.0
#: Highest plausible drive voltage amplitude [V] (above suggests mV).
MAX_VOLTAGE_V: float = 2000.0
#: |load_kg| above this suggests grams [kg].
MAX_ABS_LOAD_KG: float = 50.0
#: Lowest plausible drive frequency [Hz] (below suggests kHz).
MIN_FREQUENCY_HZ: float = 1e3
#: Highest plausible drive frequency [Hz].
MAX_FREQUENCY_HZ: float = 1e6
#: Lowest plausible stator temperature [degC].
MIN_TEMPERATURE_C: float = -100.0
#: Highest plausible stator temperature [degC] (above suggests kelvin).
MAX_TEMPERATURE_C: float = 300.0



# --------------------------------------------------------------------------
# Physical plausibility for a linear USM rig (overridable: allow_unusual_units)
# --------------------------------------------------------------------------

class PlausibleRange(NamedTuple):
    """The range of values a linear ultrasonic-motor rig produces in SI units.

    Values outside are refused when reading unless the caller allows unusual
    units (``--allow-unusual-units``); unlike the hard limits above they are
    not impossible, only far more likely a unit mistake.

    Attributes
    ----------
    low, high : float
        Plausible magnitudes [unit of the column / field]; ``low`` applies to
        non-zero magnitudes only (0 is always plausible; ``low = 0`` means no
        lower bound). With ``signed`` the values themselves are compared.
    below, above : str
        The likely unit mistake named in the message when a value is below
        ``low`` / above ``high``.
    signed : bool
        Compare signed values instead of magnitudes (temperatures).
    """

    low: float
    high: float
    below: str
    above: str
    signed: bool = False


#: column or sidecar field -> plausible magnitudes and the unit mistakes they hint at.
PLAUSIBLE: dict[str, PlausibleRange] = {
    "slider_mass_kg": PlausibleRange(1e-3, 5.0, "a slider lighter than 1 g?", "grams?"),
    LOAD: PlausibleRange(0.0, 2.0, "", "grams?"),
    VOLTAGE: PlausibleRange(5.0, 1000.0, "kV?", "mV?"),
    FREQUENCY: PlausibleRange(15e3, 1e6, "not ultrasonic: kHz x 10?", "a drive frequency above 1 MHz?"),
    "drive_frequency_Hz": PlausibleRange(15e3, 1e6, "not ultrasonic: kHz x 10?", "a drive frequency above 1 MHz?"),
    SPEED: PlausibleRange(0.0, 1.5, "", "mm/s, or position_m not in metres?"),
    POSITION: PlausibleRange(0.0, 0.5, "", "position_m scaled (cm or mm)?"),
    TEMPERATURE: PlausibleRange(-60.0, 150.0, "a temperature below -60 degC?", "kelvin or degF?", signed=True),
    "encoder_resolution_m": PlausibleRange(1e-10, 1e-4, "a resolution finer than 0.1 nm?", "micrometres or nanometres?"),
}
#: Per run, the regression slope of speed_m_s on d(position_m)/dt must lie in this band
#: (1 = consistent; filtering and a lag of a few samples give 0.9-1.0).
SPEED_SLOPE_BAND: tuple[float, float] = (0.5, 2.0)
#: Median sample interval within runs at or above this is implausible for a rig [s] (time in ms?).
MAX_SAMPLE_INTERVAL_S: float = 1.0
#: A file whose fastest sample is slower than this has no traverse in it [m/s] (time in ms?).
MIN_PEAK_SPEED_M_S: float = 1e-3


#: Unit of a known column or sidecar field (``"-"`` for dimensionless, None when unknown): the data API's name
#: of :func:`l1b2.units.data_unit`.
unit_of = data_unit


def sidecar_path(path: str | os.PathLike) -> Path:
    """Path of the sidecar ``NAME.json`` belonging to ``NAME.csv``.

    Parameters
    ----------
    path : str or os.PathLike
        The measured-data CSV file.

    Returns
    -------
    pathlib.Path
        ``path`` with its suffix replaced by ``.json``.
    """
    return Path(path).with_suffix(".json")


def run_slices(run: pd.Series | Sequence | np.ndarray) -> list[tuple[Any, slice]]:
    """Contiguous blocks of equal run id, in order.

    Parameters
    ----------
    run : array_like
        Run id per sample.

    Returns
    -------
    list of (run_id, slice)
        One entry per block of consecutive equal ids; ``slice`` indexes
        positions (not labels). With contiguous runs (as validated) there is
        exactly one block per run.
    """
    values = run.to_numpy() if isinstance(run, pd.Series) else np.asarray(run)
    n = len(values)
    if n == 0:
        return []
    change = np.ones(n, dtype=bool)
    if n > 1:
        change[1:] = values[1:] != values[:-1]
    starts = np.flatnonzero(change)
    stops = np.append(starts[1:], n)
    return [(values[a].item() if isinstance(values[a], np.generic) else values[a], slice(int(a), int(b)))
            for a, b in zip(starts, stops)]


def file_row(df: pd.DataFrame, position: int) -> int:
    """The file's 1-based data row of the frame's row at ``position`` (0-based): the frame's index there + 1. A
    measured-data frame keeps the file's row numbers as its index, also after rows were cut on reading."""
    return int(df.index[position]) + 1
