"""Ctrl-C while a command loads: one line and exit status 130, not a traceback.

A leaf of :mod:`avrisk.cli`, so that the package's entry point and the
commands' modules share it without importing each other.
"""

import sys
from collections.abc import Iterator
from contextlib import contextmanager

#: Exit status of a command stopped by Ctrl-C (128 + SIGINT, as shells give it).
INTERRUPTED = 130

__all__ = ["INTERRUPTED", "loading"]


@contextmanager
def loading() -> Iterator[None]:
    """Imports of a command's code: a Ctrl-C meanwhile is one line and status 130."""
    try:
        yield
    except KeyboardInterrupt:
        sys.stderr.write("interrupted while loading: nothing was run\n")
        raise SystemExit(INTERRUPTED) from None
