"""A user's own backend, in one module: importing it registers ``serial``.

A backend opens an evaluator of the run's chunks for the length of a run
(:mod:`avrisk.api.backends`): here this process, chunk by chunk, with a log
of when it was opened and closed, so that a test can see the run used it.
"""

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from avrisk.api.backends import register_backend
from avrisk.rare.evaluation import LocalEvaluator

#: ``("opened", workers, address)`` and ``("closed",)``, in order.
CALLS: list[tuple[Any, ...]] = []


@contextmanager
def serial(objective: Any, workers: int, address: str | None) -> Iterator[Any]:
    """This process evaluates the chunks (``workers`` and ``address`` logged)."""
    CALLS.append(("opened", workers, address))
    yield LocalEvaluator()
    CALLS.append(("closed",))


register_backend("serial", serial, description="this process, chunk by chunk")
