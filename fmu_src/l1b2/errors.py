"""Exception classes of the project.

Every error a user can cause by bad input is one of these; the CLI prints
``str(exc)`` as one line and exits non-zero.

Layering: only :mod:`l1b2.units` is imported (for the units that
:class:`DataFormatError` names), so every layer may raise these.
"""

from __future__ import annotations

from .units import data_unit


class L1B2Error(Exception):
    """Base class of all errors raised on purpose by this package."""


class ParameterError(L1B2Error):
    """A parameter file or parameter value is invalid (names file, field, unit)."""


class DataFormatError(L1B2Error):
    """A measured-data file breaks the contract of the rig data format (docs/reference/data-format.md).

    The message names the file, the column with its unit, and the first
    offending row both as 1-based data row (header excluded) and as file
    line (header is line 1), e.g.::

        data.csv: column 'time_s' [s], row 17 (line 18): time not increasing (0.016 after 0.017)

    For a sidecar ``.json`` file the ``column`` is the JSON field and the
    message says ``field`` instead of ``column``.

    Parameters
    ----------
    path : str or os.PathLike
        The offending file.
    column : str or None
        Column (or sidecar field) name; ``None`` for file-level problems.
        Its unit is looked up in :data:`l1b2.units.COLUMN_UNITS` /
        :data:`l1b2.units.SIDECAR_FIELD_UNITS`.
    row : int or None
        1-based data row number (header excluded); ``None`` when the problem
        is not tied to one row.  The file line is ``row + 1``.
    problem : str
        What is wrong, in plain words.
    """

    def __init__(self, path, column, row, problem):
        self.path = str(path)
        self.column = column
        self.row = row
        self.problem = problem
        self.unit = data_unit(column)
        self.line = None if row is None else int(row) + 1
        where = self.path
        sep = ": "
        if column is not None:
            kind = "field" if self.path.lower().endswith(".json") else "column"
            where += f"{sep}{kind} '{column}'"
            if self.unit is not None:
                where += f" [{self.unit}]"
            sep = ", "
        if row is not None:
            where += f"{sep}row {row} (line {self.line})"
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):
        # Keep the exception picklable (multiprocessing) despite the
        # four-argument constructor.
        return (type(self), (self.path, self.column, self.row, self.problem))


class SimulationError(L1B2Error):
    """A simulation could not be carried out (bad inputs, diverging coupling)."""


class SystemStructureError(L1B2Error):
    """An SSP system structure is inconsistent (missing FMU, unit mismatch)."""


class ArchiveError(SystemStructureError):
    """An ``.ssp`` or ``.fmu`` archive is unreadable or exceeds the extraction limits (size, members, ratio)."""


class SourceOutsideError(SystemStructureError):
    """An SSD ``source`` names a file outside the ``.ssp`` archive (or the SSD's folder)."""


class IdentificationError(L1B2Error):
    """Identification failed or was asked something the data cannot answer."""


class FitDivergedError(IdentificationError):
    """An identification ended non-finite or diverged, also after its retry from the identifier's multistart.

    Raised instead of drawing any conclusion from the broken fit (the
    close-the-loop baseline or the joint re-identification after a round);
    the message names the fit, what was wrong with it and the retry.
    """


class SpecError(L1B2Error):
    """A study specification (``l1b2 sweep --spec``) is invalid; the message names the key.

    E.g. ``study.toml: parameters.Interface.mu_q: unknown parameter (Interface has k_e_N_per_m, mu_p, ...)``.
    """


class ClusterError(L1B2Error):
    """The parallel engine could not be used (scheduler unreachable, workers lost for good)."""


class OutputError(L1B2Error):
    """An output folder cannot be written: it is a file, holds files not written by l1b2, or another run holds it."""
