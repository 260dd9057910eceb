"""``avrisk train-drivers``: retrain the learned drivers and their ``xi`` prior.

Runs :func:`avrisk.api.training.retrain_drivers` on the NGSIM I-80 data
shipped with the package (``avrisk/data/ngsim/``) or in ``--data-dir`` (behaviour
cloning, DAgger, the bootstrap ensemble of heads, the graphical-lasso prior of
``xi``; minutes on one core: BENCHMARKS.md, "Keeping the safest of several
trainings") with one torch thread, so that the same seed, data and CPU
kernels give the same files (the shipped ones were
trained with ``ATEN_CPU_CAPABILITY=avx2 OPENBLAS_CORETYPE=Haswell``; the
command warns when the kernels here differ), and writes into ``--out``::

    driver_net.npz          the driver network (avrisk.agents.drivers.DriverNet)
    xi_prior.npz            xi ~ N(mu0, Sigma0): mean, sparse precision, heads
    training_report.json    what the run did and measured

With ``--candidates N`` it trains seeds ``SEED .. SEED+N-1`` into
``--out/candidates/seed-S/``, prints each one's crashes on its own closed-loop
validation windows (:mod:`avrisk.learning.training.selection`) and copies the safest
into ``--out`` (``--workers K``: K at a time, one process each). Files of
those names already in ``--out`` are replaced. The shipped driver model
(``avrisk/data/drivers/``, which the bundled scenarios use) is replaced only
when ``--out`` names that folder.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import Progress, TaskID

from avrisk.api.training import retrain_drivers
from avrisk.cli.common import err_console, out_console, user_errors
from avrisk.cli.progress import stage_columns
from avrisk.cli.tables import add_columns, compact_table

if TYPE_CHECKING:
    from avrisk.api.training import TrainedFiles
    from avrisk.learning.train_config import TrainEvent

#: Where ``train-drivers`` writes by default (not the shipped model).
DEFAULT_OUT = Path("runs") / "drivers"

#: Stages of the training, as reported by its progress events, for people.
STAGE_LABELS = {
    "data": "demonstrations",
    "trunk": "behaviour cloning",
    "noise": "sampling noise",
    "dagger": "DAgger rounds",
    "closed_loop": "closed-loop training",
    "heads": "bootstrap heads",
    "prior": "xi prior",
    "candidates": "candidates scored",
    "fit": "PilotNet, BC + DAgger",
}

#: Metrics shown on a stage's line, when its events carry them.
SHOWN_METRICS = (
    "train_rows",
    "frames",
    "val_rows",
    "rows_added",
    "train_loss",
    "val/loss",
    "val_loss",
    "val_crash_rate",
    "rho_accel",
    "c_accel",
    "c_steer",
    "sparsity",
    "alpha",
    "stressed_crashes",
)


@contextmanager
def training_progress(console: Console) -> Iterator[Callable[[TrainEvent], None]]:
    """One bar per training stage; yields the callback for the training.

    Each event sets its stage's bar to ``step / total`` and shows the stage's
    key metrics (:data:`SHOWN_METRICS`). The bars show from the first event:
    an error or a warning before the training starts is a line of its own.
    """
    progress = Progress(*stage_columns("metrics"), console=console)
    tasks: dict[str, TaskID] = {}

    def update(event: TrainEvent) -> None:
        if not progress.live.is_started:
            progress.start()
        if event.stage not in tasks:
            label = STAGE_LABELS.get(event.stage, event.stage)
            tasks[event.stage] = progress.add_task(label, total=event.total, metrics="")
        metrics = " ".join(
            f"{name}={_number(event.metrics[name])}"
            for name in SHOWN_METRICS
            if name in event.metrics
        )
        progress.update(
            tasks[event.stage],
            completed=event.step,
            total=event.total,
            metrics=escape(metrics),
        )

    try:
        yield update
    finally:
        if progress.live.is_started:
            progress.stop()


def _print_selection(selection: dict) -> None:
    """Each candidate's validation crashes, and the one kept."""
    table = compact_table(
        "Candidates: crashes on their own validation windows",
        caption="Replays of the closed-loop stage's validation windows, xi ~ P0; "
        "kept: the fewest crashes with the leaders braking 1.5x as hard.",
    )
    names = (
        "seed",
        "replays",
        "crashes,\nleaders x1.5",
        "windows\nwith one",
        "crashes,\nas recorded",
        "",
    )
    add_columns(table, names, text=("",))
    for c in selection["candidates"]:
        table.add_row(
            str(c["seed"]),
            f"{c['replays']:,}",
            str(c["stressed_crashes"]),
            str(c["stressed_windows"]),
            str(c["crashes"]),
            "kept" if c["seed"] == selection["chosen_seed"] else "",
        )
    out_console.print(table)


