"""Where the rollouts are simulated: this process, worker processes or Ray.

By default in this process. ``workers=N`` spawns N local worker processes;
the ``ray`` backend sends the chunks to a Ray cluster (``address``, or a
local one). Every worker builds the simulator from the run's resolved
scenario, sent as data (:class:`avrisk.assembly.ObjectiveFactory`); the
estimate is the same bit for bit on every backend.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from enum import StrEnum
from typing import TYPE_CHECKING

from avrisk.api.errors import UserError
from avrisk.rare.evaluation import Evaluator
from avrisk.rare.parallel import ProcessPoolEvaluator
from avrisk.rare.ray_evaluator import RayEvaluator

if TYPE_CHECKING:  # the simulator (torch) is loaded by the command that runs
    from avrisk.assembly import ObjectiveFactory, SimulationObjective


class Backend(StrEnum):
    """Where worker processes run."""

    local = "local"
    ray = "ray"


@contextmanager
def open_evaluator(
    objective: SimulationObjective,
    backend: Backend,
    workers: int | None,
    address: str | None,
) -> Iterator[Evaluator | None]:
    """The evaluator asked for (None: this process), closed after.

    The workers rebuild ``objective`` (whose scenario was given by the caller,
    so they may import the components it names). The messages name the
    command's options (``--backend``, ``--address``).
    """
    if address is not None and backend != Backend.ray:
        raise UserError("--address joins a Ray cluster: add --backend ray")
    if backend == Backend.local and workers is None:
        yield None
        return
    from avrisk.assembly import ObjectiveFactory

    factory = ObjectiveFactory.of(objective, allow_import=True)
    evaluator: ProcessPoolEvaluator | RayEvaluator
    if backend == Backend.local:
        evaluator = ProcessPoolEvaluator(factory, workers or 1)
    else:
        evaluator = _ray_evaluator(factory, workers, address, objective.device)
    with evaluator:
        yield evaluator


def _ray_evaluator(
    factory: ObjectiveFactory, workers: int | None, address: str | None, device: str
) -> RayEvaluator:
    try:
        return RayEvaluator(
            factory,
            workers,
            address=address,
            num_gpus=1 if device.startswith("cuda") else 0,
        )
    except ImportError as err:
        raise UserError(str(err)) from None
    except ConnectionError as err:
        raise UserError(f"cannot join the Ray cluster at {address}: {err}") from None
