"""torch's CPU threads fitted to the cores other processes leave idle.

torch's intra-op threads (OpenMP: libgomp in the Linux wheels) meet at a
barrier after every parallel operation, and a thread that arrives first spins
before it sleeps. On an idle machine that makes small operations fast. When
other processes hold the cores, the partner a thread waits for is often
descheduled, and the waiting thread spins through its time slices: the run's
CPU time, and its wall time with it, grow many times over what one thread
needs (BENCHMARKS.md, "Threads under a competing load").

:func:`threads_fitted_to_load` counts the cores that stayed idle over a short
window (:func:`idle_cores`, from ``/proc/stat``) and runs its block with that
many intra-op threads: torch's own default on an idle machine, one thread
beside CPU-bound neighbours. The count is chosen once, when the block starts.
Results do not depend on it: the demo's estimates and the rollouts' ``f``
come out the same bit for bit on one thread and two (``benchmarks/thread_load.py``
checks it).

A user's choice wins: with ``OMP_NUM_THREADS`` in the environment the thread
count is left as torch set it. Where ``/proc/stat`` cannot be read (macOS,
Windows) nothing changes either. Worker processes compute with one thread
each (:class:`avrisk.assembly.ObjectiveFactory`) and do not use this.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import torch

__all__ = [
    "USER_SETTING",
    "WINDOW_S",
    "idle_cores",
    "parse_proc_stat",
    "threads_fitted_to_load",
]

#: The environment variable with which a user fixes the thread count.
USER_SETTING = "OMP_NUM_THREADS"
#: How long :func:`idle_cores` watches the machine [s].
WINDOW_S = 0.2

_PROC_STAT = Path("/proc/stat")
# Columns of /proc/stat's "cpu" line counted as time (user ... steal; guest
# time is already inside user), and those of them that are idle (idle, iowait).
_TIME_COLUMNS = 8
_IDLE_COLUMNS = (3, 4)


@contextmanager
def threads_fitted_to_load(window_s: float = WINDOW_S) -> Iterator[int]:
    """Run the block with as many intra-op threads as cores are idle now.

    Yields the thread count in use: ``round(idle_cores())`` within 1 and
    torch's current count, or torch's current count where the user set
    :data:`USER_SETTING` or the idle cores cannot be measured. The previous
    count is restored on exit.
    """
    previous = torch.get_num_threads()
    idle = None if USER_SETTING in os.environ else idle_cores(window_s)
    threads = previous if idle is None else max(1, min(previous, round(idle)))
    torch.set_num_threads(threads)
    try:
        yield threads
    finally:
        torch.set_num_threads(previous)


def idle_cores(window_s: float = WINDOW_S) -> float | None:
    """How many of the machine's cores were idle over the next ``window_s`` [s].

    The idle share of all CPU time in ``/proc/stat`` over the window, times
    the number of CPUs it lists; this process sleeps meanwhile, so the figure
    is what the other processes leave. None where ``/proc/stat`` cannot be read.
    """
    before = _cpu_times()
    if before is None:
        return None
    time.sleep(window_s)
    after = _cpu_times()
    if after is None:
        return None
    (total0, idle0, cpus), (total1, idle1, _) = before, after
    if total1 <= total0:
        return None
    return cpus * (idle1 - idle0) / (total1 - total0)


def _cpu_times() -> tuple[int, int, int] | None:
    """(all CPU time, idle CPU time, number of CPUs) from ``/proc/stat`` [ticks]."""
    try:
        text = _PROC_STAT.read_text()
    except OSError:
        return None
    return parse_proc_stat(text)


def parse_proc_stat(text: str) -> tuple[int, int, int] | None:
    """(all CPU time, idle CPU time, number of CPUs) of a ``/proc/stat`` text.

    None if it has no summary ``cpu`` line.
    """
    lines = text.splitlines()
    summary = next((line.split() for line in lines if line.startswith("cpu ")), None)
    if summary is None:
        return None
    ticks = [int(v) for v in summary[1 : 1 + _TIME_COLUMNS]]
    cpus = sum(1 for line in lines if line[:3] == "cpu" and line[3:4].isdigit())
    return sum(ticks), sum(ticks[i] for i in _IDLE_COLUMNS), max(cpus, 1)
