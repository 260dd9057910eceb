"""What every command shares: user-facing errors and warnings."""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import typer
from rich.console import Console
from rich.markup import escape

#: Diagnostics and progress go to stderr; results to stdout. Both are at least
#: 120 columns wide so that tables and progress lines do not wrap or get cut
#: when piped to a file (Rich assumes 80 columns there).
_WIDTH = max(Console().width, 120)
err_console = Console(stderr=True, width=_WIDTH)
out_console = Console(width=_WIDTH)


class CliError(Exception):
    """A problem to report to the user in one sentence, without a traceback."""


def _show_warning(message: Any, category: type[Warning], *args: Any, **kw: Any) -> None:
    err_console.print(
        f"[yellow]warning:[/] {escape(str(message))}", highlight=False, soft_wrap=True
    )


@contextmanager
def user_errors(*expected: type[Exception]) -> Iterator[None]:
    """Turn expected failures into a red one-line message and exit code 2.

    Warnings raised meanwhile (an estimate with zero or few effective hits) are
    printed as one yellow line each instead of Python's source-line format.
    """
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            yield
    except (CliError, *expected) as exc:
        err_console.print(
            f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True
        )
        raise typer.Exit(code=2) from None
