"""Measured data of an L1B2 test rig: the public API of the data layer.

Implements the contract of the rig data format (docs/reference/data-format.md): one CSV file with one
row per sample (SI units, unit in the column name), optionally accompanied by
a sidecar ``NAME.json`` beside ``NAME.csv`` holding rig settings.

This module holds the :class:`Measurements` container (validated samples,
settings, evaluation mask), :func:`evaluation_mask`, the train/test
:func:`split_by_load`, and the entry points :func:`load_measurements` and
:func:`write_measurements`. It re-exports the contract's names, so callers
need only this module: the vocabulary (column names, specs, defaults,
thresholds) from :mod:`~l1b2.data.columns`, :func:`validate_frame` and
:func:`run_slices` from :mod:`~l1b2.data.validate`; the files themselves are
read and written by :mod:`~l1b2.data.io`.

Reading and writing apply the same validation. Input that breaks the
contract is refused with one :class:`~l1b2.errors.DataFormatError` naming
the file, the column with its unit and the first offending row (1-based data
row and file line), e.g.::

    data.csv: column 'time_s' [s], row 17 (line 18): time not increasing (0.016 after 0.017)

Settings precedence: explicit keyword argument (the command line) > sidecar
> defaults (:data:`DEFAULT_DRIVE_FREQUENCY_HZ`,
:data:`DEFAULT_ENCODER_RESOLUTION_M`; the slider mass has no default and is
``None`` = unknown unless given).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import DataFormatError, IdentificationError
from .columns import (
    DEFAULT_DRIVE_FREQUENCY_HZ,
    DEFAULT_ENCODER_RESOLUTION_M,
    DIRECTION,
    FREQUENCY,
    KNOWN_COLUMNS,
    LOAD,
    MAX_ABS_LOAD_KG,
    MAX_ABS_POSITION_M,
    MAX_ABS_SPEED_M_S,
    MAX_FREQUENCY_HZ,
    MAX_TEMPERATURE_C,
    MAX_VOLTAGE_V,
    MIN_FREQUENCY_HZ,
    MIN_TEMPERATURE_C,
    MIN_VOLTAGE_V,
    NUMERIC_COLUMNS,
    POSITION,
    REQUIRED_COLUMNS,
    RUN,
    SIDECAR_FIELDS,
    SPEED,
    TEMPERATURE,
    TIME,
    VOLTAGE,
    ColumnSpec,
    sidecar_path,
    unit_of,
)
from .io import read_table_and_sidecar, write_table_and_sidecar
from .onset import from_onset, subset_record
from .validate import format_value, run_slices, validate_frame, validate_frame_filled

__all__ = [
    "TIME", "RUN", "POSITION", "VOLTAGE", "DIRECTION", "LOAD", "SPEED",
    "FREQUENCY", "TEMPERATURE",
    "ColumnSpec", "KNOWN_COLUMNS", "REQUIRED_COLUMNS", "NUMERIC_COLUMNS",
    "SIDECAR_FIELDS",
    "DEFAULT_DRIVE_FREQUENCY_HZ", "DEFAULT_ENCODER_RESOLUTION_M",
    "MAX_ABS_POSITION_M", "MAX_ABS_SPEED_M_S", "MIN_VOLTAGE_V", "MAX_VOLTAGE_V",
    "MAX_ABS_LOAD_KG", "MIN_FREQUENCY_HZ", "MAX_FREQUENCY_HZ",
    "MIN_TEMPERATURE_C", "MAX_TEMPERATURE_C",
    "Measurements", "load_measurements", "write_measurements",
    "validate_frame", "validate_frame_filled", "split_by_load", "run_slices", "sidecar_path", "unit_of",
]


# --------------------------------------------------------------------------
# Evaluation mask (data-format.md, "Error metrics")
# --------------------------------------------------------------------------

#: Samples with |measured speed| below this are not evaluated [m/s] (5 mm/s).
MIN_EVAL_SPEED_M_S: float = 5e-3
#: Travel excluded at the start and at the end of each run [m] (2 mm).
END_EXCLUSION_M: float = 2e-3


def as_1d(name: str, values: Any) -> np.ndarray:
    """``values`` (Series or array_like) as a 1-D float array; ``ValueError`` naming ``name`` otherwise."""
    arr = values.to_numpy(dtype=float) if isinstance(values, pd.Series) \
        else np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    return arr


def evaluation_mask(data: pd.DataFrame | Measurements | Any, position_m: Any = None,
                    run: Any = None, *, min_speed_m_s: float = MIN_EVAL_SPEED_M_S,
                    end_exclusion_m: float = END_EXCLUSION_M) -> np.ndarray:
    """Boolean mask of the samples on which errors are evaluated.

    Parameters
    ----------
    data : pandas.DataFrame, Measurements or array_like
        Either a table with columns ``speed_m_s`` [m/s] (measured speed),
        ``position_m`` [m] and ``run`` (then ``position_m`` and ``run`` must
        not be given), or the measured speed [m/s] per sample.
    position_m : array_like, optional
        Slider position per sample [m]; required when ``data`` is an array.
    run : array_like, optional
        Run id per sample (rows of one run contiguous); ``None`` = one run.
    min_speed_m_s : float
        Smallest evaluated |measured speed| [m/s]; default 5 mm/s.
    end_exclusion_m : float
        Travel excluded at each end of each run [m]; default 2 mm.

    Returns
    -------
    numpy.ndarray of bool
        True where |v_meas| >= ``min_speed_m_s`` and the distance travelled
        from the run's first sample and the distance remaining to the run's
        last sample are both >= ``end_exclusion_m``.

    Notes
    -----
    Travel is measured along the run's own path: the cumulative sum of
    |position(k) - position(k-1)| within the run (never across runs). For a
    monotonic traverse this equals |position - first position| and
    |last position - position|; if the slider reverses (e.g. bounces at an
    end stop) the back-and-forth motion counts as travel. Samples with
    non-finite speed or position are not evaluated.
    """
    if isinstance(data, Measurements):
        data = data.df
    if isinstance(data, pd.DataFrame):
        if position_m is not None or run is not None:
            raise TypeError("give either a DataFrame or arrays, not both")
        missing = [c for c in (SPEED, POSITION, RUN) if c not in data.columns]
        if missing:
            raise ValueError(f"evaluation_mask: DataFrame lacks column(s) {missing}")
        speed = as_1d(SPEED, data[SPEED])
        pos = as_1d(POSITION, data[POSITION])
        run = data[RUN]
    else:
        if position_m is None:
            raise TypeError("evaluation_mask: position_m is required with array input")
        speed = as_1d("speed", data)
        pos = as_1d("position_m", position_m)
    if pos.shape != speed.shape:
        raise ValueError(f"speed and position_m differ in length ({speed.size} vs {pos.size})")
    if run is None:
        blocks = [(None, slice(0, speed.size))] if speed.size else []
    else:
        run_values = run.to_numpy() if isinstance(run, pd.Series) else np.asarray(run)
        if run_values.shape != speed.shape:
            raise ValueError(f"run and speed differ in length ({run_values.size} vs {speed.size})")
        blocks = run_slices(run_values)

    with np.errstate(invalid="ignore"):
        mask = np.abs(speed) >= min_speed_m_s
    for _, sl in blocks:
        x = pos[sl]
        travelled = np.concatenate(([0.0], np.cumsum(np.abs(np.diff(x)))))
        remaining = travelled[-1] - travelled
        with np.errstate(invalid="ignore"):
            mask[sl] &= (travelled >= end_exclusion_m) & (remaining >= end_exclusion_m)
    return mask


# --------------------------------------------------------------------------
# Container
# --------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Measurements:
    """Validated measured data of one file.

    Attributes
    ----------
    df : pandas.DataFrame
        One row per sample, every column of the file in file order
        (including unknown extra columns, passed through). Known numeric
        columns are ``float64`` (``direction`` is ``int64``); ``run`` is
        ``int64`` when every id is a canonical integer, else strings exactly
        as given. When ``speed_m_s`` was absent it is appended, derived from
        position (``meta['speed_derived']``); when ``frequency_Hz`` was absent
        it is appended, filled with ``meta['drive_frequency_Hz']``
        (``meta['frequency_filled']``).
    meta : dict
        ``slider_mass_kg`` [kg] or ``None`` (unknown), ``encoder_resolution_m``
        [m], ``drive_frequency_Hz`` [Hz], ``description`` (str), ``source``
        (path of the CSV), ``sidecar`` (path of the sidecar read, or
        ``None``), ``speed_derived`` and ``frequency_filled`` (bool),
        ``gaps_filled`` (per optional input column whose gaps were bridged:
        ``cells``, ``runs``, ``first_row``, ``first_line``; empty when none),
        ``rest_before_onset`` (the runs at rest before their onset, cut on
        reading: :func:`l1b2.data.onset.from_onset`), plus any extra sidecar
        fields.
    path : pathlib.Path
        The CSV file the data came from.

    Notes
    -----
    ``eq=False``: comparing two instances with ``==`` compares identity
    (element-wise DataFrame comparison has no single truth value).
    """

    df: pd.DataFrame
    meta: dict
    path: Path

    @property
    def slider_mass_kg(self) -> float:
        """Slider mass [kg] from the sidecar or the caller; a :class:`DataFormatError` naming the file if unknown."""
        m_s = self.meta.get("slider_mass_kg")
        if m_s is None:
            raise DataFormatError(sidecar_path(self.path), "slider_mass_kg", None,
                                  f"slider mass unknown for {self.path}: give it on the command line "
                                  f"(--slider-mass) or in this sidecar")
        return float(m_s)

    @functools.cached_property
    def mask(self) -> np.ndarray:
        """The data format's evaluation mask (:func:`evaluation_mask`) of these samples, computed once."""
        out = evaluation_mask(self.df)
        out.setflags(write=False)
        return out

    @property
    def runs(self) -> list:
        """Run ids in file order (each once)."""
        return [rid for rid, _ in run_slices(self.df[RUN])]

    @property
    def n_samples(self) -> int:
        """Number of samples (rows)."""
        return int(len(self.df))

    def iter_runs(self) -> Iterator[tuple[Any, pd.DataFrame]]:
        """Iterate over the runs in file order.

        Yields
        ------
        run_id : int or str
            The run identifier.
        run_df : pandas.DataFrame
            The rows of that run (a slice of :attr:`df`, original index kept).
        """
        for rid, sl in run_slices(self.df[RUN]):
            yield rid, self.df.iloc[sl]


