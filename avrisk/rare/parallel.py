"""Evaluating chunks in worker processes: a local process pool (Ray: ``ray_evaluator``).

A worker never receives ``f`` itself (a simulator holds tensors, open files,
user code): it receives a *factory*, a small picklable callable without
arguments that builds ``f`` (e.g. from a scenario spec given as data). Each
worker process builds ``f`` once and keeps it for every chunk it evaluates.

Every chunk is evaluated exactly as :class:`~avrisk.rare.evaluation.
LocalEvaluator` would (same rows, same seeds, same ``batch_size`` cuts), and
the engine files the results by ``(stage, chunk)``; so the estimate is the
same bit for bit whatever the number of workers. The workers add one output,
:data:`EVALUATED_BY` (a string per sample: backend, host, process and device
that evaluated its chunk), which the run directory records like any other.

A worker that dies is never a silently wrong number: the process pool raises
:class:`WorkerError` naming the chunk (the chunks recorded so far are kept, so
rerunning resumes); Ray evaluates the lost chunk again elsewhere.

Ctrl-C is the parent's alone: the workers are started with SIGINT blocked
(a terminal sends it to every process of the command) and then ignore it, so
none of them prints a traceback; the parent raises KeyboardInterrupt, and a
pool left by an exception stops its workers at once rather than finishing
chunks whose results nobody will record (:meth:`ProcessPoolEvaluator.terminate`).
"""

from __future__ import annotations

import os
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from multiprocessing import get_context
from typing import Any

import numpy as np

from avrisk.rare.evaluation import EvalResult, EvalTask
from avrisk.rare.problem import (
    BatchFunction,
    RareEventProblem,
    check_positive_int,
    evaluate_batched,
)

__all__ = ["EVALUATED_BY", "ProcessPoolEvaluator", "WorkerError"]

#: Output column naming who evaluated a sample's chunk ("backend host pid device").
EVALUATED_BY = "evaluated_by"

#: Builds ``f`` in a worker process; must be picklable (and comparable with ==).
Factory = Callable[[], BatchFunction]

#: What a worker returns for a task: ``f``'s values (m,) and other outputs.
Outputs = tuple[np.ndarray, dict[str, np.ndarray]]

#: The ``f`` this process built, and the factory it came from.
_built: tuple[Factory, BatchFunction] | None = None


class WorkerError(RuntimeError):
    """A worker process died while evaluating a chunk."""


def worker_function(factory: Factory) -> BatchFunction:
    """``factory()``, built once per process (again only for another factory)."""
    global _built
    if _built is None or _built[0] != factory:
        _built = (factory, factory())
    return _built[1]


def evaluate_in_worker(
    factory: Factory, batch_size: int | None, backend: str, task: EvalTask
) -> Outputs:
    """Values (m,) and outputs of ``f`` on ``task``, plus :data:`EVALUATED_BY`.

    Runs in the worker; returns no copy of the task (the caller holds it).
    """
    f = worker_function(factory)
    values, extras = evaluate_batched(f, task.x, task.seeds, batch_size)
    device = getattr(f, "device", None)
    label = f"{backend} {socket.gethostname()} pid {os.getpid()}" + (
        f" {device}" if device is not None else ""
    )
    extras[EVALUATED_BY] = np.full(len(values), label)
    return values, extras


def in_flight(
    submit: Callable[[EvalTask], Future[Outputs]],
    tasks: Iterable[EvalTask],
    window: int,
    crashed: tuple[type[BaseException], ...],
) -> Iterator[EvalResult]:
    """Keep ``window`` tasks submitted; yield each result as soon as it is ready.

    Tasks are drawn from ``tasks`` only as room frees up (memory stays
    bounded); those still pending when the caller stops are cancelled. An
    exception of a type in ``crashed`` (a worker died) becomes a
    :class:`WorkerError` naming the chunk.
    """
    pending: dict[Future[Outputs], EvalTask] = {}
    todo = iter(tasks)
    try:
        while True:
            for task in todo:
                try:
                    pending[submit(task)] = task
                except crashed as err:  # the pool broke before this submission
                    if not pending:
                        raise _died(task, err) from err
                    break  # a pending chunk's result names the one that died
                if len(pending) >= window:
                    break
            if not pending:
                return
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                task = pending.pop(future)
                try:
                    values, extras = future.result()
                except crashed as err:
                    raise _died(task, err) from err
                yield EvalResult(task, values, extras)
    finally:
        for future in pending:
            future.cancel()


