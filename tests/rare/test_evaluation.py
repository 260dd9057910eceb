"""The evaluator seam: a new backend is one class, and changes no result."""

import random
from concurrent.futures import ThreadPoolExecutor, as_completed

import numpy as np
import pytest

from avrisk.rare import cross_entropy, naive_mc
from avrisk.rare.evaluation import EvalTask, evaluate_task
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


def test_a_splitting_like_estimator_plugs_into_the_protocol_and_finds_p():
    from avrisk.rare import EstimationContext, get_estimator, run_estimator
    from avrisk.rare.problem import RareEventProblem
    from tests.rare import toy_splitting  # noqa: F401  (registers it)

    problem = gaussian_linear_problem(2, p=1e-4)
    rp = RareEventProblem(problem.base, problem.f, problem.gamma)
    method = get_estimator("toy_splitting", n_particles=4000)
    steps = []
    est = run_estimator(
        method, rp, EstimationContext(seed=3), callback=lambda i, s: steps.append(i)
    )
    assert len(steps) == est.details["levels"] == 4  # 1e-4 = 0.1^4
    assert steps[-1].level == problem.gamma
    assert 0.2 < steps[-1].accepted < 1.0
    # its own (rough) relative error is about 20%: 3 of them
    assert abs(np.log(est.p / problem.p_exact)) < 3 * est.stderr / est.p