# --------------------------------------------------------------------------
# Reading and writing (the work is done in l1b2.data.io)
# --------------------------------------------------------------------------

def load_measurements(path: str | os.PathLike, *, slider_mass_kg: float | None = None,
                      encoder_resolution_m: float | None = None,
                      drive_frequency_Hz: float | None = None,
                      allow_unusual_units: bool = False, cut_rest_before_onset: bool = True) -> Measurements:
    """Read and validate a measured-data CSV (and its sidecar).

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file. Its sidecar is ``NAME.json`` beside it (optional).
    slider_mass_kg : float, optional
        Slider mass [kg]; overrides the sidecar. Unknown (``None``) unless
        given here or in the sidecar.
    encoder_resolution_m : float, optional
        Encoder resolution [m]; overrides the sidecar; default
        :data:`DEFAULT_ENCODER_RESOLUTION_M`.
    drive_frequency_Hz : float, optional
        Drive frequency [Hz]; overrides the sidecar; default
        :data:`DEFAULT_DRIVE_FREQUENCY_HZ`. Used to fill ``frequency_Hz``
        only when that column is absent (a measured column always wins).
    allow_unusual_units : bool
        Accept values a linear USM rig does not produce in SI units (loads
        above 2 kg, V0 below 5 V, a speed column that disagrees with the
        position's derivative, ...; :func:`l1b2.data.validate.unusual_values`)
        instead of refusing them as a likely unit mistake. The findings are
        kept in ``meta['unusual_units']`` either way.
    cut_rest_before_onset : bool
        Drop each run's samples at rest before its motion's onset when the
        drive inputs of its motion are logged during the rest
        (:func:`l1b2.data.onset.from_onset`: the recording began before the
        drive); counted in ``meta['rest_before_onset']`` either way.

    Returns
    -------
    Measurements
        Validated data; see the class for columns and ``meta``.

    Raises
    ------
    DataFormatError
        The CSV or the sidecar breaks the contract (message names file,
        column or field with unit, and first offending row / line).
        Likely unit mistakes (see ``allow_unusual_units``) too.
    ParameterError
        A keyword argument is not a plausible positive number (or, unless
        ``allow_unusual_units``, outside the range of a linear USM rig).

    Notes
    -----
    * When ``speed_m_s`` is absent it is derived per run from position and
      time (see ``l1b2.data.io``) and ``meta['speed_derived']`` is True.
    * When ``frequency_Hz`` is absent it is filled with the constant
      ``meta['drive_frequency_Hz']`` (keyword > sidecar > 48 500 Hz) and
      ``meta['frequency_filled']`` is True: it was not measured.
    * A gap (empty cell, NaN token, infinity) in ``frequency_Hz`` or
      ``temperature_C`` is filled within its run, linearly in time between
      the run's readings (the nearest reading at the run's ends), and
      counted in ``meta['gaps_filled']``; a run without any reading there
      is refused. A gap in any other known column is refused.
    * Whitespace around header names and values is ignored; blank lines at
      the end of the file are ignored, blank lines inside are refused.
    * The checks above read every sample; the rest before each run's onset
      is cut after them, the kept rows keep their index (file row = index
      + 1).
    """
    df, meta = read_table_and_sidecar(path, slider_mass_kg=slider_mass_kg,
                                      encoder_resolution_m=encoder_resolution_m,
                                      drive_frequency_Hz=drive_frequency_Hz,
                                      allow_unusual_units=allow_unusual_units)
    df, meta["rest_before_onset"] = from_onset(df, meta["encoder_resolution_m"], cut=cut_rest_before_onset)
    return Measurements(df=df, meta=meta, path=Path(path))


