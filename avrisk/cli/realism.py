"""``avrisk realism``: how human-like the learned drivers are, on held-out data.

Runs the realism report (:mod:`avrisk.realism`) for the shipped drivers or
those ``avrisk train-drivers`` wrote in ``--drivers``, on the held-out human
data shipped with the package (no ``$AVRISK_NGSIM_DIR`` needed):

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

import time
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer
from rich.markup import escape
from rich.progress import Progress

from avrisk.cli.common import (
    CliError,
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

    from avrisk.agents.drivers.guard import BrakeGuard
    from avrisk.realism import DriverFiles, RealismResult
    from avrisk.realism.car_following import Progress as PartProgress

#: Where ``realism`` writes by default.
DEFAULT_OUT = Path("realism")

#: What a corrupt driver file raises when read.
_UNREADABLE = (
    OSError,
    EOFError,
    ValueError,
    KeyError,
    TypeError,
    IndexError,
    RuntimeError,
    zipfile.BadZipFile,
)


def driver_files(folder: Path | None) -> DriverFiles:
    """The driver model to evaluate, each file read once to check it.

    Raises
    ------
    CliError
        For a missing folder or file, or a file that is not what it should be.
    """
    from avrisk.agents.drivers.store import load_driver_net, load_xi_prior
    from avrisk.realism import DriverFiles

    if folder is not None and not folder.is_dir():
        raise CliError(f"--drivers {folder}: no such folder")
    files = DriverFiles.in_folder(folder)
    for path, load, what in (
        (files.net, load_driver_net, "a driver network"),
        (files.prior, load_xi_prior, "an xi prior"),
    ):
        if not path.is_file():
            raise CliError(
                f"--drivers {folder}: lacks {path.name} (avrisk train-drivers "
                "writes driver_net.npz and xi_prior.npz)"
            )
        try:
            load(path)
        except _UNREADABLE as exc:
            reason = str(exc).splitlines()[0][:200] if str(exc) else ""
            raise CliError(
                f"--drivers {path}: not {what} ({reason or type(exc).__name__})"
            ) from None
    return files


@contextmanager
def part_progress() -> Iterator[tuple[PartProgress, PartProgress]]:
    """A bar per part, naming the model being simulated; yields both callbacks."""
    with Progress(*stage_columns("model"), console=err_console) as progress:

        def bar(label: str) -> PartProgress:
            task = progress.add_task(label, total=None, model="", start=False)

            def update(model: str, done: int, total: int) -> None:
                progress.start_task(task)
                progress.update(task, completed=done, total=total, model=escape(model))

            return update

        yield bar("A. car following"), bar("B. lane changes")


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
            metavar="test|PERIOD",
            help="Part A's held-out I-80 windows: 'test', the test splits of "
            "every period; or a recording period (0400pm-0415pm or "
            "0500pm-0515pm), all of it, for drivers trained on the other "
            "(train-drivers --period). The report also splits part A by speed "
            "band (leader's mean speed below 5 m/s: congested).",
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
    with user_errors(ValueError):
        guard = _brake_guard(brake_guard)
        _check_held_out(held_out)
    with user_errors(OSError):
        files = driver_files(drivers)
        _warn_trained_on(files, held_out)
        check_output_folder(out)
        import torch

        from avrisk.realism import RealismSettings, run_realism, write_report

        torch.set_num_threads(threads)
        settings = RealismSettings(
            seed=seed,
            replicates=replicates,
            windows=windows,
            scenes=scenes,
            guard=guard,
            held_out=held_out,
        )
        t0 = time.perf_counter()
        with part_progress() as (progress_a, progress_b):
            result = run_realism(files, settings, progress_a, progress_b)
        written = write_report(result, out, command_line(ctx))
        out_console.print(targets_summary(result))
        out_console.print(lane_change_summary(result))
        names = ", ".join(p.name for p in written)
        out_console.print(
            f"wrote {escape(names)} to {escape(str(out))} "
            f"({duration(time.perf_counter() - t0)})",
            highlight=False,
        )


def _check_held_out(held_out: str) -> None:
    """Raise ValueError for a ``--held-out`` that is neither test nor a period."""
    from avrisk.realism.held_out import HELD_OUT_TEST, held_out_periods

    periods = held_out_periods()
    if held_out != HELD_OUT_TEST and held_out not in periods:
        raise ValueError(
            f"--held-out {held_out}: not {HELD_OUT_TEST} nor one of the periods "
            f"{', '.join(periods)}"
        )


def _warn_trained_on(files: DriverFiles, held_out: str) -> None:
    """Warn when the drivers' training report says they trained on ``held_out``."""
    import json

    from avrisk.realism.held_out import HELD_OUT_TEST

    if held_out == HELD_OUT_TEST:
        return
    report = files.net.parent / "training_report.json"
    try:
        periods = json.loads(report.read_text())["config"].get("periods")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        periods = None  # no report: all periods, as the shipped drivers
    if periods is None or held_out in periods:
        err_console.print(
            f"[yellow]warning:[/] these drivers were trained on {escape(held_out)} "
            "(its train split): part A is not held out",
            highlight=False,
        )


def _brake_guard(text: str | None) -> BrakeGuard | Literal["drivers"] | None:
    """``--brake-guard``: the drivers' own brake (absent), none, or GAP,DECEL."""
    from avrisk.agents.drivers.guard import parse_guard
    from avrisk.realism.report import DRIVERS_GUARD

    return DRIVERS_GUARD if text is None else parse_guard(text)
