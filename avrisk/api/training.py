"""Retraining the learned drivers and the vision ego, as ``avrisk train-*`` do.

:func:`retrain_drivers` checks what minutes of training would trip on (the
brake, the NGSIM files, the periods, the output folder) and then runs
:func:`avrisk.learning.training.train.train_drivers`; :func:`retrain_vision`
runs :func:`avrisk.learning.vision.train_vision`. Both train with one torch
thread, so that the same seed and machine give the same files, and print
nothing: progress goes to a callback of
:class:`~avrisk.learning.train_config.TrainEvent` and what the caller should
know goes out as a warning (:class:`ShippedFilesWarning` when ``out`` is the
folder of the files shipped with avrisk, which are then replaced;
:class:`OtherKernelsWarning` when this machine cannot repeat the shipped
drivers byte for byte).
"""

from __future__ import annotations

import json
import os
import tempfile
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow as pa

from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    default_drivers_dir,
)
from avrisk.agents.vision.store import PILOTNET_FILE, default_vision_dir
from avrisk.api.errors import UserError
from avrisk.learning.ngsim.files import I80_LATERAL, I80_PAIRS, ngsim_dir, ngsim_file

if TYPE_CHECKING:
    from avrisk.learning.train_config import Progress, TrainConfig

__all__ = [
    "OtherKernelsWarning",
    "ShippedFilesWarning",
    "TrainedFiles",
    "retrain_drivers",
    "retrain_vision",
    "training_config",
]


class ShippedFilesWarning(UserWarning):
    """The training writes over files shipped with avrisk (``out`` is their folder)."""


class OtherKernelsWarning(UserWarning):
    """The CPU kernels here are not those that trained the shipped drivers."""


@dataclass(frozen=True)
class TrainedFiles:
    """What a training wrote.

    Attributes
    ----------
    folder : pathlib.Path
        The ``out`` folder.
    files : tuple of pathlib.Path
        The files written there, the model's first, the training report last.
    report : TrainingReport or dict
        The training report (:class:`~avrisk.learning.training.report.TrainingReport`
        of the drivers, the vision training's dict), as written.
    selection : dict or None
        Of the drivers trained as several candidates: each candidate's
        validation crashes and the seed kept (``candidates``,
        ``chosen_seed``); None otherwise.
    """

    folder: Path
    files: tuple[Path, ...]
    report: Any
    selection: dict[str, Any] | None = None


def retrain_drivers(
    out: str | Path,
    *,
    seed: int = 0,
    data_dir: str | Path | None = None,
    brake_guard: str | None = None,
    periods: list[str] | tuple[str, ...] | None = None,
    head: str = "free",
    candidates: int = 1,
    workers: int = 1,
    progress: Progress | None = None,
) -> TrainedFiles:
    """Retrain the learned drivers and their ``xi`` prior from NGSIM data.

    Writes ``driver_net.npz``, ``xi_prior.npz`` and ``training_report.json``
    into ``out`` (created; files of those names replaced). Every input is
    checked, and ``out`` written to once, before the training starts.

    Parameters
    ----------
    out : str or Path
        The folder to write; the shipped drivers' folder replaces them (with a
        :class:`ShippedFilesWarning`).
    seed : int, default=0
        Seeds the whole training (of the first candidate).
    data_dir : str or Path, optional
        NGSIM folder (packed or original files); default ``$AVRISK_NGSIM_DIR``,
        else the data shipped with avrisk.
    brake_guard, periods, head
        The recipe's changes (:func:`training_config`).
    candidates, workers : int, default=1
        Trainings with seeds ``seed, seed + 1, ...`` (each written to
        ``out/candidates/seed-S``, the one whose drivers crash least on their
        own validation windows copied to ``out``), ``workers`` at a time.
    progress : callable, optional
        Called with every :class:`~avrisk.learning.train_config.TrainEvent`.

    Raises
    ------
    UserError
        For a brake, a period, a head, NGSIM files or an ``out`` that cannot
        be used.
    OSError
        For files that cannot be read or written during the training.
    """
    config = _as_user_error(training_config, brake_guard, periods, head)
    folder = _data_folder(data_dir)
    _as_user_error(_check_periods, folder, config.periods)
    out = _writable_folder(Path(out))
    if os.path.samefile(out, default_drivers_dir()):
        _warn_shipped("replacing the shipped driver model in", out)
    # Imported here: training pulls in scikit-learn, which little else needs.
    from avrisk.learning.training import train
    from avrisk.learning.training.report import TRAINING_REPORT_FILE

    _warn_other_kernels()
    report = train.train_drivers(
        seed,
        out,
        data_dir=folder,
        config=config,
        progress=progress,
        candidates=candidates,
        workers=workers,
    )
    names = (DRIVER_NET_FILE, XI_PRIOR_FILE, TRAINING_REPORT_FILE)
    files = tuple(out / name for name in names)
    return TrainedFiles(out, files, report, report.selection)


