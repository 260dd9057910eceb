"""The realism report of a driver model, as ``avrisk realism`` writes it.

:func:`realism_report` checks the driver files and the settings, runs both
parts of :mod:`avrisk.realism` (part A, car following on held-out NGSIM I-80
windows; part B, lane changes against held-out US-101 vehicles) and writes
``realism.md``, ``realism.json`` and the two figures. It prints nothing:
each part's progress goes to a callback, and drivers trained on the windows
meant to be held out raise a :class:`NotHeldOutWarning`.
"""

from __future__ import annotations

import json
import time
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from avrisk.api.errors import UserError

if TYPE_CHECKING:
    from avrisk.agents.drivers.guard import BrakeGuard
    from avrisk.realism import DriverFiles, RealismResult

__all__ = ["NotHeldOutWarning", "RealismRun", "realism_report"]

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


class NotHeldOutWarning(UserWarning):
    """The drivers were trained on the recording period part A holds out."""


@dataclass(frozen=True)
class RealismRun:
    """A realism report, and the files written.

    Attributes
    ----------
    result : RealismResult
        Both parts' figures and issue 21's targets
        (:class:`avrisk.realism.RealismResult`).
    files : list of pathlib.Path
        ``realism.md``, ``realism.json`` and the figures, in ``out``.
    wall_s : float
        Wall-clock time of the two parts and the writing [s].
    """

    result: RealismResult
    files: list[Path]
    wall_s: float


def realism_report(
    out: str | Path,
    *,
    drivers: str | Path | None = None,
    replicates: int = 24,
    scenes: int = 256,
    windows: int | None = None,
    seed: int = 2024,
    threads: int = 1,
    brake_guard: str | None = None,
    held_out: str = "test",
    command: str = "avrisk.api.realism.realism_report",
    progress_a: Callable[[str, int, int], None] | None = None,
    progress_b: Callable[[str, int, int], None] | None = None,
) -> RealismRun:
    """Compare a driver model with held-out human driving; write the report.

    Parameters
    ----------
    out : str or Path
        The folder of ``realism.md``, ``realism.json`` and the figures
        (created; files of those names replaced).
    drivers : str or Path, optional
        Folder holding ``driver_net.npz`` and ``xi_prior.npz`` (as
        :func:`avrisk.api.training.retrain_drivers` writes them); default the
        shipped drivers.
    replicates : int, default=24
        Replays of every held-out I-80 window per model in part A.
    scenes : int, default=256
        Six-lane scenes per model in part B.
    windows : int, optional
        Evaluate only this many held-out windows, drawn with ``seed``;
        default all.
    seed : int, default=2024
        Part A's seed; part B uses ``seed + 1``.
    threads : int, default=1
        torch's CPU threads, set for the rest of the process; with one, the
        same settings give the same figures on a machine.
    brake_guard : str, optional
        The drivers' emergency brake, ``"GAP,DECEL[,hold]"`` or ``"none"``
        (:func:`avrisk.agents.drivers.guard.parse_guard`); default the one
        their weights carry.
    held_out : str, default="test"
        Part A's held-out windows: ``"test"`` (every period's test split) or a
        recording period, all of it (for drivers trained on the others).
    command : str
        The command or call that made the report, recorded in both files.
    progress_a, progress_b : callable, optional
        ``progress(model, done, total)`` of each part.

    Raises
    ------
    UserError
        For a brake, a held-out choice or driver files that cannot be used.
    OSError
        For files that cannot be read or written meanwhile.
    """
    guard = _brake_guard(brake_guard)
    _check_held_out(held_out)
    files = driver_files(None if drivers is None else Path(drivers))
    _warn_trained_on(files, held_out)
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
    result = run_realism(files, settings, progress_a, progress_b)
    written = write_report(result, Path(out), command)
    return RealismRun(result, written, time.perf_counter() - t0)


def driver_files(folder: Path | None) -> DriverFiles:
    """The driver model to evaluate, each file read once to check it.

    Raises
    ------
    UserError
        For a missing folder or file, or a file that is not what it should be.
    """
    from avrisk.agents.drivers.store import load_driver_net, load_xi_prior
    from avrisk.realism import DriverFiles

    if folder is not None and not folder.is_dir():
        raise UserError(f"--drivers {folder}: no such folder")
    files = DriverFiles.in_folder(folder)
    for path, load, what in (
        (files.net, load_driver_net, "a driver network"),
        (files.prior, load_xi_prior, "an xi prior"),
    ):
        if not path.is_file():
            raise UserError(
                f"--drivers {folder}: lacks {path.name} (avrisk train-drivers "
                "writes driver_net.npz and xi_prior.npz)"
            )
        try:
            load(path)
        except _UNREADABLE as exc:
            reason = str(exc).splitlines()[0][:200] if str(exc) else ""
            raise UserError(
                f"--drivers {path}: not {what} ({reason or type(exc).__name__})"
            ) from None
    return files


def _check_held_out(held_out: str) -> None:
    """Raise UserError for a ``held_out`` that is not a held-out set."""
    from avrisk.realism.held_out import (
        HELD_OUT_TEST,
        held_out_period,
        held_out_periods,
    )

    try:
        held_out_period(held_out)
    except ValueError:
        periods = held_out_periods()
        raise UserError(
            f"--held-out {held_out}: not a held-out set: {HELD_OUT_TEST}, a "
            f"period ({', '.join(periods)}) or a period's test split (e.g. "
            f"{periods[0]}:{HELD_OUT_TEST})"
        ) from None


def _warn_trained_on(files: DriverFiles, held_out: str) -> None:
    """Warn when the drivers' training report says they trained on ``held_out``."""
    from avrisk.realism.held_out import held_out_period

    period, test_only = held_out_period(held_out)
    if test_only:  # no training reads a test split
        return
    report = files.net.parent / "training_report.json"
    try:
        periods = json.loads(report.read_text())["config"].get("periods")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        periods = None  # no report: all periods, as the shipped drivers
    if periods is None or period in periods:
        warnings.warn(
            f"these drivers were trained on {held_out} (its train split): part A "
            "is not held out",
            NotHeldOutWarning,
            stacklevel=3,
        )


def _brake_guard(text: str | None) -> BrakeGuard | Literal["drivers"] | None:
    """The drivers' own brake (None), no brake ("none"), or GAP,DECEL[,hold]."""
    from avrisk.agents.drivers.guard import parse_guard
    from avrisk.realism.report import DRIVERS_GUARD

    if text is None:
        return DRIVERS_GUARD
    try:
        return parse_guard(text)
    except ValueError as exc:
        raise UserError(str(exc)) from None
