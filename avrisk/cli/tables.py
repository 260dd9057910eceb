"""The tables the commands print: compact, readable at 80 columns.

No vertical rules and one space between columns, so that a table of a
handful of numbers fits an 80-column terminal. Nothing is ever cut (no cell
ends in an ellipsis): on a narrower console a column wraps instead.
"""

from __future__ import annotations

from collections.abc import Sequence

from rich import box
from rich.markup import escape
from rich.table import Table


def compact_table(title: str | None = None, caption: str | None = None) -> Table:
    """A table without vertical rules; title and caption left-aligned, wrapped."""
    return Table(
        title=escape(title) if title else None,
        caption=escape(caption) if caption else None,
        box=box.SIMPLE_HEAD,
        pad_edge=False,
        collapse_padding=True,
        title_justify="left",
        caption_justify="left",
    )


def add_columns(
    table: Table, names: Sequence[str], *, text: Sequence[str] = ()
) -> None:
    """Columns of numbers, right-aligned, and ``text`` columns, left-aligned.

    Where the table is wider than the console, Rich narrows the widest
    columns first (a text column, as a rule), which then wrap at spaces; a
    word longer than its column is folded onto the next line, never cut.
    A header wraps where its name has a newline.
    """
    for name in names:
        table.add_column(
            escape(name),
            justify="left" if name in text else "right",
            overflow="fold",
        )