def retrain_vision(
    out: str | Path, *, seed: int = 0, progress: Progress | None = None
) -> TrainedFiles:
    """Retrain the vision ego's PilotNet by imitation of the lidar ego (DAgger).

    Writes ``pilotnet.npz`` and ``training_report.json`` into ``out``
    (created; files of those names replaced); the shipped weights' folder
    replaces them (with a :class:`ShippedFilesWarning`). ``seed`` seeds the
    whole training; ``progress`` is called with every
    :class:`~avrisk.learning.train_config.TrainEvent`.

    Raises
    ------
    UserError
        For an ``out`` that cannot be written.
    """
    out = _writable_folder(Path(out))
    shipped = default_vision_dir()
    if shipped.is_dir() and os.path.samefile(out, shipped):
        _warn_shipped("replacing the shipped PilotNet in", out)
    from avrisk.learning.vision import REPORT_FILE, train_vision

    report = train_vision(seed, out, progress=progress)
    return TrainedFiles(out, (out / PILOTNET_FILE, out / REPORT_FILE), report)


def training_config(
    brake_guard: str | None = None,
    periods: list[str] | tuple[str, ...] | None = None,
    head: str = "free",
) -> TrainConfig:
    """The shipped drivers' recipe, with another brake, periods or head if given.

    Parameters
    ----------
    brake_guard : str, optional
        The emergency brake written with the weights, which the closed loop
        also drives with: ``"GAP,DECEL[,hold]"`` or ``"none"`` (the closed
        loop then trains the network alone); default the recipe's.
    periods : sequence of str, optional
        I-80 recording periods to train on (``"0400pm-0415pm"``); default all.
    head : {"free", "idm"}, default="free"
        The network's acceleration head (``TrainConfig.head``): the shipped
        drivers' free one, or the IDM's law with the gap the network sets
        (:mod:`avrisk.agents.drivers.idm_head`).

    Raises
    ------
    ValueError
        For a brake that is not one (:func:`avrisk.agents.drivers.guard.parse_guard`)
        or an unknown head.
    """
    from dataclasses import replace

    from avrisk.agents.drivers.guard import parse_guard
    from avrisk.learning.train_config import TrainConfig

    default = TrainConfig(periods=tuple(periods) if periods else None, head=head)
    if brake_guard is None:
        return default
    guard = parse_guard(brake_guard)
    closed_loop = replace(default.closed_loop, drive_with_guard=guard is not None)
    return replace(default, guard=guard, closed_loop=closed_loop)


def _as_user_error(check: Any, *args: Any) -> Any:
    """``check(*args)``, its ValueError a UserError of the same sentence."""
    try:
        return check(*args)
    except ValueError as exc:
        raise UserError(str(exc)) from None


def _data_folder(data_dir: str | Path | None) -> Path:
    """The NGSIM folder to train on, checked to hold the files training reads.

    Each file is read once here, before minutes of training: a garbage
    Parquet or gzip file, or one with missing or mistyped columns, is one
    UserError naming the file.
    """
    from avrisk.learning.ngsim.loaders import load_i80_lateral, load_i80_pairs

    try:
        files = [ngsim_file(names, data_dir) for names in (I80_PAIRS, I80_LATERAL)]
    except FileNotFoundError as exc:
        raise UserError(f"{exc} (--data-dir)") from None
    for path, load in zip(files, (load_i80_pairs, load_i80_lateral), strict=True):
        try:
            load(path)
        except (pa.ArrowException, OSError, EOFError, zlib.error) as exc:
            raise UserError(_unreadable(path, exc, "not readable")) from None
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            raise UserError(_unreadable(path, exc, "not NGSIM data")) from None
    return ngsim_dir(data_dir)


def _unreadable(path: Path, exc: BaseException, what: str) -> str:
    reason = str(exc).replace(f"{path} ", "").splitlines()[0] if str(exc) else ""
    reason = reason or type(exc).__name__
    if len(reason) > 200:
        reason = reason[:200] + "..."
    return f"--data-dir: {path}: {what} ({reason}); see SOURCE.md for its format"


def _check_periods(folder: Path, periods: tuple[str, ...] | None) -> None:
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


def _writable_folder(out: Path) -> Path:
    """``out``, created and written to once, before minutes of training."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise UserError(f"cannot write to --out {out}: {reason}") from None
    return out


def _warn_shipped(what: str, out: Path) -> None:
    warnings.warn(f"{what} {out}", ShippedFilesWarning, stacklevel=3)


def _warn_other_kernels() -> None:
    """Warn when this machine's CPU kernels are not the shipped files'.

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
    warnings.warn(
        f"CPU kernels here (torch {here['torch']}, BLAS "
        f"{', '.join(here['blas'])}) differ from those that trained the shipped "
        f"files (torch {theirs['torch']}, BLAS {', '.join(theirs['blas'])}): "
        "this run is a training like theirs, not a byte-for-byte copy. To "
        f"reproduce them on an x86-64 CPU with AVX2, run with {pins} set.",
        OtherKernelsWarning,
        stacklevel=3,
    )
