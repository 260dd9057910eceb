"""Rich progress display of an estimation run."""

from __future__ import annotations

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


class RichRunMonitor:
    """Progress of a run: a bar over all rollouts, the estimator's status, ETA.

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

    def status(self, text: str) -> None:
        """Show the estimator's status line after a step."""
        assert self._progress is not None
        self._progress.update(self._task, status=text)
