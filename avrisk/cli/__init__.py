"""The ``avrisk`` command line (Typer). Each sub-command lives in its own module.

:func:`main` loads the commands itself: loading takes seconds (torch), and a
Ctrl-C meanwhile ends the command as one later would, with exit status 130
and one line, not a traceback. The Typer application is
:data:`avrisk.cli.app.app`.
"""

import sys

#: Exit status of a command stopped by Ctrl-C (128 + SIGINT, as shells give it).
INTERRUPTED = 130

__all__ = ["INTERRUPTED", "main"]


def main() -> None:
    """Entry point of the ``avrisk`` console script."""
    try:
        from avrisk.cli.app import app
    except KeyboardInterrupt:
        sys.stderr.write("interrupted while loading: nothing was run\n")
        raise SystemExit(INTERRUPTED) from None
    app()
