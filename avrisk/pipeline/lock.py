"""One process at a time per run directory: an advisory lock for the run's life.

:func:`run_lock` holds ``fcntl.flock`` on ``DIR/.lock`` (which records the
holder's process id) while a run works in ``DIR``. A second process is refused
at once, naming the first. The kernel releases the lock when its holder ends,
however it ends (``kill -9`` included), so a lock file left behind by a killed
run never blocks the next one.
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from avrisk.pipeline.layout import LOCK_FILE, RunDirectoryError


@contextmanager
def run_lock(directory: Path) -> Iterator[None]:
    """Hold the lock of run directory ``directory`` (created if missing).

    Raises
    ------
    RunDirectoryError
        If another process holds it (the message names its process id), or
        the directory cannot be created.
    """
    try:
        if directory.exists() and not directory.is_dir():
            raise RunDirectoryError(f"{directory} is a file, not a run directory")
        directory.mkdir(parents=True, exist_ok=True)
        fd = os.open(
            directory / LOCK_FILE, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644
        )
    except OSError as exc:
        raise RunDirectoryError(
            f"{directory}: cannot be used as a run directory: {exc.strerror or exc}"
        ) from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip()
            raise RunDirectoryError(
                f"{directory} is in use by another avrisk process (pid "
                f"{holder or 'unknown'}); wait for it to end, or stop it, and "
                "rerun to resume"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)
