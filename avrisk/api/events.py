"""What the API tells a progress callback while it works.

:func:`avrisk.estimate` and the other calls print nothing: they hand events
to an optional ``progress`` callable, in order. A command first gets its
:class:`Plan`; then each run is a :class:`RunOpened`, its
:class:`RunStarted` (absent when a complete run is only read back), any
number of :class:`Advanced`, :class:`Status` and :class:`DiskMeasured`, and
a :class:`RunClosed`, also when the run fails or is interrupted. A
:class:`Note` is a remark on the results (a reference run of another
definition). :class:`MonitorEvents` turns the run driver's
:class:`~avrisk.pipeline.RunMonitor` calls into these events.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple


class PlannedRun(NamedTuple):
    """One run of a command's plan.

    Attributes
    ----------
    label : str
        The run, as its progress bar names it.
    what : str
        What it does (the estimator's ``describe()``).
    rollouts : int
        The rollouts it plans, or at most makes (``at_most``).
    at_most : bool
        Whether ``rollouts`` is an upper bound
        (:attr:`~avrisk.rare.estimator.Estimator.budget_is_bound`).
    stored_in_full : int
        Those of ``rollouts`` whose every column is stored
        (:meth:`~avrisk.rare.estimator.Estimator.budget_not_redrawn`).
    grows_to : int, default=0
        The most rollouts where the run may grow its budget beyond
        ``rollouts`` (subset simulation's regrown replicates; 0: it does not).
    """

    label: str
    what: str
    rollouts: int
    at_most: bool = False
    stored_in_full: int = 0
    grows_to: int = 0


@dataclass(frozen=True)
class Plan:
    """The runs a call will make, before the first rollout.

    ``bytes_per_rollout`` [B]: the disk a rollout will take in
    ``samples.parquet``, estimated from the scenario's parameters
    (:func:`~avrisk.pipeline.sizing.estimated_row_bytes`);
    ``full_bytes_per_rollout`` [B]: the same for one stored in full.
    """

    runs: tuple[PlannedRun, ...]
    bytes_per_rollout: float
    full_bytes_per_rollout: float


@dataclass(frozen=True)
class RunOpened:
    """Run ``label`` begins (or resumes, or is read back) in ``out``.

    ``out`` is None for a run that records nothing (the demo's exact problems).
    """

    label: str
    out: Path | None


@dataclass(frozen=True)
class RunStarted:
    """Run ``label`` has work to do: ``total`` rollouts, ``description`` of it."""

    label: str
    total: int
    description: str


@dataclass(frozen=True)
class Advanced:
    """``n`` more rollouts of ``label`` are done (``replayed``: recorded earlier)."""

    label: str
    n: int
    replayed: bool


@dataclass(frozen=True)
class Status:
    """The estimator of ``label`` finished a step: its status line."""

    label: str
    text: str


@dataclass(frozen=True)
class DiskMeasured:
    """Disk a rollout of ``label`` took in its first chunk written [B].

    ``full``: whether that chunk stored every column.
    """

    label: str
    row_bytes: float
    full: bool


@dataclass(frozen=True)
class RunClosed:
    """Run ``label`` ended: ``error`` is what stopped it, None when it finished."""

    label: str
    out: Path | None
    error: BaseException | None = None


@dataclass(frozen=True)
class Note:
    """A remark on the results, one sentence."""

    text: str


Event = (
    Plan | RunOpened | RunStarted | Advanced | Status | DiskMeasured | RunClosed | Note
)
#: The ``progress`` argument of the API: called with every event, in order.
Progress = Callable[[Event], None]


def ignore(event: Event) -> None:
    """The progress callback that ignores every event."""


class MonitorEvents:
    """A :class:`~avrisk.pipeline.RunMonitor` of run ``label`` that emits events."""

    def __init__(self, label: str, progress: Progress) -> None:
        self.label, self.progress = label, progress

    def start(self, total: int, description: str) -> None:  # noqa: D102
        self.progress(RunStarted(self.label, total, description))

    def advance(self, n: int, *, replayed: bool) -> None:  # noqa: D102
        self.progress(Advanced(self.label, n, replayed))

    def status(self, text: str) -> None:  # noqa: D102
        self.progress(Status(self.label, text))

    def disk(self, row_bytes: float, *, full: bool) -> None:  # noqa: D102
        self.progress(DiskMeasured(self.label, row_bytes, full))


@contextmanager
def run_events(
    label: str, out: Path | None, progress: Progress
) -> Iterator[MonitorEvents]:
    """A run's :class:`RunOpened`, its monitor, then its :class:`RunClosed`."""
    progress(RunOpened(label, out))
    try:
        yield MonitorEvents(label, progress)
    except BaseException as exc:
        progress(RunClosed(label, out, exc))
        raise
    progress(RunClosed(label, out))
