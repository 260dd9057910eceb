import numpy as np
import pytest
from scipy import integrate, stats

from avrisk.testing import four_branch_problem


def test_four_branch_is_the_rotated_system_of_two_curved_and_two_flat_branches(rng):
    problem = four_branch_problem()
    x = 3.0 * rng.standard_normal((10_000, 2))
    u, v = (x[:, 0] + x[:, 1]) / np.sqrt(2), (x[:, 0] - x[:, 1]) / np.sqrt(2)
    rotated = np.minimum(3.0 + 0.2 * v**2 - np.abs(u), np.sqrt(2) * (3.5 - np.abs(v)))
    np.testing.assert_allclose(problem.f(x), rotated, rtol=1e-12, atol=1e-12)


def test_four_branch_probability_agrees_with_quadrature_over_the_plane():
    # (u, v) is an orthonormal rotation of (x1, x2), so again N(0, I) (the test
    # above): for each v the failure set in u is |u| >= 3 + 0.2 v^2, and every u
    # once |v| >= 3.5
    curved, err = integrate.quad(
        lambda v: stats.norm.pdf(v) * 2.0 * stats.norm.sf(3.0 + 0.2 * v**2),
        -3.5,
        3.5,
        epsabs=1e-14,
    )
    assert err < 1e-10
    exact = curved + 2.0 * stats.norm.sf(3.5)
    assert exact == pytest.approx(four_branch_problem().p_exact, abs=5e-8)


@pytest.mark.slow
def test_four_branch_probability_agrees_with_naive_monte_carlo():
    problem = four_branch_problem()
    n = 4_000_000
    x = np.random.default_rng(7).standard_normal((n, 2))
    hits = np.count_nonzero(problem.f(x) <= 0.0)
    se = np.sqrt(problem.p_exact * (1 - problem.p_exact) / n)
    assert abs(hits / n - problem.p_exact) < 5 * se
