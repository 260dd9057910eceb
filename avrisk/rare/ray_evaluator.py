"""Evaluating chunks on a Ray cluster (optional: ``pip install 'avrisk[ray]'``).

Each chunk is one Ray task asking for ``num_cpus`` CPUs (and ``num_gpus``
GPUs); a worker process builds ``f`` from the factory once and keeps it for
the tasks it runs after (:func:`avrisk.rare.parallel.worker_function`). A
worker that dies in the middle of a chunk (killed, its node lost) makes Ray
run that task again elsewhere, up to ``max_retries`` times: the chunk comes
back once, so no sample is lost or counted twice, and since a chunk's samples
and seeds depend only on ``(seed, stage, chunk)`` the estimate is the one a
local run gives.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from concurrent.futures import Future
from typing import Any

from avrisk.extras import needs_extra
from avrisk.rare.evaluation import EvalResult, EvalTask
from avrisk.rare.parallel import (
    Factory,
    Outputs,
    evaluate_in_worker,
    in_flight,
)
from avrisk.rare.problem import RareEventProblem, check_positive_int

__all__ = ["LOOPBACK_ONLY", "RayEvaluator", "import_ray"]

#: Environment of a local cluster whose servers listen on 127.0.0.1 only
#: (Ray's single-machine mode; read when ``ray`` is imported, and inherited by
#: the cluster's processes).
LOOPBACK_ONLY = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}


def import_ray(loopback_only: bool = False) -> Any:
    """The ``ray`` module, or an ImportError that says how to install it.

    ``loopback_only``: set :data:`LOOPBACK_ONLY` first (for a local cluster
    started next; only effective before ``ray`` is first imported).
    """
    if loopback_only:
        os.environ.update(LOOPBACK_ONLY)
    with needs_extra("ray", "the ray backend"):
        import ray
    return ray


class RayEvaluator:
    """Evaluate chunks as Ray tasks, at most ``workers`` at a time.

    Parameters
    ----------
    factory : callable
        Picklable; ``factory()`` builds ``f`` in a Ray worker (which must have
        avrisk, and whatever the factory reads, installed).
    workers : int, optional
        Chunks evaluated at the same time; default: the cluster's CPUs
        divided by ``num_cpus``.
    address : str, optional
        Cluster to join (``HOST:PORT`` or ``"auto"``). Default: the cluster
        this process is already connected to, else a new local one that
        listens on 127.0.0.1 only (stopped by :meth:`close`).
    num_cpus, num_gpus : float, default=1, 0
        Resources each task asks for.
    max_retries : int, default=3
        Times a chunk whose worker died is run again.
    """

    backend = "ray"

    def __init__(
        self,
        factory: Factory,
        workers: int | None = None,
        *,
        address: str | None = None,
        num_cpus: float = 1,
        num_gpus: float = 0,
        max_retries: int = 3,
    ) -> None:
        ray = import_ray(loopback_only=address is None)
        self._started = not ray.is_initialized()
        if self._started:
            local = {} if address else {"_node_ip_address": "127.0.0.1"}
            ray.init(address=address, include_dashboard=False, **local)
        self._ray = ray
        self.factory = ray.put(factory)
        if workers is None:
            workers = max(1, int(ray.cluster_resources().get("CPU", 1) // num_cpus))
        self.workers = check_positive_int("workers", workers)
        self._remote = ray.remote(evaluate_in_worker).options(
            num_cpus=num_cpus, num_gpus=num_gpus, max_retries=max_retries
        )

    def evaluate(
        self, problem: RareEventProblem, tasks: Iterable[EvalTask]
    ) -> Iterator[EvalResult]:
        """Results as the tasks finish (``problem.f`` is not used)."""

        def submit(task: EvalTask) -> Future[Outputs]:
            ref = self._remote.remote(
                self.factory, problem.batch_size, self.backend, task
            )
            return ref.future()  # type: ignore[no-any-return]

        crashed = (self._ray.exceptions.WorkerCrashedError,)
        yield from in_flight(submit, tasks, self.workers, crashed)

    def close(self) -> None:
        """Disconnect; stop the local cluster if this evaluator started it."""
        if self._started:
            self._ray.shutdown()
            self._started = False

    def __enter__(self) -> RayEvaluator:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
