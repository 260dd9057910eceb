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
