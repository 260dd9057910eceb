"""Rich progress display of an estimation run, and what the work will cost.

A :class:`CostMeter` is shared by the runs of one command (a ``compare`` has
three): before the first rollout it prints the plan (rollouts, and disk as
estimated from the scenario's parameters), and once the first chunk has been
simulated, the rate measured on it and the time the rest will take, and the
disk a rollout took in it. Where a run's rollouts are only bounded (subset
simulation ends when its levels reach ``gamma``), each figure says "at most".
A run that resumes says so when it ends: how many rollouts it reused from the
earlier session.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Column

from avrisk.api.events import (
    Advanced,
    DiskMeasured,
    Event,
    Note,
    Plan,
    PlannedRun,
    RunClosed,
    RunOpened,
    RunStarted,
    Status,
)

#: Width of the progress bar [characters].
BAR_WIDTH = 12
#: Consoles at least this wide also show the time elapsed [characters].
WIDE = 100


def stage_columns(field: str) -> tuple[ProgressColumn, ...]:
    """Columns of a bar per stage: name, bar, count, time, then ``task.fields[field]``.

    The field comes last: a narrow terminal cuts it, not the bar or the count.
    """
    return (
        TextColumn("[bold]{task.description}"),
        BarColumn(bar_width=10, table_column=Column(min_width=10)),
        MofNCompleteColumn(),
        TimeElapsedColumn(table_column=Column(min_width=7)),
        TextColumn(
            f"{{task.fields[{field}]}}",
            table_column=Column(no_wrap=True, overflow="ellipsis"),
        ),
    )


def duration(seconds: float) -> str:
    """``"7 min 20 s"``, ``"45 s"``, ``"2 h 05 min"``: a time for a person."""
    s = round(seconds)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def megabytes(n_bytes: float) -> str:
    """``"64 kB"``, ``"55 MB"``, ``"1.2 GB"``."""
    if n_bytes >= 1e9:
        return f"{n_bytes / 1e9:.1f} GB"
    return f"{n_bytes / 1e6:.0f} MB" if n_bytes >= 1e6 else f"{n_bytes / 1e3:.0f} kB"


@dataclass
class CostMeter:
    """What a command's runs will cost, printed before and once measured.

    Parameters
    ----------
    console : Console
        Where the lines go (stderr).
    plan : sequence of PlannedRun
        Each run of the command.
    bytes_per_rollout : float
        Disk a rollout will take in ``samples.parquet`` [B], as estimated
        before any is written
        (:func:`~avrisk.pipeline.sizing.estimated_row_bytes`); the chunk files
        hold as much again until they are gathered at the end of a run.
    full_bytes_per_rollout : float
        The same for a rollout stored in full (each run's
        ``stored_in_full``; ``bytes_per_rollout`` where nothing is left out).

    Attributes
    ----------
    measured_bytes : float or None
        Disk a rollout took in the first chunk written [B] (:meth:`disk`).
    measured_full : bool
        Whether that chunk stored its rollouts in full (the rate line says so
        when the plan stores rollouts of both kinds).
    """

    console: Console
    plan: Sequence[PlannedRun]
    bytes_per_rollout: float
    full_bytes_per_rollout: float
    done: int = 0
    measured_bytes: float | None = None
    measured_full: bool = False
    _scale: float = 1.0
    _announced: bool = False
    _measured: bool = False

    @property
    def total(self) -> int:
        """Rollouts of every run of the plan (an upper bound if :attr:`at_most`)."""
        return sum(run.rollouts for run in self.plan)

    @property
    def total_bytes(self) -> float:
        """Disk of every run's samples [B]: estimated, then scaled as measured."""
        estimate = sum(
            (run.rollouts - run.stored_in_full) * self.bytes_per_rollout
            + run.stored_in_full * self.full_bytes_per_rollout
            for run in self.plan
        )
        return self._scale * estimate

    @property
    def at_most(self) -> str:
        """``"at most "`` when some run's rollouts are only bounded, else ``""``."""
        return "at most " if any(run.at_most for run in self.plan) else ""

    def announce(self) -> None:
        """The plan, once, before the first rollout of the command."""
        if self._announced:
            return
        self._announced = True
        runs = ", ".join(f"{run.label} ({run.what})" for run in self.plan)
        in_all = " in all" if len(self.plan) > 1 else ""
        grows = sum(max(run.grows_to, run.rollouts) for run in self.plan)
        if grows == self.total:
            sooner = " (fewer if the levels reach gamma sooner)"
        else:
            sooner = (
                " (fewer if the levels reach gamma sooner; up to "
                f"{grows:,} if levels that run out are run again, larger, or "
                "slowly mixing chains move more)"
            )
        self.console.print(
            f"plan: {escape(runs)}: {self.at_most}{self.total:,} rollouts{in_all}"
            + ("" if not self.at_most else sooner)
            + f"; samples take {self.at_most}about "
            f"{megabytes(self.total_bytes)} on disk "
            f"(an estimate: {self._per_rollout_text()})",
            highlight=False,
        )

    @property
    def _two_kinds(self) -> bool:
        """Whether the plan stores some rollouts in full, at another size."""
        return self.full_bytes_per_rollout != self.bytes_per_rollout and any(
            run.stored_in_full for run in self.plan
        )

    def _per_rollout_text(self) -> str:
        full = self.full_bytes_per_rollout
        if not self._two_kinds:
            return f"{self.bytes_per_rollout:,.0f} B a rollout"
        return (
            f"{self.bytes_per_rollout:,.0f} B a rollout, {full:,.0f} B for one "
            "stored in full"
        )

    def disk(self, row_bytes: float, *, full: bool) -> None:
        """The disk a rollout took in a chunk just written [B]: the first counts.

        It scales the estimate of its kind (``full``: a chunk that stored
        every column), and with it the whole plan's.
        """
        if self.measured_bytes is None:
            self.measured_bytes = row_bytes
            self.measured_full = full
            estimate = self.full_bytes_per_rollout if full else self.bytes_per_rollout
            self._scale = row_bytes / estimate

    def count(self, n: int, seconds: float | None) -> None:
        """``n`` rollouts are done: simulated in ``seconds``, or replayed (None).

        The first simulated chunk gives the rate, and with it the time left
        (said when some is), and the disk measured on it (:meth:`disk`).
        """
        self.done += n
        if seconds is None or self._measured or seconds <= 0:
            return
        self._measured = True
        rate = n / seconds
        left = max(self.total - self.done, 0)
        if not left:
            return
        disk = self.measured_bytes
        kind = " stored in full" if self.measured_full and self._two_kinds else ""
        bound = self.at_most
        rest = f"at most {left:,} more" if bound else f"the {left:,} left"
        self.console.print(
            f"rate: {rate:,.0f} rollouts/s on the first {n:,}: {bound}about "
            f"{duration(left / rate)} for {rest}"
            + (
                ""
                if disk is None
                else f"; disk: {disk:,.0f} B a rollout{kind}, {bound}about "
                f"{megabytes(self.total_bytes)} in all"
            ),
            highlight=False,
        )


