"""The one-line failures of the scenario-level API, and failed writes as such.

A :class:`UserError` is a problem the caller can fix (a damaged run
directory, a threshold that cannot be met, a full disk), said in one sentence;
the ``avrisk`` command prints it as one red line, without a traceback.
"""

from __future__ import annotations

import errno
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class UserError(Exception):
    """A problem to report to the user in one sentence, without a traceback."""


#: Error numbers of a write that failed for want of room, anywhere.
_NO_ROOM = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS}
#: Error numbers of a write refused, when the file is one of ours.
_REFUSED = {errno.EACCES, errno.EPERM, errno.EIO}


def is_write_failure(exc: OSError, where: Path) -> bool:
    """Whether ``exc`` is a failed write under ``where`` (a full disk ...)."""
    if exc.errno in _NO_ROOM or "No space left" in str(exc):
        return True
    if exc.errno in _REFUSED and exc.filename:
        return Path(str(exc.filename)).resolve().is_relative_to(where.resolve())
    return False


@contextmanager
def write_failures(where: Path, then: str) -> Iterator[None]:
    """Turn a failed write under ``where`` into one UserError line ending ``then``.

    Only write failures (:func:`is_write_failure`): a full disk, a read-only
    file system, a permission or quota; other OSErrors propagate.
    """
    try:
        yield
    except OSError as exc:
        if not is_write_failure(exc, where):
            raise
        reason = exc.strerror or str(exc).splitlines()[0]
        file = f" ({exc.filename})" if exc.filename else ""
        raise UserError(f"{where}: cannot write{file}: {reason}; {then}") from None
