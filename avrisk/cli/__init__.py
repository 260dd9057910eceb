"""The ``avrisk`` command line (Typer). Each sub-command lives in its own module.

A command's module is loaded only when it runs or shows its own help
(:class:`avrisk.cli.app.LazyGroup`): loading takes seconds (torch), and a
Ctrl-C meanwhile ends the command as one later would, with exit status 130
and one line, not a traceback (:func:`loading`). The Typer application is
:data:`avrisk.cli.app.app`.
"""

import sys
from collections.abc import Iterator
from contextlib import contextmanager

#: Exit status of a command stopped by Ctrl-C (128 + SIGINT, as shells give it).
INTERRUPTED = 130

__all__ = ["INTERRUPTED", "loading", "main"]


@contextmanager
def loading() -> Iterator[None]:
    """Imports of a command's code: a Ctrl-C meanwhile is one line and status 130."""
    try:
        yield
    except KeyboardInterrupt:
        sys.stderr.write("interrupted while loading: nothing was run\n")
        raise SystemExit(INTERRUPTED) from None


def main() -> None:
    """Entry point of the ``avrisk`` console script."""
    with loading():
        from avrisk.cli.app import app
    app()