def write_measurements(df: pd.DataFrame | Measurements, path: str | os.PathLike,
                       meta: Mapping | None = None) -> Path:
    """Validate and write measured data as CSV plus sidecar JSON.

    Parameters
    ----------
    df : pandas.DataFrame or Measurements
        The samples (for a :class:`Measurements`, its ``meta`` is used when
        ``meta`` is not given).
    path : str or os.PathLike
        Target CSV file; the sidecar is written to ``NAME.json`` beside it.
    meta : mapping, optional
        Settings for the sidecar (``slider_mass_kg``, ``encoder_resolution_m``,
        ``drive_frequency_Hz``, ``description`` and any extra JSON fields);
        defaults when absent. Load-time keys (``source``, ``sidecar``,
        ``speed_derived``, ``frequency_filled``) are not written.

    Returns
    -------
    pathlib.Path
        The CSV path written.

    Raises
    ------
    DataFormatError
        The data or the settings break the contract; nothing is written.

    Notes
    -----
    * Columns marked in ``meta`` as not measured (``speed_derived`` ->
      ``speed_m_s``, ``frequency_filled`` -> ``frequency_Hz``) are not
      written, so the file does not claim they were measured; reading the
      file back derives / fills them again identically.
    * Floats are written with Python's shortest round-trip ``repr`` (the
      pandas default), so reading back gives bit-identical ``float64``.
    * Both files are written to temporary files in the target directory and
      then moved into place with ``os.replace``; a refused input writes
      nothing. The sidecar is always written (so a stale one cannot
      contradict the new CSV).
    """
    if isinstance(df, Measurements):
        meta = df.meta if meta is None else meta
        df = df.df
    return write_table_and_sidecar(df, path, meta)