class RichRunMonitor:
    """Progress of a run: a bar over all rollouts, the estimator's status, ETA.

    Implements :class:`avrisk.pipeline.RunMonitor`.

    Parameters
    ----------
    console : Console
    label : str
        The run, as the bar names it.
    cost : CostMeter, optional
        Told of every rollout (shared by the runs of one command).

    Attributes
    ----------
    started : bool
        Whether the run did any work (a complete run is only read back).
    replayed, simulated : int
        Rollouts reused from an earlier session, and simulated in this one.
    """

    def __init__(
        self, console: Console, label: str, cost: CostMeter | None = None
    ) -> None:
        self.console = console
        self.label = label
        self.cost = cost
        self.started = False
        self.replayed = 0
        self.simulated = 0
        self._progress: Progress | None = None
        self._task = 0
        self._total = 0
        self._last = 0.0

    def __enter__(self) -> RichRunMonitor:
        self._status = Column(overflow="fold")  # wraps, never cut
        elapsed = [TimeElapsedColumn()] if self.console.width >= WIDE else []
        self._progress = Progress(
            TextColumn("[bold]{task.description}", table_column=Column(no_wrap=True)),
            BarColumn(bar_width=BAR_WIDTH),
            MofNCompleteColumn(table_column=Column(no_wrap=True)),
            *elapsed,
            TextColumn("ETA", table_column=Column(no_wrap=True)),
            TimeRemainingColumn(),
            TextColumn("{task.fields[status]}", table_column=self._status),
            console=self.console,
        )
        self._progress.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        assert self._progress is not None
        if exc[0] is None and self.started:
            # A run that ends below its planned rollouts (levels that reach
            # gamma sooner than the bound, a stopping rule) ends its bar full.
            done = self.replayed + self.simulated
            self._progress.update(self._task, total=done)
        self._progress.__exit__(*exc)  # type: ignore[arg-type]
        if exc[0] is None and self.replayed:
            self.console.print(
                f"{escape(self.label)}: resumed: {self.replayed:,} rollouts reused "
                f"from the earlier session, {self.simulated:,} simulated now",
                highlight=False,
            )

    def start(self, total: int, description: str) -> None:
        """Open the bar for ``total`` rollouts (``description``: in the plan line)."""
        assert self._progress is not None
        self.started = True
        if self.cost is not None:
            self.cost.announce()
        # The estimator's status gets what the other columns leave of a line.
        used = len(self.label) + BAR_WIDTH + len(f"{total}/{total}") + len("ETA")
        used += len("0:00:00") * (2 if self.console.width >= WIDE else 1) + 7
        self._status.width = max(self.console.width - used, 10)
        self._task = self._progress.add_task(self.label, total=total, status="")
        self._total = total
        self._last = time.perf_counter()

    def advance(self, n: int, *, replayed: bool) -> None:
        """Count ``n`` rollouts (replayed ones come from an earlier session)."""
        assert self._progress is not None
        now = time.perf_counter()
        if replayed:
            self.replayed += n
        else:
            self.simulated += n
        if self.cost is not None:
            self.cost.count(n, None if replayed else now - self._last)
        self._last = now
        done = self.replayed + self.simulated
        if done > self._total:  # a run that grew its budget (regrown levels)
            self._total = done
            self._progress.update(self._task, total=done)
        self._progress.update(self._task, advance=n)

    def status(self, text: str) -> None:
        """Show the estimator's status line after a step."""
        assert self._progress is not None
        self._progress.update(self._task, status=text)

    def disk(self, row_bytes: float, *, full: bool) -> None:
        """Tell the cost meter the disk a rollout took in the first chunk [B]."""
        if self.cost is not None:
            self.cost.disk(row_bytes, full=full)


