"""The evaluator seam: a new backend is one class, and changes no result."""

import random
from concurrent.futures import ThreadPoolExecutor, as_completed

import numpy as np
import pytest

from avrisk.rare import cross_entropy, naive_mc, subset_simulation
from avrisk.rare.evaluation import EvalTask, evaluate_task
from avrisk.rare.problem import SAMPLE_CHUNK
from avrisk.testing import gaussian_linear_problem

PROBLEM = gaussian_linear_problem(3, p=1e-4)


class ThreadPoolEvaluator:
    """The whole of a parallel backend: tasks to threads, results as they finish."""

    def __init__(self, workers=3):
        self.workers = workers

    def evaluate(self, problem, tasks):
        with ThreadPoolExecutor(self.workers) as pool:
            futures = [pool.submit(evaluate_task, problem, t) for t in tasks]
            for future in as_completed(futures):
                yield future.result()


class ShuffledEvaluator:
    """Returns every stage's results in a random order (a remote backend's worst)."""

    def __init__(self, seed):
        self.random = random.Random(seed)

    def evaluate(self, problem, tasks):
        results = [evaluate_task(problem, t) for t in tasks]
        self.random.shuffle(results)
        yield from results


def ce(evaluator=None, **kw):
    return cross_entropy(
        PROBLEM.f,
        PROBLEM.base,
        PROBLEM.gamma,
        rho=0.1,
        n_per_iter=9000,  # two chunks per iteration
        n_iter=4,
        n_final=20_000,
        seed=5,
        evaluator=evaluator,
        **kw,
    )


@pytest.mark.parametrize("evaluator", [ThreadPoolEvaluator(), ShuffledEvaluator(1)])
def test_any_evaluator_gives_the_local_result_bit_for_bit(evaluator):
    local, other = ce(), ce(evaluator)
    assert other.to_dict() | {"wall_time_s": 0} == local.to_dict() | {"wall_time_s": 0}


def test_results_are_filed_by_chunk_whatever_order_they_come_back_in():
    recorded = []
    naive_mc(
        PROBLEM.f,
        PROBLEM.base,
        PROBLEM.gamma,
        30_000,
        seed=2,
        on_batch=recorded.append,
        evaluator=ShuffledEvaluator(7),
    )
    assert sorted(b.chunk for b in recorded) == [0, 1, 2, 3]
    assert [b.chunk for b in recorded] != [0, 1, 2, 3]  # came back shuffled
    for batch in recorded:
        np.testing.assert_array_equal(batch.values, PROBLEM.f(batch.x))


def test_an_evaluator_that_loses_a_chunk_is_an_error():
    class Lossy:
        def evaluate(self, problem, tasks):
            for task in list(tasks)[:-1]:
                yield evaluate_task(problem, task)

    with pytest.raises(RuntimeError, match=r"no result for chunks \[2\] of stage 0"):
        naive_mc(PROBLEM.f, PROBLEM.base, 0.0, 20_000, evaluator=Lossy())


def test_a_task_carries_sample_ids_and_seeds_of_its_chunk():
    seen = []

    class Spy:
        def evaluate(self, problem, tasks):
            for task in tasks:
                assert isinstance(task, EvalTask)
                seen.append(task)
                yield evaluate_task(problem, task)

    naive_mc(PROBLEM.f, PROBLEM.base, 0.0, 10_000, seed=1, evaluator=Spy())
    np.testing.assert_array_equal(seen[1].ids, np.arange(8192, 10_000))
    assert seen[1].seeds.shape == (10_000 - 8192,) and seen[1].stage == 0


@pytest.mark.parametrize("evaluator", [ThreadPoolEvaluator(), ShuffledEvaluator(2)])
def test_splitting_moves_through_any_evaluator_to_the_local_result(evaluator):
    def run(evaluator=None):
        return subset_simulation(
            PROBLEM.f,
            PROBLEM.base,
            PROBLEM.gamma,
            n_particles=SAMPLE_CHUNK + 500,  # two chunks of draws of P0
            seed=5,
            evaluator=evaluator,
        )

    local, other = run(), run(evaluator)
    assert other.to_dict() | {"wall_time_s": 0} == local.to_dict() | {"wall_time_s": 0}