def _died(task: EvalTask, err: BaseException) -> WorkerError:
    """The error of a worker that died while ``task`` was under way."""
    return WorkerError(
        f"a worker died while evaluating chunk {task.chunk} of stage {task.stage} "
        f"({type(err).__name__}: {err}); the chunks recorded so far are kept: "
        "rerun to resume"
    )


def _start_worker(factory: Factory, parent: int) -> None:
    """Pool initializer: leave Ctrl-C to the parent, die with it, build ``f``.

    A factory that fails here fails again, with its own error, in the
    worker's first task (which the parent then raises).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with, args=(parent,), daemon=True).start()
    try:
        worker_function(factory)
    except Exception:  # raised again, with its type, by the first task
        pass


def _exit_with(parent: int) -> None:
    """Exit this worker once process ``parent`` is gone (e.g. ``kill -9``)."""
    while os.getppid() == parent:
        time.sleep(1.0)
    os._exit(1)


#: Seconds a terminated worker is given to exit before it is killed.
_DEATH_WAIT_S = 5.0


class ProcessPoolEvaluator:
    """Evaluate chunks in ``workers`` local processes, each with its own ``f``.

    The processes are spawned (never forked: a forked torch or thread pool is
    unsafe) on the first stage and kept until :meth:`close` (or the end of a
    ``with`` block); each builds ``f`` once with ``factory``.

    Parameters
    ----------
    factory : callable
        Picklable; ``factory()`` builds ``f`` in a worker.
    workers : int
        Worker processes, ``>= 1``.

    """

    backend = "processes"

    def __init__(self, factory: Factory, workers: int) -> None:
        self.factory = factory
        self.workers = check_positive_int("workers", workers)
        self._pool: ProcessPoolExecutor | None = None

    def evaluate(
        self, problem: RareEventProblem, tasks: Iterable[EvalTask]
    ) -> Iterator[EvalResult]:
        """Results as the workers finish them (``problem.f`` is not used)."""
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                self.workers,
                mp_context=get_context("spawn"),
                initializer=_start_worker,
                initargs=(self.factory, os.getpid()),
            )
        pool = self._pool

        def submit(task: EvalTask) -> Future[Outputs]:
            with _sigint_blocked():  # a worker it starts inherits the mask
                return pool.submit(
                    evaluate_in_worker,
                    self.factory,
                    problem.batch_size,
                    self.backend,
                    task,
                )

        try:
            yield from in_flight(submit, tasks, 2 * self.workers, (BrokenProcessPool,))
        except WorkerError:
            self.close()  # a broken pool takes no more work; the next one is new
            raise

    def close(self) -> None:
        """Stop the worker processes (chunks under way are finished first)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def terminate(self) -> None:
        """Stop the worker processes now: the chunks under way are lost.

        For a run that stops (Ctrl-C, an error): their results would not be
        recorded, so waiting for them only delays the stop.
        """
        if self._pool is None:
            return
        # Python 3.14 has ProcessPoolExecutor.terminate_workers; before, its
        # processes are only reachable through this attribute.
        processes = list((getattr(self._pool, "_processes", None) or {}).values())
        for process in processes:
            process.terminate()
        for process in processes:
            process.join(_DEATH_WAIT_S)
            if process.is_alive():
                process.kill()
                process.join()
        # A worker killed while it wrote a result leaves half a message in the
        # results pipe, and the pool's manager thread then waits in recv()
        # for the rest, forever (and shutdown with it). With every worker
        # dead, the parent's end is the pipe's last writer: closing it ends
        # that read with EOFError, which the manager thread takes for a broken
        # pool and exits.
        result_queue = getattr(self._pool, "_result_queue", None)
        if result_queue is not None:
            result_queue._writer.close()
        self.close()

    def __enter__(self) -> ProcessPoolEvaluator:
        return self

    def __exit__(self, *exc: Any) -> None:
        if exc[0] is None:
            self.close()
        else:
            self.terminate()


@contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT held back in this thread meanwhile (delivered after, not lost)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)
