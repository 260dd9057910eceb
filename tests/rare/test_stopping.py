"""Stopping rules: each stops where it should, says so, and resumes the same."""

import numpy as np
import pytest

from avrisk.rare import cross_entropy, naive_mc
from avrisk.rare.problem import SAMPLE_CHUNK
from avrisk.rare.stopping import StoppingRule
from avrisk.testing import gaussian_linear_problem

PROBLEM = gaussian_linear_problem(2, p=1e-3)


def naive(**kw):
    return naive_mc(PROBLEM.f, PROBLEM.base, PROBLEM.gamma, 20 * SAMPLE_CHUNK, **kw)


def test_without_a_rule_the_run_spends_its_budget():
    est = naive(seed=1)
    assert est.stopped_by == "budget" and est.n_evals == 20 * SAMPLE_CHUNK


def test_the_precision_rule_stops_at_the_first_chunk_that_reaches_it():
    est = naive(seed=1, stopping=StoppingRule(rel_half_width=0.2))
    assert est.stopped_by == "precision"
    assert est.n_evals % SAMPLE_CHUNK == 0 and est.n_evals < 20 * SAMPLE_CHUNK
    half = 1.96 * est.stderr
    assert half <= 0.2 * est.p * 1.01  # binomial vs normal stderr: same here
    shorter = naive_mc(
        PROBLEM.f, PROBLEM.base, PROBLEM.gamma, est.n_evals - SAMPLE_CHUNK, seed=1
    )
    assert 1.96 * shorter.stderr > 0.2 * shorter.p  # one chunk earlier: not yet
    assert abs(est.p - PROBLEM.p_exact) < 4 * est.stderr


def test_the_rollout_cap_counts_the_search_and_is_never_exceeded():
    est = cross_entropy(
        PROBLEM.f,
        PROBLEM.base,
        PROBLEM.gamma,
        rho=0.1,
        n_per_iter=2000,
        n_iter=3,
        n_final=100_000,
        seed=2,
        stopping=StoppingRule(max_rollouts=30_000),
    )
    assert est.stopped_by == "max_rollouts"
    assert est.n_evals <= 30_000 and est.n_evals > 30_000 - SAMPLE_CHUNK


def test_a_wall_time_rule_stops_after_at_least_one_chunk():
    est = naive(seed=1, stopping=StoppingRule(max_seconds=1e-9))
    assert est.stopped_by == "wall_time" and est.n_evals == SAMPLE_CHUNK


def test_a_resumed_run_stops_at_the_same_chunk():
    record = {}
    rule = dict(rel_half_width=0.2)
    first = naive(
        seed=3,
        stopping=StoppingRule(**rule),
        on_batch=lambda b: record.__setitem__((b.stage, b.chunk), b),
    )
    again = naive(
        seed=3,
        stopping=StoppingRule(**rule),
        cache=lambda stage, chunk: record.get((stage, chunk)),
    )
    assert (again.p, again.n_evals) == (first.p, first.n_evals)


@pytest.mark.parametrize("name", ["rel_half_width", "max_rollouts", "max_seconds"])
def test_bad_rules_are_refused_by_name(name):
    with pytest.raises(ValueError, match=name):
        StoppingRule(**{name: 0})


def test_the_rule_ignores_failed_samples_as_hits():
    rule = StoppingRule(rel_half_width=0.5)
    values = np.full(10, np.nan)
    assert rule.reason(values, np.zeros(10), 0.0, 0) is None
