"""``avrisk simulate`` and ``avrisk replay``: naive rollouts from P0, and animations.

``simulate`` draws ``X ~ P0`` and writes one Parquet row per rollout, in the
samples-table format of a run, the scenario in its metadata; ``replay``
simulates chosen rows of such a file, or of a run directory, again
(:mod:`avrisk.api.rollouts` does both). A spec read back from a file never
makes avrisk import code: one that names user code by import path must be
given again (``--scenario``).

The simulator (torch) is imported where it runs, not by this module: ``--help``
starts without it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Annotated

import numpy as np
import pyarrow as pa
import typer
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

from avrisk.cli.common import (
    CliError,
    Device,
    check_output_file,
    err_console,
    out_console,
    user_errors,
)
from avrisk.cli.tables import add_columns, compact_table
from avrisk.extras import MissingExtraError
from avrisk.pipeline.layout import SAMPLES_FILE
from avrisk.pipeline.regenerate import RegenerationError
from avrisk.registry import ComponentError
from avrisk.scenario import ScenarioSpecError

#: Thresholds on the minimum TTC [s] counted in the summary.
SUMMARY_GAMMAS: tuple[float, ...] = (0.1, 0.2, 0.3)

#: Where ``simulate`` and ``replay`` write without ``--out`` (``runs/`` is made).
DEFAULT_ROLLOUTS = Path("runs/rollouts.parquet")
DEFAULT_GIF = Path("runs/replay.gif")


def _out_path(out: Path | None, default: Path, suffixes: Sequence[str]) -> Path:
    """``--out``, or ``default`` (its folder made); checked to be writable."""
    if out is None:
        out = default
        out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() not in suffixes:
        raise CliError(
            f"--out {out}: expected a file ending in {' or '.join(suffixes)}"
        )
    check_output_file(out)
    return out


def _summary_table(table: pa.Table, wall_s: float) -> Table:
    n = table.num_rows
    f = table.column("f").to_numpy()
    summary = compact_table(
        f"{n} rollouts in {wall_s:.1f} s ({n / max(wall_s, 1e-9):.0f}/s)"
    )
    add_columns(summary, ["event", "count", "fraction"], text=["event"])
    rows = [(f"min TTC <= {g:g} s", int(np.sum(f <= g))) for g in SUMMARY_GAMMAS]
    rows += [
        (k, int(np.sum(table.column(k).to_numpy())))
        for k in ("crash", "offroad", "reversing")
    ]
    for name, k in rows:
        # Zero hits is not p = 0: show the 95% upper bound (rule of three).
        frac = f"{k / n:.3g}" if k else f"< {3.0 / n:.2g} (95%)"
        summary.add_row(name, str(k), frac)
    return summary


def _shown_as(progress: Progress, task: TaskID) -> Callable[[str], None]:
    """Shows ``progress`` once the scenario is loaded, ``task`` labelled by its name."""

    def start(name: str) -> None:
        progress.update(task, description=name)
        progress.start()

    return start


def simulate(
    scenario: Annotated[
        str, typer.Argument(help="Scenario YAML file, or a bundled name.")
    ] = "highway_default",
    n: Annotated[int, typer.Option("--n", min=1, help="Number of rollouts.")] = 1000,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Run seed.")] = 0,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help=f"Parquet file to write (one row per rollout) [default: "
            f"{DEFAULT_ROLLOUTS}].",
        ),
    ] = None,
    batch_size: Annotated[
        int, typer.Option("--batch-size", min=1, help="Rollouts simulated together.")
    ] = 1024,
    device: Device = "cpu",
    threads: Annotated[
        int | None, typer.Option(min=1, help="CPU threads for torch (default: all).")
    ] = None,
) -> None:
    """Sample scenarios from P0, simulate them, write one Parquet row per rollout."""
    from avrisk.api.rollouts import write_rollouts

    with user_errors(ScenarioSpecError, ComponentError, MissingExtraError):
        out = _out_path(out, DEFAULT_ROLLOUTS, (".parquet", ".pq"))
        progress = Progress(
            TextColumn("[bold]simulate[/] {task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=err_console,
            transient=False,
        )
        task = progress.add_task("", total=n)
        try:
            run = write_rollouts(
                scenario,
                n,
                out,
                seed=seed,
                batch_size=batch_size,
                device=device,
                threads=threads,
                on_start=_shown_as(progress, task),
                on_batch=lambda k: progress.advance(task, k),
            )
        finally:
            progress.stop()
    out_console.print(_summary_table(run.table, run.wall_s))
    out_console.print(f"wrote {out}", highlight=False)


def replay(
    file: Annotated[
        Path,
        typer.Argument(
            help="Parquet file written by 'avrisk simulate', or a run directory "
            "(or its samples.parquet): its scenario is read from the file or the "
            "run's config.json, as data (no code imported)."
        ),
    ],
    rows: Annotated[
        str | None, typer.Option(help="Comma-separated row numbers, e.g. 0,5,12.")
    ] = None,
    worst: Annotated[
        int | None,
        typer.Option(min=1, help="Instead of --rows: the K rows of lowest f."),
    ] = None,
    out: Annotated[
        Path | None, typer.Option(help=f"GIF file to write [default: {DEFAULT_GIF}].")
    ] = None,
    scenario: Annotated[
        str | None,
        typer.Option(
            help="Scenario to use instead of the one stored with the samples: "
            "needed only for one that names user code by import path."
        ),
    ] = None,
    fps: Annotated[int, typer.Option(min=1, max=50, help="Frames per second.")] = 10,
    view_length: Annotated[
        float,
        typer.Option(min=10.0, help="Length of road shown around the ego, in metres."),
    ] = 120.0,
    frame_png: Annotated[
        Path | None, typer.Option(help="Also save the frame of lowest TTC as a PNG.")
    ] = None,
) -> None:
    """Re-simulate chosen rows of a samples table and write a top-down GIF."""
    from avrisk.api.rollouts import replay_rollouts

    with user_errors(
        ScenarioSpecError, ComponentError, MissingExtraError, RegenerationError
    ):
        if file.is_dir() and not (file / SAMPLES_FILE).is_file():
            parts = sorted(p.parent.name for p in file.glob(f"*/{SAMPLES_FILE}"))
            hint = f"; a comparison: give one of its runs, e.g. {file / parts[0]}"
            raise CliError(f"{file}: holds no {SAMPLES_FILE}" + (hint if parts else ""))
        if file.is_dir():
            file = file / SAMPLES_FILE
        if not file.is_file():
            raise CliError(f"{file}: no such file")
        out = _out_path(out, DEFAULT_GIF, (".gif",))
        if frame_png is not None:
            check_output_file(frame_png, "--frame-png")
        replay = replay_rollouts(
            file,
            out,
            rows=rows,
            worst=worst,
            scenario=scenario,
            fps=fps,
            view_length=view_length,
            frame_png=frame_png,
        )
    if replay.stored_f is not None:
        err_console.print(
            "[yellow]warning:[/] re-simulated min TTC differs from the file "
            f"(stored {replay.stored_f}, now {replay.again_f}); was the "
            "simulator or scenario changed?"
        )
    for r, tr in zip(replay.rows, replay.traces, strict=True):
        out_console.print(
            f"row {r}: min TTC {tr.min_ttc:.3g} s"
            + (", crash" if tr.crashed else "")
            + f", {tr.n_frames} frames",
            highlight=False,
        )
    out_console.print(
        f"wrote {out}" + (f" and {frame_png}" if frame_png else ""), highlight=False
    )