def _number(value: float) -> str:
    """Counts with thousands separators, other values to 4 significant digits."""
    return f"{value:,.0f}" if float(value).is_integer() else f"{value:.4g}"


def _size(n_bytes: int) -> str:
    return f"{n_bytes / 1024:,.0f} kB" if n_bytes >= 1024 else f"{n_bytes} B"


def train_drivers_command(
    seed: Annotated[int, typer.Option(min=0, help="Seeds the whole training.")] = 0,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            help="Folder for driver_net.npz, xi_prior.npz and training_report.json "
            "(created; files of those names are replaced).",
        ),
    ] = DEFAULT_OUT,
    data_dir: Annotated[
        Path | None,
        typer.Option(
            "--data-dir",
            help="NGSIM folder (packed or original files); default "
            "$AVRISK_NGSIM_DIR, else the data shipped with avrisk.",
        ),
    ] = None,
    candidates: Annotated[
        int,
        typer.Option(
            min=1,
            help="Trainings with seeds SEED, SEED+1, ...: each is written to "
            "OUT/candidates/seed-S and the one whose drivers crash least on their "
            "own validation windows (training data only) is copied to OUT. Each "
            "takes as long as one training.",
        ),
    ] = 1,
    workers: Annotated[
        int,
        typer.Option(
            min=1,
            help="With --candidates: train this many at once, in worker "
            "processes of one CPU each (the same files as one after the other).",
        ),
    ] = 1,
    brake_guard: Annotated[
        str | None,
        typer.Option(
            "--brake-guard",
            metavar="GAP,DECEL[,hold]|none",
            help="The emergency brake written with the weights, which the "
            "scenarios' traffic, avrisk realism and the closed loop's "
            "minibatches drive with: brake where the vehicle ahead needs more "
            "than DECEL [m/s^2] to stop the closing GAP [m] short of it "
            "(',hold': also whenever closing inside GAP); 'none' for no brake "
            "(the closed loop then trains the network alone). Default: 2,2,hold.",
        ),
    ] = None,
    period: Annotated[
        list[str] | None,
        typer.Option(
            "--period",
            metavar="PERIOD",
            help="Train on this I-80 recording period only (repeatable; e.g. "
            "0400pm-0415pm or 0500pm-0515pm), for leave-one-period-out "
            "validation with avrisk realism --held-out; default every period. "
            "The lateral file (16:00-16:15) is read only with its period.",
        ),
    ] = None,
    head: Annotated[
        str,
        typer.Option(
            "--head",
            metavar="free|idm",
            help="The network's acceleration head: 'free' (the shipped drivers': "
            "the network outputs the acceleration) or 'idm' (the network sets "
            "the gap a driver keeps, the IDM's law the acceleration).",
        ),
    ] = "free",
) -> None:
    """Retrain the learned drivers and their xi prior from NGSIM data.

    The bundled scenarios keep using the shipped model in avrisk/data/drivers
    unless --out names that folder. Trainings that differ only in their seed
    crash very differently; --candidates N trains N and keeps the safest.
    """
    with user_errors(OSError):
        with training_progress(err_console) as progress:
            trained = retrain_drivers(
                out,
                seed=seed,
                data_dir=data_dir,
                brake_guard=brake_guard,
                periods=period,
                head=head,
                candidates=candidates,
                workers=workers,
                progress=progress,
            )
        if trained.selection is not None:
            _print_selection(trained.selection)
        show_written(trained)


def show_written(trained: TrainedFiles) -> None:
    """The files a training wrote, each with its size, and where."""
    written = ", ".join(f"{p.name} ({_size(p.stat().st_size)})" for p in trained.files)
    out_console.print(
        f"wrote {escape(written)} to {escape(str(trained.folder))}", highlight=False
    )
