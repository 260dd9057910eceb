"""Freed memory kept for reuse: the C allocator's settings for batched work.

A batched rollout allocates and frees tensors of megabytes at every step (the
driver network's hidden layer at batch 1,024: 5,120 x 200 floats, 4 MB).
glibc's ``malloc`` serves a block above its mmap threshold (128 KiB at start,
raised as such blocks are freed) with a fresh mapping, and gives freed memory
at the top of its heap back to the system above its trim threshold: either
way the next step's block is page-faulted and zeroed again, page by page.
These page faults take a noticeable share of a compiled step. How often they
happen depends on what the process allocated and freed before, since glibc
adapts both thresholds to the blocks it has freed.
:func:`keep_freed_memory` raises both thresholds, so that such blocks come
from the heap and are reused, whatever came before: a fresh worker process
gains most from it, the ``avrisk`` command (whose start-up already freed
large blocks) least (BENCHMARKS.md, "The lidar's reduction fused, and freed
memory kept", has the figures).

Results do not depend on it (only where memory comes from). The cost: a
process keeps up to :data:`TRIM_THRESHOLD` bytes of freed memory instead of
returning it, and its resident size stays near its peak. avrisk's commands
and worker processes call it at start; a program that builds simulators
itself may call it too.
"""

from __future__ import annotations

import ctypes
import os
import sys

__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_freed_memory"]

#: Blocks up to this size [bytes] come from the heap (glibc's largest allowed
#: value on 64-bit systems, 32 MiB).
MMAP_THRESHOLD = 32 * 2**20
#: Freed memory kept at the top of the heap before it goes back [bytes].
TRIM_THRESHOLD = 256 * 2**20

# mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3

_USER_SETTINGS = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds for this process.

    Returns
    -------
    bool
        True if the thresholds were set; False where the C library is not
        glibc (macOS, musl, Windows) or the user set glibc's malloc tunables
        (``GLIBC_TUNABLES`` with ``glibc.malloc``, ``MALLOC_MMAP_THRESHOLD_``,
        ``MALLOC_TRIM_THRESHOLD_``), which are then left as they are.
    """
    if not sys.platform.startswith("linux") or _user_configured(os.environ):
        return False
    libc = _glibc()
    if libc is None:
        return False
    mallopt = libc.mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(
        mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
        and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    )


def _user_configured(environ: dict[str, str] | os._Environ[str]) -> bool:
    tunables = environ.get("GLIBC_TUNABLES", "")
    return "glibc.malloc" in tunables or any(k in environ for k in _USER_SETTINGS)


def _glibc() -> ctypes.CDLL | None:
    """The C library of this process if it is glibc, else None.

    ``CDLL(None)`` looks symbols up in the process itself (no library search,
    which would run ``ldconfig`` at every command's start).
    """
    libc = ctypes.CDLL(None)
    try:
        libc.gnu_get_libc_version  # noqa: B018 -- only glibc has it
    except AttributeError:
        return None
    return libc
