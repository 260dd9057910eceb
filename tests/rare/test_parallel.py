"""Worker processes: the local result bit for bit, and a dead worker is an error."""

import os
import time
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from avrisk.rare import cross_entropy, naive_mc
from avrisk.rare.evaluation import EvalTask
from avrisk.rare.parallel import (
    EVALUATED_BY,
    ProcessPoolEvaluator,
    WorkerError,
    in_flight,
)
from avrisk.testing import gaussian_linear_problem

PROBLEM = gaussian_linear_problem(3, p=1e-4)


@dataclass(frozen=True)
class LinearFactory:
    """Builds PROBLEM.f in a worker; with ``die_once``, the first worker to be
    called exits (as if killed) and leaves that file behind."""

    die_once: str | None = None

    def __call__(self):
        f = gaussian_linear_problem(3, p=1e-4).f
        if self.die_once is None:
            return f

        def dying(x):
            marker = Path(self.die_once)
            if not marker.exists():
                marker.write_text(str(os.getpid()))
                os._exit(9)
            return f(x)

        return dying


@pytest.fixture(scope="module")
def pool():
    with ProcessPoolEvaluator(LinearFactory(), workers=2) as pool:
        yield pool


def without_time(result):
    return result.to_dict() | {"wall_time_s": 0}


def ce(evaluator=None):
    return cross_entropy(
        PROBLEM.f,
        PROBLEM.base,
        PROBLEM.gamma,
        rho=0.1,
        n_per_iter=20_000,  # three chunks per iteration
        n_iter=2,
        n_final=20_000,
        seed=5,
        evaluator=evaluator,
    )


def test_worker_processes_give_the_local_result_bit_for_bit(pool):
    assert without_time(ce(pool)) == without_time(ce())


def test_every_sample_says_which_worker_process_evaluated_it(pool):
    batches = []
    naive_mc(
        PROBLEM.f,
        PROBLEM.base,
        0.0,
        20_000,
        on_batch=batches.append,
        evaluator=pool,
    )
    labels = {str(b.extras[EVALUATED_BY][0]) for b in batches}
    assert all(label.startswith("processes ") for label in labels)
    assert all(f"pid {os.getpid()}" not in label for label in labels)
    assert all(len(set(b.extras[EVALUATED_BY])) == 1 for b in batches)


def test_a_dead_worker_is_an_error_naming_its_chunk_and_the_run_resumes(pool, tmp_path):
    recorded = {}

    def run(evaluator):
        return naive_mc(
            PROBLEM.f,
            PROBLEM.base,
            PROBLEM.gamma,
            40_000,
            seed=3,
            on_batch=lambda b: recorded.setdefault(b.chunk, b),
            cache=lambda stage, chunk: recorded.get(chunk),
            evaluator=evaluator,
        )

    dying = LinearFactory(die_once=str(tmp_path / "died"))
    with ProcessPoolEvaluator(dying, workers=2) as doomed:
        with pytest.raises(WorkerError, match=r"chunk \d of stage 0 .* rerun to res"):
            run(doomed)
    assert len(recorded) < 5
    resumed = run(pool)
    local = naive_mc(PROBLEM.f, PROBLEM.base, PROBLEM.gamma, 40_000, seed=3)
    assert without_time(resumed) == without_time(local)


@pytest.mark.parametrize("under_way", [False, True])
def test_a_pool_broken_before_a_submission_is_the_dead_workers_error(under_way):
    # the worker may die before the next chunk is submitted: the submission then
    # raises (not a pending future); the chunk under way, if any, is the one named
    dead = BrokenProcessPool("a child process terminated abruptly")
    died = Future()
    died.set_exception(dead)
    chunks = (7, 8) if under_way else (8,)
    tasks = [
        EvalTask(0, j, np.arange(1), np.zeros((1, 3)), np.zeros(1)) for j in chunks
    ]

    def submit(task):
        if task.chunk == 7:
            return died
        raise dead

    named = 7 if under_way else 8
    with pytest.raises(WorkerError, match=f"chunk {named} of stage 0 .* rerun to res"):
        list(in_flight(submit, tasks, 4, (BrokenProcessPool,)))


def test_workers_must_be_a_positive_integer():
    with pytest.raises(ValueError, match="workers must be an integer >= 1; got 0"):
        ProcessPoolEvaluator(LinearFactory(), workers=0)


@dataclass(frozen=True)
class BrokenFactory:
    def __call__(self):
        raise ValueError("no component named 'nope'")


def test_a_factory_that_fails_in_the_workers_raises_its_own_error():
    with ProcessPoolEvaluator(BrokenFactory(), workers=1) as pool:
        with pytest.raises(ValueError, match="no component named 'nope'"):
            naive_mc(PROBLEM.f, PROBLEM.base, 0.0, 100, evaluator=pool)


@dataclass(frozen=True)
class SlowAfterFirstFactory:
    """Builds PROBLEM.f; every chunk but the first to start sleeps 60 s."""

    marker: str

    def __call__(self):
        f = gaussian_linear_problem(3, p=1e-4).f

        def slow(x):
            try:
                os.close(os.open(self.marker, os.O_CREAT | os.O_EXCL))
            except FileExistsError:
                time.sleep(60)
            return f(x)

        return slow


def test_a_run_stopped_by_an_exception_stops_its_workers_at_once(tmp_path):
    """Ctrl-C: the chunks under way would not be recorded; nobody waits for them."""

    def interrupt(batch):
        raise KeyboardInterrupt

    slow = SlowAfterFirstFactory(str(tmp_path / "first"))
    with pytest.raises(KeyboardInterrupt):
        with ProcessPoolEvaluator(slow, workers=2) as pool:
            try:
                naive_mc(
                    PROBLEM.f, PROBLEM.base, PROBLEM.gamma, 30_000,
                    on_batch=interrupt, evaluator=pool,
                )  # fmt: skip
            finally:
                processes = list(pool._pool._processes.values())
                start = time.monotonic()
    assert time.monotonic() - start < 20  # not the 60 s of the chunks under way
    assert processes and not any(p.is_alive() for p in processes)


def test_stopping_does_not_hang_on_a_result_half_written_by_a_killed_worker():
    """A worker killed while writing its result leaves part of a message in the
    results pipe: the pool's manager thread must not wait for the rest."""
    import struct
    import threading

    pool = ProcessPoolEvaluator(LinearFactory(), workers=2)
    naive_mc(PROBLEM.f, PROBLEM.base, PROBLEM.gamma, 2_000, evaluator=pool)
    # a message header announcing 1,000 bytes, then 10 of them: as a killed writer
    writer = pool._pool._result_queue._writer
    os.write(writer.fileno(), struct.pack("!i", 1000) + b"x" * 10)
    time.sleep(0.5)  # the manager thread now waits for the other 990
    stopper = threading.Thread(target=pool.terminate, daemon=True)
    stopper.start()
    stopper.join(60)
    assert not stopper.is_alive()
