"""``avrisk train-vision``: retrain the vision ego's PilotNet on rendered images.

Runs :func:`avrisk.api.training.retrain_vision` (behaviour cloning of the
lidar ego's steering on camera images of ``highway_vision``, then DAgger
rounds; minutes on one core, as ``avrisk/data/vision/SOURCE.md`` records for
the shipped weights) with one torch thread, so that the same seed and
machine give the same weights, and writes into ``--out``::

    pilotnet.npz            PilotNet weights (avrisk.agents.vision.PilotNet)
    training_report.json    held-out steering error, closed-loop lane keeping

The shipped weights (``avrisk/data/vision/``, which ``vision_pilotnet`` uses)
are replaced only when ``--out`` names that folder.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from avrisk.api.training import retrain_vision
from avrisk.cli.common import err_console, user_errors
from avrisk.cli.train_drivers import show_written, training_progress

#: Where ``train-vision`` writes by default (not the shipped weights).
DEFAULT_OUT = Path("runs") / "vision"


def train_vision_command(
    seed: Annotated[int, typer.Option(min=0, help="Seeds the whole training.")] = 0,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            help="Folder for pilotnet.npz and training_report.json (created; "
            "files of those names are replaced).",
        ),
    ] = DEFAULT_OUT,
) -> None:
    """Retrain the vision ego's PilotNet by imitation of the lidar ego (DAgger).

    The vision_pilotnet ego keeps using the shipped weights in
    avrisk/data/vision unless --out names that folder.
    """
    with user_errors(OSError):
        with training_progress(err_console) as progress:
            trained = retrain_vision(out, seed=seed, progress=progress)
        show_written(trained)
