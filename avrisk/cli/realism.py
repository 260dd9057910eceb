"""``avrisk realism``: how human-like the learned drivers are, on held-out data.

Runs the realism report (:func:`avrisk.api.realism.realism_report`) for the
shipped drivers or those ``avrisk train-drivers`` wrote in ``--drivers``, on
the held-out human data shipped with the package (no ``$AVRISK_NGSIM_DIR``
needed):

* part A, car following on the held-out NGSIM I-80 windows (each replayed
  ``--replicates`` times per model: 24 by default, the benchmark's setting,
  20.2 vehicle-hours per model);
* part B, lane changes in ``--scenes`` random six-lane scenes against the
  held-out US-101 vehicles.

It writes ``realism.md``, ``realism.json``, ``part_a_cdfs.png`` and
``lane_changes.png`` into ``--out`` and prints issue 21's targets and the
lane-change rates. With one torch thread (the default) the same seed and
settings give the same figures on a machine.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.progress import Progress, TaskID

from avrisk.api.realism import realism_report
from avrisk.cli.common import (
    check_output_folder,
    command_line,
    err_console,
    out_console,
    user_errors,
)
from avrisk.cli.progress import duration, stage_columns
from avrisk.cli.tables import add_columns, compact_table

if TYPE_CHECKING:
    from rich.table import Table

    from avrisk.realism import RealismResult
    from avrisk.realism.car_following import Progress as PartProgress

#: Where ``realism`` writes by default.
DEFAULT_OUT = Path("realism")


@contextmanager
def part_progress() -> Iterator[tuple[PartProgress, PartProgress]]:
    """A bar per part, naming the model being simulated; yields both callbacks.

    The bars show from the first call of either: an error or a warning before
    the parts start is a line of its own.
    """
    progress = Progress(*stage_columns("model"), console=err_console)
    tasks: list[TaskID] = []

    def bar(part: int) -> PartProgress:
        def update(model: str, done: int, total: int) -> None:
            if not tasks:
                progress.start()
                for label in ("A. car following", "B. lane changes"):
                    tasks.append(
                        progress.add_task(label, total=None, model="", start=False)
                    )
            progress.start_task(tasks[part])
            progress.update(
                tasks[part], completed=done, total=total, model=escape(model)
            )

        return update

    try:
        yield bar(0), bar(1)
    finally:
        if progress.live.is_started:
            progress.stop()


def targets_summary(result: RealismResult) -> Table:
    """Issue 21's targets on part A: one row a target, one column a model."""
    hours = next(iter(result.summary_a["models"].values()))["vehicle_hours"]
    table = compact_table(
        title=f"Issue 21's targets, part A (held-out I-80, {hours:.3g} "
        "vehicle-hours per model)",
    )
    models = [m.removeprefix("learned ") for m in result.targets]
    add_columns(table, ["target", "human", *models], text=["target"])
    for row in zip(*result.targets.values(), strict=True):
        cells = [f"{t.figure} {'pass' if t.passed else 'FAIL'}" for t in row]
        table.add_row(escape(row[0].target), row[0].human_figure or "-", *cells)
    return table


def lane_change_summary(result: RealismResult) -> Table:
    """Part B: lane changes per vehicle-hour against the held-out humans'."""
    b = result.summary_b
    human = b["human_held_out"]
    table = compact_table(
        title=f"Lane changes, part B ({result.settings.scenes} six-lane scenes; "
        "target: within +-30% of the held-out humans)",
    )
    add_columns(table, ["drivers", "per veh-h [95% CI]", "vs humans"], text=["drivers"])
    table.add_row(
        f"human, held-out US-101 ({human['vehicles']} vehicles)",
        f"{human['rate']:.1f} [{human['rate_low']:.1f}, {human['rate_high']:.1f}]",
        "-",
    )
    for name, m in b["models"].items():
        table.add_row(
            escape(name),
            f"{m['rate']:.1f} [{m['rate_low']:.1f}, {m['rate_high']:.1f}]",
            f"{m['vs_held_out']:+.0%} {'pass' if m['target_met'] else 'FAIL'}",
        )
    return table


def realism_command(
    ctx: typer.Context,
    drivers: Annotated[
        Path | None,
        typer.Option(
            "--drivers",
            help="Folder holding driver_net.npz and xi_prior.npz (as avrisk "
            "train-drivers writes them); default the shipped drivers.",
        ),
    ] = None,
    replicates: Annotated[
        int,
        typer.Option(
            min=1,
            help="Replays of every held-out I-80 window per model in part A "
            "(24, the benchmark's setting: 20.2 vehicle-hours per model).",
        ),
    ] = 24,
    scenes: Annotated[
        int,
        typer.Option(min=1, help="Six-lane scenes of 60 s per model in part B."),
    ] = 256,
    windows: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Evaluate only this many held-out windows, drawn at random with "
            "--seed (for tests and quick looks); default all 202.",
        ),
    ] = None,
    seed: Annotated[
        int, typer.Option(min=0, help="Part A's seed; part B uses seed + 1.")
    ] = 2024,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            help="Folder for realism.md, realism.json and the figures (created; "
            "files of those names are replaced).",
        ),
    ] = DEFAULT_OUT,
    threads: Annotated[
        int,
        typer.Option(
            min=1,
            help="CPU threads for torch; with one, the same settings give the "
            "same figures on a machine.",
        ),
    ] = 1,
    brake_guard: Annotated[
        str | None,
        typer.Option(
            "--brake-guard",
            metavar="GAP,DECEL[,hold]|none",
            help="The learned drivers' emergency brake: where the vehicle ahead "
            "on the front beam needs more than DECEL [m/s^2] of braking to stop "
            "the closing GAP [m] short of it, brake that hard (e.g. 3,0.5; "
            "',hold' also brakes whenever closing inside GAP); "
            "'none' drives the network alone. Default: the brake the driver "
            "weights carry (the shipped drivers': 2,2,hold).",
        ),
    ] = None,
    held_out: Annotated[
        str,
        typer.Option(
            "--held-out",
            metavar="test|PERIOD|PERIOD:test",
            help="Part A's held-out I-80 windows: 'test', the test splits of "
            "every period; or a recording period (0400pm-0415pm or "
            "0500pm-0515pm), all of it, for drivers trained on the other "
            "(train-drivers --period); or a period's test split alone (e.g. "
            "0400pm-0415pm:test), to validate drivers trained on that period "
            "before scoring them on the other. The report also splits part A "
            "by speed band (leader's mean speed below 5 m/s: congested).",
        ),
    ] = "test",
) -> None:
    """Compare the learned drivers with held-out human driving (issue 21).

    Part A replays held-out NGSIM I-80 car following (learned drivers and
    IDM against the human followers); part B counts lane changes in six-lane
    traffic against held-out US-101 vehicles. Both use only data shipped with
    avrisk. Its cost at the defaults is in BENCHMARKS.md ("The report: avrisk
    realism").
    """
    with user_errors(OSError):
        check_output_folder(out)
        with part_progress() as (progress_a, progress_b):
            run = realism_report(
                out,
                drivers=drivers,
                replicates=replicates,
                scenes=scenes,
                windows=windows,
                seed=seed,
                threads=threads,
                brake_guard=brake_guard,
                held_out=held_out,
                command=command_line(ctx),
                progress_a=progress_a,
                progress_b=progress_b,
            )
        out_console.print(targets_summary(run.result))
        out_console.print(lane_change_summary(run.result))
        names = ", ".join(p.name for p in run.files)
        out_console.print(
            f"wrote {escape(names)} to {escape(str(out))} ({duration(run.wall_s)})",
            highlight=False,
        )
