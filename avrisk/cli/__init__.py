"""The ``avrisk`` command line (Typer). Each sub-command lives in its own module.

A command's module is loaded only when it runs or shows its own help
(:class:`avrisk.cli.app.LazyGroup`): loading takes seconds (torch), and a
Ctrl-C meanwhile ends the command as one later would, with exit status 130
and one line, not a traceback (:func:`avrisk.cli.interrupt.loading`). The
Typer application is :data:`avrisk.cli.app.app`.
"""

from avrisk.cli.interrupt import INTERRUPTED, loading

__all__ = ["INTERRUPTED", "loading", "main"]


def main() -> None:
    """Entry point of the ``avrisk`` console script."""
    with loading():
        from avrisk.cli.app import app
    app()