# --------------------------------------------------------------------------
# Train / test split
# --------------------------------------------------------------------------

def split_by_load(meas: Measurements, test_abs_loads: Sequence[float] = (0.05,),
                  atol: float = 1e-9) -> tuple[Measurements, Measurements]:
    """Split into training and test runs by load, as in the paper.

    Parameters
    ----------
    meas : Measurements
        Validated data.
    test_abs_loads : sequence of float
        |load_kg| values [kg] whose runs form the test set.
    atol : float
        Absolute tolerance [kg] when comparing |load_kg| with those values.

    Returns
    -------
    train, test : Measurements
        Disjoint subsets of whole runs, rows in file order, original index
        kept (file row = index + 1); ``meta`` copied with ``subset`` set to
        ``"train"`` / ``"test"`` and ``test_abs_loads`` recorded.

    Raises
    ------
    IdentificationError
        Either part would be empty, or a run mixes test and training loads.
    """
    loads = [float(v) for v in test_abs_loads]
    abs_load = np.abs(meas.df[LOAD].to_numpy(dtype=float))
    is_test = np.zeros(len(abs_load), dtype=bool)
    for value in loads:
        is_test |= np.isclose(abs_load, abs(value), rtol=0.0, atol=atol)
    for rid, sl in run_slices(meas.df[RUN]):
        part = is_test[sl]
        if part.any() and not part.all():
            raise IdentificationError(
                f"{meas.path}: run {format_value(rid)} mixes loads selected for test "
                f"(|load_kg| in {loads} kg) with other loads; cannot split by run")
    for name, mask in (("test", is_test), ("training", ~is_test)):
        if not mask.any():
            present = sorted({float(v) for v in np.round(abs_load, 12)})
            raise IdentificationError(
                f"{meas.path}: split by load leaves the {name} set empty "
                f"(test |load_kg| = {loads} kg, atol {atol} kg; "
                f"|load_kg| present: {present} kg)")

    def subset(mask: np.ndarray, label: str) -> Measurements:
        meta = dict(meas.meta)
        meta["subset"] = label
        meta["test_abs_loads"] = loads
        part = meas.df.loc[mask]
        if "rest_before_onset" in meta:
            meta["rest_before_onset"] = subset_record(meta["rest_before_onset"], pd.unique(part[RUN]))
        return Measurements(df=part, meta=meta, path=meas.path)

    return subset(~is_test, "train"), subset(is_test, "test")
