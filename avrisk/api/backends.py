"""Where the rollouts are simulated: backends registered by name.

``local`` (the default) simulates in this process, or with ``workers=N`` in
N local worker processes; ``ray`` sends the chunks to a Ray cluster
(``address``, or a local one). Every worker builds the simulator from the
run's resolved scenario, sent as data (:func:`worker_factory`); the estimate
is the same bit for bit on every backend.

A backend is an *opener*, registered with :func:`register_backend`: called
with the objective (a scenario's, or an A/B comparison's
:class:`~avrisk.assembly.paired.PairedObjective`, whose workers build both
egos) and the command's ``workers`` and ``address``, it returns
a context manager that yields the :class:`~avrisk.rare.evaluation.Evaluator`
(None: this process) and closes it on exit. The command line's ``--backend``
offers the registered names. Its errors name the command's options
(``--backend``, ``--address``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from typing import TYPE_CHECKING

from avrisk.api.errors import UserError
from avrisk.rare.evaluation import Evaluator
from avrisk.rare.parallel import Factory, ProcessPoolEvaluator
from avrisk.rare.ray_evaluator import RayEvaluator
from avrisk.registry import Registry

if TYPE_CHECKING:  # the simulator (torch) is loaded by the command that runs
    from avrisk.assembly import SimulationObjective
    from avrisk.assembly.paired import PairedObjective

    #: What a backend simulates: a scenario's objective, or an A/B comparison's.
    Objective = SimulationObjective | PairedObjective

#: ``opener(objective, workers, address)``: yields the evaluator (None: this
#: process) and closes it on exit.
Opener = Callable[
    ["Objective", int | None, str | None],
    AbstractContextManager[Evaluator | None],
]

#: The backend of a run that names none.
DEFAULT_BACKEND = "local"

#: The backends by name, extended by ``register_backend(name, opener, *,
#: description)`` (:class:`~avrisk.registry.Registry`; ``description`` says
#: where it simulates, for ``--help``: ``"this machine"``).
BACKENDS = Registry("backend")
register_backend = BACKENDS.register
backend_descriptions = BACKENDS.descriptions


def open_evaluator(
    objective: Objective,
    backend: str,
    workers: int | None,
    address: str | None,
) -> AbstractContextManager[Evaluator | None]:
    """The evaluator of the backend ``backend`` (None: this process), closed after.

    Raises
    ------
    UnknownComponentError
        If no backend is registered as ``backend``; the message lists them.
    """
    return BACKENDS.get(backend)(objective, workers, address)


def worker_factory(objective: Objective) -> Factory:
    """What a worker builds ``objective`` from: its resolved scenario(s), as data.

    A scenario's objective is built again as it is
    (:class:`~avrisk.assembly.ObjectiveFactory`); a paired one as the
    ``min(f_A, f_B)`` box its run evaluates
    (:class:`~avrisk.assembly.paired.PairedFactory`). The workers may import
    the components the scenarios name: they were given by the caller, not
    read back from a run directory.
    """
    from avrisk.assembly import ObjectiveFactory
    from avrisk.assembly.paired import PairedFactory, PairedObjective

    if isinstance(objective, PairedObjective):
        return PairedFactory.of(objective, allow_import=True)
    return ObjectiveFactory.of(objective, allow_import=True)


@contextmanager
def _local(
    objective: Objective, workers: int | None, address: str | None
) -> Iterator[Evaluator | None]:
    """In this process, or in ``workers`` worker processes on this machine.

    In this process, with as many torch threads as cores are idle when the
    run starts (:func:`~avrisk.assembly.threads.threads_fitted_to_load`:
    threads spinning beside other processes' work waste the machine).
    """
    if address is not None:
        raise UserError("--address joins a Ray cluster: add --backend ray")
    if workers is None:
        from avrisk.assembly.threads import threads_fitted_to_load

        with threads_fitted_to_load():
            yield None
        return
    with ProcessPoolEvaluator(worker_factory(objective), workers or 1) as evaluator:
        yield evaluator


@contextmanager
def _ray(
    objective: Objective, workers: int | None, address: str | None
) -> Iterator[Evaluator | None]:
    """A Ray cluster: ``address``, else the one joined already or a new local one.

    A worker takes a GPU where the objective simulates on one.
    """
    factory = worker_factory(objective)
    try:
        evaluator = RayEvaluator(
            factory,
            workers,
            address=address,
            num_gpus=1 if objective.device.startswith("cuda") else 0,
        )
    except ImportError as err:
        raise UserError(str(err)) from None
    except ConnectionError as err:
        raise UserError(f"cannot join the Ray cluster at {address}: {err}") from None
    with evaluator:
        yield evaluator


register_backend(DEFAULT_BACKEND, _local, description="this machine")
register_backend("ray", _ray, description="a Ray cluster; pip install 'avrisk[ray]'")
