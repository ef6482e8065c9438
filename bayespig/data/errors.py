"""The one error type of measurement files and sets, and atomic text output.

Every problem a user can cause in a measurement file is a :class:`Problem` that
names the file, the row (the 1-based line number in the file, comment lines
included, so an editor's "go to line" finds it) and the field (a column name,
a header keyword or a sample attribute). Readers collect every problem they can
find and raise one :class:`MeasurementError` listing them all.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .._atomic import write_text_atomically as atomic_write_text

__all__ = ["MeasurementError", "Problem", "atomic_write_text"]


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a measurement file or set.

    Attributes
    ----------
    message : str
        What is wrong and what to do about it.
    file : str or None
        The file it was found in.
    row : int or None
        1-based line number in the file.
    field : str or None
        Column, header keyword or sample attribute at fault.
    sample : str or None
        Name of the sample concerned (used to find the row when a problem is
        found after the rows were read).
    measurement : int or None
        Index of the measurement within its sample, for the same purpose.
    """

    message: str
    file: str | None = None
    row: int | None = None
    field: str | None = None
    sample: str | None = None
    measurement: int | None = None

    def located(self, file=None, row=None):
        """A copy with the file and row filled in (existing values are kept)."""
        return dataclasses.replace(self, file=self.file or file, row=self.row or row)

    def __str__(self):
        where = []
        if self.file:
            where.append(str(self.file))
        if self.row:
            where.append(f"row {self.row}")
        if self.sample and not self.row:
            where.append(f"sample {self.sample!r}")
        if self.field:
            where.append(f"field {self.field!r}")
        return f"{', '.join(where)}: {self.message}" if where else self.message


class MeasurementError(ValueError):
    """A measurement file or set is invalid; the message lists every problem found.

    Attributes
    ----------
    problems : tuple of Problem
    """

    def __init__(self, problems):
        if isinstance(problems, (str, Problem)):
            problems = [problems]
        self.problems = tuple(p if isinstance(p, Problem) else Problem(str(p)) for p in problems)
        if not self.problems:
            raise ValueError("MeasurementError needs at least one problem")
        if len(self.problems) == 1:
            text = str(self.problems[0])
        else:
            text = f"{len(self.problems)} problems:\n" + "\n".join(f"  {p}" for p in self.problems)
        super().__init__(text)

    def located(self, file=None, row=None):
        """The same error with the file (and a default row) filled in where missing."""
        return MeasurementError([p.located(file, row) for p in self.problems])


