"""A table of diagnostics an estimator contributes to reports (engine-neutral)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["DiagnosticTable"]


@dataclass(frozen=True)
class DiagnosticTable:
    """Diagnostics an estimator contributes to reports (engine-neutral).

    A report draws ``lines`` against the first column (a top panel, with the
    threshold ``gamma`` marked) and ``bars`` below it; a table with neither
    (a summary rather than steps) it shows as a table.

    Attributes
    ----------
    title : str
    columns : tuple of str
        Column names, the step index (or what else a row stands for) first;
        units in brackets.
    rows : list of tuple
        One row per step (numbers, ``(low, high)`` intervals, or None).
    lines : tuple of str
        Columns drawn as lines on the top panel (in the unit of ``f``).
    bars : str or None
        A column drawn as bars on the bottom panel (counts).
    note : str
        What it shows, in plain words, for a reader who does not know the
        method (a report prints it under the table or plot).
    """

    title: str
    columns: tuple[str, ...]
    rows: list[tuple[Any, ...]]
    lines: tuple[str, ...] = ()
    bars: str | None = None
    note: str = ""

    @property
    def drawn(self) -> bool:
        """Whether a report draws it (it has ``lines`` or ``bars``)."""
        return bool(self.lines or self.bars)

    def column(self, name: str) -> list[Any]:
        """The values of one column, in step order."""
        j = self.columns.index(name)
        return [row[j] for row in self.rows]

    def to_dict(self) -> dict[str, Any]:
        """``title``, ``columns``, ``rows`` (lists) and ``note``: for JSON."""
        return {
            "title": self.title,
            "columns": list(self.columns),
            "rows": [list(row) for row in self.rows],
            "note": self.note,
        }
