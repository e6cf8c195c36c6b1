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

    The message names the file, the column (with its unit) and the first
    offending row (1-based data row, header excluded).
    """

    def __init__(self, path, column, row, problem):
        self.path = str(path)
        self.column = column
        self.row = row
        self.problem = problem
        where = f"{self.path}"
        if column is not None:
            where += f": column '{column}'"
        if row is not None:
            where += f", row {row}"
        super().__init__(f"{where}: {problem}")


class SimulationError(L1B2Error):
    """A simulation could not be carried out (bad inputs, diverging coupling)."""


class SystemStructureError(L1B2Error):
    """An SSP system structure is inconsistent (missing FMU, unit mismatch)."""


class IdentificationError(L1B2Error):
    """Identification failed or was asked something the data cannot answer."""
