import numpy as np
import pytest

from avrisk.testing import four_branch_problem


def test_four_branch_exact_p_is_the_literature_value_and_agrees_with_naive_mc():
    problem = four_branch_problem()
    assert problem.p_exact == pytest.approx(2.2228e-3, abs=5e-8)  # as published
    n = 4_000_000
    x = problem.base.sample(n, np.random.default_rng(11))
    hits = np.count_nonzero(problem.f(x) <= problem.gamma)
    stderr = np.sqrt(problem.p_exact * (1 - problem.p_exact) / n)  # 1% of p
    assert abs(hits / n - problem.p_exact) < 5 * stderr


def test_four_branch_fails_in_all_four_directions():
    problem = four_branch_problem()
    d = 3.6  # beyond every branch along its own direction, inside the others
    corners = np.array([[d, d], [-d, -d], [-d, d], [d, -d]]) / np.sqrt(2)
    assert (problem.f(corners) <= 0).all()
    assert problem.f(np.zeros((1, 2)))[0] == pytest.approx(3.0)
