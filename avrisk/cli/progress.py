"""Rich progress display for cross-entropy searches."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from avrisk.rare import CEInfo, CEState


@contextmanager
def ce_progress(
    console: Console, label: str, n_iter: int
) -> Iterator[Callable[[CEInfo], None]]:
    """Show a bar over CE iterations; yields the callback to pass to the search.

    Each update shows the iteration, ``gamma_k``, the hits and the elite ESS.
    """
    columns = (
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[status]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=console, transient=False) as progress:
        task = progress.add_task(label, total=n_iter, status="")

        def update(info: CEInfo, state: CEState | None = None) -> None:
            status = f"gamma_k={info.gamma_k:.4g} hits={info.n_hits} ESS={info.ess:.0f}"
            progress.update(task, advance=1, status=status)

        yield update


class RichRunMonitor:
    """Progress of a run: a bar over all rollouts, CE iteration status, ETA.

    Implements :class:`avrisk.pipeline.RunMonitor`.
    """

    def __init__(self, console: Console, label: str) -> None:
        self.console = console
        self.label = label
        self._progress: Progress | None = None
        self._task = 0

    def __enter__(self) -> RichRunMonitor:
        self._progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[status]}"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=self.console,
        )
        self._progress.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        assert self._progress is not None
        self._progress.__exit__(*exc)  # type: ignore[arg-type]

    def start(self, total: int, description: str) -> None:
        """Open the bar for ``total`` rollouts."""
        assert self._progress is not None
        self._task = self._progress.add_task(
            f"{self.label}: {description}", total=total, status=""
        )

    def advance(self, n: int, *, replayed: bool) -> None:
        """Count ``n`` rollouts (replayed ones come from an earlier session)."""
        assert self._progress is not None
        self._progress.update(self._task, advance=n)

    def iteration(self, info: CEInfo) -> None:
        """Show the state of the CE search after an iteration."""
        assert self._progress is not None
        status = (
            f"iter {info.iteration}: gamma_k={info.gamma_k:.3g} "
            f"hits={info.n_hits} ESS={info.ess:.0f}"
        )
        self._progress.update(self._task, status=status)
