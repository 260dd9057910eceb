import numpy as np
import pytest

from avrisk.rare import FixedCovNormal, RareEventProblem, cross_entropy, naive_mc
from avrisk.rare.problem import SAMPLE_CHUNK
from avrisk.testing import gaussian_linear_problem


class CountingLimitState:
    """``3 - x_0`` with a crash flag as an extra output; counts rows evaluated."""

    def __init__(self):
        self.rows = 0

    def __call__(self, x):
        self.rows += len(x)
        return {"f": 3.0 - x[:, 0], "crash": x[:, 0] > 3.5}


BASE = FixedCovNormal(np.zeros(2), cov=np.eye(2))


def test_sample_i_of_a_stage_does_not_depend_on_the_stage_size():
    recorded = {}
    for n in (SAMPLE_CHUNK + 10, 2 * SAMPLE_CHUNK + 1):
        batches = []
        naive_mc(CountingLimitState(), BASE, 0.0, n, seed=4, on_batch=batches.append)
        recorded[n] = np.concatenate([b.x for b in batches])
    short = SAMPLE_CHUNK + 10
    np.testing.assert_array_equal(
        recorded[short], recorded[2 * SAMPLE_CHUNK + 1][:short]
    )


def test_extra_outputs_of_f_are_recorded_with_every_chunk():
    batches = []
    est = naive_mc(
        CountingLimitState(), BASE, 0.0, 2 * SAMPLE_CHUNK + 5, on_batch=batches.append
    )
    assert [b.chunk for b in batches] == [0, 1, 2]
    ids = np.concatenate([b.ids for b in batches])
    np.testing.assert_array_equal(ids, np.arange(2 * SAMPLE_CHUNK + 5))
    for b in batches:
        np.testing.assert_array_equal(b.extras["crash"], b.x[:, 0] > 3.5)
        np.testing.assert_array_equal(b.values, 3.0 - b.x[:, 0])
    assert sum(int((b.values <= 0).sum()) for b in batches) == est.n_hits


def test_extra_outputs_of_the_wrong_shape_are_rejected_by_name():
    def f(x):
        return {"f": x[:, 0], "crash": np.zeros(3)}

    with pytest.raises(ValueError, match="output 'crash'"):
        naive_mc(f, BASE, 0.0, 10)


def test_replaying_recorded_chunks_reproduces_the_run_without_evaluating_them():
    problem = gaussian_linear_problem(2, p=1e-4)
    settings = dict(rho=0.1, n_per_iter=3000, n_iter=4, n_final=20_000, seed=8)
    record = {}
    first = CountingLimitState()
    full = cross_entropy(
        problem.f,
        problem.base,
        problem.gamma,
        **settings,
        on_batch=lambda b: record.__setitem__((b.stage, b.chunk), b),
    )
    # an interrupted run recorded only the first stages; resuming replays them
    kept = {k: v for k, v in record.items() if k[0] in (1, 2)}
    evaluated = []

    def f(x):
        evaluated.append(len(x))
        return problem.f(x)

    resumed = cross_entropy(
        f,
        problem.base,
        problem.gamma,
        **settings,
        cache=lambda stage, chunk: kept.get((stage, chunk)),
    )
    assert resumed.p == full.p and resumed.stderr == full.stderr
    assert resumed.history == full.history and resumed.details == full.details
    # stages 1 and 2 were not re-run; the rest, the audit and the rays were
    audit_calls = full.details["audit"]["n_calls"]
    rays = full.details["directional"]["n_calls"]
    assert sum(evaluated) == 2 * 3000 + 20_000 + audit_calls + rays
    assert first.rows == 0


def test_a_cached_chunk_of_another_size_is_evaluated_again():
    problem = RareEventProblem(BASE, CountingLimitState(), 0.0)
    f = problem.f
    naive_mc(f, BASE, 0.0, 100, cache=lambda s, c: None)
    stale = []
    naive_mc(f, BASE, 0.0, 50, on_batch=stale.append)
    before = f.rows
    naive_mc(f, BASE, 0.0, 100, cache=lambda s, c: stale[0])
    assert f.rows - before == 100