class RichProgress:
    """The API's progress events (:mod:`avrisk.api.events`) as Rich output.

    A :class:`~avrisk.api.events.Plan` makes the command's
    :class:`CostMeter`; each run is a :class:`RichRunMonitor` from its
    :class:`~avrisk.api.events.RunOpened` to its
    :class:`~avrisk.api.events.RunClosed`. A run that was complete already
    (it never started) says it was read back; a note is one line.
    """

    def __init__(self, console: Console) -> None:
        self.console = console
        self.cost: CostMeter | None = None
        self.monitor: RichRunMonitor | None = None

    def __call__(self, event: Event) -> None:
        """Show ``event``."""
        match event:
            case Plan(runs, bytes_per_rollout, full_bytes_per_rollout):
                self.cost = CostMeter(
                    self.console, runs, bytes_per_rollout, full_bytes_per_rollout
                )
            case RunOpened(label):
                self.monitor = RichRunMonitor(self.console, label, self.cost)
                self.monitor.__enter__()
            case RunStarted(_, total, description):
                self._run.start(total, description)
            case Advanced(_, n, replayed):
                self._run.advance(n, replayed=replayed)
            case Status(_, text):
                self._run.status(text)
            case DiskMeasured(_, row_bytes, full):
                self._run.disk(row_bytes, full=full)
            case RunClosed(label, out, error):
                monitor, self.monitor = self._run, None
                if error is None:
                    monitor.__exit__(None, None, None)
                else:
                    monitor.__exit__(type(error), error, error.__traceback__)
                if error is None and not monitor.started:
                    self.console.print(
                        f"{escape(label)}: complete already in {escape(str(out))}: "
                        "read back, nothing simulated",
                        highlight=False,
                    )
            case Note(text):
                self.console.print(f"note: {escape(text)}", highlight=False)

    @property
    def _run(self) -> RichRunMonitor:
        """The monitor of the run under way."""
        assert self.monitor is not None, "an event of a run that was not opened"
        return self.monitor
