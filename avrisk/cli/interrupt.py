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
    """Imports of a command's code: a Ctrl-C meanwhile is one line and status 130.

    A Ctrl-C that lands while a compiled extension initialises (SciPy's, as
    torch loads) comes out as that import's ``ImportError``, raised from the
    ``KeyboardInterrupt``: an interruption too.
    """
    try:
        yield
    except (KeyboardInterrupt, ImportError) as exc:
        if isinstance(exc, ImportError) and not _interrupted(exc):
            raise
        sys.stderr.write("interrupted while loading: nothing was run\n")
        raise SystemExit(INTERRUPTED) from None


def _interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` was raised from a Ctrl-C, directly or further down."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False
