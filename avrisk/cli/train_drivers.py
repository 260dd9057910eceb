"""``avrisk train-drivers``: retrain the learned drivers and their ``xi`` prior.

Runs :func:`avrisk.learning.training.train.train_drivers` on the NGSIM I-80 data
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

import json
import os
import tempfile
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import pyarrow as pa
import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import Progress, TaskID

from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    default_drivers_dir,
)
from avrisk.cli.common import CliError, err_console, out_console, user_errors
from avrisk.cli.progress import stage_columns
from avrisk.cli.tables import add_columns, compact_table
from avrisk.learning.ngsim.files import I80_LATERAL, I80_PAIRS, ngsim_dir, ngsim_file

if TYPE_CHECKING:
    from avrisk.learning.train_config import TrainConfig, TrainEvent

#: Where ``train-drivers`` writes by default (not the shipped model).
DEFAULT_OUT = Path("runs") / "drivers"

#: What :func:`avrisk.learning.training.train.train_drivers` writes.
OUTPUT_FILES = (DRIVER_NET_FILE, XI_PRIOR_FILE, "training_report.json")

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
    """One bar per training stage; yields the callback for ``train_drivers``.

    Each event sets its stage's bar to ``step / total`` and shows the stage's
    key metrics (:data:`SHOWN_METRICS`).
    """
    with Progress(*stage_columns("metrics"), console=console) as progress:
        tasks: dict[str, TaskID] = {}

        def update(event: TrainEvent) -> None:
            if event.stage not in tasks:
                label = STAGE_LABELS.get(event.stage, event.stage)
                tasks[event.stage] = progress.add_task(
                    label, total=event.total, metrics=""
                )
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

        yield update


def _data_folder(data_dir: Path | None) -> Path:
    """The NGSIM folder to train on, checked to hold the files training reads.

    Each file is read once here, before minutes of training: a garbage
    Parquet or gzip file, or one with missing or mistyped columns, is one
    CliError naming the file.
    """
    from avrisk.learning.ngsim.loaders import load_i80_lateral, load_i80_pairs

    try:
        files = [ngsim_file(names, data_dir) for names in (I80_PAIRS, I80_LATERAL)]
    except FileNotFoundError as exc:
        raise CliError(f"{exc} (--data-dir)") from None
    for path, load in zip(files, (load_i80_pairs, load_i80_lateral), strict=True):
        try:
            load(path)
        except (pa.ArrowException, OSError, EOFError, zlib.error) as exc:
            raise CliError(_unreadable(path, exc, "not readable")) from None
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            raise CliError(_unreadable(path, exc, "not NGSIM data")) from None
    return ngsim_dir(data_dir)


def _unreadable(path: Path, exc: BaseException, what: str) -> str:
    reason = str(exc).replace(f"{path} ", "").splitlines()[0] if str(exc) else ""
    reason = reason or type(exc).__name__
    if len(reason) > 200:
        reason = reason[:200] + "..."
    return f"--data-dir: {path}: {what} ({reason}); see SOURCE.md for its format"


def _check_writable(out: Path) -> None:
    """Create ``out`` and write a scratch file there, before minutes of training."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise CliError(f"cannot write to --out {out}: {reason}") from None


def _warn_other_kernels() -> None:
    """Say so when this machine's CPU kernels are not the shipped files'.

    The shipped ``training_report.json`` records the kernels that trained
    them; with others the run is a training like theirs, not their copy.
    """
    from avrisk.learning.training.report import (
        KERNEL_PINS,
        TRAINING_REPORT_FILE,
        cpu_kernels,
    )

    shipped = json.loads((default_drivers_dir() / TRAINING_REPORT_FILE).read_text())
    theirs = shipped["environment"].get("cpu_kernels")
    here = cpu_kernels()
    if theirs is None or here == theirs:
        return
    pins = " ".join(f"{k}={v}" for k, v in KERNEL_PINS.items())
    err_console.print(
        f"[yellow]warning:[/] CPU kernels here (torch {here['torch']}, BLAS "
        f"{', '.join(here['blas'])}) differ from those that trained the shipped "
        f"files (torch {theirs['torch']}, BLAS {', '.join(theirs['blas'])}): "
        "this run is a training like theirs, not a byte-for-byte copy. To "
        f"reproduce them on an x86-64 CPU with AVX2, run with {pins} set.",
        highlight=False,
    )


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


def _config(brake_guard: str | None, periods: list[str] | None = None) -> TrainConfig:
    """The default recipe, with ``--brake-guard``'s brake and ``--period`` if given.

    Without a brake the closed loop trains the network alone.
    """
    from dataclasses import replace

    from avrisk.agents.drivers.guard import parse_guard
    from avrisk.learning.train_config import TrainConfig

    default = TrainConfig(periods=tuple(periods) if periods else None)
    if brake_guard is None:
        return default
    guard = parse_guard(brake_guard)
    closed_loop = replace(default.closed_loop, drive_with_guard=guard is not None)
    return replace(default, guard=guard, closed_loop=closed_loop)


def _check_periods(folder: Path | None, periods: tuple[str, ...] | None) -> None:
    """Raise ValueError, naming those there are, for a period the data lack."""
    if periods is None:
        return
    from avrisk.learning.training.data import available_periods

    there = available_periods(folder)
    unknown = sorted(set(periods) - set(there))
    if unknown:
        raise ValueError(
            f"--period {', '.join(unknown)}: the I-80 data hold {', '.join(there)}"
        )


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
) -> None:
    """Retrain the learned drivers and their xi prior from NGSIM data.

    The bundled scenarios keep using the shipped model in avrisk/data/drivers
    unless --out names that folder. Trainings that differ only in their seed
    crash very differently; --candidates N trains N and keeps the safest.
    """
    with user_errors(ValueError):
        config = _config(brake_guard, period)
    with user_errors(OSError):
        folder = _data_folder(data_dir)
        with user_errors(ValueError):
            _check_periods(folder, config.periods)
        _check_writable(out)
        if os.path.samefile(out, default_drivers_dir()):
            err_console.print(
                f"[yellow]warning:[/] replacing the shipped driver model in "
                f"{escape(str(out))}",
                highlight=False,
            )
        # Imported here: training pulls in scikit-learn, which no other
        # command needs at start-up.
        from avrisk.learning.training import train

        _warn_other_kernels()
        with training_progress(err_console) as progress:
            report = train.train_drivers(
                seed,
                out,
                data_dir=folder,
                config=config,
                progress=progress,
                candidates=candidates,
                workers=workers,
            )
        if report.selection is not None:
            _print_selection(report.selection)
        written = ", ".join(
            f"{name} ({_size((out / name).stat().st_size)})" for name in OUTPUT_FILES
        )
        out_console.print(
            f"wrote {escape(written)} to {escape(str(out))}", highlight=False
        )
