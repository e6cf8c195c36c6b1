"""Exception classes of the project.

Every error a user can cause by bad input is one of these; the CLI prints
``str(exc)`` as one line and exits non-zero.
"""

from __future__ import annotations


class L1B2Error(Exception):
    """Base class of all errors raised on purpose by this package."""


class ParameterError(L1B2Error):
    """A parameter file or parameter value is invalid (names file, field, unit)."""


class DataFormatError(L1B2Error):
    """A measured-data file breaks the contract of ``shared/data-format.md``.

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
        Its unit is looked up in :data:`l1b2.data.measurements.KNOWN_COLUMNS` /
        :data:`l1b2.data.measurements.SIDECAR_FIELDS`.
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
        self.unit = self._unit_of(column)
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

    @staticmethod
    def _unit_of(column):
        """Unit of a known data column or sidecar field, else ``None``."""
        if column is None:
            return None
        try:  # lazy: l1b2.data.measurements imports this module
            from .data.measurements import unit_of
        except ImportError:  # pragma: no cover - partial installs only
            return None
        return unit_of(column)


class SimulationError(L1B2Error):
    """A simulation could not be carried out (bad inputs, diverging coupling)."""


class SystemStructureError(L1B2Error):
    """An SSP system structure is inconsistent (missing FMU, unit mismatch)."""


class IdentificationError(L1B2Error):
    """Identification failed or was asked something the data cannot answer."""
